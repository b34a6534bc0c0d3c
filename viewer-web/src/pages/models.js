// /models: the library (updated live from /ws/library) and, for admins, the upload form that
// shows the server's parse error with its file, line and column.
import { api, ApiError } from '../net/api.js';
import { h, page, formatDate } from './dom.js';

const kColumns = ['Model', 'Latest version', 'Atoms', 'Elements', 'Triangles', 'Size', 'Description', 'Added'];

/** @param {string} role */
export function modelsPage(role) {
  const body = h('tbody');
  const status = h('p', { class: 'muted', role: 'status' });
  const table = h('table', { class: 'list cards', id: 'models' }, [
    h('thead', {}, [h('tr', {}, kColumns.map((t) => h('th', { scope: 'col', text: t })))]),
    body,
  ]);
  page('Models', [h('h1', { text: 'Model library' }), status, h('div', { class: 'scroll' }, [table]),
    role === 'admin' ? uploadForm(refresh) : h('p', { class: 'muted', text: 'Uploads and deletes need an admin token.' })]);

  async function refresh() {
    try {
      const { models } = await api('/api/models');
      // Each cell labelled for a phone's card (style.css, table.cards).
      const cell = (/** @type {number} */ k, /** @type {Record<string, any>} */ attrs, /** @type {Node[]} */ children = []) =>
        h('td', { ...attrs, 'data-label': kColumns[k] }, children);
      body.replaceChildren(...models.map((/** @type {any} */ m) => h('tr', { 'data-name': m.name }, [
        cell(0, {}, [h('a', { href: `/models/${encodeURIComponent(m.name)}`, text: m.name })]),
        cell(1, { class: 'num', text: String(m.latest_version) }),
        cell(2, { class: 'num', text: String(m.atoms) }),
        cell(3, { class: 'num', text: String(m.elements) }),
        cell(4, { class: 'num', text: String(m.triangles) }),
        cell(5, { class: 'num', text: `${(m.bytes / 1024).toFixed(1)} KiB` }),
        cell(6, { text: m.description }),
        cell(7, { text: formatDate(m.created) }),
      ])));
      status.textContent = `${models.length} models`;
    } catch (e) {
      status.textContent = `Cannot load the library: ${e instanceof Error ? e.message : String(e)}`;
    }
  }
  refresh();
  // The library's changes, pushed by the server.
  const ws = new WebSocket((location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/ws/library');
  ws.onmessage = () => refresh();
  return () => ws.close();
}

/** @param {() => void} done */
function uploadForm(done) {
  const name = h('input', { id: 'up-name', name: 'name', required: true, pattern: '[A-Za-z0-9_.\\-]{1,64}' });
  const fem = h('input', { id: 'up-fem', name: 'fem', type: 'file', accept: '.fem', required: true });
  const plg = h('input', { id: 'up-plg', name: 'plg', type: 'file', accept: '.plg', required: true });
  const desc = h('input', { id: 'up-desc', name: 'description' });
  const result = h('div', { id: 'upload-result', role: 'alert' });
  const form = h('form', { class: 'card', id: 'upload', 'aria-labelledby': 'upload-title' }, [
    h('h2', { id: 'upload-title', text: 'Upload a model (a new version if the name exists)' }),
    h('label', { for: 'up-name', text: 'Name' }), name,
    h('label', { for: 'up-fem', text: 'Atoms and elements (.fem)' }), fem,
    h('label', { for: 'up-plg', text: 'Surface polygons (.plg)' }), plg,
    h('label', { for: 'up-desc', text: 'Description' }), desc,
    h('button', { type: 'submit', text: 'Upload' }), result,
  ]);
  form.addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const data = new FormData();
    data.append('fem', /** @type {File} */ (fem.files?.[0]));
    data.append('plg', /** @type {File} */ (plg.files?.[0]));
    data.append('description', desc.value);
    result.className = '';
    result.textContent = 'Uploading…';
    try {
      const r = await api(`/api/models/${encodeURIComponent(name.value)}`, { method: 'PUT', body: data });
      result.className = 'ok';
      result.replaceChildren('Stored ', h('a', { href: `/models/${encodeURIComponent(r.name)}`, text: `${r.name} version ${r.version}` }),
        ` (${r.atoms} atoms).`);
      done();
    } catch (e) {
      result.className = 'error';
      const b = e instanceof ApiError ? e.body || {} : {};
      // The parser's own place: file:line:column, then what it expected.
      const where = b.file ? `${b.file}:${b.line}:${b.column}` : '';
      const message = e instanceof Error ? e.message : String(e);
      result.replaceChildren(h('strong', { text: 'Refused: ' }), where ? h('code', { class: 'where', text: where }) : '',
        where ? ': ' : '', where && message.startsWith(`${where}: `) ? message.slice(where.length + 2) : message);
    }
  });
  return form;
}
