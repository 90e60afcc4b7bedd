//! The cells of a plan (dataset x condition point x method x [sweep value x] seed) and the
//! `unispine train` arguments of each: Gaussian cells get the plan's iterations, schedule,
//! `[train]` flags and the train conditions' values at their point;
//! baseline cells their seed, fields `--iters` from `field_iters`, and only the flags a baseline
//! takes ([`crate::baseline::FLAGS`]).

use std::path::{Path, PathBuf};

use super::plan::conditions::{Point, Target, ITERS};
use super::plan::{MethodSpec, Plan};

/// One cell of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// 0-based position in the plan's cell order (dataset, point, method, sweep value, seed).
    pub index: usize,
    pub dataset: String,
    /// The condition point (None: the base). At a method condition's value, `method` keeps
    /// the plan method's name with the replacing preset's base and flags.
    pub point: Point,
    pub method: MethodSpec,
    /// The sweep value of this cell (the flag is the plan's).
    pub sweep: Option<String>,
    pub seed: u64,
}

impl Cell {
    /// Folder of the method (and sweep value) below `runs/DATASET/`.
    pub fn method_dir(&self, plan: &Plan) -> String {
        let mut d = match (&plan.sweep, &self.sweep) {
            (Some(s), Some(v)) => format!("{}@{}={}", self.method.name, s.flag, v),
            _ => self.method.name.clone(),
        };
        if let Some((axis, value)) = plan.point_label(self.point) {
            d.push_str(&format!("@{axis}={value}"));
        }
        d
    }
    /// The dataset folder this cell reads ([`Plan::data_name`]).
    pub fn data_name(&self, plan: &Plan) -> String {
        plan.data_name(&self.dataset, self.point)
    }
    /// Training iterations of this cell: the plan's, or a schedule condition's value.
    pub fn iters(&self, plan: &Plan) -> usize {
        if let Some((ci, vi)) = self.point {
            let c = &plan.conditions[ci];
            if c.on == Target::Train && c.flag == ITERS {
                return c.values[vi].parse().unwrap_or(plan.iters);
            }
        }
        plan.conditions
            .iter()
            .find(|c| c.on == Target::Train && c.flag == ITERS && c.acts_on(&self.method.name))
            .and_then(|c| c.base.as_ref())
            .and_then(|b| b.parse().ok())
            .unwrap_or(plan.iters)
    }
    /// The run folder relative to OUT.
    pub fn rel_dir(&self, plan: &Plan) -> PathBuf {
        PathBuf::from("runs")
            .join(&self.dataset)
            .join(self.method_dir(plan))
            .join(format!("seed{}", self.seed))
    }
    /// A short label: `DATASET/METHOD[@flag=v]/seedK`.
    pub fn label(&self, plan: &Plan) -> String {
        self.rel_dir(plan)
            .strip_prefix("runs")
            .unwrap_or(Path::new(""))
            .display()
            .to_string()
    }
    /// `unispine train` arguments of this cell except `--data`, `--out` and `--threads`.
    pub fn train_args(&self, plan: &Plan) -> Vec<String> {
        let baseline = crate::method::Baseline::parse(&self.method.base);
        let mut a = vec!["--method".to_string(), self.method.base.clone()];
        match baseline {
            None => a.extend(["--iters".into(), self.iters(plan).to_string()]),
            Some(crate::method::Baseline::Field(_)) => {
                if let Some(n) = plan.field_iters {
                    a.extend(["--iters".into(), n.to_string()]);
                }
            }
            Some(crate::method::Baseline::Fdk) => {}
        }
        a.extend(["--seed".into(), self.seed.to_string()]);
        if plan.compress_schedule && baseline.is_none() {
            a.push("--compress-schedule".into());
        }
        let mut flags: Vec<String> = plan.train_args.clone();
        flags.extend(self.method.args.iter().cloned());
        // Train conditions: the value at this cell's point, the base value elsewhere; at a
        // method condition's value the replacing preset runs with its own settings (the base
        // values describe the method it replaces: `3dgs`'s `--init random` is not vanilla
        // 3DGS's unit cube).
        let replaced = self
            .point
            .is_some_and(|(pc, _)| plan.conditions[pc].on == Target::Method);
        for (ci, c) in plan.conditions.iter().enumerate() {
            if c.on != Target::Train || c.flag == ITERS || !c.acts_on(&self.method.name) {
                continue;
            }
            let v = match self.point {
                Some((pc, vi)) if pc == ci => Some(&c.values[vi]),
                _ if replaced => None,
                _ => c.base.as_ref(),
            };
            if let Some(v) = v {
                flags.push(format!("--{}", c.flag));
                flags.push(v.clone());
            }
        }
        if let (Some(s), Some(v)) = (&plan.sweep, &self.sweep) {
            flags.push(format!("--{}", s.flag));
            flags.push(v.clone());
        }
        if baseline.is_some() {
            flags = baseline_flags(&flags);
        }
        a.extend(flags);
        a
    }
}

