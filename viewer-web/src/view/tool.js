// The tool and the force on it as one mesh, drawn in one draw call: the tool a sphere of its
// radius (thesis 6.1), half see-through, in the colour of its state; the force an arrow from its
// centre, scaled to the force's magnitude, drawn over the sphere. As two objects (a sphere and
// three.js's ArrowHelper, itself a line and a cone) they were three draws; on a machine without a
// GPU (headless Chromium's SwiftShader) each draw of a few hundred triangles costs a fixed part of
// a 75 ms frame, and its lit pixels more: 0.6 ms unlit and 1.6 lit in one batch, up to 4.5 in
// another (bench/web, `--variants "bare bare,sphere"`, beside the bare page; the material below
// says what lighting costs). Only the arrow's
// vertices are rewritten when the force changes, and only they are uploaded; nothing is allocated.
import * as THREE from 'three';

/** Segments around the arrow's shaft and head. */
const kSides = 12;
/** The arrow's rings (shaft base, shaft top, head side, head base) and its tip and base centre. */
const kArrowVertices = 4 * kSides + 2;
const kUp = new THREE.Vector3(0, 1, 0);
const kSeeThrough = 0.5;
/** The cosine and sine of each side's angle around the arrow. */
const kSideCos = Float64Array.from({ length: kSides }, (_, i) => Math.cos((2 * Math.PI * i) / kSides));
const kSideSin = Float64Array.from({ length: kSides }, (_, i) => Math.sin((2 * Math.PI * i) / kSides));

