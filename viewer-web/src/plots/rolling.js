// Time plots of the last seconds at the full 1 kHz (thesis figures 6-2 to 6-8): uPlot over
// preallocated Float64Arrays that slide in place. Samples are pushed as they arrive; the plot is
// redrawn in an animation frame, at most kRedrawHz times a second, and only when samples came.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';

// Plots redraw at most this often; samples still arrive and are kept at 1 kHz.
const kRedrawHz = 20;

export class RollingPlot {
  /**
   * @param {HTMLElement} host
   * @param {{title: string, unit: string, series: {label: string, color: string}[], capacity: number}} spec
   */
  constructor(host, spec) {
    this.capacity = spec.capacity;
    this.numSeries = spec.series.length;
    // Column 0 is time; the pending ring holds samples not yet drawn.
    /** @type {Float64Array[]} */
    this.columns = [];
    for (let c = 0; c <= this.numSeries; c++) this.columns.push(new Float64Array(this.capacity));
    this.pending = new Float64Array(this.capacity * (this.numSeries + 1));
    this.numPending = 0;
    this.length = 0;
    this.total = 0;
    this.frameRequested = false;
    this.lastDraw = 0;
    this.drawCallback = () => this.draw();
    /** @type {any[]} */
    this.fullData = this.columns;
    const width = Math.max(200, host.clientWidth || 400);
    this.plot = new uPlot({
      title: spec.title,
      width,
      height: 170,
      scales: { x: { time: false } },
      legend: { live: false },
      cursor: { show: false },
      series: [{ label: 't (s)' }, ...spec.series.map((s) => ({ label: s.label, stroke: s.color, width: 1, points: { show: false } }))],
      axes: [{ label: 'session time (s)' }, { label: spec.unit, size: 60 }],
    }, [[], ...spec.series.map(() => [])], host);
    this.resizeObserver = new ResizeObserver(() => this.plot.setSize({ width: Math.max(200, host.clientWidth), height: 170 }));
    this.resizeObserver.observe(host);
  }

  /**
   * One sample: time and a value per series. Allocates nothing.
   * @param {number} t @param {number} a @param {number} [b] @param {number} [c] @param {number} [d]
   */
  push(t, a, b = 0, c = 0, d = 0) {
    const w = this.numSeries + 1;
    if (this.numPending === this.capacity) this.flush();
    const o = this.numPending * w;
    this.pending[o] = t;
    this.pending[o + 1] = a;
    if (w > 2) this.pending[o + 2] = b;
    if (w > 3) this.pending[o + 3] = c;
    if (w > 4) this.pending[o + 4] = d;
    this.numPending++;
    this.total++;
    if (!this.frameRequested) {
      this.frameRequested = true;
      // At most kRedrawHz: a software-rastered page spends its CPU on the 3D view instead.
      const wait = Math.max(0, this.lastDraw + 1000 / kRedrawHz - performance.now());
      if (wait > 0) setTimeout(() => requestAnimationFrame(this.drawCallback), wait);
      else requestAnimationFrame(this.drawCallback);
    }
  }

  /** Forgets everything (a seek in a replay, a new session). */
  clear() {
    this.numPending = 0;
    this.length = 0;
    this.plot.setData([[], ...this.columns.slice(1).map(() => [])]);
  }

  /** Moves pending samples into the columns: one copyWithin per column, then the new values. */
  flush() {
    const k = this.numPending;
    if (k === 0) return;
    const w = this.numSeries + 1;
    const keep = Math.min(this.length, this.capacity - k);
    for (let c = 0; c < w; c++) {
      const col = this.columns[c];
      if (keep > 0 && this.length > keep) col.copyWithin(0, this.length - keep, this.length);
      for (let i = 0; i < k; i++) col[keep + i] = this.pending[i * w + c];
    }
    this.length = keep + k;
    this.numPending = 0;
  }

  draw() {
    this.frameRequested = false;
    this.lastDraw = performance.now();
    this.flush();
    // Views while the window fills (the first seconds only), then the full columns themselves.
    const data = this.length === this.capacity ? this.fullData : this.columns.map((col) => col.subarray(0, this.length));
    this.plot.setData(/** @type {any} */ (data));
  }

  dispose() {
    this.resizeObserver.disconnect();
    this.plot.destroy();
  }
}
