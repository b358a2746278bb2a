//! Multilayer coating on an opaque substrate (scene type `thinfilm` with a `layers` string,
//! e.g. an anti-reflection coating or a dielectric mirror). The Fresnel term is the
//! unpolarised reflectance R = (R_s + R_p)/2 of the layer stack from the transfer-matrix
//! method of [`crate::optics::Stack`] (Born & Wolf §1.6; validated against `tmm.coh_tmm` in
//! `tests/optics_tmm.rs`), evaluated in f64 at each of the path's four wavelengths with each
//! layer's index at that wavelength (named dispersive materials). Ambient n = 1, like
//! `thinfilm`. Smooth: a mirror lobe weighted by R; rough (α > 0): a GGX lobe with R at the
//! microfacet angle, exactly as [`super::ThinFilmBsdf`]. What the stack transmits into the
//! substrate is absorbed. One-sided.

use super::fresnel::{reflect, reflect_local};
use super::microfacet::Ggx;
use super::{BsdfSample, Counters, ShadingCtx};
use crate::optics::{Ior, Layer, Stack};
use crate::render::texture::Spec;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct StackBsdf {
    /// (index, thickness nm), top (ambient side) first.
    pub layers: Vec<(Ior, f64)>,
    pub substrate_ior: Ior,
    /// None = smooth.
    pub ggx: Option<Ggx>,
}

impl StackBsdf {
    /// The stack at one wavelength (all layers coherent).
    pub fn stack_at(&self, lambda_nm: f64) -> Stack {
        Stack {
            ambient_ior: 1.0,
            layers: self
                .layers
                .iter()
                .map(|(n, d)| Layer::coherent(n.at(lambda_nm), *d))
                .collect(),
            substrate_ior: self.substrate_ior.at(lambda_nm),
        }
    }

    /// Unpolarised TMM reflectance at the four path wavelengths for `cos θ` in the ambient.
    #[inline]
    pub fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32, counters: &mut Counters) -> Spec {
        counters.film_evals += 1;
        let cos = (cos_theta as f64).clamp(0.0, 1.0);
        let r = ctx.wl.lambda.map(|l| {
            let v = self.stack_at(l as f64).response(l as f64, cos).r() as f32;
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        Spec::from_array(r)
    }

    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3, counters: &mut Counters) -> Spec {
        match self.ggx.and_then(|ggx| ggx.reflection(wi, wo)) {
            Some((m, weight)) => self.reflectance(ctx, wi.dot(m), counters) * weight,
            None => Spec::ZERO,
        }
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        self.ggx.map_or(0.0, |ggx| ggx.reflection_pdf(wi, wo))
    }

    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u: Vec2,
        counters: &mut Counters,
    ) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        match self.ggx {
            None => Some(BsdfSample::delta(
                reflect_local(wi),
                self.reflectance(ctx, wi.z, counters),
            )),
            Some(ggx) => {
                let m = ggx.sample_visible(wi, u);
                let wo = reflect(wi, m);
                if wo.z <= 0.0 {
                    return None;
                }
                let pdf = ggx.pdf_visible(wi, m) / (4.0 * wo.dot(m));
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                let weight = self.reflectance(ctx, wi.dot(m), counters) * ggx.g1(wo, m);
                Some(BsdfSample::smooth(wo, weight, pdf))
            }
        }
    }
}
