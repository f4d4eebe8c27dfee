//! The record's signals gathered for screening (the subsample's rows and their signals).

use super::*;

/// The signals effect columns are computed from, at a set of rows of the record: either every
/// sample (`rows` None, slices borrowed from the context) or a gathered subsample for screening
/// (the values are exactly those of the full record at these rows, so screening sees the
/// same columns as the final fit; anything that needs the sample history — lag, resonance
/// filter — is taken from the full record).
pub struct Sig<'s> {
    pub rows: Option<&'s [usize]>,
    pub x: &'s [f64],
    pub v: &'s [f64],
    pub a: &'s [f64],
    pub sgn: &'s [f64],
    pub xn: &'s [f64],
    pub bp: &'s [f64],
}

impl<'s> Sig<'s> {
    /// Every sample of the record.
    pub fn full(ctx: &'s Context) -> Self {
        Sig {
            rows: None,
            x: &ctx.rec.x,
            v: &ctx.rec.v,
            a: &ctx.rec.a,
            sgn: &ctx.sgn,
            xn: &ctx.xn,
            bp: &ctx.base_pred,
        }
    }
    pub(crate) fn len(&self) -> usize {
        self.x.len()
    }
}

/// Gathered copy of the context signals at `rows` (contiguous in memory, so that screening
/// does not miss the cache on every sample of a long record).
pub struct SubSignals {
    pub rows: Vec<usize>,
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    pub sgn: Vec<f64>,
    pub xn: Vec<f64>,
    pub bp: Vec<f64>,
}

impl SubSignals {
    pub fn new(ctx: &Context, rows: Vec<usize>) -> Self {
        let g = |s: &[f64]| rows.iter().map(|&i| s[i]).collect::<Vec<f64>>();
        SubSignals {
            x: g(&ctx.rec.x),
            v: g(&ctx.rec.v),
            a: g(&ctx.rec.a),
            sgn: g(&ctx.sgn),
            xn: g(&ctx.xn),
            bp: g(&ctx.base_pred),
            rows,
        }
    }
    pub fn sig(&self) -> Sig<'_> {
        Sig {
            rows: Some(&self.rows),
            x: &self.x,
            v: &self.v,
            a: &self.a,
            sgn: &self.sgn,
            xn: &self.xn,
            bp: &self.bp,
        }
    }
}
