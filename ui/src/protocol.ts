// The drive's machine-readable console (PROTOCOL: tagged lines R/D/T/H/N, `#<id>` command
// ids, `machine on`), independent of the transport and of the page.

export interface Reply {
  ok: boolean;
  /** The final line's text (`ok …` without `ok `, or the refusal without `error: `). */
  text: string;
  /** The reply's `D` lines, in order. */
  data: string[];
  /** When the command was sent and its reply ended (performance.now(), ms). */
  sent: number;
  done: number;
}

/** Key=value fields of a `D` line (`list`, `status`). */
export function fields(line: string): Record<string, string> {
  const out: Record<string, string> = {};
  for (const w of line.trim().split(/\s+/)) {
    const i = w.indexOf("=");
    if (i > 0) out[w.slice(0, i)] = w.slice(i + 1);
  }
  return out;
}

export interface TelSink {
  header(channels: string[]): void;
  /** One sample: `t` and the channels' values. */
  sample(t: number, v: number[]): void;
}

type Pending = { resolve: (r: Reply) => void; data: string[]; sent: number; line: string };

export class Console {
  private buf = "";
  private nextId = 1;
  private pending = new Map<string, Pending>();
  /** Every line that is not telemetry, for the console log (tagged as received). */
  onLine: (line: string) => void = () => {};
  onNotice: (text: string) => void = () => {};
  /** A line of the bridge itself (`! refused: …`). */
  onBridge: (text: string) => void = () => {};
  tel: TelSink | null = null;
  /** Telemetry lines that did not parse (count). */
  badTel = 0;
  /** Whether `machine on` was answered in machine form. */
  machine = false;

  constructor(private send: (text: string) => void) {}

  /** Text from the transport. */
  feed(text: string): void {
    const b = this.buf + text;
    let from = 0, i: number;
    while ((i = b.indexOf("\n", from)) >= 0) {
      const line = b.slice(from, i > from && b.charCodeAt(i - 1) === 13 ? i - 1 : i);
      from = i + 1;
      if (line.length) this.line(line);
    }
    this.buf = b.slice(from);
  }

  private line(l: string): void {
    const tag = l[0];
    if (l[1] !== " " && l.length > 1) {
      // Not a machine line: the human console's banner, echo or prompt before `machine on`.
      this.onLine(l);
      if (l.startsWith("error:") && this.pending.has("-")) this.finish("-", false, l.slice(6).trim());
      return;
    }
    const rest = l.slice(2);
    switch (tag) {
      case "T": {
        const s = rest.split(",");
        const t = Number(s[0]);
        const v = new Array<number>(s.length - 1);
        for (let k = 1; k < s.length; k++) v[k - 1] = Number(s[k]);
        if (!Number.isFinite(t)) this.badTel++;
        else this.tel?.sample(t, v);
        return;
      }
      case "H":
        this.onLine(l);
        this.tel?.header(rest.split(",").slice(1));
        return;
      case "N":
        this.onLine(l);
        this.onNotice(rest);
        return;
      case "D": {
        this.onLine(l);
        const sp = rest.indexOf(" ");
        const id = sp < 0 ? rest : rest.slice(0, sp);
        this.pending.get(id)?.data.push(sp < 0 ? "" : rest.slice(sp + 1));
        return;
      }
      case "R": {
        this.onLine(l);
        const m = /^(\S+) (ok|err)(?: (.*))?$/.exec(rest);
        if (m) this.finish(m[1], m[2] === "ok", m[3] ?? "");
        return;
      }
      case "!":
        this.onLine(l);
        this.onBridge(rest);
        // The bridge refused the whole message: the command it held gets no reply.
        for (const [id, p] of this.pending) if (id !== "-") { p.resolve({ ok: false, text: "the bridge refused the message: " + rest, data: [], sent: p.sent, done: performance.now() }); this.pending.delete(id); }
        return;
      default:
        this.onLine(l);
    }
  }

  private finish(id: string, ok: boolean, text: string): void {
    const p = this.pending.get(id);
    if (!p) return;
    this.pending.delete(id);
    if (id === "-" && ok) this.machine = true;
    p.resolve({ ok, text, data: p.data, sent: p.sent, done: performance.now() });
  }

  /** Switch the session to machine mode; the drive's refusal if it has none. */
  start(): Promise<Reply> {
    return this.raw("machine on", "-");
  }

  private raw(line: string, id: string): Promise<Reply> {
    return new Promise((resolve) => {
      this.pending.set(id, { resolve, data: [], sent: performance.now(), line });
      this.send(line + "\n");
    });
  }

  /** Send one command with a fresh id; resolves with its reply. */
  cmd(line: string): Promise<Reply> {
    const id = (this.nextId++).toString(36);
    return this.raw(`#${id} ${line}`, id);
  }

  /** The link ended: every command waiting gets a refusal. */
  fail(why: string): void {
    for (const p of this.pending.values()) p.resolve({ ok: false, text: why, data: [], sent: p.sent, done: performance.now() });
    this.pending.clear();
  }
}
