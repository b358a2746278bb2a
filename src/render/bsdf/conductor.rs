//! Smooth and rough (GGX) conductors (Mitsuba `conductor`, `roughconductor`), one-sided.
//! The complex index comes from [`crate::optics::Ior`] (constant or a named metal).

use super::fresnel::{fresnel_conductor, reflect, reflect_local};
use super::microfacet::Ggx;
use super::{BsdfSample, ShadingCtx};
use crate::optics::Ior;
use crate::render::texture::Spec;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct Conductor {
    pub eta: Ior,
    /// None = smooth (a delta lobe).
    pub ggx: Option<Ggx>,
}

impl Conductor {
    #[inline]
    fn fresnel(&self, ctx: &ShadingCtx, cos_i: f32) -> Spec {
        Spec::from_array(ctx.wl.lambda.map(|l| {
            let n = self.eta.at(l as f64);
            fresnel_conductor(cos_i, n.re as f32, n.im as f32)
        }))
    }

    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        match self.ggx.and_then(|ggx| ggx.reflection(wi, wo)) {
            Some((m, weight)) => self.fresnel(ctx, wi.dot(m)) * weight,
            None => Spec::ZERO,
        }
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        self.ggx.map_or(0.0, |ggx| ggx.reflection_pdf(wi, wo))
    }

    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        match self.ggx {
            None => Some(BsdfSample::delta(
                reflect_local(wi),
                self.fresnel(ctx, wi.z),
            )),
            Some(ggx) => {
                let m = ggx.sample_visible(wi, u);
                let wo = reflect(wi, m);
                if wo.z <= 0.0 {
                    return None;
                }
                let pdf = ggx.pdf_visible(wi, m) / (4.0 * wo.dot(m));
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                // eval / pdf = F · G1(wo) for visible-normal sampling with separable Smith G.
                let weight = self.fresnel(ctx, wi.dot(m)) * ggx.g1(wo, m);
                Some(BsdfSample::smooth(wo, weight, pdf))
            }
        }
    }
}
