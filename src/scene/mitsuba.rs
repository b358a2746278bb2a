//! Mitsuba 3 XML scenes: the parser, Mitsuba's scene-description mechanics and the plugins
//! the renderer can draw as Mitsuba draws them. docs/mitsuba-support.md lists every
//! supported plugin and parameter, Mitsuba's defaults where one is omitted, and each
//! deviation. BSDFs are the models registered in [`crate::render::bsdf`], each built by its
//! own builder from [`PluginParams`] (the typed parameter access of [`params`]).
//!
//! Mechanics: `<scene version>`, `<include>`, `<path>`, `<default>` / `$param` (with `-D`
//! overrides), `id` / `<ref>` / `<alias>`, transforms composed in document order (each new
//! operation applied after the previous ones, M ← op · M), `shapegroup` / `instance`.
//!
//! Everything else — elements, attributes, parameters, plugin types, values a plugin would
//! need a model the renderer lacks (Beckmann microfacets, anisotropic roughness, scaled
//! specular lobes, RGB-valued indices) — is an error naming the file, line:column, element,
//! plugin and parameter. No plugin is silently replaced by another; parameters that change
//! nothing in the image (e.g. `focus_distance` on a pinhole camera) are accepted as Mitsuba
//! accepts them, and wrapper integrators say on stderr what they ignore.

// `!(x >= 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod medium;
mod params;
mod ply_attributes;

pub use params::{parse_layers, PluginParams, RealSpectrum};

use super::{
    look_at, shapes, BitmapTexture, Camera, EmitterDesc, FilmSettings, FovAxis, Geometry,
    IntegratorSettings, Polarizer, Projection, ReconstructionFilter, SamplerKind, Scene, Shape,
    SpectrumDesc, SpotCone, TextureDesc, TextureFilter, TriangleMesh, WrapMode,
};
use crate::optics::Ior;
use crate::render::bsdf::{self, Bsdf};
use anyhow::{anyhow, bail, Result};
use glam::{Mat3, Mat4, Vec2, Vec3};
use roxmltree::{Document, Node};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use typed_arena::Arena;

/// Mitsuba 3's named refractive indices (`include/mitsuba/render/ior.h`), used for
/// `dielectric`/`plastic` `int_ior`/`ext_ior` strings. Constants, as in Mitsuba.
pub const MITSUBA_IOR_TABLE: &[(&str, f64)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

/// Looks up a Mitsuba IOR name (case-insensitive).
pub fn mitsuba_ior(name: &str) -> Option<f64> {
    MITSUBA_IOR_TABLE
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(name.trim()))
        .map(|&(_, v)| v)
}

/// Loads a Mitsuba XML file. Relative file names resolve as in Mitsuba: against the `<path>`
/// directories (the last declared first), then the scene file's directory, then the current
/// directory.
pub fn load_file(path: &Path, defaults: &[(String, String)]) -> Result<Scene> {
    let text = crate::limits::read_text(path, "scene file", 16)?;
    let base = path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let mut scene = load_str(&text, &base, defaults, &path.display().to_string())?;
    scene.source = Some(path.to_path_buf());
    Ok(scene)
}

/// Parses XML text. `base_dir` resolves relative file names; `file_name` is used in messages.
pub fn load_str(
    text: &str,
    base_dir: &Path,
    defaults: &[(String, String)],
    file_name: &str,
) -> Result<Scene> {
    // Included files are parsed while the scene is walked; the arenas keep every file's text
    // and document alive for as long as the nodes borrowed from them.
    let texts: Arena<String> = Arena::new();
    let docs: Arena<Document> = Arena::new();
    let text: &str = texts.alloc(text.to_string());
    let doc: &Document =
        docs.alloc(Document::parse(text).map_err(|e| anyhow!("{file_name}: malformed XML: {e}"))?);
    let mut search_paths = vec![base_dir.to_path_buf()];
    if let Ok(cwd) = std::env::current_dir() {
        search_paths.push(cwd);
    }
    let mut ctx = Ctx {
        texts: &texts,
        docs: &docs,
        files: vec![SourceFile::new(
            doc,
            file_name.to_string(),
            base_dir.to_path_buf(),
        )],
        include_stack: Vec::new(),
        included_bytes: 0,
        search_paths,
        params: Vec::new(),
        pending: HashMap::new(),
        built: HashSet::new(),
        ids: HashMap::new(),
        bsdfs: Vec::new(),
        mesh_attributes: Default::default(),
        shapes: Vec::new(),
        emitters: Vec::new(),
        sensor: None,
        integrator: None,
        integrator_plugin: None,
        media: Vec::new(),
        shape_media: Vec::new(),
        depth: 0,
        instanced_triangles: 0,
        direct_strategies: None,
    };
    ctx.parse_scene(doc.root_element(), defaults)
}

// ------------------------------------------------------------------------------------------
// Parsed values

#[derive(Debug, Clone)]
enum Emitter {
    Area(SpectrumDesc),
    Other(EmitterDesc),
}

#[derive(Debug, Clone)]
struct Sensor {
    camera: Camera,
    film: FilmSettings,
    spp: u32,
    seed: u64,
    sampler: SamplerKind,
    polarizer: Option<Polarizer>,
    /// The sensor's medium (index into the parser's media).
    medium: Option<u32>,
}

#[derive(Debug, Clone)]
enum Val {
    Float(f64),
    Int(i64),
    Bool(bool),
    Str(String),
    Rgb([f32; 3]),
    Spectrum(SpectrumDesc),
    Point(Vec3),
    Vector(Vec3),
    Transform(Mat4),
    Texture(TextureDesc),
    /// An inline BSDF.
    Bsdf(Bsdf),
    /// A reference to a BSDF already in the scene list.
    BsdfRef(usize),
    Emitter(Emitter),
    Film(FilmSettings),
    Sampler(u32, u64, SamplerKind),
    Rfilter(ReconstructionFilter),
    Shapes(Shapes),
    /// A reference to a `shapegroup` (the child of an `instance`).
    ShapeGroup(Arc<Vec<Shape>>),
    Sensor(Box<Sensor>),
    Integrator(IntegratorSettings),
    /// A participating medium (index into the parser's media).
    Medium(u32),
    Phase(crate::render::medium::Phase),
    /// A `constvolume`'s value (an RGB is upsampled unbounded, as Mitsuba's `constvolume`).
    ConstVolume(SpectrumDesc),
}

/// What a `<shape>` element yields.
#[derive(Debug, Clone)]
enum Shapes {
    /// Shapes of the scene: one, or several for an `instance` of a multi-shape group, and
    /// the [interior, exterior] media they bound (`medium::NO_MEDIUM`: none).
    Plain(Vec<Shape>, [u32; 2]),
    /// A `shapegroup`: shapes drawn only through `instance`s.
    Group(Vec<Shape>),
}

impl Val {
    fn kind(&self) -> &'static str {
        match self {
            Val::Float(_) => "float",
            Val::Int(_) => "integer",
            Val::Bool(_) => "boolean",
            Val::Str(_) => "string",
            Val::Rgb(_) => "rgb",
            Val::Spectrum(_) => "spectrum",
            Val::Point(_) => "point",
            Val::Vector(_) => "vector",
            Val::Transform(_) => "transform",
            Val::Texture(_) => "texture",
            Val::Bsdf(_) | Val::BsdfRef(_) => "bsdf",
            Val::Emitter(_) => "emitter",
            Val::Film(_) => "film",
            Val::Sampler(..) => "sampler",
            Val::Rfilter(_) => "rfilter",
            Val::Shapes(_) | Val::ShapeGroup(_) => "shape",
            Val::Sensor(_) => "sensor",
            Val::Integrator(_) => "integrator",
            Val::Medium(_) => "medium",
            Val::Phase(_) => "phase",
            Val::ConstVolume(_) => "volume",
        }
    }
}

/// A value registered under an `id`.
#[derive(Debug, Clone)]
enum Named {
    Bsdf(usize),
    Texture(TextureDesc),
    Value(Val),
    Shape,
    Emitter,
    /// The shapes of a `shapegroup`, in the group's space.
    ShapeGroup(Arc<Vec<Shape>>),
    Medium(u32),
}

struct Prop<'a, 'i> {
    name: String,
    val: Val,
    node: Node<'a, 'i>,
}

/// The parameters of one plugin element, consumed one by one; leftovers are errors.
struct Props<'a, 'i> {
    node: Node<'a, 'i>,
    tag: String,
    plugin: String,
    list: Vec<Prop<'a, 'i>>,
}

struct Ctx<'a, 'i> {
    /// Texts and parsed documents of the scene file and every file it includes.
    texts: &'i Arena<String>,
    docs: &'a Arena<Document<'i>>,
    files: Vec<SourceFile>,
    /// Canonical paths of the `<include>` files being expanded (cycle detection).
    include_stack: Vec<PathBuf>,
    /// Bytes of every included file read so far (an include tree without cycles can still
    /// expand exponentially: ten includes of a file that includes ten …).
    included_bytes: u64,
    /// Mitsuba's file resolver: directories searched in order for relative file names.
    search_paths: Vec<PathBuf>,
    /// `$name` substitutions, longest name first (Mitsuba substitutes in that order).
    params: Vec<Param>,
    /// Top-level objects with an `id`, not built yet: a `<ref>` may name an object declared
    /// later in the file (Mitsuba resolves references after parsing).
    pending: HashMap<String, Node<'a, 'i>>,
    /// Top-level objects already built on demand by a forward `<ref>`.
    built: HashSet<NodeKey>,
    ids: HashMap<String, Named>,
    bsdfs: Vec<Bsdf>,
    shapes: Vec<Shape>,
    emitters: Vec<EmitterDesc>,
    sensor: Option<Sensor>,
    integrator: Option<IntegratorSettings>,
    /// The integrator's plugin name, once read.
    integrator_plugin: Option<String>,
    /// Participating media declared so far, and the shapes that bound them.
    media: Vec<crate::render::medium::Medium>,
    shape_media: Vec<(u32, [u32; 2])>,
    /// Triangles added by flattening `instance`s so far.
    instanced_triangles: usize,
    /// A `direct` integrator's strategies (emitter sampling, BSDF sampling), checked against
    /// the scene's lights and BSDFs once everything is loaded.
    direct_strategies: Option<(Node<'a, 'i>, u32, bool)>,
    /// Objects being parsed around the current one (nesting depth).
    depth: usize,
    /// Attribute names of the scene's `mesh_attribute` textures (a mesh supplies one, as the
    /// interpolated colour of its shading points).
    mesh_attributes: std::collections::BTreeSet<String>,
}

/// A node's identity across documents: (document address, node id).
type NodeKey = (usize, roxmltree::NodeId);

fn node_key(node: Node) -> NodeKey {
    (node.document() as *const Document as usize, node.id())
}

/// One parsed XML file: its document (by address), name for messages and directory.
struct SourceFile {
    doc: usize,
    label: String,
    dir: PathBuf,
    /// Written for Mitsuba 0.x (`version` < 2.0): parameter names are upgraded.
    v1: bool,
}

impl SourceFile {
    fn new(doc: &Document, label: String, dir: PathBuf) -> Self {
        SourceFile {
            doc: doc as *const Document as usize,
            label,
            dir,
            v1: false,
        }
    }
}

/// A `$name` parameter: from `-D` (`cli`) or a `<default>`.
struct Param {
    name: String,
    value: String,
    cli: bool,
    /// Also declared by a `<default>` (for `-D` checks).
    declared: bool,
    used: std::cell::Cell<bool>,
}

/// Mitsuba's include depth limit (`ParserConfig::max_include_depth`).
const MAX_INCLUDE_DEPTH: usize = 15;

/// Most `<include>` expansions in one scene (real scenes use a few dozen; without a cap, a
/// tree of repeated includes 15 deep expands ten-fold per level).
const MAX_INCLUDES: usize = 10_000;

/// A child element of an object after `<include>` expansion, with the property name an
/// `<include name="…">` gives an included non-scene object.
#[derive(Clone)]
struct Child<'a, 'i> {
    node: Node<'a, 'i>,
    name: Option<String>,
}

/// Scene properties Mitsuba's `Scene` accepts for its acceleration structure (Embree,
/// kd-tree); they do not change the image.
const SCENE_ACCEL_PROPS: &[&str] = &[
    "embree_use_robust_intersections",
    "kd_intersection_cost",
    "kd_traversal_cost",
    "kd_empty_space_bonus",
    "kd_stop_prims",
    "kd_max_depth",
    "kd_min_max_bins",
    "kd_clip",
    "kd_retract_bad_splits",
    "kd_exact_primitive_threshold",
];

/// Deepest nesting of objects (a BSDF inside a BSDF inside a shape …) accepted; real scenes
/// stay below 5, and the parser recurses once per level.
const MAX_NESTING: usize = 32;

/// Physical domains of numeric parameters, by name: Mitsuba gives each name one meaning
/// across plugins, so one table checks every plugin's parameters as they are collected —
/// finite, and inside these closed ranges (`(names, lowest, highest)`). Spectra and RGB
/// values are checked component by component.
const DOMAINS: &[(&[&str], f64, f64)] = &[
    (
        &[
            "reflectance",
            "diffuse_reflectance",
            "specular_reflectance",
            "specular_transmittance",
            "transmittance",
            "color0",
            "color1",
            "radiance",
            "intensity",
            "irradiance",
            "scale",
        ],
        0.0,
        f32::MAX as f64,
    ),
    (
        &["radius", "near_clip", "far_clip"],
        f32::MIN_POSITIVE as f64,
        f32::MAX as f64,
    ),
    (&["stddev"], f32::MIN_POSITIVE as f64, 32.0),
    (&["alpha", "alpha_u", "alpha_v"], 0.0, 10.0),
    (
        &["int_ior", "ext_ior", "film_ior", "substrate_ior", "eta"],
        f32::MIN_POSITIVE as f64,
        crate::limits::MAX_IOR,
    ),
    (&["k", "substrate_k"], 0.0, crate::limits::MAX_EXTINCTION),
    (&["thickness"], 0.0, crate::limits::MAX_THICKNESS_NM),
];

