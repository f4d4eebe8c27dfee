// Units of the drive's quantities and their display: significant digits with an SI prefix,
// as a drive's status bar shows them.

/** Units of `tel`'s channels (docs/console.md, `tel`). */
export const CHANNEL_UNIT: Record<string, string> = {
  ia: "A", ib: "A", ic: "A", id: "A", iq: "A", id_ref: "A", iq_ref: "A",
  vd: "V", vq: "V", vbus: "V", w: "rad/s", x: "m", p: "W",
};

/** The unit a channel is in ("" when unknown). */
export const unitOf = (ch: string): string => CHANNEL_UNIT[ch] ?? "";

/** A status key's unit suffix and display name: `speed_rad_s` → ["speed", "rad/s"]. */
const SUFFIX: [string, string][] = [["_rad_s", "rad/s"], ["_v", "V"], ["_a", "A"], ["_w", "W"], ["_j", "J"], ["_m", "m"], ["_s", "s"]];
export function splitKey(key: string): [string, string] {
  for (const [suf, unit] of SUFFIX) if (key.endsWith(suf)) return [key.slice(0, -suf.length).replace(/_/g, " "), unit];
  return [key.replace(/_/g, " "), ""];
}

/** Units that take an SI prefix (k, m, µ); others (rad/s, counts) are shown as they are. */
const PREFIXED = new Set(["V", "A", "W", "J", "m", "s", "Ω"]);

/** `x` with `sig` significant digits and its unit, prefixed: 0.04796 m → "47.96 mm". */
export function fmtQty(x: number, unit: string, sig = 4): string {
  if (!Number.isFinite(x)) return String(x);
  let v = x, pre = "";
  if (PREFIXED.has(unit) && x !== 0) {
    const a = Math.abs(x);
    if (a >= 1e3 && unit !== "s") { v = x / 1e3; pre = "k"; }
    else if (a < 1e-3) { v = x * 1e6; pre = "µ"; }
    else if (a < 1) { v = x * 1e3; pre = "m"; }
  }
  let t = v === 0 ? "0" : v.toPrecision(sig);
  if (t.includes("e")) t = String(Number(t));
  return unit ? `${t} ${pre}${unit}` : t;
}

/** A status field's value for display: numbers with their unit, words as they are. */
export function fmtField(key: string, raw: string): string {
  const [, unit] = splitKey(key);
  const x = Number(raw);
  if (raw === "" || raw === "-" ) return "–";
  if (!Number.isFinite(x)) return raw;
  return fmtQty(x, unit);
}
