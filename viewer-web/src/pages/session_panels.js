// The session page's panels that only talk to the page through what they are given: the header
// line, the loop health list, events, annotations, the annotation form and the admin's commands.
// The header and the health list are parts of the page's frame loop, redrawn a few times a second.
import { idms } from '../codec/proto.js';
import { FrameLoop, isDue } from '../view/frame_loop.js';
import { api } from '../net/api.js';
import { h, formatTime } from './dom.js';
import { LoopWatch } from './loop_verdict.js';
import { traineeHref } from './session_table.js';
import { gradeList } from './grade.js';
import { Units } from '../view/units.js';

/** @typedef {(env: idms.v1.IEnvelope) => boolean} Send  sends a frame; false when not connected */

/** The header and the health list change at most this often (text is rastered on each change). */
const kPanelHz = 4;

const v1 = idms.v1;
const EventKind = v1.SessionEvent.Kind;
/** Each event kind's enum name without KIND_, lower case: its CSS class ("force_limit"). */
/** The enum's values by name. @type {Record<string, number>} */
const kKindByName = /** @type {any} */ (EventKind);
const kEventSlugs = new Map(Object.entries(EventKind).map(([name, n]) => [n, name.replace(/^KIND_/, '').toLowerCase()]));

/**
 * An event kind as words: "Reset", "Force limit", "Agent disconnected".
 * @param {number | string | null | undefined} kind the enum's number, or its name as the REST API writes it
 */
export function eventName(kind) {
  const n = typeof kind === 'string' ? kKindByName[kind] : kind;
  const slug = kEventSlugs.get(Number(n));
  if (!slug || n === EventKind.KIND_UNSPECIFIED) return 'Note';
  const words = slug.replace(/_/g, ' ');
  return words[0].toUpperCase() + words.slice(1);
}

/** What an event's count means, in words ('' when it has none). @param {number} kind @param {number} count */
function countWords(kind, count) {
  if (!(count > 0)) return '';
  if (kind === EventKind.KIND_FORCE_LIMIT) return `${count} ${count === 1 ? 'tick' : 'ticks'} clamped`;
  if (kind === EventKind.KIND_WARNING) return `${count} ${count === 1 ? 'warning' : 'warnings'}`;
  if (kind === EventKind.KIND_SAMPLES_DROPPED) return `${count} samples lost`;
  return '';
}

/** The agent's commands as the buttons name them (a relayed command's event names its enum). */
const kCommandWords = new Map([['KIND_TWEEZERS_CLOSE', 'Close tweezers'], ['KIND_TWEEZERS_OPEN', 'Open tweezers'],
  ['KIND_RESET', 'Reset model'], ['KIND_KEYFRAME_REQUEST', 'Request keyframe']]);

/**
 * An event's message with the enum names the server writes into some ("command KIND_RESET relayed
 * to the agent") as words: a command as its button says it, anything else in lower case.
 * @param {number} kind @param {string} message
 */
export function messageWords(kind, message) {
  // "Command: command reset ..." says it twice.
  if (kind === EventKind.KIND_COMMAND) message = message.replace(/^command /, '');
  return message.replace(/\bKIND_[A-Z_]+\b/g, (name) => (kind === EventKind.KIND_COMMAND && kCommandWords.get(name))
    || `"${name.slice(5).toLowerCase().replace(/_/g, ' ')}"`);
}

/**
 * An event as the REST API lists it ({kind: "KIND_RESET", time_s, tick, count, message, peer}), as
 * the stream carries it.
 * @param {any} e @returns {idms.v1.ISessionEvent}
 */
export function eventFromRecord(e) {
  return { kind: kKindByName[e.kind] ?? 0, timeS: e.time_s, tick: e.tick, count: e.count,
    message: e.message, peer: e.peer };
}

/**
 * The line under the title: model, device, identity, state and duration, and the trainee (an
 * admin can correct it: PATCH /api/sessions/{id}). A live session's duration follows the session's
 * time as samples arrive; a replay's is the recording's.
 */
