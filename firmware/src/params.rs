//! The parameter registry: the one source of every tunable's name, unit, bounds, default,
//! description and whether it may change while the drive runs.
//!
//! Table driven: a new [`Config`] field gets one [`Param`] entry in [`PARAMS`] (use the
//! `real!`/`int!`/`flag!` macros). The default shown is always read from `Config::default()`
//! through the entry's getter, so it cannot drift. Values cross the console as `f32`; integer,
//! flag and law parameters must be integral. Setting is validated twice: against the entry's
//! range, then the whole candidate `Config` against [`Config::validate`] (relations between
//! fields); on any refusal nothing changes.

use crate::config::Config;
use crate::laws::LawKind;

/// How a parameter's value is interpreted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Any finite value in range (or `inf` when `max` is infinite).
    Real,
    /// An integer in range.
    Int,
    /// 0 or 1.
    Flag,
    /// A [`LawKind`] code.
    Law,
}

/// One registry entry.
#[derive(Clone, Copy)]
pub struct Param {
    pub name: &'static str,
    pub unit: &'static str,
    pub kind: Kind,
    pub min: f32,
    pub max: f32,
    /// May be changed while the drive is in `Run` (otherwise only in Idle/Short/Open).
    pub runtime: bool,
    /// The description (`Param::desc`); not in the board's image (`target_os = "none"`), for
    /// flash: the descriptions are ≈ 2 KB of the 64 KiB, and `docs/console.md` has them.
    #[cfg(not(target_os = "none"))]
    pub desc: &'static str,
    pub get: fn(&Config) -> f32,
    pub set: fn(&mut Config, f32),
}

/// Why a set was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamError {
    UnknownName,
    NotFinite,
    NotInteger,
    OutOfRange,
    NotWhileRunning,
    /// The whole configuration was refused: field and reason from [`Config::validate`].
    Invalid(&'static str, &'static str),
}

impl ParamError {
    /// The message; for [`ParamError::Invalid`] its start, followed by `: field: reason`.
    pub fn message(self) -> &'static str {
        match self {
            ParamError::UnknownName => "unknown parameter",
            ParamError::NotFinite => "value is not a finite number",
            ParamError::NotInteger => "value must be an integer",
            ParamError::OutOfRange => "value out of range",
            ParamError::NotWhileRunning => {
                "parameter may not change while running (mode idle first)"
            }
            ParamError::Invalid(..) => "config refused",
        }
    }
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())?;
        match self {
            ParamError::Invalid(field, why) => write!(f, ": {field}: {why}"),
            _ => Ok(()),
        }
    }
}

macro_rules! real {
    ($field:ident, $unit:expr, $min:expr, $max:expr, $rt:expr, $desc:expr) => {
        Param {
            name: stringify!($field),
            unit: $unit,
            kind: Kind::Real,
            min: $min,
            max: $max,
            runtime: $rt,
            #[cfg(not(target_os = "none"))]
            desc: $desc,
            get: |c| c.$field,
            set: |c, v| c.$field = v,
        }
    };
}
macro_rules! int {
    ($field:ident, $ty:ty, $unit:expr, $min:expr, $max:expr, $rt:expr, $desc:expr) => {
        Param {
            name: stringify!($field),
            unit: $unit,
            kind: Kind::Int,
            min: $min,
            max: $max,
            runtime: $rt,
            #[cfg(not(target_os = "none"))]
            desc: $desc,
            get: |c| c.$field as f32,
            set: |c, v| c.$field = v as $ty,
        }
    };
}
macro_rules! flag {
    ($field:ident, $rt:expr, $desc:expr) => {
        Param {
            name: stringify!($field),
            unit: "0/1",
            kind: Kind::Flag,
            min: 0.0,
            max: 1.0,
            runtime: $rt,
            #[cfg(not(target_os = "none"))]
            desc: $desc,
            get: |c| if c.$field { 1.0 } else { 0.0 },
            set: |c, v| c.$field = v != 0.0,
        }
    };
}

