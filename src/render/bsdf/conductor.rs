//! Smooth and rough (GGX or Beckmann, isotropic or anisotropic) conductors (Mitsuba
//! `conductor`, `roughconductor`), one-sided. Anisotropic roughness is oriented as Mitsuba
//! orients it: α_u along the shading tangent dp/du ([`super::normal_map::dpdu_frame`]).
//! The complex index comes from [`crate::optics::Ior`] (constant, a named metal, or `eta`/`k`
//! spectra). Polarised: Mitsuba's `specular_reflection` Mueller matrix of the complex
//! Fresnel amplitudes at the (micro)facet.

use super::microfacet::{
    opaque_reflector_methods, reflection_lobe, Distribution, Microfacet, OpaqueReflector,
};
use super::{fresnel::fresnel_conductor, BsdfFlags, BsdfModel, BsdfPlugin, ShadingCtx};
use crate::optics::Ior;
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::polarization::{specular_reflection_conductor, Mueller};
use crate::render::texture::Spec;
use crate::scene::mitsuba::{PluginParams, RealSpectrum};
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct Conductor {
    pub eta: Ior,
    /// None = smooth (a delta lobe).
    pub ggx: Option<Microfacet>,
}

/// Roughness must be finite and ≥ 0 (0: smooth).
pub(super) fn check_alpha(alpha: f32, what: &str) -> anyhow::Result<()> {
    if alpha.is_finite() && alpha >= 0.0 {
        Ok(())
    } else {
        anyhow::bail!("{what} must be finite and ≥ 0, got {alpha}")
    }
}

impl Conductor {
    /// A conductor of complex index `eta`; GGX roughness (α_u, α_v), (0, 0) = smooth.
    pub fn new(eta: Ior, alpha_u: f32, alpha_v: f32) -> anyhow::Result<Self> {
        Self::with_distribution(eta, Distribution::Ggx, alpha_u, alpha_v)
    }

    /// [`Self::new`] with the microfacet distribution `kind`.
    pub fn with_distribution(
        eta: Ior,
        kind: Distribution,
        alpha_u: f32,
        alpha_v: f32,
    ) -> anyhow::Result<Self> {
        check_alpha(alpha_u, "conductor alpha_u")?;
        check_alpha(alpha_v, "conductor alpha_v")?;
        Ok(Conductor {
            eta,
            ggx: (alpha_u > 0.0 || alpha_v > 0.0).then(|| Microfacet::of(kind, alpha_u, alpha_v)),
        })
    }
}

impl OpaqueReflector for Conductor {
    fn ggx(&self) -> Option<Microfacet> {
        self.ggx
    }

    #[inline]
    fn reflectance(&self, ctx: &ShadingCtx, cos_i: f32) -> Spec {
        Spec::from_array(ctx.wl.lambda.map(|l| {
            let n = self.eta.at(l as f64);
            fresnel_conductor(cos_i, n.re as f32, n.im as f32)
        }))
    }

    #[inline]
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_i: f32) -> [Mueller; 4] {
        ctx.wl.lambda.map(|l| {
            let n = self.eta.at(l as f64);
            specular_reflection_conductor(cos_i, Complex32::new(n.re as f32, n.im as f32))
        })
    }
}

impl BsdfPlugin for Conductor {
    const PLUGINS: &'static [&'static str] = &["conductor", "roughconductor"];

    /// Mitsuba's parameters: `material` (a metal of the dispersion library, or `none`: a
    /// perfect mirror) or `eta`/`k` (numbers or spectra; Mitsuba's defaults 0 and 1), and for
    /// `roughconductor` the microfacet roughness.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let (kind, au, av) = if p.plugin() == "roughconductor" {
            p.microfacet()?
        } else {
            (Distribution::Ggx, 0.0, 0.0)
        };
        let material = p.string("material")?;
        let plugin = p.plugin().to_string();
        let eta = p.real_spectrum_as("eta", &format!("'eta' of bsdf \"{plugin}\""))?;
        let k = p.real_spectrum_as("k", &format!("'k' of bsdf \"{plugin}\""))?;
        p.unit_factors(&["specular_reflectance"])?;
        let ior = match (material, eta, k) {
            (Some(_), Some(_), _) | (Some(_), None, Some(_)) => {
                return Err(p.error("give either 'material' or 'eta'/'k', not both"))
            }
            (Some(m), None, None) => p.conductor_material(&m)?,
            (None, None, None) => p.conductor_material("none")?,
            (None, eta, k) => {
                let n = eta.unwrap_or(RealSpectrum::Const(0.0));
                let k = k.unwrap_or(RealSpectrum::Const(1.0));
                if !(n.min() >= 0.0 && k.min() >= 0.0) {
                    return Err(p.error("eta and k must be ≥ 0"));
                }
                p.complex_index(&n, &k, "eta/k")
            }
        };
        Conductor::with_distribution(ior, kind, au, av).map_err(|e| p.error(e))
    }
}

impl BsdfModel for Conductor {
    fn flags(&self) -> BsdfFlags {
        reflection_lobe(self.ggx)
    }

    fn describe(&self) -> String {
        match self.ggx {
            None => format!("conductor {}", self.eta),
            Some(g) => format!("roughconductor {} {}", self.eta, g.describe()),
        }
    }

    /// Mitsuba's frame (s along dp/du) when the roughness is anisotropic; an isotropic lobe
    /// does not depend on the tangent.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        match self.ggx {
            Some(g) if g.is_anisotropic() => super::normal_map::dpdu_frame(si),
            _ => si.shading,
        }
    }

    opaque_reflector_methods!();
}

