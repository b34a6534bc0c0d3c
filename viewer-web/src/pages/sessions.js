// /sessions: live and recorded sessions with their summary figures; the list refreshes itself
// every 2 s while the page is visible, each row updated in place (SessionRow), so that a link or
// button with the keyboard's focus keeps it and a thumbnail is not fetched again.
import { api } from '../net/api.js';
import { h, page, fixed, formatDate } from './dom.js';

// The start under the session's id and the duration under its state, the identity under the
// device: the summary figures stay within a 1280 px window.
const kColumns = ['Preview', 'Session, started', 'State, duration', 'Model', 'Device', 'Peak force', 'Contact', 'Path',
  'Tick p99', 'Warnings', ''];

/** One session's row, kept from one refresh to the next; only what changed is rewritten. */
class SessionRow {
  /** @param {string} id @param {string} role @param {() => void} refresh */
  constructor(id, role, refresh) {
    this.id = id;
    this.role = role;
    this.refresh = refresh;
    // The model wraps (a path); the summary figures are numbers, right-aligned.
    this.cells = kColumns.map((_, i) => h('td', { class: i === 3 ? 'model' : i >= 5 && i <= 9 ? 'num' : undefined }));
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
    // A recorded session's thumbnail: the server renders its surface halfway through (idms-render,
    // cached by content), so the list shows what each session looked like.
    const mid = fixed(s.duration_s / 2, 2);
    this.set(0, live || !(s.duration_s > 0) ? '' : mid, () => [live || !(s.duration_s > 0) ? null
      : h('img', { class: 'thumb', width: 160, height: 90, loading: 'lazy', alt: `The surface at ${mid} s`,
        src: `/api/sessions/${encodeURIComponent(id)}/screenshot.png?t=${mid}&size=160x90` })]);
    const href = live ? `/session/${id}` : `/replay/${id}`;
    const started = formatDate(s.started);
    this.set(1, `${href}|${started}`, () => [h('a', { href, text: id }), h('div', { class: 'under', text: started })]);
    const under = `${fixed(s.duration_s, 1)} s` + (live ? ` · ${s.viewers} watching` : '');
    this.set(2, `${s.state}|${under}`, () => [h('span', { class: `badge ${s.state}`, text: s.state }),
      h('div', { class: 'under', text: under })]);
    this.text(3, s.model);
    // The device (Hello.device), and the agent's identity (its host and pid) under it when it says more.
    const identity = s.identity && s.identity !== s.device ? s.identity : '';
    this.set(4, `${s.device}|${identity}`, () => [s.device, identity ? h('div', { class: 'under identity', text: identity }) : null]);
    const sum = s.summary || {};
    const figures = [fixed(sum.peak_force ?? NaN), `${fixed(sum.contact_time_s ?? NaN, 1)} s`, fixed(sum.path_length ?? NaN),
      sum.tick_p99_us !== undefined ? `${sum.tick_p99_us} µs` : '–', String(sum.warnings ?? '–')];
    for (let k = 0; k < figures.length; k++) this.text(5 + k, figures[k]);
    const deletable = this.role === 'admin' && !live;
    this.set(10, String(deletable), () => [deletable
      ? h('button', { class: 'small danger', 'aria-label': `Delete session ${id}`, text: 'Delete', onclick: async () => {
        if (!confirm(`Delete session ${id} and its recording?`)) return;
        await api(`/api/sessions/${encodeURIComponent(id)}`, { method: 'DELETE' });
        this.refresh();
      } }) : null]);
  }
}

/** @param {string} role */
export function sessionsPage(role) {
  const body = h('tbody');
  const status = h('p', { class: 'muted', role: 'status' });
  const table = h('table', { class: 'list', id: 'sessions' }, [
    h('caption', { text: 'Live sessions first; a live session opens its live view, an ended one its replay.' }),
    h('thead', {}, [h('tr', {}, kColumns.map((t) => h('th', { scope: 'col', text: t })))]),
    body,
  ]);
  page('Sessions', [h('h1', { text: 'Sessions' }), status, h('div', { class: 'scroll' }, [table])]);
  /** @type {Map<string, SessionRow>} */
  const rows = new Map();

  /**
   * The rows in the list's order: new ones inserted, gone ones removed, a kept one moved only when
   * it is out of place (moving a node takes the focus from what is in it).
   * @param {any[]} sessions sorted
   */
  const show = (sessions) => {
    const ids = new Set(sessions.map((s) => String(s.id)));
    for (const [id, row] of rows) {
      if (ids.has(id)) continue;
      row.tr.remove();
      rows.delete(id);
    }
    sessions.forEach((s, i) => {
      const id = String(s.id);
      let row = rows.get(id);
      if (!row) rows.set(id, row = new SessionRow(id, role, refresh));
      row.update(s);
      if (body.children[i] !== row.tr) body.insertBefore(row.tr, body.children[i] ?? null);
    });
  };

  let timer = 0;
  async function refresh() {
    clearTimeout(timer);
    try {
      const { sessions } = await api('/api/sessions');
      sessions.sort((/** @type {any} */ a, /** @type {any} */ b) =>
        Number(b.state === 'live') - Number(a.state === 'live') || String(b.started).localeCompare(String(a.started)));
      show(sessions);
      status.textContent = sessions.length ? `${sessions.length} sessions, updated ${new Date().toLocaleTimeString()}`
        : 'No sessions yet: start an idms-agent against this server.';
    } catch (e) {
      status.textContent = `Cannot load the sessions: ${e instanceof Error ? e.message : String(e)}; retrying…`;
    }
    timer = window.setTimeout(refresh, document.hidden ? 10000 : 2000);
  }
  refresh();
}
