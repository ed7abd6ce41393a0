// The Residency web viewer page: drives the WebAssembly `Viewer` (viewer/src/web) from
// requestAnimationFrame, draws its frames into the canvas, and defines `window.residency`.
//
// Which dataset: `/NAME/view` on a brickserver opens dataset NAME there; `?server=URL&dataset=NAME`
// opens one on another brickserver. `?width=W&height=H` fixes the image size in pixels (else
// the canvas fills the window when the page opens). `#scene=` followed by URI-encoded scene
// JSON (schemas/json/scene.schema.json) sets the view; the page keeps it up to date.
//
// Remote mode: `?render=URL` names a render service (`viewer serve`) serving the same dataset
// (`?render_token=TOKEN`: its bearer token, when it runs with --serve-token-file). The *Remote*
// switch then starts on: the page streams no bricks but asks the service for volumetric depth
// images (VDIs) of its view (POST URL/vdi) and ray casts the newest one for its own camera
// (viewer/src/web/remote.rs decides when to ask; only the latest request matters: a newer one
// aborts the fetch in flight; an answer 429 or 503 is asked again after its Retry-After, at
// most 3 times). `?target_fps=N` is the frame rate its frame-rate controller holds while the
// camera moves (default 60). `?vdi_filter=auto|nearest|linear` (and the *VDI filter* menu) is
// how the page reads a VDI between its lists: the nearest list (the paper's, the fastest), the
// bilinear mix of the four around each point (closer to DVR away from the VDI's camera, at
// several times the cost), or `auto` (the default): the linear filter once the camera rests,
// and while it moves where the last linear frame at full resolution held the target frame
// rate, else the nearest list. `?vdi_compression=auto|shuffled_lz4|shuffled_zstd` is how the
// service compresses the VDIs it sends: zstd is 1.4 to 1.7 times smaller than LZ4 and slower
// to write and read; `auto` (the default) asks for zstd while the last answer large enough to
// weigh the link crossed it slower than the threshold (viewer/src/vdi_compression_choice.rs:
// its body's bytes over the time from its first byte to its last, as Resource Timing gives
// them), else for LZ4. The page reads each VDI answer in a worker (vdi_worker.js, the same
// WebAssembly), off its main thread: it only uploads the buffers the worker sends back.
//
// Frames reach the screen on the GPU: the canvas holds a WebGPU context, and the viewer draws
// each frame into it from the frame's image on the GPU (an sRGB encode in a small pass, no
// readback). Where no WebGPU canvas context can be made the page falls back to the CPU path:
// each frame read back, encoded to sRGB in the viewer and drawn with putImageData on a 2D
// canvas. `?present=auto|gpu|cpu` picks (auto, the default: the GPU where it can; gpu: an error
// where it cannot; cpu: the CPU path always). `state().present` says which is in use, and
// `state().image_readbacks` counts the images read back (one a frame on the CPU path, one a
// `snapshot()` on the GPU path).

import init, { Viewer } from "./residency_viewer.js";

// Replaced by a fresh element when a WebGPU context was made but cannot be used (a canvas with
// a WebGPU context cannot also hold the CPU path's 2D context).
let canvas = document.getElementById("canvas");
const message = document.getElementById("message");
const stats = document.getElementById("stats");

/** Shows a message over the view (null hides it). */
function show(text) {
  message.hidden = text == null;
  message.textContent = text ?? "";
}

/** Where the dataset is: {server, dataset}. */
function target() {
  const params = new URLSearchParams(location.search);
  if (params.has("dataset")) {
    return { server: params.get("server") ?? location.origin, dataset: params.get("dataset") };
  }
  const m = location.pathname.match(/^(.*)\/([^/]+)\/view\/?$/);
  if (m) return { server: location.origin + m[1], dataset: decodeURIComponent(m[2]) };
  return null;
}

/** The image size: ?width=&height=, else what the view area offers. */
function size() {
  const params = new URLSearchParams(location.search);
  const area = document.getElementById("view").getBoundingClientRect();
  const w = parseInt(params.get("width") ?? "", 10) || Math.max(64, Math.floor(area.width));
  const h = parseInt(params.get("height") ?? "", 10) || Math.max(64, Math.floor(area.height));
  return [Math.min(w, 4096), Math.min(h, 4096)];
}

// Linear RGB (scene colours) <-> sRGB hex (colour inputs).
const toSrgb = (v) => (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055);
const toLinear = (v) => (v <= 0.04045 ? v / 12.92 : Math.pow((v + 0.055) / 1.055, 2.4));
const hex = (rgb) =>
  "#" + rgb.map((v) => Math.round(toSrgb(Math.min(1, Math.max(0, v))) * 255).toString(16).padStart(2, "0")).join("");
