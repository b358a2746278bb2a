//! Direct reader for binary PLY files (little or big endian): the header gives every
//! element's record layout, and the body is read straight into the mesh arrays.
//!
//! The general reader (`ply-rs-bw`, [`super::meshio::load_ply`]) keeps a map of named
//! properties per element: for a 2M-triangle mesh that was ~1 GB of allocations and most of
//! the scene's loading time. This reader handles what meshes use (scalar vertex properties;
//! integer face lists, other elements skipped) with the same results and error messages,
//! and answers `None` for anything else (ascii files, lists in the vertex element, float
//! index lists, a body shorter than its header says), which the general reader then reads
//! or rejects with its own message.

use super::ply_scalar::Ty;
use super::TriangleMesh;
use anyhow::{bail, Result};
use glam::{Vec2, Vec3};

impl Ty {
    /// The factor that maps a stored colour channel to [0, 1]: integer channels are
    /// normalised by their maximum (u8 / 255), floats are taken as stored.
    fn color_scale(self) -> f32 {
        match self {
            Ty::U8 => 1.0 / 255.0,
            Ty::U16 => 1.0 / 65535.0,
            _ => 1.0,
        }
    }

    fn is_int(self) -> bool {
        !matches!(self, Ty::F32 | Ty::F64)
    }
}

struct Prop {
    name: String,
    /// `Some(count type)` for a list.
    list: Option<Ty>,
    ty: Ty,
}

struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

/// A body cursor; every read is bounds-checked (None past the end).
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl Body<'_> {
    #[inline]
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let b: [u8; N] = self.bytes.get(self.pos..self.pos + N)?.try_into().ok()?;
        self.pos += N;
        Some(if self.big_endian {
            let mut r = b;
            r.reverse();
            r
        } else {
            b
        })
    }

    /// The value as f64: exact for every PLY type (the callers convert as `as f32`/`as i64`
    /// would from the stored type, which these round trips preserve).
    #[inline]
    fn read(&mut self, ty: Ty) -> Option<f64> {
        Some(match ty {
            Ty::I8 => i8::from_le_bytes(self.take()?) as f64,
            Ty::U8 => u8::from_le_bytes(self.take()?) as f64,
            Ty::I16 => i16::from_le_bytes(self.take()?) as f64,
            Ty::U16 => u16::from_le_bytes(self.take()?) as f64,
            Ty::I32 => i32::from_le_bytes(self.take()?) as f64,
            Ty::U32 => u32::from_le_bytes(self.take()?) as f64,
            Ty::F32 => f32::from_le_bytes(self.take()?) as f64,
            Ty::F64 => f64::from_le_bytes(self.take()?),
        })
    }

    /// A vertex property as the general reader converts it (`v as f32` from its type).
    #[inline]
    fn read_f32(&mut self, ty: Ty) -> Option<f32> {
        Some(match ty {
            Ty::F32 => f32::from_le_bytes(self.take()?),
            Ty::F64 => f64::from_le_bytes(self.take()?) as f32,
            Ty::I32 => i32::from_le_bytes(self.take()?) as f32,
            Ty::U32 => u32::from_le_bytes(self.take()?) as f32,
            other => self.read(other)? as f32,
        })
    }
}

/// Parses the header: (big endian, elements, body offset), or None if this reader does not
/// handle the file.
fn header(bytes: &[u8]) -> Option<(bool, Vec<Element>, usize)> {
    let mut pos = 0;
    let mut big_endian = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let end = pos
            + bytes
                .get(pos..)?
                .iter()
                .take(4096)
                .position(|&b| b == b'\n')?;
        let line = std::str::from_utf8(&bytes[pos..end]).ok()?;
        pos = end + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["ply"] | [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", "binary_little_endian", "1.0"] => big_endian = Some(false),
            ["format", "binary_big_endian", "1.0"] => big_endian = Some(true),
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().ok()?,
                props: Vec::new(),
            }),
            ["property", "list", count_ty, ty, name] => elements.last_mut()?.props.push(Prop {
                name: name.to_string(),
                list: Some(Ty::parse(count_ty).filter(|t| t.is_int())?),
                ty: Ty::parse(ty)?,
            }),
            ["property", ty, name] => elements.last_mut()?.props.push(Prop {
                name: name.to_string(),
                list: None,
                ty: Ty::parse(ty)?,
            }),
            ["end_header"] => break,
            _ => return None,
        }
    }
    Some((big_endian?, elements, pos))
}

