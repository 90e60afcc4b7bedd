//! The DRR's vector kernels against the per-ray loops: the same bits on every instruction set
//! the CPU supports (`scalar` runs the per-ray loops; on AVX-512 the trilinear march on 8 and
//! on 16 lanes), for 1, 2 and 8 threads, on random
//! volumes and geometries, on rays that graze voxel faces and box edges, miss the box or run
//! parallel to an axis.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use unispine::drr::{MarchLanes, Method, Projector};
use unispine::geometry::{ConeBeam, Mode};
use unispine::simd::Simd;
use unispine::volume::Volume;

/// A volume of random values in [0, 1) (a few exactly 0, a few negative) on the given grid.
fn random_volume(rng: &mut ChaCha8Rng, dims: [usize; 3], spacing: [f64; 3]) -> Volume<f32> {
    let mut v = Volume::zeros(dims, spacing);
    for x in v.data.iter_mut() {
        *x = match rng.random_range(0..10) {
            0 => 0.0,
            1 => -rng.random_range(0.0f32..1.0),
            _ => rng.random_range(0.0f32..1.0),
        };
    }
    v
}

/// An instruction set and, on AVX-512, the trilinear march's lanes.
type Path = (Simd, MarchLanes);

const SCALAR: Path = (Simd::Scalar, MarchLanes::Eight);

/// Every path the CPU supports, the AVX-512 one with each march width.
fn paths() -> Vec<Path> {
    let mut out = Vec::new();
    for simd in Simd::supported_paths() {
        out.push((simd, MarchLanes::Eight));
        if simd == Simd::Avx512 {
            out.push((simd, MarchLanes::Sixteen));
        }
    }
    out
}

fn name((simd, lanes): Path) -> String {
    format!("{} ({} march lanes)", simd.name(), lanes.count())
}

/// Bits of the view of `vol` at `angle` on `path`, or the error's text.
fn try_bits(
    vol: &Volume<f32>,
    geo: &ConeBeam,
    angle: f64,
    method: Method,
    (simd, lanes): Path,
) -> Result<Vec<u32>, String> {
    Projector::new(vol, geo, method)
        .and_then(|p| p.with_simd(simd).with_march_lanes(lanes).view(angle))
        .map(|img| img.data.iter().map(|v| v.to_bits()).collect())
        .map_err(|e| e.to_string())
}

fn bits(vol: &Volume<f32>, geo: &ConeBeam, angle: f64, method: Method, path: Path) -> Vec<u32> {
    try_bits(vol, geo, angle, method, path).unwrap()
}

/// Every supported path gives the scalar path's bits (or its error); returns how many pixels
/// are non-zero.
fn check_paths(vol: &Volume<f32>, geo: &ConeBeam, angle: f64, what: &str) -> usize {
    let mut nonzero = 0;
    for method in [Method::Siddon, Method::Trilinear] {
        let want = match try_bits(vol, geo, angle, method, SCALAR) {
            Ok(b) => b,
            Err(e) => {
                for path in paths() {
                    assert_eq!(try_bits(vol, geo, angle, method, path), Err(e.clone()));
                }
                continue;
            }
        };
        nonzero = want.iter().filter(|&&b| f32::from_bits(b) != 0.0).count();
        for path in paths() {
            let got = bits(vol, geo, angle, method, path);
            if let Some(k) = (0..want.len()).find(|&k| got[k] != want[k]) {
                panic!(
                    "{what}, {method:?}, {}: pixel {k} (col {}, row {}) is {} (scalar {})",
                    name(path),
                    k % geo.n_detector[1],
                    k / geo.n_detector[1],
                    f32::from_bits(got[k]),
                    f32::from_bits(want[k])
                );
            }
        }
    }
    nonzero
}

