//! Joint refinement stage of `full`: the shared parameters (film index, optionally the
//! substrate, and the nuisance terms of [`super::nuisance`]) together with the
//! thicknesses of a few hundred pixels, on the full forward model.
//!
//! How much of the model is free is chosen by the data: starting from the simplest model
//! (constant index, a free gain per pixel and angle unless the capture declares absolute
//! radiometry, no multiplier, no background), each round tries one extension — one more
//! multiplier term, one more background term, a Cauchy film, a fitted substrate — on a
//! subset of the joint pixels and keeps the one that lowers the Bayesian information
//! criterion most, N_eff ln(χ²/N) + k ln N_eff (N_eff = N / inflation for correlated
//! residuals), by more than [`MIN_IMPROVEMENT`]; it stops when none does. The chosen model
//! is then fitted on every joint pixel, re-searching each pixel's thickness order until it
//! no longer changes.

mod problem;

pub use problem::{JointData, JointFit, Problem, State, Structure};

use super::data::{spread, PixelData};
use super::film::{FilmIndex, FilmModelKind};
use super::nuisance::{Nuisance, NuisanceSpec, Whitening};
use super::solver::{FixedModel, ThicknessSolver};
use super::stage::{Context, FilmSolution, IndexEstimate, RefineStage, SelectionStep};
use anyhow::{bail, Result};
use rayon::prelude::*;

/// Smallest decrease of the criterion that makes a model extension worth keeping
/// ("very strong" evidence on Kass & Raftery's scale).
pub const MIN_IMPROVEMENT: f64 = 10.0;

/// Pixels used to choose the model (the final fit uses all joint pixels).
const SELECTION_PIXELS: usize = 64;

/// The `full` method's refinement stage.
pub struct JointRefine;

/// A model structure being compared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub film: Option<FilmModelKind>,
    pub fit_substrate: bool,
    pub nuisance: NuisanceSpec,
}

impl Candidate {
    fn describe(&self) -> String {
        let film = match self.film {
            Some(k) => format!("{k} film"),
            None => "known film".into(),
        };
        let sub = if self.fit_substrate {
            ", fitted substrate"
        } else {
            ""
        };
        format!("{film}{sub}, {}", self.nuisance.describe())
    }
}

/// Context of the fits of one capture.
pub struct Joint<'a, 'c> {
    pub cx: &'a Context<'c>,
    pub d_min: f64,
    pub d_max: f64,
}

impl<'a, 'c> Joint<'a, 'c> {
    pub fn new(cx: &'a Context<'c>) -> Self {
        Joint {
            cx,
            d_min: cx.opts.min_thickness_nm,
            d_max: cx.opts.max_thickness_nm,
        }
    }

    /// Thickness step limit: a sixth of the shortest fringe.
    fn max_d_step(&self, film: &FilmIndex) -> f64 {
        let g = &self.cx.obs.geom;
        let n = film.n550();
        let kx = g.max_kx().min(n * 0.999);
        g.lambda_min() / (2.0 * (n * n - kx * kx).sqrt()) / 6.0
    }

