//! Surface scattering models. Each model lives in its own module and owns its behaviour:
//! its parameters and the builder that reads them from a Mitsuba plugin (validating them,
//! once: a built model is always renderable), its [`BsdfFlags`], `eval` / `pdf` / `sample`
//! with a lobe mask ([`Lobes`], as pbrt-v4's `BxDFReflTransFlags`), and its polarised form
//! (Mueller matrices) or the reason it has none. The integrator sees models only through
//! [`Bsdf`]'s methods, and effect analysis only through their flags.
//!
//! **Adding a model** (`docs/adding-a-bsdf.md`): a module implementing [`BsdfModel`] and
//! [`BsdfPlugin`], one line in [`bsdf_models!`] below, and its tests (χ² of the sampled
//! directions against `pdf`, `eval`/`pdf`/`sample` agreement, white furnace, a Mitsuba
//! reference). [`Bsdf`]'s dispatch has no wildcard arm: a model that does not implement a
//! method — its polarised form included — does not compile.
//!
//! Conventions follow Mitsuba 3: directions are in the local shading frame (normal = +z),
//! `wi` points towards the previous path vertex (the camera side), `wo` is the sampled or
//! queried direction; `eval` returns f(wi, wo)·|cos θo| and `sample` returns the weight
//! eval / pdf (for delta lobes: the lobe's value divided by its selection probability).

mod flags;
pub mod fresnel;
pub mod lobe_factor;
pub mod microfacet;
mod mueller;
pub mod roughness;

pub use flags::{BsdfFlags, Lobes};
pub use mueller::{MuellerValue, PolarizedLobe};

use super::geometry::{Frame, SurfaceInteraction};
use super::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};

/// What a BSDF may know about the shading point besides the directions: the path's
/// wavelengths and the surface's texture coordinates (for textured parameters).
pub struct ShadingCtx<'a> {
    pub wl: &'a SampledWavelengths,
    pub uv: Vec2,
    /// Length of the ray segment that arrived at this point (scene units; 0 where unknown):
    /// a model with an absorbing interior attenuates light that crossed it (glTF
    /// `KHR_materials_volume`, Beer–Lambert).
    pub segment: f32,
    /// The vertex colour at the point ([`super::geometry::SurfaceInteraction::color`]).
    pub color: Vec3,
    /// The model's [`BsdfModel::perturbed_normal`] at the point (+z unless a bump map
    /// perturbs the normal per direction): computed once per hit from the surface
    /// derivatives, which `eval` / `sample` / `pdf` do not otherwise see.
    pub bump_normal: Vec3,
}

/// A sampled direction.
#[derive(Debug, Clone, Copy)]
pub struct BsdfSample {
    pub wo: Vec3,
    /// eval / pdf, per wavelength.
    pub weight: Spec,
    /// Solid-angle pdf (for delta lobes: the discrete selection probability).
    pub pdf: f32,
    /// The lobe sampled: one of the lobe flags of [`BsdfFlags`].
    pub lobe: BsdfFlags,
    /// Relative index crossed (1 for reflection), for Russian roulette's η².
    pub eta: f32,
    /// The direction is valid only for the hero wavelength (dispersion).
    pub terminate_secondary: bool,
}

impl BsdfSample {
    /// A sample of a non-delta `lobe`.
    #[inline]
    pub fn smooth(wo: Vec3, weight: Spec, pdf: f32, lobe: BsdfFlags) -> Self {
        BsdfSample {
            wo,
            weight,
            pdf,
            lobe,
            eta: 1.0,
            terminate_secondary: false,
        }
    }

    /// A sample drawn from one lobe of a mixture, weighted by the whole model's
    /// `eval() / pdf` at `wo` (one-sample MIS over the lobes); `None` where the mixture's
    /// pdf vanishes or overflows.
    #[inline]
    pub fn of_mixture(
        wo: Vec3,
        pdf: f32,
        eval: impl FnOnce() -> Spec,
        lobe: BsdfFlags,
    ) -> Option<Self> {
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(BsdfSample::smooth(wo, eval() / pdf, pdf, lobe))
    }

