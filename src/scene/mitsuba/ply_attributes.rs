//! Mesh attributes of a PLY file as Mitsuba 3's PLY loader names them (`src/shapes/ply.h`,
//! `find_other_fields`), for the `mesh_attribute` texture.
//!
//! Per element (`vertex` → `vertex_…`, `face` → `face_…`): the properties `r g b` (or
//! `red green blue`) form `{type}color`; the other properties not used by the geometry form
//! attributes from consecutive names `{prefix}_{x|y|z|w}`, `{prefix}_{r|g|b|a}` (named
//! `{type}{prefix}_color`), `{prefix}_{0|1|2|3}` or `{prefix}_{1|2|3|4}`, of 1 or 3 fields.
//! Integer properties are normalised by their type's maximum (u8 / 255), floats are taken as
//! stored. (Mitsuba 3.9.1 takes integer colour properties unnormalised — 255 stays 255 — with
//! a warning that colours are expected in [0, 1]; thinfilm keeps its reading of them.)

use crate::scene::ply_scalar::Ty;
use anyhow::{anyhow, bail, Context, Result};
use std::path::Path;

/// One attribute's values: `dim` floats per vertex or per face.
#[derive(Debug, Clone)]
pub struct MeshAttribute {
    pub per_face: bool,
    pub dim: usize,
    pub values: Vec<f32>,
}

impl Ty {
    /// The maximum of an integer type (None for floats): Mitsuba's `Normalized` divisor.
    fn int_max(self) -> Option<f64> {
        Some(match self {
            Ty::I8 => 127.0,
            Ty::U8 => 255.0,
            Ty::I16 => 32767.0,
            Ty::U16 => 65535.0,
            Ty::I32 => 2147483647.0,
            Ty::U32 => 4294967295.0,
            Ty::F32 | Ty::F64 => return None,
        })
    }
}

struct Prop {
    name: String,
    ty: Ty,
    /// The count type of a list property.
    list: Option<Ty>,
}

struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

#[derive(PartialEq)]
enum Format {
    Ascii,
    Little,
    Big,
}

/// Reads attribute `name` (`vertex_…` or `face_…`) of the PLY file `path`.
pub fn read(path: &Path, name: &str) -> Result<MeshAttribute> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let (format, elements, body) = header(&bytes)?;
    let per_face = name.starts_with("face_");
    let wanted = if per_face { "face" } else { "vertex" };
    let mut values = Vec::new();
    let mut reader = Body::new(body, format);
    for e in &elements {
        let fields = if e.name == wanted {
            let groups = attributes(wanted, &e.props);
            let found = groups.into_iter().find(|(n, _)| n == name);
            found.map(|(_, f)| f)
        } else {
            None
        };
        for _ in 0..e.count {
            let record = reader.record(&e.props)?;
            if let Some(f) = &fields {
                values.extend(f.iter().map(|&k| record[k]));
            }
        }
        if let Some(f) = fields {
            if !(f.len() == 1 || f.len() == 3) {
                bail!(
                    "attribute \"{name}\" has {} channels (Mitsuba evaluates 1 or 3)",
                    f.len()
                );
            }
            return Ok(MeshAttribute {
                per_face,
                dim: f.len(),
                values,
            });
        }
    }
    let names: Vec<String> = (elements.iter())
        .filter(|e| e.name == "vertex" || e.name == "face")
        .flat_map(|e| attributes(&e.name, &e.props).into_iter().map(|(n, _)| n))
        .collect();
    Err(anyhow!(
        "the mesh has no attribute \"{name}\" (it has: {})",
        if names.is_empty() {
            "none".into()
        } else {
            names.join(", ")
        }
    ))
}

/// The format, the elements and the body of a PLY file.
fn header(bytes: &[u8]) -> Result<(Format, Vec<Element>, &[u8])> {
    const END: &[u8] = b"end_header";
    let end = (bytes.windows(END.len()).position(|w| w == END))
        .ok_or_else(|| anyhow!("not a PLY file (no end_header)"))?;
    let mut body = end + END.len();
    while body < bytes.len() && bytes[body] != b'\n' {
        body += 1;
    }
    let text = std::str::from_utf8(&bytes[..end]).context("PLY header is not text")?;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Little,
                    "binary_big_endian" => Format::Big,
                    _ => bail!("unknown PLY format \"{f}\""),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().context("PLY element count")?,
                props: Vec::new(),
            }),
            ["property", "list", ct, it, name] => {
                let (Some(ct), Some(it)) = (Ty::parse(ct), Ty::parse(it)) else {
                    bail!("PLY property {name}: unknown type");
                };
                let e = elements
                    .last_mut()
                    .ok_or_else(|| anyhow!("PLY property before element"))?;
                e.props.push(Prop {
                    name: name.to_string(),
                    ty: it,
                    list: Some(ct),
                });
            }
            ["property", ty, name] => {
                let ty = Ty::parse(ty)
                    .ok_or_else(|| anyhow!("PLY property {name}: unknown type {ty}"))?;
                let e = elements
                    .last_mut()
                    .ok_or_else(|| anyhow!("PLY property before element"))?;
                e.props.push(Prop {
                    name: name.to_string(),
                    ty,
                    list: None,
                });
            }
            _ => {}
        }
    }
    let format = format.ok_or_else(|| anyhow!("PLY header without a format line"))?;
    Ok((format, elements, &bytes[(body + 1).min(bytes.len())..]))
}

