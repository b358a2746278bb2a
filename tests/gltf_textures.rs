//! glTF textures that light and shadows read: per-texel emission (`emissiveTexture`), the
//! `TEXCOORD_n` set a material names, and alpha cut-outs (MASK / BLEND) in shadow rays.
//!
//! - Textured emission: a 2 × 2 quad whose texture is white on its left half and black on
//!   its right is seen directly (radiance = factor × strength on the left, 0 on the right)
//!   and lights a floor exactly as an untextured quad covering only the left half does (the
//!   light-sampled and BSDF-sampled paths read the texel where they land; MIS unchanged).
//! - Alpha in shadow rays: a point light (reached by shadow rays only) lights a floor
//!   through the hole of a MASK quad with the closed-form irradiance, not at all under the
//!   opaque half, and through a BLEND quad of alpha a with (1 − a) of it; an area light
//!   seen through a fully cut-out quad lights the floor as if the quad were absent (so the
//!   light-sampling and BSDF-sampling estimates are not both counted).

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::{EmitterDesc, Scene};

/// glTF document under construction: one binary buffer, meshes of quads.
struct Doc {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
}

impl Doc {
    fn new() -> Self {
        Doc {
            bin: Vec::new(),
            views: Vec::new(),
            accessors: Vec::new(),
            meshes: Vec::new(),
        }
    }

    fn view(&mut self, bytes: Vec<u8>) -> usize {
        let off = self.bin.len();
        self.bin.extend(&bytes);
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        self.views
            .push(json!({"buffer": 0, "byteOffset": off, "byteLength": bytes.len()}));
        self.views.len() - 1
    }

    /// A horizontal quad at height `y` over x ∈ [x0, x1], z ∈ [z0, z1], facing down
    /// (`down`) or up, with UVs u = (x − x0)/(x1 − x0), v = (z − z0)/(z1 − z0); returns
    /// the mesh index.
    fn quad(
        &mut self,
        y: f32,
        [x0, x1]: [f32; 2],
        [z0, z1]: [f32; 2],
        down: bool,
        material: usize,
    ) -> usize {
        let p = [[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]];
        let uv = [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        // (x, z) counter-clockwise seen from +Y is 0, 3, 2 (normal +Y).
        let idx: [u16; 6] = if down {
            [0, 1, 2, 0, 2, 3]
        } else {
            [0, 3, 2, 0, 2, 1]
        };
        let pv = self.view(p.iter().flatten().flat_map(|v| v.to_le_bytes()).collect());
        let uvv = self.view(uv.iter().flatten().flat_map(|v| v.to_le_bytes()).collect());
        let iv = self.view(idx.iter().flat_map(|v| v.to_le_bytes()).collect());
        let a = self.accessors.len();
        self.accessors.push(
            json!({"bufferView": pv, "componentType": 5126, "count": 4, "type": "VEC3",
            "min": [x0, y, z0], "max": [x1, y, z1]}),
        );
        self.accessors
            .push(json!({"bufferView": uvv, "componentType": 5126, "count": 4, "type": "VEC2"}));
        self.accessors
            .push(json!({"bufferView": iv, "componentType": 5123, "count": 6, "type": "SCALAR"}));
        self.meshes.push(
            json!({"primitives": [{"attributes": {"POSITION": a, "TEXCOORD_0": a + 1},
            "indices": a + 2, "material": material}]}),
        );
        self.meshes.len() - 1
    }

    /// Moves the last quad's UVs to `TEXCOORD_1` and gives it a `TEXCOORD_0` that reads the
    /// right half of every texture everywhere.
    fn uvs_to_set_1(&mut self) {
        let uv0: Vec<u8> = [0.75f32, 0.5]
            .repeat(4)
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let uvv = self.view(uv0);
        self.accessors
            .push(json!({"bufferView": uvv, "componentType": 5126, "count": 4, "type": "VEC2"}));
        let a = self.accessors.len() - 1;
        let attrs = &mut self.meshes.last_mut().unwrap()["primitives"][0]["attributes"];
        attrs["TEXCOORD_1"] = attrs["TEXCOORD_0"].clone();
        attrs["TEXCOORD_0"] = json!(a);
    }

    /// Gives the last quad a `TANGENT` accessor of `values` (4 floats per element), declared
    /// as `ty` with `count` elements.
    fn tangents(&mut self, values: &[f32], ty: &str, count: usize) {
        let v = self.view(values.iter().flat_map(|v| v.to_le_bytes()).collect());
        self.accessors
            .push(json!({"bufferView": v, "componentType": 5126, "count": count, "type": ty}));
        let a = self.accessors.len() - 1;
        self.meshes.last_mut().unwrap()["primitives"][0]["attributes"]["TANGENT"] = json!(a);
    }

    /// Writes `name`.gltf (+ .bin) in `dir` with every mesh on a root node, `extra_nodes`
    /// after them and `top` merged into the root.
    fn write(
        self,
        dir: &Path,
        name: &str,
        materials: Value,
        extra_nodes: Vec<Value>,
        top: Value,
    ) -> PathBuf {
        let bin_name = format!("{name}.bin");
        std::fs::write(dir.join(&bin_name), &self.bin).unwrap();
        let mut nodes: Vec<Value> = (0..self.meshes.len()).map(|m| json!({"mesh": m})).collect();
        nodes.extend(extra_nodes);
        let roots: Vec<usize> = (0..nodes.len()).collect();
        let mut doc = json!({
            "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}],
            "nodes": nodes, "meshes": self.meshes, "materials": materials,
            "buffers": [{"uri": bin_name, "byteLength": self.bin.len()}],
            "bufferViews": self.views, "accessors": self.accessors,
        });
        if let Value::Object(m) = top {
            for (k, v) in m {
                doc[k] = v;
            }
        }
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
        path
    }
}

/// A 2 × 1 RGBA PNG `name` in `dir`: left texel `left`, right texel `right`.
fn png(dir: &Path, name: &str, left: [u8; 4], right: [u8; 4]) {
    let img = image::RgbaImage::from_raw(2, 1, [left, right].concat()).unwrap();
    img.save(dir.join(name)).unwrap();
}

/// Textures and images for one PNG, nearest filtering (the halves stay sharp).
fn texture_table(png_name: &str) -> Value {
    json!({
        "samplers": [{"magFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
        "images": [{"uri": png_name}],
        "textures": [{"source": 0, "sampler": 0}],
    })
}

fn merge(mut a: Value, b: Value) -> Value {
    if let (Value::Object(a), Value::Object(b)) = (&mut a, b) {
        a.extend(b);
    }
    a
}

/// A grey diffuse-like glTF floor material (dielectric, rough).
fn floor_material() -> Value {
    json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 1}})
}

