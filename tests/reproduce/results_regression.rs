//! Results regression: the built-in `quick` plan at seed 0 (the main job's plan with one seed)
//! is rerun and compared bit for bit with `golden/results/quick-seed0.json`: each cell's test
//! PSNR and SSIM (exact decimal round trip), Gaussian count and the FNV-1a 64 of its
//! `model.ply`. A change of numerics must update that file in the same commit and say why:
//! `UNISPINE_BLESS=1 cargo test --release --test reproduce results_regression::` rewrites it.

use crate::common;

use std::path::Path;

use serde_json::{json, Value};

const GOLDEN: &str = "golden/results/quick-seed0.json";

fn fnv1a(bytes: &[u8]) -> String {
    let h = bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("{h:016x}")
}

#[test]
fn the_quick_plan_at_seed_0_gives_the_committed_bits() {
    let d = tempfile::tempdir().unwrap();
    let plan = common::cli::ok(&["reproduce", "--show", "quick"]);
    let one_seed = plan.replace("seeds = [0, 1]", "seeds = [0]");
    assert_ne!(
        plan, one_seed,
        "the quick plan no longer lists seeds [0, 1]"
    );
    let p = d.path().join("quick-seed0.toml");
    std::fs::write(&p, one_seed).unwrap();
    let out = d.path().join("out");
    let r = common::cli::run(&[
        "reproduce",
        p.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "2",
    ]);
    assert!(r.ok, "{}", r.stderr);
    let results: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let rows = results["rows"].as_array().expect("rows");
    let mut cells = Vec::new();
    for row in rows {
        let dir = out.join(row["run_dir"].as_str().unwrap());
        let model = std::fs::read(dir.join("model.ply")).unwrap();
        cells.push(json!({
            "cell": format!("{}/{}/seed{}", row["dataset"].as_str().unwrap(),
                            row["method"].as_str().unwrap(), row["seed"]),
            "psnr": row["psnr"],
            "ssim": row["ssim"],
            "n_gaussians": row["n_gaussians"],
            "model_fnv1a": fnv1a(&model),
        }));
    }
    let got = json!({ "plan": "quick, seeds = [0]", "cells": cells });
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join(GOLDEN);
    if std::env::var_os("UNISPINE_BLESS").is_some() {
        std::fs::write(&golden, serde_json::to_string_pretty(&got).unwrap() + "\n").unwrap();
        return;
    }
    let want: Value = serde_json::from_str(
        &std::fs::read_to_string(&golden)
            .unwrap_or_else(|e| panic!("{GOLDEN}: {e} (write it with UNISPINE_BLESS=1)")),
    )
    .unwrap();
    assert_eq!(
        got, want,
        "the quick plan's results changed: if on purpose, rerun with UNISPINE_BLESS=1 and say why \
         in the commit"
    );
}
