//! Compaction (`train --compact-*`): the importance score against a brute-force f64
//! computation, the prune keeps exactly the highest-ranked Gaussians, a compacted run is
//! bit-identical for 1, 2 and 8 threads and across a stop / resume on either side of the
//! compaction, and bad settings are errors naming the flag.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::common;
use common::tiny;
use unispine::gaussians::Gaussians;
use unispine::geometry::{Camera, ConeBeam};
use unispine::render::{self, tiles, ColorMode, RenderSettings};
use unispine::session::{self, Control};
use unispine::simd::Simd;
use unispine::train::compact::{self, CompactConfig};
use unispine::train::{self, Event, Method, RunDir, TrainOverrides, Trainer};

fn quiet(_: &Event) {}

fn settings() -> RenderSettings {
    RenderSettings {
        color: ColorMode::RirfXgaussian,
        active_features: 1,
        background: 0.0,
        ..Default::default()
    }
}

/// A few overlapping Gaussians on a 20 x 20 detector (2 x 2 tiles).
fn scene() -> (Gaussians<f64>, Vec<Camera>) {
    let geo = ConeBeam::centred([20, 20], [4.8, 4.8], [32, 32, 32], [2.0, 2.0, 2.0]);
    let n = 7;
    let mut g = Gaussians::<f64>::zeros(n);
    for i in 0..n {
        let t = i as f64;
        g.means[i] = [
            12.0 * (1.7 * t).sin(),
            10.0 * (0.9 * t).cos(),
            3.0 * t - 9.0,
        ];
        g.log_scales[i] = [(4.0 + t % 3.0).ln(), 5.0f64.ln(), (3.0 + t % 2.0).ln()];
        g.quats[i] = [1.0, 0.2 * t.sin(), 0.1, -0.2];
        // Opacities from 0.2 to 0.98: some pixels reach the 0.99 clamp and the T stop.
        g.opacity_logits[i] = -1.4 + 0.9 * t;
        g.features[i][0] = 0.5;
    }
    let cams = (0..3).map(|k| geo.camera(0.6 * k as f64)).collect();
    (g, cams)
}

/// sum over views and pixels of alpha_i T_i, pixel by pixel in f64 from the projected splats:
/// the drawn splats whose tile rectangle holds the pixel's tile, in (depth, index) order,
/// alpha = min(0.99, o exp(power)), skipped when power > 0 or alpha < 1/255, stop before the
/// blend that takes T below 1e-4.
fn brute_force(g: &Gaussians<f64>, cams: &[Camera]) -> Vec<f64> {
    let mut score = vec![0.0; g.len()];
    for cam in cams {
        let (s, _) = render::project::forward(g, cam, &settings()).unwrap();
        let (tx, ty) = (cam.width.div_ceil(16), cam.height.div_ceil(16));
        let mut order: Vec<usize> = (0..g.len()).filter(|&i| tiles::drawn(&s, i)).collect();
        order.sort_by(|&a, &b| s.depth[a].total_cmp(&s.depth[b]).then(a.cmp(&b)));
        for row in 0..cam.height {
            for col in 0..cam.width {
                let mut t = 1.0f64;
                for &i in &order {
                    let [u, v] = s.mean2d[i];
                    let Some(r) = tiles::tile_rect(u, v, s.radius[i], tx, ty) else {
                        continue;
                    };
                    let (px, py) = (col / 16, row / 16);
                    if !(r[0] <= px && px < r[1] && r[2] <= py && py < r[3]) {
                        continue;
                    }
                    let dx = col as f64 + 0.5 - u;
                    let dy = row as f64 + 0.5 - v;
                    let [a, b, c] = s.conic[i];
                    let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
                    if power > 0.0 {
                        continue;
                    }
                    let alpha = (s.opacity[i] * power.exp()).min(0.99);
                    if alpha < 1.0 / 255.0 {
                        continue;
                    }
                    if t * (1.0 - alpha) < 1e-4 {
                        break;
                    }
                    score[i] += alpha * t;
                    t *= 1.0 - alpha;
                }
            }
        }
    }
    score
}

#[test]
fn score_matches_alpha_t_summed_pixel_by_pixel() {
    let (g, cams) = scene();
    let want = brute_force(&g, &cams);
    // The scene exercises distinct scores (no test of equal values).
    assert!(want.iter().filter(|&&w| w > 1.0).count() >= 4, "{want:?}");
    for simd in Simd::supported_paths() {
        let got = compact::importance_with(simd, &g, &cams, &settings()).unwrap();
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                "{simd:?} Gaussian {i}: {a} vs brute force {b}"
            );
        }
    }
    // f32 (what training uses): the same to f32 accuracy, and bit-identical over SIMD paths
    // and thread counts.
    let g32 = g.cast::<f32>();
    let base = compact::importance_with(Simd::Scalar, &g32, &cams, &settings()).unwrap();
    for (a, b) in base.iter().zip(&want) {
        assert!((a - b).abs() <= 1e-4 * b.abs().max(1.0), "{a} vs {b}");
    }
    for simd in Simd::supported_paths() {
        for threads in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let s = pool
                .install(|| compact::importance_with(simd, &g32, &cams, &settings()))
                .unwrap();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&s), bits(&base), "{simd:?}, {threads} threads");
        }
    }
}

