//! Decimal text ↔ `f32` for the console, small enough for the board image.
//!
//! core's `str::parse::<f64>` (Eisel–Lemire with a 10 KiB power-of-five table and a big-decimal
//! fallback) and `{}` on floats (Grisu with a Dragon fallback) cost about 25 KiB of flash on the
//! Cortex-M4; the console needs neither their full precision nor their range (everything it
//! reads or writes is an `f32`). This module does both in integer arithmetic only (a 64-bit
//! binary mantissa scaled by ten step by step, see `Big`): no soft-float `f64` is linked for
//! it on the board.
//!
//! * [`parse_f32`] accepts what `str::parse::<f64>` accepted on the console: an optional sign,
//!   digits with an optional `.` (at least one digit, `1.` and `.5` included), an optional
//!   exponent `e`/`E` with optional sign and at least one digit. Anything else (`nan`, `inf`,
//!   `0x10`, `1_000`, `1e`, spaces) is [`NumError::NotANumber`]; a value beyond `f32::MAX` is
//!   [`NumError::Overflow`]; a nonzero value whose nearest `f32` is zero (below half the smallest
//!   subnormal, 7.0e-46) is [`NumError::Underflow`] (core reads it as 0): both ends refused.
//!   **Precision**: the result is the `f32` nearest the decimal (ties to even) — the
//!   scaling carries 64 bits and a sticky bit, exact on ties, within 2⁻⁵⁶ (relative)
//!   otherwise, so only a decimal within 2⁻⁵⁶ of the midpoint between two `f32` (none of
//!   the console's short numbers) could round the other way — tested bit for bit against
//!   core's correctly rounded parser. Digits past the
//!   19th significant one are ignored (a relative change below 10⁻¹⁸: the result is then
//!   within 1 ulp of the correctly rounded value).
//! * [`Num`] displays an `f32` with the fewest significant digits (1 … 9) that parse back
//!   ([`parse_f32`] and core's parser both) to the same `f32`, like core's `{}`; positional
//!   for 10⁻⁵ ≤ |v| < 10¹⁰ (`0.0122`, `100`, `-2.5`), otherwise with an exponent (`1e-7`,
//!   `3.4028235e38`), where core's `{}` wrote every zero. `inf`, `-inf`, `NaN`, `0` and `-0`
//!   as core writes them.
//! * [`Fixed`] displays with a fixed number of decimals (≤ 9), like core's `{:.N}`, rounded to
//!   nearest, ties to even, from the same scaling (exact: an `f32` times 10⁹ fits 64 bits); beyond 10¹⁸ units
//!   of the last decimal it falls back to [`Num`].
//!
//! Nothing here panics or allocates.

use core::fmt;

/// A Q16.16 value as `f32`: the same value as `to_num::<f32>()` (the `i32` rounds to nearest,
/// ties to even, then the power-of-two scaling is exact), in two instructions instead of
/// `fixed`'s generic float conversion (≈ 0.5 KB of flash).
#[inline]
pub fn q_f32(x: crate::fx::Q) -> f32 {
    x.to_bits() as f32 * (1.0 / 65536.0)
}

/// Q16.16 from `f32`, saturating, NaN → 0, rounded to nearest with ties to even: the same
/// value as `fx::q` (`fixed`'s `saturating_from_num`), without its generic float conversion
/// (≈ 0.4 KB of flash). `v·2^16` is exact in `f32` and so is its fraction below 2^23.
pub fn q_of(v: f32) -> crate::fx::Q {
    use crate::fx::Q;
    let s = v * 65536.0;
    if v.is_nan() {
        Q::ZERO
    } else if s >= 2_147_483_648.0 {
        Q::MAX
    } else if s < -2_147_483_648.0 {
        Q::MIN
    } else {
        let t = s as i32; // toward zero
        let f = s - t as f32;
        let odd = t & 1 != 0;
        Q::from_bits(if f > 0.5 || (f == 0.5 && odd) {
            t + 1
        } else if f < -0.5 || (f == -0.5 && odd) {
            t - 1
        } else {
            t
        })
    }
}

