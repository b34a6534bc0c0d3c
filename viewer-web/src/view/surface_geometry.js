// The tissue's surface as one three.js BufferGeometry updated in place: a keyframe sets it whole
// (or, with the triangles already shown, as the vertices that moved), a delta moves vertices, and
// once per frame drawn the normals around every vertex moved since the last frame are recomputed
// and only the spans that changed are uploaded, as update ranges. Each vertex also carries its
// colour-map value (display.json: its displacement from rest over the model's fixed range, or its
// stiffness), and is drawn at rest + scale (p - rest) (the deformation scale). Nothing is
// allocated per frame once the first keyframe is set. No renderer, canvas or camera: SurfaceView
// draws it, and the tests build it in Node.
import * as THREE from 'three';
import { length3 } from '../length3.js';
import { colourIndex, displacementRange } from './display.js';

/** @typedef {'displacement' | 'stiffness' | 'plain'} ColourBy */

export class SurfaceGeometry {
  constructor() {
    // Buffers sized at a keyframe, reused while the surface does not grow (allocate makes a new
    // geometry when it does: its holder takes it up after setSurface).
    this.geometry = new THREE.BufferGeometry();
    this.capacityV = 0;
    this.capacityT = 0;
    this.numVertices = 0;
    this.numTriangles = 0;
    /** @type {THREE.BufferAttribute | null} */ this.posAttr = null;
    /** @type {THREE.BufferAttribute | null} */ this.normAttr = null;
    /** Each vertex's colour-map entry / 255 (the material's `value`). @type {THREE.BufferAttribute | null} */
    this.valueAttr = null;
    // The true positions (the drawn ones are exaggerated when scale != 1), rest, and what colours.
    this.actual = new Float32Array(0);
    this.rest = new Float32Array(0);
    /** Vertices rest holds (display.json: the first surface, or the first of a new size). */
    this.restVertices = -1;
    /** Session time of rest, s. */
    this.restTimeS = 0;
    /** The model at rest from elsewhere (the library), for a surface of its size. @type {Float32Array | null} */
    this.modelRest = null;
    this.scale = 1;
    /** @type {ColourBy} */
    this.colourBy = 'displacement';
    /** Per vertex, for colourBy 'stiffness'. @type {Float64Array | null} */
    this.stiffness = null;
    /** The range the map spans. */
    this.lo = 0;
    this.hi = 1;
    // The buffers go whole with the next render (new triangles): until then no update range is
    // set (three.js uploads only the ranges when there are any).
    this.wholePending = false;
    // Vertex -> triangles (CSR), face normals, and stamps that collect the triangles and
    // vertices around the moved ones without clearing anything.
    this.adjStart = new Int32Array(1);
    this.adjTris = new Int32Array(0);
    this.faceNormals = new Float32Array(0);
    this.triStamp = new Uint32Array(0);
    this.vertStamp = new Uint32Array(0);
    this.touchedTris = new Int32Array(0);
    this.touchedVerts = new Int32Array(0);
    this.keyframeMoved = new Int32Array(0);
    /** @type {{positions: Float32Array, changed: Int32Array, numChanged: number}} */
    this.keyframeDelta = { positions: new Float32Array(0), changed: this.keyframeMoved, numChanged: 0 };
    this.stamp = 1;
    // Moved since the last frame drawn: the triangles around them (stamped with this.stamp) and
    // the span of their ids; their normals are recomputed when the frame is drawn.
    this.numTouchedTris = 0;
    this.movedLo = 0;
    this.movedHi = -1;
    /** Time spent on normals, ms (the bench counts it as the page's work). */
    this.normalsMs = 0;
  }

