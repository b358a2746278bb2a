//! The environment of a scene, chosen on the command line (`thinfilm render --environment
//! FILE|constant:V|constant:R,G,B --environment-rotation DEG`), for Mitsuba XML, glTF, OBJ
//! and PLY scenes alike.
//!
//! - `FILE`: a lat-long EXR or Radiance HDR in Mitsuba's `envmap` layout (u = 0 looks along
//!   −Z, u = ¼ along +X, v = 0 straight up, +Y), linear sRGB texels upsampled as
//!   illuminants — exactly `<emitter type="envmap"><string name="filename" value="FILE"/>`.
//! - `constant:V`: Mitsuba's `constant` emitter with `<float name="radiance" value="V"/>`, the
//!   D65 illuminant scaled so that its luminance Y is V.
//! - `constant:R,G,B`: the same with `<rgb name="radiance" value="R, G, B"/>`, upsampled as an
//!   illuminant (the way every RGB emitter is).
//!
//! The new environment replaces the scene's own (its `envmap` and `constant` emitters; area,
//! point, spot and directional lights stay). `--environment-rotation DEG` turns the
//! environment about the world +Y (up) axis by DEG degrees, right-handed — the same as
//! `<transform name="to_world"><rotate y="1" angle="DEG"/></transform>` on a Mitsuba
//! `envmap`: with 90, what the map shows at u = 0 (seen along −Z) is seen along −X. Given
//! alone it rotates the scene's own environment map (after its `to_world`).

use super::{EmitterDesc, Scene, SpectrumDesc};
use anyhow::{bail, Context, Result};
use glam::Mat4;
use std::path::PathBuf;
use std::sync::Arc;

/// What `--environment` names.
#[derive(Debug, Clone, PartialEq)]
pub enum EnvironmentSource {
    /// A lat-long EXR or HDR image.
    File(PathBuf),
    /// A uniform environment of this radiance.
    Constant(SpectrumDesc),
}

impl std::str::FromStr for EnvironmentSource {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let Some(rest) = s.strip_prefix("constant:") else {
            if s.trim().is_empty() {
                return Err(
                    "empty environment: expected FILE, constant:V or constant:R,G,B".into(),
                );
            }
            return Ok(EnvironmentSource::File(PathBuf::from(s)));
        };
        let values: Vec<f32> = rest
            .split(',')
            .map(|v| {
                v.trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite() && *x >= 0.0)
                    .ok_or_else(|| format!("'{s}': '{}' is not a finite radiance ≥ 0", v.trim()))
            })
            .collect::<std::result::Result<_, _>>()?;
        match values[..] {
            [v] => Ok(EnvironmentSource::Constant(SpectrumDesc::D65 { scale: v })),
            [r, g, b] => Ok(EnvironmentSource::Constant(SpectrumDesc::Rgb([r, g, b]))),
            _ => Err(format!(
                "'{s}': expected constant:V or constant:R,G,B ({} values given)",
                values.len()
            )),
        }
    }
}

/// The rotation `--environment-rotation DEG` applies (about +Y, right-handed, as Mitsuba's
/// `<rotate y="1" angle="DEG"/>`).
pub fn rotation(deg: f32) -> Mat4 {
    Mat4::from_rotation_y(deg.to_radians())
}

/// Replaces the scene's environment by `source` (if given) and rotates the environment by
/// `rotation_deg` (if given); see the module docs.
pub fn apply(
    scene: &mut Scene,
    source: Option<&EnvironmentSource>,
    rotation_deg: Option<f32>,
) -> Result<()> {
    if let Some(deg) = rotation_deg {
        if !deg.is_finite() {
            bail!("--environment-rotation {deg}: must be a finite angle in degrees");
        }
    }
    let turn = rotation(rotation_deg.unwrap_or(0.0));
    if let Some(source) = source {
        let emitter = match source {
            EnvironmentSource::File(path) => {
                let image = super::load_rgb_image(path)
                    .with_context(|| format!("--environment {}", path.display()))?;
                if let Some(p) = image
                    .pixels
                    .iter()
                    .find(|p| p.iter().any(|v| !v.is_finite() || *v < 0.0))
                {
                    bail!(
                        "--environment {}: texel {p:?} is negative or not finite",
                        path.display()
                    );
                }
                if image.width < 1 || image.height < 2 {
                    bail!(
                        "--environment {}: a lat-long map needs at least 1×2 texels, got {}×{}",
                        path.display(),
                        image.width,
                        image.height
                    );
                }
                EmitterDesc::Envmap {
                    image: Arc::new(image),
                    scale: 1.0,
                    to_world: turn,
                    path: Some(path.clone()),
                }
            }
            EnvironmentSource::Constant(radiance) => EmitterDesc::Constant {
                radiance: radiance.clone(),
            },
        };
        scene.emitters.retain(|e| !is_environment(e));
        scene.emitters.push(emitter);
        return Ok(());
    }
    if rotation_deg.is_some() {
        if !scene.emitters.iter().any(is_environment) {
            bail!("--environment-rotation: the scene has no environment to rotate (add --environment)");
        }
        for e in &mut scene.emitters {
            if let EmitterDesc::Envmap { to_world, .. } = e {
                *to_world = turn * *to_world;
            }
        }
    }
    Ok(())
}

/// The default environment of glTF scenes: the neutral studio of
/// [`super::sky::neutral_radiance`], generated in memory.
pub fn neutral_studio() -> EmitterDesc {
    let (w, h) = super::sky::NEUTRAL_SIZE;
    EmitterDesc::Envmap {
        image: Arc::new(super::sky::neutral_environment(w, h)),
        scale: 1.0,
        to_world: Mat4::IDENTITY,
        path: None,
    }
}

fn is_environment(e: &EmitterDesc) -> bool {
    matches!(e, EmitterDesc::Envmap { .. } | EmitterDesc::Constant { .. })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn parses_the_three_forms_and_refuses_bad_ones() {
        assert_eq!(
            "constant:2".parse::<EnvironmentSource>(),
            Ok(EnvironmentSource::Constant(SpectrumDesc::D65 {
                scale: 2.0
            }))
        );
        assert_eq!(
            "constant:0.5, 1,2".parse::<EnvironmentSource>(),
            Ok(EnvironmentSource::Constant(SpectrumDesc::Rgb([
                0.5, 1.0, 2.0
            ])))
        );
        assert_eq!(
            "sky.exr".parse::<EnvironmentSource>(),
            Ok(EnvironmentSource::File("sky.exr".into()))
        );
        for bad in [
            "constant:",
            "constant:-1",
            "constant:nan",
            "constant:1,2",
            "",
        ] {
            assert!(bad.parse::<EnvironmentSource>().is_err(), "{bad}");
        }
    }

    /// The rotation is Mitsuba's `<rotate y="1" angle="90"/>`: −Z goes to −X.
    #[test]
    fn rotation_turns_minus_z_to_minus_x() {
        let d = rotation(90.0).transform_vector3(-Vec3::Z);
        assert!((d + Vec3::X).length() < 1e-6, "{d}");
    }
}
