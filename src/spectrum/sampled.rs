//! Hero-wavelength sampling (4 wavelengths per path) and 4-sample spectra ([`Spec`]).
//!
//! Wavelengths are importance-sampled over 360–830 nm with the pdf of pbrt-v4 / Mitsuba 3
//! (`SampleVisibleWavelengths`, Radziszewski et al. 2009):
//! p(λ) = 0.0039398042 / cosh²(0.0072 (λ − 538)), inverted in closed form as
//! λ = 538 − atanh(0.85691062 − 1.82750197 u) / 0.0072. One random number drives all four
//! wavelengths, rotated by k/4 (Wilkie et al. 2014, "Hero wavelength spectral sampling").

use super::{CIE_Y_INTEGRAL, LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// The 1 nm CIE tables in f32 for the renderer's per-sample lookups, one row per nm
/// (index = λ − 360): (x̄, ȳ, z̄, D65(λ) / [`super::RGB_ILLUMINANT_D65_NORM`]). One 16-byte
/// row holds everything a path needs at one wavelength, and f32 interpolation avoids the
/// f64 round trips of [`super::cie_xyz_cmf`] / [`super::d65`] (values agree to ~1e-7
/// relative; see `tests::f32_cie_table_matches_f64`). Built at compile time.
static CMF_D65_F32: [[f32; 4]; super::N_TABLE_NM] = {
    let (cmf, d65) = (&super::tables::CIE_CMF_1NM, &super::tables::CIE_D65_1NM);
    let mut out = [[0.0f32; 4]; super::N_TABLE_NM];
    let mut i = 0;
    while i < super::N_TABLE_NM {
        out[i] = [
            cmf[i][0] as f32,
            cmf[i][1] as f32,
            cmf[i][2] as f32,
            (d65[i] / super::RGB_ILLUMINANT_D65_NORM) as f32,
        ];
        i += 1;
    }
    out
};

/// Linear-sRGB matching functions per nm, (r̄, ḡ, b̄) = XYZ→sRGB · (x̄, ȳ, z̄) divided by
/// the Monte-Carlo normalisation N·∫ȳ: a sample's RGB is Σ_k rgb̄(λ_k)·L_k/p(λ_k) directly,
/// without the XYZ step and its f64 matrix product. The fourth column is D65 as in
/// [`CMF_D65_F32`], so one interpolated row serves both the film and the RGB illuminants.
static RGB_CMF_F32: [[f32; 4]; super::N_TABLE_NM] = {
    let cmf = &super::tables::CIE_CMF_1NM;
    let m = &super::XYZ_TO_SRGB;
    let norm = 1.0 / (N_SPECTRUM_SAMPLES as f64 * CIE_Y_INTEGRAL);
    let mut out = [[0.0f32; 4]; super::N_TABLE_NM];
    let mut i = 0;
    while i < super::N_TABLE_NM {
        let c = cmf[i];
        let mut r = 0;
        while r < 3 {
            out[i][r] = ((m[r][0] * c[0] + m[r][1] * c[1] + m[r][2] * c[2]) * norm) as f32;
            r += 1;
        }
        out[i][3] = (super::tables::CIE_D65_1NM[i] / super::RGB_ILLUMINANT_D65_NORM) as f32;
        i += 1;
    }
    out
};

/// Linear interpolation in a 1 nm f32 table; zero outside 360–830 nm (and for NaN).
#[inline]
fn lerp_table(table: &[[f32; 4]; super::N_TABLE_NM], lambda_nm: f32) -> glam::Vec4 {
    let x = lambda_nm - LAMBDA_MIN_NM as f32;
    let n = super::N_TABLE_NM;
    if !(x >= 0.0 && x <= (n - 1) as f32) {
        return glam::Vec4::ZERO;
    }
    // Through i32: f32 → usize is a slow saturating conversion on x86-64 (8 calls per sample).
    let i = (x as i32 as usize).min(n - 2);
    let t = x - i as f32;
    let (a, b) = (glam::Vec4::from(table[i]), glam::Vec4::from(table[i + 1]));
    a + (b - a) * t
}

/// (x̄, ȳ, z̄, D65/[`super::RGB_ILLUMINANT_D65_NORM`]) at `lambda_nm`, linearly interpolated
/// in f32 from the 1 nm tables; zero outside 360–830 nm (and for NaN).
#[inline]
pub fn cmf_d65_f32(lambda_nm: f32) -> [f32; 4] {
    lerp_table(&CMF_D65_F32, lambda_nm).to_array()
}

/// (r̄, ḡ, b̄, D65/[`super::RGB_ILLUMINANT_D65_NORM`]) at `lambda_nm`: the film's linear-sRGB
/// matching functions (as in [`spectrum_to_linear_srgb`]) and the D65 factor of
/// [`cmf_d65_f32`], bit for bit, from one interpolated row.
#[inline]
pub fn rgb_cmf_d65_f32(lambda_nm: f32) -> [f32; 4] {
    lerp_table(&RGB_CMF_F32, lambda_nm).to_array()
}

/// Wavelengths carried by one path.
pub const N_SPECTRUM_SAMPLES: usize = 4;

/// Normalisation of the visible pdf: 0.0072 / (tanh(0.0072·178) + tanh(0.0072·292)).
const VISIBLE_PDF_NORM: f32 = 0.003_939_804;

/// Four wavelengths (nm) and their sampling pdfs (1/nm). A pdf of 0 marks a terminated
/// secondary wavelength (after a dispersive refraction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampledWavelengths {
    pub lambda: [f32; N_SPECTRUM_SAMPLES],
    pub pdf: [f32; N_SPECTRUM_SAMPLES],
}

