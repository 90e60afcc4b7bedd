//! Ultrasound-like (B-mode) proxy volume from a label volume.
//!
//! The paper treats a 3D ultrasound volume as a scalar field and projects it with the same DRR
//! operator as a CT. For a spine without a real ultrasound volume we synthesise such a field
//! from labels (after Ultra-NeRF's ray model, magdalena-wysocki/ultra-nerf `run_ultra_nerf.py`,
//! with CT-derived reflection as in Wein et al. 2008):
//!
//! 1. each label gets an acoustic impedance Z (MRayl), an attenuation alpha (dB/(cm MHz)) and a
//!    backscatter strength sigma ([`acoustic`]);
//! 2. along every scan line (the beam direction, [`BeamDir`]; default `-y`: the probe lies on
//!    the back and the sound travels posterior -> anterior, as in spine and fetal-spine scans),
//!    the intensity reflection at each interface is R = ((Z2 - Z1) / (Z2 + Z1))^2 and the two-way
//!    transmission T is the product of (1 - R)^2 over the interfaces crossed and
//!    10^(-2 alpha f dx / 10) over the voxels crossed, compensated by a time-gain TGC of
//!    `tgc_db_per_cm_mhz` and clamped at 1; bone (R ~ 0.33 from soft tissue, ~105 dB/cm two-way at
//!    3.5 MHz) therefore casts its acoustic shadow by itself;
//! 3. speckle: two i.i.d. N(0, 1) fields from a counter-based hash of (seed, voxel index),
//!    each blurred by the PSF, an anisotropic Gaussian (axial / lateral / elevational sigma in
//!    mm), and combined as the modulus sqrt(g1^2 + g2^2) (Rayleigh, fully developed speckle),
//!    normalised to mean 1;
//! 4. echo e = g_r (PSF * (T_incident R)) / (w_0 R_ref) + g_s T sigma speckle, with w_0 the
//!    centre weight of the axial kernel and R_ref the soft-tissue / bone reflection, so that a
//!    fully insonified bone surface gives e ~ 1;
//! 5. log compression y = ln(1 + a e) / ln(1 + a), clipped to [0, 1].
//!
//! Deterministic: every scan line and every blur line is computed from its own inputs only,
//! in parallel over fixed groups of lines whose outputs are collected in order; the speckle is
//! a pure function of (seed, voxel index). Bit-identical for any thread count.

use rayon::prelude::*;

use super::phantom::{ids, noise};
use super::{LabelMap, Provenance, Volume};
use crate::error::{Error, Result};

/// Seed purpose of the speckle.
const PURPOSE_SPECKLE: u64 = 0x5553_5350_4543_4b4c; // "USSPECKL"

/// Direction the sound travels in (the probe sits on the opposite face of the volume).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BeamDir {
    #[serde(rename = "+x")]
    XPos,
    #[serde(rename = "-x")]
    XNeg,
    #[serde(rename = "+y")]
    YPos,
    #[serde(rename = "-y")]
    YNeg,
    #[serde(rename = "+z")]
    ZPos,
    #[serde(rename = "-z")]
    ZNeg,
}

impl BeamDir {
    /// Volume axis of the beam.
    pub fn axis(self) -> usize {
        match self {
            BeamDir::XPos | BeamDir::XNeg => 0,
            BeamDir::YPos | BeamDir::YNeg => 1,
            BeamDir::ZPos | BeamDir::ZNeg => 2,
        }
    }
    /// True when depth grows with the voxel index.
    pub fn increasing(self) -> bool {
        matches!(self, BeamDir::XPos | BeamDir::YPos | BeamDir::ZPos)
    }
    /// (lateral, elevational) axes: the probe's array runs along the lateral axis (x unless
    /// the beam is along x), the elevational axis is the remaining one.
    pub fn lateral_elevational(self) -> (usize, usize) {
        match self.axis() {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        }
    }
}

