//! Noise per angle and band, estimated from the data before any fit (so the fit's
//! residual can be judged against it: a residual far above the noise means the model is
//! wrong, not the data noisy).
//!
//! Two estimators, each an upper bound (signal can only leak in), combined by taking the
//! smaller:
//! - spectral: the residual of a least-squares cubic through 7 consecutive bands, at the
//!   centre band (a fixed linear filter h; σ = MAD(h·y)/(0.6745 ‖h‖)). Fringes leak in
//!   only when a fringe spans fewer than ~12 bands;
//! - spatial: the second difference across neighbouring pixels of a row,
//!   (y(x−1) − 2y(x) + y(x+1))/√6, blind to linear gain and thickness gradients (seed
//!   assumption 3: thickness varies smoothly).
//!
//! Both are medians over pixels per (angle, band); with too few pixels (point spectra)
//! the samples of neighbouring bands are pooled.

use super::data::{median, Observations};
use rayon::prelude::*;

/// Noise of every (angle, band) in the data's units.
#[derive(Debug, Clone)]
pub struct NoiseEstimate {
    /// σ per angle and band (`angles × bands`).
    pub sigma: Vec<f32>,
    /// Median σ over all angles and bands.
    pub typical: f64,
    /// How it was obtained, for the report.
    pub source: String,
}

/// Residual filter of a least-squares cubic through 7 points, evaluated at the centre.
fn cubic_residual_filter() -> [f64; 7] {
    // Savitzky–Golay cubic smoothing weights for 7 points: (−2, 3, 6, 7, 6, 3, −2)/21.
    let sg = [-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0];
    let mut h = [0.0; 7];
    for (i, v) in h.iter_mut().enumerate() {
        *v = if i == 3 { 1.0 } else { 0.0 } - sg[i] / 21.0;
    }
    h
}

/// Robust σ of a set of values assumed zero-mean: MAD / 0.6745.
fn mad_sigma(v: &mut [f64]) -> Option<f64> {
    for x in v.iter_mut() {
        *x = x.abs();
    }
    median(v).map(|m| m / 0.674_489_75)
}

/// One pixel's noise samples per (angle, band), `angles × bands` (NaN = none).
struct Samples {
    /// Spectral filter outputs h·y / ‖h‖.
    spectral: Vec<f64>,
    /// Spatial second differences / √6.
    spatial: Vec<f64>,
}

/// A pixel's spectrum and mask, and its two row neighbours'.
struct Neighbourhood {
    y: Vec<f32>,
    m: Vec<bool>,
    yl: Vec<f32>,
    ml: Vec<bool>,
    yr: Vec<f32>,
    mr: Vec<bool>,
}

impl Neighbourhood {
    fn new(obs: &Observations) -> Self {
        let (n, s) = (obs.angles, obs.stride);
        Neighbourhood {
            y: vec![0f32; n * s],
            m: vec![false; n],
            yl: vec![0f32; n * s],
            ml: vec![false; n],
            yr: vec![0f32; n * s],
            mr: vec![false; n],
        }
    }
}

/// Estimates the noise from `pixels` (a spread subset of usable pixels).
pub fn estimate(obs: &Observations, pixels: &[usize]) -> NoiseEstimate {
    let (na, nb) = (obs.angles, obs.bands);
    let per_pixel: Vec<Samples> = pixels
        .par_iter()
        .map_init(
            || Neighbourhood::new(obs),
            |nh, &p| pixel_samples(obs, p, nh),
        )
        .collect();
    let (mut sigma, used_spectral, used_spatial) = smaller_estimate(&per_pixel, na, nb);
    let (typical, floor) = fill_and_floor(&mut sigma, na, nb);
    let source = match (used_spectral, used_spatial) {
        (true, true) => {
            "smaller of spectral (7-band cubic residual) and spatial (second difference) estimates"
        }
        (true, false) => "spectral estimate (7-band cubic residual)",
        (false, true) => "spatial estimate (second difference across pixels)",
        (false, false) => "no estimate possible (too few bands and pixels); floor value",
    };
    NoiseEstimate {
        sigma,
        typical: typical.max(floor),
        source: format!("{source} over {} pixels", pixels.len()),
    }
}

