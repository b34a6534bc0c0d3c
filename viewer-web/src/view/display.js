// What both viewers share about colouring a surface: protocol/display.json (the colour map, the
// range rules, the lights, the tool's and the contact markers' look), imported as it is; idms-render
// embeds the same file (viewer-offscreen/src/display.cc). The arithmetic here is the C++'s, step for
// step, so that a value takes the same entry of the map in both (tests/web/display.test.mjs checks
// it against the C++). Pure: no three.js, no DOM.
import display from '../../../protocol/display.json' with { type: 'json' };

export { display };

/** An sRGB hex colour as bytes. @param {string} hex "#rrggbb" @returns {[number, number, number]} */
export function srgbBytes(hex) {
  return [Number.parseInt(hex.slice(1, 3), 16), Number.parseInt(hex.slice(3, 5), 16), Number.parseInt(hex.slice(5, 7), 16)];
}

/** The map as RGBA bytes, 256 entries (a texture's and the legend's). */
export const kMapRgba = (() => {
  const out = new Uint8Array(4 * display.map.srgb.length);
  display.map.srgb.forEach((hex, i) => out.set([...srgbBytes(hex), 255], 4 * i));
  return out;
})();

/**
 * The map's entry for v in [lo, hi]: round(clamp((v - lo) / (hi - lo), 0, 1) * 255); 0 when the
 * range has no width (ColourIndex in C++).
 * @param {number} v @param {number} lo @param {number} hi
 */
export function colourIndex(v, lo, hi) {
  // A span within rounding of the values (a fitted model's k, 12 x 1.25 = 15.000000000000002 on
  // some elements) is no span: one colour, not the whole map over the noise.
  if (!(hi - lo > 1e-9 * Math.max(Math.abs(lo), Math.abs(hi))) || !Number.isFinite(v)) return 0;
  const t = Math.min(1, Math.max(0, (v - lo) / (hi - lo)));
  return Math.floor(t * 255 + 0.5);
}

/**
 * The first of display.json's nice steps times a power of ten at or above x, within a part in a
 * million; 1 for x <= 0 (NiceCeil).
 * @param {number} x
 */
export function niceCeil(x) {
  if (!(x > 0) || !Number.isFinite(x)) return 1;
  // The power of ten at or below x by steps of ten, as the C++ does (Math.pow and log10 may round
  // differently from C's).
  let p = 1;
  while (p > x) p /= 10;
  while (p * 10 <= x) p *= 10;
  // A part in a million over a step is taken as the step (a mesh of unit sides is 1 within its
  // float positions' rounding, either way).
  for (const m of display.displacement.nice_steps) if (x <= m * p * (1 + 1e-6)) return m * p;
  return 10 * p;
}

/**
 * The displacement range's top for a rest surface: niceCeil(range_fraction x the mean length of the
 * triangles' sides, each triangle's three in order) (DisplacementRange).
 * @param {ArrayLike<number>} rest (num_vertices x 3) @param {ArrayLike<number>} tris @param {number} numTriangles
 */
export function displacementRange(rest, tris, numTriangles) {
  let sum = 0;
  /** @param {number} a @param {number} b */
  const side = (a, b) => {
    const dx = rest[3 * a] - rest[3 * b], dy = rest[3 * a + 1] - rest[3 * b + 1], dz = rest[3 * a + 2] - rest[3 * b + 2];
    sum += Math.sqrt(dx * dx + dy * dy + dz * dz);
  };
  for (let t = 0; t < numTriangles; t++) {
    side(tris[3 * t], tris[3 * t + 1]);
    side(tris[3 * t + 1], tris[3 * t + 2]);
    side(tris[3 * t + 2], tris[3 * t]);
  }
  if (numTriangles === 0) return 1;
  return niceCeil(display.displacement.range_fraction * (sum / (3 * numTriangles)));
}

/** The legend's tick values, lo to hi in display.json's number of steps (lo alone for no width). @param {number} lo @param {number} hi */
export function legendTicks(lo, hi) {
  if (!(hi - lo > 0)) return [lo];
  const n = display.displacement.ticks;
  return Array.from({ length: n + 1 }, (_, i) => lo + ((hi - lo) * i) / n);
}

/** A tick's text: at most 3 significant digits, no trailing zeros (C's %.3g for these ranges). @param {number} v */
export function tickText(v) {
  return String(Number(v.toPrecision(3)));
}

/**
 * Per surface vertex (the external atoms in file order = plg vertex order): the mean k of the
 * elements that end at its atom (StiffnessPerVertex), from a .fem's text (appendix B: `name na ne`,
 * na lines `x y z mass bc sc`, ne lines `a1 a2 k b`; blank lines between sections). The server has
 * validated the file; anything unexpected throws.
 * @param {string} fem
 * @returns {Float64Array}
 */
export function stiffnessPerVertex(fem) {
  const lines = fem.split('\n').map((l) => l.trim()).filter((l) => l !== '');
  const [, naText, neText] = lines[0].split(/\s+/);
  const na = Number(naText), ne = Number(neText);
  if (!(na > 0 && ne >= 0 && lines.length >= 1 + na + ne)) throw new Error('fem: expected "name na ne" and its atoms and elements');
  const sum = new Float64Array(na), count = new Int32Array(na);
  for (let e = 0; e < ne; e++) {
    const [a, b, k] = lines[1 + na + e].split(/\s+/).map(Number);
    sum[a] += k;
    sum[b] += k;
    count[a]++;
    count[b]++;
  }
  /** @type {number[]} */
  const out = [];
  for (let i = 0; i < na; i++) {
    // sc 2001: external, a surface vertex.
    if (lines[1 + i].split(/\s+/)[5] === '2001') out.push(count[i] > 0 ? sum[i] / count[i] : 0);
  }
  return Float64Array.from(out);
}
