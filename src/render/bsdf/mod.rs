//! Surface scattering models, one file per model, dispatched through the [`Bsdf`] enum (no
//! trait objects on the hot path).
//!
//! Conventions follow Mitsuba 3: directions are in the local shading frame (normal = +z),
//! `wi` points towards the previous path vertex (the camera side), `wo` is the sampled or
//! queried direction; `eval` returns f(wi, wo)·|cos θo| and `sample` returns the weight
//! eval / pdf (for delta lobes: the lobe's value divided by its selection probability).

pub mod bubble;
pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod microfacet;
pub mod plastic;
pub mod polarizer;
pub mod stack;
pub mod thinfilm;

use super::texture::{Spec, Texture};
use crate::scene::BsdfDesc;
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};
use microfacet::Ggx;

pub use bubble::BubbleBsdf;
pub use conductor::Conductor;
pub use dielectric::Dielectric;
pub use diffuse::Diffuse;
pub use plastic::Plastic;
pub use polarizer::PolarizerBsdf;
pub use stack::{CoatedDielectric, StackBsdf};
pub use thinfilm::ThinFilmBsdf;

/// What a BSDF needs to know about the shading point besides directions.
pub struct ShadingCtx<'a> {
    pub wl: &'a SampledWavelengths,
    pub uv: Vec2,
}

/// Per-thread work counters (summed into the render statistics).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Airy thin-film evaluations (each covers 4 wavelengths).
    pub film_evals: u64,
    /// Closest-hit rays traced.
    pub rays: u64,
    /// Shadow (occlusion) rays traced.
    pub shadow_rays: u64,
    /// Samples whose estimate was NaN/inf and was discarded.
    pub invalid_samples: u64,
    /// Paths whose secondary wavelengths were terminated at a dispersive interface (0 in a
    /// scene without dispersion: the proof that the 4-wavelength fast path is kept).
    pub secondary_terminations: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.film_evals += o.film_evals;
        self.rays += o.rays;
        self.shadow_rays += o.shadow_rays;
        self.invalid_samples += o.invalid_samples;
        self.secondary_terminations += o.secondary_terminations;
    }
}

/// A sampled direction.
#[derive(Debug, Clone, Copy)]
pub struct BsdfSample {
    pub wo: Vec3,
    /// eval / pdf, per wavelength.
    pub weight: Spec,
    /// Solid-angle pdf (for delta lobes: the discrete selection probability).
    pub pdf: f32,
    /// Sampled from a Dirac lobe (no MIS with light sampling).
    pub delta: bool,
    /// Relative index crossed (1 for reflection), for Russian roulette's η².
    pub eta: f32,
    /// The direction is valid only for the hero wavelength (dispersion).
    pub terminate_secondary: bool,
}

impl BsdfSample {
    #[inline]
    pub fn smooth(wo: Vec3, weight: Spec, pdf: f32) -> Self {
        BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta: 1.0,
            terminate_secondary: false,
        }
    }
    #[inline]
    pub fn delta(wo: Vec3, weight: Spec) -> Self {
        BsdfSample {
            wo,
            weight,
            pdf: 1.0,
            delta: true,
            eta: 1.0,
            terminate_secondary: false,
        }
    }
}

/// A prepared BSDF.
#[derive(Debug, Clone)]
pub enum Bsdf {
    Diffuse(Diffuse),
    Conductor(Conductor),
    Dielectric(Dielectric),
    Plastic(Plastic),
    ThinFilm(ThinFilmBsdf),
    /// Multilayer coating (`thinfilm` with `layers`).
    Stack(StackBsdf),
    /// Free-standing film (`thinfilm_bubble`), two-sided.
    Bubble(BubbleBsdf),
    /// Dielectric interface under a multilayer coating (`coateddielectric`).
    CoatedDielectric(CoatedDielectric),
    /// Mitsuba `twosided`: the back face behaves like the front.
    TwoSided(Box<Bsdf>),
    /// Mitsuba `polarizer`: null pass-through (see [`polarizer`]).
    Polarizer(PolarizerBsdf),
}

