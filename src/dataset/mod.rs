//! Projection datasets: a geometry, training and test views (angles + projections) and a
//! manifest of units, normalisation and provenance. Stored as a folder (see [`store`]):
//! `dataset.json`, `train.npy`, `test.npy` (f32 [N, v, u], row 0 = top), `volume.npy`
//! ([x, y, z]) and PNG previews.
//!
//! [`store`]: crate::dataset::store

pub mod generate;
pub mod noise;
pub mod pickle;
pub mod pose;
pub mod store;
pub mod targets;

use serde::{Deserialize, Serialize};

use crate::geometry::{Camera, ConeBeam};
use crate::image2d::Image2d;

/// One split: projection angles (radians) and the projections (line integrals) at them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Split {
    pub angles: Vec<f64>,
    pub projections: Vec<Image2d<f32>>,
}

/// What the numbers mean and where they came from (the `dataset.json` manifest minus geometry
/// and angles).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Unit of the projection values, e.g. "mm * volume value" (line integrals in mm).
    pub projection_units: String,
    /// How the volume values were produced (HU conversion, normalisation), human-readable.
    pub volume_normalisation: String,
    /// Provenance of the volume (file, phantom seed, crop, resampling).
    pub provenance: crate::volume::Provenance,
    /// Projector used ("siddon" / "trilinear") and noise settings.
    pub projector: String,
    /// Noise model applied to the projections ("none" or a description).
    pub noise: String,
    /// Free-form extra fields (generator settings).
    #[serde(default)]
    pub extra: serde_json::Map<String, serde_json::Value>,
    /// Pose error of the recorded training cameras ([`pose`]); absent = exact cameras.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_noise: Option<pose::PoseNoise>,
}

/// A projection dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    pub geometry: ConeBeam,
    pub train: Split,
    pub test: Split,
    pub manifest: Manifest,
    /// The ground-truth volume the projections came from (absent for imported pickles that
    /// carry none).
    pub volume: Option<crate::volume::Volume<f32>>,
}

impl Dataset {
    /// Camera of training view `k`, as recorded: perturbed by the dataset's pose noise, if any
    /// (the projections were computed with the exact camera).
    pub fn train_camera(&self, k: usize) -> Camera {
        let cam = self.geometry.camera(self.train.angles[k]);
        match self
            .manifest
            .pose_noise
            .as_ref()
            .and_then(|p| p.views.get(k))
        {
            Some(v) => v.apply(&cam),
            None => cam,
        }
    }
    /// Camera of test view `k`.
    pub fn test_camera(&self, k: usize) -> Camera {
        self.geometry.camera(self.test.angles[k])
    }
    /// Fingerprint of what training and evaluation read: the geometry, each split's angles
    /// and projections (sizes and values), as 16 hex digits
    /// ([`crate::fingerprint::Words`]). Where the dataset is stored does not enter it.
    pub fn fingerprint(&self) -> String {
        let mut h = crate::fingerprint::Words::default();
        h.bytes(
            serde_json::to_string(&self.geometry)
                .expect("the geometry serialises")
                .as_bytes(),
        );
        for split in [&self.train, &self.test] {
            h.f64s(&split.angles);
            for p in &split.projections {
                h.bytes(&(p.width as u64).to_le_bytes())
                    .bytes(&(p.height as u64).to_le_bytes())
                    .f32s(&p.data);
            }
        }
        h.hex()
    }
}
