//! Anisotropic GGX (Trowbridge–Reitz) microfacet distribution with visible-normal sampling
//! (Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4)) and the
//! separable Smith shadowing term G = G1(wi) G1(wo) that Mitsuba 3 uses.

use super::fresnel::{reflect, reflect_local};
use super::{BsdfFlags, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx};
use crate::render::polarization::Mueller;
use crate::render::texture::Spec;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ggx {
    pub alpha_u: f32,
    pub alpha_v: f32,
}

impl Ggx {
    pub fn new(alpha_u: f32, alpha_v: f32) -> Self {
        // Very small α makes D overflow in f32; clamp like Mitsuba's 1e-4 floor.
        Ggx {
            alpha_u: alpha_u.max(1e-4),
            alpha_v: alpha_v.max(1e-4),
        }
    }

    /// D(m) for a local microfacet normal m.
    #[inline]
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let x = m.x / self.alpha_u;
        let y = m.y / self.alpha_v;
        let t = x * x + y * y + m.z * m.z;
        let v = 1.0 / (PI * self.alpha_u * self.alpha_v * t * t);
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }

    /// Smith Λ-based G1 for direction v and microfacet m.
    #[inline]
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let xy2 = (self.alpha_u * v.x).powi(2) + (self.alpha_v * v.y).powi(2);
        if xy2 == 0.0 {
            return 1.0;
        }
        let tan2 = xy2 / (v.z * v.z);
        let r = 2.0 / (1.0 + (1.0 + tan2).sqrt());
        if r.is_finite() {
            r
        } else {
            0.0
        }
    }

    #[inline]
    pub fn g(&self, wi: Vec3, wo: Vec3, m: Vec3) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// Microfacet reflection without its Fresnel factor (Walter et al. 2007): the half vector
    /// m and D(m)·G(wi, wo)/(4 cosθi), or `None` when the pair cannot reflect.
    #[inline]
    pub fn reflection(&self, wi: Vec3, wo: Vec3) -> Option<(Vec3, f32)> {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return None;
        }
        let m = (wi + wo).normalize();
        let d = self.d(m);
        if d == 0.0 {
            return None;
        }
        Some((m, d * self.g(wi, wo, m) / (4.0 * wi.z)))
    }

    /// pdf of `wo` when m is drawn from the visible normals of `wi` and reflected
    /// (the 1/(4 wo·m) Jacobian of reflection).
    #[inline]
    pub fn reflection_pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let m = (wi + wo).normalize();
        let dot = wo.dot(m);
        if dot <= 0.0 {
            return 0.0;
        }
        self.pdf_visible(wi, m) / (4.0 * dot)
    }

    /// Density of visible normals seen from `wi` (wi.z > 0): G1(wi) max(0, wi·m) D(m) / wi.z.
    #[inline]
    pub fn pdf_visible(&self, wi: Vec3, m: Vec3) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        self.g1(wi, m) * wi.dot(m).max(0.0) * self.d(m) / wi.z
    }

    /// Samples a visible normal from `wi` (wi.z > 0).
    #[inline]
    pub fn sample_visible(&self, wi: Vec3, u: Vec2) -> Vec3 {
        // Section 3.2: transform the view direction to the hemisphere configuration.
        let vh = Vec3::new(self.alpha_u * wi.x, self.alpha_v * wi.y, wi.z).normalize();
        let lensq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if lensq > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        // Section 4.2: parameterisation of the projected area.
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let (sp, cp) = phi.sin_cos();
        let p1 = r * cp;
        let mut p2 = r * sp;
        let s = 0.5 * (1.0 + vh.z);
        p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
        // Section 4.3: reprojection onto the hemisphere.
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        // Section 3.4: transform the normal back to the ellipsoid configuration.
        Vec3::new(self.alpha_u * nh.x, self.alpha_v * nh.y, nh.z.max(1e-7)).normalize()
    }
}

/// The lobe of an opaque reflector (conductor, thin film, layer stack): a mirror when `ggx`
/// is None, else a GGX lobe; `fresnel(cos θ)` is the reflectance at the (micro)facet angle —
/// a spectrum, or per-wavelength Mueller matrices for polarised transport
/// ([`super::MuellerValue`]). f·|cos θo| at (wi, wo) with the microfacet normal; None for
/// the mirror (a delta lobe) and where the pair cannot reflect.
#[inline]
pub fn reflection_eval<V>(
    ggx: Option<Ggx>,
    wi: Vec3,
    wo: Vec3,
    fresnel: impl FnOnce(f32) -> V,
    scale: impl FnOnce(V, f32) -> V,
) -> Option<(Vec3, V)> {
    let (m, weight) = ggx?.reflection(wi, wo)?;
    Some((m, scale(fresnel(wi.dot(m)), weight)))
}

