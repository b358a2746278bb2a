//! A BSDF value for polarised transport ([`super::PolarizedBsdf`]), with Mitsuba 3's
//! conventions (`mitsuba/render/mueller.h`; see [`crate::render::polarization`]).

use crate::render::polarization::{rotate_stokes_basis, Mueller};
use crate::render::texture::Spec;
use glam::Vec3;

/// A Mueller-matrix BSDF value in the local shading frame: a depolarising part (only S0
/// survives, scaled per wavelength) plus, optionally, a polarising part.
#[derive(Debug, Clone, Copy)]
pub struct MuellerValue {
    /// Scales S0 of the incident light, per wavelength; the outgoing light is unpolarised.
    pub depolarized: Spec,
    pub polarized: Option<PolarizedLobe>,
}

/// A polarising lobe: a Mueller matrix per wavelength and the Stokes bases it is expressed
/// in — `s_in` (⟂ wo) for the light arriving along −wo, `s_out` (⟂ wi) for the light leaving
/// along wi (local frame). A specular lobe's natural bases are the s directions of its plane
/// of incidence ([`MuellerValue::specular`]).
#[derive(Debug, Clone, Copy)]
pub struct PolarizedLobe {
    pub m: [Mueller; 4],
    pub s_in: Vec3,
    pub s_out: Vec3,
}

/// Unit s axis n × v (None when v is along n).
#[inline]
fn s_axis(n: Vec3, v: Vec3) -> Option<Vec3> {
    let c = n.cross(v);
    let l2 = c.length_squared();
    (l2 > 1e-14).then(|| c / l2.sqrt())
}

impl MuellerValue {
    pub const ZERO: MuellerValue = MuellerValue {
        depolarized: Spec::ZERO,
        polarized: None,
    };

    /// A depolariser of value `v` (diffuse lobes).
    #[inline]
    pub fn depolarizing(v: Spec) -> Self {
        MuellerValue {
            depolarized: v,
            polarized: None,
        }
    }

    /// A polarising lobe with bases `s_in`, `s_out`.
    #[inline]
    pub fn polarizing(m: [Mueller; 4], s_in: Vec3, s_out: Vec3) -> Self {
        MuellerValue {
            depolarized: Spec::ZERO,
            polarized: Some(PolarizedLobe { m, s_in, s_out }),
        }
    }

    /// A specular interaction about the (micro)facet normal `normal` (local), in its
    /// natural bases: the s directions normal × (−wo) and normal × wi of the plane of
    /// incidence, with Mitsuba's fallback (1, 0, 0) when the directions are collinear with
    /// the normal.
    #[inline]
    pub fn specular(m: [Mueller; 4], normal: Vec3, wi: Vec3, wo: Vec3) -> Self {
        let (s_in, s_out) = match s_axis(normal, -wo) {
            Some(a) => (a, s_axis(normal, wi).unwrap_or(a)),
            None => (Vec3::X, Vec3::X),
        };
        Self::polarizing(m, s_in, s_out)
    }

    /// Every part times `f`.
    #[inline]
    pub fn scaled(mut self, f: f32) -> Self {
        self.depolarized *= f;
        if let Some(p) = &mut self.polarized {
            p.m = p.m.map(|x| x.scale(f));
        }
        self
    }

    /// The value seen in the frame mirrored at the tangent plane (a two-sided model
    /// evaluated from below): the bases are mirrored.
    #[inline]
    pub fn mirrored(mut self) -> Self {
        if let Some(p) = &mut self.polarized {
            let flip = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
            p.s_in = flip(p.s_in);
            p.s_out = flip(p.s_out);
        }
        self
    }

    /// The sum of two values at the same (wi, wo): `other`'s polarising part is re-expressed
    /// in this value's bases first (M' = R_out · M · R_inᵀ, Mitsuba's
    /// `rotate_mueller_basis`).
    pub fn plus(self, other: MuellerValue, wi: Vec3, wo: Vec3) -> Self {
        let depolarized = self.depolarized + other.depolarized;
        let polarized = match (self.polarized, other.polarized) {
            (None, p) | (p, None) => p,
            (Some(a), Some(b)) => {
                let r_in = rotate_stokes_basis(-wo, a.s_in, b.s_in);
                let r_out = rotate_stokes_basis(wi, b.s_out, a.s_out);
                let m = std::array::from_fn(|k| {
                    let b_in_a = r_out.mul(&b.m[k]).mul(&r_in);
                    Mueller(std::array::from_fn(|i| {
                        std::array::from_fn(|j| a.m[k].0[i][j] + b_in_a.0[i][j])
                    }))
                });
                Some(PolarizedLobe { m, ..a })
            }
        };
        MuellerValue {
            depolarized,
            polarized,
        }
    }

    /// What unpolarised light sees: S0 out per unit S0 in, per wavelength (the unpolarised
    /// BSDF value).
    #[inline]
    pub fn unpolarized(&self) -> Spec {
        let mut v = self.depolarized;
        if let Some(p) = &self.polarized {
            v += Spec::new(
                p.m[0].0[0][0],
                p.m[1].0[0][0],
                p.m[2].0[0][0],
                p.m[3].0[0][0],
            );
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::polarization::{linear_polarizer, specular_reflection, Stokes};

    /// M applied to a Stokes vector given in basis `s_in`, result read in `s_out`.
    fn apply(p: &PolarizedLobe, k: usize, s: Stokes) -> Stokes {
        p.m[k].apply(s)
    }

    #[test]
    fn sums_in_common_bases_and_keeps_the_unpolarised_value() {
        let wi = Vec3::new(0.3, 0.1, 0.9).normalize();
        let wo = Vec3::new(-0.5, 0.2, 0.8).normalize();
        let a = MuellerValue::specular([specular_reflection(0.7, 1.5); 4], Vec3::Z, wi, wo);
        // The same matrix expressed in bases rotated by 90° about each beam: a polariser
        // along s reads as one along t there.
        let pol = linear_polarizer(1.0);
        let b_same = MuellerValue::polarizing(
            [pol; 4],
            a.polarized.unwrap().s_in,
            a.polarized.unwrap().s_out,
        );
        let sum = a.plus(b_same, wi, wo);
        let p = sum.polarized.unwrap();
        let want = specular_reflection(0.7, 1.5).0[0][0] + 0.5;
        assert!((p.m[0].0[0][0] - want).abs() < 1e-6);
        assert!((sum.unpolarized().x - want).abs() < 1e-6);
        // Unpolarised in, S0 out = the two values added, whatever the bases.
        let turned = MuellerValue::polarizing(
            [pol; 4],
            (-wo).cross(a.polarized.unwrap().s_in).normalize(),
            wi.cross(a.polarized.unwrap().s_out).normalize(),
        );
        let s = a.plus(turned, wi, wo);
        let out = apply(&s.polarized.unwrap(), 0, [1.0, 0.0, 0.0, 0.0]);
        assert!((out[0] - want).abs() < 1e-5, "{out:?}");
        // The turned polariser passes t-polarised light of the specular lobe's bases.
        let t_in = apply(&s.polarized.unwrap(), 0, [1.0, -1.0, 0.0, 0.0]);
        let s_in = apply(&s.polarized.unwrap(), 0, [1.0, 1.0, 0.0, 0.0]);
        let r = specular_reflection(0.7, 1.5);
        assert!(
            (t_in[0] - (r.0[0][0] - r.0[0][1] + 1.0)).abs() < 1e-5,
            "{t_in:?}"
        );
        assert!((s_in[0] - (r.0[0][0] + r.0[0][1])).abs() < 1e-5, "{s_in:?}");
    }
}
