//! Charts and `report.html` of a `unispine reproduce` output folder, from its result rows (and
//! the runs' `log.csv`): test PSNR against training time and against render fps (mean +- sd per
//! method, every seed as a dot), test PSNR against the Gaussian count, training curves with a
//! band over seeds, and the stability map. `report.html` is one self-contained page (inline
//! SVG, no script, no server).
//!
//! Over 600 lines with its tests (the page writer itself is about 560).

use std::fmt::Write as _;
use std::path::Path;

use super::svg::{self, Band, Dot, ErrorBar, Line, Marker, Panel};
use crate::doc::Doc;
use crate::error::{Error, Result};
use crate::reproduce::aggregate::Row;
use crate::reproduce::verdict::mean_sd;

/// Methods in first-appearance order (their colour index is the position).
fn methods(rows: &[Row]) -> Vec<String> {
    let mut m: Vec<String> = Vec::new();
    for r in rows {
        if !m.contains(&r.method) {
            m.push(r.method.clone());
        }
    }
    m
}

/// The chart label of method `m` ([`method_label`](crate::reproduce::aggregate::method_label)).
fn label(rows: &[Row], m: &str) -> String {
    let base = rows
        .iter()
        .find(|r| r.method == m)
        .map_or("", |r| r.base.as_str());
    crate::reproduce::aggregate::method_label(m, base)
}

fn datasets(rows: &[Row]) -> Vec<String> {
    let mut d: Vec<String> = Vec::new();
    for r in rows {
        if !d.contains(&r.dataset) {
            d.push(r.dataset.clone());
        }
    }
    d
}

/// Mean, and mean +- sd (the mean alone for one value).
fn spread(v: &[f64]) -> Option<(f64, f64, f64)> {
    let (m, sd, n) = mean_sd(v);
    match n {
        0 => None,
        1 => Some((m, m, m)),
        _ => Some((m, m - sd, m + sd)),
    }
}

