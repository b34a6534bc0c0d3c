// Whether the agent's 1 kHz loop keeps up, in words, from its cumulative LoopStats. Pure (no DOM):
// node:test tests it (tests/web/loop_verdict.test.mjs).
//
// The rule: the loop falls behind when more than 1 % of its ticks overran their deadline over the
// last second of ticks (overruns are what the hand feels: a late force). The session-long period
// p99 (cumulative, so it cannot say "now") adds "fell behind earlier" when it is over 1.5 periods
// or more than 1 % of all ticks overran. Rejected: the period p99 alone as the test (cumulative:
// once high it never comes down), and any overrun at all (a loaded desktop misses a tick now and
// then without the hand feeling it).

/** More than this share of ticks overran: behind. */
export const kBehindShare = 0.01;
/** A period p99 above this many nominal periods: behind at some point. */
export const kBehindPeriods = 1.5;
/** Ticks the recent share is taken over (a second at 1 kHz). */
export const kWindowTicks = 1000;

/**
 * @typedef {{state: 'unknown' | 'ok' | 'earlier' | 'behind', text: string}} Verdict
 */

/** Follows the cumulative stats and keeps the share of overruns over the last window of ticks. */
export class LoopWatch {
  /** @param {number} [nominalUs] the loop's period, µs (1000 at 1 kHz) */
  constructor(nominalUs = 1000) {
    this.nominalUs = nominalUs;
    this.baseTicks = -1;
    this.baseOverruns = 0;
    /** The last complete window's ticks and overruns; -1 before there is one. */
    this.recentTicks = -1;
    this.recentOverruns = 0;
  }

  /**
   * @param {{ticks?: number | null, overruns?: number | null, periodP99Us?: number | null}} s cumulative
   * @returns {Verdict}
   */
  update(s) {
    const ticks = Number(s.ticks ?? 0), overruns = Number(s.overruns ?? 0);
    // A seek back in a replay, or a new session: the counts went down; start again.
    if (this.baseTicks < 0 || ticks < this.baseTicks) {
      this.baseTicks = ticks;
      this.baseOverruns = overruns;
      this.recentTicks = -1;
    } else if (ticks - this.baseTicks >= kWindowTicks) {
      this.recentTicks = ticks - this.baseTicks;
      this.recentOverruns = Math.max(0, overruns - this.baseOverruns);
      this.baseTicks = ticks;
      this.baseOverruns = overruns;
    }
    return verdict({ ticks, overruns, periodP99Us: Number(s.periodP99Us ?? 0), recentTicks: this.recentTicks,
      recentOverruns: this.recentOverruns, nominalUs: this.nominalUs });
  }
}

/** @param {number} x a share @returns {string} */
const percent = (x) => `${(100 * x).toFixed(x < 0.1 ? 1 : 0)} %`;

/**
 * @param {{ticks: number, overruns: number, periodP99Us: number, recentTicks: number, recentOverruns: number,
 *   nominalUs: number}} f recentTicks < 0: no complete window yet (the whole session stands for it)
 * @returns {Verdict}
 */
export function verdict(f) {
  if (!(f.ticks > 0)) return { state: 'unknown', text: 'No loop figures yet.' };
  const rate = `${Math.round(1e6 / f.nominalUs)} Hz`;
  const recent = f.recentTicks > 0 ? f.recentOverruns / f.recentTicks : f.overruns / f.ticks;
  const over = f.recentTicks > 0 ? 'in the last second' : 'so far';
  if (recent > kBehindShare) {
    return { state: 'behind', text: `Falling behind: ${percent(recent)} of ticks ${over} overran their ${f.nominalUs} µs deadline `
      + `(more than ${percent(kBehindShare)}); the ${rate} loop is late and the hand feels the forces late.` };
  }
  const whole = f.overruns / f.ticks;
  const slow = f.periodP99Us > kBehindPeriods * f.nominalUs;
  if (whole > kBehindShare || slow) {
    const why = slow ? `period p99 ${f.periodP99Us} µs over the session, more than ${kBehindPeriods}× ${f.nominalUs} µs`
      : `${percent(whole)} of all ticks overran`;
    return { state: 'earlier', text: `Keeping up now; fell behind earlier (${why}).` };
  }
  return { state: 'ok', text: `Keeping up: the ${rate} loop meets its deadlines (${percent(recent)} of ticks ${over} overran; behind means more than ${percent(kBehindShare)}).` };
}
