// The length of a 3-vector, for the paths that run per sample (1 kHz) or per vertex moved.
// Math.hypot(x, y, z) is what it replaces: in V8 (Node 20, Chromium 156) a three-argument hypot
// allocates on every call, even in optimised code, and took 37 ns against 4 ns for this (a loop
// of a million calls in Node); in the surface's normals it was about 160 kB of garbage per frame
// drawn at 10^4 vertices. The values here are forces and positions of the order of 1, far from
// where the sum of squares would overflow, which is all hypot's care buys.

/** @param {number} x @param {number} y @param {number} z */
export function length3(x, y, z) {
  return Math.sqrt(x * x + y * y + z * z);
}