    /// A sample of the Dirac `lobe` with selection probability `pdf`.
    #[inline]
    pub fn delta(wo: Vec3, weight: Spec, pdf: f32, lobe: BsdfFlags) -> Self {
        BsdfSample {
            wo,
            weight,
            pdf,
            lobe,
            eta: 1.0,
            terminate_secondary: false,
        }
    }

    /// Sampled from a Dirac lobe (no MIS with light sampling).
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.lobe.intersects(BsdfFlags::DELTA)
    }
}

/// A scattering model's behaviour. Every method is required: the compiler names each model
/// that lacks one (there is no default that would, say, make a model silently depolarise).
pub trait BsdfModel {
    /// Lobes and properties; effect analysis and the integrator decide from these alone.
    fn flags(&self) -> BsdfFlags;

    /// The model and its parameters in a few words, for the effect log
    /// (e.g. "thinfilm n=1.37 d=400 nm on 1.64").
    fn describe(&self) -> String;

    /// f(wi, wo)·|cos θo| at the path's wavelengths (zero for delta lobes).
    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec;

    /// Solid-angle pdf with which [`sample`](Self::sample) (all lobes) draws `wo` (non-delta
    /// lobes only).
    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32;

    /// Samples `wo` from `wi` using `u1` (lobe choice) and `u2` (direction), from the lobes
    /// in `lobes` only: with one of a reflection/transmission pair masked out, the other is
    /// chosen with probability 1 and carries its full value (Fresnel splitting follows both
    /// that way). None if nothing is sampled.
    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample>;

    /// The reflected and the transmitted lobe, each as [`sample`](Self::sample) with only
    /// that lobe unmasked (Fresnel splitting). Models whose two lobes share an expensive
    /// evaluation (a film's coherent R and T) override this to evaluate it once.
    fn sample_split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
    ) -> [Option<BsdfSample>; 2] {
        [
            self.sample(ctx, wi, u1, u2, Lobes::REFLECTION),
            self.sample(ctx, wi, u1, u2, Lobes::TRANSMISSION),
        ]
    }

    /// The model's polarised form, or why it has none: a scene that asks for polarisation
    /// and uses this model is then refused with that reason.
    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str>;

    /// The frame the model scatters in, at `si` (the hook for tangents and perturbed
    /// normals): the interpolated-normal frame unless overridden; a model that needs a
    /// tangent (a polariser's axis, an anisotropic roughness, a normal or bump map) builds
    /// it from `si.dpdu` and `si.uv`.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        si.shading
    }

    /// A perturbed normal at `si` in the local coordinates of [`Self::shading_frame`], for a
    /// model that perturbs wi and wo itself (Mitsuba 3.8+'s `bumpmap`); it reaches the
    /// model's methods as [`ShadingCtx::bump_normal`]. +z (no perturbation) unless overridden.
    fn perturbed_normal(&self, si: &SurfaceInteraction) -> Vec3 {
        let _ = si;
        Vec3::Z
    }

    /// The microfacet distribution of a model whose only lobe is one glossy reflection about
    /// its shading normal, the same at every shading point (not textured); None otherwise.
    /// Environment light samples at such a surface are drawn around its mirror direction
    /// ([`super::env_sampling`]).
    fn glossy_lobe(&self) -> Option<microfacet::Microfacet> {
        None
    }
}

/// A model's polarised form: the Mueller-matrix versions of `eval` and `sample`, with the same
/// sampling decisions (directions, pdfs, lobe choices, random numbers) as the unpolarised
/// ones, following Mitsuba 3's polarised BSDFs ([`MuellerValue`]).
pub trait PolarizedBsdf {
    /// f(wi, wo)·|cos θo| as a Mueller operator.
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue;

    /// [`BsdfModel::sample`] with the Mueller weight (value / pdf) of the sampled direction.
    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)>;
}

