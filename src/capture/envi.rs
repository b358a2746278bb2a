//! ENVI raster I/O: a text header (`.hdr`) beside a raw binary cube.
//!
//! Reader: header values may span lines inside braces, keys are case-insensitive, lines
//! starting with `;` are comments. Interleave `bsq`/`bil`/`bip`, data types 1, 2, 3, 4, 5,
//! 12, 13, 14, 15, byte order 0/1, `header offset`, `wavelength` (+ `wavelength units`
//! nm or µm), `fwhm`, `data ignore value`. The binary is found by the header's stem with
//! `.img`, `.raw`, `.dat`, `.bin` or no extension (either case).
//!
//! Large cubes are memory-mapped and decoded straight into the output layout, so a cube
//! costs its f32 output once in RAM (the mapping is page cache, evictable), never a
//! second in-memory copy of the raw bytes.
//!
//! Writer: any interleave, float32/float64/uint16/int16/uint8, header + binary written
//! through temporary files and renamed into place (see [`write_cube`]).

use super::samples::{transpose_runs, TILE_PX};
use super::Samples;
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

/// ENVI `data type` codes this module understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    U8,
    I16,
    I32,
    F32,
    F64,
    U16,
    U32,
    I64,
    U64,
}

impl DataType {
    /// From the ENVI code (complex types 6 and 9 are not supported: no reflectance is complex).
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            1 => DataType::U8,
            2 => DataType::I16,
            3 => DataType::I32,
            4 => DataType::F32,
            5 => DataType::F64,
            12 => DataType::U16,
            13 => DataType::U32,
            14 => DataType::I64,
            15 => DataType::U64,
            _ => return None,
        })
    }

    pub fn code(self) -> u32 {
        match self {
            DataType::U8 => 1,
            DataType::I16 => 2,
            DataType::I32 => 3,
            DataType::F32 => 4,
            DataType::F64 => 5,
            DataType::U16 => 12,
            DataType::U32 => 13,
            DataType::I64 => 14,
            DataType::U64 => 15,
        }
    }

    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            DataType::U8 => 1,
            DataType::I16 | DataType::U16 => 2,
            DataType::I32 | DataType::U32 | DataType::F32 => 4,
            DataType::F64 | DataType::I64 | DataType::U64 => 8,
        }
    }

    pub fn is_integer(self) -> bool {
        !matches!(self, DataType::F32 | DataType::F64)
    }

    /// Largest representable value of an integer type: a raw sample at (or, after f32
    /// rounding, above) it is a clipped, saturated reading. `None` for float types.
    pub fn saturation_value(self) -> Option<f64> {
        Some(match self {
            DataType::U8 => u8::MAX as f64,
            DataType::I16 => i16::MAX as f64,
            DataType::I32 => i32::MAX as f64,
            DataType::U16 => u16::MAX as f64,
            DataType::U32 => u32::MAX as f64,
            DataType::I64 => i64::MAX as f64,
            DataType::U64 => u64::MAX as f64,
            DataType::F32 | DataType::F64 => return None,
        })
    }

    /// Parses a user-facing name (`float32`, `uint16`, `int16`, `float64`, `uint8`).
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name.to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "byte" => DataType::U8,
            "i16" | "int16" => DataType::I16,
            "i32" | "int32" => DataType::I32,
            "f32" | "float32" | "float" => DataType::F32,
            "f64" | "float64" | "double" => DataType::F64,
            "u16" | "uint16" => DataType::U16,
            "u32" | "uint32" => DataType::U32,
            "i64" | "int64" => DataType::I64,
            "u64" | "uint64" => DataType::U64,
            _ => return None,
        })
    }
}

/// Sample order in the binary file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interleave {
    /// Band sequential: `[band][line][sample]`.
    #[default]
    Bsq,
    /// Band interleaved by line: `[line][band][sample]`.
    Bil,
    /// Band interleaved by pixel: `[line][sample][band]`.
    Bip,
}

impl Interleave {
    /// Index of sample (`line`, `sample`, `band`) in a file of the given size.
    #[inline]
    pub fn index(
        self,
        lines: usize,
        samples: usize,
        bands: usize,
        y: usize,
        x: usize,
        b: usize,
    ) -> usize {
        match self {
            Interleave::Bsq => (b * lines + y) * samples + x,
            Interleave::Bil => (y * bands + b) * samples + x,
            Interleave::Bip => (y * samples + x) * bands + b,
        }
    }
}

impl fmt::Display for Interleave {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Interleave::Bsq => "bsq",
            Interleave::Bil => "bil",
            Interleave::Bip => "bip",
        })
    }
}

impl std::str::FromStr for Interleave {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "bsq" => Ok(Interleave::Bsq),
            "bil" => Ok(Interleave::Bil),
            "bip" => Ok(Interleave::Bip),
            other => Err(format!(
                "unknown interleave '{other}' (expected bsq, bil or bip)"
            )),
        }
    }
}

