// The replay's timeline: a slider to seek by click, drag or keys, play/pause, speed 0.1x-10x,
// events and annotations marked on it, and the URL's ?t= following the time so that a link opens
// at the moment it names. Keys: arrows step 0.1 s (with Shift 1 s), Page Up/Down 10 s, Home/End
// the ends, Space plays or pauses (anywhere on the page but in a field or on a button).
import { idms } from '../codec/proto.js';
import { h, formatTime } from './dom.js';

const Action = idms.v1.PlaybackControl.Action;
const kSpeeds = [0.1, 0.25, 0.5, 1, 2, 4, 10];
/** What an arrow key moves the time by, s; with Shift; Page Up/Down. */
export const kStepS = 0.1, kShiftStepS = 1, kPageStepS = 10;

/**
 * The time a key moves to, or null for a key that does not move it.
 * @param {string} key KeyboardEvent.key @param {boolean} shift @param {number} t now, s @param {number} duration s
 * @returns {number | null}
 */
export function keyTarget(key, shift, t, duration) {
  const step = shift ? kShiftStepS : kStepS;
  let to = null;
  if (key === 'ArrowRight' || key === 'ArrowUp') to = t + step;
  else if (key === 'ArrowLeft' || key === 'ArrowDown') to = t - step;
  else if (key === 'PageUp') to = t + kPageStepS;
  else if (key === 'PageDown') to = t - kPageStepS;
  else if (key === 'Home') to = 0;
  else if (key === 'End') to = duration;
  if (to === null) return null;
  // On the 1 ms grid, within the recording.
  return Math.round(1000 * Math.min(Math.max(0, to), duration > 0 ? duration : Infinity)) / 1000;
}

export class Timeline {
  /**
   * @param {HTMLElement} host
   * @param {(control: idms.v1.IPlaybackControl) => void} send
   */
  constructor(host, send) {
    this.send = send;
    this.duration = 0;
    this.time = 0;
    this.playing = false;
    this.speed = 1;
    this.dragging = false;
    this.opened = false;
    /** A seek sent and not yet confirmed by a PlaybackState at its time; NaN = none. */
    this.seekTarget = NaN;
    /** @type {{t: number, kind: string, title: string}[]} */
    this.marks = [];
    const t = Number(new URLSearchParams(location.search).get('t'));
    this.urlTime = Number.isFinite(t) && t > 0 ? t : 0;
    this.slider = h('input', { type: 'range', id: 'seek', min: 0, max: 1, step: 0.001, value: 0, 'aria-label': 'Session time (seek)' });
    this.timeText = h('output', { id: 'replay-time', for: 'seek', text: formatTime(0) });
    this.playButton = h('button', { type: 'button', id: 'play', text: 'Play', 'aria-pressed': 'false' });
    this.speedSelect = h('select', { id: 'speed' }, kSpeeds.map((s) => h('option', { value: s, text: `${s}×`, selected: s === 1 })));
    this.markLayer = h('div', { class: 'marks', id: 'marks' });
    host.append(
      h('div', { class: 'timeline' }, [h('div', { class: 'track' }, [this.slider, this.markLayer])]),
      h('div', { class: 'transport' }, [this.playButton, this.timeText,
        h('label', { for: 'speed', text: 'Speed' }), this.speedSelect]));
    this.slider.addEventListener('input', () => {
      this.dragging = true;
      this.timeText.textContent = formatTime(Number(this.slider.value));
    });
    this.slider.addEventListener('change', () => {
      this.dragging = false;
      this.seek(Number(this.slider.value));
    });
    this.playButton.addEventListener('click', () => this.toggle());
    this.slider.addEventListener('keydown', (ev) => this.onKey(ev));
    // Space and the arrows anywhere but where they already mean something (fields, buttons, links).
    document.addEventListener('keydown', (ev) => {
      if (ev.defaultPrevented || ev.target === this.slider) return;
      const el = /** @type {HTMLElement | null} */ (ev.target instanceof HTMLElement ? ev.target : null);
      if (el && el.closest('input, select, textarea, button, a, [contenteditable]')) return;
      this.onKey(ev);
    });
    this.speedSelect.addEventListener('change', () => this.send({ action: Action.ACTION_SET_SPEED, speed: Number(this.speedSelect.value) }));
  }