const OBJECT_TAGS: &[&str] = &[
    "medium",
    "phase",
    "volume",
    "shape",
    "bsdf",
    "texture",
    "emitter",
    "sensor",
    "film",
    "sampler",
    "integrator",
    "rfilter",
];

/// A number as scene files may hold it: finite and within single precision (the renderer's
/// geometry and spectra are f32; `1e39` would silently become infinity).
fn parse_f64(s: &str) -> Option<f64> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && v.abs() <= f32::MAX as f64)
}

/// Splits "1, 2, 3" or "1 2 3".
fn parse_list(s: &str) -> Option<Vec<f64>> {
    s.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(parse_f64)
        .collect()
}

impl<'a, 'i> Ctx<'a, 'i> {
    // ---------------------------------------------------------------- messages and attributes

    fn file_of(&self, doc: &Document) -> &SourceFile {
        let addr = doc as *const Document as usize;
        self.files
            .iter()
            .find(|f| f.doc == addr)
            .unwrap_or(&self.files[0])
    }

    fn loc(&self, node: Node) -> String {
        let doc = node.document();
        let p = doc.text_pos_at(node.range().start);
        format!("{}:{}:{}", self.file_of(doc).label, p.row, p.col)
    }

    fn describe(node: Node) -> String {
        let tag = node.tag_name().name();
        match (node.attribute("type"), node.attribute("name")) {
            (Some(t), _) => format!("<{tag} type=\"{t}\">"),
            (None, Some(n)) => format!("<{tag} name=\"{n}\">"),
            _ => format!("<{tag}>"),
        }
    }

    fn err(&self, node: Node, msg: impl std::fmt::Display) -> anyhow::Error {
        anyhow!("{}: {}: {msg}", self.loc(node), Self::describe(node))
    }

    /// Rejects attributes not in `allowed`.
    fn check_attrs(&self, node: Node, allowed: &[&str]) -> Result<()> {
        for a in node.attributes() {
            if !allowed.contains(&a.name()) {
                let doc = node.document();
                let p = doc.text_pos_at(a.range().start);
                bail!(
                    "{}:{}:{}: {}: unknown attribute '{}' (allowed: {})",
                    self.file_of(doc).label,
                    p.row,
                    p.col,
                    Self::describe(node),
                    a.name(),
                    allowed.join(", ")
                );
            }
        }
        Ok(())
    }

    /// Attribute value with `$param` substituted.
    fn attr(&self, node: Node, name: &str) -> Result<Option<String>> {
        match node.attribute(name) {
            None => Ok(None),
            Some(v) => Ok(Some(self.substitute(node, v)?)),
        }
    }

    fn req_attr(&self, node: Node, name: &str) -> Result<String> {
        self.attr(node, name)?
            .ok_or_else(|| self.err(node, format!("missing attribute '{name}'")))
    }

    /// Mitsuba's parameter substitution (`parser.cpp`): every `$name` of every parameter,
    /// longest name first, is replaced by its value unless escaped as `\$`; a `$` left over
    /// is an undefined parameter; `\$` then becomes `$`.
    fn substitute(&self, node: Node, value: &str) -> Result<String> {
        if !value.contains('$') {
            return Ok(value.to_string());
        }
        let mut out = value.to_string();
        for p in &self.params {
            let key = format!("${}", p.name);
            let mut pos = 0;
            while let Some(found) = out[pos..].find(&key) {
                let at = pos + found;
                if at > 0 && out.as_bytes()[at - 1] == b'\\' {
                    pos = at + key.len();
                } else {
                    out.replace_range(at..at + key.len(), &p.value);
                    p.used.set(true);
                    pos = at + p.value.len();
                }
            }
        }
        let bytes = out.as_bytes();
        for (i, _) in out.match_indices('$') {
            if i > 0 && bytes[i - 1] == b'\\' {
                continue;
            }
            let name: String = out[i + 1..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            return Err(self.err(
                node,
                if name.is_empty() {
                    format!("stray '$' in attribute value \"{value}\"")
                } else {
                    format!(
                        "undefined parameter ${name} (declare <default name=\"{name}\" value=\"…\"/> or pass -D {name}=…)"
                    )
                },
            ));
        }
        Ok(out.replace("\\$", "$"))
    }

    /// Adds a parameter unless one of that name exists (a `-D` value or an earlier
    /// `<default>` wins, as in Mitsuba).
    fn add_param(&mut self, name: &str, value: &str, cli: bool) {
        if let Some(p) = self.params.iter_mut().find(|p| p.name == name) {
            p.declared |= !cli;
            return;
        }
        let at = self
            .params
            .iter()
            .position(|p| p.name.len() < name.len())
            .unwrap_or(self.params.len());
        self.params.insert(
            at,
            Param {
                name: name.to_string(),
                value: value.to_string(),
                cli,
                declared: !cli,
                used: std::cell::Cell::new(false),
            },
        );
    }

    /// Mitsuba's file resolver: an absolute name as is, otherwise the first of the search
    /// directories (`<path>` entries, the scene's directory, the current directory) where
    /// it exists.
    fn resolve_path(&self, node: Node, file: &str) -> Result<PathBuf> {
        self.resolve_in(node, file, &[])
    }

    /// [`resolve_path`](Self::resolve_path) with `first` searched before the resolver.
    fn resolve_in(&self, node: Node, file: &str, first: &[PathBuf]) -> Result<PathBuf> {
        let p = Path::new(file);
        let not_a_file = |f: &Path| {
            self.err(
                node,
                format!(
                    "'{}' is not a regular file (a folder or a device)",
                    f.display()
                ),
            )
        };
        if p.is_absolute() {
            if p.is_file() {
                return Ok(p.to_path_buf());
            }
            if p.exists() {
                return Err(not_a_file(p));
            }
            return Err(self.err(node, format!("file '{file}' not found")));
        }
        let dirs: Vec<&PathBuf> = first.iter().chain(&self.search_paths).collect();
        if let Some(found) = dirs.iter().map(|d| d.join(p)).find(|f| f.is_file()) {
            return Ok(found);
        }
        if let Some(other) = dirs.iter().map(|d| d.join(p)).find(|f| f.exists()) {
            return Err(not_a_file(&other));
        }
        let looked: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
        Err(self.err(
            node,
            format!(
                "file '{file}' not found (searched {}; add a <path value=\"…\"/> or fix the name)",
                looked.join(", ")
            ),
        ))
    }

    fn elements(node: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
        node.children().filter(|c| c.is_element())
    }

    /// The element children of `node` in document order, with `<include>`s replaced by the
    /// included file's elements and `<default>`s registered (Mitsuba allows both anywhere).
    /// `<path>` is only allowed as a child of the root element (handled before the walk).
    fn children(&mut self, node: Node<'a, 'i>) -> Result<Vec<Child<'a, 'i>>> {
        let mut out = Vec::new();
        for c in Self::elements(node) {
            match c.tag_name().name() {
                "default" => {
                    self.check_attrs(c, &["name", "value"])?;
                    let name = self.req_attr(c, "name")?;
                    let value = self.req_attr(c, "value")?;
                    if name.is_empty() {
                        return Err(self.err(c, "<default>: name must not be empty"));
                    }
                    self.add_param(&name, &value, false);
                }
                "include" => out.extend(self.include(c)?),
                "path" => {
                    let root = node.parent().is_some_and(|p| p.is_root());
                    if !root {
                        return Err(self.err(c, "<path> can only be a child of the root <scene>"));
                    }
                }
                _ => out.push(Child {
                    node: c,
                    name: None,
                }),
            }
        }
        Ok(out)
    }

    /// Expands `<include filename="…" [name="…"]/>`: the included file's root element, or —
    /// when that root is a `<scene>` — its children. The file is found in the including
    /// file's directory first, then through the resolver (Mitsuba's order).
    fn include(&mut self, node: Node<'a, 'i>) -> Result<Vec<Child<'a, 'i>>> {
        self.check_attrs(node, &["filename", "name"])?;
        let file = self.req_attr(node, "filename")?;
        let here = self.file_of(node.document()).dir.clone();
        let path = self.resolve_in(node, &file, &[here])?;
        let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
        if self.include_stack.contains(&canonical) {
            let chain: Vec<String> = self
                .include_stack
                .iter()
                .chain([&canonical])
                .map(|p| p.display().to_string())
                .collect();
            return Err(self.err(node, format!("<include> cycle: {}", chain.join(" → "))));
        }
        if self.include_stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(self.err(
                node,
                format!("<include> nested deeper than {MAX_INCLUDE_DEPTH} files"),
            ));
        }
        if self.files.len() > MAX_INCLUDES {
            return Err(self.err(
                node,
                format!("more than {MAX_INCLUDES} <include> expansions in one scene"),
            ));
        }
        let label = path.display().to_string();
        let text = crate::limits::read_text(&path, "included file", 16)
            .map_err(|e| self.err(node, format!("{e:#}")))?;
        self.included_bytes += text.len() as u64;
        crate::limits::check_alloc(
            format!(
                "the files <include>d so far ({} bytes)",
                self.included_bytes
            ),
            self.included_bytes.saturating_mul(16),
        )
        .map_err(|e| self.err(node, format!("{e:#}")))?;
        let text: &'i str = self.texts.alloc(text);
        let doc: &'a Document<'i> =
            self.docs.alloc(Document::parse(text).map_err(|e| {
                self.err(node, format!("included file {label}: malformed XML: {e}"))
            })?);
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        self.files.push(SourceFile::new(doc, label, dir));
        let root = doc.root_element();
        self.check_version(root)?;
        let name = self.attr(node, "name")?;
        if root.tag_name().name() != "scene" {
            return Ok(vec![Child { node: root, name }]);
        }
        // `<path>` in an included scene only serves that file's own includes (Mitsuba
        // applies it to a resolver that is discarded after the include).
        let saved_paths = self.search_paths.clone();
        for p in Self::elements(root).filter(|c| c.tag_name().name() == "path") {
            self.add_search_path(p)?;
        }
        self.include_stack.push(canonical);
        let children = self.children(root);
        self.include_stack.pop();
        self.search_paths = saved_paths;
        children
    }

    /// `<path value="DIR"/>`: DIR (relative to the file's directory, else through the
    /// resolver) is searched first from now on.
    fn add_search_path(&mut self, node: Node) -> Result<()> {
        self.check_attrs(node, &["value"])?;
        let value = self.req_attr(node, "value")?;
        let p = Path::new(&value);
        let dir = if p.is_absolute() {
            p.to_path_buf()
        } else {
            let here = self.file_of(node.document()).dir.join(p);
            if here.is_dir() {
                here
            } else {
                self.search_paths
                    .iter()
                    .map(|d| d.join(p))
                    .find(|d| d.is_dir())
                    .unwrap_or(here)
            }
        };
        if !dir.is_dir() {
            return Err(self.err(
                node,
                format!("<path>: folder \"{}\" not found", dir.display()),
            ));
        }
        self.search_paths.insert(0, dir);
        Ok(())
    }

    // ---------------------------------------------------------------- scene

    fn parse_scene(&mut self, root: Node<'a, 'i>, overrides: &[(String, String)]) -> Result<Scene> {
        if root.tag_name().name() != "scene" {
            return Err(self.err(root, "the root element must be <scene version=\"3.0.0\">"));
        }
        self.check_attrs(root, &["version"])?;
        self.check_version(root)?;
        for (k, v) in overrides {
            self.add_param(k, v, true);
        }
        // `<path>` entries apply to every file name of the scene (Mitsuba resolves them when
        // the plugins are built, after the whole file is parsed).
        for c in Self::elements(root).filter(|c| c.tag_name().name() == "path") {
            self.add_search_path(c)?;
        }
        let children = self.children(root)?;
        for c in &children {
            if OBJECT_TAGS.contains(&c.node.tag_name().name()) {
                if let Some(id) = self.attr(c.node, "id")? {
                    self.pending.entry(id).or_insert(c.node);
                }
            }
        }
        for Child { node: c, .. } in children {
            if self.built.contains(&node_key(c)) {
                continue;
            }
            if let Some(id) = self.attr(c, "id")? {
                if self
                    .pending
                    .get(&id)
                    .is_some_and(|n| node_key(*n) == node_key(c))
                {
                    self.pending.remove(&id);
                }
            }
            self.top_level(c)?;
        }
        self.check_overrides()?;
        self.check_direct_strategies()?;
        let integrator = self.integrator.unwrap_or_default();
        let sensor_medium = self.sensor.as_ref().and_then(|s| s.medium);
        let (camera, film, spp, seed, sampler, polarizer) = match self.sensor.clone() {
            Some(s) => (s.camera, s.film, s.spp, s.seed, s.sampler, s.polarizer),
            None => (
                mitsuba_default_camera(super::shapes_bounds(&self.shapes)),
                FilmSettings {
                    width: 768,
                    height: 576,
                    filter: ReconstructionFilter::Gaussian { stddev: 0.5 },
                },
                4,
                0,
                SamplerKind::Independent,
                None,
            ),
        };
        Ok(Scene {
            camera,
            film,
            integrator,
            spp,
            seed,
            sampler,
            shapes: std::mem::take(&mut self.shapes),
            bsdfs: std::mem::take(&mut self.bsdfs),
            emitters: std::mem::take(&mut self.emitters),
            polarizer,
            source: None,
            media: self.scene_media(sensor_medium)?,
        })
    }

    /// Checks `<scene version="X.Y.Z">`; files older than 2.0 get Mitsuba's upgrade
    /// (camelCase parameter names to snake_case) when their objects are read.
    fn check_version(&mut self, root: Node) -> Result<()> {
        let version = root.attribute("version").ok_or_else(|| {
            self.err(root, "missing attribute 'version' (e.g. version=\"3.0.0\")")
        })?;
        let major = version
            .split('.')
            .next()
            .and_then(|m| m.trim().parse::<u32>().ok())
            .ok_or_else(|| {
                self.err(
                    root,
                    format!("version \"{version}\" is not a version number"),
                )
            })?;
        let addr = root.document() as *const Document as usize;
        if let Some(f) = self.files.iter_mut().find(|f| f.doc == addr) {
            f.v1 = major < 2;
        }
        Ok(())
    }

