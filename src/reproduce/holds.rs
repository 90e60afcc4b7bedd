//! "Where each claim holds": each accuracy claim at every value of every condition of a plan
//! ([`super::plan::conditions`]), pooled over the plan's datasets and per dataset, with the
//! paired effect, its 95 % interval, the sign verdict ([`super::verdict`]) and the magnitude
//! verdict ([`super::magnitude`]).
//!
//! At a condition's value the claim pairs the cells of that value for the methods the condition
//! acts on with the base cells of the methods it does not act on (a claim "RIRF + ACUI beat
//! 3DGS" at `init = unit-cube` acting on `3dgs` pairs X-Gaussian's base cells with 3DGS's
//! unit-cube cells). A condition acting on neither method of a claim is left out of that claim.

use serde::Serialize;

use super::aggregate::Row;
use super::magnitude::{db, scopes, Scoped};
use super::plan::conditions::Condition;
use super::plan::Plan;
use super::verdict::{claims_for, Claim, Measure};
use crate::doc::{Doc, Table};

/// One claim at one condition value, pooled and per dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Holds {
    pub claim: Claim,
    pub axis: String,
    /// The value's label (the base's: [`Condition::base_label`]).
    pub value: String,
    pub is_base: bool,
    /// `pooled` first, then each plan dataset in plan order.
    pub scopes: Vec<Scoped>,
}

/// The rows a claim sees at condition `c` (index `ci`) and value `vi` (None: the base): the
/// cells at that value for the methods `c` acts on, the base cells of the others; returned at
/// the base point (their condition cleared) so that they pair.
pub fn rows_at(rows: &[Row], c: &Condition, vi: Option<usize>) -> Vec<Row> {
    rows.iter()
        .filter(|r| match vi {
            None => r.condition.is_none(),
            Some(v) => {
                if c.acts_on(&r.method) {
                    r.condition.as_deref() == Some(c.axis.as_str())
                        && r.condition_value.as_deref() == Some(c.values[v].as_str())
                } else {
                    r.condition.is_none()
                }
            }
        })
        .map(|r| Row {
            condition: None,
            condition_value: None,
            ..r.clone()
        })
        .collect()
}

/// Every accuracy claim whose two methods the plan has, at every value (base first) of every
/// condition acting on one of its methods. Empty when the plan has no conditions.
pub fn holds(plan: &Plan, rows: &[Row]) -> Vec<Holds> {
    let methods: Vec<String> = plan.methods.iter().map(|m| m.name.clone()).collect();
    let mut out = Vec::new();
    for claim in claims_for(&methods).into_iter().filter(|c| {
        c.measure == Measure::PsnrGain && methods.contains(&c.a) && methods.contains(&c.b)
    }) {
        for c in &plan.conditions {
            if !(c.acts_on(&claim.a) || c.acts_on(&claim.b)) {
                continue;
            }
            let mut points: Vec<(String, Option<usize>)> = vec![(c.base_label(), None)];
            points.extend(
                c.values
                    .iter()
                    .cloned()
                    .enumerate()
                    .map(|(i, v)| (v, Some(i))),
            );
            for (label, vi) in points {
                out.push(Holds {
                    claim: claim.clone(),
                    axis: c.axis.clone(),
                    value: label,
                    is_base: vi.is_none(),
                    scopes: scopes(plan, &claim, &rows_at(rows, c, vi)),
                });
            }
        }
    }
    out
}

/// The `tables.md` section "Where each claim holds" under `title` (empty without conditions).
pub fn section(plan: &Plan, rows: &[Row], title: &str) -> Doc {
    let mut d = Doc::new();
    let h = holds(plan, rows);
    if h.is_empty() {
        return d;
    }
    d.heading(2, title);
    d.para(
        "Each accuracy claim at each value of each condition (every other condition at its \
         base). At a condition's value the methods it acts on use their cells at that value, \
         the others their base cells. Effect: PSNR(A) - PSNR(B) in dB, mean over the pairs \
         (dataset, seed) with the paired 95 % t interval; sign: the interval against 0; \
         magnitude: the paper's effect against the interval (inside / above: ours is smaller / \
         below: ours is larger). Chart: `charts/holds-N.svg` in the report.",
    );
    let mut i = 0;
    while i < h.len() {
        let claim = &h[i].claim;
        d.heading(
            3,
            format!("{} (A = {}, B = {})", claim.text, claim.a, claim.b),
        );
        let mut t = Table::new(&[
            ("condition", false),
            ("value", false),
            ("scope", false),
            ("pairs", true),
            ("effect", true),
            ("95 % interval", false),
            ("paper", true),
            ("sign", false),
            ("magnitude", false),
        ]);
        while i < h.len() && h[i].claim.text == claim.text {
            let x = &h[i];
            for sc in &x.scopes {
                let v = &sc.verdict;
                t.row(vec![
                    x.axis.clone(),
                    format!("{}{}", x.value, if x.is_base { " (base)" } else { "" }),
                    sc.scope.clone(),
                    v.n.to_string(),
                    db(v.mean),
                    sc.interval_cell(db),
                    sc.paper_cell(),
                    v.word.as_str().to_string(),
                    sc.place.as_str().to_string(),
                ]);
            }
            i += 1;
        }
        d.table(t);
    }
    d
}

