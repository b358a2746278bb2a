//! `fit.json`: what `thinfilm estimate` found, as a typed, versioned document.
//!
//! The schema is this struct. Adding a field is one line here with `#[serde(default)]` (so
//! files written before it still read) and, if it may be absent or unknown, an `Option` that
//! is written as `null` (JSON has no NaN: non-finite numbers become `null`, see [`finite`]).
//! Readers ignore fields they do not know. [`FIT_FORMAT`] changes only when a field changes
//! meaning or disappears.

use crate::capture::{InvalidCounts, Polarization};
use crate::optics::Ior;
use crate::stats::Summary;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The value of `fit.json`'s `format` field.
pub const FIT_FORMAT: &str = "thinfilm-fit/1";

/// A number, or `None` for NaN and ±∞ (written as `null`).
#[inline]
pub fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// `fit.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitFile {
    /// [`FIT_FORMAT`].
    pub format: String,
    /// Estimation method (`paper`, `full`, `grid`).
    pub method: String,
    /// Film index n at 550 nm; null when no index was found.
    pub film_ior: Option<f64>,
    /// The film's index model with its dispersion, in the index syntax of
    /// [`crate::optics::Ior`] (a number, `n+ki`, a material name, `cauchy:…`, `sellmeier:…`).
    /// Absent in files written before it existed: there `film_ior` is the constant index.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "optional_index"
    )]
    pub film_index: Option<Ior>,
    /// The fitted index model (absent when the index was given): its kind, the 1σ of each
    /// parameter (n(550 nm) first) and, for Cauchy models, A, B (nm²) and C (nm⁴).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub film_model: Option<FilmModelFit>,
    /// Fitted substrate index (when the fit adjusted the capture's substrate).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub substrate_fit: Option<SubstrateFit>,
    /// The nuisance model the data chose (scale, lamp shape, background) and its terms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nuisance: Option<NuisanceFit>,
    /// Noise estimated from the data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseFit>,
    /// Noise-weighted residual per degree of freedom (≈ 1 when the model explains the data).
    #[serde(default)]
    pub chi2_per_dof: Option<f64>,
    /// Every model the selection tried, with its information criterion.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_selection: Vec<ModelSelectionStep>,
    /// Statistics of the per-pixel thickness 1σ map (nm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness_sigma_nm: Option<MapStats>,
    /// The per-pixel thickness 1σ map (EXR, one channel `thickness_sigma`, nm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness_sigma_file: Option<String>,
    /// Pixels whose thickness is not identifiable (less than one fringe in band with an
    /// unknown scale): no thickness is reported there.
    #[serde(default)]
    pub not_identifiable_pixels: usize,
    /// 1σ uncertainty of `film_ior`.
    pub film_ior_uncertainty: Option<f64>,
    /// Why `film_ior_uncertainty` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub film_ior_uncertainty_reason: Option<String>,
    /// How the index was obtained.
    pub film_ior_note: String,
    /// Index of the medium the light arrives from (real).
    pub ambient_ior: Option<f64>,
    /// Substrate n and k at 550 nm (for readers that want numbers).
    pub substrate_ior: Option<f64>,
    pub substrate_k: Option<f64>,
    /// The substrate's index model with its full dispersion, in the index syntax.
    #[serde(with = "index")]
    pub substrate: Ior,
    /// Polarisation the capture observed.
    pub polarization: Polarization,
    /// Incident angles of the capture, degrees.
    pub incident_deg: Vec<Option<f64>>,
    /// Spectral bands of the capture.
    pub bands: usize,
    /// Size of the thickness map, pixels.
    pub width: usize,
    pub height: usize,
    /// Rows `[A, B)` of the capture the map covers, when the fit covered only those
    /// (`thinfilm estimate --rows`); absent: every row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rows: Option<[usize; 2]>,
    /// Statistics of the fitted thickness map (nm).
    pub thickness_nm: MapStats,
    /// Why `thickness_nm` holds nulls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness_nm_reason: Option<String>,
    pub pixels: PixelCounts,
    /// Masked samples (pixel × band × angle) by cause.
    pub invalid_samples: InvalidCounts,
    /// Residual RMSE over every fitted sample (reflectance).
    pub residual_rmse: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_rmse_reason: Option<String>,
    /// Mean ΔE*ab (D65) between measured and model spectra (seed eq. 15).
    pub delta_e_ab_d65_mean: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_e_reason: Option<String>,
    /// Wall-clock seconds per stage, and `total`.
    pub seconds: BTreeMap<String, Option<f64>>,
    /// Where the data contradict the model or the fit is doubtful.
    pub warnings: Vec<String>,
    /// Errors against a ground truth, when one was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<TruthComparison>,
}

