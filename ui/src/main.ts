import "uplot/dist/uPlot.min.css";
import "./style.css";
import uPlot from "uplot";
import { Console, fields, type Reply } from "./protocol";
import { SerialTransport, WsTransport, type Transport } from "./transport";
import { LivePlot, TelStore } from "./telemetry";
import { fmtField, fmtQty, splitKey, unitOf } from "./units";
import { CapPlot, parseCapStatus, parseDump, trigText, type CapDump, type CapStatus } from "./capture";

const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
const token = new URLSearchParams(location.search).get("token") ?? "";

let link: Transport | null = null;
let con: Console | null = null;
let mode = "";
const store = new TelStore();
const plot = new LivePlot($("plot"), store);
store.onHeader = () => plot.rebuild();

// Figures the browser suite reads (window.__regen).
const stats = { telReceived: () => store.n, telGaps: () => store.gaps, plotted: () => plot.drawnUpTo, frames: () => plot.frames, drawMs: () => plot.drawMs, rtt: [] as number[], log: [] as string[] };
(window as unknown as { __regen: unknown }).__regen = { stats, store, plot, cap: () => capDump, capPlot: () => capPlot, cmd: (l: string) => send(l) };

// ---------- tabs, modal confirmation, log ----------
document.querySelectorAll<HTMLButtonElement>("#tabs button").forEach((b) =>
  b.addEventListener("click", () => {
    document.querySelectorAll("#tabs button, .panel").forEach((e) => e.classList.remove("on"));
    b.classList.add("on");
    $(b.dataset.tab!).classList.add("on");
    if (b.dataset.tab === "harvest") void harvest();
    if (b.dataset.tab === "capture" && con) void capShow();
  }),
);

function ask(title: string, text: string): Promise<boolean> {
  const d = $<HTMLDialogElement>("confirm");
  $("q-title").textContent = title;
  $("q-text").textContent = text;
  d.showModal();
  return new Promise((res) => d.addEventListener("close", () => res(d.returnValue === "yes"), { once: true }));
}

/** The console log: kept in `stats.log`, shown (last 400 lines) once per frame at most. */
let logShown = true;
function log(l: string): void {
  stats.log.push(l);
  if (stats.log.length > 4000) stats.log.splice(0, 2000);
  if (!logShown) return;
  logShown = false;
  requestAnimationFrame(() => {
    logShown = true;
    const el = $("c-log");
    el.textContent = stats.log.slice(-400).join("\n");
    el.scrollTop = el.scrollHeight;
  });
}

function alarm(text: string | null): void {
  const a = $("alarm");
  a.hidden = text === null;
  a.textContent = text ?? "";
}

// ---------- commands ----------
/** Whether a command moves current (asks first): run, align, short, measure; any set while running. */
function movesCurrent(line: string): string | null {
  const w = line.trim().split(/\s+/);
  if (w[0] === "mode" && ["run", "align", "short"].includes(w[1])) return `mode ${w[1]} drives current through the machine.`;
  if (w[0] === "measure" && (w.length === 1)) return "measure injects current into the machine.";
  if (w[0] === "set" && mode === "run") return `The drive is running: ${w[1]} = ${w[2]} changes the current at once.`;
  return null;
}

async function send(line: string, confirmFirst = true): Promise<Reply> {
  if (!con) return { ok: false, text: "not connected", data: [], sent: 0, done: 0 };
  const why = confirmFirst ? movesCurrent(line) : null;
  if (why && !(await ask(`Send “${line}”?`, why))) return { ok: false, text: "cancelled here (nothing sent)", data: [], sent: 0, done: 0 };
  const r = await con.cmd(line);
  if (r.done) stats.rtt.push(r.done - r.sent);
  return r;
}

