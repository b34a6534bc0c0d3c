// Both viewers draw the same colours: viewer-web's view/display.js against what idms-render makes
// of protocol/display.json (idms-web-display-colours, linked with idms_render): for the shipped
// models, the same displacement range from the same rest surface, the same colour-map entry and
// colour for each displacement (around entries' boundaries too), the same per-vertex stiffness.
// A table copied into one viewer and edited in the other, a stale embedding, or arithmetic that
// drifts (rounding, the range's rule) fails here.
//   IDMS_WEB_DISPLAY_COLOURS_BIN=build/bin/idms-web-display-colours node --test tests/web/display.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { colourIndex, display, displacementRange, niceCeil, srgbBytes, stiffnessPerVertex } from '../../viewer-web/src/view/display.js';

const bin = process.env.IDMS_WEB_DISPLAY_COLOURS_BIN;
const source = process.env.IDMS_SOURCE_DIR ?? join(import.meta.dirname ?? '.', '..', '..');
const kModels = ['hex_4x5_home', 'slab_40x40', 'slab_40x40_tumour', 'sphere_cap'];

/** @returns {Record<string, any>} */
function cpp() {
  assert.ok(bin, 'IDMS_WEB_DISPLAY_COLOURS_BIN names build/bin/idms-web-display-colours');
  return JSON.parse(execFileSync(bin, [join(source, 'models'), ...kModels], { encoding: 'utf8', maxBuffer: 64 << 20 }));
}

test('a displacement takes the same entry and colour of the map in both viewers', () => {
  const all = cpp();
  for (const name of kModels) {
    const m = all[name];
    const positions = Float32Array.from(m.positions);
    const range = displacementRange(positions, Uint32Array.from(m.triangles), m.triangles.length / 3);
    assert.equal(range, m.range, `${name}: the displacement range`);
    assert.ok(m.colours.length > 20);
    for (const c of m.colours) {
      const index = colourIndex(c.displacement, 0, range);
      assert.equal(index, c.index, `${name}: entry of ${c.displacement}`);
      assert.deepEqual(srgbBytes(display.map.srgb[index]), c.srgb, `${name}: colour of ${c.displacement}`);
    }
  }
  // The palpation's fragment and the slabs (sides of 1 unit) span 0.1 model units.
  assert.equal(all.hex_4x5_home.range, 0.1);
  assert.equal(all.slab_40x40.range, 0.1);
});

test('per-vertex stiffness is the same in both viewers; the tumour has its inclusion, the slab none', () => {
  const all = cpp();
  for (const name of kModels) {
    const k = stiffnessPerVertex(readFileSync(join(source, 'models', `${name}.fem`), 'utf8'));
    assert.equal(k.length, all[name].stiffness.length, name);
    k.forEach((x, i) => assert.ok(Math.abs(x - all[name].stiffness[i]) <= 1e-9 * Math.abs(x), `${name} vertex ${i}: ${x}`));
  }
  const plain = all.slab_40x40.stiffness, tumour = all.slab_40x40_tumour.stiffness;
  assert.equal(Math.min(...plain), Math.max(...plain));
  assert.ok(Math.max(...tumour) >= 4 * Math.min(...tumour), 'the inclusion is stiffer');
});

test('the range rule: nice steps, exact at their boundaries', () => {
  assert.equal(niceCeil(0.1), 0.1);
  assert.equal(niceCeil(0.10001), 0.2);
  assert.equal(niceCeil(0.10000002), 0.1);
  assert.equal(niceCeil(0.21), 0.25);
  assert.equal(niceCeil(0.3), 0.5);
  assert.equal(niceCeil(7), 10);
  assert.equal(niceCeil(0), 1);
  assert.equal(colourIndex(5, 0, 0), 0);
  assert.equal(colourIndex(-1, 0, 1), 0);
  assert.equal(colourIndex(3, 0, 1), 255);
  assert.equal(colourIndex(15.000000000000002, 15, 15.000000000000004), 0, 'a span of rounding is one colour');
  assert.equal(colourIndex(15.5, 15, 16), 128);
  assert.equal(display.map.srgb.length, 256);
});