export class SessionHeader {
  /**
   * @param {string} id @param {'live' | 'replay'} mode @param {string} role
   * @param {{timeS: number}} st @param {FrameLoop} loop
   */
  constructor(id, mode, role, st, loop) {
    this.id = id;
    this.mode = mode;
    this.role = role;
    this.st = st;
    this.loop = loop;
    this.text = h('span', { id: 'meta-text', text: 'Loading…' });
    this.duration = h('span', { id: 'duration' });
    this.trainee = h('span', { id: 'trainee' });
    this.grade = h('div', { id: 'grade' });
    this.el = h('div', { class: 'meta', id: 'meta' }, [h('p', {}, [this.text, this.duration]), this.trainee, this.grade]);
    /** The record's duration when the page asked, s; NaN until it answers. */
    this.recordS = NaN;
    this.lastDraw = -1e9;
    this.shown = '';
    loop.add(this);
  }

  /**
   * @param {{model: string, device: string, identity: string, state: string, duration_s: number, trainee?: string,
   *   grade?: import('./grade.js').Grade, units?: any}} s
   */
  setRecord(s) {
    this.text.textContent = `${s.model} · ${s.device} · ${s.identity} · ${s.state} · `;
    this.recordS = s.duration_s;
    this.showTrainee(String(s.trainee || ''));
    this.grade.replaceChildren(gradeList(s.grade, new Units(s.units)));
    this.invalidate();
  }

  /** The trainee, a link to their page; for an admin an Edit button that opens a field in place. @param {string} name */
  showTrainee(name) {
    const edit = this.role === 'admin' ? h('button', { type: 'button', class: 'small', id: 'trainee-edit', text: 'Edit',
      'aria-label': 'Edit the trainee', onclick: () => this.editTrainee(name) }) : null;
    this.trainee.replaceChildren('Trainee: ', name ? h('a', { href: traineeHref(name), id: 'trainee-name', text: name })
      : h('span', { class: 'muted', id: 'trainee-name', text: 'not named' }), ' ', edit ?? '');
  }

  /** @param {string} name the trainee now */
  editTrainee(name) {
    const input = h('input', { id: 'trainee-input', value: name, maxlength: 256, 'aria-label': 'Trainee', autocomplete: 'off' });
    const said = h('span', { class: 'error', role: 'alert', id: 'trainee-error' });
    const form = h('form', { class: 'inline trainee-form', id: 'trainee-form' }, [h('label', { for: 'trainee-input', text: 'Trainee' }), input,
      h('button', { type: 'submit', class: 'small', text: 'Save' }),
      h('button', { type: 'button', class: 'small', text: 'Cancel', onclick: () => this.showTrainee(name) }), said]);
    form.addEventListener('submit', async (ev) => {
      ev.preventDefault();
      try {
        const row = await api(`/api/sessions/${encodeURIComponent(this.id)}`, { method: 'PATCH',
          headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ trainee: input.value.trim() }) });
        this.showTrainee(String(row.trainee ?? ''));
      } catch (e) {
        said.textContent = `Not saved: ${e instanceof Error ? e.message : String(e)}`;
      }
    });
    this.trainee.replaceChildren(form);
    input.focus();
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
    // Whole tenths of a second in the page's one time format (a 1 kHz millisecond would churn).
    const text = formatTime(Math.floor(10 * s) / 10);
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
   * @param {{timeS: number, warnings: number, fallbacks: number, frames: number, keyframes: number, gaps: number,
   *   portEnergy?: number, passivityDamping?: number}} st
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
    /** Whether the loop keeps up, in words (loop_verdict.js says the rule). */
    this.watch = new LoopWatch();
    this.verdict = h('p', { id: 'loop-verdict', class: 'verdict unknown', role: 'status', text: 'No loop figures yet.' });
    this.dirty = true;
    this.lastDraw = -1e9;
    const labels = ['Session time', 'Tick compute p99', 'Period p99', 'Overruns', 'Real-time', 'Warnings',
      'Stability fallbacks', 'Samples dropped', 'Mesh frames', 'Port energy', 'Passivity controller'];
    /** @type {Text[]} */
    this.values = labels.map(() => document.createTextNode(''));
    // A pair per div (as HTML allows in a dl), so that the pairs flow into as many columns as the
    // width holds: a strip under the view, one column on a phone.
    this.list = h('dl', { class: 'health', id: 'health' },
      labels.map((label, i) => h('div', {}, [h('dt', { text: label }), h('dd', {}, [this.values[i]])])));
    this.el = h('div', {}, [this.verdict, this.list]);
    loop.add(this);
  }

  /** @param {number} hz the loop's rate (the scene's DeviceMapping.max_rate_hz) */
  setRate(hz) {
    if (hz > 0) this.watch.nominalUs = Math.round(1e6 / hz);
  }

  /**
   * @param {import('../codec/frames.js').Stats | idms.v1.ILoopStats | null | undefined} stats kept by reference
   *   (FrameDecoder's is rewritten in place by each batch: still the latest)
   * @param {number} dropped
   */
  setStats(stats, dropped) {
    if (stats) {
      this.stats = stats;
      const v = this.watch.update(stats);
      if (this.verdict.textContent !== v.text) this.verdict.textContent = v.text;
      this.verdict.className = `verdict ${v.state}`;
    }
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
    this.set(2, `${s.periodP99Us ?? 0} µs (of ${this.watch.nominalUs} µs)`);
    this.set(3, `${s.overruns ?? 0} of ${s.ticks ?? 0} ticks`);
    this.set(4, s.realtime ? 'yes' : 'no');
    this.set(5, String(st.warnings));
    this.set(6, String(st.fallbacks));
    this.set(7, String(this.dropped));
    this.set(8, `${st.frames} (${st.keyframes} keyframes, ${st.gaps} gaps)`);
    // The passivity controller (docs/passivity.md): the energy the hand has put in through the port,
    // and how often and how much its damping took out; "off" when the agent runs without it.
    const acted = Number(s.passivityTicks ?? 0), dissipated = Number(s.passivityDissipated ?? 0);
    const energy = st.portEnergy ?? 0, damping = st.passivityDamping ?? 0;
    const on = acted > 0 || energy !== 0 || dissipated !== 0;
    this.set(9, on ? energy.toPrecision(3) : 'not observed');
    this.set(10, on ? `acted on ${acted} ticks, dissipated ${dissipated.toPrecision(3)}, damping now ${damping.toPrecision(3)}` : 'off');
    return false;
  }

  /** @param {number} i @param {string} text */
  set(i, text) {
    if (this.values[i].data !== text) this.values[i].data = text;
  }
}

