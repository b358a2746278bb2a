//! Camera samples in struct-of-arrays form: the first stage of the renderer's batches
//! ([`super::trace_batches`]).
//!
//! [`BATCH`] samples — of one pixel, or at low sample counts of several neighbouring pixels
//! ([`BatchSpan`]) — share their row and camera origin, and their camera steps are the same
//! arithmetic on different numbers: sample numbers
//! ([`PixelSampler::camera_samples`]), hero wavelengths, film positions, ray directions
//! ([`super::camera::PerspectiveCamera::generate_rays`]). Written as loops over lanes, each
//! step compiles to SIMD (16 lanes are one AVX-512 or two AVX2 registers); the
//! colour-matching rows of their wavelengths are table rows, interpolated four channels at a
//! time. A lane's values do not depend on the other lanes (test
//! `render::tests::samples_do_not_depend_on_their_batch`: bit for bit against each sample
//! traced alone).
//!
//! The rows (r̄, ḡ, b̄, D65) at a sample's wavelengths are looked up once here and used twice:
//! by the environment lookups of every ray of the path (the D65 factor of RGB illuminants)
//! and by the film (the sample's RGB).

use super::camera::{Camera, Ray};
use super::primary::PixelRays;
use super::sampler::{PixelSampler, Sampler, SamplerKind};
use super::texture::Spec;
use crate::spectrum::{SampledWavelengths, LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Samples of one pixel traced together.
pub const BATCH: usize = 16;
// A batch's camera rays are one packet of the screen-bin test and one group of env lookups.
const _: () = assert!(BATCH == super::accel::PACKET && BATCH == super::lights::LANES);

/// Lane values, one per sample of the batch.
pub type Lanes = [f32; BATCH];

/// Rays of a camera without a single pinhole, lane by lane, with their origins; a thin lens
/// draws its lens sample from each sample's stream (two dimensions after the camera's).
fn lens_rays(
    camera: &Camera,
    film_uv: &[Lanes; 2],
    samplers: &mut [Sampler; BATCH],
) -> (PixelRays, Option<[Lanes; 3]>) {
    let mut rays = PixelRays {
        origin: glam::Vec3::ZERO,
        dir: [[0.0; BATCH]; 3],
        tmin: [0.0; BATCH],
        tmax: [0.0; BATCH],
    };
    let mut origins = [[0.0f32; BATCH]; 3];
    for i in 0..BATCH {
        let aperture = if camera.needs_aperture_sample() {
            samplers[i].next_2d()
        } else {
            glam::Vec2::splat(0.5)
        };
        let uv = glam::Vec2::new(film_uv[0][i], film_uv[1][i]);
        let r = camera.generate_ray_through(uv, aperture);
        for (k, (dir, origin)) in rays.dir.iter_mut().zip(&mut origins).enumerate() {
            dir[i] = r.dir[k];
            origin[i] = r.origin[k];
        }
        rays.tmin[i] = r.tmin;
        rays.tmax[i] = r.tmax;
    }
    (rays, Some(origins))
}

/// The samples a camera batch holds: samples `first .. first + len` of each of `pixels`
/// neighbouring pixels (`x0 + j`, `y`). Lane i is sample `first + i % len` of pixel
/// `x0 + i / len`: one pixel's samples at ≥ [`BATCH`] samples per pixel, several pixels'
/// at lower counts, so that a 1-spp preview fills the lanes with 16 pixels instead of
/// computing 16 lanes for one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchSpan {
    pub x0: u32,
    pub y: u32,
    pub pixels: u32,
    pub first: u32,
    pub len: u32,
}

impl BatchSpan {
    /// Samples in the batch (≤ [`BATCH`]).
    #[inline]
    pub fn lanes(&self) -> usize {
        (self.pixels * self.len) as usize
    }

    /// Each lane's pixel offset j (pixel `x0 + j`) and sample offset k (sample `first + k`),
    /// lane by lane (nested loops: no division per lane).
    #[inline]
    pub fn lane_samples(&self) -> impl Iterator<Item = (u32, u32)> {
        let len = self.len;
        (0..self.pixels).flat_map(move |j| (0..len).map(move |k| (j, k)))
    }
}

