// Replays a recorded camera path in the Residency web viewer page (headless Chromium, WebGPU on
// SwiftShader) for benchmarks/remote_session_bench.py, and records what the page shows.
//
//   node tests/browser/remote_session.mjs '<JSON spec>'
//
// The spec: {"url": PAGE_URL, "viewport": {"width": W, "height": H}, "timeout_s": 300,
//   "converge_s": 120,                       the most to wait for the first converged image
//   "keys": [[T, AZ, EL, DIST], ...],        the path: at T seconds, the camera orbits the
//                                            page's first camera by AZ degrees (about its up
//                                            axis) and EL degrees (about its right axis), at
//                                            DIST times its distance to the target; linear
//                                            between keys, held after the last
//   "segments": [{"name", "start", "move_end", "end"}, ...],   seconds, for the records
//   "samples": [T, ...],                     when to record the page (seconds, ascending)
//   "input_ms": 33,                          how often the camera is set while it moves
//   "final_s": 60}                           the most to wait, after the path, for the page to
//                                            converge on its last camera
// Before the replay (the first image converged, nothing in flight) and after it, the driver
// prints {"mark": "start"|"end", ...} and waits for a line on stdin: the bench reads its proxies'
// byte counts then. Last, it prints {"scene", "adapter", "start", "end", "final", "samples",
// "draws", "rested", "console"} as JSON: each sample {t (scheduled), late_ms, camera (the path's
// at t), state (window.residency.state()), bytes (fetch() body bytes so far per origin), png
// (window.residency.snapshot(): the frame on show as a PNG data URL, read back on the page's
// GPU path)}; draws: the times (s) the page drew a frame into its canvas (a putImageData on the
// CPU path, a WebGPU canvas texture acquired on the GPU path);
// rested: per segment, seconds from the end of its move until the page was converged on the
// rested camera (null if it was not before the segment ended); final {waited_s, state, png}:
// the page once converged on the last camera, off the schedule; start/end: the page's state
// and the body bytes its fetch() received per origin.

import { createInterface } from "node:readline";
import { launch } from "./browser.mjs";

const spec = JSON.parse(process.argv[2]);
const deadline = Date.now() + (spec.timeout_s ?? 300) * 1000;
const { browser, page, consoleMessages } = await launch(spec.viewport ?? {});

// Counts the body bytes of every fetch() by origin as they arrive (the page's bricks and VDIs,
// both fetched with fetch()), the largest whole body, and what the page aborted (a superseded
// request): for a body cut short, the bytes its Content-Length promised but the page never read;
// the requests aborted before their answer's headers. Those may have crossed the link before the
// abort reached the other end. Also timestamps every frame drawn into the canvas (putImageData on the page's
// CPU path; getCurrentTexture of its WebGPU canvas context, once a frame, on the GPU path).
await page.addInitScript(() => {
  const rs = { draws: [], bytes: {}, fetches: {}, failed: {}, unread: {}, unbounded: {}, unanswered: {}, largest: {} };
  window.__session = rs;
  const fetch = window.fetch.bind(window);
  const add = (table, key, n) => { table[key] = (table[key] ?? 0) + n; };
  window.fetch = async (input, init) => {
    const url = new URL(typeof input === "string" ? input : input.url ?? String(input), location.href);
    const key = url.origin;
    let response;
    try {
      response = await fetch(input, init);
    } catch (e) {
      // Aborted before its answer's headers were read: the answer may still have crossed the
      // link, whole, before the abort reached the other end.
      add(rs.unanswered, key, 1);
      throw e;
    }
    const promised = Number(response.headers.get("content-length") ?? NaN);
    const body = response.clone().body;
    let read = 0;
    (async () => {
      if (body) {
        const reader = body.getReader();
        for (;;) {
          const { done, value } = await reader.read();
          if (done) break;
          read += value.byteLength;
          add(rs.bytes, key, value.byteLength);
        }
      }
    })().then(
      () => {
        add(rs.fetches, key, 1);
        rs.largest[key] = Math.max(rs.largest[key] ?? 0, read);
      },
      () => {
        add(rs.failed, key, 1);
        // Without a Content-Length nothing bounds what crossed: counted apart, the test fails.
        if (Number.isFinite(promised)) add(rs.unread, key, promised - read);
        else add(rs.unbounded, key, 1);
      },
    );
    return response;
  };
  const put = CanvasRenderingContext2D.prototype.putImageData;
  CanvasRenderingContext2D.prototype.putImageData = function (...args) {
    rs.draws.push(performance.now());
    return put.apply(this, args);
  };
  if (window.GPUCanvasContext) {
    const acquire = GPUCanvasContext.prototype.getCurrentTexture;
    GPUCanvasContext.prototype.getCurrentTexture = function (...args) {
      rs.draws.push(performance.now());
      return acquire.apply(this, args);
    };
  }
});

const stdin = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
async function mark(name, extra) {
  console.log(JSON.stringify({ mark: name, ...extra }));
  await stdin.next();
}

const counters = () => page.evaluate(() => ({
  state: window.residency.state(),
  bytes: { ...window.__session.bytes },
  fetches: { ...window.__session.fetches },
  failed: { ...window.__session.failed },
  unread: { ...window.__session.unread },
  unbounded: { ...window.__session.unbounded },
  unanswered: { ...window.__session.unanswered },
  largest: { ...window.__session.largest },
}));

