//! Complex Fresnel amplitudes for s and p polarisation (seed eqs. 6, 7), valid for
//! absorbing media and evanescent waves.

use num_complex::Complex64;

/// `n cosθ` in a medium of index `n` for a ray whose invariant is `n1 sinθ1 = kx`.
///
/// Picks the square-root branch of the forward wave: `Im(n cosθ) ≥ 0` (decaying into
/// the medium), and `Re(n cosθ) > 0` where the wave propagates without loss. This is the
/// branch `tmm` uses (`is_forward_angle`) and the one that keeps `e^{iβ}` bounded.
#[inline]
pub fn n_cos_theta(n: Complex64, kx: f64) -> Complex64 {
    let nc = (n * n - kx * kx).sqrt();
    // sqrt() returns the principal root (Re ≥ 0); flip to the forward branch when needed.
    // (A real root skips the norm: 0 > x is false for every x the norm can give.)
    let forward = if nc.im != 0.0 && nc.im.abs() > 100.0 * f64::EPSILON * nc.norm().max(1e-300) {
        nc.im > 0.0
    } else {
        nc.re > 0.0
    };
    if forward {
        nc
    } else {
        -nc
    }
}

/// Fresnel amplitude coefficients of one interface, from medium i into medium f.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InterfaceAmplitudes {
    pub r_s: Complex64,
    pub r_p: Complex64,
    pub t_s: Complex64,
    pub t_p: Complex64,
}

/// Fresnel amplitudes at an interface i → f.
///
/// `ni_cos`/`nf_cos` are `n cosθ` of each medium (see [`n_cos_theta`]); `cos_i`/`cos_f`
/// the (complex) cosines. Written in the form of `tmm.interface_r/t`.
#[inline]
pub fn interface(
    n_i: Complex64,
    n_f: Complex64,
    cos_i: Complex64,
    cos_f: Complex64,
) -> InterfaceAmplitudes {
    let a_s = n_i * cos_i;
    let b_s = n_f * cos_f;
    let a_p = n_f * cos_i;
    let b_p = n_i * cos_f;
    InterfaceAmplitudes {
        r_s: (a_s - b_s) / (a_s + b_s),
        r_p: (a_p - b_p) / (a_p + b_p),
        t_s: 2.0 * a_s / (a_s + b_s),
        t_p: 2.0 * n_i * cos_i / (a_p + b_p),
    }
}
