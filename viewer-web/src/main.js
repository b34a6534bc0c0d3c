// The viewer's entry: one page module per URL. Every page but /login asks who the visitor is
// first, which sends a visitor without a login to /login and back.
import './style.css';
import { requireLogin, logout, ApiError } from './net/api.js';
import { loginPage } from './pages/login.js';
import { sessionsPage } from './pages/sessions.js';
import { sessionPage } from './pages/session.js';
import { modelsPage } from './pages/models.js';
import { modelPage } from './pages/model.js';
import { traineePage } from './pages/trainee.js';
import { comparePage } from './pages/compare.js';
import { reportPage } from './pages/report.js';
import { fitPage } from './pages/fit.js';
import { h } from './pages/dom.js';

/** @param {string} path */
function route(path) {
  const parts = path.split('/').filter(Boolean).map(decodeURIComponent);
  if (parts.length === 0) return null;
  const [first, second] = parts;
  if (first === 'sessions' && parts.length === 1) return (/** @type {string} */ role) => sessionsPage(role);
  if (first === 'session' && parts.length === 2) return (/** @type {string} */ role) => sessionPage(second, role, 'live');
  if (first === 'replay' && parts.length === 2) return (/** @type {string} */ role) => sessionPage(second, role, 'replay');
  if (first === 'compare' && parts.length === 3) return (/** @type {string} */ role) => comparePage(second, parts[2], role);
  if (first === 'fit' && parts.length === 2) return (/** @type {string} */ role) => fitPage(second, role);
  if (first === 'report' && parts.length === 2) return (/** @type {string} */ role) => reportPage(second, role);
  if (first === 'trainee' && parts.length === 2) return (/** @type {string} */ role) => traineePage(second, role);
  if (first === 'models' && parts.length === 1) return (/** @type {string} */ role) => modelsPage(role);
  if (first === 'models' && parts.length === 2) return (/** @type {string} */ role) => modelPage(second, role);
  return undefined;
}

async function start() {
  const path = location.pathname;
  if (path === '/login') return loginPage();
  if (path === '/' || path === '') return location.replace('/sessions');
  const show = route(path);
  const role = await requireLogin();
  const who = document.getElementById('who');
  if (who) {
    who.replaceChildren(`${role} `, h('button', { type: 'button', class: 'small', text: 'Log out',
      onclick: async () => { await logout(); location.assign('/login'); } }));
  }
  if (!show) {
    const app = /** @type {HTMLElement} */ (document.getElementById('app'));
    app.replaceChildren(h('h1', { text: 'Not found' }), h('p', {}, ['No page at ', h('code', { text: path }), '.']));
    return;
  }
  show(role);
}

start().catch((e) => {
  // A 401 is already on its way to /login; anything else is said on the page.
  if (e instanceof ApiError && e.status === 401) return;
  const app = /** @type {HTMLElement} */ (document.getElementById('app'));
  app.replaceChildren(h('h1', { text: 'Something went wrong' }), h('p', { class: 'error', role: 'alert', text: String(e instanceof Error ? e.message : e) }));
});
