//! Anisotropic microfacet distributions as Mitsuba 3 has them (`microfacet.h`): GGX
//! (Trowbridge–Reitz) and Beckmann, with the separable Smith shadowing term
//! G = G1(wi) G1(wo) and sampling of the visible normals — GGX by Heitz 2018 ("Sampling the
//! GGX Distribution of Visible Normals", JCGT 7(4)), Beckmann by inverting the visible-slope
//! CDF of Heitz & d'Eon 2014 ("Importance Sampling Microfacet-Based BSDFs using the
//! Distribution of Visible Normals", EGSR), as Mitsuba's `sample_visible_11` does.

use super::fresnel::{reflect, reflect_local};
use super::{BsdfFlags, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx};
use crate::render::polarization::Mueller;
use crate::render::texture::Spec;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The microfacet normal distribution (Mitsuba's `distribution` parameter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Distribution {
    /// Trowbridge–Reitz: D ∝ 1/(1 + tan²θ/α²)², long tails.
    Ggx,
    /// Beckmann: a Gaussian of the slopes, D ∝ exp(−tan²θ/α²); Mitsuba's default.
    Beckmann,
}

impl Distribution {
    /// Mitsuba's names.
    pub fn name(self) -> &'static str {
        match self {
            Distribution::Ggx => "ggx",
            Distribution::Beckmann => "beckmann",
        }
    }
}

/// An anisotropic microfacet distribution: α_u along the shading frame's s axis, α_v along t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Microfacet {
    pub alpha_u: f32,
    pub alpha_v: f32,
    pub kind: Distribution,
}

/// The GGX distribution (the only one of thinfilm's own film models).
pub type Ggx = Microfacet;

impl Microfacet {
    /// A GGX distribution.
    pub fn new(alpha_u: f32, alpha_v: f32) -> Self {
        Self::of(Distribution::Ggx, alpha_u, alpha_v)
    }

    /// A distribution of the given kind.
    pub fn of(kind: Distribution, alpha_u: f32, alpha_v: f32) -> Self {
        // Very small α makes D overflow in f32; clamp like Mitsuba's 1e-4 floor.
        Microfacet {
            alpha_u: alpha_u.max(1e-4),
            alpha_v: alpha_v.max(1e-4),
            kind,
        }
    }

    /// Whether α_u ≠ α_v (the model then needs a tangent frame).
    pub fn is_anisotropic(&self) -> bool {
        self.alpha_u != self.alpha_v
    }

    /// "beckmann α=0.1" or "ggx α=(0.1, 0.3)", for logs.
    pub fn describe(&self) -> String {
        if self.is_anisotropic() {
            format!(
                "{} α=({}, {})",
                self.kind.name(),
                self.alpha_u,
                self.alpha_v
            )
        } else {
            format!("{} α={}", self.kind.name(), self.alpha_u)
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
        let z2 = m.z * m.z;
        let v = match self.kind {
            Distribution::Ggx => {
                let t = x * x + y * y + z2;
                1.0 / (PI * self.alpha_u * self.alpha_v * t * t)
            }
            Distribution::Beckmann => {
                (-(x * x + y * y) / z2).exp() / (PI * self.alpha_u * self.alpha_v * z2 * z2)
            }
        };
        // Mitsuba drops values with D cos θ ≤ 1e-20 (numerical issues downstream).
        if v.is_finite() && v * m.z > 1e-20 {
            v
        } else {
            0.0
        }
    }

    /// Smith G1 for direction v and microfacet m: GGX's closed form; Beckmann's
    /// 1/(1 + Λ) with the exact Λ(a) = (erf a − 1)/2 + e^(−a²)/(2a√π) (Mitsuba uses a rational
    /// fit of it, within 0.35 %; the exact form keeps the sampled density equal to the pdf).
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
        let r = match self.kind {
            Distribution::Ggx => 2.0 / (1.0 + (1.0 + tan2).sqrt()),
            Distribution::Beckmann => {
                let a = 1.0 / (tan2 as f64).sqrt();
                if a > 8.0 {
                    1.0
                } else {
                    let lambda = 0.5 * (libm::erf(a) - 1.0)
                        + (-a * a).exp() / (2.0 * a * std::f64::consts::PI.sqrt());
                    (1.0 / (1.0 + lambda)) as f32
                }
            }
        };
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
        match self.kind {
            Distribution::Ggx => self.sample_visible_ggx(wi, u),
            Distribution::Beckmann => self.sample_visible_beckmann(wi, u),
        }
    }

