//! `capture.json` (format `thinfilm-capture/1`, `docs/physics-and-formats.md`, "Data formats") and the simulator's ground
//! truth (`ground_truth/ground_truth.json` + `thickness.exr`).
//!
//! Reflectance per sample is the cube value, or with references
//! R = (raw − dark) / (white − dark), where white and dark are averaged per band over
//! their usable samples (any spatial size). Bad samples are masked to NaN and counted by
//! cause in [`InvalidCounts`]; they are never an error.

use super::envi::{self, EnviFile};
use super::{AngleCapture, CaptureSet, Cause, GroundTruth, InvalidCounts, Polarization, Samples};
use crate::optics::{Complex64, Ior};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::{Path, PathBuf};

pub const CAPTURE_FORMAT: &str = "thinfilm-capture/1";
pub const GROUND_TRUTH_FORMAT: &str = "thinfilm-ground-truth/1";

/// The JSON document, as written and read.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureFile {
    pub format: String,
    pub polarization: Polarization,
    /// A number (or a numeric string); must be real.
    #[serde(default = "default_ambient")]
    pub ambient_ior: Value,
    /// `{"ior": 1.64, "k": 0.0}`, `{"material": "PET"}`, or a bare number / `"n+ki"` / name.
    pub substrate: Value,
    pub angles: Vec<AngleEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// `relative` (default: unknown scale per pixel and angle) or `absolute` (calibrated
    /// reflectance).
    #[serde(default)]
    pub radiometry: super::Radiometry,
    /// Film index model to fit: `constant`, `cauchy` or `cauchy3` (default: chosen by
    /// the data).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub film_model: Option<crate::estimate::film::FilmModelKind>,
}

fn default_ambient() -> Value {
    Value::from(1.0)
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AngleEntry {
    pub incident_deg: f64,
    pub cube: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark: Option<String>,
    /// EXR of the per-pixel incidence in degrees (one channel, `Y` or `incident_deg`), for
    /// cameras whose field of view spans several degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub incident_deg_map: Option<String>,
}

/// `{"ior": n, "k": k}` for a constant index, `{"material": name}` for a library material.
pub fn ior_to_json(ior: &Ior) -> Value {
    match ior {
        Ior::Constant(c) => serde_json::json!({"ior": c.re, "k": c.im}),
        Ior::Material(m) => serde_json::json!({"material": m.name}),
    }
}

/// Parses an index given as `{"ior": n|"n+ki", "k": k}`, `{"material": name}`, a number,
/// or a string (`"1.64"`, `"0.18+3.4i"`, `"Au"`). `what` names the field for errors.
pub fn ior_from_json(v: &Value, what: &str) -> Result<Ior> {
    let from_text = |s: &str| s.parse::<Ior>().map_err(|e| anyhow::anyhow!("{what}: {e}"));
    match v {
        Value::Number(n) => from_text(&n.to_string()),
        Value::String(s) => from_text(s),
        Value::Object(map) => {
            if let Some(unknown) = map
                .keys()
                .find(|k| !matches!(k.as_str(), "ior" | "k" | "material"))
            {
                bail!(
                    "{what}: unknown key '{unknown}' (expected \"ior\" and \"k\", or \"material\")"
                );
            }
            match (map.get("ior"), map.get("material")) {
                (Some(_), Some(_)) => {
                    bail!("{what}: give either \"ior\" (and \"k\") or \"material\", not both")
                }
                (None, Some(Value::String(name))) => {
                    if map.contains_key("k") {
                        bail!("{what}: \"k\" cannot be combined with \"material\"");
                    }
                    match from_text(name)? {
                        m @ Ior::Material(_) => Ok(m),
                        _ => bail!("{what}.material: '{name}' is not a material name"),
                    }
                }
                (None, Some(_)) => bail!("{what}.material must be a string"),
                (Some(ior), None) => {
                    let base = match ior {
                        Value::Number(n) => from_text(&n.to_string())?,
                        Value::String(s) => from_text(s)?,
                        _ => bail!("{what}.ior must be a number or a string like \"0.18+3.4i\""),
                    };
                    let k = match map.get("k") {
                        None | Some(Value::Null) => 0.0,
                        Some(Value::Number(k)) => k.as_f64().unwrap_or(f64::NAN),
                        Some(_) => bail!("{what}.k must be a number"),
                    };
                    if !(k.is_finite() && k >= 0.0) {
                        bail!("{what}.k must be finite and ≥ 0, got {k}");
                    }
                    match base {
                        Ior::Constant(c) if k > 0.0 && c.im > 0.0 => {
                            bail!("{what}: extinction given twice (in \"ior\" and in \"k\")")
                        }
                        Ior::Constant(c) => Ok(Ior::Constant(Complex64::new(c.re, c.im + k))),
                        Ior::Material(_) if map.contains_key("k") => {
                            bail!("{what}: \"k\" cannot be combined with a material name")
                        }
                        m => Ok(m),
                    }
                }
                (None, None) => {
                    bail!("{what}: expected {{\"ior\": n, \"k\": k}} or {{\"material\": name}}")
                }
            }
        }
        _ => bail!("{what}: expected a number, a string or an object"),
    }
}

/// Largest `ambient_ior` accepted (dense immersion liquids reach ~1.8; 3 leaves room).
const MAX_AMBIENT_IOR: f64 = 3.0;

/// Most angles a capture set may list. Goniometric captures use tens; the fit's cost grows
/// with the square of the count (angle pairs), so thousands would stall it.
const MAX_ANGLES: usize = 64;

/// Two captures at the same incident angle add no information about the index and make the
/// angle pairs of the fit degenerate: refuse them, naming both entries.
fn check_distinct_angles(angles: &[AngleEntry], json: &impl std::fmt::Display) -> Result<()> {
    for (i, a) in angles.iter().enumerate() {
        if let Some(k) = angles[..i]
            .iter()
            .position(|b| (a.incident_deg - b.incident_deg).abs() < 1e-9)
        {
            bail!(
                "{json}: angles[{i}].incident_deg = {} repeats angles[{k}] (average repeated captures into one cube)",
                a.incident_deg
            );
        }
    }
    Ok(())
}

fn resolve(dir: &Path, name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        dir.join(p)
    }
}

