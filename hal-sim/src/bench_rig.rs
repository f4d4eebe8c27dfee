//! Imposed-motion bench rig: an independent generator of measured records for the diagnosis.
//!
//! It shares no code with `diagnose` (its own random source, trajectories, device physics and
//! CSV writer): an actuator imposes a motion on the device's rod and a load cell measures the
//! force. The device is simulated as physics at `SUB` substeps per sample (`substeps_for` at
//! other sample rates):
//! inertia, a damping drive (the motor emulating a damper through its current loop),
//! LuGre friction (presliding, its displacement below what the record shows, and standstill included), a force offset, and at most one hidden
//! effect: a clipped current loop, a delay of the force channel, a load-path resonance (a mass on
//! a spring-damper), a Stribeck bump (static above Coulomb), a soft presliding regime, play in
//! the screw (the device's mass and drive sit behind a gap), or an effect outside the
//! diagnosis's catalogue (a force disturbance at a frequency unrelated to the motion, or a
//! thermal drift of the force offset); the widened rig adds the kinds below.
//!
//! **Observability rule**: a hidden effect is kept only when the force it changes, simulated
//! with and without it on the same motion, holds on the samples in motion (`rest_of`: the
//! rig's own rest set, from its true motion and its encoder's quantum) an rms of at least 5×
//! the force-sensor noise and at least 3 % of the rms the force without it holds there
//! (`rms_in_motion`: the energy on the samples in motion per sample of the record); otherwise
//! its parameters are redrawn (at most 40 draws). Samples at rest are excluded because no
//! diagnosis may use them: friction at rest is static, anywhere within its breakaway level,
//! and carries no Coulomb sign (the velocity is within its noise), so a force there is no
//! evidence of any effect; this holds for every kind (the diagnosis leaves them out of every
//! fit and of its residual analysis too, the spectral peaks and the slow change a hum or a
//! drift is reported by). When all 40 fail, the trajectory's own parameters are redrawn
//! within its family (a new draw of the motion's random stream: another period and sharpness
//! of a rounded triangle, other sines, moves or excitation) and the effect's 40 draws are made
//! on that motion, at most 8 motions in all. When its family cannot show the effect on any of
//! them (a Stribeck band crossed only at the reversals of a triangle that cruises at one
//! speed; a recorded trajectory has no parameters to redraw), the record is drawn in the next
//! parametric family (multisine → rounded triangle → point-to-point → narrowband → multisine),
//! 8 motions each, and says so (`requested` keeps the family it was asked for). When no family
//! shows it, the record keeps its own family's last motion and draw and the draw's size is
//! raised to the least the rule accepts (`size_to_rule`: a hum's amplitude or a drift's total
//! at most `SIZE_MAX_SCALE` times the draw, a clip's level down to `CLIP_MIN_FRACTION` of the
//! drive's peak force); only when that maximum does not reach the rule is the record flagged
//! `observable = false`. A record observable on its first motion is unchanged by the redraws.
//!
//! **Two generators.** `RigSpec::random` is the classic rig: 1 kHz, a length given by the
//! caller, the nine kinds of `Hidden::KINDS`. `RigSpec::widened` draws the conditions too: the
//! sample rate (500 Hz … 10 kHz; the physics at a substep rate of at least 20 kHz,
//! `substeps_for`), the length (6–20 s), the force noise (0.05–5 N), the encoder (0.1–25.6 µm),
//! the lead, wider devices, a chirp family beside the classic four and the recorded one, and
//! the kinds of `Hidden::WIDE_KINDS`: beside the classic ones a load path whose compliance the
//! force is measured in front of (the device behind the spring), play without impact (a light
//! side behind the gap), a spring, a spring beside presliding, and a drag growing with the
//! square of the speed (outside the catalogue). Its observability rule adds a clause: the part
//! of the effect's force no refitted baseline (inertia, viscous, Coulomb, offset, on the true
//! motion) explains holds at least `REFIT_NOISE_RATIO` times the noise (`unexplained_rms`).

use std::f64::consts::TAU;
use std::fmt::Write as _;

/// Substeps per output sample of the physics integration at the classic rig's 1 kHz; other
/// sample rates take `substeps_for` (a substep rate of at least 20 kHz).
pub const SUB: usize = 20;

/// Substeps per sample at sample rate `fs`: at least 2, and a substep rate of at least 20 kHz
/// (the play's contact modes, up to about 420 Hz, are integrated at ω·h ≤ 0.13).
pub fn substeps_for(fs: f64) -> usize {
    ((20_000.0 / fs).ceil() as usize).max(2)
}

/// xorshift64* random source (independent of the diagnosis's generator).
pub struct RigRng(u64);
impl RigRng {
    pub fn new(seed: u64) -> Self {
        RigRng(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) | 1)
    }
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [a, b).
    pub fn uni(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * ((self.next() >> 11) as f64 * (1.0 / (1u64 << 53) as f64))
    }
    /// Standard normal (polar method).
    pub fn gauss(&mut self) -> f64 {
        loop {
            let u = self.uni(-1.0, 1.0);
            let v = self.uni(-1.0, 1.0);
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                return u * (-2.0 * s.ln() / s).sqrt();
            }
        }
    }
    pub fn pick(&mut self, n: usize) -> usize {
        ((self.next() >> 33) as usize) % n.max(1)
    }
}

/// Trajectory families of the imposed motion.
#[derive(Debug, Clone, PartialEq)]
pub enum Trajectory {
    /// Sum of 5 sines, 0.1–2 Hz, random phases.
    Multisine,
    /// Triangle in position with rounded reversals (velocity tanh-shaped square wave).
    RoundedTriangle,
    /// Minimum-jerk moves between random positions with dwells at rest.
    PointToPoint,
    /// Response of a lightly damped structural mode (0.6–2 Hz) to white noise.
    Narrowband,
    /// A recorded position (metres, at the record's sample rate), e.g. EMPS's trajectory.
    Recorded(Vec<f64>),
    /// A sine swept linearly in frequency from 0.1–0.3 Hz to 1.5–4 Hz over the record.
    Chirp,
}

impl Trajectory {
    pub fn name(&self) -> &'static str {
        match self {
            Trajectory::Multisine => "multisine",
            Trajectory::RoundedTriangle => "rounded_triangle",
            Trajectory::PointToPoint => "point_to_point",
            Trajectory::Narrowband => "narrowband",
            Trajectory::Recorded(_) => "recorded",
            Trajectory::Chirp => "chirp",
        }
    }
}

