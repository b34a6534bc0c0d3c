// The tool's sphere as the browser draws it (viewer-web/src/view/tool.js: a square facing the eye
// whose shader keeps the sphere's silhouette, an opaque outline at its edge over a faint fill), in
// Debian's headless chromium: the pixels it covers are those whose ray meets the sphere, at the
// centre of the view, off to a side and corner and close to the eye (where perspective widens the
// silhouette most), save a pixel's width at the edge; its outline is opaque and its inside
// see-through at display.json's fill_alpha, unlit (as idms-render draws it); the force's arrow is
// drawn over it, opaque.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import * as THREE from '../../viewer-web/node_modules/three/build/three.module.js';
import { launchBrowser, sourceDir, shot } from './e2e/harness.mjs';
import { display } from '../../viewer-web/src/view/display.js';

const width = 320, height = 240, fov = 40;
/** @type {Awaited<ReturnType<typeof launchBrowser>>} */
let browser;
/** @type {import('playwright-core').Page} */
let page;

before(async () => {
  const esbuild = await import(join(sourceDir(), 'viewer-web', 'node_modules', 'esbuild', 'lib', 'main.js'));
  const built = await esbuild.build({ entryPoints: [join(sourceDir(), 'tests', 'web', 'tool_page.js')], bundle: true, write: false,
    format: 'iife', target: 'es2020', nodePaths: [join(sourceDir(), 'viewer-web', 'node_modules')], logLevel: 'warning' });
  browser = await launchBrowser();
  page = browser.page;
  await page.setContent('<!doctype html><html><body style="margin:0"></body></html>');
  await page.addScriptTag({ content: built.outputFiles[0].text });
});

after(async () => {
  await browser?.context.close();
  assert.deepEqual(browser?.errors ?? [], [], 'errors on the page');
});

/**
 * Draws the tool; returns its pixels (top row first) and where the sphere is by ray casting each
 * pixel's centre from the same camera: 'in', 'out', or 'edge' (within a pixel of the silhouette).
 * @param {{camera: number[], centre: number[], radius: number, force?: number[], light?: number[]}} spec
 */
async function draw(spec) {
  const base64 = await page.evaluate((s) => /** @type {any} */ (window).renderTool(s),
    { width, height, fov, camera: spec.camera, centre: spec.centre, radius: spec.radius, force: spec.force ?? null, light: spec.light ?? [1, 0, 0] });
  const raw = Buffer.from(base64, 'base64');
  const camera = new THREE.PerspectiveCamera(fov, width / height, 0.01, 100);
  camera.position.fromArray(spec.camera);
  camera.lookAt(0, 0, 0);
  camera.updateMatrixWorld();
  const sphere = new THREE.Sphere(new THREE.Vector3().fromArray(spec.centre), spec.radius);
  const ray = new THREE.Raycaster();
  /** @param {number} x @param {number} y pixel, from the top left */
  const cast = (x, y) => {
    ray.setFromCamera(new THREE.Vector2((2 * x) / width - 1, 1 - (2 * y) / height), camera);
    return ray.ray.intersectsSphere(sphere);
  };
  /** @type {('in' | 'out' | 'edge')[]} */
  const where = [];
  const lit = [];
  for (let y = 0; y < height; y++) {
    for (let x = 0; x < width; x++) {
      const c = cast(x + 0.5, y + 0.5);
      // Edge: the pixel's corners disagree (its area crosses the silhouette).
      const corners = [cast(x - 0.5, y - 0.5), cast(x + 1.5, y - 0.5), cast(x - 0.5, y + 1.5), cast(x + 1.5, y + 1.5)];
      where.push(corners.every((k) => k === c) ? (c ? 'in' : 'out') : 'edge');
      const o = 4 * ((height - 1 - y) * width + x);
      lit.push([raw[o], raw[o + 1], raw[o + 2]]);
    }
  }
  return { where, lit };
}

/** @param {Awaited<ReturnType<typeof draw>>} d */
function coverage(d) {
  let inside = 0, wrong = 0;
  const bad = [];
  for (let i = 0; i < d.where.length; i++) {
    if (d.where[i] === 'edge') continue;
    const drawn = d.lit[i][0] + d.lit[i][1] + d.lit[i][2] > 0;
    if (d.where[i] === 'in') inside++;
    if (drawn !== (d.where[i] === 'in')) {
      wrong++;
      if (bad.length < 5) bad.push(`(${i % width}, ${Math.floor(i / width)}) ${d.where[i]} drawn=${drawn}`);
    }
  }
  return { inside, wrong, bad };
}

for (const [name, spec] of /** @type {const} */ ([
  ['at the centre of the view', { camera: [0, 0, 10], centre: [0, 0, 0], radius: 1.5 }],
  ['off to a side and a corner', { camera: [0, 0, 10], centre: [3.6, 2.2, 0], radius: 1.2 }],
  ['close to the eye', { camera: [0, 0, 10], centre: [0.6, -0.3, 6.8], radius: 1.5 }],
  ['seen from above, off-centre', { camera: [0, -6, 8], centre: [-2, 1, 1], radius: 1 }],
])) {
  test(`the sphere covers the pixels whose ray meets it: ${name}`, async () => {
    const d = await draw(spec);
    const c = coverage(d);
    assert.ok(c.inside > 200, `the sphere covers ${c.inside} pixels: too small a case`);
    assert.equal(c.wrong, 0, `${c.wrong} pixels off the silhouette (of ${c.inside} inside): ${c.bad.join('; ')}`);
  });
}

test('the outline is opaque, the inside see-through and unlit; the arrow is drawn over the sphere, opaque', async () => {
  const d = await draw({ camera: [0, 0, 10], centre: [0, 0, 0], radius: 2, force: [0, -3.5, 0] });
  // A row across the sphere above its centre (the arrow points down), white over black: its first
  // and last pixels inside are the outline, full white; its inside white at fill_alpha, the same
  // across (no light on it).
  const y = height / 2, above = y - 20, row = [];
  for (let x = 0; x < width; x++) if (d.where[above * width + x] === 'in') row.push(d.lit[above * width + x][0]);
  assert.ok(row.length > 40, `${row.length} pixels across the sphere`);
  assert.ok(row[0] > 240 && row[row.length - 1] > 240, `the outline: ${row[0]}, ${row[row.length - 1]}`);
  const fill = Math.round(255 * display.tool.fill_alpha);
  const inside = row.slice(6, -6);
  assert.ok(inside.every((v) => Math.abs(v - fill) <= 3), `the inside should be ${fill}: ${Math.min(...inside)} to ${Math.max(...inside)}`);
  // The arrow points down from the centre: below the centre, on the axis, blue and nothing else.
  const p = d.lit[(y + 40) * width + width / 2];
  assert.ok(p[2] > 100 && p[0] < 40 && p[1] < 40, `the arrow's shaft is ${p}`);
  await shot(page, 'tool-impostor.png');
});