/// Wavelength lists agree to 1e-3 nm (text round trips of µm values lose a little).
fn same_wavelengths(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-3)
}

fn describe_wavelengths(w: &[f64]) -> String {
    match (w.first(), w.last()) {
        (Some(a), Some(b)) => format!("{} bands {a}–{b} nm", w.len()),
        _ => "no bands".into(),
    }
}

/// Opens a cube named in `capture.json`, with the JSON field in the error.
fn open_named(json: &Path, dir: &Path, field: &str, name: &str) -> Result<EnviFile> {
    let path = resolve(dir, name);
    if !envi::header_path(&path).is_file() {
        bail!(
            "{}: {field}: cube '{}' not found",
            json.display(),
            path.display()
        );
    }
    envi::open(&path).with_context(|| format!("{}: {field}", json.display()))
}

/// Per-band reference (mean of usable samples), checked against the cube's bands.
fn reference_means(
    json: &Path,
    dir: &Path,
    field: &str,
    name: &str,
    cube: &EnviFile,
) -> Result<Vec<f64>> {
    let file = open_named(json, dir, field, name)?;
    if file.header.bands != cube.header.bands {
        bail!(
            "{}: {field}: {} has {} bands but {} has {}",
            json.display(),
            file.header.path.display(),
            file.header.bands,
            cube.header.path.display(),
            cube.header.bands
        );
    }
    if let (Some(a), Some(b)) = (&file.header.wavelengths_nm, &cube.header.wavelengths_nm) {
        if !same_wavelengths(a, b) {
            bail!(
                "{}: {field}: wavelengths of {} ({}) differ from {} ({})",
                json.display(),
                file.header.path.display(),
                describe_wavelengths(a),
                cube.header.path.display(),
                describe_wavelengths(b)
            );
        }
    }
    Ok(file.band_means().0)
}

