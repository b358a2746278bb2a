//! Per-pixel thickness fit for a fixed film, substrate and nuisance model: the whitened
//! model m(d) = s·R(d)/σ (tabulated when it fits in memory, see [`super::table`]),
//! a free or unit gain per angle, a coarse scan that covers whole- and half-order fringe
//! positions alike, and damped Gauss–Newton from the best few minima.

use super::data::PixelData;
use super::film::FilmIndex;
use super::model::{FilmModel, Geometry};
use super::nuisance::Nuisance;
use super::table::{padded_bands, AngleSums, GainMode, PassSums, ThicknessTable};

/// Largest thickness table the solver builds; beyond it (very wide thickness ranges or
/// thousands of bands) it evaluates the model directly.
const MAX_TABLE_BYTES: usize = 256 << 20;

/// Everything that is fixed while thicknesses are fitted.
#[derive(Debug, Clone)]
pub struct FixedModel<'a> {
    pub geom: &'a Geometry,
    pub film: &'a FilmIndex,
    pub substrate_shift: f64,
    pub nuisance: &'a Nuisance,
    /// Noise per angle and band.
    pub sigma: &'a [f32],
}

impl<'a> FixedModel<'a> {
    /// The model of a film solution on the capture's geometry.
    pub fn of(geom: &'a Geometry, sol: &'a super::stage::FilmSolution) -> Self {
        FixedModel {
            geom,
            film: &sol.film,
            substrate_shift: sol.substrate_shift,
            nuisance: &sol.nuisance,
            sigma: &sol.sigma,
        }
    }

    /// s_ab/σ_ab per angle and band: the model side of the whitening.
    pub fn model_weights(&self) -> Vec<f32> {
        let (na, nb) = (self.geom.incident_deg.len(), self.geom.wavelengths_nm.len());
        let mut w = vec![0f32; na * nb];
        for a in 0..na {
            for b in 0..nb {
                w[a * nb + b] =
                    (self.nuisance.multiplier_at(a, b) / self.sigma[a * nb + b] as f64) as f32;
            }
        }
        w
    }

    pub fn gain(&self) -> GainMode {
        if self.nuisance.spec.free_gain {
            GainMode::Free
        } else {
            GainMode::Unit
        }
    }
}

/// Thickness search context (see the module doc).
pub struct ThicknessSolver {
    model: FilmModel,
    /// s/σ per angle and band.
    weights: Vec<f32>,
    table: Option<ThicknessTable>,
    gain: GainMode,
    angles: usize,
    bands: usize,
    stride: usize,
    pub d_min: f64,
    pub d_max: f64,
    /// Coarse scan step: 1/8 of a fringe at the shortest wavelength, so some scan point
    /// always lies inside the Gauss–Newton basin of the true thickness.
    pub scan_step: f64,
    max_newton_step: f64,
}

impl ThicknessSolver {
    /// A solver over [d_min, d_max]; `tabulate` builds the thickness table (64 nodes per
    /// scan fringe) when it fits in [`MAX_TABLE_BYTES`] — worth it when many pixels share
    /// the model: building costs about as much as fitting a few hundred pixels directly.
    pub fn new(fixed: &FixedModel, d_min: f64, d_max: f64, tabulate: bool) -> Self {
        let geom = fixed.geom;
        let model = geom.model_of(fixed.film, fixed.substrate_shift);
        let n = fixed.film.n550();
        let kx_min = geom
            .incident_deg
            .iter()
            .map(|a| geom.ambient_ior * a.to_radians().sin())
            .fold(f64::INFINITY, f64::min);
        let n_eff = (n * n - kx_min * kx_min).max(1e-6).sqrt();
        let fringe = geom.lambda_min() / (2.0 * n_eff); // d change for one whole order
        let (angles, bands) = (geom.incident_deg.len(), geom.wavelengths_nm.len());
        let mut s = ThicknessSolver {
            model,
            weights: fixed.model_weights(),
            table: None,
            gain: fixed.gain(),
            angles,
            bands,
            stride: padded_bands(bands),
            d_min,
            d_max,
            scan_step: fringe / 8.0,
            max_newton_step: fringe / 6.0,
        };
        let step = s.scan_step / 8.0;
        if tabulate
            && step > 0.0
            && ThicknessTable::bytes_for(angles, bands, d_min, d_max, step) <= MAX_TABLE_BYTES
        {
            let (model, weights) = (&s.model, &s.weights);
            s.table = Some(ThicknessTable::build(
                angles,
                bands,
                d_min,
                d_max,
                step,
                |d, a, m, dm| {
                    model.spectrum_and_derivative(a, d, m, dm);
                    let w = &weights[a * bands..(a + 1) * bands];
                    for ((m, dm), &w) in m.iter_mut().zip(dm.iter_mut()).zip(w) {
                        *m *= w;
                        *dm *= w;
                    }
                },
            ));
        }
        s
    }

