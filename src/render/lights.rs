//! Emitters: the lat-long environment map (Mitsuba orientation, texel lattice and RGB→spectrum
//! conventions, importance-sampled by a 2-D piecewise-constant distribution), the constant
//! environment, area lights on shapes, and the delta lights: point, spot (Mitsuba's linear
//! and glTF's smooth cone profiles) and directional.

use super::accel::Accel;
use super::camera::Ray;
use super::env_sampling::{HemisphereTables, NormalBin};
use super::geometry::{
    offset_ray_origin, square_to_uniform_cone, square_to_uniform_sphere,
    square_to_uniform_triangle, Frame,
};
use super::texture::{Spec, Spectrum};
use crate::image_io::RgbImage;
use crate::scene::{EmitterDesc, Geometry, Scene, SpotCone};
use crate::spectrum::sampled::ColourQuadrature;
use crate::spectrum::{RgbIlluminantSpectrum, RgbSigmoidPolynomial, SampledWavelengths};
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::f32::consts::PI;

/// Piecewise-constant 1-D distribution on [0, 1) (pbrt-v4 `PiecewiseConstant1D`).
#[derive(Debug, Clone)]
pub struct Distribution1D {
    /// n + 1 cells: the CDF at each cell's start, the cell's pdf and the guide entry, side by
    /// side so that a sample's guide entry, CDF values and pdf are mostly one cache line
    /// (three separate arrays cost the envmap's samples three dependent cache misses: its
    /// 257 × 513-entry rows, with the texels and the BVH, exceed L2). Cell n holds only
    /// cdf = 1.
    cells: Vec<Cell>,
    integral: f32,
}

/// One cell of a [`Distribution1D`].
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct Cell {
    /// CDF at the cell's start.
    cdf: f32,
    /// func / integral (1 when the integral is 0): the density in the cell.
    pdf: f32,
    /// Guide table (Chen & Asau 1974, "cutpoint" search): for cell k, the first `j` with
    /// `cdf[j] > k/n`, so a sample starts its search next to its answer instead of
    /// bisecting the whole CDF. Same cell as a binary search, ~1 probe on average.
    guide: u32,
}

impl Distribution1D {
    pub fn new(func: &[f32]) -> Self {
        let n = func.len().max(1);
        let func: Vec<f32> = if func.is_empty() {
            vec![0.0]
        } else {
            func.iter()
                .map(|f| if f.is_finite() { f.abs() } else { 0.0 })
                .collect()
        };
        let mut cdf = vec![0.0f64; n + 1];
        for i in 0..n {
            cdf[i + 1] = cdf[i] + func[i] as f64 / n as f64;
        }
        let integral = cdf[n];
        let cdf: Vec<f32> = if integral > 0.0 {
            cdf.iter().map(|c| (c / integral) as f32).collect()
        } else {
            (0..=n).map(|i| i as f32 / n as f32).collect()
        };
        let integral = integral as f32;
        let cells = (0..=n)
            .map(|k| Cell {
                cdf: cdf[k],
                pdf: match (k < n, integral > 0.0) {
                    (false, _) => 0.0,
                    (true, true) => func[k] / integral,
                    (true, false) => 1.0,
                },
                guide: if k == 0 || k == n {
                    0
                } else {
                    cdf.partition_point(|&c| c <= k as f32 / n as f32) as u32
                },
            })
            .collect();
        Distribution1D { cells, integral }
    }

    /// The CDF's `partition_point(|&c| c <= u)`, started from the guide table. The CDF is
    /// non-decreasing, so walking from any start to the boundary finds the same index.
    #[inline]
    fn search(&self, u: f32) -> usize {
        let n = self.len();
        let k = ((u * n as f32) as usize).min(n - 1);
        let mut j = self.cells[k].guide as usize;
        while j > 0 && self.cells[j - 1].cdf > u {
            j -= 1;
        }
        while j < self.cells.len() && self.cells[j].cdf <= u {
            j += 1;
        }
        j
    }

    /// Starts loading the CDF cell the guide entry of `u` points to ([`Self::search`]'s
    /// second read; its guide cell should be in cache by now: [`Self::prefetch_guide`]).
    #[inline]
    fn prefetch_guided(&self, u: f32) {
        let n = self.len();
        let j = self.cells[((u * n as f32) as usize).min(n - 1)].guide as usize;
        prefetch(&self.cells[j]);
    }

    /// Starts loading the cell [`Self::pdf`] of `x` reads.
    #[inline]
    fn prefetch_pdf(&self, x: f32) {
        let n = self.len();
        prefetch(&self.cells[((x * n as f32) as usize).min(n - 1)]);
    }

    /// Starts loading the guide cell [`Self::search`] reads first for `u`.
    #[inline]
    fn prefetch_guide(&self, u: f32) {
        let n = self.len();
        prefetch(&self.cells[((u * n as f32) as usize).min(n - 1)]);
    }

    pub fn len(&self) -> usize {
        self.cells.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Returns (x ∈ [0,1), pdf(x), cell index).
    #[inline]
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.len();
        let i = (self.search(u).max(1) - 1).min(n - 1);
        let (c0, c1) = (self.cells[i].cdf, self.cells[i + 1].cdf);
        let width = c1 - c0;
        let du = if width > 0.0 {
            ((u - c0) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let x = ((i as f32 + du) / n as f32).min(1.0 - f32::EPSILON);
        (x, self.pdf_cell(i), i)
    }

    #[inline]
    pub fn pdf_cell(&self, i: usize) -> f32 {
        self.cells[i].pdf
    }

    #[inline]
    pub fn pdf(&self, x: f32) -> f32 {
        let n = self.len();
        let i = ((x * n as f32) as usize).min(n - 1);
        self.pdf_cell(i)
    }

    pub fn integral(&self) -> f32 {
        self.integral
    }
}

/// Piecewise-constant 2-D distribution on [0,1)²: a marginal over rows and one conditional
/// per row.
#[derive(Debug, Clone)]
pub struct Distribution2D {
    conditional: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `func` is row-major with `nu` columns and `nv` rows.
    pub fn new(func: &[f32], nu: usize, nv: usize) -> Self {
        let conditional: Vec<Distribution1D> = (0..nv)
            .map(|v| Distribution1D::new(&func[v * nu..(v + 1) * nu]))
            .collect();
        let marginal =
            Distribution1D::new(&conditional.iter().map(|c| c.integral()).collect::<Vec<_>>());
        Distribution2D {
            conditional,
            marginal,
        }
    }

    /// Returns ((u, v), pdf).
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (v, pdf_v, row) = self.marginal.sample(u.y);
        let (x, pdf_u, _) = self.conditional[row].sample(u.x);
        (Vec2::new(x, v), pdf_u * pdf_v)
    }

    /// Starts loading the cache line [`Self::sample`] of `u` misses first: the guide cell
    /// of the row it picks (the marginal, a few kB, stays in cache).
    #[inline]
    pub fn prefetch_sample(&self, u: Vec2) {
        let row = self.marginal.sample(u.y).2;
        self.conditional[row].prefetch_guide(u.x);
    }

    /// [`Self::prefetch_sample`]'s next stage: the CDF cell the row's guide entry points to.
    #[inline]
    pub fn prefetch_sample_guided(&self, u: Vec2) {
        let row = self.marginal.sample(u.y).2;
        self.conditional[row].prefetch_guided(u.x);
    }

    /// Starts loading the conditional cell [`Self::pdf`] of `p` reads.
    #[inline]
    pub fn prefetch_pdf(&self, p: Vec2) {
        let nv = self.conditional.len();
        let row = ((p.y * nv as f32) as usize).min(nv - 1);
        self.conditional[row].prefetch_pdf(p.x);
    }

    pub fn pdf(&self, p: Vec2) -> f32 {
        let nv = self.conditional.len();
        let row = ((p.y * nv as f32) as usize).min(nv - 1);
        self.marginal.pdf_cell(row) * self.conditional[row].pdf(p.x)
    }
}

/// Coefficients of the odd polynomial z·P(z²) ≈ atan z on [0, 1] used by [`atan2_fast`].
const ATAN_C: [f32; 8] = [
    0.999_999_34,
    -0.333_298_6,
    0.199_465_66,
    -0.139_086_34,
    0.096_422_08,
    -0.055_912_48,
    0.021_863_066,
    -0.004_054_597,
];

/// atan z for z ∈ [0, 1] (Horner on z², the operations every atan2 variant here shares).
#[inline(always)]
fn atan_unit(z: f32) -> f32 {
    let z2 = z * z;
    let mut p = ATAN_C[7];
    for &c in ATAN_C[..7].iter().rev() {
        p = p * z2 + c;
    }
    z * p
}

/// atan2(y, x) from a degree-15 odd minimax-style polynomial for atan on [0, 1] (fitted by
/// iteratively reweighted least squares; max error 1.3e-7 rad in f32, tested in
/// `tests::atan2_fast_matches_std`) plus octant reduction. The envmap direction→texel map
/// was ~10 % of a teapot render with libm's `atan2f`/`acosf`; a texel spans ≥ 1e-3 rad.
#[inline]
pub(crate) fn atan2_fast(y: f32, x: f32) -> f32 {
    if x.is_nan() || y.is_nan() {
        return f32::NAN;
    }
    let (ax, ay) = (x.abs(), y.abs());
    // No NaN here (checked above): plain compares, not `f32::max`'s NaN handling.
    let (mx, mn) = if ax >= ay { (ax, ay) } else { (ay, ax) };
    if mx == 0.0 {
        // atan2(±0, +0) = ±0, atan2(±0, −0) = ±π.
        return if x.is_sign_negative() {
            PI.copysign(y)
        } else {
            y
        };
    }
    let mut r = atan_unit(mn / mx);
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    r.copysign(y)
}

/// Two [`atan2_fast`] evaluations at once, (atan2(y0, x0), atan2(y1, x1)), in the lanes of
/// one `Vec4`: the same operations per lane, so the results are bit-identical to two scalar
/// calls (`tests::atan2_fast2_is_bit_identical_to_scalar`); the envmap lookup needs both
/// angles of every escaped ray. NaN or (0, 0) inputs take the scalar path.
#[inline]
fn atan2_fast2(y0: f32, x0: f32, y1: f32, x1: f32) -> (f32, f32) {
    let y = Vec4::new(y0, y1, y0, y1);
    let x = Vec4::new(x0, x1, x0, x1);
    let (ax, ay) = (x.abs(), y.abs());
    let x_ge_y = ax.cmpge(ay);
    let mx = Vec4::select(x_ge_y, ax, ay);
    // NaN lanes and atan2(±0, ±0) take the scalar path (its special cases).
    if x.is_nan_mask().any() || y.is_nan_mask().any() || mx.cmpeq(Vec4::ZERO).any() {
        return (atan2_fast(y0, x0), atan2_fast(y1, x1));
    }
    let mn = Vec4::select(x_ge_y, ay, ax);
    let z = mn / mx;
    let z2 = z * z;
    let mut p = Vec4::splat(ATAN_C[7]);
    for &c in ATAN_C[..7].iter().rev() {
        p = p * z2 + Vec4::splat(c);
    }
    let mut r = z * p;
    r = Vec4::select(
        ay.cmpgt(ax),
        Vec4::splat(std::f32::consts::FRAC_PI_2) - r,
        r,
    );
    r = Vec4::select(x.cmplt(Vec4::ZERO), Vec4::splat(PI) - r, r);
    let r = r.copysign(y);
    (r.x, r.y)
}

/// Lanes of the batched environment lookup ([`EnvMap::add_batch`]); a multiple of 4 (texel
/// rows are transposed four at a time).
pub(crate) const LANES: usize = 16;
const _: () = assert!(LANES % 4 == 0);

/// A hint to start loading the cache line of `r` (no effect on any value). The environment
/// sample is a chain of dependent cache misses (row CDF guide entry → CDF cell → texels);
/// [`crate::render::integrator`] finishes a round's samples stage by stage, and a prefetch
/// of every sample's next address before the stage that reads it overlaps their misses.
#[inline(always)]
pub(super) fn prefetch<T>(r: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults and reads nothing architecturally; SSE is baseline on
    // x86_64.
    #[allow(unused_unsafe)]
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((r as *const T).cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = r;
}

/// [`atan2_fast`] lane by lane, branch-free: the same operations per lane, so the results
/// are bit-identical where `special` is false; `special` marks lanes (NaN, or both
/// arguments zero) whose value here is not atan2_fast's and must be recomputed.
#[inline]
fn atan2_lanes<const N: usize>(y: &[f32; N], x: &[f32; N]) -> ([f32; N], [bool; N]) {
    let mut r = [0.0f32; N];
    let mut special = [false; N];
    for i in 0..N {
        let (ax, ay) = (x[i].abs(), y[i].abs());
        let x_ge_y = ax >= ay;
        let mx = if x_ge_y { ax } else { ay };
        let mn = if x_ge_y { ay } else { ax };
        special[i] = x[i].is_nan() || y[i].is_nan() || mx == 0.0;
        let mut a = atan_unit(mn / mx);
        a = if ay > ax {
            std::f32::consts::FRAC_PI_2 - a
        } else {
            a
        };
        a = if x[i] < 0.0 { PI - a } else { a };
        r[i] = a.copysign(y[i]);
    }
    (r, special)
}

/// [`ColourQuadrature`]'s nodes with the D65 factor of an RGB illuminant spectrum
/// ([`RgbIlluminantSpectrum`]) folded into the weights: the expected colour of an
/// environment texel is then one weighted sum of its sigmoid at the nodes.
struct ColourNodes {
    lambda_nm: &'static [f32],
    weight: [Vec<f32>; 3],
}

impl ColourNodes {
    fn with_d65() -> Self {
        let q = ColourQuadrature::get();
        let d65 = |l: f32| crate::spectrum::sampled::rgb_cmf_d65_f32(l)[3];
        ColourNodes {
            lambda_nm: &q.lambda_nm,
            weight: q.weight.clone().map(|w| {
                (w.iter().zip(&q.lambda_nm))
                    .map(|(w, &l)| w * d65(l))
                    .collect()
            }),
        }
    }

    /// The expected film colour of the sigmoid spectrum of coefficients `c` times D65
    /// (per unit scale): [`Self::sigmoid_colour_avx2`] where the CPU has AVX2 and FMA and
    /// the sigmoid's argument stays finite, else [`Self::sigmoid_colour_exact`].
    fn sigmoid_colour(&self, c: [f32; 3]) -> [f32; 3] {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has AVX2 and FMA (checked above).
            if let Some(rgb) = unsafe { self.sigmoid_colour_avx2(c) } {
                return rgb;
            }
        }
        self.sigmoid_colour_exact(c)
    }

    /// [`Self::sigmoid_colour`] with the sigmoid 1/2 + x/(2√(1 + x²)) from a
    /// reciprocal-square-root estimate refined by one Newton step (relative error ~2e-7,
    /// the f32 rounding of the exact form; no square root or division: a third of the time of
    /// [`Self::sigmoid_colour_exact`], which a 512 × 256 map's ~26,000 distinct texels
    /// otherwise spend 15 ms of set-up in). None if 1 + x² overflows at some node (black or
    /// white coefficients).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn sigmoid_colour_avx2(&self, c: [f32; 3]) -> Option<[f32; 3]> {
        use std::arch::x86_64::*;
        let (c0, c1, c2) = (
            _mm256_set1_ps(c[0]),
            _mm256_set1_ps(c[1]),
            _mm256_set1_ps(c[2]),
        );
        let (half, three_halves) = (_mm256_set1_ps(0.5), _mm256_set1_ps(1.5));
        let (one, inf) = (_mm256_set1_ps(1.0), _mm256_set1_ps(f32::INFINITY));
        let mut acc = [_mm256_setzero_ps(); 3];
        let mut finite = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        for (j, l) in self.lambda_nm.chunks_exact(8).enumerate() {
            let l = _mm256_loadu_ps(l.as_ptr());
            let x = _mm256_fmadd_ps(_mm256_fmadd_ps(c0, l, c1), l, c2);
            let y = _mm256_fmadd_ps(x, x, one);
            finite = _mm256_and_ps(finite, _mm256_cmp_ps::<_CMP_LT_OQ>(y, inf));
            // r ≈ 1/√y: the estimate r0, then r0·(3/2 − y·r0²/2).
            let r0 = _mm256_rsqrt_ps(y);
            let yr0 = _mm256_mul_ps(_mm256_mul_ps(half, y), r0);
            let r = _mm256_mul_ps(r0, _mm256_fnmadd_ps(yr0, r0, three_halves));
            let s = _mm256_fmadd_ps(_mm256_mul_ps(half, x), r, half);
            for (acc, w) in acc.iter_mut().zip(&self.weight) {
                let w = _mm256_loadu_ps(w[8 * j..8 * j + 8].as_ptr());
                *acc = _mm256_fmadd_ps(w, s, *acc);
            }
        }
        if _mm256_movemask_ps(finite) != 0xff {
            return None;
        }
        Some(acc.map(|a| {
            let mut lanes = [0.0f32; 8];
            _mm256_storeu_ps(lanes.as_mut_ptr(), a);
            lanes.iter().sum()
        }))
    }

