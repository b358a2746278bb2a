//! `thinfilm bench_optics` (not yet built).

#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`bench optics` is not built yet")
}
