//! `unispine report`: the table rows come from each run's metrics.json; a folder without one
//! gets a row saying so (the others are still reported), a stopped run shows no PSNR.

use std::ffi::OsStr;

use common::cli;
use unispine::render::RenderSettings;
use unispine::train::{EvalPoint, Metrics};

use crate::common;

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
        model_bytes: None,
        peak_memory_bytes: Some(3 * 1024 * 1024),
        extent: 1285.36,
        render: RenderSettings::default(),
        threads: 2,
        compaction: None,
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
    let table = cli::ok(&[
        OsStr::new("report"),
        dir.path().join("a").as_os_str(),
        dir.path().join("b").as_os_str(),
        OsStr::new("--out"),
        out_file.as_os_str(),
    ]);
    assert_eq!(table, std::fs::read_to_string(&out_file).unwrap());
    let rows: Vec<&str> = table.lines().skip(2).collect();
    assert_eq!(rows.len(), 2);
    assert!(
        rows[0].starts_with("| a | unispine | 1000 | 38.68 | 0.9877 | 12.3 | 41.2 | 13936 | 3 |"),
        "{}",
        rows[0]
    );
    assert!(rows[1].starts_with("| b | 3dgs |"), "{}", rows[1]);

    // A folder without metrics.json and a stopped run, beside a finished one.
    let missing = dir.path().join("nothing-here");
    std::fs::create_dir_all(&missing).unwrap();
    let mut stopped = metrics("unispine", 30.0, 99);
    stopped.completed = false;
    stopped.test_psnr = None;
    stopped.test_ssim = None;
    stopped.render_fps = None;
    let sd = dir.path().join("stopped");
    std::fs::create_dir_all(&sd).unwrap();
    std::fs::write(
        sd.join("metrics.json"),
        serde_json::to_string(&stopped).unwrap(),
    )
    .unwrap();
    let a = dir.path().join("a");
    let table = cli::ok(&[
        OsStr::new("report"),
        missing.as_os_str(),
        sd.as_os_str(),
        a.as_os_str(),
    ]);
    let rows: Vec<&str> = table.lines().skip(2).collect();
    assert!(
        rows[0].starts_with("| nothing-here | no metrics.json"),
        "{}",
        rows[0]
    );
    assert!(
        rows[1].starts_with("| stopped | unispine | 1000 (stopped) | - | - |"),
        "{}",
        rows[1]
    );
    assert!(rows[2].starts_with("| a | unispine |"), "{}", rows[2]);
    // A folder that does not exist is still an error naming it.
    let gone = dir.path().join("no-such-run");
    let err = cli::fails(&[OsStr::new("report"), gone.as_os_str()]);
    assert!(err.contains("no-such-run"), "{err}");
}

/// `--charts DIR` writes tradeoff.svg (one marker per run in each panel, placed by value) and
/// curves.svg (three panels with one line per run); a malformed log.csv is an error naming the
/// file and the line.
#[test]
fn report_charts_place_runs_by_value_and_name_bad_logs() {
    let dir = tempfile::tempdir().unwrap();
    let mut a = metrics("unispine", 38.0, 100);
    a.train_time_s = 50.0;
    let mut b = metrics("3dgs", 34.0, 200);
    b.train_time_s = 100.0;
    for (m, psnr) in [(&mut a, 38.0), (&mut b, 34.0)] {
        m.evals = [(100, psnr - 10.0), (300, psnr)]
            .map(|(iteration, psnr)| EvalPoint {
                iteration,
                psnr,
                ssim: 0.9,
                n_gaussians: 300,
            })
            .to_vec();
    }
    for (name, m) in [("a", &a), ("b", &b)] {
        let d = dir.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("metrics.json"), serde_json::to_string(m).unwrap()).unwrap();
        let mut log = String::from("iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n");
        for it in 1..=300 {
            log += &format!(
                "{it},0,0.1,0.1,0.9,{},{},0.1\n",
                20.0 + it as f64 / 30.0,
                50 + it
            );
        }
        std::fs::write(d.join("log.csv"), log).unwrap();
    }
    let charts = dir.path().join("charts");
    let run = |runs: &[&std::path::Path]| {
        let mut args: Vec<&OsStr> = vec![OsStr::new("report")];
        args.extend(runs.iter().map(|p| p.as_os_str()));
        args.extend([OsStr::new("--charts"), charts.as_os_str()]);
        cli::run(&args)
    };
    let out = run(&[&dir.path().join("a"), &dir.path().join("b")]);
    assert!(out.ok, "{}", out.stderr);

    let tradeoff = std::fs::read_to_string(charts.join("tradeoff.svg")).unwrap();
    assert!(tradeoff.starts_with("<svg"));
    let markers = unispine::report::svg::marker_centres(&tradeoff);
    // Two panels (time, fps) x two runs; in the time panel run b is slower (right) and worse (lower).
    assert_eq!(markers.len(), 4, "{tradeoff}");
    assert!(markers[1].0 > markers[0].0 && markers[1].1 > markers[0].1);
    assert!(tradeoff.contains("a (unispine)") && tradeoff.contains("b (3dgs)"));

    let curves = std::fs::read_to_string(charts.join("curves.svg")).unwrap();
    assert_eq!(
        curves.matches("<polyline").count(),
        6,
        "three panels x two runs"
    );

    std::fs::write(
        dir.path().join("b/log.csv"),
        "iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n1,0,0.1,0.1,0.9,oops,3,0.1\n",
    )
    .unwrap();
    let out = run(&[&dir.path().join("b")]);
    assert!(!out.ok);
    let err = out.stderr;
    assert!(err.contains("log.csv") && err.contains("line 2"), "{err}");
}
