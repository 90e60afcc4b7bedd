//! 8-bit PNG previews of single-channel images (dataset previews, `unispine drr` and
//! `unispine render` outputs): min-max scaled, a constant image is black.

use std::path::Path;

use crate::error::{Error, Result};
use crate::image2d::Image2d;

/// (min, max) of `x` (NaN values are skipped by `f32::min` / `f32::max`; empty: (inf, -inf)).
pub fn min_max(x: &[f32]) -> (f32, f32) {
    x.iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        })
}

/// Write an image min-max scaled to 8 bits (a constant image is black).
pub fn write_png(path: &Path, img: &Image2d<f32>) -> Result<()> {
    let (lo, hi) = min_max(&img.data);
    let scale = if hi > lo { 255.0 / (hi - lo) } else { 0.0 };
    let px: Vec<u8> = img
        .data
        .iter()
        .map(|&v| ((v - lo) * scale).round().clamp(0.0, 255.0) as u8)
        .collect();
    let buf = image::GrayImage::from_raw(img.width as u32, img.height as u32, px)
        .ok_or_else(|| Error::format(path, "png", "image buffer size"))?;
    crate::fsio::write_png_atomic(path, &buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_is_min_max_scaled_and_constant_is_black() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        write_png(&p, &Image2d::from_vec(3, 1, vec![-1.0f32, 0.0, 1.0])).unwrap();
        let img = image::open(&p).unwrap().into_luma8();
        assert_eq!(img.as_raw(), &vec![0u8, 128, 255]);
        write_png(&p, &Image2d::from_vec(2, 1, vec![7.0f32; 2])).unwrap();
        assert_eq!(
            image::open(&p).unwrap().into_luma8().as_raw(),
            &vec![0u8, 0]
        );
        let e = write_png(
            &dir.path().join("no/such/dir.png"),
            &Image2d::filled(1, 1, 0.0f32),
        );
        assert!(e.unwrap_err().to_string().contains("dir.png"));
    }
}
