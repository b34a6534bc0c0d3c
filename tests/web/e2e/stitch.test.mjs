// A stitch in the browser, against the real server and agent (scripted:stitch: a needle upright
// over the hex fragment's middle atom goes down through it, is drawn through, and the button ties
// its thread at 10.5 s): the live view draws the thread over the surface, its two punctures once
// it has been drawn through them, and says the knot; the replay, sought to after the knot, draws
// the same from the recording. Checked in the compositor's screenshot: the thread's colour along
// the thread's projected line, and the punctures' colour at their points.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, startAgent, docShot, shot, frames, threadOnCanvas } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent> | null} */
let agent = null;
const kTiedS = 11.5;

before(async () => {
  server = await new Server(tempDir('stitch')).start();
  browser = await launchBrowser();
});
after(async () => {
  agent?.kill();
  await browser?.context.close();
  await server?.stop();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

test('live and replayed: the thread over the surface, its two punctures and the knot', async () => {
  const { page } = browser;
  agent = startAgent(server, 14, 'scripted:stitch', { library: true });
  const id = await server.liveSession();
  await login(page, server, 'admin', `/session/${id}`);
  // The thread from the first frames: 65 nodes, no puncture yet.
  await page.waitForFunction(() => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && /** @type {any} */ (window).__idmsSurface().suture.nodes === 65;
  }, undefined, { timeout: 60000, polling: 100 });
  // Tied: both points drawn through and the knot.
  await page.waitForFunction((t) => {
    const s = /** @type {any} */ (window).__idms;
    const u = /** @type {any} */ (window).__idmsSurface().suture;
    return s.timeS >= t && u.punctures === 2 && u.ties === 1;
  }, kTiedS, { timeout: 60000, polling: 50 });
  await frames(page);
  const live = await threadOnCanvas(browser.context, page, 'stitch-live.png');
  await docShot(page.locator('#view3d canvas'), 'stitch-tied.png');
  assert.ok(live.total > 20, `${live.total} of the thread's nodes on the canvas`);
  assert.ok(live.share > 0.8, `${(100 * live.share).toFixed(0)} % of the thread's nodes drawn in its colour`);
  assert.deepEqual(live.holes, [true, true], 'both punctures drawn');
  assert.equal(live.s.suture.brokenSegment, 0);
  await shot(page, 'stitch-live-page.png');
  assert.equal(await agent.exited, 0, agent.log());
  // The replay after the knot: the same thread from the recording.
  for (let i = 0; i < 200; i++) {
    if (JSON.parse((await server.get('/api/sessions')).body).sessions.find((/** @type {any} */ s) => s.id === id)?.state !== 'live') break;
    await new Promise((r) => setTimeout(r, 100));
  }
  await page.goto(`${server.base}/replay/${id}?t=12`);
  await page.waitForFunction(() => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - 12) < 0.05
      && /** @type {any} */ (window).__idmsSurface().suture.ties === 1;
  }, undefined, { timeout: 20000, polling: 50 });
  await frames(page);
  const replay = await threadOnCanvas(browser.context, page, 'stitch-replay.png');
  assert.equal(replay.s.suture.nodes, 65);
  assert.equal(replay.s.suture.punctures, 2);
  assert.ok(replay.share > 0.8, `${(100 * replay.share).toFixed(0)} % of the thread's nodes drawn in its colour in the replay`);
  assert.deepEqual(replay.holes, [true, true], 'both punctures drawn in the replay');
});
