//! The material stage, between `estimate` and `scene`: a thin film as a fit found it and as
//! scenes and figures use it, in types.
//!
//! - [`FitFile`] (`fit.json`): the fit's numbers, versioned ([`FIT_FORMAT`]).
//! - [`FilmMaterial`]: the film index (a model, dispersion included), the per-pixel thickness
//!   map and the substrate index (a model, its full dispersion included). Read from a fit
//!   folder, a ground truth, `material.xml` or `material.gltf`; written as all of these.
//!
//! Each file format's writer sits beside its reader: [`mitsuba`] (`material.xml`, the
//! `thinfilm` BSDF read back through the scene parser) and [`gltf`] (`material.gltf`,
//! `KHR_materials_iridescence`). Round trips are tested there.

mod fit_file;
pub mod gltf;
pub mod mitsuba;

pub use fit_file::{
    finite, FilmModelFit, FitFile, MapStats, ModelSelectionStep, NoiseFit, NuisanceFit,
    PixelCounts, SubstrateFit, TruthComparison, FIT_FORMAT,
};

use crate::capture::GroundTruth;
use crate::optics::Ior;
use crate::render::bsdf::{thinfilm::ThinFilmBsdf, Bsdf};
use crate::render::texture::{Spectrum, Texture};
use crate::scene::{BitmapTexture, TextureDesc, TextureFilter, WrapMode};
use anyhow::{bail, Context, Result};
use glam::Mat3;
use std::path::Path;
use std::sync::Arc;

/// File names in a fit folder.
pub const FIT_JSON: &str = "fit.json";
pub const THICKNESS_EXR: &str = "thickness.exr";
pub const MATERIAL_XML: &str = "material.xml";
pub const MATERIAL_GLTF: &str = "material.gltf";
/// The 8-bit thickness texture `material.gltf` refers to.
pub const THICKNESS_GLTF_PNG: &str = "thickness_gltf.png";
/// The single channel of `thickness.exr` (so that Mitsuba's `bitmap` reads it); files from
/// older versions named it `thickness`, which is read too.
pub const THICKNESS_CHANNEL: &str = "Y";

/// A thin film with a (possibly spatially varying) thickness map on a substrate.
#[derive(Debug, Clone, PartialEq)]
pub struct FilmMaterial {
    /// Film index model (dispersion included).
    pub film_ior: Ior,
    /// Substrate index model (dispersion and absorption included).
    pub substrate_ior: Ior,
    /// Size of the thickness map, pixels.
    pub width: usize,
    pub height: usize,
    /// Thickness in nm, row-major, top row first; NaN where unknown.
    pub thickness_nm: Vec<f32>,
}

impl FilmMaterial {
    /// Mean of the finite thickness values, nm (NaN if there are none).
    pub fn mean_thickness_nm(&self) -> f64 {
        crate::stats::Summary::of_finite(&self.thickness_nm).map_or(f64::NAN, |s| s.mean)
    }

    /// Film index at 550 nm, for labels.
    pub fn film_ior_550(&self) -> f64 {
        self.film_ior.at(550.0).re
    }

    /// "n 1.370, mean d 408 nm" for panel titles.
    pub fn label(&self) -> String {
        format!(
            "n {:.3}, mean d {:.0} nm",
            self.film_ior_550(),
            self.mean_thickness_nm()
        )
    }

    /// The material of a ground truth written by `thinfilm simulate`.
    pub fn from_ground_truth(gt: &GroundTruth) -> Self {
        FilmMaterial {
            film_ior: gt.film_ior.clone(),
            substrate_ior: gt.substrate_ior.clone(),
            width: gt.width,
            height: gt.height,
            thickness_nm: gt.thickness_nm.clone(),
        }
    }

