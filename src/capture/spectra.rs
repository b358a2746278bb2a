//! Point spectra: 2-column text files (`wavelength_nm, intensity`, comma, semicolon, tab or
//! space separated; `.csv`, `.xy`, `.txt`) from a point spectrometer, each one pixel of a
//! capture set with one incident angle. An optional dark ("void") spectrum — the signal
//! with no film: dark offset and stray light — is subtracted from each.
//!
//! Every file must hold the same wavelengths (sorted, no duplicates). Lines starting with
//! `#` and a non-numeric first line (a header) are skipped; any other non-numeric line is
//! an error naming the file and line. Non-finite intensities (`nan`, `inf`) are masked: the
//! band is dropped from every spectrum (the estimator fits one wavelength grid) and the
//! masked samples are counted in `invalid_samples.non_finite`.

use super::{AngleCapture, CaptureSet, InvalidCounts, Polarization, Radiometry};
use crate::optics::Ior;
use anyhow::{bail, Context, Result};
use std::path::Path;

/// How the spectra were taken (what capture.json says for a cube).
#[derive(Debug, Clone)]
pub struct SpectraSetup {
    pub incident_deg: f64,
    pub ambient_ior: f64,
    /// `None`: a free-standing film (the substrate is the ambient medium, e.g. soap films).
    pub substrate_ior: Option<Ior>,
    pub polarization: Polarization,
    pub radiometry: Radiometry,
}

/// One spectrum: wavelengths (nm) and values, as read.
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    pub wavelengths_nm: Vec<f64>,
    pub values: Vec<f64>,
}

/// Parses a 2-column spectrum; `what` names the file in errors.
pub fn parse_spectrum(text: &str, what: &str) -> Result<Spectrum> {
    let (mut wl, mut val) = (Vec::new(), Vec::new());
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = line
            .split(|c: char| c == ',' || c == ';' || c.is_whitespace())
            .filter(|c| !c.is_empty())
            .collect();
        let nums: Option<Vec<f64>> = cols.iter().map(|c| c.parse::<f64>().ok()).collect();
        let nums = match nums {
            Some(n) if n.len() >= 2 => n,
            _ if wl.is_empty() && cols.iter().any(|c| c.parse::<f64>().is_err()) && i == 0 => {
                continue; // a header line
            }
            _ => bail!(
                "{what}:{}: expected two numbers (wavelength in nm, intensity), got '{line}'",
                i + 1
            ),
        };
        let (l, v) = (nums[0], nums[1]);
        if !(l.is_finite() && l > 0.0) {
            bail!(
                "{what}:{}: wavelength {l} is not a positive number of nm",
                i + 1
            );
        }
        if let Some(&prev) = wl.last() {
            if l <= prev {
                bail!(
                    "{what}:{}: wavelength {l} nm after {prev} nm: wavelengths must increase \
                     (unsorted or duplicate)",
                    i + 1
                );
            }
        }
        wl.push(l);
        val.push(v);
    }
    if wl.len() < 3 {
        bail!("{what}: {} samples; a spectrum needs at least 3", wl.len());
    }
    Ok(Spectrum {
        wavelengths_nm: wl,
        values: val,
    })
}

fn read_spectrum(path: &Path) -> Result<Spectrum> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_spectrum(&text, &path.display().to_string())
}

/// Checks `s` has the wavelengths of `reference` (read from `first`).
fn same_grid(s: &Spectrum, reference: &Spectrum, what: &Path, first: &Path) -> Result<()> {
    if s.wavelengths_nm.len() != reference.wavelengths_nm.len() {
        bail!(
            "{}: {} samples but {} has {}: every spectrum must share the wavelengths",
            what.display(),
            s.wavelengths_nm.len(),
            first.display(),
            reference.wavelengths_nm.len()
        );
    }
    for (i, (a, b)) in s
        .wavelengths_nm
        .iter()
        .zip(&reference.wavelengths_nm)
        .enumerate()
    {
        if (a - b).abs() > 1e-6 * b.abs().max(1.0) {
            bail!(
                "{}: sample {} is at {a} nm but at {b} nm in {}: every spectrum must share \
                 the wavelengths",
                what.display(),
                i + 1,
                first.display()
            );
        }
    }
    Ok(())
}

