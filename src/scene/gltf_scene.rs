//! glTF 2.0 (`.gltf` / `.glb`) scenes via the `gltf` crate.
//!
//! What is read and how it maps onto [`Scene`]:
//! - **Meshes**: every triangle primitive of every node of the default scene (or the first
//!   scene), with node transforms composed down the hierarchy; positions, normals (inverse
//!   transpose; computed smooth if absent), `TANGENT` (for normal maps; ∂p/∂u if absent),
//!   the `TEXCOORD_n` set its material's textures read (glTF's v runs down the image, the
//!   same as Mitsuba's bitmap convention, so no flip), `COLOR_0`. Point/line primitives are
//!   skipped with a warning.
//! - **Materials**: every material becomes a [`GltfPbr`](crate::render::bsdf::gltf_pbr::GltfPbr),
//!   the glTF 2.0 metallic-roughness BRDF with its extensions (ior, specular, transmission,
//!   volume, iridescence, emissive strength, texture transform), built by
//!   [`super::gltf_material`] (`docs/gltf-materials.md`); emissive factor × strength > 0 →
//!   area emission (linear RGB).
//! - **Cameras and lights** ([`super::gltf_lights`]): the first camera found on a node
//!   (perspective or orthographic); without one, the model is framed as `<model-viewer>`
//!   frames it. `KHR_lights_punctual` lights on nodes, converted from photometric units.
//!   The environment is the neutral studio ([`super::environment::neutral_studio`]) unless
//!   `--environment` replaces it.

use super::{
    gltf_lights, BitmapTexture, Camera, FilmSettings, Geometry, IntegratorSettings,
    ReconstructionFilter, Scene, Shape, SpectrumDesc, TextureDesc, TextureFilter, TriangleMesh,
    WrapMode, DEFAULT_RESOLUTION, DEFAULT_SPP,
};
use crate::optics::{Complex64, Ior};
use crate::render::bsdf::Bsdf;
use anyhow::{bail, Context, Result};
use glam::{Mat4, Vec2, Vec3, Vec4};
use gltf::image::Format;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// Channel count and bytes per channel of a decoded glTF image.
pub(super) fn image_layout(f: Format) -> (usize, usize) {
    match f {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        Format::R32G32B32FLOAT => (3, 4),
        Format::R32G32B32A32FLOAT => (4, 4),
    }
}

/// One channel of a decoded glTF image as floats in [0,1] (row-major, top row first).
fn image_channel(img: &gltf::image::Data, channel: usize) -> Result<Vec<f32>> {
    let (n, bytes_per) = image_layout(img.format);
    if channel >= n {
        bail!("image has {n} channel(s), channel {channel} requested");
    }
    let stride = n * bytes_per;
    let count = img.width as usize * img.height as usize;
    if img.pixels.len() < count * stride {
        bail!("image data is truncated");
    }
    Ok((0..count)
        .map(|i| {
            let o = i * stride + channel * bytes_per;
            match bytes_per {
                1 => img.pixels[o] as f32 / 255.0,
                2 => u16::from_le_bytes([img.pixels[o], img.pixels[o + 1]]) as f32 / 65535.0,
                _ => f32::from_le_bytes(img.pixels[o..o + 4].try_into().unwrap()),
            }
        })
        .collect())
}

pub(super) fn wrap_mode(m: gltf::texture::WrappingMode) -> WrapMode {
    match m {
        gltf::texture::WrappingMode::ClampToEdge => WrapMode::Clamp,
        gltf::texture::WrappingMode::MirroredRepeat => WrapMode::Mirror,
        gltf::texture::WrappingMode::Repeat => WrapMode::Repeat,
    }
}

fn filter_of(t: &gltf::Texture) -> TextureFilter {
    match t.sampler().mag_filter() {
        Some(gltf::texture::MagFilter::Nearest) => TextureFilter::Nearest,
        _ => TextureFilter::Bilinear,
    }
}

struct Loader<'a> {
    doc: &'a gltf::Document,
    images: &'a [gltf::image::Data],
    buffers: &'a [gltf::buffer::Data],
    file: String,
    /// Per material: its BSDF index, emission and the texture coordinate set it reads.
    materials: HashMap<Option<usize>, (usize, Option<SpectrumDesc>, u32)>,
    bsdfs: Vec<Bsdf>,
}