    /// [`Self::sigmoid_colour`] with the exact sigmoid ([`RgbSigmoidPolynomial::eval4`], which
    /// maps S(±∞) to 1 or 0), four nodes at a time.
    fn sigmoid_colour_exact(&self, c: [f32; 3]) -> [f32; 3] {
        let poly = RgbSigmoidPolynomial { c };
        let mut acc = [Vec4::ZERO; 3];
        for (j, l) in self.lambda_nm.chunks_exact(4).enumerate() {
            let s = poly.eval4(Vec4::from_slice(l));
            for (acc, w) in acc.iter_mut().zip(&self.weight) {
                *acc += Vec4::from_slice(&w[4 * j..4 * j + 4]) * s;
            }
        }
        acc.map(|a| a.element_sum())
    }
}

/// The expected film colour of spectrum `s` seen directly ([`ColourQuadrature`]).
fn film_colour(s: &Spectrum) -> [f32; 3] {
    ColourQuadrature::get().expected_rgb(|l| s.eval(&SampledWavelengths::new([l; 4], [1.0; 4]))[0])
}

/// Lat-long environment map.
#[derive(Debug, Clone)]
pub struct EnvMap {
    width: usize,
    height: usize,
    /// The texels' sigmoid coefficients and scale (`RgbIlluminantSpectrum`) as
    /// (c0, c1, c2, scale) rows: one 16-byte load per corner (one copy only: the 512 × 256
    /// studio map is 2 MB, the size of L2).
    texel_rows: Vec<[f32; 4]>,
    /// Each texel's expected film colour (linear sRGB, alpha 0: one 16-byte row): its
    /// spectrum (sigmoid × scale × D65) integrated against the film's matching functions
    /// once ([`ColourQuadrature`]), for rays that see the map straight from the camera.
    texel_rgb: Vec<[f32; 4]>,
    scale: f32,
    to_world: Mat3,
    to_local: Mat3,
    dist: Distribution2D,
    /// The same distribution restricted per surface normal bin (hemisphere-aware sampling,
    /// [`super::env_sampling`]); None for a black map.
    hemispheres: Option<HemisphereTables>,
}