/// Per (angle, band), the smaller of the pooled spectral and spatial σ (each is an upper
/// bound: signal can only leak in), NaN where neither exists; and whether each was used.
fn smaller_estimate(per_pixel: &[Samples], na: usize, nb: usize) -> (Vec<f32>, bool, bool) {
    let mut sigma = vec![0f32; na * nb];
    let mut used_spatial = false;
    let mut used_spectral = false;
    for a in 0..na {
        let spec = pooled_sigma(per_pixel, |s| &s.spectral, a, nb);
        let spat = pooled_sigma(per_pixel, |s| &s.spatial, a, nb);
        for b in 0..nb {
            let (x, z) = (spec[b], spat[b]);
            let v = match (x.is_finite() && x > 0.0, z.is_finite() && z > 0.0) {
                (true, true) => {
                    if z <= x {
                        used_spatial = true;
                        z
                    } else {
                        used_spectral = true;
                        x
                    }
                }
                (true, false) => {
                    used_spectral = true;
                    x
                }
                (false, true) => {
                    used_spatial = true;
                    z
                }
                (false, false) => f64::NAN,
            };
            sigma[a * nb + b] = v as f32;
        }
    }
    (sigma, used_spectral, used_spatial)
}

/// Pixel `p`'s spectral residuals and, where it has both row neighbours (and pixels are
/// neighbours at all), its spatial second differences.
fn pixel_samples(obs: &Observations, p: usize, nh: &mut Neighbourhood) -> Samples {
    let (na, nb, s) = (obs.angles, obs.bands, obs.stride);
    let h = cubic_residual_filter();
    let hn = h.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut spec = vec![f64::NAN; na * nb];
    let mut spat = vec![f64::NAN; na * nb];
    let (y, m) = (&mut nh.y, &mut nh.m);
    obs.get(p, y, m);
    for a in 0..na {
        if !m[a] || nb < 7 {
            continue;
        }
        let ya = &y[a * s..a * s + nb];
        for b in 3..nb - 3 {
            let r: f64 = (0..7).map(|k| h[k] * ya[b + k - 3] as f64).sum();
            spec[a * nb + b] = r / hn;
        }
    }
    let x = p % obs.width;
    if !obs.independent_pixels() && x > 0 && x + 1 < obs.width {
        let (yl, ml, yr, mr) = (&mut nh.yl, &mut nh.ml, &mut nh.yr, &mut nh.mr);
        obs.get(p - 1, yl, ml);
        obs.get(p + 1, yr, mr);
        for a in 0..na {
            if !(m[a] && ml[a] && mr[a]) {
                continue;
            }
            for b in 0..nb {
                let i = a * s + b;
                let e = yl[i] as f64 - 2.0 * y[i] as f64 + yr[i] as f64;
                spat[a * nb + b] = e / 6f64.sqrt();
            }
        }
    }
    Samples {
        spectral: spec,
        spatial: spat,
    }
}

/// σ per band of angle `a` from one kind of sample (`which`), by MAD over pixels; with
/// too few pixels, neighbouring bands are pooled until each band has about 48 samples.
/// NaN where fewer than 8 samples remain.
fn pooled_sigma(
    per_pixel: &[Samples],
    which: impl Fn(&Samples) -> &Vec<f64>,
    a: usize,
    nb: usize,
) -> Vec<f64> {
    let want = 48usize;
    let count_at = |b: usize| {
        per_pixel
            .iter()
            .filter(|pp| which(pp)[a * nb + b].is_finite())
            .count()
    };
    let typical = count_at(nb / 2).max(1);
    let half = (want.div_ceil(typical) / 2).min(nb / 2);
    (0..nb)
        .map(|b| {
            let lo = b.saturating_sub(half);
            let hi = (b + half + 1).min(nb);
            let mut v: Vec<f64> = per_pixel
                .iter()
                .flat_map(|pp| which(pp)[a * nb + lo..a * nb + hi].iter().copied())
                .filter(|x| x.is_finite())
                .collect();
            if v.len() < 8 {
                return f64::NAN;
            }
            mad_sigma(&mut v).unwrap_or(f64::NAN)
        })
        .collect()
}

