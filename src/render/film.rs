//! The film: spectral samples → linear sRGB, pixel reconstruction and exact-merge accumulation.
//!
//! Each sample's spectrum becomes linear sRGB through the RGB matching functions
//! ([`crate::spectrum::sampled::rgb_cmf_d65_f32`]: the mean over the four wavelengths of
//! cmf·L/pdf, Mitsuba/pbrt-v4; Rec.709, D65, no adaptation, no clamping;
//! `docs/physics-and-formats.md`, "Film").
//!
//! Box filter (every sample stays in its pixel): a pixel's samples are summed in a fixed
//! binary tree over their *global* sample indices ([`tree_sum`]). A render of samples
//! [0, 2^k) is then the sum of the renders of [0, 2^(k−1)) and [2^(k−1), 2^k) — so renders split
//! with `--sample-range` at power-of-two boundaries merge (sample-weighted mean) to exactly the
//! full render, bit for bit. Tent and Gaussian filters splat each sample onto the pixels within
//! their radius with normalised weights (Mitsuba `hdrfilm` with `tent`/`gaussian`).

use crate::scene::ReconstructionFilter;

/// Sum of `values` in the canonical binary tree over sample indices: the range is split at its
/// largest power-of-two-aligned midpoint, so aligned sub-ranges are exact subtrees.
/// `first_index` is the global sample index of `values[0]` (must be aligned to the block).
pub fn tree_sum(values: &[[f32; 3]]) -> [f32; 3] {
    match values.len() {
        0 => [0.0; 3],
        1 => values[0],
        n => {
            // Largest power of two strictly below n (n ≥ 2).
            let half = if n.is_power_of_two() {
                n / 2
            } else {
                1usize << (usize::BITS - 1 - n.leading_zeros())
            };
            let a = tree_sum(&values[..half]);
            let b = tree_sum(&values[half..]);
            [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
        }
    }
}

/// [`tree_sum`] computed in place (the same additions in the same tree, so the same bits),
/// without recursion: a power-of-two block is reduced level by level (pairs, then pairs of
/// pairs, …), and a remainder is the sum of its own largest power-of-two prefix and the rest.
/// Overwrites `values`. The recursive form cost ~50 instructions per sample.
pub fn tree_sum_in_place(values: &mut [[f32; 3]]) -> [f32; 3] {
    let n = values.len();
    match n {
        0 => [0.0; 3],
        1 => values[0],
        _ => {
            let half = if n.is_power_of_two() {
                n / 2
            } else {
                1usize << (usize::BITS - 1 - n.leading_zeros())
            };
            let (left, right) = values.split_at_mut(half);
            // `left` has a power-of-two length: reduce it level by level.
            let mut stride = 1;
            while stride < half {
                let mut i = 0;
                while i < half {
                    let b = left[i + stride];
                    let a = &mut left[i];
                    *a = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
                    i += 2 * stride;
                }
                stride *= 2;
            }
            let a = left[0];
            let b = tree_sum_in_place(right);
            [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
        }
    }
}

/// Reconstruction filter in pixel units.
#[derive(Debug, Clone, Copy)]
pub enum Filter {
    Box,
    Tent { radius: f32 },
    Gaussian { stddev: f32, radius: f32 },
}

impl Filter {
    pub fn new(f: &ReconstructionFilter) -> anyhow::Result<Self> {
        Ok(match *f {
            ReconstructionFilter::Box => Filter::Box,
            ReconstructionFilter::Tent { radius } => {
                if !(radius.is_finite() && radius > 0.0) {
                    anyhow::bail!("tent filter radius must be > 0, got {radius}");
                }
                Filter::Tent { radius }
            }
            ReconstructionFilter::Gaussian { stddev } => {
                if !(stddev.is_finite() && stddev > 0.0) {
                    anyhow::bail!("gaussian filter stddev must be > 0, got {stddev}");
                }
                // Mitsuba: radius = 4 σ.
                Filter::Gaussian {
                    stddev,
                    radius: 4.0 * stddev,
                }
            }
        })
    }

    /// Mitsuba's name of the filter (`rfilter type`).
    pub fn name(&self) -> &'static str {
        match self {
            Filter::Box => "box",
            Filter::Tent { .. } => "tent",
            Filter::Gaussian { .. } => "gaussian",
        }
    }

    pub fn radius(&self) -> f32 {
        match *self {
            Filter::Box => 0.5,
            Filter::Tent { radius } => radius,
            Filter::Gaussian { radius, .. } => radius,
        }
    }

    /// 1-D filter weight at offset `x` pixels.
    #[inline]
    pub fn eval_1d(&self, x: f32) -> f32 {
        match *self {
            Filter::Box => {
                if x.abs() <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            Filter::Tent { radius } => (1.0 - x.abs() / radius).max(0.0),
            Filter::Gaussian { stddev, radius } => {
                if x.abs() > radius {
                    0.0
                } else {
                    // Mitsuba subtracts the value at the radius so the filter reaches zero.
                    let g = |v: f32| (-0.5 * v * v / (stddev * stddev)).exp();
                    (g(x) - g(radius)).max(0.0)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tree_sum_of_halves_is_exact() {
        let vals: Vec<[f32; 3]> = (0..64)
            .map(|i| {
                [
                    (i as f32 * 0.377).sin() * 1e3,
                    0.1 * i as f32,
                    1.0 / (i as f32 + 1.0),
                ]
            })
            .collect();
        let whole = tree_sum(&vals);
        let a = tree_sum(&vals[..32]);
        let b = tree_sum(&vals[32..]);
        for c in 0..3 {
            // Means written separately, merged as a sample-weighted mean: bit-identical.
            let merged = (32.0 * (a[c] / 32.0) + 32.0 * (b[c] / 32.0)) / 64.0;
            assert_eq!(merged.to_bits(), (whole[c] / 64.0).to_bits());
        }
    }

    #[test]
    fn in_place_tree_sum_is_bit_identical() {
        for n in 0..=70usize {
            let vals: Vec<[f32; 3]> = (0..n)
                .map(|i| {
                    let x = i as f32;
                    [(x * 0.377).sin() * 1e3, 0.1 * x + 1e-3, 1.0 / (x + 1.0)]
                })
                .collect();
            let reference = tree_sum(&vals);
            let mut buf = vals.clone();
            let fast = tree_sum_in_place(&mut buf);
            assert_eq!(
                reference.map(f32::to_bits),
                fast.map(f32::to_bits),
                "n = {n}"
            );
        }
    }

    #[test]
    fn filters_vanish_at_radius() {
        let g = Filter::new(&ReconstructionFilter::Gaussian { stddev: 0.5 }).unwrap();
        assert_eq!(g.eval_1d(2.0), 0.0);
        assert!(g.eval_1d(0.0) > 0.9);
        let t = Filter::new(&ReconstructionFilter::Tent { radius: 1.0 }).unwrap();
        assert_eq!(t.eval_1d(0.5), 0.5);
        assert!(Filter::new(&ReconstructionFilter::Tent { radius: 0.0 }).is_err());
    }
}
