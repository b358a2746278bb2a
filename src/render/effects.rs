//! Effect analysis: before rendering, the flags of the BSDFs that shapes use
//! ([`BsdfFlags`]) decide which machinery is switched on — only what the scene calls for
//! (`docs/architecture.md`, "Effect analysis"). Each decision is a typed value
//! ([`Decision`]) that says why; the render log prints them.
//!
//! - interference (the Airy film code) for models with [`BsdfFlags::INTERFERENCE`];
//!   free-standing films (interference with transmission: coherent R and T) and multilayer
//!   stacks ([`BsdfFlags::MULTILAYER`], the transfer-matrix method) are reported separately,
//!   since each has its own cost;
//! - dispersion handling (terminating secondary wavelengths at refractions) for
//!   [`BsdfFlags::DISPERSIVE`] models;
//! - microfacet (GGX visible-normal) sampling for glossy lobes;
//! - Fresnel splitting (both lobes of smooth glass and bubbles followed at a path's first
//!   such vertices, [`super::integrator`]) where there are such Fresnel pairs and no
//!   dispersion;
//! - polarisation (Stokes vectors and Mueller matrices) if the scene asks for a polariser: a
//!   model with [`BsdfFlags::NEEDS_POLARIZATION`] on a shape, or a sensor polariser. A model
//!   without a polarised form is then refused with its own reason
//!   ([`super::bsdf::BsdfModel::polarized`]).

use super::bsdf::{Bsdf, BsdfFlags};
use crate::scene::{Polarizer, Scene};
use std::fmt;

/// Machinery the renderer switches on only where a scene needs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    Interference,
    FreeStandingFilm,
    MultilayerStack,
    Dispersion,
    FresnelSplitting,
    MicrofacetSampling,
    Polarization,
    /// How camera rays find their first hit (screen bins or the BVH).
    CameraRays,
    /// Wavelength sampling for camera rays that see an emitter directly (the environment, an
    /// untextured area light); off, their colour is the emitter's expectation over
    /// wavelengths, integrated once per texel or light.
    SpectralDirectView,
    /// Environment light samples at reflecting surfaces drawn from the hemisphere their
    /// normal faces (radiance × the mean clamped cosine, per normal bin) instead of by radiance
    /// over the whole sphere ([`super::env_sampling`]).
    HemisphereEnvSampling,
    /// Eight wavelengths instead of four on paths that only reflect off Dirac reflectors,
    /// first off a smooth film or coating, whose directions every wavelength shares
    /// (`integrator::specular_chain`).
    SpecularChainWavelengths,
    /// After every pixel's samples, the work of a quarter more where the neighbouring pixels'
    /// samples spread most ([`super::adaptive`]).
    AdaptiveSampleCounts,
}

impl Effect {
    /// The effect's name in the log.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Interference => "interference",
            Effect::FreeStandingFilm => "free-standing film",
            Effect::MultilayerStack => "multilayer stack",
            Effect::Dispersion => "dispersion",
            Effect::FresnelSplitting => "Fresnel splitting",
            Effect::MicrofacetSampling => "microfacet sampling",
            Effect::Polarization => "polarisation",
            Effect::CameraRays => "Camera rays",
            Effect::SpectralDirectView => "wavelength sampling of emitters seen directly",
            Effect::HemisphereEnvSampling => "hemisphere-aware environment sampling",
            Effect::SpecularChainWavelengths => "wavelength supersampling of specular chains",
            Effect::AdaptiveSampleCounts => "adaptive sample counts",
        }
    }
}

/// One decision: an effect on or off, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub effect: Effect,
    pub on: bool,
    pub reason: String,
}

impl fmt::Display for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.effect == Effect::CameraRays {
            return write!(f, "{}: {}", self.effect.name(), self.reason);
        }
        let state = if self.on { "ON" } else { "off" };
        write!(f, "{}: {state} — {}", self.effect.name(), self.reason)
    }
}

