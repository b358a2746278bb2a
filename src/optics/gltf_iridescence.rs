//! The Fresnel term of glTF's `KHR_materials_iridescence`, as the extension and the Khronos
//! glTF Sample Viewer compute it: Belcour & Barla's (2017) thin-film model with Schlick
//! Fresnel for both interfaces, phase shifts of 0 or π, the base's index inferred from its F0
//! with no extinction, and the spectral integral replaced by a Gaussian fit of the CIE XYZ
//! sensitivities in Fourier space (two orders), converted to linear Rec.709.
//!
//! This is what glTF viewers draw. thinfilm renders glTF films with the exact Airy sum at the
//! path's wavelengths instead ([`crate::optics::ThinFilm`]); this module exists to measure how
//! far the viewers' approximation is from that (`thinfilm bench gltf-iridescence`).
//!
//! Sources: the extension text (KhronosGroup/glTF, `KHR_materials_iridescence/README.md`,
//! "Implementation Notes") and the Sample Viewer's `evalIridescence` (iridescence.glsl). The two
//! differ in one place: the extension's text computes the optical path difference with
//! cos θ1 (the angle in the outside medium), the Sample Viewer — and Belcour & Barla's
//! derivation, where the phase is accumulated inside the film — with cos θ2.
//! [`OpdCosine`] selects which.

use std::f64::consts::PI;

/// Which cosine the optical path difference 2 n d cos θ uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpdCosine {
    /// cos θ2, the refracted angle inside the film (Sample Viewer; physically right).
    InsideFilm,
    /// cos θ1, the incident angle, as the extension's text writes it.
    Incident,
}

/// Schlick's approximation F0 + (1 − F0)(1 − cos θ)^5 (glTF 2.0 spec, Appendix B.3.4).
fn f_schlick(f0: f64, cos_theta: f64) -> f64 {
    let x = (1.0 - cos_theta).clamp(0.0, 1.0);
    let x2 = x * x;
    f0 + (1.0 - f0) * x2 * x2 * x
}

/// Normal-incidence reflectance between two real indices.
fn ior_to_f0(transmitted: f64, incident: f64) -> f64 {
    ((transmitted - incident) / (transmitted + incident)).powi(2)
}

/// The inverse of [`ior_to_f0`] against air (extinction assumed 0, as the extension does).
fn f0_to_ior(f0: f64) -> f64 {
    let s = f0.sqrt();
    (1.0 + s) / (1.0 - s)
}

/// The Sample Viewer's `evalSensitivity`: the Fourier transform of Gaussian fits to the CIE
/// XYZ colour-matching functions at optical path difference `opd_nm` and phase `shift`,
/// normalised and converted to linear Rec.709.
fn eval_sensitivity(opd_nm: f64, shift: [f64; 3]) -> [f64; 3] {
    let phase = 2.0 * PI * opd_nm * 1.0e-9;
    let val = [5.4856e-13, 4.4201e-13, 5.2481e-13];
    let pos = [1.6810e+06, 1.7953e+06, 2.2084e+06];
    let var = [4.3278e+09, 9.3046e+09, 6.6121e+09];
    let mut xyz = [0.0; 3];
    for c in 0..3 {
        xyz[c] = val[c]
            * (2.0 * PI * var[c]).sqrt()
            * (pos[c] * phase + shift[c]).cos()
            * (-phase * phase * var[c]).exp();
    }
    xyz[0] += 9.7470e-14
        * (2.0 * PI * 4.5282e+09f64).sqrt()
        * (2.2399e+06 * phase + shift[0]).cos()
        * (-4.5282e+09 * phase * phase).exp();
    let xyz = xyz.map(|v| v / 1.0685e-7);
    // XYZ → Rec.709 as the extension writes it (column-major GLSL mat3, here as rows).
    [
        3.2404542 * xyz[0] - 1.5371385 * xyz[1] - 0.4985314 * xyz[2],
        -0.9692660 * xyz[0] + 1.8760108 * xyz[1] + 0.0415560 * xyz[2],
        0.0556434 * xyz[0] - 0.2040259 * xyz[1] + 1.0572252 * xyz[2],
    ]
}

