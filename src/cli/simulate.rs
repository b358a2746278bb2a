//! `thinfilm simulate` (not yet built).

#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`simulate` is not built yet")
}
