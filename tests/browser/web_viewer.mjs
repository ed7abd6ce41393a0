// Drives the Residency web viewer page in headless Chromium (WebGPU on SwiftShader) for
// tests/python/test_web_viewer.py.
//
//   node tests/browser/web_viewer.mjs '<JSON spec>'
//
// The spec: {"url": PAGE_URL, "noWebGPU": false, "timeout_s": 240, "steps": [STEP...]}, where
// a STEP is one of
//   {"do": "converge"}                 wait until state().converged or state().error
//   {"do": "opened"}                   wait until the page has opened its dataset (info())
//   {"do": "state"}                    window.residency.state()
//   {"do": "snapshot", "path": P}      window.residency.snapshot() written to P as PNG
//   {"do": "setScene", "scene": S}     window.residency.setScene(S)
//   {"do": "drag", "dx": X, "dy": Y}   a left-button mouse drag across the canvas
//   {"do": "hash", "not": H}           location.hash, once it differs from H (if given)
//   {"do": "goto", "url": U}           open another URL in the same page
//   {"do": "message"}                  the on-page message (null when hidden)
//   {"do": "waitMessage"}              wait until the on-page message shows, then return it
//   {"do": "pause"}                    print {"paused": STEP_INDEX} and wait for a line on stdin
//                                      (the test does something to the server meanwhile)
// It prints {"results": [one per step], "console": ["type: text", ...]} as JSON.

import { writeFileSync } from "node:fs";
import { createInterface } from "node:readline";
import { launch } from "./browser.mjs";

const spec = JSON.parse(process.argv[2]);
const deadline = Date.now() + (spec.timeout_s ?? 240) * 1000;
const { browser, page, consoleMessages } = await launch();
if (spec.noWebGPU) {
  await page.addInitScript(() => Object.defineProperty(Navigator.prototype, "gpu", { get: () => undefined }));
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
        await page.mouse.move(x, y);
        await page.mouse.down();
        await page.mouse.move(x + step.dx, y + step.dy, { steps: 5 });
        await page.mouse.up();
        results.push(null);
        break;
      }
      case "hash":
        // The fragment follows the view once the next frame renders.
        results.push(await until(() => page.evaluate((old) => (location.hash && location.hash !== old ? location.hash : null), step.not ?? null)));
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