    fn sample_visible_ggx(&self, wi: Vec3, u: Vec2) -> Vec3 {
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

    /// Heitz & d'Eon 2014, Section 4 (Mitsuba's `sample` with `sample_visible`): stretch wi
    /// to the α = 1 configuration, sample the visible slopes there, rotate to wi's azimuth
    /// and unstretch.
    fn sample_visible_beckmann(&self, wi: Vec3, u: Vec2) -> Vec3 {
        let wp = Vec3::new(self.alpha_u * wi.x, self.alpha_v * wi.y, wi.z).normalize();
        let sin_t = (wp.x * wp.x + wp.y * wp.y).sqrt();
        let (sin_phi, cos_phi) = if sin_t > 1e-7 {
            (wp.y / sin_t, wp.x / sin_t)
        } else {
            (0.0, 1.0)
        };
        let (sx, sy) = beckmann_visible_slopes_11(wp.z as f64, u);
        let x = (cos_phi * sx - sin_phi * sy) * self.alpha_u;
        let y = (sin_phi * sx + cos_phi * sy) * self.alpha_v;
        Vec3::new(-x, -y, 1.0).normalize()
    }
}

impl Microfacet {
    /// Directional albedo of microfacet reflection off (`transmit` false) or refraction
    /// through (true) a dielectric interface of relative index `eta` seen at cos θ = `cos_i`:
    /// ∫ F G1(wo) (or (1 − F) G1(wo)) over the visible normals, by an n×n Gauss–Legendre rule
    /// on the sampling square — Mitsuba's `eval_reflectance` / `eval_transmittance` (n = 32
    /// for η > 1, 128 for η < 1), which its `roughplastic` tabulates.
    pub fn dielectric_albedo(&self, cos_i: f32, eta: f32, transmit: bool) -> f32 {
        let n = if eta > 1.0 { 32 } else { 128 };
        let (nodes, weights) = gauss_legendre(n);
        let wi = Vec3::new((1.0 - cos_i * cos_i).max(0.0).sqrt(), 0.0, cos_i);
        let mut sum = 0.0f64;
        for (x, wx) in nodes.iter().zip(&weights) {
            for (y, wy) in nodes.iter().zip(&weights) {
                let u = Vec2::new(0.5 * *x as f32 + 0.5, 0.5 * *y as f32 + 0.5);
                let m = self.sample_visible(wi, u);
                let c = wi.dot(m);
                let (f, cos_t, _, eta_ti) = super::fresnel::fresnel_dielectric(c, eta);
                let (wo, value) = if transmit {
                    (m * (c * eta_ti + cos_t) - wi * eta_ti, 1.0 - f)
                } else {
                    (reflect(wi, m), f)
                };
                if (wo.z > 0.0) == transmit || wi.z <= 0.0 {
                    continue;
                }
                sum += (value * self.g1(wo, m)) as f64 * wx * wy * 0.25;
            }
        }
        sum as f32
    }
}

/// Nodes and weights of the n-point Gauss–Legendre rule on [−1, 1] (Newton iteration on
/// the Legendre polynomial from Tricomi's initial guesses).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = Vec::with_capacity(n);
    let mut weights = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        nodes.push(x);
        weights.push(2.0 / ((1.0 - x * x) * dp * dp));
    }
    (nodes, weights)
}

