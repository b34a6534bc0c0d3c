// The tool and the force on it as one mesh, drawn in one draw call: the tool a sphere of its
// radius (thesis 6.1), drawn as its outline (a ring of display.json's outline_px pixels at its
// silhouette, in the colour of its state) over a faint fill (fill_alpha), unlit, so that the
// contact patch under it keeps its colours: a shaded half see-through sphere halved the patch's
// contrast and tinted it, and a wire sphere's lines crossed it like the tissue's own mesh;
// idms-render draws the same outline. The force an arrow from its centre, scaled to the force's
// magnitude, drawn over the sphere. As two objects (a sphere and three.js's ArrowHelper, itself a
// line and a cone) they were three draws.
//
// The sphere is an impostor: a square of two triangles facing the eye, whose shader keeps the
// pixels inside the sphere's silhouette and shades each with the sphere's normal where its ray
// meets it. Round at any zoom, and two triangles where a tessellated sphere of 32x16 segments
// was 960: on a machine without a GPU (headless Chromium's SwiftShader) each triangle costs
// its setup whatever it covers, and that sphere's triangles were about 5% of a 10^4-vertex
// frame's (bench/web: the sphere at 12x6 segments drew the page 3% faster over 8 paired runs).
// Only the arrow's vertices are rewritten when the force changes, and only they are uploaded;
// nothing is allocated.
//
// A needle (Tool.KIND_NEEDLE, setNeedle) adds its shaft to the same mesh: a lit cylinder of a
// third of the tip's radius from the tip (the sphere's centre) back along its orientation's local
// +z for its length, steel, red while it is in the tissue (idms-render's kNeedleColour and
// kNeedleInColour, viewer-offscreen/include/idms/render/render.h). Its triangles come first in the
// index, so that the tip's ring and the force are drawn over it; a tool that is not a needle draws
// from after them, as it did before the shaft was added.
import * as THREE from 'three';
import { display } from './display.js';

/** Segments around the arrow's shaft and head. */
const kSides = 12;
/** The arrow's rings (shaft base, shaft top, head side, head base) and its tip and base centre. */
const kArrowVertices = 4 * kSides + 2;
const kUp = new THREE.Vector3(0, 1, 0);
const kSeeThrough = display.tool.fill_alpha;
/** The shaft's rings (at the tip, at the tail, the tail cap's rim) and the cap's centre. */
const kShaftVertices = 3 * kSides + 1;
/** The shaft's colours, sRGB (idms-render's): out of the tissue, and while it is in. */
const kSteel = new THREE.Color().setRGB(0.45, 0.50, 0.58, THREE.SRGBColorSpace);
const kInside = new THREE.Color().setRGB(0.80, 0.18, 0.16, THREE.SRGBColorSpace);
/** The cosine and sine of each side's angle around the arrow (and the shaft). */
const kSideCos = Float64Array.from({ length: kSides }, (_, i) => Math.cos((2 * Math.PI * i) / kSides));
const kSideSin = Float64Array.from({ length: kSides }, (_, i) => Math.sin((2 * Math.PI * i) / kSides));

/** The impostor's corners, in units of the silhouette's radius, counter-clockwise facing the eye. */
const kCorners = [[-1, -1], [1, -1], [1, 1], [-1, 1]];

/**
 * What the shader adds to three.js's Lambert material. Vertex: the corners (toolCorner.z = 1) are
 * placed around the sphere's centre in the plane through it square to the line of sight, at the
 * radius of the silhouette there: the eye's tangent cone to a sphere of radius r at distance d
 * meets that plane in a circle of radius r d / sqrt(d^2 - r^2). Fragment: outside that circle
 * nothing (its edge smoothed over a pixel); inside, the normal where the pixel's ray meets the
 * sphere. The arrow's vertices (toolCorner.z = 0) are drawn as they are. For a perspective camera
 * (rays from the eye), as the views' are.
 */
