//! The loss stage's own checks (`SpwmConfig::validate`, `LossConfig::validate`, which the
//! Python module calls) at both ends of every range, from the documented meaning of each
//! setting: a value just inside is accepted, one just outside (and NaN, and the infinities
//! where the range is finite) is refused with an error naming the field.

use unispine::loss::spwm::SpwmConfig;
use unispine::loss::LossConfig;

/// A setting's name, how to set it, the values accepted and the values refused.
type Case<C> = (&'static str, fn(&mut C, f64), Vec<f64>, Vec<f64>);

fn spwm_cases() -> Vec<Case<SpwmConfig>> {
    let (inf, nan) = (f64::INFINITY, f64::NAN);
    vec![
        (
            "alpha",
            |c, v| c.alpha = v,
            vec![0.0, 1.0, 7.5],
            vec![-1e-9, inf, nan],
        ),
        (
            "hf_lambda",
            |c, v| c.hf_lambda = v,
            vec![0.0, 3.0],
            vec![-1e-9, inf, nan],
        ),
        (
            "blur_kernel",
            |c, v| c.blur_kernel = v as usize,
            vec![1.0, 4.0],
            vec![0.0],
        ),
        (
            "blur_sigma",
            |c, v| c.blur_sigma = v,
            vec![1e-9, 2.0],
            vec![0.0, -1.0, inf, nan],
        ),
        (
            "quantile",
            |c, v| c.quantile = v,
            vec![0.0, 1.0],
            vec![-1e-9, 1.0 + 1e-9, nan],
        ),
        (
            "tau_max",
            |c, v| c.tau_max = v,
            vec![0.0, 1.0],
            vec![-1e-9, 1.0 + 1e-9, nan],
        ),
        (
            "fixed_tau",
            |c, v| c.fixed_tau = v,
            vec![0.0, 1.0],
            vec![-1e-9, 1.0 + 1e-9, nan],
        ),
        (
            "gate_temperature",
            |c, v| c.gate_temperature = v,
            vec![1e-9, 5.0],
            vec![0.0, -1.0, inf, nan],
        ),
    ]
}

fn loss_cases() -> Vec<Case<LossConfig>> {
    let (inf, nan) = (f64::INFINITY, f64::NAN);
    vec![
        (
            "lambda_dssim",
            |c, v| c.lambda_dssim = v,
            vec![0.0, 1.0],
            vec![-1e-9, 1.0 + 1e-9, nan],
        ),
        (
            "charbonnier_eps",
            |c, v| c.charbonnier_eps = v,
            vec![0.0, 2.0],
            vec![-1e-9, inf, nan],
        ),
        (
            "delta",
            |c, v| c.delta = v,
            vec![0.0, 2.0],
            vec![-1e-9, inf, nan],
        ),
    ]
}

/// Each case of `cases` on a default `C`: the accepted values pass `validate`, the refused
/// ones fail it with an error naming `prefix.field`.
fn check<C: Default>(prefix: &str, cases: Vec<Case<C>>, validate: fn(&C) -> unispine::Result<()>) {
    assert!(
        validate(&C::default()).is_ok(),
        "{prefix}: the defaults refused"
    );
    for (field, set, good, bad) in cases {
        for (v, ok) in good
            .into_iter()
            .map(|v| (v, true))
            .chain(bad.into_iter().map(|v| (v, false)))
        {
            let mut c = C::default();
            set(&mut c, v);
            match (validate(&c), ok) {
                (Ok(()), true) => {}
                (Err(e), false) => {
                    assert!(
                        e.to_string().contains(&format!("{prefix}.{field}")),
                        "{field} = {v}: {e}"
                    )
                }
                (r, _) => panic!("{prefix}.{field} = {v}: {r:?}"),
            }
        }
    }
}

#[test]
fn spwm_settings_are_checked_at_both_ends_of_every_range() {
    check("spwm", spwm_cases(), SpwmConfig::validate);
}

#[test]
fn loss_settings_are_checked_at_both_ends_of_every_range() {
    check("loss", loss_cases(), LossConfig::validate);
}

/// The three named loss settings, as their documents state them: 3DGS / X-Gaussian's
/// 0.8 L1 + 0.2 (1 - SSIM), plain Charbonnier, and UniSpine-GS's Eqs. (8)-(9) (eps 1e-3,
/// delta 1e-6), each with lambda_dssim = 0.2.
#[test]
fn named_loss_settings_hold_their_data_terms() {
    use unispine::loss::DataTerm;
    for (c, term) in [
        (LossConfig::l1_dssim(), DataTerm::L1),
        (LossConfig::charbonnier_dssim(), DataTerm::Charbonnier),
        (
            LossConfig::weighted_charbonnier_dssim(),
            DataTerm::WeightedCharbonnier,
        ),
    ] {
        assert_eq!(c.data_term, term);
        assert_eq!(
            (c.lambda_dssim, c.charbonnier_eps, c.delta),
            (0.2, 1e-3, 1e-6),
            "{term:?}"
        );
    }
}

/// The gate's thresholds may reach 1 (both checks allow it): the soft gate's denominator
/// `1 - tau + 1e-6` stays positive, so the gate is finite, 0 wherever the attention is below 1,
/// for the adaptive and the fixed threshold alike.
#[test]
fn a_gate_threshold_of_one_gives_a_finite_gate() {
    use unispine::image2d::Image2d;
    use unispine::loss::spwm;
    let (w, h) = (23, 17);
    let gt = Image2d::from_vec(
        w,
        h,
        (0..w * h)
            .map(|p| ((p * 37 % 101) as f64 / 100.0).powi(2))
            .collect(),
    );
    for adaptive in [true, false] {
        let cfg = SpwmConfig {
            adaptive_gate: adaptive,
            quantile: 1.0,
            tau_max: 1.0,
            fixed_tau: 1.0,
            ..SpwmConfig::default()
        };
        assert!(cfg.validate().is_ok());
        let a = spwm::attention(&gt, &cfg);
        for (g, att) in a.gate.data.iter().zip(&a.attention.data) {
            assert!(
                g.is_finite() && (0.0..=1.0).contains(g),
                "adaptive {adaptive}: {g}"
            );
            if *att < a.tau {
                assert_eq!(*g, 0.0, "adaptive {adaptive}");
            }
        }
        assert!(spwm::view_prior(&gt, &cfg)
            .data
            .iter()
            .all(|v| v.is_finite()));
    }
}