/// Why [`parse_f32`] refused a text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NumError {
    /// Not a decimal number (includes `nan` and `inf`).
    NotANumber,
    /// A finite decimal whose magnitude exceeds `f32::MAX`.
    Overflow,
    /// A nonzero decimal whose nearest `f32` is zero.
    Underflow,
}

impl NumError {
    /// The reason, as the console writes it after the refused text.
    pub fn as_str(self) -> &'static str {
        match self {
            NumError::NotANumber => "not a number",
            NumError::Overflow => "above the f32 range (3.4e38)",
            NumError::Underflow => "below the f32 range (not 0, reads as 0)",
        }
    }
}

impl fmt::Display for NumError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// 10^0 … 10^19.
const POW10: [u64; 20] = {
    let mut t = [1u64; 20];
    let mut i = 1;
    while i < 20 {
        t[i] = t[i - 1] * 10;
        i += 1;
    }
    t
};

/// A positive binary floating-point value `m·2^e` with a 64-bit mantissa (normalised: bit
/// 63 set) and a sticky flag: `true` when bits below the mantissa were dropped (the exact
/// value is then a little *above* `m·2^e`). Multiplying or dividing by ten loses less than
/// one unit of the 64th bit per step; the callers take at most 84 steps, so the result is
/// within 2⁻⁵⁶ (relative) of the exact value, and *exact*, sticky clear, whenever the exact
/// value fits the mantissa — every tie between two `f32` or two decimals does (≤ 25 and
/// ≤ 54 significant bits). Integers only: no soft-float `f64` in the image; 64-bit words
/// (two registers on the Cortex-M4) keep the code small.
#[derive(Clone, Copy)]
struct Big {
    m: u64,
    e: i32,
    sticky: bool,
}

/// A non-negative value as integer part, 64 fraction bits, and whether bits below those
/// were dropped.
struct Split {
    int: u64,
    frac: u64,
    lost: bool,
}

impl Big {
    /// `v·2^e` (`v > 0`).
    fn new(v: u64, e: i32) -> Big {
        let z = v.leading_zeros();
        Big {
            m: v << z,
            e: e - z as i32,
            sticky: false,
        }
    }

    fn mul10(&mut self) {
        let p = self.m as u128 * 10;
        let (hi, lo) = ((p >> 64) as u64, p as u64); // hi < 10
        let sh = 64 - hi.leading_zeros(); // 3 or 4: bits above the 64 kept
        self.sticky |= lo & ((1 << sh) - 1) != 0;
        self.m = (hi << (64 - sh)) | (lo >> sh);
        self.e += sh as i32;
    }

    fn div10(&mut self) {
        let (q, r) = (self.m / 10, self.m % 10);
        let z = q.leading_zeros(); // 3 or 4
        let r = r << z;
        self.sticky |= r % 10 != 0;
        self.m = (q << z) | (r / 10);
        self.e -= z as i32;
    }

    /// `self·10^n`.
    #[inline(never)]
    fn scale10(mut self, n: i32) -> Big {
        for _ in 0..n.unsigned_abs() {
            if n > 0 {
                self.mul10()
            } else {
                self.div10()
            }
        }
        self
    }

    /// Integer part and fraction (`None` if the value is 2^64 or more).
    fn split(self) -> Option<Split> {
        let sh = -self.e; // value = m / 2^sh
        if sh <= 0 {
            return None;
        }
        Some(if sh < 64 {
            Split {
                int: self.m >> sh,
                frac: self.m << (64 - sh),
                lost: self.sticky,
            }
        } else if sh < 128 {
            let t = sh - 64;
            Split {
                int: 0,
                frac: self.m.checked_shr(t as u32).unwrap_or(0),
                lost: self.sticky || self.m & ((1u64 << t) - 1) != 0,
            }
        } else {
            Split {
                int: 0,
                frac: 0,
                lost: true,
            }
        })
    }

