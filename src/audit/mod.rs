//! Numerical audits: gradient checks against central finite differences ([`gradcheck`] for the
//! rasterizer, [`field`] for the neural-field baselines); the benchmarks live in
//! [`crate::bench`]. A gradient check of any stage reports [`Row`]s (stage, case,
//! variant, parameter group, errors), so a new stage adds its rows to the same table: write a
//! `rows` function like [`gradcheck::rows`] and print it with the others in `unispine gradcheck`.
//!
//! [`gradcheck`]: crate::audit::gradcheck
//! [`field`]: crate::audit::field
//! [`Row`]: crate::audit::Row
//! [`gradcheck::rows`]: crate::audit::gradcheck::rows

pub mod field;
pub mod gradcheck;

/// Relative error tolerance of every gradient check.
pub const TOLERANCE: f64 = 1e-6;

/// One line of a gradient check: the analytic gradient of one parameter group against central
/// finite differences (f64).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Row {
    /// Pipeline stage checked (e.g. `render`).
    pub stage: &'static str,
    /// Scene or input case.
    pub case: String,
    /// Variant of the stage (e.g. the colour mode).
    pub variant: String,
    /// Parameter group.
    pub group: &'static str,
    /// max |FD| (the gradient's scale).
    pub scale: f64,
    /// max |analytic - FD|.
    pub max_abs: f64,
    /// max |analytic - FD| / max |FD| ([`crate::math::fd::rel_err_maxabs`]).
    pub rel: f64,
}

impl Row {
    /// Whether the relative error is within [`TOLERANCE`] (false for NaN).
    pub fn passes(&self) -> bool {
        self.rel <= TOLERANCE
    }
}

/// The largest relative error of `rows` (NaN if any is NaN, 0 for none).
pub fn worst(rows: &[Row]) -> f64 {
    rows.iter().fold(0.0, |w: f64, r| {
        if r.rel.is_nan() || w.is_nan() {
            f64::NAN
        } else {
            w.max(r.rel)
        }
    })
}
