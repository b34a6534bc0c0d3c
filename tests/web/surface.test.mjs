// The surface's per-frame work (viewer-web/src/view/surface_geometry.js) without a browser: the moved
// vertices of a C++-encoded stream applied, then the normals around them recomputed once per frame
// drawn, as the live view does. It must give the normals a full recomputation gives, upload only
// the spans that moved, and allocate nothing per frame (the issue's "nothing is allocated per
// frame"; a three-argument Math.hypot there once made about 160 kB of garbage a frame). And the
// camera's fit (surface.js's placeCamera and framedBox): all of what it frames in view, tightly.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { PerformanceObserver } from 'node:perf_hooks';
import * as THREE from '../../viewer-web/node_modules/three/build/three.module.js';
import { idms } from '../../viewer-web/src/codec/proto.js';
import { MeshState } from '../../viewer-web/src/codec/mesh.js';
import { SurfaceGeometry } from '../../viewer-web/src/view/surface_geometry.js';
import { placeCamera, toolNear } from '../../viewer-web/src/view/surface.js';

const bin = process.env.IDMS_WEB_MESH_FRAMES_BIN;

/** The bench's stream (a dent circling over a 100 x 100 sheet), as Envelope bytes. */
function sheetFrames() {
  assert.ok(bin, 'IDMS_WEB_MESH_FRAMES_BIN names build/bin/idms-web-mesh-frames');
  const file = join(mkdtempSync(join(tmpdir(), 'idms-web-surface-')), 'frames.bin');
  execFileSync(bin, ['--sheet', '100', '100', '120', file]);
  const bytes = readFileSync(file);
  const out = [];
  for (let p = 0; p < bytes.length;) {
    const n = bytes.readUInt32LE(p);
    out.push(bytes.subarray(p + 4, p + 4 + n));
    p += 4 + n;
  }
  return out;
}

/**
 * What a render does to the buffers: three.js uploads what is pending and clears the ranges.
 * @param {SurfaceGeometry} surface
 */
function rendered(surface) {
  if (surface.moved) surface.updateNormals();
  for (const a of [surface.posAttr, surface.normAttr, surface.geometry.index]) a?.clearUpdateRanges();
  surface.rendered();
}

/**
 * Each delta's moved vertices, as applyMoved reads them from the mirror (copied: the mirror
 * rewrites its arrays at every frame).
 */
function decodedDeltas() {
  const mirror = new MeshState();
  const frames = sheetFrames();
  assert.equal(mirror.apply(idms.v1.Envelope.decode(frames[0])), 'ok');
  const keyframe = { numVertices: mirror.numVertices, numTriangles: mirror.numTriangles,
    positions: mirror.positions.slice(), triangles: mirror.triangles.slice() };
  const deltas = [];
  for (const bytes of frames.slice(1)) {
    assert.equal(mirror.apply(idms.v1.Envelope.decode(bytes)), 'ok', mirror.error);
    if (mirror.numChanged === 0) continue;
    deltas.push({ numChanged: mirror.numChanged, changed: mirror.changed.slice(0, mirror.numChanged),
      positions: mirror.positions.slice() });
  }
  assert.ok(deltas.length > 100, `${deltas.length} deltas`);
  return { keyframe, deltas };
}

test('normals updated around the moved vertices equal a full recomputation; only the moved span is uploaded', () => {
  const { keyframe, deltas } = decodedDeltas();
  const surface = new SurfaceGeometry();
  surface.setSurface(keyframe);
  rendered(surface);
  // Three deltas per frame drawn, as the bench's 60 Hz stream against a 20 fps surface.
  for (let k = 0; k + 3 <= 30; k += 3) {
    for (let j = k; j < k + 3; j++) surface.applyMoved(deltas[j]);
    const lo = surface.movedLo, hi = surface.movedHi;
    surface.updateNormals();
    const pos = /** @type {THREE.BufferAttribute} */ (surface.posAttr);
    assert.deepEqual(pos.updateRanges, [{ start: 3 * lo, count: 3 * (hi - lo + 1) }]);
    for (let j = k; j < k + 3; j++) assert.ok(deltas[j].changed[0] >= lo && deltas[j].changed[deltas[j].numChanged - 1] <= hi);
  }
  // Against every normal computed afresh from the same positions.
  const fresh = new SurfaceGeometry();
  fresh.setSurface({ ...keyframe, positions: /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (surface.posAttr).array) });
  const a = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (surface.normAttr).array);
  const b = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (fresh.normAttr).array);
  let worst = 0;
  for (let i = 0; i < 3 * keyframe.numVertices; i++) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  assert.ok(worst < 1e-6, `normals differ by up to ${worst}`);
});

