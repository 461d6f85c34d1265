// Builds the studio page into ../beastbt/studio/page/ (run through build.sh: npm ci && npm run build).
// Monaco and its two workers, monaco-yaml, Leaflet and elkjs are bundled with esbuild; every URL in the page is
// relative, so the studio serves it at any path and it needs no network beyond the studio itself.
import * as esbuild from "esbuild";
import { createHash } from "node:crypto";
import { copyFileSync, mkdirSync, readFileSync, readdirSync, rmSync, statSync, writeFileSync } from "node:fs";
import { dirname, join, relative } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = join(here, "..", "beastbt", "studio", "page");

/** Every file the bundle is made from, in a stable order: the lockfile, the build config and src/. */
export function sourceFiles() {
  const files = ["package.json", "package-lock.json", "build.mjs", "tsconfig.json"];
  const walk = (dir) => {
    for (const name of readdirSync(join(here, dir)).sort()) {
      const rel = join(dir, name);
      if (statSync(join(here, rel)).isDirectory()) walk(rel);
      else files.push(rel);
    }
  };
  walk("src");
  return files;
}

/** sha256 over the source files' names and bytes: the same recipe as tests/test_studio_page.py. */
export function sourceHash() {
  const h = createHash("sha256");
  for (const rel of sourceFiles()) {
    h.update(rel.split("\\").join("/") + "\n");
    h.update(readFileSync(join(here, rel)));
    h.update("\n");
  }
  return h.digest("hex");
}

rmSync(out, { recursive: true, force: true });
mkdirSync(out, { recursive: true });

const common = {
  bundle: true,
  metafile: true,
  minify: true,
  legalComments: "none",
  target: "es2020",
  logLevel: "warning",
  loader: { ".ttf": "file", ".png": "file", ".svg": "file" },
  assetNames: "[name]",
};

const bundles = [];
bundles.push(await esbuild.build({
  ...common,
  entryPoints: { studio: join(here, "src", "main.ts") },
  outdir: out,
  format: "iife",
}));
// The page never formats (monaco-yaml's format: false): prettier is left out of the YAML worker.
const noPrettier = {
  name: "no-prettier",
  setup(build) {
    build.onResolve({ filter: /^prettier(\/|$)/ }, () => ({ path: join(here, "src", "stubs", "prettier.ts") }));
  },
};
bundles.push(await esbuild.build({
  ...common,
  entryPoints: {
    "editor.worker": "monaco-editor/esm/vs/editor/editor.worker.js",
    "yaml.worker": join(here, "src", "yaml-worker.ts"),
  },
  outdir: out,
  format: "iife",
  plugins: [noPrettier],
}));
// elkjs ships its worker closure-compiled (smaller than esbuild makes it): copied as it is.
copyFileSync(join(here, "node_modules", "elkjs", "lib", "elk-worker.min.js"), join(out, "elk-worker.js"));
copyFileSync(join(here, "src", "index.html"), join(out, "index.html"));
copyFileSync(join(here, "src", "favicon.svg"), join(out, "favicon.svg"));

// The licences of every package bundled (the bundles carry no comments): one text file beside the page.
const packages = new Set(["elkjs"]);
for (const b of bundles) {
  for (const input of Object.keys(b.metafile.inputs)) {
    const m = /node_modules\/((?:@[^/]+\/)?[^/]+)\//.exec(input);
    if (m) packages.add(m[1]);
  }
}
const notices = [];
for (const name of [...packages].sort()) {
  const dir = join(here, "node_modules", name);
  const meta = JSON.parse(readFileSync(join(dir, "package.json"), "utf8"));
  const file = readdirSync(dir).find((f) => /^(licen[sc]e|copying)(\.|$)/i.test(f));
  const text = file ? readFileSync(join(dir, file), "utf8").trim()
    : `(no licence file; package.json says ${meta.license})`;
  const more = readdirSync(dir).find((f) => /^thirdpartynotices/i.test(f));  // what Monaco itself bundles
  const extra = more ? `\n\n${readFileSync(join(dir, more), "utf8").trim()}` : "";
  notices.push(`${"=".repeat(78)}\n${name} ${meta.version} (${meta.license ?? "see below"})\n${"=".repeat(78)}\n`
    + `${text}${extra}\n`);
}
writeFileSync(join(out, "THIRD_PARTY_LICENSES.txt"),
  "The beastbt studio page bundles these packages (studio-web/package-lock.json has their exact versions).\n\n"
  + notices.join("\n"));

// The JSON Schemas monaco-yaml uses are not copied: the studio serves schemas/NAME.schema.json (and
// schemas/parts/...) from the installed package, the very files validation uses.

const files = {};
for (const name of readdirSync(out).sort()) {
  if (statSync(join(out, name)).isFile()) files[name] = statSync(join(out, name)).size;
}
const info = {
  source_sha256: sourceHash(),
  sources: sourceFiles().map((f) => f.split("\\").join("/")),
  files,
  total_bytes: Object.values(files).reduce((a, b) => a + b, 0),
  rebuild: "studio-web/build.sh",
};
writeFileSync(join(out, "BUILD_INFO.json"), JSON.stringify(info, null, 2) + "\n");
console.log(`built ${relative(process.cwd(), out)}: ${info.total_bytes} bytes in ${Object.keys(files).length} files`);
