// The browser's MeshMirror: applies MeshKeyframe and MeshDelta payloads exactly as protocol/'s
// C++ decoder does (protocol/src/mesh_codec.cc, mesh_mirror.cc): zigzag LEB128 varints, planar
// axes, zstd with declared sizes, gaps reported and never drawn. Pure (no DOM, no three.js);
// buffers grow only when a keyframe is larger than any before, so a delta allocates nothing here.
import { decompress } from 'fzstd';
import { inspectZstdFrame } from './zstd_frame.js';

/** @typedef {'ok' | 'gap' | 'invalid'} MirrorStatus */

/**
 * The fields of idms.v1.MeshKeyframe the decoder reads (protobufjs objects have them).
 * @typedef {{sequence: number, topologyVersion: number, timeS: number, quantStep: number,
 *   numVertices: number, numTriangles: number, compression: number, payload: Uint8Array}} KeyframeMsg
 */
/**
 * The fields of idms.v1.MeshDelta the decoder reads.
 * @typedef {{sequence: number, baseSequence: number, topologyVersion: number, timeS: number,
 *   numChanged: number, compression: number, payload: Uint8Array}} DeltaMsg
 */

export const COMPRESSION_NONE = 0;
export const COMPRESSION_ZSTD = 1;

/** Limits checked before anything is allocated (protocol's DecodeLimits defaults). */
export const kDefaultLimits = Object.freeze({
  maxVertices: 2 ** 22,
  maxTriangles: 2 ** 23,
  maxDecompressedBytes: 256 * 2 ** 20,
});

const kInt32Min = -(2 ** 31);
const kInt32Max = 2 ** 31 - 1;
const kMaxVarintBytes = 10;
const kTwo33 = 2 ** 33;

/** Reads zigzag LEB128 varints; the value lands in `v`, a failure's reason in `error`. */
class VarintReader {
  constructor() {
    /** @type {Uint8Array} */ this.data = new Uint8Array(0);
    this.p = 0;
    this.end = 0;
    this.v = 0;
    this.error = '';
  }
  /** @param {Uint8Array} data @param {number} size */
  reset(data, size) {
    this.data = data;
    this.p = 0;
    this.end = size;
    this.error = '';
  }
  /**
   * One signed value into this.v. Exact for |v| < 2^52; larger values fail every range check
   * the callers make, as they do in C++.
   * @returns {boolean}
   */
  read() {
    let u = 0;
    let mul = 1;
    for (let shift = 0; shift < 64; shift += 7) {
      if (this.p === this.end) {
        this.error = shift === 0 ? 'payload ends early' : 'truncated varint';
        return false;
      }
      const b = this.data[this.p++];
      // The 10th byte may only carry the top bit of a 64-bit value.
      if (shift === 63 && b > 1) {
        this.error = 'varint longer than 64 bits';
        return false;
      }
      u += (b & 0x7f) * mul;
      mul *= 128;
      if ((b & 0x80) === 0) {
        this.v = u % 2 === 0 ? u / 2 : -(u + 1) / 2;
        return true;
      }
    }
    this.error = 'varint longer than 64 bits';
    return false;
  }
}

/** A double as C++'s std::to_string prints it ("%f"), so that messages match protocol/'s. @param {number} x */
function cppDouble(x) {
  if (Number.isNaN(x)) return x < 0 ? '-nan' : 'nan';
  if (!Number.isFinite(x)) return x > 0 ? 'inf' : '-inf';
  return x.toFixed(6);
}

/** base + d when the result is an int32 (|d| < 2^33, as the C++ AddInt32), else NaN. */
function addInt32(/** @type {number} */ base, /** @type {number} */ d) {
  if (d <= -kTwo33 || d >= kTwo33) return NaN;
  const s = base + d;
  return s >= kInt32Min && s <= kInt32Max ? s : NaN;
}

