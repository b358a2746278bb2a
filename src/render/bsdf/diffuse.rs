//! Lambertian reflection (Mitsuba `diffuse`), one-sided.

use super::{BsdfSample, ShadingCtx};
use crate::render::geometry::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::render::texture::{Spec, Texture};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Debug, Clone)]
pub struct Diffuse {
    pub reflectance: Texture,
}

impl Diffuse {
    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spec::ZERO;
        }
        self.reflectance.eval(ctx.uv, ctx.wl) * (FRAC_1_PI * wo.z)
    }
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wo.z)
    }
    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let wo = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wo.z);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample::smooth(
            wo,
            self.reflectance.eval(ctx.uv, ctx.wl),
            pdf,
        ))
    }
}
