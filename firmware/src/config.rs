//! Drive configuration in SI units, its validation, and its compilation into the fixed-point
//! constants the current loop uses ([`Gains`]).
//!
//! Compilation uses only IEEE-754 `+ − × ÷` on `f32`, which are correctly rounded on every
//! platform, so the board and the host derive the same bits from the same configuration.

use core::f32::consts::{PI, TAU};

use crate::encoder::EncoderGains;
use crate::fx::{Angle, Gain, Scale32, Q};
use crate::laws::{LawKind, LtiParams};
use crate::numtext::q_of;
use crate::params::{ParamError, PARAMS};
use crate::pi::PiGains;

/// The drive's configuration (SI units). Defaults describe the reference device (Kollmorgen
/// AKM42E on a 16 mm-lead ballscrew, see `docs/physics.md`) on the reference
/// board scalings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Phase resistance, line-to-neutral, Ω.
    pub r_phase_ohm: f32,
    /// Phase inductance, line-to-neutral, H. The datasheet value was lost from our copy; 6 mH
    /// (half of a line-to-line value of about 12 mH, the order of the AKM4x family) is assumed.
    pub l_phase_h: f32,
    /// d-axis inductance, line-to-neutral, H; 0: the same as `l_phase_h` (a non-salient
    /// machine). On a salient machine `l_phase_h` holds L_q (the q loop's, `measure apply`)
    /// and this L_d; the short's peak bound takes the smaller ([`Config::l_d`]).
    pub l_d_h: f32,
    /// Back-emf constant, per-phase peak, V·s/rad (mechanical): `e_q = K_e·ω_m`,
    /// `T = 3/2·K_e·i_q`. Default 0.77·√(3/2) = 0.943: the reading of the paper's "K_e = 0.77"
    /// under which its own formulas (`c_e = 9/4·K²/(l²(R+R_L))`) are physically right in our
    /// convention, and the one its measurements support: the measured TMD power maximum at
    /// 300 Ω (predicted 306 Ω) fixes `c_e·(R+R_L)`; reading 0.77 as torque per peak ampere
    /// (0.513) would put that maximum near 90 Ω. See docs/simulator.md (K_e convention).
    pub ke_v_s_per_rad: f32,
    /// Pole pairs.
    pub pole_pairs: u8,
    /// Screw lead, m/rad (16 mm/rev = 2.546e-3).
    pub lead_m_per_rad: f32,
    /// Encoder counts per revolution (after ×4 decoding).
    pub encoder_cpr: u32,
    /// Electrical angle of the d axis at encoder count 0 within a turn, rad.
    pub encoder_offset_rad: f32,
    /// Phase-current scaling, A per ADC count.
    pub amps_per_count: f32,
    /// ADC code of zero current.
    pub adc_zero_code: u16,
    /// Bus-voltage scaling, V per ADC count.
    pub volts_per_count: f32,
    /// PWM (and current-loop) frequency, Hz.
    pub pwm_hz: f32,
    /// Current-loop bandwidth, Hz (`Kp = L·ωc`, `Ki = R·ωc`).
    pub current_bw_hz: f32,
    /// Bandwidth of the speed-tracking loop, Hz.
    pub speed_bw_hz: f32,
    /// Back-emf feed-forward on the q axis.
    pub ff_emf: bool,
    /// d/q cross-coupling feed-forward (`∓ω_e·L·i`).
    pub ff_decouple: bool,
    /// Advance the output angle by 1.5 periods of rotation (sample-to-PWM delay).
    pub delay_comp: bool,
    /// Fraction of the linear-modulation circle `V_bus/√3` the controller may use.
    pub m_max: f32,
    /// Current-reference limit (magnitude of the dq vector), A.
    /// Default: the AKM42E's rated torque, 2.74 N·m = 3/2·K_e·i_q → 1.94 A, i.e. the device's
    /// force rating f_rat = 1,076 N (the bench drive clipped there, §6 of the reference).
    pub i_max_a: f32,
    /// Instantaneous phase over-current trip, A.
    pub i_trip_a: f32,
    /// Bus over-voltage trip, V.
    pub v_bus_ov: f32,
    /// Bus under-voltage trip while running, V.
    pub v_bus_uv: f32,
    /// Brake chopper closes above this bus voltage, V.
    pub brake_on_v: f32,
    /// Brake chopper opens below this bus voltage, V.
    pub brake_off_v: f32,
    /// Bus voltage where the regenerative current starts to be derated, V
    /// (`brake_on_v ≤ derate_start_v < derate_end_v ≤ v_bus_ov`).
    pub derate_start_v: f32,
    /// Bus voltage where the regenerative current reaches zero, V.
    pub derate_end_v: f32,
    /// Flux braking (docs/protection.md, "Bus management"): largest d-axis current burning
    /// regenerated power in the winding, A (0 = off). Bounded at run time by the current
    /// limit (`|i_dq| ≤ i_max_a`) and the voltage circle.
    pub flux_brake_a: f32,
    /// Regenerated power the bus takes up to `brake_on_v`, W (`inf` = all of it); the
    /// share falls linearly to zero at `derate_start_v`, and flux braking burns the rest.
    pub max_regen_power_w: f32,
    /// Force trip, N: the low-pass filtered electromagnetic force above it trips `over_force`
    /// (`inf` = off, for experiments beyond the rating). Default 1.2× the device rating
    /// f_rat = 1,076 N (the rated torque 2.74 N·m over the lead).
    pub f_trip_n: f32,
    /// Time constant of the force filter, s.
    pub f_filter_s: f32,
    /// Machine continuous current (dq magnitude), A: the I²t estimate settles at
    /// `(|i|/i2t_cont_a)²` and trips at 1. Default 2.0 A: 3 % above the rated-torque current
    /// (the default clip), so a drive held at its clip with ADC noise stays below the trip.
    pub i2t_cont_a: f32,
    /// Thermal time constant of the winding for the I²t estimate, s (assumed; the AKM42E
    /// datasheet value is not in our reference).
    pub i2t_tau_s: f32,
    /// Largest plausible shaft speed, rad/s (default: 6,000 rpm, the AKM4x's maximum).
    pub omega_max_rad_s: f32,
    /// Encoder/emf plausibility: absolute allowance on the emf mismatch, V (plus 50 %).
    pub enc_emf_tol_v: f32,
    /// Stroke end limits of the travel `x` (from the zero position), m.
    pub x_min_m: f32,
    pub x_max_m: f32,
    /// Largest tolerated |i_a + i_b + i_c|, A (sensor consistency).
    pub i_sum_tol_a: f32,
    /// Power-up alignment (docs/protection.md): d-axis current of each step, A.
    pub align_i_a: f32,
    /// Power-up alignment: duration of each of its two steps (ramp over the first half, then
    /// hold and settle check), s.
    pub align_time_s: f32,
    /// Power-up alignment: largest travel from where it started before `align_moving`, m.
    pub align_travel_m: f32,
    /// Boot calibration: largest |zero-current code − adc_zero_code| of a phase, A.
    pub offset_tol_a: f32,
    /// Angle plausibility: largest angle of the loop's back-emf from the q axis, degrees.
    pub angle_tol_deg: f32,
    /// Angle plausibility: judged only above this encoder back-emf K_e·|ω|, V.
    pub angle_emf_min_v: f32,
    /// Overrun bucket size: more than this many current-loop overruns beyond one per
    /// millisecond trip `loop_overrun`.
    pub overrun_max: u16,
    /// Command law.
    pub law: LawKind,
    /// Emulated load resistance per phase, Ω (`f32::INFINITY` = open circuit). The tracking
    /// law starts from it.
    pub r_load_ohm: f32,
    /// Rate of the dynamic laws (impedance, two-way, one-way), Hz: they update every
    /// `round(pwm_hz/law_rate_hz)` loop periods and hold their command in between.
    pub law_rate_hz: f32,
    /// Impedance law: emulated series inductance, H (0 = none).
    pub l_load_h: f32,
    /// Impedance law: emulated series capacitance, F (0 = none, i.e. shorted).
    pub c_load_f: f32,
    /// Tracking law: dither amplitude on `ln R_L` (0.15 = ×e^±0.15).
    pub trk_dither: f32,
    /// Tracking law: dither period (one gradient estimate), s.
    pub trk_period_s: f32,
    /// Tracking law: integrator gain (ln R_L per unit of relative gradient per cycle).
    pub trk_gain: f32,
    /// Tracking law: largest step of `ln R_L` per cycle.
    pub trk_step_max: f32,
    /// Tracking law: lower bound of R_L, Ω.
    pub trk_r_min_ohm: f32,
    /// Tracking law: upper bound of R_L, Ω.
    pub trk_r_max_ohm: f32,
    /// Tracking law: below this mean power, W, R_L is held.
    pub trk_p_min_w: f32,
    /// Two-way / one-way law: host-designed discrete controller at `law_rate_hz` (inputs
    /// `[x m, ω_m rad/s, applied i_q A]`, output `i_q*` A). Default all zero: commands no
    /// current until a design is loaded (`regen study design`).
    pub opt: LtiParams,
    /// Commissioning (`measure`, `docs/commissioning.md`): the d current of the resistance's
    /// upper step (the lower is half of it) and the inductance pulses' swing, A (at most
    /// `i_max_a` is used).
    pub meas_i_a: f32,
    /// Commissioning: each of the resistance's two current steps, s.
    pub meas_r_time_s: f32,
    /// Commissioning: each inductance voltage pulse (8 per axis), s.
    pub meas_l_time_s: f32,
    /// Commissioning: the back-emf window (zero current, the structure's own motion), s.
    pub meas_ke_time_s: f32,
    /// Commissioning: the r.m.s. shaft speed below which K_e is refused (`ke_no_motion`),
    /// rad/s.
    pub meas_speed_min_rad_s: f32,
    /// Commissioning: largest travel while the d current flows (R, L), m.
    pub meas_travel_m: f32,
}

