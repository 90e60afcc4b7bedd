//! Volumes: voxel values with voxel size and voxel-to-world placement, their readers (NIfTI,
//! MetaImage), conversions (HU to attenuation, crop, resample, normalise), the built-in spine
//! phantom and the ultrasound-like proxy.
//!
//! Placement follows TIGRE / NAF: voxel (i, j, k) has its centre at
//! (-sX/2 + (i + 1/2) dX, -sY/2 + (j + 1/2) dY, -sZ/2 + (k + 1/2) dZ) + offOrigin,
//! with sX = nX dX. Values are stored x fastest (index i + nx (j + ny k)), as NIfTI does.

pub mod attenuation;
pub mod metaimage;
pub mod nifti;
pub mod phantom;
pub mod resample;
pub mod ultrasound;

use crate::real::Real;

/// Where a volume came from (kept in dataset manifests).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// Source file, or `phantom` for the built-in generator.
    pub source: String,
    /// The file's own voxel-to-world affine (NIfTI sform/qform, MetaImage Offset/TransformMatrix),
    /// row-major 4x4, when there is one. Informational: placement uses `spacing` and `offset`.
    pub file_affine: Option<[[f64; 4]; 4]>,
    /// Every transformation applied since loading, in order (human-readable).
    pub steps: Vec<String>,
}

/// A scalar volume.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume<R: Real = f32> {
    /// Voxel values, x fastest: `data[i + nx * (j + ny * k)]`.
    pub data: Vec<R>,
    /// Voxel counts `[x, y, z]` (TIGRE `nVoxel`).
    pub dims: [usize; 3],
    /// Voxel size `[x, y, z]` in mm (TIGRE `dVoxel`).
    pub spacing: [f64; 3],
    /// Offset of the volume centre from the world origin `[x, y, z]` in mm (TIGRE `offOrigin`).
    pub offset: [f64; 3],
    /// Where the values came from.
    pub provenance: Provenance,
}

impl<R: Real> Volume<R> {
    /// A volume of zeros.
    pub fn zeros(dims: [usize; 3], spacing: [f64; 3]) -> Self {
        Volume {
            data: vec![R::zero(); dims[0] * dims[1] * dims[2]],
            dims,
            spacing,
            offset: [0.0; 3],
            provenance: Provenance::default(),
        }
    }

    /// Linear index of voxel (i, j, k).
    #[inline(always)]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Value of voxel (i, j, k).
    #[inline(always)]
    pub fn get(&self, i: usize, j: usize, k: usize) -> R {
        self.data[self.index(i, j, k)]
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when the volume has no voxel.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Physical size `[x, y, z]` in mm.
    pub fn size_mm(&self) -> [f64; 3] {
        [
            self.dims[0] as f64 * self.spacing[0],
            self.dims[1] as f64 * self.spacing[1],
            self.dims[2] as f64 * self.spacing[2],
        ]
    }

    /// World coordinates of the centre of voxel (i, j, k) (fractional indices allowed).
    pub fn voxel_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        crate::geometry::voxel_centre(self.dims, self.spacing, self.offset, ijk)
    }

    /// Fractional voxel index of a world point (inverse of [`Volume::voxel_to_world`]).
    pub fn world_to_voxel(&self, p: [f64; 3]) -> [f64; 3] {
        let mut v = [0.0; 3];
        for a in 0..3 {
            v[a] = (p[a] - self.offset[a] + self.dims[a] as f64 * self.spacing[a] / 2.0)
                / self.spacing[a]
                - 0.5;
        }
        v
    }

    /// Axis-aligned world bounding box (min corner, max corner) of the voxel grid, in mm.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let s = self.size_mm();
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for a in 0..3 {
            lo[a] = self.offset[a] - s[a] / 2.0;
            hi[a] = self.offset[a] + s[a] / 2.0;
        }
        (lo, hi)
    }

    /// The same volume with values converted to another precision.
    pub fn cast<S: Real>(&self) -> Volume<S> {
        Volume {
            data: self.data.iter().map(|&v| S::c(v.f64())).collect(),
            dims: self.dims,
            spacing: self.spacing,
            offset: self.offset,
            provenance: self.provenance.clone(),
        }
    }

    /// Error naming `what` and the first NaN/infinite voxel (i, j, k), if any.
    pub fn check_finite(&self, what: &str) -> crate::error::Result<()> {
        if let Some(idx) = self.data.iter().position(|v| !v.is_finite()) {
            let i = idx % self.dims[0];
            let j = (idx / self.dims[0]) % self.dims[1];
            let k = idx / (self.dims[0] * self.dims[1]);
            return Err(crate::error::Error::NonFinite {
                what: format!("{what} voxel (i, j, k) = ({i}, {j}, {k})"),
                index: idx,
                value: self.data[idx].f64(),
            });
        }
        Ok(())
    }
}

/// A label volume (segmentation ids, 0 = background) on the same grid conventions as
/// [`Volume`]: `data[i + nx * (j + ny * k)]`.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelMap {
    pub data: Vec<u16>,
    pub dims: [usize; 3],
    pub spacing: [f64; 3],
    pub offset: [f64; 3],
}

/// Load a scalar volume, choosing the reader from the file name: `.nii`, `.nii.gz` (NIfTI),
/// `.mha`, `.mhd` (MetaImage) or `.npy` ([x, y, z], 1 mm voxels unless a sidecar says otherwise).
/// Values are returned as stored (NIfTI slope/intercept applied); no HU conversion.
pub fn load(path: &std::path::Path) -> crate::error::Result<Volume<f32>> {
    Err(crate::error::Error::format(
        path,
        "file",
        "volume readers are not implemented yet",
    ))
}

/// Load a label volume (NIfTI or MetaImage) and round its values to label ids.
pub fn load_labels(path: &std::path::Path) -> crate::error::Result<LabelMap> {
    Err(crate::error::Error::format(
        path,
        "file",
        "label readers are not implemented yet",
    ))
}