impl EnvMap {
    /// The map `image` × `scale` turned by `to_world`, with hemisphere sampling tables for
    /// the glossy lobe widths `lobes` ([`super::env_sampling::lobe_families`]).
    pub fn new(
        image: &RgbImage,
        scale: f32,
        to_world: Mat3,
        lobes: &[f32],
    ) -> anyhow::Result<Self> {
        let (w, h) = (image.width, image.height);
        if w < 1 || h < 2 {
            anyhow::bail!("environment map must be at least 1×2 texels, got {w}×{h}");
        }
        if !(scale.is_finite() && scale >= 0.0) {
            anyhow::bail!("environment map scale must be finite and ≥ 0, got {scale}");
        }
        if let Some((i, p)) = image
            .pixels
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite() || *v < 0.0))
        {
            anyhow::bail!(
                "environment map texel ({}, {}) is {:?}: radiance must be finite and ≥ 0",
                i % w,
                i / w,
                p
            );
        }
        if to_world.determinant().abs() < 1e-12 || !to_world.is_finite() {
            anyhow::bail!("environment map to_world is singular");
        }
        // One rgb2spec lookup per texel (a 512 × 256 map: ~40 ms on one core, mostly cache
        // misses in the 9 MB table), on every worker: set-up runs it beside the BVH build. A
        // texel equal to the one before it (flat regions: 80 % of the studio map's) reuses
        // its row.
        // Its expected film colour is integrated on the same pass (~0.2 µs per distinct texel).
        let mut texel_rows = vec![[0.0f32; 4]; image.pixels.len()];
        let mut texel_rgb = vec![[0.0f32; 4]; image.pixels.len()];
        let nodes = ColourNodes::with_d65();
        const CHUNK: usize = 4096;
        (texel_rows.par_chunks_mut(CHUNK))
            .zip(texel_rgb.par_chunks_mut(CHUNK))
            .zip(image.pixels.par_chunks(CHUNK))
            .for_each(|((rows, colours), pixels)| {
                let mut last: Option<([f32; 3], [f32; 4], [f32; 4])> = None;
                for ((row, colour), p) in rows.iter_mut().zip(colours).zip(pixels) {
                    (*row, *colour) = match last {
                        Some((q, r, c)) if q.map(f32::to_bits) == p.map(f32::to_bits) => (r, c),
                        _ => {
                            let t = RgbIlluminantSpectrum::new(*p);
                            let [r, g, b] = nodes.sigmoid_colour(t.poly.c);
                            let c = [r * t.scale, g * t.scale, b * t.scale, 0.0];
                            ([t.poly.c[0], t.poly.c[1], t.poly.c[2], t.scale], c)
                        }
                    };
                    last = Some((*p, *row, *colour));
                }
            });
        // Cells between lattice rows (v = i/(H−1)) and around texel columns (u = (j+½)/W).
        // A cell's value bounds the bilinear interpolant over it (max of the texels it
        // touches), times sin θ at its centre, so the pdf is positive wherever light is.
        let lum = |x: usize, y: usize| {
            let p = image.pixels[y * w + x];
            0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2] + 1e-3 * (p[0] + p[1] + p[2])
        };
        let nv = h - 1;
        let mut func = vec![0.0f32; w * nv];
        for i in 0..nv {
            let sin_theta = (PI * (i as f32 + 0.5) / nv as f32).sin();
            for j in 0..w {
                let mut m = 0.0f32;
                for dj in [w - 1, 0, 1] {
                    let jj = (j + dj) % w;
                    m = m.max(lum(jj, i)).max(lum(jj, i + 1));
                }
                func[i * w + j] = m * sin_theta;
            }
        }
        Ok(EnvMap {
            width: w,
            height: h,
            texel_rows,
            texel_rgb,
            scale,
            to_world,
            to_local: to_world.inverse(),
            hemispheres: HemisphereTables::new(&func, w, nv, to_world, lobes),
            dist: Distribution2D::new(&func, w, nv),
        })
    }

    /// Texture coordinates of a world direction (`docs/physics-and-formats.md`, "Environment map").
    #[inline]
    fn uv_of(&self, dir: Vec3) -> Vec2 {
        let d = (self.to_local * dir).normalize();
        // atan2 ∈ [−π, π] so u ∈ [−½, ½]: rem_euclid(1) is one conditional add (rem_euclid
        // calls libm floor without SSE4.1).
        // acos y = atan2(√((1 − y)(1 + y)), y), accurate also near the poles.
        let y = d.y.clamp(-1.0, 1.0);
        let (phi, theta) = atan2_fast2(d.x, -d.z, ((1.0 - y) * (1.0 + y)).sqrt(), y);
        let mut u = phi * (0.5 / PI);
        if u < 0.0 {
            u += 1.0;
        }
        let v = theta / PI;
        Vec2::new(if u >= 1.0 { 0.0 } else { u }, v)
    }

    /// Radiance arriving from world direction `dir` (bilinear over the texel spectra).
    #[inline]
    pub fn eval(&self, dir: Vec3, wl: &SampledWavelengths) -> Spec {
        self.eval_uv(self.uv_of(dir), wl)
    }

    /// `out[i] += eval(dirs[i], wls[i])` for a batch of directions, [`LANES`] at a time in
    /// struct-of-arrays form: every step is a loop over independent lanes of plain
    /// arithmetic that the compiler turns into SIMD (and the CPU overlaps where it does not),
    /// where one lookup alone is a ~150-cycle chain of square roots and divisions. Per lane
    /// the operations are those of [`Self::eval`], so the values are bit-identical
    /// (`tests::batched_lookup_is_bit_identical`); lanes needing a special case (NaN, a
    /// pole, a non-finite sigmoid argument) take the scalar path.
    pub fn add_batch(&self, dirs: &[Vec3], lambda: &[Spec], d65: &[Spec], out: &mut [Spec]) {
        in_lanes(dirs, lambda, d65, out, |dirs, l, w, active, sum| {
            let mut d = [[0.0f32; LANES]; 3];
            d[0] = [1.0; LANES];
            for (i, dir) in dirs.iter().enumerate() {
                for c in 0..3 {
                    d[c][i] = dir[c];
                }
            }
            self.add_lanes(&d, l, w, active, sum);
        });
    }

    /// [`Self::add_batch`] on one group of [`LANES`] lookups already in struct-of-arrays
    /// form (`dir[axis][lane]`, `lambda[k][lane]`, `d65[k][lane]`): `out[k][i] +=` the
    /// radiance of lane i where `active[i]`; inactive lanes are computed (their numbers must
    /// be finite or NaN, nothing more) but left out.
    pub fn add_lanes(
        &self,
        dir: &[[f32; LANES]; 3],
        lambda: &[[f32; LANES]; 4],
        d65: &[[f32; LANES]; 4],
        active: &[bool; LANES],
        out: &mut [[f32; LANES]; 4],
    ) {
        self.add_uv_lanes(&self.uv_lanes_exact(dir), lambda, d65, active, out);
    }

    /// `out[i] +=` the expected film colour (linear sRGB) of the radiance arriving from
    /// direction i, for the lanes `active`: what the film's spectral estimate of
    /// [`Self::eval`] averages to over the sampled wavelengths (the bilinear blend of the
    /// texels' colours, [`EnvMap::texel_rgb`]), without sampling them. Lanes whose direction
    /// is NaN add nothing, as their spectral lookup does.
    pub fn add_colour_lanes(
        &self,
        dir: &[[f32; LANES]; 3],
        active: &[bool; LANES],
        out: &mut [[f32; 3]; LANES],
    ) {
        let uv = self.uv_lanes_exact(dir);
        let (index, wgt) = self.bilinear_texels_lanes(&uv);
        for (i, out) in out.iter_mut().enumerate() {
            if !active[i] || uv[0][i].is_nan() || uv[1][i].is_nan() {
                continue;
            }
            let mut sum = Vec4::ZERO;
            for t in 0..4 {
                sum += Vec4::from(self.texel_rgb[index[t][i] as usize]) * wgt[t][i];
            }
            let rgb = sum * self.scale;
            for c in 0..3 {
                out[c] += rgb[c];
            }
        }
    }

    /// [`Self::add_lanes`] at texture coordinates already known (`uv[axis][lane]`, from
    /// [`Self::uv_lanes_exact`]): lanes whose uv is NaN or whose sigmoid argument is not
    /// finite take the scalar [`Self::eval_uv`], the others are its operations in SIMD lanes.
    fn add_uv_lanes(
        &self,
        uv: &[[f32; LANES]; 2],
        lambda: &[[f32; LANES]; 4],
        d65: &[[f32; LANES]; 4],
        active: &[bool; LANES],
        out: &mut [[f32; LANES]; 4],
    ) {
        let (mut spec, bad) = self.eval_lanes(uv, lambda, d65);
        for i in 0..LANES {
            let scalar = bad[i] || uv[0][i].is_nan() || uv[1][i].is_nan();
            if active[i] && scalar {
                let wl = SampledWavelengths::new([0, 1, 2, 3].map(|k| lambda[k][i]), [1.0; 4]);
                let v = self.eval_uv(Vec2::new(uv[0][i], uv[1][i]), &wl);
                for (k, row) in spec.iter_mut().enumerate() {
                    row[i] = v[k];
                }
            }
        }
        for k in 0..4 {
            for i in 0..LANES {
                if active[i] {
                    out[k][i] += spec[k][i];
                }
            }
        }
    }

    /// [`Self::uv_of`] on [`LANES`] directions, every lane bit-identical to it: SIMD lanes,
    /// and the scalar `uv_of` for the lanes needing its special cases.
    #[inline]
    fn uv_lanes_exact(&self, dir: &[[f32; LANES]; 3]) -> [[f32; LANES]; 2] {
        let (mut uv, scalar) = self.uv_lanes(dir);
        for i in 0..LANES {
            if scalar[i] {
                let t = self.uv_of(Vec3::new(dir[0][i], dir[1][i], dir[2][i]));
                (uv[0][i], uv[1][i]) = (t.x, t.y);
            }
        }
        uv
    }

    /// [`Self::uv_of`] of `dirs` into `uvs` ([`LANES`] at a time in SIMD lanes, bit-identical),
    /// starting the loads of what the lookups at them read: the texel rows
    /// ([`Self::eval_uv`]) and, with `plain_pdf`, the radiance-only sampling pdf's cell
    /// ([`Self::pdf_uv`] for MIS where no normal bin is used — not worth a load where the
    /// bins' tables are read instead, or where the ray left a Dirac vertex and needs no pdf:
    /// 1.5–2 % of the gold and diffuse teapots' render).
    pub fn uvs_prefetch(&self, dirs: &[Vec3], uvs: &mut [Vec2], plain_pdf: bool) {
        for (dirs, uvs) in dirs.chunks(LANES).zip(uvs.chunks_mut(LANES)) {
            let mut d = [[0.0f32; LANES]; 3];
            d[0] = [1.0; LANES];
            for (i, v) in dirs.iter().enumerate() {
                (d[0][i], d[1][i], d[2][i]) = (v.x, v.y, v.z);
            }
            let uv = self.uv_lanes_exact(&d);
            for (i, t) in uvs.iter_mut().enumerate() {
                *t = Vec2::new(uv[0][i], uv[1][i]);
                if plain_pdf {
                    self.dist.prefetch_pdf(*t);
                }
                let [(a, _), _, (b, _), _] = self.bilinear_texels(t.x, t.y);
                prefetch(&self.texel_rows[a]);
                prefetch(&self.texel_rows[b]);
            }
        }
    }

    /// [`Self::add_batch`] at texture coordinates already known (`uvs[i]` =
    /// [`Self::uv_of`] of the direction): the same values, without computing them again.
    pub fn add_batch_uv(&self, uvs: &[Vec2], lambda: &[Spec], d65: &[Spec], out: &mut [Spec]) {
        in_lanes(uvs, lambda, d65, out, |uvs, l, w, active, sum| {
            let mut uv = [[0.5f32; LANES]; 2];
            for (i, p) in uvs.iter().enumerate() {
                (uv[0][i], uv[1][i]) = (p.x, p.y);
            }
            self.add_uv_lanes(&uv, l, w, active, sum);
        });
    }

    /// [`Self::uv_of`] on [`LANES`] directions; `true` marks lanes whose atan2 needs the
    /// scalar special cases (NaN, or both arguments zero).
    fn uv_lanes(&self, dirs: &[[f32; LANES]; 3]) -> ([[f32; LANES]; 2], [bool; LANES]) {
        let m = &self.to_local;
        let (mut x, mut y, mut z) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        for i in 0..LANES {
            // glam's Mat3 * Vec3 and Vec3::normalize, operation for operation.
            let v = Vec3::new(dirs[0][i], dirs[1][i], dirs[2][i]);
            let lx = m.x_axis.x * v.x + m.y_axis.x * v.y + m.z_axis.x * v.z;
            let ly = m.x_axis.y * v.x + m.y_axis.y * v.y + m.z_axis.y * v.z;
            let lz = m.x_axis.z * v.x + m.y_axis.z * v.y + m.z_axis.z * v.z;
            let r = 1.0 / (lx * lx + ly * ly + lz * lz).sqrt();
            (x[i], y[i], z[i]) = (lx * r, ly * r, lz * r);
        }
        // atan2(x, −z) → φ and atan2(√(1 − y²), y) → θ, as in `uv_of`.
        let mut ya = [0.0f32; 4 * LANES / 2];
        let mut xa = [0.0f32; 4 * LANES / 2];
        for i in 0..LANES {
            let yc = y[i].clamp(-1.0, 1.0);
            ya[i] = x[i];
            xa[i] = -z[i];
            ya[LANES + i] = ((1.0 - yc) * (1.0 + yc)).sqrt();
            xa[LANES + i] = yc;
        }
        let (angles, special) = atan2_lanes(&ya, &xa);
        let mut uv = [[0.0f32; LANES]; 2];
        let mut scalar = [false; LANES];
        for i in 0..LANES {
            let mut u = angles[i] * (0.5 / PI);
            if u < 0.0 {
                u += 1.0;
            }
            uv[0][i] = if u >= 1.0 { 0.0 } else { u };
            uv[1][i] = angles[LANES + i] / PI;
            scalar[i] = special[i] || special[LANES + i];
        }
        (uv, scalar)
    }

    /// [`Self::eval_uv`] on [`LANES`] texture coordinates and wavelength sets (`lambda[k]`:
    /// the k-th wavelength of every lane): (radiance per wavelength and lane, lanes whose
    /// sigmoid argument was not finite and need the scalar path).
    fn eval_lanes(
        &self,
        uv: &[[f32; LANES]; 2],
        lambda: &[[f32; LANES]; 4],
        d65: &[[f32; LANES]; 4],
    ) -> ([[f32; LANES]; 4], [bool; LANES]) {
        // Corner texels and bilinear weights per lane, then the corners' rows (gathers:
        // scalar). Texels are finite and ≥ 0 (checked in `new`), so an unused corner (zero
        // weight or zero scale) gets weight +0 and adds exactly +0, as skipping it would.
        let (index, wgt) = self.bilinear_texels_lanes(uv);
        let mut coef = [[[0.0f32; LANES]; 3]; 4];
        let mut weight = [[0.0f32; LANES]; 4];
        let mut scale = [0.0f32; LANES];
        for t in 0..4 {
            // Four lanes' rows at a time, transposed in registers (a 4×4 shuffle).
            for i in (0..LANES).step_by(4) {
                let row = |j: usize| Vec4::from(self.texel_rows[index[t][i + j] as usize]);
                let m = Mat4::from_cols(row(0), row(1), row(2), row(3)).transpose();
                for (c, coef) in coef[t].iter_mut().enumerate() {
                    coef[i..i + 4].copy_from_slice(&m.col(c).to_array());
                }
                scale[i..i + 4].copy_from_slice(&m.col(3).to_array());
            }
            for i in 0..LANES {
                weight[t][i] = wgt[t][i] * scale[i];
            }
        }
        let mut out = [[0.0f32; LANES]; 4];
        let mut bad = [false; LANES];
        for k in 0..4 {
            let l = &lambda[k];
            let d65 = &d65[k];
            let mut acc = [0.0f32; LANES];
            for t in 0..4 {
                let [c0, c1, c2] = &coef[t];
                for i in 0..LANES {
                    let x = (c0[i] * l[i] + c1[i]) * l[i] + c2[i];
                    bad[i] |= !x.is_finite();
                    let s = 0.5 + x / (2.0 * (1.0 + x * x).sqrt());
                    // Unused corners have weight 0 and a finite sigmoid: adding 0 · s keeps
                    // the sum bit-identical to skipping them.
                    acc[i] += s * weight[t][i];
                }
            }
            for i in 0..LANES {
                out[k][i] = acc[i] * d65[i] * self.scale;
            }
        }
        (out, bad)
    }

    /// The four texels (indices) under texture coordinates (u, v) and their bilinear
    /// weights: texel centres at half-integers, columns wrapping, rows clamped.
    #[inline(always)]
    fn bilinear_texels(&self, u: f32, v: f32) -> [(usize, f32); 4] {
        let (w, h) = (self.width, self.height);
        let x = u * w as f32 - 0.5;
        let y = (v * (h - 1) as f32).clamp(0.0, (h - 1) as f32);
        // floor without the libm call: x ≥ −½ (NaN casts to 0 like before), y ≥ 0.
        let mut xi = x as i64;
        if (xi as f32) > x {
            xi -= 1;
        }
        let fx = x - xi as f32;
        // Column wrap without integer division (two `div`s were the slowest instructions
        // here): u ∈ [0, 1) puts xi in [−1, w − 1]; the general case is kept for safety.
        let wi = w as i64;
        let c0 = if (0..wi).contains(&xi) {
            xi as usize
        } else if xi == -1 {
            w - 1
        } else {
            xi.rem_euclid(wi) as usize
        };
        let c1 = if c0 + 1 == w { 0 } else { c0 + 1 };
        // y ∈ [0, h − 1] (clamped above; NaN casts to 0 either way): an i32 cast is exact
        // and cheaper than f32 → usize.
        let r0 = (y as i32 as usize).min(h - 2);
        let fy = y - r0 as f32;
        [
            (r0 * w + c0, (1.0 - fx) * (1.0 - fy)),
            (r0 * w + c1, fx * (1.0 - fy)),
            ((r0 + 1) * w + c0, (1.0 - fx) * fy),
            ((r0 + 1) * w + c1, fx * fy),
        ]
    }

    /// [`Self::bilinear_texels`] on [`LANES`] texture coordinates, `[corner][lane]`, with
    /// the same arithmetic for u ∈ [0, 1) and v ∈ [0, 1] (what [`Self::uv_lanes`] gives; NaN
    /// goes to texel 0 as there) but no branches, so that it compiles to SIMD.
    #[inline]
    fn bilinear_texels_lanes(
        &self,
        uv: &[[f32; LANES]; 2],
    ) -> ([[u32; LANES]; 4], [[f32; LANES]; 4]) {
        let (w, h) = (self.width as i32, self.height as i32);
        let mut index = [[0u32; LANES]; 4];
        let mut wgt = [[0.0f32; LANES]; 4];
        for i in 0..LANES {
            let x = uv[0][i] * w as f32 - 0.5;
            let y = (uv[1][i] * (h - 1) as f32).clamp(0.0, (h - 1) as f32);
            let mut xi = x as i32;
            if (xi as f32) > x {
                xi -= 1;
            }
            let fx = x - xi as f32;
            // Wrap by one period either way, then clamp: in range for any input.
            let c0 = if xi < 0 {
                xi + w
            } else if xi >= w {
                xi - w
            } else {
                xi
            }
            .clamp(0, w - 1);
            let c1 = if c0 + 1 == w { 0 } else { c0 + 1 };
            let r0 = (y as i32).clamp(0, h - 2);
            let fy = y - r0 as f32;
            index[0][i] = (r0 * w + c0) as u32;
            index[1][i] = (r0 * w + c1) as u32;
            index[2][i] = ((r0 + 1) * w + c0) as u32;
            index[3][i] = ((r0 + 1) * w + c1) as u32;
            wgt[0][i] = (1.0 - fx) * (1.0 - fy);
            wgt[1][i] = fx * (1.0 - fy);
            wgt[2][i] = (1.0 - fx) * fy;
            wgt[3][i] = fx * fy;
        }
        (index, wgt)
    }

    /// Radiance at texture coordinates `uv` ([`Self::uv_of`]).
    #[inline]
    fn eval_uv(&self, uv: Vec2, wl: &SampledWavelengths) -> Spec {
        // The four texels share the D65 factor: evaluate it once per wavelength.
        let d65 = Spec::from_array(
            wl.lambda
                .map(|l| crate::spectrum::sampled::rgb_cmf_d65_f32(l)[3]),
        );
        let lambda = Spec::from_array(wl.lambda);
        let mut out = Spec::ZERO;
        for (index, wgt) in self.bilinear_texels(uv.x, uv.y) {
            let [c0, c1, c2, scale] = self.texel_rows[index];
            if wgt > 0.0 && scale > 0.0 {
                let poly = crate::spectrum::RgbSigmoidPolynomial { c: [c0, c1, c2] };
                out += poly.eval4(lambda) * (wgt * scale);
            }
        }
        out *= d65;
        out * self.scale
    }

    /// Whether the map has per-bin sampling tables (not for a black map: every bin samples
    /// by radiance alone then).
    pub fn has_hemisphere_tables(&self) -> bool {
        self.hemispheres.is_some()
    }

    /// Samples a world direction for a vertex in normal bin `bin` (radiance alone for
    /// [`NormalBin::WHOLE_SPHERE`]); returns (dir, solid-angle pdf).
    #[inline]
    pub fn sample_direction(&self, u: Vec2, bin: NormalBin) -> Option<(Vec3, f32)> {
        self.sample_direction_uv(u, bin)
            .map(|(dir, pdf, _)| (dir, pdf))
    }

    /// Starts loading the first cache line [`Self::sample_direction`] of `u` will miss.
    #[inline]
    pub fn prefetch_sample(&self, u: Vec2, bin: NormalBin) {
        match (&self.hemispheres, bin) {
            (Some(h), b) if b != NormalBin::WHOLE_SPHERE => h.prefetch_sample(u, b),
            _ => self.dist.prefetch_sample(u),
        }
    }

    /// [`Self::prefetch_sample`]'s next stage (after it, before [`Self::sample_direction`]).
    #[inline]
    pub fn prefetch_sample_guided(&self, u: Vec2, bin: NormalBin) {
        if bin == NormalBin::WHOLE_SPHERE || self.hemispheres.is_none() {
            self.dist.prefetch_sample_guided(u);
        }
    }

    /// Starts loading what the lookups of a ray escaping along `dir` read: the sampling
    /// pdf's cell ([`Self::pdf_direction`], for MIS) and the texel rows ([`Self::eval`]).
    #[inline]
    fn prefetch_lookup(&self, dir: Vec3) {
        let uv = self.uv_of(dir);
        self.dist.prefetch_pdf(uv);
        let [(a, _), _, (b, _), _] = self.bilinear_texels(uv.x, uv.y);
        prefetch(&self.texel_rows[a]);
        prefetch(&self.texel_rows[b]);
    }

    /// [`Self::sample_direction`], and starts loading the texel rows [`Self::eval`] of the
    /// direction will read (those under the sampled (u, v); `eval` recomputes (u, v) from
    /// the direction, the same texels but for rounding at a texel edge).
    #[inline]
    pub fn sample_direction_prefetch(&self, u: Vec2, bin: NormalBin) -> Option<(Vec3, f32)> {
        let (dir, pdf, uv) = self.sample_direction_uv(u, bin)?;
        // Corners 0 and 2: the texel rows above and below; the column neighbours (16-byte
        // entries) are mostly in the same cache lines.
        let [(a, _), _, (b, _), _] = self.bilinear_texels(uv.x, uv.y);
        prefetch(&self.texel_rows[a]);
        prefetch(&self.texel_rows[b]);
        Some((dir, pdf))
    }

    /// [`Self::sample_direction`] with the sampled texture coordinates.
    #[inline(always)]
    fn sample_direction_uv(&self, u: Vec2, bin: NormalBin) -> Option<(Vec3, f32, Vec2)> {
        let (uv, pdf_uv) = match (&self.hemispheres, bin) {
            (Some(h), b) if b != NormalBin::WHOLE_SPHERE => h.sample(u, b),
            _ => self.dist.sample(u),
        };
        let theta = PI * uv.y;
        let phi = 2.0 * PI * uv.x;
        let (st, ct) = theta.sin_cos();
        if st <= 0.0 || pdf_uv <= 0.0 {
            return None;
        }
        let (sp, cp) = phi.sin_cos();
        let local = Vec3::new(st * sp, ct, -st * cp);
        let dir = (self.to_world * local).normalize();
        // Jacobian of (u, v) → direction: dω = 2π² sin θ du dv.
        Some((dir, pdf_uv / (2.0 * PI * PI * st), uv))
    }

    /// Solid-angle pdf of [`Self::sample_direction`] for `bin` at `dir`.
    #[inline]
    pub fn pdf_direction(&self, dir: Vec3, bin: NormalBin) -> f32 {
        self.pdf_uv(self.uv_of(dir), bin)
    }

    /// [`Self::pdf_direction`] of the direction whose texture coordinates are `uv`.
    #[inline]
    pub fn pdf_uv(&self, uv: Vec2, bin: NormalBin) -> f32 {
        let st = (PI * uv.y).sin();
        if st <= 0.0 {
            return 0.0;
        }
        let pdf_uv = match (&self.hemispheres, bin) {
            (Some(h), b) if b != NormalBin::WHOLE_SPHERE => h.pdf(uv, b),
            _ => self.dist.pdf(uv),
        };
        pdf_uv / (2.0 * PI * PI * st)
    }
}