    /// One child of the scene (after include expansion).
    fn top_level(&mut self, c: Node<'a, 'i>) -> Result<()> {
        match c.tag_name().name() {
            "shape" | "bsdf" | "texture" | "emitter" | "sensor" | "integrator" | "medium"
            | "phase" | "volume" | "film" | "sampler" | "rfilter" => {
                let val = self.parse_object(c)?;
                self.add_top_level(c, val)?;
            }
            "float" | "integer" | "boolean" | "string" | "rgb" | "spectrum" | "point"
            | "vector"
                if c.attribute("id").is_none()
                    && c.attribute("name")
                        .is_some_and(|n| SCENE_ACCEL_PROPS.contains(&n)) =>
            {
                // Options of Mitsuba's ray-tracing back end: no effect on the image.
                self.parse_value(c)?;
            }
            "float" | "integer" | "boolean" | "string" | "rgb" | "spectrum" | "point"
            | "vector" => {
                // A named top-level value usable through <ref>.
                let (_, val) = self.parse_value(c)?;
                let id = self
                    .req_attr(c, "id")
                    .map_err(|_| self.err(c, "a top-level value needs an 'id' to be referenced"))?;
                self.register(c, id, Named::Value(val))?;
            }
            "alias" => {
                self.check_attrs(c, &["id", "as"])?;
                let id = self.req_attr(c, "id")?;
                let alias = self.req_attr(c, "as")?;
                let named = self.lookup(c, &id)?;
                self.register(c, alias, named)?;
            }
            _ => return Err(self.unknown_element(c, "<scene>")),
        }
        Ok(())
    }

    /// The object or value registered under `id`; a top-level object declared later in the
    /// file is built now (forward reference).
    fn lookup(&mut self, node: Node, id: &str) -> Result<Named> {
        if let Some(n) = self.ids.get(id) {
            return Ok(n.clone());
        }
        if let Some(target) = self.pending.remove(id) {
            self.built.insert(node_key(target));
            self.top_level(target)?;
            if let Some(n) = self.ids.get(id) {
                return Ok(n.clone());
            }
        }
        Err(self.err(
            node,
            format!("reference to unknown id \"{id}\" (or a circular reference)"),
        ))
    }

    /// A `direct` integrator without one of its strategies misses light the path tracer
    /// finds (see [`direct_integrator`](Self::direct_integrator)): refused when that light
    /// exists in this scene. With several emitter samples, Mitsuba 3.9 adds every sample of a
    /// delta light (point) at full weight — its MIS weight for delta lights lacks the
    /// 1/`emitter_samples` factor (`direct.cpp`) — so point lights come out
    /// `emitter_samples` times brighter; thinfilm scales them to render what Mitsuba renders.
    fn check_direct_strategies(&mut self) -> Result<()> {
        let Some((node, emitter_samples, bsdf_sampling)) = self.direct_strategies else {
            return Ok(());
        };
        let is_delta = |e: &EmitterDesc| {
            matches!(
                e,
                EmitterDesc::Point { .. }
                    | EmitterDesc::Spot { .. }
                    | EmitterDesc::Directional { .. }
                    | EmitterDesc::Projector { .. }
                    | EmitterDesc::TexturedSpot { .. }
            )
        };
        let has_point = self.emitters.iter().any(is_delta);
        if emitter_samples > 1 && has_point {
            eprintln!(
                "note: {}: direct with emitter_samples = {emitter_samples}: point lights are {emitter_samples}× as bright, as Mitsuba renders them (its delta-light weight omits 1/emitter_samples)",
                self.loc(node)
            );
            for e in &mut self.emitters {
                match e {
                    EmitterDesc::Point { intensity, .. }
                    | EmitterDesc::Spot { intensity, .. }
                    | EmitterDesc::TexturedSpot { intensity, .. } => {
                        *intensity = scaled_spectrum(intensity, emitter_samples as f32)
                    }
                    EmitterDesc::Directional { irradiance, .. } => {
                        *irradiance = scaled_spectrum(irradiance, emitter_samples as f32)
                    }
                    EmitterDesc::Projector { scale, .. } => *scale *= emitter_samples as f32,
                    _ => {}
                }
            }
        }
        if emitter_samples == 0 && has_point {
            return Err(self.err(
                node,
                "direct with emitter_samples = 0 in a scene with point lights is not supported (Mitsuba never reaches them; thinfilm's path tracer would)",
            ));
        }
        if !bsdf_sampling
            && self.shapes.iter().any(|s| {
                self.bsdfs[s.bsdf]
                    .flags()
                    .intersects(bsdf::BsdfFlags::DELTA)
            })
        {
            return Err(self.err(
                node,
                "direct with bsdf_samples = 0 in a scene with smooth (delta) BSDFs is not supported (Mitsuba shows them black; thinfilm's path tracer would not)",
            ));
        }
        Ok(())
    }

    /// Every `-D name=value` must name a parameter the scene declares or uses (Mitsuba
    /// rejects unused parameters).
    fn check_overrides(&self) -> Result<()> {
        if let Some(p) = self
            .params
            .iter()
            .find(|p| p.cli && !p.declared && !p.used.get())
        {
            let mut names: Vec<&str> = self
                .params
                .iter()
                .filter(|p| p.declared)
                .map(|p| p.name.as_str())
                .collect();
            names.sort_unstable();
            bail!(
                "{}: -D {}={}: the scene has no parameter ${} (declared: {})",
                self.files[0].label,
                p.name,
                p.value,
                p.name,
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            );
        }
        Ok(())
    }

    fn unknown_element(&self, node: Node, parent: &str) -> anyhow::Error {
        self.err(
            node,
            format!(
                "unsupported element <{}> inside {parent}",
                node.tag_name().name()
            ),
        )
    }

    fn register(&mut self, node: Node, id: String, named: Named) -> Result<()> {
        if self.ids.contains_key(&id) {
            return Err(self.err(node, format!("duplicate id \"{id}\"")));
        }
        self.ids.insert(id, named);
        Ok(())
    }

    fn add_top_level(&mut self, node: Node<'a, 'i>, val: Val) -> Result<()> {
        let id = self.attr(node, "id")?;
        match val {
            Val::Bsdf(b) => {
                self.bsdfs.push(b);
                let idx = self.bsdfs.len() - 1;
                if let Some(id) = id {
                    self.register(node, id, Named::Bsdf(idx))?;
                }
            }
            Val::Texture(t) => {
                let id = id.ok_or_else(|| self.err(node, "a top-level texture needs an 'id'"))?;
                self.register(node, id, Named::Texture(t))?;
            }
            Val::Emitter(Emitter::Other(e)) => {
                self.emitters.push(e);
                if let Some(id) = id {
                    self.register(node, id, Named::Emitter)?;
                }
            }
            // Objects a shape or sensor takes by <ref>: Mitsuba keeps them by id; one that
            // is never referenced does nothing (an area emitter lights only a shape).
            v @ (Val::Emitter(Emitter::Area(_))
            | Val::Film(_)
            | Val::Sampler(..)
            | Val::Rfilter(_)) => match id {
                Some(id) => self.register(node, id, Named::Value(v))?,
                None => eprintln!(
                    "note: {}: a top-level {} without an id is not used by anything",
                    self.loc(node),
                    v.kind()
                ),
            },
            Val::Shapes(Shapes::Group(shapes)) => {
                let id = id.ok_or_else(|| {
                    self.err(node, "a shapegroup needs an 'id' (instances refer to it)")
                })?;
                self.register(node, id, Named::ShapeGroup(Arc::new(shapes)))?;
            }
            Val::Shapes(Shapes::Plain(shapes, media)) => {
                self.add_shape_media(shapes.len(), media);
                self.shapes.extend(shapes);
                if let Some(id) = id {
                    self.register(node, id, Named::Shape)?;
                }
            }
            Val::Sensor(s) => {
                if self.sensor.is_some() {
                    // mi.render(scene) renders the first sensor unless told otherwise.
                    eprintln!(
                        "note: {}: the scene has several sensors; rendering the first (as Mitsuba's render does by default)",
                        self.loc(node)
                    );
                } else {
                    self.sensor = Some(*s);
                }
            }
            Val::Medium(i) => match id {
                Some(id) => self.register(node, id, Named::Medium(i))?,
                None => eprintln!(
                    "note: {}: a top-level medium without an id is not used by anything",
                    self.loc(node)
                ),
            },
            Val::Integrator(s) => {
                if self.integrator.is_some() {
                    return Err(self.err(node, "only one <integrator> is supported"));
                }
                self.integrator = Some(s);
            }
            other => {
                return Err(self.err(
                    node,
                    format!("a {} cannot be a child of <scene>", other.kind()),
                ))
            }
        }
        Ok(())
    }

    // ---------------------------------------------------------------- values

    /// Parses a value element (`float`, `rgb`, `transform`, …) into (name, value).
    fn parse_value(&mut self, node: Node<'a, 'i>) -> Result<(String, Val)> {
        let tag = node.tag_name().name();
        let name = self.attr(node, "name")?.unwrap_or_default();
        let bad = |ctx: &Self, what: &str, v: &str| ctx.err(node, format!("'{v}' is not {what}"));
        let val = match tag {
            "float" => {
                self.check_attrs(node, &["name", "value", "id"])?;
                let v = self.req_attr(node, "value")?;
                Val::Float(parse_f64(&v).ok_or_else(|| bad(self, "a finite number", &v))?)
            }
            "integer" => {
                self.check_attrs(node, &["name", "value", "id"])?;
                let v = self.req_attr(node, "value")?;
                let n = v
                    .trim()
                    .parse::<i64>()
                    .ok()
                    .or_else(|| {
                        // Mitsuba accepts "64.0"-like integers from parameter substitution.
                        parse_f64(&v).filter(|f| f.fract() == 0.0).map(|f| f as i64)
                    })
                    .ok_or_else(|| bad(self, "an integer", &v))?;
                Val::Int(n)
            }
            "boolean" => {
                self.check_attrs(node, &["name", "value", "id"])?;
                let v = self.req_attr(node, "value")?;
                match v.trim().to_ascii_lowercase().as_str() {
                    "true" | "1" => Val::Bool(true),
                    "false" | "0" => Val::Bool(false),
                    _ => return Err(bad(self, "a boolean (true/false)", &v)),
                }
            }
            "string" => {
                self.check_attrs(node, &["name", "value", "id"])?;
                Val::Str(self.req_attr(node, "value")?)
            }
            "rgb" => {
                self.check_attrs(node, &["name", "value", "id"])?;
                let v = self.req_attr(node, "value")?;
                let l = parse_list(&v).ok_or_else(|| bad(self, "an RGB triple", &v))?;
                let rgb = match l.as_slice() {
                    [x] => [*x as f32; 3],
                    [r, g, b] => [*r as f32, *g as f32, *b as f32],
                    _ => return Err(bad(self, "an RGB value (1 or 3 numbers)", &v)),
                };
                if rgb.iter().any(|c| !c.is_finite()) {
                    return Err(bad(self, "a finite RGB value", &v));
                }
                Val::Rgb(rgb)
            }
            "spectrum" => Val::Spectrum(self.parse_spectrum(node)?),
            "point" | "vector" => {
                self.check_attrs(node, &["name", "value", "x", "y", "z", "id"])?;
                let p = if let Some(v) = self.attr(node, "value")? {
                    let l = parse_list(&v).ok_or_else(|| bad(self, "a 3-vector", &v))?;
                    match l.as_slice() {
                        [x, y, z] => Vec3::new(*x as f32, *y as f32, *z as f32),
                        [x] => Vec3::splat(*x as f32),
                        _ => return Err(bad(self, "a 3-vector", &v)),
                    }
                } else {
                    self.xyz(node, 0.0)?
                };
                if tag == "point" {
                    Val::Point(p)
                } else {
                    Val::Vector(p)
                }
            }
            "transform" => {
                self.check_attrs(node, &["name", "id"])?;
                Val::Transform(self.parse_transform(node)?)
            }
            _ => return Err(self.err(node, "not a value element")),
        };
        if !matches!(tag, "transform") {
            for c in Self::elements(node) {
                if !(tag == "spectrum" && c.tag_name().name() == "float") {
                    return Err(self.unknown_element(c, &Self::describe(node)));
                }
            }
        }
        Ok((name, val))
    }

    /// x/y/z attributes with a default for missing ones.
    fn xyz(&self, node: Node, default: f32) -> Result<Vec3> {
        let mut out = [default; 3];
        for (k, key) in ["x", "y", "z"].iter().enumerate() {
            if let Some(v) = self.attr(node, key)? {
                out[k] = parse_f64(&v).ok_or_else(|| {
                    self.err(node, format!("{key}=\"{v}\" is not a finite number"))
                })? as f32;
            }
        }
        Ok(Vec3::from(out))
    }

    fn vec3_attr(&self, node: Node, key: &str) -> Result<Vec3> {
        let v = self.req_attr(node, key)?;
        match parse_list(&v).as_deref() {
            Some([x, y, z]) => Ok(Vec3::new(*x as f32, *y as f32, *z as f32)),
            _ => Err(self.err(node, format!("{key}=\"{v}\" is not a 3-vector \"x, y, z\""))),
        }
    }

    fn parse_spectrum(&mut self, node: Node<'a, 'i>) -> Result<SpectrumDesc> {
        self.check_attrs(node, &["name", "value", "filename", "type", "id"])?;
        if let Some(t) = self.attr(node, "type")? {
            if t != "d65" {
                return Err(self.err(
                    node,
                    format!("unsupported spectrum type \"{t}\" (only d65)"),
                ));
            }
            let mut scale = 1.0;
            for c in Self::elements(node) {
                if c.tag_name().name() == "float" && c.attribute("name") == Some("scale") {
                    let v = self.req_attr(c, "value")?;
                    scale = parse_f64(&v)
                        .ok_or_else(|| self.err(c, format!("'{v}' is not a finite number")))?
                        as f32;
                } else {
                    return Err(self.err(c, "unsupported parameter of a d65 spectrum (only scale)"));
                }
            }
            return Ok(SpectrumDesc::D65 { scale });
        }
        if let Some(f) = self.attr(node, "filename")? {
            let path = self.resolve_path(node, &f)?;
            return read_spd(&path).map_err(|e| self.err(node, format!("{e:#}")));
        }
        let v = self.req_attr(node, "value")?;
        parse_spectrum_value(&v).map_err(|e| self.err(node, e))
    }

