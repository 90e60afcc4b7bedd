//! Charts of "Where each claim holds" ([`crate::reproduce::holds`]): one figure per accuracy
//! claim, one panel per condition; the claim's pooled effect (dB) on y against the condition's
//! value on x (its number when every value is a number, else its position, each point labelled
//! with its value), the 95 % interval as a band, each pair's difference as a dot, and lines at
//! 0 dB and at the paper's effect.

use crate::reproduce::aggregate::Row;
use crate::reproduce::holds::{holds, Holds};
use crate::reproduce::plan::Plan;

use super::svg::{figure, Band, Dot, Line, Marker, Panel};

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
                figure(&panels),
            )
        })
        .collect()
}