/// Geometry of an area light, for sampling points on it.
#[derive(Debug, Clone)]
pub enum AreaGeometry {
    Triangles {
        tris: Vec<[Vec3; 3]>,
        /// Each triangle's unit normal, computed once (per sample it was a cross product,
        /// a square root and a division on the light sample's critical path).
        normals: Vec<Vec3>,
        dist: Distribution1D,
        area: f32,
    },
    Sphere {
        center: Vec3,
        radius: f32,
        flip: bool,
    },
}

#[derive(Debug, Clone)]
pub enum Light {
    Env(Box<EnvMap>),
    Constant(Spectrum),
    Point {
        position: Vec3,
        intensity: Spectrum,
    },
    Spot(Box<SpotLight>),
    /// Light travelling along `direction` (unit) with `irradiance` on a surface facing it.
    Directional {
        direction: Vec3,
        irradiance: Spectrum,
    },
    Area {
        shape: u32,
        radiance: Spectrum,
        /// The expected film colour of `radiance` ([`ColourQuadrature`]; None with a
        /// texture): what a camera ray that sees the light takes ([`Light::direct_colour`]).
        colour: Option<[f32; 3]>,
        geometry: AreaGeometry,
        /// Per-texel emission (glTF `emissiveTexture`), replacing `radiance` where set.
        texture: Option<Box<TexturedEmission>>,
    },
    Projector(Box<ProjectorLight>),
    /// A spot light whose value is also multiplied by a texture ([`EmitterDesc::TexturedSpot`]):
    /// the texture and tan(cutoff), Mitsuba's `m_uv_factor`.
    TexturedSpot(Box<(SpotLight, super::texture::Texture, f32)>),
}

/// A spot light ([`EmitterDesc::Spot`]) prepared for shading.
#[derive(Debug, Clone)]
pub struct SpotLight {
    position: Vec3,
    /// Inverse of the linear part of `to_world`: world direction → light-local direction
    /// (Mitsuba applies the inverse transform before normalising, so a scaled `to_world`
    /// reshapes the cone exactly as there).
    to_local: Mat3,
    intensity: Spectrum,
    cone: SpotCone,
    range: Option<f32>,
}

impl SpotLight {
    fn new(to_world: Mat4, intensity: Spectrum, cone: SpotCone, range: Option<f32>) -> Self {
        SpotLight {
            position: to_world.transform_point3(Vec3::ZERO),
            to_local: Mat3::from_mat4(to_world).inverse(),
            intensity,
            cone,
            range,
        }
    }

    /// Fraction of the axial intensity emitted along light-local direction `local`.
    fn profile(&self, local: Vec3) -> f32 {
        let cos_theta = local.normalize_or_zero().z;
        match self.cone {
            SpotCone::Linear { cutoff, beam_width } => {
                // Mitsuba `spot.cpp` `falloff_curve`: linear in the angle between the beam
                // width and the cutoff.
                if cos_theta <= cutoff.cos() {
                    0.0
                } else if cos_theta >= beam_width.cos() {
                    1.0
                } else {
                    ((cutoff - cos_theta.clamp(-1.0, 1.0).acos()) / (cutoff - beam_width))
                        .clamp(0.0, 1.0)
                }
            }
            SpotCone::Smooth {
                cos_inner,
                cos_outer,
            } => {
                // KHR_lights_punctual's reference falloff.
                let scale = 1.0 / (cos_inner - cos_outer).max(1e-3);
                let t = ((cos_theta - cos_outer) * scale).clamp(0.0, 1.0);
                t * t
            }
            SpotCone::Omni => 1.0,
        }
    }
}

/// A projector ([`EmitterDesc::Projector`]) prepared for shading: Mitsuba 3.9's
/// `projector.cpp` `sample_direction`. A point p with light-local coordinates (x, y, z), z > 0,
/// sees texel uv = (½ − ½·x/(z·t), ½ − ½·aspect·y/(z·t)), t = tan(fov_x/2) (Mitsuba's
/// `perspective_projection`: u grows to local −x, v downwards), and receives the value
/// π·scale·E(uv) / (z²·cos θ), θ between the projector's axis and the ray — the irradiance
/// E·scale on the plane z = 1 facing the projector, falling as a pinhole's.
#[derive(Debug, Clone)]
pub struct ProjectorLight {
    position: Vec3,
    /// `to_world` applied to local +Z (not normalised, as Mitsuba's `ds.n`).
    axis: Vec3,
    to_local: Mat4,
    irradiance: super::texture::Texture,
    /// The image is a bitmap (upsampled as a reflectance), not an emission spectrum.
    is_bitmap: bool,
    irradiance_value: Spectrum,
    scale: f32,
    tan_half_fov_x: f32,
    aspect: f32,
}

impl ProjectorLight {
    /// The incident direction, distance and value at `p`; None outside the frustum.
    fn incident(&self, p: Vec3, wl: &SampledWavelengths) -> Option<(Vec3, f32, Spec)> {
        let local = self.to_local.transform_point3(p);
        if local.z.is_nan() || local.z <= 0.0 {
            return None;
        }
        let k = 0.5 / (local.z * self.tan_half_fov_x);
        let uv = Vec2::new(0.5 - k * local.x, 0.5 - self.aspect * k * local.y);
        if !(uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all()) {
            return None;
        }
        let d = self.position - p;
        let dist = d.length();
        let wi = d / dist;
        let cos = -self.axis.dot(wi);
        let e = if self.is_bitmap {
            self.irradiance.eval(uv, wl)
        } else {
            self.irradiance_value.eval(wl)
        };
        let v = e * (PI * self.scale / (local.z * local.z * cos));
        (cos > 0.0 && dist > 0.0 && v.is_finite()).then_some((wi, dist, v))
    }
}

/// KHR_lights_punctual's recommended range window clamp(1 − (d/range)⁴, 0, 1), which brings
/// the inverse-square falloff smoothly to zero at `range` (1 without a range).
fn range_window(range: Option<f32>, dist: f32) -> f32 {
    match range {
        Some(r) => (1.0 - (dist / r).powi(4)).clamp(0.0, 1.0),
        None => 1.0,
    }
}

/// A light sample seen from a reference point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    pub wi: Vec3,
    /// Distance to the sampled point (∞ for environment lights).
    pub dist: f32,
    /// The sampled point on the light (unused for infinite lights).
    pub p_light: Vec3,
    /// Geometric normal at `p_light` (zero for point and infinite lights).
    pub n_light: Vec3,
    pub radiance: Spec,
    /// Solid-angle pdf including the light-selection probability (1 for delta lights, times
    /// the selection probability).
    pub pdf: f32,
    pub delta: bool,
}

impl LightSample {
    /// A sample of a delta light at `p_light` seen along `d = p_light − p` (unit pdf: the
    /// light-selection probability is applied by the caller).
    fn delta_at(p_light: Vec3, wi: Vec3, dist: f32, radiance: Spec) -> Self {
        LightSample {
            wi,
            dist,
            p_light,
            n_light: Vec3::ZERO,
            radiance,
            pdf: 1.0,
            delta: true,
        }
    }

    /// A sample of a light at infinity arriving along `wi`.
    pub(super) fn from_infinity(wi: Vec3, radiance: Spec, pdf: f32, delta: bool) -> Self {
        LightSample {
            wi,
            dist: f32::INFINITY,
            p_light: Vec3::ZERO,
            n_light: Vec3::ZERO,
            radiance,
            pdf,
            delta,
        }
    }

