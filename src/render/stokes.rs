//! What a path carries when the scene asks for a polariser ([`StokesPath`], a
//! [`Carrier`] of the one integrator): light carries Stokes vectors and BSDFs act as Mueller
//! matrices ([`crate::render::bsdf::PolarizedBsdf`]), with Mitsuba 3's conventions
//! ([`super::polarization`]). Scenes without a polariser never use it (effect analysis).
//!
//! **Adjoint (covector) transport.** The sensor records S0 only, and emitters are
//! unpolarised, so the measured value of a path with Mueller matrices M₁ … M_k (camera side
//! first) is e₀ᵀ · M₁ ⋯ M_k · (L, 0, 0, 0)ᵀ. Mitsuba multiplies full 4×4 throughput matrices;
//! here the row vector `row = e₀ᵀ · M₁ ⋯ M_j` (4 numbers per wavelength) is carried from the
//! camera instead — exactly the first row of Mitsuba's throughput, at a quarter of the cost.
//! `row[0]` is Mitsuba's `unpolarized_spectrum(throughput)`, used for Russian roulette.
//!
//! **Reference frames.** `row` is expressed against Stokes vectors of light travelling along
//! `−ray.dir` in the basis vector `basis` (world). Each BSDF value comes in its natural bases
//! ([`MuellerValue`]: s = n × (−wo) on the incident side, s = n × wi on the outgoing side,
//! with the microfacet normal for rough lobes), and the row is rotated into them first:
//! `row ← row · R(wi, s_out → basis) · M`, after which `basis = s_in`. Frame choices cancel, so
//! the result equals Mitsuba's, which routes everything through `stokes_basis(direction)`.
//!
//! **Sensor polariser** ([`crate::scene::Polarizer`]): the path starts from the covector of an
//! ideal polariser, e₀ᵀ·P = (½, ±½, 0, 0) in the polariser's basis: for `S`/`P` the basis is
//! the s direction n × wi of the camera ray's first hit (so S passes R_s/2 of unpolarised
//! light reflected there, P passes R_p/2), for an angle it is the axis in the image plane
//! projected perpendicular to the ray (Korger et al. 2013, as Mitsuba's `polarizer` BSDF).

use super::bsdf::{Bsdf, BsdfSample, Lobes, MuellerValue, ShadingCtx};
use super::integrator::{Carrier, VertexFrame};
use super::polarization::{row_times_rotation, stokes_basis, Stokes};
use super::texture::Spec;
use crate::scene::{Polarizer, Scene};
use glam::{Vec2, Vec3};

/// What polarised transport needs of the scene: the sensor's polariser and the image axes.
#[derive(Debug, Clone)]
pub struct PolarizedSetup {
    /// Polariser in front of the sensor, if any.
    pub sensor: Option<Polarizer>,
    /// World directions of the image's +x (rightwards) and +y (upwards) axes.
    image_x: Vec3,
    image_y: Vec3,
}

impl PolarizedSetup {
    pub fn new(scene: &Scene) -> Self {
        let m = scene.camera.to_world;
        PolarizedSetup {
            sensor: scene.polarizer,
            image_x: -m.transform_vector3(Vec3::X).normalize(),
            image_y: m.transform_vector3(Vec3::Y).normalize(),
        }
    }

    /// The sensor polariser's covector and basis for a camera ray along `dir`, given the
    /// first hit's shading normal (None on a miss); None without a sensor polariser.
    fn sensor_row(&self, dir: Vec3, first_normal: Option<Vec3>) -> Option<(Stokes, Vec3)> {
        let forward = -dir;
        let fallback = stokes_basis(forward);
        Some(match self.sensor? {
            Polarizer::AngleDeg(deg) => {
                let (s, c) = deg.to_radians().sin_cos();
                let a = c * self.image_x + s * self.image_y;
                let a = a - a.dot(forward) * forward;
                let basis = if a.length_squared() > 1e-12 {
                    a.normalize()
                } else {
                    fallback
                };
                ([0.5, 0.5, 0.0, 0.0], basis)
            }
            p => {
                // s direction of the first hit's plane of incidence: n × wi (Mitsuba's
                // s_axis_out).
                let basis = first_normal
                    .map(|n| n.cross(forward))
                    .filter(|c| c.length_squared() > 1e-14)
                    .map_or(fallback, Vec3::normalize);
                let sign = if p == Polarizer::S { 0.5 } else { -0.5 };
                ([0.5, sign, 0.0, 0.0], basis)
            }
        })
    }

    /// S0 of the sensor's covector: what the polariser passes of unpolarised light that
    /// reaches the camera directly (camera rays that hit nothing).
    pub fn unpolarized_transmission(&self) -> f32 {
        if self.sensor.is_some() {
            0.5
        } else {
            1.0
        }
    }
}

