//! RGB → spectrum upsampling as Mitsuba 3 does it: Jakob & Hanika 2019 sigmoid polynomials
//! looked up in a 3-D coefficient table for sRGB.
//!
//! The table `spectra/srgb_rgb2spec_64.coeff` ("SPEC" format of mitsuba-renderer/rgb2spec:
//! magic, u32 resolution, `res` f32 z-nodes, then `[3][res][res][res][3]` f32 coefficients for
//! λ in nm) is made by `tools/rgb2spec` — `rgb2spec_opt`'s algorithm at Mitsuba 3's resolution
//! (64), fitted against this module's own 1 nm CIE/D65 quadrature and sRGB matrix with
//! Levenberg–Marquardt (see tools/rgb2spec/README.md for timings and the comparison with
//! Mitsuba's table). It is embedded with `include_bytes!` (4-byte aligned); `build.rs`
//! validates its header, size and values, and on little-endian targets it is read in place.
//!
//! Lookup follows `rgb2spec_fetch` (Mitsuba 3, `ext/rgb2spec/rgb2spec.c`): clamp to [0,1],
//! pick the largest component (ties go to the later channel), z = that component on the
//! smoothstep² node grid, x/y = the next two components over z, trilinear interpolation of the
//! three coefficients. Two deliberate additions, both exact rather than fitted:
//! black → (0, 0, −∞) and white → (0, 0, +∞) as Mitsuba's `srgb_model_fetch` does, and any
//! other grey r = g = b → the constant spectrum r via c = (0, 0, (r−½)/√(r(1−r))) as pbrt-v4
//! does (S(c) = r exactly).
//!
//! Emitters: [`RgbIlluminantSpectrum`] is Mitsuba's `srgb_d65` — scale = 2·max(rgb), the
//! polynomial of rgb/scale (so its largest component is ½, which keeps the sigmoid smooth),
//! times D65 divided by [`RGB_ILLUMINANT_D65_NORM`].
//!
//! ## The D65 normalisation constant
//! Our film divides by [`super::CIE_Y_INTEGRAL`] = Σȳ = 106.857 (CIE 1931 2°, 1 nm). For RGB
//! (1,1,1) to render as (1,1,1) the emitted spectrum k·D65 must have
//! Σ ȳ·k·D65 / Σȳ = 1, so k = 1/[`RGB_ILLUMINANT_D65_NORM`] with
//! `RGB_ILLUMINANT_D65_NORM = Σ ȳ·D65 / Σ ȳ = 10567.08 / 106.857 = 98.890` (from the compiled
//! tables). Mitsuba uses 98.9974, which pairs with its film's Σȳ = 106.75 (its own 5 nm CMF
//! table); with our film that constant would render white as 0.99891. We keep Mitsuba's intent
//! (white emitter → white pixel) rather than its digits; the two agree within 0.11 %.

use super::Spec;
use std::borrow::Cow;
use std::sync::OnceLock;

/// Σ ȳ·D65 / Σ ȳ over the 1 nm tables: D65 divided by this has luminance 1 under the film's
/// 1/[`super::CIE_Y_INTEGRAL`] normalisation (see the module docs).
pub const RGB_ILLUMINANT_D65_NORM: f64 = super::tables::D65_Y_SUM_1NM / super::CIE_Y_INTEGRAL;

/// Bytes at an address that is a multiple of 4, so that the embedded table's f32 data can be
/// read where it lies.
#[repr(C, align(4))]
struct Aligned4<B: ?Sized>(B);

/// The embedded sRGB table (validated by build.rs: header, size, finite coefficients,
/// increasing z-nodes).
static SRGB_COEFF: &Aligned4<[u8]> = &Aligned4(*include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/spectra/srgb_rgb2spec_64.coeff"
)));

/// f(λ) = S(c0 λ² + c1 λ + c2), S(x) = ½ + x / (2 √(1 + x²)), λ in nm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbSigmoidPolynomial {
    pub c: [f32; 3],
}

impl RgbSigmoidPolynomial {
    /// The constant spectrum 0 (black) — c2 = −∞.
    pub const BLACK: RgbSigmoidPolynomial = RgbSigmoidPolynomial {
        c: [0.0, 0.0, f32::NEG_INFINITY],
    };
    /// The constant spectrum 1 (white) — c2 = +∞.
    pub const WHITE: RgbSigmoidPolynomial = RgbSigmoidPolynomial {
        c: [0.0, 0.0, f32::INFINITY],
    };

