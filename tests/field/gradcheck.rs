//! The neural-field stages against f64 central differences (MLP with skips and each output
//! activation, hash grid, the whole line-integral loss with the hash grid and the frequency
//! encoder), closed forms (frequency encoding, the line integral of a constant field), Adam by
//! hand, bit-identical gradients for 1, 2 and 8 threads, and errors naming bad settings.

use rand_chacha::ChaCha8Rng;
use unispine::field::encode::{Encoder, Frequency, HashGrid};
use unispine::field::mlp::{Mlp, OutAct};
use unispine::field::render::{self, Ray};
use unispine::field::train::{loss_and_grad, Sampling};

use crate::small_cfg;
use unispine::field::{EncoderConfig, Field, FieldConfig};
use unispine::simd::Simd;

/// Relative error of a parameter group: `|analytic - fd| / |fd|` (2-norms over the group).
#[derive(Default)]
struct Group {
    diff2: f64,
    ref2: f64,
}

impl Group {
    fn add(&mut self, analytic: f64, fd: f64) {
        self.diff2 += (analytic - fd).powi(2);
        self.ref2 += fd * fd;
    }
    fn rel(&self) -> f64 {
        assert!(
            self.ref2 > 0.0,
            "a group with a zero reference gradient checks nothing"
        );
        (self.diff2 / self.ref2).sqrt()
    }
}

#[test]
fn mlp_matches_central_differences() {
    for act in [OutAct::Sigmoid, OutAct::LeakyRelu, OutAct::Softplus] {
        let m = Mlp::new(5, 6, 5, &[2, 3], act).unwrap();
        let p: Vec<f64> = m.init(7);
        let n = 9;
        let x: Vec<f64> = (0..n * 5)
            .map(|i| ((i * 37 % 23) as f64 / 23.0) - 0.4)
            .collect();
        let c: Vec<f64> = (0..n).map(|i| 0.3 + 0.1 * i as f64).collect();
        let loss = |p: &[f64], x: &[f64]| -> f64 {
            let (y, _) = m.forward(p, x, n, false);
            y.iter().zip(&c).map(|(a, b)| a * b).sum()
        };
        let (_, cache) = m.forward(&p, &x, n, true);
        let mut g = vec![0.0; m.n_params];
        let mut gx = vec![0.0; n * 5];
        m.backward(&p, &cache, &c, n, &mut g, Some(&mut gx));
        let h = 1e-6;
        let (mut gp, mut gi) = (Group::default(), Group::default());
        for i in 0..m.n_params {
            let mut a = p.clone();
            a[i] += h;
            let mut b = p.clone();
            b[i] -= h;
            gp.add(g[i], (loss(&a, &x) - loss(&b, &x)) / (2.0 * h));
        }
        for i in 0..n * 5 {
            let mut a = x.clone();
            a[i] += h;
            let mut b = x.clone();
            b[i] -= h;
            gi.add(gx[i], (loss(&p, &a) - loss(&p, &b)) / (2.0 * h));
        }
        let (ep, ei) = (gp.rel(), gi.rel());
        eprintln!("mlp {act:?}: weights {ep:.2e}, input {ei:.2e}");
        assert!(ep < 1e-7 && ei < 1e-7, "{act:?}: weights {ep}, input {ei}");
    }
}

#[test]
fn hash_grid_matches_central_differences() {
    // 3 levels (R = 2, 4, 8), T = 64: level 0 dense (27 entries), levels 1-2 hashed.
    let h = HashGrid::new(3, 2, 6, 2, 0.3);
    assert_eq!(h.offsets, vec![0, 27, 27 + 64, 27 + 128]);
    let table: Vec<f64> = (0..h.n_params())
        .map(|i| ((i * 29 % 31) as f64 / 31.0) - 0.5)
        .collect();
    let pts: Vec<[f64; 3]> = (0..7)
        .map(|i| {
            let t = i as f64;
            [
                0.29 * (t * 0.7).sin(),
                -0.2 + 0.05 * t,
                0.25 * (t * 1.3).cos(),
            ]
        })
        .collect();
    let od = h.out_dim();
    let gout: Vec<f64> = (0..pts.len() * od)
        .map(|i| 0.1 * (i % 5) as f64 - 0.2)
        .collect();
    let loss = |t: &[f64]| -> f64 {
        let mut s = 0.0;
        let mut o = vec![0.0; od];
        for (n, p) in pts.iter().enumerate() {
            h.encode(t, *p, &mut o);
            for k in 0..od {
                s += o[k] * gout[n * od + k];
            }
        }
        s
    };
    let mut g = vec![0.0; h.n_params()];
    h.backward(Simd::active(), &pts, &gout, od, 0, &mut g);
    let eps = 1e-6;
    let mut grp = Group::default();
    let mut touched = 0;
    for i in 0..h.n_params() {
        let mut a = table.clone();
        a[i] += eps;
        let mut b = table.clone();
        b[i] -= eps;
        let fd = (loss(&a) - loss(&b)) / (2.0 * eps);
        grp.add(g[i], fd);
        // An entry no point touches has exactly zero gradient both ways.
        assert!(
            g[i] != 0.0 || fd.abs() < 1e-9,
            "entry {i}: {} vs {fd}",
            g[i]
        );
        touched += (g[i] != 0.0) as usize;
    }
    assert!(touched > 20, "only {touched} entries touched");
    eprintln!("hash grid: {:.2e}", grp.rel());
    assert!(grp.rel() < 1e-8, "relative error {}", grp.rel());
    // Trilinear weights sum to 1: a constant table gives a constant encoding.
    let ones = vec![1.0; h.n_params()];
    let mut o = vec![0.0; od];
    h.encode(&ones, pts[3], &mut o);
    assert!(o.iter().all(|&v| (v - 1.0).abs() < 1e-12), "{o:?}");
}

