// The capture view (`cap`, /work CAPTURE spec in docs/console.md): the drive's status line and
// its dump parsed, and the dump drawn on one time axis with t = 0 at the trigger and the
// pre-trigger part shaded.

import uPlot from "uplot";
import { fields } from "./protocol";
import { PLOT_HEIGHT, unitAxes } from "./telemetry";
import { unitOf } from "./units";

/** `cap <state> ch=… div=… dt_s=… n=… pre=… trig=… [t_trig_s=…]`. */
export interface CapStatus {
  state: string;
  f: Record<string, string>;
}

/** The status line among a reply's lines (`D` data first, then the final line's text). */
export function parseCapStatus(lines: string[]): CapStatus | null {
  for (const l of lines) {
    const m = /^cap (\w+)(\s|$)/.exec(l.trim());
    if (m) return { state: m[1], f: fields(l) };
  }
  return null;
}

/** A dump: its header fields, channel names, times (s from the trigger) and columns. */
export interface CapDump {
  head: Record<string, string>;
  channels: string[];
  t: number[];
  v: number[][];
  /** Samples before the trigger (the header's `pre`). */
  pre: number;
  /** The dump's lines as the drive sent them (the CSV export). */
  lines: string[];
}

/** `# cap dt_s=… n=… pre=… trig=…`, `t,c1,…`, then one line per sample; an error names the line. */
export function parseDump(lines: string[]): CapDump {
  const hi = lines.findIndex((l) => l.startsWith("# cap"));
  if (hi < 0) throw new Error("no '# cap' header line in the dump");
  const head = fields(lines[hi].slice(1));
  const cols = (lines[hi + 1] ?? "").split(",");
  if (cols[0] !== "t" || cols.length < 2) throw new Error(`the dump's column line is '${lines[hi + 1] ?? ""}', not 't,<channels>'`);
  const channels = cols.slice(1);
  const t: number[] = [];
  const v: number[][] = channels.map(() => []);
  for (let i = hi + 2; i < lines.length; i++) {
    const s = lines[i].split(",");
    const x = s.map(Number);
    if (s.length !== cols.length || x.some((q) => !Number.isFinite(q))) throw new Error(`dump line ${i + 1} is '${lines[i]}': not ${cols.length} numbers`);
    t.push(x[0]);
    for (let k = 0; k < channels.length; k++) v[k].push(x[k + 1]);
  }
  const n = Number(head.n);
  if (Number.isFinite(n) && n !== t.length) throw new Error(`the dump's header says n=${head.n} but ${t.length} samples came`);
  return { head, channels, t, v, pre: Number(head.pre), lines: lines.slice(hi) };
}

/** A trigger as the drive names it (`iq,fall,-1`) in words: "iq falling through -1 A". */
export function trigText(t: string): string {
  const [ch, edge, level] = t.split(",");
  if (edge === undefined) return t === "cmd" ? "command (Trigger now)" : t;
  const how = ({ rise: "rising", fall: "falling", both: "crossing" } as Record<string, string>)[edge] ?? edge;
  return `${ch} ${how} through ${level} ${unitOf(ch)}`.trim();
}

/** The dump drawn: t in ms from the trigger, t < 0 shaded, t = 0 a red line. */
export class CapPlot {
  u: uPlot | null = null;
  constructor(private el: HTMLElement) {
    let w = 0;
    new ResizeObserver(() => {
      if (this.el.clientWidth !== w) { w = this.el.clientWidth; this.u?.setSize({ width: Math.max(300, w - 8), height: PLOT_HEIGHT }); }
    }).observe(el);
  }

  show(d: CapDump): void {
    this.u?.destroy();
    this.el.textContent = "";
    const ua = unitAxes(d.channels);
    const shade: uPlot.Plugin = {
      hooks: {
        drawClear: (u) => {
          const x0 = u.valToPos(u.scales.x.min ?? 0, "x", true), xt = u.valToPos(0, "x", true);
          const { top, height } = u.bbox;
          const c = u.ctx;
          c.save();
          if (xt > x0) { c.fillStyle = "#eef2f7"; c.fillRect(x0, top, Math.min(xt, u.bbox.left + u.bbox.width) - x0, height); }
          c.restore();
        },
        draw: (u) => {
          const xt = u.valToPos(0, "x", true);
          if (xt < u.bbox.left || xt > u.bbox.left + u.bbox.width) return;
          const c = u.ctx;
          c.save();
          c.strokeStyle = "#c62828";
          c.lineWidth = 1.5 * devicePixelRatio;
          c.setLineDash([6, 4]);
          c.beginPath();
          c.moveTo(xt, u.bbox.top);
          c.lineTo(xt, u.bbox.top + u.bbox.height);
          c.stroke();
          c.fillStyle = "#c62828";
          c.font = `${12 * devicePixelRatio}px system-ui, sans-serif`;
          c.textAlign = "left";
          c.textBaseline = "alphabetic";
          c.fillText(`trigger: ${trigText(d.head.trig ?? "")}`, xt + 4 * devicePixelRatio, u.bbox.top + 14 * devicePixelRatio);
          c.fillStyle = "#68737d";
          c.textAlign = "right";
          if (d.pre > 0) c.fillText(`pre-trigger: ${d.pre} samples`, xt - 4 * devicePixelRatio, u.bbox.top + 14 * devicePixelRatio);
          c.restore();
        },
      },
    };
    this.u = new uPlot(
      {
        width: Math.max(300, this.el.clientWidth - 8),
        height: PLOT_HEIGHT,
        plugins: [shade],
        series: [{ label: "t", value: (_u, v) => (v == null ? "–" : v.toFixed(3) + " ms") }, ...ua.series.map((s) => ({ ...s, points: { show: d.t.length <= 200, size: 4 } }))],
        scales: { x: { time: false }, ...ua.scales },
        axes: [{ label: "t from the trigger (ms)" }, ...ua.axes],
        cursor: { drag: { x: true, y: false, setScale: true } },
      },
      [d.t.map((x) => x * 1e3), ...d.v] as unknown as uPlot.AlignedData,
      this.el,
    );
  }
}
