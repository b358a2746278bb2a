//! Participating media as Mitsuba 3 defines them (`src/media/homogeneous.cpp`,
//! `src/phase/{isotropic,hg}.cpp`): a `homogeneous` medium of extinction σ_t (per unit
//! length, times `scale`) and single-scattering albedo α (σ_s = α σ_t), with an `isotropic`
//! or Henyey–Greenstein phase function. The path integrator's hook
//! (`integrator/media.rs`) samples free-flight distances here, scatters with the phase
//! function and attenuates shadow rays by the transmittance exp(−σ_t d).
//!
//! Chromatic extinction: a path carries four wavelengths, each with its own σ_t. A distance
//! is sampled from one wavelength's exponential chosen uniformly and weighted by the average
//! of the four densities (one-sample MIS with the balance heuristic over the channels, as
//! Mitsuba's `volpathmis`; its `volpath` always samples the first channel — the same
//! expectation, noisier where σ_t varies over the spectrum).

use super::texture::{Spec, Spectrum};
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A path outside every medium (vacuum).
pub const NO_MEDIUM: u32 = u32::MAX;
/// A camera path before its first segment: the sensor's medium, resolved by the hook.
pub const SENSOR_MEDIUM: u32 = u32::MAX - 1;

/// A phase function (directions as Mitsuba's: `wi` points back along the path).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    Isotropic,
    /// Henyey–Greenstein with mean cosine g ∈ (−1, 1) (g > 0: forward scattering).
    HenyeyGreenstein {
        g: f32,
    },
}

impl Phase {
    /// p(wi, wo) = pdf of [`Phase::sample`] (both phase functions are sampled exactly).
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        match *self {
            Phase::Isotropic => 1.0 / (4.0 * PI),
            Phase::HenyeyGreenstein { g } => hg(g, wo.dot(wi)),
        }
    }

    /// Samples wo ([`pdf`](Self::pdf) returns its density; the weight is 1).
    pub fn sample(&self, wi: Vec3, u: Vec2) -> (Vec3, f32) {
        match *self {
            Phase::Isotropic => {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (s, c) = (2.0 * PI * u.y).sin_cos();
                (Vec3::new(r * c, r * s, z), 1.0 / (4.0 * PI))
            }
            Phase::HenyeyGreenstein { g } => {
                // Mitsuba's inversion (hg.cpp): cos θ of wo against −wi.
                let cos_theta = if g.abs() < f32::EPSILON {
                    1.0 - 2.0 * u.x
                } else {
                    let sqr = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
                    (1.0 + g * g - sqr * sqr) / (2.0 * g)
                }
                .clamp(-1.0, 1.0);
                let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
                let (sp, cp) = (2.0 * PI * u.y).sin_cos();
                let frame = super::geometry::Frame::from_normal(wi);
                let wo = frame.to_world(Vec3::new(sin_theta * cp, sin_theta * sp, -cos_theta));
                (wo, hg(g, -cos_theta))
            }
        }
    }
}

/// The Henyey–Greenstein density at cosine `cos` between wo and wi (Mitsuba's `eval_hg`).
fn hg(g: f32, cos: f32) -> f32 {
    let temp = 1.0 + g * g + 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * temp * temp.sqrt())
}

/// Mitsuba's `homogeneous` medium.
#[derive(Debug, Clone)]
pub struct Medium {
    /// σ_t before `scale` (a bounded RGB is upsampled as a reflectance, as Mitsuba's
    /// `constvolume` does with `<rgb>`).
    pub sigma_t: Spectrum,
    pub albedo: Spectrum,
    pub scale: f32,
    pub phase: Phase,
    /// Light sampling at scattering vertices (Mitsuba's `sample_emitters`).
    pub sample_emitters: bool,
}

impl Medium {
    /// σ_t at the path's wavelengths (per scene unit).
    #[inline]
    pub fn sigma_t(&self, wl: &SampledWavelengths) -> Spec {
        self.sigma_t.eval(wl) * self.scale
    }

    /// σ_s = α σ_t at the path's wavelengths.
    #[inline]
    pub fn sigma_s(&self, wl: &SampledWavelengths) -> Spec {
        self.sigma_t(wl) * self.albedo.eval(wl)
    }
}