// ---------- connection ----------
async function connect(): Promise<void> {
  if (link) { disconnect("disconnected here"); return; }
  const pill = $("link");
  try {
    link = $<HTMLSelectElement>("transport").value === "serial" ? await SerialTransport.open(115200) : await WsTransport.open(token);
  } catch (e) {
    pill.className = "pill bad";
    pill.textContent = (e as Error).message;
    return;
  }
  const c = new Console((t) => link?.send(t));
  con = c;
  c.tel = store;
  c.onLine = log;
  c.onNotice = (t) => {
    if (t.startsWith("cap ")) { capNotice(t); return; }
    void poll();
    if (/fault/i.test(t)) { alarm(`Drive: ${t}`); void readFaults(); }
  };
  c.onBridge = (t) => alarm(`Bridge: ${t}`);
  link.onText = (t) => c.feed(t);
  link.onClose = (why) => {
    const wasRunning = mode === "run";
    disconnect(why);
    alarm(wasRunning ? `CONNECTION LOST WHILE RUNNING (${why}). The drive goes on in mode run with its last settings: reconnect, or stop it at the drive.` : `Connection lost: ${why}`);
  };
  pill.className = "pill on";
  pill.textContent = link.label;
  $("connect").textContent = "Disconnect";
  const r = await c.start();
  if (!r.ok) {
    pill.className = "pill bad";
    pill.textContent = "no machine mode";
    alarm(`The drive's console has no machine mode; its answer to “machine on”: ${r.text}`);
    return;
  }
  alarm(null);
  await poll();
  await loadParams();
  await steps();
}

function disconnect(why: string): void {
  con?.fail(why);
  link?.close();
  link = null;
  con = null;
  $("connect").textContent = "Connect";
  $("link").className = "pill off";
  $("link").textContent = "not connected";
}

$("connect").addEventListener("click", () => void connect());
$("stop").addEventListener("click", () => void send("mode idle", false).then(poll));

// ---------- status ----------
const STATUS_ORDER = ["mode", "boot", "fault", "vbus_v", "speed_rad_s", "travel_m", "id_a", "iq_a", "p_w", "p_avg_w", "p_cycle_w", "cycle_s", "energy_j", "warnings"];
let lastStatus: Record<string, string> = {};

async function poll(): Promise<void> {
  if (!con?.machine) return;
  const r = await send("status", false);
  if (!r.ok) return;
  const f: Record<string, string> = {};
  for (const d of r.data) Object.assign(f, fields(d));
  lastStatus = f;
  mode = f.mode ?? mode;
  const keys = [...STATUS_ORDER.filter((k) => k in f), ...Object.keys(f).filter((k) => !STATUS_ORDER.includes(k))];
  $("status").innerHTML = "";
  for (const k of keys) {
    // Shown with its unit and 4 significant digits; the drive's own text in data-v and the title.
    const s = document.createElement("span");
    s.className = "kv" + (k === "fault" && f[k] !== "none" ? " bad" : "") + (k === "mode" ? " mode-" + f[k] : "");
    s.title = `${k}=${f[k]}`;
    const name = document.createElement("b");
    name.textContent = splitKey(k)[0];
    const v = document.createElement("span");
    v.dataset.k = k;
    v.dataset.v = f[k];
    v.textContent = fmtField(k, f[k]);
    s.append(name, " ", v);
    $("status").append(s);
  }
  renderSteps();
  if (capState === "armed" || capState === "triggered" || $("capture").classList.contains("on")) await capShow();
}
setInterval(() => void poll(), 500);

// ---------- power-up and commissioning ----------
type Step = { name: string; cmd: string | null; what: string; state: () => string; reply?: Reply };
const STEPS: Step[] = [
  { name: "calibrate", cmd: null, what: "current offsets measured with the gates off (0.1 s at power-up)", state: () => (lastStatus.boot === "calibrating" ? "running" : lastStatus.boot ? "done" : "?") },
  { name: "align", cmd: "mode align", what: "finds the commutation angle (moves the rotor a few mm)", state: () => ({ aligning: "running", aligned: "done", stored: "done", unaligned: "to do" })[lastStatus.boot] ?? lastStatus.boot ?? "?" },
  { name: "measure", cmd: "measure", what: "measures R, L_d, L_q, K_e of the machine (idle, calibrated)", state: () => "" },
  { name: "run", cmd: "mode run", what: "emulates the load (the law) and harvests", state: () => (mode === "run" ? "running" : "to do") },
];

