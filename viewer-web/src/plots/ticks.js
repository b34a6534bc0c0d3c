// Axis ticks for the plots drawn on a plain canvas (the force-against-depth plot): round values
// (1, 2 or 5 x 10^n apart) that cover a range, as uPlot's axes choose theirs. Pure: no DOM.

/**
 * Ticks from 0 (or lo, when it is below 0) to at least hi, about `target` of them, at a round step.
 * @param {number} lo @param {number} hi hi > lo
 * @param {number} [target] how many ticks are wanted, about
 * @returns {{ticks: number[], step: number, top: number, bottom: number}} top and bottom: the axis's ends (first and last tick)
 */
export function niceTicks(lo, hi, target = 5) {
  if (!(hi > lo) || !Number.isFinite(lo) || !Number.isFinite(hi)) return { ticks: [lo], step: 1, top: lo + 1, bottom: lo };
  const raw = (hi - lo) / Math.max(1, target - 1);
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? 10 * mag;
  const bottom = Math.floor(lo / step + 1e-9) * step;
  const top = Math.ceil(hi / step - 1e-9) * step;
  const ticks = [];
  for (let k = 0; bottom + k * step <= top + step * 1e-9; k++) ticks.push(bottom + k * step);
  return { ticks, step, top, bottom };
}

/** A tick's text: no more digits than its step needs. @param {number} v @param {number} step */
export function tickLabel(v, step) {
  const digits = Math.max(0, -Math.floor(Math.log10(step) + 1e-9) + (String(step / 10 ** Math.floor(Math.log10(step))).includes('.') ? 1 : 0));
  return (Math.abs(v) < step * 1e-9 ? 0 : v).toFixed(Math.min(digits, 10));
}
