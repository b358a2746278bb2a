//! `thinfilm demo`: the whole pipeline on the seed paper's three samples.

use std::path::PathBuf;
use thinfilm::demo::{self, DemoConfig};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder (created). Holds the capture sets, fits, figures, README.md and index.html.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// Simulated capture size, WxH pixels.
    #[arg(long, default_value = "128x96", value_parser = super::args::size)]
    size: (usize, usize),
    /// Teapot render resolution (square), pixels.
    #[arg(long, default_value_t = 192, value_parser = clap::value_parser!(u32).range(1..=65536))]
    resolution: u32,
    /// Samples per pixel of the teapot renders.
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u32).range(1..=1 << 20))]
    spp: u32,
    /// Additive reflectance noise σ of the simulated captures.
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.004, value_parser = super::args::non_negative)]
    noise: f64,
}

pub fn run(args: Args, report: super::Output) -> anyhow::Result<()> {
    let mut cfg = DemoConfig {
        out: args.out,
        noise_sigma: args.noise,
        progress: report.progress(),
        ..DemoConfig::default()
    };
    (cfg.width, cfg.height) = args.size;
    cfg.render.resolution = args.resolution;
    cfg.render.spp = args.spp;
    let summary = demo::run(&cfg)?;
    println!("{}", summary.table_markdown);
    println!(
        "Finished in {:.1} s. Outputs in {}:",
        summary.seconds,
        cfg.out.display()
    );
    for f in summary
        .figures
        .iter()
        .chain(summary.method_figures.iter().map(|(_, f, _)| f))
    {
        println!("  {}", f.display());
    }
    println!(
        "  {} (open in a browser) and {}",
        cfg.out.join("index.html").display(),
        cfg.out.join("README.md").display()
    );
    Ok(())
}
