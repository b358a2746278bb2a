//! glTF lights, cameras, environments and malformed files.
//!
//! - `KHR_lights_punctual` against closed form: a grey diffuse floor (ρ = 0.5) under one
//!   light reflects L = ρ/π · E, with E = (I/683)·cos θ / d² (point, spot inside its inner
//!   cone, times the extension's t² falloff between the cones and its range window) or
//!   E = (lux/683)·cos θ (directional). A narrow camera looks straight down at one floor point.
//! - Defaults: the neutral grey studio environment, `<model-viewer>` framing, orthographic
//!   cameras; `--environment` / `--environment-rotation` on glTF and XML scenes.
//! - Malformed files (including ones on which the `gltf` crate itself would panic) are
//!   refused with an error naming the file.

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use thinfilm::render::bsdf::Bsdf;
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::environment::{self, EnvironmentSource};
use thinfilm::scene::{EmitterDesc, Projection, Scene, SpectrumDesc};

const RHO: f64 = 0.5;

/// A 20 × 20 floor at y = 0 (normal +Y) as `floor.bin` in `dir`; returns the glTF pieces.
fn floor(dir: &Path) -> Value {
    let mut bin = Vec::new();
    for p in [
        [-10.0f32, 0.0, -10.0],
        [10.0, 0.0, -10.0],
        [10.0, 0.0, 10.0],
        [-10.0, 0.0, 10.0],
    ] {
        for v in p {
            bin.extend(v.to_le_bytes());
        }
    }
    for i in [0u16, 3, 2, 0, 2, 1] {
        bin.extend(i.to_le_bytes());
    }
    std::fs::write(dir.join("floor.bin"), &bin).unwrap();
    json!({
        "buffers": [{"uri": "floor.bin", "byteLength": 60}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-10, 0, -10], "max": [10, 0, 10]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]
    })
}