/// A parsed ENVI header.
#[derive(Debug, Clone, PartialEq)]
pub struct EnviHeader {
    /// The `.hdr` file this came from (for error messages).
    pub path: PathBuf,
    /// Width (`samples`).
    pub samples: usize,
    /// Height (`lines`).
    pub lines: usize,
    pub bands: usize,
    pub header_offset: usize,
    pub data_type: DataType,
    pub interleave: Interleave,
    /// `true` for `byte order = 1` (big-endian).
    pub big_endian: bool,
    /// Band centres converted to nanometres.
    pub wavelengths_nm: Option<Vec<f64>>,
    /// Band full widths at half maximum, nanometres.
    pub fwhm_nm: Option<Vec<f64>>,
    pub ignore_value: Option<f64>,
    /// Every field as text, keys lower-cased and whitespace-collapsed, braces removed.
    pub fields: BTreeMap<String, String>,
}

impl EnviHeader {
    /// Number of samples (pixels × bands).
    pub fn len(&self) -> usize {
        self.samples * self.lines * self.bands
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes the binary must hold after the header offset.
    pub fn data_bytes(&self) -> usize {
        self.len() * self.data_type.size()
    }

    /// Bytes of the f32 decoding plus a validity flag per pixel (what a reader allocates).
    pub fn decoded_bytes(&self) -> u64 {
        self.len() as u64 * 4 + (self.samples * self.lines) as u64
    }

    /// Refuses to decode this cube when, on top of `already` bytes decoded before it, it
    /// exceeds the memory budget (a sparse file can declare terabytes and pass the size
    /// check against the binary).
    pub fn check_decode_budget(&self, already: u64) -> Result<()> {
        crate::limits::check_alloc(
            format!(
                "{}: decoding {}×{}×{} samples",
                self.path.display(),
                self.samples,
                self.lines,
                self.bands
            ),
            already.saturating_add(self.decoded_bytes()),
        )
    }
}

/// Splits header text into `key → raw value` (braces kept off), with line numbers for errors.
fn split_fields(text: &str, path: &Path) -> Result<BTreeMap<String, (String, usize)>> {
    let mut lines = text.lines().enumerate().peekable();
    match lines.next() {
        Some((_, first))
            if first
                .trim_start_matches('\u{feff}')
                .trim()
                .starts_with("ENVI") => {}
        _ => bail!(
            "{}: not an ENVI header (the first line must be 'ENVI')",
            path.display()
        ),
    }
    let mut out = BTreeMap::new();
    while let Some((i, line)) = lines.next() {
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with(';') {
            continue;
        }
        let Some((key, value)) = trimmed.split_once('=') else {
            bail!(
                "{}:{}: expected 'key = value', got '{}'",
                path.display(),
                i + 1,
                trimmed
            );
        };
        let key = key
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .to_ascii_lowercase();
        let mut value = value.trim().to_string();
        if value.starts_with('{') {
            // Braced value: read on until the closing brace, skipping comment lines.
            while !value.ends_with('}') {
                let Some((_, next)) = lines.next() else {
                    bail!(
                        "{}:{}: field '{key}' opens '{{' but never closes it",
                        path.display(),
                        i + 1
                    );
                };
                let next = next.trim();
                if next.starts_with(';') {
                    continue;
                }
                value.push('\n');
                value.push_str(next);
            }
            value = value[1..value.len() - 1].trim().to_string();
        }
        out.insert(key, (value, i + 1));
    }
    Ok(out)
}

fn parse_list(value: &str) -> Vec<&str> {
    value
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect()
}

/// Reads and validates an ENVI header.
pub fn read_header(path: &Path) -> Result<EnviHeader> {
    let bytes = crate::limits::read_file(path, "ENVI header", 16)?;
    let text = String::from_utf8_lossy(&bytes);
    parse_header(&text, path)
}

/// Parses header text (`path` is only used in messages).
pub fn parse_header(text: &str, path: &Path) -> Result<EnviHeader> {
    let raw = split_fields(text, path)?;
    let p = path.display();
    let get = |key: &str| raw.get(key).map(|(v, line)| (v.as_str(), *line));
    let int_field = |key: &str, required: bool| -> Result<Option<usize>> {
        match get(key) {
            None if required => bail!("{p}: header has no '{key}' field"),
            None => Ok(None),
            Some((v, line)) => v.trim().parse::<usize>().map(Some).map_err(|_| {
                anyhow::anyhow!("{p}:{line}: field '{key}' = '{v}' is not a non-negative integer")
            }),
        }
    };
    let samples = int_field("samples", true)?.unwrap_or(0);
    let lines = int_field("lines", true)?.unwrap_or(0);
    let bands = int_field("bands", true)?.unwrap_or(0);
    if samples == 0 || lines == 0 || bands == 0 {
        bail!("{p}: empty cube (samples = {samples}, lines = {lines}, bands = {bands})");
    }
    let header_offset = int_field("header offset", false)?.unwrap_or(0);
    let code = int_field("data type", true)?.unwrap_or(0);
    let data_type = u32::try_from(code)
        .ok()
        .and_then(DataType::from_code)
        .with_context(|| {
            format!(
            "{p}:{}: field 'data type' = {code} is not supported (supported: 1 uint8, 2 int16, \
             3 int32, 4 float32, 5 float64, 12 uint16, 13 uint32, 14 int64, 15 uint64)",
            get("data type").map(|g| g.1).unwrap_or(0)
        )
        })?;
    let interleave = match get("interleave") {
        Some((v, line)) => v
            .parse::<Interleave>()
            .map_err(|e| anyhow::anyhow!("{p}:{line}: field 'interleave': {e}"))?,
        // With one band every interleave is the same layout.
        None if bands == 1 => Interleave::Bsq,
        None => bail!("{p}: header has no 'interleave' field (bsq, bil or bip)"),
    };
    let big_endian = match get("byte order") {
        Some((v, line)) => match v.trim() {
            "0" => false,
            "1" => true,
            other => bail!("{p}:{line}: field 'byte order' = '{other}' must be 0 (little-endian) or 1 (big-endian)"),
        },
        // Byte order is irrelevant for single-byte samples; otherwise guessing would
        // silently produce garbage.
        None if data_type.size() == 1 => false,
        None => bail!("{p}: header has no 'byte order' field (0 little-endian, 1 big-endian)"),
    };
    // Sizes from the file: checked, so a header cannot wrap the size check to zero.
    let data_bytes = crate::limits::size_product(
        &p,
        &[
            ("samples", samples as u64),
            ("lines", lines as u64),
            ("bands", bands as u64),
            ("bytes per sample", data_type.size() as u64),
        ],
    )?;
    if data_bytes
        .checked_add(header_offset as u64)
        .is_none_or(|end| usize::try_from(end).is_err())
    {
        bail!("{p}: field 'header offset' = {header_offset} plus {data_bytes} bytes of data overflows");
    }
    let float_list = |key: &str| -> Result<Option<(Vec<f64>, usize)>> {
        let Some((v, line)) = get(key) else {
            return Ok(None);
        };
        let items = parse_list(v);
        let mut out = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            let x: f64 = item.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{p}:{line}: field '{key}' item {} = '{item}' is not a number",
                    i + 1
                )
            })?;
            if !x.is_finite() {
                bail!(
                    "{p}:{line}: field '{key}' item {} = '{item}' is not finite",
                    i + 1
                );
            }
            out.push(x);
        }
        if out.len() != bands {
            bail!(
                "{p}:{line}: field '{key}' has {} values but the cube has {bands} bands",
                out.len()
            );
        }
        Ok(Some((out, line)))
    };
    let wavelengths = float_list("wavelength")?;
    let fwhm = float_list("fwhm")?;
    // Unit scale to nanometres.
    let scale = match get("wavelength units") {
        Some((v, line)) => match v.trim().to_ascii_lowercase().as_str() {
            "nm" | "nanometer" | "nanometers" | "nanometre" | "nanometres" => 1.0,
            "um" | "µm" | "μm" | "micrometer" | "micrometers" | "micrometre" | "micrometres" | "microns" | "micron" => 1000.0,
            "mm" | "millimeter" | "millimeters" => 1.0e6,
            // Tools write "Unknown" when they had no unit: fall through to the heuristic.
            "unknown" | "" => unit_heuristic(wavelengths.as_ref()),
            other => bail!("{p}:{line}: field 'wavelength units' = '{other}' is not supported (nm or micrometers)"),
        },
        None => unit_heuristic(wavelengths.as_ref()),
    };
    let wavelengths_nm =
        wavelengths.map(|(w, _)| w.into_iter().map(|x| x * scale).collect::<Vec<_>>());
    if let Some(w) = &wavelengths_nm {
        check_wavelengths(w, &p)?;
    }
    let fwhm_nm = fwhm.map(|(w, _)| w.into_iter().map(|x| x * scale).collect::<Vec<_>>());
    if let (Some(f), Some(w)) = (&fwhm_nm, &wavelengths_nm) {
        check_fwhm(f, w, &p)?;
    }
    let ignore_value = match get("data ignore value") {
        None => None,
        Some((v, line)) => Some(v.trim().parse::<f64>().map_err(|_| {
            anyhow::anyhow!("{p}:{line}: field 'data ignore value' = '{v}' is not a number")
        })?),
    };
    Ok(EnviHeader {
        path: path.to_path_buf(),
        samples,
        lines,
        bands,
        header_offset,
        data_type,
        interleave,
        big_endian,
        wavelengths_nm,
        fwhm_nm,
        ignore_value,
        fields: raw.into_iter().map(|(k, (v, _))| (k, v)).collect(),
    })
}

