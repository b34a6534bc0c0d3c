// /session/{id} (live, /ws/session) and /replay/{id}?t=SECONDS (/ws/replay): the layout, the
// socket and what each message feeds. The drawing is LiveView's (3D, plots, tool state); the
// header, loop health, events, annotations and commands are session_panels.js's; the replay's
// timeline is timeline.js's.
import { idms } from '../codec/proto.js';
import { EnvelopeSocket } from '../net/socket.js';
import { FrameLoop } from '../view/frame_loop.js';
import { api } from '../net/api.js';
import { h, page } from './dom.js';
import { display } from '../view/display.js';
import { Timeline } from './timeline.js';
import { LiveView, loadModelRest } from './live_view.js';
import { Units } from '../view/units.js';
import { AnnotationList, EventList, HealthPanel, SessionHeader, annotationForm, commandPanel, eventFromRecord, eventName,
  messageWords } from './session_panels.js';

/** Seconds the time plots keep; the server's replay sends as much with a seek (kPlotWindowNs in server/src/replay.cc). */
const kWindowS = 5;

/**
 * What the page has seen, for the status line and the tests (window.__idms).
 * @typedef {{mode: string, frames: number, keyframes: number, deltas: number, gaps: number, invalid: number,
 *   samples: number, renders: number, timeS: number, warnings: number, fallbacks: number, lastError: string, lastInvalid: string,
 *   annotations: number, connection: string, ended: boolean, movedVertices: number, peakForce: number,
 *   contactSamples: number, forcePoints: number, forceShown: number, forceFirstS: number, forceLastS: number,
 *   depthSamples: number, forceLimited: boolean, forceLimitHits: number, commandsSent: number}} PageState
 */

/**
 * The page's elements, laid out for watching: the 3D view, the plots beside it (what an instructor
 * looks at rather than reads), and under the view the annotations, the loop health as a strip,
 * the commands (for admins of a live session) and the events. At 1280x720 the view, the force
 * plot and the note field are on the first screen; on a phone it is one column, the plots after
 * the view (style.css, .session-grid).
 * @param {string} id @param {'live' | 'replay'} mode
 * @param {{meta: HTMLElement, timeline: HTMLElement, health: HTMLElement, notes: HTMLElement,
 *   annotate: HTMLElement | null, events: HTMLElement, commands: HTMLElement | null}} panels
 */
function layout(id, mode, panels) {
  const hosts = {
    view: h('div', { class: 'view3d', id: 'view3d' }),
    force: h('div', { class: 'plot', id: 'force-plot' }),
    contact: h('div', { class: 'plot', id: 'contact-plot', hidden: true }),
    position: h('div', { class: 'plot', id: 'position-plot' }),
    depth: h('div', { class: 'plot', id: 'depth-plot' }),
    toolState: h('span', { id: 'tool-state', class: 'tool-state', role: 'status', text: 'tool: –' }),
    forceLimit: h('span', { id: 'force-limit', class: 'force-limit', role: 'status', text: 'Force limit: not reached' }),
    gapNote: h('p', { class: 'gap-note', id: 'gap-note', role: 'status' }),
  };
  const wire = h('input', { type: 'checkbox', id: 'wireframe' });
  // What the colours say and how much the deformation is exaggerated (display.json's scales).
  const colour = h('select', { id: 'colour-by', 'aria-label': 'Colour the surface by' },
    [h('option', { value: 'displacement', text: 'displacement' }), h('option', { value: 'plain', text: 'plain' })]);
  const scale = h('select', { id: 'deformation-scale', 'aria-label': 'Deformation scale' },
    display.displacement.scales.map((x) => h('option', { value: String(x), text: `×${x}` })));
  const plots = h('aside', { class: 'side plots-side' }, [
    h('section', { 'aria-labelledby': 'plots-title' }, [h('h2', { id: 'plots-title', text: `Last ${kWindowS} s at 1 kHz` }),
      hosts.force, hosts.contact, hosts.position, hosts.depth]),
  ]);
  const below = h('div', { class: 'side below-view' }, [
    h('section', { 'aria-labelledby': 'notes-title' }, [h('h2', { id: 'notes-title', text: 'Annotations' }),
      panels.annotate, panels.notes]),
    h('section', { 'aria-labelledby': 'health-title' }, [h('h2', { id: 'health-title', text: 'Loop health' }), panels.health]),
    panels.commands,
    h('section', { 'aria-labelledby': 'events-title' }, [h('h2', { id: 'events-title', text: 'Events' }), panels.events]),
  ]);
  page(`${mode === 'live' ? 'Live' : 'Replay'} ${id}`, [
    h('h1', {}, [mode === 'live' ? 'Live session ' : 'Replay of ', h('code', { text: id })]),
    panels.meta,
    mode === 'replay' ? panels.timeline : null,
    h('div', { class: 'session-grid' }, [
      h('section', { class: 'view-section', 'aria-label': '3D view' }, [
        hosts.view,
        h('div', { class: 'toolbar' }, [h('label', {}, ['Colour ', colour]), h('label', {}, ['Deformation ', scale]),
          h('label', {}, [wire, ' Wireframe']), hosts.toolState, hosts.forceLimit, hosts.gapNote]),
      ]),
      plots,
      below,
    ]),
  ].filter((x) => x !== null));
  return { hosts, wire, colour, scale };
}