#[test]
fn frequency_encoding_closed_form() {
    let f = Frequency { bands: 3 };
    assert_eq!(f.out_dim(), 21);
    let x = [0.1f64, -0.2, 0.25];
    let mut o = vec![0.0; 21];
    f.encode(x, &mut o);
    assert_eq!(&o[..3], &x);
    for k in 0..3 {
        let fr = (1 << k) as f64;
        for d in 0..3 {
            assert_eq!(o[3 + 6 * k + d], (fr * x[d]).sin());
            assert_eq!(o[3 + 6 * k + 3 + d], (fr * x[d]).cos());
        }
    }
}

fn rays() -> Vec<Ray> {
    // Rays through the cube from a source 1 m away (metres, unnormalised directions).
    (0..5)
        .map(|i| Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, -0.1 + 0.05 * i as f64, 0.02 * i as f64 - 0.03],
        })
        .collect()
}

fn jitter(i: usize) -> ChaCha8Rng {
    render::ray_rng(3, 9, 1, i as u64)
}

#[test]
fn field_loss_matches_central_differences() {
    let encs = [
        EncoderConfig::HashGrid {
            levels: 3,
            features: 2,
            table_size: 64,
            base_resolution: 2,
        },
        EncoderConfig::Frequency { bands: 2 },
    ];
    for enc in encs {
        for act in [OutAct::Sigmoid, OutAct::LeakyRelu] {
            let mut cfg = small_cfg(enc.clone());
            cfg.last_activation = act;
            let mut f = Field::<f64>::new(&cfg).unwrap();
            let ne = f.n_encoder_params();
            // Larger hash features than the init so that the encoder matters.
            for (i, v) in f.params[..ne].iter_mut().enumerate() {
                *v = 0.3 * (((i * 13) % 17) as f64 / 17.0 - 0.5);
            }
            let r = rays();
            let targets: Vec<f64> = (0..r.len()).map(|i| 0.05 + 0.02 * i as f64).collect();
            let sampling = Sampling::new((0.7, 1.3), cfg.n_samples, 0.3, &jitter);
            let (_, g) = loss_and_grad(&f, &r, &targets, &sampling);
            let h = 1e-6;
            let (mut genc, mut gmlp) = (Group::default(), Group::default());
            let mut nonzero = 0;
            for (i, &gi) in g.iter().enumerate().take(f.params.len()) {
                if i < ne && gi == 0.0 && i % 3 != 0 {
                    continue; // untouched hash entries: check every third one only
                }
                let mut a = f.clone();
                a.params[i] += h;
                let mut b = f.clone();
                b.params[i] -= h;
                let la = loss_and_grad(&a, &r, &targets, &sampling).0;
                let lb = loss_and_grad(&b, &r, &targets, &sampling).0;
                let fd = (la - lb) / (2.0 * h);
                if i < ne {
                    genc.add(gi, fd);
                    nonzero += (gi != 0.0) as usize;
                } else {
                    gmlp.add(gi, fd);
                }
            }
            let em = gmlp.rel();
            eprintln!("field {enc:?} {act:?}: mlp {em:.2e}");
            assert!(em < 1e-6, "{enc:?} {act:?}: mlp {em}");
            if ne > 0 {
                let ee = genc.rel();
                eprintln!("field {enc:?} {act:?}: encoder {ee:.2e}");
                assert!(ee < 1e-6, "{enc:?} {act:?}: encoder {ee}");
                assert!(nonzero > 20, "{nonzero} encoder gradients");
            }
        }
    }
}

