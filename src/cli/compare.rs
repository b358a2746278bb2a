//! `thinfilm compare A.exr B.exr`: error metrics of A against the reference B (RMSE, relMSE,
//! mean and 95th-percentile ΔE00, mean-colour bias) and an optional A | B | ΔE figure. Images
//! whose sizes differ by an integer factor are compared after box-downsampling the larger.

use super::Output;
use anyhow::{Context, Result};
use std::path::PathBuf;
use thinfilm::compare::figure::{compose_comparison, ComparisonStyle};
use thinfilm::compare::{compare_images, downsample_box, match_sizes};
use thinfilm::image_io::read_exr_rgb;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Test image (linear sRGB EXR). If its size is an integer multiple of the reference's
    /// (or the other way round), the larger image is box-downsampled to the smaller first.
    pub a: PathBuf,
    /// Reference image (linear sRGB EXR); relative metrics are relative to it.
    pub b: PathBuf,
    /// Write an A | B | ΔE00 heat-map figure (PNG) here.
    #[arg(long)]
    pub figure: Option<PathBuf>,
    /// Box-downsample both images by this integer factor first (averages out noise).
    #[arg(long, default_value_t = 1, value_parser = super::args::count)]
    pub downsample: usize,
    /// Linear exposure for the figure's tone mapping.
    #[arg(long, allow_hyphen_values = true, default_value_t = 1.0, value_parser = super::args::non_negative_f32)]
    pub exposure: f32,
    /// Colour-bar maximum of the ΔE00 heat map (default: a round number ≥ the 99th percentile).
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::non_negative)]
    pub delta_e_max: Option<f64>,
}

pub fn run(args: Args, report: Output) -> Result<()> {
    let (an, bn) = (args.a.display().to_string(), args.b.display().to_string());
    let a = read_exr_rgb(&args.a).with_context(|| format!("reading {an}"))?;
    let b = read_exr_rgb(&args.b).with_context(|| format!("reading {bn}"))?;
    let (a, b, resized) = match_sizes(a, &an, b, &bn)?;
    // Bit-identical pixels (e.g. a merged render against the single run it reproduces).
    let identical = resized.is_none()
        && a.pixels.len() == b.pixels.len()
        && a.pixels
            .iter()
            .zip(&b.pixels)
            .all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits));
    let (a, b) = if args.downsample != 1 {
        (
            downsample_box(&a, args.downsample)?,
            downsample_box(&b, args.downsample)?,
        )
    } else {
        (a, b)
    };
    let m = compare_images(&a, &b).with_context(|| format!("comparing {an} with {bn}"))?;
    if report.json {
        let v = serde_json::json!({
            "a": an, "b": bn, "resized": resized, "identical": identical,
            "downsample": args.downsample, "metrics": m,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("A (test):      {an}");
        println!("B (reference): {bn}");
        println!(
            "size:          {}×{} (downsample {})",
            m.width, m.height, args.downsample
        );
        if let Some(note) = &resized {
            // A result, not a log line: the numbers below are of the resized image.
            println!("resized:       {note}");
        }
        println!(
            "identical:     {}",
            if identical { "yes, bit for bit" } else { "no" }
        );
        println!("RMSE:          {:.6}", m.rmse);
        println!("relMSE:        {:.6}", m.rel_mse);
        println!("ΔE00 mean:     {:.4}", m.delta_e00_mean);
        println!("ΔE00 95th pct: {:.4}", m.delta_e00_p95);
        println!(
            "mean bias:     R {:+.3}%  G {:+.3}%  B {:+.3}%",
            100.0 * m.mean_bias_rgb[0],
            100.0 * m.mean_bias_rgb[1],
            100.0 * m.mean_bias_rgb[2]
        );
    }
    if let Some(path) = &args.figure {
        let style = ComparisonStyle {
            exposure: args.exposure,
            delta_e_max: args.delta_e_max,
            ..Default::default()
        };
        let name = |p: &PathBuf| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string())
        };
        let fig = compose_comparison(&a, &name(&args.a), &b, &name(&args.b), &m, &style)?;
        fig.save_png(path)?;
        if !report.json {
            println!("figure:        {}", path.display());
        }
    }
    Ok(())
}