/// Writes `name` in `dir`: the floor, `extra_nodes` (after the floor node 0) and `top`
/// merged into the document root.
fn write_gltf(dir: &Path, name: &str, extra_nodes: Vec<Value>, top: Value) -> PathBuf {
    let mut doc = floor(dir);
    let mut nodes = vec![json!({"mesh": 0})];
    nodes.extend(extra_nodes);
    let roots: Vec<usize> = (0..nodes.len()).collect();
    doc["asset"] = json!({"version": "2.0"});
    doc["nodes"] = Value::Array(nodes);
    doc["scenes"] = json!([{"nodes": roots}]);
    doc["scene"] = json!(0);
    if let Value::Object(m) = top {
        for (k, v) in m {
            doc[k] = v;
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
    path
}

/// Half a turn about X by `deg` degrees as a glTF quaternion [x, y, z, w].
fn rot_x(deg: f64) -> Value {
    let h = deg.to_radians() / 2.0;
    json!([h.sin(), 0.0, 0.0, h.cos()])
}

/// A camera node 0.5 above floor point (x, z) looking straight down with a tiny field.
fn down_camera(x: f64, z: f64) -> Value {
    json!({"camera": 0, "translation": [x, 0.5, z], "rotation": rot_x(-90.0)})
}

fn cameras() -> Value {
    json!([{"type": "perspective", "perspective": {"yfov": 0.005, "znear": 0.01, "aspectRatio": 1.0}}])
}

/// Mean RGB of the floor point seen by the down camera, lit only by the file's lights on a
/// diffuse floor of reflectance ρ.
fn floor_radiance(path: &Path) -> [f64; 3] {
    let mut scene: Scene = thinfilm::scene::load(path, &[]).expect("glTF loads");
    scene.bsdfs = vec![Bsdf::default_diffuse()];
    for s in &mut scene.shapes {
        s.bsdf = 0;
    }
    scene
        .emitters
        .retain(|e| !matches!(e, EmitterDesc::Envmap { .. } | EmitterDesc::Constant { .. }));
    mean_rgb(&scene, 16)
}

/// Mean RGB of a 4 × 4 render of `scene` at `spp` samples per pixel (seed 1).
fn mean_rgb(scene: &Scene, spp: u32) -> [f64; 3] {
    let out = render(
        scene,
        &RenderOptions {
            spp: Some(spp),
            resolution: Some((4, 4)),
            seed: Some(1),
            ..Default::default()
        },
    )
    .expect("render");
    let n = out.image.pixels.len() as f64;
    let mut m = [0.0; 3];
    for p in &out.image.pixels {
        for c in 0..3 {
            m[c] += p[c] as f64 / n;
        }
    }
    m
}

fn assert_close(what: &str, got: [f64; 3], want: f64) {
    for (c, g) in got.iter().enumerate() {
        assert!(
            (g / want - 1.0).abs() < 0.02,
            "{what}: channel {c} = {g:.5}, closed form {want:.5}"
        );
    }
}

fn lights(list: Value) -> Value {
    json!({"extensions": {"KHR_lights_punctual": {"lights": list}},
           "extensionsUsed": ["KHR_lights_punctual"], "cameras": cameras()})
}

#[test]
fn point_light_in_candela_matches_the_inverse_square_law() {
    let dir = tempfile::tempdir().unwrap();
    // 4 · 683 cd = 4 W/sr at 2 m.
    for (x, range) in [(0.0, None), (1.5, None), (0.0, Some(3.0))] {
        let mut light = json!({"type": "point", "intensity": 4.0 * 683.0});
        if let Some(r) = range {
            light["range"] = json!(r);
        }
        let path = write_gltf(
            dir.path(),
            "point.gltf",
            vec![
                down_camera(x, 0.0),
                json!({"translation": [0, 2, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}}),
            ],
            lights(json!([light])),
        );
        let d2 = x * x + 4.0;
        let cos = 2.0 / d2.sqrt();
        let window = range.map_or(1.0, |r: f64| 1.0 - (d2.sqrt() / r).powi(4));
        let want = RHO / std::f64::consts::PI * 4.0 * cos / d2 * window;
        assert_close(
            &format!("point, floor x = {x}, range {range:?}"),
            floor_radiance(&path),
            want,
        );
    }
}

#[test]
fn spot_light_follows_the_smooth_cone_and_ignores_node_scale() {
    let dir = tempfile::tempdir().unwrap();
    let (inner, outer) = (0.2f64, 0.6f64);
    for theta in [0.0f64, 0.4, 0.7] {
        let x = 2.0 * theta.tan();
        let path = write_gltf(
            dir.path(),
            "spot.gltf",
            vec![
                down_camera(x, 0.0),
                json!({"translation": [0, 2, 0], "rotation": rot_x(-90.0), "scale": [3, 3, 3],
                       "extensions": {"KHR_lights_punctual": {"light": 0}}}),
            ],
            lights(json!([{"type": "spot", "intensity": 683.0 * 3.0,
                           "spot": {"innerConeAngle": inner, "outerConeAngle": outer}}])),
        );
        let t = ((theta.cos() - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0);
        let d2 = x * x + 4.0;
        let want = RHO / std::f64::consts::PI * 3.0 * t * t * theta.cos() / d2;
        let got = floor_radiance(&path);
        if want == 0.0 {
            assert!(got.iter().all(|g| *g < 1e-6), "outside the cone: {got:?}");
        } else {
            assert_close(&format!("spot at θ = {theta}"), got, want);
        }
    }
}

#[test]
fn directional_light_in_lux_follows_the_node_rotation() {
    let dir = tempfile::tempdir().unwrap();
    // −Z turned by −60° about X points along (0, −cos 30°, −½): cos θ = cos 30° on the floor.
    let path = write_gltf(
        dir.path(),
        "sun.gltf",
        vec![
            down_camera(0.3, 0.2),
            json!({"rotation": rot_x(-60.0), "translation": [5, 5, 5],
                   "extensions": {"KHR_lights_punctual": {"light": 0}}}),
        ],
        lights(json!([{"type": "directional", "intensity": 2.0 * 683.0}])),
    );
    let want = RHO / std::f64::consts::PI * 2.0 * 30f64.to_radians().cos();
    assert_close("directional", floor_radiance(&path), want);
}

#[test]
fn defaults_are_a_neutral_studio_and_model_viewer_framing() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(dir.path(), "plain.gltf", vec![], json!({}));
    let s = thinfilm::scene::load(&path, &[]).unwrap();
    let [EmitterDesc::Envmap { image, .. }] = s.emitters.as_slice() else {
        panic!("expected one environment map, got {:?}", s.emitters.len());
    };
    assert!(image.pixels.iter().all(|p| p[0] == p[1] && p[1] == p[2]));
    // In front (+Z) of the floor's centre, 15° above it.
    let o = s.camera.to_world.transform_point3(glam::Vec3::ZERO);
    let el = (o.y / o.length()).asin().to_degrees();
    assert!((el - 15.0).abs() < 1e-3 && o.z > 0.0, "{o} {el}");
    assert_eq!(s.camera.projection, Projection::Perspective);
}

/// How far the model reaches towards the frame's edges when `scene`'s camera renders at
/// `width` × `height`: the largest |x|/x_edge and |y|/y_edge over the mesh's vertices in the
/// camera's frame (≤ 1: in view).
fn frame_fill(scene: &Scene, width: u32, height: u32) -> (f32, f32) {
    let aspect = width as f32 / height as f32;
    let c = &scene.camera;
    let fov_x = thinfilm::render::camera::fov_x_deg(c.fov_deg, c.fov_axis, aspect);
    let tan_x = (0.5 * fov_x.to_radians()).tan();
    let tan_y = tan_x / aspect;
    let to_local = c.to_world.inverse();
    let mut fill = (0.0f32, 0.0f32);
    for s in &scene.shapes {
        let thinfilm::scene::Geometry::Mesh(m) = &s.geometry else {
            continue;
        };
        for p in &m.positions {
            let q = to_local.transform_point3(*p);
            assert!(q.z > 0.0, "vertex {p} behind the camera");
            fill.0 = fill.0.max((q.x / q.z).abs() / tan_x);
            fill.1 = fill.1.max((q.y / q.z).abs() / tan_y);
        }
    }
    fill
}

/// Without a camera the model is framed as `<model-viewer>` frames it at the aspect the
/// render asks for: a vertical field of 30° on square and wide films, widened on films
/// narrower than the model's ideal aspect so that it fits horizontally — in view at every
/// aspect, and filling the narrower dimension of a tall film as much as a square film's.
#[test]
fn camera_less_framing_fits_the_model_at_any_aspect() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(dir.path(), "plain.gltf", vec![], json!({}));
    let s = thinfilm::scene::load(&path, &[]).unwrap();
    let square = frame_fill(&s, 300, 300).0;
    for (w, h) in [(300, 300), (600, 200), (200, 600), (100, 400)] {
        let (fx, fy) = frame_fill(&s, w, h);
        eprintln!(
            "{w}×{h}: the floor reaches {fx:.3} of the half width, {fy:.3} of the half height"
        );
        assert!(fx <= 1.0 && fy <= 1.0, "{w}×{h}: out of view ({fx}, {fy})");
        let aspect = w as f32 / h as f32;
        let fov_x =
            thinfilm::render::camera::fov_x_deg(s.camera.fov_deg, s.camera.fov_axis, aspect);
        let tan_y = (0.5 * fov_x.to_radians()).tan() / aspect;
        if w >= h {
            assert!(
                (tan_y - 15f32.to_radians().tan()).abs() < 1e-5,
                "{w}×{h}: tan {tan_y}"
            );
        } else {
            // The floor (wider than tall) fills the narrower, horizontal, dimension.
            assert!(
                fx > 0.95 * square,
                "{w}×{h}: the floor fills {fx} of the width, {square} on a square film"
            );
        }
    }
}

#[test]
fn orthographic_camera_sets_extent_and_aspect() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(
        dir.path(),
        "ortho.gltf",
        vec![json!({"camera": 0, "translation": [0, 1, 5]})],
        json!({"cameras": [{"type": "orthographic",
            "orthographic": {"xmag": 3.0, "ymag": 1.5, "znear": 0.1, "zfar": 50}}]}),
    );
    let s = thinfilm::scene::load(&path, &[]).unwrap();
    assert_eq!(s.camera.projection, Projection::Orthographic);
    assert_eq!(s.film.width, 2 * s.film.height);
    let x = s.camera.to_world.transform_vector3(glam::Vec3::X);
    assert!((x.length() - 3.0).abs() < 1e-5);
    // Looking down −Z from z = 5.
    let z = s.camera.to_world.transform_vector3(glam::Vec3::Z);
    assert!((z + glam::Vec3::Z).length() < 1e-5, "{z}");
}

