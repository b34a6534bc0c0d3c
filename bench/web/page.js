// The bench's two pages in one bundle, both in a canvas the size of the window.
// "page": the live view as /session/{id} assembles it (LiveView: the 3D view with the tool and
// force arrow, the force, position and force-depth plots, the tool's state; and the loop-health
// panel, all in one frame loop), fed C++-encoded mesh frames and 17 device samples (1 kHz / 60)
// as protobuf envelopes at 60 Hz; its own JavaScript is timed (decode, apply, normals, plots;
// the last two in the frames drawn, added to the frames received in between).
// "bare": three.js alone drawing the same mesh (still) with the same lights, material, antialias
// and pixel ratio, rendering every animation frame. Both report their canvas and draw calls.
// Variants (web_bench.mjs --variants), switches after the URL's #, comma-separated:
//   bare          the bare page;  bare,sphere  with one more lit sphere (one more draw call);
//                 bare,sphere,sphere2  two more (what each small object costs)
//   still         the page fed nothing after its first frames, rendering every animation frame as
//                 the bare page does (what the page costs standing)
//   notool        the tool and force hidden
//   nopanel       the plots' and loop-health panel hidden (still drawn into, never composited)
//   noplots       the plots never redrawn (samples still pushed)
//   nohealth      the loop-health panel not updated
//   nomesh        the mesh deltas decoded but not applied
//   align         the plots and the panel drawn only in the same frames, at most 10 a second
//   bare,panel    the bare page with the page's plots and loop-health panel beside it, drawn once
//                 and then left standing (what a panel's composited content costs, unchanging)
import * as THREE from 'three';
import { idms } from '../../viewer-web/src/codec/proto.js';
import { MeshState } from '../../viewer-web/src/codec/mesh.js';
import { FrameDecoder } from '../../viewer-web/src/codec/frames.js';
import { frameTool, placeCamera } from '../../viewer-web/src/view/surface.js';
import { LiveView, kForcePlot, kPositionPlot } from '../../viewer-web/src/pages/live_view.js';
import { FrameLoop } from '../../viewer-web/src/view/frame_loop.js';
import { RollingPlot } from '../../viewer-web/src/plots/rolling.js';
import { DepthPlot } from '../../viewer-web/src/plots/depth.js';
import { HealthPanel } from '../../viewer-web/src/pages/session_panels.js';

const Envelope = idms.v1.Envelope;
const w = /** @type {any} */ (window);

/** @returns {Promise<Uint8Array[]>} the stream's frames, [u32 size][Envelope] each */
async function frames() {
  const bytes = new Uint8Array(await (await fetch('/frames.bin')).arrayBuffer());
  const out = [];
  for (let p = 0; p < bytes.length;) {
    const n = bytes[p] | (bytes[p + 1] << 8) | (bytes[p + 2] << 16) | (bytes[p + 3] << 24);
    out.push(bytes.subarray(p + 4, p + 4 + n));
    p += 4 + n;
  }
  return out;
}

/**
 * The device samples of frame `n` as the agent sends them: a press every 2 s (contact for 1 s).
 * The bench's own work: encoded before the run (precomputed), as the server does it, not the page.
 * @param {number} n
 */
function samplesEnvelope(n) {
  return Envelope.encode({ deviceSamples: { samples: samplesOf(n), stats: { ticks: 17 * n, computeP99Us: 40, periodP99Us: 1010 } } }).finish();
}

/** @param {number} n */
function samplesOf(n) {
  const samples = [];
  for (let k = 0; k < 17; k++) {
    const t = (17 * n + k) / 1000;
    const contact = t % 2 < 1;
    const depth = contact ? 0.3 * Math.sin(Math.PI * (t % 2)) : 0;
    samples.push({ timeS: t, toolPos: { x: Math.cos(t), y: Math.sin(t), z: 1 - depth },
      force: { x: 0.05 * Math.sin(7 * t), y: 0.05 * Math.cos(5 * t), z: contact ? 2 * depth : 0 }, contact });
  }
  return samples;
}

/** @param {HTMLCanvasElement} canvas @param {THREE.WebGLRenderer} renderer */
function describe(canvas, renderer) {
  const gl = renderer.getContext();
  return { canvas: `${gl.drawingBufferWidth}x${gl.drawingBufferHeight}`, pixelRatio: renderer.getPixelRatio(),
    antialias: !!gl.getContextAttributes()?.antialias, cssSize: `${canvas.clientWidth}x${canvas.clientHeight}` };
}

/** The variant's switches (see above). */
const flags = new Set(location.hash.slice(1).split(',').filter(Boolean));

