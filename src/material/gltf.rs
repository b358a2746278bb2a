//! `material.gltf`: a [`FilmMaterial`] as a glTF 2.0 material with
//! `KHR_materials_iridescence` (the film: `iridescenceIor` at 550 nm, thickness texture in the
//! **G** channel mapped onto [`iridescenceThicknessMinimum`, `…Maximum`]) over the base
//! layer (the substrate), and back, through the same reader the glTF scene loader uses
//! ([`crate::scene::gltf_scene::iridescent_film`]).
//!
//! glTF cannot express everything a fit finds: indices are real constants (the film at
//! 550 nm), the thickness texture has 8 bits (an error ≤ (max − min)/510), and a substrate
//! is either a dielectric of index `KHR_materials_ior` (k = 0: metallic 0, black base, so
//! that what enters it is absorbed, as in the `thinfilm` BSDF) or, when it absorbs, a metal
//! (metallic 1) whose base colour is its normal-incidence reflectance, read back as the grey
//! conductor of the same luminance.

use super::FilmMaterial;
use crate::optics::{Ior, ThinFilm};
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::Path;

/// The thickness map as 8-bit texels G = (d − min)/(max − min) (R = B = 0; NaN texels take
/// the median), with (min, max) in nm.
fn thickness_texture(material: &FilmMaterial) -> (Vec<u8>, f64, f64) {
    let filled = material.filled_thickness_nm();
    let (lo, hi) = crate::stats::Summary::of_finite(&filled).map_or((0.0, 0.0), |s| (s.min, s.max));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut bytes = Vec::with_capacity(filled.len() * 3);
    for &d in &filled {
        let g = (((d as f64 - lo) / span).clamp(0.0, 1.0) * 255.0).round() as u8;
        bytes.extend_from_slice(&[0, g, 0]);
    }
    (bytes, lo, hi)
}

/// Normal-incidence reflectance of the substrate as linear sRGB (D65): a metal's glTF base
/// colour.
fn substrate_f0_rgb(substrate: &Ior) -> [f64; 3] {
    let r = |l: f64| {
        let n = substrate.at(l);
        ThinFilm {
            ambient_ior: 1.0,
            film_ior: n,
            thickness_nm: 0.0,
            substrate_ior: n,
        }
        .response(l, 1.0)
        .r()
    };
    crate::spectrum::xyz_to_linear_srgb(crate::spectrum::reflectance_xyz_d65(r))
        .map(|v| v.clamp(0.0, 1.0))
}

/// Writes `path` (`material.gltf`) and its thickness texture `texture_name` beside it.
pub fn write(material: &FilmMaterial, path: &Path, texture_name: &str) -> Result<()> {
    let (bytes, lo, hi) = thickness_texture(material);
    let dir = path.parent().unwrap_or(Path::new("."));
    crate::image_io::write_png_rgb8(
        &dir.join(texture_name),
        material.width,
        material.height,
        bytes,
    )
    .with_context(|| format!("writing {texture_name}"))?;
    let sub = material.substrate_ior.at(550.0);
    let (base, metallic) = if sub.im > 0.0 {
        let [r, g, b] = substrate_f0_rgb(&material.substrate_ior);
        ([r, g, b, 1.0], 1.0)
    } else {
        ([0.0, 0.0, 0.0, 1.0], 0.0)
    };
    let doc = json!({
        "asset": {"version": "2.0", "generator": "thinfilm"},
        "extensionsUsed": ["KHR_materials_iridescence", "KHR_materials_ior"],
        "materials": [{
            "name": "fitted_film",
            "pbrMetallicRoughness": {"baseColorFactor": base, "metallicFactor": metallic, "roughnessFactor": 0.0},
            "extensions": {
                "KHR_materials_ior": {"ior": super::finite(sub.re)},
                "KHR_materials_iridescence": {
                    "iridescenceFactor": 1.0,
                    "iridescenceIor": super::finite(material.film_ior_550()),
                    "iridescenceThicknessMinimum": super::finite(lo),
                    "iridescenceThicknessMaximum": super::finite(hi),
                    "iridescenceThicknessTexture": {"index": 0}
                }
            }
        }],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729}],
        "images": [{"uri": texture_name, "mimeType": "image/png"}]
    });
    let text = serde_json::to_string_pretty(&doc)?;
    crate::image_io::write_atomically(path, |p| Ok(std::fs::write(p, text.as_bytes())?))
}

