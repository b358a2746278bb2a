//! Effect analysis (simulate only the effects a scene calls for): before
//! rendering, the scene's materials are inspected and only the machinery they need is switched
//! on. Each decision records why, for the render log.
//!
//! - interference (the Airy film code) only for `thinfilm` materials that some shape uses;
//!   free-standing films (`thinfilm_bubble`: coherent reflection *and* transmission) and
//!   multilayer stacks (`thinfilm` with `layers`: the transfer-matrix method) are reported
//!   separately, since each has its own cost;
//! - dispersion handling (terminating secondary wavelengths at refractions) only for dielectric
//!   interfaces whose index depends on wavelength;
//! - microfacet (GGX visible-normal) sampling only for BSDFs with α > 0;
//! - Fresnel splitting (both lobes of smooth glass and bubbles followed at a path's first
//!   such vertices, [`super::integrator`]) only where there are such interfaces and no
//!   dispersion;
//! - polarisation (Stokes vectors and Mueller matrices, [`super::integrator_polarized`]) only
//!   if the scene asks for a polariser: a `polarizer` BSDF on a shape or a sensor polariser.

use crate::scene::{BsdfDesc, Scene, TextureDesc};

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
    /// Paths carry Stokes vectors (polarised integrator).
    pub polarization: bool,
    /// Free-standing films (bubbles): coherent R and T, transmission straight through.
    pub bubble: bool,
    /// Multilayer coatings: transfer-matrix reflectance per wavelength.
    pub stack: bool,
    /// Smooth reflect/transmit interfaces whose two lobes can both be followed
    /// ([`super::bsdf::Bsdf::is_fresnel_pair`]); off with dispersion, whose branches would
    /// have to terminate wavelengths independently.
    pub fresnel_split: bool,
    /// One line per decision, for the log.
    pub reasons: Vec<String>,
}

impl std::fmt::Display for Effects {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for r in &self.reasons {
            writeln!(f, "  {r}")?;
        }
        Ok(())
    }
}

