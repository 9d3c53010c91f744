// Bundles the page's modules (src/main.js and what it imports: three.js,
// ajv, the job schema, style.css) into one script and one style sheet
// named by their content's hash, and writes index.html naming them:
//
//   OUTDIR/index.html
//   OUTDIR/assets/app-HASH.js, OUTDIR/assets/app-HASH.css
//
//   node build.mjs OUTDIR
//
// The server's build script runs it into its OUT_DIR and embeds the folder;
// the hashed names let the server mark the assets immutable.
import { build } from "esbuild";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { basename, dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = process.argv[2];
if (!out) {
  console.error("usage: node build.mjs OUTDIR");
  process.exit(2);
}
mkdirSync(join(out, "assets"), { recursive: true });
const result = await build({
  entryPoints: { app: join(here, "src", "main.js") },
  bundle: true,
  format: "esm",
  minify: true,
  target: "es2022",
  legalComments: "eof",
  outdir: join(out, "assets"),
  entryNames: "[name]-[hash]",
  metafile: true,
  logLevel: "warning",
});
const outputs = Object.keys(result.metafile.outputs).map((p) => basename(p));
const pick = (ext) => {
  const name = outputs.find((n) => n.endsWith(ext));
  if (!name) throw new Error(`esbuild wrote no ${ext} file`);
  return name;
};
const html = readFileSync(join(here, "src", "index.html"), "utf8")
  .replaceAll("{{app.js}}", `assets/${pick(".js")}`)
  .replaceAll("{{app.css}}", `assets/${pick(".css")}`);
writeFileSync(join(out, "index.html"), html);