/// Settings of the ultrasound-like proxy (every field has a default; JSON may omit any).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct UsProxySpec {
    /// Seed of the speckle.
    pub seed: u64,
    /// Direction the sound travels in (default `-y`: posterior -> anterior).
    pub beam: BeamDir,
    /// Centre frequency (MHz); attenuation scales with it.
    pub frequency_mhz: f64,
    /// Time-gain compensation (dB/(cm MHz), two-way applied); 0 disables it.
    pub tgc_db_per_cm_mhz: f64,
    /// PSF standard deviations in mm: [axial, lateral, elevational].
    pub psf_sigma_mm: [f64; 3],
    /// Gain of the interface reflections (g_r).
    pub reflection_gain: f64,
    /// Gain of the diffuse scattering (g_s).
    pub speckle_gain: f64,
    /// Log-compression parameter a in ln(1 + a e) / ln(1 + a).
    pub compression: f64,
}

impl Default for UsProxySpec {
    fn default() -> Self {
        UsProxySpec {
            seed: 0,
            beam: BeamDir::YNeg,
            frequency_mhz: 3.5,
            tgc_db_per_cm_mhz: 0.5,
            psf_sigma_mm: [0.5, 1.0, 1.5],
            reflection_gain: 1.0,
            speckle_gain: 0.25,
            compression: 30.0,
        }
    }
}

impl UsProxySpec {
    /// Error naming the field when a setting is unusable.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: f64, allow_zero: bool| -> Result<()> {
            if !v.is_finite() || v < 0.0 || (!allow_zero && v == 0.0) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "must be finite and {} 0, got {v}",
                        if allow_zero { ">=" } else { ">" }
                    ),
                ));
            }
            Ok(())
        };
        pos("frequency_mhz", self.frequency_mhz, false)?;
        pos("tgc_db_per_cm_mhz", self.tgc_db_per_cm_mhz, true)?;
        for (a, name) in ["axial", "lateral", "elevational"].iter().enumerate() {
            pos(
                &format!("psf_sigma_mm[{a}] ({name})"),
                self.psf_sigma_mm[a],
                true,
            )?;
        }
        pos("reflection_gain", self.reflection_gain, true)?;
        pos("speckle_gain", self.speckle_gain, true)?;
        pos("compression", self.compression, false)
    }
}

/// Acoustic properties of one label.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Acoustic {
    /// Impedance (MRayl).
    pub z: f64,
    /// Attenuation (dB / (cm MHz)).
    pub alpha: f64,
    /// Backscatter strength (relative).
    pub sigma: f64,
}

/// Coupling medium / water / amniotic fluid.
pub const WATER: Acoustic = Acoustic {
    z: 1.48,
    alpha: 0.002,
    sigma: 0.0,
};
/// Bone (cortical-dominated surface).
pub const BONE: Acoustic = Acoustic {
    z: 6.0,
    alpha: 15.0,
    sigma: 0.2,
};
/// Soft tissue / muscle.
pub const SOFT: Acoustic = Acoustic {
    z: 1.63,
    alpha: 0.54,
    sigma: 0.5,
};

/// Acoustic properties of a label id (phantom ids and TotalSegmentator v2 ids). Values from
/// PMC10346919 Table A2, PMC10001275 Table 4 and typical soft-tissue values.
/// Label 0 is the coupling medium (gel / water), not air: an air gap would reflect everything.
/// TotalSegmentator bones (vertebrae 25-50, humerus .. hip 69-78, skull 91, ribs 92-115,
/// sternum 116) are bone; costal cartilage 117 is cartilage; every other id is soft tissue.
pub fn acoustic(id: u16) -> Acoustic {
    match id {
        ids::BACKGROUND | ids::FLUID => WATER,
        25..=50 | 69..=78 | 91..=116 => BONE,
        ids::CANAL => Acoustic {
            z: 1.50,
            alpha: 0.002,
            sigma: 0.02,
        },
        ids::DISC => Acoustic {
            z: 1.70,
            alpha: 0.8,
            sigma: 0.3,
        },
        ids::FAT => Acoustic {
            z: 1.38,
            alpha: 0.63,
            sigma: 0.35,
        },
        // Unossified cartilage (design: hypoechoic, slightly stiffer than muscle).
        ids::CARTILAGE | 117 => Acoustic {
            z: 1.75,
            alpha: 1.0,
            sigma: 0.1,
        },
        _ => SOFT,
    }
}