/// The media of a scene rendered with Mitsuba's `volpath`: the media, which shapes bound
/// them and the sensor's.
#[derive(Debug, Clone, Default)]
pub struct SceneMedia {
    pub media: Vec<Medium>,
    /// Per shape with media: (shape index, [interior, exterior]); [`NO_MEDIUM`] where the
    /// shape names none. Sorted by shape index.
    pub shape_media: Vec<(u32, [u32; 2])>,
    /// The sensor's medium, or [`NO_MEDIUM`].
    pub sensor: u32,
}

impl SceneMedia {
    /// The medium a path enters when it leaves shape `shape` along `dir` (geometric normal
    /// `ng`): Mitsuba's `target_medium` — exterior if dir · ng > 0, interior otherwise —
    /// or None if the shape is no medium transition (the path's medium is unchanged).
    #[inline]
    pub fn target(&self, shape: u32, ng: Vec3, dir: Vec3) -> Option<u32> {
        let i = self
            .shape_media
            .binary_search_by_key(&shape, |s| s.0)
            .ok()?;
        let [interior, exterior] = self.shape_media[i].1;
        Some(if dir.dot(ng) > 0.0 {
            exterior
        } else {
            interior
        })
    }

    /// The medium `index` ([`NO_MEDIUM`]: none).
    #[inline]
    pub fn get(&self, index: u32) -> Option<&Medium> {
        self.media.get(index as usize)
    }
}

/// A sampled free flight: scattering at distance `t`, or the ray reaching its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Flight {
    /// Scatters at `t`; multiply the throughput by `weight` · σ_s.
    Scatter { t: f32, weight: Spec },
    /// Reaches `t_max`; multiply the throughput by `weight`.
    Pass { weight: Spec },
}

/// Transmittance exp(−σ_t d) per wavelength; over an infinite distance 0 where σ_t > 0
/// (never NaN).
#[inline]
pub fn transmittance(sigma_t: Spec, d: f32) -> Spec {
    if d.is_finite() {
        (-sigma_t * d).exp()
    } else {
        Spec::select(sigma_t.cmpgt(Spec::ZERO), Spec::ZERO, Spec::ONE)
    }
}

