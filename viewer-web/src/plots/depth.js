// Force against depth while pressing (thesis fig. 6-3): for the current or last press, |F|
// against how far the tool has gone along the force's line since contact began. A plain canvas
// over preallocated arrays, redrawn at most once per animation frame and only when it changed.

export class DepthPlot {
  /** @param {HTMLElement} host @param {number} capacity samples kept per press */
  constructor(host, capacity) {
    this.canvas = document.createElement('canvas');
    this.canvas.setAttribute('role', 'img');
    this.canvas.setAttribute('aria-label', 'Force magnitude against pressing depth for the current press');
    this.canvas.height = 160;
    this.canvas.style.width = '100%';
    this.canvas.style.height = '160px';
    host.append(this.canvas);
    // Redrawn at its box's width whenever that changes.
    this.resizeObserver = new ResizeObserver(() => this.draw());
    this.resizeObserver.observe(host);
    this.ctx = /** @type {CanvasRenderingContext2D} */ (this.canvas.getContext('2d'));
    this.depth = new Float32Array(capacity);
    this.force = new Float32Array(capacity);
    this.count = 0;
    this.pressing = false;
    this.x0 = 0;
    this.y0 = 0;
    this.z0 = 0;
    this.frameRequested = false;
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
    const f = Math.hypot(fx, fy, fz);
    const d = f > 0 ? ((this.x0 - x) * fx + (this.y0 - y) * fy + (this.z0 - z) * fz) / f : 0;
    this.depth[this.count] = d;
    this.force[this.count] = f;
    this.count++;
    if (!this.frameRequested) {
      this.frameRequested = true;
      requestAnimationFrame(() => this.draw());
    }
  }

  /** Forgets the press (a seek in a replay). */
  clear() {
    this.pressing = false;
    this.count = 0;
    this.draw();
  }

  dispose() {
    this.resizeObserver.disconnect();
  }

  draw() {
    this.frameRequested = false;
    const c = this.ctx;
    const w = (this.canvas.width = Math.max(100, this.canvas.clientWidth));
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
