// REST calls with the login cookie, and the login round trip: a page that meets a 401 sends the
// visitor to /login?next=PATH, and /login sends them back.

/** Thrown for a non-2xx answer; carries the server's JSON body ({error, file, line, column}). */
export class ApiError extends Error {
  /** @param {number} status @param {any} body */
  constructor(status, body) {
    super(body && body.error ? String(body.error) : `HTTP ${status}`);
    this.status = status;
    this.body = body;
  }
}

// The token typed at /login, kept for this tab only, so that the page can log in again by itself
// when a server restart ended its cookie (logins live in the server's memory).
const kTokenKey = 'idms.token';

/** Sends the visitor to the login page, to come back to where they are. */
export function toLogin() {
  const here = location.pathname + location.search;
  location.assign('/login?next=' + encodeURIComponent(here));
}

/**
 * POST /api/login; remembers the token for silent re-login in this tab.
 * @param {string} token
 * @returns {Promise<{role: string}>}
 */
export async function login(token) {
  const res = await fetch('/api/login', {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ token }),
    credentials: 'same-origin',
  });
  const body = await res.json().catch(() => null);
  if (!res.ok) throw new ApiError(res.status, body);
  sessionStorage.setItem(kTokenKey, token);
  return body;
}

/** Logs in again with the remembered token; false when there is none or it is refused. */
export async function relogin() {
  const token = sessionStorage.getItem(kTokenKey);
  if (!token) return false;
  try {
    await login(token);
    return true;
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) sessionStorage.removeItem(kTokenKey);
    return false;
  }
}

export async function logout() {
  sessionStorage.removeItem(kTokenKey);
  await fetch('/api/logout', { method: 'POST', credentials: 'same-origin' }).catch(() => {});
}

/**
 * A JSON API call. A 401 tries one silent re-login, then sends the visitor to /login.
 * @param {string} path
 * @param {RequestInit} [init]
 * @returns {Promise<any>}
 */
export async function api(path, init = {}) {
  for (let attempt = 0; ; attempt++) {
    const res = await fetch(path, { credentials: 'same-origin', ...init });
    if (res.status === 401 && attempt === 0 && (await relogin())) continue;
    if (res.status === 401) {
      toLogin();
      throw new ApiError(401, { error: 'not logged in' });
    }
    const text = await res.text();
    let body = null;
    try {
      body = text ? JSON.parse(text) : null;
    } catch {
      body = { error: text };
    }
    if (!res.ok) throw new ApiError(res.status, body);
    return body;
  }
}

/** The visitor's role, or a trip to /login. @returns {Promise<string>} */
export async function requireLogin() {
  const who = await api('/api/whoami');
  return String(who.role);
}
