// The bench's two pages in one bundle. "viewer": the viewer's own modules (MeshState, SurfaceView,
// RollingPlot) fed C++-encoded frames at 60 Hz with 17 samples per frame, its JavaScript timed;
// "bare": three.js drawing the same mesh, rendering every animation frame. Both at the window's size.
// "#noupload" (the mesh decoded, not uploaded) and "#noplots" split the viewer's costs.
import * as THREE from 'three';
import { idms } from '../../viewer-web/src/codec/proto.js';
import { MeshState } from '../../viewer-web/src/codec/mesh.js';
import { SurfaceView, placeCamera } from '../../viewer-web/src/view/surface.js';
import { RollingPlot } from '../../viewer-web/src/plots/rolling.js';

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

/** @param {boolean} withPlots */
async function viewer(withPlots) {
  const list = await frames();
  const host = /** @type {HTMLElement} */ (document.getElementById('view'));
  const plotHost = /** @type {HTMLElement} */ (document.getElementById('plots'));
  const mirror = new MeshState();
  const view = new SurfaceView(host);
  const force = new RollingPlot(plotHost, { title: 'force', unit: 'N', capacity: 5000,
    series: [{ label: 'x', color: 'red' }, { label: 'y', color: 'green' }, { label: 'z', color: 'blue' }, { label: 'm', color: 'black' }] });
  const pos = new RollingPlot(plotHost, { title: 'position', unit: 'u', capacity: 5000,
    series: [{ label: 'x', color: 'red' }, { label: 'y', color: 'green' }, { label: 'z', color: 'blue' }] });
  const stats = { frames: 0, jsMs: 0, renders: 0, changed: 0, gaps: 0, startedAt: 0, jsSamples: /** @type {number[]} */ ([]) };
  w.__bench = stats;
  view.onRender = () => stats.renders++;
  // The plots' draws are the page's JavaScript too (uPlot draws in a microtask after setData:
  // the time to the next macrotask counts them).
  for (const plot of [force, pos]) {
    const draw = plot.draw.bind(plot);
    plot.draw = () => {
      const a = performance.now();
      draw();
      queueMicrotask(() => queueMicrotask(() => { stats.jsMs += performance.now() - a; }));
    };
  }
  let i = 0;
  let tick = 0;
  const apply = (/** @type {Uint8Array} */ bytes) => {
    const env = Envelope.decode(bytes);
    if (env.meshKeyframe) {
      if (mirror.applyKeyframe(/** @type {any} */ (env.meshKeyframe)) === 'ok') view.setSurface(mirror);
    } else if (env.meshDelta) {
      // A gap is never drawn (the page waits for a keyframe): the bench must not send one.
      if (mirror.applyDelta(/** @type {any} */ (env.meshDelta)) !== 'ok') {
        stats.gaps++;
        return;
      }
      stats.changed += mirror.numChanged;
      if (location.hash.includes('noupload')) view.invalidate();
      else view.applyMoved(mirror);
    }
  };
  apply(list[0]);
  // 60 Hz: one mesh frame and 17 device samples each time (1 kHz / 60).
  stats.startedAt = performance.now();
  setInterval(() => {
    const a = performance.now();
    // The stream loops through its keyframe, as a server's periodic keyframe: a delta after the
    // last frame would be based on a sequence the page has passed (a gap, never drawn).
    i = i + 1 < list.length ? i + 1 : 0;
    apply(list[i]);
    for (let k = 0; withPlots && k < 17; k++, tick++) {
      const t = tick / 1000;
      force.push(t, Math.sin(t), Math.cos(t), 0.5, 1);
      pos.push(t, Math.cos(t), Math.sin(t), 0);
    }
    const ms = performance.now() - a;
    stats.jsMs += ms;
    stats.frames++;
  }, 1000 / 60);
}

async function bare() {
  const list = await frames();
  const mirror = new MeshState();
  mirror.apply(Envelope.decode(list[0]));
  const host = /** @type {HTMLElement} */ (document.getElementById('view'));
  const renderer = new THREE.WebGLRenderer({ antialias: true });
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
  const s = /** @type {THREE.Sphere} */ (geometry.boundingSphere);
  const camera = new THREE.PerspectiveCamera(40, host.clientWidth / host.clientHeight);
  placeCamera(camera, s);
  const stats = { renders: 0, startedAt: performance.now() };
  w.__bench = stats;
  const loop = () => {
    renderer.render(scene, camera);
    stats.renders++;
    requestAnimationFrame(loop);
  };
  loop();
}

(location.hash === '#bare' ? bare() : viewer(!location.hash.includes('noplots'))).catch((e) => { w.__benchError = String(e); });