    /// The fitted material in a `thinfilm estimate` output folder (`fit.json` with the index
    /// models, `thickness.exr`).
    pub fn from_fit_dir(dir: &Path) -> Result<Self> {
        let fit_path = dir.join(FIT_JSON);
        if !fit_path.is_file() {
            bail!(
                "{} does not exist (is {} an estimate output folder?)",
                fit_path.display(),
                dir.display()
            );
        }
        let fit = FitFile::read(&fit_path)?;
        let film_ior = fit
            .film_index()
            .with_context(|| format!("{}", fit_path.display()))?;
        let (width, height, thickness_nm) = read_thickness_exr(&dir.join(THICKNESS_EXR))?;
        if (width, height) != (fit.width, fit.height) {
            bail!(
                "{}: the thickness map is {width}×{height} px but {} says {}×{}",
                dir.join(THICKNESS_EXR).display(),
                fit_path.display(),
                fit.width,
                fit.height
            );
        }
        Ok(FilmMaterial {
            film_ior,
            substrate_ior: fit.substrate,
            width,
            height,
            thickness_nm,
        })
    }

    /// Writes the material files of a fit folder: `thickness.exr`, `material.xml` (whose
    /// comment starts with `note`), `material.gltf` and its `thickness_gltf.png`.
    pub fn write_files(&self, dir: &Path, note: &str) -> Result<()> {
        self.write_files_with_provenance(dir, note, &[])
    }

    /// [`Self::write_files`], with text attributes in `thickness.exr`'s header (a fit's
    /// provenance, which `thinfilm merge` reads to stitch row bands).
    pub fn write_files_with_provenance(
        &self,
        dir: &Path,
        note: &str,
        thickness_attributes: &[(String, String)],
    ) -> Result<()> {
        crate::image_io::write_exr_channels_with_attributes(
            &dir.join(THICKNESS_EXR),
            self.width,
            self.height,
            &[(THICKNESS_CHANNEL, &self.thickness_nm)],
            thickness_attributes,
        )
        .with_context(|| format!("writing {THICKNESS_EXR}"))?;
        let xml = mitsuba::write(self, THICKNESS_EXR, note);
        crate::image_io::write_atomically(&dir.join(MATERIAL_XML), |p| {
            Ok(std::fs::write(p, xml.as_bytes())?)
        })?;
        gltf::write(self, &dir.join(MATERIAL_GLTF), THICKNESS_GLTF_PNG)
    }

    /// The thickness map with NaN texels (pixels the fit could not use) replaced by the
    /// median, so they render as the typical film.
    pub fn filled_thickness_nm(&self) -> Vec<f32> {
        let fill =
            crate::stats::Summary::of_finite(&self.thickness_nm).map_or(0.0, |s| s.median as f32);
        self.thickness_nm
            .iter()
            .map(|&v| if v.is_finite() { v } else { fill })
            .collect()
    }

    /// The `thinfilm` BSDF with the (filled) thickness map as a bilinear, mirrored texture.
    pub fn bsdf(&self) -> Result<Bsdf> {
        let thickness = TextureDesc::Bitmap(Arc::new(BitmapTexture {
            width: self.width,
            height: self.height,
            channels: 1,
            data: self.filled_thickness_nm(),
            filter: TextureFilter::Bilinear,
            wrap: WrapMode::Mirror,
            to_uv: Mat3::IDENTITY,
            value_range: None,
            path: None,
        }));
        let film = ThinFilmBsdf::new(
            self.film_ior.clone(),
            &thickness,
            self.substrate_ior.clone(),
            0.0,
        )?;
        Ok(film.into())
    }

    /// The material of a scene's single-film `thinfilm` BSDF: its indices and its thickness
    /// (a bitmap's texels after its value range, or a constant as a 1×1 map).
    pub fn from_bsdf(bsdf: &Bsdf) -> Result<Self> {
        let Bsdf::ThinFilm(film) = bsdf else {
            bail!("not a single-film thinfilm BSDF: {}", bsdf.describe());
        };
        let (width, height, thickness_nm) = match &film.thickness_nm {
            Texture::Value(Spectrum::Constant(d)) => (1, 1, vec![*d]),
            Texture::Bitmap(b) => {
                let range = |v: f32| match b.value_range {
                    Some((lo, hi)) => lo + v * (hi - lo),
                    None => v,
                };
                let data = b.data.iter().step_by(b.channels).map(|&v| range(v));
                (b.width, b.height, data.collect())
            }
            other => bail!("the film thickness is neither a number nor a bitmap: {other:?}"),
        };
        Ok(FilmMaterial {
            film_ior: film.film_ior.clone(),
            substrate_ior: film.substrate_ior.clone(),
            width,
            height,
            thickness_nm,
        })
    }
}

