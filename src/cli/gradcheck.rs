//! `unispine gradcheck`: prints the gradient-check rows of [`unispine::audit`] (every analytic
//! gradient against 5-point central finite differences in f64: the rasterizer's render rows
//! and the neural-field rows of [`unispine::audit::field`]) as a table, or with `--json` as a JSON
//! object, and exits non-zero when any relative error exceeds [`TOLERANCE`].

use anyhow::bail;

use unispine::audit::{self, field, gradcheck, Row, TOLERANCE};
use unispine::render::ColorMode;

/// Arguments of `unispine gradcheck`.
#[derive(Debug, clap::Args)]
pub struct GradcheckArgs {
    /// Rasterizer scene set: `small` (cone, cone-offset-bg, parallel) or one scene by name.
    #[arg(long, default_value = "small")]
    pub scene: String,
    /// Colour model(s): `all`, `rirf-paper`, `rirf-xgaussian` or `sh`.
    #[arg(long, default_value = "all")]
    pub color: String,
    /// Stages: `all`, `render` (the rasterizer) or `field` (encoders, MLP, line integral, the
    /// field training loss).
    #[arg(long, default_value = "all")]
    pub stage: String,
    /// Print one JSON object (`tolerance`, `worst`, `rows`: stage, case, variant, group,
    /// scale, max_abs, rel, pass) instead of the table.
    #[arg(long)]
    pub json: bool,
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
    let (render, fields) = match args.stage.as_str() {
        "all" => (true, true),
        "render" => (true, false),
        "field" => (false, true),
        s => bail!("invalid `--stage`: must be all, render or field (got `{s}`)"),
    };
    let mut rows: Vec<Row> = Vec::new();
    if render {
        let scenes = gradcheck::scenes(&args.scene)?;
        let colors = colors(&args.color)?;
        rows.extend(gradcheck::rows(&scenes, &colors)?);
    }
    if fields {
        rows.extend(field::rows());
    }
    let worst = audit::worst(&rows);
    if args.json {
        let list: Vec<serde_json::Value> = rows
            .iter()
            .map(|r| {
                let mut v = serde_json::to_value(r).expect("row serialises");
                v["pass"] = serde_json::Value::Bool(r.passes());
                v
            })
            .collect();
        let out = serde_json::json!({
            "tolerance": TOLERANCE,
            "worst": if worst.is_finite() { serde_json::json!(worst) } else { serde_json::Value::Null },
            "rows": list,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&out).expect("json serialises")
        );
    } else {
        println!(
            "analytic gradients against 5-point central differences in f64; rel = max|an - fd| \
             / max|fd| per group; tolerance {TOLERANCE:e}"
        );
        if render {
            println!(
                "render: L = sum(W * image) through projection + compositing, step 1e-3 in \
                 every group"
            );
        }
        if fields {
            println!(
                "field-*: L = sum(g . output) of each stage (field-loss: the training MSE), step \
                 {:e} for parameters, {:e} m for points",
                field::H_PARAM,
                field::H_POINT
            );
        }
        println!(
            "{:<13} {:<16} {:<18} {:<15} {:>11} {:>11} {:>11}  ok",
            "stage", "case", "variant", "group", "max|fd|", "max abs err", "rel err"
        );
        for r in &rows {
            println!(
                "{:<13} {:<16} {:<18} {:<15} {:>11.3e} {:>11.3e} {:>11.3e}  {}",
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
        println!("worst relative error {worst:.3e} (tolerance {TOLERANCE:e})");
    }
    if !rows.iter().all(Row::passes) {
        bail!("gradient check failed: worst relative error {worst:e} > {TOLERANCE:e}");
    }
    Ok(())
}
