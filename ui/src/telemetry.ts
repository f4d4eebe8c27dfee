// Telemetry kept whole (every sample the drive sent, up to CAPACITY) and drawn decimated.

import uPlot from "uplot";
import type { TelSink } from "./protocol";
import { fmtQty } from "./units";
import { AXIS_W, StripChart, fmtTick, plotBox, unitGroups, type Chan, type Frame, type YAxis } from "./strip";

/** Samples kept per channel: over two minutes at the firmware's highest rate (2 kHz). */
export const CAPACITY = 1 << 18;
/** Buckets of min/max kept between frames (twice the widest plot in pixel columns). */
const BUCKETS = 8192;
/** Shortest time between two frames of the live plot (ms): at most 62 frames/s. */
const FRAME_MS = 16;

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

/**
 * uPlot's series, scales and y axes for channels on one time axis (`unitGroups`: one scale
 * per unit, its axis labelled with the unit, alternating left and right and drawn in its first
 * channel's colour); values in the legend with their unit.
 */
export function unitAxes(channels: string[]): { series: uPlot.Series[]; scales: uPlot.Scales; axes: uPlot.Axis[] } {
  const g = unitGroups(channels);
  const scales: uPlot.Scales = {};
  const axes: uPlot.Axis[] = g.axes.map((a, i) => {
    scales[a.scale] = { auto: true };
    return { scale: a.scale, side: a.side, label: a.label, stroke: a.color, size: AXIS_W, grid: { show: i === 0 }, values: (_u, v) => v.map((x) => fmtTick(x)) };
  });
  const series: uPlot.Series[] = g.chans.map((c) => ({ label: c.label, scale: c.scale, stroke: c.color, width: 1, points: { show: false }, value: (_u, v) => (v == null ? "–" : fmtQty(v, c.unit)) }));
  return { series, scales, axes };
}

/** Height of the plots' drawing area (the legend goes below it, inside the panel). */
export const PLOT_HEIGHT = 400;

/**
 * Several channels on one time axis. Following the stream, the last `span` seconds are drawn
 * once per frame from min/max per pixel column by a `StripChart` in a Web Worker, on canvases
 * handed to it (`transferControlToOffscreen`): the page's main thread only cuts the points and
 * posts them. Paused, uPlot draws every sample of the window (drag to zoom, double-click to
 * reset, values under the cursor).
 */
export class LivePlot {
  /** The paused view (null while following the stream). */
  u: uPlot | null = null;
  paused = false;
  /** Seconds shown while following the stream. */
  span = 10;
  /** Samples in the last frame drawn (the test compares it with the store's count). */
  drawnUpTo = 0;
  /** Frames drawn (a frame in which no sample arrived is not redrawn). */
  frames = 0;
  /** The points of the last frame drawn: times, then each channel's. */
  get points(): Float64Array[] {
    const f = this.last;
    if (!f) return [];
    return Array.from({ length: this.chans.length + 1 }, (_, k) => f.buf.subarray(k * f.stride, k * f.stride + f.n));
  }
  private last: Frame | null = null;
  /** Point buffers not in use. */
  private pool: Float64Array[] = [];
  /** Pixel columns (CSS px) of the plotting area: one bucket of samples each. */
  cols = 0;
  /** The worker's drawing time, summed over the frames (ms). */
  drawMs = 0;
  private dirty = false;
  /** Frames handed to the worker and not yet drawn: at most two (the next waits for one). */
  private pending = 0;
  private timer = 0;
  /** When the last frame was cut (performance.now(), ms). */
  private lastCut = 0;
  private live: HTMLDivElement;
  private bgCv: HTMLCanvasElement;
  private trCv: HTMLCanvasElement;
  private legend: HTMLDivElement;
  private pausedEl: HTMLDivElement;
  private worker: Worker | null = null;
  /** Without OffscreenCanvas: the same chart drawn on the main thread. */
  private local: StripChart | null = null;
  private chans: Chan[] = [];
  private axes: YAxis[] = [];
  private w = 0;