#[test]
fn every_path_gives_the_scalar_bits_on_random_geometries() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut lit = 0;
    for case in 0..40 {
        // Grids with 1-voxel axes, odd sizes and anisotropic voxels.
        let dims = [0, 1, 2].map(|_| match rng.random_range(0..6) {
            0 => 1,
            1 => 2,
            _ => rng.random_range(3..40),
        });
        let spacing = [0, 1, 2].map(|_| rng.random_range(0.3..3.0));
        let mut vol = random_volume(&mut rng, dims, spacing);
        vol.offset = [0, 1, 2].map(|_| rng.random_range(-5.0..5.0));
        let size = vol.size_mm();
        let extent = size[0].max(size[1]).max(size[2]);
        let mode = if rng.random_range(0..4) == 0 {
            Mode::Parallel
        } else {
            Mode::Cone
        };
        let (h, w) = (rng.random_range(1..40), rng.random_range(1..40));
        // Detectors from much smaller to much larger than the shadow (rays that miss).
        let pitch = extent * rng.random_range(0.5..4.0) / w.max(h) as f64;
        let dso = rng.random_range(2.0 * extent..3.0 * extent) + 20.0;
        let geo = ConeBeam {
            dso,
            dsd: dso + extent + rng.random_range(0.0..1000.0),
            off_origin: vol.offset,
            off_detector: [0, 1].map(|_| rng.random_range(-0.2..0.2) * extent),
            mode,
            accuracy: rng.random_range(0.1..1.0),
            ..ConeBeam::centred(
                [h, w],
                [pitch, pitch * rng.random_range(0.5..2.0)],
                dims,
                spacing,
            )
        };
        // Random angles and the axis-parallel ones.
        let angle = match case % 4 {
            0 => 0.0,
            1 => std::f64::consts::FRAC_PI_2,
            _ => rng.random_range(-7.0..7.0),
        };
        if check_paths(&vol, &geo, angle, &format!("case {case}")) > 0 {
            lit += 1;
        }
    }
    assert!(lit >= 30, "only {lit} of 40 random views hit their volume");
}

/// Parallel rays along the x axis whose detector coordinates fall exactly on voxel faces and
/// box edges (1 mm voxels, 1 mm pixels, integer offsets): the walk's ties between axes and the
/// half-open faces.
#[test]
fn rays_on_faces_and_edges_agree() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let vol = random_volume(&mut rng, [6, 8, 5], [1.0; 3]);
    for (off, n) in [
        ([0.0, 0.0], [12, 14]),
        ([0.5, 0.5], [13, 15]),
        ([0.25, -0.5], [9, 11]),
    ] {
        for mode in [Mode::Parallel, Mode::Cone] {
            let geo = ConeBeam {
                off_detector: off,
                mode,
                ..ConeBeam::centred(n, [1.0, 1.0], [6, 8, 5], [1.0; 3])
            };
            for angle in [
                0.0,
                std::f64::consts::FRAC_PI_2,
                std::f64::consts::PI,
                std::f64::consts::FRAC_PI_4,
            ] {
                let lit = check_paths(&vol, &geo, angle, &format!("{mode:?} off {off:?}"));
                assert!(lit > 0, "{mode:?} at {angle}: no ray hit");
            }
        }
    }
}

#[test]
fn every_path_is_thread_count_invariant() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let vol = random_volume(&mut rng, [37, 29, 23], [0.9, 1.1, 2.0]);
    let geo = ConeBeam {
        accuracy: 0.5,
        ..ConeBeam::centred([45, 51], [1.9, 1.7], [37, 29, 23], [0.9, 1.1, 2.0])
    };
    for method in [Method::Siddon, Method::Trilinear] {
        let want = bits(&vol, &geo, 0.7, method, SCALAR);
        for path in paths() {
            for t in [1, 2, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .unwrap();
                let got = pool.install(|| bits(&vol, &geo, 0.7, method, path));
                assert!(got == want, "{method:?} {} with {t} threads", name(path));
            }
        }
    }
}
