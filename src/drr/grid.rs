//! The voxel grid as the projectors see it: its placement, the checks of a volume against a
//! geometry, and the clipping of a line or a ray to the grid's box.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::{Camera, ConeBeam, Mode};
use crate::real::Real;
use crate::simd::Simd;
use crate::volume::Volume;

/// Relative tolerance when comparing the geometry's `dVoxel` / `offOrigin` with the volume's
/// `spacing` / `offset` (the two usually come from different files, one of them JSON text).
pub const GRID_REL_TOL: f64 = 1e-6;

/// The voxel grid as the ray-marchers see it.
pub(crate) struct Grid<'a, R: Real> {
    /// Voxel values, x fastest.
    pub data: &'a [R],
    /// Voxel counts `[x, y, z]`.
    pub n: [usize; 3],
    /// Voxel size `[x, y, z]`, mm.
    pub s: [f64; 3],
    /// Box corners (world, mm).
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

impl<'a, R: Real> Grid<'a, R> {
    pub(super) fn new(vol: &'a Volume<R>) -> Self {
        let (lo, hi) = vol.bounds();
        Grid {
            data: &vol.data,
            n: vol.dims,
            s: vol.spacing,
            lo,
            hi,
        }
    }

    /// The grid of `data` with `n` voxels of 1 mm from the origin.
    #[cfg(test)]
    pub(super) fn unit(data: &'a [R], n: [usize; 3]) -> Self {
        Grid {
            data,
            n,
            s: [1.0; 3],
            lo: [0.0; 3],
            hi: n.map(|v| v as f64),
        }
    }
}

/// Voxel counts in `1..=max` per axis and values for them: both signs, zeros of both signs and
/// tiny ones (products that underflow).
#[cfg(test)]
pub(super) fn random_values<R: Real>(rng: &mut impl rand::Rng, max: usize) -> ([usize; 3], Vec<R>) {
    use rand::RngExt;
    let n = [0; 3].map(|_| rng.random_range(1..=max));
    let data = (0..n[0] * n[1] * n[2])
        .map(|_| match rng.random_range(0..6) {
            0 => R::c(0.0),
            1 => R::c(-0.0),
            2 => R::c(rng.random_range(-1e-38..1e-38)),
            _ => R::c(rng.random_range(-3.0..3.0)),
        })
        .collect();
    (n, data)
}

/// Parameter interval `(t_near, t_far)` of the line `o + t d` inside the box `[lo, hi]` (slab
/// test). The interval is empty when `t_far <= t_near`. For a direction component that is
/// exactly 0 the line is inside the slab when `lo <= o < hi` (half-open, as voxel indices are).
#[inline]
pub(crate) fn clip_line(o: [f64; 3], d: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> (f64, f64) {
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        if d[a] == 0.0 {
            if !(o[a] >= lo[a] && o[a] < hi[a]) {
                return (f64::INFINITY, f64::NEG_INFINITY);
            }
        } else {
            let inv = 1.0 / d[a];
            let (ta, tb) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
            let (ta, tb) = if ta <= tb { (ta, tb) } else { (tb, ta) };
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
    }
    (t0, t1)
}

/// The part of the ray of `cam` (origin `o`, unit direction `d`) inside `[lo, hi]`: the whole
/// line for a parallel beam, the half-line beyond the source for a cone beam.
#[inline]
pub(crate) fn clip_ray(
    cam: &Camera,
    o: [f64; 3],
    d: [f64; 3],
    lo: [f64; 3],
    hi: [f64; 3],
) -> Option<(f64, f64)> {
    let (mut t0, t1) = clip_line(o, d, lo, hi);
    if cam.mode == Mode::Cone {
        t0 = t0.max(0.0);
    }
    (t1 > t0).then_some((t0, t1))
}

/// `geo`'s grid fields must describe `vol`'s grid.
pub(super) fn check_grid<R: Real>(vol: &Volume<R>, geo: &ConeBeam) -> Result<()> {
    if geo.n_voxel != vol.dims {
        return Err(Error::invalid(
            "nVoxel",
            format!(
                "the geometry says {:?} but the volume has {:?} voxels [x, y, z]",
                geo.n_voxel, vol.dims
            ),
        ));
    }
    if vol.data.len() != vol.dims.iter().product::<usize>() {
        return Err(Error::invalid(
            "volume",
            format!("{} values for dims {:?}", vol.data.len(), vol.dims),
        ));
    }
    for a in 0..3 {
        let (g, v) = (geo.d_voxel[a], vol.spacing[a]);
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                format!("volume spacing[{a}]"),
                format!("must be finite and > 0, got {v}"),
            ));
        }
        if (g - v).abs() > GRID_REL_TOL * v {
            return Err(Error::invalid(
                format!("dVoxel[{a}]"),
                format!("the geometry says {g} mm but the volume's voxel size is {v} mm"),
            ));
        }
        let (g, v) = (geo.off_origin[a], vol.offset[a]);
        let scale = vol.dims[a] as f64 * vol.spacing[a];
        if !v.is_finite() || (g - v).abs() > GRID_REL_TOL * scale {
            return Err(Error::invalid(
                format!("offOrigin[{a}]"),
                format!("the geometry says {g} mm but the volume's offset is {v} mm"),
            ));
        }
    }
    Ok(())
}

