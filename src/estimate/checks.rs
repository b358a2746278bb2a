//! Report stage, common to every method: the per-pixel thickness uncertainty, the
//! identifiability of thin films, and model checks that say *why* the residual is far
//! above the noise when it is.
//!
//! σ(d) per pixel = √(σ_noise² + σ_shared² + σ_nuisance²):
//! - σ_noise² = κ · max(1, χ²_p/dof_p) / H_p, H_p the Gauss–Newton curvature of the pixel's
//!   noise-weighted χ² in d (gain projected out), κ the correlation inflation of the joint
//!   fit's residuals (AR(1): (1 + ρ)/(1 − ρ));
//! - σ_shared = (σ(d)/d from the shared parameters' covariance, median over the joint
//!   pixels) · d — the film index and nuisance terms move every thickness together;
//! - σ_nuisance: for a pixel with less than one fringe under a relative scale, the shift of
//!   its thickness when the shared nuisance terms (multiplier, background, substrate) are
//!   replaced by its own gain alone — such a thickness is not identifiable independent of
//!   those terms, which the thicker pixels fixed (see `sub_fringe_nuisance`);
//! - for independent spectra (no spatial prior), a competing fringe order whose χ² is
//!   within 9 (3σ) of the best widens σ to cover it.

use super::data::{spread, PixelData};
use super::film::FilmModelKind;
use super::joint::{Candidate, Joint, JointData, State, Structure};
use super::nuisance::{NuisanceSpec, Whitening};
use super::solver::{FixedModel, ThicknessSolver};
use super::stage::{Context, FilmSolution, ThicknessMap};
use crate::capture::{Polarization, Radiometry};
use rayon::prelude::*;

/// χ²/dof above which the model is reported as not explaining the data.
pub const CHI2_WARN: f64 = 1.5;

/// Residual RMS (data units) below which a fit is perfect whatever its χ²/dof: what the
/// per-pixel stage's single-precision model reproduces (measured: 2.7·10⁻⁵ RMS on a
/// noise-free simulated capture of reflectances ~0.1–0.3, against a noise estimate of
/// 9·10⁻⁷ from the float32 cubes' rounding). Without it χ²/dof ≈ 900 called the model's own
/// precision a misfit; real instruments' noise is well above this.
const MODEL_PRECISION: f64 = 1e-4;

/// What the checks found.
#[derive(Debug, Clone, Default)]
pub struct Checked {
    /// 1σ thickness per pixel, nm (NaN where no thickness).
    pub sigma: Vec<f32>,
    /// Pixels whose thickness cannot be identified (< 1 fringe, no absolute reference).
    pub not_identifiable: usize,
    /// Pixels with a competing fringe order within 3σ.
    pub ambiguous: usize,
    /// χ²/dof over every fitted pixel.
    pub chi2_red: f64,
}

/// Fringes across the band of a film of thickness `d`: 2 d n_eff (1/λmin − 1/λmax).
pub fn fringes(cx: &Context, sol: &FilmSolution, d: f64) -> f64 {
    let g = &cx.obs.geom;
    let n = sol.film.n550();
    let kx = g.max_kx().min(n * 0.999);
    2.0 * d * (n * n - kx * kx).sqrt() * (1.0 / g.lambda_min() - 1.0 / g.lambda_max())
}

