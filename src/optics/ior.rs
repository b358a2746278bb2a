//! Refractive index specifications: a number, a complex `n+ki`, or a material name.

use super::dispersion::{self, Material, Model};
use num_complex::Complex64;
use std::fmt;
use std::str::FromStr;

/// A (possibly wavelength-dependent, possibly complex) refractive index.
#[derive(Debug, Clone, PartialEq)]
pub enum Ior {
    /// Same `n + ik` at every wavelength.
    Constant(Complex64),
    /// A named material from the dispersion library (`MgF2`, `BK7`, `Au`, …).
    Material(&'static Material),
}

impl Ior {
    pub fn real(n: f64) -> Self {
        Ior::Constant(Complex64::new(n, 0.0))
    }

    /// `n + ik` at `lambda_nm`.
    #[inline]
    pub fn at(&self, lambda_nm: f64) -> Complex64 {
        match self {
            Ior::Constant(c) => *c,
            Ior::Material(m) => m.nk(lambda_nm),
        }
    }

    /// `n + ik` at `N` wavelengths ([`Material::nk_lanes`]).
    #[inline]
    pub fn at_lanes<const N: usize>(&self, lambda_nm: [f64; N]) -> [Complex64; N] {
        match self {
            Ior::Constant(c) => [*c; N],
            Ior::Material(m) => m.nk_lanes(lambda_nm),
        }
    }

    /// True when the index depends on wavelength (so refraction splits hero wavelengths).
    pub fn is_dispersive(&self) -> bool {
        !matches!(self, Ior::Constant(_))
    }
}

impl fmt::Display for Ior {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ior::Constant(c) if c.im == 0.0 => write!(f, "{}", c.re),
            Ior::Constant(c) => write!(f, "{}+{}i", c.re, c.im),
            Ior::Material(m) => write!(f, "{}", m.name),
        }
    }
}

/// Parses `1.37`, `0.18+3.4i` (also `j`), or a material name (case-insensitive).
impl FromStr for Ior {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        if t.is_empty() {
            return Err("empty refractive index".into());
        }
        if let Some(m) = dispersion::lookup(t) {
            return Ok(Ior::Material(m));
        }
        if let Some(formula) = parse_formula(t)? {
            return Ok(formula);
        }
        let value = parse_complex(t).ok_or_else(|| {
            format!(
                "'{t}' is not a refractive index: expected a number (1.37), a complex n+ki (0.18+3.4i) \
                 or a material name ({})",
                dispersion::names().join(", ")
            )
        })?;
        if !(value.re.is_finite() && value.im.is_finite() && value.re > 0.0 && value.im >= 0.0) {
            return Err(format!("refractive index '{t}' must have n > 0 and k ≥ 0"));
        }
        Ok(Ior::Constant(value))
    }
}

