//! The scalar reference render under any [`Conventions`] (Eqs. 3-5), forward and exact
//! backward: what [`super::forward`] runs when the conventions are not the default.
//!
//! Projection: the same per-Gaussian geometry as [`super::project`] (`geom_core`, with the
//! near plane, eps2d and Jacobian limits of the conventions); the radius by `radius_rule` and
//! `radius_sigmas` (one radius from lambda_max, or one per axis from the Sigma2D diagonal); a
//! splat is drawn unless its quaternion is zero, it is at or before the near plane, Sigma2D is
//! degenerate, or its rectangle [u - rx, u + rx] x [v - ry, v + ry] misses the image.
//!
//! Compositing, per pixel (col, row) sampled at (col + pixel_center, row + pixel_center), over
//! every drawn splat whose tile rectangle (floor((u - rx)/16) .. ceil((u + rx)/16), the same in
//! v) holds the pixel's tile, in (f32 depth, index) order: skip if the exponent is > 0; alpha =
//! min(alpha_max, o G); skip if alpha < 1/255; stop (this splat not blended) when T (1 - alpha)
//! < 1e-4 (`exclusive`) or <= 1e-4 (`inclusive`); C += c alpha T, T <- T (1 - alpha); the
//! output is C + T_final bg. Every blend is kept (splat, alpha, T, G, whether clamped, the
//! offsets), so the backward needs no division to recover T.
//!
//! Backward: with S_k the colour behind blend k, dL/dc_k = g alpha_k T_k and dL/dalpha_k =
//! g (c_k T_k - (S_k + bg T_final) / (1 - alpha_k)); through the clamp the derivative is 0
//! (`zero`) or that of o G (`pass`); then the exponent's derivatives as in
//! [`super::composite`], and [`super::project::backward`] for the parameters. Sequential in
//! pixel order: bit-identical for any thread count. Time O(pixels x splats per tile); the
//! blend lists take one record per blend.

use super::conventions::{ClampGradient, Conventions, RadiusRule, TStop};
use super::project::{self, CamConsts, ProjectSaved};
use super::tiles::{self, TILE};
use super::{composite, RenderSaved, RenderSettings, SplatGrads, Splats};
use crate::gaussians::Gaussians;
use crate::geometry::Camera;
use crate::image2d::Image2d;
use crate::math::activations::sigmoid;
use crate::math::round;
use crate::real::Real;

/// One (pixel, splat) blend of the forward.
#[derive(Clone, Copy, Debug)]
struct Blend<R: Real> {
    splat: u32,
    alpha: R,
    /// Transmittance before this blend.
    t: R,
    /// exp(power).
    g: R,
    clamped: bool,
    dx: R,
    dy: R,
}

/// What the reference backward needs from its forward.
#[derive(Clone, Debug)]
pub struct ReferenceSaved<R: Real> {
    conventions: Conventions,
    background: R,
    /// Pixel p's blends are `blends[offsets[p]..offsets[p + 1]]`, front to back.
    offsets: Vec<usize>,
    blends: Vec<Blend<R>>,
    final_t: Vec<R>,
}

/// Radii (x, y) of Sigma2D = [[a, b], [b, c]] by the rule of `conv` (f64, as the tile kernels).
fn radii(conv: &Conventions, cov2d: [f64; 3]) -> [f64; 2] {
    let [a, b, c] = cov2d;
    let k = conv.radius_sigmas;
    match conv.radius_rule {
        RadiusRule::Eigen => {
            let det = a * c - b * b;
            let mid = 0.5 * (a + c);
            let lmax = mid + (mid * mid - det).max(project::DISCRIMINANT_FLOOR).sqrt();
            let r = round::ceil(k * lmax.sqrt());
            [r, r]
        }
        RadiusRule::Axes => [round::ceil(k * a.sqrt()), round::ceil(k * c.sqrt())],
    }
}

