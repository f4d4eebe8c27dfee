// The live plot's drawing, off the page's main thread: the page hands it its two canvases
// (transferControlToOffscreen) once, then the channels, the size and one frame of points at a
// time; each frame drawn is answered with `drawn` (the page sends the next only then).

import { StripChart, type Chan, type Frame, type YAxis } from "./strip";

type Msg =
  | { type: "init"; bg: OffscreenCanvas; tr: OffscreenCanvas }
  | { type: "setup"; chans: Chan[]; axes: YAxis[] }
  | { type: "size"; w: number; h: number; dpr: number }
  | ({ type: "frame"; upTo: number } & Frame);

const scope = self as unknown as { onmessage: (e: MessageEvent<Msg>) => void; postMessage(m: unknown): void };
let chart: StripChart | null = null;

scope.onmessage = (e) => {
  const m = e.data;
  if (m.type === "init") chart = new StripChart(m.bg.getContext("2d")!, m.tr.getContext("2d")!);
  else if (m.type === "setup") chart?.setup(m.chans, m.axes);
  else if (m.type === "size") chart?.size(m.w, m.h, m.dpr);
  else if (m.type === "frame") {
    const t0 = performance.now();
    chart?.draw(m);
    scope.postMessage({ type: "drawn", upTo: m.upTo, ms: performance.now() - t0 });
  }
};
