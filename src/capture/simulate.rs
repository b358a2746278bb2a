//! A synthetic hyperspectral camera looking at a thin film (the seed paper's setup):
//! one ENVI cube per incident angle plus `capture.json`, and the ground truth
//! (`ground_truth/ground_truth.json`, `ground_truth/thickness.exr`).
//!
//! Physics: the Airy film of [`crate::optics::ThinFilm`] (f64), seen through a Gaussian
//! band response of full width `fwhm_nm` that is *integrated* (Simpson quadrature over
//! ±4σ, finer than the local fringe period), not point-sampled. `fwhm_nm = 0` samples the
//! band centre.
//!
//! Thickness: d(x, y) = d0 · (1 + v · f(x, y)), with f a smooth zero-mean field in
//! [−1, 1] (a few low-frequency plane waves plus Gaussian bumps drawn from the seed,
//! shifted to zero mean and scaled so max |f| = 1): the seed paper's assumption that thickness varies slowly over the
//! surface.
//!
//! Speed: for big images the band reflectance is tabulated against thickness on a grid
//! of ≥ 256 nodes per interference period and read back with Catmull–Rom interpolation
//! (error < 1e-6 in reflectance, tested); images with fewer pixels than table nodes are
//! evaluated directly.
//!
//! Noise: `noise_sigma` adds Gaussian noise in reflectance units. In raw-counts mode the
//! camera records uint16 counts: raw = Poisson(R·S(λ)) + dark + read noise, with a
//! smooth white-signal spectrum S peaking at `white_counts`, plus white and dark
//! reference cubes recorded the same way (so R = (raw − dark)/(white − dark) recovers
//! the reflectance within shot noise). Randomness: an in-module SplitMix64 stream per
//! (angle, row), so output is identical for any thread count.
//!
//! Realism ([`Realism`], all off by default — an ideal capture is written with
//! `"radiometry": "absolute"`): what a real capture does to the calibrated reflectance R,
//!
//!   measured = e_a · v(x, y) · (1 + t_a x_λ) · R(θ_a(x)) + c_a  (+ noise),
//!
//! with e_a the exposure of angle a (uniform in 1 ± `exposure_variation`), v a radial
//! vignetting falling to `vignetting_min` in the corners, t_a a lamp tilt across the band
//! (x_λ ∈ [−1, 1], t_a uniform in ±`lamp_tilt`: the lamp drifted after the white
//! reference), c_a stray light uniform in [0, `background`], and θ_a(x) the incidence
//! varying by ±`fov_half_deg` across the image (a camera's field of view). A substrate
//! index error writes `substrate_ior + substrate_error` into capture.json. Every drawn
//! value is recorded in the ground truth. With any of the first four, capture.json says
//! `"radiometry": "relative"`.

use super::envi::{self, DataType, Interleave, WriteOptions};
use super::rng::SplitMix64;
use super::set::{ior_to_json, AngleEntry, CaptureFile, CAPTURE_FORMAT, GROUND_TRUTH_FORMAT};
use super::Polarization;
use crate::optics::{Ior, ThinFilm};
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde_json::{json, Value};
use std::path::Path;

/// Everything the simulator needs. `Default` is the seed paper's Sample 1.
#[derive(Debug, Clone)]
pub struct SimulateConfig {
    pub film_ior: Ior,
    /// Mean (nominal) film thickness d0, nm.
    pub thickness_nm: f64,
    /// Relative amplitude v of the smooth thickness field, 0 ≤ v ≤ 1.
    pub thickness_variation: f64,
    pub substrate_ior: Ior,
    pub ambient_ior: f64,
    pub angles_deg: Vec<f64>,
    pub wavelengths_nm: Vec<f64>,
    /// Gaussian band FWHM, nm; 0 = point sampling at the band centre.
    pub fwhm_nm: f64,
    /// Additive Gaussian noise, reflectance units (raw mode: scaled by the white signal).
    pub noise_sigma: f64,
    /// Write uint16 counts with white and dark references instead of float reflectance.
    pub raw_counts: bool,
    /// Raw mode: white-reference signal at the peak of the light × sensor spectrum, counts.
    pub white_counts: f64,
    /// Raw mode: dark level, counts.
    pub dark_counts: f64,
    /// Raw mode: Gaussian read noise, counts.
    pub read_noise: f64,
    pub polarization: Polarization,
    pub width: usize,
    pub height: usize,
    pub seed: u64,
    pub interleave: Interleave,
    /// The preset this configuration started from (recorded in the ground truth).
    pub preset: Option<String>,
    /// Effects of a real capture (see the module doc).
    pub realism: Realism,
    /// Show a progress bar (CLI only).
    pub progress: bool,
}

impl Default for SimulateConfig {
    fn default() -> Self {
        SimulateConfig {
            film_ior: Ior::real(1.37),
            thickness_nm: 400.0,
            thickness_variation: 0.05,
            substrate_ior: Ior::real(1.64),
            ambient_ior: 1.0,
            angles_deg: vec![10.0, 20.0, 30.0, 40.0, 50.0],
            wavelengths_nm: parse_wavelengths("400:720:4").expect("valid default"),
            fwhm_nm: 4.0,
            noise_sigma: 0.0,
            raw_counts: false,
            white_counts: 40_000.0,
            dark_counts: 800.0,
            read_noise: 3.0,
            polarization: Polarization::S,
            width: 64,
            height: 64,
            seed: 1,
            interleave: Interleave::Bsq,
            preset: None,
            realism: Realism::default(),
            progress: false,
        }
    }
}

