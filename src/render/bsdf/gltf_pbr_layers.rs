//! The glTF material at one shading point: textures looked up, the base colour upsampled,
//! the Fresnel terms of its layers (exact dielectric, Gulbrandsen metal, Airy film), the
//! microfacet refraction term and the normal-map frame.

use super::super::fresnel::{fresnel_conductor, fresnel_dielectric};
use super::super::microfacet::Ggx;
use super::super::ShadingCtx;
use super::{GltfMaterial, GltfPbr};
use crate::optics::film_f32::ThinFilmX4;
use crate::render::counters::{count, Counter};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::Spec;
use crate::scene::BitmapTexture;
use crate::spectrum::rgb2spec::{srgb_reflectance, RgbSigmoidPolynomial};
use anyhow::bail;
use glam::Vec3;
use num_complex::Complex32;
use std::sync::Arc;

/// glTF `alphaMode`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AlphaMode {
    Opaque,
    /// Opaque where alpha ≥ `alphaCutoff`, absent elsewhere.
    Mask(f32),
    /// Coverage = alpha (stochastic opacity).
    Blend,
}

/// `KHR_materials_iridescence`.
#[derive(Debug, Clone)]
pub struct Iridescence {
    /// `iridescenceFactor` and `iridescenceTexture` (R).
    pub factor: f32,
    pub factor_texture: Option<Arc<BitmapTexture>>,
    /// `iridescenceIor` (the film's index).
    pub ior: f32,
    /// `iridescenceThicknessMinimum`/`Maximum` (nm): the thickness texture's G channel
    /// interpolates between them; without a texture the thickness is the maximum.
    pub thickness_min_nm: f32,
    pub thickness_max_nm: f32,
    pub thickness_texture: Option<Arc<BitmapTexture>>,
}

/// `KHR_materials_volume` with a thickness > 0: the mesh bounds a refracting medium.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    /// `attenuationColor` (linear RGB): the transmittance after `attenuation_distance`.
    pub attenuation_color: [f32; 3],
    /// `attenuationDistance` in scene units (∞: no absorption).
    pub attenuation_distance: f32,
}

fn check(ok: bool, key: &str, v: impl std::fmt::Debug, range: &str) -> anyhow::Result<()> {
    if ok {
        Ok(())
    } else {
        bail!("{key} = {v:?} is invalid: must be {range}")
    }
}

fn unit(v: f32) -> bool {
    (0.0..=1.0).contains(&v)
}

/// Every factor finite and in the range the glTF schema gives it.
pub(super) fn validate(m: &GltfMaterial) -> anyhow::Result<()> {
    let range01 = "finite and in [0, 1]";
    check(m.base_color.iter().all(|&c| unit(c)), "baseColorFactor", m.base_color, range01)?;
    check(unit(m.metallic), "metallicFactor", m.metallic, range01)?;
    check(unit(m.roughness), "roughnessFactor", m.roughness, range01)?;
    check(m.ior.is_finite() && m.ior >= 1.0, "KHR_materials_ior.ior", m.ior, "finite and ≥ 1")?;
    check(unit(m.specular), "KHR_materials_specular.specularFactor", m.specular, range01)?;
    check(
        m.specular_color.iter().all(|&c| c.is_finite() && c >= 0.0),
        "KHR_materials_specular.specularColorFactor",
        m.specular_color,
        "finite and ≥ 0",
    )?;
    check(
        unit(m.transmission),
        "KHR_materials_transmission.transmissionFactor",
        m.transmission,
        range01,
    )?;
    if let AlphaMode::Mask(c) = m.alpha_mode {
        check(c.is_finite() && c >= 0.0, "alphaCutoff", c, "finite and ≥ 0")?;
    }
    if let Some((_, s)) = &m.normal_texture {
        check(s.is_finite(), "normalTexture.scale", s, "finite")?;
    }
    if let Some(v) = &m.volume {
        check(
            v.attenuation_color.iter().all(|&c| unit(c)),
            "KHR_materials_volume.attenuationColor",
            v.attenuation_color,
            range01,
        )?;
        check(
            v.attenuation_distance > 0.0,
            "KHR_materials_volume.attenuationDistance",
            v.attenuation_distance,
            "> 0",
        )?;
    }
    if let Some(i) = &m.iridescence {
        let k = "KHR_materials_iridescence";
        check(unit(i.factor), &format!("{k}.iridescenceFactor"), i.factor, range01)?;
        check(i.ior.is_finite() && i.ior >= 1.0, &format!("{k}.iridescenceIor"), i.ior, "finite and ≥ 1")?;
        for (key, v) in [
            ("iridescenceThicknessMinimum", i.thickness_min_nm),
            ("iridescenceThicknessMaximum", i.thickness_max_nm),
        ] {
            check(v.is_finite() && v >= 0.0, &format!("{k}.{key}"), v, "finite and ≥ 0 (nm)")?;
        }
    }
    Ok(())
}

