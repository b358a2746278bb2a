//! Thickness tables: with the film index and the nuisance terms fixed, every whitened
//! model sample m(d) = w·s·R(d) (angle, band — band integration, polarisation, spectral
//! multiplier s and noise weight w folded in) depends on d alone. Tabulating m(d) and
//! dm/dd once on a fine d grid turns the per-pixel thickness fit into table work:
//!
//! - the coarse scan scores a node with one dot product per angle (m·y), Σm² being
//!   precomputed per node and angle;
//! - Gauss–Newton evaluates m and dm/dd anywhere by cubic Hermite interpolation between
//!   nodes (values and derivatives both tabulated, so the interpolant is C¹ and its
//!   error is O(h⁴ m'''') — with 64 nodes per fringe of the fastest sample, ≈ 2·10⁻⁷ of
//!   the fringe amplitude, far below f32 noise of the model itself).
//!
//! Rows are padded with zeros to a multiple of 8 bands ([`padded_bands`]) so every angle's
//! run is whole SIMD vectors; the caller's data rows are padded the same way.
//!
//! What a pass returns are the five per-angle sums the profiled objective needs
//! ([`AngleSums`]): with a free gain g per pixel and angle, g = m·y / m·m is eliminated
//! analytically (variable projection) — see [`AngleSums::combine`].

use rayon::prelude::*;

/// Bands rounded up to a multiple of 8 (row length of tables and pixel buffers).
pub fn padded_bands(bands: usize) -> usize {
    bands.div_ceil(8) * 8
}

/// Whether each pixel-angle spectrum has its own free scale factor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GainMode {
    /// Absolute radiometry: model = data scale.
    Unit,
    /// A free gain g ≥ 0 per pixel and angle, eliminated analytically.
    Free,
}

/// Σ m·y, Σ m·m, Σ m'·y, Σ m'·m, Σ m'·m' over one angle's bands (m' = dm/dd).
#[derive(Debug, Clone, Copy, Default)]
pub struct AngleSums {
    pub my: f32,
    pub mm: f32,
    pub dy: f32,
    pub dm: f32,
    pub dd: f32,
}

/// Objective, half-gradient and Gauss–Newton Hessian in d over a pixel's angles.
#[derive(Debug, Clone, Copy, Default)]
pub struct PassSums {
    /// Σ (y − g m)² over used samples (whitened units).
    pub sse: f64,
    /// ½ ∂sse/∂d.
    pub grad: f64,
    /// Gauss–Newton Hessian (Kaufman's approximation when the gain is eliminated).
    pub hess: f64,
    pub count: usize,
}

impl AngleSums {
    /// The five sums from per-lane partial sums (my, mm, dy, dm, dd), each lane array
    /// added in order.
    #[inline]
    fn from_lanes<const N: usize>(lanes: &[[f32; N]; 5]) -> Self {
        let s = |i: usize| lanes[i].iter().sum::<f32>();
        AngleSums {
            my: s(0),
            mm: s(1),
            dy: s(2),
            dm: s(3),
            dd: s(4),
        }
    }

    /// Adds this angle's contribution for data energy `yy` = Σy² and derivative scale
    /// `rho` (dm/dd of the pixel = rho · tabulated dm/dd; 1 unless the pixel has its own
    /// incidence angle). With a free gain, g = max(0, m·y / m·m) and the residual is
    /// y − g m: sse = yy − g m·y; ½ sse' = −g (m'·y − g m'·m) (the gain's own derivative
    /// drops out at its optimum); Kaufman's Gauss–Newton Hessian g² (m'·m' − (m'·m)²/m·m)
    /// is that of the residual projected off m.
    #[inline]
    pub fn combine(&self, yy: f32, rho: f32, gain: GainMode, out: &mut PassSums) {
        let (my, mm) = (self.my as f64, self.mm as f64);
        let (dy, dm, dd) = (
            (self.dy * rho) as f64,
            (self.dm * rho) as f64,
            (self.dd * rho * rho) as f64,
        );
        let yy = yy as f64;
        match gain {
            GainMode::Unit => {
                out.sse += (yy - 2.0 * my + mm).max(0.0);
                out.grad += -(dy - dm);
                out.hess += dd;
            }
            GainMode::Free => {
                let g = if mm > 0.0 { (my / mm).max(0.0) } else { 0.0 };
                out.sse += (yy - g * my).max(0.0);
                if g > 0.0 {
                    out.grad += -g * (dy - g * dm);
                    out.hess += g * g * (dd - dm * dm / mm).max(0.0);
                }
            }
        }
    }