/// Effects of a real capture on the calibrated reflectance (module doc). `Default`: none.
#[derive(Debug, Clone, PartialEq)]
pub struct Realism {
    /// Exposure of each angle drawn in [1 − v, 1 + v].
    pub exposure_variation: f64,
    /// Vignetting gain in the image corners (1 = none); radial falloff 1 − (1 − v) r².
    pub vignetting_min: f64,
    /// Lamp tilt across the band per angle, drawn in [−v, v].
    pub lamp_tilt: f64,
    /// Additive stray light per angle drawn in [0, v], reflectance units.
    pub background: f64,
    /// Added to the substrate index written into capture.json (the truth is unchanged).
    pub substrate_error: f64,
    /// Incidence changes by ±this across the image width, degrees.
    pub fov_half_deg: f64,
    /// Write the per-pixel incidence as one EXR per angle and name it in capture.json.
    pub write_angle_maps: bool,
}

impl Default for Realism {
    fn default() -> Self {
        Realism {
            exposure_variation: 0.0,
            vignetting_min: 1.0,
            lamp_tilt: 0.0,
            background: 0.0,
            substrate_error: 0.0,
            fov_half_deg: 0.0,
            write_angle_maps: false,
        }
    }
}

impl Realism {
    /// True when the values are no longer calibrated reflectance.
    pub fn relative(&self) -> bool {
        self.exposure_variation > 0.0
            || self.vignetting_min < 1.0
            || self.lamp_tilt > 0.0
            || self.background > 0.0
    }

    fn validate(&self) -> Result<()> {
        let ok = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        if !ok(self.exposure_variation, 0.0, 0.95) {
            bail!(
                "exposure variation must be in [0, 0.95], got {}",
                self.exposure_variation
            );
        }
        if !ok(self.vignetting_min, 0.01, 1.0) {
            bail!(
                "vignetting minimum must be in [0.01, 1], got {}",
                self.vignetting_min
            );
        }
        if !ok(self.lamp_tilt, 0.0, 0.9) {
            bail!("lamp tilt must be in [0, 0.9], got {}", self.lamp_tilt);
        }
        if !ok(self.background, 0.0, 1.0) {
            bail!("background must be in [0, 1], got {}", self.background);
        }
        if !self.substrate_error.is_finite() {
            bail!("substrate error must be finite");
        }
        if !ok(self.fov_half_deg, 0.0, 30.0) {
            bail!(
                "field of view half-angle must be in [0°, 30°], got {}",
                self.fov_half_deg
            );
        }
        Ok(())
    }
}

/// The values drawn for one capture (recorded in the ground truth).
#[derive(Debug, Clone, PartialEq)]
pub struct Effects {
    pub exposure: Vec<f64>,
    pub lamp_tilt: Vec<f64>,
    pub background: Vec<f64>,
}

impl SimulateConfig {
    /// Per-angle exposure, tilt and background, from the seed (all neutral without realism).
    pub fn effects(&self) -> Effects {
        let r = &self.realism;
        let mut rng = SplitMix64::stream(self.seed, u64::MAX - 1, 0, 3);
        let mut e = Effects {
            exposure: Vec::new(),
            lamp_tilt: Vec::new(),
            background: Vec::new(),
        };
        for _ in &self.angles_deg {
            e.exposure
                .push(1.0 + r.exposure_variation * (2.0 * rng.uniform() - 1.0));
            e.lamp_tilt.push(r.lamp_tilt * (2.0 * rng.uniform() - 1.0));
            e.background.push(r.background * rng.uniform());
        }
        e
    }

    /// Vignetting gain of pixel (x, y): 1 − (1 − v) r², r = 1 in the corners.
    pub fn vignetting(&self, x: usize, y: usize) -> f64 {
        let v = self.realism.vignetting_min;
        let u = 2.0 * (x as f64 + 0.5) / self.width as f64 - 1.0;
        let w = 2.0 * (y as f64 + 0.5) / self.height as f64 - 1.0;
        1.0 - (1.0 - v) * (u * u + w * w) / 2.0
    }

    /// Incidence of column x at angle index a, degrees.
    pub fn incident_deg_at(&self, a: usize, x: usize) -> f64 {
        let f = self.realism.fov_half_deg;
        let u = 2.0 * (x as f64 + 0.5) / self.width as f64 - 1.0;
        (self.angles_deg[a] + f * u).clamp(0.0, 89.9)
    }

    /// The substrate index capture.json states.
    pub fn stated_substrate(&self) -> Ior {
        let e = self.realism.substrate_error;
        if e == 0.0 {
            return self.substrate_ior.clone();
        }
        match &self.substrate_ior {
            Ior::Constant(c) => Ior::Constant(crate::optics::Complex64::new(c.re + e, c.im)),
            // A material with an error: the nearest constant (at 550 nm) plus the error.
            Ior::Material(m) => {
                let c = m.nk(550.0);
                Ior::Constant(crate::optics::Complex64::new(c.re + e, c.im))
            }
        }
    }
}

impl SimulateConfig {
    /// The seed paper's samples (§5): MgF2 (1.37) 400 nm, MgF2 600 nm, ZnS (2.37) 500 nm,
    /// evaporated on PET (n ≈ 1.64), S-polarised, 10–50° in 10° steps, 4 nm bands 400–720 nm.
    pub fn preset(name: &str) -> Result<Self> {
        let (n, d) = match name.to_ascii_lowercase().as_str() {
            "sample1" => (1.37, 400.0),
            "sample2" => (1.37, 600.0),
            "sample3" => (2.37, 500.0),
            other => bail!("unknown preset '{other}' (sample1, sample2 or sample3)"),
        };
        Ok(SimulateConfig {
            film_ior: Ior::real(n),
            thickness_nm: d,
            preset: Some(name.to_ascii_lowercase()),
            ..SimulateConfig::default()
        })
    }

