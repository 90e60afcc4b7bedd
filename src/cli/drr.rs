//! `unispine drr`: project a volume with our DRR ray-marcher for given angles.
//!
//! Outputs in `--out`:
//! - `projections.npy`: f32 `[N, v, u]`, row 0 = top (+z), line integrals in mm x volume value
//!   (no exp, no log);
//! - `view_000.png`, ...: each view min-max scaled to 8 bits;
//! - `drr.json`: the geometry as used (with `nVoxel`/`dVoxel`/`offOrigin` filled in), the
//!   angles, the method, the precision, the HU conversion and the volume's provenance.
//!
//! The geometry file holds the TIGRE / NAF fields of [`ConeBeam`]. `nVoxel`, `dVoxel` and
//! `offOrigin` may be omitted: they are then taken from the volume (its dims, voxel size and
//! offset). When given they must describe the volume's grid (checked, the error names the field).

use std::path::PathBuf;
use std::sync::Mutex;

use anyhow::{bail, Context};
use ndarray::Array3;

use crate::cli::progress::Progress;
use crate::cli::render::Precision;
use unispine::drr::{self, Method};
use unispine::geometry::{self, ConeBeam, VoxelGrid};
use unispine::image2d::Image2d;
use unispine::preview::write_png;
use unispine::real::Real;
use unispine::volume::attenuation::HuConversion;
use unispine::volume::{self, Volume};

/// Arguments of `unispine drr`.
#[derive(Debug, clap::Args)]
pub struct DrrArgs {
    /// Volume to project: NIfTI (.nii, .nii.gz), MetaImage (.mha, .mhd) or .npy ([x, y, z],
    /// 1 mm voxels). Its values are projected as they are unless `--hu` names a conversion.
    #[arg(long)]
    pub volume: PathBuf,
    /// TIGRE / NAF geometry JSON: DSD, DSO, nDetector [v, u], dDetector [v, u] (mm), offDetector
    /// [u, v] (mm), mode (cone | parallel), accuracy (trilinear step in voxels, default 0.5).
    /// nVoxel, dVoxel and offOrigin may be omitted (taken from the volume); if given they must
    /// match the volume.
    #[arg(long)]
    pub geometry: PathBuf,
    /// Projection angles in degrees, comma-separated (e.g. `0,45,90` or `-30,30`).
    #[arg(long, allow_hyphen_values = true)]
    pub angles_deg: String,
    /// Projector: `siddon` (exact line integrals through the voxel grid, TIGRE's default) or
    /// `trilinear` (ray-march with step accuracy x min voxel size, TIGRE 'interpolated').
    #[arg(long, value_enum, default_value = "siddon")]
    pub method: MethodArg,
    /// Arithmetic precision of the projector (the output file is f32 either way).
    #[arg(long, value_enum, default_value = "f32")]
    pub precision: Precision,
    /// HU conversion applied before projecting: `none` (values as they are), `naf-mu`
    /// (mu = 0.206 + (0.206 - 0.0004) / 1000 * HU in 1/cm, clamped at 0) or `linear-clip`
    /// (HU clipped to [-1000, 2000], mapped to [0, 1]).
    #[arg(long, value_parser = super::flags::choice::<HuConversion>(), default_value = "none")]
    pub hu: HuConversion,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// `--method` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum MethodArg {
    Siddon,
    Trilinear,
}

