//! `unispine bench` (not yet implemented).

/// Arguments of `unispine bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {}

/// Run `unispine bench`.
pub fn run(_args: BenchArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine bench` is not implemented yet")
}