#[test]
fn constant_field_integrates_to_mu_times_length() {
    let ray = Ray {
        o: [1.0, 0.0, 0.0],
        d: [-1.0, 0.1, 0.0],
    };
    let mut rng = jitter(0);
    let t = render::stratified(0.8, 1.2, 16, &mut rng);
    assert!(t.windows(2).all(|w| w[0] <= w[1]));
    assert!(t[0] >= 0.8 && t[15] <= 1.2);
    let (mut pts, mut delta) = (Vec::<[f64; 3]>::new(), Vec::<f64>::new());
    render::samples(&ray, &t, 0.3, &mut pts, &mut delta);
    let mu = vec![0.7; 16];
    let norm = (1.0f64 + 0.01).sqrt();
    let want = 0.7 * ((t[15] - t[0]) * norm + 1e-10 * norm);
    let got = render::line_integral(&mu, &delta);
    assert!((got - want).abs() < 1e-13, "{got} {want}");
    // Clamped to the cube.
    assert!(pts.iter().all(|p| p.iter().all(|v| v.abs() <= 0.3 - 1e-6)));
}

#[test]
fn gradients_are_bit_identical_for_1_2_8_threads() {
    let cfg = small_cfg(EncoderConfig::HashGrid {
        levels: 4,
        features: 2,
        table_size: 256,
        base_resolution: 4,
    });
    let f = Field::<f32>::new(&cfg).unwrap();
    let r: Vec<Ray> = (0..37)
        .map(|i| Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, -0.1 + 0.005 * i as f64, 0.002 * i as f64 - 0.03],
        })
        .collect();
    let targets: Vec<f32> = (0..r.len()).map(|i| 0.01 * i as f32).collect();
    let mut out = Vec::new();
    for t in [1, 2, 8] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        let (l, g) = pool.install(|| {
            loss_and_grad(
                &f,
                &r,
                &targets,
                &Sampling::new((0.7, 1.3), 6, 0.3, &jitter),
            )
        });
        out.push((
            l.to_bits(),
            g.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        ));
    }
    assert_eq!(out[0], out[1]);
    assert_eq!(out[0], out[2]);
}

#[test]
fn bad_settings_name_the_setting() {
    let mut c = small_cfg(EncoderConfig::HashGrid {
        levels: 4,
        features: 2,
        table_size: 1000,
        base_resolution: 4,
    });
    let e = Field::<f32>::new(&c).unwrap_err().to_string();
    assert!(
        e.contains("table_size") && e.contains("power of two"),
        "{e}"
    );
    c.encoder = EncoderConfig::Frequency { bands: 2 };
    c.n_samples = 0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("n_samples"), "{e}");
    c.n_samples = 4;
    c.skips = vec![3];
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("skips") && e.contains("skip layer 3"), "{e}");
    let e = FieldConfig::preset("tensorf-lite", 50)
        .unwrap_err()
        .to_string();
    assert!(e.contains("tensorf-lite"), "{e}");
    // Encoder enum and preset presets agree on the NAF layout.
    let naf = FieldConfig::preset("naf-full", 50).unwrap();
    assert_eq!(naf.iterations, 75_000);
    assert_eq!(naf.lr_step, 25_000);
    match naf.build_encoder() {
        Encoder::HashGrid(h) => assert_eq!(h.n_params(), 14_262_438),
        _ => panic!("naf uses the hash grid"),
    }
}

#[test]
fn diverging_run_names_the_iteration() {
    use unispine::dataset::generate::{generate, GenerateOptions};
    let mut vol = unispine::volume::Volume::<f32>::zeros([8, 8, 8], [10.0; 3]);
    vol.data.iter_mut().for_each(|v| *v = 0.02);
    let opts = GenerateOptions {
        train_views: 2,
        test_views: 1,
        detector: 8,
        ..Default::default()
    };
    let ds = generate(&vol, &opts, &|_, _| {}).unwrap();
    let mut cfg = FieldConfig::preset("nerf", 2).unwrap();
    cfg.hidden_dim = 8;
    cfg.n_rays = 8;
    cfg.n_samples = 4;
    // Adam moves every parameter by about lr: 1e30 at step 1, then the f32 products overflow.
    cfg.lr = 1e30;
    let mut tr = unispine::field::train::FieldTrainer::new(cfg, &ds).unwrap();
    let first = tr.step().unwrap();
    assert_eq!(first.iteration, 1);
    let e = tr.step().unwrap_err();
    assert!(
        matches!(e, unispine::Error::Diverged { iteration: 2, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("iteration 2"), "{e}");
}
