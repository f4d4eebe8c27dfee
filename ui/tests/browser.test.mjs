// The browser suite: Debian's chromium, headless, driven by playwright-core (nothing downloads a
// browser) against `regen ui --sim hal-sim/scenarios/tmd-306.toml`. Screenshots of each panel
// go to docs/figures/ui-*.png. REGEN_BIN names the regen binary (default target/debug/regen).

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { createInterface } from "node:readline";
import { mkdtempSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, dirname } from "node:path";
import { fileURLToPath } from "node:url";
import http from "node:http";
import { chromium } from "playwright-core";

const ROOT = join(dirname(fileURLToPath(import.meta.url)), "..", "..");
const BIN = process.env.REGEN_BIN ?? join(ROOT, "target/debug/regen");
const FIG = join(ROOT, "docs/figures");
const CHROMIUM = process.env.CHROMIUM ?? "/usr/bin/chromium";

/** `regen ui --sim tmd-306` on a free loopback port; resolves with its URL parts. */
function startUi(speed) {
  const p = spawn(BIN, ["ui", "--sim", join(ROOT, "hal-sim/scenarios/tmd-306.toml"), "--listen", "127.0.0.1:0", "--speed", String(speed)], { stdio: ["ignore", "pipe", "inherit"] });
  return new Promise((resolve, reject) => {
    const rl = createInterface({ input: p.stdout });
    rl.on("line", (l) => {
      const m = /^open (http:\/\/([^/]+)\/)\?token=([0-9a-f]+)$/.exec(l);
      if (m) resolve({ proc: p, url: m[0].slice(5), base: m[1], host: m[2], token: m[3] });
    });
    p.on("exit", (c) => reject(new Error(`regen ui exited ${c}`)));
  });
}

// playwright gives each launch a fresh temporary profile (its own --user-data-dir).
let browser;
before(async () => {
  browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
});
after(async () => browser?.close());

/** Record every WebSocket text message the page receives (the stream, for the CSV check). */
const RECORD_WS = () => {
  window.__ws = [];
  const W = window.WebSocket;
  window.WebSocket = class extends W {
    constructor(...a) {
      super(...a);
      this.addEventListener("message", (e) => window.__ws.push(e.data));
    }
  };
};

/** Contexts a test opened (closed at its end: an idle page of one test costs the next nothing). */
const contexts = [];
async function closeContexts() {
  while (contexts.length) await contexts.pop().close();
}

async function openPage(ui, init) {
  const ctx = await browser.newContext({ viewport: { width: 1400, height: 860 }, acceptDownloads: true });
  contexts.push(ctx);
  const page = await ctx.newPage();
  page.on("pageerror", (e) => console.log("page error:", e.message));
  if (init) await page.addInitScript(init);
  await page.goto(ui.url);
  return page;
}

/** A status field as the drive sent it (the page shows it formatted, with its unit). */
const statusOf = (page, k) => page.locator(`#status [data-k="${k}"]`).getAttribute("data-v", { timeout: 15000 });
const tab = (page, name) => page.click(`#tabs button[data-tab="${name}"]`);
/** Answer the page's confirmation with Yes, if it asks (a `set` asks only while running). */
async function confirmIfAsked(page) {
  await page.locator("#confirm[open]").waitFor({ timeout: 2000 }).then(() => page.click("#q-yes"), () => {});
}
/** Answer the page's confirmation with Yes (it must ask). */
async function confirmYes(page) {
  await page.locator("#confirm[open]").waitFor({ timeout: 5000 });
  await page.click("#q-yes");
}

