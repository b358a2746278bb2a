//! Thickness tables: with the film index fixed, every model sample (angle, band — band
//! integration and polarisation included) depends on d alone. Tabulating R(d) and
//! dR/dd once on a fine d grid turns the per-pixel thickness fit into table work:
//!
//! - the coarse scan scores a node with one dot product, using
//!   Σ(R − y)² = ΣR² − 2 R·y + Σy² with ΣR² precomputed per node and angle;
//! - Gauss–Newton evaluates R and dR/dd anywhere by cubic Hermite interpolation between
//!   nodes (values and derivatives both tabulated, so the interpolant is C¹ and its
//!   error is O(h⁴ R'''') — with 64 nodes per fringe of the fastest sample, ≈ 2·10⁻⁷ of
//!   the fringe amplitude, far below f32 noise of the model itself).
//!
//! The table is built from [`FilmModel::spectrum_and_derivative`], i.e. exactly the model
//! the direct fit uses; only where the samples are taken changes.

use super::model::{FilmModel, PassSums};
use rayon::prelude::*;

/// Tabulated model samples over a uniform thickness grid for one film index.
#[derive(Debug, Clone)]
pub struct ThicknessTable {
    /// Thickness of node 0, nm.
    pub d_min: f64,
    /// Node spacing h, nm.
    pub step_nm: f64,
    /// Number of nodes; the last one is at or beyond the largest thickness asked for.
    pub nodes: usize,
    angles: usize,
    bands: usize,
    /// Per node: `angles × bands` values of R, then `angles × bands` values of h·dR/dd
    /// (pre-scaled by h for the Hermite basis).
    data: Vec<f32>,
    /// Per node and angle: Σ_b R².
    rr: Vec<f32>,
}

/// Dot product with 8 independent accumulators so it vectorises without fast-math.
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
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

