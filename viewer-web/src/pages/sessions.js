// /sessions: live and recorded sessions with their summary figures; the list refreshes itself
// every 2 s while the page is visible.
import { api } from '../net/api.js';
import { h, page, fixed, formatDate } from './dom.js';

/** @param {string} role */
export function sessionsPage(role) {
  const body = h('tbody');
  const status = h('p', { class: 'muted', role: 'status' });
  const table = h('table', { class: 'list', id: 'sessions' }, [
    h('caption', { text: 'Live sessions first; a live session opens its live view, an ended one its replay.' }),
    h('thead', {}, [h('tr', {}, ['Preview', 'Session', 'State', 'Model', 'Device', 'Identity', 'Started', 'Duration', 'Peak force',
      'Contact', 'Path', 'Tick p99', 'Warnings', ''].map((t) => h('th', { scope: 'col', text: t })))]),
    body,
  ]);
  page('Sessions', [h('h1', { text: 'Sessions' }), status, h('div', { class: 'scroll' }, [table])]);

  /** @param {any} s */
  const row = (s) => {
    const live = s.state === 'live';
    const href = live ? `/session/${s.id}` : `/replay/${s.id}`;
    const sum = s.summary || {};
    const del = role === 'admin' && !live
      ? h('button', { class: 'small danger', 'aria-label': `Delete session ${s.id}`, text: 'Delete', onclick: async () => {
        if (!confirm(`Delete session ${s.id} and its recording?`)) return;
        await api(`/api/sessions/${encodeURIComponent(s.id)}`, { method: 'DELETE' });
        refresh();
      } }) : null;
    // A recorded session's thumbnail: the server renders its surface halfway through (idms-render,
    // cached by content), so the list shows what each session looked like.
    const mid = fixed(s.duration_s / 2, 2);
    const thumb = !live && s.duration_s > 0
      ? h('img', { class: 'thumb', width: 160, height: 90, loading: 'lazy', alt: `The surface at ${mid} s`,
        src: `/api/sessions/${encodeURIComponent(s.id)}/screenshot.png?t=${mid}&size=160x90` })
      : null;
    return h('tr', { 'data-id': s.id, 'data-state': s.state }, [
      h('td', {}, [thumb]),
      h('td', {}, [h('a', { href, text: s.id })]),
      h('td', {}, [h('span', { class: `badge ${s.state}`, text: s.state + (live ? ` · ${s.viewers} watching` : '') })]),
      h('td', { text: s.model }),
      h('td', { text: s.device }),
      h('td', { text: s.identity }),
      h('td', { text: formatDate(s.started) }),
      h('td', { class: 'num', text: `${fixed(s.duration_s, 1)} s` }),
      h('td', { class: 'num', text: fixed(sum.peak_force ?? NaN) }),
      h('td', { class: 'num', text: `${fixed(sum.contact_time_s ?? NaN, 1)} s` }),
      h('td', { class: 'num', text: fixed(sum.path_length ?? NaN) }),
      h('td', { class: 'num', text: sum.tick_p99_us !== undefined ? `${sum.tick_p99_us} µs` : '–' }),
      h('td', { class: 'num', text: String(sum.warnings ?? '–') }),
      h('td', {}, [del]),
    ]);
  };

  let timer = 0;
  async function refresh() {
    clearTimeout(timer);
    try {
      const { sessions } = await api('/api/sessions');
      sessions.sort((/** @type {any} */ a, /** @type {any} */ b) =>
        Number(b.state === 'live') - Number(a.state === 'live') || String(b.started).localeCompare(String(a.started)));
      body.replaceChildren(...sessions.map(row));
      status.textContent = sessions.length ? `${sessions.length} sessions, updated ${new Date().toLocaleTimeString()}`
        : 'No sessions yet: start an idms-agent against this server.';
    } catch (e) {
      status.textContent = `Cannot load the sessions: ${e instanceof Error ? e.message : String(e)}; retrying…`;
    }
    timer = window.setTimeout(refresh, document.hidden ? 10000 : 2000);
  }
  refresh();
}