const kVertexPars = /* glsl */ `
attribute vec3 toolCorner;
uniform float toolRadius;
varying vec3 vToolCorner;
varying vec3 vToolCentre;
`;
const kVertexMain = /* glsl */ `
vToolCorner = toolCorner;
vToolCentre = vec3(0.0);
if (toolCorner.z > 0.5) {
  vec3 c = (modelViewMatrix * vec4(0.0, 0.0, 0.0, 1.0)).xyz;
  float d2 = dot(c, c), r2 = toolRadius * toolRadius;
  vec3 ahead = c * inversesqrt(d2);
  vec3 u = normalize(cross(ahead, abs(ahead.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
  vec3 v = cross(u, ahead);
  // The eye inside the sphere: nothing drawn (a square of size 0).
  float k = d2 > 1.0001 * r2 ? sqrt(r2 * d2 / (d2 - r2)) : 0.0;
  mvPosition = vec4(c + (u * toolCorner.x + v * toolCorner.y) * k, 1.0);
  gl_Position = projectionMatrix * mvPosition;
  vToolCentre = c;
}
`;
const kFragmentPars = /* glsl */ `
uniform float toolRadius;
const float kOutlinePx = ${display.tool.outline_px.toFixed(3)};
varying vec3 vToolCorner;
varying vec3 vToolCentre;
`;
const kFragmentNormal = /* glsl */ `
if (vToolCorner.z > 0.5) {
  float q = length(vToolCorner.xy);
  // Pixels inside the silhouette: past kOutlinePx the fill, within it the opaque ring (its inner
  // edge smoothed over a pixel); outside nothing (its outer edge smoothed likewise).
  float px = (1.0 - q) / max(fwidth(q), 1e-6);
  float ring = clamp(kOutlinePx - px + 0.5, 0.0, 1.0);
  diffuseColor.a = mix(diffuseColor.a, 1.0, ring) * clamp(px + 0.5, 0.0, 1.0);
  if (diffuseColor.a <= 0.0) discard;
  vec3 ray = normalize(-vViewPosition);
  float b = dot(ray, vToolCentre);
  float h = max(b * b - dot(vToolCentre, vToolCentre) + toolRadius * toolRadius, 0.0);
  normal = (ray * (b - sqrt(h)) - vToolCentre) / toolRadius;
  nonPerturbedNormal = normal;
}
`;

