//! Complex numbers in `N` lanes (one per wavelength of a bundle), for kernels written once
//! for one wavelength (`N = 1`) and for the renderer's four at a time.
//!
//! Each operation is `num_complex`'s formula lane by lane — `(a+ib)(c+id) = (ac − bd) +
//! i(ad + bc)`, division by `(a+ib)·conj(c+id) / |c+id|²` — so a lane's value equals the
//! scalar `Complex64` computation bit for bit, while the compiler keeps the lanes in SIMD
//! registers.

use num_complex::Complex64;
use std::ops::{Add, Div, Mul, Sub};

/// `[f(0), …, f(N − 1)]` by a plain loop (which the compiler unrolls into SIMD operations;
/// `std::array::from_fn` was seen left as a call per operation).
#[inline(always)]
pub(super) fn lanes<const N: usize>(f: impl Fn(usize) -> f64) -> [f64; N] {
    let mut out = [0.0; N];
    for (k, o) in out.iter_mut().enumerate() {
        *o = f(k);
    }
    out
}

/// `N` complex numbers, real and imaginary parts apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Cx<const N: usize> {
    pub re: [f64; N],
    pub im: [f64; N],
}

impl<const N: usize> Cx<N> {
    pub const ZERO: Self = Cx {
        re: [0.0; N],
        im: [0.0; N],
    };

    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> Complex64) -> Self {
        let mut z = Self::ZERO;
        for k in 0..N {
            let c = f(k);
            z.re[k] = c.re;
            z.im[k] = c.im;
        }
        z
    }

    #[inline(always)]
    pub fn lane(&self, k: usize) -> Complex64 {
        Complex64::new(self.re[k], self.im[k])
    }

    /// `self · x` with a real factor per lane (`Complex * f64`).
    #[inline(always)]
    pub fn scale(self, x: [f64; N]) -> Self {
        Cx {
            re: lanes(|k| self.re[k] * x[k]),
            im: lanes(|k| self.im[k] * x[k]),
        }
    }

    /// `x · self` with one real factor (`f64 * Complex`).
    #[inline(always)]
    pub fn times(self, x: f64) -> Self {
        self.scale([x; N])
    }

    /// `x + self` with a real `x` (`f64 + Complex`).
    #[inline(always)]
    pub fn plus(self, x: f64) -> Self {
        Cx {
            re: lanes(|k| x + self.re[k]),
            im: self.im,
        }
    }

    #[inline(always)]
    pub fn norm_sqr(&self) -> [f64; N] {
        lanes(|k| self.re[k] * self.re[k] + self.im[k] * self.im[k])
    }
}

impl<const N: usize> Add for Cx<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Cx {
            re: lanes(|k| self.re[k] + o.re[k]),
            im: lanes(|k| self.im[k] + o.im[k]),
        }
    }
}

impl<const N: usize> Sub for Cx<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Cx {
            re: lanes(|k| self.re[k] - o.re[k]),
            im: lanes(|k| self.im[k] - o.im[k]),
        }
    }
}

impl<const N: usize> Mul for Cx<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Cx {
            re: lanes(|k| self.re[k] * o.re[k] - self.im[k] * o.im[k]),
            im: lanes(|k| self.re[k] * o.im[k] + self.im[k] * o.re[k]),
        }
    }
}

impl<const N: usize> Div for Cx<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let norm = o.norm_sqr();
        Cx {
            re: lanes(|k| (self.re[k] * o.re[k] + self.im[k] * o.im[k]) / norm[k]),
            im: lanes(|k| (self.im[k] * o.re[k] - self.re[k] * o.im[k]) / norm[k]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn finite() -> impl Strategy<Value = f64> {
        prop_oneof![-1e3..1e3f64, -1e-3..1e-3f64, Just(0.0), Just(-0.0)]
    }

    proptest! {
        /// Every lane equals `num_complex`'s scalar operation bit for bit (NaN where it
        /// gives NaN), including the real-factor forms.
        #[test]
        fn lanes_equal_scalar_complex(
            a in proptest::collection::vec((finite(), finite()), 3),
            b in proptest::collection::vec((finite(), finite()), 3),
            x in finite(),
        ) {
            let za: Vec<Complex64> = a.iter().map(|&(r, i)| Complex64::new(r, i)).collect();
            let zb: Vec<Complex64> = b.iter().map(|&(r, i)| Complex64::new(r, i)).collect();
            let la = Cx::<3>::from_fn(|k| za[k]);
            let lb = Cx::<3>::from_fn(|k| zb[k]);
            let same = |l: Cx<3>, f: &dyn Fn(usize) -> Complex64| {
                (0..3).all(|k| {
                    let (g, w) = (l.lane(k), f(k));
                    (g.re.to_bits() == w.re.to_bits() || (g.re.is_nan() && w.re.is_nan()))
                        && (g.im.to_bits() == w.im.to_bits() || (g.im.is_nan() && w.im.is_nan()))
                })
            };
            prop_assert!(same(la + lb, &|k| za[k] + zb[k]));
            prop_assert!(same(la - lb, &|k| za[k] - zb[k]));
            prop_assert!(same(la * lb, &|k| za[k] * zb[k]));
            prop_assert!(same(la / lb, &|k| za[k] / zb[k]));
            prop_assert!(same(la.times(x), &|k| x * za[k]));
            prop_assert!(same(la.scale([x; 3]), &|k| za[k] * x));
            prop_assert!(same(la.plus(x), &|k| x + za[k]));
            for (n, z) in la.norm_sqr().iter().zip(&za) {
                prop_assert_eq!(n.to_bits(), z.norm_sqr().to_bits());
            }
        }
    }
}
