// Comparing, grading and reporting, against the real server and agents (issue 28): two sessions
// graded against their scenes' limits show their marks in the list and on their pages; picked in
// the list they open side by side, replayed in step by one timeline, their whole-session force
// overlaid; a session's one-page report holds its figures, grade, the tissue at the peak force,
// the force over the session and its notes, and prints to exactly one A4 page.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { Server, tempDir, launchBrowser, login, startAgent, artifacts, sourceDir, docShot } from './harness.mjs';

/** @type {Server} */
let server;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {ReturnType<typeof startAgent>[]} */
const agents = [];
/** The tight scene's session (fails its peak-force limit) and the loose one's (passes). */
const ids = { failed: '', passed: '' };

/**
 * The palpation scene with a grading block (and more lines).
 * @param {string} dir @param {string} name @param {string} grading @param {string} [more]
 */
function gradedScene(dir, name, grading, more = '') {
  const text = readFileSync(join(sourceDir(), 'models', 'palpate.scene'), 'utf8')
    .replace(/^recording: true$/m, `recording: true\ngrading { ${grading} }\n${more}`);
  assert.match(text, /grading/);
  const file = join(dir, `${name}.scene`);
  writeFileSync(file, text);
  return file;
}

before(async () => {
  const dir = tempDir('compare');
  server = await new Server(join(dir, 'server')).start();
  browser = await launchBrowser();
  // The palpation's peak is about 1.7 force units: a 1.0 limit fails it, 5.0 passes it.
  const tight = gradedScene(dir, 'tight', 'max_peak_force: 1.0 max_force_limit_hits: 0');
  // The loose scene also says what its units are (the thesis's model is in inches; a PHANToM's
  // forces are in N): its pages show mm and N.
  const loose = gradedScene(dir, 'loose', 'max_peak_force: 5.0 max_contact_time_s: 60',
    'units { mm_per_unit: 25.4 newtons_per_force_unit: 1 }');
  const runs = [
    startAgent(server, 3, 'scripted:palpate', { args: ['--scene', tight, '--trainee', 'carol'] }),
    startAgent(server, 2.5, 'scripted:palpate', { args: ['--scene', loose, '--trainee', 'dan'] }),
  ];
  agents.push(...runs);
  for (const run of runs) assert.equal(await run.exited, 0, run.log());
  const { body } = await server.get('/api/sessions');
  const sessions = JSON.parse(body).sessions;
  ids.failed = String(sessions.find((/** @type {any} */ s) => s.trainee === 'carol')?.id ?? '');
  ids.passed = String(sessions.find((/** @type {any} */ s) => s.trainee === 'dan')?.id ?? '');
  assert.ok(ids.failed && ids.passed, body);
  const grades = Object.fromEntries(sessions.map((/** @type {any} */ s) => [s.trainee, s.grade?.passed]));
  assert.deepEqual(grades, { carol: false, dan: true }, body);
});
after(async () => {
  for (const a of agents) a.kill();
  await browser?.context.close();
  await server?.stop();
});