/// Runs the checks, fills missing curvatures, blanks unidentifiable pixels.
pub fn run(cx: &Context, sol: &FilmSolution, map: &mut ThicknessMap) -> Checked {
    let obs = &cx.obs;
    let fixed = FixedModel::of(&obs.geom, sol);
    let white = Whitening::new(&sol.nuisance, &sol.sigma, obs.angles, obs.stride);
    let independent = obs.independent_pixels();
    let need_solver = map.curvature.is_none() || independent;
    let solver = need_solver.then(|| {
        ThicknessSolver::new(
            &fixed,
            cx.opts.min_thickness_nm,
            cx.opts.max_thickness_nm,
            obs.pixels() > 64,
        )
    });
    // Curvature, χ² and order ambiguity per pixel where needed.
    let extra: Vec<(f32, f32, f32)> = (0..obs.pixels())
        .into_par_iter()
        .map_init(
            || PixelData::new(obs),
            |px, p| {
                let d = map.d[p];
                let (Some(s), true) = (&solver, d.is_finite()) else {
                    return (f32::NAN, f32::NAN, 0.0);
                };
                px.load(obs, &white, &sol.film, p);
                let pass = s.pass(d as f64, px);
                let alt = if independent {
                    s.runner_up(px, d as f64)
                        .filter(|r| {
                            r.1 - pass.sse < 9.0 * (pass.sse / px.samples.max(2) as f64).max(1.0)
                        })
                        .map(|r| (r.0 - d as f64).abs() as f32)
                        .unwrap_or(0.0)
                } else {
                    0.0
                };
                (pass.hess as f32, pass.sse as f32, alt)
            },
        )
        .collect();
    if map.curvature.is_none() {
        map.curvature = Some(extra.iter().map(|e| e.0).collect());
        for (c, e) in map.chi2.iter_mut().zip(&extra) {
            if e.1.is_finite() {
                *c = e.1;
            }
        }
    }
    // Thin-film identifiability: with relative radiometry and a single angle, the shape
    // of less than one fringe is indistinguishable from the spectral multiplier unless
    // other pixels with whole fringes fix that multiplier.
    let blank_thin = obs.radiometry != Radiometry::Absolute
        && obs.angles == 1
        && !anchored(cx, sol, &fixed, &white);
    let nuisance_shift = if blank_thin {
        vec![0f32; obs.pixels()]
    } else {
        super::subfringe::refit(cx, sol, map)
    };
    let curv = map.curvature.as_ref().expect("filled above");
    let gains = if sol.nuisance.spec.free_gain {
        1.0
    } else {
        0.0
    };
    let mut out = Checked {
        sigma: vec![f32::NAN; obs.pixels()],
        ..Checked::default()
    };
    let (mut chi_sum, mut dof_sum) = (0.0, 0.0);
    for p in 0..obs.pixels() {
        let d = map.d[p] as f64;
        if !d.is_finite() {
            continue;
        }
        if blank_thin && fringes(cx, sol, d) < 1.0 {
            map.d[p] = f32::NAN;
            out.not_identifiable += 1;
            continue;
        }
        let n = map.samples[p] as f64;
        let dof = (n - 1.0 - gains * (n / obs.bands as f64)).max(1.0);
        let chi = map.chi2[p] as f64;
        chi_sum += chi;
        dof_sum += dof;
        let s2 = (chi / dof).max(1.0) * sol.inflation;
        let h = curv[p] as f64;
        let noise = if h > 0.0 {
            (s2 / h).sqrt()
        } else {
            f64::INFINITY
        };
        let shared = sol.thickness_rel_sigma * d;
        let shift = nuisance_shift[p] as f64;
        let mut sigma = (noise * noise + shared * shared + shift * shift).sqrt();
        let alt = extra[p].2 as f64;
        if alt > 0.0 {
            sigma = sigma.max(alt);
            out.ambiguous += 1;
        }
        out.sigma[p] = sigma as f32;
    }
    out.chi2_red = if dof_sum > 0.0 {
        chi_sum / dof_sum
    } else {
        f64::NAN
    };
    if out.not_identifiable > 0 {
        cx.warn(format!(
            "{} of {} spectra have less than one interference fringe in {:.0}–{:.0} nm: \
             their thickness is not identifiable without an absolute reference (the spectral \
             shape of a partial fringe is indistinguishable from the lamp and camera response); \
             set \"radiometry\": \"absolute\" for calibrated reflectance, or fit them together \
             with thicker films of the same setup",
            out.not_identifiable,
            cx.band().len(),
            obs.geom.lambda_min(),
            obs.geom.lambda_max()
        ));
    }
    if out.ambiguous > 0 {
        cx.warn(format!(
            "{} pixels have a second thickness (another fringe order) that fits within 3σ: \
             their σ covers both",
            out.ambiguous
        ));
    }
    if out.chi2_red > CHI2_WARN && out.chi2_red.sqrt() * cx.noise.typical > MODEL_PRECISION {
        diagnose(cx, sol, out.chi2_red);
    }
    out
}

/// Whether at least two pixels of the joint fit — those that fixed the shared multiplier —
/// hold a whole fringe, by their own best thickness (a global search each, so that a band
/// of rows decides as the whole fit does without the other rows' thickness).
fn anchored(cx: &Context, sol: &FilmSolution, fixed: &FixedModel, white: &Whitening) -> bool {
    let obs = &cx.obs;
    let solver = ThicknessSolver::new(
        fixed,
        cx.opts.min_thickness_nm,
        cx.opts.max_thickness_nm,
        obs.pixels() > 64,
    );
    let whole: usize = sol
        .joint_pixels
        .par_iter()
        .map_init(
            || PixelData::new(obs),
            |px, &p| {
                if px.load(obs, white, &sol.film, p) == 0 {
                    return 0;
                }
                let d = solver.search(px).0;
                usize::from(d.is_finite() && fringes(cx, sol, d) >= 1.0)
            },
        )
        .sum();
    whole >= 2
}

