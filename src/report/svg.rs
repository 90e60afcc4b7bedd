//! A minimal SVG plot writer (axes, ticks, polylines, labelled markers, legend) so that charts
//! need no font files and no system libraries. Coordinates are data units; each panel maps them
//! linearly (or log10 on the y axis) into its box.
//!
//! Over 600 lines with its tests (the writer itself is about 500): the tests draw whole
//! figures and read positions back from the SVG text.

use std::fmt::Write as _;

/// Colours for series, in order (colour-blind-safe Okabe-Ito palette).
pub const PALETTE: [&str; 8] = [
    "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000",
];

/// One line series.
#[derive(Clone, Debug)]
pub struct Line {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// One labelled marker.
#[derive(Clone, Debug)]
pub struct Marker {
    pub label: String,
    pub x: f64,
    pub y: f64,
    /// Index into [`PALETTE`] (modulo its length).
    pub colour: usize,
}

/// A shaded band between two curves over the same x values (e.g. mean +- sd over seeds).
#[derive(Clone, Debug)]
pub struct Band {
    /// (x, low, high) triples.
    pub points: Vec<(f64, f64, f64)>,
    /// Index into [`PALETTE`].
    pub colour: usize,
}

/// Error bars around a point: x and y ranges (equal to the centre for none).
#[derive(Clone, Debug)]
pub struct ErrorBar {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub colour: usize,
}

/// A small unlabelled dot (e.g. one seed's result beside the labelled mean).
#[derive(Clone, Debug)]
pub struct Dot {
    pub x: f64,
    pub y: f64,
    pub colour: usize,
}

/// One panel: title, axis labels, lines and markers.
#[derive(Clone, Debug, Default)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_y: bool,
    /// log10 x axis (non-positive x values are skipped).
    pub log_x: bool,
    /// Ticks only at whole numbers (an axis of categories numbered 0, 1, ...).
    pub x_whole: bool,
    pub lines: Vec<Line>,
    pub markers: Vec<Marker>,
    pub bands: Vec<Band>,
    pub error_bars: Vec<ErrorBar>,
    pub dots: Vec<Dot>,
}

const PANEL_W: f64 = 520.0;
const PANEL_H: f64 = 380.0;
const MARGIN_L: f64 = 70.0;
const MARGIN_R: f64 = 20.0;
const MARGIN_T: f64 = 36.0;
const MARGIN_B: f64 = 56.0;

// The one escaping helper every report writer uses (`&`, `<`, `>`, both quotes).
pub use crate::doc::escape;

