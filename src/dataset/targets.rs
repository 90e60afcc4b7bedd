//! Training and test targets: each projection min-max normalised to [0, 1] on its own, as the
//! UniSpine-GS code does (`scene/cameras.py`). Upstream first clamps the raw projection to
//! [0, 1], a no-op for its line integrals in metres (0 to about 0.5) but not for ours in mm, so
//! we normalise the raw values (the same image whenever upstream's clamp is inactive).

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::image2d::Image2d;

/// Min-max normalise one projection to [0, 1] (computed in f64, stored in f32). A constant or
/// non-finite projection is an error naming `what`.
pub fn normalise_gt(img: &Image2d<f32>, what: &str) -> Result<Image2d<f32>> {
    crate::error::check_finite(what, &img.data)?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in &img.data {
        lo = lo.min(v as f64);
        hi = hi.max(v as f64);
    }
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return Err(Error::invalid(
            what,
            format!("constant projection (min = max = {lo}); it cannot be min-max normalised"),
        ));
    }
    let r = hi - lo;
    Ok(Image2d {
        width: img.width,
        height: img.height,
        data: img
            .data
            .iter()
            .map(|&v| ((v as f64 - lo) / r) as f32)
            .collect(),
    })
}

/// The normalised ground truth of the first `n` training views.
pub fn train_targets(ds: &Dataset, n: usize) -> Result<Vec<Image2d<f32>>> {
    ds.train.projections[..n.min(ds.train.projections.len())]
        .iter()
        .enumerate()
        .map(|(k, p)| normalise_gt(p, &format!("train projection {k}")))
        .collect()
}

/// The normalised ground truth of every test view.
pub fn test_targets(ds: &Dataset) -> Result<Vec<Image2d<f32>>> {
    ds.test
        .projections
        .iter()
        .enumerate()
        .map(|(k, p)| normalise_gt(p, &format!("test projection {k}")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalisation_maps_to_unit_range_and_names_bad_views() {
        let img = Image2d::from_vec(2, 2, vec![2.0f32, 4.0, 3.0, 6.0]);
        let n = normalise_gt(&img, "x").unwrap();
        assert_eq!(n.data, vec![0.0, 0.5, 0.25, 1.0]);
        let c = Image2d::from_vec(2, 2, vec![5.0f32; 4]);
        let e = normalise_gt(&c, "test projection 3")
            .unwrap_err()
            .to_string();
        assert!(e.contains("test projection 3"), "{e}");
        let mut nan = img.clone();
        nan.data[1] = f32::NAN;
        assert!(normalise_gt(&nan, "t").is_err());
    }
}
