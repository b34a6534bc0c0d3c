// The server serves the built viewer (types, ETags, page URLs, API precedence), every page sends
// a visitor without a login to /login and back, and a wrong token is refused on the page.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, shot } from './harness.mjs';

/** @type {Server} */
let server;
before(async () => { server = await new Server(tempDir('login')).start(); });
after(async () => { await server?.stop(); });

test('static files: types, ETag revalidation, page URLs get index.html, the API keeps its routes', async () => {
  const index = await fetch(`${server.base}/sessions`);
  assert.equal(index.status, 200);
  assert.match(index.headers.get('content-type') ?? '', /^text\/html/);
  const html = await index.text();
  assert.match(html, /<script type="module" src="\/assets\/app.js">/);
  for (const path of ['/', '/login', '/session/abc', '/replay/abc', '/trainee/alice', '/models', '/models/hex_4x5_home']) {
    const res = await fetch(server.base + path);
    assert.equal(res.status, 200, path);
    assert.equal(await res.text(), html, path);
  }
  const js = await fetch(`${server.base}/assets/app.js`);
  assert.equal(js.status, 200);
  assert.match(js.headers.get('content-type') ?? '', /^text\/javascript/);
  assert.equal(js.headers.get('cache-control'), 'no-cache');
  const etag = js.headers.get('etag');
  assert.ok(etag);
  const again = await fetch(`${server.base}/assets/app.js`, { headers: { 'If-None-Match': etag } });
  assert.equal(again.status, 304);
  assert.match((await fetch(`${server.base}/assets/app.css`)).headers.get('content-type') ?? '', /^text\/css/);
  // The API and unknown paths are untouched; nothing outside the build is reachable.
  const health = await fetch(`${server.base}/api/health`);
  assert.equal(JSON.parse(await health.text()).status, 'ok');
  assert.equal((await fetch(`${server.base}/api/sessions`)).status, 401);
  assert.equal((await fetch(`${server.base}/nowhere`)).status, 404);
  assert.equal((await fetch(`${server.base}/assets/.hidden`)).status, 404);
  const escape = await fetch(`${server.base}/assets/%2e%2e%2ftokens`);
  assert.ok(escape.status === 400 || escape.status === 404, `${escape.status}`);
  assert.equal((await fetch(`${server.base}/assets/nope.js`)).status, 404);
});

test('a visitor without a login goes to /login and back; a wrong token is refused', async () => {
  const { context, page, errors } = await launchBrowser();
  try {
    await page.goto(`${server.base}/models`);
    await page.waitForURL((u) => u.pathname === '/login');
    assert.equal(new URL(page.url()).searchParams.get('next'), '/models');
    // Wrong token: an error on the page, still at /login, no cookie.
    await page.fill('#token', 'not-a-token');
    await page.click('button[type=submit]');
    await page.waitForSelector('#login-error:has-text("not known")');
    assert.equal(new URL(page.url()).pathname, '/login');
    assert.equal((await context.cookies()).length, 0);
    await shot(page, 'login-refused.png');
    // The right one: back to /models, logged in as observer.
    await page.fill('#token', server.token('observer'));
    await Promise.all([page.waitForURL((u) => u.pathname === '/models'), page.click('button[type=submit]')]);
    await page.waitForSelector('#who:has-text("observer")');
    await page.waitForSelector('#models tr[data-name="hex_4x5_home"]');
    // Logging out ends the cookie: the next page goes to /login again.
    await Promise.all([page.waitForURL((u) => u.pathname === '/login'), page.click('#who button')]);
    await page.goto(`${server.base}/sessions`);
    await page.waitForURL((u) => u.pathname === '/login');
    await login(page, server, 'admin', '/sessions');
    await page.waitForSelector('#who:has-text("admin")');
    assert.deepEqual(errors, []);
  } finally {
    await context.close();
  }
});
