//! `thinfilm estimate CAPTURE_DIR --out DIR`: fit the film index and per-pixel thickness
//! of a capture set and write the fitted material (see `crate::estimate`).

use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use thinfilm::capture::Radiometry;
use thinfilm::estimate::film::FilmModelKind;
use thinfilm::estimate::{report, Method, Options};
use thinfilm::optics::Ior;

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
    /// Known film index: fit the thickness only (works with a single angle). A number
    /// (1.33), n+ki, a material name (water, MgF2, …), cauchy:A,B[,C] (λ in nm) or
    /// sellmeier:B1,C1,… (λ in µm).
    #[arg(long)]
    pub film_ior: Option<Ior>,
    /// Film index model to fit: constant, cauchy (A + B/λ²) or cauchy3 (+ C/λ⁴). Default:
    /// the capture's "film_model", else chosen by the data (information criterion).
    #[arg(long, value_enum)]
    pub film_model: Option<FilmModelKind>,
    /// Fit a shift of the substrate's real index (reported in fit.json). Default: only
    /// when the data demand it.
    #[arg(long, conflicts_with = "no_fit_substrate")]
    pub fit_substrate: bool,
    /// Never fit the substrate index.
    #[arg(long)]
    pub no_fit_substrate: bool,
    /// Override the capture's "radiometry": relative (unknown scale per pixel and angle,
    /// the default) or absolute (calibrated reflectance: the fit uses amplitudes).
    #[arg(long, value_enum)]
    pub radiometry: Option<Radiometry>,
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
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: Args) -> Result<()> {
    let opts = Options {
        method: args.method,
        film_ior: args.film_ior,
        film_model: args.film_model,
        fit_substrate: match (args.fit_substrate, args.no_fit_substrate) {
            (true, _) => Some(true),
            (_, true) => Some(false),
            _ => None,
        },
        radiometry: args.radiometry,
        min_thickness_nm: args.min_thickness_nm,
        max_thickness_nm: args.max_thickness_nm,
        min_film_ior: args.min_film_ior,
        max_film_ior: args.max_film_ior,
        grid_ior_step: args.grid_ior_step,
        grid_thickness_step_nm: args.grid_thickness_step_nm,
        grid_pixel_stride: args.grid_pixel_stride,
        band_integration: !args.no_band_integration,
        progress: !args.quiet,
        ..Options::default()
    };
    if !(opts.grid_ior_step > 0.0 && opts.grid_thickness_step_nm > 0.0) {
        anyhow::bail!("--grid-ior-step and --grid-thickness-step-nm must be > 0");
    }
    let t = Instant::now();
    let report::FitRun {
        fit,
        delta_e: de,
        truth,
        ..
    } = report::fit_capture_dir(
        &args.capture_dir,
        &args.out,
        &opts,
        args.ground_truth.as_deref(),
    )?;
    let stats = report::thickness_stats(&fit.thickness_nm);
    println!(
        "{}: film index {:.4}{}, thickness mean {} nm, residual RMSE {}, ΔE*ab {} (written in {:.2} s to {})",
        fit.method,
        fit.film_ior,
        fit.film_ior_sigma.map(|s| format!(" ± {s:.4}")).unwrap_or_default(),
        stats.map(|s| format!("{:.1}", s.mean)).unwrap_or_else(|| "n/a".into()),
        fit.rmse().map(|r| format!("{r:.4}")).unwrap_or_else(|| "n/a".into()),
        de.as_ref().map(|d| format!("{d:.2}")).unwrap_or_else(|e| format!("n/a ({e})")),
        t.elapsed().as_secs_f64(),
        args.out.display()
    );
    if let Some(t) = truth {
        println!(
            "vs ground truth: |n error| {:.4}, thickness MAE {:.2} nm, mean error {:+.2} nm",
            t.film_ior_abs_error, t.thickness_mae_nm, t.thickness_mean_error_nm
        );
    }
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}