test('grading: each session\'s mark in the list and its checks on its page', async () => {
  const { page, errors } = browser;
  await login(page, server, 'admin', '/sessions');
  const failed = page.locator(`#sessions tr[data-id="${ids.failed}"] .badge.grade`);
  const passed = page.locator(`#sessions tr[data-id="${ids.passed}"] .badge.grade`);
  await failed.waitFor();
  assert.equal(await failed.innerText(), 'failed');
  assert.match(await failed.getAttribute('title') ?? '', /peak force \d+\.\d+ > 1\.00/);
  assert.equal(await passed.innerText(), 'passed');
  // The session that declares its units shows them; the other its model's.
  const peak = (/** @type {string} */ id) => page.locator(`#sessions tr[data-id="${id}"] td[data-label^="Peak force"]`).innerText();
  const path = (/** @type {string} */ id) => page.locator(`#sessions tr[data-id="${id}"] td[data-label^="Path"]`).innerText();
  assert.match(await peak(ids.passed), /^1\.\d\d N$/);
  assert.match(await peak(ids.failed), /^1\.\d\d$/);
  assert.match(await path(ids.passed), /^2\d\.\d\d mm$/);  // about 1.06 inches
  assert.match(await path(ids.failed), /^1\.\d\d$/);
  await docShot(page, 'sessions-graded.png');
  await page.goto(`${server.base}/replay/${ids.failed}`);
  await page.waitForSelector('#grade .grade-checks li.failed');
  const checks = await page.locator('#grade .grade-checks').innerText();
  assert.match(checks, /✗ beyond peak force \d+\.\d+ > 1\.00 model force units/);
  assert.match(checks, /✓ within force-limit hits 0 ≤ 0/);
  // In the units its scene declares: the plots, the depth plot's axes, the legend and the grade.
  await page.goto(`${server.base}/replay/${ids.passed}`);
  await page.waitForSelector('#grade .grade-checks li.passed');
  assert.match(await page.locator('#grade .grade-checks').innerText(), /✓ within peak force 1\.\d\d ≤ 5\.00 N/);
  await page.waitForFunction(() => (document.querySelector('#force-plot .u-title')?.textContent ?? '').includes('(N)'));
  assert.match(await page.locator('#position-plot .u-title').innerText(), /Tool position \(mm\)/);
  await page.waitForFunction(() => /** @type {any} */ (window).__idms?.keyframes >= 1);
  const axes = await page.evaluate(() => /** @type {any} */ (window).__idmsDepthAxes());
  assert.equal(axes.xUnit, 'mm');
  assert.equal(axes.yUnit, 'N');
  assert.match(await page.locator('#view3d').innerText(), /displacement\s+mm/);
  assert.deepEqual(errors, []);
});

test('compare: two sessions picked in the list, side by side, one timeline plays both in step, force overlaid', async () => {
  const { page, errors } = browser;
  await page.goto(`${server.base}/sessions`);
  await page.check(`input[data-compare="${ids.failed}"]`);
  await page.check(`input[data-compare="${ids.passed}"]`);
  const link = page.locator('#compare-link');
  assert.equal(await link.getAttribute('href'), `/compare/${ids.failed}/${ids.passed}`);
  await Promise.all([page.waitForURL((u) => u.pathname.startsWith('/compare/')), link.click()]);
  /** @returns {Promise<any>} */
  const seen = () => page.evaluate(() => /** @type {any} */ (window).__idmsCompare());
  await page.waitForFunction(() => {
    const c = /** @type {any} */ (window).__idmsCompare?.();
    return c && c.sides.every((/** @type {any} */ s) => s.keyframes >= 1) && c.profilePoints.every((/** @type {number} */ n) => n > 100);
  }, undefined, { timeout: 20000 }).catch(() => {});
  const opened = await seen();
  assert.ok(opened.sides.every((/** @type {any} */ s) => s.keyframes >= 1), `both surfaces drawn: ${JSON.stringify(opened)}`);
  assert.ok(opened.profilePoints.every((/** @type {number} */ n) => n > 100), `both force profiles: ${JSON.stringify(opened)}`);
  // The figures side by side, the grades among them; the longer session (A, 3 s) leads.
  const figures = await page.locator('#compare-figures').innerText();
  assert.match(figures, /Grade\s+failed\s+passed/);
  assert.match(figures, /Trainee\s+carol\s+dan/);
  assert.match(figures, /Peak force\s+1\.\d\d model force units\s+1\.\d\d N/);
  assert.match(figures, /Path length\s+1\.\d\d model units\s+2\d\.\d\d mm/);
  assert.equal((await seen()).lead, 0);
  // Played from 0.5 s: both replays advance together.
  await page.evaluate(() => {
    const slider = /** @type {HTMLInputElement} */ (document.getElementById('seek'));
    slider.value = '0.5';
    slider.dispatchEvent(new Event('change'));
  });
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsCompare().sides.every((/** @type {any} */ s) => Math.abs((s.state?.timeS ?? 0) - 0.5) < 0.05));
  await page.click('#play');
  await page.waitForFunction(() => /** @type {any} */ (window).__idmsCompare().sides.every((/** @type {any} */ s) => s.timeS > 1.6),
    undefined, { timeout: 15000 });
  const c = await seen();
  const [a, b] = c.sides;
  assert.ok(Math.abs(a.timeS - b.timeS) < 0.35, `in step: A at ${a.timeS} s, B at ${b.timeS} s`);
  assert.ok(a.deltas > 0 && b.deltas > 0, JSON.stringify(c.sides));
  assert.ok(c.markS > 1, `the profile marks the time played: ${c.markS}`);
  await page.click('#play');
  await page.waitForSelector('#play[aria-pressed="false"]');
  await docShot(page, 'compare.png');
  // One column on a phone.
  await page.setViewportSize({ width: 390, height: 844 });
  const [va, vb] = await Promise.all(['#view-A', '#view-B'].map((s) => page.locator(s).boundingBox()));
  assert.ok(va && vb && vb.y > va.y + va.height - 1, `stacked: ${JSON.stringify([va, vb])}`);
  await page.setViewportSize({ width: 1280, height: 720 });
  assert.deepEqual(errors, []);
});

