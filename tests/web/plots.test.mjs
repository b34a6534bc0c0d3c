// The plots' pure part: decimateMinMax keeps, for every pixel column, the first, lowest, highest
// and last value of every series, so the line drawn from it is the line drawn from every sample.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { decimateMinMax } from '../../viewer-web/src/plots/decimate.js';

/**
 * Per pixel column (as the plot rounds x), per series: [first, min, max, last].
 * @param {Float64Array[]} cols @param {number} n @param {number} width @param {number} t0 @param {number} t1
 */
function columnsOf(cols, n, width, t0, t1) {
  /** @type {Map<number, number[][]>} */
  const out = new Map();
  for (let i = 0; i < n; i++) {
    const px = Math.round(((cols[0][i] - t0) / (t1 - t0)) * width);
    const per = out.get(px) ?? cols.slice(1).map((c) => [c[i], c[i], c[i], c[i]]);
    cols.slice(1).forEach((c, s) => {
      per[s][1] = Math.min(per[s][1], c[i]);
      per[s][2] = Math.max(per[s][2], c[i]);
      per[s][3] = c[i];
    });
    out.set(px, per);
  }
  return out;
}

test('a 1 kHz window reduced to 4 points per pixel column keeps every column\'s entry, extent and exit', () => {
  const n = 5000, width = 317;
  // A rolling window: times from 12.345 s at 1 kHz with a little jitter; a smooth force, a step,
  // and noise.
  const cols = [0, 1, 2, 3].map(() => new Float64Array(n));
  let seed = 7;
  const rand = () => ((seed = (seed * 1103515245 + 12345) % 2 ** 31) / 2 ** 31);
  for (let i = 0; i < n; i++) {
    cols[0][i] = 12.345 + i / 1000 + 1e-5 * rand();
    cols[1][i] = Math.sin(i / 300);
    cols[2][i] = i > 2500 ? 1 : 0;
    cols[3][i] = rand() - 0.5;
  }
  const dst = cols.map(() => new Float64Array(4 * (width + 1)));
  const m = decimateMinMax(cols, n, width, dst);
  assert.ok(m <= 4 * (width + 1) && m < n / 3, `${m} points`);
  for (let i = 1; i < m; i++) assert.ok(dst[0][i] > dst[0][i - 1], `time ascends at ${i}`);
  assert.equal(dst[0][0], cols[0][0]);
  assert.equal(dst[0][m - 1], cols[0][n - 1]);
  const t0 = cols[0][0], t1 = cols[0][n - 1];
  assert.deepEqual(columnsOf(dst, m, width, t0, t1), columnsOf(cols, n, width, t0, t1));
});

test('columns of four samples or fewer pass through as they are', () => {
  const cols = [new Float64Array([0, 1, 2, 3, 4, 5]), new Float64Array([5, 3, 4, 1, 2, 0])];
  const dst = cols.map(() => new Float64Array(64));
  const m = decimateMinMax(cols, 6, 10, dst);
  assert.equal(m, 6);
  assert.deepEqual([...dst[0].subarray(0, m)], [...cols[0]]);
  assert.deepEqual([...dst[1].subarray(0, m)], [...cols[1]]);
});