async function viewerPage() {
  const list = await frames();
  const panel = /** @type {HTMLElement} */ (document.getElementById('plots'));
  /** @param {string} tag @param {string} id */
  const el = (tag, id) => {
    const e = document.createElement(tag);
    e.id = id;
    return e;
  };
  const hosts = { view: /** @type {HTMLElement} */ (document.getElementById('view')), force: el('div', 'force'),
    position: el('div', 'position'), depth: el('div', 'depth'), toolState: el('span', 'tool'), gapNote: el('p', 'gap'),
    forceLimit: el('span', 'force-limit') };
  const st = { frames: 0, keyframes: 0, deltas: 0, gaps: 0, invalid: 0, samples: 0, renders: 0, timeS: 0, warnings: 0,
    fallbacks: 0, lastError: '', lastInvalid: '', movedVertices: 0, peakForce: 0, contactSamples: 0, forceLimited: false, forceLimitHits: 0 };
  // The three plots on screen (they skip drawing when scrolled away), the panel's text below them.
  panel.append(hosts.force, hosts.position, hosts.depth, hosts.toolState, hosts.forceLimit, hosts.gapNote);
  const view = new LiveView(st, hosts, 5);
  if (flags.has('nopanel')) panel.style.display = 'none';
  const health = new HealthPanel(st, view.loop);
  panel.append(health.el);
  const plots = [view.forcePlot, view.posPlot, view.depthPlot];
  if (flags.has('noplots')) for (const p of plots) view.loop.remove(p);
  if (flags.has('align')) {
    // One shared gate: a frame is the panel's when 98 ms have passed since the last one.
    const gate = { now: -1, open: false, last: -1e9 };
    for (const part of [...plots, health]) {
      const draw = part.draw.bind(part);
      part.draw = (/** @type {number} */ now) => {
        if (now !== gate.now) {
          gate.now = now;
          gate.open = now - gate.last >= 98;
          if (gate.open) gate.last = now;
        }
        return gate.open ? draw(now) : true;
      };
    }
  }
  const stats = { frames: 0, jsMs: 0, renders: 0, changed: 0, gaps: 0, calls: 0, ...describe(view.view.renderer.domElement, view.view.renderer) };
  w.__bench = stats;
  view.view.onRender = () => {
    stats.renders++;
    stats.calls += view.view.renderer.info.render.calls;
  };
  // Decoded as the page's socket decodes them (FrameDecoder).
  const decoder = new FrameDecoder();
  /** @param {Uint8Array} bytes */
  const apply = (bytes) => {
    const env = decoder.decode(bytes);
    if (env.meshKeyframe) view.applyKeyframe(env.meshKeyframe);
    else if (env.meshDelta) {
      if (!flags.has('nomesh')) view.applyDelta(env.meshDelta);
    } else if (env.deviceSamples) {
      view.onSamples(env.deviceSamples.samples, env.deviceSamples.count);
      if (!flags.has('nohealth')) health.setStats(env.deviceSamples.stats, 0);
      if (flags.has('notool')) view.view.tool.visible = false;
    }
  };
  apply(list[0]);
  // The camera as the bare page's: fitted to the surface and the tool where the first samples put
  // it, then held (the page would grow its frame as the tool circles: a few small refits that
  // cost nothing but would draw the mesh a little smaller than the bare page does).
  apply(samplesEnvelope(0));
  view.view.userMoved = true;
  // The run's device samples, encoded now: encoding them at 60 Hz would load the page's own
  // thread with work that is the server's (?seconds= says how long the run is; past it, they are
  // encoded as they go).
  const seconds = Number(new URLSearchParams(location.search).get('seconds')) || 10;
  const precomputed = [];
  for (let k = 1; k <= 60 * (seconds + 10); k++) precomputed.push(samplesEnvelope(k));
  // 60 Hz: one mesh frame and 17 device samples each time, as the server relays them.
  let i = 0;
  let n = 1;
  let drawMs = 0;
  if (flags.has('still')) {
    const again = () => {
      view.view.invalidate();
      requestAnimationFrame(again);
    };
    again();
    return;
  }
  setInterval(() => {
    const samples = n <= precomputed.length ? precomputed[n - 1] : samplesEnvelope(n);
    n++;
    const start = performance.now();
    // The stream loops through its keyframe, as a server's periodic keyframe: a delta after the
    // last frame would be based on a sequence the page has passed (a gap, never drawn).
    i = i + 1 < list.length ? i + 1 : 0;
    apply(list[i]);
    apply(samples);
    // The normals and the plots' draws (in the frame loop, when a frame is drawn) are the page's
    // JavaScript too.
    let d = view.view.normalsMs;
    for (const p of plots) d += p.drawMs;
    stats.jsMs += performance.now() - start + (d - drawMs);
    drawMs = d;
    stats.frames++;
    stats.gaps = st.gaps + st.invalid;
    stats.changed = st.movedVertices;
  }, 1000 / 60);
}