impl Bsdf {
    /// Prepares a scene BSDF. Errors name what is unsupported.
    pub fn from_desc(desc: &BsdfDesc) -> anyhow::Result<Self> {
        Ok(match desc {
            BsdfDesc::Diffuse { reflectance } => Bsdf::Diffuse(Diffuse {
                reflectance: Texture::new(reflectance),
            }),
            BsdfDesc::Conductor {
                eta,
                alpha_u,
                alpha_v,
            } => {
                check_alpha(*alpha_u, "conductor alpha_u")?;
                check_alpha(*alpha_v, "conductor alpha_v")?;
                Bsdf::Conductor(Conductor {
                    eta: eta.clone(),
                    ggx: (*alpha_u > 0.0 || *alpha_v > 0.0).then(|| Ggx::new(*alpha_u, *alpha_v)),
                })
            }
            BsdfDesc::Dielectric {
                int_ior,
                ext_ior,
                alpha,
            } => {
                if *alpha > 0.0 {
                    anyhow::bail!("bsdf 'roughdielectric' (dielectric with alpha = {alpha}) is not supported by the renderer");
                }
                Bsdf::Dielectric(Dielectric {
                    int_ior: int_ior.clone(),
                    ext_ior: ext_ior.clone(),
                    dispersive: int_ior.is_dispersive() || ext_ior.is_dispersive(),
                })
            }
            BsdfDesc::Plastic {
                diffuse_reflectance,
                int_ior,
                ext_ior,
                alpha,
                nonlinear,
            } => {
                check_alpha(*alpha, "plastic alpha")?;
                let eta = int_ior / ext_ior;
                if !(eta.is_finite() && eta > 0.0) {
                    anyhow::bail!("plastic: int_ior/ext_ior must be positive and finite, got {int_ior}/{ext_ior}");
                }
                Bsdf::Plastic(Plastic::new(
                    Texture::new(diffuse_reflectance),
                    eta,
                    *nonlinear,
                    *alpha,
                ))
            }
            BsdfDesc::TwoSided(inner) => Bsdf::TwoSided(Box::new(Bsdf::from_desc(inner)?)),
            BsdfDesc::Polarizer {
                theta_deg,
                transmittance,
            } => Bsdf::Polarizer(PolarizerBsdf {
                theta: theta_deg.to_radians(),
                transmittance: Texture::new(transmittance),
            }),
            BsdfDesc::ThinFilm {
                film_ior,
                thickness_nm,
                substrate_ior,
                alpha,
            } => {
                check_alpha(*alpha, "thinfilm alpha")?;
                Bsdf::ThinFilm(ThinFilmBsdf {
                    film_ior: film_ior.clone(),
                    thickness_nm: Texture::new(thickness_nm),
                    substrate_ior: substrate_ior.clone(),
                    ggx: (*alpha > 0.0).then(|| Ggx::new(*alpha, *alpha)),
                })
            }
            BsdfDesc::ThinFilmStack {
                layers,
                substrate_ior,
                alpha,
            } => {
                check_alpha(*alpha, "thinfilm alpha")?;
                let b = StackBsdf {
                    layers: layers.clone(),
                    substrate_ior: substrate_ior.clone(),
                    ggx: (*alpha > 0.0).then(|| Ggx::new(*alpha, *alpha)),
                };
                // Indices and thicknesses once, at a mid-visible wavelength: the hot path
                // does not validate.
                b.stack_at(550.0)
                    .validate()
                    .map_err(|e| anyhow::anyhow!("thinfilm layers: {e}"))?;
                Bsdf::Stack(b)
            }
            BsdfDesc::CoatedDielectric {
                layers,
                int_ior,
                ext_ior,
            } => {
                let b = CoatedDielectric {
                    layers: layers.clone(),
                    int_ior: int_ior.clone(),
                    ext_ior: ext_ior.clone(),
                    dispersive: int_ior.is_dispersive() || ext_ior.is_dispersive(),
                };
                for inside in [false, true] {
                    b.stack_at(550.0, inside)
                        .validate()
                        .map_err(|e| anyhow::anyhow!("dielectric coating: {e}"))?;
                }
                for (what, n) in [("int_ior", int_ior), ("ext_ior", ext_ior)] {
                    if n.at(550.0).im != 0.0 {
                        anyhow::bail!("coated dielectric: {what} must be real, got {n}");
                    }
                }
                Bsdf::CoatedDielectric(b)
            }
            BsdfDesc::Bubble {
                film_ior,
                thickness_nm,
                ext_ior,
            } => {
                let ext = ext_ior.at(550.0);
                if ext_ior.is_dispersive() || ext.im != 0.0 || !(ext.re > 0.0 && ext.re.is_finite())
                {
                    anyhow::bail!(
                        "thinfilm_bubble: ext_ior must be a constant real index > 0, got {ext_ior}"
                    );
                }
                let n = film_ior.at(550.0);
                if !(n.re > 0.0 && n.re.is_finite() && n.im >= 0.0) {
                    anyhow::bail!(
                        "thinfilm_bubble: film_ior must have n > 0 and k ≥ 0, got {film_ior}"
                    );
                }
                Bsdf::Bubble(BubbleBsdf {
                    film_ior: film_ior.clone(),
                    thickness_nm: Texture::new(thickness_nm),
                    ext_ior: ext.re as f32,
                })
            }
        })
    }