/// "Nice" tick positions covering [lo, hi]: steps of 1, 2 or 5 times a power of ten.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        // Three significant digits, trailing zeros dropped: neighbouring ticks stay distinct.
        let s = format!("{v:.2e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
    } else if (v - v.round()).abs() < 1e-9 * a.max(1.0) {
        format!("{}", v.round() as i64)
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Data range of a panel, padded by 5 % (log y: in decades).
fn range(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    if hi - lo < 1e-12 * lo.abs().max(1.0) {
        let d = 0.5 * lo.abs().max(1.0);
        return Some((lo - d, hi + d));
    }
    let pad = 0.05 * (hi - lo);
    Some((lo - pad, hi + pad))
}

impl Panel {
    fn x_value(&self, x: f64) -> f64 {
        if self.log_x {
            if x > 0.0 {
                x.log10()
            } else {
                f64::NAN
            }
        } else {
            x
        }
    }

    fn y_value(&self, y: f64) -> f64 {
        if self.log_y {
            if y > 0.0 {
                y.log10()
            } else {
                f64::NAN
            }
        } else {
            y
        }
    }

    /// Data ranges (y in log10 when `log_y`); None when the panel holds no finite point.
    pub fn ranges(&self) -> Option<((f64, f64), (f64, f64))> {
        let xs = self
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.0))
            .chain(self.markers.iter().map(|m| m.x))
            .chain(self.bands.iter().flat_map(|b| b.points.iter().map(|p| p.0)))
            .chain(self.error_bars.iter().flat_map(|e| [e.x.0, e.x.1]))
            .chain(self.dots.iter().map(|d| d.x))
            .map(|x| self.x_value(x));
        let ys = self
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.1))
            .chain(self.markers.iter().map(|m| m.y))
            .chain(
                self.bands
                    .iter()
                    .flat_map(|b| b.points.iter().flat_map(|p| [p.1, p.2])),
            )
            .chain(self.error_bars.iter().flat_map(|e| [e.y.0, e.y.1]))
            .chain(self.dots.iter().map(|d| d.y))
            .map(|y| self.y_value(y));
        Some((range(xs)?, range(ys)?))
    }

    /// Append the panel's SVG, its box's top-left corner at (ox, oy).
    fn draw(&self, out: &mut String, ox: f64, oy: f64) {
        let (x0, y0) = (ox + MARGIN_L, oy + MARGIN_T);
        let (w, h) = (PANEL_W - MARGIN_L - MARGIN_R, PANEL_H - MARGIN_T - MARGIN_B);
        let _ = writeln!(
            out,
            r#"<text x="{:.1}" y="{:.1}" font-size="15" text-anchor="middle" font-weight="bold">{}</text>"#,
            x0 + w / 2.0,
            oy + 22.0,
            escape(&self.title)
        );
        let _ = writeln!(
            out,
            r##"<rect x="{x0:.1}" y="{y0:.1}" width="{w:.1}" height="{h:.1}" fill="none" stroke="#444"/>"##
        );
        let Some(((xlo, xhi), (ylo, yhi))) = self.ranges() else {
            let _ = writeln!(
                out,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">no data</text>"#,
                x0 + w / 2.0,
                y0 + h / 2.0
            );
            return;
        };
        let px = |x: f64| x0 + (x - xlo) / (xhi - xlo) * w;
        let py = |y: f64| y0 + h - (y - ylo) / (yhi - ylo) * h;
        let xticks = if self.log_x {
            let t: Vec<f64> = (xlo.ceil() as i64..=xhi.floor() as i64)
                .map(|k| k as f64)
                .collect();
            if t.len() >= 2 {
                t
            } else {
                ticks(xlo, xhi, 5)
            }
        } else if self.x_whole {
            (xlo.ceil() as i64..=xhi.floor() as i64)
                .map(|k| k as f64)
                .collect()
        } else {
            ticks(xlo, xhi, 6)
        };
        for t in xticks {
            let _ = writeln!(
                out,
                r##"<line x1="{0:.1}" y1="{1:.1}" x2="{0:.1}" y2="{2:.1}" stroke="#ddd"/><text x="{0:.1}" y="{3:.1}" font-size="12" text-anchor="middle">{4}</text>"##,
                px(t),
                y0,
                y0 + h,
                y0 + h + 16.0,
                if self.log_x {
                    fmt_tick(10f64.powf(t))
                } else {
                    fmt_tick(t)
                }
            );
        }
        let yticks = if self.log_y {
            let t: Vec<f64> = (ylo.ceil() as i64..=yhi.floor() as i64)
                .map(|k| k as f64)
                .collect();
            if t.len() >= 2 {
                t
            } else {
                ticks(ylo, yhi, 5)
            }
        } else {
            ticks(ylo, yhi, 6)
        };
        for t in yticks {
            let label = if self.log_y {
                fmt_tick(10f64.powf(t))
            } else {
                fmt_tick(t)
            };
            let _ = writeln!(
                out,
                r##"<line x1="{0:.1}" y1="{1:.1}" x2="{2:.1}" y2="{1:.1}" stroke="#ddd"/><text x="{3:.1}" y="{4:.1}" font-size="12" text-anchor="end">{5}</text>"##,
                x0,
                py(t),
                x0 + w,
                x0 - 6.0,
                py(t) + 4.0,
                label
            );
        }
        let _ = writeln!(
            out,
            r#"<text x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle">{}</text>"#,
            x0 + w / 2.0,
            y0 + h + 38.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            out,
            r#"<text x="{0:.1}" y="{1:.1}" font-size="13" text-anchor="middle" transform="rotate(-90 {0:.1} {1:.1})">{2}</text>"#,
            ox + 18.0,
            y0 + h / 2.0,
            escape(&self.y_label)
        );
        let pxv = |x: f64| px(self.x_value(x));
        for b in &self.bands {
            let c = PALETTE[b.colour % PALETTE.len()];
            let ok: Vec<(f64, f64, f64)> = b
                .points
                .iter()
                .map(|&(x, l, u)| (self.x_value(x), self.y_value(l), self.y_value(u)))
                .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
                .collect();
            let mut pts = String::new();
            for &(x, l, _) in &ok {
                let _ = write!(pts, "{:.2},{:.2} ", px(x), py(l));
            }
            for &(x, _, u) in ok.iter().rev() {
                let _ = write!(pts, "{:.2},{:.2} ", px(x), py(u));
            }
            let _ = writeln!(
                out,
                r#"<polygon class="band" points="{}" fill="{c}" fill-opacity="0.18" stroke="none"/>"#,
                pts.trim_end()
            );
        }
        for e in &self.error_bars {
            let c = PALETTE[e.colour % PALETTE.len()];
            let (xa, xb) = (pxv(e.x.0), pxv(e.x.1));
            let (ya, yb) = (py(self.y_value(e.y.0)), py(self.y_value(e.y.1)));
            let (xm, ym) = ((xa + xb) / 2.0, (ya + yb) / 2.0);
            if [xa, xb, ya, yb].iter().all(|v| v.is_finite()) {
                let _ = writeln!(
                    out,
                    r#"<path class="errorbar" d="M{xa:.2},{ym:.2}H{xb:.2}M{xm:.2},{ya:.2}V{yb:.2}" stroke="{c}" stroke-width="1.5"/>"#
                );
            }
        }
        for d in &self.dots {
            let (x, y) = (pxv(d.x), py(self.y_value(d.y)));
            if x.is_finite() && y.is_finite() {
                let c = PALETTE[d.colour % PALETTE.len()];
                let _ = writeln!(
                    out,
                    r#"<circle cx="{x:.2}" cy="{y:.2}" r="2.5" fill="none" stroke="{c}"/>"#
                );
            }
        }
        for (i, l) in self.lines.iter().enumerate() {
            let c = PALETTE[i % PALETTE.len()];
            let mut pts = String::new();
            for &(x, y) in &l.points {
                let x = self.x_value(x);
                let yv = self.y_value(y);
                if x.is_finite() && yv.is_finite() {
                    let _ = write!(pts, "{:.2},{:.2} ", px(x), py(yv));
                }
            }
            let _ = writeln!(
                out,
                r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="1.5"><title>{}</title></polyline>"#,
                pts.trim_end(),
                escape(&l.label)
            );
            // Sparse series (a few evaluation points) also get a dot per point.
            if l.points.len() < 50 {
                for &(x, y) in &l.points {
                    let x = self.x_value(x);
                    let yv = self.y_value(y);
                    if x.is_finite() && yv.is_finite() {
                        let _ = writeln!(
                            out,
                            r#"<circle cx="{:.2}" cy="{:.2}" r="3" fill="{c}"/>"#,
                            px(x),
                            py(yv)
                        );
                    }
                }
            }
        }
        // Labels: on the side with room (right of the marker in the left half, else left;
        // above it in the lower half, else below), then moved down or up in steps of one text
        // line until the label's box overlaps no label placed before it (close points, e.g.
        // two methods with nearly the same PSNR and fps); a moved label gets a leader line.
        let mut placed: Vec<[f64; 4]> = Vec::new();
        for m in &self.markers {
            let yv = self.y_value(m.y);
            let mx = self.x_value(m.x);
            if !(mx.is_finite() && yv.is_finite()) {
                continue;
            }
            let c = PALETTE[m.colour % PALETTE.len()];
            let _ = writeln!(
                out,
                r#"<circle class="marker" cx="{:.2}" cy="{:.2}" r="5" fill="{c}"><title>{}</title></circle>"#,
                px(mx),
                py(yv),
                escape(&m.label),
            );
            let (lx, anchor) = if px(mx) < x0 + w / 2.0 {
                (px(mx) + 7.0, "start")
            } else {
                (px(mx) - 7.0, "end")
            };
            let ly0 = if py(yv) > y0 + h / 2.0 {
                py(yv) - 7.0
            } else {
                py(yv) + 15.0
            };
            let tw = LABEL_CHAR_W * m.label.chars().count() as f64;
            let bx = |ly: f64| -> [f64; 4] {
                let x = if anchor == "start" { lx } else { lx - tw };
                [x, ly - LABEL_H + 2.0, x + tw, ly + 2.0]
            };
            let hits = |b: [f64; 4]| {
                placed
                    .iter()
                    .any(|p| b[0] < p[2] && p[0] < b[2] && b[1] < p[3] && p[1] < b[3])
            };
            let mut ly = ly0;
            for k in 1..=2 * MAX_LABEL_MOVES {
                if !hits(bx(ly)) {
                    break;
                }
                // 1, -1, 2, -2, ... lines away from the first place.
                let step = k.div_ceil(2) as f64 * if k % 2 == 1 { 1.0 } else { -1.0 };
                ly = ly0 + step * LABEL_H;
            }
            placed.push(bx(ly));
            if ly != ly0 {
                let _ = writeln!(
                    out,
                    r##"<line x1="{:.1}" y1="{:.1}" x2="{lx:.1}" y2="{:.1}" stroke="#999" stroke-width="0.8"/>"##,
                    px(mx),
                    py(yv),
                    ly - LABEL_H / 2.0 + 2.0
                );
            }
            let _ = writeln!(
                out,
                r#"<text class="marker-label" x="{lx:.1}" y="{ly:.1}" font-size="11" text-anchor="{anchor}">{}</text>"#,
                escape(&m.label)
            );
        }
    }
}