function renderSteps(): void {
  const ol = $("steps");
  ol.innerHTML = "";
  for (const s of STEPS) {
    const li = document.createElement("li");
    const st = s.state() || (s.reply ? (s.reply.ok ? "done" : "refused") : "to do");
    li.className = "step st-" + st.replace(/\s/g, "-");
    li.innerHTML = `<div class="sname">${s.name}</div><div class="sstate">${st}</div><div class="swhat"></div><div class="sact"></div><div class="reply"></div>`;
    li.querySelector(".swhat")!.textContent = s.what;
    if (s.cmd) {
      const b = document.createElement("button");
      b.textContent = s.cmd;
      b.addEventListener("click", async () => { s.reply = await send(s.cmd!); await poll(); });
      li.querySelector(".sact")!.append(b);
    }
    if (s.reply) {
      const r = li.querySelector(".reply")!;
      r.textContent = (s.reply.ok ? "ok " : "refused: ") + s.reply.text + (s.reply.data.length ? "\n" + s.reply.data.join("\n") : "");
      r.classList.toggle("err", !s.reply.ok);
    }
    ol.append(li);
  }
}
async function steps(): Promise<void> { renderSteps(); }

// ---------- parameters ----------
type Param = Record<string, string>;
let params: Param[] = [];

async function loadParams(): Promise<void> {
  const r = await send("list", false);
  if (!r.ok) { $("p-info").textContent = r.text; return; }
  params = r.data.map(fields);
  $("p-info").textContent = `${params.length} parameters; ● = in RAM, not what flash holds`;
  renderParams();
}

function renderParams(): void {
  const tb = $("ptable").querySelector("tbody")!;
  const filt = $<HTMLInputElement>("p-filter").value.trim();
  tb.innerHTML = "";
  for (const p of params) {
    if (filt && !p.name.includes(filt)) continue;
    const tr = document.createElement("tr");
    const changed = p.saved === "changed";
    tr.className = changed ? "changed" : "";
    tr.innerHTML = `<td class="name"></td><td><input class="val"><div class="ferr"></div></td><td>${p.unit === "-" ? "" : p.unit}</td><td>${p.min} … ${p.max}</td><td>${p.default}</td><td>${p.when}</td><td>${changed ? "● changed" : "saved"}</td>`;
    tr.querySelector(".name")!.textContent = p.name;
    const inp = tr.querySelector<HTMLInputElement>(".val")!;
    inp.value = p.value;
    inp.dataset.name = p.name;
    inp.addEventListener("keydown", async (e) => {
      if (e.key !== "Enter") return;
      // The Enter's own default (its keypress) would otherwise press the dialog's focused
      // Cancel button the moment `send` opens the confirmation.
      e.preventDefault();
      const err = tr.querySelector(".ferr")!;
      const r = await send(`set ${p.name} ${inp.value.trim()}`);
      err.textContent = r.ok ? "" : r.text;
      inp.classList.toggle("bad", !r.ok);
      if (r.ok) await loadParams();
    });
    tb.append(tr);
  }
}
$("p-filter").addEventListener("input", renderParams);
$("p-refresh").addEventListener("click", () => void loadParams());
for (const [id, cmd, text] of [
  ["p-save", "save", "Write the RAM configuration to flash (replaces what flash holds)."],
  ["p-load", "load", "Replace the RAM configuration with what flash holds (unsaved changes are lost)."],
  ["p-defaults", "defaults", "Replace the RAM configuration with this hardware's factory configuration (unsaved changes are lost)."],
] as const) {
  $(id).addEventListener("click", async () => {
    if (!(await ask(`${cmd}?`, text))) return;
    const r = await send(cmd, false);
    $("p-info").textContent = (r.ok ? "ok " : "refused: ") + r.text;
    $("p-info").className = r.ok ? "muted" : "reply err";
    await loadParams();
  });
}