fn compacting(iters: usize, to: usize, at: Option<usize>, finetune: usize) -> train::TrainConfig {
    let mut c = tiny::tiny(Method::Unispine, iters);
    c.compact = Some(CompactConfig {
        keep: None,
        to: Some(to),
        at,
        finetune,
    });
    c
}

#[test]
fn compaction_keeps_exactly_the_highest_scores_with_their_adam_moments() {
    let ds = tiny::dataset();
    let cfg = compacting(30, 150, Some(15), 5);
    let mut tr = Trainer::new(cfg, &ds).unwrap();
    for _ in 0..14 {
        tr.step().unwrap();
    }
    let before = tr.state.clone();
    let n = before.len();
    assert!(n > 150, "the tiny run has {n} Gaussians before compacting");
    let cams: Vec<Camera> = (0..tr.targets.len()).map(|k| ds.train_camera(k)).collect();
    let score = compact::importance(&before.params, &cams, &tr.settings(15)).unwrap();
    let info = tr.step().unwrap();
    assert_eq!(info.iteration, 15);
    assert_eq!(tr.state.len(), 150);
    assert_eq!(info.eval.as_ref().unwrap().n_gaussians, 150);
    // Which Gaussians survive: found by matching parameters (the prune keeps the order).
    let mut kept = Vec::new();
    let mut j = 0;
    for i in 0..n {
        if j < 150 && before.params.means[i] == tr.state.params.means[j] {
            assert_eq!(before.params.features[i], tr.state.params.features[j]);
            assert_eq!(before.adam.m.means[i], tr.state.adam.m.means[j]);
            assert_eq!(
                before.adam.v.opacity_logits[i],
                tr.state.adam.v.opacity_logits[j]
            );
            kept.push(i);
            j += 1;
        }
    }
    assert_eq!(kept.len(), 150);
    let min_kept = kept.iter().map(|&i| score[i]).fold(f64::INFINITY, f64::min);
    let removed: Vec<usize> = (0..n).filter(|i| !kept.contains(i)).collect();
    for &r in &removed {
        // Lowest scores removed; among equal scores the higher index goes.
        let below = score[r] < min_kept
            || (score[r] == min_kept && kept.iter().all(|&k| score[k] > min_kept || k < r));
        assert!(
            below,
            "removed {r} (score {}) vs kept min {min_kept}",
            score[r]
        );
    }
    // Adam step counts are untouched by the prune (and no update at the compaction).
    assert_eq!(tr.state.adam.steps, before.adam.steps);
    let c = tr.compaction.clone().unwrap();
    assert_eq!((c.iteration, c.n_before, c.n_after), (15, n, 150));
    // The rest of the schedule and the fine-tuning (iterations 16..=35): no densification
    // (the tiny schedule would densify at iteration 20), the count stays.
    while tr.iteration < 35 {
        let s = tr.step().unwrap();
        assert!(s.densified.is_none());
        assert_eq!(s.n_gaussians, 150);
    }
}

fn run_in(
    threads: usize,
    dir: &Path,
    cfg: &train::TrainConfig,
    stop_after: Option<usize>,
) -> train::Metrics {
    let ds = tiny::dataset();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let never = AtomicBool::new(false);
    let ctl = Control {
        stop: &never,
        stop_after,
    };
    pool.install(|| session::run(&cfg.clone().into(), &ds, Some(dir), ctl, &mut quiet))
        .unwrap()
}

fn strip_seconds(m: &train::Metrics) -> String {
    let mut v = serde_json::to_value(m).unwrap();
    for k in [
        "train_time_s",
        "eval_time_s",
        "render_fps",
        "peak_memory_bytes",
        "threads",
    ] {
        v.as_object_mut().unwrap().remove(k);
    }
    v.to_string()
}

