// The sessions' table that /sessions and /trainee/{name} share: a row per session with its summary
// figures, each row kept from one refresh to the next and updated in place (SessionRow), so that
// a link or button with the keyboard's focus keeps it and a thumbnail is not fetched again. On a
// phone each row is a card of labelled lines (style.css, table.cards; the labels are data-label).
import { api } from '../net/api.js';
import { display } from '../view/display.js';
import { h, fixed, formatDate } from './dom.js';
import { gradeBadge, gradeWords } from './grade.js';
import { Units } from '../view/units.js';

const kForceUnit = display.unit.force;

/**
 * The columns: a header, the label a phone's card gives the value, and the cell's class. The
 * start under the session's id, the duration under its state and the identity under the device
 * keep the figures within a 1280 px window.
 */
export const kColumns = [
  { head: 'Preview', unit: '', label: '', cls: 'thumb-cell' },
  { head: 'Session', unit: 'started', label: 'Session', cls: 'id-cell' },
  { head: 'State', unit: 'duration', label: 'State', cls: undefined },
  { head: 'Trainee', unit: '', label: 'Trainee', cls: 'trainee' },
  { head: 'Model', unit: '', label: 'Model', cls: 'model' },
  { head: 'Device', unit: '', label: 'Device', cls: 'device' },
  { head: 'Peak force', unit: kForceUnit, label: `Peak force (${kForceUnit})`, cls: 'num' },
  { head: 'Contact', unit: 's', label: 'Contact', cls: 'num' },
  { head: 'Force-limit hits', unit: 'time at the limit', label: 'Force-limit hits', cls: 'num' },
  { head: 'Path', unit: display.unit.length, label: `Path (${display.unit.length})`, cls: 'num' },
  { head: 'Tick p99', unit: '', label: 'Tick p99', cls: 'num' },
  { head: 'Warnings', unit: '', label: 'Warnings', cls: 'num' },
  { head: '', unit: '', label: '', cls: 'actions' },
];
const kPeak = 6, kLimit = 8, kActions = 12;

/** A trainee's page. @param {string} name */
export const traineeHref = (name) => `/trainee/${encodeURIComponent(name)}`;

/**
 * The two recorded sessions picked for a comparison (a third pick lets go of the first), and the
 * bar that links to /compare/{a}/{b} once there are two.
 */
class Picker {
  constructor() {
    /** @type {string[]} */
    this.ids = [];
    this.link = h('a', { id: 'compare-link', class: 'button-link' });
    this.said = h('span', { class: 'muted', id: 'compare-said' });
    this.bar = h('div', { class: 'compare-bar', id: 'compare-bar' }, [this.said, this.link]);
    this.show();
  }

  /** @param {string} id */
  has(id) {
    return this.ids.includes(id);
  }

  /** @param {string} id @param {boolean} on */
  pick(id, on) {
    this.ids = this.ids.filter((x) => x !== id);
    if (on) this.ids.push(id);
    if (this.ids.length > 2) {
      const dropped = /** @type {string} */ (this.ids.shift());
      const box = /** @type {HTMLInputElement | null} */ (document.querySelector(`input[data-compare="${CSS.escape(dropped)}"]`));
      if (box) box.checked = false;
    }
    this.show();
  }

  show() {
    const [a, b] = this.ids;
    this.said.textContent = this.ids.length === 0 ? 'Tick two recorded sessions\u2019 \u201ccompare\u201d boxes to see them side by side.'
      : this.ids.length === 1 ? `Picked ${a}; tick one more to compare.` : '';
    if (b) {
      this.link.href = `/compare/${encodeURIComponent(a)}/${encodeURIComponent(b)}`;
      this.link.textContent = `Compare ${a} and ${b}`;
      this.link.hidden = false;
    } else this.link.hidden = true;
  }
}

/** One session's row; only what changed is rewritten. */
class SessionRow {
  /** @param {string} id @param {string} role @param {() => void} refresh @param {Picker} picker */
  constructor(id, role, refresh, picker) {
    this.id = id;
    this.role = role;
    this.refresh = refresh;
    this.picker = picker;
    this.cells = kColumns.map((c) => h('td', { class: c.cls, 'data-label': c.label || undefined }));
    this.tr = h('tr', { 'data-id': id }, this.cells);
    /** What each cell shows, as a key: rewritten only when it differs. @type {string[]} */
    this.shown = kColumns.map(() => '\u0000');
  }

  /**
   * @param {number} i the column
   * @param {string} key what the cell shows
   * @param {() => (Node | string | null)[]} make its content, called only when the key changed
   */
  set(i, key, make) {
    if (this.shown[i] === key) return;
    this.shown[i] = key;
    this.cells[i].replaceChildren(...make().filter((x) => x !== null));
  }

  /** @param {number} i @param {string} text */
  text(i, text) {
    this.set(i, text, () => [text]);
  }

