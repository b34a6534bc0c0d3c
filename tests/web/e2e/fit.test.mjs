// The fit page (issue 34), against the real server and agent: a palpation recorded on
// hex_4x5_home is fitted, from the page, to a copy of the model typed in 20% too soft; the page
// follows the job to its end and shows the factor that makes the copy the model the session ran,
// with the recorded force against the fitted model's; the library's model page shows the same
// report under the fitted version; an observer sees the fit but not the form; a bad region is
// refused on the page with the server's reason. And a scan of the tumour slab, mapped from the
// page against the plain slab: the map shows the lump where the tumour is, on the fit page and on
// the plain slab's model page.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { Server, tempDir, launchBrowser, login, startAgent, docShot, sourceDir, tooWide } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent>[]} */
const agents = [];
/** The scan (49.7 s), started during the first test. @type {ReturnType<typeof startAgent> | null} */
let scan = null;

before(async () => {
  server = await new Server(tempDir('fit')).start();
  browser = await launchBrowser();
});
after(async () => {
  for (const a of agents) a.kill();
  await browser?.context.close();
  await server?.stop();
});

/** hex_4x5_home's .fem with every element's k times `factor` (element lines: atom atom k b). @param {number} factor */
function scaledFem(factor) {
  return readFileSync(join(sourceDir(), 'models', 'hex_4x5_home.fem'), 'utf8').split('\n').map((l) => {
    const t = l.trim().split(/\s+/);
    return t.length === 4 ? [t[0], t[1], String(Number(t[2]) * factor), t[3]].join(' ') : l;
  }).join('\n');
}