const fromHex = (h) => [1, 3, 5].map((i) => toLinear(parseInt(h.slice(i, i + 2), 16) / 255));

let viewer = null;
let lastScene = "";
let failure = null;
/** Frames are presented on the GPU (a WebGPU canvas context), not by putImageData. */
let onGpu = false;
/** snapshot() and presented() calls waiting for the loop, between two steps: {kind, resolve, reject}. */
const waiting = [];

/** `?present=`: how frames reach the canvas ("auto", "gpu" or "cpu"), or null for another value. */
function presentWanted() {
  const value = new URLSearchParams(location.search).get("present") ?? "auto";
  return ["auto", "gpu", "cpu"].includes(value) ? value : null;
}

/** The render service of the remote mode: {url, token, frameMs (NaN: the default), vdiFilter
 * and vdiCompression (null: the default)}, or null. */
function renderService() {
  const params = new URLSearchParams(location.search);
  const url = params.get("render");
  if (!url) return null;
  const fps = parseFloat(params.get("target_fps") ?? "");
  return {
    url: url.replace(/\/+$/, ""),
    token: params.get("render_token"),
    frameMs: fps > 0 ? 1000 / fps : NaN,
    vdiFilter: params.get("vdi_filter"),
    vdiCompression: params.get("vdi_compression"),
  };
}

const service = renderService();
/** The fetch of the request in flight: {sequence, abort: AbortController}. */
let inFlight = null;
/** The remote mode's error is on show (hidden again once a VDI is drawn). */
let remoteShown = false;

/** The page's VDI reader (vdi_worker.js), made with the remote mode: `read(sequence, bytes)`
 * transfers an answer's bytes to the worker and resolves to its message, {read} or {failed}.
 * A worker whose WebAssembly trapped is replaced by a new one (the reads it held fail); one
 * whose script did not load fails every read from then on, saying so. */
class VdiReader {
  static NAME = "the page's VDI reader (vdi_worker.js)";

  constructor() {
    this.pending = new Map();
    this.broken = null;
    this.start();
  }

  start() {
    this.worker = new Worker(new URL("./vdi_worker.js", import.meta.url), { type: "module" });
    this.worker.onmessage = ({ data }) => {
      this.settle(data.sequence, data);
      if (data.spent) this.restart(data.failed);
    };
    this.worker.onmessageerror = () => this.restart(`${VdiReader.NAME} sent a message the page cannot read`);
    // The worker's script or its imports did not load (or it failed outside a read).
    this.worker.onerror = (e) => {
      e.preventDefault();
      this.broken = `${VdiReader.NAME} failed: ${e.message || "it did not load"}`;
      this.failAll(this.broken);
    };
  }

  /** A new worker in place of a spent one; the reads the old one held fail with `why`. */
  restart(why) {
    this.worker.terminate();
    this.failAll(why);
    this.start();
  }

  failAll(why) {
    for (const sequence of [...this.pending.keys()]) this.settle(sequence, { failed: why });
  }

  settle(sequence, answer) {
    const resolve = this.pending.get(sequence);
    this.pending.delete(sequence);
    if (resolve) resolve(answer);
  }

  read(sequence, bytes) {
    if (this.broken) return Promise.resolve({ failed: this.broken });
    return new Promise((resolve) => {
      this.pending.set(sequence, resolve);
      this.worker.postMessage({ sequence, bytes }, [bytes]);
    });
  }
}

const vdiReader = service ? new VdiReader() : null;

function serviceHeaders(json) {
  const headers = {};
  if (service.token) headers.authorization = `Bearer ${service.token}`;
  if (json) headers["content-type"] = "application/json";
  return headers;
}

/** The error message of a failed service answer: its JSON `error`, else the status. */
async function serviceError(response) {
  try {
    const body = await response.json();
    if (typeof body.error === "string") return body.error;
  } catch {
    // not JSON
  }
  return `HTTP ${response.status} ${response.statusText}`.trim();
}

/** Reads the service's /info and hands it to the viewer (errors become the remote error). */
async function openService() {
  try {
    const r = await fetch(`${service.url}/info`, { headers: serviceHeaders(false) });
    if (!r.ok) {
      viewer.remote_failed(0, r.status, await serviceError(r));
      return;
    }
    viewer.remote_info(await r.text());
  } catch (e) {
    // remote_info records its own errors; a fetch that failed is the service unreachable.
    if (e instanceof TypeError) viewer.remote_failed(0, 0, `cannot reach the render service: ${e.message}`);
  }
}