    /// Rejects configurations that would produce NaN or nonsense.
    pub fn validate(&self) -> Result<()> {
        use crate::limits::{check_alloc, check_range, size_product, MAX_THICKNESS_NM};
        check_range("thickness (nm)", self.thickness_nm, 0.0, MAX_THICKNESS_NM)?;
        check_range("ambient index", self.ambient_ior, 1.0, 3.0)?;
        check_range("noise sigma", self.noise_sigma, 0.0, 10.0)?;
        if let Some(i) =
            (1..self.angles_deg.len()).find(|&i| self.angles_deg[..i].contains(&self.angles_deg[i]))
        {
            bail!("incident angle {}° is given twice", self.angles_deg[i]);
        }
        // Spectrometers have a few hundred bands; the simulation's cost grows with each.
        if self.wavelengths_nm.len() > 2048 || self.angles_deg.len() > 64 {
            bail!(
                "{} wavelengths and {} angles: at most 2048 wavelengths and 64 angles",
                self.wavelengths_nm.len(),
                self.angles_deg.len()
            );
        }
        // One angle's cube is in memory at a time (f32 plus its encoded copy ≤ 8 bytes).
        let samples = size_product(
            "image size",
            &[
                ("width", self.width as u64),
                ("height", self.height as u64),
                ("bands", self.wavelengths_nm.len() as u64),
            ],
        )?;
        check_alloc(
            format!(
                "image size {}×{} with {} bands",
                self.width,
                self.height,
                self.wavelengths_nm.len()
            ),
            samples.saturating_mul(12),
        )?;
        if !(0.0..=1.0).contains(&self.thickness_variation) {
            bail!(
                "thickness variation must be a fraction in [0, 1], got {}",
                self.thickness_variation
            );
        }
        if self.angles_deg.is_empty() {
            bail!("no incident angles");
        }
        if let Some(a) = self
            .angles_deg
            .iter()
            .find(|a| !(a.is_finite() && (0.0..90.0).contains(*a)))
        {
            bail!("incident angle {a}° is outside [0°, 90°)");
        }
        if self.wavelengths_nm.is_empty() {
            bail!("no wavelengths");
        }
        if let Some(w) = self
            .wavelengths_nm
            .iter()
            .find(|w| !(w.is_finite() && **w > 0.0))
        {
            bail!("wavelength {w} nm must be finite and > 0");
        }
        if !(self.fwhm_nm.is_finite() && self.fwhm_nm >= 0.0) {
            bail!("fwhm must be finite and ≥ 0 nm, got {}", self.fwhm_nm);
        }
        if let Some(w) = self.wavelengths_nm.first() {
            if self.fwhm_nm > 0.0 && w - 4.0 * sigma_of(self.fwhm_nm) <= 0.0 {
                bail!(
                    "fwhm {} nm is too wide for the band at {w} nm",
                    self.fwhm_nm
                );
            }
        }
        if !(self.noise_sigma.is_finite() && self.noise_sigma >= 0.0) {
            bail!(
                "noise sigma must be finite and ≥ 0, got {}",
                self.noise_sigma
            );
        }
        if self.width == 0 || self.height == 0 {
            bail!(
                "image size must be at least 1×1, got {}×{}",
                self.width,
                self.height
            );
        }
        if self.raw_counts {
            let top = self.white_counts + self.dark_counts;
            if !(self.white_counts > 0.0 && self.dark_counts >= 0.0 && top < u16::MAX as f64) {
                bail!(
                    "raw counts: white ({}) must be > 0 and white + dark ({top}) below 65535",
                    self.white_counts
                );
            }
            if !(self.read_noise.is_finite() && (0.0..=65535.0).contains(&self.read_noise)) {
                bail!(
                    "read noise must be in [0, 65535] counts, got {}",
                    self.read_noise
                );
            }
        }
        self.realism.validate()?;
        for (what, ior) in [("film", &self.film_ior), ("substrate", &self.substrate_ior)] {
            crate::limits::check_index(format!("{what} index"), ior)?;
            let film = ThinFilm {
                ambient_ior: self.ambient_ior,
                film_ior: ior.at(self.wavelengths_nm[0]),
                thickness_nm: self.thickness_nm,
                substrate_ior: ior.at(self.wavelengths_nm[0]),
            };
            film.validate()
                .with_context(|| format!("{what} index {ior}"))?;
        }
        Ok(())
    }

    /// Every option, for `ground_truth.json`.
    pub fn to_json(&self) -> Value {
        json!({
            "preset": self.preset,
            "film": ior_to_json(&self.film_ior),
            "thickness_nm": self.thickness_nm,
            "thickness_variation": self.thickness_variation,
            "substrate": ior_to_json(&self.substrate_ior),
            "ambient_ior": self.ambient_ior,
            "angles_deg": self.angles_deg,
            "wavelengths_nm": self.wavelengths_nm,
            "fwhm_nm": self.fwhm_nm,
            "noise_sigma": self.noise_sigma,
            "raw_counts": self.raw_counts,
            "white_counts": self.white_counts,
            "dark_counts": self.dark_counts,
            "read_noise": self.read_noise,
            "polarization": self.polarization,
            "width": self.width,
            "height": self.height,
            "seed": self.seed,
            "interleave": self.interleave,
            "realism": {
                "exposure_variation": self.realism.exposure_variation,
                "vignetting_min": self.realism.vignetting_min,
                "lamp_tilt": self.realism.lamp_tilt,
                "background": self.realism.background,
                "substrate_error": self.realism.substrate_error,
                "fov_half_deg": self.realism.fov_half_deg,
                "write_angle_maps": self.realism.write_angle_maps,
            },
        })
    }
}