impl Default for Config {
    /// Out of line: called from several places on the board (boot, `defaults`, `list`), each
    /// inlined copy of the ≈ 50 stores costs ≈ 250 bytes of flash.
    #[inline(never)]
    fn default() -> Self {
        Config {
            r_phase_ohm: 2.41,
            l_phase_h: 6.0e-3,
            l_d_h: 0.0,
            ke_v_s_per_rad: 0.943_054,
            pole_pairs: 5,
            lead_m_per_rad: 0.016 / TAU,
            encoder_cpr: 10_000,
            encoder_offset_rad: 0.0,
            amps_per_count: 50.0 / 4096.0,
            adc_zero_code: 2048,
            volts_per_count: 120.0 / 4096.0,
            pwm_hz: 20_000.0,
            current_bw_hz: 1_000.0,
            speed_bw_hz: 100.0,
            ff_emf: true,
            ff_decouple: true,
            delay_comp: true,
            m_max: 0.95,
            i_max_a: 1.937,
            i_trip_a: 20.0,
            v_bus_ov: 95.0,
            v_bus_uv: 20.0,
            brake_on_v: 85.0,
            brake_off_v: 82.0,
            derate_start_v: 88.0,
            derate_end_v: 93.0,
            flux_brake_a: 1.9,
            max_regen_power_w: f32::INFINITY,
            f_trip_n: 1_300.0,
            f_filter_s: 0.01,
            i2t_cont_a: 2.0,
            i2t_tau_s: 300.0,
            omega_max_rad_s: 628.0,
            enc_emf_tol_v: 10.0,
            x_min_m: -0.5,
            x_max_m: 0.5,
            i_sum_tol_a: 0.5,
            overrun_max: 10,
            align_i_a: 1.9,
            align_time_s: 0.4,
            align_travel_m: 0.004,
            offset_tol_a: 0.5,
            angle_tol_deg: 45.0,
            angle_emf_min_v: 5.0,
            law: LawKind::Resistor,
            r_load_ohm: 306.0,
            law_rate_hz: 1_000.0,
            l_load_h: 0.0,
            c_load_f: 0.0,
            trk_dither: 0.15,
            trk_period_s: 16.0,
            trk_gain: 1.0,
            trk_step_max: 0.3,
            trk_r_min_ohm: 1.0,
            meas_i_a: 1.9,
            meas_r_time_s: 0.025,
            meas_l_time_s: 1.0e-3,
            meas_ke_time_s: 2.0,
            meas_speed_min_rad_s: 2.0,
            meas_travel_m: 0.2,
            trk_r_max_ohm: 10_000.0,
            trk_p_min_w: 0.5,
            opt: LtiParams::default(),
        }
    }
}

