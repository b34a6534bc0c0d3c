// The tool and force as one mesh (viewer-web/src/view/tool.js): the arrow starts at the tool's
// centre and ends at the force's length along its direction, its faces and normals point
// outward, it is drawn after the sphere and only while there is a force, and the sphere (a square
// of two triangles the shader makes round; tool_render.test.mjs checks it as Chromium draws it)
// takes its state's colour, half see-through. A needle's shaft runs from the tip along its
// orientation's +z for its length, red while it is in the tissue; a tool that is not a needle
// draws no shaft.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from '../../viewer-web/node_modules/three/build/three.module.js';
import { ToolMesh } from '../../viewer-web/src/view/tool.js';
import { display } from '../../viewer-web/src/view/display.js';

/** @param {ToolMesh} m @param {number} v */
const vertex = (m, v) => new THREE.Vector3().fromArray(m.positions, 3 * v);
/** @param {ToolMesh} m @param {number} v */
const normal = (m, v) => new THREE.Vector3().fromArray(m.normals, 3 * v);

test('the arrow runs from the centre along the force, its length and head as asked', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setRadius(1.5);
  const dir = new THREE.Vector3(0.4, -0.2, 1).normalize();
  const length = 4.5, headLength = 0.9, headWidth = 0.525;
  m.setForce(dir, length, headLength, headWidth);
  const n = m.shaftVertex;
  const arrow = [];
  for (let v = m.numSphere; v < n; v++) arrow.push(vertex(m, v));
  // Every arrow vertex lies on the axis's segment [0, length], within the head's half width of it.
  let tip = 0;
  for (const p of arrow) {
    const along = p.dot(dir);
    const off = p.clone().sub(dir.clone().multiplyScalar(along)).length();
    assert.ok(along >= -1e-6 && along <= length + 1e-6, `along ${along}`);
    assert.ok(off <= headWidth / 2 + 1e-6, `off the axis by ${off}`);
    tip = Math.max(tip, along);
  }
  assert.ok(Math.abs(tip - length) < 1e-5, `the tip at ${tip}, not ${length}`);
  // The head's base: widest ring at length - headLength.
  const widest = arrow.filter((p) => Math.abs(p.clone().sub(dir.clone().multiplyScalar(p.dot(dir))).length() - headWidth / 2) < 1e-5);
  assert.ok(widest.length >= 12, `${widest.length} vertices on the head's rim`);
  for (const p of widest) assert.ok(Math.abs(p.dot(dir) - (length - headLength)) < 1e-5);
});

test('the sphere is a square of two triangles at the centre, its radius the shader\'s; every arrow face faces outward', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setRadius(2);
  assert.equal(m.radius.value, 2);
  assert.equal(m.numSphere, 4);
  assert.equal(m.numSphereIndices, 6);
  const corner = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.toolCorner).array;
  const index = /** @type {THREE.BufferAttribute} */ (m.geometry.index).array;
  // The corners: at the centre (the shader places them), marked, at (+-1, +-1); the two
  // triangles counter-clockwise in those coordinates (facing the eye), after the shaft's.
  const s0 = m.numShaftIndices, arrow0 = s0 + m.numSphereIndices;
  for (let v = 0; v < m.numSphere; v++) {
    assert.deepEqual(Array.from(m.positions.subarray(3 * v, 3 * v + 3)), [0, 0, 0]);
    assert.equal(corner[3 * v + 2], 1);
    assert.equal(Math.abs(corner[3 * v]) + Math.abs(corner[3 * v + 1]), 2);
  }
  let area = 0;
  for (let t = s0; t < arrow0; t += 3) {
    const [a, b, c] = [index[t], index[t + 1], index[t + 2]];
    const cross = (corner[3 * b] - corner[3 * a]) * (corner[3 * c + 1] - corner[3 * a + 1]) -
      (corner[3 * b + 1] - corner[3 * a + 1]) * (corner[3 * c] - corner[3 * a]);
    assert.ok(cross > 0, `triangle ${t / 3} is clockwise`);
    area += cross / 2;
  }
  assert.equal(area, 4, 'the two triangles cover the square');
  m.setForce(new THREE.Vector3(0, 0, -1), 5, 1, 0.7);
  let faces = 0;
  for (let t = arrow0; t < index.length; t += 3) {
    const [a, b, c] = [index[t], index[t + 1], index[t + 2]];
    assert.equal(corner[3 * a + 2] + corner[3 * b + 2] + corner[3 * c + 2], 0, 'arrow vertices are not corners');
    const pa = vertex(m, a), pb = vertex(m, b), pc = vertex(m, c);
    const face = pb.clone().sub(pa).cross(pc.clone().sub(pb));
    // Counter-clockwise seen from outside: the face normal agrees with the vertices' normals.
    const avg = normal(m, a).add(normal(m, b)).add(normal(m, c));
    assert.ok(face.dot(avg) > 0, `triangle ${t / 3} (${a}, ${b}, ${c}) faces inward`);
    faces++;
  }
  assert.equal(faces, 4 * 12, 'the arrow: shaft, head and base');
  for (let v = 0; v < m.shaftVertex; v++) assert.ok(Math.abs(normal(m, v).length() - 1) < 1e-5, `normal ${v}`);
});

