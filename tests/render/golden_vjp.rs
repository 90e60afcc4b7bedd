//! Golden files of each per-Gaussian stage's backward pass (vector-Jacobian products), so a
//! backend can check its covariance, intensity and projection backward on their own:
//! - `eq01-covariance-vjp`: Eq. (1), upstream d_covariance -> d_log_scales, d_quats;
//! - `eq02-rirf-vjp`: Eq. (2) (both RIRF variants) and SH colour, upstream d_intensity ->
//!   d_features (and d_means for SH, through the view direction);
//! - `eq03-projection-vjp`: Eq. (3), upstream d_mean2d, d_conic -> d_means, d_log_scales,
//!   d_quats (through Eq. 1), including the Jacobian clamp and culled Gaussians (zero gradient).
//!
//! The forward inputs are those of the forward golden files (`eq01-covariance/basic`,
//! `eq02-rirf/*`, `eq03-projection/*`), copied into each VJP file so it stands alone; the
//! upstream gradients are fixed pseudo-random numbers.
//!
//! (a) Recomputes every case from its inputs with the f64 path and compares with the stored
//!     outputs within the file's tolerance.
//! (b) Runs `python3 tools/vjp_reference.py`: independent numpy forwards differentiated by the
//!     complex step (no hand-written backward), compared with the stored outputs.
//!
//! Regenerate: `UNISPINE_REGEN_GOLDEN=1 cargo test --release --test render golden_vjp::`.

use crate::common;
use common::golden::*;

use serde_json::{json, Value};
use unispine::gaussians::model::N_FEATURES;
use unispine::gaussians::Gaussians;
use unispine::geometry::ConeBeam;
use unispine::math::covariance::{covariance, covariance_vjp};
use unispine::render::project::{self, intensity, intensity_vjp};
use unispine::render::{ColorMode, RenderSettings, SplatGrads};

const TOL: [f64; 2] = [1e-12, 1e-9];

const CHECKED_BY: &str = "tools/vjp_reference.py (independent numpy forward of the stage, \
    differentiated by the complex step f'(x) = Im f(x + i h) / h, h = 1e-30, one input at a \
    time; hard decisions (culling, the Jacobian clamp, max(0, .)) taken at the unperturbed \
    point); central finite differences of the same backward in src/render/project/tests.rs \
    and src/math";

/// Fixed pseudo-random numbers in [-1, 1) (an LCG; the values are stored in the files).
fn upstream(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            2.0 * ((s >> 11) as f64 / (1u64 << 53) as f64) - 1.0
        })
        .collect()
}

fn vjp_case(equation: &str, description: &str, inputs: Value) -> Value {
    new_case(equation, description, inputs, TOL, CHECKED_BY)
}

/// Every case: (folder, stem, case without outputs).
fn cases() -> Vec<(&'static str, String, Value)> {
    let mut v = Vec::new();
    // Eq. (1).
    let fwd = read_case("eq01-covariance", "basic");
    let n = rows::<3>(&fwd["inputs"], "log_scales").len();
    let mut g = upstream(9 * n, 1);
    for i in 0..n {
        // Symmetric upstream gradient (the convention of the library's VJP).
        for r in 0..3 {
            for c in 0..r {
                g[9 * i + 3 * c + r] = g[9 * i + 3 * r + c];
            }
        }
    }
    let mut inputs = fwd["inputs"].clone();
    inputs["d_covariance"] = arr(&[n, 3, 3], g);
    v.push((
        "eq01-covariance-vjp",
        "basic".to_string(),
        vjp_case(
            "Eq. (1), backward",
            "L = sum(d_covariance * Sigma), Sigma = R(q/|q|) S S^T R(q/|q|)^T, S = \
             diag(exp(log_scales)); outputs dL/d log_scales and dL/d quats (the unnormalised \
             (w, x, y, z) as given). d_covariance is symmetric: a backend that takes the 6 \
             unique entries passes 2 d_covariance[i][j] for each off-diagonal pair",
            inputs,
        ),
    ));
    // Eq. (2).
    for (k, stem) in ["rirf-paper", "rirf-xgaussian", "sh"].iter().enumerate() {
        let fwd = read_case("eq02-rirf", stem);
        let n = rows::<16>(&fwd["inputs"], "features").len();
        let n_active = fwd["inputs"]["active_features"].as_array().unwrap().len();
        let mut inputs = fwd["inputs"].clone();
        inputs["d_intensity"] = arr(&[n_active, n], upstream(n_active * n, 10 + k as u64));
        let extra = if *stem == "sh" {
            "; and dL/d means (through the view direction d = (mean - camera_centre) / |mean - \
             camera_centre|), d_means[j][i]"
        } else {
            ""
        };
        v.push((
            "eq02-rirf-vjp",
            stem.to_string(),
            vjp_case(
                "Eq. (2), backward",
                &format!(
                    "L_j = sum_i d_intensity[j][i] intensity[j][i] for K = active_features[j] \
                     (the forward of eq02-rirf/{stem}); outputs d_features[j][i] = dL_j / d \
                     features[i] (zero beyond K, and where max(0, .) clamps){extra}"
                ),
                inputs,
            ),
        ));
    }
    // Eq. (3).
    for (k, stem) in ["cone-centred", "cone-offset-detector", "parallel"]
        .iter()
        .enumerate()
    {
        let fwd = read_case("eq03-projection", stem);
        let n = rows::<3>(&fwd["inputs"], "means").len();
        let mut inputs = fwd["inputs"].clone();
        inputs["d_mean2d"] = arr(&[n, 2], upstream(2 * n, 20 + k as u64));
        inputs["d_conic"] = arr(&[n, 3], upstream(3 * n, 30 + k as u64));
        v.push((
            "eq03-projection-vjp",
            stem.to_string(),
            vjp_case(
                "Eq. (3), backward",
                &format!(
                    "L = sum(d_mean2d * mean2d) + sum(d_conic * conic) for the projection of \
                     eq03-projection/{stem} (conic (A, B, C), B a single parameter); outputs \
                     dL/d means, dL/d log_scales, dL/d quats (unnormalised). Culled Gaussians \
                     (radius 0) get exact zeros; where x/z (or y/z) is clamped inside J the \
                     clamped coordinate has zero derivative but the 1/z factors of J keep \
                     theirs (3DGS's CUDA backward drops a factor 2 there)"
                ),
                inputs,
            ),
        ));
    }
    v
}