/// Parses `START:END:STEP` (inclusive of END when it lies on the grid) or a comma list.
pub fn parse_wavelengths(s: &str) -> Result<Vec<f64>> {
    let parts: Vec<&str> = s.split(':').map(str::trim).collect();
    let num = |t: &str| -> Result<f64> {
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("wavelengths '{s}': '{t}' is not a number"))
    };
    let out = match parts.as_slice() {
        [a, b, step] => {
            let (a, b, step) = (num(a)?, num(b)?, num(step)?);
            if !(step > 0.0 && b >= a) {
                bail!("wavelengths '{s}': need START ≤ END and STEP > 0");
            }
            let n = ((b - a) / step + 1e-9).floor() as usize + 1;
            if n > 100_000 {
                bail!("wavelengths '{s}': {n} bands is too many");
            }
            (0..n).map(|i| a + i as f64 * step).collect()
        }
        [_] => s
            .split(',')
            .map(|t| num(t.trim()))
            .collect::<Result<Vec<_>>>()?,
        _ => bail!("wavelengths '{s}': expected START:END:STEP or a comma list"),
    };
    if out.iter().any(|&w| w <= 0.0) {
        bail!("wavelengths '{s}': every wavelength must be > 0 nm");
    }
    if out.windows(2).any(|p| p[1] <= p[0]) {
        bail!("wavelengths '{s}': must be strictly increasing");
    }
    Ok(out)
}

/// Parses a comma list of angles in degrees.
pub fn parse_angles(s: &str) -> Result<Vec<f64>> {
    s.split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|a| a.is_finite() && (0.0..90.0).contains(a))
                .with_context(|| format!("angles '{s}': '{}' is not an angle in [0, 90)", t.trim()))
        })
        .collect()
}

fn sigma_of(fwhm_nm: f64) -> f64 {
    fwhm_nm / (2.0 * (2.0 * std::f64::consts::LN_2).sqrt())
}

