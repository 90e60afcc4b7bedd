//! The `.npy` reader (NumPy's array file format): volumes, dataset arrays and weight images.

use super::{Provenance, Volume};

/// Read a `.npy` array `[x, y, z]` (f32, f64, u8 or i16; C or Fortran order) as a volume with
/// 1 mm voxels.
pub fn read_volume(path: &std::path::Path) -> crate::error::Result<Volume<f32>> {
    use ndarray::Array3;
    use ndarray_npy::{ReadNpyError, ReadNpyExt};
    let bytes = super::read_bytes(path)?;
    let fail = |e: ReadNpyError| {
        let field = match &e {
            ReadNpyError::ParseHeader(_) => "header",
            ReadNpyError::WrongNdim(..) => "shape",
            ReadNpyError::WrongDescriptor(_) => "descr",
            _ => "data",
        };
        crate::error::Error::format(path, field, e.to_string())
    };
    // Try each supported dtype in turn; only a dtype mismatch moves on to the next.
    type Attempt = Result<Option<(Vec<f32>, [usize; 3])>, ReadNpyError>;
    fn attempt<T: ndarray_npy::ReadableElement + Copy>(
        bytes: &[u8],
        conv: fn(T) -> f32,
    ) -> Attempt {
        match Array3::<T>::read_npy(std::io::Cursor::new(bytes)) {
            Ok(a) => {
                let (nx, ny, nz) = a.dim();
                // Reversing the axes gives [z, y, x]; its logical order is x fastest.
                let t = a.reversed_axes();
                let data: Vec<f32> = t.iter().map(|&v| conv(v)).collect();
                Ok(Some((data, [nx, ny, nz])))
            }
            Err(ReadNpyError::WrongDescriptor(_)) => Ok(None),
            Err(e) => Err(e),
        }
    }
    type Try = fn(&[u8]) -> Attempt;
    let tries: [(&str, Try); 4] = [
        ("float32", |b| attempt::<f32>(b, |v| v)),
        ("float64", |b| attempt::<f64>(b, |v| v as f32)),
        ("uint8", |b| attempt::<u8>(b, |v| v as f32)),
        ("int16", |b| attempt::<i16>(b, |v| v as f32)),
    ];
    for (name, f) in tries {
        if let Some((data, dims)) = f(&bytes).map_err(fail)? {
            if dims.contains(&0) {
                return Err(crate::error::Error::format(
                    path,
                    "shape",
                    format!("empty array of shape {dims:?}"),
                ));
            }
            return Ok(Volume {
                data,
                dims,
                spacing: [1.0; 3],
                offset: [0.0; 3],
                provenance: Provenance {
                    source: path.display().to_string(),
                    file_affine: None,
                    steps: vec![format!(
                        "read .npy {name} array [x, y, z] = {dims:?}; voxel size 1 mm assumed \
                         (.npy carries none); centred (offset 0)"
                    )],
                },
            });
        }
    }
    Err(crate::error::Error::format(
        path,
        "descr",
        "unsupported dtype: .npy volumes must be float32, float64, uint8 or int16",
    ))
}