/// The hidden effect of a record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hidden {
    None,
    /// The drive's force saturates at ±limit_n (its current loop clips).
    ClippedCurrentLoop {
        limit_n: f64,
    },
    /// The force channel lags the position channel by delay_s (acquisition skew).
    Delay {
        delay_s: f64,
    },
    /// A mass on a spring-damper in the load path.
    Resonance {
        mass_kg: f64,
        freq_hz: f64,
        zeta: f64,
    },
    /// Static friction above Coulomb, decaying with speed (LuGre's Stribeck curve).
    Stribeck {
        static_n: f64,
        vs_m_s: f64,
    },
    /// Soft presliding: the LuGre bristle stiffness gives a characteristic displacement.
    Presliding {
        x_char_m: f64,
    },
    /// Play in the screw of total width.
    Backlash {
        width_m: f64,
    },
    /// Out of catalogue: a force disturbance at a frequency unrelated to the motion.
    Hum {
        freq_hz: f64,
        amp_n: f64,
    },
    /// Out of catalogue: the force offset drifts linearly over the record.
    Drift {
        total_n: f64,
    },
    /// A compliant load path with the force measured on the actuator's side of it: the load
    /// cell carries a spring-damper, the whole device (mass, drive, friction) sits behind it.
    ResonanceBehind {
        freq_hz: f64,
        zeta: f64,
    },
    /// Play without impact: only `PLAY_LIGHT_SIDE` of the device's mass, with its drive and
    /// friction, sits behind the gap (the rest moves with the load cell), and the contact is
    /// critically damped: taking up the play exchanges almost no momentum.
    PlayNoImpact {
        width_m: f64,
    },
    /// A position-proportional force (a mount, a centring spring), k·x about the stroke's
    /// middle.
    Spring {
        k_n_per_m: f64,
    },
    /// A spring beside soft presliding (the stiffness a friction hysteresis shows at small
    /// displacement, as in a passive friction damper on a mount).
    SpringPresliding {
        k_n_per_m: f64,
        x_char_m: f64,
    },
    /// Out of catalogue: a force growing with the square of the speed, c₂·v·|v|.
    QuadraticDrag {
        c2_n_s2_per_m2: f64,
    },
}

/// Share of the device's mass behind the gap of `Hidden::PlayNoImpact`.
pub const PLAY_LIGHT_SIDE: f64 = 0.02;

impl Hidden {
    /// The diagnosis's name for this effect (`unexplained` for effects outside the catalogue,
    /// None for no effect).
    pub fn expected(&self) -> Option<&'static str> {
        Some(match self {
            Hidden::None => return None,
            Hidden::ClippedCurrentLoop { .. } => "current_limit",
            Hidden::Delay { .. } => "lag",
            Hidden::Resonance { .. } => "compliance",
            Hidden::Stribeck { .. } => "stribeck",
            Hidden::Presliding { .. } => "presliding_hysteresis",
            Hidden::Backlash { .. } => "backlash",
            Hidden::Hum { .. } | Hidden::Drift { .. } | Hidden::QuadraticDrag { .. } => {
                "unexplained"
            }
            Hidden::ResonanceBehind { .. } => "compliance",
            Hidden::PlayNoImpact { .. } => "backlash",
            Hidden::Spring { .. } | Hidden::SpringPresliding { .. } => "spring",
        })
    }
    /// Every name the diagnosis should give this effect, sorted (empty for no effect,
    /// `unexplained` alone for effects outside the catalogue).
    pub fn expected_names(&self) -> &'static [&'static str] {
        match self {
            Hidden::SpringPresliding { .. } => &["presliding_hysteresis", "spring"],
            Hidden::None => &[],
            h => match h.expected() {
                Some("current_limit") => &["current_limit"],
                Some("lag") => &["lag"],
                Some("compliance") => &["compliance"],
                Some("stribeck") => &["stribeck"],
                Some("presliding_hysteresis") => &["presliding_hysteresis"],
                Some("backlash") => &["backlash"],
                Some("spring") => &["spring"],
                _ => &["unexplained"],
            },
        }
    }
    /// Whether the effect lies outside the diagnosis's catalogue (its right answer is
    /// `unexplained`).
    pub fn out_of_catalogue(&self) -> bool {
        self.expected() == Some("unexplained")
    }
    pub fn kind(&self) -> &'static str {
        match self {
            Hidden::None => "none",
            Hidden::ClippedCurrentLoop { .. } => "clipped_current_loop",
            Hidden::Delay { .. } => "delay",
            Hidden::Resonance { .. } => "resonance",
            Hidden::Stribeck { .. } => "stribeck",
            Hidden::Presliding { .. } => "presliding",
            Hidden::Backlash { .. } => "backlash",
            Hidden::Hum { .. } => "hum",
            Hidden::Drift { .. } => "drift",
            Hidden::ResonanceBehind { .. } => "resonance_behind",
            Hidden::PlayNoImpact { .. } => "play_no_impact",
            Hidden::Spring { .. } => "spring",
            Hidden::SpringPresliding { .. } => "spring_presliding",
            Hidden::QuadraticDrag { .. } => "quadratic_drag",
        }
    }
    /// The classic rig's kinds (`RigSpec::random`), in the order its long run cycles through
    /// them.
    pub const KINDS: [&'static str; 9] = [
        "none",
        "clipped_current_loop",
        "delay",
        "resonance",
        "stribeck",
        "presliding",
        "backlash",
        "hum",
        "drift",
    ];
    /// Every kind of the widened rig (`RigSpec::widened`): the classic ones, then the
    /// topologies and effects the classic rig lacks.
    pub const WIDE_KINDS: [&'static str; 14] = [
        "none",
        "clipped_current_loop",
        "delay",
        "resonance",
        "stribeck",
        "presliding",
        "backlash",
        "hum",
        "drift",
        "resonance_behind",
        "play_no_impact",
        "spring",
        "spring_presliding",
        "quadratic_drag",
    ];
}