    /// The problem of fitting `cand` to `data`, thickness steps limited for `film`.
    pub fn problem<'p>(
        &'p self,
        data: &'p JointData,
        cand: &Candidate,
        film: &FilmIndex,
    ) -> Problem<'p> {
        Problem {
            obs: &self.cx.obs,
            data,
            geom: self.cx.obs.geom.clone(),
            sigma: &self.cx.noise.sigma,
            structure: Structure {
                fit_film: cand.film.is_some(),
                fit_substrate: cand.fit_substrate,
                fit_angles: false,
            },
            d_min: self.d_min,
            d_max: self.d_max,
            max_d_step: self.max_d_step(film),
        }
    }

    /// Best thickness of every joint pixel for the model of `st` (global search).
    pub fn search(&self, data: &JointData, st: &State) -> Vec<f64> {
        let obs = &self.cx.obs;
        let fixed = FixedModel {
            geom: &obs.geom,
            film: &st.film,
            substrate_shift: st.substrate_shift,
            nuisance: &st.nuisance,
            sigma: &self.cx.noise.sigma,
        };
        let solver = ThicknessSolver::new(&fixed, self.d_min, self.d_max, true);
        let white = Whitening::new(&st.nuisance, &self.cx.noise.sigma, obs.angles, obs.stride);
        (0..data.pixels.len())
            .into_par_iter()
            .map_init(
                || PixelData::new(obs),
                |px, i| {
                    data.pixel(i, obs, &white, &st.film, px);
                    let d = solver.search(px).0;
                    if d.is_finite() {
                        d
                    } else {
                        0.5 * (self.d_min + self.d_max)
                    }
                },
            )
            .collect()
    }

    /// Fits `cand` from `init` (thicknesses as given), at most `iterations` LM steps.
    pub fn fit(
        &self,
        data: &JointData,
        cand: &Candidate,
        init: &State,
        iterations: usize,
    ) -> JointFit {
        let mut st = init.clone();
        if let Some(kind) = cand.film {
            st.film = st.film.as_kind(kind);
        }
        st.nuisance = st.nuisance.with_spec(cand.nuisance);
        if !cand.fit_substrate {
            st.substrate_shift = 0.0;
        }
        self.problem(data, cand, &st.film).solve(st, iterations)
    }

    /// Fits `cand`, re-searching every pixel's thickness until the orders settle.
    pub fn fit_with_search(
        &self,
        data: &JointData,
        cand: &Candidate,
        init: &State,
        rounds: usize,
    ) -> JointFit {
        let mut st = init.clone();
        st.d = self.search(data, &st);
        let mut fit = self.fit(data, cand, &st, 40);
        for _ in 1..rounds {
            let d = self.search(data, &fit.state);
            let tol = 2.0 * self.max_d_step(&fit.state.film);
            let changed = d
                .iter()
                .zip(&fit.state.d)
                .filter(|(a, b)| (*a - *b).abs() > tol)
                .count();
            if changed == 0 {
                break;
            }
            let mut next = fit.state.clone();
            // Keep a pixel's old thickness where the new one fits no better.
            next.d = d;
            let trial = self.fit(data, cand, &next, 40);
            if trial.chi2 < fit.chi2 {
                fit = trial;
            } else {
                break;
            }
        }
        fit
    }
}

/// Bayesian information criterion with N_eff = N / inflation.
pub(crate) fn criterion(fit: &JointFit, inflation: f64) -> f64 {
    let n = fit.samples as f64;
    let n_eff = (n / inflation).max(2.0);
    n_eff * (fit.chi2 / n).max(1e-300).ln() + fit.globals as f64 * n_eff.ln()
}

/// Extensions of `c` worth trying.
fn extensions(
    cx: &Context,
    c: &Candidate,
    film_auto: bool,
    substrate_auto: bool,
) -> Vec<Candidate> {
    let nb = cx.obs.bands;
    let k_max = (nb / 25).clamp(2, 8);
    let mut out = Vec::new();
    if c.nuisance.free_gain {
        if c.nuisance.multiplier_terms < k_max {
            let mut n = *c;
            n.nuisance.multiplier_terms += 1;
            out.push(n);
        }
        if c.nuisance.background_terms < 2 {
            let mut n = *c;
            n.nuisance.background_terms += 1;
            out.push(n);
        }
    }
    let next_film = match c.film {
        Some(FilmModelKind::Constant) => Some(FilmModelKind::Cauchy),
        Some(FilmModelKind::Cauchy) => Some(FilmModelKind::Cauchy3),
        _ => None,
    };
    if let (true, Some(k)) = (film_auto, next_film) {
        out.push(Candidate {
            film: Some(k),
            ..*c
        });
    }
    if substrate_auto && !c.fit_substrate {
        out.push(Candidate {
            fit_substrate: true,
            ..*c
        });
    }
    out
}

/// Where model selection starts: the joint pixels, the simplest candidate and its state
/// before any thickness is known, and which extensions the options leave to the data.
struct Start {
    /// The film index is fitted (not given).
    fitted: bool,
    pixels: Vec<usize>,
    cand: Candidate,
    blank: State,
    film_auto: bool,
    substrate_auto: bool,
}

