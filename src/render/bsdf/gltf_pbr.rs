//! glTF 2.0's metallic-roughness material (glTF 2.0 specification, Appendix B "BRDF
//! Implementation") with `KHR_materials_ior`, `_specular`, `_transmission`, `_volume` and
//! `_iridescence`, rendered spectrally (`docs/gltf-materials.md`).
//!
//! The model is the specification's layering, at each of the path's four wavelengths:
//!
//! ```text
//! metal      = F_metal(v·h) · specular_brdf                       (B.3.5 conductor_fresnel)
//! dielectric = F_d(v·h) · specular_brdf                            (B.3.5 fresnel_mix)
//!            + (1 − F_d(v·h)) · [(1 − tr) · ρ/π + tr · ρ · specular_btdf]
//! material   = mix(dielectric, metal, metallic)
//! ```
//!
//! with specular_brdf = D·G/(4 cos θi cos θo), GGX, α = roughness² (B.3.2), separable Smith G,
//! and ρ the base colour upsampled to a reflectance spectrum (Jakob & Hanika 2019). Where the
//! specification writes Schlick's approximation this model uses the exact terms it
//! approximates: F_d is the unpolarised Fresnel reflectance of index `ior` (scaled by
//! `KHR_materials_specular`), F_metal the Fresnel reflectance of a complex index derived from
//! the base colour (F0) and the edge tint (Gulbrandsen 2014, [`gulbrandsen_index`]).
//! `KHR_materials_iridescence` replaces both by the exact Airy reflectance of the film on
//! that base, s and p averaged, blended with `iridescenceFactor`; transmission gets the
//! film's complement 1 − R (the film is lossless).
//!
//! Transmission (`KHR_materials_transmission`) refracts (Walter et al. 2007, GGX) when the
//! material has a volume (`KHR_materials_volume`, thickness > 0), and is thin-walled
//! otherwise (the reflected microfacet lobe mirrored through the surface, no bending), as
//! the extensions specify. Inside a volume, `attenuationColor`/`attenuationDistance` absorb
//! along the path (Beer–Lambert over the incoming segment, [`ShadingCtx::segment`]).
//! `alphaMode` MASK/BLEND is stochastic opacity: a null lobe (straight through) of weight
//! 1 − coverage. Sampling: one lobe (null, specular, diffuse, transmission) is chosen from
//! weights estimated at wi, GGX visible normals for the microfacet lobes, cosine for the
//! diffuse one; the pdf is the mixture's.

#[path = "gltf_pbr_layers.rs"]
mod layers;

pub use layers::{gulbrandsen_index, AlphaMode, Iridescence, Volume};