/// The complex index n + ik of a metal whose normal-incidence reflectance is `r` and whose
/// edge tint is `g` (Gulbrandsen 2014, "Artist Friendly Metallic Fresnel", JCGT 3(4), eqs.
/// 8–9): n = g (1−r)/(1+r) + (1−g) (1+√r)/(1−√r), k = √(((n+1)² r − (n−1)²)/(1−r)).
/// r is kept below 1 (k would be infinite), g in [0, 1].
pub fn gulbrandsen_index(r: f32, g: f32) -> Complex32 {
    let r = r.clamp(0.0, 0.999);
    let g = g.clamp(0.0, 1.0);
    let sr = r.sqrt();
    let n_min = (1.0 - r) / (1.0 + r);
    let n_max = (1.0 + sr) / (1.0 - sr);
    let n = g * n_min + (1.0 - g) * n_max;
    let k2 = ((n + 1.0) * (n + 1.0) * r - (n - 1.0) * (n - 1.0)) / (1.0 - r);
    Complex32::new(n, k2.max(0.0).sqrt())
}

/// Grid of the single-scattering albedo table [`ggx_albedo`]: α and cos θ, each sampled at
/// `ALBEDO_N` points over [0, 1].
const ALBEDO_N: usize = 32;

/// E(μ, α) = ∫ D G / (4 μ) dωo, the directional albedo of the GGX reflection lobe with
/// F = 1 (what one scattering off the microfacets keeps; 1 − E is lost to the multiple
/// scattering a single-scattering model leaves out), tabulated once on a 32 × 32 grid of
/// (α, μ) by a 24 × 24 midpoint rule over the visible-normal sampling square
/// (E = ∫ G1(wo) over the visible normals, Heitz 2018), and bilinearly interpolated.
pub(super) fn ggx_albedo(alpha: f32, mu: f32) -> f32 {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let q = 24;
        let mut t = Vec::with_capacity(ALBEDO_N * ALBEDO_N);
        for ia in 0..ALBEDO_N {
            let a = (ia as f32 / (ALBEDO_N - 1) as f32).max(1e-3);
            let ggx = Ggx::new(a, a);
            for im in 0..ALBEDO_N {
                let mu = (im as f32 / (ALBEDO_N - 1) as f32).max(1e-3);
                let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let mut sum = 0.0f64;
                for i in 0..q * q {
                    let u = glam::Vec2::new(
                        ((i % q) as f32 + 0.5) / q as f32,
                        ((i / q) as f32 + 0.5) / q as f32,
                    );
                    let m = ggx.sample_visible(wi, u);
                    let wo = 2.0 * wi.dot(m) * m - wi;
                    if wo.z > 0.0 {
                        sum += ggx.g1(wo, m) as f64;
                    }
                }
                t.push((sum / (q * q) as f64) as f32);
            }
        }
        t
    });
    // a·(1 − t) + b·t, as the table was always read (renders stay bit-identical).
    bilinear(t, alpha, mu, |a, b, t| a * (1.0 - t) + b * t)
}

