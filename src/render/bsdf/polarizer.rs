//! Ideal linear polariser sheet (Mitsuba 3 `polarizer`, `src/bsdfs/polarizer.cpp`): a
//! two-sided null interaction — light passes straight through, the direction is unchanged.
//!
//! In an unpolarised render it is a neutral filter that passes half the light (times
//! `transmittance`), which is what Mitsuba's unpolarised variants do. The polarised
//! integrator ([`crate::render::integrator_polarized`]) instead applies the Mueller matrix
//! of a linear polariser whose transmission axis is built as Mitsuba 3.9 does: the absorbing
//! axis is a = sin θ·u + cos θ·v in the surface's tangent plane (u = dp/du made ⟂ n,
//! v = n × u; so the v direction at θ = 0), projected perpendicular to the beam (Korger et
//! al. 2013, "The polarization properties of a tilted polarizer"); the transmission axis is
//! forward × a.

use super::{BsdfSample, ShadingCtx};
use crate::render::polarization::{self, Mueller};
use crate::render::texture::Texture;
use glam::Vec3;

#[derive(Debug, Clone)]
pub struct PolarizerBsdf {
    /// Rotation of the polariser about the beam, radians.
    pub theta: f32,
    pub transmittance: Texture,
}

impl PolarizerBsdf {
    /// Pass-through sample (unpolarised weight: transmittance / 2).
    pub fn sample(&self, ctx: &ShadingCtx, wi: Vec3) -> Option<BsdfSample> {
        let mut s = BsdfSample::delta(-wi, self.transmittance.eval(ctx.uv, ctx.wl) * 0.5);
        s.pdf = 1.0;
        Some(s)
    }

    /// Mueller matrix (same for every wavelength, before the transmittance) and the world
    /// basis it is expressed in, for light travelling along `forward` (world, unit) through a
    /// sheet with world tangents `u_axis` (normalised dp/du ⟂ n) and `v_axis` = n × u.
    ///
    /// Mitsuba 3.9 (`polarizer.cpp`): the absorbing axis is a = sin θ·u + cos θ·v (v at θ = 0),
    /// made perpendicular to the beam (Korger et al. 2013); the polariser transmits along
    /// forward × a, where the unrotated [`polarization::linear_polarizer`] applies.
    pub fn mueller(&self, forward: Vec3, u_axis: Vec3, v_axis: Vec3) -> (Mueller, Vec3) {
        let (s, c) = self.theta.sin_cos();
        let a = s * u_axis + c * v_axis;
        let a = a - a.dot(forward) * forward;
        let a = if a.length_squared() > 1e-12 {
            a.normalize()
        } else {
            // Beam along the absorbing axis (grazing): any perpendicular frame.
            polarization::stokes_basis(forward)
        };
        (polarization::linear_polarizer(1.0), forward.cross(a))
    }
}