/// The camera samples of a [`BatchSpan`].
pub struct CameraBatch {
    pub n: usize,
    /// Film position in pixels.
    pub pos: [Lanes; 2],
    /// Each sample's wavelength number u (its hero set: {u + k/4}), from which
    /// [`Self::sample_wavelengths`] makes `lambda`, `pdf` and `rows`.
    wavelength_u: Lanes,
    /// The four wavelengths (nm) and their pdfs, `[k][lane]` (after
    /// [`Self::sample_wavelengths`]).
    pub lambda: [Lanes; 4],
    pub pdf: [Lanes; 4],
    /// (r̄, ḡ, b̄, D65) at wavelength k: `rows[k][lane]`
    /// ([`crate::spectrum::sampled::rgb_cmf_d65_f32`]). One interpolated table row per
    /// wavelength, kept as a row: the lerp is one 4-wide operation, and the film sums rows
    /// (spread over channel lanes, with a 4 × 4 transpose per four lanes, the lookups were
    /// ~a quarter of a render of camera rays that see only the environment).
    pub rows: [[[f32; 4]; BATCH]; 4],
    /// The camera rays.
    pub rays: PixelRays,
    /// Per-lane ray origins for cameras without a single pinhole (thin lens, orthographic;
    /// hook of the `lights` branch): then `rays.origin` is unused and [`Self::ray`] reads
    /// these.
    pub origins: Option<[Lanes; 3]>,
    /// Each sample's stream, positioned after the camera dimensions.
    pub samplers: [Sampler; BATCH],
}

impl CameraBatch {
    /// A batch to generate into ([`Self::generate`]).
    pub fn empty() -> Self {
        CameraBatch {
            n: 0,
            pos: [[0.0; BATCH]; 2],
            wavelength_u: [0.0; BATCH],
            lambda: [[0.0; BATCH]; 4],
            pdf: [[0.0; BATCH]; 4],
            rows: [[[0.0; 4]; BATCH]; 4],
            rays: PixelRays {
                origin: glam::Vec3::ZERO,
                dir: [[0.0; BATCH]; 3],
                tmin: [0.0; BATCH],
                tmax: [0.0; BATCH],
            },
            origins: None,
            samplers: [Sampler::from_seed(0); BATCH],
        }
    }

