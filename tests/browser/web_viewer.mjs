// Drives the Residency web viewer page in headless Chromium (WebGPU on SwiftShader) for
// tests/python/test_web_viewer.py and tests/python/test_web_remote.py.
//
//   node tests/browser/web_viewer.mjs '<JSON spec>'
//
// The spec: {"url": PAGE_URL, "noWebGPU": false, "noWebGPUCanvas": false (canvases refuse a
// "webgpu" context, WebGPU itself stays), "timeout_s": 240, "viewport": {"width": W,
// "height": H} (default 1024×768), "steps": [STEP...]}, where a STEP is one of
//   {"do": "converge"}                 wait until state().converged or state().error
//   {"do": "opened"}                   wait until the page has opened its dataset (info())
//   {"do": "state"}                    window.residency.state()
//   {"do": "waitState", "when": EXPR}  wait until EXPR, a JavaScript expression of `s` (the
//                                      state), is true (or s.error is set); return the state
//   {"do": "snapshot", "path": P}      window.residency.snapshot() written to P as PNG
//   {"do": "presented", "path": P}     window.residency.presented() (what the canvas shows)
//                                      written to P as PNG
//   {"do": "setScene", "scene": S}     window.residency.setScene(S)
//   {"do": "drag", "dx": X, "dy": Y, "moves": N, "delay_ms": D, "button": B, "shift": true}
//                                      a mouse drag across the canvas from its centre in N
//                                      moves (default 5), D ms apart (default 0), with button B
//                                      (left, the default; right or middle), Shift held if asked
//   {"do": "pinch", "scale": S}        a two-finger touch pinch on the canvas (pointer events
//                                      of type touch), the fingers' distance times S
//   {"do": "clickLink", "row": NAME, "text": T}
//                                      on brickserver's dataset list, click the link T in the
//                                      row of dataset NAME, and wait for the page it opens
//   {"do": "click", "selector": S}     click the element S (a button, a checkbox), as a person does
//   {"do": "location"}                 location.pathname + location.search
//   {"do": "hash", "not": H}           location.hash, once it differs from H (if given)
//   {"do": "goto", "url": U}           open another URL in the same page
//   {"do": "message"}                  the on-page message (null when hidden)
//   {"do": "waitMessage"}              wait until the on-page message shows, then return it
//   {"do": "sleep", "ms": MS}          wait MS milliseconds (what the page does meanwhile)
//   {"do": "workers"}                  the URLs of the page's workers
//   {"do": "histograms"}               once every channel's histogram canvas has a bar: per
//                                      canvas {width, height, bars}, bars[x] the pixels of
//                                      column x, counted up from the bottom, that are exactly
//                                      the bars' colour (#9ab)
//   {"do": "pause"}                    print {"paused": STEP_INDEX} and wait for a line on stdin
//                                      (the test does something to the server meanwhile)
// It prints {"results": [one per step], "console": ["type: text", ...]} as JSON.

import { writeFileSync } from "node:fs";
import { createInterface } from "node:readline";
import { launch } from "./browser.mjs";

const spec = JSON.parse(process.argv[2]);
const deadline = Date.now() + (spec.timeout_s ?? 240) * 1000;
const { browser, page, consoleMessages } = await launch(spec.viewport ?? {});
if (spec.noWebGPU) {
  await page.addInitScript(() => Object.defineProperty(Navigator.prototype, "gpu", { get: () => undefined }));
}
if (spec.noWebGPUCanvas) {
  await page.addInitScript(() => {
    const getContext = HTMLCanvasElement.prototype.getContext;
    HTMLCanvasElement.prototype.getContext = function (kind, ...rest) {
      return kind === "webgpu" ? null : getContext.call(this, kind, ...rest);
    };
  });
}

async function until(check) {
  for (;;) {
    const value = await check();
    if (value) return value;
    if (Date.now() > deadline) throw new Error("timed out");
    await page.waitForTimeout(100);
  }
}