/// Reflectance and masking for one angle's cube, in place on its BIP f32 samples: without
/// references a float32 BIP cube is its own samples (mapped, no decoding pass), else each
/// row is calibrated as it is decoded.
fn reflectance(
    file: EnviFile,
    white: Option<&[f64]>,
    dark: Option<&[f64]>,
) -> (Samples, Vec<bool>, InvalidCounts) {
    let h = &file.header;
    let (w, nb) = (h.samples, h.bands);
    let ignore = h.ignore_value.map(|v| v as f32);
    let sat = h.data_type.saturation_value().map(|v| v as f32);
    // Per band: (offset, scale) with R = (raw − offset) · scale, or None if the band's
    // reference is unusable (white − dark ≤ 0, or no usable reference sample).
    let band_map: Vec<Option<(f64, f64)>> = (0..nb)
        .map(|b| match white {
            None => Some((0.0, 1.0)),
            Some(white) => {
                let d = dark.map_or(0.0, |d| d[b]);
                let span = white[b] - d;
                (span > 0.0 && span.is_finite()).then(|| (d, 1.0 / span))
            }
        })
        .collect();
    // Fast path per pixel (branch-free, vectorises): every raw sample usable and every
    // band reference usable → calibrate in place. Anything else → the per-sample path
    // below, which counts the cause. Same results either way.
    let identity = white.is_none();
    let all_refs = band_map.iter().all(Option::is_some);
    let offset: Vec<f64> = band_map.iter().map(|m| m.map_or(0.0, |m| m.0)).collect();
    let scale: Vec<f64> = band_map.iter().map(|m| m.map_or(1.0, |m| m.1)).collect();
    let ignore_v = ignore.unwrap_or(f32::NAN); // NaN never compares equal
    let sat_v = sat.unwrap_or(f32::INFINITY); // inf is caught as non-finite anyway
    let lines = h.lines;
    // Calibrated and masked row by row as each row is decoded (still in cache).
    let per_row = |_, row: &mut [f32]| {
        let mut c = InvalidCounts::default();
        let mut valid_row = vec![true; w];
        let mut cal = vec![0f32; nb];
        for (px, ok) in row.chunks_mut(nb).zip(valid_row.iter_mut()) {
            if all_refs {
                let bad = px.iter().fold(false, |bad, &v| {
                    bad | !v.is_finite() | (v == ignore_v) | (v >= sat_v)
                });
                if !bad {
                    if identity {
                        continue;
                    }
                    for (((o, &v), &off), &sc) in
                        cal.iter_mut().zip(px.iter()).zip(&offset).zip(&scale)
                    {
                        *o = ((v as f64 - off) * sc) as f32;
                    }
                    if cal.iter().all(|v| v.is_finite()) {
                        px.copy_from_slice(&cal);
                        continue;
                    }
                }
            }
            for (b, v) in px.iter_mut().enumerate() {
                let raw = *v;
                let cause = if let Some(cause) = raw_sample_cause(raw, ignore, sat) {
                    Some(c.of(cause))
                } else if let Some((offset, scale)) = band_map[b] {
                    let r = ((raw as f64 - offset) * scale) as f32;
                    if r.is_finite() {
                        *v = r;
                        None
                    } else {
                        Some(&mut c.non_finite)
                    }
                } else {
                    Some(&mut c.bad_reference)
                };
                if let Some(counter) = cause {
                    *counter += 1;
                    *v = f32::NAN;
                    *ok = false;
                }
            }
        }
        (valid_row, c)
    };
    let (data, rows) = if identity {
        match file.into_planar() {
            Ok(planar) => return mask_planar(planar, (w, lines, nb), ignore, sat),
            Err(file) => (*file).into_bip_rows(per_row),
        }
    } else {
        // Calibration writes every sample: decode (a mapping would copy every page).
        let (data, rows) = file.decode_bip_rows(per_row);
        (data.into(), rows)
    };
    let mut valid = Vec::with_capacity(w * lines);
    let mut counts = InvalidCounts::default();
    for (valid_row, c) in rows {
        valid.extend_from_slice(&valid_row);
        counts.add(&c);
    }
    (data, valid, counts)
}

