//! Verdicts on magnitude as well as sign: where the paper's own effect lies against our 95 %
//! interval of the paired effect, per dataset and pooled.
//!
//! The sign verdict ([`super::verdict`]) asks whether the effect is above the paper's threshold
//! (0 dB for accuracy claims). This module asks whether it is as large as the paper says: the
//! paper's effect for a claim on a paper dataset is the difference of the paper's own rows
//! (Table 2: PSNR(A) - PSNR(B) on that dataset; Table 1 claims use Table 1's UniSpine-GS row);
//! it is **inside** our interval, **above** it (our effect is smaller than the paper's) or
//! **below** it (ours is larger). Speed claims already test the paper's factor and get no
//! magnitude line.
//!
//! Per dataset, the paper effect is that of the paper dataset the plan dataset stands in for.
//! Pooled, it is the pair-weighted mean of the per-dataset paper effects, sum(n_k e_k) / sum(n_k):
//! the mean our pooled interval estimates if every dataset reproduced the paper's effect. It is
//! undefined (no magnitude line) when a dataset with pairs stands in for no paper dataset.

use serde::Serialize;

use super::aggregate::{self, Row};
use super::plan::Plan;
use super::verdict::{claims_for, evaluate, Claim, Measure, Verdict, Word, PAPER};
use crate::doc::{Doc, Table};

/// Where the paper's effect lies against our interval.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Place {
    /// lo <= paper <= hi: the magnitude is reproduced.
    Inside,
    /// paper > hi: our effect is smaller than the paper's.
    Above,
    /// paper < lo: our effect is larger than the paper's.
    Below,
    /// No paper effect for this claim and scope, or fewer than 2 pairs.
    NotTested,
}

impl Place {
    pub fn as_str(self) -> &'static str {
        match self {
            Place::Inside => "inside",
            Place::Above => "above",
            Place::Below => "below",
            Place::NotTested => "not tested",
        }
    }
}

/// The magnitude rule: the paper's effect against the interval [lo, hi] of n pairs.
pub fn place(paper: Option<f64>, lo: f64, hi: f64, n: usize) -> Place {
    match paper {
        Some(p) if p.is_finite() && n >= 2 && lo.is_finite() && hi.is_finite() => {
            if p > hi {
                Place::Above
            } else if p < lo {
                Place::Below
            } else {
                Place::Inside
            }
        }
        _ => Place::NotTested,
    }
}

/// The paper's row name for a plan method (`nerf-full` is the upstream NeRF configuration the
/// paper's `nerf` row ran).
fn paper_method(m: &str) -> &str {
    m.strip_suffix("-full").unwrap_or(m)
}

/// The paper's effect (dB) for an accuracy claim on a paper dataset: PSNR(A) - PSNR(B) from
/// the table that holds B's row (Table 1 rows compare with Table 1's UniSpine-GS row).
pub fn paper_effect(claim: &Claim, paper_dataset: &str) -> Option<f64> {
    if claim.measure != Measure::PsnrGain {
        return None;
    }
    let (a, b) = (paper_method(&claim.a), paper_method(&claim.b));
    let rb = PAPER
        .iter()
        .find(|r| r.dataset == paper_dataset && r.method == b)?;
    let a_t1 = format!("{a}-t1");
    let ra = PAPER.iter().find(|r| {
        r.table == rb.table
            && r.dataset == paper_dataset
            && (r.method == a || (rb.table == 1 && r.method == a_t1))
    })?;
    Some(ra.psnr - rb.psnr)
}

/// A claim's verdict on one scope (`pooled` or a plan dataset), with its magnitude.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scoped {
    /// `pooled`, or the plan dataset's name.
    pub scope: String,
    pub verdict: Verdict,
    /// The paper's effect this scope is compared with (dB), if any.
    pub paper_effect: Option<f64>,
    pub place: Place,
}

impl Scoped {
    /// The 95 % interval as a table cell, its ends written by `f` ("-" below two pairs).
    pub fn interval_cell(&self, f: impl Fn(f64) -> String) -> String {
        let v = &self.verdict;
        if v.n >= 2 {
            format!("[{}, {}]", f(v.lo), f(v.hi))
        } else {
            "-".into()
        }
    }

    /// The paper's effect as a table cell ("-" when the paper gives none here).
    pub fn paper_cell(&self) -> String {
        self.paper_effect
            .map(|e| format!("{e:+.2} dB"))
            .unwrap_or_else(|| "-".into())
    }

