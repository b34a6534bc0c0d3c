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
import * as THREE from 'three';
import { display } from './display.js';

/** Segments around the arrow's shaft and head. */
const kSides = 12;
/** The arrow's rings (shaft base, shaft top, head side, head base) and its tip and base centre. */
const kArrowVertices = 4 * kSides + 2;
const kUp = new THREE.Vector3(0, 1, 0);
const kSeeThrough = display.tool.fill_alpha;
/** The cosine and sine of each side's angle around the arrow. */
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
    const n = numSphere + kArrowVertices;
    const positions = new Float32Array(3 * n);
    const normals = new Float32Array(3 * n);
    const colors = new Float32Array(4 * n);
    const corners = new Float32Array(3 * n);
    for (let v = 0; v < numSphere; v++) {
      corners.set([kCorners[v][0], kCorners[v][1], 1], 3 * v);
      // Unused (the shader makes the sphere's normals); facing the eye, as the square does.
      normals[3 * v + 2] = 1;
    }
    const index = [0, 1, 2, 0, 2, 3];
    const numSphereIndices = index.length;
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
    for (let v = numSphere; v < n; v++) colors.set([c.r, c.g, c.b, 1], 4 * v);
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
