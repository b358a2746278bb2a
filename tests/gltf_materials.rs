//! glTF materials rendered end to end: white-furnace spheres (a uniform D65 environment of
//! radiance 1) whose mean radiance must equal the material's directional albedo computed from
//! the BSDF itself, per material class; emissive strength; malformed materials; and
//! Khronos' IridescenceSuzanne with assertions on what the reference viewers show.

use glam::Vec3;
use std::path::{Path, PathBuf};
use thinfilm::render::bsdf::{Bsdf, Lobes, ShadingCtx};
use thinfilm::render::sampler::Sampler;
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::{load, look_at, Camera, EmitterDesc, FovAxis, Scene, SpectrumDesc};
use thinfilm::spectrum::SampledWavelengths;

const CAMERA_Z: f32 = 10.0;
const FOV_DEG: f32 = 14.0;
const SIZE: u32 = 40;

/// A UV sphere of radius 1 at the origin (positions = normals) and its index list.
fn sphere() -> (Vec<[f32; 3]>, Vec<u32>) {
    let (rings, segs) = (32u32, 64u32);
    let mut p = Vec::new();
    for i in 0..=rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segs {
            let ph = 2.0 * std::f32::consts::PI * j as f32 / segs as f32;
            p.push([th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()]);
        }
    }
    let mut idx = Vec::new();
    for i in 0..rings {
        for j in 0..segs {
            let a = i * (segs + 1) + j;
            let b = a + segs + 1;
            // Counter-clockwise seen from outside (outward geometric normals).
            idx.extend_from_slice(&[a, a + 1, b, a + 1, b + 1, b]);
        }
    }
    (p, idx)
}

