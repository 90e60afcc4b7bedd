//! Finite-difference audit of the whole render (projection, Eq. 3, then compositing, Eqs. 4-5):
//! the analytic gradient of L = sum(W * image) against 5-point central differences in f64, for
//! every parameter group (means, log_scales, quats, opacity_logits, features), colour modes
//! rirf-paper, rirf-xgaussian and sh, on three small scenes (cone beam, cone beam with offset
//! detector and background, parallel beam); f32 against f64 on the same scenes.
//!
//! The scenes are those of `unispine gradcheck` (`unispine::audit::gradcheck::small_scenes`);
//! `scenes_stay_away_from_the_hard_cutoffs` asserts that no perturbation of the FD stencil can
//! cross a cutoff of the rasterizer (1/255 skip, 0.99 clamp, 1e-4 stop, tile rectangle).

use unispine::audit::gradcheck::{self, small_scenes, GROUPS};
use unispine::audit::{self, TOLERANCE};
use unispine::math::fd;
use unispine::render::ColorMode;

const COLORS: [ColorMode; 3] = [
    ColorMode::RirfPaper,
    ColorMode::RirfXgaussian,
    ColorMode::Sh,
];

#[test]
fn scenes_stay_away_from_the_hard_cutoffs() {
    for s in small_scenes() {
        for c in COLORS {
            let m = gradcheck::margins(&s, c).unwrap();
            println!("{} {c:?}: {m:?}", s.name);
            assert_eq!(
                m.drawn,
                s.gaussians.len(),
                "{}: every Gaussian drawn",
                s.name
            );
            // ln(255 o G) >= 1: o G >= 2.7/255 at every pixel (the FD steps move ln(o G) by
            // less than 0.05).
            assert!(m.log_alpha_over_skip >= 1.0, "{}: {m:?}", s.name);
            assert!(m.below_clamp >= 0.3, "{}: {m:?}", s.name);
            assert!(m.t_final_over_stop >= 5.0, "{}: {m:?}", s.name);
            // The radius may change by 1 px under a perturbation: 2 px of overhang keeps every
            // tile rectangle the whole grid.
            assert!(m.square_overhang >= 2.0, "{}: {m:?}", s.name);
        }
    }
}

#[test]
fn every_group_matches_central_differences() {
    let scenes = small_scenes();
    let rows = gradcheck::rows(&scenes, &COLORS).unwrap();
    assert_eq!(rows.len(), scenes.len() * COLORS.len() * GROUPS.len());
    for r in &rows {
        println!(
            "{:<15} {:<14} {:<15} max|fd| {:.3e}  abs {:.3e}  rel {:.3e}",
            r.case, r.variant, r.group, r.scale, r.max_abs, r.rel
        );
        assert!(r.scale > 0.0, "{r:?}: zero gradient");
        assert!(r.rel <= TOLERANCE && r.passes(), "{r:?}");
    }
    println!("worst relative error {:.3e}", audit::worst(&rows));
}

#[test]
fn f32_agrees_with_f64() {
    let (mut wi, mut wg): (f64, [f64; 5]) = (0.0, [0.0; 5]);
    for s in small_scenes() {
        for c in COLORS {
            let i64_ = gradcheck::image::<f64>(&s, c).unwrap();
            let i32_ = gradcheck::image::<f32>(&s, c).unwrap();
            let e = fd::rel_err_maxabs(&i32_, &i64_);
            wi = wi.max(e);
            assert!(e <= 1e-6, "{} {c:?}: image f32 vs f64 {e:e}", s.name);
            let g64 = gradcheck::analytic::<f64>(&s, c).unwrap();
            let g32 = gradcheck::analytic::<f32>(&s, c).unwrap();
            for k in 0..5 {
                let e = fd::rel_err_maxabs(&g32[k], &g64[k]);
                wg[k] = wg[k].max(e);
                assert!(
                    e <= 1e-4,
                    "{} {c:?} {}: f32 vs f64 {e:e}",
                    s.name,
                    GROUPS[k]
                );
            }
        }
    }
    println!(
        "f32 vs f64: image {wi:.2e}, gradients {:?}",
        wg.map(|x| format!("{x:.2e}"))
    );
}
