//! Mitsuba's `roughdielectric`: a rough interface between two dielectrics (Walter et al.
//! 2007, "Microfacet Models for Refraction through Rough Surfaces", EGSR), two-sided, as
//! Mitsuba 3's `roughdielectric.cpp`: microfacet reflection and refraction about a visible
//! normal sampled from the side wi is on, chosen with probability F and 1 − F, the generalised
//! half vector m ∝ wi + η wo for transmission (Walter et al. eq. 16), the half-vector Jacobians
//! (eqs. 14 and 17) and radiance compressed by 1/η² on entering the denser side. The index is
//! a constant, as Mitsuba's (a dispersive index is refused when the scene is read). The
//! roughness may be textured ([`Roughness`]); `specular_reflectance` /
//! `specular_transmittance` scale the two lobes' values, not their probabilities
//! ([`SpecularFactors`]).

use super::fresnel::{fresnel_dielectric, reflect};
use super::lobe_factor::SpecularFactors;
use super::microfacet::{Distribution, Microfacet};
use super::roughness::Roughness;
use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx,
};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct RoughDielectric {
    /// n_int / n_ext.
    pub eta: f32,
    pub roughness: Roughness,
    pub factors: SpecularFactors,
}

/// A direction pair's microfacet normal (z ≥ 0), whether it is a reflection, and for
/// transmission η of the side wo is on relative to wi's.
struct Pair {
    m: Vec3,
    reflect: bool,
    eta: f32,
}

impl RoughDielectric {
    /// Interface of relative index `eta` = n_int/n_ext > 0, ≠ 1.
    pub fn new(eta: f32, mf: Microfacet) -> anyhow::Result<Self> {
        Self::with_roughness(eta, Roughness::Constant(Some(mf)))
    }

    /// [`Self::new`] with a constant or textured roughness.
    pub fn with_roughness(eta: f32, roughness: Roughness) -> anyhow::Result<Self> {
        if !(eta.is_finite() && eta > 0.0 && eta != 1.0) {
            anyhow::bail!("roughdielectric: int_ior/ext_ior must be positive, finite and ≠ 1, got {eta}");
        }
        Ok(RoughDielectric {
            eta,
            roughness,
            factors: SpecularFactors::default(),
        })
    }

    /// The distribution at the shading point (always rough: α is floored at 1e-4).
    #[inline]
    fn mf(&self, ctx: &ShadingCtx) -> Microfacet {
        self.roughness
            .at(ctx)
            .unwrap_or_else(|| Microfacet::of(Distribution::Beckmann, 0.0, 0.0))
    }

    /// The half vector of (wi, wo) (Mitsuba: wi + η wo for transmission, flipped up).
    fn pair(&self, wi: Vec3, wo: Vec3) -> Option<Pair> {
        let reflect = wi.z * wo.z > 0.0;
        let eta = if reflect {
            1.0
        } else if wi.z > 0.0 {
            self.eta
        } else {
            1.0 / self.eta
        };
        let m = (wi + wo * eta).normalize();
        let m = if m.z < 0.0 { -m } else { m };
        (m.is_finite() && wi.z != 0.0 && wo.z != 0.0).then_some(Pair { m, reflect, eta })
    }

    /// The Jacobian |dm/dwo| (Walter et al. eqs. 14, 17).
    fn jacobian(wi: Vec3, wo: Vec3, p: &Pair) -> f32 {
        if p.reflect {
            1.0 / (4.0 * wo.dot(p.m).abs())
        } else {
            let denom = wi.dot(p.m) + p.eta * wo.dot(p.m);
            (p.eta * p.eta * wo.dot(p.m) / (denom * denom)).abs()
        }
    }

    /// Density of the visible normal m seen from wi's side.
    fn pdf_m(mf: &Microfacet, wi: Vec3, m: Vec3) -> f32 {
        let wi_up = if wi.z < 0.0 { -wi } else { wi };
        mf.pdf_visible(wi_up, m)
    }
}

