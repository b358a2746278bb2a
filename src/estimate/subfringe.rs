//! Films thinner than one fringe under a relative scale. Their thickness is not
//! identifiable independent of the spectral multiplier: a partial fringe is a colour, and a
//! lamp can have the same colour. The multiplier the joint stage fitted comes mostly from
//! thicker films, and on real spectra it carries what only thick films have: their fringe
//! contrast falls towards the blue (thickness variation across the spot, spectrometer
//! resolution: the phase spread 4πn·δd/λ grows as λ falls), which the shared multiplier
//! absorbs as a lamp that rises towards the red. Applied to a sub-fringe film, that "lamp"
//! tilts its colour and biases it thin (measured soap films: 15–25 nm low at 80–125 nm).
//!
//! So the spectra with less than half a fringe (no maximum–minimum pair in band, whose
//! positions would fix the phase whatever the lamp) get a multiplier of their own when
//! there are enough of them with different thicknesses to tell a lamp from a film (point
//! spectra: the lamp is shared, the film colour moves with d): a joint fit of them alone —
//! their thicknesses, a gain each and one multiplier of degree 0 or 1 (a tilt: see
//! [`GROUP_MAX_TERMS`]), the degree chosen by the information criterion, no background (the dark spectrum is
//! subtracted; a free background per group makes a partial fringe and an offset
//! interchangeable). σ covers the chosen fit's covariance, the other degree's thickness
//! and the thickness the shared multiplier gave. With too few
//! such spectra, and for those between half and one fringe, each is refitted with its own gain alone and the better of the two fits
//! is kept, σ covering the distance between them.

use super::checks::fringes;
use super::data::{median, PixelData};
use super::joint::{criterion, Candidate, Joint, JointData, State};
use super::nuisance::{Nuisance, NuisanceSpec, Whitening};
use super::solver::{FixedModel, ThicknessSolver};
use super::stage::{Context, FilmSolution, ThicknessMap};
use crate::capture::Radiometry;
use rayon::prelude::*;

/// Fewest sub-fringe spectra that get a multiplier of their own.
const GROUP_MIN: usize = 4;
/// Their thickness spread in fringes: below it the lamp and the film colour are one shape.
const GROUP_MIN_SPAN: f64 = 0.05;
/// Highest multiplier degree of the group: a partial fringe has at most one extremum in
/// band, and a multiplier with an extremum of its own (degree ≥ 2) takes that shape — on
/// measured soap films degrees 2 and 3 drove 80–125 nm films to 6–100 nm. A tilt cannot.
const GROUP_MAX_TERMS: usize = 1;

/// The sub-fringe spectra's own multiplier.
struct Group {
    nuisance: Nuisance,
    /// Per pixel of the group: thickness of the chosen model and its lamp-shape 1σ.
    d: Vec<f64>,
    spread: Vec<f64>,
}

/// Refits the sub-fringe pixels of `map` (see the module doc); returns per pixel the
/// thickness uncertainty this adds (nm, 0 elsewhere).
pub(super) fn refit(cx: &Context, sol: &FilmSolution, map: &mut ThicknessMap) -> Vec<f32> {
    let obs = &cx.obs;
    let mut shift = vec![0f32; obs.pixels()];
    if map.curvature.is_none() {
        map.curvature = Some(vec![0.0; obs.pixels()]);
    }
    let shared_terms = sol.nuisance.spec.per_angle() > 0 || sol.substrate_shift != 0.0;
    if obs.radiometry == Radiometry::Absolute || !shared_terms {
        return shift;
    }
    let thin: Vec<usize> = (0..obs.pixels())
        .filter(|&p| map.d[p].is_finite() && fringes(cx, sol, map.d[p] as f64) < 1.0)
        .collect();
    if thin.is_empty() {
        return shift;
    }
    // Less than half a fringe: no maximum and minimum pair in band to fix the phase
    // whatever the lamp, so the thickness sits in the colour alone.
    let colour_only: Vec<usize> = thin
        .iter()
        .copied()
        .filter(|&p| fringes(cx, sol, map.d[p] as f64) < 0.5)
        .collect();
    let span = {
        let f: Vec<f64> = colour_only
            .iter()
            .map(|&p| fringes(cx, sol, map.d[p] as f64))
            .collect();
        f.iter().cloned().fold(0.0, f64::max) - f.iter().cloned().fold(1.0, f64::min)
    };
    let group =
        (obs.independent_pixels() && colour_only.len() >= GROUP_MIN && span >= GROUP_MIN_SPAN)
            .then(|| group_fit(cx, sol, &colour_only, map));
    let own = Nuisance::new(
        NuisanceSpec::smallest(obs.radiometry),
        obs.angles,
        &obs.geom.wavelengths_nm,
    );
    let (in_group, alone): (Vec<usize>, Vec<usize>) = match &group {
        Some(_) => thin.iter().partition(|p| colour_only.contains(p)),
        None => (Vec::new(), thin.clone()),
    };
    if let Some(g) = &group {
        let refits = refine(cx, sol, &g.nuisance, &in_group, &g.d);
        for (i, (&p, &(d, chi2, hess))) in in_group.iter().zip(&refits).enumerate() {
            if d.is_finite() {
                // The group's fit replaces the shared one; σ covers both lamp estimates
                // (a curved lamp, which a tilt cannot follow, leaves them far apart).
                let shared = (d - map.d[p] as f64).abs();
                shift[p] = g.spread[i].max((d - g.d[i]).abs()).hypot(shared) as f32;
                store(map, p, (d, chi2, hess));
            }
        }
    }
    let starts: Vec<f64> = alone.iter().map(|&p| map.d[p] as f64).collect();
    let refits = refine(cx, sol, &own, &alone, &starts);
    for (&p, &(d, chi2, hess)) in alone.iter().zip(&refits) {
        if d.is_finite() {
            shift[p] = (d - map.d[p] as f64).abs() as f32;
            // Both fits have the same free parameters per pixel: keep the better.
            if chi2 < map.chi2[p] as f64 {
                store(map, p, (d, chi2, hess));
            }
        }
    }
    warn(
        cx,
        sol,
        &shift,
        (thin.len(), in_group.len()),
        group.as_ref(),
    );
    shift
}

