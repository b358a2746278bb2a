//! RGB → spectrum upsampling as Mitsuba 3 does it: Jakob & Hanika 2019 sigmoid polynomials
//! looked up in a 3-D coefficient table for sRGB.

/// f(λ) = S(c0 λ² + c1 λ + c2), S(x) = ½ + x / (2 √(1 + x²)), λ in nm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbSigmoidPolynomial {
    pub c: [f32; 3],
}

impl RgbSigmoidPolynomial {
    pub fn eval(&self, lambda_nm: f32) -> f32 {
        let x = (self.c[0] * lambda_nm + self.c[1]) * lambda_nm + self.c[2];
        if x.is_infinite() {
            return if x > 0.0 { 1.0 } else { 0.0 };
        }
        0.5 + x / (2.0 * (1.0 + x * x).sqrt())
    }
}

/// Upsample a linear sRGB reflectance (components clamped to [0, 1]).
pub fn srgb_reflectance(rgb: [f32; 3]) -> RgbSigmoidPolynomial {
    let _ = rgb;
    todo!("foundation: rgb2spec table")
}

/// An RGB emitter's spectrum as Mitsuba's `srgb_d65`: scale = 2·max, polynomial of rgb/scale,
/// times D65 normalised so that RGB (1,1,1) renders as (1,1,1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbIlluminantSpectrum {
    pub scale: f32,
    pub poly: RgbSigmoidPolynomial,
}

impl RgbIlluminantSpectrum {
    pub fn new(rgb: [f32; 3]) -> Self {
        let _ = rgb;
        todo!("foundation: rgb2spec table")
    }
    pub fn eval(&self, lambda_nm: f32) -> f32 {
        let _ = lambda_nm;
        todo!("foundation: rgb2spec table")
    }
}

/// A non-negative RGB quantity that may exceed 1 (e.g. texture values > 1): scale = 2·max,
/// polynomial of rgb/scale, no illuminant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbUnboundedSpectrum {
    pub scale: f32,
    pub poly: RgbSigmoidPolynomial,
}
