//! Geometric operations on volumes: crop to the bounding box of label ids, pad, recentre, and
//! trilinear resampling to a target grid. Each appends a line to `provenance.steps`.
//!
//! Placement (TIGRE / NAF, see `volume/mod.rs`): voxel (i, j, k) has its centre at
//! `-n d / 2 + (i + 1/2) d + offset` per axis. Crop and pad keep every kept voxel at its world
//! position by adjusting `offset`; [`recentre`] sets `offset` to 0 when a centred volume is
//! wanted (the TIGRE/NAF datasets put the volume at the origin).
//!
//! Resampling keeps the physical extent `n d` and the offset: the new spacing is
//! `n d / n'`, and new voxel i' samples the old grid at the fractional index
//! `(i' + 1/2) d' / d - 1/2` (voxel centres as TIGRE places them; unlike `scipy.ndimage.zoom`,
//! which aligns the first and last voxel centres instead). Samples beyond the outermost voxel
//! centres take the edge value (no zero fade at the border). Trilinear interpolation, computed
//! in f64; parallel over output z-slices, each slice written by one task: bit-identical for any
//! thread count.

use std::ops::RangeInclusive;

use super::{LabelMap, Volume};
use crate::error::{Error, Result};
use crate::real::Real;

/// A set of label ids: a range (`25..=50`) or a list (`&[29, 30]`).
pub trait LabelIds: Sync {
    /// True when `id` is in the set.
    fn contains_id(&self, id: u16) -> bool;
    /// Human-readable form for messages and provenance.
    fn describe(&self) -> String;
}

impl LabelIds for RangeInclusive<u16> {
    fn contains_id(&self, id: u16) -> bool {
        self.contains(&id)
    }
    fn describe(&self) -> String {
        format!("{}..={}", self.start(), self.end())
    }
}

impl LabelIds for [u16] {
    fn contains_id(&self, id: u16) -> bool {
        self.contains(&id)
    }
    fn describe(&self) -> String {
        format!("{self:?}")
    }
}

impl<const N: usize> LabelIds for [u16; N] {
    fn contains_id(&self, id: u16) -> bool {
        self.contains(&id)
    }
    fn describe(&self) -> String {
        format!("{self:?}")
    }
}

impl LabelIds for Vec<u16> {
    fn contains_id(&self, id: u16) -> bool {
        self.contains(&id)
    }
    fn describe(&self) -> String {
        format!("{self:?}")
    }
}

/// An index box: voxels `lo[a] ..= hi[a]` on each axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct IndexBox {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

impl IndexBox {
    /// Voxel counts of the box.
    pub fn dims(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.hi[a] - self.lo[a] + 1)
    }
}

/// The bounding box of the voxels whose label is in `ids`, grown by `margin_mm` (rounded up to
/// whole voxels per axis) and clamped to the grid. Error naming the ids when none is present.
pub fn label_box(
    labels: &LabelMap,
    ids: &(impl LabelIds + ?Sized),
    margin_mm: f64,
) -> Result<IndexBox> {
    if !(margin_mm.is_finite() && margin_mm >= 0.0) {
        return Err(Error::invalid(
            "margin",
            format!("{margin_mm} mm is not a finite non-negative margin"),
        ));
    }
    let [nx, ny, nz] = labels.dims;
    if labels.data.len() != nx * ny * nz {
        return Err(Error::invalid(
            "labels",
            format!("{} values for dims {:?}", labels.data.len(), labels.dims),
        ));
    }
    // Per-slice boxes in parallel, merged in slice order (min/max: exact).
    use rayon::prelude::*;
    let per_slice: Vec<Option<IndexBox>> = labels
        .data
        .par_chunks(nx * ny)
        .enumerate()
        .map(|(k, s)| {
            let mut b: Option<IndexBox> = None;
            for j in 0..ny {
                for i in 0..nx {
                    if ids.contains_id(s[i + nx * j]) {
                        let p = [i, j, k];
                        b = Some(match b {
                            None => IndexBox { lo: p, hi: p },
                            Some(b) => IndexBox {
                                lo: [0, 1, 2].map(|a| b.lo[a].min(p[a])),
                                hi: [0, 1, 2].map(|a| b.hi[a].max(p[a])),
                            },
                        });
                    }
                }
            }
            b
        })
        .collect();
    let mut bb: Option<IndexBox> = None;
    for b in per_slice.into_iter().flatten() {
        bb = Some(match bb {
            None => b,
            Some(c) => IndexBox {
                lo: [0, 1, 2].map(|a| c.lo[a].min(b.lo[a])),
                hi: [0, 1, 2].map(|a| c.hi[a].max(b.hi[a])),
            },
        });
    }
    let Some(mut b) = bb else {
        return Err(Error::invalid(
            "labels",
            format!("no voxel carries a label id in {}", ids.describe()),
        ));
    };
    for a in 0..3 {
        let m = (margin_mm / labels.spacing[a] - 1e-9).ceil().max(0.0) as usize;
        b.lo[a] = b.lo[a].saturating_sub(m);
        b.hi[a] = (b.hi[a] + m).min(labels.dims[a] - 1);
    }
    Ok(b)
}