/// Run `unispine drr`.
pub fn run(args: DrrArgs) -> anyhow::Result<()> {
    let angles_deg = parse_angles(&args.angles_deg)?;
    let method = match args.method {
        MethodArg::Siddon => Method::Siddon,
        MethodArg::Trilinear => Method::Trilinear,
    };
    let vol = volume::load(&args.volume)
        .with_context(|| format!("reading --volume {}", args.volume.display()))?;
    let grid = VoxelGrid {
        n_voxel: vol.dims,
        d_voxel: vol.spacing,
        off_origin: vol.offset,
    };
    let geo = geometry::read_json(&args.geometry, Some(&grid)).context("--geometry")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let outs = [args.out.join("projections.npy"), args.out.join("drr.json")];
    unispine::fsio::check_not_output("--volume", &args.volume, &outs)?;
    match args.precision {
        Precision::F32 => project_and_write::<f32>(&args, vol, &geo, &angles_deg, method),
        Precision::F64 => project_and_write::<f64>(&args, vol.cast(), &geo, &angles_deg, method),
    }
}

/// `a,b,c` in degrees; every entry must be a finite number.
fn parse_angles(s: &str) -> anyhow::Result<Vec<f64>> {
    let mut out = Vec::new();
    for (k, part) in s.split(',').enumerate() {
        let t = part.trim();
        let v: f64 = t.parse().map_err(|_| {
            anyhow::anyhow!(
                "--angles-deg: entry {k} (`{t}`) is not a number; expected comma-separated \
                 degrees such as `0,45,90`"
            )
        })?;
        if !v.is_finite() {
            bail!("--angles-deg: entry {k} (`{t}`) must be finite");
        }
        out.push(v);
    }
    Ok(out)
}

fn project_and_write<R: Real>(
    args: &DrrArgs,
    mut vol: Volume<R>,
    geo: &ConeBeam,
    angles_deg: &[f64],
    method: Method,
) -> anyhow::Result<()> {
    args.hu.apply(&mut vol);
    let angles: Vec<f64> = angles_deg.iter().map(|a| a.to_radians()).collect();
    let progress = Mutex::new(Progress::new("drr", angles.len() as u64));
    let views = drr::project_views(&vol, geo, &angles, method, &|k| {
        if let Ok(mut p) = progress.lock() {
            p.inc(1, &format!("view {k}/{}", angles.len()));
        }
    })
    .with_context(|| {
        format!(
            "projecting --volume {} with --geometry {}",
            args.volume.display(),
            args.geometry.display()
        )
    })?;
    if let Ok(p) = progress.into_inner() {
        p.finish(&format!("{} views", angles.len()));
    }
    let (w, h) = (geo.n_detector[1], geo.n_detector[0]);
    // Views of an earlier, longer angle list would look like part of this one.
    unispine::fsio::remove_matching(&args.out, "view_", ".png")?;
    let mut stack = Array3::<f32>::zeros((views.len(), h, w));
    for (k, img) in views.iter().enumerate() {
        let img32: Vec<f32> = img.data.iter().map(|v| v.f64() as f32).collect();
        for (i, v) in img32.iter().enumerate() {
            stack[[k, i / w, i % w]] = *v;
        }
        let png = args.out.join(format!("view_{k:03}.png"));
        write_png(&png, &Image2d::from_vec(w, h, img32))?;
    }
    let npy = args.out.join("projections.npy");
    ndarray_npy::write_npy(&npy, &stack).with_context(|| format!("writing {}", npy.display()))?;
    let meta = serde_json::json!({
        "geometry": geo,
        "angles_deg": angles_deg,
        "method": method,
        "precision": R::NAME,
        "hu": args.hu.name(),
        "units": "line integral: mm x volume value (after --hu); row 0 = top (+z)",
        "volume": vol.provenance,
    });
    unispine::fsio::write_json_atomic(&args.out.join("drr.json"), &meta)?;
    println!("{} views [{h} x {w}] -> {}", views.len(), npy.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_parse_and_errors_name_the_entry() {
        assert_eq!(parse_angles("0, 45,-90.5").unwrap(), vec![0.0, 45.0, -90.5]);
        let e = parse_angles("0,abc").unwrap_err().to_string();
        assert!(e.contains("--angles-deg") && e.contains("entry 1"), "{e}");
        assert!(parse_angles("").is_err());
        assert!(parse_angles("1,inf").is_err());
    }
}
