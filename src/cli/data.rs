//! `unispine data`: make a projection dataset folder (see `dataset::store`) from the built-in
//! phantom, a CT, an ultrasound volume or the ultrasound-like proxy, or import a NAF-layout
//! pickle. Every generator subcommand takes the same dataset flags (views, span, detector,
//! noise, seed, scanner distances, projector); their defaults are the paper's protocol.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{bail, Context};
use clap::{Args, Subcommand, ValueEnum};

use super::progress::Progress;
use unispine::dataset::generate::{self, GenerateOptions, Noise};
use unispine::dataset::{pickle, store, Dataset};
use unispine::drr::Method;
use unispine::geometry::Mode;
use unispine::volume::attenuation::{HuConversion, Normalization};
use unispine::volume::phantom::{self, PhantomSpec};
use unispine::volume::{resample, ultrasound, Volume};

/// Arguments of `unispine data`.
#[derive(Debug, Args)]
pub struct DataArgs {
    #[command(subcommand)]
    pub source: Source,
}

/// Where the volume comes from.
#[derive(Debug, Subcommand)]
pub enum Source {
    /// The built-in procedural spine phantom (linear attenuation in 1/mm at about 70 keV).
    Phantom(PhantomArgs),
    /// A CT volume (NIfTI, MetaImage or npy), optionally cropped to labelled vertebrae.
    Ct(CtArgs),
    /// A real ultrasound volume (MetaImage, NIfTI or npy) projected as a scalar field.
    Us(UsArgs),
    /// The ultrasound-like (B-mode) proxy computed from the phantom's labels.
    UsProxy(PhantomArgs),
    /// Import a NAF / SAX-NeRF / X-Gaussian / UniSpine-GS dataset pickle.
    Import(ImportArgs),
}

/// Projector choice on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ProjectorArg {
    /// Exact line integrals through the voxel grid (TIGRE `Ax` default).
    Siddon,
    /// Trilinear ray-march with step `accuracy` x voxel (TIGRE 'interpolated').
    Trilinear,
}

/// Beam shape on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Divergent cone beam from a point source (the paper).
    Cone,
    /// Parallel rays.
    Parallel,
}

/// Flags shared by every generator subcommand. Defaults: the paper's protocol.
#[derive(Debug, Clone, Args)]
pub struct DatasetFlags {
    /// Output folder (created; files of an earlier dataset there are overwritten).
    #[arg(long)]
    pub out: PathBuf,
    /// Training views, evenly spaced over the span: theta_k = k * span / N (paper: 50, every
    /// 3.6 deg).
    #[arg(long, default_value_t = 50)]
    pub train_views: usize,
    /// Test views, at the midpoints: theta_k = (k + 1/2) * span / N (paper: 50, at 1.8 + 3.6 k
    /// deg). Must be at least 1.
    #[arg(long, default_value_t = 50)]
    pub test_views: usize,
    /// Angular span of the orbit in degrees (paper: 180).
    #[arg(long, default_value_t = 180.0)]
    pub span_deg: f64,
    /// Detector pixels per side (square). The pixel pitch is chosen so the detector covers the
    /// projection of the volume's box at every angle, plus `--margin` (a 2-D volume, one voxel
    /// in z, gets rows of their own, finer pitch). At most 8 GiB of projections in all.
    #[arg(long, default_value_t = 256)]
    pub detector: usize,
    /// Extra detector coverage around the volume's projection (0.05 = 5 %).
    #[arg(long, default_value_t = 0.05)]
    pub margin: f64,
    /// Noise: `none`, `poisson:I0[,SIGMA]` (TIGRE CTnoise-style, NAF uses poisson:1e5,10) or
    /// `gaussian:S` (additive, S times the largest projection value).
    #[arg(long, default_value = "none")]
    pub noise: String,
    /// Seed of every random choice (phantom anatomy, speckle, noise).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Source-detector distance in mm (NAF / SAX-NeRF / UniSpine-GS: 1500).
    #[arg(long, default_value_t = unispine::geometry::DSD_MM)]
    pub dsd: f64,
    /// Source-origin distance in mm (NAF / SAX-NeRF / UniSpine-GS: 1000).
    #[arg(long, default_value_t = unispine::geometry::DSO_MM)]
    pub dso: f64,
    /// Beam shape.
    #[arg(long, value_enum, default_value = "cone")]
    pub mode: ModeArg,
    /// Projector.
    #[arg(long, value_enum, default_value = "siddon")]
    pub projector: ProjectorArg,
    /// Pose error: the recorded training cameras are rotated about a uniformly random axis
    /// through the isocentre by N(0, S^2) degrees (the projections use the exact cameras; test
    /// cameras stay exact). 0 with `--pose-noise-mm 0` = the exact cameras, today's dataset.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub pose_noise_deg: f64,
    /// Pose error: the recorded training sources and detectors are translated by N(0, T^2) mm
    /// per axis.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub pose_noise_mm: f64,
    /// Seed of the pose error (default: `--seed`).
    #[arg(long)]
    pub pose_seed: Option<u64>,
}

