//! Geometry of the phantom: the per-vertebra parameters drawn from the seed (the only random
//! draws, made sequentially before any voxel is touched) and the classification of one point.
//! Every voxel is a pure function of its position and of this layout.
//!
//! Axes (world, mm): x = left-right, y = anterior -> posterior (+y is the back), z = inferior ->
//! superior (+z is the head; image row 0 of every projection is +z). Shapes are our design
//! (anatomical proportions, no upstream source), in units of the anatomical scale `s`
//! (s = 1: adult lumbar size). Local vertebra coordinates: u (lateral), v (posterior) about the
//! centre of the spinal canal, rotated by the vertebra's axial rotation.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{ids, noise, Tissue};

/// Seed purposes (folded into the seed so that each use has its own stream).
const PURPOSE_LAYOUT: u64 = 0x5048_414e_544f_4d01; // "PHANTOM" + 1
const PURPOSE_TEXTURE: u64 = 0x5048_414e_544f_4d02;

/// Adult: vertebral body height, disc height (units of s). Pitch = body + disc.
const BODY_H: f64 = 26.0;
const DISC_H: f64 = 10.0;
/// Body semi-axes (x, y) for W = 45 s, D = 33 s.
const BODY_A: f64 = 22.5;
const BODY_B: f64 = 16.5;
/// Gap between the canal's anterior edge and the body's posterior wall.
const BODY_GAP: f64 = 1.0;
/// Concavity of the body's sides at mid-height (fraction of the semi-axes).
const WAIST: f64 = 0.06;
/// Fraction of the disc's semi-axes beyond the bodies (bulge).
const DISC_BULGE: f64 = 1.02;
/// Cancellous texture: +-60 HU in mu (mu_w = 0.01936 /mm per 1000 HU) on a 1.5 mm lattice.
const TEXTURE_AMP: f64 = 60.0 * 0.01936 / 1000.0;
const TEXTURE_CELL_MM: f64 = 1.5;

/// One vertebra, in world mm.
#[derive(Clone, Debug)]
pub(crate) struct Vert {
    /// Label id (TotalSegmentator numbering), 0 when the vertebra does not reach the box.
    pub id: u16,
    pub zc: f64,
    /// Canal centre (world x, y) at the vertebra's mid-height.
    pub cx: f64,
    pub cy: f64,
    /// Axial rotation (radians) and its cosine / sine.
    pub rot: f64,
    pub cr: f64,
    pub sr: f64,
    /// Body half-height, semi-axes, centre (local v), cortical thickness.
    pub hh: f64,
    pub a: f64,
    pub b: f64,
    pub vb: f64,
    pub t: f64,
    /// Canal semi-axes; neural-arch ring semi-axes and half-height.
    pub canal_a: f64,
    pub canal_b: f64,
    pub arch_a: f64,
    pub arch_b: f64,
    pub arch_hh: f64,
    /// Spinous process: local v range, half-width, half-height, caudal shear (mm per mm).
    pub sp_v0: f64,
    pub sp_v1: f64,
    pub sp_hw: f64,
    pub sp_hh: f64,
    pub sp_shear: f64,
    /// Transverse processes: |u| range, v centre and half-thickness, half-height.
    pub tp_u0: f64,
    pub tp_u1: f64,
    pub tp_vc: f64,
    pub tp_hv: f64,
    pub tp_hh: f64,
    /// Mean cancellous attenuation of this vertebra (1/mm).
    pub mu_canc: f64,
    /// Fetal: the two neural-arch ossification centres are present.
    pub arch_centres: bool,
    /// Largest |z - zc| reached by any part.
    pub reach: f64,
}

impl Vert {
    #[inline(always)]
    fn local(&self, x: f64, y: f64) -> (f64, f64) {
        let dx = x - self.cx;
        let dy = y - self.cy;
        (self.cr * dx + self.sr * dy, -self.sr * dx + self.cr * dy)
    }
    /// World (x, y) of the body centre.
    pub fn body_centre(&self) -> (f64, f64) {
        (self.cx - self.sr * self.vb, self.cy + self.cr * self.vb)
    }
}

/// The whole phantom layout.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    pub fetal: bool,
    /// Anatomical scale (1 = adult lumbar).
    pub s: f64,
    /// Body (torso) outline semi-axes and fat thickness.
    pub ax: f64,
    pub ay: f64,
    pub fat: f64,
    /// Vertebrae sorted by z (including neighbours just outside the box, id 0, which only shape
    /// the discs and the canal at the ends).
    pub verts: Vec<Vert>,
    pub texture_key: u64,
}