/// Error naming the first NaN / infinite voxel; the scan is parallel over fixed chunks and the
/// first bad chunk is found in order, so the voxel named does not depend on the thread count.
pub(super) fn check_finite_par<R: Real>(vol: &Volume<R>) -> Result<()> {
    const C: usize = 1 << 16;
    let bad = vol
        .data
        .par_chunks(C)
        .position_first(|c| c.iter().any(|v| !v.is_finite()));
    match bad {
        None => Ok(()),
        Some(_) => vol.check_finite("volume"),
    }
}

/// The grid and output band as f32 when the vector kernels can run them: an f32 volume of fewer
/// than 2^31 voxels (i32 lane indices) and a vector path.
pub(super) fn lanes_f32<'g, 'o, R: Real>(
    simd: Simd,
    grid: &Grid<'g, R>,
    out: &'o mut [R],
) -> Option<(Grid<'g, f32>, &'o mut [f32])> {
    let data = lane_data(simd, grid.data)?;
    // SAFETY: R is f32 (`lane_data` checked it): same size, alignment and bits.
    let out = unsafe { std::slice::from_raw_parts_mut(out.as_mut_ptr().cast::<f32>(), out.len()) };
    Some((
        Grid {
            data,
            n: grid.n,
            s: grid.s,
            lo: grid.lo,
            hi: grid.hi,
        },
        out,
    ))
}