/// Tiles [tx0, tx1) x [ty0, ty1) of the rectangle of radii `r` around (u, v), or `None`.
fn rect(u: f64, v: f64, r: [f64; 2], tiles_x: usize, tiles_y: usize) -> Option<[usize; 4]> {
    let t = TILE as f64;
    let clamp = |x: f64, n: usize| x.max(0.0).min(n as f64) as i64 as usize;
    let tx0 = clamp(round::floor((u - r[0]) / t), tiles_x);
    let tx1 = clamp(round::ceil((u + r[0]) / t), tiles_x);
    let ty0 = clamp(round::floor((v - r[1]) / t), tiles_y);
    let ty1 = clamp(round::ceil((v + r[1]) / t), tiles_y);
    (tx0 < tx1 && ty0 < ty1).then_some([tx0, tx1, ty0, ty1])
}

/// Render `g` from `cam` under `settings.conventions` (any value, the default included).
#[allow(clippy::needless_range_loop)] // one index into several per-Gaussian arrays
pub fn forward<R: Real>(
    g: &Gaussians<R>,
    cam: &Camera,
    settings: &RenderSettings,
) -> crate::error::Result<(Image2d<R>, RenderSaved<R>)> {
    let conv = &settings.conventions;
    conv.validate()?;
    // Input checks (lengths, finiteness, active features) as the fast path.
    project::check_inputs(g, settings)?;
    let n = g.len();
    let cc = CamConsts::<R>::with_conventions(cam, conv);
    let z = R::zero();
    let mut s = Splats::zeros(n);
    let mut scale = vec![[z; 3]; n];
    let (w, h) = (cam.width, cam.height);
    let (tiles_x, tiles_y) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let mut order = Vec::new();
    for i in 0..n {
        let ls = g.log_scales[i];
        scale[i] = [ls[0].exp(), ls[1].exp(), ls[2].exp()];
        let (geo, cull) = if cc.parallel {
            project::geom_core::<R, true, true>(&cc, g.means[i], scale[i], g.quats[i])
        } else {
            project::geom_core::<R, true, false>(&cc, g.means[i], scale[i], g.quats[i])
        };
        s.depth[i] = geo.t[2];
        if matches!(cull, Some(c) if c != project::Cull::OffImage) {
            continue;
        }
        let r = radii(conv, geo.cov2d.map(|x| x.f64()));
        let (u, v) = (geo.mean2d[0].f64(), geo.mean2d[1].f64());
        let ok = r
            .iter()
            .all(|x| x.is_finite() && *x >= 1.0 && *x < u32::MAX as f64);
        let on_image =
            (u + r[0] > 0.0) & (u - r[0] < w as f64) & (v + r[1] > 0.0) & (v - r[1] < h as f64);
        if !(ok && on_image) {
            continue;
        }
        s.mean2d[i] = geo.mean2d;
        s.conic[i] = geo.conic;
        s.radius[i] = r[0].max(r[1]) as u32;
        s.opacity[i] = sigmoid(g.opacity_logits[i]);
        s.color[i] = project::intensity(
            settings.color,
            settings.active_features,
            cc.centre,
            g.means[i],
            &g.features[i],
        );
        if !tiles::drawn(&s, i) {
            s.radius[i] = 0;
            continue;
        }
        if let Some(rc) = rect(u, v, r, tiles_x, tiles_y) {
            order.push((tiles::sort_key(geo.t[2].f64(), i as u32), i, rc));
        }
    }
    order.sort_unstable_by_key(|e| e.0);
    // Per tile, the drawn splats whose rectangle holds it, in (depth, index) order.
    let mut lists: Vec<Vec<usize>> = vec![Vec::new(); tiles_x * tiles_y];
    for &(_, i, r) in &order {
        for ty in r[2]..r[3] {
            for tx in r[0]..r[1] {
                lists[ty * tiles_x + tx].push(i);
            }
        }
    }

    let bg = R::c(settings.background);
    let (amax, amin, tmin) = (
        R::c(conv.alpha_max),
        R::c(composite::ALPHA_MIN),
        R::c(composite::T_MIN),
    );
    let (pc, half) = (R::c(conv.pixel_center), R::c(0.5));
    let mut img = Image2d::filled(w, h, z);
    let mut saved = ReferenceSaved {
        conventions: conv.clone(),
        background: bg,
        offsets: Vec::with_capacity(w * h + 1),
        blends: Vec::new(),
        final_t: vec![R::one(); w * h],
    };
    let mut n_contrib = vec![0u32; w * h];
    saved.offsets.push(0);
    for row in 0..h {
        for col in 0..w {
            let list = &lists[(row / TILE) * tiles_x + col / TILE];
            let (px, py) = (R::c(col as f64) + pc, R::c(row as f64) + pc);
            let (mut c, mut t) = (z, R::one());
            for &i in list {
                let dx = px - s.mean2d[i][0];
                let dy = py - s.mean2d[i][1];
                let [ca, cb, cc_] = s.conic[i];
                let power = -half * (ca * dx * dx + cc_ * dy * dy) - cb * dx * dy;
                if power > z {
                    continue;
                }
                let gv = power.exp();
                let og = s.opacity[i] * gv;
                let clamped = og > amax;
                let alpha = if clamped { amax } else { og };
                if alpha < amin {
                    continue;
                }
                let next = t * (R::one() - alpha);
                let stop = match conv.t_stop {
                    TStop::Exclusive => next < tmin,
                    TStop::Inclusive => next <= tmin,
                };
                if stop {
                    break;
                }
                c += s.color[i] * alpha * t;
                saved.blends.push(Blend {
                    splat: i as u32,
                    alpha,
                    t,
                    g: gv,
                    clamped,
                    dx,
                    dy,
                });
                t = next;
            }
            let p = row * w + col;
            img.data[p] = c + t * bg;
            saved.final_t[p] = t;
            n_contrib[p] = (saved.blends.len() - saved.offsets[p]) as u32;
            saved.offsets.push(saved.blends.len());
        }
    }
    let cs = composite::CompositeSaved {
        background: bg,
        final_t: saved.final_t.clone(),
        n_contrib,
        blends: saved.blends.len() as u64,
        ..Default::default()
    };
    Ok((
        img,
        RenderSaved {
            splats: s,
            project: ProjectSaved { scale },
            composite: cs,
            reference: Some(Box::new(saved)),
        },
    ))
}

