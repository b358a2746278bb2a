//! The seed's method as published, kept as the baseline: band-quantised peak
//! wavelengths, eq. (12) for n over angle pairs (median), eq. (13) for d with the integer
//! order m picked by least squares on the reflectance, eq. (14). It models calibrated
//! reflectance (no nuisance terms) and gives no index uncertainty.

use super::data::{median, spread};
use super::film::FilmIndex;
use super::index::angle_order;
use super::nuisance::{Nuisance, NuisanceSpec};
use super::peaks;
use super::stage::{
    Context, FilmSolution, IndexEstimate, IndexStage, RefineStage, ThicknessMap, ThicknessStage,
};
use anyhow::{bail, Result};
use rayon::prelude::*;

/// Eq. (12) over every angle pair of band-quantised peaks.
pub struct Eq12Index;
/// No refinement: the index as found, calibrated reflectance.
pub struct NoRefine;
/// Eqs. (13)–(14) per pixel.
pub struct Eq13Thickness;

/// Band-quantised peak (3-band smoothing, 4σ prominence) of every usable angle.
fn peaks_of(cx: &Context, y: &[f32], m: &[bool]) -> Vec<Option<f64>> {
    let (nb, s) = (cx.obs.bands, cx.obs.stride);
    let lambdas = &cx.obs.geom.wavelengths_nm;
    (0..cx.obs.angles)
        .map(|a| {
            if !m[a] {
                return None;
            }
            let ya = &y[a * s..a * s + nb];
            let sigma = peaks::noise_sigma(ya);
            peaks::band_peak(ya, lambdas, (4.0 * sigma).max(0.002)).map(|p| p.lambda_nm)
        })
        .collect()
}

impl IndexStage for Eq12Index {
    fn run(&self, cx: &Context) -> Result<IndexEstimate> {
        let obs = &cx.obs;
        let (na, s) = (obs.angles, obs.stride);
        let order = angle_order(obs.set);
        let sub = spread(&obs.pixels_with_angles(2), 4096);
        let mut ests: Vec<f64> = sub
            .par_iter()
            .map_init(
                || (vec![0f32; na * s], vec![false; na]),
                |(y, m), &p| {
                    obs.get(p, y, m);
                    let pk = peaks_of(cx, y, m);
                    let mut out = Vec::new();
                    for i in 0..order.len() {
                        for j in i + 1..order.len() {
                            let (ai, ki) = order[i];
                            let (aj, kj) = order[j];
                            if let (Some(l1), Some(l2)) = (pk[ai], pk[aj]) {
                                if let Ok(n) = peaks::index_from_pair(l1, ki, l2, kj) {
                                    out.push(n);
                                }
                            }
                        }
                    }
                    out
                },
            )
            .flatten()
            .collect();
        let k = ests.len();
        let n = median(&mut ests).ok_or_else(|| {
            anyhow::anyhow!(
                "paper method: no pixel has peaks at two angles that satisfy eq. (12) \
                 (flat or peak-less spectra, or λ1 = λ2); try --method full or --film-ior"
            )
        })?;
        Ok(IndexEstimate {
            film: FilmIndex::constant(n),
            sigma: None,
            note: format!("eq. (12): median over {k} angle pairs of band-quantised peaks"),
            dispersive_start: None,
        })
    }
}

impl RefineStage for NoRefine {
    fn run(&self, cx: &Context, first: IndexEstimate) -> Result<FilmSolution> {
        let obs = &cx.obs;
        if first.film.n550() <= obs.geom.max_kx() {
            bail!(
                "index {} ≤ n1 sinθ = {:.4}: eq. (13) has no real solution",
                first.film.n550(),
                obs.geom.max_kx()
            );
        }
        Ok(FilmSolution {
            film: first.film,
            film_param_sigma: first.sigma.into_iter().collect(),
            note: first.note,
            substrate_shift: 0.0,
            substrate_sigma: None,
            nuisance: Nuisance::new(NuisanceSpec::ABSOLUTE, obs.angles, &obs.geom.wavelengths_nm),
            sigma: cx.noise.sigma.clone(),
            thickness_rel_sigma: 0.0,
            inflation: 1.0,
            joint_pixels: Vec::new(),
            selection: Vec::new(),
        })
    }
}

impl ThicknessStage for Eq13Thickness {
    fn run(&self, cx: &Context, sol: &FilmSolution) -> Result<ThicknessMap> {
        let obs = &cx.obs;
        let (na, nb, s) = (obs.angles, obs.bands, obs.stride);
        let n = sol.film.n550();
        let m = obs.geom.model_of(&sol.film, 0.0);
        let order = angle_order(obs.set);
        let pb = cx.progress_bar(obs.pixels(), "thickness");
        let sigma2: f64 = cx.noise.typical * cx.noise.typical;
        let band = cx.band();
        let res: Vec<(f32, f32, u32)> = (0..obs.pixels())
            .into_par_iter()
            .map_init(
                || (vec![0f32; na * s], vec![false; na]),
                |(y, mk), p| {
                    let used = if band.contains(&p) {
                        obs.get(p, y, mk)
                    } else {
                        0
                    };
                    if used == 0 {
                        return (f32::NAN, 0.0, 0);
                    }
                    let pk = peaks_of(cx, y, mk);
                    // Eq. (13) per angle with integer m; eq. (14) picks m.
                    let mut best = (f64::NAN, f64::INFINITY);
                    for order_m in 1..200 {
                        let (mut sum, mut cnt) = (0.0, 0);
                        for &(a, kx) in &order {
                            if let Some(l) = pk[a] {
                                sum += order_m as f64 * l / (2.0 * (n * n - kx * kx).sqrt());
                                cnt += 1;
                            }
                        }
                        if cnt == 0 {
                            break;
                        }
                        let d = sum / cnt as f64;
                        if d > cx.opts.max_thickness_nm {
                            break;
                        }
                        let e = m.sse(d, y, s, mk, 1);
                        if e < best.1 {
                            best = (d, e);
                        }
                    }
                    (best.0 as f32, (best.1 / sigma2) as f32, (used * nb) as u32)
                },
            )
            .inspect(|_| pb.inc(1))
            .collect();
        pb.finish_and_clear();
        let nopeak = res.iter().filter(|r| r.2 > 0 && !r.0.is_finite()).count();
        if nopeak > 0 {
            cx.warn(format!(
                "{nopeak} pixels had no peak at any angle: no thickness (eq. 13 needs a peak)"
            ));
        }
        Ok(ThicknessMap {
            d: res.iter().map(|r| r.0).collect(),
            chi2: res
                .iter()
                .map(|r| if r.0.is_finite() { r.1 } else { 0.0 })
                .collect(),
            samples: res.iter().map(|r| r.2).collect(),
            curvature: None,
        })
    }
}