/// Approximate width of one character of an 11 px marker label, and the height of its line.
const LABEL_CHAR_W: f64 = 6.6;
const LABEL_H: f64 = 13.0;
/// Lines a marker label may move down (or up) to avoid another.
const MAX_LABEL_MOVES: usize = 6;

/// Height of the shared legend strip under the panels.
const LEGEND_H: f64 = 28.0;

/// A figure of panels side by side, as a standalone SVG document. Line series are matched
/// across panels by position (series i has colour i everywhere); their labels, taken from the
/// panel with the most series, form one legend strip under the panels.
pub fn figure(panels: &[Panel]) -> String {
    figure_rows(panels, panels.len())
}

/// [`figure`] with at most `cols` panels per row (rows top to bottom), so a figure of many
/// panels stays readable at a page's width.
pub fn figure_rows(panels: &[Panel], cols: usize) -> String {
    let cols = cols.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(cols).max(1);
    let width = PANEL_W * cols as f64;
    let legend: Vec<&str> = panels
        .iter()
        .max_by_key(|p| p.lines.len())
        .map(|p| p.lines.iter().map(|l| l.label.as_str()).collect())
        .unwrap_or_default();
    let height = PANEL_H * rows as f64 + if legend.is_empty() { 0.0 } else { LEGEND_H };
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="DejaVu Sans, Arial, sans-serif">
<rect width="100%" height="100%" fill="white"/>
"#
    );
    for (i, p) in panels.iter().enumerate() {
        p.draw(
            &mut s,
            PANEL_W * (i % cols) as f64,
            PANEL_H * (i / cols) as f64,
        );
    }
    let mut x = MARGIN_L;
    let y = PANEL_H * rows as f64 + 12.0;
    for (i, label) in legend.iter().enumerate() {
        let c = PALETTE[i % PALETTE.len()];
        let _ = writeln!(
            s,
            r#"<line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{c}" stroke-width="3"/><text x="{:.1}" y="{:.1}" font-size="12">{}</text>"#,
            x + 20.0,
            x + 26.0,
            y + 4.0,
            escape(label)
        );
        x += 40.0 + 7.5 * label.chars().count() as f64;
    }
    s.push_str("</svg>\n");
    s
}

