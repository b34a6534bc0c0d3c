// The tissue in 3D: the surface as one three.js BufferGeometry updated in place (SurfaceGeometry:
// only moved vertices' positions, colour values and the normals around them, uploaded as update
// ranges; the normals once per frame drawn, for every vertex moved since the last), coloured by
// displacement from rest (or stiffness) through protocol/display.json's map and lit by its grazing
// key and fill lights (surface_material.js: idms-render's arithmetic), with a legend; the vertices
// in contact marked; the tool as an outlined see-through sphere of its radius (thesis 6.1) so the
// contact patch keeps its colours, the force as an arrow scaled to its magnitude; a needle's shaft
// from its tip along its orientation, red while it is in the tissue. Renders only when
// something changed, in the page's frame (FrameLoop); nothing is allocated per frame once the first
// keyframe is drawn.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { FrameLoop } from './frame_loop.js';
import { SurfaceGeometry } from './surface_geometry.js';
import { surfaceMaterial } from './surface_material.js';
import { Legend } from './legend.js';
import { display, tickText } from './display.js';
import { Units, kModelUnits } from './units.js';
import { ToolMesh } from './tool.js';
import { length3 } from '../length3.js';

const hexNumber = (/** @type {string} */ hex) => Number.parseInt(hex.slice(1), 16);
const kToolFree = hexNumber(display.tool.free_srgb);
const kToolContact = hexNumber(display.tool.contact_srgb);
const kToolGrasp = hexNumber(display.tool.grasp_srgb);
const kToolSlip = hexNumber(display.tool.slip_srgb);

/** The camera's direction from what it looks at: in front, a little above and to the side. */
const kViewFrom = new THREE.Vector3(0.3, -2.6, 1.0).normalize();
/** The view's margin around what it frames: the distance placeCamera finds, times this. */
const kFrameMargin = 1.05;
const scratchRight = new THREE.Vector3();
const scratchUp = new THREE.Vector3();
const scratchCorner = new THREE.Vector3();
const scratchBox = new THREE.Box3();
const scratchTail = new THREE.Vector3();
/** A needle's shaft: a third of its tip's radius, and at least this many pixels (idms-render's kNeedleMinPx). */
const kShaftMinPx = 1.5;
/** placeCamera's points: x across, y up, z towards the camera and radius, for 16 at most. */
const scratchPoints = new Float64Array(16 * 4);

/**
 * Looks from the front, a little above and to the side, z up, from as near as shows all of a box
 * (the surface's) and of a sphere wherever its centre has been in another (the tool's travel):
 * every corner of the first, and a sphere of the radius at every corner of the second, inside the
 * view, whatever the view's shape. A flat tissue seen from above fills a wide view this way, where
 * fitting a bounding sphere of both into the narrower field of view left it a third of the width.
 * The bench's bare page uses it too, so that both draw the same pixels.
 * @param {THREE.PerspectiveCamera} camera its fov and aspect already set
 * @param {THREE.Box3} box not empty
 * @param {THREE.Box3} [centres] where the sphere's centre has been; empty or not given: no sphere
 * @param {number} [radius] the sphere's
 * @param {THREE.Vector3} [target] set to the point looked at (the middle of all of it)
 */
