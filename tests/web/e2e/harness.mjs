// What the end-to-end tests share: the real idms-server (a free loopback port, its own data
// directory), the real idms-agent publishing a scripted session, Debian's chromium through
// playwright-core with a fresh profile, the login, and screenshots kept under build/.
import { spawn } from 'node:child_process';
import { copyFileSync, mkdirSync, mkdtempSync, readFileSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const env = (/** @type {string} */ name) => {
  const v = process.env[name];
  if (!v) throw new Error(`${name} is not set (ctest sets it; see tests/web/CMakeLists.txt)`);
  return v;
};
export const serverBin = () => env('IDMS_SERVER_BIN');
export const agentBin = () => env('IDMS_AGENT_BIN');
export const sourceDir = () => env('IDMS_SOURCE_DIR');
export const artifacts = () => {
  const dir = env('IDMS_WEB_ARTIFACTS');
  mkdirSync(dir, { recursive: true });
  return dir;
};

/** A temporary directory for one test. @param {string} name */
export const tempDir = (name) => mkdtempSync(join(tmpdir(), `idms-web-${name}-`));

export class Server {
  /** @param {string} dataDir */
  constructor(dataDir) {
    this.dataDir = dataDir;
    this.port = 0;
    /** @type {import('node:child_process').ChildProcess | null} */
    this.child = null;
    this.log = '';
  }

  /** Starts idms-server (port 0 the first time, the same port after a restart); resolves when it listens. */
  async start() {
    const args = ['--data', this.dataDir, '--listen', `127.0.0.1:${this.port}`, '--web-root', env('IDMS_WEB_ROOT'), '--threads', '2'];
    const child = spawn(serverBin(), args, { stdio: ['ignore', 'pipe', 'pipe'] });
    this.child = child;
    child.stderr.on('data', (d) => { this.log += d; });
    const lines = createInterface({ input: child.stdout });
    const first = await new Promise((resolve, reject) => {
      const timer = setTimeout(() => reject(new Error(`idms-server did not start:\n${this.log}`)), 60000);
      lines.once('line', (l) => { clearTimeout(timer); resolve(l); });
      child.once('exit', (code) => { clearTimeout(timer); reject(new Error(`idms-server exited ${code}:\n${this.log}`)); });
    });
    // "idms-server listening on http://127.0.0.1:PORT"
    const m = /:(\d+)$/.exec(String(first));
    if (!m) throw new Error(`unexpected first line: ${first}`);
    this.port = Number(m[1]);
    return this;
  }

  get base() { return `http://127.0.0.1:${this.port}`; }

  /** @param {string} role admin | agent | observer */
  token(role) {
    for (const line of readFileSync(join(this.dataDir, 'tokens'), 'utf8').split('\n')) {
      const [r, t] = line.trim().split(/\s+/);
      if (r === role) return t;
    }
    throw new Error(`no ${role} token`);
  }

  /** SIGTERM, and the exit. */
  async stop() {
    const child = this.child;
    if (!child || child.exitCode !== null) return;
    const exited = new Promise((resolve) => child.once('exit', resolve));
    child.kill('SIGTERM');
    await exited;
    this.child = null;
  }

  /** A REST call with a bearer token. @param {string} path @param {string} role */
  async get(path, role = 'admin') {
    const res = await fetch(this.base + path, { headers: { Authorization: `Bearer ${this.token(role)}` } });
    return { status: res.status, headers: res.headers, body: await res.text() };
  }

  /** The id of the first live session, once there is one. */
  async liveSession(timeoutMs = 60000) {
    const deadline = Date.now() + timeoutMs;
    while (Date.now() < deadline) {
      const { body } = await this.get('/api/sessions');
      const live = JSON.parse(body).sessions.find((/** @type {any} */ s) => s.state === 'live');
      if (live) return String(live.id);
      await new Promise((r) => setTimeout(r, 100));
    }
    throw new Error('no live session');
  }
}

/**
 * The real agent publishing a scripted palpation of a shipped model (`model`, the hex fragment
 * unless named): its files, or with `library` the server's library's copy by name (downloaded, as a
 * deployed agent does), or `modelFile`, a prefix of its own; `args`: more of the agent's options
 * (--trainee NAME, --max-force F, --scene FILE).
 * @param {Server} server @param {number} durationS @param {string} [device]
 * @param {{library?: boolean, model?: string, modelFile?: string, args?: string[]}} [options]
 */
export function startAgent(server, durationS, device = 'scripted:palpate', options = {}) {
  const name = options.model ?? 'hex_4x5_home';
  const model = options.library ? ['--model', name, '--cache-dir', tempDir('agent-cache')]
    : ['--model-file', options.modelFile ?? join(sourceDir(), 'models', name)];
  const child = spawn(agentBin(), ['--server', `ws://127.0.0.1:${server.port}`, '--token', server.token('agent'),
    ...model, '--device', device, '--no-realtime', '--duration', String(durationS), ...(options.args ?? [])],
  { stdio: ['ignore', 'ignore', 'pipe'] });
  let log = '';
  child.stderr.on('data', (d) => { log += d; });
  const exited = new Promise((resolve) => child.once('exit', (code) => resolve(code)));
  return { child, exited, log: () => log, kill: () => child.exitCode === null && child.kill('SIGTERM') };
}

/** Debian's chromium, headless, with a fresh profile; WebGL through SwiftShader. */
export async function launchBrowser() {
  const context = await chromium.launchPersistentContext(tempDir('profile'), {
    executablePath: '/usr/bin/chromium',
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-background-networking', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
    viewport: { width: 1280, height: 720 },
  });
  const page = context.pages()[0] ?? (await context.newPage());
  /** @type {string[]} */
  const errors = [];
  context.on('weberror', (e) => errors.push(String(e.error())));
  return { context, page, errors };
}

/**
 * Logs in through /login, as a visitor would.
 * @param {import('playwright-core').Page} page @param {Server} server @param {string} role @param {string} [next]
 */
export async function login(page, server, role, next = '/sessions') {
  await page.goto(`${server.base}/login?next=${encodeURIComponent(next)}`);
  await page.fill('#token', server.token(role));
  await Promise.all([page.waitForURL((u) => u.pathname === next), page.click('button[type=submit]')]);
}

/**
 * A screenshot kept under build/web-artifacts, and copied to docs/web (the README shows them) when
 * IDMS_UPDATE_DOCS is set: a test run does not rewrite tracked files.
 * @param {import('playwright-core').Page | import('playwright-core').Locator} page @param {string} name
 */
/** Two animation frames: what changed is drawn and composited. @param {import('playwright-core').Page} page */
export const frames = (page) => page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r(null)))));

