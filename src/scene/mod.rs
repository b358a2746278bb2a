//! Scene description: what the renderer is asked to draw, independent of file format.
//! Loaders (Mitsuba XML subset, glTF, OBJ, PLY) produce a [`Scene`]; the renderer consumes it.
//!
//! CONTRACT between the scene loaders and the renderer. Geometry is in world space.
//! Conventions are Mitsuba 3's (`docs/physics-and-formats.md`): the camera looks along +Z of its
//! `to_world` frame with +Y up; environment maps use Mitsuba's lat-long mapping. BSDFs are
//! the renderer's models ([`crate::render::bsdf`]), each built from a file by its own builder.

use crate::image_io::RgbImage;
use crate::render::bsdf::Bsdf;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use std::path::PathBuf;
use std::sync::Arc;

/// Everything needed to render one image.
/// The sample sequence of a render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SamplerKind {
    /// Independent uniform numbers: Mitsuba's `independent` (its default).
    #[default]
    Independent,
    /// Owen-scrambled Sobol' (Burley 2020): thinfilm's low-discrepancy sampler, used for
    /// Mitsuba's stratified samplers `ldsampler`, `stratified`, `multijitter` and
    /// `orthogonal`, and for meshes rendered without a scene file.
    Sobol,
}

impl SamplerKind {
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Independent => "independent",
            SamplerKind::Sobol => "sobol",
        }
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "independent" => Ok(SamplerKind::Independent),
            "sobol" => Ok(SamplerKind::Sobol),
            _ => Err(format!(
                "unknown sampler {s:?}: expected \"independent\" or \"sobol\""
            )),
        }
    }
}

#[derive(Debug, Clone)]
pub struct Scene {
    pub camera: Camera,
    pub film: FilmSettings,
    pub integrator: IntegratorSettings,
    /// Samples per pixel (sampler `sample_count`).
    pub spp: u32,
    /// Sampler seed (Mitsuba `seed`, default 0).
    pub seed: u64,
    /// Which sequence the samples come from (the sampler's plugin type).
    pub sampler: SamplerKind,
    pub shapes: Vec<Shape>,
    /// The BSDFs shapes refer to (built and validated by their models' builders).
    pub bsdfs: Vec<Bsdf>,
    pub emitters: Vec<EmitterDesc>,
    /// Linear polariser in front of the sensor, if the scene asks for one.
    pub polarizer: Option<Polarizer>,
    /// File the scene came from (for messages), if any.
    pub source: Option<PathBuf>,
    /// Participating media, when the scene has some and asks for Mitsuba's `volpath`
    /// (None: surfaces only, the path tracer's transport).
    pub media: Option<Arc<crate::render::medium::SceneMedia>>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Camera-to-world transform (camera looks along local +Z, up is local +Y).
    pub to_world: Mat4,
    /// Field of view in degrees along `fov_axis`.
    pub fov_deg: f32,
    pub fov_axis: FovAxis,
    pub near_clip: f32,
    pub far_clip: f32,
    /// How film positions become rays (the fov fields apply to the perspective kinds).
    pub projection: Projection,
}

