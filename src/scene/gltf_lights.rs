//! glTF lights (`KHR_lights_punctual`) and cameras, see `docs/lights-and-cameras.md`.
//!
//! **Lights.** The extension's photometric quantities become the renderer's radiometric ones
//! at 683 lm/W (the luminous efficacy at 555 nm, the constant Blender's glTF importer uses,
//! `PBR_WATTS_TO_LUMENS`): a point or spot light's intensity in candela (lm/sr) gives a
//! radiant intensity of I/683 W/sr, a directional light's illuminance in lux (lm/m²) an
//! irradiance of E/683 W/m², times the light's linear `color` upsampled as an illuminant. A
//! white 683 cd point light therefore renders exactly as Mitsuba's `point` of intensity 1
//! (D65 of luminance Y = 1), and a rendered pixel's Y is luminance in cd/m² divided by 683.
//! Lights shine along their node's local −Z; the world transform's scale is ignored (the
//! extension says light properties are unaffected by it). Spot cones use the extension's
//! smooth falloff; a `range` applies its recommended window clamp(1 − (d/range)⁴, 0, 1).
//!
//! **Cameras.** glTF cameras look along −Z with +X right, Mitsuba's along +Z with +X left:
//! the camera frame is the node's rotation times a half turn about Y (scale dropped).
//! Perspective: `yfov` along y, `aspectRatio` sets the film width (height 512). Orthographic:
//! `xmag`/`ymag` are the half-width and half-height of the view; the film's aspect is
//! xmag/ymag. Without a camera, [`model_viewer_camera`] frames the model as `<model-viewer>`
//! does by default.

use super::{look_at, Camera, EmitterDesc, FovAxis, Projection, SpectrumDesc, SpotCone};
use anyhow::{bail, Context, Result};
use glam::{Mat3, Mat4, Vec3};
use serde_json::Value;
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};

/// Lumens per watt at 555 nm: photometric → radiometric.
pub const LUMENS_PER_WATT: f32 = 683.0;

/// Most lights one file may declare (each becomes an emitter sampled at every vertex).
const MAX_LIGHTS: usize = 4096;

/// One entry of the document's `KHR_lights_punctual.lights`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PunctualLight {
    kind: Kind,
    color: [f32; 3],
    intensity: f32,
    range: Option<f32>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Directional,
    Point,
    Spot { inner: f32, outer: f32 },
}

/// A number at `v[key]`: `default` if absent, an error naming `at.key` if not a finite
/// number in [lo, hi].
fn number(v: &Value, key: &str, default: f64, (lo, hi): (f64, f64), at: &str) -> Result<f32> {
    match v.get(key) {
        None => Ok(default as f32),
        Some(x) => {
            let n = x
                .as_f64()
                .filter(|n| n.is_finite() && (lo..=hi).contains(n));
            n.map(|n| n as f32)
                .with_context(|| format!("{at}.{key} = {x} must be a number in [{lo}, {hi}]"))
        }
    }
}

/// Reads and validates the document-level `KHR_lights_punctual` object (`ext`), naming
/// `file` and the JSON path in every error.
pub(crate) fn parse_lights(ext: Option<&Value>, file: &str) -> Result<Vec<PunctualLight>> {
    let Some(ext) = ext else {
        return Ok(Vec::new());
    };
    let at = "extensions.KHR_lights_punctual";
    let list = match ext.get("lights") {
        Some(Value::Array(a)) => a,
        _ => bail!("{file}: {at}.lights must be an array"),
    };
    if list.len() > MAX_LIGHTS {
        bail!(
            "{file}: {at}.lights has {} lights; at most {MAX_LIGHTS} are supported",
            list.len()
        );
    }
    list.iter()
        .enumerate()
        .map(|(i, l)| {
            parse_light(l, &format!("{at}.lights[{i}]")).with_context(|| file.to_string())
        })
        .collect()
}

