// What an instructor uses to follow trainees, against the real server and agents: the sessions
// list's Trainee column, force-limit hits and filters (kept in the URL, through a reload); a
// trainee's page with their figures over time; an admin correcting a session's trainee; in the
// live view the force-limit indicator, its events as words at their times, the loop's verdict in
// words, Reset asking first and the tweezers' commands only with tweezers; the force-against-depth
// plot's ticks and units; a replay played to the end and again (plots in step with the view, no
// duplicate events), its keys; the phone's cards, the model page at 1280 px, the favicon.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { Server, tempDir, launchBrowser, login, startAgent, tooWide, docShot } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent>[]} */
const agents = [];
/** The recorded sessions by what they are. */
const ids = { aliceLimited: '', alice: '', bob: '' };

/** @param {import('playwright-core').Page} page */
const state = (page) => page.evaluate(() => /** @type {any} */ (window).__idms);

/** @param {string} trainee */
async function sessionOf(trainee) {
  const { body } = await server.get(`/api/sessions?trainee=${encodeURIComponent(trainee)}`);
  return JSON.parse(body).sessions;
}

before(async () => {
  server = await new Server(tempDir('instructor')).start();
  browser = await launchBrowser();
  // Three recorded sessions at once: alice twice (the first held at a low force limit, so that
  // the palpation reaches it), bob once from a model file (another model name).
  const runs = [
    startAgent(server, 3.5, 'scripted:palpate', { library: true, args: ['--trainee', 'alice', '--max-force', '0.5'] }),
    startAgent(server, 3, 'scripted:palpate', { library: true, args: ['--trainee', 'alice'] }),
    startAgent(server, 2, 'scripted:palpate', { args: ['--trainee', 'bob'] }),
  ];
  agents.push(...runs);
  for (const run of runs) assert.equal(await run.exited, 0, run.log());
  const alice = await sessionOf('alice');
  assert.equal(alice.length, 2, JSON.stringify(alice));
  ids.aliceLimited = String(alice.find((/** @type {any} */ s) => s.summary.force_limit_hits > 0)?.id ?? '');
  ids.alice = String(alice.find((/** @type {any} */ s) => s.summary.force_limit_hits === 0)?.id ?? '');
  ids.bob = String((await sessionOf('bob'))[0]?.id ?? '');
  assert.ok(ids.aliceLimited && ids.alice && ids.bob, JSON.stringify({ ids, alice }));
});
after(async () => {
  for (const a of agents) a.kill();
  await browser?.context.close();
  await server?.stop();
});

/** The ids of the rows the sessions table shows. @param {import('playwright-core').Page} page */
const rowIds = (page) => page.$$eval('#sessions tbody tr', (trs) => trs.map((tr) => /** @type {HTMLElement} */ (tr).dataset.id).sort());