/// A camera's projection (Mitsuba's `perspective`, `thinlens` and `orthographic` sensors).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Projection {
    /// A pinhole at the origin of `to_world`.
    #[default]
    Perspective,
    /// A thin lens of radius `aperture_radius` in the local z = 0 plane, focused on the plane
    /// local z = `focus_distance` (Mitsuba `thinlens`).
    ThinLens {
        aperture_radius: f32,
        focus_distance: f32,
    },
    /// Parallel rays along local +Z from the local rectangle x ∈ [−1, 1],
    /// y ∈ [−1/aspect, 1/aspect] at z = `near_clip` (Mitsuba `orthographic`; `to_world`'s
    /// scale sets the extent).
    Orthographic,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FovAxis {
    X,
    Y,
    Diagonal,
    Smaller,
    Larger,
    /// `fov` along y on films at least `min_aspect` wide; a narrower film keeps the width of
    /// a `min_aspect` one, tan(fov_x/2) = min_aspect·tan(fov/2): `<model-viewer>`'s framing at
    /// any aspect (glTF files without a camera; `min_aspect` is the model's ideal aspect).
    FitY {
        min_aspect: f32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilmSettings {
    pub width: u32,
    pub height: u32,
    pub filter: ReconstructionFilter,
}

/// Pixel reconstruction filter (Mitsuba `rfilter`); radii in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReconstructionFilter {
    Box,
    Tent { radius: f32 },
    Gaussian { stddev: f32 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegratorSettings {
    /// Mitsuba semantics: −1 unlimited, 1 = directly visible emitters only.
    pub max_depth: i32,
    /// Russian roulette starts at this depth (Mitsuba default 5).
    pub rr_depth: i32,
    pub hide_emitters: bool,
}

impl Default for IntegratorSettings {
    fn default() -> Self {
        IntegratorSettings {
            max_depth: -1,
            rr_depth: 5,
            hide_emitters: false,
        }
    }
}

/// An ideal linear polariser in front of the sensor (`<string name="polarizer" …/>` inside
/// `<sensor>`; a thinfilm extension, see scenes/README.md). It passes half of unpolarised
/// light, like Mitsuba's `polarizer` BSDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Polarizer {
    /// Per camera ray, transmits the s component (E ⟂ the plane of incidence spanned by the
    /// ray and the shading normal at the ray's first surface hit) — the seed's S-wave camera.
    S,
    /// Per camera ray, transmits the p component (E in that plane of incidence).
    P,
    /// A fixed polariser whose transmission axis lies at this angle in degrees from the
    /// image's +x (rightwards) axis towards its +y (upwards) axis, projected onto the plane
    /// perpendicular to each camera ray.
    AngleDeg(f32),
}

#[derive(Debug, Clone)]
pub struct Shape {
    pub geometry: Geometry,
    /// Index into [`Scene::bsdfs`].
    pub bsdf: usize,
    /// Area-light radiance, if the shape emits.
    pub emission: Option<SpectrumDesc>,
    /// Optional name/id for messages.
    pub name: Option<String>,
}

#[derive(Debug, Clone)]
pub enum Geometry {
    /// Shared with the prepared scene (a render reads the scene's arrays, not a copy).
    Mesh(std::sync::Arc<TriangleMesh>),
    /// Analytic sphere (world space), normals pointing out (in if `flip_normals`).
    /// `rotation` takes the sphere's local frame to world space (orthonormal; a reflection if
    /// its `to_world` mirrors): Mitsuba measures a sphere's (u, v) in the local frame, so a
    /// rotated sphere turns its textures with it.
    Sphere {
        center: Vec3,
        radius: f32,
        rotation: Mat3,
        flip_normals: bool,
    },
}

/// A world-space triangle mesh. `normals`, `uvs` and `colors` are either empty or one per
/// vertex.
#[derive(Clone, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub indices: Vec<[u32; 3]>,
    /// Linear RGB vertex colours (glTF `COLOR_0`, PLY `red green blue`): they reach the
    /// shading point interpolated ([`crate::render::geometry::SurfaceInteraction::color`]).
    pub colors: Vec<Vec3>,
    /// Vertex tangents (glTF `TANGENT`: xyz the tangent, w = ±1 the bitangent's sign): they
    /// reach the shading point interpolated
    /// ([`crate::render::geometry::SurfaceInteraction::tangent`]).
    pub tangents: Vec<Vec4>,
}

/// Sizes and a hash of every bit of the arrays, not the arrays: a render's provenance hashes
/// the scene's `Debug` form, and a 2M-triangle mesh printed in full was ~200 MB of float
/// formatting (~1 s). Any change to a coordinate, normal, uv, index or colour changes the hash.
impl std::fmt::Debug for TriangleMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // FNV-1a over 32-bit words, one stream per array so a value cannot move between them
        // unnoticed.
        let words = |it: &mut dyn Iterator<Item = u32>| {
            it.fold(0xcbf2_9ce4_8422_2325u64, |h, w| {
                (h ^ w as u64).wrapping_mul(0x0000_0100_0000_01b3)
            })
        };
        let hash = [
            words(
                &mut self
                    .positions
                    .iter()
                    .flat_map(|p| p.to_array().map(f32::to_bits)),
            ),
            words(
                &mut self
                    .normals
                    .iter()
                    .flat_map(|n| n.to_array().map(f32::to_bits)),
            ),
            words(&mut self.uvs.iter().flat_map(|t| t.to_array().map(f32::to_bits))),
            words(&mut self.indices.iter().flat_map(|t| *t)),
            words(
                &mut self
                    .colors
                    .iter()
                    .flat_map(|c| c.to_array().map(f32::to_bits)),
            ),
        ];
        let mut d = f.debug_struct("TriangleMesh");
        // Tangents only where there are any (the form of other meshes is unchanged).
        if !self.tangents.is_empty() {
            let t = words(&mut (self.tangents.iter()).flat_map(|t| t.to_array().map(f32::to_bits)));
            d.field("tangents", &format!("{} {t:016x}", self.tangents.len()));
        }
        d.field("vertices", &self.positions.len())
            .field("normals", &self.normals.len())
            .field("uvs", &self.uvs.len())
            .field("triangles", &self.indices.len())
            .field("colors", &self.colors.len())
            .field("content_hash", &hash.map(|h| format!("{h:016x}")))
            .finish()
    }
}