  constructor(private el: HTMLElement, private store: TelStore) {
    this.live = document.createElement("div");
    this.live.style.cssText = `position:relative;height:${PLOT_HEIGHT}px`;
    this.bgCv = document.createElement("canvas");
    this.trCv = document.createElement("canvas");
    this.bgCv.style.cssText = "position:absolute;left:0;top:0";
    this.trCv.style.cssText = "position:absolute;transform-origin:0 0;transform:matrix(0,1,1,0,0,0);pointer-events:none";
    this.live.append(this.bgCv, this.trCv);
    this.legend = document.createElement("div");
    this.legend.className = "strip-legend";
    this.pausedEl = document.createElement("div");
    this.pausedEl.hidden = true;
    el.append(this.live, this.legend, this.pausedEl);
    if ("transferControlToOffscreen" in this.bgCv) {
      try {
        const bg = this.bgCv.transferControlToOffscreen(), tr = this.trCv.transferControlToOffscreen();
        this.worker = new Worker(new URL("./plot.worker.ts", import.meta.url), { type: "module" });
        this.worker.postMessage({ type: "init", bg, tr }, [bg, tr]);
        this.worker.onmessage = (e: MessageEvent<{ type: string; f: Frame; ms: number }>) => {
          if (e.data.type !== "drawn") return;
          this.drawMs += e.data.ms;
          this.pending--;
          this.drawn(e.data.f);
          if (this.dirty) this.changed();
        };
      } catch {
        this.worker = null;
      }
    }
    if (!this.worker) {
      // The canvases were not transferred (an older browser): draw them here.
      this.bgCv = this.bgCv.cloneNode() as HTMLCanvasElement;
      this.trCv = this.trCv.cloneNode() as HTMLCanvasElement;
      this.live.replaceChildren(this.bgCv, this.trCv);
      this.local = new StripChart(this.bgCv.getContext("2d")!, this.trCv.getContext("2d")!);
    }
    new ResizeObserver(() => {
      if (this.el.clientWidth !== this.w) { this.w = this.el.clientWidth; this.resize(); }
    }).observe(el);
  }

  private post(m: Record<string, unknown>): void {
    if (this.worker) this.worker.postMessage(m);
    else if (m.type === "setup") this.local!.setup(this.chans, this.axes);
    else if (m.type === "size") this.local!.size(m.w as number, m.h as number, m.dpr as number);
  }

  private resize(): void {
    const w = Math.max(300, this.el.clientWidth - 8), h = PLOT_HEIGHT;
    const b = plotBox(w, h, this.axes);
    this.cols = Math.floor(b.width);
    this.bgCv.style.width = w + "px";
    this.bgCv.style.height = h + "px";
    // Transposed into place: its width is the plotting area's height.
    Object.assign(this.trCv.style, { left: b.left + "px", top: b.top + "px", width: b.height + "px", height: b.width + "px" });
    this.post({ type: "size", w, h, dpr: devicePixelRatio });
    this.u?.setSize({ width: w, height: h });
    this.changed();
  }

  rebuild(): void {
    const s = this.store;
    const g = unitGroups(s.channels);
    this.chans = g.chans;
    this.axes = g.axes;
    this.post({ type: "setup", chans: this.chans, axes: this.axes });
    this.legend.replaceChildren(
      ...this.chans.map((c) => {
        const e = document.createElement("span");
        const m = document.createElement("i");
        m.style.background = c.color;
        e.append(m, c.unit ? `${c.label} (${c.unit})` : c.label);
        return e;
      }),
    );
    this.resize();
    // A new stream counts its samples from 0 again: no bucket of the last one is reused.
    this.per = 0;
    this.key.fill(-1);
    this.changed();
    if (this.paused) this.pause(true);
  }

  /**
   * Samples arrived (or the view changed): a frame is cut at most FRAME_MS after the last one,
   * on a timer, not on the page's animation frames (those would have the main thread run
   * Chrome's frame pipeline every display frame; the worker's canvases need none of it).
   */
  changed(): void {
    this.dirty = true;
    if (this.timer || this.paused || this.pending >= 2) return;
    this.timer = setTimeout(() => {
      this.timer = 0;
      if (this.dirty && !this.paused && this.pending < 2) this.draw();
    }, Math.max(0, FRAME_MS - (performance.now() - this.lastCut)));
  }