/// Band centres (nm) must lie in [`MIN_WAVELENGTH_NM`, `MAX_WAVELENGTH_NM`] and increase
/// strictly: a repeated or unsorted band is a broken header, not a spectrum.
fn check_wavelengths(w: &[f64], p: &impl fmt::Display) -> Result<()> {
    for (i, &x) in w.iter().enumerate() {
        if !(MIN_WAVELENGTH_NM..=MAX_WAVELENGTH_NM).contains(&x) {
            bail!(
                "{p}: field 'wavelength' item {} = {x} nm is outside [{MIN_WAVELENGTH_NM}, {MAX_WAVELENGTH_NM}] nm (check 'wavelength units')",
                i + 1
            );
        }
        if i > 0 && x <= w[i - 1] {
            bail!(
                "{p}: field 'wavelength' must increase strictly, but item {} = {x} nm follows {} nm",
                i + 1,
                w[i - 1]
            );
        }
    }
    Ok(())
}

/// Band widths must be ≥ 0 and narrow enough that the Gaussian response (±4σ) stays at
/// positive wavelengths.
fn check_fwhm(f: &[f64], w: &[f64], p: &impl fmt::Display) -> Result<()> {
    for (i, (&fw, &c)) in f.iter().zip(w).enumerate() {
        // 4σ = 4 · FWHM / 2.3548 < λ.
        if !(fw >= 0.0 && 4.0 * fw / 2.354_820_045 < c) {
            bail!(
                "{p}: field 'fwhm' item {} = {fw} nm must be ≥ 0 and below {:.1} nm for the band at {c} nm",
                i + 1,
                c * 2.354_820_045 / 4.0
            );
        }
    }
    Ok(())
}