/// Bilinear lookup in a table of `ALBEDO_N` × `ALBEDO_N` over (α, μ) ∈ [0, 1]².
#[inline]
fn bilinear<T: Copy>(t: &[T], alpha: f32, mu: f32, lerp: impl Fn(T, T, f32) -> T) -> T {
    let fa = alpha.clamp(0.0, 1.0) * (ALBEDO_N - 1) as f32;
    let fm = mu.clamp(0.0, 1.0) * (ALBEDO_N - 1) as f32;
    let (ia, im) = ((fa as usize).min(ALBEDO_N - 2), (fm as usize).min(ALBEDO_N - 2));
    let (da, dm) = (fa - ia as f32, fm - im as f32);
    let at = |a: usize, m: usize| t[a * ALBEDO_N + m];
    let lo = lerp(at(ia, im), at(ia, im + 1), dm);
    let hi = lerp(at(ia + 1, im), at(ia + 1, im + 1), dm);
    lerp(lo, hi, da)
}

/// The single-scattering directional albedo of a rough lossless dielectric interface
/// (GGX, exact Fresnel, no film), split into reflection E_R(α, μ) and refraction E_T(α, μ)
/// in energy (the radiance factor 1/η² undone), from outside (relative index η = ior) and
/// from inside (1/η); tabulated per material over the same (α, μ) grid as [`ggx_albedo`]
/// by a 16 × 16 midpoint rule over the visible normals of wi: a visible normal m reflects
/// with weight F(wi·m)·G1(wo_r) and refracts with (1 − F)·G1(wo_t) (Heitz 2018; Walter et
/// al. 2007). What is missing from E_R + E_T is the energy of the light that scatters
/// more than once between the microfacets.
#[derive(Debug)]
pub(super) struct GlassAlbedo {
    /// [outside, inside], each ALBEDO_N² of (E_R, E_T).
    sides: [Vec<[f32; 2]>; 2],
}

impl GlassAlbedo {
    pub fn new(ior: f32) -> Self {
        GlassAlbedo {
            sides: [ior, 1.0 / ior].map(Self::table),
        }
    }

    fn table(eta: f32) -> Vec<[f32; 2]> {
        let q = 16;
        let mut t = Vec::with_capacity(ALBEDO_N * ALBEDO_N);
        for ia in 0..ALBEDO_N {
            let a = (ia as f32 / (ALBEDO_N - 1) as f32).max(1e-3);
            let ggx = Ggx::new(a, a);
            for im in 0..ALBEDO_N {
                let mu = (im as f32 / (ALBEDO_N - 1) as f32).max(1e-3);
                let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let (mut er, mut et) = (0.0f64, 0.0f64);
                for i in 0..q * q {
                    let u = glam::Vec2::new(
                        ((i % q) as f32 + 0.5) / q as f32,
                        ((i / q) as f32 + 0.5) / q as f32,
                    );
                    let m = ggx.sample_visible(wi, u);
                    let c = wi.dot(m);
                    let f = fresnel_dielectric(c, eta).0;
                    let wr = 2.0 * c * m - wi;
                    if wr.z > 0.0 {
                        er += (f * ggx.g1(wr, m)) as f64;
                    }
                    if let Some(wt) = super::refract(wi, m, eta) {
                        if wt.z < 0.0 {
                            et += ((1.0 - f) * ggx.g1(wt, m)) as f64;
                        }
                    }
                }
                let n = (q * q) as f64;
                t.push([(er / n) as f32, (et / n) as f32]);
            }
        }
        t
    }

    /// (E_R, E_T) from inside (`inside`) or outside at roughness α and cos θ = μ.
    pub fn at(&self, inside: bool, alpha: f32, mu: f32) -> [f32; 2] {
        let side = &self.sides[usize::from(inside)];
        let lerp = |a: f32, b: f32, t: f32| a * (1.0 - t) + b * t;
        bilinear(side, alpha, mu, |a, b, t| [lerp(a[0], b[0], t), lerp(a[1], b[1], t)])
    }
}

