//! Mitsuba's `null`: a surface that does not scatter — light passes straight through
//! (wo = −wi, weight 1, a null interaction). It bounds participating media without
//! refracting (Mitsuba 3 `null.cpp`): `volpath` crosses it without a path vertex and lets
//! shadow rays through (`render/integrator/media.rs`); the surface path tracer treats it as
//! any Dirac lobe and its shadow rays are blocked, as Mitsuba's `path` does.

use super::{BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct NullBsdf;

impl BsdfPlugin for NullBsdf {
    const PLUGINS: &'static [&'static str] = &["null"];

    /// No parameters.
    fn build(_p: &mut PluginParams) -> anyhow::Result<Self> {
        Ok(NullBsdf)
    }
}

impl BsdfModel for NullBsdf {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::NULL | BsdfFlags::TWO_SIDED
    }

    fn describe(&self) -> String {
        "null".to_string()
    }

    super::delta_lobes_only!();

    fn sample(
        &self,
        _ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        lobes
            .transmission()
            .then(|| BsdfSample::delta(-wi, Spec::ONE, 1.0, BsdfFlags::NULL))
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("null has no polarised form in thinfilm")
    }
}