/// Solid-angle pdf of [`reflection_sample`] (zero for the mirror).
#[inline]
pub fn reflection_lobe_pdf(ggx: Option<Ggx>, wi: Vec3, wo: Vec3) -> f32 {
    ggx.map_or(0.0, |ggx| ggx.reflection_pdf(wi, wo))
}

/// A sampled direction of an opaque reflector's lobe.
#[derive(Debug, Clone, Copy)]
pub struct ReflectionSample<V> {
    pub wo: Vec3,
    /// The (micro)facet normal it reflects about.
    pub normal: Vec3,
    /// eval / pdf: F·G1(wo) (separable Smith G), or F for the mirror.
    pub weight: V,
    /// Solid-angle pdf, 1 for the mirror.
    pub pdf: f32,
}

impl<V> ReflectionSample<V> {
    /// As a [`BsdfSample`] of the mirror (no `ggx`) or the glossy lobe, of unpolarised
    /// weight `weight`.
    #[inline]
    pub fn bsdf_sample(&self, weight: Spec, ggx: Option<Ggx>) -> BsdfSample {
        match ggx {
            None => BsdfSample::delta(self.wo, weight, 1.0, BsdfFlags::DELTA_REFLECTION),
            Some(_) => BsdfSample::smooth(self.wo, weight, self.pdf, BsdfFlags::GLOSSY_REFLECTION),
        }
    }
}

impl ReflectionSample<Spec> {
    /// As a [`BsdfSample`].
    #[inline]
    pub fn into_sample(self, ggx: Option<Ggx>) -> BsdfSample {
        self.bsdf_sample(self.weight, ggx)
    }
}

/// [`reflection_eval`] with a Mueller Fresnel term (per wavelength), in the facet's natural
/// bases ([`MuellerValue::specular`]).
#[inline]
pub fn reflection_eval_mueller(
    ggx: Option<Ggx>,
    wi: Vec3,
    wo: Vec3,
    fresnel: impl FnOnce(f32) -> [Mueller; 4],
) -> MuellerValue {
    match reflection_eval(ggx, wi, wo, fresnel, scale4) {
        Some((m, v)) => MuellerValue::specular(v, m, wi, wo),
        None => MuellerValue::ZERO,
    }
}

/// [`reflection_sample`] with a Mueller Fresnel term: the same direction, pdf and random
/// numbers as the unpolarised sample; the sample's weight is the Mueller value's response
/// to unpolarised light.
#[inline]
pub fn reflection_sample_mueller(
    ggx: Option<Ggx>,
    wi: Vec3,
    u: Vec2,
    fresnel: impl FnOnce(f32) -> [Mueller; 4],
) -> Option<(BsdfSample, MuellerValue)> {
    let s = reflection_sample(ggx, wi, u, fresnel, scale4)?;
    let value = MuellerValue::specular(s.weight, s.normal, wi, s.wo);
    Some((s.bsdf_sample(value.unpolarized(), ggx), value))
}

/// Scales per-wavelength Mueller matrices.
#[inline]
fn scale4(m: [Mueller; 4], f: f32) -> [Mueller; 4] {
    m.map(|x| x.scale(f))
}

/// Samples the opaque reflector's lobe: the mirror direction, or a visible GGX normal
/// (weight F · G1(wo)); `scale(v, g)` multiplies a Fresnel value by a number. None below the
/// surface.
#[inline]
pub fn reflection_sample<V>(
    ggx: Option<Ggx>,
    wi: Vec3,
    u: Vec2,
    fresnel: impl FnOnce(f32) -> V,
    scale: impl FnOnce(V, f32) -> V,
) -> Option<ReflectionSample<V>> {
    if wi.z <= 0.0 {
        return None;
    }
    match ggx {
        None => Some(ReflectionSample {
            wo: reflect_local(wi),
            normal: Vec3::Z,
            weight: fresnel(wi.z),
            pdf: 1.0,
        }),
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
            let weight = scale(fresnel(wi.dot(m)), ggx.g1(wo, m));
            Some(ReflectionSample {
                wo,
                normal: m,
                weight,
                pdf,
            })
        }
    }
}

