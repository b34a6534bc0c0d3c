// The device force over whole sessions (GET /api/sessions/{id}/force: peak |F| per slice of session
// time), one line per session on one session-time axis, and a marker at the time being replayed:
// the comparison overlays two sessions, the report draws one. Redrawn when the data change; the
// marker moves by a redraw of uPlot's draw hook only (no new data).
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { withCpuCanvases } from './rolling.js';
import { figureRange } from './trend.js';

/**
 * Profiles given on their own time points, as one table on their joined times (uPlot's one x per
 * plot): a profile has null where it has no point, and the line spans the gap.
 * @param {{time_s: number[], force: number[]}[]} profiles
 * @returns {(number | null)[][]} [times, force of the first, force of the second, ...]
 */
export function joinProfiles(profiles) {
  const times = [...new Set(profiles.flatMap((p) => p.time_s))].sort((a, b) => a - b);
  const index = new Map(times.map((t, i) => [t, i]));
  const columns = profiles.map((p) => {
    /** @type {(number | null)[]} */
    const col = new Array(times.length).fill(null);
    p.time_s.forEach((t, i) => { col[/** @type {number} */ (index.get(t))] = p.force[i]; });
    return col;
  });
  return [times, ...columns];
}

const kHeight = 240;

export class ProfilePlot {
  /**
   * @param {HTMLElement} host
   * @param {{title: string, series: {label: string, color: string}[], legend?: boolean, yLabel?: string}} spec
   *   the force's unit is in the section's heading (a long unit on the axis was cut); yLabel: the
   *   force axis's label (peak |F| unless given)
   */
  constructor(host, spec) {
    this.host = host;
    /** The session time marked, s; NaN = none. */
    this.markS = NaN;
    /** Factors from model force units into what is shown, per series. @type {number[]} */
    this.scales = [];
    /** Points per series as last given (the tests read it). @type {number[]} */
    this.points = spec.series.map(() => 0);
    const width = Math.max(280, host.clientWidth || 600);
    this.plot = withCpuCanvases(() => new uPlot({
      title: spec.title,
      width,
      height: kHeight,
      scales: { x: { time: false }, y: { range: (_u, min, max) => figureRange(min, max) } },
      cursor: { drag: { x: false, y: false } },
      legend: { show: spec.legend ?? true },
      series: [{ label: 'session time (s)' },
        ...spec.series.map((s) => ({ label: s.label, stroke: s.color, width: 1.5, spanGaps: true, points: { show: false } }))],
      axes: [{ label: 'session time (s)' },
        { label: spec.yLabel ?? 'peak |F|', size: 60, labelFont: '12px system-ui, sans-serif' }],
      hooks: { draw: [(u) => this.drawMark(u)] },
    }, [[], ...spec.series.map(() => [])], host));
    this.resizeObserver = new ResizeObserver(() => this.plot.setSize({ width: Math.max(280, host.clientWidth), height: kHeight }));
    this.resizeObserver.observe(host);
  }

  /**
   * The forces' factor into what the page shows (one per series: the sessions' units may differ),
   * for data given after. @param {...number} scales
   */
  scaleForce(...scales) {
    this.scales = scales;
  }

  /** @param {{time_s: number[], force: number[]}[]} profiles one per series, in model force units */
  setData(profiles) {
    this.points = profiles.map((p) => p.time_s.length);
    const scaled = profiles.map((p, i) => {
      const k = this.scales[i] ?? 1;
      return k === 1 ? p : { time_s: p.time_s, force: p.force.map((f) => f * k) };
    });
    this.plot.setData(/** @type {any} */ (joinProfiles(scaled)));
  }

  /** Marks session time t (a replay's), redrawing only when the marker moves a pixel. @param {number} t */
  mark(t) {
    const u = this.plot;
    const x = (/** @type {number} */ v) => (Number.isFinite(v) ? Math.round(u.valToPos(v, 'x')) : NaN);
    if (x(t) === x(this.markS)) return;
    this.markS = t;
    u.redraw(false, false);
  }

  /** @param {uPlot} u */
  drawMark(u) {
    if (!Number.isFinite(this.markS)) return;
    const x = Math.round(u.valToPos(this.markS, 'x', true));
    const { ctx } = u;
    ctx.save();
    ctx.strokeStyle = '#d4880f';
    ctx.lineWidth = 2 * devicePixelRatio;
    ctx.beginPath();
    ctx.moveTo(x, u.bbox.top);
    ctx.lineTo(x, u.bbox.top + u.bbox.height);
    ctx.stroke();
    ctx.restore();
  }

  dispose() {
    this.resizeObserver.disconnect();
    this.plot.destroy();
  }
}