use super::fresnel::{fresnel_dielectric, reflect, reflect_local};
use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx,
};
use crate::render::geometry::{
    cosine_hemisphere_pdf, square_to_cosine_hemisphere, Frame, SurfaceInteraction,
};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use crate::scene::{BitmapTexture, SpectrumDesc, TextureDesc};
use crate::spectrum::rgb2spec::{srgb_reflectance, RgbSigmoidPolynomial};
use glam::{Vec2, Vec3};
use layers::Point;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// A glTF material's parameters (every factor and texture as the file gives them; colours
/// linear).
#[derive(Debug, Clone)]
pub struct GltfMaterial {
    /// `baseColorFactor` (linear RGBA).
    pub base_color: [f32; 4],
    /// `baseColorTexture` RGB, sRGB-decoded (multiplied by the factor at lookup).
    pub base_color_texture: Option<Arc<BitmapTexture>>,
    /// `baseColorTexture` alpha (1 channel).
    pub alpha_texture: Option<Arc<BitmapTexture>>,
    pub alpha_mode: AlphaMode,
    pub metallic: f32,
    pub roughness: f32,
    /// `metallicRoughnessTexture` (linear RGB: G roughness, B metallic).
    pub metallic_roughness_texture: Option<Arc<BitmapTexture>>,
    /// `normalTexture` (linear RGB) and its `scale`.
    pub normal_texture: Option<(Arc<BitmapTexture>, f32)>,
    /// `KHR_materials_ior` (default 1.5).
    pub ior: f32,
    /// `KHR_materials_specular`: `specularFactor` and its texture (A channel).
    pub specular: f32,
    pub specular_texture: Option<Arc<BitmapTexture>>,
    /// `specularColorFactor` (linear) and its texture (RGB, sRGB-decoded); for metals the
    /// edge tint of [`gulbrandsen_index`].
    pub specular_color: [f32; 3],
    pub specular_color_texture: Option<Arc<BitmapTexture>>,
    /// Whether `KHR_materials_specular` was given (metals: white edge tint otherwise).
    pub has_specular_extension: bool,
    /// `KHR_materials_transmission`: factor and texture (R).
    pub transmission: f32,
    pub transmission_texture: Option<Arc<BitmapTexture>>,
    /// `KHR_materials_volume` with thickness > 0 (refraction), None: thin-walled.
    pub volume: Option<Volume>,
    pub iridescence: Option<Iridescence>,
    pub double_sided: bool,
    /// `emissiveTexture` (linear RGB, sRGB-decoded): the shape's area light reads it per
    /// texel ([`crate::render::lights::TexturedEmission`]); not used by the BSDF itself.
    pub emissive_texture: Option<Arc<BitmapTexture>>,
}

impl Default for GltfMaterial {
    /// The glTF defaults: white, fully metallic and rough, ior 1.5, no extension.
    fn default() -> Self {
        GltfMaterial {
            base_color: [1.0; 4],
            base_color_texture: None,
            alpha_texture: None,
            alpha_mode: AlphaMode::Opaque,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            ior: 1.5,
            specular: 1.0,
            specular_texture: None,
            specular_color: [1.0; 3],
            specular_color_texture: None,
            has_specular_extension: false,
            transmission: 0.0,
            transmission_texture: None,
            volume: None,
            iridescence: None,
            double_sided: false,
            emissive_texture: None,
        }
    }
}

/// A glTF material ready to render: its parameters and what is precomputed from them.
#[derive(Debug, Clone)]
pub struct GltfPbr {
    pub material: GltfMaterial,
    /// `baseColorFactor` RGB upsampled to a reflectance spectrum (Jakob & Hanika 2019).
    base_poly: RgbSigmoidPolynomial,
    /// The edge tint of metals (`specularColorFactor` × `specularFactor`, white without
    /// `KHR_materials_specular`), upsampled the same way.
    edge_poly: RgbSigmoidPolynomial,
    /// Rough refracting glass: its interface's single-scattering albedos, for the energy
    /// compensation of its lobes ([`layers::Point::glass_compensation`]).
    glass: Option<Arc<layers::GlassAlbedo>>,
}

/// Lobe choice weights at wi: null (alpha), specular reflection, diffuse, transmission.
#[derive(Debug, Clone, Copy)]
struct LobeWeights([f32; 4]);

const NULL: usize = 0;
const SPEC: usize = 1;
const DIFF: usize = 2;
const TRANS: usize = 3;

impl LobeWeights {
    fn masked(mut self, lobes: Lobes) -> Option<Self> {
        if !lobes.reflection() {
            self.0[SPEC] = 0.0;
            self.0[DIFF] = 0.0;
        }
        if !lobes.transmission() {
            self.0[NULL] = 0.0;
            self.0[TRANS] = 0.0;
        }
        let sum: f32 = self.0.iter().sum();
        (sum > 0.0 && sum.is_finite()).then(|| LobeWeights(self.0.map(|w| w / sum)))
    }

    /// The lobe `u` picks and its probability.
    fn pick(&self, u: f32) -> (usize, f32) {
        let mut acc = 0.0;
        for (i, &w) in self.0.iter().enumerate() {
            acc += w;
            if u < acc && w > 0.0 {
                return (i, w);
            }
        }
        let last = (0..4).rev().find(|&i| self.0[i] > 0.0).unwrap_or(SPEC);
        (last, self.0[last])
    }
}

