//! The physics the simulator's plant and the diagnosis share, one implementation each: the
//! play walk (a device behind a play, its contact and impacts). The simulator steps it in
//! `hal-sim`'s `device_model`, the diagnosis (`regen-diagnose`) walks a record with it, so the
//! physics a report names is the physics the simulator replays.

/// `backlash`'s second parameter c as its contact: (restitution, contact frequency in Hz; 0:
/// rigid). c ≥ 0 is a rigid flank's restitution; c < 0 a compliant, plastic flank of contact
/// frequency −c.
pub fn play_contact(c: f64) -> (f64, f64) {
    if c < 0.0 {
        (0.0, -c)
    } else {
        (c, 0.0)
    }
}

/// Samples over which the `backlash` impact's force pulse is resolved (free shape, one
/// coefficient per sample after the contact): a contact that brings the device to the
/// motion's velocity within 12 sample periods (12 ms at 1 kHz; a contact mode above
/// ≈ fs/40 with a damping ratio ≥ 0.3 settles within it).
pub const IMPACT_TAPS: usize = 12;

/// The walk of the diagnosis's `play_device` one sample at a time: the diagnosis's column walks a record
/// with it, the simulator's plant (`device_model`'s `backlash`) its own steps, so the physics
/// the report names is the physics the simulator replays.
#[derive(Debug, Clone)]
pub struct PlayWalk {
    h: f64,
    m: f64,
    fv: f64,
    fc: f64,
    /// The contact's restitution (0: the flank carries the device on after striking it).
    e: f64,
    decay: f64,
    dv_c: f64,
    dt: f64,
    /// flank in contact: +1 (x pushes the device towards +), −1, or 0 (free)
    flank: f64,
    /// The device's position and velocity.
    pub xm: f64,
    vm: f64,
    /// The motion's position at the last step (None before the first).
    x_last: Option<f64>,
    /// The contact's stiffness over the device's inertia, ω_c² (1/s²): a flank that is a
    /// spring of stiffness M·ω_c², its contact mode at ω_c; infinite (`new`): a rigid flank.
    wc2: f64,
    /// The force the contact's spring carries while the device is held off its sliding
    /// contact (signed: + pushes the device towards +): unloading after the motion reverses
    /// on a flank, loading before the device breaks away; 0 otherwise and on a rigid flank.
    pub spring: f64,
}

impl PlayWalk {
    /// A device of inertia `m`, viscous `fv` and Coulomb `fc` friction behind a play of total
    /// width `b`, stepped every `dt` seconds; it starts centred on the first step's position
    /// with its velocity.
    pub fn new(b: f64, m: f64, fv: f64, fc: f64, dt: f64) -> Self {
        let (m, fv, fc) = (m.max(0.0), fv.max(0.0), fc.max(0.0));
        PlayWalk {
            h: 0.5 * b,
            m,
            fv,
            fc,
            e: 0.0,
            decay: if m > 0.0 { (-fv * dt / m).exp() } else { 0.0 },
            dv_c: if m > 0.0 { fc * dt / m } else { f64::INFINITY },
            dt,
            flank: 0.0,
            xm: 0.0,
            vm: 0.0,
            x_last: None,
            wc2: f64::INFINITY,
            spring: 0.0,
        }
    }

    /// The same device behind a contact of finite stiffness k = M·(2π·`hz`)² (a gear's or a
    /// ballscrew's flank is a spring, not a wall; `hz` its contact mode with the device's
    /// inertia; `hz` ≤ 0 or not finite: rigid, `new`'s walk). On a flank the spring carries the
    /// device's force f = M·a + Fv·v + Fc·sgn v and the device lags the flank by f/k. When the
    /// motion reverses on a flank, the device's friction stops it (static friction, anywhere
    /// within Fc, holds it) with the spring loaded by the force it carried, M·a + Fv·v +
    /// Fc·sign (sliding friction in the flank's direction, as it stops): the spring then
    /// unloads linearly with the motion's retreat, k·pen, and the device is free only once it
    /// has unloaded (over f/k of travel, where a rigid flank releases it at once). A flank
    /// that reaches a device at rest loads its spring likewise until k·pen reaches the force
    /// the device needs to move with it. A device that coasts off the flank mid-motion (the
    /// motion decelerating faster than its friction) leaves it unloaded, as on a rigid flank.
    pub fn with_contact_hz(mut self, hz: f64) -> Self {
        self.wc2 = f64::INFINITY;
        if hz.is_finite() && hz > 0.0 {
            let w = 2.0 * std::f64::consts::PI * hz;
            self.wc2 = w * w;
        }
        self
    }

    /// The contact of `backlash`'s second parameter `c` (`play_contact`): a rigid flank of
    /// restitution c ≥ 0 (`with_restitution`), or a compliant, plastic one of contact
    /// frequency −c > 0 (`with_contact_hz`).
    pub fn with_contact(self, c: f64) -> Self {
        let (e, hz) = play_contact(c);
        self.with_restitution(e).with_contact_hz(hz)
    }

    /// The contact's stiffness (N/m; infinite for a rigid flank).
    pub fn stiffness(&self) -> f64 {
        self.m * self.wc2
    }

    /// Whether the flank is a spring (a finite, positive stiffness; otherwise the rigid walk).
    pub fn compliant(&self) -> bool {
        let k = self.stiffness();
        k.is_finite() && k > 0.0
    }

