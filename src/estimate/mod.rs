//! Film index (global) and per-pixel thickness from multi-angle hyperspectral captures
//! or point spectra (the seed paper's §4, made robust for real captures; the corrections are in
//! `docs/physics-and-formats.md`, "Thin-film physics").
//!
//! The estimator is a pipeline of stages ([`stage`]): noise estimate → index → joint
//! refinement → thickness → checks, over one forward model ([`model`]: the Airy film,
//! polarisation, band response, dispersive film index [`film`]) and one nuisance model
//! ([`nuisance`]: gain per pixel and angle, spectral multiplier and background per angle,
//! noise per band). This module only orchestrates: it validates the inputs, runs the
//! stages of the chosen [`Method`] and assembles the [`Fit`].
//!
//! - [`Method::Full`] (default) — sub-band peaks tracked over angles give a first index
//!   ([`index`]); a joint Levenberg–Marquardt fit of the shared parameters and a few
//!   hundred thicknesses chooses the model by an information criterion ([`joint`]);
//!   every pixel's thickness on a tabulated model ([`thickness`]);
//! - [`Method::Paper`] — the seed as published ([`paper`]), the baseline;
//! - [`Method::Grid`] — the exhaustive (n, d) search the seed compares against ([`grid`]).

// `!(x > 0.0)` is deliberate throughout: it is also true for NaN. Per-pixel results are
// small tuples collected from rayon.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::type_complexity)]

pub mod checks;
pub mod data;
pub mod film;
mod grid;
mod index;
pub mod joint;
mod linalg;
pub mod model;
pub mod noise;
pub mod nuisance;
mod paper;
pub mod peaks;
pub mod report;
pub mod solver;
pub mod stage;
mod subfringe;
pub mod synth;
pub mod table;
mod thickness;
pub mod tiles;

use crate::capture::{CaptureSet, Radiometry};
use crate::optics::Ior;
use anyhow::{bail, Result};
use film::{FilmIndex, FilmModelKind};
use nuisance::Nuisance;
use stage::{Context, IndexEstimate, Pipeline, SelectionStep};
use std::time::Instant;

/// CPU seconds (user + system, all threads) used by this process so far, from
/// `/proc/self/stat` (Linux, 10 ms ticks); `None` where that is unavailable. Benchmarks on
/// a shared machine report it beside wall-clock time, which other load inflates.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ is 100 on every Linux ABI Rust targets
}

/// Wall-clock and CPU seconds of one stage.
pub(crate) struct Stopwatch {
    wall: Instant,
    cpu: Option<f64>,
}

/// Per-stage wall-clock and CPU seconds, in stage order.
#[derive(Default)]
pub(crate) struct Stages {
    wall: Vec<(String, f64)>,
    cpu: Vec<(String, f64)>,
}

impl Stopwatch {
    pub(crate) fn start() -> Self {
        Stopwatch {
            wall: Instant::now(),
            cpu: process_cpu_seconds(),
        }
    }
    pub(crate) fn stop(self, name: &str, stages: &mut Stages) {
        stages
            .wall
            .push((name.to_string(), self.wall.elapsed().as_secs_f64()));
        if let (Some(a), Some(b)) = (self.cpu, process_cpu_seconds()) {
            stages.cpu.push((name.to_string(), b - a));
        }
    }
}

/// Which estimator to run.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The seed's method as published (band-quantised peaks, eqs. 12–14).
    Paper,
    /// Exhaustive (n, d) grid search.
    Grid,
    /// Sub-band peaks + joint least-squares refinement + spatial order resolution.
    Full,
}

impl Method {
    /// The stage implementations of this method (one line per method).
    pub fn pipeline(self) -> Pipeline {
        match self {
            Method::Full => Pipeline {
                index: &index::PeaksIndex,
                refine: &joint::JointRefine,
                thickness: &thickness::TableThickness,
                names: ["index_from_peaks", "joint_refinement", "thickness"],
            },
            Method::Paper => Pipeline {
                index: &paper::Eq12Index,
                refine: &paper::NoRefine,
                thickness: &paper::Eq13Thickness,
                names: ["index_eq12", "no_refinement", "thickness_eq13_14"],
            },
            Method::Grid => Pipeline {
                index: &grid::GridIndex,
                refine: &paper::NoRefine,
                thickness: &grid::GridThickness,
                names: ["index_grid", "no_refinement", "thickness_grid"],
            },
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Method::Paper => "paper",
            Method::Grid => "grid",
            Method::Full => "full",
        })
    }
}

