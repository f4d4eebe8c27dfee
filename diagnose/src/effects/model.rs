//! What every effect of the library is to the method: the trait each implements
//! (`EffectModel`) and the handle the selection carries (`EffectKind`). The effects themselves
//! are in `catalogue/`, one file each, listed in its `REGISTRY`.

use super::*;

/// One effect of the library. The selection, the validation and the report know an effect only
/// through these methods; none of them names one.
///
/// Required: its name, its columns over the record, its physical admissibility, its parameters
/// in words and units and its one-line reading. The rest has defaults that fit an effect of
/// fixed columns without a scanned parameter; the evidence methods (`force_delay` …
/// `apart_from_hum`) state which of the method's shared tests apply to it.
pub trait EffectModel: Sync {
    /// The catalogue name (the report's and the `--model` fragment's).
    fn name(&self) -> &'static str;

    /// True when the effect carries a scanned nonlinear parameter (counted in the BIC).
    fn scanned(&self) -> bool {
        false
    }

    /// Its regressor columns on the rows of `s` (unit coefficients; names `name.suffix`).
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)>;

    /// The columns of several values of the effect on the rows of `s` (one pass over the
    /// record for an effect that walks its history).
    fn columns_batch(
        &self,
        ctx: &Context,
        s: &Sig,
        effs: &[Effect],
    ) -> Vec<Vec<(String, Vec<f64>)>> {
        effs.iter().map(|e| self.columns_on(ctx, s, e)).collect()
    }

    /// True when its columns walk the record's history (a resonator, a friction state, the
    /// device behind a gap): the scan fills the values of a grid in one pass
    /// (`columns_batch`).
    fn walks_history(&self) -> bool {
        false
    }

    /// The coarse grid of parameter values (a single value when not scanned).
    fn grid(&self, _ctx: &Context, cand: &Effect) -> Vec<Effect> {
        vec![Effect::new(cand.kind, 0.0)]
    }

    /// Local refinement values around a coarse best `e`, relative half-width `width`.
    fn refine(&self, _ctx: &Context, _e: &Effect, _width: f64) -> Vec<Effect> {
        Vec::new()
    }

    /// The relative half-widths of the successive refinements.
    fn refine_widths(&self) -> &'static [f64] {
        &[0.15, 0.03]
    }

    /// Values of a second parameter tried at the best first one (ranked as the first is).
    fn variants(&self, _ctx: &Context, _centre: &Effect) -> Vec<Effect> {
        Vec::new()
    }

    /// Values of a further parameter tried when the best value passes the selection: one
    /// parameter more, so one of them replaces it only when it cuts its held-out rss by the
    /// selection's margin.
    fn extended_variants(&self, _ctx: &Context, _centre: &Effect) -> Vec<Effect> {
        Vec::new()
    }

    /// Values of the second parameter around the variant chosen, at refinement level `level`
    /// (0, 1, …): each level is scanned around the best value so far, ranked as the variants
    /// are, until a level gives none (a second parameter on a coarse grid bisected towards its
    /// optimum).
    fn variant_fine(&self, _centre: &Effect, _level: usize) -> Vec<Effect> {
        Vec::new()
    }

    /// The relative half-width of a last refinement of the first parameter at the variant
    /// chosen (None: none).
    fn variant_refine(&self, _centre: &Effect) -> Option<f64> {
        None
    }

    /// The same effect with its extended parameter dropped (None when it has none): kept
    /// instead when it fits the whole record's held-out part as well.
    fn simpler(&self, _e: &Effect) -> Option<Effect> {
        None
    }

    /// Physical admissibility of its fitted coefficients `coef` with the baseline's `base`
    /// (inertia, viscous, Coulomb, offset) fitted beside them. Finiteness is checked before.
    fn admissible(&self, e: &Effect, coef: &[f64], base: &[f64]) -> bool;

    /// Whether a fit is consistent with the measured force `f` beside the baseline prediction
    /// `bp` and the velocity `v` on the same rows (`resid_rms` the baseline residual's rms).
    #[allow(clippy::too_many_arguments)]
    fn consistent_with_force(
        &self,
        _ctx: &Context,
        _e: &Effect,
        _coef: &[f64],
        _base: &[f64],
        _bp: &[f64],
        _v: &[f64],
        _f: &[f64],
        _resid_rms: f64,
    ) -> bool {
        true
    }

    /// Its physical parameters in words and units, from its own coefficients (`coef` by column
    /// suffix, 0 when absent) and the baseline's `base` (inertia, viscous, Coulomb, offset).
    fn parameters(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        base: &[f64],
    ) -> Vec<(String, f64)>;

    /// A one-line physical reading.
    fn describe(&self, ctx: &Context, e: &Effect) -> String;

    /// Its scenario fragment for the simulator's `--model` output: the entries the plant's
    /// effect takes beside its name and the report's parameters (`model` the final model's
    /// columns and coefficients, `dt` the sample period), or why the plant does not express it.
    fn fragment(
        &self,
        _e: &Effect,
        _model: &[(String, f64)],
        _dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        Ok(Vec::new())
    }

    // ---- which of the method's shared tests apply ----

    /// The delay τ when the effect makes the force the device's at t − τ: the samples whose
    /// motion τ earlier is at rest are left out of its fits and of those it is compared with.
    fn force_delay(&self, _e: &Effect) -> Option<f64> {
        None
    }

    /// The covariance of the derived signals' noise in its column with the inertia's and the
    /// viscous columns, and how the scan uses it, when its column carries that noise.
    fn derived_noise(&self, _ctx: &Context, _e: &Effect) -> Option<(NoiseUse, [[f64; 3]; 3])> {
        None
    }

    /// True when its evidence lies at the contacts right after reversals: its stability is
    /// tested on every row in motion, a delay's left-out rows included.
    fn tested_at_reversals(&self) -> bool {
        false
    }

    /// Agreement of its coefficients over the stability segments' fits (`held`: the segments
    /// where it held).
    fn agreement(&self, fits: &[Vec<f64>], _held: &[bool]) -> f64 {
        crate::jackknife_t(fits)
    }

    /// The wavelength when the effect is a force periodic in position.
    fn spatial_wavelength(&self, _e: &Effect) -> Option<f64> {
        None
    }

    /// The samples where its column lies inside the band the derived signals follow, with the
    /// wording of that test, when the acceleration is derived (None otherwise).
    fn in_band(&self, _ctx: &Context, _e: &Effect) -> Option<(Vec<bool>, InBandWords)> {
        None
    }

    /// True when it names a force of the motion that must stand apart from a force at one
    /// time frequency in the residual.
    fn apart_from_hum(&self) -> bool {
        false
    }
}

