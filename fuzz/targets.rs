//! Fuzz targets: one per input format thinfilm reads, each running the loader the command
//! line uses on arbitrary bytes. Shared by the in-process fuzz test (`tests/fuzz.rs`, run by
//! `cargo test`) and the AFL++ harness (`fuzz/src/main.rs`, see `fuzz/README.md`).
//!
//! A loader may refuse its input with an error — that is the expected outcome for garbage.
//! What counts as a finding: a panic, an error that reports a contained panic
//! ([`thinfilm::limits::CONTAINED_PANIC`]), a hang or runaway memory. An input a loader
//! accepts is rendered (4×4 pixels, 1 sample) or fitted, so that accepted values are also
//! checked for what they do downstream.

// Each user of this file compiles only the functions it calls.
#![allow(dead_code)]

use std::path::Path;
use thinfilm::capture::envi::{self, WriteOptions};
use thinfilm::render::RenderOptions;

/// The formats the fuzzers feed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// An ENVI header (the binary beside it is valid and long).
    EnviHeader,
    /// An ENVI binary (the header beside it is valid).
    EnviCube,
    /// A `capture.json` whose cubes are valid.
    CaptureJson,
    /// A Mitsuba XML scene (meshes and textures beside it are valid).
    MitsubaXml,
    Ply,
    Obj,
    /// A `.gltf` JSON file.
    Gltf,
    /// A binary `.glb` file.
    Glb,
    /// An EXR texture / image.
    Exr,
    /// A Mitsuba `.serialized` mesh: the input is its version (`u16`) and its uncompressed
    /// stream, which the target compresses into a file (the corrupt-container cases are in the
    /// hostile corpus; mutating the stream itself reaches the parser).
    Serialized,
    /// A file a scene `<include>`s (it may include `leaf.xml`, or itself).
    Include,
    /// An integer-format bitmap texture: JPEG, BMP, TGA or PPM (by its magic bytes).
    Image,
    /// A render piece or a fitted thickness tile (an EXR with provenance attributes), merged
    /// by `thinfilm merge` with a valid companion piece.
    Provenance,
}

pub const ALL: [Target; 13] = [
    Target::EnviHeader,
    Target::EnviCube,
    Target::CaptureJson,
    Target::MitsubaXml,
    Target::Ply,
    Target::Obj,
    Target::Gltf,
    Target::Glb,
    Target::Exr,
    Target::Serialized,
    Target::Include,
    Target::Image,
    Target::Provenance,
];

impl Target {
    /// The target's name on the command line of the AFL harness.
    pub fn name(self) -> &'static str {
        match self {
            Target::EnviHeader => "envi-header",
            Target::EnviCube => "envi-cube",
            Target::CaptureJson => "capture",
            Target::MitsubaXml => "xml",
            Target::Ply => "ply",
            Target::Obj => "obj",
            Target::Gltf => "gltf",
            Target::Glb => "glb",
            Target::Exr => "exr",
            Target::Serialized => "serialized",
            Target::Include => "include",
            Target::Image => "image",
            Target::Provenance => "provenance",
        }
    }

    pub fn from_name(name: &str) -> Option<Target> {
        ALL.into_iter().find(|t| t.name() == name)
    }
}

const BANDS: usize = 8;
const WAVELENGTHS: [f64; BANDS] = [400.0, 440.0, 480.0, 520.0, 560.0, 600.0, 640.0, 680.0];

fn cube_options() -> WriteOptions {
    let mut o = WriteOptions::new(4, 3, BANDS);
    o.wavelengths_nm = Some(WAVELENGTHS.to_vec());
    o.fwhm_nm = Some(vec![4.0; BANDS]);
    o
}

fn cube_values(seed: usize) -> Vec<f32> {
    (0..4 * 3 * BANDS)
        .map(|i| 0.05 + 0.25 * (((i * 7 + seed * 13) % 29) as f32 / 29.0))
        .collect()
}

const OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n\
vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 2/2/1 4/4/1 3/3/1\n";

