// Telemetry kept whole (every sample the drive sent, up to CAPACITY) and drawn decimated.

import uPlot from "uplot";
import type { TelSink } from "./protocol";
import { fmtQty, unitOf } from "./units";

/** Samples kept per channel: over two minutes at the firmware's highest rate (2 kHz). */
export const CAPACITY = 1 << 18;
/** Buckets of min/max kept between frames (twice the widest plot in pixel columns). */
const BUCKETS = 8192;

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

const linear = uPlot.paths.linear!();

/** `#rrggbb` as a pixel of an ImageData's Uint32Array (little-endian RGBA), opaque. */
function pixel(hex: string): number {
  const n = parseInt(hex.slice(1), 16);
  return (0xff000000 | ((n & 0xff) << 16) | (n & 0xff00) | ((n >> 16) & 0xff)) >>> 0;
}

/**
 * Series drawn as an oscilloscope draws a trace: into a pixel buffer of the plotting area, in
 * each pixel column every pixel from the lowest to the highest point falling in it, extended to
 * the previous column's last point so the trace stays joined (peaks kept). The buffer is put,
 * once per redraw, on a canvas of its own over the plotting area: column-major (a column's span
 * is one contiguous run of the buffer), the canvas turned into place by a CSS transposition.
 * Stroking a line through the same points costs several times more (docs/ui.md, Performance).
 * With fewer points than pixel columns (zoomed in) a series is drawn by uPlot's own line.
 */
