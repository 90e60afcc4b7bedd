//! NIfTI-1 reader (`.nii`, `.nii.gz`), written from the NIfTI-1 header layout (nifti1.h).
//!
//! Our own parser rather than the `nifti` crate's reader, for three reasons: every failure is an
//! error naming the file and the header field (truncated data, bad magic, unsupported datatype),
//! the crate's `qform_affine` panics on some valid headers, and its scaling turns a NaN
//! `scl_slope` into an all-NaN volume. (Tests write fixtures with the crate's writer, an
//! independent implementation.)
//!
//! - Values: `v * scl_slope + scl_inter` computed in f64, stored as f32. A slope that is 0 or not
//!   finite means "no scaling" (NIfTI-1 and nibabel); a non-finite intercept with a valid slope
//!   is taken as 0.
//! - Voxel size: `|pixdim[1..=3]|` converted to mm with `xyzt_units` (metre, mm, micron; unknown
//!   is taken as mm). A zero or non-finite voxel size is an error.
//! - Affine (recorded only): sform when `sform_code > 0`, else the quaternion qform when
//!   `qform_code > 0` (computed here as in nifti1_io's `nifti_quatern_to_mat44`), else
//!   diag(pixdim) (ANALYZE "method 1"). An affine with a NaN or infinite entry is dropped with
//!   a note in the provenance (it is informational only).
//! - Input limits: only regular files are read (a symlink to `/dev/urandom` is refused); only
//!   the bytes the header needs are read, and a `.gz` is decompressed only that far (trailing
//!   bytes after the voxel data, such as zero padding, are never looked at); the claimed data
//!   size is checked against the file length (times deflate's largest ratio, 1032, for `.gz`)
//!   before reading it.
//! - The array index (i, j, k) is our (x, y, z); the volume is centred (offset 0).

use super::{byte_count, decode, from_file, open_regular, Elem, Volume};
use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

/// Size of a NIfTI-1 header in bytes.
const HEADER_LEN: usize = 348;

/// The header fields the reader uses.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// True when the file is big-endian.
    pub big_endian: bool,
    /// Voxel counts `[x, y, z]` (missing trailing dimensions are 1).
    pub dims: [usize; 3],
    /// NIfTI `datatype` code.
    pub datatype: i16,
    /// `pixdim[0..8]` as stored (`pixdim[0]` is qfac).
    pub pixdim: [f32; 8],
    /// Byte offset of the voxel data.
    pub vox_offset: f32,
    pub scl_slope: f32,
    pub scl_inter: f32,
    pub xyzt_units: u8,
    pub qform_code: i16,
    pub sform_code: i16,
    /// quatern_b, quatern_c, quatern_d.
    pub quatern: [f32; 3],
    /// qoffset_x, qoffset_y, qoffset_z.
    pub qoffset: [f32; 3],
    /// srow_x, srow_y, srow_z.
    pub srow: [[f32; 4]; 3],
}

/// Largest ratio of deflate's output to its input (a stored zero byte costs at least about
/// 1/1032 of a byte): a gzip file of `n` bytes cannot decompress to more than `n * 1032`.
const DEFLATE_MAX_RATIO: u64 = 1032;

/// Read up to `n` bytes of `src` into `buf` (fewer only when the stream ends).
fn fill(src: &mut impl Read, buf: &mut Vec<u8>, n: usize) -> std::io::Result<()> {
    if buf.len() < n {
        // Reserve at most 64 MiB ahead; beyond that the vector grows with what actually arrives.
        buf.reserve((n - buf.len()).min(1 << 26));
        src.by_ref().take((n - buf.len()) as u64).read_to_end(buf)?;
    }
    Ok(())
}

/// The bytes a header asks for: `vox_offset` + the voxel data, when the header fields needed
/// for that are valid (else `None`: [`read`] then reports the bad field).
fn needed_len(path: &Path, b: &[u8]) -> Option<usize> {
    let h = parse_header(path, b).ok()?;
    let a = [b[72], b[73]];
    let bitpix = if h.big_endian {
        i16::from_be_bytes(a)
    } else {
        i16::from_le_bytes(a)
    };
    let elem = element_type(path, h.datatype, bitpix).ok()?;
    let off = h.vox_offset;
    if !(off.is_finite() && off >= HEADER_LEN as f32 && off.fract() == 0.0) {
        return None;
    }
    let need = byte_count(path, "dim", h.dims, elem.size()).ok()?;
    (off as usize).checked_add(need)
}