    fn parse_transform(&mut self, node: Node<'a, 'i>) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for c in Self::elements(node) {
            let op = match c.tag_name().name() {
                "translate" => {
                    self.check_attrs(c, &["x", "y", "z", "value"])?;
                    let t = match self.attr(c, "value")? {
                        Some(_) => self.vec3_attr(c, "value")?,
                        None => self.xyz(c, 0.0)?,
                    };
                    Mat4::from_translation(t)
                }
                "scale" => {
                    self.check_attrs(c, &["x", "y", "z", "value"])?;
                    let s = match self.attr(c, "value")? {
                        Some(v) => match parse_list(&v).as_deref() {
                            Some([s]) => Vec3::splat(*s as f32),
                            Some([x, y, z]) => Vec3::new(*x as f32, *y as f32, *z as f32),
                            _ => return Err(self.err(c, format!("value=\"{v}\" is not a scale"))),
                        },
                        None => self.xyz(c, 1.0)?,
                    };
                    Mat4::from_scale(s)
                }
                "rotate" => {
                    self.check_attrs(c, &["x", "y", "z", "value", "angle"])?;
                    let axis = match self.attr(c, "value")? {
                        Some(_) => self.vec3_attr(c, "value")?,
                        None => self.xyz(c, 0.0)?,
                    };
                    let angle = self.req_attr(c, "angle")?;
                    let angle = parse_f64(&angle).ok_or_else(|| {
                        self.err(c, format!("angle=\"{angle}\" is not a finite number"))
                    })?;
                    if axis == Vec3::ZERO {
                        return Err(self.err(c, "rotation axis is zero"));
                    }
                    mitsuba_rotation(axis, angle)
                }
                "matrix" => {
                    self.check_attrs(c, &["value"])?;
                    let v = self.req_attr(c, "value")?;
                    let l = parse_list(&v)
                        .ok_or_else(|| self.err(c, "matrix value must be 9 or 16 numbers"))?;
                    let f: Vec<f32> = l.iter().map(|&x| x as f32).collect();
                    match f.len() {
                        // Row-major in the file; glam is column-major.
                        16 => Mat4::from_cols_slice(&f).transpose(),
                        9 => Mat4::from_mat3(Mat3::from_cols_slice(&f).transpose()),
                        n => {
                            return Err(
                                self.err(c, format!("matrix has {n} numbers, expected 9 or 16"))
                            )
                        }
                    }
                }
                "lookat" => {
                    self.check_attrs(c, &["origin", "target", "up"])?;
                    let origin = self.vec3_attr(c, "origin")?;
                    let target = self.vec3_attr(c, "target")?;
                    let up = match self.attr(c, "up")? {
                        Some(_) => self.vec3_attr(c, "up")?,
                        None => Vec3::Y,
                    };
                    let dir = target - origin;
                    if dir.length_squared() == 0.0 || up.cross(dir).length_squared() == 0.0 {
                        return Err(self.err(c, "degenerate lookat (origin = target or up ∥ view)"));
                    }
                    look_at(origin, target, up)
                }
                _ => return Err(self.unknown_element(c, "<transform>")),
            };
            if !op.is_finite() {
                return Err(self.err(c, "transform has non-finite entries"));
            }
            m = op * m;
        }
        Ok(m)
    }

    // ---------------------------------------------------------------- objects

    fn collect_props(&mut self, node: Node<'a, 'i>) -> Result<Props<'a, 'i>> {
        let tag = node.tag_name().name().to_string();
        let plugin = self
            .attr(node, "type")?
            .ok_or_else(|| self.err(node, "missing attribute 'type'"))?;
        let mut list = Vec::new();
        for Child {
            node: c,
            name: include_name,
        } in self.children(node)?
        {
            let ctag = c.tag_name().name();
            let (name, val) = match ctag {
                "float" | "integer" | "boolean" | "string" | "rgb" | "spectrum" | "point"
                | "vector" | "transform" => {
                    let (name, val) = self.parse_value(c)?;
                    if name.is_empty() {
                        return Err(self.err(c, "missing attribute 'name'"));
                    }
                    (name, val)
                }
                "ref" => {
                    self.check_attrs(c, &["id", "name"])?;
                    let id = self.req_attr(c, "id")?;
                    let val = match self.lookup(c, &id)? {
                        Named::Bsdf(i) => Val::BsdfRef(i),
                        Named::Texture(t) => Val::Texture(t),
                        Named::Value(v) => v,
                        Named::ShapeGroup(g) => Val::ShapeGroup(g),
                        Named::Medium(i) => Val::Medium(i),
                        Named::Shape | Named::Emitter => {
                            return Err(self.err(c, format!("\"{id}\" cannot be referenced here")))
                        }
                    };
                    let name = self
                        .attr(c, "name")?
                        .unwrap_or_else(|| format!("<{}>", val.kind()));
                    (name, val)
                }
                t if OBJECT_TAGS.contains(&t) => {
                    let mut val = self.parse_object(c)?;
                    let name = match include_name {
                        Some(n) => n,
                        None => self.attr(c, "name")?.unwrap_or_else(|| format!("<{t}>")),
                    };
                    if let Some(id) = self.attr(c, "id")? {
                        // A nested object with an id can be referenced from anywhere after it.
                        match &val {
                            Val::Texture(t) => self.register(c, id, Named::Texture(t.clone()))?,
                            Val::Bsdf(b) => {
                                self.bsdfs.push(b.clone());
                                let i = self.bsdfs.len() - 1;
                                self.register(c, id, Named::Bsdf(i))?;
                                val = Val::BsdfRef(i);
                            }
                            Val::Medium(i) => self.register(c, id, Named::Medium(*i))?,
                            _ => {}
                        }
                    }
                    (name, val)
                }
                _ => return Err(self.unknown_element(c, &Self::describe(node))),
            };
            let name = if self.file_of(c.document()).v1 {
                upgrade_v1_name(&plugin, &name)
            } else {
                name
            };
            self.check_domain(c, &name, &val)?;
            // Unnamed nested objects ("<bsdf>") are checked by the plugin that takes them.
            if !name.starts_with('<') && list.iter().any(|p: &Prop| p.name == name) {
                return Err(self.err(c, format!("parameter '{name}' given twice")));
            }
            list.push(Prop { name, val, node: c });
        }
        Ok(Props {
            node,
            tag,
            plugin,
            list,
        })
    }

    fn parse_object(&mut self, node: Node<'a, 'i>) -> Result<Val> {
        if self.depth >= MAX_NESTING {
            return Err(self.err(node, format!("objects nested more than {MAX_NESTING} deep")));
        }
        self.depth += 1;
        let val = self.parse_object_inner(node);
        self.depth -= 1;
        val
    }

    /// Checks a parameter's value against its name's entry in [`DOMAINS`] (and an index
    /// given as text against the physical index range).
    fn check_domain(&self, node: Node, name: &str, val: &Val) -> Result<()> {
        let Some(&(_, lo, hi)) = DOMAINS.iter().find(|(names, _, _)| names.contains(&name)) else {
            return Ok(());
        };
        let values: Vec<f64> = match val {
            Val::Float(v) => vec![*v],
            Val::Int(v) => vec![*v as f64],
            Val::Rgb(c) => c.iter().map(|&x| x as f64).collect(),
            Val::Spectrum(s) | Val::Texture(TextureDesc::Value(s)) => match s {
                SpectrumDesc::Constant(v) | SpectrumDesc::D65 { scale: v } => vec![*v as f64],
                SpectrumDesc::Rgb(c) => c.iter().map(|&x| x as f64).collect(),
                SpectrumDesc::Tabulated(t) => t.iter().map(|p| p.1 as f64).collect(),
            },
            Val::Str(s) if lo > 0.0 && mitsuba_ior(s).is_none() => {
                // An index written as text ("1.5", "2+0.1i", "cauchy:…"): physical range.
                if let Ok(ior) = s.parse::<Ior>() {
                    crate::limits::check_index(format!("parameter '{name}'"), &ior)
                        .map_err(|e| self.err(node, e))?;
                }
                Vec::new()
            }
            _ => Vec::new(),
        };
        if let Some(v) = values
            .iter()
            .find(|v| !(v.is_finite() && **v >= lo && **v <= hi))
        {
            // f32::MIN_POSITIVE / f32::MAX stand for "> 0" / "no upper bound": say so.
            let lower = if lo == f32::MIN_POSITIVE as f64 {
                "> 0".to_string()
            } else {
                format!("≥ {lo}")
            };
            let range = if hi >= f32::MAX as f64 {
                format!("must be a finite number {lower}")
            } else if lo == f32::MIN_POSITIVE as f64 {
                format!("is outside (0, {hi}]")
            } else {
                format!("is outside [{lo}, {hi}]")
            };
            return Err(self.err(node, format!("parameter '{name}' = {v} {range}")));
        }
        Ok(())
    }

    fn parse_object_inner(&mut self, node: Node<'a, 'i>) -> Result<Val> {
        let tag = node.tag_name().name();
        if node.parent().is_some_and(|p| p.is_root()) {
            // The root element of an included file carries the scene version.
            self.check_attrs(node, &["type", "id", "name", "version"])?;
        } else {
            self.check_attrs(node, &["type", "id", "name"])?;
        }
        let mut p = self.collect_props(node)?;
        let val = match tag {
            "medium" => Val::Medium(self.build_medium(&mut p)?),
            "phase" => Val::Phase(self.build_phase(&mut p)?),
            "volume" => Val::ConstVolume(self.build_volume(&mut p)?),
            "bsdf" => Val::Bsdf(self.build_bsdf(&mut p)?),
            "texture" => Val::Texture(self.build_texture(&mut p)?),
            "emitter" => Val::Emitter(self.build_emitter(&mut p)?),
            "shape" => Val::Shapes(self.build_shapes(&mut p)?),
            "sensor" => Val::Sensor(Box::new(self.build_sensor(&mut p)?)),
            "integrator" => Val::Integrator(self.build_integrator(&mut p)?),
            "film" => Val::Film(self.build_film(&mut p)?),
            "sampler" => {
                let (n, s, k) = self.build_sampler(&mut p)?;
                Val::Sampler(n, s, k)
            }
            "rfilter" => Val::Rfilter(self.build_rfilter(&mut p)?),
            _ => return Err(self.err(node, "unsupported object")),
        };
        p.finish(self)?;
        Ok(val)
    }

    fn unknown_plugin(&self, p: &Props, known: &[&str]) -> anyhow::Error {
        self.err(
            p.node,
            format!(
                "unsupported {} plugin \"{}\" (supported: {})",
                p.tag,
                p.plugin,
                known.join(", ")
            ),
        )
    }

    /// A BSDF, built by the registered model that claims the plugin.
    fn build_bsdf(&self, p: &mut Props<'a, 'i>) -> Result<Bsdf> {
        let plugin = p.plugin.clone();
        let mut params = PluginParams::new(p, self);
        match bsdf::build_plugin(&plugin, &mut params) {
            Some(b) => b,
            None => Err(self.unknown_plugin(p, &bsdf::plugin_names())),
        }
    }

    fn build_texture(&mut self, p: &mut Props<'a, 'i>) -> Result<TextureDesc> {
        match p.plugin.as_str() {
            "bitmap" => {
                let file = p
                    .string(self, "filename")?
                    .ok_or_else(|| self.err(p.node, "missing parameter 'filename'"))?;
                let path = self.resolve_path(p.node, &file)?;
                let raw = p.bool(self, "raw", false)?;
                let mut tex = BitmapTexture::load(&path, raw)
                    .map_err(|e| self.err(p.node, format!("{e:#}")))?;
                if let Some(f) = p.string(self, "filter_type")? {
                    tex.filter = TextureFilter::parse(&f).ok_or_else(|| {
                        self.err(p.node, format!("filter_type \"{f}\" (bilinear, nearest)"))
                    })?;
                }
                if let Some(w) = p.string(self, "wrap_mode")? {
                    tex.wrap = WrapMode::parse(&w).ok_or_else(|| {
                        self.err(p.node, format!("wrap_mode \"{w}\" (repeat, mirror, clamp)"))
                    })?;
                }
                tex.to_uv = p.uv_transform(self)?;
                // Storage precision and lookup acceleration: the same texel values.
                p.accept(&["format"], self, |v| matches!(v, Val::Str(_)))?;
                p.accept(&["accel"], self, |v| matches!(v, Val::Bool(_)))?;
                Ok(TextureDesc::Bitmap(Arc::new(tex)))
            }
            "checkerboard" => {
                let color0 = p.spectrum(self, "color0", 0.4)?;
                let color1 = p.spectrum(self, "color1", 0.2)?;
                let to_uv = p.uv_transform(self)?;
                Ok(TextureDesc::Checkerboard {
                    color0,
                    color1,
                    to_uv,
                })
            }
            "mesh_attribute" => {
                let name = p
                    .string(self, "name")?
                    .ok_or_else(|| self.err(p.node, "mesh_attribute: missing parameter 'name'"))?;
                if !(name.starts_with("vertex_") || name.starts_with("face_")) {
                    return Err(self.err(
                        p.node,
                        format!("mesh_attribute: invalid name \"{name}\": it must start with \"vertex_\" or \"face_\" (as in Mitsuba)"),
                    ));
                }
                // Mitsuba multiplies the evaluated (upsampled) value by `scale`.
                let scale = p.float(self, "scale", 1.0)?;
                if scale != 1.0 {
                    return Err(self.err(
                        p.node,
                        format!("mesh_attribute: scale = {scale} is not supported (only 1)"),
                    ));
                }
                self.mesh_attributes.insert(name);
                Ok(TextureDesc::VertexColor)
            }
            "rawconstant" => self.raw_constant(p),
            _ => Err(self.unknown_plugin(
                p,
                &["bitmap", "checkerboard", "mesh_attribute", "rawconstant"],
            )),
        }
    }

    /// Mitsuba's `rawconstant` (`src/spectra/rawconstant.cpp`): a `<float>` value is a flat
    /// constant; a `<vector>` is a raw RGB triple (no upsampling, no sRGB decoding), which
    /// Mitsuba's spectral variants evaluate only through `eval_3` (a `normalmap`): a 1 × 1
    /// raw bitmap.
    fn raw_constant(&mut self, p: &mut Props<'a, 'i>) -> Result<TextureDesc> {
        match p.take("value") {
            Some(Prop {
                val: Val::Float(v), ..
            }) => Ok(TextureDesc::Value(SpectrumDesc::Constant(v as f32))),
            Some(Prop {
                val: Val::Vector(v) | Val::Point(v),
                ..
            }) => BitmapTexture::new(1, 1, 3, v.to_array().to_vec())
                .map(|b| TextureDesc::Bitmap(Arc::new(b)))
                .map_err(|e| self.err(p.node, format!("rawconstant: {e:#}"))),
            Some(q) => Err(Props::type_err(self, &q, "a <float> or a <vector>")),
            None => Err(self.err(
                p.node,
                "rawconstant: missing parameter 'value' (a <float> or a <vector>)",
            )),
        }
    }

    fn build_emitter(&mut self, p: &mut Props<'a, 'i>) -> Result<Emitter> {
        // Only changes how often the emitter is sampled, not the image.
        p.accept(&["sampling_weight"], self, |v| {
            matches!(v, Val::Float(_) | Val::Int(_))
        })?;
        Ok(match p.plugin.as_str() {
            "area" => Emitter::Area(p.emission(self, "radiance")?),
            "constant" => Emitter::Other(EmitterDesc::Constant {
                radiance: p.emission(self, "radiance")?,
            }),
            "point" => {
                let to_world = p.take("to_world");
                let position = match (p.take("position"), to_world) {
                    (Some(_), Some(t)) => {
                        return Err(self.err(
                            t.node,
                            "give either 'position' or 'to_world' for a point light, not both",
                        ))
                    }
                    (
                        Some(Prop {
                            val: Val::Point(v) | Val::Vector(v),
                            ..
                        }),
                        None,
                    ) => v,
                    (Some(q), None) => return Err(self.err(q.node, "position must be a <point>")),
                    (
                        None,
                        Some(Prop {
                            val: Val::Transform(m),
                            ..
                        }),
                    ) => m.transform_point3(Vec3::ZERO),
                    (None, Some(q)) => return Err(Props::type_err(self, &q, "a <transform>")),
                    (None, None) => Vec3::ZERO,
                };
                EmitterDesc::Point {
                    position,
                    intensity: p.emission(self, "intensity")?,
                }
                .into()
            }
            "envmap" => {
                let file = p
                    .string(self, "filename")?
                    .ok_or_else(|| self.err(p.node, "missing parameter 'filename'"))?;
                let path = self.resolve_path(p.node, &file)?;
                let image = super::texture::load_rgb_image(&path)
                    .map_err(|e| self.err(p.node, format!("{e:#}")))?;
                if image
                    .pixels
                    .iter()
                    .flatten()
                    .any(|v| !v.is_finite() || *v < 0.0)
                {
                    return Err(self.err(
                        p.node,
                        format!(
                            "environment map {} has negative or non-finite texels",
                            path.display()
                        ),
                    ));
                }
                let scale = p.float(self, "scale", 1.0)? as f32;
                let to_world = p.transform(self, "to_world")?;
                // Changes the sampling density only (Karlík et al. 2019), not the image.
                p.accept(&["mis_compensation"], self, |v| matches!(v, Val::Bool(_)))?;
                EmitterDesc::Envmap {
                    image: Arc::new(image),
                    scale,
                    to_world,
                    path: Some(path),
                }
                .into()
            }
            "spot" => self.spot_emitter(p)?.into(),
            "directional" => {
                let direction = match (p.take("direction"), p.take("to_world")) {
                    (Some(_), Some(t)) => return Err(self.err(
                        t.node,
                        "give either 'direction' or 'to_world' for a directional light, not both",
                    )),
                    (
                        Some(Prop {
                            val: Val::Vector(v) | Val::Point(v),
                            ..
                        }),
                        None,
                    ) => v,
                    (Some(q), None) => return Err(Props::type_err(self, &q, "a <vector>")),
                    (
                        None,
                        Some(Prop {
                            val: Val::Transform(m),
                            ..
                        }),
                    ) => m.transform_vector3(Vec3::Z),
                    (None, Some(q)) => return Err(Props::type_err(self, &q, "a <transform>")),
                    (None, None) => Vec3::Z,
                };
                let direction = direction.try_normalize().ok_or_else(|| {
                    self.err(p.node, "the light's direction is zero or not finite")
                })?;
                EmitterDesc::Directional {
                    direction,
                    irradiance: p.emission(self, "irradiance")?,
                }
                .into()
            }
            "projector" => self.projector_emitter(p)?.into(),
            _ => {
                return Err(self.unknown_plugin(
                    p,
                    &[
                        "area",
                        "constant",
                        "point",
                        "envmap",
                        "spot",
                        "directional",
                        "projector",
                    ],
                ))
            }
        })
    }

    /// Mitsuba's `projector` (`projector.cpp`): `irradiance` (a bitmap texture, or an
    /// emission value: 1 = D65), `scale` (1), `fov` / `fov_axis` / `focal_length` as a
    /// perspective sensor's with the image's aspect ratio, `to_world`.
    fn projector_emitter(&mut self, p: &mut Props<'a, 'i>) -> Result<EmitterDesc> {
        let irradiance = match p.list.iter().position(|q| q.name == "irradiance") {
            Some(i) if matches!(p.list[i].val, Val::Texture(_)) => match p.list.remove(i).val {
                Val::Texture(t @ TextureDesc::Bitmap(_)) => t,
                _ => {
                    return Err(self.err(
                        p.node,
                        "projector: 'irradiance' must be a bitmap texture or a value",
                    ))
                }
            },
            _ => TextureDesc::Value(p.emission(self, "irradiance")?),
        };
        let aspect = match &irradiance {
            TextureDesc::Bitmap(b) => b.width as f32 / b.height as f32,
            _ => 1.0,
        };
        let (fov, axis) = self.sensor_fov(p)?;
        let fov_x = crate::render::camera::fov_x_deg(fov, axis, aspect);
        let scale = p.float(self, "scale", 1.0)? as f32;
        let to_world = p.transform(self, "to_world")?;
        if !(scale.is_finite() && scale >= 0.0 && fov_x > 0.0 && fov_x < 180.0) {
            return Err(self.err(p.node, "projector: scale must be ≥ 0 and fov in (0, 180)"));
        }
        Ok(EmitterDesc::Projector {
            to_world,
            irradiance,
            scale,
            tan_half_fov_x: (fov_x.to_radians() * 0.5).tan(),
            aspect,
        })
    }

    /// Mitsuba's `spot`: `intensity` on the axis (local +Z of `to_world`), full out to
    /// `beam_width`, falling linearly in angle to zero at `cutoff_angle` (degrees; defaults
    /// 20 and ¾ of the cutoff).
    fn spot_emitter(&mut self, p: &mut Props<'a, 'i>) -> Result<EmitterDesc> {
        let texture = match p.take("texture") {
            None => None,
            Some(Prop {
                val: Val::Texture(t @ TextureDesc::Bitmap(_)),
                ..
            }) => Some(t),
            Some(q) => {
                // Mitsuba: "The parameter 'texture' must be spatially varying".
                return Err(self.err(q.node, "a spot light 'texture' must be a bitmap texture"));
            }
        };
        let cutoff = p.float(self, "cutoff_angle", 20.0)?;
        let beam = p.float(self, "beam_width", cutoff * 0.75)?;
        if !(cutoff > 0.0 && cutoff <= 180.0 && beam >= 0.0 && beam <= cutoff) {
            return Err(self.err(
                p.node,
                format!("spot needs 0 < cutoff_angle ≤ 180 and 0 ≤ beam_width ≤ cutoff_angle (got {cutoff}, {beam})"),
            ));
        }
        let to_world = p.transform(self, "to_world")?;
        let intensity = p.emission(self, "intensity")?;
        let cone = SpotCone::Linear {
            cutoff: (cutoff as f32).to_radians(),
            beam_width: (beam as f32).to_radians(),
        };
        Ok(match texture {
            Some(texture) => EmitterDesc::TexturedSpot {
                to_world,
                intensity,
                cone,
                texture,
            },
            None => EmitterDesc::Spot {
                to_world,
                intensity,
                cone,
                range: None,
            },
        })
    }

    /// A `<shape>`: one shape, a `shapegroup`'s shapes, or an `instance` of a group, which
    /// is flattened into world-space copies of the group's shapes (meshes are duplicated per
    /// instance; the total is capped by [`MAX_INSTANCED_TRIANGLES`]).
    fn build_shapes(&mut self, p: &mut Props<'a, 'i>) -> Result<Shapes> {
        match p.plugin.as_str() {
            "shapegroup" => {
                let mut group = Vec::new();
                for q in std::mem::take(&mut p.list) {
                    match q.val {
                        Val::Shapes(Shapes::Plain(s, m)) => {
                            if m != [crate::render::medium::NO_MEDIUM; 2] {
                                return Err(self.err(
                                    q.node,
                                    "media bounded by shapes of a shapegroup are not supported",
                                ));
                            }
                            group.extend(s)
                        }
                        Val::Shapes(Shapes::Group(_)) => {
                            return Err(self.err(q.node, "a shapegroup cannot contain a shapegroup"))
                        }
                        _ => p.list.push(q),
                    }
                }
                if let Some(s) = group.iter().find(|s| s.emission.is_some()) {
                    return Err(self.err(
                        p.node,
                        format!(
                            "shapegroup: shape {} is an area emitter (Mitsuba does not instance emitters)",
                            s.name.as_deref().unwrap_or("(unnamed)")
                        ),
                    ));
                }
                Ok(Shapes::Group(group))
            }
            "instance" => {
                let to_world = p.transform(self, "to_world")?;
                let mut group = None;
                for q in std::mem::take(&mut p.list) {
                    match q.val {
                        Val::ShapeGroup(g) if group.is_none() => group = Some(g),
                        Val::ShapeGroup(_) => {
                            return Err(self.err(q.node, "an instance takes a single shapegroup"))
                        }
                        _ => p.list.push(q),
                    }
                }
                let group = group.ok_or_else(|| {
                    self.err(
                        p.node,
                        "an instance needs a <ref id=\"…\"/> to a shapegroup",
                    )
                })?;
                self.instanced_triangles += group
                    .iter()
                    .map(|s| match &s.geometry {
                        Geometry::Mesh(m) => m.indices.len(),
                        Geometry::Sphere { .. } => 0,
                    })
                    .sum::<usize>();
                if self.instanced_triangles > MAX_INSTANCED_TRIANGLES {
                    return Err(self.err(
                        p.node,
                        format!(
                            "instances add more than {MAX_INSTANCED_TRIANGLES} triangles (each instance is stored as a copy)"
                        ),
                    ));
                }
                let name = self.attr(p.node, "id")?;
                group
                    .iter()
                    .map(|s| {
                        let mut s =
                            transformed_shape(s, &to_world).map_err(|e| self.err(p.node, e))?;
                        if name.is_some() {
                            s.name.clone_from(&name);
                        }
                        Ok(s)
                    })
                    .collect::<Result<_>>()
                    .map(|s| Shapes::Plain(s, [crate::render::medium::NO_MEDIUM; 2]))
            }
            _ => {
                let media = self.shape_media_refs(p)?;
                Ok(Shapes::Plain(vec![self.build_shape(p)?], media))
            }
        }
    }

    fn build_shape(&mut self, p: &mut Props<'a, 'i>) -> Result<Shape> {
        let to_world = p.transform(self, "to_world")?;
        let flip_normals = p.bool(self, "flip_normals", false)?;
        // Differentiable-rendering weight: no effect on images.
        p.accept(&["silhouette_sampling_weight"], self, |v| {
            matches!(v, Val::Float(_))
        })?;
        let mut bsdf = None;
        let mut emission = None;
        let mut rest = Vec::new();
        for q in std::mem::take(&mut p.list) {
            match &q.val {
                Val::Bsdf(_) | Val::BsdfRef(_) if bsdf.is_none() => bsdf = Some(q.val.clone()),
                Val::Bsdf(_) | Val::BsdfRef(_) => {
                    return Err(self.err(q.node, "a shape takes one BSDF"))
                }
                Val::Emitter(Emitter::Area(s)) if emission.is_none() => emission = Some(s.clone()),
                Val::Emitter(_) => {
                    return Err(self.err(q.node, "a shape takes one emitter, of type \"area\""))
                }
                Val::Sensor(_) => {
                    return Err(self.err(q.node, "sensors attached to shapes are not supported"))
                }
                _ => rest.push(q),
            }
        }
        p.list = rest;
        let attribute = self.mesh_attribute_of(p, bsdf.as_ref())?;
        let geometry = match p.plugin.as_str() {
            "sphere" => self.sphere(p, &to_world, flip_normals)?,
            "obj" | "ply" | "serialized" | "rectangle" | "cube" | "disk" | "cylinder" => {
                Geometry::Mesh(
                    self.mesh(p, &to_world, flip_normals, attribute.as_deref())?
                        .into(),
                )
            }
            _ => {
                return Err(self.unknown_plugin(
                    p,
                    &[
                        "obj",
                        "ply",
                        "serialized",
                        "sphere",
                        "rectangle",
                        "cube",
                        "disk",
                        "cylinder",
                        "shapegroup",
                        "instance",
                    ],
                ))
            }
        };
        let bsdf = match bsdf {
            Some(Val::BsdfRef(i)) => i,
            Some(Val::Bsdf(b)) => {
                self.bsdfs.push(b);
                self.bsdfs.len() - 1
            }
            _ => {
                // Mitsuba 3 (`Shape::Shape`): a shape without a BSDF gets a diffuse one, black
                // when the shape is an emitter, so light falling on an area light's front is
                // not reflected.
                self.bsdfs.push(if emission.is_some() {
                    bsdf::diffuse::Diffuse::constant(0.0).into()
                } else {
                    Bsdf::default_diffuse()
                });
                self.bsdfs.len() - 1
            }
        };
        let name = self.attr(p.node, "id")?;
        if let (Some(a), Geometry::Sphere { .. }) = (&attribute, &geometry) {
            return Err(self.err(
                p.node,
                format!(
                    "shape \"{}\" (sphere): its BSDF reads the mesh attribute \"{a}\", which an analytic sphere lacks",
                    name.as_deref().unwrap_or("unnamed"),
                ),
            ));
        }
        Ok(Shape {
            geometry,
            bsdf,
            emission,
            name,
        })
    }

    /// Mitsuba's analytic `sphere`: `to_world · translate(center) · scale(radius)`, which
    /// must be a similarity.
    fn sphere(
        &mut self,
        p: &mut Props<'a, 'i>,
        to_world: &Mat4,
        flip_normals: bool,
    ) -> Result<Geometry> {
        let center = self.point(p, "center", Vec3::ZERO)?;
        let radius = p.float(self, "radius", 1.0)? as f32;
        let m = *to_world * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius));
        sphere_geometry(&m, flip_normals).map_err(|e| self.err(p.node, e))
    }

    /// The mesh attribute a shape's BSDF reads (its flags say whether it reads one): the
    /// scene's one `mesh_attribute` name.
    fn mesh_attribute_of(&self, p: &Props<'a, 'i>, bsdf: Option<&Val>) -> Result<Option<String>> {
        let flags = match bsdf {
            Some(Val::BsdfRef(i)) => self.bsdfs[*i].flags(),
            Some(Val::Bsdf(b)) => b.flags(),
            _ => return Ok(None),
        };
        if !flags.contains(bsdf::BsdfFlags::VERTEX_COLOR) {
            return Ok(None);
        }
        match self.mesh_attributes.iter().collect::<Vec<_>>().as_slice() {
            [one] => Ok(Some(one.to_string())),
            names => Err(self.err(
                p.node,
                format!(
                    "the scene's mesh_attribute textures read {} attributes ({}): thinfilm supports one per scene",
                    names.len(),
                    names.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                ),
            )),
        }
    }

    /// Reads mesh attribute `name` of the mesh file `path` into `m.colors` as the colour
    /// its shading points interpolate: an RGB "color" attribute as stored (upsampled at
    /// shading, as Mitsuba's spectral variants upsample it), another 3-channel attribute as
    /// its luminance, a 1-channel one as a grey. A per-face attribute is returned instead,
    /// one colour per triangle (Mitsuba evaluates it constant over the face).
    fn load_mesh_attribute(
        &self,
        p: &Props<'a, 'i>,
        path: &Path,
        name: &str,
        m: &mut TriangleMesh,
    ) -> Result<Option<Vec<Vec3>>> {
        if p.plugin == "serialized" && name == "vertex_color" {
            return Ok(None); // the file's vertex colours, if any
        }
        if p.plugin != "ply" {
            return Err(self.err(
                p.node,
                format!("{} shape: mesh attribute \"{name}\": only PLY files (and serialized vertex colours) carry mesh attributes", p.plugin),
            ));
        }
        let a = ply_attributes::read(path, name)
            .map_err(|e| self.err(p.node, format!("{}: {e:#}", path.display())))?;
        let color = a.dim == 3 && name.contains("color");
        let colors: Vec<Vec3> = (a.values.chunks_exact(a.dim))
            .map(|v| match v {
                [r, g, b] if color => Vec3::new(*r, *g, *b),
                [r, g, b] => Vec3::splat(0.2126 * r + 0.7152 * g + 0.0722 * b),
                _ => Vec3::splat(v[0]),
            })
            .collect();
        let (want, what) = if a.per_face {
            (m.indices.len(), "triangles")
        } else {
            (m.positions.len(), "vertices")
        };
        if colors.len() != want {
            return Err(self.err(
                p.node,
                format!("{}: attribute \"{name}\" has {} values for {want} {what} (face attributes need a triangle mesh)", path.display(), colors.len()),
            ));
        }
        if a.per_face {
            return Ok(Some(colors));
        }
        m.colors = colors;
        Ok(None)
    }

    /// A triangle-mesh shape in world space: a mesh file (`obj`, `ply`, `serialized`) or a
    /// tessellated primitive (`rectangle`, `cube`, `disk`, `cylinder`).
    fn mesh(
        &mut self,
        p: &mut Props<'a, 'i>,
        to_world: &Mat4,
        flip_normals: bool,
        attribute: Option<&str>,
    ) -> Result<TriangleMesh> {
        let mut to_world = *to_world;
        let mut face_colors = None;
        let mut file_face_normals = false;
        let mut what = self.loc(p.node);
        let mut mesh = match p.plugin.as_str() {
            "obj" | "ply" | "serialized" => {
                let file = p
                    .string(self, "filename")?
                    .ok_or_else(|| self.err(p.node, "missing parameter 'filename'"))?;
                let path = self.resolve_path(p.node, &file)?;
                what = format!("{what}: mesh {}", path.display());
                let loaded = match p.plugin.as_str() {
                    // Mitsuba flips OBJ texture coordinates by default (v ↦ 1 − v), PLY not.
                    "obj" => super::meshio::load_obj(&path).map(|m| (m, true)),
                    "ply" => super::meshio::load_ply(&path).map(|m| (m, false)),
                    _ => {
                        let index = p.int(self, "shape_index", 0)?;
                        let index = usize::try_from(index)
                            .map_err(|_| self.err(p.node, "shape_index must be ≥ 0"))?;
                        super::serialized::load(&path, index).map(|s| {
                            file_face_normals = s.face_normals;
                            (s.mesh, false)
                        })
                    }
                };
                let (mut m, flipped) = loaded.map_err(|e| self.err(p.node, format!("{e:#}")))?;
                if let Some(a) = attribute {
                    face_colors = self.load_mesh_attribute(p, &path, a, &mut m)?;
                }
                if p.plugin != "serialized" {
                    let flip_tex = p.bool(self, "flip_tex_coords", p.plugin == "obj")?;
                    if flip_tex != flipped {
                        for uv in &mut m.uvs {
                            uv.y = 1.0 - uv.y;
                        }
                    }
                }
                m
            }
            "rectangle" => shapes::rectangle(),
            "cube" => shapes::cube(),
            "disk" => shapes::disk(8, 128),
            _ => {
                // Mitsuba's analytic cylinder, tessellated finely (see shapes::cylinder).
                let radius = p.float(self, "radius", 1.0)? as f32;
                let p0 = self.point(p, "p0", Vec3::ZERO)?;
                let p1 = self.point(p, "p1", Vec3::Z)?;
                let length = (p1 - p0).length();
                if !(radius > 0.0 && length > 0.0) {
                    return Err(self.err(p.node, "cylinder needs radius > 0 and p0 ≠ p1"));
                }
                to_world = to_world
                    * Mat4::from_translation(p0)
                    * mitsuba_to_frame((p1 - p0) / length)
                    * Mat4::from_scale(Vec3::new(radius, radius, length));
                shapes::cylinder(shapes::CYLINDER_SEGMENTS)
            }
        };
        let face_normals = match p.take("face_normals") {
            Some(Prop {
                val: Val::Bool(b), ..
            }) => b,
            Some(q) => return Err(Props::type_err(self, &q, "a <boolean>")),
            None => file_face_normals,
        };
        if face_normals {
            mesh.normals.clear();
        } else {
            mesh.ensure_normals();
        }
        if let Some(c) = face_colors {
            // After the smooth normals, which need the shared vertices.
            mesh.split_faces_with_colors(&c);
        }
        if attribute.is_some() && mesh.colors.is_empty() {
            return Err(self.err(
                p.node,
                format!(
                    "{} shape: its BSDF reads the mesh attribute \"{}\", which the shape lacks",
                    p.plugin,
                    attribute.unwrap_or_default()
                ),
            ));
        }
        mesh.transform(&to_world);
        if flip_normals {
            mesh.flip();
        }
        mesh.validate(&what)?;
        Ok(mesh)
    }

    fn point(&self, p: &mut Props<'a, 'i>, name: &str, default: Vec3) -> Result<Vec3> {
        match p.take(name) {
            None => Ok(default),
            Some(Prop {
                val: Val::Point(v) | Val::Vector(v),
                ..
            }) => Ok(v),
            Some(q) => Err(Props::type_err(self, &q, "a <point>")),
        }
    }

    fn build_sensor(&mut self, p: &mut Props<'a, 'i>) -> Result<Sensor> {
        let (fov, fov_axis) = match p.plugin.as_str() {
            "perspective" | "thinlens" => self.sensor_fov(p)?,
            // The view's extent comes from to_world's scale.
            "orthographic" => (90.0, FovAxis::X),
            _ => return Err(self.unknown_plugin(p, &["perspective", "thinlens", "orthographic"])),
        };
        let near_clip = p.float(self, "near_clip", 0.01)? as f32;
        let far_clip = p.float(self, "far_clip", 10000.0)? as f32;
        if !(near_clip > 0.0 && far_clip > near_clip) {
            return Err(self.err(p.node, "need 0 < near_clip < far_clip"));
        }
        let projection = match p.plugin.as_str() {
            "thinlens" => {
                let aperture_radius = p
                    .float_opt(self, "aperture_radius")?
                    .ok_or_else(|| self.err(p.node, "thinlens needs 'aperture_radius'"))?
                    as f32;
                // Mitsuba's ProjectiveCamera: the focal plane defaults to the far clip.
                let focus_distance = p.float(self, "focus_distance", far_clip as f64)? as f32;
                if !(aperture_radius >= 0.0 && aperture_radius.is_finite() && focus_distance > 0.0)
                {
                    return Err(self.err(
                        p.node,
                        format!("thinlens needs aperture_radius ≥ 0 and focus_distance > 0 (got {aperture_radius}, {focus_distance})"),
                    ));
                }
                Projection::ThinLens {
                    aperture_radius,
                    focus_distance,
                }
            }
            "orthographic" => Projection::Orthographic,
            _ => {
                // A pinhole has no focal plane (Mitsuba's perspective reads and ignores it).
                p.accept(&["focus_distance"], self, |v| {
                    matches!(v, Val::Float(_) | Val::Int(_))
                })?;
                Projection::Perspective
            }
        };
        // No motion blur without animated transforms: the shutter changes nothing.
        p.accept(&["shutter_open", "shutter_close"], self, |v| {
            matches!(v, Val::Float(_) | Val::Int(_))
        })?;
        for axis in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(self, axis, 0.0)? != 0.0 {
                return Err(self.err(p.node, format!("a non-zero {axis} is not supported")));
            }
        }
        if let Some(q) = p.take("srf") {
            return Err(self.err(
                q.node,
                "a sensor spectral response ('srf') is not supported",
            ));
        }
        let to_world = p.transform(self, "to_world")?;
        if p.plugin == "thinlens" {
            let m = glam::Mat3::from_mat4(to_world);
            if [m.x_axis, m.y_axis, m.z_axis]
                .iter()
                .any(|a| (a.length() - 1.0).abs() > 1e-3)
            {
                return Err(self.err(
                    p.node,
                    "thinlens: scale factors in to_world are not allowed (Mitsuba refuses them too)",
                ));
            }
        }
        self.finish_sensor(
            p,
            to_world,
            (fov, fov_axis),
            (near_clip, far_clip),
            projection,
        )
    }

    /// Mitsuba's `parse_fov` (sensor.cpp) for the perspective sensors.
    fn sensor_fov(&mut self, p: &mut Props<'a, 'i>) -> Result<(f32, FovAxis)> {
        // Mitsuba's `parse_fov` (sensor.cpp): `fov` in degrees along `fov_axis`, or a
        // `focal_length` ("50mm" by default) of a 36 × 24 mm film, whose field of view is
        // measured along the film diagonal (2·atan(√(36² + 24²) / 2f)) whatever `fov_axis` says.
        let focal = p.string(self, "focal_length")?;
        let fov_given = p.float_opt(self, "fov")?;
        let fov_axis_str = p.string(self, "fov_axis")?.map(|a| a.to_ascii_lowercase());
        let (fov, fov_axis_str) = match (fov_given, focal) {
            (Some(_), Some(_)) => {
                return Err(self.err(p.node, "give either 'fov' or 'focal_length', not both"))
            }
            (Some(f), None) => (f as f32, fov_axis_str),
            (None, _) if fov_axis_str.is_some() => {
                return Err(self.err(
                    p.node,
                    "'fov_axis' applies to 'fov' only (a focal length is always measured along the film diagonal; Mitsuba rejects it too)",
                ))
            }
            (None, f) => {
                let f = f.unwrap_or_else(|| "50mm".to_string());
                let mm = f
                    .trim()
                    .strip_suffix("mm")
                    .unwrap_or(f.trim())
                    .trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| *v > 0.0 && v.is_finite())
                    .ok_or_else(|| {
                        self.err(
                            p.node,
                            format!("focal_length \"{f}\" is not a length like \"50mm\""),
                        )
                    })?;
                let diagonal_mm = (36.0f64 * 36.0 + 24.0 * 24.0).sqrt();
                let fov = (2.0 * (diagonal_mm / (2.0 * mm)).atan()).to_degrees() as f32;
                (fov, Some("diagonal".to_string()))
            }
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(self.err(p.node, format!("fov {fov}° must be in (0, 180)")));
        }
        let fov_axis = match fov_axis_str.as_deref() {
            None | Some("x") => FovAxis::X,
            Some("y") => FovAxis::Y,
            Some("diagonal") => FovAxis::Diagonal,
            Some("smaller") => FovAxis::Smaller,
            Some("larger") => FovAxis::Larger,
            Some(o) => {
                return Err(self.err(
                    p.node,
                    format!("fov_axis \"{o}\" (x, y, diagonal, smaller, larger)"),
                ))
            }
        };
        Ok((fov, fov_axis))
    }

    /// The rest of a sensor: polariser, film and sampler.
    fn finish_sensor(
        &mut self,
        p: &mut Props<'a, 'i>,
        to_world: Mat4,
        (fov, fov_axis): (f32, FovAxis),
        (near_clip, far_clip): (f32, f32),
        projection: Projection,
    ) -> Result<Sensor> {
        let medium = self.sensor_medium(p)?;
        // thinfilm extension: an ideal linear polariser in front of the sensor.
        let polarizer = match p.string(self, "polarizer")? {
            None => None,
            Some(v) => Some(match v.trim().to_ascii_lowercase().as_str() {
                "s" => Polarizer::S,
                "p" => Polarizer::P,
                a => match a.strip_suffix("deg").unwrap_or(a).trim().parse::<f32>() {
                    Ok(deg) if deg.is_finite() => Polarizer::AngleDeg(deg),
                    _ => {
                        return Err(self.err(
                            p.node,
                            format!(
                                "polarizer \"{v}\" must be \"s\", \"p\" or an angle in degrees"
                            ),
                        ))
                    }
                },
            }),
        };
        let mut film = None;
        let mut sampler = None;
        let mut rest = Vec::new();
        for q in std::mem::take(&mut p.list) {
            match q.val {
                Val::Film(f) => film = Some(f),
                Val::Sampler(n, s, k) => sampler = Some((n, s, k)),
                _ => rest.push(q),
            }
        }
        p.list = rest;
        let film = film.unwrap_or(FilmSettings {
            width: 768,
            height: 576,
            filter: ReconstructionFilter::Gaussian { stddev: 0.5 },
        });
        let (spp, seed, sampler) = sampler.unwrap_or((4, 0, SamplerKind::Independent));
        Ok(Sensor {
            camera: Camera {
                to_world,
                fov_deg: fov,
                fov_axis,
                near_clip,
                far_clip,
                projection,
            },
            film,
            spp,
            seed,
            sampler,
            polarizer,
            medium,
        })
    }

    fn build_film(&mut self, p: &mut Props<'a, 'i>) -> Result<FilmSettings> {
        if p.plugin != "hdrfilm" {
            return Err(self.unknown_plugin(p, &["hdrfilm"]));
        }
        let width = p.int(self, "width", 768)?;
        let height = p.int(self, "height", 576)?;
        if !(1..=65536).contains(&width) || !(1..=65536).contains(&height) {
            return Err(self.err(
                p.node,
                format!("film width {width} × height {height}: each must be in 1..=65536"),
            ));
        }
        // A crop window other than the whole film is not supported.
        let crop = [
            ("crop_offset_x", 0),
            ("crop_offset_y", 0),
            ("crop_width", width),
            ("crop_height", height),
        ];
        for (name, full) in crop {
            let v = p.int(self, name, full)?;
            if v != full {
                return Err(self.err(
                    p.node,
                    format!("crop windows are not supported ({name} = {v}; the whole {width}×{height} film is rendered only)"),
                ));
            }
        }
        // Output-format options do not change pixel values (thinfilm writes RGB EXRs).
        p.accept(
            &["pixel_format", "component_format", "file_format"],
            self,
            |v| matches!(v, Val::Str(_)),
        )?;
        p.accept(&["banner", "compensate"], self, |v| {
            matches!(v, Val::Bool(_))
        })?;
        if p.bool(self, "sample_border", false)? {
            eprintln!(
                "note: {}: sample_border is ignored (only pixels at the image border would change)",
                self.loc(p.node)
            );
        }
        let mut filter = ReconstructionFilter::Gaussian { stddev: 0.5 };
        if let Some(i) = p.list.iter().position(|q| matches!(q.val, Val::Rfilter(_))) {
            if let Val::Rfilter(f) = p.list.remove(i).val {
                filter = f;
            }
        }
        Ok(FilmSettings {
            width: width as u32,
            height: height as u32,
            filter,
        })
    }

    fn build_rfilter(&mut self, p: &mut Props<'a, 'i>) -> Result<ReconstructionFilter> {
        Ok(match p.plugin.as_str() {
            "box" => ReconstructionFilter::Box,
            "tent" => {
                let radius = p.float(self, "radius", 1.0)? as f32;
                // The filter's footprint is allocated per image row: keep it to pixels.
                if !(radius > 0.0 && radius <= 32.0) {
                    return Err(self.err(
                        p.node,
                        format!("tent radius {radius} must be in (0, 32] pixels"),
                    ));
                }
                ReconstructionFilter::Tent { radius }
            }
            "gaussian" => {
                let stddev = p.float(self, "stddev", 0.5)? as f32;
                if !(stddev > 0.0) {
                    return Err(self.err(p.node, "gaussian stddev must be > 0"));
                }
                ReconstructionFilter::Gaussian { stddev }
            }
            _ => return Err(self.unknown_plugin(p, &["box", "tent", "gaussian"])),
        })
    }

    fn build_sampler(&mut self, p: &mut Props<'a, 'i>) -> Result<(u32, u64, SamplerKind)> {
        const KNOWN: &[&str] = &[
            "independent",
            "stratified",
            "multijitter",
            "orthogonal",
            "ldsampler",
        ];
        if !KNOWN.contains(&p.plugin.as_str()) {
            return Err(self.unknown_plugin(p, KNOWN));
        }
        let n = p.int(self, "sample_count", 4)?;
        let seed = p.int(self, "seed", 0)?;
        if n < 1 || n > u32::MAX as i64 {
            return Err(self.err(p.node, format!("sample_count {n} must be ≥ 1")));
        }
        if seed < 0 {
            return Err(self.err(p.node, "seed must be ≥ 0"));
        }
        // Stratification options change the noise, not the expected image.
        if matches!(
            p.plugin.as_str(),
            "stratified" | "multijitter" | "orthogonal"
        ) {
            p.accept(&["jitter"], self, |v| matches!(v, Val::Bool(_)))?;
        }
        if p.plugin == "orthogonal" {
            p.accept(&["strength"], self, |v| matches!(v, Val::Int(_)))?;
        }
        let kind = if p.plugin == "independent" {
            SamplerKind::Independent
        } else {
            SamplerKind::Sobol
        };
        Ok((n as u32, seed as u64, kind))
    }

    fn build_integrator(&mut self, p: &mut Props<'a, 'i>) -> Result<IntegratorSettings> {
        // Mitsuba's generic integrator parameters that do not change the expected image.
        p.accept(&["timeout"], self, |v| {
            matches!(v, Val::Float(_) | Val::Int(_))
        })?;
        p.accept(&["block_size", "samples_per_pass"], self, |v| {
            matches!(v, Val::Int(_))
        })?;
        let plugin = p.plugin.clone();
        if !matches!(plugin.as_str(), "moment" | "aov" | "stokes") {
            // (A wrapper renders its nested integrator, read before it.)
            self.integrator_plugin = Some(plugin.clone());
        }
        match plugin.as_str() {
            "path" | "volpath" | "volpathmis" | "prb" | "prb_basic" => {
                if plugin == "volpathmis" {
                    // Media are rendered with volpath's transport (`render/integrator/media.rs`)
                    // whose distance sampling already averages the channels' densities.
                    eprintln!(
                        "note: {}: integrator \"volpathmis\" is rendered as volpath (same expected image; volpathmis's spectral MIS changes only the noise)",
                        self.loc(p.node)
                    );
                } else if plugin.starts_with("prb") {
                    // Surfaces only: their estimate is the path tracer's.
                    eprintln!(
                        "note: {}: integrator \"{plugin}\" is rendered by the path tracer (same expected image)",
                        self.loc(p.node)
                    );
                }
                let max_depth = p.int(self, "max_depth", -1)?;
                let rr_depth = p.int(self, "rr_depth", 5)?;
                if max_depth < -1 || rr_depth < 1 {
                    return Err(self.err(p.node, "max_depth must be ≥ −1 and rr_depth ≥ 1"));
                }
                Ok(IntegratorSettings {
                    max_depth: max_depth.min(i32::MAX as i64) as i32,
                    rr_depth: rr_depth.min(i32::MAX as i64) as i32,
                    hide_emitters: p.bool(self, "hide_emitters", false)?,
                })
            }
            "direct" => self.direct_integrator(p),
            "moment" | "aov" | "stokes" => self.wrapper_integrator(p),
            _ => Err(self.unknown_plugin(
                p,
                &[
                    "path",
                    "direct",
                    "volpath",
                    "volpathmis",
                    "prb",
                    "prb_basic",
                    "moment",
                    "aov",
                    "stokes",
                ],
            )),
        }
    }

    /// Mitsuba's `direct`: directly visible emitters plus one bounce of direct light, each
    /// shading point combining `emitter_samples` light samples and `bsdf_samples` BSDF
    /// samples by multiple importance sampling (power heuristic). Its expected image is the
    /// path tracer's with `max_depth` 2 — both strategies estimate the same integral — except
    /// that without emitter samples delta lights (point) are never reached, and without BSDF
    /// samples delta BSDF lobes (smooth mirrors and glass) reflect nothing; those two
    /// combinations are refused rather than rendered differently. (Checked against Mitsuba
    /// 3.9 `direct.cpp`.)
    fn direct_integrator(&mut self, p: &mut Props<'a, 'i>) -> Result<IntegratorSettings> {
        let shading = p.int_opt(self, "shading_samples")?;
        let emitter = p.int_opt(self, "emitter_samples")?;
        let bsdf = p.int_opt(self, "bsdf_samples")?;
        if shading.is_some() && (emitter.is_some() || bsdf.is_some()) {
            return Err(self.err(
                p.node,
                "give either 'shading_samples' or 'emitter_samples'/'bsdf_samples', not both",
            ));
        }
        let shading = shading.unwrap_or(1);
        let (emitter, bsdf) = (emitter.unwrap_or(shading), bsdf.unwrap_or(shading));
        if emitter < 0 || bsdf < 0 || emitter + bsdf == 0 {
            return Err(self.err(
                p.node,
                "need at least one BSDF or emitter sample (counts ≥ 0)",
            ));
        }
        self.direct_strategies = Some((p.node, emitter.min(u32::MAX as i64) as u32, bsdf > 0));
        Ok(IntegratorSettings {
            max_depth: 2,
            rr_depth: i32::MAX,
            hide_emitters: p.bool(self, "hide_emitters", false)?,
        })
    }

    /// `moment`, `aov` and `stokes` wrap other integrators and add channels thinfilm does
    /// not write (second moments, AOVs, Stokes components); the image itself is the first
    /// nested integrator's, which is what is rendered.
    fn wrapper_integrator(&mut self, p: &mut Props<'a, 'i>) -> Result<IntegratorSettings> {
        let aovs = if p.plugin == "aov" {
            p.string(self, "aovs")?
        } else {
            None
        };
        let mut inner = Vec::new();
        for q in std::mem::take(&mut p.list) {
            match q.val {
                Val::Integrator(s) => inner.push((q.name, s)),
                _ => p.list.push(q),
            }
        }
        let Some((name, first)) = inner.first().cloned() else {
            return Err(self.err(
                p.node,
                format!("a {} integrator needs a nested <integrator>", p.plugin),
            ));
        };
        let ignored = match p.plugin.as_str() {
            "moment" => "the second-moment channels".to_string(),
            "aov" => format!("the AOV channels ({})", aovs.as_deref().unwrap_or("none")),
            _ => "the Stokes channels S1–S3 (the image is the intensity S0)".to_string(),
        };
        let others = if inner.len() > 1 {
            format!(" and {} further nested integrator(s)", inner.len() - 1)
        } else {
            String::new()
        };
        eprintln!(
            "note: {}: integrator \"{}\": rendering its first nested integrator ({}); ignoring {ignored}{others}",
            self.loc(p.node),
            p.plugin,
            if name.starts_with('<') { "unnamed".to_string() } else { format!("\"{name}\"") }
        );
        Ok(first)
    }
}

