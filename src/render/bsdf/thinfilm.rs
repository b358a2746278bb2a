//! Opaque thin film on a substrate (scene type `thinfilm`, the estimator's material;
//! `docs/physics-and-formats.md`, "The thin-film BSDF"): the Fresnel term is the Airy single-film
//! reflectance R(λ, θ) of [`crate::optics::ThinFilm`] (seed eq. 4), averaged over s and p.
//! Smooth: a mirror lobe weighted by R. Rough (α > 0): a GGX microfacet lobe with the Airy
//! term evaluated at the microfacet angle (the "rough thin film" of Belcour & Barla 2017
//! without their spectral antialiasing). Light transmitted into the substrate is absorbed.
//! One-sided. Polarised: the Mueller matrix of the film's complex amplitudes r_s, r_p
//! (which reduces to the bare substrate's at zero thickness).

use super::microfacet::{opaque_reflector_methods, reflection_lobe, Ggx, OpaqueReflector};
use super::{BsdfFlags, BsdfModel, BsdfPlugin, ShadingCtx};
use crate::optics::film_f32::ThinFilmX4;
use crate::optics::Ior;
use crate::render::counters::{count, Counter};
use crate::render::polarization::{film_reflection, Mueller};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::{PluginParams, RealSpectrum};
use crate::scene::TextureDesc;
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct ThinFilmBsdf {
    pub film_ior: Ior,
    pub thickness_nm: Texture,
    pub substrate_ior: Ior,
    /// None = smooth.
    pub ggx: Option<Ggx>,
}

#[inline]
fn c32(z: crate::optics::Complex64) -> Complex32 {
    Complex32::new(z.re as f32, z.im as f32)
}

/// A film thickness for the optics: negative, NaN or infinite (a texture hole) counts as 0,
/// the bare substrate, instead of poisoning the image.
#[inline]
pub(super) fn usable_thickness(d: f32) -> f32 {
    if d.is_finite() && d > 0.0 {
        d
    } else {
        0.0
    }
}

impl ThinFilmBsdf {
    /// A film of index `film_ior` and thickness `thickness_nm` (a value or a texture, nm) on
    /// `substrate_ior`, GGX roughness `alpha` (0 = smooth).
    pub fn new(
        film_ior: Ior,
        thickness_nm: &TextureDesc,
        substrate_ior: Ior,
        alpha: f32,
    ) -> anyhow::Result<Self> {
        super::conductor::check_alpha(alpha, "thinfilm alpha")?;
        Ok(ThinFilmBsdf {
            film_ior,
            thickness_nm: Texture::new(thickness_nm),
            substrate_ior,
            ggx: (alpha > 0.0).then(|| Ggx::new(alpha, alpha)),
        })
    }

    /// The film at the path's four wavelengths, at the shading point.
    #[inline]
    fn film(&self, ctx: &ShadingCtx) -> ThinFilmX4 {
        count(Counter::FilmEvals, 1);
        ThinFilmX4 {
            ambient_ior: 1.0,
            film_ior: ctx.wl.lambda.map(|l| c32(self.film_ior.at(l as f64))),
            thickness_nm: usable_thickness(self.thickness_nm.eval_scalar(ctx.uv)),
            substrate_ior: ctx.wl.lambda.map(|l| c32(self.substrate_ior.at(l as f64))),
        }
    }

    /// Unpolarised (R, T) at the four wavelengths for `cos θ` at the film, from the optics
    /// module's single-precision 4-wavelength Airy path ([`ThinFilmX4`], within 1e-5 of the
    /// f64 [`crate::optics::ThinFilm`]); T is what enters the substrate (absorbed there).
    #[inline]
    pub fn reflect_transmit(&self, ctx: &ShadingCtx, cos_theta: f32) -> (Spec, Spec) {
        let resp = self
            .film(ctx)
            .response(ctx.wl.lambda, cos_theta.clamp(0.0, 1.0));
        let clean = |v: f32, hi: f32| if v.is_finite() { v.clamp(0.0, hi) } else { 0.0 };
        let r = resp.r().map(|v| clean(v, 1.0));
        let t = resp.t().map(|v| clean(v, f32::MAX));
        (Spec::from_array(r), Spec::from_array(t))
    }
}