/// A camera 0.5 above floor point (x, z) looking straight down with a tiny field.
fn down_camera(x: f32, z: f32) -> Value {
    let h = (-90.0f64).to_radians() / 2.0;
    json!({"camera": 0, "translation": [x, 0.5, z], "rotation": [h.sin(), 0.0, 0.0, h.cos()]})
}

fn narrow_camera() -> Value {
    json!({"cameras": [{"type": "perspective", "perspective": {"yfov": 0.005, "znear": 0.01, "aspectRatio": 1.0}}]})
}

/// Mean RGB of the scene at `path` without its environment.
fn mean_radiance(path: &Path, spp: u32) -> [f64; 3] {
    let mut scene: Scene = thinfilm::scene::load(path, &[]).expect("glTF loads");
    scene
        .emitters
        .retain(|e| !matches!(e, EmitterDesc::Envmap { .. } | EmitterDesc::Constant { .. }));
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(spp),
            resolution: Some((4, 4)),
            seed: Some(3),
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

fn close(what: &str, got: [f64; 3], want: [f64; 3], tol: f64) {
    for c in 0..3 {
        let scale = want[c].abs().max(1e-3);
        assert!(
            ((got[c] - want[c]) / scale).abs() < tol,
            "{what}: channel {c} = {:.5}, expected {:.5}",
            got[c],
            want[c]
        );
    }
}

/// The textured emitter: 2 × 2 at y = 2 facing down, white left half, black right half,
/// emissive factor × strength = (1, 0.5, 0.25) × 3.
fn emitter_material() -> Value {
    json!({"emissiveFactor": [1.0, 0.5, 0.25], "emissiveTexture": {"index": 0},
           "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3}},
           "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0}})
}

#[test]
fn textured_emission_is_read_per_texel() {
    let dir = tempfile::tempdir().unwrap();
    png(dir.path(), "e.png", [255, 255, 255, 255], [0, 0, 0, 255]);
    let look_up = |x: f32| {
        let mut d = Doc::new();
        d.quad(2.0, [-1.0, 1.0], [-1.0, 1.0], true, 0);
        let h = (90.0f64).to_radians() / 2.0;
        let cam = json!({"camera": 0, "translation": [x, 0.5, 0.0], "rotation": [h.sin(), 0.0, 0.0, h.cos()]});
        let top = merge(texture_table("e.png"), narrow_camera());
        let p = d.write(
            dir.path(),
            &format!("up{x}"),
            json!([emitter_material()]),
            vec![cam],
            top,
        );
        mean_radiance(&p, 4)
    };
    // Seen directly: the texel × factor × strength (white: the factor's RGB exactly).
    close("left half", look_up(-0.5), [3.0, 1.5, 0.75], 0.02);
    let right = look_up(0.5);
    assert!(
        right.iter().all(|&v| v.abs() < 1e-4),
        "right half emits {right:?}"
    );
}

/// A material whose textures read `texCoord` 1 gets the mesh's `TEXCOORD_1`: the emitter's
/// left half (white texel by set 1) emits although set 0 points at the black texel.
#[test]
fn textures_read_the_texcoord_set_their_material_names() {
    let dir = tempfile::tempdir().unwrap();
    png(dir.path(), "e.png", [255, 255, 255, 255], [0, 0, 0, 255]);
    let look_up = |set: u32| {
        let mut d = Doc::new();
        d.quad(2.0, [-1.0, 1.0], [-1.0, 1.0], true, 0);
        d.uvs_to_set_1();
        let h = (90.0f64).to_radians() / 2.0;
        let cam = json!({"camera": 0, "translation": [-0.5, 0.5, 0.0], "rotation": [h.sin(), 0.0, 0.0, h.cos()]});
        let top = merge(texture_table("e.png"), narrow_camera());
        let mut m = emitter_material();
        m["emissiveTexture"]["texCoord"] = json!(set);
        let p = d.write(dir.path(), &format!("set{set}"), json!([m]), vec![cam], top);
        mean_radiance(&p, 4)
    };
    close(
        "left half by TEXCOORD_1",
        look_up(1),
        [3.0, 1.5, 0.75],
        0.02,
    );
    let set0 = look_up(0);
    assert!(
        set0.iter().all(|&v| v.abs() < 1e-4),
        "TEXCOORD_0 reads black: {set0:?}"
    );
}

#[test]
fn textured_emission_lights_like_its_untextured_equivalent() {
    let dir = tempfile::tempdir().unwrap();
    png(dir.path(), "e.png", [255, 255, 255, 255], [0, 0, 0, 255]);
    let top = merge(texture_table("e.png"), narrow_camera());
    let floor_at = |textured: bool, x: f32| {
        let mut d = Doc::new();
        d.quad(0.0, [-10.0, 10.0], [-10.0, 10.0], false, 0);
        let mut emitter = emitter_material();
        if textured {
            d.quad(2.0, [-1.0, 1.0], [-1.0, 1.0], true, 1);
        } else {
            // Only the left half, without a texture.
            d.quad(2.0, [-1.0, 0.0], [-1.0, 1.0], true, 1);
            emitter.as_object_mut().unwrap().remove("emissiveTexture");
        }
        let name = format!("floor{textured}{x}");
        let p = d.write(
            dir.path(),
            &name,
            json!([floor_material(), emitter]),
            vec![down_camera(x, 0.0)],
            top.clone(),
        );
        mean_radiance(&p, 256)
    };
    for x in [-0.5f32, 0.8] {
        let (t, u) = (floor_at(true, x), floor_at(false, x));
        assert!(u[0] > 0.05, "the floor at x = {x} is lit: {u:?}");
        close(&format!("floor at x = {x}"), t, u, 0.03);
    }
}

/// A point light of 683 cd (1 W/sr) 2 above the origin and, 1 above the floor, a 2 × 2
/// quad of material `blocker` if given (texture 0: left half alpha 0, right half alpha 1).
fn floor_under_blocker(dir: &Path, name: &str, blocker: Option<Value>, x: f32) -> [f64; 3] {
    let mut d = Doc::new();
    d.quad(0.0, [-10.0, 10.0], [-10.0, 10.0], false, 0);
    if blocker.is_some() {
        d.quad(1.0, [-1.0, 1.0], [-1.0, 1.0], false, 1);
    }
    let blocker = blocker.unwrap_or_else(floor_material);
    let light = json!({"extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 683.0}]}},
                       "extensionsUsed": ["KHR_lights_punctual"]});
    let top = merge(merge(texture_table("a.png"), narrow_camera()), light);
    let lamp = json!({"translation": [0.0, 2.0, 0.0], "extensions": {"KHR_lights_punctual": {"light": 0}}});
    let p = d.write(
        dir,
        name,
        json!([floor_material(), blocker]),
        vec![down_camera(x, 0.0), lamp],
        top,
    );
    mean_radiance(&p, 64)
}

#[test]
fn shadow_rays_pass_mask_holes_and_blend_by_one_minus_alpha() {
    let dir = tempfile::tempdir().unwrap();
    png(
        dir.path(),
        "a.png",
        [255, 255, 255, 0],
        [255, 255, 255, 255],
    );
    // Black (RGB) blockers: little light bounces off their undersides.
    let mask = json!({"alphaMode": "MASK", "doubleSided": true,
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "baseColorTexture": {"index": 0}, "metallicFactor": 0}});
    // The same floor without the blocker: the reference (point light, shadow rays only).
    let open = floor_under_blocker(dir.path(), "open", None, -0.5);
    // Closed form for the grey floor's diffuse part: L = ρ/π · E, E = 1 W/sr · cos θ / d².
    let x = 0.5f64;
    let d2 = 4.0 + x * x;
    let e = (2.0 / d2.sqrt()) / d2;
    assert!(
        open[1] > 0.5 / std::f64::consts::PI * e * 0.8,
        "{open:?} vs E = {e}"
    );
    let hole = floor_under_blocker(dir.path(), "hole", Some(mask.clone()), -0.5);
    close("under the hole", hole, open, 0.03);
    let shade = floor_under_blocker(dir.path(), "shade", Some(mask), 0.5);
    assert!(
        shade.iter().all(|&v| v < 0.05 * open[1]),
        "under the opaque half: {shade:?}"
    );
    let blend = json!({"alphaMode": "BLEND", "doubleSided": true,
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 0.25], "metallicFactor": 0}});
    let through = floor_under_blocker(dir.path(), "blend", Some(blend), 0.5);
    close("through alpha 0.25", through, open.map(|v| 0.75 * v), 0.03);
}

