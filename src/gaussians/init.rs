//! Initialisation: where the first Gaussians are placed. Four rules ([`InitKind`]):
//! `acui` (X-Gaussian's angle-pose cuboid uniform initialisation), `random` (the `3dgs`
//! preset: as many points as ACUI, uniform in the volume box), `unit-cube` (the upstream
//! non-ACUI branch, see below) and `fdk` (points where an FDK reconstruction of the training
//! views is dense, as R2-Gaussian does; [`super::fdk_init`]). Every rule then gives each point
//! the same Gaussian ([`gaussians_at`]): isotropic 3-NN scale, identity rotation, opacity
//! `init.opacity`, intensity `init.intensity`.
//!
//! ACUI (X-Gaussian / UniSpine-GS `scene/dataset_readers.py`, `gaussian_model.py`
//! `create_from_pcd`):
//! - the cuboid is the volume box of the geometry (`nVoxel`, `dVoxel`); per axis the voxel
//!   centres are `linspace(-s, s, n)` with `s = sVoxel/2 - dVoxel/2`, `sVoxel = nVoxel dVoxel`,
//!   and every `interval`-th one is kept (`[::8, ::8, ::8]`), starting at the first centre (so
//!   the grid is not centred: 256 voxels give -127.5 ... 120.5). Upstream ignores `offOrigin`;
//!   we add it, because our projector honours it (identical when it is 0, as in every upstream
//!   config). Point order: x outermost, z innermost (numpy C order of an `ij` meshgrid).
//! - scale: isotropic, `log(sqrt(max(1e-7, mean squared distance to the 3 nearest
//!   neighbours)))` (simple-knn `distCUDA2`; here the exact 3 nearest neighbours from a uniform
//!   spatial grid, see [`knn3_mean_sq`]);
//! - rotation (1, 0, 0, 0); opacity `logit(0.1)`;
//! - features: only the first is non-zero, chosen so the Gaussian's intensity is
//!   `intensity`. Upstream writes the colour through a uint8 PLY and reads 127/255 back, so its
//!   intensity is 0.49804 (f_dc = -0.00695 with X-Gaussian's RIRF); the issue asks for 0.5,
//!   which is our default (`TrainConfig::init_intensity`). For the paper RIRF,
//!   sigmoid(lambda_0 f_0) = i gives f_0 = logit(i) / lambda_0; for X-Gaussian's RIRF and the
//!   SH colour, 0.5 + lambda_0 f_0 = i gives f_0 = (i - 0.5) / lambda_0. Both are 0 for i = 0.5.
//!
//! Random init (3DGS baseline): the same number of points, uniform in the full volume box
//! `[-sVoxel/2, sVoxel/2] + offOrigin`, from `ChaCha8Rng` seeded with the run seed; everything
//! else as ACUI.
//!
//! Unit-cube init: the branch X-Gaussian / UniSpine-GS `scene/dataset_readers.py` take when
//! `cube_pcd_init` is off, itself 3D Gaussian splatting's rule for scenes without SfM points
//! (graphdeco-inria/gaussian-splatting `scene/dataset_readers.py`, `readNerfSyntheticInfo`):
//! `init.points` (upstream 100,000) points uniform in `[-1.3, 1.3)^3` in scene units. The
//! upstream X-ray scene is in millimetres (its `ConeGeometry` keeps TIGRE's mm with scale 1),
//! and so is ours, so the cube is 2.6 mm wide at the world origin (the isocentre: upstream does
//! not shift it, and neither do we, whatever `offOrigin`). Scale, rotation and opacity as ACUI
//! (upstream `create_from_pcd` treats both point clouds alike); `ChaCha8Rng` seeded with the
//! run seed. A cube with no point inside the volume box is an error naming the setting.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::rirf::ColorMode;
use crate::gaussians::rirf::SH_C0;
use crate::gaussians::Gaussians;
use crate::geometry::ConeBeam;
use crate::math::activations::logit;
use crate::par::CHUNK;
use crate::real::Real;