/** Aborts the request in flight, if any (the viewer has forgotten it already). */
function abortInFlight() {
  if (inFlight) inFlight.abort.abort();
  inFlight = null;
}

/** The wait (ms) a 429 or 503 answer asks for: its `Retry-After` in seconds (or as an HTTP
 * date), else 1 s; at most 60 s. */
function retryAfterMs(response) {
  const value = (response.headers.get("retry-after") ?? "").trim();
  let ms = 1000;
  if (/^\d+$/.test(value)) ms = parseInt(value, 10) * 1000;
  else if (value && !Number.isNaN(Date.parse(value))) ms = Math.max(0, Date.parse(value) - Date.now());
  return Math.min(ms, 60000);
}

/** Resolves after `ms`, or at once when `signal` aborts (a newer request superseded it). */
function sleep(ms, signal) {
  return new Promise((resolve) => {
    const timer = setTimeout(resolve, ms);
    signal.addEventListener("abort", () => { clearTimeout(timer); resolve(); }, { once: true });
  });
}

/** How long the body of the newest answer from `url` took on the link, ms: from its first byte
 * to its last as the browser's network stack timed them (Resource Timing, which the service
 * allows with `Timing-Allow-Origin`), whatever the main thread did meanwhile; NaN where the
 * browser kept no timing. Clears the page's resource timings, so that their buffer never
 * fills. */
function bodyMs(url) {
  const entries = performance.getEntriesByName(url, "resource");
  performance.clearResourceTimings();
  let newest = null;
  for (const e of entries) if (!newest || e.responseEnd > newest.responseEnd) newest = e;
  if (!newest || !(newest.responseStart > 0) || !(newest.responseEnd >= newest.responseStart)) return NaN;
  return newest.responseEnd - newest.responseStart;
}

/** Sends the request the viewer wants now, if any, superseding the one in flight. An answer
 * 429 or 503 is retried after its Retry-After while the viewer allows (remote_retry: the
 * request is still the latest, and retried fewer than MAX_RETRIES times). */
function remoteTick() {
  const body = viewer.remote_request();
  if (body == null) return;
  abortInFlight();
  const sequence = JSON.parse(body).request;
  const mine = { sequence, abort: new AbortController() };
  inFlight = mine;
  const send = () => fetch(`${service.url}/vdi`, { method: "POST", headers: serviceHeaders(true), body, signal: mine.abort.signal });
  const answered = async (r) => {
    if (r.ok) {
      const bytes = await r.arrayBuffer();
      if (mine.abort.signal.aborted) return;
      // Counted and timed now, whatever becomes of it while the worker reads it.
      viewer.remote_received(bytes.byteLength, bodyMs(`${service.url}/vdi`));
      const answer = await vdiReader.read(sequence, bytes);
      if (mine.abort.signal.aborted) return;
      if (answer.failed) viewer.remote_failed(sequence, 0, answer.failed);
      else viewer.remote_answer(sequence, answer.read);
      return;
    }
    const message = await serviceError(r);
    if (mine.abort.signal.aborted) return;
    if ((r.status === 429 || r.status === 503) && viewer.remote_retry(sequence)) {
      await sleep(retryAfterMs(r), mine.abort.signal);
      if (!mine.abort.signal.aborted) await answered(await send());
      return;
    }
    viewer.remote_failed(sequence, r.status, message);
  };
  send()
    .then(answered)
    .catch((e) => {
      if (!mine.abort.signal.aborted) viewer.remote_failed(sequence, 0, `cannot reach the render service: ${e.message}`);
    })
    .finally(() => {
      if (inFlight === mine) inFlight = null;
    });
}

function draw() {
  if (onGpu) return; // drawn on the GPU by the step
  const w = viewer.width(), h = viewer.height();
  const rgba = viewer.rgba();
  if (rgba.length !== w * h * 4) return;
  const ctx = canvas.getContext("2d");
  ctx.putImageData(new ImageData(new Uint8ClampedArray(rgba.buffer, rgba.byteOffset, rgba.length), w, h), 0, 0);
}

function state() {
  if (!viewer) {
    return { frame: 0, converged: false, bricks_fetched: 0, bytes_fetched: 0, error: failure, controls_built: 0 };
  }
  const s = JSON.parse(viewer.state_json());
  if (failure && !s.error) s.error = failure;
  s.controls_built = controlsBuilt;
  return s;
}