const stdin = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
const results = [];
try {
  await page.goto(spec.url);
  for (const step of spec.steps) {
    switch (step.do) {
      case "converge":
        results.push(await until(() => page.evaluate(() => {
          const s = window.residency?.state();
          return s && (s.converged || s.error) ? s : null;
        })));
        break;
      case "opened":
        results.push(await until(() => page.evaluate(() => window.residency?.info() ?? null)));
        break;
      case "state":
        results.push(await page.evaluate(() => window.residency.state()));
        break;
      case "waitState":
        results.push(await until(() => page.evaluate((when) => {
          const s = window.residency?.state();
          return s && (s.error || new Function("s", `return (${when});`)(s)) ? s : null;
        }, step.when)));
        break;
      case "presented": {
        const url = await page.evaluate(() => window.residency.presented());
        writeFileSync(step.path, Buffer.from(url.split(",")[1], "base64"));
        results.push(step.path);
        break;
      }
      case "snapshot": {
        const url = await page.evaluate(() => window.residency.snapshot());
        writeFileSync(step.path, Buffer.from(url.split(",")[1], "base64"));
        results.push(step.path);
        break;
      }
      case "setScene":
        await page.evaluate((s) => window.residency.setScene(s), step.scene);
        results.push(null);
        break;
      case "drag": {
        const box = await page.locator("#canvas").boundingBox();
        const x = box.x + box.width / 2, y = box.y + box.height / 2;
        const button = step.button ?? "left";
        await page.mouse.move(x, y);
        if (step.shift) await page.keyboard.down("Shift");
        await page.mouse.down({ button });
        const moves = step.moves ?? 5;
        for (let i = 1; i <= moves; i++) {
          await page.mouse.move(x + (step.dx * i) / moves, y + (step.dy * i) / moves);
          if (step.delay_ms) await page.waitForTimeout(step.delay_ms);
        }
        await page.mouse.up({ button });
        if (step.shift) await page.keyboard.up("Shift");
        results.push(null);
        break;
      }
      case "pinch":
        await page.evaluate((scale) => {
          const c = document.getElementById("canvas");
          const r = c.getBoundingClientRect();
          const cx = r.x + r.width / 2, cy = r.y + r.height / 2, d0 = r.width / 8;
          const send = (type, id, x) =>
            c.dispatchEvent(new PointerEvent(type, {
              pointerId: id, pointerType: "touch", isPrimary: id === 1, bubbles: true,
              clientX: x, clientY: cy, buttons: type === "pointerup" ? 0 : 1,
            }));
          send("pointerdown", 1, cx - d0);
          send("pointerdown", 2, cx + d0);
          let d = d0;
          for (let i = 1; i <= 5; i++) {
            d = d0 * (1 + ((scale - 1) * i) / 5);
            send("pointermove", 1, cx - d);
            send("pointermove", 2, cx + d);
          }
          // Lift the fingers after a frame, as a person does.
          return new Promise((done) => requestAnimationFrame(() => {
            send("pointerup", 1, cx - d);
            send("pointerup", 2, cx + d);
            done();
          }));
        }, step.scale);
        results.push(null);
        break;
      case "clickLink": {
        const row = page.locator("tbody tr").filter({
          has: page.locator("td:first-child", { hasText: new RegExp(`^${step.row}$`) }),
        });
        const from = page.url();
        await Promise.all([page.waitForURL((u) => u.href !== from), row.getByText(step.text, { exact: true }).click()]);
        results.push(null);
        break;
      }
      case "workers":
        results.push(page.workers().map((w) => w.url()));
        break;
      case "histograms":
        results.push(await until(() => page.evaluate(() => {
          const canvases = [...document.querySelectorAll(".channel .histogram")];
          const out = canvases.map((c) => {
            const { data } = c.getContext("2d").getImageData(0, 0, c.width, c.height);
            const bar = (x, y) => {
              const i = 4 * (y * c.width + x);
              return data[i] === 0x99 && data[i + 1] === 0xaa && data[i + 2] === 0xbb && data[i + 3] === 255;
            };
            const bars = [];
            for (let x = 0; x < c.width; x++) {
              let n = 0;
              while (n < c.height && bar(x, c.height - 1 - n)) n++;
              bars.push(n);
            }
            return { width: c.width, height: c.height, bars };
          });
          return out.length && out.every((h) => h.bars.some((n) => n > 0)) ? out : null;
        })));
        break;
      case "location":
        results.push(await page.evaluate(() => location.pathname + location.search));
        break;
      case "hash":
        // The fragment follows the view once the next frame renders.
        results.push(await until(() => page.evaluate((old) => (location.hash && location.hash !== old ? location.hash : null), step.not ?? null)));
        break;
      case "click":
        await page.click(step.selector);
        results.push(null);
        break;
      case "select":
        // Picks an option of a <select> on the page, as a person does.
        await page.selectOption(step.selector, step.value);
        results.push(null);
        break;
      case "orientation":
        results.push(await until(() => page.evaluate(() => window.residency?.orientation() ?? null)));
        break;
      case "slide":
        // Moves a range input (a slider) to a value, as dragging it does: input, then change.
        await page.$eval(step.selector, (el, value) => {
          el.value = value;
          el.dispatchEvent(new Event("input", { bubbles: true }));
          el.dispatchEvent(new Event("change", { bubbles: true }));
        }, String(step.value));
        results.push(null);
        break;
      case "goto":
        await page.goto(step.url);
        results.push(null);
        break;
      case "message":
        results.push(await page.evaluate(() => {
          const m = document.getElementById("message");
          return m.hidden ? null : m.textContent;
        }));
        break;
      case "waitMessage":
        results.push(await until(() => page.evaluate(() => {
          const m = document.getElementById("message");
          return m.hidden ? null : m.textContent;
        })));
        break;
      case "sleep":
        await new Promise((resolve) => setTimeout(resolve, step.ms));
        results.push(null);
        break;
      case "pause":
        console.log(JSON.stringify({ paused: results.length }));
        await stdin.next();
        results.push(null);
        break;
      default:
        throw new Error(`unknown step ${step.do}`);
    }
  }
} finally {
  await browser.close();
}
console.log(JSON.stringify({ results, console: consoleMessages }));
// stdin (for `pause`) would keep the process alive.
process.exit(0);