/**
 * The first n bytes of `raw` as fzstd's output buffer. fzstd (0.1.1) tests the buffer it is given
 * with a loose `== 1` twice per frame, which converts a Uint8Array to the string of all its bytes:
 * measured in Node, 3.5 ms for a 40 kB buffer that takes 0.15 ms to decompress into. A view that
 * converts to NaN answers the test at once, and fzstd then writes into it as before.
 * @param {Uint8Array} raw @param {number} n
 */
export function outputView(raw, n) {
  const view = raw.subarray(0, n);
  Object.defineProperty(view, Symbol.toPrimitive, { value: notANumber });
  return view;
}

function notANumber() {
  return NaN;
}

export class MeshState {
  /** @param {typeof kDefaultLimits} [limits] */
  constructor(limits = kDefaultLimits) {
    this.limits = limits;
    this.hasKeyframe = false;
    this.sequence = 0;
    this.topologyVersion = 0;
    this.timeS = 0;
    this.quantStep = 1e-4;
    this.numVertices = 0;
    this.numTriangles = 0;
    /** Quantized positions (numVertices x 3), quanta. */
    this.q = new Int32Array(0);
    /** Positions (numVertices x 3), model units: q * quantStep as float32, as MeshMirror. */
    this.positions = new Float32Array(0);
    /** Surface triangles (numTriangles x 3), vertex ids. */
    this.triangles = new Uint32Array(0);
    /** The vertices the last delta moved (first numChanged entries), increasing. */
    this.changed = new Int32Array(0);
    this.numChanged = 0;
    /** Why the last apply returned 'gap' or 'invalid'. */
    this.error = '';
    // Scratch: a keyframe decodes here and is swapped in only when valid; a delta's new values too.
    this.scratchQ = new Int32Array(0);
    this.scratchTris = new Uint32Array(0);
    this.scratchValues = new Int32Array(0);
    this.raw = new Uint8Array(0);
    this.reader = new VarintReader();
  }

  /**
   * @param {{meshKeyframe?: KeyframeMsg | null, meshDelta?: DeltaMsg | null}} envelope
   * @returns {MirrorStatus}
   */
  apply(envelope) {
    if (envelope.meshKeyframe) return this.applyKeyframe(envelope.meshKeyframe);
    if (envelope.meshDelta) return this.applyDelta(envelope.meshDelta);
    this.error = 'not a mesh frame';
    return 'invalid';
  }

