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
pub mod npy;
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

/// Load a scalar volume, choosing the reader from the file name: `.nii`, `.nii.gz` (NIfTI-1),
/// `.mha`, `.mhd` (MetaImage) or `.npy` (a 3-D array indexed `[x, y, z]`, f32/f64/u8/i16,
/// 1 mm voxels).
///
/// Conventions (see paper_notes.md):
/// - the file's array index (i, j, k) is our voxel (x, y, z) as is (x fastest); the file's own
///   voxel-to-world affine (NIfTI sform/qform, MetaImage Offset/TransformMatrix) is recorded in
///   [`Provenance::file_affine`] but not applied;
/// - `offset` is 0: the volume is centred on the world origin (TIGRE/NAF placement);
/// - values are returned as stored (NIfTI scl_slope/scl_inter applied); no HU conversion;
/// - NaN or infinite voxels are *not* an error here (files may legitimately hold them, e.g.
///   outside a reconstruction's field of view): callers that need finite values call
///   [`Volume::check_finite`], which names the first bad voxel.
///
/// `provenance.source` is the path as given; `provenance.steps` records what the reader did.
pub fn load(path: &std::path::Path) -> crate::error::Result<Volume<f32>> {
    match format_of(path)? {
        Format::Nifti => nifti::read(path),
        Format::MetaImage => metaimage::read(path),
        Format::Npy => npy::read_volume(path),
    }
}

/// Load a label volume (NIfTI or MetaImage) and round its values to label ids. A value that is
/// negative, above 65535 or not finite is an error naming the file and the voxel.
pub fn load_labels(path: &std::path::Path) -> crate::error::Result<LabelMap> {
    let vol = match format_of(path)? {
        Format::Nifti => nifti::read(path)?,
        Format::MetaImage => metaimage::read(path)?,
        Format::Npy => {
            return Err(crate::error::Error::format(
                path,
                "file name",
                "label volumes are read from NIfTI (.nii, .nii.gz) or MetaImage (.mha, .mhd)",
            ))
        }
    };
    let mut data = Vec::with_capacity(vol.data.len());
    for (idx, &v) in vol.data.iter().enumerate() {
        let r = (v as f64).round();
        if !(v.is_finite() && (0.0..=65535.0).contains(&r)) {
            let i = idx % vol.dims[0];
            let j = (idx / vol.dims[0]) % vol.dims[1];
            let k = idx / (vol.dims[0] * vol.dims[1]);
            return Err(crate::error::Error::format(
                path,
                "data",
                format!(
                    "label voxel (i, j, k) = ({i}, {j}, {k}) holds {v}, which is not a label id \
                     (ids are finite values in [0, 65535])"
                ),
            ));
        }
        data.push(r as u16);
    }
    Ok(LabelMap {
        data,
        dims: vol.dims,
        spacing: vol.spacing,
        offset: vol.offset,
    })
}

/// The file formats [`load`] knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Nifti,
    MetaImage,
    Npy,
}

/// The format of `path` from its file name (case-insensitive extension).
fn format_of(path: &std::path::Path) -> crate::error::Result<Format> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        Ok(Format::Nifti)
    } else if name.ends_with(".mha") || name.ends_with(".mhd") {
        Ok(Format::MetaImage)
    } else if name.ends_with(".npy") {
        Ok(Format::Npy)
    } else {
        Err(crate::error::Error::format(
            path,
            "file name",
            "unknown volume format: expected .nii, .nii.gz, .mha, .mhd or .npy",
        ))
    }
}

/// Open `path` for reading, refusing anything but a regular file once symlinks are followed
/// (a device such as `/dev/zero` or `/dev/urandom`, a FIFO or a directory has no length to check
/// sizes against). Returns the file and its length in bytes.
pub(crate) fn open_regular(path: &std::path::Path) -> crate::error::Result<(std::fs::File, u64)> {
    let file = std::fs::File::open(path).map_err(|e| crate::error::Error::io(path, e))?;
    let meta = file
        .metadata()
        .map_err(|e| crate::error::Error::io(path, e))?;
    if !meta.is_file() {
        return Err(crate::error::Error::format(
            path,
            "file",
            format!(
                "not a regular file ({}): only regular files are read",
                if meta.is_dir() {
                    "a directory"
                } else {
                    "a device, FIFO or socket"
                }
            ),
        ));
    }
    Ok((file, meta.len()))
}

/// Read a whole regular file (see [`open_regular`]), naming it in the error.
pub(crate) fn read_bytes(path: &std::path::Path) -> crate::error::Result<Vec<u8>> {
    use std::io::Read;
    let (file, len) = open_regular(path)?;
    let cap = usize::try_from(len).map_err(|_| {
        crate::error::Error::format(
            path,
            "file",
            format!("{len} bytes exceed the address space"),
        )
    })?;
    let mut out = Vec::new();
    out.try_reserve_exact(cap).map_err(|_| {
        crate::error::Error::format(path, "file", format!("cannot hold {len} bytes in memory"))
    })?;
    // `take`: a file that grows while it is read cannot make us read past its length.
    file.take(len)
        .read_to_end(&mut out)
        .map_err(|e| crate::error::Error::io(path, e))?;
    Ok(out)
}

