//! The whole of `tables.md`, `results.json` and the files `write_all` leaves, read back from
//! plans and rows built here, each expected figure computed by hand.

use super::{tables, to_json, write_all, WHAT_RUNS};
use crate::doc::{Block, Doc, Table};
use crate::reproduce::aggregate::{verdicts, Row};
use crate::reproduce::plan::tests::parse;

/// A plan of UniSpine-GS against NAF on one dataset standing in for CTSpine3D and one with no
/// rows at all; with `fdk`, FDK too and the neural fields on their presets' own schedules.
fn plan_text(fdk: bool) -> String {
    format!(
        "name = \"w\"\niters = 10\nseeds = [0, 1]\nmethods = [\"unispine\", \"naf\"{}]\n{}\
         [[datasets]]\nname = \"ct\"\npaper = \"CTSpine3D\"\ndata = [\"phantom\"]\n\
         [[datasets]]\nname = \"us\"\ndata = [\"phantom\"]\n",
        if fdk { ", \"fdk\"" } else { "" },
        if fdk {
            "field_iters = \"preset\"\n"
        } else {
            ""
        }
    )
}

fn row(method: &str, seed: u64, psnr: f64, time: f64, fps: f64) -> Row {
    Row {
        dataset: "ct".into(),
        paper_dataset: Some("CTSpine3D".into()),
        method: method.into(),
        base: method.into(),
        seed,
        status: "done".into(),
        completed: true,
        psnr: Some(psnr),
        ssim: Some(0.5 + psnr / 100.0),
        train_time_s: Some(time),
        fps: Some(fps),
        n_gaussians: (method == "unispine").then_some(1000 + seed as usize * 200),
        ..Default::default()
    }
}

/// UniSpine-GS: PSNR 35.0 and 35.4 dB, 100 s, 50 fps; NAF 30.0 and 30.2 dB, 620 s and 620 s
/// (6.2x slower, the paper's factor), 0.5 fps (100x fewer frames); the `us` cells missing.
fn rows() -> Vec<Row> {
    let mut r = vec![
        row("unispine", 0, 35.0, 100.0, 50.0),
        row("unispine", 1, 35.4, 100.0, 50.0),
        row("naf", 0, 30.0, 620.0, 0.5),
        row("naf", 1, 30.2, 620.0, 0.5),
    ];
    for m in ["unispine", "naf"] {
        for s in 0..2 {
            r.push(Row {
                dataset: "us".into(),
                method: m.into(),
                base: m.into(),
                seed: s,
                status: "missing".into(),
                ..Default::default()
            });
        }
    }
    r
}

fn doc(fdk: bool, extra: &str) -> Doc {
    let plan = parse(&plan_text(fdk)).unwrap();
    let rows = rows();
    let v = verdicts(&plan, &rows);
    tables(&plan, &rows, &v, &[], extra)
}

/// The table right after the heading `h`.
fn table_after<'a>(d: &'a Doc, h: &str) -> &'a Table {
    let i = d
        .blocks
        .iter()
        .position(|b| matches!(b, Block::Heading(2, t) if t == h))
        .unwrap_or_else(|| panic!("no heading {h:?} in {:#?}", d.blocks));
    match &d.blocks[i + 1] {
        Block::Table(t) => t,
        b => panic!("{b:?} after {h:?}"),
    }
}

fn paragraphs(d: &Doc) -> Vec<&str> {
    d.blocks
        .iter()
        .filter_map(|b| match b {
            Block::Paragraph(p) => Some(p.as_str()),
            _ => None,
        })
        .collect()
}

#[test]
fn each_method_row_gives_mean_sd_and_n_over_its_seeds() {
    let d = doc(false, "");
    let t = table_after(&d, "ct (stands in for CTSpine3D)");
    assert_eq!(t.head[..4], ["method", "n", "PSNR (dB)", "SSIM"]);
    // Means and sample sds by hand: 35.2 ± 0.2828, 30.1 ± 0.1414; SSIM 0.5 + PSNR / 100.
    assert_eq!(
        t.rows[0][..7],
        [
            "unispine",
            "2 of 2",
            "35.20 ± 0.28",
            "0.8520 ± 0.0028",
            "100.0 ± 0.0",
            "50.0 ± 0.0",
            "1100 ± 141"
        ]
    );
    assert_eq!(
        t.rows[1][..7],
        [
            "naf (reduced)",
            "2 of 2",
            "30.10 ± 0.14",
            "0.8010 ± 0.0014",
            "620.0 ± 0.0",
            "0.500 ± 0.000",
            "-"
        ]
    );
    // The paper's Table 1 row beside each (UniSpine-GS and NAF on CTSpine3D).
    for r in &t.rows {
        assert!(r[7].contains(" / "), "{r:?}");
    }
    // A dataset none of whose cells ran says so instead of a table.
    assert!(d
        .blocks
        .iter()
        .any(|b| matches!(b, Block::Heading(2, t) if t == "us: no results")));
    assert!(!d.blocks.iter().any(
        |b| matches!(b, Block::Heading(2, t) if t.starts_with("us") && t != "us: no results")
    ));
}