/// The lobe flag of an opaque reflector: mirror or glossy.
#[inline]
pub fn reflection_lobe(ggx: Option<Ggx>) -> BsdfFlags {
    match ggx {
        None => BsdfFlags::DELTA_REFLECTION,
        Some(_) => BsdfFlags::GLOSSY_REFLECTION,
    }
}

/// An opaque reflector: one lobe, a mirror or a GGX lobe, weighted by a Fresnel term
/// (conductor, thin film, multilayer stack). Such a model implements this trait and writes
/// [`opaque_reflector_methods!`] in its `BsdfModel` impl; its polarised form is the impl
/// below.
pub trait OpaqueReflector {
    /// The roughness (None: a mirror).
    fn ggx(&self) -> Option<Ggx>;
    /// Reflectance at the path's wavelengths for cos θ at the (micro)facet.
    fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32) -> Spec;
    /// The same as Mueller matrices (Mitsuba's conventions).
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_theta: f32) -> [Mueller; 4];
}

impl<T: OpaqueReflector> PolarizedBsdf for T {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        reflection_eval_mueller(self.ggx(), wi, wo, |c| self.reflectance_mueller(ctx, c))
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        if !lobes.reflection() {
            return None;
        }
        reflection_sample_mueller(self.ggx(), wi, u2, |c| self.reflectance_mueller(ctx, c))
    }
}

/// `BsdfModel::eval` of an [`OpaqueReflector`].
#[inline]
pub fn opaque_eval(r: &impl OpaqueReflector, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
    let fresnel = |c| r.reflectance(ctx, c);
    reflection_eval(r.ggx(), wi, wo, fresnel, |f, w| f * w).map_or(Spec::ZERO, |(_, v)| v)
}

/// `BsdfModel::sample` of an [`OpaqueReflector`] (`u2` picks the direction).
#[inline]
pub fn opaque_sample(
    r: &impl OpaqueReflector,
    ctx: &ShadingCtx,
    wi: Vec3,
    u2: Vec2,
    lobes: Lobes,
) -> Option<BsdfSample> {
    if !lobes.reflection() {
        return None;
    }
    let s = reflection_sample(r.ggx(), wi, u2, |c| r.reflectance(ctx, c), |f, g| f * g)?;
    Some(s.into_sample(r.ggx()))
}

/// The `eval`, `pdf`, `sample` and `polarized` methods of an [`OpaqueReflector`]'s
/// `BsdfModel` impl.
macro_rules! opaque_reflector_methods {
    () => {
        fn eval(
            &self,
            ctx: &$crate::render::bsdf::ShadingCtx,
            wi: ::glam::Vec3,
            wo: ::glam::Vec3,
        ) -> $crate::render::texture::Spec {
            $crate::render::bsdf::microfacet::opaque_eval(self, ctx, wi, wo)
        }

        fn pdf(
            &self,
            _ctx: &$crate::render::bsdf::ShadingCtx,
            wi: ::glam::Vec3,
            wo: ::glam::Vec3,
        ) -> f32 {
            use $crate::render::bsdf::microfacet::OpaqueReflector;
            $crate::render::bsdf::microfacet::reflection_lobe_pdf(self.ggx(), wi, wo)
        }

        fn sample(
            &self,
            ctx: &$crate::render::bsdf::ShadingCtx,
            wi: ::glam::Vec3,
            _u1: f32,
            u2: ::glam::Vec2,
            lobes: $crate::render::bsdf::Lobes,
        ) -> Option<$crate::render::bsdf::BsdfSample> {
            $crate::render::bsdf::microfacet::opaque_sample(self, ctx, wi, u2, lobes)
        }

        fn polarized(&self) -> Result<&dyn $crate::render::bsdf::PolarizedBsdf, &'static str> {
            Ok(self)
        }
    };
}
pub(crate) use opaque_reflector_methods;

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ D(m) cos θm dω = 1 (normalisation of any microfacet distribution).
    #[test]
    fn d_is_normalised() {
        let g = Ggx::new(0.3, 0.15);
        let n = 400;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let ct = (i as f64 + 0.5) / n as f64;
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n as f64;
                let st = (1.0 - ct * ct).sqrt();
                let m = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                sum +=
                    g.d(m) as f64 * ct * (1.0 / n as f64) * (2.0 * std::f64::consts::PI / n as f64);
            }
        }
        assert!((sum - 1.0).abs() < 0.01, "{sum}");
    }
}