/// The offset that keeps voxel `b.lo` of a grid `(dims, spacing, offset)` in place when it
/// becomes voxel 0 of a grid of `new_dims` (works for padding too, with a negative `lo`).
fn shifted_offset(
    dims: [usize; 3],
    spacing: [f64; 3],
    offset: [f64; 3],
    lo: [f64; 3],
    new_dims: [usize; 3],
) -> [f64; 3] {
    [0, 1, 2]
        .map(|a| offset[a] + (lo[a] + (new_dims[a] as f64 - dims[a] as f64) / 2.0) * spacing[a])
}

/// Copy the voxels of `b` out of a grid stored x fastest.
fn copy_box<T: Copy + Send + Sync>(data: &[T], dims: [usize; 3], b: &IndexBox) -> Vec<T> {
    use rayon::prelude::*;
    let [nx, ny, _] = dims;
    let nd = b.dims();
    let mut out = Vec::with_capacity(nd[0] * nd[1] * nd[2]);
    let slices: Vec<Vec<T>> = (b.lo[2]..=b.hi[2])
        .into_par_iter()
        .map(|k| {
            let mut s = Vec::with_capacity(nd[0] * nd[1]);
            for j in b.lo[1]..=b.hi[1] {
                let row = nx * (j + ny * k);
                s.extend_from_slice(&data[row + b.lo[0]..=row + b.hi[0]]);
            }
            s
        })
        .collect();
    for s in slices {
        out.extend_from_slice(&s);
    }
    out
}

fn check_box(dims: [usize; 3], b: &IndexBox) -> Result<()> {
    for a in 0..3 {
        if b.lo[a] > b.hi[a] || b.hi[a] >= dims[a] {
            return Err(Error::invalid(
                "crop box",
                format!("{b:?} does not fit a grid of {dims:?} voxels"),
            ));
        }
    }
    Ok(())
}

/// Crop a volume to the index box `b`; the kept voxels stay at their world positions.
pub fn crop<R: Real>(vol: &Volume<R>, b: &IndexBox) -> Result<Volume<R>> {
    check_box(vol.dims, b)?;
    let nd = b.dims();
    let note = format!(
        "cropped to voxels {:?} ..= {:?} ({nd:?} voxels), world placement kept",
        b.lo, b.hi
    );
    let data = copy_box(&vol.data, vol.dims, b);
    Ok(regridded(vol, data, nd, b.lo.map(|x| x as f64), note))
}

/// `vol`'s voxels re-gridded to `data` on an `nd` grid whose voxel (0, 0, 0) is `vol`'s voxel
/// `lo` (a crop or a pad), at the same world positions and voxel size; `note` is recorded.
fn regridded<R: Real>(
    vol: &Volume<R>,
    data: Vec<R>,
    nd: [usize; 3],
    lo: [f64; 3],
    note: String,
) -> Volume<R> {
    let mut provenance = vol.provenance.clone();
    provenance.steps.push(note);
    Volume {
        data,
        dims: nd,
        spacing: vol.spacing,
        offset: shifted_offset(vol.dims, vol.spacing, vol.offset, lo, nd),
        provenance,
    }
}

