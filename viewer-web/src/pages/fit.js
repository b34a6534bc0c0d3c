// /fit/{id}: a model fitted to a recorded session (POST /api/sessions/{id}/fit). An admin picks
// the model (the session's unless another is named), the parameters and any regions, and starts
// the fit; everyone sees where it has got to (queued, the solver's iterations and the force error
// so far) and, once the fitted model is the library's next version, the fit's report: the
// parameters with their uncertainty and the recorded force against the fitted model's.
import { api, ApiError } from '../net/api.js';
import { showFitReport } from './fit_report.js';
import { h, page } from './dom.js';

/** The parameters the fitter knows, with what each scales. */
const kParams = [
  ['home_k', 'home elements’ stiffness'], ['home_b', 'home elements’ damping'],
  ['surface_k', 'surface elements’ stiffness'], ['surface_b', 'surface elements’ damping'],
  ['k', 'every element’s stiffness'], ['b', 'every element’s damping'], ['tool_k', 'the MIO’s contact stiffness'],
];
const kPollMs = 500;

/** @param {number} x */
function sig(x) {
  return Number.isFinite(x) ? Number(x.toPrecision(4)).toString() : '–';
}

/** @param {string} id @param {string} role */
export function fitPage(id, role) {
  const status = h('p', { class: 'meta', id: 'fit-status', role: 'status', text: 'Loading…' });
  const reportHost = h('section', { id: 'fit-report', 'aria-label': 'Fit report' });
  const form = role === 'admin' ? fitForm(id, () => poll()) : null;
  page(`Fit ${id}`, [
    h('h1', {}, ['Fit a model to session ', h('code', { text: id })]),
    h('p', {}, [h('a', { href: `/replay/${encodeURIComponent(id)}`, text: 'open the replay' }), ' · ',
      h('a', { href: `/report/${encodeURIComponent(id)}`, text: 'report' })]),
    ...(form ? [form.el] : []), status, reportHost,
  ]);
  /** For the tests. */
  const st = { state: '', iteration: 0, replays: 0, model: '', version: 0, points: 0, kind: '', presses: 0, lump: false };
  /** @type {any} */ (window).__idmsFit = st;
  /** @type {{dispose: () => void} | null} */
  let plot = null;
  let timer = 0;
  let shown = '';
  let disposed = false;

  /** @param {any} job */
  async function show(job) {
    // "done" once its report is on the page (the version's metadata is one more request).
    if (job.state !== 'done') st.state = job.state;
    if (form) form.busy(job.state === 'queued' || job.state === 'running');
    status.className = job.state === 'failed' ? 'error' : 'meta';
    if (job.state === 'queued') {
      status.textContent = `Queued: ${job.ahead} fit${job.ahead === 1 ? '' : 's'} ahead.`;
    } else if (job.state === 'running') {
      const p = job.progress || {};
      st.iteration = p.iteration || 0;
      st.replays = p.replays || 0;
      status.textContent = p.presses_total
        ? `Mapping: press ${p.presses_done + 1} of ${p.presses_total}, ${st.replays} replays so far.`
        : `Fitting: iteration ${st.iteration}, ${st.replays} replays of the session, force RMS error ${sig(p.rms)}.`;
    } else if (job.state === 'done') {
      const m = job.result.model;
      status.replaceChildren('Done: the fitted model is ',
        h('a', { href: `/models/${encodeURIComponent(m.name)}?version=${m.version}`, id: 'fit-model', text: `${m.name} version ${m.version}` }), '.');
      const key = `${m.name}@${m.version}`;
      if (shown !== key) {
        shown = key;
        const v = await api(`/api/models/${encodeURIComponent(m.name)}?version=${m.version}`);
        if (disposed) return;
        plot?.dispose();
        const report = v.metadata.fit;
        plot = showFitReport(reportHost, report);
        st.kind = report.kind;
        st.points = (report.curve?.t || []).length;
        st.presses = (report.map?.points || []).length;
        st.lump = !!report.map?.lump?.found;
        st.model = m.name;
        st.version = m.version;
      }
      st.state = 'done';
    } else {
      status.replaceChildren(h('strong', { text: job.state === 'failed' ? 'The fit failed: ' : 'Stopped: ' }), String(job.error || ''));
    }
  }

  async function poll() {
    clearTimeout(timer);
    if (disposed) return;
    try {
      const job = await api(`/api/sessions/${encodeURIComponent(id)}/fit`);
      await show(job);
      if (job.state === 'queued' || job.state === 'running') timer = window.setTimeout(poll, kPollMs);
    } catch (e) {
      if (e instanceof ApiError && e.status === 404) {
        st.state = 'none';
        status.className = 'meta';
        status.textContent = role === 'admin' ? 'No fit of this session yet: choose what to fit and start one.'
          : 'No fit of this session yet (an admin starts one).';
      } else {
        status.className = 'error';
        status.textContent = `Cannot read the fit: ${e instanceof Error ? e.message : String(e)}`;
      }
    }
  }
  poll();
  return () => {
    disposed = true;
    clearTimeout(timer);
    plot?.dispose();
  };
}

