//! `unispine render`: outputs, the gradient of sum(W * image) with respect to the stored PLY
//! fields (checked by central differences through the command itself, on PLY files written by an
//! independent writer below), and errors for bad input.

use std::path::{Path, PathBuf};

use common::cli::run;
use ndarray::{Array1, Array2};

use crate::common;

/// One Gaussian as stored in a 3DGS PLY (62 float32 fields).
#[derive(Clone)]
struct Stored {
    xyz: [f32; 3],
    f_dc: [f32; 3],
    f_rest: [f32; 45],
    opacity: f32,
    scale: [f32; 3],
    rot: [f32; 4],
}

/// A 3DGS-layout binary PLY written field by field (independent of the crate's writer).
fn write_ply(path: &Path, gs: &[Stored]) {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\n");
    h += &format!("element vertex {}\n", gs.len());
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"].map(String::from).to_vec();
    names.extend((0..3).map(|i| format!("f_dc_{i}")));
    names.extend((0..45).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    for n in &names {
        h += &format!("property float {n}\n");
    }
    h += "end_header\n";
    let mut bytes = h.into_bytes();
    for g in gs {
        let mut v: Vec<f32> = g.xyz.to_vec();
        v.extend([0.0; 3]);
        v.extend(g.f_dc);
        v.extend(g.f_rest);
        v.push(g.opacity);
        v.extend(g.scale);
        v.extend(g.rot);
        for x in v {
            bytes.extend(x.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

fn scene() -> Vec<Stored> {
    let mk = |xyz: [f32; 3], s: f32, o: f32, f0: f32| {
        let mut f_rest = [0.0f32; 45];
        // A little view-independent structure in the first rest coefficient of each channel.
        for c in 0..3 {
            f_rest[c * 15] = 0.125 * (c as f32 + 1.0);
        }
        Stored {
            xyz,
            f_dc: [f0, f0 + 0.25, f0 - 0.25],
            f_rest,
            opacity: o,
            scale: [s, s + 0.25, s - 0.125],
            rot: [1.0, 0.125, -0.25, 0.0625],
        }
    };
    vec![
        mk([0.0, 0.0, 0.0], 2.0, 0.0, 0.5),
        mk([6.0, -4.0, 5.0], 1.75, -0.5, -0.25),
        mk([-7.0, 3.0, -6.0], 2.25, 0.5, 0.25),
    ]
}

fn write_geometry(dir: &Path) -> PathBuf {
    let p = dir.join("geometry.json");
    let extra =
        r#", "nVoxel": [32, 32, 32], "dVoxel": [2.0, 2.0, 2.0], "offDetector": [2.0, -3.0]"#;
    common::cli::write_geometry(&p, [1500.0, 1000.0], [24, 28], 4.0, extra);
    p
}

fn render(ply: &Path, geo: &Path, out: &Path, weights: Option<&Path>) -> Array2<f32> {
    let mut a = vec![
        "render".to_string(),
        "--ply".into(),
        ply.display().to_string(),
        "--geometry".into(),
        geo.display().to_string(),
        "--angle-deg".into(),
        "30".into(),
        "--out".into(),
        out.display().to_string(),
    ];
    if let Some(w) = weights {
        a.push("--grad-weights".into());
        a.push(w.display().to_string());
    }
    common::cli::ok(&a);
    ndarray_npy::read_npy(out.join("image.npy")).unwrap()
}

#[test]
fn render_writes_image_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("m.ply");
    write_ply(&ply, &scene());
    let geo = write_geometry(dir.path());
    let img = render(&ply, &geo, &dir.path().join("out"), None);
    assert_eq!(img.dim(), (24, 28));
    assert!(img.iter().all(|v| v.is_finite()));
    assert!(
        img.iter().cloned().fold(0.0f32, f32::max) > 0.05,
        "scene is visible"
    );
    assert!(dir.path().join("out/image.png").exists());
    assert!(!dir.path().join("out/grads.npz").exists());
}

/// Gradients from `grads.npz` against central differences of sum(W * image), each stored field
/// perturbed in its own PLY file. The PLY stores f32, so the step is a power of two and the
/// tolerance is set by the f32 rounding of the image (1e-7 relative) over the step, not by the
/// model: 2e-3 relative to the largest gradient of the group.
#[test]
fn grads_match_central_differences_of_stored_fields() {
    let dir = tempfile::tempdir().unwrap();
    let geo = write_geometry(dir.path());
    let base = scene();
    let ply = dir.path().join("m.ply");
    write_ply(&ply, &base);
    let (h, w) = (24usize, 28usize);
    let wts = Array2::from_shape_fn((h, w), |(r, c)| ((r * 7 + c * 3) % 11) as f64 / 11.0 - 0.3);
    let wpath = dir.path().join("w.npy");
    ndarray_npy::write_npy(&wpath, &wts).unwrap();
    let out = dir.path().join("out");
    render(&ply, &geo, &out, Some(&wpath));
    let mut npz =
        ndarray_npy::NpzReader::new(std::fs::File::open(out.join("grads.npz")).unwrap()).unwrap();
    let xyz: Array2<f64> = npz.by_name("xyz").unwrap();
    let feats: Array2<f64> = npz.by_name("features").unwrap();
    let opac: Array1<f64> = npz.by_name("opacity").unwrap();
    let scale: Array2<f64> = npz.by_name("scale").unwrap();
    let rot: Array2<f64> = npz.by_name("rot").unwrap();
    assert_eq!(xyz.dim(), (3, 3));
    assert_eq!(feats.dim(), (3, 48));
    assert_eq!(opac.dim(), 3);
    assert_eq!(scale.dim(), (3, 3));
    assert_eq!(rot.dim(), (3, 4));

    let objective = |gs: &[Stored], tag: &str| -> f64 {
        let p = dir.path().join(format!("{tag}.ply"));
        write_ply(&p, gs);
        let img = render(&p, &geo, &dir.path().join(tag), None);
        img.iter().zip(wts.iter()).map(|(a, b)| *a as f64 * b).sum()
    };
    // (group, gaussian, field setter, analytic value, step)
    type Setter = fn(&mut Stored, f32);
    let cases: Vec<(&str, usize, Setter, f64, f32)> = vec![
        ("xyz", 1, |g, d| g.xyz[0] += d, xyz[[1, 0]], 1.0 / 64.0),
        ("xyz", 2, |g, d| g.xyz[2] += d, xyz[[2, 2]], 1.0 / 64.0),
        (
            "f_dc_1",
            0,
            |g, d| g.f_dc[1] += d,
            feats[[0, 1]],
            1.0 / 64.0,
        ),
        (
            "f_rest_15",
            1,
            |g, d| g.f_rest[15] += d,
            feats[[1, 3 + 15]],
            1.0 / 64.0,
        ),
        ("opacity", 2, |g, d| g.opacity += d, opac[2], 1.0 / 64.0),
        (
            "scale_1",
            0,
            |g, d| g.scale[1] += d,
            scale[[0, 1]],
            // Not 1/256: the 1/255 alpha skip makes the image jump where a pixel's o G crosses
            // 1/255, here at scale_1 offsets of about -0.0017 and -0.0033 (each jump ~1e-3 in
            // the objective), so the stencil must stay inside (-0.0017, +0.0017).
            1.0 / 1024.0,
        ),
        ("rot_2", 1, |g, d| g.rot[2] += d, rot[[1, 2]], 1.0 / 256.0),
    ];
    for (name, i, set, analytic, step) in cases {
        let mut p = base.clone();
        set(&mut p[i], step);
        let mut m = base.clone();
        set(&mut m[i], -step);
        let fd = (objective(&p, "p") - objective(&m, "m")) / (2.0 * step as f64);
        let scale_ref = analytic.abs().max(fd.abs()).max(1e-3);
        assert!(
            (analytic - fd).abs() <= 2e-3 * scale_ref,
            "{name} of Gaussian {i}: analytic {analytic} vs central difference {fd}"
        );
    }
}

#[test]
fn bad_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let geo = write_geometry(dir.path());
    let ply = dir.path().join("m.ply");
    write_ply(&ply, &scene());
    let out = dir.path().join("out").display().to_string();
    let (g, p) = (geo.display().to_string(), ply.display().to_string());

    let args_for = |ply: &str| -> Vec<String> {
        [
            "render",
            "--ply",
            ply,
            "--geometry",
            g.as_str(),
            "--angle-deg",
            "0",
            "--out",
            out.as_str(),
        ]
        .map(String::from)
        .to_vec()
    };
    let o = run(&args_for("nope.ply"));
    assert!(!o.ok);
    assert!(o.stderr.contains("nope.ply"));

    let wrong = dir.path().join("w.npy");
    ndarray_npy::write_npy(&wrong, &Array2::<f32>::zeros((5, 5))).unwrap();
    let wp = wrong.display().to_string();
    let args = args_for(&p);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = run(&[&args[..], &["--grad-weights", &wp]].concat());
    assert!(!o.ok);
    let e = o.stderr;
    assert!(e.contains("does not match") && e.contains("w.npy"), "{e}");

    let o = run(&["render", "--ply", &p, "--out", &out]);
    assert!(!o.ok, "no view given");

    let o = run(&[&args[..], &["--active-features", "5"]].concat());
    assert!(!o.ok);
    assert!(o.stderr.contains("active-features"));

    let o = run(&[&args[..], &["--background", "NaN"]].concat());
    assert!(!o.ok);
    let e = o.stderr;
    assert!(e.contains("--background") && e.contains("NaN"), "{e}");

    // A NaN in the model is reported, not rendered.
    let mut s = scene();
    s[1].opacity = f32::NAN;
    write_ply(&ply, &s);
    let o = run(&args);
    assert!(!o.ok);
    let e = o.stderr;
    assert!(e.contains("opacity") || e.contains("NaN"), "{e}");
}

/// `render` and `drr` share one per-view geometry check (`geometry::check_view`): a source
/// inside the volume box, or a detector plane cutting it, is refused by both with the same
/// message; a source just outside is accepted by both.
#[test]
fn render_and_drr_refuse_the_same_views_with_the_same_message() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("m.ply");
    write_ply(&ply, &scene());
    // The volume drr projects: 32^3 voxels of 1 mm (npy), box [-16, 16]^3 mm.
    let vol = dir.path().join("v.npy");
    ndarray_npy::write_npy(&vol, &ndarray::Array3::<f32>::ones((32, 32, 32))).unwrap();
    let out = dir.path().join("out");
    let grid = r#", "nVoxel": [32, 32, 32], "dVoxel": [1.0, 1.0, 1.0]"#;
    let both = |name: &str, dsd: f64, dso: f64| -> (common::cli::Run, common::cli::Run) {
        let geo = dir.path().join(name);
        common::cli::write_geometry(&geo, [dsd, dso], [8, 8], 4.0, grid);
        let (g, o) = (geo.display().to_string(), out.display().to_string());
        let r = run(&[
            "render",
            "--ply",
            ply.to_str().unwrap(),
            "--geometry",
            &g,
            "--angle-deg",
            "0",
            "--out",
            &o,
        ]);
        let d = run(&[
            "drr",
            "--volume",
            vol.to_str().unwrap(),
            "--geometry",
            &g,
            "--angles-deg",
            "0",
            "--out",
            &o,
        ]);
        (r, d)
    };
    // The library's sentence, from its first word to the end of the line.
    let sentence = |e: &str, first: &str| -> String {
        let at = e
            .find(first)
            .unwrap_or_else(|| panic!("`{first}` not in:\n{e}"));
        e[at..].lines().next().unwrap().to_string()
    };
    // Source at x = 10 mm, inside [-16, 16]^3.
    let (r, d) = both("inside.json", 15.0, 10.0);
    assert!(!r.ok && !d.ok, "render:\n{}\ndrr:\n{}", r.stderr, d.stderr);
    assert!(!r.stderr.contains("panicked") && !d.stderr.contains("panicked"));
    let (sr, sd) = (
        sentence(&r.stderr, "the source at"),
        sentence(&d.stderr, "the source at"),
    );
    assert_eq!(sr, sd);
    assert!(sr.contains("lies inside the volume box"), "{sr}");
    assert!(r.stderr.contains("inside.json") && r.stderr.contains("--angle-deg"));
    // Source outside (x = 20 mm) but the detector plane at 30 mm from it cuts the box (it
    // reaches 36 mm).
    let (r, d) = both("cuts.json", 30.0, 20.0);
    assert!(!r.ok && !d.ok, "render:\n{}\ndrr:\n{}", r.stderr, d.stderr);
    assert_eq!(
        sentence(&r.stderr, "the volume reaches"),
        sentence(&d.stderr, "the volume reaches")
    );
    // Both outside: both accepted.
    let (r, d) = both("fine.json", 300.0, 200.0);
    assert!(r.ok, "{}", r.stderr);
    assert!(d.ok, "{}", d.stderr);
}
