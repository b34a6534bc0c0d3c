// /compare/{a}/{b}: two recorded sessions side by side, for an instructor comparing two attempts
// (or a trainee against a reference): their tissue in two 3D views replayed in step by one
// timeline (every control goes to both replays; the longer session leads the timeline), their
// device force over the whole session overlaid with the time being replayed marked, and their
// figures and grades in one table. ?t= opens both there, as a replay's does.
import { idms } from '../codec/proto.js';
import { MeshState } from '../codec/mesh.js';
import { EnvelopeSocket } from '../net/socket.js';
import { api } from '../net/api.js';
import { SurfaceView } from '../view/surface.js';
import { FrameLoop } from '../view/frame_loop.js';
import { display } from '../view/display.js';
import { Units, kModelUnits } from '../view/units.js';
import { ProfilePlot } from '../plots/profile.js';
import { h, page, fixed, formatDate, formatTime } from './dom.js';
import { Timeline } from './timeline.js';
import { loadModelRest, needleLength, toolWords } from './live_view.js';
import { gradeBadge, gradeWords } from './grade.js';
import { traineeHref } from './session_table.js';

const Action = idms.v1.PlaybackControl.Action;
const kColours = ['#c0392b', '#2471a3'];

/** The rows of the figures table: a label and how a session's record gives it, in its units. */
const kRows = /** @type {[string, (s: any, u: Units) => (Node | string | null)][]} */ ([
  ['Trainee', (s) => (s.trainee ? h('a', { href: traineeHref(s.trainee), text: s.trainee }) : h('span', { class: 'muted', text: 'not named' }))],
  ['Model', (s) => s.model],
  ['Started', (s) => formatDate(s.started)],
  ['Duration', (s) => formatTime(s.duration_s)],
  ['Peak force', (s, u) => `${fixed(u.frc(s.summary?.peak_force ?? NaN))} ${u.force}`],
  ['Mean contact force', (s, u) => `${fixed(u.frc(s.summary?.mean_contact_force ?? NaN))} ${u.force}`],
  ['Time in contact', (s) => `${fixed(s.summary?.contact_time_s ?? NaN, 1)} s`],
  ['Path length', (s, u) => `${fixed(u.len(s.summary?.path_length ?? NaN))} ${u.length}`],
  ['Force-limit hits', (s) => String(s.summary?.force_limit_hits ?? '–')],
  ['Warnings', (s) => String(s.summary?.warnings ?? '–')],
  ['Grade', (s, u) => gradeBadge(s.grade, u) ?? h('span', { class: 'muted', text: 'not graded' })],
]);

/** One of the two sessions: its replay socket, surface and tool. */
class Side {
  /** @param {string} id @param {number} index @param {FrameLoop} loop @param {(side: Side) => void} onOpen */
  constructor(id, index, loop, onOpen) {
    this.id = id;
    this.index = index;
    this.name = 'AB'[index];
    this.host = h('div', { class: 'view3d compare-view', id: `view-${this.name}` });
    this.caption = h('h2', { class: 'compare-caption' }, [h('span', { class: 'swatch', style: `background: ${kColours[index]}` }),
      ` ${this.name}: `, h('a', { href: `/replay/${encodeURIComponent(id)}`, text: id })]);
    this.toolState = h('span', { class: 'tool-state', role: 'status', id: `tool-state-${this.name}`, text: 'tool: –' });
    this.el = h('section', { class: 'compare-side', 'aria-label': `Session ${this.name}` }, [this.caption, this.host, this.toolState]);
    this.mirror = new MeshState();
    this.view = /** @type {SurfaceView | null} */ (null);
    this.loop = loop;
    /** What it has shown (the tests read it). */
    this.st = { keyframes: 0, deltas: 0, gaps: 0, samples: 0, timeS: 0 };
    /** @type {idms.v1.IPlaybackState | null} */
    this.state = null;
    this.onOpen = onOpen;
    /** @type {EnvelopeSocket | null} */
    this.socket = null;
    /** @type {(side: Side, ps: idms.v1.IPlaybackState) => void} */
    this.onState = () => {};
    /** @type {(side: Side) => void} */
    this.onTime = () => {};
  }

