//! Single-precision Airy film for the renderer: R_s, R_p, T_s, T_p at four wavelengths
//! at once (one hero-wavelength bundle), within 1e-5 of the f64 [`ThinFilm`] result for
//! d ≤ 5000 nm and θ ≤ 89.9° (tested over a dense grid in `tests/optics_f32.rs`).
//!
//! Where f32 would lose that accuracy is the film phase: β = 2π d n2 cosθ2 / λ reaches
//! ~250 rad at d = 5000 nm, where one f32 ulp is 1.5e-5 rad, and `sin`/`cos` of an f32
//! argument that large inherit that error. So `n2 cosθ2` and β are formed in f64 and β is
//! reduced to (−π, π] in f64 before the f32 `sin_cos`; everything else (Fresnel
//! amplitudes, the Airy sum, powers) is f32, whose ~1e-7 relative error is harmless there.

use super::film::ThinFilm;
use num_complex::{Complex32, Complex64};
use std::f64::consts::{PI, TAU};

/// A film with per-wavelength indices for a bundle of four wavelengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThinFilmX4 {
    /// Ambient index (lossless).
    pub ambient_ior: f32,
    /// Film `n + ik` at each of the four wavelengths.
    pub film_ior: [Complex32; 4],
    /// Film thickness in nm.
    pub thickness_nm: f32,
    /// Substrate `n + ik` at each of the four wavelengths.
    pub substrate_ior: [Complex32; 4],
}

/// Power reflectance / transmittance of four wavelengths.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FilmResponseX4 {
    pub r_s: [f32; 4],
    pub r_p: [f32; 4],
    pub t_s: [f32; 4],
    pub t_p: [f32; 4],
}

impl FilmResponseX4 {
    /// Unpolarised reflectance per wavelength.
    pub fn r(&self) -> [f32; 4] {
        std::array::from_fn(|i| 0.5 * (self.r_s[i] + self.r_p[i]))
    }
    /// Unpolarised transmittance per wavelength.
    pub fn t(&self) -> [f32; 4] {
        std::array::from_fn(|i| 0.5 * (self.t_s[i] + self.t_p[i]))
    }
}

/// Forward-branch square root of `z = (n cosθ)²` (Im ≥ 0, or Re > 0 when lossless), f64.
#[inline]
fn forward_sqrt64(z: Complex64) -> Complex64 {
    let nc = z.sqrt();
    let forward = if nc.im.abs() > 100.0 * f64::EPSILON * nc.norm() {
        nc.im > 0.0
    } else {
        nc.re > 0.0
    };
    if forward {
        nc
    } else {
        -nc
    }
}

/// Same in f32 (branch test at f32 resolution).
#[inline]
fn forward_sqrt32(z: Complex32) -> Complex32 {
    let nc = z.sqrt();
    let forward = if nc.im.abs() > 100.0 * f32::EPSILON * nc.norm() {
        nc.im > 0.0
    } else {
        nc.re > 0.0
    };
    if forward {
        nc
    } else {
        -nc
    }
}

impl ThinFilmX4 {
    /// The same film at all four wavelengths (non-dispersive indices).
    pub fn from_film(f: &ThinFilm) -> Self {
        let c = |z: Complex64| Complex32::new(z.re as f32, z.im as f32);
        ThinFilmX4 {
            ambient_ior: f.ambient_ior as f32,
            film_ior: [c(f.film_ior); 4],
            thickness_nm: f.thickness_nm as f32,
            substrate_ior: [c(f.substrate_ior); 4],
        }
    }

    /// Evaluate at four wavelengths (nm) for `cos θ1` in the ambient. No validation: inputs
    /// must satisfy [`ThinFilm::validate`] (the renderer checks materials at load time).
    #[inline]
    pub fn response(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> FilmResponseX4 {
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        let n1 = self.ambient_ior;
        // (1 − c)(1 + c) keeps sin² accurate near normal incidence.
        let kx2 = n1 * n1 * ((1.0 - cos1) * (1.0 + cos1));
        let cos1_64 = cos1 as f64;
        let n1_64 = n1 as f64;
        let kx2_64 = n1_64 * n1_64 * ((1.0 - cos1_64) * (1.0 + cos1_64));
        let d_64 = self.thickness_nm as f64;
        let n1c = n1 * cos1;
        let mut out = FilmResponseX4::default();
        for i in 0..4 {
            let n2 = self.film_ior[i];
            let n3 = self.substrate_ior[i];
            // Film n cosθ and phase in f64 (see module docs), reduced before sin/cos.
            let n2_64 = Complex64::new(n2.re as f64, n2.im as f64);
            let n2c_64 = forward_sqrt64(n2_64 * n2_64 - kx2_64);
            let beta = n2c_64 * (2.0 * PI * d_64 / lambda_nm[i] as f64);
            let beta_re = beta.re - TAU * (beta.re / TAU).round();
            let decay = (-beta.im).exp() as f32;
            let (s, c) = (beta_re as f32).sin_cos();
            let e_half = Complex32::new(decay * c, decay * s);
            let e_full = e_half * e_half;

            let n2c = Complex32::new(n2c_64.re as f32, n2c_64.im as f32);
            let n3c = forward_sqrt32(n3 * n3 - kx2);
            let (n1sq, n2sq, n3sq) = (n1 * n1, n2 * n2, n3 * n3);
            // Interface amplitudes in n cosθ form (tmm.interface_r/t times n_i n_f for p).
            let s12 = n1c + n2c;
            let r12s = (n1c - n2c) / s12;
            let t12s = 2.0 * n1c / s12;
            let p12a = n2sq * n1c;
            let p12b = n1sq * n2c;
            let p12 = p12a + p12b;
            let r12p = (p12a - p12b) / p12;
            let t12p = 2.0 * n1 * n2 * n1c / p12;
            let s23 = n2c + n3c;
            let r23s = (n2c - n3c) / s23;
            let t23s = 2.0 * n2c / s23;
            let p23a = n3sq * n2c;
            let p23b = n2sq * n3c;
            let p23 = p23a + p23b;
            let r23p = (p23a - p23b) / p23;
            let t23p = 2.0 * n2 * n3 * n2c / p23;
            // Airy sums (seed eq. 4).
            let ds = 1.0 + r12s * r23s * e_full;
            let dp = 1.0 + r12p * r23p * e_full;
            let rs = (r12s + r23s * e_full) / ds;
            let rp = (r12p + r23p * e_full) / dp;
            let ts = t12s * t23s * e_half / ds;
            let tp = t12p * t23p * e_half / dp;
            out.r_s[i] = rs.norm_sqr();
            out.r_p[i] = rp.norm_sqr();
            if n1c > 0.0 {
                // tmm.T_from_t: s uses Re(n3 cosθ3), p uses Re(n3 conj(cosθ3)).
                let cos3 = n3c / n3;
                out.t_s[i] = (ts.norm_sqr() * n3c.re / n1c).max(0.0);
                out.t_p[i] = (tp.norm_sqr() * (n3 * cos3.conj()).re / n1c).max(0.0);
            }
        }
        out
    }
}