crate::choice! {
/// How the initial positions are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum InitKind {
    /// Grid of voxel centres every `interval` voxels (X-Gaussian ACUI).
    Acui = "acui",
    /// Uniform random points in the volume box, as many as ACUI would give (3DGS baseline).
    Random = "random",
    /// `init.points` uniform points in [-1.3, 1.3)^3 mm about the isocentre (the upstream
    /// non-ACUI branch, 3DGS's rule without SfM points).
    UnitCube = "unit-cube",
    /// `init.points` voxel centres where an FDK reconstruction of the training views exceeds
    /// `init.fdk_threshold` of its maximum (as R2-Gaussian).
    Fdk = "fdk",
}
}

/// Default `init.points` (the upstream unit cube's 100,000).
pub const DEFAULT_INIT_POINTS: usize = 100_000;
/// Most `init.points` (each point becomes a Gaussian of about 100 bytes plus optimiser state).
pub const MAX_INIT_POINTS: usize = 5_000_000;
/// Default `init.fdk_threshold`, a fraction of the FDK volume's maximum (R2-Gaussian: 0.05 on
/// its [0, 1] volume of a 360 degree orbit; see [`super::fdk_init`] for why ours is 0.10).
pub const DEFAULT_FDK_THRESHOLD: f64 = 0.1;
/// Half side of the upstream unit cube, scene units (mm).
pub const UNIT_CUBE_HALF: f64 = 1.3;

fn default_points() -> usize {
    DEFAULT_INIT_POINTS
}
fn is_default_points(n: &usize) -> bool {
    *n == DEFAULT_INIT_POINTS
}
fn default_fdk_threshold() -> f64 {
    DEFAULT_FDK_THRESHOLD
}
fn is_default_fdk_threshold(t: &f64) -> bool {
    *t == DEFAULT_FDK_THRESHOLD
}

/// Initialisation settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InitConfig {
    pub kind: InitKind,
    /// ACUI grid step in voxels (8).
    pub interval: usize,
    /// Initial opacity (0.1).
    pub opacity: f64,
    /// Initial intensity of every Gaussian (0.5).
    pub intensity: f64,
    /// Number of points of the `unit-cube` and `fdk` rules (100,000). Left out of the JSON at
    /// its default, so configs written before the setting existed keep their fingerprint.
    #[serde(default = "default_points", skip_serializing_if = "is_default_points")]
    pub points: usize,
    /// `fdk`: candidate voxels exceed this fraction of the FDK volume's maximum (0.1; left out
    /// of the JSON at its default).
    #[serde(
        default = "default_fdk_threshold",
        skip_serializing_if = "is_default_fdk_threshold"
    )]
    pub fdk_threshold: f64,
}

/// Per-axis ACUI coordinates: `linspace(-s, s, n)[::interval] + off`.
fn axis(n: usize, d: f64, off: f64, interval: usize) -> Vec<f64> {
    let s = n as f64 * d / 2.0 - d / 2.0;
    let step = if n > 1 { 2.0 * s / (n - 1) as f64 } else { 0.0 };
    (0..n)
        .step_by(interval)
        .map(|i| {
            // numpy linspace: start + i * step, with the last sample exactly `stop`.
            let x = if n > 1 && i == n - 1 {
                s
            } else {
                -s + i as f64 * step
            };
            x + off
        })
        .collect()
}

/// ACUI positions for a geometry.
pub fn acui_positions(geo: &ConeBeam, interval: usize) -> Result<Vec<[f64; 3]>> {
    if interval == 0 {
        return Err(Error::invalid("acui_interval", "must be >= 1"));
    }
    let ax: Vec<Vec<f64>> = (0..3)
        .map(|a| axis(geo.n_voxel[a], geo.d_voxel[a], geo.off_origin[a], interval))
        .collect();
    let mut out = Vec::with_capacity(ax[0].len() * ax[1].len() * ax[2].len());
    for &x in &ax[0] {
        for &y in &ax[1] {
            for &z in &ax[2] {
                out.push([x, y, z]);
            }
        }
    }
    Ok(out)
}