/// Device, sensors and test of one bench record.
#[derive(Debug, Clone)]
pub struct RigSpec {
    pub seed: u64,
    pub fs: f64,
    pub samples: usize,
    pub trajectory: Trajectory,
    /// Peak displacement, m.
    pub amplitude_m: f64,
    pub mass_kg: f64,
    /// Damping the drive emulates, N·s/m.
    pub drive_damping: f64,
    /// Viscous friction, N·s/m.
    pub viscous: f64,
    /// Coulomb friction, N.
    pub coulomb: f64,
    pub offset_n: f64,
    pub noise_n: f64,
    pub quantum_m: f64,
    pub lead_m: f64,
    pub hidden: Hidden,
    /// The observability rule held for the hidden effect.
    pub observable: bool,
    /// rms the force the hidden effect changes holds on the samples in motion (`rest_of`,
    /// `rms_in_motion`), N.
    pub effect_rms_n: f64,
    /// Presliding displacement of the device's own (LuGre) friction, m: 2 µm, halved until the
    /// force it changes against a rigid Coulomb switch on this motion is invisible to a
    /// matched filter (a record with nothing hidden must not carry a detectable catalogue
    /// effect; see `with_base_friction`).
    pub base_x_char_m: f64,
    /// Draw of the trajectory's own parameters (0: the first; see the observability rule).
    pub motion_draw: u64,
    /// The trajectory family the record was asked for (`trajectory` is another one when that
    /// family could not show the hidden effect; see the observability rule).
    pub requested: &'static str,
    /// Substeps per sample of the physics (`substeps_for(fs)`).
    pub sub: usize,
    /// Samples of the rest window (`rest_of`): 20 ms.
    pub rest_window: usize,
    /// The widened rig's second observability clause: what a refitted baseline cannot explain
    /// (`unexplained_rms`) holds at least `REFIT_NOISE_RATIO` times the noise.
    pub refit_rule: bool,
    /// rms of the part of the effect's force no refitted baseline explains (`unexplained_rms`),
    /// N.
    pub effect_unexplained_n: f64,
}

/// Least ratio of the unexplained part of an effect (`unexplained_rms`) to the force noise in
/// the widened rig.
pub const REFIT_NOISE_RATIO: f64 = 4.0;

/// Imposed motion at the substep rate: (x, v, a), drawn from the record's motion stream.
fn motion_of(s: &RigSpec) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    // draw 0 is the stream every record had before redraws existed; draw k > 0 another one
    let seed = s
        .seed
        .wrapping_add(7)
        .wrapping_add(s.motion_draw.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    motion(s, &mut RigRng::new(seed))
}

/// Imposed motion at the substep rate: (x, v, a).
fn motion(s: &RigSpec, rng: &mut RigRng) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let sub = s.sub;
    let n = s.samples * sub;
    let h = 1.0 / (s.fs * sub as f64);
    let mut x = vec![0.0; n];
    match &s.trajectory {
        Trajectory::Multisine => {
            let comps: Vec<(f64, f64, f64)> = (0..5)
                .map(|_| (rng.uni(0.1, 2.0), rng.uni(0.0, TAU), rng.uni(0.3, 1.0)))
                .collect();
            for (i, xi) in x.iter_mut().enumerate() {
                let t = i as f64 * h;
                *xi = comps
                    .iter()
                    .map(|c| c.2 * (TAU * c.0 * t + c.1).sin())
                    .sum();
            }
        }
        Trajectory::RoundedTriangle => {
            let period = rng.uni(1.5, 4.0);
            let sharp = rng.uni(3.0, 10.0);
            let mut p = 0.0;
            for (i, xi) in x.iter_mut().enumerate() {
                let t = i as f64 * h;
                p += (sharp * (TAU * t / period).sin()).tanh() * h;
                *xi = p;
            }
        }
        Trajectory::PointToPoint => {
            let mut i = 0;
            let mut at = 0.0;
            while i < n {
                let dwell = (rng.uni(0.3, 1.0) / h) as usize;
                for xi in x.iter_mut().skip(i).take(dwell) {
                    *xi = at;
                }
                i += dwell;
                let to = rng.uni(-1.0, 1.0);
                let len = (rng.uni(0.4, 1.2) / h) as usize;
                for k in 0..len.min(n.saturating_sub(i)) {
                    let u = k as f64 / len as f64;
                    x[i + k] =
                        at + (to - at) * (10.0 * u.powi(3) - 15.0 * u.powi(4) + 6.0 * u.powi(5));
                }
                i += len;
                at = to;
            }
        }
        Trajectory::Narrowband => {
            let f0 = rng.uni(0.6, 2.0);
            let z = rng.uni(0.02, 0.06);
            let w = TAU * f0;
            let (mut y, mut yd) = (0.0, 0.0);
            // white force into the mode, band-limited to the structure's excitation band (a
            // critically damped 2nd-order low-pass at 5·f0: wind and traffic loads are
            // band-limited; unfiltered, the mode's acceleration would carry the white force up
            // to the substep rate, a band set by the integration step, not by the motion),
            // integrated semi-implicitly; a 1 s run-in is discarded
            let wb = TAU * 5.0 * f0;
            let (mut u1, mut u1d) = (0.0, 0.0);
            let pre = (1.0 / h) as usize;
            let sd = (1.0 / h).sqrt();
            for i in 0..n + pre {
                let e = rng.gauss() * sd;
                u1d += (wb * wb * (e - u1) - 2.0 * wb * u1d) * h;
                u1 += u1d * h;
                let u = u1;
                yd += (u - 2.0 * z * w * yd - w * w * y) * h;
                y += yd * h;
                if i >= pre {
                    x[i - pre] = y;
                }
            }
        }
        Trajectory::Recorded(r) => {
            // linear interpolation of the recorded samples to the substep rate
            for (i, xi) in x.iter_mut().enumerate() {
                let u = i as f64 / sub as f64;
                let k = (u as usize).min(r.len().saturating_sub(2));
                let fr = (u - k as f64).min(1.0);
                *xi = if r.len() >= 2 {
                    r[k] + (r[k + 1] - r[k]) * fr
                } else {
                    0.0
                };
            }
        }
        Trajectory::Chirp => {
            let f0 = rng.uni(0.1, 0.3);
            let f1 = rng.uni(1.5, 4.0);
            let ph = rng.uni(0.0, TAU);
            let dur = n as f64 * h;
            for (i, xi) in x.iter_mut().enumerate() {
                let t = i as f64 * h;
                *xi = (TAU * (f0 * t + 0.5 * (f1 - f0) * t * t / dur) + ph).sin();
            }
        }
    }
    // smooth the substep interpolation / integration (moving average of one sample period,
    // twice) so that the acceleration is defined, then centre and scale to the amplitude
    let smooth = |x: &[f64]| -> Vec<f64> {
        let w = sub;
        let mut out = vec![0.0; x.len()];
        let mut acc = 0.0;
        for i in 0..x.len() {
            acc += x[i];
            if i >= w {
                acc -= x[i - w];
            }
            out[i] = acc / (i + 1).min(w) as f64;
        }
        out
    };
    if !matches!(s.trajectory, Trajectory::PointToPoint) {
        x = smooth(&smooth(&x));
    }
    let lo = x.iter().cloned().fold(f64::MAX, f64::min);
    let hi = x.iter().cloned().fold(f64::MIN, f64::max);
    let (mid, half) = (0.5 * (lo + hi), (0.5 * (hi - lo)).max(1e-12));
    let k = s.amplitude_m / half;
    for xi in x.iter_mut() {
        *xi = (*xi - mid) * k;
    }
    let mut v = vec![0.0; n];
    let mut a = vec![0.0; n];
    for i in 1..n - 1 {
        v[i] = (x[i + 1] - x[i - 1]) / (2.0 * h);
    }
    for i in 1..n - 1 {
        a[i] = (v[i + 1] - v[i - 1]) / (2.0 * h);
    }
    (x, v, a)
}

