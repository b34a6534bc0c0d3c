// /trainee/{name}: one trainee's sessions (GET /api/sessions?trainee=NAME), their figures over time
// (a point per session: peak force and time in contact), and the sessions' table as /sessions
// shows it. Refreshed every 5 s while visible, so a session that ends shows its figures.
import { api } from '../net/api.js';
import { display } from '../view/display.js';
import { TrendPlot } from '../plots/trend.js';
import { h, page, fixed, formatDate } from './dom.js';
import { sessionTable, sortSessions } from './session_table.js';

/** @param {string} name @param {string} role */
export function traineePage(name, role) {
  const status = h('p', { class: 'muted', role: 'status', id: 'trainee-status', text: 'Loading…' });
  const plotHost = h('div', { class: 'plot trend', id: 'trend-plot' });
  const { el: tableBox, show } = sessionTable('trainee-sessions', `${name}'s sessions, newest first.`, role, () => refresh());
  page(`Trainee ${name}`, [
    h('h1', {}, ['Trainee ', h('span', { class: 'trainee-name', text: name })]),
    h('p', {}, [h('a', { href: `/sessions?trainee=${encodeURIComponent(name)}`, text: 'in the sessions list' })]),
    status,
    h('section', { class: 'card wide', 'aria-labelledby': 'trend-title' }, [
      h('h2', { id: 'trend-title', text: 'Figures over time' }), plotHost]),
    tableBox,
  ]);
  const plot = new TrendPlot(plotHost, { forceUnit: display.unit.force });
  /** For the tests: what the plot was given. */
  const seen = { sessions: 0, points: 0 };
  /** @type {any} */ (window).__idmsTrainee = seen;
  let timer = 0;

  async function refresh() {
    clearTimeout(timer);
    try {
      const { sessions } = await api(`/api/sessions?trainee=${encodeURIComponent(name)}`);
      show(sortSessions(sessions));
      // The plot: every session with figures (a live one's so far), oldest first.
      const points = sessions
        .map((/** @type {any} */ s) => ({ startS: Date.parse(s.started) / 1000, peakForce: Number(s.summary?.peak_force ?? NaN),
          contactS: Number(s.summary?.contact_time_s ?? NaN) }))
        .filter((/** @type {any} */ p) => Number.isFinite(p.startS) && Number.isFinite(p.peakForce))
        .sort((/** @type {any} */ a, /** @type {any} */ b) => a.startS - b.startS);
      plot.setData(points);
      seen.sessions = sessions.length;
      seen.points = plot.points;
      if (sessions.length === 0) status.textContent = `No sessions name ${name} as their trainee.`;
      else {
        const peak = Math.max(...sessions.map((/** @type {any} */ s) => Number(s.summary?.peak_force ?? 0)));
        const hits = sessions.reduce((/** @type {number} */ n, /** @type {any} */ s) => n + Number(s.summary?.force_limit_hits ?? 0), 0);
        const starts = sessions.map((/** @type {any} */ s) => String(s.started)).sort();
        status.textContent = `${sessions.length} sessions from ${formatDate(starts[0])} to ${formatDate(starts[starts.length - 1])}; `
          + `highest peak force ${fixed(peak)} ${display.unit.force}; force limit reached ${hits} ${hits === 1 ? 'time' : 'times'} in all.`;
      }
    } catch (e) {
      status.textContent = `Cannot load the sessions: ${e instanceof Error ? e.message : String(e)}; retrying…`;
    }
    timer = window.setTimeout(refresh, document.hidden ? 20000 : 5000);
  }
  refresh();
  return () => {
    clearTimeout(timer);
    plot.dispose();
  };
}
