//! Built-in procedural spine phantom: the embedded default data set (no download).
//!
//! A lumbar / lower-thoracic spine segment along world z (+z superior, image row 0 of every
//! projection) inside an elliptic torso: vertebral bodies (cortical shell and textured
//! cancellous core), intervertebral discs, the spinal canal, the posterior elements (pedicles
//! and laminae as a ring, spinous and transverse processes), muscle / soft tissue, a fat rim and
//! air outside. Values are linear attenuation coefficients in 1/mm at about 70 keV (see
//! [`Tissue::mu`] and docs/phantom.md for the sources). The fetal variant is a small torso in
//! amniotic fluid whose vertebrae are cartilage with three ossification centres each.
//!
//! Determinism: the per-vertebra parameters are drawn once, in a fixed order, from a
//! `ChaCha8Rng` seeded by the spec's seed; then every voxel is a pure function of its position
//! and of those parameters (the cancellous texture uses a counter-based hash of the position).
//! The volume is filled in parallel over z-slices, so the result is bit-identical for any
//! thread count.
//!
//! Label ids follow TotalSegmentator v2 where it has a class (vertebrae 25-50, spinal cord 79),
//! so `crop to ids 25-50` works as for the real CT; see [`ids`].

mod anatomy;
pub(crate) mod noise;

use rayon::prelude::*;

use super::{LabelMap, Provenance, Volume};
use crate::error::{Error, Result};

/// Label ids of the phantom's label map.
pub mod ids {
    /// Outside the body: air (adult). The fetal variant uses [`FLUID`] there instead.
    pub const BACKGROUND: u16 = 0;
    /// First id of TotalSegmentator's vertebra range (25 = sacrum, 26 = S1).
    pub const VERTEBRA_FIRST: u16 = 25;
    /// TotalSegmentator `vertebrae_L5`: the lowest vertebra reaching the box; the ones above get
    /// 28 (L4), 29 (L3), 30 (L2), 31 (L1), 32 (T12), ...
    pub const VERTEBRA_L5: u16 = 27;
    /// Last id of the vertebra range (50 = C1).
    pub const VERTEBRA_LAST: u16 = 50;
    /// Spinal canal (CSF and cord): TotalSegmentator `spinal_cord`.
    pub const CANAL: u16 = 79;
    /// Intervertebral disc (no TotalSegmentator class in the `total` task).
    pub const DISC: u16 = 200;
    /// Soft tissue / muscle inside the fat rim.
    pub const SOFT_TISSUE: u16 = 201;
    /// Subcutaneous fat rim.
    pub const FAT: u16 = 202;
    /// Amniotic fluid (fetal variant, outside the fetus).
    pub const FLUID: u16 = 203;
    /// Unossified vertebral cartilage (fetal variant).
    pub const CARTILAGE: u16 = 204;

    /// True for a vertebra id (25-50): the bony voxels of one vertebra.
    pub fn is_vertebra(id: u16) -> bool {
        (VERTEBRA_FIRST..=VERTEBRA_LAST).contains(&id)
    }
}

/// Tissue classes of the phantom (finer than the label map: the label map gives every bony
/// voxel of a vertebra that vertebra's id, as TotalSegmentator does).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Tissue {
    Air = 0,
    Fat = 1,
    SoftTissue = 2,
    Disc = 3,
    Canal = 4,
    Cancellous = 5,
    Cortical = 6,
    PosteriorBone = 7,
    Fluid = 8,
    Cartilage = 9,
    Ossification = 10,
}

impl Tissue {
    /// Every tissue, in code order.
    pub const ALL: [Tissue; 11] = [
        Tissue::Air,
        Tissue::Fat,
        Tissue::SoftTissue,
        Tissue::Disc,
        Tissue::Canal,
        Tissue::Cancellous,
        Tissue::Cortical,
        Tissue::PosteriorBone,
        Tissue::Fluid,
        Tissue::Cartilage,
        Tissue::Ossification,
    ];

    /// The tissue with code `c`.
    pub fn from_code(c: u8) -> Option<Tissue> {
        Tissue::ALL.get(c as usize).copied()
    }