/**
 * What each message feeds.
 * @typedef {{st: PageState, view: LiveView, health: HealthPanel, header: SessionHeader, timeline: Timeline | null,
 *   notes: AnnotationList, events: EventList, commands: {setTools: (tools: idms.v1.ITool[]) => void} | null,
 *   onEvent: (e: idms.v1.ISessionEvent) => void}} Parts
 */

/** @param {Parts} p @param {import('../codec/frames.js').Frame} env */
function dispatch(p, env) {
  if (env.meshKeyframe) p.view.applyKeyframe(env.meshKeyframe);
  else if (env.meshDelta) p.view.applyDelta(env.meshDelta);
  else if (env.deviceSamples) {
    const batch = env.deviceSamples;
    p.view.onSamples(batch.samples, batch.count);
    if (batch.count > 0) p.timeline?.setTime(p.st.timeS);
    p.health.setStats(batch.stats, batch.samplesDropped);
    p.header.invalidate();
    return;
  } else if (env.sessionEvent) p.onEvent(env.sessionEvent);
  else if (env.annotation) p.notes.add(env.annotation);
  else if (env.playbackState) {
    // A confirmed seek: its catch-up follows (the plot window's samples before the new time, then
    // the surface there), so the plots restart here and are full at once, paused or not.
    if (p.timeline?.onState(env.playbackState)) p.view.clearPlots();
  } else if (env.welcome) {
    p.view.setUnits(new Units(env.welcome.scene?.units));
    const tools = env.welcome.scene?.tools || [];
    if (tools.some((t) => (t.staticFriction ?? 0) > 0)) p.view.showContactForces();
    p.view.setSceneTools(tools);
    p.commands?.setTools(tools);
    p.health.setRate(env.welcome.scene?.device?.maxRateHz || 1000);
    if (env.welcome.scene?.model) loadModelRest(p.view.view, env.welcome.scene.model, env.welcome.scene.quantStep || 1e-4);
  }
  p.health.invalidate();
}


/** The connection's state in the top bar (nothing while connected). @param {string} state @param {string} text */
function showConnection(state, text) {
  const conn = document.getElementById('conn');
  if (!conn) return;
  conn.textContent = state === 'open' ? '' : text;
  conn.className = `conn ${state}`;
}

/**
 * The session's record: model, state, duration, past events and annotations.
 * @param {string} id @param {'live' | 'replay'} mode @param {Parts} p
 */
function loadRecord(id, mode, p) {
  api(`/api/sessions/${encodeURIComponent(id)}`).then((s) => {
    p.header.setRecord(s);
    for (const a of s.annotations || []) p.notes.add({ id: a.id, timeS: a.time_s, text: a.text, author: a.author });
    // The events so far: in the list at their times (a late joiner sees those before it came; the
    // stream's own copies are not listed twice), and on a replay's timeline.
    for (const record of s.events || []) {
      const e = eventFromRecord(record);
      p.events.add(e);
      if (mode === 'replay') p.timeline?.addMark(record.time_s, 'event', `${eventName(e.kind)}: ${messageWords(Number(e.kind), e.message || '')}`);
    }
    p.timeline?.setDuration(s.duration_s);
    p.view.countLimitHits = mode === 'live';
    p.view.setForceLimitHits(Number(s.summary?.force_limit_hits ?? 0));
  }).catch((e) => p.header.fail(`Cannot load the session: ${e instanceof Error ? e.message : String(e)}`));
}