/**
 * The session's events, newest first by session time, each once: a replay played again, sought
 * back or reconnected sends them again, and the record lists those from before the page opened.
 * The last 200.
 */
export class EventList {
  /** @param {{fallbacks: number}} st */
  constructor(st) {
    this.st = st;
    this.el = h('ol', { class: 'events', id: 'events', 'aria-live': 'polite' });
    /** @type {Set<string>} */
    this.keys = new Set();
  }

  /** @param {idms.v1.ISessionEvent} e @returns {boolean} it was new */
  add(e) {
    const kind = Number(e.kind || 0), t = Number(e.timeS || 0);
    const key = `${kind}|${e.tick ?? 0}|${t.toFixed(6)}|${e.message || ''}|${e.peer || ''}`;
    if (this.keys.has(key)) return false;
    this.keys.add(key);
    if (kind === EventKind.KIND_STABILITY_FALLBACK) this.st.fallbacks++;
    const counted = countWords(kind, Number(e.count || 0));
    const li = h('li', { class: `event ${kEventSlugs.get(kind) || 'note'}`, 'data-time': String(t) }, [
      h('span', { class: 'time', text: formatTime(t) }), ' ', h('strong', { text: eventName(kind) }),
      counted ? ` (${counted})` : '', ' ', messageWords(kind, e.message || ''),
      e.peer && kind === EventKind.KIND_COMMAND ? h('span', { class: 'muted', text: ` — ${e.peer}` }) : null]);
    // Newest first: before the first one that is not later (a live event is at the top at once).
    let next = this.el.firstElementChild;
    while (next && Number(/** @type {HTMLElement} */ (next).dataset.time) > t) next = next.nextElementSibling;
    this.el.insertBefore(li, next);
    while (this.el.childElementCount > 200) this.el.lastElementChild?.remove();
    return true;
  }
}

/**
 * The notes, in session-time order whenever they came (recorded, live, added in replay), each time
 * a button that jumps there (a replay seeks; a live view opens the replay at that time).
 */