/// Read the bytes the header needs (header, extensions, voxel data), gunzipping `.gz`; never
/// more. A `.gz` is decompressed only as far as the voxel data reaches, so trailing bytes
/// (zero padding, another gzip member, gigabytes of zeros) are never read; the gzip size field
/// is not used. Only regular files are read.
fn file_bytes(path: &Path) -> Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    let gz = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase().ends_with(".gz"))
        .unwrap_or(false);
    let gzip_err = |e: std::io::Error| {
        Error::format(
            path,
            "gzip",
            format!("truncated or corrupt gzip stream: {e}"),
        )
    };
    let mut buf = Vec::new();
    let mut src: Box<dyn Read> = if gz {
        Box::new(flate2::read::MultiGzDecoder::new(std::io::BufReader::new(
            file,
        )))
    } else {
        Box::new(file)
    };
    let io_err = |e: std::io::Error| if gz { gzip_err(e) } else { Error::io(path, e) };
    fill(&mut src, &mut buf, HEADER_LEN).map_err(io_err)?;
    let Some(total) = needed_len(path, &buf) else {
        return Ok(buf);
    };
    let most = if gz {
        len.saturating_mul(DEFLATE_MAX_RATIO)
    } else {
        len
    };
    if total as u64 > most {
        let h = parse_header(path, &buf)?;
        return Err(Error::format(
            path,
            "dim",
            if gz {
                format!(
                    "{:?} voxels need {total} bytes after decompression; a {len}-byte gzip file cannot hold more than {most} (truncated file, or a false header)",
                    h.dims
                )
            } else {
                format!(
                    "truncated: {:?} voxels need {total} bytes (vox_offset + data), the file holds {len}",
                    h.dims
                )
            },
        ));
    }
    fill(&mut src, &mut buf, total).map_err(io_err)?;
    Ok(buf)
}

/// Parse the 348-byte header at the start of `b`.
pub fn parse_header(path: &Path, b: &[u8]) -> Result<Header> {
    if b.len() < HEADER_LEN {
        return Err(Error::format(
            path,
            "header",
            format!(
                "file holds {} bytes, fewer than the {HEADER_LEN}-byte NIfTI-1 header",
                b.len()
            ),
        ));
    }
    let le = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let be = i32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    let big_endian = match (le, be) {
        (348, _) => false,
        (_, 348) => true,
        (540, _) | (_, 540) => {
            return Err(Error::format(
                path,
                "sizeof_hdr",
                "NIfTI-2 files (sizeof_hdr = 540) are not supported; convert to NIfTI-1",
            ))
        }
        _ => {
            return Err(Error::format(
                path,
                "sizeof_hdr",
                format!("expected 348 (NIfTI-1), found {le}: not a NIfTI-1 file"),
            ))
        }
    };
    let magic = &b[344..348];
    if magic == b"ni1\0" {
        return Err(Error::format(
            path,
            "magic",
            "header-only NIfTI (`ni1`, a .hdr/.img pair) is not supported; use a single .nii file",
        ));
    }
    if magic != b"n+1\0" {
        return Err(Error::format(
            path,
            "magic",
            format!("expected \"n+1\\0\", found {magic:?}"),
        ));
    }
    let i16_at = |o: usize| {
        let a = [b[o], b[o + 1]];
        if big_endian {
            i16::from_be_bytes(a)
        } else {
            i16::from_le_bytes(a)
        }
    };
    let f32_at = |o: usize| {
        let a = [b[o], b[o + 1], b[o + 2], b[o + 3]];
        if big_endian {
            f32::from_be_bytes(a)
        } else {
            f32::from_le_bytes(a)
        }
    };
    let mut dim = [0i16; 8];
    for (n, d) in dim.iter_mut().enumerate() {
        *d = i16_at(40 + 2 * n);
    }
    let rank = dim[0];
    if !(1..=7).contains(&rank) {
        return Err(Error::format(
            path,
            "dim[0]",
            format!("number of dimensions {rank} is not in 1..=7"),
        ));
    }
    let mut dims = [1usize; 3];
    for a in 1..=rank as usize {
        let d = dim[a];
        if d < 1 {
            return Err(Error::format(
                path,
                format!("dim[{a}]"),
                format!("size {d} must be at least 1"),
            ));
        }
        if a <= 3 {
            dims[a - 1] = d as usize;
        } else if d != 1 {
            return Err(Error::format(
                path,
                format!("dim[{a}]"),
                format!("a {rank}-D image with dim[{a}] = {d}: only 3-D volumes are supported"),
            ));
        }
    }
    let mut pixdim = [0f32; 8];
    for (n, p) in pixdim.iter_mut().enumerate() {
        *p = f32_at(76 + 4 * n);
    }
    let mut srow = [[0f32; 4]; 3];
    for (r, row) in srow.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = f32_at(280 + 16 * r + 4 * c);
        }
    }
    Ok(Header {
        big_endian,
        dims,
        datatype: i16_at(70),
        pixdim,
        vox_offset: f32_at(108),
        scl_slope: f32_at(112),
        scl_inter: f32_at(116),
        xyzt_units: b[123],
        qform_code: i16_at(252),
        sform_code: i16_at(254),
        quatern: [f32_at(256), f32_at(260), f32_at(264)],
        qoffset: [f32_at(268), f32_at(272), f32_at(276)],
        srow,
    })
}