/// Writes the valid files the inputs may refer to into `dir`: three cubes (`c10`, `c30`,
/// `c50`), a PLY and an OBJ mesh, an EXR and a PNG texture.
pub fn prepare_assets(dir: &Path) -> anyhow::Result<()> {
    for (i, a) in [10, 30, 50].into_iter().enumerate() {
        envi::write_cube(
            &dir.join(format!("c{a}.hdr")),
            &cube_values(i),
            &cube_options(),
        )?;
    }
    std::fs::write(dir.join("mesh.obj"), OBJ)?;
    let mesh = thinfilm::scene::meshio::load_obj(&dir.join("mesh.obj"))?;
    thinfilm::scene::meshio::write_ply_binary(&dir.join("mesh.ply"), &mesh)?;
    let plane: Vec<f32> = (0..16).map(|i| 100.0 + 10.0 * i as f32).collect();
    thinfilm::image_io::write_exr_channels(
        &dir.join("tex.exr"),
        4,
        4,
        &[("R", &plane), ("G", &plane), ("B", &plane)],
    )?;
    thinfilm::image_io::write_png_rgb8(&dir.join("tex.png"), 2, 2, vec![200; 12])?;
    std::fs::write(
        dir.join("leaf.xml"),
        r#"<scene version="3.0.0"><shape type="sphere"><float name="radius" value="0.5"/></shape></scene>"#,
    )?;
    let pixels: Vec<[f32; 3]> = (0..16).map(|i| [0.1 * (i % 4) as f32, 0.5, 1.0]).collect();
    let image = thinfilm::image_io::RgbImage {
        width: 4,
        height: 4,
        pixels,
    };
    // Two pieces of a render and two row tiles of a fit: `_a` is mutated, `_b` its companion.
    for (name, range, rows) in [("a", (0, 16), (0, 2)), ("b", (16, 32), (2, 4))] {
        let piece = dir.join(format!("piece_{name}.exr"));
        thinfilm::render::provenance::write_exr(&piece, &image, None, &render_info(range))?;
        thinfilm::image_io::write_exr_channels_with_attributes(
            &dir.join(format!("tile_{name}.exr")),
            4,
            2,
            &[("Y", &[400.0f32; 8])],
            &tile_info(rows).attributes(),
        )?;
    }
    Ok(())
}

fn render_info(sample_range: (u32, u32)) -> thinfilm::render::provenance::RenderInfo {
    thinfilm::render::provenance::RenderInfo {
        sample_range,
        requested_range: sample_range,
        seed: 7,
        sampler: "independent".into(),
        filter: "box".into(),
        adaptive: false,
        image_hash: 0xdead_beef,
        version: "0".into(),
    }
}

fn tile_info(rows: (usize, usize)) -> thinfilm::estimate::tiles::TileInfo {
    thinfilm::estimate::tiles::TileInfo {
        rows,
        image_height: 4,
        fit_hash: 0xdead_beef,
        film_ior: 1.33,
        version: "0".into(),
    }
}

/// A `.serialized` mesh stream: `flags`, the counts and the records of two triangles
/// (versions 3/4: positions, normals and uvs as f32; version 5: 8-float vertex records).
fn serialized_stream(version: u16) -> Vec<u8> {
    let mut b = version.to_le_bytes().to_vec();
    let positions = [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]];
    let uvs = [[0f32, 0.], [1., 0.], [0., 1.], [1., 1.]];
    let f32s = |b: &mut Vec<u8>, v: &[f32]| v.iter().for_each(|x| b.extend(x.to_le_bytes()));
    if version == 5 {
        b.extend((0x1000u32 | 0x1 | 0x4).to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend(b"quad");
        [4u64, 2, 0, 0]
            .iter()
            .for_each(|n| b.extend(n.to_le_bytes()));
        for (p, uv) in positions.iter().zip(&uvs) {
            f32s(&mut b, p);
            f32s(&mut b, &[0., 0., 1.]);
            f32s(&mut b, uv);
        }
        [0u32, 1, 2, 0, 1, 3, 2, 0]
            .iter()
            .for_each(|i| b.extend(i.to_le_bytes()));
        b.extend(0u32.to_le_bytes()); // no custom attributes
    } else {
        b.extend((0x1000u32 | 0x1 | 0x2).to_le_bytes());
        if version == 4 {
            b.extend(b"quad\0");
        }
        [4u64, 2].iter().for_each(|n| b.extend(n.to_le_bytes()));
        positions.iter().for_each(|p| f32s(&mut b, p));
        positions.iter().for_each(|_| f32s(&mut b, &[0., 0., 1.]));
        uvs.iter().for_each(|uv| f32s(&mut b, uv));
        [0u32, 1, 2, 1, 3, 2]
            .iter()
            .for_each(|i| b.extend(i.to_le_bytes()));
    }
    b
}