/// LuGre friction state update over a step of displacement dx at speed v (exact for constant
/// v): z → z_ss + (z − z_ss)·exp(−σ0|dx|/g), z_ss = g·sgn(v)/σ0.
fn lugre(z: &mut f64, v: f64, h: f64, sigma0: f64, g: f64) {
    if v != 0.0 {
        let zss = g * v.signum() / sigma0;
        *z = zss + (*z - zss) * (-sigma0 * v.abs() * h / g).exp();
    }
}

/// Simulate the device force (true, at the substep rate) for motion (x, v, a).
fn device_force(s: &RigSpec, hidden: Hidden, x: &[f64], v: &[f64], a: &[f64]) -> Vec<f64> {
    let n = x.len();
    let h = 1.0 / (s.fs * s.sub as f64);
    let dur = n as f64 * h;
    let fc = s.coulomb;
    // bristle stiffness: the base presliding displacement unless the effect softens it
    let x_char = match hidden {
        Hidden::Presliding { x_char_m } | Hidden::SpringPresliding { x_char_m, .. } => x_char_m,
        _ => s.base_x_char_m,
    };
    let sigma0 = fc / x_char;
    let (fsx, vs) = match hidden {
        Hidden::Stribeck { static_n, vs_m_s } => (static_n, vs_m_s),
        _ => (fc, 1.0),
    };
    let g = |v: f64| fc + (fsx - fc) * (-(v / vs).powi(2)).exp();
    let delay = match hidden {
        Hidden::Delay { delay_s } => (delay_s / h).round() as usize,
        _ => 0,
    };
    let limit = match hidden {
        Hidden::ClippedCurrentLoop { limit_n } => limit_n,
        _ => f64::INFINITY,
    };
    // play: the device (mass, drive, friction) sits behind a gap of `width`; contact
    // stiffness and damping put the contact mode at 60 Hz, ζ 0.5. Without impact only a
    // light part of the mass sits behind the gap, on the same stiffness critically damped.
    let (width, m_behind) = match hidden {
        Hidden::Backlash { width_m } => (width_m, s.mass_kg),
        Hidden::PlayNoImpact { width_m } => (width_m, PLAY_LIGHT_SIDE * s.mass_kg),
        _ => (0.0, s.mass_kg),
    };
    let m_front = s.mass_kg - m_behind;
    let wc = TAU * 60.0;
    let kc = s.mass_kg * wc * wc;
    let cc = if matches!(hidden, Hidden::PlayNoImpact { .. }) {
        2.0 * (kc * m_behind).sqrt()
    } else {
        s.mass_kg * wc
    };
    // a compliant load path with the device behind it: the link's spring-damper
    let link = match hidden {
        Hidden::ResonanceBehind { freq_hz, zeta } => {
            let w = TAU * freq_hz;
            Some((s.mass_kg * w * w, 2.0 * zeta * s.mass_kg * w))
        }
        _ => None,
    };
    let (mut xm, mut vm) = (x[0], v[0]);
    let mut z = 0.0;
    let (mut y2, mut yd2) = (x[0], v[0]);
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let t = i as f64 * h;
        let mut f_cell;
        if width > 0.0 {
            // device side integrated: contact force through the gap
            let d = x[i] - xm;
            let pen = if d > 0.5 * width {
                d - 0.5 * width
            } else if d < -0.5 * width {
                d + 0.5 * width
            } else {
                0.0
            };
            let fct = if pen != 0.0 {
                (kc * pen + cc * (v[i] - vm)).clamp(
                    if pen > 0.0 { 0.0 } else { f64::MIN },
                    if pen < 0.0 { 0.0 } else { f64::MAX },
                )
            } else {
                0.0
            };
            let fdrive = (s.drive_damping * vm).clamp(-limit, limit);
            lugre(&mut z, vm, h, sigma0, g(vm));
            let ffr = sigma0 * z + s.viscous * vm;
            let am = (fct - fdrive - ffr) / m_behind;
            vm += am * h;
            xm += vm * h;
            f_cell = fct + m_front * a[i];
        } else if let Some((kl, cl)) = link {
            // the cell measures the force through the link; the device moves behind it
            let fl = kl * (x[i] - xm) + cl * (v[i] - vm);
            let fdrive = (s.drive_damping * vm).clamp(-limit, limit);
            lugre(&mut z, vm, h, sigma0, g(vm));
            let ffr = sigma0 * z + s.viscous * vm;
            vm += (fl - fdrive - ffr) / s.mass_kg * h;
            xm += vm * h;
            f_cell = fl;
        } else {
            let fdrive = (s.drive_damping * v[i]).clamp(-limit, limit);
            lugre(&mut z, v[i], h, sigma0, g(v[i]));
            f_cell = s.mass_kg * a[i] + fdrive + sigma0 * z + s.viscous * v[i];
        }
        f_cell += s.offset_n;
        match hidden {
            Hidden::Resonance {
                mass_kg,
                freq_hz,
                zeta,
            } => {
                let w = TAU * freq_hz;
                let (k2, c2) = (mass_kg * w * w, 2.0 * zeta * mass_kg * w);
                let fs = k2 * (x[i] - y2) + c2 * (v[i] - yd2);
                yd2 += fs / mass_kg * h;
                y2 += yd2 * h;
                f_cell += fs;
            }
            Hidden::Hum { freq_hz, amp_n } => f_cell += amp_n * (TAU * freq_hz * t).sin(),
            Hidden::Drift { total_n } => f_cell += total_n * (t / dur - 0.5),
            Hidden::Spring { k_n_per_m } | Hidden::SpringPresliding { k_n_per_m, .. } => {
                f_cell += k_n_per_m * x[i]
            }
            Hidden::QuadraticDrag { c2_n_s2_per_m2 } => {
                f_cell += c2_n_s2_per_m2 * v[i] * v[i].abs()
            }
            _ => {}
        }
        out.push(f_cell);
    }
    if delay > 0 {
        // the force channel lags the position channel (acquisition skew, a load-cell
        // amplifier's group delay): the measured force at t is the force at t − delay
        let first = out[0];
        out.rotate_right(delay.min(n));
        for o in out.iter_mut().take(delay.min(n)) {
            *o = first;
        }
    }
    out
}