/// Intensity reflection coefficient between impedances `z1` and `z2`.
pub fn reflection(z1: f64, z2: f64) -> f64 {
    let r = (z2 - z1) / (z2 + z1);
    r * r
}

/// Lines along `axis`: apply `f(line_in, line_out)` to every line (inputs in increasing index
/// order), in parallel over fixed groups of lines; outputs are collected in order and written
/// back sequentially, so the result does not depend on the thread count.
fn map_lines<T, U, F>(data: &[T], dims: [usize; 3], axis: usize, f: F) -> Vec<U>
where
    T: Copy + Sync,
    U: Copy + Default + Send,
    F: Fn(&[T], &mut [U]) + Sync,
{
    let n = dims[axis];
    let stride = [1, dims[0], dims[0] * dims[1]];
    let nxy = dims[0] * dims[1];
    let mut res = vec![U::default(); data.len()];
    if axis < 2 {
        // The lines lie inside z-slices: one task per slice, written in place.
        let other = 1 - axis;
        res.par_chunks_mut(nxy).enumerate().for_each(|(kz, o)| {
            let inp = &data[kz * nxy..(kz + 1) * nxy];
            let mut line = Vec::with_capacity(n);
            let mut buf = vec![U::default(); n];
            for l in 0..dims[other] {
                let s0 = l * stride[other];
                line.clear();
                line.extend((0..n).map(|t| inp[s0 + t * stride[axis]]));
                f(&line, &mut buf);
                for (t, &v) in buf.iter().enumerate() {
                    o[s0 + t * stride[axis]] = v;
                }
            }
        });
        return res;
    }
    // Lines along z: fixed groups of rows (j), outputs collected in order, written back.
    let groups: Vec<Vec<U>> = (0..dims[1])
        .into_par_iter()
        .map(|j| {
            let mut out = vec![U::default(); dims[0] * n];
            let mut line = Vec::with_capacity(n);
            for i in 0..dims[0] {
                let s0 = i + dims[0] * j;
                line.clear();
                line.extend((0..n).map(|t| data[s0 + t * nxy]));
                f(&line, &mut out[i * n..(i + 1) * n]);
            }
            out
        })
        .collect();
    for (j, out) in groups.iter().enumerate() {
        for (i, line) in out.chunks(n).enumerate() {
            let s0 = i + dims[0] * j;
            for (t, &v) in line.iter().enumerate() {
                res[s0 + t * nxy] = v;
            }
        }
    }
    res
}

/// Normalised discrete Gaussian of standard deviation `sigma` voxels (radius ceil(3 sigma));
/// `[1]` when sigma is negligible.
fn gaussian_kernel(sigma: f64) -> Vec<f64> {
    if sigma < 1e-3 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil() as i64;
    let w: Vec<f64> = (-r..=r)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.into_iter().map(|v| v / s).collect()
}

