//! Smooth and rough (GGX) conductors (Mitsuba `conductor`, `roughconductor`), one-sided.
//! The complex index comes from [`crate::optics::Ior`] (constant or a named metal).

use super::fresnel::fresnel_conductor;
use super::microfacet::{reflection_eval, reflection_lobe_pdf, reflection_sample, Ggx};
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
        reflection_eval(self.ggx, wi, wo, |c| self.fresnel(ctx, c))
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        reflection_lobe_pdf(self.ggx, wi, wo)
    }

    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3, u: Vec2) -> Option<BsdfSample> {
        reflection_sample(self.ggx, wi, u, |c| self.fresnel(ctx, c))
    }
}