export class ToolMesh extends THREE.Mesh {
  /** @param {number} color the tool's colour @param {number} arrowColor */
  constructor(color, arrowColor) {
    const numSphere = kCorners.length;
    const shaft = numSphere + kArrowVertices;
    const n = shaft + kShaftVertices;
    const positions = new Float32Array(3 * n);
    const normals = new Float32Array(3 * n);
    const colors = new Float32Array(4 * n);
    const corners = new Float32Array(3 * n);
    for (let v = 0; v < numSphere; v++) {
      corners.set([kCorners[v][0], kCorners[v][1], 1], 3 * v);
      // Unused (the shader makes the sphere's normals); facing the eye, as the square does.
      normals[3 * v + 2] = 1;
    }
    // The shaft's triangles first (drawn only for a needle, under the rest); rings as in
    // setShaft, counter-clockwise seen from outside.
    const index = [];
    const capCentre = shaft + 3 * kSides;
    for (let i = 0; i < kSides; i++) {
      const j = (i + 1) % kSides;
      index.push(shaft + i, shaft + j, shaft + kSides + j, shaft + i, shaft + kSides + j, shaft + kSides + i);
      index.push(shaft + 2 * kSides + i, shaft + 2 * kSides + j, capCentre);
    }
    const numShaftIndices = index.length;
    index.push(0, 1, 2, 0, 2, 3);
    const numSphereIndices = index.length - numShaftIndices;
    const numArrowIndices = 12 * kSides;
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
    geometry.setAttribute('toolCorner', new THREE.BufferAttribute(corners, 3));
    geometry.setIndex(index);
    // No depth test: the force shows through the tissue (a grasp pulls the hand towards it) and
    // the tool where the tissue hides it; drawn after the tissue (renderOrder). Lambert: the
    // physically based material it was (three.js's defaults, fully rough, not metal) added only a
    // faint sheen to this see-through sphere, and its per-pixel shading cost a software renderer
    // half the tool's time (bench/web at 10^3 vertices, where the tool is large on screen: 6.6 ms
    // a frame with it, 3.2 with Lambert; the screenshots are the same to the eye).
    const material = new THREE.MeshLambertMaterial({ vertexColors: true, transparent: true, depthWrite: false, depthTest: false });
    const radius = { value: 1 };
    material.onBeforeCompile = (shader) => {
      shader.uniforms.toolRadius = radius;
      shader.vertexShader = shader.vertexShader
        .replace('#include <common>', `#include <common>\n${kVertexPars}`)
        .replace('#include <project_vertex>', `#include <project_vertex>\n${kVertexMain}`);
      shader.fragmentShader = shader.fragmentShader
        .replace('#include <common>', `#include <common>\n${kFragmentPars}`)
        .replace('#include <normal_fragment_begin>', `#include <normal_fragment_begin>\n${kFragmentNormal}`)
        // The sphere unlit: its colour as it is (three.js converts it to sRGB after).
        .replace('#include <opaque_fragment>', 'if (vToolCorner.z > 0.5) outgoingLight = diffuseColor.rgb;\n#include <opaque_fragment>');
    };
    super(geometry, material);
    this.renderOrder = 10;
    // The square follows the eye and the arrow's vertices move: a bounding sphere would be stale.
    this.frustumCulled = false;
    this.numSphere = numSphere;
    this.numSphereIndices = numSphereIndices;
    /** The shaft's first vertex and its index count (the index's first entries). */
    this.shaftVertex = shaft;
    this.numShaftIndices = numShaftIndices;
    this.numArrowIndices = numArrowIndices;
    /** The needle's length, model units; 0: not a needle (no shaft drawn). */
    this.needleLength = 0;
    /** The shaft's radius, model units. */
    this.shaftRadius = 0;
    /** The needle's orientation (model frame): the shaft runs from the tip along its local +z. */
    this.orientation = new THREE.Quaternion();
    this.punctured = false;
    this.forceShown = false;
    /** The sphere's radius, model units (the shader's uniform). */
    this.radius = radius;
    this.positions = positions;
    this.normals = normals;
    this.colors = colors;
    this.direction = new THREE.Quaternion();
    this.scratch = new THREE.Vector3();
    this.tint = new THREE.Color();
    this.shownColor = -1;
    const c = new THREE.Color(arrowColor);
    for (let v = numSphere; v < shaft; v++) colors.set([c.r, c.g, c.b, 1], 4 * v);
    this.setRadius(1);
    this.setColor(color);
    this.hideForce();
  }

  /** @param {number} radius model units */
  setRadius(radius) {
    this.radius.value = radius;
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
    this.forceShown = true;
    this.setDrawn();
  }

  /** No force: the sphere alone (and a needle's shaft). */
  hideForce() {
    this.forceShown = false;
    this.setDrawn();
  }

  /**
   * The tool is a needle of this length (model units; 0 or less: it is not, and no shaft is
   * drawn), its shaft of this radius (model units; a third of the tip's).
   * @param {number} length @param {number} radius
   */
  setNeedle(length, radius) {
    this.needleLength = length > 0 ? length : 0;
    this.shaftRadius = radius;
    this.setShaft();
    this.setDrawn();
  }