test('sessions list: trainee column, force-limit hits, filters by trainee, model and date kept in the URL', async () => {
  const { page, errors } = browser;
  await login(page, server, 'admin', '/sessions');
  await page.waitForSelector(`#sessions tr[data-id="${ids.bob}"]`);
  const all = [ids.aliceLimited, ids.alice, ids.bob].sort();
  await page.waitForFunction((n) => document.querySelectorAll('#sessions tbody tr').length === n, all.length);
  // The trainee links to their page; the force-limit hits are the summary's.
  const limitedRow = page.locator(`#sessions tr[data-id="${ids.aliceLimited}"]`);
  assert.equal(await limitedRow.locator('td.trainee a').getAttribute('href'), '/trainee/alice');
  const hits = (await sessionOf('alice')).find((/** @type {any} */ s) => String(s.id) === ids.aliceLimited).summary.force_limit_hits;
  assert.ok(hits > 0);
  assert.equal(await limitedRow.locator('td[data-label="Force-limit hits"] .limit-hits').innerText(), String(hits));
  assert.equal(await page.locator(`#sessions tr[data-id="${ids.bob}"] td[data-label="Force-limit hits"] .limit-hits`).innerText(), '0');
  assert.match(await page.locator('#sessions thead').innerText(), /Peak force\s+model force units/);
  const right = await page.evaluate(() => /** @type {HTMLElement} */ (document.getElementById('sessions')).getBoundingClientRect().right);
  assert.ok(right <= 1280, `the session list is ${right} px wide at 1280`);
  await docShot(page, 'sessions-trainee.png');

  // By trainee: the URL says so, the list is alice's; a reload keeps both.
  await page.fill('#f-trainee', 'alice');
  await page.press('#f-trainee', 'Enter');
  await page.waitForFunction(() => new URL(location.href).searchParams.get('trainee') === 'alice');
  await page.waitForFunction((n) => document.querySelectorAll('#sessions tbody tr').length === n, 2);
  assert.deepEqual(await rowIds(page), [ids.aliceLimited, ids.alice].sort());
  await page.reload();
  await page.waitForSelector('#sessions tbody tr');
  assert.equal(await page.inputValue('#f-trainee'), 'alice');
  await page.waitForFunction((n) => document.querySelectorAll('#sessions tbody tr').length === n, 2);
  assert.deepEqual(await rowIds(page), [ids.aliceLimited, ids.alice].sort());
  await docShot(page, 'sessions-filtered.png');

  // By model: bob's session names the model by its file path.
  const bobModel = JSON.parse((await server.get(`/api/sessions/${ids.bob}`)).body).model;
  await page.click('#f-clear');
  await page.fill('#f-model', bobModel);
  await page.press('#f-model', 'Enter');
  await page.waitForFunction(() => new URL(location.href).searchParams.get('model') !== null && !new URL(location.href).searchParams.has('trainee'));
  await page.waitForFunction((n) => document.querySelectorAll('#sessions tbody tr').length === n, 1);
  assert.deepEqual(await rowIds(page), [ids.bob]);

  // By date (UTC, as the server reads it): from tomorrow none, from today all.
  const today = new Date().toISOString().slice(0, 10);
  const tomorrow = new Date(Date.now() + 86400e3).toISOString().slice(0, 10);
  await page.click('#f-clear');
  await page.fill('#f-from', tomorrow);
  await page.waitForFunction((d) => new URL(location.href).searchParams.get('from') === d, tomorrow);
  await page.waitForSelector('p[role=status]:has-text("No sessions match")');
  assert.equal(await page.locator('#sessions tbody tr').count(), 0);
  await page.fill('#f-from', today);
  await page.fill('#f-to', today);
  await page.waitForFunction((d) => new URL(location.href).searchParams.get('to') === d, today);
  await page.waitForFunction((n) => document.querySelectorAll('#sessions tbody tr').length === n, all.length);
  assert.deepEqual(await rowIds(page), all);
  assert.deepEqual(errors, []);
});

test('trainee page: their sessions and figures over time; an admin corrects a trainee, an observer cannot', async () => {
  const { page, errors } = browser;
  await page.goto(`${server.base}/trainee/alice`);
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsTrainee?.points === 2);
  await page.waitForSelector('#trainee-sessions tbody tr >> nth=1');
  assert.deepEqual(await page.$$eval('#trainee-sessions tbody tr', (trs) => trs.map((tr) => /** @type {HTMLElement} */ (tr).dataset.trainee)),
    ['alice', 'alice']);
  // The plot's axes have ticks and say their units.
  const axes = await page.locator('#trend-plot').innerText();
  assert.match(axes, /peak force \(model force units\)/);
  assert.match(axes, /time in contact \(s\)/);
  // uPlot draws its tick values on the canvas, in the axes' spaces: three, each sized.
  const sizes = await page.$$eval('#trend-plot .u-axis', (els) => els.map((el) => Math.min(el.getBoundingClientRect().width, el.getBoundingClientRect().height)));
  assert.equal(sizes.length, 3, 'three axes: time, force, contact');
  assert.ok(sizes.every((s) => s > 20), `axis sizes ${sizes}`);
  assert.match(await page.locator('#trainee-status').innerText(), /2 sessions .* force limit reached [1-9]\d* times?/);
  await docShot(page, 'trainee.png');

  // An admin corrects bob's session to carol on its page: the API and the header say carol.
  await page.goto(`${server.base}/replay/${ids.bob}`);
  await page.waitForSelector('#trainee-name:has-text("bob")');
  await page.click('#trainee-edit');
  await page.fill('#trainee-input', 'carol');
  await page.press('#trainee-input', 'Enter');
  await page.waitForSelector('#trainee-name:has-text("carol")');
  assert.equal(JSON.parse((await server.get(`/api/sessions/${ids.bob}`)).body).trainee, 'carol');
  assert.equal(await page.getAttribute('#trainee-name', 'href'), '/trainee/carol');
  assert.equal((await sessionOf('bob')).length, 0);

  // An observer sees the trainee and no way to edit it.
  await Promise.all([page.waitForURL((u) => u.pathname === '/login'), page.click('#who button')]);
  await login(page, server, 'observer', `/replay/${ids.bob}`);
  await page.waitForSelector('#trainee-name:has-text("carol")');
  assert.equal(await page.locator('#trainee-edit').count(), 0);
  await Promise.all([page.waitForURL((u) => u.pathname === '/login'), page.click('#who button')]);
  await login(page, server, 'admin', '/sessions');
  assert.deepEqual(errors, []);
});