  /**
   * A whole surface (a keyframe): positions, triangles, adjacency, every normal. The same
   * triangles again (the stream's periodic keyframe, every few seconds of a session) are taken as
   * a delta of the vertices that moved: nothing rebuilt, nothing uploaded but what moved.
   * @param {{numVertices: number, numTriangles: number, positions: Float32Array, triangles: Uint32Array}} s
   * @param {number} [timeS] the surface's session time (rest's, when it becomes rest)
   * @returns {boolean} whether it was rebuilt whole (new triangles), not taken as moved vertices
   */
  setSurface(s, timeS = 0) {
    const nv = s.numVertices;
    const nt = s.numTriangles;
    if (nt > 0 && nv === this.numVertices && nt === this.numTriangles && this.sameTriangles(s.triangles)) {
      this.applyMoved(this.movedSince(s.positions));
      return false;
    }
    if (nv > this.capacityV || nt > this.capacityT) this.allocate(Math.max(nv, this.capacityV), Math.max(nt, this.capacityT));
    this.actual.set(s.positions.subarray(0, 3 * nv));
    const index = /** @type {THREE.BufferAttribute} */ (this.geometry.index);
    /** @type {Uint32Array} */ (index.array).set(s.triangles.subarray(0, 3 * nt));
    this.numVertices = nv;
    this.numTriangles = nt;
    this.buildAdjacency(s.triangles, nv, nt);
    // Rest: the model's at rest when known and of this size; else the first surface, or the first
    // of a new size (a cut that exposed atoms).
    if (this.restVertices !== nv) {
      const model = this.modelRest && this.modelRest.length === 3 * nv ? this.modelRest : null;
      this.rest.set(model ?? s.positions.subarray(0, 3 * nv));
      this.restVertices = nv;
      this.restTimeS = model ? 0 : timeS;
    }
    this.geometry.setDrawRange(0, 3 * nt);
    this.redrawAll();
    /** @type {THREE.BufferAttribute} */ (this.geometry.index).needsUpdate = true;
    // Everything is new: nothing moved is left to do (a new stamp: the arrays may be new too).
    this.stamp++;
    this.numTouchedTris = 0;
    this.movedHi = -1;
    return true;
  }

  /**
   * Every vertex's drawn position, value and normal again, uploaded whole with the next render (a
   * new surface, scale, or what the colours say).
   */
  redrawAll() {
    const nv = this.numVertices, nt = this.numTriangles;
    if (!this.posAttr || !this.normAttr || !this.valueAttr) return;
    const p = /** @type {Float32Array} */ (this.posAttr.array);
    this.range();
    for (let v = 0; v < nv; v++) this.drawVertex(v, p);
    for (let t = 0; t < nt; t++) this.faceNormal(t);
    for (let v = 0; v < nv; v++) this.vertexNormal(v);
    for (const a of [this.posAttr, this.normAttr, this.valueAttr]) {
      a.clearUpdateRanges();
      a.needsUpdate = true;
    }
    this.wholePending = true;
    this.stamp++;
    this.numTouchedTris = 0;
    this.movedHi = -1;
  }

  /** The range the colour map spans for what it says (display.json's rules). */
  range() {
    this.lo = 0;
    this.hi = 1;
    if (this.colourBy === 'displacement') {
      const index = /** @type {Uint32Array} */ (/** @type {THREE.BufferAttribute} */ (this.geometry.index).array);
      this.hi = displacementRange(this.rest, index, this.numTriangles);
    } else if (this.colourBy === 'stiffness' && this.stiffness) {
      this.lo = Infinity;
      this.hi = -Infinity;
      for (const k of this.stiffness) {
        this.lo = Math.min(this.lo, k);
        this.hi = Math.max(this.hi, k);
      }
    }
  }

