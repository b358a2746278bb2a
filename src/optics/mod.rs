//! Thin-film optics: complex Fresnel amplitudes, the Airy single film, transfer-matrix
//! stacks and a dispersion library. Knows nothing of pixels or rays.
//!
//! Sign conventions follow Born & Wolf and the `tmm` package: a complex index is
//! `n + ik` with `k ≥ 0` for absorption (time dependence `e^{-iωt}`), and the forward
//! wave in every layer is chosen with `Im(n cosθ) ≥ 0` (decaying, or propagating forward).

pub mod coating;
pub mod dispersion;
pub mod film;
pub mod film_f32;
pub mod fresnel;
pub mod gltf_iridescence;
pub mod ior;
mod lanes;
pub mod stack;

pub use coating::Coating;
pub use film::{FilmResponse, ThinFilm};
pub use ior::Ior;
pub use num_complex::Complex64;
pub use stack::{Coherence, Layer, Stack};

/// Why an optical computation was refused (never a NaN instead).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpticsError {
    #[error("thickness must be finite and ≥ 0 nm, got {0}")]
    BadThickness(f64),
    #[error("wavelength must be finite and > 0 nm, got {0}")]
    BadWavelength(f64),
    #[error("incident angle must be finite and in [0°, 90°), got {0}°")]
    BadAngle(f64),
    #[error("refractive index must be finite with n > 0 and k ≥ 0, got {0}")]
    BadIndex(String),
}