/// `F_iridescence` in linear Rec.709: the reflectance of a film of index `film_ior` and
/// thickness `thickness_nm` between `outside_ior` and a base of normal-incidence reflectance
/// `base_f0` (per channel), seen at `cos_theta1` — the Sample Viewer's `evalIridescence`,
/// including its fade of the film index to the outside index for films thinner than 0.03 nm
/// and its answer 1 under total internal reflection.
pub fn f_iridescence(
    outside_ior: f64,
    film_ior: f64,
    cos_theta1: f64,
    thickness_nm: f64,
    base_f0: [f64; 3],
    opd_cosine: OpdCosine,
) -> [f64; 3] {
    let smooth = {
        let t = (thickness_nm / 0.03).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let film = outside_ior + (film_ior - outside_ior) * smooth;
    let sin2_theta2 = (outside_ior / film).powi(2) * (1.0 - cos_theta1 * cos_theta1);
    let cos2_theta2 = 1.0 - sin2_theta2;
    if cos2_theta2 < 0.0 {
        return [1.0; 3];
    }
    let cos_theta2 = cos2_theta2.sqrt();

    // First interface (outside | film).
    let r12 = f_schlick(ior_to_f0(film, outside_ior), cos_theta1);
    let t121 = 1.0 - r12;
    let phi12 = if film < outside_ior { PI } else { 0.0 };
    let phi21 = PI - phi12;

    // Second interface (film | base), per channel.
    let base_ior = base_f0.map(|f0| f0_to_ior(f0.clamp(0.0, 0.9999)));
    let r23 = base_ior.map(|n| f_schlick(ior_to_f0(n, film), cos_theta2));
    let phi23 = base_ior.map(|n| if n < film { PI } else { 0.0 });

    let cos_opd = match opd_cosine {
        OpdCosine::InsideFilm => cos_theta2,
        OpdCosine::Incident => cos_theta1,
    };
    let opd = 2.0 * film * thickness_nm * cos_opd;
    let phi = phi23.map(|p| phi21 + p);

    let mut out = [0.0; 3];
    let mut cm = [0.0; 3];
    let mut r123 = [0.0; 3];
    for c in 0..3 {
        let r123_pow = (r12 * r23[c]).clamp(1e-5, 0.9999);
        r123[c] = r123_pow.sqrt();
        let rs = t121 * t121 * r23[c] / (1.0 - r123_pow);
        out[c] = r12 + rs;
        cm[c] = rs - t121;
    }
    for m in 1..=2 {
        let mf = m as f64;
        let sm = eval_sensitivity(mf * opd, phi.map(|p| mf * p));
        for c in 0..3 {
            cm[c] *= r123[c];
            out[c] += cm[c] * 2.0 * sm[c];
        }
    }
    out.map(|v| v.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vanishing_film_leaves_the_schlick_base() {
        // d → 0 fades the film index to the outside index: what remains is Schlick's F of
        // the base, plus the model's own floor: R12·R23 is clamped to ≥ 1e-5, so the first
        // Fourier order keeps an amplitude of 2·√1e-5 ≈ 0.006 (0.047 instead of 0.04 for a
        // dielectric at normal incidence — a small artefact of the viewers' model). Only at
        // normal incidence: obliquely, Schlick's F with F0 = 0 still reflects (1 − cos θ)^5
        // at the index-matched outside | film interface, and the film's orders come back.
        {
            let cos = 1.0;
            let f = f_iridescence(1.0, 1.8, cos, 0.0, [0.04, 0.5, 0.9], OpdCosine::InsideFilm);
            for (c, &f0) in [0.04, 0.5, 0.9].iter().enumerate() {
                let want = f_schlick(f0, cos);
                assert!((f[c] - want).abs() < 0.01, "{f:?} vs {want}");
            }
        }
    }

    #[test]
    fn total_internal_reflection_gives_one() {
        // A film thinner in index than the outside medium reflects everything beyond the
        // critical angle.
        let f = f_iridescence(1.5, 1.2, 0.2, 300.0, [0.04; 3], OpdCosine::InsideFilm);
        assert_eq!(f, [1.0; 3]);
    }

    #[test]
    fn finite_and_non_negative_over_the_domain() {
        for i in 0..=60 {
            let d = i as f64 * 20.0;
            for j in 0..=17 {
                let cos = (j as f64 * 5.0).to_radians().cos();
                for n in [1.2, 1.33, 1.8, 2.4] {
                    for f0 in [[0.04; 3], [1.0, 0.78, 0.34], [0.0; 3], [1.0; 3]] {
                        for o in [OpdCosine::InsideFilm, OpdCosine::Incident] {
                            let f = f_iridescence(1.0, n, cos, d, f0, o);
                            assert!(f.iter().all(|v| v.is_finite() && *v >= 0.0), "{f:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_two_opd_readings_agree_at_normal_incidence_only() {
        let a = f_iridescence(1.0, 1.5, 1.0, 400.0, [0.04; 3], OpdCosine::InsideFilm);
        let b = f_iridescence(1.0, 1.5, 1.0, 400.0, [0.04; 3], OpdCosine::Incident);
        assert_eq!(a, b);
        let cos = 60f64.to_radians().cos();
        let a = f_iridescence(1.0, 1.5, cos, 400.0, [0.04; 3], OpdCosine::InsideFilm);
        let b = f_iridescence(1.0, 1.5, cos, 400.0, [0.04; 3], OpdCosine::Incident);
        assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 0.01));
    }
}
