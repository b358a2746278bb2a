//! Mitsuba's `plastic` and `roughplastic`: a diffuse base under a dielectric coating.
//!
//! Smooth: a Fresnel mirror lobe plus the diffuse base seen through the interface, with
//! internal reflections summed as a geometric series, ρ / (1 − F_dr ρ) (`nonlinear`) or
//! ρ / (1 − F_dr), times (1 − F_i)(1 − F_o) / η² (Mitsuba 3 `plastic.cpp`).
//! Rough: the mirror lobe becomes a GGX lobe; the coating's transmittance into and out of the
//! base uses the smooth Fresnel term instead of Mitsuba's precomputed rough transmittance
//! table (a small difference at grazing angles for large α).

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance, reflect, reflect_local};
use super::microfacet::Ggx;
use super::{BsdfSample, ShadingCtx};
use crate::render::geometry::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::render::texture::{Spec, Texture};
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
    pub fn new(diffuse_reflectance: Texture, eta: f32, nonlinear: bool, alpha: f32) -> Self {
        let d_mean = match &diffuse_reflectance {
            Texture::Value(s) => s.mean_hint(),
            _ => 0.5,
        };
        Plastic {
            diffuse_reflectance,
            eta,
            nonlinear,
            ggx: (alpha > 0.0).then(|| Ggx::new(alpha, alpha)),
            specular_sampling_weight: 1.0 / (1.0 + d_mean.max(0.0)),
            fdr_int: fresnel_diffuse_reflectance(1.0 / eta),
        }
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

    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spec::ZERO;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        self.diffuse_value(ctx, f_i, wo) + Spec::splat(self.specular_value(wi, wo))
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
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

    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3, u1: f32, u2: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        let ps = self.prob_specular(f_i);
        match self.ggx {
            None => {
                if u1 < ps {
                    let mut s = BsdfSample::delta(reflect_local(wi), Spec::splat(f_i / ps));
                    s.pdf = ps;
                    Some(s)
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
                    ))
                }
            }
            Some(ggx) => {
                let wo = if u1 < ps {
                    reflect(wi, ggx.sample_visible(wi, u2))
                } else {
                    square_to_cosine_hemisphere(u2)
                };
                if wo.z <= 0.0 {
                    return None;
                }
                let pdf = self.pdf(wi, wo);
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                Some(BsdfSample::smooth(wo, self.eval(ctx, wi, wo) / pdf, pdf))
            }
        }
    }
}