    /// The shadow ray from a surface point `p` (geometric normal `ng`) towards this sample.
    ///
    /// For a light at a finite distance both ends are moved off their surfaces and the ray
    /// is aimed from one moved end to the other (pbrt-v4 `SpawnRayTo(pFrom, nFrom, pTo, nTo)`).
    /// Offsetting only the origin and keeping `wi` and `dist` (as this renderer once did)
    /// makes the ray run parallel to the true segment, `offset / cos θ_light` closer to
    /// the emitter's plane than `dist` says: on a floor lit from above every shadow ray then
    /// hit the emitting rectangle itself, and only points straight under a light were lit.
    pub fn shadow_ray(&self, p: Vec3, ng: Vec3) -> Ray {
        let origin = offset_ray_origin(p, ng, self.wi);
        if !self.dist.is_finite() {
            return Ray {
                origin,
                dir: self.wi,
                tmin: 0.0,
                tmax: f32::INFINITY,
            };
        }
        let target = if self.n_light == Vec3::ZERO {
            self.p_light
        } else {
            offset_ray_origin(self.p_light, self.n_light, -self.wi)
        };
        let d = target - origin;
        let len = d.length();
        if len <= 0.0 || !len.is_finite() {
            // The two moved ends met (a light touching the surface): nothing can be in between.
            return Ray {
                origin,
                dir: self.wi,
                tmin: 0.0,
                tmax: 0.0,
            };
        }
        Ray {
            origin,
            dir: d / len,
            tmin: 0.0,
            // The moved target lies in front of the emitter's surface, so the emitter itself
            // is beyond `len`; the small margin only guards against the target's own rounding.
            tmax: len * (1.0 - 1e-5),
        }
    }
}

impl Light {
    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Env(_) | Light::Constant(_))
    }

    /// Radiance emitted towards a ray along `dir` that hit this light's shape at texture
    /// coordinates `uv` where the geometric normal is `ng`: area lights emit from their
    /// front face only (Mitsuba). None where nothing is emitted.
    #[inline]
    pub fn emitted(&self, ng: Vec3, uv: Vec2, dir: Vec3, wl: &SampledWavelengths) -> Option<Spec> {
        match self {
            Light::Area {
                texture: Some(t), ..
            } if ng.dot(-dir) > 0.0 => Some(t.radiance(uv, wl)),
            Light::Area { radiance, .. } if ng.dot(-dir) > 0.0 => Some(radiance.eval(wl)),
            _ => None,
        }
    }

    /// The expected film colour (linear sRGB) of what an untextured area light emits along
    /// `dir` at a point of normal `ng` ([`Self::emitted`]: black from behind), over the
    /// sampled wavelengths — for camera rays that see it directly; None for other lights
    /// and textured emission (no closed form here: their rays sample wavelengths).
    pub fn direct_colour(&self, ng: Vec3, dir: Vec3) -> Option<[f32; 3]> {
        match self {
            Light::Area {
                colour: Some(c), ..
            } => Some(if ng.dot(-dir) > 0.0 { *c } else { [0.0; 3] }),
            _ => None,
        }
    }

    /// `out[i] +=` the radiance of this infinite light along `dirs[i]` at λ = `lambda[i]`,
    /// batched for environment maps; `d65[i]`: the D65 factor at those wavelengths
    /// ([`crate::spectrum::sampled::rgb_cmf_d65_f32`]), which the caller has already looked up.
    pub fn add_env_batch(&self, dirs: &[Vec3], lambda: &[Spec], d65: &[Spec], out: &mut [Spec]) {
        match self {
            Light::Env(e) => e.add_batch(dirs, lambda, d65, out),
            Light::Constant(s) => {
                for (o, l) in out.iter_mut().zip(lambda) {
                    *o += s.eval(&SampledWavelengths::new(l.to_array(), [1.0; 4]));
                }
            }
            _ => {}
        }
    }

    /// [`Self::add_env_batch`] on [`LANES`] lookups in struct-of-arrays form (see
    /// [`EnvMap::add_lanes`]), for the lanes marked `active`.
    pub fn add_env_lanes(
        &self,
        dir: &[[f32; LANES]; 3],
        lambda: &[[f32; LANES]; 4],
        d65: &[[f32; LANES]; 4],
        active: &[bool; LANES],
        out: &mut [[f32; LANES]; 4],
    ) {
        match self {
            Light::Env(e) => e.add_lanes(dir, lambda, d65, active, out),
            Light::Constant(s) => {
                for i in 0..LANES {
                    if active[i] {
                        let l = [0, 1, 2, 3].map(|k| lambda[k][i]);
                        let v = s.eval(&SampledWavelengths::new(l, [1.0; 4]));
                        for (k, row) in out.iter_mut().enumerate() {
                            row[i] += v[k];
                        }
                    }
                }
            }
            _ => {}
        }
    }

    /// [`Self::pdf_direction`] of a ray that escaped the scene along `dir` from `p` (a vertex
    /// in normal bin `bin`), from its texture coordinates `uv` on this environment map when
    /// they are already known.
    #[inline]
    pub fn pdf_escaped(&self, p: Vec3, dir: Vec3, uv: Option<Vec2>, bin: NormalBin) -> f32 {
        match (uv, self) {
            (Some(uv), Light::Env(e)) => e.pdf_uv(uv, bin),
            (None, Light::Env(e)) => e.pdf_direction(dir, bin),
            _ => self.pdf_direction(p, dir, f32::INFINITY, Vec3::ZERO),
        }
    }

    /// Solid-angle pdf of sampling `dir` from `p` (hit at distance `dist` with normal `n_light`
    /// for area lights); without the light-selection probability.
    #[inline]
    pub fn pdf_direction(&self, p: Vec3, dir: Vec3, dist: f32, n_light: Vec3) -> f32 {
        match self {
            Light::Env(e) => e.pdf_direction(dir, NormalBin::WHOLE_SPHERE),
            Light::Constant(_) => 1.0 / (4.0 * PI),
            Light::Point { .. }
            | Light::Spot(_)
            | Light::Directional { .. }
            | Light::Projector(_)
            | Light::TexturedSpot(_) => 0.0,
            Light::Area { geometry, .. } => {
                let pdf_area = match geometry {
                    AreaGeometry::Triangles { area, .. } => 1.0 / area,
                    AreaGeometry::Sphere {
                        center,
                        radius,
                        flip,
                    } => {
                        if let (false, Some((sin2, cos))) =
                            (*flip, sphere_cone((*center - p).length(), *radius))
                        {
                            return sphere_cone_pdf(sin2, cos);
                        }
                        1.0 / (4.0 * PI * radius * radius)
                    }
                };
                let cos_l = n_light.dot(-dir).abs();
                if cos_l.is_nan() || cos_l <= 0.0 {
                    return 0.0;
                }
                pdf_area * dist * dist / cos_l
            }
        }
    }

    /// Samples incident light at `p`; `pdf` without the light-selection probability.
    pub fn sample(&self, p: Vec3, u: Vec2, wl: &SampledWavelengths) -> Option<LightSample> {
        match self {
            Light::Env(e) => {
                let (wi, pdf) = e.sample_direction(u, NormalBin::WHOLE_SPHERE)?;
                Some(LightSample::from_infinity(wi, e.eval(wi, wl), pdf, false))
            }
            Light::Constant(s) => {
                let wi = square_to_uniform_sphere(u);
                Some(LightSample::from_infinity(
                    wi,
                    s.eval(wl),
                    1.0 / (4.0 * PI),
                    false,
                ))
            }
            Light::Point {
                position,
                intensity,
            } => {
                let d = *position - p;
                let dist2 = d.length_squared();
                if dist2 <= 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let radiance = intensity.eval(wl) / dist2;
                Some(LightSample::delta_at(*position, d / dist, dist, radiance))
            }
            Light::TexturedSpot(ts) => {
                let (spot, texture, uv_factor) = ts.as_ref();
                let d = spot.position - p;
                let (dist2, local) = (d.length_squared(), spot.to_local * -d);
                let f = spot.profile(local);
                // Mitsuba's `direction_to_uv` of the light-local direction towards p.
                let k = 0.5 / (local.z * uv_factor);
                let uv = Vec2::new(0.5 + k * local.x, 0.5 + k * local.y);
                let radiance = spot.intensity.eval(wl) * texture.eval(uv, wl) * (f / dist2);
                (f > 0.0 && dist2 > 0.0 && radiance.is_finite()).then(|| {
                    LightSample::delta_at(spot.position, d / dist2.sqrt(), dist2.sqrt(), radiance)
                })
            }
            Light::Projector(pr) => {
                let (wi, dist, radiance) = pr.incident(p, wl)?;
                Some(LightSample::delta_at(pr.position, wi, dist, radiance))
            }
            Light::Spot(spot) => {
                let d = spot.position - p;
                let dist2 = d.length_squared();
                if dist2.is_nan() || dist2 <= 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let f = spot.profile(spot.to_local * -wi) * range_window(spot.range, dist);
                if f.is_nan() || f <= 0.0 {
                    return None;
                }
                let radiance = spot.intensity.eval(wl) * (f / dist2);
                Some(LightSample::delta_at(spot.position, wi, dist, radiance))
            }
            Light::Directional {
                direction,
                irradiance,
            } => Some(LightSample::from_infinity(
                -*direction,
                irradiance.eval(wl),
                1.0,
                true,
            )),
            Light::Area {
                radiance,
                geometry,
                texture,
                ..
            } => {
                let mut uv = Vec2::ZERO;
                let (q, n, pdf) = match geometry {
                    AreaGeometry::Triangles {
                        tris,
                        normals,
                        dist,
                        area,
                    } => {
                        let (x, _, i) = dist.sample(u.x);
                        // Reuse the fractional position inside the chosen cell for one barycentric.
                        let n_cells = dist.len() as f32;
                        let ux = (x * n_cells - i as f32).clamp(0.0, 1.0);
                        let b = square_to_uniform_triangle(Vec2::new(ux, u.y));
                        let [a, bb, c] = tris[i];
                        let q = a * (1.0 - b.x - b.y) + bb * b.x + c * b.y;
                        if let Some(t) = texture {
                            uv = t.uv_at(i, b);
                        }
                        (q, normals[i], LightPdf::Area(1.0 / area))
                    }
                    AreaGeometry::Sphere {
                        center,
                        radius,
                        flip,
                    } => sample_sphere(p, *center, *radius, *flip, u)?,
                };
                let d = q - p;
                let dist2 = d.length_squared();
                if dist2.is_nan() || dist2 <= 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = n.dot(-wi);
                // Area lights emit from their front side only (Mitsuba `area`).
                if cos_l.is_nan() || cos_l <= 0.0 {
                    return None;
                }
                let pdf = match pdf {
                    LightPdf::Area(pdf_area) => pdf_area * dist2 / cos_l,
                    LightPdf::SolidAngle(pdf) => pdf,
                };
                Some(LightSample {
                    wi,
                    dist,
                    p_light: q,
                    n_light: n,
                    radiance: match texture {
                        Some(t) => t.radiance(uv, wl),
                        None => radiance.eval(wl),
                    },
                    pdf,
                    delta: false,
                })
            }
        }
    }
}

/// How a sampled point on an area light was drawn.
enum LightPdf {
    /// Uniformly by area: density per unit area.
    Area(f32),
    /// By solid angle seen from the reference point.
    SolidAngle(f32),
}

/// Sine and cosine of the half-angle of the cone a sphere subtends from a point at distance
/// `dist` from its centre (`None` inside or on it). 1 − cos α is written sin²α / (1 + cos α)
/// so that small, far spheres keep their precision.
fn sphere_cone(dist: f32, radius: f32) -> Option<(f32, f32)> {
    if dist.is_nan() || dist <= radius * (1.0 + 1e-4) {
        return None;
    }
    let sin2 = (radius / dist).powi(2);
    let cos = (1.0 - sin2).max(0.0).sqrt();
    Some((sin2, cos))
}

/// Solid-angle pdf of the cone sampling of [`sample_sphere`].
fn sphere_cone_pdf(sin2: f32, cos: f32) -> f32 {
    (1.0 + cos) / (2.0 * PI * sin2)
}

/// A point on a spherical emitter seen from `p`: uniform over the cone of directions the
/// sphere subtends when `p` is outside an outward-facing sphere (Mitsuba's and pbrt-v4's
/// `Sphere::Sample(ctx)`: every sample lands on the visible cap, so the noise of uniform-area
/// sampling, half of whose points face away, is gone); uniform by area otherwise.
fn sample_sphere(
    p: Vec3,
    center: Vec3,
    radius: f32,
    flip: bool,
    u: Vec2,
) -> Option<(Vec3, Vec3, LightPdf)> {
    let to_center = center - p;
    let dist = to_center.length();
    if let (false, Some((sin2, cos_alpha))) = (flip, sphere_cone(dist, radius)) {
        let axis = to_center / dist;
        let local = square_to_uniform_cone(u, cos_alpha);
        let dir = Frame::from_normal(axis).to_world(local);
        // Nearest intersection of the ray p + t·dir with the sphere (law of cosines), clamped
        // for directions at the cone's rim where rounding makes the discriminant negative.
        let cos_t = local.z;
        let disc = (radius * radius - dist * dist * (1.0 - cos_t * cos_t)).max(0.0);
        let t = dist * cos_t - disc.sqrt();
        let q = p + dir * t;
        let n = (q - center).normalize();
        return Some((q, n, LightPdf::SolidAngle(sphere_cone_pdf(sin2, cos_alpha))));
    }
    let n = square_to_uniform_sphere(u);
    Some((
        center + n * radius,
        if flip { -n } else { n },
        LightPdf::Area(1.0 / (4.0 * PI * radius * radius)),
    ))
}