/// Estimator settings.
#[derive(Debug, Clone)]
pub struct Options {
    pub method: Method,
    /// Known film index (number, n+ki, material, cauchy:…, sellmeier:…): fit thickness
    /// only (works with a single angle).
    pub film_ior: Option<Ior>,
    /// Film index model; `None`: the capture's `film_model`, else chosen by the data.
    pub film_model: Option<FilmModelKind>,
    /// Fit a shift of the substrate's real index: `Some(true)` always, `Some(false)`
    /// never, `None` when the data demand it (information criterion).
    pub fit_substrate: Option<bool>,
    /// Overrides the capture's `radiometry`.
    pub radiometry: Option<Radiometry>,
    pub min_thickness_nm: f64,
    pub max_thickness_nm: f64,
    /// Index range searched by `grid` and by `full`'s fallback when no peaks are found.
    pub min_film_ior: f64,
    pub max_film_ior: f64,
    pub grid_ior_step: f64,
    pub grid_thickness_step_nm: f64,
    /// `grid` evaluates the index search on every k-th pixel in x and y (1 = all).
    pub grid_pixel_stride: usize,
    /// Model the camera's Gaussian band response when the capture gives FWHMs.
    pub band_integration: bool,
    /// Pixels used for the joint refinement of `full`.
    pub joint_pixels: usize,
    pub progress: bool,
    /// Fit only a band of rows: everything from its pixels when the index is not given,
    /// else its thickness exactly as in the whole fit, computing only its rows and a halo
    /// ([`tiles`]). `None`: every row.
    pub rows: Option<tiles::RowBand>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::Full,
            film_ior: None,
            film_model: None,
            fit_substrate: None,
            radiometry: None,
            min_thickness_nm: 0.0,
            max_thickness_nm: 2000.0,
            min_film_ior: 1.1,
            max_film_ior: 3.0,
            grid_ior_step: 0.01,
            grid_thickness_step_nm: 2.0,
            grid_pixel_stride: 1,
            band_integration: true,
            joint_pixels: 256,
            progress: false,
            rows: None,
        }
    }
}

/// A fitted film.
#[derive(Debug, Clone)]
pub struct Fit {
    pub method: Method,
    /// The film index model and its coefficients.
    pub film: FilmIndex,
    /// n at 550 nm.
    pub film_ior: f64,
    /// 1σ of n(550 nm), when the method gives one.
    pub film_ior_sigma: Option<f64>,
    /// 1σ of every fitted film parameter (n(550), then the Cauchy terms).
    pub film_param_sigma: Vec<f64>,
    /// How the index was obtained / why it has no uncertainty.
    pub film_ior_note: String,
    /// Fitted shift of the substrate's real index, with its 1σ (None: not fitted).
    pub substrate_shift: f64,
    pub substrate_sigma: Option<f64>,
    /// The nuisance model and its fitted terms.
    pub nuisance: Nuisance,
    /// Typical noise estimated from the data (data units) and how.
    pub noise: f64,
    pub noise_source: String,
    /// χ²/dof over every fitted pixel (≈ 1: the model explains the data to the noise).
    pub chi2_red: f64,
    /// Model selection record of the joint stage.
    pub selection: Vec<SelectionStep>,
    pub width: usize,
    /// Rows in this fit (`rows.1 − rows.0`).
    pub height: usize,
    /// Rows `[A, B)` of the capture this fit covers (all of them unless `--rows`).
    pub rows: (usize, usize),
    /// What the thickness map is, for its EXR header (`thinfilm merge` stitches by it).
    pub provenance: tiles::TileInfo,
    /// Per pixel of `rows`, nm, NaN where no thickness was fitted.
    pub thickness_nm: Vec<f32>,
    /// Per pixel 1σ, nm (NaN where no thickness).
    pub thickness_sigma_nm: Vec<f32>,
    /// Per pixel noise-weighted residual Σ(e/σ)² and sample count.
    pub chi2: Vec<f32>,
    pub samples: Vec<u32>,
    /// Pixels with no usable angle.
    pub invalid_pixels: usize,
    /// Pixels with data but no thickness (no peak for `paper`, not identifiable, …).
    pub unfitted_pixels: usize,
    /// Pixels whose thickness is not identifiable (less than one fringe, relative scale).
    pub not_identifiable: usize,
    pub stage_seconds: Vec<(String, f64)>,
    /// CPU seconds (all threads) per stage, where the platform reports them.
    pub stage_cpu_seconds: Vec<(String, f64)>,
    pub warnings: Vec<String>,
}

