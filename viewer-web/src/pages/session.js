// /session/{id} (live, /ws/session) and /replay/{id}?t=SECONDS (/ws/replay): the tissue in 3D,
// the tool and force, 1 kHz force and position plots, the loop's health, events, annotations,
// admin commands (live) and a timeline with play, pause, seek and speed (replay).
import { idms } from '../codec/proto.js';
import { MeshState } from '../codec/mesh.js';
import { SurfaceView } from '../view/surface.js';
import { RollingPlot } from '../plots/rolling.js';
import { DepthPlot } from '../plots/depth.js';
import { EnvelopeSocket } from '../net/socket.js';
import { api } from '../net/api.js';
import { h, page, fixed, formatTime } from './dom.js';
import { Timeline } from './timeline.js';
import { annotationForm, commandPanel, renderHealth } from './session_panels.js';

const v1 = idms.v1;
const kWindowS = 5;
const kEventNames = new Map(Object.entries(v1.SessionEvent.Kind).map(([name, n]) => [n, name.replace(/^KIND_/, '')]));

/**
 * What the page has seen, for the status line and the tests (window.__idms).
 * @typedef {{mode: string, frames: number, keyframes: number, deltas: number, gaps: number, invalid: number,
 *   samples: number, renders: number, timeS: number, warnings: number, fallbacks: number, lastError: string, lastInvalid: string,
 *   annotations: number, connection: string, ended: boolean, movedVertices: number, peakForce: number,
 *   contactSamples: number, forcePoints: number, depthSamples: number}} PageState
 */

/**
 * @param {string} id
 * @param {string} role
 * @param {'live' | 'replay'} mode
 */