/// Samples of the rig's rest window: 20 ms at the classic rig's 1 kHz (see `rest_of`; other
/// sample rates take 20 ms of their samples, `RigSpec::rest_window`).
pub const REST_WINDOW: usize = 20;

/// The record's samples at rest as the rig's own sensor defines them, from the true motion:
/// a sample is at rest when, within `REST_WINDOW` samples of it, the true speed falls below
/// one encoder quantum per window, q·fs/`REST_WINDOW` (0.02, 0.08, 0.32 mm/s for the 0.4,
/// 1.6, 6.4 µm encoders). Below that speed the encoder counts less than one quantum over
/// the window, so no velocity derived from the record (whatever its filter, if it averages
/// over no more than the window) tells the motion from standstill or its direction: friction
/// there is static, anywhere within its breakaway level, and carries no Coulomb sign (the
/// issue's "samples at rest (velocity within its noise)"). The samples within the window of
/// such a sample are at rest too: a velocity averaged over the window mixes them with the
/// unresolved ones. 20 ms is long enough that one quantum resolves speeds well below the
/// motions' (their peaks are 40–300 mm/s) and short against their changes (the rounded
/// reversals and minimum-jerk starts last 50 ms and more). `v` is the true velocity at the
/// substep rate; the result is per record sample.
fn rest_of(s: &RigSpec, v: &[f64]) -> Vec<bool> {
    let w = s.rest_window;
    let v_q = s.quantum_m * s.fs / w as f64;
    let n = s.samples;
    let still: Vec<bool> = (0..n).map(|i| v[i * s.sub].abs() < v_q).collect();
    let mut rest = vec![false; n];
    let mut last: Option<usize> = None;
    for i in 0..n {
        if still[i] {
            last = Some(i);
        }
        rest[i] = last.is_some_and(|j| i - j <= w);
    }
    let mut next: Option<usize> = None;
    for i in (0..n).rev() {
        if still[i] {
            next = Some(i);
        }
        rest[i] |= next.is_some_and(|j| j - i <= w);
    }
    rest
}

/// The rms `x` (at the substep rate) holds on the samples in motion (`rest` per record
/// sample): its energy there per substep of the whole record, √(Σ_motion x²/n). A fit's
/// evidence for an effect is its energy on the samples the fit can use over the record's
/// length (what a matched filter against the noise sees); averaging over the samples in
/// motion only would inflate the evidence of a record that is mostly at rest. An effect with
/// nothing at rest has the rms over every sample.
fn rms_in_motion(x: &[f64], rest: &[bool]) -> f64 {
    let sub = (x.len() / rest.len().max(1)).max(1);
    let mut e = 0.0;
    for (c, &r) in x.chunks(sub).zip(rest) {
        if !r {
            e += c.iter().map(|v| v * v).sum::<f64>();
        }
    }
    (e / x.len().max(1) as f64).sqrt()
}

/// Most samples of a widened-rig record (10 kHz × 6 s).
pub const WIDE_MAX_SAMPLES: usize = 60_000;

/// `n` samples at `fs_to` of a position recorded at `fs_from`, linearly interpolated (held at
/// its last sample beyond its end).
pub fn resample(x: &[f64], fs_from: f64, fs_to: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let u = i as f64 * fs_from / fs_to;
            let k = (u as usize).min(x.len().saturating_sub(2));
            match x.len() {
                0 => 0.0,
                1 => x[0],
                _ => x[k] + (x[k + 1] - x[k]) * (u - k as f64).min(1.0),
            }
        })
        .collect()
}

/// The part of an effect's force `d` (at the substep rate) no refitted baseline explains: `d`
/// fitted by least squares, on the samples in motion (`rest` false), with the baseline's
/// columns from the true motion (inertia a, viscous v, Coulomb sgn v, offset 1); the rms of
/// what is left there, per sample of the record (as `rms_in_motion`). The rig's own solver
/// (normal equations, Gaussian elimination with partial pivoting).
fn unexplained_rms(sub: usize, d: &[f64], v: &[f64], a: &[f64], rest: &[bool]) -> f64 {
    const K: usize = 4;
    let row = |k: usize| [a[k], v[k], v[k].signum(), 1.0];
    let mut m = [[0.0f64; K + 1]; K];
    for (i, &r) in rest.iter().enumerate() {
        if r {
            continue;
        }
        let k = i * sub;
        let c = row(k);
        for p in 0..K {
            for q in 0..K {
                m[p][q] += c[p] * c[q];
            }
            m[p][K] += c[p] * d[k];
        }
    }
    // scale each column to a unit diagonal so that the pivots compare
    let sc: Vec<f64> = (0..K).map(|p| m[p][p].sqrt().max(1e-300)).collect();
    for p in 0..K {
        for q in 0..K {
            m[p][q] /= sc[p] * sc[q];
        }
        m[p][K] /= sc[p];
    }
    let mut th = [0.0f64; K];
    let mut ok = true;
    for c in 0..K {
        let piv = (c..K)
            .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
            .unwrap_or(c);
        m.swap(c, piv);
        if m[c][c].abs() < 1e-12 {
            ok = false;
            break;
        }
        for r in c + 1..K {
            let f = m[r][c] / m[c][c];
            let pivot_row = m[c];
            for (x, p) in m[r].iter_mut().zip(&pivot_row).skip(c) {
                *x -= f * p;
            }
        }
    }
    if ok {
        for c in (0..K).rev() {
            let mut acc = m[c][K];
            for q in c + 1..K {
                acc -= m[c][q] * th[q];
            }
            th[c] = acc / m[c][c];
        }
        for (t, s) in th.iter_mut().zip(&sc) {
            *t /= s;
        }
    }
    let mut e = 0.0;
    for (i, &r) in rest.iter().enumerate() {
        if r {
            continue;
        }
        let k = i * sub;
        let c = row(k);
        let fit: f64 = c.iter().zip(&th).map(|(x, t)| x * t).sum();
        e += (d[k] - fit) * (d[k] - fit);
    }
    (e / rest.len().max(1) as f64).sqrt()
}

