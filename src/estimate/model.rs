//! The fast forward model used by every fit: the Airy reflectance (seed eq. 4/5) of a
//! film of real index n and thickness d, tabulated per (angle, band) for one n.
//!
//! For a non-absorbing film whose wave propagates (n² > n1² sin²θ1), |e^{iΔ}| = 1 and
//!
//!   R(d) = |r12 + r23 e^{iΔ}|² / |1 + r12 r23 e^{iΔ}|²
//!        = (P + 2 Re(Q e^{iΔ})) / (D + 2 Re(C e^{iΔ})),   Δ = k d,  k = 4π n cosθ2 / λ,
//!
//! with P = |r12|² + |r23|², Q = conj(r12) r23, D = 1 + |r12 r23|², C = r12 r23. Everything but
//! Δ depends on n only, so for a fixed n each sample costs one sin/cos and a division (this is
//! what makes a 1-megapixel fit take seconds). Complex r23 (metal substrates) is supported.
//! Polarisation (s, p or the unpolarised mean) and the camera's Gaussian band response
//! (3-point Gauss–Hermite quadrature when the FWHM is known) become several weighted terms
//! per sample. A dispersive film (n(λ), [`FilmIndex`]) only changes the per-sample
//! coefficients: each quadrature node uses the index at its own wavelength.

use super::film::FilmIndex;
use crate::capture::{CaptureSet, Polarization};
use crate::optics::fresnel::{interface, n_cos_theta};
use num_complex::Complex64;

/// Per-sample coefficient tables for one film index (structure of arrays, f32 for speed).
#[derive(Debug, Clone)]
pub struct FilmModel {
    /// Film index at 550 nm (fringe spacing estimates).
    pub film_ior: f64,
    /// Terms per sample (polarisations × quadrature nodes).
    pub terms: usize,
    pub bands: usize,
    pub angles: usize,
    k: Vec<f32>,
    w: Vec<f32>,
    p: Vec<f32>,
    qr: Vec<f32>,
    qi: Vec<f32>,
    dd: Vec<f32>,
    cr: Vec<f32>,
    ci: Vec<f32>,
}

/// Geometry shared by every model of one capture.
#[derive(Debug, Clone)]
pub struct Geometry {
    pub ambient_ior: f64,
    pub substrate: crate::optics::Ior,
    pub wavelengths_nm: Vec<f64>,
    pub fwhm_nm: Option<Vec<f64>>,
    pub incident_deg: Vec<f64>,
    pub polarization: Polarization,
    /// Use the band quadrature (only when FWHM is known and requested).
    pub band_integration: bool,
}

impl Geometry {
    pub fn from_capture(set: &CaptureSet, band_integration: bool) -> Self {
        Geometry {
            ambient_ior: set.ambient_ior,
            substrate: set.substrate_ior.clone(),
            wavelengths_nm: set.wavelengths_nm.clone(),
            fwhm_nm: set.fwhm_nm.clone(),
            incident_deg: set.angles.iter().map(|a| a.incident_deg).collect(),
            polarization: set.polarization,
            band_integration: band_integration && set.fwhm_nm.is_some(),
        }
    }

    /// True when the substrate absorbs anywhere in the band (metals): its reflection phase
    /// is not 0 or π, so a substrate index error shifts fringes.
    pub fn substrate_absorbs(&self) -> bool {
        self.wavelengths_nm
            .iter()
            .any(|&l| self.substrate.at(l).im > 1e-6)
    }

    /// Largest n1 sinθ1 over the angles: the film index must exceed it for Δ to be real.
    pub fn max_kx(&self) -> f64 {
        self.incident_deg
            .iter()
            .map(|a| self.ambient_ior * a.to_radians().sin())
            .fold(0.0, f64::max)
    }

    /// Smallest film index the model accepts (propagating wave in the film at every angle).
    pub fn min_film_ior(&self) -> f64 {
        (self.max_kx() + 1e-3).max(1.0001)
    }

    pub fn lambda_min(&self) -> f64 {
        self.wavelengths_nm
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }

    pub fn lambda_max(&self) -> f64 {
        self.wavelengths_nm.iter().copied().fold(0.0, f64::max)
    }

    /// Builds the tables for a constant film index `n` (clamped to the propagating range).
    pub fn model(&self, n: f64) -> FilmModel {
        self.model_of(&FilmIndex::constant(n), 0.0)
    }

