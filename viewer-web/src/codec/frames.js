// The two messages a session streams every frame, DeviceSamples (about 17 ticks each) and
// MeshDelta, at 60 Hz, decoded into objects this decoder owns and reuses, through protobufjs's
// Reader, reading the fields the viewer uses; the generated decoder made about 55 objects a
// frame for the samples alone. Every other message goes through the generated decoder (they come
// a few times a session). Pure: no DOM.
import $protobuf from 'protobufjs/minimal.js';
import { idms } from './proto.js';

/** A 3-vector as the viewer reads it. @typedef {{x: number, y: number, z: number}} Vec3 */
/** A quaternion as the viewer reads it. @typedef {{w: number, x: number, y: number, z: number}} Quat */

/**
 * One tick, as idms.v1.DeviceSample's fields the viewer reads (unset fields read 0 / false).
 * @typedef {{timeS: number, toolPos: Vec3, force: Vec3, contact: boolean, grasp: boolean, warnings: number,
 *   forceLimited: boolean, frictionForce: Vec3, normalForce: number, friction: number, portEnergy: number,
 *   portEnergyWindow: number, passivityDamping: number, toolOrientation: Quat, needlePunctured: boolean,
 *   needleInserted: number, toolIndex: number}} Sample
 *   friction: idms.v1.FrictionState (0 none, 1 stick, 2 slip); portEnergy, portEnergyWindow, passivityDamping: the
 *   passivity controller's (0 when off); toolOrientation: the identity when unset (as the protocol says), its
 *   fields 0 when unset inside a set one
 */

/**
 * idms.v1.LoopStats's fields the viewer reads.
 * @typedef {{ticks: number, overruns: number, periodP99Us: number, computeP99Us: number, realtime: boolean,
 *   passivityTicks: number, passivityDissipated: number}} Stats
 */

/**
 * A batch of ticks: samples[0, count) are this batch's (the array is a pool, longer when an
 * earlier batch was); stats is null when the batch carried none.
 * @typedef {{samples: Sample[], count: number, stats: Stats | null, samplesDropped: number}} SampleBatch
 */

/**
 * idms.v1.MeshDelta's fields, as MeshState.applyDelta reads them.
 * @typedef {import('./mesh.js').DeltaMsg} Delta
 */

/**
 * A needle's suture thread as a mesh frame carries it (idms.v1.SutureShape): nodes[0, 3 numNodes)
 * and punctures[0, 3 numPunctures), x y z each.
 * @typedef {{nodes: Float32Array, numNodes: number, punctures: Float32Array, numPunctures: number, ties: number,
 *   brokenSegment: number}} Suture
 */

/**
 * A decoded frame: exactly one of its fields is set. The per-frame ones (meshDelta,
 * deviceSamples) are this decoder's and valid until its next decode; the others are the
 * generated decoder's messages.
 * @typedef {{meshDelta?: Delta | null, deviceSamples?: SampleBatch | null, meshKeyframe?: idms.v1.IMeshKeyframe | null,
 *   sessionEvent?: idms.v1.ISessionEvent | null, annotation?: idms.v1.IAnnotation | null,
 *   playbackState?: idms.v1.IPlaybackState | null, welcome?: idms.v1.IWelcome | null}} Frame
 */

const kEnvelopeDeviceSamples = 3;
const kEnvelopeMeshDelta = 5;
const kEnvelopeFrames = 13;
const kWireVarint = 0;
const kWireFixed64 = 1;
const kWireLength = 2;

/** @returns {Sample} */
const newSample = () => ({ timeS: 0, toolPos: { x: 0, y: 0, z: 0 }, force: { x: 0, y: 0, z: 0 }, contact: false, grasp: false, warnings: 0,
  forceLimited: false, frictionForce: { x: 0, y: 0, z: 0 }, normalForce: 0, friction: 0,
  portEnergy: 0, portEnergyWindow: 0, passivityDamping: 0, toolOrientation: { w: 1, x: 0, y: 0, z: 0 },
  needlePunctured: false, needleInserted: 0, toolIndex: 0 });

