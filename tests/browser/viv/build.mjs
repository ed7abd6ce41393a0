// Bundles the Viv test page (viv/main.jsx with @hms-dbmi/viv, deck.gl and React) with esbuild
// into OUT_DIR, beside a copy of viv/index.html:
//
//   node tests/browser/viv/build.mjs OUT_DIR        (or '{"out": OUT_DIR}')
import { copyFileSync, mkdirSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { build } from "esbuild";

const here = dirname(fileURLToPath(import.meta.url));
const arg = process.argv[2] ?? "";
const out = arg.startsWith("{") ? JSON.parse(arg).out : arg;
if (!out) throw new Error("usage: node build.mjs OUT_DIR");
mkdirSync(out, { recursive: true });
await build({
  entryPoints: [join(here, "main.jsx")],
  bundle: true,
  format: "esm",
  outfile: join(out, "viv.js"),
  jsx: "automatic",
  minify: true,
  define: { "process.env.NODE_ENV": '"production"' },
  logLevel: "warning",
});
copyFileSync(join(here, "index.html"), join(out, "index.html"));
console.log(JSON.stringify({ out }));
