//! The joint least-squares problem on a subset of pixels: shared parameters θ (film index
//! coefficients, optionally a substrate index shift and per-angle incidence offsets, the
//! nuisance terms of every angle) and one thickness d_p per pixel, with the gain of every
//! pixel and angle eliminated analytically (variable projection, Kaufman's Jacobian).
//!
//! Levenberg–Marquardt on the block-arrow normal equations: the d block is diagonal, so
//! each step solves the small dense Schur complement in θ and back-substitutes d. The
//! same blocks give θ's covariance: the Schur complement's inverse scaled by the residual
//! variance and a correlation inflation, or the cluster-robust ("sandwich") estimate with
//! one cluster per pixel, whichever is larger — so a model that does not fit the data
//! reports a larger uncertainty instead of the noise-only one.

use super::super::data::{Observations, PixelData};
use super::super::film::FilmIndex;
use super::super::linalg::{cholesky, cholesky_solve, spd_inverse};
use super::super::model::{FilmModel, Geometry};
use super::super::nuisance::Nuisance;
use rayon::prelude::*;

/// Which shared parameters are free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Structure {
    /// Fit the film index coefficients (false: index known).
    pub fit_film: bool,
    pub fit_substrate: bool,
    /// One incidence offset per angle (model checks only).
    pub fit_angles: bool,
}

/// The joint pixels' raw spectra.
pub struct JointData {
    pub pixels: Vec<usize>,
    /// Per pixel: `angles × stride` raw values.
    y: Vec<Vec<f32>>,
    mask: Vec<Vec<bool>>,
}

impl JointData {
    pub fn new(obs: &Observations, pixels: &[usize]) -> Self {
        let (y, mask) = pixels
            .par_iter()
            .map(|&p| {
                let mut y = vec![0f32; obs.angles * obs.stride];
                let mut m = vec![false; obs.angles];
                obs.get(p, &mut y, &mut m);
                (y, m)
            })
            .unzip();
        JointData {
            pixels: pixels.to_vec(),
            y,
            mask,
        }
    }

    /// A pixel's data as [`PixelData`] whitened with `white` (for thickness searches).
    pub fn pixel(
        &self,
        i: usize,
        obs: &Observations,
        white: &super::super::nuisance::Whitening,
        film: &FilmIndex,
        out: &mut PixelData,
    ) {
        out.y.copy_from_slice(&self.y[i]);
        out.mask.copy_from_slice(&self.mask[i]);
        out.used = out.mask.iter().filter(|&&m| m).count();
        out.samples = out.used * obs.bands;
        white.apply(&mut out.y, &out.mask, &mut out.yy);
        obs.rho(self.pixels[i], film.n550(), &mut out.rho);
    }
}

/// Values of every parameter.
#[derive(Debug, Clone)]
pub struct State {
    pub film: FilmIndex,
    pub substrate_shift: f64,
    /// Degrees, per angle.
    pub angle_offsets: Vec<f64>,
    pub nuisance: Nuisance,
    /// Per joint pixel, nm.
    pub d: Vec<f64>,
}

/// Per-pixel blocks of the normal equations.
#[derive(Debug, Clone, Default)]
struct PixelLin {
    hdd: f64,
    gd: f64,
    /// H_dθ (length G).
    hdg: Vec<f64>,
    /// ∂χ²/2∂θ of this pixel alone (length G).
    score: Vec<f64>,
}

/// χ² and (optionally) the linearisation at a state.
struct Evaluation {
    chi2: f64,
    samples: usize,
    free_gains: usize,
    /// Σ e_b e_{b+1} and Σ e_b² over neighbouring bands (residual correlation).
    lag: (f64, f64),
    pixels: Vec<PixelLin>,
    hgg: Vec<f64>,
    gg: Vec<f64>,
}

