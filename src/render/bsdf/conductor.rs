//! Smooth and rough (GGX or Beckmann, isotropic or anisotropic) conductors (Mitsuba
//! `conductor`, `roughconductor`), one-sided. Anisotropic roughness is oriented as Mitsuba
//! orients it: α_u along the shading tangent dp/du ([`super::normal_map::dpdu_frame`]).
//! The complex index comes from [`crate::optics::Ior`] (constant, a named metal, or `eta`/`k`
//! spectra, or RGB upsampled as Mitsuba does: [`PluginParams::conductor_spectrum`]). The
//! roughness may be textured ([`Roughness`]) and the lobe scaled by `specular_reflectance`
//! ([`LobeFactor`]). Polarised: Mitsuba's `specular_reflection` Mueller matrix of the complex
//! Fresnel amplitudes at the (micro)facet, times `specular_reflectance`.

use super::lobe_factor::LobeFactor;
use super::microfacet::{
    opaque_reflector_methods, Distribution, Microfacet, OpaqueReflector,
};
use super::roughness::Roughness;
use super::{fresnel::fresnel_conductor4, BsdfFlags, BsdfModel, BsdfPlugin, ShadingCtx};
use crate::optics::dispersion::Nk4;
use crate::optics::Ior;
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::polarization::{specular_reflection_conductor, Mueller};
use crate::render::texture::Spec;
use crate::scene::mitsuba::{PluginParams, RealSpectrum};
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct Conductor {
    pub eta: Ior,
    /// `eta` at four wavelengths for a named material (a metal's table found in a grid).
    eta4: Option<Nk4>,
    /// Constant None = smooth (a delta lobe).
    pub roughness: Roughness,
    /// Mitsuba's `specular_reflectance`.
    pub specular: LobeFactor,
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
            eta4: nk4_of(&eta),
            eta,
            roughness: Roughness::Constant(
                (alpha_u > 0.0 || alpha_v > 0.0).then(|| Microfacet::of(kind, alpha_u, alpha_v)),
            ),
            specular: LobeFactor::default(),
        })
    }
}

/// The four-wavelength lookup of a named material's index.
fn nk4_of(eta: &Ior) -> Option<Nk4> {
    match eta {
        Ior::Material(m) => Some(Nk4::new(m)),
        Ior::Constant(_) => None,
    }
}

impl Conductor {
    /// (n, k) at the sample's four wavelengths, in f32 (inlined: the lanes go to the Fresnel
    /// term in registers, not through four stores and one wide load).
    #[inline(always)]
    fn nk(&self, ctx: &ShadingCtx) -> ([f32; 4], [f32; 4]) {
        match &self.eta4 {
            Some(lookup) => lookup.at(ctx.wl.lambda),
            None => {
                let n = ctx.wl.lambda.map(|l| self.eta.at(l as f64));
                (n.map(|n| n.re as f32), n.map(|n| n.im as f32))
            }
        }
    }
}

impl OpaqueReflector for Conductor {
    fn ggx(&self, ctx: &ShadingCtx) -> Option<Microfacet> {
        self.roughness.at(ctx)
    }

    #[inline]
    fn reflectance(&self, ctx: &ShadingCtx, cos_i: f32) -> Spec {
        let (n, k) = self.nk(ctx);
        let r = fresnel_conductor4(cos_i, n, k);
        Spec::from_array(r) * self.specular.eval(ctx)
    }

    #[inline]
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_i: f32) -> [Mueller; 4] {
        let (n, k) = self.nk(ctx);
        let m = std::array::from_fn(|i| {
            specular_reflection_conductor(cos_i, Complex32::new(n[i], k[i]))
        });
        self.specular.scale_mueller(ctx, m)
    }
}

impl BsdfPlugin for Conductor {
    const PLUGINS: &'static [&'static str] = &["conductor", "roughconductor"];

    /// Mitsuba's parameters: `material` (a metal of the dispersion library, or `none`: a
    /// perfect mirror) or `eta`/`k` (numbers or spectra; Mitsuba's defaults 0 and 1), and for
    /// `roughconductor` the microfacet roughness.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let roughness = if p.plugin() == "roughconductor" {
            Roughness::read(p, false)?
        } else {
            Roughness::Constant(None)
        };
        let material = p.string("material")?;
        let plugin = p.plugin().to_string();
        let eta = p.conductor_spectrum("eta", &format!("'eta' of bsdf \"{plugin}\""))?;
        let k = p.conductor_spectrum("k", &format!("'k' of bsdf \"{plugin}\""))?;
        let specular = LobeFactor::read(p, "specular_reflectance")?;
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
        Ok(Conductor {
            eta4: nk4_of(&ior),
            eta: ior,
            roughness,
            specular,
        })
    }
}

impl BsdfModel for Conductor {
    fn flags(&self) -> BsdfFlags {
        let lobe = if self.roughness.is_rough() {
            BsdfFlags::GLOSSY_REFLECTION
        } else {
            BsdfFlags::DELTA_REFLECTION
        };
        lobe.with(
            BsdfFlags::VERTEX_COLOR,
            self.specular.reads_mesh_attribute() || self.roughness.reads_mesh_attribute(),
        )
    }

    fn glossy_lobe(&self) -> Option<Microfacet> {
        match self.roughness {
            Roughness::Constant(m) => m,
            Roughness::Textured { .. } => None,
        }
    }

    fn describe(&self) -> String {
        let spec = self.specular.describe("specular_reflectance");
        if self.roughness.is_rough() {
            let r = self.roughness.describe();
            format!("roughconductor {} {r}{spec}", self.eta)
        } else {
            format!("conductor {}{spec}", self.eta)
        }
    }

    /// Mitsuba's frame (s along dp/du) when the roughness is anisotropic; an isotropic lobe
    /// does not depend on the tangent.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        if self.roughness.is_anisotropic() {
            super::normal_map::dpdu_frame(si)
        } else {
            si.shading
        }
    }

    opaque_reflector_methods!();
}

