//! Mitsuba's `plastic` and `roughplastic`: a diffuse base under a dielectric coating.
//!
//! Smooth: a Fresnel mirror lobe plus the diffuse base seen through the interface, with
//! internal reflections summed as a geometric series, ρ / (1 − F_dr ρ) (`nonlinear`) or
//! ρ / (1 − F_dr), times (1 − F_i)(1 − F_o) / η² (Mitsuba 3 `plastic.cpp`).
//! Rough: the mirror lobe becomes a GGX lobe; the coating's transmittance into and out of the
//! base uses the smooth Fresnel term instead of Mitsuba's precomputed rough transmittance
//! table (a small difference at grazing angles for large α).
//! Polarised (as Mitsuba's polarised `plastic`): the diffuse base depolarises, the specular
//! lobe is the dielectric reflection Mueller matrix at the (micro)facet.

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance, reflect, reflect_local};
use super::microfacet::Ggx;
use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx,
};
use crate::render::geometry::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::render::polarization::specular_reflection;
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::TextureDesc;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Debug, Clone)]
pub struct Plastic {
    pub diffuse_reflectance: Texture,
    /// n_int / n_ext.
    pub eta: f32,
    pub nonlinear: bool,
    /// None = smooth coating.
    pub ggx: Option<Ggx>,
    /// Mitsuba's specular sampling weight s/(s + d_mean) with specular reflectance s = 1.
    pub specular_sampling_weight: f32,
    /// Internal diffuse Fresnel reflectance F_dr(1/η).
    pub fdr_int: f32,
}

impl Plastic {
    /// A diffuse base under a coating of relative index `int_ior`/`ext_ior`, GGX roughness
    /// `alpha` (0 = smooth).
    pub fn new(
        diffuse_reflectance: &TextureDesc,
        int_ior: f32,
        ext_ior: f32,
        nonlinear: bool,
        alpha: f32,
    ) -> anyhow::Result<Self> {
        super::conductor::check_alpha(alpha, "plastic alpha")?;
        let eta = int_ior / ext_ior;
        if !(eta.is_finite() && eta > 0.0) {
            anyhow::bail!(
                "plastic: int_ior/ext_ior must be positive and finite, got {int_ior}/{ext_ior}"
            );
        }
        let diffuse_reflectance = Texture::new(diffuse_reflectance);
        let d_mean = match &diffuse_reflectance {
            Texture::Value(s) => s.mean_hint(),
            _ => 0.5,
        };
        Ok(Plastic {
            diffuse_reflectance,
            eta,
            nonlinear,
            ggx: (alpha > 0.0).then(|| Ggx::new(alpha, alpha)),
            specular_sampling_weight: 1.0 / (1.0 + d_mean.max(0.0)),
            fdr_int: fresnel_diffuse_reflectance(1.0 / eta),
        })
    }

    fn prob_specular(&self, f_i: f32) -> f32 {
        let ps = f_i * self.specular_sampling_weight;
        let pd = (1.0 - f_i) * (1.0 - self.specular_sampling_weight);
        if ps + pd > 0.0 {
            ps / (ps + pd)
        } else {
            1.0
        }
    }

    fn diffuse_value(&self, ctx: &ShadingCtx, f_i: f32, wo: Vec3) -> Spec {
        let rho = self.diffuse_reflectance.eval(ctx.uv, ctx.wl);
        let base = if self.nonlinear {
            rho / (Spec::ONE - rho * self.fdr_int)
        } else {
            rho / (1.0 - self.fdr_int)
        };
        let f_o = fresnel_dielectric(wo.z, self.eta).0;
        base * ((1.0 - f_i) * (1.0 - f_o) / (self.eta * self.eta) * FRAC_1_PI * wo.z)
    }

    fn specular_value(&self, wi: Vec3, wo: Vec3) -> f32 {
        let Some(ggx) = self.ggx else { return 0.0 };
        let m = (wi + wo).normalize();
        let f = fresnel_dielectric(wi.dot(m), self.eta).0;
        f * ggx.d(m) * ggx.g(wi, wo, m) / (4.0 * wi.z)
    }
}

