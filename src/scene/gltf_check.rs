//! glTF import with validation before use: a `.gltf`/`.glb` is checked completely before
//! any accessor is read, because the `gltf` crate's readers index buffers without bounds
//! checks of their own and its validation misses what this module checks:
//!
//! - the GLB container (lengths within the file), then the `gltf` crate's own validation;
//! - buffers (declared lengths within the memory budget, files present and long enough),
//!   buffer views (inside their buffer, legal strides), accessors (inside their view, count
//!   ≥ 1, not sparse), primitives (attribute and index accessors exist and have the types the
//!   loader reads, one vertex count), images (exactly one source, decoded size within the
//!   budget), textures, materials (every factor finite and in its range, texture indices
//!   valid), cameras (the projection object their `type` names present — the crate unwraps
//!   it — with a usable field of view, aspect ratio, magnification and clip range),
//!   `KHR_lights_punctual` (every light well formed, every node's light index valid), nodes
//!   (indices valid, each node at most one parent and no cycles — glTF nodes form disjoint
//!   trees — and finite transforms).
//!
//! Every error names the file and the JSON path of the culprit (`accessors[3]`).

use crate::limits::{check_alloc, check_range};
use anyhow::{anyhow, bail, Context, Result};
use gltf::json::accessor::{ComponentType, Type};
use gltf::json::mesh::Semantic;
use gltf::json::validation::Checked;
use gltf::json::Root;
use serde_json::Value;
use std::path::Path;

/// A validated document with its buffers and decoded images.
pub(crate) type Imported = (
    gltf::Document,
    Vec<gltf::buffer::Data>,
    Vec<gltf::image::Data>,
);

/// Reads, validates and loads `path` (see the module docs).
pub(crate) fn import(path: &Path) -> Result<Imported> {
    let file = path.display().to_string();
    let bytes = crate::limits::read_file(path, "glTF", 4)?;
    if bytes.starts_with(b"glTF") {
        check_glb(&bytes, &file)?;
    }
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(&bytes)
        .map_err(|e| anyhow!("{file}: not a readable glTF file: {e}"))?;
    let json = document.into_json();
    // Our checks first: the crate's validation itself indexes POSITION accessors unchecked.
    check_document(&json, blob.is_some(), &file)?;
    let document = gltf::Document::from_json(json).map_err(|e| match e {
        gltf::Error::Validation(errors) => {
            let list: Vec<String> = errors
                .iter()
                .take(8)
                .map(|(p, e)| format!("{p}: {e}"))
                .collect();
            anyhow!("{file}: invalid glTF: {}", list.join("; "))
        }
        other => anyhow!("{file}: not a valid glTF file: {other}"),
    })?;
    let root = document.as_json();
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = load_buffers(root, base, blob, &file)?;
    let images = load_images(root, base, &buffers, &file)?;
    Ok((document, buffers, images))
}

fn u32_at(b: &[u8], at: usize) -> u64 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]) as u64
}

/// The GLB header and chunk headers must describe lengths inside the file.
fn check_glb(b: &[u8], file: &str) -> Result<()> {
    let n = b.len() as u64;
    if n < 20 {
        bail!("{file}: a .glb needs a 12-byte header and a JSON chunk, but has {n} bytes");
    }
    let (version, length) = (u32_at(b, 4), u32_at(b, 8));
    if version != 2 {
        bail!("{file}: GLB version {version}; only version 2 is supported");
    }
    if !(20..=n).contains(&length) {
        bail!("{file}: GLB header declares {length} bytes but the file has {n}");
    }
    let mut at = 12u64;
    for expected in [b"JSON", b"BIN\0"] {
        if at == length {
            break;
        }
        if at + 8 > length {
            bail!("{file}: GLB chunk header at byte {at} runs past the end ({length} bytes)");
        }
        let chunk_len = u32_at(b, at as usize);
        let ty = &b[at as usize + 4..at as usize + 8];
        if ty != expected {
            bail!(
                "{file}: GLB chunk at byte {at} is {:?}, expected {:?}",
                String::from_utf8_lossy(ty),
                String::from_utf8_lossy(expected)
            );
        }
        at += 8 + chunk_len;
        if at > length {
            bail!(
                "{file}: GLB chunk {:?} of {chunk_len} bytes runs past the end ({length} bytes)",
                String::from_utf8_lossy(expected)
            );
        }
    }
    Ok(())
}

