//! Lambertian reflection (Mitsuba `diffuse`), one-sided. Depolarising.

use super::ShadingCtx;
use super::{BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf};
use crate::render::geometry::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::{SpectrumDesc, TextureDesc};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Debug, Clone)]
pub struct Diffuse {
    pub reflectance: Texture,
}

impl Diffuse {
    pub fn new(reflectance: &TextureDesc) -> Self {
        Diffuse {
            reflectance: Texture::new(reflectance),
        }
    }

    /// A constant grey reflectance.
    pub fn constant(reflectance: f32) -> Self {
        Self::new(&TextureDesc::Value(SpectrumDesc::Constant(reflectance)))
    }
}

impl BsdfPlugin for Diffuse {
    const PLUGINS: &'static [&'static str] = &["diffuse"];

    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        Ok(Diffuse::new(&p.texture("reflectance", 0.5)?))
    }
}

impl BsdfModel for Diffuse {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DIFFUSE_REFLECTION.with(
            BsdfFlags::VERTEX_COLOR,
            self.reflectance.reads_mesh_attribute(),
        )
    }

    fn describe(&self) -> String {
        "diffuse".into()
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spec::ZERO;
        }
        self.reflectance.eval_at(ctx) * (FRAC_1_PI * wo.z)
    }

    fn pdf(&self, _ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wo.z)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        if wi.z <= 0.0 || !lobes.reflection() {
            return None;
        }
        let wo = square_to_cosine_hemisphere(u2);
        let pdf = cosine_hemisphere_pdf(wo.z);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample::smooth(
            wo,
            self.reflectance.eval_at(ctx),
            pdf,
            BsdfFlags::DIFFUSE_REFLECTION,
        ))
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Ok(self)
    }
}

/// A depolariser: only S0 survives (Mitsuba's polarised `diffuse`).
impl PolarizedBsdf for Diffuse {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        MuellerValue::depolarizing(self.eval(ctx, wi, wo))
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let s = self.sample(ctx, wi, u1, u2, lobes)?;
        Some((s, MuellerValue::depolarizing(s.weight)))
    }
}
