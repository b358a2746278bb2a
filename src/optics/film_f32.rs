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
use std::f64::consts::PI;

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

/// Complex reflection amplitudes r_s, r_p of four wavelengths (the e^{−iωt} convention of
/// [`ThinFilm::amplitudes`]).
pub type AmplitudesX4 = [[Complex32; 2]; 4];

/// What the lossless Airy sums of four wavelengths share: the ambient index and n1 cosθ1,
/// the film and substrate indices and n cosθ (all real), and E − 1 = e^{2iβ} − 1 formed
/// without cancellation.
struct LosslessLanes {
    n1: f32,
    n1c: f32,
    n2: glam::Vec4,
    n3: glam::Vec4,
    n2c: glam::Vec4,
    n3c: glam::Vec4,
    em1_re: glam::Vec4,
    em1_im: glam::Vec4,
}

/// One lane of the general Airy sums: complex r and t of s and p, and whether f32 keeps
/// 1e-5 there (the denominator's condition number is at most [`F32_MAX_CONDITION`]).
struct GeneralLane {
    rs: Complex32,
    rp: Complex32,
    ts: Complex32,
    tp: Complex32,
    n3c: Complex32,
    well_conditioned: bool,
}

/// `forward_sqrt64` / `forward_sqrt32`: the forward-branch square root of `z = (n cosθ)²`
/// (Im ≥ 0, or Re > 0 when lossless), the branch test at the type's own resolution.
macro_rules! forward_sqrt {
    ($name:ident, $complex:ty, $real:ty) => {
        #[inline]
        fn $name(z: $complex) -> $complex {
            let nc = z.sqrt();
            let forward = if nc.im.abs() > 100.0 * <$real>::EPSILON * nc.norm() {
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
    };
}
forward_sqrt!(forward_sqrt64, Complex64, f64);
forward_sqrt!(forward_sqrt32, Complex32, f32);

/// Largest denominator condition number for which the f32 path stays within 1e-5
/// (f32 rounding ≈ 1e-7 per operation times this factor, with margin).
pub const F32_MAX_CONDITION: f32 = 12.0;

impl ThinFilmX4 {
    /// Lane `i` in f64 (the fallback for ill-conditioned lanes).
    pub fn lane_f64(&self, i: usize, lambda_nm: f32, cos_theta1: f32) -> super::FilmResponse {
        let c = |z: Complex32| Complex64::new(z.re as f64, z.im as f64);
        ThinFilm {
            ambient_ior: self.ambient_ior as f64,
            film_ior: c(self.film_ior[i]),
            thickness_nm: self.thickness_nm as f64,
            substrate_ior: c(self.substrate_ior[i]),
        }
        .response(lambda_nm as f64, cos_theta1 as f64)
    }

    /// Evaluate at four wavelengths (nm) for `cos θ1` in the ambient. No validation: inputs
    /// must satisfy [`ThinFilm::validate`] (the renderer checks materials at load time).
    #[inline]
    pub fn response(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> FilmResponseX4 {
        if let Some(out) = self.response_lossless(lambda_nm, cos_theta1) {
            return out;
        }
        self.response_general(lambda_nm, cos_theta1)
    }

    /// The common dielectric case — real film and substrate indices, light propagating in
    /// both (n² > n1² sin²θ1) — with the four wavelengths in SIMD lanes: the admittances
    /// are real and only E = e^{2iβ} is complex, so the Airy sums of
    /// [`Self::response_lossless`] and [`Self::amplitudes_lossless`] are
    /// [`Self::response_general`]'s formulas with the zero imaginary parts dropped. The film
    /// phase is formed and reduced in f64 exactly as there. None (the caller falls back to
    /// the general path) for absorbing or evanescent layers.
    #[inline]
    fn lossless_setup(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> Option<LosslessLanes> {
        use glam::Vec4;
        if self.film_ior.iter().any(|z| z.im != 0.0)
            || self.substrate_ior.iter().any(|z| z.im != 0.0)
        {
            return None;
        }
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        let n1 = self.ambient_ior;
        let cos1_64 = cos1 as f64;
        let n1_64 = n1 as f64;
        let kx2_64 = n1_64 * n1_64 * ((1.0 - cos1_64) * (1.0 + cos1_64));
        let d_64 = self.thickness_nm as f64;
        let n1c = n1 * cos1;
        let n2 = Vec4::from_array(self.film_ior.map(|z| z.re));
        let n3 = Vec4::from_array(self.substrate_ior.map(|z| z.re));
        // n3 cosθ3 from (n3 − n1)(n3 + n1) + (n1 cosθ1)² (no cancellation at grazing).
        let n3c_sq = (n3 - Vec4::splat(n1)) * (n3 + Vec4::splat(n1)) + Vec4::splat(n1c * n1c);
        if !(n3c_sq.cmpgt(Vec4::ZERO).all() && n2.cmpgt(Vec4::ZERO).all()) {
            return None;
        }
        let n3c = n3c_sq.sqrt();
        // Lane by lane in f64 but without early exits, so that the loop compiles to 4-wide
        // f64 SIMD (the same IEEE operations per lane as a scalar loop).
        let mut n2c_sq = [0.0f64; 4];
        for i in 0..4 {
            let n2_64 = n2[i] as f64;
            n2c_sq[i] = n2_64 * n2_64 - kx2_64;
        }
        // Evanescent in the film (or NaN): the general path handles it.
        if !n2c_sq.iter().all(|&v| v > 0.0) {
            return None;
        }
        let mut n2c_a = [0.0f32; 4];
        let mut y_a = [0.0f32; 4];
        let mut odd_a = [0.0f32; 4];
        for i in 0..4 {
            let n2c_64 = n2c_sq[i].sqrt();
            let two_beta = 2.0 * (n2c_64 * (2.0 * PI * d_64 / lambda_nm[i] as f64));
            // Nearest multiple of π (one `vroundpd` where SSE4.1 is there); |2β/π| is far
            // below 2⁵³, so k is an exact integer. Ties may go either way: y stays in ±π/2.
            // (× 1/π, not ÷ π: k only needs to be a nearest integer, and y is exact given k.)
            let k = (two_beta * std::f64::consts::FRAC_1_PI).round_ties_even();
            y_a[i] = (two_beta - k * PI) as f32;
            odd_a[i] = if (k as i64) & 1 == 0 { 0.0 } else { 1.0 };
            n2c_a[i] = n2c_64 as f32;
        }
        let n2c = Vec4::from_array(n2c_a);
        // sin, cos of y/2 with |y/2| ≤ π/4 + ε: Taylor to degree 9/10, error < 2e-9.
        let h = Vec4::from_array(y_a) * 0.5;
        let h2 = h * h;
        let sh = h
            * (Vec4::ONE
                + h2 * (Vec4::splat(-1.0 / 6.0)
                    + h2 * (Vec4::splat(1.0 / 120.0)
                        + h2 * (Vec4::splat(-1.0 / 5040.0) + h2 * (1.0 / 362_880.0)))));
        let ch = Vec4::ONE
            + h2 * (Vec4::splat(-0.5)
                + h2 * (Vec4::splat(1.0 / 24.0)
                    + h2 * (Vec4::splat(-1.0 / 720.0)
                        + h2 * (Vec4::splat(1.0 / 40_320.0) + h2 * (-1.0 / 3_628_800.0)))));
        // e^{iy} − 1 = −2 sin²(y/2) + i sin y; odd k flips the sign of E: E − 1 = −(e^{iy} − 1) − 2.
        let m_re = Vec4::splat(-2.0) * sh * sh;
        let m_im = Vec4::splat(2.0) * sh * ch;
        let odd = Vec4::from_array(odd_a).cmpgt(Vec4::ZERO);
        let em1_re = Vec4::select(odd, -m_re - Vec4::splat(2.0), m_re);
        let em1_im = Vec4::select(odd, -m_im, m_im);
        Some(LosslessLanes {
            n1,
            n1c,
            n2,
            n3,
            n2c,
            n3c,
            em1_re,
            em1_im,
        })
    }

    /// [`FilmResponseX4`] of the lossless case ([`Self::lossless_setup`]); None for absorbing
    /// or evanescent layers and ill-conditioned lanes.
    #[inline]
    fn response_lossless(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> Option<FilmResponseX4> {
        use glam::Vec4;
        let LosslessLanes {
            n1,
            n1c,
            n2,
            n3,
            n2c,
            n3c,
            em1_re,
            em1_im,
        } = self.lossless_setup(lambda_nm, cos_theta1)?;
        let e_re = em1_re + Vec4::ONE;
        let e_im = em1_im;

        // Airy sum with real admittances a, b, c (see response_general).
        let airy = |a: Vec4, b: Vec4, c: Vec4| {
            let (amb, apb, bpc, bmc) = (a - b, a + b, b + c, b - c);
            let p = apb * bmc;
            let num_re = amb * bpc + p * e_re;
            let num_im = p * e_im;
            let q = amb * bmc;
            let den0 = Vec4::splat(2.0) * b * (a + c);
            let den_re = den0 + q * em1_re;
            let den_im = q * em1_im;
            let den2 = den_re * den_re + den_im * den_im;
            let inv2 = Vec4::ONE / den2;
            let big2 =
                Vec4::splat(2.0) * (den0 * den0 + q * q * (em1_re * em1_re + em1_im * em1_im));
            let t_amp = Vec4::splat(4.0) * a * b;
            (
                (num_re * num_re + num_im * num_im) * inv2,
                t_amp * t_amp * inv2,
                big2 * inv2,
            )
        };
        let a_s = Vec4::splat(n1c);
        let (r_s, ts2, cond_s) = airy(a_s, n2c, n3c);
        let (r_p, tp02, cond_p) = airy(a_s / (n1 * n1), n2c / (n2 * n2), n3c / (n3 * n3));
        let max2 = Vec4::splat(F32_MAX_CONDITION * F32_MAX_CONDITION);
        if !(cond_s.cmple(max2).all() && cond_p.cmple(max2).all()) {
            return None;
        }
        let mut out = FilmResponseX4 {
            r_s: r_s.to_array(),
            r_p: r_p.to_array(),
            ..Default::default()
        };
        if n1c > 0.0 {
            // tmm.T_from_t with real n3 cosθ3: |t_p|² carries (n1/n3)².
            let tp2 = tp02 * (Vec4::splat(n1) / n3) * (Vec4::splat(n1) / n3);
            let inv_n1c = 1.0 / n1c;
            out.t_s = (ts2 * n3c * inv_n1c).max(Vec4::ZERO).to_array();
            out.t_p = (tp2 * n3c * inv_n1c).max(Vec4::ZERO).to_array();
        }
        Some(out)
    }

    /// Complex reflection amplitudes (r_s, r_p) at four wavelengths for `cos θ1` in the ambient
    /// (polarised rendering: their Mueller matrix), within 1e-5 of the f64
    /// [`ThinFilm::amplitudes`] as [`Self::response`] is of its powers: the lossless SIMD path
    /// where it applies, else the general complex lanes, else f64 for ill-conditioned lanes.
    #[inline]
    pub fn reflection_amplitudes(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> AmplitudesX4 {
        if let Some(a) = self.amplitudes_lossless(lambda_nm, cos_theta1) {
            return a;
        }
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        std::array::from_fn(|i| {
            let lane = self.general_lane(i, lambda_nm[i], cos1);
            if lane.well_conditioned {
                [lane.rs, lane.rp]
            } else {
                let c = |z: Complex32| Complex64::new(z.re as f64, z.im as f64);
                let a = ThinFilm {
                    ambient_ior: self.ambient_ior as f64,
                    film_ior: c(self.film_ior[i]),
                    thickness_nm: self.thickness_nm as f64,
                    substrate_ior: c(self.substrate_ior[i]),
                }
                .amplitudes(lambda_nm[i] as f64, cos1 as f64);
                let c32 = |z: Complex64| Complex32::new(z.re as f32, z.im as f32);
                [c32(a.r_s), c32(a.r_p)]
            }
        })
    }

    /// [`Self::reflection_amplitudes`] of the lossless case: r = N·conj(D)/|D|² with the
    /// numerator and denominator of [`Self::response_lossless`]'s Airy sums.
    #[inline]
    fn amplitudes_lossless(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> Option<AmplitudesX4> {
        use glam::Vec4;
        let l = self.lossless_setup(lambda_nm, cos_theta1)?;
        let (e_re, e_im) = (l.em1_re + Vec4::ONE, l.em1_im);
        let airy = |a: Vec4, b: Vec4, c: Vec4| {
            let (amb, apb, bpc, bmc) = (a - b, a + b, b + c, b - c);
            let p = apb * bmc;
            let (num_re, num_im) = (amb * bpc + p * e_re, p * e_im);
            let q = amb * bmc;
            let den0 = Vec4::splat(2.0) * b * (a + c);
            let (den_re, den_im) = (den0 + q * l.em1_re, q * l.em1_im);
            let inv2 = Vec4::ONE / (den_re * den_re + den_im * den_im);
            let big2 = Vec4::splat(2.0)
                * (den0 * den0 + q * q * (l.em1_re * l.em1_re + l.em1_im * l.em1_im));
            (
                (num_re * den_re + num_im * den_im) * inv2,
                (num_im * den_re - num_re * den_im) * inv2,
                big2 * inv2,
            )
        };
        let a_s = Vec4::splat(l.n1c);
        let (rs_re, rs_im, cond_s) = airy(a_s, l.n2c, l.n3c);
        let (rp_re, rp_im, cond_p) = airy(
            a_s / (l.n1 * l.n1),
            l.n2c / (l.n2 * l.n2),
            l.n3c / (l.n3 * l.n3),
        );
        let max2 = Vec4::splat(F32_MAX_CONDITION * F32_MAX_CONDITION);
        if !(cond_s.cmple(max2).all() && cond_p.cmple(max2).all()) {
            return None;
        }
        Some(std::array::from_fn(|i| {
            [
                Complex32::new(rs_re[i], rs_im[i]),
                Complex32::new(rp_re[i], rp_im[i]),
            ]
        }))
    }

    /// Any indices, lane by lane (complex arithmetic; f64 fallback for ill-conditioned lanes).
    #[inline]
    #[allow(clippy::needless_range_loop)] // lane i indexes four parallel arrays
    pub fn response_general(&self, lambda_nm: [f32; 4], cos_theta1: f32) -> FilmResponseX4 {
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        let n1c = self.ambient_ior * cos1;
        let mut out = FilmResponseX4::default();
        for i in 0..4 {
            let lane = self.general_lane(i, lambda_nm[i], cos1);
            // A sharp resonance (high finesse: near-grazing incidence, or a film between two
            // strong reflectors) amplifies f32 rounding of the phase and admittances beyond
            // 1e-5; such lanes are evaluated in f64 instead (rare in practice; always correct).
            if !lane.well_conditioned {
                let r = self.lane_f64(i, lambda_nm[i], cos1);
                out.r_s[i] = r.r_s as f32;
                out.r_p[i] = r.r_p as f32;
                out.t_s[i] = r.t_s as f32;
                out.t_p[i] = r.t_p as f32;
                continue;
            }
            out.r_s[i] = lane.rs.norm_sqr();
            out.r_p[i] = lane.rp.norm_sqr();
            if n1c > 0.0 {
                // tmm.T_from_t: s uses Re(n3 cosθ3), p uses Re(n3 conj(cosθ3)).
                let n3 = self.substrate_ior[i];
                let cos3 = lane.n3c / n3;
                out.t_s[i] = (lane.ts.norm_sqr() * lane.n3c.re / n1c).max(0.0);
                out.t_p[i] = (lane.tp.norm_sqr() * (n3 * cos3.conj()).re / n1c).max(0.0);
            }
        }
        out
    }

    /// Lane `i` of the general Airy sums at `lambda_nm` for the clamped `cos1`.
    #[inline]
    fn general_lane(&self, i: usize, lambda_nm: f32, cos1: f32) -> GeneralLane {
        let n1 = self.ambient_ior;
        let cos1_64 = cos1 as f64;
        let n1_64 = n1 as f64;
        let kx2_64 = n1_64 * n1_64 * ((1.0 - cos1_64) * (1.0 + cos1_64));
        let d_64 = self.thickness_nm as f64;
        let n1c = n1 * cos1;
        let n2 = self.film_ior[i];
        let n3 = self.substrate_ior[i];
        // Film n cosθ and phase in f64 (see module docs), reduced before sin/cos.
        let n2_64 = Complex64::new(n2.re as f64, n2.im as f64);
        let n2c_64 = forward_sqrt64(n2_64 * n2_64 - kx2_64);
        let beta = n2c_64 * (2.0 * PI * d_64 / lambda_nm as f64);
        // Only E = e^{2iβ} and |e^{iβ}| enter R and T. Write 2 Re β = kπ + y with
        // |y| ≤ π/2 (in f64, so y keeps full relative precision in f32); then
        // E = ±e^{x} e^{iy}, x = −2 Im β, and E − 1 is formed without cancellation:
        // e^{x} e^{iy} − 1 = expm1(x) e^{iy} + (e^{iy} − 1),  e^{iy} − 1 = −2 sin²(y/2) + i sin y.
        let two_beta = 2.0 * beta.re;
        let k = (two_beta / PI).round();
        let y = (two_beta - k * PI) as f32;
        let (sh, ch) = (0.5 * y).sin_cos();
        let eiy_m1 = Complex32::new(-2.0 * sh * sh, 2.0 * sh * ch);
        // Lossless film (the common case): x = 0, skip the exponentials.
        let (em1x, decay) = if beta.im == 0.0 {
            (0.0, 1.0)
        } else {
            (((-2.0 * beta.im) as f32).exp_m1(), (-beta.im).exp() as f32)
        };
        let plus = eiy_m1 * em1x + em1x + eiy_m1; // e^{x} e^{iy} − 1
        let e_minus_1 = if (k as i64) % 2 == 0 {
            plus
        } else {
            -plus - 2.0
        };

        let n2c = Complex32::new(n2c_64.re as f32, n2c_64.im as f32);
        // n3² − n1² sin²θ1 written as (n3 − n1)(n3 + n1) + (n1 cosθ1)²: no cancellation
        // when n3 ≈ n1 at grazing incidence (where n3² − kx² loses all f32 digits).
        let n1c_c = Complex32::new(n1, 0.0);
        let n1c_sq = Complex32::new(n1c * n1c, 0.0);
        let n3c = forward_sqrt32((n3 - n1c_c) * (n3 + n1c_c) + n1c_sq);
        // The Airy sum cleared of fractions. With admittances a, b, c of ambient, film and
        // substrate (s: n cosθ; p: n cosθ / n² = cosθ / n), r_ij = (y_i − y_j)/(y_i + y_j) and
        //   N = (a+b)(b+c) + (a−b)(b−c) E = 2b(a+c) + (a−b)(b−c)(E − 1),
        //   r = [(a−b)(b+c) + (a+b)(b−c) E] / N,
        //   t_s = 4ab e^{iβ} / N,   t_p = (n1/n3) 4ab e^{iβ} / N  (only |t| is needed, so
        //   e^{iβ} is replaced by its modulus).
        // Near grazing 1 + r12 r23 E → 0 and the textbook form loses ~2 digits in f32;
        // this form has no such cancellation.
        let airy = |a: Complex32, b: Complex32, cc: Complex32| {
            let e_full = e_minus_1 + 1.0;
            let num = (a - b) * (b + cc) + (a + b) * (b - cc) * e_full;
            let den = 2.0 * b * (a + cc) + (a - b) * (b - cc) * e_minus_1;
            // Condition number of the denominator: how much the cancellation in N
            // amplifies f32 rounding (≈ finesse of the resonance).
            // (|x| + |y|)² ≤ 2(|x|² + |y|²): a squared upper bound without hypot().
            let big2 = 2.0
                * ((2.0 * b * (a + cc)).norm_sqr() + ((a - b) * (b - cc) * e_minus_1).norm_sqr());
            let inv = den.inv();
            (num * inv, 4.0 * a * b * decay * inv, big2 * inv.norm_sqr())
        };
        let n1x = Complex32::new(n1, 0.0);
        let a_s = Complex32::new(n1c, 0.0);
        let (rs, ts, cond_s) = airy(a_s, n2c, n3c);
        let (rp, tp0, cond_p) = airy(a_s / (n1x * n1x), n2c / (n2 * n2), n3c / (n3 * n3));
        let tp = tp0 * n1x / n3;
        let max2 = F32_MAX_CONDITION * F32_MAX_CONDITION;
        GeneralLane {
            rs,
            rp,
            ts,
            tp,
            n3c,
            well_conditioned: cond_s <= max2 && cond_p <= max2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SIMD lossless path itself (not just `response`, which may fall back) against the
    /// f64 film: it must take the common dielectric cases and agree to 1e-5.
    #[test]
    fn lossless_simd_path_matches_f64() {
        let mut taken = 0usize;
        let mut max_err = 0.0f64;
        for (n1, n2, n3) in [
            (1.0f32, 1.37f32, 1.64f32),
            (1.0, 2.37, 1.64),
            (1.33, 1.9, 1.5),
        ] {
            for di in 0..=100 {
                let d = di as f32 * 49.7;
                for ai in 0..=45 {
                    let cos1 = (ai as f32 * 2.0).to_radians().cos();
                    let x4 = ThinFilmX4 {
                        ambient_ior: n1,
                        film_ior: [Complex32::new(n2, 0.0); 4],
                        thickness_nm: d,
                        substrate_ior: [Complex32::new(n3, 0.0); 4],
                    };
                    let lambdas = [360.0, 455.5 + di as f32, 600.25, 830.0];
                    let Some(got) = x4.response_lossless(lambdas, cos1) else {
                        continue;
                    };
                    taken += 1;
                    for (i, &l) in lambdas.iter().enumerate() {
                        let want = x4.lane_f64(i, l, cos1);
                        for (g, w) in [
                            (got.r_s[i], want.r_s),
                            (got.r_p[i], want.r_p),
                            (got.t_s[i], want.t_s),
                            (got.t_p[i], want.t_p),
                        ] {
                            let e = (g as f64 - w).abs();
                            assert!(
                                e < 1e-5,
                                "n {n1}/{n2}/{n3} d {d} cos {cos1} λ {l}: {g} vs {w}"
                            );
                            max_err = max_err.max(e);
                        }
                    }
                }
            }
        }
        assert!(taken > 3 * 101 * 40, "fast path taken only {taken} times");
        println!("lossless SIMD path: {taken} evaluations, max |Δ| {max_err:.2e}");
    }

    /// Complex amplitudes of every path (lossless SIMD, general complex, f64 fallback) against
    /// the f64 film's, phases included: what the Mueller matrices of polarised rendering use.
    #[test]
    fn reflection_amplitudes_match_f64() {
        let mut max_err = 0.0f64;
        for (n2, n3) in [
            (Complex32::new(1.37, 0.0), Complex32::new(1.64, 0.0)),
            (Complex32::new(2.37, 0.0), Complex32::new(1.5, 0.0)),
            (Complex32::new(1.38, 0.0), Complex32::new(0.18, 3.4)),
            (Complex32::new(1.9, 0.05), Complex32::new(1.5, 0.0)),
        ] {
            for d in [0.0f32, 120.0, 400.0, 1500.0, 4800.0] {
                for deg in [0.0f32, 30.0, 60.0, 85.0, 89.5] {
                    let cos1 = deg.to_radians().cos();
                    let film = ThinFilmX4 {
                        ambient_ior: 1.0,
                        film_ior: [n2; 4],
                        thickness_nm: d,
                        substrate_ior: [n3; 4],
                    };
                    let lambdas = [380.0, 471.5, 588.25, 760.0];
                    let got = film.reflection_amplitudes(lambdas, cos1);
                    for (i, &l) in lambdas.iter().enumerate() {
                        let c = |z: Complex32| Complex64::new(z.re as f64, z.im as f64);
                        let want = ThinFilm {
                            ambient_ior: 1.0,
                            film_ior: c(n2),
                            thickness_nm: d as f64,
                            substrate_ior: c(n3),
                        }
                        .amplitudes(l as f64, cos1 as f64);
                        for (g, w) in [(got[i][0], want.r_s), (got[i][1], want.r_p)] {
                            let e = (c(g) - w).norm();
                            assert!(e < 2e-5, "{n2}/{n3} d {d} {deg}° λ {l}: {g} vs {w}");
                            max_err = max_err.max(e);
                        }
                    }
                }
            }
        }
        println!("amplitudes: max |Δr| {max_err:.2e}");
    }

    #[test]
    fn lossless_path_declines_absorbing_and_evanescent_layers() {
        let base = ThinFilmX4 {
            ambient_ior: 1.0,
            film_ior: [Complex32::new(1.37, 0.0); 4],
            thickness_nm: 400.0,
            substrate_ior: [Complex32::new(1.64, 0.0); 4],
        };
        let l = [400.0, 500.0, 600.0, 700.0];
        assert!(base.response_lossless(l, 0.5).is_some());
        let mut metal = base;
        metal.substrate_ior[2] = Complex32::new(0.18, 3.4);
        assert!(metal.response_lossless(l, 0.5).is_none());
        // Film index below the ambient one: evanescent in the film at grazing incidence.
        let mut tir = base;
        tir.ambient_ior = 1.5;
        tir.film_ior = [Complex32::new(1.2, 0.0); 4];
        assert!(tir.response_lossless(l, 0.1).is_none());
        assert_eq!(tir.response(l, 0.1), tir.response_general(l, 0.1));
    }
}