  /** Once the page is laid out (the view takes its size from its box). */
  start() {
    this.view = new SurfaceView(this.host, this.loop);
    this.socket = new EnvelopeSocket(`/ws/replay/${encodeURIComponent(this.id)}`, {
      onOpen: () => this.onOpen(this),
      onEnvelope: (env) => this.dispatch(env),
    });
  }

  /** @param {idms.v1.IPlaybackControl} control */
  control(control) {
    this.socket?.send({ playbackControl: control });
  }

  /** @param {import('../codec/frames.js').Frame} env */
  dispatch(env) {
    const view = /** @type {SurfaceView} */ (this.view);
    if (env.meshKeyframe) {
      if (this.mirror.applyKeyframe(/** @type {any} */ (env.meshKeyframe)) === 'ok') {
        this.st.keyframes++;
        view.setSurface(this.mirror, this.mirror.timeS);
      } else this.st.gaps++;
    } else if (env.meshDelta) {
      if (this.mirror.applyDelta(/** @type {any} */ (env.meshDelta)) === 'ok') {
        this.st.deltas++;
        view.applyMoved(this.mirror);
      } else this.st.gaps++;
    } else if (env.deviceSamples) {
      const { samples, count } = env.deviceSamples;
      this.st.samples += count;
      if (count === 0) return;
      const last = samples[count - 1];
      const f = last.force, p = last.toolPos;
      view.setNeedlePose(last.toolOrientation, !!last.needlePunctured);
      view.setTool(p?.x || 0, p?.y || 0, p?.z || 0, f?.x || 0, f?.y || 0, f?.z || 0, !!last.contact, !!last.grasp, last.friction === 2);
      this.st.timeS = last.timeS || 0;
      this.onTime(this);
      const words = toolWords(last);
      if (this.toolState.textContent !== words) this.toolState.textContent = words;
    } else if (env.playbackState) {
      this.state = env.playbackState;
      this.onState(this, env.playbackState);
    } else if (env.welcome) {
      const scene = env.welcome.scene;
      view.setToolRadius(scene?.tools?.[0]?.radius ?? 1.5);
      view.setNeedle(needleLength(scene?.tools?.[0]));
      if (scene?.model) loadModelRest(view, scene.model, scene.quantStep || 1e-4);
    }
  }

  dispose() {
    this.socket?.close();
    this.view?.dispose();
  }
}