/// Gradients of sum(d_image * image) with respect to the splat fields, from the blend lists of
/// [`forward`] (see the module docs).
pub fn composite_backward<R: Real>(
    splats: &Splats<R>,
    saved: &ReferenceSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    let n = splats.radius.len();
    let z = R::zero();
    let mut d = SplatGrads {
        mean2d: vec![[z; 2]; n],
        conic: vec![[z; 3]; n],
        opacity: vec![z; n],
        color: vec![z; n],
    };
    let half = R::c(0.5);
    let pass = saved.conventions.clamp_gradient == ClampGradient::Pass;
    for p in 0..saved.final_t.len() {
        let gp = d_image.data[p];
        let bl = &saved.blends[saved.offsets[p]..saved.offsets[p + 1]];
        // Colour behind blend k plus the background term: S_k + bg T_final.
        let mut behind = saved.background * saved.final_t[p];
        for b in bl.iter().rev() {
            let i = b.splat as usize;
            let c = splats.color[i];
            d.color[i] += gp * b.alpha * b.t;
            let dalpha = gp * (c * b.t - behind / (R::one() - b.alpha));
            behind += c * b.alpha * b.t;
            if b.clamped && !pass {
                continue;
            }
            let o = splats.opacity[i];
            d.opacity[i] += dalpha * b.g;
            let dpow = dalpha * o * b.g;
            let [ca, cb, cc] = splats.conic[i];
            let (dx, dy) = (b.dx, b.dy);
            // power = -(A dx^2 + C dy^2)/2 - B dx dy with d = pixel - mean2d.
            d.mean2d[i][0] += dpow * (ca * dx + cb * dy);
            d.mean2d[i][1] += dpow * (cb * dx + cc * dy);
            d.conic[i][0] -= half * dx * dx * dpow;
            d.conic[i][1] -= dx * dy * dpow;
            d.conic[i][2] -= half * dy * dy * dpow;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ConeBeam;
    use crate::render::{self, ColorMode};

    fn scene(n: usize, seed: u64) -> Gaussians<f64> {
        let mut s = seed;
        let mut r = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64) / ((1u64 << 53) as f64)
        };
        let mut g = Gaussians::zeros(n);
        for i in 0..n {
            g.means[i] = [30.0 * r() - 15.0, 30.0 * r() - 15.0, 30.0 * r() - 15.0];
            g.log_scales[i] = [r() + 0.2, r() + 0.2, r() + 0.2];
            g.quats[i] = [r() - 0.5, r() - 0.5, r() - 0.5, r() - 0.5];
            g.opacity_logits[i] = 5.0 * r() - 1.0;
            g.features[i][0] = 2.0 * r() - 1.0;
        }
        g
    }

    fn cam() -> Camera {
        ConeBeam::centred([48, 64], [1.0, 1.0], [16, 16, 16], [2.0, 2.0, 2.0]).camera(0.4)
    }

    fn settings(conv: Conventions) -> RenderSettings {
        RenderSettings {
            color: ColorMode::RirfPaper,
            active_features: 1,
            background: 0.2,
            conventions: conv,
        }
    }

    /// The reference path under the default conventions equals the tile kernels to rounding
    /// (image, and every parameter gradient).
    #[test]
    fn default_conventions_match_the_tile_kernels() {
        let g = scene(40, 3);
        let cam = cam();
        let st = settings(Conventions::default());
        let (img, saved) = render::forward(&g, &cam, &st).unwrap();
        assert!(saved.reference.is_none());
        let (rimg, rsaved) = forward(&g, &cam, &st).unwrap();
        let scale = img.data.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (a, b) in img.data.iter().zip(&rimg.data) {
            assert!((a - b).abs() <= 1e-12 * scale, "{a} {b}");
        }
        let d = Image2d::from_vec(
            cam.width,
            cam.height,
            rimg.data.iter().map(|x| x.sin()).collect(),
        );
        let ga = render::backward(&g, &cam, &st, &saved, &d).params;
        let gb = render::backward(&g, &cam, &st, &rsaved, &d).params;
        let flat = |g: &Gaussians<f64>| -> Vec<f64> {
            let mut v: Vec<f64> = g.means.iter().flatten().copied().collect();
            v.extend(g.log_scales.iter().flatten());
            v.extend(g.quats.iter().flatten());
            v.extend(&g.opacity_logits);
            v.extend(g.features.iter().flatten());
            v
        };
        let (fa, fb) = (flat(&ga), flat(&gb));
        let m = fa.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(m > 0.0);
        for (a, b) in fa.iter().zip(&fb) {
            assert!((a - b).abs() <= 1e-10 * m, "{a} {b}");
        }
    }

    /// Each convention changes the image of a scene that exercises it, and the routed render
    /// is the reference path.
    #[test]
    fn every_convention_is_live() {
        let g = scene(60, 5);
        let cam = cam();
        let base = render::forward(&g, &cam, &settings(Conventions::default()))
            .unwrap()
            .0;
        let d = Conventions::default();
        let variants = [
            Conventions {
                alpha_max: 0.999,
                ..d.clone()
            },
            Conventions {
                radius_sigmas: 3.33,
                ..d.clone()
            },
            Conventions {
                radius_rule: RadiusRule::Axes,
                ..d.clone()
            },
            Conventions {
                eps2d: 0.1,
                ..d.clone()
            },
            Conventions {
                pixel_center: 0.0,
                ..d.clone()
            },
        ];
        for v in variants {
            let (img, saved) = render::forward(&g, &cam, &settings(v.clone())).unwrap();
            assert!(saved.reference.is_some());
            assert!(img.data != base.data, "{v:?} changed nothing");
        }
    }
}