    /// f·|cos θo| at the four wavelengths.
    pub fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3, c: &mut Counters) -> Spec {
        match self {
            Bsdf::Diffuse(b) => b.eval(ctx, wi, wo),
            Bsdf::Conductor(b) => b.eval(ctx, wi, wo),
            Bsdf::Dielectric(_) | Bsdf::Polarizer(_) => Spec::ZERO,
            Bsdf::Plastic(b) => b.eval(ctx, wi, wo),
            Bsdf::ThinFilm(b) => b.eval(ctx, wi, wo, c),
            Bsdf::Stack(b) => b.eval(ctx, wi, wo, c),
            Bsdf::Bubble(_) | Bsdf::CoatedDielectric(_) => Spec::ZERO,
            Bsdf::TwoSided(b) => {
                let (wi, wo) = two_sided_flip(wi, wo);
                b.eval(ctx, wi, wo, c)
            }
        }
    }

    /// Solid-angle pdf of sampling `wo` (non-delta components only).
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        match self {
            Bsdf::Diffuse(b) => b.pdf(wi, wo),
            Bsdf::Conductor(b) => b.pdf(wi, wo),
            Bsdf::Dielectric(_) | Bsdf::Polarizer(_) => 0.0,
            Bsdf::Plastic(b) => b.pdf(wi, wo),
            Bsdf::ThinFilm(b) => b.pdf(wi, wo),
            Bsdf::Stack(b) => b.pdf(wi, wo),
            Bsdf::Bubble(_) | Bsdf::CoatedDielectric(_) => 0.0,
            Bsdf::TwoSided(b) => {
                let (wi, wo) = two_sided_flip(wi, wo);
                b.pdf(wi, wo)
            }
        }
    }

    /// Samples `wo` from `wi` using `u1` (lobe choice) and `u2` (direction).
    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        c: &mut Counters,
    ) -> Option<BsdfSample> {
        let s = match self {
            Bsdf::Diffuse(b) => b.sample(ctx, wi, u2),
            Bsdf::Conductor(b) => b.sample(ctx, wi, u2),
            Bsdf::Dielectric(b) => {
                let s = b.sample(ctx, wi, u1);
                if matches!(s, Some(s) if s.terminate_secondary) && !ctx.wl.secondary_terminated() {
                    c.secondary_terminations += 1;
                }
                s
            }
            Bsdf::Plastic(b) => b.sample(ctx, wi, u1, u2),
            Bsdf::ThinFilm(b) => b.sample(ctx, wi, u2, c),
            Bsdf::Polarizer(b) => b.sample(ctx, wi),
            Bsdf::Stack(b) => b.sample(ctx, wi, u2, c),
            Bsdf::Bubble(b) => b.sample(ctx, wi, u1, c),
            Bsdf::CoatedDielectric(b) => {
                let s = b.sample(ctx, wi, u1, c);
                if matches!(s, Some(s) if s.terminate_secondary) && !ctx.wl.secondary_terminated() {
                    c.secondary_terminations += 1;
                }
                s
            }
            Bsdf::TwoSided(b) => {
                if wi.z < 0.0 {
                    let mut s = b.sample(ctx, Vec3::new(wi.x, wi.y, -wi.z), u1, u2, c)?;
                    s.wo.z = -s.wo.z;
                    Some(s)
                } else {
                    b.sample(ctx, wi, u1, u2, c)
                }
            }
        }?;
        (s.pdf > 0.0 && s.weight.is_finite() && s.wo.is_finite()).then_some(s)
    }

    /// Whether the BSDF is a pair of Dirac lobes, mirror reflection and transmission, chosen
    /// by `u1` (Fresnel-weighted) and leaving in the same directions at all four wavelengths:
    /// then both can be followed at once ([`Bsdf::split`]). Dispersive interfaces are not
    /// (their refraction direction is the hero wavelength's).
    pub fn is_fresnel_pair(&self) -> bool {
        match self {
            Bsdf::Dielectric(b) => !b.dispersive,
            Bsdf::CoatedDielectric(b) => !b.dispersive,
            Bsdf::Bubble(_) => true,
            Bsdf::TwoSided(b) => b.is_fresnel_pair(),
            _ => false,
        }
    }

    /// Both lobes of a [`Bsdf::is_fresnel_pair`] BSDF — [reflection, transmission] — each with
    /// its full value as weight (R, resp. T·η_ti²) and selection probability 1: "splitting"
    /// instead of choosing one lobe at random. Sampling forced to each lobe (u1 = 0 picks the
    /// reflection, u1 = 1 the transmission) and the selection probability multiplied back
    /// in, so the lobes are exactly those of [`Bsdf::sample`]. A lobe that does not exist
    /// (R = 0, or total internal reflection for T) is None.
    pub fn split(&self, ctx: &ShadingCtx, wi: Vec3, c: &mut Counters) -> [Option<BsdfSample>; 2] {
        let lobes = match self {
            // The film models evaluate R and T once for both lobes.
            Bsdf::Bubble(b) => b.split(ctx, wi, c),
            Bsdf::CoatedDielectric(b) => b.split(ctx, wi, c),
            Bsdf::TwoSided(b) if wi.z < 0.0 => {
                let flip = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
                b.split(ctx, flip(wi), c).map(|s| {
                    s.map(|mut s| {
                        s.wo = flip(s.wo);
                        s
                    })
                })
            }
            Bsdf::TwoSided(b) => b.split(ctx, wi, c),
            _ => {
                let mut lobe = |u1: f32, reflection: bool| {
                    let mut s = self.sample(ctx, wi, u1, Vec2::ZERO, c)?;
                    if (s.wo.z * wi.z > 0.0) != reflection {
                        return None;
                    }
                    s.weight *= s.pdf;
                    s.pdf = 1.0;
                    Some(s)
                };
                [lobe(0.0, true), lobe(1.0, false)]
            }
        };
        lobes.map(|s| s.filter(|s| s.weight.is_finite() && s.wo.is_finite()))
    }

    /// Whether the BSDF has a non-delta component (worth light sampling).
    pub fn has_smooth_component(&self) -> bool {
        match self {
            Bsdf::Diffuse(_) | Bsdf::Plastic(_) => true,
            Bsdf::Conductor(b) => b.ggx.is_some(),
            Bsdf::ThinFilm(b) => b.ggx.is_some(),
            Bsdf::Stack(b) => b.ggx.is_some(),
            Bsdf::Dielectric(_)
            | Bsdf::Bubble(_)
            | Bsdf::CoatedDielectric(_)
            | Bsdf::Polarizer(_) => false,
            Bsdf::TwoSided(b) => b.has_smooth_component(),
        }
    }

    /// Whether the BSDF scatters only on the front side of its shading normal.
    pub fn is_one_sided(&self) -> bool {
        !matches!(
            self,
            Bsdf::Dielectric(_)
                | Bsdf::TwoSided(_)
                | Bsdf::Bubble(_)
                | Bsdf::CoatedDielectric(_)
                | Bsdf::Polarizer(_)
        )
    }
}

fn check_alpha(alpha: f32, what: &str) -> anyhow::Result<()> {
    if alpha.is_finite() && alpha >= 0.0 {
        Ok(())
    } else {
        anyhow::bail!("{what} must be finite and ≥ 0, got {alpha}")
    }
}

#[inline]
fn two_sided_flip(mut wi: Vec3, mut wo: Vec3) -> (Vec3, Vec3) {
    if wi.z < 0.0 {
        wi.z = -wi.z;
        wo.z = -wo.z;
    }
    (wi, wo)
}

#[cfg(test)]
mod tests;