/// Separable blur with one kernel per axis (edges replicated). Each output value is a fixed
/// weighted sum of inputs in a fixed order; work is split over z-slices (x and y passes) or
/// output slices (z pass), so the result does not depend on the thread count.
fn blur(data: &[f32], dims: [usize; 3], kernels: &[Vec<f64>; 3]) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let nxy = nx * ny;
    let mut cur = data.to_vec();
    let mut next = vec![0f32; data.len()];
    for (axis, k) in kernels.iter().enumerate() {
        if k.len() == 1 {
            continue;
        }
        let r = (k.len() / 2) as i64;
        let w: Vec<f32> = k.iter().map(|&v| v as f32).collect();
        let src = &cur;
        match axis {
            0 => next.par_chunks_mut(nx).enumerate().for_each(|(row, o)| {
                let inp = &src[row * nx..(row + 1) * nx];
                for (t, ov) in o.iter_mut().enumerate() {
                    let mut acc = 0.0f32;
                    for (q, &wq) in w.iter().enumerate() {
                        let s = (t as i64 + q as i64 - r).clamp(0, nx as i64 - 1);
                        acc += wq * inp[s as usize];
                    }
                    *ov = acc;
                }
            }),
            1 => next.par_chunks_mut(nxy).enumerate().for_each(|(kz, o)| {
                let inp = &src[kz * nxy..(kz + 1) * nxy];
                o.fill(0.0);
                for j in 0..ny {
                    let orow = &mut o[j * nx..(j + 1) * nx];
                    for (q, &wq) in w.iter().enumerate() {
                        let s = (j as i64 + q as i64 - r).clamp(0, ny as i64 - 1) as usize;
                        let irow = &inp[s * nx..(s + 1) * nx];
                        for (ov, &iv) in orow.iter_mut().zip(irow) {
                            *ov += wq * iv;
                        }
                    }
                }
            }),
            _ => next.par_chunks_mut(nxy).enumerate().for_each(|(kz, o)| {
                o.fill(0.0);
                for (q, &wq) in w.iter().enumerate() {
                    let s = (kz as i64 + q as i64 - r).clamp(0, nz as i64 - 1) as usize;
                    let islice = &src[s * nxy..(s + 1) * nxy];
                    for (ov, &iv) in o.iter_mut().zip(islice) {
                        *ov += wq * iv;
                    }
                }
            }),
        }
        std::mem::swap(&mut cur, &mut next);
    }
    cur
}

/// Check a label map's grid: non-zero dims, matching data length, finite positive spacing.
fn check_labels(labels: &LabelMap) -> Result<()> {
    let n = super::check_grid("labels.", labels.dims, labels.spacing)?;
    if n != Some(labels.data.len()) {
        return Err(Error::invalid(
            "labels.data",
            format!(
                "holds {} values but dims {:?} need {:?}",
                labels.data.len(),
                labels.dims,
                n
            ),
        ));
    }
    Ok(())
}