/// Σe², Σ(dR/dd)e, Σ(dR/dd)² with R, dR/dd interpolated from the two nodes' values
/// (`r0`, `r1`) and h-scaled derivatives (`d0`, `d1`); `b` = Hermite basis for R (0..4)
/// and dR/dd (4..8). This is the inner loop of the whole thickness stage (two calls per
/// pixel), so on x86-64 it is written with SIMD intrinsics: AVX2+FMA when the CPU has
/// them (checked at run time; the crate is built for baseline x86-64), else SSE2, which
/// every x86-64 CPU has. The compiler's own vectorisation of the portable loop shuffled
/// lanes one by one and ran ~3× slower than SSE2 in `perf`.
#[inline]
fn hermite_sums(
    y: &[f32],
    r0: &[f32],
    d0: &[f32],
    r1: &[f32],
    d1: &[f32],
    b: &[f32; 8],
) -> (f32, f32, f32) {
    let n = y.len();
    assert!(r0.len() >= n && d0.len() >= n && r1.len() >= n && d1.len() >= n);
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
    use std::arch::x86_64::*;

    /// # Safety
    /// The CPU must support AVX2 and FMA; `r0`, `d0`, `r1`, `d1` at least `y.len()` long.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn hermite_sums_avx2(
        y: &[f32],
        r0: &[f32],
        d0: &[f32],
        r1: &[f32],
        d1: &[f32],
        b: &[f32; 8],
    ) -> (f32, f32, f32) {
        let n = y.len();
        let full = n - n % 8;
        let bb: [__m256; 8] = std::array::from_fn(|k| _mm256_set1_ps(b[k]));
        let (mut s, mut g, mut h) = (
            _mm256_setzero_ps(),
            _mm256_setzero_ps(),
            _mm256_setzero_ps(),
        );
        let mut j = 0;
        while j < full {
            // SAFETY: j + 8 ≤ full ≤ every slice's length.
            let (yv, a0, b0, a1, b1) = unsafe {
                (
                    _mm256_loadu_ps(y.as_ptr().add(j)),
                    _mm256_loadu_ps(r0.as_ptr().add(j)),
                    _mm256_loadu_ps(d0.as_ptr().add(j)),
                    _mm256_loadu_ps(r1.as_ptr().add(j)),
                    _mm256_loadu_ps(d1.as_ptr().add(j)),
                )
            };
            let r = _mm256_fmadd_ps(
                bb[3],
                b1,
                _mm256_fmadd_ps(
                    bb[2],
                    a1,
                    _mm256_fmadd_ps(bb[1], b0, _mm256_mul_ps(bb[0], a0)),
                ),
            );
            let dr = _mm256_fmadd_ps(
                bb[7],
                b1,
                _mm256_fmadd_ps(
                    bb[6],
                    a1,
                    _mm256_fmadd_ps(bb[5], b0, _mm256_mul_ps(bb[4], a0)),
                ),
            );
            let e = _mm256_sub_ps(r, yv);
            s = _mm256_fmadd_ps(e, e, s);
            g = _mm256_fmadd_ps(dr, e, g);
            h = _mm256_fmadd_ps(dr, dr, h);
            j += 8;
        }
        let mut lanes = [[0f32; 8]; 3];
        // SAFETY: each destination holds 8 f32.
        unsafe {
            _mm256_storeu_ps(lanes[0].as_mut_ptr(), s);
            _mm256_storeu_ps(lanes[1].as_mut_ptr(), g);
            _mm256_storeu_ps(lanes[2].as_mut_ptr(), h);
        }
        let t = super::hermite_sums_scalar(
            &y[full..],
            &r0[full..n],
            &d0[full..n],
            &r1[full..n],
            &d1[full..n],
            b,
        );
        (
            lanes[0].iter().sum::<f32>() + t.0,
            lanes[1].iter().sum::<f32>() + t.1,
            lanes[2].iter().sum::<f32>() + t.2,
        )
    }

    /// # Safety
    /// `r0`, `d0`, `r1`, `d1` at least `y.len()` long (SSE2 is always present on x86-64).
    pub unsafe fn hermite_sums_sse2(
        y: &[f32],
        r0: &[f32],
        d0: &[f32],
        r1: &[f32],
        d1: &[f32],
        b: &[f32; 8],
    ) -> (f32, f32, f32) {
        let n = y.len();
        let full = n - n % 4;
        let bb: [__m128; 8] = std::array::from_fn(|k| _mm_set1_ps(b[k]));
        let (mut s, mut g, mut h) = (_mm_setzero_ps(), _mm_setzero_ps(), _mm_setzero_ps());
        let mut j = 0;
        while j < full {
            // SAFETY: j + 4 ≤ full ≤ every slice's length.
            let (yv, a0, b0, a1, b1) = unsafe {
                (
                    _mm_loadu_ps(y.as_ptr().add(j)),
                    _mm_loadu_ps(r0.as_ptr().add(j)),
                    _mm_loadu_ps(d0.as_ptr().add(j)),
                    _mm_loadu_ps(r1.as_ptr().add(j)),
                    _mm_loadu_ps(d1.as_ptr().add(j)),
                )
            };
            let r = _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(bb[0], a0), _mm_mul_ps(bb[1], b0)),
                _mm_add_ps(_mm_mul_ps(bb[2], a1), _mm_mul_ps(bb[3], b1)),
            );
            let dr = _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(bb[4], a0), _mm_mul_ps(bb[5], b0)),
                _mm_add_ps(_mm_mul_ps(bb[6], a1), _mm_mul_ps(bb[7], b1)),
            );
            let e = _mm_sub_ps(r, yv);
            s = _mm_add_ps(s, _mm_mul_ps(e, e));
            g = _mm_add_ps(g, _mm_mul_ps(dr, e));
            h = _mm_add_ps(h, _mm_mul_ps(dr, dr));
            j += 4;
        }
        let mut lanes = [[0f32; 4]; 3];
        // SAFETY: each destination holds 4 f32.
        unsafe {
            _mm_storeu_ps(lanes[0].as_mut_ptr(), s);
            _mm_storeu_ps(lanes[1].as_mut_ptr(), g);
            _mm_storeu_ps(lanes[2].as_mut_ptr(), h);
        }
        let t = super::hermite_sums_scalar(
            &y[full..],
            &r0[full..n],
            &d0[full..n],
            &r1[full..n],
            &d1[full..n],
            b,
        );
        (
            lanes[0].iter().sum::<f32>() + t.0,
            lanes[1].iter().sum::<f32>() + t.1,
            lanes[2].iter().sum::<f32>() + t.2,
        )
    }
}

