// What /session and /replay draw from the stream: the tissue, tool and force in 3D, the 1 kHz
// force and position plots, force against depth, and the tool's state in words; all drawn in one
// frame loop (one composited frame per change). The bench (bench/web) drives this same class.
import { MeshState } from '../codec/mesh.js';
import { SurfaceView } from '../view/surface.js';
import { FrameLoop } from '../view/frame_loop.js';
import { RollingPlot } from '../plots/rolling.js';
import { DepthPlot } from '../plots/depth.js';
import { length3 } from '../length3.js';
import { display } from '../view/display.js';
import { Units, kModelUnits } from '../view/units.js';
import { parseObj } from '../codec/obj.js';
import { idms } from '../codec/proto.js';

/**
 * What the view has seen (a part of the page's state object, window.__idms).
 * @typedef {{frames: number, keyframes: number, deltas: number, gaps: number, invalid: number,
 *   samples: number, renders: number, timeS: number, warnings: number, lastError: string, lastInvalid: string,
 *   movedVertices: number, peakForce: number, contactSamples: number, forceLimited: boolean, forceLimitHits: number,
 *   friction?: string, portEnergy?: number, passivityDamping?: number}} ViewState  friction: 'stick' | 'slip' | ''
 *   at the last sample; portEnergy, passivityDamping: the passivity controller's at the last sample (0 when off)
 */

/**
 * Where the view draws: elements the page has laid out.
 * @typedef {{view: HTMLElement, force: HTMLElement, position: HTMLElement, depth: HTMLElement,
 *   toolState: HTMLElement, gapNote: HTMLElement, forceLimit: HTMLElement, contact?: HTMLElement}} ViewHosts
 *   contact: where friction's normal and tangential force go (hidden until the scene has friction)
 */

/** The time plots' titles, units and series (the bench's standing panel draws the same). */
export const kForcePlot = { title: 'Device force', unit: display.unit.force, axis: 'force', series: [
  { label: 'Fx', color: '#c0392b' }, { label: 'Fy', color: '#27ae60' }, { label: 'Fz', color: '#2471a3' }, { label: '|F|', color: '#222' }] };
export const kPositionPlot = { title: 'Tool position', unit: display.unit.length, axis: 'position', series: [
  { label: 'x', color: '#c0392b' }, { label: 'y', color: '#27ae60' }, { label: 'z', color: '#2471a3' }] };

/**
 * The tool's state in words, for beside the 3D view (colour alone is not enough); with friction,
 * whether the contact sticks or slips.
 * @param {{contact?: boolean | null, grasp?: boolean | null, friction?: number | null}} sample the last one
 */
export function toolWords(sample) {
  const held = sample.friction === 1 ? ', sticking' : sample.friction === 2 ? ', slipping' : '';
  return sample.grasp ? `tool: grasping${held}` : sample.contact ? `tool: in contact${held}` : 'tool: free';
}

/**
 * A generated decoder's SutureShape (a keyframe's) as SurfaceView.setSuture takes it; null
 * without a thread.
 * @param {idms.v1.ISutureShape | null | undefined} shape
 */
export function sutureOf(shape) {
  if (!shape || !shape.nodes || shape.nodes.length < 6) return null;
  return { nodes: shape.nodes, numNodes: Math.floor(shape.nodes.length / 3), punctures: shape.punctures ?? [],
    numPunctures: Math.floor((shape.punctures?.length ?? 0) / 3), ties: shape.ties ?? 0, brokenSegment: shape.brokenSegment ?? 0 };
}

/**
 * A needle's shaft length (its scene's Needle.length, protocol/idms.proto's default 10 when not
 * given), model units; 0 for a tool that is not a needle (no shaft drawn).
 * @param {idms.v1.ITool | null | undefined} tool the scene's first
 */
export function needleLength(tool) {
  if (tool?.kind !== idms.v1.Tool.Kind.KIND_NEEDLE) return 0;
  return tool.needle?.length ?? 10;
}

