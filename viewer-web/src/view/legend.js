// The colour legend over the 3D view's top right corner: what the colours say, its unit, a bar of
// display.json's map with ticks and their values (">=" on the top one when larger values take its
// colour), and notes (the deformation scale when it is not 1; rest's time when it is not the
// session's start). idms-render draws the same lines into its image (viewer-offscreen/src/legend.cc).
// Rebuilt only when what it shows changes.
import { kMapRgba, legendTicks, tickText } from './display.js';

/** Bar height, CSS pixels. */
const kBarPx = 130;

/**
 * @typedef {{title: string, unit: string, lo: number, hi: number, saturates: boolean, notes: string[]}} LegendSpec
 */

export class Legend {
  /** @param {HTMLElement} host positioned (the view's box) */
  constructor(host) {
    this.el = document.createElement('div');
    this.el.className = 'legend';
    this.el.id = 'legend';
    this.el.setAttribute('role', 'img');
    this.el.hidden = true;
    host.appendChild(this.el);
    this.shown = '';
  }

  /** @param {LegendSpec | null} spec null: no legend */
  show(spec) {
    const key = JSON.stringify(spec);
    if (key === this.shown) return;
    this.shown = key;
    this.el.hidden = spec === null;
    if (spec === null) return;
    const ticks = legendTicks(spec.lo, spec.hi);
    const labels = ticks.map((t, i) => (i === ticks.length - 1 && ticks.length > 1 && spec.saturates ? '≥' : '') + tickText(t));
    this.el.setAttribute('aria-label', `Colour legend: ${spec.title} in ${spec.unit}, ${labels[0]} to ${labels[labels.length - 1]}`
      + (spec.notes.length ? `; ${spec.notes.join('; ')}` : ''));
    // The bar: one row per pixel, the top the range's top.
    const bar = document.createElement('canvas');
    bar.width = 1;
    bar.height = kBarPx;
    const ctx = /** @type {CanvasRenderingContext2D} */ (bar.getContext('2d'));
    const img = ctx.createImageData(1, kBarPx);
    for (let r = 0; r < kBarPx; r++) {
      const i = Math.round((255 * (kBarPx - 1 - r)) / (kBarPx - 1));
      img.data.set(kMapRgba.subarray(4 * i, 4 * i + 4), 4 * r);
    }
    ctx.putImageData(img, 0, 0);
    const scale = document.createElement('div');
    scale.className = 'legend-scale';
    scale.style.height = `${kBarPx}px`;
    scale.append(bar);
    ticks.forEach((_, i) => {
      const f = ticks.length > 1 ? i / (ticks.length - 1) : 0;
      const tick = document.createElement('span');
      tick.className = 'legend-tick';
      tick.style.top = `${((1 - f) * (kBarPx - 1)).toFixed(1)}px`;
      tick.textContent = labels[i];
      scale.append(tick);
    });
    const line = (/** @type {string} */ cls, /** @type {string} */ text) => {
      const d = document.createElement('div');
      d.className = cls;
      d.textContent = text;
      return d;
    };
    this.el.replaceChildren(line('legend-title', spec.title), line('legend-unit', spec.unit), scale,
      ...spec.notes.map((n) => line('legend-note', n)));
  }

  dispose() {
    this.el.remove();
  }
}