    /// Gain of this angle's fit (1 for [`GainMode::Unit`]).
    pub fn gain(&self, gain: GainMode) -> f32 {
        match gain {
            GainMode::Unit => 1.0,
            GainMode::Free if self.mm > 0.0 => (self.my / self.mm).max(0.0),
            GainMode::Free => 0.0,
        }
    }
}

/// The five sums over `y` with m, m' interpolated from two nodes' values (`r0`, `r1`) and
/// h-scaled derivatives (`d0`, `d1`); `b` = Hermite basis for m (0..4) and m' (4..8).
/// This is the inner loop of the whole thickness stage, so on x86-64 it is written with
/// SIMD intrinsics: AVX2+FMA when the CPU has them (checked at run time), else SSE2, which
/// every x86-64 CPU has. Lengths are multiples of 8 ([`padded_bands`]).
#[inline]
pub fn hermite_sums(
    y: &[f32],
    r0: &[f32],
    d0: &[f32],
    r1: &[f32],
    d1: &[f32],
    b: &[f32; 8],
) -> AngleSums {
    let n = y.len();
    assert!(
        n % 8 == 0 && r0.len() >= n && d0.len() >= n && r1.len() >= n && d1.len() >= n,
        "hermite_sums: rows must be padded to 8 bands"
    );
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: AVX2 and FMA are present (checked above); lengths checked above.
            return unsafe { x86::hermite_sums_avx2(y, r0, d0, r1, d1, b) };
        }
        // SAFETY: SSE2 is part of the x86-64 baseline; lengths checked above.
        return unsafe { x86::hermite_sums_sse2(y, r0, d0, r1, d1, b) };
    }
    #[allow(unreachable_code)]
    hermite_sums_scalar(y, r0, d0, r1, d1, b)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::AngleSums;
    use std::arch::x86_64::*;

    /// # Safety
    /// The CPU must support AVX2 and FMA; every slice at least `y.len()` long, a multiple of 8.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn hermite_sums_avx2(
        y: &[f32],
        r0: &[f32],
        d0: &[f32],
        r1: &[f32],
        d1: &[f32],
        b: &[f32; 8],
    ) -> AngleSums {
        let bb: [__m256; 8] = std::array::from_fn(|k| _mm256_set1_ps(b[k]));
        let z = _mm256_setzero_ps();
        let (mut my, mut mm, mut dy, mut dm, mut dd) = (z, z, z, z, z);
        let mut j = 0;
        while j < y.len() {
            // SAFETY: j + 8 ≤ y.len() ≤ every slice's length.
            let (yv, a0, b0, a1, b1) = unsafe {
                (
                    _mm256_loadu_ps(y.as_ptr().add(j)),
                    _mm256_loadu_ps(r0.as_ptr().add(j)),
                    _mm256_loadu_ps(d0.as_ptr().add(j)),
                    _mm256_loadu_ps(r1.as_ptr().add(j)),
                    _mm256_loadu_ps(d1.as_ptr().add(j)),
                )
            };
            let m = _mm256_fmadd_ps(
                bb[3],
                b1,
                _mm256_fmadd_ps(
                    bb[2],
                    a1,
                    _mm256_fmadd_ps(bb[1], b0, _mm256_mul_ps(bb[0], a0)),
                ),
            );
            let dv = _mm256_fmadd_ps(
                bb[7],
                b1,
                _mm256_fmadd_ps(
                    bb[6],
                    a1,
                    _mm256_fmadd_ps(bb[5], b0, _mm256_mul_ps(bb[4], a0)),
                ),
            );
            my = _mm256_fmadd_ps(m, yv, my);
            mm = _mm256_fmadd_ps(m, m, mm);
            dy = _mm256_fmadd_ps(dv, yv, dy);
            dm = _mm256_fmadd_ps(dv, m, dm);
            dd = _mm256_fmadd_ps(dv, dv, dd);
            j += 8;
        }
        let mut lanes = [[0f32; 8]; 5];
        // SAFETY: each destination holds 8 f32.
        unsafe {
            for (o, v) in lanes.iter_mut().zip([my, mm, dy, dm, dd]) {
                _mm256_storeu_ps(o.as_mut_ptr(), v);
            }
        }
        AngleSums::from_lanes(&lanes)
    }

    /// # Safety
    /// Every slice at least `y.len()` long, a multiple of 4 (SSE2 is always present).
    pub unsafe fn hermite_sums_sse2(
        y: &[f32],
        r0: &[f32],
        d0: &[f32],
        r1: &[f32],
        d1: &[f32],
        b: &[f32; 8],
    ) -> AngleSums {
        let bb: [__m128; 8] = std::array::from_fn(|k| _mm_set1_ps(b[k]));
        let z = _mm_setzero_ps();
        let (mut my, mut mm, mut dy, mut dm, mut dd) = (z, z, z, z, z);
        let mut j = 0;
        while j < y.len() {
            // SAFETY: j + 4 ≤ y.len() ≤ every slice's length.
            let (yv, a0, b0, a1, b1) = unsafe {
                (
                    _mm_loadu_ps(y.as_ptr().add(j)),
                    _mm_loadu_ps(r0.as_ptr().add(j)),
                    _mm_loadu_ps(d0.as_ptr().add(j)),
                    _mm_loadu_ps(r1.as_ptr().add(j)),
                    _mm_loadu_ps(d1.as_ptr().add(j)),
                )
            };
            let m = _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(bb[0], a0), _mm_mul_ps(bb[1], b0)),
                _mm_add_ps(_mm_mul_ps(bb[2], a1), _mm_mul_ps(bb[3], b1)),
            );
            let dv = _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(bb[4], a0), _mm_mul_ps(bb[5], b0)),
                _mm_add_ps(_mm_mul_ps(bb[6], a1), _mm_mul_ps(bb[7], b1)),
            );
            my = _mm_add_ps(my, _mm_mul_ps(m, yv));
            mm = _mm_add_ps(mm, _mm_mul_ps(m, m));
            dy = _mm_add_ps(dy, _mm_mul_ps(dv, yv));
            dm = _mm_add_ps(dm, _mm_mul_ps(dv, m));
            dd = _mm_add_ps(dd, _mm_mul_ps(dv, dv));
            j += 4;
        }
        let mut lanes = [[0f32; 4]; 5];
        // SAFETY: each destination holds 4 f32.
        unsafe {
            for (o, v) in lanes.iter_mut().zip([my, mm, dy, dm, dd]) {
                _mm_storeu_ps(o.as_mut_ptr(), v);
            }
        }
        AngleSums::from_lanes(&lanes)
    }
}