/// The grey conductor n = 1 + ik whose normal-incidence reflectance is the luminance F0 of
/// a metal's linear base colour: R = ((n−1)² + k²)/((n+1)² + k²) gives k = 2·√(F0/(1−F0)).
/// The hue of coloured metals is lost.
pub(crate) fn grey_conductor(r: f32, g: f32, b: f32) -> Ior {
    let f0 = (0.2126 * r + 0.7152 * g + 0.0722 * b).clamp(0.0, 0.999) as f64;
    Ior::Constant(Complex64::new(1.0, 2.0 * (f0 / (1.0 - f0)).sqrt()))
}

/// Texture `tex_index` of `doc` and its decoded image.
fn texture_image<'a>(
    doc: &'a gltf::Document,
    images: &'a [gltf::image::Data],
    file: &str,
    tex_index: usize,
) -> Result<(&'a gltf::image::Data, gltf::Texture<'a>)> {
    let tex = doc
        .textures()
        .nth(tex_index)
        .with_context(|| format!("{file}: texture {tex_index} does not exist"))?;
    let img = images
        .get(tex.source().index())
        .with_context(|| format!("{file}: image {} was not loaded", tex.source().index()))?;
    Ok((img, tex))
}

/// The film of material `m`'s `KHR_materials_iridescence`, if its `iridescenceFactor` is
/// ≥ 0.5 (a factor in (0, 0.5) is ignored with a warning: the film is on or off): the film
/// index `iridescenceIor` (default 1.3) and the thickness in nm, `iridescenceThicknessMaximum`
/// (default 400) or, with `iridescenceThicknessTexture`, its **G** channel v ∈ [0, 1] mapped
/// through `value_range = (min, max)` (defaults 100, 400). The `material.gltf` reader
/// ([`crate::material::gltf`]) shares it.
pub(crate) fn iridescent_film(
    m: &gltf::Material,
    doc: &gltf::Document,
    images: &[gltf::image::Data],
    what: &str,
) -> Result<Option<(f64, TextureDesc)>> {
    let Some(v) = m.extension_value("KHR_materials_iridescence") else {
        return Ok(None);
    };
    let num = |k: &str, d: f64| v.get(k).and_then(|x| x.as_f64()).unwrap_or(d);
    let factor = num("iridescenceFactor", 0.0);
    if factor < 0.5 {
        if factor > 0.0 {
            eprintln!("warning: {what}: iridescenceFactor {factor} < 0.5 is ignored (thin film is on/off)");
        }
        return Ok(None);
    }
    let film_n = v
        .get("iridescenceIor")
        .or_else(|| v.get("iridescenceIOR"))
        .and_then(|x| x.as_f64())
        .unwrap_or(1.3);
    let tmin = num("iridescenceThicknessMinimum", 100.0) as f32;
    let tmax = num("iridescenceThicknessMaximum", 400.0) as f32;
    if !(film_n > 0.0 && tmin >= 0.0 && tmax >= 0.0) {
        bail!("{what}: iridescence needs ior > 0 and thicknesses ≥ 0");
    }
    let thickness_nm = match v.get("iridescenceThicknessTexture") {
        None => TextureDesc::Value(SpectrumDesc::Constant(tmax)),
        Some(t) => {
            let index = t
                .get("index")
                .and_then(|x| x.as_u64())
                .with_context(|| format!("{what}: iridescenceThicknessTexture has no index"))?
                as usize;
            if t.get("texCoord").and_then(|x| x.as_u64()).unwrap_or(0) != 0 {
                eprintln!(
                    "warning: {what}: thickness texture uses texCoord ≠ 0; TEXCOORD_0 is used"
                );
            }
            let (img, tex) = texture_image(doc, images, what, index)?;
            // G channel, linear data (not colour).
            let g = image_channel(img, 1).with_context(|| format!("{what}: thickness texture"))?;
            let mut b = BitmapTexture::new(img.width as usize, img.height as usize, 1, g)?;
            b.value_range = Some((tmin, tmax));
            b.wrap = wrap_mode(tex.sampler().wrap_s());
            b.filter = filter_of(&tex);
            TextureDesc::Bitmap(Arc::new(b))
        }
    };
    Ok(Some((film_n, thickness_nm)))
}

