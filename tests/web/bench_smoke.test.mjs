// The browser viewer's bench (bench/web) still runs: one short round of each page at 10^3
// vertices, and one of its variants, each printing its figures. Nothing here is timed: the
// figures are read only for being there and being numbers (the bench is for a person to run
// and read; this is so that a change to the viewer that breaks it shows in CI, not then).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import { join } from 'node:path';
import { promisify } from 'node:util';

const run = promisify(execFile);
const source = process.env.IDMS_SOURCE_DIR ?? '';
const build = process.env.IDMS_BUILD_DIR ?? '';

/** @param {string[]} args @returns {Promise<string>} what the bench printed */
async function bench(args) {
  assert.ok(source && build, 'IDMS_SOURCE_DIR and IDMS_BUILD_DIR (ctest sets them)');
  const { stdout } = await run(process.execPath, [join(source, 'bench', 'web', 'web_bench.mjs'), build,
    '--vertices', '1000', '--runs', '1', '--warmup', '1', '--seconds', '1', ...args], { timeout: 180000 });
  return stdout;
}

test('the bench prints both pages\' figures at 10^3 vertices', async () => {
  const out = await bench([]);
  // vertices, triangles, moved/frame, frames/s in, page JS ms/frame, page fps (runs), bare fps (runs), ratio
  const row = /^\s+1000\s+1872\s+(\d+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+) \(([\d.]+)\)\s+([\d.]+) \(([\d.]+)\)\s+([\d.]+)$/m.exec(out);
  assert.ok(row, `no result row in:\n${out}`);
  const [moved, received, js, page, , bare] = row.slice(1).map(Number);
  assert.ok(moved > 0, 'the stream moved vertices');
  assert.ok(received > 10, `${received} frames a second received`);
  assert.ok(js > 0 && page > 0 && bare > 0, row[0]);
  assert.match(out, /page\/bare per round: median [\d.]+/);
  assert.match(out, /CPU ms per frame drawn: page [\d.]+ \(renderer [\d.]+ \+ GPU process [\d.]+\), bare [\d.]+/);
  assert.match(out, /canvas: page 1280x720 \(pixel ratio 1, antialias true\), bare 1280x720/);
});

test('the bench runs its variants, the bare page\'s standing panel among them', async () => {
  const out = await bench(['--variants', 'page,notool bare,panel bare']);
  for (const name of ['page,notool', 'bare,panel', 'bare']) {
    assert.match(out, new RegExp(`^  ${name}\\s+fps\\s+[\\d.]+ \\([\\d.]+\\), CPU ms per frame drawn [\\d.]+`, 'm'), out);
  }
  assert.match(out, /page,notool \/ bare fps per round: median [\d.]+/);
});