/// Per-slice quantities (depend on z only).
pub struct Slice {
    z: f64,
    cand: Vec<usize>,
    /// Canal centre, semi-axes, rotation (cos, sin).
    canal: [f64; 6],
    /// Disc: centre x, y, semi-axes, rotation cos, sin.
    disc: Option<[f64; 6]>,
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

impl Layout {
    /// Draw the layout for a box of `size` mm (x, y, z) whose voxel centres span z in
    /// [`zlo`, `zhi`], with the largest voxel size `dmax` (mm).
    pub fn new(
        seed: u64,
        fetal: bool,
        size: [f64; 3],
        zlo: f64,
        zhi: f64,
        dmax: f64,
    ) -> crate::error::Result<Layout> {
        let mut rng = ChaCha8Rng::seed_from_u64(noise::key(seed, PURPOSE_LAYOUT));
        let mut j = move || -> f64 { rng.random_range(-1.0..1.0) };
        // Scale and torso outline (see docs/phantom.md for the fit constraints).
        let (s, ax, ay, fat, ycanal0) = if fetal {
            let s = 0.15f64
                .min(0.42 * size[0] / 150.0)
                .min(0.36 * size[1] / 130.0);
            let (ax, ay) = (150.0 * s, 130.0 * s);
            (s, ax, ay, 10.0 * s, ay - 40.0 * s)
        } else {
            let (ax, ay) = (0.46 * size[0], 0.40 * size[1]);
            let s = 1.0f64.min(ax / 56.0).min(2.0 * ay / 114.0);
            (s, ax, ay, 8.0 * s, ay - 52.0 * s)
        };
        let pitch = (BODY_H + DISC_H) * s;
        if BODY_H * s < 3.0 * dmax || 2.0 * BODY_B * s < 3.0 * dmax {
            return Err(crate::error::Error::invalid(
                "dims",
                format!(
                    "box {:.1} x {:.1} x {:.1} mm is too small for a vertebra at {dmax} mm voxels \
                     (scale {s:.3}: body height {:.2} mm, depth {:.2} mm; need 3 voxels each)",
                    size[0],
                    size[1],
                    size[2],
                    BODY_H * s,
                    2.0 * BODY_B * s
                ),
            ));
        }
        let n_complete = (size[2] / pitch).floor() as i64;
        // Fetal: the lowest 0-2 levels have no neural-arch ossification centres yet.
        let missing_arch = ((j() + 1.0) * 1.5).floor().clamp(0.0, 2.0) as i64;
        let tmin = 1.5 * dmax;
        let mut verts = Vec::new();
        for m in -2..n_complete + 2 {
            let zc = (m as f64 - (n_complete as f64 - 1.0) / 2.0) * pitch;
            // Gentle lordosis: the middle of the box lies up to 3 s anterior.
            let lordosis = -3.0 * s * (std::f64::consts::PI * zc / size[2]).cos().max(0.0);
            let size_j = 1.0 + 0.04 * j();
            let aspect_j = 1.0 + 0.03 * j();
            let cx = 1.0 * s * j();
            let cy = ycanal0 + lordosis + 0.5 * s * j();
            let rot = 3f64.to_radians() * j();
            let t = (1.2 * s * (1.0 + 0.15 * j())).max(tmin);
            let hu_canc = 200.0 + 25.0 * j();
            let sp_len = 38.0 * s * (1.0 + 0.08 * j());
            let sp_shear = 0.25 * (1.0 + 0.3 * j());
            let tp_len = 40.0 * s * (1.0 + 0.1 * j());
            let canal_j = 1.0 + 0.05 * j();
            let hh = 0.5 * BODY_H * s * size_j;
            let a = BODY_A * s * size_j * aspect_j;
            let b = BODY_B * s * size_j / aspect_j;
            let canal_a = 11.0 * s * canal_j;
            let canal_b = 8.0 * s * canal_j;
            let vb = -(canal_b + BODY_GAP * s + b);
            let arch_hh = 0.5 * (BODY_H - 6.0) * s * size_j;
            let sp_v0 = 10.0 * s;
            let sp_hh = 9.0 * s;
            let tp_hh = 5.0 * s;
            let reach = if fetal {
                hh.max(arch_hh)
            } else {
                hh.max(arch_hh)
                    .max(sp_hh + sp_shear * (sp_len - sp_v0))
                    .max(tp_hh)
            };
            verts.push(Vert {
                id: 0,
                zc,
                cx,
                cy,
                rot,
                cr: rot.cos(),
                sr: rot.sin(),
                hh,
                a,
                b,
                vb,
                t,
                canal_a,
                canal_b,
                arch_a: 16.0 * s * canal_j,
                arch_b: 13.0 * s * canal_j,
                arch_hh,
                sp_v0,
                sp_v1: sp_len,
                sp_hw: 3.5 * s,
                sp_hh,
                sp_shear,
                tp_u0: 12.0 * s,
                tp_u1: tp_len,
                tp_vc: -2.0 * s,
                tp_hv: 4.0 * s,
                tp_hh,
                mu_canc: 0.01936 * (1.0 + hu_canc / 1000.0),
                arch_centres: true,
                reach,
            });
        }
        // Label ids, from the bottom: the lowest vertebra reaching the box is L5 (27).
        let mut next = ids::VERTEBRA_L5;
        for v in verts.iter_mut() {
            if v.zc + v.reach >= zlo && v.zc - v.reach <= zhi {
                if next > ids::VERTEBRA_LAST {
                    return Err(crate::error::Error::invalid(
                        "dims",
                        format!(
                            "the box holds more than {} vertebrae (z extent {:.1} mm at scale \
                             {s:.3}); label ids 27-50 would run out",
                            ids::VERTEBRA_LAST - ids::VERTEBRA_L5 + 1,
                            size[2]
                        ),
                    ));
                }
                if fetal && ((next - ids::VERTEBRA_L5) as i64) < missing_arch {
                    v.arch_centres = false;
                }
                v.id = next;
                next += 1;
            }
        }
        Ok(Layout {
            fetal,
            s,
            ax,
            ay,
            fat,
            verts,
            texture_key: noise::key(seed, PURPOSE_TEXTURE),
        })
    }