/// The sensor Mitsuba 3 (up to 3.8; 3.9 refuses to render without one) creates for a scene
/// without a sensor: a 45° (horizontal) perspective camera looking along +z at the centre of
/// the shapes' bounding box from `distance = max extent / (2·tan 22.5°)` in front of its
/// z = min face, near clip distance / 100, far clip 5·max extent + distance; at the origin
/// looking along +z when the scene has no shapes.
fn mitsuba_default_camera(bounds: Option<(Vec3, Vec3)>) -> Camera {
    let (to_world, near_clip, far_clip) = match bounds {
        Some((lo, hi)) if (hi - lo).max_element() > 0.0 => {
            let (center, extents) = ((lo + hi) * 0.5, hi - lo);
            let max_extent = extents.max_element();
            let distance = max_extent / (2.0 * (22.5f32).to_radians().tan());
            (
                Mat4::from_translation(Vec3::new(center.x, center.y, lo.z - distance)),
                distance / 100.0,
                max_extent * 5.0 + distance,
            )
        }
        _ => (Mat4::IDENTITY, 0.01, 10000.0),
    };
    Camera {
        to_world,
        fov_deg: 45.0,
        fov_axis: FovAxis::X,
        near_clip,
        far_clip,
        projection: Projection::Perspective,
    }
}