// ---------- telemetry ----------
$("tel-start").addEventListener("click", async () => {
  const ch = $<HTMLInputElement>("tel-ch").value.replace(/\s/g, "");
  const hz = Number($<HTMLInputElement>("tel-hz").value);
  store.period = hz > 0 ? 1 / hz : 0;
  const r = await send(`tel ${ch} ${hz}`, false);
  $("tel-info").textContent = (r.ok ? "" : "refused: ") + r.text;
  $("tel-info").className = r.ok ? "muted" : "reply err";
});
$("tel-stop").addEventListener("click", () => void send("tel off", false));
$("span").addEventListener("change", () => { plot.span = Math.max(0.01, Number($<HTMLInputElement>("span").value) || 10); plot.changed(); });
$("pause").addEventListener("click", () => {
  plot.pause(!plot.paused);
  $("pause").textContent = plot.paused ? "Resume" : "Pause";
});
function download(name: string, text: string): void {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(new Blob([text], { type: "text/csv" }));
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
}
$("csv").addEventListener("click", () => download("regen-tel.csv", store.csv()));
const origTel = store.sample.bind(store);
store.sample = (t, v) => { origTel(t, v); plot.changed(); };

// ---------- capture ----------
const capPlot = new CapPlot($("cap-plot"));
let capDump: CapDump | null = null;
let capState = "";
const capV = (id: string) => $<HTMLInputElement>(id).value.trim();
function capKindShown(): void {
  $("cap-levelset").hidden = $<HTMLSelectElement>("cap-kind").value !== "level";
  $("cap-unit").textContent = unitOf($<HTMLSelectElement>("cap-tch").value);
}
$("cap-kind").addEventListener("change", capKindShown);
$("cap-tch").addEventListener("change", capKindShown);
capKindShown();

function showCapState(st: CapStatus | null, text?: string): void {
  const pill = $("cap-state");
  if (!st) { pill.className = "pill bad"; pill.textContent = text ?? "?"; return; }
  capState = st.state;
  pill.className = "pill cap-" + st.state;
  pill.textContent = st.state;
  const f = st.f;
  const dt = Number(f.dt_s);
  const n = Number(f.n);
  const parts = [`ch ${f.ch ?? "?"}`, Number.isFinite(dt) ? `every ${fmtQty(dt, "s")}` : "", Number.isFinite(n) && Number.isFinite(dt) ? `${n} samples = ${fmtQty(n * dt, "s")}` : "", `pre-trigger ${f.pre ?? "?"} %`, `trigger: ${trigText(f.trig ?? "?")}`];
  if (f.t_trig_s) parts.push(`triggered ${fmtQty(Number(f.t_trig_s), "s")} after arming`);
  $("cap-info").textContent = parts.filter(Boolean).join(" · ");
}

/** `cap show`: the capture's state (also polled with the status while armed or triggered). */
async function capShow(): Promise<void> {
  const r = await send("cap show", false);
  if (!r.ok) { showCapState(null, "no cap"); showReply("cap-msg", r); return; }
  showCapState(parseCapStatus([...r.data, r.text]));
}

/** Send the set-up, one command at a time; the first refusal stops it and is shown. */
async function capSend(lines: string[]): Promise<boolean> {
  for (const l of lines) {
    const r = await send(l, false);
    // The refusal with the command it answers (the drive's own text names it mostly).
    if (!r.ok) { showReply("cap-msg", { ...r, text: r.text.startsWith(l) ? r.text : `${l}: ${r.text}` }); return false; }
  }
  $("cap-msg").textContent = "ok " + lines.join("; ");
  $("cap-msg").classList.remove("err");
  return true;
}