/// Why a configuration was refused: the field and what is wrong with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigError {
    pub field: &'static str,
    pub reason: &'static str,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: {}", self.field, self.reason)
    }
}

fn check(ok: bool, field: &'static str, reason: &'static str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError { field, reason })
    }
}

impl Config {
    /// The d-axis inductance, H: `l_d_h`, or `l_phase_h` where that is 0 (non-salient).
    pub fn l_d(&self) -> f32 {
        if self.l_d_h > 0.0 {
            self.l_d_h
        } else {
            self.l_phase_h
        }
    }

    /// Check every field and the relations between them.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // Each field against its range in the parameter registry (`params::PARAMS`, the one
        // place ranges are written; one loop instead of a check per field keeps the board
        // image small), then the relations between fields.
        for p in PARAMS {
            let reason = match (p.name, p.check(p.get(self))) {
                (_, Ok(())) => continue,
                ("r_load_ohm", _) => "must be ≥ 0 (inf = open)",
                ("f_trip_n", _) => "must be ≥ 1 N (inf = off)",
                // Both current signs need codes: at least 512 on either side of zero.
                ("adc_zero_code", _) => "out of range (512 .. 3583)",
                (_, Err(ParamError::NotFinite)) => "not a finite number",
                _ => "out of range",
            };
            return Err(ConfigError {
                field: p.name,
                reason,
            });
        }
        // A discrete PI with one period of delay loses its margin as ωc·Ts approaches 1.
        check(
            self.current_bw_hz * TAU / self.pwm_hz <= 0.6,
            "current_bw_hz",
            "too high for pwm_hz (ωc·Ts > 0.6)",
        )?;
        check(
            self.speed_bw_hz * TAU / self.pwm_hz <= 0.3,
            "speed_bw_hz",
            "too high for pwm_hz",
        )?;
        check(
            self.i_trip_a > self.i_max_a,
            "i_trip_a",
            "must exceed i_max_a",
        )?;
        check(
            self.align_i_a < self.i_trip_a,
            "align_i_a",
            "must be below i_trip_a",
        )?;
        check(
            self.v_bus_uv < self.v_bus_ov,
            "v_bus_uv",
            "must be below v_bus_ov",
        )?;
        check(
            self.brake_off_v < self.brake_on_v,
            "brake_off_v",
            "must be below brake_on_v",
        )?;
        check(
            self.brake_on_v < self.v_bus_ov,
            "brake_on_v",
            "must be below v_bus_ov",
        )?;
        // A trip the ADC cannot see is no protection.
        check(
            self.v_bus_ov < self.volts_per_count * 4095.0,
            "v_bus_ov",
            "above the bus ADC's full scale (volts_per_count·4095)",
        )?;
        check(
            self.brake_off_v > self.v_bus_uv,
            "brake_off_v",
            "must exceed v_bus_uv (the chopper would drain the bus into an under-voltage trip)",
        )?;
        check(
            self.derate_start_v >= self.brake_on_v,
            "derate_start_v",
            "must not be below brake_on_v (brake first, then derate)",
        )?;
        check(
            self.derate_end_v > self.derate_start_v,
            "derate_end_v",
            "must exceed derate_start_v",
        )?;
        check(
            self.derate_end_v <= self.v_bus_ov,
            "derate_end_v",
            "must not exceed v_bus_ov",
        )?;
        check(
            self.x_min_m < self.x_max_m,
            "x_min_m",
            "must be below x_max_m",
        )?;
        // Three readings each rounded by half an LSB, plus a count of noise each.
        check(
            self.i_sum_tol_a >= 4.0 * self.amps_per_count,
            "i_sum_tol_a",
            "below 4 ADC counts (quantisation alone would trip it)",
        )?;
        check(
            self.law_rate_hz <= self.pwm_hz,
            "law_rate_hz",
            "must not exceed pwm_hz",
        )?;
        check(
            self.law != LawKind::Impedance || self.r_load_ohm.is_finite(),
            "r_load_ohm",
            "must be finite for the impedance law",
        )?;
        check(
            self.trk_period_s * self.pwm_hz >= 8.0,
            "trk_period_s",
            "shorter than 8 loop periods",
        )?;
        check(
            self.trk_r_min_ohm < self.trk_r_max_ohm,
            "trk_r_min_ohm",
            "must be below trk_r_max_ohm",
        )?;
        check(
            self.opt.is_valid(),
            "opt",
            "coefficient not finite or beyond ±8e6",
        )?;
        // Full-scale of the ADC must be representable in Q16.16 amperes and volts.
        check(
            self.amps_per_count * 4096.0 < 30_000.0,
            "amps_per_count",
            "full scale too large",
        )?;
        check(
            self.volts_per_count * 4096.0 < 30_000.0,
            "volts_per_count",
            "full scale too large",
        )?;
        Ok(())
    }

    /// `self != other` for configurations without NaN (every validated one): through the
    /// parameter registry's readers (every field but `opt` has an entry, see the tests) and
    /// `opt`. One small loop instead of the derived comparison of 48 fields, which costs
    /// ≈ 0.8 KB of flash wherever it is inlined. (Integer fields compare as `f32`: exact
    /// within their validated ranges.)
    #[inline(never)]
    pub fn differs(&self, other: &Config) -> bool {
        self.opt != other.opt || PARAMS.iter().any(|p| p.get(self) != p.get(other))
    }

    /// Sampling period, s.
    pub fn ts(&self) -> f32 {
        1.0 / self.pwm_hz
    }
}