/// Of `flags` (`--name [value]` ...), the ones a baseline run takes ([`crate::baseline::FLAGS`]),
/// with their values.
fn baseline_flags(flags: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut keep = false;
    for f in flags {
        if let Some(name) = f.strip_prefix("--") {
            keep = crate::baseline::FLAGS.contains(&name);
        }
        if keep {
            out.push(f.clone());
        }
    }
    out
}

/// Every cell of the plan, in order: dataset, condition point (the base, then each
/// condition's values), method (at a condition's value, only those it acts on), sweep value,
/// seed.
pub fn cells(plan: &Plan) -> Vec<Cell> {
    let sweep: Vec<Option<String>> = match &plan.sweep {
        Some(s) => s.values.iter().cloned().map(Some).collect(),
        None => vec![None],
    };
    let mut out = Vec::new();
    for d in &plan.datasets {
        for p in plan.points() {
            for m in &plan.methods {
                let spec = match p {
                    None => m.clone(),
                    Some((ci, vi)) => {
                        let c = &plan.conditions[ci];
                        if !c.acts_on(&m.name) {
                            continue;
                        }
                        match c.on {
                            Target::Method => MethodSpec {
                                name: m.name.clone(),
                                ..c.replacements[vi].clone()
                            },
                            _ => m.clone(),
                        }
                    }
                };
                for v in &sweep {
                    for &seed in &plan.seeds {
                        out.push(Cell {
                            index: out.len(),
                            dataset: d.name.clone(),
                            point: p,
                            method: spec.clone(),
                            sweep: v.clone(),
                            seed,
                        });
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::plan::tests::parse;

    /// `3dgs` and `xgaussian` on one dataset with a data axis of integer values, a budget on
    /// `3dgs` only, a schedule axis on `3dgs` only and a method axis replacing `3dgs`.
    const PLAN: &str = "name = \"c\"\niters = 10\nseeds = [0]\nmethods = [\"3dgs\", \"xgaussian\"]\n\
        [[conditions]]\naxis = \"res\"\non = \"data\"\nflag = \"detector\"\nbase = 32\nvalues = [64]\n\
        [[conditions]]\naxis = \"budget\"\non = \"train\"\nflag = \"max-gaussians\"\n\
        methods = [\"3dgs\"]\nbase = 500\nvalues = [100]\n\
        [[conditions]]\naxis = \"length\"\non = \"train\"\nflag = \"iters\"\n\
        methods = [\"3dgs\"]\nbase = 20\nvalues = [40]\n\
        [[conditions]]\naxis = \"preset\"\non = \"method\"\nmethods = [\"3dgs\"]\n\
        values = [\"3dgs-vanilla\"]\n\
        [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n";

    /// The cell of `method` at the point labelled `axis=value` (None: the base).
    fn cell(plan: &Plan, method: &str, at: Option<(&str, &str)>) -> Cell {
        cells(plan)
            .into_iter()
            .find(|c| {
                let l = plan.point_label(c.point);
                c.method.name == method && l.as_ref().map(|(a, v)| (a.as_str(), v.as_str())) == at
            })
            .unwrap_or_else(|| panic!("no cell {method} at {at:?}"))
    }

    #[test]
    fn a_schedule_axis_sets_the_iterations_of_the_methods_it_acts_on_only() {
        let p = parse(PLAN).unwrap();
        // Its base value wherever it acts, its value at its own point, the plan's elsewhere.
        assert_eq!(cell(&p, "3dgs", None).iters(&p), 20);
        assert_eq!(cell(&p, "3dgs", Some(("length", "40"))).iters(&p), 40);
        assert_eq!(cell(&p, "xgaussian", None).iters(&p), 10);
        // A point on a data or a train axis of integer values is not a schedule.
        assert_eq!(cell(&p, "xgaussian", Some(("res", "64"))).iters(&p), 10);
        assert_eq!(cell(&p, "3dgs", Some(("res", "64"))).iters(&p), 20);
        assert_eq!(cell(&p, "3dgs", Some(("budget", "100"))).iters(&p), 20);
        // Without a schedule axis, a train axis's integer base is not one either.
        let cut = PLAN.replace("flag = \"iters\"", "flag = \"grad-threshold\"");
        let q = parse(&cut).unwrap();
        assert_eq!(cell(&q, "3dgs", None).iters(&q), 10);
    }

    #[test]
    fn train_args_carry_each_train_axis_at_its_point_and_its_base_elsewhere() {
        let p = parse(PLAN).unwrap();
        let args = |m: &str, at: Option<(&str, &str)>| cell(&p, m, at).train_args(&p).join(" ");
        assert_eq!(
            args("3dgs", None),
            "--method 3dgs --iters 20 --seed 0 --max-gaussians 500"
        );
        assert_eq!(
            args("3dgs", Some(("budget", "100"))),
            "--method 3dgs --iters 20 --seed 0 --max-gaussians 100"
        );
        assert_eq!(
            args("3dgs", Some(("length", "40"))),
            "--method 3dgs --iters 40 --seed 0 --max-gaussians 500"
        );
        // A data axis is the dataset's, not a flag of training.
        assert_eq!(
            args("3dgs", Some(("res", "64"))),
            "--method 3dgs --iters 20 --seed 0 --max-gaussians 500"
        );
        // Axes acting on 3dgs only leave xgaussian alone.
        assert_eq!(
            args("xgaussian", None),
            "--method xgaussian --iters 10 --seed 0"
        );
        // The replacing preset runs with its own settings.
        assert_eq!(
            args("3dgs", Some(("preset", "3dgs-vanilla"))),
            "--method 3dgs-vanilla --iters 20 --seed 0"
        );
    }

    #[test]
    fn a_sweep_value_names_the_folder_and_the_label() {
        let p = parse(
            "name = \"s\"\niters = 10\nseeds = [3]\nmethods = [\"3dgs\"]\n\
             [sweep]\nflag = \"train-views\"\nvalues = [5, 10]\n\
             [[conditions]]\naxis = \"res\"\non = \"data\"\nflag = \"detector\"\nvalues = [64]\n\
             [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n",
        )
        .unwrap();
        let c = cells(&p);
        let labels: Vec<String> = c.iter().map(|c| c.label(&p)).collect();
        assert_eq!(
            labels,
            [
                "ph/3dgs@train-views=5/seed3",
                "ph/3dgs@train-views=10/seed3",
                "ph/3dgs@train-views=5@res=64/seed3",
                "ph/3dgs@train-views=10@res=64/seed3",
            ]
        );
        assert_eq!(
            c[1].rel_dir(&p),
            Path::new("runs/ph/3dgs@train-views=10/seed3")
        );
        assert!(c[1]
            .train_args(&p)
            .ends_with(&["--train-views".into(), "10".into()]));
    }
}