export function placeCamera(camera, box, centres, radius = 0, target = new THREE.Vector3()) {
  const all = scratchBox.copy(box);
  const sphere = centres !== undefined && !centres.isEmpty();
  if (sphere) all.union(centres.clone().expandByScalar(radius));
  const c = all.getCenter(target);
  const r = Math.max(all.getSize(scratchCorner).length() / 2, 1e-9);
  // The camera's axes for this direction (they do not depend on its distance).
  camera.up.set(0, 0, 1);
  camera.position.copy(c).add(kViewFrom);
  camera.lookAt(c);
  camera.updateMatrixWorld();
  const right = scratchRight.setFromMatrixColumn(camera.matrixWorld, 0);
  const up = scratchUp.setFromMatrixColumn(camera.matrixWorld, 1);
  const halfY = THREE.MathUtils.degToRad(camera.fov) / 2;
  const halfX = Math.atan(Math.tan(halfY) * camera.aspect);
  const cosX = Math.cos(halfX), sinX = Math.sin(halfX), cosY = Math.cos(halfY), sinY = Math.sin(halfY);
  // A sphere of radius s at x across, y up and z towards the camera from c is inside the view's
  // right side from distance d when (d - z) sin(halfX) >= x cos(halfX) + s; likewise its left
  // (-x), top (y, halfY) and bottom (-y). The distance each side needs, the farthest thing's:
  let right0 = 0, left0 = 0, top0 = 0, bottom0 = 0, front = 0;
  const points = scratchPoints;
  let n = 0;
  /** @param {THREE.Box3} b @param {number} s */
  const fit = (b, s) => {
    for (let i = 0; i < 8; i++) {
      const q = scratchCorner.set(i & 1 ? b.max.x : b.min.x, i & 2 ? b.max.y : b.min.y, i & 4 ? b.max.z : b.min.z).sub(c);
      const x = q.dot(right), y = q.dot(up), z = q.dot(kViewFrom);
      points[4 * n] = x;
      points[4 * n + 1] = y;
      points[4 * n + 2] = z;
      points[4 * n + 3] = s;
      n++;
      front = Math.max(front, z + s);
      right0 = Math.max(right0, z + (x * cosX + s) / sinX);
      left0 = Math.max(left0, z + (-x * cosX + s) / sinX);
      top0 = Math.max(top0, z + (y * cosY + s) / sinY);
      bottom0 = Math.max(bottom0, z + (-y * cosY + s) / sinY);
    }
  };
  fit(box, 0);
  if (sphere) fit(/** @type {THREE.Box3} */ (centres), radius);
  // Moving what the camera looks at by u along its right takes u / tan(halfX) off what the right
  // side needs and adds it to the left's: the two meet at their mean, the nearest the camera can
  // be for that axis. Likewise up; the farther of the two is the distance. Whatever is nearest the
  // camera stays beyond the near plane (r / 100).
  const d = Math.max(kFrameMargin * Math.max((right0 + left0) / 2, (top0 + bottom0) / 2), front + r / 50);
  // From there, each axis centred: moved by u, the farthest thing on one side as far from the
  // middle of the view as the farthest on the other (by angle, a sphere's silhouette included).
  // Moving further along an axis turns everything the other way, so the u that balances them is
  // found by halving.
  /** @param {number} k 0 across, 1 up @returns {number} u */
  const centre = (k) => {
    let lo = -(d + r), hi = d + r;
    for (let it = 0; it < 60; it++) {
      const u = (lo + hi) / 2;
      let first = -Infinity, last = Infinity;
      for (let i = 0; i < n; i++) {
        const a = points[4 * i + k] - u, depth = d - points[4 * i + 2];
        const angle = Math.atan2(a, depth), spread = Math.asin(Math.min(1, points[4 * i + 3] / Math.sqrt(a * a + depth * depth)));
        first = Math.max(first, angle + spread);
        last = Math.min(last, angle - spread);
      }
      if (first + last > 0) lo = u;
      else hi = u;
    }
    return (lo + hi) / 2;
  };
  const across = centre(0), upward = centre(1);
  c.addScaledVector(right, across).addScaledVector(up, upward);
  camera.position.copy(c).addScaledVector(kViewFrom, d);
  camera.near = r / 100;
  camera.far = d + r * 100;
  camera.lookAt(c);
  camera.updateProjectionMatrix();
}

/**
 * Whether the tool is near enough to the surface to be framed with it: within the surface's
 * diameter of its bounding sphere. A tool further off is left out, the tissue staying the subject
 * (the camera fitted to the surface alone had the tool hovering above it fill the view's top, cut
 * off; fitted to a far tool, the tissue shrank to a few pixels).
 * @param {THREE.Sphere} surface @param {THREE.Sphere} tool
 */
export function toolNear(surface, tool) {
  return surface.center.distanceTo(tool.center) - tool.radius <= 2 * surface.radius;
}

