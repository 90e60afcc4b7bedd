//! `unispine render`: render Gaussians from a 3DGS-layout PLY for one view and, optionally, the
//! gradient of sum(W * image) with respect to every stored PLY field. This is how another backend
//! (or a person) audits a forward pass or a gradient without writing Rust.
//!
//! Outputs in `--out`:
//! - `image.npy`: f32 [v, u], row 0 = top;
//! - `image.png`: the same, min-max scaled to 8 bits;
//! - `grads.npz` (with `--grad-weights W.npy`): one array per PLY field group, in the PLY's stored
//!   (pre-activation) parametrisation and in the computing precision (f64 by default):
//!   `xyz` [N, 3], `features` [N, 3 + 3 K] (`f_dc_0..2` then `f_rest_0..3K-1`, channel-major as
//!   stored; K = rest coefficients per channel present in the file), `opacity` \[N\] (logit),
//!   `scale` [N, 3] (log-scale), `rot` [N, 4] (unnormalised quaternion w, x, y, z).
//!   The file's three colour channels are averaged into our single channel on reading, so the
//!   gradient of each stored channel is one third of the gradient of the averaged feature.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use ndarray::Array2;

use unispine::gaussians::model::N_FEATURES;
use unispine::gaussians::ply::FeatureLayout;
use unispine::gaussians::{ply, Gaussians};
use unispine::geometry::{self, Camera};
use unispine::image2d::Image2d;
use unispine::real::Real;
use unispine::render::{self, ColorMode, RenderSettings};

/// Arguments of `unispine render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Gaussians in the 3DGS PLY layout (pre-activation parameters, as 3DGS and X-Gaussian write).
    #[arg(long, required_unless_present = "run", conflicts_with = "run")]
    pub ply: Option<PathBuf>,
    /// A run folder of `unispine train`: its saved model (`model.ply`, or the checkpoint of a
    /// stopped run) with the render settings it records.
    #[arg(long)]
    pub run: Option<PathBuf>,
    /// Dataset folder (from `unispine data`) whose geometry and view angle to use.
    #[arg(long, conflicts_with_all = ["geometry", "angle_deg"], requires = "view")]
    pub dataset: Option<PathBuf>,
    /// View of the dataset: `test:K` or `train:K` (K counts from 0).
    #[arg(long, requires = "dataset")]
    pub view: Option<String>,
    /// TIGRE / NAF geometry JSON (DSD, DSO, nDetector, dDetector, nVoxel, dVoxel, offOrigin,
    /// offDetector, mode), lengths in mm.
    #[arg(long, requires = "angle_deg")]
    pub geometry: Option<PathBuf>,
    /// Projection angle in degrees (with `--geometry`).
    #[arg(long, requires = "geometry", allow_hyphen_values = true)]
    pub angle_deg: Option<f64>,
    /// Intensity model: `rirf-paper` (Eq. 2, sigmoid), `rirf-xgaussian` (X-Gaussian code,
    /// max(0, 0.5 + lambda . f)) or `sh` (view-dependent SH colour, the 3DGS baseline).
    /// Default: the model's recorded one (`comment unispine-render` in PLYs written by
    /// `unispine train`), else `rirf-paper`. A value that contradicts the record is an error.
    #[arg(long, value_enum)]
    pub color: Option<ColorArg>,
    /// Number of active features / SH coefficients (1, 4, 9 or 16). Default: the model's
    /// recorded value, else 16.
    #[arg(long)]
    pub active_features: Option<usize>,
    /// Background value (added with the final transmittance). Default: the model's recorded
    /// value, else 0.
    #[arg(long, allow_hyphen_values = true)]
    pub background: Option<f64>,
    /// Upstream gradient W (npy, f32 or f64, shape [v, u]): also write the gradient of
    /// sum(W * image) with respect to every stored PLY field to `grads.npz`.
    #[arg(long)]
    pub grad_weights: Option<PathBuf>,
    /// Arithmetic precision of the rasterizer.
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: Precision,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// `--color` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ColorArg {
    RirfPaper,
    RirfXgaussian,
    Sh,
}

/// `--precision` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Precision {
    F32,
    F64,
}

/// Run `unispine render`.
pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let cam = camera(&args)?;
    let weights = match &args.grad_weights {
        Some(p) => Some(read_weights(p, &cam)?),
        None => None,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    match args.precision {
        Precision::F32 => render_and_write::<f32>(&args, &cam, weights.as_ref()),
        Precision::F64 => render_and_write::<f64>(&args, &cam, weights.as_ref()),
    }
}

/// The model (from `--ply` or `--run`), its source path, the settings it records, and the
/// layout of its stored features (a run's model has the layout [`ply::write_ply`] writes).
fn load_model<R: Real>(
    args: &RenderArgs,
) -> anyhow::Result<(Gaussians<R>, PathBuf, Option<RenderSettings>, FeatureLayout)> {
    if let Some(run) = &args.run {
        let m = unispine::train::RunDir::open(run)?.read_model()?;
        let layout = FeatureLayout {
            channels: 3,
            rest_per_channel: N_FEATURES - 1,
        };
        return Ok((m.gaussians.cast(), m.path, Some(m.render), layout));
    }
    let path = args.ply.clone().context("--ply or --run is required")?;
    let (g, layout, comments) = ply::read_ply_full::<R>(&path)?;
    let recorded = RenderSettings::from_ply_comments(&path, &comments)?;
    Ok((g, path, recorded, layout))
}