test('live: force-limit indicator and events, loop verdict in words, depth plot ticks, Reset confirmed, tweezers only with tweezers', async () => {
  const { page, context, errors } = browser;
  const live = startAgent(server, 30, 'scripted:palpate', { args: ['--trainee', 'dora', '--max-force', '0.3'] });
  agents.push(live);
  let liveId = '';
  for (let i = 0; i < 600 && !liveId; i++) {
    liveId = String((await sessionOf('dora')).find((/** @type {any} */ s) => s.state === 'live')?.id ?? '');
    if (!liveId) await new Promise((r) => setTimeout(r, 100));
  }
  assert.ok(liveId, 'a live session for dora');
  await page.goto(`${server.base}/session/${liveId}`);
  // The palpation reaches 0.3: the indicator lights with a hit; its event is listed by name at its time.
  await page.waitForSelector('#force-limit.lit', { timeout: 30000 });
  assert.match(await page.locator('#force-limit').innerText(), /AT FORCE LIMIT · [1-9]\d* hits?/);
  const event = page.locator('#events li.event.force_limit').first();
  await event.waitFor({ timeout: 10000 });
  const eventText = await event.innerText();
  assert.match(eventText, /^0:0\d\.\d{3} Force limit \(\d+ ticks? clamped\)/);
  assert.notEqual(eventText.slice(0, 8), '0:00.000', 'the event carries its time');
  assert.equal(await page.locator('text=/KIND_/').count(), 0, 'no enum names on the page');
  // The loop in words, under the rule loop_verdict.js states.
  await page.waitForFunction(() => /^(Keeping up|Falling behind)/.test(document.getElementById('loop-verdict')?.textContent ?? ''));
  const verdict = await page.locator('#loop-verdict').innerText();
  const health = await page.locator('#health').innerText();
  const [, overruns, ticks] = /Overruns\s+(\d+) of (\d+) ticks/.exec(health) ?? [];
  if (Number(overruns) === 0) assert.match(verdict, /^Keeping up/, `${verdict} / ${health}`);
  // The press's force against depth: ticks on both axes and units.
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsDepthAxes?.().x.length >= 2);
  const depth = await page.evaluate(() => /** @type {any} */ (window).__idmsDepthAxes());
  assert.ok(depth.x.length >= 2 && depth.y.length >= 2, JSON.stringify(depth));
  assert.deepEqual([depth.xUnit, depth.yUnit], ['model units', 'model force units']);
  // The time plots sit inside their boxes.
  const overflow = await page.$$eval('.plot', (hosts) => hosts.map((host) => {
    const box = host.getBoundingClientRect();
    return [...host.querySelectorAll('canvas')].filter((c) => c.getBoundingClientRect().right > box.right + 1).length;
  }));
  assert.ok(overflow.length >= 3 && overflow.every((n) => n === 0), `canvases outside their plots' boxes: ${overflow}`);
  assert.ok(Number(ticks) > 0);
  await page.evaluate(() => scrollTo(0, 0));
  await docShot(page, 'live-force-limit.png');

  // Commands: a sphere has no tweezers to close; Reset asks first: declined, nothing is sent;
  // accepted, the agent resets (its event, listed as "Reset").
  const buttons = await page.locator('#commands button').allInnerTexts();
  assert.deepEqual(buttons, ['Reset model', 'Request keyframe']);
  page.once('dialog', (d) => d.dismiss());
  await page.click('#commands button:has-text("Reset model")');
  assert.equal((await state(page)).commandsSent, 0);
  page.once('dialog', (d) => { assert.match(d.message(), /Reset the model to rest\?/); d.accept(); });
  await page.click('#commands button:has-text("Reset model")');
  assert.equal((await state(page)).commandsSent, 1);
  // The relayed command's event, in words (the server writes the enum's name into its message).
  await page.waitForSelector('#events li.event.command:has-text("Reset model relayed to the agent")', { timeout: 10000 });
  assert.equal(await page.locator('text=/KIND_/').count(), 0, 'no enum names on the page');
  await page.locator('#commands').scrollIntoViewIfNeeded();
  await docShot(page, 'live-events-commands.png');

  // Tweezers (the pluck's default tool): their commands are offered.
  const pluck = startAgent(server, 20, 'scripted:pluck', { args: ['--trainee', 'erin'] });
  agents.push(pluck);
  let pluckId = '';
  for (let i = 0; i < 600 && !pluckId; i++) {
    pluckId = String((await sessionOf('erin')).find((/** @type {any} */ s) => s.state === 'live')?.id ?? '');
    if (!pluckId) await new Promise((r) => setTimeout(r, 100));
  }
  const tweezersPage = await context.newPage();
  await tweezersPage.goto(`${server.base}/session/${pluckId}`);
  await tweezersPage.waitForSelector('#commands button:has-text("Close tweezers")');
  assert.deepEqual(await tweezersPage.locator('#commands button').allInnerTexts(),
    ['Close tweezers', 'Open tweezers', 'Reset model', 'Request keyframe']);
  await tweezersPage.close();
  live.kill();
  pluck.kill();
  assert.deepEqual(errors, []);
});