/// A spectral value as written in a scene file.
#[derive(Debug, Clone, PartialEq)]
pub enum SpectrumDesc {
    /// Wavelength-independent value.
    Constant(f32),
    /// Linear sRGB; upsampled as a reflectance (BSDF) or as an illuminant (emitter).
    Rgb([f32; 3]),
    /// Piecewise-linear (λ nm, value) pairs.
    Tabulated(Vec<(f32, f32)>),
    /// CIE D65 normalised like Mitsuba's `d65` spectrum, times a scale.
    D65 { scale: f32 },
}

/// A texture or a constant.
#[derive(Debug, Clone, PartialEq)]
pub enum TextureDesc {
    Value(SpectrumDesc),
    Bitmap(Arc<BitmapTexture>),
    Checkerboard {
        color0: SpectrumDesc,
        color1: SpectrumDesc,
        to_uv: Mat3,
    },
    /// The mesh's vertex colours (Mitsuba's `mesh_attribute` `vertex_color`), upsampled as
    /// a reflectance at the shading point.
    VertexColor,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TextureFilter {
    Bilinear,
    Nearest,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WrapMode {
    Repeat,
    Mirror,
    Clamp,
}

/// An image texture. `data` is row-major, top row first, `channels` floats per texel
/// (1 or 3), already linear (sRGB 8-bit inputs decoded unless `raw`). A `thickness` bitmap
/// holds nanometres.
#[derive(Debug, Clone, PartialEq)]
pub struct BitmapTexture {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
    pub filter: TextureFilter,
    pub wrap: WrapMode,
    /// UV transform (Mitsuba `to_uv`), applied before lookup.
    pub to_uv: Mat3,
    /// For a thickness map given as [0,1] data (glTF G channel): thickness = lerp(min, max, v).
    pub value_range: Option<(f32, f32)>,
    pub path: Option<PathBuf>,
}

#[derive(Debug, Clone)]
pub enum EmitterDesc {
    /// Lat-long environment map (linear sRGB texels), Mitsuba orientation and `to_world`.
    Envmap {
        image: Arc<RgbImage>,
        scale: f32,
        to_world: Mat4,
        path: Option<PathBuf>,
    },
    Constant {
        radiance: SpectrumDesc,
    },
    Point {
        position: Vec3,
        intensity: SpectrumDesc,
    },
    /// A spot light at the origin of `to_world` shining along its local +Z; `intensity` is
    /// the radiant intensity on the axis, scaled by the `cone` profile off it and, with a
    /// `range`, by glTF's distance window.
    Spot {
        to_world: Mat4,
        intensity: SpectrumDesc,
        cone: SpotCone,
        range: Option<f32>,
    },
    /// Light from infinitely far away travelling along `direction` (unit), delivering
    /// `irradiance` to a surface facing it (Mitsuba `directional`).
    Directional {
        direction: Vec3,
        irradiance: SpectrumDesc,
    },
    /// Mitsuba's `projector`: a pinhole at the origin of `to_world` projecting `irradiance`
    /// (a bitmap, upsampled like a reflectance as Mitsuba's bitmap texture is, or a constant
    /// emission spectrum) along local +Z through a frustum of horizontal half-angle tangent
    /// `tan_half_fov_x` and width/height `aspect` (the image's); `scale` multiplies it.
    Projector {
        to_world: Mat4,
        irradiance: TextureDesc,
        scale: f32,
        tan_half_fov_x: f32,
        aspect: f32,
    },
    /// Mitsuba's `spot` with a `texture`: the spot light of `intensity` and Mitsuba's linear
    /// `cone`, its value also multiplied by `texture` at uv = ½ + ½·(x, y)/(z·tan cutoff) of
    /// the light-local direction (Mitsuba's `direction_to_uv`).
    TexturedSpot {
        to_world: Mat4,
        intensity: SpectrumDesc,
        cone: SpotCone,
        texture: TextureDesc,
    },
}

/// The angular profile of a [`EmitterDesc::Spot`] (θ: angle from the axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpotCone {
    /// Mitsuba's `spot`: 1 for θ ≤ `beam_width`, falling linearly in θ to 0 at
    /// `cutoff` (radians, beam_width < cutoff).
    Linear { cutoff: f32, beam_width: f32 },
    /// glTF `KHR_lights_punctual`: t = clamp((cos θ − cos outer) / max(10⁻³, cos inner −
    /// cos outer), 0, 1), profile t² (the extension's recommended smooth falloff).
    Smooth { cos_inner: f32, cos_outer: f32 },
    /// Every direction (a glTF point light given a `range`).
    Omni,
}

pub mod environment;
pub(crate) mod gltf_check;
pub(crate) mod gltf_lights;
mod gltf_material;
pub mod gltf_scene;
pub mod meshio;
pub mod mitsuba;
mod ply_binary;
mod ply_scalar;
pub mod serialized;
pub mod shapes;
pub mod sky;
pub mod teapot;
pub mod texture;

pub use texture::load_rgb_image;

use anyhow::{bail, Context, Result};
use std::path::Path;

/// Loads a scene file, choosing the reader by extension: `.xml` (Mitsuba 3 subset),
/// `.gltf`/`.glb`, `.obj`, `.ply`. `defaults` are `-D key=value` overrides of the XML's
/// `<default>` parameters. For XML, an override of a parameter the file neither declares nor
/// uses is an error (a typo); other formats have no parameters, so any override is an error.
pub fn load(path: &Path, defaults: &[(String, String)]) -> Result<Scene> {
    if !path.is_file() {
        bail!("scene file {} does not exist", path.display());
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    // Parsed text and meshes take a multiple of the file in memory (DOM nodes, per-vertex
    // maps of the PLY reader): refuse files whose parse could not fit the budget.
    let expansion = match ext.as_str() {
        "ply" => 32,
        "gltf" | "glb" => 4,
        _ => 16,
    };
    let bytes = std::fs::metadata(path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    crate::limits::check_alloc(
        format!("scene file {} ({bytes} bytes)", path.display()),
        bytes.saturating_mul(expansion),
    )?;
    let mut scene = crate::limits::contain_panics(path, || load_format(path, &ext, defaults))?;
    scene.source = Some(path.to_path_buf());
    scene
        .validate()
        .with_context(|| format!("scene {}", path.display()))?;
    Ok(scene)
}

/// The reader for `ext` (see [`load`]).
fn load_format(path: &Path, ext: &str, defaults: &[(String, String)]) -> Result<Scene> {
    let non_xml_defaults = || -> Result<()> {
        if let Some((k, _)) = defaults.first() {
            bail!(
                "-D {k}=…: parameter overrides apply to Mitsuba XML scenes only ({} is .{ext})",
                path.display()
            );
        }
        Ok(())
    };
    Ok(match ext {
        "xml" => mitsuba::load_file(path, defaults)?,
        "gltf" | "glb" => {
            non_xml_defaults()?;
            gltf_scene::load_gltf(path)?
        }
        "obj" | "ply" => {
            non_xml_defaults()?;
            let mesh = if ext == "obj" {
                meshio::load_obj(path)?
            } else {
                meshio::load_ply(path)?
            };
            scene_for_mesh(mesh, path)?
        }
        _ => bail!(
            "{}: unknown scene format '.{ext}' (expected .xml, .gltf, .glb, .obj or .ply)",
            path.display()
        ),
    })
}

/// Default resolution for formats that carry none (OBJ, PLY, glTF).
pub const DEFAULT_RESOLUTION: (u32, u32) = (512, 512);
/// Default samples per pixel for formats that carry none.
pub const DEFAULT_SPP: u32 = 64;

/// The studio environment (the same map as `scenes/textures/studio.exr`), generated in memory
/// so that standalone meshes and glTF files need no file beside them.
pub fn default_environment() -> EmitterDesc {
    let (w, h) = sky::STUDIO_SIZE;
    EmitterDesc::Envmap {
        image: Arc::new(sky::studio_environment(w, h)),
        scale: 1.0,
        to_world: Mat4::IDENTITY,
        path: None,
    }
}

/// A camera that frames the bounding box `(lo, hi)`: it looks at the box centre from the
/// front (+Z side), a little above and to the right, with a 40° field of view along x
/// (Mitsuba's default `fov_axis`), at a distance where the box's bounding sphere fills about
/// 80 % of the view.
pub fn default_camera(bounds: (Vec3, Vec3)) -> Camera {
    let (lo, hi) = bounds;
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-3);
    let fov_deg: f32 = 40.0;
    let half = (fov_deg.to_radians() * 0.5).tan();
    let distance = radius / (0.8 * half).atan().sin();
    let dir = Vec3::new(0.35, 0.45, 1.0).normalize();
    let origin = center + dir * distance;
    Camera {
        to_world: look_at(origin, center, Vec3::Y),
        fov_deg,
        fov_axis: FovAxis::X,
        near_clip: (distance - radius).max(distance * 1e-3) * 0.5,
        far_clip: (distance + radius) * 2.0,
        projection: Projection::Perspective,
    }
}

/// Mitsuba's `lookat` transform: camera at `origin` looking at `target`, local +Z forward,
/// +Y up, +X = up × forward (Mitsuba's left-handed screen convention).
pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let dir = (target - origin).normalize();
    let left = up.normalize().cross(dir).normalize();
    let new_up = dir.cross(left);
    Mat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    )
}

