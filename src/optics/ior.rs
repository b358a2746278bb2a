//! Refractive index specifications: a number, a complex `n+ki`, or a material name.

use super::dispersion::{self, Material};
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
}