/// Why a raw sample is unusable before any calibration: not finite, the header's ignore
/// value, or at or above the data type's saturation value.
fn raw_sample_cause(raw: f32, ignore: Option<f32>, sat: Option<f32>) -> Option<Cause> {
    if !raw.is_finite() {
        Some(Cause::NonFinite)
    } else if Some(raw) == ignore {
        Some(Cause::IgnoreValue)
    } else if sat.is_some_and(|s| raw >= s) {
        Some(Cause::Saturated)
    } else {
        None
    }
}

/// Masking of an uncalibrated planar (BSQ/BIL float32) cube read in place from its mapping:
/// the same masks, counts and NaN samples as decoding it would give, from one pass over
/// the band runs of each block of lines (a pixel is checked sample by sample only when a
/// run flags it). Band-major within a block: a BSQ band's lines follow each other in the
/// file, so each band is one long run the prefetcher follows (a line at a time it
/// restarted every 4 KB).
fn mask_planar(
    mut samples: Samples,
    (w, lines, nb): (usize, usize, usize),
    ignore: Option<f32>,
    sat: Option<f32>,
) -> (Samples, Vec<bool>, InvalidCounts) {
    use rayon::prelude::*;
    const BLOCK_LINES: usize = 8;
    let ignore_v = ignore.unwrap_or(f32::NAN); // NaN never compares equal
    let sat_v = sat.unwrap_or(f32::INFINITY); // inf is caught as non-finite anyway
    let s = &samples;
    let run = |y, b| s.planar_run(y, b).expect("a planar cube");
    let blocks: Vec<(Vec<bool>, InvalidCounts, Vec<(usize, usize, usize)>)> = (0..lines
        .div_ceil(BLOCK_LINES))
        .into_par_iter()
        .map(|block| {
            let y0 = block * BLOCK_LINES;
            let ys = y0..(y0 + BLOCK_LINES).min(lines);
            let mut bad = vec![false; w * ys.len()];
            for b in 0..nb {
                for (y, bad) in ys.clone().zip(bad.chunks_exact_mut(w)) {
                    for (k, &v) in bad.iter_mut().zip(run(y, b)) {
                        *k |= !v.is_finite() | (v == ignore_v) | (v >= sat_v);
                    }
                }
            }
            let (mut c, mut masked) = (InvalidCounts::default(), Vec::new());
            for i in (0..bad.len()).filter(|&i| bad[i]) {
                let (y, x) = (y0 + i / w, i % w);
                for b in 0..nb {
                    if let Some(cause) = raw_sample_cause(run(y, b)[x], ignore, sat) {
                        *c.of(cause) += 1;
                        masked.push((y, x, b));
                    }
                }
            }
            (bad.iter().map(|b| !b).collect(), c, masked)
        })
        .collect();
    let mut valid = Vec::with_capacity(w * lines);
    let mut counts = InvalidCounts::default();
    for (valid_block, c, masked) in blocks {
        valid.extend_from_slice(&valid_block);
        counts.add(&c);
        for (y, x, b) in masked {
            samples.set_planar(y, x, b, f32::NAN);
        }
    }
    (samples, valid, counts)
}

/// A per-pixel incidence map named in capture.json: degrees, the cube's size, each value
/// in [0, 90) or NaN (unknown: that pixel is not used at this angle).
fn angle_map(
    json: &Path,
    dir: &Path,
    field: &str,
    name: &str,
    size: (usize, usize),
) -> Result<Vec<f32>> {
    let path = resolve(dir, name);
    let (w, h, map) = crate::image_io::read_exr_scalar(&path, &["incident_deg", "Y"])
        .with_context(|| format!("{}: {field}", json.display()))?;
    if (w, h) != size {
        bail!(
            "{}: {field}: {} is {w}×{h} but the cube is {}×{}",
            json.display(),
            path.display(),
            size.0,
            size.1
        );
    }
    if let Some((i, v)) = map
        .iter()
        .enumerate()
        .find(|(_, v)| v.is_finite() && !(0.0..90.0).contains(*v) || v.is_infinite())
    {
        bail!(
            "{}: {field}: {} pixel ({}, {}) = {v}° is outside [0°, 90°)",
            json.display(),
            path.display(),
            i % w,
            i / w
        );
    }
    Ok(map)
}

