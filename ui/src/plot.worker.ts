// The live plot's drawing, off the page's main thread: the page hands it its two canvases
// (transferControlToOffscreen) once, then the channels, the size and one frame of points at a
// time; each frame drawn is answered with `drawn` (the page sends the next only then).

import { StripChart, type Chan, type Frame, type YAxis } from "./strip";

type Msg =
  | { type: "init"; bg: OffscreenCanvas; tr: OffscreenCanvas }
  | { type: "setup"; chans: Chan[]; axes: YAxis[] }
  | { type: "size"; w: number; h: number; dpr: number }
  | ({ type: "frame" } & Frame);

const scope = self as unknown as { onmessage: (e: MessageEvent<Msg>) => void; postMessage(m: unknown, t: Transferable[]): void };
let chart: StripChart | null = null;

scope.onmessage = (e) => {
  const m = e.data;
  if (m.type === "init") chart = new StripChart(m.bg.getContext("2d")!, m.tr.getContext("2d")!);
  else if (m.type === "setup") chart?.setup(m.chans, m.axes);
  else if (m.type === "size") chart?.size(m.w, m.h, m.dpr);
  else if (m.type === "frame") {
    const t0 = performance.now();
    chart?.draw(m);
    // The buffer back to the page (the points on show; reused for a later frame).
    const f: Frame = { upTo: m.upTo, x0: m.x0, x1: m.x1, n: m.n, stride: m.stride, buf: m.buf };
    scope.postMessage({ type: "drawn", f, ms: performance.now() - t0 }, [m.buf.buffer]);
  }
};