/// A converged joint fit.
#[derive(Debug, Clone)]
pub struct JointFit {
    pub state: State,
    pub chi2: f64,
    pub samples: usize,
    pub dof: f64,
    /// Shared parameters (G).
    pub globals: usize,
    /// Lag-1 correlation of neighbouring-band residuals.
    pub residual_correlation: f64,
    /// Covariance of θ (G×G, parameter order of [`Problem::pack`]), when it exists.
    pub cov: Option<Vec<f64>>,
    /// Per pixel: 1σ of d from the shared parameters alone.
    pub d_sigma_global: Vec<f64>,
}

impl JointFit {
    pub fn chi2_red(&self) -> f64 {
        self.chi2 / self.dof.max(1.0)
    }

    /// Variance inflation for correlated residuals, (1 + ρ)/(1 − ρ) (AR(1) model).
    pub fn inflation(&self) -> f64 {
        let r = self.residual_correlation.clamp(0.0, 0.98);
        (1.0 + r) / (1.0 - r)
    }

    /// 1σ of global parameter `i`.
    pub fn sigma(&self, i: usize) -> Option<f64> {
        self.cov
            .as_ref()
            .map(|c| c[i * self.globals + i].max(0.0).sqrt())
    }
}

/// Problem definition (see the module doc).
pub struct Problem<'a> {
    pub obs: &'a Observations<'a>,
    pub data: &'a JointData,
    /// Geometry (polarisation may differ from the capture's for model checks).
    pub geom: Geometry,
    pub sigma: &'a [f32],
    pub structure: Structure,
    pub d_min: f64,
    pub d_max: f64,
    /// Largest thickness step per iteration (a fraction of a fringe: no order jumps).
    pub max_d_step: f64,
}

/// A finite-difference parameter: its index in θ, step, model, and the one angle it
/// affects (None: all).
struct FdParam {
    index: usize,
    step: f64,
    model: FilmModel,
    angle: Option<usize>,
}

/// The column index of a pixel's own thickness among an angle's local Jacobian columns
/// (the others are θ indices).
const D_COLUMN: usize = usize::MAX;

/// What every pixel's evaluation shares at one state.
struct EvalSetup<'s> {
    st: &'s State,
    /// Build the normal-equation blocks (else χ² only).
    lin: bool,
    /// G, and the offset of the nuisance block in θ.
    g_count: usize,
    nuis_off: usize,
    /// The model at `st`, and one model per finite-difference parameter (when `lin`).
    m0: FilmModel,
    fd: Vec<FdParam>,
    n550: f64,
    /// Per angle and band: s_ab/σ_ab (multiplier over noise), c_ab (background), 1/σ_ab.
    sw: Vec<f64>,
    cb: Vec<f64>,
    w: Vec<f64>,
}

/// One pixel's working rows at one angle (length: bands).
struct AngleRows {
    /// Model spectrum, its thickness derivative, a finite-difference model's spectrum.
    r: Vec<f32>,
    dr: Vec<f32>,
    rf: Vec<f32>,
    /// Whitened data minus background, whitened model, residual g·m − y.
    yt: Vec<f64>,
    mt: Vec<f64>,
    e: Vec<f64>,
    /// Local Jacobian columns: (θ index, or [`D_COLUMN`]; values per band).
    cols: Vec<(usize, Vec<f64>)>,
}

impl AngleRows {
    fn new(nb: usize) -> Self {
        AngleRows {
            r: vec![0f32; nb],
            dr: vec![0f32; nb],
            rf: vec![0f32; nb],
            yt: vec![0f64; nb],
            mt: vec![0f64; nb],
            e: vec![0f64; nb],
            cols: Vec::new(),
        }
    }
}

/// Sums of an evaluation over pixels (one per rayon fold, then merged).
struct Acc {
    chi2: f64,
    samples: usize,
    gains: usize,
    lag: (f64, f64),
    hgg: Vec<f64>,
    gg: Vec<f64>,
    px: Vec<(usize, PixelLin)>,
}