/// The centres of the labelled markers of a figure written by [`figure`], in SVG coordinates
/// (y grows downwards), in drawing order (panel by panel). For tests, and for tools that read
/// our charts back.
pub fn marker_centres(svg: &str) -> Vec<(f64, f64)> {
    let attr = |line: &str, key: &str| -> Option<f64> {
        let i = line.find(key)? + key.len();
        line[i..].split('"').next()?.parse().ok()
    };
    svg.lines()
        .filter(|l| l.contains(r#"class="marker""#))
        .filter_map(|l| Some((attr(l, "cx=\"")?, attr(l, "cy=\"")?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_of_close_markers_do_not_overlap() {
        let mk = |label: &str, x: f64, y: f64| Marker {
            label: label.into(),
            x,
            y,
            colour: 0,
        };
        let p = Panel {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            markers: vec![
                mk("xgaussian", 10.0, 42.24),
                mk("unispine", 10.2, 42.26),
                mk("3dgs", 10.1, 42.25),
                mk("far", 90.0, 30.0),
            ],
            ..Default::default()
        };
        let svg = figure(&[p]);
        let boxes: Vec<[f64; 4]> = svg
            .lines()
            .filter(|l| l.contains("marker-label"))
            .map(|l| {
                let a = |k: &str| -> f64 {
                    let i = l.find(k).unwrap() + k.len();
                    l[i..].split('"').next().unwrap().parse().unwrap()
                };
                let text = l.split('>').nth(1).unwrap().split('<').next().unwrap();
                let tw = LABEL_CHAR_W * text.chars().count() as f64;
                let x = if l.contains("\"end\"") {
                    a("x=\"") - tw
                } else {
                    a("x=\"")
                };
                let y = a("y=\"");
                [x, y - LABEL_H + 2.0, x + tw, y + 2.0]
            })
            .collect();
        assert_eq!(boxes.len(), 4);
        for i in 0..4 {
            for j in 0..i {
                let (a, b) = (boxes[i], boxes[j]);
                let overlap = a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
                assert!(!overlap, "labels {i} and {j} overlap: {a:?} {b:?}");
            }
        }
    }

    #[test]
    fn panels_wrap_into_rows() {
        let p = |t: &str| Panel {
            title: t.into(),
            lines: vec![Line {
                label: "l".into(),
                points: vec![(0.0, 0.0), (1.0, 1.0)],
            }],
            ..Default::default()
        };
        let s = figure_rows(&[p("A"), p("B"), p("C")], 2);
        let (w, h) = (2.0 * PANEL_W, 2.0 * PANEL_H + LEGEND_H);
        assert!(
            s.contains(&format!(r#"width="{w:.0}" height="{h:.0}""#)),
            "{s}"
        );
        // Titles: A and B side by side in the first row, C under A.
        let title = |t: &str| -> (f64, f64) {
            let l = s
                .lines()
                .find(|l| l.ends_with(&format!(">{t}</text>")))
                .unwrap();
            let num = |k: &str| -> f64 {
                let i = l.find(k).unwrap() + k.len();
                l[i..].split('"').next().unwrap().parse().unwrap()
            };
            (num(" x=\""), num(" y=\""))
        };
        let (a, b, c) = (title("A"), title("B"), title("C"));
        assert_eq!(a.1, b.1);
        assert_eq!(b.0 - a.0, PANEL_W);
        assert_eq!(c.0, a.0);
        assert_eq!(c.1 - a.1, PANEL_H);
        // One row: `figure`.
        assert!(figure(&[p("A"), p("B"), p("C")]).contains(&format!(
            r#"width="{:.0}" height="{:.0}""#,
            3.0 * PANEL_W,
            PANEL_H + LEGEND_H
        )));
    }

    #[test]
    fn a_category_axis_has_whole_ticks_only() {
        let x_ticks = |whole: bool| -> Vec<String> {
            let p = Panel {
                lines: vec![Line {
                    label: "l".into(),
                    points: vec![(0.0, 0.0), (1.0, 10.0)],
                }],
                x_whole: whole,
                ..Default::default()
            };
            figure(&[p])
                .lines()
                .filter(|l| l.starts_with("<line") && l.contains("text-anchor=\"middle\""))
                .filter_map(|l| {
                    let t = l.rsplit_once("\">")?.1;
                    Some(t.trim_end_matches("</text>").to_string())
                })
                .collect()
        };
        assert_eq!(x_ticks(true), ["0", "1"]);
        assert!(x_ticks(false).contains(&"0.2".to_string()));
    }

    #[test]
    fn small_and_large_ticks_keep_their_digits() {
        assert_eq!(fmt_tick(1.5e-4), "1.5e-4");
        assert_eq!(fmt_tick(2e-4), "2e-4");
        assert_eq!(fmt_tick(-1.25e-5), "-1.25e-5");
        assert_eq!(fmt_tick(3e6), "3e6");
        assert_eq!(fmt_tick(0.05), "0.05");
        assert_eq!(fmt_tick(12.0), "12");
    }

    #[test]
    fn ticks_are_nice_and_inside() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(33.7, 38.9, 6);
        assert_eq!(t, vec![34.0, 35.0, 36.0, 37.0, 38.0]);
        for w in t.windows(2) {
            assert!(w[1] > w[0]);
        }
    }

    #[test]
    fn markers_are_placed_by_value_and_text_is_escaped() {
        let p = Panel {
            title: "a<b & c".into(),
            markers: vec![
                Marker {
                    label: "lo".into(),
                    x: 1.0,
                    y: 10.0,
                    colour: 0,
                },
                Marker {
                    label: "hi".into(),
                    x: 3.0,
                    y: 30.0,
                    colour: 1,
                },
            ],
            ..Default::default()
        };
        let svg = figure(&[p]);
        assert!(svg.contains("a&lt;b &amp; c"));
        let circles = marker_centres(&svg);
        assert_eq!(circles.len(), 2);
        // larger x to the right, larger y higher up (smaller SVG y)
        assert!(circles[1].0 > circles[0].0);
        assert!(circles[1].1 < circles[0].1);
    }

    #[test]
    fn log_axis_skips_non_positive_values_and_empty_panel_says_so() {
        let p = Panel {
            log_y: true,
            lines: vec![Line {
                label: "l".into(),
                points: vec![(0.0, 1.0), (1.0, 0.0), (2.0, 100.0)],
            }],
            ..Default::default()
        };
        let ((_, _), (ylo, yhi)) = p.ranges().unwrap();
        assert!(ylo < 0.0 && yhi > 2.0 && yhi < 2.5, "{ylo} {yhi}");
        let svg = figure(&[p]);
        let poly = svg.lines().find(|l| l.starts_with("<polyline")).unwrap();
        let n = poly
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        assert_eq!(n.split_whitespace().count(), 2);
        assert!(figure(&[Panel::default()]).contains("no data"));
    }
}