    /// Round to nearest, ties to even, at bit `sh` of the mantissa (`1 ≤ sh ≤ 64`): the
    /// mantissa kept, as an integer.
    fn round_at(self, sh: u32) -> u64 {
        let kept = self.m.checked_shr(sh).unwrap_or(0);
        let rest = self.m & (u64::MAX >> (64 - sh));
        let half = 1u64 << (sh - 1);
        let up = rest > half || (rest == half && (self.sticky || kept & 1 == 1));
        kept + up as u64
    }
}

fn n_digits(mut v: u64) -> i32 {
    let mut n = 1;
    while v >= 10 {
        v /= 10;
        n += 1;
    }
    n
}

/// The `f32` nearest `mant·10^e10` (`mant > 0`), see the module's precision note.
fn decimal_to_f32(mut mant: u64, mut e10: i32) -> Result<f32, NumError> {
    // Canonical form, so that equal values take the same path through `scale`.
    while mant.is_multiple_of(10) && mant != 0 {
        mant /= 10;
        e10 = e10.saturating_add(1);
    }
    if mant == 0 {
        return Ok(0.0);
    }
    let top = e10.saturating_add(n_digits(mant)); // mant·10^e10 < 10^top, ≥ 10^(top−1)
    if top - 1 > 38 {
        return Err(NumError::Overflow); // ≥ 1e39 > f32::MAX
    }
    if top <= -46 {
        return Err(NumError::Underflow); // ≤ 1e-46, below half the smallest subnormal (7.0e-46)
    }
    // Here −65 ≤ e10 ≤ 38 and mant < 10^19.
    let b = Big::new(mant, 0).scale10(e10);
    // The value is in [2^(63+e), 2^(64+e)): its f32 exponent, and where the 24-bit
    // significand ends (lower for a subnormal).
    let exp = 63 + b.e;
    if exp > 127 {
        return Err(NumError::Overflow);
    }
    let bits = if exp >= -126 {
        let sig = b.round_at(40) as u32; // 2^23 … 2^24 (carry into the exponent)
        (((exp + 126) as u32) << 23) + sig
    } else {
        let sh = 40 + (-126 - exp) as u32;
        if sh > 64 {
            0 // below 2^-150: half the smallest subnormal
        } else {
            b.round_at(sh) as u32
        }
    };
    let v = f32::from_bits(bits);
    if bits == 0 {
        Err(NumError::Underflow) // `mant > 0` rounded to zero
    } else if v.is_finite() {
        Ok(v)
    } else {
        Err(NumError::Overflow)
    }
}

/// Parse a console number; see the module documentation for the accepted forms.
pub fn parse_f32(s: &str) -> Result<f32, NumError> {
    let b = s.as_bytes();
    let mut i = 0;
    let neg = match b.first() {
        Some(b'-') => {
            i = 1;
            true
        }
        Some(b'+') => {
            i = 1;
            false
        }
        _ => false,
    };
    let mut mant: u64 = 0;
    let mut kept = 0; // significant digits in `mant`
    let mut e10: i32 = 0;
    let mut any = false;
    let mut frac = false;
    while i < b.len() {
        let c = b[i];
        if c == b'.' && !frac {
            frac = true;
            i += 1;
            continue;
        }
        if !c.is_ascii_digit() {
            break;
        }
        any = true;
        let d = (c - b'0') as u64;
        if mant == 0 && d == 0 {
            // A leading zero: only its place counts.
            if frac {
                e10 = e10.saturating_sub(1);
            }
        } else if kept < 19 {
            mant = mant * 10 + d;
            kept += 1;
            if frac {
                e10 = e10.saturating_sub(1);
            }
        } else if !frac {
            e10 = e10.saturating_add(1); // a dropped integer digit still scales
        }
        i += 1;
    }
    if !any {
        return Err(NumError::NotANumber);
    }
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        i += 1;
        let eneg = match b.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let mut e: i32 = 0;
        let mut edigits = false;
        while i < b.len() && b[i].is_ascii_digit() {
            e = (e * 10 + (b[i] - b'0') as i32).min(1_000_000);
            edigits = true;
            i += 1;
        }
        if !edigits {
            return Err(NumError::NotANumber);
        }
        e10 = e10.saturating_add(if eneg { -e } else { e });
    }
    if i != b.len() {
        return Err(NumError::NotANumber);
    }
    let v = decimal_to_f32(mant, e10)?;
    Ok(if neg { -v } else { v })
}

