//! MetaImage reader (`.mha` with the data after the header, `.mhd` with a separate data file),
//! written from the MetaIO text-header format (ITK's MetaImage).
//!
//! Header keys used (`Key = Value` lines, key names case-insensitive; `ElementDataFile` is the
//! last one): `NDims` (2 or 3), `DimSize`, `ElementSpacing` (else `ElementSize`, else 1 mm as
//! MetaIO defaults), `ElementType` (MET_UCHAR, MET_CHAR, MET_SHORT, MET_USHORT, MET_INT,
//! MET_UINT, MET_LONG_LONG, MET_ULONG_LONG, MET_FLOAT, MET_DOUBLE), `ElementNumberOfChannels`
//! (must be 1), `ElementByteOrderMSB` / `BinaryDataByteOrderMSB`, `CompressedData` (zlib, or
//! gzip when the stream starts with the gzip magic), `CompressedDataSize`, `HeaderSize` (bytes to
//! skip in a separate data file; -1 = the data is the end of the file), `Offset` (or `Position`,
//! `Origin`), `TransformMatrix` (or `Rotation`, `Orientation`), `ElementDataFile` (`LOCAL` or a
//! plain file name in the header's folder; `LIST` and file patterns are not supported).
//!
//! Input limits: the text header must end (with `ElementDataFile`) within 1 MiB; a separate data
//! file must be a regular file beside the header (a name with a folder part, `..` or an absolute
//! path is refused, so is a device such as `/dev/zero`); the claimed data size is checked against
//! the bytes present before decoding. An affine with a NaN or infinite entry is dropped with a
//! note in the provenance.
//!
//! The recorded affine is `world = Offset + sum_a index_a * spacing_a * TM[a]`, where `TM[a]`
//! is row `a` of TransformMatrix as written (the direction of array axis `a`; ITK's MetaImageIO
//! reads it the same way). It is not applied: index (i, j, k) is our (x, y, z), centred.

use super::{byte_count, decode, from_file, read_bytes, Elem, Volume};
use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

/// Longest header we accept before `ElementDataFile` (bytes).
const MAX_HEADER: usize = 1 << 20;

/// The parsed text header: (key as written, value) in file order, and the byte offset just after
/// the `ElementDataFile` line.
struct Header {
    fields: Vec<(String, String)>,
    data_start: usize,
}

impl Header {
    /// The value of the first of `keys` present (case-insensitive).
    fn get(&self, keys: &[&str]) -> Option<(&str, &str)> {
        for k in keys {
            if let Some((key, v)) = self.fields.iter().find(|(f, _)| f.eq_ignore_ascii_case(k)) {
                return Some((key.as_str(), v.as_str()));
            }
        }
        None
    }
}

fn parse_header(path: &Path, b: &[u8]) -> Result<Header> {
    let mut fields = Vec::new();
    let mut pos = 0;
    while pos < b.len() && pos < MAX_HEADER {
        let end = b[pos..]
            .iter()
            .position(|&c| c == b'\n')
            .map(|e| pos + e)
            .unwrap_or(b.len());
        let line = std::str::from_utf8(&b[pos..end]).map_err(|_| {
            Error::format(
                path,
                "header",
                format!("byte {pos}: not a MetaImage text header (non-text bytes before ElementDataFile)"),
            )
        })?;
        let line = line.trim();
        pos = (end + 1).min(b.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let Some((k, v)) = line.split_once('=') else {
            return Err(Error::format(
                path,
                "header",
                format!("line `{line}` is not `Key = Value`: not a MetaImage header"),
            ));
        };
        let k = k.trim().to_string();
        let v = v.trim().to_string();
        let last = k.eq_ignore_ascii_case("ElementDataFile");
        fields.push((k, v));
        if last {
            return Ok(Header {
                fields,
                data_start: pos,
            });
        }
    }
    if pos >= MAX_HEADER {
        return Err(Error::format(
            path,
            "header",
            format!(
                "no `ElementDataFile` line within the first {MAX_HEADER} bytes: the text header \
                 is longer than the {MAX_HEADER}-byte limit (or this is not a MetaImage file)"
            ),
        ));
    }
    Err(Error::format(
        path,
        "ElementDataFile",
        "missing header key (the MetaImage header ends with `ElementDataFile = ...`)",
    ))
}

fn required<'a>(path: &Path, h: &'a Header, key: &str) -> Result<(&'a str, &'a str)> {
    h.get(&[key])
        .ok_or_else(|| Error::format(path, key, "missing header key"))
}

fn numbers(path: &Path, key: &str, v: &str) -> Result<Vec<f64>> {
    v.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| Error::format(path, key, format!("`{t}` is not a number in `{v}`")))
        })
        .collect()
}