/// A glTF file in `dir` holding the unit sphere with material `material` (JSON).
fn sphere_gltf(dir: &Path, material: &str) -> PathBuf {
    let (p, idx) = sphere();
    let mut bin = Vec::new();
    for v in p.iter().flatten() {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for v in p.iter().flatten() {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let idx_off = bin.len();
    for i in &idx {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("sphere.bin"), &bin).unwrap();
    let n = p.len();
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0, "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2, "material": 0}}]}}],
  "materials": [{material}],
  "buffers": [{{"uri": "sphere.bin", "byteLength": {len}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pl}}},
    {{"buffer": 0, "byteOffset": {pl}, "byteLength": {pl}}},
    {{"buffer": 0, "byteOffset": {idx_off}, "byteLength": {il}}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {n}, "type": "VEC3", "min": [-1,-1,-1], "max": [1,1,1]}},
    {{"bufferView": 1, "componentType": 5126, "count": {n}, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5125, "count": {ni}, "type": "SCALAR"}}]
}}"#,
        len = bin.len(),
        pl = n * 12,
        il = idx.len() * 4,
        ni = idx.len(),
    );
    let path = dir.join("sphere.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

/// The sphere under a uniform D65 environment of radiance 1 (RGB 1, 1, 1), seen from +Z.
fn furnace(material: &str, spp: u32) -> (Scene, thinfilm::image_io::RgbImage) {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = load(&sphere_gltf(dir.path(), material), &[]).unwrap();
    scene.emitters = vec![EmitterDesc::Constant {
        radiance: SpectrumDesc::D65 { scale: 1.0 },
    }];
    scene.camera = Camera {
        to_world: look_at(Vec3::new(0.0, 0.0, CAMERA_Z), Vec3::ZERO, Vec3::Y),
        fov_deg: FOV_DEG,
        fov_axis: FovAxis::X,
        near_clip: 0.1,
        far_clip: 100.0,
        projection: Default::default(),
    };
    let options = RenderOptions {
        spp: Some(spp),
        resolution: Some((SIZE, SIZE)),
        ..Default::default()
    };
    let out = render(&scene, &options).unwrap();
    (scene, out.image)
}

/// cos θ between the view ray of pixel (x, y) and the sphere's normal where it hits, if it
/// hits with cos θ ≥ 0.3 (away from the silhouette, where pixels mix with the background).
fn pixel_cos(x: usize, y: usize) -> Option<f32> {
    let half = (FOV_DEG.to_radians() * 0.5).tan();
    let ndc = |i: usize| ((i as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0) * half;
    let d = Vec3::new(ndc(x), -ndc(y), -1.0).normalize();
    let o = Vec3::new(0.0, 0.0, CAMERA_Z);
    let b = o.dot(d);
    let disc = b * b - (o.length_squared() - 1.0);
    if disc <= 0.0 {
        return None;
    }
    let n = (o + d * (-b - disc.sqrt())).normalize();
    let c = -d.dot(n);
    (c >= 0.3).then_some(c)
}

/// The directional albedo of the opaque `bsdf` from cos θ = `c` at wavelengths `lambda`
/// (a convex sphere in a uniform environment: every reflected path leaves to the
/// environment, so the pixel's radiance is this albedo).
fn albedo(bsdf: &Bsdf, c: f32, lambda: [f32; 4], n: u32) -> [f32; 4] {
    let wl = SampledWavelengths::new(lambda, [1.0; 4]);
    let ctx = ShadingCtx {
        wl: &wl,
        uv: glam::Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    let wi = Vec3::new((1.0 - c * c).max(0.0).sqrt(), 0.0, c);
    let mut s = Sampler::from_seed(3);
    let mut sum = glam::Vec4::ZERO;
    for _ in 0..n {
        if let Some(smp) = bsdf.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) {
            sum += smp.weight;
        }
    }
    (sum / n as f32).to_array()
}

/// Linear sRGB of the reflectance spectrum `f(λ)` under D65 (white = 1, 1, 1).
fn srgb_of(f: impl Fn(f64) -> f64) -> [f64; 3] {
    let [x, y, z] = thinfilm::spectrum::reflectance_xyz_d65(f);
    [
        3.2404542 * x - 1.5371385 * y - 0.4985314 * z,
        -0.969266 * x + 1.8760108 * y + 0.041556 * z,
        0.0556434 * x - 0.2040259 * y + 1.0572252 * z,
    ]
}

/// Mean rendered RGB over the sphere's pixels (cos θ ≥ 0.3) and the mean expected RGB there:
/// the BSDF's directional albedo spectrum at each pixel's angle, as linear sRGB.
fn measured_and_expected(material: &str) -> ([f64; 3], [f64; 3]) {
    let (scene, img) = furnace(material, 256);
    let bsdf = &scene.bsdfs[scene.shapes[0].bsdf];
    // Albedo table over cos θ (12 bins) and λ (400–700 nm, 10 nm).
    let lambdas: Vec<f32> = (0..32).map(|i| 400.0 + 10.0 * i as f32).collect();
    let cos_bins: Vec<f32> = (0..12)
        .map(|i| 0.3 + 0.7 * (i as f32 + 0.5) / 12.0)
        .collect();
    let table: Vec<[f64; 3]> = cos_bins
        .iter()
        .map(|&c| {
            let mut a = Vec::new();
            for ch in lambdas.chunks(4) {
                a.extend_from_slice(&albedo(bsdf, c, [ch[0], ch[1], ch[2], ch[3]], 20_000));
            }
            srgb_of(|l| {
                let t = ((l as f32 - 400.0) / 10.0).clamp(0.0, 30.999);
                let i = t as usize;
                (a[i] + (a[i + 1] - a[i]) * (t - i as f32)) as f64
            })
        })
        .collect();
    let (mut got, mut want, mut n) = ([0.0f64; 3], [0.0f64; 3], 0.0);
    for y in 0..SIZE as usize {
        for x in 0..SIZE as usize {
            let Some(c) = pixel_cos(x, y) else { continue };
            let bin = (((c - 0.3) / 0.7 * 12.0) as usize).min(11);
            let px = img.pixels[y * SIZE as usize + x];
            for k in 0..3 {
                got[k] += px[k] as f64;
                want[k] += table[bin][k];
            }
            n += 1.0;
        }
    }
    assert!(n > 100.0, "{n} sphere pixels");
    (got.map(|v| v / n), want.map(|v| v / n))
}

fn luminance(c: [f64; 3]) -> f64 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

const GREY_DIELECTRIC: &str = r#"{"name": "grey",
  "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 0.4}}"#;

#[test]
fn furnace_grey_dielectric_and_under_a_film() {
    let (got, want) = measured_and_expected(GREY_DIELECTRIC);
    let r = luminance(got) / luminance(want);
    eprintln!("grey dielectric: rendered {got:?} albedo {want:?} ratio {r:.4}");
    assert!((r - 1.0).abs() < 0.12, "ratio {r}");
    let film = r#"{"name": "film",
      "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 0.4},
      "extensions": {"KHR_materials_iridescence": {"iridescenceFactor": 1, "iridescenceIor": 1.33,
                     "iridescenceThicknessMaximum": 400}}}"#;
    let (got_f, want_f) = measured_and_expected(film);
    let r = luminance(got_f) / luminance(want_f);
    eprintln!("film on dielectric: rendered {got_f:?} albedo {want_f:?} ratio {r:.4}");
    assert!((r - 1.0).abs() < 0.12, "ratio {r}");
    // The base is kept: the diffuse base still dominates (within 25 % of the bare one).
    assert!((luminance(got_f) / luminance(got) - 1.0).abs() < 0.25);
}

#[test]
fn furnace_coloured_metal_keeps_its_hue_and_film_on_metal() {
    let gold = r#"{"name": "gold",
      "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1], "metallicFactor": 1, "roughnessFactor": 0.3}}"#;
    let (got, want) = measured_and_expected(gold);
    let r = luminance(got) / luminance(want);
    eprintln!("gold metal: rendered {got:?} albedo {want:?} ratio {r:.4}");
    assert!((r - 1.0).abs() < 0.12, "ratio {r}");
    for k in [0, 2] {
        let (a, b) = (got[k] / got[1], want[k] / want[1]);
        assert!((a - b).abs() < 0.08, "channel {k}/G: {a} vs {b}");
    }
    // Hue: red > green > blue, as the base colour.
    assert!(got[0] > got[1] && got[1] > got[2], "{got:?}");
    let film = r#"{"name": "filmed gold",
      "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1], "metallicFactor": 1, "roughnessFactor": 0.3},
      "extensions": {"KHR_materials_iridescence": {"iridescenceFactor": 1, "iridescenceIor": 1.5,
                     "iridescenceThicknessMaximum": 300}}}"#;
    let (got_f, want_f) = measured_and_expected(film);
    let r = luminance(got_f) / luminance(want_f);
    eprintln!("film on metal: rendered {got_f:?} albedo {want_f:?} ratio {r:.4}");
    assert!((r - 1.0).abs() < 0.12, "ratio {r}");
    // The film changes the colour.
    let hue = |c: [f64; 3]| c[2] / c[0];
    assert!((hue(got_f) - hue(got)).abs() > 0.05, "{got_f:?} vs {got:?}");
    // With KHR_materials_specular the film sits on the metal's complex index with that
    // colour as edge tint: the furnace still reads the BSDF's own albedo.
    let tinted = r#"{"name": "filmed tinted gold",
      "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1], "metallicFactor": 1, "roughnessFactor": 0.3},
      "extensions": {"KHR_materials_iridescence": {"iridescenceFactor": 1, "iridescenceIor": 1.5,
                     "iridescenceThicknessMaximum": 300},
                     "KHR_materials_specular": {"specularColorFactor": [1.0, 0.6, 0.3]}}}"#;
    let (got_t, want_t) = measured_and_expected(tinted);
    let r = luminance(got_t) / luminance(want_t);
    eprintln!("film on tinted metal: rendered {got_t:?} albedo {want_t:?} ratio {r:.4}");
    assert!((r - 1.0).abs() < 0.12, "ratio {r}");
}