/**
 * The admin's form: the model, the parameters, the regions.
 * @param {string} id @param {() => void} started
 */
function fitForm(id, started) {
  const model = h('select', { id: 'fit-model-name', 'aria-label': 'Model to fit' },
    [h('option', { value: '', text: 'the one the session ran' })]);
  const params = kParams.map(([name, what]) => h('label', { class: 'check', title: what }, [
    h('input', { type: 'checkbox', name: 'param', value: name, checked: name === 'home_k' || name === 'surface_k' }), ` ${name}`]));
  const regions = h('textarea', { id: 'fit-regions', rows: 2, placeholder: 'lump=sphere:2,1.5,0,0.9 (one a line; optional)' });
  const map = h('input', { type: 'checkbox', id: 'fit-map-mode' });
  map.addEventListener('change', () => {
    for (const l of params) /** @type {HTMLInputElement} */ (l.firstChild).disabled = map.checked;
    regions.disabled = map.checked;
  });
  const start = h('button', { type: 'submit', id: 'fit-start', text: 'Fit' });
  const result = h('div', { id: 'fit-result', role: 'alert' });
  const el = h('form', { class: 'card', id: 'fit-form', 'aria-labelledby': 'fit-form-title' }, [
    h('h2', { id: 'fit-form-title', text: 'What to fit' }),
    h('label', { for: 'fit-model-name', text: 'Model (the fitted one is its next version)' }), model,
    h('label', { class: 'check' }, [map, ' A scan: map the stiffness press by press and look for a lump (instead of the parameters below)']),
    h('fieldset', {}, [h('legend', { text: 'Parameters' }), ...params]),
    h('label', { for: 'fit-regions', text: 'Regions (each parameter is fitted inside each and outside them all)' }), regions,
    start, result,
  ]);
  api('/api/models').then((r) => {
    for (const m of r.models || []) model.append(h('option', { value: m.name, text: m.name }));
  }).catch(() => {});
  el.addEventListener('submit', async (ev) => {
    ev.preventDefault();
    /** @type {Record<string, any>} */
    const body = map.checked ? { map: true } : {
      params: params.map((l) => /** @type {HTMLInputElement} */ (l.firstChild)).filter((c) => c.checked).map((c) => c.value),
      regions: regions.value.split('\n').map((s) => s.trim()).filter(Boolean),
    };
    if (model.value) body.model = model.value;
    result.className = '';
    result.textContent = '';
    try {
      await api(`/api/sessions/${encodeURIComponent(id)}/fit`, {
        method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
      started();
    } catch (e) {
      result.className = 'error';
      result.replaceChildren(h('strong', { text: 'Refused: ' }), e instanceof Error ? e.message : String(e));
    }
  });
  return { el, busy: (/** @type {boolean} */ b) => { start.disabled = b; } };
}