/// The largest factor by which `size_to_rule` scales a hum's amplitude or a drift's total
/// (4: a hum up to 2× Coulomb, a drift up to 4× Coulomb), and the lowest clip level it
/// reaches as a fraction of the drive's peak force (0.1, against the drawn 0.45–0.8).
pub const SIZE_MAX_SCALE: f64 = 4.0;
pub const CLIP_MIN_FRACTION: f64 = 0.1;

/// Draw the parameters of a hidden effect of `kind` for a device (ranges per kind; the
/// observability rule then accepts or redraws).
fn draw_hidden(kind: &str, s: &RigSpec, vmax: f64, rng: &mut RigRng) -> Hidden {
    match kind {
        "clipped_current_loop" => Hidden::ClippedCurrentLoop {
            limit_n: s.drive_damping * vmax * rng.uni(0.45, 0.8),
        },
        "delay" => Hidden::Delay {
            delay_s: rng.uni(0.005, 0.04),
        },
        "resonance" => Hidden::Resonance {
            mass_kg: s.mass_kg * rng.uni(0.2, 0.6),
            freq_hz: rng.uni(0.8, 3.0),
            zeta: rng.uni(0.03, 0.15),
        },
        "stribeck" => Hidden::Stribeck {
            static_n: s.coulomb * rng.uni(1.5, 2.5),
            vs_m_s: vmax * rng.uni(0.03, 0.1),
        },
        "presliding" => Hidden::Presliding {
            x_char_m: s.amplitude_m * rng.uni(0.01, 0.04),
        },
        "backlash" => Hidden::Backlash {
            width_m: s.amplitude_m * rng.uni(0.01, 0.04),
        },
        "hum" => Hidden::Hum {
            freq_hz: rng.uni(6.0, 30.0),
            amp_n: s.coulomb * rng.uni(0.2, 0.5),
        },
        "drift" => Hidden::Drift {
            total_n: s.coulomb
                * rng.uni(0.4, 1.0)
                * if rng.uni(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 },
        },
        "resonance_behind" => Hidden::ResonanceBehind {
            freq_hz: rng.uni(1.0, 8.0),
            zeta: rng.uni(0.03, 0.3),
        },
        "play_no_impact" => Hidden::PlayNoImpact {
            width_m: s.amplitude_m * rng.uni(0.01, 0.04),
        },
        // a spring's force at the stroke's end 0.3–2× the Coulomb level
        "spring" => Hidden::Spring {
            k_n_per_m: s.coulomb * rng.uni(0.3, 2.0) / s.amplitude_m,
        },
        "spring_presliding" => Hidden::SpringPresliding {
            k_n_per_m: s.coulomb * rng.uni(0.3, 2.0) / s.amplitude_m,
            x_char_m: s.amplitude_m * rng.uni(0.01, 0.04),
        },
        // the drag at the peak speed 1–4× the Coulomb level (a refitted viscous and Coulomb
        // term takes most of a smaller one)
        "quadratic_drag" => Hidden::QuadraticDrag {
            c2_n_s2_per_m2: s.coulomb * rng.uni(1.0, 4.0) / (vmax * vmax).max(1e-12),
        },
        _ => Hidden::None,
    }
}

impl RigSpec {
    /// A random device and test (seeded) with a hidden effect of `kind` (one of
    /// `Hidden::KINDS`) on the given trajectory family.
    pub fn random(seed: u64, kind: &str, trajectory: Trajectory, samples: usize) -> Self {
        let mut rng = RigRng::new(seed);
        RigSpec {
            seed,
            fs: 1000.0,
            samples,
            trajectory: trajectory.clone(),
            amplitude_m: rng.uni(0.02, 0.06),
            mass_kg: rng.uni(20.0, 100.0),
            drive_damping: rng.uni(200.0, 900.0),
            viscous: rng.uni(20.0, 100.0),
            coulomb: rng.uni(15.0, 60.0),
            offset_n: rng.uni(-5.0, 5.0),
            noise_n: rng.uni(0.2, 2.0),
            quantum_m: [0.4e-6, 1.6e-6, 6.4e-6][rng.pick(3)],
            lead_m: 0.016,
            hidden: Hidden::None,
            observable: true,
            effect_rms_n: 0.0,
            base_x_char_m: 2e-6,
            motion_draw: 0,
            requested: trajectory.name(),
            sub: SUB,
            rest_window: REST_WINDOW,
            refit_rule: false,
            effect_unexplained_n: 0.0,
        }
        .with_base_friction()
        .with_hidden(kind, seed)
    }