function showStats() {
  const s = state();
  const mib = (s.bytes_fetched / (1 << 20)).toFixed(1);
  stats.textContent =
    `frame ${s.frame}${s.converged ? " (converged)" : ""}\n` +
    `bricks requested ${s.bricks_requested} · fetched ${s.bricks_fetched} · resident ${s.bricks_resident}\n` +
    `in flight ${s.requests_in_flight} requests · failed ${s.bricks_failed}\n` +
    `fetched ${mib} MiB\n` +
    (s.gpu_time_ms != null ? `GPU ${s.gpu_time_ms.toFixed(2)} ms/frame\n` : "GPU time: no timestamp queries\n");
  const r = s.remote;
  if (r) {
    stats.textContent +=
      `remote: ${r.mode}${r.converged ? " (converged)" : ""}\n` +
      (r.service_adapter ? `service GPU ${r.service_adapter.name} (${r.service_adapter.backend})\n` : "") +
      `VDIs received ${r.vdis_received} (${(r.vdi_bytes_received / (1 << 20)).toFixed(1)} MiB) · requests ${r.requests_sent} · retried ${r.requests_retried} · aborted ${r.requests_aborted} · dropped ${r.answers_dropped}\n` +
      `compression ${r.vdi_compression}` + (r.answer_compression ? ` (last VDI ${r.answer_compression})` : "") + (r.link_mbit_per_s != null ? ` · link ${r.link_mbit_per_s.toFixed(0)} Mbit/s` : "") + "\n" +
      `D_I ${r.d_i.toFixed(2)} · ${r.vdi_filter} filter` + (r.vdi_filter === "auto" && r.frame_filter ? ` (${r.frame_filter})` : "") + (r.frame_ms != null ? ` · ${r.frame_ms.toFixed(1)} ms/frame` : "") +
      // What decides auto's filter while the camera moves: the last linear frame's time.
      (r.vdi_filter === "auto" && r.linear_frame_ms != null ? ` · linear ${r.linear_frame_ms.toFixed(1)} ms` : "") +
      (r.drawn_request != null && !r.scene_current ? " · VDI of an older style" : "") + "\n" +
      // This side's share of each answer's latency: reading the VDI, then setting it up.
      (r.vdi_decode_ms != null && r.vdi_setup_ms != null ? `last VDI read in ${r.vdi_decode_ms.toFixed(1)} ms · set up in ${r.vdi_setup_ms.toFixed(1)} ms\n` : "");
  }
  if (s.error) {
    const hint = r && r.mode !== "off" ? "" : "Is the brick server still running? ";
    show(`Error: ${s.error}\n\n${hint}Reload the page to try again.`);
  } else if (r && r.mode !== "off" && r.last_error) {
    show(`Render service ${r.service}: ${r.last_error}`);
    remoteShown = true;
  } else if (remoteShown) {
    show(null);
    remoteShown = false;
  }
}

function keepSceneInUrl() {
  const json = viewer.scene_json();
  if (json !== lastScene) {
    lastScene = json;
    history.replaceState(null, "", location.pathname + location.search + "#scene=" + encodeURIComponent(json));
  }
  return json;
}

/** Draws channel `c`'s histogram (log counts) with its window [lo, hi] shaded. */
function drawHistogram(canvasEl, hist, lo, hi) {
  const ctx = canvasEl.getContext("2d");
  const w = canvasEl.width, h = canvasEl.height;
  ctx.clearRect(0, 0, w, h);
  if (!hist) return;
  const finite = hist.edges.filter((e) => e != null && Number.isFinite(e));
  if (finite.length < 2) return;
  const x0 = finite[0], x1 = finite[finite.length - 1];
  const x = (v) => ((Math.min(x1, Math.max(x0, v)) - x0) / (x1 - x0 || 1)) * w;
  ctx.fillStyle = "#2a3a4a";
  ctx.fillRect(x(lo), 0, Math.max(1, x(hi) - x(lo)), h);
  const top = Math.log1p(Math.max(...hist.counts, 1));
  ctx.fillStyle = "#9ab";
  hist.counts.forEach((n, i) => {
    const a = hist.edges[i] ?? x0, b = hist.edges[i + 1] ?? x1;
    const bh = (Math.log1p(n) / top) * h;
    ctx.fillRect(x(a), h - bh, Math.max(1, x(b) - x(a)), bh);
  });
}

/** Channel `c`'s histogram over the whole volume, from the server's region metadata. */
async function fetchHistogram(where, info, c) {
  if (!info.region_metadata) return null;
  const level = info.levels.length - 1;
  const [z, y, x] = info.levels[level];
  const url = `${where.server}/${encodeURIComponent(where.dataset)}/regions?level=${level}&channel=${c}&min=0,0,0&max=${x},${y},${z}`;
  try {
    const r = await fetch(url);
    return r.ok ? (await r.json()).histogram : null;
  } catch {
    return null;
  }
}

const histograms = new Map();

/** Times the channel controls were built (state().controls_built). */
let controlsBuilt = 0;