/// Every parameter, in display order.
pub static PARAMS: &[Param] = &[
    real!(
        r_load_ohm,
        "ohm",
        0.0,
        f32::INFINITY,
        true,
        "emulated load resistance per phase (inf = open)"
    ),
    Param {
        name: "law",
        unit: "code",
        kind: Kind::Law,
        min: 0.0,
        max: 255.0,
        runtime: false,
        #[cfg(not(target_os = "none"))]
        desc: "command law code (0 resistor, 1 impedance, 2 tracking, 3 two-way, 4 one-way)",
        get: |c| c.law as u8 as f32,
        set: |c, v| {
            if let Some(k) = LawKind::from_code(v as u8) {
                c.law = k
            }
        },
    },
    real!(
        law_rate_hz,
        "Hz",
        50.0,
        100_000.0,
        false,
        "command-law update rate (<= pwm_hz)"
    ),
    real!(
        l_load_h,
        "H",
        0.0,
        10_000.0,
        true,
        "impedance law: series load inductance (0 = none)"
    ),
    real!(
        c_load_f,
        "F",
        0.0,
        100.0,
        true,
        "impedance law: series load capacitance (0 = none)"
    ),
    real!(
        trk_dither,
        "1",
        0.01,
        1.0,
        true,
        "tracking law: relative R_L dither"
    ),
    real!(
        trk_period_s,
        "s",
        0.05,
        3_600.0,
        true,
        "tracking law: dither period"
    ),
    real!(trk_gain, "1", 0.0, 100.0, true, "tracking law: gain"),
    real!(
        trk_step_max,
        "1",
        0.0,
        5.0,
        true,
        "tracking law: max relative step"
    ),
    real!(
        trk_r_min_ohm,
        "ohm",
        0.01,
        1.0e6,
        true,
        "tracking law: min R_L"
    ),
    real!(
        trk_r_max_ohm,
        "ohm",
        0.01,
        1.0e6,
        true,
        "tracking law: max R_L"
    ),
    real!(
        trk_p_min_w,
        "W",
        0.0,
        1.0e6,
        true,
        "tracking law: min power to adapt"
    ),
    real!(
        current_bw_hz,
        "Hz",
        10.0,
        5_000.0,
        true,
        "current-loop bandwidth"
    ),
    real!(
        speed_bw_hz,
        "Hz",
        1.0,
        2_000.0,
        true,
        "speed-tracking PLL bandwidth"
    ),
    real!(
        pwm_hz,
        "Hz",
        5_000.0,
        100_000.0,
        false,
        "PWM and current-loop frequency"
    ),
    real!(
        i_max_a,
        "A",
        0.0,
        1_000.0,
        true,
        "current reference limit (dq magnitude)"
    ),
    real!(i_trip_a, "A", 0.1, 2_000.0, true, "phase over-current trip"),
    real!(v_bus_ov, "V", 1.0, 2_000.0, true, "bus over-voltage trip"),
    real!(
        v_bus_uv,
        "V",
        0.0,
        2_000.0,
        true,
        "bus under-voltage trip while running"
    ),
    real!(
        brake_on_v,
        "V",
        1.0,
        2_000.0,
        true,
        "brake chopper on above"
    ),
    real!(
        brake_off_v,
        "V",
        0.0,
        2_000.0,
        true,
        "brake chopper off below"
    ),
    real!(
        derate_start_v,
        "V",
        1.0,
        2_000.0,
        true,
        "regenerative current derated from this bus voltage (>= brake_on_v)"
    ),
    real!(
        derate_end_v,
        "V",
        1.0,
        2_000.0,
        true,
        "regenerative current zero at this bus voltage (<= v_bus_ov)"
    ),
    real!(
        f_trip_n,
        "N",
        1.0,
        f32::INFINITY,
        true,
        "force trip on the filtered force (device rating; inf = off)"
    ),
    real!(
        f_filter_s,
        "s",
        1e-3,
        10.0,
        true,
        "time constant of the force filter"
    ),
    real!(
        i2t_cont_a,
        "A",
        0.01,
        1_000.0,
        true,
        "machine continuous current for the I2t estimate"
    ),
    real!(
        i2t_tau_s,
        "s",
        0.1,
        1.0e5,
        true,
        "winding thermal time constant for the I2t estimate"
    ),
    real!(
        omega_max_rad_s,
        "rad/s",
        1.0,
        2_000.0,
        true,
        "largest plausible shaft speed"
    ),
    real!(
        enc_emf_tol_v,
        "V",
        0.1,
        2_000.0,
        true,
        "encoder/emf plausibility allowance (plus 50 %)"
    ),
    real!(
        x_min_m,
        "m",
        -1_000.0,
        1_000.0,
        true,
        "stroke limit, low end"
    ),
    real!(
        x_max_m,
        "m",
        -1_000.0,
        1_000.0,
        true,
        "stroke limit, high end"
    ),
    real!(
        i_sum_tol_a,
        "A",
        0.0,
        1_000.0,
        true,
        "largest |ia+ib+ic| (current-sensor consistency)"
    ),
    int!(
        overrun_max,
        u16,
        "count",
        1.0,
        10_000.0,
        true,
        "loop overruns tolerated beyond one per ms"
    ),
    real!(
        align_i_a,
        "A",
        0.1,
        1_000.0,
        true,
        "power-up alignment d current"
    ),
    real!(
        align_time_s,
        "s",
        0.02,
        10.0,
        true,
        "power-up alignment, each of 2 steps"
    ),
    real!(
        align_travel_m,
        "m",
        1e-5,
        1.0,
        true,
        "largest travel while aligning"
    ),
    real!(
        offset_tol_a,
        "A",
        0.0,
        1_000.0,
        true,
        "largest phase zero-current offset at boot"
    ),
    real!(
        angle_tol_deg,
        "deg",
        10.0,
        90.0,
        true,
        "largest angle of the emf from the q axis"
    ),
    real!(
        angle_emf_min_v,
        "V",
        0.1,
        2_000.0,
        true,
        "angle check only above this emf"
    ),
    real!(
        m_max,
        "1",
        0.1,
        1.0,
        true,
        "usable fraction of the linear modulation circle"
    ),
    flag!(ff_emf, true, "back-emf feed-forward on q"),
    flag!(ff_decouple, true, "dq cross-coupling feed-forward"),
    flag!(delay_comp, true, "advance output angle by 1.5 periods"),
    real!(
        r_phase_ohm,
        "ohm",
        1e-3,
        100.0,
        false,
        "phase resistance, line-to-neutral"
    ),
    real!(
        l_phase_h,
        "H",
        1e-6,
        1.0,
        false,
        "phase inductance, line-to-neutral"
    ),
    real!(
        ke_v_s_per_rad,
        "V*s/rad",
        1e-4,
        20.0,
        false,
        "back-emf constant, per-phase peak"
    ),
    int!(pole_pairs, u8, "1", 1.0, 50.0, false, "pole pairs"),
    real!(lead_m_per_rad, "m/rad", 1e-5, 1.0, false, "screw lead"),
    int!(
        encoder_cpr,
        u32,
        "count",
        16.0,
        16_384.0,
        false,
        "encoder counts per turn (x4)"
    ),
    real!(
        encoder_offset_rad,
        "rad",
        -core::f32::consts::TAU,
        core::f32::consts::TAU,
        false,
        "electrical angle of d axis at count 0"
    ),
    real!(
        amps_per_count,
        "A",
        1e-5,
        1.0,
        false,
        "phase current per ADC count"
    ),
    int!(
        adc_zero_code,
        u16,
        "count",
        512.0,
        3_583.0,
        false,
        "ADC code of zero current"
    ),
    real!(
        volts_per_count,
        "V",
        1e-4,
        1.0,
        false,
        "bus voltage per ADC count"
    ),
];

