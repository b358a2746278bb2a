//! Mitsuba `twosided`: the back face scatters like the front. Light arriving from below the
//! shading normal sees the nested model in the frame mirrored at the tangent plane.

use super::{
    Bsdf, BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf,
    ShadingCtx,
};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct TwoSided {
    pub inner: Box<Bsdf>,
}

/// `v` mirrored at the tangent plane.
#[inline]
fn mirror(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

/// (wi, wo) seen from the front: both mirrored when wi is below.
#[inline]
fn front(wi: Vec3, wo: Vec3) -> (Vec3, Vec3) {
    if wi.z < 0.0 {
        (mirror(wi), mirror(wo))
    } else {
        (wi, wo)
    }
}

/// `sample` of the nested model seen from the front (wi mirrored when below), its direction
/// (`wo_of`) and value (`mirror_value`) mapped back.
#[inline]
fn sampled_from_front<T>(
    wi: Vec3,
    sample: impl FnOnce(Vec3) -> Option<T>,
    wo_of: impl FnOnce(&mut T) -> &mut Vec3,
    mirror_value: impl FnOnce(&mut T),
) -> Option<T> {
    if wi.z < 0.0 {
        let mut s = sample(mirror(wi))?;
        let wo = wo_of(&mut s);
        *wo = mirror(*wo);
        mirror_value(&mut s);
        Some(s)
    } else {
        sample(wi)
    }
}

impl TwoSided {
    /// `inner` on both faces. A model that is already two-sided (a polariser sheet) is
    /// refused: wrapping it would mirror what it does on its back face.
    pub fn new(inner: Bsdf) -> anyhow::Result<Self> {
        if matches!(inner, Bsdf::Polarizer(_)) {
            anyhow::bail!("a polarizer is already two-sided; remove the twosided wrapper");
        }
        Ok(TwoSided {
            inner: Box::new(inner),
        })
    }
}

impl BsdfPlugin for TwoSided {
    const PLUGINS: &'static [&'static str] = &["twosided"];

    /// One nested BSDF (default: diffuse).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let inner = match p.bsdfs()?.as_slice() {
            [b] => b.clone(),
            [] => Bsdf::default_diffuse(),
            _ => {
                return Err(p.error("twosided with two different BSDFs is not supported (give one)"))
            }
        };
        TwoSided::new(inner).map_err(|e| p.error(e))
    }
}

impl BsdfModel for TwoSided {
    fn flags(&self) -> BsdfFlags {
        self.inner.flags() | BsdfFlags::TWO_SIDED
    }

    fn describe(&self) -> String {
        format!("twosided {}", self.inner.describe())
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        let (wi, wo) = front(wi, wo);
        self.inner.eval(ctx, wi, wo)
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        let (wi, wo) = front(wi, wo);
        self.inner.pdf(ctx, wi, wo)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let sample = |wi| self.inner.sample(ctx, wi, u1, u2, lobes);
        sampled_from_front(wi, sample, |s| &mut s.wo, |_| {})
    }

    fn sample_split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
    ) -> [Option<BsdfSample>; 2] {
        let flip = wi.z < 0.0;
        let lobes = self
            .inner
            .sample_split(ctx, if flip { mirror(wi) } else { wi }, u1, u2);
        lobes.map(|s| {
            s.map(|mut s| {
                if flip {
                    s.wo = mirror(s.wo);
                }
                s
            })
        })
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        self.inner.polarized().map(|_| self as &dyn PolarizedBsdf)
    }

    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        self.inner.shading_frame(si)
    }

    fn perturbed_normal(&self, si: &SurfaceInteraction) -> glam::Vec3 {
        self.inner.perturbed_normal(si)
    }

    /// The inner model's lobe, about the normal on the side the light arrives from.
    fn glossy_lobe(&self) -> Option<super::microfacet::Microfacet> {
        self.inner.glossy_lobe()
    }
}

impl PolarizedBsdf for TwoSided {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        let Ok(inner) = self.inner.polarized() else {
            return MuellerValue::ZERO;
        };
        if wi.z < 0.0 {
            inner.eval_mueller(ctx, mirror(wi), mirror(wo)).mirrored()
        } else {
            inner.eval_mueller(ctx, wi, wo)
        }
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let inner = self.inner.polarized().ok()?;
        let sample = |wi| inner.sample_mueller(ctx, wi, u1, u2, lobes);
        sampled_from_front(wi, sample, |s| &mut s.0.wo, |s| s.1 = s.1.mirrored())
    }
}