impl Start {
    fn new(cx: &Context, first: &IndexEstimate) -> Result<Start> {
        let obs = &cx.obs;
        let opts = cx.opts;
        let fitted = !matches!(first.film, FilmIndex::Known(_));
        let usable = obs.pixels_with_angles(if fitted { 2 } else { 1 });
        if usable.is_empty() {
            bail!(if fitted {
                "no pixel is valid at two or more angles: the film index cannot be estimated"
            } else {
                "no pixel has a usable spectrum"
            });
        }
        let film_kind = if fitted {
            Some(opts.film_model.unwrap_or(FilmModelKind::Constant))
        } else {
            None
        };
        let cand = Candidate {
            film: film_kind,
            fit_substrate: opts.fit_substrate == Some(true),
            nuisance: NuisanceSpec::smallest(obs.radiometry),
        };
        let init_film = match (film_kind, &first.dispersive_start) {
            (Some(FilmModelKind::Constant), _) | (None, _) => first.film.clone(),
            (Some(k), Some(start)) => start.as_kind(k),
            (Some(k), None) => first.film.as_kind(k),
        };
        let blank = State {
            film: init_film,
            substrate_shift: 0.0,
            angle_offsets: vec![0.0; obs.angles],
            nuisance: Nuisance::new(cand.nuisance, obs.angles, &obs.geom.wavelengths_nm),
            d: Vec::new(),
        };
        Ok(Start {
            fitted,
            pixels: spread(&usable, opts.joint_pixels.max(1)),
            cand,
            blank,
            film_auto: fitted && opts.film_model.is_none(),
            substrate_auto: opts.fit_substrate.is_none() && !obs.geom.substrate_absorbs(),
        })
    }
}

/// The outcome of model selection on the subset.
struct Selected {
    cand: Candidate,
    fit: JointFit,
    steps: Vec<SelectionStep>,
    /// Model sensitivity: how far the extensions the data did not ask for move n(550)
    /// and (median, relative) the thicknesses — a model error the noise does not show.
    model_dn: f64,
    model_dd: f64,
}

/// Greedy selection on `sel_data`: each round fits every extension of the current model
/// and keeps the one with the lowest criterion if it beats the current one by more than
/// [`MIN_IMPROVEMENT`].
fn select_model(
    joint: &Joint,
    first: &IndexEstimate,
    sel_data: &JointData,
    start: &Start,
) -> Selected {
    let mut cand = start.cand;
    let mut cur = joint.fit_with_search(sel_data, &cand, &start.blank, 2);
    let mut steps = vec![SelectionStep {
        model: cand.describe(),
        chi2: cur.chi2,
        parameters: cur.globals,
        criterion: criterion(&cur, cur.inflation()),
        chosen: true,
    }];
    loop {
        let infl = cur.inflation();
        let base = criterion(&cur, infl);
        let tried = try_extensions(joint, first, sel_data, start, &cand, &cur);
        let mut best: Option<(usize, f64)> = None;
        for (i, (c, f)) in tried.iter().enumerate() {
            let crit = criterion(f, infl);
            steps.push(SelectionStep {
                model: c.describe(),
                chi2: f.chi2,
                parameters: f.globals,
                criterion: crit,
                chosen: false,
            });
            if crit < base - MIN_IMPROVEMENT && best.is_none_or(|b| crit < b.1) {
                best = Some((i, crit));
            }
        }
        let Some((i, _)) = best else {
            let (model_dn, model_dd) = model_sensitivity(&cur, &tried, start.fitted);
            return Selected {
                cand,
                fit: cur,
                steps,
                model_dn,
                model_dd,
            };
        };
        let n = steps.len() - tried.len() + i;
        steps[n].chosen = true;
        let (c, f) = tried
            .into_iter()
            .nth(i)
            .expect("index of a tried candidate");
        cand = c;
        cur = f;
    }
}

/// Fits every extension of `cand` (worth trying) from the current fit `cur`.
fn try_extensions(
    joint: &Joint,
    first: &IndexEstimate,
    sel_data: &JointData,
    start: &Start,
    cand: &Candidate,
    cur: &JointFit,
) -> Vec<(Candidate, JointFit)> {
    extensions(joint.cx, cand, start.film_auto, start.substrate_auto)
        .into_iter()
        .map(|c| {
            let mut f = joint.fit(sel_data, &c, &cur.state, 15);
            // A dispersive film far from the constant fit: also start from the peaks'
            // dispersion with fresh thickness orders.
            if let (true, Some(start)) = (c.film != cand.film, &first.dispersive_start) {
                let init = State {
                    film: start.clone(),
                    ..cur.state.clone()
                };
                let g = joint.fit_with_search(sel_data, &c, &init, 2);
                if g.chi2 < f.chi2 {
                    f = g;
                }
            }
            (c, f)
        })
        .collect()
}