/// The pose error of `f`'s training views (None: exact cameras); errors name the flag.
fn pose_noise(
    f: &DatasetFlags,
    views: usize,
) -> anyhow::Result<Option<unispine::dataset::pose::PoseNoise>> {
    Ok(unispine::dataset::pose::draw(
        f.pose_noise_deg,
        f.pose_noise_mm,
        f.pose_seed.unwrap_or(f.seed),
        views,
    )?)
}

/// `data phantom` and `data us-proxy`.
#[derive(Debug, Args)]
pub struct PhantomArgs {
    /// Fetal variant (small torso in amniotic fluid, three ossification centres per vertebra).
    #[arg(long)]
    pub fetal: bool,
    /// Voxels per side of the phantom cube. The physical box stays the default one (128 mm
    /// adult, 51.2 mm fetal), so a smaller size means coarser voxels.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    #[command(flatten)]
    pub data: DatasetFlags,
}

/// `data ct`.
#[derive(Debug, Args)]
pub struct CtArgs {
    /// The CT volume in HU (`.nii`, `.nii.gz`, `.mha`, `.mhd` or `.npy`).
    #[arg(long)]
    pub volume: PathBuf,
    /// A label volume on the CT's grid (TotalSegmentator-style ids): crop to `--crop-labels`.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Label ids to crop to, as a range `A-B` or a list `A,B,C` (vertebrae: 25-50).
    #[arg(long, default_value = "25-50")]
    pub crop_labels: String,
    /// Margin around the labels' bounding box, mm.
    #[arg(long, default_value_t = 10.0)]
    pub margin_mm: f64,
    /// HU conversion: `naf-mu` (NAF: mu = 0.206 + (0.206 - 0.0004) / 1000 HU in 1/cm, clamped
    /// at 0), `linear-clip` ([-1000, 2000] HU -> [0, 1]) or `none`.
    #[arg(long, value_parser = super::flags::choice::<HuConversion>(), default_value = "naf-mu")]
    pub hu: HuConversion,
    /// Normalisation after the HU conversion: `min-max` to [0, 1] (NAF / UniSpine-GS),
    /// `percentile` (0.5 / 99.5 %) or `none`.
    #[arg(long, value_parser = super::flags::choice::<Normalization>(), default_value = "min-max")]
    pub normalize: Normalization,
    /// Resample so that no axis has more than N voxels (trilinear, same physical box; axes
    /// already at or below N are kept). 0 keeps the grid.
    #[arg(long, default_value_t = 128)]
    pub resample: usize,
    #[command(flatten)]
    pub data: DatasetFlags,
}