test('the arrow is drawn after the sphere, and only with a force', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  const s0 = m.numShaftIndices;
  assert.deepEqual(m.geometry.drawRange, { start: s0, count: m.numSphereIndices }, 'no force yet: the sphere alone');
  m.setForce(new THREE.Vector3(1, 0, 0), 3, 0.9, 0.5);
  const count = /** @type {THREE.BufferAttribute} */ (m.geometry.index).count;
  assert.deepEqual(m.geometry.drawRange, { start: s0, count: count - s0 }, 'the sphere and the arrow');
  const index = /** @type {THREE.BufferAttribute} */ (m.geometry.index).array;
  for (let i = s0; i < s0 + m.numSphereIndices; i++) assert.ok(index[i] < m.numSphere, 'the sphere first');
  for (let i = s0 + m.numSphereIndices; i < index.length; i++) {
    assert.ok(index[i] >= m.numSphere && index[i] < m.shaftVertex, 'then the arrow');
  }
  m.hideForce();
  assert.deepEqual(m.geometry.drawRange, { start: s0, count: m.numSphereIndices });
});

test('the sphere\'s fill is see-through (display.json\'s fill_alpha) in its state colour; the arrow opaque', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setColor(0xe08a1e);
  const want = new THREE.Color(0xe08a1e);
  for (let v = 0; v < m.numSphere; v++) {
    assert.deepEqual(Array.from(m.colors.subarray(4 * v, 4 * v + 4)), [Math.fround(want.r), Math.fround(want.g), Math.fround(want.b), Math.fround(display.tool.fill_alpha)]);
  }
  const arrow = new THREE.Color(0x1d5fa8);
  assert.deepEqual(Array.from(m.colors.subarray(4 * m.numSphere, 4 * m.numSphere + 4)),
    [Math.fround(arrow.r), Math.fround(arrow.g), Math.fround(arrow.b), 1]);
});

test('a force changed several times before a render uploads the arrow once', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  const pos = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.position);
  pos.clearUpdateRanges();
  for (let i = 0; i < 3; i++) m.setForce(new THREE.Vector3(0, 1, 0), 2 + i, 0.5, 0.3);
  assert.deepEqual(pos.updateRanges, [{ start: 3 * m.numSphere, count: 3 * (m.shaftVertex - m.numSphere) }]);
});

test('every change is uploaded, also when its range is still pending from the first upload', () => {
  // three.js uploads a new buffer whole and leaves the ranges asked for before it pending.
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  const color = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.color);
  const uploaded = color.version;
  m.setColor(0xe08a1e);
  assert.ok(color.version > uploaded, 'the new colour is uploaded');
  const arrowStart = 3 * m.numSphere;
  const pos = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.position);
  const before = pos.version;
  m.setForce(new THREE.Vector3(0, 0, 1), 2, 0.5, 0.3);
  m.setForce(new THREE.Vector3(0, 1, 0), 3, 0.5, 0.3);
  assert.ok(pos.version > before, 'the new force is uploaded');
  assert.equal(pos.updateRanges.filter((r) => r.start === arrowStart).length, 1, 'its range once');
});

/**
 * The shaft's vertices, as drawn: those the drawn range of the index names past the arrow's.
 * @param {ToolMesh} m
 */
function drawnShaft(m) {
  const index = /** @type {THREE.BufferAttribute} */ (m.geometry.index).array;
  const { start, count } = m.geometry.drawRange;
  const drawn = new Set();
  for (let i = start; i < Math.min(index.length, start + count); i++) if (index[i] >= m.shaftVertex) drawn.add(index[i]);
  return [...drawn].map((v) => vertex(m, v));
}

/**
 * Every point's distance along the axis from the tip and off it.
 * @param {THREE.Vector3[]} points @param {THREE.Vector3} axis unit, tip to tail
 */
const alongAxis = (points, axis) => points.map((p) => {
  const along = p.dot(axis);
  return { along, off: p.clone().sub(axis.clone().multiplyScalar(along)).length() };
});