    pub fn new(scope: &str, verdict: Verdict, paper_effect: Option<f64>) -> Scoped {
        let place = place(paper_effect, verdict.lo, verdict.hi, verdict.n);
        Scoped {
            scope: scope.into(),
            verdict,
            paper_effect,
            place,
        }
    }

    /// The verdict in words, e.g. "sign reproduced, magnitude not (paper +8.21 dB is above the
    /// interval)".
    pub fn reading(&self) -> String {
        let sign = self.verdict.word;
        if self.paper_effect.is_none() || self.place == Place::NotTested {
            return format!("sign {}", sign.as_str());
        }
        let p = format!("{:+.2} dB", self.paper_effect.unwrap_or(f64::NAN));
        let where_ = format!("paper {p} is {} the interval", self.place.as_str());
        match (sign, self.place) {
            (Word::Reproduced, Place::Inside) => {
                format!("sign and magnitude reproduced ({where_})")
            }
            (Word::Reproduced, _) => format!("sign reproduced, magnitude not ({where_})"),
            (Word::Inconclusive, Place::Inside) => {
                format!("sign inconclusive, magnitude consistent ({where_})")
            }
            (w, Place::Inside) => format!("sign {}, magnitude consistent ({where_})", w.as_str()),
            (w, _) => format!("sign {}, magnitude not ({where_})", w.as_str()),
        }
    }
}

/// The pooled paper effect: the pair-weighted mean of per-dataset paper effects, given
/// (pairs, paper effect) per dataset; None when a dataset with pairs has no paper effect or no
/// dataset has pairs.
pub fn pooled_effect(per_dataset: &[(usize, Option<f64>)]) -> Option<f64> {
    let mut num = 0.0;
    let mut den = 0usize;
    for &(n, e) in per_dataset {
        if n == 0 {
            continue;
        }
        num += n as f64 * e?;
        den += n;
    }
    (den > 0).then(|| num / den as f64)
}

/// Every accuracy claim of the plan, pooled and then per plan dataset (plan order).
pub fn scoped(plan: &Plan, rows: &[Row]) -> Vec<Scoped> {
    let methods: Vec<String> = plan.methods.iter().map(|m| m.name.clone()).collect();
    claims_for(&methods)
        .iter()
        .filter(|c| c.measure == Measure::PsnrGain)
        .flat_map(|c| scopes(plan, c, rows))
        .collect()
}

/// A claim's verdicts on `rows`: pooled, then per plan dataset (plan order).
pub(super) fn scopes(plan: &Plan, claim: &Claim, rows: &[Row]) -> Vec<Scoped> {
    let per: Vec<Scoped> = plan
        .datasets
        .iter()
        .map(|d| {
            let sub: Vec<Row> = rows
                .iter()
                .filter(|r| r.dataset == d.name)
                .cloned()
                .collect();
            let e = d.paper.as_deref().and_then(|p| paper_effect(claim, p));
            Scoped::new(&d.name, evaluate(claim, &aggregate::observations(&sub)), e)
        })
        .collect();
    let weights: Vec<(usize, Option<f64>)> =
        per.iter().map(|s| (s.verdict.n, s.paper_effect)).collect();
    let mut out = vec![Scoped::new(
        "pooled",
        evaluate(claim, &aggregate::observations(rows)),
        pooled_effect(&weights),
    )];
    out.extend(per);
    out
}

/// The `tables.md` section: each accuracy claim, pooled and per dataset, its interval, the
/// paper's effect and the reading on sign and magnitude.
pub fn section(plan: &Plan, rows: &[Row]) -> Doc {
    let mut d = Doc::new();
    let sc = scoped(plan, rows);
    if sc.is_empty() {
        return d;
    }
    d.heading(2, "Verdicts on magnitude, per dataset and pooled");
    d.table(table(&sc, "mean difference", "paper effect"));
    d.para(
        "Paper effect: PSNR(A) - PSNR(B) of the paper's own rows for the paper dataset the \
         plan dataset stands in for (Table 1 claims use Table 1's UniSpine-GS row); pooled: the \
         per-dataset paper effects weighted by each dataset's pairs. Magnitude reproduced: the \
         paper's effect lies inside our 95 % interval; above: our effect is smaller than the \
         paper's; below: ours is larger.",
    );
    d
}

/// An effect in dB with its sign, `-` when not finite.
pub fn db(x: f64) -> String {
    if x.is_finite() {
        format!("{x:+.3} dB")
    } else {
        "-".into()
    }
}