$("cap-arm").addEventListener("click", async () => {
  const kind = $<HTMLSelectElement>("cap-kind").value;
  const trig = kind === "level" ? `cap trig ${$<HTMLSelectElement>("cap-tch").value} ${$<HTMLSelectElement>("cap-edge").value} ${capV("cap-level")}` : `cap trig ${kind}`;
  const pre = capState === "armed" || capState === "triggered" ? ["cap stop"] : [];
  await capSend([...pre, `cap ch ${capV("cap-ch").replace(/\s/g, "")}`, `cap div ${capV("cap-div")}`, `cap pre ${capV("cap-pre")}`, trig, "cap arm"]);
  await capShow();
});
$("cap-now").addEventListener("click", async () => { await capSend(["cap now"]); await capShow(); });
$("cap-stop").addEventListener("click", async () => { await capSend(["cap stop"]); await capShow(); });

async function capRead(): Promise<void> {
  const r = await send("cap dump", false);
  if (!r.ok) { showReply("cap-msg", r); return; }
  try {
    capDump = parseDump(r.data);
  } catch (e) {
    showReply("cap-msg", { ...r, ok: false, text: (e as Error).message });
    return;
  }
  const d = capDump;
  $("cap-msg").textContent = `read ${d.t.length} samples of ${d.channels.join(", ")}, ${d.pre} before the trigger, every ${fmtQty(Number(d.head.dt_s), "s")}`;
  $("cap-msg").classList.remove("err");
  capPlot.show(d);
}
$("cap-dump").addEventListener("click", () => void capRead());
$("cap-csv").addEventListener("click", () => { if (capDump) download("regen-capture.csv", capDump.lines.join("\n") + "\n"); });

/** `N cap triggered` / `N cap ready`: the state at once; a ready capture is read. */
function capNotice(t: string): void {
  const m = /^cap (\w+)/.exec(t);
  if (!m) return;
  void capShow().then(() => (m[1] === "ready" ? capRead() : undefined));
}

function showReply(id: string, r: Reply): void {
  const el = $(id);
  el.textContent = (r.ok ? "ok " : "refused: ") + r.text;
  el.classList.toggle("err", !r.ok);
}

// ---------- faults ----------
async function readFaults(): Promise<void> {
  const r = await send("faults", false);
  $("f-text").textContent = r.data.join("\n");
  showReply("f-msg", r);
  // The alarm in words: the fault's name and meaning, and the safe state the drive took.
  const f = r.data.map((l) => /^fault \d+ (\S+): (.*)$/.exec(l)).find((m) => m);
  const safe = r.data.find((l) => l.startsWith("safe state:"));
  if (f) alarm(`FAULT ${f[1]}: ${f[2]}.${safe ? " " + safe[0].toUpperCase() + safe.slice(1) + "." : ""} Details on the Faults tab; Clear there once the cause is gone.`);
}
$("f-read").addEventListener("click", () => void readFaults());
$("f-clear").addEventListener("click", async () => { showReply("f-msg", await send("clear", false)); await poll(); });