/// Skips one record of `e`.
fn skip_record(body: &mut Body, e: &Element) -> Option<()> {
    for p in &e.props {
        let n = match p.list {
            Some(ct) => usize::try_from(body.read(ct)? as i64).ok()?,
            None => 1,
        };
        body.pos = body.pos.checked_add(n.checked_mul(p.ty.size())?)?;
        if body.pos > body.bytes.len() {
            return None;
        }
    }
    Some(())
}

/// Reads the vertex element into `mesh`; None if the layout is not handled or the body ends.
fn read_vertices(body: &mut Body, e: &Element, mesh: &mut TriangleMesh) -> Option<()> {
    if e.props.iter().any(|p| p.list.is_some()) {
        return None;
    }
    for (i, p) in e.props.iter().enumerate() {
        if e.props[..i].iter().any(|q| q.name == p.name) {
            return None; // duplicate names: leave the choice to the general reader
        }
    }
    let find = |k: &str| e.props.iter().position(|p| p.name == k);
    let xyz = [find("x")?, find("y")?, find("z")?];
    let normal = match (find("nx"), find("ny"), find("nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let uv = [("u", "v"), ("s", "t"), ("texture_u", "texture_v")]
        .into_iter()
        .find_map(|(a, b)| Some([find(a)?, find(b)?]));
    let rgb = [["red", "green", "blue"], ["r", "g", "b"]]
        .into_iter()
        .find_map(|k| Some([find(k[0])?, find(k[1])?, find(k[2])?]));
    let stride: usize = e.props.iter().map(|p| p.ty.size()).sum();
    if body.bytes.len() - body.pos < e.count.checked_mul(stride)? {
        return None;
    }
    mesh.positions.reserve_exact(e.count);
    if normal.is_some() {
        mesh.normals.reserve_exact(e.count);
    }
    if uv.is_some() {
        mesh.uvs.reserve_exact(e.count);
    }
    if rgb.is_some() {
        mesh.colors.reserve_exact(e.count);
    }
    let mut vals = vec![0.0f32; e.props.len()];
    for _ in 0..e.count {
        for (v, p) in vals.iter_mut().zip(&e.props) {
            *v = body.read_f32(p.ty)?;
        }
        mesh.positions.push(Vec3::from(xyz.map(|k| vals[k])));
        if let Some(n) = normal {
            mesh.normals.push(Vec3::from(n.map(|k| vals[k])));
        }
        if let Some([a, b]) = uv {
            mesh.uvs.push(Vec2::new(vals[a], vals[b]));
        }
        if let Some(c) = rgb {
            mesh.colors
                .push(Vec3::from(c.map(|k| vals[k] * e.props[k].ty.color_scale())));
        }
    }
    Some(())
}

/// Reads the face element's index lists into `mesh` (fan-triangulated). Ok(None) if the
/// layout is not handled or the body ends; errors for faces the general reader rejects too.
fn read_faces(
    body: &mut Body,
    e: &Element,
    mesh: &mut TriangleMesh,
    what: &str,
) -> Result<Option<()>> {
    let Some(list) = e
        .props
        .iter()
        .position(|p| p.name == "vertex_indices")
        .or_else(|| e.props.iter().position(|p| p.name == "vertex_index"))
    else {
        return Ok(None);
    };
    let (Some(count_ty), true) = (e.props[list].list, e.props[list].ty.is_int()) else {
        return Ok(None);
    };
    let item_ty = e.props[list].ty;
    let nv = mesh.positions.len() as i64;
    // Each record holds at least its scalars and list counts: reserve only what fits.
    let min_record: usize = e.props.iter().map(|p| p.list.unwrap_or(p.ty).size()).sum();
    if e.count.saturating_mul(min_record) > body.bytes.len() - body.pos {
        return Ok(None);
    }
    mesh.indices.reserve(e.count);
    let mut face = Vec::new();
    for k in 0..e.count {
        for (j, p) in e.props.iter().enumerate() {
            if j != list {
                let n = match p.list {
                    Some(ct) => match body.read(ct).and_then(|c| usize::try_from(c as i64).ok()) {
                        Some(n) => n,
                        None => return Ok(None),
                    },
                    None => 1,
                };
                body.pos = body.pos.saturating_add(n.saturating_mul(p.ty.size()));
                if body.pos > body.bytes.len() {
                    return Ok(None);
                }
                continue;
            }
            let Some(n) = body.read(count_ty).map(|c| c as i64) else {
                return Ok(None);
            };
            if n < 0 || (n as usize).saturating_mul(item_ty.size()) > body.bytes.len() - body.pos {
                return Ok(None);
            }
            face.clear();
            for _ in 0..n {
                face.push(body.read(item_ty).map(|v| v as i64).unwrap_or(-1));
            }
            if face.len() < 3 {
                bail!("{what}: face {k} has {} vertices (need ≥ 3)", face.len());
            }
            if let Some(bad) = face.iter().find(|&&i| i < 0 || i >= nv) {
                bail!("{what}: face {k} refers to vertex {bad}, but there are {nv} vertices");
            }
            for j in 1..face.len() - 1 {
                mesh.indices
                    .push([face[0] as u32, face[j] as u32, face[j + 1] as u32]);
            }
        }
    }
    Ok(Some(()))
}

/// Loads `path` if it is a binary PLY this reader handles (the header is checked before the
/// body is read); Ok(None) hands the file to the general reader.
pub(super) fn load_file(path: &std::path::Path, what: &str) -> Result<Option<TriangleMesh>> {
    use anyhow::Context;
    use std::io::Read;
    let mut prefix = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(1 << 16).read_to_end(&mut prefix))
        .with_context(|| format!("reading {}", path.display()))?;
    if header(&prefix).is_none() {
        return Ok(None);
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    load(&bytes, what)
}

/// Loads a binary PLY mesh from its bytes (see the module documentation); Ok(None) hands the
/// file to the general reader.
fn load(bytes: &[u8], what: &str) -> Result<Option<TriangleMesh>> {
    let Some((big_endian, elements, start)) = header(bytes) else {
        return Ok(None);
    };
    if !elements.iter().any(|e| e.name == "face") {
        return Ok(None);
    }
    let mut body = Body {
        bytes,
        pos: start,
        big_endian,
    };
    let mut mesh = TriangleMesh::default();
    let (mut seen_vertex, mut seen_face) = (false, false);
    for e in &elements {
        if e.name == "vertex" && !seen_vertex {
            seen_vertex = true;
            if read_vertices(&mut body, e, &mut mesh).is_none() {
                return Ok(None);
            }
        } else if e.name == "face" && !seen_face {
            seen_face = true;
            if !seen_vertex || read_faces(&mut body, e, &mut mesh, what)?.is_none() {
                return Ok(None);
            }
        } else {
            for _ in 0..e.count {
                if skip_record(&mut body, e).is_none() {
                    return Ok(None);
                }
            }
        }
    }
    if mesh.indices.is_empty() {
        bail!("{what} contains no faces");
    }
    mesh.validate(what)?;
    Ok(Some(mesh))
}

#[cfg(test)]
mod tests {
    use super::super::meshio::{load_ply, load_ply_general, write_ply_binary};
    use super::*;
    use std::path::Path;

    fn same(a: &TriangleMesh, b: &TriangleMesh) {
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.normals, b.normals);
        assert_eq!(a.uvs, b.uvs);
        assert_eq!(a.indices, b.indices);
    }

    /// A scratch file in the temp directory, removed when dropped (tests run in parallel
    /// threads of one process: one file each, no shared directory to remove).
    struct TmpFile(std::path::PathBuf);

    impl Drop for TmpFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    impl std::ops::Deref for TmpFile {
        type Target = Path;
        fn deref(&self) -> &Path {
            &self.0
        }
    }

    impl AsRef<Path> for TmpFile {
        fn as_ref(&self) -> &Path {
            &self.0
        }
    }

    fn tmp(name: &str) -> TmpFile {
        let file = format!("thinfilm-ply-{}-{name}", std::process::id());
        TmpFile(std::env::temp_dir().join(file))
    }

    /// Header + body of a little- or big-endian file: uchar/ushort/double vertex properties
    /// (x as double, uv as s/t), an unrelated element with a list before the faces, a quad
    /// with an extra per-face list and a uint index list.
    fn odd_layout(big: bool) -> Vec<u8> {
        let fmt = if big { "big" } else { "little" };
        let mut b = format!(
            "ply\nformat binary_{fmt}_endian 1.0\ncomment odd layout\nelement vertex 5\n\
             property double x\nproperty float y\nproperty float z\nproperty uchar flag\n\
             property float s\nproperty float t\nelement junk 2\nproperty list uchar short j\n\
             property ushort k\nelement face 2\nproperty list uchar float w\n\
             property list ushort uint vertex_indices\nend_header\n"
        )
        .into_bytes();
        let put = |b: &mut Vec<u8>, le: &[u8]| {
            let mut v = le.to_vec();
            if big {
                v.reverse();
            }
            b.extend(v);
        };
        for i in 0..5u8 {
            put(&mut b, &(i as f64 * 0.25 - 0.3).to_le_bytes());
            put(&mut b, &(i as f32 * 1.5).to_le_bytes());
            put(&mut b, &(-(i as f32)).to_le_bytes());
            b.push(7);
            put(&mut b, &(i as f32 / 8.0).to_le_bytes());
            put(&mut b, &(1.0 - i as f32 / 8.0).to_le_bytes());
        }
        for n in [1u8, 0] {
            b.push(n);
            for _ in 0..n {
                put(&mut b, &(-3i16).to_le_bytes());
            }
            put(&mut b, &9u16.to_le_bytes());
        }
        for face in [&[0u32, 1, 2, 3][..], &[4, 0, 2]] {
            b.push(1);
            put(&mut b, &0.5f32.to_le_bytes());
            put(&mut b, &(face.len() as u16).to_le_bytes());
            for &i in face {
                put(&mut b, &i.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn direct_reader_matches_the_general_reader() {
        // The project's own writer (positions, normals, uvs).
        let mut mesh = crate::scene::shapes::cube();
        mesh.ensure_normals();
        mesh.uvs = mesh.positions.iter().map(|p| Vec2::new(p.x, p.y)).collect();
        let path = tmp("cube.ply");
        write_ply_binary(&path, &mesh).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let direct = load(&bytes, "cube").unwrap().expect("handled");
        same(&direct, &load_ply_general(&path).unwrap());
        same(&direct, &mesh);
        for big in [false, true] {
            let path = tmp(&format!("odd{big}.ply"));
            std::fs::write(&path, odd_layout(big)).unwrap();
            let direct = load(&odd_layout(big), "odd").unwrap().expect("handled");
            assert_eq!(direct.indices.len(), 3, "quad fanned + triangle");
            assert_eq!(direct.uvs.len(), 5);
            same(&direct, &load_ply_general(&path).unwrap());
            same(&direct, &load_ply(&path).unwrap());
        }
    }

    #[test]
    fn direct_reader_rejects_like_the_general_reader_or_hands_over() {
        let good = odd_layout(false);
        // Out-of-range index: same message from both readers.
        let mut bad = good.clone();
        let n = bad.len();
        bad[n - 4..].copy_from_slice(&99u32.to_le_bytes());
        let path = tmp("badindex.ply");
        std::fs::write(&path, &bad).unwrap();
        let e = load(&bad, "PLY x").unwrap_err().to_string();
        assert!(e.contains("face 1 refers to vertex 99"), "{e}");
        let general = load_ply_general(&path).unwrap_err();
        assert!(format!("{general:#}").contains("face 1 refers to vertex 99"));
        // Truncated body, ascii, counts larger than the file: not handled here.
        assert!(load(&good[..good.len() - 3], "t").unwrap().is_none());
        assert!(load(b"ply\nformat ascii 1.0\nend_header\n", "a")
            .unwrap()
            .is_none());
        let at = good.windows(12).position(|w| w == b"element face").unwrap();
        let mut huge = good[..at].to_vec();
        huge.extend_from_slice(b"element face 2000000000000");
        huge.extend_from_slice(&good[at + b"element face 2".len()..]);
        assert!(load(&huge, "h").unwrap().is_none());
    }
}