/// A fitted film index model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilmModelFit {
    /// `constant`, `cauchy` or `cauchy3`.
    pub model: String,
    /// 1σ of each fitted parameter: n(550 nm), then the dispersion terms.
    pub parameters_sigma: Vec<Option<f64>>,
    /// Cauchy n(λ) = A + B/λ² + C/λ⁴, λ in nm.
    #[serde(default)]
    pub cauchy_a: Option<f64>,
    #[serde(default)]
    pub cauchy_b_nm2: Option<f64>,
    #[serde(default)]
    pub cauchy_c_nm4: Option<f64>,
}

/// A fitted shift of the substrate's real index.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SubstrateFit {
    pub shift: Option<f64>,
    pub shift_sigma: Option<f64>,
    /// Fitted substrate n at 550 nm.
    pub substrate_ior: Option<f64>,
}

/// The nuisance terms of the forward model: a free gain per pixel and angle (not listed),
/// a spectral multiplier per angle (Legendre coefficients beyond the constant) and an
/// additive background per angle (Legendre coefficients, data units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NuisanceFit {
    pub model: String,
    pub multiplier: Vec<Vec<f64>>,
    pub background: Vec<Vec<f64>>,
}

/// The noise the fit weighted by.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseFit {
    /// Typical 1σ per sample (data units).
    pub typical: Option<f64>,
    /// How it was estimated.
    pub source: String,
}

/// One model of the selection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSelectionStep {
    pub model: String,
    /// χ² (noise-weighted residual) on the pixels of the joint fit.
    pub chi2: f64,
    /// Global parameters of the model.
    pub parameters: usize,
    /// Information criterion (lower is better).
    pub criterion: f64,
    /// Kept (the selection moved to it).
    pub chosen: bool,
}

/// Statistics of a map; nulls when it has no finite value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MapStats {
    pub mean: Option<f64>,
    pub median: Option<f64>,
    pub p5: Option<f64>,
    pub p95: Option<f64>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    #[serde(default)]
    pub std: Option<f64>,
}

impl From<Option<Summary>> for MapStats {
    fn from(s: Option<Summary>) -> Self {
        match s {
            None => MapStats::default(),
            Some(s) => MapStats {
                mean: finite(s.mean),
                median: finite(s.median),
                p5: finite(s.p5),
                p95: finite(s.p95),
                min: finite(s.min),
                max: finite(s.max),
                std: finite(s.std),
            },
        }
    }
}

/// Pixel counts of the thickness map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PixelCounts {
    /// Pixels with a fitted thickness.
    pub valid: usize,
    /// Pixels with no usable angle.
    pub invalid: usize,
    /// Pixels with data but no thickness.
    pub unfitted: usize,
}

/// The fit against a known truth (simulated captures).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthComparison {
    pub film_ior: Option<f64>,
    pub film_ior_abs_error: Option<f64>,
    pub mean_thickness_nm: Option<f64>,
    pub thickness_mae_nm: Option<f64>,
    pub thickness_mean_error_nm: Option<f64>,
    pub pixels_compared: usize,
}

impl FitFile {
    /// Reads and checks `fit.json`: errors name the file and the field.
    pub fn read(path: &Path) -> Result<Self> {
        let text = crate::limits::read_text(path, "fit file", 16)?;
        let fit: FitFile = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a valid {FIT_FORMAT} document", path.display()))?;
        if fit.format != FIT_FORMAT {
            bail!(
                "{}: field 'format' is '{}', expected '{FIT_FORMAT}'",
                path.display(),
                fit.format
            );
        }
        Ok(fit)
    }

