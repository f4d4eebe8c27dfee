//! Model diagnosis: fit the baseline device model to a measured record, show what it gets
//! wrong, name the cause from a catalogue of physical effects, extend the model and measure
//! the gain on held-out data. It reads records and shares no code with the simulator (the
//! physics both use is `regen-physics`). See docs/diagnose.md.

// Numerical kernels index several arrays in step; iterator rewrites would obscure them.
#![allow(clippy::needless_range_loop)]

mod conclusion;
pub mod effects;
mod fit;
pub mod record;
pub mod report;
mod runs;
mod selection;
pub mod synth;
mod validation;

pub(crate) use conclusion::*;
pub use fit::*;
pub use runs::*;
pub use selection::*;
pub use validation::*;

pub use effects::{Effect, EffectKind};
pub use record::{parse_csv, read_csv, Record, RecordError};

/// Options of a diagnosis run.
#[derive(Debug, Clone)]
pub struct Options {
    /// Held-out relative rss improvement a candidate must bring to be kept (fraction, e.g. 0.02
    /// = the held-out residual sum of squares falls by at least 2 %), on top of a BIC decrease.
    pub min_holdout_gain: f64,
    /// Maximum number of effects added.
    pub max_effects: usize,
    /// Samples used for screening candidates (strided subsample of the record); the final
    /// refit uses every sample.
    pub screen_samples: usize,
    /// Samples from the record's start the candidates are screened on (`SCREEN_WINDOW`; the
    /// whole record when it is shorter).
    pub screen_window: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            min_holdout_gain: 0.02,
            max_effects: 6,
            screen_samples: 10_000,
            screen_window: SCREEN_WINDOW,
        }
    }
}

/// Samples from the record's start over which candidates are screened (forward selection and
/// swap pass: the screening subsample is strided over them, with their own held-out blocks,
/// `holdout_mask` of the window). A column that walks the record's history (resonator, Dahl
/// state, the device behind a play) is walked up to its last screening row, so on a long
/// record every scanned value walks this window instead of the whole record (50 s at 1 kHz,
/// five times the 10,000 screening rows; the damping-ratio profile's rows lie in it too).
/// What is kept is checked and reported on the whole record: the stability segments (a
/// finding selected in the window must hold on segments of the whole record, four of five
/// lying outside it), the final fit and every reported error. Records up to this length are
/// screened over all their samples, exactly as without the window.
pub const SCREEN_WINDOW: usize = 50_000;

/// Samples screened on a record of `n` samples by default: `n`, at most `SCREEN_WINDOW`.
pub fn screen_window(n: usize) -> usize {
    n.min(SCREEN_WINDOW)
}

/// Part of the record a sample belongs to: training.
pub const TRAIN: u8 = 0;
/// Held out (validation).
pub const HELD_OUT: u8 = 1;
/// Left out of every fit (the device is at rest: friction is static, anywhere within its
/// breakaway level, and carries no Coulomb sign).
pub const AT_REST: u8 = 2;

/// Training / held-out splits: the record is cut into 10 consecutive blocks and every third
/// block is held out, so both parts span the whole trajectory. Split `s` holds out the blocks
/// whose index is `SPLITS[s]` modulo 3: split 0 the blocks 2, 5, 8 (every run starts there),
/// split 1 the blocks 1, 4, 7, split 2 the blocks 0, 3, 6, 9 (`runs::diagnose_checked` runs
/// the selection on splits 0 and 1, and on split 2 where those two name different effects).
pub fn holdout_mask(n: usize, split: usize) -> Vec<u8> {
    let r = SPLITS[split % SPLITS.len()];
    (0..n)
        .map(|i| {
            if (i * 10 / n) % 3 == r {
                HELD_OUT
            } else {
                TRAIN
            }
        })
        .collect()
}

/// The held-out block index modulo 3 of each split (`holdout_mask`).
pub const SPLITS: [usize; 3] = [2, 1, 0];

