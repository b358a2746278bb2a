//! Mitsuba 3 participating media in scene files: `<medium type="homogeneous">` with its
//! `<phase>` (`isotropic`, `hg`) and a `constvolume` albedo or extinction, shapes' `interior`
//! / `exterior` media, the sensor's medium. Media are transported only by `volpath` (and
//! `volpathmis`, rendered as volpath); Mitsuba's other integrators ignore them, and so does
//! thinfilm, saying so. Other medium, phase and volume plugins are refused by name.

use super::{Ctx, Props, Val};
use crate::render::medium::{Medium, Phase, SceneMedia, NO_MEDIUM};
use crate::render::texture::Spectrum;
use crate::scene::SpectrumDesc;
use anyhow::Result;
use std::sync::Arc;

impl<'a, 'i> Ctx<'a, 'i> {
    /// `homogeneous`: `sigma_t` (1), `albedo` (0.75), `scale` (1), `sample_emitters`
    /// (true), a nested `<phase>` (isotropic). Returns the medium's index.
    pub(super) fn build_medium(&mut self, p: &mut Props<'a, 'i>) -> Result<u32> {
        if p.plugin != "homogeneous" {
            return Err(self.unknown_plugin(p, &["homogeneous"]));
        }
        let sigma_t = self.medium_spectrum(p, "sigma_t", 1.0)?;
        let albedo = self.medium_spectrum(p, "albedo", 0.75)?;
        let scale = p.float(self, "scale", 1.0)?;
        if !(scale >= 0.0 && scale.is_finite()) {
            return Err(self.err(p.node, format!("homogeneous: scale = {scale} must be ≥ 0")));
        }
        let sample_emitters = p.bool(self, "sample_emitters", true)?;
        // Mitsuba's shortcut for a spectrally flat σ_t: the same image when σ_t is flat
        // (thinfilm always weights by the channels' densities).
        p.bool(self, "has_spectral_extinction", true)?;
        let mut phase = Phase::Isotropic;
        let mut phases = 0;
        for q in std::mem::take(&mut p.list) {
            match q.val {
                Val::Phase(ph) => {
                    phase = ph;
                    phases += 1;
                }
                _ => p.list.push(q),
            }
        }
        if phases > 1 {
            return Err(self.err(p.node, "a medium takes one <phase>"));
        }
        self.media.push(Medium {
            sigma_t,
            albedo,
            scale: scale as f32,
            phase,
            sample_emitters,
        });
        Ok(self.media.len() as u32 - 1)
    }

