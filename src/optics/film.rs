//! The Airy single film (seed eq. 4): ambient n1 | film n2, thickness d | substrate n3.
//!
//! r = (r12 + r23 e^{iΔ}) / (1 + r12 r23 e^{iΔ}),  Δ = 4π n2 d cosθ2 / λ  (eqs. 2, 3, 4)
//! t = t12 t23 e^{iΔ/2} / (1 + r12 r23 e^{iΔ})

use super::fresnel::{interface, n_cos_theta};
use super::OpticsError;
use num_complex::Complex64;

/// A single film on a semi-infinite substrate, all indices at one wavelength.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThinFilm {
    /// Ambient (incidence) medium, real: light arrives from a lossless medium.
    pub ambient_ior: f64,
    /// Film index n2 (+ i k2 for absorbing films).
    pub film_ior: Complex64,
    /// Physical film thickness d in nanometres.
    pub thickness_nm: f64,
    /// Substrate index n3 + i k3 (metals: k3 > 0).
    pub substrate_ior: Complex64,
}

/// Power reflectance and transmittance for s and p polarisation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FilmResponse {
    pub r_s: f64,
    pub r_p: f64,
    /// Power transmitted into the substrate (zero for an absorbing substrate's far side is
    /// *not* implied: this is the flux crossing the film–substrate interface).
    pub t_s: f64,
    pub t_p: f64,
}

impl FilmResponse {
    /// Unpolarised reflectance (R_s + R_p) / 2.
    #[inline]
    pub fn r(&self) -> f64 {
        0.5 * (self.r_s + self.r_p)
    }
    /// Unpolarised transmittance (T_s + T_p) / 2.
    #[inline]
    pub fn t(&self) -> f64 {
        0.5 * (self.t_s + self.t_p)
    }
}

/// Complex amplitudes r_s, r_p, t_s, t_p of the film (for Mueller matrices and stacks).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilmAmplitudes {
    pub r_s: Complex64,
    pub r_p: Complex64,
    pub t_s: Complex64,
    pub t_p: Complex64,
}

fn check_index(n: Complex64) -> Result<(), OpticsError> {
    if n.re.is_finite() && n.im.is_finite() && n.re > 0.0 && n.im >= 0.0 {
        Ok(())
    } else {
        Err(OpticsError::BadIndex(format!("{}{:+}i", n.re, n.im)))
    }
}

impl ThinFilm {
    /// Rejects inputs that would otherwise produce NaN: negative or non-finite thickness,
    /// non-physical indices.
    pub fn validate(&self) -> Result<(), OpticsError> {
        if !(self.thickness_nm.is_finite() && self.thickness_nm >= 0.0) {
            return Err(OpticsError::BadThickness(self.thickness_nm));
        }
        check_index(Complex64::new(self.ambient_ior, 0.0))?;
        check_index(self.film_ior)?;
        check_index(self.substrate_ior)
    }

    /// Complex amplitudes at wavelength `lambda_nm` for a ray with `cos θ1` in the ambient.
    /// No validation (hot path): call [`ThinFilm::validate`] once on untrusted input.
    #[inline]
    pub fn amplitudes(&self, lambda_nm: f64, cos_theta1: f64) -> FilmAmplitudes {
        let n1 = Complex64::new(self.ambient_ior, 0.0);
        let cos1 = Complex64::new(cos_theta1.clamp(0.0, 1.0), 0.0);
        // (1 − c)(1 + c) keeps sin²θ1 accurate near normal incidence.
        let c1 = cos_theta1.clamp(0.0, 1.0);
        let kx = self.ambient_ior * ((1.0 - c1) * (1.0 + c1)).max(0.0).sqrt();
        let n2 = self.film_ior;
        let n3 = self.substrate_ior;
        let n2c = n_cos_theta(n2, kx);
        let n3c = n_cos_theta(n3, kx);
        let cos2 = n2c / n2;
        let cos3 = n3c / n3;
        let i12 = interface(n1, n2, cos1, cos2);
        let i23 = interface(n2, n3, cos2, cos3);
        // β = 2π d n2 cosθ2 / λ, Δ = 2β. Im β ≥ 0 by the branch choice, so |e^{iβ}| ≤ 1.
        let beta = n2c * (2.0 * std::f64::consts::PI * self.thickness_nm / lambda_nm);
        let decay = (-beta.im).exp();
        let (s1, c1) = beta.re.sin_cos();
        let e_half = Complex64::new(decay * c1, decay * s1);
        let e_full = e_half * e_half;
        let airy_r =
            |r12: Complex64, r23: Complex64| (r12 + r23 * e_full) / (1.0 + r12 * r23 * e_full);
        let airy_t = |t12: Complex64, t23: Complex64, r12: Complex64, r23: Complex64| {
            t12 * t23 * e_half / (1.0 + r12 * r23 * e_full)
        };
        FilmAmplitudes {
            r_s: airy_r(i12.r_s, i23.r_s),
            r_p: airy_r(i12.r_p, i23.r_p),
            t_s: airy_t(i12.t_s, i23.t_s, i12.r_s, i23.r_s),
            t_p: airy_t(i12.t_p, i23.t_p, i12.r_p, i23.r_p),
        }
    }

    /// Power reflectance and transmittance at `lambda_nm` for `cos θ1` in the ambient.
    #[inline]
    pub fn response(&self, lambda_nm: f64, cos_theta1: f64) -> FilmResponse {
        let a = self.amplitudes(lambda_nm, cos_theta1);
        let n1 = self.ambient_ior;
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        let sin1 = ((1.0 - cos1) * (1.0 + cos1)).max(0.0).sqrt();
        let n3 = self.substrate_ior;
        let n3c = n_cos_theta(n3, n1 * sin1);
        let cos3 = n3c / n3;
        // Power transmittance (tmm.T_from_t): s uses Re(n3 cos3), p uses Re(n3 conj(cos3)).
        let denom = n1 * cos1;
        let (t_s, t_p) = if denom > 0.0 {
            (
                a.t_s.norm_sqr() * n3c.re / denom,
                a.t_p.norm_sqr() * (n3 * cos3.conj()).re / denom,
            )
        } else {
            (0.0, 0.0)
        };
        FilmResponse {
            r_s: a.r_s.norm_sqr(),
            r_p: a.r_p.norm_sqr(),
            t_s,
            t_p,
        }
    }

    /// Checked version of [`ThinFilm::response`] taking the incident angle in degrees.
    pub fn response_at_angle(
        &self,
        lambda_nm: f64,
        incident_deg: f64,
    ) -> Result<FilmResponse, OpticsError> {
        self.validate()?;
        if !(lambda_nm.is_finite() && lambda_nm > 0.0) {
            return Err(OpticsError::BadWavelength(lambda_nm));
        }
        if !(incident_deg.is_finite() && (0.0..90.0).contains(&incident_deg)) {
            return Err(OpticsError::BadAngle(incident_deg));
        }
        Ok(self.response(lambda_nm, incident_deg.to_radians().cos()))
    }
}
