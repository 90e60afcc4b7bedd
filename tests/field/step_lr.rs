//! The field trainer past its StepLR step: the rate it reports and the rate it uses (an Adam
//! step replayed here at the reported rate).

#[test]
fn the_field_trainer_reports_and_uses_step_lr_past_its_step() {
    use unispine::dataset::generate::{generate, GenerateOptions};
    use unispine::field::train::FieldTrainer;
    use unispine::field::FieldConfig;
    let mut vol = unispine::volume::Volume::<f32>::zeros([12, 12, 12], [5.0; 3]);
    for z in 4..8 {
        for y in 4..8 {
            for x in 4..8 {
                vol.data[(z * 12 + y) * 12 + x] = 0.02;
            }
        }
    }
    let opts = GenerateOptions {
        train_views: 2,
        test_views: 1,
        detector: 12,
        ..Default::default()
    };
    let ds = generate(&vol, &opts, &|_, _| {}).unwrap();
    let mut cfg = FieldConfig::preset("intratomo", 2).unwrap();
    cfg.n_rays = 16;
    cfg.n_samples = 8;
    cfg.lr_step = 3;
    cfg.lr_gamma = 0.5;
    let lr0 = cfg.lr;
    let mut flat = cfg.clone();
    flat.lr_gamma = 1.0;
    let mut tr = FieldTrainer::new(cfg, &ds).unwrap();
    let mut tr_flat = FieldTrainer::new(flat, &ds).unwrap();
    let params = |t: &FieldTrainer| t.checkpoint(0.0, "").params;
    for it in 1..=10usize {
        let (before, before_flat) = (params(&tr), params(&tr_flat));
        let st = tr.step().unwrap();
        let st_flat = tr_flat.step().unwrap();
        let want = lr0 * 0.5f64.powi(((it - 1) / 3) as i32);
        assert_eq!(st.iteration, it);
        assert!(
            (st.lr - want).abs() <= 1e-15 * lr0,
            "it {it}: lr {} vs {want}",
            st.lr
        );
        assert_eq!(st_flat.lr, lr0, "it {it}");
        // Iterations 1-3 run at lr0 in both runs (same bits); iteration 4 starts from the same
        // state with the same gradient and Adam moments, so its update is half the flat run's.
        let step = |a: &[f32], b: &[f32]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .map(|(x, y)| (*y as f64) - (*x as f64))
                .collect()
        };
        let (after, after_flat) = (params(&tr), params(&tr_flat));
        if it <= 3 {
            assert_eq!(after, after_flat, "it {it}");
        }
        if it == 4 {
            assert_eq!(before, before_flat);
            let (d, d_flat) = (step(&before, &after), step(&before_flat, &after_flat));
            let big = d_flat.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(big > 0.1 * lr0, "{big}");
            for (x, y) in d.iter().zip(&d_flat) {
                // f32 parameters: the updates are rounded to the parameter's ulp.
                let ulp = 4.0
                    * f32::EPSILON as f64
                    * before.iter().fold(1.0f32, |m, p| m.max(p.abs())) as f64;
                assert!((x - 0.5 * y).abs() <= ulp, "update {x} vs half of {y}");
            }
        }
    }
}
