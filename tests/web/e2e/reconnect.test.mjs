// The server restarts under a live view: the page says it is reconnecting, logs in again by
// itself (a restart ends every cookie), and resumes the view with a fresh keyframe once the agent
// has resumed its session.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, shot, startAgent } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {ReturnType<typeof startAgent>} */
let agent;
before(async () => { server = await new Server(tempDir('reconnect')).start(); });
after(async () => {
  agent?.kill();
  await server?.stop();
});

test('a server restart is survived: reconnecting shown, then a fresh keyframe and new samples', async () => {
  agent = startAgent(server, 40);
  const id = await server.liveSession();
  const { context, page, errors } = await launchBrowser();
  try {
    await login(page, server, 'observer', `/session/${id}`);
    await page.waitForFunction(() => { const s = /** @type {any} */ (window).__idms; return s.keyframes >= 1 && s.samples > 200; });
    const before1 = await page.evaluate(() => ({ ...(/** @type {any} */ (window).__idms) }));

    await server.stop();
    await page.waitForFunction(() => /** @type {any} */ (window).__idms.connection === 'reconnecting');
    await page.waitForSelector('#conn.reconnecting:has-text("reconnecting")');
    await shot(page, 'reconnecting.png');

    await server.start();
    // Back: connected again, a keyframe after the restart, and samples later than before it.
    await page.waitForFunction((b) => {
      const s = /** @type {any} */ (window).__idms;
      return s.connection === 'open' && s.keyframes > b.keyframes && s.timeS > b.timeS + 0.5;
    }, before1, { timeout: 90000 });
    assert.equal(await page.locator('#conn').innerText(), '');
    await shot(page.locator('#view3d'), 'reconnected.png');
    assert.deepEqual(errors, []);
  } finally {
    await context.close();
  }
});