fn parse_light(l: &Value, at: &str) -> Result<PunctualLight> {
    if !l.is_object() {
        bail!("{at} must be an object");
    }
    let color = match l.get("color") {
        None => [1.0; 3],
        Some(Value::Array(c)) if c.len() == 3 => {
            let mut out = [0.0f32; 3];
            for (o, x) in out.iter_mut().zip(c) {
                *o = x
                    .as_f64()
                    .filter(|v| (0.0..=1.0).contains(v))
                    .with_context(|| format!("{at}.color has {x}: components must be in [0, 1]"))?
                    as f32;
            }
            out
        }
        Some(c) => bail!("{at}.color = {c} must be an array of 3 numbers"),
    };
    let intensity = number(l, "intensity", 1.0, (0.0, 1e12), at)?;
    let range = match l.get("range") {
        None => None,
        Some(_) => Some(number(l, "range", 0.0, (f64::MIN_POSITIVE, 1e30), at)?),
    };
    let kind = match l.get("type").and_then(Value::as_str) {
        Some("directional") => Kind::Directional,
        Some("point") => Kind::Point,
        Some("spot") => {
            let spot = l
                .get("spot")
                .filter(|s| s.is_object())
                .with_context(|| format!("{at}: a spot light needs a 'spot' object"))?;
            let sat = format!("{at}.spot");
            let outer = number(
                spot,
                "outerConeAngle",
                FRAC_PI_4 as f64,
                (0.0, FRAC_PI_2 as f64),
                &sat,
            )?;
            let inner = number(spot, "innerConeAngle", 0.0, (0.0, FRAC_PI_2 as f64), &sat)?;
            if inner >= outer {
                bail!("{sat}: innerConeAngle {inner} must be less than outerConeAngle {outer}");
            }
            Kind::Spot { inner, outer }
        }
        other => bail!(
            "{at}.type {}: expected \"directional\", \"point\" or \"spot\"",
            other.map_or_else(|| "is missing".to_string(), |t| format!("\"{t}\""))
        ),
    };
    Ok(PunctualLight {
        kind,
        color,
        intensity,
        range,
    })
}

/// The light index a node's `KHR_lights_punctual` extension (`ext`) names, checked against
/// the `count` lights of the document.
pub(crate) fn node_light(ext: Option<&Value>, count: usize, node: usize) -> Result<Option<usize>> {
    let Some(ext) = ext else { return Ok(None) };
    let i = ext.get("light").and_then(Value::as_u64);
    match i {
        Some(i) if (i as usize) < count && i <= usize::MAX as u64 => Ok(Some(i as usize)),
        _ => bail!(
            "nodes[{node}].extensions.KHR_lights_punctual.light = {} does not name one of the {count} lights",
            ext.get("light").map_or("(missing)".to_string(), |v| v.to_string())
        ),
    }
}

/// Rotation and translation of `world` (its scale removed): columns normalised and made
/// orthogonal (Gram–Schmidt, keeping the handedness).
fn rigid(world: Mat4) -> Mat4 {
    let m = Mat3::from_mat4(world);
    let z = m.z_axis.normalize_or(Vec3::Z);
    let x = (m.x_axis - z * m.x_axis.dot(z)).normalize_or(z.any_orthonormal_vector());
    let y = z.cross(x) * if m.determinant() < 0.0 { -1.0 } else { 1.0 };
    Mat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        world.w_axis.truncate().extend(1.0),
    )
}

/// The emitter of `light` on a node with world transform `world`.
pub(crate) fn emitter(light: &PunctualLight, world: Mat4) -> EmitterDesc {
    let k = light.intensity / LUMENS_PER_WATT;
    let power = SpectrumDesc::Rgb(light.color.map(|c| c * k));
    let position = world.transform_point3(Vec3::ZERO);
    let dir = world
        .transform_vector3(-Vec3::Z)
        .try_normalize()
        .unwrap_or(-Vec3::Z);
    // A frame whose +Z is the light's direction (the cone is symmetric: its roll is free).
    let up = if dir.y.abs() > 0.9 { Vec3::X } else { Vec3::Y };
    let frame = look_at(position, position + dir, up);
    match light.kind {
        Kind::Directional => EmitterDesc::Directional {
            direction: dir,
            irradiance: power,
        },
        Kind::Point if light.range.is_none() => EmitterDesc::Point {
            position,
            intensity: power,
        },
        Kind::Point => EmitterDesc::Spot {
            to_world: frame,
            intensity: power,
            cone: SpotCone::Omni,
            range: light.range,
        },
        Kind::Spot { inner, outer } => EmitterDesc::Spot {
            to_world: frame,
            intensity: power,
            cone: SpotCone::Smooth {
                cos_inner: inner.cos(),
                cos_outer: outer.cos(),
            },
            range: light.range,
        },
    }
}