  /**
   * Replaces the surface with a keyframe's; on 'invalid' the state is unchanged.
   * @param {KeyframeMsg} msg
   * @returns {MirrorStatus}
   */
  applyKeyframe(msg) {
    const where = `keyframe ${msg.sequence}: `;
    // Header values first: nothing is allocated for counts beyond the limits.
    if (!(msg.quantStep > 0) || !Number.isFinite(msg.quantStep))
      return this.fail(where + `quant_step must be finite and > 0, got ${cppDouble(msg.quantStep)}`);
    const nv = msg.numVertices;
    const nt = msg.numTriangles;
    if (nv > this.limits.maxVertices)
      return this.fail(where + `${nv} vertices exceed the limit of ${this.limits.maxVertices}`);
    if (nt > this.limits.maxTriangles)
      return this.fail(where + `${nt} triangles exceed the limit of ${this.limits.maxTriangles}`);
    // The payload, no larger than its counts allow.
    const numValues = 3 * (nv + nt);
    const size = this.payload(msg, Math.min(this.limits.maxDecompressedBytes, kMaxVarintBytes * numValues));
    if (size < 0) return this.fail(where + this.error);
    if (size < numValues)
      return this.fail(where + `payload of ${size} bytes is too short for ${nv} vertices and ${nt} triangles`);
    // Positions (planar axes, each relative to the previous vertex), triangles, nothing after.
    if (this.scratchQ.length < 3 * nv) this.scratchQ = new Int32Array(3 * nv);
    if (this.scratchTris.length < 3 * nt) this.scratchTris = new Uint32Array(3 * nt);
    const r = this.reader;
    const q = this.scratchQ;
    for (let axis = 0; axis < 3; axis++) {
      let prev = 0;
      for (let i = 0; i < nv; i++) {
        if (!r.read()) return this.readFailed(where, `vertex ${i} axis ${axis}`);
        prev = addInt32(prev, r.v);
        if (Number.isNaN(prev)) return this.fail(where + `vertex ${i} axis ${axis} leaves the int32 range`);
        q[3 * i + axis] = prev;
      }
    }
    const tris = this.scratchTris;
    let prev = 0;
    for (let j = 0; j < 3 * nt; j++) {
      if (!r.read()) return this.readFailed(where, `triangle ${Math.floor(j / 3)}`);
      prev = addInt32(prev, r.v);
      if (Number.isNaN(prev) || prev < 0 || prev >= nv)
        return this.fail(where + `triangle ${Math.floor(j / 3)} has a vertex id outside [0, ${nv})`);
      tris[j] = prev;
    }
    if (r.p !== r.end)
      return this.fail(
        where + `${r.end - r.p} bytes left after ${nv} vertices and ${nt} triangles (counts disagree with the payload)`);
    // Valid: swap the scratch in, refresh the float positions.
    this.scratchQ = this.q;
    this.q = q;
    this.scratchTris = this.triangles;
    this.triangles = tris;
    if (this.positions.length < 3 * nv) this.positions = new Float32Array(3 * nv);
    if (this.changed.length < nv) this.changed = new Int32Array(nv);
    if (this.scratchValues.length < 3 * nv) this.scratchValues = new Int32Array(3 * nv);
    const step = msg.quantStep;
    for (let k = 0; k < 3 * nv; k++) this.positions[k] = q[k] * step;
    this.hasKeyframe = true;
    this.sequence = msg.sequence;
    this.topologyVersion = msg.topologyVersion;
    this.timeS = msg.timeS;
    this.quantStep = step;
    this.numVertices = nv;
    this.numTriangles = nt;
    this.numChanged = 0;
    this.error = '';
    return 'ok';
  }

  /**
   * Moves the vertices a delta lists; on 'gap' or 'invalid' the state is unchanged.
   * @param {DeltaMsg} msg
   * @returns {MirrorStatus}
   */
  applyDelta(msg) {
    const where = `delta ${msg.sequence}: `;
    // Sequencing: a delta applies only to the frame it was made against.
    if (!this.hasKeyframe) return this.gap(where + 'no keyframe received yet');
    if (msg.baseSequence !== this.sequence) {
      const ahead = msg.baseSequence > this.sequence;
      return this.gap(
        where + `base ${msg.baseSequence}` + (ahead ? ' is ahead of' : ' is behind') +
          ` the mirror's frame ${this.sequence}` + (ahead ? ' (frames lost)' : ' (stale or repeated)'));
    }
    if (msg.sequence <= msg.baseSequence) return this.fail(where + `sequence is not after its base ${msg.baseSequence}`);
    if (msg.topologyVersion !== this.topologyVersion)
      return this.fail(
        where + `topology version ${msg.topologyVersion} differs from the base frame's ${this.topologyVersion}`);
    // Counts: a delta lists at most every vertex, and nothing when it lists none.
    const nv = this.numVertices;
    const n = msg.numChanged;
    if (n > nv) return this.fail(where + `num_changed ${n} exceeds the ${nv} vertices`);
    if (n === 0) {
      if (msg.payload.length !== 0)
        return this.fail(where + `num_changed is 0 but the payload has ${msg.payload.length} bytes`);
      return this.commitDelta(msg, 0);
    }
    const size = this.payload(msg, Math.min(this.limits.maxDecompressedBytes, kMaxVarintBytes * (1 + 4 * n)));
    if (size < 0) return this.fail(where + this.error);
    // Count, ids (gaps >= 1 from -1), planar changes; new values into scratch, nothing after.
    const r = this.reader;
    if (!r.read()) return this.readFailed(where, 'count');
    if (r.v !== n) return this.fail(where + `payload lists ${r.v} vertices but num_changed is ${n}`);
    const ids = this.changed;
    let prev = -1;
    for (let k = 0; k < n; k++) {
      if (!r.read()) return this.readFailed(where, `id ${k}`);
      const gap = r.v;
      if (gap < 1) return this.fail(where + `ids not increasing at entry ${k} (gap ${gap})`);
      if (gap > nv - 1 - prev) return this.fail(where + `id at entry ${k} is beyond the ${nv} vertices`);
      prev += gap;
      ids[k] = prev;
    }
    const values = this.scratchValues;
    const q = this.q;
    for (let axis = 0; axis < 3; axis++) {
      for (let k = 0; k < n; k++) {
        const id = ids[k];
        if (!r.read()) return this.readFailed(where, `vertex ${id} axis ${axis}`);
        const v = addInt32(q[3 * id + axis], r.v);
        if (Number.isNaN(v)) return this.fail(where + `vertex ${id} axis ${axis} leaves the int32 range`);
        values[axis * n + k] = v;
      }
    }
    if (r.p !== r.end)
      return this.fail(where + `${r.end - r.p} bytes left after ${n} vertices (counts disagree with the payload)`);
    // All valid: apply, refresh the moved vertices' float positions.
    const step = this.quantStep;
    for (let axis = 0; axis < 3; axis++) {
      for (let k = 0; k < n; k++) {
        const i = 3 * ids[k] + axis;
        q[i] = values[axis * n + k];
        this.positions[i] = q[i] * step;
      }
    }
    return this.commitDelta(msg, n);
  }

