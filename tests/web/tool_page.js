// The page tool_render.test.mjs draws in: the viewer's ToolMesh alone, lit, in a canvas of a given
// size, from a camera at a given place; returns the canvas's pixels (RGBA rows, bottom row first).
import * as THREE from 'three';
import { ToolMesh } from '../../viewer-web/src/view/tool.js';

/**
 * @param {{width: number, height: number, fov: number, camera: number[], centre: number[], radius: number,
 *   force: number[] | null, light: number[]}} spec
 * @returns {string} the pixels, base64
 */
function renderTool(spec) {
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(spec.width, spec.height);
  document.body.replaceChildren(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x000000);
  // One light, from where the spec says (towards it from the origin), and a little ambient.
  const sun = new THREE.DirectionalLight(0xffffff, 3);
  sun.position.fromArray(spec.light);
  scene.add(sun);
  scene.add(new THREE.AmbientLight(0xffffff, 0.3));
  const camera = new THREE.PerspectiveCamera(spec.fov, spec.width / spec.height, 0.01, 100);
  camera.position.fromArray(spec.camera);
  camera.lookAt(0, 0, 0);
  const tool = new ToolMesh(0xffffff, 0x0000ff);
  tool.setRadius(spec.radius);
  tool.position.fromArray(spec.centre);
  if (spec.force) {
    const f = new THREE.Vector3().fromArray(spec.force);
    tool.setForce(f.clone().normalize(), f.length(), 0.3 * f.length(), 0.3 * spec.radius);
  }
  scene.add(tool);
  renderer.render(scene, camera);
  const gl = renderer.getContext();
  const pixels = new Uint8Array(4 * spec.width * spec.height);
  gl.readPixels(0, 0, spec.width, spec.height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
  renderer.dispose();
  let text = '';
  for (let i = 0; i < pixels.length; i += 8192) text += String.fromCharCode(...pixels.subarray(i, i + 8192));
  return btoa(text);
}

/** @type {any} */ (window).renderTool = renderTool;