/// The index under a film on a metal without `KHR_materials_specular`: Gulbrandsen's
/// complex index at edge tint g = 0, which is the real index whose normal-incidence
/// reflectance is the base colour F0(λ), n = (1 + √F0)/(1 − √F0), k = 0 — the index the
/// iridescence extension itself puts under the film (KHR_materials_iridescence, "Thin-film
/// Fresnel": `Fresnel0ToIor(baseF0)`) and every viewer draws. Written in closed form (F0 kept
/// below 0.9999) because [`gulbrandsen_index`] at g = 0 leaves k a rounding error ≠ 0. With
/// the specular extension the film's base is the bare metal's own index, its colour the
/// edge tint ([`Point::at`]). On the white-tint index of a bare glTF metal the film's
/// colours are far paler (F0 0.8, 600 nm of index 1.3: linear sRGB 0.85, 0.82, 0.80 against
/// 0.67, 0.79, 0.71 here) than the viewers' and the specification's.
#[inline]
fn metal_film_base(f0: Spec) -> [Complex32; 4] {
    f0.to_array().map(|f| {
        let s = f.clamp(0.0, 0.9999).sqrt();
        Complex32::new((1.0 + s) / (1.0 - s), 0.0)
    })
}

/// A reflectance spectrum at the path's wavelengths.
#[inline]
fn spectrum(p: &RgbSigmoidPolynomial, ctx: &ShadingCtx) -> Spec {
    p.eval4(Spec::from_array(ctx.wl.lambda))
}

/// Linear RGB `factor` × texture (if any) at the shading point, upsampled.
#[inline]
fn rgb_spectrum(
    factor: [f32; 3],
    tex: &Option<Arc<BitmapTexture>>,
    cached: &RgbSigmoidPolynomial,
    ctx: &ShadingCtx,
) -> Spec {
    match tex {
        None => spectrum(cached, ctx),
        Some(t) => {
            let v = t.eval(ctx.uv);
            let rgb = [0, 1, 2].map(|c| factor[c] * v[c]);
            if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
                Spec::splat(rgb[0].clamp(0.0, 1.0))
            } else {
                spectrum(&srgb_reflectance(rgb), ctx)
            }
        }
    }
}

/// The first channel of an optional texture (1 without one).
#[inline]
fn channel(tex: &Option<Arc<BitmapTexture>>, ctx: &ShadingCtx, c: usize) -> f32 {
    tex.as_ref().map_or(1.0, |t| t.eval(ctx.uv)[c])
}

/// A metal's edge tint g(λ) at the shading point: white without `KHR_materials_specular`;
/// with it `specularColorFactor` × `specularColorTexture` × `specularFactor` ×
/// `specularTexture` A (`specular`, the factor × A), each channel at most 1.
#[inline]
fn edge_tint(pbr: &GltfPbr, ctx: &ShadingCtx, specular: f32) -> Spec {
    let m = &pbr.material;
    let tint = |s: f32| m.specular_color.map(|c| (c * s).min(1.0));
    match &m.specular_texture {
        None => rgb_spectrum(tint(m.specular), &m.specular_color_texture, &pbr.edge_poly, ctx),
        Some(_) => {
            let f = tint(specular);
            rgb_spectrum(f, &m.specular_color_texture, &srgb_reflectance(f), ctx)
        }
    }
}

/// The material's values at one shading point, seen from the side the light arrives on.
pub(super) struct Point {
    pub base: Spec,
    pub coverage: f32,
    pub metallic: f32,
    /// None: smooth (mirror lobes).
    pub ggx: Option<Ggx>,
    pub specular: f32,
    /// KHR_materials_specular colour (spectral), None when white.
    pub specular_color: Option<Spec>,
    pub transmission: f32,
    /// η_t / η_i across the interface from this side.
    pub eta: f32,
    /// The ambient index on this side and the index beyond (glass interior: ior | 1).
    pub ambient: f32,
    pub beyond: f32,
    /// Film factor and thickness (nm), if any.
    pub film: Option<(f32, f32, f32)>,
    /// The metal's complex index per wavelength (when metallic > 0).
    pub metal: [Complex32; 4],
    /// The index under the film on the metal (when metallic > 0 and there is a film):
    /// Gulbrandsen's with edge tint g = the `KHR_materials_specular` colour, g = 0 without
    /// that extension ([`metal_film_base`]).
    pub metal_film: [Complex32; 4],
    /// Beer–Lambert transmittance of the segment that arrived from inside a volume.
    pub absorption: Spec,
    /// GGX roughness α (0 for smooth surfaces), for the energy compensation.
    pub alpha: f32,
}

