//! Edge cases of the whole render: a Gaussian behind the camera, zero scale, zero quaternion,
//! NaN input (a clear error, not a poisoned image), the empty scene (the background), the alpha
//! clamp and early termination (the exclusive transmittance stop).
//! (The splat-level versions of the clamp, stop and 1/255 skip are in
//! `src/render/composite/tests.rs`.)

use unispine::gaussians::Gaussians;
use unispine::geometry::{Camera, ConeBeam};
use unispine::image2d::Image2d;
use unispine::render::{self, composite, RenderSettings};

fn camera() -> Camera {
    ConeBeam::centred([24, 32], [1.0, 1.0], [16, 16, 16], [2.0, 2.0, 2.0]).camera(0.0)
}

fn settings(bg: f64) -> RenderSettings {
    RenderSettings {
        background: bg,
        ..RenderSettings::default()
    }
}

/// One Gaussian at camera-space point `t`, scale `s` mm, opacity logit `o`.
fn one(cam: &Camera, t: [f64; 3], s: f64, o: f64) -> Gaussians<f64> {
    let mut g = Gaussians::zeros(1);
    let w = cam.cam_dir_to_world(t);
    g.means[0] = std::array::from_fn(|a| cam.centre[a] + w[a]);
    g.log_scales[0] = [s.ln(); 3];
    g.quats[0] = [1.0, 0.0, 0.0, 0.0];
    g.opacity_logits[0] = o;
    g.features[0][0] = 0.8;
    g
}

fn concat(a: &Gaussians<f64>, b: &Gaussians<f64>) -> Gaussians<f64> {
    let mut g = a.clone();
    g.means.extend(&b.means);
    g.log_scales.extend(&b.log_scales);
    g.quats.extend(&b.quats);
    g.opacity_logits.extend(&b.opacity_logits);
    g.features.extend(&b.features);
    g
}

fn render_grads(
    g: &Gaussians<f64>,
    cam: &Camera,
    bg: f64,
) -> (Image2d<f64>, render::RenderGrads<f64>) {
    let st = settings(bg);
    let (img, saved) = render::forward(g, cam, &st).unwrap();
    let d = Image2d::filled(cam.width, cam.height, 1.0);
    let gr = render::backward(g, cam, &st, &saved, &d);
    (img, gr)
}

fn all_finite(g: &Gaussians<f64>) -> bool {
    g.check_finite().is_ok()
}

#[test]
fn empty_scene_gives_the_background() {
    let cam = camera();
    let (img, gr) = render_grads(&Gaussians::zeros(0), &cam, 0.25);
    assert!(img.data.iter().all(|&v| v == 0.25));
    assert!(gr.params.is_empty());
}

#[test]
fn gaussian_behind_the_camera_is_not_drawn() {
    let cam = camera();
    let front = one(&cam, [0.0, 0.0, 1000.0], 8.0, 0.0);
    let behind = one(&cam, [0.0, 0.0, -50.0], 8.0, 3.0);
    let (img_f, _) = render_grads(&front, &cam, 0.0);
    let (img, gr) = render_grads(&concat(&front, &behind), &cam, 0.0);
    assert_eq!(img, img_f, "the Gaussian behind the source changes nothing");
    assert!(!gr.visible[1] && gr.visible[0]);
    assert_eq!(gr.params.means[1], [0.0; 3]);
    assert_eq!(gr.params.opacity_logits[1], 0.0);
    assert!(all_finite(&gr.params));
}

#[test]
fn zero_scale_draws_the_dilation_footprint() {
    let cam = camera();
    let g = one(&cam, [0.0, 0.0, 1000.0], 1e-30, 2.0);
    let (img, gr) = render_grads(&g, &cam, 0.0);
    assert!(gr.visible[0]);
    assert!(img.data.iter().all(|v| v.is_finite()));
    // Sigma2D = 0.3 I: a footprint of a few pixels around the image centre (16, 12).
    let lit = img.data.iter().filter(|&&v| v > 0.0).count();
    assert!(lit > 0 && lit <= 49, "{lit} pixels lit");
    assert!(img.at(11, 15) > 0.0);
    assert!(all_finite(&gr.params));
}

