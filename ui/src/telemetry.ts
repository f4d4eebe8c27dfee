// Telemetry kept whole (every sample the drive sent, up to CAPACITY) and drawn decimated.

import uPlot from "uplot";
import type { TelSink } from "./protocol";
import { fmtQty, unitOf } from "./units";

/** Samples kept per channel: over two minutes at the firmware's highest rate (2 kHz). */
export const CAPACITY = 1 << 18;

export class TelStore implements TelSink {
  channels: string[] = [];
  t = new Float64Array(CAPACITY);
  v: Float64Array[] = [];
  /** Samples received since the header (may exceed CAPACITY: the oldest are overwritten). */
  n = 0;
  /** Samples whose time step was more than 1.5 periods (a lost sample), and the period. */
  gaps = 0;
  period = 0;
  onHeader: () => void = () => {};

  header(channels: string[]): void {
    this.channels = channels;
    this.v = channels.map(() => new Float64Array(CAPACITY));
    this.n = 0;
    this.gaps = 0;
    this.onHeader();
  }

  sample(t: number, v: number[]): void {
    const i = this.n & (CAPACITY - 1);
    if (this.n > 0 && this.period > 0) {
      const prev = this.t[(this.n - 1) & (CAPACITY - 1)];
      if (t - prev > 1.5 * this.period) this.gaps++;
    }
    this.t[i] = t;
    for (let k = 0; k < this.v.length; k++) this.v[k][i] = v[k] ?? NaN;
    this.n++;
  }

  /** Index range [a, b) of the samples still held. */
  held(): [number, number] {
    return [Math.max(0, this.n - CAPACITY), this.n];
  }

  /** Every held sample as CSV: `t,ch1,…` then one line per sample. */
  csv(): string {
    const [a, b] = this.held();
    const out: string[] = ["t," + this.channels.join(",")];
    for (let j = a; j < b; j++) {
      const i = j & (CAPACITY - 1);
      let l = String(this.t[i]);
      for (const c of this.v) l += "," + String(c[i]);
      out.push(l);
    }
    return out.join("\n") + "\n";
  }
}

export const COLORS = ["#1f6fd1", "#d1461f", "#2c9a4b", "#8d44c9", "#c28a00", "#0b9aa6", "#b8336a", "#5c6670"];

/**
 * Series, scales and y axes for channels on one time axis: one scale per unit (currents in A
 * share one, voltages another, …), its axis labelled with the unit, alternating left and right
 * and drawn in its first channel's colour; values in the legend with their unit.
 */
export function unitAxes(channels: string[]): { series: uPlot.Series[]; scales: uPlot.Scales; axes: uPlot.Axis[] } {
  const units: string[] = [];
  const series: uPlot.Series[] = [];
  const axes: uPlot.Axis[] = [];
  const scales: uPlot.Scales = {};
  channels.forEach((c, k) => {
    const unit = unitOf(c);
    const scale = unit ? "u:" + unit : "c:" + c;
    const stroke = COLORS[k % COLORS.length];
    if (!(scale in scales)) {
      scales[scale] = { auto: true };
      const side = units.length % 2 === 0 ? 3 : 1;
      units.push(scale);
      axes.push({ scale, side, label: unit || c, stroke, size: 62, grid: { show: units.length === 1 }, values: (_u, v) => v.map((x) => fmtTick(x)) });
    }
    series.push({ label: c, scale, stroke, width: 1, points: { show: false }, value: (_u, v) => (v == null ? "–" : fmtQty(v, unit)) });
  });
  return { series, scales, axes };
}

/** An axis tick: short, no prefix (the axis label carries the unit). */
function fmtTick(x: number): string {
  const a = Math.abs(x);
  if (a !== 0 && (a >= 1e5 || a < 1e-3)) return x.toExponential(1);
  return String(Number(x.toPrecision(6)));
}

/** Height of the plots' drawing area (the legend goes below it, inside the panel). */
export const PLOT_HEIGHT = 400;

/** Several channels on one time axis, redrawn once per frame from min/max per pixel column. */
export class LivePlot {
  u: uPlot | null = null;
  paused = false;
  /** Seconds shown while following the stream. */
  span = 10;
  shown: boolean[] = [];
  /** Samples that reached the plot's data (the test compares it with the store's count). */
  drawnUpTo = 0;
  frames = 0;
  private dirty = false;

  constructor(private el: HTMLElement, private store: TelStore) {
    const tick = () => {
      this.frames++;
      if (this.dirty && !this.paused) this.draw();
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
    let w = 0;
    new ResizeObserver(() => {
      if (this.el.clientWidth !== w) { w = this.el.clientWidth; this.u?.setSize(this.size()); }
    }).observe(el);
  }

  private size() {
    return { width: Math.max(300, this.el.clientWidth - 8), height: PLOT_HEIGHT };
  }

  rebuild(): void {
    this.u?.destroy();
    this.el.textContent = "";
    const s = this.store;
    this.shown = s.channels.map(() => true);
    const ua = unitAxes(s.channels);
    this.u = new uPlot(
      {
        ...this.size(),
        series: [{ label: "t", value: (_u, v) => (v == null ? "–" : v.toFixed(4) + " s") }, ...ua.series],
        scales: { x: { time: false }, ...ua.scales },
        axes: [{ label: "t since tel (s)" }, ...ua.axes],
        cursor: { drag: { x: true, y: false, setScale: true } },
        legend: { live: true },
      },
      [[], ...s.channels.map(() => [])] as unknown as uPlot.AlignedData,
      this.el,
    );
    this.dirty = true;
  }

  changed(): void {
    this.dirty = true;
  }

  /** The last `span` seconds, at most two points (min and max) per pixel column per channel. */
  draw(): void {
    const s = this.store;
    const u = this.u;
    if (!u) return;
    this.dirty = false;
    const [a, b] = s.held();
    this.drawnUpTo = b;
    if (b === a) return;
    const M = CAPACITY - 1;
    const tEnd = s.t[(b - 1) & M];
    const t0 = tEnd - this.span;
    // First sample inside the window (binary search on the ring).
    let lo = a, hi = b - 1;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (s.t[mid & M] < t0) lo = mid + 1;
      else hi = mid;
    }
    const cols = Math.max(100, Math.floor(u.bbox.width / devicePixelRatio));
    const per = Math.max(1, Math.ceil((b - lo) / cols));
    const xs: number[] = [];
    const ys: (number | null)[][] = s.channels.map(() => []);
    for (let j = lo; j < b; j += per) {
      const e = Math.min(b, j + per);
      if (per === 1) {
        xs.push(s.t[j & M]);
        for (let k = 0; k < ys.length; k++) ys[k].push(s.v[k][j & M]);
        continue;
      }
      xs.push(s.t[j & M], s.t[(e - 1) & M]);
      for (let k = 0; k < ys.length; k++) {
        const c = s.v[k];
        let mn = Infinity, mx = -Infinity, imn = j, imx = j;
        for (let q = j; q < e; q++) {
          const x = c[q & M];
          if (x < mn) { mn = x; imn = q; }
          if (x > mx) { mx = x; imx = q; }
        }
        if (imn <= imx) ys[k].push(mn, mx);
        else ys[k].push(mx, mn);
      }
    }
    u.setData([xs, ...ys] as unknown as uPlot.AlignedData, true);
  }
}