/// `data us`.
#[derive(Debug, Args)]
pub struct UsArgs {
    /// The ultrasound volume (`.mha`, `.mhd`, `.nii`, `.nii.gz` or `.npy`).
    #[arg(long)]
    pub volume: PathBuf,
    /// Resample so that no axis has more than N voxels (0 keeps the grid).
    #[arg(long, default_value_t = 0)]
    pub resample: usize,
    #[command(flatten)]
    pub data: DatasetFlags,
}

/// `data import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The NAF-layout pickle (protocol 2-5, numpy 1.x or 2.x).
    #[arg(long)]
    pub pickle: PathBuf,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Factor applied to the stored projections: NAF-family generators compute them in metres,
    /// 1000 converts to our mm. Use 1 for pickles already in mm.
    #[arg(long, default_value_t = unispine::geometry::DSO_MM)]
    pub projection_scale: f64,
}

/// Run `unispine data`.
pub fn run(args: DataArgs) -> anyhow::Result<()> {
    match args.source {
        Source::Phantom(a) => run_phantom(a, false),
        Source::UsProxy(a) => run_phantom(a, true),
        Source::Ct(a) => run_ct(a),
        Source::Us(a) => run_us(a),
        Source::Import(a) => run_import(a),
    }
}

fn options(f: &DatasetFlags, units: &str, normalisation: &str) -> anyhow::Result<GenerateOptions> {
    let o = GenerateOptions {
        train_views: f.train_views,
        test_views: f.test_views,
        span_deg: f.span_deg,
        start_deg: 0.0,
        detector: f.detector,
        margin: f.margin,
        dsd: f.dsd,
        dso: f.dso,
        mode: match f.mode {
            ModeArg::Cone => Mode::Cone,
            ModeArg::Parallel => Mode::Parallel,
        },
        projector: match f.projector {
            ProjectorArg::Siddon => Method::Siddon,
            ProjectorArg::Trilinear => Method::Trilinear,
        },
        accuracy: 0.5,
        noise: Noise::parse(&f.noise).context("--noise")?,
        seed: f.seed,
        volume_units: units.into(),
        volume_normalisation: normalisation.into(),
    };
    o.validate().map_err(flag_error)?;
    pose_noise(f, 0)?;
    Ok(o)
}

/// Turn an option-field error into one naming the command-line flag.
fn flag_error(e: unispine::error::Error) -> anyhow::Error {
    match e {
        unispine::error::Error::Invalid { field, msg } => {
            let flag = match field.as_str() {
                "train_views" => "--train-views",
                "test_views" => "--test-views",
                "span_deg" => "--span-deg",
                "detector" => "--detector",
                "margin" => "--margin",
                "DSD" => "--dsd",
                "DSO" => "--dso",
                other => return anyhow::anyhow!("invalid `{other}`: {msg}"),
            };
            anyhow::anyhow!("invalid {flag}: {msg}")
        }
        other => other.into(),
    }
}

/// Project `vol` and write the dataset, with a progress bar.
fn make(vol: &Volume<f32>, opts: &GenerateOptions, flags: &DatasetFlags) -> anyhow::Result<()> {
    let out = flags.out.as_path();
    let total = (opts.train_views + opts.test_views) as u64;
    let bar = Mutex::new(Progress::new("projecting", total));
    let ds = generate::generate(vol, opts, &|done, _total| {
        if let Ok(mut b) = bar.lock() {
            b.inc(1, &format!("view {done}"));
        }
    })?;
    bar.into_inner()
        .map(|b| b.finish(&format!("{total} views")))
        .ok();
    let mut ds = ds;
    if let Some(p) = pose_noise(flags, ds.train.angles.len())? {
        unispine::dataset::pose::check(&p, &ds.geometry, &ds.train.angles).map_err(|e| {
            anyhow::anyhow!(
                "invalid --pose-noise-deg {} / --pose-noise-mm {}: {e}",
                flags.pose_noise_deg,
                flags.pose_noise_mm
            )
        })?;
        ds.manifest.pose_noise = Some(p);
    }
    save(&ds, out)
}

