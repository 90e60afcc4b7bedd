//! `unispine gradcheck` (not yet implemented).

/// Arguments of `unispine gradcheck`.
#[derive(Debug, clap::Args)]
pub struct GradcheckArgs {}

/// Run `unispine gradcheck`.
pub fn run(_args: GradcheckArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine gradcheck` is not implemented yet")
}