  /**
   * Vertex v's drawn position (rest + scale (p - rest)) into p, and its value.
   * @param {number} v @param {Float32Array} p the position attribute's array
   */
  drawVertex(v, p) {
    const a = this.actual, r = this.rest, i = 3 * v;
    if (this.scale === 1) {
      p[i] = a[i];
      p[i + 1] = a[i + 1];
      p[i + 2] = a[i + 2];
    } else {
      const s = this.scale;
      p[i] = r[i] + s * (a[i] - r[i]);
      p[i + 1] = r[i + 1] + s * (a[i + 1] - r[i + 1]);
      p[i + 2] = r[i + 2] + s * (a[i + 2] - r[i + 2]);
    }
    const values = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (this.valueAttr).array);
    if (this.colourBy === 'displacement') {
      // In doubles from the float positions, as idms-render does.
      const dx = a[i] - r[i], dy = a[i + 1] - r[i + 1], dz = a[i + 2] - r[i + 2];
      values[v] = colourIndex(Math.sqrt(dx * dx + dy * dy + dz * dz), this.lo, this.hi) / 255;
    } else if (this.colourBy === 'stiffness' && this.stiffness) {
      values[v] = colourIndex(this.stiffness[v], this.lo, this.hi) / 255;
    } else {
      values[v] = 0;
    }
  }

  /**
   * The model at rest (num_vertices x 3), as the session's first keyframe had it: rest from now on
   * for a surface of its size, the one shown included.
   * @param {Float32Array} positions
   */
  setModelRest(positions) {
    this.modelRest = positions;
    if (this.numVertices > 0 && positions.length === 3 * this.numVertices) {
      this.rest.set(positions);
      this.restVertices = this.numVertices;
      this.restTimeS = 0;
      this.redrawAll();
    }
  }

  /**
   * The deformation scale: drawn = rest + scale (p - rest); colours stay true.
   * @param {number} scale > 0
   */
  setScale(scale) {
    this.scale = scale;
    this.redrawAll();
  }

  /**
   * What the colours say; stiffness per vertex for 'stiffness' (the same count as the surface's).
   * @param {ColourBy} by @param {Float64Array | null} [stiffness]
   */
  setColourBy(by, stiffness = null) {
    this.colourBy = by;
    if (stiffness) this.stiffness = stiffness;
    this.redrawAll();
  }

  /**
   * The vertices a delta moved: their positions now; the normals around them when the frame is
   * drawn (a stream faster than the frame rate moves some vertices several times a frame).
   * @param {{positions: Float32Array, changed: Int32Array, numChanged: number}} s
   * @returns {boolean} whether anything moved
   */
  applyMoved(s) {
    const n = s.numChanged;
    if (n === 0 || !this.posAttr || !this.normAttr) return false;
    const p = /** @type {Float32Array} */ (this.posAttr.array);
    const a = this.actual;
    const stamp = this.stamp;
    let numTris = this.numTouchedTris;
    // Positions (and values) of the moved vertices, and the triangles around them not yet collected.
    for (let k = 0; k < n; k++) {
      const v = s.changed[k];
      a[3 * v] = s.positions[3 * v];
      a[3 * v + 1] = s.positions[3 * v + 1];
      a[3 * v + 2] = s.positions[3 * v + 2];
      this.drawVertex(v, p);
      for (let a = this.adjStart[v]; a < this.adjStart[v + 1]; a++) {
        const t = this.adjTris[a];
        if (this.triStamp[t] !== stamp) {
          this.triStamp[t] = stamp;
          this.touchedTris[numTris++] = t;
        }
      }
    }
    this.numTouchedTris = numTris;
    // The span of moved ids (each delta's are increasing).
    if (s.changed[0] < this.movedLo || this.movedHi < 0) this.movedLo = s.changed[0];
    if (s.changed[n - 1] > this.movedHi) this.movedHi = s.changed[n - 1];
    return true;
  }

  /** The collected triangles' normals, their vertices' normals, and the spans to upload. */
  updateNormals() {
    const start = performance.now();
    const pos = /** @type {THREE.BufferAttribute} */ (this.posAttr);
    const norm = /** @type {THREE.BufferAttribute} */ (this.normAttr);
    const stamp = this.stamp;
    const index = /** @type {Uint32Array} */ (/** @type {THREE.BufferAttribute} */ (this.geometry.index).array);
    let numVerts = 0;
    for (let k = 0; k < this.numTouchedTris; k++) {
      const t = this.touchedTris[k];
      this.faceNormal(t);
      for (let c = 0; c < 3; c++) {
        const v = index[3 * t + c];
        if (this.vertStamp[v] !== stamp) {
          this.vertStamp[v] = stamp;
          this.touchedVerts[numVerts++] = v;
        }
      }
    }
    let lo = this.numVertices;
    let hi = -1;
    for (let k = 0; k < numVerts; k++) {
      const v = this.touchedVerts[k];
      this.vertexNormal(v);
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    // Upload only the spans that changed, unless the buffers go whole with this frame (a keyframe
    // of new triangles, then a delta, before it).
    if (!this.wholePending) {
      pos.clearUpdateRanges();
      pos.addUpdateRange(3 * this.movedLo, 3 * (this.movedHi - this.movedLo + 1));
      pos.needsUpdate = true;
      const values = /** @type {THREE.BufferAttribute} */ (this.valueAttr);
      values.clearUpdateRanges();
      values.addUpdateRange(this.movedLo, this.movedHi - this.movedLo + 1);
      values.needsUpdate = true;
      if (hi >= lo) {
        norm.clearUpdateRanges();
        norm.addUpdateRange(3 * lo, 3 * (hi - lo + 1));
        norm.needsUpdate = true;
      }
    }
    // The next frame collects afresh: a new stamp, nothing cleared.
    this.stamp++;
    this.numTouchedTris = 0;
    this.movedHi = -1;
    this.normalsMs += performance.now() - start;
  }

  /** @param {number} nv @param {number} nt */
  allocate(nv, nt) {
    this.capacityV = nv;
    this.capacityT = nt;
    this.geometry.dispose();
    this.geometry = new THREE.BufferGeometry();
    this.posAttr = new THREE.BufferAttribute(new Float32Array(3 * nv), 3).setUsage(THREE.DynamicDrawUsage);
    this.normAttr = new THREE.BufferAttribute(new Float32Array(3 * nv), 3).setUsage(THREE.DynamicDrawUsage);
    this.valueAttr = new THREE.BufferAttribute(new Float32Array(nv), 1).setUsage(THREE.DynamicDrawUsage);
    this.geometry.setAttribute('position', this.posAttr);
    this.geometry.setAttribute('normal', this.normAttr);
    this.geometry.setAttribute('value', this.valueAttr);
    // Rest survives a larger buffer (more triangles, the same vertices).
    const rest = new Float32Array(3 * nv);
    rest.set(this.rest.subarray(0, Math.min(this.rest.length, 3 * nv)));
    this.rest = rest;
    this.actual = new Float32Array(3 * nv);
    this.geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(3 * nt), 1));
    this.faceNormals = new Float32Array(3 * nt);
    this.triStamp = new Uint32Array(nt);
    this.vertStamp = new Uint32Array(nv);
    this.touchedTris = new Int32Array(nt);
    this.touchedVerts = new Int32Array(nv);
    this.adjStart = new Int32Array(nv + 1);
    this.adjTris = new Int32Array(3 * nt);
    // A keyframe of the same triangles, as a delta (setSurface).
    this.keyframeMoved = new Int32Array(nv);
    this.keyframeDelta.changed = this.keyframeMoved;
  }

  /** @param {Uint32Array} tris @returns {boolean} whether they are the triangles shown */
  sameTriangles(tris) {
    const shown = /** @type {Uint32Array} */ (/** @type {THREE.BufferAttribute} */ (this.geometry.index).array);
    for (let i = 0; i < 3 * this.numTriangles; i++) if (shown[i] !== tris[i]) return false;
    return true;
  }

  /**
   * The vertices whose positions differ from those shown, in increasing order, as applyMoved reads
   * a delta (the object is reused).
   * @param {Float32Array} positions
   */
  movedSince(positions) {
    const shown = this.actual;
    const moved = this.keyframeMoved;
    let n = 0;
    for (let v = 0; v < this.numVertices; v++) {
      const i = 3 * v;
      if (shown[i] !== positions[i] || shown[i + 1] !== positions[i + 1] || shown[i + 2] !== positions[i + 2]) moved[n++] = v;
    }
    const delta = this.keyframeDelta;
    delta.positions = positions;
    delta.numChanged = n;
    return delta;
  }

  /** @param {Uint32Array} tris @param {number} nv @param {number} nt */
  buildAdjacency(tris, nv, nt) {
    const start = this.adjStart;
    start.fill(0, 0, nv + 1);
    for (let j = 0; j < 3 * nt; j++) start[tris[j] + 1]++;
    for (let v = 0; v < nv; v++) start[v + 1] += start[v];
    const fill = this.touchedVerts;  // per-vertex cursor, scratch here
    fill.set(start.subarray(0, nv));
    for (let j = 0; j < 3 * nt; j++) this.adjTris[fill[tris[j]]++] = Math.floor(j / 3);
  }

  /** The area-weighted normal of triangle t into faceNormals. @param {number} t */
  faceNormal(t) {
    const p = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (this.posAttr).array);
    const idx = /** @type {Uint32Array} */ (/** @type {THREE.BufferAttribute} */ (this.geometry.index).array);
    const a = 3 * idx[3 * t], b = 3 * idx[3 * t + 1], c = 3 * idx[3 * t + 2];
    const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
    const vx = p[c] - p[a], vy = p[c + 1] - p[a + 1], vz = p[c + 2] - p[a + 2];
    this.faceNormals[3 * t] = uy * vz - uz * vy;
    this.faceNormals[3 * t + 1] = uz * vx - ux * vz;
    this.faceNormals[3 * t + 2] = ux * vy - uy * vx;
  }

  /** Vertex v's normal: the normalised sum of its triangles' normals. @param {number} v */
  vertexNormal(v) {
    let x = 0, y = 0, z = 0;
    for (let a = this.adjStart[v]; a < this.adjStart[v + 1]; a++) {
      const t = 3 * this.adjTris[a];
      x += this.faceNormals[t];
      y += this.faceNormals[t + 1];
      z += this.faceNormals[t + 2];
    }
    const len = length3(x, y, z) || 1;
    const n = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (this.normAttr).array);
    n[3 * v] = x / len;
    n[3 * v + 1] = y / len;
    n[3 * v + 2] = z / len;
  }

  /**
   * The box around the vertices shown. Not the buffer's: it keeps the size of the largest surface
   * seen, and past numVertices holds an earlier surface's vertices.
   * @param {THREE.Box3} box @returns {THREE.Box3} box
   */
  boundingBox(box) {
    box.makeEmpty();
    if (!this.posAttr) return box;
    return box.setFromArray(/** @type {Float32Array} */ (this.posAttr.array).subarray(0, 3 * this.numVertices));
  }

  /**
   * The sphere around the vertices shown, centred on their box (as three.js's own), empty (radius
   * -1) with none.
   * @param {THREE.Sphere} sphere @returns {THREE.Sphere} sphere
   */
  boundingSphere(sphere) {
    const box = this.boundingBox(new THREE.Box3());
    if (box.isEmpty()) return sphere.makeEmpty();
    const c = box.getCenter(sphere.center);
    const p = /** @type {Float32Array} */ (/** @type {THREE.BufferAttribute} */ (this.posAttr).array);
    let r2 = 0;
    for (let i = 0; i < 3 * this.numVertices; i += 3) {
      const dx = p[i] - c.x, dy = p[i + 1] - c.y, dz = p[i + 2] - c.z;
      r2 = Math.max(r2, dx * dx + dy * dy + dz * dz);
    }
    sphere.radius = Math.sqrt(r2);
    return sphere;
  }

  /** Whether vertices moved since the last frame drawn (their normals are still to recompute). */
  get moved() {
    return this.movedHi >= 0;
  }

  /** The frame was drawn: what was pending went to the GPU. */
  rendered() {
    this.wholePending = false;
  }

  dispose() {
    this.geometry.dispose();
  }
}