/// All lights of a scene, with the shape → light map for emitters hit by BSDF sampling.
pub struct LightSet {
    pub lights: Vec<Light>,
    /// For each shape, the index of its area light.
    pub shape_light: Vec<Option<u32>>,
    /// Indices of infinite lights (seen when a ray escapes).
    pub infinite: Vec<u32>,
    /// Some material has alpha cut-outs that shadow rays pass ([`blocked_shadow_transmittance`]).
    pub see_through: bool,
    /// The constant environments' expected film colour, summed ([`ColourQuadrature`]).
    constant_rgb: [f32; 3],
}

impl LightSet {
    /// The light of scene emitter `i` (environment, constant, point, spot, projector,
    /// directional); errors name the emitter.
    fn emitter_light(i: usize, e: &EmitterDesc, lobes: &[f32]) -> anyhow::Result<Light> {
        Ok(match e {
            EmitterDesc::Envmap {
                image,
                scale,
                to_world,
                path,
            } => {
                let m = Mat3::from_mat4(*to_world);
                Light::Env(Box::new(EnvMap::new(image, *scale, m, lobes).map_err(
                    |err| {
                        anyhow::anyhow!(
                            "emitter {i} (envmap{}): {err}",
                            path.as_ref()
                                .map(|p| format!(" {}", p.display()))
                                .unwrap_or_default()
                        )
                    },
                )?))
            }
            EmitterDesc::Constant { radiance } => Light::Constant(Spectrum::illuminant(radiance)),
            EmitterDesc::Point {
                position,
                intensity,
            } => Light::Point {
                position: *position,
                intensity: Spectrum::illuminant(intensity),
            },
            EmitterDesc::Spot {
                to_world,
                intensity,
                cone,
                range,
            } => {
                let m = Mat3::from_mat4(*to_world);
                if !(to_world.is_finite() && m.determinant().abs() > 1e-12) {
                    anyhow::bail!("emitter {i} (spot): to_world is singular or not finite");
                }
                Light::Spot(Box::new(SpotLight::new(
                    *to_world,
                    Spectrum::illuminant(intensity),
                    *cone,
                    *range,
                )))
            }
            EmitterDesc::TexturedSpot {
                to_world,
                intensity,
                cone,
                texture,
            } => {
                let m = Mat3::from_mat4(*to_world);
                if !(to_world.is_finite() && m.determinant().abs() > 1e-12) {
                    anyhow::bail!("emitter {i} (spot): to_world is singular or not finite");
                }
                let SpotCone::Linear { cutoff, .. } = *cone else {
                    anyhow::bail!("emitter {i} (spot): a texture needs Mitsuba's cone");
                };
                let spot = SpotLight::new(*to_world, Spectrum::illuminant(intensity), *cone, None);
                let texture = super::texture::Texture::new(texture);
                Light::TexturedSpot(Box::new((spot, texture, cutoff.tan())))
            }
            EmitterDesc::Projector {
                to_world,
                irradiance,
                scale,
                tan_half_fov_x,
                aspect,
            } => {
                if !(to_world.is_finite() && to_world.determinant().abs() > 1e-12) {
                    anyhow::bail!("emitter {i} (projector): to_world is singular or not finite");
                }
                let value = match irradiance {
                    crate::scene::TextureDesc::Value(v) => Spectrum::illuminant(v),
                    _ => Spectrum::Constant(0.0),
                };
                Light::Projector(Box::new(ProjectorLight {
                    position: to_world.transform_point3(Vec3::ZERO),
                    axis: to_world.transform_vector3(Vec3::Z),
                    to_local: to_world.inverse(),
                    irradiance: super::texture::Texture::new(irradiance),
                    is_bitmap: !matches!(irradiance, crate::scene::TextureDesc::Value(_)),
                    irradiance_value: value,
                    scale: *scale,
                    tan_half_fov_x: *tan_half_fov_x,
                    aspect: *aspect,
                }))
            }
            EmitterDesc::Directional {
                direction,
                irradiance,
            } => {
                let d = direction.normalize_or_zero();
                if d == Vec3::ZERO || !d.is_finite() {
                    anyhow::bail!(
                        "emitter {i} (directional): direction {direction} is not a direction"
                    );
                }
                Light::Directional {
                    direction: d,
                    irradiance: Spectrum::illuminant(irradiance),
                }
            }
        })
    }

    /// The area light of shape `si`, if it emits: its geometry (sphere, or the mesh's
    /// triangles with an area-proportional sampling table) and its (textured) radiance.
    fn area_light(scene: &Scene, accel: &Accel, si: usize) -> anyhow::Result<Option<Light>> {
        let shape = &scene.shapes[si];
        let Some(radiance) = &shape.emission else {
            return Ok(None);
        };
        let geometry = match &shape.geometry {
            Geometry::Sphere {
                center,
                radius,
                flip_normals,
                ..
            } => AreaGeometry::Sphere {
                center: *center,
                radius: *radius,
                flip: *flip_normals,
            },
            Geometry::Mesh(_) => {
                let mesh = accel.mesh(si as u32).expect("mesh shape");
                let tris: Vec<[Vec3; 3]> = mesh
                    .indices
                    .iter()
                    .map(|i| i.map(|k| mesh.positions[k as usize]))
                    .collect();
                let areas: Vec<f32> = tris
                    .iter()
                    .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())
                    .collect();
                let area: f32 = areas.iter().filter(|a| a.is_finite()).sum();
                if area.is_nan() || area <= 0.0 {
                    anyhow::bail!("area light on shape {si} has zero surface area");
                }
                AreaGeometry::Triangles {
                    dist: Distribution1D::new(&areas),
                    normals: (tris.iter())
                        .map(|[a, b, c]| (*b - *a).cross(*c - *a).normalize())
                        .collect(),
                    tris,
                    area,
                }
            }
        };
        let texture = TexturedEmission::of_shape(scene, accel, si, radiance);
        let radiance = Spectrum::illuminant(radiance);
        let colour = texture.is_none().then(|| film_colour(&radiance));
        Ok(Some(Light::Area {
            shape: si as u32,
            radiance,
            colour,
            texture,
            geometry,
        }))
    }

    /// The scene's `<emitter>` lights (environment maps with their RGB → spectrum texels and
    /// sampling tables, delta lights), in order: they need no BVH, so [`super::prepare`]
    /// builds them on a second thread beside it.
    pub fn emitter_lights(scene: &Scene, lobes: &[f32]) -> anyhow::Result<Vec<Light>> {
        (scene.emitters.iter().enumerate())
            .map(|(i, e)| Self::emitter_light(i, e, lobes))
            .collect()
    }

    /// The light set: `emitters` ([`Self::emitter_lights`] of `scene`), then the area lights
    /// of the shapes.
    pub fn build(scene: &Scene, accel: &Accel, emitters: Vec<Light>) -> anyhow::Result<Self> {
        let mut lights = emitters;
        let mut shape_light = vec![None; scene.shapes.len()];
        for (si, slot) in shape_light.iter_mut().enumerate() {
            if let Some(light) = Self::area_light(scene, accel, si)? {
                *slot = Some(lights.len() as u32);
                lights.push(light);
            }
        }
        let infinite: Vec<u32> = lights
            .iter()
            .enumerate()
            .filter(|(_, l)| l.is_infinite())
            .map(|(i, _)| i as u32)
            .collect();
        let mut constant_rgb = [0.0f32; 3];
        for &li in &infinite {
            if let Light::Constant(s) = &lights[li as usize] {
                let rgb = film_colour(s);
                for (sum, c) in constant_rgb.iter_mut().zip(rgb) {
                    *sum += c;
                }
            }
        }
        Ok(LightSet {
            lights,
            shape_light,
            infinite,
            constant_rgb,
            see_through: scene
                .bsdfs
                .iter()
                .any(|b| alpha_coverage(b, Vec2::ZERO).is_some()),
        })
    }

    /// Whether every infinite light has its expected film colour in closed form
    /// ([`Self::add_background_colour_lanes`]): environment maps and constant environments.
    pub fn background_colour_in_closed_form(&self) -> bool {
        (self.infinite.iter())
            .all(|&li| matches!(self.lights[li as usize], Light::Env(_) | Light::Constant(_)))
    }

    /// `out[i] +=` the expected film colour (linear sRGB) of what lane i's ray sees when it
    /// escapes along `dir` (every infinite light), for the lanes `active`: the mean over the
    /// sampled wavelengths of the film value of [`Light::add_env_lanes`]' radiance. Only
    /// when [`Self::background_colour_in_closed_form`].
    pub fn add_background_colour_lanes(
        &self,
        dir: &[[f32; LANES]; 3],
        active: &[bool; LANES],
        out: &mut [[f32; 3]; LANES],
    ) {
        for &li in &self.infinite {
            if let Light::Env(e) = &self.lights[li as usize] {
                e.add_colour_lanes(dir, active, out);
            }
        }
        if self.constant_rgb != [0.0; 3] {
            for (o, _) in out.iter_mut().zip(active).filter(|(_, &a)| a) {
                for (o, c) in o.iter_mut().zip(self.constant_rgb) {
                    *o += c;
                }
            }
        }
    }

    /// The environment map that is the scene's only infinite light, if it is one: the
    /// escaped rays' texture coordinates can then be computed once for every lookup.
    pub fn sole_env(&self) -> Option<&EnvMap> {
        match self.infinite.as_slice() {
            [li] => match &self.lights[*li as usize] {
                Light::Env(e) => Some(e),
                _ => None,
            },
            _ => None,
        }
    }

    /// Starts the environment lookups (MIS pdf, radiance) of the rays that escaped the
    /// scene (`hits[i]` is None), before the lanes' vertices wait on them one by one.
    pub fn prefetch_escaped(&self, rays: &[Ray], hits: &[Option<super::accel::Hit>]) {
        for &li in &self.infinite {
            if let Light::Env(e) = &self.lights[li as usize] {
                for (ray, _) in rays.iter().zip(hits).filter(|(_, h)| h.is_none()) {
                    e.prefetch_lookup(ray.dir);
                }
            }
        }
    }

    /// Chooses a light (its index in `lights`) uniformly ([`Self::selection_pdf`]) with one
    /// sampler dimension, which is skipped when there is a single light so that the stream
    /// layout stays the same. The set must not be empty.
    #[inline]
    pub fn pick_index(&self, sampler: &mut super::sampler::Sampler) -> usize {
        let n = self.lights.len();
        if n == 1 {
            sampler.skip(1, 0);
            0
        } else {
            ((sampler.next_1d() * n as f32) as usize).min(n - 1)
        }
    }

    /// Probability of choosing any one light (uniform selection, as Mitsuba does).
    #[inline]
    pub fn selection_pdf(&self) -> f32 {
        if self.lights.is_empty() {
            0.0
        } else {
            1.0 / self.lights.len() as f32
        }
    }
}

// ---- Textured emission (glTF `emissiveTexture`; gltf branch, additive) ----

/// Per-texel emission of an area light on a triangle mesh: radiance = the emissive texture
/// (linear RGB, sRGB-decoded) × `scale` (glTF `emissiveFactor` × `emissiveStrength`) at the
/// surface's texture coordinates, upsampled as an illuminant (Mitsuba's `srgb_d65`, as every
/// RGB emitter). The light's points are still drawn uniformly by area, so the pdf of a point
/// (and of the direction a BSDF-sampled ray hits it from) stays the untextured one and MIS
/// stays exact; only the radiance is looked up at the point (sampled or hit).
#[derive(Debug, Clone)]
pub struct TexturedEmission {
    texture: std::sync::Arc<crate::scene::BitmapTexture>,
    scale: [f32; 3],
    /// Texture coordinates of each triangle's corners (the mesh's triangle order).
    uvs: Vec<[Vec2; 3]>,
}

impl TexturedEmission {
    /// The textured emission of shape `si` (emitting `radiance`), if its BSDF is a glTF
    /// material with an emissive texture and its mesh has texture coordinates.
    fn of_shape(
        scene: &Scene,
        accel: &Accel,
        si: usize,
        radiance: &crate::scene::SpectrumDesc,
    ) -> Option<Box<Self>> {
        let shape = &scene.shapes[si];
        let super::bsdf::Bsdf::GltfPbr(pbr) = scene.bsdfs.get(shape.bsdf)? else {
            return None;
        };
        let texture = pbr.material.emissive_texture.clone()?;
        let crate::scene::SpectrumDesc::Rgb(scale) = radiance else {
            return None;
        };
        let mesh = accel.mesh(si as u32)?;
        // Without texture coordinates a hit's UV is its barycentrics (Mitsuba's default
        // parameterisation, `Accel::interaction`): corners (0, 0), (1, 0), (0, 1).
        let uvs = if mesh.uvs.len() == mesh.positions.len() {
            let uv = |k: u32| mesh.uvs[k as usize];
            mesh.indices.iter().map(|t| t.map(uv)).collect()
        } else {
            vec![[Vec2::ZERO, Vec2::X, Vec2::Y]; mesh.indices.len()]
        };
        Some(Box::new(TexturedEmission {
            texture,
            scale: *scale,
            uvs,
        }))
    }

    /// Texture coordinates at barycentrics `b` (of corners 1 and 2) of triangle `tri`.
    #[inline]
    fn uv_at(&self, tri: usize, b: Vec2) -> Vec2 {
        let [t0, t1, t2] = self.uvs[tri];
        t0 * (1.0 - b.x - b.y) + t1 * b.x + t2 * b.y
    }