/// Mitsuba's `<rotate>` (drjit's `rotate`): Rodrigues' formula with the axis as given, *not*
/// normalised — an axis of length ≠ 1 also scales and shears, exactly as in Mitsuba 3.9
/// (`rotate x="0" y="1" z="1" angle="15"` gives a matrix with unit diagonal entries on y, z).
fn mitsuba_rotation(axis: Vec3, angle_deg: f64) -> Mat4 {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let a = axis.as_dvec3();
    let k = 1.0 - c;
    let m = glam::DMat3::from_cols(
        glam::DVec3::new(
            c + a.x * a.x * k,
            a.x * a.y * k + a.z * s,
            a.x * a.z * k - a.y * s,
        ),
        glam::DVec3::new(
            a.x * a.y * k - a.z * s,
            c + a.y * a.y * k,
            a.y * a.z * k + a.x * s,
        ),
        glam::DVec3::new(
            a.x * a.z * k + a.y * s,
            a.y * a.z * k - a.x * s,
            c + a.z * a.z * k,
        ),
    );
    Mat4::from_mat3(m.as_mat3())
}

fn scaled_spectrum(s: &SpectrumDesc, k: f32) -> SpectrumDesc {
    match s {
        SpectrumDesc::Constant(v) => SpectrumDesc::Constant(v * k),
        SpectrumDesc::Rgb(c) => SpectrumDesc::Rgb(c.map(|x| x * k)),
        SpectrumDesc::Tabulated(t) => {
            SpectrumDesc::Tabulated(t.iter().map(|&(l, v)| (l, v * k)).collect())
        }
        SpectrumDesc::D65 { scale } => SpectrumDesc::D65 { scale: scale * k },
    }
}