    /// Linear attenuation coefficient at about 70 keV, in 1/mm. Sources (the
    /// NIST-format tables shipped with deepdrr 1.2.2, `deepdrr/material/material_decompositions/`,
    /// and the HU -> mu rule
    /// mu = 0.01936 (1 + HU/1000) /mm, the NAF mapping with mu_water at 70 keV):
    /// air 2e-5 (stored as 0, see notes); fat -100 HU; soft tissue = muscle 0.1924 cm2/g x
    /// 1.05 g/cm3; disc 90 HU; canal (CSF) 10 HU; cancellous 200 HU (mean; per vertebra
    /// 175-225 HU and +-60 HU texture, L1 norms of Jang et al., Radiology 2019); cortical
    /// 0.2616 cm2/g x 1.92 g/cm3; posterior elements 700 HU (a cortical / cancellous mix);
    /// water / amniotic fluid 0.1936 cm2/g x 1.00; fetal cartilage 50 HU; fetal ossification
    /// centres 800 HU (design: partly mineralised bone between cancellous and cortical).
    pub fn mu(self) -> f32 {
        match self {
            Tissue::Air => 0.0,
            Tissue::Fat => 0.0174,
            Tissue::SoftTissue => 0.0202,
            Tissue::Disc => 0.0211,
            Tissue::Canal => 0.0196,
            Tissue::Cancellous => 0.0232,
            Tissue::Cortical => 0.0502,
            Tissue::PosteriorBone => 0.0329,
            Tissue::Fluid => 0.0194,
            Tissue::Cartilage => 0.0203,
            Tissue::Ossification => 0.0348,
        }
    }

    /// Bony tissue (labelled with its vertebra's id).
    pub fn is_bone(self) -> bool {
        matches!(
            self,
            Tissue::Cancellous | Tissue::Cortical | Tissue::PosteriorBone | Tissue::Ossification
        )
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Tissue::Air => "air",
            Tissue::Fat => "fat",
            Tissue::SoftTissue => "soft tissue",
            Tissue::Disc => "disc",
            Tissue::Canal => "canal",
            Tissue::Cancellous => "cancellous bone",
            Tissue::Cortical => "cortical bone",
            Tissue::PosteriorBone => "posterior elements",
            Tissue::Fluid => "amniotic fluid",
            Tissue::Cartilage => "cartilage",
            Tissue::Ossification => "ossification centre",
        }
    }
}

/// Settings of the procedural phantom.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhantomSpec {
    /// Seed of every random choice (same seed, same phantom, bit for bit).
    pub seed: u64,
    /// Voxel counts `[x, y, z]`.
    pub dims: [usize; 3],
    /// Voxel size `[x, y, z]` in mm.
    pub spacing: [f64; 3],
    /// Fetal variant (small scale, ossification centres, fluid).
    pub fetal: bool,
}

impl Default for PhantomSpec {
    fn default() -> Self {
        PhantomSpec {
            seed: 0,
            dims: [128, 128, 128],
            spacing: [1.0, 1.0, 1.0],
            fetal: false,
        }
    }
}

impl PhantomSpec {
    /// The fetal default: 128^3 voxels of 0.4 mm (a 51 mm box around a ~22-week torso).
    pub fn fetal_default() -> Self {
        PhantomSpec {
            seed: 0,
            dims: [128, 128, 128],
            spacing: [0.4, 0.4, 0.4],
            fetal: true,
        }
    }

    /// Error naming the field when the spec cannot produce a phantom.
    pub fn validate(&self) -> Result<()> {
        let n = super::check_grid("", self.dims, self.spacing)?.filter(|&n| n <= MAX_VOXELS);
        if n.is_none() {
            return Err(Error::invalid(
                "dims",
                format!("{:?} holds more than {MAX_VOXELS} voxels", self.dims),
            ));
        }
        Ok(())
    }
}

/// Largest partial-volume sampling factor per axis.
pub const MAX_SUPERSAMPLE: usize = 8;

/// Largest phantom (voxels): 1024^3 (4 GiB of f32).
pub const MAX_VOXELS: usize = 1 << 30;

