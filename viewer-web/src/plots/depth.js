// Force against depth while pressing (thesis fig. 6-3): for the current or last press, |F|
// against how far the tool has gone along the force's line since contact began. A plain canvas
// over preallocated arrays, redrawn in the page's frame (FrameLoop) as often as the time plots,
// only when it changed and only while it is on screen.
import { FrameLoop, Visibility, isDue } from '../view/frame_loop.js';
import { kPlotRedrawHz } from './rolling.js';
import { length3 } from '../length3.js';

export class DepthPlot {
  /**
   * @param {HTMLElement} host
   * @param {number} capacity samples kept per press
   * @param {FrameLoop} [loop] the page's frame loop
   */
  constructor(host, capacity, loop = new FrameLoop()) {
    this.loop = loop;
    this.canvas = document.createElement('canvas');
    this.canvas.setAttribute('role', 'img');
    this.canvas.setAttribute('aria-label', 'Force magnitude against pressing depth for the current press');
    this.canvas.height = 160;
    this.canvas.style.width = '100%';
    this.canvas.style.height = '160px';
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
    c.fillStyle = '#5b6673';
    c.font = '12px system-ui, sans-serif';
    c.fillText('|F| against depth (current press)', 8, 14);
    if (this.count < 2) {
      c.fillText('no contact yet', 8, 34);
      return;
    }
    let dMax = 1e-9, fMax = 1e-9;
    for (let i = 0; i < this.count; i++) {
      if (this.depth[i] > dMax) dMax = this.depth[i];
      if (this.force[i] > fMax) fMax = this.force[i];
    }
    const left = 44, bottom = h - 22, right = w - 10, top = 24;
    c.strokeStyle = '#d5dbe2';
    c.strokeRect(left, top, right - left, bottom - top);
    c.fillText(fMax.toPrecision(3), 4, top + 10);
    c.fillText('0', 30, bottom);
    c.fillText(`depth ${dMax.toPrecision(3)}`, right - 90, h - 6);
    c.strokeStyle = '#c0392b';
    c.beginPath();
    for (let i = 0; i < this.count; i++) {
      const px = left + (Math.max(0, this.depth[i]) / dMax) * (right - left);
      const py = bottom - (this.force[i] / fMax) * (bottom - top);
      if (i === 0) c.moveTo(px, py);
      else c.lineTo(px, py);
    }
    c.stroke();
  }
}
