//! Adaptive sample counts: every pixel its `spp` samples, then more where pixels are noisy.
//!
//! While a render of `spp` samples per pixel runs, each pixel keeps its spread (the sum of
//! squared deviations of its samples from their mean, over the three channels) and the work
//! its samples took ([`sample_cost`]: the path vertices they reached). Then extra samples —
//! the work of a quarter of `spp` more in every pixel ([`extra_budget`]) — go to the pixels by
//! Neyman's allocation for unequal costs ([`extra_counts`]): nᵢ ∝ σᵢ / √cᵢ minimises the
//! summed variance of the pixel means, Σ σᵢ² / nᵢ, for a fixed total work Σ cᵢ nᵢ. Pixel errors
//! are far from even: wherever a pixel sees the edge of a light, a sun's glint or a caustic a
//! few very bright samples dominate it (in the Cornell box 97 % of the squared error at 64 spp
//! lies in the 0.5 % of pixels along the light's outline), and these pixels get up to
//! [`MAX_EXTRA_PER_SPP`] × `spp` more. No pixel gets fewer than `spp`: nowhere is the image
//! noisier than the uniform render, for up to a quarter more work.
//!
//! **Unbiased.** A pixel's count is decided by its eight neighbours' samples, never by its
//! own: every sample stream is keyed by its own pixel ([`super::sampler`]), so given the counts
//! a pixel's samples are still independent draws and their mean is unbiased. (Choosing by a
//! pixel's own spread would favour pixels whose first samples happened to be far from their
//! mean and dilute exactly those deviations.) The price: a bright detail one pixel wide is
//! found only through its neighbours' spread.
//!
//! Only for the box filter (a wider filter mixes the samples of pixels with different counts)
//! and for whole renders (`--sample-range` pieces must each hold the same samples of every
//! pixel to merge exactly).

/// Below this many samples per pixel every pixel gets the same count: the spread would rest
/// on too few samples.
pub const MIN_SPP: u32 = 8;

/// A pixel gets at most this many times `spp` extra samples, so that a few extreme pixels
/// cannot take the whole budget.
pub const MAX_EXTRA_PER_SPP: u32 = 8;

/// The extra samples' work, in samples per pixel: that of a quarter of `spp` more in every
/// pixel.
pub fn extra_budget(spp: u32) -> u32 {
    spp / 4
}

/// The work of one camera sample, in units of one path vertex (its ray, shading, light
/// sample): the vertices its path reached, and a tenth of one for a camera ray that saw only
/// the background (measured, one thread, 128², 64 spp: the studio map alone 0.03 s, the gold
/// teapot in front of it 0.20 s, where its 31 % of the pixels take two vertices per sample:
/// ~0.1 per background sample; the diffuse teapot 0.42 s, ~4 vertices). A proxy, counted
/// the same on every machine.
#[inline]
pub fn sample_cost(vertices: u32) -> f32 {
    if vertices == 0 {
        0.1
    } else {
        vertices as f32
    }
}

/// Per pixel (row-major), over the render's passes: the sums of squared deviations from each
/// pass's mean, over the three channels, with their degrees of freedom (Σ over passes of
/// count − 1), and the summed [`sample_cost`] of its `samples` samples.
#[derive(Debug, Clone, Default)]
pub struct Spread {
    pub m2: Vec<f32>,
    pub work_done: Vec<f32>,
    pub samples: u32,
    pub dof: u32,
}

impl Spread {
    /// Adds one pass of `samples` per pixel.
    pub fn add_pass(&mut self, m2: &[f32], work_done: &[f32], samples: u32) {
        if self.m2.is_empty() {
            self.m2 = vec![0.0; m2.len()];
            self.work_done = vec![0.0; work_done.len()];
        }
        for (a, b) in self.m2.iter_mut().zip(m2) {
            *a += b;
        }
        for (a, b) in self.work_done.iter_mut().zip(work_done) {
            *a += b;
        }
        self.samples += samples;
        self.dof += samples.saturating_sub(1);
    }
}