    /// Builds the tables for `film` (n(λ) clamped to the propagating range at every
    /// wavelength) with the substrate's real index shifted by `substrate_shift`.
    pub fn model_of(&self, film: &FilmIndex, substrate_shift: f64) -> FilmModel {
        let n_min = self.min_film_ior();
        // Gauss–Hermite nodes for a Gaussian band response, normalised weights.
        let nodes: &[(f64, f64)] = if self.band_integration {
            &[
                (-1.224_744_871, 1.0 / 6.0),
                (0.0, 2.0 / 3.0),
                (1.224_744_871, 1.0 / 6.0),
            ]
        } else {
            &[(0.0, 1.0)]
        };
        let pols: &[(bool, f64)] = match self.polarization {
            Polarization::S => &[(true, 1.0)],
            Polarization::P => &[(false, 1.0)],
            Polarization::Unpolarized => &[(true, 0.5), (false, 0.5)],
        };
        let terms = nodes.len() * pols.len();
        let bands = self.wavelengths_nm.len();
        let angles = self.incident_deg.len();
        let len = angles * bands * terms;
        let mut m = FilmModel {
            film_ior: film.n550(),
            terms,
            bands,
            angles,
            k: Vec::with_capacity(len),
            w: Vec::with_capacity(len),
            p: Vec::with_capacity(len),
            qr: Vec::with_capacity(len),
            qi: Vec::with_capacity(len),
            dd: Vec::with_capacity(len),
            cr: Vec::with_capacity(len),
            ci: Vec::with_capacity(len),
        };
        let n1 = Complex64::new(self.ambient_ior, 0.0);
        for &deg in &self.incident_deg {
            let (sin1, cos1) = deg.to_radians().sin_cos();
            let kx = self.ambient_ior * sin1;
            for (b, &lambda) in self.wavelengths_nm.iter().enumerate() {
                let sigma = self
                    .fwhm_nm
                    .as_ref()
                    .map(|f| f[b] / 2.354_820_045)
                    .unwrap_or(0.0);
                for &(x, wn) in nodes {
                    let lam = (lambda + std::f64::consts::SQRT_2 * sigma * x).max(1.0);
                    let n2 = Complex64::new(film.at(lam).max(n_min), 0.0);
                    let n2c = n_cos_theta(n2, kx);
                    let n3 = self.substrate.at(lam) + substrate_shift;
                    let n3c = n_cos_theta(n3, kx);
                    let i12 = interface(n1, n2, Complex64::new(cos1, 0.0), n2c / n2);
                    let i23 = interface(n2, n3, n2c / n2, n3c / n3);
                    for &(is_s, wp) in pols {
                        let (r12, r23) = if is_s {
                            (i12.r_s, i23.r_s)
                        } else {
                            (i12.r_p, i23.r_p)
                        };
                        let q = r12.conj() * r23;
                        let c = r12 * r23;
                        m.k.push((4.0 * std::f64::consts::PI * n2c.re / lam) as f32);
                        m.w.push((wn * wp) as f32);
                        m.p.push((r12.norm_sqr() + r23.norm_sqr()) as f32);
                        m.qr.push(q.re as f32);
                        m.qi.push(q.im as f32);
                        m.dd.push((1.0 + c.norm_sqr()) as f32);
                        m.cr.push(c.re as f32);
                        m.ci.push(c.im as f32);
                    }
                }
            }
        }
        m
    }
}