/// `n` uniform random points in the volume box (seeded).
pub fn random_positions(geo: &ConeBeam, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1a17_0000_0000_0001);
    let half: [f64; 3] = std::array::from_fn(|a| geo.n_voxel[a] as f64 * geo.d_voxel[a] / 2.0);
    (0..n)
        .map(|_| {
            std::array::from_fn(|a| {
                let u: f64 = rng.random();
                geo.off_origin[a] + (2.0 * u - 1.0) * half[a]
            })
        })
        .collect()
}

/// `n` uniform points in the upstream unit cube `[-1.3, 1.3)^3` (seeded): upstream's
/// `random() * 2.6 - 1.3` per coordinate.
pub fn unit_cube_positions(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1a17_0000_0000_0003);
    (0..n)
        .map(|_| {
            std::array::from_fn(|_| {
                let u: f64 = rng.random();
                u * (2.0 * UNIT_CUBE_HALF) - UNIT_CUBE_HALF
            })
        })
        .collect()
}

/// Error naming the init rule unless at least one point lies inside the volume box.
pub fn check_some_point_inside(geo: &ConeBeam, kind: InitKind, p: &[[f64; 3]]) -> Result<()> {
    let (lo, hi) = geo.volume_box();
    if p.iter()
        .any(|q| (0..3).all(|a| q[a] >= lo[a] && q[a] <= hi[a]))
    {
        return Ok(());
    }
    Err(Error::invalid(
        "init.kind (--init)",
        format!(
            "`{}` gave {} points and none inside the volume box {lo:?} .. {hi:?} mm: choose \
             another initialiser",
            kind.name(),
            p.len()
        ),
    ))
}

/// Mean squared distance from each point to its 3 nearest other points (exact).
///
/// A uniform grid with about 2 points per cell; for each point, rings of cells at Chebyshev
/// distance r = 0, 1, 2, ... are scanned until the 3rd best squared distance is at most
/// (r cell)^2, the smallest possible distance to any cell not yet scanned. Each point is a pure
/// function of the input, so the result is the same for any thread count. With fewer than 4
/// points, the missing neighbours are left out of the mean (0 points: empty output).
pub fn knn3_mean_sq(p: &[[f64; 3]]) -> Vec<f64> {
    let n = p.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in p {
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    let ext: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]).max(1e-9));
    // Cell edge so that about 2 points share a cell, over the non-degenerate axes.
    let vol: f64 = ext.iter().filter(|&&e| e > 1e-9).product();
    let dims_used = ext.iter().filter(|&&e| e > 1e-9).count().max(1) as f64;
    let mut cell = (2.0 * vol / n as f64).powf(1.0 / dims_used);
    if !(cell.is_finite() && cell > 0.0) {
        cell = ext.iter().cloned().fold(0.0, f64::max).max(1e-9);
    }
    let dim: [usize; 3] =
        std::array::from_fn(|a| ((ext[a] / cell).floor() as usize + 1).min(1 << 10));
    let cell_of = |q: &[f64; 3]| -> [usize; 3] {
        std::array::from_fn(|a| (((q[a] - lo[a]) / cell).floor().max(0.0) as usize).min(dim[a] - 1))
    };
    let lin = |c: [usize; 3]| c[0] + dim[0] * (c[1] + dim[1] * c[2]);
    let ncell = dim[0] * dim[1] * dim[2];
    // Counting sort of point indices by cell.
    let mut start = vec![0usize; ncell + 1];
    let cells: Vec<usize> = p.iter().map(|q| lin(cell_of(q))).collect();
    for &c in &cells {
        start[c + 1] += 1;
    }
    for c in 0..ncell {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut order = vec![0usize; n];
    for (i, &c) in cells.iter().enumerate() {
        order[fill[c]] = i;
        fill[c] += 1;
    }
    let max_r = dim.iter().cloned().max().unwrap_or(1);
    let mut out = vec![0.0; n];
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, oc)| {
        for (k, o) in oc.iter_mut().enumerate() {
            let i = ci * CHUNK + k;
            let c = cell_of(&p[i]);
            let mut best = [f64::INFINITY; 3];
            let visit = |cc: [usize; 3], best: &mut [f64; 3]| {
                let l = lin(cc);
                for &j in &order[start[l]..start[l + 1]] {
                    if j == i {
                        continue;
                    }
                    let d2 = (0..3).map(|a| (p[j][a] - p[i][a]).powi(2)).sum::<f64>();
                    if d2 < best[2] {
                        best[2] = d2;
                        if best[2] < best[1] {
                            best.swap(1, 2);
                            if best[1] < best[0] {
                                best.swap(0, 1);
                            }
                        }
                    }
                }
            };
            for r in 0..=max_r {
                let r = r as isize;
                for dz in -r..=r {
                    for dy in -r..=r {
                        for dx in -r..=r {
                            if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                                continue;
                            }
                            let cc = [c[0] as isize + dx, c[1] as isize + dy, c[2] as isize + dz];
                            if (0..3).any(|a| cc[a] < 0 || cc[a] >= dim[a] as isize) {
                                continue;
                            }
                            visit([cc[0] as usize, cc[1] as usize, cc[2] as usize], &mut best);
                        }
                    }
                }
                let bound = r as f64 * cell;
                if best[2] <= bound * bound {
                    break;
                }
            }
            let found: Vec<f64> = best.iter().cloned().filter(|d| d.is_finite()).collect();
            *o = found.iter().sum::<f64>() / found.len().max(1) as f64;
        }
    });
    out
}

