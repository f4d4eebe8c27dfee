// The live strip chart: the last seconds of the stream drawn from min/max points, DOM-free so a
// Web Worker draws it on OffscreenCanvases (plot.worker.ts) and the page's main thread does not.
// uPlot needs the DOM (it builds its legend, cursor and canvas itself), so it cannot run in a
// worker; it draws the paused view, the capture and the harvest (docs/ui.md, Performance).

import { unitOf } from "./units";

export const COLORS = ["#1f6fd1", "#d1461f", "#2c9a4b", "#8d44c9", "#c28a00", "#0b9aa6", "#b8336a", "#5c6670"];

/** A channel drawn: its name, colour and the scale (one per unit) it is drawn against. */
export interface Chan {
  label: string;
  scale: string;
  color: string;
  unit: string;
}
/** A y axis: one per unit, alternating left (3) and right (1), in its first channel's colour. */
export interface YAxis {
  scale: string;
  label: string;
  side: 1 | 3;
  color: string;
}

/** Channels on one time axis: one scale and y axis per unit (currents share one, …). */
export function unitGroups(channels: string[]): { chans: Chan[]; axes: YAxis[] } {
  const chans: Chan[] = [];
  const axes: YAxis[] = [];
  channels.forEach((c, k) => {
    const unit = unitOf(c);
    const scale = unit ? "u:" + unit : "c:" + c;
    const color = COLORS[k % COLORS.length];
    if (!axes.some((a) => a.scale === scale)) axes.push({ scale, label: unit || c, side: axes.length % 2 === 0 ? 3 : 1, color });
    chans.push({ label: c, scale, color, unit });
  });
  return { chans, axes };
}

/** An axis tick: short, no prefix (the axis label carries the unit). */
export function fmtTick(x: number): string {
  const a = Math.abs(x);
  if (a !== 0 && (a >= 1e5 || a < 1e-3)) return x.toExponential(1);
  return String(Number(x.toPrecision(6)));
}

/** Width of a y axis, height of the x axis, padding on the sides without one (CSS px). */
export const AXIS_W = 62;
export const X_AXIS_H = 50;
const PAD = 10;

/** The plotting area inside a chart of w × h CSS px with these y axes. */
export function plotBox(w: number, h: number, axes: YAxis[]): { left: number; top: number; width: number; height: number } {
  const nl = axes.filter((a) => a.side === 3).length, nr = axes.length - nl;
  const left = nl ? nl * AXIS_W : PAD, right = nr ? nr * AXIS_W : PAD;
  return { left, top: PAD, width: Math.max(1, w - left - right), height: Math.max(1, h - PAD - X_AXIS_H) };
}

/** The smallest of 1, 2, 2.5, 5 × 10^k at least `x`. */
function niceStep(x: number): number {
  const e = Math.pow(10, Math.floor(Math.log10(x)));
  for (const m of [1, 2, 2.5, 5, 10]) if (m * e >= x * (1 - 1e-9)) return m * e;
  return 10 * e;
}

/** A y range around [mn, mx] padded by 10 % and widened to whole ticks (at least `px` apart). */
function yRange(mn: number, mx: number, hCss: number): { lo: number; hi: number; step: number } {
  if (!(mn <= mx)) return { lo: 0, hi: 1, step: 0.2 };
  let pad = (mx - mn) * 0.1;
  if (pad === 0) pad = Math.abs(mx) * 0.1 || 1;
  const ticks = Math.max(2, Math.floor(hCss / 40));
  const step = niceStep((mx - mn + 2 * pad) / ticks);
  return { lo: Math.floor((mn - pad) / step) * step, hi: Math.ceil((mx + pad) / step) * step, step };
}

/** `#rrggbb` as a pixel of an ImageData's Uint32Array (little-endian RGBA), opaque. */
function pixel(hex: string): number {
  const n = parseInt(hex.slice(1), 16);
  return (0xff000000 | ((n & 0xff) << 16) | (n & 0xff00) | ((n >> 16) & 0xff)) >>> 0;
}

type Ctx = OffscreenCanvasRenderingContext2D | CanvasRenderingContext2D;

/**
 * One frame: the time window [x0, x1] and `n` points (min and max per pixel column) in `buf`:
 * their times from 0, then each channel's from `stride`, `2·stride`, …; `upTo` the samples
 * received when it was cut.
 */
export interface Frame {
  upTo: number;
  x0: number;
  x1: number;
  n: number;
  stride: number;
  buf: Float64Array;
}

/**
 * Axes, grid and labels on one canvas (`bg`), the traces on another over the plotting area
 * (`tr`). The traces are drawn as an oscilloscope draws them: in each pixel column every pixel
 * from the lowest to the highest point falling in it, joined to the previous column's last
 * point (peaks kept), written into a column-major pixel buffer (a column's span is one run of
 * `Uint32Array.fill`) and put once per frame on `tr`, which the page turns into place by a CSS
 * transposition. Stroking a line through the same points costs several times more
 * (docs/ui.md, Performance).
 */
export class StripChart {
  private chans: Chan[] = [];
  private axes: YAxis[] = [];
  private w = 300;
  private h = 200;
  private dpr = 1;
  private img: ImageData | null = null;
  private buf = new Uint32Array(0);
  private px: number[] = [];

  constructor(private bg: Ctx, private tr: Ctx) {}

  setup(chans: Chan[], axes: YAxis[]): void {
    this.chans = chans;
    this.axes = axes;
    this.px = chans.map((c) => pixel(c.color));
    this.resize();
  }

  size(w: number, h: number, dpr: number): void {
    this.w = w;
    this.h = h;
    this.dpr = dpr;
    this.resize();
  }

