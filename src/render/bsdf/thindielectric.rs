//! Mitsuba's `thindielectric`: a thin slab of dielectric (a window pane) whose two parallel
//! interfaces are folded into one surface. Light reflects with the slab's total reflectance
//! R' = R + T²R / (1 − R²) (the geometric series of internal reflections, R the single
//! interface's Fresnel reflectance, T = 1 − R) or passes straight through (wo = −wi, no
//! refraction, no radiance scaling) with 1 − R'. Two-sided, both lobes Dirac deltas.
//! Polarised form: none (Mitsuba's polarised thin dielectric is not reproduced).
//! `specular_reflectance` / `specular_transmittance` scale the lobes' weights
//! ([`SpecularFactors`]).

use super::fresnel::{fresnel_dielectric, reflect_local};
use super::lobe_factor::SpecularFactors;
use super::{BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx};
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct ThinDielectric {
    /// n_int / n_ext.
    pub eta: f32,
    pub factors: SpecularFactors,
}

impl ThinDielectric {
    /// The slab's reflectance R' at |cos θ|.
    fn reflectance(&self, cos_theta: f32) -> f32 {
        let r = fresnel_dielectric(cos_theta.abs(), self.eta).0;
        if r < 1.0 {
            let t = 1.0 - r;
            r + t * t * r / (1.0 - r * r)
        } else {
            r
        }
    }
}

impl BsdfPlugin for ThinDielectric {
    const PLUGINS: &'static [&'static str] = &["thindielectric"];

    /// `int_ior` (BK7, 1.5046), `ext_ior` (air, 1.000277): numbers or Mitsuba IOR names.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let int_ior = p.dielectric_ior("int_ior", 1.5046)?;
        let ext_ior = p.dielectric_ior("ext_ior", 1.000277)?;
        if int_ior.is_dispersive() || ext_ior.is_dispersive() {
            return Err(p.error(
                "thindielectric: a dispersive (wavelength-dependent) index is not supported; give a number or a Mitsuba IOR name, as Mitsuba does",
            ));
        }
        let factors = SpecularFactors::read(p)?;
        let eta = (int_ior.at(550.0).re / ext_ior.at(550.0).re) as f32;
        if !(eta.is_finite() && eta > 0.0) {
            return Err(p.error("thindielectric: int_ior/ext_ior must be positive"));
        }
        Ok(ThinDielectric { eta, factors })
    }
}

impl BsdfModel for ThinDielectric {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::DELTA_REFLECTION | BsdfFlags::DELTA_TRANSMISSION | BsdfFlags::TWO_SIDED)
            .with(BsdfFlags::VERTEX_COLOR, self.factors.reads_mesh_attribute())
    }

    fn describe(&self) -> String {
        format!("thindielectric η={}{}", self.eta, self.factors.describe())
    }

    super::delta_lobes_only!();

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let r = self.reflectance(wi.z);
        let reflect = |w: f32, pdf| {
            BsdfSample::delta(reflect_local(wi), crate::render::texture::Spec::splat(w), pdf, BsdfFlags::DELTA_REFLECTION)
        };
        let transmit = |w: f32, pdf| {
            BsdfSample::delta(-wi, crate::render::texture::Spec::splat(w), pdf, BsdfFlags::DELTA_TRANSMISSION)
        };
        let s = match (lobes.reflection(), lobes.transmission()) {
            (true, true) if u1 <= r => reflect(1.0, r),
            (true, true) => transmit(1.0, 1.0 - r),
            (true, false) if r > 0.0 => reflect(r, 1.0),
            (false, true) if r < 1.0 => transmit(1.0 - r, 1.0),
            _ => return None,
        };
        Some(self.factors.scale_sample(ctx, s))
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("thindielectric has no polarised form in thinfilm")
    }
}
