// The dent at a glance (issue 28), in Debian's headless chromium against the real server and agent:
// the replay of the thesis palpation, seen from the default camera, before contact and at the
// deepest press: the contact region's pixels change clearly (before the surface was coloured by
// displacement, lit at a grazing angle and the tool drawn as an outline, 1.5 % of them did in
// idms-render, the same look), the contact vertices are marked, the legend says what the colours
// mean and the deformation scale when it is not 1; and the model page coloured by stiffness shows
// the tumour model's inclusion where the plain slab has none.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, shot, startAgent, decodePng, clearChange, frames, surface } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
let sessionId = '';
// The scripted palpation (sim/src/interaction_script.cc): the tool hovers 1 unit above first
// contact until 0.5 s, presses 0.063 below it at 2.5 s and holds until 3 s.
const kBeforeContactS = 1.0, kDeepestS = 2.8;

before(async () => {
  server = await new Server(tempDir('dent')).start();
  // From the library, as a deployed agent: the page takes rest from the library's model.
  const agent = startAgent(server, 3, 'scripted:palpate', { library: true });
  assert.equal(await agent.exited, 0, agent.log());
  // The session is recorded to its end.
  for (let i = 0; i < 600 && !sessionId; i++) {
    const ended = JSON.parse((await server.get('/api/sessions')).body).sessions.find((/** @type {any} */ s) => s.state === 'ended');
    if (ended) sessionId = String(ended.id);
    else await new Promise((r) => setTimeout(r, 50));
  }
  assert.ok(sessionId, 'the session did not end');
  browser = await launchBrowser();
});
after(async () => {
  await browser?.context.close();
  await server?.stop();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

/** The paused replay at t, drawn, with the tool in the state asked. @param {import('playwright-core').Page} page @param {number} t @param {string} tool */
async function at(page, t, tool) {
  await page.waitForFunction(([t, tool]) => {
    const s = /** @type {any} */ (window).__idms;
    return s && s.keyframes >= 1 && s.renders >= 1 && Math.abs(s.timeS - Number(t)) < 0.05
      && (document.getElementById('tool-state')?.textContent ?? '').includes(String(tool));
  }, [t, tool], { timeout: 20000 });
  await frames(page);
}

test('replay: the contact region changes clearly between before contact and the deepest press', async () => {
  const { page, context } = browser;
  await login(page, server, 'observer', '/sessions');
  // The deepest press first, then before contact: the camera, fitted to the tool's travel, has
  // framed both, so the two images share it (checked below).
  await page.goto(`${server.base}/replay/${sessionId}?t=${kDeepestS}`);
  await at(page, kDeepestS, 'in contact');
  await page.locator('#seek').fill(String(kBeforeContactS));
  await at(page, kBeforeContactS, 'free');
  await page.locator('#seek').fill(String(kDeepestS));
  await at(page, kDeepestS, 'in contact');
  const canvas = page.locator('#view3d canvas');
  /** @returns {Promise<any>} */
  const deep = await surface(page);
  assert.ok(deep.contacts >= 1, `${deep.contacts} contact vertices marked at the deepest press`);
  assert.equal(deep.colourBy, 'displacement');
  assert.equal(deep.hi, 0.1, 'the fragment of unit sides spans 0.1 model units');
  const pressedPng = await shot(canvas, 'dent-deepest.png');
  await shot(page, 'dent-deepest-page.png');
  // The legend says what the colours are, in which unit, and that the top takes larger values too.
  const legend = await page.locator('#legend').innerText();
  assert.doesNotMatch(legend, /from t =/, 'rest is the model at rest, not the surface the replay opened at');
  assert.match(legend, /displacement/);
  assert.match(legend, /model units/);
  assert.match(legend, /≥0\.1/);
  await page.locator('#seek').fill(String(kBeforeContactS));
  await at(page, kBeforeContactS, 'free');
  const free = await surface(page);
  assert.equal(free.contacts, 0);
  assert.deepEqual(free.camera, deep.camera, 'the camera moved between the two images');
  const beforePng = await shot(canvas, 'dent-before-contact.png');
  // The contact region: the disc of the tool's radius around the surface point under the tool.
  const [tx, ty] = deep.tool;
  const c = await page.evaluate(([x, y]) => /** @type {any} */ (window).__idmsProject(x, y, 0), [tx, ty]);
  const e = await page.evaluate(([x, y, r]) => /** @type {any} */ (window).__idmsProject(x + r, y, 0), [tx, ty, deep.toolRadius]);
  const radius = Math.hypot(e.x - c.x, e.y - c.y);
  const change = clearChange(await decodePng(context, beforePng), await decodePng(context, pressedPng), c.x, c.y, radius);
  console.log(`contact region (${radius.toFixed(0)} px around ${c.x.toFixed(0)}, ${c.y.toFixed(0)}): `
    + `${(100 * change.region).toFixed(1)} % of its pixels changed clearly; the canvas: ${(100 * change.image).toFixed(2)} %`);
  assert.ok(change.region > 0.5, `${(100 * change.region).toFixed(1)} % of the contact region changed clearly`);
  // The deformation scale: the dent drawn ten times deeper, said in the legend.
  await page.selectOption('#deformation-scale', '10');
  await page.locator('#seek').fill(String(kDeepestS));
  await at(page, kDeepestS, 'in contact');
  assert.match(await page.locator('#legend').innerText(), /deformation ×10/);
  await shot(page, 'dent-deepest-x10-page.png');
});

test('the model page coloured by stiffness: the tumour model differs from the plain slab in its inclusion', async () => {
  const { page, context } = browser;
  await login(page, server, 'observer', '/models');
  /** @param {string} name */
  const preview = async (name) => {
    await page.goto(`${server.base}/models/${name}`);
    await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.colourBy === 'stiffness', undefined, { timeout: 20000 });
    await frames(page);
    // The canvas, the legend over it masked (its numbers differ: it is not what is compared).
    return page.locator('#preview canvas').screenshot({ mask: [page.locator('#legend')] });
  };
  const plainPng = await preview('slab_40x40');
  assert.equal(await page.evaluate(() => /** @type {any} */ (window).__idmsStiffRegion()), null, 'the plain slab has one stiffness');
  const tumourPng = await preview('slab_40x40_tumour');
  await shot(page, 'stiffness-tumour-page.png');
  const region = await page.evaluate(() => /** @type {any} */ (window).__idmsStiffRegion());
  assert.ok(region && region.count > 3, 'the tumour model has a stiffer region');
  assert.match(await page.locator('#legend').innerText(), /stiffness/);
  const plain = await decodePng(context, plainPng), tumour = await decodePng(context, tumourPng);
  const inside = clearChange(plain, tumour, region.x, region.y, 0.7 * region.rx, 0.7 * region.ry);
  console.log(`inclusion (${region.rx.toFixed(0)} x ${region.ry.toFixed(0)} px around ${region.x.toFixed(0)}, ${region.y.toFixed(0)}): `
    + `${(100 * inside.region).toFixed(1)} % of its pixels differ clearly; the canvas: ${(100 * inside.image).toFixed(2)} %`);
  assert.ok(inside.region > 0.8, `${(100 * inside.region).toFixed(1)} % of the inclusion's region differs clearly`);
  // Away from it nothing differs.
  const away = clearChange(plain, tumour, region.x, region.y, 2.5 * region.rx, 2.5 * region.ry).outside;
  assert.ok(away < 0.0005, `${(100 * away).toFixed(3)} % of the canvas differs away from the inclusion`);
});
