//! The capture as the estimator's stages see it: pixels read in the model's order
//! (angle-major, each angle's bands padded to a multiple of 8), which angles of a pixel
//! are usable, and per-pixel incidence where the capture gives angle maps.

use super::film::FilmIndex;
use super::model::Geometry;
use super::nuisance::Whitening;
use super::table::padded_bands;
use crate::capture::{CaptureSet, Radiometry};

/// Read access to a capture set in the layout every fit uses.
pub struct Observations<'a> {
    pub set: &'a CaptureSet,
    pub width: usize,
    pub height: usize,
    pub angles: usize,
    pub bands: usize,
    /// Padded row length per angle ([`padded_bands`]).
    pub stride: usize,
    /// The capture's geometry with the nominal angles.
    pub geom: Geometry,
    /// Whether amplitudes are calibrated (the capture's, or the user's override).
    pub radiometry: Radiometry,
}

impl<'a> Observations<'a> {
    pub fn new(set: &'a CaptureSet, band_integration: bool, radiometry: Radiometry) -> Self {
        let bands = set.bands();
        Observations {
            set,
            width: set.width,
            height: set.height,
            angles: set.angles.len(),
            bands,
            stride: padded_bands(bands),
            geom: Geometry::from_capture(set, band_integration),
            radiometry,
        }
    }

    /// True when pixels are independent point spectra (no spatial smoothness prior).
    pub fn independent_pixels(&self) -> bool {
        self.set.pixel_names.is_some()
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Raw spectra of pixel `p` into `y` (`angles × stride`, padding and unusable angles
    /// zero) and which angles are usable into `mask`; returns the number of usable angles.
    pub fn get(&self, p: usize, y: &mut [f32], mask: &mut [bool]) -> usize {
        let (nb, s) = (self.bands, self.stride);
        let mut used = 0;
        for (a, ang) in self.set.angles.iter().enumerate() {
            let row = &mut y[a * s..(a + 1) * s];
            row[nb..].iter_mut().for_each(|v| *v = 0.0);
            mask[a] = ang.pixel(p, &mut row[..nb]);
            if mask[a] {
                used += 1;
            } else {
                row.iter_mut().for_each(|v| *v = 0.0);
            }
        }
        used
    }

    /// Number of usable angles of pixel `p` (from the validity masks, without reading).
    pub fn usable_angles(&self, p: usize) -> usize {
        self.set.angles.iter().filter(|a| a.valid[p]).count()
    }

    /// Pixels usable at `min_angles` or more angles.
    pub fn pixels_with_angles(&self, min_angles: usize) -> Vec<usize> {
        (0..self.pixels())
            .filter(|&p| self.usable_angles(p) >= min_angles)
            .collect()
    }

    /// Phase-equivalent thickness scale of pixel `p` at each angle: the model of the
    /// nominal angle θa at thickness ρ·d has the phase of angle θp at d, with
    /// ρ = √(n² − n1² sin²θp) / √(n² − n1² sin²θa) (n at 550 nm). The Fresnel amplitudes
    /// change far less over a few degrees than the phase, and the free gain absorbs most
    /// of that. All ones without angle maps.
    pub fn rho(&self, p: usize, n550: f64, out: &mut [f32]) {
        let n1 = self.set.ambient_ior;
        for (a, ang) in self.set.angles.iter().enumerate() {
            out[a] = match &ang.incident_deg_map {
                None => 1.0,
                Some(map) => {
                    let th = map[p] as f64;
                    if !th.is_finite() {
                        1.0
                    } else {
                        let kp = n1 * th.to_radians().sin();
                        let ka = n1 * ang.incident_deg.to_radians().sin();
                        ((n550 * n550 - kp * kp).max(1e-9) / (n550 * n550 - ka * ka).max(1e-9))
                            .sqrt() as f32
                    }
                }
            };
        }
    }
}

/// One pixel's whitened data, ready for a thickness fit (buffers reused per thread).
#[derive(Debug, Clone)]
pub struct PixelData {
    /// Whitened spectra, `angles × stride`.
    pub y: Vec<f32>,
    pub mask: Vec<bool>,
    /// Σỹ² per angle.
    pub yy: Vec<f32>,
    /// Phase-equivalent thickness scale per angle ([`Observations::rho`]).
    pub rho: Vec<f32>,
    /// Usable angles.
    pub used: usize,
    /// Usable samples (used angles × bands).
    pub samples: usize,
}

impl PixelData {
    pub fn new(obs: &Observations) -> Self {
        PixelData {
            y: vec![0.0; obs.angles * obs.stride],
            mask: vec![false; obs.angles],
            yy: vec![0.0; obs.angles],
            rho: vec![1.0; obs.angles],
            used: 0,
            samples: 0,
        }
    }

    /// Reads pixel `p` and whitens it; returns the number of usable angles.
    pub fn load(
        &mut self,
        obs: &Observations,
        white: &Whitening,
        film: &FilmIndex,
        p: usize,
    ) -> usize {
        self.used = obs.get(p, &mut self.y, &mut self.mask);
        self.samples = self.used * obs.bands;
        white.apply(&mut self.y, &self.mask, &mut self.yy);
        obs.rho(p, film.n550(), &mut self.rho);
        self.used
    }
}

/// Evenly spread subset of `items`, at most `max` long.
pub fn spread<T: Copy>(items: &[T], max: usize) -> Vec<T> {
    if items.len() <= max {
        return items.to_vec();
    }
    (0..max).map(|i| items[i * items.len() / max]).collect()
}

/// Median (reorders `v`); `None` when empty.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}
