// The live view's side panels that only talk to the page through what they are given: the loop
// health list, the annotation form and the admin's commands.
import { idms } from '../codec/proto.js';
import { h, formatTime } from './dom.js';

/** @typedef {(env: idms.v1.IEnvelope) => boolean} Send  sends a frame; false when not connected */

/**
 * The agent's loop health as a definition list.
 * @param {HTMLElement} dl
 * @param {{timeS: number, warnings: number, fallbacks: number, frames: number, keyframes: number, gaps: number}} st
 * @param {idms.v1.ILoopStats | null} stats the latest cumulative loop statistics
 * @param {number} dropped samples the agent's backlog lost
 */
export function renderHealth(dl, st, stats, dropped) {
  const s = stats || {};
  const rows = [
    ['Session time', formatTime(st.timeS)],
    ['Tick compute p99', `${s.computeP99Us ?? 0} µs`],
    ['Period p99', `${s.periodP99Us ?? 0} µs`],
    ['Overruns', `${s.overruns ?? 0} of ${s.ticks ?? 0} ticks`],
    ['Real-time', s.realtime ? 'yes' : 'no'],
    ['Warnings', String(st.warnings)],
    ['Stability fallbacks', String(st.fallbacks)],
    ['Samples dropped', String(dropped)],
    ['Mesh frames', `${st.frames} (${st.keyframes} keyframes, ${st.gaps} gaps)`],
  ];
  dl.replaceChildren(...rows.flatMap(([k, v]) => [h('dt', { text: k }), h('dd', { text: v })]));
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
