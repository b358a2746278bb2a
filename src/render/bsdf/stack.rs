//! Multilayer coating on an opaque substrate (scene type `thinfilm` with a `layers` string,
//! e.g. an anti-reflection coating or a dielectric mirror). The Fresnel term is the
//! unpolarised reflectance R = (R_s + R_p)/2 of the layer stack from the transfer-matrix
//! method of [`crate::optics::Stack`] (Born & Wolf §1.6; validated against `tmm.coh_tmm` in
//! `tests/optics_tmm.rs`), evaluated in f64 at each of the path's four wavelengths with each
//! layer's index at that wavelength (named dispersive materials; each distinct material
//! evaluated once per wavelength, [`crate::optics::Coating`]). Ambient n = 1, like
//! `thinfilm`. Smooth: a mirror lobe weighted by R; rough (α > 0): a GGX lobe with R at the
//! microfacet angle, exactly as [`super::thinfilm::ThinFilmBsdf`]. What the stack transmits
//! into the substrate is absorbed. One-sided. Polarised: the Mueller matrix of the stack's
//! complex amplitudes r_s, r_p.

use super::microfacet::{opaque_reflector_methods, reflection_lobe, Ggx, OpaqueReflector};
use super::{BsdfFlags, BsdfModel, BsdfPlugin, ShadingCtx};
use crate::optics::{Coating, Ior, Stack};
use crate::render::counters::{count, Counter};
use crate::render::polarization::{film_reflection, Mueller};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct StackBsdf {
    /// (index, thickness nm), top (ambient side) first.
    pub layers: Vec<(Ior, f64)>,
    pub substrate_ior: Ior,
    /// None = smooth.
    pub ggx: Option<Ggx>,
    /// The layers under air, evaluated per wavelength.
    coating: Coating,
}

/// "MgF2:100, TiO2:50" (the first six layers, then a count).
pub(super) fn describe_layers(layers: &[(Ior, f64)]) -> String {
    let names: Vec<String> = layers.iter().map(|(n, d)| format!("{n}:{d}")).collect();
    if names.len() > 6 {
        format!("{} … ({} layers)", names[..6].join(", "), names.len())
    } else {
        names.join(", ")
    }
}

impl StackBsdf {
    /// A stack of `layers` (top first) on `substrate_ior`, GGX roughness `alpha`. Indices and
    /// thicknesses are checked once, at a mid-visible wavelength: the hot path does not
    /// validate.
    pub fn new(layers: Vec<(Ior, f64)>, substrate_ior: Ior, alpha: f32) -> anyhow::Result<Self> {
        super::conductor::check_alpha(alpha, "thinfilm alpha")?;
        let b = StackBsdf {
            coating: Coating::new(Ior::real(1.0), &layers, substrate_ior.clone()),
            layers,
            substrate_ior,
            ggx: (alpha > 0.0).then(|| Ggx::new(alpha, alpha)),
        };
        b.stack_at(550.0)
            .validate()
            .map_err(|e| anyhow::anyhow!("thinfilm layers: {e}"))?;
        Ok(b)
    }

    /// The stack at one wavelength (all layers coherent).
    pub fn stack_at(&self, lambda_nm: f64) -> Stack {
        self.coating.stack_at(lambda_nm)
    }
}

impl OpaqueReflector for StackBsdf {
    fn ggx(&self, _ctx: &ShadingCtx) -> Option<Ggx> {
        self.ggx
    }

    /// Unpolarised TMM reflectance at the four path wavelengths for `cos θ` in the ambient.
    #[inline]
    fn reflectance(&self, ctx: &ShadingCtx, cos_theta: f32) -> Spec {
        count(Counter::FilmEvals, 1);
        let cos = (cos_theta as f64).clamp(0.0, 1.0);
        let r = self.coating.reflectance(ctx.wl.lambda.map(f64::from), cos);
        Spec::from_array(r.map(|v| {
            let v = v as f32;
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        }))
    }

    /// The stack's reflection Mueller matrices at the four path wavelengths.
    fn reflectance_mueller(&self, ctx: &ShadingCtx, cos_theta: f32) -> [Mueller; 4] {
        count(Counter::FilmEvals, 1);
        let cos = (cos_theta as f64).clamp(0.0, 1.0);
        let c32 = |z: crate::optics::Complex64| Complex32::new(z.re as f32, z.im as f32);
        let amplitudes = self.coating.amplitudes(ctx.wl.lambda.map(f64::from), cos);
        amplitudes.map(|a| {
            let m = film_reflection(c32(a.r_s), c32(a.r_p));
            if m.is_finite() {
                m
            } else {
                Mueller::ZERO
            }

        })
    }
}

impl BsdfPlugin for StackBsdf {
    const PLUGINS: &'static [&'static str] = &["thinfilm"];

    /// `thinfilm` with a `layers` string.
    fn claims(plugin: &str, params: &PluginParams) -> bool {
        plugin == "thinfilm" && params.has("layers")
    }

    /// `layers` ("MgF2:100, TiO2:50", top first; `(A:d, B:d)xN` repeats), `substrate_ior`
    /// (a number, `n+ki` or a material name; default 1.64), `alpha` (default 0).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        for conflicting in ["film_ior", "thickness"] {
            if p.has(conflicting) {
                return Err(p.error_at(
                    conflicting,
                    format!("'{conflicting}' cannot be combined with 'layers' (give each layer as material:thickness_nm)"),
                ));
            }
        }
        let layers = p
            .layers("layers")?
            .expect("claimed only with a `layers` parameter");
        let substrate_ior = p.index("substrate_ior", Ior::real(1.64))?;
        if p.has("substrate_k") {
            return Err(p.error_at(
                "substrate_k",
                "with 'layers', give an absorbing substrate as substrate_ior=\"n+ki\" or a material name",
            ));
        }
        let alpha = p.float("alpha", 0.0)? as f32;
        StackBsdf::new(layers, substrate_ior, alpha).map_err(|e| p.error_at("alpha", e))
    }
}

impl BsdfModel for StackBsdf {
    fn flags(&self) -> BsdfFlags {
        reflection_lobe(self.ggx) | BsdfFlags::MULTILAYER
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
            "layered thinfilm [{}] on {}{rough}",
            describe_layers(&self.layers),
            self.substrate_ior
        )
    }

    opaque_reflector_methods!();
}