impl BsdfPlugin for Plastic {
    const PLUGINS: &'static [&'static str] = &["plastic", "roughplastic"];

    /// `diffuse_reflectance` (default 0.5), `int_ior` (1.49) and `ext_ior` (1.000277):
    /// numbers or Mitsuba IOR names, `nonlinear` (false); `roughplastic`: isotropic
    /// microfacet roughness.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let alpha = if p.plugin() == "roughplastic" {
            p.microfacet()?
        } else {
            0.0
        };
        let diffuse = p.texture("diffuse_reflectance", 0.5)?;
        let int_ior = p.ior_number("int_ior", 1.49)? as f32;
        let ext_ior = p.ior_number("ext_ior", 1.000277)? as f32;
        let nonlinear = p.bool("nonlinear", false)?;
        p.unit_factors(&["specular_reflectance"])?;
        Plastic::new(&diffuse, int_ior, ext_ior, nonlinear, alpha).map_err(|e| p.error(e))
    }
}

impl BsdfModel for Plastic {
    fn flags(&self) -> BsdfFlags {
        let specular = match self.ggx {
            None => BsdfFlags::DELTA_REFLECTION,
            Some(_) => BsdfFlags::GLOSSY_REFLECTION,
        };
        specular | BsdfFlags::DIFFUSE_REFLECTION
    }

    fn describe(&self) -> String {
        match self.ggx {
            None => format!("plastic η={}", self.eta),
            Some(g) => format!("roughplastic η={} α={}", self.eta, g.alpha_u),
        }
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spec::ZERO;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        self.diffuse_value(ctx, f_i, wo) + Spec::splat(self.specular_value(wi, wo))
    }

    fn pdf(&self, _ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        let ps = self.prob_specular(f_i);
        let mut pdf = (1.0 - ps) * cosine_hemisphere_pdf(wo.z);
        if let Some(ggx) = self.ggx {
            let m = (wi + wo).normalize();
            let dot = wo.dot(m);
            if dot > 0.0 {
                pdf += ps * ggx.pdf_visible(wi, m) / (4.0 * dot);
            }
        }
        pdf
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        if wi.z <= 0.0 || !lobes.reflection() {
            return None;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        let ps = self.prob_specular(f_i);
        match self.ggx {
            None => {
                if u1 < ps {
                    Some(BsdfSample::delta(
                        reflect_local(wi),
                        Spec::splat(f_i / ps),
                        ps,
                        BsdfFlags::DELTA_REFLECTION,
                    ))
                } else {
                    let wo = square_to_cosine_hemisphere(u2);
                    let pdf = (1.0 - ps) * cosine_hemisphere_pdf(wo.z);
                    if pdf <= 0.0 {
                        return None;
                    }
                    Some(BsdfSample::smooth(
                        wo,
                        self.diffuse_value(ctx, f_i, wo) / pdf,
                        pdf,
                        BsdfFlags::DIFFUSE_REFLECTION,
                    ))
                }
            }
            Some(ggx) => {
                let (wo, lobe) = if u1 < ps {
                    let wo = reflect(wi, ggx.sample_visible(wi, u2));
                    (wo, BsdfFlags::GLOSSY_REFLECTION)
                } else {
                    (
                        square_to_cosine_hemisphere(u2),
                        BsdfFlags::DIFFUSE_REFLECTION,
                    )
                };
                if wo.z <= 0.0 {
                    return None;
                }
                let pdf = self.pdf(ctx, wi, wo);
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                Some(BsdfSample::smooth(
                    wo,
                    self.eval(ctx, wi, wo) / pdf,
                    pdf,
                    lobe,
                ))
            }
        }
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Ok(self)
    }
}

impl PolarizedBsdf for Plastic {
    /// The diffuse part depolarised, the microfacet part polarised (Fresnel at the
    /// microfacet).
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        let total = self.eval(ctx, wi, wo);
        match self.ggx {
            Some(ggx) if wi.z > 0.0 && wo.z > 0.0 => {
                let m = (wi + wo).normalize();
                let scale = ggx.d(m) * ggx.g(wi, wo, m) / (4.0 * wi.z);
                let f = specular_reflection(wi.dot(m), self.eta).scale(scale);
                let mut value = MuellerValue::specular([f; 4], m, wi, wo);
                value.depolarized = total - Spec::splat(f.0[0][0]);
                value
            }
            _ => MuellerValue::depolarizing(total),
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
        let s = self.sample(ctx, wi, u1, u2, lobes)?;
        let value = if s.is_delta() {
            let f = specular_reflection(wi.z, self.eta).scale(1.0 / s.pdf);
            MuellerValue::specular([f; 4], Vec3::Z, wi, s.wo)
        } else if self.ggx.is_some() {
            self.eval_mueller(ctx, wi, s.wo).scaled(1.0 / s.pdf)
        } else {
            MuellerValue::depolarizing(s.weight)
        };
        Some((s, value))
    }
}