impl Acc {
    fn new(lin: bool, g_count: usize) -> Self {
        Acc {
            chi2: 0.0,
            samples: 0,
            gains: 0,
            lag: (0.0, 0.0),
            hgg: vec![0.0; if lin { g_count * g_count } else { 0 }],
            gg: vec![0.0; if lin { g_count } else { 0 }],
            px: Vec::new(),
        }
    }

    fn merge(mut self, b: Acc) -> Acc {
        self.chi2 += b.chi2;
        self.samples += b.samples;
        self.gains += b.gains;
        self.lag.0 += b.lag.0;
        self.lag.1 += b.lag.1;
        for (x, y) in self.hgg.iter_mut().zip(&b.hgg) {
            *x += y;
        }
        for (x, y) in self.gg.iter_mut().zip(&b.gg) {
            *x += y;
        }
        self.px.extend(b.px);
        self
    }

    /// The evaluation, pixel blocks in joint-pixel order.
    fn into_evaluation(self) -> Evaluation {
        let mut px = self.px;
        px.sort_by_key(|x| x.0);
        Evaluation {
            chi2: self.chi2,
            samples: self.samples,
            free_gains: self.gains,
            lag: self.lag,
            pixels: px.into_iter().map(|x| x.1).collect(),
            hgg: self.hgg,
            gg: self.gg,
        }
    }
}

/// Adds one angle's local columns to the normal equations: the gradient (column ·
/// residual) and the Gauss–Newton Hessian (column · column), split into the pixel's own
/// d entries (`pl`) and the shared θ blocks (`acc`).
fn add_normal_blocks(
    cols: &[(usize, Vec<f64>)],
    e: &[f64],
    g_count: usize,
    pl: &mut PixelLin,
    acc: &mut Acc,
) {
    for (ci, (ii, vi)) in cols.iter().enumerate() {
        let ge: f64 = vi.iter().zip(e).map(|(x, y)| x * y).sum();
        if *ii == D_COLUMN {
            pl.gd += ge;
        } else {
            acc.gg[*ii] += ge;
            pl.score[*ii] += ge;
        }
        for (jj, vj) in cols[ci..].iter() {
            let h: f64 = vi.iter().zip(vj).map(|(x, y)| x * y).sum();
            match (*ii == D_COLUMN, *jj == D_COLUMN) {
                (true, true) => pl.hdd += h,
                (true, false) => pl.hdg[*jj] += h,
                (false, true) => pl.hdg[*ii] += h,
                (false, false) => {
                    acc.hgg[ii * g_count + jj] += h;
                    if ii != jj {
                        acc.hgg[jj * g_count + ii] += h;
                    }
                }
            }
        }
    }
}

