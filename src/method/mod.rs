//! Every method `unispine train --method` runs, and the interface the session driver
//! ([`crate::session`]) runs them through.
//!
//! The registry: [`TrainMethod`] is a Gaussian preset ([`crate::train::Method`]) or a
//! [`Baseline`] (FDK or a neural-field preset of [`crate::field`]);
//! [`TrainMethod::all`] lists
//! every name with its help, read by the command line and by reproduction plans. A method with
//! its settings is a [`Config`]; [`Config::build`] gives the [`Method`] that trains it.
//!
//! The interface ([`Method`]): [`describe`](Method::describe) (name, iterations, checkpoint
//! policy, what the progress output shows first), [`step`](Method::step) (one iteration, the
//! one step record [`Step`]), [`checkpoint`](Method::checkpoint) (the state after the
//! iterations done with the run's identity, as the bytes of `checkpoint.bin`),
//! [`restore`](Method::restore) (from those bytes, refusing another run's), and
//! [`evaluate`](Method::evaluate) (score the final model and write its files). The three
//! implementations:
//! - [`gaussians`]: the Gaussian trainer ([`crate::train::Trainer`]);
//! - [`field`]: the neural-field trainer ([`crate::field::train::FieldTrainer`]);
//! - [`fdk`]: FDK, one step (the reconstruction), nothing to checkpoint: it is not resumable
//!   and a stop request does not interrupt it.
//!
//! Adding a method: see `ARCHITECTURE.md`, "Add a method".

pub mod fdk;
pub mod field;
pub mod gaussians;

use std::path::Path;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::field::FieldConfig;
use crate::record::Step;
use crate::train::run_dir::CONFIG;
use crate::train::{EvalPoint, Event, Metrics, RunDir, TrainConfig};

pub use crate::baseline::BaselineOptions;

/// A baseline method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Baseline {
    /// FDK (TIGRE semantics) from the training views, re-projected at the test views.
    Fdk,
    /// A neural attenuation field preset of [`crate::field`] (`naf`, `naf-full`, ...).
    Field(&'static str),
}

impl Baseline {
    /// Every baseline name, in table order.
    pub fn names() -> Vec<&'static str> {
        let mut v = vec!["fdk"];
        v.extend(crate::field::PRESETS);
        v
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Fdk => "fdk",
            Baseline::Field(p) => p,
        }
    }

    /// One line on what the baseline runs (as `unispine train --help` and `tables.md` show it).
    pub fn help(self) -> String {
        match self {
            Baseline::Fdk => {
                "FDK (TIGRE semantics: cosine weights, Ram-Lak, 1/U^2 backprojection) \
                              from the training views, re-projected at the test views"
                    .into()
            }
            Baseline::Field(p) => FieldConfig::preset(p, 1)
                .map(|c| c.describe())
                .unwrap_or_default(),
        }
    }

    /// The baseline called `name`, if any.
    pub fn parse(name: &str) -> Option<Baseline> {
        if name == "fdk" {
            return Some(Baseline::Fdk);
        }
        crate::field::PRESETS
            .into_iter()
            .find(|p| *p == name)
            .map(Baseline::Field)
    }
}

/// A method of `unispine train --method`: a Gaussian preset of [`crate::train`] or a baseline.
/// The one list of method names, read by the command line and by reproduction plans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrainMethod {
    Gaussians(crate::train::Method),
    Baseline(Baseline),
}