/// Inverse CDF of the visible pdf: u ∈ [0,1] → λ ∈ [360, 830] nm.
#[inline]
pub fn sample_visible_wavelength(u: f32) -> f32 {
    let l = 538.0 - 138.888_89 * (0.856_910_6 - 1.827_502 * u).atanh();
    // f32 rounding can overshoot the ends by ~1e-4 nm; keep the sample inside the range
    // where its pdf is defined (a clamped sample would otherwise get pdf 0 and be lost).
    l.clamp(LAMBDA_MIN_NM as f32, LAMBDA_MAX_NM as f32)
}

impl SampledWavelengths {
    /// Mitsuba/pbrt visible-range importance sampling from one random number `u` ∈ [0,1),
    /// rotated by k/4 for the other three wavelengths.
    pub fn sample_visible(u: f32) -> Self {
        let mut lambda = [0.0; N_SPECTRUM_SAMPLES];
        let mut pdf = [0.0; N_SPECTRUM_SAMPLES];
        for k in 0..N_SPECTRUM_SAMPLES {
            let mut up = u + k as f32 / N_SPECTRUM_SAMPLES as f32;
            if up > 1.0 {
                up -= 1.0;
            }
            lambda[k] = sample_visible_wavelength(up);
            pdf[k] = visible_wavelengths_pdf(lambda[k]);
        }
        SampledWavelengths { lambda, pdf }
    }

    /// Four fixed wavelengths with the given pdfs (tests, spectral films).
    pub fn new(lambda: [f32; N_SPECTRUM_SAMPLES], pdf: [f32; N_SPECTRUM_SAMPLES]) -> Self {
        SampledWavelengths { lambda, pdf }
    }

    /// Keep only the hero wavelength (index 0); its pdf is divided by 4 so the 4-sample
    /// average stays unbiased. Idempotent.
    pub fn terminate_secondary(&mut self) {
        if self.secondary_terminated() {
            return;
        }
        for p in &mut self.pdf[1..] {
            *p = 0.0;
        }
        self.pdf[0] /= N_SPECTRUM_SAMPLES as f32;
    }

    pub fn secondary_terminated(&self) -> bool {
        self.pdf[1..].iter().all(|&p| p == 0.0)
    }
}

/// pdf (1/nm) of [`SampledWavelengths::sample_visible`] for one wavelength
/// (0 outside 360–830 nm and for NaN).
pub fn visible_wavelengths_pdf(lambda_nm: f32) -> f32 {
    if !(LAMBDA_MIN_NM as f32..=LAMBDA_MAX_NM as f32).contains(&lambda_nm) {
        return 0.0;
    }
    let c = (0.0072 * (lambda_nm - 538.0)).cosh();
    VISIBLE_PDF_NORM / (c * c)
}

/// A spectral quantity at the four path wavelengths, one SIMD lane each: the one spectrum
/// type of the crate (the renderer's `render::texture::Spec` is this type); arithmetic,
/// `max_element`, `is_finite`, … come from glam.
pub type Spec = glam::Vec4;