/// The voxel values as f32 when the vector kernels can run them: `simd` is a vector path, the
/// values are f32 and fewer than 2^31 (i32 lane indices).
pub(super) fn lane_data<R: Real>(simd: Simd, data: &[R]) -> Option<&[f32]> {
    if simd == Simd::Scalar
        || std::any::TypeId::of::<R>() != std::any::TypeId::of::<f32>()
        || data.len() >= 1 << 31
    {
        return None;
    }
    // SAFETY: R is f32 (checked above): same size, alignment and bits.
    Some(unsafe { std::slice::from_raw_parts(data.as_ptr().cast::<f32>(), data.len()) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_line_slab() {
        let (t0, t1) = clip_line([-5.0, 0.5, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert_eq!((t0, t1), (5.0, 6.0));
        // On the upper face (half-open): outside.
        let (t0, t1) = clip_line([-5.0, 1.0, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert!(t1 <= t0);
        // On the lower face: inside.
        let (t0, t1) = clip_line([-5.0, 0.0, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert!(t1 > t0);
        // Parallel to x and y, inside both slabs, outside the z one (either side): empty.
        for z in [-0.5, 1.0, 1.5] {
            let (t0, t1) = clip_line([0.5, 0.5, z], [0.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
            assert!(t1 <= t0, "z = {z}");
        }
        // Parallel to z, inside the x slab at its lower face, outside the y slab: empty.
        let (t0, t1) = clip_line([0.0, 1.0, -3.0], [0.0, 0.0, 1.0], [0.0; 3], [1.0; 3]);
        assert!(t1 <= t0);
    }

    /// The geometry's grid fields against the volume's, each at a tolerance it must pass and
    /// one it must fail: dVoxel relative to the voxel size (1e-6), offOrigin relative to the
    /// extent (1e-6 x 100 voxels x 2 mm = 2e-4 mm); a voxel size that is zero, negative or not
    /// finite is named.
    #[test]
    fn check_grid_tolerances_and_spacing() {
        let vol = Volume::<f32>::zeros([100, 3, 2], [2.0, 1.0, 1.0]);
        let geo = ConeBeam::centred([4, 4], [1.0, 1.0], vol.dims, vol.spacing);
        let field = |g: &ConeBeam, v: &Volume<f32>| match check_grid(v, g) {
            Ok(()) => String::new(),
            Err(e) => e.to_string(),
        };
        assert_eq!(field(&geo, &vol), "");
        for (dv, ok) in [(1.5e-6, true), (2.5e-6, false)] {
            let mut g = geo.clone();
            g.d_voxel[0] += dv;
            let e = field(&g, &vol);
            assert_eq!(e.is_empty(), ok, "dVoxel off by {dv}: {e}");
            assert!(ok || e.contains("dVoxel[0]"), "{e}");
        }
        for (d, ok) in [(1.5e-4, true), (-1.5e-4, true), (2.5e-4, false)] {
            let mut g = geo.clone();
            g.off_origin[0] += d;
            let e = field(&g, &vol);
            assert_eq!(e.is_empty(), ok, "offOrigin off by {d}: {e}");
            assert!(ok || e.contains("offOrigin[0]"), "{e}");
        }
        for bad in [0.0, -1.0, f64::INFINITY, f64::NAN] {
            let mut v = vol.clone();
            v.spacing[1] = bad;
            let mut g = geo.clone();
            g.d_voxel[1] = bad;
            let e = field(&g, &v);
            assert!(e.contains("volume spacing[1]"), "spacing {bad}: {e}");
        }
    }

    /// A volume with no finite voxel at all is refused (the parallel scan finds the chunk that
    /// holds a non-finite value, not one that holds a finite one), as is a single NaN in the
    /// second chunk, named by its voxel.
    #[test]
    fn non_finite_voxels_are_found_by_the_parallel_scan() {
        let mut vol = Volume::<f32>::zeros([256, 256, 3], [1.0; 3]);
        assert!(check_finite_par(&vol).is_ok());
        vol.data.iter_mut().for_each(|v| *v = f32::NAN);
        assert!(check_finite_par(&vol).is_err());
        let mut vol = Volume::<f32>::zeros([256, 256, 3], [1.0; 3]);
        let idx = (1 << 16) + 5 * 256 + 7;
        vol.data[idx] = f32::INFINITY;
        let e = check_finite_par(&vol).unwrap_err().to_string();
        assert!(e.contains("(7, 5, 1)"), "{e}");
    }

    /// The vector kernels take every f32 grid on a vector path (their speed is the point of
    /// them; the per-ray loop would give the same bits), never an f64 one or the scalar path.
    #[test]
    fn vector_paths_take_f32_grids() {
        let data = [0.5f32; 8];
        for simd in [Simd::Avx2, Simd::Avx512] {
            assert_eq!(
                lane_data(simd, &data).map(<[f32]>::len),
                Some(8),
                "{simd:?}"
            );
            let mut out = [0.0f32; 4];
            let grid = Grid::unit(&data, [2, 2, 2]);
            let (g, o) = lanes_f32(simd, &grid, &mut out).expect("an f32 grid");
            assert_eq!(
                (g.data.len(), g.n, g.s, g.lo, g.hi),
                (8, [2; 3], [1.0; 3], [0.0; 3], [2.0; 3])
            );
            assert_eq!(o.len(), 4);
            assert!(lane_data(simd, &[0.5f64; 8]).is_none(), "{simd:?} f64");
        }
        assert!(lane_data(Simd::Scalar, &data).is_none());
    }

    /// A cone-beam ray starts at its source (t >= 0), a parallel-beam ray is the whole line;
    /// a ray touching the box at one corner only (t_near = t_far) misses it.
    #[test]
    fn clip_ray_cone_from_the_source_parallel_whole_line() {
        let geo = ConeBeam::centred([4, 4], [1.0, 1.0], [2, 2, 2], [1.0; 3]);
        let mut cam = geo.camera(0.0);
        let (lo, hi) = ([0.0; 3], [2.0; 3]);
        // A source inside the box, looking along +x.
        let (o, d) = ([0.5, 1.0, 1.0], [1.0, 0.0, 0.0]);
        cam.mode = Mode::Cone;
        assert_eq!(clip_ray(&cam, o, d, lo, hi), Some((0.0, 1.5)));
        cam.mode = Mode::Parallel;
        assert_eq!(clip_ray(&cam, o, d, lo, hi), Some((-0.5, 1.5)));
        // The box behind a cone-beam source: nothing; along the parallel line: all of it.
        let o = [3.0, 1.0, 1.0];
        assert_eq!(clip_ray(&cam, o, d, lo, hi), Some((-3.0, -1.0)));
        cam.mode = Mode::Cone;
        assert_eq!(clip_ray(&cam, o, d, lo, hi), None);
        // Through the corner (2, 2) only: x in [0, 2], y in [2, 4] for t.
        for mode in [Mode::Cone, Mode::Parallel] {
            cam.mode = mode;
            let touch = clip_ray(&cam, [0.0, 4.0, 1.0], [1.0, -1.0, 0.0], lo, hi);
            assert_eq!(touch, None, "{mode:?}");
        }
    }
}