  private resize(): void {
    const b = plotBox(this.w, this.h, this.axes), r = this.dpr;
    this.bg.canvas.width = Math.round(this.w * r);
    this.bg.canvas.height = Math.round(this.h * r);
    // Transposed: a row of this canvas is a pixel column of the plotting area.
    const W = Math.round(b.width * r), H = Math.round(b.height * r);
    this.tr.canvas.width = H;
    this.tr.canvas.height = W;
    this.img = new ImageData(H, W);
    this.buf = new Uint32Array(this.img.data.buffer);
  }

  draw(f: Frame): void {
    const r = this.dpr, c = this.bg;
    const xs = f.buf.subarray(0, f.n), ys = this.chans.map((_, k) => f.buf.subarray((k + 1) * f.stride, (k + 1) * f.stride + f.n));
    const b = plotBox(this.w, this.h, this.axes);
    const L = b.left * r, T = b.top * r, W = Math.round(b.width * r), H = Math.round(b.height * r);
    const ranges = new Map<string, { lo: number; hi: number; step: number }>();
    for (const a of this.axes) {
      let mn = Infinity, mx = -Infinity;
      this.chans.forEach((ch, k) => {
        if (ch.scale !== a.scale) return;
        const y = ys[k];
        for (let i = 0; i < y.length; i++) { const v = y[i]; if (v < mn) mn = v; if (v > mx) mx = v; }
      });
      ranges.set(a.scale, yRange(mn, mx, b.height));
    }
    c.clearRect(0, 0, c.canvas.width, c.canvas.height);
    c.lineWidth = Math.max(1, Math.round(r));
    c.font = `${12 * r}px system-ui, sans-serif`;
    // The time axis: ticks at least 80 CSS px apart, a grid line at each.
    const span = f.x1 - f.x0;
    if (span > 0) {
      const step = niceStep((span * 80) / b.width);
      c.strokeStyle = "rgba(0,0,0,0.07)";
      c.fillStyle = "#1d2329";
      c.textAlign = "center";
      c.textBaseline = "top";
      c.beginPath();
      for (let t = Math.ceil(f.x0 / step) * step; t <= f.x1; t += step) {
        const x = Math.round(L + ((t - f.x0) / span) * W) + 0.5;
        c.moveTo(x, T);
        c.lineTo(x, T + H + 6 * r);
        c.fillText(fmtTick(Number(t.toPrecision(12))), x, T + H + 8 * r);
      }
      c.stroke();
      c.font = `bold ${12 * r}px system-ui, sans-serif`;
      c.fillText("t since tel (s)", L + W / 2, T + H + 30 * r);
    }
    // The y axes, outwards from the plotting area on each side; the first one's grid.
    let nl = 0, nr = 0;
    this.axes.forEach((a, i) => {
      const g = ranges.get(a.scale)!;
      const left = a.side === 3;
      const edge = left ? L - nl++ * AXIS_W * r : L + W + nr++ * AXIS_W * r;
      const dir = left ? -1 : 1;
      c.fillStyle = a.color;
      c.strokeStyle = "rgba(0,0,0,0.07)";
      c.font = `${12 * r}px system-ui, sans-serif`;
      c.textAlign = left ? "right" : "left";
      c.textBaseline = "middle";
      c.beginPath();
      for (let v = g.lo, k = 0; v <= g.hi + g.step * 1e-6; v = g.lo + ++k * g.step) {
        const y = Math.round(T + ((g.hi - v) / (g.hi - g.lo)) * H) + 0.5;
        if (i === 0) { c.moveTo(L, y); c.lineTo(L + W, y); }
        c.moveTo(edge, y);
        c.lineTo(edge + dir * 8 * r, y);
        c.fillText(fmtTick(Number(v.toPrecision(12))), edge + dir * 11 * r, y);
      }
      c.stroke();
      c.save();
      c.translate(edge + dir * (AXIS_W - 10) * r, T + H / 2);
      c.rotate(left ? -Math.PI / 2 : Math.PI / 2);
      c.font = `bold ${12 * r}px system-ui, sans-serif`;
      c.textAlign = "center";
      c.textBaseline = "middle";
      c.fillText(a.label, 0, 0);
      c.restore();
    });
    // The traces.
    const buf = this.buf, img = this.img;
    if (!img || img.width !== H || img.height !== W) return;
    buf.fill(0);
    const kx = W / span;
    if (kx > 0 && kx < Infinity) {
      this.chans.forEach((ch, k) => {
        const g = ranges.get(ch.scale)!;
        this.trace(xs, ys[k], f.x0, kx, g.hi, H / (g.lo - g.hi), W, H, this.px[k], Math.max(1, Math.round(r)));
      });
    }
    this.tr.putImageData(img, 0, 0);
  }

  /** One series into the column-major buffer (W columns of H pixels). */
  private trace(xs: Float64Array, ys: Float64Array, x0: number, kx: number, y0: number, ky: number, W: number, H: number, px: number, lw: number): void {
    const buf = this.buf;
    const span = (c: number, a: number, b: number) => {
      if (c < 0 || c >= W) return;
      const r0 = Math.max(0, Math.round(Math.min(a, b))), r1 = Math.min(H - 1, Math.round(Math.max(a, b)) + lw - 1);
      for (let k = 0; k < lw && c + k < W; k++) buf.fill(px, (c + k) * H + r0, (c + k) * H + r1 + 1);
    };
    let col = -1, lo = 0, hi = 0, last = NaN;
    for (let i = 0; i < ys.length; i++) {
      const v = ys[i];
      if (v !== v) { if (col >= 0) span(col, lo, hi); col = -1; last = NaN; continue; }
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
  }
}