/// The fixed-point constants of the current loop, compiled from a valid [`Config`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Gains {
    pub amps_per_count: Gain,
    pub adc_zero: i32,
    pub volts_per_count: Gain,
    pub pi: PiGains,
    pub enc: EncoderGains,
    /// K_e, V·s/rad.
    pub ke: Gain,
    /// L, H (for decoupling).
    pub l: Gain,
    pub pole_pairs: i32,
    /// Output-angle advance per rad/s of electrical speed (1.5 Ts), in angle LSB·2^-16.
    pub advance: Gain,
    /// `m_max/√3`: the voltage limit per volt of bus.
    pub v_lim_per_bus: Gain,
    pub i_max: Q,
    pub i_trip: Q,
    pub v_ov: Q,
    pub v_uv: Q,
    pub brake_on: Q,
    pub brake_off: Q,
    pub ff_emf: bool,
    pub ff_decouple: bool,
    /// The diode onset as a speed (`protect::onset_bits`): a latch is above it when the
    /// speed estimate's Q16.16 bits have at least this magnitude.
    pub onset_w: u32,
    /// Constants of the step in the forms its fast paths use.
    pub k: StepConsts,
}

/// The current loop's constants folded for the step: raw-code scalings and thresholds, and
/// products of gains with the speed estimate, so each costs one multiply per period.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StepConsts {
    /// α (Q16.16 LSB) per unit of `2a − b − c` (ADC codes, |.| ≤ 8192; the zero code
    /// cancels): `amps_per_count/3·2^16`.
    pub alpha_per_code: Scale32,
    /// β per unit of `b − c` (codes, |.| ≤ 4096): `amps_per_count/√3·2^16`.
    pub beta_per_code: Scale32,
    /// Bus voltage (LSB) per bus code (≤ 4095): `volts_per_count·2^16`.
    pub volts_per_code: Scale32,
    /// Radius of the allowed voltage circle (LSB) per bus code: `m_max/√3·volts_per_count·2^16`.
    pub v_max_per_code: Scale32,
    /// Over-current window on the phase codes: trip when `code − i_lo` (wrapping `u32`)
    /// exceeds `i_span`, i.e. `|code − zero| > ⌊i_trip/amps_per_count⌋`.
    pub i_lo: u32,
    pub i_span: u32,
    /// Sum of the three phases' zero-current codes (`3·adc_zero_code`): the reconstruction
    /// of the unread phase (`shunt::two_valid`).
    pub zero3: i32,
    /// Bus thresholds in codes: over-voltage when `code > ov`, under-voltage when
    /// `code < uv`; the brake chopper's, indexed by its state: it closes when
    /// `code > brake[0]` (on), stays closed while `code > brake[1]` (off).
    pub ov: u32,
    pub uv: u32,
    pub brake: [u32; 2],
    /// Back-emf per speed estimate: `K_e·2π·f_pwm/cpr`, V per (count per step).
    pub ke_per_vel: Gain,
    /// `ω_e·L` per speed estimate: `L·p·2π·f_pwm/cpr`, Ω per (count per step).
    pub wl_per_vel: Gain,
    /// Output-angle advance per speed-estimate LSB, `1.5·(electrical angle per count)/2^4`:
    /// advance (angle LSB) = `(vel_bits · adv_per_vel) >> 12` (0 without delay compensation).
    pub adv_per_vel: i32,
}