#[test]
fn zero_quaternion_is_culled_without_nan() {
    let cam = camera();
    let mut g = concat(
        &one(&cam, [0.0, 0.0, 1000.0], 8.0, 0.0),
        &one(&cam, [2.0, 1.0, 990.0], 8.0, 0.0),
    );
    g.quats[1] = [0.0; 4];
    let (img, gr) = render_grads(&g, &cam, 0.0);
    let (img0, _) = render_grads(&one(&cam, [0.0, 0.0, 1000.0], 8.0, 0.0), &cam, 0.0);
    assert_eq!(img, img0);
    assert!(!gr.visible[1]);
    assert_eq!(gr.params.quats[1], [0.0; 4]);
    assert!(all_finite(&gr.params));
}

#[test]
fn nan_input_is_a_clear_error() {
    let cam = camera();
    let mut g = concat(
        &one(&cam, [0.0, 0.0, 1000.0], 8.0, 0.0),
        &one(&cam, [2.0, 1.0, 990.0], 8.0, 0.0),
    );
    g.means[1][2] = f64::NAN;
    let e = render::forward(&g, &cam, &settings(0.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("Gaussian 1") && e.contains("means"), "{e}");
    g.means[1][2] = 0.0;
    g.opacity_logits[0] = f64::INFINITY;
    let e = render::forward(&g, &cam, &settings(0.0))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("Gaussian 0") && e.contains("opacity_logits"),
        "{e}"
    );
}

#[test]
fn alpha_clamp_zeroes_the_geometry_gradient_at_the_centre() {
    // A bright Gaussian (o = sigmoid(8) = 0.99966): o G > 0.99 near its centre, so alpha is
    // clamped there and those pixels give no gradient to opacity or position.
    let cam = camera();
    let g = one(&cam, [0.0, 0.0, 1000.0], 6.0, 8.0);
    let st = settings(0.0);
    let (img, saved) = render::forward(&g, &cam, &st).unwrap();
    let c = saved.splats.color[0];
    // Pixel (row 11, col 15) is 0.5 px from the centre (16, 12) in both axes.
    assert!((img.at(11, 15) - 0.99 * c).abs() < 1e-15);
    let mut d = Image2d::filled(cam.width, cam.height, 0.0);
    d.data[11 * cam.width + 15] = 1.0;
    let gr = render::backward(&g, &cam, &st, &saved, &d);
    assert_eq!(gr.params.opacity_logits[0], 0.0);
    assert_eq!(gr.params.means[0], [0.0; 3]);
    assert_eq!(gr.params.log_scales[0], [0.0; 3]);
    assert!(
        gr.params.features[0][0] != 0.0,
        "the colour still gets alpha T"
    );
}

#[test]
fn early_termination_hides_what_is_behind() {
    // Two bright Gaussians in front (alpha 0.99 each at the centre pixel: T = 1e-4 after them)
    // and a third behind: the third would bring T below 1e-4, so the pixel stops before it.
    let cam = camera();
    let mut g = one(&cam, [0.0, 0.0, 990.0], 6.0, 8.0);
    g = concat(&g, &one(&cam, [0.0, 0.0, 1000.0], 6.0, 8.0));
    g = concat(&g, &one(&cam, [0.0, 0.0, 1010.0], 6.0, 8.0));
    let st = settings(0.0);
    let (img, saved) = render::forward(&g, &cam, &st).unwrap();
    let q = 11 * cam.width + 15;
    assert_eq!(saved.composite.n_contrib[q], 2);
    assert!(saved.composite.final_t[q] >= composite::T_MIN);
    // Changing the third Gaussian's colour does not change that pixel.
    let mut g2 = g.clone();
    g2.features[2][0] = -3.0;
    let (img2, _) = render::forward(&g2, &cam, &st).unwrap();
    assert_eq!(img.data[q], img2.data[q]);
    let mut d = Image2d::filled(cam.width, cam.height, 0.0);
    d.data[q] = 1.0;
    let gr = render::backward(&g, &cam, &st, &saved, &d);
    assert_eq!(gr.params.features[2], [0.0; 16]);
    assert!(gr.params.features[1][0] != 0.0);
}