/// Portable [`hermite_sums`] (four lanes per sum, so the compiler may vectorise it).
// The lane index addresses five accumulators at once.
#[allow(clippy::needless_range_loop)]
#[inline]
fn hermite_sums_scalar(
    y: &[f32],
    r0: &[f32],
    d0: &[f32],
    r1: &[f32],
    d1: &[f32],
    b: &[f32; 8],
) -> AngleSums {
    const L: usize = 4;
    let mut acc = [[0f32; L]; 5];
    for j in (0..y.len()).step_by(L) {
        for i in 0..L {
            let k = j + i;
            if k >= y.len() {
                break;
            }
            let m = b[0] * r0[k] + b[1] * d0[k] + b[2] * r1[k] + b[3] * d1[k];
            let dv = b[4] * r0[k] + b[5] * d0[k] + b[6] * r1[k] + b[7] * d1[k];
            acc[0][i] += m * y[k];
            acc[1][i] += m * m;
            acc[2][i] += dv * y[k];
            acc[3][i] += dv * m;
            acc[4][i] += dv * dv;
        }
    }
    AngleSums::from_lanes(&acc)
}

/// Dot product with 8 independent accumulators so it vectorises without fast-math.
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0f32; 8];
    let mut ca = a.chunks_exact(8);
    let mut cb = b.chunks_exact(8);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for v in acc {
        s += v;
    }
    s
}

/// Hermite basis for m (0..4) and its d-derivative (4..8, divided by h) at fraction `t`.
#[inline]
fn hermite_basis(t: f32, inv_h: f32) -> [f32; 8] {
    let (t2, t3) = (t * t, t * t * t);
    [
        2.0 * t3 - 3.0 * t2 + 1.0,
        t3 - 2.0 * t2 + t,
        -2.0 * t3 + 3.0 * t2,
        t3 - t2,
        (6.0 * t2 - 6.0 * t) * inv_h,
        (3.0 * t2 - 4.0 * t + 1.0) * inv_h,
        (-6.0 * t2 + 6.0 * t) * inv_h,
        (3.0 * t2 - 2.0 * t) * inv_h,
    ]
}

/// Tabulated whitened model over a uniform thickness grid.
#[derive(Debug, Clone)]
pub struct ThicknessTable {
    /// Thickness of node 0, nm.
    pub d_min: f64,
    /// Node spacing h, nm.
    pub step_nm: f64,
    /// Number of nodes; the last one is at or beyond the largest thickness asked for.
    pub nodes: usize,
    angles: usize,
    /// Padded row length (bands rounded up to 8).
    stride: usize,
    /// Per node: `angles × stride` values of m, then `angles × stride` values of h·dm/dd.
    data: Vec<f32>,
    /// Per node and angle: Σ_b m².
    mm: Vec<f32>,
}

