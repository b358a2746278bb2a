//! Fitting a capture in row bands (`thinfilm estimate --rows A:B`) that `thinfilm merge`
//! stitches into exactly the whole fit.
//!
//! With the film index given, the `full` method's thickness of a pixel depends on the rest of
//! the image through (1) the global search on a lattice of seed pixels spread over the whole
//! image, and the typical residual of those seeds, (2) its own row (propagation from the left
//! neighbour), (3) spatial order resolution (two rounds of a 5×5 median, reaching
//! [`HALO_ROWS`](super::thickness::HALO_ROWS) = 4 rows above and below), and (4) the global
//! stages, which run on pixel samples of the whole capture (noise, the nuisance terms of the
//! joint fit, whether thin films are anchored by the joint fit's pixels). A band fit runs (1)
//! and (4) on the whole capture, (2) and (3) on its rows and the halo, and the checks (σ,
//! identifiability, sub-fringe refits, χ²/dof, warnings) and the report on its rows: the band's
//! thickness is the same arithmetic on the same values as in the whole fit, so the stitched map
//! is bit-identical, and its σ, χ²/dof and warnings describe the band. The `paper` and `grid`
//! methods fit each pixel on its own; a band fits only its pixels. Without `--film-ior`, a band
//! is fitted as a capture of its own — index, noise, nuisance terms and thickness from its
//! pixels (phase one of the two-phase recipe for huge captures: the index from a band, then
//! every band with that index).
//!
//! Cost (`thinfilm bench estimate --large-only --bands 4`, 1024×1024 × 5 angles × 81 bands): see
//! `docs/scale-out.md`.
//!
//! Every thickness EXR carries its provenance (text attributes `thinfilm.kind` = `fit`,
//! `thinfilm.rows` `A:B`, `thinfilm.imageHeight`, `thinfilm.fitHash` — a fingerprint of the
//! capture and of every option that changes the fit — `thinfilm.filmIor`, `thinfilm.version`).

use crate::capture::CaptureSet;
use crate::image_io::Attributes;
use crate::render::provenance::{parse_range, Fnv, KIND, VERSION};
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;

const ROWS: &str = "thinfilm.rows";
const IMAGE_HEIGHT: &str = "thinfilm.imageHeight";
const FIT_HASH: &str = "thinfilm.fitHash";
const FILM_IOR: &str = "thinfilm.filmIor";

/// The provenance of a fitted thickness map (a band of rows, or the whole image).
#[derive(Debug, Clone, PartialEq)]
pub struct TileInfo {
    /// Rows `[A, B)` of the capture this map holds.
    pub rows: (usize, usize),
    /// Rows of the whole capture.
    pub image_height: usize,
    /// Fingerprint of the capture and the fit options (see [`fit_hash`]).
    pub fit_hash: u64,
    /// The film index the thickness was fitted with.
    pub film_ior: f64,
    pub version: String,
}

impl TileInfo {
    pub fn attributes(&self) -> Attributes {
        vec![
            (KIND.into(), "fit".into()),
            (ROWS.into(), format!("{}:{}", self.rows.0, self.rows.1)),
            (IMAGE_HEIGHT.into(), self.image_height.to_string()),
            (FIT_HASH.into(), format!("{:016x}", self.fit_hash)),
            (FILM_IOR.into(), format!("{:?}", self.film_ior)),
            (VERSION.into(), self.version.clone()),
        ]
    }