const _: () = assert!(
    N_SPECTRUM_SAMPLES == 4,
    "Spec has one lane per path wavelength"
);

/// `f(λ)` at each path wavelength.
pub fn spectrum_at(w: &SampledWavelengths, f: impl FnMut(f32) -> f32) -> Spec {
    Spec::from_array(w.lambda.map(f))
}

/// Monte-Carlo estimate of CIE XYZ of `s`: mean over the 4 samples of cmf(λ)·L(λ)/pdf(λ),
/// divided by [`super::CIE_Y_INTEGRAL`] (zero-pdf samples contribute 0).
pub fn spectrum_to_xyz(s: Spec, wavelengths: &SampledWavelengths) -> [f32; 3] {
    let mut xyz = [0.0f32; 3];
    for k in 0..N_SPECTRUM_SAMPLES {
        let pdf = wavelengths.pdf[k];
        if pdf == 0.0 {
            continue;
        }
        let cmf = cmf_d65_f32(wavelengths.lambda[k]);
        let w = s[k] / pdf;
        for c in 0..3 {
            xyz[c] += cmf[c] * w;
        }
    }
    let norm = 1.0 / (N_SPECTRUM_SAMPLES as f64 * CIE_Y_INTEGRAL) as f32;
    xyz.map(|v| v * norm)
}

/// Monte-Carlo estimate of linear sRGB (XYZ → Rec.709, D65) of `s`, as the film records it.
/// Uses the per-nm sRGB matching functions (the XYZ→sRGB matrix folded into the table),
/// equal to `xyz_to_linear_srgb(spectrum_to_xyz)` up to f32 rounding.
pub fn spectrum_to_linear_srgb(s: Spec, wavelengths: &SampledWavelengths) -> [f32; 3] {
    let mut rgb = glam::Vec4::ZERO;
    for k in 0..N_SPECTRUM_SAMPLES {
        let pdf = wavelengths.pdf[k];
        if pdf == 0.0 {
            continue;
        }
        rgb += lerp_table(&RGB_CMF_F32, wavelengths.lambda[k]) * (s[k] / pdf);
    }
    [rgb.x, rgb.y, rgb.z]
}

/// The film's expected colour of a spectrum, in closed form: the mean over the hero-wavelength
/// sampling of [`spectrum_to_linear_srgb`], E[Σ_k rgb̄(λ_k)·L(λ_k)/p(λ_k)] = N·∫ rgb̄(λ) L(λ) dλ
/// over 360–830 nm (each of the N wavelengths is distributed as p), as quadrature nodes and
/// weights: Σ_j `weight[c][j]`·L(`lambda_nm[j]`). Composite Simpson on every 1 nm interval of
/// the tables (nodes at whole and half nanometres): rgb̄ is linear within an interval, so the
/// rule is exact where L is quadratic there, and for the smooth spectra it is used on
/// (sigmoid spectra, D65 between table rows) the error is far below f32 rounding of the sum.
/// Padded to a multiple of 8 nodes (weight 0 at 360 nm) for 8-lane loops.
pub struct ColourQuadrature {
    pub lambda_nm: Vec<f32>,
    pub weight: [Vec<f32>; 3],
}

impl ColourQuadrature {
    fn new() -> Self {
        let intervals = super::N_TABLE_NM - 1;
        let mut lambda_nm = Vec::with_capacity(2 * intervals + 8);
        let mut weight: [Vec<f32>; 3] = Default::default();
        let n = N_SPECTRUM_SAMPLES as f64;
        let mut node = |l: f64, w: f64| {
            let rgb = lerp_table(&RGB_CMF_F32, l as f32);
            lambda_nm.push(l as f32);
            for (c, col) in weight.iter_mut().enumerate() {
                col.push((n * w * rgb[c] as f64) as f32);
            }
        };
        for i in 0..=intervals {
            let l = LAMBDA_MIN_NM + i as f64;
            // Simpson on [i, i + 1]: (f(i) + 4 f(i + ½) + f(i + 1)) / 6.
            let end = if i == 0 || i == intervals { 1.0 } else { 2.0 };
            node(l, end / 6.0);
            if i < intervals {
                node(l + 0.5, 4.0 / 6.0);
            }
        }
        // 2·470 + 1 nodes, padded to a multiple of 8.
        for _ in (2 * intervals + 1)..(2 * intervals + 1).next_multiple_of(8) {
            node(LAMBDA_MIN_NM, 0.0);
        }
        ColourQuadrature { lambda_nm, weight }
    }