    /// Everything that depends on z only.
    pub fn slice(&self, z: f64) -> Slice {
        let cand = (0..self.verts.len())
            .filter(|&m| (z - self.verts[m].zc).abs() <= self.verts[m].reach + 1e-9)
            .collect();
        // Bracketing vertebrae for the canal (piecewise linear between centres, constant beyond).
        let vs = &self.verts;
        let n = vs.len();
        let (m0, m1, t) = if z <= vs[0].zc {
            (0, 0, 0.0)
        } else if z >= vs[n - 1].zc {
            (n - 1, n - 1, 0.0)
        } else {
            let m = (0..n - 1).find(|&m| z < vs[m + 1].zc).unwrap_or(n - 2);
            (m, m + 1, (z - vs[m].zc) / (vs[m + 1].zc - vs[m].zc))
        };
        let (p, q) = (&vs[m0], &vs[m1]);
        let rot = lerp(p.rot, q.rot, t);
        let canal = [
            lerp(p.cx, q.cx, t),
            lerp(p.cy, q.cy, t),
            lerp(p.canal_a, q.canal_a, t),
            lerp(p.canal_b, q.canal_b, t),
            rot.cos(),
            rot.sin(),
        ];
        // Disc: strictly between the end plates of two consecutive bodies.
        let disc = (0..n - 1)
            .find(|&m| z > vs[m].zc + vs[m].hh && z < vs[m + 1].zc - vs[m + 1].hh)
            .map(|m| {
                let (p, q) = (&vs[m], &vs[m + 1]);
                let t = (z - (p.zc + p.hh)) / ((q.zc - q.hh) - (p.zc + p.hh));
                let (px, py) = p.body_centre();
                let (qx, qy) = q.body_centre();
                let rot = lerp(p.rot, q.rot, t);
                [
                    lerp(px, qx, t),
                    lerp(py, qy, t),
                    DISC_BULGE * lerp(p.a, q.a, t),
                    DISC_BULGE * lerp(p.b, q.b, t),
                    rot.cos(),
                    rot.sin(),
                ]
            });
        Slice {
            z,
            cand,
            canal,
            disc,
        }
    }

    /// Tissue and label id at world point (x, y) of slice `sl`.
    #[inline]
    pub fn classify(&self, sl: &Slice, x: f64, y: f64) -> (Tissue, u16) {
        // Outside the torso: nothing else can be there (the spine is fitted inside).
        let ex = x / self.ax;
        let ey = y / self.ay;
        if ex * ex + ey * ey > 1.0 {
            return if self.fetal {
                (Tissue::Fluid, ids::FLUID)
            } else {
                (Tissue::Air, ids::BACKGROUND)
            };
        }
        // Spinal canal (continuous over every level).
        {
            let [cx, cy, ca, cb, c, s] = sl.canal;
            let (dx, dy) = (x - cx, y - cy);
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            if (u / ca).powi(2) + (v / cb).powi(2) <= 1.0 {
                return (Tissue::Canal, ids::CANAL);
            }
        }
        for &m in &sl.cand {
            if let Some(t) = self.vertebra(&self.verts[m], sl.z, x, y) {
                let id = if t.is_bone() {
                    self.verts[m].id
                } else {
                    ids::CARTILAGE
                };
                return (t, id);
            }
        }
        if let Some([cx, cy, a, b, c, s]) = sl.disc {
            let (dx, dy) = (x - cx, y - cy);
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            if (u / a).powi(2) + (v / b).powi(2) <= 1.0 {
                return (Tissue::Disc, ids::DISC);
            }
        }
        let fx = x / (self.ax - self.fat);
        let fy = y / (self.ay - self.fat);
        if fx * fx + fy * fy <= 1.0 {
            (Tissue::SoftTissue, ids::SOFT_TISSUE)
        } else {
            (Tissue::Fat, ids::FAT)
        }
    }