/// Cap on the triangles `instance`s add (each instance is a world-space copy).
const MAX_INSTANCED_TRIANGLES: usize = 1 << 26;

/// An analytic sphere from the matrix mapping the unit sphere to it (a similarity).
fn sphere_geometry(m: &Mat4, flip_normals: bool) -> std::result::Result<Geometry, String> {
    let c = m.transform_point3(Vec3::ZERO);
    let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| m.transform_vector3(a));
    let r = axes[0].length();
    let similar = axes
        .iter()
        .all(|a| (a.length() - r).abs() <= 1e-4 * r.max(1e-12))
        && axes[0].dot(axes[1]).abs() <= 1e-4 * r * r
        && axes[1].dot(axes[2]).abs() <= 1e-4 * r * r
        && axes[0].dot(axes[2]).abs() <= 1e-4 * r * r;
    if !similar {
        return Err(
            "sphere to_world must be a similarity (uniform scale, rotation, translation)".into(),
        );
    }
    if !(r > 0.0 && r.is_finite()) {
        return Err("sphere radius must be > 0".into());
    }
    Ok(Geometry::Sphere {
        center: c,
        radius: r,
        rotation: Mat3::from_cols(axes[0] / r, axes[1] / r, axes[2] / r),
        flip_normals,
    })
}

