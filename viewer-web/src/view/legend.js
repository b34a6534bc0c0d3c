// The colour legend over the 3D view's top right corner: what the colours say, its unit, a bar of
// display.json's map with ticks and their values (">=" on the top one when larger values take its
// colour), and notes (the deformation scale when it is not 1; rest's time when it is not the
// session's start). idms-render draws the same lines into its image (viewer-offscreen/src/legend.cc).
// Rebuilt only when what it shows changes.
import { display, legendTicks, tickText } from './display.js';

/** The map as a CSS gradient, bottom (entry 0) to top: one stop per entry. */
const kGradient = `linear-gradient(to top, ${display.map.srgb.map((c, i) => `${c} ${((100 * i) / 255).toFixed(2)}%`).join(', ')})`;

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
    // The bar, the range's top at the top (a gradient, not a canvas: the view's canvas stays its only one).
    const bar = document.createElement('div');
    bar.className = 'legend-bar';
    bar.style.background = kGradient;
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