/// `eval` and `pdf` of a model whose lobes are all Dirac deltas: zero everywhere (only
/// `sample` reaches such lobes), written out by the model so that it says so.
macro_rules! delta_lobes_only {
    () => {
        fn eval(
            &self,
            _ctx: &$crate::render::bsdf::ShadingCtx,
            _wi: ::glam::Vec3,
            _wo: ::glam::Vec3,
        ) -> $crate::render::texture::Spec {
            $crate::render::texture::Spec::ZERO
        }

        fn pdf(
            &self,
            _ctx: &$crate::render::bsdf::ShadingCtx,
            _wi: ::glam::Vec3,
            _wo: ::glam::Vec3,
        ) -> f32 {
            0.0
        }
    };
}
use delta_lobes_only;

/// How a model is made from a scene file's plugin element.
pub trait BsdfPlugin: Sized {
    /// Mitsuba plugin names (`type="…"`) this model is built from.
    const PLUGINS: &'static [&'static str];

    /// Whether this model builds plugin `plugin` given its parameters (`thinfilm` with a
    /// `layers` string is a multilayer stack, without one a single film).
    fn claims(plugin: &str, params: &PluginParams) -> bool {
        let _ = params;
        Self::PLUGINS.contains(&plugin)
    }

    /// Reads and validates the parameters (errors name the element and the parameter).
    fn build(params: &mut PluginParams) -> anyhow::Result<Self>;
}

/// Registers the models: one line each, `Variant(module::Type)`. Declares each model's module
/// and generates [`Bsdf`], its dispatch (no wildcard arms) and the plugin table of the scene
/// parser.
macro_rules! bsdf_models {
    ($($(#[$doc:meta])* $variant:ident($module:ident :: $model:ident),)*) => {
        $(pub mod $module;)*

        /// A BSDF of a scene: one of the registered models.
        #[derive(Debug, Clone)]
        pub enum Bsdf {
            $($(#[$doc])* $variant($module::$model),)*
        }

        $(impl From<$module::$model> for Bsdf {
            fn from(b: $module::$model) -> Self {
                Bsdf::$variant(b)
            }
        })*

        bsdf_dispatch!($($variant($module::$model),)*);
    };
}

/// [`Bsdf`]'s methods and the plugin table, one match arm per registered model.
macro_rules! bsdf_dispatch {
    ($($variant:ident($ty:ty),)*) => {
        impl Bsdf {
            /// The model as a trait object (for the rarely called methods).
            fn model(&self) -> &dyn BsdfModel {
                match self {
                    $(Bsdf::$variant(b) => b,)*
                }
            }

            /// Lobes and properties.
            #[inline]
            pub fn flags(&self) -> BsdfFlags {
                match self {
                    $(Bsdf::$variant(b) => b.flags(),)*
                }
            }

            /// f·|cos θo| at the four wavelengths.
            #[inline]
            pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
                match self {
                    $(Bsdf::$variant(b) => b.eval(ctx, wi, wo),)*
                }
            }

            /// Solid-angle pdf of sampling `wo` (non-delta lobes).
            #[inline]
            pub fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
                match self {
                    $(Bsdf::$variant(b) => b.pdf(ctx, wi, wo),)*
                }
            }

            /// Samples `wo` from the unmasked `lobes`; None unless the sample is usable
            /// (positive pdf, finite weight and direction).
            #[inline]
            pub fn sample(
                &self,
                ctx: &ShadingCtx,
                wi: Vec3,
                u1: f32,
                u2: Vec2,
                lobes: Lobes,
            ) -> Option<BsdfSample> {
                let s = match self {
                    $(Bsdf::$variant(b) => b.sample(ctx, wi, u1, u2, lobes),)*
                }?;
                usable(&s).then_some(s)
            }

            /// [reflection, transmission] at full weight (Fresnel splitting).
            #[inline]
            pub fn sample_split(
                &self,
                ctx: &ShadingCtx,
                wi: Vec3,
                u1: f32,
                u2: Vec2,
            ) -> [Option<BsdfSample>; 2] {
                let lobes = match self {
                    $(Bsdf::$variant(b) => b.sample_split(ctx, wi, u1, u2),)*
                };
                lobes.map(|s| s.filter(usable))
            }

            /// The polarised form, or why there is none.
            #[inline]
            pub fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
                match self {
                    $(Bsdf::$variant(b) => b.polarized(),)*
                }
            }

            /// The frame the model scatters in at `si`.
            #[inline]
            pub fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
                match self {
                    $(Bsdf::$variant(b) => b.shading_frame(si),)*
                }
            }

            /// The perturbed normal for [`ShadingCtx::bump_normal`] at `si`.
            #[inline]
            pub fn perturbed_normal(&self, si: &SurfaceInteraction) -> Vec3 {
                match self {
                    $(Bsdf::$variant(b) => b.perturbed_normal(si),)*
                }
            }

            /// The model in a few words, for logs.
            pub fn describe(&self) -> String {
                self.model().describe()
            }
        }

        /// Builds the model that claims Mitsuba plugin `plugin`; None if no model does.
        pub fn build_plugin(
            plugin: &str,
            params: &mut PluginParams,
        ) -> Option<anyhow::Result<Bsdf>> {
            $(if <$ty as BsdfPlugin>::claims(plugin, params) {
                return Some(<$ty as BsdfPlugin>::build(params).map(Bsdf::$variant));
            })*
            None
        }

        /// Every plugin name a model is registered for, for messages.
        pub fn plugin_names() -> Vec<&'static str> {
            let mut names: Vec<&'static str> = Vec::new();
            $(names.extend(<$ty as BsdfPlugin>::PLUGINS);)*
            names.dedup();
            names
        }
    };
}

