// Global dynamics at a slower rate (issue 33) as an instructor sees it, in Debian's headless chromium
// against the real server and agents: a pluck on a membrane on weak home springs, recorded once with
// local simulation alone (the thesis) and once with the global pass at 100 Hz; the replays at the top
// of the lift. With the global pass the membrane around the haptic window rises with the pull (more
// of the surface moved), where local simulation alone moves only the window.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { dirname, join } from 'node:path';
import { Server, tempDir, launchBrowser, login, docShot, startAgent, agentBin } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
// The scripted pluck (sim/src/interaction_script.cc): grasped near 2 s, lifted to its top by 3.5 s,
// let go after 4 s.
const kTopS = 3.6;
/** @type {Record<string, string>} */
const sessions = {};

before(async () => {
  server = await new Server(tempDir('global')).start();
  const dir = tempDir('membrane');
  execFileSync(join(dirname(agentBin()), 'idms-sim'), ['generate', 'slab', '--rows', '20', '--cols', '20', '--home-k', '0.3',
    '--name', 'membrane', '--out', join(dir, 'membrane')]);
  for (const [label, rate] of [['local', '0'], ['global', '100']]) {
    const agent = startAgent(server, 4.5, 'scripted:pluck', { modelFile: join(dir, 'membrane'), args: ['--global-rate', rate] });
    assert.equal(await agent.exited, 0, agent.log());
    for (let i = 0; i < 600 && !sessions[label]; i++) {
      const ended = JSON.parse((await server.get('/api/sessions')).body).sessions
        .filter((/** @type {any} */ s) => s.state === 'ended' && !Object.values(sessions).includes(String(s.id)));
      if (ended.length > 0) sessions[label] = String(ended[0].id);
      else await new Promise((r) => setTimeout(r, 50));
    }
    assert.ok(sessions[label], `the ${label} session did not end`);
  }
  browser = await launchBrowser();
});
after(async () => {
  await browser?.context.close();
  await server?.stop();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

/** The replay of `id` paused at t, drawn. @param {import('playwright-core').Page} page @param {string} id @param {number} t */
async function replayAt(page, id, t) {
  await page.goto(`${server.base}/replay/${id}?t=${t}`);
  await page.waitForFunction((t) => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - Number(t)) < 0.05;
  }, t, { timeout: 20000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r(null)))));
  return page.evaluate(() => /** @type {any} */ (window).__idmsSurface());
}

test('replay at the top of a pluck: the global pass moves the membrane beyond the haptic window', async () => {
  const { page } = browser;
  await login(page, server, 'observer', '/sessions');
  const local = await replayAt(page, sessions.local, kTopS);
  await docShot(page.locator('#view3d canvas'), 'global-pluck-local-only.png');
  const global = await replayAt(page, sessions.global, kTopS);
  await docShot(page.locator('#view3d canvas'), 'global-pluck-two-rate.png');
  console.log(`surface vertices moved by more than 1% of the colour range: local only ${local.moved}, with the global pass ${global.moved}`);
  assert.ok(local.moved > 0, 'the pluck moved nothing');
  assert.ok(global.moved > 2 * local.moved, `with the global pass ${global.moved} vertices moved, local only ${local.moved}`);
});
