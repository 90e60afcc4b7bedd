//! Built-in procedural spine phantom (interface; the generator is not written yet).

use super::{LabelMap, Volume};

/// Settings of the procedural phantom.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhantomSpec {
    /// Seed of every random choice (same seed, same phantom, bit for bit).
    pub seed: u64,
    /// Voxel counts `[x, y, z]`.
    pub dims: [usize; 3],
    /// Voxel size `[x, y, z]` in mm.
    pub spacing: [f64; 3],
    /// Fetal variant (small scale, ossification centres, fluid).
    pub fetal: bool,
}

impl Default for PhantomSpec {
    fn default() -> Self {
        PhantomSpec {
            seed: 0,
            dims: [128, 128, 128],
            spacing: [1.0, 1.0, 1.0],
            fetal: false,
        }
    }
}

/// Generate the phantom: linear attenuation (1/mm) and the label volume beside it.
pub fn generate(_spec: &PhantomSpec) -> crate::error::Result<(Volume<f32>, LabelMap)> {
    Err(crate::error::Error::invalid(
        "phantom",
        "the phantom generator is not implemented yet",
    ))
}
