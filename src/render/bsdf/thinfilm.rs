//! Opaque thin film on a substrate: the Fresnel term is the
//! Airy single-film reflectance R(λ, θ) of [`crate::optics::ThinFilm`] (seed eq. 4), averaged
//! over s and p. Smooth: a mirror lobe weighted by R. Rough (α > 0): a GGX microfacet lobe with
//! the Airy term evaluated at the microfacet angle (the "rough thin film" of Belcour & Barla
//! 2017 without their spectral antialiasing). Light transmitted into the substrate is absorbed.
//! One-sided.

use super::microfacet::{reflection_eval, reflection_lobe_pdf, reflection_sample, Ggx};
use super::{BsdfSample, Counters, ShadingCtx};
use crate::optics::film_f32::ThinFilmX4;
use crate::optics::{Ior, ThinFilm};
use crate::render::texture::{Spec, Texture};
use glam::{Vec2, Vec3};
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct ThinFilmBsdf {
    pub film_ior: Ior,
    pub thickness_nm: Texture,
    pub substrate_ior: Ior,
    /// None = smooth.
    pub ggx: Option<Ggx>,
}

impl ThinFilmBsdf {
    /// The film at one wavelength for a given thickness (negative/NaN thickness → 0: a texture
    /// hole shows the bare substrate instead of poisoning the image).
    #[inline]
    pub fn film_at(&self, lambda_nm: f32, thickness_nm: f32) -> ThinFilm {
        let d = if thickness_nm.is_finite() && thickness_nm > 0.0 {
            thickness_nm as f64
        } else {
            0.0
        };
        ThinFilm {
            ambient_ior: 1.0,
            film_ior: self.film_ior.at(lambda_nm as f64),
            thickness_nm: d,
            substrate_ior: self.substrate_ior.at(lambda_nm as f64),
        }
    }

    /// Unpolarised (R, T) at the four wavelengths for `cos θ` at the film, from the optics
    /// module's single-precision 4-wavelength Airy path ([`ThinFilmX4`], within 1e-5 of the
    /// f64 [`ThinFilm`]).
    #[inline]
    pub fn reflect_transmit(
        &self,
        ctx: &ShadingCtx,
        cos_theta: f32,
        counters: &mut Counters,
    ) -> (Spec, Spec) {
        counters.film_evals += 1;
        let d = self.thickness_nm.eval_scalar(ctx.uv);
        let d = if d.is_finite() && d > 0.0 { d } else { 0.0 };
        let c32 = |z: crate::optics::Complex64| Complex32::new(z.re as f32, z.im as f32);
        let film = ThinFilmX4 {
            ambient_ior: 1.0,
            film_ior: ctx.wl.lambda.map(|l| c32(self.film_ior.at(l as f64))),
            thickness_nm: d,
            substrate_ior: ctx.wl.lambda.map(|l| c32(self.substrate_ior.at(l as f64))),
        };
        let resp = film.response(ctx.wl.lambda, cos_theta.clamp(0.0, 1.0));
        let clean = |v: f32, hi: f32| if v.is_finite() { v.clamp(0.0, hi) } else { 0.0 };
        let r = resp.r().map(|v| clean(v, 1.0));
        let t = resp.t().map(|v| clean(v, f32::MAX));
        (Spec::from_array(r), Spec::from_array(t))
    }

    #[inline]
    fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32, counters: &mut Counters) -> Spec {
        self.reflect_transmit(ctx, cos_theta, counters).0
    }

    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3, counters: &mut Counters) -> Spec {
        reflection_eval(self.ggx, wi, wo, |c| self.reflectance(ctx, c, counters))
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        reflection_lobe_pdf(self.ggx, wi, wo)
    }

    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u: Vec2,
        counters: &mut Counters,
    ) -> Option<BsdfSample> {
        reflection_sample(self.ggx, wi, u, |c| self.reflectance(ctx, c, counters))
    }
}