/// Crop a label map to the index box `b`; the kept voxels stay at their world positions.
pub fn crop_labels(labels: &LabelMap, b: &IndexBox) -> Result<LabelMap> {
    check_box(labels.dims, b)?;
    let nd = b.dims();
    Ok(LabelMap {
        data: copy_box(&labels.data, labels.dims, b),
        dims: nd,
        spacing: labels.spacing,
        offset: shifted_offset(
            labels.dims,
            labels.spacing,
            labels.offset,
            b.lo.map(|x| x as f64),
            nd,
        ),
    })
}

/// Crop `vol` to the bounding box of the voxels of `labels` whose id is in `ids` (a range such
/// as `25..=50`, or a list), grown by `margin_mm` and clamped to the grid. The labels must lie
/// on the volume's grid (same dims and spacing). The cropped volume keeps its world placement
/// (`offset` set so the kept voxels stay where they were); call [`recentre`] to centre it.
pub fn crop_to_labels<R: Real>(
    vol: &Volume<R>,
    labels: &LabelMap,
    ids: &(impl LabelIds + ?Sized),
    margin_mm: f64,
) -> Result<Volume<R>> {
    let same_spacing =
        (0..3).all(|a| (vol.spacing[a] - labels.spacing[a]).abs() <= 1e-6 * vol.spacing[a]);
    if vol.dims != labels.dims || !same_spacing {
        return Err(Error::invalid(
            "labels",
            format!(
                "label grid {:?} voxels of {:?} mm differs from the volume's {:?} of {:?} mm",
                labels.dims, labels.spacing, vol.dims, vol.spacing
            ),
        ));
    }
    let b = label_box(labels, ids, margin_mm)?;
    let mut out = crop(vol, &b)?;
    if let Some(s) = out.provenance.steps.last_mut() {
        *s = format!(
            "{s}: bounding box of label ids {} plus a {margin_mm} mm margin",
            ids.describe()
        );
    }
    Ok(out)
}

/// Set the offset to 0 (the volume centred on the world origin, as TIGRE/NAF datasets place
/// it), recording the shift.
pub fn recentre<R: Real>(vol: &mut Volume<R>) {
    if vol.offset != [0.0; 3] {
        vol.provenance.steps.push(format!(
            "recentred: offset {:?} mm -> [0, 0, 0]",
            vol.offset
        ));
        vol.offset = [0.0; 3];
    }
}

/// Pad with `before[a]` voxels below and `after[a]` above on each axis, filled with `value`;
/// the existing voxels stay at their world positions.
pub fn pad<R: Real>(vol: &Volume<R>, before: [usize; 3], after: [usize; 3], value: R) -> Volume<R> {
    let [nx, ny, nz] = vol.dims;
    let nd = [0, 1, 2].map(|a| vol.dims[a] + before[a] + after[a]);
    let mut data = vec![value; nd[0] * nd[1] * nd[2]];
    for k in 0..nz {
        for j in 0..ny {
            let src = nx * (j + ny * k);
            let dst = before[0] + nd[0] * ((j + before[1]) + nd[1] * (k + before[2]));
            data[dst..dst + nx].copy_from_slice(&vol.data[src..src + nx]);
        }
    }
    let note = format!(
        "padded with {value}: {before:?} voxels before, {after:?} after ({nd:?} voxels), world \
         placement kept"
    );
    regridded(vol, data, nd, before.map(|b| -(b as f64)), note)
}

/// Pad every axis to the largest physical extent (in whole voxels of that axis), split evenly
/// (an odd voxel goes above), filled with `value` (e.g. -1000 HU): a cube in mm when the
/// spacings divide it, as the R2-Gaussian preparation does before resizing.
pub fn pad_to_cube<R: Real>(vol: &Volume<R>, value: R) -> Volume<R> {
    let size = vol.size_mm();
    let side = size.iter().cloned().fold(0.0, f64::max);
    let mut before = [0; 3];
    let mut after = [0; 3];
    for a in 0..3 {
        let n = ((side / vol.spacing[a]) - 1e-9).ceil() as usize;
        let extra = n.saturating_sub(vol.dims[a]);
        before[a] = extra / 2;
        after[a] = extra - extra / 2;
    }
    pad(vol, before, after, value)
}