/// Lossless glass (smooth, with a volume) in a white furnace is invisible: radiance 1, with
/// and without a film; rough (roughness 0.5) too, with the energy compensation of its
/// refraction lobe.
#[test]
fn furnace_lossless_glass_with_and_without_a_film() {
    for (ext, roughness) in [
        ("", 0.0),
        (
            r#", "KHR_materials_iridescence": {"iridescenceFactor": 1, "iridescenceIor": 1.8, "iridescenceThicknessMaximum": 350}"#,
            0.0,
        ),
        ("", 0.5),
    ] {
        let m = format!(
            r#"{{"name": "glass",
              "pbrMetallicRoughness": {{"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": {roughness}}},
              "extensions": {{"KHR_materials_transmission": {{"transmissionFactor": 1}},
                             "KHR_materials_volume": {{"thicknessFactor": 1}}{ext}}}}}"#
        );
        let (_, img) = furnace(&m, 64);
        let (mut sum, mut n) = ([0.0f64; 3], 0.0);
        for y in 0..SIZE as usize {
            for x in 0..SIZE as usize {
                if pixel_cos(x, y).is_some() {
                    let p = img.pixels[y * SIZE as usize + x];
                    for k in 0..3 {
                        sum[k] += p[k] as f64;
                    }
                    n += 1.0;
                }
            }
        }
        let mean = sum.map(|v| v / n);
        eprintln!(
            "glass{} roughness {roughness}: mean {mean:?}",
            if ext.is_empty() { "" } else { " + film" }
        );
        for v in mean {
            assert!((v - 1.0).abs() < 0.03, "{mean:?}");
        }
    }
}