/** A scene's JSON without its camera: what the controls show. */
function styleOf(json) {
  const { camera: _, ...style } = JSON.parse(json);
  return JSON.stringify(style);
}

function buildControls(info) {
  controlsBuilt += 1;
  const panel = document.getElementById("channels");
  panel.textContent = "";
  const scene = JSON.parse(viewer.scene_json());
  info.channels.forEach((name, c) => {
    const style = scene.channels.find((s) => s.channel === c);
    const display = info.display[c] ?? {};
    const pts = style?.opacity ?? [];
    const lo0 = pts.length ? pts[0].value : 0;
    const hi0 = pts.length ? pts[pts.length - 1].value : 1;
    const range = display.range ?? display.window ?? [Math.min(lo0, 0), hi0];
    const top = pts.reduce((m, p) => Math.max(m, p.opacity), 0);
    const box = document.createElement("div");
    box.className = "channel";
    box.innerHTML = `
      <label><input type="checkbox" class="visible"><span class="name"></span><input type="color" class="color"></label>
      <label>low <input type="range" class="lo"><input type="number" class="lo-n"></label>
      <label>high <input type="range" class="hi"><input type="number" class="hi-n"></label>
      <canvas class="histogram" width="240" height="40" title="histogram (log counts) and window"></canvas>
      <label>opacity <input type="range" class="opacity" min="0" max="1" step="0.001"></label>`;
    const q = (sel) => box.querySelector(sel);
    q(".name").textContent = name;
    q(".name").title = name;
    q(".visible").checked = style ? style.visible !== false : false;
    q(".visible").dataset.channel = c;
    q(".color").value = hex(style?.color ?? [1, 1, 1]);
    for (const cls of [".lo", ".hi"]) {
      q(cls).min = range[0];
      q(cls).max = range[1] > range[0] ? range[1] : range[0] + 1;
      q(cls).step = info.data_type.startsWith("float") ? (range[1] - range[0]) / 1000 || 0.001 : 1;
    }
    q(".lo").value = q(".lo-n").value = lo0;
    q(".hi").value = q(".hi-n").value = hi0;
    q(".opacity").value = top;
    q(".visible").addEventListener("change", (e) => viewer.set_visible(c, e.target.checked));
    q(".color").addEventListener("input", (e) => viewer.set_color(c, ...fromHex(e.target.value)));
    const redraw = () => drawHistogram(q(".histogram"), histograms.get(c), +q(".lo").value, +q(".hi").value);
    const setWindow = (lo, hi) => {
      if (hi > lo) viewer.set_window(c, lo, hi);
      redraw();
    };
    if (histograms.has(c)) redraw();
    else fetchHistogram(target(), info, c).then((hist) => { histograms.set(c, hist); redraw(); });
    q(".lo").addEventListener("input", (e) => { q(".lo-n").value = e.target.value; setWindow(+e.target.value, +q(".hi").value); });
    q(".hi").addEventListener("input", (e) => { q(".hi-n").value = e.target.value; setWindow(+q(".lo").value, +e.target.value); });
    q(".lo-n").addEventListener("change", (e) => { q(".lo").value = e.target.value; setWindow(+e.target.value, +q(".hi-n").value); });
    q(".hi-n").addEventListener("change", (e) => { q(".hi").value = e.target.value; setWindow(+q(".lo-n").value, +e.target.value); });
    q(".opacity").addEventListener("input", (e) => viewer.set_opacity(c, +e.target.value));
    panel.appendChild(box);
  });
}