async function barePage() {
  const list = await frames();
  const mirror = new MeshState();
  mirror.applyKeyframe(/** @type {any} */ (Envelope.decode(list[0]).meshKeyframe));
  const host = /** @type {HTMLElement} */ (document.getElementById('view'));
  // The viewer's renderer settings: antialias, pixel ratio capped at 2.
  const renderer = new THREE.WebGLRenderer({ antialias: true });
  renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
  renderer.setSize(host.clientWidth, host.clientHeight);
  host.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  // The viewer's lights and material: the same drawing work per pixel.
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8090a0, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(3, 5, 8);
  scene.add(sun);
  scene.background = new THREE.Color(0xf4f5f7);
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(mirror.positions.slice(0, 3 * mirror.numVertices), 3));
  geometry.setIndex(new THREE.BufferAttribute(mirror.triangles.slice(0, 3 * mirror.numTriangles), 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  scene.add(new THREE.Mesh(geometry, new THREE.MeshStandardMaterial({ color: 0xe3a6a0, roughness: 0.7, side: THREE.DoubleSide })));
  // The live view's camera: fitted to the surface and the tool where the first samples put it
  // (of the live view's default radius), so that both draw the mesh at the same size.
  geometry.computeBoundingBox();
  const p = samplesOf(0)[16].toolPos;
  const tool = new THREE.Sphere(new THREE.Vector3(p.x, p.y, p.z), 1.5);
  const camera = new THREE.PerspectiveCamera(40, host.clientWidth / host.clientHeight);
  const box = /** @type {THREE.Box3} */ (geometry.boundingBox);
  placeCamera(camera, box, frameTool(new THREE.Box3(), box.getBoundingSphere(new THREE.Sphere()), tool), tool.radius);
  if (flags.has('sphere')) {
    // One more draw: a lit sphere the tool's size where the tool is.
    const sphere = new THREE.Mesh(new THREE.SphereGeometry(1.5, 32, 16), new THREE.MeshStandardMaterial({ color: 0x4f7cac }));
    sphere.position.copy(tool.center);
    scene.add(sphere);
    if (flags.has('sphere2')) {
      const second = new THREE.Mesh(sphere.geometry, sphere.material);
      second.position.copy(tool.center).add(new THREE.Vector3(3, 0, 0));
      scene.add(second);
    }
  }
  if (flags.has('panel')) standingPanel();
  const stats = { renders: 0, calls: 0, ...describe(renderer.domElement, renderer) };
  w.__bench = stats;
  const loop = () => {
    renderer.render(scene, camera);
    stats.renders++;
    stats.calls += renderer.info.render.calls;
    requestAnimationFrame(loop);
  };
  loop();
}

/** The page's plots and loop-health panel in #plots, fed 5 s of samples once and drawn once. */
function standingPanel() {
  const panel = /** @type {HTMLElement} */ (document.getElementById('plots'));
  const loop = new FrameLoop();
  const hosts = ['force', 'position', 'depth'].map(() => panel.appendChild(document.createElement('div')));
  const force = new RollingPlot(hosts[0], { ...kForcePlot, capacity: 5000 }, loop);
  const position = new RollingPlot(hosts[1], { ...kPositionPlot, capacity: 5000 }, loop);
  const depth = new DepthPlot(hosts[2], 5000, loop);
  for (let n = 0; n < 300; n++) {
    for (const s of samplesOf(n)) {
      const f = s.force, p = s.toolPos;
      force.push(s.timeS, f.x, f.y, f.z, Math.hypot(f.x, f.y, f.z));
      position.push(s.timeS, p.x, p.y, p.z);
      depth.push(p.x, p.y, p.z, f.x, f.y, f.z, s.contact);
    }
  }
  const st = { frames: 0, keyframes: 0, deltas: 0, gaps: 0, invalid: 0, samples: 5100, renders: 0, timeS: 5.1, warnings: 0,
    fallbacks: 0, lastError: '', lastInvalid: '', movedVertices: 0, peakForce: 0.6, contactSamples: 2550 };
  const health = new HealthPanel(st, loop);
  panel.append(health.el);
  health.setStats({ ticks: 5100, computeP99Us: 40, periodP99Us: 1010 }, 0);
}

(flags.has('bare') ? barePage() : viewerPage()).catch((e) => { w.__benchError = String(e); });