/// Quadrature nodes `(λ, weight)` (weights sum to 1) of one band's Gaussian response.
/// `fringe_nm` is the shortest interference period in wavelength the band must resolve.
pub fn band_nodes(center_nm: f64, fwhm_nm: f64, fringe_nm: f64) -> Vec<(f64, f64)> {
    if fwhm_nm <= 0.0 {
        return vec![(center_nm, 1.0)];
    }
    let sigma = sigma_of(fwhm_nm);
    let half = 4.0 * sigma;
    // ≥ 32 intervals over ±4σ, and ≥ 16 per fringe; even count for Simpson.
    let h_max = (2.0 * half / 32.0).min(fringe_nm / 16.0);
    let mut intervals = ((2.0 * half / h_max).ceil() as usize).clamp(32, 8000);
    intervals += intervals % 2;
    let h = 2.0 * half / intervals as f64;
    let mut nodes: Vec<(f64, f64)> = (0..=intervals)
        .map(|i| {
            let x = -half + i as f64 * h;
            let simpson = if i == 0 || i == intervals {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            (center_nm + x, simpson * (-0.5 * (x / sigma).powi(2)).exp())
        })
        .collect();
    let total: f64 = nodes.iter().map(|n| n.1).sum();
    for n in &mut nodes {
        n.1 /= total;
    }
    nodes
}

/// Interference period in wavelength near λ for thickness d: Δλ ≈ λ² / (2 n2 d cosθ2)
/// (seed eq. 8 differentiated); taking cosθ2 = 1 gives the shortest (safe) period.
fn fringe_period_nm(lambda_nm: f64, film_n: f64, thickness_nm: f64) -> f64 {
    let opd = 2.0 * film_n.max(1e-6) * thickness_nm;
    if opd <= 0.0 {
        f64::INFINITY
    } else {
        lambda_nm * lambda_nm / opd
    }
}

/// The camera's band response model for one configuration (nodes for every band).
#[derive(Debug, Clone)]
pub struct BandModel {
    /// Per band: quadrature nodes (λ, weight).
    pub nodes: Vec<Vec<(f64, f64)>>,
    film_ior: Ior,
    substrate_ior: Ior,
    ambient_ior: f64,
    polarization: Polarization,
}

impl BandModel {
    /// Nodes fine enough for every thickness up to `max_thickness_nm`.
    pub fn new(cfg: &SimulateConfig, max_thickness_nm: f64) -> Self {
        let nodes = cfg
            .wavelengths_nm
            .iter()
            .map(|&c| {
                let n = cfg.film_ior.at(c).re;
                band_nodes(c, cfg.fwhm_nm, fringe_period_nm(c, n, max_thickness_nm))
            })
            .collect();
        BandModel {
            nodes,
            film_ior: cfg.film_ior.clone(),
            substrate_ior: cfg.substrate_ior.clone(),
            ambient_ior: cfg.ambient_ior,
            polarization: cfg.polarization,
        }
    }

    /// Band-integrated reflectance of band `b` at thickness d and angle θ (cos given).
    pub fn reflectance(&self, b: usize, thickness_nm: f64, cos_theta: f64) -> f64 {
        self.nodes[b]
            .iter()
            .map(|&(lambda, w)| {
                let film = ThinFilm {
                    ambient_ior: self.ambient_ior,
                    film_ior: self.film_ior.at(lambda),
                    thickness_nm,
                    substrate_ior: self.substrate_ior.at(lambda),
                };
                w * self
                    .polarization
                    .reflectance(&film.response(lambda, cos_theta))
            })
            .sum()
    }

    /// All bands at once.
    pub fn spectrum(&self, thickness_nm: f64, cos_theta: f64, out: &mut [f64]) {
        for (b, o) in out.iter_mut().enumerate() {
            *o = self.reflectance(b, thickness_nm, cos_theta);
        }
    }
}

/// Band reflectance against thickness for one angle, on a uniform grid, read back by
/// Catmull–Rom interpolation.
struct ThicknessTable {
    d0: f64,
    step: f64,
    nodes: usize,
    bands: usize,
    /// `values[node * bands + b]`
    values: Vec<f64>,
}

impl ThicknessTable {
    fn new(
        model: &BandModel,
        cos_theta: f64,
        d_lo: f64,
        d_hi: f64,
        step: f64,
        bands: usize,
    ) -> Self {
        // One node of padding below and two above for the 4-point stencil.
        let d0 = d_lo - step;
        let nodes = ((d_hi - d_lo) / step).ceil() as usize + 4;
        let mut values = vec![0.0; nodes * bands];
        values
            .par_chunks_mut(bands)
            .enumerate()
            .for_each(|(i, row)| {
                model.spectrum(d0 + i as f64 * step, cos_theta, row);
            });
        ThicknessTable {
            d0,
            step,
            nodes,
            bands,
            values,
        }
    }

    fn spectrum(&self, d: f64, out: &mut [f64]) {
        let u = (d - self.d0) / self.step;
        let i = (u.floor() as usize).clamp(1, self.nodes - 3);
        let t = u - i as f64;
        let row = |k: usize| &self.values[k * self.bands..(k + 1) * self.bands];
        let (p0, p1, p2, p3) = (row(i - 1), row(i), row(i + 1), row(i + 2));
        let (t2, t3) = (t * t, t * t * t);
        for b in 0..self.bands {
            out[b] = 0.5
                * (2.0 * p1[b]
                    + (p2[b] - p0[b]) * t
                    + (2.0 * p0[b] - 5.0 * p1[b] + 4.0 * p2[b] - p3[b]) * t2
                    + (3.0 * p1[b] - p0[b] - 3.0 * p2[b] + p3[b]) * t3);
        }
    }
}

/// The smooth thickness field, nm, row-major `width × height`.
pub fn thickness_field(cfg: &SimulateConfig) -> Vec<f32> {
    let (w, h) = (cfg.width, cfg.height);
    let mut rng = SplitMix64::stream(cfg.seed, u64::MAX, 0, 0);
    let size = w.max(h) as f64;
    // Plane waves with periods 0.7–2.5 image sizes, random direction/phase/amplitude.
    let waves: Vec<(f64, f64, f64, f64)> = (0..4)
        .map(|_| {
            let period = size * (0.7 + 1.8 * rng.uniform());
            let dir = 2.0 * std::f64::consts::PI * rng.uniform();
            let k = 2.0 * std::f64::consts::PI / period;
            (
                k * dir.cos(),
                k * dir.sin(),
                2.0 * std::f64::consts::PI * rng.uniform(),
                0.5 + 0.5 * rng.uniform(),
            )
        })
        .collect();
    // Gaussian bumps (centres inside the image, widths 0.1–0.3 image sizes, either sign).
    let bumps: Vec<(f64, f64, f64, f64)> = (0..3)
        .map(|_| {
            let cx = rng.uniform() * w as f64;
            let cy = rng.uniform() * h as f64;
            let s = size * (0.1 + 0.2 * rng.uniform());
            let a = if rng.uniform() < 0.5 { -1.0 } else { 1.0 } * (0.5 + 0.5 * rng.uniform());
            (cx, cy, s, a)
        })
        .collect();
    let g: Vec<f64> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let mut v = 0.0;
            for &(kx, ky, ph, a) in &waves {
                v += a * (kx * x + ky * y + ph).sin();
            }
            for &(cx, cy, s, a) in &bumps {
                v += a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * s * s)).exp();
            }
            v
        })
        .collect();
    // Zero mean, so d0 is the mean thickness (before clamping at 0 for v = 1).
    let mean = g.iter().sum::<f64>() / g.len() as f64;
    let g: Vec<f64> = g.iter().map(|v| v - mean).collect();
    let peak = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let scale = if peak > 0.0 {
        cfg.thickness_variation / peak
    } else {
        0.0
    };
    g.iter()
        .map(|v| (cfg.thickness_nm * (1.0 + scale * v)).max(0.0) as f32)
        .collect()
}

/// Smooth white-signal spectrum (light × optics × sensor), counts at `white_counts` peak.
fn white_signal(cfg: &SimulateConfig, lambda_nm: f64) -> f64 {
    cfg.white_counts * (0.35 + 0.65 * (-((lambda_nm - 600.0) / 170.0).powi(2)).exp())
}

/// One simulated angle: BIP f32 cube (reflectance, or raw counts in raw mode).
pub struct SimulatedAngle {
    pub incident_deg: f64,
    pub data: Vec<f32>,
    /// Raw mode: (width, height, white cube, dark cube), BIP.
    pub references: Option<(usize, usize, Vec<f32>, Vec<f32>)>,
}

/// Noise-free band reflectance for every pixel, or with noise/raw conversion applied.
pub struct Simulator<'a> {
    cfg: &'a SimulateConfig,
    model: BandModel,
    thickness: &'a [f32],
    d_lo: f64,
    d_hi: f64,
}