/// A `.serialized` file of one mesh from a [`Target::Serialized`] input.
fn serialized_file(input: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let (version, stream) = input.split_at(input.len().min(2));
    let mut out = vec![0x1C, 0x04];
    out.extend(version);
    out.resize(4, 0);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    let _ = z.write_all(stream);
    out.extend(z.finish().unwrap_or_default());
    let v3 = version.first() == Some(&3);
    if v3 {
        out.extend(0u32.to_le_bytes());
    } else {
        out.extend(0u64.to_le_bytes());
    }
    out.extend(1u32.to_le_bytes());
    out
}

/// Tiny JPEG, BMP, TGA and PPM images.
fn integer_images() -> Vec<Vec<u8>> {
    use image::ImageFormat::{Bmp, Jpeg, Pnm, Tga};
    let img = image::RgbImage::from_fn(5, 3, |x, y| image::Rgb([40 * x as u8, 80 * y as u8, 100]));
    [Jpeg, Bmp, Tga, Pnm]
        .into_iter()
        .map(|f| {
            let mut out = Vec::new();
            img.write_to(&mut std::io::Cursor::new(&mut out), f)
                .expect("encoding a seed image");
            out
        })
        .collect()
}

/// The file extension of an integer-format image, from its magic bytes.
fn image_extension(data: &[u8]) -> &'static str {
    match data {
        [0xFF, 0xD8, ..] => "jpg",
        [b'B', b'M', ..] => "bmp",
        [b'P', ..] => "ppm",
        _ => "tga",
    }
}

/// Valid inputs of each format to start mutating from (files of `prepare_assets` in `dir`).
pub fn seeds(target: Target, dir: &Path) -> Vec<Vec<u8>> {
    let capture = |angles: &[(f64, &str)]| {
        let list: Vec<String> = angles
            .iter()
            .map(|(a, c)| format!("{{\"incident_deg\": {a}, \"cube\": \"{c}\"}}"))
            .collect();
        format!(
            "{{\"format\": \"thinfilm-capture/1\", \"polarization\": \"s\", \"ambient_ior\": 1.0,\n\
             \"substrate\": {{\"ior\": 1.64, \"k\": 0}},\n\"angles\": [{}]}}\n",
            list.join(",\n")
        )
    };
    match target {
        Target::EnviHeader => vec![
            envi::header_text(&cube_options()).into_bytes(),
            std::fs::read(dir.join("c10.hdr")).unwrap_or_default(),
        ],
        Target::EnviCube => vec![std::fs::read(dir.join("c10.img")).unwrap_or_default()],
        Target::CaptureJson => vec![
            capture(&[(10.0, "c10.hdr"), (30.0, "c30.hdr"), (50.0, "c50.hdr")]).into_bytes(),
            capture(&[(10.0, "c10.hdr")]).into_bytes(),
        ],
        Target::MitsubaXml => XML_SEEDS.iter().map(|s| s.as_bytes().to_vec()).collect(),
        Target::Ply => vec![
            std::fs::read(dir.join("mesh.ply")).unwrap_or_default(),
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
property float z\nproperty float u\nproperty float v\nelement face 1\n\
property list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n"
                .to_vec(),
        ],
        Target::Obj => vec![OBJ.as_bytes().to_vec()],
        Target::Gltf => vec![gltf_json(true).into_bytes()],
        Target::Glb => vec![glb()],
        Target::Exr => vec![std::fs::read(dir.join("tex.exr")).unwrap_or_default()],
        Target::Serialized => [3, 4, 5].map(serialized_stream).to_vec(),
        Target::Include => vec![
            br#"<scene version="3.0.0"><include filename="leaf.xml"/>
<bsdf type="thinfilm" id="f"><float name="thickness" value="300"/></bsdf>
<shape type="rectangle"><ref id="f"/><transform name="to_world"><translate z="-1"/></transform></shape>
</scene>"#
                .to_vec(),
            br#"<scene version="3.0.0"><bsdf type="diffuse" id="d"><rgb name="reflectance" value="0.5"/></bsdf>
<shape type="disk"><ref id="d"/></shape><include filename="leaf.xml"/></scene>"#
                .to_vec(),
        ],
        Target::Image => integer_images(),
        Target::Provenance => vec![
            std::fs::read(dir.join("piece_a.exr")).unwrap_or_default(),
            std::fs::read(dir.join("tile_a.exr")).unwrap_or_default(),
        ],
    }
}

