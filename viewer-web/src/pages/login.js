// /login: a token in, the server's cookie out, then back to where the visitor was going.
import { login, ApiError } from '../net/api.js';
import { h, page } from './dom.js';

export function loginPage() {
  const next = new URLSearchParams(location.search).get('next') || '/sessions';
  const input = h('input', { id: 'token', name: 'token', type: 'password', autocomplete: 'current-password', required: true });
  const error = h('p', { id: 'login-error', class: 'error', role: 'alert' });
  const form = h('form', { class: 'card narrow', 'aria-labelledby': 'login-title' }, [
    h('h1', { id: 'login-title', text: 'Log in' }),
    h('p', { text: 'Paste the token your administrator gave you (idms-server token create ROLE).' }),
    h('label', { for: 'token', text: 'Token' }),
    input,
    h('button', { type: 'submit', text: 'Log in' }),
    error,
  ]);
  form.addEventListener('submit', async (ev) => {
    ev.preventDefault();
    error.textContent = '';
    try {
      await login(input.value.trim());
      // Only a path on this site: never an open redirect.
      location.assign(next.startsWith('/') && !next.startsWith('//') ? next : '/sessions');
    } catch (e) {
      error.textContent = e instanceof ApiError && e.status === 401 ? 'That token is not known to this server.'
        : `Login failed: ${e instanceof Error ? e.message : String(e)}`;
    }
  });
  page('Log in', [form]);
  input.focus();
}
