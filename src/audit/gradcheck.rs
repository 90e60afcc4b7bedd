//! Gradient check of the whole render (projection, Eq. 3, then compositing, Eqs. 4-5): the
//! analytic gradient ([`crate::render::backward`]) against 5-point central finite differences
//! in f64 ([`crate::math::fd`]) of L = sum(W * image) with a fixed random W, for every parameter
//! group (means, log_scales, quats, opacity_logits, features), as [`Row`]s of stage `render`.
//!
//! The scenes are small (32 x 24 detector, 3-8 Gaussians) and chosen away from every hard
//! cutoff of the rasterizer, where the function is not differentiable: [`margins`] measures the
//! distance to each cutoff and `tests/render/gradcheck.rs` asserts it. Every Gaussian's 3-sigma square
//! covers the image with 2 px to spare (so its tile rectangle cannot change under a
//! perturbation), o G stays inside (1/255, 0.99) at every pixel, and the final transmittance
//! stays far above 1e-4.
//!
//! `unispine gradcheck` prints these rows; `tests/render/gradcheck.rs` asserts them.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::audit::Row;
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::geometry::{Camera, ConeBeam, Mode};
use crate::image2d::Image2d;
use crate::math::fd;
use crate::real::Real;
use crate::render::{self, composite, tiles, ColorMode, RenderSettings};

/// Names of the parameter groups, in the order of [`GroupErrors`].
pub const GROUPS: [&str; 5] = ["means", "log_scales", "quats", "opacity_logits", "features"];

/// A named gradcheck scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: &'static str,
    pub geometry: ConeBeam,
    pub angle: f64,
    pub gaussians: Gaussians<f64>,
    pub background: f64,
}

impl Scene {
    /// The scene's camera.
    pub fn camera(&self) -> Camera {
        self.geometry.camera(self.angle)
    }
    /// Render settings for a colour mode (all 16 features active).
    pub fn settings(&self, color: ColorMode) -> RenderSettings {
        RenderSettings {
            color,
            active_features: N_FEATURES,
            background: self.background,
            ..Default::default()
        }
    }
    /// The fixed upstream gradient W (uniform in [-1, 1], seeded by the scene).
    pub fn weights(&self) -> Image2d<f64> {
        let (w, h) = self.geometry.image_size();
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed ^ self.gaussians.len() as u64);
        Image2d::from_vec(
            w,
            h,
            (0..w * h).map(|_| rng.random_range(-1.0..1.0)).collect(),
        )
    }
}

fn geometry(mode: Mode, pitch: f64, off: [f64; 2]) -> ConeBeam {
    ConeBeam {
        off_detector: off,
        mode,
        ..ConeBeam::centred([24, 32], [pitch, pitch], [16, 16, 16], [2.0, 2.0, 2.0])
    }
}

/// `n` Gaussians near the isocentre: scales 9-13 mm (13-20 px on these detectors), random
/// rotations, opacities 0.31-0.55, features giving intensities well above 0.
fn gaussians(n: usize, seed: u64) -> Gaussians<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut g = Gaussians::zeros(n);
    for i in 0..n {
        g.means[i] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
        g.log_scales[i] = std::array::from_fn(|_| rng.random_range(9.0f64..13.0).ln());
        g.quats[i] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        g.quats[i][0] += 1.5;
        g.opacity_logits[i] = rng.random_range(-0.8..0.2);
        g.features[i] = std::array::from_fn(|k| {
            if k == 0 {
                0.8
            } else {
                rng.random_range(-0.1..0.1)
            }
        });
    }
    g
}