/// Bounds of every shape (spheres included); None if the scene has no geometry.
pub fn shapes_bounds(shapes: &[Shape]) -> Option<(Vec3, Vec3)> {
    let mut acc: Option<(Vec3, Vec3)> = None;
    for s in shapes {
        let b = match &s.geometry {
            Geometry::Mesh(m) => m.bounds(),
            Geometry::Sphere { center, radius, .. } => Some((
                *center - Vec3::splat(*radius),
                *center + Vec3::splat(*radius),
            )),
        };
        if let Some((lo, hi)) = b {
            acc = Some(match acc {
                None => (lo, hi),
                Some((a, c)) => (a.min(lo), c.max(hi)),
            });
        }
    }
    acc
}

/// A standalone mesh: default diffuse material, default camera framing it, studio light.
fn scene_for_mesh(mut mesh: TriangleMesh, path: &Path) -> Result<Scene> {
    mesh.ensure_normals();
    let bounds = mesh
        .bounds()
        .with_context(|| format!("{}: mesh has no vertices", path.display()))?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    Ok(Scene {
        camera: default_camera(bounds),
        film: FilmSettings::default(),
        integrator: IntegratorSettings::default(),
        spp: DEFAULT_SPP,
        seed: 0,
        sampler: SamplerKind::Sobol,
        shapes: vec![Shape {
            geometry: Geometry::Mesh(mesh.into()),
            bsdf: 0,
            emission: None,
            name,
        }],
        bsdfs: vec![Bsdf::default_diffuse()],
        emitters: vec![default_environment()],
        polarizer: None,
        source: Some(path.to_path_buf()),
        media: None,
    })
}