function listen() {
  // Pointers down on the canvas (mouse, pen or fingers). One drags: orbit, or pan with shift
  // or the right button. Two (a pinch) zoom by the change of their distance and pan with
  // their midpoint.
  const pointers = new Map();
  let drag = null;
  let pinch = null;
  const pinchState = () => {
    const [a, b] = [...pointers.values()];
    return { d: Math.hypot(a.x - b.x, a.y - b.y), x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 };
  };
  let pinchScheduled = false;
  const applyPinch = () => {
    pinchScheduled = false;
    if (!pinch || pointers.size !== 2) return;
    const now = pinchState();
    // Four zoom steps halve the distance: fingers twice as far apart, half the distance.
    if (pinch.d > 0 && now.d > 0) viewer.zoom(4 * Math.log2(now.d / pinch.d));
    viewer.pan(now.x - pinch.x, now.y - pinch.y);
    pinch = now;
  };
  canvas.addEventListener("pointerdown", (e) => {
    try {
      canvas.setPointerCapture(e.pointerId);
    } catch {
      // a pointer the browser does not track (synthetic events): nothing to capture
    }
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    if (pointers.size === 1) {
      drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
    } else if (pointers.size === 2) {
      drag = null;
      pinch = pinchState();
    }
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!pointers.has(e.pointerId)) return;
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    if (pinch && pointers.size === 2) {
      // Applied once per animation frame, so that both fingers' moves count together.
      if (!pinchScheduled) {
        pinchScheduled = true;
        requestAnimationFrame(applyPinch);
      }
      return;
    }
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.pan) viewer.pan(dx, dy);
    else viewer.orbit(dx, dy);
  });
  const end = (e) => {
    if (pinch && pointers.size === 2) applyPinch();
    pointers.delete(e.pointerId);
    if (pointers.size < 2) pinch = null;
    drag = null;
    if (pointers.size === 1) {
      // The finger left on the glass goes on orbiting from where it is.
      const [p] = pointers.values();
      drag = { x: p.x, y: p.y, pan: false };
    }
  };
  canvas.addEventListener("pointerup", end);
  canvas.addEventListener("pointercancel", end);
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    viewer.zoom(-Math.sign(e.deltaY) * Math.min(4, Math.abs(e.deltaY) / 100 || 1));
  }, { passive: false });
  // The reconstruction filter (scene "filter"): a new renderer, the cache refilled.
  const filter = document.getElementById("filter");
  const showFilter = () => { filter.value = JSON.parse(viewer.scene_json()).filter ?? "trilinear"; };
  showFilter();
  filter.addEventListener("change", (e) => viewer.set_filter(e.target.value));
  // The render mode (scene "mode"): a new renderer, the cache refilled.
  const mode = document.getElementById("mode");
  const showMode = () => { mode.value = JSON.parse(viewer.scene_json()).mode ?? "dvr"; };
  showMode();
  mode.addEventListener("change", (e) => viewer.set_mode(e.target.value));
  // Clipping (scene "clip"): a box, as fractions of the volume's extent per axis, and a cut
  // facing the camera at `near` from the eye, from the volume's nearest possible point (0) to
  // its farthest (1) at the camera's distance. The scene's own planes are kept.
  const extent = JSON.parse(viewer.info_json()).extent;
  const axes = ["x", "y", "z"];
  const slider = (name) => document.getElementById(`clip-${name}`);
  const radius = 0.5 * Math.hypot(...extent);
  const eyeDistance = (camera) => Math.hypot(...camera.eye.map((e, a) => e - camera.target[a]));
  const applyClip = () => {
    const scene = JSON.parse(viewer.scene_json());
    const clip = {};
    const lo = axes.map((a, i) => Math.min(+slider(`${a}-min`).value, +slider(`${a}-max`).value) * extent[i]);
    const hi = axes.map((a, i) => Math.max(+slider(`${a}-min`).value, +slider(`${a}-max`).value) * extent[i]);
    if (lo.some((v) => v > 0) || hi.some((v, i) => v < extent[i])) clip.box = { min: lo, max: hi };
    if (scene.clip?.planes) clip.planes = scene.clip.planes;
    const front = +slider("near").value;
    if (front > 0) clip.near = Math.max(0, eyeDistance(scene.camera) - radius) + front * 2 * radius;
    viewer.set_clip(JSON.stringify(clip));
  };
  const showClip = () => {
    const scene = JSON.parse(viewer.scene_json());
    const box = scene.clip?.box;
    axes.forEach((a, i) => {
      slider(`${a}-min`).value = box ? box.min[i] / extent[i] : 0;
      slider(`${a}-max`).value = box ? box.max[i] / extent[i] : 1;
    });
    const near = scene.clip?.near;
    slider("near").value = near == null ? 0 : (near - Math.max(0, eyeDistance(scene.camera) - radius)) / (2 * radius);
  };
  showClip();
  for (const a of axes) for (const end of ["min", "max"]) slider(`${a}-${end}`).addEventListener("input", applyClip);
  slider("near").addEventListener("input", applyClip);
  const reset = () => {
    viewer.reset();
    buildControls(JSON.parse(viewer.info_json()));
    showFilter();
    showMode();
    showClip();
  };
  // The remote switch: only with a render service (?render=URL).
  const remote = document.getElementById("remote");
  remote.disabled = !service;
  remote.checked = service != null;
  remote.parentElement.title = service
    ? `VDIs of the view from the render service ${service.url}, ray cast here`
    : "needs a render service: open the page with ?render=URL (viewer serve)";
  remote.addEventListener("change", (e) => {
    if (!e.target.checked) abortInFlight();
    viewer.set_remote(e.target.checked);
    // Refused or unreachable before: read its /info again.
    if (e.target.checked && state().remote?.mode === "starting") openService();
    if (!e.target.checked && remoteShown) {
      show(null);
      remoteShown = false;
    }
  });
  // How the remote mode reads a VDI between its lists: drawn again at once, not asked again.
  const vdiFilter = document.getElementById("vdi-filter");
  vdiFilter.disabled = !service;
  vdiFilter.addEventListener("change", (e) => viewer.set_vdi_filter(e.target.value));
  document.getElementById("reset").addEventListener("click", reset);
  window.addEventListener("keydown", (e) => {
    if ((e.key === "r" || e.key === "R") && e.target.tagName !== "INPUT") reset();
  });
}