const XML_SEEDS: [&str; 3] = [
    r#"<scene version="3.0.0">
  <default name="res" value="4"/>
  <sensor type="perspective">
    <float name="fov" value="40"/><string name="polarizer" value="30deg"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="1"/></sampler>
    <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>
      <rfilter type="gaussian"><float name="stddev" value="0.5"/></rfilter></film>
  </sensor>
  <emitter type="envmap"><string name="filename" value="tex.exr"/><float name="scale" value="1"/></emitter>
  <bsdf type="thinfilm" id="film">
    <float name="film_ior" value="1.37"/><float name="thickness" value="400"/>
    <float name="substrate_ior" value="1.64"/><float name="alpha" value="0.1"/>
  </bsdf>
  <shape type="sphere"><point name="center" x="0" y="0" z="0"/><float name="radius" value="1"/><ref id="film"/></shape>
  <shape type="obj"><string name="filename" value="mesh.obj"/>
    <transform name="to_world"><scale value="2"/><rotate y="1" angle="30"/><translate x="0.5" y="0" z="1"/></transform>
    <bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.2"/>
      <string name="distribution" value="ggx"/></bsdf>
  </shape>
</scene>"#,
    r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="6"/></integrator>
  <emitter type="constant"><rgb name="radiance" value="0.5, 0.6, 0.7"/></emitter>
  <shape type="ply"><string name="filename" value="mesh.ply"/>
    <bsdf type="thinfilm"><texture type="bitmap" name="thickness"><string name="filename" value="tex.exr"/>
      <string name="wrap_mode" value="clamp"/></texture><string name="substrate_ior" value="BK7"/></bsdf>
  </shape>
  <shape type="rectangle"><transform name="to_world"><matrix value="1 0 0 0 0 1 0 0 0 0 1 -1 0 0 0 1"/></transform>
    <bsdf type="plastic"><texture type="checkerboard" name="diffuse_reflectance"><rgb name="color0" value="0.8"/>
      <rgb name="color1" value="0.1, 0.2, 0.3"/></texture></bsdf>
    <emitter type="area"><spectrum name="radiance" value="400:1, 700:2"/></emitter>
  </shape>
</scene>"#,
    r#"<scene version="3.0.0">
  <sensor type="perspective"><string name="focal_length" value="35mm"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="3"/></film></sensor>
  <emitter type="point"><point name="position" x="1" y="2" z="3"/><spectrum name="intensity" type="d65"><float name="scale" value="2"/></spectrum></emitter>
  <shape type="cube"><bsdf type="twosided"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">
    <string name="filename" value="tex.png"/></texture></bsdf></bsdf></shape>
  <shape type="disk"><bsdf type="thinfilm"><string name="layers" value="(TiO2:52, SiO2:94)x3, MgF2:100"/></bsdf></shape>
  <shape type="sphere"><float name="radius" value="0.3"/><bsdf type="thinfilm_bubble"><float name="thickness" value="500"/></bsdf></shape>
  <shape type="sphere"><float name="radius" value="0.2"/><bsdf type="coateddielectric"><string name="coating" value="MgF2:99.6"/></bsdf></shape>
</scene>"#,
];