export class FrameDecoder {
  constructor() {
    this.reader = new $protobuf.Reader(new Uint8Array(0));
    this.outer = new $protobuf.Reader(new Uint8Array(0));  // a Frames message's envelopes
    /** @type {SampleBatch} */
    this.batch = { samples: [], count: 0, stats: null, samplesDropped: 0 };
    /** @type {Stats} */
    this.stats = { ticks: 0, overruns: 0, periodP99Us: 0, computeP99Us: 0, realtime: false, passivityTicks: 0,
      passivityDissipated: 0 };
    /** @type {Delta} */
    /** @type {Suture} the delta's thread, when it carries one (pooled: at most 129 nodes, 16 punctures) */
    this.suture = { nodes: new Float32Array(3 * 129), numNodes: 0, punctures: new Float32Array(3 * 16), numPunctures: 0,
      ties: 0, brokenSegment: 0 };
    /** @type {Delta & {suture: Suture | null}} */
    this.delta = { sequence: 0, baseSequence: 0, topologyVersion: 0, timeS: 0, numChanged: 0, compression: 0,
      payload: new Uint8Array(0), suture: null };
    /** @type {Frame} */
    this.samplesFrame = { deviceSamples: this.batch };
    /** @type {Frame} */
    this.deltaFrame = { meshDelta: this.delta };
  }

  /**
   * Every Envelope of one WebSocket message, in order, to `handle`: the message itself, or each
   * of its Frames (a live session's viewers get sample batches gathered with the next mesh frame
   * into one message). Each decoded frame is valid until `handle` returns.
   * @param {Uint8Array} bytes @param {(frame: Frame) => void} handle
   */
  each(bytes, handle) {
    const outer = this.outer;
    outer.buf = bytes;
    outer.pos = 0;
    outer.len = bytes.length;
    if (outer.len > 0 && outer.uint32() === ((kEnvelopeFrames << 3) | kWireLength)) {
      const end = outer.uint32() + outer.pos;
      if (end > outer.len) throw RangeError(`index out of range: ${end} > ${outer.len}`);
      while (outer.pos < end) {
        const tag = outer.uint32();
        if (tag !== ((1 << 3) | kWireLength)) {
          outer.skipType(tag & 7);
          continue;
        }
        const length = outer.uint32();
        const start = outer.pos;
        outer.skip(length);
        handle(this.decode(bytes.subarray(start, start + length)));
      }
      return;
    }
    handle(this.decode(bytes));
  }

  /**
   * One Envelope. Allocates nothing for DeviceSamples (once the pool holds a batch's ticks); a
   * MeshDelta's payload is a view into `bytes` (one small object). Throws as the generated
   * decoder does on malformed input.
   * @param {Uint8Array} bytes
   * @returns {Frame}
   */
  decode(bytes) {
    const r = this.reader;
    r.buf = bytes;
    r.pos = 0;
    r.len = bytes.length;
    // The fast path: an Envelope that is one length-delimited DeviceSamples or MeshDelta.
    if (r.len > 0) {
      const tag = r.uint32();
      const field = tag >>> 3;
      if ((tag & 7) === kWireLength && (field === kEnvelopeDeviceSamples || field === kEnvelopeMeshDelta)) {
        const end = r.uint32() + r.pos;
        if (end === r.len) {
          if (field === kEnvelopeDeviceSamples) {
            this.readSamples(end);
            return this.samplesFrame;
          }
          this.readDelta(end);
          return this.deltaFrame;
        }
      }
    }
    const env = idms.v1.Envelope.decode(bytes);
    // A per-frame message laid out otherwise (fields beside the body that this viewer does not
    // know): the body alone, through the fast path.
    if (env.deviceSamples) return this.decode(idms.v1.Envelope.encode({ deviceSamples: env.deviceSamples }).finish());
    if (env.meshDelta) return this.decode(idms.v1.Envelope.encode({ meshDelta: env.meshDelta }).finish());
    return /** @type {Frame} */ (/** @type {unknown} */ (env));
  }