/// The camera of glTF camera `cam` on a node with world transform `world`, and the film
/// aspect ratio it asks for (None: the default square film).
pub(crate) fn camera(world: Mat4, cam: &gltf::Camera) -> (Camera, Option<f32>) {
    // glTF looks down −Z with +X right; Mitsuba looks down +Z with +X left.
    let frame = rigid(world) * Mat4::from_rotation_y(std::f32::consts::PI);
    match cam.projection() {
        gltf::camera::Projection::Perspective(p) => {
            let znear = p.znear().max(1e-6);
            (
                Camera {
                    to_world: frame,
                    fov_deg: p.yfov().to_degrees(),
                    fov_axis: FovAxis::Y,
                    near_clip: znear,
                    far_clip: p.zfar().unwrap_or(1e4).max(znear * 2.0),
                    projection: Projection::Perspective,
                },
                p.aspect_ratio(),
            )
        }
        gltf::camera::Projection::Orthographic(o) => {
            // Mitsuba's orthographic view spans x ∈ [−1, 1] scaled by to_world and
            // y ∈ [−1/aspect, 1/aspect]: scaling x and y by xmag gives ±xmag × ±ymag when
            // the film's aspect is xmag/ymag.
            let (xmag, ymag) = (o.xmag(), o.ymag());
            (
                Camera {
                    to_world: frame * Mat4::from_scale(Vec3::new(xmag, xmag, 1.0)),
                    fov_deg: 0.0,
                    fov_axis: FovAxis::X,
                    near_clip: o.znear(),
                    far_clip: o.zfar(),
                    projection: Projection::Orthographic,
                },
                Some(xmag / ymag),
            )
        }
    }
}

