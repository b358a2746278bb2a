//! `thinfilm estimate CAPTURE_DIR --out DIR`: fit the film index and per-pixel thickness
//! of a capture set and write the fitted material (see `crate::estimate`).

use super::Output;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use std::time::Instant;
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
    /// Known film index: fit the thickness only (works with a single angle). In [1, 10].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::film_index)]
    pub film_ior: Option<f64>,
    /// Ground truth folder (from `thinfilm simulate`) to report errors against.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Largest thickness considered, nm (at most 20000).
    #[arg(long, allow_hyphen_values = true, default_value_t = 2000.0, value_parser = super::args::thickness_nm)]
    pub max_thickness_nm: f64,
    /// Smallest thickness considered, nm.
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0, value_parser = super::args::thickness_nm)]
    pub min_thickness_nm: f64,
    /// Index range for `grid` (and `full`'s fallback scan), within [1, 10].
    #[arg(long, allow_hyphen_values = true, default_value_t = 1.1, value_parser = super::args::film_index)]
    pub min_film_ior: f64,
    #[arg(long, allow_hyphen_values = true, default_value_t = 3.0, value_parser = super::args::film_index)]
    pub max_film_ior: f64,
    /// `grid` index step (at most 100000 steps over the index range).
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.01, value_parser = super::args::positive)]
    pub grid_ior_step: f64,
    /// `grid` thickness step, nm (at most 1000000 steps over the thickness range).
    #[arg(long, allow_hyphen_values = true, default_value_t = 2.0, value_parser = super::args::positive)]
    pub grid_thickness_step_nm: f64,
    /// `grid` searches the index on every k-th pixel (x and y), k ≥ 1.
    #[arg(long, default_value_t = 1, value_parser = super::args::count)]
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
}

/// Most steps a `grid` search may take along the index and along the thickness.
const MAX_GRID_IOR_STEPS: f64 = 1e5;
const MAX_GRID_THICKNESS_STEPS: f64 = 1e6;

/// Relations between options that clap checks one by one.
fn check_ranges(args: &Args) -> Result<()> {
    for (what, lo, hi) in [
        ("thickness-nm", args.min_thickness_nm, args.max_thickness_nm),
        ("film-ior", args.min_film_ior, args.max_film_ior),
    ] {
        if lo >= hi {
            bail!("--min-{what} {lo} must be below --max-{what} {hi}");
        }
    }
    let grids = [
        (
            "grid-ior-step",
            args.grid_ior_step,
            args.min_film_ior,
            args.max_film_ior,
        ),
        (
            "grid-thickness-step-nm",
            args.grid_thickness_step_nm,
            args.min_thickness_nm,
            args.max_thickness_nm,
        ),
    ];
    for ((opt, step, lo, hi), most) in grids
        .into_iter()
        .zip([MAX_GRID_IOR_STEPS, MAX_GRID_THICKNESS_STEPS])
    {
        let steps = (hi - lo) / step;
        if steps > most {
            bail!("--{opt} {step} makes {steps:.0} steps over [{lo}, {hi}]; at most {most}");
        }
    }
    Ok(())
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
        rows: args.rows,
        ..Options::default()
    };
    check_ranges(&args)?;
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