/// Visible slopes (x̃, ỹ) of the unit-α Beckmann surface seen at cos θ_i along +x: x̃ from
/// its marginal CDF C(x̃) ∝ 1 + erf x̃ + tan θ_i e^(−x̃²)/√π on (−∞, cot θ_i], inverted by
/// safeguarded Newton steps; ỹ is an independent Gaussian slope, erf⁻¹(2u − 1).
fn beckmann_visible_slopes_11(cos_i: f64, u: Vec2) -> (f32, f32) {
    let sqrt_pi = std::f64::consts::PI.sqrt();
    let u1 = (u.x as f64).clamp(1e-9, 1.0 - 1e-9);
    let y = erfinv(2.0 * (u.y as f64).clamp(1e-9, 1.0 - 1e-9) - 1.0);
    let sin_i = (1.0 - cos_i * cos_i).max(0.0).sqrt();
    if sin_i < 1e-6 {
        return (erfinv(2.0 * u1 - 1.0) as f32, y as f32);
    }
    let tan_i = sin_i / cos_i.max(1e-12);
    let cot_i = cos_i.max(1e-12) / sin_i;
    let cdf = |x: f64| 1.0 + libm::erf(x) + tan_i * (-x * x).exp() / sqrt_pi;
    let target = u1 * cdf(cot_i);
    let (mut lo, mut hi) = (-10.0f64, cot_i);
    // Start from the inverse of the normal-incidence CDF, clamped into the bracket.
    let mut x = erfinv(2.0 * u1 - 1.0).clamp(lo, hi);
    for _ in 0..100 {
        let value = cdf(x) - target;
        if value.abs() < 1e-12 * target.max(1e-300) || hi - lo < 1e-13 {
            break;
        }
        if value > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let derivative = 2.0 / sqrt_pi * (-x * x).exp() * (1.0 - x * tan_i);
        let next = x - value / derivative;
        x = if derivative > 0.0 && next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
    }
    (x as f32, y as f32)
}

/// erf⁻¹(y) for |y| < 1: Giles' approximation ("Approximating the erfinv function", GPU
/// Computing Gems 2011) polished by two Newton steps on erf.
fn erfinv(y: f64) -> f64 {
    const CENTRAL: [f64; 9] = [
        2.810_226_36e-08,
        3.432_739_39e-07,
        -3.523_387_7e-06,
        -4.391_506_54e-06,
        0.000_218_580_87,
        -0.001_253_725_03,
        -0.004_177_681_64,
        0.246_640_727,
        1.501_409_41,
    ];
    const TAIL: [f64; 9] = [
        -0.000_200_214_257,
        0.000_100_950_558,
        0.001_349_343_22,
        -0.003_673_428_44,
        0.005_739_507_73,
        -0.007_622_461_3,
        0.009_438_870_47,
        1.001_674_06,
        2.832_976_82,
    ];
    let w = -((1.0 - y) * (1.0 + y)).ln();
    let (w, coeffs) = if w < 5.0 {
        (w - 2.5, &CENTRAL)
    } else {
        (w.sqrt() - 3.0, &TAIL)
    };
    let mut x = coeffs.iter().fold(0.0, |p, c| c + p * w) * y;
    for _ in 0..2 {
        let d = 2.0 / std::f64::consts::PI.sqrt() * (-x * x).exp();
        if d > 0.0 {
            x -= (libm::erf(x) - y) / d;
        }
    }
    x
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
    /// The roughness at the shading point (None: a mirror).
    fn ggx(&self, ctx: &ShadingCtx) -> Option<Ggx>;
    /// Reflectance at the path's wavelengths for cos θ at the (micro)facet.
    fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32) -> Spec;
    /// The same as Mueller matrices (Mitsuba's conventions).
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_theta: f32) -> [Mueller; 4];
}

impl<T: OpaqueReflector> PolarizedBsdf for T {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        reflection_eval_mueller(self.ggx(ctx), wi, wo, |c| self.reflectance_mueller(ctx, c))
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
        reflection_sample_mueller(self.ggx(ctx), wi, u2, |c| self.reflectance_mueller(ctx, c))
    }
}

