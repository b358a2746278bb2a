//! `thinfilm bench_estimate` (not yet built).

#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`bench estimate` is not built yet")
}