/** What the session page's 3-D view shows (its __idmsSurface). @param {import('playwright-core').Page} page @returns {Promise<any>} */
export const surface = (page) => page.evaluate(() => /** @type {any} */ (window).__idmsSurface());

export async function docShot(page, name) {
  await shot(page, name);
  if (!process.env.IDMS_UPDATE_DOCS) return;
  mkdirSync(join(sourceDir(), 'docs', 'web'), { recursive: true });
  copyFileSync(join(artifacts(), name), join(sourceDir(), 'docs', 'web', name));
}

/** A screenshot kept under build/web-artifacts. @param {import('playwright-core').Page | import('playwright-core').Locator} target @param {string} name */
export async function shot(target, name) {
  const buffer = await target.screenshot();
  writeFileSync(join(artifacts(), name), buffer);
  return buffer;
}

/**
 * A PNG's pixels, decoded by the browser in a blank page of the same context (no Content-Security-
 * Policy there): RGBA rows, top first.
 * @param {import('playwright-core').BrowserContext} context @param {Buffer} png
 * @returns {Promise<{width: number, height: number, data: Uint8Array}>}
 */
export async function decodePng(context, png) {
  const blank = await context.newPage();
  try {
    const { width, height, data } = await blank.evaluate(async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width;
      c.height = img.height;
      const ctx = /** @type {CanvasRenderingContext2D} */ (c.getContext('2d'));
      ctx.drawImage(img, 0, 0);
      const pixels = ctx.getImageData(0, 0, c.width, c.height).data;
      let text = '';
      for (let i = 0; i < pixels.length; i += 8192) text += String.fromCharCode(...pixels.subarray(i, i + 8192));
      return { width: c.width, height: c.height, data: btoa(text) };
    }, png.toString('base64'));
    return { width, height, data: new Uint8Array(Buffer.from(data, 'base64')) };
  } finally {
    await blank.close();
  }
}

// protocol/display.json's suture colours: the thread #4b1d8f (a 1-pixel line, antialiased: its hue,
// blue well above red and green, not its exact value), the punctures #f2a900 (squares: the value).
const isThread = (/** @type {number[]} */ c) => c[2] > c[0] + 25 && c[2] > c[1] + 40;
const isPuncture = (/** @type {number[]} */ c) => Math.abs(c[0] - 0xf2) < 24 && Math.abs(c[1] - 0xa9) < 24 && c[2] < 40;

/**
 * A suture thread as the compositor drew it (the stitch's and the suture's tests): the screenshot
 * of the view, the share of the thread's nodes on the canvas with the thread's colour (or a
 * puncture's) within 2 pixels, and for each puncture whether its colour is within 4.
 * @param {import('playwright-core').BrowserContext} context @param {import('playwright-core').Page} page
 * @param {string} name the screenshot's file
 */