export class AnnotationList {
  /**
   * @param {{annotations: number}} st
   * @param {((a: idms.v1.IAnnotation) => void) | null} onNew
   * @param {(t: number) => void} onJump
   */
  constructor(st, onNew, onJump) {
    this.st = st;
    this.onNew = onNew;
    this.onJump = onJump;
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
    const t = Number(a.timeS || 0);
    const jump = h('button', { type: 'button', class: 'time jump', title: 'Go to this time', text: formatTime(t) });
    jump.addEventListener('click', () => this.onJump(t));
    const li = h('li', { 'data-id': id, 'data-time': String(t) }, [jump, ' ', a.text || '', ' ',
      h('span', { class: 'muted', text: `— ${a.author || ''}` })]);
    const later = [...this.el.children].find((c) => Number(/** @type {HTMLElement} */ (c).dataset.time) > t);
    this.el.insertBefore(li, later ?? null);
    this.onNew?.(a);
  }
}

/**
 * A note at the current session time: `submit` sends it and resolves to '' once taken, else to
 * what went wrong (said beside the field; the text stays to try again).
 * @param {string} label
 * @param {(text: string) => Promise<string>} submit
 */
export function annotationForm(label, submit) {
  const input = h('input', { id: 'note', type: 'text', maxlength: 1000, required: true, placeholder: 'e.g. too much force here' });
  const said = h('span', { class: 'error', role: 'alert' });
  const form = h('form', { class: 'inline', id: 'annotate' }, [
    h('label', { for: 'note', text: label }), input, h('button', { type: 'submit', text: 'Add note' }), said]);
  form.addEventListener('submit', (ev) => {
    ev.preventDefault();
    const text = input.value.trim();
    if (!text) return;
    submit(text).then((error) => {
      if (!error) input.value = '';
      said.textContent = error;
    });
  });
  return form;
}

/**
 * The admin's commands to the agent (relayed by the server; an observer's would be refused): only
 * those that apply to the session's tools (the tweezers' for tweezers, said by the scene in the
 * Welcome), and Reset model only once confirmed (it puts the tissue back to rest under the
 * trainee's hand).
 * @param {Send} send
 * @param {{commandsSent: number}} st counted into
 */
export function commandPanel(send, st) {
  let next = 1;
  const K = idms.v1.Command.Kind;
  /** @param {number} kind @param {number} tool */
  const sendCommand = (kind, tool) => {
    if (send({ command: { kind, tool, id: next++ } })) st.commandsSent++;
  };
  /** @param {string} label @param {number} kind @param {number} [tool] @param {string} [ask] a question to confirm first */
  const button = (label, kind, tool = 0, ask = '') => h('button', { type: 'button', text: label, class: ask ? 'danger-fill' : undefined,
    onclick: () => {
      if (ask && !confirm(ask)) return;
      sendCommand(kind, tool);
    } });
  const reset = button('Reset model', K.KIND_RESET, 0,
    'Reset the model to rest? The tissue under the trainee\'s tool returns to its rest shape at once.');
  const buttons = h('div', { class: 'buttons' }, [reset, button('Request keyframe', K.KIND_KEYFRAME_REQUEST)]);
  const el = h('section', { 'aria-labelledby': 'commands-title', id: 'commands' }, [h('h2', { id: 'commands-title', text: 'Commands (admin)' }), buttons]);
  /** The scene's tools: a pair of tweezers buttons per tweezers tool, named when there are several. @param {idms.v1.ITool[]} tools */
  const setTools = (tools) => {
    for (const b of buttons.querySelectorAll('.tweezers')) b.remove();
    const tweezers = tools.map((t, i) => ({ t, i })).filter(({ t }) => t.kind === idms.v1.Tool.Kind.KIND_TWEEZERS);
    for (const { t, i } of tweezers.reverse()) {
      const name = tweezers.length > 1 ? ` ${t.name || i}` : '';
      const close = button(`Close tweezers${name}`, K.KIND_TWEEZERS_CLOSE, i), open = button(`Open tweezers${name}`, K.KIND_TWEEZERS_OPEN, i);
      close.classList.add('tweezers');
      open.classList.add('tweezers');
      buttons.prepend(close, open);
    }
  };
  return { el, setTools };
}
