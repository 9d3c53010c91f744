// Bundles the page's modules (src/main.js and what it imports: three.js,
// ajv, the job schema, style.css) into one script and one style sheet
// named by their content's hash, and writes index.html naming them:
//
//   OUTDIR/index.html
//   OUTDIR/assets/app-HASH.js, OUTDIR/assets/app-HASH.css
//   OUTDIR/assets/basis-HASH/basis_transcoder.{js,wasm}
//
// The Basis Universal transcoder (three.js's copy, which its KTX2Loader
// loads by these fixed names from a folder) decodes KTX2 impostor atlases
// in the viewer; its folder is named by the hash of both files and the
// bundle is told the folder (BASIS_PATH). Draco's decoder (three.js's copy,
// for its DRACOLoader: scenes with KHR_draco_mesh_compression) likewise
// (OUTDIR/assets/draco-HASH/, DRACO_PATH).
//
//   node build.mjs OUTDIR
//
// The server's build script runs it into its OUT_DIR and embeds the folder;
// the hashed names let the server mark the assets immutable.
import { build } from "esbuild";
import { createHash } from "node:crypto";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { dirname, extname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = process.argv[2];
if (!out) {
  console.error("usage: node build.mjs OUTDIR");
  process.exit(2);
}
mkdirSync(join(out, "assets"), { recursive: true });
/// Copies three.js's decoder files `names` from its `libs/LIB` into
/// `assets/LIB-HASH/` (the hash of the files); returns that folder.
function decoderFolder(lib, names) {
  const from = join(here, "node_modules", "three", "examples", "jsm", "libs", lib);
  const files = names.map((name) => [name, readFileSync(join(from, name))]);
  const hash = createHash("sha256");
  for (const [, data] of files) hash.update(data);
  const dir = `assets/${lib}-${hash.digest("hex").slice(0, 16)}/`;
  mkdirSync(join(out, dir), { recursive: true });
  for (const [name, data] of files) writeFileSync(join(out, dir, name), data);
  return dir;
}
const basisDir = decoderFolder("basis", ["basis_transcoder.js", "basis_transcoder.wasm"]);
const dracoDir = decoderFolder("draco", ["draco_wasm_wrapper.js", "draco_decoder.wasm"]);
const result = await build({
  entryPoints: { app: join(here, "src", "main.js") },
  bundle: true,
  format: "esm",
  minify: true,
  target: "es2022",
  legalComments: "eof",
  outdir: "bundle",
  write: false,
  logLevel: "warning",
  define: { BASIS_PATH: JSON.stringify(basisDir), DRACO_PATH: JSON.stringify(dracoDir) },
});
// Named by a hash of their content alone (esbuild's [hash] also depends on
// where the output goes), so a checkout builds the same names anywhere.
const names = {};
for (const file of result.outputFiles) {
  const ext = extname(file.path);
  const hash = createHash("sha256").update(file.contents).digest("hex").slice(0, 16);
  names[ext] = `assets/app-${hash}${ext}`;
  writeFileSync(join(out, names[ext]), file.contents);
}
for (const ext of [".js", ".css"]) {
  if (!names[ext]) throw new Error(`esbuild wrote no ${ext} file`);
}
const html = readFileSync(join(here, "src", "index.html"), "utf8")
  .replaceAll("{{app.js}}", names[".js"])
  .replaceAll("{{app.css}}", names[".css"]);
writeFileSync(join(out, "index.html"), html);