/// What the renderer switched on, and why.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Effects {
    /// Thin-film interference (Airy reflectance) is evaluated.
    pub interference: bool,
    /// Some thin film has a spatially varying thickness map.
    pub thickness_texture: bool,
    /// Wavelength-dependent refraction: secondary wavelengths are terminated there.
    pub dispersion: bool,
    /// GGX microfacet sampling is used.
    pub rough: bool,
    /// Paths carry Stokes vectors (polarised transport).
    pub polarization: bool,
    /// Free-standing films (bubbles): coherent R and T, transmission straight through.
    pub bubble: bool,
    /// Multilayer coatings: transfer-matrix reflectance per wavelength.
    pub stack: bool,
    /// Smooth reflect/transmit interfaces whose two lobes can both be followed
    /// ([`Bsdf::is_fresnel_pair`]); off with dispersion, whose branches would have to
    /// terminate wavelengths independently.
    pub fresnel_split: bool,
    /// The decisions, in the order of the log.
    pub decisions: Vec<Decision>,
}

impl Effects {
    /// The decision about `effect`, if one was made.
    pub fn decision_mut(&mut self, effect: Effect) -> Option<&mut Decision> {
        self.decisions.iter_mut().find(|d| d.effect == effect)
    }

    /// One line per decision.
    pub fn lines(&self) -> Vec<String> {
        self.decisions.iter().map(ToString::to_string).collect()
    }

    /// Records that `effect` is on or off and why; returns `on`.
    pub(super) fn decide(&mut self, effect: Effect, on: bool, reason: String) -> bool {
        self.decisions.push(Decision { effect, on, reason });
        on
    }

    /// [`Self::decide`] for an effect that is on unless `off` gives the reason it is not;
    /// `on()` says what it does.
    pub(super) fn decide_unless(
        &mut self,
        effect: Effect,
        off: Option<&str>,
        on: impl FnOnce() -> String,
    ) -> bool {
        let reason = off.map_or_else(on, str::to_string);
        self.decide(effect, off.is_none(), reason)
    }

    /// [`Self::decide`] for an effect that is on when `causes` (the BSDFs that bring it) is
    /// not empty: `off` says why it is off, `on(causes)` what it does.
    fn decide_by(
        &mut self,
        effect: Effect,
        causes: &[String],
        off: &str,
        on: impl FnOnce(&[String]) -> String,
    ) -> bool {
        let reason = if causes.is_empty() {
            off.to_string()
        } else {
            on(causes)
        };
        self.decide(effect, !causes.is_empty(), reason)
    }
}

impl fmt::Display for Effects {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for d in &self.decisions {
            writeln!(f, "  {d}")?;
        }
        Ok(())
    }
}

/// Descriptions of the used BSDFs whose flags satisfy `pick`, each once.
fn described(bsdfs: &[&Bsdf], pick: impl Fn(&Bsdf) -> bool) -> Vec<String> {
    let mut out: Vec<String> = bsdfs
        .iter()
        .filter(|b| pick(b))
        .map(|b| b.describe())
        .collect();
    out.sort();
    out.dedup();
    out
}

/// Why the scene asks for polarisation (empty if it does not).
fn polarization_causes(scene: &Scene, used: &[&Bsdf]) -> Vec<String> {
    let mut why = Vec::new();
    if let Some(p) = scene.polarizer {
        why.push(match p {
            Polarizer::S => "an S polariser on the sensor".to_string(),
            Polarizer::P => "a P polariser on the sensor".to_string(),
            Polarizer::AngleDeg(d) => format!("a polariser at {d}° on the sensor"),
        });
    }
    let n = used
        .iter()
        .filter(|b| b.flags().contains(BsdfFlags::NEEDS_POLARIZATION))
        .count();
    if n > 0 {
        why.push(format!("{n} polarizer BSDF(s) in use"));
    }
    why
}

