//! `unispine data` (not yet implemented).

/// Arguments of `unispine data`.
#[derive(Debug, clap::Args)]
pub struct DataArgs {}

/// Run `unispine data`.
pub fn run(_args: DataArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine data` is not implemented yet")
}