/// Refracted direction of `wi` (wi·m > 0) about `m` for the relative index `eta` = η_t/η_i;
/// None under total internal reflection.
#[inline]
fn refract(wi: Vec3, m: Vec3, eta: f32) -> Option<Vec3> {
    let c = wi.dot(m);
    let sin2_t = (1.0 - c * c).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wi / eta + (c / eta - cos_t) * m).normalize())
}

/// The mirror image of `w` through the surface plane.
#[inline]
fn mirror(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

impl GltfPbr {
    /// The material after validation (every factor finite and in its range; errors name
    /// the glTF key).
    pub fn new(material: GltfMaterial) -> anyhow::Result<Self> {
        layers::validate(&material)?;
        let [r, g, b, _] = material.base_color;
        let edge = if material.has_specular_extension {
            material.specular_color.map(|c| (c * material.specular).min(1.0))
        } else {
            [1.0; 3]
        };
        let transmits = material.transmission > 0.0 || material.transmission_texture.is_some();
        let glass = (transmits && material.volume.is_some() && material.roughness > 0.0)
            .then(|| Arc::new(layers::GlassAlbedo::new(material.ior)));
        Ok(GltfPbr {
            base_poly: srgb_reflectance([r, g, b]),
            edge_poly: srgb_reflectance(edge),
            glass,
            material,
        })
    }

    /// The alpha coverage at `uv` (`baseColorFactor` A × texture A; MASK: 1 at or above
    /// `alphaCutoff`, else 0; BLEND: alpha), None for OPAQUE materials.
    pub fn coverage(&self, uv: Vec2) -> Option<f32> {
        let m = &self.material;
        let alpha = || m.base_color[3] * m.alpha_texture.as_ref().map_or(1.0, |t| t.eval(uv)[0]);
        match m.alpha_mode {
            AlphaMode::Opaque => None,
            AlphaMode::Mask(cut) => Some(if alpha() >= cut { 1.0 } else { 0.0 }),
            AlphaMode::Blend => Some(alpha().clamp(0.0, 1.0)),
        }
    }

    /// Whether light can pass through (transmission or alpha).
    fn transmissive(&self) -> bool {
        self.material.transmission > 0.0 || self.material.alpha_mode != AlphaMode::Opaque
    }

    /// The GGX lobe, None for a smooth surface (roughness factor 0: mirror lobes).
    fn smooth(&self) -> bool {
        self.material.roughness == 0.0
    }

    /// The side `wi` arrives from, and `wi`, `wo` seen from it (z > 0 for wi); None where
    /// the material does not scatter (the back of a one-sided opaque surface).
    #[inline]
    fn orient(&self, wi: Vec3, wo: Vec3) -> Option<(bool, Vec3, Vec3)> {
        if wi.z >= 0.0 {
            return (wi.z > 0.0).then_some((false, wi, wo));
        }
        (self.material.double_sided || self.transmissive()).then(|| (true, mirror(wi), mirror(wo)))
    }

    /// Lobe weights at `wi` (seen from its side): estimates of each lobe's albedo.
    fn weights(&self, p: &Point, wi: Vec3) -> LobeWeights {
        let fd = fresnel_dielectric(wi.z, p.eta).0 * p.specular;
        let fd = fd.clamp(0.05, 1.0);
        let m = p.metallic;
        let rho = (p.base.x + p.base.y + p.base.z + p.base.w) * 0.25;
        let cov = p.coverage;
        LobeWeights([
            1.0 - cov,
            cov * (m + (1.0 - m) * fd),
            cov * (1.0 - m) * (1.0 - fd) * (1.0 - p.transmission) * rho,
            cov * (1.0 - m) * (1.0 - fd) * p.transmission * rho.max(0.05),
        ])
    }

    /// f·|cos θo| of the non-delta lobes (wi, wo seen from wi's side).
    fn eval_oriented(&self, p: &Point, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wo.z > 0.0 {
            let h = (wi + wo).normalize();
            let c = wi.dot(h).clamp(0.0, 1.0);
            let (f_d, f_m) = p.fresnel(self, ctx, c);
            let mut v = Spec::ZERO;
            if p.metallic < 1.0 && p.transmission < 1.0 {
                let diffuse = (Spec::ONE - f_d) * p.base * (FRAC_1_PI * wo.z);
                v += diffuse * ((1.0 - p.metallic) * (1.0 - p.transmission));
            }
            if let Some(ggx) = p.ggx {
                if let Some((_, w)) = ggx.reflection(wi, wo) {
                    v += p.mix_metal(f_d, f_m) * p.energy_compensation(self, wi.z) * w;
                }
            }
            v * p.coverage
        } else if wo.z < 0.0 && p.transmission > 0.0 {
            let Some(ggx) = p.ggx else {
                return Spec::ZERO;
            };
            let t = p.coverage * (1.0 - p.metallic) * p.transmission;
            match self.material.volume {
                Some(_) => match layers::refraction(ggx, wi, wo, p.eta) {
                    Some((m, w, _)) => {
                        let (f_d, _) = p.fresnel(self, ctx, wi.dot(m).clamp(0.0, 1.0));
                        let k = p.glass_compensation(self, wi.z).unwrap_or(1.0);
                        (Spec::ONE - f_d) * p.base * (w * t * k)
                    }
                    None => Spec::ZERO,
                },
                None => match ggx.reflection(wi, mirror(wo)) {
                    Some((m, w)) => {
                        let (f_d, _) = p.fresnel(self, ctx, wi.dot(m).clamp(0.0, 1.0));
                        (Spec::ONE - f_d) * p.base * (w * t)
                    }
                    None => Spec::ZERO,
                },
            }
        } else {
            Spec::ZERO
        }
    }

    /// Solid-angle pdf of the non-delta lobes under lobe weights `w` (wi, wo seen from wi's
    /// side).
    fn pdf_oriented(&self, p: &Point, w: &LobeWeights, wi: Vec3, wo: Vec3) -> f32 {
        let [_, ws, wd, wt] = w.0;
        if wo.z > 0.0 {
            let spec = p.ggx.map_or(0.0, |g| g.reflection_pdf(wi, wo));
            ws * spec + wd * cosine_hemisphere_pdf(wo.z)
        } else if wo.z < 0.0 {
            match (p.ggx, &self.material.volume) {
                (Some(g), Some(_)) => {
                    wt * layers::refraction(g, wi, wo, p.eta).map_or(0.0, |(_, _, pdf)| pdf)
                }
                (Some(g), None) => wt * g.reflection_pdf(wi, mirror(wo)),
                (None, _) => 0.0,
            }
        } else {
            0.0
        }
    }

    /// A sample of a Dirac lobe (seen from wi's side), or None if `lobe` is smooth here.
    fn sample_delta(
        &self,
        p: &Point,
        ctx: &ShadingCtx,
        wi: Vec3,
        lobe: usize,
        prob: f32,
    ) -> Option<BsdfSample> {
        match lobe {
            NULL => Some(BsdfSample::delta(
                -wi,
                Spec::splat((1.0 - p.coverage) / prob),
                prob,
                BsdfFlags::NULL,
            )),
            SPEC if p.ggx.is_none() => {
                let (f_d, f_m) = p.fresnel(self, ctx, wi.z);
                let v = p.mix_metal(f_d, f_m) * p.coverage;
                Some(BsdfSample::delta(
                    reflect_local(wi),
                    v / prob,
                    prob,
                    BsdfFlags::DELTA_REFLECTION,
                ))
            }
            TRANS if p.ggx.is_none() => {
                let (f_d, _) = p.fresnel(self, ctx, wi.z);
                let t = p.coverage * (1.0 - p.metallic) * p.transmission;
                let v = (Spec::ONE - f_d) * p.base * t;
                let mut s = match self.material.volume {
                    Some(_) => {
                        let wo = refract(wi, Vec3::Z, p.eta)?;
                        // Radiance scales by 1/η² across the interface (Veach 1997, 5.2).
                        let v = v / (p.eta * p.eta);
                        BsdfSample::delta(wo, v / prob, prob, BsdfFlags::DELTA_TRANSMISSION)
                    }
                    None => BsdfSample::delta(-wi, v / prob, prob, BsdfFlags::DELTA_TRANSMISSION),
                };
                if self.material.volume.is_some() {
                    s.eta = p.eta;
                }
                Some(s)
            }
            _ => None,
        }
    }

    /// `sample` seen from wi's side.
    fn sample_oriented(
        &self,
        p: &Point,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let w = self.weights(p, wi).masked(lobes)?;
        let (lobe, prob) = w.pick(u1);
        if let Some(s) = self.sample_delta(p, ctx, wi, lobe, prob) {
            return Some(s);
        }
        let (wo, flag) = match (lobe, p.ggx) {
            (SPEC, Some(g)) => (reflect(wi, g.sample_visible(wi, u2)), BsdfFlags::GLOSSY_REFLECTION),
            (DIFF, _) => (square_to_cosine_hemisphere(u2), BsdfFlags::DIFFUSE_REFLECTION),
            (TRANS, Some(g)) => {
                let m = g.sample_visible(wi, u2);
                let wo = match self.material.volume {
                    Some(_) => refract(wi, m, p.eta)?,
                    None => mirror(reflect(wi, m)),
                };
                (wo, BsdfFlags::GLOSSY_TRANSMISSION)
            }
            _ => return None,
        };
        let reflected = flag == BsdfFlags::GLOSSY_REFLECTION || flag == BsdfFlags::DIFFUSE_REFLECTION;
        if (wo.z > 0.0) != reflected || wo.z == 0.0 {
            return None;
        }
        let pdf = self.pdf_oriented(p, &w, wi, wo);
        let mut s = BsdfSample::of_mixture(wo, pdf, || self.eval_oriented(p, ctx, wi, wo), flag)?;
        if flag == BsdfFlags::GLOSSY_TRANSMISSION && self.material.volume.is_some() {
            s.eta = p.eta;
        }
        Some(s)
    }
}

impl BsdfPlugin for GltfPbr {
    /// glTF materials come from `.gltf`/`.glb` files (`scene::gltf_material`); `gltf_pbr`
    /// is the same model in a Mitsuba-syntax scene (thinfilm's own plugin, for comparisons
    /// and benchmarks on Mitsuba scenes).
    const PLUGINS: &'static [&'static str] = &["gltf_pbr"];

    /// `base_color` (linear RGB or a number, default 1), `metallic` (1), `roughness` (1),
    /// `ior` (1.5), `transmission` (0; with `volume` true (default) it refracts),
    /// `iridescence` (film factor, 0), `iridescence_ior` (1.3), `iridescence_thickness`
    /// (nm, 400), `double_sided` (false).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let base_color = match p.texture("base_color", 1.0)? {
            TextureDesc::Value(SpectrumDesc::Constant(v)) => [v, v, v, 1.0],
            TextureDesc::Value(SpectrumDesc::Rgb([r, g, b])) => [r, g, b, 1.0],
            _ => return Err(p.error_at("base_color", "base_color must be an rgb or a number")),
        };
        let num = |p: &mut PluginParams, k: &str, d: f64| p.float(k, d).map(|v| v as f32);
        let film_factor = num(p, "iridescence", 0.0)?;
        let film_ior = num(p, "iridescence_ior", 1.3)?;
        let film_d = num(p, "iridescence_thickness", 400.0)?;
        let volume = p.bool("volume", true)?.then_some(Volume {
            attenuation_color: [1.0; 3],
            attenuation_distance: f32::INFINITY,
        });
        let m = GltfMaterial {
            base_color,
            metallic: num(p, "metallic", 1.0)?,
            roughness: num(p, "roughness", 1.0)?,
            ior: num(p, "ior", 1.5)?,
            transmission: num(p, "transmission", 0.0)?,
            volume,
            iridescence: (film_factor > 0.0).then_some(Iridescence {
                factor: film_factor,
                factor_texture: None,
                ior: film_ior,
                thickness_min_nm: 0.0,
                thickness_max_nm: film_d,
                thickness_texture: None,
            }),
            double_sided: p.bool("double_sided", false)?,
            ..GltfMaterial::default()
        };
        GltfPbr::new(m).map_err(|e| p.error(e))
    }
}