// ---------- harvest ----------
let hplot: uPlot | null = null;
/** The harvest plot's legend markers, by series (a CSS background for `fill`; dots round). */
const HMARK = [
  { width: 0, stroke: "", fill: "" },
  { width: 0, stroke: "#1f6fd1", fill: "linear-gradient(#1f6fd1, #1f6fd1) center / 100% 2px no-repeat" },
  { width: 2, stroke: "#2c9a4b", fill: "#2c9a4b" },
  { width: 2, stroke: "#d1461f", fill: "#d1461f" },
  { width: 2, stroke: "#d1461f", fill: "#fff" },
];
const readings: [number, number][] = [];
async function harvest(): Promise<void> {
  const res = await fetch(`api/harvest?token=${encodeURIComponent(token)}`);
  if (!res.ok) { $("h-info").textContent = await res.text(); return; }
  const j = await res.json();
  if (!j.available) { $("h-info").textContent = j.reason; return; }
  const r = Number(params.find((p) => p.name === "r_load_ohm")?.value ?? NaN);
  const p = Number((lastStatus.p_cycle_w ?? "").replace(/[^0-9.eE+-].*$/, ""));
  // A new reading at the same R_L replaces the previous one (else "earlier" hides "now").
  if (Number.isFinite(r) && Number.isFinite(p)) {
    if (readings.length && readings[readings.length - 1][0] === r) readings.pop();
    readings.push([r, p]);
  }
  const xs: number[] = j.curve.map((c: number[]) => c[0]);
  const curve: number[] = j.curve.map((c: number[]) => c[1]);
  const nearest = (x: number) => xs.reduce((b, v, i) => (Math.abs(Math.log(v / x)) < Math.abs(Math.log(xs[b] / x)) ? i : b), 0);
  const opt = new Array<number | null>(xs.length).fill(null);
  opt[nearest(j.optimum.r_ohm)] = j.optimum.p_w;
  const now = new Array<number | null>(xs.length).fill(null);
  const past = new Array<number | null>(xs.length).fill(null);
  readings.forEach(([rr, pp], k) => ((k === readings.length - 1 ? now : past)[nearest(rr)] = pp));
  $("h-info").textContent = `${j.scenario}: optimum R_L = ${fmtQty(j.optimum.r_ohm, "Ω")}, ${fmtQty(j.optimum.p_w, "W")}` + (readings.length ? `; the drive now at ${fmtQty(r, "Ω")}: p_cycle ${fmtQty(p, "W")}` : "");
  hplot?.destroy();
  const el = $("h-plot");
  el.textContent = "";
  hplot = new uPlot(
    {
      width: Math.max(400, el.clientWidth), height: 380,
      scales: { x: { time: false, distr: 3 } },
      // Each legend entry in its series' style (uPlot's default marker is a square outline of
      // the stroke): a line for the curve, a dot or a ring for the points.
      legend: { live: false, markers: { width: (_u, i) => HMARK[i].width, stroke: (_u, i) => HMARK[i].stroke, fill: (_u, i) => HMARK[i].fill } },
      axes: [{ label: "R_L (Ω per phase)" }, { label: "mean load power (W)", size: 60 }],
      series: [
        { label: "R_L" },
        { label: "harmonic balance", stroke: HMARK[1].stroke, width: 2, points: { show: false } },
        { label: "optimum", stroke: HMARK[2].stroke, paths: () => null, points: { show: true, size: 12, fill: HMARK[2].fill } },
        { label: "drive now", stroke: HMARK[3].stroke, paths: () => null, points: { show: true, size: 10, fill: HMARK[3].fill } },
        { label: "earlier", stroke: HMARK[4].stroke, paths: () => null, points: { show: true, size: 8, fill: HMARK[4].fill } },
      ],
    },
    [xs, curve, opt, now, past] as unknown as uPlot.AlignedData,
    el,
  );
  // The points' markers (those with a border) round.
  el.querySelectorAll<HTMLElement>(".u-legend .u-marker").forEach((m) => { if (m.style.borderWidth === "2px") m.style.borderRadius = "50%"; });
}
$("h-refresh").addEventListener("click", async () => { await loadParams(); await poll(); await harvest(); });

// ---------- console ----------
$("c-line").addEventListener("keydown", (e) => {
  if (e.key !== "Enter") return;
  e.preventDefault(); // as in the parameter table: the Enter must not press the dialog's Cancel
  $("c-send").click();
});
$("c-send").addEventListener("click", async () => {
  const i = $<HTMLInputElement>("c-line");
  const l = i.value.trim();
  if (!l) return;
  i.value = "";
  const r = await send(l);
  log(`→ ${l}: ${r.ok ? "ok" : "refused"} ${r.text}`);
});

renderSteps();
if (!token) alarm("This page has no token: open the URL `regen ui` printed.");
else if (location.hash !== "#manual") void connect();