    /// Emitted radiance at texture coordinates `uv`.
    #[inline]
    fn radiance(&self, uv: Vec2, wl: &SampledWavelengths) -> Spec {
        let v = self.texture.eval(uv);
        let rgb = [0, 1, 2].map(|c| (self.scale[c] * v[c]).max(0.0));
        if rgb == [0.0; 3] {
            return Spec::ZERO;
        }
        RgbIlluminantSpectrum::new(rgb).eval4(Spec::from_array(wl.lambda))
    }
}

// ---- Shadow rays through alpha cut-outs (glTF alphaMode MASK/BLEND; gltf branch) ----

/// Most cut-out surfaces a shadow ray passes before it counts as blocked.
const MAX_ALPHA_CROSSINGS: u32 = 32;

/// The coverage (alpha) of `bsdf` at `uv` if it has alpha cut-outs (glTF MASK or BLEND),
/// None for every opaque model.
#[inline]
fn alpha_coverage(bsdf: &super::bsdf::Bsdf, uv: Vec2) -> Option<f32> {
    match bsdf {
        super::bsdf::Bsdf::GltfPbr(p) => p.coverage(uv),
        _ => None,
    }
}

/// Whether shadow rays pass (partly) through shape `shape` (its material has alpha
/// cut-outs): a path crossing it by the null lobe then keeps the MIS state of the vertex
/// before it, since light sampling from that vertex sees through it too.
#[inline]
pub(crate) fn passes_shadow_rays(scene: &super::PreparedScene, shape: u32) -> bool {
    let bsdf = &scene.bsdfs[scene.shape_bsdf[shape as usize] as usize];
    scene.lights().see_through && alpha_coverage(bsdf, Vec2::ZERO).is_some()
}

/// The fraction of light a blocked shadow ray carries to its end: the product of
/// (1 − coverage) over the alpha-cut-out surfaces it crosses (0 at an opaque one). A MASK surface is absent where alpha < cutoff and BLEND is stochastic
/// opacity, which the BSDF samples as a null lobe of weight 1 − coverage: the light
/// sample's (1 − coverage) is that lobe's expected value, so light sampling and BSDF
/// sampling see the same light through holes (the integrator keeps the MIS state of the
/// vertex before a null interaction). The common case costs one any-hit query as before:
/// this function is called only for a ray that query found blocked (the batch's shadow rays
/// are tested together, [`super::accel::Accel::occluded_batch`]).
pub(crate) fn blocked_shadow_transmittance(scene: &super::PreparedScene, ray: &Ray) -> f32 {
    if !scene.lights().see_through {
        return 0.0;
    }
    let mut r = *ray;
    let mut t = 1.0f32;
    for _ in 0..MAX_ALPHA_CROSSINGS {
        let Some(hit) = scene.intersect(&r, None) else {
            return t;
        };
        let si = scene.interaction(&r, &hit);
        match alpha_coverage(si.bsdf(), si.uv) {
            Some(c) if c < 1.0 => t *= 1.0 - c.max(0.0),
            _ => return 0.0,
        }
        // Past this hit (relative step: the ray's origin stays fixed).
        r.tmin = hit.t + 1e-5 * (1.0 + hit.t);
        if r.tmin >= r.tmax {
            return t;
        }
    }
    0.0
}

