// A fit's report (POST /api/sessions/{id}/fit stores it in the fitted version's metadata): the
// parameters found, each as a factor on what was typed in and as a value, with one standard
// deviation; the force error before and after; and the recorded f_z against the fitted model's
// over the session. Shown on the fit page and on the model page of a fitted version.
import { ProfilePlot } from '../plots/profile.js';
import { colourIndex, display } from '../view/display.js';
import { h, fixed } from './dom.js';

const kSvg = 'http://www.w3.org/2000/svg';

/** An SVG element. @param {string} tag @param {Record<string, string | number>} attrs @param {Node[]} [children] */
function svg(tag, attrs, children = []) {
  const el = document.createElementNS(kSvg, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, String(v));
  el.append(...children);
  return el;
}

/** @param {number} x @param {number} [digits] significant digits */
function sig(x, digits = 4) {
  return Number.isFinite(x) ? Number(x.toPrecision(digits)).toString() : '–';
}

/**
 * Fills `host` with the report; returns what to dispose (the plot).
 * @param {HTMLElement} host
 * @param {any} report metadata.fit: {session, from: {name, version}, params: [{name, scale, scale_sigma,
 *   value, value_sigma}], rms_before, rms_after, peak_force, samples, replays, seconds, regions,
 *   curve: {t, measured, fitted}}
 */
export function showFitReport(host, report) {
  if (report.kind === 'map') return showMap(host, report);
  const rows = (report.params || []).map((/** @type {any} */ p) => h('tr', { 'data-param': p.name }, [
    h('td', {}, [h('code', { text: p.name })]),
    h('td', { class: 'num', text: `× ${sig(p.scale)} ± ${sig(p.scale_sigma, 2)}` }),
    h('td', { class: 'num', text: `${sig(p.value)} ± ${sig(p.value_sigma, 2)}` }),
  ]));
  const plotHost = h('div', { class: 'plot', id: 'fit-plot' });
  const regions = (report.regions || []).length ? ` Regions: ${report.regions.join('; ')}.` : '';
  host.replaceChildren(
    h('p', { class: 'meta', id: 'fit-summary' }, [
      `Fitted to session `, h('a', { href: `/replay/${encodeURIComponent(report.session)}`, text: report.session }),
      ` from ${report.from?.name} version ${report.from?.version}: force RMS error ${sig(report.rms_before, 3)} → ${sig(report.rms_after, 3)}`
      + ` (peak ${sig(report.peak_force, 3)}), ${report.samples} samples, ${report.replays} replays in ${fixed(report.seconds, 2)} s.${regions}`]),
    h('table', { class: 'list', id: 'fit-params' }, [
      h('thead', {}, [h('tr', {}, ['Parameter', 'Factor on typed-in', 'Value'].map((t) => h('th', { scope: 'col', text: t })))]),
      h('tbody', {}, rows)]),
    plotHost);
  const curve = report.curve || { t: [], measured: [], fitted: [] };
  const plot = new ProfilePlot(plotHost, {
    title: 'Force along the session: recorded and fitted (f_z, model force units)', yLabel: 'f_z',
    series: [{ label: 'recorded', color: '#1f77b4' }, { label: 'fitted model', color: '#d62728' }],
  });
  plot.setData([{ time_s: curve.t, force: curve.measured }, { time_s: curve.t, force: curve.fitted }]);
  return plot;
}

/**
 * A scan's stiffness map (report.kind "map"): every press at the tool's x, y, coloured by its
 * apparent stiffness factor through the display's colour map (display.json, as the surface's), the
 * lump's circle where one was found, and the figures. Model x to the right, y up.
 * @param {HTMLElement} host @param {any} report
 */