impl Point {
    pub fn at(pbr: &GltfPbr, ctx: &ShadingCtx, inside: bool) -> Point {
        let m = &pbr.material;
        let [r, g, b, _] = m.base_color;
        // glTF 2.0 §3.9.2: baseColor = factor × texture × COLOR_0 (the vertex colour).
        let c = ctx.color;
        let base = if c == Vec3::ONE {
            rgb_spectrum([r, g, b], &m.base_color_texture, &pbr.base_poly, ctx)
        } else {
            let factor = [r * c.x, g * c.y, b * c.z];
            rgb_spectrum(factor, &m.base_color_texture, &srgb_reflectance(factor), ctx)
        };
        let coverage = pbr.coverage(ctx.uv).unwrap_or(1.0);
        let (roughness, metallic) = match &m.metallic_roughness_texture {
            Some(t) => {
                let v = t.eval(ctx.uv);
                (m.roughness * v[1], m.metallic * v[2])
            }
            None => (m.roughness, m.metallic),
        };
        let alpha = (roughness * roughness).clamp(1e-3, 1.0);
        let ggx = (m.roughness > 0.0).then(|| Ggx::new(alpha, alpha));
        let specular = m.specular * m.specular_texture.as_ref().map_or(1.0, |t| t.eval(ctx.uv)[0]);
        let specular_color = (m.specular_color != [1.0; 3] || m.specular_color_texture.is_some())
            .then(|| {
                let v = m.specular_color_texture.as_ref().map_or([1.0; 3], |t| t.eval(ctx.uv));
                let rgb = [0, 1, 2].map(|c| m.specular_color[c] * v[c]);
                // Not a reflectance: may exceed 1 (the product with F0 is clamped).
                let mx = rgb[0].max(rgb[1]).max(rgb[2]).max(1e-6);
                spectrum(&srgb_reflectance(rgb.map(|c| c / mx)), ctx) * mx
            });
        let transmission = m.transmission * channel(&m.transmission_texture, ctx, 0);
        let refracting_inside = inside && m.volume.is_some();
        let (ambient, beyond) = if refracting_inside {
            (m.ior, 1.0)
        } else {
            (1.0, m.ior)
        };
        let film = m.iridescence.as_ref().and_then(|i| {
            let f = i.factor * channel(&i.factor_texture, ctx, 0);
            let d = match &i.thickness_texture {
                Some(t) => {
                    let v = t.eval(ctx.uv)[1];
                    i.thickness_min_nm + v * (i.thickness_max_nm - i.thickness_min_nm)
                }
                None => i.thickness_max_nm,
            };
            let d = if d.is_finite() { d.max(0.0) } else { 0.0 };
            (f > 0.0).then_some((f, d, i.ior))
        });
        let metal = if metallic > 0.0 {
            let edge = edge_tint(pbr, ctx, specular);
            std::array::from_fn(|i| gulbrandsen_index(base[i], edge[i]))
        } else {
            [Complex32::new(1.0, 0.0); 4]
        };
        let metal_film = match (metallic > 0.0 && film.is_some(), m.has_specular_extension) {
            (true, true) => metal,
            (true, false) => metal_film_base(base),
            (false, _) => [Complex32::new(1.0, 0.0); 4],
        };
        let absorption = match &m.volume {
            Some(v) if inside && v.attenuation_distance.is_finite() => {
                let c = spectrum(&srgb_reflectance(v.attenuation_color), ctx);
                let d = ctx.segment.max(0.0) / v.attenuation_distance;
                // T = c^(s/d): Beer–Lambert with σ = −ln(c)/d.
                Spec::from_array(c.to_array().map(|c| if c > 0.0 { c.powf(d) } else { 0.0 }))
            }
            _ => Spec::ONE,
        };
        Point {
            base,
            coverage,
            metallic,
            ggx,
            specular,
            specular_color,
            transmission,
            eta: beyond / ambient,
            ambient,
            beyond,
            film,
            metal,
            metal_film,
            absorption,
            alpha: if m.roughness > 0.0 { alpha } else { 0.0 },
        }
    }

