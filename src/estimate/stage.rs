//! The estimator as a pipeline of stages with typed hand-overs:
//!
//! ```text
//! Observations + NoiseEstimate ─▶ IndexStage ─▶ IndexEstimate
//!                                 RefineStage ─▶ FilmSolution   (film index, substrate, nuisance, σ's)
//!                                 ThicknessStage ─▶ ThicknessMap (d per pixel, χ², curvature)
//!                                 checks (common) ─▶ σ(d) map, warnings
//! ```
//!
//! A method ([`super::Method`]) is one [`Pipeline`]: which implementation runs each stage.
//! `full` = peaks → joint refinement → tabulated thickness; `paper` = the seed's eq. (12)
//! → nothing → eqs. (13)–(14); `grid` = exhaustive index search → nothing → thickness
//! grid. A new method implements the stage it changes ([`IndexStage`], [`RefineStage`] or
//! [`ThicknessStage`]) in its own module and adds one line to [`super::Method::pipeline`].

use super::data::Observations;
use super::film::FilmIndex;
use super::noise::NoiseEstimate;
use super::nuisance::Nuisance;
use super::Options;
use anyhow::Result;
use std::sync::Mutex;

/// What every stage sees.
pub struct Context<'a> {
    pub obs: Observations<'a>,
    pub opts: &'a Options,
    pub noise: NoiseEstimate,
    /// Rows `[A, B)` whose thickness the per-pixel stages fit (every row unless a band fit,
    /// [`super::tiles`]); the global stages always see the whole capture.
    pub rows: (usize, usize),
    warnings: Mutex<Vec<String>>,
}

impl<'a> Context<'a> {
    /// A context for a fit of every row.
    pub fn new(obs: Observations<'a>, opts: &'a Options, noise: NoiseEstimate) -> Self {
        let rows = (0, obs.height);
        Context {
            obs,
            opts,
            noise,
            rows,
            warnings: Mutex::new(Vec::new()),
        }
    }

    /// The pixels (capture indices) of [`Context::rows`]: outside them per-pixel stages
    /// leave NaN.
    pub fn band(&self) -> std::ops::Range<usize> {
        self.rows.0 * self.obs.width..self.rows.1 * self.obs.width
    }

    /// Records a warning for `fit.json` and the console.
    pub fn warn(&self, message: impl Into<String>) {
        if let Ok(mut w) = self.warnings.lock() {
            w.push(message.into());
        }
    }

    pub fn take_warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .map(|mut w| std::mem::take(&mut *w))
            .unwrap_or_default()
    }

    /// A progress bar over `len` pixels (hidden unless the options ask for one).
    pub fn progress_bar(&self, len: usize, what: &str) -> indicatif::ProgressBar {
        if !self.opts.progress {
            return indicatif::ProgressBar::hidden();
        }
        let pb = indicatif::ProgressBar::new(len as u64);
        pb.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg:>12} [{bar:40}] {pos}/{len} px ({eta} left)",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        pb.set_message(what.to_string());
        pb
    }
}

/// First film index (before any joint fit).
#[derive(Debug, Clone)]
pub struct IndexEstimate {
    pub film: FilmIndex,
    /// 1σ of n(550 nm), when the stage gives one.
    pub sigma: Option<f64>,
    /// How it was obtained.
    pub note: String,
    /// A dispersive (Cauchy) starting point, when the stage sees dispersion.
    pub dispersive_start: Option<FilmIndex>,
}

/// One step of the model selection (as written in fit.json).
pub use crate::material::ModelSelectionStep as SelectionStep;

/// Film, substrate and nuisance terms shared by every pixel, with their uncertainty.
#[derive(Debug, Clone)]
pub struct FilmSolution {
    pub film: FilmIndex,
    /// 1σ of each fitted film parameter (empty when the index was given).
    pub film_param_sigma: Vec<f64>,
    pub note: String,
    /// Fitted change of the substrate's real index (0 when not fitted).
    pub substrate_shift: f64,
    /// 1σ of the substrate shift, when fitted.
    pub substrate_sigma: Option<f64>,
    pub nuisance: Nuisance,
    /// Noise σ per angle and band used to weight every fit.
    pub sigma: Vec<f32>,
    /// σ(d)/d caused by the uncertainty of the shared parameters.
    pub thickness_rel_sigma: f64,
    /// Variance inflation for correlated residuals (≥ 1), applied to per-pixel σ(d).
    pub inflation: f64,
    /// Pixels of the joint fit.
    pub joint_pixels: Vec<usize>,
    /// Model selection record.
    pub selection: Vec<SelectionStep>,
}

impl FilmSolution {
    /// 1σ of n(550 nm), when the index was fitted.
    pub fn film_sigma(&self) -> Option<f64> {
        self.film_param_sigma.first().copied()
    }
}

/// Per-pixel thickness fit.
#[derive(Debug, Clone)]
pub struct ThicknessMap {
    /// nm; NaN where no thickness was fitted.
    pub d: Vec<f32>,
    /// Noise-weighted residual Σ(e/σ)² per pixel.
    pub chi2: Vec<f32>,
    /// Samples per pixel.
    pub samples: Vec<u32>,
    /// Gauss–Newton curvature ½∂²χ²/∂d² at the fit (None: computed by the checks).
    pub curvature: Option<Vec<f32>>,
}

/// First index from the data.
pub trait IndexStage: Sync {
    fn run(&self, cx: &Context) -> Result<IndexEstimate>;
}

/// Shared parameters from the first index.
pub trait RefineStage: Sync {
    fn run(&self, cx: &Context, first: IndexEstimate) -> Result<FilmSolution>;
}

/// Thickness of every pixel for a solved film.
pub trait ThicknessStage: Sync {
    fn run(&self, cx: &Context, film: &FilmSolution) -> Result<ThicknessMap>;
}

/// Which implementation runs each stage.
pub struct Pipeline {
    pub index: &'static dyn IndexStage,
    pub refine: &'static dyn RefineStage,
    pub thickness: &'static dyn ThicknessStage,
    /// Stage names for timings.
    pub names: [&'static str; 3],
}