  /**
   * A needle's pose and state, from its last sample; the shaft rewritten only when they change.
   * @param {{w?: number | null, x?: number | null, y?: number | null, z?: number | null} | null | undefined} q
   *   unit, model frame; absent (or zero): identity, the shaft straight up from the tip
   * @param {boolean} punctured in the tissue: the shaft red
   */
  setNeedlePose(q, punctured) {
    const w = q?.w || 0, x = q?.x || 0, y = q?.y || 0, z = q?.z || 0;
    const norm = Math.sqrt(w * w + x * x + y * y + z * z);
    const o = this.orientation;
    const turned = norm > 1e-9 ? o.w !== w / norm || o.x !== x / norm || o.y !== y / norm || o.z !== z / norm
      : o.w !== 1 || o.x !== 0 || o.y !== 0 || o.z !== 0;
    if (turned) {
      if (norm > 1e-9) o.set(x / norm, y / norm, z / norm, w / norm);
      else o.identity();
    }
    if (punctured !== this.punctured) {
      this.punctured = punctured;
      this.colorShaft();
    }
    if (turned) this.setShaft();
  }

  /** @param {number} radius the shaft's, model units; rewritten only when it changes */
  setShaftRadius(radius) {
    if (radius === this.shaftRadius) return;
    this.shaftRadius = radius;
    this.setShaft();
  }

  /** The needle's tail (the far end of its shaft), model frame. @param {THREE.Vector3} target */
  tail(target) {
    return target.set(0, 0, this.needleLength).applyQuaternion(this.orientation).add(this.position);
  }

  /**
   * The shaft's vertices, given along +z from the tip, turned by the orientation: a ring at the
   * tip, one at the tail, and the tail's cap (its rim and centre); then its colours.
   */
  setShaft() {
    if (this.needleLength <= 0) return;
    const s = this.shaftVertex, r = this.shaftRadius, len = this.needleLength;
    const q = this.orientation;
    for (let i = 0; i < kSides; i++) {
      const c = kSideCos[i], sn = kSideSin[i];
      this.arrowVertex(s + i, r * c, r * sn, 0, c, sn, 0, q);
      this.arrowVertex(s + kSides + i, r * c, r * sn, len, c, sn, 0, q);
      this.arrowVertex(s + 2 * kSides + i, r * c, r * sn, len, 0, 0, 1, q);
    }
    this.arrowVertex(s + 3 * kSides, 0, 0, len, 0, 0, 1, q);
    this.upload('position', s, kShaftVertices);
    this.upload('normal', s, kShaftVertices);
    this.colorShaft();
  }

  /** The shaft's colour: steel, or red while the needle is in the tissue. */
  colorShaft() {
    const { r, g, b } = this.punctured ? kInside : kSteel;
    const k = this.colors;
    for (let v = this.shaftVertex; v < this.shaftVertex + kShaftVertices; v++) {
      k[4 * v] = r;
      k[4 * v + 1] = g;
      k[4 * v + 2] = b;
      k[4 * v + 3] = 1;
    }
    this.upload('color', this.shaftVertex, kShaftVertices);
  }

  /**
   * What is drawn, one range of the index: the shaft (a needle's), the sphere, the arrow (while
   * there is a force). A tool that is not a needle starts after the shaft.
   */
  setDrawn() {
    const first = this.needleLength > 0 ? 0 : this.numShaftIndices;
    const end = this.numShaftIndices + this.numSphereIndices + (this.forceShown ? this.numArrowIndices : 0);
    this.geometry.setDrawRange(first, end - first);
  }

  /**
   * One of the arrow's vertices, given pointing along +y, turned to the force's direction (or one
   * of the shaft's, given along +z, turned by the needle's orientation).
   * @param {number} v @param {number} x @param {number} y @param {number} z
   * @param {number} nx @param {number} ny @param {number} nz @param {THREE.Quaternion} [turn]
   */
  arrowVertex(v, x, y, z, nx, ny, nz, turn = this.direction) {
    const t = this.scratch.set(x, y, z).applyQuaternion(turn);
    this.positions[3 * v] = t.x;
    this.positions[3 * v + 1] = t.y;
    this.positions[3 * v + 2] = t.z;
    const m = this.scratch.set(nx, ny, nz).applyQuaternion(turn);
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
