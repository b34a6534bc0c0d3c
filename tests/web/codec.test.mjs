// The browser's mesh codec against frames protocol/'s C++ encoder wrote (idms-web-mesh-frames):
// every frame applied in order must leave MeshState exactly where the C++ MeshMirror was, with the
// same status and message, so the two decoders cannot drift apart.
//   IDMS_WEB_MESH_FRAMES_BIN=build/bin/idms-web-mesh-frames node --test tests/web/codec.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { idms } from '../../viewer-web/src/codec/proto.js';
import { MeshState } from '../../viewer-web/src/codec/mesh.js';
import { inspectZstdFrame } from '../../viewer-web/src/codec/zstd_frame.js';
import { FrameDecoder } from '../../viewer-web/src/codec/frames.js';

const bin = process.env.IDMS_WEB_MESH_FRAMES_BIN;
const Envelope = idms.v1.Envelope;

/** The C++ tool's lines: frame bytes, status, message and the mirror's state after each. */
function cppFrames() {
  assert.ok(bin, 'IDMS_WEB_MESH_FRAMES_BIN names build/bin/idms-web-mesh-frames');
  const file = join(mkdtempSync(join(tmpdir(), 'idms-web-codec-')), 'frames.jsonl');
  execFileSync(bin, [file]);
  return readFileSync(file, 'utf8').trim().split('\n').map((l) => JSON.parse(l));
}

// zstd's and fzstd's own messages for a corrupt frame differ; everything else is our text.
const sameMessage = (/** @type {string} */ js, /** @type {string} */ cpp) =>
  cpp.includes('zstd: ') || cpp.includes('corrupt zstd frame') ? js.split(': ')[0] === cpp.split(': ')[0] : js === cpp;

test('every C++-encoded frame, valid or damaged, decodes to the C++ mirror state', () => {
  const lines = cppFrames();
  assert.ok(lines.length > 90, `${lines.length} frames`);
  /** @type {Map<string, MeshState>} */
  const states = new Map();
  let keyframes = 0, deltas = 0, empty = 0, zstd = 0, raw = 0, refused = 0;
  for (const line of lines) {
    // One MeshState per scenario, as the tool keeps one mirror per scenario.
    const scenario = line.name.replace(/ frame \d+$/, '').replace(/^damaged( keyframe)?: .*/, 'damaged');
    if (!states.has(scenario)) states.set(scenario, new MeshState());
    const state = /** @type {MeshState} */ (states.get(scenario));
    const env = Envelope.decode(Buffer.from(line.frame, 'hex'));
    const frame = env.meshKeyframe ?? env.meshDelta;
    assert.ok(frame, line.name);
    const status = state.apply(env);
    assert.equal(status, line.status, `${line.name}: ${state.error}`);
    assert.ok(sameMessage(state.error, line.error), `${line.name}: JS "${state.error}" vs C++ "${line.error}"`);
    // The state after, exactly: sequence, quantized positions, float positions, triangles.
    assert.equal(state.sequence, line.sequence, line.name);
    assert.deepEqual(Array.from(state.q.subarray(0, 3 * state.numVertices)), line.q, line.name);
    assert.deepEqual(Array.from(state.triangles.subarray(0, 3 * state.numTriangles)), line.triangles, line.name);
    for (let k = 0; k < line.q.length; k++) assert.equal(state.positions[k], Math.fround(line.q[k] * state.quantStep));
    if (status === 'ok' && env.meshDelta) assert.equal(state.numChanged, line.num_changed, line.name);
    // What was covered.
    if (status !== 'ok') refused++;
    else if (env.meshKeyframe) keyframes++;
    else if (env.meshDelta?.numChanged === 0) empty++;
    else deltas++;
    if (frame.compression === 1) zstd++;
    else raw++;
  }
  assert.ok(keyframes >= 6 && deltas >= 50 && empty >= 4 && refused >= 20 && zstd > 20 && raw > 10,
    JSON.stringify({ keyframes, deltas, empty, refused, zstd, raw }));
});