test('report: one page with the figures, grade, the tissue at the peak, the force and the notes; prints to one A4 page', async () => {
  const { page, errors } = browser;
  // Two notes (one in replay, one long), so the report has some.
  for (const [t, text] of [[0.9, 'pressing deeper than needed'], [2.1, 'released cleanly']]) {
    const res = await fetch(`${server.base}/api/sessions/${ids.failed}/notes`, { method: 'POST',
      headers: { Authorization: `Bearer ${server.token('admin')}`, 'Content-Type': 'application/json' }, body: JSON.stringify({ time_s: t, text }) });
    assert.equal(res.status, 201, await res.text());
  }
  await page.goto(`${server.base}/sessions`);
  await Promise.all([page.waitForURL((u) => u.pathname === `/report/${ids.failed}`),
    page.click(`#sessions tr[data-id="${ids.failed}"] a.report-link`)]);
  await page.waitForFunction(() => { const r = /** @type {any} */ (window).__idmsReport; return r?.loaded && r.pictureLoaded; },
    undefined, { timeout: 30000 });
  const r = await page.evaluate(() => /** @type {any} */ (window).__idmsReport);
  assert.equal(r.notes, 2);
  assert.ok(r.profilePoints > 100, JSON.stringify(r));
  const figures = await page.locator('#report-figures').innerText();
  assert.match(figures, /Peak force\s+1\.\d\d model force units/);
  assert.match(await page.locator('#report-who').innerText(), /Trainee\s+carol/);
  assert.match(await page.locator('#report-grade').innerText(), /failed/);
  const notes = await page.locator('#report-notes').innerText();
  assert.ok(notes.indexOf('pressing deeper') < notes.indexOf('released cleanly'), notes);
  // The picture is the server's rendering at the peak's time.
  const src = await page.locator('#report-picture img').getAttribute('src') ?? '';
  assert.match(src, new RegExp(`/api/sessions/${ids.failed}/screenshot\\.png\\?t=${r.peakS.toFixed(3)}&size=480x270`));
  await docShot(page, 'report.png');
  // Printed (as "Save as PDF" does): one A4 page, without the site's header or buttons.
  const pdf = Buffer.from(await page.pdf({ format: 'A4' }));
  writeFileSync(join(artifacts(), 'report.pdf'), pdf);
  const text = pdf.toString('latin1');
  const pages = (text.match(/\/Type\s*\/Page[^s]/g) ?? []).length;
  assert.equal(pages, 1, `the report printed on ${pages} pages`);
  // What the page looks like on paper (A4 at 96 dpi less the margins), for docs/web.
  await page.emulateMedia({ media: 'print' });
  await page.setViewportSize({ width: 703, height: 1032 });
  await docShot(page, 'report-print.png');
  await page.emulateMedia({ media: 'screen' });
  await page.setViewportSize({ width: 1280, height: 720 });
  assert.deepEqual(errors, []);
});