/// Inspects the BSDFs that shapes actually use.
pub fn analyze(scene: &Scene) -> anyhow::Result<Effects> {
    let mut used = vec![false; scene.bsdfs.len()];
    for (i, s) in scene.shapes.iter().enumerate() {
        if s.bsdf >= scene.bsdfs.len() {
            anyhow::bail!(
                "shape {i} ({}) refers to BSDF {} but the scene has {}",
                s.name.as_deref().unwrap_or("unnamed"),
                s.bsdf,
                scene.bsdfs.len()
            );
        }
        used[s.bsdf] = true;
    }
    let all: Vec<&Bsdf> = (scene.bsdfs.iter().zip(&used))
        .filter(|(_, &u)| u)
        .map(|(b, _)| b)
        .collect();
    let has = |flag: BsdfFlags| move |b: &Bsdf| b.flags().intersects(flag);
    let mut e = Effects::default();

    let films = described(&all, has(BsdfFlags::INTERFERENCE | BsdfFlags::MULTILAYER));
    e.thickness_texture = all.iter().any(|b| has(BsdfFlags::THICKNESS_MAP)(b));
    e.interference = e.decide(
        Effect::Interference,
        all.iter()
            .any(|b| has(BsdfFlags::INTERFERENCE | BsdfFlags::MULTILAYER)(b)),
        if films.is_empty() {
            "no thin-film material in use".into()
        } else {
            let texture = if e.thickness_texture {
                ", thickness from a texture"
            } else {
                ""
            };
            format!("{} thin-film material(s){texture}", films.len())
        },
    );
    let bubbles = described(&all, |b| {
        b.flags().contains(BsdfFlags::INTERFERENCE) && b.flags().intersects(BsdfFlags::TRANSMISSION)
    });
    e.bubble = e.decide_by(
        Effect::FreeStandingFilm,
        &bubbles,
        "no thinfilm_bubble in use",
        |b| {
            let b = b.join("; ");
            format!("coherent Airy reflection and transmission (R + T = 1 when lossless) for {b}")
        },
    );
    let stacks = described(&all, has(BsdfFlags::MULTILAYER));
    e.stack = e.decide_by(
        Effect::MultilayerStack,
        &stacks,
        "no thinfilm with layers in use",
        |s| {
            format!(
                "transfer-matrix reflectance per wavelength for {}",
                s.join("; ")
            )
        },
    );
    let dispersive = described(&all, has(BsdfFlags::DISPERSIVE));
    e.dispersion = e.decide_by(
        Effect::Dispersion,
        &dispersive,
        "no refracting interface with a wavelength-dependent index (all 4 wavelengths share each path)",
        |d| {
            let d = d.join(", ");
            format!("wavelength-dependent refraction at {d}; secondary wavelengths terminate there")
        },
    );
    let pairs = described(&all, |b| {
        let f = b.flags().lobes();
        f == BsdfFlags::DELTA_REFLECTION | BsdfFlags::DELTA_TRANSMISSION
    });
    e.fresnel_split = e.decide(
        Effect::FresnelSplitting,
        !pairs.is_empty() && !e.dispersion,
        if pairs.is_empty() {
            "no smooth glass or bubble in use".into()
        } else if e.dispersion {
            "the scene has dispersion (split branches would share the path's wavelengths)".into()
        } else {
            format!(
                "reflection and transmission both followed at the first smooth interfaces of each path ({})",
                pairs.join(", ")
            )
        },
    );
    let rough = described(&all, has(BsdfFlags::GLOSSY));
    e.rough = e.decide_by(
        Effect::MicrofacetSampling,
        &rough,
        "all BSDFs smooth or diffuse",
        |r| r.join(", "),
    );
    let why = polarization_causes(scene, &all);
    if !why.is_empty() {
        let refused: Vec<String> = all
            .iter()
            .filter_map(|b| {
                b.polarized()
                    .err()
                    .map(|r| format!("{}: {r}", b.describe()))
            })
            .collect();
        if !refused.is_empty() {
            anyhow::bail!(
                "the scene asks for polarisation ({}) but uses materials without Mueller matrices — {}: remove the polariser or these materials",
                why.join(" and "),
                refused.join("; ")
            );
        }
    }
    e.polarization = e.decide(
        Effect::Polarization,
        !why.is_empty(),
        if why.is_empty() {
            "no polariser in the scene (unpolarised transport)".into()
        } else {
            format!(
                "because of {}; paths carry Stokes vectors, BSDFs act as Mueller matrices",
                why.join(" and ")
            )
        },
    );
    Ok(e)
}