/** The capture panel's CSV export and the dump's `D` lines as the page received them. */
async function capCsvAndDump(page) {
  const dl = page.waitForEvent("download");
  await page.click("#cap-csv");
  const csv = Buffer.concat(await (await (await dl).createReadStream()).toArray()).toString();
  const ws = (await page.evaluate(() => window.__ws.join(""))).split(/\r?\n/);
  // The last dump the page read.
  const h = ws.findLastIndex((l) => /^D \S+ # cap /.test(l));
  const id = ws[h].split(" ")[1];
  const dump = [];
  for (let i = h; i < ws.length && !ws[i].startsWith(`R ${id} `); i++) if (ws[i].startsWith(`D ${id} `)) dump.push(ws[i].slice(3 + id.length));
  return { csv: csv.trimEnd().split("\n"), dump };
}

/**
 * The live plot's traces as shown: a screenshot of the plotting area (what the compositor
 * shows of the worker's canvas), decoded by the page; per channel colour, the pixel columns
 * holding it, and a hash of the pixels.
 */
async function traceColumns(page) {
  const box = await page.evaluate(() => { const r = window.__regen.plot.trCv.getBoundingClientRect(); return { x: r.left, y: r.top, width: r.width, height: r.height }; });
  const png = (await page.screenshot({ clip: box })).toString("base64");
  return page.evaluate(async (b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const bm = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
    const cv = new OffscreenCanvas(bm.width, bm.height);
    const cx = cv.getContext("2d");
    cx.drawImage(bm, 0, 0);
    const px = cx.getImageData(0, 0, bm.width, bm.height).data;
    const colors = window.__regen.plot.chans.map((c) => c.color);
    const rgb = colors.map((h) => [1, 3, 5].map((i) => parseInt(h.slice(i, i + 2), 16)));
    const cols = colors.map(() => new Set());
    let hash = 0;
    for (let y = 0; y < bm.height; y++)
      for (let x = 0; x < bm.width; x++) {
        const o = 4 * (y * bm.width + x);
        hash = (hash * 31 + px[o] + 7 * px[o + 1] + 13 * px[o + 2]) | 0;
        rgb.forEach((c, k) => { if (px[o] === c[0] && px[o + 1] === c[1] && px[o + 2] === c[2]) cols[k].add(x); });
      }
    return { width: bm.width, columns: cols.map((s) => s.size), hash };
  }, png);
}

test("end to end: connect, set R_L, align, run, power vs harmonic balance, fault, CSV", async () => {
  const ui = await startUi(10);
  try {
    const page = await openPage(ui, RECORD_WS);
    const fault0 = await statusOf(page, "fault").catch(async (e) => {
      console.log(await page.evaluate(() => [document.querySelector("#alarm").textContent, ...window.__regen.stats.log.slice(0, 5)].join("\n")));
      throw e;
    });
    assert.equal(fault0, "none");
    // Set R_L = 200 Ω from the parameter table (running: the page asks first).
    await tab(page, "params");
    await page.locator("#ptable tbody tr").first().waitFor();
    const field = page.locator('#ptable input[data-name="r_load_ohm"]');
    await field.fill("200");
    await field.press("Enter");
    await confirmIfAsked(page);
    await page.locator('#ptable tr.changed input[data-name="r_load_ohm"]').waitFor();
    assert.equal(await field.inputValue(), "200");
    // A refused value: the firmware's message at the field, nothing changed.
    const ff = page.locator('#ptable input[data-name="f_filter_s"]');
    await ff.fill("-1");
    await ff.press("Enter");
    await confirmIfAsked(page);
    const ferrEl = ff.locator("xpath=following-sibling::div");
    await ferrEl.filter({ hasText: /\S/ }).waitFor({ timeout: 5000 }).catch(() => {});
    assert.match(await ferrEl.textContent(), /f_filter_s -1/);
    await page.screenshot({ path: join(FIG, "ui-params.png"), fullPage: true });
    // Power-up sequence: idle, align, run.
    await page.click("#stop");
    await tab(page, "commission");
    await page.click('button:text("mode align")');
    await confirmYes(page);
    // The scenario boots with a stored angle (`boot stored`); a finished align reads `aligned`.
    await page.waitForFunction(() => document.querySelector('#status [data-k="boot"]')?.textContent === "aligned", null, { timeout: 30000 });
    await page.click('button:text("mode run")');
    await confirmYes(page);
    await page.waitForFunction(() => document.querySelector('#status [data-k="mode"]')?.textContent === "run", null, { timeout: 10000 });
    await page.screenshot({ path: join(FIG, "ui-powerup.png") });
    // Settle (8 simulated s, the free response < 1e-3 of its amplitude; docs/console.md), then
    // the drive's p_cycle (mean over the last whole motion cycle) against the harmonic balance.
    await page.waitForTimeout(2500); // 25 simulated s at --speed 10
    const hb = await (await fetch(`${ui.base}api/harvest?token=${ui.token}&r=200`)).json();
    const pHb = hb.at[0][1];
    // Bound 0.4 % (inside the required 1 %): the drive's p_cycle reads +0.11 to +0.12 % above
    // the harmonic balance in repeated runs; the bound is about 3x that.
    const TOL = 0.004;
    let pDrive = NaN;
    for (let k = 0; k < 20; k++) {
      pDrive = parseFloat(await statusOf(page, "p_cycle_w"));
      if (Math.abs(pDrive / pHb - 1) < TOL) break;
      await page.waitForTimeout(500);
    }
    console.log(`mean power at R_L = 200 ohm: drive p_cycle ${pDrive} W, harmonic balance ${pHb.toFixed(4)} W, ${(100 * (pDrive / pHb - 1)).toFixed(3)} %`);
    assert.ok(Math.abs(pDrive / pHb - 1) < TOL, `p_cycle ${pDrive} W vs ${pHb} W`);
    await tab(page, "harvest");
    await page.click("#h-refresh");
    await page.waitForTimeout(500);
    await page.screenshot({ path: join(FIG, "ui-harvest.png") });
    // Each legend entry in its series' style: the curve a line (no outline, a 2 px stripe), the
    // points round (an outline; the ring white inside).
    const marks = await page.$$eval("#h-plot .u-legend .u-series", (rows) =>
      rows.map((r) => { const m = r.querySelector(".u-marker"), c = m && getComputedStyle(m); return c && { label: r.textContent.trim(), border: c.borderTopWidth, round: c.borderTopLeftRadius, image: c.backgroundImage, color: c.backgroundColor }; }).filter((x) => x && x.label));
    const mark = (l) => marks.find((m) => m.label.startsWith(l));
    assert.equal(mark("harmonic balance").border, "0px");
    assert.match(mark("harmonic balance").image, /linear-gradient/);
    for (const l of ["optimum", "drive now", "earlier"]) assert.equal(mark(l).round, "50%", l);
    assert.equal(mark("earlier").color, "rgb(255, 255, 255)");
    assert.equal(mark("drive now").color, "rgb(209, 70, 31)");
    // Telemetry, a few channels on one axis; export the CSV and compare with the stream.
    await tab(page, "monitor");
    await page.fill("#tel-ch", "p,w,iq,x");
    await page.fill("#tel-hz", "100");
    await page.click("#tel-start");
    await page.waitForTimeout(2500);
    await page.click("#tel-stop");
    await page.waitForTimeout(300);
    await page.screenshot({ path: join(FIG, "ui-plots.png") });
    const dl = page.waitForEvent("download");
    await page.click("#csv");
    const csv = await (await (await dl).createReadStream()).toArray();
    const rows = Buffer.concat(csv).toString().trim().split("\n");
    const stream = (await page.evaluate(() => window.__ws.join(""))).split(/\r?\n/).filter((l) => l.startsWith("T ")).map((l) => l.slice(2));
    const lastH = (await page.evaluate(() => window.__ws.join(""))).split(/\r?\n/).filter((l) => l.startsWith("H ")).pop();
    assert.equal(rows[0], lastH.slice(2));
    assert.ok(stream.length > 100, `${stream.length} samples streamed`);
    assert.equal(rows.length - 1, stream.length, "every streamed sample is in the CSV, no other");
    for (let i = 0; i < stream.length; i++) {
      const a = rows[i + 1].split(",").map(Number), b = stream[i].split(",").map(Number);
      assert.deepEqual(a, b, `row ${i}`);
    }
    console.log(`CSV: ${stream.length} rows, each equal to the streamed sample`);
    // Paused, uPlot draws every sample of the window (the last 10 s of the stream's times, the
    // CSV's rows); resumed, the live chart.
    await page.click("#pause");
    const tLast = Number(rows.at(-1).split(",")[0]);
    const inWindow = rows.slice(1).filter((r) => Number(r.split(",")[0]) >= tLast - 10).length;
    assert.equal(await page.evaluate(() => window.__regen.plot.u.data[0].length), inWindow, "paused: every sample of the window");
    await page.click("#pause");
    assert.equal(await page.evaluate(() => window.__regen.plot.u), null);
    // A capture armed on a fault (25 % before the trigger), then the fault provoked: a force
    // trip below the running force.
    const CPRE = 25;
    await tab(page, "capture");
    await page.fill("#cap-ch", "iq_ref,iq,vq,p");
    await page.fill("#cap-div", "1");
    await page.fill("#cap-pre", String(CPRE));
    await page.selectOption("#cap-kind", "fault");
    await page.click("#cap-arm");
    await page.waitForFunction(() => document.querySelector("#cap-state")?.textContent === "armed", null, { timeout: 10000 });
    await tab(page, "params");
    const ft = page.locator('#ptable input[data-name="f_trip_n"]');
    await ft.fill("1");
    await ft.press("Enter");
    await confirmYes(page); // running: a set asks first
    await page.locator("#alarm:not([hidden])").waitFor({ timeout: 10000 });
    await tab(page, "faults");
    await page.waitForFunction(() => /over_force/.test(document.querySelector("#f-text")?.textContent ?? ""), null, { timeout: 10000 });
    const ftext = await page.locator("#f-text").textContent();
    assert.match(ftext, /over_force/);
    await page.screenshot({ path: join(FIG, "ui-faults.png") });
    // The fault's capture, read by the page on `N cap ready` and decoded in the capture panel.
    await tab(page, "capture");
    await page.waitForFunction(() => window.__regen.cap()?.head.trig === "fault", null, { timeout: 15000 });
    const c = await page.evaluate(() => window.__regen.cap());
    const cn = c.t.length, cp = c.pre;
    const around = (k) => c.v[k].slice(cp - 3, cp + 4).join(", ");
    console.log(`fault capture: ${cn} samples of ${c.channels.join(",")}, ${cp} before the latch; around t = 0: ${c.channels.map((ch, k) => `${ch} ${around(k)}`).join("; ")}`);
    console.log(`fault capture: pre-trigger means ${c.channels.map((ch, k) => `${ch} ${(c.v[k].slice(0, cp).reduce((a, x) => a + Math.abs(x), 0) / cp).toFixed(4)}`).join(", ")}; post-trigger ${c.channels.map((ch, k) => `${ch} ${(c.v[k].slice(cp + 1).reduce((a, x) => a + Math.abs(x), 0) / (cn - cp - 1)).toFixed(4)}`).join(", ")}`);
    assert.equal(await page.locator("#cap-state").textContent(), "ready");
    assert.match(await page.locator("#cap-info").textContent(), /trigger: fault/);
    assert.match(await page.locator("#cap-msg").textContent(), new RegExp(`^read ${cn} samples of iq_ref, iq, vq, p, ${cp} before the trigger`));
    // The pre-trigger share: ⌊n·25/100⌋ (n the ring's samples) samples before the latch's period, t < 0 exactly there.
    assert.equal(cp, Math.floor((cn * CPRE) / 100));
    assert.equal(c.t.filter((x) => x < 0).length, cp, "the pre-trigger samples have t < 0");
    assert.equal(c.t[cp], 0, "t = 0 is the latch's period");
    // Before the latch the drive ran: the voltage it applied (vq, the back-emf's share and the
    // law's current; zero only at a turning point of the motion, which 12.5 ms of a 2 s cycle
    // rarely holds) non-zero in every pre-trigger sample in the runs seen; required in 90 %.
    // After it the safe state (open: gates off) shows: from the next period on, no current
    // commanded, no voltage applied, no load power, in every sample.
    const [IQR, , VQ, PW] = [0, 1, 2, 3];
    const running = c.v[VQ].slice(0, cp).filter((x) => x !== 0).length;
    assert.ok(running >= 0.9 * cp, `vq non-zero in ${running} of ${cp} samples before the latch`);
    for (let i = cp + 1; i < cn; i++) assert.ok(c.v[IQR][i] === 0 && c.v[VQ][i] === 0 && c.v[PW][i] === 0, `sample ${i} after the latch: iq_ref ${c.v[IQR][i]}, vq ${c.v[VQ][i]}, p ${c.v[PW][i]}`);
    assert.equal(await page.evaluate(() => window.__regen.capPlot().u.data[0].length), cn, "every sample plotted");
    {
      const { csv, dump } = await capCsvAndDump(page);
      assert.equal(dump.length, cn + 2, "header, column line, samples");
      assert.deepEqual(csv, dump, "the fault capture's CSV is the dump, line for line");
    }
    // Losing the connection while running is shown at once.
    await page.click('#tabs button[data-tab="params"]');
    ui.proc.kill("SIGKILL");
    await page.locator("#alarm:not([hidden])").waitFor({ timeout: 3000 });
  } finally {
    ui.proc.kill("SIGKILL");
    await closeContexts();
  }
});

test("a foreign Origin and a missing token are refused", async () => {
  const ui = await startUi(1);
  const foreign = http.createServer((_, r) => r.end("<!doctype html><title>foreign</title>"));
  await new Promise((r) => foreign.listen(0, "127.0.0.1", r));
  try {
    const ctx = await browser.newContext();
    contexts.push(ctx);
    const page = await ctx.newPage();
    await page.goto(`http://127.0.0.1:${foreign.address().port}/`);
    const tryWs = (url) => new Promise((res) => { const w = new WebSocket(url); w.onopen = () => res("open"); w.onerror = () => res("refused"); });
    assert.equal(await page.evaluate(tryWs, `ws://${ui.host}/ws?token=${ui.token}`), "refused", "foreign origin with the token");
    const own = await openPage(ui);
    await own.locator('#status [data-k="mode"]').waitFor();
    await own.close();
    const noTok = await browser.newPage();
    await noTok.goto(ui.base);
    assert.match(await noTok.locator("#alarm").textContent(), /no token/);
    assert.equal(await noTok.evaluate(tryWs, `ws://${ui.host}/ws`), "refused", "own origin without the token");
    console.log("foreign origin refused; missing token refused");
  } finally {
    foreign.close();
    ui.proc.kill("SIGKILL");
  }
});

test("Web Serial path: navigator.serial stubbed onto the simulated drive", async () => {
  const ui = await startUi(1);
  try {
    // A stub port whose byte streams go to the server's bridge (the same console the board's
    // UART would carry).
    const stub = ({ token }) => {
      const enc = new TextEncoder();
      // Chromium has its own navigator.serial (a getter on Navigator.prototype): a plain
      // assignment is silently ignored, so the stub is defined on the instance.
      Object.defineProperty(navigator, "serial", { configurable: true, value: {
        requestPort: async () => {
          const ws = new WebSocket(`ws://${location.host}/ws?token=${token}`);
          await new Promise((r) => (ws.onopen = r));
          window.__serialStub = true;
          return {
            open: async () => {},
            close: async () => ws.close(),
            readable: new ReadableStream({ start(c) { ws.onmessage = (e) => c.enqueue(enc.encode(e.data)); ws.onclose = () => c.close(); } }),
            writable: new WritableStream({ write(chunk) { ws.send(new TextDecoder().decode(chunk)); } }),
          };
        },
      } });
    };
    const ctx = await browser.newContext();
    contexts.push(ctx);
    const page = await ctx.newPage();
    await page.addInitScript(stub, { token: ui.token });
    await page.addInitScript(() => delete HTMLCanvasElement.prototype.transferControlToOffscreen);
    await page.goto(ui.base + "?token=" + ui.token + "#manual"); // no automatic connection
    await page.selectOption("#transport", "serial");
    await page.click("#connect");
    await page.locator('#status [data-k="mode"]').waitFor({ timeout: 15000 });
    assert.equal(await page.evaluate(() => window.__serialStub), true);
    assert.match(await page.locator("#link").textContent(), /Web Serial/);
    // Telemetry over the same port, into a page without OffscreenCanvas (removed below): the
    // live chart drawn on the main thread instead, every sample reaching it.
    await page.fill("#tel-ch", "p,w");
    await page.fill("#tel-hz", "200");
    await page.click("#tel-start");
    await page.waitForTimeout(1500);
    await page.click("#tel-stop");
    await page.waitForFunction(() => window.__regen.stats.telReceived() > 200 && window.__regen.stats.plotted() === window.__regen.stats.telReceived(), null, { timeout: 5000 });
    const live = await page.evaluate(() => ({ n: window.__regen.stats.telReceived(), frames: window.__regen.stats.frames(), worker: window.__regen.plot.worker !== null, points: window.__regen.plot.points.length }));
    assert.equal(live.worker, false, "no worker without OffscreenCanvas");
    assert.ok(live.frames > 30 && live.points === 3, JSON.stringify(live));
    console.log("Web Serial stub: connected, status read:", await statusOf(page, "mode"), "; telemetry drawn without a worker:", JSON.stringify(live));
  } finally {
    ui.proc.kill("SIGKILL");
    await closeContexts();
  }
});

test("capture: a level trigger around an R_L step; pre-trigger samples, t = 0 at the crossing, CSV equal to the dump", async () => {
  const ui = await startUi(1);
  try {
    const page = await openPage(ui, RECORD_WS);
    await page.locator('#status [data-k="mode"]').waitFor();
    assert.equal(await statusOf(page, "mode"), "run");
    // The motion builds up from rest after the drive starts: arm once it is near its steady
    // state (mean power over the last cycle above 20 W; 23.0 W at 306 Ω when settled).
    await page.waitForFunction(() => Number(document.querySelector('#status [data-k="p_cycle_w"]')?.dataset.v) > 20, null, { timeout: 40000 });
    await tab(page, "capture");
    // The load power p peaks at about 46 W at R_L = 306 Ω. A step to 30 Ω near the speed's
    // peak drives the current to its 1.9 A limit into 30 Ω (150-280 W); one near a turning
    // point only 60-90 W, as the heavier damping stops the motion: the step is sent when
    // |w| > 75 rad/s (amplitude 90-100; 137-280 W seen), and a rise through 60 W happens only
    // after it.
    const LEVEL = 60, PRE = 25, P = 2;
    await page.fill("#cap-ch", "iq,w,p");
    await page.fill("#cap-div", "2");
    await page.fill("#cap-pre", String(PRE));
    await page.selectOption("#cap-kind", "level");
    await page.selectOption("#cap-tch", "p");
    await page.selectOption("#cap-edge", "rise");
    await page.fill("#cap-level", String(LEVEL));
    await page.click("#cap-arm");
    await page.waitForFunction(() => document.querySelector("#cap-state")?.textContent === "armed", null, { timeout: 10000 });
    await page.waitForTimeout(1000);
    assert.equal(await page.locator("#cap-state").textContent(), "armed", "no trigger before the step");
    // The step, from the console tab (running: the page asks first).
    await tab(page, "console");
    await page.fill("#c-line", "set r_load_ohm 30");
    await page.press("#c-line", "Enter");
    // The page asks first (the drive runs); Yes is pressed once |w| > 75 rad/s.
    await page.locator("#confirm[open]").waitFor({ timeout: 5000 });
    const speed = () => page.evaluate(async () => Number(/speed_rad_s=(\S+)/.exec((await window.__regen.cmd("status")).data.join(" "))?.[1]));
    let w = NaN;
    for (let k = 0; k < 2000 && !(Math.abs((w = await speed())) > 75); k++);
    await page.click("#q-yes");
    console.log(`step to 30 ohm sent at w = ${w} rad/s`);
    await tab(page, "capture");
    // `N cap ready` makes the page read the dump by itself.
    await page.waitForFunction(() => window.__regen.cap() !== null, null, { timeout: 15000 }).catch(async (e) => {
      console.log(await page.evaluate(async () => [document.querySelector("#cap-state").textContent, document.querySelector("#cap-msg").textContent, ...window.__regen.stats.log.filter((l) => /r_load|cap|^N|err/.test(l) && !/cap armed/.test(l)).slice(-40), JSON.stringify(await window.__regen.cmd("cap show")), JSON.stringify(await window.__regen.cmd("status"))].join("\n")));
      throw e;
    });
    await page.waitForTimeout(300);
    const d = await page.evaluate(() => window.__regen.cap());
    const n = d.t.length, pre = d.pre, dt = Number(d.head.dt_s);
    const tTrig = d.t[pre];
    console.log(`capture: ${n} samples of ${d.channels.join(",")} every ${dt} s, ${pre} before the trigger (${((100 * pre) / n).toFixed(1)} %); t[pre] = ${tTrig}; p around the trigger: ${d.v[P].slice(pre - 3, pre + 3).join(", ")} W`);
    assert.equal(await page.locator("#cap-state").textContent(), "ready");
    assert.equal(d.head.trig, `p,rise,${LEVEL}`);
    assert.ok(pre > 0 && d.t.filter((x) => x < 0).length === pre, "the pre-trigger samples have t < 0");
    assert.ok(Math.abs(pre / n - PRE / 100) <= 1 / n + 1e-9, `pre-trigger share ${pre}/${n}`);
    assert.equal(tTrig, 0, "t = 0 is the trigger sample");
    // The trigger sample is the rise through the level (the drive compares the same codes it
    // stores, so the dumped values show the crossing exactly).
    assert.ok(d.v[P][pre - 1] < LEVEL && d.v[P][pre] >= LEVEL, `p ${d.v[P][pre - 1]} -> ${d.v[P][pre]}`);
    // Before the trigger p stayed below the level: the pre-trigger samples are the step's
    // run-up, not an earlier crossing.
    assert.ok(Math.max(...d.v[P].slice(0, pre)) < LEVEL);
    for (let i = 1; i < n; i++) assert.ok(Math.abs(d.t[i] - d.t[i - 1] - dt) < 1e-6, `t step at ${i}`);
    // The plot holds every sample, on one axis in ms from the trigger.
    const plotted = await page.evaluate(() => window.__regen.capPlot().u.data[0].length);
    assert.equal(plotted, n);
    await page.screenshot({ path: join(FIG, "ui-capture.png") });
    // CSV export: the dump's lines as the drive sent them (its `D` lines, in order).
    const { csv, dump } = await capCsvAndDump(page);
    assert.equal(dump.length, n + 2, "header, column line, samples");
    assert.deepEqual(csv, dump, "the CSV is the dump, line for line");
    console.log(`capture CSV: ${dump.length} lines, equal to the dump`);
    // Trigger now (`cap trig cmd`, `cap now`): a second capture read on its own notice.
    await page.selectOption("#cap-kind", "cmd");
    await page.fill("#cap-pre", "50");
    await page.click("#cap-arm");
    await page.waitForFunction(() => document.querySelector("#cap-state")?.textContent === "armed", null, { timeout: 10000 });
    await page.click("#cap-now");
    await page.waitForFunction(() => window.__regen.cap()?.head.trig === "cmd", null, { timeout: 10000 });
    const d2 = await page.evaluate(() => window.__regen.cap());
    assert.equal(d2.t[d2.pre], 0);
    assert.equal(d2.pre, d2.t.length / 2, "50 % before the trigger");
    // Stop disarms; a refused set-up shows the drive's refusal with its command, and Arm stops there.
    await page.click("#cap-arm");
    await page.waitForFunction(() => document.querySelector("#cap-state")?.textContent === "armed", null, { timeout: 10000 });
    await page.click("#cap-stop");
    await page.waitForFunction(() => document.querySelector("#cap-state")?.textContent === "idle", null, { timeout: 10000 });
    await page.fill("#cap-ch", "iq,w,p,x,vbus");
    await page.click("#cap-arm");
    await page.locator("#cap-msg.err").waitFor({ timeout: 10000 });
    const refused = await page.locator("#cap-msg").textContent();
    assert.match(refused, /^refused: cap ch iq,w,p,x,vbus: /);
    assert.equal(await page.locator("#cap-state").textContent(), "idle", "nothing armed after the refusal");
    console.log(`capture: Trigger now read ${d2.t.length} samples, ${d2.pre} before; Stop -> idle; ${refused}`);
  } finally {
    ui.proc.kill("SIGKILL");
    await closeContexts();
  }
});

test("smoothness: 8 channels at the highest tel rate for 60 s; round trip", async () => {
  const ui = await startUi(1);
  const secs = Number(process.env.SMOOTH_S ?? 60);
  try {
    const page = await openPage(ui);
    await page.locator('#status [data-k="mode"]').waitFor().catch(async (e) => {
      console.log("no status; the page's console log:\n" + (await page.evaluate(() => window.__regen.stats.log.join("\n"))));
      throw e;
    });
    // Round trip: 200 commands over the bridge, one at a time.
    const rtt = await page.evaluate(async () => {
      const out = [];
      for (let i = 0; i < 200; i++) { const r = await window.__regen.cmd("get r_load_ohm"); out.push(r.done - r.sent); }
      return out.sort((a, b) => a - b);
    });
    const q = (p) => rtt[Math.floor((rtt.length - 1) * p)];
    console.log(`round trip (page -> bridge -> drive -> page), 200 commands: min ${rtt[0].toFixed(2)} ms, median ${q(0.5).toFixed(2)}, p90 ${q(0.9).toFixed(2)}, p99 ${q(0.99).toFixed(2)}, max ${rtt.at(-1).toFixed(2)}`);
    assert.ok(q(0.5) < 10, `median round trip ${q(0.5)} ms`);
    await page.fill("#tel-ch", "ia,ib,ic,id,iq,vbus,w,p");
    await page.fill("#tel-hz", "2000");
    await page.click("#tel-start");
    await page.waitForTimeout(1000);
    // The page's main-thread busy time: the renderer's own counters (CDP Performance.getMetrics,
    // seconds of main-thread tasks, script, layout, style), deltas over the wall time.
    const cdp = await page.context().newCDPSession(page);
    await cdp.send("Performance.enable", { timeDomain: "timeTicks" });
    // Beside it, the CPU time of the renderer processes (all their threads; not inflated by
    // waiting for a CPU on a busy machine, as the main thread's wall-clock task time is).
    const sys = await browser.newBrowserCDPSession();
    const rendererCpu = async () => (await sys.send("SystemInfo.getProcessInfo")).processInfo.filter((p) => p.type === "renderer").reduce((a, p) => a + p.cpuTime, 0);
    const metrics = async () => {
      const m = Object.fromEntries((await cdp.send("Performance.getMetrics")).metrics.map((x) => [x.name, x.value]));
      const p = await page.evaluate(() => ({ frames: window.__regen.stats.frames(), drawMs: window.__regen.stats.drawMs(), n: window.__regen.stats.telReceived(), gaps: window.__regen.stats.telGaps(), plotted: window.__regen.stats.plotted() }));
      return { ...m, ...p, cpu: await rendererCpu() };
    };
    const t0 = await metrics();
    // Busy share per 5 s slice too: a stall in one slice shows even when the mean is low.
    const slices = [];
    // Samples received but not yet in the plot's data, read at each slice's end (a plot that
    // falls behind the stream shows a growing lag).
    const lags = [];
    let prev = t0;
    for (let left = secs; left > 0; left -= 5) {
      await page.waitForTimeout(Math.min(5, left) * 1000);
      const now = await metrics();
      slices.push((now.TaskDuration - prev.TaskDuration) / (now.Timestamp - prev.Timestamp));
      lags.push(now.n - now.plotted);
      prev = now;
    }
    const t1 = prev;
    // Redrawn while streaming: the traces' pixels change from one look to the next.
    const look1 = await traceColumns(page);
    await page.waitForTimeout(300);
    const look2 = await traceColumns(page);
    await page.click("#tel-stop");
    // What the plot was handed: two points per bucket of consecutive samples (its first and
    // last time; its minimum and maximum in time order). Checked against the page's buffer
    // directly: each bucket's min and max over its samples, the buckets back to back, every
    // sample of the window in one.
    await page.waitForFunction(() => window.__regen.stats.plotted() === window.__regen.stats.telReceived());
    // The frame's own end (the samples it was cut from), read in the same turn as its points:
    // lines still in flight after the stop may arrive between the wait and this look.
    const dec = await page.evaluate(() => {
      const { store: s, plot } = window.__regen;
      const d = plot.points, M = s.t.length - 1;
      const a = s.held()[0], b = plot.drawnUpTo;
      let j = a;
      while (j < b && s.t[j & M] < d[0][0]) j++;
      const first = j;
      let bad = 0, covered = 0;
      for (let i = 0; i + 1 < d[0].length; i += 2) {
        if (s.t[j & M] !== d[0][i]) { bad++; break; }
        const j0 = j;
        while (j < b && s.t[j & M] <= d[0][i + 1]) j++;
        covered += j - j0;
        for (let k = 0; k < s.channels.length; k++) {
          let mn = Infinity, mx = -Infinity;
          for (let q = j0; q < j; q++) { mn = Math.min(mn, s.v[k][q & M]); mx = Math.max(mx, s.v[k][q & M]); }
          if (Math.min(d[k + 1][i], d[k + 1][i + 1]) !== mn || Math.max(d[k + 1][i], d[k + 1][i + 1]) !== mx) bad++;
        }
      }
      return { points: d[0].length, window: b - first, covered, bad, cols: plot.cols };
    });
    // Drawn: every channel's colour on screen, and the last channel drawn (p, never painted
    // over) in every pixel column of the window (the stream has run longer than the window).
    await page.waitForTimeout(200);
    const look = await traceColumns(page);
    console.log(`traces on screen: pixel columns holding each channel's colour ${look.columns.join(", ")} of ${look.width}; changed while streaming: ${look1.hash !== look2.hash}`);
    assert.notEqual(look1.hash, look2.hash, "the traces redrawn while streaming");
    assert.ok(look.columns.every((c) => c > 0), "every channel drawn");
    assert.ok(look.columns.at(-1) >= look.width - 1, `p in ${look.columns.at(-1)} of ${look.width} columns`);
    console.log(`plotted: ${dec.points} points per channel for the ${dec.window} samples of the window (${dec.cols} pixel columns); samples in a bucket ${dec.covered}, buckets whose min/max differ from the buffer's ${dec.bad}`);
    assert.equal(dec.bad, 0, "every bucket's min and max are its samples' min and max");
    assert.equal(dec.covered, dec.window, "every sample of the window is in a bucket");
    assert.ok(dec.points <= 2 * dec.cols + 4, `${dec.points} points for ${dec.cols} columns`);
    const dt = t1.Timestamp - t0.Timestamp;
    const d = (k) => (t1[k] - t0[k]) / dt;
    const rate = (t1.n - t0.n) / dt, busy = d("TaskDuration");
    // Frames: those the worker drew.
    const fps = d("frames");
    const pct = (x) => (100 * x).toFixed(1) + " %";
    console.log(`smoothness over ${dt.toFixed(1)} s: ${t1.n - t0.n} samples of 8 channels (${rate.toFixed(0)}/s), dropped (gaps) ${t1.gaps}, the plot behind the stream by ${lags.join(", ")} samples at the slices' ends; ${fps.toFixed(1)} frames/s drawn, the worker's drawing ${((t1.drawMs - t0.drawMs) / (t1.frames - t0.frames)).toFixed(2)} ms per frame`);
    console.log(`main thread busy ${pct(busy)} of wall time (script ${pct(d("ScriptDuration"))}, layout ${pct(d("LayoutDuration"))}, style ${pct(d("RecalcStyleDuration"))}); per 5 s slice: ${slices.map(pct).join(", ")}; renderer CPU ${pct(d("cpu"))} of one core`);
    assert.equal(t1.gaps, 0, "no sample dropped");
    assert.ok(rate > 1900, `sample rate ${rate}`);
    // A frame at 60 Hz is 33 samples at 2 kHz, the bridge holds telemetry up to 8 ms (16
    // samples) and up to two frames are with the worker: the lag read at a random moment was
    // 0-140 samples in the runs on this loaded machine (docs/ui.md, Status); bound 200 (100
    // ms), about 1.4x that.
    assert.ok(Math.max(...lags) < 200, `the plot keeps up with the stream (lags ${lags.join(", ")})`);
    assert.ok(fps >= 50, `${fps} frames/s`);
    // Required (issue 33): under 25 %. Measured 7.2-7.3 % in 20 s runs and 7.5-13.9 % in full
    // runs with load average 6-12 on this 2-core machine; the same drawing on the main thread
    // 27 %, the page before the worker 36-49 % in the same hour (docs/ui.md, Status).
    assert.ok(busy < 0.25, `main thread busy ${pct(busy)}`);
  } finally {
    ui.proc.kill("SIGKILL");
    await closeContexts();
  }
});