/// `capture.json` read and checked, with its media resolved.
struct Spec {
    file: CaptureFile,
    ambient_ior: f64,
    substrate_ior: Ior,
}

/// Reads and checks `capture.json` (not its cubes): every error names the field.
fn read_spec(json: &Path) -> Result<Spec> {
    let text = crate::limits::read_text(json, "capture set", 16)?;
    let j = json.display();
    let doc: Value = serde_json::from_str(&text).with_context(|| format!("{j}: not valid JSON"))?;
    // Checked by hand first so the message names the field and the allowed values.
    match doc.get("polarization") {
        Some(Value::String(p)) => {
            p.parse::<Polarization>()
                .map_err(|e| anyhow::anyhow!("{j}: field 'polarization': {e}"))?;
        }
        Some(other) => {
            bail!("{j}: field 'polarization' must be a string (s, p or unpolarized), got {other}")
        }
        None => bail!("{j}: missing field 'polarization' (s, p or unpolarized)"),
    }
    drop(doc);
    // Typed from the text (not the parsed value) so that errors carry a line and column.
    let file: CaptureFile = serde_json::from_str(&text)
        .with_context(|| format!("{j}: not a valid {CAPTURE_FORMAT} document"))?;
    if file.format != CAPTURE_FORMAT {
        bail!(
            "{j}: field 'format' is '{}', expected '{CAPTURE_FORMAT}'",
            file.format
        );
    }
    let ambient =
        ior_from_json(&file.ambient_ior, "ambient_ior").with_context(|| format!("{j}"))?;
    let ambient_ior = match ambient {
        Ior::Constant(c) if c.im == 0.0 => c.re,
        other => bail!("{j}: ambient_ior must be a real number (light arrives through a lossless medium), got {other}"),
    };
    // Air, water, immersion oils: a transparent medium light can arrive through.
    crate::limits::check_range(
        format!("{j}: ambient_ior"),
        ambient_ior,
        1.0,
        MAX_AMBIENT_IOR,
    )?;
    let substrate_ior =
        ior_from_json(&file.substrate, "substrate").with_context(|| format!("{j}"))?;
    crate::limits::check_index(format!("{j}: substrate"), &substrate_ior)?;
    if file.angles.is_empty() {
        bail!("{j}: 'angles' is empty");
    }
    if file.angles.len() > MAX_ANGLES {
        bail!(
            "{j}: 'angles' lists {} captures; at most {MAX_ANGLES} are supported",
            file.angles.len()
        );
    }
    check_distinct_angles(&file.angles, &j)?;
    for (i, a) in file.angles.iter().enumerate() {
        if !(a.incident_deg.is_finite() && (0.0..90.0).contains(&a.incident_deg)) {
            bail!(
                "{j}: angles[{i}].incident_deg = {} must be in [0, 90)",
                a.incident_deg
            );
        }
    }
    Ok(Spec {
        file,
        ambient_ior,
        substrate_ior,
    })
}

/// A cube of another angle must have the first one's size and wavelengths.
fn check_same_cube(
    j: &impl std::fmt::Display,
    first: &envi::EnviHeader,
    h: &envi::EnviHeader,
) -> Result<()> {
    if (first.samples, first.lines) != (h.samples, h.lines) {
        bail!(
            "{j}: cube sizes differ: {} is {}×{} but {} is {}×{}",
            first.path.display(),
            first.samples,
            first.lines,
            h.path.display(),
            h.samples,
            h.lines
        );
    }
    let fw = first.wavelengths_nm.as_deref().unwrap_or_default();
    let wl = h.wavelengths_nm.as_deref().unwrap_or_default();
    if !same_wavelengths(fw, wl) {
        bail!(
            "{j}: wavelengths differ: {} has {} but {} has {}",
            first.path.display(),
            describe_wavelengths(fw),
            h.path.display(),
            describe_wavelengths(wl)
        );
    }
    Ok(())
}