    /// Makes this the camera samples of `span`, in place (a batch is ~2.7 kB: returned by
    /// value and moved into the wavefront it was copied twice, ~5 % of a render of camera
    /// rays that see only the environment). Lanes from `span.lanes()` on hold further samples
    /// of its last pixel and are ignored. The wavelengths are drawn but not yet mapped to
    /// nanometres: [`Self::sample_wavelengths`] does that for batches whose samples need them
    /// (not one whose rays all see the environment's closed-form colour).
    pub fn generate(
        &mut self,
        camera: &Camera,
        sampler: SamplerKind,
        seed: u64,
        span: &BatchSpan,
        [width, height]: [u32; 2],
        wavelength_grid: bool,
    ) {
        let n = span.lanes();
        debug_assert!(n <= BATCH && span.pixels >= 1);
        let pixel = |j: u32| PixelSampler::new(sampler, span.x0 + j, span.y, seed);
        let first_pixel = pixel(0);
        let mut bits = [0u32; BATCH];
        let mut jitter = [[0.0f32; BATCH]; 2];
        let samplers = &mut self.samplers;
        let mut x = [span.x0; BATCH];
        if span.pixels == 1 {
            // One pixel (the common case): the same seeds in every lane.
            let index = std::array::from_fn(|i| span.first.wrapping_add(i as u32));
            PixelSampler::camera_samples(
                |_| &first_pixel,
                &index,
                wavelength_grid,
                &mut bits,
                &mut jitter,
                samplers,
            );
        } else {
            let mut per_pixel = [first_pixel; BATCH];
            for (j, p) in per_pixel.iter_mut().enumerate().take(span.pixels as usize) {
                *p = pixel(j as u32);
            }
            // Lanes past the span's continue its last pixel's samples.
            let tail = (span.len..).map(|k| (span.pixels - 1, k));
            let mut lane_pixel = [0u32; BATCH];
            let mut index = [0u32; BATCH];
            for (i, (j, k)) in span.lane_samples().chain(tail).take(BATCH).enumerate() {
                lane_pixel[i] = j;
                x[i] = span.x0 + j;
                index[i] = span.first.wrapping_add(k);
            }
            PixelSampler::camera_samples(
                |i| &per_pixel[lane_pixel[i] as usize],
                &index,
                wavelength_grid,
                &mut bits,
                &mut jitter,
                samplers,
            );
        }
        for (u, &b) in self.wavelength_u.iter_mut().zip(&bits) {
            *u = super::hero_wavelength_u(b);
        }
        let mut film_uv = [[0.0f32; BATCH]; 2];
        let size = [width as f32, height as f32];
        let pos = &mut self.pos;
        for i in 0..BATCH {
            pos[0][i] = x[i] as f32 + jitter[0][i];
            pos[1][i] = span.y as f32 + jitter[1][i];
            film_uv[0][i] = pos[0][i] / size[0];
            film_uv[1][i] = pos[1][i] / size[1];
        }
        self.n = n;
        match camera.pinhole() {
            Some(pinhole) => {
                let (dir, tmin, tmax) = pinhole.generate_rays(&film_uv);
                self.rays = PixelRays {
                    origin: pinhole.origin(),
                    dir,
                    tmin,
                    tmax,
                };
                self.origins = None;
            }
            None => (self.rays, self.origins) = lens_rays(camera, &film_uv, samplers),
        }
    }

    /// The samples' wavelengths, pdfs and colour-matching rows (`lambda`, `pdf`, `rows`)
    /// from the wavelength numbers [`Self::generate`] drew.
    pub fn sample_wavelengths(&mut self) {
        (self.lambda, self.pdf) = sample_visible_wavelengths(&self.wavelength_u);
        for (rows, lambda) in self.rows.iter_mut().zip(&self.lambda) {
            for (row, &l) in rows.iter_mut().zip(lambda) {
                *row = crate::spectrum::sampled::rgb_cmf_d65_f32(l);
            }
        }
    }

    /// Lane `i`'s camera ray.
    #[inline]
    pub fn ray(&self, i: usize) -> Ray {
        let mut ray = self.rays.ray(i);
        if let Some(o) = &self.origins {
            ray.origin = glam::Vec3::new(o[0][i], o[1][i], o[2][i]);
        }
        ray
    }

    /// Lane `i`'s wavelengths.
    #[inline]
    pub fn wavelengths(&self, i: usize) -> SampledWavelengths {
        SampledWavelengths::new(
            // Written out: `[0, 1, 2, 3].map` was left as an out-of-line call.
            [
                self.lambda[0][i],
                self.lambda[1][i],
                self.lambda[2][i],
                self.lambda[3][i],
            ],
            [
                self.pdf[0][i],
                self.pdf[1][i],
                self.pdf[2][i],
                self.pdf[3][i],
            ],
        )
    }

    /// The wavelengths of every lane's `SETS` specular-chain sets
    /// (`integrator::specular_chain`), `[set][lane]`: set j of a lane with number u is
    /// {u + (j + 1)/(4·(SETS + 1)) + k/4}, so that with the lane's own set they stratify.
    pub fn chain_wavelengths<const SETS: usize>(&self) -> [[SampledWavelengths; BATCH]; SETS] {
        std::array::from_fn(|j| {
            let u = self.wavelength_u.map(|u| {
                let u = u + (j + 1) as f32 / (4 * (SETS + 1)) as f32;
                if u >= 1.0 {
                    u - 1.0
                } else {
                    u
                }
            });
            let (lambda, pdf) = sample_visible_wavelengths(&u);
            std::array::from_fn(|i| {
                SampledWavelengths::new(lambda.map(|l| l[i]), pdf.map(|p| p[i]))
            })
        })
    }

