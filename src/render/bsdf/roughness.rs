//! Microfacet roughness as Mitsuba's rough plugins take it: a constant, or `alpha` /
//! `alpha_u` / `alpha_v` given as textures (a checkerboard, a bitmap), evaluated at each
//! shading point with the texture's `eval_1` (an RGB bitmap's luminance) and floored at
//! Mitsuba's 1e-4 (`MicrofacetDistribution::configure`) — so a texel of roughness 0 is a very
//! narrow glossy lobe there, not a mirror, as in Mitsuba.

use super::microfacet::{Distribution, Microfacet};
use super::ShadingCtx;
use crate::render::texture::Texture;
use crate::scene::mitsuba::PluginParams;
use crate::scene::{SpectrumDesc, TextureDesc};

/// A constant or textured roughness.
#[derive(Debug, Clone)]
pub enum Roughness {
    /// None: smooth (a Dirac lobe).
    Constant(Option<Microfacet>),
    /// α_u and α_v looked up at the shading point's uv (boxed: keeps [`super::Bsdf`] small).
    Textured {
        kind: Distribution,
        alpha_u: Box<Texture>,
        alpha_v: Box<Texture>,
    },
}

impl Roughness {
    /// The distribution at the shading point.
    #[inline]
    pub fn at(&self, ctx: &ShadingCtx) -> Option<Microfacet> {
        match self {
            Roughness::Constant(m) => *m,
            Roughness::Textured {
                kind,
                alpha_u,
                alpha_v,
            } => Some(Microfacet::of(
                *kind,
                scalar(alpha_u, ctx),
                scalar(alpha_v, ctx),
            )),
        }
    }

    /// Whether α is a `mesh_attribute`.
    pub fn reads_mesh_attribute(&self) -> bool {
        match self {
            Roughness::Constant(_) => false,
            Roughness::Textured {
                alpha_u, alpha_v, ..
            } => alpha_u.reads_mesh_attribute() || alpha_v.reads_mesh_attribute(),
        }
    }

    /// Whether the lobe is glossy (not a Dirac delta).
    pub fn is_rough(&self) -> bool {
        !matches!(self, Roughness::Constant(None))
    }

    /// Whether the model needs the dp/du tangent frame (α_u may differ from α_v).
    pub fn is_anisotropic(&self) -> bool {
        match self {
            Roughness::Constant(m) => m.is_some_and(|m| m.is_anisotropic()),
            Roughness::Textured { .. } => true,
        }
    }

    /// For logs.
    pub fn describe(&self) -> String {
        match self {
            Roughness::Constant(Some(m)) => m.describe(),
            Roughness::Constant(None) => "smooth".into(),
            Roughness::Textured { kind, .. } => format!("{} textured α", kind.name()),
        }
    }

    /// `distribution` and `alpha` or `alpha_u`/`alpha_v` (default 0.1) of a rough plugin, as
    /// numbers or textures. A constant roughness of 0 is smooth when `zero_is_smooth`.
    pub fn read(p: &mut PluginParams, zero_is_smooth: bool) -> anyhow::Result<Self> {
        let textured = ["alpha", "alpha_u", "alpha_v"]
            .iter()
            .any(|n| p.has(n) && !p.is_number(n));
        if !textured {
            let (kind, au, av) = p.microfacet()?;
            let smooth = zero_is_smooth && au == 0.0 && av == 0.0;
            return Ok(Roughness::Constant(
                (!smooth).then(|| Microfacet::of(kind, au, av)),
            ));
        }
        let kind = p.distribution()?;
        let (u, v) = match (p.has("alpha"), p.has("alpha_u"), p.has("alpha_v")) {
            (true, false, false) => {
                let a = p.texture("alpha", 0.1)?;
                (a.clone(), a)
            }
            (false, true, true) => (p.texture("alpha_u", 0.1)?, p.texture("alpha_v", 0.1)?),
            _ => {
                return Err(p.error("give either 'alpha' or both 'alpha_u' and 'alpha_v'"));
            }
        };
        for (name, t) in [("alpha_u", &u), ("alpha_v", &v)] {
            if let TextureDesc::Value(SpectrumDesc::Rgb(_) | SpectrumDesc::Tabulated(_)) = t {
                return Err(p.error_at(name, "roughness must be a number or a texture"));
            }
        }
        Ok(Roughness::Textured {
            kind,
            alpha_u: Box::new(Texture::new(&u)),
            alpha_v: Box::new(Texture::new(&v)),
        })
    }
}

/// A roughness at `uv`: [`eval_1`], ≥ 0.
fn scalar(t: &Texture, ctx: &ShadingCtx) -> f32 {
    eval_1(t, ctx).max(0.0)
}

/// Mitsuba 3.9's `Texture::eval_1`, the scalar lookup its BSDFs use for roughness, opacity and
/// blend weights: an RGB bitmap's luminance; for a `checkerboard`, **color1 where `eval`
/// gives color0** and the other way round — its `eval_1` tests `mask.x != mask.y` where
/// `eval` tests `==` (`checkerboard.cpp`), so a checkerboard roughness sits on the other
/// squares than the same checkerboard as a colour; a `mesh_attribute`'s value (a
/// 1-channel attribute is stored as a grey, so this is its value); else the value.
pub fn eval_1(t: &Texture, ctx: &ShadingCtx) -> f32 {
    let uv = ctx.uv;
    match t {
        Texture::VertexColor => {
            let c = ctx.color;
            0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
        }
        Texture::Bitmap(b) if b.channels >= 3 => {
            let c = b.eval(uv);
            0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
        }
        Texture::Checkerboard {
            color0,
            color1,
            to_uv,
        } => {
            let p = *to_uv * glam::Vec3::new(uv.x, uv.y, 1.0);
            let (mx, my) = (p.x - p.x.floor() > 0.5, p.y - p.y.floor() > 0.5);
            if mx != my {
                color0.mean_hint()
            } else {
                color1.mean_hint()
            }
        }
        t => t.eval_scalar(uv),
    }
}
