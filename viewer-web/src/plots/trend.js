// A trainee's figures over time: one point per session at its start, peak force on the left axis
// and time in contact on the right (uPlot, two scales), so that progress from one session to the
// next reads at a glance. Redrawn only when the sessions change.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { withCpuCanvases } from './rolling.js';

/**
 * A scale's range that keeps 0 in sight and one value away from the edges: a lone session, or
 * equal figures, still plot in the frame (uPlot's default made 0 to 100 of them).
 * @param {number | null} min @param {number | null} max @returns {uPlot.Range.MinMax}
 */
export function figureRange(min, max) {
  const lo = Math.min(0, min ?? 0), hi = Math.max(max ?? 0, lo);
  if (hi === lo) return [lo, lo + 1];
  return uPlot.rangeNum(lo, hi, 0.1, true);
}

/**
 * A time range (s) around the sessions' starts with room for the points at the ends: a tenth of
 * the span each side, a minute at least.
 * @param {number | null} min @param {number | null} max @returns {uPlot.Range.MinMax}
 */
export function startRange(min, max) {
  const lo = min ?? 0, hi = max ?? lo;
  const pad = Math.max(60, (hi - lo) / 10);
  return [lo - pad, hi + pad];
}

/** Tall enough that the axes' labels with their units fit beside the plot. */
const kHeight = 300;

export class TrendPlot {
  /**
   * @param {HTMLElement} host
   * @param {{forceUnit: string}} units
   */
  constructor(host, units) {
    this.host = host;
    /** The points drawn (the tests read it). */
    this.points = 0;
    const width = Math.max(280, host.clientWidth || 600);
    this.plot = withCpuCanvases(() => new uPlot({
      title: 'Peak force and time in contact per session',
      width,
      height: kHeight,
      scales: { x: { time: true, range: (_u, min, max) => startRange(min, max) },
        force: { range: (_u, min, max) => figureRange(min, max) }, contact: { range: (_u, min, max) => figureRange(min, max) } },
      cursor: { drag: { x: false, y: false } },
      series: [
        { label: 'session start' },
        { label: `peak force (${units.forceUnit})`, scale: 'force', stroke: '#c0392b', width: 1.5, points: { show: true, size: 7 } },
        { label: 'time in contact (s)', scale: 'contact', stroke: '#2471a3', width: 1.5, dash: [6, 4], points: { show: true, size: 7 } },
      ],
      axes: [
        { label: 'session start (local time)' },
        { scale: 'force', label: `peak force (${units.forceUnit})`, size: 56, stroke: '#c0392b', labelFont: '12px system-ui, sans-serif' },
        { scale: 'contact', side: 1, label: 'time in contact (s)', size: 56, stroke: '#2471a3', grid: { show: false },
          labelFont: '12px system-ui, sans-serif' },
      ],
    }, [[], [], []], host));
    this.resizeObserver = new ResizeObserver(() => this.plot.setSize({ width: Math.max(280, host.clientWidth), height: kHeight }));
    this.resizeObserver.observe(host);
  }

  /** @param {{startS: number, peakForce: number, contactS: number}[]} points oldest first */
  setData(points) {
    this.points = points.length;
    this.plot.setData([points.map((p) => p.startS), points.map((p) => p.peakForce), points.map((p) => p.contactS)]);
  }

  dispose() {
    this.resizeObserver.disconnect();
    this.plot.destroy();
  }
}