/// Explicitly dispersive specifications (scene syntax, documented in scenes/README.md):
/// - `material:NAME` — a material of the dispersion library (e.g. `material:BK7`, to get the
///   Sellmeier N-BK7 where a bare `bk7` means Mitsuba's constant 1.5046);
/// - `cauchy:A,B[,C]` — n(λ) = A + B/λ² + C/λ⁴ with λ in nm, B in nm², C in nm⁴ (the form used
///   in graphics, e.g. BK7 ≈ `cauchy:1.5046,4200`);
/// - `sellmeier:B1,C1[,B2,C2,…]` — n² = 1 + Σ B_i λ²/(λ² − C_i) with λ in µm and C_i in µm²
///   (the Schott catalogue form; N-BK7 = `sellmeier:1.03961212,0.00600069867,0.231792344,0.0200179144,1.01046945,103.560653`).
///
/// Returns `Ok(None)` when `t` has none of these prefixes. A formula becomes a [`Material`]
/// leaked to obtain the `&'static` that [`Ior::Material`] holds (a few dozen bytes per formula
/// in a loaded scene, as for tabulated spectra in scene files).
fn parse_formula(t: &str) -> Result<Option<Ior>, String> {
    let Some((kind, rest)) = t.split_once(':') else {
        return Ok(None);
    };
    let kind_l = kind.trim().to_ascii_lowercase();
    if kind_l == "material" {
        return dispersion::lookup(rest)
            .map(|m| Some(Ior::Material(m)))
            .ok_or_else(|| {
                format!(
                    "unknown material '{}' in '{t}' (known: {})",
                    rest.trim(),
                    dispersion::names().join(", ")
                )
            });
    }
    if kind_l != "cauchy" && kind_l != "sellmeier" {
        return Ok(None);
    }
    let c: Vec<f64> = rest
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("'{t}': coefficients must be numbers ({e})"))?;
    if c.iter().any(|v| !v.is_finite()) {
        return Err(format!("'{t}': coefficients must be finite"));
    }
    let model = if kind_l == "cauchy" {
        if !(2..=3).contains(&c.len()) {
            return Err(format!("'{t}': cauchy needs A,B or A,B,C (λ in nm)"));
        }
        // nm² → µm² and nm⁴ → µm⁴ (the library's Cauchy is in µm).
        Model::Cauchy {
            a: c[0],
            b: c[1] * 1e-6,
            c: c.get(2).copied().unwrap_or(0.0) * 1e-12,
        }
    } else {
        if c.is_empty() || c.len() % 2 != 0 {
            return Err(format!(
                "'{t}': sellmeier needs pairs B1,C1[,B2,C2,…] (C in µm²)"
            ));
        }
        Model::Sellmeier {
            a: 1.0,
            terms: c.chunks_exact(2).map(|p| (p[0], p[1])).collect(),
        }
    };
    let material = Material {
        name: Box::leak(t.to_string().into_boxed_str()),
        aliases: Vec::new(),
        source: "formula in the scene file",
        valid_range_nm: (360.0, 830.0),
        model,
    };
    // Physical over the visible range (a pole inside it, or n ≤ 0, is a user error; the
    // Sellmeier model clamps n² < 0 to n = 0, caught here).
    for l in (360..=830).step_by(5) {
        let n = material.nk(l as f64);
        if !(n.re.is_finite() && n.re > 0.0) {
            return Err(format!(
                "'{t}' gives n = {} at {l} nm: not a refractive index over the visible range",
                n.re
            ));
        }
    }
    Ok(Some(Ior::Material(Box::leak(Box::new(material)))))
}

fn parse_complex(t: &str) -> Option<Complex64> {
    if let Ok(v) = t.parse::<f64>() {
        return Some(Complex64::new(v, 0.0));
    }
    let body = t.strip_suffix(['i', 'j'])?;
    // Split at the last sign that is not part of an exponent.
    let bytes = body.as_bytes();
    let split = (1..bytes.len()).rev().find(|&i| {
        (bytes[i] == b'+' || bytes[i] == b'-') && !matches!(bytes[i - 1], b'e' | b'E')
    })?;
    let re = body[..split].trim().parse::<f64>().ok()?;
    let im = body[split..].replace(' ', "").parse::<f64>().ok()?;
    Some(Complex64::new(re, im))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_numbers_and_complex() {
        assert_eq!("1.37".parse::<Ior>().unwrap(), Ior::real(1.37));
        assert_eq!(
            "0.18+3.4i".parse::<Ior>().unwrap(),
            Ior::Constant(Complex64::new(0.18, 3.4))
        );
        assert_eq!(
            "1e0+2e-1j".parse::<Ior>().unwrap(),
            Ior::Constant(Complex64::new(1.0, 0.2))
        );
        assert!("-1".parse::<Ior>().is_err());
        assert!("1.5-0.1i".parse::<Ior>().is_err());
        assert!("nonsense".parse::<Ior>().is_err());
        assert!("NaN".parse::<Ior>().is_err());
    }

    #[test]
    fn parses_dispersion_formulas() {
        let c: Ior = "cauchy:1.5046,4200".parse().unwrap();
        assert!(c.is_dispersive());
        // n(500 nm) = 1.5046 + 4200/500².
        assert!((c.at(500.0).re - (1.5046 + 4200.0 / 250_000.0)).abs() < 1e-12);
        let s: Ior =
            "sellmeier:1.03961212,0.00600069867,0.231792344,0.0200179144,1.01046945,103.560653"
                .parse()
                .unwrap();
        // Same formula as the library's N-BK7: n_d = 1.5168.
        assert!((s.at(587.6).re - 1.5168).abs() < 1e-4, "{}", s.at(587.6));
        let bk7: Ior = "material:BK7".parse().unwrap();
        assert!((bk7.at(587.6).re - s.at(587.6).re).abs() < 1e-9);
        // Errors name the problem, never panic.
        for bad in [
            "cauchy:1.5",
            "cauchy:a,b",
            "cauchy:-3,0",
            "sellmeier:1.0",
            "sellmeier:1.0,0.3", // pole at λ = 548 nm inside the visible range
            "material:unobtainium",
            "cauchy:1.5,inf",
        ] {
            assert!(bad.parse::<Ior>().is_err(), "{bad} accepted");
        }
    }
}
