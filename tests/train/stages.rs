//! The training step's stage timers and `unispine bench train`: timing changes no bit of the
//! training, the stages sum to the step, densification events are counted and amortised, and
//! the benchmark runs on a dataset folder and on the phantom fallback.

use crate::common;
use common::cli;
use common::tiny;
use tiny::{dataset, hidden, tiny};
use unispine::bench::train::{self, Clock};
use unispine::train::{Method, StageTimes, Trainer};

#[test]
fn stage_timers_change_no_bit_and_sum_to_the_step() {
    let ds = dataset();
    let cfg = tiny(Method::Unispine, 60);
    let mut plain = Trainer::new(cfg.clone(), &ds).unwrap();
    let mut timed = Trainer::new(cfg, &ds).unwrap();
    timed.stages = Some(StageTimes::default());
    let mut events = 0;
    for _ in 0..60 {
        let mut a = plain.step().unwrap();
        let mut b = timed.step().unwrap();
        // Everything but the wall time of the evaluation.
        for e in [&mut a.eval, &mut b.eval].into_iter().flatten() {
            e.seconds = 0.0;
        }
        assert_eq!(a, b);
        events += usize::from(b.densified.is_some());
    }
    assert_eq!(plain.state.params, timed.state.params);
    assert_eq!(plain.state.adam, timed.state.adam);
    assert_eq!(plain.state.stats, timed.state.stats);
    assert!(plain.stages.is_none());
    let s = timed.stages.unwrap();
    assert_eq!(s.steps, 60);
    assert!(events > 0, "the tiny schedule densifies");
    assert_eq!(s.n_densify_events, events);
    let w = &s.wall;
    assert!(w.densify_events > 0.0 && w.densify_events <= w.densify);
    for c in [&s.wall, &s.cpu] {
        let secs = c.seconds();
        for (name, v) in unispine::train::stages::STAGES.iter().zip(secs) {
            assert!(v >= -1e-9, "{name}: {v}");
        }
        // The named stages are laps inside the step; everything else is bookkeeping.
        let sum: f64 = secs.iter().sum();
        assert!(
            (sum - c.step).abs() <= 1e-9 * c.step.max(1.0),
            "{sum} vs {}",
            c.step
        );
    }
    assert!(w.render_forward > 0.0 && w.render_backward > 0.0 && w.loss > 0.0);
    assert!(s.cpu.step > 0.0);
    // Test evaluation at iterations 1 and 60 is timed on its own.
    assert!(w.eval > 0.0);
}

#[test]
fn bench_amortises_densification_and_sums_to_the_step() {
    let ds = dataset();
    // From a model at schedule position 598: iteration 599 untimed, then 600..=602 timed, an
    // event at 600 (the preset densifies every 200 iterations in (500, 8000)).
    let b = train::time_train(&ds, 598, 3, Some(hidden().cast())).unwrap();
    assert_eq!(b.first_iteration, 600);
    assert_eq!(b.stages.steps, 3);
    assert_eq!(b.stages.n_densify_events, 1);
    assert!(b.densify_phase);
    assert_eq!(b.densify_interval, 200);
    assert_eq!(b.densify_event.0, b.stages.wall.densify_events);
    assert_eq!(b.densify_event.1, b.stages.cpu.densify_events);
    for (clock, st, ev) in [
        (Clock::Wall, &b.stages.wall, b.densify_event.0),
        (Clock::Cpu, &b.stages.cpu, b.densify_event.1),
    ] {
        let v = b.per_iteration(clock);
        let raw = st.seconds().map(|x| x / 3.0);
        let want = raw[4] - st.densify_events / 3.0 + ev / 200.0;
        assert!((v[4] - want).abs() <= 1e-15, "{} vs {want}", v[4]);
        for k in [0, 1, 2, 3, 5, 6] {
            assert_eq!(v[k], raw[k]);
        }
        assert!((b.step(clock) - v.iter().sum::<f64>()).abs() <= 1e-15);
        let share = b.non_rasterizer_share(clock);
        assert!(share > 0.0 && share < 1.0, "{share}");
        assert!((share - (1.0 - (v[0] + v[2]) / b.step(clock))).abs() < 1e-12);
    }
    // No event in the window (602..=604, after the untimed 601): one is timed on a copy of
    // the state.
    let b = train::time_train(&ds, 600, 3, Some(hidden().cast())).unwrap();
    assert_eq!(b.stages.n_densify_events, 0);
    assert!(b.densify_phase && b.densify_event.0 > 0.0 && b.densify_event.1 > 0.0);
    // Past the phase: nothing amortised.
    let b = train::time_train(&ds, 9000, 2, Some(hidden().cast())).unwrap();
    assert!(!b.densify_phase);
    assert_eq!(b.densify_event, (0.0, 0.0));
    assert_eq!(b.per_iteration(Clock::Wall)[4], b.stages.wall.densify / 2.0);
}

#[test]
fn bench_train_prints_the_stages_on_a_dataset_folder_and_the_phantom() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("tiny");
    unispine::dataset::store::save(&dataset(), &data).unwrap();
    let d = data.display().to_string();
    let out = cli::ok(&[
        "bench", "train", "--data", &d, "--warmup", "3", "--iters", "2",
    ]);
    for w in [
        "32x32",
        "render forward",
        "loss + SPWM + SSIM",
        "render backward",
        "Adam",
        "densification",
        "bookkeeping",
        "CPU time",
        "(target <= 15%)",
    ] {
        assert!(out.contains(w), "missing `{w}`:\n{out}");
    }
    let err = cli::fails(&["bench", "train", "--data", &d, "--sizes", "64"]);
    assert!(err.contains("--sizes") && err.contains("--data"), "{err}");
    let missing = dir.path().join("none.nii.gz").display().to_string();
    let out = cli::ok(&[
        "bench", "train", "--sizes", "16", "--views", "2", "--warmup", "0", "--iters", "1",
        "--volume", &missing, "--mask", &missing,
    ]);
    assert!(
        out.contains("built-in phantom") && out.contains("not found"),
        "{out}"
    );
    assert!(out.contains("16x16"), "{out}");
}

/// `bench loss` prints, per size, the fused SSIM, its definition (the run fails if the two
/// differ in a bit), their ratio and the whole loss.
#[test]
fn bench_loss_prints_the_fused_kernels_against_the_definition() {
    let out = cli::ok(&["bench", "loss", "--sizes", "16,37", "--reps", "2"]);
    for w in [
        "ssim fused",
        "ssim definition",
        "ratio (CPU)",
        "whole loss",
        "median of 2",
    ] {
        assert!(out.contains(w), "missing `{w}`:\n{out}");
    }
    let rows: Vec<&str> = out
        .lines()
        .filter(|l| l.trim_start().starts_with("16 ") || l.trim_start().starts_with("37 "))
        .collect();
    assert_eq!(rows.len(), 2, "{out}");
    for r in rows {
        let ratio = r.split_whitespace().find(|f| f.ends_with('x')).unwrap();
        let v: f64 = ratio.trim_end_matches('x').parse().unwrap();
        assert!(v.is_finite() && v > 0.0, "{r}");
    }
}