test('replay: played to the end and again, the plots keep step with the view and the events are listed once; keys', async () => {
  const { page, errors } = browser;
  await page.goto(`${server.base}/replay/${ids.alice}`);
  await page.waitForFunction(() => Number(/** @type {HTMLInputElement} */ (document.getElementById('seek')).max) > 1);
  const duration = Number(await page.getAttribute('#seek', 'max'));
  /** Plays from where it is to the end. */
  const playToEnd = async () => {
    await page.click('#play');
    await page.waitForSelector('#play[aria-pressed="true"]');
    await page.waitForSelector('#play[aria-pressed="false"]', { timeout: 30000 });
    await page.waitForFunction((d) => Number(new URL(location.href).searchParams.get('t')) >= d - 0.02, duration);
  };
  await playToEnd();
  const events1 = await page.locator('#events li').allInnerTexts();
  assert.ok(events1.length >= 2, events1.join('\n'));
  // Again: from the start, the plots restart with the view (no sample of the last pass, none
  // ahead of the time shown).
  await page.click('#play');
  await page.waitForFunction(() => { const s = /** @type {any} */ (window).__idms; return s.timeS > 0.5 && s.timeS < 1.5; }, undefined, { timeout: 10000 });
  const times = await page.evaluate(() => /** @type {any} */ (window).__idmsForceTimes());
  const now = (await state(page)).timeS;
  assert.ok(times.ordered, `the force plot's times run in order: ${JSON.stringify(times)}`);
  assert.ok(times.max <= now + 0.1, `the force plot reaches ${times.max} s, the view is at ${now} s`);
  await page.waitForSelector('#play[aria-pressed="false"]', { timeout: 30000 });
  const events2 = await page.locator('#events li').allInnerTexts();
  assert.deepEqual(events2, events1, 'the events, once each, after a second pass');
  assert.equal(new Set(events2).size, events2.length);

  // Keys: arrows step 0.1 s, with Shift 1 s; Space plays and pauses.
  const seekTo = (/** @type {number} */ t) => page.evaluate((t) => {
    const slider = /** @type {HTMLInputElement} */ (document.getElementById('seek'));
    slider.value = String(t);
    slider.dispatchEvent(new Event('change'));
  }, t);
  const urlT = (/** @type {string} */ t) => page.waitForFunction((t) => new URL(location.href).searchParams.get('t') === t, t, { timeout: 5000 });
  await seekTo(0.5);
  await urlT('0.50');
  await page.focus('#seek');
  await page.keyboard.press('ArrowRight');
  await urlT('0.60');
  await page.keyboard.press('Shift+ArrowRight');
  await urlT('1.60');
  await page.keyboard.press('ArrowLeft');
  await urlT('1.50');
  await page.locator('h1').click();
  await page.keyboard.press('Space');
  await page.waitForSelector('#play[aria-pressed="true"]');
  await page.keyboard.press('Space');
  await page.waitForSelector('#play[aria-pressed="false"]');
  assert.deepEqual(errors, []);
});