/// Speed against accuracy on one dataset: test PSNR against training time and against fps.
pub fn tradeoff(rows: &[Row], dataset: &str) -> String {
    let ms = methods(rows);
    let mut time = Panel {
        title: format!("{dataset}: PSNR against training time"),
        x_label: "training wall time (s), mean ± sd".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    let mut fps = Panel {
        title: format!("{dataset}: PSNR against render speed"),
        x_label: "render speed (test views / s), mean ± sd".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    for (ci, m) in ms.iter().enumerate() {
        let rs: Vec<&Row> = rows
            .iter()
            .filter(|r| r.dataset == dataset && r.method == *m && r.psnr.is_some())
            .collect();
        let p: Vec<f64> = rs.iter().filter_map(|r| r.psnr).collect();
        let Some((pm, plo, phi)) = spread(&p) else {
            continue;
        };
        for (panel, xs) in [
            (
                &mut time,
                rs.iter().map(|r| r.train_time_s).collect::<Vec<_>>(),
            ),
            (&mut fps, rs.iter().map(|r| r.fps).collect::<Vec<_>>()),
        ] {
            let x: Vec<f64> = xs.iter().flatten().copied().collect();
            let Some((xm, xlo, xhi)) = spread(&x) else {
                continue;
            };
            for (r, xv) in rs.iter().zip(&xs) {
                if let (Some(xv), Some(y)) = (xv, r.psnr) {
                    panel.dots.push(Dot {
                        x: *xv,
                        y,
                        colour: ci,
                    });
                }
            }
            panel.error_bars.push(ErrorBar {
                x: (xlo, xhi),
                y: (plo, phi),
                colour: ci,
            });
            panel.markers.push(Marker {
                label: label(rows, m),
                x: xm,
                y: pm,
                colour: ci,
            });
        }
    }
    svg::figure(&[time, fps])
}

/// Test PSNR against the final Gaussian count on one dataset: a line per method over the sweep
/// values (mean), each run as a dot.
pub fn psnr_vs_count(rows: &[Row], dataset: &str) -> String {
    let ms = methods(rows);
    let mut p = Panel {
        title: format!("{dataset}: PSNR against Gaussian count"),
        x_label: "Gaussians at the end of training (log scale)".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    // A log axis only when the counts span more than a decade.
    let counts: Vec<f64> = rows
        .iter()
        .filter(|r| r.dataset == dataset)
        .filter_map(|r| r.n_gaussians.map(|n| n as f64))
        .collect();
    let (lo, hi) = counts
        .iter()
        .fold((f64::INFINITY, 0.0f64), |a, &c| (a.0.min(c), a.1.max(c)));
    p.log_x = lo > 0.0 && hi / lo > 10.0;
    if !p.log_x {
        p.x_label = "Gaussians at the end of training".into();
    }
    for (ci, m) in ms.iter().enumerate() {
        let rs: Vec<&Row> = rows
            .iter()
            .filter(|r| r.dataset == dataset && r.method == *m && r.psnr.is_some())
            .collect();
        let mut sweep: Vec<Option<String>> = Vec::new();
        for r in &rs {
            p.dots.push(Dot {
                x: r.n_gaussians.unwrap_or(0) as f64,
                y: r.psnr.unwrap_or(f64::NAN),
                colour: ci,
            });
            if !sweep.contains(&r.sweep_value) {
                sweep.push(r.sweep_value.clone());
            }
        }
        let mut pts: Vec<(f64, f64)> = sweep
            .iter()
            .filter_map(|v| {
                let g: Vec<&&Row> = rs.iter().filter(|r| r.sweep_value == *v).collect();
                let n: Vec<f64> = g
                    .iter()
                    .filter_map(|r| r.n_gaussians.map(|x| x as f64))
                    .collect();
                let y: Vec<f64> = g.iter().filter_map(|r| r.psnr).collect();
                Some((mean_sd(&n).0, mean_sd(&y).0)).filter(|p| p.0.is_finite())
            })
            .collect();
        // A compaction ladder ends at the unbounded model it pruned.
        let unb = crate::reproduce::compactness::unbounded(rows);
        if let Some((_, _, n, y)) = unb.iter().find(|u| u.0 == dataset && u.1 == *m) {
            pts.push((*n, *y));
            p.markers.push(Marker {
                label: format!("{} unbounded", label(rows, m)),
                x: *n,
                y: *y,
                colour: ci,
            });
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        p.lines.push(Line {
            label: label(rows, m),
            points: pts,
        });
    }
    svg::figure(&[p])
}

/// Training curves on one dataset: training-view PSNR (moving mean over 2 % of the run) per
/// method, mean over seeds with a band of +- sd; the runs' `log.csv` files are read from `out`.
pub fn curves(rows: &[Row], dataset: &str, out: &Path) -> String {
    let ms = methods(rows);
    // With a sweep, the curves of its last value (e.g. the most views, the largest budget).
    let shown = rows
        .iter()
        .rev()
        .find(|r| r.dataset == dataset && r.psnr.is_some())
        .and_then(|r| r.sweep_value.clone());
    let which = match (&shown, rows.iter().find_map(|r| r.sweep_flag.clone())) {
        (Some(v), Some(f)) => format!(", {f} = {v}"),
        _ => String::new(),
    };
    let mut p = Panel {
        title: format!("{dataset}: training curves{which} (band: ± sd over seeds)"),
        x_label: "iteration".into(),
        y_label: "training-view PSNR (dB), moving mean".into(),
        ..Default::default()
    };
    for (ci, m) in ms.iter().enumerate() {
        let mut series: Vec<Vec<(f64, f64)>> = Vec::new();
        for r in rows
            .iter()
            .filter(|r| r.dataset == dataset && r.method == *m && r.psnr.is_some())
            .filter(|r| r.sweep_value == shown)
        {
            let Ok(log) = super::read_log(&out.join(&r.run_dir)) else {
                continue;
            };
            let psnr: Vec<f64> = log.iter().map(|x| x.1).collect();
            let sm = super::moving_mean(&psnr, log.len().div_ceil(50));
            series.push(log.iter().zip(&sm).map(|(x, s)| (x.0, *s)).collect());
        }
        let Some(len) = series.iter().map(|s| s.len()).min() else {
            continue;
        };
        let mut mean = Vec::new();
        let mut band = Vec::new();
        for i in 0..len {
            let v: Vec<f64> = series.iter().map(|s| s[i].1).collect();
            let (mu, sd, n) = mean_sd(&v);
            let sd = if n > 1 { sd } else { 0.0 };
            mean.push((series[0][i].0, mu));
            band.push((series[0][i].0, mu - sd, mu + sd));
        }
        p.bands.push(Band {
            points: super::thin(&band, 300),
            colour: ci,
        });
        p.lines.push(Line {
            label: format!("{} (n = {})", label(rows, m), series.len()),
            points: super::thin(&mean, 300),
        });
    }
    svg::figure(&[p])
}

/// Colour of a PSNR on the map's scale [lo, hi] (light yellow -> dark blue).
fn heat(v: f64, lo: f64, hi: f64) -> String {
    let t = if hi > lo {
        ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let a = [255.0, 247.0, 188.0];
    let b = [8.0, 64.0, 129.0];
    let c: Vec<u8> = (0..3)
        .map(|k| (a[k] + t * (b[k] - a[k])).round() as u8)
        .collect();
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// The stability map: one row per (dataset, method [at a condition value]), one column per
/// sweep value; each cell
/// shows the mean test PSNR over seeds, "×" when a seed diverged or failed, and a red frame
/// when a seed fell below `floor_db`.
pub fn stability_map(rows: &[Row], floor_db: Option<f64>) -> String {
    // A method at a condition's value is a row of its own (`METHOD @ axis=value`).
    let relabelled: Vec<Row> = rows
        .iter()
        .map(|r| match (&r.condition, &r.condition_value) {
            (Some(a), Some(v)) => Row {
                method: format!("{} @ {a}={v}", r.method),
                ..r.clone()
            },
            _ => r.clone(),
        })
        .collect();
    let rows = &relabelled[..];
    let ms = methods(rows);
    let ds = datasets(rows);
    let mut cols: Vec<Option<String>> = Vec::new();
    for r in rows {
        if !cols.contains(&r.sweep_value) {
            cols.push(r.sweep_value.clone());
        }
    }
    let flag = rows
        .iter()
        .find_map(|r| r.sweep_flag.clone())
        .unwrap_or_else(|| "setting".into());
    let all: Vec<f64> = rows.iter().filter_map(|r| r.psnr).collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (cw, ch, left, top) = (90.0, 34.0, 230.0, 84.0);
    let nrow = ds.len() * ms.len();
    let width = (left + cw * cols.len() as f64 + 30.0).max(640.0);
    let height = top + ch * nrow as f64 + 80.0;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="DejaVu Sans, Arial, sans-serif">
<rect width="100%" height="100%" fill="white"/>
<text x="{:.1}" y="22" font-size="15" font-weight="bold" text-anchor="middle">Stability: mean test PSNR (dB) over seeds</text>
<text x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle">{}</text>
"#,
        width / 2.0,
        left + cw * cols.len() as f64 / 2.0,
        top - 36.0,
        svg::escape(&flag)
    );
    for (j, c) in cols.iter().enumerate() {
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="12" text-anchor="middle">{}</text>"#,
            left + cw * (j as f64 + 0.5),
            top - 10.0,
            svg::escape(c.as_deref().unwrap_or("-"))
        );
    }
    let mut i = 0;
    for d in &ds {
        for m in &ms {
            let y = top + ch * i as f64;
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" font-size="12" text-anchor="end">{} / {}</text>"#,
                left - 8.0,
                y + ch / 2.0 + 4.0,
                svg::escape(d),
                svg::escape(m)
            );
            for (j, c) in cols.iter().enumerate() {
                let x = left + cw * j as f64;
                let rs: Vec<&Row> = rows
                    .iter()
                    .filter(|r| r.dataset == *d && r.method == *m && r.sweep_value == *c)
                    .collect();
                let ok: Vec<f64> = rs.iter().filter_map(|r| r.psnr).collect();
                let failed = rs.iter().filter(|r| r.status == "failed").count();
                let below = floor_db.map_or(0, |f| ok.iter().filter(|&&p| p < f).count());
                let (fill, label) = if ok.is_empty() {
                    ("#eeeeee".to_string(), "-".to_string())
                } else {
                    let m = mean_sd(&ok).0;
                    (heat(m, lo, hi), format!("{m:.1}"))
                };
                let dark = !ok.is_empty() && (mean_sd(&ok).0 - lo) > 0.6 * (hi - lo);
                let _ = writeln!(
                    s,
                    r##"<rect class="cell" x="{x:.1}" y="{y:.1}" width="{cw:.1}" height="{ch:.1}" fill="{fill}" stroke="{}" stroke-width="{}"><title>{} / {} / {}: {} of {} seeds finished, {failed} failed, {below} below the floor</title></rect>"##,
                    if below > 0 { "#d00000" } else { "#ffffff" },
                    if below > 0 { 3 } else { 1 },
                    svg::escape(d),
                    svg::escape(m),
                    svg::escape(c.as_deref().unwrap_or("-")),
                    ok.len(),
                    rs.len()
                );
                let _ = writeln!(
                    s,
                    r#"<text x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle" fill="{}">{}{}</text>"#,
                    x + cw / 2.0,
                    y + ch / 2.0 + 5.0,
                    if dark { "white" } else { "black" },
                    label,
                    if failed > 0 {
                        format!(" ×{failed}")
                    } else {
                        String::new()
                    }
                );
            }
            i += 1;
        }
    }
    let ly = top + ch * nrow as f64 + 28.0;
    let _ = writeln!(
        s,
        r##"<text x="20" y="{ly:.1}" font-size="12">×k: k seeds diverged or failed; red frame: a seed ended below {}.</text>
<text x="20" y="{:.1}" font-size="12">Colour: mean test PSNR from {lo:.1} dB (light) to {hi:.1} dB (dark); grey: no result.</text>"##,
        floor_db.map_or("the floor (none set)".to_string(), |f| format!("{f} dB")),
        ly + 18.0
    );
    s.push_str("</svg>\n");
    s
}

/// The charts of a reproduce folder: (file name, title, SVG), in report order.
pub fn charts(rows: &[Row], out: &Path, floor_db: Option<f64>) -> Vec<(String, String, String)> {
    let mut v = Vec::new();
    let sweep_flag = rows.iter().find_map(|r| r.sweep_flag.clone());
    for d in datasets(rows) {
        if !rows.iter().any(|r| r.dataset == d && r.psnr.is_some()) {
            continue;
        }
        v.push((
            format!("tradeoff_{d}.svg"),
            format!("{d}: speed against accuracy"),
            tradeoff(rows, &d),
        ));
        v.push((
            format!("gaussians_{d}.svg"),
            format!("{d}: PSNR against Gaussian count"),
            psnr_vs_count(rows, &d),
        ));
        v.push((
            format!("curves_{d}.svg"),
            format!("{d}: training curves"),
            curves(rows, &d, out),
        ));
    }
    if sweep_flag.is_some() || floor_db.is_some() {
        v.push((
            "stability.svg".into(),
            "Stability map".into(),
            stability_map(rows, floor_db),
        ));
    }
    v
}

/// Write the charts (and `more`, e.g. [`super::holds::charts`]) into `out/charts/` and
/// `out/report.html`; returns the chart paths.
pub fn write_report(
    rows: &[Row],
    out: &Path,
    tables: &Doc,
    floor_db: Option<f64>,
    more: Vec<(String, String, String)>,
) -> Result<Vec<std::path::PathBuf>> {
    let dir = out.join("charts");
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut cs = charts(rows, out, floor_db);
    cs.extend(more);
    let mut paths = Vec::new();
    let mut body = String::new();
    for (name, title, svg) in &cs {
        let p = dir.join(name);
        std::fs::write(&p, svg).map_err(|e| Error::io(&p, e))?;
        paths.push(p);
        let _ = writeln!(
            body,
            "<figure><figcaption>{}</figcaption>\n{}</figure>",
            svg::escape(title),
            svg
        );
    }
    let html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>unispine reproduce</title><style>\
         body{{font-family:DejaVu Sans,Arial,sans-serif;max-width:1150px;margin:1.5em auto;\
         padding:0 1em;color:#222;line-height:1.4}}\
         table{{border-collapse:collapse;margin:0.6em 0 1.2em;font-size:14px}}\
         td,th{{border:1px solid #bbb;padding:3px 8px;text-align:left}}\
         td.r,th.r{{text-align:right}}td.r{{white-space:nowrap}}th{{background:#f0f0f0}}\
         figure{{margin:1.5em 0;overflow-x:auto}}figcaption{{font-weight:bold;margin-bottom:0.3em}}\
         code{{background:#f4f4f4;padding:0 3px}}h2{{border-bottom:1px solid #ddd}}\
         </style></head><body>\n{}\n<h2>Charts</h2>\n{}</body></html>\n",
        tables.to_html(),
        body
    );
    let p = out.join("report.html");
    std::fs::write(&p, html).map_err(|e| Error::io(&p, e))?;
    Ok(paths)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn heat_runs_from_light_to_dark() {
        assert_eq!(heat(0.0, 0.0, 1.0), "#fff7bc");
        assert_eq!(heat(1.0, 0.0, 1.0), "#084081");
    }

    /// Check that `doc` is well-formed markup: tags nest, every `&` starts an entity, no `<`
    /// inside text or an attribute value; and that no element is named `script`.
    pub(crate) fn assert_well_formed(doc: &str) {
        let mut stack: Vec<String> = Vec::new();
        let b = doc.as_bytes();
        let mut i = 0;
        while i < b.len() {
            match b[i] {
                b'<' => {
                    let end = i + doc[i..].find('>').expect("unclosed tag");
                    let tag = &doc[i + 1..end];
                    assert!(!tag.contains('<'), "`<` inside a tag: {tag}");
                    let quotes = tag.matches('"').count();
                    assert!(quotes.is_multiple_of(2), "unbalanced quotes in {tag}");
                    if !(tag.starts_with('!') || tag.starts_with('?')) {
                        let name: String = tag
                            .trim_start_matches('/')
                            .chars()
                            .take_while(|c| c.is_ascii_alphanumeric())
                            .collect();
                        assert!(!name.eq_ignore_ascii_case("script"), "a script element");
                        let void = ["meta", "br", "hr", "img", "link", "input"];
                        if tag.starts_with('/') {
                            assert_eq!(stack.pop().as_deref(), Some(name.as_str()), "at {tag}");
                        } else if !tag.ends_with('/') && !void.contains(&name.as_str()) {
                            stack.push(name);
                        }
                    }
                    i = end + 1;
                }
                b'&' => {
                    let rest = &doc[i + 1..];
                    let ok = ["amp;", "lt;", "gt;", "quot;", "#39;", "#160;"]
                        .iter()
                        .any(|e| rest.starts_with(e));
                    assert!(ok, "a bare `&` at {}", &doc[i..(i + 12).min(doc.len())]);
                    i += 1;
                }
                _ => i += 1,
            }
        }
        assert!(stack.is_empty(), "unclosed elements {stack:?}");
    }

    #[test]
    fn names_with_markup_are_escaped_in_every_chart_and_the_report() {
        let evil = |k: &str| format!("<script>alert('{k}')</script>\"&x");
        let mut rows = Vec::new();
        for (i, seed) in [0u64, 1].iter().enumerate() {
            rows.push(Row {
                index: i,
                dataset: evil("d"),
                paper_dataset: Some(evil("p")),
                method: evil("m"),
                base: "unispine".into(),
                sweep_flag: Some(evil("f")),
                sweep_value: Some(evil("v")),
                seed: *seed,
                iters: 10,
                status: "done".into(),
                completed: true,
                psnr: Some(30.0 + i as f64),
                ssim: Some(0.9),
                train_time_s: Some(1.0),
                fps: Some(100.0),
                n_gaussians: Some(1000),
                curve: vec![(5, 20.0), (10, 30.0)],
                run_dir: evil("r"),
                error: Some(evil("e")),
                ..Default::default()
            });
        }
        let d = tempfile::tempdir().unwrap();
        let cs = charts(&rows, d.path(), Some(31.0));
        assert!(cs.iter().any(|c| c.0 == "stability.svg"));
        for (name, title, svg) in &cs {
            assert_well_formed(svg);
            assert!(!svg.contains("<script"), "{name}");
            assert!(!title.is_empty());
        }
        let mut doc = crate::doc::Doc::new();
        doc.heading(1, evil("h"));
        let mut t = crate::doc::Table::new(&[("a", false), ("b", true)]);
        t.row(vec![evil("c1"), evil("c2")]);
        doc.table(t);
        doc.list(vec![evil("l")]);
        let html = doc.to_html();
        assert_well_formed(&html);
        assert!(html.contains("&lt;script&gt;alert(&#39;c1&#39;)&lt;/script&gt;&quot;&amp;x"));
    }
}
