//! Mitsuba's `.serialized` triangle meshes (the `serialized` shape plugin).
//!
//! Layout (Mitsuba 3.9 `src/shapes/serialized.cpp`, little endian): every mesh starts with an
//! uncompressed header — `u16` magic `0x041C`, `u16` version (3, 4 or 5) — followed by a zlib
//! stream. A file may hold several meshes one after another; a table at the end of the file
//! gives each mesh's byte offset (version 3: `u32` offsets, version 4/5: `u64`), followed by
//! the `u32` mesh count, so `shape_index` can seek straight to its mesh.
//!
//! Versions 3 and 4 (written by Mitsuba 0.x, 2 and 3 up to 3.8), inside the zlib stream:
//! `u32` flags (0x1 normals, 0x2 texture coordinates, 0x8 vertex colours, 0x1000 single /
//! 0x2000 double precision), version 4 only: a NUL-terminated name; `u64` vertex count V,
//! `u64` face count F; 3V positions, [3V normals], [2V uvs], [3V colours] (f32 or f64), 3F
//! `u32` vertex indices.
//!
//! Version 5 (Mitsuba 3.9): `u32` flags (low bits: 0x1 normals, 0x2 tangents, 0x4 uvs;
//! 0x10 face normals; 0x1000 single precision, required), a `u32`-length-prefixed name,
//! `u64` V, F, P (surface-point count), N (normal-group count); 8V f32 vertex records
//! (position, normal, uv); 4F `u32` face records (three indices and a BSDF index); V `u32`
//! surface-point and V `u32` normal-group indices when P, N > 0; then custom attributes.
//! Records with stored tangents encode a whole shading frame in the normal lanes, which this
//! loader does not decode (an error says so).
//!
//! Vertex colours (versions 3/4) become the mesh's colours (a `mesh_attribute`
//! `vertex_color` reads them); custom attributes are read past and not used (an error would
//! refuse meshes Mitsuba renders identically: they only matter to a `mesh_attribute` texture).

use super::TriangleMesh;
use anyhow::{bail, Context, Result};
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3};
use std::io::Read;
use std::path::Path;

const MAGIC: u16 = 0x041C;

/// Largest vertex or face count accepted from a header (2^28: 8 GiB of f32 vertex records),
/// so that a corrupt count fails with a message instead of an allocation failure.
const MAX_COUNT: u64 = 1 << 28;

/// Deflate (zlib) expands at most 1032:1 (a run of one byte, 258 bytes per 2-bit code): a
/// header declaring more vertex and face data than that over the compressed bytes left in
/// the file is corrupt, or a decompression bomb.
const MAX_ZLIB_RATIO: u64 = 1032;

/// A mesh read from a `.serialized` file, in object space.
#[derive(Debug)]
pub struct SerializedMesh {
    pub mesh: TriangleMesh,
    /// The file asks for face normals (version 5 flag 0x10); used when the scene leaves
    /// `face_normals` unset, as Mitsuba does.
    pub face_normals: bool,
}

/// Reads mesh number `shape_index` (0-based) of a `.serialized` file.
pub fn load(path: &Path, shape_index: usize) -> Result<SerializedMesh> {
    let bytes = crate::limits::read_file(path, "serialized mesh", 1)?;
    parse(&bytes, shape_index).with_context(|| {
        format!(
            "serialized mesh {} (shape_index {shape_index})",
            path.display()
        )
    })
}

/// Parses mesh `shape_index` of a `.serialized` file held in memory.
pub fn parse(bytes: &[u8], shape_index: usize) -> Result<SerializedMesh> {
    let (magic, version) = header(bytes, 0)?;
    if magic != MAGIC {
        bail!("not a Mitsuba .serialized file (magic 0x{magic:04X}, expected 0x{MAGIC:04X})");
    }
    if !(3..=5).contains(&version) {
        bail!("unsupported .serialized version {version} (3, 4 and 5 are read)");
    }
    let offset = if shape_index == 0 {
        0
    } else {
        mesh_offset(bytes, version, shape_index)?
    };
    let (magic, v) = header(bytes, offset)?;
    if magic != MAGIC || v != version {
        bail!("mesh {shape_index} at byte {offset} has no valid header");
    }
    let compressed = &bytes[offset + 4..];
    let mut r = Reader {
        r: &mut ZlibDecoder::new(compressed),
        compressed: compressed.len() as u64,
    };
    if version == 5 {
        read_v5(&mut r)
    } else {
        read_legacy(&mut r, version)
    }
}