impl BsdfModel for GltfPbr {
    fn flags(&self) -> BsdfFlags {
        let smooth = self.smooth();
        let mut f = if smooth {
            BsdfFlags::DELTA_REFLECTION
        } else {
            BsdfFlags::GLOSSY_REFLECTION
        };
        let mr_tex = self.material.metallic_roughness_texture.is_some();
        let tr_tex = self.material.transmission_texture.is_some();
        if (self.material.metallic < 1.0 || mr_tex) && (self.material.transmission < 1.0 || tr_tex) {
            f |= BsdfFlags::DIFFUSE_REFLECTION;
        }
        if self.material.transmission > 0.0 && (self.material.metallic < 1.0 || mr_tex) {
            f |= if smooth {
                BsdfFlags::DELTA_TRANSMISSION
            } else {
                BsdfFlags::GLOSSY_TRANSMISSION
            };
        }
        if self.material.alpha_mode != AlphaMode::Opaque {
            f |= BsdfFlags::NULL;
        }
        if self.material.double_sided || self.transmissive() {
            f |= BsdfFlags::TWO_SIDED;
        }
        if let Some(i) = &self.material.iridescence {
            f |= BsdfFlags::INTERFERENCE;
            if i.thickness_texture.is_some() {
                f |= BsdfFlags::THICKNESS_MAP;
            }
        }
        f
    }