/// Shortest band centre accepted, nm (the far ultraviolet).
pub const MIN_WAVELENGTH_NM: f64 = 100.0;
/// Longest band centre accepted, nm (the thermal infrared).
pub const MAX_WAVELENGTH_NM: f64 = 30_000.0;

/// Without a unit, values below 100 can only be micrometres for optical bands
/// (0.4–2.5 µm); anything else is taken as nanometres.
fn unit_heuristic(w: Option<&(Vec<f64>, usize)>) -> f64 {
    match w {
        Some((w, _)) if !w.is_empty() && w.iter().all(|&x| x < 100.0) => 1000.0,
        _ => 1.0,
    }
}

/// The header file for a path that is a header, or the binary of one.
pub fn header_path(path: &Path) -> PathBuf {
    let is_hdr = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("hdr"));
    if is_hdr {
        return path.to_path_buf();
    }
    for candidate in [
        path.with_extension("hdr"),
        PathBuf::from(format!("{}.hdr", path.display())),
    ] {
        if candidate.is_file() {
            return candidate;
        }
    }
    path.to_path_buf()
}

/// Finds the binary beside a header: same stem with `.img`, `.raw`, `.dat`, `.bin`,
/// upper-case variants, or no extension.
pub fn find_binary(header: &Path) -> Result<PathBuf> {
    let stem = header.with_extension("");
    let mut tried = Vec::new();
    for ext in ["img", "raw", "dat", "bin", "IMG", "RAW", "DAT", "BIN", ""] {
        let candidate = if ext.is_empty() {
            stem.clone()
        } else {
            stem.with_extension(ext)
        };
        if candidate.is_file() && candidate != header {
            return Ok(candidate);
        }
        tried.push(
            candidate
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
    }
    bail!(
        "{}: no binary data file beside the header (tried {})",
        header.display(),
        tried.join(", ")
    )
}

/// An opened ENVI cube: header plus the memory-mapped binary.
pub struct EnviFile {
    pub header: EnviHeader,
    pub binary_path: PathBuf,
    /// Private (copy-on-write): a cube already in the model's layout becomes the samples
    /// themselves ([`EnviFile::into_bip_rows`]), and masking a sample never writes the file.
    map: memmap2::MmapMut,
}

impl fmt::Debug for EnviFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EnviFile")
            .field("header", &self.header)
            .field("binary_path", &self.binary_path)
            .finish()
    }
}

/// Opens a cube (header path, or binary path with a header beside it) and maps its binary.
pub fn open(path: &Path) -> Result<EnviFile> {
    let hdr = header_path(path);
    let header = read_header(&hdr)?;
    let binary_path = find_binary(&hdr)?;
    let file = std::fs::File::open(&binary_path)
        .with_context(|| format!("opening ENVI data {}", binary_path.display()))?;
    let len = file
        .metadata()
        .with_context(|| format!("reading size of {}", binary_path.display()))?
        .len();
    let needed = header.header_offset as u64 + header.data_bytes() as u64;
    if len < needed {
        bail!(
            "{}: truncated: {} bytes, but the header {} ({}×{}×{} samples of {} bytes + header offset {}) needs {}",
            binary_path.display(),
            len,
            hdr.display(),
            header.samples,
            header.lines,
            header.bands,
            header.data_type.size(),
            header.header_offset,
            needed
        );
    }
    // Decoding allocates f32 per sample: refuse before mapping what cannot be decoded.
    header.check_decode_budget(0)?;
    // SAFETY: the mapping is read-only and lives as long as `EnviFile`. If another process
    // truncates the file while we read it, the OS may signal; that is the usual contract
    // of read-only memory maps and cheaper than reading gigabytes into a buffer. Only the
    // bytes the header describes are mapped (a file may carry trailing data).
    let map = unsafe {
        memmap2::MmapOptions::new()
            .len(needed as usize)
            .map_copy(&file)
    }
    .with_context(|| format!("memory-mapping {}", binary_path.display()))?;
    Ok(EnviFile {
        header,
        binary_path,
        map,
    })
}

/// Decodes sample `index` (in file order) as f32.
trait Decode: Sync {
    fn get(&self, bytes: &[u8], index: usize) -> f32;
    /// Decodes the consecutive samples `start..start + out.len()` (in file order) into
    /// every `stride`-th element of `out_strided` — one bounds check per run, not per sample.
    fn run(&self, bytes: &[u8], start: usize, count: usize, out_strided: &mut [f32], stride: usize);
}