/// Largest code of a 12-bit converter.
pub const CODE_MAX: u32 = 4095;

fn scale32(v: f32, x_max: u32, field: &'static str) -> Result<Scale32, ConfigError> {
    Scale32::new(v, x_max).ok_or(ConfigError {
        field,
        reason: "scaling not representable",
    })
}

/// `⌊v⌋` of a non-negative threshold ratio as a code bound, saturated to `u32`.
fn floor_code(v: f32) -> u32 {
    // `as` truncates toward zero and saturates (NaN → 0); v ≥ 0 here.
    v as u32
}

/// `⌈v⌉` of a non-negative ratio.
fn ceil_code(v: f32) -> u32 {
    let f = v as u32;
    if (f as f32) < v {
        f.saturating_add(1)
    } else {
        f
    }
}

impl Gains {
    /// Validate and compile.
    pub fn new(c: &Config) -> Result<Gains, ConfigError> {
        c.validate()?;
        let ts = c.ts();
        let wc = TAU * c.current_bw_hz;
        let wb = TAU * c.speed_bw_hz * ts;
        let turn_per_count = (4_294_967_296u64 / c.encoder_cpr as u64) as u32;
        let rad_s_per_count_step = TAU * c.pwm_hz / c.encoder_cpr as f32;
        // 1.5 periods of electrical angle per (count per step): 1.5·tpc·p ≤ 1.5·2^28·50 <
        // 2^35, divided by 2^4 → < 2^31 (cpr ≥ 16, p ≤ 50).
        let adv_per_vel = if c.delay_comp {
            ((3 * turn_per_count as u64 * c.pole_pairs as u64) >> 5).min(i32::MAX as u64) as i32
        } else {
            0
        };
        let n_trip = floor_code(c.i_trip_a / c.amps_per_count).min(70_000);
        let zero = c.adc_zero_code as u32;
        let k = StepConsts {
            // amps_per_count ≤ 1 and volts_per_count ≤ 1 (validated) keep every value below
            // 2^16·1 and the inputs within the stated counts, so `new` always succeeds.
            alpha_per_code: scale32(c.amps_per_count / 3.0 * 65_536.0, 8192, "amps_per_count")?,
            beta_per_code: scale32(
                c.amps_per_count * INV_SQRT3 * 65_536.0,
                4096,
                "amps_per_count",
            )?,
            volts_per_code: scale32(c.volts_per_count * 65_536.0, CODE_MAX, "volts_per_count")?,
            v_max_per_code: scale32(
                c.m_max * INV_SQRT3 * c.volts_per_count * 65_536.0,
                CODE_MAX,
                "m_max",
            )?,
            i_lo: zero.wrapping_sub(n_trip),
            i_span: 2 * n_trip,
            zero3: 3 * zero as i32,
            ov: floor_code(c.v_bus_ov / c.volts_per_count),
            uv: ceil_code(c.v_bus_uv / c.volts_per_count),
            brake: [
                floor_code(c.brake_on_v / c.volts_per_count),
                floor_code(c.brake_off_v / c.volts_per_count),
            ],
            ke_per_vel: Gain::from_f32(c.ke_v_s_per_rad * rad_s_per_count_step),
            wl_per_vel: Gain::from_f32(c.l_phase_h * c.pole_pairs as f32 * rad_s_per_count_step),
            adv_per_vel,
        };
        let advance = if c.delay_comp {
            // Δθ (LSB) = ω_e·1.5·Ts·2^32/2π; applied to ω_e in Q16.16 → divide by 2^16.
            1.5 * ts * 65_536.0 / (2.0 * PI)
        } else {
            0.0
        };
        Ok(Gains {
            amps_per_count: Gain::from_f32(c.amps_per_count),
            adc_zero: c.adc_zero_code as i32,
            volts_per_count: Gain::from_f32(c.volts_per_count),
            pi: PiGains::new(c.l_phase_h * wc, c.r_phase_ohm * wc * ts),
            enc: EncoderGains {
                cpr: c.encoder_cpr,
                turn_per_count,
                pole_pairs: c.pole_pairs as u32,
                e_per_count: turn_per_count.wrapping_mul(c.pole_pairs as u32),
                offset: angle_of_radians(c.encoder_offset_rad),
                kp31: crate::fx::fixed_i32(2.0 * wb, 31),
                ki34: crate::fx::fixed_i32(wb * wb, 34),
                rad_s_per_count_step: Gain::from_f32(rad_s_per_count_step),
                m_per_count: Gain::from_f32(c.lead_m_per_rad * TAU / c.encoder_cpr as f32),
                // Four times the count change at 20,000 rpm would still be implausible.
                max_step_counts: ((20_000.0 / 60.0 * c.encoder_cpr as f32 / c.pwm_hz) as i32 + 1)
                    .min(16_000),
            },
            ke: Gain::from_f32(c.ke_v_s_per_rad),
            l: Gain::from_f32(c.l_phase_h),
            pole_pairs: c.pole_pairs as i32,
            advance: Gain::from_f32(advance),
            v_lim_per_bus: Gain::from_f32(c.m_max * INV_SQRT3),
            i_max: q_of(c.i_max_a),
            // A trip above the ADC's range could never fire: clamp it to the last code below
            // the nearer rail, so that an over-range reading trips.
            i_trip: q_of(c.i_trip_a.min(
                c.amps_per_count * (c.adc_zero_code.min(4095 - c.adc_zero_code) as f32 - 1.0),
            )),
            v_ov: q_of(c.v_bus_ov),
            v_uv: q_of(c.v_bus_uv),
            brake_on: q_of(c.brake_on_v),
            brake_off: q_of(c.brake_off_v),
            ff_emf: c.ff_emf,
            ff_decouple: c.ff_decouple,
            onset_w: crate::protect::onset_bits(c),
            k,
        })
    }
}

