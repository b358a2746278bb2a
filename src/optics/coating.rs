//! A coating: coherent layers of (possibly dispersive) materials between a lossless ambient
//! and a substrate, evaluated at any wavelength without building a [`Stack`].
//!
//! A renderer asks for the stack's response at four wavelengths per shading point, and a
//! dielectric mirror such as `(TiO2:51.9, SiO2:94.2)x6, TiO2:51.9` repeats two materials
//! thirteen times. So the distinct materials are found once, here, and at each wavelength
//! every one of them is evaluated once — its index and its `n cosθ` (a complex square root)
//! — and shared by all the layers made of it; so is the phase factor `e^{iβ}` (a sine and a
//! cosine per wavelength) of all the layers of one material and thickness. The four
//! wavelengths go through the recursion together, in SIMD lanes. The recursion itself is
//! [`Stack`]'s (the same function), so the values equal [`Coating::stack_at`]`(λ)` evaluated
//! as a [`Stack`] bit for bit, without the allocations of the general (incoherent-capable)
//! path.

use super::film::{FilmAmplitudes, FilmResponse};
use super::ior::Ior;
use super::lanes::lanes;
use super::stack::{
    layer_phase, rouard, t_power, AmplitudeLanes, Layer, LayerPhase, Medium, MediumLanes, Stack,
};

/// Distinct materials (and distinct material–thickness pairs) whose media (phases) are kept
/// on the stack per evaluation; layers of further ones (rare) are evaluated where they are
/// used.
const CACHED: usize = 8;

/// Coherent layers of named or constant indices on a substrate.
#[derive(Debug, Clone, PartialEq)]
pub struct Coating {
    /// Ambient (incidence) medium; its real part is used (lossless).
    ambient_ior: Ior,
    /// The distinct layer materials.
    materials: Vec<Ior>,
    /// The distinct layers: material (an index into `materials`) and thickness in nm.
    kinds: Vec<(usize, f64)>,
    /// Each layer's kind (an index into `kinds`), top first.
    layers: Vec<usize>,
    substrate_ior: Ior,
}

impl Coating {
    /// `layers` (index, thickness nm) from the ambient side down to the substrate.
    pub fn new(ambient_ior: Ior, layers: &[(Ior, f64)], substrate_ior: Ior) -> Self {
        fn id_of<T: PartialEq + Clone>(list: &mut Vec<T>, x: &T) -> usize {
            list.iter().position(|y| y == x).unwrap_or_else(|| {
                list.push(x.clone());
                list.len() - 1
            })
        }
        let mut materials = Vec::new();
        let mut kinds = Vec::new();
        let layers = (layers.iter())
            .map(|(n, d)| {
                let material = id_of(&mut materials, n);
                // (Thicknesses compare by bits: equal phases need equal values.)
                let kind = (kinds.iter())
                    .position(|&(m, t): &(usize, f64)| m == material && t.to_bits() == d.to_bits());
                kind.unwrap_or_else(|| {
                    kinds.push((material, *d));
                    kinds.len() - 1
                })
            })
            .collect();
        Coating {
            ambient_ior,
            materials,
            kinds,
            layers,
            substrate_ior,
        }
    }

    /// The same layers seen from the substrate: substrate and ambient swapped, layers in
    /// reverse order (the substrate's index must then be real).
    pub fn reversed(&self) -> Coating {
        Coating {
            ambient_ior: self.substrate_ior.clone(),
            materials: self.materials.clone(),
            kinds: self.kinds.clone(),
            layers: self.layers.iter().rev().copied().collect(),
            substrate_ior: self.ambient_ior.clone(),
        }
    }

    /// The stack at one wavelength (every layer coherent): for validation, and the
    /// reference the fast path equals.
    pub fn stack_at(&self, lambda_nm: f64) -> Stack {
        Stack {
            ambient_ior: self.ambient_ior.at(lambda_nm).re,
            layers: (self.layers.iter())
                .map(|&kind| {
                    let (id, d) = self.kinds[kind];
                    Layer::coherent(self.materials[id].at(lambda_nm), d)
                })
                .collect(),
            substrate_ior: self.substrate_ior.at(lambda_nm),
        }
    }

