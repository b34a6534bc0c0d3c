// A suture in the browser, against the real server and agent (scripted:suture on models/suture.scene
// at 5 times real time: the scalpel opens an incision through the soft slab in its first 9 s, then
// the needle places three stitches across it and ties each, and holds still from 93 s): the live
// view draws the needle's shaft, and at the end the thread through its twelve points with three
// knots; the replay at 5 s draws the scalpel (no shaft, its small tip), and sought to the end the
// same thread from the recording, and the report says the stitches and the
// gap. Checked in the compositor's screenshot: the thread's colour along its projected line, and the
// punctures' colour at their points.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import { Server, tempDir, launchBrowser, login, startAgent, docShot, frames, surface, sourceDir, threadOnCanvas } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent> | null} */
let agent = null;

before(async () => {
  server = await new Server(tempDir('suture')).start();
  browser = await launchBrowser();
});
after(async () => {
  agent?.kill();
  await browser?.context.close();
  await server?.stop();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

test('live and replayed: the scalpel, then the needle; three stitches tied across the incision', async () => {
  const { page } = browser;
  agent = startAgent(server, 20, 'scripted:suture', { library: true, model: 'suture_slab',
    args: ['--scene', join(sourceDir(), 'models', 'suture.scene'), '--rate', '5000'] });
  const id = await server.liveSession();
  await login(page, server, 'admin', `/session/${id}`);
  // The needle from its first key on (9.06 s): its 3-unit shaft. (The scalpel before it passes in
  // under 2 s at this rate: the replay below looks at it.)
  await page.waitForFunction(() => /** @type {any} */ (window).__idms?.timeS > 10
    && /** @type {any} */ (window).__idmsSurface().needle !== null, undefined, { timeout: 60000, polling: 50 });
  const stitching = await surface(page);
  assert.equal(stitching.needle.length, 3);
  assert.equal(stitching.toolRadius, 0.25);
  // Three knots, twelve points the thread passes.
  await page.waitForFunction(() => {
    const u = /** @type {any} */ (window).__idmsSurface().suture;
    return /** @type {any} */ (window).__idms.timeS > 95 && u.punctures === 12 && u.ties === 3;
  }, undefined, { timeout: 120000, polling: 100 });
  await frames(page);
  const live = await threadOnCanvas(browser.context, page, 'suture-live.png');
  assert.equal(live.s.suture.nodes, 129);
  assert.equal(live.s.suture.brokenSegment, 0);
  assert.ok(live.total > 40, `${live.total} of the thread's nodes on the canvas`);
  assert.ok(live.share > 0.7, `${(100 * live.share).toFixed(0)} % of the thread's nodes drawn in its colour`);
  const coloured = live.holes.filter(Boolean).length;
  assert.ok(coloured >= 6, `${coloured} of 12 punctures drawn in their colour (some may lie under the lips)`);
  assert.equal(await agent.exited, 0, agent.log());
  // The replay at the end: the same thread from the recording.
  for (let i = 0; i < 200; i++) {
    if (JSON.parse((await server.get('/api/sessions')).body).sessions.find((/** @type {any} */ s) => s.id === id)?.state !== 'live') break;
    await new Promise((r) => setTimeout(r, 100));
  }
  // The incision in the replay: the scalpel held (its 0.05 tip, no shaft).
  await page.goto(`${server.base}/replay/${id}?t=5`);
  await page.waitForFunction(() => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - 5) < 0.05;
  }, undefined, { timeout: 30000, polling: 50 });
  await frames(page);
  const cutting = await surface(page);
  assert.equal(cutting.needle, null, 'no shaft while the scalpel is held');
  assert.equal(cutting.toolRadius, 0.05);
  await page.goto(`${server.base}/replay/${id}?t=97`);
  await page.waitForFunction(() => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - 97) < 0.05
      && /** @type {any} */ (window).__idmsSurface().suture.ties === 3;
  }, undefined, { timeout: 30000, polling: 50 });
  await frames(page);
  const replay = await threadOnCanvas(browser.context, page, 'suture-replay.png');
  assert.equal(replay.s.suture.punctures, 12);
  assert.ok(replay.share > 0.7, `${(100 * replay.share).toFixed(0)} % of the thread's nodes drawn in its colour in the replay`);
  // The view frames the whole thread (drawn far above the slab by the first stitch): zoomed in with
  // the wheel, as an instructor would, for the README.
  const box = await page.locator('#view3d canvas').boundingBox();
  assert.ok(box);
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  for (let i = 0; i < 6; i++) await page.mouse.wheel(0, -200);
  await frames(page);
  await docShot(page.locator('#view3d canvas'), 'suture-closed.png');
  // The session's report: the stitches tied, and the incision's gap against its open width.
  await page.goto(`${server.base}/report/${id}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsReport?.loaded, undefined, { timeout: 30000 });
  const figures = await page.locator('#report-figures').innerText();
  assert.match(figures, /Stitches tied\s+3/);
  assert.match(figures, /Incision gap\s+0\.\d\d of 1\.00 model units open \(\d\d %\)/);
});
