//! A small deterministic random number generator for the simulator (no dependency):
//! SplitMix64 (Steele, Lea & Flood 2014) for uniform bits, Box–Muller normals, and
//! Poisson variates by inversion (λ < 10) or Hörmann's PTRS transformed rejection
//! (Hörmann 1993, "The transformed rejection method for generating Poisson random
//! variables", as in NumPy) for λ ≥ 10.
//!
//! Each image row × angle gets its own stream derived from the seed, so results do not
//! depend on how rayon schedules rows.

#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
    spare_normal: Option<f64>,
}

/// One SplitMix64 output step, also used to hash stream ids into seeds.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64 {
            state: seed,
            spare_normal: None,
        }
    }

    /// An independent stream for `(seed, a, b, c)`.
    pub fn stream(seed: u64, a: u64, b: u64, c: u64) -> Self {
        Self::new(mix64(mix64(mix64(seed ^ 0x5eed) ^ a) ^ b.rotate_left(21)) ^ c.rotate_left(42))
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box–Muller, both outputs used).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        // 1 − u ∈ (0, 1] keeps the logarithm finite.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
        self.spare_normal = Some(r * s);
        r * c
    }

    /// Poisson variate with mean `lambda` (≥ 0; non-finite or negative gives 0).
    pub fn poisson(&mut self, lambda: f64) -> f64 {
        if lambda <= 0.0 || !lambda.is_finite() {
            return 0.0;
        }
        if lambda < 10.0 {
            // Inversion by sequential search.
            let mut k = 0.0;
            let mut p = (-lambda).exp();
            let mut cdf = p;
            let u = self.uniform();
            while u > cdf && k < 1000.0 {
                k += 1.0;
                p *= lambda / k;
                cdf += p;
            }
            return k;
        }
        let slam = lambda.sqrt();
        let loglam = lambda.ln();
        let b = 0.931 + 2.53 * slam;
        let a = -0.059 + 0.02483 * b;
        let invalpha = 1.1239 + 1.1328 / (b - 3.4);
        let vr = 0.9277 - 3.6224 / (b - 2.0);
        loop {
            let u = self.uniform() - 0.5;
            let v = self.uniform();
            let us = 0.5 - u.abs();
            let k = ((2.0 * a / us + b) * u + lambda + 0.43).floor();
            if us >= 0.07 && v <= vr {
                return k;
            }
            if k < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            if v.ln() + invalpha.ln() - (a / (us * us) + b).ln()
                <= -lambda + k * loglam - log_gamma(k + 1.0)
            {
                return k;
            }
        }
    }
}

/// ln Γ(x) for x ≥ 1 (Stirling series after shifting x above 7; as NumPy's `random_loggam`).
fn log_gamma(x: f64) -> f64 {
    const A: [f64; 10] = [
        8.333333333333333e-02,
        -2.777777777777778e-03,
        7.936507936507937e-04,
        -5.952380952380952e-04,
        8.417508417508418e-04,
        -1.917526917526918e-03,
        6.41025641025641e-3,
        -2.955065359477124e-02,
        1.796443723688307e-01,
        -1.39243221690590e+00,
    ];
    if x == 1.0 || x == 2.0 {
        return 0.0;
    }
    let n = if x < 7.0 { (7.0 - x) as i32 } else { 0 };
    let x0 = x + n as f64;
    let x2 = 1.0 / (x0 * x0);
    let mut gl0 = A[9];
    for k in (0..9).rev() {
        gl0 = gl0 * x2 + A[k];
    }
    let mut gl = gl0 / x0 + 0.5 * (2.0 * std::f64::consts::PI).ln() + (x0 - 0.5) * x0.ln() - x0;
    let mut x0 = x0;
    for _ in 0..n {
        x0 -= 1.0;
        gl -= x0.ln();
    }
    gl
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mean_var(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let m = xs.iter().sum::<f64>() / n;
        (
            m,
            xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0),
        )
    }

    #[test]
    fn log_gamma_matches_factorials() {
        let mut f = 1.0f64;
        for k in 1..30 {
            f *= k as f64;
            assert!((log_gamma(k as f64 + 1.0) - f.ln()).abs() < 1e-10, "{k}");
        }
    }

    #[test]
    fn normal_and_poisson_moments() {
        let mut r = SplitMix64::new(7);
        let z: Vec<f64> = (0..200_000).map(|_| r.normal()).collect();
        let (m, v) = mean_var(&z);
        assert!(m.abs() < 0.01 && (v - 1.0).abs() < 0.02, "{m} {v}");
        for lambda in [0.5, 3.0, 12.0, 250.0, 40_000.0] {
            let p: Vec<f64> = (0..100_000).map(|_| r.poisson(lambda)).collect();
            let (m, v) = mean_var(&p);
            // Standard error of the mean is sqrt(λ/n); of the variance about λ·sqrt(2/n).
            assert!(
                (m - lambda).abs() < 5.0 * (lambda / 1e5).sqrt(),
                "λ={lambda}: mean {m}"
            );
            assert!((v / lambda - 1.0).abs() < 0.03, "λ={lambda}: var {v}");
            assert!(p.iter().all(|&k| k >= 0.0 && k.fract() == 0.0));
        }
        assert_eq!(r.poisson(0.0), 0.0);
        assert_eq!(r.poisson(f64::NAN), 0.0);
    }

    #[test]
    fn streams_are_deterministic_and_distinct() {
        let a: Vec<u64> = (0..4)
            .map({
                let mut r = SplitMix64::stream(1, 2, 3, 4);
                move |_| r.next_u64()
            })
            .collect();
        let b: Vec<u64> = (0..4)
            .map({
                let mut r = SplitMix64::stream(1, 2, 3, 4);
                move |_| r.next_u64()
            })
            .collect();
        let c: Vec<u64> = (0..4)
            .map({
                let mut r = SplitMix64::stream(1, 2, 4, 3);
                move |_| r.next_u64()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