/// `<model-viewer>`'s default framing (`camera-orbit="0deg 75deg 105%"`, `camera-target`
/// auto, `field-of-view` auto, framed field of view 30°): the target is the centre c of the
/// bounding box; the bounding sphere about c has radius r = the farthest vertex; the ideal
/// distance is D = r / sin 15°; the camera sits at c + 1.05·D·(0, cos 75°, sin 75°) (in front,
/// 15° above the target), and its vertical field of view is 2·atan(tan 15° · max(1, a*/a))
/// for a film of aspect a, with a* = max over vertices of √(x² + z²)/(D − |y|) / tan 15°
/// (vertex offsets from c; model-viewer's `idealAspect`): wide models get a wider view on
/// narrow films. The film's aspect is known only when rendering (`--resolution`), so the
/// camera carries a* ([`FovAxis::FitY`]) and the renderer applies the rule at any aspect.
pub fn model_viewer_camera(vertices: &[Vec3]) -> Option<Camera> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for v in vertices {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let c = (lo + hi) * 0.5;
    let r = vertices
        .iter()
        .map(|v| v.distance_squared(c))
        .fold(0.0f32, f32::max)
        .sqrt()
        .max(1e-6);
    let tan_half = 15f32.to_radians().tan();
    let d = r / 15f32.to_radians().sin();
    let ideal_aspect = vertices
        .iter()
        .map(|v| {
            let o = *v - c;
            (o.x * o.x + o.z * o.z).sqrt() / (d - o.y.abs())
        })
        .fold(0.0f32, f32::max)
        / tan_half;
    let dist = 1.05 * d;
    let phi = 75f32.to_radians();
    let origin = c + dist * Vec3::new(0.0, phi.cos(), phi.sin());
    Some(Camera {
        to_world: look_at(origin, c, Vec3::Y),
        // 2·atan(tan 15°): 30° up to rounding, computed as before the aspect was deferred so
        // that square renders are bit-identical.
        fov_deg: (2.0 * tan_half.atan()).to_degrees(),
        fov_axis: FovAxis::FitY {
            min_aspect: ideal_aspect,
        },
        near_clip: ((dist - r) * 0.5).max(dist * 1e-4),
        far_clip: (dist + r) * 2.0,
        projection: Projection::Perspective,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn lights_parse_with_defaults_and_refuse_bad_values() {
        let ext = json!({"lights": [
            {"type": "point"},
            {"type": "spot", "spot": {}, "intensity": 2, "range": 5},
            {"type": "directional", "color": [1, 0.5, 0]}
        ]});
        let l = parse_lights(Some(&ext), "f").unwrap();
        assert_eq!(l[0].intensity, 1.0);
        assert_eq!(
            l[1].kind,
            Kind::Spot {
                inner: 0.0,
                outer: FRAC_PI_4
            }
        );
        assert_eq!(l[1].range, Some(5.0));
        assert_eq!(l[2].color, [1.0, 0.5, 0.0]);
        for bad in [
            json!({"lights": {}}),
            json!({"lights": [{"type": "area"}]}),
            json!({"lights": [{}]}),
            json!({"lights": [{"type": "point", "intensity": -1}]}),
            json!({"lights": [{"type": "point", "color": [1, 2]}]}),
            json!({"lights": [{"type": "point", "range": 0}]}),
            json!({"lights": [{"type": "spot"}]}),
            json!({"lights": [{"type": "spot", "spot": {"innerConeAngle": 0.5, "outerConeAngle": 0.4}}]}),
            json!({"lights": [{"type": "spot", "spot": {"outerConeAngle": 2.0}}]}),
        ] {
            let err = parse_lights(Some(&bad), "bad.gltf").unwrap_err();
            assert!(format!("{err:#}").contains("bad.gltf"), "{err:#}");
        }
        assert!(node_light(Some(&json!({"light": 3})), 3, 0).is_err());
        assert!(node_light(Some(&json!({"light": -1})), 3, 0).is_err());
        assert_eq!(
            node_light(Some(&json!({"light": 2})), 3, 0).unwrap(),
            Some(2)
        );
    }

    /// A spot on a node rotated and scaled: placed at the node, shining along its −Z, the
    /// scale ignored, intensity in W/sr = cd / 683.
    #[test]
    fn spot_takes_the_node_transform() {
        let light = PunctualLight {
            kind: Kind::Spot {
                inner: 0.1,
                outer: 0.5,
            },
            color: [1.0; 3],
            intensity: 683.0,
            range: None,
        };
        let world = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
            * Mat4::from_rotation_x(-FRAC_PI_2)
            * Mat4::from_scale(Vec3::splat(3.0));
        let EmitterDesc::Spot {
            to_world,
            intensity,
            ..
        } = emitter(&light, world)
        else {
            panic!("not a spot");
        };
        assert!((to_world.transform_point3(Vec3::ZERO) - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-5);
        let axis = to_world.transform_vector3(Vec3::Z);
        assert!((axis - -Vec3::Y).length() < 1e-5, "{axis}");
        assert_eq!(intensity, SpectrumDesc::Rgb([1.0; 3]));
    }

    #[test]
    fn model_viewer_framing_puts_the_sphere_in_view() {
        let verts = [Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0)];
        let cam = model_viewer_camera(&verts).unwrap();
        let origin = cam.to_world.transform_point3(Vec3::ZERO);
        let c = Vec3::new(0.0, 1.0, 0.0);
        let r = 3f32.sqrt();
        let dist = origin.distance(c);
        assert!((dist - 1.05 * r / 15f32.to_radians().sin()).abs() < 1e-4);
        // 15° above the target, on its +Z side.
        let el = ((origin.y - c.y) / dist).asin().to_degrees();
        assert!((el - 15.0).abs() < 1e-3 && origin.z > 0.0, "{el}");
        assert!((cam.fov_deg - 30.0).abs() < 1e-4, "{}", cam.fov_deg);
        let FovAxis::FitY { min_aspect } = cam.fov_axis else {
            panic!("{:?}", cam.fov_axis)
        };
        assert!(min_aspect > 0.0 && min_aspect <= 1.0 + 1e-5, "{min_aspect}");
    }
}