/// A small stack buffer implementing the text building (never more than 32 bytes used).
/// A `heapless::String`, not bytes: its text is a `&str` without `core::str::from_utf8`
/// (which, with its 256-byte table, is 0.6 KB of the board's flash).
struct Buf(heapless::String<40>);

impl Buf {
    fn new() -> Buf {
        Buf(heapless::String::new())
    }
    /// One ASCII byte (the only kind pushed); dropped when the buffer is full.
    fn push(&mut self, c: u8) {
        let _ = self.0.push(char::from(c));
    }
    /// The decimal digits of `v`, `width` of them at least (zero padded).
    #[inline(never)]
    fn push_u64(&mut self, mut v: u64, width: usize) {
        let mut d = [0u8; 20];
        let mut n = 0;
        while (v > 0 || n < width.max(1)) && n < d.len() {
            d[n] = b'0' + (v % 10) as u8;
            v /= 10;
            n += 1;
        }
        while n > 0 {
            n -= 1;
            self.push(d[n]);
        }
    }
    fn push_str(&mut self, s: &str) {
        for &c in s.as_bytes() {
            self.push(c);
        }
    }
    fn as_str(&self) -> &str {
        self.0.as_str()
    }
}

/// A number's text, built on the stack: [`Num::text`], [`Fixed::text`], [`uint`]. Writing it
/// with `write_str` keeps `core::fmt`'s formatting machinery (`write!`, `Formatter`) out of
/// the board image.
pub struct Text(Buf);

impl Text {
    pub fn as_str(&self) -> &str {
        self.0.as_str()
    }
}

/// The decimal text of an unsigned integer.
pub fn uint(v: u64) -> Text {
    let mut buf = Buf::new();
    buf.push_u64(v, 0);
    Text(buf)
}

/// The shortest decimal `d·10^e` (d with 1 … 9 digits) that converts back to `x`
/// (finite, > 0).
fn shortest(x: f32) -> (u64, i32) {
    let bits = x.to_bits();
    let be = ((bits >> 23) & 0xff) as i32;
    let frac = (bits & 0x7f_ffff) as u64;
    // x = b exactly; e2 = floor(log2 x).
    let (b, e2) = if be == 0 {
        (Big::new(frac, -149), 63 - frac.leading_zeros() as i32 - 149) // subnormal
    } else {
        (Big::new(frac | 1 << 23, be - 150), be - 127)
    };
    // k ≈ floor(log10 x) (1233/4096 ≈ log10 2), then made exact so that
    // s = x·10^(8−k) rounds to a 9-digit integer.
    let s_of = |k: i32| {
        b.scale10(8 - k).split().unwrap_or(Split {
            int: u64::MAX,
            frac: 0,
            lost: false,
        })
    };
    let mut k = (e2 * 1233) >> 12;
    let mut s = s_of(k);
    for _ in 0..4 {
        let half = s.frac >= 1 << 63;
        if s.int > 999_999_999 || (s.int == 999_999_999 && half) {
            k += 1; // s ≥ 999,999,999.5
        } else if s.int < 99_999_999 || (s.int == 99_999_999 && !half) {
            k -= 1; // s < 99,999,999.5
        } else {
            break;
        }
        s = s_of(k);
    }
    let good = |(d, e): (u64, i32)| decimal_to_f32(d, e) == Ok(x);
    let digits = |p: i32| digits_p(&s, k, p);
    // Fewest digits that round-trip: 9 always do for an f32 (half a unit of the 9th digit is
    // ≤ 5·10⁻⁹ relative, half an f32 ulp ≥ 2.98·10⁻⁸); a binary search over 1 … 8, each
    // candidate checked by converting it back.
    let (mut lo, mut hi) = (1, 9);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if good(digits(mid)) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    let (mut d, mut e) = digits(hi);
    while d.is_multiple_of(10) && d != 0 {
        d /= 10;
        e += 1;
    }
    (d, e)
}