impl<'a> Simulator<'a> {
    pub fn new(cfg: &'a SimulateConfig, thickness: &'a [f32]) -> Result<Self> {
        cfg.validate()?;
        if thickness.len() != cfg.width * cfg.height {
            bail!(
                "thickness field has {} pixels, expected {}",
                thickness.len(),
                cfg.width * cfg.height
            );
        }
        let (d_lo, d_hi) = thickness
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| {
                (lo.min(d as f64), hi.max(d as f64))
            });
        Ok(Simulator {
            cfg,
            model: BandModel::new(cfg, d_hi),
            thickness,
            d_lo,
            d_hi,
        })
    }

    pub fn model(&self) -> &BandModel {
        &self.model
    }

    /// Thickness step giving ≥ 256 nodes per interference period in d (λ / 2n), so the
    /// cubic interpolation error stays below ~1e-6 in reflectance.
    fn table_step(&self) -> f64 {
        let min_lambda = self
            .model
            .nodes
            .iter()
            .flatten()
            .map(|n| n.0)
            .fold(f64::INFINITY, f64::min);
        let max_n = self
            .model
            .nodes
            .iter()
            .flatten()
            .map(|n| self.cfg.film_ior.at(n.0).norm())
            .fold(0.0, f64::max);
        min_lambda / (2.0 * max_n.max(1.0)) / 256.0
    }

    /// Noise-free band reflectance, BIP f64 → f32, for angle index `a`. `use_table`
    /// `None` picks the cheaper method (a field of view gives every column its own angle:
    /// evaluated directly).
    pub fn clean_cube(&self, a: usize, use_table: Option<bool>) -> Vec<f32> {
        let cfg = self.cfg;
        let nb = cfg.wavelengths_nm.len();
        let cos_theta = cfg.angles_deg[a].to_radians().cos();
        let fov = cfg.realism.fov_half_deg > 0.0;
        let step = self.table_step();
        let table_nodes = ((self.d_hi - self.d_lo) / step).ceil() + 4.0;
        let use_table = !fov && use_table.unwrap_or(table_nodes < self.thickness.len() as f64);
        let table = use_table
            .then(|| ThicknessTable::new(&self.model, cos_theta, self.d_lo, self.d_hi, step, nb));
        let mut out = vec![0f32; self.thickness.len() * nb];
        out.par_chunks_mut(cfg.width * nb)
            .enumerate()
            .for_each(|(y, row)| {
                let mut spec = vec![0.0; nb];
                for (x, px) in row.chunks_mut(nb).enumerate() {
                    let d = self.thickness[y * cfg.width + x] as f64;
                    match &table {
                        Some(t) => t.spectrum(d, &mut spec),
                        None if fov => self.model.spectrum(
                            d,
                            cfg.incident_deg_at(a, x).to_radians().cos(),
                            &mut spec,
                        ),
                        None => self.model.spectrum(d, cos_theta, &mut spec),
                    }
                    for (o, s) in px.iter_mut().zip(&spec) {
                        *o = *s as f32;
                    }
                }
            });
        out
    }

    /// The cube the camera records at angle index `a` (effects, noise, raw counts).
    pub fn angle(&self, a: usize, progress: &indicatif::ProgressBar) -> SimulatedAngle {
        let cfg = self.cfg;
        let nb = cfg.wavelengths_nm.len();
        let mut data = self.clean_cube(a, None);
        let signal: Vec<f64> = cfg
            .wavelengths_nm
            .iter()
            .map(|&l| white_signal(cfg, l))
            .collect();
        let fx = cfg.effects();
        let (lo, hi) = (
            cfg.wavelengths_nm[0],
            cfg.wavelengths_nm[nb - 1].max(cfg.wavelengths_nm[0] + 1e-9),
        );
        // Spectral factor of angle a: exposure × lamp tilt.
        let spectral: Vec<f64> = cfg
            .wavelengths_nm
            .iter()
            .map(|&l| fx.exposure[a] * (1.0 + fx.lamp_tilt[a] * (2.0 * (l - lo) / (hi - lo) - 1.0)))
            .collect();
        data.par_chunks_mut(cfg.width * nb)
            .enumerate()
            .for_each(|(y, row)| {
                let mut rng = SplitMix64::stream(cfg.seed, a as u64, y as u64, 1);
                for (x, px) in row.chunks_mut(nb).enumerate() {
                    let vig = cfg.vignetting(x, y);
                    for (b, v) in px.iter_mut().enumerate() {
                        // No draw at all for σ = 0: a noise-free float capture is the clean cube.
                        let noise = if cfg.noise_sigma > 0.0 {
                            cfg.noise_sigma * rng.normal()
                        } else {
                            0.0
                        };
                        let r = *v as f64 * vig * spectral[b] + fx.background[a] + noise;
                        *v = if cfg.raw_counts {
                            raw_count(&mut rng, r * signal[b], cfg) as f32
                        } else {
                            r as f32
                        };
                    }
                }
                progress.inc(1);
            });
        let references = cfg.raw_counts.then(|| {
            let (rw, rh) = (cfg.width.min(32), cfg.height.min(32));
            let mut rng = SplitMix64::stream(cfg.seed, a as u64, u64::MAX, 2);
            let mut white = Vec::with_capacity(rw * rh * nb);
            let mut dark = Vec::with_capacity(rw * rh * nb);
            for _ in 0..rw * rh {
                for &s in &signal {
                    white.push(raw_count(&mut rng, s, cfg) as f32);
                    dark.push(raw_count(&mut rng, 0.0, cfg) as f32);
                }
            }
            (rw, rh, white, dark)
        });
        SimulatedAngle {
            incident_deg: cfg.angles_deg[a],
            data,
            references,
        }
    }
}

