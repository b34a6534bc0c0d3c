// Force against depth while pressing (thesis fig. 6-3): for the current or last press, |F|
// against how far the tool has gone along the force's line since contact began. A plain canvas
// over preallocated arrays, redrawn in the page's frame (FrameLoop) as often as the time plots,
// only when it changed and only while it is on screen; axes with round ticks and units, the
// line clipped to its frame.
import { FrameLoop, Visibility, isDue } from '../view/frame_loop.js';
import { kPlotRedrawHz } from './rolling.js';
import { length3 } from '../length3.js';
import { niceTicks, tickLabel } from './ticks.js';

/** The canvas's height, CSS pixels (as the time plots'). */
const kHeight = 170;

export class DepthPlot {
  /**
   * @param {HTMLElement} host
   * @param {number} capacity samples kept per press
   * @param {FrameLoop} [loop] the page's frame loop
   * @param {{force: string, length: string}} [units] the axes' units
   */
  constructor(host, capacity, loop = new FrameLoop(), units = { force: 'force', length: 'length' }) {
    this.loop = loop;
    this.units = units;
    /** The last picture's axes (the tests read them): tick labels and the frame, CSS pixels. */
    this.axes = { x: /** @type {string[]} */ ([]), y: /** @type {string[]} */ ([]), frame: { left: 0, top: 0, right: 0, bottom: 0 } };
    this.canvas = document.createElement('canvas');
    this.canvas.setAttribute('role', 'img');
    this.canvas.setAttribute('aria-label', 'Force magnitude against pressing depth for the current press');
    this.canvas.height = kHeight;
    this.canvas.style.width = '100%';
    this.canvas.style.height = `${kHeight}px`;
    host.append(this.canvas);
    // Redrawn at its box's width whenever that changes (kept here: no layout read per frame); the
    // box's width now, so that a plot below the fold is not left drawn at a placeholder's width,
    // stretched, until the observer's first report.
    this.width = Math.max(100, Math.round(host.clientWidth));
    this.resizeObserver = new ResizeObserver((entries) => {
      this.width = Math.max(100, Math.round(entries[entries.length - 1].contentRect.width));
      this.invalidate();
    });
    this.resizeObserver.observe(host);
    // Rasterised by the CPU, as the time plots are (withCpuCanvases says why).
    this.ctx = /** @type {CanvasRenderingContext2D} */ (this.canvas.getContext('2d', { willReadFrequently: true }));
    this.depth = new Float32Array(capacity);
    this.force = new Float32Array(capacity);
    this.count = 0;
    this.pressing = false;
    this.x0 = 0;
    this.y0 = 0;
    this.z0 = 0;
    this.dirty = true;
    this.lastDraw = -1e9;
    /** Time spent drawing, ms (the bench reads it). */
    this.drawMs = 0;
    this.visibility = new Visibility(host, () => loop.request());
    loop.add(this);
    loop.request();
  }

  invalidate() {
    this.dirty = true;
    this.loop.request();
  }

  /**
   * One sample. A press starts when contact does; depth is the tool's travel from there along
   * the force's line (the force pushes the tool out of the tissue). Allocates nothing.
   * @param {number} x @param {number} y @param {number} z tool centre
   * @param {number} fx @param {number} fy @param {number} fz force on the device
   * @param {boolean} contact
   */
  push(x, y, z, fx, fy, fz, contact) {
    if (!contact) {
      this.pressing = false;
      return;
    }
    if (!this.pressing) {
      this.pressing = true;
      this.count = 0;
      this.x0 = x;
      this.y0 = y;
      this.z0 = z;
    }
    if (this.count === this.depth.length) return;
    const f = length3(fx, fy, fz);
    const d = f > 0 ? ((this.x0 - x) * fx + (this.y0 - y) * fy + (this.z0 - z) * fz) / f : 0;
    this.depth[this.count] = d;
    this.force[this.count] = f;
    this.count++;
    this.invalidate();
  }

  /** Forgets the press (a seek in a replay). */
  clear() {
    this.pressing = false;
    this.count = 0;
    this.invalidate();
  }

  dispose() {
    this.loop.remove(this);
    this.visibility.dispose();
    this.resizeObserver.disconnect();
  }

