// Small DOM helpers shared by the pages: element creation, text formatting.

/**
 * An element with attributes and children. Attributes starting with "on" become listeners.
 * @template {keyof HTMLElementTagNameMap} K
 * @param {K} tag
 * @param {Record<string, any>} [attrs]
 * @param {(Node | string | null | undefined | false)[]} [children]
 * @returns {HTMLElementTagNameMap[K]}
 */
export function h(tag, attrs = {}, children = []) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith('on') && typeof v === 'function') el.addEventListener(k.slice(2), v);
    else if (k === 'text') el.textContent = String(v);
    else el.setAttribute(k, v === true ? '' : String(v));
  }
  for (const c of children) if (c !== null && c !== undefined && c !== false) el.append(c);
  return el;
}

/** @param {number} s seconds @returns {string} e.g. 1:02.345 */
export function formatTime(s) {
  if (!Number.isFinite(s)) return '–';
  const m = Math.floor(s / 60);
  const rest = s - 60 * m;
  return `${m}:${rest.toFixed(3).padStart(6, '0')}`;
}

/** @param {string} iso @returns {string} */
export function formatDate(iso) {
  const d = new Date(iso);
  return Number.isNaN(d.getTime()) ? iso : d.toLocaleString();
}

/** @param {number} x @param {number} [digits] */
export function fixed(x, digits = 2) {
  return Number.isFinite(x) ? x.toFixed(digits) : '–';
}

/** Replaces the page's content and title. @param {string} title @param {Node[]} children */
export function page(title, children) {
  document.title = `${title} · idms`;
  const app = /** @type {HTMLElement} */ (document.getElementById('app'));
  app.replaceChildren(...children);
  return app;
}
