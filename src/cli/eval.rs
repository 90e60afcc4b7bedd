//! `unispine eval` (not yet implemented).

/// Arguments of `unispine eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {}

/// Run `unispine eval`.
pub fn run(_args: EvalArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine eval` is not implemented yet")
}
