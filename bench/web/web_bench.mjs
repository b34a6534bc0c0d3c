// The browser viewer's bench: for 10^3, 10^4 and 10^5 surface vertices streamed at 60 Hz (frames
// from protocol/'s C++ encoder), the page's own JavaScript per frame (decode, apply, normals,
// plots) and its frame rate, beside a bare three.js page drawing the same mesh at the same size,
// in Debian's headless chromium (software WebGL). Prints figures; never fails on time.
//   node bench/web/web_bench.mjs BUILD_DIR [--seconds S]
// IDMS_WEB_BENCH_BREAKDOWN=1 adds the viewer page without its buffer uploads and without plots.
import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const root = join(here, '..', '..');
const build = process.argv[2];
const seconds = process.argv[3] === '--seconds' ? Number(process.argv[4]) : 6;
if (!build) {
  console.error('usage: node bench/web/web_bench.mjs BUILD_DIR [--seconds S]');
  process.exit(2);
}
const esbuild = await import(join(root, 'viewer-web', 'node_modules', 'esbuild', 'lib', 'main.js'));
const { chromium } = await import(join(root, 'tests', 'web', 'node_modules', 'playwright-core', 'index.mjs'));

// The page bundle (the viewer's own modules, as the viewer bundles them).
const out = mkdtempSync(join(tmpdir(), 'idms-web-bench-'));
await esbuild.build({ entryPoints: [join(here, 'page.js')], outdir: out, bundle: true, format: 'esm', minify: true,
  target: 'es2020', nodePaths: [join(root, 'viewer-web', 'node_modules')], logLevel: 'warning' });

const sizes = [[40, 25], [100, 100], [400, 250]];
/** @type {Record<string, Buffer>} */
const files = {};
const server = createServer((req, res) => {
  const path = (req.url ?? '/').split('?')[0];
  const body = path === '/' ? readFileSync(join(here, 'index.html')) : path === '/frames.bin' ? files.frames
    : path === '/page.js' ? readFileSync(join(out, 'page.js')) : path === '/page.css' ? readFileSync(join(out, 'page.css')) : null;
  if (!body) { res.writeHead(404).end(); return; }
  const type = path.endsWith('.js') ? 'text/javascript' : path.endsWith('.css') ? 'text/css' : path === '/' ? 'text/html' : 'application/octet-stream';
  res.writeHead(200, { 'Content-Type': type }).end(body);
});
await new Promise((r) => server.listen(0, '127.0.0.1', () => r(undefined)));
const port = /** @type {import('node:net').AddressInfo} */ (server.address()).port;

const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--headless', '--no-sandbox', '--disable-background-networking', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
/** @param {string} hash */
async function run(hash) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
  await page.goto(`http://127.0.0.1:${port}/${hash}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__bench || /** @type {any} */ (window).__benchError, undefined, { timeout: 120000 });
  const err = await page.evaluate(() => /** @type {any} */ (window).__benchError);
  if (err) throw new Error(err);
  await page.waitForTimeout(1500);  // warm-up: the plots' window and the GPU buffers fill
  const a = await page.evaluate(() => ({ ...(/** @type {any} */ (window).__bench), now: performance.now() }));
  await page.waitForTimeout(seconds * 1000);
  const b = await page.evaluate(() => ({ ...(/** @type {any} */ (window).__bench), now: performance.now() }));
  await page.close();
  const wall = (b.now - a.now) / 1000;
  if (b.gaps) throw new Error(`${hash || 'viewer'}: ${b.gaps} mesh frames were gaps: the page drew nothing for them`);
  return { fps: (b.renders - a.renders) / wall, frames: (b.frames ?? 0) - (a.frames ?? 0),
    jsMs: ((b.jsMs ?? 0) - (a.jsMs ?? 0)) / Math.max(1, (b.frames ?? 0) - (a.frames ?? 0)),
    changed: ((b.changed ?? 0) - (a.changed ?? 0)) / Math.max(1, (b.frames ?? 0) - (a.frames ?? 0)), wall };
}

console.log(`idms web bench: headless chromium ${browser.version()}, 1280x720, ${seconds} s per point, frames at 60 Hz`);
console.log('vertices  triangles  moved/frame  frames/s in  page JS ms/frame  page fps  bare fps  page/bare');
for (const [nx, ny] of sizes) {
  const file = join(out, `frames-${nx}x${ny}.bin`);
  execFileSync(join(build, 'bin', 'idms-web-mesh-frames'), ['--sheet', String(nx), String(ny), '240', file]);
  files.frames = readFileSync(file);
  const viewer = await run('');
  const noPlots = process.env.IDMS_WEB_BENCH_BREAKDOWN ? await run('#noplots') : null;
  const noUpload = process.env.IDMS_WEB_BENCH_BREAKDOWN ? await run('#noupload') : null;
  if (noUpload) console.log(`  no upload: page JS ${noUpload.jsMs.toFixed(3)} ms/frame, ${noUpload.fps.toFixed(1)} fps`);
  if (noPlots) console.log(`  without plots: page JS ${noPlots.jsMs.toFixed(3)} ms/frame, ${noPlots.fps.toFixed(1)} fps`);
  const bare = await run('#bare');
  const tris = 2 * (nx - 1) * (ny - 1);
  console.log(`${String(nx * ny).padStart(8)}  ${String(tris).padStart(9)}  ${viewer.changed.toFixed(0).padStart(11)}  ` +
    `${(viewer.frames / viewer.wall).toFixed(1).padStart(11)}  ${viewer.jsMs.toFixed(3).padStart(16)}  ` +
    `${viewer.fps.toFixed(1).padStart(8)}  ${bare.fps.toFixed(1).padStart(8)}  ${(viewer.fps / bare.fps).toFixed(2).padStart(9)}`);
}
await browser.close();
server.close();