/** Friction's plot: the contact's normal force and the tangential (friction) force's magnitude. */
export const kContactPlot = { title: 'Contact force', unit: display.unit.force, axis: 'force', series: [
  { label: 'normal f_n', color: '#2471a3' }, { label: 'tangential |f_t|', color: '#b5179e' }] };

export class LiveView {
  /**
   * @param {ViewState} st counted into
   * @param {ViewHosts} hosts already in the document (the plots take their width from them)
   * @param {number} windowS seconds the time plots keep at 1 kHz
   * @param {FrameLoop} [loop] the page's frame loop, when other parts draw in it too
   */
  constructor(st, hosts, windowS, loop = new FrameLoop()) {
    this.st = st;
    this.hosts = hosts;
    this.loop = loop;
    this.mirror = new MeshState();
    this.view = new SurfaceView(hosts.view, this.loop);
    this.view.onRender = () => st.renders++;
    const capacity = windowS * 1000;
    this.capacity = capacity;
    /** Normal and tangential force, once the scene says its tools have friction. @type {RollingPlot | null} */
    this.contactPlot = null;
    this.forcePlot = new RollingPlot(hosts.force, { ...kForcePlot, capacity }, this.loop);
    this.posPlot = new RollingPlot(hosts.position, { ...kPositionPlot, capacity }, this.loop);
    this.depthPlot = new DepthPlot(hosts.depth, capacity, this.loop, { force: display.unit.force, length: display.unit.length });
    this.shownToolState = '';
    /** Force-limit hits from before the page's samples (the record's count when it came); -1 until then. */
    this.limitBase = -1;
    /** Hits seen in the samples since limitBase was set. */
    this.limitSeen = 0;
    /**
     * Whether the samples' hits add to the count: live, yes; a replay's samples come again after
     * each seek, so it shows the recording's count (setForceLimitHits).
     */
    this.countLimitHits = true;
    this.shownLimit = '';
    /** The session's units (its scene's, from the Welcome): the plots convert into them. */
    this.units = kModelUnits;
    this.ls = 1;
    this.fs = 1;
    /** @type {idms.v1.ITool[]} the scene's tools; the device holds one (DeviceSample.toolIndex) */
    this.tools = [];
    this.heldTool = -1;
  }

  /**
   * The scene's tools (from its welcome): the view draws the one the device holds, the first
   * until a sample says another (scripted:suture: the scalpel, then the needle).
   * @param {idms.v1.ITool[]} tools
   */
  setSceneTools(tools) {
    this.tools = tools;
    this.heldTool = -1;
    this.holdTool(0);
  }

  /** @param {number} index the scene tool the device holds */
  holdTool(index) {
    if (index === this.heldTool) return;
    this.heldTool = index;
    const tool = this.tools[index];
    this.view.setToolRadius(tool?.radius ?? 1.5);
    this.view.setNeedle(needleLength(tool));
  }

  /**
   * The session's units, from its scene (sent before any sample): the plots and the legend say
   * and show them from here on. @param {Units} units
   */
  setUnits(units) {
    if (units.equals(this.units)) return;
    this.units = units;
    this.ls = units.lengthScale;
    this.fs = units.forceScale;
    this.forcePlot.setTitle(kForcePlot.title, units.force);
    this.posPlot.setTitle(kPositionPlot.title, units.length);
    this.depthPlot.units = { force: units.force, length: units.length };
    this.contactPlot?.setTitle(kContactPlot.title, units.force);
    this.depthPlot.invalidate();
    this.view.setUnits(units);
  }

  /**
   * The session's hits so far when the page asked (its summary): the indicator counts on from it.
   * @param {number} hits
   */
  setForceLimitHits(hits) {
    this.limitBase = hits;
    this.limitSeen = 0;
    this.showForceLimit();
  }