fn visit<'a>(desc: &'a BsdfDesc, out: &mut Vec<&'a BsdfDesc>) {
    out.push(desc);
    if let BsdfDesc::TwoSided(inner) = desc {
        visit(inner, out);
    }
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
    let mut all = Vec::new();
    for (i, d) in scene.bsdfs.iter().enumerate() {
        if used[i] {
            visit(d, &mut all);
        }
    }
    let mut e = Effects::default();
    let mut films = 0;
    let mut rough = Vec::new();
    let mut dispersive = Vec::new();
    let mut polarizer_bsdfs = 0;
    let mut bubbles = Vec::new();
    let mut stacks = Vec::new();
    let mut fresnel_pairs = Vec::new();
    for d in &all {
        match d {
            BsdfDesc::Dielectric {
                int_ior, ext_ior, ..
            } if !(int_ior.is_dispersive() || ext_ior.is_dispersive()) => {
                fresnel_pairs.push(format!("dielectric {int_ior}/{ext_ior}"))
            }
            BsdfDesc::CoatedDielectric {
                int_ior, ext_ior, ..
            } if !(int_ior.is_dispersive() || ext_ior.is_dispersive()) => {
                fresnel_pairs.push(format!("coated dielectric {int_ior}/{ext_ior}"))
            }
            BsdfDesc::Bubble { film_ior, .. } => {
                fresnel_pairs.push(format!("thinfilm_bubble n={film_ior}"))
            }
            _ => {}
        }
        match d {
            BsdfDesc::ThinFilm {
                thickness_nm,
                alpha,
                film_ior,
                substrate_ior,
            } => {
                films += 1;
                e.interference = true;
                if matches!(
                    thickness_nm,
                    TextureDesc::Bitmap(_) | TextureDesc::Checkerboard { .. }
                ) {
                    e.thickness_texture = true;
                }
                if *alpha > 0.0 {
                    rough.push(format!("thinfilm α={alpha}"));
                }
                let _ = (film_ior, substrate_ior);
            }
            BsdfDesc::Bubble {
                film_ior,
                thickness_nm,
                ext_ior,
            } => {
                films += 1;
                e.interference = true;
                e.bubble = true;
                let textured = matches!(
                    thickness_nm,
                    TextureDesc::Bitmap(_) | TextureDesc::Checkerboard { .. }
                );
                e.thickness_texture |= textured;
                bubbles.push(format!(
                    "film n={film_ior} in n={ext_ior}{}",
                    if textured { ", textured thickness" } else { "" }
                ));
            }
            BsdfDesc::ThinFilmStack {
                layers,
                substrate_ior,
                alpha,
            } => {
                films += 1;
                e.interference = true;
                e.stack = true;
                if *alpha > 0.0 {
                    rough.push(format!("layered thinfilm α={alpha}"));
                }
                let names: Vec<String> = layers.iter().map(|(n, d)| format!("{n}:{d}")).collect();
                let shown = if names.len() > 6 {
                    format!("{} … ({} layers)", names[..6].join(", "), names.len())
                } else {
                    names.join(", ")
                };
                stacks.push(format!("[{shown}] on {substrate_ior}"));
            }
            BsdfDesc::CoatedDielectric {
                layers,
                int_ior,
                ext_ior,
            } => {
                films += 1;
                e.interference = true;
                e.stack = true;
                let names: Vec<String> = layers.iter().map(|(n, d)| format!("{n}:{d}")).collect();
                stacks.push(format!(
                    "coating [{}] on dielectric {int_ior}/{ext_ior}",
                    names.join(", ")
                ));
                if int_ior.is_dispersive() || ext_ior.is_dispersive() {
                    dispersive.push(format!("coated dielectric {int_ior}/{ext_ior}"));
                }
            }
            BsdfDesc::Conductor {
                alpha_u, alpha_v, ..
            } if *alpha_u > 0.0 || *alpha_v > 0.0 => {
                rough.push(format!("roughconductor α=({alpha_u}, {alpha_v})"))
            }
            BsdfDesc::Polarizer { .. } => polarizer_bsdfs += 1,
            BsdfDesc::Plastic { alpha, .. } if *alpha > 0.0 => {
                rough.push(format!("roughplastic α={alpha}"))
            }
            BsdfDesc::Dielectric {
                int_ior, ext_ior, ..
            } if int_ior.is_dispersive() || ext_ior.is_dispersive() => {
                dispersive.push(format!("dielectric {int_ior}/{ext_ior}"));
            }
            _ => {}
        }
    }
    e.reasons.push(if e.interference {
        format!(
            "interference: ON — {films} thin-film material(s){}",
            if e.thickness_texture {
                ", thickness from a texture"
            } else {
                ""
            }
        )
    } else {
        "interference: off — no thin-film material in use".into()
    });
    e.reasons.push(if e.bubble {
        format!(
            "free-standing film: ON — coherent Airy reflection and transmission (R + T = 1 when lossless) for {}",
            bubbles.join("; ")
        )
    } else {
        "free-standing film: off — no thinfilm_bubble in use".into()
    });
    e.reasons.push(if e.stack {
        format!(
            "multilayer stack: ON — transfer-matrix reflectance per wavelength for {}",
            stacks.join("; ")
        )
    } else {
        "multilayer stack: off — no thinfilm with layers in use".into()
    });
    // Several shapes may share one glass: name each interface once.
    dispersive.sort();
    dispersive.dedup();
    e.dispersion = !dispersive.is_empty();
    e.reasons.push(if e.dispersion {
        format!("dispersion: ON — wavelength-dependent refraction at {}; secondary wavelengths terminate there", dispersive.join(", "))
    } else {
        "dispersion: off — no refracting interface with a wavelength-dependent index (all 4 wavelengths share each path)".into()
    });
    fresnel_pairs.sort();
    fresnel_pairs.dedup();
    e.fresnel_split = !fresnel_pairs.is_empty() && !e.dispersion;
    e.reasons.push(if e.fresnel_split {
        format!(
            "Fresnel splitting: ON — reflection and transmission both followed at the first \
             smooth interfaces of each path ({})",
            fresnel_pairs.join(", ")
        )
    } else if fresnel_pairs.is_empty() {
        "Fresnel splitting: off — no smooth glass or bubble in use".into()
    } else {
        "Fresnel splitting: off — the scene has dispersion (split branches would share the path's wavelengths)".into()
    });
    e.rough = !rough.is_empty();
    e.reasons.push(if e.rough {
        format!("microfacet sampling: ON — {}", rough.join(", "))
    } else {
        "microfacet sampling: off — all BSDFs smooth or diffuse".into()
    });
    let mut why = Vec::new();
    if let Some(p) = scene.polarizer {
        why.push(match p {
            crate::scene::Polarizer::S => "an S polariser on the sensor".to_string(),
            crate::scene::Polarizer::P => "a P polariser on the sensor".to_string(),
            crate::scene::Polarizer::AngleDeg(d) => format!("a polariser at {d}° on the sensor"),
        });
    }
    if polarizer_bsdfs > 0 {
        why.push(format!("{polarizer_bsdfs} polarizer BSDF(s) in use"));
    }
    e.polarization = !why.is_empty();
    // The polarised integrator has Mueller matrices for the single film, conductors,
    // dielectrics, plastic and diffuse; the layered and free-standing films would silently
    // act as depolarisers there, so refuse rather than render something wrong.
    let unpolarisable: Vec<String> = bubbles
        .iter()
        .map(|b| format!("thinfilm_bubble ({b})"))
        .chain(stacks.iter().map(|s| format!("layered film {s}")))
        .collect();
    if e.polarization && !unpolarisable.is_empty() {
        anyhow::bail!(
            "the scene asks for polarisation ({}) but uses {}, whose Mueller matrices are not \
             implemented (only thinfilm, conductor, dielectric, plastic and diffuse are): remove \
             the polariser or these materials",
            why.join(" and "),
            unpolarisable
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    e.reasons.push(if e.polarization {
        format!(
            "polarisation: ON — because of {}; paths carry Stokes vectors, BSDFs act as Mueller matrices",
            why.join(" and ")
        )
    } else {
        "polarisation: off — no polariser in the scene (unpolarised integrator)".into()
    });
    Ok(e)
}