let out;
try {
  await page.goto(spec.url);
  const convergeBy = Date.now() + (spec.converge_s ?? 120) * 1000;
  for (;;) {
    const s = await page.evaluate(() => window.residency?.state() ?? null);
    if (s?.error) throw new Error(`the page failed: ${s.error}`);
    if (s?.converged && !s.remote?.in_flight) break;
    if (Date.now() > Math.min(deadline, convergeBy)) throw new Error(`the first image did not converge: ${JSON.stringify(s)}`);
    await page.waitForTimeout(100);
  }
  const scene = await page.evaluate(() => JSON.parse(decodeURIComponent(location.hash.slice("#scene=".length))));
  // The viewer's adapter name, else what WebGPU tells of it (Chromium may give no name).
  const adapter = await page.evaluate(async () => {
    const name = window.residency.info().adapter;
    if (name) return name;
    const info = (await navigator.gpu.requestAdapter())?.info ?? {};
    return [info.vendor, info.architecture, info.description].filter(Boolean).join(" ") || null;
  });
  const start = await counters();
  await mark("start", { state: start.state });

  const replay = await page.evaluate(async ({ scene, keys, samples, segments, input_ms }) => {
    const sub = (a, b) => a.map((v, i) => v - b[i]);
    const add = (a, b) => a.map((v, i) => v + b[i]);
    const mul = (a, k) => a.map((v) => v * k);
    const dot = (a, b) => a.reduce((s, v, i) => s + v * b[i], 0);
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const unit = (a) => mul(a, 1 / Math.hypot(...a));
    const c0 = scene.camera;
    const offset = sub(c0.eye, c0.target);
    const dist = Math.hypot(...offset);
    const back = unit(offset);
    const up0 = unit(sub(c0.up, mul(back, dot(c0.up, back))));
    const right = cross(up0, back);
    const rad = Math.PI / 180;
    // The path's pose at t: linear between keys.
    function pose(t) {
      if (t <= keys[0][0]) return keys[0].slice(1);
      for (let i = 1; i < keys.length; i++) {
        if (t <= keys[i][0]) {
          const [ta, ...a] = keys[i - 1];
          const [tb, ...b] = keys[i];
          const f = tb > ta ? (t - ta) / (tb - ta) : 1;
          return a.map((v, j) => v + (b[j] - v) * f);
        }
      }
      return keys[keys.length - 1].slice(1);
    }
    function camera([az, el, d]) {
      const h = add(mul(back, Math.cos(az * rad)), mul(right, Math.sin(az * rad)));
      const dir = add(mul(h, Math.cos(el * rad)), mul(up0, Math.sin(el * rad)));
      const up = add(mul(h, -Math.sin(el * rad)), mul(up0, Math.cos(el * rad)));
      return { ...c0, eye: add(c0.target, mul(dir, dist * d)), up };
    }
    const rs = window.__session;
    const total = segments[segments.length - 1].end;
    const records = [];
    const rested = segments.map(() => null);
    let set = null, setAt = -Infinity, next = 0;
    const t0 = performance.now();
    const drawsFrom = rs.draws.length;
    await new Promise((done) => {
      async function tick() {
        const now = performance.now();
        const t = (now - t0) / 1000;
        const p = pose(Math.min(t, total));
        const key = JSON.stringify(p);
        // Moving, the camera is set every input_ms (as mouse events come); resting, at once.
        const resting = t >= total || segments.some((g) => t >= g.move_end && t < g.end);
        if (key !== set && (resting || now - setAt >= input_ms)) {
          window.residency.setScene({ ...scene, camera: camera(p) });
          set = key;
          setAt = now;
        }
        const s = window.residency.state();
        segments.forEach((g, i) => {
          if (rested[i] === null && t >= g.move_end && t < g.end && set === JSON.stringify(pose(g.move_end)) && s.converged) {
            rested[i] = t - g.move_end;
          }
        });
        if (next < samples.length && t >= samples[next]) {
          const bytes = { ...rs.bytes };
          const png = await window.residency.snapshot();
          while (next < samples.length && t >= samples[next]) {
            records.push({
              t: samples[next],
              late_ms: (t - samples[next]) * 1000,
              camera: camera(pose(samples[next])),
              state: s,
              bytes,
              png,
            });
            next++;
          }
        }
        if (t >= total && next >= samples.length) done();
        else requestAnimationFrame(tick);
      }
      requestAnimationFrame(tick);
    });
    return { samples: records, rested, draws: rs.draws.slice(drawsFrom).map((d) => (d - t0) / 1000) };
  }, { scene, keys: spec.keys, samples: spec.samples, segments: spec.segments, input_ms: spec.input_ms ?? 33 });

  // Off the schedule: wait until the page has converged on the path's last camera, then
  // record it (the quality at rest, whatever the schedule allowed).
  const waitFrom = Date.now();
  const finalBy = Date.now() + (spec.final_s ?? 60) * 1000;
  let settled;
  for (;;) {
    settled = await page.evaluate(() => window.residency.state());
    if (settled.error || (settled.converged && !settled.remote?.in_flight) || Date.now() > Math.min(deadline, finalBy)) break;
    await page.waitForTimeout(100);
  }
  const final = {
    waited_s: (Date.now() - waitFrom) / 1000,
    state: settled,
    png: await page.evaluate(() => window.residency.snapshot()),
  };
  const end = await counters();
  await mark("end", { state: end.state });
  out = { scene, adapter, start, end, final, ...replay };
} finally {
  await browser.close();
}
// A large line: exit once it is written (process.exit would cut a pipe's pending output).
process.stdout.write(JSON.stringify({ ...out, console: consoleMessages }) + "\n", () => process.exit(0));
