//! `unispine render` (not yet implemented).

/// Arguments of `unispine render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {}

/// Run `unispine render`.
pub fn run(_args: RenderArgs) -> anyhow::Result<()> {
    anyhow::bail!("`unispine render` is not implemented yet")
}