export async function threadOnCanvas(context, page, name) {
  const s = await surface(page);
  const png = await shot(page.locator('#view3d canvas'), name);
  const img = await decodePng(context, png);
  const pixel = (/** @type {number} */ x, /** @type {number} */ y) => {
    const i = 4 * (Math.round(y) * img.width + Math.round(x));
    return [img.data[i], img.data[i + 1], img.data[i + 2]];
  };
  const within = (/** @type {{x: number, y: number}} */ p, /** @type {(c: number[]) => boolean} */ is, /** @type {number} */ r) => {
    for (let dy = -r; dy <= r; dy++) {
      for (let dx = -r; dx <= r; dx++) {
        const x = p.x + dx, y = p.y + dy;
        if (x >= 0 && y >= 0 && x < img.width && y < img.height && is(pixel(x, y))) return true;
      }
    }
    return false;
  };
  const pts = await page.evaluate(() => /** @type {any} */ (window).__idmsSuturePoints());
  /** @param {number[]} p */
  const project = (p) => page.evaluate(([x, y, z]) => /** @type {any} */ (window).__idmsProject(x, y, z), p);
  let on = 0, total = 0;
  for (const n of pts.nodes) {
    const q = await project(n);
    if (q.x < 3 || q.y < 3 || q.x > img.width - 4 || q.y > img.height - 4) continue;
    total++;
    if (within(q, isThread, 2) || within(q, isPuncture, 2)) on++;
  }
  /** @type {boolean[]} */
  const holes = [];
  for (const p of pts.punctures) holes.push(within(await project(p), isPuncture, 4));
  console.log(`${name}: ${s.suture.nodes} nodes, ${s.suture.punctures} punctures, ${s.suture.ties} knots; `
    + `${on} of ${total} nodes on the canvas have the thread's colour; punctures coloured: ${holes.join(', ')}`);
  return { s, share: total ? on / total : 0, total, holes };
}

/**
 * The share of pixels that changed clearly (some channel by more than 24 levels: a change a person
 * sees, not a level of shading; render_test.cc's ClearChange) between two images of one size, in a
 * disc of radius r around (cx, cy) (an ellipse of radii r and ry when given), and over the whole image.
 * @param {{width: number, height: number, data: Uint8Array}} a @param {{width: number, height: number, data: Uint8Array}} b
 * @param {number} cx @param {number} cy @param {number} r pixels @param {number} [ry]
 */
export function clearChange(a, b, cx, cy, r, ry = r) {
  let inside = 0, insideChanged = 0, changed = 0, outsideChanged = 0;
  for (let y = 0; y < a.height; y++) {
    for (let x = 0; x < a.width; x++) {
      const i = 4 * (y * a.width + x);
      const clear = Math.max(Math.abs(a.data[i] - b.data[i]), Math.abs(a.data[i + 1] - b.data[i + 1]), Math.abs(a.data[i + 2] - b.data[i + 2])) > 24;
      if (clear) changed++;
      if (Math.hypot((x + 0.5 - cx) / r, (y + 0.5 - cy) / ry) > 1) {
        if (clear) outsideChanged++;
        continue;
      }
      inside++;
      if (clear) insideChanged++;
    }
  }
  const n = a.width * a.height;
  return { region: inside ? insideChanged / inside : 0, image: changed / n, outside: outsideChanged / n };
}

/**
 * What is wider than the page's window (a phone's, say), once the layout has settled (plots follow
 * their box a frame later): each as tag#id.class and width; [] when nothing is. What is inside a
 * `.scroll` box (a wide table) scrolls within it and counts only if the box itself is too wide.
 * @param {import('playwright-core').Page} page
 */
export async function tooWide(page) {
  // Functions, not strings: a string predicate that has to be polled is evaluated in the page,
  // which the viewer's Content-Security-Policy (no 'unsafe-eval') refuses with an EvalError.
  /** @param {boolean} settled true: whether nothing is too wide; false: what is */
  const wide = (settled) => {
    const found = [...document.querySelectorAll('body *')]
      .filter((el) => el.getBoundingClientRect().right > innerWidth + 1 && !el.parentElement?.closest('.scroll'))
      .map((el) => `${el.tagName.toLowerCase()}#${el.id}.${el.className} ${el.getBoundingClientRect().width.toFixed(0)} px`)
      .concat(document.documentElement.scrollWidth > innerWidth ? [`the page scrolls sideways: ${document.documentElement.scrollWidth} px`] : []);
    return settled ? found.length === 0 : found;
  };
  await page.waitForFunction(wide, true, { timeout: 10000, polling: 100 }).catch(() => {});
  return page.evaluate(wide, false);
}