/// The white and dark per-band means of entry `field` (`None` without references).
fn references(
    json: &Path,
    dir: &Path,
    field: &str,
    a: &AngleEntry,
    file: &EnviFile,
) -> Result<(Option<Vec<f64>>, Option<Vec<f64>>)> {
    let white = a
        .white
        .as_deref()
        .map(|n| reference_means(json, dir, &format!("{field}.white"), n, file))
        .transpose()?;
    let dark = match (&a.dark, &white) {
        (Some(_), None) => {
            bail!(
                "{}: {field}: a 'dark' reference needs a 'white' reference too",
                json.display()
            )
        }
        (Some(n), Some(_)) => Some(reference_means(
            json,
            dir,
            &format!("{field}.dark"),
            n,
            file,
        )?),
        (None, _) => None,
    };
    Ok((white, dark))
}

/// One angle of the set: its cube calibrated and masked, and its incidence map.
fn load_angle(
    json: &Path,
    dir: &Path,
    field: &str,
    a: &AngleEntry,
    file: EnviFile,
) -> Result<(AngleCapture, InvalidCounts)> {
    let (white, dark) = references(json, dir, field, a, &file)?;
    let size = (file.header.samples, file.header.lines);
    let map = a
        .incident_deg_map
        .as_deref()
        .map(|name| angle_map(json, dir, &format!("{field}.incident_deg_map"), name, size))
        .transpose()?;
    let (data, mut valid, counts) = reflectance(file, white.as_deref(), dark.as_deref());
    if let Some(m) = &map {
        // Pixels of unknown incidence are not used at this angle.
        for (v, th) in valid.iter_mut().zip(m) {
            *v &= th.is_finite();
        }
    }
    let angle = AngleCapture {
        incident_deg: a.incident_deg,
        incident_deg_map: map,
        reflectance: data,
        valid,
    };
    Ok((angle, counts))
}

pub(super) fn load_capture_set(path: &Path) -> Result<CaptureSet> {
    let (dir, json) = if path.is_file() {
        (
            path.parent().unwrap_or(Path::new(".")).to_path_buf(),
            path.to_path_buf(),
        )
    } else {
        (path.to_path_buf(), path.join("capture.json"))
    };
    let j = json.display();
    let spec = read_spec(&json)?;
    // Decoded bytes of the angles loaded so far, against the memory budget.
    let mut decoded = 0u64;
    // Only the first header is kept (a mapping is dropped as soon as it is decoded, or
    // kept as the samples of a cube already in their layout).
    let mut first: Option<envi::EnviHeader> = None;
    let mut angles = Vec::with_capacity(spec.file.angles.len());
    let mut invalid = InvalidCounts::default();
    for (i, a) in spec.file.angles.iter().enumerate() {
        let field = format!("angles[{i}]");
        let file = open_named(&json, &dir, &format!("{field}.cube"), &a.cube)?;
        let h = &file.header;
        h.check_decode_budget(decoded)
            .with_context(|| format!("{j}: {field}.cube"))?;
        decoded += h.decoded_bytes();
        if h.wavelengths_nm.is_none() {
            bail!(
                "{}: header has no 'wavelength' field (a capture needs band wavelengths)",
                h.path.display()
            );
        }
        if let Some(fh) = &first {
            check_same_cube(&j, fh, h)?;
        } else {
            first = Some(h.clone());
        }
        let (angle, counts) = load_angle(&json, &dir, &field, a, file)?;
        angles.push(angle);
        invalid.add(&counts);
    }
    let Some(h) = first else {
        bail!("{j}: 'angles' is empty");
    };
    let samples = (h.samples * h.lines * h.bands * angles.len()) as u64;
    if invalid.total() >= samples {
        bail!(
            "{j}: no usable sample in any cube ({} NaN/inf, {} equal to the ignore value, {} saturated, {} with a bad white/dark reference)",
            invalid.non_finite,
            invalid.ignore_value,
            invalid.saturated,
            invalid.bad_reference
        );
    }
    Ok(CaptureSet {
        polarization: spec.file.polarization,
        radiometry: spec.file.radiometry,
        film_model: spec.file.film_model,
        pixel_names: None,
        ambient_ior: spec.ambient_ior,
        substrate_ior: spec.substrate_ior,
        wavelengths_nm: h.wavelengths_nm.unwrap_or_default(),
        fwhm_nm: h.fwhm_nm,
        width: h.samples,
        height: h.lines,
        angles,
        invalid,
    })
}