    /// Reads the attributes back; `what` names the file in errors.
    pub fn from_attributes(attrs: &BTreeMap<String, String>, what: &str) -> Result<Self> {
        let get = |key: &str| -> Result<&str> {
            attrs.get(key).map(String::as_str).with_context(|| {
                format!("{what}: no '{key}' attribute in the EXR header (not a map written by thinfilm estimate)")
            })
        };
        if get(KIND)? != "fit" {
            bail!("{what}: '{KIND}' is '{}', not 'fit'", get(KIND)?);
        }
        let (a, b) = parse_range(get(ROWS)?).with_context(|| format!("{what}: '{ROWS}'"))?;
        let info = TileInfo {
            rows: (a as usize, b as usize),
            image_height: get(IMAGE_HEIGHT)?
                .parse()
                .with_context(|| format!("{what}: '{IMAGE_HEIGHT}'"))?,
            fit_hash: u64::from_str_radix(get(FIT_HASH)?, 16)
                .with_context(|| format!("{what}: '{FIT_HASH}' is not hex"))?,
            film_ior: get(FILM_IOR)?
                .parse()
                .with_context(|| format!("{what}: '{FILM_IOR}'"))?,
            version: get(VERSION)?.to_string(),
        };
        crate::limits::check_range(
            format!("{what}: '{FILM_IOR}'"),
            info.film_ior,
            f64::MIN_POSITIVE,
            crate::limits::MAX_IOR,
        )?;
        if info.rows.1 > info.image_height {
            bail!(
                "{what}: rows {}:{} lie outside an image of {} rows",
                info.rows.0,
                info.rows.1,
                info.image_height
            );
        }
        Ok(info)
    }
}

/// Fingerprint of a fit: the capture (size, wavelengths, FWHMs, angles, indices,
/// polarisation, and every 4099th reflectance value and mask entry of every angle) and
/// `options` (index, method, thickness range, …; not the rows). Tiles with equal hashes
/// stitch into one fit.
pub fn fit_hash(set: &CaptureSet, film_ior: f64, options: &super::Options) -> u64 {
    let mut h = Fnv::default();
    let super::Options {
        method,
        film_ior: _, // the index used is hashed below
        film_model,
        fit_substrate,
        radiometry,
        min_thickness_nm,
        max_thickness_nm,
        min_film_ior,
        max_film_ior,
        grid_ior_step,
        grid_thickness_step_nm,
        grid_pixel_stride,
        band_integration,
        joint_pixels,
        progress: _,
        rows: _,
    } = options;
    let _ = write!(
        h,
        "{method}|{film_ior:?}|{film_model:?}|{fit_substrate:?}|{radiometry:?}|{min_thickness_nm:?}|{max_thickness_nm:?}|{min_film_ior:?}|\
         {max_film_ior:?}|{grid_ior_step:?}|{grid_thickness_step_nm:?}|{grid_pixel_stride}|\
         {band_integration}|{joint_pixels}|{}x{}|{:?}|{:?}|{}|{}|{:?}|{}",
        set.width,
        set.height,
        set.wavelengths_nm,
        set.fwhm_nm,
        set.ambient_ior,
        set.substrate_ior,
        set.polarization,
        env!("CARGO_PKG_VERSION"),
    );
    for a in &set.angles {
        let _ = write!(h, "|{:?}", a.incident_deg);
        for i in (0..a.reflectance.len()).step_by(4099) {
            let _ = write!(h, ",{:x}", a.reflectance.at(i).to_bits());
        }
        for v in a.valid.iter().step_by(4099) {
            let _ = write!(h, "{}", *v as u8);
        }
    }
    h.0
}

/// Which rows a fit covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowBand {
    /// Rows `[A, B)` (`--rows A:B`).
    Rows(usize, usize),
    /// Band `index` of `count` equal bands (`--part K/N`; band K is rows
    /// `⌊K·H/N⌋ .. ⌊(K+1)·H/N⌋`), so a job array needs no arithmetic.
    Part { index: usize, count: usize },
}

impl RowBand {
    /// Rows `[A, B)` of a capture of `height` rows; an error naming the option when the band
    /// is empty or outside the capture.
    pub fn resolve(self, height: usize) -> Result<(usize, usize)> {
        match self {
            RowBand::Rows(a, b) => {
                if a >= b || b > height {
                    bail!(
                        "--rows {a}:{b} must satisfy START < END ≤ {height} (the capture's height)"
                    );
                }
                Ok((a, b))
            }
            RowBand::Part { index, count } => {
                if index >= count || count > height {
                    bail!(
                        "--part {index}/{count} must satisfy K < N ≤ {height} (the capture's height)"
                    );
                }
                Ok((index * height / count, (index + 1) * height / count))
            }
        }
    }
}