fn compute(folder: &str, inputs: &Value) -> Value {
    match folder {
        "eq01-covariance-vjp" => {
            let ls = rows::<3>(inputs, "log_scales");
            let qs = rows::<4>(inputs, "quats");
            let (_, g) = get_arr(inputs, "d_covariance");
            let (mut dl, mut dq) = (Vec::new(), Vec::new());
            for i in 0..ls.len() {
                let (_, parts) = covariance(ls[i], qs[i]).expect("non-degenerate quaternion");
                let gm: [[f64; 3]; 3] =
                    std::array::from_fn(|r| std::array::from_fn(|c| g[9 * i + 3 * r + c]));
                let (a, b) = covariance_vjp(&parts, &gm);
                dl.extend(a);
                dq.extend(b);
            }
            let n = ls.len();
            json!({ "d_log_scales": arr(&[n, 3], dl), "d_quats": arr(&[n, 4], dq) })
        }
        "eq02-rirf-vjp" => {
            let f = rows::<16>(inputs, "features");
            let n = f.len();
            let (mode, means, centre, actives) = intensity_inputs(inputs, n);
            let (_, gi) = get_arr(inputs, "d_intensity");
            let (mut df, mut dm) = (Vec::new(), Vec::new());
            for (j, &k) in actives.iter().enumerate() {
                for i in 0..n {
                    let value = intensity(mode, k, centre, means[i], &f[i]);
                    let (m, d) =
                        intensity_vjp(mode, k, centre, means[i], &f[i], value, gi[j * n + i]);
                    df.extend(d);
                    dm.extend(m);
                }
            }
            let mut out = json!({ "d_features": arr(&[actives.len(), n, N_FEATURES], df) });
            if mode == ColorMode::Sh {
                out["d_means"] = arr(&[actives.len(), n, 3], dm);
            }
            out
        }
        "eq03-projection-vjp" => {
            let geo: ConeBeam = serde_json::from_value(inputs["geometry"].clone()).unwrap();
            let cam = geo.camera(inputs["angle"].as_f64().unwrap());
            let means = rows::<3>(inputs, "means");
            let n = means.len();
            let mut g = Gaussians::<f64>::zeros(n);
            g.means = means;
            g.log_scales = rows::<3>(inputs, "log_scales");
            g.quats = rows::<4>(inputs, "quats");
            let settings = RenderSettings::default();
            let (splats, saved) = project::forward(&g, &cam, &settings).unwrap();
            let d = SplatGrads {
                mean2d: rows::<2>(inputs, "d_mean2d"),
                conic: rows::<3>(inputs, "d_conic"),
                opacity: vec![0.0; n],
                color: vec![0.0; n],
            };
            let p = project::backward(&g, &cam, &settings, &splats, &saved, &d);
            json!({
                "d_means": arr(&[n, 3], p.means.into_flattened()),
                "d_log_scales": arr(&[n, 3], p.log_scales.into_flattened()),
                "d_quats": arr(&[n, 4], p.quats.into_flattened()),
            })
        }
        _ => panic!("unknown golden folder {folder}"),
    }
}

#[test]
fn vjp_golden_files_match_the_rust_backward() {
    let mut checked = 0;
    for (folder, stem, mut c) in cases() {
        if regen_requested() {
            c["outputs"] = compute(folder, &c["inputs"]);
            write_case(folder, &stem, &c);
        }
        check_case(folder, &stem, |inputs| compute(folder, inputs));
        checked += 1;
    }
    assert_eq!(checked, 7);
}

#[test]
fn vjp_cases_exercise_the_clamp_and_the_culling() {
    // cone-centred: Gaussian 2 has x/z clamped (nonzero gradient), 3..5 are culled (zeros).
    let c = read_case("eq03-projection-vjp", "cone-centred");
    let dm = rows::<3>(&c["outputs"], "d_means");
    let dq = rows::<4>(&c["outputs"], "d_quats");
    assert!(dm[..3].iter().all(|r| r.iter().any(|&x| x != 0.0)));
    assert!(dm[3..].iter().all(|r| r.iter().all(|&x| x == 0.0)));
    assert!(dq[3..].iter().all(|r| r.iter().all(|&x| x == 0.0)));
    // xgaussian: some clamped intensities give exactly zero feature gradients, others not.
    let x = read_case("eq02-rirf-vjp", "rirf-xgaussian");
    let df = rows::<16>(&x["outputs"], "d_features");
    assert!(df.iter().any(|r| r.iter().all(|&v| v == 0.0)));
    assert!(df.iter().any(|r| r[0] != 0.0));
}

#[test]
fn numpy_reference_agrees() {
    run_numpy_reference("tools/vjp_reference.py");
}