#[test]
fn a_compacted_run_is_thread_count_invariant_and_honest() {
    let cfg = compacting(30, 120, None, 6);
    let dirs: Vec<_> = (0..3).map(|_| tempfile::tempdir().unwrap()).collect();
    let ms: Vec<_> = [1, 2, 8]
        .iter()
        .zip(&dirs)
        .map(|(&t, d)| run_in(t, d.path(), &cfg, None))
        .collect();
    let m = &ms[0];
    let c = m.compaction.as_ref().unwrap();
    assert_eq!((c.iteration, c.n_after), (30, 120));
    assert!(c.n_before > 120);
    // The saved model is the compacted one, and metrics.json says so.
    assert_eq!(m.iterations, 36);
    assert_eq!(m.n_gaussians, 120);
    let model =
        unispine::gaussians::ply::read_ply::<f32>(&dirs[0].path().join("model.ply")).unwrap();
    assert_eq!(model.len(), 120);
    let on_disk = RunDir::open(dirs[0].path())
        .unwrap()
        .read_metrics()
        .unwrap();
    assert_eq!(on_disk.compaction, m.compaction);
    // Before pruning: the same PSNR as a plain 30-iteration run (the compaction replaces the
    // update of iteration 30, which a plain run skips as its last).
    let plain_dir = tempfile::tempdir().unwrap();
    let plain = run_in(2, plain_dir.path(), &tiny::tiny(Method::Unispine, 30), None);
    assert_eq!(Some(c.psnr_before), plain.test_psnr);
    assert_eq!(c.n_before, plain.n_gaussians);
    // The pruned model's evaluation is the one recorded at iteration 30.
    let at30 = m.evals.iter().find(|e| e.iteration == 30).unwrap();
    assert_eq!((at30.psnr, at30.n_gaussians), (c.psnr_pruned, 120));
    for (o, d) in ms[1..].iter().zip(&dirs[1..]) {
        assert_eq!(strip_seconds(o), strip_seconds(m));
        assert_eq!(
            std::fs::read(d.path().join("model.ply")).unwrap(),
            std::fs::read(dirs[0].path().join("model.ply")).unwrap()
        );
    }
}

#[test]
fn resume_across_the_compaction_gives_the_same_bits() {
    let ds = tiny::dataset();
    let cfg = compacting(30, 120, Some(24), 6);
    let straight_dir = tempfile::tempdir().unwrap();
    let straight = run_in(2, straight_dir.path(), &cfg, None);
    // Stopped before the compaction (20) and during the fine-tuning (33).
    for stop in [20, 33] {
        let d = tempfile::tempdir().unwrap();
        let s = run_in(2, d.path(), &cfg, Some(stop));
        assert!(!s.completed);
        assert_eq!(s.compaction.is_some(), stop >= 24);
        let never = AtomicBool::new(false);
        let ctl = Control {
            stop: &never,
            stop_after: None,
        };
        let r = session::resume(d.path(), &ds, ctl, &mut quiet).unwrap();
        assert_eq!(
            strip_seconds(&r),
            strip_seconds(&straight),
            "stopped at {stop}"
        );
        assert_eq!(
            std::fs::read(d.path().join("model.ply")).unwrap(),
            std::fs::read(straight_dir.path().join("model.ply")).unwrap(),
            "stopped at {stop}"
        );
    }
}

#[test]
fn bad_compaction_settings_name_the_flag() {
    let apply = |o: TrainOverrides| o.apply(Method::Unispine, Some(50)).unwrap_err().to_string();
    let o = TrainOverrides::default;
    for f in [0.0, 1.5, -1.0] {
        let e = apply(TrainOverrides {
            compact_keep: Some(f),
            ..o()
        });
        assert!(e.contains("--compact-keep") && e.contains("(0, 1]"), "{e}");
    }
    let e = apply(TrainOverrides {
        compact_to: Some(0),
        ..o()
    });
    assert!(e.contains("--compact-to"), "{e}");
    let e = apply(TrainOverrides {
        compact_finetune: Some(10),
        ..o()
    });
    assert!(
        e.contains("--compact-finetune") && e.contains("needs a compaction"),
        "{e}"
    );
    let e = apply(TrainOverrides {
        compact_at: Some(10),
        ..o()
    });
    assert!(e.contains("--compact-at"), "{e}");
    let e = apply(TrainOverrides {
        compact_keep: Some(0.5),
        compact_at: Some(51),
        ..o()
    });
    assert!(e.contains("--compact-at") && e.contains("[1, 50]"), "{e}");
    let e = apply(TrainOverrides {
        compact_keep: Some(0.5),
        compact_to: Some(10),
        ..o()
    });
    assert!(e.contains("--compact-keep / --compact-to"), "{e}");
    let c = TrainOverrides {
        compact_keep: Some(0.5),
        compact_finetune: Some(10),
        ..o()
    }
    .apply(Method::Unispine, Some(50))
    .unwrap();
    assert_eq!(c.total_iterations(), 60);
    assert_eq!(c.compact_at(), Some(50));
    // Through the binary: exit code 1 and the flag in the message.
    let out = common::cli::bin()
        .args([
            "train",
            "--data",
            "nowhere",
            "--out",
            "nowhere-out",
            "--compact-keep",
            "2",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--compact-keep"), "{err}");
}