macro_rules! decoder {
    ($name:ident, $t:ty, $n:expr) => {
        struct $name {
            big: bool,
        }
        impl Decode for $name {
            #[inline(always)]
            fn get(&self, bytes: &[u8], index: usize) -> f32 {
                let s: [u8; $n] = bytes[index * $n..index * $n + $n].try_into().unwrap();
                let v = if self.big {
                    <$t>::from_be_bytes(s)
                } else {
                    <$t>::from_le_bytes(s)
                };
                v as f32
            }
            #[inline(always)]
            fn run(
                &self,
                bytes: &[u8],
                start: usize,
                count: usize,
                out_strided: &mut [f32],
                stride: usize,
            ) {
                let src = &bytes[start * $n..(start + count) * $n];
                let big = self.big;
                for (c, o) in src
                    .chunks_exact($n)
                    .zip(out_strided.iter_mut().step_by(stride))
                {
                    let s: [u8; $n] = c.try_into().unwrap();
                    let v = if big {
                        <$t>::from_be_bytes(s)
                    } else {
                        <$t>::from_le_bytes(s)
                    };
                    *o = v as f32;
                }
            }
        }
    };
}
decoder!(DecU8, u8, 1);
decoder!(DecI16, i16, 2);
decoder!(DecI32, i32, 4);
decoder!(DecF32, f32, 4);
decoder!(DecF64, f64, 8);
decoder!(DecU16, u16, 2);
decoder!(DecU32, u32, 4);
decoder!(DecI64, i64, 8);
decoder!(DecU64, u64, 8);

impl EnviFile {
    fn data(&self) -> &[u8] {
        &self.map[self.header.header_offset..self.header.header_offset + self.header.data_bytes()]
    }

    /// Runs `f` with the decoder for this file's type (monomorphised per type).
    fn with_decoder<R>(&self, f: impl FnOnce(&dyn Decode) -> R) -> R {
        let big = self.header.big_endian;
        match self.header.data_type {
            DataType::U8 => f(&DecU8 { big }),
            DataType::I16 => f(&DecI16 { big }),
            DataType::I32 => f(&DecI32 { big }),
            DataType::F32 => f(&DecF32 { big }),
            DataType::F64 => f(&DecF64 { big }),
            DataType::U16 => f(&DecU16 { big }),
            DataType::U32 => f(&DecU32 { big }),
            DataType::I64 => f(&DecI64 { big }),
            DataType::U64 => f(&DecU64 { big }),
        }
    }

    /// The whole cube as band-interleaved-by-pixel f32, `[(y * samples + x) * bands + b]`,
    /// decoded in parallel row by row straight from the mapping.
    pub fn to_bip_f32(&self) -> Vec<f32> {
        self.decode_bip_rows(|_, _| ()).0
    }

    /// As [`EnviFile::to_bip_f32`], and runs `per_row(line, row)` on every decoded row
    /// while it is still in cache (e.g. calibration and masking), collecting its results
    /// in line order. One pass over gigabyte cubes instead of two.
    pub fn decode_bip_rows<T: Send>(
        &self,
        per_row: impl Fn(usize, &mut [f32]) -> T + Sync,
    ) -> (Vec<f32>, Vec<T>) {
        let big = self.header.big_endian;
        // Dispatched once per cube so the row loops are monomorphised per sample type
        // (a dynamic call per sample was most of the load time of a 1.6 GB capture).
        match self.header.data_type {
            DataType::U8 => self.decode_rows(&DecU8 { big }, per_row),
            DataType::I16 => self.decode_rows(&DecI16 { big }, per_row),
            DataType::I32 => self.decode_rows(&DecI32 { big }, per_row),
            DataType::F32 => self.decode_rows(&DecF32 { big }, per_row),
            DataType::F64 => self.decode_rows(&DecF64 { big }, per_row),
            DataType::U16 => self.decode_rows(&DecU16 { big }, per_row),
            DataType::U32 => self.decode_rows(&DecU32 { big }, per_row),
            DataType::I64 => self.decode_rows(&DecI64 { big }, per_row),
            DataType::U64 => self.decode_rows(&DecU64 { big }, per_row),
        }
    }

    /// As [`EnviFile::decode_bip_rows`], consuming the file: when the binary already is
    /// BIP f32 in this machine's byte order, `per_row` runs on the mapping itself — no
    /// decoding pass and no copy of the cube (a 1 Mpx × 81-band angle is 324 MB that need
    /// not be allocated, zeroed by the kernel and written); else the rows are decoded.
    pub fn into_bip_rows<T: Send>(
        self,
        per_row: impl Fn(usize, &mut [f32]) -> T + Sync,
    ) -> (Samples, Vec<T>) {
        let h = &self.header;
        let native = h.data_type == DataType::F32 && h.big_endian == cfg!(target_endian = "big");
        // One band: every interleave is the BIP layout.
        if !(native && (h.interleave == Interleave::Bip || h.bands == 1)) {
            let (data, rows) = self.decode_bip_rows(per_row);
            return (data.into(), rows);
        }
        let (row_len, offset, len) = (h.samples * h.bands, h.header_offset, h.len());
        let EnviFile {
            header,
            binary_path,
            map,
        } = self;
        match Samples::mapped(map, offset, len) {
            Ok(mut samples) => {
                let rows = (samples.as_bip_mut().expect("a BIP mapping"))
                    .par_chunks_mut(row_len.max(1))
                    .enumerate()
                    .map(|(y, row)| per_row(y, row))
                    .collect();
                (samples, rows)
            }
            Err(map) => {
                let file = EnviFile {
                    header,
                    binary_path,
                    map,
                };
                let (data, rows) = file.decode_bip_rows(per_row);
                (data.into(), rows)
            }
        }
    }

