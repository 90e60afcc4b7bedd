//! `unispine report`: the table rows come from each run's metrics.json; a folder without one is
//! an error naming the file.

use std::process::Command;

use unispine::render::RenderSettings;
use unispine::train::Metrics;

fn metrics(method: &str, psnr: f64, n: usize) -> Metrics {
    Metrics {
        method: method.into(),
        iterations: 1000,
        completed: true,
        evals: vec![],
        test_psnr: Some(psnr),
        test_ssim: Some(0.98765),
        train_time_s: 12.34,
        eval_time_s: 1.0,
        render_fps: Some(41.25),
        render_fps_protocol: String::new(),
        n_gaussians: n,
        peak_memory_bytes: Some(3 * 1024 * 1024),
        extent: 1285.36,
        render: RenderSettings::default(),
        threads: 2,
    }
}

#[test]
fn report_prints_one_row_per_run_and_names_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let runs = [
        ("a", metrics("unispine", 38.6789, 13936)),
        ("b", metrics("3dgs", 34.3, 7)),
    ];
    for (name, m) in &runs {
        let d = dir.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("metrics.json"), serde_json::to_string(m).unwrap()).unwrap();
    }
    let out_file = dir.path().join("table.md");
    let out = Command::new(env!("CARGO_BIN_EXE_unispine"))
        .arg("report")
        .arg(dir.path().join("a"))
        .arg(dir.path().join("b"))
        .arg("--out")
        .arg(&out_file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8(out.stdout).unwrap();
    assert_eq!(table, std::fs::read_to_string(&out_file).unwrap());
    let rows: Vec<&str> = table.lines().skip(2).collect();
    assert_eq!(rows.len(), 2);
    assert!(
        rows[0].starts_with("| a | unispine | 1000 | 38.68 | 0.9877 | 12.3 | 41.2 | 13936 | 3 |"),
        "{}",
        rows[0]
    );
    assert!(rows[1].starts_with("| b | 3dgs |"), "{}", rows[1]);

    let missing = dir.path().join("nothing-here");
    std::fs::create_dir_all(&missing).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_unispine"))
        .arg("report")
        .arg(&missing)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("metrics.json"), "{err}");
}