/**
 * @param {string} id
 * @param {string} role
 * @param {'live' | 'replay'} mode
 */
export function sessionPage(id, role, mode) {
  /** @type {PageState} */
  const st = { mode, frames: 0, keyframes: 0, deltas: 0, gaps: 0, invalid: 0, samples: 0, renders: 0, timeS: 0,
    warnings: 0, fallbacks: 0, lastError: '', lastInvalid: '', annotations: 0, connection: 'connecting', ended: false,
    movedVertices: 0, peakForce: 0, contactSamples: 0, forcePoints: 0, forceShown: 0, forceFirstS: NaN, forceLastS: NaN,
    depthSamples: 0, forceLimited: false, forceLimitHits: 0, commandsSent: 0 };
  /** @type {any} */ (window).__idms = st;

  // The panels, the layout, then what draws into it (the plots take their width from their boxes).
  /** @type {EnvelopeSocket | null} */
  let socket = null;
  /** @param {idms.v1.IEnvelope} env */
  const send = (env) => socket?.send(env) ?? false;
  const loop = new FrameLoop();
  const header = new SessionHeader(id, mode, role, st, loop);
  const timelineHost = h('section', { class: 'timeline-section', 'aria-label': 'Timeline' });
  /** @type {Timeline | null} */
  const timeline = mode === 'replay' ? new Timeline(timelineHost, (msg) => send({ playbackControl: msg })) : null;
  // A replay's session time is where playback is (the timeline's), not its latest sample's: paused
  // after a seek, the samples stop short of the time sought.
  const health = new HealthPanel(st, loop, timeline ? () => timeline.time : undefined);
  const events = new EventList(st);
  const notes = new AnnotationList(st, (a) => timeline?.addMark(a.timeS || 0, 'annotation', a.text || ''),
    (t) => (timeline ? timeline.seek(t) : window.location.assign(`/replay/${encodeURIComponent(id)}?t=${t.toFixed(3)}`)));
  const commands = mode === 'live' && role === 'admin' ? commandPanel(send, st) : null;
  // Live, a note goes over the session's socket at its current time; in a replay it is added to
  // the session at the timeline's time (kept beside its recording once it has ended).
  const annotate = mode === 'live'
    ? annotationForm('Note at the current time', async (text) => (send({ annotation: { text } }) ? ''
      : st.ended ? 'The session has ended: add notes in its replay.' : 'Not connected: the note was not sent.'))
    : annotationForm('Note at the replay\'s time', async (text) => {
      try {
        const n = await api(`/api/sessions/${encodeURIComponent(id)}/notes`, { method: 'POST',
          headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ time_s: timeline?.time ?? 0, text }) });
        notes.add({ id: n.id, timeS: n.time_s, text: n.text, author: n.author });
        return '';
      } catch (e) {
        return `The note was not added: ${e instanceof Error ? e.message : String(e)}`;
      }
    });
  const { hosts, wire, colour, scale } = layout(id, mode, { meta: header.el, timeline: timelineHost, health: health.el, notes: notes.el,
    annotate, events: events.el, commands: commands?.el ?? null });
  const view = new LiveView(st, hosts, kWindowS, loop);
  wire.addEventListener('change', () => view.view.setWireframe(wire.checked));
  colour.addEventListener('change', () => view.view.setColourBy(/** @type {'displacement' | 'plain'} */ (colour.value)));
  scale.addEventListener('change', () => view.view.setScale(Number(scale.value)));
  Object.defineProperty(st, 'forcePoints', { get: () => view.forcePlot.length + view.forcePlot.numPending, enumerable: true });
  Object.defineProperty(st, 'forceShown', { get: () => view.forcePlot.shown, enumerable: true });
  Object.defineProperty(st, 'forceFirstS', { get: () => view.forcePlot.shownFirstS, enumerable: true });
  Object.defineProperty(st, 'forceLastS', { get: () => view.forcePlot.shownLastS, enumerable: true });
  // Where the surface and the tool fall in the view, for the tests (computed when asked).
  /** @type {any} */ (window).__idmsFraming = () => view.view.framing();
  // What the surface shows, and where a model point falls on the canvas, for the tests.
  /** @type {any} */ (window).__idmsSurface = () => ({ contacts: view.view.numContacts, lo: view.view.surface.lo, hi: view.view.surface.hi,
    colourBy: view.view.surface.colourBy, scale: view.view.surface.scale, restTimeS: view.view.surface.restTimeS,
    camera: view.view.camera.position.toArray(), tool: view.view.tool.position.toArray(), toolRadius: view.view.toolRadius,
    moved: movedVertices(view.view.surface), needle: needleShown(view.view.tool),
    suture: { ...view.view.sutureShown } });
  // The thread's nodes and punctures as drawn (model frame), for the tests.
  /** @type {any} */ (window).__idmsSuturePoints = () => {
    const v = view.view, n = v.sutureShown.segments;
    const seg = v.threadGeometry.getAttribute('position').array, marks = v.punctureGeometry.getAttribute('position').array;
    const nodes = [];
    for (let i = 0; i < n; i++) nodes.push([seg[6 * i], seg[6 * i + 1], seg[6 * i + 2]]);
    const punctures = [];
    for (let i = 0; i < v.sutureShown.punctures; i++) punctures.push([marks[3 * i], marks[3 * i + 1], marks[3 * i + 2]]);
    return { nodes, punctures };
  };
  /** @type {any} */ (window).__idmsProject = (/** @type {number} */ x, /** @type {number} */ y, /** @type {number} */ z) => view.view.project(x, y, z);
  Object.defineProperty(st, 'depthSamples', { get: () => view.depthPlot.count, enumerable: true });
  // The force-against-depth plot's axes as last drawn, for the tests.
  /** @type {any} */ (window).__idmsDepthAxes = () => ({ ...view.depthPlot.axes, xUnit: view.depthPlot.units.length,
    yUnit: view.depthPlot.units.force });
  // The force plot's sample times: whether they run in order and how far (a replay played again
  // must not keep the last pass's), for the tests.
  /** @type {any} */ (window).__idmsForceTimes = () => {
    const p = view.forcePlot, w = p.numSeries + 1;
    const times = [...p.columns[0].subarray(0, p.length)];
    for (let i = 0; i < p.numPending; i++) times.push(p.pending[i * w]);
    const ordered = times.every((t, i) => i === 0 || t >= times[i - 1]);
    return { count: times.length, first: times[0] ?? NaN, last: times[times.length - 1] ?? NaN, max: Math.max(...times), ordered };
  };

  /** @type {Parts} */
  const parts = { st, view, health, header, timeline, notes, events, commands, onEvent: (e) => {
    events.add(e);
    if (e.kind !== idms.v1.SessionEvent.Kind.KIND_ENDED || mode !== 'live') return;
    // The end of a live session: say so, link its replay, stop reconnecting.
    st.ended = true;
    header.el.append(' · ', h('a', { href: `/replay/${id}`, text: 'ended: open the replay' }));
    socket?.close();
  } };
  socket = new EnvelopeSocket(`/ws/${mode === 'live' ? 'session' : 'replay'}/${encodeURIComponent(id)}`, {
    onStatus: (state, text) => {
      st.connection = state;
      showConnection(state, text);
    },
    onOpen: () => {
      // A fresh connection starts with a keyframe: drop what the last one left half-done.
      hosts.gapNote.textContent = '';
      if (mode === 'replay') timeline?.reconnected();
    },
    onEnvelope: (env) => dispatch(parts, env),
  });
  loadRecord(id, mode, parts);

  return () => {
    socket?.close();
    view.dispose();
  };
}

/**
 * A needle's shaft as drawn (null for another tool): its length, radius, tail (model frame) and
 * whether it is red (in the tissue). @param {import('../view/tool.js').ToolMesh} tool
 */
function needleShown(tool) {
  if (tool.needleLength <= 0) return null;
  return { length: tool.needleLength, radius: tool.shaftRadius, tail: tool.tail(tool.position.clone()).toArray(), punctured: tool.punctured };
}

/**
 * Vertices displaced from rest by more than a hundredth of the colour map's range (the tests' measure
 * of how much of the surface moved). @param {import('../view/surface_geometry.js').SurfaceGeometry} g
 */
function movedVertices(g) {
  const t2 = (0.01 * g.hi) ** 2;
  let n = 0;
  for (let i = 0; i < 3 * g.numVertices; i += 3) {
    const dx = g.actual[i] - g.rest[i], dy = g.actual[i + 1] - g.rest[i + 1], dz = g.actual[i + 2] - g.rest[i + 2];
    if (dx * dx + dy * dy + dz * dz > t2) n++;
  }
  return n;
}