impl Fit {
    pub fn valid_pixels(&self) -> usize {
        self.thickness_nm.iter().filter(|d| d.is_finite()).count()
    }

    /// Residual RMS in data units over every fitted sample (noise-weighted residual
    /// scaled by the typical noise), `None` if nothing was fitted.
    pub fn rmse(&self) -> Option<f64> {
        let (mut s, mut c) = (0.0f64, 0u64);
        for ((&e, &k), d) in self.chi2.iter().zip(&self.samples).zip(&self.thickness_nm) {
            if d.is_finite() && k > 0 {
                s += e as f64;
                c += k as u64;
            }
        }
        (c > 0).then(|| (s / c as f64).sqrt() * self.noise)
    }
}

fn check_set(set: &CaptureSet) -> Result<()> {
    let b = set.bands();
    if b < 3 {
        bail!("capture has {b} bands; at least 3 are needed to fit a spectrum");
    }
    if set.angles.is_empty() {
        bail!("capture has no incident angles");
    }
    let px = set.width * set.height;
    for a in &set.angles {
        if a.reflectance.len() != px * b || a.valid.len() != px {
            bail!(
                "angle {}°: cube holds {} samples / {} mask entries, expected {}×{}×{} / {}",
                a.incident_deg,
                a.reflectance.len(),
                a.valid.len(),
                set.width,
                set.height,
                b,
                px
            );
        }
        if !(a.incident_deg.is_finite() && (0.0..90.0).contains(&a.incident_deg)) {
            bail!("incident angle {}° is outside [0°, 90°)", a.incident_deg);
        }
    }
    if set
        .wavelengths_nm
        .iter()
        .any(|l| !(l.is_finite() && *l > 0.0))
    {
        bail!("capture wavelengths must be finite and > 0 nm");
    }
    Ok(())
}

/// The index stage's result for a known index, after checking it can be used.
fn known_index(ior: &Ior, cx: &Context) -> Result<IndexEstimate> {
    let g = &cx.obs.geom;
    for &l in &g.wavelengths_nm {
        let n = ior.at(l);
        if !(n.re.is_finite() && n.re > 0.0) {
            bail!(
                "--film-ior {ior}: n = {} at {l} nm is not a refractive index",
                n.re
            );
        }
        if n.im > 1e-6 {
            bail!(
                "--film-ior {ior}: k = {} at {l} nm; the estimator models non-absorbing films",
                n.im
            );
        }
        if n.re <= g.max_kx() {
            bail!(
                "--film-ior {ior}: n = {} at {l} nm ≤ n1·sinθ = {:.4} at the largest angle: no \
                 propagating wave in the film",
                n.re,
                g.max_kx()
            );
        }
    }
    Ok(IndexEstimate {
        film: FilmIndex::Known(ior.clone()),
        sigma: None,
        note: "given (--film-ior)".into(),
        dispersive_start: None,
    })
}