/// A B-mode-like scalar volume in [0, 1] on the grid of `labels`.
pub fn proxy(labels: &LabelMap, spec: &UsProxySpec) -> Result<Volume<f32>> {
    check_labels(labels)?;
    spec.validate()?;
    let dims = labels.dims;
    let axis = spec.beam.axis();
    let inc = spec.beam.increasing();
    let dx_cm = labels.spacing[axis] / 10.0;
    let f = spec.frequency_mhz;
    let ln10_10 = std::f64::consts::LN_10 / 10.0;
    let tgc_step = 2.0 * spec.tgc_db_per_cm_mhz * f * dx_cm * ln10_10;
    // Step 2: along every scan line, [incident intensity x R, T x sigma] per voxel.
    let echo: Vec<[f32; 2]> = map_lines(&labels.data, dims, axis, |lab: &[u16], out| {
        let n = lab.len();
        let mut log_t = 0.0f64; // two-way attenuation + reflection losses, without TGC
        let mut prev: Option<Acoustic> = None;
        for step in 0..n {
            let t = if inc { step } else { n - 1 - step };
            let ac = acoustic(lab[t]);
            let tgc = tgc_step * step as f64;
            let mut r = 0.0;
            if let Some(p) = prev {
                // Leave the previous voxel (its full two-way attenuation), meet the interface.
                log_t -= 2.0 * p.alpha * f * dx_cm * ln10_10;
                r = reflection(p.z, ac.z);
            }
            let incident = (log_t + tgc).min(0.0).exp();
            if r > 0.0 {
                log_t += 2.0 * (1.0 - r).ln();
            }
            let trans = (log_t + tgc).min(0.0).exp();
            out[t] = [(incident * r) as f32, (trans * ac.sigma) as f32];
            prev = Some(ac);
        }
    });
    let refl: Vec<f32> = echo.iter().map(|e| e[0]).collect();
    let scat: Vec<f32> = echo.iter().map(|e| e[1]).collect();
    drop(echo);
    // The PSF, per volume axis.
    let (lat, ele) = spec.beam.lateral_elevational();
    let mut sig_vox = [0.0; 3];
    sig_vox[axis] = spec.psf_sigma_mm[0] / labels.spacing[axis];
    sig_vox[lat] = spec.psf_sigma_mm[1] / labels.spacing[lat];
    sig_vox[ele] = spec.psf_sigma_mm[2] / labels.spacing[ele];
    let kernels = [
        gaussian_kernel(sig_vox[0]),
        gaussian_kernel(sig_vox[1]),
        gaussian_kernel(sig_vox[2]),
    ];
    // Step 3: Rayleigh speckle, normalised to mean 1 (interior variance of a blurred N(0,1)
    // field is prod_a sum_k w_ak^2; the mean of the modulus is sqrt(pi v / 2)).
    let key = noise::key(spec.seed, PURPOSE_SPECKLE);
    let n = labels.data.len();
    let mut g1 = vec![0f32; n];
    let mut g2 = vec![0f32; n];
    g1.par_chunks_mut(crate::par::CHUNK)
        .zip(g2.par_chunks_mut(crate::par::CHUNK))
        .enumerate()
        .for_each(|(c, (a, b))| {
            let lo = c * crate::par::CHUNK;
            for (q, (av, bv)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
                (*av, *bv) = noise::normal_pair_f32(key, (lo + q) as u64);
            }
        });
    let g1 = blur(&g1, dims, &kernels);
    let g2 = blur(&g2, dims, &kernels);
    let var: f64 = kernels
        .iter()
        .map(|k| k.iter().map(|w| w * w).sum::<f64>())
        .product();
    let rayleigh_mean = (std::f64::consts::PI * var / 2.0).sqrt();
    // Step 4: reflections through the PSF, normalised to a fully insonified bone surface.
    let refl = blur(&refl, dims, &kernels);
    let w0 = kernels[axis][kernels[axis].len() / 2];
    let r_ref = reflection(SOFT.z, BONE.z);
    let refl_scale = spec.reflection_gain / (w0 * r_ref);
    let a = spec.compression;
    let ln1a = (1.0 + a).ln();
    let mut out = vec![0f32; n];
    out.par_chunks_mut(crate::par::CHUNK)
        .enumerate()
        .for_each(|(c, o)| {
            let lo = c * crate::par::CHUNK;
            for (q, v) in o.iter_mut().enumerate() {
                let i = lo + q;
                let sp = ((g1[i] as f64).powi(2) + (g2[i] as f64).powi(2)).sqrt() / rayleigh_mean;
                let e = refl_scale * refl[i] as f64 + spec.speckle_gain * scat[i] as f64 * sp;
                // Step 5: log compression.
                *v = ((1.0 + a * e).ln() / ln1a).clamp(0.0, 1.0) as f32;
            }
        });
    Ok(Volume {
        data: out,
        dims,
        spacing: labels.spacing,
        offset: labels.offset,
        provenance: Provenance {
            source: "ultrasound proxy".into(),
            file_affine: None,
            steps: vec![format!(
                "B-mode-like proxy from labels (seed {}, beam {:?}, {} MHz, TGC {} dB/cm/MHz, \
                 PSF sigma axial/lateral/elevational {:?} mm, g_r {}, g_s {}, log compression \
                 a = {}), values in [0, 1]",
                spec.seed,
                spec.beam,
                spec.frequency_mhz,
                spec.tgc_db_per_cm_mhz,
                spec.psf_sigma_mm,
                spec.reflection_gain,
                spec.speckle_gain,
                spec.compression
            )],
        },
    })
}