/// Loads point spectra as a capture set of `files.len()` × 1 pixels and one angle.
pub fn load_spectra(
    files: &[&Path],
    dark: Option<&Path>,
    setup: &SpectraSetup,
) -> Result<CaptureSet> {
    if files.is_empty() {
        bail!("no spectrum given");
    }
    if !(setup.incident_deg.is_finite() && (0.0..90.0).contains(&setup.incident_deg)) {
        bail!(
            "incident angle {}° is outside [0°, 90°)",
            setup.incident_deg
        );
    }
    let spectra: Vec<Spectrum> = files
        .iter()
        .map(|f| read_spectrum(f))
        .collect::<Result<_>>()?;
    let reference = &spectra[0];
    for (s, f) in spectra.iter().zip(files).skip(1) {
        same_grid(s, reference, f, files[0])?;
    }
    let dark = dark
        .map(|d| -> Result<Spectrum> {
            let s = read_spectrum(d)?;
            same_grid(&s, reference, d, files[0])?;
            Ok(s)
        })
        .transpose()?;
    let nb = reference.wavelengths_nm.len();
    // Bands usable in every spectrum (and the dark one).
    let keep: Vec<bool> = (0..nb)
        .map(|b| {
            spectra.iter().all(|s| s.values[b].is_finite())
                && dark.as_ref().is_none_or(|d| d.values[b].is_finite())
        })
        .collect();
    let kept = keep.iter().filter(|&&k| k).count();
    if kept < 3 {
        bail!("fewer than 3 wavelengths are finite in every spectrum");
    }
    let mut invalid = InvalidCounts::default();
    for s in &spectra {
        invalid.non_finite += s.values.iter().filter(|v| !v.is_finite()).count() as u64;
    }
    let mut reflectance = Vec::with_capacity(spectra.len() * kept);
    for s in &spectra {
        for b in (0..nb).filter(|&b| keep[b]) {
            let d = dark.as_ref().map_or(0.0, |d| d.values[b]);
            reflectance.push((s.values[b] - d) as f32);
        }
    }
    let wavelengths_nm: Vec<f64> = (0..nb)
        .filter(|&b| keep[b])
        .map(|b| reference.wavelengths_nm[b])
        .collect();
    Ok(CaptureSet {
        polarization: setup.polarization,
        radiometry: setup.radiometry,
        film_model: None,
        pixel_names: Some(files.iter().map(|f| f.display().to_string()).collect()),
        ambient_ior: setup.ambient_ior,
        substrate_ior: setup
            .substrate_ior
            .clone()
            .unwrap_or_else(|| Ior::real(setup.ambient_ior)),
        wavelengths_nm,
        fwhm_nm: None,
        width: spectra.len(),
        height: 1,
        angles: vec![AngleCapture::from_bip(
            setup.incident_deg,
            reflectance,
            kept,
        )],
        invalid,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_csv_and_xy_with_header() {
        let s = parse_spectrum(
            "wavelength,intensity\n400,0.1\n401;0.2\n402\t0.3\n",
            "a.csv",
        )
        .unwrap();
        assert_eq!(s.wavelengths_nm, vec![400.0, 401.0, 402.0]);
        assert_eq!(s.values, vec![0.1, 0.2, 0.3]);
        let nan = parse_spectrum("400 nan\n401 1\n402 2\n", "b.xy").unwrap();
        assert!(nan.values[0].is_nan());
    }

    #[test]
    fn bad_files_name_file_and_line() {
        let e = parse_spectrum("400,1\n401,x\n402,1\n", "s.xy").unwrap_err();
        assert!(format!("{e:#}").contains("s.xy:2"), "{e:#}");
        let e = parse_spectrum("400,1\n402,1\n401,1\n", "s.xy").unwrap_err();
        assert!(format!("{e:#}").contains("s.xy:3") && format!("{e:#}").contains("increase"));
        let e = parse_spectrum("400,1\n400,1\n401,1\n", "s.xy").unwrap_err();
        assert!(format!("{e:#}").contains("duplicate"), "{e:#}");
        let e = parse_spectrum("400,1\n", "s.xy").unwrap_err();
        assert!(format!("{e:#}").contains("at least 3"), "{e:#}");
    }

    #[test]
    fn spectra_become_pixels_and_mismatches_are_errors() {
        let dir = std::env::temp_dir().join(format!("thinfilm-spectra-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, text: &str| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        let a = write("a.xy", "400,1\n410,nan\n420,3\n430,4\n");
        let b = write("b.xy", "400,2\n410,2\n420,2\n430,2\n");
        let dark = write("void.xy", "400,0.5\n410,0.5\n420,0.5\n430,0.5\n");
        let short = write("c.xy", "400,2\n410,2\n420,2\n");
        let setup = SpectraSetup {
            incident_deg: 0.0,
            ambient_ior: 1.0,
            substrate_ior: None,
            polarization: Polarization::S,
            radiometry: Radiometry::Relative,
        };
        let set = load_spectra(&[&a, &b], Some(&dark), &setup).unwrap();
        assert_eq!((set.width, set.height, set.bands()), (2, 1, 3));
        assert_eq!(set.wavelengths_nm, vec![400.0, 420.0, 430.0]);
        assert_eq!(set.invalid.non_finite, 1);
        assert_eq!(
            set.angles[0].reflectance,
            vec![0.5, 2.5, 3.5, 1.5, 1.5, 1.5]
        );
        assert_eq!(set.substrate_ior.at(550.0).re, 1.0);
        let e = load_spectra(&[&a, &short], None, &setup).unwrap_err();
        assert!(format!("{e:#}").contains("c.xy"), "{e:#}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
