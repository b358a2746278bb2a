//! Colour science: CIE tables, hero wavelengths, sampled spectra, XYZ/RGB/Lab, ΔE and
//! RGB → spectrum upsampling (Jakob & Hanika 2019).
//!
//! The CIE 1931 2° colour-matching functions and the CIE D65 illuminant are tabulated at 1 nm
//! over 360–830 nm in `spectra/*.csv` (written by `spectra/generate.py` with colour-science) and
//! compiled into arrays by `build.rs`. Everything here integrates over that range on that grid,
//! so "exact" XYZ means the CIE's own 1 nm summation (CIE 15:2004 §7.1), which is also what
//! `colour.sd_to_XYZ` computes for a 1 nm spectrum.
//!
//! CONTRACT: other modules code against these signatures.

pub mod color;
pub mod rgb2spec;
mod rgb2spec_format;
pub mod sampled;
pub mod table_csv;

pub use color::*;
pub use rgb2spec::{
    srgb_reflectance, srgb_table, Rgb2SpecTable, RgbIlluminantSpectrum, RgbSigmoidPolynomial,
    RgbUnboundedSpectrum, RGB_ILLUMINANT_D65_NORM,
};
pub use sampled::{
    spectrum_at, spectrum_to_linear_srgb, spectrum_to_xyz, visible_wavelengths_pdf,
    SampledWavelengths, Spec,
};

mod tables {
    include!(concat!(env!("OUT_DIR"), "/cie_tables.rs"));
}

/// Visible range over which everything is integrated and sampled, nm.
pub const LAMBDA_MIN_NM: f64 = 360.0;
pub const LAMBDA_MAX_NM: f64 = 830.0;
/// Number of 1 nm table entries, 360..=830 nm.
pub const N_TABLE_NM: usize = 471;
/// ∫ ȳ(λ) dλ over 360–830 nm at 1 nm (CIE 1931 2°), summed from the compiled table
/// (106.856917; pbrt-v4 rounds the same sum to 106.856895).
pub const CIE_Y_INTEGRAL: f64 = tables::CIE_Y_SUM_1NM;

/// Linear interpolation position in the 1 nm tables: (index, fraction), or None outside
/// 360–830 nm (and for NaN).
#[inline]
fn table_pos(lambda_nm: f64) -> Option<(usize, f64)> {
    if !(LAMBDA_MIN_NM..=LAMBDA_MAX_NM).contains(&lambda_nm) {
        return None;
    }
    let x = lambda_nm - LAMBDA_MIN_NM;
    let i = (x.floor() as usize).min(N_TABLE_NM - 2);
    Some((i, x - i as f64))
}

/// CIE 1931 2° colour-matching functions (x̄, ȳ, z̄) at `lambda_nm`, linearly interpolated
/// from the 1 nm table; zero outside 360–830 nm.
pub fn cie_xyz_cmf(lambda_nm: f64) -> [f64; 3] {
    match table_pos(lambda_nm) {
        None => [0.0; 3],
        Some((i, t)) => {
            let (a, b) = (tables::CIE_CMF_1NM[i], tables::CIE_CMF_1NM[i + 1]);
            [
                a[0] + t * (b[0] - a[0]),
                a[1] + t * (b[1] - a[1]),
                a[2] + t * (b[2] - a[2]),
            ]
        }
    }
}

/// CIE standard illuminant D65 relative spectral power (100 at 560 nm), 0 outside 360–830 nm.
pub fn d65(lambda_nm: f64) -> f64 {
    match table_pos(lambda_nm) {
        None => 0.0,
        Some((i, t)) => {
            let (a, b) = (tables::CIE_D65_1NM[i], tables::CIE_D65_1NM[i + 1]);
            a + t * (b - a)
        }
    }
}

/// Σ D65(λ)·ȳ(λ) over the 1 nm grid: the normalisation that gives a perfect reflector Y = 1.
fn d65_y_sum() -> f64 {
    tables::D65_Y_SUM_1NM
}

/// Exact XYZ of a reflectance spectrum under D65, integrated at 1 nm over 360–830 nm,
/// normalised so a perfect reflector has Y = 1 (CIE 15:2004 eq. 7.1–7.3 with k = 1/Σ S ȳ).
pub fn reflectance_xyz_d65(reflectance: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (i, (s, c)) in tables::CIE_D65_1NM
        .iter()
        .zip(tables::CIE_CMF_1NM.iter())
        .enumerate()
    {
        let r = reflectance(LAMBDA_MIN_NM + i as f64) * s;
        xyz[0] += r * c[0];
        xyz[1] += r * c[1];
        xyz[2] += r * c[2];
    }
    let k = 1.0 / d65_y_sum();
    xyz.map(|v| v * k)
}

/// XYZ of an emission spectrum (absolute units in, XYZ out) integrated at 1 nm over
/// 360–830 nm and divided by [`CIE_Y_INTEGRAL`], the convention of the renderer's film:
/// an emitter with Y = 1 here displays with luminance 1.
pub fn emission_xyz(radiance: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (i, c) in tables::CIE_CMF_1NM.iter().enumerate() {
        let l = radiance(LAMBDA_MIN_NM + i as f64);
        xyz[0] += l * c[0];
        xyz[1] += l * c[1];
        xyz[2] += l * c[2];
    }
    xyz.map(|v| v / CIE_Y_INTEGRAL)
}

/// Linear interpolation of a tabulated function at `x`, held constant beyond its ends.
/// `xs` must be ascending and as long as `ys`; empty tables give 0.
pub fn interp_clamped(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len().min(ys.len());
    if n == 0 {
        return 0.0;
    }
    if x <= xs[0] || n == 1 {
        return ys[0];
    }
    if x >= xs[n - 1] {
        return ys[n - 1];
    }
    // First index with xs[j] > x; x lies in [xs[j-1], xs[j]).
    let j = xs[..n].partition_point(|&v| v <= x);
    let (x0, x1, y0, y1) = (xs[j - 1], xs[j], ys[j - 1], ys[j]);
    if x1 == x0 {
        return y1;
    }
    y0 + (x - x0) / (x1 - x0) * (y1 - y0)
}

/// XYZ (D65, Y = 1 for a perfect reflector) of a tabulated reflectance spectrum given at
/// `wavelengths_nm` (ascending), linearly interpolated, held constant beyond its ends.
pub fn tabulated_reflectance_xyz_d65(wavelengths_nm: &[f64], values: &[f64]) -> [f64; 3] {
    reflectance_xyz_d65(|l| interp_clamped(wavelengths_nm, values, l))
}