impl Default for FilmSettings {
    /// Mitsuba's `hdrfilm` defaults would be 768×576 with a Gaussian filter; for files without
    /// a film we use [`DEFAULT_RESOLUTION`] and a box filter (every sample in its own pixel).
    fn default() -> Self {
        FilmSettings {
            width: DEFAULT_RESOLUTION.0,
            height: DEFAULT_RESOLUTION.1,
            filter: ReconstructionFilter::Box,
        }
    }
}

impl Scene {
    /// Checks what the renderer relies on: BSDF indices in range, meshes well formed, a
    /// positive resolution and sample count, finite camera.
    pub fn validate(&self) -> Result<()> {
        if self.film.width == 0 || self.film.height == 0 {
            bail!(
                "film resolution {}×{} is empty",
                self.film.width,
                self.film.height
            );
        }
        if self.spp == 0 {
            bail!("sample_count must be ≥ 1");
        }
        let c = &self.camera;
        let fov_ok = c.fov_deg > 0.0 && c.fov_deg < 180.0;
        if !(c.to_world.is_finite() && (fov_ok || c.projection == Projection::Orthographic)) {
            bail!("camera is degenerate (fov {}°)", c.fov_deg);
        }
        if let Projection::ThinLens {
            aperture_radius,
            focus_distance,
        } = c.projection
        {
            let lens_ok = aperture_radius.is_finite() && aperture_radius >= 0.0;
            if !(lens_ok && focus_distance.is_finite() && focus_distance > 0.0) {
                bail!("thin lens needs aperture_radius ≥ 0 and focus_distance > 0, got {aperture_radius} and {focus_distance}");
            }
        }
        for (i, s) in self.shapes.iter().enumerate() {
            let what = s.name.clone().unwrap_or_else(|| format!("shape {i}"));
            if s.bsdf >= self.bsdfs.len() {
                bail!("{what}: BSDF index {} out of range", s.bsdf);
            }
            match &s.geometry {
                Geometry::Mesh(m) => m.validate(&what)?,
                Geometry::Sphere { center, radius, .. } => {
                    if !(center.is_finite() && radius.is_finite() && *radius > 0.0) {
                        bail!("{what}: sphere needs a finite centre and radius > 0");
                    }
                }
            }
        }
        Ok(())
    }
}