    pub fn eval(&self, lambda_nm: f32) -> f32 {
        let x = (self.c[0] * lambda_nm + self.c[1]) * lambda_nm + self.c[2];
        if x.is_infinite() {
            // S(±∞) = 1 or 0 (x/√(1+x²) would be ∞/∞ = NaN).
            return if x > 0.0 { 1.0 } else { 0.0 };
        }
        0.5 + x / (2.0 * (1.0 + x * x).sqrt())
    }

    /// [`Self::eval`] at four wavelengths at once (SIMD lanes). Same operations in the same
    /// order per lane (IEEE `sqrt` and `/` are exact in both forms), so the result is
    /// bit-identical to four scalar calls: the four wavelengths' chains of a square root and
    /// a division overlap instead of running one after another. Infinite or NaN polynomial
    /// values (black/white coefficients) take the scalar path, which maps S(±∞) to 1 or 0.
    #[inline]
    pub fn eval4(&self, lambda: Spec) -> Spec {
        let [c0, c1, c2] = self.c;
        let x = (Spec::splat(c0) * lambda + Spec::splat(c1)) * lambda + Spec::splat(c2);
        if !x.is_finite() {
            return Spec::from_array(lambda.to_array().map(|l| self.eval(l)));
        }
        Spec::splat(0.5) + x / (Spec::splat(2.0) * (Spec::ONE + x * x).sqrt())
    }
}

/// The parsed coefficient table.
#[derive(Debug)]
pub struct Rgb2SpecTable {
    res: usize,
    /// z-node positions (smoothstep(smoothstep(k/(res−1)))).
    scale: Cow<'static, [f32]>,
    /// `[3][res][res][res][3]`: the embedded table's read where it lies in the binary
    /// (9.4 MB: copying and checking it took ~13 ms of every render's set-up, and only the
    /// pages a scene's colours touch are ever read), a parsed file's owned.
    data: Cow<'static, [f32]>,
}

impl Rgb2SpecTable {
    /// Parse the "SPEC" format (trailing bytes, e.g. newer Mitsuba's forward-model block,
    /// are ignored).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
        let res = super::rgb2spec_format::check_spec(bytes)?;
        let floats = |from: usize, n: usize| -> Vec<f32> {
            bytes[from..from + 4 * n]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        Ok(Rgb2SpecTable {
            res,
            scale: Cow::Owned(floats(8, res)),
            data: Cow::Owned(floats(8 + 4 * res, 9 * res * res * res)),
        })
    }

    /// A table whose values build.rs has checked, read in place where the target's byte
    /// order is the file's (little-endian) and parsed into a copy elsewhere.
    fn from_checked_static(bytes: &'static [u8]) -> Result<Self, String> {
        let res = super::rgb2spec_format::spec_resolution(bytes)?;
        let n_data = 9 * res * res * res;
        let floats = &bytes[8..8 + 4 * (res + n_data)];
        match bytemuck::try_cast_slice::<u8, f32>(floats) {
            Ok(f) if cfg!(target_endian = "little") => Ok(Rgb2SpecTable {
                res,
                scale: Cow::Borrowed(&f[..res]),
                data: Cow::Borrowed(&f[res..]),
            }),
            _ => Self::from_bytes(bytes),
        }
    }

    pub fn resolution(&self) -> usize {
        self.res
    }