/// First feature giving intensity `i` under `color` (the others are 0).
pub fn feature_for_intensity(color: ColorMode, i: f64) -> f64 {
    match color {
        ColorMode::RirfPaper => logit(i) / SH_C0,
        ColorMode::RirfXgaussian | ColorMode::Sh => (i - 0.5) / SH_C0,
    }
}

/// Gaussians at `points` with isotropic 3-NN scales, identity rotation, the configured opacity
/// and intensity.
pub fn gaussians_at<R: Real>(
    points: &[[f64; 3]],
    cfg: &InitConfig,
    color: ColorMode,
) -> Result<Gaussians<R>> {
    if !(cfg.opacity > 0.0 && cfg.opacity < 1.0) {
        return Err(Error::invalid(
            "init_opacity",
            format!("must be in (0, 1), got {}", cfg.opacity),
        ));
    }
    let lim = if color == ColorMode::RirfPaper {
        (0.0, 1.0)
    } else {
        (0.0, f64::INFINITY)
    };
    if !(cfg.intensity > lim.0 && cfg.intensity < lim.1) {
        return Err(Error::invalid(
            "init_intensity",
            format!(
                "must be in ({}, {}) for {color:?}, got {}",
                lim.0, lim.1, cfg.intensity
            ),
        ));
    }
    let d2 = knn3_mean_sq(points);
    let n = points.len();
    let f0 = feature_for_intensity(color, cfg.intensity);
    let mut f = [R::zero(); N_FEATURES];
    f[0] = R::c(f0);
    Ok(Gaussians {
        means: points.iter().map(|q| q.map(R::c)).collect(),
        log_scales: d2
            .iter()
            .map(|&d| [R::c(d.max(1e-7).sqrt().ln()); 3])
            .collect(),
        quats: vec![[R::one(), R::zero(), R::zero(), R::zero()]; n],
        opacity_logits: vec![R::c(logit(cfg.opacity)); n],
        features: vec![f; n],
    })
}

/// The initial points of a run on `ds`, which trains on its first `n_views` training views
/// (the `fdk` rule reconstructs from those, with their recorded cameras).
pub fn positions(
    ds: &Dataset,
    n_views: usize,
    cfg: &InitConfig,
    seed: u64,
) -> Result<Vec<[f64; 3]>> {
    let geo = &ds.geometry;
    let pts = match cfg.kind {
        InitKind::Acui => acui_positions(geo, cfg.interval)?,
        InitKind::Random => random_positions(geo, acui_positions(geo, cfg.interval)?.len(), seed),
        InitKind::UnitCube => unit_cube_positions(cfg.points, seed),
        InitKind::Fdk => {
            super::fdk_init::fdk_positions(ds, n_views, cfg.fdk_threshold, cfg.points, seed)?
        }
    };
    check_some_point_inside(geo, cfg.kind, &pts)?;
    Ok(pts)
}