fn header(bytes: &[u8], offset: usize) -> Result<(u16, u16)> {
    let h = bytes
        .get(offset..offset + 4)
        .with_context(|| format!("file ends before the mesh header at byte {offset}"))?;
    Ok((
        u16::from_le_bytes([h[0], h[1]]),
        u16::from_le_bytes([h[2], h[3]]),
    ))
}

/// The byte offset of mesh `index` from the end-of-file table.
fn mesh_offset(bytes: &[u8], version: u16, index: usize) -> Result<usize> {
    let n = bytes.len();
    let tail = |start: usize, len: usize| -> Result<&[u8]> {
        bytes
            .get(start..start + len)
            .context("file too short for its mesh offset table")
    };
    if n < 4 {
        bail!("file too short for its mesh count");
    }
    let count = u32::from_le_bytes(tail(n - 4, 4)?.try_into().unwrap()) as usize;
    if index >= count {
        bail!(
            "shape_index {index} is out of range: the file holds {count} mesh{}",
            if count == 1 { "" } else { "es" }
        );
    }
    let from_end = count - index;
    let offset = if version == 3 {
        let start = n
            .checked_sub(4 * (from_end + 1))
            .context("file too short for its mesh offset table")?;
        u32::from_le_bytes(tail(start, 4)?.try_into().unwrap()) as usize
    } else {
        let start = n
            .checked_sub(8 * from_end + 4)
            .context("file too short for its mesh offset table")?;
        let o = u64::from_le_bytes(tail(start, 8)?.try_into().unwrap());
        usize::try_from(o).context("mesh offset does not fit in memory")?
    };
    if offset + 4 > n {
        bail!("mesh {index} offset {offset} lies beyond the end of the file ({n} bytes)");
    }
    Ok(offset)
}

struct Reader<'r, R: Read> {
    r: &'r mut R,
    /// Bytes of the compressed stream (from the mesh header to the end of the file).
    compressed: u64,
}

impl<R: Read> Reader<'_, R> {
    /// The next `n` decompressed bytes. The buffer grows with the data actually decoded, so
    /// a truncated stream fails before it allocates what the header declared.
    fn bytes(&mut self, n: usize) -> Result<Vec<u8>> {
        let mut buf = Vec::new();
        self.r
            .by_ref()
            .take(n as u64)
            .read_to_end(&mut buf)
            .context("corrupt compressed data")?;
        if buf.len() < n {
            bail!("compressed data ends early (truncated or corrupt file)");
        }
        Ok(buf)
    }
    /// Checks the data a header declares — `vertices` records of `vertex_bytes` and `faces` of
    /// `face_bytes` — against what the compressed stream can hold and the memory budget
    /// (the decoded records plus the mesh built from them: 32 bytes a vertex, 12 a face).
    fn check_declared(
        &self,
        (vertices, vertex_bytes): (usize, u64),
        (faces, face_bytes): (usize, u64),
    ) -> Result<()> {
        let (v, f) = (vertices as u64, faces as u64);
        // Counts are at most 2^28 and record sizes at most 96 bytes: no overflow.
        let raw = v * vertex_bytes + f * face_bytes;
        if raw > self.compressed.saturating_mul(MAX_ZLIB_RATIO) {
            bail!(
                "the header declares {vertices} vertices and {faces} faces ({raw} bytes), but \
                 the compressed mesh has {} bytes and zlib expands at most {MAX_ZLIB_RATIO}:1 \
                 (corrupt file)",
                self.compressed
            );
        }
        crate::limits::check_alloc(
            format!("{vertices} vertices and {faces} faces"),
            raw + v * 32 + f * 12,
        )
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.bytes(4)?.try_into().unwrap()))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.bytes(8)?.try_into().unwrap()))
    }
    fn count(&mut self, what: &str) -> Result<usize> {
        let n = self.u64()?;
        if n > MAX_COUNT {
            bail!("{what} count {n} exceeds the limit of {MAX_COUNT}");
        }
        Ok(n as usize)
    }
    /// `n` floats stored as f32 or (`double`) f64.
    fn floats(&mut self, n: usize, double: bool) -> Result<Vec<f32>> {
        if double {
            let b = self.bytes(8 * n)?;
            Ok(b.chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32)
                .collect())
        } else {
            let b = self.bytes(4 * n)?;
            Ok(b.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect())
        }
    }
    fn u32s(&mut self, n: usize) -> Result<Vec<u32>> {
        let b = self.bytes(4 * n)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
}