impl BsdfPlugin for RoughDielectric {
    const PLUGINS: &'static [&'static str] = &["roughdielectric"];

    /// `int_ior` (BK7, 1.5046), `ext_ior` (air, 1.000277), `distribution` (beckmann), `alpha`
    /// or `alpha_u`/`alpha_v` (0.1), `sample_visible`.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let roughness = Roughness::read(p, false)?;
        let int_ior = p.dielectric_ior("int_ior", 1.5046)?;
        let ext_ior = p.dielectric_ior("ext_ior", 1.000277)?;
        if int_ior.is_dispersive() || ext_ior.is_dispersive() {
            return Err(p.error(
                "roughdielectric: a dispersive (wavelength-dependent) index is not supported; give a number or a Mitsuba IOR name, as Mitsuba does",
            ));
        }
        let factors = SpecularFactors::read(p)?;
        let eta = (int_ior.at(550.0).re / ext_ior.at(550.0).re) as f32;
        let mut d = RoughDielectric::with_roughness(eta, roughness).map_err(|e| p.error(e))?;
        d.factors = factors;
        Ok(d)
    }
}

impl BsdfModel for RoughDielectric {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::GLOSSY_REFLECTION | BsdfFlags::GLOSSY_TRANSMISSION | BsdfFlags::TWO_SIDED)
            .with(
                BsdfFlags::VERTEX_COLOR,
                self.factors.reads_mesh_attribute() || self.roughness.reads_mesh_attribute(),
            )
    }

    fn describe(&self) -> String {
        format!(
            "roughdielectric η={} {}{}",
            self.eta,
            self.roughness.describe(),
            self.factors.describe()
        )
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        let Some(p) = self.pair(wi, wo) else {
            return Spec::ZERO;
        };
        let mf = self.mf(ctx);
        let d = mf.d(p.m);
        let f = fresnel_dielectric(wi.dot(p.m), self.eta).0;
        let g = mf.g1(wi, p.m) * mf.g1(wo, p.m);
        let v = if p.reflect {
            f * d * g / (4.0 * wi.z.abs())
        } else {
            let denom = wi.dot(p.m) + p.eta * wo.dot(p.m);
            // Walter et al. eq. 21 times |cos θo|, with the 1/η² radiance compression.
            ((1.0 - f) * d * g * wi.dot(p.m) * wo.dot(p.m) / (wi.z * denom * denom)).abs()
        };
        if v.is_finite() {
            Spec::splat(v) * self.factors.for_pair(ctx, wi, wo)
        } else {
            Spec::ZERO
        }
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        let Some(p) = self.pair(wi, wo) else {
            return 0.0;
        };
        // Mitsuba rejects pairs whose m is back-facing for either direction.
        if wi.dot(p.m) * wi.z <= 0.0 || wo.dot(p.m) * wo.z <= 0.0 {
            return 0.0;
        }
        let f = fresnel_dielectric(wi.dot(p.m), self.eta).0;
        let lobe = if p.reflect { f } else { 1.0 - f };
        let v = Self::pdf_m(&self.mf(ctx), wi, p.m) * lobe * Self::jacobian(wi, wo, &p);
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        if wi.z == 0.0 {
            return None;
        }
        let wi_up = if wi.z < 0.0 { -wi } else { wi };
        let m = self.mf(ctx).sample_visible(wi_up, u2);
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), self.eta);
        let reflect_lobe = match (lobes.reflection(), lobes.transmission()) {
            (true, true) => u1 <= f,
            (true, false) => true,
            (false, true) => false,
            (false, false) => return None,
        };
        let wo = if reflect_lobe {
            reflect(wi, m)
        } else {
            // Refraction about m (Mitsuba's `refract(wi, m, cos_theta_t, eta_ti)`).
            m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti
        };
        // The sampled direction must land on the lobe's side.
        if (wi.z * wo.z > 0.0) != reflect_lobe || !wo.is_finite() {
            return None;
        }
        let pdf = self.pdf(ctx, wi, wo);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        let lobe = if reflect_lobe {
            BsdfFlags::GLOSSY_REFLECTION
        } else {
            BsdfFlags::GLOSSY_TRANSMISSION
        };
        // With one lobe masked out the other carries its full value: pdf without the
        // F / (1 − F) choice.
        let choice = match (lobes.reflection(), lobes.transmission()) {
            (true, true) => 1.0,
            _ if reflect_lobe => f,
            _ => 1.0 - f,
        };
        let pdf = if choice > 0.0 { pdf / choice } else { return None };
        let mut s = BsdfSample::smooth(wo, self.eval(ctx, wi, wo) / pdf, pdf, lobe);
        if !reflect_lobe {
            s.eta = eta_it;
        }
        Some(s)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("roughdielectric has no polarised form in thinfilm (Mitsuba's polarised rough dielectric is not reproduced)")
    }

    /// Mitsuba's frame (s along dp/du) when the roughness is anisotropic.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        if self.roughness.is_anisotropic() {
            super::normal_map::dpdu_frame(si)
        } else {
            si.shading
        }
    }
}
