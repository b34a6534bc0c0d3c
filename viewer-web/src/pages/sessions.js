// /sessions?trainee=NAME&model=NAME&from=YYYY-MM-DD&to=YYYY-MM-DD: live and recorded sessions with
// their summary figures, filtered by the server (GET /api/sessions takes the same parameters),
// the filters kept in the page's URL so that a reload or a shared link shows the same list. The
// list refreshes itself every 2 s while the page is visible (session_table.js keeps the rows).
import { api } from '../net/api.js';
import { h, page } from './dom.js';
import { sessionTable, sortSessions } from './session_table.js';

/** The filters, in the order of the form; each is a query parameter of the page and of the API. */
const kFilters = /** @type {const} */ (['trainee', 'model', 'from', 'to']);

/** @param {URLSearchParams} params @returns {string} the API's query ('' or '?...'), known filters only, empty ones left out */
export function filterQuery(params) {
  const q = new URLSearchParams();
  for (const k of kFilters) {
    const v = (params.get(k) || '').trim();
    if (v) q.set(k, v);
  }
  const s = q.toString();
  return s ? `?${s}` : '';
}

/** @param {string} role */
export function sessionsPage(role) {
  const status = h('p', { class: 'muted', role: 'status' });
  const { el: tableBox, show } = sessionTable('sessions',
    'Live sessions first; a live session opens its live view, an ended one its replay; a trainee, their page.', role, () => refresh());
  // The filters: free text with the names seen so far offered; dates as the server reads them (UTC).
  const input = {
    trainee: h('input', { id: 'f-trainee', name: 'trainee', list: 'f-trainees', autocomplete: 'off', placeholder: 'any' }),
    model: h('input', { id: 'f-model', name: 'model', list: 'f-models', autocomplete: 'off', placeholder: 'any' }),
    from: h('input', { id: 'f-from', name: 'from', type: 'date' }),
    to: h('input', { id: 'f-to', name: 'to', type: 'date' }),
  };
  const trainees = h('datalist', { id: 'f-trainees' });
  const models = h('datalist', { id: 'f-models' });
  const clear = h('button', { type: 'button', class: 'small', id: 'f-clear', text: 'Clear filters' });
  const form = h('form', { class: 'filters', id: 'filters', role: 'search', 'aria-label': 'Filter the sessions' }, [
    h('label', {}, ['Trainee ', input.trainee]), h('label', {}, ['Model ', input.model]),
    h('label', {}, ['Started from ', input.from]), h('label', {}, ['to ', input.to, ' (UTC dates)']),
    h('button', { type: 'submit', class: 'small', text: 'Apply' }), clear, trainees, models,
  ]);
  page('Sessions', [h('h1', { text: 'Sessions' }), form, status, tableBox]);

  // The URL says what is filtered: the fields from it at load, it from the fields on each change.
  const fromUrl = () => {
    const params = new URLSearchParams(location.search);
    for (const k of kFilters) input[k].value = params.get(k) || '';
  };
  const apply = () => {
    const params = new URLSearchParams();
    for (const k of kFilters) if (input[k].value.trim()) params.set(k, input[k].value.trim());
    const search = params.toString();
    history.replaceState(null, '', `${location.pathname}${search ? `?${search}` : ''}`);
    refresh();
  };
  fromUrl();
  form.addEventListener('submit', (ev) => { ev.preventDefault(); apply(); });
  for (const k of kFilters) input[k].addEventListener('change', apply);
  clear.addEventListener('click', () => {
    for (const k of kFilters) input[k].value = '';
    apply();
  });

  // The names offered: every trainee and model the unfiltered list has, asked once.
  api('/api/sessions').then(({ sessions }) => {
    const names = (/** @type {string} */ key) => [...new Set(sessions.map((/** @type {any} */ s) => String(s[key] || '')))].filter(Boolean).sort();
    trainees.replaceChildren(...names('trainee').map((n) => h('option', { value: n })));
    models.replaceChildren(...names('model').map((n) => h('option', { value: n })));
  }).catch(() => {});

  let timer = 0;
  let asked = 0;
  async function refresh() {
    clearTimeout(timer);
    const query = filterQuery(new URLSearchParams(location.search));
    const mine = ++asked;
    try {
      const { sessions } = await api(`/api/sessions${query}`);
      // A slower answer to an older filter does not replace a newer one's.
      if (mine !== asked) return;
      show(sortSessions(sessions));
      const filtered = query ? ' matching the filters' : '';
      status.textContent = sessions.length ? `${sessions.length} sessions${filtered}, updated ${new Date().toLocaleTimeString()}`
        : query ? 'No sessions match the filters.' : 'No sessions yet: start an idms-agent against this server.';
    } catch (e) {
      if (mine !== asked) return;
      status.textContent = `Cannot load the sessions: ${e instanceof Error ? e.message : String(e)}; retrying…`;
    }
    timer = window.setTimeout(refresh, document.hidden ? 10000 : 2000);
  }
  refresh();
}
