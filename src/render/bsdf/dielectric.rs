//! Smooth dielectric interface (Mitsuba `dielectric`): Fresnel-weighted choice between mirror
//! reflection and refraction. Two-sided. With a wavelength-dependent index the refracted
//! direction differs per wavelength, so the sample uses the hero wavelength's index and asks
//! the integrator to terminate the secondary wavelengths (Wilkie et al. 2014; pbrt-v4).

use super::fresnel::{fresnel_dielectric, reflect_local};
use super::{BsdfSample, ShadingCtx};
use crate::optics::Ior;
use crate::render::texture::Spec;
use glam::Vec3;

#[derive(Debug, Clone)]
pub struct Dielectric {
    pub int_ior: Ior,
    pub ext_ior: Ior,
    /// Set by effect analysis: either index depends on wavelength.
    pub dispersive: bool,
}

impl Dielectric {
    /// Relative index n_int / n_ext at `lambda_nm` (real part).
    #[inline]
    fn eta_at(&self, lambda_nm: f32) -> f32 {
        (self.int_ior.at(lambda_nm as f64).re / self.ext_ior.at(lambda_nm as f64).re) as f32
    }

    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3, u1: f32) -> Option<BsdfSample> {
        let eta = self.eta_at(ctx.wl.lambda[0]);
        let (r, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, eta);
        let mut s = if u1 <= r {
            BsdfSample::delta(reflect_local(wi), Spec::ONE)
        } else {
            let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
            // Radiance is compressed by η² crossing into the denser medium (Veach 1997 §5.2).
            let mut s = BsdfSample::delta(wo, Spec::splat(eta_ti * eta_ti));
            s.eta = eta_it;
            s
        };
        s.pdf = if u1 <= r { r } else { 1.0 - r };
        // pbrt-v4 terminates on either branch: the choice itself used the hero index.
        s.terminate_secondary = self.dispersive;
        if !s.wo.is_finite() {
            return None;
        }
        Some(s)
    }
}