impl ThicknessTable {
    /// Bytes a table of `angles × bands` samples over `[d_min, d_max]` at `step_nm` takes.
    pub fn bytes_for(angles: usize, bands: usize, d_min: f64, d_max: f64, step_nm: f64) -> usize {
        let nodes = ((d_max - d_min) / step_nm).ceil() as usize + 2;
        nodes * angles * (2 * padded_bands(bands) + 1) * 4
    }

    /// Tabulates `fill(d, angle, m, dm)` (which writes `bands` values of m and dm/dd) on
    /// `d_min, d_min + h, …` up to at least `d_max`.
    pub fn build(
        angles: usize,
        bands: usize,
        d_min: f64,
        d_max: f64,
        step_nm: f64,
        fill: impl Fn(f64, usize, &mut [f32], &mut [f32]) + Sync,
    ) -> Self {
        let stride = padded_bands(bands);
        let s = angles * stride;
        // One node past d_max so interpolation at d_max has a right neighbour.
        let nodes = ((d_max - d_min) / step_nm).ceil() as usize + 2;
        let mut data = vec![0f32; nodes * 2 * s];
        let mut mm = vec![0f32; nodes * angles];
        data.par_chunks_mut(2 * s)
            .zip(mm.par_chunks_mut(angles))
            .enumerate()
            .for_each(|(i, (row, mm_row))| {
                let d = d_min + i as f64 * step_nm;
                let (r, dr) = row.split_at_mut(s);
                for a in 0..angles {
                    let ra = &mut r[a * stride..a * stride + bands];
                    let dra = &mut dr[a * stride..a * stride + bands];
                    fill(d, a, ra, dra);
                    dra.iter_mut().for_each(|v| *v *= step_nm as f32);
                    mm_row[a] = dot(ra, ra);
                }
            });
        ThicknessTable {
            d_min,
            step_nm,
            nodes,
            angles,
            stride,
            data,
            mm,
        }
    }

    /// Thickness of node `i`.
    #[inline]
    pub fn node_d(&self, i: usize) -> f64 {
        self.d_min + i as f64 * self.step_nm
    }

    /// Nearest node of thickness `d` (clamped to the table).
    #[inline]
    pub fn nearest_node(&self, d: f64) -> usize {
        (((d - self.d_min) / self.step_nm).round().max(0.0) as usize).min(self.nodes - 1)
    }

    /// m·y and m·m of angle `a` at node `i` (m·m exact, m·y one dot product).
    #[inline]
    pub fn node_sums(&self, i: usize, a: usize, ya: &[f32]) -> (f32, f32) {
        let s = self.angles * self.stride;
        let row = &self.data[i * 2 * s + a * self.stride..i * 2 * s + (a + 1) * self.stride];
        (dot(row, ya), self.mm[i * self.angles + a])
    }

