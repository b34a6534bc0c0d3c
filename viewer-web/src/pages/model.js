// /models/{name}: the model's versions with their hashes, a 3D preview of a version at rest (its
// .obj surface) coloured by stiffness (each surface atom's mean element k, from its .fem: an
// inclusion shows), a fitted version's fit report (fit_report.js), and delete for admins.
// ?version=N previews that version first.
import { api } from '../net/api.js';
import { parseObj } from '../codec/obj.js';
import { SurfaceView } from '../view/surface.js';
import { stiffnessPerVertex } from '../view/display.js';
import { showFitReport } from './fit_report.js';
import { h, page, formatDate } from './dom.js';

const kVersionColumns = ['Version', '', 'Atoms', 'Elements', 'Triangles', 'Description', 'Added', 'fem SHA-256'];

/** @param {string} name @param {string} role */
export function modelPage(name, role) {
  const viewHost = h('div', { class: 'view3d preview', id: 'preview' });
  const colour = h('select', { id: 'colour-by', 'aria-label': 'Colour the preview by' },
    [h('option', { value: 'stiffness', text: 'stiffness' }), h('option', { value: 'plain', text: 'plain' })]);
  const info = h('p', { class: 'meta', id: 'preview-info', role: 'status', text: 'Loading…' });
  const body = h('tbody');
  const fitHost = h('div', { id: 'fit-report' });
  const fitSection = h('section', { 'aria-labelledby': 'fit-title', id: 'fit-section', hidden: true },
    [h('h2', { id: 'fit-title', text: 'Fit report' }), fitHost]);
  page(`Model ${name}`, [
    h('h1', {}, ['Model ', h('code', { text: name })]),
    info,
    h('div', { class: 'model-grid' }, [
      h('section', { 'aria-label': 'Preview at rest' }, [viewHost, h('div', { class: 'toolbar' }, [h('label', {}, ['Colour ', colour])])]),
      h('section', { 'aria-labelledby': 'versions-title' }, [h('h2', { id: 'versions-title', text: 'Versions' }),
        h('div', { class: 'scroll' }, [h('table', { class: 'list', id: 'versions' }, [
          h('thead', {}, [h('tr', {}, kVersionColumns.map((t) => h('th', { scope: 'col', text: t })))]), body])])]),
    ]),
    fitSection,
  ]);
  const view = new SurfaceView(viewHost);
  /** The fit report's plot, while one is shown. @type {{dispose: () => void} | null} */
  let fitPlot = null;
  /** Per surface vertex of the version shown; null until its .fem is read (or when it cannot be). @type {Float64Array | null} */
  let stiffness = null;
  const applyColour = () => view.setColourBy(colour.value === 'stiffness' && stiffness ? 'stiffness' : 'plain', stiffness);
  colour.addEventListener('change', applyColour);

  /** @param {number} version */
  async function preview(version) {
    const file = (/** @type {string} */ kind) => fetch(`/api/models/${encodeURIComponent(name)}/${kind}?version=${version}`,
      { credentials: 'same-origin' }).then((res) => {
      if (!res.ok) throw new Error(`${kind}: HTTP ${res.status}`);
      return res.text();
    });
    const [obj, fem, meta] = await Promise.all([file('obj'), file('fem'),
      api(`/api/models/${encodeURIComponent(name)}?version=${version}`)]);
    // A fitted version's report under the preview; none for an upload.
    fitPlot?.dispose();
    fitPlot = null;
    fitSection.hidden = !meta.metadata?.fit;
    if (meta.metadata?.fit) {
      fitPlot = showFitReport(fitHost, meta.metadata.fit);
      /** @type {HTMLElement} */ (document.getElementById('fit-title')).textContent =
        `${meta.metadata.fit.kind === 'map' ? 'Stiffness map' : 'Fit report'} of version ${version}`;
    }
    const surface = parseObj(obj);
    stiffness = stiffnessPerVertex(fem);
    if (stiffness.length !== surface.numVertices) stiffness = null;
    view.fitted = false;
    view.setSurface(surface);
    applyColour();
    let kRange = '';
    if (stiffness) kRange = `, stiffness k ${view.surface.lo.toPrecision(3)} to ${view.surface.hi.toPrecision(3)}`;
    info.textContent = `Version ${version} at rest: ${surface.numVertices} surface vertices, ${surface.numTriangles} triangles${kRange}`;
    /** @type {any} */ (window).__idmsPreview = { version, fitted: !!meta.metadata?.fit, vertices: surface.numVertices, triangles: surface.numTriangles,
      colourBy: view.surface.colourBy, lo: view.surface.lo, hi: view.surface.hi };
  }
  // For the tests: where the stiffer half of the range's vertices fall on the canvas (their centre
  // and half their extent across and up, CSS pixels); null when the model is one stiffness.
  /** @type {any} */ (window).__idmsStiffRegion = () => {
    const g = view.surface;
    if (!stiffness || !(g.hi > g.lo)) return null;
    const points = [];
    for (let v = 0; v < g.numVertices; v++) {
      if (stiffness[v] >= (g.lo + g.hi) / 2) points.push(view.project(g.actual[3 * v], g.actual[3 * v + 1], g.actual[3 * v + 2]));
    }
    const xs = points.map((p) => p.x), ys = points.map((p) => p.y);
    const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
    return { x: (x0 + x1) / 2, y: (y0 + y1) / 2, rx: (x1 - x0) / 2, ry: (y1 - y0) / 2, count: points.length };
  };

  async function load() {
    const m = await api(`/api/models/${encodeURIComponent(name)}`);
    const versions = [...(m.versions || [])].sort((/** @type {any} */ a, /** @type {any} */ b) => b.version - a.version);
    // The actions next to the version they act on (last, they sat past the right edge at 1280 px).
    const cell = (/** @type {number} */ k, /** @type {Record<string, any>} */ attrs, /** @type {(Node | string | null)[]} */ children = []) =>
      h('td', { ...attrs, 'data-label': kVersionColumns[k] || undefined }, children);
    body.replaceChildren(...versions.map((/** @type {any} */ v) => h('tr', { 'data-version': v.version }, [
      cell(0, { class: 'num', text: String(v.version) }),
      cell(1, { class: 'actions' }, [
        h('button', { type: 'button', class: 'small', text: 'Preview', 'aria-label': `Preview version ${v.version}`, onclick: () => preview(v.version) }),
        role === 'admin' ? h('button', { type: 'button', class: 'small danger', text: 'Delete', 'aria-label': `Delete version ${v.version}`,
          onclick: async () => {
            if (!confirm(`Delete ${name} version ${v.version}?`)) return;
            await api(`/api/models/${encodeURIComponent(name)}?version=${v.version}`, { method: 'DELETE' });
            if (versions.length === 1) location.assign('/models');
            else load();
          } }) : null,
      ]),
      cell(2, { class: 'num', text: String(v.atoms) }),
      cell(3, { class: 'num', text: String(v.elements) }),
      cell(4, { class: 'num', text: String(v.triangles) }),
      cell(5, { text: v.description }),
      cell(6, { text: formatDate(v.created) }),
      cell(7, { class: 'hash' }, [h('code', { text: String(v.fem_sha256).slice(0, 12) + '…', title: v.fem_sha256 })]),
    ])));
    const asked = Number(new URL(location.href).searchParams.get('version'));
    const first = versions.find((/** @type {any} */ v) => v.version === asked) ?? versions[0];
    if (first) await preview(first.version);
  }
  load().catch((e) => { info.textContent = `Cannot load ${name}: ${e instanceof Error ? e.message : String(e)}`; });
  return () => {
    fitPlot?.dispose();
    view.dispose();
  };
}
