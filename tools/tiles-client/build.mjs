// Bundles the test client (src/main.js with three.js and 3d-tiles-renderer)
// into one script beside a copy of its page:
//
//   OUTDIR/index.html, OUTDIR/tiles-client.js
//
//   node build.mjs [OUTDIR]        (default: dist, beside this file)
//
// tools/test.sh runs it after `npm ci`; server/tests/tiles_client.rs runs it
// again into its own folder, so the page it serves is never stale.
import { build } from "esbuild";
import { copyFileSync, mkdirSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = resolve(process.argv[2] ?? join(here, "dist"));
mkdirSync(out, { recursive: true });
await build({
  entryPoints: [join(here, "src", "main.js")],
  bundle: true,
  format: "esm",
  target: "es2022",
  legalComments: "eof",
  outfile: join(out, "tiles-client.js"),
  logLevel: "warning",
});
copyFileSync(join(here, "src", "index.html"), join(out, "index.html"));