/// The render settings: each flag given, else the model's record, else the defaults. An
/// explicit `--color` that contradicts the record is an error (the image would be silently
/// wrong).
fn settings(
    args: &RenderArgs,
    model: &Path,
    recorded: Option<&RenderSettings>,
) -> anyhow::Result<RenderSettings> {
    let color = args.color.map(|c| match c {
        ColorArg::RirfPaper => ColorMode::RirfPaper,
        ColorArg::RirfXgaussian => ColorMode::RirfXgaussian,
        ColorArg::Sh => ColorMode::Sh,
    });
    if let (Some(c), Some(r)) = (color, recorded) {
        if c != r.color {
            bail!(
                "--color {c:?} contradicts {}, which records the intensity model {:?} it was \
                 trained with; omit --color",
                model.display(),
                r.color
            );
        }
    }
    let def = RenderSettings::default();
    let s = RenderSettings {
        color: color.or(recorded.map(|r| r.color)).unwrap_or(def.color),
        active_features: args
            .active_features
            .or(recorded.map(|r| r.active_features))
            .unwrap_or(def.active_features),
        background: args
            .background
            .or(recorded.map(|r| r.background))
            .unwrap_or(def.background),
        ..Default::default()
    };
    if !unispine::gaussians::rirf::valid_active(s.active_features) {
        bail!(
            "--active-features must be 1, 4, 9 or 16 (got {})",
            s.active_features
        );
    }
    if !s.background.is_finite() {
        bail!(
            "--background must be a finite number (got {})",
            s.background
        );
    }
    Ok(s)
}

/// The camera named by `--dataset/--view` or `--geometry/--angle-deg`.
fn camera(args: &RenderArgs) -> anyhow::Result<Camera> {
    if let (Some(dir), Some(view)) = (&args.dataset, &args.view) {
        let ds = unispine::dataset::store::load(dir)?;
        let (split, k) = view
            .split_once(':')
            .and_then(|(s, k)| k.parse::<usize>().ok().map(|k| (s, k)))
            .with_context(|| format!("--view must be `test:K` or `train:K` (got `{view}`)"))?;
        let angles = match split {
            "test" => &ds.test.angles,
            "train" => &ds.train.angles,
            _ => bail!("--view split must be `test` or `train` (got `{split}`)"),
        };
        let angle = *angles.get(k).with_context(|| {
            format!(
                "--view {view}: the dataset {} has {} {split} views (K counts from 0)",
                dir.display(),
                angles.len()
            )
        })?;
        ds.geometry
            .check_view(angle)
            .with_context(|| format!("--dataset {} --view {view}", dir.display()))?;
        return Ok(ds.geometry.camera(angle));
    }
    if let (Some(g), Some(a)) = (&args.geometry, args.angle_deg) {
        let geo = geometry::read_json(g, None).context("--geometry")?;
        if !a.is_finite() {
            bail!("--angle-deg must be finite (got {a})");
        }
        geo.check_view(a.to_radians())
            .with_context(|| format!("--geometry {} --angle-deg {a}", g.display()))?;
        return Ok(geo.camera(a.to_radians()));
    }
    bail!("give either --dataset DIR --view test:K, or --geometry G.json --angle-deg A")
}

/// The upstream gradient W, checked against the image shape.
fn read_weights(path: &Path, cam: &Camera) -> anyhow::Result<Image2d<f64>> {
    let arr = unispine::volume::npy::read(path).context("--grad-weights")?;
    if arr.shape.len() != 2 || !arr.is_float() {
        bail!(
            "--grad-weights {}: expected a 2-D f32 or f64 npy array [v, u], got {} {:?}",
            path.display(),
            arr.descr,
            arr.shape
        );
    }
    let (h, w) = (arr.shape[0], arr.shape[1]);
    if (h, w) != (cam.height, cam.width) {
        bail!(
            "--grad-weights {}: shape [{h}, {w}] does not match the detector [v, u] = [{}, {}]",
            path.display(),
            cam.height,
            cam.width
        );
    }
    let data: Vec<f64> = arr.to_f64_c();
    unispine::error::check_finite(&format!("--grad-weights {}", path.display()), &data)?;
    Ok(Image2d::from_vec(w, h, data))
}

fn render_and_write<R: Real>(
    args: &RenderArgs,
    cam: &Camera,
    weights: Option<&Image2d<f64>>,
) -> anyhow::Result<()> {
    let (g, model, recorded, layout) = load_model::<R>(args)?;
    let settings = &settings(args, &model, recorded.as_ref())?;
    let (img, saved) = render::forward(&g, cam, settings)
        .with_context(|| format!("rendering {}", model.display()))?;
    let img32: Vec<f32> = img.data.iter().map(|v| v.f64() as f32).collect();
    let arr = Array2::from_shape_vec((img.height, img.width), img32.clone())?;
    let npy = args.out.join("image.npy");
    ndarray_npy::write_npy(&npy, &arr).with_context(|| format!("writing {}", npy.display()))?;
    unispine::preview::write_png(
        &args.out.join("image.png"),
        &Image2d::from_vec(img.width, img.height, img32),
    )?;
    println!("image: {}", npy.display());

    if let Some(w) = weights {
        let d_image: Image2d<R> = w.cast();
        let grads = render::backward(&g, cam, settings, &saved, &d_image);
        let path = args.out.join("grads.npz");
        ply::StoredGrads::new(&grads.params, layout).write_npz(&path)?;
        println!("gradients of sum(W * image): {}", path.display());
    }
    Ok(())
}