test('decompressing never turns the output buffer into a string (fzstd tests it with a loose == 1)', () => {
  // A Uint8Array meets == through %TypedArray%.prototype.toString: every byte as text, some
  // milliseconds a frame. The viewer hands fzstd a view that converts to NaN instead.
  const proto = Object.getPrototypeOf(Uint8Array.prototype);
  const toString = proto.toString;
  let calls = 0;
  proto.toString = function () {
    calls++;
    return toString.call(this);
  };
  let zstd = 0;
  try {
    const state = new MeshState();
    for (const line of cppFrames()) {
      const env = Envelope.decode(Buffer.from(line.frame, 'hex'));
      const frame = env.meshKeyframe ?? env.meshDelta;
      if (line.status !== 'ok' || frame?.compression !== 1) continue;
      state.payload(/** @type {any} */ (frame), 1 << 24);
      assert.equal(state.error, '', line.name);
      zstd++;
    }
  } finally {
    proto.toString = toString;
  }
  assert.ok(zstd > 20, `${zstd} zstd frames`);
  assert.equal(calls, 0, 'typed arrays converted to strings while decompressing');
});

test('a refused frame leaves the surface as it was, and the next valid delta applies', () => {
  const lines = cppFrames().filter((l) => l.name.startsWith('session origin 0'));
  const state = new MeshState();
  assert.equal(state.apply(Envelope.decode(Buffer.from(lines[0].frame, 'hex'))), 'ok');
  const delta = Envelope.decode(Buffer.from(lines[1].frame, 'hex'));
  assert.ok(delta.meshDelta && delta.meshDelta.numChanged > 0);
  const before = Array.from(state.q.subarray(0, 3 * state.numVertices));
  // A gap (the base is not the frame held) is reported, not drawn.
  const lost = Envelope.decode(Buffer.from(lines[2].frame, 'hex'));
  assert.equal(state.apply(lost), 'gap');
  assert.match(state.error, /is ahead of the mirror's frame .* \(frames lost\)/);
  // A truncated zstd payload is refused with the frame named.
  const cut = Envelope.decode(Buffer.from(lines[1].frame, 'hex'));
  if (!cut.meshDelta) throw new Error('not a delta');
  cut.meshDelta.payload = cut.meshDelta.payload.subarray(0, cut.meshDelta.payload.length - 3);
  assert.equal(state.apply(cut), 'invalid');
  assert.match(state.error, /^delta \d+: /);
  assert.deepEqual(Array.from(state.q.subarray(0, 3 * state.numVertices)), before);
  assert.equal(state.apply(delta), 'ok');
  assert.deepEqual(Array.from(state.q.subarray(0, 3 * state.numVertices)), lines[1].q);
});

test('zstd frame inspection names what is wrong', () => {
  assert.equal(inspectZstdFrame(new Uint8Array([1, 2, 3, 4, 5, 6])).error, 'payload is not a zstd frame');
  // Magic, then a header without a content size (no single segment, FCS flag 0), window byte.
  const noSize = new Uint8Array([0x28, 0xb5, 0x2f, 0xfd, 0x00, 0x58, 0x01, 0x00, 0x00]);
  assert.equal(inspectZstdFrame(noSize).error, 'zstd frame does not declare its content size');
});

test('64-bit fields are numbers, set or not: an unset topology version compares equal across messages', () => {
  const key = Envelope.decode(Envelope.encode({ meshKeyframe: { sequence: 1, quantStep: 1e-4 } }).finish());
  const delta = Envelope.decode(Envelope.encode({ meshDelta: { sequence: 2, baseSequence: 1 } }).finish());
  assert.equal(typeof key.meshKeyframe?.topologyVersion, 'number');
  assert.equal(key.meshKeyframe?.topologyVersion, delta.meshDelta?.topologyVersion);
  const state = new MeshState();
  assert.equal(state.apply(key), 'ok');
  assert.equal(state.apply(delta), 'ok', state.error);
});

test('FrameDecoder reads every C++-encoded frame as the generated decoder does', () => {
  const decoder = new FrameDecoder();
  /** @type {Map<string, MeshState[]>} */
  const states = new Map();
  let fast = 0;
  for (const line of cppFrames()) {
    const scenario = line.name.replace(/ frame \d+$/, '').replace(/^damaged( keyframe)?: .*/, 'damaged');
    if (!states.has(scenario)) states.set(scenario, [new MeshState(), new MeshState()]);
    const [a, b] = /** @type {MeshState[]} */ (states.get(scenario));
    const bytes = Buffer.from(line.frame, 'hex');
    const frame = decoder.decode(bytes);
    if (frame === decoder.deltaFrame) fast++;
    assert.equal(b.apply(/** @type {any} */ (frame)), a.apply(Envelope.decode(bytes)), line.name);
    assert.equal(b.error, a.error, line.name);
    assert.equal(b.sequence, a.sequence, line.name);
    assert.deepEqual(b.q.subarray(0, 3 * b.numVertices), a.q.subarray(0, 3 * a.numVertices), line.name);
  }
  assert.ok(fast > 50, `${fast} deltas through the fast path`);
});

test('FrameDecoder reads device samples into the same objects every batch, with unset fields as 0', () => {
  const decoder = new FrameDecoder();
  const batch = (/** @type {number} */ n, /** @type {boolean} */ stats) => Envelope.encode({ deviceSamples: {
    samples: Array.from({ length: n }, (_, k) => ({ tick: 2 ** 40 + k, timeS: k / 1000, toolPos: { x: k, y: -k, z: 0.5 },
      force: k % 2 ? { x: 0.25, z: -k } : null, contact: k % 3 === 0, grasp: k === 1, warnings: k === 2 ? 3 : 0, substeps: 1,
      forceLimited: k % 4 === 1, ...(k === 4 ? { frictionForce: { x: 0.3, y: -0.1 }, normalForce: 1.25, friction: 2 } : {}),
      ...(k === 5 ? { toolOrientation: { w: 0.966, y: 0.259 }, needlePunctured: true, needleInserted: 1.5 } : {}),
      ...(k === 6 ? { toolIndex: 1 } : {}) })),
    stats: stats ? { ticks: 2 ** 45, overruns: 7, periodP99Us: 1010, computeP99Us: 40, realtime: true, periodMaxUs: 9 } : null,
    samplesDropped: 12, sentUnixNs: 1.7e18 } }).finish();
  const first = decoder.decode(batch(17, true));
  const d = first.deviceSamples;
  assert.ok(d);
  assert.equal(d.count, 17);
  assert.deepEqual(d.stats, { ticks: 2 ** 45, overruns: 7, periodP99Us: 1010, computeP99Us: 40, realtime: true,
    passivityTicks: 0, passivityDissipated: 0 });
  assert.equal(d.samplesDropped, 12);
  for (let k = 0; k < 17; k++) {
    const s = d.samples[k];
    assert.deepEqual(s, { timeS: k / 1000, toolPos: { x: k, y: -k, z: 0.5 }, force: k % 2 ? { x: 0.25, y: 0, z: -k } : { x: 0, y: 0, z: 0 },
      contact: k % 3 === 0, grasp: k === 1, warnings: k === 2 ? 3 : 0, forceLimited: k % 4 === 1,
      frictionForce: k === 4 ? { x: 0.3, y: -0.1, z: 0 } : { x: 0, y: 0, z: 0 }, normalForce: k === 4 ? 1.25 : 0,
      friction: k === 4 ? 2 : 0, portEnergy: 0, portEnergyWindow: 0, passivityDamping: 0,
      // A needle's pose and state (k = 5); unset, the orientation is the identity.
      toolOrientation: k === 5 ? { w: 0.966, x: 0, y: 0.259, z: 0 } : { w: 1, x: 0, y: 0, z: 0 },
      needlePunctured: k === 5, needleInserted: k === 5 ? 1.5 : 0,
      // The scene tool held (k = 6: the second, as the suture's scalpel).
      toolIndex: k === 6 ? 1 : 0 }, `sample ${k}`);
  }
  const sample3 = d.samples[3];
  // A smaller batch without statistics: the same objects, rewritten.
  const second = decoder.decode(batch(5, false));
  assert.equal(second, first);
  assert.equal(second.deviceSamples?.samples[3], sample3);
  assert.equal(second.deviceSamples?.count, 5);
  assert.equal(second.deviceSamples?.stats, null);
  // Other messages go through the generated decoder; malformed bytes throw.
  const note = decoder.decode(Envelope.encode({ annotation: { text: 'here', timeS: 1.5 } }).finish());
  assert.equal(note.annotation?.text, 'here');
  const cut = batch(3, true);
  assert.throws(() => decoder.decode(cut.subarray(0, cut.length - 4)), RangeError);
});

test('FrameDecoder.each hands over a Frames message\'s envelopes in order, and a lone envelope as itself', () => {
  const decoder = new FrameDecoder();
  const samples = (/** @type {number} */ tick) => Envelope.encode({ deviceSamples: { samples: [{ tick, timeS: tick / 1000 }] } }).finish();
  const delta = Envelope.encode({ meshDelta: { sequence: 7, baseSequence: 6, numChanged: 1 } }).finish();
  const note = Envelope.encode({ annotation: { text: 'deep', timeS: 2 } }).finish();
  const gathered = Envelope.encode({ frames: { envelopes: [samples(40), samples(60), delta, note] } }).finish();
  /** @type {string[]} */
  const seen = [];
  decoder.each(gathered, (f) => {
    if (f.deviceSamples) seen.push(`samples ${f.deviceSamples.samples[0].timeS * 1000}`);
    else if (f.meshDelta) seen.push(`delta ${f.meshDelta.sequence}`);
    else if (f.annotation) seen.push(`note ${f.annotation.text}`);
  });
  assert.deepEqual(seen, ['samples 40', 'samples 60', 'delta 7', 'note deep']);
  /** @type {number[]} */
  const alone = [];
  decoder.each(samples(5), (f) => alone.push(f.deviceSamples?.count ?? -1));
  assert.deepEqual(alone, [1]);
  // A Frames cut short throws, as any malformed message does.
  assert.throws(() => decoder.each(gathered.subarray(0, gathered.length - 3), () => {}), RangeError);
});

test('FrameDecoder reads a delta\'s suture thread as the generated decoder does, and refuses one too long', () => {
  const nodes = Array.from({ length: 3 * 65 }, (_, i) => Math.fround(0.25 * i - 7));
  const punctures = [1.5, 1.75, 0, Math.fround(1.5), Math.fround(1.7), Math.fround(-0.8)];
  const bytes = Envelope.encode({ meshDelta: { sequence: 3, baseSequence: 2, numChanged: 0,
    suture: { nodes, punctures, ties: 1, brokenSegment: 12 } } }).finish();
  const decoder = new FrameDecoder();
  const f = decoder.decode(bytes);
  const s = f.meshDelta?.suture;
  assert.ok(s, 'the delta carries its thread');
  assert.equal(s.numNodes, 65);
  assert.deepEqual([...s.nodes.subarray(0, 3 * 65)], nodes);
  assert.equal(s.numPunctures, 2);
  assert.deepEqual([...s.punctures.subarray(0, 6)], punctures.map(Math.fround));
  assert.equal(s.ties, 1);
  assert.equal(s.brokenSegment, 12);
  // The next delta without one has none (the pool's old thread is not shown again).
  const bare = decoder.decode(Envelope.encode({ meshDelta: { sequence: 4, baseSequence: 3 } }).finish());
  assert.equal(bare.meshDelta?.suture, null);
  // More nodes than a frame may carry (129): refused, as the server refuses it.
  const long = Envelope.encode({ meshDelta: { sequence: 5, baseSequence: 4,
    suture: { nodes: new Array(3 * 130).fill(0) } } }).finish();
  assert.throws(() => decoder.decode(long), /suture: more than 129 nodes/);
});