/// Mitsuba's attribute grouping of one element's scalar properties (`find_other_fields`):
/// (attribute name, property indices).
fn attributes(element: &str, props: &[Prop]) -> Vec<(String, Vec<usize>)> {
    let prefix = format!("{element}_");
    let find = |n: &str| props.iter().position(|p| p.name == n && p.list.is_none());
    let mut out = Vec::new();
    let rgb = [["r", "g", "b"], ["red", "green", "blue"]]
        .iter()
        .find_map(|k| Some([find(k[0])?, find(k[1])?, find(k[2])?]));
    if let Some(c) = rgb {
        let alpha = find("a").or_else(|| find("alpha"));
        out.push((
            format!("{prefix}color"),
            c.iter().copied().chain(alpha).collect(),
        ));
    }
    let reserved = [
        "x",
        "y",
        "z",
        "nx",
        "ny",
        "nz",
        "u",
        "v",
        "s",
        "t",
        "texture_u",
        "texture_v",
        "r",
        "g",
        "b",
        "a",
        "red",
        "green",
        "blue",
        "alpha",
    ];
    const POSTFIXES: [&[u8; 4]; 4] = [b"xr01", b"yg12", b"zb23", b"wa34"];
    let mut seen: Vec<String> = Vec::new();
    // (prefix, postfix category, fields)
    let mut current: Option<(String, usize, Vec<usize>)> = None;
    let mut flush = |cur: &mut Option<(String, usize, Vec<usize>)>, seen: &mut Vec<String>| {
        if let Some((p, cat, fields)) = cur.take() {
            if fields.len() == 1 || fields.len() == 3 {
                let suffix = if cat == 1 { "_color" } else { "" };
                out.push((format!("{prefix}{p}{suffix}"), fields));
                seen.push(p);
            }
        }
    };
    for (i, p) in props.iter().enumerate() {
        if p.list.is_some() || reserved.contains(&p.name.as_str()) {
            continue;
        }
        let Some((pre, post)) = p.name.rsplit_once('_') else {
            flush(&mut current, &mut seen);
            continue;
        };
        let &[ch] = post.as_bytes() else {
            flush(&mut current, &mut seen);
            continue;
        };
        if current.as_ref().is_some_and(|c| c.0 != pre) {
            flush(&mut current, &mut seen);
        }
        match &mut current {
            Some((_, cat, fields)) => {
                if fields.len() < 4 && POSTFIXES[fields.len()][*cat] == ch {
                    fields.push(i);
                } else {
                    current = None; // an invalid sequence: Mitsuba ignores the attribute
                }
            }
            None if !seen.iter().any(|s| s == pre) => {
                if let Some(cat) = POSTFIXES[0].iter().position(|&c| c == ch) {
                    current = Some((pre.to_string(), cat, vec![i]));
                }
            }
            None => {}
        }
    }
    flush(&mut current, &mut seen);
    out
}

/// The body of a PLY file, read record by record.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    format: Format,
    tokens: std::str::SplitAsciiWhitespace<'a>,
}

impl<'a> Body<'a> {
    fn new(bytes: &'a [u8], format: Format) -> Self {
        let text = if format == Format::Ascii {
            std::str::from_utf8(bytes).unwrap_or("")
        } else {
            ""
        };
        Body {
            bytes,
            pos: 0,
            format,
            tokens: text.split_ascii_whitespace(),
        }
    }

