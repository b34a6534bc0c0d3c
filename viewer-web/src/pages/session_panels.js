// The session page's panels that only talk to the page through what they are given: the header
// line, the loop health list, events, annotations, the annotation form and the admin's commands.
// The header and the health list are parts of the page's frame loop, redrawn a few times a second.
import { idms } from '../codec/proto.js';
import { FrameLoop, isDue } from '../view/frame_loop.js';
import { h, fixed, formatTime } from './dom.js';

/** @typedef {(env: idms.v1.IEnvelope) => boolean} Send  sends a frame; false when not connected */

/** The header and the health list change at most this often (text is rastered on each change). */
const kPanelHz = 4;

const v1 = idms.v1;
const kEventNames = new Map(Object.entries(v1.SessionEvent.Kind).map(([name, n]) => [n, name.replace(/^KIND_/, '')]));

/**
 * The line under the title: model, device, identity, state and duration. A live session's
 * duration follows the session's time as samples arrive; a replay's is the recording's.
 */
export class SessionHeader {
  /** @param {'live' | 'replay'} mode @param {{timeS: number}} st @param {FrameLoop} loop */
  constructor(mode, st, loop) {
    this.mode = mode;
    this.st = st;
    this.loop = loop;
    this.text = h('span', { id: 'meta-text', text: 'Loading…' });
    this.duration = h('span', { id: 'duration' });
    this.el = h('p', { class: 'meta', id: 'meta' }, [this.text, this.duration]);
    /** The record's duration when the page asked, s; NaN until it answers. */
    this.recordS = NaN;
    this.lastDraw = -1e9;
    this.shown = '';
    loop.add(this);
  }

  /** @param {{model: string, device: string, identity: string, state: string, duration_s: number}} s */
  setRecord(s) {
    this.text.textContent = `${s.model} · ${s.device} · ${s.identity} · ${s.state} · `;
    this.recordS = s.duration_s;
    this.invalidate();
  }

  /** @param {string} text why the record cannot be shown */
  fail(text) {
    this.text.textContent = text;
  }

  /** The session's time moved (samples came). */
  invalidate() {
    this.loop.request();
  }

  /** @param {number} now ms @returns {boolean} still to draw in a later frame */
  draw(now) {
    if (Number.isNaN(this.recordS)) return false;
    const s = this.mode === 'live' ? Math.max(this.recordS, this.st.timeS) : this.recordS;
    const text = `${fixed(s, 1)} s`;
    if (text === this.shown) return false;
    if (!isDue(this.lastDraw, now, kPanelHz)) return true;
    this.lastDraw = now;
    this.duration.textContent = this.shown = text;
    return false;
  }
}

/**
 * The agent's loop health as a definition list, built once; its values are written in place
 * when they change.
 */
export class HealthPanel {
  /**
   * @param {{timeS: number, warnings: number, fallbacks: number, frames: number, keyframes: number, gaps: number}} st
   * @param {FrameLoop} loop
   * @param {() => number} [sessionTimeS] the session time shown, s: by default the latest sample's
   *   (st.timeS); a replay's is where playback is
   */
  constructor(st, loop, sessionTimeS = () => st.timeS) {
    this.st = st;
    this.loop = loop;
    this.sessionTimeS = sessionTimeS;
    /** @type {import('../codec/frames.js').Stats | idms.v1.ILoopStats} the latest cumulative loop statistics */
    this.stats = {};
    /** Samples the agent's backlog lost. */
    this.dropped = 0;
    this.dirty = true;
    this.lastDraw = -1e9;
    const labels = ['Session time', 'Tick compute p99', 'Period p99', 'Overruns', 'Real-time', 'Warnings',
      'Stability fallbacks', 'Samples dropped', 'Mesh frames'];
    /** @type {Text[]} */
    this.values = labels.map(() => document.createTextNode(''));
    // A pair per div (as HTML allows in a dl), so that the pairs flow into as many columns as the
    // width holds: a strip under the view, one column on a phone.
    this.el = h('dl', { class: 'health', id: 'health' },
      labels.map((label, i) => h('div', {}, [h('dt', { text: label }), h('dd', {}, [this.values[i]])])));
    loop.add(this);
  }

  /**
   * @param {import('../codec/frames.js').Stats | idms.v1.ILoopStats | null | undefined} stats kept by reference
   *   (FrameDecoder's is rewritten in place by each batch: still the latest)
   * @param {number} dropped
   */
  setStats(stats, dropped) {
    if (stats) this.stats = stats;
    this.dropped = dropped;
    this.invalidate();
  }

  invalidate() {
    this.dirty = true;
    this.loop.request();
  }