/// How an effect's column noise from the derived signals enters the scan. Either way it must
/// carry the selection's margin on the fits with and without it corrected for the noise, and
/// every candidate beside it must carry the margin on the fits corrected for its noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseUse {
    /// Its admissibility is also judged on the fit corrected for the noise, and a value whose
    /// least-squares fit is not admissible ranks behind every value whose fit is.
    RankCorrected,
    /// The margin only.
    MarginCorrected,
}

/// The words of an in-band test: what the finding is not when it fails, where the band lies,
/// and what lies outside it.
#[derive(Debug, Clone, Copy)]
pub struct InBandWords {
    pub not: &'static str,
    pub band: &'static str,
    pub outside: &'static str,
}

/// A value of a scenario fragment's entry.
#[derive(Debug, Clone, PartialEq)]
pub enum FragmentValue {
    Number(f64),
    List(Vec<f64>),
}

/// An effect of the library: a handle on its `EffectModel` (compared by name).
#[derive(Clone, Copy)]
pub struct EffectKind(pub &'static dyn EffectModel);

impl std::ops::Deref for EffectKind {
    type Target = dyn EffectModel;
    fn deref(&self) -> &Self::Target {
        self.0
    }
}

impl PartialEq for EffectKind {
    fn eq(&self, other: &Self) -> bool {
        self.0.name() == other.0.name()
    }
}
impl Eq for EffectKind {}

impl std::fmt::Debug for EffectKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0.name())
    }
}

impl EffectKind {
    /// Every effect of the library, in the registry's order.
    pub fn all() -> &'static [EffectKind] {
        &REGISTRY
    }
    /// The effect of a catalogue name.
    pub fn from_name(s: &str) -> Option<Self> {
        REGISTRY.iter().copied().find(|k| k.name() == s)
    }
    /// Its position in the registry (the caches' key).
    pub fn index(self) -> usize {
        REGISTRY
            .iter()
            .position(|k| *k == self)
            .unwrap_or(REGISTRY.len())
    }
}