fn vec3s(v: &[f32]) -> Vec<Vec3> {
    v.chunks_exact(3).map(Vec3::from_slice).collect()
}

fn read_legacy<R: Read>(r: &mut Reader<R>, version: u16) -> Result<SerializedMesh> {
    let flags = r.u32()?;
    if version == 4 {
        // NUL-terminated shape name.
        let mut len = 0;
        while r.bytes(1)?[0] != 0 {
            len += 1;
            if len > 1 << 16 {
                bail!("shape name is not terminated");
            }
        }
    }
    let vertices = r.count("vertex")?;
    let faces = r.count("face")?;
    let double = flags & 0x2000 != 0;
    let channels = [
        (true, 3),
        (flags & 0x1 != 0, 3),
        (flags & 0x2 != 0, 2),
        (flags & 0x8 != 0, 3),
    ]
    .iter()
    .filter(|c| c.0)
    .map(|c| c.1)
    .sum::<u64>();
    let float_bytes = if double { 8 } else { 4 };
    r.check_declared((vertices, channels * float_bytes), (faces, 12))?;
    let positions = vec3s(&r.floats(3 * vertices, double)?);
    let normals = if flags & 0x1 != 0 {
        vec3s(&r.floats(3 * vertices, double)?)
    } else {
        Vec::new()
    };
    let uvs = if flags & 0x2 != 0 {
        r.floats(2 * vertices, double)?
            .chunks_exact(2)
            .map(|c| Vec2::new(c[0], c[1]))
            .collect()
    } else {
        Vec::new()
    };
    // Mitsuba's `vertex_color` attribute (for a `mesh_attribute` texture).
    let colors = if flags & 0x8 != 0 {
        vec3s(&r.floats(3 * vertices, double)?)
    } else {
        Vec::new()
    };
    let indices = triangles(&r.u32s(3 * faces)?, 3, vertices)?;
    Ok(SerializedMesh {
        mesh: TriangleMesh {
            colors,
            tangents: Vec::new(),
            positions,
            normals,
            uvs,
            indices,
        },
        face_normals: false,
    })
}

fn read_v5<R: Read>(r: &mut Reader<R>) -> Result<SerializedMesh> {
    let flags = r.u32()?;
    if flags & 0x1000 == 0 {
        bail!("version 5 meshes must be stored in single precision (flag 0x1000)");
    }
    let name_len = r.u32()? as usize;
    if name_len > 1 << 16 {
        bail!("shape name of {name_len} bytes");
    }
    r.bytes(name_len)?;
    let (has_normals, has_tangents, has_uvs) = (flags & 1 != 0, flags & 2 != 0, flags & 4 != 0);
    if has_tangents {
        bail!("version 5 meshes with stored shading tangents (flag 0x2) are not supported");
    }
    let vertices = r.count("vertex")?;
    let faces = r.count("face")?;
    let points = r.count("surface point")?;
    let groups = r.count("normal group")?;
    if points > vertices || groups > vertices {
        bail!("invalid header: more surface points or normal groups than vertices");
    }
    let maps = 4 * (points > 0) as u64 + 4 * (groups > 0) as u64;
    r.check_declared((vertices, 32 + maps), (faces, 16))?;
    let records = r.floats(8 * vertices, false)?;
    let faces = triangles(&r.u32s(4 * faces)?, 4, vertices)?;
    // The surface-point and normal-group maps only tell Mitsuba which vertices to weld when
    // it recomputes normals after a position edit; the records hold the final data.
    if points > 0 {
        r.u32s(vertices)?;
    }
    if groups > 0 {
        r.u32s(vertices)?;
    }
    let mesh = TriangleMesh {
        colors: Vec::new(),
        tangents: Vec::new(),
        positions: records
            .chunks_exact(8)
            .map(|c| Vec3::from_slice(c))
            .collect(),
        normals: if has_normals {
            records
                .chunks_exact(8)
                .map(|c| Vec3::from_slice(&c[3..6]))
                .collect()
        } else {
            Vec::new()
        },
        uvs: if has_uvs {
            records
                .chunks_exact(8)
                .map(|c| Vec2::new(c[6], c[7]))
                .collect()
        } else {
            Vec::new()
        },
        indices: faces,
    };
    Ok(SerializedMesh {
        mesh,
        face_normals: flags & 0x10 != 0,
    })
}