fn store(map: &mut ThicknessMap, p: usize, (d, chi2, hess): (f64, f64, f64)) {
    map.d[p] = d as f32;
    map.chi2[p] = chi2 as f32;
    if let Some(c) = map.curvature.as_mut() {
        c[p] = hess as f32;
    }
}

/// Each of `pixels` refitted from `starts` with `nuisance`: (d, χ², curvature).
fn refine(
    cx: &Context,
    sol: &FilmSolution,
    nuisance: &Nuisance,
    pixels: &[usize],
    starts: &[f64],
) -> Vec<(f64, f64, f64)> {
    let obs = &cx.obs;
    let fixed = FixedModel {
        geom: &obs.geom,
        film: &sol.film,
        substrate_shift: 0.0,
        nuisance,
        sigma: &sol.sigma,
    };
    let solver = ThicknessSolver::new(
        &fixed,
        cx.opts.min_thickness_nm,
        cx.opts.max_thickness_nm,
        pixels.len() > 64,
    );
    let white = Whitening::new(nuisance, &sol.sigma, obs.angles, obs.stride);
    pixels
        .par_iter()
        .zip(starts)
        .map_init(
            || PixelData::new(obs),
            |px, (&p, &start)| {
                px.load(obs, &white, &sol.film, p);
                solver.refine(px, start, 12)
            },
        )
        .collect()
}

/// Joint fit of the sub-fringe pixels with a multiplier of their own, its degree chosen
/// by the information criterion.
fn group_fit(cx: &Context, sol: &FilmSolution, thin: &[usize], map: &ThicknessMap) -> Group {
    let obs = &cx.obs;
    let data = JointData::new(obs, thin);
    let joint = Joint::new(cx);
    let init = State {
        film: sol.film.clone(),
        substrate_shift: 0.0,
        angle_offsets: vec![0.0; obs.angles],
        nuisance: Nuisance::new(
            NuisanceSpec::smallest(obs.radiometry),
            obs.angles,
            &obs.geom.wavelengths_nm,
        ),
        d: thin.iter().map(|&p| map.d[p] as f64).collect(),
    };
    let fits: Vec<_> = (0..=GROUP_MAX_TERMS)
        .map(|k| {
            let cand = Candidate {
                film: None,
                fit_substrate: false,
                nuisance: NuisanceSpec {
                    free_gain: true,
                    multiplier_terms: k,
                    background_terms: 0,
                },
            };
            joint.fit(&data, &cand, &init, 60)
        })
        .collect();
    // One residual-correlation inflation for every degree, so the criteria compare like
    // with like (the largest: the fewest effective samples, the weakest evidence).
    let inflation = fits.iter().map(|f| f.inflation()).fold(1.0, f64::max);
    let best = (0..fits.len())
        .min_by(|&a, &b| criterion(&fits[a], inflation).total_cmp(&criterion(&fits[b], inflation)))
        .expect("at least one degree");
    let chosen = &fits[best].state;
    let spread = (0..thin.len())
        .map(|i| {
            let between = fits
                .iter()
                .map(|f| (f.state.d[i] - chosen.d[i]).abs())
                .fold(0.0, f64::max);
            let within = fits[best].d_sigma_global.get(i).copied().unwrap_or(0.0);
            within.hypot(between)
        })
        .collect();
    Group {
        nuisance: chosen.nuisance.clone(),
        d: chosen.d.clone(),
        spread,
    }
}

fn warn(
    cx: &Context,
    sol: &FilmSolution,
    shift: &[f32],
    (thin, grouped): (usize, usize),
    group: Option<&Group>,
) {
    let mut shifts: Vec<f64> = shift
        .iter()
        .filter(|s| **s > 0.0)
        .map(|&s| s as f64)
        .collect();
    let typical = median(&mut shifts).unwrap_or(0.0);
    cx.warn(match group {
        Some(g) => format!(
            "{thin} spectra have less than one interference fringe: their thickness depends \
             on the spectral multiplier, which the thicker films' fit ({}) does not fix for \
             them; the {grouped} with less than half a fringe were fitted together with a \
             multiplier of their own ({}), and σ \
             covers it, a flat one and the shared one (median {typical:.1} nm)",
            sol.nuisance.spec.describe(),
            g.nuisance.spec.describe()
        ),
        None => format!(
            "{thin} spectra have less than one interference fringe: their thickness depends \
             on the shared spectral multiplier, background and substrate terms fitted mostly \
             from thicker films ({}); each was also fitted with only its own gain, the better \
             fit kept, and σ covers both (median shift {typical:.1} nm)",
            sol.nuisance.spec.describe()
        ),
    });
}