/// The conditions of a plan in words, for `tables.md` ("What each method row runs").
pub fn describe_conditions(plan: &Plan) -> Doc {
    let mut d = Doc::new();
    if plan.conditions.is_empty() {
        return d;
    }
    d.para("Conditions, varied one at a time (every other condition at its base value):");
    d.list(
        plan.conditions
            .iter()
            .map(|c| {
                let what = match c.on {
                    super::plan::conditions::Target::Method => "the method replaced by".to_string(),
                    t => format!("`unispine {} --{}`", t.as_str(), c.flag),
                };
                format!(
                    "**{}**: {what} {} (base: {}), for {}",
                    c.axis,
                    c.values.join(", "),
                    c.base_label(),
                    c.methods.join(", ")
                )
            })
            .collect(),
    );
    d
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::reproduce::magnitude::Place;
    use crate::reproduce::verdict::{paired_interval, Word};

    /// A plan with a pose-noise axis on every method and an init axis on 3dgs only.
    pub(crate) const PLAN: &str = "name = \"h\"\niters = 10\nseeds = [0, 1, 2]\n\
        methods = [\"3dgs\", \"xgaussian\"]\n\
        [[conditions]]\naxis = \"pose-noise\"\non = \"data\"\nflag = \"pose-noise-deg\"\n\
        base = 0\nvalues = [0.1, 0.2]\n\
        [[conditions]]\naxis = \"init\"\non = \"train\"\nflag = \"init\"\n\
        methods = [\"3dgs\"]\nvalues = [\"acui\"]\n\
        [[datasets]]\nname = \"ct\"\ndata = [\"phantom\"]\npaper = \"CTSpine3D\"\n";

    pub(crate) fn plan() -> Plan {
        crate::reproduce::plan::tests::parse(PLAN).unwrap()
    }

    fn row(method: &str, seed: u64, cond: Option<(&str, &str)>, psnr: f64) -> Row {
        Row {
            dataset: "ct".into(),
            paper_dataset: Some("CTSpine3D".into()),
            method: method.into(),
            base: method.into(),
            condition: cond.map(|c| c.0.into()),
            condition_value: cond.map(|c| c.1.into()),
            seed,
            status: "done".into(),
            completed: true,
            psnr: Some(psnr),
            ..Default::default()
        }
    }

    /// Rows whose xgaussian - 3dgs differences are `d` per seed at each point (3dgs = 30 dB).
    pub(crate) fn rows() -> Vec<Row> {
        let base = [8.0, 8.4, 8.2]; // mean 8.2: the paper's +8.21 dB is inside
        let pose1 = [1.0, 1.2, 0.8]; // mean 1.0: the paper's effect is above
        let pose2 = [12.0, 12.5, 11.5]; // mean 12.0: the paper's effect is below
        let acui = [-0.5, 0.5, 0.1]; // mean 0.033: sign inconclusive, paper above
        let mut r = Vec::new();
        for s in 0..3u64 {
            let i = s as usize;
            r.push(row("3dgs", s, None, 30.0));
            r.push(row("xgaussian", s, None, 30.0 + base[i]));
            r.push(row("3dgs", s, Some(("pose-noise", "0.1")), 20.0));
            r.push(row(
                "xgaussian",
                s,
                Some(("pose-noise", "0.1")),
                20.0 + pose1[i],
            ));
            r.push(row("3dgs", s, Some(("pose-noise", "0.2")), 10.0));
            r.push(row(
                "xgaussian",
                s,
                Some(("pose-noise", "0.2")),
                10.0 + pose2[i],
            ));
            // The init axis acts on 3dgs only: xgaussian's base cell (30 + base) stands in.
            r.push(row(
                "3dgs",
                s,
                Some(("init", "acui")),
                30.0 + base[i] - acui[i],
            ));
        }
        r
    }

    #[test]
    fn each_condition_value_gets_its_interval_and_both_verdicts() {
        let p = plan();
        let h = holds(&p, &rows());
        // Only the claims whose two methods the plan has (not SPWM's: no `unispine`).
        let names: Vec<&str> = p.methods.iter().map(|m| m.name.as_str()).collect();
        assert!(!h.is_empty());
        assert!(
            h.iter()
                .all(|x| names.contains(&x.claim.a.as_str()) && names.contains(&x.claim.b.as_str())),
            "{names:?}"
        );
        let first: Vec<&Holds> = h
            .iter()
            .filter(|x| x.claim.a == "xgaussian" && x.claim.b == "3dgs")
            .collect();
        let got: Vec<(&str, &str, bool)> = first
            .iter()
            .map(|x| (x.axis.as_str(), x.value.as_str(), x.is_base))
            .collect();
        assert_eq!(
            got,
            [
                ("pose-noise", "0", true),
                ("pose-noise", "0.1", false),
                ("pose-noise", "0.2", false),
                ("init", "default", true),
                ("init", "acui", false),
            ]
        );
        let want: [(&[f64], Word, Place); 5] = [
            (&[8.0, 8.4, 8.2], Word::Reproduced, Place::Inside),
            (&[1.0, 1.2, 0.8], Word::Reproduced, Place::Above),
            (&[12.0, 12.5, 11.5], Word::Reproduced, Place::Below),
            (&[8.0, 8.4, 8.2], Word::Reproduced, Place::Inside),
            (&[-0.5, 0.5, 0.1], Word::Inconclusive, Place::Above),
        ];
        let paper = 46.04 - 37.83; // Table 2, CTSpine3D: X-Gaussian - 3DGS
        for (x, (d, word, place)) in first.iter().zip(want) {
            let pooled = &x.scopes[0];
            assert_eq!(pooled.scope, "pooled");
            let (m, lo, hi, n) = paired_interval(d);
            let v = &pooled.verdict;
            assert_eq!(n, v.n, "{} {}", x.axis, x.value);
            for (a, b) in [(m, v.mean), (lo, v.lo), (hi, v.hi)] {
                assert!((a - b).abs() < 1e-9, "{} {}: {a} vs {b}", x.axis, x.value);
            }
            assert_eq!(v.word, word, "{} {}", x.axis, x.value);
            assert_eq!(pooled.place, place, "{} {}", x.axis, x.value);
            assert!((pooled.paper_effect.unwrap() - paper).abs() < 1e-9);
            // One dataset: its scope says the same.
            assert_eq!(x.scopes[1].scope, "ct");
            assert_eq!(x.scopes[1].verdict.diffs, v.diffs);
        }
    }

    #[test]
    fn the_section_lists_every_value_with_its_verdicts() {
        let p = plan();
        let s = section(&p, &rows(), "Where each claim holds").to_markdown();
        assert!(s.starts_with("## Where each claim holds"));
        assert!(s.contains(
            "| pose-noise | 0.1 | pooled | 3 | +1.000 dB | [+0.503 dB, +1.497 dB] | +8.21 dB | \
             reproduced | above |"
        ), "{s}");
        assert!(s.contains("| pose-noise | 0 (base) | ct | 3 |"), "{s}");
        assert!(s.contains("| below |") && s.contains("| inside |"));
        assert!(s.contains("| init | acui | pooled | 3 |") && s.contains("| inconclusive |"));
        // No conditions: no section.
        let mut q = p.clone();
        q.conditions.clear();
        assert!(section(&q, &rows(), "x").is_empty());
    }

    #[test]
    fn rows_at_a_value_pair_with_the_base_cells_of_methods_it_does_not_act_on() {
        let p = plan();
        let init = &p.conditions[1];
        let r = rows_at(&rows(), init, Some(0));
        assert_eq!(r.len(), 6);
        assert!(r.iter().all(|x| x.condition.is_none()));
        assert_eq!(r.iter().filter(|x| x.method == "xgaussian").count(), 3);
        // The 3dgs rows are the init cells (30 + base - acui), not the base cells (30).
        assert!(r
            .iter()
            .filter(|x| x.method == "3dgs")
            .all(|x| x.psnr != Some(30.0)));
        // The pose-noise value acts on both: no base cell is mixed in.
        let r = rows_at(&rows(), &p.conditions[0], Some(1));
        assert!(r.iter().all(|x| x.psnr.unwrap() < 25.0));
    }
}