/// A uint16 reading: shot noise on the signal, dark level, read noise, clipped.
fn raw_count(rng: &mut SplitMix64, signal: f64, cfg: &SimulateConfig) -> f64 {
    let electrons = rng.poisson(signal.max(0.0));
    (electrons + cfg.dark_counts + cfg.read_noise * rng.normal())
        .round()
        .clamp(0.0, u16::MAX as f64)
}

/// Thickness statistics for the ground truth (null when no value is finite).
pub fn thickness_stats(t: &[f32]) -> Value {
    serde_json::to_value(crate::stats::Summary::of_finite(t)).unwrap_or(Value::Null)
}

fn angle_label(deg: f64) -> String {
    let s = format!("{deg}");
    s.replace('.', "p")
}

/// What [`write_capture_set`] wrote.
#[derive(Debug, Clone)]
pub struct SimulationSummary {
    pub capture_json: std::path::PathBuf,
    pub ground_truth_json: std::path::PathBuf,
    pub thickness_nm: Vec<f32>,
}

/// Simulates and writes `out/capture.json`, one cube per angle (`theta10.hdr`/`.img`,
/// raw mode also `white10`, `dark10`), and `out/ground_truth/`. Every file is written
/// atomically; `capture.json` last, so an interrupted run leaves no loadable set.
pub fn write_capture_set(cfg: &SimulateConfig, out: &Path) -> Result<SimulationSummary> {
    cfg.validate()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let thickness = thickness_field(cfg);
    let sim = Simulator::new(cfg, &thickness)?;
    let nb = cfg.wavelengths_nm.len();
    let work = (cfg.angles_deg.len() * cfg.height) as u64;
    let progress = crate::progress::bar(
        cfg.progress,
        work,
        "simulate {bar:40} {pos}/{len} rows [{elapsed_precise}, {eta} left]",
    );
    let fwhm = (cfg.fwhm_nm > 0.0).then(|| vec![cfg.fwhm_nm; nb]);
    let options = |w: usize, h: usize, what: &str| {
        let mut o = WriteOptions::new(w, h, nb);
        o.interleave = cfg.interleave;
        o.data_type = if cfg.raw_counts {
            DataType::U16
        } else {
            DataType::F32
        };
        o.wavelengths_nm = Some(cfg.wavelengths_nm.clone());
        o.fwhm_nm = fwhm.clone();
        o.description = Some(format!("thinfilm simulate: {what}"));
        o
    };
    let mut entries = Vec::new();
    for a in 0..cfg.angles_deg.len() {
        let angle = sim.angle(a, &progress);
        let label = angle_label(angle.incident_deg);
        let cube = format!("theta{label}.hdr");
        let what = if cfg.raw_counts {
            "raw counts"
        } else {
            "reflectance"
        };
        envi::write_cube(
            &out.join(&cube),
            &angle.data,
            &options(
                cfg.width,
                cfg.height,
                &format!("{what} at {}°", angle.incident_deg),
            ),
        )?;
        let mut entry = AngleEntry {
            incident_deg: angle.incident_deg,
            cube,
            white: None,
            dark: None,
            incident_deg_map: None,
        };
        if cfg.realism.write_angle_maps {
            let a = entries.len();
            let map: Vec<f32> = (0..cfg.width * cfg.height)
                .map(|p| cfg.incident_deg_at(a, p % cfg.width) as f32)
                .collect();
            let name = format!("angle{label}.exr");
            crate::image_io::write_exr_channels(
                &out.join(&name),
                cfg.width,
                cfg.height,
                &[("incident_deg", &map)],
            )?;
            entry.incident_deg_map = Some(name);
        }
        if let Some((rw, rh, white, dark)) = &angle.references {
            let (wn, dn) = (format!("white{label}.hdr"), format!("dark{label}.hdr"));
            envi::write_cube(&out.join(&wn), white, &options(*rw, *rh, "white reference"))?;
            envi::write_cube(&out.join(&dn), dark, &options(*rw, *rh, "dark reference"))?;
            entry.white = Some(wn);
            entry.dark = Some(dn);
        }
        entries.push(entry);
    }
    progress.finish_and_clear();

    let fx = cfg.effects();
    let gt_dir = out.join("ground_truth");
    let exr = gt_dir.join("thickness.exr");
    crate::image_io::write_exr_channels(
        &exr,
        cfg.width,
        cfg.height,
        &[(crate::material::THICKNESS_CHANNEL, &thickness)],
    )?;
    let gt = json!({
        "format": GROUND_TRUTH_FORMAT,
        "film": ior_to_json(&cfg.film_ior),
        "substrate": ior_to_json(&cfg.substrate_ior),
        "ambient_ior": cfg.ambient_ior,
        "polarization": cfg.polarization,
        "width": cfg.width,
        "height": cfg.height,
        "thickness_exr": "thickness.exr",
        "thickness_nm": thickness_stats(&thickness),
        "options": cfg.to_json(),
        "effects": {
            "exposure": fx.exposure,
            "lamp_tilt": fx.lamp_tilt,
            "background": fx.background,
            "vignetting_min": cfg.realism.vignetting_min,
            "fov_half_deg": cfg.realism.fov_half_deg,
            "substrate_in_capture": ior_to_json(&cfg.stated_substrate()),
        },
    });
    let gt_json = gt_dir.join("ground_truth.json");
    write_json(&gt_json, &gt)?;
    let capture = CaptureFile {
        format: CAPTURE_FORMAT.into(),
        polarization: cfg.polarization,
        ambient_ior: Value::from(cfg.ambient_ior),
        substrate: ior_to_json(&cfg.stated_substrate()),
        angles: entries,
        description: None,
        radiometry: if cfg.realism.relative() {
            super::Radiometry::Relative
        } else {
            super::Radiometry::Absolute
        },
        film_model: None,
    };
    let capture_json = out.join("capture.json");
    write_json(&capture_json, &serde_json::to_value(&capture)?)?;
    Ok(SimulationSummary {
        capture_json,
        ground_truth_json: gt_json,
        thickness_nm: thickness,
    })
}