    /// The Rouard recursion at `N` wavelengths (in lanes), `cos θ1` in the ambient (clamped
    /// to [0, 1]); also each wavelength's ambient and substrate media (for transmitted
    /// powers).
    #[inline]
    fn solve<const N: usize, const WITH_T: bool>(
        &self,
        lambda_nm: [f64; N],
        cos_theta1: f64,
    ) -> (AmplitudeLanes<N>, [Medium; N], [Medium; N]) {
        let ambient_n = self.ambient_ior.at_lanes(lambda_nm);
        let ambient_kx = ambient_n.map(|n| Medium::ambient(n.re, cos_theta1));
        let ambient = ambient_kx.map(|(m, _)| m);
        let kx = ambient_kx.map(|(_, kx)| kx);
        let media_of = |m: &Ior| {
            let n = m.at_lanes(lambda_nm);
            // A plain loop: `std::array::from_fn` was seen left as calls (see `lanes`).
            let mut lanes = [Medium::new(n[0], kx[0]); N];
            for (k, m) in lanes.iter_mut().enumerate().skip(1) {
                *m = Medium::new(n[k], kx[k]);
            }
            lanes
        };
        let substrate = media_of(&self.substrate_ior);
        let ambient_lanes = MediumLanes::from_lanes(&ambient);
        let substrate_lanes = MediumLanes::from_lanes(&substrate);
        let mut media = [ambient_lanes; CACHED];
        for (c, m) in media.iter_mut().zip(&self.materials) {
            *c = MediumLanes::from_lanes(&media_of(m));
        }
        // Materials past the first CACHED (rare): on the heap, also computed once.
        let extra: Vec<MediumLanes<N>> = (self.materials.iter().skip(CACHED))
            .map(|m| MediumLanes::from_lanes(&media_of(m)))
            .collect();
        // perf: the recursion borrows the media instead of taking 192-byte copies from
        // closures (which the compiler did not always inline: a 13-layer mirror's render
        // once took 35 % longer with the same code, compiled beside other changes).
        let layer_medium = |id: usize| media.get(id).unwrap_or_else(|| &extra[id - CACHED]);
        let kind_phase = |&(id, d): &(usize, f64)| layer_phase(layer_medium(id), d, lambda_nm);
        let mut phases = [LayerPhase::ZERO; CACHED];
        for (p, kind) in phases.iter_mut().zip(&self.kinds) {
            *p = kind_phase(kind);
        }
        let len = self.layers.len() + 2;
        let medium = |j: usize| match j {
            0 => &ambient_lanes,
            j if j == len - 1 => &substrate_lanes,
            j => layer_medium(self.kinds[self.layers[j - 1]].0),
        };
        let phase = |j: usize, m: &MediumLanes<N>| match phases.get(self.layers[j]) {
            Some(p) => *p,
            None => layer_phase(m, self.kinds[self.layers[j]].1, lambda_nm),
        };
        let a = rouard::<N, WITH_T>(len, medium, phase);
        (a, ambient, substrate)
    }

    /// Complex amplitudes (r_s, r_p, t_s, t_p) at each wavelength, `cos θ1` in the ambient.
    pub fn amplitudes<const N: usize>(
        &self,
        lambda_nm: [f64; N],
        cos_theta1: f64,
    ) -> [FilmAmplitudes; N] {
        let a = self.solve::<N, true>(lambda_nm, cos_theta1).0;
        std::array::from_fn(|k| a.lane(k))
    }

    /// Unpolarised reflectance (R_s + R_p)/2 at each wavelength (no transmission amplitudes
    /// computed).
    pub fn reflectance<const N: usize>(&self, lambda_nm: [f64; N], cos_theta1: f64) -> [f64; N] {
        let a = self.solve::<N, false>(lambda_nm, cos_theta1).0;
        lanes(|k| {
            let a = a.lane(k);
            0.5 * (a.r_s.norm_sqr() + a.r_p.norm_sqr())
        })
    }