/// A copy of `shape` moved by `m` (an `instance` of a shapegroup member).
fn transformed_shape(shape: &Shape, m: &Mat4) -> std::result::Result<Shape, String> {
    let geometry = match &shape.geometry {
        Geometry::Mesh(mesh) => {
            let mut mesh = TriangleMesh::clone(mesh);
            mesh.transform(m);
            Geometry::Mesh(mesh.into())
        }
        Geometry::Sphere {
            center,
            radius,
            rotation,
            flip_normals,
        } => {
            let to_unit = Mat4::from_translation(*center)
                * Mat4::from_mat3(*rotation)
                * Mat4::from_scale(Vec3::splat(*radius));
            sphere_geometry(&(*m * to_unit), *flip_normals)
                .map_err(|e| format!("instanced sphere: {e}"))?
        }
    };
    Ok(Shape {
        geometry,
        ..shape.clone()
    })
}

/// Mitsuba's `Transform4f::to_frame(Frame3f(n))`: a matrix whose columns are the frame's
/// s, t, n (local z goes to n), with s, t from `coordinate_system(n)` (Duff et al. 2017,
/// "Building an Orthonormal Basis, Revisited"). `cylinder` composes it exactly as Mitsuba
/// does, so that the tessellated cylinder's seam (u = 0) lies where Mitsuba's is.
fn mitsuba_to_frame(n: Vec3) -> Mat4 {
    let sign = if n.z >= 0.0 { 1.0f32 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    // mulsign(x, z) = x·sign(z); mulsign_neg(x, z) = −x·sign(z).
    let s = Vec3::new(n.x * n.x * a * sign + 1.0, b * sign, -n.x * sign);
    let t = Vec3::new(b, n.y * n.y * a + sign, -n.y);
    Mat4::from_cols(s.extend(0.0), t.extend(0.0), n.extend(0.0), glam::Vec4::W)
}

/// Mitsuba's upgrade of a parameter name from a scene older than version 2.0
/// (`transform_upgrade`): camelCase becomes snake_case ("maxDepth" → "max_depth"), and a
/// `diffuse` BSDF's `diffuseReflectance` becomes `reflectance`.
fn upgrade_v1_name(plugin: &str, name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::with_capacity(name.len() + 4);
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if i > 0 && chars[i - 1].is_ascii_lowercase() && c.is_ascii_uppercase() {
            out.push('_');
            out.push(c.to_ascii_lowercase());
            while i + 1 < chars.len() && chars[i + 1].is_ascii_uppercase() {
                i += 1;
                out.push(chars[i].to_ascii_lowercase());
            }
        } else {
            out.push(c);
        }
        i += 1;
    }
    if plugin == "diffuse" && out == "diffuse_reflectance" {
        return "reflectance".to_string();
    }
    out
}

/// Parses a `<spectrum value>`: one number, or "λ:v, λ:v, …" pairs (increasing λ in nm).
pub fn parse_spectrum_value(v: &str) -> std::result::Result<SpectrumDesc, String> {
    if !v.contains(':') {
        return match parse_f64(v) {
            Some(x) if x.is_finite() => Ok(SpectrumDesc::Constant(x as f32)),
            _ => Err(format!("'{v}' is not a number or a list of λ:value pairs")),
        };
    }
    let mut pairs = Vec::new();
    for item in v.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (l, x) = item
            .split_once(':')
            .ok_or_else(|| format!("'{item}' is not a λ:value pair"))?;
        match (parse_f64(l), parse_f64(x)) {
            (Some(l), Some(x)) if l.is_finite() && x.is_finite() && l > 0.0 => {
                pairs.push((l as f32, x as f32))
            }
            _ => return Err(format!("'{item}' is not a λ:value pair")),
        }
    }
    check_tabulated(pairs)
}

fn check_tabulated(pairs: Vec<(f32, f32)>) -> std::result::Result<SpectrumDesc, String> {
    if pairs.len() < 2 {
        return Err("a tabulated spectrum needs at least two λ:value pairs".into());
    }
    if pairs.windows(2).any(|w| w[1].0 <= w[0].0) {
        return Err("wavelengths must increase strictly".into());
    }
    Ok(SpectrumDesc::Tabulated(pairs))
}

/// Reads a `.spd` file: lines "λ value" (whitespace or comma separated), `#` comments.
pub fn read_spd(path: &Path) -> Result<SpectrumDesc> {
    let text = crate::limits::read_text(path, "spectrum file", 16)?;
    let mut pairs = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        match parse_list(line).as_deref() {
            Some([l, v]) if l.is_finite() && v.is_finite() && *l > 0.0 => {
                pairs.push((*l as f32, *v as f32))
            }
            _ => bail!(
                "{}:{}: expected \"wavelength value\", got \"{line}\"",
                path.display(),
                n + 1
            ),
        }
    }
    check_tabulated(pairs).map_err(|e| anyhow!("{}: {e}", path.display()))
}

impl From<EmitterDesc> for Emitter {
    fn from(e: EmitterDesc) -> Self {
        Emitter::Other(e)
    }
}

impl<'a, 'i> Props<'a, 'i> {
    fn take(&mut self, name: &str) -> Option<Prop<'a, 'i>> {
        let i = self.list.iter().position(|p| p.name == name)?;
        Some(self.list.remove(i))
    }

    /// Leftover parameters are errors naming the parameter, element and plugin.
    fn finish(self, ctx: &Ctx) -> Result<()> {
        if let Some(q) = self.list.first() {
            return Err(anyhow!(
                "{}: unknown parameter '{}' ({}) for {} plugin \"{}\" at {}",
                ctx.loc(q.node),
                q.name,
                q.val.kind(),
                self.tag,
                self.plugin,
                ctx.loc(self.node)
            ));
        }
        Ok(())
    }

    /// Removes the named parameters if present, checking their type with `ok`.
    fn accept(&mut self, names: &[&str], ctx: &Ctx, ok: impl Fn(&Val) -> bool) -> Result<()> {
        self.accept_or(names, ctx, ok, "")
    }

    /// [`Self::accept`] with `why` appended to the error message.
    fn accept_or(
        &mut self,
        names: &[&str],
        ctx: &Ctx,
        ok: impl Fn(&Val) -> bool,
        why: &str,
    ) -> Result<()> {
        for n in names {
            if let Some(q) = self.take(n) {
                if !ok(&q.val) {
                    return Err(ctx.err(
                        q.node,
                        format!(
                            "unsupported value for '{n}' of {} plugin \"{}\"{why}",
                            self.tag, self.plugin
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn type_err(ctx: &Ctx, q: &Prop, want: &str) -> anyhow::Error {
        ctx.err(
            q.node,
            format!(
                "parameter '{}' must be {want}, not {}",
                q.name,
                q.val.kind()
            ),
        )
    }

    fn float_opt(&mut self, ctx: &Ctx, name: &str) -> Result<Option<f64>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => match q.val {
                Val::Float(v) if v.is_finite() => Ok(Some(v)),
                Val::Int(v) => Ok(Some(v as f64)),
                _ => Err(Self::type_err(ctx, &q, "a finite <float>")),
            },
        }
    }

    fn float(&mut self, ctx: &Ctx, name: &str, default: f64) -> Result<f64> {
        Ok(self.float_opt(ctx, name)?.unwrap_or(default))
    }

    fn int(&mut self, ctx: &Ctx, name: &str, default: i64) -> Result<i64> {
        Ok(self.int_opt(ctx, name)?.unwrap_or(default))
    }

    fn int_opt(&mut self, ctx: &Ctx, name: &str) -> Result<Option<i64>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => match q.val {
                Val::Int(v) => Ok(Some(v)),
                _ => Err(Self::type_err(ctx, &q, "an <integer>")),
            },
        }
    }

    fn bool(&mut self, ctx: &Ctx, name: &str, default: bool) -> Result<bool> {
        match self.take(name) {
            None => Ok(default),
            Some(q) => match q.val {
                Val::Bool(v) => Ok(v),
                _ => Err(Self::type_err(ctx, &q, "a <boolean>")),
            },
        }
    }

    fn string(&mut self, ctx: &Ctx, name: &str) -> Result<Option<String>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => match q.val {
                Val::Str(v) => Ok(Some(v)),
                _ => Err(Self::type_err(ctx, &q, "a <string>")),
            },
        }
    }

    fn transform(&mut self, ctx: &Ctx, name: &str) -> Result<Mat4> {
        match self.take(name) {
            None => Ok(Mat4::IDENTITY),
            Some(q) => match q.val {
                // A singular object or camera transform has no inverse: normals and camera
                // rays would be NaN. (`to_uv` may legitimately collapse a texture.)
                Val::Transform(m)
                    if name == "to_world"
                        && !(m.determinant().is_normal() && m.inverse().is_finite()) =>
                {
                    Err(ctx.err(
                        q.node,
                        "to_world is singular (a zero scale or a degenerate matrix)",
                    ))
                }
                Val::Transform(m) => Ok(m),
                _ => Err(Self::type_err(ctx, &q, "a <transform>")),
            },
        }
    }

    /// `to_uv` as a 3×3 homogeneous 2-D transform (the x/y rows of the 4×4).
    fn uv_transform(&mut self, ctx: &Ctx) -> Result<Mat3> {
        let m = self.transform(ctx, "to_uv")?;
        Ok(Mat3::from_cols(
            m.x_axis.truncate().truncate().extend(0.0),
            m.y_axis.truncate().truncate().extend(0.0),
            Vec2::new(m.w_axis.x, m.w_axis.y).extend(1.0),
        ))
    }

    fn spectrum(&mut self, ctx: &Ctx, name: &str, default: f32) -> Result<SpectrumDesc> {
        match self.take(name) {
            None => Ok(SpectrumDesc::Constant(default)),
            Some(q) => match q.val {
                Val::Float(v) => Ok(SpectrumDesc::Constant(v as f32)),
                Val::Rgb(c) => Ok(SpectrumDesc::Rgb(c)),
                Val::Spectrum(s) => Ok(s),
                _ => Err(Self::type_err(ctx, &q, "a <float>, <rgb> or <spectrum>")),
            },
        }
    }

    /// An emitter's spectrum as Mitsuba's `get_emissive_texture` reads it in spectral
    /// variants: a number `v` (or nothing: 1) is the D65 illuminant scaled by `v`, RGB is
    /// upsampled as an illuminant (`srgb_d65`), a `<spectrum value="v">` is flat.
    fn emission(&mut self, ctx: &Ctx, name: &str) -> Result<SpectrumDesc> {
        match self.take(name) {
            None => Ok(SpectrumDesc::D65 { scale: 1.0 }),
            Some(q) => match q.val {
                Val::Float(v) if v.is_finite() => Ok(SpectrumDesc::D65 { scale: v as f32 }),
                Val::Int(v) => Ok(SpectrumDesc::D65 { scale: v as f32 }),
                Val::Rgb(c) => Ok(SpectrumDesc::Rgb(c)),
                Val::Spectrum(s) => Ok(s),
                Val::Texture(_) => Err(ctx.err(
                    q.node,
                    format!("a textured '{name}' (spatially varying emission) is not supported"),
                )),
                _ => Err(Self::type_err(ctx, &q, "a <float>, <rgb> or <spectrum>")),
            },
        }
    }

    fn texture(&mut self, ctx: &Ctx, name: &str, default: f32) -> Result<TextureDesc> {
        match self.take(name) {
            None => Ok(TextureDesc::Value(SpectrumDesc::Constant(default))),
            Some(q) => match q.val {
                Val::Float(v) => Ok(TextureDesc::Value(SpectrumDesc::Constant(v as f32))),
                Val::Rgb(c) => Ok(TextureDesc::Value(SpectrumDesc::Rgb(c))),
                Val::Spectrum(s) => Ok(TextureDesc::Value(s)),
                Val::Texture(t) => Ok(t),
                _ => Err(Self::type_err(ctx, &q, "a value or a <texture>")),
            },
        }
    }

    /// A dielectric index as a number: a float or a Mitsuba IOR name.
    fn ior_number(&mut self, ctx: &Ctx, name: &str, default: f64) -> Result<f64> {
        let v = match self.take(name) {
            None => default,
            Some(q) => match &q.val {
                Val::Float(v) => *v,
                Val::Str(s) => mitsuba_ior(s).ok_or_else(|| {
                    let names: Vec<_> = MITSUBA_IOR_TABLE.iter().map(|(n, _)| *n).collect();
                    ctx.err(
                        q.node,
                        format!("unknown IOR name \"{s}\" (known: {})", names.join(", ")),
                    )
                })?,
                _ => return Err(Self::type_err(ctx, &q, "a <float> or an IOR name <string>")),
            },
        };
        if !(v.is_finite() && v > 0.0) {
            return Err(ctx.err(self.node, format!("{name} must be > 0")));
        }
        Ok(v)
    }
}
