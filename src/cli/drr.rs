//! `unispine drr` (not yet implemented).

/// Arguments of `unispine drr`.
#[derive(Debug, clap::Args)]
pub struct DrrArgs {}

/// Run `unispine drr`.
pub fn run(_args: DrrArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine drr` is not implemented yet")
}
