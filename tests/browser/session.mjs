// One headless Chromium (browser.mjs) for many pages, so that a test module starts the browser
// once (tests/python/support/browser.py, `BrowserSession`):
//
//   node tests/browser/session.mjs
//
// It prints {"ready": true, "version": CHROMIUM_VERSION} once the browser runs, then reads JSON
// lines on stdin, one request each:
//   {"id": N, "spec": SPEC}   runs a page as run_page.mjs does and prints
//                             {"id": N, "results": ..., "console": ..., "pageErrors": ...,
//                              "error": ..., "step": ...}
//   {"resume": N}             lets request N go on after its `pause` step printed
//                             {"id": N, "paused": STEP_INDEX}
// One request runs at a time. It exits (closing the browser) at the end of stdin.

import { createInterface } from "node:readline";
import { openBrowser, runPage } from "./browser.mjs";

const write = (obj) => process.stdout.write(`${JSON.stringify(obj)}\n`);
let browser;
try {
  browser = await openBrowser();
} catch (e) {
  write({ ready: false, error: `cannot start Chromium: ${e.message}` });
  process.exit(2);
}
write({ ready: true, version: browser.version() });

const lines = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
const waitResume = async (id) => {
  for (;;) {
    const { value, done } = await lines.next();
    if (done) throw new Error("stdin closed during a pause");
    if (JSON.parse(value).resume === id) return;
  }
};
for (;;) {
  const { value, done } = await lines.next();
  if (done) break;
  if (!value.trim()) continue;
  const { id, spec } = JSON.parse(value);
  const out = await runPage(browser, spec, {
    onPause: async (i) => {
      write({ id, paused: i });
      await waitResume(id);
    },
  });
  write({ id, ...out });
}
await browser.close();
process.exit(0);