    /// The nodes and weights (built once).
    pub fn get() -> &'static ColourQuadrature {
        static Q: std::sync::OnceLock<ColourQuadrature> = std::sync::OnceLock::new();
        Q.get_or_init(ColourQuadrature::new)
    }

    /// The expected film colour of the spectrum `l` (λ in nm → radiance).
    pub fn expected_rgb(&self, mut l: impl FnMut(f32) -> f32) -> [f32; 3] {
        let mut rgb = [0.0f64; 3];
        for (j, &lambda) in self.lambda_nm.iter().enumerate() {
            let v = l(lambda) as f64;
            for (c, sum) in rgb.iter_mut().enumerate() {
                *sum += self.weight[c][j] as f64 * v;
            }
        }
        rgb.map(|v| v as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_cmf_d65_column_is_the_cmf_d65_factor() {
        // The batch camera reads D65 from the RGB row; it must be the very value the
        // single-ray path reads from the XYZ row, or 1- and N-lane renders would differ.
        for i in 0..=5000 {
            let lambda = 355.0 + i as f32 * 0.0951;
            let a = rgb_cmf_d65_f32(lambda)[3];
            let b = cmf_d65_f32(lambda)[3];
            assert_eq!(a.to_bits(), b.to_bits(), "λ = {lambda}");
        }
    }

    /// The closed-form colour is what the film's spectral estimate averages to: for smooth,
    /// saturated (steep) and constant spectra, the mean of [`spectrum_to_linear_srgb`] over
    /// 2^18 stratified wavelength numbers u (hero sets {u + k/4}) agrees with
    /// [`ColourQuadrature::expected_rgb`] to 2e-5 of the colour's size. Leaving out the
    /// factor N = 4, a Simpson weight or the half-nanometre nodes fails it.
    #[test]
    fn closed_form_colour_is_the_film_mean() {
        let q = ColourQuadrature::get();
        assert_eq!(q.lambda_nm.len() % 8, 0);
        let spectra: [(&str, Box<dyn Fn(f32) -> f32>); 5] = [
            ("constant", Box::new(|_| 1.0)),
            ("D65", Box::new(|l| rgb_cmf_d65_f32(l)[3])),
            (
                "smooth sigmoid",
                Box::new(|l| {
                    let x = (1e-4 * l - 0.1) * l + 18.0;
                    0.5 + x / (2.0 * (1.0 + x * x).sqrt())
                }),
            ),
            (
                "steep edge at 587 nm",
                Box::new(|l| 1.0 / (1.0 + (-(l - 587.3) / 1.5).exp())),
            ),
            (
                "line at 532 nm",
                Box::new(|l| (-((l - 532.0) / 4.0).powi(2)).exp()),
            ),
        ];
        let n = 1 << 18;
        for (name, f) in &spectra {
            let mut mean = [0.0f64; 3];
            for i in 0..n {
                let wl = SampledWavelengths::sample_visible((i as f32 + 0.5) / n as f32);
                let rgb = spectrum_to_linear_srgb(spectrum_at(&wl, f), &wl);
                for c in 0..3 {
                    mean[c] += rgb[c] as f64 / n as f64;
                }
            }
            let want = q.expected_rgb(f);
            let size = mean.iter().map(|v| v.abs()).fold(0.0, f64::max);
            for c in 0..3 {
                let err = (want[c] as f64 - mean[c]).abs();
                assert!(
                    err < 2e-5 * size,
                    "{name}: channel {c}: {} vs mean {}",
                    want[c],
                    mean[c]
                );
            }
        }
        // The constant 1 has the film's white: equal-energy white is (1, 1, 1) / (…) in
        // linear sRGB, so its luminance is Y = ∫ȳ/∫ȳ = 1.
        let white = q.expected_rgb(|_| 1.0);
        let y = 0.2126 * white[0] + 0.7152 * white[1] + 0.0722 * white[2];
        assert!((y - 1.0).abs() < 1e-3, "Y of the constant 1: {y}");
    }

    #[test]
    fn rgb_table_matches_xyz_then_matrix() {
        for i in 0..2000 {
            let w = SampledWavelengths::sample_visible(i as f32 / 2000.0);
            let l = Spec::new(0.3, 1.7, 0.02, 5.0);
            let want = super::super::xyz_to_linear_srgb(spectrum_to_xyz(l, &w).map(f64::from));
            let got = spectrum_to_linear_srgb(l, &w);
            // f32 accumulation: error relative to the sample's overall magnitude (channels
            // can cancel to near zero).
            let scale: f64 = want.iter().map(|v| v.abs()).sum();
            for c in 0..3 {
                let tol = 2e-6 * scale;
                assert!(
                    (got[c] as f64 - want[c]).abs() <= tol,
                    "{i} {c}: {got:?} {want:?}"
                );
            }
        }
        // Terminated secondaries (pdf 0) contribute nothing in both forms.
        let mut w = SampledWavelengths::sample_visible(0.3);
        w.pdf[1] = 0.0;
        let l = Spec::new(0.0, 1e30, 0.0, 0.0);
        assert_eq!(spectrum_to_linear_srgb(l, &w), [0.0; 3]);
    }

    #[test]
    fn f32_cie_table_matches_f64() {
        for i in 0..=47_000 {
            let l = 360.0 + i as f32 * 0.01;
            let fast = cmf_d65_f32(l);
            let cmf = super::super::cie_xyz_cmf(l as f64);
            let d = super::super::d65(l as f64) / super::super::RGB_ILLUMINANT_D65_NORM;
            for (c, want) in [cmf[0], cmf[1], cmf[2], d].into_iter().enumerate() {
                assert!(
                    (fast[c] as f64 - want).abs() <= 2e-6 * want.abs().max(1e-3),
                    "λ {l} channel {c}: {} vs {want}",
                    fast[c]
                );
            }
        }
        for l in [359.99, 830.01, f32::NAN, f32::INFINITY, -1.0] {
            assert_eq!(cmf_d65_f32(l), [0.0; 4], "λ {l}");
        }
        assert!(cmf_d65_f32(830.0)[3] > 0.0 && cmf_d65_f32(360.0)[3] > 0.0);
    }

    #[test]
    fn sample_visible_ends_and_rotation() {
        let w = SampledWavelengths::sample_visible(0.0);
        assert!((w.lambda[0] - 360.0).abs() < 1e-3, "{:?}", w.lambda);
        // u = 0.5 maps to 545.9 nm (pbrt's documented value).
        assert!((w.lambda[2] - 545.9).abs() < 0.1, "{:?}", w.lambda);
        let w2 = SampledWavelengths::sample_visible(0.25);
        assert_eq!(w.lambda[1], w2.lambda[0]);
        let end = sample_visible_wavelength(1.0);
        assert!((end - 830.0).abs() < 1e-3, "{end}");
        for l in w.lambda {
            assert!((360.0..=830.0).contains(&l));
        }
    }

    #[test]
    fn pdf_zero_outside_and_nan() {
        assert_eq!(visible_wavelengths_pdf(359.9), 0.0);
        assert_eq!(visible_wavelengths_pdf(830.1), 0.0);
        assert_eq!(visible_wavelengths_pdf(f32::NAN), 0.0);
        assert!(visible_wavelengths_pdf(538.0) > 0.0039);
    }

    #[test]
    fn terminate_secondary_is_idempotent_and_unbiased() {
        let mut w = SampledWavelengths::sample_visible(0.3);
        let p0 = w.pdf[0];
        assert!(!w.secondary_terminated());
        w.terminate_secondary();
        assert!(w.secondary_terminated());
        assert_eq!(w.pdf[0], p0 / 4.0);
        w.terminate_secondary();
        assert_eq!(w.pdf[0], p0 / 4.0);
        // The 4-sample average of L/pdf equals L0/p0 alone.
        let l = Spec::new(2.0, 5.0, 7.0, 9.0);
        let xyz = spectrum_to_xyz(l, &w);
        let cmf = super::super::cie_xyz_cmf(w.lambda[0] as f64);
        let expect = cmf[1] as f32 * 2.0 / p0 / CIE_Y_INTEGRAL as f32;
        assert!((xyz[1] - expect).abs() <= 1e-5 * expect.abs().max(1e-6));
    }
}
