// /report/{id}: one session on one printed page (A4 or Letter, portrait), for a trainee's file or
// a debrief: who, what and when; the figures and the grade against the scene's limits; the tissue
// at the session's peak force (the server's own rendering, idms-render's, colours as the viewers');
// the device force over the whole session; and the notes by time. "Save as PDF" is the browser's
// print (every browser can save a page as PDF; style.css's print rules lay it out on one page).
import { api } from '../net/api.js';
import { display } from '../view/display.js';
import { Units } from '../view/units.js';
import { ProfilePlot } from '../plots/profile.js';
import { h, page, fixed, formatDate, formatTime } from './dom.js';
import { gradeList } from './grade.js';

/** Notes beyond this many are counted, not listed: the page stays one page. */
export const kReportNotes = 12;

/** @param {string} id @param {string} _role */
export function reportPage(id, _role) {
  const status = h('p', { class: 'muted no-print', role: 'status', id: 'report-status', text: 'Loading…' });
  const who = h('dl', { class: 'report-who', id: 'report-who' });
  const figures = h('dl', { class: 'report-figures', id: 'report-figures' });
  const grade = h('div', { id: 'report-grade' });
  const picture = h('figure', { class: 'report-picture', id: 'report-picture' });
  const profileHost = h('div', { class: 'plot', id: 'report-profile' });
  const notes = h('ol', { class: 'report-notes', id: 'report-notes' });
  const profileTitle = h('h2', { id: 'report-profile-title', text: `Device force over the session (${display.unit.force})` });
  const print = h('button', { type: 'button', id: 'report-print', text: 'Print or save as PDF', onclick: () => window.print() });
  const generated = h('p', { class: 'muted report-generated', text: `Report generated ${new Date().toLocaleString()}` });
  page(`Report ${id}`, [
    h('div', { class: 'report', id: 'report' }, [
      h('div', { class: 'report-head' }, [
        h('h1', {}, ['Session report ', h('code', { text: id })]),
        h('p', { class: 'no-print' }, [print, ' ', h('a', { href: `/replay/${encodeURIComponent(id)}`, text: 'open the replay' }), ' · ',
          h('a', { href: `/api/sessions/${encodeURIComponent(id)}/samples.csv`, text: 'samples as CSV' })]),
      ]),
      status,
      h('div', { class: 'report-grid' }, [
        h('section', { 'aria-labelledby': 'report-who-title' }, [h('h2', { id: 'report-who-title', text: 'Session' }), who]),
        h('section', { 'aria-labelledby': 'report-figures-title' }, [h('h2', { id: 'report-figures-title', text: 'Figures' }), figures]),
      ]),
      h('section', { 'aria-labelledby': 'report-grade-title' }, [h('h2', { id: 'report-grade-title', text: 'Grade' }), grade]),
      h('div', { class: 'report-grid' }, [
        h('section', { 'aria-labelledby': 'report-picture-title' }, [h('h2', { id: 'report-picture-title', text: 'The tissue at the peak force' }), picture]),
        h('section', { 'aria-labelledby': 'report-notes-title' }, [h('h2', { id: 'report-notes-title', text: 'Notes' }), notes]),
      ]),
      h('section', { 'aria-labelledby': 'report-profile-title' }, [profileTitle, profileHost]),
      generated,
    ]),
  ]);
  const profile = new ProfilePlot(profileHost, { title: '', series: [{ label: '|F|', color: '#222' }], legend: false });
  /** For the tests: what the report holds once loaded. */
  const seen = { loaded: false, notes: 0, profilePoints: 0, pictureLoaded: false, peakS: NaN };
  /** @type {any} */ (window).__idmsReport = seen;

  /** @param {HTMLElement} dl @param {[string, string | Node][]} rows */
  const fill = (dl, rows) => dl.replaceChildren(...rows.flatMap(([k, v]) => [h('dt', { text: k }), h('dd', {}, [v])]));

  Promise.all([api(`/api/sessions/${encodeURIComponent(id)}`), api(`/api/sessions/${encodeURIComponent(id)}/force?points=600`)])
    .then(([s, force]) => {
      const sum = s.summary || {};
      const u = new Units(s.units);
      profileTitle.textContent = `Device force over the session (${u.force}, the peak of each slice; the marker: the picture's time)`;
      profile.scaleForce(u.forceScale);
      fill(who, [['Trainee', s.trainee || 'not named'], ['Model', s.model], ['Device', s.device], ['Started', formatDate(s.started)],
        ['Duration', formatTime(s.duration_s)], ['State', s.state]]);
      fill(figures, [[`Peak force`, `${fixed(u.frc(sum.peak_force ?? NaN))} ${u.force}`],
        ['Mean contact force', `${fixed(u.frc(sum.mean_contact_force ?? NaN))} ${u.force}`],
        ['Time in contact', `${fixed(sum.contact_time_s ?? NaN, 1)} s`],
        ['Path length', `${fixed(u.len(sum.path_length ?? NaN))} ${u.length}`],
        ['Force-limit hits', `${sum.force_limit_hits ?? '–'} (${fixed(sum.force_limited_s ?? NaN, 2)} s at the limit)`],
        ['Numerical warnings', String(sum.warnings ?? '–')],
        ['Loop', `tick p99 ${sum.tick_p99_us ?? '–'} µs, ${sum.overruns ?? '–'} overruns`],
        ...sutureRows(sum, u)]);
      grade.replaceChildren(gradeList(s.grade, u));
      const all = /** @type {any[]} */ (s.annotations || []);
      notes.replaceChildren(...all.slice(0, kReportNotes).map((n) => h('li', {}, [h('span', { class: 'time', text: formatTime(n.time_s) }), ' ', n.text])));
      if (all.length === 0) notes.replaceChildren(h('li', { class: 'muted', text: 'No notes.' }));
      if (all.length > kReportNotes) notes.append(h('li', { class: 'muted', text: `and ${all.length - kReportNotes} more in the replay` }));
      seen.notes = Math.min(all.length, kReportNotes);
      profile.setData([force]);
      seen.profilePoints = profile.points[0];
      // The peak: where the profile's largest slice is (its sample's own time).
      const forces = /** @type {number[]} */ (force.force);
      const at = forces.length ? forces.indexOf(Math.max(...forces)) : -1;
      const peakS = at >= 0 ? Number(force.time_s[at]) : Number(s.duration_s) / 2;
      seen.peakS = peakS;
      profile.mark(peakS);
      const img = h('img', { width: 480, height: 270, alt: `The tissue at ${formatTime(peakS)}, the session's peak force`,
        src: `/api/sessions/${encodeURIComponent(id)}/screenshot.png?t=${peakS.toFixed(3)}&size=480x270` });
      img.addEventListener('load', () => { seen.pictureLoaded = true; });
      picture.replaceChildren(img, h('figcaption', { class: 'muted', text: `at ${formatTime(peakS)}: the largest device force of the session` }));
      status.textContent = '';
      seen.loaded = true;
    })
    .catch((e) => { status.textContent = `Cannot load the session: ${e instanceof Error ? e.message : String(e)}`; });
  return () => profile.dispose();
}

/**
 * A suture's rows (issue 32), when the session had one: the knots tied, and the incision's gap left
 * against its open width. @param {any} sum the session's summary @param {Units} u
 * @returns {[string, string][]}
 */
function sutureRows(sum, u) {
  /** @type {[string, string][]} */
  const rows = [];
  if (sum.stitches > 0) rows.push(['Stitches tied', String(sum.stitches)]);
  if (sum.incision_open > 0) {
    rows.push(['Incision gap', `${fixed(u.len(sum.incision_gap))} of ${fixed(u.len(sum.incision_open))} ${u.length} open`
      + ` (${fixed(100 * sum.incision_gap / sum.incision_open, 0)} %)`]);
  }
  return rows;
}