#[test]
fn environment_override_replaces_only_the_environment() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(
        dir.path(),
        "lit.gltf",
        vec![
            json!({"translation": [0, 2, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}}),
        ],
        lights(json!([{"type": "point"}])),
    );
    let mut s = thinfilm::scene::load(&path, &[]).unwrap();
    let env: EnvironmentSource = "constant:0.2,0.3,0.4".parse().unwrap();
    environment::apply(&mut s, Some(&env), None).unwrap();
    assert_eq!(s.emitters.len(), 2);
    assert!(matches!(s.emitters[0], EmitterDesc::Point { .. }));
    assert!(
        matches!(&s.emitters[1], EmitterDesc::Constant { radiance: SpectrumDesc::Rgb(c) } if *c == [0.2, 0.3, 0.4])
    );
}

/// `--environment-rotation 90` on an XML envmap equals `<rotate y="1" angle="90"/>` there.
#[test]
fn environment_rotation_matches_mitsubas_rotate() {
    let dir = tempfile::tempdir().unwrap();
    let mut img = thinfilm::image_io::RgbImage::new(8, 4);
    img.pixels[3] = [5.0, 1.0, 0.5];
    thinfilm::image_io::write_exr_rgb(&dir.path().join("env.exr"), &img).unwrap();
    let xml = |rot: &str| {
        format!(
            r#"<scene version="3.0.0"><emitter type="envmap"><string name="filename" value="env.exr"/>{rot}</emitter>
               <shape type="sphere"/></scene>"#
        )
    };
    let load = |s: &str| thinfilm::scene::mitsuba::load_str(s, dir.path(), &[], "t.xml").unwrap();
    let want = load(&xml(
        r#"<transform name="to_world"><rotate y="1" angle="90"/></transform>"#,
    ));
    let mut got = load(&xml(""));
    environment::apply(&mut got, None, Some(90.0)).unwrap();
    let m = |s: &Scene| match &s.emitters[0] {
        EmitterDesc::Envmap { to_world, .. } => *to_world,
        _ => panic!("no envmap"),
    };
    assert!(
        m(&got).abs_diff_eq(m(&want), 1e-6),
        "{} vs {}",
        m(&got),
        m(&want)
    );
    // Replacing with a file keeps the rotation.
    let env = EnvironmentSource::File(dir.path().join("env.exr"));
    environment::apply(&mut got, Some(&env), Some(90.0)).unwrap();
    assert!(m(&got).abs_diff_eq(m(&want), 1e-6));
}

