//! Multilayer coating on an opaque substrate (scene type `thinfilm` with a `layers` string,
//! e.g. an anti-reflection coating or a dielectric mirror). The Fresnel term is the
//! unpolarised reflectance R = (R_s + R_p)/2 of the layer stack from the transfer-matrix
//! method of [`crate::optics::Stack`] (Born & Wolf §1.6; validated against `tmm.coh_tmm` in
//! `tests/optics_tmm.rs`), evaluated in f64 at each of the path's four wavelengths with each
//! layer's index at that wavelength (named dispersive materials). Ambient n = 1, like
//! `thinfilm`. Smooth: a mirror lobe weighted by R; rough (α > 0): a GGX lobe with R at the
//! microfacet angle, exactly as [`super::ThinFilmBsdf`]. What the stack transmits into the
//! substrate is absorbed. One-sided.
//!
//! [`CoatedDielectric`] (scene type `coateddielectric`) puts the same stack on a transparent
//! dielectric: the stack's R and T (from whichever side the light arrives) replace the Fresnel
//! terms of a smooth glass interface.

use super::fresnel::reflect_local;
use super::microfacet::{reflection_eval, reflection_lobe_pdf, reflection_sample, Ggx};
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
        reflection_eval(self.ggx, wi, wo, |c| self.reflectance(ctx, c, counters))
    }

    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        reflection_lobe_pdf(self.ggx, wi, wo)
    }

    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u: Vec2,
        counters: &mut Counters,
    ) -> Option<BsdfSample> {
        reflection_sample(self.ggx, wi, u, |c| self.reflectance(ctx, c, counters))
    }
}

/// Smooth dielectric interface under a multilayer coating (scene type
/// `coateddielectric` with a `coating` string), e.g. an anti-reflection coated lens. The coating is on the outside
/// (`ext_ior` side). R and T are the transfer-matrix powers of the stack seen from the side
/// the light arrives on — ext | layers | int from outside, int | reversed layers | ext from
/// inside (total internal reflection gives T = 0 through the evanescent exit medium) — at
/// each path wavelength. The layers are parallel, so the refracted direction is Snell's
/// between the two bulk media, as for the uncoated [`super::Dielectric`].
///
/// Sampling picks reflection with probability P_R = R̄/(R̄ + T̄) over the live wavelengths;
/// weights R/P_R and T/(1 − P_R)·η_ti² (radiance compression, Veach 1997 §5.2, as in
/// Mitsuba's `dielectric`). With a dispersive bulk index the refracted direction is the hero
/// wavelength's and the secondary wavelengths are terminated (only on refraction: the
/// reflected direction does not depend on wavelength).
#[derive(Debug, Clone)]
pub struct CoatedDielectric {
    /// (index, thickness nm), outside first.
    pub layers: Vec<(Ior, f64)>,
    pub int_ior: Ior,
    pub ext_ior: Ior,
    /// Either bulk index depends on wavelength.
    pub dispersive: bool,
}

impl CoatedDielectric {
    /// The stack seen from outside (`inside` = false) or from inside the object.
    pub fn stack_at(&self, lambda_nm: f64, inside: bool) -> Stack {
        let ext = self.ext_ior.at(lambda_nm);
        let int = self.int_ior.at(lambda_nm);
        let layer = |(n, d): &(Ior, f64)| Layer::coherent(n.at(lambda_nm), *d);
        if inside {
            Stack {
                ambient_ior: int.re,
                layers: self.layers.iter().rev().map(layer).collect(),
                substrate_ior: ext,
            }
        } else {
            Stack {
                ambient_ior: ext.re,
                layers: self.layers.iter().map(layer).collect(),
                substrate_ior: int,
            }
        }
    }

    /// Unpolarised (R, T) at the four path wavelengths for `cos θ` (signed: < 0 = inside).
    pub fn reflect_transmit(
        &self,
        ctx: &ShadingCtx,
        cos_theta: f32,
        counters: &mut Counters,
    ) -> (Spec, Spec) {
        counters.film_evals += 1;
        let inside = cos_theta < 0.0;
        let cos = (cos_theta.abs() as f64).min(1.0);
        let clean = |v: f64| {
            if v.is_finite() {
                (v as f32).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let mut r = [0.0f32; 4];
        let mut t = [0.0f32; 4];
        for k in 0..4 {
            let l = ctx.wl.lambda[k] as f64;
            let resp = self.stack_at(l, inside).response(l, cos);
            r[k] = clean(resp.r());
            t[k] = clean(resp.t());
        }
        (Spec::from_array(r), Spec::from_array(t))
    }

    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        counters: &mut Counters,
    ) -> Option<BsdfSample> {
        if wi.z == 0.0 || !wi.is_finite() {
            return None;
        }
        let (r, t) = self.reflect_transmit(ctx, wi.z, counters);
        let p_r = super::BubbleBsdf::reflect_probability(ctx, r, t, 0.0);
        if u1 < p_r {
            let mut s = BsdfSample::delta(reflect_local(wi), r / p_r);
            s.pdf = p_r;
            return Some(s);
        }
        let p_t = 1.0 - p_r;
        let mut s = self.refraction(ctx, wi, t / p_t)?;
        s.pdf = p_t;
        (s.pdf > 0.0).then_some(s)
    }

    /// The refracted lobe with `weight`·η_ti² (Snell's direction at the hero wavelength's
    /// bulk index); None under total internal reflection at the hero wavelength, which the
    /// stack can miss when only a secondary wavelength's index lets light through.
    fn refraction(&self, ctx: &ShadingCtx, wi: Vec3, weight: Spec) -> Option<BsdfSample> {
        let lambda = ctx.wl.lambda[0] as f64;
        let eta = (self.int_ior.at(lambda).re / self.ext_ior.at(lambda).re) as f32;
        let (_, cos_t, eta_it, eta_ti) = super::fresnel::fresnel_dielectric(wi.z, eta);
        if cos_t == 0.0 {
            return None;
        }
        let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
        let mut s = BsdfSample::delta(wo, weight * (eta_ti * eta_ti));
        s.eta = eta_it;
        s.terminate_secondary = self.dispersive;
        s.wo.is_finite().then_some(s)
    }

    /// [reflection, transmission] with weights R and T·η_ti² (Fresnel splitting, see
    /// [`super::Bsdf::split`]): one transfer-matrix evaluation for both lobes.
    pub fn split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        counters: &mut Counters,
    ) -> [Option<BsdfSample>; 2] {
        if wi.z == 0.0 || !wi.is_finite() {
            return [None, None];
        }
        let (r, t) = self.reflect_transmit(ctx, wi.z, counters);
        [
            (r.max_element() > 0.0).then(|| BsdfSample::delta(reflect_local(wi), r)),
            (t.max_element() > 0.0)
                .then(|| self.refraction(ctx, wi, t))
                .flatten(),
        ]
    }
}