export function tracePlugin(): uPlot.Plugin {
  let img: ImageData | null = null;
  let buf = new Uint32Array(0);
  let cv: HTMLCanvasElement | null = null;
  const paths: uPlot.Series.PathBuilder = (u, si, i0, i1) => {
    const { width: W, height: H } = u.bbox;
    // Fewer points than CSS pixel columns (the plot is handed two per column): a line.
    if (i1 - i0 + 1 < W / devicePixelRatio || !img) return linear(u, si, i0, i1);
    const xs = u.data[0], ys = u.data[si];
    const s = u.series[si];
    const sx = u.scales.x, sy = u.scales[s.scale!];
    const x0 = sx.min!, kx = W / (sx.max! - x0);
    const y0 = sy.max!, ky = H / (sy.min! - y0);
    if (!(kx > 0 && kx < Infinity && ky < 0 && ky > -Infinity)) return linear(u, si, i0, i1);
    const px = pixel((s as unknown as { _stroke: string })._stroke);
    const lw = Math.max(1, Math.round(devicePixelRatio));
    const span = (c: number, a: number, b: number) => {
      if (c < 0 || c >= W) return;
      const r0 = Math.max(0, Math.round(Math.min(a, b))), r1 = Math.min(H - 1, Math.round(Math.max(a, b)) + lw - 1);
      for (let k = 0; k < lw && c + k < W; k++) buf.fill(px, (c + k) * H + r0, (c + k) * H + r1 + 1);
    };
    let col = -1, lo = 0, hi = 0, last = NaN;
    for (let i = i0; i <= i1; i++) {
      const v = ys[i];
      if (v == null || v !== v) { if (col >= 0) span(col, lo, hi); col = -1; last = NaN; continue; }
      const x = Math.floor((xs[i] - x0) * kx);
      const y = (v - y0) * ky;
      if (x !== col) {
        if (col >= 0) span(col, lo, hi);
        // Columns no point fell in (a bucket wider than a pixel): the straight line between.
        if (last === last && col >= 0 && x - col > 1) {
          const ya = last;
          for (let c = col + 1; c < x; c++) {
            const yc = ya + ((y - ya) * (c - col)) / (x - col);
            span(c, last, yc);
            last = yc;
          }
        }
        col = x;
        lo = hi = last === last ? last : y;
      }
      if (y < lo) lo = y;
      if (y > hi) hi = y;
      last = y;
    }
    if (col >= 0) span(col, lo, hi);
    return { stroke: null, fill: null, clip: null, band: null, gaps: null, flags: 0, _width: 0 } as unknown as uPlot.Series.Paths;
  };
  return {
    opts: (_u, o) => {
      o.series.forEach((s, i) => { if (i > 0) s.paths = paths; });
    },
    hooks: {
      drawClear: (u) => {
        const { width: W, height: H } = u.bbox;
        if (W <= 0 || H <= 0) { img = null; return; }
        if (!img || img.width !== H || img.height !== W) {
          img = new ImageData(H, W);
          buf = new Uint32Array(img.data.buffer);
          cv?.remove();
          cv = document.createElement("canvas");
          cv.width = H;
          cv.height = W;
          const r = devicePixelRatio;
          cv.style.cssText = `position:absolute;left:0;top:0;width:${H / r}px;height:${W / r}px;transform-origin:0 0;transform:matrix(0,1,1,0,0,0);pointer-events:none`;
          u.over.prepend(cv);
        } else buf.fill(0);
        // Every redraw rebuilds the traces (uPlot keeps a series' paths between redraws).
        u.series.forEach((s, i) => { if (i > 0) (s as unknown as { _paths: unknown })._paths = null; });
      },
      draw: () => {
        if (!img || !cv) return;
        cv.getContext("2d")!.putImageData(img, 0, 0);
      },
    },
  };
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
        plugins: [tracePlugin()],
      },
      [[], ...s.channels.map(() => [])] as unknown as uPlot.AlignedData,
      this.el,
    );
    // A new stream counts its samples from 0 again: no bucket of the last one is reused.
    this.per = 0;
    this.key.fill(-1);
    this.dirty = true;
  }

  changed(): void {
    this.dirty = true;
  }

  /**
   * Min/max of whole buckets (`per` samples, aligned on the sample count) already computed,
   * a ring keyed by bucket number: a frame computes only the buckets completed since the last.
   */
  private per = 0;
  private key = new Float64Array(BUCKETS).fill(-1);
  private bt = new Float64Array(2 * BUCKETS);
  private bv: Float64Array[] = [];
  /** The arrays handed to uPlot (views of these), reused from frame to frame. */
  private xs = new Float64Array(0);
  private ys: Float64Array[] = [];

  /** One bucket [j, e) into xs/ys at point index o (two points: min and max in time order). */
  private bucket(j: number, e: number, xs: Float64Array, ys: Float64Array[], o: number): void {
    const s = this.store;
    const M = CAPACITY - 1;
    xs[o] = s.t[j & M];
    xs[o + 1] = s.t[(e - 1) & M];
    for (let k = 0; k < ys.length; k++) {
      const c = s.v[k];
      let mn = Infinity, mx = -Infinity, imn = j, imx = j;
      for (let q = j; q < e; q++) {
        const x = c[q & M];
        if (x < mn) { mn = x; imn = q; }
        if (x > mx) { mx = x; imx = q; }
      }
      // A bucket of NaNs (a channel the drive did not send) stays NaN: a gap in the trace.
      if (mn > mx) mn = mx = NaN;
      ys[k][o] = imn <= imx ? mn : mx;
      ys[k][o + 1] = imn <= imx ? mx : mn;
    }
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
    const K = s.channels.length;
    const tEnd = s.t[(b - 1) & M];
    const t0 = tEnd - this.span;
    // First sample inside the window (binary search on the ring).
    let lo = a, hi = b - 1;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (s.t[mid & M] < t0) lo = mid + 1;
      else hi = mid;
    }
    const cols = Math.min(BUCKETS >> 1, Math.max(100, Math.floor(u.bbox.width / devicePixelRatio)));
    const per = Math.max(1, Math.ceil((b - lo) / cols));
    if (per !== this.per || this.bv.length !== K) {
      this.per = per;
      this.key.fill(-1);
      this.bv = s.channels.map(() => new Float64Array(2 * BUCKETS));
    }
    const need = 2 * (Math.ceil((b - lo) / per) + 2);
    if (this.xs.length < need || this.ys.length !== K) {
      this.xs = new Float64Array(2 * need);
      this.ys = s.channels.map(() => new Float64Array(2 * need));
    }
    const xs = this.xs, ys = this.ys;
    let n = 0;
    if (per === 1) {
      for (let j = lo; j < b; j++, n++) {
        xs[n] = s.t[j & M];
        for (let k = 0; k < K; k++) ys[k][n] = s.v[k][j & M];
      }
    } else {
      // The first bucket cut at the window's start and the last, still filling, computed every
      // frame; the whole ones in between from the ring.
      const q0 = Math.floor(lo / per), q1 = Math.floor(b / per);
      for (let q = q0; q <= q1; q++) {
        const j = Math.max(lo, q * per), e = Math.min(b, (q + 1) * per);
        if (j >= e) continue;
        if (j === q * per && e === (q + 1) * per) {
          const r = q % BUCKETS;
          if (this.key[r] !== q) {
            this.bucket(j, e, this.bt.subarray(2 * r, 2 * r + 2), this.bv.map((c) => c.subarray(2 * r, 2 * r + 2)), 0);
            this.key[r] = q;
          }
          xs[n] = this.bt[2 * r];
          xs[n + 1] = this.bt[2 * r + 1];
          for (let k = 0; k < K; k++) { ys[k][n] = this.bv[k][2 * r]; ys[k][n + 1] = this.bv[k][2 * r + 1]; }
        } else {
          this.bucket(j, e, xs, ys, n);
        }
        n += 2;
      }
    }
    u.setData([xs.subarray(0, n), ...ys.map((c) => c.subarray(0, n))] as unknown as uPlot.AlignedData, true);
  }
}