impl Loader<'_> {
    /// Material `m` as a [`GltfPbr`](crate::render::bsdf::gltf_pbr::GltfPbr) (see
    /// [`super::gltf_material`]) and its emission, built once per material.
    fn material(&mut self, m: &gltf::Material) -> Result<(usize, Option<SpectrumDesc>, u32)> {
        if let Some(v) = self.materials.get(&m.index()) {
            return Ok(v.clone());
        }
        let what = format!(
            "{}: material {}",
            self.file,
            match (m.name(), m.index()) {
                (Some(n), Some(i)) => format!("{n:?} (#{i})"),
                (None, Some(i)) => format!("#{i}"),
                (_, None) => "default".to_string(),
            }
        );
        let reader = super::gltf_material::MaterialReader {
            doc: self.doc,
            images: self.images,
            what,
            tex_coords: Default::default(),
        };
        let (bsdf, emission, uv_set) = reader.read(m)?;
        self.bsdfs.push(bsdf);
        let entry = (self.bsdfs.len() - 1, emission, uv_set);
        self.materials.insert(m.index(), entry.clone());
        Ok(entry)
    }

    /// Triangle primitive `prim` of `mesh` placed by `world` as a shape (None, with a
    /// warning, for points and lines): positions, normals, the texture coordinate set its
    /// material reads (`TEXCOORD_n`), indices.
    fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        world: Mat4,
    ) -> Result<Option<Shape>> {
        let file = &self.file;
        let what = format!(
            "{file}: mesh {} primitive {}",
            mesh.name()
                .map(str::to_string)
                .unwrap_or_else(|| mesh.index().to_string()),
            prim.index()
        );
        if prim.mode() != gltf::mesh::Mode::Triangles {
            eprintln!(
                "warning: {what}: mode {:?} is not triangles; skipped",
                prim.mode()
            );
            return Ok(None);
        }
        let (bsdf, emission, uv_set) = self.material(&prim.material())?;
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .with_context(|| format!("{what}: no POSITION"))?
            .map(Vec3::from)
            .collect();
        let normals: Vec<Vec3> = reader
            .read_normals()
            .map(|n| n.map(Vec3::from).collect())
            .unwrap_or_default();
        let uvs: Vec<Vec2> = reader
            .read_tex_coords(uv_set)
            .map(|t| t.into_f32().map(Vec2::from).collect())
            .unwrap_or_default();
        // glTF 2.0 §3.9.2: baseColor = baseColorFactor × baseColorTexture × COLOR_0 (linear;
        // normalized u8/u16 are mapped to [0, 1] by the reader, alpha is not a colour).
        let colors: Vec<Vec3> = reader
            .read_colors(0)
            .map(|c| c.into_rgb_f32().map(Vec3::from).collect())
            .unwrap_or_default();
        let tangents = tangents(
            reader.read_tangents().map(|t| t.map(Vec4::from).collect()),
            positions.len(),
            &what,
        );
        if uv_set > 0 && uvs.is_empty() {
            eprintln!("warning: {what}: its material reads TEXCOORD_{uv_set}, which it lacks");
        }
        let flat: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if flat.len() % 3 != 0 {
            bail!("{what}: index count {} is not a multiple of 3", flat.len());
        }
        let n = positions.len();
        let mut m = TriangleMesh {
            normals: if normals.len() == n {
                normals
            } else {
                Vec::new()
            },
            uvs: if uvs.len() == n { uvs } else { Vec::new() },
            colors: if colors.len() == n {
                colors
            } else {
                Vec::new()
            },
            tangents,
            positions,
            indices: flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        m.validate(&what)?;
        m.ensure_normals();
        m.transform(&world);
        if world.determinant() < 0.0 {
            // A mirroring node transform flips the winding; glTF says to reverse it.
            for t in &mut m.indices {
                t.swap(1, 2);
            }
        }
        Ok(Some(Shape {
            geometry: Geometry::Mesh(m.into()),
            bsdf,
            emission,
            name: mesh.name().map(str::to_string),
        }))
    }
}