/// `ground_truth.json` as written by the simulator (only the fields the loader needs
/// are typed; the rest — statistics and options — is free-form).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GroundTruthFile {
    pub format: String,
    pub film: Value,
    pub substrate: Value,
    pub width: usize,
    pub height: usize,
    #[serde(default = "default_thickness_file")]
    pub thickness_exr: String,
    #[serde(flatten)]
    pub extra: serde_json::Map<String, Value>,
}

fn default_thickness_file() -> String {
    "thickness.exr".into()
}

pub(super) fn load_ground_truth(dir: &Path) -> Result<GroundTruth> {
    let gt_dir = if dir.join("ground_truth.json").is_file() {
        dir.to_path_buf()
    } else {
        dir.join("ground_truth")
    };
    let json = gt_dir.join("ground_truth.json");
    let text = crate::limits::read_text(&json, "ground truth", 16)?;
    let spec: GroundTruthFile = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a valid ground-truth document", json.display()))?;
    let j = json.display();
    if spec.format != GROUND_TRUTH_FORMAT {
        bail!(
            "{j}: field 'format' is '{}', expected '{GROUND_TRUTH_FORMAT}'",
            spec.format
        );
    }
    let film_ior = ior_from_json(&spec.film, "film").with_context(|| format!("{j}"))?;
    crate::limits::check_index(format!("{j}: film"), &film_ior)?;
    let substrate_ior =
        ior_from_json(&spec.substrate, "substrate").with_context(|| format!("{j}"))?;
    crate::limits::check_index(format!("{j}: substrate"), &substrate_ior)?;
    let exr = resolve(&gt_dir, &spec.thickness_exr);
    let (w, h, thickness_nm) = crate::material::read_thickness_exr(&exr)?;
    if (w, h) != (spec.width, spec.height) {
        bail!(
            "{}: is {w}×{h} but {j} says {}×{}",
            exr.display(),
            spec.width,
            spec.height
        );
    }
    Ok(GroundTruth {
        film_ior,
        substrate_ior,
        width: w,
        height: h,
        thickness_nm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn ior_json_forms() {
        assert_eq!(ior_from_json(&json!(1.64), "s").unwrap(), Ior::real(1.64));
        assert_eq!(
            ior_from_json(&json!({"ior": 0.18, "k": 3.4}), "s").unwrap(),
            Ior::Constant(Complex64::new(0.18, 3.4))
        );
        assert_eq!(
            ior_from_json(&json!({"ior": "0.18+3.4i"}), "s").unwrap(),
            Ior::Constant(Complex64::new(0.18, 3.4))
        );
        assert_eq!(ior_from_json(&json!("1.5"), "s").unwrap(), Ior::real(1.5));
        for bad in [
            json!({"ior": 1.5, "k": -1}),
            json!({"ior": 1.5, "kk": 0}),
            json!({"material": "NoSuchGlass"}),
            json!({"ior": 1.5, "material": "x"}),
            json!([1.5]),
            json!(-2),
        ] {
            let e = ior_from_json(&bad, "substrate").unwrap_err().to_string();
            assert!(e.contains("substrate"), "{e}");
        }
        let v = ior_to_json(&Ior::Constant(Complex64::new(1.64, 0.0)));
        assert_eq!(ior_from_json(&v, "s").unwrap(), Ior::real(1.64));
    }
}
