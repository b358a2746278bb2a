//! `thinfilm estimate CAPTURE_DIR --out DIR`: fit the film index and per-pixel thickness
//! of a capture set and write the fitted material (see `crate::estimate`).

use super::Output;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use std::time::Instant;
use thinfilm::capture::spectra::{load_spectra, SpectraSetup};
use thinfilm::capture::{Polarization, Radiometry};
use thinfilm::estimate::film::FilmModelKind;
use thinfilm::estimate::tiles::RowBand;
use thinfilm::estimate::{report as fit_report, Method, Options};
use thinfilm::optics::Ior;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Capture folder holding `capture.json` and one ENVI cube per angle.
    #[arg(required_unless_present = "spectra")]
    pub capture_dir: Option<PathBuf>,
    /// Point spectra instead of a capture folder: 2-column text files (wavelength nm,
    /// intensity; .csv/.xy), one pixel each, all on the same wavelengths. Fit with the same
    /// engine (each spectrum gets its own scale; lamp shape and background are shared).
    #[arg(long, num_args = 1.., conflicts_with = "capture_dir", value_name = "FILE")]
    pub spectra: Vec<PathBuf>,
    /// With --spectra: a dark / "void" spectrum (no film: dark offset and stray light),
    /// subtracted from each spectrum.
    #[arg(long, requires = "spectra", value_name = "FILE")]
    pub dark: Option<PathBuf>,
    /// With --spectra: incident angle, degrees.
    #[arg(long, requires = "spectra", default_value_t = 0.0)]
    pub incident_deg: f64,
    /// With --spectra: substrate index (index syntax as --film-ior). Default: the ambient
    /// medium (a free-standing film, e.g. a soap film).
    #[arg(long, requires = "spectra")]
    pub substrate_ior: Option<Ior>,
    /// With --spectra: index of the medium the light arrives from.
    #[arg(long, requires = "spectra", default_value_t = 1.0)]
    pub ambient_ior: f64,
    /// With --spectra: polarisation observed (s, p or unpolarized).
    #[arg(long, requires = "spectra", default_value = "unpolarized")]
    pub polarization: Polarization,
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
    /// With --film-ior, the noise and nuisance terms come from pixel samples of the whole
    /// capture and only the band and 4 rows around it are fitted, so the band's thickness
    /// equals the same rows of the whole fit, bit for bit, and `thinfilm merge` stitches the
    /// bands' thickness.exr. Without it the band is fitted on its own (its own index).
    #[arg(long, value_parser = parse_rows, value_name = "START:END")]
    pub rows: Option<(usize, usize)>,
    /// Fit band K of N equal row bands (K from 0; e.g. a job array's task index and count):
    /// the same as --rows with that band's rows.
    #[arg(long, value_parser = super::parse_part, value_name = "K/N", conflicts_with = "rows")]
    pub part: Option<(usize, usize)>,
}

/// Most steps a `grid` search may take along the index and along the thickness.
const MAX_GRID_IOR_STEPS: f64 = 1e5;
const MAX_GRID_THICKNESS_STEPS: f64 = 1e6;

/// Relations between options that clap checks one by one.
fn check_ranges(args: &Args) -> Result<()> {
    if let Some(ior) = &args.film_ior {
        thinfilm::limits::check_index("--film-ior", ior)?;
    }
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
    check_ranges(&args)?;
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
        progress: report.progress(),
        rows: match (args.rows, args.part) {
            (Some((a, b)), _) => Some(RowBand::Rows(a, b)),
            (None, Some((index, count))) => Some(RowBand::Part { index, count }),
            (None, None) => None,
        },
        ..Options::default()
    };
    let t = Instant::now();
    let fit_report::FitRun {
        fit,
        delta_e: de,
        truth,
        ..
    } = match &args.capture_dir {
        Some(dir) => {
            fit_report::fit_capture_dir(dir, &args.out, &opts, args.ground_truth.as_deref())?
        }
        None => {
            let setup = SpectraSetup {
                incident_deg: args.incident_deg,
                ambient_ior: args.ambient_ior,
                substrate_ior: args.substrate_ior.clone(),
                polarization: args.polarization,
                radiometry: args.radiometry.unwrap_or_default(),
            };
            let files: Vec<&std::path::Path> = args.spectra.iter().map(|p| p.as_path()).collect();
            fit_report::fit_loaded(
                || load_spectra(&files, args.dark.as_deref(), &setup),
                &args.out,
                &opts,
                args.ground_truth.as_deref(),
            )?
        }
    };
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
