//! Hyperspectral captures: ENVI cubes, capture sets (`capture.json`) and the capture
//! simulator. Knows nothing of rays or fitting.
//!
//! CONTRACT (the estimator codes against these types).
//!
//! - [`envi`]: ENVI header + binary reader (memory-mapped) and writer;
//! - `set`: `capture.json` (format `thinfilm-capture/1`) → [`CaptureSet`], ground truth;
//! - [`simulate`]: a synthetic camera (Airy film, Gaussian band response, noise, raw counts).

use crate::optics::Ior;
use std::path::Path;

pub mod envi;
mod rng;
mod samples;
mod set;
pub mod simulate;
pub mod spectra;

pub use samples::Samples;

/// Polarisation state the camera observed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarization {
    S,
    P,
    #[serde(alias = "unpolarised")]
    Unpolarized,
}

impl std::str::FromStr for Polarization {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "s" => Ok(Polarization::S),
            "p" => Ok(Polarization::P),
            "unpolarized" | "unpolarised" | "u" => Ok(Polarization::Unpolarized),
            other => Err(format!(
                "unknown polarization '{other}' (expected s, p or unpolarized)"
            )),
        }
    }
}

impl Polarization {
    /// The reflectance this camera sees from a film response.
    pub fn reflectance(self, r: &crate::optics::FilmResponse) -> f64 {
        match self {
            Polarization::S => r.r_s,
            Polarization::P => r.r_p,
            Polarization::Unpolarized => r.r(),
        }
    }
}

/// Reflectance cube at one incident angle, in memory as band-interleaved-by-pixel f32:
/// `reflectance[(y * width + x) * bands + b]`. Invalid samples are NaN.
#[derive(Debug, Clone)]
pub struct AngleCapture {
    /// Nominal incident angle (the angle of the whole cube when there is no map).
    pub incident_deg: f64,
    /// Per-pixel incident angle in degrees (row-major; NaN = unknown), when the capture
    /// gives an angle map or the geometry.
    pub incident_deg_map: Option<Vec<f32>>,
    /// In memory, or the cube file itself when it has this layout ([`Samples`]).
    pub reflectance: Samples,
    /// Per pixel: every band finite and usable.
    pub valid: Vec<bool>,
}

impl AngleCapture {
    /// A cube of BIP reflectance with `bands` bands; a pixel is valid when all its bands
    /// are finite.
    pub fn from_bip(incident_deg: f64, reflectance: Vec<f32>, bands: usize) -> Self {
        let valid = reflectance
            .chunks(bands.max(1))
            .map(|px| px.iter().all(|v| v.is_finite()))
            .collect();
        AngleCapture {
            incident_deg,
            incident_deg_map: None,
            reflectance: reflectance.into(),
            valid,
        }
    }

    /// Copies the `out.len()` bands of pixel `p` into `out`; false when the pixel is not
    /// usable at this angle (`out` is then untouched, or holds its non-finite samples).
    #[inline]
    pub fn pixel(&self, p: usize, out: &mut [f32]) -> bool {
        if !self.valid.get(p).copied().unwrap_or(false) {
            return false;
        }
        self.reflectance.pixel(p, out);
        out.iter().all(|v| v.is_finite())
    }
}

/// What the capture's values are relative to.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Radiometry {
    /// Values are proportional to reflectance with an unknown scale per pixel and angle
    /// (a diffuse white reference does not calibrate a specular reflection; raw counts).
    #[default]
    Relative,
    /// Values are calibrated reflectance: the fit may use their amplitude.
    Absolute,
}

/// A loaded capture set: every angle shares wavelengths and size.
#[derive(Debug, Clone)]
pub struct CaptureSet {
    pub polarization: Polarization,
    /// `"radiometry"` of capture.json (default relative).
    pub radiometry: Radiometry,
    /// `"film_model"` of capture.json: the film index model to fit, when given.
    pub film_model: Option<crate::estimate::film::FilmModelKind>,
    /// Names of the pixels when they are independent point spectra (one file, one
    /// pixel): no spatial neighbourhood between them.
    pub pixel_names: Option<Vec<String>>,
    pub ambient_ior: f64,
    pub substrate_ior: Ior,
    pub wavelengths_nm: Vec<f64>,
    /// Band FWHM in nm when the headers give it (Gaussian band response).
    pub fwhm_nm: Option<Vec<f64>>,
    pub width: usize,
    pub height: usize,
    pub angles: Vec<AngleCapture>,
    /// Counts of masked samples by cause, for reporting.
    pub invalid: InvalidCounts,
}

impl CaptureSet {
    pub fn bands(&self) -> usize {
        self.wavelengths_nm.len()
    }

    /// Rows `[a, b)` as a capture of their own (a band fitted by itself).
    pub fn rows(&self, a: usize, b: usize) -> CaptureSet {
        let (w, nb) = (self.width, self.bands());
        let px = a * w..b * w;
        let angles = self
            .angles
            .iter()
            .map(|ang| AngleCapture {
                incident_deg: ang.incident_deg,
                incident_deg_map: ang
                    .incident_deg_map
                    .as_ref()
                    .map(|m| m[px.clone()].to_vec()),
                reflectance: ang.reflectance.pixels_to_vec(px.clone(), nb).into(),
                valid: ang.valid[px.clone()].to_vec(),
            })
            .collect();
        CaptureSet {
            pixel_names: self.pixel_names.as_ref().map(|n| n[px.clone()].to_vec()),
            substrate_ior: self.substrate_ior.clone(),
            wavelengths_nm: self.wavelengths_nm.clone(),
            fwhm_nm: self.fwhm_nm.clone(),
            height: b - a,
            angles,
            ..*self
        }
    }
}

/// Masked samples (pixel × band × angle) by cause.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InvalidCounts {
    pub non_finite: u64,
    pub ignore_value: u64,
    pub saturated: u64,
    pub bad_reference: u64,
}

impl InvalidCounts {
    pub fn total(&self) -> u64 {
        self.non_finite + self.ignore_value + self.saturated + self.bad_reference
    }

    /// The counter of `cause`.
    pub(crate) fn of(&mut self, cause: Cause) -> &mut u64 {
        match cause {
            Cause::NonFinite => &mut self.non_finite,
            Cause::IgnoreValue => &mut self.ignore_value,
            Cause::Saturated => &mut self.saturated,
        }
    }

    pub fn add(&mut self, o: &InvalidCounts) {
        self.non_finite += o.non_finite;
        self.ignore_value += o.ignore_value;
        self.saturated += o.saturated;
        self.bad_reference += o.bad_reference;
    }
}

/// Why a raw sample was masked (the causes found before calibration).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cause {
    NonFinite,
    IgnoreValue,
    Saturated,
}

/// Ground truth written by `thinfilm simulate` in `DIR/ground_truth/`.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    pub film_ior: Ior,
    pub substrate_ior: Ior,
    pub width: usize,
    pub height: usize,
    /// Per-pixel thickness, nm, row-major.
    pub thickness_nm: Vec<f32>,
}

/// Loads `dir/capture.json` and its cubes.
/// `dir` may also be the path of the `capture.json` itself.
pub fn load_capture_set(dir: &Path) -> anyhow::Result<CaptureSet> {
    crate::limits::contain_panics(dir, || set::load_capture_set(dir))
}

/// Loads `dir/ground_truth.json` + `dir/thickness.exr` (`dir` is the `ground_truth` folder
/// or the capture folder that contains it).
pub fn load_ground_truth(dir: &Path) -> anyhow::Result<GroundTruth> {
    crate::limits::contain_panics(dir, || set::load_ground_truth(dir))
}