bsdf_models! {
    Diffuse(diffuse::Diffuse),
    Conductor(conductor::Conductor),
    Dielectric(dielectric::Dielectric),
    Plastic(plastic::Plastic),
    ThinFilm(thinfilm::ThinFilmBsdf),
    Stack(stack::StackBsdf),
    Bubble(bubble::BubbleBsdf),
    CoatedDielectric(coated::CoatedDielectric),
    TwoSided(twosided::TwoSided),
    Polarizer(polarizer::PolarizerBsdf),
    Blend(blend::BlendBsdf),
    GltfPbr(gltf_pbr::GltfPbr),
    RoughDielectric(roughdielectric::RoughDielectric),
    ThinDielectric(thindielectric::ThinDielectric),
    NormalMap(normal_map::NormalMap),
    Mask(mask::Mask),
    BumpMap(bump_map::BumpMap),
    PolarizedPlastic(pplastic::PolarizedPlastic),
    Null(null::NullBsdf),
}

impl Bsdf {
    /// The default BSDF (Mitsuba: diffuse, reflectance 0.5).
    pub fn default_diffuse() -> Self {
        diffuse::Diffuse::constant(0.5).into()
    }

    /// [`BsdfModel::glossy_lobe`].
    pub fn glossy_lobe(&self) -> Option<microfacet::Microfacet> {
        self.model().glossy_lobe()
    }

    /// Whether the BSDF has a non-delta lobe (worth light sampling).
    #[inline]
    pub fn has_smooth_lobe(&self) -> bool {
        self.flags().intersects(BsdfFlags::SMOOTH)
    }

    /// Whether the BSDF is exactly a pair of Dirac lobes, mirror reflection and transmission,
    /// leaving in the same directions at all four wavelengths (no dispersion): then both can
    /// be followed at once ([`Bsdf::sample_split`]).
    #[inline]
    pub fn is_fresnel_pair(&self) -> bool {
        let f = self.flags();
        f.lobes() == BsdfFlags::DELTA_REFLECTION | BsdfFlags::DELTA_TRANSMISSION
            && !f.contains(BsdfFlags::DISPERSIVE)
    }

    /// Whether the BSDF only reflects, in Dirac lobes, without acting on polarisation: a
    /// smooth conductor, film or coating. Its sampled direction is then the same at every
    /// wavelength, and only its weight depends on them
    /// ([`super::integrator`]'s specular chains).
    #[inline]
    pub fn is_specular_reflector(&self) -> bool {
        let f = self.flags();
        f.lobes() == BsdfFlags::DELTA_REFLECTION
            && !f.intersects(BsdfFlags::DISPERSIVE | BsdfFlags::NEEDS_POLARIZATION)
    }
}

#[inline]
fn usable(s: &BsdfSample) -> bool {
    s.pdf > 0.0 && s.weight.is_finite() && s.wo.is_finite()
}

#[cfg(test)]
mod tests;
