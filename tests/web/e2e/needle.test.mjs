// A needle in the browser, against the real server and agent (scripted:pierce: a needle tilted 30
// degrees from vertical in the x-z plane, in along its axis from 1 unit short of the surface to 2
// past it in 6 s, held, out; it punctures at about 2.9 s): the live view draws its shaft from the
// tip back along the streamed orientation, red once the samples say it punctured, and the replay
// draws it steel before the puncture. Checked in the compositor's screenshot along the line the
// shaft should cover, against lines beside it.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, startAgent, docShot, shot, decodePng, frames, surface } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent> | null} */
let agent = null;
const kBeforeS = 2.0, kInsideS = 5.0;
const kTilt = Math.PI / 6;

before(async () => {
  server = await new Server(tempDir('needle')).start();
  browser = await launchBrowser();
});
after(async () => {
  agent?.kill();
  await browser?.context.close();
  await server?.stop();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

/** @typedef {{width: number, height: number, data: Uint8Array}} Pixels */

/**
 * Red: the shaft in the tissue (0.80, 0.18, 0.16 sRGB, lit: from about (80, 14, 14) to (170, 37, 33)),
 * its green and blue alike and low; not the displacement map's salmon (green high) or magenta (blue
 * well over green). @param {number} r @param {number} g @param {number} b
 */
const isRed = (r, g, b) => r >= 60 && g < 0.3 * r && b < 0.3 * r && Math.abs(g - b) < 15;
/** Steel: a blue-grey (0.45, 0.50, 0.58 sRGB, lit), darker than the untouched surface and the background. */
const isSteel = (/** @type {number} */ r, /** @type {number} */ g, /** @type {number} */ b) =>
  b - r >= 12 && b >= g && Math.max(r, g, b) < 225 && Math.max(r, g, b) - Math.min(r, g, b) < 90;

/**
 * The share of points along the segment from a to b (CSS pixels on the canvas), from `from` to
 * `to` of its length, shifted sideways by `offset` pixels, with a pixel of the colour within 2
 * pixels of them.
 * @param {Pixels} img @param {{x: number, y: number}} a @param {{x: number, y: number}} b
 * @param {(r: number, g: number, b: number) => boolean} colour @param {number} offset
 */
function along(img, a, b, colour, offset = 0, from = 0.2, to = 0.95) {
  const len = Math.hypot(b.x - a.x, b.y - a.y);
  const nx = -(b.y - a.y) / len, ny = (b.x - a.x) / len;
  let points = 0, found = 0;
  for (let t = from; t <= to; t += 0.025) {
    const cx = a.x + t * (b.x - a.x) + offset * nx, cy = a.y + t * (b.y - a.y) + offset * ny;
    if (cx < 2 || cy < 2 || cx > img.width - 3 || cy > img.height - 3) continue;
    points++;
    let hit = false;
    for (let dy = -2; dy <= 2 && !hit; dy++) {
      for (let dx = -2; dx <= 2 && !hit; dx++) {
        const i = 4 * (Math.round(cy + dy) * img.width + Math.round(cx + dx));
        hit = colour(img.data[i], img.data[i + 1], img.data[i + 2]);
      }
    }
    if (hit) found++;
  }
  return points ? found / points : 0;
}

/**
 * The canvas's screenshot, where the needle's tip and tail fall on it, and how much of the line
 * between them (and of lines 15 px either side) has the colour.
 * @param {import('playwright-core').Page} page @param {string} name @param {(r: number, g: number, b: number) => boolean} colour
 */
async function look(page, name, colour) {
  const s = await surface(page);
  const png = await shot(page.locator('#view3d canvas'), name);
  const img = await decodePng(browser.context, png);
  /** @param {number[]} p */
  const project = (p) => page.evaluate(([x, y, z]) => /** @type {any} */ (window).__idmsProject(x, y, z), p);
  const tip = await project(s.tool), tail = await project(s.needle.tail);
  const on = along(img, tip, tail, colour);
  const beside = Math.max(along(img, tip, tail, colour, 15), along(img, tip, tail, colour, -15));
  const px = Math.hypot(tail.x - tip.x, tail.y - tip.y);
  console.log(`${name}: tip at ${s.tool.map((/** @type {number} */ v) => v.toFixed(2))}, on the canvas (${tip.x.toFixed(0)}, ${tip.y.toFixed(0)}) tail (${tail.x.toFixed(0)}, ${tail.y.toFixed(0)}), `
    + `${px.toFixed(0)} px long; on the line ${(100 * on).toFixed(0)} %, beside it ${(100 * beside).toFixed(0)} %`);
  return { s, on, beside, px, tip, tail };
}

test('live: the needle\'s shaft along its orientation, red once it has punctured; the replay draws it steel before', async () => {
  const { page } = browser;
  agent = startAgent(server, 15, 'scripted:pierce', { library: true });
  const id = await server.liveSession();
  await login(page, server, 'admin', `/session/${id}`);
  // The scene says needle: the shaft is drawn, its length the scene's.
  await page.waitForFunction(() => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.samples > 0 && s.renders >= 1 && /** @type {any} */ (window).__idmsSurface().needle;
  }, undefined, { timeout: 60000, polling: 100 });
  const first = await surface(page);
  assert.equal(first.needle.length, 5, 'the pierce\'s needle is 5 long');
  assert.ok(Math.abs(first.toolRadius - 0.25) < 1e-9, 'the tip\'s radius');
  // Tilted 30 degrees from vertical in the x-z plane: the tail above the tip, off in x, not in y.
  const d = first.needle.tail.map((/** @type {number} */ v, /** @type {number} */ i) => v - first.tool[i]);
  assert.ok(Math.abs(Math.hypot(...d) - 5) < 1e-6, `the tail ${Math.hypot(...d)} from the tip`);
  assert.ok(Math.abs(Math.acos(d[2] / 5) - kTilt) < 0.01, `the shaft ${(Math.acos(d[2] / 5) * 180 / Math.PI).toFixed(1)} degrees from vertical`);
  assert.ok(Math.abs(d[1]) < 1e-6, 'in the x-z plane');
  // Inside: the samples say punctured and the shaft is red along its line.
  await page.waitForFunction((t) => {
    const s = /** @type {any} */ (window).__idms;
    return s.timeS >= t && /** @type {any} */ (window).__idmsSurface().needle.punctured;
  }, kInsideS, { timeout: 60000, polling: 50 });
  await frames(page);
  const inside = await look(page, 'needle-inside-live.png', isRed);
  await docShot(page.locator('#view3d canvas'), 'needle-inside.png');
  assert.ok(inside.px > 40, `the shaft ${inside.px.toFixed(0)} px long on the canvas`);
  assert.ok(inside.on > 0.8, `${(100 * inside.on).toFixed(0)} % of the shaft's line is red`);
  assert.ok(inside.beside < 0.2, `${(100 * inside.beside).toFixed(0)} % of the lines beside it are red`);
  await shot(page, 'needle-inside-page.png');
  assert.equal(await agent.exited, 0, agent.log());
  // The replay before the puncture: steel, not red.
  for (let i = 0; i < 200; i++) {
    if (JSON.parse((await server.get('/api/sessions')).body).sessions.find((/** @type {any} */ s) => s.id === id)?.state !== 'live') break;
    await new Promise((r) => setTimeout(r, 100));
  }
  await page.goto(`${server.base}/replay/${id}?t=${kBeforeS}`);
  await page.waitForFunction((t) => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - t) < 0.05 && /** @type {any} */ (window).__idmsSurface().needle;
  }, kBeforeS, { timeout: 20000, polling: 50 });
  await frames(page);
  const before = await look(page, 'needle-before-replay.png', isSteel);
  await docShot(page.locator('#view3d canvas'), 'needle-before.png');
  assert.equal(before.s.needle.punctured, false);
  assert.ok(before.on > 0.8, `${(100 * before.on).toFixed(0)} % of the shaft's line is steel`);
  assert.ok(before.beside < 0.2, `${(100 * before.beside).toFixed(0)} % of the lines beside it are steel`);
  const red = await look(page, 'needle-before-replay.png', isRed);
  assert.ok(red.on < 0.1, `${(100 * red.on).toFixed(0)} % of the shaft's line is red before the puncture`);
});