/// Reads the first material of a glTF file that has `KHR_materials_iridescence` as a
/// [`FilmMaterial`] (the thickness in nm after the texture's value range).
pub fn read(path: &Path) -> Result<FilmMaterial> {
    let file = path.display().to_string();
    // Validated before use, like a glTF scene (see `scene::gltf_check`).
    let (doc, _, images) =
        crate::limits::contain_panics(path, || crate::scene::gltf_check::import(path))?;
    for m in doc.materials() {
        let what = format!("{file}: material {:?}", m.name().unwrap_or(""));
        let Some((film_n, thickness)) =
            crate::scene::gltf_scene::iridescent_film(&m, &doc, &images, &what)?
        else {
            continue;
        };
        let pbr = m.pbr_metallic_roughness();
        let substrate_ior = if pbr.metallic_factor() >= 0.5 {
            let [r, g, b, _] = pbr.base_color_factor();
            crate::scene::gltf_scene::grey_conductor(r, g, b)
        } else {
            Ior::real(m.ior().unwrap_or(1.5) as f64)
        };
        let film = crate::render::bsdf::thinfilm::ThinFilmBsdf::new(
            Ior::real(film_n),
            &thickness,
            substrate_ior,
            0.0,
        )?;
        return FilmMaterial::from_bsdf(&film.into()).with_context(|| what);
    }
    bail!("{file}: no material with KHR_materials_iridescence")
}

#[cfg(test)]
mod tests {
    use super::super::tests::example;
    use super::*;

    #[test]
    fn round_trips_to_8_bits_of_thickness() {
        for (film, substrate) in [("1.38", "1.52"), ("cauchy:1.36,3400", "PET")] {
            let dir = tempfile::tempdir().unwrap();
            let mut m = example(film, substrate);
            m.thickness_nm[5] = f32::NAN;
            let path = dir.path().join("material.gltf");
            write(&m, &path, "thickness_gltf.png").unwrap();
            let back = read(&path).unwrap();
            assert!((back.film_ior_550() - m.film_ior_550()).abs() < 1e-9);
            let n_sub = m.substrate_ior.at(550.0).re;
            // glTF stores the base layer's index in f32.
            assert!(!back.substrate_ior.is_dispersive());
            assert!((back.substrate_ior.at(550.0) - n_sub).norm() < 1e-6);
            let (lo, hi) = (380.0, 435.0);
            let filled = m.filled_thickness_nm();
            for (a, b) in back.thickness_nm.iter().zip(&filled) {
                assert!((a - b).abs() <= (hi - lo) / 510.0 + 1e-3, "{a} vs {b}");
            }
            assert_eq!((back.width, back.height), (m.width, m.height));
        }
    }

    #[test]
    fn an_absorbing_substrate_becomes_a_metal_of_its_reflectance() {
        let dir = tempfile::tempdir().unwrap();
        let m = example("1.38", "Au");
        let path = dir.path().join("material.gltf");
        write(&m, &path, "t.png").unwrap();
        let doc: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let pbr = &doc["materials"][0]["pbrMetallicRoughness"];
        assert_eq!(pbr["metallicFactor"], 1.0);
        let base = pbr["baseColorFactor"].as_array().unwrap();
        // Gold: red above blue.
        assert!(
            base[0].as_f64().unwrap() > base[2].as_f64().unwrap() + 0.2,
            "{base:?}"
        );
        let back = read(&path).unwrap();
        assert!(back.substrate_ior.at(550.0).im > 0.0);
    }
}
