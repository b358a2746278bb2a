//! glTF materials → [`GltfPbr`] (`docs/gltf-materials.md`): the core metallic-roughness
//! parameters and textures, `alphaMode`, `doubleSided`, `KHR_texture_transform` on every
//! texture, and the extensions `KHR_materials_ior`, `_specular`, `_transmission`, `_volume`,
//! `_iridescence` and `_emissive_strength` (the extensions the `gltf` crate does not model
//! are read from the material's JSON). Colour textures (base colour, specular colour,
//! emissive) are sRGB-decoded; data textures are linear. Every error names the file, the
//! material and the key.

use super::gltf_scene::{image_layout, wrap_mode};
use super::texture::srgb_to_linear;
use super::{BitmapTexture, SpectrumDesc, TextureFilter};
use crate::render::bsdf::gltf_pbr::{AlphaMode, GltfMaterial, GltfPbr, Iridescence, Volume};
use crate::render::bsdf::Bsdf;
use anyhow::{bail, Context, Result};
use glam::Mat3;
use serde_json::Value;
use std::sync::Arc;

/// The `KHR_texture_transform` of a textureInfo as Mitsuba's `to_uv` — the extension's
/// translation · rotation · scale, with the rotation u' = u cos r + v sin r,
/// v' = −u sin r + v cos r as the glTF Sample Viewer and three.js apply it (counter-clockwise
/// in the image, whose v runs down) — and its `texCoord` override.
fn texture_transform(t: &Value, key: &str) -> Result<(Mat3, Option<u64>)> {
    let num = |v: Option<&Value>, d: f32| -> Result<f32> {
        match v {
            None => Ok(d),
            Some(x) => x
                .as_f64()
                .map(|x| x as f32)
                .filter(|x| x.is_finite())
                .with_context(|| format!("{key}.KHR_texture_transform: {x} is not a number")),
        }
    };
    let pair = |name: &str, d: f32| -> Result<[f32; 2]> {
        match t.get(name) {
            None => Ok([d, d]),
            Some(Value::Array(a)) if a.len() == 2 => Ok([num(a.first(), d)?, num(a.get(1), d)?]),
            Some(x) => bail!("{key}.KHR_texture_transform.{name} = {x} must be [x, y]"),
        }
    };
    let [ox, oy] = pair("offset", 0.0)?;
    let [sx, sy] = pair("scale", 1.0)?;
    let r = num(t.get("rotation"), 0.0)?;
    let (s, c) = r.sin_cos();
    let translation = Mat3::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, ox, oy, 1.0]);
    let rotation = Mat3::from_cols_array(&[c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0]);
    let scale = Mat3::from_cols_array(&[sx, 0.0, 0.0, 0.0, sy, 0.0, 0.0, 0.0, 1.0]);
    Ok((
        translation * rotation * scale,
        t.get("texCoord").and_then(Value::as_u64),
    ))
}

/// A textureInfo: texture index, `texCoord`, and its `KHR_texture_transform` object.
struct TexRef<'v> {
    index: usize,
    tex_coord: u64,
    transform: Option<&'v Value>,
    key: String,
}

/// The textureInfo of one of the `gltf` crate's typed texture references.
fn typed_ref<'v>(
    index: usize,
    tex_coord: u32,
    extensions: Option<&'v serde_json::Map<String, Value>>,
    key: &str,
) -> TexRef<'v> {
    TexRef {
        index,
        tex_coord: tex_coord as u64,
        transform: extensions.and_then(|e| e.get("KHR_texture_transform")),
        key: key.to_string(),
    }
}

/// Reads a textureInfo JSON object.
fn tex_ref<'v>(v: &'v Value, key: String) -> Result<TexRef<'v>> {
    let index = v
        .get("index")
        .and_then(Value::as_u64)
        .with_context(|| format!("{key} has no texture index"))? as usize;
    Ok(TexRef {
        index,
        tex_coord: v.get("texCoord").and_then(Value::as_u64).unwrap_or(0),
        transform: v
            .get("extensions")
            .and_then(|e| e.get("KHR_texture_transform")),
        key,
    })
}

