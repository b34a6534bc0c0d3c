// The library pages: the list, a model's versions and its 3D preview at rest, an upload of a bad
// model showing the parser's file:line:column on the page, a good one appearing in the list (pushed
// by /ws/library) with its preview, and an admin's delete.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { Server, tempDir, launchBrowser, login, shot, sourceDir, tooWide } from './harness.mjs';

/** @type {Server} */
let server;
before(async () => { server = await new Server(tempDir('models')).start(); });
after(async () => { await server?.stop(); });

test('library: list, preview, bad upload shows file:line:column, good upload listed, delete', async () => {
  const fem = readFileSync(join(sourceDir(), 'models', 'hex_4x5_home.fem'), 'utf8');
  const plg = readFileSync(join(sourceDir(), 'models', 'hex_4x5_home.plg'), 'utf8');
  const lines = fem.split('\n');
  lines[3] = '1.5 0 zero 0.002 1001 2001';  // the second atom's z is not a number
  const badFem = lines.join('\n');
  // What the server says about it, asked directly: the page must show exactly that place.
  const direct = await fetch(`${server.base}/api/models/broken`, {
    method: 'PUT',
    headers: { Authorization: `Bearer ${server.token('admin')}`, 'Content-Type': 'application/json' },
    body: JSON.stringify({ fem: badFem, plg, description: 'x' }),
  });
  assert.equal(direct.status, 400);
  const expected = await direct.json();
  assert.ok(expected.file && expected.line === 4 && expected.column > 0, JSON.stringify(expected));

  const { context, page, errors } = await launchBrowser();
  try {
    await login(page, server, 'admin', '/models');
    await page.waitForSelector('#models tr[data-name="hex_4x5_home"]');
    await shot(page, 'models.png');

    // A bad upload: the parser's place and message on the page, nothing stored.
    const upload = async (/** @type {string} */ name, /** @type {string} */ femText) => {
      await page.fill('#up-name', name);
      await page.setInputFiles('#up-fem', { name: `${name}.fem`, mimeType: 'text/plain', buffer: Buffer.from(femText) });
      await page.setInputFiles('#up-plg', { name: `${name}.plg`, mimeType: 'text/plain', buffer: Buffer.from(plg) });
      await page.fill('#up-desc', `${name} from the browser test`);
      await page.click('#upload button[type=submit]');
    };
    await upload('broken', badFem);
    const where = page.locator('#upload-result.error code.where');
    await where.waitFor();
    assert.equal(await where.innerText(), `${expected.file}:${expected.line}:${expected.column}`);
    // The place once, then what the parser expected.
    const shown = await page.locator('#upload-result').innerText();
    assert.ok(shown.includes(expected.error.replace(`${expected.file}:${expected.line}:${expected.column}: `, '')), shown);
    assert.equal(shown.split(`${expected.line}:${expected.column}`).length, 2, shown);
    await shot(page, 'models-upload-error.png');
    // On a phone: one column, the form and its error within the screen.
    await page.setViewportSize({ width: 390, height: 844 });
    assert.deepEqual(await tooWide(page), [], 'wider than a 390 px screen');
    await shot(page, 'models-phone.png');
    await page.setViewportSize({ width: 1280, height: 720 });
    assert.equal((await server.get('/api/models/broken')).status, 404);

    // A good one: stored, listed (the library socket refreshes the list), previewed.
    await upload('hex_copy', fem);
    await page.waitForSelector('#upload-result.ok a[href="/models/hex_copy"]');
    await page.waitForSelector('#models tr[data-name="hex_copy"]');
    await Promise.all([page.waitForURL('**/models/hex_copy'), page.click('#models tr[data-name="hex_copy"] a')]);
    await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.vertices > 0);
    const preview = await page.evaluate(() => /** @type {any} */ (window).__idmsPreview);
    assert.equal(preview.vertices, 22);  // the .plg's vertices
    assert.equal(preview.triangles > 0, true);
    await page.waitForSelector('#versions tr[data-version="1"]');
    await shot(page, 'model-preview.png');

    // Delete (admin): gone from the library.
    page.once('dialog', (d) => d.accept());
    await Promise.all([page.waitForURL('**/models'), page.click('#versions button:has-text("Delete")')]);
    await page.waitForSelector('#models tr[data-name="hex_4x5_home"]');
    assert.equal(await page.locator('#models tr[data-name="hex_copy"]').count(), 0);
    assert.equal((await server.get('/api/models/hex_copy')).status, 404);
    assert.deepEqual(errors, []);
  } finally {
    await context.close();
  }
});