export function sessionPage(id, role, mode) {
  /** @type {PageState} */
  const st = { mode, frames: 0, keyframes: 0, deltas: 0, gaps: 0, invalid: 0, samples: 0, renders: 0, timeS: 0,
    warnings: 0, fallbacks: 0, lastError: '', lastInvalid: '', annotations: 0, connection: 'connecting', ended: false,
    movedVertices: 0, peakForce: 0, contactSamples: 0, forcePoints: 0, depthSamples: 0 };
  /** @type {any} */ (window).__idms = st;

  // Layout.
  const viewHost = h('div', { class: 'view3d', id: 'view3d' });
  const meta = h('p', { class: 'meta', id: 'meta', text: 'Loading…' });
  const gapNote = h('p', { class: 'gap-note', id: 'gap-note', role: 'status' });
  const wire = h('input', { type: 'checkbox', id: 'wireframe' });
  const health = h('dl', { class: 'health', id: 'health' });
  const forceHost = h('div', { class: 'plot', id: 'force-plot' });
  const posHost = h('div', { class: 'plot', id: 'position-plot' });
  const depthHost = h('div', { class: 'plot', id: 'depth-plot' });
  const toolState = h('span', { id: 'tool-state', class: 'tool-state', role: 'status', text: 'tool: –' });
  const events = h('ol', { class: 'events', id: 'events', 'aria-live': 'polite' });
  const notes = h('ol', { class: 'notes', id: 'annotations' });
  const side = h('aside', { class: 'side' });
  const timelineHost = h('section', { class: 'timeline-section', 'aria-label': 'Timeline' });
  page(`${mode === 'live' ? 'Live' : 'Replay'} ${id}`, [
    h('h1', {}, [mode === 'live' ? 'Live session ' : 'Replay of ', h('code', { text: id })]),
    meta,
    mode === 'replay' ? timelineHost : null,
    h('div', { class: 'session-grid' }, [
      h('section', { class: 'view-section', 'aria-label': '3D view' }, [
        viewHost,
        h('div', { class: 'toolbar' }, [h('label', {}, [wire, ' Wireframe']), toolState, gapNote]),
      ]),
      side,
    ]),
  ].filter((x) => x !== null));
  side.append(
    h('section', { 'aria-labelledby': 'health-title' }, [h('h2', { id: 'health-title', text: 'Loop health' }), health]),
    h('section', { 'aria-labelledby': 'plots-title' }, [h('h2', { id: 'plots-title', text: `Last ${kWindowS} s at 1 kHz` }), forceHost, posHost, depthHost]),
    h('section', { 'aria-labelledby': 'notes-title' }, [h('h2', { id: 'notes-title', text: 'Annotations' }),
      mode === 'live' ? annotationForm((env) => socket.send(env), st) : null, notes].filter((x) => x !== null)),
    h('section', { 'aria-labelledby': 'events-title' }, [h('h2', { id: 'events-title', text: 'Events' }), events]),
  );
  if (mode === 'live' && role === 'admin') side.prepend(commandPanel((env) => socket.send(env)));

  const mirror = new MeshState();
  const view = new SurfaceView(viewHost);
  view.onRender = () => st.renders++;
  wire.addEventListener('change', () => view.setWireframe(wire.checked));
  const capacity = kWindowS * 1000;
  const forcePlot = new RollingPlot(forceHost, { title: 'Force on the device', unit: 'force', capacity, series: [
    { label: 'Fx', color: '#c0392b' }, { label: 'Fy', color: '#27ae60' }, { label: 'Fz', color: '#2471a3' }, { label: '|F|', color: '#222' }] });
  Object.defineProperty(st, 'forcePoints', { get: () => forcePlot.length + forcePlot.numPending, enumerable: true });
  const posPlot = new RollingPlot(posHost, { title: 'Tool position', unit: 'model units', capacity, series: [
    { label: 'x', color: '#c0392b' }, { label: 'y', color: '#27ae60' }, { label: 'z', color: '#2471a3' }] });
  const depthPlot = new DepthPlot(depthHost, capacity);
  Object.defineProperty(st, 'depthSamples', { get: () => depthPlot.count, enumerable: true });
  /** @type {Timeline | null} */
  const timeline = mode === 'replay' ? new Timeline(timelineHost, (msg) => socket.send({ playbackControl: msg })) : null;

  // Loop health: the latest cumulative stats, drawn a few times a second when they changed.
  /** @type {idms.v1.ILoopStats | null} */
  let stats = null;
  let dropped = 0;
  let healthDirty = false;
  const healthTimer = window.setInterval(() => {
    if (!healthDirty) return;
    healthDirty = false;
    renderHealth(health, st, stats, dropped);
  }, 250);

  let shownToolState = '';
  /** @param {idms.v1.IDeviceSamples} batch */
  function onSamples(batch) {
    const samples = batch.samples || [];
    for (const s of samples) {
      const f = s.force || {}, p = s.toolPos || {};
      const fx = f.x || 0, fy = f.y || 0, fz = f.z || 0;
      const t = s.timeS || 0;
      const f2 = Math.hypot(fx, fy, fz);
      forcePlot.push(t, fx, fy, fz, f2);
      if (f2 > st.peakForce) st.peakForce = f2;
      if (s.contact) st.contactSamples++;
      posPlot.push(t, p.x || 0, p.y || 0, p.z || 0);
      depthPlot.push(p.x || 0, p.y || 0, p.z || 0, fx, fy, fz, !!s.contact);
      st.warnings += s.warnings || 0;
    }
    st.samples += samples.length;
    const last = samples[samples.length - 1];
    if (last) {
      const f = last.force || {}, p = last.toolPos || {};
      view.setTool(p.x || 0, p.y || 0, p.z || 0, f.x || 0, f.y || 0, f.z || 0, !!last.contact, !!last.grasp);
      // The tool's state in words (colour alone is not enough), written only when it changes.
      const words = last.grasp ? 'tool: grasping' : last.contact ? 'tool: in contact' : 'tool: free';
      if (words !== shownToolState) toolState.textContent = shownToolState = words;
      st.timeS = last.timeS || 0;
      timeline?.setTime(st.timeS);
    }
    if (batch.stats) stats = batch.stats;
    dropped = batch.samplesDropped || 0;
    healthDirty = true;
  }

  /** @param {'ok' | 'gap' | 'invalid'} status @param {boolean} keyframe */
  function onMesh(status, keyframe) {
    st.frames++;
    if (status === 'ok') {
      if (keyframe) {
        st.keyframes++;
        view.setSurface(mirror);
        gapNote.textContent = '';
      } else {
        st.deltas++;
        st.movedVertices += mirror.numChanged;
        view.applyMoved(mirror);
      }
    } else {
      // Never drawn: the surface stays at the last frame applied until a keyframe comes.
      if (status === 'gap') st.gaps++;
      else {
        st.invalid++;
        st.lastInvalid = mirror.error;
      }
      st.lastError = mirror.error;
      gapNote.textContent = `${status === 'gap' ? 'Frames lost' : 'Bad frame'}: ${mirror.error}. Waiting for a keyframe.`;
    }
    healthDirty = true;
  }

  /** @param {idms.v1.ISessionEvent} e */
  function addEvent(e) {
    const kind = e.kind ? kEventNames.get(e.kind) || String(e.kind) : 'NOTE';
    if (e.kind === v1.SessionEvent.Kind.KIND_STABILITY_FALLBACK) st.fallbacks++;
    const li = h('li', { class: `event ${kind.toLowerCase()}` }, [
      h('span', { class: 'time', text: formatTime(e.timeS || 0) }), ' ', h('strong', { text: kind }), ' ', e.message || '']);
    events.prepend(li);
    while (events.childElementCount > 200) events.lastElementChild?.remove();
    if (e.kind === v1.SessionEvent.Kind.KIND_ENDED && mode === 'live') {
      st.ended = true;
      meta.append(' · ', h('a', { href: `/replay/${id}`, text: 'ended: open the replay' }));
      socket.close();
    }
  }

  /** @param {idms.v1.IAnnotation} a */
  function addAnnotation(a) {
    if (notes.querySelector(`[data-id="${a.id}"]`)) return;
    st.annotations++;
    notes.append(h('li', { 'data-id': String(a.id ?? ''), 'data-time': String(a.timeS ?? 0) }, [
      h('span', { class: 'time', text: formatTime(a.timeS || 0) }), ' ', a.text || '', ' ',
      h('span', { class: 'muted', text: `— ${a.author || ''}` })]));
    timeline?.addMark(a.timeS || 0, 'annotation', a.text || '');
  }

  const socket = new EnvelopeSocket(`/ws/${mode === 'live' ? 'session' : 'replay'}/${encodeURIComponent(id)}`, {
    onStatus: (state, text) => {
      st.connection = state;
      const conn = document.getElementById('conn');
      if (conn) {
        conn.textContent = state === 'open' ? '' : text;
        conn.className = `conn ${state}`;
      }
    },
    onOpen: () => {
      // A fresh connection starts with a keyframe: drop what the last one left half-done.
      gapNote.textContent = '';
      if (mode === 'replay') timeline?.reconnected();
    },
    onEnvelope: (env) => {
      if (env.meshKeyframe) onMesh(mirror.applyKeyframe(/** @type {any} */ (env.meshKeyframe)), true);
      else if (env.meshDelta) onMesh(mirror.applyDelta(/** @type {any} */ (env.meshDelta)), false);
      else if (env.deviceSamples) onSamples(env.deviceSamples);
      else if (env.sessionEvent) addEvent(env.sessionEvent);
      else if (env.annotation) addAnnotation(env.annotation);
      else if (env.playbackState) {
        const ps = env.playbackState;
        if (timeline?.onState(ps)) {
          // A seek: the plots restart at the new time.
          forcePlot.clear();
          posPlot.clear();
          depthPlot.clear();
        }
      } else if (env.welcome) {
        const tools = env.welcome.scene?.tools || [];
        view.setToolRadius(tools[0]?.radius ?? 1.5);
      }
    },
  });

  // The session's record: model, state, past events and annotations.
  api(`/api/sessions/${encodeURIComponent(id)}`).then((s) => {
    meta.textContent = `${s.model} · ${s.device} · ${s.identity} · ${s.state} · ${fixed(s.duration_s, 1)} s`;
    for (const a of s.annotations || []) addAnnotation({ id: a.id, timeS: a.time_s, text: a.text, author: a.author });
    for (const e of s.events || []) {
      if (mode === 'replay') timeline?.addMark(e.time_s, 'event', `${e.kind}: ${e.message}`);
    }
    if (timeline) timeline.setDuration(s.duration_s);
  }).catch((e) => { meta.textContent = `Cannot load the session: ${e instanceof Error ? e.message : String(e)}`; });

  return () => {
    socket.close();
    clearInterval(healthTimer);
    view.dispose();
    forcePlot.dispose();
    posPlot.dispose();
    depthPlot.dispose();
  };
}
