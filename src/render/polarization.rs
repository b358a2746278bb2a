//! Stokes vectors and Mueller matrices for polarised rendering.
//!
//! Conventions are Mitsuba 3's (`mitsuba/render/mueller.h`, `fresnel.h`), so that a scene
//! renders the same here and in Mitsuba's `*_polarized` variants:
//!
//! - A Stokes vector S = (S0, S1, S2, S3) only means something together with a *reference
//!   basis vector* `b` perpendicular to the direction `forward` the light travels in: S1 > 0 is
//!   linear polarisation along `b`. Bases are never stored with Mueller matrices; functions
//!   that change them take the vectors explicitly ([`rotate_stokes_basis`]).
//! - [`rotator`]`(θ)` re-expresses a Stokes vector in a basis rotated by θ (counter-clockwise
//!   seen from the sensor, i.e. looking against `forward`); Collett, "Polarized Light", ch. 5
//!   eq. 43.
//! - Fresnel amplitudes use the Verdet sign convention for r_p (r_p = r_s at normal incidence
//!   up to sign −1) and Mitsuba's e^{+iωt} time dependence, where an absorbing index is
//!   n − ik. The optics module ([`crate::optics`]) uses e^{−iωt} (n + ik, Born & Wolf / `tmm`):
//!   its amplitudes are the complex conjugates of these (see [`film_reflection`]).
//! - Matrices are row-major, `m[row][col]`, acting on column Stokes vectors: S_out = M S_in.
//!
//! The path tracer only records S0 at the sensor, so it transports the *first row* of the
//! path's Mueller product (a Stokes covector) from the camera towards the lights instead of
//! full 4×4 matrices: `row ← row · M` per vertex, and an unpolarised emitter of radiance L
//! contributes `row[0] · L` (see [`super::stokes`]).

use glam::Vec3;
use num_complex::Complex32;

/// A Stokes vector (S0, S1, S2, S3) or, in the integrator, a Stokes covector.
pub type Stokes = [f32; 4];

/// A 4×4 Mueller matrix, row-major: `self.0[row][col]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mueller(pub [[f32; 4]; 4]);

impl Mueller {
    pub const IDENTITY: Mueller = Mueller([
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);
    pub const ZERO: Mueller = Mueller([[0.0; 4]; 4]);

    /// Matrix product `self · rhs` (apply `rhs` first).
    #[inline]
    pub fn mul(&self, rhs: &Mueller) -> Mueller {
        let mut out = [[0.0f32; 4]; 4];
        for (i, row) in out.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..4).map(|k| self.0[i][k] * rhs.0[k][j]).sum();
            }
        }
        Mueller(out)
    }

    /// M · S.
    #[inline]
    pub fn apply(&self, s: Stokes) -> Stokes {
        std::array::from_fn(|i| (0..4).map(|k| self.0[i][k] * s[k]).sum())
    }

    /// Covector times matrix: `row · M`.
    #[inline]
    pub fn left_apply(&self, row: Stokes) -> Stokes {
        std::array::from_fn(|j| (0..4).map(|k| row[k] * self.0[k][j]).sum())
    }

    #[inline]
    pub fn transpose(&self) -> Mueller {
        Mueller(std::array::from_fn(|i| {
            std::array::from_fn(|j| self.0[j][i])
        }))
    }

    #[inline]
    pub fn scale(&self, f: f32) -> Mueller {
        Mueller(self.0.map(|r| r.map(|v| v * f)))
    }

    pub fn is_finite(&self) -> bool {
        self.0.iter().flatten().all(|v| v.is_finite())
    }
}

/// Ideal depolariser: keeps `value` · S0, removes all polarisation (Mitsuba `depolarizer`).
#[inline]
pub fn depolarizer(value: f32) -> Mueller {
    let mut m = Mueller::ZERO;
    m.0[0][0] = value;
    m
}