/// Environment lookups `items[i]` (directions or (u, v)), with the path's wavelengths
/// `lambda[i]` and D65 weights `d65[i]`, in groups of [`LANES`]: `lanes(group, λ, w,
/// active, sum)` adds the group's radiances to `sum` (struct-of-arrays; lanes past the
/// group are inactive, with λ = 500 nm and w = 0), which `out[i]` then accumulates.
fn in_lanes<T>(
    items: &[T],
    lambda: &[Spec],
    d65: &[Spec],
    out: &mut [Spec],
    mut lanes: impl FnMut(
        &[T],
        &[[f32; LANES]; 4],
        &[[f32; LANES]; 4],
        &[bool; LANES],
        &mut [[f32; LANES]; 4],
    ),
) {
    for (((items, lambdas), d65s), out) in (items.chunks(LANES))
        .zip(lambda.chunks(LANES))
        .zip(d65.chunks(LANES))
        .zip(out.chunks_mut(LANES))
    {
        let n = items.len();
        let mut l = [[500.0f32; LANES]; 4];
        let mut w = [[0.0f32; LANES]; 4];
        for i in 0..n {
            for k in 0..4 {
                l[k][i] = lambdas[i][k];
                w[k][i] = d65s[i][k];
            }
        }
        let mut active = [false; LANES];
        active[..n].fill(true);
        let mut sum = [[0.0f32; LANES]; 4];
        lanes(items, &l, &w, &active, &mut sum);
        for (i, o) in out.iter_mut().enumerate() {
            *o += Spec::new(sum[0][i], sum[1][i], sum[2][i], sum[3][i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atan2_fast_matches_std() {
        let mut worst = 0.0f32;
        for i in 0..=20_000 {
            let a = i as f32 / 20_000.0 * 2.0 * PI - PI;
            for r in [1e-30f32, 1e-3, 0.7, 1.0, 3e4] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let err = (atan2_fast(y, x) - y.atan2(x)).abs();
                worst = worst.max(err);
            }
        }
        // 2.5 ulp of π: the final π − r rounding dominates near ±π.
        assert!(worst < 6e-7, "max error {worst}");
        for (y, x) in [
            (0.0f32, 0.0f32),
            (-0.0, 0.0),
            (0.0, -0.0),
            (-0.0, -0.0),
            (0.0, -1.0),
        ] {
            assert_eq!(atan2_fast(y, x), y.atan2(x), "atan2({y}, {x})");
        }
        assert_eq!(atan2_fast(-0.0, -1.0), -PI);
        assert_eq!(atan2_fast(1.0, 0.0), std::f32::consts::FRAC_PI_2);
        assert!(atan2_fast(f32::NAN, 1.0).is_nan());
    }

    #[test]
    fn atan2_fast2_is_bit_identical_to_scalar() {
        let mut rng = crate::render::sampler::Sampler::from_seed(11);
        let specials = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            1e-30,
            -1e-30,
            f32::NAN,
            f32::INFINITY,
        ];
        for i in 0..20_000 {
            let mut v = [0.0f32; 4];
            for c in &mut v {
                *c = (rng.next_1d() - 0.5) * 4.0;
            }
            if i % 5 == 0 {
                v[i % 4] = specials[(i / 5) % specials.len()];
            }
            let (a, b) = atan2_fast2(v[0], v[1], v[2], v[3]);
            let (ra, rb) = (atan2_fast(v[0], v[1]), atan2_fast(v[2], v[3]));
            assert_eq!(
                (a.to_bits(), b.to_bits()),
                (ra.to_bits(), rb.to_bits()),
                "{v:?}: {a} {b} vs {ra} {rb}"
            );
        }
    }

    #[test]
    fn distribution_1d_guide_search_equals_bisection() {
        // Smooth, peaked, zero runs, all-zero and one-cell functions; u on a fine grid plus
        // the edges and cdf values themselves (ties decide which cell a sample lands in).
        let mut funcs: Vec<Vec<f32>> = vec![
            (0..513).map(|i| 1.0 + (i as f32 * 0.1).sin()).collect(),
            (0..300).map(|i| if i == 77 { 1e6 } else { 1e-6 }).collect(),
            (0..64)
                .map(|i| if i % 7 < 4 { 0.0 } else { i as f32 })
                .collect(),
            vec![0.0; 10],
            vec![2.5],
        ];
        funcs.push((0..1000).map(|i| ((i * 7919) % 101) as f32).collect());
        for f in funcs {
            let d = Distribution1D::new(&f);
            let mut us: Vec<f32> = (0..=4096).map(|i| i as f32 / 4096.0).collect();
            let cdf: Vec<f32> = d.cells.iter().map(|c| c.cdf).collect();
            us.extend(cdf.iter().copied());
            us.extend([1.0 - f32::EPSILON, -0.0, 1.5, -1.0, f32::NAN]);
            for u in us {
                let expected = cdf.partition_point(|&c| c <= u);
                assert_eq!(d.search(u), expected, "len {} u {u}", f.len());
            }
        }
    }

    #[test]
    fn distribution_1d_samples_proportionally() {
        let d = Distribution1D::new(&[1.0, 3.0, 0.0, 4.0]);
        let (x, pdf, i) = d.sample(0.05);
        assert_eq!(i, 0);
        assert!((pdf - 0.5).abs() < 1e-6 && x < 0.25);
        let (_, _, i) = d.sample(0.49);
        assert_eq!(i, 1);
        let (_, _, i) = d.sample(0.9);
        assert_eq!(i, 3);
        assert_eq!(d.pdf(0.6), 0.0);
        assert!((d.pdf(0.9) - 2.0).abs() < 1e-6);
    }

    fn test_env() -> EnvMap {
        let mut img = RgbImage::new(16, 9);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            let v = 0.1 + (i % 7) as f32;
            *p = [v, 0.5 * v, 0.2];
        }
        EnvMap::new(&img, 1.0, Mat3::from_rotation_y(0.3), &[]).unwrap()
    }

    /// Camera rays that see the map take the texels' closed-form colour: for every
    /// direction it is the mean of the film value of the spectral lookup ([`EnvMap::eval`])
    /// over 4096 stratified wavelength sets, to 1e-4 of its size — on smooth, saturated
    /// (large sigmoid coefficients), black and bright texels, across the seam and the poles.
    /// NaN directions add nothing, as their spectral lookup; inactive lanes are left alone.
    #[test]
    fn closed_form_colour_is_the_spectral_lookups_mean() {
        use crate::spectrum::sampled::spectrum_to_linear_srgb;
        let mut img = RgbImage::new(7, 4);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = match i % 5 {
                0 => [40.0, 0.0, 0.0],
                1 => [0.0, 0.0, 0.0],
                2 => [0.0, 3.0, 1e-4],
                3 => [0.9, 0.9, 0.9],
                _ => [0.2, 0.05, 0.6],
            };
        }
        let envs = [
            test_env(),
            EnvMap::new(&img, 2.5, Mat3::IDENTITY, &[]).unwrap(),
        ];
        let mut rng = crate::render::sampler::Sampler::from_seed(11);
        let mut dirs: Vec<Vec3> = (0..60)
            .map(|_| {
                let u = rng.next_2d();
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        dirs.extend([
            Vec3::Y,
            -Vec3::Y,
            Vec3::new(-1e-7, 0.0, -1.0),
            Vec3::new(0.0, 0.0, 1.0),
        ]);
        dirs.push(Vec3::new(f32::NAN, 0.0, 1.0));
        let n = 4096;
        for env in &envs {
            for chunk in dirs.chunks(LANES) {
                let mut d = [[0.0f32; LANES]; 3];
                let mut active = [false; LANES];
                for (i, v) in chunk.iter().enumerate() {
                    (d[0][i], d[1][i], d[2][i]) = (v.x, v.y, v.z);
                    active[i] = i % 7 != 6;
                }
                let mut got = [[0.5f32; 3]; LANES];
                env.add_colour_lanes(&d, &active, &mut got);
                for (i, &dir) in chunk.iter().enumerate() {
                    let mut mean = [0.0f64; 3];
                    for j in 0..n {
                        let wl = SampledWavelengths::sample_visible((j as f32 + 0.5) / n as f32);
                        let rgb = spectrum_to_linear_srgb(env.eval(dir, &wl), &wl);
                        for c in 0..3 {
                            mean[c] += rgb[c] as f64 / n as f64;
                        }
                    }
                    let size = mean.iter().fold(1e-6f64, |m, v| m.max(v.abs()));
                    for c in 0..3 {
                        let added = got[i][c] as f64 - 0.5;
                        let want = if active[i] { mean[c] } else { 0.0 };
                        assert!(
                            (added - want).abs() <= 1e-4 * size + 1e-6,
                            "{dir}: channel {c}: {added} vs {want}"
                        );
                    }
                }
            }
        }
    }

    /// The reciprocal-square-root form of a texel's colour agrees with the exact sigmoid
    /// to 4e-6 of its size (f32 sums of ~950 terms in both), for smooth, steep and flat coefficients; a sigmoid whose
    /// argument overflows is left to the exact form.
    #[test]
    fn fast_texel_colour_matches_the_exact_form() {
        let nodes = ColourNodes::with_d65();
        let mut rng = crate::render::sampler::Sampler::from_seed(3);
        for k in 0..500 {
            let rgb = [rng.next_1d(), rng.next_1d(), rng.next_1d()].map(|v| v * v * 4.0);
            let rgb = if k % 10 == 0 { [rgb[0], 0.0, 0.0] } else { rgb };
            let c = RgbIlluminantSpectrum::new(rgb).poly.c;
            let exact = nodes.sigmoid_colour_exact(c);
            let fast = nodes.sigmoid_colour(c);
            let size = exact.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
            for ch in 0..3 {
                assert!(
                    (fast[ch] - exact[ch]).abs() <= 4e-6 * size,
                    "{rgb:?} {c:?}: {fast:?} vs {exact:?}"
                );
            }
        }
        for c in [
            RgbSigmoidPolynomial::BLACK.c,
            RgbSigmoidPolynomial::WHITE.c,
            [1e18, 0.0, 0.0],
        ] {
            let exact = nodes.sigmoid_colour_exact(c);
            assert_eq!(nodes.sigmoid_colour(c), exact, "{c:?}");
            assert!(exact.iter().all(|v| v.is_finite()), "{c:?}: {exact:?}");
        }
    }

    /// The batched lookup gives every lane exactly the scalar lookup's value: random
    /// directions, the poles, the seam, axis directions, NaN and zero directions, and
    /// batches of every length (partial chunks).
    #[test]
    fn batched_lookup_is_bit_identical() {
        let mut envs = vec![test_env()];
        // Saturated texels (large sigmoid coefficients) and a black one.
        let mut img = RgbImage::new(7, 4);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = match i % 4 {
                0 => [40.0, 0.0, 0.0],
                1 => [0.0, 0.0, 0.0],
                2 => [0.0, 3.0, 1e-4],
                _ => [0.2, 0.2, 0.2],
            };
        }
        envs.push(EnvMap::new(&img, 2.5, Mat3::IDENTITY, &[]).unwrap());
        let mut rng = crate::render::sampler::Sampler::from_seed(5);
        let mut dirs = Vec::new();
        for _ in 0..997 {
            let u = rng.next_2d();
            let z = 1.0 - 2.0 * u.x;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * PI * u.y;
            dirs.push(Vec3::new(r * phi.cos(), r * phi.sin(), z));
        }
        dirs.extend([
            Vec3::Y,
            -Vec3::Y,
            Vec3::X,
            -Vec3::X,
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(1e-30, 1.0, 0.0),
            Vec3::new(-1e-7, 0.0, -1.0),
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::ZERO,
            Vec3::new(3.0, -4.0, 12.0),
        ]);
        let wls: Vec<SampledWavelengths> = (0..dirs.len())
            .map(|i| SampledWavelengths::sample_visible((i as f32 * 0.618_034).fract()))
            .collect();
        let lambda: Vec<Spec> = wls.iter().map(|w| Spec::from_array(w.lambda)).collect();
        let d65: Vec<Spec> = wls
            .iter()
            .map(|w| {
                Spec::from_array(
                    w.lambda
                        .map(|l| crate::spectrum::sampled::rgb_cmf_d65_f32(l)[3]),
                )
            })
            .collect();
        for env in &envs {
            for len in [1, 3, LANES, LANES + 1, dirs.len()] {
                for start in (0..dirs.len()).step_by(len.max(97)) {
                    let end = (start + len).min(dirs.len());
                    let mut out = vec![Spec::splat(0.25); end - start];
                    env.add_batch(
                        &dirs[start..end],
                        &lambda[start..end],
                        &d65[start..end],
                        &mut out,
                    );
                    // The same lookups at texture coordinates computed in SIMD lanes.
                    let mut uvs = vec![Vec2::ZERO; end - start];
                    env.uvs_prefetch(&dirs[start..end], &mut uvs, start % 2 == 0);
                    let mut out_uv = vec![Spec::splat(0.25); end - start];
                    env.add_batch_uv(&uvs, &lambda[start..end], &d65[start..end], &mut out_uv);
                    let same =
                        |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
                    for (i, (o, o_uv)) in out.iter().zip(&out_uv).enumerate() {
                        let d = dirs[start + i];
                        let want = Spec::splat(0.25) + env.eval(d, &wls[start + i]);
                        let b = want.to_array();
                        for a in [o.to_array(), o_uv.to_array()] {
                            assert!(
                                a.iter().zip(&b).all(|(x, y)| same(*x, *y)),
                                "{d:?}: batched {a:?} vs scalar {b:?}"
                            );
                        }
                        let (uv, want_uv) = (uvs[i], env.uv_of(d));
                        assert!(same(uv.x, want_uv.x) && same(uv.y, want_uv.y), "{d:?}");
                        let bin = NormalBin::of(d);
                        assert!(
                            same(env.pdf_uv(uv, bin), env.pdf_direction(d, bin)),
                            "{d:?}"
                        );
                    }
                }
            }
        }
    }

    /// ∫ pdf dω = 1 over the sphere, and sampled directions report the pdf the lookup gives.
    #[test]
    fn envmap_pdf_integrates_to_one_and_matches_sampling() {
        let env = test_env();
        for bin in [
            NormalBin::WHOLE_SPHERE,
            NormalBin::of(Vec3::Y),
            NormalBin::of(-Vec3::X),
        ] {
            let sum = sphere_integral(300, |d| env.pdf_direction(d, bin));
            assert!((sum - 1.0).abs() < 0.01, "{bin:?}: {sum}");
            let mut s = crate::render::sampler::Sampler::from_seed(3);
            for _ in 0..1000 {
                if let Some((d, pdf, uv)) = env.sample_direction_uv(s.next_2d(), bin) {
                    // The tables agree exactly. From the direction, `uv_of` finds θ from its
                    // y, and φ is ill-conditioned, within ~0.01 of a pole: a neighbour cell's
                    // density there (MIS weights off in a negligible solid angle).
                    let (p_uv, p_dir) = (env.pdf_uv(uv, bin), env.pdf_direction(d, bin));
                    assert!((pdf - p_uv).abs() <= 1e-5 * pdf, "{bin:?}: {pdf} vs {p_uv}");
                    if (0.01..0.99).contains(&uv.y) {
                        let (a, b) = (pdf, p_dir);
                        assert!((a - b).abs() <= 1e-3 * a, "{bin:?}: {a} vs {b}");
                    }
                }
            }
        }
    }

    /// ∫ f dω over the sphere, midpoint rule on an n × 2n (θ, φ) grid.
    fn sphere_integral(n: usize, f: impl Fn(Vec3) -> f32) -> f64 {
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..2 * n {
                let d = grid_direction(n, i, j);
                let theta = PI * (i as f32 + 0.5) / n as f32;
                let dw = (PI / n as f32) * (2.0 * PI / (2 * n) as f32) * theta.sin();
                sum += (f(d) * dw) as f64;
            }
        }
        sum
    }

    fn grid_direction(n: usize, i: usize, j: usize) -> Vec3 {
        let theta = PI * (i as f32 + 0.5) / n as f32;
        let phi = 2.0 * PI * (j as f32 + 0.5) / (2 * n) as f32;
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    }

    /// A studio-like map (a small bright sun, a sky gradient, a dark ground; turned), with
    /// tables for the glossy lobe widths `lobes`.
    fn studio_like_map(lobes: &[f32]) -> EnvMap {
        let (w, h) = (64, 32);
        let mut img = RgbImage::new(w, h);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            *p = if y >= h / 2 {
                [0.05, 0.04, 0.03]
            } else if (10..13).contains(&x) && (9..12).contains(&y) {
                [80.0, 75.0, 60.0]
            } else {
                let t = y as f32 / h as f32;
                [0.3 + t, 0.4 + t, 0.8 + 0.5 * t]
            };
        }
        let to_world = Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(0.2);
        EnvMap::new(&img, 1.0, to_world, lobes).unwrap()
    }

    /// Checks sampling bin `bin` of `env`: its density integrates to 1, is what its samples
    /// report, is positive wherever the radiance-only density is (no light lost), and its
    /// samples fall in 16 regions of the sphere as often as its integral there says (within
    /// 5σ + 0.2 %). Returns the bin's probability of a direction within `cone` (cosine) of
    /// `axis`, and the radiance-only one's; fewer than 3 % of its samples land behind `axis`
    /// (axis · ω < −0.2), and under 0.3 × the radiance-only share there.
    fn check_bin(env: &EnvMap, bin: NormalBin, axis: Vec3, cone: f32, seed: u64) -> (f64, f64) {
        let mut s = crate::render::sampler::Sampler::from_seed(seed);
        let region = |d: Vec3| {
            ((d.y * 0.499 + 0.5) * 4.0) as usize * 4
                + ((d.x.atan2(d.z) / PI * 0.499 + 0.5) * 4.0) as usize
        };
        let sum = sphere_integral(400, |d| env.pdf_direction(d, bin));
        assert!((sum - 1.0).abs() < 0.01, "{axis}: ∫ pdf = {sum}");
        let mut expected = [0.0f64; 16];
        let (mut below, mut near) = ([0.0f64; 2], [0.0f64; 2]);
        let n_grid = 400;
        for i in 0..n_grid {
            for j in 0..2 * n_grid {
                let d = grid_direction(n_grid, i, j);
                let (p, plain) = (
                    env.pdf_direction(d, bin),
                    env.pdf_direction(d, NormalBin::WHOLE_SPHERE),
                );
                assert!(
                    p > 0.0 || plain == 0.0,
                    "{axis}: no density at {d} (radiance-only {plain})"
                );
                let theta = PI * (i as f32 + 0.5) / n_grid as f32;
                let dw = ((PI / n_grid as f32) * (PI / n_grid as f32) * theta.sin()) as f64;
                expected[region(d)] += p as f64 * dw;
                if axis.dot(d) < -0.2 {
                    below[0] += p as f64 * dw;
                    below[1] += plain as f64 * dw;
                }
                if axis.dot(d) > cone {
                    near[0] += p as f64 * dw;
                    near[1] += plain as f64 * dw;
                }
            }
        }
        assert!(
            below[0] < 0.03 && below[0] < 0.3 * below[1],
            "{axis}: mass behind {below:?}"
        );
        let draws = 200_000;
        let mut seen = [0u32; 16];
        for _ in 0..draws {
            let u = s.next_2d();
            let Some((d, pdf, uv)) = env.sample_direction_uv(u, bin) else {
                continue;
            };
            let p2 = env.pdf_uv(uv, bin);
            assert!(
                (pdf - p2).abs() <= 1e-5 * pdf,
                "{axis}: sampled pdf {pdf} vs {p2}"
            );
            seen[region(d)] += 1;
        }
        for (k, (&c, &e)) in seen.iter().zip(&expected).enumerate() {
            let f = c as f64 / draws as f64;
            let sigma = (e * (1.0 - e) / draws as f64).sqrt();
            assert!(
                (f - e).abs() < 5.0 * sigma + 0.002,
                "{axis}: region {k}: {f} drawn vs {e}"
            );
        }
        (near[0], near[1])
    }

    /// Normals and mirror directions the bin tests check.
    fn checked_directions() -> [Vec3; 5] {
        [
            Vec3::Y,
            -Vec3::Y,
            Vec3::X,
            Vec3::new(0.3, 0.5, -0.8).normalize(),
            Vec3::new(-0.6, -0.1, 0.79).normalize(),
        ]
    }

    /// Hemisphere-aware sampling ([`NormalBin`]) on [`studio_like_map`]: for normals all over
    /// the sphere, each bin passes [`check_bin`] (few samples where the normal's surface
    /// cannot receive light, where radiance-only sampling puts many).
    #[test]
    fn hemisphere_sampling_is_a_density_that_matches_its_samples() {
        let env = studio_like_map(&[]);
        for n in checked_directions() {
            check_bin(&env, NormalBin::of(n), n, 1.0, 9);
        }
    }

    /// Mirror-direction bins of glossy lobes (α 0.15 and 0.3, [`NormalBin::of_lobe`]) on
    /// [`studio_like_map`]: each passes [`check_bin`] about its mirror direction, and a lobe
    /// whose mirror direction is in the sky, far from the bright patch, draws over half its
    /// samples within 25° of it: more than twice the normal bin of that direction, ten times
    /// radiance-only sampling.
    #[test]
    fn lobe_bins_are_densities_that_favour_their_mirror_direction() {
        let env = studio_like_map(&[0.15, 0.3]);
        for family in 0..2 {
            for r in checked_directions() {
                check_bin(&env, NormalBin::of_lobe(family, r), r, 1.0, 11);
            }
        }
        // A mirror direction in the sky, far from the bright patch (texels 10–12, 9–11).
        let (u, v) = (0.6f32, 0.3f32);
        let (st, ct) = (PI * v).sin_cos();
        let (sp, cp) = (2.0 * PI * u).sin_cos();
        let sky = (env.to_world * Vec3::new(st * sp, ct, -st * cp)).normalize();
        let cone = 25f32.to_radians().cos();
        let (lobe, plain) = check_bin(&env, NormalBin::of_lobe(0, sky), sky, cone, 12);
        let (normal, _) = check_bin(&env, NormalBin::of(sky), sky, cone, 13);
        // (Measured: 0.63, 0.24, 0.024: the patch's share of a lobe bin is its brightness
        // times the lobe's tail there.)
        assert!(
            lobe > 0.5 && lobe > 2.0 * normal && lobe > 10.0 * plain,
            "within 25° of a mirror direction in the sky: lobe bin {lobe}, normal bin {normal}, radiance-only {plain}"
        );
    }

    #[test]
    fn envmap_orientation_matches_mitsuba() {
        let env = EnvMap::new(&RgbImage::new(8, 5), 1.0, Mat3::IDENTITY, &[]).unwrap();
        let uv = env.uv_of(Vec3::new(0.0, 0.0, -1.0));
        assert!(uv.x.abs() < 1e-6 && (uv.y - 0.5).abs() < 1e-6);
        let uv = env.uv_of(Vec3::X);
        assert!((uv.x - 0.25).abs() < 1e-6);
        let uv = env.uv_of(Vec3::Z);
        assert!((uv.x - 0.5).abs() < 1e-6);
        assert!(env.uv_of(Vec3::Y).y.abs() < 1e-6);
    }
}