impl Problem<'_> {
    fn film_params(&self, st: &State) -> usize {
        if self.structure.fit_film {
            st.film.params().len()
        } else {
            0
        }
    }

    /// Offset of the nuisance block in θ.
    fn nuisance_offset(&self, st: &State) -> usize {
        self.film_params(st)
            + usize::from(self.structure.fit_substrate)
            + if self.structure.fit_angles {
                self.obs.angles
            } else {
                0
            }
    }

    pub fn globals(&self, st: &State) -> usize {
        self.nuisance_offset(st) + st.nuisance.to_vec().len()
    }

    /// θ in order: film, substrate, angle offsets, nuisance.
    pub fn pack(&self, st: &State) -> Vec<f64> {
        let mut v = Vec::new();
        if self.structure.fit_film {
            v.extend_from_slice(st.film.params());
        }
        if self.structure.fit_substrate {
            v.push(st.substrate_shift);
        }
        if self.structure.fit_angles {
            v.extend_from_slice(&st.angle_offsets);
        }
        v.extend(st.nuisance.to_vec());
        v
    }

    fn unpack(&self, st: &State, theta: &[f64]) -> State {
        let mut s = st.clone();
        let mut o = 0;
        if self.structure.fit_film {
            let nf = st.film.params().len();
            s.film = st.film.with_params(&theta[..nf]);
            o = nf;
        }
        if self.structure.fit_substrate {
            s.substrate_shift = theta[o];
            o += 1;
        }
        if self.structure.fit_angles {
            s.angle_offsets = theta[o..o + self.obs.angles].to_vec();
            o += self.obs.angles;
        }
        s.nuisance = st.nuisance.from_vec(&theta[o..]);
        s
    }

    fn geometry(&self, st: &State) -> Geometry {
        let mut g = self.geom.clone();
        for (a, off) in g.incident_deg.iter_mut().zip(&st.angle_offsets) {
            *a = (*a + off).clamp(0.0, 89.9);
        }
        g
    }

    fn fd_params(&self, st: &State) -> Vec<FdParam> {
        let mut out = Vec::new();
        let geom = self.geometry(st);
        let mut i = 0;
        if self.structure.fit_film {
            let p = st.film.params();
            for k in 0..p.len() {
                let step = 1e-4;
                let mut q = p.to_vec();
                q[k] += step;
                out.push(FdParam {
                    index: i,
                    step,
                    model: geom.model_of(&st.film.with_params(&q), st.substrate_shift),
                    angle: None,
                });
                i += 1;
            }
        }
        if self.structure.fit_substrate {
            let step = 1e-3;
            out.push(FdParam {
                index: i,
                step,
                model: geom.model_of(&st.film, st.substrate_shift + step),
                angle: None,
            });
            i += 1;
        }
        if self.structure.fit_angles {
            for a in 0..self.obs.angles {
                let step = 0.02; // degrees
                let mut g = geom.clone();
                g.incident_deg[a] += step;
                out.push(FdParam {
                    index: i,
                    step,
                    model: g.model_of(&st.film, st.substrate_shift),
                    angle: Some(a),
                });
                i += 1;
            }
        }
        out
    }

    /// χ² at `st` and, when `lin`, the normal-equation blocks: per pixel, per angle, the
    /// gain is eliminated ([`Problem::fit_gain`]), the residual summed, and the local Jacobian
    /// columns ([`Problem::jacobian_columns`]) projected off the model direction
    /// (Kaufman) are accumulated into the block-arrow normal equations.
    fn evaluate(&self, st: &State, lin: bool) -> Evaluation {
        // Fixed chunks of pixels, merged in order: the same sums to the last bit in every
        // run and on any thread count (a rayon fold splits wherever work was stolen, and
        // the fit moved by up to 0.02 nm between identical runs).
        const CHUNKS: usize = 16;
        let setup = self.eval_setup(st, lin);
        let new_acc = || Acc::new(lin, setup.g_count);
        let n = self.data.pixels.len();
        let size = n.div_ceil(CHUNKS).max(1);
        let parts: Vec<Acc> = (0..n.div_ceil(size))
            .into_par_iter()
            .map(|c| {
                let mut acc = new_acc();
                for i in c * size..((c + 1) * size).min(n) {
                    self.add_pixel(&setup, i, &mut acc);
                }
                acc
            })
            .collect();
        (parts.into_iter().fold(new_acc(), Acc::merge)).into_evaluation()
    }

    /// The model, finite-difference models and per-band weights at `st`.
    fn eval_setup<'s>(&self, st: &'s State, lin: bool) -> EvalSetup<'s> {
        let (na, nb) = (self.obs.angles, self.obs.bands);
        let mut sw = vec![0f64; na * nb];
        let mut cb = vec![0f64; na * nb];
        let mut w = vec![0f64; na * nb];
        for a in 0..na {
            for b in 0..nb {
                let i = a * nb + b;
                w[i] = 1.0 / self.sigma[i] as f64;
                sw[i] = st.nuisance.multiplier_at(a, b) * w[i];
                cb[i] = st.nuisance.background_at(a, b);
            }
        }
        EvalSetup {
            st,
            lin,
            g_count: self.globals(st),
            nuis_off: self.nuisance_offset(st),
            m0: self.geometry(st).model_of(&st.film, st.substrate_shift),
            fd: if lin { self.fd_params(st) } else { Vec::new() },
            n550: st.film.n550(),
            sw,
            cb,
            w,
        }
    }

    /// Adds joint pixel `i`'s χ² (and, when linearising, its blocks) to `acc`.
    fn add_pixel(&self, s: &EvalSetup, i: usize, acc: &mut Acc) {
        let (na, nb) = (self.obs.angles, self.obs.bands);
        let (lin, g_count) = (s.lin, s.g_count);
        let mask = &self.data.mask[i];
        let mut rho = vec![1f32; na];
        self.obs.rho(self.data.pixels[i], s.n550, &mut rho);
        let d = s.st.d[i];
        let mut pl = PixelLin {
            hdg: vec![0.0; if lin { g_count } else { 0 }],
            score: vec![0.0; if lin { g_count } else { 0 }],
            ..PixelLin::default()
        };
        let mut rows = AngleRows::new(nb);
        for a in 0..na {
            if !mask[a] {
                continue;
            }
            let da = (d * rho[a] as f64).max(0.0);
            s.m0.spectrum_and_derivative(a, da, &mut rows.r, &mut rows.dr);
            let (g, mm) = self.fit_gain(s, &self.data.y[i], a, &mut rows, acc);
            if !lin {
                continue;
            }
            self.jacobian_columns(s, a, da, g, rho[a] as f64, &mut rows);
            if s.st.nuisance.spec.free_gain && g > 0.0 && mm > 0.0 {
                // Kaufman: project every column off the model direction.
                for (_, v) in rows.cols.iter_mut() {
                    let c = v.iter().zip(&rows.mt).map(|(x, m)| x * m).sum::<f64>() / mm;
                    for (x, m) in v.iter_mut().zip(&rows.mt) {
                        *x -= c * m;
                    }
                }
            }
            add_normal_blocks(&rows.cols, &rows.e, g_count, &mut pl, acc);
        }
        if lin {
            acc.px.push((i, pl));
        }
    }

    /// Angle `a` of a pixel whose raw values are `y` and whose model spectrum is in
    /// `rows.r`: whitens data and model, eliminates the gain (its least-squares value
    /// m·y/m·m, kept ≥ 0; 1 when the radiometry is absolute), leaves the residual in
    /// `rows.e` and adds it to χ² and the lag-1 sums. Returns the gain and m·m.
    fn fit_gain(
        &self,
        s: &EvalSetup,
        y: &[f32],
        a: usize,
        rows: &mut AngleRows,
        acc: &mut Acc,
    ) -> (f64, f64) {
        let (nb, stride) = (self.obs.bands, self.obs.stride);
        let free = s.st.nuisance.spec.free_gain;
        let (mut my, mut mm) = (0.0, 0.0);
        for b in 0..nb {
            let k = a * nb + b;
            rows.yt[b] = (y[a * stride + b] as f64 - s.cb[k]) * s.w[k];
            rows.mt[b] = rows.r[b] as f64 * s.sw[k];
            my += rows.mt[b] * rows.yt[b];
            mm += rows.mt[b] * rows.mt[b];
        }
        let g = if free {
            if mm > 0.0 {
                (my / mm).max(0.0)
            } else {
                0.0
            }
        } else {
            1.0
        };
        if free && g > 0.0 {
            acc.gains += 1;
        }
        let mut prev = f64::NAN;
        for ((e, m), y) in rows.e.iter_mut().zip(&rows.mt).zip(&rows.yt) {
            *e = g * m - y;
            acc.chi2 += *e * *e;
            acc.lag.1 += *e * *e;
            if prev.is_finite() {
                acc.lag.0 += prev * *e;
            }
            prev = *e;
        }
        acc.samples += nb;
        (g, mm)
    }

    /// The whitened residual's derivatives at angle `a` (thickness `da` after the angle's
    /// refraction scale `rho_a`, gain `g`) into `rows.cols`: the pixel's thickness
    /// (analytic), the finite-difference parameters that affect this angle, and this
    /// angle's multiplier terms — all zero when the gain is — and its background terms.
    fn jacobian_columns(
        &self,
        s: &EvalSetup,
        a: usize,
        da: f64,
        g: f64,
        rho_a: f64,
        rows: &mut AngleRows,
    ) {
        let nb = self.obs.bands;
        let nuis = &s.st.nuisance;
        let (kmul, kbg) = (nuis.spec.multiplier_terms, nuis.spec.background_terms);
        let k0 = a * nb;
        let first = s.nuis_off + a * (kmul + kbg);
        let (sw, w) = (&s.sw[k0..k0 + nb], &s.w[k0..k0 + nb]);
        rows.cols.clear();
        if g > 0.0 {
            let (r, dr) = (&rows.r, &rows.dr);
            let d_col = (0..nb).map(|b| g * sw[b] * dr[b] as f64 * rho_a).collect();
            rows.cols.push((D_COLUMN, d_col));
            for f in s.fd.iter().filter(|f| f.angle.is_none_or(|fa| fa == a)) {
                f.model.spectrum(a, da, &mut rows.rf);
                let rf = &rows.rf;
                let col = (0..nb)
                    .map(|b| g * sw[b] * (rf[b] - r[b]) as f64 / f.step)
                    .collect();
                rows.cols.push((f.index, col));
            }
            for k in 0..kmul {
                let col = (0..nb)
                    .map(|b| g * w[b] * nuis.multiplier_basis(k, b) * r[b] as f64)
                    .collect();
                rows.cols.push((first + k, col));
            }
        }
        for j in 0..kbg {
            let col = (0..nb)
                .map(|b| w[b] * nuis.background_basis(j, b))
                .collect();
            rows.cols.push((first + kmul + j, col));
        }
    }

    /// χ² at a state (no linearisation).
    pub fn chi2(&self, st: &State) -> f64 {
        self.evaluate(st, false).chi2
    }

    /// Levenberg–Marquardt from `init` (at most `iterations` accepted steps).
    pub fn solve(&self, init: State, iterations: usize) -> JointFit {
        let mut st = init;
        let mut ev = self.evaluate(&st, true);
        let mut mu = 1e-3;
        let g = self.globals(&st);
        let nf = self.film_params(&st);
        let mut accepted = 0;
        let mut tries = 0;
        while accepted < iterations && tries < 4 * iterations + 10 {
            tries += 1;
            let theta = self.pack(&st);
            // Damped Schur complement in θ.
            let mut s = ev.hgg.clone();
            let mut rhs = ev.gg.clone();
            for i in 0..g {
                s[i * g + i] = s[i * g + i] * (1.0 + mu) + 1e-12;
            }
            for pl in &ev.pixels {
                let a = pl.hdd * (1.0 + mu) + 1e-12;
                for i in 0..g {
                    let hi = pl.hdg[i];
                    if hi == 0.0 {
                        continue;
                    }
                    rhs[i] -= hi * pl.gd / a;
                    for j in 0..g {
                        s[i * g + j] -= hi * pl.hdg[j] / a;
                    }
                }
            }
            let dtheta = if g == 0 {
                Vec::new()
            } else {
                match cholesky(&s, g) {
                    Some(l) => cholesky_solve(&l, g, &rhs).iter().map(|v| -v).collect(),
                    None => {
                        mu *= 8.0;
                        if mu > 1e10 {
                            break;
                        }
                        continue;
                    }
                }
            };
            let mut theta_new = theta.clone();
            for (i, (t, dt)) in theta_new.iter_mut().zip(&dtheta).enumerate() {
                // Keep the index steps small: a far jump changes the fringe orders.
                let lim = if i < nf { 0.05 } else { f64::INFINITY };
                *t += dt.clamp(-lim, lim);
            }
            let mut cand = self.unpack(&st, &theta_new);
            let n_min = self.geom.min_film_ior();
            if self.structure.fit_film && cand.film.n550() < n_min {
                mu *= 8.0;
                continue;
            }
            for (k, pl) in ev.pixels.iter().enumerate() {
                let a = pl.hdd * (1.0 + mu) + 1e-12;
                let hd: f64 = pl.hdg.iter().zip(&dtheta).map(|(x, y)| x * y).sum();
                let step = (-(pl.gd + hd) / a).clamp(-self.max_d_step, self.max_d_step);
                cand.d[k] = (st.d[k] + step).clamp(self.d_min, self.d_max);
            }
            let chi2_new = self.chi2(&cand);
            if chi2_new < ev.chi2 {
                let converged = ev.chi2 - chi2_new <= 1e-9 * ev.chi2
                    && dtheta.iter().take(nf).all(|v| v.abs() < 1e-7);
                st = cand;
                ev = self.evaluate(&st, true);
                mu = (mu / 3.0).max(1e-9);
                accepted += 1;
                if converged {
                    break;
                }
            } else {
                mu *= 8.0;
                if mu > 1e10 {
                    break;
                }
            }
        }
        self.finish(st, ev)
    }

    /// Covariance and per-pixel sensitivities at the solution.
    fn finish(&self, st: State, ev: Evaluation) -> JointFit {
        let g = self.globals(&st);
        let nf = self.film_params(&st);
        let npx = self.data.pixels.len();
        let dof = ev.samples as f64 - npx as f64 - g as f64 - ev.free_gains as f64;
        let rho = if ev.lag.1 > 0.0 {
            ev.lag.0 / ev.lag.1
        } else {
            0.0
        };
        let mut s0 = ev.hgg.clone();
        let mut meat = vec![0.0; g * g];
        for pl in &ev.pixels {
            if !(pl.hdd > 0.0) {
                continue;
            }
            for i in 0..g {
                for j in 0..g {
                    s0[i * g + j] -= pl.hdg[i] * pl.hdg[j] / pl.hdd;
                }
            }
            let u: Vec<f64> = (0..g)
                .map(|i| pl.score[i] - pl.hdg[i] * pl.gd / pl.hdd)
                .collect();
            for i in 0..g {
                for j in 0..g {
                    meat[i * g + j] += u[i] * u[j];
                }
            }
        }
        let mut fit = JointFit {
            chi2: ev.chi2,
            samples: ev.samples,
            dof: dof.max(1.0),
            globals: g,
            residual_correlation: rho,
            cov: None,
            d_sigma_global: vec![0.0; npx],
            state: st,
        };
        if g == 0 {
            return fit;
        }
        let Some(inv) = spd_inverse(&s0, g) else {
            return fit;
        };
        let s2 = fit.chi2_red();
        // Sandwich: S⁻¹ M S⁻¹.
        let mut sand = vec![0.0; g * g];
        for i in 0..g {
            for j in 0..g {
                let mut acc = 0.0;
                for k in 0..g {
                    let ik = inv[i * g + k];
                    if ik == 0.0 {
                        continue;
                    }
                    for l in 0..g {
                        acc += ik * meat[k * g + l] * inv[l * g + j];
                    }
                }
                sand[i * g + j] = acc;
            }
        }
        let classical = fit.inflation() * s2;
        let mut scale = classical;
        for i in 0..nf.max(1).min(g) {
            if inv[i * g + i] > 0.0 {
                scale = scale.max(sand[i * g + i] / inv[i * g + i]);
            }
        }
        let cov: Vec<f64> = inv.iter().map(|v| v * scale).collect();
        for (k, pl) in ev.pixels.iter().enumerate() {
            if pl.hdd > 0.0 {
                let h: Vec<f64> = pl.hdg.iter().map(|v| -v / pl.hdd).collect();
                let mut var = 0.0;
                for i in 0..g {
                    for j in 0..g {
                        var += h[i] * cov[i * g + j] * h[j];
                    }
                }
                fit.d_sigma_global[k] = var.max(0.0).sqrt();
            }
        }
        fit.cov = Some(cov);
        fit
    }
}