/// A triangle with normals, uvs, an index buffer, a material with an iridescence texture, a
/// camera and a two-node hierarchy; buffers inline (`inline_buffer`) or in a GLB chunk.
fn gltf_json(inline_buffer: bool) -> String {
    let bin = gltf_bin();
    let buffer = if inline_buffer {
        let b64 = base64_encode(&bin);
        format!(
            "{{\"byteLength\": {}, \"uri\": \"data:application/octet-stream;base64,{b64}\"}}",
            bin.len()
        )
    } else {
        format!("{{\"byteLength\": {}}}", bin.len())
    };
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0, 2]}}],
"nodes": [{{"children": [1], "translation": [0, 0, -1]}}, {{"mesh": 0, "scale": [1, 2, 1], "rotation": [0, 0, 0, 1]}},
 {{"camera": 0, "translation": [0.3, 0.3, 4]}}],
"cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.8, "znear": 0.1, "zfar": 100, "aspectRatio": 1.0}}}}],
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}, "indices": 3, "material": 0}}]}}],
"materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [0.8, 0.7, 0.6, 1], "roughnessFactor": 0.3}},
 "extensions": {{"KHR_materials_iridescence": {{"iridescenceFactor": 1, "iridescenceIor": 1.4,
  "iridescenceThicknessMinimum": 100, "iridescenceThicknessMaximum": 600, "iridescenceThicknessTexture": {{"index": 0}}}},
  "KHR_materials_ior": {{"ior": 1.5}}}}}}],
"textures": [{{"source": 0, "sampler": 0}}], "samplers": [{{"magFilter": 9729, "wrapS": 33071}}],
"images": [{{"bufferView": 4, "mimeType": "image/png"}}],
"accessors": [
 {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
 {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}},
 {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"}},
 {{"bufferView": 3, "componentType": 5123, "count": 3, "type": "SCALAR"}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 36}},
 {{"buffer": 0, "byteOffset": 72, "byteLength": 24}}, {{"buffer": 0, "byteOffset": 96, "byteLength": 6}},
 {{"buffer": 0, "byteOffset": 104, "byteLength": {}}}],
"buffers": [{buffer}]}}"#,
        bin.len() - 104
    )
}

/// Positions, normals, uvs, u16 indices (padded to 104 bytes), then a 2×2 PNG.
fn gltf_bin() -> Vec<u8> {
    let mut b = Vec::new();
    for v in [
        0f32, 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 1., 0., 0., 1.,
    ] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0f32, 0., 1., 0., 0., 1.] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b.extend_from_slice(&png_2x2());
    while b.len() % 4 != 0 {
        b.push(0);
    }
    b
}