/// The `small` scenes: a centred cone beam (5 Gaussians), a cone beam with an offset detector
/// and a background (8 Gaussians), a parallel beam (3 Gaussians).
pub fn small_scenes() -> Vec<Scene> {
    vec![
        Scene {
            name: "cone",
            geometry: geometry(Mode::Cone, 1.0, [0.0, 0.0]),
            angle: 0.4,
            gaussians: gaussians(5, 11),
            background: 0.0,
        },
        Scene {
            name: "cone-offset-bg",
            geometry: geometry(Mode::Cone, 1.0, [1.5, -1.0]),
            angle: 2.2,
            gaussians: gaussians(8, 12),
            background: 0.3,
        },
        Scene {
            name: "parallel",
            geometry: geometry(Mode::Parallel, 0.7, [0.5, 0.25]),
            angle: 4.0,
            gaussians: gaussians(3, 13),
            background: 0.0,
        },
    ]
}

/// Scenes by name: `small` (all three) or one of them by its name.
pub fn scenes(name: &str) -> crate::Result<Vec<Scene>> {
    let all = small_scenes();
    if name == "small" {
        return Ok(all);
    }
    let names: Vec<&str> = all.iter().map(|s| s.name).collect();
    all.into_iter()
        .find(|s| s.name == name)
        .map(|s| vec![s])
        .ok_or_else(|| {
            crate::Error::invalid(
                "--scene",
                format!("unknown scene `{name}` (small, {})", names.join(", ")),
            )
        })
}

/// Distances of a scene to the hard cutoffs of the rasterizer (f64 render).
#[derive(Clone, Copy, Debug)]
pub struct Margins {
    /// min over (pixel, drawn Gaussian) of ln(o G) - ln(1/255) (positive: above the skip).
    pub log_alpha_over_skip: f64,
    /// min of 0.99 - o G (positive: below the clamp).
    pub below_clamp: f64,
    /// min over pixels of T_final / 1e-4.
    pub t_final_over_stop: f64,
    /// min over drawn Gaussians of the distance (px) by which the 3-sigma square overhangs the
    /// image on each side (positive: the tile rectangle is the whole grid).
    pub square_overhang: f64,
    /// Number of Gaussians drawn.
    pub drawn: usize,
}

/// [`Margins`] of `scene` in colour mode `color`.
pub fn margins(scene: &Scene, color: ColorMode) -> crate::Result<Margins> {
    let cam = scene.camera();
    let st = scene.settings(color);
    let (_, saved) = render::forward(&scene.gaussians, &cam, &st)?;
    let s = &saved.splats;
    let (w, h) = (cam.width, cam.height);
    let mut m = Margins {
        log_alpha_over_skip: f64::INFINITY,
        below_clamp: f64::INFINITY,
        t_final_over_stop: f64::INFINITY,
        square_overhang: f64::INFINITY,
        drawn: 0,
    };
    for i in 0..s.radius.len() {
        if !tiles::drawn(s, i) {
            continue;
        }
        m.drawn += 1;
        let r = s.radius[i] as f64;
        let [u, v] = s.mean2d[i];
        m.square_overhang = m
            .square_overhang
            .min(r - u)
            .min(u + r - w as f64)
            .min(r - v)
            .min(v + r - h as f64);
        let [a, b, c] = s.conic[i];
        for row in 0..h {
            for col in 0..w {
                let dx = col as f64 + 0.5 - u;
                let dy = row as f64 + 0.5 - v;
                let og = s.opacity[i] * (-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy).exp();
                m.log_alpha_over_skip = m.log_alpha_over_skip.min((255.0 * og).ln());
                m.below_clamp = m.below_clamp.min(composite::ALPHA_MAX - og);
            }
        }
    }
    for &t in &saved.composite.final_t {
        m.t_final_over_stop = m.t_final_over_stop.min(t / composite::T_MIN);
    }
    Ok(m)
}

/// Per-group errors of one check.
#[derive(Clone, Copy, Debug)]
pub struct GroupErrors {
    /// max |analytic - FD| per group.
    pub max_abs: [f64; 5],
    /// max |analytic - FD| / max |FD| per group ([`fd::rel_err_maxabs`]).
    pub rel: [f64; 5],
    /// max |FD| per group (the scale).
    pub scale: [f64; 5],
}

