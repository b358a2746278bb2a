//! Scene description: what the renderer is asked to draw, independent of file format.
//! Loaders (Mitsuba XML subset, glTF, OBJ, PLY) produce a [`Scene`]; the renderer consumes it.
//!
//! CONTRACT between the scene loaders and the renderer. Geometry is in world space.
//! Conventions are Mitsuba 3's (see shared/docs/conventions.md): the camera looks along +Z of
//! its `to_world` frame with +Y up; environment maps use Mitsuba's lat-long mapping.

use crate::image_io::RgbImage;
use crate::optics::Ior;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::path::PathBuf;
use std::sync::Arc;

/// Everything needed to render one image.
#[derive(Debug, Clone)]
pub struct Scene {
    pub camera: Camera,
    pub film: FilmSettings,
    pub integrator: IntegratorSettings,
    /// Samples per pixel (sampler `sample_count`).
    pub spp: u32,
    /// Sampler seed (Mitsuba `seed`, default 0).
    pub seed: u64,
    pub shapes: Vec<Shape>,
    pub bsdfs: Vec<BsdfDesc>,
    pub emitters: Vec<EmitterDesc>,
    /// Linear polariser in front of the sensor, if the scene asks for one.
    pub polarizer: Option<Polarizer>,
    /// File the scene came from (for messages), if any.
    pub source: Option<PathBuf>,
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
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FovAxis {
    X,
    Y,
    Diagonal,
    Smaller,
    Larger,
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

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Polarizer {
    /// Passes the s component relative to the plane of incidence at the first hit.
    S,
    P,
    /// Transmission axis angle in degrees in the sensor's image plane (from +X).
    AngleDeg(i32),
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
    Mesh(TriangleMesh),
    /// Analytic sphere (world space), normals pointing out (in if `flip_normals`).
    Sphere {
        center: Vec3,
        radius: f32,
        flip_normals: bool,
    },
}

/// A world-space triangle mesh. `normals` and `uvs` are either empty or one per vertex.
#[derive(Debug, Clone, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub indices: Vec<[u32; 3]>,
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
#[derive(Debug, Clone)]
pub enum TextureDesc {
    Value(SpectrumDesc),
    Bitmap(Arc<BitmapTexture>),
    Checkerboard {
        color0: SpectrumDesc,
        color1: SpectrumDesc,
        to_uv: Mat3,
    },
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
#[derive(Debug, Clone)]
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

/// Surface scattering models. Roughness `alpha` is the GGX α; 0 means perfectly smooth.
#[derive(Debug, Clone)]
pub enum BsdfDesc {
    Diffuse {
        reflectance: TextureDesc,
    },
    Conductor {
        eta: Ior,
        alpha_u: f32,
        alpha_v: f32,
    },
    Dielectric {
        int_ior: Ior,
        ext_ior: Ior,
        alpha: f32,
    },
    Plastic {
        diffuse_reflectance: TextureDesc,
        int_ior: f32,
        ext_ior: f32,
        alpha: f32,
        nonlinear: bool,
    },
    TwoSided(Box<BsdfDesc>),
    /// Opaque thin film on a substrate (design.md): Airy Fresnel term, optional GGX roughness.
    ThinFilm {
        film_ior: Ior,
        thickness_nm: TextureDesc,
        substrate_ior: Ior,
        alpha: f32,
    },
}

impl BsdfDesc {
    /// The default BSDF (Mitsuba: diffuse, reflectance 0.5).
    pub fn default_diffuse() -> Self {
        BsdfDesc::Diffuse {
            reflectance: TextureDesc::Value(SpectrumDesc::Constant(0.5)),
        }
    }
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
}