/// sin and cos of `x` (radians) without branches so loops vectorise: reduce to [−π, π],
/// then Taylor polynomials to x^17/x^16 (abs. error < 2e-7, below f32 rounding of R).
#[inline(always)]
pub fn fast_sin_cos(x: f32) -> (f32, f32) {
    const INV_TWO_PI: f32 = 1.0 / (2.0 * std::f32::consts::PI);
    // Round to nearest with the 1.5·2²³ trick instead of `f32::round`: on baseline x86-64
    // `round` is a libm call that blocks vectorisation of the band loops (it was ~10 % of
    // `estimate --method full` in `perf`). Exact for |x/2π| < 2²², far beyond any phase here.
    const MAGIC: f32 = 12_582_912.0;
    let q = (x * INV_TWO_PI + MAGIC) - MAGIC;
    // Two-step Cody–Waite reduction keeps Δ up to a few hundred radians accurate in f32.
    let r = (x - q * 6.283_185_5) + q * 1.748_455_5e-7;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0
                    + r2 * (-1.0 / 5040.0
                        + r2 * (1.0 / 362_880.0
                            + r2 * (-1.0 / 39_916_800.0
                                + r2 * (1.0 / 6_227_020_800.0
                                    + r2 * (-1.0 / 1_307_674_368_000.0
                                        + r2 * (1.0 / 355_687_428_096_000.0)))))))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0
                    + r2 * (1.0 / 40_320.0
                        + r2 * (-1.0 / 3_628_800.0
                            + r2 * (1.0 / 479_001_600.0
                                + r2 * (-1.0 / 87_178_291_200.0
                                    + r2 * (1.0 / 20_922_789_888_000.0))))))));
    (s, c)
}

impl FilmModel {
    #[inline]
    fn range(&self, angle: usize) -> std::ops::Range<usize> {
        let t = self.bands * self.terms;
        angle * t..(angle + 1) * t
    }

    /// Weighted term values (and d-derivatives) for terms `j0..j0 + r.len()`: a flat
    /// loop that vectorises; callers sum groups of `terms`.
    #[inline(always)]
    fn eval_terms(&self, j0: usize, d: f32, r: &mut [f32], dr: &mut [f32]) {
        let n = r.len();
        let it = r
            .iter_mut()
            .zip(dr.iter_mut())
            .zip(&self.k[j0..j0 + n])
            .zip(&self.w[j0..j0 + n])
            .zip(&self.p[j0..j0 + n])
            .zip(&self.qr[j0..j0 + n])
            .zip(&self.qi[j0..j0 + n])
            .zip(&self.dd[j0..j0 + n])
            .zip(&self.cr[j0..j0 + n])
            .zip(&self.ci[j0..j0 + n]);
        for (((((((((ro, dro), &k), &w), &p), &qr), &qi), &dd), &cr), &ci) in it {
            let (s, c) = fast_sin_cos(k * d);
            let num = p + 2.0 * (qr * c - qi * s);
            let den = dd + 2.0 * (cr * c - ci * s);
            let dnum = -2.0 * k * (qr * s + qi * c);
            let dden = -2.0 * k * (cr * s + ci * c);
            let inv = 1.0 / den;
            *ro = w * num * inv;
            *dro = w * (dnum * den - num * dden) * inv * inv;
        }
    }

    /// Σ (R − y)² over one angle's bands, the terms of each band summed (multi-term path).
    fn multi_term_sse(&self, angle: usize, d: f32, ya: &[f32]) -> f32 {
        const CHUNK: usize = 96; // divisible by 1, 2, 3 and 6 terms
        let t = self.terms;
        let per = CHUNK / t;
        let start = self.range(angle).start;
        let mut r = [0f32; CHUNK];
        let mut dr = [0f32; CHUNK];
        let mut b0 = 0;
        let mut sse = 0f32;
        while b0 < self.bands {
            let nb = per.min(self.bands - b0);
            self.eval_terms(start + b0 * t, d, &mut r[..nb * t], &mut dr[..nb * t]);
            for i in 0..nb {
                let rv: f32 = r[i * t..(i + 1) * t].iter().sum();
                let e = rv - ya[b0 + i];
                sse += e * e;
            }
            b0 += nb;
        }
        sse
    }

    /// Model reflectance of every band at one angle for thickness `d` into `out`.
    pub fn spectrum(&self, angle: usize, d: f64, out: &mut [f32]) {
        self.spectrum_terms(angle, d, out, None);
    }

    /// Model reflectance and its d-derivative at one angle (per band) into `r`, `dr`.
    pub fn spectrum_and_derivative(&self, angle: usize, d: f64, r: &mut [f32], dr: &mut [f32]) {
        self.spectrum_terms(angle, d, r, Some(dr));
    }