    /// The samples of a float32 band-sequential or band-interleaved-by-line cube in this
    /// machine's byte order as the file's own mapping, read by tiles in BIP order
    /// ([`Samples`]): no decoding pass and no copy. The file back for any other cube.
    pub fn into_planar(self) -> std::result::Result<Samples, Box<EnviFile>> {
        let h = &self.header;
        let native = h.data_type == DataType::F32 && h.big_endian == cfg!(target_endian = "big");
        let (w, l, nb) = (h.samples, h.lines, h.bands);
        let strides = match h.interleave {
            Interleave::Bsq => (w, w * l),
            Interleave::Bil => (w * nb, w),
            Interleave::Bip => return Err(Box::new(self)),
        };
        if !native || nb < 2 {
            return Err(Box::new(self));
        }
        let offset = h.header_offset;
        let EnviFile {
            header,
            binary_path,
            map,
        } = self;
        Samples::planar(map, offset, (w, l, nb), strides).map_err(|map| {
            Box::new(EnviFile {
                header,
                binary_path,
                map,
            })
        })
    }

    fn decode_rows<D: Decode, T: Send>(
        &self,
        dec: &D,
        per_row: impl Fn(usize, &mut [f32]) -> T + Sync,
    ) -> (Vec<f32>, Vec<T>) {
        let h = &self.header;
        let (w, l, nb, il) = (h.samples, h.lines, h.bands, h.interleave);
        let bytes = self.data();
        let mut out = vec![0f32; h.len()];
        let results = out
            .par_chunks_mut(w * nb)
            .enumerate()
            .map(|(y, row)| {
                match il {
                    Interleave::Bip => dec.run(bytes, y * w * nb, w * nb, row, 1),
                    // BSQ/BIL → BIP by tiles of pixels, as a planar cube read in place.
                    _ => {
                        for (x0, tile) in (0..w).step_by(TILE_PX).zip(row.chunks_mut(TILE_PX * nb))
                        {
                            let n = tile.len() / nb;
                            transpose_runs(nb, n, tile, |b, run| {
                                let base = il.index(l, w, nb, y, 0, b);
                                dec.run(bytes, base + x0, n, run, 1);
                            });
                        }
                    }
                }
                per_row(y, row)
            })
            .collect();
        (out, results)
    }

    /// One sample as f32.
    pub fn sample(&self, x: usize, y: usize, b: usize) -> f32 {
        let h = &self.header;
        let i = h.interleave.index(h.lines, h.samples, h.bands, y, x, b);
        self.with_decoder(|dec| dec.get(self.data(), i))
    }

    /// Per band: the mean of the usable samples (finite, not the ignore value, not
    /// saturated) and how many samples were not usable. A band with no usable sample has
    /// mean NaN. Used for white/dark references of any spatial size.
    pub fn band_means(&self) -> (Vec<f64>, Vec<u64>) {
        let h = &self.header;
        let (w, l, nb, il) = (h.samples, h.lines, h.bands, h.interleave);
        let bytes = self.data();
        let ignore = h.ignore_value.map(|v| v as f32);
        let sat = h.data_type.saturation_value().map(|v| v as f32);
        self.with_decoder(|dec| {
            (0..nb)
                .into_par_iter()
                .map(|b| {
                    let (mut sum, mut n, mut bad) = (0f64, 0u64, 0u64);
                    for y in 0..l {
                        for x in 0..w {
                            let v = dec.get(bytes, il.index(l, w, nb, y, x, b));
                            let usable =
                                v.is_finite() && Some(v) != ignore && sat.is_none_or(|s| v < s);
                            if usable {
                                sum += v as f64;
                                n += 1;
                            } else {
                                bad += 1;
                            }
                        }
                    }
                    (if n > 0 { sum / n as f64 } else { f64::NAN }, bad)
                })
                .unzip()
        })
    }
}

/// A cube in memory, band-interleaved-by-pixel f32.
#[derive(Debug, Clone, PartialEq)]
pub struct Cube {
    pub header: EnviHeader,
    /// `data[(y * samples + x) * bands + b]`.
    pub data: Vec<f32>,
}

/// Reads a whole cube as BIP f32.
pub fn read_cube(path: &Path) -> Result<Cube> {
    let file = open(path)?;
    file.header.check_decode_budget(0)?;
    let data = file.to_bip_f32();
    Ok(Cube {
        header: file.header,
        data,
    })
}

/// What to write: the cube's size and band metadata plus the on-disk encoding.
#[derive(Debug, Clone)]
pub struct WriteOptions {
    pub samples: usize,
    pub lines: usize,
    pub bands: usize,
    pub interleave: Interleave,
    pub data_type: DataType,
    pub big_endian: bool,
    pub wavelengths_nm: Option<Vec<f64>>,
    pub fwhm_nm: Option<Vec<f64>>,
    /// Written as `data ignore value`; NaN samples are stored as this value (required to
    /// write NaN into an integer type).
    pub ignore_value: Option<f64>,
    pub description: Option<String>,
}

impl WriteOptions {
    pub fn new(samples: usize, lines: usize, bands: usize) -> Self {
        WriteOptions {
            samples,
            lines,
            bands,
            interleave: Interleave::Bsq,
            data_type: DataType::F32,
            big_endian: false,
            wavelengths_nm: None,
            fwhm_nm: None,
            ignore_value: None,
            description: None,
        }
    }
}

