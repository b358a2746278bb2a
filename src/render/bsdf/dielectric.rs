//! Smooth dielectric interface (Mitsuba `dielectric`): Fresnel-weighted choice between mirror
//! reflection and refraction. Two-sided. With a wavelength-dependent index the refracted
//! direction differs per wavelength, so the sample uses the hero wavelength's index and asks
//! the integrator to terminate the secondary wavelengths (Wilkie et al. 2014; pbrt-v4).
//! Polarised: Mitsuba's `specular_reflection` / `specular_transmission` Mueller matrices.
//! `specular_reflectance` / `specular_transmittance` scale the lobes' weights, not their
//! selection probabilities, as in Mitsuba ([`SpecularFactors`]).

use super::fresnel::{fresnel_dielectric, reflect_local};
use super::lobe_factor::SpecularFactors;
use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx,
};
use crate::optics::Ior;
use crate::render::polarization::{specular_reflection, specular_transmission, Mueller};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct Dielectric {
    pub int_ior: Ior,
    pub ext_ior: Ior,
    /// Either index depends on wavelength.
    pub dispersive: bool,
    pub factors: SpecularFactors,
}

impl Dielectric {
    pub fn new(int_ior: Ior, ext_ior: Ior) -> Self {
        Dielectric {
            dispersive: int_ior.is_dispersive() || ext_ior.is_dispersive(),
            int_ior,
            ext_ior,
            factors: SpecularFactors::default(),
        }
    }

    /// Relative index n_int / n_ext at `lambda_nm` (real part).
    #[inline]
    fn eta_at(&self, lambda_nm: f32) -> f32 {
        (self.int_ior.at(lambda_nm as f64).re / self.ext_ior.at(lambda_nm as f64).re) as f32
    }

    /// The sample and η_ti of the hero wavelength's interface.
    #[inline]
    fn sample_interface(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        lobes: Lobes,
    ) -> Option<(BsdfSample, f32)> {
        let eta = self.eta_at(ctx.wl.lambda[0]);
        let (r, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, eta);
        let reflection = BsdfFlags::DELTA_REFLECTION;
        let transmission = |weight, pdf| {
            // Radiance is compressed by η² crossing into the denser medium (Veach 1997 §5.2).
            let mut s = BsdfSample::delta(
                Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t),
                weight,
                pdf,
                BsdfFlags::DELTA_TRANSMISSION,
            );
            s.eta = eta_it;
            s
        };
        let mut s = match (lobes.reflection(), lobes.transmission()) {
            (true, true) if u1 <= r => {
                BsdfSample::delta(reflect_local(wi), Spec::ONE, r, reflection)
            }
            (true, true) => transmission(Spec::splat(eta_ti * eta_ti), 1.0 - r),
            // One lobe at its full value (Fresnel splitting); none where it does not exist.
            (true, false) if r > 0.0 => {
                BsdfSample::delta(reflect_local(wi), Spec::splat(r), 1.0, reflection)
            }
            (false, true) if r < 1.0 => transmission(Spec::splat(eta_ti * eta_ti) * (1.0 - r), 1.0),
            _ => return None,
        };
        // pbrt-v4 terminates on either branch: the choice itself used the hero index.
        s.terminate_secondary = self.dispersive;
        let s = self.factors.scale_sample(ctx, s);
        s.wo.is_finite().then_some((s, eta_ti))
    }
}

impl BsdfPlugin for Dielectric {
    const PLUGINS: &'static [&'static str] = &["dielectric"];

    /// `int_ior` (default BK7's 1.5046), `ext_ior` (air, 1.000277): numbers, Mitsuba IOR
    /// names, or dispersive indices (`material:NAME`, `cauchy:…`, `sellmeier:…`, spectra).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let int_ior = p.dielectric_ior("int_ior", 1.5046)?;
        let ext_ior = p.dielectric_ior("ext_ior", 1.000277)?;
        let mut d = Dielectric::new(int_ior, ext_ior);
        d.factors = SpecularFactors::read(p)?;
        Ok(d)
    }
}

impl BsdfModel for Dielectric {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::DELTA_REFLECTION | BsdfFlags::DELTA_TRANSMISSION | BsdfFlags::TWO_SIDED)
            .with(BsdfFlags::DISPERSIVE, self.dispersive)
            .with(BsdfFlags::VERTEX_COLOR, self.factors.reads_mesh_attribute())
    }

    fn describe(&self) -> String {
        format!(
            "dielectric {}/{}{}",
            self.int_ior,
            self.ext_ior,
            self.factors.describe()
        )
    }

    super::delta_lobes_only!();

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        self.sample_interface(ctx, wi, u1, lobes).map(|(s, _)| s)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Ok(self)
    }
}

impl PolarizedBsdf for Dielectric {
    fn eval_mueller(&self, _ctx: &ShadingCtx, _wi: Vec3, _wo: Vec3) -> MuellerValue {
        MuellerValue::ZERO
    }

    /// Mitsuba: the interface's Mueller matrix for light arriving along −wo (cos θ of wo,
    /// signed) over the lobe's selection probability; transmission also carries the η_ti²
    /// radiance compression of the unpolarised weight.
    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let (s, eta_ti) = self.sample_interface(ctx, wi, u1, lobes)?;
        let wo = s.wo;
        let reflected = wo.z * wi.z > 0.0;
        let scale = if reflected { 1.0 } else { eta_ti * eta_ti } / s.pdf;
        let m: [Mueller; 4] = ctx.wl.lambda.map(|lambda| {
            let eta = self.eta_at(lambda);
            let m = if reflected {
                specular_reflection(wo.z, eta)
            } else {
                specular_transmission(wo.z, eta)
            };
            m.scale(scale)
        });
        let factor = if reflected {
            &self.factors.reflection
        } else {
            &self.factors.transmission
        };
        let m = factor.scale_mueller(ctx, m);
        Some((s, MuellerValue::specular(m, Vec3::Z, wi, wo)))
    }
}