/// Runs the chosen estimator.
pub fn estimate(set: &CaptureSet, opts: &Options) -> Result<Fit> {
    check_set(set)?;
    let rows = match opts.rows {
        Some(band) => band.resolve(set.height)?,
        None => (0, set.height),
    };
    if opts.film_ior.is_none() && rows != (0, set.height) {
        return band_on_its_own(set, opts, rows);
    }
    if opts.film_ior.is_none() {
        let mut distinct: Vec<f64> = set.angles.iter().map(|a| a.incident_deg).collect();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        if distinct.len() < 2 {
            bail!(
                "the capture has a single incident angle ({}°): the film index cannot be \
                 separated from the thickness (seed eq. 12 needs two angles); pass --film-ior",
                distinct[0]
            );
        }
    }
    if !(opts.max_thickness_nm > opts.min_thickness_nm && opts.min_thickness_nm >= 0.0) {
        bail!(
            "thickness range [{}, {}] nm is empty",
            opts.min_thickness_nm,
            opts.max_thickness_nm
        );
    }
    let mut opts = opts.clone();
    opts.film_model = opts.film_model.or(set.film_model);
    let mut stages = Stages::default();
    let t = Stopwatch::start();
    let obs = data::Observations::new(
        set,
        opts.band_integration,
        opts.radiometry.unwrap_or(set.radiometry),
    );
    let sample = data::spread(&obs.pixels_with_angles(1), 4096);
    let noise = noise::estimate(&obs, &sample);
    t.stop("noise", &mut stages);
    let mut cx = Context::new(obs, &opts, noise);
    // A band with a given index: the global stages (noise, nuisance terms, thickness seeds)
    // see the whole capture, the per-pixel ones fit the band (and the thickness stage its
    // halo), so the band's rows come out exactly as in the whole fit.
    cx.rows = rows;
    let pipe = opts.method.pipeline();
    let first = match &opts.film_ior {
        Some(ior) => known_index(ior, &cx)?,
        None => {
            let t = Stopwatch::start();
            let r = pipe.index.run(&cx)?;
            t.stop(pipe.names[0], &mut stages);
            r
        }
    };
    let t = Stopwatch::start();
    let sol = pipe.refine.run(&cx, first)?;
    t.stop(pipe.names[1], &mut stages);
    let t = Stopwatch::start();
    let mut map = pipe.thickness.run(&cx, &sol)?;
    t.stop(pipe.names[2], &mut stages);
    let t = Stopwatch::start();
    let checked = checks::run(&cx, &sol, &mut map);
    t.stop("checks", &mut stages);
    // Per-pixel maps are of the whole image, NaN outside the band: keep the band's rows.
    let kept = rows.0 * set.width..rows.1 * set.width;
    let mut sigma = checked.sigma;
    crop(&mut map.d, &kept);
    crop(&mut sigma, &kept);
    crop(&mut map.chi2, &kept);
    crop(&mut map.samples, &kept);
    let invalid = kept
        .clone()
        .filter(|&p| !set.angles.iter().any(|a| a.valid[p]))
        .count();
    let fitted = map.d.iter().filter(|d| d.is_finite()).count();
    let total = kept.len();
    let film_ior = sol.film.n550();
    Ok(Fit {
        method: opts.method,
        film_ior,
        film_ior_sigma: sol.film_sigma().filter(|s| s.is_finite()),
        film_param_sigma: sol.film_param_sigma.clone(),
        film_ior_note: sol.note.clone(),
        substrate_shift: sol.substrate_shift,
        substrate_sigma: sol.substrate_sigma,
        nuisance: sol.nuisance.clone(),
        noise: cx.noise.typical,
        noise_source: cx.noise.source.clone(),
        chi2_red: checked.chi2_red,
        selection: sol.selection.clone(),
        film: sol.film,
        width: set.width,
        height: rows.1 - rows.0,
        rows,
        provenance: tiles::TileInfo {
            rows,
            image_height: set.height,
            fit_hash: tiles::fit_hash(set, film_ior, &opts),
            film_ior,
            version: env!("CARGO_PKG_VERSION").to_string(),
        },
        unfitted_pixels: total - invalid - fitted.min(total - invalid),
        not_identifiable: checked.not_identifiable,
        thickness_nm: map.d,
        thickness_sigma_nm: sigma,
        chi2: map.chi2,
        samples: map.samples,
        invalid_pixels: invalid,
        stage_seconds: stages.wall,
        stage_cpu_seconds: stages.cpu,
        warnings: cx.take_warnings(),
    })
}

/// A band of rows fitted as a capture of its own — index, noise, nuisance terms and
/// thickness from its pixels alone (phase one of the two-phase recipe: the index from a band
/// of typical film) — reported as rows `rows` of `set`.
fn band_on_its_own(set: &CaptureSet, opts: &Options, rows: (usize, usize)) -> Result<Fit> {
    let band = set.rows(rows.0, rows.1);
    let mut fit = estimate(
        &band,
        &Options {
            rows: None,
            ..opts.clone()
        },
    )?;
    let mut hashed = opts.clone();
    hashed.film_model = hashed.film_model.or(set.film_model);
    fit.rows = rows;
    fit.provenance.rows = rows;
    fit.provenance.image_height = set.height;
    fit.provenance.fit_hash = tiles::fit_hash(set, fit.film_ior, &hashed);
    Ok(fit)
}

/// Keeps the pixels `kept` of a per-pixel map.
fn crop<T>(v: &mut Vec<T>, kept: &std::ops::Range<usize>) {
    v.truncate(kept.end);
    v.drain(..kept.start);
}
