//! Ideal linear polariser sheet (Mitsuba 3 `polarizer`, `src/bsdfs/polarizer.cpp`): a
//! two-sided null interaction — light passes straight through, the direction is unchanged.
//!
//! Unpolarised, it is a neutral filter that passes half the light (times `transmittance`),
//! as Mitsuba's unpolarised variants do; its flags ask for polarised rendering. Polarised, it
//! is the Mueller matrix of a linear polariser whose axes are built as Mitsuba 3.9 builds
//! them: in the shading frame aligned with dp/du (s = dp/du made ⟂ n, t = n × s; see
//! [`BsdfModel::shading_frame`]), the absorbing axis is a = sin θ·s + cos θ·t (t at θ = 0),
//! projected perpendicular to the beam (Korger et al. 2013, "The polarization properties of
//! a tilted polarizer"); the polariser transmits along forward × a.

use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx,
};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::polarization::{linear_polarizer, stokes_basis};
use crate::render::texture::Texture;
use crate::scene::mitsuba::PluginParams;
use crate::scene::TextureDesc;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct PolarizerBsdf {
    /// Rotation of the polariser about the normal, radians.
    pub theta: f32,
    pub transmittance: Texture,
}

impl PolarizerBsdf {
    pub fn new(theta_deg: f32, transmittance: &TextureDesc) -> Self {
        PolarizerBsdf {
            theta: theta_deg.to_radians(),
            transmittance: Texture::new(transmittance),
        }
    }

    /// The Stokes basis (local, ⟂ `forward`) along which the polariser transmits, for light
    /// travelling along `forward` through the sheet.
    #[inline]
    pub fn transmission_axis(&self, forward: Vec3) -> Vec3 {
        let (s, c) = self.theta.sin_cos();
        let a = Vec3::new(s, c, 0.0);
        let a = a - a.dot(forward) * forward;
        let a = if a.length_squared() > 1e-12 {
            a.normalize()
        } else {
            // Beam along the absorbing axis (grazing): any perpendicular frame.
            stokes_basis(forward)
        };
        forward.cross(a)
    }
}

impl BsdfPlugin for PolarizerBsdf {
    const PLUGINS: &'static [&'static str] = &["polarizer"];

    /// `theta` (degrees, a constant; default 0), `transmittance` (default 1).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let theta_deg = p.constant("theta", 0.0)?;
        if !theta_deg.is_finite() {
            return Err(p.error_at(
                "theta",
                "polarizer theta must be a finite constant angle in degrees",
            ));
        }
        p.accept_bool("polarizing", |v| v)?;
        let transmittance = p.texture("transmittance", 1.0)?;
        Ok(PolarizerBsdf::new(theta_deg as f32, &transmittance))
    }
}

impl BsdfModel for PolarizerBsdf {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::NULL | BsdfFlags::TWO_SIDED | BsdfFlags::NEEDS_POLARIZATION)
            .with(BsdfFlags::VERTEX_COLOR, self.transmittance.reads_mesh_attribute())
    }

    fn describe(&self) -> String {
        format!("polarizer θ={}°", self.theta.to_degrees())
    }

    super::delta_lobes_only!();

    /// Pass-through (unpolarised weight: transmittance / 2).
    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        lobes.transmission().then(|| {
            let t = self.transmittance.eval_at(ctx);
            BsdfSample::delta(-wi, t * 0.5, 1.0, BsdfFlags::NULL)
        })
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Ok(self)
    }

    /// The frame aligned with dp/du (Mitsuba's `sh_frame`), where the polariser's axes are.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        super::normal_map::dpdu_frame(si)
    }
}

impl PolarizedBsdf for PolarizerBsdf {
    fn eval_mueller(&self, _ctx: &ShadingCtx, _wi: Vec3, _wo: Vec3) -> MuellerValue {
        MuellerValue::ZERO
    }

    /// The beam travels along wi through the sheet: the unrotated [`linear_polarizer`] in the
    /// basis of its transmission axis, times the transmittance.
    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let s = self.sample(ctx, wi, u1, u2, lobes)?;
        let axis = self.transmission_axis(wi);
        let t = self.transmittance.eval_at(ctx).to_array();
        let m = t.map(linear_polarizer);
        Some((s, MuellerValue::polarizing(m, axis, axis)))
    }
}