#[test]
fn emissive_strength_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let m = r#"{"name": "lamp", "emissiveFactor": [0.5, 0.25, 0.1],
      "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0, "roughnessFactor": 1},
      "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}}"#;
    let mut scene = load(&sphere_gltf(dir.path(), m), &[]).unwrap();
    scene.emitters.clear();
    scene.camera = Camera {
        to_world: look_at(Vec3::new(0.0, 0.0, CAMERA_Z), Vec3::ZERO, Vec3::Y),
        fov_deg: FOV_DEG,
        fov_axis: FovAxis::X,
        near_clip: 0.1,
        far_clip: 100.0,
        projection: Default::default(),
    };
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(16),
            resolution: Some((SIZE, SIZE)),
            ..Default::default()
        },
    )
    .unwrap();
    let c = (SIZE / 2) as usize;
    let p = out.image.pixels[c * SIZE as usize + c];
    for (k, want) in [2.0f32, 1.0, 0.4].into_iter().enumerate() {
        assert!((p[k] / want - 1.0).abs() < 0.06, "{p:?}");
    }
}

#[test]
fn malformed_materials_name_file_material_and_key() {
    for (material, key) in [
        (
            r#"{"name": "bad", "pbrMetallicRoughness": {"metallicFactor": 0},
               "extensions": {"KHR_materials_iridescence": {"iridescenceFactor": "lots"}}}"#,
            "iridescenceFactor",
        ),
        (
            r#"{"name": "bad", "pbrMetallicRoughness": {"metallicFactor": 0},
               "extensions": {"KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": -2}}}"#,
            "attenuationDistance",
        ),
        (
            r#"{"name": "bad", "pbrMetallicRoughness": {"metallicFactor": 0},
               "extensions": {"KHR_materials_iridescence": {"iridescenceFactor": 1,
                 "iridescenceThicknessTexture": {"index": 7}}}}"#,
            "iridescenceThicknessTexture",
        ),
        (
            r#"{"name": "bad", "pbrMetallicRoughness": {"metallicFactor": 0},
               "extensions": {"KHR_materials_specular": {"specularColorFactor": [1, 2]}}}"#,
            "specularColorFactor",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let e = format!(
            "{:#}",
            load(&sphere_gltf(dir.path(), material), &[]).unwrap_err()
        );
        assert!(e.contains("sphere.gltf"), "{e}");
        // The material by name (our reader) or by index (the file check before it).
        assert!(e.contains("\"bad\"") || e.contains("materials[0]"), "{e}");
        assert!(e.contains(key), "{e}");
    }
}

/// Khronos' IridescenceSuzanne seen from the front (the golden images' view), background
/// hidden: per Suzanne (the left, centre and right thirds
/// of the image, object pixels = the non-zero ones) the mean colour and the mean per-pixel
/// chroma (max − min)/max. `max_depth` limits the path; `centre_film` = false removes the
/// centre Suzanne's film (iridescenceFactor 0), lit as `light` says.
/// How the Suzanne test scene is lit.
#[derive(Clone, Copy)]
enum Light {
    /// As loaded: the file's directional light and the default neutral studio.
    Default,
    /// A uniform white environment only.
    White,
    /// One white directional light from above the camera, no environment.
    Sun,
}