/// A thickness map: the single channel of `path` named `Y` (or `thickness`, older files).
pub fn read_thickness_exr(path: &Path) -> Result<(usize, usize, Vec<f32>)> {
    let (w, h, channels) = crate::image_io::read_exr_channels(path)?;
    let names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
    let index = names
        .iter()
        .position(|n| *n == THICKNESS_CHANNEL)
        .or_else(|| names.iter().position(|n| *n == "thickness"))
        .with_context(|| {
            format!(
                "{}: no thickness channel (expected '{THICKNESS_CHANNEL}' or 'thickness', found {})",
                path.display(),
                names.join(", ")
            )
        })?;
    let plane = channels.into_iter().nth(index).map(|(_, p)| p);
    Ok((w, h, plane.unwrap_or_default()))
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn example(film: &str, substrate: &str) -> FilmMaterial {
        FilmMaterial {
            film_ior: film.parse().unwrap(),
            substrate_ior: substrate.parse().unwrap(),
            width: 4,
            height: 3,
            thickness_nm: (0..12).map(|i| 380.0 + 5.0 * i as f32).collect(),
        }
    }

    #[test]
    fn nan_texels_are_filled_with_the_median() {
        let mut m = example("1.37", "1.64");
        m.thickness_nm = vec![400.0; 12];
        m.thickness_nm[0] = f32::NAN;
        m.thickness_nm[1] = 500.0;
        let Bsdf::ThinFilm(film) = m.bsdf().unwrap() else {
            panic!("expected a thin film");
        };
        let Texture::Bitmap(tex) = &film.thickness_nm else {
            panic!("expected a bitmap thickness");
        };
        assert_eq!(tex.data[0], 400.0);
        assert_eq!(tex.data[1], 500.0);
        assert!(tex.data.iter().all(|v| v.is_finite()));
        assert!((m.mean_thickness_nm() - (400.0 * 10.0 + 500.0) / 11.0).abs() < 1e-3);
    }

    #[test]
    fn fit_folder_files_read_back_with_full_dispersion() {
        let dir = tempfile::tempdir().unwrap();
        let m = example("cauchy:1.36,3400", "PET");
        m.write_files(dir.path(), "test").unwrap();
        let mut fit: FitFile = serde_json::from_str(&fit_file_example_json()).unwrap();
        fit.film_index = Some(m.film_ior.clone());
        fit.substrate = m.substrate_ior.clone();
        fit.width = m.width;
        fit.height = m.height;
        fit.write(&dir.path().join(FIT_JSON)).unwrap();
        let back = FilmMaterial::from_fit_dir(dir.path()).unwrap();
        assert_eq!(back, m);
        // The wrong size is named.
        fit.width = 5;
        fit.write(&dir.path().join(FIT_JSON)).unwrap();
        let e = format!("{:#}", FilmMaterial::from_fit_dir(dir.path()).unwrap_err());
        assert!(e.contains("4×3") && e.contains("5×3"), "{e}");
        let e = format!(
            "{:#}",
            FilmMaterial::from_fit_dir(&dir.path().join("nope")).unwrap_err()
        );
        assert!(e.contains("estimate output folder"), "{e}");
    }

    /// A minimal valid `fit.json` (tests).
    pub(crate) fn fit_file_example_json() -> String {
        format!(
            r#"{{"format": "{FIT_FORMAT}", "method": "full", "film_ior": 1.37, "film_ior_uncertainty": null,
            "film_ior_note": "", "ambient_ior": 1.0, "substrate_ior": 1.64, "substrate_k": 0.0,
            "substrate": "1.64", "polarization": "s", "incident_deg": [10.0], "bands": 3,
            "width": 1, "height": 1, "thickness_nm": {{"mean": null, "median": null, "p5": null,
            "p95": null, "min": null, "max": null}}, "pixels": {{"valid": 0, "invalid": 0,
            "unfitted": 1}}, "invalid_samples": {{"non_finite": 0, "ignore_value": 0,
            "saturated": 0, "bad_reference": 0}}, "residual_rmse": null,
            "delta_e_ab_d65_mean": null, "seconds": {{}}, "warnings": []}}"#
        )
    }
}