    /// The widened rig: a random device, sensors and test (seeded) with a hidden effect of
    /// `kind` (one of `Hidden::WIDE_KINDS`). Beside the classic rig's ranges it draws the
    /// sample rate (500 Hz … 10 kHz), the record's length (6–20 s, at most `WIDE_MAX_SAMPLES`
    /// samples), the force noise (0.05–5 N rms, log-uniform), the encoder's quantum (0.1 …
    /// 25.6 µm), the lead, and the trajectory family (the classic four, a chirp, and `recorded`
    /// when a recorded position at `recorded_fs` is given, resampled to the record's rate). Its
    /// observability rule adds a clause: the part of the effect's force no refitted baseline
    /// explains (`unexplained_rms`) holds at least `REFIT_NOISE_RATIO` times the noise.
    pub fn widened(seed: u64, kind: &str, recorded: Option<(&[f64], f64)>) -> Self {
        let mut rng = RigRng::new(seed ^ 0x005E_ED0F_71DE_0000);
        let fs = [500.0, 1000.0, 2000.0, 5000.0, 10_000.0][rng.pick(5)];
        let mut dur = rng.uni(6.0, 20.0);
        let families = if recorded.is_some() { 6 } else { 5 };
        let trajectory = match rng.pick(families) {
            0 => Trajectory::Multisine,
            1 => Trajectory::RoundedTriangle,
            2 => Trajectory::PointToPoint,
            3 => Trajectory::Narrowband,
            4 => Trajectory::Chirp,
            _ => {
                let (x, rfs) = recorded.unwrap_or((&[], 1.0));
                dur = dur.min((x.len().saturating_sub(2)) as f64 / rfs);
                let n = ((dur * fs) as usize).min(WIDE_MAX_SAMPLES);
                Trajectory::Recorded(resample(x, rfs, fs, n))
            }
        };
        let samples = ((dur * fs) as usize).min(WIDE_MAX_SAMPLES);
        let amplitude_m = rng.uni(0.01, 0.08);
        let mass_kg = rng.uni(10.0, 150.0);
        let drive_damping = rng.uni(100.0, 1500.0);
        let viscous = rng.uni(10.0, 150.0);
        let coulomb = rng.uni(10.0, 80.0);
        let offset_n = rng.uni(-10.0, 10.0);
        let noise_n = (rng.uni(0.05f64.ln(), 5.0f64.ln())).exp();
        let quantum_m = [0.1e-6, 0.4e-6, 1.6e-6, 6.4e-6, 25.6e-6][rng.pick(5)];
        let lead_m = [0.005, 0.01, 0.016, 0.025][rng.pick(4)];
        RigSpec {
            seed,
            fs,
            samples,
            trajectory: trajectory.clone(),
            amplitude_m,
            mass_kg,
            drive_damping,
            viscous,
            coulomb,
            offset_n,
            noise_n,
            quantum_m,
            lead_m,
            hidden: Hidden::None,
            observable: true,
            effect_rms_n: 0.0,
            base_x_char_m: 2e-6,
            motion_draw: 0,
            requested: trajectory.name(),
            sub: substeps_for(fs),
            rest_window: ((0.02 * fs).round() as usize).max(2),
            refit_rule: true,
            effect_unexplained_n: 0.0,
        }
        .with_base_friction()
        .with_hidden(kind, seed)
    }

    /// The device's own presliding must not be detectable: halve its displacement (from 2 µm,
    /// at most 16 times) while the force it changes against a rigid switch (0.1 nm), sampled
    /// as recorded, would stand out of the force noise to a matched filter at 3σ
    /// (‖Δf‖₂ ≥ 3·noise). The observability rule of `with_hidden` (rms ≥ 5× noise) is a
    /// threshold for an effect meant to be seen; "nothing hidden" needs the dual, "nothing
    /// detectable": a 2 µm LuGre transition at every reversal is below the first and far above
    /// the second (on some records it is most of the baseline's residual).
    fn with_base_friction(mut self) -> Self {
        let (x, v, a) = motion_of(&self);
        self.base_x_char_m = 1e-10;
        let rigid = device_force(&self, Hidden::None, &x, &v, &a);
        let mut xc = 2e-6;
        for _ in 0..16 {
            self.base_x_char_m = xc;
            let f = device_force(&self, Hidden::None, &x, &v, &a);
            let e2: f64 = f
                .iter()
                .zip(&rigid)
                .step_by(self.sub)
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            if e2.sqrt() < 3.0 * self.noise_n {
                break;
            }
            xc *= 0.5;
        }
        self
    }

    fn with_hidden(mut self, kind: &str, seed: u64) -> Self {
        if kind == "none" {
            return self;
        }
        let mut rng = RigRng::new(seed ^ 0xA5A5_5A5A_1234_8765);
        if self.observable_on_family(kind, &mut rng) {
            return self;
        }
        // the family cannot show the effect: the next parametric families, in turn (the
        // widened rig's chirp among them)
        const ALL_FAMILIES: [Trajectory; 5] = [
            Trajectory::Multisine,
            Trajectory::RoundedTriangle,
            Trajectory::PointToPoint,
            Trajectory::Narrowband,
            Trajectory::Chirp,
        ];
        let families = &ALL_FAMILIES[..if self.refit_rule { 5 } else { 4 }];
        let own = families.iter().position(|f| *f == self.trajectory);
        let start = own.map_or(0, |k| k + 1);
        let mut other = self.clone();
        for k in 0..families.len() {
            let fam = &families[(start + k) % families.len()];
            if Some((start + k) % families.len()) == own {
                continue;
            }
            other.trajectory = fam.clone();
            other.motion_draw = 0;
            other = other.with_base_friction();
            if other.observable_on_family(kind, &mut rng) {
                return other;
            }
        }
        // no family shows the effect at its drawn size: sized to the rule
        self.size_to_rule();
        self
    }

    /// The observability rule on the record's own family: up to 8 motions (1 for a recorded
    /// one), 40 draws of the effect on each; true when a draw is observable (the record then
    /// holds it), false with the last draw held.
    fn observable_on_family(&mut self, kind: &str, rng: &mut RigRng) -> bool {
        let motions = if matches!(self.trajectory, Trajectory::Recorded(_)) {
            1
        } else {
            8
        };
        for m in 0..motions {
            if m > 0 {
                // the effect is not observable on this motion: the next draw of the
                // trajectory's parameters (the device's own presliding re-sized for it)
                self.motion_draw = m;
                *self = self.clone().with_base_friction();
            }
            let (x, v, a) = motion_of(self);
            let f0 = device_force(self, Hidden::None, &x, &v, &a);
            let vmax = v.iter().fold(0.0f64, |m, u| m.max(u.abs()));
            let rest = rest_of(self, &v);
            let f0r = rms_in_motion(&f0, &rest);
            for _ in 0..40 {
                let hd = draw_hidden(kind, self, vmax, rng);
                if self.holds_rule(hd, &x, &v, &a, &f0, f0r, &rest) {
                    return true;
                }
            }
        }
        false
    }