    /// Multiple-scattering energy compensation of the specular reflection lobe (Turquin
    /// 2019, "Practical multiple scattering compensation for microfacet models", eq. 11):
    /// the single-scattering lobe times 1 + F0 (1 − E(μ))/E(μ), with E the lobe's albedo
    /// for F = 1 ([`ggx_albedo`]) at the incident angle and F0 the layer's normal-incidence
    /// reflectance (the dielectric's exact F(1) × specular, the metal's base colour, mixed
    /// by metallic; the film is left out of F0). With F ≡ 1 the lobe's albedo is then 1 at
    /// every roughness (white furnace); smooth lobes are unchanged. The transmitting share
    /// of a rough refracting dielectric takes the glass factor instead
    /// ([`Self::glass_compensation`]).
    #[inline]
    pub fn energy_compensation(&self, pbr: &GltfPbr, mu: f32) -> Spec {
        if self.alpha <= 0.0 {
            return Spec::ONE;
        }
        let e = ggx_albedo(self.alpha, mu).max(1e-3);
        let f0_d = fresnel_dielectric(1.0, self.eta).0 * self.specular;
        let f0 = Spec::splat(f0_d) * (1.0 - self.metallic) + self.base * self.metallic;
        let c = Spec::ONE + f0 * ((1.0 - e) / e);
        match self.glass_compensation(pbr, mu) {
            // The dielectric's transmitting share: its factor 1 + F0 (1 − E)/E replaced.
            Some(k) => {
                let c_d = 1.0 + f0_d * (1.0 - e) / e;
                c + Spec::splat((1.0 - self.metallic) * self.transmission * (k - c_d))
            }
            None => c,
        }
    }

    /// Energy compensation of rough refracting glass (Turquin 2019, §4 for dielectrics):
    /// its reflection and refraction lobes both scaled by 1/(E_R(μ) + E_T(μ)), the
    /// interface's single-scattering albedo ([`GlassAlbedo`]), so that lossless clear glass
    /// keeps all the energy at every angle and roughness, total internal reflection
    /// included (white furnace). Kept in [1, 4]. None for smooth glass, thin-walled
    /// transmission and materials without transmission.
    #[inline]
    pub fn glass_compensation(&self, pbr: &GltfPbr, mu: f32) -> Option<f32> {
        let glass = pbr.glass.as_deref()?;
        if self.alpha <= 0.0 || self.transmission <= 0.0 {
            return None;
        }
        let [er, et] = glass.at(self.ambient > 1.0, self.alpha, mu);
        Some((1.0 / (er + et).max(0.25)).clamp(1.0, 4.0))
    }

    /// The Airy reflectance of the film on `substrate` at cos θ (exact, s and p averaged).
    #[inline]
    fn film_r(&self, ctx: &ShadingCtx, d: f32, n: f32, substrate: [Complex32; 4], c: f32) -> Spec {
        count(Counter::FilmEvals, 1);
        let film = ThinFilmX4 {
            ambient_ior: self.ambient,
            film_ior: [Complex32::new(n, 0.0); 4],
            thickness_nm: d,
            substrate_ior: substrate,
        };
        let r = film.response(ctx.wl.lambda, c).r();
        Spec::from_array(r.map(|v| if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }))
    }

    /// (dielectric F_d, metal F_m) at cos θ = `c` on the facet, the film blended in.
    #[inline]
    pub fn fresnel(&self, pbr: &GltfPbr, ctx: &ShadingCtx, c: f32) -> (Spec, Spec) {
        let c = c.clamp(0.0, 1.0);
        let mut f_d = Spec::splat(fresnel_dielectric(c, self.eta).0);
        if let (Some(sc), false) = (self.specular_color, self.ambient > 1.0) {
            // KHR_materials_specular scales F0 by the colour, not the grazing value:
            // F = F_exact + (colour − 1)·F0·(1 − (1 − c)^5).
            let ior = pbr.material.ior;
            let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
            let w = 1.0 - (1.0 - c).powi(5);
            f_d += (sc - Spec::ONE) * (f0 * w);
        }
        let mut f_m = Spec::ZERO;
        if self.metallic > 0.0 {
            f_m = Spec::from_array(std::array::from_fn(|i| {
                fresnel_conductor(c, self.metal[i].re, self.metal[i].im)
            }));
        }
        if let Some((factor, d, n)) = self.film {
            if self.metallic < 1.0 {
                let sub = [Complex32::new(self.beyond, 0.0); 4];
                let r = self.film_r(ctx, d, n, sub, c);
                f_d = f_d * (1.0 - factor) + r * factor;
            }
            if self.metallic > 0.0 {
                let r = self.film_r(ctx, d, n, self.metal_film, c);
                f_m = f_m * (1.0 - factor) + r * factor;
            }
        }
        (
            (f_d * self.specular).clamp(Spec::ZERO, Spec::ONE),
            f_m,
        )
    }

    /// The specular layer's Fresnel term: dielectric and metal mixed by `metallic`.
    #[inline]
    pub fn mix_metal(&self, f_d: Spec, f_m: Spec) -> Spec {
        f_d * (1.0 - self.metallic) + f_m * self.metallic
    }
}

