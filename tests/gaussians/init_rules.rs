//! The `fdk` initialiser on a phantom with one ball: every point lies where the FDK volume is
//! dense, i.e. inside the ball (off the isocentre, so a mix-up of axes or of voxel centre and
//! corner would show); the points are the same bits for 1 and 3 threads; a pose-noisy dataset
//! is reconstructed with its recorded cameras; an empty volume is an error naming the setting.

use unispine::dataset::generate::{generate, GenerateOptions};
use unispine::dataset::Dataset;
use unispine::gaussians::init::{self, InitConfig, InitKind};
use unispine::volume::Volume;

use crate::common;

const CENTRE: [f64; 3] = [4.0, -3.0, 2.0];
const RADIUS: f64 = 6.0;

/// A 24^3 volume of 1 mm voxels holding a ball of value 1 (radius 6 mm, centre off the
/// isocentre), projected on 40 training views at a 48 px detector.
fn ball_dataset(value: f32) -> Dataset {
    let n = 24;
    let mut v = Volume::<f32>::zeros([n, n, n], [1.0; 3]);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [i, j, k].map(|x| x as f64 - n as f64 / 2.0 + 0.5);
                let d2: f64 = (0..3).map(|a| (p[a] - CENTRE[a]).powi(2)).sum();
                if d2 <= RADIUS * RADIUS {
                    v.data[i + n * (j + n * k)] = value;
                }
            }
        }
    }
    let opts = GenerateOptions {
        train_views: 40,
        test_views: 2,
        detector: 48,
        ..Default::default()
    };
    generate(&v, &opts, &|_, _| {}).unwrap()
}

fn cfg(points: usize, threshold: f64) -> InitConfig {
    InitConfig {
        kind: InitKind::Fdk,
        interval: 8,
        opacity: 0.1,
        intensity: 0.5,
        points,
        fdk_threshold: threshold,
    }
}

fn dist(p: &[f64; 3]) -> f64 {
    (0..3)
        .map(|a| (p[a] - CENTRE[a]).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn fdk_points_lie_inside_the_ball() {
    let ds = ball_dataset(1.0);
    // Voxel centres of the ball (about 4/3 pi 6^3 = 905).
    let n = 24;
    let inside = (0..n * n * n)
        .filter(|l| {
            let p = [l % n, (l / n) % n, l / (n * n)].map(|x| x as f64 - n as f64 / 2.0 + 0.5);
            dist(&p) <= RADIUS
        })
        .count() as f64;
    // Half of the maximum: the ball's interior, not the FDK's blur around its surface.
    let p = init::positions(&ds, 40, &cfg(100_000, 0.5), 0).unwrap();
    assert!(
        p.len() as f64 > 0.6 * inside,
        "{} points, the ball has {inside} voxels",
        p.len()
    );
    for q in &p {
        assert!(dist(q) <= RADIUS, "{q:?} is {} mm from the centre", dist(q));
    }
    // The default threshold (10 % of the maximum) also keeps the ball's blurred rim: every
    // point within one voxel of the ball, and the whole ball covered.
    let p = init::positions(&ds, 40, &cfg(100_000, 0.1), 0).unwrap();
    let covered = p.iter().filter(|q| dist(q) <= RADIUS).count() as f64;
    assert_eq!(covered, inside, "the ball's voxels kept");
    let far = p.iter().map(dist).fold(0.0, f64::max);
    assert!(far <= RADIUS + 1.0, "a point {far} mm from the centre");
    // R2-Gaussian's 5 % (for 360 degree orbits) also keeps the streaks of a 180 degree FDK
    // without Parker weights: points well away from the ball.
    let loose = init::positions(&ds, 40, &cfg(100_000, 0.05), 0).unwrap();
    assert!(loose.iter().any(|q| dist(q) > RADIUS + 3.0));
    // A draw of 200 of them: 200 distinct voxel centres of the candidates.
    let some = init::positions(&ds, 40, &cfg(200, 0.1), 7).unwrap();
    assert_eq!(some.len(), 200);
    assert!(some.iter().all(|q| p.contains(q)));
    assert_ne!(some, init::positions(&ds, 40, &cfg(200, 0.1), 8).unwrap());
}

#[test]
fn fdk_points_are_the_same_bits_for_any_thread_count() {
    let ds = ball_dataset(1.0);
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| init::initialise::<f32>(&ds, 40, &cfg(300, 0.1), Default::default(), 1))
            .unwrap()
    };
    let (a, b) = (run(1), run(3));
    assert_eq!(a.means, b.means);
    assert_eq!(a.log_scales, b.log_scales);
}

#[test]
fn fdk_uses_the_recorded_cameras_of_a_pose_noisy_dataset() {
    let exact = ball_dataset(1.0);
    let mut noisy = exact.clone();
    noisy.manifest.pose_noise = unispine::dataset::pose::draw(1.0, 1.0, 3, 40).unwrap();
    let a = init::positions(&exact, 40, &cfg(100_000, 0.1), 0).unwrap();
    let b = init::positions(&noisy, 40, &cfg(100_000, 0.1), 0).unwrap();
    // The same projections, other cameras: another volume, other points ...
    assert_ne!(a, b);
    // ... still mostly around the ball (1 degree and 1 mm of error blur it and add streaks):
    // centroid near the ball's centre, 80 % of the points within 2 voxels of the ball.
    let near = b.iter().filter(|q| dist(q) <= RADIUS + 2.0).count() as f64 / b.len() as f64;
    let c: Vec<f64> = (0..3)
        .map(|a| b.iter().map(|q| q[a]).sum::<f64>() / b.len() as f64)
        .collect();
    let off = dist(&[c[0], c[1], c[2]]);
    assert!(
        near >= 0.8 && off < 1.0,
        "{near} near the ball, centroid {off} mm off"
    );
    // Without pose noise the volume is the FDK baseline's (the exact orbit).
    let vol = unispine::fdk::reconstruct(
        &exact.geometry,
        &exact.train.angles,
        &exact.train.projections,
    )
    .unwrap();
    let max = vol.data.iter().cloned().fold(f32::MIN, f32::max) as f64;
    let n_dense = vol.data.iter().filter(|&&v| v as f64 > 0.1 * max).count();
    assert_eq!(a.len(), n_dense);
}

#[test]
fn an_empty_volume_is_an_error_naming_the_setting() {
    let ds = ball_dataset(0.0);
    let e = init::positions(&ds, 40, &cfg(1000, 0.05), 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("init.kind") && e.contains("fdk"), "{e}");
}

#[test]
fn bad_init_settings_exit_1_naming_the_flag_and_value_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    for (flags, words) in [
        (vec!["--init", "cube"], vec!["--init", "cube", "unit-cube"]),
        (vec!["--init-points", "0"], vec!["init.points", "got 0"]),
        (
            vec!["--fdk-threshold", "1.5"],
            vec!["init.fdk_threshold", "got 1.5"],
        ),
        (
            vec!["--grad-threshold=-1"],
            vec!["densify.grad_threshold", "got -1"],
        ),
    ] {
        let mut args = vec!["train", "--data", "no-such-dataset", "--out"];
        args.push(out.to_str().unwrap());
        args.extend(&flags);
        let o = common::cli::bin().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{flags:?}: {err}");
        for w in words {
            assert!(err.contains(w), "{flags:?}: `{err}` lacks {w}");
        }
        assert!(!out.exists(), "{flags:?} wrote {}", out.display());
    }
}