  /** DeviceSamples up to `end`. @param {number} end */
  readSamples(end) {
    const r = this.reader;
    const b = this.batch;
    b.count = 0;
    b.stats = null;
    b.samplesDropped = 0;
    while (r.pos < end) {
      const tag = r.uint32();
      switch (tag >>> 3) {
        case 1: {
          if (b.count === b.samples.length) b.samples.push(newSample());
          this.readSample(b.samples[b.count++], r.uint32() + r.pos);
          break;
        }
        case 2:
          this.readStats(r.uint32() + r.pos);
          b.stats = this.stats;
          break;
        case 3:
          b.samplesDropped = uint64(r);
          break;
        default:
          r.skipType(tag & 7);
      }
    }
    checkEnd(r, end);
  }

  /** @param {Sample} s @param {number} end */
  readSample(s, end) {
    const r = this.reader;
    s.timeS = 0;
    s.contact = false;
    s.grasp = false;
    s.warnings = 0;
    s.forceLimited = false;
    s.normalForce = 0;
    s.friction = 0;
    s.portEnergy = 0;
    s.portEnergyWindow = 0;
    s.passivityDamping = 0;
    s.needlePunctured = false;
    s.needleInserted = 0;
    s.toolIndex = 0;
    const q = s.toolOrientation;
    q.w = 1;
    q.x = q.y = q.z = 0;
    zero(s.toolPos);
    zero(s.force);
    zero(s.frictionForce);
    while (r.pos < end) {
      const tag = r.uint32();
      switch (tag >>> 3) {
        case 2: s.timeS = r.double(); break;
        case 3: this.readVec3(s.toolPos, r.uint32() + r.pos); break;
        case 4: this.readVec3(s.force, r.uint32() + r.pos); break;
        case 7: s.contact = r.bool(); break;
        case 8: s.grasp = r.bool(); break;
        case 10: s.warnings = r.uint32(); break;
        case 12: s.forceLimited = r.bool(); break;
        case 13: this.readVec3(s.frictionForce, r.uint32() + r.pos); break;
        case 14: s.normalForce = r.double(); break;
        case 15: s.friction = r.int32(); break;
        case 16: s.portEnergy = r.double(); break;
        case 17: s.portEnergyWindow = r.double(); break;
        case 18: s.passivityDamping = r.double(); break;
        case 19: this.readQuat(q, r.uint32() + r.pos); break;
        case 20: s.needlePunctured = r.bool(); break;
        case 21: s.needleInserted = r.double(); break;
        case 23: s.toolIndex = r.uint32(); break;
        default: r.skipType(tag & 7);
      }
    }
    checkEnd(r, end);
  }

  /** @param {Vec3} v @param {number} end */
  readVec3(v, end) {
    const r = this.reader;
    while (r.pos < end) {
      const tag = r.uint32();
      const f = tag >>> 3;
      if ((tag & 7) === kWireFixed64 && f >= 1 && f <= 3) {
        const d = r.double();
        if (f === 1) v.x = d;
        else if (f === 2) v.y = d;
        else v.z = d;
      } else r.skipType(tag & 7);
    }
    checkEnd(r, end);
  }

  /** Set: its fields 0 until read (proto3 leaves zeros out). @param {Quat} q @param {number} end */
  readQuat(q, end) {
    const r = this.reader;
    q.w = q.x = q.y = q.z = 0;
    while (r.pos < end) {
      const tag = r.uint32();
      const f = tag >>> 3;
      if ((tag & 7) === kWireFixed64 && f >= 1 && f <= 4) {
        const d = r.double();
        if (f === 1) q.w = d;
        else if (f === 2) q.x = d;
        else if (f === 3) q.y = d;
        else q.z = d;
      } else r.skipType(tag & 7);
    }
    checkEnd(r, end);
  }

  /** @param {number} end */
  readStats(end) {
    const r = this.reader;
    const s = this.stats;
    s.ticks = 0;
    s.overruns = 0;
    s.periodP99Us = 0;
    s.computeP99Us = 0;
    s.realtime = false;
    s.passivityTicks = 0;
    s.passivityDissipated = 0;
    while (r.pos < end) {
      const tag = r.uint32();
      switch (tag >>> 3) {
        case 1: s.ticks = uint64(r); break;
        case 2: s.overruns = uint64(r); break;
        case 4: s.periodP99Us = r.uint32(); break;
        case 8: s.computeP99Us = r.uint32(); break;
        case 10: s.realtime = r.bool(); break;
        case 11: s.passivityTicks = uint64(r); break;
        case 12: s.passivityDissipated = r.double(); break;
        default: r.skipType(tag & 7);
      }
    }
    checkEnd(r, end);
  }