    fn describe(&self) -> String {
        let [r, g, b, _] = self.material.base_color;
        let film = self
            .material.iridescence
            .as_ref()
            .map(|i| format!(", film n={} {}–{} nm ×{}", i.ior, i.thickness_min_nm, i.thickness_max_nm, i.factor))
            .unwrap_or_default();
        format!(
            "glTF PBR base=({r:.3},{g:.3},{b:.3}) metallic={} roughness={} ior={} transmission={}{film}",
            self.material.metallic, self.material.roughness, self.material.ior, self.material.transmission
        )
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        let Some((inside, wi, wo)) = self.orient(wi, wo) else {
            return Spec::ZERO;
        };
        let p = Point::at(self, ctx, inside);
        self.eval_oriented(&p, ctx, wi, wo) * p.absorption
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        let Some((inside, wi, wo)) = self.orient(wi, wo) else {
            return 0.0;
        };
        let p = Point::at(self, ctx, inside);
        match self.weights(&p, wi).masked(Lobes::ALL) {
            Some(w) => self.pdf_oriented(&p, &w, wi, wo),
            None => 0.0,
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
        let (inside, wi_o, _) = self.orient(wi, Vec3::Z)?;
        let p = Point::at(self, ctx, inside);
        let mut s = self.sample_oriented(&p, ctx, wi_o, u1, u2, lobes)?;
        s.weight *= p.absorption;
        if wi.z < 0.0 {
            s.wo = mirror(s.wo);
        }
        Some(s)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("the glTF PBR material has no polarised form (its layers mix unpolarised terms)")
    }

    /// The `normalTexture` perturbation (tangent from ∂p/∂u, bitangent n × t, as the glTF
    /// Sample Viewer builds it without a TANGENT attribute).
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        match &self.material.normal_texture {
            Some((tex, scale)) => layers::normal_mapped(si, tex, *scale),
            None => si.shading,
        }
    }
}

#[cfg(test)]
#[path = "gltf_pbr_tests.rs"]
mod tests;