/// Samples a free-flight distance up to `t_max` in a medium of extinction `sigma_t` from the
/// first `channels` wavelengths (4, or 1 once the secondaries are terminated), one chosen by
/// `u`, and weights it by the channels' average density (the balance heuristic): the free
/// flight density of channel k is σ_k e^(−σ_k t) before `t_max`, and e^(−σ_k t_max) is its
/// probability of reaching `t_max`.
pub fn sample_flight(sigma_t: Spec, t_max: f32, u: f32, channels: usize) -> Flight {
    let n = channels.clamp(1, 4);
    let c = ((u * n as f32) as usize).min(n - 1);
    let u = (u * n as f32 - c as f32).clamp(0.0, 1.0 - f32::EPSILON);
    let s = sigma_t.to_array();
    let t = if s[c] > 0.0 {
        -(1.0 - u).ln() / s[c]
    } else {
        f32::INFINITY
    };
    let live = |v: Spec| -> f32 { v.to_array()[..n].iter().sum::<f32>() / n as f32 };
    if t < t_max {
        let tr = transmittance(sigma_t, t);
        let pdf = live(sigma_t * tr);
        if pdf > 0.0 {
            return Flight::Scatter {
                t,
                weight: tr / pdf,
            };
        }
        return Flight::Scatter {
            t,
            weight: Spec::ZERO,
        };
    }
    let tr = transmittance(sigma_t, t_max);
    let p = live(tr);
    Flight::Pass {
        weight: if p > 0.0 { tr / p } else { Spec::ZERO },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Sampler;

    const SIGMA: Spec = Spec::from_array([0.3, 1.7, 4.0, 0.9]);

    /// The channel-averaged free-flight density integrates to 1 with the probability of
    /// reaching the surface: ∫₀^d p(t) dt + P(pass) = 1 (trapezoid rule).
    #[test]
    fn free_flight_density_and_surface_probability_sum_to_one() {
        let d = 1.3f32;
        let n = 200_000;
        let dens = |t: f32| -> f32 {
            let p = SIGMA * transmittance(SIGMA, t);
            p.to_array().iter().sum::<f32>() / 4.0
        };
        let h = d / n as f32;
        let integral: f64 = (0..n)
            .map(|i| 0.5 * (dens(i as f32 * h) + dens((i + 1) as f32 * h)) as f64 * h as f64)
            .sum();
        let pass = transmittance(SIGMA, d).to_array().iter().sum::<f32>() as f64 / 4.0;
        assert!(
            (integral + pass - 1.0).abs() < 1e-4,
            "∫p + P(pass) = {}",
            integral + pass
        );
    }

    /// A slab of thickness d: the sampled pass weights estimate exp(−σ_t d) per wavelength,
    /// and the scatter weights × σ_t estimate the interaction probability 1 − exp(−σ_t d).
    #[test]
    fn slab_transmittance_matches_beer_lambert() {
        let d = 0.8f32;
        let n = 400_000;
        let mut rng = Sampler::from_seed(11);
        let (mut pass, mut hit) = (Spec::ZERO, Spec::ZERO);
        for _ in 0..n {
            match sample_flight(SIGMA, d, rng.next_1d(), 4) {
                Flight::Pass { weight } => pass += weight,
                Flight::Scatter { t, weight } => {
                    assert!(t < d);
                    hit += weight * SIGMA;
                }
            }
        }
        let expect = (-SIGMA * d).exp();
        for k in 0..4 {
            let (p, h) = (pass[k] / n as f32, hit[k] / n as f32);
            assert!(
                (p - expect[k]).abs() < 0.01,
                "channel {k}: {p} vs {}",
                expect[k]
            );
            assert!((h - (1.0 - expect[k])).abs() < 0.01, "channel {k}: {h}");
        }
        // The analytic transmittance of the shadow rays is the same law.
        assert_eq!(transmittance(SIGMA, d), expect);
        assert_eq!(
            transmittance(Spec::new(0.0, 1.0, 0.0, 2.0), f32::INFINITY),
            Spec::new(1.0, 0.0, 1.0, 0.0)
        );
    }

    /// Henyey–Greenstein: the density integrates to 1 and the sampled cosines follow it (χ²
    /// over 20 bins of cos θ, 19 degrees of freedom: 43.8 is the 0.1 % tail).
    #[test]
    fn hg_sampling_matches_its_pdf() {
        for g in [0.7f32, -0.4, 0.0] {
            let phase = Phase::HenyeyGreenstein { g };
            let wi = Vec3::new(0.3, -0.5, 0.81).normalize();
            let frame = crate::render::geometry::Frame::from_normal(wi);
            // Bin probabilities by integrating the pdf over cos θ (2π per ring).
            let bins = 20;
            let expected: Vec<f64> = (0..bins)
                .map(|b| {
                    let steps = 2000;
                    let (lo, hi) = (
                        -1.0 + 2.0 * b as f64 / bins as f64,
                        -1.0 + 2.0 * (b + 1) as f64 / bins as f64,
                    );
                    (0..steps)
                        .map(|i| {
                            let c = lo + (hi - lo) * (i as f64 + 0.5) / steps as f64;
                            let wo = frame.to_world(Vec3::new(
                                (1.0 - c * c).sqrt() as f32,
                                0.0,
                                c as f32,
                            ));
                            2.0 * std::f64::consts::PI * phase.pdf(wi, wo) as f64 * (hi - lo)
                                / steps as f64
                        })
                        .sum()
                })
                .collect();
            let total: f64 = expected.iter().sum();
            assert!((total - 1.0).abs() < 1e-3, "g = {g}: ∫p = {total}");
            let n = 200_000;
            let mut counts = vec![0f64; bins];
            let mut rng = Sampler::from_seed(5);
            for _ in 0..n {
                let (wo, pdf) = phase.sample(wi, rng.next_2d());
                assert!((pdf - phase.pdf(wi, wo)).abs() <= 1e-3 * pdf.max(1.0));
                let c = frame.to_local(wo).z.clamp(-1.0, 0.999_999);
                counts[((c + 1.0) * 0.5 * bins as f32) as usize] += 1.0;
            }
            let chi2: f64 = counts
                .iter()
                .zip(&expected)
                .map(|(o, e)| (o - e * n as f64).powi(2) / (e * n as f64))
                .sum();
            assert!(chi2 < 43.8, "g = {g}: χ² = {chi2}");
        }
    }

    /// The isotropic phase function samples the sphere uniformly: mean direction ≈ 0.
    #[test]
    fn isotropic_is_uniform() {
        let mut rng = Sampler::from_seed(2);
        let n = 100_000;
        let mut mean = Vec3::ZERO;
        for _ in 0..n {
            let (wo, pdf) = Phase::Isotropic.sample(Vec3::Z, rng.next_2d());
            assert!((wo.length() - 1.0).abs() < 1e-5 && pdf == Phase::Isotropic.pdf(Vec3::Z, wo));
            mean += wo;
        }
        assert!((mean / n as f32).length() < 0.01);
    }
}