    /// Tissue of vertebra `v` at (x, y, z), or None outside it.
    #[inline]
    fn vertebra(&self, v: &Vert, z: f64, x: f64, y: f64) -> Option<Tissue> {
        let dz = z - v.zc;
        let (u, w) = v.local(x, y);
        // Vertebral body (elliptic cylinder with a slight waist).
        if dz.abs() <= v.hh {
            let q = dz / v.hh;
            let r = 1.0 - WAIST * (1.0 - q * q);
            let (ar, br) = (v.a * r, v.b * r);
            let wb = w - v.vb;
            if (u / ar).powi(2) + (wb / br).powi(2) <= 1.0 {
                if self.fetal {
                    let e = (u / (0.55 * v.a)).powi(2)
                        + (wb / (0.55 * v.b)).powi(2)
                        + (dz / (0.6 * v.hh)).powi(2);
                    return Some(if e <= 1.0 {
                        Tissue::Ossification
                    } else {
                        Tissue::Cartilage
                    });
                }
                let (ai, bi) = (ar - v.t, br - v.t);
                let inner = dz.abs() <= v.hh - v.t
                    && ai > 0.0
                    && bi > 0.0
                    && (u / ai).powi(2) + (wb / bi).powi(2) <= 1.0;
                return Some(if inner {
                    Tissue::Cancellous
                } else {
                    Tissue::Cortical
                });
            }
        }
        // Neural arch: pedicles and laminae as an elliptic ring around the canal.
        if dz.abs() <= v.arch_hh
            && (u / v.arch_a).powi(2) + (w / v.arch_b).powi(2) <= 1.0
            && (u / v.canal_a).powi(2) + (w / v.canal_b).powi(2) > 1.0
        {
            if self.fetal {
                // Two ossification centres, posterolateral to the canal.
                let uc = 0.5 * (v.canal_a + v.arch_a);
                let ra = 0.5 * (v.arch_a - v.canal_a);
                let e = ((u.abs() - uc) / ra).powi(2)
                    + ((w - 0.2 * v.canal_b) / (0.6 * v.canal_b)).powi(2)
                    + (dz / (0.6 * v.arch_hh)).powi(2);
                return Some(if v.arch_centres && e <= 1.0 {
                    Tissue::Ossification
                } else {
                    Tissue::Cartilage
                });
            }
            return Some(Tissue::PosteriorBone);
        }
        if self.fetal {
            // The spinous and transverse processes are cartilaginous: not modelled apart.
            return None;
        }
        // Spinous process: a tapering plate sheared caudally.
        if w >= v.sp_v0 && w <= v.sp_v1 {
            let f = (w - v.sp_v0) / (v.sp_v1 - v.sp_v0);
            if u.abs() <= v.sp_hw * (1.0 - 0.3 * f)
                && (dz + v.sp_shear * (w - v.sp_v0)).abs() <= v.sp_hh
            {
                return Some(Tissue::PosteriorBone);
            }
        }
        // Transverse processes.
        if u.abs() > v.tp_u0
            && u.abs() <= v.tp_u1
            && (w - v.tp_vc).abs() <= v.tp_hv
            && dz.abs() <= v.tp_hh
        {
            return Some(Tissue::PosteriorBone);
        }
        None
    }

    /// Attenuation (1/mm) of `t` at world point p (texture for cancellous bone).
    #[inline]
    pub fn mu(&self, t: Tissue, vert: Option<&Vert>, p: [f64; 3]) -> f64 {
        match (t, vert) {
            (Tissue::Cancellous, Some(v)) => {
                v.mu_canc + TEXTURE_AMP * noise::value_noise(self.texture_key, p, TEXTURE_CELL_MM)
            }
            _ => t.mu() as f64,
        }
    }

    /// The vertebra with label `id`, if any.
    pub fn vert_by_id(&self, id: u16) -> Option<&Vert> {
        if id == 0 {
            return None;
        }
        self.verts.iter().find(|v| v.id == id)
    }
}