  /** @param {any} s the session, as /api/sessions lists it */
  update(s) {
    const live = s.state === 'live';
    const id = this.id;
    this.tr.dataset.state = s.state;
    this.tr.dataset.trainee = s.trainee || '';
    // A recorded session's thumbnail: the server renders its surface halfway through (idms-render,
    // cached by content), so the list shows what each session looked like.
    const mid = fixed(s.duration_s / 2, 2);
    this.set(0, live || !(s.duration_s > 0) ? '' : mid, () => [live || !(s.duration_s > 0) ? null
      : h('img', { class: 'thumb', width: 160, height: 90, loading: 'lazy', alt: `The surface at ${mid} s`,
        src: `/api/sessions/${encodeURIComponent(id)}/screenshot.png?t=${mid}&size=160x90` })]);
    const href = live ? `/session/${id}` : `/replay/${id}`;
    const started = formatDate(s.started);
    // Under a recorded session's id: its one-page report and a box to pick it for a comparison
    // (here, not in the last column, so that they stay in sight whatever the table's width).
    this.set(1, `${href}|${started}`, () => [h('a', { href, text: id }), h('div', { class: 'under', text: started }),
      live ? null : h('div', { class: 'row-tools' }, [
        h('a', { class: 'report-link', href: `/report/${encodeURIComponent(id)}`, text: 'Report' }), ' ',
        h('a', { class: 'fit-link', href: `/fit/${encodeURIComponent(id)}`, text: 'Fit' }), ' ',
        h('label', { class: 'compare-pick', title: 'Pick to compare side by side' }, [h('input', { type: 'checkbox', 'data-compare': id,
          'aria-label': `Pick session ${id} to compare`, checked: this.picker.has(id),
          onchange: (/** @type {Event} */ ev) => this.picker.pick(id, /** @type {HTMLInputElement} */ (ev.target).checked) }), ' compare'])])]);
    const under = `${fixed(s.duration_s, 1)} s` + (live ? ` · ${s.viewers} watching` : '');
    // The grade against the scene's limits beside the state (a live session's so far).
    const units = new Units(s.units);
    const grade = gradeWords(s.grade, units);
    this.set(2, `${s.state}|${under}|${grade.detail}`, () => [h('span', { class: `badge ${s.state}`, text: s.state }),
      gradeBadge(s.grade, units), h('div', { class: 'under', text: under })]);
    const trainee = String(s.trainee || '');
    this.set(3, trainee, () => [trainee ? h('a', { href: traineeHref(trainee), text: trainee }) : h('span', { class: 'muted', text: 'not named' })]);
    this.text(4, s.model);
    // The device (Hello.device), and the agent's identity (its host and pid) under it when it says more.
    const identity = s.identity && s.identity !== s.device ? s.identity : '';
    this.set(5, `${s.device}|${identity}`, () => [s.device, identity ? h('div', { class: 'under identity', text: identity }) : null]);
    const sum = s.summary || {};
    // A session whose scene declares its units shows N and mm, said in the cell; others the
    // model's units of the column's head.
    const peak = Number(sum.peak_force ?? NaN);
    this.text(kPeak, units.force !== kForceUnit ? `${fixed(units.frc(peak))} ${units.force}` : fixed(peak));
    this.cells[kPeak].title = `${fixed(units.frc(peak))} ${units.force}`;
    this.text(7, `${fixed(sum.contact_time_s ?? NaN, 1)} s`);
    // Hits: how often the device force reached its limit; under it, for how long it stayed there.
    const hits = sum.force_limit_hits ?? NaN;
    const limited = `${fixed(sum.force_limited_s ?? NaN, 2)} s`;
    this.set(kLimit, `${hits}|${limited}`, () => [h('span', { class: hits > 0 ? 'limit-hits hit' : 'limit-hits', text: Number.isFinite(hits) ? String(hits) : '–' }),
      h('div', { class: 'under', text: limited })]);
    const path = Number(sum.path_length ?? NaN);
    this.text(9, units.length !== display.unit.length ? `${fixed(units.len(path))} ${units.length}` : fixed(path));
    this.text(10, sum.tick_p99_us !== undefined ? `${sum.tick_p99_us} µs` : '–');
    this.text(11, String(sum.warnings ?? '–'));
    const deletable = this.role === 'admin' && !live;
    this.set(kActions, String(deletable), () => [deletable
      ? h('button', { class: 'small danger', 'aria-label': `Delete session ${id}`, text: 'Delete', onclick: async () => {
        if (!confirm(`Delete session ${id} and its recording?`)) return;
        await api(`/api/sessions/${encodeURIComponent(id)}`, { method: 'DELETE' });
        this.refresh();
      } }) : null]);
  }
}

/**
 * The table, empty; `show` puts sessions in it in the order given.
 * @param {string} id the table's id
 * @param {string} caption
 * @param {string} role
 * @param {() => void} refresh what a delete calls
 */
export function sessionTable(id, caption, role, refresh) {
  const body = h('tbody');
  const picker = new Picker();
  const table = h('table', { class: 'list cards', id }, [
    h('caption', { text: caption }),
    // Each header with its unit (or what the cell's second line says) under it.
    h('thead', {}, [h('tr', {}, kColumns.map((c) => h('th', { scope: 'col', class: c.cls === 'num' ? 'num' : undefined },
      [c.head, c.unit ? h('span', { class: 'unit', text: c.unit }) : null])))]),
    body,
  ]);
  /** @type {Map<string, SessionRow>} */
  const rows = new Map();

  /**
   * The rows in the list's order: new ones inserted, gone ones removed, a kept one moved only when
   * it is out of place (moving a node takes the focus from what is in it).
   * @param {any[]} sessions sorted
   */
  const show = (sessions) => {
    const ids = new Set(sessions.map((s) => String(s.id)));
    for (const [key, row] of rows) {
      if (ids.has(key)) continue;
      row.tr.remove();
      rows.delete(key);
    }
    sessions.forEach((s, i) => {
      const key = String(s.id);
      let row = rows.get(key);
      if (!row) rows.set(key, row = new SessionRow(key, role, refresh, picker));
      row.update(s);
      if (body.children[i] !== row.tr) body.insertBefore(row.tr, body.children[i] ?? null);
    });
  };
  return { el: h('div', {}, [picker.bar, h('div', { class: 'scroll' }, [table])]), show };
}

/** Live sessions first, then the newest. @param {any[]} sessions sorted in place */
export function sortSessions(sessions) {
  return sessions.sort((a, b) =>
    Number(b.state === 'live') - Number(a.state === 'live') || String(b.started).localeCompare(String(a.started)));
}