/// `s` (the value times 10^(8−k), in [10^8 − 0.5, 10^9 − 0.5)) rounded to `p` digits (ties
/// away from zero: the candidates are checked by converting them back, so the tie rule does
/// not matter), as `d·10^e`.
#[inline(never)]
fn digits_p(s: &Split, k: i32, p: i32) -> (u64, i32) {
    let div = POW10[(9 - p) as usize];
    // s/div = q + (r + frac)/div; for div ≥ 10, div/2 is an integer, so the rest reaches
    // one half exactly when r ≥ div/2.
    let (q, r) = (s.int / div, s.int % div);
    let up = if div == 1 {
        s.frac >= 1 << 63
    } else {
        r >= div / 2
    };
    let mut d = q + up as u64;
    let mut e = k - p + 1;
    if d >= POW10[p as usize] {
        d /= 10; // 9.99… rounded up to 10.0…
        e += 1;
    }
    (d, e)
}

fn write_special(v: f32, buf: &mut Buf) -> bool {
    if v.is_nan() {
        buf.push_str("NaN");
    } else if v.is_infinite() {
        buf.push_str(if v > 0.0 { "inf" } else { "-inf" });
    } else if v == 0.0 {
        buf.push_str(if v.is_sign_negative() { "-0" } else { "0" });
    } else {
        return false;
    }
    true
}

fn write_num(v: f32, buf: &mut Buf) {
    if write_special(v, buf) {
        return;
    }
    if v < 0.0 {
        buf.push(b'-');
    }
    let (d, e) = shortest(v.abs());
    let nd = n_digits(d);
    let k = e + nd - 1; // decimal exponent of the leading digit
    if (-5..10).contains(&k) {
        if e >= 0 {
            buf.push_u64(d, 0);
            for _ in 0..e {
                buf.push(b'0');
            }
        } else {
            let f = (-e) as u32; // digits after the point
            let p = 10u64.pow(f.min(19));
            if f >= nd as u32 {
                buf.push(b'0');
            } else {
                buf.push_u64(d / p, 0);
            }
            buf.push(b'.');
            buf.push_u64(d % p, f as usize);
        }
    } else {
        let p = 10u64.pow((nd - 1) as u32);
        buf.push_u64(d / p, 0);
        if nd > 1 {
            buf.push(b'.');
            buf.push_u64(d % p, (nd - 1) as usize);
        }
        buf.push(b'e');
        if k < 0 {
            buf.push(b'-');
        }
        buf.push_u64(k.unsigned_abs() as u64, 0);
    }
}

/// Display an `f32` with the fewest digits that read back to it (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Num(pub f32);

impl Num {
    /// The text, without `core::fmt` (see [`Text`]).
    pub fn text(self) -> Text {
        let mut buf = Buf::new();
        write_num(self.0, &mut buf);
        Text(buf)
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text().as_str())
    }
}

/// Display an `f32` with `self.1` decimals (at most 9), like `{:.N}`.
#[derive(Clone, Copy, Debug)]
pub struct Fixed(pub f32, pub u8);