fn boolean(path: &Path, key: &str, v: &str) -> Result<bool> {
    match v.to_ascii_lowercase().as_str() {
        "true" | "1" => Ok(true),
        "false" | "0" => Ok(false),
        _ => Err(Error::format(
            path,
            key,
            format!("`{v}` is not True or False"),
        )),
    }
}

fn element_type(path: &Path, key: &str, v: &str) -> Result<Elem> {
    Ok(match v.to_ascii_uppercase().as_str() {
        "MET_UCHAR" => Elem::U8,
        "MET_CHAR" => Elem::I8,
        "MET_USHORT" => Elem::U16,
        "MET_SHORT" => Elem::I16,
        "MET_UINT" => Elem::U32,
        "MET_INT" => Elem::I32,
        "MET_ULONG_LONG" => Elem::U64,
        "MET_LONG_LONG" => Elem::I64,
        "MET_FLOAT" => Elem::F32,
        "MET_DOUBLE" => Elem::F64,
        _ => {
            return Err(Error::format(
                path,
                key,
                format!(
                    "unsupported element type `{v}`; supported: MET_UCHAR, MET_CHAR, MET_USHORT, \
                     MET_SHORT, MET_UINT, MET_INT, MET_ULONG_LONG, MET_LONG_LONG, MET_FLOAT, \
                     MET_DOUBLE"
                ),
            ))
        }
    })
}

