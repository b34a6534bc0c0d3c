// A fit's report (POST /api/sessions/{id}/fit stores it in the fitted version's metadata): the
// parameters found, each as a factor on what was typed in and as a value, with one standard
// deviation; the force error before and after; and the recorded f_z against the fitted model's
// over the session. Shown on the fit page and on the model page of a fitted version.
import { ProfilePlot } from '../plots/profile.js';
import { h, fixed } from './dom.js';

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