    /// Band sums of the terms in chunks through the vectorised [`FilmModel::eval_terms`].
    fn spectrum_terms(&self, angle: usize, d: f64, out: &mut [f32], mut dout: Option<&mut [f32]>) {
        const CHUNK: usize = 96; // divisible by 1, 2, 3 and 6 terms
        let d = d as f32;
        let t = self.terms;
        let start = self.range(angle).start;
        let (mut r, mut dr) = ([0f32; CHUNK], [0f32; CHUNK]);
        let per = (CHUNK / t).max(1);
        let mut b0 = 0;
        while b0 < self.bands {
            let nb = per.min(self.bands - b0);
            let n = (nb * t).min(CHUNK);
            if t * nb > CHUNK {
                // More terms than a chunk holds (never for the models built here).
                for b in b0..b0 + nb {
                    let (mut acc, mut dacc) = (0f32, 0f32);
                    for j in 0..t {
                        self.eval_terms(start + b * t + j, d, &mut r[..1], &mut dr[..1]);
                        acc += r[0];
                        dacc += dr[0];
                    }
                    out[b] = acc;
                    if let Some(o) = dout.as_deref_mut() {
                        o[b] = dacc;
                    }
                }
            } else {
                self.eval_terms(start + b0 * t, d, &mut r[..n], &mut dr[..n]);
                for i in 0..nb {
                    out[b0 + i] = r[i * t..(i + 1) * t].iter().sum();
                    if let Some(o) = dout.as_deref_mut() {
                        o[b0 + i] = dr[i * t..(i + 1) * t].iter().sum();
                    }
                }
            }
            b0 += nb;
        }
    }

    /// Sum of squared residuals over one angle, every `step`-th band (fast scoring).
    #[inline]
    pub fn sse_angle(&self, angle: usize, d: f64, y: &[f32], step: usize) -> f32 {
        let d = d as f32;
        let start = self.range(angle).start;
        let t = self.terms;
        let mut sse = 0.0f32;
        if t == 1 {
            // Hot path (single term): written as one flat loop so it vectorises.
            let k = &self.k[start..start + self.bands];
            let p = &self.p[start..start + self.bands];
            let qr = &self.qr[start..start + self.bands];
            let qi = &self.qi[start..start + self.bands];
            let dd = &self.dd[start..start + self.bands];
            let cr = &self.cr[start..start + self.bands];
            let ci = &self.ci[start..start + self.bands];
            let w = &self.w[start..start + self.bands];
            if step == 1 {
                let it = y
                    .iter()
                    .zip(k)
                    .zip(w)
                    .zip(p)
                    .zip(qr)
                    .zip(qi)
                    .zip(dd)
                    .zip(cr)
                    .zip(ci);
                for ((((((((&yb, &k), &w), &p), &qr), &qi), &dd), &cr), &ci) in it {
                    let (s, c) = fast_sin_cos(k * d);
                    let num = p + 2.0 * (qr * c - qi * s);
                    let den = dd + 2.0 * (cr * c - ci * s);
                    let e = w * num / den - yb;
                    sse += e * e;
                }
                return sse;
            }
            let mut b = 0;
            while b < self.bands {
                let (s, c) = fast_sin_cos(k[b] * d);
                let num = p[b] + 2.0 * (qr[b] * c - qi[b] * s);
                let den = dd[b] + 2.0 * (cr[b] * c - ci[b] * s);
                let e = w[b] * num / den - y[b];
                sse += e * e;
                b += step;
            }
            return sse;
        }
        if step == 1 && t <= 6 && 96 % t == 0 {
            return self.multi_term_sse(angle, d, y);
        }
        let mut b = 0;
        while b < self.bands {
            let mut acc = 0.0f32;
            for j in start + b * t..start + (b + 1) * t {
                let (s, c) = fast_sin_cos(self.k[j] * d);
                let num = self.p[j] + 2.0 * (self.qr[j] * c - self.qi[j] * s);
                let den = self.dd[j] + 2.0 * (self.cr[j] * c - self.ci[j] * s);
                acc += self.w[j] * num / den;
            }
            let e = acc - y[b];
            sse += e * e;
            b += step;
        }
        sse
    }

    /// SSE over all masked angles (every `step`-th band); angle a's data start at
    /// `y[a * stride]`.
    pub fn sse(&self, d: f64, y: &[f32], stride: usize, mask: &[bool], step: usize) -> f64 {
        let mut s = 0.0f64;
        for a in 0..self.angles {
            if mask[a] {
                s += self.sse_angle(a, d, &y[a * stride..a * stride + self.bands], step) as f64;
            }
        }
        s
    }
}

