//! `project_views` and the projector's reported settings: the 8 GiB bound on the projections
//! at its boundary, progress after every view, and the march lanes each path reports.

use std::sync::Mutex;

use unispine::drr::{self, MarchLanes, Method, Projector, MAX_PROJECTION_BYTES};
use unispine::geometry::ConeBeam;
use unispine::simd::Simd;
use unispine::volume::Volume;

/// A 4^3 volume of ones at 1 mm and a cone beam of `n_det` pixels that sees all of it.
fn scene(n_det: [usize; 2]) -> (Volume<f32>, ConeBeam) {
    let mut vol = Volume::<f32>::zeros([4, 4, 4], [1.0; 3]);
    vol.data.iter_mut().for_each(|v| *v = 1.0);
    let pitch = [16.0 / n_det[0] as f64, 16.0 / n_det[1] as f64];
    let geo = ConeBeam::centred(n_det, pitch, vol.dims, vol.spacing);
    (vol, geo)
}

/// Exactly 8 GiB of projections pass the bound (the first view, at a NaN angle, then fails on
/// its own field), one view more is refused before any view is projected, naming `angles`.
#[test]
fn projections_of_exactly_8_gib_pass_the_bound_and_one_view_more_does_not() {
    // 1024 x 2048 f32 pixels: 8 MiB a view, 1024 views = 8 GiB.
    let (vol, geo) = scene([1024, 2048]);
    let per_view = 1024 * 2048 * 4;
    let n = (MAX_PROJECTION_BYTES / per_view) as usize;
    assert_eq!(n as u64 * per_view, 8 << 30);
    for (views, field) in [(n, "angle"), (n + 1, "angles")] {
        let angles = vec![f64::NAN; views];
        let e = drr::project_views(&vol, &geo, &angles, Method::Siddon, &|_| {})
            .err()
            .unwrap_or_else(|| panic!("{views} views: no error"));
        let text = e.to_string();
        assert!(
            text.contains(&format!("`{field}`")),
            "{views} views: {text}"
        );
        if views > n {
            let bytes = views as u64 * per_view;
            assert!(text.contains(&bytes.to_string()), "{text}");
        }
    }
}

/// `progress(k)` after view k, 1 to n in order, and the views are those of the projector.
#[test]
fn progress_counts_every_view_in_order() {
    let (vol, geo) = scene([6, 5]);
    let angles = [0.0, 0.7, 2.1];
    let seen = Mutex::new(Vec::new());
    let views = drr::project_views(&vol, &geo, &angles, Method::Trilinear, &|k| {
        seen.lock().unwrap().push(k)
    })
    .unwrap();
    assert_eq!(*seen.lock().unwrap(), vec![1, 2, 3]);
    let p = Projector::new(&vol, &geo, Method::Trilinear).unwrap();
    for (img, &a) in views.iter().zip(&angles) {
        assert_eq!(img.data, p.view(a).unwrap().data, "angle {a}");
        assert!(img.data.iter().any(|&v| v > 0.0));
    }
}

/// The lanes of the trilinear march each path reports: the per-ray loop on the scalar path, 8
/// on AVX2, the chosen width on AVX-512.
#[test]
fn march_lanes_reported_per_path() {
    assert_eq!(
        (MarchLanes::Eight.count(), MarchLanes::Sixteen.count()),
        (8, 16)
    );
    let (vol, geo) = scene([6, 5]);
    for simd in Simd::supported_paths() {
        for lanes in [MarchLanes::Eight, MarchLanes::Sixteen] {
            let p = Projector::new(&vol, &geo, Method::Trilinear)
                .unwrap()
                .with_simd(simd)
                .with_march_lanes(lanes);
            let want = match simd {
                Simd::Scalar => 1,
                Simd::Avx2 => 8,
                Simd::Avx512 => lanes.count(),
            };
            assert_eq!(p.march_lanes(), want, "{simd:?} {lanes:?}");
        }
    }
}
