//! Hostile model files: a PLY claiming a huge vertex count.

use crate::common::hostile::*;

#[test]
fn ply_claiming_huge_vertex_counts_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let geo = dir.path().join("geometry.json");
    std::fs::write(
        &geo,
        r#"{"DSD": 1500.0, "DSO": 1000.0, "nDetector": [8, 8], "dDetector": [4.0, 4.0],
            "nVoxel": [8, 8, 8], "dVoxel": [2.0, 2.0, 2.0]}"#,
    )
    .unwrap();
    let props = [
        "x", "y", "z", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        "opacity", "f_dc_0",
    ];
    for (name, count, fmt) in [
        ("e9.ply", "1000000000", "binary_little_endian"),
        ("e12.ply", "1000000000000", "binary_little_endian"),
        ("e18.ply", "1000000000000000000", "binary_little_endian"),
        ("ascii.ply", "1000000000000", "ascii"),
    ] {
        let mut h = format!("ply\nformat {fmt} 1.0\nelement vertex {count}\n");
        for p in props {
            h += &format!("property float {p}\n");
        }
        h += "end_header\n";
        let mut b = h.into_bytes();
        b.extend_from_slice(&[0u8; 480]);
        let p = dir.path().join(name);
        std::fs::write(&p, &b).unwrap();
        let out = dir.path().join("out");
        assert_error(
            &[
                "render",
                "--ply",
                &s(&p),
                "--geometry",
                &s(&geo),
                "--angle-deg",
                "0",
                "--out",
                &s(&out),
            ],
            name,
            &["element vertex"],
        );
    }
}