  /** The indicator: lit while the device force is at its limit, with the session's hits. */
  showForceLimit() {
    const st = this.st;
    st.forceLimitHits = Math.max(0, this.limitBase) + this.limitSeen;
    const hits = this.limitBase < 0 && this.limitSeen === 0 ? ''
      : ` · ${st.forceLimitHits} ${st.forceLimitHits === 1 ? 'hit' : 'hits'}${this.countLimitHits ? '' : ' in the recording'}`;
    const text = (st.forceLimited ? 'AT FORCE LIMIT' : 'Force limit: not reached') + hits;
    if (text === this.shownLimit) return;
    this.shownLimit = text;
    this.hosts.forceLimit.textContent = text;
    this.hosts.forceLimit.classList.toggle('lit', st.forceLimited);
  }

  /** @param {any} msg a MeshKeyframe */
  applyKeyframe(msg) {
    this.onMesh(this.mirror.applyKeyframe(msg), true);
    this.view.setSuture(sutureOf(msg.suture));
  }

  /** @param {any} msg a MeshDelta (the frame decoder's: its suture already unpacked) */
  applyDelta(msg) {
    this.onMesh(this.mirror.applyDelta(msg), false);
    this.view.setSuture(msg.suture?.numNodes !== undefined ? msg.suture : sutureOf(msg.suture));
  }

  /** @param {'ok' | 'gap' | 'invalid'} status @param {boolean} keyframe */
  onMesh(status, keyframe) {
    const st = this.st;
    st.frames++;
    if (status === 'ok') {
      if (keyframe) {
        st.keyframes++;
        this.view.setSurface(this.mirror, this.mirror.timeS);
        this.hosts.gapNote.textContent = '';
      } else {
        st.deltas++;
        st.movedVertices += this.mirror.numChanged;
        this.view.applyMoved(this.mirror);
      }
      return;
    }
    // Never drawn: the surface stays at the last frame applied until a keyframe comes.
    if (status === 'gap') st.gaps++;
    else {
      st.invalid++;
      st.lastInvalid = this.mirror.error;
    }
    st.lastError = this.mirror.error;
    this.hosts.gapNote.textContent = `${status === 'gap' ? 'Frames lost' : 'Bad frame'}: ${this.mirror.error}. Waiting for a keyframe.`;
  }