/** 8-bit sRGB RGBA pixels of the image size as a PNG data URL, as the CPU path's canvas encodes them. */
function pngOf(rgba) {
  const w = viewer.width(), h = viewer.height();
  const c = document.createElement("canvas");
  c.width = w;
  c.height = h;
  if (rgba.length === w * h * 4) {
    c.getContext("2d").putImageData(new ImageData(new Uint8ClampedArray(rgba.buffer, rgba.byteOffset, rgba.length), w, h), 0, 0);
  }
  return c.toDataURL("image/png");
}

/** What the WebGPU canvas shows, as a PNG data URL: the frame presented again and copied in the same task. */
function presentedPng() {
  viewer.repaint();
  const c = document.createElement("canvas");
  c.width = canvas.width;
  c.height = canvas.height;
  c.getContext("2d").drawImage(canvas, 0, 0);
  return c.toDataURL("image/png");
}

/** Answers the snapshot() and presented() calls waiting, between two steps. */
async function answerWaiting() {
  while (waiting.length) {
    const { kind, resolve, reject } = waiting.shift();
    try {
      resolve(kind === "snapshot" ? pngOf(await viewer.snapshot_rgba()) : presentedPng());
    } catch (e) {
      reject(new Error(String(e)));
    }
  }
}

// ---- orientation: a scale bar in the store's unit and axes that turn with the camera ----

let orientation = null;
let orientationKey = null;

// Draws the orientation over the view of the scene `sceneJson` (a frame just drawn) when the
// scene or the view's size changed.
function drawOrientation(sceneJson) {
  const overlay = document.getElementById("orientation");
  const rect = canvas.getBoundingClientRect();
  const key = `${rect.width}x${rect.height} ${sceneJson}`;
  if (key === orientationKey || rect.height === 0) return;
  orientationKey = key;
  // Worked out in the WebAssembly module, by the rule `viewer view` draws by.
  orientation = JSON.parse(viewer.orientation_json(rect.height));
  if (!orientation) return;
  const dpr = window.devicePixelRatio || 1;
  overlay.style.width = `${rect.width}px`;
  overlay.style.height = `${rect.height}px`;
  overlay.width = Math.round(rect.width * dpr);
  overlay.height = Math.round(rect.height * dpr);
  const g = overlay.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, rect.width, rect.height);
  g.font = "12px system-ui, sans-serif";
  g.lineWidth = 2;
  g.shadowColor = "black";
  g.shadowBlur = 2;
  // The scale bar, bottom left.
  const { length, unit, pixels } = orientation.scale;
  const y = rect.height - 14;
  g.strokeStyle = g.fillStyle = "white";
  g.beginPath();
  g.moveTo(12, y - 4); g.lineTo(12, y); g.lineTo(12 + pixels, y); g.lineTo(12 + pixels, y - 4);
  g.stroke();
  g.fillText(`${length} ${unit}`, 12, y - 7);
  // The axes, bottom right: x red, y green, z blue.
  const origin = [rect.width - 40, rect.height - 40];
  for (const [name, colour] of [["x", "#f55"], ["y", "#5f5"], ["z", "#59f"]]) {
    const [dx, dy] = orientation.axes[name];
    g.strokeStyle = g.fillStyle = colour;
    g.beginPath();
    g.moveTo(...origin);
    g.lineTo(origin[0] + 24 * dx, origin[1] + 24 * dy);
    g.stroke();
    g.fillText(name, origin[0] + 31 * dx - 3, origin[1] + 31 * dy + 4);
  }
}

async function loop() {
  try {
    if (service) remoteTick();
    if (await viewer.step()) {
      draw();
      drawOrientation(keepSceneInUrl());
    }
  } catch (e) {
    failure = String(e);
  }
  await answerWaiting();
  showStats();
  requestAnimationFrame(loop);
}