    /// One value as f64 (raw, not normalised).
    fn value(&mut self, ty: Ty) -> Result<f64> {
        if self.format == Format::Ascii {
            let t = self
                .tokens
                .next()
                .ok_or_else(|| anyhow!("PLY body ends early"))?;
            return t.parse().with_context(|| format!("PLY value \"{t}\""));
        }
        let n = ty.size();
        let raw = (self.bytes.get(self.pos..self.pos + n))
            .ok_or_else(|| anyhow!("PLY body ends early"))?;
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(raw);
        if self.format == Format::Big {
            b[..n].reverse();
        }
        Ok(match ty {
            Ty::I8 => b[0] as i8 as f64,
            Ty::U8 => b[0] as f64,
            Ty::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Ty::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Ty::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Ty::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Ty::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Ty::F64 => f64::from_le_bytes(b),
        })
    }

    /// The scalar properties of one record as Mitsuba converts them (lists skipped, NaN).
    fn record(&mut self, props: &[Prop]) -> Result<Vec<f32>> {
        let mut out = Vec::with_capacity(props.len());
        for p in props {
            if let Some(ct) = p.list {
                let n = self.value(ct)?;
                if !(0.0..=1e6).contains(&n) {
                    bail!("PLY list {} has {n} items", p.name);
                }
                for _ in 0..n as usize {
                    self.value(p.ty)?;
                }
                out.push(f32::NAN);
                continue;
            }
            let v = self.value(p.ty)?;
            out.push(match p.ty.int_max() {
                Some(max) => (v / max) as f32,
                None => v as f32,
            });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn props(names: &[&str]) -> Vec<Prop> {
        (names.iter())
            .map(|n| Prop {
                name: n.to_string(),
                ty: Ty::F32,
                list: None,
            })
            .collect()
    }

    /// Mitsuba's names: `color_0..2` → `vertex_color`, `weight_0` → `face_weight`,
    /// `n_r n_g n_b` → `vertex_n_color`, `r g b` → `vertex_color`; a two-field group and a
    /// broken sequence are ignored.
    #[test]
    fn groups_properties_as_mitsuba_does() {
        let names = |e: &str, p: &[&str]| -> Vec<String> {
            attributes(e, &props(p))
                .into_iter()
                .map(|(n, _)| n)
                .collect()
        };
        assert_eq!(
            names(
                "vertex",
                &["x", "y", "z", "nx", "ny", "nz", "u", "v", "color_0", "color_1", "color_2"]
            ),
            ["vertex_color"]
        );
        assert_eq!(
            names("face", &["color_0", "color_1", "color_2", "weight_0"]),
            ["face_color", "face_weight"]
        );
        assert_eq!(
            names("vertex", &["x", "y", "z", "red", "green", "blue"]),
            ["vertex_color"]
        );
        assert_eq!(
            names("vertex", &["n_r", "n_g", "n_b", "q_x", "q_y"]),
            ["vertex_n_color"]
        );
        assert_eq!(
            names("vertex", &["k_x", "k_z", "k_y"]),
            Vec::<String>::new()
        );
    }

    #[test]
    fn reads_ascii_and_binary_records() {
        let dir = std::env::temp_dir().join(format!("thinfilm_plyattr_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ascii = dir.join("a.ply");
        std::fs::write(
            &ascii,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\nproperty list uchar int vertex_indices\nproperty float weight_0\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 128\n3 0 1 2 0.25\n",
        )
        .unwrap();
        let c = read(&ascii, "vertex_color").unwrap();
        assert!(!c.per_face && c.dim == 3 && c.values.len() == 9);
        assert_eq!(&c.values[..6], &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        // u8 128 → 128/255.
        assert!(
            (c.values[8] - 128.0 / 255.0).abs() < 1e-6,
            "{}",
            c.values[8]
        );
        let w = read(&ascii, "face_weight").unwrap();
        assert!(w.per_face && w.dim == 1 && w.values == [0.25]);
        let e = format!("{:#}", read(&ascii, "face_color").unwrap_err());
        assert!(
            e.contains("no attribute \"face_color\"") && e.contains("face_weight"),
            "{e}"
        );
        // The same in binary (little endian).
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float f_0\nelement face 1\nproperty list uchar int vertex_indices\nproperty float c_0\nproperty float c_1\nproperty float c_2\nend_header\n".to_vec();
        for v in [1.0f32, 2.0, 3.0, 0.5] {
            bin.extend(v.to_le_bytes());
        }
        bin.push(3);
        for i in [0i32, 0, 0] {
            bin.extend(i.to_le_bytes());
        }
        for v in [0.1f32, 0.2, 0.3] {
            bin.extend(v.to_le_bytes());
        }
        let path = dir.join("b.ply");
        std::fs::write(&path, &bin).unwrap();
        assert_eq!(read(&path, "vertex_f").unwrap().values, [0.5]);
        assert_eq!(read(&path, "face_c").unwrap().values, [0.1, 0.2, 0.3]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