fn flatten(g: &Gaussians<f64>) -> Vec<Vec<f64>> {
    vec![
        g.means.concat(),
        g.log_scales.concat(),
        g.quats.concat(),
        g.opacity_logits.clone(),
        g.features.concat(),
    ]
}

fn set_group(g: &mut Gaussians<f64>, group: usize, v: &[f64]) {
    fn put<const N: usize>(dst: &mut [[f64; N]], v: &[f64]) {
        for (d, c) in dst.iter_mut().zip(v.chunks(N)) {
            d.copy_from_slice(c);
        }
    }
    match group {
        0 => put(&mut g.means, v),
        1 => put(&mut g.log_scales, v),
        2 => put(&mut g.quats, v),
        3 => g.opacity_logits.copy_from_slice(v),
        _ => put(&mut g.features, v),
    }
}

/// L = sum(W * image) of the f64 render of `g`.
fn loss(g: &Gaussians<f64>, cam: &Camera, st: &RenderSettings, w: &Image2d<f64>) -> f64 {
    let (img, _) = render::forward(g, cam, st).expect("finite scene");
    img.data.iter().zip(&w.data).map(|(a, b)| a * b).sum()
}

/// Analytic gradient of L = sum(W * image) for `scene` in precision `R`, flattened per group.
pub fn analytic<R: Real>(scene: &Scene, color: ColorMode) -> crate::Result<Vec<Vec<f64>>> {
    let cam = scene.camera();
    let st = scene.settings(color);
    let g = scene.gaussians.cast::<R>();
    let (_, saved) = render::forward(&g, &cam, &st)?;
    let grads = render::backward(&g, &cam, &st, &saved, &scene.weights().cast::<R>());
    Ok(flatten(&grads.params.cast::<f64>()))
}

/// Rendered image of `scene` in precision `R`, widened to f64.
pub fn image<R: Real>(scene: &Scene, color: ColorMode) -> crate::Result<Vec<f64>> {
    let g = scene.gaussians.cast::<R>();
    let (img, _) = render::forward(&g, &scene.camera(), &scene.settings(color))?;
    Ok(img.data.iter().map(|x| x.f64()).collect())
}

/// Analytic (f64) against 5-point central differences (step 1e-3 in every group: mm for means,
/// log units, quaternion units, logits, feature units).
pub fn check(scene: &Scene, color: ColorMode) -> crate::Result<GroupErrors> {
    let cam = scene.camera();
    let st = scene.settings(color);
    let w = scene.weights();
    let an = analytic::<f64>(scene, color)?;
    let base = flatten(&scene.gaussians);
    let mut out = GroupErrors {
        max_abs: [0.0; 5],
        rel: [0.0; 5],
        scale: [0.0; 5],
    };
    for k in 0..5 {
        let mut g = scene.gaussians.clone();
        let num = fd::central_diff5(
            |v| {
                set_group(&mut g, k, v);
                loss(&g, &cam, &st, &w)
            },
            &base[k],
            1e-3,
        );
        out.max_abs[k] = an[k]
            .iter()
            .zip(&num)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        out.scale[k] = num.iter().map(|x| x.abs()).fold(0.0, f64::max);
        out.rel[k] = fd::rel_err_maxabs(&an[k], &num);
    }
    Ok(out)
}

/// Stage name of the rows of this check.
pub const STAGE: &str = "render";

/// [`check`] of every scene in every colour mode, as table rows (variant = colour mode).
pub fn rows(scenes: &[Scene], colors: &[ColorMode]) -> crate::Result<Vec<Row>> {
    let mut out = Vec::new();
    for s in scenes {
        for &c in colors {
            let e = check(s, c)?;
            for (k, group) in GROUPS.iter().enumerate() {
                out.push(Row {
                    stage: STAGE,
                    case: s.name.to_string(),
                    variant: c.name().to_string(),
                    group,
                    scale: e.scale[k],
                    max_abs: e.max_abs[k],
                    rel: e.rel[k],
                });
            }
        }
    }
    Ok(out)
}
