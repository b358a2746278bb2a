//! Mitsuba's `mask`: an opacity texture over a nested BSDF. With probability 1 − opacity the
//! path passes straight through (a null interaction, wo = −wi, weight 1), otherwise the
//! nested model scatters with its value scaled by the opacity (Mitsuba 3 `mask.cpp`). The
//! path integrator treats the null lobe as any Dirac lobe, as Mitsuba's `path` does (shadow
//! rays are blocked by masked surfaces in both).

use super::{Bsdf, BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct Mask {
    pub inner: Box<Bsdf>,
    pub opacity: Texture,
}

impl Mask {
    /// Opacity at the shading point, in [0, 1]: Mitsuba's `eval_1`
    /// ([`super::roughness::eval_1`]: an RGB bitmap's luminance, a checkerboard's squares
    /// swapped).
    fn opacity(&self, ctx: &ShadingCtx) -> f32 {
        super::roughness::eval_1(&self.opacity, ctx).clamp(0.0, 1.0)
    }
}

impl BsdfPlugin for Mask {
    const PLUGINS: &'static [&'static str] = &["mask"];

    /// `opacity` (0.5; value or texture), one nested BSDF (default diffuse).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let opacity = Texture::new(&p.texture("opacity", 0.5)?);
        let inner = match p.bsdfs()?.as_slice() {
            [b] => b.clone(),
            [] => Bsdf::default_diffuse(),
            _ => return Err(p.error("mask takes one nested BSDF")),
        };
        Ok(Mask {
            inner: Box::new(inner),
            opacity,
        })
    }
}

impl BsdfModel for Mask {
    fn flags(&self) -> BsdfFlags {
        (self.inner.flags() | BsdfFlags::NULL)
            .with(BsdfFlags::VERTEX_COLOR, self.opacity.reads_mesh_attribute())
    }

    fn describe(&self) -> String {
        format!("mask {}", self.inner.describe())
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        self.inner.eval(ctx, wi, wo) * self.opacity(ctx)
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        self.inner.pdf(ctx, wi, wo) * self.opacity(ctx)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let opacity = self.opacity(ctx);
        if !lobes.transmission() {
            // The null lobe is masked out: the nested model at its opacity-scaled value.
            let mut s = self.inner.sample(ctx, wi, u1, u2, lobes)?;
            s.weight *= opacity;
            return Some(s);
        }
        let null_pdf = 1.0 - opacity;
        if u1 < null_pdf {
            return Some(BsdfSample::delta(-wi, Spec::ONE, null_pdf, BsdfFlags::NULL));
        }
        let u1 = ((u1 - null_pdf) / opacity).clamp(0.0, 1.0 - f32::EPSILON);
        let mut s = self.inner.sample(ctx, wi, u1, u2, lobes)?;
        s.pdf *= opacity;
        Some(s)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("mask has no polarised form in thinfilm")
    }

    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        self.inner.shading_frame(si)
    }

    fn perturbed_normal(&self, si: &SurfaceInteraction) -> glam::Vec3 {
        self.inner.perturbed_normal(si)
    }
}