/// The blocks a split holds out, in words (its verdicts): `holdout_mask` of ten samples, one
/// per block.
pub fn split_blocks(split: usize) -> String {
    holdout_mask(10, split)
        .iter()
        .enumerate()
        .filter(|(_, &h)| h == HELD_OUT)
        .map(|(b, _)| b.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// One kept finding.
#[derive(Debug, Clone, Default)]
pub struct Finding {
    /// Catalogue name or `unexplained`.
    pub effect: String,
    /// Named fitted parameters.
    pub parameters: Vec<(String, f64)>,
    /// Held-out rss fraction removed, BIC change, and free text.
    pub holdout_rss_drop: f64,
    pub delta_bic: f64,
    pub note: String,
    pub holdout_rel_error_after: f64,
    /// Fraction of the independent segments of the record on which the finding held (see
    /// `STABILITY_SEGMENTS`); 0 for `unexplained`.
    pub consistency: f64,
    /// The catalogue effect of another kind that explains the same residual as well on the
    /// held-out data (within the selection's margin): the record does not tell the two
    /// apart, and the finding is reported as confounded with it, not named.
    pub confounded_with: Option<String>,
}

/// A baseline term with its significance (held-out error when it is dropped).
#[derive(Debug, Clone)]
pub struct BaselineTerm {
    pub effect: String,
    pub value: f64,
    pub unit: String,
    pub holdout_rel_error_without: f64,
    pub significant: bool,
}

/// Everything the diagnosis produced.
#[derive(Debug, Clone, Default)]
pub struct Diagnosis {
    pub n: usize,
    /// The training / held-out split its held-out figures are on (`holdout_mask`; the run the
    /// splits agree on, `runs::diagnose_checked`).
    pub split: usize,
    /// Stated verdicts, reported first: a record the diagnosis cannot use, a baseline that is
    /// not physical (with what it suggests), samples left out at rest.
    pub verdicts: Vec<String>,
    pub derivative_method: String,
    pub baseline_terms: Vec<BaselineTerm>,
    /// Baseline terms the record cannot tell apart (report names, centred correlation of
    /// their columns; `CONFOUNDED_R`): only their combination is identified.
    pub confounded: Vec<(String, String, f64)>,
    pub baseline_holdout_rel_error: f64,
    pub baseline_train_rel_error: f64,
    /// Baseline refitted on the whole record, error on the whole record (comparable with
    /// published figures that fit and evaluate on the same record).
    pub baseline_full_rel_error: f64,
    pub findings: Vec<Finding>,
    pub final_holdout_rel_error: f64,
    pub final_full_rel_error: f64,
    /// Final model: column names and coefficients (fitted on the whole record).
    pub model: Vec<(String, f64)>,
    /// The model after each stage, refitted on the whole record: index 0 the baseline,
    /// index k the baseline with the first k findings (the cross-check evaluates each).
    pub stage_models: Vec<Vec<(String, f64)>>,
    pub effects: Vec<Effect>,
    pub residual: Vec<f64>,
    pub prediction: Vec<f64>,
    pub whiteness: report::Whiteness,
    pub spectrum_peaks: Vec<report::Peak>,
    /// Spectrum of the final residual over position (binned per direction of motion).
    pub position_spectrum: report::PositionSpectrum,
    /// Error of the final model on a second record (cross-test), when given.
    pub cross: Option<CrossCheck>,
    /// Numerical rank of the final model's columns on the whole record (= `model.len()` when
    /// every coefficient is determined by the data).
    pub fit_rank: usize,
    /// Condition number of the final model's design matrix (columns scaled to unit norm).
    pub fit_condition: f64,
}

impl Diagnosis {
    /// The force the model of stage `k` predicts on `rec` (0: the baseline; k: the baseline
    /// with the first k findings' effects), each column with that stage's coefficients
    /// (fitted on the whole diagnosed record); `None` when there is no such stage or `rec`
    /// cannot be evaluated. The cross-check evaluates a second record through it, the plots
    /// the diagnosed one (before: stage 0).
    pub fn stage_prediction(&self, rec: &Record, k: usize) -> Option<Vec<f64>> {
        if k > self.effects.len()
            || self.stage_models.len() != self.effects.len() + 1
            || try_diagnose_shape(rec).is_err()
        {
            return None;
        }
        let ctx = effects::Context::new(rec);
        let cols = effects::build_columns(&ctx, &self.effects[..k]);
        let mut pred = vec![0.0; rec.len()];
        for (name, c) in &cols {
            if let Some((_, th)) = self.stage_models[k].iter().find(|(n, _)| n == name) {
                for (p, v) in pred.iter_mut().zip(c) {
                    *p += th * v;
                }
            }
        }
        Some(pred)
    }

    /// The catalogue names among the findings, in order (`unexplained` and findings confounded
    /// with another effect left out).
    pub fn catalogue_names(&self) -> Vec<&str> {
        self.findings
            .iter()
            .filter(|f| f.effect != "unexplained" && f.confounded_with.is_none())
            .map(|f| f.effect.as_str())
            .collect()
    }
}

#[derive(Debug, Clone)]
pub struct CrossCheck {
    pub baseline_rel_error: f64,
    pub final_rel_error: f64,
    /// Per finding: relative error on the second record with effects up to this one.
    pub after_each: Vec<(String, f64)>,
    /// Per finding: true when it makes the second record's error worse than the stage before.
    pub worsens: Vec<bool>,
}

/// Samples in motion the diagnosis needs at least (training and held-out together).
pub const MIN_MOVING: usize = 200;

/// Run the diagnosis on a record. A record or options it cannot use give a diagnosis with no
/// finding and the reason as its first verdict (never a panic); `try_diagnose` returns it as
/// an error instead.
pub fn diagnose(rec: &Record, opt: &Options) -> Diagnosis {
    match try_diagnose(rec, opt) {
        Ok(d) => d,
        Err(e) => Diagnosis {
            n: rec.len(),
            verdicts: vec![e],
            ..Default::default()
        },
    }
}

/// Check a record and options, then diagnose.
pub fn try_diagnose(rec: &Record, opt: &Options) -> Result<Diagnosis, String> {
    if !(0.0..1.0).contains(&opt.min_holdout_gain) {
        return Err(format!(
            "option min_holdout_gain = {}: allowed range [0, 1)",
            opt.min_holdout_gain
        ));
    }
    if opt.max_effects > EffectKind::all().len() {
        return Err(format!(
            "option max_effects = {}: allowed range 0 ..= {}",
            opt.max_effects,
            EffectKind::all().len()
        ));
    }
    if !(100..=10_000_000).contains(&opt.screen_samples) {
        return Err(format!(
            "option screen_samples = {}: allowed range 100 ..= 10000000",
            opt.screen_samples
        ));
    }
    if opt.screen_window < 100 {
        return Err(format!(
            "option screen_window = {}: allowed range 100 ..= {}",
            opt.screen_window,
            usize::MAX
        ));
    }
    let n = rec.len();
    let lens = [rec.x.len(), rec.f.len(), rec.v.len(), rec.a.len()];
    if n < 3 || lens.iter().any(|&l| l != n) {
        return Err(format!(
            "record: {n} time samples (x {}, f {}, v {}, a {}): at least 3, all columns of equal length",
            lens[0], lens[1], lens[2], lens[3]
        ));
    }
    let finite = |c: &[f64]| c.iter().all(|v| v.is_finite());
    if !(finite(&rec.t) && finite(&rec.x) && finite(&rec.f) && finite(&rec.v) && finite(&rec.a))
        || rec.extra.values().any(|c| c.len() != n || !finite(c))
    {
        return Err("record: a column holds a non-finite value or has a different length".into());
    }
    let dt = rec.dt();
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(format!("record: mean sample period {dt} s is not positive"));
    }
    let rest = effects::at_rest(&rec.x, &rec.v, dt);
    let moving = rest.iter().filter(|r| !**r).count();
    if moving < MIN_MOVING {
        return Err(format!(
            "record: {moving} of {n} samples in motion (the rest at rest or at the ends): at least {MIN_MOVING} are needed; no finding can be stated"
        ));
    }
    // every split the selection may run on must leave enough of the motion on either side
    for split in 0..SPLITS.len() {
        let hold = holdout_mask(n, split);
        let (mut tr_n, mut ho_n) = (0, 0);
        for (h, r) in hold.iter().zip(&rest) {
            if !r {
                if *h == HELD_OUT {
                    ho_n += 1;
                } else {
                    tr_n += 1;
                }
            }
        }
        if tr_n < MIN_MOVING / 2 || ho_n < MIN_MOVING / 4 {
            return Err(format!(
                "record: {tr_n} training and {ho_n} held-out samples in motion (held out: blocks {} of 10): at least {} and {} are needed",
                split_blocks(split),
                MIN_MOVING / 2,
                MIN_MOVING / 4
            ));
        }
    }
    Ok(diagnose_checked(rec, opt, rest))
}

/// The shape checks of `try_diagnose` alone (lengths, finiteness, sample period).
fn try_diagnose_shape(rec: &Record) -> Result<(), String> {
    let n = rec.len();
    let lens = [rec.x.len(), rec.f.len(), rec.v.len(), rec.a.len()];
    let finite = |c: &[f64]| c.iter().all(|v| v.is_finite());
    if n < 3
        || lens.iter().any(|&l| l != n)
        || !(finite(&rec.t) && finite(&rec.x) && finite(&rec.f) && finite(&rec.v) && finite(&rec.a))
        || rec.extra.values().any(|c| c.len() != n || !finite(c))
    {
        return Err(
            "record: fewer than 3 samples, columns of different lengths or non-finite values"
                .into(),
        );
    }
    Ok(())
}

#[cfg(test)]
mod stribeck_band_tests;
#[cfg(test)]
mod tests;