/// Portable [`hermite_sums`]: four lanes per sum so the compiler may vectorise it
/// (f32 reductions only vectorise when the order of additions is spelled out).
#[inline]
fn hermite_sums_scalar(
    y: &[f32],
    r0: &[f32],
    d0: &[f32],
    r1: &[f32],
    d1: &[f32],
    b: &[f32; 8],
) -> (f32, f32, f32) {
    const L: usize = 4;
    let (mut s, mut g, mut h) = ([0f32; L], [0f32; L], [0f32; L]);
    let n = y.len();
    let full = n - n % L;
    let mut j = 0;
    while j < full {
        let (yc, a0, b0, a1, b1) = (
            &y[j..j + L],
            &r0[j..j + L],
            &d0[j..j + L],
            &r1[j..j + L],
            &d1[j..j + L],
        );
        for i in 0..L {
            let r = b[0] * a0[i] + b[1] * b0[i] + b[2] * a1[i] + b[3] * b1[i];
            let dr = b[4] * a0[i] + b[5] * b0[i] + b[6] * a1[i] + b[7] * b1[i];
            let e = r - yc[i];
            s[i] += e * e;
            g[i] += dr * e;
            h[i] += dr * dr;
        }
        j += L;
    }
    for k in full..n {
        let r = b[0] * r0[k] + b[1] * d0[k] + b[2] * r1[k] + b[3] * d1[k];
        let dr = b[4] * r0[k] + b[5] * d0[k] + b[6] * r1[k] + b[7] * d1[k];
        let e = r - y[k];
        s[0] += e * e;
        g[0] += dr * e;
        h[0] += dr * dr;
    }
    (s.iter().sum(), g.iter().sum(), h.iter().sum())
}

impl ThicknessTable {
    /// Bytes a table over `[d_min, d_max]` at `step_nm` would take (to decide whether to
    /// build one).
    pub fn bytes_for(model: &FilmModel, d_min: f64, d_max: f64, step_nm: f64) -> usize {
        let nodes = ((d_max - d_min) / step_nm).ceil() as usize + 2;
        nodes * model.angles * (2 * model.bands + 1) * 4
    }

    /// Tabulates `model` on `d_min, d_min + h, …` up to at least `d_max`.
    pub fn build(model: &FilmModel, d_min: f64, d_max: f64, step_nm: f64) -> Self {
        let (na, nb) = (model.angles, model.bands);
        let s = na * nb;
        // One node past d_max so interpolation at d_max has a right neighbour.
        let nodes = ((d_max - d_min) / step_nm).ceil() as usize + 2;
        let mut data = vec![0f32; nodes * 2 * s];
        let mut rr = vec![0f32; nodes * na];
        data.par_chunks_mut(2 * s)
            .zip(rr.par_chunks_mut(na))
            .enumerate()
            .for_each(|(i, (row, rr_row))| {
                let d = d_min + i as f64 * step_nm;
                let (r, dr) = row.split_at_mut(s);
                for a in 0..na {
                    let (ra, dra) = (&mut r[a * nb..(a + 1) * nb], &mut dr[a * nb..(a + 1) * nb]);
                    model.spectrum_and_derivative(a, d, ra, dra);
                    dra.iter_mut().for_each(|v| *v *= step_nm as f32);
                    rr_row[a] = dot(ra, ra);
                }
            });
        ThicknessTable {
            d_min,
            step_nm,
            nodes,
            angles: na,
            bands: nb,
            data,
            rr,
        }
    }

    /// Thickness of node `i`.
    #[inline]
    pub fn node_d(&self, i: usize) -> f64 {
        self.d_min + i as f64 * self.step_nm
    }

    #[inline]
    fn values(&self, i: usize) -> &[f32] {
        let s = self.angles * self.bands;
        &self.data[i * 2 * s..i * 2 * s + s]
    }