    /// Trilinear table lookup of `rgb` (clamped to [0,1]), exactly as `rgb2spec_fetch`.
    /// Returns coefficients for λ in nm. Black (all zero) gives [`RgbSigmoidPolynomial::BLACK`].
    pub fn fetch(&self, rgb: [f32; 3]) -> RgbSigmoidPolynomial {
        let rgb = rgb.map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) });
        let mut i = 0;
        for j in 1..3 {
            if rgb[j] >= rgb[i] {
                i = j;
            }
        }
        let z = rgb[i];
        if z <= 0.0 {
            return RgbSigmoidPolynomial::BLACK;
        }
        let res = self.res;
        let s = (res - 1) as f32 / z;
        let x = rgb[(i + 1) % 3] * s;
        let y = rgb[(i + 2) % 3] * s;
        let xi = (x as usize).min(res - 2);
        let yi = (y as usize).min(res - 2);
        // Largest node index with scale[zi] <= z (clamped so zi + 1 is valid).
        let zi = self.scale.partition_point(|&v| v <= z).clamp(1, res - 1) - 1;
        let x1 = x - xi as f32;
        let y1 = y - yi as f32;
        let z1 = (z - self.scale[zi]) / (self.scale[zi + 1] - self.scale[zi]);
        let (x0, y0, z0) = (1.0 - x1, 1.0 - y1, 1.0 - z1);
        let dx = 3;
        let dy = 3 * res;
        let dz = 3 * res * res;
        let base = (((i * res + zi) * res + yi) * res + xi) * 3;
        let d = &self.data;
        let mut c = [0.0f32; 3];
        for (k, ck) in c.iter_mut().enumerate() {
            let o = base + k;
            *ck = ((d[o] * x0 + d[o + dx] * x1) * y0 + (d[o + dy] * x0 + d[o + dy + dx] * x1) * y1)
                * z0
                + ((d[o + dz] * x0 + d[o + dz + dx] * x1) * y0
                    + (d[o + dz + dy] * x0 + d[o + dz + dy + dx] * x1) * y1)
                    * z1;
        }
        RgbSigmoidPolynomial { c }
    }
}

/// The embedded sRGB table, parsed on first use.
pub fn srgb_table() -> &'static Rgb2SpecTable {
    static TABLE: OnceLock<Rgb2SpecTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        // build.rs validated the table, so failure here means a corrupted build.
        Rgb2SpecTable::from_checked_static(&SRGB_COEFF.0)
            .unwrap_or_else(|e| panic!("embedded spectra/srgb_rgb2spec_64.coeff: {e}"))
    })
}

/// Clamp to [0,1]; NaN → 0.
fn sanitize_unit(rgb: [f32; 3]) -> [f32; 3] {
    rgb.map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) })
}

/// Non-negative and finite; NaN, negative and infinite components → 0.
fn sanitize_unbounded(rgb: [f32; 3]) -> [f32; 3] {
    rgb.map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 })
}

/// Upsample a linear sRGB reflectance (components clamped to [0, 1]; NaN → 0).
pub fn srgb_reflectance(rgb: [f32; 3]) -> RgbSigmoidPolynomial {
    let rgb = sanitize_unit(rgb);
    if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
        let r = rgb[0];
        return if r <= 0.0 {
            RgbSigmoidPolynomial::BLACK
        } else if r >= 1.0 {
            RgbSigmoidPolynomial::WHITE
        } else {
            // S((r − ½)/√(r(1−r))) = r exactly (pbrt-v4's grey shortcut).
            RgbSigmoidPolynomial {
                c: [0.0, 0.0, (r - 0.5) / (r * (1.0 - r)).sqrt()],
            }
        };
    }
    srgb_table().fetch(rgb)
}

/// Split a non-negative RGB into scale = 2·max and the polynomial of rgb/scale.
fn scaled_poly(rgb: [f32; 3]) -> (f32, RgbSigmoidPolynomial) {
    let rgb = sanitize_unbounded(rgb);
    let m = rgb[0].max(rgb[1]).max(rgb[2]);
    if m <= 0.0 {
        return (0.0, RgbSigmoidPolynomial::BLACK);
    }
    let scale = 2.0 * m;
    (scale, srgb_reflectance(rgb.map(|v| v / scale)))
}

/// An RGB quantity as a spectrum: scale = 2·max, the sigmoid polynomial of rgb/scale, and —
/// for an emitter (`ILLUMINANT`) — times D65 normalised so that RGB (1,1,1) renders as
/// (1,1,1). Negative, NaN and infinite components are treated as 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbScaledSpectrum<const ILLUMINANT: bool> {
    pub scale: f32,
    pub poly: RgbSigmoidPolynomial,
}

/// An RGB emitter's spectrum as Mitsuba's `srgb_d65`.
pub type RgbIlluminantSpectrum = RgbScaledSpectrum<true>;

/// A non-negative RGB quantity that may exceed 1 (e.g. texture values > 1), no illuminant
/// (pbrt-v4's `RGBUnboundedSpectrum`).
pub type RgbUnboundedSpectrum = RgbScaledSpectrum<false>;

impl<const ILLUMINANT: bool> RgbScaledSpectrum<ILLUMINANT> {
    pub fn new(rgb: [f32; 3]) -> Self {
        let (scale, poly) = scaled_poly(rgb);
        Self { scale, poly }
    }