impl TrainMethod {
    /// The Gaussian preset, when the method is one.
    pub fn gaussians(self) -> Option<crate::train::Method> {
        match self {
            TrainMethod::Gaussians(m) => Some(m),
            TrainMethod::Baseline(_) => None,
        }
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TrainMethod::Gaussians(m) => m.name(),
            TrainMethod::Baseline(b) => b.name(),
        }
    }

    /// Every method name with its one line of help: the presets in declaration order, then the
    /// baselines in table order.
    pub fn all() -> Vec<(&'static str, String)> {
        use crate::flags::FlagValue;
        let presets = crate::train::Method::choices();
        let baselines = Baseline::names().into_iter().map(|b| {
            let help = Baseline::parse(b).map(Baseline::help).unwrap_or_default();
            (b, help)
        });
        presets.into_iter().chain(baselines).collect()
    }

    /// The method called `name`; the error lists every name.
    pub fn parse(name: &str) -> std::result::Result<TrainMethod, String> {
        if let Some(b) = Baseline::parse(name) {
            return Ok(TrainMethod::Baseline(b));
        }
        crate::flags::parse_choice::<crate::train::Method>(name)
            .map(TrainMethod::Gaussians)
            .map_err(|_| {
                let names: Vec<&str> = TrainMethod::all().into_iter().map(|m| m.0).collect();
                format!("unknown method `{name}` (one of: {})", names.join(", "))
            })
    }
}

/// A method with its settings: what [`crate::session::run`] trains and what `config.json`
/// records.
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::large_enum_variant)] // one per run, never in a collection
pub enum Config {
    Gaussians(TrainConfig),
    Field(FieldConfig),
    Fdk,
}

impl From<TrainConfig> for Config {
    fn from(c: TrainConfig) -> Config {
        Config::Gaussians(c)
    }
}

impl Config {
    /// The settings of `baseline` on a dataset of `train_views` training views with `opts`
    /// (each option checked against the baseline: `--iters` and `--rays` are errors for FDK,
    /// `--vm-lines` for every preset but TensoRF's).
    pub fn baseline(
        baseline: Baseline,
        train_views: usize,
        opts: &BaselineOptions,
    ) -> Result<Config> {
        crate::baseline::check_vm_lines(baseline.name(), opts.vm_lines)?;
        match baseline {
            Baseline::Fdk => {
                if opts.iters.is_some() {
                    return Err(Error::invalid(
                        "--iters",
                        "fdk is a single pass (no iterations)",
                    ));
                }
                if opts.rays.is_some() {
                    return Err(Error::invalid(
                        "--rays",
                        "fdk uses every pixel of every view (no ray sampling)",
                    ));
                }
                Ok(Config::Fdk)
            }
            Baseline::Field(name) => field::configure(name, train_views, opts).map(Config::Field),
        }
    }

    /// The method that trains these settings on `ds` (validates both).
    pub fn build<'a>(&self, ds: &'a Dataset) -> Result<Box<dyn Method + 'a>> {
        Ok(match self {
            Config::Gaussians(c) => Box::new(gaussians::Gaussians::new(c.clone(), ds)?),
            Config::Field(c) => Box::new(field::Field::new(c.clone(), ds)?),
            Config::Fdk => Box::new(fdk::Fdk::new(ds)?),
        })
    }

    /// The settings of the run in `rd` (its `config.json`): a neural-field run names its
    /// `preset`, an FDK run has `"method": "fdk"`, any other is a Gaussian run.
    pub fn read(rd: &RunDir) -> Result<Config> {
        let v: serde_json::Value = rd.read_config()?;
        if v.get("preset").is_some_and(|p| p.is_string()) {
            let c: FieldConfig = rd.read_config()?;
            c.validate()?;
            return Ok(Config::Field(c));
        }
        if v.get("method").is_some_and(|m| m == "fdk") {
            return Ok(Config::Fdk);
        }
        Ok(Config::Gaussians(rd.read_config()?))
    }

    /// Write the settings as `config.json` of a starting run (FDK writes its own at the end).
    pub fn write(&self, rd: &RunDir) -> Result<()> {
        match self {
            Config::Gaussians(c) => rd.write_config(c),
            Config::Field(c) => {
                crate::fsio::write_json_atomic(&rd.path(CONFIG), &field::config_json(c, &[]))
            }
            Config::Fdk => Ok(()),
        }
    }

    /// The method's name on the command line (a field's preset, without its labels).
    pub fn name(&self) -> &str {
        match self {
            Config::Gaussians(c) => c.method.name(),
            Config::Field(c) => &c.preset,
            Config::Fdk => Baseline::Fdk.name(),
        }
    }

    /// The method's name in `metrics.json`.
    pub fn label(&self) -> String {
        match self {
            Config::Gaussians(c) => c.method.name().to_string(),
            Config::Field(c) => c.label(),
            Config::Fdk => Baseline::Fdk.name().to_string(),
        }
    }
}

