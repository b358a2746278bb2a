//! `thinfilm figure`: ground truth vs fitted teapots (seed Figs. 5 and 6).

use std::path::PathBuf;
use thinfilm::figure::{self, RenderSettings};

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  thinfilm figure fit/ --ground-truth capture/ground_truth --out fig.png\n  \
thinfilm figure fit/ --capture capture/ --angle-index 0 --out fig.png   # no ground truth: captured vs model colour\n  \
thinfilm figure --samples --out fig6.png                                # the seed's Fig. 6 for its three samples"
)]
pub struct Args {
    /// Output folder of `thinfilm estimate` (fit.json + thickness.exr).
    #[arg(required_unless_present = "samples")]
    fit_dir: Option<PathBuf>,
    /// Ground-truth folder written by `thinfilm simulate` (teapots: truth | fit | ΔE00 and the
    /// thickness error map).
    #[arg(long)]
    ground_truth: Option<PathBuf>,
    /// Without ground truth: the capture set the fit came from (captured vs model colours).
    #[arg(long, conflicts_with = "ground_truth")]
    capture: Option<PathBuf>,
    /// Which angle of the capture to show (index into capture.json's angles).
    #[arg(long, default_value_t = 0)]
    angle_index: usize,
    /// Scene to render instead of the built-in teapot (every shape gets the film material).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulate, fit and draw the seed's three samples (Fig. 6 layout): same as `demo`.
    #[arg(long)]
    samples: bool,
    /// Output PNG; EXRs of each render are written beside it.
    #[arg(long, short, default_value = "figure.png")]
    out: PathBuf,
    /// Render resolution (square), pixels.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..=65536))]
    resolution: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=1 << 20))]
    spp: u32,
    /// Sampler seed (shared by both renders).
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: Args, report: super::Output) -> anyhow::Result<()> {
    let settings = RenderSettings {
        resolution: args.resolution,
        spp: args.spp,
        seed: args.seed,
        progress: report.progress(),
        ..RenderSettings::default()
    };
    if args.samples {
        let out_dir = args.out.with_extension("");
        let cfg = thinfilm::demo::DemoConfig {
            out: out_dir.clone(),
            render: settings,
            progress: report.progress(),
            ..Default::default()
        };
        let summary = thinfilm::demo::run(&cfg)?;
        println!("{}", summary.table_markdown);
        println!("wrote {}", summary.figures[0].display());
        return Ok(());
    }
    let fit_dir = args
        .fit_dir
        .expect("clap requires FIT_DIR without --samples");
    let out = match (&args.ground_truth, &args.capture) {
        (Some(gt), _) => {
            figure::fit_figure(&fit_dir, gt, args.scene.as_deref(), &settings, &args.out)?
        }
        (None, Some(cap)) => figure::capture_figure(&fit_dir, cap, args.angle_index, &args.out)?,
        (None, None) => anyhow::bail!(
            "give --ground-truth DIR (simulated captures) or --capture DIR (real captures)"
        ),
    };
    println!(
        "wrote {} (mean ΔE00 {:.3})",
        out.png.display(),
        out.delta_e00_mean
    );
    for e in &out.exrs {
        println!("  {}", e.display());
    }
    Ok(())
}
