//! A tiny synthetic training set shared by the trainer and run-folder tests: a 32 x 32
//! detector, 8 training and 4 test views, 512 ACUI Gaussians; the ground truth is rendered from
//! a hidden set of 12 Gaussians, so no projector is needed.

use unispine::dataset::{Dataset, Manifest, Split};
use unispine::gaussians::Gaussians;
use unispine::geometry::ConeBeam;
use unispine::render::{self, ColorMode, RenderSettings};
use unispine::train::{Method, TrainConfig};

pub fn geometry() -> ConeBeam {
    // 64 mm box, magnification 1.5 -> 96 mm on a 32 px detector at 3 mm.
    ConeBeam::centred([32, 32], [3.0, 3.0], [32, 32, 32], [2.0, 2.0, 2.0])
}

pub fn hidden() -> Gaussians<f64> {
    let n = 12;
    let mut g = Gaussians::<f64>::zeros(n);
    for i in 0..n {
        let t = i as f64;
        g.means[i] = [
            18.0 * (1.3 * t).sin(),
            18.0 * (0.7 * t + 1.0).cos(),
            -22.0 + 4.0 * t,
        ];
        g.log_scales[i] = [(3.0 + (t % 3.0)).ln(), 4.0f64.ln(), (2.5 + (t % 2.0)).ln()];
        g.quats[i] = [1.0, 0.1 * t.sin(), 0.2, -0.1];
        g.opacity_logits[i] = 0.5 + 0.2 * (t % 4.0);
        g.features[i][0] = 0.8 + 0.3 * (t % 3.0);
    }
    g
}

pub fn dataset() -> Dataset {
    let geo = geometry();
    let g = hidden();
    let settings = RenderSettings {
        color: ColorMode::RirfXgaussian,
        active_features: 1,
        background: 0.0,
        ..Default::default()
    };
    let split = |angles: Vec<f64>| Split {
        projections: angles
            .iter()
            .map(|&a| {
                let (img, _) = render::forward(&g, &geo.camera(a), &settings).unwrap();
                img.cast::<f32>()
            })
            .collect(),
        angles,
    };
    let pi = std::f64::consts::PI;
    Dataset {
        train: split((0..8).map(|k| k as f64 * pi / 8.0).collect()),
        test: split((0..4).map(|k| (k as f64 + 0.5) * pi / 4.0).collect()),
        geometry: geo,
        manifest: Manifest::default(),
        volume: None,
    }
}

pub fn tiny(method: Method, iters: usize) -> TrainConfig {
    let mut c = TrainConfig::preset(method);
    c.iterations = iters;
    c.init.interval = 4; // 8^3 = 512 Gaussians
    c.densify.from_iter = 10;
    c.densify.until_iter = iters.saturating_sub(10);
    c.densify.interval = 10;
    c.densify.opacity_reset_interval = 1000;
    c.densify.grad_threshold = 1e-4;
    c.feature_step_interval = 20;
    c.lr.position_max_steps = iters;
    c.eval_iterations = vec![1];
    c.checkpoint_every = 10;
    c.preview_views = 2;
    // The paper's learning rates are tuned for 20000 iterations; ten times larger ones let a
    // few dozen iterations show progress.
    c.lr.feature *= 10.0;
    c.lr.opacity *= 10.0;
    c.lr.scaling *= 10.0;
    c.lr.rotation *= 10.0;
    c
}
