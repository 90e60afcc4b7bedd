//! `unispine gradcheck`: prints the gradient-check rows of [`crate::audit`] (every analytic
//! gradient against 5-point central finite differences in f64) as a table and exits non-zero
//! when any relative error exceeds [`TOLERANCE`].

use anyhow::bail;

use crate::audit::{self, gradcheck, TOLERANCE};
use crate::render::ColorMode;

/// Arguments of `unispine gradcheck`.
#[derive(Debug, clap::Args)]
pub struct GradcheckArgs {
    /// Scene set: `small` (cone, cone-offset-bg, parallel) or one scene by name.
    #[arg(long, default_value = "small")]
    pub scene: String,
    /// Colour model(s): `all`, `rirf-paper`, `rirf-xgaussian` or `sh`.
    #[arg(long, default_value = "all")]
    pub color: String,
}

/// Colour modes named by `--color`.
fn colors(name: &str) -> anyhow::Result<Vec<ColorMode>> {
    Ok(match name {
        "all" => vec![
            ColorMode::RirfPaper,
            ColorMode::RirfXgaussian,
            ColorMode::Sh,
        ],
        "rirf-paper" => vec![ColorMode::RirfPaper],
        "rirf-xgaussian" => vec![ColorMode::RirfXgaussian],
        "sh" => vec![ColorMode::Sh],
        _ => bail!("--color must be all, rirf-paper, rirf-xgaussian or sh (got `{name}`)"),
    })
}

/// Run `unispine gradcheck`.
pub fn run(args: GradcheckArgs) -> anyhow::Result<()> {
    let scenes = gradcheck::scenes(&args.scene)?;
    let colors = colors(&args.color)?;
    println!(
        "gradient of L = sum(W * image) through projection + compositing, f64, 5-point central \
         differences (step 1e-3); rel = max|an - fd| / max|fd| per group; tolerance {TOLERANCE:e}"
    );
    println!(
        "{:<8} {:<16} {:<15} {:<15} {:>11} {:>11} {:>11}  ok",
        "stage", "scene", "colour", "group", "max|fd|", "max abs err", "rel err"
    );
    let rows = gradcheck::rows(&scenes, &colors)?;
    for r in &rows {
        println!(
            "{:<8} {:<16} {:<15} {:<15} {:>11.3e} {:>11.3e} {:>11.3e}  {}",
            r.stage,
            r.case,
            r.variant,
            r.group,
            r.scale,
            r.max_abs,
            r.rel,
            if r.passes() { "yes" } else { "NO" }
        );
    }
    let worst = audit::worst(&rows);
    println!("worst relative error {worst:.3e} (tolerance {TOLERANCE:e})");
    if !rows.iter().all(audit::Row::passes) {
        bail!("gradient check failed: worst relative error {worst:e} > {TOLERANCE:e}");
    }
    Ok(())
}