impl Fixed {
    /// The text, without `core::fmt` (see [`Text`]).
    pub fn text(self) -> Text {
        let mut buf = Buf::new();
        let n = self.1.min(9) as i32;
        let a = self.0.abs();
        let bits = a.to_bits();
        let (be, frac) = (((bits >> 23) & 0xff) as i32, (bits & 0x7f_ffff) as u64);
        // |v|·10^n, exact (24 + 30 bits fit the mantissa), split at the point.
        let s = if !a.is_finite() {
            None
        } else if a == 0.0 {
            Some(Split {
                int: 0,
                frac: 0,
                lost: false,
            })
        } else if be == 0 {
            Big::new(frac, -149).scale10(n).split()
        } else {
            Big::new(frac | 1 << 23, be - 150).scale10(n).split()
        };
        // Ties to even, as core (a tie is exact here: `lost` is clear only then).
        let q = s.map(|s| {
            let half = 1u64 << 63;
            let up = s.frac > half || (s.frac == half && (s.lost || s.int % 2 == 1));
            s.int.saturating_add(up as u64)
        });
        match q {
            Some(q) if q < POW10[18] => {
                if self.0.is_sign_negative() {
                    buf.push(b'-');
                }
                let p = POW10[n as usize];
                buf.push_u64(q / p, 0);
                if n > 0 {
                    buf.push(b'.');
                    buf.push_u64(q % p, n as usize);
                }
            }
            _ => write_num(self.0, &mut buf),
        }
        Text(buf)
    }
}