  /** @param {DeltaMsg} msg @param {number} n @returns {MirrorStatus} */
  commitDelta(msg, n) {
    this.numChanged = n;
    this.sequence = msg.sequence;
    this.timeS = msg.timeS;
    this.error = '';
    return 'ok';
  }

  /**
   * Points the reader at the frame's raw payload (decompressed into this.raw when zstd); returns
   * its size, or -1 with this.error set.
   * @param {{compression: number, payload: Uint8Array}} msg
   * @param {number} maxBytes
   */
  payload(msg, maxBytes) {
    const payload = msg.payload;
    if (msg.compression === COMPRESSION_NONE) {
      if (payload.length > maxBytes) {
        this.error = `payload of ${payload.length} bytes exceeds the limit of ${maxBytes}`;
        return -1;
      }
      this.reader.reset(payload, payload.length);
      return payload.length;
    }
    if (msg.compression !== COMPRESSION_ZSTD) {
      this.error = `unknown compression ${msg.compression}`;
      return -1;
    }
    // The declared size decides the buffer: present, within the limit, exactly one frame.
    const frame = inspectZstdFrame(payload);
    if (frame.error) {
      this.error = frame.error;
      return -1;
    }
    if (frame.contentSize > maxBytes) {
      this.error = `zstd frame declares ${frame.contentSize} bytes, more than the limit of ${maxBytes}`;
      return -1;
    }
    if (frame.frameSize !== payload.length) {
      this.error = `${payload.length - frame.frameSize} bytes follow the zstd frame`;
      return -1;
    }
    if (this.raw.length < frame.contentSize) this.raw = new Uint8Array(Math.max(frame.contentSize, 2 * this.raw.length));
    try {
      decompress(payload, outputView(this.raw, frame.contentSize));
    } catch (e) {
      this.error = `zstd: ${e instanceof Error ? e.message : String(e)}`;
      return -1;
    }
    this.reader.reset(this.raw, frame.contentSize);
    return frame.contentSize;
  }

  /** @param {string} where @param {string} what @returns {MirrorStatus} */
  readFailed(where, what) {
    return this.fail(where + `${this.reader.error} at byte ${this.reader.p} (${what})`);
  }

  /** @param {string} message @returns {MirrorStatus} */
  fail(message) {
    this.error = message;
    return 'invalid';
  }

  /** @param {string} message @returns {MirrorStatus} */
  gap(message) {
    this.error = message;
    return 'gap';
  }
}