/// Scalar element types shared by the readers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Elem {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Elem {
    /// Bytes per element.
    pub(crate) fn size(self) -> usize {
        match self {
            Elem::U8 | Elem::I8 => 1,
            Elem::U16 | Elem::I16 => 2,
            Elem::U32 | Elem::I32 | Elem::F32 => 4,
            Elem::U64 | Elem::I64 | Elem::F64 => 8,
        }
    }
    /// Short name (numpy-like) for provenance and messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Elem::U8 => "uint8",
            Elem::I8 => "int8",
            Elem::U16 => "uint16",
            Elem::I16 => "int16",
            Elem::U32 => "uint32",
            Elem::I32 => "int32",
            Elem::U64 => "uint64",
            Elem::I64 => "int64",
            Elem::F32 => "float32",
            Elem::F64 => "float64",
        }
    }
}

/// Check a voxel grid: every voxel count at least 1 and every voxel size finite and > 0 mm,
/// errors naming `{prefix}dims[a]` or `{prefix}spacing[a]`. Returns the number of voxels, or
/// `None` when it overflows `usize`.
pub(crate) fn check_grid(
    prefix: &str,
    dims: [usize; 3],
    spacing: [f64; 3],
) -> crate::error::Result<Option<usize>> {
    for a in 0..3 {
        if dims[a] == 0 {
            return Err(crate::error::Error::invalid(
                format!("{prefix}dims[{a}]"),
                "voxel count must be at least 1",
            ));
        }
        let d = spacing[a];
        if !d.is_finite() || d <= 0.0 {
            return Err(crate::error::Error::invalid(
                format!("{prefix}spacing[{a}]"),
                format!("voxel size must be finite and > 0 mm, got {d}"),
            ));
        }
    }
    Ok(dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)))
}

/// A volume read from the file `path`, centred (offset 0). The file's own affine is recorded in
/// the provenance, not applied, when all its entries are finite, and dropped with a note
/// otherwise (placement never uses it). `from` says where the affine came from and `unit` its
/// unit when the notes should name it; `steps` are the reader's notes so far.
pub(crate) fn from_file(
    path: &std::path::Path,
    data: Vec<f32>,
    dims: [usize; 3],
    spacing: [f64; 3],
    affine: [[f64; 4]; 4],
    (from, unit): (&str, Option<&str>),
    mut steps: Vec<String>,
) -> Volume<f32> {
    let file_affine = if affine.iter().flatten().all(|v| v.is_finite()) {
        let unit = unit.map(|u| format!(", in {u}")).unwrap_or_default();
        steps.push(format!(
            "file affine from {from}{unit}; recorded, not applied"
        ));
        Some(affine)
    } else {
        let unit = unit.map(|u| format!("in {u}: ")).unwrap_or_default();
        steps.push(format!(
            "file affine from {from} has a NaN or infinite entry ({unit}{affine:?}); dropped (it \
             is informational only: placement never uses it)"
        ));
        None
    };
    Volume {
        data,
        dims,
        spacing,
        offset: [0.0; 3],
        provenance: Provenance {
            source: path.display().to_string(),
            file_affine,
            steps,
        },
    }
}

/// Decode `bytes` (exactly `n * elem.size()` of them) to f32, applying `v * slope + inter` in f64
/// when `scale` is given. Each voxel is converted on its own (the same operations on every
/// path), so the result does not depend on how the blocks are spread over threads; the
/// byte order and the scaling are chosen once per block, so the loops vectorise.
pub(crate) fn decode(
    bytes: &[u8],
    elem: Elem,
    big_endian: bool,
    scale: Option<(f64, f64)>,
) -> Vec<f32> {
    use rayon::prelude::*;
    const BLOCK: usize = 1 << 16;
    macro_rules! dec {
        ($t:ty, $n:expr) => {{
            let mut out = vec![0.0f32; bytes.len() / $n];
            out.par_chunks_mut(BLOCK)
                .zip(bytes.par_chunks(BLOCK * $n))
                .for_each(|(o, b)| {
                    let words = b.chunks_exact($n).map(|c| {
                        let mut a = [0u8; $n];
                        a.copy_from_slice(c);
                        a
                    });
                    let pairs = o.iter_mut().zip(words);
                    match (big_endian, scale) {
                        (false, None) => {
                            pairs.for_each(|(o, a)| *o = <$t>::from_le_bytes(a) as f32)
                        }
                        (true, None) => pairs.for_each(|(o, a)| *o = <$t>::from_be_bytes(a) as f32),
                        (false, Some((s, i))) => pairs
                            .for_each(|(o, a)| *o = (<$t>::from_le_bytes(a) as f64 * s + i) as f32),
                        (true, Some((s, i))) => pairs
                            .for_each(|(o, a)| *o = (<$t>::from_be_bytes(a) as f64 * s + i) as f32),
                    }
                });
            out
        }};
    }
    match elem {
        Elem::U8 => dec!(u8, 1),
        Elem::I8 => dec!(i8, 1),
        Elem::U16 => dec!(u16, 2),
        Elem::I16 => dec!(i16, 2),
        Elem::U32 => dec!(u32, 4),
        Elem::I32 => dec!(i32, 4),
        Elem::U64 => dec!(u64, 8),
        Elem::I64 => dec!(i64, 8),
        Elem::F32 => dec!(f32, 4),
        Elem::F64 => dec!(f64, 8),
    }
}

