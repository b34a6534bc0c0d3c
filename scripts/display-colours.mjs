// Writes the colour map of protocol/display.json (its "map.srgb", 256 entries), the one table both
// viewers colour a surface by (viewer-web imports the JSON; CMake embeds it into idms-render).
// The rest of the file is edited by hand; this script rewrites only the table:
//   node scripts/display-colours.mjs [--png OUT.png]   (--png: the map as a strip, to look at)
//
// The map is a path through OKLab (Ottosson 2020, a perceptually uniform space) whose lightness
// falls linearly from 0.92 to 0.30, so equal steps of displacement are equal steps of perceived
// lightness and the order reads without a legend (lighter = less): rest tissue is a pale peach,
// a dent goes through rose and red to a deep violet. Hue and chroma turn with it only to keep
// neighbouring steps apart; a colour outside sRGB keeps its lightness and hue and loses chroma.
// Rainbow maps (jet), FEM post-processors' default, were rejected: their lightness rises and
// falls, so yellow bands read as features that are not there.
import { readFileSync, writeFileSync } from 'node:fs';
import { deflateSync } from 'node:zlib';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const file = join(dirname(fileURLToPath(import.meta.url)), '..', 'protocol', 'display.json');
const kEntries = 256;

/** OKLab to linear sRGB (the published matrices). @param {number} L @param {number} a @param {number} b */
function oklabToLinear(L, a, b) {
  const l = (L + 0.3963377774 * a + 0.2158037573 * b) ** 3;
  const m = (L - 0.1055613458 * a - 0.0638541728 * b) ** 3;
  const s = (L - 0.0894841775 * a - 1.291485548 * b) ** 3;
  return [4.0767416621 * l - 3.3077115913 * m + 0.2309699292 * s,
    -1.2684380046 * l + 2.6097574011 * m - 0.3413193965 * s,
    -0.0041960863 * l - 0.7034186147 * m + 1.707614701 * s];
}

/** Linear to sRGB-encoded, 0..1. @param {number} x */
const encode = (x) => (x <= 0.0031308 ? 12.92 * x : 1.055 * x ** (1 / 2.4) - 0.055);

/** The map at t in [0, 1]: lightness, chroma and hue (degrees) in OKLCh. @param {number} t */
function lch(t) {
  const L = 0.92 - 0.62 * t;
  const C = 0.035 + 0.16 * Math.sin(Math.PI * Math.min(t / 0.9, 1)) ** 0.7 + 0.07 * t;
  const h = 60 - 95 * t;
  return [L, C, h];
}

/** sRGB bytes of t, chroma reduced (by halving) until it fits. @param {number} t */
function colour(t) {
  const [L, C0, h] = lch(t);
  const rad = (h * Math.PI) / 180;
  let lo = 0, hi = C0;
  const fits = (/** @type {number} */ c) => oklabToLinear(L, c * Math.cos(rad), c * Math.sin(rad)).every((x) => x >= 0 && x <= 1);
  if (!fits(hi)) {
    for (let i = 0; i < 40; i++) {
      const mid = (lo + hi) / 2;
      if (fits(mid)) lo = mid;
      else hi = mid;
    }
    hi = lo;
  }
  return oklabToLinear(L, hi * Math.cos(rad), hi * Math.sin(rad)).map((x) => Math.round(255 * encode(Math.min(1, Math.max(0, x)))));
}

const hex = (/** @type {number[]} */ c) => '#' + c.map((x) => x.toString(16).padStart(2, '0')).join('');
const table = Array.from({ length: kEntries }, (_, i) => colour(i / (kEntries - 1)));
const display = JSON.parse(readFileSync(file, 'utf8'));
display.map.srgb = table.map(hex);
// Two spaces of indent; arrays of numbers on one line, the table eight colours a line.
const text = JSON.stringify(display, null, 2)
  .replace(/\[\s*(-?[\d.]+(?:,\s*-?[\d.]+)*)\s*\]/g, (_, xs) => `[${xs.split(/,\s*/).join(', ')}]`)
  .replace(/"srgb": \[([^\]]*)\]/, (_, xs) => {
    const all = xs.trim().split(/,\s*/);
    const lines = [];
    for (let i = 0; i < all.length; i += 8) lines.push('      ' + all.slice(i, i + 8).join(', '));
    return `"srgb": [\n${lines.join(',\n')}\n    ]`;
  });
writeFileSync(file, text + '\n');
console.log(`${file}: ${kEntries} colours, ${hex(table[0])} .. ${hex(table[kEntries - 1])}`);

// --png OUT: the table as a 512x48 strip (a minimal PNG: one IDAT, filter 0 on every row).
const png = process.argv.indexOf('--png');
if (png > 0) {
  const w = 512, h = 48;
  const raw = Buffer.alloc(h * (1 + 3 * w));
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) raw.set(table[Math.floor((x * kEntries) / w)], y * (1 + 3 * w) + 1 + 3 * x);
  }
  const crcTable = Array.from({ length: 256 }, (_, n) => {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    return c >>> 0;
  });
  const crc = (/** @type {Buffer} */ b) => {
    let c = 0xffffffff;
    for (const x of b) c = crcTable[(c ^ x) & 255] ^ (c >>> 8);
    return (c ^ 0xffffffff) >>> 0;
  };
  const chunk = (/** @type {string} */ type, /** @type {Buffer} */ data) => {
    const out = Buffer.alloc(12 + data.length);
    out.writeUInt32BE(data.length, 0);
    out.write(type, 4, 'ascii');
    data.copy(out, 8);
    out.writeUInt32BE(crc(out.subarray(4, 8 + data.length)), 8 + data.length);
    return out;
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0);
  ihdr.writeUInt32BE(h, 4);
  ihdr.set([8, 2, 0, 0, 0], 8);
  writeFileSync(process.argv[png + 1], Buffer.concat([Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]),
    chunk('IHDR', ihdr), chunk('IDAT', deflateSync(raw)), chunk('IEND', Buffer.alloc(0))]));
}
