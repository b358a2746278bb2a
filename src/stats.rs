//! Summary statistics shared by the stages: one percentile definition and one summary of a
//! per-pixel map (thickness maps of fits and ground truths, ΔE maps of comparisons).

use serde::{Deserialize, Serialize};

/// The `q`-quantile (`q` ∈ [0, 1]) of NaN-free `values` by linear interpolation between the
/// ⌊q(n−1)⌋-th order statistic and the next (numpy's default `linear` method), found by
/// selection in O(n): a megapixel map is sorted in ~0.1 s, and callers ask for several
/// quantiles. Reorders `values`; NaN for an empty slice.
pub fn percentile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let x = q.clamp(0.0, 1.0) * (values.len() - 1) as f64;
    let i = x.floor() as usize;
    let (_, &mut lo, right) = values.select_nth_unstable_by(i, f64::total_cmp);
    let hi = right.iter().copied().min_by(f64::total_cmp).unwrap_or(lo);
    lo + (hi - lo) * (x - i as f64)
}

/// Mean, spread and quantiles of the finite values of a map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean: f64,
    pub median: f64,
    pub p5: f64,
    pub p95: f64,
    pub min: f64,
    pub max: f64,
    /// Population standard deviation.
    pub std: f64,
}

impl Summary {
    /// Statistics of the finite entries of `values`; None if there are none.
    pub fn of_finite(values: &[f32]) -> Option<Self> {
        let mut v: Vec<f64> = values
            .iter()
            .filter(|x| x.is_finite())
            .map(|&x| x as f64)
            .collect();
        if v.is_empty() {
            return None;
        }
        // Moments in the input's order (selection reorders v).
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(Summary {
            mean,
            median: percentile(&mut v, 0.5),
            p5: percentile(&mut v, 0.05),
            p95: percentile(&mut v, 0.95),
            min,
            max,
            std,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Selection-based quantiles equal interpolation between sorted order statistics.
    #[test]
    fn percentiles_match_the_sorted_definition() {
        let data: Vec<f64> = (0..1001)
            .map(|i| ((i * 7919) % 1009) as f64 * 0.5)
            .collect();
        let mut sorted = data.clone();
        sorted.sort_by(f64::total_cmp);
        for q in [0.0, 0.005, 0.05, 0.5, 0.95, 0.995, 1.0] {
            let x = q * (sorted.len() - 1) as f64;
            let i = x.floor() as usize;
            let j = (i + 1).min(sorted.len() - 1);
            let want = sorted[i] + (sorted[j] - sorted[i]) * (x - i as f64);
            let mut v = data.clone();
            assert_eq!(percentile(&mut v, q), want, "q={q}");
        }
        let mut hundred: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        assert!((percentile(&mut hundred, 0.95) - 95.05).abs() < 1e-12);
        assert_eq!(percentile(&mut [3.0], 0.95), 3.0);
        assert!(percentile(&mut [], 0.5).is_nan());
    }

    #[test]
    fn summary_skips_non_finite_values() {
        let single = Summary::of_finite(&[f32::NAN, 3.0, f32::INFINITY]).unwrap();
        assert_eq!((single.min, single.median, single.max), (3.0, 3.0, 3.0));
        assert_eq!(single.std, 0.0);
        let s = Summary::of_finite(&[4.0, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!((s.min, s.median, s.max, s.mean), (1.0, 2.5, 4.0, 2.5));
        assert!((s.std - 1.25f64.sqrt()).abs() < 1e-12);
        assert!(Summary::of_finite(&[f32::NAN]).is_none());
    }
}
