// Time plots of the last seconds at the full 1 kHz (thesis figures 6-2 to 6-8): uPlot over
// preallocated Float64Arrays that slide in place. Samples are pushed as they arrive; the plot is
// redrawn in the page's frame (FrameLoop), at most kPlotRedrawHz times a second, only when samples
// came and only while it is on screen.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { FrameLoop, Visibility, isDue } from '../view/frame_loop.js';
import { decimateMinMax } from './decimate.js';

/**
 * Plots redraw at most this often; samples still arrive and are kept at 1 kHz. 10 Hz moves a
 * 5 s window by 0.1 s a step, which reads as smooth; 20 Hz doubled the plots' share of a frame.
 */
export const kPlotRedrawHz = 10;

/**
 * Runs `make` with every 2D canvas it creates backed by the CPU (willReadFrequently), and returns
 * what it made. A plot of a few thousand line segments rasterises in about a millisecond on the
 * CPU; on a GPU-accelerated canvas each redraw is rasterised in the GPU process, which on a
 * machine without a GPU (software GL, as headless Chromium's SwiftShader) is the same process
 * that draws the 3D view: measured there, the two plots at 20 Hz added ~60 ms of GPU-process time
 * per 3D frame, and with CPU canvases nothing. uPlot makes its canvas itself, hence the request
 * made while it does; the prototype is restored at once.
 * @template T
 * @param {() => T} make
 * @returns {T}
 */
export function withCpuCanvases(make) {
  const proto = HTMLCanvasElement.prototype;
  const getContext = proto.getContext;
  /** @type {any} */ (proto).getContext = function (/** @type {string} */ type, /** @type {any} */ attrs) {
    return getContext.call(this, type, type === '2d' ? { ...attrs, willReadFrequently: true } : attrs);
  };
  try {
    return make();
  } finally {
    proto.getContext = getContext;
  }
}

export class RollingPlot {
  /**
   * @param {HTMLElement} host
   * @param {{title: string, unit: string, axis: string, series: {label: string, color: string}[], capacity: number}} spec
   *   axis: the value axis's short name (the unit is in the title)
   * @param {FrameLoop} [loop] the page's frame loop
   */
  constructor(host, spec, loop = new FrameLoop()) {
    this.loop = loop;
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
    this.lastDraw = -1e9;
    /** Samples in the picture on screen, and the times of its first and last, s (the tests read them). */
    this.shown = 0;
    this.shownFirstS = NaN;
    this.shownLastS = NaN;
    /** Redraws and the time they took, ms (the bench reads them). */
    this.draws = 0;
    this.drawMs = 0;
    // What uPlot draws when the samples outnumber what the plot's width can show: the samples
    // reduced per pixel column (decimateMinMax), and views of it, made again only when the count
    // changes (not per redraw once the window is full and the width settled).
    /** @type {Float64Array[]} */
    this.reduced = [];
    /** @type {Float64Array[]} */
    this.views = [];
    this.viewsOf = /** @type {Float64Array[] | null} */ (null);
    this.viewsLength = -1;
    const width = Math.max(200, host.clientWidth || 400);
    this.plot = withCpuCanvases(() => new uPlot({
      // The unit in the title: a vertical axis label 170 px tall cuts "model force units" short.
      title: `${spec.title} (${spec.unit})`,
      width,
      height: 170,
      // A flat series (no force yet) spans +-1 around its value, where uPlot's default made 0 to
      // 100 of a zero force, as if it had been large.
      scales: { x: { time: false }, y: { range: (_u, min, max) => (min === max ? [min - 1, max + 1] : uPlot.rangeNum(min, max, 0.1, true)) } },
      legend: { live: false },
      cursor: { show: false },
      series: [{ label: 't (s)' }, ...spec.series.map((s) => ({ label: s.label, stroke: s.color, width: 1, points: { show: false } }))],
      axes: [{ label: 'session time (s)' }, { label: spec.axis, size: 60 }],
    }, [[], ...spec.series.map(() => [])], host));
    this.visibility = new Visibility(host, () => loop.request());
    loop.add(this);
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
    this.loop.request();
  }

  /**
   * The title's unit, once the session says what its units are (the samples pushed after are in
   * it: the caller converts). @param {string} title @param {string} unit
   */
  setTitle(title, unit) {
    const el = this.plot.root.querySelector('.u-title');
    if (el) el.textContent = `${title} (${unit})`;
  }

  /** Forgets everything (a seek in a replay, a new session). */
  clear() {
    this.numPending = 0;
    this.length = 0;
    this.shown = 0;
    this.shownFirstS = this.shownLastS = NaN;
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

  /**
   * The frame loop's part: a redraw when samples came, the plot is on screen and its rate allows.
   * @param {number} now ms @returns {boolean} still to draw in a later frame
   */
  draw(now) {
    if (this.numPending === 0 || !this.visibility.visible) return false;
    if (!isDue(this.lastDraw, now, kPlotRedrawHz)) return true;
    this.lastDraw = now;
    const start = performance.now();
    this.flush();
    // Four points per pixel column at most: uPlot's time goes with the points it is given.
    const width = Math.max(1, Math.round(this.plot.bbox.width));
    let data = this.columns;
    let n = this.length;
    if (n > 4 * (width + 1)) {
      if (this.reduced.length === 0 || this.reduced[0].length < 4 * (width + 1)) {
        this.reduced = this.columns.map(() => new Float64Array(4 * (width + 1)));
      }
      n = decimateMinMax(this.columns, n, width, this.reduced);
      data = this.reduced;
    }
    // batch: drawn now, in this frame (setData alone draws in a microtask).
    const views = this.viewsFor(data, n);
    this.plot.batch(() => this.plot.setData(/** @type {any} */ (views)));
    this.drawMs += performance.now() - start;
    this.draws++;
    this.shown = this.length;
    this.shownFirstS = this.columns[0][0];
    this.shownLastS = this.columns[0][this.length - 1];
    return false;
  }

  /**
   * The first n values of each column, as uPlot takes them; the same views while n and the
   * columns are the same.
   * @param {Float64Array[]} data @param {number} n
   */
  viewsFor(data, n) {
    if (data !== this.viewsOf || n !== this.viewsLength) {
      this.views = data.map((col) => (n === col.length ? col : col.subarray(0, n)));
      this.viewsOf = data;
      this.viewsLength = n;
    }
    return this.views;
  }

  dispose() {
    this.loop.remove(this);
    this.visibility.dispose();
    this.resizeObserver.disconnect();
    this.plot.destroy();
  }
}