/// Sum of squared deviations of `samples` from their mean, over the three channels.
pub fn sum_squared_deviations(samples: &[[f32; 3]]) -> f32 {
    let n = samples.len() as f32;
    if samples.len() < 2 {
        return 0.0;
    }
    let mut mean = [0.0f32; 3];
    for s in samples {
        for c in 0..3 {
            mean[c] += s[c];
        }
    }
    let mut m2 = 0.0f32;
    for s in samples {
        for c in 0..3 {
            let d = s[c] - mean[c] / n;
            m2 += d * d;
        }
    }
    m2
}

/// A number in [0, 1) from a pixel index (splitmix64's finaliser).
fn threshold(i: usize) -> f64 {
    let mut z = (i as u64).wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Pixel k's 8-neighbourhood summed up: how many, their summed cost, the
/// largest standard deviation among them and which pixel has it, and the largest among the
/// others (what is left when that pixel is taken out).
#[derive(Clone, Copy)]
struct Neighbourhood {
    count: u32,
    cost: f64,
    max: f64,
    argmax: usize,
    second: f64,
}

impl Neighbourhood {
    fn of(k: usize, (w, h): (usize, usize), sigma: &[f64], cost: &[f64]) -> Self {
        let (x, y) = (k % w, k / w);
        let mut n = Neighbourhood {
            count: 0,
            cost: 0.0,
            max: 0.0,
            argmax: usize::MAX,
            second: 0.0,
        };
        for ny in y.saturating_sub(1)..(y + 2).min(h) {
            for nx in x.saturating_sub(1)..(x + 2).min(w) {
                let j = ny * w + nx;
                if j == k {
                    continue;
                }
                n.count += 1;
                n.cost += cost[j];
                if sigma[j] > n.max || n.argmax == usize::MAX {
                    n.second = n.max;
                    (n.max, n.argmax) = (sigma[j], j);
                } else {
                    n.second = n.second.max(sigma[j]);
                }
            }
        }
        n
    }

    /// (largest σ, mean cost) over the neighbourhood, without pixel `skip` if given.
    fn score(&self, skip: Option<(usize, f64)>) -> (f64, f64) {
        let (max, count, cost) = match skip {
            Some((i, cost_i)) => (
                if self.argmax == i {
                    self.second
                } else {
                    self.max
                },
                self.count - 1,
                self.cost - cost_i,
            ),
            None => (self.max, self.count, self.cost),
        };
        if count == 0 {
            return (0.0, 0.0);
        }
        (max, (cost / count as f64).max(0.0))
    }
}

/// Extra samples per pixel (row-major, `width × height`) for the work of `extra` more samples
/// in every pixel: Neyman's allocation for unequal costs, nᵢ ∝ σᵢ / √cᵢ under Σ cᵢ nᵢ = the
/// work of `extra` samples in every pixel (so the extra samples take about the time uniform
/// ones would), where σᵢ is the largest standard deviation among pixel i's
/// eight neighbours and cᵢ their mean [`sample_cost`]. At most `cap` per pixel (a capped
/// pixel's share is not passed on), in multiples of `granule`: a share is rounded down or up
/// by a threshold hashed from the pixel's index (so the rounding neither depends on the
/// samples nor loses budget on average). A Sobol' pixel keeps its samples in whole blocks of
/// a power of two that way, each block stratified.
///
/// Pixel i's count depends on no value of its own: its score and cost are its neighbours', and
/// the two sums that normalise the allocation are taken with pixel i's terms replaced by what
/// they would be without it (to rounding: its values reach them only through the last bits of
/// a subtraction). Deterministic.
pub fn extra_counts(
    spread: &Spread,
    (width, height): (usize, usize),
    extra: u32,
    cap: u32,
    granule: u32,
) -> Vec<u32> {
    use rayon::prelude::*;
    let size = (width, height);
    let n = width * height;
    debug_assert_eq!(spread.m2.len(), n);
    let dof = spread.dof.max(1) as f64;
    let finite_at_most = |v: f64, max: f64| {
        if v.is_finite() {
            v.clamp(0.0, max)
        } else {
            0.0
        }
    };
    let sigma: Vec<f64> = (spread.m2.iter())
        .map(|&m2| finite_at_most((m2 as f64 / dof).sqrt(), 1e12))
        .collect();
    let samples = spread.samples.max(1) as f64;
    let cost: Vec<f64> = (spread.work_done.iter())
        .map(|&c| finite_at_most(c as f64 / samples, 4096.0).max(0.1))
        .collect();
    let hoods: Vec<Neighbourhood> = (0..n)
        .into_par_iter()
        .map(|k| Neighbourhood::of(k, size, &sigma, &cost))
        .collect();
    // The normalising sums' terms: tₖ = σₖ √cₖ (scores) and cₖ (uniform work).
    let term = |(s, c): (f64, f64)| s * c.sqrt();
    let t: Vec<f64> = hoods.iter().map(|h| term(h.score(None))).collect();
    let total_t: f64 = t.iter().sum();
    let total_c: f64 = cost.iter().sum();
    (0..n)
        .into_par_iter()
        .map(|i| {
            let (s_i, c_i) = hoods[i].score(None);
            if s_i <= 0.0 || c_i <= 0.0 {
                return 0;
            }
            let (x, y) = (i % width, i / width);
            let mut d = 0.0;
            for ny in y.saturating_sub(1)..(y + 2).min(height) {
                for nx in x.saturating_sub(1)..(x + 2).min(width) {
                    let k = ny * width + nx;
                    if k != i {
                        d += term(hoods[k].score(Some((i, cost[i])))) - t[k];
                    }
                }
            }
            // The local differences first: where pixel i changes nothing they are exactly 0.
            let d = total_t + d;
            // Pixel i's own cost replaced by its neighbours' mean.
            let work = total_c - cost[i] + c_i;
            if d <= 0.0 {
                return 0;
            }
            let share = extra as f64 * (work / d) * s_i / c_i.sqrt();
            let g = granule.max(1);
            let blocks = (share / g as f64 + threshold(i))
                .floor()
                .min((cap / g) as f64);
            blocks as u32 * g
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 16 samples per pixel, each of cost `cost`.
    fn spread(m2: Vec<f32>, cost: f32) -> Spread {
        let work_done = vec![16.0 * cost; m2.len()];
        Spread {
            m2,
            work_done,
            samples: 16,
            dof: 15,
        }
    }

    #[test]
    fn squared_deviations_are_the_channels_summed_variance_times_n_minus_one() {
        let s = [[1.0, 0.0, 2.0], [3.0, 0.0, 2.0], [5.0, 3.0, 2.0]];
        // red: mean 3, deviations 4 + 0 + 4; green: mean 1, 1 + 1 + 4; blue: 0.
        assert!((sum_squared_deviations(&s) - 14.0).abs() < 1e-5);
        assert_eq!(sum_squared_deviations(&s[..1]), 0.0);
    }

    #[test]
    fn the_extra_samples_go_to_the_neighbours_of_noisy_pixels_within_the_budget() {
        // 5 × 5, one noisy pixel in the middle: its eight neighbours share the extra work of
        // 25 pixels (25 × 32 samples of cost 3), the pixel itself gets nothing (its own spread is not
        // looked at), the rest nothing.
        let mut m2 = vec![0.0; 25];
        m2[12] = 100.0;
        let c = extra_counts(&spread(m2, 3.0), (5, 5), 32, 1000, 1);
        for y in 0..5 {
            for x in 0..5 {
                let neighbour = (x as i32 - 2).abs() <= 1 && (y as i32 - 2).abs() <= 1;
                let want = if neighbour && (x, y) != (2, 2) {
                    100
                } else {
                    0
                };
                let got = c[y * 5 + x];
                assert!(got == want || got + 1 == want, "pixel {x},{y}: {got}");
            }
        }
        // Proportional to the neighbours' standard deviation, rounded down.
        let mut m2 = vec![1.0; 9];
        m2[0] = 4.0; // σ 2 beside σ 1: pixels next to (0, 0) score 2, the others 1
        let c = extra_counts(&spread(m2, 1.0), (3, 3), 100, 1000, 1);
        // (Rounded down from values within 1e-12 of the integers.)
        let want = [100, 150, 75, 150, 150, 75, 75, 75, 75];
        assert!(
            c.iter().zip(want).all(|(&c, w)| c == w || c + 1 == w),
            "{c:?}"
        );
        // About the budget (9 × 100): pixel (0, 0)'s count is normalised as if it were as
        // quiet as the others (its own spread left out), so it gets 100, not 75.
    }

    #[test]
    fn costly_pixels_get_fewer_samples_by_the_square_root_of_their_cost() {
        // Two halves of a 4 × 2 image with equal spread, the right half's samples 4× the work.
        let mut s = spread(vec![1.0; 8], 1.0);
        for i in [2, 3, 6, 7] {
            s.work_done[i] *= 4.0;
        }
        let c = extra_counts(&s, (4, 2), 64, 1000, 1);
        // Far from the boundary (x = 0 sees only cost 1, x = 3 only cost 4): half the samples.
        // (Each pixel's normalisation leaves its own terms out, so the ratio is not exact.)
        let ratio = c[0] as f64 / c[3] as f64;
        assert!((ratio / 2.0 - 1.0).abs() < 0.05, "{c:?}");
        // The extra work is about that of 64 samples everywhere: 64 × (4 × 1 + 4 × 4).
        let work: f64 = (0..8)
            .map(|i| c[i] as f64 * s.work_done[i] as f64 / 16.0)
            .sum();
        assert!((work / (64.0 * 20.0) - 1.0).abs() < 0.2, "{work}");
    }

    #[test]
    fn a_pixels_own_values_do_not_change_its_count() {
        let base: Vec<f32> = (0..48).map(|i| ((i * 7) % 11) as f32).collect();
        let s0 = spread(base, 2.0);
        let a = extra_counts(&s0, (8, 6), 16, 1000, 1);
        assert!(a.iter().any(|&n| n > 0));
        for i in 0..48 {
            for (m2, work) in [(50.0, 1.0), (0.0, 1.0), (1.0, 7.0), (f32::NAN, 0.0)] {
                let mut s = s0.clone();
                s.m2[i] *= m2;
                s.work_done[i] *= work;
                let b = extra_counts(&s, (8, 6), 16, 1000, 1);
                assert_eq!(b[i], a[i], "pixel {i}, m2 × {m2}, work × {work}");
            }
        }
    }

    #[test]
    fn the_cap_holds() {
        let mut m2 = vec![0.01; 9];
        m2[0] = 1e6;
        let c = extra_counts(&spread(m2, 1.0), (9, 1), 100, 10, 1);
        assert_eq!(c[1], 10);
        assert!(c.iter().all(|&n| n <= 10));
    }

    #[test]
    fn no_spread_or_non_finite_spread_gives_no_extra_samples() {
        let c = extra_counts(&spread(vec![0.0; 16], 1.0), (4, 4), 100, 10, 1);
        assert!(c.iter().all(|&n| n == 0));
        let mut m2 = vec![0.0; 16];
        m2[5] = f32::INFINITY;
        m2[6] = f32::NAN;
        let c = extra_counts(&spread(m2, 1.0), (4, 4), 100, 10, 1);
        assert!(c.iter().all(|&n| n == 0));
        // A one-pixel image has no neighbours.
        assert_eq!(
            extra_counts(&spread(vec![5.0], 1.0), (1, 1), 100, 10, 1),
            vec![0]
        );
    }

    #[test]
    fn rounding_to_granules_keeps_the_budget_on_average() {
        // Every pixel's share is 10 samples: in blocks of 16, 3/8 of the pixels get none and
        // 5/8 one block (the hashed thresholds), 10 per pixel on average.
        let n = 64 * 64;
        let c = extra_counts(&spread(vec![1.0; n], 1.0), (64, 64), 10, 1000, 16);
        assert!(c.iter().all(|&k| k == 0 || k == 16));
        let mean = c.iter().sum::<u32>() as f64 / n as f64;
        assert!((mean / 10.0 - 1.0).abs() < 0.05, "{mean}");
        // The cap is respected in whole blocks.
        let c = extra_counts(&spread(vec![1.0; n], 1.0), (64, 64), 100, 40, 16);
        assert!(c.iter().all(|&k| k == 32), "{:?}", &c[..8]);
    }
}