test('fit page: an admin fits a session to a soft copy; the report, the model page, an observer, a bad region', async () => {
  const { page, errors } = browser;
  const plg = readFileSync(join(sourceDir(), 'models', 'hex_4x5_home.plg'), 'utf8');
  const put = await fetch(`${server.base}/api/models/hex_soft`, {
    method: 'PUT',
    headers: { Authorization: `Bearer ${server.token('admin')}`, 'Content-Type': 'application/json' },
    body: JSON.stringify({ fem: scaledFem(0.8), plg, description: 'typed in too soft' }),
  });
  assert.equal(put.status, 201, await put.text());
  const agent = startAgent(server, 4, 'scripted:palpate', { library: true });
  agents.push(agent);
  const id = await server.liveSession();
  // The scan for the second test, meanwhile (its own session).
  scan = startAgent(server, 50, 'scripted:scan', { library: true, model: 'slab_40x40_tumour' });
  agents.push(scan);
  assert.equal(await agent.exited, 0, agent.log());
  for (let i = 0; i < 200; i++) {
    const { body } = await server.get(`/api/sessions/${id}`);
    if (JSON.parse(body).state !== 'live') break;
    await new Promise((r) => setTimeout(r, 100));
  }

  // The list links to the fit page.
  await login(page, server, 'admin', '/sessions');
  await page.locator(`#sessions tr[data-id="${id}"] a.fit-link`).click();
  await page.waitForURL(`**/fit/${id}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsFit?.state === 'none');
  assert.match(await page.locator('#fit-status').innerText(), /No fit of this session yet/);
  // A bad region: refused on the page, with the server's reason.
  await page.locator('#fit-regions').fill('lump=cube:1,2,3');
  await page.locator('#fit-start').click();
  await page.locator('#fit-result.error').waitFor();
  assert.match(await page.locator('#fit-result').innerText(), /Refused: regions: .*cube/);
  // The soft copy, every element's k.
  await page.locator('#fit-regions').fill('');
  await page.waitForFunction(() => document.querySelectorAll('#fit-model-name option').length > 2);
  await page.locator('#fit-model-name').selectOption('hex_soft');
  for (const p of ['home_k', 'surface_k']) await page.locator(`input[name="param"][value="${p}"]`).uncheck();
  await page.locator('input[name="param"][value="k"]').check();
  await page.locator('#fit-start').click();
  await page.waitForFunction(() => { const s = /** @type {any} */ (window).__idmsFit; return s.state === 'done' && s.points > 0; },
    undefined, { timeout: 120000 });
  const fit = await page.evaluate(() => /** @type {any} */ (window).__idmsFit);
  assert.equal(fit.model, 'hex_soft');
  assert.equal(fit.version, 2);
  assert.ok(fit.points > 100 && fit.points <= 500, `${fit.points} points on the force plot`);
  const factor = await page.locator('#fit-params tr[data-param="k"] td').nth(1).innerText();
  const m = /× ([\d.]+) ± /.exec(factor);
  assert.ok(m && Math.abs(Number(m[1]) - 1.25) < 1e-3, `k's factor: ${factor}`);
  assert.match(await page.locator('#fit-status').innerText(), /Done: the fitted model is hex_soft version 2/);
  assert.match(await page.locator('#fit-plot .u-title').innerText(), /recorded and fitted/);
  assert.equal(await page.locator('#fit-plot .u-legend .u-series').count(), 3, 'time, recorded, fitted');
  assert.deepEqual(await tooWide(page), [], 'nothing wider than the page');
  await docShot(page, 'fit-done.png');

  // The model page of the fitted version: the same report under its preview.
  await page.locator('#fit-model').click();
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.version === 2);
  assert.equal(await page.evaluate(() => /** @type {any} */ (window).__idmsPreview.fitted), true);
  await page.locator('#fit-section').waitFor({ state: 'visible' });
  assert.match(await page.locator('#fit-title').innerText(), /Fit report of version 2/);
  assert.match(await page.locator('#fit-params tr[data-param="k"]').innerText(), /× 1\.25/);
  await docShot(page, 'model-fit-report.png');
  // Version 1 (an upload) has none.
  await page.locator('button[aria-label="Preview version 1"]').click();
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.version === 1);
  assert.equal(await page.locator('#fit-section').isHidden(), true);

  // An observer sees the fit, not the form.
  await login(page, server, 'observer', `/fit/${id}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsFit?.state === 'done');
  assert.equal(await page.locator('#fit-form').count(), 0);
  assert.match(await page.locator('#fit-params tr[data-param="k"]').innerText(), /× 1\.25/);
  assert.deepEqual(errors, []);
});

test('map: a scan mapped from the page against the plain slab shows the lump where the tumour is', async () => {
  const { page, errors } = browser;
  assert.ok(scan, 'the first test started the scan');
  assert.equal(await scan.exited, 0, scan.log());
  /** @type {string} */
  let id = '';
  for (let i = 0; i < 200 && !id; i++) {
    const { body } = await server.get('/api/sessions');
    const s = JSON.parse(body).sessions.find((/** @type {any} */ x) => x.device === 'scripted:scan' && x.state !== 'live');
    if (s) id = String(s.id);
    else await new Promise((r) => setTimeout(r, 100));
  }
  assert.ok(id, 'the scan session ended');
  await login(page, server, 'admin', `/fit/${id}`);
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsFit?.state === 'none');
  await page.waitForFunction(() => document.querySelectorAll('#fit-model-name option').length > 2);
  await page.locator('#fit-model-name').selectOption('slab_40x40');
  await page.locator('#fit-map-mode').check();
  assert.equal(await page.locator('input[name="param"][value="k"]').isDisabled(), true);
  await page.locator('#fit-start').click();
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsFit.state === 'done', undefined, { timeout: 180000 });
  const fit = await page.evaluate(() => /** @type {any} */ (window).__idmsFit);
  assert.equal(fit.kind, 'map');
  assert.equal(fit.presses, 49);
  assert.equal(fit.lump, true);
  assert.equal(await page.locator('#fit-map circle[data-press]').count(), 49);
  // The lump's circle around the tumour (20, 17), and its dots the stiffest colour's end.
  const ring = page.locator('#map-lump');
  assert.ok(Math.abs(Number(await ring.getAttribute('cx')) - 20) < 1);
  assert.ok(Math.abs(-Number(await ring.getAttribute('cy')) - 17) < 1);
  const stiffest = await page.evaluate(() => {
    const dots = [...document.querySelectorAll('#fit-map circle[data-press]')];
    const top = dots.reduce((a, b) => (Number(b.getAttribute('data-scale')) > Number(a.getAttribute('data-scale')) ? b : a));
    return { x: Number(top.getAttribute('cx')), y: -Number(top.getAttribute('cy')), scale: Number(top.getAttribute('data-scale')) };
  });
  assert.ok(Math.hypot(stiffest.x - 20, stiffest.y - 17) < 4, `the stiffest press at ${stiffest.x}, ${stiffest.y}`);
  assert.ok(stiffest.scale > 4, `its factor ${stiffest.scale}`);
  assert.match(await page.locator('#map-lump-text').innerText(), /A lump at x 2\d\.?\d*, y 1\d/);
  assert.deepEqual(await tooWide(page), [], 'nothing wider than the page');
  await docShot(page.locator('#fit-report'), 'fit-map.png');
  // The plain slab's model page: version 2 carries the map.
  await page.locator('#fit-model').click();
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.version === 2);
  await page.locator('#fit-section').waitFor({ state: 'visible' });
  assert.match(await page.locator('#fit-title').innerText(), /Stiffness map of version 2/);
  assert.equal(await page.locator('#fit-map circle[data-press]').count(), 49);
  assert.deepEqual(errors, []);
});