/// Triangles from face records of `stride` u32s (three vertex indices first), each index
/// checked against the vertex count.
fn triangles(records: &[u32], stride: usize, vertices: usize) -> Result<Vec<[u32; 3]>> {
    records
        .chunks_exact(stride)
        .enumerate()
        .map(|(f, c)| {
            let t = [c[0], c[1], c[2]];
            if let Some(&bad) = t.iter().find(|&&i| i as usize >= vertices) {
                bail!("face {f} refers to vertex {bad}, but the mesh has {vertices} vertices");
            }
            Ok(t)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::write::ZlibEncoder;
    use flate2::Compression;
    use std::io::Write;

    /// One mesh as stored: the uncompressed header, then `body` zlib-compressed.
    fn compressed(version: u16, body: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend(MAGIC.to_le_bytes());
        out.extend(version.to_le_bytes());
        let mut e = ZlibEncoder::new(Vec::new(), Compression::default());
        e.write_all(body).unwrap();
        out.extend(e.finish().unwrap());
        out
    }

    /// A version-3/4 mesh stream: one triangle, with normals and uvs.
    fn legacy_mesh(version: u16, z_shift: f32, double: bool) -> Vec<u8> {
        let mut body = Vec::new();
        let flags: u32 = 0x1 | 0x2 | if double { 0x2000 } else { 0x1000 };
        body.extend(flags.to_le_bytes());
        if version == 4 {
            body.extend(b"tri\0");
        }
        body.extend(3u64.to_le_bytes());
        body.extend(1u64.to_le_bytes());
        let put = |body: &mut Vec<u8>, v: f32| {
            if double {
                body.extend((v as f64).to_le_bytes())
            } else {
                body.extend(v.to_le_bytes())
            }
        };
        for p in [
            [0.0, 0.0, z_shift],
            [1.0, 0.0, z_shift],
            [0.0, 1.0, z_shift],
        ] {
            p.iter().for_each(|&v| put(&mut body, v));
        }
        for _ in 0..3 {
            [0.0, 0.0, 1.0].iter().for_each(|&v| put(&mut body, v));
        }
        for uv in [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]] {
            uv.iter().for_each(|&v| put(&mut body, v));
        }
        for i in [0u32, 1, 2] {
            body.extend(i.to_le_bytes());
        }
        compressed(version, &body)
    }

    /// Concatenated meshes plus the end-of-file offset table.
    fn file(version: u16, meshes: &[Vec<u8>]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut offsets = Vec::new();
        for m in meshes {
            offsets.push(out.len());
            out.extend(m);
        }
        for o in offsets {
            if version == 3 {
                out.extend((o as u32).to_le_bytes());
            } else {
                out.extend((o as u64).to_le_bytes());
            }
        }
        out.extend((meshes.len() as u32).to_le_bytes());
        out
    }

    #[test]
    fn legacy_versions_and_shape_index() {
        for version in [3, 4] {
            for double in [false, true] {
                let f = file(
                    version,
                    &[
                        legacy_mesh(version, 0.0, double),
                        legacy_mesh(version, 5.0, double),
                        legacy_mesh(version, 7.0, double),
                    ],
                );
                for (i, z) in [(0, 0.0), (1, 5.0), (2, 7.0)] {
                    let m = parse(&f, i).unwrap().mesh;
                    assert_eq!(m.indices, vec![[0, 1, 2]]);
                    assert_eq!(m.positions[1], Vec3::new(1.0, 0.0, z));
                    assert_eq!(m.normals[2], Vec3::Z);
                    assert_eq!(m.uvs[2], Vec2::new(0.0, 1.0));
                }
                let e = parse(&f, 3).unwrap_err().to_string();
                assert!(e.contains("out of range") && e.contains("3 meshes"), "{e}");
            }
        }
    }

    #[test]
    fn version_5_records() {
        let mut body = Vec::new();
        body.extend((0x1000u32 | 0x1 | 0x4 | 0x10).to_le_bytes());
        body.extend(3u32.to_le_bytes());
        body.extend(b"tri");
        for n in [3u64, 1, 0, 0] {
            body.extend(n.to_le_bytes());
        }
        for (p, uv) in [
            ([0.0f32, 0.0, 1.0], [0.0f32, 0.0]),
            ([2.0, 0.0, 1.0], [1.0, 0.0]),
            ([0.0, 2.0, 1.0], [0.0, 1.0]),
        ] {
            for v in p.iter().chain(&[0.0, 0.0, -1.0]).chain(&uv) {
                body.extend(v.to_le_bytes());
            }
        }
        for i in [0u32, 2, 1, 0] {
            body.extend(i.to_le_bytes());
        }
        body.extend(0u32.to_le_bytes()); // no attributes
        let s = parse(&file(5, &[compressed(5, &body)]), 0).unwrap();
        assert!(s.face_normals);
        assert_eq!(s.mesh.indices, vec![[0, 2, 1]]);
        assert_eq!(s.mesh.positions[1], Vec3::new(2.0, 0.0, 1.0));
        assert_eq!(s.mesh.normals[0], -Vec3::Z);
        assert_eq!(s.mesh.uvs[2], Vec2::new(0.0, 1.0));
    }

    #[test]
    fn corrupt_files_are_errors() {
        let good = file(4, &[legacy_mesh(4, 0.0, false)]);
        assert!(parse(&good, 0).is_ok());
        // Wrong magic, unknown version, truncated stream, empty file.
        let mut bad = good.clone();
        bad[0] = 0;
        assert!(parse(&bad, 0).unwrap_err().to_string().contains("magic"));
        let mut bad = good.clone();
        bad[2] = 9;
        assert!(parse(&bad, 0)
            .unwrap_err()
            .to_string()
            .contains("version 9"));
        let cut = &good[..good.len() / 2];
        assert!(parse(cut, 0).is_err());
        assert!(parse(&[], 0).is_err());
        // An index beyond the vertex count.
        let mut body = Vec::new();
        body.extend(0x1000u32.to_le_bytes());
        body.extend(b"\0");
        body.extend(1u64.to_le_bytes());
        body.extend(1u64.to_le_bytes());
        body.extend([0u8; 12]);
        for i in [0u32, 0, 5] {
            body.extend(i.to_le_bytes());
        }
        let e = parse(&file(4, &[compressed(4, &body)]), 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("refers to vertex 5"), "{e}");
        // A huge vertex count fails cleanly.
        let mut body = Vec::new();
        body.extend(0x1000u32.to_le_bytes());
        body.extend(b"\0");
        body.extend(u64::MAX.to_le_bytes());
        assert!(parse(&file(4, &[compressed(4, &body)]), 0)
            .unwrap_err()
            .to_string()
            .contains("exceeds the limit"));
    }

    /// Counts within the per-field limit that declare more data than the compressed bytes can
    /// expand to are refused before anything is allocated for them.
    #[test]
    fn counts_beyond_the_compressed_size_are_refused() {
        let mut body = Vec::new();
        body.extend(0x1000u32.to_le_bytes());
        body.extend(b"\0");
        body.extend((100_000_000u64).to_le_bytes());
        body.extend((100_000_000u64).to_le_bytes());
        let m = compressed(4, &body);
        let e = format!("{:#}", parse(&file(4, &[m]), 0).unwrap_err());
        assert!(
            e.contains("100000000 vertices") && e.contains("1032:1"),
            "{e}"
        );
    }
}
