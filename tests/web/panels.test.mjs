// The session page's pure rules: the loop-health verdict (loop_verdict.js), the replay's key
// steps (timeline.js's keyTarget) and the canvas plots' ticks (plots/ticks.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { LoopWatch, verdict } from '../../viewer-web/src/pages/loop_verdict.js';
import { keyTarget } from '../../viewer-web/src/pages/timeline.js';
import { niceTicks, tickLabel } from '../../viewer-web/src/plots/ticks.js';

test('the loop falls behind when more than 1 % of the last second\'s ticks overran, and says so in words', () => {
  const watch = new LoopWatch(1000);
  assert.equal(watch.update({ ticks: 0, overruns: 0 }).state, 'unknown');
  // The first second: 5 of 1000 overran (0.5 %): keeping up.
  let v = watch.update({ ticks: 1000, overruns: 5, periodP99Us: 1010 });
  assert.equal(v.state, 'ok', v.text);
  assert.match(v.text, /^Keeping up/);
  // The next second: 30 more of 1000 (3 %): falling behind, with the share and the rule.
  v = watch.update({ ticks: 2000, overruns: 35, periodP99Us: 1400 });
  assert.equal(v.state, 'behind', v.text);
  assert.match(v.text, /^Falling behind: 3\.0 % of ticks in the last second overran their 1000 µs deadline \(more than 1\.0 %\)/);
  // Within a window the last complete one stands.
  assert.equal(watch.update({ ticks: 2500, overruns: 35, periodP99Us: 1400 }).state, 'behind');
  // A clean second after: keeping up now, behind earlier (3.5 % of all ticks overran).
  v = watch.update({ ticks: 3000, overruns: 35, periodP99Us: 1400 });
  assert.equal(v.state, 'earlier', v.text);
  assert.match(v.text, /^Keeping up now; fell behind earlier/);
  // A seek back (the counts go down) starts again: the whole so far stands until a window is full.
  v = watch.update({ ticks: 400, overruns: 0, periodP99Us: 1000 });
  assert.equal(v.state, 'ok', v.text);
  // The period p99 alone: over 1.5 periods is behind earlier, not now.
  assert.equal(verdict({ ticks: 5000, overruns: 0, periodP99Us: 1600, recentTicks: 1000, recentOverruns: 0, nominalUs: 1000 }).state, 'earlier');
  assert.equal(verdict({ ticks: 5000, overruns: 0, periodP99Us: 1400, recentTicks: 1000, recentOverruns: 0, nominalUs: 1000 }).state, 'ok');
  // At another rate the deadline is its period.
  assert.match(verdict({ ticks: 5000, overruns: 500, periodP99Us: 600, recentTicks: 1000, recentOverruns: 100, nominalUs: 500 }).text,
    /500 µs deadline.*2000 Hz/);
});

test('replay keys: arrows 0.1 s, Shift 1 s, Page 10 s, Home and End, within the recording on the 1 ms grid', () => {
  assert.equal(keyTarget('ArrowRight', false, 1.234, 20), 1.334);
  assert.equal(keyTarget('ArrowLeft', false, 1.234, 20), 1.134);
  assert.equal(keyTarget('ArrowUp', true, 1.234, 20), 2.234);
  assert.equal(keyTarget('ArrowDown', true, 0.5, 20), 0);
  assert.equal(keyTarget('PageUp', false, 15, 20), 20);
  assert.equal(keyTarget('PageDown', false, 15, 20), 5);
  assert.equal(keyTarget('Home', false, 15, 20), 0);
  assert.equal(keyTarget('End', false, 1, 20), 20);
  assert.equal(keyTarget('a', false, 1, 20), null);
  assert.equal(keyTarget(' ', false, 1, 20), null);
});

test('canvas ticks: round steps that cover the range, labelled with the digits their step needs', () => {
  for (const [lo, hi] of [[0, 0.0634], [0, 1.71], [0, 8], [-0.013, 0.06], [0, 1e-3], [0, 123]]) {
    const t = niceTicks(lo, hi, 5);
    assert.ok(t.bottom <= lo && t.top >= hi, `${lo}..${hi}: ${JSON.stringify(t)}`);
    assert.ok(t.ticks.length >= 2 && t.ticks.length <= 8, `${lo}..${hi}: ${t.ticks}`);
    const mantissa = t.step / 10 ** Math.floor(Math.log10(t.step) + 1e-9);
    assert.ok([1, 2, 2.5, 5].some((m) => Math.abs(mantissa - m) < 1e-9), `step ${t.step}`);
    const labels = t.ticks.map((v) => tickLabel(v, t.step));
    assert.equal(new Set(labels).size, labels.length, `distinct labels: ${labels}`);
  }
  assert.deepEqual(niceTicks(0, 8, 5).ticks.map((v) => tickLabel(v, 2)), ['0', '2', '4', '6', '8']);
  const small = niceTicks(0, 0.0634, 5);
  assert.deepEqual(small.ticks.map((v) => tickLabel(v, small.step)), ['0.00', '0.02', '0.04', '0.06', '0.08']);
});
