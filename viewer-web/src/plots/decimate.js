// A dense time series reduced to what a line plot of a given width draws (pure: no DOM), so that
// the 1 kHz plots hand uPlot a few points per pixel column instead of every sample.

/**
 * Reduces samples to what a line plot `width` pixels wide draws: for each pixel column, the
 * first, lowest, highest and last value of every series (M4: the same picture, uPlot drawing each
 * column of a denser line as its entry, extent and exit anyway). Column k holds the samples that
 * land nearest pixel k of [x[0], x[n-1]] mapped onto [0, width], as the plot rounds them; its four
 * points spread over its samples' time span, in order. Allocates nothing.
 * @param {Float64Array[]} src columns (0 = time, ascending), n samples each
 * @param {number} n @param {number} width pixels
 * @param {Float64Array[]} dst as many columns as src, capacity >= 4 * (width + 1) each
 * @returns {number} points written
 */
export function decimateMinMax(src, n, width, dst) {
  const x = src[0];
  const t0 = x[0];
  const scale = width / Math.max(x[n - 1] - t0, 1e-12);
  const w = src.length;
  let out = 0;
  for (let i = 0; i < n;) {
    // One column: samples [i, j).
    const col = Math.floor((x[i] - t0) * scale + 0.5);
    let j = i + 1;
    while (j < n && Math.floor((x[j] - t0) * scale + 0.5) === col) j++;
    if (j - i <= 4) {
      for (let k = i; k < j; k++, out++) for (let c = 0; c < w; c++) dst[c][out] = src[c][k];
    } else {
      const xa = x[i], xb = x[j - 1];
      dst[0][out] = xa;
      dst[0][out + 1] = xa + (xb - xa) / 3;
      dst[0][out + 2] = xa + (2 * (xb - xa)) / 3;
      dst[0][out + 3] = xb;
      for (let c = 1; c < w; c++) {
        const v = src[c];
        let lo = v[i], hi = v[i];
        for (let k = i + 1; k < j; k++) {
          const y = v[k];
          if (y < lo) lo = y;
          else if (y > hi) hi = y;
        }
        const d = dst[c];
        d[out] = v[i];
        d[out + 1] = lo;
        d[out + 2] = hi;
        d[out + 3] = v[j - 1];
      }
      out += 4;
    }
    i = j;
  }
  return out;
}