/// 1/√3, correctly rounded to `f32` (`f32::sqrt` is not in `core`).
pub(crate) const INV_SQRT3: f32 = 0.577_350_26;

/// The angle of `r` radians (|r| ≤ 2π, validated), in integers: `r·2^32` is exact in `f32`
/// (power-of-two scaling) and fits an `i64`; times 2^64/2π (rounded) and shifted back gives
/// `r/2π` turns in 2^-32 units, wrapped mod one turn. The same angle as
/// `Angle::from_radians(r as f64)` to within 1 LSB (2^-32 turn), without soft-float `f64`.
fn angle_of_radians(r: f32) -> Angle {
    const TURNS_PER_RAD_Q64: i128 = 2_935_890_503_282_001_226; // 2^64/2π
    let r_q32 = (r * 4_294_967_296.0) as i64;
    Angle(((r_q32 as i128 * TURNS_PER_RAD_Q64) >> 64) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoder_offset_angle_matches_the_f64_conversion() {
        // Every 1/1000 of the validated range ±2π (and its ends): within 1 LSB (2^-32 turn,
        // 1.5 nrad) of the f64 conversion, which rounds r/2π once more before truncating.
        for k in -1000..=1000 {
            let r = k as f32 * core::f32::consts::TAU / 1000.0;
            let a = angle_of_radians(r).0;
            let b = Angle::from_radians(r as f64).0;
            assert!(a.wrapping_sub(b).wrapping_add(1) <= 2, "{r}: {a} vs {b}");
        }
    }

    #[test]
    fn defaults_are_valid() {
        Gains::new(&Config::default()).unwrap();
    }

    #[test]
    fn every_registry_range_is_enforced_by_validate() {
        use crate::params::Kind;
        // Just outside each end of each entry's range (NaN for the real ones too): refused,
        // naming that field; the range ends themselves are not refused for being out of range.
        for p in PARAMS.iter().filter(|p| p.kind == Kind::Real) {
            for v in [
                p.min - 1.0 - p.min.abs(),
                p.max + 1.0 + p.max.abs(),
                f32::NAN,
            ] {
                if v.is_infinite() {
                    continue; // an infinite maximum admits everything above the minimum
                }
                let mut c = Config::default();
                p.set(&mut c, v);
                let e = c.validate().unwrap_err();
                assert_eq!(e.field, p.name, "{} = {v}: {e:?}", p.name);
            }
        }
        for p in PARAMS.iter().filter(|p| p.kind == Kind::Int) {
            let mut c = Config::default();
            p.set(&mut c, p.max + 1.0);
            assert_eq!(c.validate().unwrap_err().field, p.name);
        }
    }

    /// The top-level field names of `Config`, from its `Debug` text.
    fn field_names() -> std::vec::Vec<std::string::String> {
        let text = std::format!("{:?}", Config::default());
        let (mut depth, mut word, mut names) = (0, std::string::String::new(), std::vec![]);
        for ch in text.chars() {
            match ch {
                '{' | '[' | '(' => depth += 1,
                '}' | ']' | ')' => depth -= 1,
                ':' if depth == 1 => names.push(word.clone()),
                _ => {}
            }
            if ch.is_alphanumeric() || ch == '_' {
                word.push(ch);
            } else if ch != ':' {
                word.clear();
            }
        }
        names
    }

    #[test]
    fn differs_covers_every_field() {
        let names = field_names();
        assert_eq!(names.len(), 63, "{names:?}");
        for n in &names {
            assert!(
                n == "opt" || PARAMS.iter().any(|p| p.name == n.as_str()),
                "field {n} has no registry entry: Config::differs would miss it"
            );
        }
        let d = Config::default();
        assert!(!d.differs(&d));
        // Each entry changed to another valid value, and `opt`: a difference, as `!=` says.
        for p in PARAMS {
            for v in [p.min, p.max, p.get(&d) + 1.0] {
                let mut c = d;
                if p.apply(&mut c, v, false).is_ok() && c != d {
                    assert!(c.differs(&d) && d.differs(&c), "{}", p.name);
                }
            }
        }
        let mut c = d;
        c.opt.c[3] = 1.0;
        assert!(c.differs(&d));
    }

    #[test]
    fn bad_values_are_refused_by_name() {
        let mut c = Config {
            r_phase_ohm: f32::NAN,
            ..Config::default()
        };
        assert_eq!(Gains::new(&c).unwrap_err().field, "r_phase_ohm");
        c = Config {
            current_bw_hz: 4_000.0,
            ..Config::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "current_bw_hz");
        c = Config {
            r_load_ohm: -1.0,
            ..Config::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "r_load_ohm");
        c = Config {
            brake_on_v: 200.0,
            ..Config::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "brake_on_v");
        c = Config {
            r_load_ohm: f32::INFINITY,
            ..Config::default()
        };
        assert!(c.validate().is_ok());
    }

    #[test]
    fn pi_gains_follow_bandwidth_design() {
        let c = Config::default();
        let g = Gains::new(&c).unwrap();
        let wc = TAU * c.current_bw_hz;
        assert!((g.pi.kp() - c.l_phase_h * wc).abs() < 1e-6 * c.l_phase_h * wc);
        assert!((g.pi.ki_ts() - c.r_phase_ohm * wc / c.pwm_hz).abs() < 1e-6);
    }
}
