//! A single-channel image, row-major with row 0 at the top (+z for projections).

use crate::real::Real;

/// A single-channel image `data[row * width + col]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Image2d<R: Real = f32> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<R>,
}

impl<R: Real> Image2d<R> {
    /// An image filled with `v`.
    pub fn filled(width: usize, height: usize, v: R) -> Self {
        Image2d {
            width,
            height,
            data: vec![v; width * height],
        }
    }

    /// Wrap row-major data. Panics if the length does not match (a programming error).
    pub fn from_vec(width: usize, height: usize, data: Vec<R>) -> Self {
        assert_eq!(data.len(), width * height, "image data length");
        Image2d {
            width,
            height,
            data,
        }
    }

    /// Value at (row, col).
    #[inline(always)]
    pub fn at(&self, row: usize, col: usize) -> R {
        self.data[row * self.width + col]
    }

    /// The pixel-wise image f(self, other). Panics if the sizes differ (a programming error).
    pub fn zip_map(&self, other: &Image2d<R>, f: impl Fn(R, R) -> R) -> Image2d<R> {
        assert_eq!(
            (self.width, self.height),
            (other.width, other.height),
            "image sizes"
        );
        Image2d {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(&a, &b)| f(a, b))
                .collect(),
        }
    }

    /// The same image in another precision.
    pub fn cast<S: Real>(&self) -> Image2d<S> {
        Image2d {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| S::c(v.f64())).collect(),
        }
    }
}