    /// The same device behind a contact of restitution `e` (0 ≤ e < 1; values outside are
    /// clamped to it): a flank striking the device at the relative velocity v_r = v − v_m
    /// throws it ahead at v + e·v_r, and it flies free (no force passes: viscous decay and
    /// Coulomb deceleration) until a flank strikes it again, unless the flank's push
    /// (M·a + Fv·v + Fc·sgn v) brings it back within the step (its flight 2·e·|v_r|·M / push
    /// shorter than dt): it then stays on the flank. At e = 0 the walk is `new`'s.
    pub fn with_restitution(mut self, e: f64) -> Self {
        self.e = if e.is_finite() {
            e.clamp(0.0, 0.999)
        } else {
            0.0
        };
        self
    }

    /// The next sample of the motion (x, v, a, and sgn v as the baseline takes it): whether
    /// the device is off both flanks after it, and the impact when a flank strikes it within
    /// this step (the time from the contact to the sample, in steps, and the relative
    /// velocity v − v_m).
    pub fn step(&mut self, x: f64, v: f64, a: f64, sg: f64) -> (bool, Option<(f64, f64)>) {
        let (h, dt) = (self.h, self.dt);
        let Some(x_prev) = self.x_last.replace(x) else {
            (self.xm, self.vm) = (x, v);
            return (true, None);
        };
        let mut impact = None;
        let k = self.stiffness();
        let compliant = self.compliant();
        self.spring = 0.0;
        if self.flank != 0.0 {
            // on the flank while it pushes; otherwise the device left it after the last step
            let s = self.flank;
            if !compliant {
                let f = self.m * a + self.fv * v + self.fc * sg;
                if s * f >= 0.0 {
                    self.xm = x - s * h;
                    self.vm = v;
                } else {
                    self.flank = 0.0;
                }
            } else {
                // a compliant flank: the force its spring carries while the device slides in
                // the flank's direction (its friction the sliding one, Fc·s, at any speed)
                let hold = self.m * a + self.fv * v + self.fc * s;
                if s * v > 0.0 && s * hold >= 0.0 {
                    // the spring carries `hold`, the device hold/k behind the flank
                    self.xm = x - s * h - hold / k;
                    self.vm = v;
                } else {
                    self.flank = 0.0;
                    if s * hold > 0.0 {
                        // the motion stops or reverses on the flank: static friction holds
                        // the device where it stopped, the spring loaded by `hold`
                        self.xm = x_prev - s * h - hold / k;
                        self.vm = 0.0;
                    }
                }
            }
        }
        if self.flank == 0.0 {
            let (xp, dp, vm) = (self.xm, x_prev - self.xm, self.vm);
            // velocity linear over the step (viscous decay and Coulomb deceleration); stopped
            // where it reaches 0 (friction then holds the device)
            let w = vm * self.decay - vm.signum() * self.dv_c;
            let (travel, vn) = if vm == 0.0 {
                (0.0, 0.0)
            } else if w * vm > 0.0 {
                (0.5 * (vm + w) * dt, w)
            } else {
                (0.5 * vm * dt * (vm / (vm - w)), 0.0)
            };
            self.xm = xp + travel;
            self.vm = vn;
            let d = x - self.xm;
            for s in [1.0, -1.0] {
                if compliant && s * d > h {
                    let pen = s * d - h;
                    let vr = v - self.vm;
                    // the spring was compressed at the last sample: no new contact
                    let was_in = s * dp > h;
                    let need = s * (self.m * a + self.fv * v + self.fc * sg);
                    // a moving device is struck at the contact; one at rest when the spring
                    // carries what it needs to move (it breaks away): the impact then, at
                    // the penetration need/k (interpolated within the step)
                    let at = if self.vm != 0.0 {
                        (!was_in).then_some(0.0)
                    } else {
                        Some(need.max(0.0) / k)
                    };
                    let struck = at.filter(|&p| s * vr > 0.0 && pen >= p);
                    if let Some(p_at) = struck {
                        let p_prev = s * dp - h;
                        let phi = ((p_at - p_prev) / (pen - p_prev)).clamp(0.0, 1.0);
                        impact = Some((1.0 - phi, vr));
                    }
                    // struck, or a moving device the compressed spring catches up: on the
                    // flank, the spring carrying what the device needs
                    if struck.is_some() || (s * vr > 0.0 && self.vm != 0.0) {
                        self.flank = s;
                        self.vm = v;
                        self.xm = x - s * h - s * need.max(0.0) / k;
                    } else {
                        // unloading after a reversal, or loading against a device at rest:
                        // the device held, the spring carrying k·pen
                        self.spring = s * k * pen;
                    }
                    continue;
                }
                if s * d >= h {
                    let vr = v - self.vm;
                    self.xm = x - s * h;
                    if s * vr > 0.0 {
                        // the flank catches the device up: struck into the motion
                        let phi = ((s * h - dp) / (d - dp)).clamp(0.0, 1.0);
                        impact = Some((1.0 - phi, vr));
                        self.flank = s;
                        self.vm = v;
                        if self.e > 0.0 {
                            // thrown ahead at v + e·v_r from the contact instant, unless the
                            // push returns it to the flank within the step
                            let push = s * (self.m * a + self.fv * v + self.fc * sg);
                            // the relative velocity at the contact instant (the device's
                            // decayed over the part of the step before it)
                            let vc = vm * self.decay.powf(phi) - vm.signum() * self.dv_c * phi;
                            let vc = if vc * vm > 0.0 { vc } else { 0.0 };
                            let ev = self.e * (v - vc);
                            if 2.0 * s * ev * self.m > dt * push.max(0.0) {
                                // its flight from the contact instant to the sample: ahead of
                                // the flank by e·v_r over that time, its velocity decayed
                                let w = v + ev;
                                self.flank = 0.0;
                                self.vm = w * self.decay.powf(1.0 - phi)
                                    - w.signum() * self.dv_c * (1.0 - phi);
                                self.xm += ev * (1.0 - phi) * dt;
                            }
                        }
                    }
                }
            }
        }
        (self.flank == 0.0, impact)
    }
}