test('a needle\'s shaft runs from the tip along its orientation\'s +z for its length, within its radius', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setRadius(0.25);
  m.setNeedle(5, 0.25 / 3);
  // The pierce's needle: tilted 30 degrees from vertical in the x-z plane.
  const q = new THREE.Quaternion().setFromAxisAngle(new THREE.Vector3(0, 1, 0), Math.PI / 6);
  m.setNeedlePose({ w: q.w, x: q.x, y: q.y, z: q.z }, false);
  const axis = new THREE.Vector3(0, 0, 1).applyQuaternion(q);
  const shaft = drawnShaft(m);
  assert.equal(shaft.length, 3 * 12 + 1, 'a ring at each end and the tail\'s cap');
  const ends = { tip: 0, tail: 0 };
  for (const { along, off } of alongAxis(shaft, axis)) {
    assert.ok(along >= -1e-6 && along <= 5 + 1e-6, `along ${along}`);
    assert.ok(off <= 0.25 / 3 + 1e-6, `off the axis by ${off}`);
    if (Math.abs(off - 0.25 / 3) < 1e-6) ends[along < 2.5 ? 'tip' : 'tail']++;
  }
  assert.deepEqual(ends, { tip: 12, tail: 24 }, 'rims at the tip and at the tail, at the shaft\'s radius');
  // Its faces point away from the axis (or out of the tail's end).
  const index = /** @type {THREE.BufferAttribute} */ (m.geometry.index).array;
  const tail = axis.clone().multiplyScalar(5);
  for (let t = 0; t < m.numShaftIndices; t += 3) {
    const [a, b, c] = [vertex(m, index[t]), vertex(m, index[t + 1]), vertex(m, index[t + 2])];
    const face = b.clone().sub(a).cross(c.clone().sub(b));
    const centre = a.clone().add(b).add(c).divideScalar(3);
    const out = centre.clone().sub(axis.clone().multiplyScalar(centre.dot(axis)));
    assert.ok(face.dot(out.lengthSq() > 1e-9 ? out : centre.clone().sub(tail).add(axis)) > 0, `shaft triangle ${t / 3} faces inward`);
  }
  for (let v = m.shaftVertex; v < m.positions.length / 3; v++) assert.ok(Math.abs(normal(m, v).length() - 1) < 1e-5, `normal ${v}`);
  // Drawn first (the tip's ring and the force over it), then the sphere, with or without a force.
  assert.deepEqual(m.geometry.drawRange, { start: 0, count: m.numShaftIndices + m.numSphereIndices });
  m.setForce(new THREE.Vector3(0, 0, 1), 2, 0.5, 0.3);
  assert.deepEqual(m.geometry.drawRange, { start: 0, count: /** @type {THREE.BufferAttribute} */ (m.geometry.index).count });
  // The tail where the orientation puts it.
  m.position.set(1, 2, 3);
  assert.ok(m.tail(new THREE.Vector3()).distanceTo(axis.clone().multiplyScalar(5).add(m.position)) < 1e-9);
});

test('no orientation (or a zero one) is the identity: the shaft straight up from the tip', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setNeedle(10, 0.1);
  for (const q of [null, undefined, { w: 0, x: 0, y: 0, z: 0 }, { w: 1 }]) {
    m.setNeedlePose(q, false);
    const shaft = drawnShaft(m);
    assert.equal(shaft.length, 37);
    for (const p of shaft) {
      assert.ok(Math.hypot(p.x, p.y) <= 0.1 + 1e-6, `off the vertical by ${Math.hypot(p.x, p.y)}`);
      assert.ok(p.z >= -1e-6 && p.z <= 10 + 1e-6, `z ${p.z}`);
    }
    assert.ok(Math.max(...shaft.map((p) => p.z)) > 10 - 1e-6, 'the tail above the tip');
  }
});

test('the shaft is steel, red while the needle is in the tissue; rewritten only when its pose or state changes', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setNeedle(5, 0.1);
  const colour = (/** @type {number} */ v) => Array.from(m.colors.subarray(4 * v, 4 * v + 4));
  const steel = new THREE.Color().setRGB(0.45, 0.50, 0.58, THREE.SRGBColorSpace);
  const red = new THREE.Color().setRGB(0.80, 0.18, 0.16, THREE.SRGBColorSpace);
  const f = Math.fround;
  m.setNeedlePose(null, false);
  for (let v = m.shaftVertex; v < m.positions.length / 3; v++) assert.deepEqual(colour(v), [f(steel.r), f(steel.g), f(steel.b), 1]);
  m.setNeedlePose(null, true);
  for (let v = m.shaftVertex; v < m.positions.length / 3; v++) assert.deepEqual(colour(v), [f(red.r), f(red.g), f(red.b), 1]);
  const pos = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.position);
  const col = /** @type {THREE.BufferAttribute} */ (m.geometry.attributes.color);
  const [p0, c0] = [pos.version, col.version];
  m.setNeedlePose({ w: 1, x: 0, y: 0, z: 0 }, true);
  assert.deepEqual([pos.version, col.version], [p0, c0], 'the same pose and state: nothing uploaded');
});

test('a tool that is not a needle draws no shaft, as before there was one', () => {
  const m = new ToolMesh(0x4f7cac, 0x1d5fa8);
  m.setRadius(1.5);
  assert.equal(drawnShaft(m).length, 0);
  m.setForce(new THREE.Vector3(0.2, 0, -1).normalize(), 4, 1, 0.5);
  assert.equal(drawnShaft(m).length, 0, 'with a force');
  m.setNeedlePose({ w: 0.9, x: 0.1, y: 0.3, z: 0.2 }, true);
  assert.equal(drawnShaft(m).length, 0, 'with an orientation');
  // A needle, then a tool that is not (another session's scene): the shaft goes.
  m.setNeedle(5, 0.1);
  assert.equal(drawnShaft(m).length, 37);
  m.setNeedle(0, 0.1);
  assert.equal(drawnShaft(m).length, 0);
  assert.equal(m.geometry.drawRange.start, m.numShaftIndices);
});
