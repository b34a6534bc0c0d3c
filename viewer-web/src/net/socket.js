// A WebSocket of idms.v1.Envelope frames that reconnects by itself (backoff 0.25 s doubling to
// 5 s) and says what it is doing; a refused upgrade first tries a silent re-login.
import { idms } from '../codec/proto.js';
import { FrameDecoder } from '../codec/frames.js';
import { relogin } from './api.js';

const Envelope = idms.v1.Envelope;

/**
 * @typedef {{
 *   onOpen?: (socket: EnvelopeSocket) => void,
 *   onEnvelope: (env: import('../codec/frames.js').Frame) => void,
 *   onStatus?: (state: 'connecting' | 'open' | 'reconnecting' | 'closed', text: string) => void,
 * }} SocketHandlers
 */

export class EnvelopeSocket {
  /** @param {string} path e.g. /ws/session/ID @param {SocketHandlers} handlers */
  constructor(path, handlers) {
    this.path = path;
    this.handlers = handlers;
    // Frames decoded into reused objects (valid until the next message).
    this.decoder = new FrameDecoder();
    /** @type {WebSocket | null} */
    this.ws = null;
    this.attempt = 0;
    this.stopped = false;
    this.opened = false;
    /** @type {ReturnType<typeof setTimeout> | undefined} */
    this.timer = undefined;
    this.connect();
  }

  connect() {
    const url = (location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + this.path;
    this.status(this.attempt === 0 ? 'connecting' : 'reconnecting',
      this.attempt === 0 ? 'connecting…' : `reconnecting (attempt ${this.attempt})…`);
    const ws = new WebSocket(url);
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    this.opened = false;
    ws.onopen = () => {
      this.opened = true;
      this.attempt = 0;
      this.status('open', 'connected');
      this.handlers.onOpen?.(this);
    };
    ws.onmessage = (ev) => {
      if (!(ev.data instanceof ArrayBuffer)) return;
      this.decoder.each(new Uint8Array(ev.data), (frame) => this.handlers.onEnvelope(frame));
    };
    ws.onclose = () => this.retry();
  }

  async retry() {
    if (this.stopped) return;
    this.ws = null;
    this.attempt++;
    const delay = Math.min(5000, 250 * 2 ** Math.min(this.attempt - 1, 5));
    this.status('reconnecting', `connection lost; reconnecting in ${(delay / 1000).toFixed(1)} s…`);
    // A connection refused before it opened may be a login that ended with a server restart.
    if (!this.opened && this.attempt > 1) await relogin();
    this.timer = setTimeout(() => this.connect(), delay);
  }

  /** @param {idms.v1.IEnvelope} env @returns {boolean} sent */
  send(env) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(/** @type {Uint8Array<ArrayBuffer>} */ (Envelope.encode(env).finish()));
    return true;
  }

  close() {
    this.stopped = true;
    clearTimeout(this.timer);
    this.ws?.close();
    this.status('closed', '');
  }

  /** @param {'connecting' | 'open' | 'reconnecting' | 'closed'} state @param {string} text */
  status(state, text) {
    this.handlers.onStatus?.(state, text);
  }
}