  /** Play, or pause; at the end, play again from the start. */
  toggle() {
    if (this.playing) {
      this.send({ action: Action.ACTION_PAUSE });
      return;
    }
    // From the start, as a seek the page makes itself: its confirmation restarts the plots and
    // the 3D view together (the server's own rewind on Play said nothing, and the plots kept the
    // last pass's samples, ahead of the view).
    if (this.duration > 0 && this.time >= this.duration - 0.01) this.seek(0);
    this.send({ action: Action.ACTION_PLAY });
  }

  /** @param {KeyboardEvent} ev */
  onKey(ev) {
    if (ev.altKey || ev.ctrlKey || ev.metaKey) return;
    if (ev.key === ' ') {
      ev.preventDefault();
      if (!ev.repeat) this.toggle();
      return;
    }
    const to = keyTarget(ev.key, ev.shiftKey, Number.isNaN(this.seekTarget) ? this.time : this.seekTarget, this.duration);
    if (to === null) return;
    ev.preventDefault();
    this.seek(to);
  }

  /** @param {number} t session time, s */
  seek(t) {
    this.seekTarget = t;
    this.time = t;
    this.send({ action: Action.ACTION_SEEK, seekTimeS: t });
    this.showTime();
  }

  /** Every (re)connection starts paused at 0: go back to where the view was (or the URL's t). */
  reconnected() {
    const target = this.opened ? this.time : this.urlTime;
    const wasPlaying = this.opened && this.playing;
    this.opened = true;
    if (target > 0) this.seek(target);
    if (this.speed !== 1) this.send({ action: Action.ACTION_SET_SPEED, speed: this.speed });
    if (wasPlaying) this.send({ action: Action.ACTION_PLAY });
  }

  /** @param {number} d */
  setDuration(d) {
    if (!(d > 0)) return;
    this.duration = d;
    this.slider.max = String(d);
    this.layoutMarks();
  }

  /**
   * The time of the samples being shown, while playing. Paused, the time is the server's (its
   * PlaybackState): a seek's catch-up samples end just before the time sought, and a key's step
   * from there would land a sample short (0.1 s on from 0.6 s made 0.699 s).
   * @param {number} t
   */
  setTime(t) {
    if (!Number.isNaN(this.seekTarget) || !this.playing) return;
    this.time = t;
    this.showTime();
  }

  /**
   * A PlaybackState from the server; true when it confirms the pending seek. The server sends that
   * state before the seek's catch-up (the device samples of the plots' window before the new time,
   * and the keyframe at or before it with the deltas since, in log-time order), so the plots restart
   * here and the catch-up fills them at once, paused or not. (They restarted at the catch-up's
   * keyframe before, which dropped the samples older than it: a seek showed only the seconds since
   * its keyframe.)
   * @param {idms.v1.IPlaybackState} ps
   */
  onState(ps) {
    this.setDuration(ps.durationS || 0);
    this.playing = !!ps.playing;
    this.speed = ps.speed || 1;
    this.playButton.textContent = this.playing ? 'Pause' : 'Play';
    this.playButton.setAttribute('aria-pressed', String(this.playing));
    this.speedSelect.value = String(this.speed);
    const t = ps.timeS || 0;
    let seeked = false;
    if (!Number.isNaN(this.seekTarget)) {
      // States sent before the seek was handled still name the old time: wait for the new one.
      const want = this.duration > 0 ? Math.min(this.seekTarget, this.duration) : this.seekTarget;
      if (Math.abs(t - want) > 0.05) return false;
      this.seekTarget = NaN;
      seeked = true;
    }
    this.time = t;
    this.showTime();
    history.replaceState(null, '', `${location.pathname}?t=${t.toFixed(2)}`);
    return seeked;
  }

  /** @param {number} t @param {string} kind @param {string} title */
  addMark(t, kind, title) {
    this.marks.push({ t, kind, title });
    this.layoutMarks();
  }

  layoutMarks() {
    if (!(this.duration > 0)) return;
    this.markLayer.replaceChildren(...this.marks.map((m) => h('button', {
      type: 'button', class: `mark ${m.kind}`, title: `${formatTime(m.t)} ${m.title}`,
      'aria-label': `${m.kind} at ${formatTime(m.t)}: ${m.title}`,
      style: `left: ${(100 * Math.min(1, m.t / this.duration)).toFixed(3)}%`,
      onclick: () => this.seek(m.t),
    })));
  }

  showTime() {
    if (this.dragging) return;
    this.slider.value = String(this.time);
    this.timeText.textContent = `${formatTime(this.time)} / ${formatTime(this.duration)}`;
  }
}