export class ToolMesh extends THREE.Mesh {
  /** @param {number} color the tool's colour @param {number} arrowColor */
  constructor(color, arrowColor) {
    const sphere = new THREE.SphereGeometry(1, 32, 16);
    const numSphere = sphere.attributes.position.count;
    const n = numSphere + kArrowVertices;
    const positions = new Float32Array(3 * n);
    const normals = new Float32Array(3 * n);
    const colors = new Float32Array(4 * n);
    // The unit sphere's normals are its positions; setRadius scales them into place.
    normals.set(/** @type {Float32Array} */ (sphere.attributes.normal.array));
    const index = Array.from(/** @type {THREE.BufferAttribute} */ (sphere.index).array);
    const numSphereIndices = index.length;
    sphere.dispose();
    // The arrow's triangles after the sphere's, so that it is drawn over it. Counter-clockwise
    // seen from outside; rings as in arrowVertex.
    const a = numSphere;
    const tip = a + 4 * kSides, baseCentre = tip + 1;
    for (let i = 0; i < kSides; i++) {
      const j = (i + 1) % kSides;
      index.push(a + i, a + kSides + i, a + kSides + j, a + i, a + kSides + j, a + j);
      index.push(a + 2 * kSides + i, tip, a + 2 * kSides + j);
      index.push(a + 3 * kSides + i, a + 3 * kSides + j, baseCentre);
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute('normal', new THREE.BufferAttribute(normals, 3));
    geometry.setAttribute('color', new THREE.BufferAttribute(colors, 4));
    geometry.setIndex(index);
    // No depth test: the force shows through the tissue (a grasp pulls the hand towards it) and
    // the tool where the tissue hides it; drawn after the tissue (renderOrder). Lambert: the
    // physically based material it was (three.js's defaults, fully rough, not metal) added only a
    // faint sheen to this see-through sphere, and its per-pixel shading cost a software renderer
    // half the tool's time (bench/web at 10^3 vertices, where the tool is large on screen: 6.6 ms
    // a frame with it, 3.2 with Lambert; the screenshots are the same to the eye).
    const material = new THREE.MeshLambertMaterial({ vertexColors: true, transparent: true, depthWrite: false, depthTest: false });
    super(geometry, material);
    this.renderOrder = 10;
    // The arrow's vertices move: a bounding sphere would be stale.
    this.frustumCulled = false;
    this.numSphere = numSphere;
    this.numSphereIndices = numSphereIndices;
    this.unit = Float32Array.from(normals.subarray(0, 3 * numSphere));
    this.positions = positions;
    this.normals = normals;
    this.colors = colors;
    this.direction = new THREE.Quaternion();
    this.scratch = new THREE.Vector3();
    this.tint = new THREE.Color();
    this.shownColor = -1;
    const c = new THREE.Color(arrowColor);
    for (let v = numSphere; v < n; v++) colors.set([c.r, c.g, c.b, 1], 4 * v);
    this.setRadius(1);
    this.setColor(color);
    this.hideForce();
  }

  /** @param {number} radius model units */
  setRadius(radius) {
    const p = this.positions, u = this.unit;
    for (let i = 0; i < u.length; i++) p[i] = radius * u[i];
    this.upload('position', 0, this.numSphere);
  }

  /** @param {number} color the sphere's, as a hex number; rewritten only when it changes */
  setColor(color) {
    if (color === this.shownColor) return;
    this.shownColor = color;
    // Hex colours are sRGB; Color holds them linear, as vertex colours are taken.
    const { r, g, b } = this.tint.setHex(color);
    const k = this.colors;
    for (let v = 0; v < this.numSphere; v++) {
      k[4 * v] = r;
      k[4 * v + 1] = g;
      k[4 * v + 2] = b;
      k[4 * v + 3] = kSeeThrough;
    }
    this.upload('color', 0, this.numSphere);
  }

  /**
   * The arrow along a unit direction from the sphere's centre (as ArrowHelper's setDirection and
   * setLength): its length, its head's length and its head's width, model units.
   * @param {THREE.Vector3} dir @param {number} length @param {number} headLength @param {number} headWidth
   */
  setForce(dir, length, headLength, headWidth) {
    this.direction.setFromUnitVectors(kUp, dir);
    const neck = Math.max(0, length - headLength);
    const shaft = headWidth / 8, head = headWidth / 2;
    // The head's side normal: outward and up by the cone's slope.
    const h = Math.max(length - neck, 1e-9);
    const slope = Math.sqrt(h * h + head * head);
    const a = this.numSphere;
    for (let i = 0; i < kSides; i++) {
      const c = kSideCos[i], s = kSideSin[i];
      this.arrowVertex(a + i, shaft * c, 0, shaft * s, c, 0, s);
      this.arrowVertex(a + kSides + i, shaft * c, neck, shaft * s, c, 0, s);
      this.arrowVertex(a + 2 * kSides + i, head * c, neck, head * s, (h * c) / slope, head / slope, (h * s) / slope);
      this.arrowVertex(a + 3 * kSides + i, head * c, neck, head * s, 0, -1, 0);
    }
    this.arrowVertex(a + 4 * kSides, 0, length, 0, 0, 1, 0);
    this.arrowVertex(a + 4 * kSides + 1, 0, neck, 0, 0, -1, 0);
    this.upload('position', a, kArrowVertices);
    this.upload('normal', a, kArrowVertices);
    this.geometry.setDrawRange(0, Infinity);
  }

  /** No force: the sphere alone. */
  hideForce() {
    this.geometry.setDrawRange(0, this.numSphereIndices);
  }

  /**
   * One of the arrow's vertices, given pointing along +y, turned to the force's direction.
   * @param {number} v @param {number} x @param {number} y @param {number} z
   * @param {number} nx @param {number} ny @param {number} nz
   */
  arrowVertex(v, x, y, z, nx, ny, nz) {
    const t = this.scratch.set(x, y, z).applyQuaternion(this.direction);
    this.positions[3 * v] = t.x;
    this.positions[3 * v + 1] = t.y;
    this.positions[3 * v + 2] = t.z;
    const m = this.scratch.set(nx, ny, nz).applyQuaternion(this.direction);
    this.normals[3 * v] = m.x;
    this.normals[3 * v + 1] = m.y;
    this.normals[3 * v + 2] = m.z;
  }

  /**
   * Uploads vertices [first, first + count) of an attribute with the next render, once however
   * often they change before it (three.js merges and then clears the ranges as it uploads).
   * @param {'position' | 'normal' | 'color'} name @param {number} first vertex @param {number} count
   */
  upload(name, first, count) {
    const attr = /** @type {THREE.BufferAttribute} */ (this.geometry.attributes[name]);
    const start = first * attr.itemSize, size = count * attr.itemSize;
    attr.needsUpdate = true;
    // A range already pending (three.js keeps them until an update, not a first upload) is not
    // added again.
    const ranges = attr.updateRanges;
    for (let i = 0; i < ranges.length; i++) if (ranges[i].start === start && ranges[i].count === size) return;
    attr.addUpdateRange(start, size);
  }

  dispose() {
    this.geometry.dispose();
    /** @type {THREE.Material} */ (this.material).dispose();
  }
}