/// Linear polariser transmitting polarisation along the basis vector (0°); `value` = 1 is ideal
/// (Collett ch. 5 eq. 13; Mitsuba `linear_polarizer`). Passes half of unpolarised light.
#[inline]
pub fn linear_polarizer(value: f32) -> Mueller {
    let a = 0.5 * value;
    Mueller([
        [a, a, 0.0, 0.0],
        [a, a, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
    ])
}

/// Rotator from cos 2θ and sin 2θ (see [`rotator`]).
#[inline]
pub fn rotator_cs(cos_2theta: f32, sin_2theta: f32) -> Mueller {
    let (c, s) = (cos_2theta, sin_2theta);
    Mueller([
        [1.0, 0.0, 0.0, 0.0],
        [0.0, c, s, 0.0],
        [0.0, -s, c, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ])
}

/// Rotation of the Stokes reference frame by `theta` radians (Mitsuba `rotator`):
/// horizontally polarised light (1, 1, 0, 0) reads (1, 0, −1, 0) after `rotator(45°)`.
#[inline]
pub fn rotator(theta: f32) -> Mueller {
    let (s, c) = (2.0 * theta).sin_cos();
    rotator_cs(c, s)
}

/// An optical element `m` rotated counter-clockwise by `theta` about the beam:
/// Rᵀ(θ) · M · R(θ) (Mitsuba `rotated_element`).
#[inline]
pub fn rotated_element(theta: f32, m: &Mueller) -> Mueller {
    let r = rotator(theta);
    r.transpose().mul(m).mul(&r)
}

/// Mitsuba's implicit Stokes basis of a direction: the first tangent of Duff et al.'s
/// orthonormal basis (`mueller::stokes_basis` = `coordinate_system(forward).first`).
#[inline]
pub fn stokes_basis(forward: Vec3) -> Vec3 {
    crate::render::geometry::Frame::from_normal(forward).s
}

/// (cos 2θ, sin 2θ) of the signed angle θ from `current` to `target` about `forward`, as in
/// Mitsuba's `rotate_stokes_basis` (θ = angle(current, target), negated when
/// forward · (current × target) < 0), without trigonometric calls: with both bases
/// perpendicular to `forward`, cos θ = current·target and sin θ = forward·(current × target).
#[inline]
pub fn basis_rotation_cs(forward: Vec3, current: Vec3, target: Vec3) -> (f32, f32) {
    let c = current.dot(target);
    let s = forward.dot(current.cross(target));
    let n2 = c * c + s * s;
    if !(n2 > 0.0 && n2.is_finite()) {
        return (1.0, 0.0);
    }
    ((c * c - s * s) / n2, 2.0 * c * s / n2)
}

/// The Mueller matrix re-expressing a Stokes vector given in basis `current` in basis
/// `target` (both ⟂ `forward`). Mitsuba `rotate_stokes_basis`.
#[inline]
pub fn rotate_stokes_basis(forward: Vec3, current: Vec3, target: Vec3) -> Mueller {
    let (c, s) = basis_rotation_cs(forward, current, target);
    rotator_cs(c, s)
}

/// Covector update `row · R(forward, current → target)`: the row is then expressed against
/// Stokes vectors given in `current` (used by the integrator; cheaper than building R).
#[inline]
pub fn row_times_rotation(row: Stokes, forward: Vec3, current: Vec3, target: Vec3) -> Stokes {
    let (c, s) = basis_rotation_cs(forward, current, target);
    // R = [[1,0,0,0],[0,c,s,0],[0,−s,c,0],[0,0,0,1]].
    [
        row[0],
        row[1] * c - row[2] * s,
        row[1] * s + row[2] * c,
        row[3],
    ]
}

/// Mueller matrix of a reflection with complex amplitudes `a_s`, `a_p` (Mitsuba convention),
/// in the basis s = perpendicular to the plane of incidence on both sides (Mitsuba
/// `specular_reflection`): with δ = arg a_p − arg a_s,
/// [[A, B, 0, 0], [B, A, 0, 0], [0, 0, C cos δ, −C sin δ], [0, 0, C sin δ, C cos δ]],
/// A = (R_s + R_p)/2, B = (R_s − R_p)/2, C = √(R_s R_p).
#[inline]
pub fn reflection_from_amplitudes(a_s: Complex32, a_p: Complex32) -> Mueller {
    let r_s = a_s.norm_sqr();
    let r_p = a_p.norm_sqr();
    let a = 0.5 * (r_s + r_p);
    let b = 0.5 * (r_s - r_p);
    let c = (r_s * r_p).sqrt();
    // cos δ, sin δ of the phase difference without atan2: a_p · conj(a_s) = |a_p||a_s| e^{iδ}.
    let z = a_p * a_s.conj();
    let (cd, sd) = if c > 0.0 {
        (z.re / c, z.im / c)
    } else {
        (0.0, 0.0)
    };
    Mueller([
        [a, b, 0.0, 0.0],
        [b, a, 0.0, 0.0],
        [0.0, 0.0, c * cd, -c * sd],
        [0.0, 0.0, c * sd, c * cd],
    ])
}

/// Polarised Fresnel amplitudes of a dielectric interface with real relative index `eta`
/// (n_inside / n_outside); `cos_theta_i` < 0 means arriving from inside. Returns
/// (a_s, a_p, cos θt signed, η_it, η_ti) — Mitsuba `fresnel_polarized(Float, Float)`, including
/// its root choice under total internal reflection (cos θt = −i·√(sin²θt − 1), Clarke,
/// "Stellar Polarimetry" App. A.2), which fixes the sign of the retardance there.
#[inline]
pub fn fresnel_polarized(cos_theta_i: f32, eta: f32) -> (Complex32, Complex32, f32, f32, f32) {
    let outside = cos_theta_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_theta_i * cos_theta_i);
    let cos_i = cos_theta_i.abs();
    let cos_t = if cos_t_sqr >= 0.0 {
        Complex32::new(cos_t_sqr.sqrt(), 0.0)
    } else {
        Complex32::new(0.0, -(-cos_t_sqr).sqrt())
    };
    let (a_s, a_p) = if eta == 1.0 || eta == 0.0 {
        (Complex32::new(0.0, 0.0), Complex32::new(0.0, 0.0))
    } else {
        (
            (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t),
            (eta_it * cos_i - cos_t) / (eta_it * cos_i + cos_t),
        )
    };
    let cos_t_signed = if cos_t_sqr >= 0.0 {
        if cos_theta_i >= 0.0 {
            -cos_t.re
        } else {
            cos_t.re
        }
    } else {
        0.0
    };
    (a_s, a_p, cos_t_signed, eta_it, eta_ti)
}

/// Polarised Fresnel amplitudes of a conductor with complex relative index `eta` = n + ik
/// (k ≥ 0, the scene's convention), light arriving from outside with `cos_theta_i` ∈ [0, 1].
/// Mitsuba `fresnel_polarized(Float, Complex)`: it conjugates the index to n − ik and takes
/// the root of cos θt with Im ≤ 0.
#[inline]
pub fn fresnel_polarized_conductor(cos_theta_i: f32, eta: Complex32) -> (Complex32, Complex32) {
    let eta = if eta.im > 0.0 { eta.conj() } else { eta };
    if eta.norm_sqr() == 0.0 || (eta.im == 0.0 && eta.re == 1.0) {
        return (Complex32::new(0.0, 0.0), Complex32::new(0.0, 0.0));
    }
    let cos_i = cos_theta_i.abs();
    let (eta_it, eta_ti) = if cos_theta_i >= 0.0 {
        (eta, eta.inv())
    } else {
        (eta.inv(), eta)
    };
    let cos_t_sqr = Complex32::new(1.0, 0.0) - eta_ti * eta_ti * (1.0 - cos_i * cos_i);
    let mut cos_t = cos_t_sqr.sqrt();
    if cos_t.im > 0.0 {
        cos_t = cos_t.conj();
    }
    let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
    let a_p = (eta_it * cos_i - cos_t) / (eta_it * cos_i + cos_t);
    (a_s, a_p)
}

/// Specular reflection off a dielectric (real `eta`) — Mitsuba `specular_reflection`.
#[inline]
pub fn specular_reflection(cos_theta_i: f32, eta: f32) -> Mueller {
    let (a_s, a_p, ..) = fresnel_polarized(cos_theta_i, eta);
    reflection_from_amplitudes(a_s, a_p)
}

/// Specular reflection off a conductor `eta` = n + ik.
#[inline]
pub fn specular_reflection_conductor(cos_theta_i: f32, eta: Complex32) -> Mueller {
    let (a_s, a_p) = fresnel_polarized_conductor(cos_theta_i, eta);
    reflection_from_amplitudes(a_s, a_p)
}

/// Specular transmission through a dielectric interface (Mitsuba `specular_transmission`),
/// in the s basis on both sides; includes the n cos θ flux factor, so M₀₀ = 1 − R for
/// unpolarised light. Zero under total internal reflection.
#[inline]
pub fn specular_transmission(cos_theta_i: f32, eta: f32) -> Mueller {
    let (a_s, a_p, cos_t, eta_it, eta_ti) = fresnel_polarized(cos_theta_i, eta);
    let factor = if cos_theta_i.abs() > 1e-8 {
        -eta_it * cos_t / cos_theta_i
    } else {
        0.0
    };
    // Transmission amplitudes t_s = 1 + r_s, t_p = (1 + r_p) n_i/n_t (real for real indices).
    let ts_amp = 1.0 + a_s.re;
    let tp_amp = (1.0 + a_p.re) * eta_ti;
    let t_s = ts_amp * ts_amp;
    let t_p = tp_amp * tp_amp;
    let a = 0.5 * factor * (t_s + t_p);
    let b = 0.5 * factor * (t_s - t_p);
    let c = factor * (t_s * t_p).sqrt();
    Mueller([
        [a, b, 0.0, 0.0],
        [b, a, 0.0, 0.0],
        [0.0, 0.0, c, 0.0],
        [0.0, 0.0, 0.0, c],
    ])
}

/// Reflection Mueller matrix of a thin film from the optics module's complex amplitudes
/// ([`crate::optics::film::FilmAmplitudes`], e^{−iωt} convention): they are conjugated into
/// Mitsuba's convention (which flips the sign of the retardance δ), so a film of zero
/// thickness gives exactly [`specular_reflection`] / [`specular_reflection_conductor`] of its
/// substrate.
#[inline]
pub fn film_reflection(r_s: Complex32, r_p: Complex32) -> Mueller {
    reflection_from_amplitudes(r_s.conj(), r_p.conj())
}

/// Degree of polarisation √(S1² + S2² + S3²) / S0 (0 for S0 ≤ 0).
#[inline]
pub fn degree_of_polarization(s: Stokes) -> f32 {
    if s[0] > 0.0 {
        (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]).sqrt() / s[0]
    } else {
        0.0
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // 4×4 matrices are compared entry by entry
mod tests {
    use super::*;
    use crate::optics::{Complex64, ThinFilm};

    const UNPOL: Stokes = [1.0, 0.0, 0.0, 0.0];

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    /// Physical validity for non-depolarising and depolarising elements alike: every fully
    /// polarised input gives an output with S0 ≥ |S1..3| (Stokes criterion), sampled densely.
    fn assert_physical(m: &Mueller, what: &str) {
        for i in 0..40 {
            for j in 0..20 {
                let phi = i as f32 / 40.0 * std::f32::consts::TAU;
                let ct = -1.0 + 2.0 * (j as f32 + 0.5) / 20.0;
                let st = (1.0 - ct * ct).sqrt();
                let s = [1.0, st * phi.cos(), st * phi.sin(), ct];
                let o = m.apply(s);
                let pol = (o[1] * o[1] + o[2] * o[2] + o[3] * o[3]).sqrt();
                assert!(
                    o[0] >= pol - 1e-5 && o[0] >= -1e-6,
                    "{what}: {s:?} → {o:?} (|pol| {pol})"
                );
            }
        }
    }

    #[test]
    fn unpolarised_reflection_dop_is_the_fresnel_ratio() {
        // Dielectric: DoP = (R_s − R_p)/(R_s + R_p), with R_s, R_p from the f64 optics core.
        for deg in [0.0f64, 20.0, 45.0, 56.31, 70.0, 85.0] {
            let cos_i = deg.to_radians().cos();
            let m = specular_reflection(cos_i as f32, 1.5);
            let out = m.apply(UNPOL);
            let bare = ThinFilm {
                ambient_ior: 1.0,
                film_ior: Complex64::new(1.5, 0.0),
                thickness_nm: 0.0,
                substrate_ior: Complex64::new(1.5, 0.0),
            }
            .response(550.0, cos_i);
            let want = ((bare.r_s - bare.r_p) / (bare.r_s + bare.r_p)) as f32;
            let dop = degree_of_polarization(out);
            assert!(close(dop, want.abs(), 2e-5), "{deg}°: DoP {dop} vs {want}");
            // s-polarised: S1 > 0 in the s basis.
            assert!(out[1] >= -1e-7, "{deg}°: {out:?}");
            assert!(close(out[0], (0.5 * (bare.r_s + bare.r_p)) as f32, 1e-6));
            assert_physical(&m, &format!("glass reflection {deg}°"));
        }
        // Brewster's angle: reflected light fully s-polarised.
        let brewster = 1.5f32.atan().cos();
        let out = specular_reflection(brewster, 1.5).apply(UNPOL);
        assert!(close(degree_of_polarization(out), 1.0, 1e-4), "{out:?}");
        // Gold at 550 nm, 60°: matches the optics core's R_s and R_p.
        let au = crate::optics::Ior::Material(crate::optics::dispersion::lookup("Au").unwrap())
            .at(550.0);
        let c = 60f64.to_radians().cos();
        let m = specular_reflection_conductor(c as f32, Complex32::new(au.re as f32, au.im as f32));
        let r = ThinFilm {
            ambient_ior: 1.0,
            film_ior: au,
            thickness_nm: 0.0,
            substrate_ior: au,
        }
        .response(550.0, c);
        let out = m.apply(UNPOL);
        assert!(close(out[0], r.r() as f32, 1e-5), "{out:?} vs {r:?}");
        assert!(close(out[1], (0.5 * (r.r_s - r.r_p)) as f32, 1e-5));
        assert_physical(&m, "gold 60°");
    }

    #[test]
    fn malus_law_for_two_polarisers() {
        for deg in [0.0f32, 15.0, 30.0, 45.0, 60.0, 90.0, 135.0] {
            let th = deg.to_radians();
            let p1 = linear_polarizer(1.0);
            let p2 = rotated_element(th, &linear_polarizer(1.0));
            let out = p2.mul(&p1).apply(UNPOL);
            let want = 0.5 * th.cos().powi(2);
            assert!(close(out[0], want, 1e-6), "{deg}°: {} vs {want}", out[0]);
            assert_physical(&p2, "rotated polariser");
        }
        // The closed form of a rotated polariser (Collett ch. 5).
        let th = 33f32.to_radians();
        let (s, c) = (2.0 * th).sin_cos();
        let m = rotated_element(th, &linear_polarizer(1.0));
        let want = [
            [1.0, c, s, 0.0],
            [c, c * c, s * c, 0.0],
            [s, s * c, s * s, 0.0],
            [0.0; 4],
        ];
        for i in 0..4 {
            for j in 0..4 {
                assert!(close(m.0[i][j], 0.5 * want[i][j], 1e-6), "{i}{j}");
            }
        }
    }

    #[test]
    fn rotator_matches_mitsuba_and_composes() {
        // Mitsuba test_mueller.py: rotator(±45°) · (1,1,0,0) = (1,0,∓1,0).
        let o = rotator(45f32.to_radians()).apply([1.0, 1.0, 0.0, 0.0]);
        assert!(close(o[1], 0.0, 1e-6) && close(o[2], -1.0, 1e-6), "{o:?}");
        let o = rotator(-45f32.to_radians()).apply([1.0, 1.0, 0.0, 0.0]);
        assert!(close(o[2], 1.0, 1e-6), "{o:?}");
        // R(a) R(b) = R(a + b); R(π) = I.
        let (a, b) = (0.3f32, 1.1f32);
        let ab = rotator(a).mul(&rotator(b));
        let want = rotator(a + b);
        for i in 0..4 {
            for j in 0..4 {
                assert!(close(ab.0[i][j], want.0[i][j], 1e-6));
                assert!(close(
                    rotator(std::f32::consts::PI).0[i][j],
                    Mueller::IDENTITY.0[i][j],
                    1e-6
                ));
            }
        }
        // Basis rotations from vectors compose: (x→y) after (z'→x) equals (z'→y).
        let f = Vec3::new(0.2, -0.3, 0.93).normalize();
        let b0 = stokes_basis(f);
        let t = f.cross(b0);
        let b1 = (b0 * 0.3f32.cos() + t * 0.3f32.sin()).normalize();
        let b2 = (b0 * (-1.2f32).cos() + t * (-1.2f32).sin()).normalize();
        let direct = rotate_stokes_basis(f, b0, b2);
        let chained = rotate_stokes_basis(f, b1, b2).mul(&rotate_stokes_basis(f, b0, b1));
        for i in 0..4 {
            for j in 0..4 {
                assert!(close(direct.0[i][j], chained.0[i][j], 1e-5), "{i}{j}");
            }
        }
        // The same as Mitsuba's angle form: θ = angle(b0, b1) = +0.3 about f.
        let want = rotator(0.3);
        for i in 0..4 {
            for j in 0..4 {
                assert!(close(
                    rotate_stokes_basis(f, b0, b1).0[i][j],
                    want.0[i][j],
                    1e-5
                ));
            }
        }
        // Covector form agrees with the matrix.
        let row = [0.7, 0.2, -0.4, 0.1];
        let r1 = row_times_rotation(row, f, b0, b2);
        let r2 = direct.left_apply(row);
        for k in 0..4 {
            assert!(close(r1[k], r2[k], 1e-6));
        }
        // Degenerate bases do not poison the result.
        let r = row_times_rotation(row, f, Vec3::ZERO, b1);
        assert_eq!(r, row);
    }

    #[test]
    fn transmission_conserves_energy_and_tir_retards() {
        for deg in [0.0f32, 30.0, 60.0, 80.0, 89.0] {
            let c = deg.to_radians().cos();
            for (ci, eta) in [(c, 1.5f32), (-c, 1.5), (c, 1.0 / 1.33)] {
                let r = specular_reflection(ci, eta);
                let t = specular_transmission(ci, eta);
                let (_, _, cos_t, ..) = fresnel_polarized(ci, eta);
                if cos_t == 0.0 && ci.abs() < 1.0 {
                    // TIR: everything reflected.
                    assert!(close(r.0[0][0], 1.0, 1e-5));
                    continue;
                }
                // Energy for each linear polarisation separately: R + T = 1.
                for s in [[1.0, 1.0, 0.0, 0.0], [1.0, -1.0, 0.0, 0.0], UNPOL] {
                    let sum = r.apply(s)[0] + t.apply(s)[0];
                    assert!(close(sum, 1.0, 2e-5), "{deg}° η{eta} ci{ci}: {sum}");
                }
                assert_physical(&t, "transmission");
                assert_physical(&r, "reflection");
            }
        }
        // Inside glass beyond the critical angle: |r_s| = |r_p| = 1 with a phase difference,
        // so 45° linear light partly turns circular (Fresnel rhomb: δ ≈ 45° at ~50–53°).
        let m = specular_reflection(-(52f32.to_radians().cos()), 1.5);
        let out = m.apply([1.0, 0.0, 1.0, 0.0]);
        assert!(close(out[0], 1.0, 1e-5), "{out:?}");
        assert!(out[3].abs() > 0.6, "retardance under TIR: {out:?}");
        assert!(close(degree_of_polarization(out), 1.0, 1e-4));
        assert_physical(&m, "TIR");
    }

    #[test]
    fn film_mueller_matches_power_reflectances_and_bare_substrate() {
        let film = ThinFilm {
            ambient_ior: 1.0,
            film_ior: Complex64::new(1.38, 0.0),
            thickness_nm: 420.0,
            substrate_ior: Complex64::new(0.2, 3.4),
        };
        for deg in [0.0f64, 30.0, 65.0, 89.0] {
            for lambda in [400.0, 550.0, 700.0] {
                let c = deg.to_radians().cos();
                let a = film.amplitudes(lambda, c);
                let r = film.response(lambda, c);
                let c32 = |z: Complex64| Complex32::new(z.re as f32, z.im as f32);
                let m = film_reflection(c32(a.r_s), c32(a.r_p));
                let out = m.apply(UNPOL);
                assert!(close(out[0], r.r() as f32, 1e-5));
                assert!(close(
                    degree_of_polarization(out),
                    ((r.r_s - r.r_p) / (r.r_s + r.r_p)).abs() as f32,
                    1e-4
                ));
                // An S-oriented analyser sees R_s / 2, a P one R_p / 2.
                let s_row = linear_polarizer(1.0).left_apply([1.0, 0.0, 0.0, 0.0]);
                let p_row = rotated_element(std::f32::consts::FRAC_PI_2, &linear_polarizer(1.0))
                    .left_apply([1.0, 0.0, 0.0, 0.0]);
                let s_seen: f32 = (0..4).map(|k| s_row[k] * out[k]).sum();
                let p_seen: f32 = (0..4).map(|k| p_row[k] * out[k]).sum();
                assert!(close(s_seen, 0.5 * r.r_s as f32, 1e-5), "{s_seen} {r:?}");
                assert!(close(p_seen, 0.5 * r.r_p as f32, 1e-5), "{p_seen} {r:?}");
                assert_physical(&m, "film");
            }
        }
        // Zero thickness: the bare substrate's matrix, including the retardance sign.
        let bare = ThinFilm {
            thickness_nm: 0.0,
            ..film
        };
        let c = 50f64.to_radians().cos();
        let a = bare.amplitudes(550.0, c);
        let m = film_reflection(
            Complex32::new(a.r_s.re as f32, a.r_s.im as f32),
            Complex32::new(a.r_p.re as f32, a.r_p.im as f32),
        );
        let want = specular_reflection_conductor(c as f32, Complex32::new(0.2, 3.4));
        for i in 0..4 {
            for j in 0..4 {
                assert!(
                    close(m.0[i][j], want.0[i][j], 1e-5),
                    "{i}{j}: {m:?} {want:?}"
                );
            }
        }
    }

    #[test]
    fn edge_cases_stay_finite() {
        for c in [0.0f32, 1e-8, 1.0, -1.0, -1e-8] {
            for eta in [1.0f32, 1.5, 1.0 / 1.5] {
                assert!(specular_reflection(c, eta).is_finite(), "{c} {eta}");
                assert!(specular_transmission(c, eta).is_finite(), "{c} {eta}");
            }
            assert!(specular_reflection_conductor(c.abs(), Complex32::new(0.2, 3.0)).is_finite());
            assert!(specular_reflection_conductor(c.abs(), Complex32::new(0.0, 0.0)).is_finite());
        }
        // Index matched: nothing reflected, everything transmitted unchanged.
        let t = specular_transmission(0.6, 1.0);
        assert!(close(t.0[0][0], 1.0, 1e-6) && close(t.0[0][1], 0.0, 1e-6));
        assert_eq!(specular_reflection(0.6, 1.0).0[0][0], 0.0);
        assert_eq!(degree_of_polarization([0.0, 0.0, 0.0, 0.0]), 0.0);
        assert_physical(&depolarizer(0.7), "depolariser");
    }
}