/// Bytes per component.
fn component_size(c: ComponentType) -> u64 {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// Components per element.
fn multiplicity(t: Type) -> u64 {
    match t {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

/// Component type and element type of accessor `i` (validated by the gltf crate).
fn accessor_kind(root: &Root, i: usize, file: &str) -> Result<(ComponentType, Type, u64)> {
    let a = root
        .accessors
        .get(i)
        .with_context(|| format!("{file}: accessors[{i}] does not exist"))?;
    match (&a.component_type, &a.type_) {
        (Checked::Valid(c), Checked::Valid(t)) => Ok((c.0, *t, a.count.0)),
        _ => bail!("{file}: accessors[{i}] has an invalid componentType or type"),
    }
}

fn check_document(root: &Root, has_blob: bool, file: &str) -> Result<()> {
    let major = root.asset.version.split('.').next().unwrap_or("");
    if major != "2" {
        bail!(
            "{file}: asset.version \"{}\": only glTF 2.x is supported",
            root.asset.version
        );
    }
    check_buffers(root, has_blob, file)?;
    check_accessors(root, file)?;
    check_meshes(root, file)?;
    check_nodes(root, file)?;
    check_cameras(root, file)?;
    check_lights(root, file)?;
    check_images_and_textures(root, file)?;
    for (i, m) in root.materials.iter().enumerate() {
        let value = serde_json::to_value(m)?;
        check_material_value(
            &value,
            &format!("materials[{i}]"),
            root.textures.len(),
            file,
        )?;
    }
    Ok(())
}

fn check_buffers(root: &Root, has_blob: bool, file: &str) -> Result<()> {
    for (i, b) in root.buffers.iter().enumerate() {
        check_alloc(
            format!("{file}: buffers[{i}].byteLength {}", b.byte_length.0),
            b.byte_length.0,
        )?;
        if b.uri.is_none() && !(i == 0 && has_blob) {
            bail!("{file}: buffers[{i}] has no uri (only the first buffer of a .glb may use its binary chunk)");
        }
    }
    for (i, v) in root.buffer_views.iter().enumerate() {
        let bi = v.buffer.value();
        let buffer = root
            .buffers
            .get(bi)
            .with_context(|| format!("{file}: bufferViews[{i}].buffer {bi} does not exist"))?;
        let offset = v.byte_offset.map_or(0, |o| o.0);
        let end = offset.checked_add(v.byte_length.0);
        if end.is_none_or(|e| e > buffer.byte_length.0) {
            bail!(
                "{file}: bufferViews[{i}] (byteOffset {offset}, byteLength {}) runs past the end of buffers[{bi}] ({} bytes)",
                v.byte_length.0,
                buffer.byte_length.0
            );
        }
        if let Some(s) = v.byte_stride {
            if !(4..=252).contains(&s.0) || s.0 % 4 != 0 {
                bail!(
                    "{file}: bufferViews[{i}].byteStride {} must be a multiple of 4 in [4, 252]",
                    s.0
                );
            }
        }
    }
    Ok(())
}

fn check_accessors(root: &Root, file: &str) -> Result<()> {
    for (i, a) in root.accessors.iter().enumerate() {
        let (comp, ty, count) = accessor_kind(root, i, file)?;
        if count == 0 {
            bail!("{file}: accessors[{i}].count must be ≥ 1");
        }
        if a.sparse.is_some() {
            bail!("{file}: accessors[{i}] is sparse; sparse accessors are not supported");
        }
        let elem = component_size(comp) * multiplicity(ty);
        let Some(vi) = a.buffer_view.map(|v| v.value()) else {
            // Zero-filled: the reader would allocate count elements.
            check_alloc(
                format!("{file}: accessors[{i}] ({count} elements)"),
                count.saturating_mul(elem),
            )?;
            continue;
        };
        let view = root
            .buffer_views
            .get(vi)
            .with_context(|| format!("{file}: accessors[{i}].bufferView {vi} does not exist"))?;
        let stride = view.byte_stride.map_or(elem, |s| s.0 as u64);
        if stride < elem {
            bail!("{file}: accessors[{i}]: bufferViews[{vi}].byteStride {stride} is smaller than its {elem}-byte elements");
        }
        let offset = a.byte_offset.map_or(0, |o| o.0);
        let need = (count - 1)
            .checked_mul(stride)
            .and_then(|b| b.checked_add(elem))
            .and_then(|b| b.checked_add(offset));
        if need.is_none_or(|n| n > view.byte_length.0) {
            bail!(
                "{file}: accessors[{i}] ({count} elements of {elem} bytes, stride {stride}, byteOffset {offset}) is longer than bufferViews[{vi}] ({} bytes)",
                view.byte_length.0
            );
        }
    }
    Ok(())
}

/// Accessor `idx` used as `what` must exist, have a bufferView and one of the `types`.
fn check_use(
    root: &Root,
    idx: usize,
    what: &str,
    types: &[(Type, &[ComponentType])],
    file: &str,
) -> Result<u64> {
    let (comp, ty, count) = accessor_kind(root, idx, file)
        .with_context(|| format!("{file}: {what} refers to accessors[{idx}]"))?;
    if !types.iter().any(|(t, cs)| *t == ty && cs.contains(&comp)) {
        bail!("{file}: {what} (accessors[{idx}]) is {ty:?} of {comp:?}, which the loader cannot read there");
    }
    if root.accessors[idx].buffer_view.is_none() {
        bail!("{file}: {what} (accessors[{idx}]) has no bufferView (zero-filled accessors are not supported there)");
    }
    Ok(count)
}

fn check_meshes(root: &Root, file: &str) -> Result<()> {
    use ComponentType::{F32, U16, U32, U8};
    for (mi, m) in root.meshes.iter().enumerate() {
        if m.primitives.is_empty() {
            bail!("{file}: meshes[{mi}] has no primitives");
        }
        for (pi, p) in m.primitives.iter().enumerate() {
            let at = format!("meshes[{mi}].primitives[{pi}]");
            if matches!(p.mode, Checked::Invalid) {
                bail!("{file}: {at}.mode is not a glTF primitive mode");
            }
            for (sem, idx) in &p.attributes {
                if idx.value() >= root.accessors.len() {
                    bail!(
                        "{file}: {at} attribute {} refers to accessors[{}], which does not exist",
                        sem.to_string(),
                        idx.value()
                    );
                }
            }
            let get = |s: Semantic| p.attributes.get(&Checked::Valid(s)).map(|i| i.value());
            let pos = get(Semantic::Positions)
                .with_context(|| format!("{file}: {at} has no POSITION attribute"))?;
            let n = check_use(
                root,
                pos,
                &format!("{at} POSITION"),
                &[(Type::Vec3, &[F32])],
                file,
            )?;
            // NORMAL, TANGENT and every TEXCOORD_n (a material may read any set).
            let mut vertex_attrs: Vec<(Semantic, String, &[(Type, &[ComponentType])])> = vec![
                (Semantic::Normals, "NORMAL".into(), &[(Type::Vec3, &[F32])]),
                (
                    Semantic::Tangents,
                    "TANGENT".into(),
                    &[(Type::Vec4, &[F32])],
                ),
            ];
            for sem in p.attributes.keys() {
                if let Checked::Valid(Semantic::TexCoords(k)) = sem {
                    let types: &[(Type, &[ComponentType])] = &[(Type::Vec2, &[F32, U8, U16])];
                    vertex_attrs.push((Semantic::TexCoords(*k), format!("TEXCOORD_{k}"), types));
                }
            }
            for (sem, name, types) in vertex_attrs {
                if let Some(i) = get(sem) {
                    let c = check_use(root, i, &format!("{at} {name}"), types, file)?;
                    if c != n {
                        bail!("{file}: {at} {name} has {c} elements but POSITION has {n}");
                    }
                }
            }
            if let Some(i) = p.indices.map(|i| i.value()) {
                check_use(
                    root,
                    i,
                    &format!("{at} indices"),
                    &[(Type::Scalar, &[U8, U16, U32])],
                    file,
                )?;
            }
            if let Some(mat) = p.material.map(|m| m.value()) {
                if mat >= root.materials.len() {
                    bail!("{file}: {at}.material {mat} does not exist");
                }
            }
        }
    }
    Ok(())
}

fn finite_all(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Nodes form disjoint trees: valid indices, at most one parent each, no cycles, scene roots
/// without parents; transforms finite.
fn check_nodes(root: &Root, file: &str) -> Result<()> {
    let n = root.nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for (i, node) in root.nodes.iter().enumerate() {
        let at = format!("nodes[{i}]");
        for c in node.children.iter().flatten().map(|c| c.value()) {
            if c >= n {
                bail!("{file}: {at}.children lists node {c}, which does not exist");
            }
            if c == i {
                bail!("{file}: node {i} is its own child");
            }
            if let Some(p) = parent[c] {
                bail!("{file}: node {c} is a child of node {p} and of node {i}; glTF nodes form trees (one parent each)");
            }
            parent[c] = Some(i);
        }
        if node.mesh.is_some_and(|m| m.value() >= root.meshes.len()) {
            bail!("{file}: {at}.mesh does not exist");
        }
        if node.camera.is_some_and(|c| c.value() >= root.cameras.len()) {
            bail!("{file}: {at}.camera does not exist");
        }
        let finite = node.matrix.is_none_or(|m| finite_all(&m))
            && node.translation.is_none_or(|t| finite_all(&t))
            && node.scale.is_none_or(|s| finite_all(&s))
            && node.rotation.is_none_or(|r| finite_all(&r.0));
        if !finite {
            bail!("{file}: node {i} has a non-finite transform (matrix, translation, rotation or scale)");
        }
    }
    // With one parent per node, a cycle is a parent chain longer than the node count.
    for start in 0..n {
        let (mut at, mut steps) = (start, 0);
        while let Some(p) = parent[at] {
            at = p;
            steps += 1;
            if steps > n {
                bail!("{file}: node {start} is its own ancestor: the node hierarchy has a cycle");
            }
        }
    }
    if let Some(s) = root.scene.map(|s| s.value()) {
        if s >= root.scenes.len() {
            bail!(
                "{file}: scene {s} does not exist (the file has {} scenes)",
                root.scenes.len()
            );
        }
    }
    for (si, scene) in root.scenes.iter().enumerate() {
        for r in scene.nodes.iter().map(|r| r.value()) {
            if r >= n {
                bail!("{file}: scenes[{si}].nodes lists node {r}, which does not exist");
            }
            if let Some(p) = parent[r] {
                bail!("{file}: scenes[{si}].nodes lists node {r}, which is a child of node {p}");
            }
        }
    }
    Ok(())
}

/// `KHR_lights_punctual`: the lights parse ([`super::gltf_lights::parse_lights`]) and every
/// node's light index names one of them.
fn check_lights(root: &Root, file: &str) -> Result<()> {
    let ext = root
        .extensions
        .as_ref()
        .and_then(|e| e.others.get("KHR_lights_punctual"));
    let lights = super::gltf_lights::parse_lights(ext, file)?;
    for (i, node) in root.nodes.iter().enumerate() {
        let ext = node
            .extensions
            .as_ref()
            .and_then(|e| e.others.get("KHR_lights_punctual"));
        super::gltf_lights::node_light(ext, lights.len(), i).with_context(|| file.to_string())?;
    }
    Ok(())
}

fn check_cameras(root: &Root, file: &str) -> Result<()> {
    use gltf::json::camera::Type;
    for (i, c) in root.cameras.iter().enumerate() {
        // The crate's `Camera::projection` unwraps the object its type names.
        let present = match c.type_ {
            Checked::Valid(Type::Perspective) => c.perspective.is_some(),
            Checked::Valid(Type::Orthographic) => c.orthographic.is_some(),
            Checked::Invalid => false,
        };
        if !present {
            bail!("{file}: cameras[{i}]: its type is missing, unknown or names a projection object the camera lacks");
        }
        if let Some(o) = &c.orthographic {
            let at = format!("{file}: cameras[{i}].orthographic");
            for (k, v) in [("xmag", o.xmag), ("ymag", o.ymag)] {
                check_range(format!("{at}.{k}"), v as f64, 1e-12, f32::MAX as f64)?;
            }
            check_range(format!("{at}.znear"), o.znear as f64, 0.0, f32::MAX as f64)?;
            if !(o.zfar > o.znear && o.zfar.is_finite()) {
                bail!(
                    "{at}.zfar {} must be finite and greater than znear {}",
                    o.zfar,
                    o.znear
                );
            }
        }
        let Some(p) = &c.perspective else { continue };
        let at = format!("{file}: cameras[{i}].perspective");
        check_range(
            format!("{at}.yfov"),
            p.yfov as f64,
            1e-6,
            std::f64::consts::PI - 1e-6,
        )?;
        check_range(
            format!("{at}.znear"),
            p.znear as f64,
            f32::MIN_POSITIVE as f64,
            f32::MAX as f64,
        )?;
        if let Some(z) = p.zfar {
            check_range(
                format!("{at}.zfar"),
                z as f64,
                p.znear as f64,
                f32::MAX as f64,
            )?;
        }
        if let Some(a) = p.aspect_ratio {
            check_range(format!("{at}.aspectRatio"), a as f64, 0.01, 100.0)?;
        }
    }
    Ok(())
}

fn check_images_and_textures(root: &Root, file: &str) -> Result<()> {
    for (i, img) in root.images.iter().enumerate() {
        match (&img.uri, img.buffer_view) {
            (Some(_), None) => {}
            (None, Some(v)) => {
                if v.value() >= root.buffer_views.len() {
                    bail!(
                        "{file}: images[{i}].bufferView {} does not exist",
                        v.value()
                    );
                }
                if img.mime_type.is_none() {
                    bail!("{file}: images[{i}] uses a bufferView but has no mimeType");
                }
            }
            _ => bail!("{file}: images[{i}] needs exactly one of 'uri' and 'bufferView'"),
        }
    }
    for (i, t) in root.textures.iter().enumerate() {
        if t.source.value() >= root.images.len() {
            bail!(
                "{file}: textures[{i}].source {} does not exist",
                t.source.value()
            );
        }
        if t.sampler.is_some_and(|s| s.value() >= root.samplers.len()) {
            bail!("{file}: textures[{i}].sampler does not exist");
        }
    }
    Ok(())
}

/// Ranges of material numbers by key (core glTF and the KHR extensions the loader reads).
const MATERIAL_DOMAINS: &[(&str, f64, f64)] = &[
    ("baseColorFactor", 0.0, 1.0),
    ("metallicFactor", 0.0, 1.0),
    ("roughnessFactor", 0.0, 1.0),
    ("emissiveFactor", 0.0, 1.0),
    ("alphaCutoff", 0.0, 1.0),
    ("transmissionFactor", 0.0, 1.0),
    ("iridescenceFactor", 0.0, 1.0),
    ("emissiveStrength", 0.0, 1e6),
    // The substrate's index: below 1 for metals (the fit's material.gltf writes gold's 0.35).
    ("ior", 1e-6, crate::limits::MAX_IOR),
    ("iridescenceIor", 1.0, crate::limits::MAX_IOR),
    ("iridescenceIOR", 1.0, crate::limits::MAX_IOR),
    (
        "iridescenceThicknessMinimum",
        0.0,
        crate::limits::MAX_THICKNESS_NM,
    ),
    (
        "iridescenceThicknessMaximum",
        0.0,
        crate::limits::MAX_THICKNESS_NM,
    ),
];

/// Walks a material's JSON: numbers under the keys of [`MATERIAL_DOMAINS`] must be in range
/// (a value the crate read as f32 infinity serialises as null, which fails too), and every
/// `index` of a texture reference must name an existing texture.
fn check_material_value(v: &Value, at: &str, textures: usize, file: &str) -> Result<()> {
    let Value::Object(map) = v else {
        return Ok(());
    };
    for (key, value) in map {
        let path = format!("{at}.{key}");
        if let Some(&(_, lo, hi)) = MATERIAL_DOMAINS.iter().find(|(k, _, _)| k == key) {
            let items: Vec<&Value> = match value {
                Value::Array(a) => a.iter().collect(),
                other => vec![other],
            };
            for item in items {
                let x = item.as_f64().unwrap_or(f64::NAN);
                check_range(format!("{file}: {path}"), x, lo, hi)?;
            }
        } else if key == "index" && at.ends_with("Texture") {
            let t = value.as_u64().unwrap_or(u64::MAX);
            if t >= textures as u64 {
                bail!("{file}: {path} = {value} does not name one of the {textures} textures");
            }
        } else if value.is_object() {
            check_material_value(value, &path, textures, file)?;
        }
    }
    Ok(())
}

/// Loads every buffer, naming the buffer and its file in errors.
fn load_buffers(
    root: &Root,
    base: &Path,
    mut blob: Option<Vec<u8>>,
    file: &str,
) -> Result<Vec<gltf::buffer::Data>> {
    let mut out = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        let data = match &b.uri {
            None => blob.take().with_context(|| {
                format!("{file}: buffers[{i}] refers to the .glb binary chunk, which is missing")
            })?,
            Some(uri) => read_uri(uri, base, &format!("buffers[{i}]"), file)?,
        };
        if (data.len() as u64) < b.byte_length.0 {
            bail!(
                "{file}: buffers[{i}] has {} bytes but its byteLength is {}",
                data.len(),
                b.byte_length.0
            );
        }
        out.push(gltf::buffer::Data(data));
    }
    Ok(out)
}

/// Bytes behind a `data:` URI or a file path relative to the glTF file.
fn read_uri(uri: &str, base: &Path, what: &str, file: &str) -> Result<Vec<u8>> {
    let shown: String = uri.chars().take(80).collect();
    if !uri.starts_with("data:") {
        if uri.contains("://") && !uri.starts_with("file://") {
            bail!("{file}: {what}.uri '{shown}': only relative paths, file: and data: URIs are supported");
        }
        let rel = uri
            .trim_start_matches("file://")
            .trim_start_matches("file:");
        let path = base.join(rel);
        // Percent-encoded names are left to the gltf crate's reader below.
        if !rel.contains('%') {
            let meta = std::fs::metadata(&path)
                .ok()
                .filter(|m| m.is_file())
                .with_context(|| {
                    format!(
                        "{file}: {what}: file '{uri}' not found (looked for {})",
                        path.display()
                    )
                })?;
            // Read whole, then copied out into vertex and index arrays: twice its size (a
            // 2 GiB buffer passed a check of its size alone and aborted in the allocator).
            check_alloc(
                format!("{file}: {what} file '{uri}' ({} bytes)", meta.len()),
                meta.len().saturating_mul(2),
            )?;
        }
    }
    gltf::buffer::Data::from_source(gltf::buffer::Source::Uri(uri), Some(base))
        .map(|d| d.0)
        .map_err(|e| anyhow!("{file}: {what}.uri '{shown}': {e}"))
}

/// Decodes every image (through the memory-budgeted decoder) into the layout the loader reads.
fn load_images(
    root: &Root,
    base: &Path,
    buffers: &[gltf::buffer::Data],
    file: &str,
) -> Result<Vec<gltf::image::Data>> {
    let mut out = Vec::with_capacity(root.images.len());
    for (i, img) in root.images.iter().enumerate() {
        let what = format!("images[{i}]");
        let bytes: Vec<u8> = match (&img.uri, img.buffer_view) {
            (Some(uri), None) => read_uri(uri, base, &what, file)?,
            (None, Some(v)) => {
                // In range: views lie inside their buffers' byteLength, and every buffer
                // holds at least that many bytes (both checked above).
                let view = &root.buffer_views[v.value()];
                let start = view.byte_offset.map_or(0, |o| o.0) as usize;
                buffers[view.buffer.value()][start..start + view.byte_length.0 as usize].to_vec()
            }
            _ => bail!("{file}: {what} needs exactly one of 'uri' and 'bufferView'"),
        };
        let name = match &img.uri {
            Some(u) if !u.starts_with("data:") => format!("{file}: {what} '{u}'"),
            _ => format!("{file}: {what}"),
        };
        let decoded = crate::image_io::decode_image_bytes(&bytes, &name, 16)?;
        let (width, height) = (decoded.width(), decoded.height());
        let (pixels, format) = if matches!(
            decoded.color(),
            image::ColorType::L16
                | image::ColorType::La16
                | image::ColorType::Rgb16
                | image::ColorType::Rgba16
        ) {
            let px = decoded.into_rgba16();
            let bytes = px.as_raw().iter().flat_map(|v| v.to_le_bytes()).collect();
            (bytes, gltf::image::Format::R16G16B16A16)
        } else {
            (
                decoded.into_rgba8().into_raw(),
                gltf::image::Format::R8G8B8A8,
            )
        };
        out.push(gltf::image::Data {
            pixels,
            format,
            width,
            height,
        });
    }
    Ok(out)
}
