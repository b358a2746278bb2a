//! Hyperspectral captures: ENVI cubes, capture sets (`capture.json`) and the capture
//! simulator. Knows nothing of rays or fitting.
//!
//! CONTRACT (the estimator codes against these types; bodies filled by the capture work).

use crate::optics::Ior;
use std::path::Path;

/// Polarisation state the camera observed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarization {
    S,
    P,
    Unpolarized,
}

/// Reflectance cube at one incident angle, in memory as band-interleaved-by-pixel f32:
/// `reflectance[(y * width + x) * bands + b]`. Invalid samples are NaN.
#[derive(Debug, Clone)]
pub struct AngleCapture {
    pub incident_deg: f64,
    pub reflectance: Vec<f32>,
    /// Per pixel: every band finite and usable.
    pub valid: Vec<bool>,
}

/// A loaded capture set: every angle shares wavelengths and size.
#[derive(Debug, Clone)]
pub struct CaptureSet {
    pub polarization: Polarization,
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
}

/// Masked samples (pixel × band × angle) by cause.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct InvalidCounts {
    pub non_finite: u64,
    pub ignore_value: u64,
    pub saturated: u64,
    pub bad_reference: u64,
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
pub fn load_capture_set(dir: &Path) -> anyhow::Result<CaptureSet> {
    let _ = dir;
    todo!("capture work")
}

/// Loads `dir/ground_truth.json` + `dir/thickness.exr` (`dir` is the `ground_truth` folder
/// or the capture folder that contains it).
pub fn load_ground_truth(dir: &Path) -> anyhow::Result<GroundTruth> {
    let _ = dir;
    todo!("capture work")
}