/// Trilinear resampling to `dims` voxels over the same physical extent (spacing scaled by
/// `old / new` per axis, offset kept). See the module header for the sample positions.
pub fn resample_trilinear<R: Real>(vol: &Volume<R>, dims: [usize; 3]) -> Result<Volume<R>> {
    use rayon::prelude::*;
    if dims.contains(&0) || vol.dims.contains(&0) {
        return Err(Error::invalid(
            "dims",
            format!("cannot resample {:?} voxels to {dims:?}", vol.dims),
        ));
    }
    let [nx, ny, nz] = vol.dims;
    let spacing = [0, 1, 2].map(|a| vol.spacing[a] * vol.dims[a] as f64 / dims[a] as f64);
    // Per axis: for each new index, the two old indices and the weight of the upper one.
    let taps = |a: usize| -> Vec<(usize, usize, f64)> {
        let n = vol.dims[a];
        (0..dims[a])
            .map(|i| {
                let f = (i as f64 + 0.5) * spacing[a] / vol.spacing[a] - 0.5;
                let f = f.clamp(0.0, (n - 1) as f64);
                let i0 = (f.floor() as usize).min(n - 1);
                let i1 = (i0 + 1).min(n - 1);
                (i0, i1, f - i0 as f64)
            })
            .collect()
    };
    let (tx, ty, tz) = (taps(0), taps(1), taps(2));
    let src = &vol.data;
    let at = |i: usize, j: usize, k: usize| src[i + nx * (j + ny * k)].f64();
    let _ = nz;
    let mut data = vec![R::zero(); dims[0] * dims[1] * dims[2]];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slice)| {
            let (k0, k1, wz) = tz[k];
            for (j, &(j0, j1, wy)) in ty.iter().enumerate() {
                for (i, &(i0, i1, wx)) in tx.iter().enumerate() {
                    let c00 = at(i0, j0, k0) * (1.0 - wx) + at(i1, j0, k0) * wx;
                    let c10 = at(i0, j1, k0) * (1.0 - wx) + at(i1, j1, k0) * wx;
                    let c01 = at(i0, j0, k1) * (1.0 - wx) + at(i1, j0, k1) * wx;
                    let c11 = at(i0, j1, k1) * (1.0 - wx) + at(i1, j1, k1) * wx;
                    let c0 = c00 * (1.0 - wy) + c10 * wy;
                    let c1 = c01 * (1.0 - wy) + c11 * wy;
                    slice[i + dims[0] * j] = R::c(c0 * (1.0 - wz) + c1 * wz);
                }
            }
        });
    let mut provenance = vol.provenance.clone();
    provenance.steps.push(format!(
        "trilinear resample {:?} -> {dims:?} voxels, spacing {:?} -> {spacing:?} mm (extent \
         kept, TIGRE voxel centres, edge values beyond the outer centres)",
        vol.dims, vol.spacing
    ));
    Ok(Volume {
        data,
        dims,
        spacing,
        offset: vol.offset,
        provenance,
    })
}

/// Trilinear resampling to voxels of about `spacing` mm (e.g. isotropic `[1.0; 3]`): the new
/// voxel counts are `round(n d / spacing)` (at least 1) and, as in [`resample_trilinear`], the
/// physical extent is kept, so the final spacing is `n d / n'`, within half a voxel of the
/// request over the whole extent.
pub fn resample_to_spacing<R: Real>(vol: &Volume<R>, spacing: [f64; 3]) -> Result<Volume<R>> {
    if spacing.iter().any(|&s| !(s.is_finite() && s > 0.0)) {
        return Err(Error::invalid(
            "spacing",
            format!("{spacing:?} mm is not a positive finite voxel size"),
        ));
    }
    let size = vol.size_mm();
    let dims = [0, 1, 2].map(|a| ((size[a] / spacing[a]).round() as usize).max(1));
    resample_trilinear(vol, dims)
}
