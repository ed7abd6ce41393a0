// Runs one page in its own headless Chromium (browser.mjs) and prints the outcome as JSON:
//
//   node tests/browser/run_page.mjs '<JSON spec>'
//
// spec: {"url": URL, "steps": [STEP...], "width": 1024, "height": 768, "noWebGPU": false,
// "timeout_s": 120}; the steps are those of browser.mjs (`runSteps`). The last line of stdout is
// {"results": [...], "console": [...], "pageErrors": [...], "error": null | "message",
// "step": null | index}. A `pause` step prints {"paused": INDEX} and waits for a line on stdin.
// The exit status is 0 whenever the page ran (a failed step is reported in "error"), 2 when the
// browser could not start.

import { createInterface } from "node:readline";
import { openBrowser, runPage } from "./browser.mjs";

const spec = JSON.parse(process.argv[2] ?? "{}");
let stdin = null;
const onPause = async (i) => {
  stdin ??= createInterface({ input: process.stdin })[Symbol.asyncIterator]();
  console.log(JSON.stringify({ paused: i }));
  await stdin.next();
};
let browser;
try {
  browser = await openBrowser();
} catch (e) {
  console.log(JSON.stringify({ error: `cannot start Chromium: ${e.message}`, results: [], console: [], pageErrors: [], step: null }));
  process.exit(2);
}
const out = await runPage(browser, spec, { onPause });
await browser.close();
console.log(JSON.stringify(out));
// stdin (for `pause`) would keep the process alive.
process.exit(0);