test('phone: the lists are cards with their figures in sight; the model page\'s buttons at 1280 px; a favicon, no 404', async () => {
  const { page, errors } = browser;
  /** @type {string[]} */
  const failed = [];
  const onResponse = (/** @type {import('playwright-core').Response} */ r) => { if (r.status() >= 400) failed.push(`${r.status()} ${r.url()}`); };
  page.on('response', onResponse);
  try {
    await page.setViewportSize({ width: 390, height: 844 });
    await page.goto(`${server.base}/sessions`);
    await page.waitForSelector(`#sessions tr[data-id="${ids.aliceLimited}"]`);
    assert.deepEqual(await tooWide(page), [], 'wider than a 390 px screen');
    // A card: the trainee, the figures and the delete button within the screen's width.
    const cells = await page.$$eval(`#sessions tr[data-id="${ids.aliceLimited}"] td`, (tds) => tds
      .filter((td) => /** @type {HTMLElement} */ (td).dataset.label)
      .map((td) => ({ label: /** @type {HTMLElement} */ (td).dataset.label, left: td.getBoundingClientRect().left, right: td.getBoundingClientRect().right })));
    const out = cells.filter((c) => c.left < 0 || c.right > 390);
    assert.deepEqual(out, [], 'cells outside the screen');
    assert.ok(cells.some((c) => c.label === 'Trainee') && cells.some((c) => c.label === 'Peak force (model force units)'));
    const box = await page.$eval('#sessions', (t) => ({ scroll: t.parentElement?.scrollWidth ?? 0, client: t.parentElement?.clientWidth ?? 0 }));
    assert.ok(box.scroll <= box.client, `the table scrolls sideways: ${JSON.stringify(box)}`);
    await docShot(page, 'sessions-phone.png');
    await page.goto(`${server.base}/trainee/alice`);
    await page.waitForFunction(() => /** @type {any} */ (window).__idmsTrainee?.points === 2);
    assert.deepEqual(await tooWide(page), [], 'the trainee page is wider than a 390 px screen');
    await docShot(page, 'trainee-phone.png');

    // The model page at 1280 px: Preview and Delete on screen.
    await page.setViewportSize({ width: 1280, height: 720 });
    await page.goto(`${server.base}/models/hex_4x5_home`);
    await page.waitForFunction(() => /** @type {any} */ (window).__idmsPreview?.vertices > 0);
    for (const name of ['Preview', 'Delete']) {
      const r = await page.locator(`#versions button:has-text("${name}")`).first().boundingBox();
      assert.ok(r && r.x >= 0 && r.x + r.width <= 1280 && r.y + r.height <= 720, `${name} at ${JSON.stringify(r)}`);
    }
    await docShot(page, 'model-buttons.png');

    // The favicon the pages name is served as an image.
    const href = await page.getAttribute('link[rel=icon]', 'href');
    assert.ok(href);
    const icon = await fetch(server.base + href);
    assert.equal(icon.status, 200);
    assert.match(icon.headers.get('content-type') ?? '', /^image\/svg\+xml/);
    assert.deepEqual(failed, [], 'requests that failed');
  } finally {
    page.off('response', onResponse);
  }
  assert.deepEqual(errors, []);
});