/// The entry of a name (exact, case-sensitive).
pub fn find(name: &str) -> Option<&'static Param> {
    PARAMS.iter().find(|p| p.name == name)
}

impl Param {
    /// The description (`list` shows it when there is one).
    #[cfg(not(target_os = "none"))]
    pub fn desc(&self) -> &'static str {
        self.desc
    }

    /// The description: none in the board's image.
    #[cfg(target_os = "none")]
    pub fn desc(&self) -> &'static str {
        ""
    }

    /// The default, read from `Config::default()`.
    pub fn default_value(&self) -> f32 {
        (self.get)(&Config::default())
    }

    /// Check `v` against this entry alone.
    pub fn check(&self, v: f32) -> Result<(), ParamError> {
        if v.is_nan() || (v.is_infinite() && !(v > 0.0 && self.max.is_infinite())) {
            return Err(ParamError::NotFinite);
        }
        if self.kind != Kind::Real && v != (v as i64) as f32 {
            return Err(ParamError::NotInteger);
        }
        if !(v >= self.min && v <= self.max) {
            return Err(ParamError::OutOfRange);
        }
        if self.kind == Kind::Law && LawKind::from_code(v as u8).is_none() {
            return Err(ParamError::OutOfRange);
        }
        Ok(())
    }

    /// Set `v` in `cfg` if it and the resulting configuration are valid; otherwise leave
    /// `cfg` unchanged.
    pub fn apply(&self, cfg: &mut Config, v: f32, running: bool) -> Result<(), ParamError> {
        if running && !self.runtime {
            return Err(ParamError::NotWhileRunning);
        }
        self.check(v)?;
        let mut c = *cfg;
        (self.set)(&mut c, v);
        c.validate()
            .map_err(|e| ParamError::Invalid(e.field, e.reason))?;
        *cfg = c;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_unique_and_defaults_match_config_default() {
        let d = Config::default();
        for (i, p) in PARAMS.iter().enumerate() {
            assert!(
                PARAMS[i + 1..].iter().all(|q| q.name != p.name),
                "{}",
                p.name
            );
            assert!(
                p.check(p.default_value()).is_ok(),
                "{} default out of its range",
                p.name
            );
            // Setting the default into a default config reproduces the default config.
            let mut c = d;
            p.apply(&mut c, p.default_value(), false).unwrap();
            assert_eq!(c, d, "{}", p.name);
        }
    }

    #[test]
    fn every_entry_round_trips_a_non_default_value() {
        for p in PARAMS {
            let d = p.default_value();
            // Try a few candidate values inside the range; at least one must pass validate()
            // and read back exactly.
            let cands = [
                p.min,
                p.max,
                d + 1.0,
                d - 1.0,
                d * 0.5,
                d * 2.0,
                (p.min + p.max) * 0.5,
            ];
            let mut ok = false;
            for v in cands {
                let v = if p.kind == Kind::Real {
                    v
                } else {
                    (v as i64) as f32
                };
                if v == d || p.check(v).is_err() {
                    continue;
                }
                let mut c = Config::default();
                if p.apply(&mut c, v, false).is_ok() {
                    assert_eq!((p.get)(&c), v, "{}", p.name);
                    ok = true;
                }
            }
            // The law has one kind only for now: no other value exists.
            assert!(ok || p.kind == Kind::Law, "{} never changes", p.name);
        }
    }

    #[test]
    fn bad_values_change_nothing() {
        let p = find("r_load_ohm").unwrap();
        let mut c = Config::default();
        for v in [f32::NAN, -1.0, f32::NEG_INFINITY] {
            assert!(p.apply(&mut c, v, false).is_err());
            assert_eq!(c, Config::default());
        }
        let pw = find("pwm_hz").unwrap();
        assert_eq!(
            pw.apply(&mut c, 10_000.0, true),
            Err(ParamError::NotWhileRunning)
        );
        let bw = find("current_bw_hz").unwrap();
        assert!(matches!(
            bw.apply(&mut c, 4_000.0, false),
            Err(ParamError::Invalid(..))
        ));
        let pp = find("pole_pairs").unwrap();
        assert_eq!(pp.apply(&mut c, 4.5, false), Err(ParamError::NotInteger));
        assert_eq!(c, Config::default());
    }
}