test('applying moved vertices and recomputing their normals allocates nothing per frame', async () => {
  const { keyframe, deltas } = decodedDeltas();
  const surface = new SurfaceGeometry();
  surface.setSurface(keyframe);
  const frame = (/** @type {number} */ f) => {
    const k = (3 * f) % (deltas.length - 2);
    surface.applyMoved(deltas[k]);
    surface.applyMoved(deltas[k + 1]);
    surface.applyMoved(deltas[k + 2]);
    surface.updateNormals();
  };
  // Warm-up: every path compiled and optimised.
  for (let f = 0; f < 2000; f++) frame(f);
  let collections = 0;
  const observer = new PerformanceObserver((list) => { collections += list.getEntries().length; });
  observer.observe({ entryTypes: ['gc'] });
  await new Promise((r) => setTimeout(r, 200));
  collections = 0;
  // 3,000 frames of about 760 moved vertices each: 16 bytes a vertex would fill V8's young
  // generation dozens of times over (the Math.hypot version collected 163 times in 2,000).
  for (let f = 0; f < 3000; f++) frame(f);
  // The entries arrive after the collections, asynchronously.
  await new Promise((r) => setTimeout(r, 200));
  observer.disconnect();
  assert.ok(collections <= 1, `${collections} garbage collections during 3,000 frames`);
});

test('a keyframe of the same triangles moves only what moved: no rebuild, no whole upload, the same normals', () => {
  const { keyframe, deltas } = decodedDeltas();
  const surface = new SurfaceGeometry();
  surface.setSurface(keyframe);
  // Drawn once: what a first keyframe uploads is done with.
  rendered(surface);
  const index = /** @type {THREE.BufferAttribute} */ (surface.geometry.index);
  const pos = /** @type {THREE.BufferAttribute} */ (surface.posAttr);
  const norm = /** @type {THREE.BufferAttribute} */ (surface.normAttr);
  for (const a of [index, pos, norm]) a.clearUpdateRanges();
  const indexVersion = index.version;
  const adjacency = surface.adjTris;
  // The stream's periodic keyframe some frames on: the same triangles, the dent moved on.
  const later = deltas[40];
  const again = { ...keyframe, positions: later.positions };
  surface.setSurface(again);
  const moved = [];
  for (let v = 0; v < keyframe.numVertices; v++) {
    for (let c = 0; c < 3; c++) {
      if (keyframe.positions[3 * v + c] !== later.positions[3 * v + c]) {
        moved.push(v);
        break;
      }
    }
  }
  assert.ok(moved.length > 0 && moved.length < keyframe.numVertices / 2, `${moved.length} vertices moved`);
  assert.equal(surface.numTouchedTris > 0, true);
  assert.equal(index.version, indexVersion, 'the triangles were uploaded again');
  assert.equal(surface.adjTris, adjacency);
  surface.updateNormals();
  // Only the span of the vertices that moved is uploaded.
  assert.deepEqual(pos.updateRanges, [{ start: 3 * moved[0], count: 3 * (moved[moved.length - 1] - moved[0] + 1) }]);
  assert.equal(norm.updateRanges.length, 1);
  assert.ok(norm.updateRanges[0].count < 3 * keyframe.numVertices);
  // The same positions and normals as the keyframe taken whole.
  const fresh = new SurfaceGeometry();
  fresh.setSurface(again);
  assert.deepEqual(pos.array, /** @type {THREE.BufferAttribute} */ (fresh.posAttr).array);
  const a = /** @type {Float32Array} */ (norm.array);
  const b = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (fresh.normAttr).array);
  let worst = 0;
  for (let i = 0; i < 3 * keyframe.numVertices; i++) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  assert.ok(worst < 1e-6, `normals differ by up to ${worst}`);
  // Other triangles: rebuilt whole.
  const flipped = keyframe.triangles.slice();
  [flipped[1], flipped[2]] = [flipped[2], flipped[1]];
  surface.setSurface({ ...keyframe, triangles: flipped });
  assert.ok(index.version > indexVersion, 'new triangles were not uploaded');
  assert.equal(/** @type {Uint32Array} */ (index.array)[1], flipped[1]);
  // And a delta before the frame is drawn leaves them whole: an update range would have three.js
  // upload that span alone, and the rest of the new surface never.
  surface.applyMoved(deltas[41]);
  surface.updateNormals();
  assert.deepEqual(pos.updateRanges, [], 'the new positions go whole, not as a range');
  assert.deepEqual(norm.updateRanges, [], 'the new normals go whole, not as a range');
});

test('the bounds are those of the surface shown, not of a larger one before it left in the buffers', () => {
  const surface = new SurfaceGeometry();
  // A 10 x 10 square, then a unit triangle: the buffers keep the square's size.
  surface.setSurface({ numVertices: 4, numTriangles: 2, positions: new Float32Array([0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 10, 0]),
    triangles: new Uint32Array([0, 1, 2, 0, 2, 3]) });
  assert.equal(surface.boundingBox(new THREE.Box3()).max.x, 10);
  surface.setSurface({ numVertices: 3, numTriangles: 1, positions: new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]),
    triangles: new Uint32Array([0, 1, 2]) });
  assert.equal(surface.capacityV, 4);
  const box = surface.boundingBox(new THREE.Box3());
  assert.deepEqual([box.min.toArray(), box.max.toArray()], [[0, 0, 0], [1, 1, 0]]);
  const sphere = surface.boundingSphere(new THREE.Sphere());
  assert.deepEqual(sphere.center.toArray(), [0.5, 0.5, 0]);
  assert.ok(Math.abs(sphere.radius - Math.SQRT1_2) < 1e-6, `radius ${sphere.radius}`);
  // three.js's own bounds take the whole buffer, the square's fourth vertex with it.
  surface.geometry.computeBoundingBox();
  assert.equal(surface.geometry.boundingBox?.max.y, 10);
  // Nothing shown: empty.
  assert.ok(new SurfaceGeometry().boundingSphere(new THREE.Sphere()).isEmpty());
});