/// One vertebra of a generated phantom (world mm).
#[derive(Clone, Debug, PartialEq)]
pub struct VertebraInfo {
    /// Label id (TotalSegmentator numbering).
    pub id: u16,
    /// Mid-height z of the body.
    pub z_centre: f64,
    /// Canal centre (x, y) at mid-height.
    pub canal_centre: [f64; 2],
    /// Body centre (x, y) at mid-height.
    pub body_centre: [f64; 2],
    /// Body half-height, and the body's semi-axes (x, y).
    pub body_half_height: f64,
    pub body_semi_axes: [f64; 2],
    /// Cortical shell thickness (mm).
    pub cortical_thickness: f64,
    /// Mean cancellous attenuation of this vertebra (1/mm).
    pub mu_cancellous: f64,
    /// Fetal variant: the two neural-arch ossification centres are present.
    pub arch_centres: bool,
}

/// A generated phantom with its tissue classes and per-vertebra description.
#[derive(Clone, Debug)]
pub struct Phantom {
    /// Linear attenuation (1/mm).
    pub mu: Volume<f32>,
    /// Label ids ([`ids`]).
    pub labels: LabelMap,
    /// Tissue code ([`Tissue`] as u8) of every voxel, same indexing.
    pub tissue: Vec<u8>,
    /// The vertebrae that reach the box, from the bottom.
    pub vertebrae: Vec<VertebraInfo>,
    /// Anatomical scale (1 = adult lumbar size).
    pub scale: f64,
    /// Torso outline semi-axes (x, y) in mm and fat-rim thickness.
    pub torso_semi_axes: [f64; 2],
    pub fat_thickness: f64,
}

/// Partial volume: boundary voxels (a 6-neighbour has another tissue) get the mean attenuation
/// of ss^3 sub-voxel samples at offsets ((a + 1/2)/ss - 1/2) voxel. Parallel over z-slices;
/// each voxel depends only on its position, the layout and the (finished) crisp tissue map.
fn partial_volume(
    layout: &anatomy::Layout,
    spec: &PhantomSpec,
    ss: usize,
    tis: &[u8],
    mu: &mut [f32],
    xs: &[f64],
    ys: &[f64],
) {
    let [nx, ny, nz] = spec.dims;
    let d = spec.spacing;
    let nxy = nx * ny;
    let off: Vec<f64> = (0..ss)
        .map(|a| (a as f64 + 0.5) / ss as f64 - 0.5)
        .collect();
    let zc = |k: usize| -(nz as f64) * d[2] / 2.0 + (k as f64 + 0.5) * d[2];
    mu.par_chunks_mut(nxy).enumerate().for_each(|(k, mu_s)| {
        let subs: Vec<(f64, anatomy::Slice)> = off
            .iter()
            .map(|o| {
                let z = zc(k) + o * d[2];
                (z, layout.slice(z))
            })
            .collect();
        let t_at = |i: usize, j: usize, k: usize| tis[i + nx * (j + ny * k)];
        for j in 0..ny {
            for i in 0..nx {
                let t = t_at(i, j, k);
                let boundary = (i > 0 && t_at(i - 1, j, k) != t)
                    || (i + 1 < nx && t_at(i + 1, j, k) != t)
                    || (j > 0 && t_at(i, j - 1, k) != t)
                    || (j + 1 < ny && t_at(i, j + 1, k) != t)
                    || (k > 0 && t_at(i, j, k - 1) != t)
                    || (k + 1 < nz && t_at(i, j, k + 1) != t);
                if !boundary {
                    continue;
                }
                let mut acc = 0.0f64;
                for (z, sl) in &subs {
                    for oy in &off {
                        let y = ys[j] + oy * d[1];
                        for ox in &off {
                            let x = xs[i] + ox * d[0];
                            let (t2, id2) = layout.classify(sl, x, y);
                            acc += if t2 == Tissue::Cancellous {
                                layout.mu(t2, layout.vert_by_id(id2), [x, y, *z])
                            } else {
                                t2.mu() as f64
                            };
                        }
                    }
                }
                mu_s[i + nx * j] = (acc / (ss * ss * ss) as f64) as f32;
            }
        }
    });
}

/// Generate the phantom: linear attenuation (1/mm) and the label volume beside it.
pub fn generate(spec: &PhantomSpec) -> Result<(Volume<f32>, LabelMap)> {
    let p = generate_detailed(spec)?;
    Ok((p.mu, p.labels))
}

/// Generate the phantom with its tissue map and vertebra list (voxels take the tissue at their
/// centre).
pub fn generate_detailed(spec: &PhantomSpec) -> Result<Phantom> {
    generate_partial_volume(spec, 1)
}

