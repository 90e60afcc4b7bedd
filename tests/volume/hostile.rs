//! Hostile volume files: NIfTI with gigabytes of trailing zeros, symlinks to devices, truncated
//! files, non-finite affines; NPY claiming huge shapes (as a volume and as a dataset array);
//! MetaImage data files outside the folder or on a device.

use crate::common::hostile::*;

#[test]
fn nifti_gz_with_gigabytes_of_trailing_zeros_reads_only_the_header_needs() {
    let dir = tempfile::tempdir().unwrap();
    // 24^3 volume (valid), then 2 GiB of zeros as 32 gzip members of 64 MiB each.
    let mut raw = nifti_header([24, 24, 24], 1.0);
    raw.extend((0..24 * 24 * 24).flat_map(|i| ((i % 7) as f32).to_le_bytes()));
    let mut file = gzip(&raw);
    let zeros = gzip(&vec![0u8; 64 << 20]);
    for _ in 0..32 {
        file.extend_from_slice(&zeros);
    }
    // Trailing zero padding after the last member, as some writers leave (Python reads it).
    file.extend_from_slice(&[0u8; 512]);
    let p = dir.path().join("zeros.nii.gz");
    std::fs::write(&p, &file).unwrap();
    let v = unispine::volume::load(&p).expect("valid volume followed by trailing data");
    assert_eq!(v.dims, [24, 24, 24]);
    assert_eq!(v.data[8], 1.0);
    // The same header claiming a huge volume: a clear error, bounded by the file's size.
    let mut raw = nifti_header([32000, 32000, 32000], 1.0);
    raw.extend_from_slice(&[0u8; 1024]);
    let p = dir.path().join("huge.nii.gz");
    std::fs::write(&p, gzip(&raw)).unwrap();
    let out = dir.path().join("out");
    assert_error(&strs(&data_us(&p, &out)), "huge.nii.gz", &["`dim`"]);
}

#[test]
fn nifti_symlink_to_a_device_and_truncated_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    #[cfg(unix)]
    {
        let p = dir.path().join("random.nii");
        std::os::unix::fs::symlink("/dev/urandom", &p).unwrap();
        assert_error(&strs(&data_us(&p, &out)), "random.nii", &["regular file"]);
    }
    let mut raw = nifti_header([64, 64, 64], 1.0);
    raw.extend_from_slice(&[0u8; 100]);
    let p = dir.path().join("cut.nii");
    std::fs::write(&p, &raw).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "cut.nii", &["truncated"]);
    // Negative and zero dims.
    let raw = nifti_header([-5, 4, 4], 1.0);
    let p = dir.path().join("neg.nii");
    std::fs::write(&p, &raw).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "neg.nii", &["dim[1]"]);
}

#[test]
fn non_finite_affine_is_dropped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let mut raw = nifti_header([4, 4, 4], f32::NAN);
    raw.extend((0..64).flat_map(|i| (i as f32).to_le_bytes()));
    let p = dir.path().join("nan_affine.nii");
    std::fs::write(&p, &raw).unwrap();
    let v = unispine::volume::load(&p).unwrap();
    assert_eq!(v.provenance.file_affine, None);
    assert!(v.provenance.steps.iter().any(|s| s.contains("dropped")));
    let p = dir.path().join("inf.mha");
    let mut b = b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nOffset = 1e400 0 0\nElementDataFile = LOCAL\n".to_vec();
    b.extend_from_slice(&[1u8; 8]);
    std::fs::write(&p, &b).unwrap();
    let v = unispine::volume::load(&p).unwrap();
    assert_eq!(v.provenance.file_affine, None);
}

#[test]
fn npy_claiming_huge_shapes_is_refused_as_volume_and_dataset_array() {
    let dir = tempfile::tempdir().unwrap();
    let mut h =
        "{'descr': '<f4', 'fortran_order': False, 'shape': (4000, 4000, 4000), }".to_string();
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(h.len() as u16).to_le_bytes());
    b.extend_from_slice(h.as_bytes());
    b.extend_from_slice(&[0u8; 4096]);
    let p = dir.path().join("huge.npy");
    std::fs::write(&p, &b).unwrap();
    let out = dir.path().join("out");
    assert_error(&strs(&data_us(&p, &out)), "huge.npy", &["`data`", "4000"]);
    // Wrong dtype string and a non-UTF-8 header.
    let mut b2 = b.clone();
    let at = b2.windows(3).position(|w| w == b"<f4").unwrap();
    b2[at..at + 3].copy_from_slice(b"<c8");
    let p = dir.path().join("complex.npy");
    std::fs::write(&p, &b2).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "complex.npy", &["`descr`"]);
    let mut b3 = b.clone();
    b3[12] = 0xff;
    let p = dir.path().join("binary.npy");
    std::fs::write(&p, &b3).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "binary.npy", &["`header`"]);
}

#[test]
fn metaimage_data_file_outside_the_folder_or_a_device_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (name, target, word) in [
        ("up.mhd", "../../etc/passwd", "plain file name"),
        ("abs.mhd", "/dev/zero", "plain file name"),
    ] {
        let p = dir.path().join(name);
        std::fs::write(
            &p,
            format!(
                "NDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\nElementDataFile = {target}\n"
            ),
        )
        .unwrap();
        assert_error(&strs(&data_us(&p, &out)), name, &["ElementDataFile", word]);
    }
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.raw")).unwrap();
        let p = dir.path().join("dev.mhd");
        std::fs::write(
            &p,
            "NDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\nElementDataFile = zero.raw\n",
        )
        .unwrap();
        assert_error(&strs(&data_us(&p, &out)), "zero.raw", &["regular file"]);
    }
    // A header over 1 MiB is reported as such.
    let p = dir.path().join("long.mha");
    let mut b = b"NDims = 3\n".to_vec();
    while b.len() < (1 << 20) + 100 {
        b.extend_from_slice(b"# comment line padding the header out\n");
    }
    b.extend_from_slice(b"ElementDataFile = LOCAL\n");
    std::fs::write(&p, &b).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "long.mha", &["1048576"]);
}