#[test]
fn what_runs_gives_the_command_of_each_kind_of_cell() {
    let with = doc(true, "");
    let without = doc(false, "");
    for d in [&with, &without] {
        assert!(d
            .blocks
            .iter()
            .any(|b| matches!(b, Block::Heading(2, t) if t == WHAT_RUNS)));
        assert!(
            paragraphs(d).contains(&"Every Gaussian cell: `unispine train --iters 10`."),
            "{:#?}",
            paragraphs(d)
        );
    }
    assert!(
        paragraphs(&with)
            .contains(&"Every neural-field cell: the preset's own schedule; FDK is one pass."),
        "{:#?}",
        paragraphs(&with)
    );
    assert!(
        paragraphs(&without).contains(&"Every neural-field cell: `unispine train --iters 10`."),
        "{:#?}",
        paragraphs(&without)
    );
}

#[test]
fn verdicts_show_decibels_for_accuracy_and_ratios_for_speed() {
    let d = doc(false, "");
    let t = table_after(&d, "Verdicts on the paper's claims");
    let row = |start: &str| {
        t.rows
            .iter()
            .find(|r| r[0].starts_with(start))
            .unwrap_or_else(|| panic!("no claim {start:?} in {:#?}", t.rows))
    };
    // d = 35.0 - 30.0 and 35.4 - 30.2: mean 5.1 dB, two pairs.
    let acc = row("UniSpine-GS beats naf");
    assert_eq!((acc[1].as_str(), acc[2].as_str()), ("unispine vs naf", "2"));
    assert_eq!(acc[3], "5.100 dB");
    assert_eq!(acc[5], "**reproduced**");
    // ln(620 / 100) per pair, shown as the ratio; 50 / 0.5 = 100x frames.
    let train = row("UniSpine-GS trains 6.2x");
    assert_eq!(train[3], "6.200x");
    let render = row("UniSpine-GS renders 300x");
    assert_eq!(render[3], "100.000x");
    assert_eq!(render[5], "**not reproduced**");
    // A claim without its methods in the plan is not tested and shows no figure.
    let untested = row("RIRF + ACUI beat 3DGS");
    assert_eq!((untested[3].as_str(), untested[4].as_str()), ("-", "-"));
}

#[test]
fn the_closing_paragraph_is_added_only_when_given() {
    let with = doc(false, "  the harness took 5 s \n");
    assert_eq!(
        with.blocks.last(),
        Some(&Block::Paragraph("the harness took 5 s".into()))
    );
    let without = doc(false, " \n ");
    assert_eq!(with.blocks[..with.blocks.len() - 1], without.blocks[..]);
}

#[test]
fn results_json_holds_the_plan_rows_and_verdicts() {
    let plan = parse(&plan_text(false)).unwrap();
    let rows = rows();
    let v = verdicts(&plan, &rows);
    let j: serde_json::Value = serde_json::from_str(&to_json(&plan, &rows, &v)).unwrap();
    assert_eq!(j["plan"], "w");
    assert_eq!(j["iters"], 10);
    assert_eq!(j["seeds"], serde_json::json!([0, 1]));
    assert_eq!(j["rows"].as_array().unwrap().len(), rows.len());
    assert_eq!(j["rows"][1]["psnr"], 35.4);
    assert_eq!(j["verdicts"].as_array().unwrap().len(), v.len());
    assert_eq!(j["verdicts"][0]["claim"]["text"], v[0].claim.text.as_str());
}

/// `write_all` reads every cell of the plan from the folder (none has run here: every row is
/// `missing`) and leaves the three files, `tables.md` being the returned document.
#[test]
fn write_all_leaves_csv_json_and_markdown_for_every_cell() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = parse(&plan_text(true)).unwrap();
    let (rows, v, d) = write_all(&plan, tmp.path(), &[], "").unwrap();
    // 2 datasets x 3 methods x 2 seeds.
    assert_eq!(rows.len(), 12);
    assert!(rows.iter().all(|r| r.status == "missing"));
    assert!(!v.is_empty());
    let read = |n: &str| std::fs::read_to_string(tmp.path().join(n)).unwrap();
    assert_eq!(read("results.csv").lines().count(), 1 + 12);
    assert_eq!(read("tables.md"), d.to_markdown());
    let j: serde_json::Value = serde_json::from_str(&read("results.json")).unwrap();
    assert_eq!(j["rows"].as_array().unwrap().len(), 12);
    assert!(d
        .blocks
        .iter()
        .any(|b| matches!(b, Block::Heading(2, t) if t == "ct: no results")));
}