/// The element type of a NIfTI `datatype` code, checked against `bitpix`.
fn element_type(path: &Path, datatype: i16, bitpix: i16) -> Result<Elem> {
    let e = match datatype {
        2 => Elem::U8,
        4 => Elem::I16,
        8 => Elem::I32,
        16 => Elem::F32,
        64 => Elem::F64,
        256 => Elem::I8,
        512 => Elem::U16,
        768 => Elem::U32,
        1024 => Elem::I64,
        1280 => Elem::U64,
        other => {
            let what = match other {
                1 => "binary (1 bit)",
                32 => "complex64",
                128 => "RGB24",
                1536 => "float128",
                1792 => "complex128",
                2048 => "complex256",
                2304 => "RGBA32",
                _ => "unknown",
            };
            return Err(Error::format(
                path,
                "datatype",
                format!(
                    "unsupported datatype {other} ({what}); supported: uint8, int8, int16, \
                     uint16, int32, uint32, int64, uint64, float32, float64"
                ),
            ));
        }
    };
    if bitpix as usize != 8 * e.size() {
        return Err(Error::format(
            path,
            "bitpix",
            format!(
                "{bitpix} bits per voxel contradicts datatype {datatype} ({}, {} bits)",
                e.name(),
                8 * e.size()
            ),
        ));
    }
    Ok(e)
}

/// Millimetres per file length unit (`xyzt_units & 7`): 1 metre, 2 mm, 3 micron, else mm.
fn mm_per_unit(xyzt_units: u8) -> (f64, &'static str) {
    match xyzt_units & 7 {
        1 => (1000.0, "m"),
        3 => (1e-3, "um"),
        2 => (1.0, "mm"),
        _ => (1.0, "unknown (taken as mm)"),
    }
}