#[test]
fn area_light_through_a_cut_out_is_counted_once() {
    let dir = tempfile::tempdir().unwrap();
    png(dir.path(), "a.png", [255, 255, 255, 0], [255, 255, 255, 0]);
    let top = merge(texture_table("a.png"), narrow_camera());
    let run = |with_blocker: bool| {
        let mut d = Doc::new();
        d.quad(0.0, [-10.0, 10.0], [-10.0, 10.0], false, 0);
        d.quad(2.0, [-1.0, 1.0], [-1.0, 1.0], true, 1);
        if with_blocker {
            d.quad(1.0, [-3.0, 3.0], [-3.0, 3.0], false, 2);
        }
        let emitter = json!({"emissiveFactor": [1, 1, 1],
            "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0}});
        // Fully cut out everywhere (alpha 0 < cutoff).
        let cut = json!({"alphaMode": "MASK", "doubleSided": true,
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0}});
        let name = format!("area{with_blocker}");
        let p = d.write(
            dir.path(),
            &name,
            json!([floor_material(), emitter, cut]),
            vec![down_camera(0.3, 0.2)],
            top.clone(),
        );
        mean_radiance(&p, 256)
    };
    let (without, with) = (run(false), run(true));
    assert!(without[0] > 0.02, "{without:?}");
    close("through a cut-out quad", with, without, 0.03);
}

/// The normal map follows the mesh's `TANGENT` (glTF 2.0 §3.7.2.1: bitangent = w·(n × t)).
/// A diffuse floor (specular 0: ρ/π exactly) with a constant normal-map texel tilted in
/// both tangent-space axes, lit by one directional light, seen straight down: its radiance
/// is ρ/π·E·(n'·l) with n' the texel in the frame (t, w·(n × t), n). A TANGENT along ∂p/∂u
/// renders as without the attribute; one turned 90° in the tangent plane, or with w = −1,
/// changes the radiance by the ratio that frame predicts; malformed ones are refused (wrong
/// type or count) or ignored with a warning (NaN), never a panic.
#[test]
fn normal_maps_follow_the_tangent_attribute() {
    use glam::{Quat, Vec3};
    let dir = tempfile::tempdir().unwrap();
    let texel = [200u8, 170, 220, 255];
    png(dir.path(), "n.png", texel, texel);
    let ts = Vec3::new(
        2.0 * texel[0] as f32 / 255.0 - 1.0,
        2.0 * texel[1] as f32 / 255.0 - 1.0,
        2.0 * texel[2] as f32 / 255.0 - 1.0,
    );
    let l = Vec3::new(1.0, 2.0, 0.7).normalize();
    let q = Quat::from_rotation_arc(Vec3::NEG_Z, -l);
    let light =
        json!({"rotation": q.to_array(), "extensions": {"KHR_lights_punctual": {"light": 0}}});
    let top = merge(
        merge(texture_table("n.png"), narrow_camera()),
        json!({"extensionsUsed": ["KHR_lights_punctual"], "extensions": {"KHR_lights_punctual":
            {"lights": [{"type": "directional", "intensity": 683.0}]}}}),
    );
    let material = json!({"normalTexture": {"index": 0},
        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 1},
        "extensions": {"KHR_materials_specular": {"specularFactor": 0}}});
    let file = |name: &str, tangent: Option<(&[f32], &str, usize)>| {
        let mut d = Doc::new();
        d.quad(0.0, [-1.0, 1.0], [-1.0, 1.0], false, 0);
        if let Some((v, ty, n)) = tangent {
            d.tangents(v, ty, n);
        }
        d.write(
            dir.path(),
            name,
            json!([material.clone()]),
            vec![down_camera(0.0, 0.0), light.clone()],
            top.clone(),
        )
    };
    let four = |t: [f32; 4]| t.repeat(4);
    // Predicted n'·l for tangent t and sign w on the floor (n = +Y).
    let predict = |t: Vec3, w: f32| {
        let n = Vec3::Y;
        let np = (t * ts.x + n.cross(t) * w * ts.y + n * ts.z).normalize();
        np.dot(l) as f64
    };
    let none = mean_radiance(&file("none", None), 4);
    assert!(none[1] > 0.01, "{none:?}");
    let along = four([1.0, 0.0, 0.0, 1.0]);
    let same = mean_radiance(&file("along", Some((&along, "VEC4", 4))), 4);
    close("TANGENT = ∂p/∂u", same, none, 1e-3);
    let cases = [
        ("turned 90°", [0.0f32, 0.0, -1.0, 1.0], Vec3::NEG_Z, 1.0),
        ("w = −1", [1.0, 0.0, 0.0, -1.0], Vec3::X, -1.0),
    ];
    for (what, t, dir_t, w) in cases {
        let tangent = four(t);
        let got = mean_radiance(&file(what, Some((&tangent, "VEC4", 4))), 4);
        let ratio = predict(dir_t, w) / predict(Vec3::X, 1.0);
        eprintln!(
            "{what}: radiance ratio {:.4}, predicted {ratio:.4}",
            got[1] / none[1]
        );
        assert!(
            (ratio - 1.0).abs() > 0.05,
            "{what}: the case does not discriminate"
        );
        close(what, got, none.map(|v| v * ratio), 0.01);
    }
    // Malformed: wrong type or count is an error naming TANGENT; NaN is ignored (∂p/∂u).
    let vec3 = [1.0f32, 0.0, 0.0].repeat(4);
    for (name, v, ty, n) in [
        ("vec3", &vec3[..], "VEC3", 4),
        ("count", &along[..12], "VEC4", 3),
    ] {
        let e = thinfilm::scene::load(&file(name, Some((v, ty, n))), &[]).unwrap_err();
        let e = format!("{e:#}");
        assert!(
            e.contains("TANGENT") && e.contains(&format!("{name}.gltf")),
            "{e}"
        );
    }
    let mut nan = along.clone();
    nan[5] = f32::NAN;
    let got = mean_radiance(&file("nan", Some((&nan, "VEC4", 4))), 4);
    close("NaN TANGENT ignored", got, none, 1e-3);
}