impl OpaqueReflector for ThinFilmBsdf {
    fn ggx(&self, _ctx: &ShadingCtx) -> Option<Ggx> {
        self.ggx
    }

    #[inline]
    fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32) -> Spec {
        self.reflect_transmit(ctx, cos_theta).0
    }

    /// The film's reflection Mueller matrices at the four wavelengths (Mitsuba's convention:
    /// the optics' e^{−iωt} amplitudes conjugated, see [`film_reflection`]).
    #[inline]
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_theta: f32) -> [Mueller; 4] {
        let a = self
            .film(ctx)
            .reflection_amplitudes(ctx.wl.lambda, cos_theta.clamp(0.0, 1.0));
        a.map(|[r_s, r_p]| {
            let m = film_reflection(r_s, r_p);
            if m.is_finite() {
                m
            } else {
                Mueller::ZERO
            }

        })
    }
}

impl BsdfPlugin for ThinFilmBsdf {
    const PLUGINS: &'static [&'static str] = &["thinfilm"];

    /// `thinfilm` without `layers` (with them it is a [`super::stack::StackBsdf`]).
    fn claims(plugin: &str, params: &PluginParams) -> bool {
        plugin == "thinfilm" && !params.has("layers")
    }

    /// `film_ior` (default 1.37), `thickness` (nm, a number or a texture; default 400),
    /// `substrate_ior` (default 1.64) with an optional `substrate_k`, `alpha` (default 0).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let film_ior = p.index("film_ior", Ior::real(1.37))?;
        let thickness_nm = p.film_thickness(400.0)?;
        let substrate_k = p.real_spectrum("substrate_k")?;
        if substrate_k
            .as_ref()
            .is_some_and(|k| k.min().is_nan() || k.min() < 0.0)
        {
            return Err(p.error_at("substrate_k", "substrate_k must be ≥ 0"));
        }
        let substrate_ior = match (p.has("substrate_ior"), substrate_k) {
            (false, None) => Ior::real(1.64),
            (false, Some(k)) => p.complex_index(&RealSpectrum::Const(1.64), &k, "substrate"),
            (true, None) => p.index("substrate_ior", Ior::real(1.64))?,
            (true, Some(k)) => {
                if p.is_string("substrate_ior") {
                    return Err(p.error_at(
                        "substrate_k",
                        "substrate_k cannot be combined with a named substrate material (its k is tabulated)",
                    ));
                }
                let n = p
                    .real_spectrum("substrate_ior")?
                    .unwrap_or(RealSpectrum::Const(1.64));
                if n.min().is_nan() || n.min() <= 0.0 {
                    return Err(p.error_at("substrate_ior", "substrate_ior must be > 0"));
                }
                p.complex_index(&n, &k, "substrate")
            }
        };
        let alpha = p.float("alpha", 0.0)? as f32;
        ThinFilmBsdf::new(film_ior, &thickness_nm, substrate_ior, alpha)
            .map_err(|e| p.error_at("alpha", e))
    }
}

impl BsdfModel for ThinFilmBsdf {
    fn flags(&self) -> BsdfFlags {
        reflection_lobe(self.ggx)
            | BsdfFlags::INTERFERENCE
            | BsdfFlags::NONE.with(BsdfFlags::THICKNESS_MAP, self.thickness_nm.is_varying())
    }

    fn glossy_lobe(&self) -> Option<Ggx> {
        self.ggx
    }

    fn describe(&self) -> String {
        let rough = self
            .ggx
            .map(|g| format!(" α={}", g.alpha_u))
            .unwrap_or_default();
        format!(
            "thinfilm n={} on {}{rough}",
            self.film_ior, self.substrate_ior
        )
    }

    opaque_reflector_methods!();
}

