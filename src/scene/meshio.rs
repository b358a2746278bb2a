//! Mesh files: Wavefront OBJ (via `tobj`) and Stanford PLY, ASCII or binary (binary meshes
//! through [`super::ply_binary`], everything else via `ply-rs-bw`), plus a small binary-PLY writer for the project's own assets.
//!
//! Texture coordinates follow Mitsuba 3: OBJ `vt` v is flipped (v ↦ 1 − v, as Mitsuba's OBJ
//! loader does), PLY `u v` (or `s t`, `texture_u texture_v`) are taken as stored.
//! All groups/objects of an OBJ file become one mesh (Mitsuba's `obj` shape does the same).

use super::TriangleMesh;
use anyhow::{anyhow, bail, Context, Result};
use glam::{Vec2, Vec3};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::io::Write;
use std::path::Path;

fn check_exists(path: &Path, what: &str) -> Result<()> {
    if !path.is_file() {
        bail!("{what} file {} does not exist", path.display());
    }
    Ok(())
}

/// Loads every model of an OBJ file into one triangle mesh (polygons triangulated).
/// Normals are kept if the file has them for every vertex; otherwise left empty.
pub fn load_obj(path: &Path) -> Result<TriangleMesh> {
    check_exists(path, "OBJ")?;
    let (models, _materials) = tobj::load_obj(path, &tobj::GPU_LOAD_OPTIONS)
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("reading OBJ {}", path.display()))?;
    let mut mesh = TriangleMesh::default();
    for model in &models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        let part = TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions: m
                .positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect(),
            normals: if m.normals.len() == 3 * n {
                m.normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2]))
                    .collect()
            } else {
                Vec::new()
            },
            uvs: if m.texcoords.len() == 2 * n {
                m.texcoords
                    .chunks_exact(2)
                    .map(|c| Vec2::new(c[0], 1.0 - c[1]))
                    .collect()
            } else {
                Vec::new()
            },
            indices: m
                .indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        };
        mesh.append(&part);
    }
    if mesh.indices.is_empty() {
        bail!("OBJ {} contains no triangles", path.display());
    }
    mesh.validate(&format!("OBJ {}", path.display()))?;
    Ok(mesh)
}

fn prop_f32(p: &Property) -> Option<f32> {
    Some(match *p {
        Property::Char(v) => v as f32,
        Property::UChar(v) => v as f32,
        Property::Short(v) => v as f32,
        Property::UShort(v) => v as f32,
        Property::Int(v) => v as f32,
        Property::UInt(v) => v as f32,
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        _ => return None,
    })
}

/// A PLY colour channel in [0, 1]: integer channels normalised by their maximum (u8 / 255),
/// floats as stored.
fn color_channel(p: &Property) -> Option<f32> {
    match *p {
        Property::UChar(v) => Some(v as f32 / 255.0),
        Property::UShort(v) => Some(v as f32 / 65535.0),
        _ => prop_f32(p),
    }
}

fn prop_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