/// Exact (f64, direct Airy) reflectance for the same geometry — used by tests and the
/// simulator to check the fast tables.
pub fn exact_reflectance(
    geom: &Geometry,
    film: &FilmIndex,
    d: f64,
    angle: usize,
    lambda_nm: f64,
) -> f64 {
    let film = crate::optics::ThinFilm {
        ambient_ior: geom.ambient_ior,
        film_ior: Complex64::new(film.at(lambda_nm), 0.0),
        thickness_nm: d,
        substrate_ior: geom.substrate.at(lambda_nm),
    };
    let r = film.response(lambda_nm, geom.incident_deg[angle].to_radians().cos());
    match geom.polarization {
        Polarization::S => r.r_s,
        Polarization::P => r.r_p,
        Polarization::Unpolarized => r.r(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Ior;

    fn geom(pol: Polarization, substrate: Ior) -> Geometry {
        Geometry {
            ambient_ior: 1.0,
            substrate,
            wavelengths_nm: (0..81).map(|i| 400.0 + 4.0 * i as f64).collect(),
            fwhm_nm: None,
            incident_deg: vec![10.0, 30.0, 50.0, 75.0],
            polarization: pol,
            band_integration: false,
        }
    }

    #[test]
    fn fast_sin_cos_matches_std() {
        for i in 0..20000 {
            let x = -300.0 + i as f32 * 0.03;
            let (s, c) = fast_sin_cos(x);
            assert!((s - (x as f64).sin() as f32).abs() < 5e-5, "{x}");
            assert!((c - (x as f64).cos() as f32).abs() < 5e-5, "{x}");
        }
    }

    #[test]
    fn tables_match_exact_airy_including_metal_and_unpolarised() {
        for (pol, sub) in [
            (Polarization::S, Ior::real(1.64)),
            (Polarization::P, Ior::real(1.64)),
            (
                Polarization::Unpolarized,
                Ior::Constant(Complex64::new(0.18, 3.4)),
            ),
        ] {
            let g = geom(pol, sub);
            for &(n, d) in &[(1.37, 400.0), (2.37, 0.0), (1.8, 1500.0)] {
                let m = g.model(n);
                let mut out = vec![0.0f32; 81];
                for a in 0..4 {
                    m.spectrum(a, d, &mut out);
                    for (b, &lam) in g.wavelengths_nm.iter().enumerate() {
                        let e = exact_reflectance(&g, &FilmIndex::constant(n), d, a, lam);
                        assert!(
                            (out[b] as f64 - e).abs() < 2e-4,
                            "{pol:?} n={n} d={d} {lam}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn derivative_matches_finite_difference() {
        let g = geom(Polarization::Unpolarized, Ior::real(1.64));
        let m = g.model(2.37);
        let (mut r, mut dr) = (vec![0.0f32; 81], vec![0.0f32; 81]);
        let (mut r1, mut r2) = (vec![0.0f32; 81], vec![0.0f32; 81]);
        m.spectrum_and_derivative(1, 500.0, &mut r, &mut dr);
        m.spectrum(1, 500.05, &mut r1);
        m.spectrum(1, 499.95, &mut r2);
        for b in 0..81 {
            let fd = (r1[b] - r2[b]) / 0.1;
            assert!(
                (fd - dr[b]).abs() < 2e-3 * dr[b].abs().max(1e-2),
                "band {b}: {fd} {}",
                dr[b]
            );
        }
    }

    #[test]
    fn sse_agrees_with_spectrum_for_multi_term_models() {
        let mut g = geom(Polarization::Unpolarized, Ior::real(1.64));
        g.fwhm_nm = Some(vec![4.0; 81]);
        g.band_integration = true;
        let m = g.model(1.6);
        assert_eq!(m.terms, 6);
        let y: Vec<f32> = (0..4 * 81).map(|i| 0.05 + 0.001 * (i % 7) as f32).collect();
        let mask = [true, false, true, true];
        let mut r = vec![0f32; 81];
        let mut sse = 0.0f64;
        for a in [0, 2, 3] {
            m.spectrum(a, 700.0, &mut r);
            for b in 0..81 {
                let e = (r[b] - y[a * 81 + b]) as f64;
                sse += e * e;
            }
        }
        assert!((m.sse(700.0, &y, 81, &mask, 1) - sse).abs() < 1e-5 * sse.max(1e-6));
    }
}
