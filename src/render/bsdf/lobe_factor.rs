//! Mitsuba's `specular_reflectance` / `specular_transmittance`: a reflectance texture (a
//! number, an RGB reflectance, a spectrum or a bitmap; default 1) that multiplies a lobe's
//! value and its sample weight but not its sampling probability — as Mitsuba 3's `conductor`,
//! `roughconductor`, `dielectric`, `roughdielectric` and `thindielectric` apply it
//! (`value *= m_specular_reflectance->eval(si)` after the Fresnel-weighted lobe choice).

use super::{BsdfFlags, BsdfSample, ShadingCtx};
use crate::render::polarization::Mueller;
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::{SpectrumDesc, TextureDesc};
use glam::Vec3;

/// One lobe's factor; `None` is Mitsuba's default 1 (nothing to evaluate). Boxed: most
/// BSDFs have none, and [`super::Bsdf`] stays small.
#[derive(Debug, Clone, Default)]
pub struct LobeFactor(Option<Box<Texture>>);

impl LobeFactor {
    /// Reads parameter `name` (default 1).
    pub fn read(p: &mut PluginParams, name: &str) -> anyhow::Result<Self> {
        let t = p.texture(name, 1.0)?;
        let unit = match &t {
            TextureDesc::Value(SpectrumDesc::Constant(v)) => *v == 1.0,
            TextureDesc::Value(SpectrumDesc::Rgb(c)) => c.iter().all(|&v| v == 1.0),
            _ => false,
        };
        Ok(LobeFactor((!unit).then(|| Box::new(Texture::new(&t)))))
    }

    /// Whether the factor is a `mesh_attribute`.
    pub fn reads_mesh_attribute(&self) -> bool {
        self.0.as_ref().is_some_and(|t| t.reads_mesh_attribute())
    }

    /// Whether the factor is 1 everywhere.
    pub fn is_one(&self) -> bool {
        self.0.is_none()
    }

    /// The factor at the shading point's wavelengths and uv.
    #[inline]
    pub fn eval(&self, ctx: &ShadingCtx) -> Spec {
        match &self.0 {
            None => Spec::ONE,
            Some(t) => t.eval_at(ctx),
        }
    }

    /// Per-wavelength Mueller matrices scaled by the factor (a non-polarising attenuation).
    #[inline]
    pub fn scale_mueller(&self, ctx: &ShadingCtx, m: [Mueller; 4]) -> [Mueller; 4] {
        if self.is_one() {
            return m;
        }
        let f = self.eval(ctx).to_array();
        let mut i = 0;
        m.map(|x| {
            i += 1;
            x.scale(f[i - 1])
        })
    }

    /// Mitsuba's `Texture::mean()` of the factor ([`texture_mean`]).
    pub fn mean(&self) -> f32 {
        self.0.as_deref().map_or(1.0, texture_mean)
    }

    /// A short description for logs ("" when 1).
    pub fn describe(&self, name: &str) -> String {
        if self.is_one() {
            String::new()
        } else {
            format!(" {name}={:?}", self.0.as_ref().map(|t| t.desc()))
        }
    }
}

/// Mitsuba's `Texture::mean()`, which weights sampling strategies (`plastic`'s specular
/// sampling weight): an RGB reflectance's spectrum averaged at 16 wavelengths evenly spaced
/// over 360–830 nm (`srgb_model_mean`), a constant's value; 0.5 for other textures.
pub fn texture_mean(t: &Texture) -> f32 {
    use crate::render::texture::Spectrum;
    match t {
        Texture::Value(Spectrum::Albedo(p, _)) => {
            (0..16)
                .map(|i| p.eval(360.0 + 470.0 * i as f32 / 15.0))
                .sum::<f32>()
                / 16.0
        }
        Texture::Value(s) => s.mean_hint(),
        _ => 0.5,
    }
}

/// The reflection and transmission factors of a two-sided interface.
#[derive(Debug, Clone, Default)]
pub struct SpecularFactors {
    pub reflection: LobeFactor,
    pub transmission: LobeFactor,
}

impl SpecularFactors {
    /// Reads `specular_reflectance` and `specular_transmittance` (default 1).
    pub fn read(p: &mut PluginParams) -> anyhow::Result<Self> {
        Ok(SpecularFactors {
            reflection: LobeFactor::read(p, "specular_reflectance")?,
            transmission: LobeFactor::read(p, "specular_transmittance")?,
        })
    }

    /// Whether either factor is a `mesh_attribute`.
    pub fn reads_mesh_attribute(&self) -> bool {
        self.reflection.reads_mesh_attribute() || self.transmission.reads_mesh_attribute()
    }

    /// Whether both are 1.
    pub fn is_one(&self) -> bool {
        self.reflection.is_one() && self.transmission.is_one()
    }

    /// The factor of the lobe joining wi and wo (reflection when on the same side).
    #[inline]
    pub fn for_pair(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z * wo.z > 0.0 {
            self.reflection.eval(ctx)
        } else {
            self.transmission.eval(ctx)
        }
    }

    /// `s` with its weight scaled by its lobe's factor.
    #[inline]
    pub fn scale_sample(&self, ctx: &ShadingCtx, mut s: BsdfSample) -> BsdfSample {
        if !self.is_one() {
            let f = if s.lobe.intersects(BsdfFlags::TRANSMISSION) {
                self.transmission.eval(ctx)
            } else {
                self.reflection.eval(ctx)
            };
            s.weight *= f;
        }
        s
    }

    /// A short description for logs.
    pub fn describe(&self) -> String {
        self.reflection.describe("specular_reflectance")
            + &self.transmission.describe("specular_transmittance")
    }
}