/// GGX refraction from `wi` (z > 0) to `wo` (z < 0) across relative index `eta` (Walter et al.
/// 2007, eqs. 16–17, 21; pbrt-v4 `DielectricBxDF`): the half vector m, f·|cos θo| without the
/// (1 − F) factor, in radiance units (÷ η²), and the pdf of sampling `wo` from the visible
/// normals of `wi` and refracting.
#[inline]
pub(super) fn refraction(ggx: Ggx, wi: Vec3, wo: Vec3, eta: f32) -> Option<(Vec3, f32, f32)> {
    if wi.z <= 0.0 || wo.z >= 0.0 {
        return None;
    }
    let mut m = (wi + wo * eta).normalize();
    if m.z < 0.0 {
        m = -m;
    }
    let (di, d_o) = (wi.dot(m), wo.dot(m));
    if !(di > 0.0 && d_o < 0.0 && m.is_finite()) {
        return None;
    }
    let denom = (d_o + di / eta).powi(2);
    let d = ggx.d(m);
    if d == 0.0 || denom <= 0.0 {
        return None;
    }
    let value = d * ggx.g(wi, wo, m) * (di * d_o).abs() / (denom * wi.z) / (eta * eta);
    let pdf = ggx.pdf_visible(wi, m) * d_o.abs() / denom;
    (value.is_finite() && pdf.is_finite()).then_some((m, value, pdf))
}

/// The shading frame perturbed by a tangent-space normal map (glTF: RGB = (x, y, z)·½ + ½,
/// x and y scaled by `scale`). The tangent is the mesh's `TANGENT` where it has one
/// (interpolated, orthogonalised against the shading normal, bitangent w·(n × t), glTF 2.0
/// §3.7.2.1), else ∂p/∂u with bitangent n × t (the Sample Viewer without the attribute).
/// The unperturbed frame where the tangent or the result degenerates.
pub(super) fn normal_mapped(si: &SurfaceInteraction, tex: &BitmapTexture, scale: f32) -> Frame {
    let n = si.shading.n;
    let tangential = |v: Vec3| {
        let t = v - n * n.dot(v);
        (t.length_squared() > 1e-20 && t.is_finite()).then(|| t.normalize())
    };
    let vertex = tangential(si.tangent.truncate()).map(|t| (t, si.tangent.w.signum()));
    let Some((t, sign)) = vertex.or_else(|| tangential(si.dpdu).map(|t| (t, 1.0))) else {
        return si.shading;
    };
    let b = n.cross(t) * sign;
    let v = tex.eval(si.uv);
    let ts = Vec3::new(
        (2.0 * v[0] - 1.0) * scale,
        (2.0 * v[1] - 1.0) * scale,
        2.0 * v[2] - 1.0,
    );
    let nn = (t * ts.x + b * ts.y + n * ts.z).normalize();
    if !nn.is_finite() || nn.dot(n) <= 0.0 {
        return si.shading;
    }
    let s = (t - nn * nn.dot(t)).normalize();
    Frame {
        s,
        t: nn.cross(s),
        n: nn,
    }
}