pub(super) struct MaterialReader<'a> {
    pub doc: &'a gltf::Document,
    pub images: &'a [gltf::image::Data],
    /// "file: material NAME" for messages.
    pub what: String,
    /// The `texCoord` set of every texture read so far, with its key.
    pub tex_coords: std::cell::RefCell<Vec<(u64, String)>>,
}

impl MaterialReader<'_> {
    /// Channels `channels` of texture `t` as a 1- or 3-channel bitmap (sRGB-decoded when
    /// `srgb`); None when the image lacks the alpha channel asked for (alpha is then 1).
    fn texture(
        &self,
        t: &TexRef,
        channels: &[usize],
        srgb: bool,
    ) -> Result<Option<Arc<BitmapTexture>>> {
        let key = format!("{}: {}", self.what, t.key);
        let tex = self
            .doc
            .textures()
            .nth(t.index)
            .with_context(|| format!("{key}: texture {} does not exist", t.index))?;
        let img = self
            .images
            .get(tex.source().index())
            .with_context(|| format!("{key}: image {} was not loaded", tex.source().index()))?;
        let (n, bytes) = image_layout(img.format);
        if channels == [3] && n < 4 {
            return Ok(None);
        }
        let count = img.width as usize * img.height as usize;
        if img.pixels.len() < count * n * bytes {
            bail!("{key}: image data is truncated");
        }
        let read = |i: usize, c: usize| -> f32 {
            let o = (i * n + c.min(n - 1)) * bytes;
            let p = &img.pixels;
            let v = match bytes {
                1 => p[o] as f32 / 255.0,
                2 => u16::from_le_bytes([p[o], p[o + 1]]) as f32 / 65535.0,
                _ => f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]),
            };
            if srgb && c < 3 {
                srgb_to_linear(v)
            } else {
                v
            }
        };
        let data = (0..count)
            .flat_map(|i| channels.iter().map(move |&c| (i, c)))
            .map(|(i, c)| read(i, c))
            .collect();
        let mut b = BitmapTexture::new(
            img.width as usize,
            img.height as usize,
            channels.len(),
            data,
        )
        .with_context(|| key.clone())?;
        let sampler = tex.sampler();
        b.wrap = wrap_mode(sampler.wrap_s());
        if let Some(gltf::texture::MagFilter::Nearest) = sampler.mag_filter() {
            b.filter = TextureFilter::Nearest;
        }
        let mut tex_coord = t.tex_coord;
        if let Some(tt) = t.transform {
            let (m, tc) = texture_transform(tt, &key)?;
            b.to_uv = m;
            tex_coord = tc.unwrap_or(tex_coord);
        }
        self.tex_coords
            .borrow_mut()
            .push((tex_coord, t.key.clone()));
        Ok(Some(Arc::new(b)))
    }

    /// The texture at JSON `v` (if present), channels as [`Self::texture`].
    fn optional(
        &self,
        v: Option<&Value>,
        key: &str,
        channels: &[usize],
        srgb: bool,
    ) -> Result<Option<Arc<BitmapTexture>>> {
        match v {
            None => Ok(None),
            Some(v) => self.texture(&tex_ref(v, key.to_string())?, channels, srgb),
        }
    }

    /// A number of extension object `ext` (default `d`); a non-number is an error.
    fn num(&self, ext: &Value, ext_name: &str, key: &str, d: f32) -> Result<f32> {
        match ext.get(key) {
            None => Ok(d),
            Some(v) => v
                .as_f64()
                .map(|x| x as f32)
                .with_context(|| format!("{}: {ext_name}.{key} = {v} is not a number", self.what)),
        }
    }

    /// A colour array of `len` numbers.
    fn color<const N: usize>(
        &self,
        ext: &Value,
        ext_name: &str,
        key: &str,
        d: [f32; N],
    ) -> Result<[f32; N]> {
        match ext.get(key) {
            None => Ok(d),
            Some(Value::Array(a)) if a.len() == N && a.iter().all(Value::is_number) => {
                Ok(std::array::from_fn(|i| a[i].as_f64().unwrap_or(0.0) as f32))
            }
            Some(v) => bail!(
                "{}: {ext_name}.{key} = {v} must be an array of {N} numbers",
                self.what
            ),
        }
    }

    /// `KHR_materials_iridescence` of `m`.
    fn iridescence(&self, m: &gltf::Material) -> Result<Option<Iridescence>> {
        let k = "KHR_materials_iridescence";
        let Some(v) = m.extension_value(k) else {
            return Ok(None);
        };
        let ior = match v.get("iridescenceIor") {
            Some(_) => self.num(v, k, "iridescenceIor", 1.3)?,
            // A misspelling some exporters write.
            None => self.num(v, k, "iridescenceIOR", 1.3)?,
        };
        Ok(Some(Iridescence {
            factor: self.num(v, k, "iridescenceFactor", 0.0)?,
            factor_texture: self.optional(
                v.get("iridescenceTexture"),
                &format!("{k}.iridescenceTexture"),
                &[0],
                false,
            )?,
            ior,
            thickness_min_nm: self.num(v, k, "iridescenceThicknessMinimum", 100.0)?,
            thickness_max_nm: self.num(v, k, "iridescenceThicknessMaximum", 400.0)?,
            thickness_texture: self.optional(
                v.get("iridescenceThicknessTexture"),
                &format!("{k}.iridescenceThicknessTexture"),
                &[0, 1, 2],
                false,
            )?,
        }))
    }

    /// The material's core textures (base colour and alpha, metallic-roughness, normal).
    fn core(&self, m: &gltf::Material, out: &mut GltfMaterial) -> Result<()> {
        let pbr = m.pbr_metallic_roughness();
        if let Some(i) = pbr.base_color_texture() {
            let t = typed_ref(
                i.texture().index(),
                i.tex_coord(),
                i.extensions(),
                "baseColorTexture",
            );
            out.base_color_texture = self.texture(&t, &[0, 1, 2], true)?;
            out.alpha_texture = self.texture(&t, &[3], false)?;
        }
        if let Some(i) = pbr.metallic_roughness_texture() {
            let key = "metallicRoughnessTexture";
            let t = typed_ref(i.texture().index(), i.tex_coord(), i.extensions(), key);
            out.metallic_roughness_texture = self.texture(&t, &[0, 1, 2], false)?;
        }
        if let Some(n) = m.normal_texture() {
            let t = typed_ref(
                n.texture().index(),
                n.tex_coord(),
                n.extensions(),
                "normalTexture",
            );
            if let Some(b) = self.texture(&t, &[0, 1, 2], false)? {
                out.normal_texture = Some((b, n.scale()));
            }
        }
        Ok(())
    }

    /// The extensions `_specular`, `_transmission`, `_volume`.
    fn extensions(&self, m: &gltf::Material, out: &mut GltfMaterial) -> Result<()> {
        let k = "KHR_materials_specular";
        if let Some(v) = m.extension_value(k) {
            out.has_specular_extension = true;
            out.specular = self.num(v, k, "specularFactor", 1.0)?;
            out.specular_texture = self.optional(
                v.get("specularTexture"),
                &format!("{k}.specularTexture"),
                &[3],
                false,
            )?;
            out.specular_color = self.color(v, k, "specularColorFactor", [1.0; 3])?;
            out.specular_color_texture = self.optional(
                v.get("specularColorTexture"),
                &format!("{k}.specularColorTexture"),
                &[0, 1, 2],
                true,
            )?;
        }
        if let Some(t) = m.transmission() {
            out.transmission = t.transmission_factor();
            if let Some(i) = t.transmission_texture() {
                let key = "KHR_materials_transmission.transmissionTexture";
                let r = typed_ref(i.texture().index(), i.tex_coord(), i.extensions(), key);
                out.transmission_texture = self.texture(&r, &[0], false)?;
            }
        }
        let k = "KHR_materials_volume";
        if let Some(v) = m.extension_value(k) {
            let thickness = self.num(v, k, "thicknessFactor", 0.0)?;
            if !(thickness.is_finite() && thickness >= 0.0) {
                bail!(
                    "{}: {k}.thicknessFactor = {thickness} must be finite and ≥ 0",
                    self.what
                );
            }
            if thickness > 0.0 {
                out.volume = Some(Volume {
                    attenuation_color: self.color(v, k, "attenuationColor", [1.0; 3])?,
                    attenuation_distance: self.num(v, k, "attenuationDistance", f32::INFINITY)?,
                });
            }
        }
        Ok(())
    }

    /// The BSDF and the emitted radiance (linear RGB, `emissiveFactor` ×
    /// `emissiveStrength`; the emissive texture rides on the BSDF) of material `m`.
    pub fn read(&self, m: &gltf::Material) -> Result<(Bsdf, Option<SpectrumDesc>, u32)> {
        let pbr = m.pbr_metallic_roughness();
        let mut out = GltfMaterial {
            base_color: pbr.base_color_factor(),
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            ior: m.ior().unwrap_or(1.5),
            double_sided: m.double_sided(),
            alpha_mode: match m.alpha_mode() {
                gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                gltf::material::AlphaMode::Mask => AlphaMode::Mask(m.alpha_cutoff().unwrap_or(0.5)),
                gltf::material::AlphaMode::Blend => AlphaMode::Blend,
            },
            ..GltfMaterial::default()
        };
        self.core(m, &mut out)?;
        self.extensions(m, &mut out)?;
        out.iridescence = self.iridescence(m)?;
        let emission = self.emission(m, &mut out)?;
        let bsdf = GltfPbr::new(out).with_context(|| self.what.clone())?;
        Ok((bsdf.into(), emission, self.uv_set()?))
    }

    /// The `TEXCOORD_n` set the material's textures read (0 without textures). A mesh has
    /// one set of texture coordinates here: textures on different sets get the first
    /// texture's set, with a warning naming the others.
    fn uv_set(&self) -> Result<u32> {
        let sets = self.tex_coords.borrow();
        let Some((first, _)) = sets.first() else {
            return Ok(0);
        };
        let Ok(set) = u32::try_from(*first) else {
            bail!("{}: texCoord {first} is out of range", self.what);
        };
        for (s, key) in sets.iter().filter(|(s, _)| s != first) {
            eprintln!(
                "warning: {}: {key} reads TEXCOORD_{s}; TEXCOORD_{first} is used (one set per material)",
                self.what
            );
        }
        Ok(set)
    }

    /// `emissiveFactor` × `KHR_materials_emissive_strength` (the emitted radiance, linear
    /// RGB); an `emissiveTexture` goes to `out.emissive_texture`, which the area light
    /// multiplies in per texel.
    fn emission(&self, m: &gltf::Material, out: &mut GltfMaterial) -> Result<Option<SpectrumDesc>> {
        let strength = m.emissive_strength().unwrap_or(1.0);
        if !(strength.is_finite() && strength >= 0.0) {
            bail!("{}: KHR_materials_emissive_strength.emissiveStrength = {strength} must be finite and ≥ 0", self.what);
        }
        let e = m.emissive_factor().map(|c| c * strength);
        if !e.iter().all(|c| c.is_finite() && *c >= 0.0) {
            bail!(
                "{}: emissiveFactor {:?} must be finite and ≥ 0",
                self.what,
                m.emissive_factor()
            );
        }
        if let (Some(i), true) = (m.emissive_texture(), e.iter().any(|&c| c > 0.0)) {
            let t = typed_ref(
                i.texture().index(),
                i.tex_coord(),
                i.extensions(),
                "emissiveTexture",
            );
            out.emissive_texture = self.texture(&t, &[0, 1, 2], true)?;
        }
        Ok(e.iter().any(|&c| c > 0.0).then_some(SpectrumDesc::Rgb(e)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_transform_is_translation_rotation_scale() {
        let t = serde_json::json!({"offset": [0.5, 0.0], "rotation": std::f32::consts::FRAC_PI_2,
                                   "scale": [2.0, 1.0], "texCoord": 1});
        let (m, tc) = texture_transform(&t, "baseColorTexture").unwrap();
        assert_eq!(tc, Some(1));
        // (1, 0) → scale (2, 0) → rotate (0, −2) → offset (0.5, −2).
        let p = m * glam::Vec3::new(1.0, 0.0, 1.0);
        assert!((p - glam::Vec3::new(0.5, -2.0, 1.0)).length() < 1e-6, "{p}");
        let bad = serde_json::json!({"scale": [1.0]});
        let e = texture_transform(&bad, "normalTexture")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("normalTexture.KHR_texture_transform.scale"),
            "{e}"
        );
    }
}