/// The primitive's `TANGENT` attribute (VEC4 float, one per vertex: `gltf_check` refuses
/// other types and counts), or none — with a warning naming the primitive when a tangent is
/// not finite, its xyz is zero or w is not ±1 (the normal map then takes its tangent from
/// ∂p/∂u, as without the attribute).
fn tangents(read: Option<Vec<Vec4>>, n: usize, what: &str) -> Vec<Vec4> {
    let Some(t) = read else {
        return Vec::new();
    };
    let bad = t.iter().position(|t| {
        !t.is_finite() || t.truncate().length_squared() < 1e-12 || (t.w.abs() - 1.0).abs() > 1e-3
    });
    match bad {
        Some(i) => {
            eprintln!(
                "warning: {what}: TANGENT {i} = {:?} is not a finite non-zero vector with w = ±1; the attribute is ignored (tangents from the texture coordinates)",
                t[i].to_array()
            );
            Vec::new()
        }
        None if t.len() != n => Vec::new(),
        None => t,
    }
}

/// Loads a `.gltf` or `.glb` file (see the module docs for the mapping).
pub fn load_gltf(path: &Path) -> Result<Scene> {
    if !path.is_file() {
        bail!("glTF file {} does not exist", path.display());
    }
    let file = path.display().to_string();
    // Validated completely before any accessor is read (see `gltf_check`).
    let (doc, buffers, images) = super::gltf_check::import(path)?;
    let mut loader = Loader {
        doc: &doc,
        images: &images,
        buffers: &buffers,
        file: file.clone(),
        materials: HashMap::new(),
        bsdfs: Vec::new(),
    };
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .with_context(|| format!("{file}: no scene"))?;
    let mut shapes = Vec::new();
    let lights = gltf_lights::parse_lights(doc.extension_value("KHR_lights_punctual"), &file)?;
    let mut emitters = vec![super::environment::neutral_studio()];
    let mut camera: Option<(Camera, Option<f32>)> = None;
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !(world.is_finite() && world.determinant().is_normal()) {
            bail!(
                "{file}: node {}: its world transform is singular or not finite",
                node.index()
            );
        }
        for c in node.children() {
            stack.push((c, world));
        }
        if let (None, Some(cam)) = (&camera, node.camera()) {
            camera = Some(gltf_lights::camera(world, &cam));
        }
        let light = node.extension_value("KHR_lights_punctual");
        if let Some(i) = gltf_lights::node_light(light, lights.len(), node.index())
            .with_context(|| file.clone())?
        {
            emitters.push(gltf_lights::emitter(&lights[i], world));
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                shapes.extend(loader.primitive(&mesh, &prim, world)?);
            }
        }
    }
    if shapes.is_empty() {
        bail!("{file}: the scene has no triangle meshes");
    }
    let mut bsdfs = std::mem::take(&mut loader.bsdfs);
    if bsdfs.is_empty() {
        bsdfs.push(Bsdf::default_diffuse());
    }
    let (camera, film) = camera_and_film(camera, &shapes, &file)?;
    Ok(Scene {
        camera,
        film,
        integrator: IntegratorSettings::default(),
        spp: DEFAULT_SPP,
        seed: 0,
        sampler: super::SamplerKind::Sobol,
        shapes,
        bsdfs,
        emitters,
        polarizer: None,
        source: Some(path.to_path_buf()),
        media: None,
    })
}

/// The file's camera with a film of its aspect ratio (512 high), or, without one, the
/// `<model-viewer>` framing of every vertex on the default film (and at any other aspect a
/// render asks for: [`FovAxis::FitY`](super::FovAxis::FitY)).
fn camera_and_film(
    camera: Option<(Camera, Option<f32>)>,
    shapes: &[Shape],
    file: &str,
) -> Result<(Camera, FilmSettings)> {
    if let Some((c, aspect)) = camera {
        let h = DEFAULT_RESOLUTION.1;
        let w = aspect
            .filter(|a| a.is_finite() && *a > 0.0)
            .map_or(DEFAULT_RESOLUTION.0, |a| {
                ((h as f32 * a).round() as u32).max(1)
            });
        let film = FilmSettings {
            width: w,
            height: h,
            filter: ReconstructionFilter::Box,
        };
        return Ok((c, film));
    }
    let film = FilmSettings::default();
    let vertices: Vec<Vec3> = shapes
        .iter()
        .filter_map(|s| match &s.geometry {
            Geometry::Mesh(m) => Some(m.positions.iter().copied()),
            Geometry::Sphere { .. } => None,
        })
        .flatten()
        .collect();
    let camera = gltf_lights::model_viewer_camera(&vertices)
        .with_context(|| format!("{file}: the meshes have no finite vertices"))?;
    Ok((camera, film))
}
