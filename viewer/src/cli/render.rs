//! `viewer render` (being written).

/// Arguments of `viewer render`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `viewer render`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("viewer render is not built yet")
}