window.residency = {
  /** Replaces the scene (the same JSON as scene files). */
  setScene(scene) {
    if (!viewer) throw new Error(failure ?? "the viewer is not open yet");
    const before = styleOf(viewer.scene_json());
    viewer.set_scene_json(JSON.stringify(scene));
    // Only the camera changed: the controls still show the scene's style.
    if (styleOf(viewer.scene_json()) !== before) buildControls(JSON.parse(viewer.info_json()));
  },
  /** {frame, converged, bricks_fetched, bytes_fetched, error, controls_built, ..., remote:
   * {mode, service_adapter: {name, backend}, requests_sent, requests_retried,
   * requests_aborted, answers_dropped, vdis_received, vdi_bytes_received, vdi_compression, link_mbit_per_s,
   * request_link_mbit_per_s, answer_compression, last_error, d_i,
   * vdi_filter, frame_filter, linear_frame_ms, moving_frames_linear, vdi_decode_ms,
   * vdi_setup_ms, vdi_camera, converged,
   * ...} with a render service, else null}. */
  state,
  /** What the orientation overlay shows: {scale: {length, unit, pixels}, axes: {x, y, z: the
   * screen direction [right, down] of each world axis}}; null before the first frame. */
  orientation: () => orientation,
  /** The current frame as a PNG data URL (8-bit sRGB, like `viewer render`'s PNG). On the GPU
   * path it is read back for this call (state().image_readbacks counts it). */
  async snapshot() {
    if (!viewer || !onGpu) return canvas.toDataURL("image/png");
    return new Promise((resolve, reject) => waiting.push({ kind: "snapshot", resolve, reject }));
  },
  /** What the canvas shows, as a PNG data URL (on the GPU path the WebGPU canvas copied into
   * a 2D canvas; for tests that compare it with snapshot()). */
  async presented() {
    if (!viewer || !onGpu) return canvas.toDataURL("image/png");
    return new Promise((resolve, reject) => waiting.push({ kind: "presented", resolve, reject }));
  },
  /** The dataset's description (channels, display hints, levels, adapter). */
  info() {
    return viewer ? JSON.parse(viewer.info_json()) : null;
  },
};

async function main() {
  const where = target();
  if (!where) {
    failure = "no dataset: open /NAME/view on a brickserver, or add ?server=URL&dataset=NAME";
    show(failure);
    return;
  }
  document.getElementById("title").textContent = where.dataset;
  document.title = `${where.dataset} · Residency viewer`;
  if (!navigator.gpu) {
    failure =
      "This browser has no WebGPU, which the Residency viewer needs.\n" +
      "Use a current Chrome or Edge (or Firefox with WebGPU enabled), over https or on localhost.";
    show(failure);
    return;
  }
  await init();
  const [w, h] = size();
  canvas.width = w;
  canvas.height = h;
  try {
    viewer = await Viewer.open(where.server, where.dataset, w, h);
  } catch (e) {
    failure = String(e);
    show(`Cannot open dataset '${where.dataset}' on ${where.server}:\n${failure}`);
    return;
  }
  if (location.hash.startsWith("#scene=")) {
    try {
      viewer.set_scene_json(decodeURIComponent(location.hash.slice("#scene=".length)));
    } catch (e) {
      show(`The link's #scene is not a valid scene (${e}); showing the default view.`);
    }
  }
  const present = presentWanted();
  if (present == null) {
    failure = `?present= must be auto, gpu or cpu, not '${new URLSearchParams(location.search).get("present")}'`;
    show(failure);
    return;
  }
  if (present !== "cpu") {
    try {
      const format = await viewer.present_on(canvas);
      onGpu = true;
      console.info(`presenting on the GPU (a ${format} WebGPU canvas context)`);
    } catch (e) {
      if (present === "gpu") {
        failure = `cannot present on the GPU (?present=gpu): ${e}`;
        show(failure);
        return;
      }
      console.warn(`no WebGPU canvas context (${e}): presenting by the CPU path (putImageData)`);
      const fresh = canvas.cloneNode(false);
      canvas.replaceWith(fresh);
      canvas = fresh;
    }
  }
  buildControls(JSON.parse(viewer.info_json()));
  listen();
  if (service) {
    viewer.remote_begin(service.url, service.frameMs);
    for (const [value, set, name] of [
      [service.vdiFilter, (v) => viewer.set_vdi_filter(v), "vdi_filter"],
      [service.vdiCompression, (v) => viewer.set_vdi_compression(v), "vdi_compression"],
    ]) {
      if (value == null) continue;
      try {
        set(value);
      } catch (e) {
        failure = `?${name}: ${e}`;
        show(failure);
        return;
      }
    }
    // The menu shows the viewer's filter (not a value the browser kept from before a reload).
    document.getElementById("vdi-filter").value = state().remote.vdi_filter;
    await openService();
  }
  requestAnimationFrame(loop);
}

main();