  /** MeshDelta up to `end`. @param {number} end */
  readDelta(end) {
    const r = this.reader;
    const d = this.delta;
    d.sequence = 0;
    d.baseSequence = 0;
    d.topologyVersion = 0;
    d.timeS = 0;
    d.numChanged = 0;
    d.compression = 0;
    d.suture = null;
    let payloadAt = 0, payloadEnd = 0;
    while (r.pos < end) {
      const tag = r.uint32();
      switch (tag >>> 3) {
        case 1: d.sequence = uint64(r); break;
        case 2: d.baseSequence = uint64(r); break;
        case 3: d.topologyVersion = uint64(r); break;
        case 4: d.timeS = r.double(); break;
        case 5: d.numChanged = r.uint32(); break;
        case 6: d.compression = r.int32(); break;
        case 7: {
          payloadEnd = r.uint32() + r.pos;
          payloadAt = r.pos;
          if (payloadEnd > end) throw RangeError(`index out of range: ${payloadEnd} > ${end}`);
          r.pos = payloadEnd;
          break;
        }
        case 8:
          this.readSuture(r.uint32() + r.pos);
          d.suture = this.suture;
          break;
        default: r.skipType(tag & 7);
      }
    }
    checkEnd(r, end);
    d.payload = r.buf.subarray(payloadAt, payloadEnd);
  }

  /**
   * SutureShape up to `end` into the pool: its packed floats (a list longer than the pool's is
   * refused, as the server refuses it). @param {number} end
   */
  readSuture(end) {
    const r = this.reader;
    const u = this.suture;
    u.numNodes = u.numPunctures = u.ties = u.brokenSegment = 0;
    let nodes = 0, punctures = 0;
    while (r.pos < end) {
      const tag = r.uint32();
      const f = tag >>> 3;
      if ((f === 1 || f === 2) && (tag & 7) === kWireLength) {
        const listEnd = r.uint32() + r.pos;
        if (listEnd > end) throw RangeError(`index out of range: ${listEnd} > ${end}`);
        const into = f === 1 ? u.nodes : u.punctures;
        let count = f === 1 ? nodes : punctures;
        while (r.pos < listEnd) {
          if (count === into.length) throw RangeError(`suture: more than ${into.length / 3} ${f === 1 ? 'nodes' : 'punctures'}`);
          into[count++] = r.float();
        }
        if (f === 1) nodes = count;
        else punctures = count;
      } else if (f === 3 && (tag & 7) === kWireVarint) {
        u.ties = r.uint32();
      } else if (f === 4 && (tag & 7) === kWireVarint) {
        u.brokenSegment = r.int32();
      } else r.skipType(tag & 7);
    }
    checkEnd(r, end);
    u.numNodes = Math.floor(nodes / 3);
    u.numPunctures = Math.floor(punctures / 3);
  }
}

/** @param {Vec3} v */
function zero(v) {
  v.x = 0;
  v.y = 0;
  v.z = 0;
}

/**
 * A uint64 varint as a number (exact below 2^53: ticks, sequences and counts stay far below),
 * without the LongBits object protobufjs's uint64() makes.
 * @param {$protobuf.Reader} r
 */
function uint64(r) {
  let v = 0;
  let mul = 1;
  for (let i = 0; i < 10; i++) {
    if (r.pos >= r.len) throw RangeError(`index out of range: ${r.pos} + 1 > ${r.len}`);
    const b = r.buf[r.pos++];
    v += (b & 0x7f) * mul;
    if (b < 0x80) return v;
    mul *= 128;
  }
  throw Error('invalid varint encoding');
}

/** A sub-message must end where its length said. @param {$protobuf.Reader} r @param {number} end */
function checkEnd(r, end) {
  if (r.pos !== end || end > r.len) throw RangeError(`index out of range: ${r.pos} != ${end} (length ${r.len})`);
}
