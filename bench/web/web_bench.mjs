// The browser viewer's bench: for 10^3, 10^4 and 10^5 surface vertices streamed at 60 Hz (frames
// from protocol/'s C++ encoder, with 17 device samples each), the live view's own JavaScript per
// frame (decode, apply, normals, plots) and its frame rate, beside a bare three.js page drawing
// the same mesh in a canvas of the same size with the same renderer settings (page.js says what
// each page holds), in Debian's headless chromium (software WebGL). The two pages alternate, RUNS
// times each per size, and the medians are printed with the load average: this machine is
// shared, and its frame rates swing by a third from one run to the next; so it also prints the
// CPU time the browser's processes spent per frame drawn (from /proc), which load moves less.
// Never fails on time.
//   node bench/web/web_bench.mjs BUILD_DIR [--seconds S] [--warmup S] [--runs N] [--vertices 1000,10000,100000]
//     [--variants "page bare still,notool ..."]
// --variants runs the named variants of the two pages in turn instead (page.js lists the switches:
// a part of the page switched off, or one more draw on the bare page), and prints each one's frame
// rate and CPU per frame drawn, and its frame rate against the last variant's round by round: how
// a part's cost is found.
import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { loadavg, tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const root = join(here, '..', '..');
const build = process.argv[2];
/** @param {string} name @param {number} fallback */
const option = (name, fallback) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? Number(process.argv[i + 1]) : fallback;
};
const seconds = option('--seconds', 6);
// Each page runs this long before it is measured. The live view's JavaScript is still being
// optimised by V8 for 10-15 s after the stream starts (a trace at 10^4: TurboFan's background
// compiles 1.0-1.2 ms of CPU per frame drawn 2-12 s in, none 15-19 s in, and the page's own
// JavaScript on its main thread 30% slower meanwhile); an instructor watches for minutes, so the
// bench measures the page as it runs then, not its first seconds. The bare page has no JavaScript
// to speak of; it gets the same warm-up.
const warmup = option('--warmup', 15);
const runs = option('--runs', 3);
const only = process.argv.includes('--vertices') ? process.argv[process.argv.indexOf('--vertices') + 1].split(',').map(Number) : null;
const variants = process.argv.includes('--variants') ? process.argv[process.argv.indexOf('--variants') + 1].split(/\s+/).filter(Boolean) : null;
if (!build || !(seconds > 0) || !(warmup >= 0) || !(runs >= 1)) {
  console.error('usage: node bench/web/web_bench.mjs BUILD_DIR [--seconds S] [--warmup S] [--runs N] [--vertices 1000,10000,100000] [--variants "page bare ..."]');
  process.exit(2);
}
const esbuild = await import(join(root, 'viewer-web', 'node_modules', 'esbuild', 'lib', 'main.js'));
const { chromium } = await import(join(root, 'tests', 'web', 'node_modules', 'playwright-core', 'index.mjs'));

// The page bundle (the viewer's own modules, as the viewer bundles them).
const out = mkdtempSync(join(tmpdir(), 'idms-web-bench-'));
// Removed however the bench ends (a failed run too).
process.on('exit', () => rmSync(out, { recursive: true, force: true }));
await esbuild.build({ entryPoints: [join(here, 'page.js')], outdir: out, bundle: true, format: 'esm', minify: true,
  target: 'es2020', nodePaths: [join(root, 'viewer-web', 'node_modules')], logLevel: 'warning' });

const sizes = [[40, 25], [100, 100], [400, 250]].filter(([nx, ny]) => !only || only.includes(nx * ny));
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

// A switch chromium ignores, to find its process tree in /proc.
const tag = `--idms-web-bench=${process.pid}`;
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--headless', '--no-sandbox', '--disable-background-networking', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', tag] });
const ticksPerS = 100;  // USER_HZ

/** CPU seconds (user + system) of each of the browser's processes so far, with its --type (renderer, gpu-process, ...). */
function browserCpu() {
  /** @type {{pid: number, ppid: number, s: number, type: string, root: boolean}[]} */
  const procs = [];
  for (const d of readdirSync('/proc')) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const stat = readFileSync(`/proc/${d}/stat`, 'utf8');
      const f = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
      const cmd = readFileSync(`/proc/${d}/cmdline`, 'utf8');
      const type = /--type=([a-z-]+)/.exec(cmd)?.[1] ?? 'browser';
      procs.push({ pid: Number(d), ppid: Number(f[1]), s: (Number(f[11]) + Number(f[12])) / ticksPerS, type, root: cmd.includes(tag) && type === 'browser' });
    } catch {
      // gone meanwhile
    }
  }
  const tree = new Set(procs.filter((p) => p.root).map((p) => p.pid));
  for (let grew = true; grew;) {
    grew = false;
    for (const p of procs) {
      if (tree.has(p.pid) || !tree.has(p.ppid)) continue;
      tree.add(p.pid);
      grew = true;
    }
  }
  /** @type {Map<number, {type: string, s: number}>} */
  const out = new Map();
  for (const p of procs) if (tree.has(p.pid)) out.set(p.pid, { type: p.type, s: p.s });
  return out;
}