/**
 * The tool's framed travel grown by where it is now, when it is near the surface (toolNear): what
 * placeCamera frames besides the surface (the live view's and the bench's bare page's one rule).
 * @param {THREE.Box3} travel grown in place @param {THREE.Sphere} surface @param {THREE.Sphere} tool
 * @returns {THREE.Box3} travel
 */
export function frameTool(travel, surface, tool) {
  if (toolNear(surface, tool)) travel.expandByPoint(tool.center);
  return travel;
}

export class SurfaceView {
  /**
   * @param {HTMLElement} host
   * @param {FrameLoop} [loop] the page's frame loop, shared with its other drawings
   */
  constructor(host, loop = new FrameLoop()) {
    this.host = host;
    this.loop = loop;
    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
    this.renderer.domElement.setAttribute('aria-label', 'Tissue surface, tool and force (drag to orbit, wheel to zoom)');
    this.renderer.domElement.setAttribute('role', 'img');
    host.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f5f7);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1000);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    // Keyboard too: focus the view (Tab) and pan with the arrow keys.
    this.renderer.domElement.tabIndex = 0;
    this.controls.listenToKeyEvents(this.renderer.domElement);
    this.controls.addEventListener('change', () => this.invalidate());
    // The arrow's light (Lambert); the surface lights itself (surface_material.js).
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8090a0, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(3, 5, 8);
    this.scene.add(sun);
    // The surface, its legend, and the contact markers (two squares per vertex, dark then light,
    // over everything: seen on any colour of the map).
    this.surface = new SurfaceGeometry();
    this.material = surfaceMaterial();
    this.mesh = new THREE.Mesh(this.surface.geometry, this.material);
    this.mesh.frustumCulled = false;
    this.mesh.visible = false;
    this.scene.add(this.mesh);
    this.legend = new Legend(host);
    this.contactIds = new Uint32Array(0);
    this.numContacts = 0;
    this.contactGeometry = new THREE.BufferGeometry();
    /** @type {THREE.Points[]} */
    this.contactMarks = [[display.contact.outer_srgb, display.contact.outer_px], [display.contact.inner_srgb, display.contact.inner_px]]
      .map(([colour, size], i) => {
        const m = new THREE.Points(this.contactGeometry, new THREE.PointsMaterial({ color: new THREE.Color(String(colour)),
          size: Number(size), sizeAttenuation: false, depthTest: false, depthWrite: false }));
        m.frustumCulled = false;
        m.renderOrder = 5 + i;
        m.visible = false;
        this.scene.add(m);
        return m;
      });
    this.contact = false;
    // A needle's suture thread (display.json's "suture"): a line through its nodes as segments
    // (a parted one left out) and its punctures as squares, over the surface. Sized for the most a
    // frame carries (idms.proto's SutureShape: 129 nodes, 16 punctures), so a frame allocates nothing.
    this.threadGeometry = new THREE.BufferGeometry();
    this.threadGeometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(2 * 128 * 3), 3));
    this.thread = new THREE.LineSegments(this.threadGeometry, new THREE.LineBasicMaterial({
      color: new THREE.Color(String(display.suture.thread_srgb)), depthTest: false, depthWrite: false }));
    this.thread.frustumCulled = false;
    this.thread.renderOrder = 4;
    this.thread.visible = false;
    this.scene.add(this.thread);
    this.punctureGeometry = new THREE.BufferGeometry();
    this.punctureGeometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(16 * 3), 3));
    this.punctureMarks = new THREE.Points(this.punctureGeometry, new THREE.PointsMaterial({
      color: new THREE.Color(String(display.suture.puncture_srgb)), size: Number(display.suture.puncture_px),
      sizeAttenuation: false, depthTest: false, depthWrite: false }));
    this.punctureMarks.frustumCulled = false;
    this.punctureMarks.renderOrder = 4;
    this.punctureMarks.visible = false;
    this.scene.add(this.punctureMarks);
    /** What the thread shows: its nodes, segments drawn, punctures and knots (for the tests). */
    this.sutureShown = { nodes: 0, segments: 0, punctures: 0, ties: 0, brokenSegment: 0 };
    // The tool and the force.
    this.tool = new ToolMesh(kToolFree, 0x1d5fa8);
    this.tool.visible = false;
    this.scene.add(this.tool);
    this.forceDir = new THREE.Vector3();
    this.toolRadius = 1.5;
    this.tool.setRadius(this.toolRadius);
    this.forceScale = 0.1;  // model units of arrow per force unit, set from the model's size
    /** What the legend says its values are in. */
    this.units = kModelUnits;
    this.fitted = false;
    // The camera is fitted at the first surface, and again whenever the tool goes where it has
    // not been (its framed travel only grows: the view settles on the tool's travel rather than
    // following it) or the view changes shape, until the viewer moves it.
    this.toolFitted = false;
    this.userMoved = false;
    this.controls.addEventListener('start', () => { this.userMoved = true; });
    this.toolSphere = new THREE.Sphere();
    this.surfaceBox = new THREE.Box3();
    this.surfaceSphere = new THREE.Sphere();
    /** Where the tool's centre has been near the surface, framed (empty until it shows). */
    this.travel = new THREE.Box3();
    this.dirty = true;
    /** Called after each render (the page counts frames). @type {(() => void) | null} */
    this.onRender = null;
    loop.add(this);
    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(host);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.host.clientWidth);
    const h = Math.max(1, this.host.clientHeight);
    this.renderer.setSize(w, h, false);
    this.renderer.domElement.style.width = '100%';
    this.renderer.domElement.style.height = '100%';
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    // The distance that shows what is framed depends on the view's shape.
    if (this.fitted && !this.userMoved) this.fit();
    this.invalidate();
  }

  /** Renders in the next frame (once, however many changes come before it). */
  invalidate() {
    this.dirty = true;
    this.loop.request();
  }

  /** The frame loop's part: one render when something changed. @returns {boolean} */
  draw() {
    if (!this.dirty) return false;
    this.dirty = false;
    if (this.surface.moved) this.surface.updateNormals();
    this.markContacts();
    // A needle's shaft as thick as the view needs, rewritten when that changes by more than 2 %
    // (orbiting changes it a little every frame).
    if (this.tool.needleLength > 0) {
      const r = this.shaftRadius();
      if (Math.abs(r - this.tool.shaftRadius) > 0.02 * r) this.tool.setShaftRadius(r);
    }
    this.renderer.render(this.scene, this.camera);
    this.surface.rendered();
    this.onRender?.();
    return false;
  }

  /** @param {boolean} on */
  setWireframe(on) {
    this.material.wireframe = on;
    this.invalidate();
  }

  /** The model at rest (SurfaceGeometry.setModelRest). @param {Float32Array} positions */
  setModelRest(positions) {
    this.surface.setModelRest(positions);
    this.showLegend();
    this.invalidate();
  }

  /** The deformation scale (drawn = rest + scale (p - rest)). @param {number} scale > 0 */
  setScale(scale) {
    this.surface.setScale(scale);
    this.showLegend();
    this.invalidate();
  }

  /**
   * What the surface's colours say.
   * @param {import('./surface_geometry.js').ColourBy} by @param {Float64Array | null} [stiffness] per vertex
   */
  setColourBy(by, stiffness = null) {
    this.surface.setColourBy(by, stiffness);
    this.material.uniforms.useMap.value = by !== 'plain';
    this.showLegend();
    this.invalidate();
  }

  /** What the legend's values are in (the session's scene may declare mm). @param {Units} units */
  setUnits(units) {
    if (units.equals(this.units)) return;
    this.units = units;
    this.showLegend();
  }

  /** The legend for what the colours say now. */
  showLegend() {
    const g = this.surface;
    if (g.colourBy === 'plain' || g.numVertices === 0) return this.legend.show(null);
    /** @type {string[]} */
    const notes = [];
    if (g.colourBy === 'displacement') {
      if (g.scale !== 1) notes.push(`deformation ×${tickText(g.scale)}`);
      if (g.restTimeS > display.displacement.rest_note_after_s) notes.push(`from t = ${tickText(g.restTimeS)} s`);
      const u = this.units;
      this.legend.show({ title: 'displacement', unit: u.length, lo: u.len(g.lo), hi: u.len(g.hi), saturates: true, notes });
    } else {
      const k = this.units.stiffnessScale;
      this.legend.show({ title: 'stiffness k', unit: this.units.stiffness, lo: g.lo * k, hi: g.hi * k, saturates: false, notes });
    }
  }

  /**
   * The vertices in contact (display.json's "contact"), while the device reports contact: those
   * within (1 + tolerance) tool radii of its centre, at their true positions; drawn where they are
   * drawn. Once per frame drawn; allocates only when the surface grows.
   */
  markContacts() {
    const g = this.surface;
    let n = 0;
    if (this.contact && this.tool.visible && g.numVertices > 0) {
      if (this.contactIds.length < g.numVertices) {
        this.contactIds = new Uint32Array(g.capacityV);
        this.contactGeometry.setIndex(new THREE.BufferAttribute(this.contactIds, 1));
      }
      const c = this.tool.position, a = g.actual;
      const reach = this.toolRadius * (1 + display.contact.radius_tolerance);
      for (let v = 0; v < g.numVertices; v++) {
        const dx = a[3 * v] - c.x, dy = a[3 * v + 1] - c.y, dz = a[3 * v + 2] - c.z;
        if (dx * dx + dy * dy + dz * dz < reach * reach) this.contactIds[n++] = v;
      }
      if (this.contactGeometry.getAttribute('position') !== g.posAttr && g.posAttr) this.contactGeometry.setAttribute('position', g.posAttr);
      const index = /** @type {THREE.BufferAttribute} */ (this.contactGeometry.index);
      index.clearUpdateRanges();
      index.addUpdateRange(0, Math.max(n, 1));
      index.needsUpdate = true;
      this.contactGeometry.setDrawRange(0, n);
    }
    this.numContacts = n;
    for (const m of this.contactMarks) m.visible = n > 0 && !this.material.wireframe;
  }

  /**
   * A whole surface (a keyframe); the same triangles again are taken as the vertices that moved
   * (SurfaceGeometry.setSurface).
   * @param {{numVertices: number, numTriangles: number, positions: Float32Array, triangles: Uint32Array}} s
   * @param {number} [timeS] its session time (rest's, for the legend, when it becomes rest)
   */
  setSurface(s, timeS = 0) {
    if (this.surface.setSurface(s, timeS)) {
      this.mesh.geometry = this.surface.geometry;
      this.mesh.visible = s.numTriangles > 0;
      if (!this.fitted && s.numVertices > 0) this.fit();
      this.showLegend();
      this.invalidate();
    } else if (this.surface.moved) {
      this.invalidate();
    }
  }

  /**
   * The vertices a delta moved (SurfaceGeometry.applyMoved).
   * @param {{positions: Float32Array, changed: Int32Array, numChanged: number}} s
   */
  applyMoved(s) {
    if (this.surface.applyMoved(s)) this.invalidate();
  }

  /** Time spent on normals, ms (the bench counts it as the page's work). */
  get normalsMs() {
    return this.surface.normalsMs;
  }

  /**
   * The tool's sphere and the force arrow.
   * @param {number} x @param {number} y @param {number} z tool centre, model units
   * @param {number} fx @param {number} fy @param {number} fz force on the device
   * @param {boolean} contact @param {boolean} grasp
   * @param {boolean} [slip] its contact slips (friction): the ring in display.json's slip colour
   */
  setTool(x, y, z, fx, fy, fz, contact, grasp, slip = false) {
    this.tool.visible = true;
    this.tool.position.set(x, y, z);
    if (this.fitted && !this.userMoved && this.toolOutOfFrame()) this.fit();
    this.tool.setColor(grasp ? kToolGrasp : slip ? kToolSlip : contact ? kToolContact : kToolFree);
    this.contact = contact;
    const f = length3(fx, fy, fz);
    if (f > 1e-9) {
      this.forceDir.set(fx / f, fy / f, fz / f);
      const length = this.toolRadius + f * this.forceScale;
      this.tool.setForce(this.forceDir, length, Math.min(0.4 * length, this.toolRadius * 0.6), this.toolRadius * 0.35);
    } else {
      this.tool.hideForce();
    }
    this.invalidate();
  }

  /** @param {number} radius model units */
  setToolRadius(radius) {
    this.toolRadius = radius > 0 ? radius : 1.5;
    this.tool.setRadius(this.toolRadius);
    this.invalidate();
  }

  /**
   * A needle's suture thread as the last mesh frame showed it (idms.proto's SutureShape), or none.
   * @param {{nodes: ArrayLike<number>, numNodes: number, punctures: ArrayLike<number>, numPunctures: number,
   *   ties: number, brokenSegment: number} | null} shape
   */
  setSuture(shape) {
    const n = shape ? Math.min(shape.numNodes, 129) : 0;
    const shown = this.sutureShown;
    if (n < 2) {
      if (!this.thread.visible && shown.nodes === 0) return;
      this.thread.visible = this.punctureMarks.visible = false;
      shown.nodes = shown.segments = shown.punctures = shown.ties = shown.brokenSegment = 0;
      this.invalidate();
      return;
    }
    const s = /** @type {NonNullable<typeof shape>} */ (shape);
    const seg = /** @type {Float32Array} */ (this.threadGeometry.getAttribute('position').array);
    let k = 0;
    for (let i = 0; i + 1 < n; i++) {
      if (i + 1 === s.brokenSegment) continue;  // the parted segment (+ 1)
      for (let c = 0; c < 6; c++) seg[k++] = s.nodes[3 * i + c];
    }
    this.threadGeometry.setDrawRange(0, k / 3);
    this.threadGeometry.getAttribute('position').needsUpdate = true;
    const np = Math.min(s.numPunctures, 16);
    const marks = /** @type {Float32Array} */ (this.punctureGeometry.getAttribute('position').array);
    for (let i = 0; i < 3 * np; i++) marks[i] = s.punctures[i];
    this.punctureGeometry.setDrawRange(0, np);
    this.punctureGeometry.getAttribute('position').needsUpdate = true;
    this.thread.visible = true;
    this.punctureMarks.visible = np > 0;
    shown.nodes = n;
    shown.segments = k / 6;
    shown.punctures = np;
    shown.ties = s.ties;
    shown.brokenSegment = s.brokenSegment;
    this.invalidate();
  }

  /**
   * The tool is a needle of this length, model units (its tip the sphere, of the tool's radius);
   * 0: it is not.
   * @param {number} length
   */
  setNeedle(length) {
    this.tool.setNeedle(length, this.toolRadius / 3);
    this.invalidate();
  }

  /**
   * A needle's orientation and state, from its last sample (nothing for another tool).
   * @param {{w?: number | null, x?: number | null, y?: number | null, z?: number | null} | null | undefined} q
   *   unit, model frame; absent: identity (the shaft straight up from the tip)
   * @param {boolean} punctured
   */
  setNeedlePose(q, punctured) {
    if (this.tool.needleLength <= 0) return;
    this.tool.setNeedlePose(q, punctured);
    this.invalidate();
  }

  /**
   * A needle's shaft's radius, model units: a third of the tip's, and no thinner than kShaftMinPx
   * pixels where the tip is, so that it shows when the view is far.
   */
  shaftRadius() {
    const d = this.camera.position.distanceTo(this.tool.position);
    const pixel = (2 * d * Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2)) / Math.max(1, this.renderer.domElement.height);
    const third = this.toolRadius / 3;
    return Math.max(third, kShaftMinPx * pixel);
  }

  /**
   * Whether the tool is near the surface where the camera has not framed it (its travel); for a
   * needle near it, its tail too.
   */
  toolOutOfFrame() {
    if (!this.toolFitted) return true;
    const p = this.tool.position;
    if (!toolNear(this.surfaceSphere, this.toolSphere.set(p, this.toolRadius))) return false;
    return !this.travel.containsPoint(p) || (this.tool.needleLength > 0 && !this.travel.containsPoint(this.tool.tail(scratchTail)));
  }

  /**
   * Points the camera at the surface, and the tool's travel while it is near (toolNear), from
   * above and in front (placeCamera). The surface's box is the first surface's.
   */
  fit() {
    if (!this.fitted) {
      const b = this.surface.boundingBox(this.surfaceBox);
      if (b.isEmpty() || b.min.equals(b.max) || !Number.isFinite(b.min.x + b.max.x + b.min.y + b.max.y + b.min.z + b.max.z)) return;
      b.getBoundingSphere(this.surfaceSphere);
    }
    this.forceScale = this.surfaceSphere.radius / 4;
    if (this.tool.visible) frameTool(this.travel, this.surfaceSphere, this.toolSphere.set(this.tool.position, this.toolRadius));
    // A needle whose tip is framed has its tail framed too, however far the shaft reaches: its
    // whole shaft in view.
    if (this.tool.visible && this.tool.needleLength > 0 && toolNear(this.surfaceSphere, this.toolSphere)) {
      this.travel.expandByPoint(this.tool.tail(scratchTail));
    }
    placeCamera(this.camera, this.surfaceBox, this.travel, this.toolRadius, this.controls.target);
    this.controls.update();
    this.fitted = true;
    this.toolFitted = this.tool.visible;
  }

  /**
   * Where the surface and the tool fall in the view (the tests read it): the surface's bounding
   * box's span across the view (1 = the view's width or height, whichever it fills more of), the
   * tool's sphere's span likewise, and whether the tool's sphere lies wholly inside the view.
   * Allocates; not for a frame.
   */
  framing() {
    const ndc = (/** @type {THREE.Vector3} */ p) => p.clone().project(this.camera);
    const span = (/** @type {THREE.Vector3[]} */ ps) => {
      const q = ps.map(ndc);
      const xs = q.map((p) => p.x), ys = q.map((p) => p.y);
      return { span: Math.max(Math.max(...xs) - Math.min(...xs), Math.max(...ys) - Math.min(...ys)) / 2,
        inside: q.every((p) => Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1 && p.z < 1) };
    };
    const b = this.surface.boundingBox(new THREE.Box3());
    const corners = [];
    for (let i = 0; i < 8; i++) {
      corners.push(new THREE.Vector3(i & 1 ? b.max.x : b.min.x, i & 2 ? b.max.y : b.min.y, i & 4 ? b.max.z : b.min.z));
    }
    // The tool's silhouette: its centre +- its radius along the camera's right and up.
    this.camera.updateMatrixWorld();
    const right = new THREE.Vector3().setFromMatrixColumn(this.camera.matrixWorld, 0).multiplyScalar(this.toolRadius);
    const up = new THREE.Vector3().setFromMatrixColumn(this.camera.matrixWorld, 1).multiplyScalar(this.toolRadius);
    const c = this.tool.position;
    const tool = span([c.clone().add(right), c.clone().sub(right), c.clone().add(up), c.clone().sub(up)]);
    // Near: where the frame takes the tool in (fit); a tool further off is left out of the frame
    // on purpose, the tissue staying the subject.
    const near = toolNear(this.surfaceSphere, new THREE.Sphere(c.clone(), this.toolRadius));
    const round = (/** @type {THREE.Vector3} */ v) => v.toArray().map((x) => Number(x.toFixed(2)));
    return { surfaceSpan: span(corners).span, toolShown: this.tool.visible, toolSpan: tool.span, toolInView: tool.inside,
      toolNear: near, surface: [round(b.min), round(b.max)], travel: [round(this.travel.min), round(this.travel.max)],
      tool: round(c), aspect: Number(this.camera.aspect.toFixed(3)) };
  }

  /**
   * Where a model-frame point falls on the canvas, CSS pixels from its top left (the tests read it).
   * @param {number} x @param {number} y @param {number} z
   */
  project(x, y, z) {
    this.camera.updateMatrixWorld();
    const p = new THREE.Vector3(x, y, z).project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    return { x: ((p.x + 1) / 2) * r.width, y: ((1 - p.y) / 2) * r.height };
  }

  dispose() {
    this.loop.remove(this);
    this.resizeObserver.disconnect();
    this.controls.dispose();
    this.legend.dispose();
    this.contactGeometry.dispose();
    for (const m of this.contactMarks) /** @type {THREE.Material} */ (m.material).dispose();
    this.surface.dispose();
    this.tool.dispose();
    this.renderer.dispose();
    this.renderer.domElement.remove();
  }
}