/** @param {string} a @param {string} b @param {string} _role */
export function comparePage(a, b, _role) {
  const loop = new FrameLoop();
  const status = h('p', { class: 'muted', role: 'status', id: 'compare-status', text: 'Loading the two sessions…' });
  const table = h('table', { class: 'list compare-figures', id: 'compare-figures' });
  const timelineHost = h('section', { class: 'timeline-section', 'aria-label': 'Timeline of both replays' });
  const profileHost = h('div', { class: 'plot', id: 'profile-plot' });
  const profileTitle = h('h2', { id: 'profile-title', text: 'Device force over each whole session' });
  /** @type {Side[]} */
  const sides = [];
  // Every control goes to both; the lead's states drive the timeline.
  const timeline = new Timeline(timelineHost, (msg) => sides.forEach((s) => s.control(msg)));
  let lead = 0;
  let durations = [0, 0];
  /** @param {Side} side */
  const opened = (side) => {
    // Where the timeline is (or the URL's t at first), at its speed, playing if it was.
    const target = Number.isNaN(timeline.seekTarget) ? (timeline.opened ? timeline.time : timeline.urlTime) : timeline.seekTarget;
    if (target > 0) {
      if (side.index === lead) timeline.seekTarget = target;
      side.control({ action: Action.ACTION_SEEK, seekTimeS: target });
    }
    if (timeline.speed !== 1) side.control({ action: Action.ACTION_SET_SPEED, speed: timeline.speed });
    if (timeline.opened && timeline.playing) side.control({ action: Action.ACTION_PLAY });
    if (side.index === lead) timeline.opened = true;
  };
  for (const [i, id] of [a, b].entries()) sides.push(new Side(id, i, loop, opened));
  page(`Compare ${a} and ${b}`, [
    h('h1', {}, ['Compare ', h('code', { text: a }), ' and ', h('code', { text: b })]),
    status,
    timelineHost,
    h('div', { class: 'compare-grid' }, sides.map((s) => s.el)),
    h('section', { class: 'card wide', 'aria-labelledby': 'profile-title' }, [
      profileTitle, profileHost]),
    h('section', { 'aria-labelledby': 'figures-title' }, [h('h2', { id: 'figures-title', text: 'Figures' }),
      h('div', { class: 'scroll' }, [table])]),
  ]);
  const profile = new ProfilePlot(profileHost, { title: '',
    series: sides.map((s, i) => ({ label: `${s.name}: ${s.id}`, color: kColours[i] })) });
  for (const side of sides) {
    side.onState = (s, ps) => {
      if (s.index !== lead) return;
      timeline.onState(ps);
      profile.mark(timeline.time);
    };
    side.onTime = (s) => {
      if (s.index === lead) timeline.setTime(s.st.timeS);
    };
    side.start();
  }
  // The lead's time on the profile, in the frames the views draw in.
  loop.add({ draw: () => {
    profile.mark(timeline.time);
    return false;
  } });

  /** For the tests: what each side has shown, and the plot. */
  /** @type {any} */ (window).__idmsCompare = () => ({ sides: sides.map((s) => ({ id: s.id, ...s.st, state: s.state })),
    lead, time: timeline.time, profilePoints: profile.points, markS: profile.markS });

  // The records: the figures table, the timeline's length and lead, the notes as marks.
  // The force in one unit: N when both sessions declare it, else model force units (a plot cannot
  // mix them).
  /** @type {Units[]} */
  let units = [kModelUnits, kModelUnits];
  const records = Promise.all(sides.map((s) => api(`/api/sessions/${encodeURIComponent(s.id)}`)));
  records.then((records) => {
    units = records.map((r) => new Units(r.units));
    table.replaceChildren(
      h('thead', {}, [h('tr', {}, [h('th', { scope: 'col', text: 'Figure' }),
        ...sides.map((s, i) => h('th', { scope: 'col' }, [h('span', { class: 'swatch', style: `background: ${kColours[i]}` }), ` ${s.name}`]))])]),
      h('tbody', {}, kRows.map(([label, cell]) => h('tr', {}, [h('th', { scope: 'row', text: label }),
        ...records.map((r, i) => h('td', {}, [cell(r, units[i])]))]))));
    durations = records.map((r) => Number(r.duration_s) || 0);
    lead = durations[1] > durations[0] ? 1 : 0;
    timeline.setDuration(Math.max(...durations));
    for (const [i, r] of records.entries()) {
      for (const n of r.annotations || []) timeline.addMark(n.time_s, 'annotation', `${sides[i].name}: ${n.text}`);
    }
    const grades = records.map((r) => gradeWords(r.grade).word || 'not graded');
    status.textContent = `A ${grades[0]}, B ${grades[1]}; one timeline plays both from the same session time`
      + (durations[0] !== durations[1] ? ` (the shorter, ${sides[1 - lead].name}, stops at its end).` : '.');
  }).catch((e) => { status.textContent = `Cannot load the sessions: ${e instanceof Error ? e.message : String(e)}`; });
  Promise.all([records, ...sides.map((s) => api(`/api/sessions/${encodeURIComponent(s.id)}/force?points=2000`))])
    .then(([, ...profiles]) => {
      const newtons = units.every((u) => u.force === 'N');
      if (newtons) profile.scaleForce(...units.map((u) => u.forceScale));
      profileTitle.textContent = `Device force over each whole session (${newtons ? 'N' : display.unit.force}, the peak of each slice)`;
      profile.setData(profiles);
    })
    .catch(() => {});

  return () => {
    for (const s of sides) s.dispose();
    profile.dispose();
  };
}