  /** Paused: uPlot with every sample of the window; resumed: the live chart again. */
  pause(on: boolean): void {
    this.paused = on;
    this.u?.destroy();
    this.u = null;
    this.pausedEl.textContent = "";
    this.pausedEl.hidden = !on;
    this.live.hidden = on;
    this.legend.hidden = on;
    if (!on) { this.changed(); return; }
    const s = this.store, M = CAPACITY - 1;
    const [lo, b] = this.window();
    const xs = new Float64Array(b - lo);
    const ys = s.channels.map(() => new Float64Array(b - lo));
    for (let j = lo; j < b; j++) {
      xs[j - lo] = s.t[j & M];
      for (let k = 0; k < ys.length; k++) ys[k][j - lo] = s.v[k][j & M];
    }
    const ua = unitAxes(s.channels);
    this.u = new uPlot(
      {
        width: Math.max(300, this.el.clientWidth - 8),
        height: PLOT_HEIGHT,
        series: [{ label: "t", value: (_u, v) => (v == null ? "–" : v.toFixed(4) + " s") }, ...ua.series],
        scales: { x: { time: false }, ...ua.scales },
        axes: [{ label: "t since tel (s)" }, ...ua.axes],
        cursor: { drag: { x: true, y: false, setScale: true } },
        legend: { live: true },
      },
      [xs, ...ys] as unknown as uPlot.AlignedData,
      this.pausedEl,
    );
  }

  /** Index range [lo, b) of the held samples in the last `span` seconds. */
  private window(): [number, number] {
    const s = this.store, M = CAPACITY - 1;
    const [a, b] = s.held();
    if (b === a) return [a, b];
    const t0 = s.t[(b - 1) & M] - this.span;
    // First sample inside the window (binary search on the ring).
    let lo = a, hi = b - 1;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (s.t[mid & M] < t0) lo = mid + 1;
      else hi = mid;
    }
    return [lo, b];
  }

  /**
   * Min/max of whole buckets (`per` samples, aligned on the sample count) already computed,
   * a ring keyed by bucket number: a frame computes only the buckets completed since the last.
   */
  private per = 0;
  private key = new Float64Array(BUCKETS).fill(-1);
  private bt = new Float64Array(2 * BUCKETS);
  private bv: Float64Array[] = [];

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

  /** The last `span` seconds, at most two points (min and max) per pixel column per channel, handed to the drawing. */
  draw(): void {
    const s = this.store;
    this.dirty = false;
    this.lastCut = performance.now();
    const [lo, b] = this.window();
    if (b === lo) return;
    const M = CAPACITY - 1;
    const K = s.channels.length;
    const tEnd = s.t[(b - 1) & M];
    const cols = Math.min(BUCKETS >> 1, Math.max(100, this.cols));
    const per = Math.max(1, Math.ceil((b - lo) / cols));
    if (per !== this.per || this.bv.length !== K) {
      this.per = per;
      this.key.fill(-1);
      this.bv = s.channels.map(() => new Float64Array(2 * BUCKETS));
    }
    // The points go into one buffer (times, then each channel's, `stride` apart), handed to the
    // worker and back without a copy.
    const need = 2 * (Math.ceil((b - lo) / per) + 2);
    let buf = this.pool.pop();
    if (!buf || buf.length < (K + 1) * need) buf = new Float64Array(2 * (K + 1) * need);
    const stride = Math.floor(buf.length / (K + 1));
    const xs = buf.subarray(0, stride), ys = s.channels.map((_, k) => buf.subarray((k + 1) * stride, (k + 2) * stride));
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
    const f: Frame = { upTo: b, x0: tEnd - this.span, x1: tEnd, n, stride, buf };
    if (this.worker) {
      this.pending++;
      this.worker.postMessage({ type: "frame", ...f }, [buf.buffer]);
    } else {
      this.local!.draw(f);
      this.drawn(f);
    }
  }

  /** A frame drawn: its buffer kept as the points on show, the one before back to the pool. */
  private drawn(f: Frame): void {
    if (this.last) this.pool.push(this.last.buf);
    this.last = f;
    this.drawnUpTo = f.upTo;
    this.frames++;
  }
}