/// Read a MetaImage volume. See the module header for the keys and conventions.
pub fn read(path: &Path) -> Result<Volume<f32>> {
    let bytes = read_bytes(path)?;
    let h = parse_header(path, &bytes)?;
    let mut steps = Vec::new();

    let (k, v) = required(path, &h, "NDims")?;
    let ndims: usize = v
        .parse()
        .map_err(|_| Error::format(path, k, format!("`{v}` is not an integer")))?;
    if !(2..=3).contains(&ndims) {
        return Err(Error::format(
            path,
            k,
            format!("{ndims} dimensions: only 2-D and 3-D images are supported"),
        ));
    }
    let (k, v) = required(path, &h, "DimSize")?;
    let ds = numbers(path, k, v)?;
    if ds.len() != ndims
        || ds
            .iter()
            .any(|&d| !(d >= 1.0 && d.fract() == 0.0 && d < 1e12))
    {
        return Err(Error::format(
            path,
            k,
            format!("`{v}` is not {ndims} positive integers (NDims = {ndims})"),
        ));
    }
    let mut dims = [1usize; 3];
    for a in 0..ndims {
        dims[a] = ds[a] as usize;
    }

    let mut spacing = [1.0; 3];
    match h.get(&["ElementSpacing", "ElementSize"]) {
        Some((k, v)) => {
            let s = numbers(path, k, v)?;
            if s.len() != ndims || s.iter().any(|&x| !(x.is_finite() && x != 0.0)) {
                return Err(Error::format(
                    path,
                    k,
                    format!("`{v}` is not {ndims} finite non-zero voxel sizes"),
                ));
            }
            for a in 0..ndims {
                spacing[a] = s[a].abs();
            }
        }
        None => steps.push(
            "no ElementSpacing/ElementSize in the header: 1 mm voxels (the MetaIO default)"
                .to_string(),
        ),
    }

    let (k, v) = required(path, &h, "ElementType")?;
    let elem = element_type(path, k, v)?;
    if let Some((k, v)) = h.get(&["ElementNumberOfChannels"]) {
        if v.trim() != "1" {
            return Err(Error::format(
                path,
                k,
                format!("{v} channels: only scalar (1-channel) images are supported"),
            ));
        }
    }
    let big_endian = match h.get(&["ElementByteOrderMSB", "BinaryDataByteOrderMSB"]) {
        Some((k, v)) => boolean(path, k, v)?,
        None => false,
    };
    let compressed = match h.get(&["CompressedData"]) {
        Some((k, v)) => boolean(path, k, v)?,
        None => false,
    };
    let compressed_size = match h.get(&["CompressedDataSize"]) {
        Some((k, v)) => Some(
            v.parse::<usize>()
                .map_err(|_| Error::format(path, k, format!("`{v}` is not a byte count")))?,
        ),
        None => None,
    };

    // Where the (possibly compressed) voxel bytes are.
    let (kf, file) = required(path, &h, "ElementDataFile")?;
    let need = byte_count(path, "DimSize", dims, elem.size())?;
    let external;
    let (data_path, stream): (std::path::PathBuf, &[u8]) = if file.eq_ignore_ascii_case("LOCAL") {
        (path.to_path_buf(), &bytes[h.data_start..])
    } else if file.eq_ignore_ascii_case("LIST") || file.contains('%') || file.contains(' ') {
        return Err(Error::format(
            path,
            kf,
            format!("`{file}`: multi-file data (LIST or a file pattern) is not supported"),
        ));
    } else {
        // Only a file beside the header: one plain name, no folder part, no `..`.
        let mut comps = std::path::Path::new(file).components();
        let beside = matches!(
            (comps.next(), comps.next()),
            (Some(std::path::Component::Normal(_)), None)
        );
        if !beside {
            return Err(Error::format(
                path,
                kf,
                format!(
                    "`{file}`: the data file must be a plain file name in the header's folder \
                     (no folder part, no `..`, not an absolute path)"
                ),
            ));
        }
        let p = path
            .parent()
            .map(|d| d.join(file))
            .unwrap_or_else(|| std::path::PathBuf::from(file));
        external = read_bytes(&p)?;
        let skip = match h.get(&["HeaderSize"]) {
            Some((k, v)) => {
                let n: i64 = v
                    .parse()
                    .map_err(|_| Error::format(path, k, format!("`{v}` is not an integer")))?;
                if n == -1 && !compressed {
                    external.len().saturating_sub(need)
                } else if n >= 0 {
                    n as usize
                } else {
                    return Err(Error::format(path, k, format!("{n} is not a byte count")));
                }
            }
            None => 0,
        };
        steps.push(format!("voxel data from `{}`", p.display()));
        let s = external.get(skip..).unwrap_or(&[]);
        (p, s)
    };

    let raw: std::borrow::Cow<[u8]> = if compressed {
        let src = match compressed_size {
            Some(n) if n <= stream.len() => &stream[..n],
            Some(n) => {
                return Err(Error::format(
                    &data_path,
                    "CompressedDataSize",
                    format!(
                        "truncated: header says {n} compressed bytes, the file holds {}",
                        stream.len()
                    ),
                ))
            }
            None => stream,
        };
        // Capacity bounded by deflate's largest ratio (about 1032:1), so a header claiming a
        // huge DimSize cannot make us reserve more than the stream can hold.
        let mut out = Vec::with_capacity(need.min(src.len().saturating_mul(1032)));
        let gz = src.starts_with(&[0x1f, 0x8b]);
        let res = if gz {
            flate2::read::GzDecoder::new(src)
                .take(need as u64)
                .read_to_end(&mut out)
        } else {
            flate2::read::ZlibDecoder::new(src)
                .take(need as u64)
                .read_to_end(&mut out)
        };
        res.map_err(|e| {
            Error::format(
                &data_path,
                "CompressedData",
                format!(
                    "corrupt or truncated {} stream: {e}",
                    if gz { "gzip" } else { "zlib" }
                ),
            )
        })?;
        steps.push(format!(
            "decompressed {} {} bytes",
            if gz { "gzip" } else { "zlib" },
            src.len()
        ));
        std::borrow::Cow::Owned(out)
    } else {
        std::borrow::Cow::Borrowed(stream)
    };
    if raw.len() < need {
        return Err(Error::format(
            &data_path,
            "ElementDataFile",
            format!(
                "truncated data: {dims:?} {} voxels need {need} bytes, found {}",
                elem.name(),
                raw.len()
            ),
        ));
    }
    let data = decode(&raw[..need], elem, big_endian, None);

    // Recorded affine: Offset and TransformMatrix (rows = directions of the array axes).
    let mut origin = [0.0; 3];
    if let Some((k, v)) = h.get(&["Offset", "Position", "Origin"]) {
        let o = numbers(path, k, v)?;
        if o.len() != ndims {
            return Err(Error::format(
                path,
                k,
                format!("`{v}` is not {ndims} numbers"),
            ));
        }
        origin[..ndims].copy_from_slice(&o);
    }
    let mut tm = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if let Some((k, v)) = h.get(&["TransformMatrix", "Rotation", "Orientation"]) {
        let m = numbers(path, k, v)?;
        if m.len() != ndims * ndims {
            return Err(Error::format(
                path,
                k,
                format!("`{v}` is not {} numbers", ndims * ndims),
            ));
        }
        for a in 0..ndims {
            for r in 0..ndims {
                tm[a][r] = m[a * ndims + r];
            }
        }
    }
    let mut affine = [[0.0; 4]; 4];
    for r in 0..3 {
        for a in 0..3 {
            affine[r][a] = tm[a][r] * spacing[a];
        }
        affine[r][3] = origin[r];
    }
    affine[3][3] = 1.0;

    steps.insert(
        0,
        format!(
            "read MetaImage {} {}-endian, dims [x, y, z] = {dims:?}, voxel size {spacing:?} mm; \
             array index (i, j, k) = (x, y, z); centred (offset 0)",
            elem.name(),
            if big_endian { "big" } else { "little" }
        ),
    );
    Ok(from_file(
        path,
        data,
        dims,
        spacing,
        affine,
        ("Offset and TransformMatrix", None),
        steps,
    ))
}