impl fmt::Display for Fixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text().as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::format;
    use std::string::String;

    fn ulps(a: f32, b: f32) -> u32 {
        // Distance in representable steps (same sign assumed, as in the uses below).
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32
    }

    /// What the console accepted before (core's parser, then the f32 range check), and the
    /// value it gave (core's f64 parse then `as f32`).
    fn core_accepts(s: &str) -> Option<f32> {
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() && (v as f32).is_finite() => Some(v as f32),
            _ => None,
        }
    }

    #[test]
    fn parses_every_console_form() {
        let cases: &[(&str, f32)] = &[
            ("0", 0.0),
            ("100", 100.0),
            ("+100", 100.0),
            ("-2.5", -2.5),
            ("1.", 1.0),
            (".5", 0.5),
            ("-.5", -0.5),
            ("0.0122", 0.0122),
            ("1e-3", 1e-3),
            ("1E3", 1e3),
            ("2.5e+2", 250.0),
            ("-1.5e-07", -1.5e-7),
            ("000012.5000", 12.5),
            ("3.4028235e38", f32::MAX),
            ("0e-99", 0.0),
            ("0.000", 0.0),
            ("1.17549435e-38", f32::MIN_POSITIVE),
            ("1.4e-45", f32::from_bits(1)),
            ("0.000000000000000000000000000000000000001", 1e-39),
        ];
        for &(s, v) in cases {
            assert_eq!(parse_f32(s), Ok(v), "{s}");
        }
        assert!(parse_f32("-0").unwrap().is_sign_negative());
        // Digits past the 19th are dropped: still the nearest f32 here.
        let long = "123456789012345678901234567890";
        assert_eq!(parse_f32(long), Ok(long.parse::<f32>().unwrap()));
        for s in [
            "", "+", "-", ".", "e3", ".e3", "1e", "1e+", "1e-", "1.2.3", "--1", "+-1", "1 ", " 1",
            "0x10", "1_000", "nan", "NaN", "inf", "-inf", "infinity", "1f", "1e3.5", "١",
        ] {
            assert_eq!(parse_f32(s), Err(NumError::NotANumber), "{s:?}");
        }
        for s in [
            "1e39",
            "-1e99",
            "3.5e38",
            "1e99999999999",
            "99999999999999999999e30",
        ] {
            assert_eq!(parse_f32(s), Err(NumError::Overflow), "{s}");
        }
        // Underflow is refused as overflow is: a nonzero decimal that would read as 0. Half
        // the smallest subnormal (2^-150 = 7.0064923e-46) rounds to even (0); just above it
        // rounds up to the smallest subnormal.
        for s in [
            "1e-50",
            "-1e-50",
            "1e-99999999999",
            "7e-46",
            "7.00649232162408535461864791e-46",
        ] {
            assert_eq!(parse_f32(s), Err(NumError::Underflow), "{s}");
        }
        assert_eq!(parse_f32("7.1e-46"), Ok(f32::from_bits(1)));
    }

    #[test]
    fn formats_like_core_for_console_values() {
        // Values whose shortest representation is positional: identical text to core's `{}`.
        for v in [
            0.0f32,
            -0.0,
            1.0,
            100.0,
            -2.5,
            0.0122,
            0.0293,
            2048.0,
            20000.0,
            0.1,
            0.3,
            1e-5,
            1e9,
            123456.79,
            core::f32::consts::PI,
            core::f32::consts::TAU,
            -core::f32::consts::TAU,
            1.0e-4,
            5.0e-4,
            95.0,
            0.6,
        ] {
            assert_eq!(format!("{}", Num(v)), format!("{v}"), "{v:e}");
        }
        assert_eq!(format!("{}", Num(f32::INFINITY)), "inf");
        assert_eq!(format!("{}", Num(f32::NEG_INFINITY)), "-inf");
        assert_eq!(format!("{}", Num(f32::NAN)), "NaN");
        assert_eq!(format!("{}", Num(1e-7)), "1e-7");
        assert_eq!(format!("{}", Num(-1.5e-7)), "-1.5e-7");
        assert_eq!(format!("{}", Num(1e10)), "1e10");
        assert_eq!(format!("{}", Num(f32::MAX)), "3.4028235e38");
        assert_eq!(format!("{}", Num(f32::from_bits(1))), "1e-45");
        assert_eq!(format!("{}", Fixed(0.5, 6)), "0.500000");
        assert_eq!(format!("{}", Fixed(-12.25, 1)), "-12.2"); // 12.25 exact: tie
        assert_eq!(format!("{}", Fixed(3.0, 0)), "3");
        assert_eq!(format!("{}", Fixed(1e30, 6)), "1e30");
        assert_eq!(format!("{}", Fixed(f32::NAN, 6)), "NaN");
    }

    /// Significant digits of a shortest text (from its mantissa, sign, point and exponent off).
    fn sig_digits(s: &str) -> usize {
        let m = s.split('e').next().unwrap_or("");
        let digits: String = m.chars().filter(|c| c.is_ascii_digit()).collect();
        let t = digits.trim_start_matches('0').trim_end_matches('0');
        t.len().max(1)
    }

    proptest! {
        #[test]
        fn q_of_is_fx_q(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            prop_assert_eq!(q_of(v), crate::fx::q(v), "{:e}", v);
        }

        #[test]
        fn q_of_is_fx_q_near_q16(raw in any::<i32>(), half in any::<bool>()) {
            // Values on and next to the Q16.16 grid, ties included.
            let v = (raw as f32 + if half { 0.5 } else { 0.0 }) / 65536.0;
            prop_assert_eq!(q_of(v), crate::fx::q(v), "{:e}", v);
        }

        #[test]
        fn q_f32_is_to_num(bits in any::<i32>()) {
            let x = crate::fx::Q::from_bits(bits);
            prop_assert_eq!(q_f32(x).to_bits(), x.to_num::<f32>().to_bits());
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        /// Every finite f32 (any bit pattern): the text reads back to the same value, by our
        /// parser and by core's (correctly rounded) one, and it is no longer than core's
        /// shortest representation: at most one digit more, and only where the shortest
        /// decimal lies on the narrow side of a power of two (see `shortest`).
        #[test]
        fn num_round_trips_every_f32(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let s = format!("{}", Num(v));
            prop_assert_eq!(parse_f32(&s).map(f32::to_bits), Ok(v.to_bits()), "{}", s);
            prop_assert_eq!(s.parse::<f32>().map(f32::to_bits), Ok(v.to_bits()), "{}", s);
            if v != 0.0 {
                let core_n = sig_digits(&format!("{:e}", v));
                let ours = sig_digits(&s);
                prop_assert!(ours <= core_n + usize::from(bits & 0x7f_ffff == 0), "{} vs {:e}", s, v);
            }
        }

        /// The `f32` values the console shows in practice (Q16.16 telemetry, parameters):
        /// identical text to core's `{}` in the positional range.
        #[test]
        fn num_matches_core_on_q16(raw in any::<i32>()) {
            let v = raw as f32 / 65536.0;
            prop_assume!(v == 0.0 || v.abs() >= 1e-5);
            let ours = format!("{}", Num(v));
            let core_s = format!("{v}");
            prop_assert_eq!(ours, core_s);
        }

        /// Decimal texts of every accepted shape: accepted exactly when core accepted them, and
        /// within 1 ulp of core's correctly rounded `f32` parse, and equal to it when no
        /// digit is dropped (≤ 19 significant digits).
        #[test]
        fn parse_agrees_with_core(s in "[-+]?[0-9]{0,22}(\\.[0-9]{0,22})?([eE][-+]?[0-9]{1,3})?") {
            let ours = parse_f32(&s);
            match core_accepts(&s) {
                None => prop_assert!(ours.is_err(), "{} -> {:?}", s, ours),
                Some(_) => {
                    let exact: f32 = s.parse().unwrap();
                    let m = s.split(['e', 'E']).next().unwrap_or("");
                    if exact == 0.0 && m.bytes().any(|c| (b'1'..=b'9').contains(&c)) {
                        // A nonzero decimal core reads as 0: refused here.
                        prop_assert_eq!(ours, Err(NumError::Underflow), "{}", s);
                        return Ok(());
                    }
                    let v = ours.unwrap();
                    prop_assert!(ulps(v, exact) <= 1, "{} -> {:e} vs {:e}", s, v, exact);
                    // Up to 19 significant digits nothing is dropped: correctly rounded.
                    let m = s.split(['e', 'E']).next().unwrap_or("");
                    let digits: String = m.chars().filter(|c| c.is_ascii_digit()).collect();
                    if digits.trim_matches('0').len() <= 19 {
                        prop_assert_eq!(v.to_bits(), exact.to_bits(), "{}", s);
                    }
                }
            }
        }

        /// Short decimals as typed on the console (≤ 7 significant digits, |exponent| ≤ 10):
        /// the exact nearest f32 (the f64 path has one rounding before the final one).
        #[test]
        fn parse_short_decimals_exactly(m in 0u32..10_000_000, e in -10i32..=10, neg in any::<bool>()) {
            let s = format!("{}{}e{}", if neg { "-" } else { "" }, m, e);
            let exact: f32 = s.parse().unwrap();
            prop_assert_eq!(parse_f32(&s).map(f32::to_bits), Ok(exact.to_bits()), "{}", s);
        }

        /// `Fixed` against core's `{:.N}` for values whose scaled magnitude is well inside the
        /// exact range (f32 times 10^N below 2^53): identical text.
        #[test]
        fn fixed_matches_core(raw in any::<i32>(), n in 0u8..=6) {
            let v = raw as f32 / 4096.0;
            let ours = format!("{}", Fixed(v, n));
            let core_s = format!("{:.*}", n as usize, v);
            prop_assert_eq!(ours, core_s);
        }

        /// Any finite `f32` (subnormals and ties included) and up to 9 decimals: identical text
        /// to core's `{:.N}` while the result has at most 17 digits (then `Fixed` is positional).
        #[test]
        fn fixed_matches_core_any_f32(m in 0u32..1 << 24, eu in any::<u32>(), n in 0u8..=9, neg in any::<bool>()) {
            // v = ±m·2^e, exact in f32 for e ≥ −149; e up to 32 − 4n keeps |v|·10^n < 2^56.
            let e = -149 + (eu % (182 - 4 * n as u32)) as i32;
            let v = (m as f64 * 2f64.powi(e)) as f32;
            let v = if neg { -v } else { v };
            prop_assert_eq!(v as f64, if neg { -1.0 } else { 1.0 } * m as f64 * 2f64.powi(e));
            let ours = format!("{}", Fixed(v, n));
            let core_s = format!("{:.*}", n as usize, v);
            prop_assert_eq!(ours, core_s);
        }
    }
}