fn png_2x2() -> Vec<u8> {
    let mut out = Vec::new();
    let img =
        image::RgbImage::from_raw(2, 2, vec![10, 200, 30, 40, 50, 60, 70, 80, 90, 250, 128, 0])
            .unwrap();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn glb() -> Vec<u8> {
    let mut json = gltf_json(false).into_bytes();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let bin = gltf_bin();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

fn base64_encode(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Tiny renders: accepted scenes must also render without panicking.
fn tiny_render(scene: &thinfilm::scene::Scene) -> anyhow::Result<()> {
    let options = RenderOptions {
        spp: Some(1),
        resolution: Some((4, 4)),
        threads: Some(1),
        ..RenderOptions::default()
    };
    thinfilm::render::render(scene, &options).map(|_| ())
}

/// Runs `target`'s loader on `data` in `dir` (which holds [`prepare_assets`]' files).
/// `Ok` when the input was accepted (and rendered or fitted), `Err` with the message when it
/// was refused.
pub fn run(target: Target, data: &[u8], dir: &Path) -> Result<(), String> {
    run_inner(target, data, dir).map_err(|e| format!("{e:#}"))
}

fn run_inner(target: Target, data: &[u8], dir: &Path) -> anyhow::Result<()> {
    let write = |name: &str| -> anyhow::Result<std::path::PathBuf> {
        let p = dir.join(name);
        std::fs::write(&p, data)?;
        Ok(p)
    };
    match target {
        Target::EnviHeader => {
            let p = write("input.hdr")?;
            // A long binary beside it, so the header's sizes decide.
            let img = dir.join("input.img");
            if !img.exists() {
                std::fs::write(&img, vec![0x3fu8; 64 * 1024])?;
            }
            let cube = envi::read_cube(&p)?;
            std::hint::black_box(cube.data.iter().sum::<f32>());
        }
        Target::EnviCube => {
            let hdr = dir.join("cube_in.hdr");
            std::fs::write(&hdr, envi::header_text(&cube_options()))?;
            std::fs::write(dir.join("cube_in.img"), data)?;
            let cube = envi::read_cube(&hdr)?;
            std::hint::black_box(cube.data.iter().sum::<f32>());
        }
        Target::CaptureJson => {
            let p = write("capture.json")?;
            let set = thinfilm::capture::load_capture_set(&p)?;
            let opts = thinfilm::estimate::Options {
                film_ior: (set.angles.len() < 2).then(|| thinfilm::optics::Ior::real(1.4)),
                ..thinfilm::estimate::Options::default()
            };
            thinfilm::estimate::estimate(&set, &opts)?;
        }
        Target::MitsubaXml => tiny_render(&thinfilm::scene::load(&write("input.xml")?, &[])?)?,
        Target::Ply => tiny_render(&thinfilm::scene::load(&write("input.ply")?, &[])?)?,
        Target::Obj => tiny_render(&thinfilm::scene::load(&write("input.obj")?, &[])?)?,
        Target::Gltf => tiny_render(&thinfilm::scene::load(&write("input.gltf")?, &[])?)?,
        Target::Glb => tiny_render(&thinfilm::scene::load(&write("input.glb")?, &[])?)?,
        Target::Exr => {
            let p = write("input.exr")?;
            let channels = thinfilm::image_io::read_exr_channels(&p)?;
            let img = thinfilm::scene::load_rgb_image(&p)?;
            std::hint::black_box((channels.2.len(), img.pixels.len()));
        }
        Target::Serialized => {
            std::fs::write(dir.join("input.serialized"), serialized_file(data))?;
            let xml = r#"<scene version="3.0.0"><shape type="serialized">
<string name="filename" value="input.serialized"/></shape></scene>"#;
            std::fs::write(dir.join("serialized.xml"), xml)?;
            tiny_render(&thinfilm::scene::load(&dir.join("serialized.xml"), &[])?)?;
        }
        Target::Include => {
            write("part.xml")?;
            let xml = r#"<scene version="3.0.0"><include filename="part.xml"/>
<shape type="sphere"><float name="radius" value="0.3"/></shape></scene>"#;
            std::fs::write(dir.join("include.xml"), xml)?;
            tiny_render(&thinfilm::scene::load(&dir.join("include.xml"), &[])?)?;
        }
        Target::Image => {
            let p = write(&format!("input.{}", image_extension(data)))?;
            let img = thinfilm::scene::load_rgb_image(&p)?;
            std::hint::black_box(img.pixels.len());
        }
        Target::Provenance => merge_with_companion(&write("input_piece.exr")?, dir)?,
    }
    Ok(())
}

/// `thinfilm merge` of `piece` with the valid companion piece of its kind.
fn merge_with_companion(piece: &Path, dir: &Path) -> anyhow::Result<()> {
    use thinfilm::merge::{merge_renders, stitch_tiles, RenderPiece, TilePiece};
    let exr = thinfilm::image_io::read_exr(piece)?;
    let what = piece.display().to_string();
    if exr
        .attributes
        .get(thinfilm::render::provenance::KIND)
        .map(String::as_str)
        == Some("fit")
    {
        let tile = |p: &Path, exr: thinfilm::image_io::ExrFile| -> anyhow::Result<TilePiece> {
            let info =
                thinfilm::estimate::tiles::TileInfo::from_attributes(&exr.attributes, &what)?;
            Ok(TilePiece {
                path: p.to_path_buf(),
                info,
                exr,
            })
        };
        let b = dir.join("tile_b.exr");
        let pieces = vec![
            tile(piece, exr)?,
            tile(&b, thinfilm::image_io::read_exr(&b)?)?,
        ];
        std::hint::black_box(stitch_tiles(pieces)?.channels.len());
    } else {
        let b = dir.join("piece_b.exr");
        let pieces = vec![
            RenderPiece::from_exr(piece, exr)?,
            RenderPiece::from_exr(&b, thinfilm::image_io::read_exr(&b)?)?,
        ];
        std::hint::black_box(merge_renders(pieces)?.image.pixels.len());
    }
    Ok(())
}