function showMap(host, report) {
  const map = report.map || { points: [], lump: { found: false } };
  const points = /** @type {{x: number, y: number, scale: number, sigma: number}[]} */ (map.points || []);
  const lump = map.lump || { found: false };
  const xs = points.map((p) => p.x), ys = points.map((p) => p.y), fs = points.map((p) => p.scale);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const [lo, hi] = [Math.min(...fs), Math.max(...fs)];
  // The presses' spacing: the nearest neighbour's distance, for the dots' size and the margin.
  let spacing = Infinity;
  for (const p of points) for (const q of points) if (p !== q) spacing = Math.min(spacing, Math.hypot(p.x - q.x, p.y - q.y));
  if (!Number.isFinite(spacing)) spacing = 1;
  const pad = spacing;
  // Room on the left for the y labels.
  const view = `${x0 - 1.6 * pad} ${-(y1 + pad)} ${x1 - x0 + 2.6 * pad} ${y1 - y0 + 2 * pad}`;
  const dots = points.map((p, i) => svg('circle', {
    cx: p.x, cy: -p.y, r: 0.38 * spacing, fill: display.map.srgb[colourIndex(p.scale, lo, hi)],
    stroke: '#444', 'stroke-width': 0.02 * spacing, 'data-press': i, 'data-scale': p.scale,
  }, [svg('title', {}, [document.createTextNode(`x ${sig(p.x)}, y ${sig(p.y)}: k × ${sig(p.scale)} ± ${sig(p.sigma, 2)}`)])]));
  const ring = lump.found ? [svg('circle', { id: 'map-lump', cx: lump.x, cy: -lump.y, r: lump.radius, fill: 'none',
    stroke: '#111', 'stroke-width': 0.08 * spacing, 'stroke-dasharray': `${0.3 * spacing} ${0.2 * spacing}` })] : [];
  // The grid's ends on each axis, model units.
  const label = (/** @type {number} */ x, /** @type {number} */ y, /** @type {string} */ anchor, /** @type {string} */ text) =>
    svg('text', { x, y, 'text-anchor': anchor, 'font-size': 0.32 * spacing, fill: '#555' }, [document.createTextNode(text)]);
  const below = -y0 + 0.85 * pad, left = x0 - 0.5 * pad;
  const axes = [label(x0, below, 'middle', `x ${sig(x0, 3)}`), label(x1, below, 'middle', `x ${sig(x1, 3)}`),
    label(left, -y0 + 0.1 * pad, 'end', `y ${sig(y0, 3)}`), label(left, -y1 + 0.1 * pad, 'end', `y ${sig(y1, 3)}`)];
  const figure = svg('svg', { id: 'fit-map', viewBox: view, role: 'img', preserveAspectRatio: 'xMidYMid meet',
    'aria-label': `Stiffness map: ${points.length} presses${lump.found ? ', the lump circled' : ''}` }, [...dots, ...ring, ...axes]);
  // The colour scale: the map's ends at the factors' ends.
  const stops = [0, 0.25, 0.5, 0.75, 1].map((t) => `${display.map.srgb[Math.round(t * 255)]} ${t * 100}%`).join(', ');
  // Through the CSSOM: the page's Content-Security-Policy refuses style attributes.
  const ramp = h('span', { class: 'map-ramp' });
  ramp.style.background = `linear-gradient(to right, ${stops})`;
  const legend = h('div', { class: 'map-legend' }, [h('span', { text: `k × ${sig(lo, 3)}` }), ramp, h('span', { text: `× ${sig(hi, 3)}` })]);
  const found = lump.found
    ? `A lump at x ${sig(lump.x)}, y ${sig(lump.y)} (± ${sig(lump.xy_sigma, 2)}), radius ${sig(lump.radius, 3)}: `
      + `${sig(lump.ratio, 3)} ± ${sig(lump.ratio_sigma, 2)} times the background's stiffness (${lump.presses} presses).`
    : 'No lump: no press stands out of the background by more than 25% and 5 times the scatter.';
  host.replaceChildren(
    h('p', { class: 'meta', id: 'fit-summary' }, [
      'Stiffness map of session ', h('a', { href: `/replay/${encodeURIComponent(report.session)}`, text: report.session }),
      ` against ${report.from?.name} version ${report.from?.version}: ${points.length} presses, background k × ${sig(map.background)}`
      + ` (scatter ${sig(map.spread, 2)}), ${map.replays} replays in ${fixed(map.seconds, 2)} s.`]),
    h('p', { id: 'map-lump-text', class: lump.found ? 'lump-found' : '', text: found }),
    h('div', { class: 'map-box' }, [figure, legend]));
  return { dispose() {} };
}