/// `n0 * n1 * n2 * size` with overflow reported as a format error of `field`.
pub(crate) fn byte_count(
    path: &std::path::Path,
    field: &str,
    dims: [usize; 3],
    size: usize,
) -> crate::error::Result<usize> {
    dims.iter()
        .try_fold(size, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| {
            crate::error::Error::format(
                path,
                field,
                format!("{dims:?} voxels of {size} bytes overflow the address space"),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The provenance notes of both readers, word for word as before they shared [`from_file`]:
    /// NIfTI names the unit, MetaImage does not; a non-finite affine is dropped.
    #[test]
    fn file_affine_notes() {
        let p = std::path::Path::new("v.nii");
        let read = |a, from| from_file(p, vec![0.0], [1; 3], [1.0; 3], a, from, vec![]);
        let mut a = [[0.0; 4]; 4];
        let v = read(a, ("sform", Some("mm")));
        assert_eq!(v.provenance.file_affine, Some(a));
        assert_eq!(
            v.provenance.steps,
            ["file affine from sform, in mm; recorded, not applied"]
        );
        assert_eq!(
            (v.offset, v.provenance.source.as_str()),
            ([0.0; 3], "v.nii")
        );
        a[0][3] = f64::NAN;
        let v = read(a, ("sform", Some("mm")));
        assert_eq!(v.provenance.file_affine, None);
        let dropped = "dropped (it is informational only: placement never uses it)";
        assert_eq!(
            v.provenance.steps,
            [format!(
                "file affine from sform has a NaN or infinite entry (in mm: {a:?}); {dropped}"
            )]
        );
        let v = read(a, ("Offset and TransformMatrix", None));
        assert_eq!(
            v.provenance.steps,
            [format!(
                "file affine from Offset and TransformMatrix has a NaN or infinite entry \
                 ({a:?}); {dropped}"
            )]
        );
    }

    /// Every element type, both byte orders, with and without scaling, over more than two
    /// blocks of voxels: each value is the typed value it was encoded from (converted to f32,
    /// or scaled in f64 then converted), checked value by value.
    #[test]
    fn decode_gives_each_encoded_value_back() {
        macro_rules! check {
            ($t:ty, $elem:expr) => {{
                let n = 2 * (1 << 16) + 3;
                // Values spread over the middle half of the type's range (negative where the
                // type allows; a finite span for the float types too).
                let (lo, hi) = (<$t>::MIN as f64 / 2.0, <$t>::MAX as f64 / 2.0);
                let vals: Vec<$t> = (0..n)
                    .map(|k| (lo + (k as f64 * 0.618_034).fract() * (hi - lo)) as $t)
                    .collect();
                assert!(vals.iter().all(|v| (*v as f64).is_finite()));
                for big in [false, true] {
                    let bytes: Vec<u8> = vals
                        .iter()
                        .flat_map(|v| {
                            if big {
                                v.to_be_bytes()
                            } else {
                                v.to_le_bytes()
                            }
                        })
                        .collect();
                    for scale in [None, Some((0.5, -1024.0))] {
                        let got = decode(&bytes, $elem, big, scale);
                        assert_eq!(got.len(), n);
                        for (k, (&g, &v)) in got.iter().zip(&vals).enumerate() {
                            let want = match scale {
                                None => v as f32,
                                Some((s, i)) => (v as f64 * s + i) as f32,
                            };
                            assert_eq!(
                                g.to_bits(),
                                want.to_bits(),
                                "{} voxel {k}, big endian {big}, scale {scale:?}",
                                stringify!($t)
                            );
                        }
                    }
                }
            }};
        }
        check!(u8, Elem::U8);
        check!(i8, Elem::I8);
        check!(u16, Elem::U16);
        check!(i16, Elem::I16);
        check!(u32, Elem::U32);
        check!(i32, Elem::I32);
        check!(u64, Elem::U64);
        check!(i64, Elem::I64);
        check!(f32, Elem::F32);
        check!(f64, Elem::F64);
    }
}