fn write_json(path: &Path, v: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v)? + "\n";
    crate::image_io::write_atomically(path, |tmp| {
        std::fs::write(tmp, text.as_bytes()).with_context(|| format!("writing {}", tmp.display()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wavelength_and_angle_parsing() {
        let w = parse_wavelengths("400:720:4").unwrap();
        assert_eq!(w.len(), 81);
        assert_eq!((w[0], w[80]), (400.0, 720.0));
        assert_eq!(
            parse_wavelengths("450, 500,550").unwrap(),
            vec![450.0, 500.0, 550.0]
        );
        for bad in ["400:300:4", "400:720:0", "a:b:c", "500,450", "1:2", "-5"] {
            assert!(parse_wavelengths(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_angles("10,20").unwrap(), vec![10.0, 20.0]);
        assert!(parse_angles("10,90").is_err());
        assert!(parse_angles("x").is_err());
    }

    #[test]
    fn band_nodes_are_normalised_gaussians() {
        let n = band_nodes(500.0, 10.0, f64::INFINITY);
        let sum: f64 = n.iter().map(|x| x.1).sum();
        assert!((sum - 1.0).abs() < 1e-12);
        let mean: f64 = n.iter().map(|x| x.0 * x.1).sum();
        assert!((mean - 500.0).abs() < 1e-9);
        let var: f64 = n.iter().map(|x| (x.0 - 500.0).powi(2) * x.1).sum();
        assert!(
            (var.sqrt() / sigma_of(10.0) - 1.0).abs() < 2e-3,
            "{}",
            var.sqrt()
        );
        // Fine fringes force finer nodes.
        assert!(band_nodes(500.0, 10.0, 1.0).len() > n.len());
        assert_eq!(band_nodes(500.0, 0.0, 1.0), vec![(500.0, 1.0)]);
    }

    #[test]
    fn thickness_field_is_smooth_bounded_and_seeded() {
        let cfg = SimulateConfig {
            width: 40,
            height: 30,
            thickness_variation: 0.2,
            ..Default::default()
        };
        let t = thickness_field(&cfg);
        let (lo, hi) = t
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        assert!(lo >= 320.0 - 1e-3 && hi <= 480.0 + 1e-3, "{lo} {hi}");
        // max |f| = 1: one end of the range is reached.
        assert!(
            (lo - 320.0).abs() < 1e-3 || (hi - 480.0).abs() < 1e-3,
            "{lo} {hi}"
        );
        // Smooth: neighbours differ by a small fraction of the range.
        let max_step = (0..30 * 40)
            .filter(|i| i % 40 != 39)
            .map(|i| (t[i + 1] - t[i]).abs())
            .fold(0f32, f32::max);
        assert!(max_step < 0.1 * (hi - lo), "{max_step}");
        let mean = t.iter().map(|&v| v as f64).sum::<f64>() / t.len() as f64;
        assert!((mean - 400.0).abs() < 1e-3, "{mean}");
        assert_eq!(t, thickness_field(&cfg));
        assert_ne!(
            t,
            thickness_field(&SimulateConfig {
                seed: 2,
                ..cfg.clone()
            })
        );
        let flat = thickness_field(&SimulateConfig {
            thickness_variation: 0.0,
            ..cfg
        });
        assert!(flat.iter().all(|&v| v == 400.0));
    }

    #[test]
    fn table_interpolation_matches_direct_evaluation() {
        for preset in ["sample1", "sample3"] {
            let cfg = SimulateConfig {
                width: 24,
                height: 16,
                thickness_variation: 0.3,
                wavelengths_nm: parse_wavelengths("400:720:16").unwrap(),
                angles_deg: vec![50.0],
                ..SimulateConfig::preset(preset).unwrap()
            };
            let t = thickness_field(&cfg);
            let sim = Simulator::new(&cfg, &t).unwrap();
            let direct = sim.clean_cube(0, Some(false));
            let table = sim.clean_cube(0, Some(true));
            let worst = direct
                .iter()
                .zip(&table)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            assert!(worst < 2e-6, "{preset}: {worst}");
        }
    }

    #[test]
    fn validate_rejects_bad_configs() {
        let ok = SimulateConfig::default();
        ok.validate().unwrap();
        for bad in [
            SimulateConfig {
                thickness_nm: -1.0,
                ..ok.clone()
            },
            SimulateConfig {
                thickness_variation: 1.5,
                ..ok.clone()
            },
            SimulateConfig {
                angles_deg: vec![90.0],
                ..ok.clone()
            },
            SimulateConfig {
                fwhm_nm: f64::NAN,
                ..ok.clone()
            },
            SimulateConfig {
                width: 0,
                ..ok.clone()
            },
            SimulateConfig {
                raw_counts: true,
                white_counts: 70_000.0,
                ..ok.clone()
            },
            SimulateConfig {
                film_ior: Ior::real(-1.0),
                ..ok.clone()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        assert!(SimulateConfig::preset("sample4").is_err());
    }
}