    /// D65 factor at lane `i`'s four wavelengths.
    #[inline]
    pub fn d65(&self, i: usize) -> Spec {
        Spec::new(
            self.rows[0][i][3],
            self.rows[1][i][3],
            self.rows[2][i][3],
            self.rows[3][i][3],
        )
    }

    /// D65 factors of every lane, `[k][lane]`.
    #[inline]
    pub fn d65_lanes(&self) -> [Lanes; 4] {
        self.rows.map(|rows| rows.map(|row| row[3]))
    }

    /// Linear sRGB of every lane's spectral radiance (`l[k][lane]`, wavelength pdfs
    /// `pdf[k][lane]`: the batch's, or fewer after a dispersive refraction), `[lane][channel]`:
    /// Σ_k rgb̄(λ_k)·L_k/p_k over the wavelengths with p_k > 0, per lane the operations of
    /// [`crate::spectrum::spectrum_to_linear_srgb`], so the same values bit for bit
    /// (a skipped wavelength adds +0 to a sum that starts at +0).
    #[inline]
    pub fn to_rgb_lanes(&self, l: &[Lanes; 4], pdf: &[Lanes; 4]) -> [[f32; 3]; BATCH] {
        let mut s = [[0.0f32; BATCH]; 4];
        for k in 0..4 {
            for i in 0..BATCH {
                s[k][i] = if pdf[k][i] == 0.0 {
                    0.0
                } else {
                    l[k][i] / pdf[k][i]
                };
            }
        }
        let mut rgb = [[0.0f32; 3]; BATCH];
        for (i, rgb) in rgb.iter_mut().enumerate() {
            // One row of (r̄, ḡ, b̄, D65) times L/p per wavelength, summed in wavelength order.
            let mut sum = glam::Vec4::ZERO;
            for (rows, s) in self.rows.iter().zip(&s) {
                sum += glam::Vec4::from(rows[i]) * s[i];
            }
            *rgb = sum.truncate().to_array();
        }
        rgb
    }
}

/// Visible-range wavelength importance sampling (pbrt-v4 / Mitsuba), the distribution of
/// [`SampledWavelengths::sample_visible`], for `N` numbers u at once, `[k][lane]`, cheaper:
/// with x = 0.85691062 − 1.82750197·u', λ = 538 − 138.888889·atanh(x) and
/// pdf(λ) = N / cosh²(0.0072·(λ − 538)). Because 0.0072 · 138.888889 = 1,
/// cosh²(atanh x) = 1 / (1 − x²), so pdf = N·(1 − x²) needs no `cosh`, and
/// atanh x = ½·ln((1 + x)/(1 − x)) is one `ln` ([`ln_fast_lanes`]). The wavelength-sampling
/// transcendental calls were ~15 % of a teapot render; values agree with the spectrum
/// module's to f32 rounding (`tests::fast_wavelength_sampling_matches_spectrum`). Written as
/// loops over lanes without branches but the rare range-end fix-up, so that every step
/// compiles to SIMD; a lane's value does not depend on the others.
pub(crate) fn sample_visible_wavelengths<const N: usize>(
    u: &[f32; N],
) -> ([[f32; N]; 4], [[f32; N]; 4]) {
    const VISIBLE_PDF_NORM: f32 = 0.003_939_804;
    let (lo, hi) = (LAMBDA_MIN_NM as f32, LAMBDA_MAX_NM as f32);
    let mut lambda = [[0.0f32; N]; 4];
    let mut pdf = [[0.0f32; N]; 4];
    for k in 0..4 {
        let offset = k as f32 * 0.25;
        let mut x = [0.0f32; N];
        let mut ratio = [0.0f32; N];
        for i in 0..N {
            let up = u[i] + offset;
            let up = if up > 1.0 { up - 1.0 } else { up };
            x[i] = 0.856_910_6 - 1.827_502 * up;
            ratio[i] = (1.0 + x[i]) / (1.0 - x[i]);
        }
        let ln = ln_fast_lanes(&ratio);
        for i in 0..N {
            lambda[k][i] = 538.0 - 138.888_89 * (0.5 * ln[i]);
            pdf[k][i] = VISIBLE_PDF_NORM * (1.0 - x[i] * x[i]);
        }
        // f32 rounding can overshoot the range ends by ~1e-4 nm (rare: scalar fix-up).
        let outside = lambda[k]
            .iter()
            .fold(false, |out, &l| out | !(l >= lo && l <= hi));
        if outside {
            for i in 0..N {
                let l_in = lambda[k][i].clamp(lo, hi);
                if l_in != lambda[k][i] {
                    lambda[k][i] = l_in;
                    pdf[k][i] = crate::spectrum::visible_wavelengths_pdf(l_in);
                }
            }
        }
    }
    (lambda, pdf)
}

