//! Fresnel terms in f32 for the hot path (Mitsuba 3 `fresnel.h` forms).

use glam::Vec3;

/// Unpolarised Fresnel reflectance of a dielectric interface (Mitsuba `fresnel`).
///
/// `eta` = n_inside / n_outside; `cos_theta_i` is signed (negative = arriving from inside).
/// Returns (R, cos θt signed opposite to cos θi, η_it, η_ti). Total internal reflection gives
/// R = 1 and cos θt = 0.
#[inline]
pub fn fresnel_dielectric(cos_theta_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_theta_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_theta_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_theta_i * cos_theta_i).max(0.0);
    let cos_i = cos_theta_i.abs();
    let cos_t = cos_theta_t_sqr.max(0.0).sqrt();
    let r = if eta == 1.0 {
        0.0
    } else if cos_i == 0.0 {
        1.0
    } else {
        let a_s = (-eta_it * cos_t + cos_i) / (eta_it * cos_t + cos_i);
        let a_p = (-eta_it * cos_i + cos_t) / (eta_it * cos_i + cos_t);
        (0.5 * (a_s * a_s + a_p * a_p)).clamp(0.0, 1.0)
    };
    let cos_theta_t = if cos_theta_i >= 0.0 { -cos_t } else { cos_t };
    (r, cos_theta_t, eta_it, eta_ti)
}

/// Unpolarised reflectance of a conductor with complex relative index `eta + i k`
/// (Mitsuba `fresnel_conductor`, after K. D. Möller, "Optics"). `cos_theta_i` ∈ [0, 1].
#[inline]
pub fn fresnel_conductor(cos_theta_i: f32, eta: f32, k: f32) -> f32 {
    let c2 = cos_theta_i * cos_theta_i;
    let s2 = (1.0 - c2).max(0.0);
    let s4 = s2 * s2;
    let temp1 = eta * eta - k * k - s2;
    let a2pb2 = (temp1 * temp1 + 4.0 * k * k * eta * eta).max(0.0).sqrt();
    let a = (0.5 * (a2pb2 + temp1)).max(0.0).sqrt();
    let term1 = a2pb2 + c2;
    let term2 = 2.0 * cos_theta_i * a;
    let r_s = (term1 - term2) / (term1 + term2);
    let term3 = a2pb2 * c2 + s4;
    let term4 = term2 * s2;
    let r_p = r_s * (term3 - term4) / (term3 + term4);
    let r = 0.5 * (r_s + r_p);
    if r.is_finite() {
        r.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// [`fresnel_conductor`] at four wavelengths (indices `eta[i] + i k[i]`): the same
/// operations lane by lane, so the same values, but the four chains of square roots and
/// divisions run side by side in SIMD lanes instead of one after another (they were the
/// bulk of a gold teapot's shading time).
#[inline]
pub fn fresnel_conductor4(cos_theta_i: f32, eta: [f32; 4], k: [f32; 4]) -> [f32; 4] {
    let mut r = [0.0; 4];
    for i in 0..4 {
        r[i] = fresnel_conductor(cos_theta_i, eta[i], k[i]);
    }
    r
}

/// Hemispherically averaged Fresnel reflectance of a dielectric with relative index `eta`
/// (Mitsuba `fresnel_diffuse_reflectance`: Egan & Hilgeman 1973 fit for η < 1, d'Eon & Irving
/// 2011 fit for η ≥ 1).
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 * inv
    } else {
        0.919317
            + inv * (-3.4793 + inv * (6.75335 + inv * (-7.80989 + inv * (4.98554 - inv * 1.36881))))
    }
}

/// Mirror reflection about the local normal (+z).
#[inline]
pub fn reflect_local(wi: Vec3) -> Vec3 {
    Vec3::new(-wi.x, -wi.y, wi.z)
}

/// Mirror reflection of `wi` about the unit vector `m`.
#[inline]
pub fn reflect(wi: Vec3, m: Vec3) -> Vec3 {
    2.0 * wi.dot(m) * m - wi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_limits() {
        let (r, ct, _, _) = fresnel_dielectric(1.0, 1.5);
        assert!((r - 0.04).abs() < 1e-6);
        assert!((ct + 1.0).abs() < 1e-6);
        // Total internal reflection from inside glass beyond the critical angle.
        let (r, ct, _, _) = fresnel_dielectric(-0.2, 1.5);
        assert_eq!(r, 1.0);
        assert_eq!(ct, 0.0);
        assert_eq!(fresnel_dielectric(0.0, 1.5).0, 1.0);
        assert_eq!(fresnel_dielectric(0.3, 1.0).0, 0.0);
    }

    #[test]
    fn conductor_reduces_to_dielectric_for_k0() {
        for c in [1.0, 0.7, 0.2, 0.01] {
            let a = fresnel_conductor(c, 1.5, 0.0);
            let b = fresnel_dielectric(c, 1.5).0;
            assert!((a - b).abs() < 1e-5, "{c}: {a} vs {b}");
        }
        assert_eq!(fresnel_conductor(0.0, 0.2, 3.0), 1.0);
        // The four-lane form is the scalar one bit for bit (gold-like, glass-like, absorbing
        // and degenerate indices, every incidence).
        let (eta, k) = ([0.18, 1.5, 2.9, 0.0], [3.4, 0.0, 3.1, 0.0]);
        for j in 0..=64 {
            let c = j as f32 / 64.0;
            let four = fresnel_conductor4(c, eta, k);
            for i in 0..4 {
                assert_eq!(
                    four[i].to_bits(),
                    fresnel_conductor(c, eta[i], k[i]).to_bits()
                );
            }
        }
    }

    #[test]
    fn diffuse_reflectance_of_glass() {
        // Known value: F_dr(1/1.5) ≈ 0.596 (internal), F_dr(1.5) ≈ 0.092 (external).
        assert!((fresnel_diffuse_reflectance(1.0 / 1.5) - 0.596).abs() < 0.01);
        assert!((fresnel_diffuse_reflectance(1.5) - 0.092).abs() < 0.01);
    }
}