fn save(ds: &Dataset, out: &Path) -> anyhow::Result<()> {
    store::save(ds, out).with_context(|| format!("writing the dataset to {}", out.display()))?;
    let g = &ds.geometry;
    let range = |views: &[unispine::image2d::Image2d<f32>]| {
        views
            .iter()
            .flat_map(|v| v.data.iter())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            })
    };
    let (lo, hi) = range(&ds.train.projections);
    println!("dataset: {}", out.join("dataset.json").display());
    println!(
        "  views: {} train, {} test; detector {}x{} px at {:.4} mm; DSD {} mm, DSO {} mm",
        ds.train.angles.len(),
        ds.test.angles.len(),
        g.n_detector[0],
        g.n_detector[1],
        g.d_detector[0],
        g.dsd,
        g.dso
    );
    println!(
        "  volume: {:?} voxels of {:?} mm; projections in {} range [{lo:.4}, {hi:.4}]",
        g.n_voxel, g.d_voxel, ds.manifest.projection_units
    );
    Ok(())
}

fn phantom_spec(a: &PhantomArgs) -> anyhow::Result<PhantomSpec> {
    if a.size == 0 || a.size > 1024 {
        bail!(
            "invalid --size: must be 1..=1024 voxels per side, got {}",
            a.size
        );
    }
    let base = if a.fetal {
        PhantomSpec::fetal_default()
    } else {
        PhantomSpec::default()
    };
    let spacing = [0, 1, 2].map(|k| base.spacing[k] * base.dims[k] as f64 / a.size as f64);
    Ok(PhantomSpec {
        seed: a.data.seed,
        dims: [a.size; 3],
        spacing,
        fetal: a.fetal,
    })
}

fn run_phantom(a: PhantomArgs, proxy: bool) -> anyhow::Result<()> {
    let spec = phantom_spec(&a)?;
    // Validate the dataset flags before the (possibly long) phantom generation.
    let _ = options(&a.data, "", "")?;
    eprintln!(
        "phantom: {}^3 voxels of {:.3} mm, seed {}{}",
        a.size,
        spec.spacing[0],
        spec.seed,
        if a.fetal { ", fetal" } else { "" }
    );
    let (mu, labels) = phantom::generate(&spec)?;
    let (vol, opts) = if proxy {
        let us = ultrasound::proxy(
            &labels,
            &ultrasound::UsProxySpec {
                seed: a.data.seed,
                ..Default::default()
            },
        )?;
        let o = options(
            &a.data,
            "B-mode-like echo, [0, 1]",
            "ultrasound-like proxy from the phantom labels, values in [0, 1]",
        )?;
        (us, o)
    } else {
        let o = options(
            &a.data,
            "1/mm",
            "linear attenuation at about 70 keV in 1/mm (not normalised; projections are \
             optical depths)",
        )?;
        (mu, o)
    };
    make(&vol, &opts, &a.data)
}

/// Parse `25-50` or `25,26,30` into label ids.
pub fn parse_label_ids(s: &str) -> anyhow::Result<Vec<u16>> {
    let bad =
        || anyhow::anyhow!("invalid --crop-labels `{s}`: expected `A-B` or `A,B,C` (ids 0-65535)");
    let mut ids = Vec::new();
    for part in s.split(',') {
        let part = part.trim();
        if let Some((a, b)) = part.split_once('-') {
            let a: u16 = a.trim().parse().map_err(|_| bad())?;
            let b: u16 = b.trim().parse().map_err(|_| bad())?;
            if a > b {
                return Err(bad());
            }
            ids.extend(a..=b);
        } else {
            ids.push(part.parse().map_err(|_| bad())?);
        }
    }
    Ok(ids)
}