    /// Σ(R − y)² at node `i` over the angles in `mask`. `y` must hold zeros at unused
    /// angles (as [`super::Pixels::get`] leaves it) and `yy` = Σy².
    #[inline]
    pub fn node_sse(&self, i: usize, y: &[f32], mask: &[bool], yy: f32) -> f32 {
        let rr = &self.rr[i * self.angles..(i + 1) * self.angles];
        let rr_sum: f32 = rr
            .iter()
            .zip(mask)
            .filter(|(_, &m)| m)
            .map(|(v, _)| v)
            .sum();
        // Clamped: cancellation in f32 can make a near-perfect fit slightly negative.
        (rr_sum - 2.0 * dot(self.values(i), y) + yy).max(0.0)
    }

    /// SSE, gradient and Gauss–Newton Hessian in d at any `d` in the table's range, from
    /// the cubic Hermite interpolant of R(d) and its derivative.
    pub fn pass(&self, d: f64, y: &[f32], mask: &[bool]) -> PassSums {
        let u = ((d - self.d_min) / self.step_nm).clamp(0.0, (self.nodes - 1) as f64);
        let i = (u.floor() as usize).min(self.nodes - 2);
        let t = (u - i as f64) as f32;
        let (t2, t3) = (t * t, t * t * t);
        // Hermite basis and its t-derivative (divided by h below; hD is pre-scaled).
        let (h00, h10, h01, h11) = (
            2.0 * t3 - 3.0 * t2 + 1.0,
            t3 - 2.0 * t2 + t,
            -2.0 * t3 + 3.0 * t2,
            t3 - t2,
        );
        let (g00, g10, g01, g11) = (
            6.0 * t2 - 6.0 * t,
            3.0 * t2 - 4.0 * t + 1.0,
            -6.0 * t2 + 6.0 * t,
            3.0 * t2 - 2.0 * t,
        );
        let inv_h = (1.0 / self.step_nm) as f32;
        let s = self.angles * self.bands;
        let n0 = &self.data[i * 2 * s..(i + 1) * 2 * s];
        let n1 = &self.data[(i + 1) * 2 * s..(i + 2) * 2 * s];
        let (r0, d0) = n0.split_at(s);
        let (r1, d1) = n1.split_at(s);
        let basis = [
            h00,
            h10,
            h01,
            h11,
            g00 * inv_h,
            g10 * inv_h,
            g01 * inv_h,
            g11 * inv_h,
        ];
        let mut out = PassSums::default();
        let nb = self.bands;
        if mask.iter().all(|&m| m) {
            // Every angle: one run over all samples.
            let (sse, g, h) = hermite_sums(y, r0, d0, r1, d1, &basis);
            out.sse = sse as f64;
            out.grad = g as f64;
            out.hess = h as f64;
            out.count = s;
            return out;
        }
        for (a, _) in mask
            .iter()
            .enumerate()
            .take(self.angles)
            .filter(|(_, &m)| m)
        {
            let rg = a * nb..(a + 1) * nb;
            let (sse, g, h) = hermite_sums(
                &y[rg.clone()],
                &r0[rg.clone()],
                &d0[rg.clone()],
                &r1[rg.clone()],
                &d1[rg],
                &basis,
            );
            out.sse += sse as f64;
            out.grad += g as f64;
            out.hess += h as f64;
            out.count += nb;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::Polarization;
    use crate::estimate::model::Geometry;
    use crate::optics::Ior;

    fn geom(pol: Polarization, fwhm: bool, substrate: Ior) -> Geometry {
        Geometry {
            ambient_ior: 1.0,
            substrate,
            wavelengths_nm: (0..81).map(|i| 400.0 + 4.0 * i as f64).collect(),
            fwhm_nm: fwhm.then(|| vec![4.0; 81]),
            incident_deg: vec![10.0, 30.0, 50.0],
            polarization: pol,
            band_integration: fwhm,
        }
    }

    /// The interpolated pass must agree with the direct model everywhere (between nodes,
    /// at nodes, at both ends), for band-integrated, unpolarised and metal-substrate models.
    #[test]
    fn hermite_pass_matches_direct_model() {
        for (pol, fwhm, sub, n) in [
            (Polarization::S, true, Ior::real(1.64), 1.37),
            (Polarization::Unpolarized, false, Ior::real(1.64), 2.37),
            (
                Polarization::P,
                true,
                Ior::Constant(num_complex::Complex64::new(0.18, 3.4)),
                1.8,
            ),
        ] {
            let g = geom(pol, fwhm, sub);
            let m = g.model(n);
            // 64 nodes per shortest fringe, as the solver uses.
            let step = 400.0 / (2.0 * n) / 64.0;
            let tab = ThicknessTable::build(&m, 0.0, 2000.0, step);
            assert!(tab.node_d(tab.nodes - 1) >= 2000.0);
            let y: Vec<f32> = (0..3 * 81)
                .map(|i| 0.05 + 0.02 * ((i as f32) * 0.37).sin())
                .collect();
            let mask = [true, false, true];
            for &d in &[0.0, 0.3, 123.456, 400.0, 777.77, 1499.99, 1999.9, 2000.0] {
                let a = tab.pass(d, &y, &mask);
                let b = m.pass(d, &y, &mask);
                assert!(
                    (a.sse - b.sse).abs() < 1e-4 * b.sse,
                    "{pol:?} d={d} sse {a:?} {b:?}"
                );
                assert!(
                    (a.grad - b.grad).abs() <= 2e-3 * (b.hess * b.sse).sqrt() + 1e-9,
                    "{pol:?} d={d} grad {a:?} {b:?}"
                );
                assert!(
                    (a.hess - b.hess).abs() <= 2e-3 * b.hess + 1e-9,
                    "{pol:?} d={d} hess"
                );
                assert_eq!(a.count, b.count);
            }
            // Node scores equal the direct SSE at the node.
            let yy: f32 = y
                .chunks(81)
                .zip(&mask)
                .filter(|(_, &m)| m)
                .flat_map(|(c, _)| c.iter().map(|v| v * v))
                .sum();
            let mut ym = y.clone();
            ym[81..162].iter_mut().for_each(|v| *v = 0.0);
            for i in [0, 1, 17, tab.nodes / 2, tab.nodes - 1] {
                let s = tab.node_sse(i, &ym, &mask, yy) as f64;
                let e = m.sse(tab.node_d(i), &y, &mask, 1);
                assert!((s - e).abs() < 1e-3 * e + 1e-5, "node {i}: {s} vs {e}");
            }
        }
    }

    /// The SIMD sums (whichever this CPU runs) agree with the portable loop, including
    /// lengths that leave a remainder.
    #[test]
    fn simd_sums_match_scalar() {
        for n in [0usize, 1, 3, 7, 8, 81, 405] {
            let v = |k: f32| -> Vec<f32> {
                (0..n)
                    .map(|i| 0.1 + 0.05 * ((i as f32) * k).sin())
                    .collect()
            };
            let (y, r0, d0, r1, d1) = (v(0.3), v(0.7), v(1.1), v(1.9), v(2.3));
            let b = [0.2, 0.1, 0.8, -0.05, -1.1, 0.3, 1.1, -0.2];
            let a = hermite_sums(&y, &r0, &d0, &r1, &d1, &b);
            let c = hermite_sums_scalar(&y, &r0, &d0, &r1, &d1, &b);
            for (x, z) in [(a.0, c.0), (a.1, c.1), (a.2, c.2)] {
                assert!(
                    (x - z).abs() <= 1e-5 * z.abs().max(1e-3),
                    "n={n}: {a:?} {c:?}"
                );
            }
        }
    }

    #[test]
    fn size_estimate_matches_allocation() {
        let g = geom(Polarization::S, false, Ior::real(1.5));
        let m = g.model(1.4);
        let tab = ThicknessTable::build(&m, 10.0, 50.0, 0.5);
        assert_eq!(tab.nodes, 82);
        assert_eq!(
            ThicknessTable::bytes_for(&m, 10.0, 50.0, 0.5),
            (tab.data.len() + tab.rr.len()) * 4
        );
    }
}