fn format_list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| format!("{v}")).collect();
    format!("{{{}}}", items.join(", "))
}

/// The header text for `opts`.
pub fn header_text(opts: &WriteOptions) -> String {
    let mut s = String::from("ENVI\n");
    if let Some(d) = &opts.description {
        s += &format!("description = {{{}}}\n", d.replace(['{', '}'], ""));
    }
    s += &format!(
        "samples = {}\nlines = {}\nbands = {}\nheader offset = 0\nfile type = ENVI Standard\n\
         data type = {}\ninterleave = {}\nbyte order = {}\n",
        opts.samples,
        opts.lines,
        opts.bands,
        opts.data_type.code(),
        opts.interleave,
        u8::from(opts.big_endian)
    );
    if let Some(v) = opts.ignore_value {
        s += &format!("data ignore value = {v}\n");
    }
    if let Some(w) = &opts.wavelengths_nm {
        s += "wavelength units = Nanometers\n";
        s += &format!("wavelength = {}\n", format_list(w));
    }
    if let Some(f) = &opts.fwhm_nm {
        s += &format!("fwhm = {}\n", format_list(f));
    }
    s
}

/// Converts one value for storage: integers are rounded and must fit the type.
fn encode(v: f32, opts: &WriteOptions, out: &mut Vec<u8>) -> Result<()> {
    let v = if v.is_nan() {
        match opts.ignore_value {
            Some(iv) => iv,
            None if opts.data_type.is_integer() => {
                bail!(
                    "NaN sample cannot be stored as {:?} without a data ignore value",
                    opts.data_type
                )
            }
            None => v as f64,
        }
    } else {
        v as f64
    };
    macro_rules! int {
        ($t:ty) => {{
            let r = v.round();
            if !(r >= <$t>::MIN as f64 && r <= <$t>::MAX as f64) {
                bail!("value {v} does not fit {}", stringify!($t));
            }
            let x = r as $t;
            if opts.big_endian {
                out.extend_from_slice(&x.to_be_bytes())
            } else {
                out.extend_from_slice(&x.to_le_bytes())
            }
        }};
    }
    match opts.data_type {
        DataType::U8 => int!(u8),
        DataType::I16 => int!(i16),
        DataType::I32 => int!(i32),
        DataType::U16 => int!(u16),
        DataType::U32 => int!(u32),
        DataType::I64 | DataType::U64 => bail!("writing 64-bit integer cubes is not supported"),
        DataType::F32 => {
            let x = v as f32;
            out.extend_from_slice(&if opts.big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            })
        }
        DataType::F64 => out.extend_from_slice(&if opts.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }),
    }
    Ok(())
}