    pub fn eval(&self, lambda_nm: f32) -> f32 {
        if self.scale == 0.0 {
            return 0.0;
        }
        let v = self.scale * self.poly.eval(lambda_nm);
        if ILLUMINANT {
            v * (super::d65(lambda_nm as f64) / RGB_ILLUMINANT_D65_NORM) as f32
        } else {
            v
        }
    }

    /// [`Self::eval`] at four wavelengths at once: the sigmoid in SIMD lanes
    /// ([`RgbSigmoidPolynomial::eval4`]), the same operations per lane, bit-identical.
    #[inline]
    pub fn eval4(&self, lambda: Spec) -> Spec {
        if self.scale == 0.0 {
            return Spec::ZERO;
        }
        let v = Spec::splat(self.scale) * self.poly.eval4(lambda);
        if ILLUMINANT {
            let d65 = lambda
                .to_array()
                .map(|l| (super::d65(l as f64) / RGB_ILLUMINANT_D65_NORM) as f32);
            v * Spec::from_array(d65)
        } else {
            v
        }
    }
}

#[cfg(test)]
mod simd_tests {
    use super::*;

    /// The embedded table read in place is the table `from_bytes` parses and checks, value
    /// for value (build.rs's checks stand in for the runtime ones only if they agree).
    #[test]
    fn embedded_table_in_place_equals_the_parsed_copy() {
        let parsed = Rgb2SpecTable::from_bytes(&SRGB_COEFF.0).unwrap();
        let table = srgb_table();
        assert_eq!(table.res, parsed.res);
        assert!(matches!(table.data, Cow::Borrowed(_)) || cfg!(target_endian = "big"));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&table.scale), bits(&parsed.scale));
        assert_eq!(bits(&table.data), bits(&parsed.data));
    }

    /// Polynomials covering black, white, greys, saturated and large-argument sigmoids.
    fn polys() -> Vec<RgbSigmoidPolynomial> {
        let mut polys = vec![RgbSigmoidPolynomial::BLACK, RgbSigmoidPolynomial::WHITE];
        for rgb in [
            [0.9, 0.1, 0.2],
            [0.0, 0.5, 1.0],
            [0.3, 0.3, 0.31],
            [1.0, 0.0, 0.0],
            [0.75, 0.45, 0.2],
            [0.5, 0.5, 0.5],
        ] {
            polys.push(srgb_reflectance(rgb));
            polys.push(RgbIlluminantSpectrum::new(rgb).poly);
        }
        polys.push(RgbSigmoidPolynomial {
            c: [1e-3, -0.9, 180.0],
        });
        polys.push(RgbSigmoidPolynomial {
            c: [f32::NAN, 0.0, 0.0],
        });
        polys
    }

    const LAMBDAS: [[f32; 4]; 3] = [
        [360.0, 451.3, 612.9, 830.0],
        [555.5, 400.25, 700.125, 380.0],
        [0.0, 1e4, 589.3, 486.1],
    ];

    #[test]
    fn sigmoid_eval4_is_bit_identical_to_scalar() {
        for poly in polys() {
            for l in LAMBDAS {
                let fast = poly.eval4(Spec::from_array(l)).to_array();
                let scalar = l.map(|l| poly.eval(l));
                assert_eq!(fast.map(f32::to_bits), scalar.map(f32::to_bits), "{poly:?}");
            }
        }
    }

    #[test]
    fn scaled_spectrum_eval4_is_bit_identical_to_scalar() {
        for rgb in [
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.75, 0.45, 0.2],
            [3.0, 0.5, 0.0],
            [0.2, 7.5, 1.25],
        ] {
            let (r, e) = (
                RgbUnboundedSpectrum::new(rgb),
                RgbIlluminantSpectrum::new(rgb),
            );
            for l in LAMBDAS {
                let fast = [r.eval4(Spec::from_array(l)), e.eval4(Spec::from_array(l))];
                let scalar = [l.map(|l| r.eval(l)), l.map(|l| e.eval(l))];
                for (f, s) in fast.iter().zip(scalar) {
                    assert_eq!(
                        f.to_array().map(f32::to_bits),
                        s.map(f32::to_bits),
                        "{rgb:?}"
                    );
                }
            }
        }
    }
}