  /**
   * The frame loop's part: a redraw when it changed, is on screen and its rate allows.
   * @param {number} now ms @returns {boolean} still to draw in a later frame
   */
  draw(now) {
    if (!this.dirty || !this.visibility.visible) return false;
    if (!isDue(this.lastDraw, now, kPlotRedrawHz)) return true;
    this.dirty = false;
    this.lastDraw = now;
    const start = performance.now();
    this.paint();
    this.drawMs += performance.now() - start;
    return false;
  }

  paint() {
    const c = this.ctx;
    // Resizing a canvas reallocates and clears it: only when its box's width changed.
    const w = this.width;
    if (this.canvas.width !== w) this.canvas.width = w;
    const h = this.canvas.height;
    c.clearRect(0, 0, w, h);
    c.fillStyle = '#1d232b';
    c.font = 'bold 12px system-ui, sans-serif';
    c.textAlign = 'center';
    c.fillText('|F| against depth (current press)', w / 2, 14);
    c.font = '11px system-ui, sans-serif';
    c.fillStyle = '#5b6673';
    if (this.count < 2) {
      c.fillText('no contact yet', w / 2, h / 2);
      this.axes = { x: [], y: [], frame: { left: 0, top: 0, right: 0, bottom: 0 } };
      return;
    }
    let dMin = 0, dMax = 1e-9, fMax = 1e-9;
    for (let i = 0; i < this.count; i++) {
      if (this.depth[i] < dMin) dMin = this.depth[i];
      if (this.depth[i] > dMax) dMax = this.depth[i];
      if (this.force[i] > fMax) fMax = this.force[i];
    }
    // A press that has not moved yet (the tool held still, as after a reset) still gets an axis
    // of readable ticks: a thousandth of a model unit at least (ten of the default quantum).
    if (dMax - dMin < 1e-3) dMax = dMin + 1e-3;
    // The frame, with room for the ticks' labels and the axes' titles.
    const left = 58, right = w - 12, top = 24, bottom = h - 40;
    const xs = niceTicks(dMin, dMax, Math.max(3, Math.min(6, Math.floor((right - left) / 70))));
    const ys = niceTicks(0, fMax, 4);
    const px = (/** @type {number} */ d) => left + ((d - xs.bottom) / (xs.top - xs.bottom)) * (right - left);
    const py = (/** @type {number} */ f) => bottom - ((f - ys.bottom) / (ys.top - ys.bottom)) * (bottom - top);
    // Grid and ticks, then their labels.
    c.strokeStyle = '#e3e7ec';
    c.lineWidth = 1;
    c.beginPath();
    for (const t of xs.ticks) { c.moveTo(Math.round(px(t)) + 0.5, top); c.lineTo(Math.round(px(t)) + 0.5, bottom + 4); }
    for (const t of ys.ticks) { c.moveTo(left - 4, Math.round(py(t)) + 0.5); c.lineTo(right, Math.round(py(t)) + 0.5); }
    c.stroke();
    c.strokeStyle = '#8795a1';
    c.strokeRect(left + 0.5, top + 0.5, right - left - 1, bottom - top - 1);
    const xLabels = xs.ticks.map((t) => tickLabel(t, xs.step)), yLabels = ys.ticks.map((t) => tickLabel(t, ys.step));
    c.textAlign = 'center';
    c.textBaseline = 'top';
    xs.ticks.forEach((t, i) => c.fillText(xLabels[i], px(t), bottom + 6));
    c.textAlign = 'right';
    c.textBaseline = 'middle';
    ys.ticks.forEach((t, i) => c.fillText(yLabels[i], left - 6, py(t)));
    c.textAlign = 'center';
    c.textBaseline = 'alphabetic';
    c.fillText(`depth along the force (${this.units.length})`, (left + right) / 2, h - 6);
    c.save();
    c.translate(12, (top + bottom) / 2);
    c.rotate(-Math.PI / 2);
    c.fillText(`|F| (${this.units.force})`, 0, 0);
    c.restore();
    // The press, clipped to the frame.
    c.save();
    c.beginPath();
    c.rect(left, top, right - left, bottom - top);
    c.clip();
    c.strokeStyle = '#c0392b';
    c.lineWidth = 1.5;
    c.beginPath();
    for (let i = 0; i < this.count; i++) {
      const x = px(this.depth[i]), y = py(this.force[i]);
      if (i === 0) c.moveTo(x, y);
      else c.lineTo(x, y);
    }
    c.stroke();
    c.restore();
    c.textAlign = 'start';
    this.axes = { x: xLabels, y: yLabels, frame: { left, top, right, bottom } };
  }
}