    /// The five sums of angle `a` at (phase-equivalent) thickness `d`.
    #[inline]
    pub fn sums(&self, d: f64, a: usize, ya: &[f32]) -> AngleSums {
        if let Some(t) = &self.table {
            return t.angle_sums(d, a, ya);
        }
        let nb = self.bands;
        let (mut m, mut dm) = (vec![0f32; nb], vec![0f32; nb]);
        self.model.spectrum_and_derivative(a, d, &mut m, &mut dm);
        let w = &self.weights[a * nb..(a + 1) * nb];
        let mut s = AngleSums::default();
        for b in 0..nb {
            let (mv, dv, yv) = (m[b] * w[b], dm[b] * w[b], ya[b]);
            s.my += mv * yv;
            s.mm += mv * mv;
            s.dy += dv * yv;
            s.dm += dv * mv;
            s.dd += dv * dv;
        }
        s
    }

    /// Objective, half-gradient and Hessian of pixel `px` at thickness `d`.
    #[inline]
    pub fn pass(&self, d: f64, px: &PixelData) -> PassSums {
        let s = self.stride;
        let mut out = PassSums::default();
        for a in 0..self.angles {
            if !px.mask[a] {
                continue;
            }
            let rho = px.rho[a];
            let sums = self.sums(d * rho as f64, a, &px.y[a * s..(a + 1) * s]);
            sums.combine(px.yy[a], rho, self.gain, &mut out);
            out.count += self.bands;
        }
        out
    }

    /// Damped Gauss–Newton in d from `d0`: (d, objective, Hessian at d).
    pub fn refine(&self, px: &PixelData, d0: f64, iters: usize) -> (f64, f64, f64) {
        let mut d = d0.clamp(self.d_min, self.d_max);
        let mut cur = self.pass(d, px);
        for _ in 0..iters {
            if !(cur.hess > 0.0) {
                break;
            }
            let mut step =
                (-cur.grad / cur.hess).clamp(-self.max_newton_step, self.max_newton_step);
            if !(step.abs() > 1e-2) {
                break; // converged: 0.01 nm is far below the accuracy needed
            }
            let mut moved = false;
            for _ in 0..6 {
                let dn = (d + step).clamp(self.d_min, self.d_max);
                let nw = self.pass(dn, px);
                if nw.sse <= cur.sse {
                    moved = (dn - d).abs() > 1e-2;
                    d = dn;
                    cur = nw;
                    break;
                }
                step *= 0.5;
            }
            if !moved {
                break;
            }
        }
        (d, cur.sse, cur.hess)
    }

    /// Coarse scan scores (d, objective) over [d_min, d_max] every `scan_step`.
    pub fn scan(&self, px: &PixelData) -> Vec<(f64, f64)> {
        let steps = ((self.d_max - self.d_min) / self.scan_step).ceil() as usize + 1;
        let s = self.stride;
        (0..steps)
            .map(|i| {
                let d = (self.d_min + i as f64 * self.scan_step).min(self.d_max);
                let mut out = PassSums::default();
                for a in 0..self.angles {
                    if !px.mask[a] {
                        continue;
                    }
                    let ya = &px.y[a * s..(a + 1) * s];
                    let da = d * px.rho[a] as f64;
                    let sums = match &self.table {
                        Some(t) => {
                            let (my, mm) = t.node_sums(t.nearest_node(da), a, ya);
                            AngleSums {
                                my,
                                mm,
                                ..AngleSums::default()
                            }
                        }
                        None => self.sums(da, a, ya),
                    };
                    sums.combine(px.yy[a], 1.0, self.gain, &mut out);
                }
                (d, out.sse)
            })
            .collect()
    }

    /// Local minima of a scan, best first.
    pub fn minima(scores: &[(f64, f64)]) -> Vec<(f64, f64)> {
        let mut m: Vec<(f64, f64)> = (0..scores.len())
            .filter(|&i| {
                let s = scores[i].1;
                (i == 0 || scores[i - 1].1 >= s) && (i + 1 == scores.len() || scores[i + 1].1 >= s)
            })
            .map(|i| scores[i])
            .collect();
        m.sort_by(|a, b| a.1.total_cmp(&b.1));
        m
    }

    /// Global search: coarse scan, then Gauss–Newton from the best few local minima.
    /// Returns (d, objective, Hessian).
    pub fn search(&self, px: &PixelData) -> (f64, f64, f64) {
        let minima = Self::minima(&self.scan(px));
        let mut best = (f64::NAN, f64::INFINITY, 0.0);
        for &(d0, _) in minima.iter().take(3) {
            let r = self.refine(px, d0, 8);
            if r.1 < best.1 {
                best = r;
            }
        }
        best
    }

    /// The best fit on another branch than `d` (a minimum further than a quarter fringe
    /// away): (d, objective), for order-ambiguity checks.
    pub fn runner_up(&self, px: &PixelData, d: f64) -> Option<(f64, f64)> {
        let minima = Self::minima(&self.scan(px));
        let far = 2.0 * self.scan_step;
        minima
            .iter()
            .filter(|m| (m.0 - d).abs() > far)
            .take(2)
            .map(|&(d0, _)| self.refine(px, d0, 8))
            .filter(|r| (r.0 - d).abs() > far)
            .map(|r| (r.0, r.1))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}