/// What a method tells the session before the loop.
#[derive(Clone, Debug, PartialEq)]
pub struct Description {
    /// Name in `metrics.json` and the progress output.
    pub name: String,
    /// Iterations of the whole run.
    pub total: usize,
    /// A checkpoint every this many iterations with a run folder (0: none on the way).
    pub checkpoint_every: usize,
    /// Whether the method checkpoints at all (else a stop request does not interrupt it and
    /// its runs cannot be resumed).
    pub resumable: bool,
    /// Write a checkpoint before the first iteration of a new run.
    pub checkpoint_at_start: bool,
    /// Keep `checkpoint.bin` in the folder of a completed run (else it is removed).
    pub keep_checkpoint: bool,
    /// The [`Event::Started`] of the run, when the method reports one.
    pub started: Option<Event>,
}

/// What the session keeps besides the method's own state (and a checkpoint restores).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Record {
    /// `log.csv` so far.
    pub log: String,
    /// Test evaluations during training.
    pub evals: Vec<EvalPoint>,
    /// Training wall time so far (summed over sessions), seconds.
    pub train_time_s: f64,
    /// Of which evaluation, seconds.
    pub eval_time_s: f64,
}

/// A method the session driver runs (see the module doc).
pub trait Method {
    /// What the session needs before the loop.
    fn describe(&self) -> Description;
    /// Iterations done.
    fn iteration(&self) -> usize;
    /// Run the next iteration.
    fn step(&mut self) -> Result<Step>;
    /// The bytes of `checkpoint.bin` after the iterations done, with `rec` and the run's
    /// identity (only called when [`Description::resumable`]).
    fn checkpoint(&mut self, rec: &Record) -> Result<Vec<u8>>;
    /// Continue from the checkpoint `bytes` (read from `path`); an error when it belongs to
    /// another run (method, settings, seed or dataset). Returns the session's record.
    fn restore(&mut self, path: &Path, bytes: &[u8]) -> Result<Record>;
    /// Score the model after the iterations (only when `completed`: else the test scores stay
    /// empty), write its files into `dir` (`metrics.json`, the model, previews, and whatever
    /// else the method keeps beside `log.csv` and `checkpoint.bin`, which the session writes),
    /// and return the run's metrics.
    fn evaluate(&mut self, rec: &Record, completed: bool, dir: Option<&RunDir>) -> Result<Metrics>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_folder_names_its_method_by_its_config() {
        let d = tempfile::tempdir().unwrap();
        let rd = RunDir::create(d.path()).unwrap();
        let field = FieldConfig::preset("naf", 4).unwrap();
        Config::Field(field.clone()).write(&rd).unwrap();
        assert_eq!(Config::read(&rd).unwrap(), Config::Field(field));
        assert_eq!(Config::read(&rd).unwrap().name(), "naf");
        let g = TrainConfig::preset(crate::train::Method::Xgaussian);
        Config::Gaussians(g.clone()).write(&rd).unwrap();
        assert_eq!(Config::read(&rd).unwrap(), Config::Gaussians(g));
        std::fs::write(rd.path(CONFIG), r#"{"method": "fdk"}"#).unwrap();
        assert_eq!(Config::read(&rd).unwrap(), Config::Fdk);
        assert_eq!(
            TrainMethod::parse("naf").unwrap(),
            TrainMethod::Baseline(Baseline::Field("naf"))
        );
        assert!(TrainMethod::parse("mean").unwrap_err().contains("fdk"));
    }
}
