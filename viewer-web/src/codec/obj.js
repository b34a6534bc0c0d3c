// A Wavefront .obj surface (what the server converts each model's .plg to) as positions and
// triangles for the preview: `v x y z` and `f a b c ...` (1-based, `a/t/n` forms, fans for n > 3).

/**
 * @param {string} text
 * @returns {{numVertices: number, numTriangles: number, positions: Float32Array, triangles: Uint32Array}}
 */
export function parseObj(text) {
  /** @type {number[]} */ const pos = [];
  /** @type {number[]} */ const tris = [];
  const lines = text.split('\n');
  for (let n = 0; n < lines.length; n++) {
    const parts = lines[n].trim().split(/\s+/);
    if (parts[0] === 'v') {
      const [x, y, z] = parts.slice(1, 4).map(Number);
      if (![x, y, z].every(Number.isFinite)) throw new Error(`obj line ${n + 1}: expected "v x y z"`);
      pos.push(x, y, z);
    } else if (parts[0] === 'f') {
      const ids = parts.slice(1).map((p) => Number.parseInt(p.split('/')[0], 10));
      const nv = pos.length / 3;
      const fixedIds = ids.map((i) => (i < 0 ? nv + i : i - 1));
      if (fixedIds.length < 3 || fixedIds.some((i) => !(i >= 0 && i < nv)))
        throw new Error(`obj line ${n + 1}: a face needs 3 or more vertex ids in 1..${nv}`);
      for (let k = 1; k + 1 < fixedIds.length; k++) tris.push(fixedIds[0], fixedIds[k], fixedIds[k + 1]);
    }
  }
  return { numVertices: pos.length / 3, numTriangles: tris.length / 3, positions: Float32Array.from(pos), triangles: Uint32Array.from(tris) };
}
