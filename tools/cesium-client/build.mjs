// Bundles the CesiumJS test client (src/main.js with @cesium/engine) into
// one script beside a copy of its page:
//
//   OUTDIR/index.html, OUTDIR/cesium-client.js
//
//   node build.mjs [OUTDIR]        (default: dist, beside this file)
//
// Both are plain top-level names: a static server that serves the page, the
// script and the tileset from one origin needs no sub-folders. The page sets
// CESIUM_BASE_URL to its own folder, where CesiumJS would look for its
// run-time files (Workers/, Assets/, ThirdParty/ of @cesium/engine). None is
// copied: loading plain glTF/GLB tile content (uncompressed, PNG/JPEG
// textures) with no globe, imagery, terrain, sky or credits fetches none of
// them. Only Draco, KTX2, Gaussian splats, vector or terrain content would
// start a web worker from Workers/ (and its wasm from ThirdParty/); the
// Earth's sky, moon and credits logo would load images from Assets/.
//
// tools/test.sh runs it after `npm ci`; a test may run it again into its
// own folder, so the page it serves is never stale.
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
  minify: true,
  legalComments: "eof",
  outfile: join(out, "cesium-client.js"),
  logLevel: "warning",
});
copyFileSync(join(here, "src", "index.html"), join(out, "index.html"));
