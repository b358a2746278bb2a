//! Ideal linear polariser sheet (Mitsuba 3 `polarizer`, `src/bsdfs/polarizer.cpp`): a
//! two-sided null interaction — light passes straight through, the direction is unchanged.
//!
//! In an unpolarised render it is a neutral filter that passes half the light (times
//! `transmittance`), which is what Mitsuba's unpolarised variants do. The polarised
//! integrator ([`crate::render::integrator_polarized`]) instead applies the Mueller matrix
//! of a linear polariser whose transmission axis is built as Mitsuba does: the absorbing
//! axis is the surface's v direction (t = n × normalize(dp/du ⟂ n)) projected perpendicular
//! to the beam (Korger et al. 2013, "The polarization properties of a tilted polarizer"),
//! the transmission axis is forward × that, and the element is rotated by `theta_deg`.

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
    /// basis it is expressed in, for light travelling along `forward` (world, unit) through
    /// a sheet whose absorbing axis at θ = 0 is `v_axis` (world, unit).
    pub fn mueller(&self, forward: Vec3, v_axis: Vec3) -> (Mueller, Vec3) {
        let m = polarization::rotated_element(self.theta, &polarization::linear_polarizer(1.0));
        let a = v_axis - v_axis.dot(forward) * forward;
        let a = if a.length_squared() > 1e-12 {
            a.normalize()
        } else {
            // Beam along the absorbing axis (grazing): any perpendicular frame.
            polarization::stokes_basis(forward)
        };
        (m, forward.cross(a))
    }
}