#[test]
fn cli_environment_is_seen_directly_and_bad_values_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // A camera at the origin looking up (+Y): the floor is behind it.
    let path = write_gltf(
        dir.path(),
        "sky.gltf",
        vec![json!({"camera": 0, "translation": [0, 1, 0], "rotation": rot_x(90.0)})],
        json!({"cameras": cameras()}),
    );
    let out = dir.path().join("out.exr");
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_thinfilm"))
            .args([
                "render",
                path.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ])
            .args(["--spp", "4", "--resolution", "4x4", "--max-depth", "1"])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run(&["--environment", "constant:0.5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = thinfilm::image_io::read_exr_rgb(&out).unwrap();
    for p in &img.pixels {
        for v in p {
            assert!((v - 0.5).abs() < 0.02, "{p:?}");
        }
    }
    for (args, needle) in [
        (vec!["--environment", "constant:-1"], "--environment"),
        (vec!["--environment", "constant:1,2"], "constant:R,G,B"),
        (
            vec!["--environment-rotation", "abc"],
            "--environment-rotation",
        ),
        (vec!["--environment", "missing.exr"], "missing.exr"),
    ] {
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}

/// Malformed lights, cameras and node graphs: an error naming the file, never a panic
/// (the first case makes the `gltf` crate's `Camera::projection` unwrap a missing object).
#[test]
fn malformed_lights_cameras_and_nodes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let many: Vec<Value> = (0..5000).map(|_| json!({"type": "point"})).collect();
    let cases: Vec<(&str, Vec<Value>, Value)> = vec![
        (
            "ortho_type_without_object",
            vec![json!({"camera": 0})],
            json!({"cameras": [{"type": "orthographic", "perspective": {"yfov": 1, "znear": 0.1}}]}),
        ),
        (
            "ortho_zero_xmag",
            vec![json!({"camera": 0})],
            json!({"cameras": [{"type": "orthographic", "orthographic": {"xmag": 0, "ymag": 1, "znear": 0.1, "zfar": 9}}]}),
        ),
        (
            "light_index_out_of_range",
            vec![json!({"extensions": {"KHR_lights_punctual": {"light": 5}}})],
            lights(json!([{"type": "point"}])),
        ),
        (
            "light_index_without_lights",
            vec![json!({"extensions": {"KHR_lights_punctual": {"light": 0}}})],
            json!({}),
        ),
        (
            "lights_not_an_array",
            vec![],
            json!({"extensions": {"KHR_lights_punctual": {"lights": 3}}}),
        ),
        (
            "unknown_light_type",
            vec![],
            lights(json!([{"type": "area"}])),
        ),
        (
            "nan_like_intensity",
            vec![],
            lights(json!([{"type": "point", "intensity": "bright"}])),
        ),
        (
            "spot_without_spot",
            vec![],
            lights(json!([{"type": "spot"}])),
        ),
        ("too_many_lights", vec![], lights(Value::Array(many))),
        (
            "node_cycle",
            vec![json!({"children": [2]}), json!({"children": [1]})],
            json!({}),
        ),
    ];
    for (name, nodes, top) in cases {
        let path = write_gltf(dir.path(), &format!("{name}.gltf"), nodes, top);
        let err = match thinfilm::scene::load(&path, &[]) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e) => format!("{e:#}"),
        };
        assert!(err.contains(&format!("{name}.gltf")), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
}

/// The floor as a glTF file with a non-reflecting dielectric material (its base colour is
/// the whole reflectance: `KHR_materials_specular` factor 0) seen by the down camera, and,
/// if `color` is given, `COLOR_0` = that linear RGB (float VEC3) on all four vertices.
fn coloured_floor(dir: &Path, name: &str, color: Option<[f32; 3]>) -> PathBuf {
    let plain = write_gltf(
        dir,
        name,
        vec![down_camera(0.0, 0.0)],
        json!({"cameras": cameras(),
               "extensionsUsed": ["KHR_materials_specular"],
               "materials": [{"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
                              "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}}]}),
    );
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(&plain).unwrap()).unwrap();
    doc["meshes"][0]["primitives"][0]["material"] = json!(0);
    if let Some(c) = color {
        let bin: Vec<u8> = (0..4).flat_map(|_| c).flat_map(f32::to_le_bytes).collect();
        let bin_name = format!("{name}.colors.bin");
        std::fs::write(dir.join(&bin_name), &bin).unwrap();
        doc["buffers"]
            .as_array_mut()
            .unwrap()
            .push(json!({"uri": bin_name, "byteLength": 48}));
        doc["bufferViews"]
            .as_array_mut()
            .unwrap()
            .push(json!({"buffer": 1, "byteOffset": 0, "byteLength": 48}));
        doc["accessors"]
            .as_array_mut()
            .unwrap()
            .push(json!({"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"}));
        doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"] = json!(2);
    }
    std::fs::write(&plain, serde_json::to_string(&doc).unwrap()).unwrap();
    plain
}

/// Mean RGB of the floor point under a constant white environment (radiance 1): a Lambert
/// surface reflects its albedo.
fn furnace_radiance(path: &Path) -> [f64; 3] {
    let mut scene: Scene = thinfilm::scene::load(path, &[]).expect("glTF loads");
    scene.emitters = vec![EmitterDesc::Constant {
        radiance: SpectrumDesc::Constant(1.0),
    }];
    mean_rgb(&scene, 64)
}

/// glTF 2.0 §3.9.2: baseColor = baseColorFactor × baseColorTexture × `COLOR_0`. In a white
/// furnace a grey `COLOR_0` of 0.5 halves the floor's radiance and a red one turns it red.
#[test]
fn vertex_colours_multiply_the_base_colour() {
    let dir = tempfile::tempdir().unwrap();
    let white = furnace_radiance(&coloured_floor(dir.path(), "plain.gltf", None));
    let grey = furnace_radiance(&coloured_floor(dir.path(), "grey.gltf", Some([0.5; 3])));
    let red = furnace_radiance(&coloured_floor(
        dir.path(),
        "red.gltf",
        Some([0.8, 0.05, 0.05]),
    ));
    // Relative to the uncoloured floor (a flat spectrum is not RGB (1, 1, 1) on the film).
    let rel = |c: [f64; 3]| [0, 1, 2].map(|k| c[k] / white[k]);
    assert!(white.iter().all(|&w| w > 0.5), "no COLOR_0: {white:?}");
    assert!(
        rel(grey).iter().all(|r| (r - 0.5).abs() < 0.01),
        "COLOR_0 = 0.5 grey: {grey:?} vs {white:?}"
    );
    let r = rel(red);
    assert!(
        r[0] > 0.6 && r[1] < 0.2 && r[2] < 0.2,
        "COLOR_0 red: {red:?} vs {white:?}"
    );
}