/// `BsdfModel::eval` of an [`OpaqueReflector`].
#[inline]
pub fn opaque_eval(r: &impl OpaqueReflector, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
    let fresnel = |c| r.reflectance(ctx, c);
    reflection_eval(r.ggx(ctx), wi, wo, fresnel, |f, w| f * w).map_or(Spec::ZERO, |(_, v)| v)
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
    let ggx = r.ggx(ctx);
    let s = reflection_sample(ggx, wi, u2, |c| r.reflectance(ctx, c), |f, g| f * g)?;
    Some(s.into_sample(ggx))
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
            ctx: &$crate::render::bsdf::ShadingCtx,
            wi: ::glam::Vec3,
            wo: ::glam::Vec3,
        ) -> f32 {
            use $crate::render::bsdf::microfacet::OpaqueReflector;
            $crate::render::bsdf::microfacet::reflection_lobe_pdf(self.ggx(ctx), wi, wo)
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

    /// Both distributions are normalised (∫ D cos θm = 1) and so are their visible normals
    /// (∫ G1(wi, m) max(0, wi·m) D(m) / cos θi dm = 1, which needs the exact Smith G1).
    #[test]
    fn beckmann_and_visible_normals_are_normalised() {
        let n = 600;
        for mf in [
            Microfacet::of(Distribution::Beckmann, 0.3, 0.15),
            Microfacet::of(Distribution::Beckmann, 0.05, 0.05),
            Microfacet::of(Distribution::Ggx, 0.4, 0.2),
        ] {
            for wi in [Vec3::Z, Vec3::new(0.6, 0.3, 0.742).normalize()] {
                let (mut d_sum, mut vis_sum) = (0.0f64, 0.0f64);
                for i in 0..n {
                    for j in 0..n {
                        // θm on [0, π/2) with more resolution near the pole (u² map).
                        let u = (i as f64 + 0.5) / n as f64;
                        let theta = u * u * std::f64::consts::FRAC_PI_2;
                        let dtheta = 2.0 * u * std::f64::consts::FRAC_PI_2 / n as f64;
                        let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n as f64;
                        let m = Vec3::new(
                            (theta.sin() * phi.cos()) as f32,
                            (theta.sin() * phi.sin()) as f32,
                            theta.cos() as f32,
                        );
                        let dw = theta.sin() * dtheta * 2.0 * std::f64::consts::PI / n as f64;
                        d_sum += mf.d(m) as f64 * theta.cos() * dw;
                        vis_sum += mf.pdf_visible(wi, m) as f64 * dw;
                    }
                }
                assert!((d_sum - 1.0).abs() < 0.01, "{mf:?}: ∫D cos = {d_sum}");
                assert!(
                    (vis_sum - 1.0).abs() < 0.01,
                    "{mf:?} wi={wi}: ∫D_vis = {vis_sum}"
                );
            }
        }
    }

    /// erf(erf⁻¹(y)) = y over the range, including the tails the sampler reaches.
    #[test]
    fn erfinv_inverts_erf() {
        for k in 0..=2000 {
            let y = -0.999_999 + 1.999_998 * k as f64 / 2000.0;
            let x = erfinv(y);
            assert!(
                (libm::erf(x) - y).abs() < 1e-10,
                "y={y}: erf(erfinv) = {}",
                libm::erf(x)
            );
        }
    }

    /// The Beckmann visible-slope sampler's marginal CDF is inverted exactly: the slope
    /// sampled from u has CDF u (also at grazing incidence).
    #[test]
    fn beckmann_slope_sampler_inverts_its_cdf() {
        for cos_i in [0.999_f64, 0.7, 0.2, 0.02] {
            let tan_i = (1.0 - cos_i * cos_i).sqrt() / cos_i;
            let cdf =
                |x: f64| 1.0 + libm::erf(x) + tan_i * (-x * x).exp() / std::f64::consts::PI.sqrt();
            let total = cdf(1.0 / tan_i);
            for k in 1..100 {
                let u = k as f32 / 100.0;
                let (x, _) = beckmann_visible_slopes_11(cos_i, Vec2::new(u, 0.5));
                let got = cdf(x as f64) / total;
                assert!(
                    (got - u as f64).abs() < 1e-4,
                    "cos {cos_i} u {u}: CDF {got}"
                );
            }
        }
    }
}