/// Writes `data` (BIP f32, `[(y * samples + x) * bands + b]`) as `hdr_path` plus a `.img`
/// beside it. Both go through temporary files; the header is renamed into place last, and
/// if it fails the binary is removed again, so a reader never sees a half-written pair.
pub fn write_cube(hdr_path: &Path, data: &[f32], opts: &WriteOptions) -> Result<()> {
    let (w, l, nb) = (opts.samples, opts.lines, opts.bands);
    if data.len() != w * l * nb {
        bail!(
            "{}: {} samples given for a {w}×{l}×{nb} cube",
            hdr_path.display(),
            data.len()
        );
    }
    for (key, list) in [
        ("wavelength", &opts.wavelengths_nm),
        ("fwhm", &opts.fwhm_nm),
    ] {
        if let Some(list) = list {
            if list.len() != nb {
                bail!(
                    "{}: {} {key} values for {nb} bands",
                    hdr_path.display(),
                    list.len()
                );
            }
        }
    }
    if !hdr_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("hdr"))
    {
        bail!(
            "{}: an ENVI header path must end in .hdr",
            hdr_path.display()
        );
    }
    let img_path = hdr_path.with_extension("img");
    crate::image_io::write_atomically(&img_path, |tmp| {
        let file =
            std::fs::File::create(tmp).with_context(|| format!("creating {}", tmp.display()))?;
        let mut writer = std::io::BufWriter::with_capacity(1 << 20, file);
        let mut buf = Vec::with_capacity(w * nb * opts.data_type.size());
        // One output line at a time (in file order) keeps memory flat for any interleave.
        let write_line = |buf: &mut Vec<u8>, y: usize, b: Option<usize>| -> Result<()> {
            match b {
                Some(b) => {
                    for x in 0..w {
                        encode(data[(y * w + x) * nb + b], opts, buf)
                            .with_context(|| format!("pixel ({x}, {y}) band {b}"))?;
                    }
                }
                None => {
                    for (i, &v) in data[y * w * nb..(y + 1) * w * nb].iter().enumerate() {
                        encode(v, opts, buf)
                            .with_context(|| format!("pixel ({}, {y}) band {}", i / nb, i % nb))?;
                    }
                }
            }
            Ok(())
        };
        let mut flush = |buf: &mut Vec<u8>| -> Result<()> {
            writer.write_all(buf).context("writing cube data")?;
            buf.clear();
            Ok(())
        };
        match opts.interleave {
            Interleave::Bsq => {
                for b in 0..nb {
                    for y in 0..l {
                        write_line(&mut buf, y, Some(b))?;
                        flush(&mut buf)?;
                    }
                }
            }
            Interleave::Bil => {
                for y in 0..l {
                    for b in 0..nb {
                        write_line(&mut buf, y, Some(b))?;
                    }
                    flush(&mut buf)?;
                }
            }
            Interleave::Bip => {
                for y in 0..l {
                    write_line(&mut buf, y, None)?;
                    flush(&mut buf)?;
                }
            }
        }
        writer.flush().context("flushing cube data")?;
        Ok(())
    })?;
    let header = header_text(opts);
    let written = crate::image_io::write_atomically(hdr_path, |tmp| {
        std::fs::write(tmp, header.as_bytes()).with_context(|| format!("writing {}", tmp.display()))
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&img_path);
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_parsing_handles_braces_comments_and_case() {
        let text = "ENVI\n; a comment\nDescription = {multi\n line}\nSamples = 3\nLINES= 2\nbands = 2\n\
                    data  Type = 12\ninterleave = BIL\nbyte order = 1\nwavelength units = Micrometers\n\
                    wavelength = {0.4,\n; comment inside\n 0.5}\nfwhm = {0.004, 0.004}\ndata ignore value = 0\n";
        let h = parse_header(text, Path::new("x.hdr")).unwrap();
        assert_eq!((h.samples, h.lines, h.bands), (3, 2, 2));
        assert_eq!(h.data_type, DataType::U16);
        assert_eq!(h.interleave, Interleave::Bil);
        assert!(h.big_endian);
        assert_eq!(h.wavelengths_nm.as_deref(), Some(&[400.0, 500.0][..]));
        let f = h.fwhm_nm.unwrap();
        assert!((f[0] - 4.0).abs() < 1e-9);
        assert_eq!(h.ignore_value, Some(0.0));
        assert_eq!(h.fields["description"], "multi\nline");
    }

    #[test]
    fn header_errors_name_the_field() {
        let cases: [(&str, &[&str]); 5] = [
            ("ENVI\nlines = 2\nbands = 1\ndata type = 4\n", &["a.hdr", "samples"]),
            (
                "ENVI\nsamples=1\nlines=1\nbands=1\ndata type=6\nbyte order=0\n",
                &["data type", "6"],
            ),
            ("nope\n", &["not an ENVI header"]),
            (
                "ENVI\nsamples=1\nlines=1\nbands=2\ndata type=4\nbyte order=0\ninterleave=bsq\nwavelength={400, x}\n",
                &["wavelength", "'x'"],
            ),
            (
                "ENVI\nsamples=1\nlines=1\nbands=2\ndata type=4\nbyte order=0\ninterleave=bsq\nwavelength={400\n",
                &["never closes"],
            ),
        ];
        for (text, words) in cases {
            let e = parse_header(text, Path::new("a.hdr"))
                .unwrap_err()
                .to_string();
            assert!(words.iter().all(|w| e.contains(w)), "{text:?}: {e}");
        }
    }

    #[test]
    fn interleave_index_is_a_bijection() {
        let (l, w, nb) = (3, 4, 5);
        for il in [Interleave::Bsq, Interleave::Bil, Interleave::Bip] {
            let mut seen = vec![false; l * w * nb];
            for y in 0..l {
                for x in 0..w {
                    for b in 0..nb {
                        let i = il.index(l, w, nb, y, x, b);
                        assert!(!seen[i]);
                        seen[i] = true;
                    }
                }
            }
        }
    }

    #[test]
    fn write_read_round_trip_every_layout() {
        let dir = tempfile::tempdir().unwrap();
        let (w, l, nb) = (5, 4, 3);
        let data: Vec<f32> = (0..w * l * nb).map(|i| i as f32 * 1.5 - 10.0).collect();
        for il in [Interleave::Bsq, Interleave::Bil, Interleave::Bip] {
            for (dt, big) in [
                (DataType::F32, false),
                (DataType::F64, true),
                (DataType::I16, true),
                (DataType::I32, false),
            ] {
                let mut o = WriteOptions::new(w, l, nb);
                o.interleave = il;
                o.data_type = dt;
                o.big_endian = big;
                o.wavelengths_nm = Some(vec![400.0, 500.0, 600.0]);
                let p = dir.path().join(format!("c_{il}_{}.hdr", dt.code()));
                let rounded: Vec<f32> = if dt.is_integer() {
                    data.iter().map(|v| v.round()).collect()
                } else {
                    data.clone()
                };
                write_cube(&p, &rounded, &o).unwrap();
                let c = read_cube(&p).unwrap();
                assert_eq!(c.data, rounded, "{il} {dt:?}");
                assert_eq!(c.header.interleave, il);
            }
        }
    }

    #[test]
    fn writer_rejects_unrepresentable_values() {
        let dir = tempfile::tempdir().unwrap();
        let mut o = WriteOptions::new(1, 1, 1);
        o.data_type = DataType::U16;
        let p = dir.path().join("bad.hdr");
        assert!(write_cube(&p, &[-1.0], &o).is_err());
        assert!(write_cube(&p, &[f32::NAN], &o).is_err());
        assert!(!p.exists() && !p.with_extension("img").exists());
        o.ignore_value = Some(0.0);
        write_cube(&p, &[f32::NAN], &o).unwrap();
        assert_eq!(read_cube(&p).unwrap().data, vec![0.0]);
    }
}