test('the camera shows every corner of the box it frames and the tool wherever it went, as near as it can, whatever the view\'s shape', () => {
  const boxes = {
    'a flat sheet': new THREE.Box3(new THREE.Vector3(-10, -8, 0), new THREE.Vector3(10, 8, 0.1)),
    'a cube off the origin': new THREE.Box3(new THREE.Vector3(3, 4, 5), new THREE.Vector3(5, 6, 7)),
    'a tall column': new THREE.Box3(new THREE.Vector3(-1, -1, 0), new THREE.Vector3(1, 1, 12)),
  };
  // The tool pressing down at one end of the sheet, or nowhere.
  const travels = { 'no tool': new THREE.Box3(), 'a tool pressing': new THREE.Box3(new THREE.Vector3(8, 0, 1), new THREE.Vector3(8, 0, 6)) };
  const radius = 1.5;
  for (const [name, box] of Object.entries(boxes)) {
    for (const [tool, travel] of Object.entries(travels)) {
      for (const aspect of [0.45, 1, 818 / 388, 3]) {
        const camera = new THREE.PerspectiveCamera(40, aspect);
        const target = new THREE.Vector3();
        placeCamera(camera, box, travel, radius, target);
        camera.updateMatrixWorld();
        const what = `${name}, ${tool}, aspect ${aspect.toFixed(2)}`;
        let edge = 0;
        const lo = new THREE.Vector2(Infinity, Infinity), hi = new THREE.Vector2(-Infinity, -Infinity);
        /** @param {THREE.Vector3} p */
        const seen = (p) => {
          const q = p.clone().project(camera);
          assert.ok(Math.abs(q.x) <= 1 + 1e-9 && Math.abs(q.y) <= 1 + 1e-9 && q.z > -1 && q.z < 1, `${what}: ${p.toArray()} at ${q.toArray()}`);
          edge = Math.max(edge, Math.abs(q.x), Math.abs(q.y));
          lo.min(new THREE.Vector2(q.x, q.y));
          hi.max(new THREE.Vector2(q.x, q.y));
        };
        for (let i = 0; i < 8; i++) seen(new THREE.Vector3(i & 1 ? box.max.x : box.min.x, i & 2 ? box.max.y : box.min.y, i & 4 ? box.max.z : box.min.z));
        // Centred: the box's corners reach as far left as right, and as far down as up.
        if (travel.isEmpty()) {
          assert.ok(Math.abs(lo.x + hi.x) < 1e-6 && Math.abs(lo.y + hi.y) < 1e-6, `${what}: spans x ${lo.x}..${hi.x}, y ${lo.y}..${hi.y}`);
        }
        if (!travel.isEmpty()) {
          // The tool's silhouette at both ends of its travel: its centre +- its radius along the
          // camera's right and up (and along the view, which shows it wider).
          const right = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 0);
          const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
          for (const c of [travel.min, travel.max]) {
            const toward = camera.position.clone().sub(c).normalize();
            for (const dir of [right, up]) {
              // The silhouette's edge as seen from the camera: the tangent point, tilted towards it.
              const tangent = dir.clone().sub(toward.clone().multiplyScalar(dir.dot(toward))).normalize();
              const sinA = radius / camera.position.distanceTo(c);
              for (const sign of [1, -1]) {
                seen(c.clone().addScaledVector(tangent, sign * radius * Math.sqrt(1 - sinA * sinA)).addScaledVector(toward, radius * sinA));
              }
            }
          }
        }
        // Tight: something reaches the view's edge, less its 5% margin (a bounding sphere fitted
        // into the narrower field of view left a flat sheet in a wide view at a third of it).
        assert.ok(edge > 0.9, `${what}: the farthest point at ${edge.toFixed(3)} of the view`);
        assert.equal(camera.up.z, 1);
        assert.ok(camera.position.z > target.z, `${what}: from above`);
      }
    }
  }
});

test('a tool near the surface is framed with it, a far one is not', () => {
  const sheet = new THREE.Sphere(new THREE.Vector3(0, 0, 0), 12.8);
  assert.ok(toolNear(sheet, new THREE.Sphere(new THREE.Vector3(9, 0, 4), 1.5)));
  assert.ok(toolNear(sheet, new THREE.Sphere(new THREE.Vector3(0, 0, 26), 1.5)), 'within the diameter of the surface\'s sphere');
  assert.ok(!toolNear(sheet, new THREE.Sphere(new THREE.Vector3(0, 0, 60), 1.5)), 'a tool far above is left out: the tissue stays the subject');
});