/// Bytes of a PLY scalar type, or None for an unknown name.
fn ply_type_size(name: &str) -> Option<u64> {
    Some(match name {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "int32" | "uint32" | "float" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

/// Checks a PLY header's element counts against the file before the reader allocates one
/// record per element: an element occupies at least its fixed-size properties (and each
/// list's count) in a binary file, one character and a separator per property in an ascii
/// one — and an element without properties occupies nothing, so its count is unbounded.
fn check_ply_header(path: &Path, what: &str) -> Result<()> {
    use std::io::{BufRead, Read};
    let file_len = std::fs::metadata(path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    let mut reader = std::io::BufReader::new(std::fs::File::open(path)?);
    let (mut header_len, mut ascii) = (0u64, false);
    // (name, count, minimum bytes per element, properties)
    let mut elements: Vec<(String, u64, u64, usize)> = Vec::new();
    let mut line = Vec::new();
    loop {
        line.clear();
        let n = reader.by_ref().take(4096).read_until(b'\n', &mut line)?;
        if n == 0 || header_len > 1 << 20 {
            return Ok(()); // no end_header: the reader reports it
        }
        header_len += n as u64;
        let text = String::from_utf8_lossy(&line);
        let words: Vec<&str> = text.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", f, ..] => ascii = *f == "ascii",
            ["element", name, count] => {
                let count = count.parse::<u64>().map_err(|_| {
                    anyhow!("{what}: element '{name}' has count '{count}', not a whole number")
                })?;
                elements.push((name.to_string(), count, 0, 0));
            }
            ["property", "list", count_type, _, _] | ["property", count_type, _] => {
                if let Some(e) = elements.last_mut() {
                    let size = ply_type_size(count_type).unwrap_or(1);
                    e.2 += if ascii { 2 } else { size };
                    e.3 += 1;
                }
            }
            _ => {}
        }
    }
    let body = file_len.saturating_sub(header_len);
    let mut records = 0u64;
    for (name, count, min_bytes, props) in &elements {
        if *props == 0 && *count > 0 {
            bail!("{what}: element '{name}' (count {count}) has no properties");
        }
        let need = count.saturating_mul(*min_bytes);
        if need > body {
            bail!(
                "{what}: the header declares {count} '{name}' elements, at least {need} bytes, but only {body} bytes follow it"
            );
        }
        records = records.saturating_add(*count);
    }
    // The reader keeps a map of named properties per element (~256 bytes each).
    crate::limits::check_alloc(
        format!("{what}: {records} elements"),
        records.saturating_mul(256),
    )
}

/// Loads a PLY mesh (ascii, binary little or big endian). Vertex properties x, y, z
/// (required), nx, ny, nz, u, v / s, t / texture_u, texture_v and red, green, blue / r, g, b
/// (optional; Mitsuba's `vertex_color` attribute); faces from
/// `vertex_indices` or `vertex_index`, polygons fan-triangulated.
pub fn load_ply(path: &Path) -> Result<TriangleMesh> {
    check_exists(path, "PLY")?;
    if let Some(mesh) = super::ply_binary::load_file(path, &format!("PLY {}", path.display()))? {
        return Ok(mesh);
    }
    load_ply_general(path)
}

/// [`load_ply`] through `ply-rs-bw`: every PLY the direct binary reader does not handle.
pub(super) fn load_ply_general(path: &Path) -> Result<TriangleMesh> {
    check_ply_header(path, &format!("PLY {}", path.display()))?;
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("reading PLY {}", path.display()))?;
    let what = format!("PLY {}", path.display());
    let vertices = ply
        .payload
        .get("vertex")
        .with_context(|| format!("{what}: no 'vertex' element"))?;
    let faces = ply
        .payload
        .get("face")
        .with_context(|| format!("{what}: no 'face' element"))?;
    let get = |e: &DefaultElement, k: &str| e.get(k).and_then(prop_f32);
    let mut mesh = TriangleMesh::default();
    let first = vertices.first();
    let has = |k: &str| first.is_some_and(|e| e.get(k).is_some());
    let uv_keys = [("u", "v"), ("s", "t"), ("texture_u", "texture_v")]
        .into_iter()
        .find(|(a, b)| has(a) && has(b));
    let has_n = has("nx") && has("ny") && has("nz");
    let rgb_keys = [["red", "green", "blue"], ["r", "g", "b"]]
        .into_iter()
        .find(|k| k.iter().all(|c| has(c)));
    for (i, e) in vertices.iter().enumerate() {
        let p = match (get(e, "x"), get(e, "y"), get(e, "z")) {
            (Some(x), Some(y), Some(z)) => Vec3::new(x, y, z),
            _ => bail!("{what}: vertex {i} lacks numeric x, y, z"),
        };
        mesh.positions.push(p);
        if has_n {
            let n = Vec3::new(
                get(e, "nx").unwrap_or(0.0),
                get(e, "ny").unwrap_or(0.0),
                get(e, "nz").unwrap_or(0.0),
            );
            mesh.normals.push(n);
        }
        if let Some((ku, kv)) = uv_keys {
            mesh.uvs.push(Vec2::new(
                get(e, ku).unwrap_or(0.0),
                get(e, kv).unwrap_or(0.0),
            ));
        }
        if let Some(keys) = rgb_keys {
            let c = keys.map(|k| e.get(k).and_then(color_channel).unwrap_or(0.0));
            mesh.colors.push(Vec3::from(c));
        }
    }
    let nv = mesh.positions.len() as i64;
    for (k, f) in faces.iter().enumerate() {
        let list = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(prop_list)
            .with_context(|| format!("{what}: face {k} has no integer list 'vertex_indices'"))?;
        if list.len() < 3 {
            bail!("{what}: face {k} has {} vertices (need ≥ 3)", list.len());
        }
        if let Some(bad) = list.iter().find(|&&i| i < 0 || i >= nv) {
            bail!("{what}: face {k} refers to vertex {bad}, but there are {nv} vertices");
        }
        for j in 1..list.len() - 1 {
            mesh.indices
                .push([list[0] as u32, list[j] as u32, list[j + 1] as u32]);
        }
    }
    if mesh.indices.is_empty() {
        bail!("{what} contains no faces");
    }
    mesh.validate(&what)?;
    Ok(mesh)
}

/// Writes a binary little-endian PLY with positions, normals and uvs if present (float32)
/// and `uchar`-counted `int` triangle lists — the layout Mitsuba's `ply` shape reads.
pub fn write_ply_binary(path: &Path, mesh: &TriangleMesh) -> Result<()> {
    mesh.validate("mesh to write")?;
    let mut buf = Vec::new();
    writeln!(buf, "ply\nformat binary_little_endian 1.0")?;
    writeln!(buf, "comment written by thinfilm")?;
    writeln!(buf, "element vertex {}", mesh.positions.len())?;
    for k in ["x", "y", "z"] {
        writeln!(buf, "property float {k}")?;
    }
    if !mesh.normals.is_empty() {
        for k in ["nx", "ny", "nz"] {
            writeln!(buf, "property float {k}")?;
        }
    }
    if !mesh.uvs.is_empty() {
        for k in ["u", "v"] {
            writeln!(buf, "property float {k}")?;
        }
    }
    writeln!(buf, "element face {}", mesh.indices.len())?;
    writeln!(buf, "property list uchar int vertex_indices\nend_header")?;
    for i in 0..mesh.positions.len() {
        let mut vals = mesh.positions[i].to_array().to_vec();
        if !mesh.normals.is_empty() {
            vals.extend(mesh.normals[i].to_array());
        }
        if !mesh.uvs.is_empty() {
            vals.extend(mesh.uvs[i].to_array());
        }
        for v in vals {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in &mesh.indices {
        buf.push(3);
        for &i in t {
            buf.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    crate::image_io::write_atomically(path, |tmp| {
        std::fs::write(tmp, &buf).with_context(|| format!("writing {}", tmp.display()))
    })
}