/// A path's Stokes covectors (one per wavelength) and the basis they are expressed in.
#[derive(Debug, Clone, Copy)]
pub struct StokesPath {
    rows: [Stokes; 4],
    basis: Vec3,
}

impl StokesPath {
    /// The row after a vertex of value `value` (local bases in `v.frame`): light then travels
    /// along −`wo_world`.
    fn apply(&mut self, value: &MuellerValue, v: &VertexFrame, wo_world: Vec3) {
        let d = value.depolarized.to_array();
        match &value.polarized {
            None => {
                for (row, d) in self.rows.iter_mut().zip(d) {
                    *row = [row[0] * d, 0.0, 0.0, 0.0];
                }
                self.basis = stokes_basis(-wo_world);
            }
            Some(p) => {
                let s_out = v.frame.to_world(p.s_out);
                for ((row, m), d) in self.rows.iter_mut().zip(&p.m).zip(d) {
                    let r = row_times_rotation(*row, v.wi_world, s_out, self.basis);
                    let mut out = m.left_apply(r);
                    out[0] += row[0] * d;
                    *row = out;
                }
                self.basis = v.frame.to_world(p.s_in);
            }
        }
    }

    /// row · M · e₀ per wavelength: what an unpolarised source seen through `value`
    /// contributes.
    fn column0(&self, value: &MuellerValue, v: &VertexFrame) -> Spec {
        let d = value.depolarized.to_array();
        let mut out: [f32; 4] = std::array::from_fn(|k| self.rows[k][0] * d[k]);
        if let Some(p) = &value.polarized {
            let s_out = v.frame.to_world(p.s_out);
            for (k, o) in out.iter_mut().enumerate() {
                let r = row_times_rotation(self.rows[k], v.wi_world, s_out, self.basis);
                *o += (0..4).map(|j| r[j] * p.m[k].0[j][0]).sum::<f32>();
            }
        }
        Spec::from_array(out)
    }
}

/// A usable polarised sample (the unpolarised sample's checks).
fn usable((s, _): &(BsdfSample, MuellerValue)) -> bool {
    s.pdf > 0.0 && s.weight.is_finite() && s.wo.is_finite()
}

impl Carrier for StokesPath {
    type Setup = PolarizedSetup;
    type Value = MuellerValue;

    #[inline]
    fn camera(dir: Vec3) -> Self {
        StokesPath {
            rows: [[1.0, 0.0, 0.0, 0.0]; 4],
            basis: stokes_basis(-dir),
        }
    }

    #[inline]
    fn at_first_vertex(&mut self, setup: &PolarizedSetup, dir: Vec3, normal: Option<Vec3>) {
        if let Some((row, basis)) = setup.sensor_row(dir, normal) {
            self.rows = [row; 4];
            self.basis = basis;
        }
    }

    #[inline]
    fn direct_view(setup: &PolarizedSetup) -> f32 {
        setup.unpolarized_transmission()
    }

    #[inline]
    fn s0(&self) -> Spec {
        Spec::new(
            self.rows[0][0],
            self.rows[1][0],
            self.rows[2][0],
            self.rows[3][0],
        )
    }

    fn eval(&self, bsdf: &Bsdf, ctx: &ShadingCtx, v: &VertexFrame, wo: Vec3) -> Option<Spec> {
        // A model without a polarised form was refused by effect analysis.
        let value = bsdf.polarized().ok()?.eval_mueller(ctx, v.wi, wo);
        let f = self.column0(&value, v);
        (f.max_element() > 0.0).then_some(f)
    }

    fn sample(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let s = bsdf
            .polarized()
            .ok()?
            .sample_mueller(ctx, v.wi, u1, u2, Lobes::ALL)?;
        usable(&s).then_some(s)
    }

    fn sample_split(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> [Option<(BsdfSample, MuellerValue)>; 2] {
        let Ok(model) = bsdf.polarized() else {
            return [None, None];
        };
        [Lobes::REFLECTION, Lobes::TRANSMISSION].map(|lobes| {
            model
                .sample_mueller(ctx, v.wi, u1, u2, lobes)
                .filter(usable)
        })
    }

    #[inline]
    fn scatter(&mut self, value: &MuellerValue, v: &VertexFrame, wo_world: Vec3) {
        self.apply(value, v, wo_world);
    }

    #[inline]
    fn keep_hero_only(&mut self) {
        for r in self.rows.iter_mut().skip(1) {
            *r = [0.0; 4];
        }
    }

    #[inline]
    fn max_component(&self) -> f32 {
        self.s0().max_element()
    }

    #[inline]
    fn divide(&mut self, q: f32) {
        for r in self.rows.iter_mut() {
            for v in r.iter_mut() {
                *v /= q;
            }
        }
    }

    #[inline]
    fn attenuate(&mut self, factor: Spec) {
        for (r, f) in self.rows.iter_mut().zip(factor.to_array()) {
            for v in r.iter_mut() {
                *v *= f;
            }
        }
    }
}