/// Bands without an estimate (edges, flat data) take their angle's median; a floor (5 %
/// of the median over all bands) keeps noise-free simulations from getting infinite
/// weights. Returns that median and the floor.
fn fill_and_floor(sigma: &mut [f32], na: usize, nb: usize) -> (f64, f64) {
    let mut all: Vec<f64> = sigma
        .iter()
        .filter(|v| v.is_finite() && **v > 0.0)
        .map(|&v| v as f64)
        .collect();
    let typical = median(&mut all).unwrap_or(0.0);
    let floor = (typical * 0.05).max(1e-7);
    for a in 0..na {
        let mut row: Vec<f64> = sigma[a * nb..(a + 1) * nb]
            .iter()
            .filter(|v| v.is_finite() && **v > 0.0)
            .map(|&v| v as f64)
            .collect();
        let fill = median(&mut row).unwrap_or(typical).max(floor);
        for v in &mut sigma[a * nb..(a + 1) * nb] {
            if !(v.is_finite() && *v > 0.0) {
                *v = fill as f32;
            }
            *v = v.max(floor as f32);
        }
    }
    (typical, floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::synth::{self, SynthSpec};

    #[test]
    fn recovers_simulated_noise_with_and_without_fringes() {
        for (n, d, sigma) in [
            (1.37, 400.0, 0.004),
            (1.45, 1500.0, 0.002),
            (2.37, 500.0, 0.01),
        ] {
            let mut spec = SynthSpec::seed_conditions(n, d);
            spec.width = 24;
            spec.height = 16;
            spec.noise_sigma = sigma;
            let (set, _) = synth::capture(&spec);
            let obs = Observations::new(&set, true, crate::capture::Radiometry::Relative);
            let px: Vec<usize> = (0..obs.pixels()).collect();
            let est = estimate(&obs, &px);
            assert!(
                (est.typical / sigma - 1.0).abs() < 0.15,
                "n={n} d={d}: {} vs {sigma}",
                est.typical
            );
        }
    }

    #[test]
    fn single_spectrum_pools_bands_and_follows_heteroscedastic_noise() {
        let mut spec = SynthSpec::seed_conditions(1.33, 3000.0);
        spec.width = 1;
        spec.height = 1;
        spec.fwhm_nm = None;
        spec.wavelengths_nm = synth::bands(400.0, 800.0, 0.32);
        spec.incident_deg = vec![0.0];
        spec.noise_sigma = 0.0;
        let (mut set, _) = synth::capture(&spec);
        // Noise 0.01 below 500 nm, 0.002 above.
        let mut rng = synth::Rng::new(3);
        for (v, l) in (set.angles[0].reflectance.as_bip_mut().unwrap())
            .iter_mut()
            .zip(&spec.wavelengths_nm)
        {
            *v += (if *l < 500.0 { 0.01 } else { 0.002 } * rng.normal()) as f32;
        }
        let obs = Observations::new(&set, false, crate::capture::Radiometry::Relative);
        let est = estimate(&obs, &[0]);
        let nb = obs.bands;
        let at = |l: f64| est.sigma[((l - 400.0) / 0.32) as usize] as f64;
        assert!((at(430.0) / 0.01 - 1.0).abs() < 0.3, "{}", at(430.0));
        assert!((at(700.0) / 0.002 - 1.0).abs() < 0.3, "{}", at(700.0));
        assert_eq!(est.sigma.len(), nb);
    }
}
