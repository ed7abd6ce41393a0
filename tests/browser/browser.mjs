// Launches Debian's Chromium headless through playwright-core, with WebGPU on Chromium's
// SwiftShader adapter, and drives pages for the browser tests (tests/python/test_web_viewer.py,
// tests/python/test_peer_viewers.py; the Python side is tests/python/support/browser.py).
//
//   import { launch, openBrowser, openPage, runSteps, runPage } from "./browser.mjs";
//
//   // One page in its own browser (persistent context in a fresh profile folder):
//   const { browser, page, consoleMessages } = await launch({ width, height });
//   ...; await browser.close();
//
//   // One browser, many pages (each page in its own incognito context):
//   const browser = await openBrowser();
//   const out = await runPage(browser, { url, steps: [...], width, height, timeout_s });
//   // out = {results: [one per step], console: ["type: text", ...], pageErrors: [...],
//   //        error: null | "message", step: null | index of the failed step}
//   await browser.close();
//
// `consoleMessages` collects "TYPE: text" for every console message and "pageerror: message"
// for every uncaught page error. The steps `runSteps` understands are listed above `STEPS`.
//
// Command-line drivers: run_page.mjs (one page, one browser) and session.mjs (one browser, pages
// sent as JSON lines on stdin).

import { mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { chromium } from "playwright-core";

/** Chromium flags: root needs --no-sandbox; the next four give WebGPU on SwiftShader (without
 * the Vulkan/ANGLE ones the first frame drawn to a WebGPU canvas loses the device in headless
 * Chromium 156; WebGL runs on SwiftShader through ANGLE); the rest keep it off the (closed)
 * network. */
export const CHROMIUM_ARGS = [
  "--no-sandbox",
  "--enable-unsafe-webgpu",
  "--enable-features=Vulkan",
  "--use-vulkan=swiftshader",
  "--use-angle=swiftshader",
  "--disable-background-networking",
  "--disable-component-update",
  "--no-first-run",
  "--disable-quic",
  "--disable-sync",
];

export const CHROMIUM = process.env.CHROMIUM ?? "/usr/bin/chromium";

/** Records console messages and uncaught errors of `page` into the arrays given. */
export function collectConsole(page, consoleMessages = [], pageErrors = []) {
  page.on("console", (m) => consoleMessages.push(`${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => {
    consoleMessages.push(`pageerror: ${e.message}`);
    pageErrors.push(e.message);
  });
  return { consoleMessages, pageErrors };
}

/** A fresh headless Chromium (its own profile folder) and one page. */
export async function launch({ width = 1024, height = 768 } = {}) {
  const profile = mkdtempSync(join(tmpdir(), "residency-chromium-"));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    args: CHROMIUM_ARGS,
    viewport: { width, height },
  });
  const page = context.pages()[0] ?? (await context.newPage());
  const { consoleMessages } = collectConsole(page);
  const browser = {
    async close() {
      await context.close();
      rmSync(profile, { recursive: true, force: true });
    },
  };
  return { browser, page, consoleMessages };
}

/** A headless Chromium for many pages (playwright gives it a fresh temporary profile). */
export async function openBrowser() {
  return chromium.launch({ executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS });
}

/** A page of `width` × `height` CSS pixels (device scale 1) in a new context of `browser`.
 * `noWebGPU` hides navigator.gpu before any script of the page runs. */
export async function openPage(browser, { width = 1024, height = 768, noWebGPU = false } = {}) {
  const context = await browser.newContext({ viewport: { width, height }, deviceScaleFactor: 1 });
  const page = await context.newPage();
  if (noWebGPU) {
    await page.addInitScript(() => Object.defineProperty(Navigator.prototype, "gpu", { get: () => undefined }));
  }
  const { consoleMessages, pageErrors } = collectConsole(page);
  return { page, context, consoleMessages, pageErrors, close: () => context.close() };
}

/** The value of the expression `js` in the page, with `arg` (JSON) bound; awaited, so `js` may
 * be a promise or use `await`. */
async function evaluate(page, js, arg) {
  return page.evaluate(`(async (arg) => (${js}))(${JSON.stringify(arg ?? null)})`);
}

async function boxOf(page, step) {
  if (step.selector) {
    const box = await page.locator(step.selector).first().boundingBox();
    if (!box) throw new Error(`${step.selector}: not visible`);
    return box;
  }
  if (step.clip) return step.clip;
  const v = page.viewportSize();
  return { x: 0, y: 0, width: v.width, height: v.height };
}

function round(box) {
  return { x: Math.round(box.x), y: Math.round(box.y), width: Math.round(box.width), height: Math.round(box.height) };
}

// The steps. Each returns one result (JSON); `js` is a JavaScript expression evaluated in the page
// (it may use `await` inside an `async` IIFE, and `arg`, the step's `arg`), and `selector` a
// playwright selector (CSS by default).
//   {"do": "goto", "url": U}                    open U (waits for the load event)
//   {"do": "eval", "js": E, "arg": A}           the value of E
//   {"do": "waitFor", "js": E, "arg": A, "timeout_s": T, "poll_ms": 100}
//                                               the value of E once it is truthy
//   {"do": "sleep", "ms": N}                    wait N ms
//   {"do": "frames", "n": N}                    wait N animation frames
//   {"do": "screenshot", "path": P, "selector": S | "clip": {x, y, width, height}}
//                                               a PNG of the page (or the element, or the
//                                               clip) written to P; returns {path, box}
//   {"do": "stable", "path": P, "selector": S, "interval_ms": 250, "count": 3, "timeout_s": T}
//                                               waits until `count` screenshots in a row, one
//                                               every interval_ms, are byte-identical; writes
//                                               the last to P (if given); returns {path, box,
//                                               shots}
//   {"do": "dataUrl", "js": E, "path": P}       E gives a data: URL (e.g. a canvas snapshot);
//                                               its bytes are written to P; returns P
//   {"do": "click", "selector": S | "x": X, "y": Y}
//   {"do": "drag", "selector": S, "dx": X, "dy": Y, "steps": 5}
//                                               a left-button drag from the element's centre
//   {"do": "wheel", "selector": S, "dy": D, "n": 1}   n wheel steps of D over the element
//   {"do": "press", "key": K}                   a key press (playwright key names)
//   {"do": "type", "selector": S, "text": T}    fills an input
//   {"do": "viewport", "width": W, "height": H} resizes the page
//   {"do": "pause"}                             calls `onPause(step index)` and waits for it
//                                               (the driver prints {"paused": i} and waits for
//                                               the test to answer)
export const STEPS = [
  "goto", "eval", "waitFor", "sleep", "frames", "screenshot", "stable", "dataUrl", "click",
  "drag", "wheel", "press", "type", "viewport", "pause",
];

/** Runs `steps` on `page`; returns their results. Throws (with `.step` set) on the first
 * failure. `deadline` is a Date.now() value no step may pass. */
export async function runSteps(page, steps, { deadline = Date.now() + 120_000, onPause } = {}) {
  const results = [];
  const left = () => Math.max(1, deadline - Date.now());
  const until = async (check, step) => {
    const stop = Math.min(deadline, step.timeout_s ? Date.now() + step.timeout_s * 1000 : Infinity);
    for (;;) {
      const value = await check();
      if (value) return value;
      if (Date.now() > stop) throw new Error(`timed out waiting for ${step.js ?? step.do}`);
      await page.waitForTimeout(step.poll_ms ?? 100);
    }
  };
  for (const [i, step] of steps.entries()) {
    try {
      page.setDefaultTimeout(left());
      results.push(await runStep(page, step, i, { until, onPause }));
    } catch (e) {
      e.step = i;
      e.results = results;
      throw e;
    }
  }
  return results;
}

async function runStep(page, step, index, { until, onPause }) {
  switch (step.do) {
    case "goto":
      await page.goto(step.url, { waitUntil: step.waitUntil ?? "load" });
      return null;
    case "eval":
      return (await evaluate(page, step.js, step.arg)) ?? null;
    case "waitFor":
      return until(() => evaluate(page, step.js, step.arg), step);
    case "sleep":
      await page.waitForTimeout(step.ms);
      return null;
    case "frames":
      await page.evaluate(async (n) => {
        for (let i = 0; i < n; i++) await new Promise((r) => requestAnimationFrame(r));
      }, step.n ?? 2);
      return null;
    case "screenshot": {
      const box = round(await boxOf(page, step));
      const png = await page.screenshot({ clip: box });
      if (step.path) writeFileSync(step.path, png);
      return { path: step.path ?? null, box };
    }
    case "stable": {
      const count = step.count ?? 3;
      let last = null, same = 0, shots = 0, box = null;
      await until(async () => {
        box = round(await boxOf(page, step));
        const png = await page.screenshot({ clip: box });
        shots += 1;
        same = last && png.equals(last) ? same + 1 : 1;
        last = png;
        if (same >= count) return true;
        await page.waitForTimeout(step.interval_ms ?? 250);
        return false;
      }, { ...step, poll_ms: 0 });
      if (step.path) writeFileSync(step.path, last);
      return { path: step.path ?? null, box, shots };
    }
    case "dataUrl": {
      const url = await evaluate(page, step.js, step.arg);
      if (typeof url !== "string" || !url.startsWith("data:")) throw new Error(`${step.js} gave no data: URL`);
      writeFileSync(step.path, Buffer.from(url.slice(url.indexOf(",") + 1), "base64"));
      return step.path;
    }
    case "click":
      if (step.selector) await page.locator(step.selector).first().click();
      else await page.mouse.click(step.x, step.y);
      return null;
    case "drag": {
      const box = await boxOf(page, step);
      const x = box.x + box.width / 2, y = box.y + box.height / 2;
      await page.mouse.move(x, y);
      await page.mouse.down();
      await page.mouse.move(x + step.dx, y + step.dy, { steps: step.steps ?? 5 });
      await page.mouse.up();
      return null;
    }
    case "wheel": {
      const box = await boxOf(page, step);
      await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
      for (let i = 0; i < (step.n ?? 1); i++) await page.mouse.wheel(0, step.dy);
      return null;
    }
    case "press":
      await page.keyboard.press(step.key);
      return null;
    case "type":
      await page.locator(step.selector).first().fill(step.text);
      return null;
    case "viewport":
      await page.setViewportSize({ width: step.width, height: step.height });
      return null;
    case "pause":
      if (!onPause) throw new Error("pause: this driver cannot pause");
      await onPause(index);
      return null;
    default:
      throw new Error(`unknown step ${JSON.stringify(step.do)} (known: ${STEPS.join(", ")})`);
  }
}

/** Opens a page in `browser` (spec: {url?, steps, width, height, noWebGPU, timeout_s}), runs the
 * steps (a `url` is a first `goto`), closes the page. Never throws for a page's failure: returns
 * {results, console, pageErrors, error, step}, with error/step null when every step ran. */
export async function runPage(browser, spec, { onPause } = {}) {
  const deadline = Date.now() + (spec.timeout_s ?? 120) * 1000;
  const { page, consoleMessages, pageErrors, close } = await openPage(browser, spec);
  const steps = spec.url ? [{ do: "goto", url: spec.url }, ...(spec.steps ?? [])] : spec.steps ?? [];
  const offset = spec.url ? 1 : 0;
  let results = [], error = null, step = null;
  try {
    results = await runSteps(page, steps, { deadline, onPause: onPause && ((i) => onPause(i - offset)) });
    if (offset) results.shift();
  } catch (e) {
    error = e.message;
    step = e.step - offset;
    results = (e.results ?? []).slice(offset);
  } finally {
    await close().catch(() => {});
  }
  return { results, console: consoleMessages, pageErrors, error, step };
}