/// The table of scoped verdicts: claim, scope, pairs, effect, interval, the paper's effect and
/// the reading (`effect` and `paper`: the titles of those two columns).
pub fn table(sc: &[Scoped], effect: &str, paper: &str) -> Table {
    let mut t = Table::new(&[
        ("claim", false),
        ("scope", false),
        ("pairs", true),
        (effect, true),
        ("95 % interval", false),
        (paper, true),
        ("reading", false),
    ]);
    for x in sc {
        let v = &x.verdict;
        t.row(vec![
            v.claim.text.clone(),
            x.scope.clone(),
            v.n.to_string(),
            db(v.mean),
            x.interval_cell(db),
            x.paper_cell(),
            x.reading(),
        ]);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::verdict::paired_interval;

    /// Student's t quantile t(0.975, df) computed independently of the table in `verdict`:
    /// bisection on the CDF, F(t) = 1/2 + c * integral_0^t (1 + x^2/df)^(-(df+1)/2) dx with
    /// c = Gamma((df+1)/2) / (sqrt(df pi) Gamma(df/2)) and Simpson's rule.
    fn t975_independent(df: usize) -> f64 {
        fn gamma_half(k: usize) -> f64 {
            // Gamma(k / 2) for integer k >= 1: Gamma(1/2) = sqrt(pi), Gamma(1) = 1, x Gamma(x).
            let (mut g, mut x) = if k.is_multiple_of(2) {
                (1.0, 1.0)
            } else {
                (std::f64::consts::PI.sqrt(), 0.5)
            };
            while x < k as f64 / 2.0 - 1e-9 {
                g *= x;
                x += 1.0;
            }
            g
        }
        let nu = df as f64;
        let c = gamma_half(df + 1) / ((nu * std::f64::consts::PI).sqrt() * gamma_half(df));
        let cdf = |t: f64| {
            let m = 4_000;
            let h = t / m as f64;
            let f = |x: f64| (1.0 + x * x / nu).powf(-(nu + 1.0) / 2.0);
            let mut s = f(0.0) + f(t);
            for i in 1..m {
                s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
            }
            0.5 + c * s * h / 3.0
        };
        let (mut lo, mut hi) = (0.0, 20.0);
        for _ in 0..45 {
            let mid = 0.5 * (lo + hi);
            if cdf(mid) < 0.975 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn the_independent_quantiles_agree_with_the_table() {
        // df = 2 in closed form: t / sqrt(2 + t^2) = 0.95 -> t = sqrt(1.805 / 0.0975).
        assert!((t975_independent(2) - (1.805f64 / 0.0975).sqrt()).abs() < 1e-6);
        // df = 1 (Cauchy): t = tan(0.475 pi).
        assert!((t975_independent(1) - (0.475 * std::f64::consts::PI).tan()).abs() < 1e-3);
        for df in 1..=30 {
            let t = t975_independent(df);
            assert!(
                (crate::reproduce::verdict::t975(df) - t).abs() < 1e-3,
                "df {df}: {t}"
            );
        }
    }

    fn claim_xg() -> Claim {
        claims_for(&[])
            .into_iter()
            .find(|c| c.a == "xgaussian" && c.b == "3dgs")
            .unwrap()
    }

    fn verdict_on(d: &[f64]) -> Verdict {
        let (mean, lo, hi, n) = paired_interval(d);
        Verdict {
            claim: claim_xg(),
            diffs: d.to_vec(),
            mean,
            lo,
            hi,
            n,
            threshold: 0.0,
            word: crate::reproduce::verdict::decide(lo, hi, n, 0.0),
        }
    }

    #[test]
    fn magnitude_inside_above_below_on_hand_computed_intervals() {
        // d = 0.4, 0.5, 0.6: mean 0.5, sd 0.1, se 0.1 / sqrt(3); half width t(0.975, 2) * se.
        let t2 = t975_independent(2);
        let half = t2 * 0.1 / 3f64.sqrt();
        assert!((half - 0.248_414).abs() < 1e-5, "{half}");
        let v = verdict_on(&[0.4, 0.5, 0.6]);
        assert!((v.lo - (0.5 - half)).abs() < 1e-3 && (v.hi - (0.5 + half)).abs() < 1e-3);
        assert_eq!(v.word, Word::Reproduced);
        // The paper's +8.21 dB lies above [0.25, 0.75].
        let s = Scoped::new("pooled", v.clone(), Some(8.21));
        assert_eq!(s.place, Place::Above);
        assert_eq!(
            s.reading(),
            "sign reproduced, magnitude not (paper +8.21 dB is above the interval)"
        );
        let s = Scoped::new("pooled", v.clone(), Some(0.5));
        assert_eq!(s.place, Place::Inside);
        assert_eq!(
            s.reading(),
            "sign and magnitude reproduced (paper +0.50 dB is inside the interval)"
        );
        let s = Scoped::new("pooled", v.clone(), Some(0.1));
        assert_eq!(s.place, Place::Below);
        assert!(s.reading().starts_with("sign reproduced, magnitude not"));
        // Edges: 0.5 - half + 0.001 is inside; 0.5 + half + 0.001 above.
        assert_eq!(
            place(Some(0.5 - half + 0.001), v.lo, v.hi, 3),
            Place::Inside
        );
        assert_eq!(place(Some(0.5 + half + 0.001), v.lo, v.hi, 3), Place::Above);
        assert_eq!(place(Some(0.5 - half - 0.001), v.lo, v.hi, 3), Place::Below);
        // d = -0.2, 0.1, 0.4, 0.3 (mean 0.15, sd = sqrt(0.21 / 3)): inconclusive sign, the
        // paper's +0.50 dB inside the interval [0.15 -+ t(3) * sqrt(0.07) / 2].
        let t3 = t975_independent(3);
        let half = t3 * (0.07f64).sqrt() / 2.0;
        let v = verdict_on(&[-0.2, 0.1, 0.4, 0.3]);
        assert!(
            (v.hi - (0.15 + half)).abs() < 1e-3,
            "{} {}",
            v.hi,
            0.15 + half
        );
        assert_eq!(v.word, Word::Inconclusive);
        let s = Scoped::new("ct", v.clone(), Some(0.50));
        assert_eq!(s.place, Place::Inside);
        assert_eq!(
            s.reading(),
            "sign inconclusive, magnitude consistent (paper +0.50 dB is inside the interval)"
        );
        let s = Scoped::new("ct", v, Some(0.91));
        assert_eq!(s.place, Place::Above, "hi = {}", 0.15 + half);
        // One pair or no paper effect: not tested, the sign alone.
        let one = verdict_on(&[1.0]);
        assert_eq!(place(Some(0.5), one.lo, one.hi, one.n), Place::NotTested);
        assert_eq!(Scoped::new("x", one, None).reading(), "sign inconclusive");
    }

    #[test]
    fn paper_effects_are_the_differences_of_the_paper_rows() {
        let c = claim_xg();
        assert!((paper_effect(&c, "CTSpine3D").unwrap() - (46.04 - 37.83)).abs() < 1e-12);
        assert!((paper_effect(&c, "FeSpine3D").unwrap() - (39.91 - 34.94)).abs() < 1e-12);
        assert_eq!(paper_effect(&c, "elsewhere"), None);
        let all = claims_for(&["naf".into(), "nerf-full".into(), "fdk".into()]);
        let spwm = all.iter().find(|c| c.b == "xgaussian").unwrap();
        assert!((paper_effect(spwm, "CTSpine3D").unwrap() - 0.50).abs() < 1e-9);
        assert!((paper_effect(spwm, "FeSpine3D").unwrap() - 0.91).abs() < 1e-9);
        // Table 1: UniSpine-GS's Table 1 row (40.35 dB on FeSpine3D, not Table 2's 40.82).
        let naf = all
            .iter()
            .find(|c| c.b == "naf" && c.measure == Measure::PsnrGain)
            .unwrap();
        assert!((paper_effect(naf, "FeSpine3D").unwrap() - (40.35 - 23.78)).abs() < 1e-9);
        let nerf = all.iter().find(|c| c.b == "nerf-full").unwrap();
        assert!((paper_effect(nerf, "CTSpine3D").unwrap() - (46.54 - 37.61)).abs() < 1e-9);
        let fdk = all.iter().find(|c| c.b == "fdk").unwrap();
        assert_eq!(paper_effect(fdk, "CTSpine3D"), None);
        let speed = all
            .iter()
            .find(|c| matches!(c.measure, Measure::TrainSpeedup(_)))
            .unwrap();
        assert_eq!(paper_effect(speed, "CTSpine3D"), None);
    }

    #[test]
    fn the_pooled_effect_weights_datasets_by_pairs() {
        // 3 CT pairs at 8.21 and 1 US pair at 4.97: (3 * 8.21 + 4.97) / 4.
        let e = pooled_effect(&[(3, Some(8.21)), (1, Some(4.97))]).unwrap();
        assert!((e - (3.0 * 8.21 + 4.97) / 4.0).abs() < 1e-12);
        assert_eq!(pooled_effect(&[(3, Some(8.21)), (0, None)]), Some(8.21));
        assert_eq!(pooled_effect(&[(3, Some(8.21)), (2, None)]), None);
        assert_eq!(pooled_effect(&[]), None);
    }

    #[test]
    fn the_interval_s_ends_are_inside_and_every_sign_word_reads_with_its_place() {
        // Both ends belong to the interval; non-finite ends or one pair test nothing.
        assert_eq!(place(Some(1.0), 1.0, 2.0, 2), Place::Inside);
        assert_eq!(place(Some(2.0), 1.0, 2.0, 2), Place::Inside);
        assert_eq!(place(Some(2.0), 1.0, 2.0, 1), Place::NotTested);
        assert_eq!(
            place(Some(1.5), f64::NEG_INFINITY, 2.0, 5),
            Place::NotTested
        );
        assert_eq!(place(Some(1.5), 1.0, f64::NAN, 5), Place::NotTested);
        assert_eq!(place(Some(f64::INFINITY), 1.0, 2.0, 5), Place::NotTested);
        assert_eq!(place(None, 1.0, 2.0, 5), Place::NotTested);
        // d = -0.6, -0.5, -0.4: an interval below 0, sign not reproduced.
        let mut v = verdict_on(&[-0.6, -0.5, -0.4]);
        assert_eq!(v.word, Word::NotReproduced);
        let s = Scoped::new("us", v.clone(), Some(-0.5));
        assert_eq!(
            s.reading(),
            "sign not reproduced, magnitude consistent (paper -0.50 dB is inside the interval)"
        );
        let s = Scoped::new("us", v.clone(), Some(-3.0));
        assert_eq!(
            s.reading(),
            "sign not reproduced, magnitude not (paper -3.00 dB is below the interval)"
        );
        // An inconclusive sign with the paper's effect outside the interval.
        v.word = Word::Inconclusive;
        let s = Scoped::new("us", v.clone(), Some(4.0));
        assert_eq!(
            s.reading(),
            "sign inconclusive, magnitude not (paper +4.00 dB is above the interval)"
        );
        // The table cells: the interval from two pairs on, the paper's effect or "-".
        assert_eq!(s.interval_cell(|x| format!("{x:.1}")), "[-0.7, -0.3]");
        assert_eq!(s.paper_cell(), "+4.00 dB");
        let two = Scoped::new("us", verdict_on(&[1.0, 2.0]), None);
        assert!(
            two.interval_cell(db).starts_with('['),
            "{}",
            two.interval_cell(db)
        );
        assert_eq!(two.paper_cell(), "-");
        let one = Scoped::new("us", verdict_on(&[1.0]), Some(1.0));
        assert_eq!(one.interval_cell(db), "-");
        assert_eq!(one.reading(), "sign inconclusive");
        assert_eq!(db(0.25), "+0.250 dB");
        assert_eq!(db(f64::NAN), "-");
        assert_eq!(db(f64::INFINITY), "-");
    }

    #[test]
    fn the_section_holds_each_accuracy_claim_pooled_and_per_dataset() {
        let plan = crate::reproduce::plan::tests::parse(
            "name = \"t\"\niters = 10\nseeds = [0, 1]\nmethods = [\"3dgs\", \"xgaussian\"]\n\
             [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n",
        )
        .unwrap();
        let row = |method: &str, seed: u64, psnr: f64| Row {
            dataset: "ph".into(),
            method: method.into(),
            seed,
            psnr: Some(psnr),
            ..Default::default()
        };
        // xgaussian - 3dgs: +1.0 and +2.0 dB.
        let rows = [
            row("3dgs", 0, 30.0),
            row("xgaussian", 0, 31.0),
            row("3dgs", 1, 30.0),
            row("xgaussian", 1, 32.0),
        ];
        let md = section(&plan, &rows).to_markdown();
        assert!(
            md.contains("## Verdicts on magnitude, per dataset and pooled"),
            "{md}"
        );
        let line = |scope: &str| {
            md.lines()
                .find(|l| {
                    l.contains("RIRF + ACUI beat 3DGS") && l.contains(&format!("| {scope} |"))
                })
                .unwrap_or_else(|| panic!("{scope}: {md}"))
                .to_string()
        };
        for scope in ["pooled", "ph"] {
            let l = line(scope);
            assert!(l.contains("| 2 | +1.500 dB |"), "{l}");
            // The plan dataset stands in for no paper dataset: no paper effect.
            assert!(l.ends_with("| - | sign inconclusive |"), "{l}");
        }
    }
}