/// The initial Gaussians of a run on `ds` trained on its first `n_views` training views:
/// [`positions`], then [`gaussians_at`].
pub fn initialise<R: Real>(
    ds: &Dataset,
    n_views: usize,
    cfg: &InitConfig,
    color: ColorMode,
    seed: u64,
) -> Result<Gaussians<R>> {
    let pts = positions(ds, n_views, cfg, seed)?;
    gaussians_at(&pts, cfg, color)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(p: &[[f64; 3]]) -> Vec<f64> {
        (0..p.len())
            .map(|i| {
                let mut d: Vec<f64> = (0..p.len())
                    .filter(|&j| j != i)
                    .map(|j| (0..3).map(|a| (p[j][a] - p[i][a]).powi(2)).sum())
                    .collect();
                d.sort_by(|a, b| a.partial_cmp(b).unwrap());
                d.iter().take(3).sum::<f64>() / d.len().min(3) as f64
            })
            .collect()
    }

    fn geo(n: [usize; 3], d: [f64; 3]) -> ConeBeam {
        ConeBeam::centred([32, 32], [1.0, 1.0], n, d)
    }

    #[test]
    fn knn_matches_brute_force() {
        for (seed, n) in [(1u64, 500usize), (2, 37), (3, 4), (4, 2)] {
            let mut p = random_positions(&geo([64, 32, 16], [1.0, 2.0, 3.0]), n, seed);
            // clustered points too
            for (i, q) in p.iter_mut().enumerate().take(n / 5) {
                *q = [0.01 * i as f64, 0.0, 0.0];
            }
            let a = knn3_mean_sq(&p);
            let b = brute(&p);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() <= 1e-12 * y.max(1.0), "{x} vs {y}");
            }
        }
    }

    #[test]
    fn acui_grid_matches_upstream_layout() {
        // 256 voxels at 1 mm, every 8: 32 per axis from -127.5 to 120.5 (X-Gaussian
        // `pt_positions[::interval, ...]` over `linspace(-s, s, n)`, `s = sVoxel / 2 - dVoxel / 2`).
        let p = acui_positions(&geo([256, 256, 256], [1.0; 3]), 8).unwrap();
        assert_eq!(p.len(), 32 * 32 * 32);
        assert_eq!(p[0], [-127.5; 3]);
        assert_eq!(*p.last().unwrap(), [120.5; 3]);
        assert_eq!(p[1], [-127.5, -127.5, -119.5]);
        // UniSpine CT geometry: 64 x 64 x 22 = 90,112 points.
        let g = geo([512, 512, 174], [0.8398, 0.8398, 3.2]);
        assert_eq!(acui_positions(&g, 8).unwrap().len(), 90_112);
        // Scale = in-plane pitch on that grid (6.72 mm) -- checked on a small copy of it.
        let small = geo([64, 64, 40], [0.8398, 0.8398, 3.2]);
        let g32 = gaussians_at::<f64>(
            &acui_positions(&small, 8).unwrap(),
            &InitConfig {
                kind: InitKind::Acui,
                interval: 8,
                opacity: 0.1,
                intensity: 0.5,
                points: DEFAULT_INIT_POINTS,
                fdk_threshold: DEFAULT_FDK_THRESHOLD,
            },
            ColorMode::RirfPaper,
        )
        .unwrap();
        let s = g32.log_scales[100][0].exp();
        assert!((s - 8.0 * 0.8398).abs() < 1e-9, "{s}");
    }

    #[test]
    fn init_intensity_and_opacity() {
        let pts = acui_positions(&geo([32, 32, 32], [1.0; 3]), 8).unwrap();
        for color in [
            ColorMode::RirfPaper,
            ColorMode::RirfXgaussian,
            ColorMode::Sh,
        ] {
            for i in [0.5, 127.0 / 255.0] {
                let cfg = InitConfig {
                    kind: InitKind::Acui,
                    interval: 8,
                    opacity: 0.1,
                    intensity: i,
                    points: DEFAULT_INIT_POINTS,
                    fdk_threshold: DEFAULT_FDK_THRESHOLD,
                };
                let g = gaussians_at::<f64>(&pts, &cfg, color).unwrap();
                let got = match color {
                    ColorMode::RirfPaper => crate::gaussians::rirf::rirf_paper(&g.features[0], 16),
                    _ => crate::gaussians::rirf::rirf_xgaussian(&g.features[0], 16),
                };
                assert!((got - i).abs() < 1e-12);
                assert!(
                    (crate::math::activations::sigmoid(g.opacity_logits[0]) - 0.1).abs() < 1e-12
                );
                assert_eq!(g.quats[0], [1.0, 0.0, 0.0, 0.0]);
            }
        }
        // Upstream's uint8 round trip of `points3d.ply` (X-Gaussian `scene/dataset_readers.py`):
        // f_dc = (127/255 - 0.5) / C0 = -0.00695.
        let f = feature_for_intensity(ColorMode::RirfXgaussian, 127.0 / 255.0);
        assert!((f + 0.006_951_4).abs() < 1e-6, "{f}");
    }

    #[test]
    fn unit_cube_matches_the_upstream_rule() {
        // X-Gaussian / UniSpine-GS `scene/dataset_readers.py` (3DGS `readNerfSyntheticInfo`):
        // `num_pts` points `np.random.random((num_pts, 3)) * 2.6 - 1.3`; `create_from_pcd`:
        // scale sqrt(max(1e-7, mean squared 3-NN distance)), opacity 0.1, identity rotation.
        let cfg = InitConfig {
            kind: InitKind::UnitCube,
            interval: 8,
            opacity: 0.1,
            intensity: 0.5,
            points: 700,
            fdk_threshold: DEFAULT_FDK_THRESHOLD,
        };
        let p = unit_cube_positions(cfg.points, 3);
        assert_eq!(p.len(), 700);
        assert_eq!(p, unit_cube_positions(700, 3));
        assert_ne!(p, unit_cube_positions(700, 4));
        assert!(p.iter().flatten().all(|&x| (-1.3..1.3).contains(&x)));
        // Uniform: the mean of each coordinate is near 0 and the extremes near +-1.3
        // (700 samples: sd of the mean 0.75 / sqrt(700) = 0.028).
        for a in 0..3 {
            let m = p.iter().map(|q| q[a]).sum::<f64>() / 700.0;
            assert!(m.abs() < 0.12, "axis {a}: mean {m}");
            let lo = p.iter().map(|q| q[a]).fold(f64::INFINITY, f64::min);
            let hi = p.iter().map(|q| q[a]).fold(f64::NEG_INFINITY, f64::max);
            assert!(lo < -1.25 && hi > 1.25, "axis {a}: {lo} .. {hi}");
        }
        let g = gaussians_at::<f64>(&p, &cfg, ColorMode::Sh).unwrap();
        let want = brute(&p);
        assert_eq!(g.len(), 700);
        for (i, q) in p.iter().enumerate() {
            let s = want[i].max(1e-7).sqrt();
            for a in 0..3 {
                assert!((g.log_scales[i][a].exp() - s).abs() <= 1e-12 * s, "{i}");
            }
            assert!((crate::math::activations::sigmoid(g.opacity_logits[i]) - 0.1).abs() < 1e-12);
            assert_eq!(g.quats[i], [1.0, 0.0, 0.0, 0.0]);
            assert_eq!(g.means[i], *q);
        }
        // The cube sits at the world origin (the isocentre), whatever offOrigin: a box moved
        // away from it holds none of the points, which is an error naming the setting.
        let mut far = geo([16, 16, 16], [1.0; 3]);
        assert!(check_some_point_inside(&far, InitKind::UnitCube, &p).is_ok());
        far.off_origin = [0.0, 0.0, 20.0];
        let e = check_some_point_inside(&far, InitKind::UnitCube, &p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("init.kind") && e.contains("unit-cube"), "{e}");
    }

    #[test]
    fn random_init_is_seeded_and_in_the_box() {
        let g = geo([40, 30, 20], [1.0, 1.0, 2.0]);
        let a = random_positions(&g, 100, 7);
        assert_eq!(a, random_positions(&g, 100, 7));
        assert_ne!(a, random_positions(&g, 100, 8));
        assert!(a
            .iter()
            .all(|q| q[0].abs() <= 20.0 && q[1].abs() <= 15.0 && q[2].abs() <= 20.0));
    }
}