fn suzanne_thirds(max_depth: i32, centre_film: bool, light: Light) -> [([f64; 3], f64); 3] {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/gltf/IridescenceSuzanne");
    let dir = tempfile::tempdir().unwrap();
    for f in ["IridescenceSuzanne.bin", "noise.png"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    let text = std::fs::read_to_string(src.join("IridescenceSuzanne.gltf")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    if !centre_film {
        json["materials"][1]["extensions"]["KHR_materials_iridescence"]["iridescenceFactor"] =
            0.0.into();
    }
    let path = dir.path().join("suzanne.gltf");
    std::fs::write(&path, json.to_string()).unwrap();
    let mut scene = load(&path, &[]).unwrap();
    // The three heads side by side (x = −3, 0, 3), seen from the front as the sample's
    // golden images show them; the file has no camera, and the default framing (model-viewer's)
    // leaves margins too wide for a 150-pixel test image.
    scene.camera = Camera {
        to_world: look_at(Vec3::new(0.0, 0.5, 10.0), Vec3::ZERO, Vec3::Y),
        fov_deg: 52.0,
        fov_axis: FovAxis::X,
        near_clip: 0.1,
        far_clip: 100.0,
        projection: Default::default(),
    };
    scene.integrator.hide_emitters = true;
    scene.integrator.max_depth = max_depth;
    match light {
        Light::Default => {}
        Light::White => {
            scene.emitters = vec![EmitterDesc::Constant {
                radiance: SpectrumDesc::D65 { scale: 1.0 },
            }]
        }
        Light::Sun => {
            scene.emitters = vec![EmitterDesc::Directional {
                direction: Vec3::new(0.3, -0.5, -1.0).normalize(),
                irradiance: SpectrumDesc::D65 { scale: 1.0 },
            }]
        }
    }
    let (w, h) = (150usize, 60usize);
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(64),
            resolution: Some((w as u32, h as u32)),
            ..Default::default()
        },
    )
    .unwrap();
    std::array::from_fn(|third| {
        let (mut sum, mut chroma, mut n) = ([0.0f64; 3], 0.0, 0.0);
        for y in 0..h {
            for x in third * w / 3..(third + 1) * w / 3 {
                let p = out.image.pixels[y * w + x].map(|v| v as f64);
                let mx = p[0].max(p[1]).max(p[2]);
                if mx > 0.0 {
                    for k in 0..3 {
                        sum[k] += p[k];
                    }
                    chroma += (mx - p[0].min(p[1]).min(p[2])) / mx;
                    n += 1.0;
                }
            }
        }
        assert!(n > 50.0, "third {third}: {n} object pixels");
        (sum.map(|v| v / n), chroma / n)
    })
}

#[test]
fn iridescence_suzanne_looks_like_the_reference_viewers() {
    let [(left, _), (centre, _), (right, _)] = suzanne_thirds(-1, true, Light::Default);
    eprintln!(
        "Suzanne luminance L/C/R: {:.3} {:.3} {:.3}",
        luminance(left),
        luminance(centre),
        luminance(right),
    );
    // Left: a dielectric with a diffuse grey base under the film; centre: a metal. Lit by one
    // directional light and no environment, the diffuse base scatters it everywhere while
    // the smooth metal (roughness 0.1) shows it only as a small highlight. (In the near-uniform
    // studio the two have about the same albedo, 0.4, and similar brightness.)
    let [(left_sun, _), (centre_sun, _), _] = suzanne_thirds(-1, true, Light::Sun);
    eprintln!(
        "one sun, luminance L/C: {:.3} {:.3}",
        luminance(left_sun),
        luminance(centre_sun)
    );
    assert!(
        luminance(left_sun) > 1.3 * luminance(centre_sun),
        "{left_sun:?} vs {centre_sun:?}"
    );
    // Centre: its reflection is coloured by the film — in a white environment the same grey
    // metal without its film is neutral (up to colour noise).
    let [_, (_, centre_chroma), _] = suzanne_thirds(-1, true, Light::White);
    let [_, (_, grey_chroma), _] = suzanne_thirds(-1, false, Light::White);
    eprintln!("centre chroma with film {centre_chroma:.3}, without {grey_chroma:.3}");
    assert!(
        centre_chroma > 2.0 * grey_chroma,
        "{centre_chroma} vs {grey_chroma}"
    );
    // Right: transmissive — one bounce shows only its surface reflection; light through it
    // needs longer paths, and brings the background with it.
    let [(left1, _), _, (right1, _)] = suzanne_thirds(2, true, Light::Default);
    let through = luminance(right) / luminance(right1);
    let opaque = luminance(left) / luminance(left1);
    eprintln!("full/one-bounce luminance: right {through:.2}, left {opaque:.2}");
    assert!(
        through > 2.0 && through > 1.5 * opaque,
        "{through} vs {opaque}"
    );
}