/// Generate the phantom with partial-volume sampling: voxels on a tissue boundary (a
/// 6-neighbour has another tissue) take the mean attenuation of `supersample`^3 sub-voxel
/// samples; `supersample` = 1 is [`generate_detailed`]. The label map and the tissue map
/// always follow the voxel centre. Error naming `supersample` outside 1..=8.
pub fn generate_partial_volume(spec: &PhantomSpec, supersample: usize) -> Result<Phantom> {
    spec.validate()?;
    if !(1..=MAX_SUPERSAMPLE).contains(&supersample) {
        return Err(Error::invalid(
            "supersample",
            format!("must be 1 (off) to {MAX_SUPERSAMPLE}, got {supersample}"),
        ));
    }
    let [nx, ny, nz] = spec.dims;
    let d = spec.spacing;
    let size = [nx as f64 * d[0], ny as f64 * d[1], nz as f64 * d[2]];
    let centre = |a: usize, i: usize| -size[a] / 2.0 + (i as f64 + 0.5) * d[a];
    let dmax = d[0].max(d[1]).max(d[2]);
    let layout = anatomy::Layout::new(
        spec.seed,
        spec.fetal,
        size,
        centre(2, 0),
        centre(2, nz - 1),
        dmax,
    )?;
    let nxy = nx * ny;
    let n = nxy * nz;
    let mut mu = vec![0f32; n];
    let mut lab = vec![0u16; n];
    let mut tis = vec![0u8; n];
    // x and y centres once (the same for every slice).
    let xs: Vec<f64> = (0..nx).map(|i| centre(0, i)).collect();
    let ys: Vec<f64> = (0..ny).map(|j| centre(1, j)).collect();
    mu.par_chunks_mut(nxy)
        .zip(lab.par_chunks_mut(nxy))
        .zip(tis.par_chunks_mut(nxy))
        .enumerate()
        .for_each(|(k, ((mu_s, lab_s), tis_s))| {
            let z = centre(2, k);
            let sl = layout.slice(z);
            for (j, &y) in ys.iter().enumerate() {
                for (i, &x) in xs.iter().enumerate() {
                    let (t, id) = layout.classify(&sl, x, y);
                    let idx = i + nx * j;
                    let m = if t == Tissue::Cancellous {
                        layout.mu(t, layout.vert_by_id(id), [x, y, z])
                    } else {
                        t.mu() as f64
                    };
                    mu_s[idx] = m as f32;
                    lab_s[idx] = id;
                    tis_s[idx] = t as u8;
                }
            }
        });
    if supersample > 1 {
        partial_volume(&layout, spec, supersample, &tis, &mut mu, &xs, &ys);
    }
    let vertebrae: Vec<VertebraInfo> = layout
        .verts
        .iter()
        .filter(|v| v.id != 0)
        .map(|v| {
            let (bx, by) = v.body_centre();
            VertebraInfo {
                id: v.id,
                z_centre: v.zc,
                canal_centre: [v.cx, v.cy],
                body_centre: [bx, by],
                body_half_height: v.hh,
                body_semi_axes: [v.a, v.b],
                cortical_thickness: v.t,
                mu_cancellous: v.mu_canc,
                arch_centres: v.arch_centres,
            }
        })
        .collect();
    let ids_str = vertebrae
        .iter()
        .map(|v| v.id.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let provenance = Provenance {
        source: "phantom".into(),
        file_affine: None,
        steps: vec![format!(
            "procedural spine phantom (seed {}, {}, dims {:?}, spacing {:?} mm, scale {:.4}, \
             vertebra ids {}, partial-volume sampling {}^3), linear attenuation in 1/mm at \
             ~70 keV",
            spec.seed,
            if spec.fetal { "fetal" } else { "adult" },
            spec.dims,
            spec.spacing,
            layout.s,
            ids_str,
            supersample
        )],
    };
    Ok(Phantom {
        mu: Volume {
            data: mu,
            dims: spec.dims,
            spacing: spec.spacing,
            offset: [0.0; 3],
            provenance,
        },
        labels: LabelMap {
            data: lab,
            dims: spec.dims,
            spacing: spec.spacing,
            offset: [0.0; 3],
        },
        tissue: tis,
        vertebrae,
        scale: layout.s,
        torso_semi_axes: [layout.ax, layout.ay],
        fat_thickness: layout.fat,
    })
}