    /// The five sums of angle `a` at thickness `d` (cubic Hermite interpolation; `ya` is
    /// the angle's padded data row).
    #[inline]
    pub fn angle_sums(&self, d: f64, a: usize, ya: &[f32]) -> AngleSums {
        let u = ((d - self.d_min) / self.step_nm).clamp(0.0, (self.nodes - 1) as f64);
        let i = (u.floor() as usize).min(self.nodes - 2);
        let basis = hermite_basis((u - i as f64) as f32, (1.0 / self.step_nm) as f32);
        let s = self.angles * self.stride;
        let row = |node: usize, deriv: usize| {
            let o = node * 2 * s + deriv * s + a * self.stride;
            &self.data[o..o + self.stride]
        };
        hermite_sums(
            ya,
            row(i, 0),
            row(i, 1),
            row(i + 1, 0),
            row(i + 1, 1),
            &basis,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth test "model": m_a,b(d) = sin(k_ab d) + 1.5, with its exact derivative.
    fn fill(d: f64, a: usize, m: &mut [f32], dm: &mut [f32]) {
        for b in 0..m.len() {
            let k = 0.02 + 0.001 * (b + 7 * a) as f64;
            m[b] = ((k * d).sin() + 1.5) as f32;
            dm[b] = (k * (k * d).cos()) as f32;
        }
    }

    #[test]
    fn interpolated_sums_match_direct_evaluation() {
        let (na, nb) = (3, 81);
        let stride = padded_bands(nb);
        // 64 nodes per period of the fastest component (k ≤ 0.115).
        let step = 2.0 * std::f64::consts::PI / 0.115 / 64.0;
        let tab = ThicknessTable::build(na, nb, 0.0, 2000.0, step, fill);
        assert!(tab.node_d(tab.nodes - 1) >= 2000.0);
        let mut y = vec![0f32; na * stride];
        for a in 0..na {
            for b in 0..nb {
                y[a * stride + b] = 0.3 + 0.2 * ((a * nb + b) as f32 * 0.37).sin();
            }
        }
        let (mut m, mut dm) = (vec![0f32; nb], vec![0f32; nb]);
        for &d in &[0.0, 0.3, 123.456, 777.77, 1999.9, 2000.0] {
            for a in 0..na {
                let s = tab.angle_sums(d, a, &y[a * stride..(a + 1) * stride]);
                fill(d, a, &mut m, &mut dm);
                let ya = &y[a * stride..a * stride + nb];
                let want = [
                    dot(&m, ya),
                    dot(&m, &m),
                    dot(&dm, ya),
                    dot(&dm, &m),
                    dot(&dm, &dm),
                ];
                let got = [s.my, s.mm, s.dy, s.dm, s.dd];
                for (g, w) in got.iter().zip(want) {
                    assert!(
                        (g - w).abs() <= 2e-4 * w.abs().max(0.05),
                        "d={d} {got:?} {want:?}"
                    );
                }
            }
        }
        // Node sums are exact.
        let i = tab.nearest_node(640.0);
        let (my, mm) = tab.node_sums(i, 1, &y[stride..2 * stride]);
        fill(tab.node_d(i), 1, &mut m, &mut dm);
        assert!(
            (mm - dot(&m, &m)).abs() < 1e-3 && (my - dot(&m, &y[stride..stride + nb])).abs() < 1e-3
        );
    }

    #[test]
    fn simd_sums_match_scalar() {
        for n in [0usize, 8, 88, 408] {
            let v = |k: f32| -> Vec<f32> {
                (0..n)
                    .map(|i| 0.1 + 0.05 * ((i as f32) * k).sin())
                    .collect()
            };
            let (y, r0, d0, r1, d1) = (v(0.3), v(0.7), v(1.1), v(1.9), v(2.3));
            let b = [0.2, 0.1, 0.8, -0.05, -1.1, 0.3, 1.1, -0.2];
            let a = hermite_sums(&y, &r0, &d0, &r1, &d1, &b);
            let c = hermite_sums_scalar(&y, &r0, &d0, &r1, &d1, &b);
            for (x, z) in [
                (a.my, c.my),
                (a.mm, c.mm),
                (a.dy, c.dy),
                (a.dm, c.dm),
                (a.dd, c.dd),
            ] {
                assert!(
                    (x - z).abs() <= 1e-5 * z.abs().max(1e-3),
                    "n={n}: {a:?} {c:?}"
                );
            }
        }
    }

    /// The profiled objective of a free gain equals the residual of the best g ≥ 0, and its
    /// gradient matches a finite difference of that objective.
    #[test]
    fn gain_elimination_is_the_optimal_gain() {
        let nb = 16;
        let m: Vec<f32> = (0..nb)
            .map(|b| 0.2 + 0.1 * (b as f32 * 0.5).sin())
            .collect();
        let dm: Vec<f32> = (0..nb).map(|b| 0.05 * (b as f32 * 0.5).cos()).collect();
        let y: Vec<f32> = (0..nb)
            .map(|b| 0.7 * m[b] + 0.01 * (b as f32).cos())
            .collect();
        let s = AngleSums {
            my: dot(&m, &y),
            mm: dot(&m, &m),
            dy: dot(&dm, &y),
            dm: dot(&dm, &m),
            dd: dot(&dm, &dm),
        };
        let mut p = PassSums::default();
        s.combine(dot(&y, &y), 1.0, GainMode::Free, &mut p);
        let g = s.gain(GainMode::Free);
        let direct: f32 = y.iter().zip(&m).map(|(a, b)| (a - g * b).powi(2)).sum();
        assert!((p.sse as f32 - direct).abs() < 1e-5, "{} {direct}", p.sse);
        assert!((g - 0.7).abs() < 0.05);
        // Anti-correlated data: the gain is clamped at 0, the objective is Σy².
        let neg: Vec<f32> = y.iter().map(|v| -v).collect();
        let s2 = AngleSums {
            my: dot(&m, &neg),
            ..s
        };
        let mut p2 = PassSums::default();
        s2.combine(dot(&neg, &neg), 1.0, GainMode::Free, &mut p2);
        assert!((p2.sse as f32 - dot(&neg, &neg)).abs() < 1e-6 && p2.hess == 0.0);
    }
}