/// Largest change of n(550) (when the index is fitted) and of the median relative
/// thickness between `cur` and the rejected extensions `tried`.
fn model_sensitivity(cur: &JointFit, tried: &[(Candidate, JointFit)], fitted: bool) -> (f64, f64) {
    let (mut model_dn, mut model_dd) = (0f64, 0f64);
    let n0 = cur.state.film.n550();
    for (_, f) in tried {
        if fitted {
            model_dn = model_dn.max((f.state.film.n550() - n0).abs());
        }
        let mut rel: Vec<f64> = f
            .state
            .d
            .iter()
            .zip(&cur.state.d)
            .filter(|(_, b)| **b > 1.0)
            .map(|(a, b)| ((a - b) / b).abs())
            .collect();
        model_dd = model_dd.max(super::data::median(&mut rel).unwrap_or(0.0));
    }
    (model_dn, model_dd)
}

/// The stage's result from the final fit: parameter σ widened by the model sensitivity
/// (added in quadrature), and the median σ(d)/d the shared parameters cause.
fn solution(
    cx: &Context,
    first: &IndexEstimate,
    sel: Selected,
    fit: &JointFit,
    pixels: Vec<usize>,
) -> FilmSolution {
    let cand = sel.cand;
    let st = &fit.state;
    let nf = if cand.film.is_some() {
        st.film.params().len()
    } else {
        0
    };
    let mut film_param_sigma: Vec<f64> = (0..nf).filter_map(|i| fit.sigma(i)).collect();
    if let Some(s0) = film_param_sigma.first_mut() {
        *s0 = s0.hypot(sel.model_dn);
    }
    let substrate_sigma = cand.fit_substrate.then(|| fit.sigma(nf)).flatten();
    let mut rel: Vec<f64> =
        st.d.iter()
            .zip(&fit.d_sigma_global)
            .filter(|(d, _)| **d > 1.0)
            .map(|(d, s)| s / d)
            .collect();
    let thickness_rel_sigma = super::data::median(&mut rel)
        .unwrap_or(0.0)
        .hypot(sel.model_dd);
    let note = format!(
        "{}; joint Levenberg–Marquardt on {} pixels ({} model, {}; χ²/dof {:.2})",
        first.note,
        pixels.len(),
        match cand.film {
            Some(k) => k.to_string(),
            None => "given".into(),
        },
        cand.nuisance.describe(),
        fit.chi2_red()
    );
    FilmSolution {
        film: st.film.clone(),
        film_param_sigma,
        note,
        substrate_shift: st.substrate_shift,
        substrate_sigma,
        nuisance: st.nuisance.clone(),
        sigma: cx.noise.sigma.clone(),
        thickness_rel_sigma,
        inflation: fit.inflation(),
        joint_pixels: pixels,
        selection: sel.steps,
    }
}

impl RefineStage for JointRefine {
    fn run(&self, cx: &Context, first: IndexEstimate) -> Result<FilmSolution> {
        let start = Start::new(cx, &first)?;
        let joint = Joint::new(cx);
        // Model selection on a subset.
        let pixels = &start.pixels;
        let sel_idx: Vec<usize> = spread(&(0..pixels.len()).collect::<Vec<_>>(), SELECTION_PIXELS);
        let sel_pixels: Vec<usize> = sel_idx.iter().map(|&i| pixels[i]).collect();
        let sel_data = JointData::new(&cx.obs, &sel_pixels);
        let sel = select_model(&joint, &first, &sel_data, &start);
        // Final fit of the chosen model on every joint pixel.
        let data = JointData::new(&cx.obs, pixels);
        let mut init = sel.fit.state.clone();
        init.d.clear();
        let fit = joint.fit_with_search(&data, &sel.cand, &init, 4);
        Ok(solution(cx, &first, sel, &fit, start.pixels))
    }
}