/**
 * CPU seconds by process type between two snapshots, process by process: one that exited
 * meanwhile (the previous page's renderer, closing) counts nothing, where subtracting totals by
 * type took its whole life off the run's figure; one that started counts from zero.
 * @param {ReturnType<typeof browserCpu>} a @param {ReturnType<typeof browserCpu>} b
 */
function cpuBetween(a, b) {
  /** @type {Record<string, number>} */
  const out = {};
  for (const [pid, p] of b) out[p.type] = (out[p.type] ?? 0) + p.s - (a.get(pid)?.s ?? 0);
  return out;
}
/** @param {string} hash '' for the live view, '#bare' for three.js alone, '#switch,switch' for a variant */
async function run(hash) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
  // The page encodes the device samples of the whole run before it starts (warm-up included).
  await page.goto(`http://127.0.0.1:${port}/?seconds=${warmup + seconds}${hash}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__bench || /** @type {any} */ (window).__benchError, undefined, { timeout: 120000 });
  const err = await page.evaluate(() => /** @type {any} */ (window).__benchError);
  if (err) throw new Error(err);
  await page.waitForTimeout(1000 * warmup);  // V8's optimising compilers done; the plots' window and the GPU buffers full
  const cpu0 = browserCpu();
  const a = await page.evaluate(() => ({ ...(/** @type {any} */ (window).__bench), now: performance.now() }));
  await page.waitForTimeout(seconds * 1000);
  const b = await page.evaluate(() => ({ ...(/** @type {any} */ (window).__bench), now: performance.now() }));
  const cpu1 = browserCpu();
  await page.close();
  const wall = (b.now - a.now) / 1000;
  const used = cpuBetween(cpu0, cpu1);
  if (b.gaps) throw new Error(`${hash || 'page'}: ${b.gaps} mesh frames were gaps or invalid: the page drew nothing for them`);
  const frames = (b.frames ?? 0) - (a.frames ?? 0);
  const renders = b.renders - a.renders;
  return { fps: renders / wall, frames, wall, jsMs: ((b.jsMs ?? 0) - (a.jsMs ?? 0)) / Math.max(1, frames),
    changed: ((b.changed ?? 0) - (a.changed ?? 0)) / Math.max(1, frames), calls: (b.calls - a.calls) / Math.max(1, renders),
    // CPU per frame drawn, ms: the page's renderer process and the GPU process (SwiftShader).
    rendererMs: 1000 * (used.renderer ?? 0) / Math.max(1, renders),
    gpuMs: 1000 * (used['gpu-process'] ?? 0) / Math.max(1, renders),
    canvas: b.canvas, pixelRatio: b.pixelRatio, antialias: b.antialias };
}

/** @param {number[]} xs */
const median = (xs) => {
  const s = [...xs].sort((x, y) => x - y);
  return s.length % 2 ? s[(s.length - 1) / 2] : (s[s.length / 2 - 1] + s[s.length / 2]) / 2;
};
const load = () => loadavg().map((x) => x.toFixed(2)).join(' ');

console.log(`idms web bench: headless chromium ${browser.version()} (SwiftShader), 1280x720 window, ${seconds} s per run after ${warmup} s of warm-up, ` +
  `${runs} alternating runs per page and size, frames at 60 Hz, load average ${load()}`);
console.log('page: the live view (3D view with tool and force arrow, force/position/depth plots, loop health) fed mesh frames + 17 samples at 60 Hz');
console.log('bare: three.js alone, the same mesh held still, the same lights, material, antialias and pixel ratio, a render every animation frame');
let described = false;
console.log('vertices  triangles  moved/frame  frames/s in  page JS ms/frame  page fps (runs)        bare fps (runs)        median page/bare');
for (const [nx, ny] of sizes) {
  const file = join(out, `frames-${nx}x${ny}.bin`);
  execFileSync(join(build, 'bin', 'idms-web-mesh-frames'), ['--sheet', String(nx), String(ny), '240', file]);
  files.frames = readFileSync(file);
  /** @type {Awaited<ReturnType<typeof run>>[]} */
  const viewer = [];
  /** @type {Awaited<ReturnType<typeof run>>[]} */
  const bare = [];
  if (variants) {
    // In turn, as the two pages alternate.
    /** @type {Awaited<ReturnType<typeof run>>[][]} */
    const results = variants.map(() => []);
    for (let r = 0; r < runs; r++) {
      for (let v = 0; v < variants.length; v++) results[v].push(await run(variants[v] === 'page' ? '' : `#${variants[v]}`));
    }
    for (let v = 0; v < variants.length; v++) {
      const xs = results[v];
      const r = median(xs.map((x) => x.rendererMs)), g = median(xs.map((x) => x.gpuMs));
      console.log(`  ${variants[v].padEnd(22)} fps ${median(xs.map((x) => x.fps)).toFixed(1).padStart(5)} (${xs.map((x) => x.fps.toFixed(1)).join(' ')}), ` +
        `CPU ms per frame drawn ${(r + g).toFixed(1)} (renderer ${r.toFixed(1)} + GPU process ${g.toFixed(1)}), draw calls ${median(xs.map((x) => x.calls)).toFixed(1)}`);
    }
    // Each variant against the last one named, round by round (runs taken minutes apart differ by
    // more than most parts cost).
    const last = results[variants.length - 1];
    for (let v = 0; v < variants.length - 1; v++) {
      const ratios = results[v].map((x, r) => x.fps / last[r].fps);
      console.log(`  ${variants[v]} / ${variants[variants.length - 1]} fps per round: median ${median(ratios).toFixed(2)} (in order: ${ratios.map((x) => x.toFixed(2)).join(' ')})`);
    }
    console.log(`  load average ${load()}`);
    continue;
  }
  // Alternating, so that a change in the machine's load falls on both.
  for (let r = 0; r < runs; r++) {
    viewer.push(await run(''));
    bare.push(await run('#bare'));
  }
  if (!described) {
    const [v, b] = [viewer[0], bare[0]];
    console.log(`  canvas: page ${v.canvas} (pixel ratio ${v.pixelRatio}, antialias ${v.antialias}), ` +
      `bare ${b.canvas} (pixel ratio ${b.pixelRatio}, antialias ${b.antialias})`);
    described = true;
  }
  const tris = 2 * (nx - 1) * (ny - 1);
  const pageFps = median(viewer.map((x) => x.fps));
  const bareFps = median(bare.map((x) => x.fps));
  const list = (/** @type {{fps: number}[]} */ xs) => xs.map((x) => x.fps.toFixed(1)).join(' ');
  console.log(`${String(nx * ny).padStart(8)}  ${String(tris).padStart(9)}  ${median(viewer.map((x) => x.changed)).toFixed(0).padStart(11)}  ` +
    `${median(viewer.map((x) => x.frames / x.wall)).toFixed(1).padStart(11)}  ${median(viewer.map((x) => x.jsMs)).toFixed(3).padStart(16)}  ` +
    `${pageFps.toFixed(1).padStart(5)} (${list(viewer)})`.padEnd(23) + `${bareFps.toFixed(1).padStart(5)} (${list(bare)})`.padEnd(23) +
    `${(pageFps / bareFps).toFixed(2).padStart(6)}`);
  /** @param {Awaited<ReturnType<typeof run>>[]} xs */
  const cpu = (xs) => {
    const r = median(xs.map((x) => x.rendererMs)), g = median(xs.map((x) => x.gpuMs));
    return { text: `${(r + g).toFixed(1)} (renderer ${r.toFixed(1)} + GPU process ${g.toFixed(1)})`, total: r + g };
  };
  // Each round's two runs were taken back to back: their ratio leaves out the load's slower
  // swings, which move both. Its median and quartiles over the rounds (a spread the ratio of the
  // medians above does not show).
  const ratios = viewer.map((v, r) => v.fps / bare[r].fps);
  const rounds = [...ratios].sort((x, y) => x - y);
  const quartile = (/** @type {number} */ q) => rounds[Math.round(q * (rounds.length - 1))];
  console.log(`  page/bare per round: median ${median(rounds).toFixed(2)}, quartiles ${quartile(0.25).toFixed(2)}-${quartile(0.75).toFixed(2)}, ` +
    `${rounds.filter((x) => x >= 0.9).length} of ${rounds.length} rounds at 0.90 or more (in order: ${ratios.map((x) => x.toFixed(2)).join(' ')})`);
  const [cv, cb] = [cpu(viewer), cpu(bare)];
  console.log(`  CPU ms per frame drawn: page ${cv.text}, bare ${cb.text}, bare/page ${(cb.total / cv.total).toFixed(2)}`);
  console.log(`  draw calls per render: page ${median(viewer.map((x) => x.calls)).toFixed(1)}, bare ${median(bare.map((x) => x.calls)).toFixed(1)}; load average ${load()}`);
}
await browser.close();
server.close();
