// Builds the viewer: protobufjs static code from protocol/idms.proto (so the schema has one
// source), then one esbuild bundle (JS + CSS) and index.html into the output directory that
// idms-server serves (--web-root; CMake writes build/web), with the favicon.
//   node build.mjs OUT_DIR [--dev]
import { execFileSync } from 'node:child_process';
import { copyFileSync, mkdirSync, statSync, existsSync, utimesSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
if (!existsSync(join(here, 'node_modules', 'esbuild'))) {
  console.error('viewer-web/node_modules is missing: run scripts/install-deps.sh (npm ci in viewer-web)');
  process.exit(1);
}
const esbuild = await import('esbuild');
const [, , outDir, flag] = process.argv;
if (!outDir) {
  console.error('usage: node build.mjs OUT_DIR [--dev]');
  process.exit(2);
}
const proto = join(here, '..', 'protocol', 'idms.proto');
const gen = join(here, 'src', 'gen');
const bin = (name) => join(here, 'node_modules', '.bin', name);
const newer = (a, b) => !existsSync(b) || statSync(a).mtimeMs > statSync(b).mtimeMs;

// 1. Messages: static code and its types, regenerated when the .proto changed.
mkdirSync(gen, { recursive: true });
const js = join(gen, 'idms_pb.js');
if (newer(proto, js) || newer(proto, join(gen, 'idms_pb.d.ts'))) {
  execFileSync(bin('pbjs'), ['-t', 'static-module', '-w', 'es6', '--force-number', '--no-create', '--no-verify',
    '--no-convert', '--no-delimited', '--no-service', '-o', js, proto], { stdio: 'inherit' });
  execFileSync(bin('pbts'), ['-o', join(gen, 'idms_pb.d.ts'), js], { stdio: 'inherit' });
}
// They are outputs of this step for CMake: newer than its inputs, or it would run every time.
const now = new Date();
for (const f of ['idms_pb.js', 'idms_pb.d.ts']) utimesSync(join(gen, f), now, now);

// 2. The bundle: ES2020 for current browsers, minified, with a source map.
mkdirSync(join(outDir, 'assets'), { recursive: true });
await esbuild.build({
  entryPoints: { app: join(here, 'src', 'main.js') },
  outdir: join(outDir, 'assets'),
  bundle: true,
  format: 'esm',
  target: 'es2020',
  minify: flag !== '--dev',
  sourcemap: true,
  logLevel: 'warning',
  legalComments: 'linked',
});
copyFileSync(join(here, 'index.html'), join(outDir, 'index.html'));
// The tab's icon (a page without one makes the browser ask for /favicon.ico: a 404 on every page).
copyFileSync(join(here, 'favicon.svg'), join(outDir, 'assets', 'favicon.svg'));
console.log(`viewer-web: built ${outDir}`);
