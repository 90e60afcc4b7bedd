//! "Where each claim holds": each accuracy claim at every value of every condition of a plan
//! ([`super::plan::conditions`]), pooled over the plan's datasets and per dataset, with the
//! paired effect, its 95 % interval, the sign verdict ([`super::verdict`]) and the magnitude
//! verdict ([`super::magnitude`]).
//!
//! At a condition's value the claim pairs the cells of that value for the methods the condition
//! acts on with the base cells of the methods it does not act on (a claim "RIRF + ACUI beat
//! 3DGS" at `init = unit-cube` acting on `3dgs` pairs X-Gaussian's base cells with 3DGS's
//! unit-cube cells). A condition acting on neither method of a claim is left out of that claim.

use std::fmt::Write as _;

use serde::Serialize;

use super::aggregate::{self, Row};
use super::magnitude::{paper_effect, pooled_effect, Scoped};
use super::plan::conditions::Condition;
use super::plan::Plan;
use super::verdict::{claims_for, evaluate, Claim, Measure};

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

/// A claim's verdicts on `rows` (already at one point): pooled, then per plan dataset.
fn scopes(plan: &Plan, claim: &Claim, rows: &[Row]) -> Vec<Scoped> {
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

/// Every accuracy claim of the plan at every value (base first) of every condition acting on
/// one of its methods. Empty when the plan has no conditions.
pub fn holds(plan: &Plan, rows: &[Row]) -> Vec<Holds> {
    let methods: Vec<String> = plan.methods.iter().map(|m| m.name.clone()).collect();
    let mut out = Vec::new();
    for claim in claims_for(&methods)
        .into_iter()
        .filter(|c| c.measure == Measure::PsnrGain)
    {
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

fn db(x: f64) -> String {
    if x.is_finite() {
        format!("{x:+.3} dB")
    } else {
        "-".into()
    }
}

/// A markdown table cell: `|` and line breaks would break the table.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// The `tables.md` section "Where each claim holds" (empty without conditions).
pub fn section(plan: &Plan, rows: &[Row]) -> String {
    let h = holds(plan, rows);
    if h.is_empty() {
        return String::new();
    }
    let mut s = String::from("## Where each claim holds\n\n");
    s.push_str(
        "Each accuracy claim at each value of each condition (every other condition at its \
         base). At a condition's value the methods it acts on use their cells at that value, \
         the others their base cells. Effect: PSNR(A) - PSNR(B) in dB, mean over the pairs \
         (dataset, seed) with the paired 95 % t interval; sign: the interval against 0; \
         magnitude: the paper's effect against the interval (inside / above: ours is smaller / \
         below: ours is larger). Chart: `charts/holds-N.svg` in the report.\n\n",
    );
    let mut last_claim = String::new();
    for x in &h {
        if x.claim.text != last_claim {
            if !last_claim.is_empty() {
                s.push('\n');
            }
            last_claim = x.claim.text.clone();
            let _ = writeln!(
                s,
                "### {} (A = {}, B = {})\n",
                cell(&x.claim.text),
                cell(&x.claim.a),
                cell(&x.claim.b)
            );
            s.push_str(
                "| condition | value | scope | pairs | effect | 95 % interval | paper | sign | \
                 magnitude |\n|---|---|---|---:|---:|---|---:|---|---|\n",
            );
        }
        for sc in &x.scopes {
            let v = &sc.verdict;
            let _ = writeln!(
                s,
                "| {} | {}{} | {} | {} | {} | {} | {} | {} | {} |",
                cell(&x.axis),
                cell(&x.value),
                if x.is_base { " (base)" } else { "" },
                cell(&sc.scope),
                v.n,
                db(v.mean),
                if v.n >= 2 {
                    format!("[{}, {}]", db(v.lo), db(v.hi))
                } else {
                    "-".into()
                },
                sc.paper_effect
                    .map(|e| format!("{e:+.2} dB"))
                    .unwrap_or_else(|| "-".into()),
                v.word.as_str(),
                sc.place.as_str()
            );
        }
    }
    s.push('\n');
    s
}

/// The conditions of a plan in words, for `tables.md` ("What each method row runs").
pub fn describe_conditions(plan: &Plan) -> String {
    if plan.conditions.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\nConditions, varied one at a time (every other condition at its base value):\n\n",
    );
    for c in &plan.conditions {
        let what = match c.on {
            super::plan::conditions::Target::Method => "the method replaced by".to_string(),
            t => format!("`unispine {} --{}`", t.as_str(), c.flag),
        };
        let _ = writeln!(
            s,
            "- **{}**: {what} {} (base: {}), for {}",
            c.axis,
            c.values.join(", "),
            c.base_label(),
            c.methods.join(", ")
        );
    }
    s
}