    /// The observability rule for effect `hd` on motion (x, v, a) with the effect-free force
    /// `f0` (its rms in motion `f0r`): the force the effect changes, over the samples in
    /// motion (`rest_of`), has an rms ≥ 5× the force noise and ≥ 3 % of `f0r`. Holds `hd`,
    /// its rms and the verdict in the record.
    #[allow(clippy::too_many_arguments)]
    fn holds_rule(
        &mut self,
        hd: Hidden,
        x: &[f64],
        v: &[f64],
        a: &[f64],
        f0: &[f64],
        f0r: f64,
        rest: &[bool],
    ) -> bool {
        let f1 = device_force(self, hd, x, v, a);
        let d: Vec<f64> = f1.iter().zip(f0).map(|(a, b)| a - b).collect();
        let r = rms_in_motion(&d, rest);
        self.hidden = hd;
        self.effect_rms_n = r;
        self.observable = r >= 5.0 * self.noise_n && r >= 0.03 * f0r;
        if self.refit_rule {
            self.effect_unexplained_n = unexplained_rms(self.sub, &d, v, a, rest);
            self.observable &= self.effect_unexplained_n >= REFIT_NOISE_RATIO * self.noise_n;
        }
        self.observable
    }

    /// Effects sized to the rule: a record no family shows keeps its motion and its last draw,
    /// and the draw's size is raised to the least that meets the observability rule. A hum's
    /// amplitude and a drift's total add a force proportional to them, so the least size is
    /// the draw's times max(5·noise, 0.03·f0r)/rms (and 10⁻⁶ above it, for rounding), at most
    /// `SIZE_MAX_SCALE`; a clip's level is lowered by bisection (24 halvings) between the
    /// drawn level and `CLIP_MIN_FRACTION` of the drive's peak force c·v_max, to the highest
    /// level that meets it. Other kinds, or a size the maximum does not reach, stay flagged.
    fn size_to_rule(&mut self) {
        let (x, v, a) = motion_of(self);
        let f0 = device_force(self, Hidden::None, &x, &v, &a);
        let rest = rest_of(self, &v);
        let f0r = rms_in_motion(&f0, &rest);
        let hd = self.hidden;
        // the least rms the rule accepts
        let need = (5.0 * self.noise_n).max(0.03 * f0r);
        match hd {
            Hidden::Hum { .. } | Hidden::Drift { .. } => {
                let r = self.effect_rms_n;
                if r <= 0.0 {
                    return;
                }
                let k = need / r * (1.0 + 1e-6);
                if k > SIZE_MAX_SCALE {
                    return;
                }
                let scaled = match hd {
                    Hidden::Hum { freq_hz, amp_n } => Hidden::Hum {
                        freq_hz,
                        amp_n: amp_n * k,
                    },
                    Hidden::Drift { total_n } => Hidden::Drift {
                        total_n: total_n * k,
                    },
                    _ => return,
                };
                if !self.holds_rule(scaled, &x, &v, &a, &f0, f0r, &rest) {
                    // not reached (the force is linear in the size): keep the draw flagged
                    self.holds_rule(hd, &x, &v, &a, &f0, f0r, &rest);
                }
            }
            Hidden::ClippedCurrentLoop { limit_n } => {
                let vmax = v.iter().fold(0.0f64, |m, u| m.max(u.abs()));
                let lo_n = CLIP_MIN_FRACTION * self.drive_damping * vmax;
                let clip = |l: f64| Hidden::ClippedCurrentLoop { limit_n: l };
                if lo_n >= limit_n || !self.holds_rule(clip(lo_n), &x, &v, &a, &f0, f0r, &rest) {
                    self.holds_rule(hd, &x, &v, &a, &f0, f0r, &rest);
                    return;
                }
                // lo meets the rule, hi does not
                let (mut lo, mut hi) = (lo_n, limit_n);
                for _ in 0..24 {
                    let mid = 0.5 * (lo + hi);
                    if self.holds_rule(clip(mid), &x, &v, &a, &f0, f0r, &rest) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                self.holds_rule(clip(lo), &x, &v, &a, &f0, f0r, &rest);
            }
            _ => {}
        }
    }

    /// The record's samples at rest by the rig's own definition (`rest_of`), from its true
    /// motion.
    pub fn rest(&self) -> Vec<bool> {
        let (_, v, _) = motion_of(self);
        rest_of(self, &v)
    }

    /// The imposed motion's velocity and acceleration at the record's samples, as the rig's
    /// physics takes them (before the encoder's quantum): for measuring what a record's derived
    /// signals miss.
    pub fn true_motion(&self) -> (Vec<f64>, Vec<f64>) {
        let (_, v, a) = motion_of(self);
        let at = |u: &[f64]| (0..self.samples).map(|i| u[i * self.sub]).collect();
        (at(&v), at(&a))
    }

    /// The record as CSV text in the diagnosis schema (t_s, x_m, f_N; lead as metadata).
    pub fn csv(&self) -> String {
        let (x, v, a) = motion_of(self);
        let f = device_force(self, self.hidden, &x, &v, &a);
        let mut rng = RigRng::new(self.seed ^ 0x0F0F_F0F0_0F0F_F0F0);
        let mut out = String::with_capacity(self.samples * 40);
        let _ = writeln!(
            out,
            "# bench rig record, seed {}, trajectory {} (draw {}; asked for {}), hidden {:?}",
            self.seed,
            self.trajectory.name(),
            self.motion_draw,
            self.requested,
            self.hidden
        );
        let _ = writeln!(
            out,
            "# device: mass {} kg, drive damping {} N·s/m, viscous {} N·s/m, Coulomb {} N, offset {} N; noise {} N rms, quantum {} m",
            self.mass_kg, self.drive_damping, self.viscous, self.coulomb, self.offset_n, self.noise_n, self.quantum_m
        );
        let _ = writeln!(out, "# lead_m_per_rev = {}", self.lead_m);
        out.push_str("t_s,x_m,f_N\n");
        for i in 0..self.samples {
            let k = i * self.sub;
            let xq = (x[k] / self.quantum_m).round() * self.quantum_m;
            let fi = f[k] + self.noise_n * rng.gauss();
            let _ = writeln!(out, "{:.6},{:.9e},{:.5}", i as f64 / self.fs, xq, fi);
        }
        out
    }
}