/// Resample so that no axis exceeds `n` voxels (0: unchanged).
fn cap_voxels(vol: Volume<f32>, n: usize) -> anyhow::Result<Volume<f32>> {
    if n == 0 || vol.dims.iter().all(|&d| d <= n) {
        return Ok(vol);
    }
    let dims = vol.dims.map(|d| d.min(n));
    eprintln!("resampling {:?} -> {:?} voxels (trilinear)", vol.dims, dims);
    Ok(resample::resample_trilinear(&vol, dims)?)
}

fn run_ct(a: CtArgs) -> anyhow::Result<()> {
    let ids = parse_label_ids(&a.crop_labels)?;
    let _ = options(&a.data, "", "")?;
    let outs = store::output_files(&a.data.out);
    unispine::fsio::check_not_output("--volume", &a.volume, &outs)?;
    if let Some(m) = &a.mask {
        unispine::fsio::check_not_output("--mask", m, &outs)?;
    }
    eprintln!("loading {}", a.volume.display());
    let mut vol = unispine::volume::load(&a.volume)?;
    vol.check_finite(&format!("{}", a.volume.display()))?;
    if let Some(m) = &a.mask {
        eprintln!("loading {}", m.display());
        let labels = unispine::volume::load_labels(m)?;
        vol = resample::crop_to_labels(&vol, &labels, &ids, a.margin_mm).with_context(|| {
            format!(
                "cropping {} to the labels of {}",
                a.volume.display(),
                m.display()
            )
        })?;
        resample::recentre(&mut vol);
    }
    // NAF order: HU conversion, resize, then normalisation (so the result spans [0, 1]).
    a.hu.apply(&mut vol);
    let mut vol = cap_voxels(vol, a.resample)?;
    a.normalize
        .apply(&mut vol)
        .with_context(|| format!("normalising {}", a.volume.display()))?;
    let units = match (a.hu, a.normalize) {
        (_, Normalization::MinMax | Normalization::Percentile) => "normalised [0, 1]",
        (HuConversion::NafMu, Normalization::None) => "1/cm (NAF mu)",
        (HuConversion::LinearClip, Normalization::None) => "[0, 1] from HU [-1000, 2000]",
        (HuConversion::None, Normalization::None) => "HU",
    };
    let norm = format!(
        "HU conversion `{}`, normalisation `{:?}`; steps: {}",
        a.hu.name(),
        a.normalize,
        vol.provenance.steps.join("; ")
    );
    let opts = options(&a.data, units, &norm)?;
    make(&vol, &opts, &a.data)
}

fn run_us(a: UsArgs) -> anyhow::Result<()> {
    let _ = options(&a.data, "", "")?;
    unispine::fsio::check_not_output("--volume", &a.volume, &store::output_files(&a.data.out))?;
    eprintln!("loading {}", a.volume.display());
    let mut vol = unispine::volume::load(&a.volume)?;
    vol.check_finite(&format!("{}", a.volume.display()))?;
    resample::recentre(&mut vol);
    let mut vol = cap_voxels(vol, a.resample)?;
    Normalization::MinMax
        .apply(&mut vol)
        .with_context(|| format!("normalising {}", a.volume.display()))?;
    let opts = options(
        &a.data,
        "echo intensity, min-max normalised to [0, 1]",
        "ultrasound scalar field, min-max normalised to [0, 1] (the paper projects ultrasound \
         volumes with the same operator as CT)",
    )?;
    make(&vol, &opts, &a.data)
}

fn run_import(a: ImportArgs) -> anyhow::Result<()> {
    unispine::fsio::check_not_output("--pickle", &a.pickle, &store::output_files(&a.out))?;
    eprintln!("reading {}", a.pickle.display());
    let ds = pickle::import(
        &a.pickle,
        &pickle::ImportOptions {
            projection_scale: a.projection_scale,
        },
    )
    .map_err(|e| match e {
        unispine::error::Error::Invalid { field, msg } if field == "projection_scale" => {
            anyhow::anyhow!("invalid --projection-scale: {msg}")
        }
        other => other.into(),
    })?;
    save(&ds, &a.out)
}