/// ln x lane by lane for positive normal x (libm `logf` was ~3 % of a teapot render, four
/// calls per sample): x = m·2^e with m ∈ [√½, √2), ln m = 2 atanh s = 2(s + s³/3 + … + s⁹/9)
/// with s = (m − 1)/(m + 1), |s| ≤ 0.172 (truncation < 2e-9). Relative error ~1e-7, i.e.
/// ≤ 2e-5 nm in λ. Here x ∈ [0.0149, 13] always (see [`sample_visible_wavelengths`]).
#[inline]
fn ln_fast_lanes<const N: usize>(x: &[f32; N]) -> [f32; N] {
    // Exponent relative to [√½, √2): shift the mantissa boundary from 1 to √½ (bits of √½).
    const SQRT_HALF_BITS: u32 = 0x3f35_04f3;
    let mut out = [0.0f32; N];
    for i in 0..N {
        let bits = x[i].to_bits();
        let e = (bits.wrapping_sub(SQRT_HALF_BITS) as i32) >> 23;
        let m = f32::from_bits(bits.wrapping_sub((e as u32) << 23));
        let e = e as f32;
        let s = (m - 1.0) / (m + 1.0);
        let s2 = s * s;
        let p = 1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0))));
        out[i] = e * std::f32::consts::LN_2 + 2.0 * s * p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_fast_matches_std() {
        let mut x = 0.01f32;
        while x < 20.0 {
            let ([a], b) = (ln_fast_lanes(&[x]), x.ln());
            assert!(
                (a - b).abs() <= 2e-7 * b.abs().max(1.0),
                "ln {x}: {a} vs {b}"
            );
            x *= 1.000_37;
        }
        assert_eq!(ln_fast_lanes(&[1.0]), [0.0]);
    }

    #[test]
    fn fast_wavelength_sampling_matches_spectrum() {
        for i in 0..=4000 {
            let u = i as f32 / 4000.0 * 0.999_999;
            let (lambda, pdf) = sample_visible_wavelengths(&[u]);
            let reference = SampledWavelengths::sample_visible(u);
            for k in 0..4 {
                let (l, lr) = (lambda[k][0], reference.lambda[k]);
                assert!((l - lr).abs() < 2e-3, "u {u} k {k}: λ {l} vs {lr}");
                assert!((360.0..=830.0).contains(&l), "u {u}: λ {l}");
                let (p, pr) = (pdf[k][0], reference.pdf[k]);
                assert!(
                    p > 0.0 && (p - pr).abs() <= 1e-4 * pr,
                    "u {u} k {k}: pdf {p} vs {pr}"
                );
            }
        }
        // The range ends (u = 0 → 360 nm) stay inside and keep a positive pdf.
        let (lambda, pdf) = sample_visible_wavelengths(&[0.0]);
        assert!((lambda[0][0] - 360.0).abs() < 1e-3 && pdf[0][0] > 0.0);
    }

    /// A lane's own wavelengths and its chain sets' are the strata u + m/(4·(SETS + 1)) of
    /// the visible distribution: with one set, eight wavelengths an eighth of u apart.
    #[test]
    fn chain_sets_stratify_the_wavelength_number() {
        let mut cam = CameraBatch::empty();
        for (i, u) in cam.wavelength_u.iter_mut().enumerate() {
            *u = (i as f32 * 0.0617 + 0.013) % 1.0;
        }
        cam.sample_wavelengths();
        let sets = cam.chain_wavelengths::<1>();
        for (i, set) in sets[0].iter().enumerate() {
            let mut all: Vec<f32> = cam.wavelengths(i).lambda.to_vec();
            all.extend(set.lambda);
            all.sort_by(f32::total_cmp);
            let u = cam.wavelength_u[i];
            let mut strata: Vec<f32> = (0..8)
                .map(|m| (u + m as f32 / 8.0) % 1.0)
                .map(crate::spectrum::sampled::sample_visible_wavelength)
                .collect();
            strata.sort_by(f32::total_cmp);
            for (a, b) in all.iter().zip(&strata) {
                assert!((a - b).abs() < 2e-3, "u {u}: λ {a} vs {b}");
            }
            assert!(set.pdf.iter().all(|&p| p > 0.0));
        }
    }

    /// A lane's wavelengths do not depend on the batch it is drawn in (what the renderer's
    /// bit-identity across batch sizes rests on).
    #[test]
    fn lanes_are_independent() {
        let u: [f32; 16] = std::array::from_fn(|i| (i as f32 * 0.0617 + 0.013) % 1.0);
        let (lambda, pdf) = sample_visible_wavelengths(&u);
        for (i, &ui) in u.iter().enumerate() {
            let (l1, p1) = sample_visible_wavelengths(&[ui]);
            for k in 0..4 {
                assert_eq!(lambda[k][i].to_bits(), l1[k][0].to_bits());
                assert_eq!(pdf[k][i].to_bits(), p1[k][0].to_bits());
            }
        }
    }

    /// A batch's rows are the one-wavelength table lookups of its samples' wavelengths, and
    /// its film values are [`crate::spectrum::spectrum_to_linear_srgb`] of each lane bit for
    /// bit: radiances of every magnitude, zero, and wavelengths whose pdf was zeroed (a
    /// dispersive refraction's).
    #[test]
    fn film_values_are_the_spectrum_module_s() {
        let scene = crate::figure::teapot_scene(&Default::default());
        let camera = Camera::new(&scene.camera, 64, 48).unwrap();
        let mut cam = CameraBatch::empty();
        let mut rng = Sampler::from_seed(17);
        for (round, y) in (0..48).step_by(5).enumerate() {
            let span = BatchSpan {
                x0: 3 * y,
                y,
                pixels: 1 + round as u32 % 3,
                first: 7 * y,
                len: 5,
            };
            let kind = [SamplerKind::Independent, SamplerKind::Sobol][round % 2];
            cam.generate(&camera, kind, 5, &span, [64, 48], round % 3 != 0);
            cam.sample_wavelengths();
            let mut l = [[0.0f32; BATCH]; 4];
            let mut pdf = cam.pdf;
            for k in 0..4 {
                for i in 0..BATCH {
                    l[k][i] = [0.0, 1e-30, 0.37, 12.5, 3e4][(i + k) % 5] * rng.next_1d();
                    if rng.next_1d() < 0.2 {
                        pdf[k][i] = 0.0;
                    }
                }
            }
            let rgb = cam.to_rgb_lanes(&l, &pdf);
            for i in 0..BATCH {
                let lambda = [0, 1, 2, 3].map(|k| cam.lambda[k][i]);
                for (k, &lambda) in lambda.iter().enumerate() {
                    let one = crate::spectrum::sampled::rgb_cmf_d65_f32(lambda);
                    assert_eq!(cam.rows[k][i].map(f32::to_bits), one.map(f32::to_bits));
                }
                let wl = SampledWavelengths::new(lambda, [0, 1, 2, 3].map(|k| pdf[k][i]));
                let l = Spec::new(l[0][i], l[1][i], l[2][i], l[3][i]);
                let one = crate::spectrum::spectrum_to_linear_srgb(l, &wl);
                assert_eq!(rgb[i].map(f32::to_bits), one.map(f32::to_bits), "lane {i}");
            }
        }
    }
}
