//! The film index the estimator fits: a constant n, or Cauchy's n(λ) = A + B/λ² (+ C/λ⁴),
//! λ in nm (the same convention as the `cauchy:A,B[,C]` index strings of
//! [`crate::optics::Ior`]).
//!
//! The fit is parameterised around 550 nm so that the first parameter *is* the reported
//! `film_ior` and the others are small and well scaled:
//!
//!   n(λ) = p0 + p1 ((550/λ)² − 1) + p2 ((550/λ)⁴ − 1),
//!
//! i.e. A = p0 − p1 − p2, B = p1 · 550², C = p2 · 550⁴.

use crate::optics::Ior;

/// Reference wavelength of the reported index, nm.
pub const REFERENCE_NM: f64 = 550.0;

/// How the film index depends on wavelength.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum FilmModelKind {
    /// One index at every wavelength.
    Constant,
    /// n(λ) = A + B/λ² (λ in nm).
    Cauchy,
    /// n(λ) = A + B/λ² + C/λ⁴ (λ in nm).
    Cauchy3,
}

impl FilmModelKind {
    /// Number of fitted coefficients.
    pub fn parameters(self) -> usize {
        match self {
            FilmModelKind::Constant => 1,
            FilmModelKind::Cauchy => 2,
            FilmModelKind::Cauchy3 => 3,
        }
    }
}

impl std::fmt::Display for FilmModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FilmModelKind::Constant => "constant",
            FilmModelKind::Cauchy => "cauchy",
            FilmModelKind::Cauchy3 => "cauchy3",
        })
    }
}

impl std::str::FromStr for FilmModelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "constant" => Ok(FilmModelKind::Constant),
            "cauchy" => Ok(FilmModelKind::Cauchy),
            "cauchy3" => Ok(FilmModelKind::Cauchy3),
            other => Err(format!(
                "unknown film model '{other}' (expected constant, cauchy or cauchy3)"
            )),
        }
    }
}

/// A film index: fitted (constant or Cauchy, see the module doc) or given by the user as
/// any [`Ior`] (then it is not fitted).
#[derive(Debug, Clone, PartialEq)]
pub enum FilmIndex {
    /// Fitted parameters `p` of `kind` (p0 = n(550 nm)).
    Fitted { kind: FilmModelKind, p: Vec<f64> },
    /// Known index (real part used; the film must not absorb).
    Known(Ior),
}

impl FilmIndex {
    pub fn constant(n: f64) -> Self {
        FilmIndex::Fitted {
            kind: FilmModelKind::Constant,
            p: vec![n],
        }
    }

    /// Basis function of parameter `i` at `lambda_nm` (∂n/∂p_i).
    #[inline]
    pub fn basis(i: usize, lambda_nm: f64) -> f64 {
        let u = (REFERENCE_NM / lambda_nm).powi(2);
        match i {
            0 => 1.0,
            1 => u - 1.0,
            _ => u * u - 1.0,
        }
    }

    /// Real index at `lambda_nm`.
    #[inline]
    pub fn at(&self, lambda_nm: f64) -> f64 {
        match self {
            FilmIndex::Fitted { p, .. } => p
                .iter()
                .enumerate()
                .map(|(i, v)| v * Self::basis(i, lambda_nm))
                .sum(),
            FilmIndex::Known(ior) => ior.at(lambda_nm).re,
        }
    }

    /// The reported `film_ior`: n at 550 nm.
    pub fn n550(&self) -> f64 {
        self.at(REFERENCE_NM)
    }

    pub fn kind(&self) -> Option<FilmModelKind> {
        match self {
            FilmIndex::Fitted { kind, .. } => Some(*kind),
            FilmIndex::Known(_) => None,
        }
    }

    /// Fitted parameters (empty for a known index).
    pub fn params(&self) -> &[f64] {
        match self {
            FilmIndex::Fitted { p, .. } => p,
            FilmIndex::Known(_) => &[],
        }
    }

    /// The same model with parameters `p`.
    pub fn with_params(&self, p: &[f64]) -> Self {
        match self {
            FilmIndex::Fitted { kind, .. } => FilmIndex::Fitted {
                kind: *kind,
                p: p.to_vec(),
            },
            known => known.clone(),
        }
    }

    /// This index as `kind` (extra coefficients start at 0, dropped ones are discarded).
    pub fn as_kind(&self, kind: FilmModelKind) -> Self {
        let mut p = self.params().to_vec();
        if p.is_empty() {
            p.push(self.n550());
        }
        p.resize(kind.parameters(), 0.0);
        FilmIndex::Fitted { kind, p }
    }

    /// Cauchy coefficients (A, B nm², C nm⁴) of a fitted index.
    pub fn cauchy_coefficients(&self) -> Option<(f64, f64, f64)> {
        let p = self.params();
        if p.is_empty() {
            return None;
        }
        let p1 = p.get(1).copied().unwrap_or(0.0);
        let p2 = p.get(2).copied().unwrap_or(0.0);
        Some((
            p[0] - p1 - p2,
            p1 * REFERENCE_NM.powi(2),
            p2 * REFERENCE_NM.powi(4),
        ))
    }

    /// The index as an [`Ior`] for materials and scenes: a number for a constant fit,
    /// `cauchy:A,B[,C]` (λ in nm) for a dispersive one.
    pub fn to_ior(&self) -> Ior {
        match self {
            FilmIndex::Known(ior) => ior.clone(),
            FilmIndex::Fitted {
                kind: FilmModelKind::Constant,
                p,
            } => Ior::real(p[0]),
            FilmIndex::Fitted { .. } => self
                .spec()
                .parse()
                .unwrap_or_else(|_| Ior::real(self.n550())),
        }
    }

    /// The index string (`1.3700`, `cauchy:2.2870,25000`, or the user's own).
    pub fn spec(&self) -> String {
        match self {
            FilmIndex::Known(ior) => ior.to_string(),
            FilmIndex::Fitted {
                kind: FilmModelKind::Constant,
                p,
            } => format!("{:.6}", p[0]),
            FilmIndex::Fitted { kind, .. } => {
                let (a, b, c) = self.cauchy_coefficients().unwrap_or_default();
                if *kind == FilmModelKind::Cauchy3 {
                    format!("cauchy:{a:.6},{b:.3},{c:.1}")
                } else {
                    format!("cauchy:{a:.6},{b:.3}")
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cauchy_parameterisation_round_trips() {
        // The optifik soap-film index: n = 1.324188 + 3102.06/λ².
        let (a, b) = (1.324188, 3102.060378);
        let n550 = a + b / 550f64.powi(2);
        let f = FilmIndex::Fitted {
            kind: FilmModelKind::Cauchy,
            p: vec![n550, b / 550f64.powi(2)],
        };
        for l in [400.0, 550.0, 700.0] {
            assert!((f.at(l) - (a + b / (l * l))).abs() < 1e-12);
        }
        let (a2, b2, c2) = f.cauchy_coefficients().unwrap();
        assert!((a2 - a).abs() < 1e-12 && (b2 - b).abs() < 1e-9 && c2 == 0.0);
        let ior = f.to_ior();
        assert!((ior.at(480.0).re - (a + b / 480f64.powi(2))).abs() < 1e-5);
        assert_eq!(FilmIndex::constant(1.37).to_ior(), Ior::real(1.37));
        let c3 = f.as_kind(FilmModelKind::Cauchy3);
        assert_eq!(c3.params().len(), 3);
        assert!((c3.at(430.0) - f.at(430.0)).abs() < 1e-12);
        assert!(c3.to_ior().at(430.0).re - f.at(430.0) < 1e-5);
    }
}