/// Tries the likely causes of a bad fit on a subset of pixels and reports the best.
fn diagnose(cx: &Context, sol: &FilmSolution, chi2_red: f64) {
    let obs = &cx.obs;
    let pixels = spread(&sol.joint_pixels, 64);
    let data = JointData::new(obs, &pixels);
    let joint = Joint::new(cx);
    let fitted = sol.film.kind().is_some();
    let base_cand = Candidate {
        film: sol.film.kind(),
        fit_substrate: sol.substrate_sigma.is_some(),
        nuisance: sol.nuisance.spec,
    };
    let mut init = State {
        film: sol.film.clone(),
        substrate_shift: sol.substrate_shift,
        angle_offsets: vec![0.0; obs.angles],
        nuisance: sol.nuisance.clone(),
        d: Vec::new(),
    };
    init.d = joint.search(&data, &init);
    let base = joint.fit(&data, &base_cand, &init, 20);
    let base_red = base.chi2_red();
    let mut causes: Vec<(String, f64)> = Vec::new();
    if fitted && sol.film.kind() == Some(FilmModelKind::Constant) {
        let f = joint.fit(
            &data,
            &Candidate {
                film: Some(FilmModelKind::Cauchy),
                ..base_cand
            },
            &init,
            20,
        );
        let (a, b, _) = f.state.film.cauchy_coefficients().unwrap_or_default();
        causes.push((
            format!(
                "a dispersive film (Cauchy A = {a:.4}, B = {b:.0} nm²; rerun with --film-model cauchy)"
            ),
            f.chi2_red(),
        ));
    }
    if !sol.nuisance.spec.free_gain {
        let f = joint.fit(
            &data,
            &Candidate {
                nuisance: NuisanceSpec {
                    free_gain: true,
                    multiplier_terms: 2,
                    background_terms: 1,
                },
                ..base_cand
            },
            &init,
            20,
        );
        causes.push((
            "the capture is not absolutely calibrated (remove \"radiometry\": \"absolute\")".into(),
            f.chi2_red(),
        ));
    }
    for pol in [Polarization::S, Polarization::P, Polarization::Unpolarized] {
        if pol == obs.geom.polarization {
            continue;
        }
        let mut prob = joint.problem(&data, &base_cand, &sol.film);
        prob.geom.polarization = pol;
        let mut st = init.clone();
        st.d = init.d.clone();
        let f = prob.solve(st, 20);
        causes.push((
            format!(
                "the wrong polarisation (the data fit {} better)",
                serde_json::to_value(pol)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default()
            ),
            f.chi2_red(),
        ));
    }
    if obs.angles >= 2 || !fitted {
        let mut prob = joint.problem(&data, &base_cand, &sol.film);
        prob.structure = Structure {
            fit_angles: true,
            ..prob.structure
        };
        let f = prob.solve(init.clone(), 20);
        let offs: Vec<String> = f
            .state
            .angle_offsets
            .iter()
            .map(|o| format!("{o:+.2}°"))
            .collect();
        causes.push((
            format!(
                "wrong incidence angles (fitted offsets {}; or the angle varies across the \
                 image: give per-pixel angles in capture.json)",
                offs.join(", ")
            ),
            f.chi2_red(),
        ));
    }
    let best = causes
        .iter()
        .filter(|c| c.1 < 0.8 * base_red)
        .min_by(|a, b| a.1.total_cmp(&b.1));
    let noise = cx.noise.typical;
    let head = format!(
        "the model does not explain the data: residual χ²/dof = {chi2_red:.2} (RMS {:.3e} against \
         an estimated noise of {noise:.3e})",
        chi2_red.sqrt() * noise
    );
    cx.warn(match best {
        Some((what, red)) => format!(
            "{head}; likely cause: {what} — that model brings χ²/dof from {base_red:.2} to {red:.2} \
             on {} pixels",
            pixels.len()
        ),
        None => format!(
            "{head}; none of dispersion, polarisation, angle offsets or calibration explains it \
             (texture, scattering, a multilayer or a wrong substrate are other causes)"
        ),
    });
}