    /// Writes the file atomically (pretty-printed).
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        crate::image_io::write_atomically(path, |p| Ok(std::fs::write(p, text.as_bytes())?))
    }

    /// The film's index model: `film_index`, else the constant `film_ior` (older files).
    pub fn film_index(&self) -> Result<Ior> {
        match (&self.film_index, self.film_ior) {
            (Some(ior), _) => Ok(ior.clone()),
            (None, Some(n)) => Ok(Ior::real(n)),
            (None, None) => bail!("the fit found no film index (film_ior is null)"),
        }
    }
}

/// An index as its text in the index syntax (round-trips through [`Ior`]'s `FromStr`).
mod index {
    use crate::optics::Ior;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(ior: &Ior, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(ior)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Ior, D::Error> {
        let text = String::deserialize(d)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

mod optional_index {
    use crate::optics::Ior;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(ior: &Option<Ior>, s: S) -> Result<S::Ok, S::Error> {
        match ior {
            Some(ior) => super::index::serialize(ior, s),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Ior>, D::Error> {
        Option::<String>::deserialize(d)?
            .map(|t| t.parse().map_err(serde::de::Error::custom))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> FitFile {
        FitFile {
            format: FIT_FORMAT.into(),
            method: "full".into(),
            film_ior: Some(1.37),
            film_index: Some("cauchy:1.36,3400".parse().unwrap()),
            film_model: None,
            substrate_fit: None,
            nuisance: None,
            noise: None,
            chi2_per_dof: None,
            model_selection: Vec::new(),
            thickness_sigma_nm: None,
            thickness_sigma_file: None,
            not_identifiable_pixels: 0,
            film_ior_uncertainty: None,
            film_ior_uncertainty_reason: Some("index given by the user".into()),
            film_ior_note: "given".into(),
            ambient_ior: Some(1.0),
            substrate_ior: Some(1.57),
            substrate_k: Some(0.0),
            substrate: "PET".parse().unwrap(),
            polarization: Polarization::S,
            incident_deg: vec![Some(10.0), Some(30.0)],
            bands: 81,
            width: 4,
            height: 3,
            rows: None,
            thickness_nm: MapStats::from(Summary::of_finite(&[400.0, 410.0])),
            thickness_nm_reason: None,
            pixels: PixelCounts {
                valid: 12,
                invalid: 0,
                unfitted: 0,
            },
            invalid_samples: InvalidCounts::default(),
            residual_rmse: Some(0.004),
            residual_rmse_reason: None,
            delta_e_ab_d65_mean: None,
            delta_e_reason: Some("no fitted pixel".into()),
            seconds: [("total".to_string(), Some(0.5))].into(),
            warnings: vec!["a warning".into()],
            ground_truth: None,
        }
    }

    #[test]
    fn round_trips_with_dispersive_indices() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fit.json");
        let fit = example();
        fit.write(&path).unwrap();
        let back = FitFile::read(&path).unwrap();
        assert_eq!(back, fit);
        let n = back.film_index().unwrap();
        assert!(n.is_dispersive());
        assert!((n.at(550.0).re - (1.36 + 3400.0 / 550f64.powi(2))).abs() < 1e-12);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"substrate\": \"PET\"") && !text.contains("NaN"));
    }

    #[test]
    fn older_files_without_the_index_model_still_read() {
        let mut v = serde_json::to_value(example()).unwrap();
        v.as_object_mut().unwrap().remove("film_index");
        v.as_object_mut()
            .unwrap()
            .insert("added_later".into(), 1.into());
        let fit: FitFile = serde_json::from_value(v).unwrap();
        assert_eq!(fit.film_index().unwrap(), Ior::real(1.37));
    }

    #[test]
    fn bad_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fit.json");
        let mut v = serde_json::to_value(example()).unwrap();
        v["format"] = "thinfilm-fit/9".into();
        std::fs::write(&path, v.to_string()).unwrap();
        let e = format!("{:#}", FitFile::read(&path).unwrap_err());
        assert!(
            e.contains("fit.json") && e.contains("thinfilm-fit/9"),
            "{e}"
        );
        v["format"] = FIT_FORMAT.into();
        v["substrate"] = "unobtainium".into();
        std::fs::write(&path, v.to_string()).unwrap();
        let e = format!("{:#}", FitFile::read(&path).unwrap_err());
        assert!(e.contains("unobtainium"), "{e}");
    }
}
