//! `unispine train` (not yet implemented).

/// Arguments of `unispine train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {}

/// Run `unispine train`.
pub fn run(_args: TrainArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine train` is not implemented yet")
}
