//! `thinfilm estimate CAPTURE_DIR --out DIR`: fit the film index and per-pixel thickness
//! of a capture set and write the fitted material (see `crate::estimate`).

use super::Output;
use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::Instant;
use thinfilm::estimate::tiles::RowBand;
use thinfilm::estimate::{report as fit_report, Method, Options};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Capture folder holding `capture.json` and one ENVI cube per angle.
    pub capture_dir: PathBuf,
    /// Output folder (fit.json, thickness.exr/png, residual.png, material.xml/gltf).
    #[arg(long)]
    pub out: PathBuf,
    /// Estimator: the seed's as published, exhaustive grid, or the full refinement.
    #[arg(long, value_enum, default_value_t = Method::Full)]
    pub method: Method,
    /// Known film index: fit the thickness only (works with a single angle).
    #[arg(long)]
    pub film_ior: Option<f64>,
    /// Ground truth folder (from `thinfilm simulate`) to report errors against.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Largest thickness considered, nm.
    #[arg(long, default_value_t = 2000.0)]
    pub max_thickness_nm: f64,
    /// Smallest thickness considered, nm.
    #[arg(long, default_value_t = 0.0)]
    pub min_thickness_nm: f64,
    /// Index range for `grid` (and `full`'s fallback scan).
    #[arg(long, default_value_t = 1.1)]
    pub min_film_ior: f64,
    #[arg(long, default_value_t = 3.0)]
    pub max_film_ior: f64,
    /// `grid` index step.
    #[arg(long, default_value_t = 0.01)]
    pub grid_ior_step: f64,
    /// `grid` thickness step, nm.
    #[arg(long, default_value_t = 2.0)]
    pub grid_thickness_step_nm: f64,
    /// `grid` searches the index on every k-th pixel (x and y).
    #[arg(long, default_value_t = 1)]
    pub grid_pixel_stride: usize,
    /// Ignore the headers' FWHM (no band integration in the model).
    #[arg(long)]
    pub no_band_integration: bool,
    /// Fit only rows START:END of the capture (a band of a capture too large for one job).
    /// With --film-ior the band's thickness equals the same rows of the whole fit, bit for
    /// bit, and `thinfilm merge` stitches the bands' thickness.exr; without it the index is
    /// fitted from the band's pixels (phase one of a huge capture: index from a band, then
    /// every band with that index).
    #[arg(long, value_parser = parse_rows, value_name = "START:END")]
    pub rows: Option<(usize, usize)>,
    /// Fit band K of N equal row bands (K from 0; e.g. a job array's task index and count):
    /// the same as --rows with that band's rows.
    #[arg(long, value_parser = super::parse_part, value_name = "K/N", conflicts_with = "rows")]
    pub part: Option<(usize, usize)>,
}

fn parse_rows(s: &str) -> Result<(usize, usize), String> {
    thinfilm::render::provenance::parse_range(s)
        .map(|(a, b)| (a as usize, b as usize))
        .map_err(|e| format!("{e:#}"))
}

pub fn run(args: Args, report: Output) -> Result<()> {
    let opts = Options {
        method: args.method,
        film_ior: args.film_ior,
        min_thickness_nm: args.min_thickness_nm,
        max_thickness_nm: args.max_thickness_nm,
        min_film_ior: args.min_film_ior,
        max_film_ior: args.max_film_ior,
        grid_ior_step: args.grid_ior_step,
        grid_thickness_step_nm: args.grid_thickness_step_nm,
        grid_pixel_stride: args.grid_pixel_stride,
        band_integration: !args.no_band_integration,
        progress: report.progress(),
        rows: match (args.rows, args.part) {
            (Some((a, b)), _) => Some(RowBand::Rows(a, b)),
            (None, Some((index, count))) => Some(RowBand::Part { index, count }),
            (None, None) => None,
        },
        ..Options::default()
    };
    if !(opts.grid_ior_step > 0.0 && opts.grid_thickness_step_nm > 0.0) {
        anyhow::bail!("--grid-ior-step and --grid-thickness-step-nm must be > 0");
    }
    let t = Instant::now();
    let fit_report::FitRun {
        fit,
        delta_e: de,
        truth,
        ..
    } = fit_report::fit_capture_dir(
        &args.capture_dir,
        &args.out,
        &opts,
        args.ground_truth.as_deref(),
    )?;
    let stats = thinfilm::stats::Summary::of_finite(&fit.thickness_nm);
    report.text(format_args!(
        "{}: film index {:.4}{}, thickness mean {} nm, residual RMSE {}, ΔE*ab {} (written in {:.2} s to {})",
        fit.method,
        fit.film_ior,
        fit.film_ior_sigma.map(|s| format!(" ± {s:.4}")).unwrap_or_default(),
        stats.map(|s| format!("{:.1}", s.mean)).unwrap_or_else(|| "n/a".into()),
        fit.rmse().map(|r| format!("{r:.4}")).unwrap_or_else(|| "n/a".into()),
        de.as_ref().map(|d| format!("{d:.2}")).unwrap_or_else(|e| format!("n/a ({e})")),
        t.elapsed().as_secs_f64(),
        args.out.display()
    ));
    if let Some(t) = &truth {
        report.text(format_args!(
            "vs ground truth: |n error| {:.4}, thickness MAE {:.2} nm, mean error {:+.2} nm",
            t.film_ior_abs_error, t.thickness_mae_nm, t.thickness_mean_error_nm
        ));
    }
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }
    // The document fit.json holds, plus where it went.
    if report.json {
        let path = args.out.join("fit.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading back {}", path.display()))?;
        let mut v: serde_json::Value = serde_json::from_str(&text)?;
        v["output"] = serde_json::json!(args.out);
        report.json(&v)?;
    }
    Ok(())
}