  /** @param {number} now ms @returns {boolean} still to draw in a later frame */
  draw(now) {
    if (!this.dirty) return false;
    if (!isDue(this.lastDraw, now, kPanelHz)) return true;
    this.dirty = false;
    this.lastDraw = now;
    const st = this.st, s = this.stats;
    this.set(0, formatTime(this.sessionTimeS()));
    this.set(1, `${s.computeP99Us ?? 0} µs`);
    this.set(2, `${s.periodP99Us ?? 0} µs`);
    this.set(3, `${s.overruns ?? 0} of ${s.ticks ?? 0} ticks`);
    this.set(4, s.realtime ? 'yes' : 'no');
    this.set(5, String(st.warnings));
    this.set(6, String(st.fallbacks));
    this.set(7, String(this.dropped));
    this.set(8, `${st.frames} (${st.keyframes} keyframes, ${st.gaps} gaps)`);
    return false;
  }

  /** @param {number} i @param {string} text */
  set(i, text) {
    if (this.values[i].data !== text) this.values[i].data = text;
  }
}

/** The session's events, newest first, the last 200. */
export class EventList {
  /** @param {{fallbacks: number}} st */
  constructor(st) {
    this.st = st;
    this.el = h('ol', { class: 'events', id: 'events', 'aria-live': 'polite' });
  }

  /** @param {idms.v1.ISessionEvent} e @returns {string} its kind's name */
  add(e) {
    const kind = e.kind ? kEventNames.get(e.kind) || String(e.kind) : 'NOTE';
    if (e.kind === v1.SessionEvent.Kind.KIND_STABILITY_FALLBACK) this.st.fallbacks++;
    this.el.prepend(h('li', { class: `event ${kind.toLowerCase()}` }, [
      h('span', { class: 'time', text: formatTime(e.timeS || 0) }), ' ', h('strong', { text: kind }), ' ', e.message || '']));
    while (this.el.childElementCount > 200) this.el.lastElementChild?.remove();
    return kind;
  }
}

/** The session's annotations, each once (they come from the record and from the stream). */
export class AnnotationList {
  /** @param {{annotations: number}} st @param {((a: idms.v1.IAnnotation) => void) | null} onNew */
  constructor(st, onNew) {
    this.st = st;
    this.onNew = onNew;
    /** @type {Set<string>} */
    this.ids = new Set();
    this.el = h('ol', { class: 'notes', id: 'annotations' });
  }

  /** @param {idms.v1.IAnnotation} a */
  add(a) {
    const id = String(a.id ?? '');
    if (this.ids.has(id)) return;
    this.ids.add(id);
    this.st.annotations++;
    this.el.append(h('li', { 'data-id': id, 'data-time': String(a.timeS ?? 0) }, [
      h('span', { class: 'time', text: formatTime(a.timeS || 0) }), ' ', a.text || '', ' ',
      h('span', { class: 'muted', text: `— ${a.author || ''}` })]));
    this.onNew?.(a);
  }
}

/**
 * A note at the current session time, for every viewer and the recording.
 * @param {Send} send
 * @param {{ended: boolean}} st
 */
export function annotationForm(send, st) {
  const input = h('input', { id: 'note', type: 'text', maxlength: 1000, required: true, placeholder: 'e.g. too much force here' });
  const said = h('span', { class: 'error', role: 'alert' });
  const form = h('form', { class: 'inline', id: 'annotate' }, [
    h('label', { for: 'note', text: 'Note at the current time' }), input, h('button', { type: 'submit', text: 'Add note' }), said]);
  form.addEventListener('submit', (ev) => {
    ev.preventDefault();
    const text = input.value.trim();
    if (!text) return;
    const sent = send({ annotation: { text } });
    if (sent) input.value = '';
    said.textContent = sent ? '' : st.ended ? 'The session has ended: notes go on live sessions.' : 'Not connected: the note was not sent.';
  });
  return form;
}

/**
 * The admin's commands to the agent (relayed by the server; an observer's would be refused).
 * @param {Send} send
 */
export function commandPanel(send) {
  let next = 1;
  /** @param {string} label @param {number} kind */
  const button = (label, kind) => h('button', { type: 'button', text: label,
    onclick: () => send({ command: { kind, tool: 0, id: next++ } }) });
  const K = idms.v1.Command.Kind;
  return h('section', { 'aria-labelledby': 'commands-title', id: 'commands' }, [
    h('h2', { id: 'commands-title', text: 'Commands (admin)' }),
    h('div', { class: 'buttons' }, [button('Close tweezers', K.KIND_TWEEZERS_CLOSE), button('Open tweezers', K.KIND_TWEEZERS_OPEN),
      button('Reset model', K.KIND_RESET), button('Request keyframe', K.KIND_KEYFRAME_REQUEST)]),
  ]);
}