    /// Power R and T (s, p) at each wavelength, as [`Stack::response`] of
    /// [`Coating::stack_at`].
    pub fn response<const N: usize>(
        &self,
        lambda_nm: [f64; N],
        cos_theta1: f64,
    ) -> [FilmResponse; N] {
        let (a, ambient, substrate) = self.solve::<N, true>(lambda_nm, cos_theta1);
        std::array::from_fn(|k| {
            let a = a.lane(k);
            let [t_s, t_p] = t_power(&a, &ambient[k], &substrate[k]);
            FilmResponse {
                r_s: a.r_s.norm_sqr(),
                r_p: a.r_p.norm_sqr(),
                t_s,
                t_p,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ior(s: &str) -> Ior {
        s.parse().unwrap()
    }

    /// Every path equals the general `Stack` of the same layers at the same wavelength bit
    /// for bit: mirrors of repeated materials, more distinct materials than are cached, an
    /// absorbing layer and substrate, a bare interface, seen from both sides, from normal to
    /// grazing incidence (where the substrate side has total internal reflection).
    #[test]
    fn equals_the_general_stack_bit_for_bit() {
        let mut mirror = Vec::new();
        for _ in 0..6 {
            mirror.push((ior("TiO2"), 51.9));
            mirror.push((ior("SiO2"), 94.2));
        }
        mirror.push((ior("TiO2"), 51.9));
        let many: Vec<(Ior, f64)> = (0..11)
            .map(|i| (Ior::real(1.3 + 0.1 * i as f64), 20.0 + 7.0 * i as f64))
            .collect();
        let cases = [
            Coating::new(Ior::real(1.0), &mirror, ior("BK7")),
            Coating::new(Ior::real(1.0), &many, ior("1.52")),
            Coating::new(
                Ior::real(1.0),
                &[(ior("MgF2"), 99.6), (ior("1.5+0.2i"), 30.0)],
                ior("Au"),
            ),
            Coating::new(Ior::real(1.0), &[], ior("BK7")),
            Coating::new(ior("BK7"), &[(ior("MgF2"), 120.0)], Ior::real(1.0)),
            Coating::new(Ior::real(1.0), &mirror, ior("BK7")).reversed(),
        ];
        let bundle = [380.0, 471.3, 550.0, 779.9];
        for c in &cases {
            for cos in [1.0, 0.8, 0.31, 0.02, 0.0, 1.2, -0.1] {
                // Four wavelengths in lanes, and one alone.
                let responses = c.response(bundle, cos);
                let reflectances = c.reflectance(bundle, cos);
                let amplitudes = c.amplitudes(bundle, cos);
                for (k, &lambda) in bundle.iter().enumerate() {
                    let s = c.stack_at(lambda);
                    let want = s.response(lambda, cos);
                    for got in [responses[k], c.response([lambda], cos)[0]] {
                        for (x, y) in [
                            (got.r_s, want.r_s),
                            (got.r_p, want.r_p),
                            (got.t_s, want.t_s),
                            (got.t_p, want.t_p),
                        ] {
                            assert_eq!(x.to_bits(), y.to_bits(), "{c:?} λ {lambda} cos {cos}");
                        }
                    }
                    assert_eq!(reflectances[k].to_bits(), want.r().to_bits());
                    assert_eq!(amplitudes[k], s.amplitudes(lambda, cos));
                }
            }
        }
    }

    #[test]
    fn distinct_materials_and_layers_are_shared() {
        let layers = [
            (ior("TiO2"), 50.0),
            (ior("SiO2"), 90.0),
            (ior("tio2"), 50.0),
            (Ior::real(1.38), 10.0),
            (Ior::real(1.38), 12.0),
        ];
        let c = Coating::new(Ior::real(1.0), &layers, ior("BK7"));
        assert_eq!(c.materials.len(), 3);
        assert_eq!(c.kinds, [(0, 50.0), (1, 90.0), (2, 10.0), (2, 12.0)]);
        assert_eq!(c.layers, [0, 1, 0, 2, 3]);
    }
}