    /// A medium's `sigma_t` or `albedo`: a number, an `<rgb>` (in [0, 1], upsampled as a
    /// bounded reflectance — Mitsuba's `get_volume` refuses other RGB values), a
    /// `<spectrum>`, or a `constvolume` (whose RGB is upsampled unbounded).
    fn medium_spectrum(&self, p: &mut Props<'a, 'i>, name: &str, default: f32) -> Result<Spectrum> {
        let Some(q) = p.take(name) else {
            return Ok(Spectrum::Constant(default));
        };
        let desc = match q.val {
            Val::Float(v) => SpectrumDesc::Constant(v as f32),
            Val::Int(v) => SpectrumDesc::Constant(v as f32),
            Val::Rgb(c) if c.iter().all(|v| (0.0..=1.0).contains(v)) => SpectrumDesc::Rgb(c),
            Val::Rgb(c) => {
                return Err(self.err(
                    q.node,
                    format!("'{name}' = {c:?}: an <rgb> medium parameter must lie in [0, 1] (as in Mitsuba; use 'scale' or a constvolume)"),
                ))
            }
            Val::Spectrum(s) => s,
            Val::ConstVolume(SpectrumDesc::Rgb(c)) => {
                // Mitsuba's `constvolume` reads its value with `get_unbounded_texture`.
                let s = crate::spectrum::RgbUnboundedSpectrum::new(c);
                let table = (360..=830).map(|l| (l as f32, s.eval(l as f32))).collect();
                SpectrumDesc::Tabulated(table)
            }
            Val::ConstVolume(s) => s,
            _ => {
                return Err(self.err(
                    q.node,
                    format!("'{name}' must be a <float>, <rgb>, <spectrum> or constvolume, not {}", q.val.kind()),
                ))
            }
        };
        let values: Vec<f32> = match &desc {
            SpectrumDesc::Constant(v) | SpectrumDesc::D65 { scale: v } => vec![*v],
            SpectrumDesc::Rgb(c) => c.to_vec(),
            SpectrumDesc::Tabulated(t) => t.iter().map(|p| p.1).collect(),
        };
        if let Some(v) = values.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(self.err(
                q.node,
                format!("'{name}' = {v} must be a finite number ≥ 0"),
            ));
        }
        Ok(Spectrum::reflectance(&desc))
    }

    /// `isotropic`, or `hg` with `g` ∈ (−1, 1) (default 0.8, as Mitsuba's).
    pub(super) fn build_phase(&mut self, p: &mut Props<'a, 'i>) -> Result<Phase> {
        match p.plugin.as_str() {
            "isotropic" => Ok(Phase::Isotropic),
            "hg" => {
                let g = p.float(self, "g", 0.8)?;
                if !(g > -1.0 && g < 1.0) {
                    return Err(self.err(p.node, format!("hg: g = {g} must lie in (−1, 1)")));
                }
                Ok(Phase::HenyeyGreenstein { g: g as f32 })
            }
            _ => Err(self.unknown_plugin(p, &["isotropic", "hg"])),
        }
    }

    /// `constvolume` with its `value` (a number, RGB or spectrum); grid volumes are refused.
    pub(super) fn build_volume(&mut self, p: &mut Props<'a, 'i>) -> Result<SpectrumDesc> {
        if p.plugin != "constvolume" {
            return Err(self.unknown_plugin(p, &["constvolume"]));
        }
        p.accept(&["to_world"], self, |v| matches!(v, Val::Transform(_)))?;
        p.spectrum(self, "value", 1.0)
    }

    /// A shape's `interior` and `exterior` media ([`NO_MEDIUM`] where not given).
    pub(super) fn shape_media_refs(&mut self, p: &mut Props<'a, 'i>) -> Result<[u32; 2]> {
        let mut media = [NO_MEDIUM; 2];
        for q in std::mem::take(&mut p.list) {
            match (q.name.as_str(), &q.val) {
                ("interior", Val::Medium(i)) => media[0] = *i,
                ("exterior", Val::Medium(i)) => media[1] = *i,
                (_, Val::Medium(_)) => {
                    return Err(self.err(
                        q.node,
                        format!(
                        "a shape's medium must be named \"interior\" or \"exterior\", not \"{}\"",
                        q.name
                    ),
                    ))
                }
                _ => p.list.push(q),
            }
        }
        Ok(media)
    }

    /// The sensor's medium (a nested or referenced `<medium>`), if any.
    pub(super) fn sensor_medium(&mut self, p: &mut Props<'a, 'i>) -> Result<Option<u32>> {
        let mut medium = None;
        for q in std::mem::take(&mut p.list) {
            match q.val {
                Val::Medium(_) if medium.is_some() => {
                    return Err(self.err(q.node, "a sensor takes one medium"))
                }
                Val::Medium(i) => medium = Some(i),
                _ => p.list.push(q),
            }
        }
        Ok(medium)
    }

    /// Records the media bounded by the next `n` shapes of the scene.
    pub(super) fn add_shape_media(&mut self, n: usize, media: [u32; 2]) {
        if media != [NO_MEDIUM; 2] {
            let first = self.shapes.len();
            self.shape_media
                .extend((first..first + n).map(|i| (i as u32, media)));
        }
    }

    /// The scene's media for the renderer: Some where the integrator is `volpath` (or
    /// `volpathmis`) and the scene has media or null interactions (which volpath's shadow
    /// rays pass); other integrators ignore media, as Mitsuba's do (said on stderr).
    pub(super) fn scene_media(&mut self, sensor: Option<u32>) -> Result<Option<Arc<SceneMedia>>> {
        let volpath = matches!(
            self.integrator_plugin.as_deref(),
            Some("volpath" | "volpathmis")
        );
        // Null interactions (a `null` surface, a thin dielectric's transmission) take no
        // vertex in volpath and let its shadow rays through, media or not.
        let has_null = self.bsdfs.iter().any(|b| {
            matches!(
                b,
                crate::render::bsdf::Bsdf::Null(_) | crate::render::bsdf::Bsdf::ThinDielectric(_)
            )
        });
        if !volpath {
            if !self.media.is_empty() {
                eprintln!(
                    "note: integrator \"{}\" ignores participating media (as Mitsuba's does); use volpath to render them",
                    self.integrator_plugin.as_deref().unwrap_or("path")
                );
            }
            return Ok(None);
        }
        if self.media.is_empty() && !has_null {
            return Ok(None);
        }
        Ok(Some(Arc::new(SceneMedia {
            media: std::mem::take(&mut self.media),
            shape_media: std::mem::take(&mut self.shape_media),
            sensor: sensor.unwrap_or(NO_MEDIUM),
        })))
    }
}