/// The qform affine (row-major 4x4, file units) from the quaternion fields, as nifti1_io's
/// `nifti_quatern_to_mat44`: a = sqrt(1 - b^2 - c^2 - d^2) (when that is below 1e-7 the
/// quaternion is renormalised with a = 0), voxel sizes |pixdim| (1 when zero or not finite),
/// z column negated when qfac = `pixdim[0]` < 0. Never panics.
pub fn qform_affine(h: &Header) -> [[f64; 4]; 4] {
    let [mut b, mut c, mut d] = h.quatern.map(|v| v as f64);
    let mut a = 1.0 - (b * b + c * c + d * d);
    if a < 1e-7 {
        let n = (b * b + c * c + d * d).sqrt();
        if n > 0.0 && n.is_finite() {
            b /= n;
            c /= n;
            d /= n;
        }
        a = 0.0;
    } else {
        a = a.sqrt();
    }
    let size = |p: f32| {
        let p = (p as f64).abs();
        if p > 0.0 && p.is_finite() {
            p
        } else {
            1.0
        }
    };
    let xd = size(h.pixdim[1]);
    let yd = size(h.pixdim[2]);
    let mut zd = size(h.pixdim[3]);
    if h.pixdim[0] < 0.0 {
        zd = -zd;
    }
    let [qx, qy, qz] = h.qoffset.map(|v| v as f64);
    [
        [
            (a * a + b * b - c * c - d * d) * xd,
            2.0 * (b * c - a * d) * yd,
            2.0 * (b * d + a * c) * zd,
            qx,
        ],
        [
            2.0 * (b * c + a * d) * xd,
            (a * a + c * c - b * b - d * d) * yd,
            2.0 * (c * d - a * b) * zd,
            qy,
        ],
        [
            2.0 * (b * d - a * c) * xd,
            2.0 * (c * d + a * b) * yd,
            (a * a + d * d - c * c - b * b) * zd,
            qz,
        ],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// The file's affine (row-major 4x4, file units) and which header fields it came from.
pub fn file_affine(h: &Header) -> ([[f64; 4]; 4], String) {
    if h.sform_code > 0 {
        let s = h.srow.map(|r| r.map(|v| v as f64));
        (
            [s[0], s[1], s[2], [0.0, 0.0, 0.0, 1.0]],
            format!("sform (sform_code {})", h.sform_code),
        )
    } else if h.qform_code > 0 {
        (
            qform_affine(h),
            format!("qform (qform_code {}, sform_code 0)", h.qform_code),
        )
    } else {
        let p = |n: usize| h.pixdim[n] as f64;
        (
            [
                [p(1), 0.0, 0.0, 0.0],
                [0.0, p(2), 0.0, 0.0],
                [0.0, 0.0, p(3), 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
            "diag(pixdim) (qform_code = sform_code = 0)".to_string(),
        )
    }
}

/// Read a NIfTI-1 volume. See the module header for the conventions.
pub fn read(path: &Path) -> Result<Volume<f32>> {
    let bytes = file_bytes(path)?;
    let h = parse_header(path, &bytes)?;
    let bitpix = {
        let a = [bytes[72], bytes[73]];
        if h.big_endian {
            i16::from_be_bytes(a)
        } else {
            i16::from_le_bytes(a)
        }
    };
    let elem = element_type(path, h.datatype, bitpix)?;

    let (unit, unit_name) = mm_per_unit(h.xyzt_units);
    let mut spacing = [0.0; 3];
    for (a, s) in spacing.iter_mut().enumerate() {
        let p = h.pixdim[a + 1] as f64;
        if !(p.is_finite() && p != 0.0) {
            return Err(Error::format(
                path,
                format!("pixdim[{}]", a + 1),
                format!("voxel size {p} must be finite and non-zero"),
            ));
        }
        *s = p.abs() * unit;
    }

    let off = h.vox_offset;
    if !(off.is_finite() && off >= HEADER_LEN as f32 && off.fract() == 0.0) {
        return Err(Error::format(
            path,
            "vox_offset",
            format!("{off} is not a byte offset at or after the {HEADER_LEN}-byte header"),
        ));
    }
    let start = off as usize;
    let need = byte_count(path, "dim", h.dims, elem.size())?;
    let have = bytes.len().saturating_sub(start);
    if have < need {
        return Err(Error::format(
            path,
            "data",
            format!(
                "truncated: {:?} {} voxels need {need} bytes after vox_offset {start}, the file \
                 holds {have}",
                h.dims,
                elem.name()
            ),
        ));
    }

    let slope = h.scl_slope as f64;
    let inter = h.scl_inter as f64;
    let scale = if slope.is_finite() && slope != 0.0 {
        Some((slope, if inter.is_finite() { inter } else { 0.0 }))
    } else {
        None
    };
    let data = decode(&bytes[start..start + need], elem, h.big_endian, scale);

    let (mut affine, affine_from) = file_affine(&h);
    for row in affine.iter_mut().take(3) {
        for v in row.iter_mut() {
            *v *= unit;
        }
    }
    let mut steps = vec![format!(
        "read NIfTI-1 {} {}-endian, dims [x, y, z] = {:?}, voxel size {:?} mm (|pixdim[1..=3]|, \
         unit {unit_name}); array index (i, j, k) = (x, y, z); centred (offset 0)",
        elem.name(),
        if h.big_endian { "big" } else { "little" },
        h.dims,
        spacing
    )];
    steps.push(match scale {
        Some((s, i)) => format!("applied scl_slope {s} and scl_inter {i} (v * slope + inter)"),
        None => format!(
            "no scaling (scl_slope {} is 0 or not finite: values as stored)",
            h.scl_slope
        ),
    });
    Ok(from_file(
        path,
        data,
        h.dims,
        spacing,
        affine,
        (&affine_from, Some("mm")),
        steps,
    ))
}
