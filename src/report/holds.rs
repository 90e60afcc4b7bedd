//! Charts of "Where each claim holds" ([`crate::reproduce::holds`]): one figure per accuracy
//! claim, one panel per condition; the claim's pooled effect (dB) on y against the condition's
//! value on x (its number when every value is a number, else its position, each point labelled
//! with its value), the 95 % interval as a band, each pair's difference as a dot, and lines at
//! 0 dB and at the paper's effect.

use crate::reproduce::aggregate::Row;
use crate::reproduce::holds::{holds, Holds};
use crate::reproduce::plan::Plan;

use super::svg::{figure_rows, Band, Dot, Line, Marker, Panel};

/// Panels per row: two fit the report's page width.
const COLS: usize = 2;

/// One panel: the points of one claim on one axis.
fn panel(axis: &str, pts: &[&Holds]) -> Panel {
    let numeric: Option<Vec<f64>> = pts
        .iter()
        .map(|h| h.value.parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect();
    let xs: Vec<f64> = match &numeric {
        Some(v) => v.clone(),
        None => (0..pts.len()).map(|i| i as f64).collect(),
    };
    let x_label = match &numeric {
        Some(_) => format!("{axis} (base: {})", pts.first().map_or("", |h| &h.value)),
        None => format!(
            "{axis}: {}",
            pts.iter()
                .enumerate()
                .map(|(i, h)| format!("{i} = {}", h.value))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut mean = Vec::new();
    let mut band = Vec::new();
    let mut dots = Vec::new();
    let mut markers = Vec::new();
    let mut paper = Vec::new();
    for (h, &x) in pts.iter().zip(&xs) {
        let Some(p) = h.scopes.first() else { continue };
        let v = &p.verdict;
        if v.mean.is_finite() {
            mean.push((x, v.mean));
            markers.push(Marker {
                label: if numeric.is_some() {
                    String::new()
                } else {
                    h.value.clone()
                },
                x,
                y: v.mean,
                colour: 0,
            });
        }
        if v.n >= 2 && v.lo.is_finite() && v.hi.is_finite() {
            band.push((x, v.lo, v.hi));
        }
        dots.extend(v.diffs.iter().map(|&d| Dot { x, y: d, colour: 0 }));
        if let Some(e) = p.paper_effect {
            paper.push((x, e));
        }
    }
    let (xlo, xhi) = xs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, &x| {
        (a.0.min(x), a.1.max(x))
    });
    let mut lines = vec![
        Line {
            label: "effect, mean over pairs (band: 95 % interval, dots: pairs)".into(),
            points: mean,
        },
        Line {
            label: "0 dB".into(),
            points: if xlo <= xhi {
                vec![(xlo, 0.0), (xhi, 0.0)]
            } else {
                vec![]
            },
        },
    ];
    if !paper.is_empty() {
        lines.push(Line {
            label: "paper's effect".into(),
            points: paper,
        });
    }
    Panel {
        title: axis.to_string(),
        x_label,
        y_label: "PSNR(A) - PSNR(B), dB".into(),
        lines,
        markers,
        bands: if band.is_empty() {
            vec![]
        } else {
            vec![Band {
                points: band,
                colour: 0,
            }]
        },
        dots,
        x_whole: numeric.is_none(),
        ..Default::default()
    }
}

/// The charts: (file name `holds-N.svg`, title, SVG), one per accuracy claim with conditions.
pub fn charts(plan: &Plan, rows: &[Row]) -> Vec<(String, String, String)> {
    let h = holds(plan, rows);
    let mut claims: Vec<&str> = Vec::new();
    for x in &h {
        if !claims.contains(&x.claim.text.as_str()) {
            claims.push(&x.claim.text);
        }
    }
    claims
        .iter()
        .enumerate()
        .map(|(i, text)| {
            let of: Vec<&Holds> = h.iter().filter(|x| x.claim.text == *text).collect();
            let mut axes: Vec<&str> = Vec::new();
            for x in &of {
                if !axes.contains(&x.axis.as_str()) {
                    axes.push(&x.axis);
                }
            }
            let panels: Vec<Panel> = axes
                .iter()
                .map(|a| {
                    let pts: Vec<&Holds> = of.iter().copied().filter(|x| x.axis == *a).collect();
                    panel(a, &pts)
                })
                .collect();
            (
                format!("holds-{}.svg", i + 1),
                format!("Where it holds: {text} (pooled over datasets)"),
                figure_rows(&panels, COLS),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::reproduce::tests::assert_well_formed;
    use crate::reproduce::holds::tests::{plan, rows};
    use crate::reproduce::magnitude::Scoped;
    use crate::reproduce::verdict::{evaluate, Claim, Measure, Obs};

    #[test]
    fn one_chart_per_claim_one_panel_per_axis_well_formed() {
        let cs = charts(&plan(), &rows());
        // Claims with both methods in the plan: RIRF + ACUI over 3DGS only.
        assert_eq!(cs.len(), 1);
        let (name, title, svg) = &cs[0];
        assert_eq!(name, "holds-1.svg");
        assert!(title.contains("RIRF + ACUI beat 3DGS"));
        assert_well_formed(svg);
        // Two panels (pose-noise numeric on x, init categorical with labelled points).
        assert!(svg.contains(">pose-noise</text>") && svg.contains(">init</text>"));
        assert!(svg.contains("0 = default, 1 = acui"));
        // A band per panel and a dot per pair (pose-noise: 3 values x 3 pairs; init: 2 x 3).
        assert_eq!(svg.matches("class=\"band\"").count(), 2);
        assert_eq!(svg.matches("r=\"2.5\" fill=\"none\"").count(), 9 + 6);
    }

    #[test]
    fn text_in_the_chart_is_escaped() {
        let evil = "<script>alert('x')</script>\"&";
        let claim = Claim {
            text: evil.into(),
            a: "a".into(),
            b: "b".into(),
            measure: Measure::PsnrGain,
            dataset: None,
        };
        let obs: Vec<Obs> = (0..3)
            .flat_map(|s| {
                [("a", 31.0 + s as f64), ("b", 30.0)].map(|(m, p)| Obs {
                    key: format!("d/{s}/"),
                    paper_dataset: None,
                    method: m.into(),
                    psnr: p,
                    train_time_s: 1.0,
                    fps: 1.0,
                })
            })
            .collect();
        let h: Vec<Holds> = [evil, "v2"]
            .iter()
            .enumerate()
            .map(|(i, v)| Holds {
                claim: claim.clone(),
                axis: evil.into(),
                value: v.to_string(),
                is_base: i == 0,
                scopes: vec![Scoped::new("pooled", evaluate(&claim, &obs), Some(2.0))],
            })
            .collect();
        let svg = figure_rows(&[panel(evil, &h.iter().collect::<Vec<_>>())], COLS);
        assert_well_formed(&svg);
        assert!(!svg.contains("<script"));
        assert!(svg.contains("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;&quot;&amp;"));
    }
}