  /**
   * A batch of device samples (1 kHz): into the plots; the last one moves the tool and the arrow.
   * Allocates nothing.
   * @param {{timeS?: number | null, force?: {x?: number | null, y?: number | null, z?: number | null} | null,
   *   toolPos?: {x?: number | null, y?: number | null, z?: number | null} | null, contact?: boolean | null,
   *   grasp?: boolean | null, warnings?: number | null, forceLimited?: boolean | null,
   *   frictionForce?: {x?: number | null, y?: number | null, z?: number | null} | null, normalForce?: number | null,
   *   friction?: number | null, portEnergy?: number | null, passivityDamping?: number | null,
   *   toolOrientation?: {w?: number | null, x?: number | null, y?: number | null, z?: number | null} | null,
   *   needlePunctured?: boolean | null, toolIndex?: number | null}[]} samples
   * @param {number} [count] the batch's samples are samples[0, count) (FrameDecoder's pool)
   */
  onSamples(samples, count = samples.length) {
    const st = this.st;
    for (let i = 0; i < count; i++) {
      const s = samples[i];
      const f = s.force, p = s.toolPos;
      const fx = f?.x || 0, fy = f?.y || 0, fz = f?.z || 0;
      const px = p?.x || 0, py = p?.y || 0, pz = p?.z || 0;
      const t = s.timeS || 0;
      const f2 = length3(fx, fy, fz);
      const fs = this.fs, ls = this.ls;  // into the session's units (1: model units)
      this.forcePlot.push(t, fx * fs, fy * fs, fz * fs, f2 * fs);
      if (f2 > st.peakForce) st.peakForce = f2;
      if (s.contact) st.contactSamples++;
      this.posPlot.push(t, px * ls, py * ls, pz * ls);
      this.depthPlot.push(px * ls, py * ls, pz * ls, fx * fs, fy * fs, fz * fs, !!s.contact);
      if (this.contactPlot) {
        const t3 = s.frictionForce;
        this.contactPlot.push(t, (s.normalForce || 0) * fs, length3(t3?.x || 0, t3?.y || 0, t3?.z || 0) * fs);
      }
      st.warnings += s.warnings || 0;
      // A hit: the force comes to the limit (the server's summary counts the same way).
      const limited = !!s.forceLimited;
      if (limited && !st.forceLimited && this.countLimitHits) this.limitSeen++;
      st.forceLimited = limited;
    }
    st.samples += count;
    if (count === 0) return;
    this.showForceLimit();
    const last = samples[count - 1];
    const f = last.force, p = last.toolPos;
    const friction = last.friction || 0;  // idms.v1.FrictionState: 1 stick, 2 slip
    this.holdTool(last.toolIndex || 0);
    this.view.setNeedlePose(last.toolOrientation, !!last.needlePunctured);
    this.view.setTool(p?.x || 0, p?.y || 0, p?.z || 0, f?.x || 0, f?.y || 0, f?.z || 0, !!last.contact, !!last.grasp, friction === 2);
    // The tool's state in words (colour alone is not enough), written only when it changes.
    const words = toolWords(last);
    st.friction = friction === 1 ? 'stick' : friction === 2 ? 'slip' : '';
    if (words !== this.shownToolState) this.hosts.toolState.textContent = this.shownToolState = words;
    st.portEnergy = last.portEnergy || 0;
    st.passivityDamping = last.passivityDamping || 0;
    st.timeS = last.timeS || 0;
  }

  /**
   * The session's tools have friction (its scene, from the Welcome): the normal and tangential
   * force get their own plot under the force's, in its host (shown from here on).
   */
  showContactForces() {
    if (this.contactPlot || !this.hosts.contact) return;
    this.hosts.contact.hidden = false;
    this.contactPlot = new RollingPlot(this.hosts.contact, { ...kContactPlot, unit: this.units.force, capacity: this.capacity }, this.loop);
  }

  /** Forgets the plots' samples (a seek in a replay). */
  clearPlots() {
    this.st.forceLimited = false;
    this.contactPlot?.clear();
    this.forcePlot.clear();
    this.posPlot.clear();
    this.depthPlot.clear();
  }

  dispose() {
    this.contactPlot?.dispose();
    this.view.dispose();
    this.forcePlot.dispose();
    this.posPlot.dispose();
    this.depthPlot.dispose();
  }
}

/**
 * The displacement's rest: the library model the scene names ("NAME" or "NAME@VERSION") at rest,
 * its positions on the session's quantisation grid as its first keyframe had them; without it
 * (a model from a file, a library that lost it) rest is the first surface the page gets, which in
 * a replay opened or a live session joined after the start is not the model at rest (the legend
 * then says from when).
 * @param {SurfaceView} view @param {string} model @param {number} quantStep
 */
export function loadModelRest(view, model, quantStep) {
  const [name, version] = model.split('@');
  const query = version ? `?version=${encodeURIComponent(version)}` : '';
  fetch(`/api/models/${encodeURIComponent(name)}/obj${query}`, { credentials: 'same-origin' })
    .then((res) => (res.ok ? res.text() : Promise.reject(new Error(`HTTP ${res.status}`))))
    .then((text) => {
      // Quantised as protocol/'s encoder does (half away from zero), dequantised as its mirror.
      const rest = parseObj(text).positions, inv = 1 / quantStep;
      for (let i = 0; i < rest.length; i++) {
        const v = rest[i] * inv;
        rest[i] = Math.trunc(v + (v >= 0 ? 0.5 : -0.5)) * quantStep;
      }
      view.setModelRest(rest);
    })
    .catch(() => {});  // rest stays the first surface
}
