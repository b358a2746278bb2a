//! Dispersion library: n(λ), k(λ) of named materials (to be filled by the optics work).

use num_complex::Complex64;

/// A named optical material.
#[derive(Debug, PartialEq)]
pub struct Material {
    pub name: &'static str,
    pub n_constant: f64,
}

impl Material {
    /// `n + ik` at `lambda_nm`.
    pub fn nk(&self, _lambda_nm: f64) -> Complex64 {
        Complex64::new(self.n_constant, 0.0)
    }
}

static MATERIALS: &[Material] = &[];

/// Looks a material up by name (case-insensitive).
pub fn lookup(name: &str) -> Option<&'static Material> {
    MATERIALS.iter().find(|m| m.name.eq_ignore_ascii_case(name))
}

/// Names of all built-in materials.
pub fn names() -> Vec<&'static str> {
    MATERIALS.iter().map(|m| m.name).collect()
}
