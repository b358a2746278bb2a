//! Colour science: CIE tables, hero wavelengths, sampled spectra, XYZ/RGB/Lab, ΔE and
//! RGB → spectrum upsampling (Jakob & Hanika 2019).
//!
//! CONTRACT (other modules code against these signatures; bodies filled by the foundation work).

pub mod color;
pub mod rgb2spec;
pub mod sampled;

pub use color::*;
pub use rgb2spec::{RgbIlluminantSpectrum, RgbSigmoidPolynomial};
pub use sampled::{SampledSpectrum, SampledWavelengths, N_SPECTRUM_SAMPLES};

/// Visible range over which everything is integrated and sampled, nm.
pub const LAMBDA_MIN_NM: f64 = 360.0;
pub const LAMBDA_MAX_NM: f64 = 830.0;
/// ∫ ȳ(λ) dλ over 360–830 nm at 1 nm (CIE 1931 2°).
pub const CIE_Y_INTEGRAL: f64 = 106.856895;

/// CIE 1931 2° colour-matching functions (x̄, ȳ, z̄) at `lambda_nm`, linearly interpolated
/// from the 1 nm table; zero outside 360–830 nm.
pub fn cie_xyz_cmf(lambda_nm: f64) -> [f64; 3] {
    let _ = lambda_nm;
    todo!("foundation: CIE tables from build.rs")
}

/// CIE standard illuminant D65 relative spectral power (100 at 560 nm), 0 outside 360–830 nm.
pub fn d65(lambda_nm: f64) -> f64 {
    let _ = lambda_nm;
    todo!("foundation: D65 table from build.rs")
}

/// Exact XYZ of a reflectance spectrum under D65, integrated at 1 nm over 360–830 nm,
/// normalised so a perfect reflector has Y = 1.
pub fn reflectance_xyz_d65(reflectance: impl Fn(f64) -> f64) -> [f64; 3] {
    let _ = reflectance;
    todo!("foundation")
}

/// XYZ (D65, Y = 1 for a perfect reflector) of a tabulated reflectance spectrum given at
/// `wavelengths_nm` (ascending), linearly interpolated, held constant beyond its ends.
pub fn tabulated_reflectance_xyz_d65(wavelengths_nm: &[f64], values: &[f64]) -> [f64; 3] {
    let _ = (wavelengths_nm, values);
    todo!("foundation")
}
