//! Ultrasound-like (B-mode) proxy volume from a label volume (interface; not written yet).

use super::{LabelMap, Volume};

/// Settings of the ultrasound-like proxy.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UsProxySpec {
    /// Seed of the speckle.
    pub seed: u64,
}

impl Default for UsProxySpec {
    fn default() -> Self {
        UsProxySpec { seed: 0 }
    }
}

/// A B-mode-like scalar volume in [0, 1] on the grid of `labels`.
pub fn proxy(_labels: &LabelMap, _spec: &UsProxySpec) -> crate::error::Result<Volume<f32>> {
    Err(crate::error::Error::invalid(
        "ultrasound",
        "the ultrasound proxy is not implemented yet",
    ))
}
