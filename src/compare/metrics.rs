//! Error metrics between a test image `A` and a reference image `B`, both linear sRGB
//! (Rec.709 primaries, D65 white), as written by `thinfilm render` and Mitsuba's `hdrfilm`.
//!
//! - RMSE over all pixels and channels.
//! - relMSE as in pbrt-v4's `imgtool diff` and Mitsuba's test suite:
//!   mean over pixels and channels of (a − b)² / (b² + ε), with ε = [`RELMSE_EPSILON`], so dark
//!   reference pixels do not blow the metric up.
//! - ΔE00 (CIEDE2000, Sharma, Wu & Dalal 2005) per pixel after linear sRGB → XYZ → CIELAB
//!   relative to the D65 white with Y = 1; mean and 95th percentile (linear interpolation between order statistics).
//! - Mean-colour bias: per channel (mean(A) − mean(B)) / mean(B), the systematic error that
//!   survives any amount of averaging (a noise-free estimator has zero bias at any spp).

use crate::image_io::RgbImage;
use crate::spectrum::{delta_e2000, linear_srgb_to_xyz, xyz_to_lab, D65_WHITE_XYZ};
use anyhow::{bail, Result};
use serde::Serialize;

/// ε in the relMSE denominator (pbrt-v4 `imgtool`, Mitsuba tests use 1e-2).
pub const RELMSE_EPSILON: f64 = 1e-2;

/// All metrics of one comparison (B is the reference).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageMetrics {
    pub width: usize,
    pub height: usize,
    pub rmse: f64,
    pub rel_mse: f64,
    pub delta_e00_mean: f64,
    pub delta_e00_p95: f64,
    /// Per channel (R, G, B) relative bias of the mean colour, (mean A − mean B) / mean B.
    /// Infinite when the reference channel mean is zero and A's is not; 0 when both are zero.
    pub mean_bias_rgb: [f64; 3],
    pub mean_rgb_a: [f64; 3],
    pub mean_rgb_b: [f64; 3],
}

impl ImageMetrics {
    /// Largest |relative bias| over the three channels.
    pub fn max_abs_bias(&self) -> f64 {
        self.mean_bias_rgb
            .iter()
            .fold(0.0_f64, |m, b| m.max(b.abs()))
    }
}

/// Errors unless both images have the same size; the message names both labels (file names).
pub fn check_same_size(a: &RgbImage, a_label: &str, b: &RgbImage, b_label: &str) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        bail!(
            "image sizes differ: {a_label} is {}×{}, {b_label} is {}×{}",
            a.width,
            a.height,
            b.width,
            b.height
        );
    }
    if a.pixels.len() != a.width * a.height || b.pixels.len() != b.width * b.height {
        bail!("pixel buffer does not match width × height ({a_label} or {b_label})");
    }
    if a.pixels.is_empty() {
        bail!("images {a_label} and {b_label} are empty (0 pixels)");
    }
    Ok(())
}

/// Brings two images to one size for comparison: equal sizes pass unchanged; when one is an
/// integer multiple `k` of the other in both directions (a render at 4× the reference's
/// resolution, say), the larger is box-downsampled by `k` (each output pixel the mean of a
/// k×k block, which is what rendering at the smaller size estimates). Returns the images and,
/// when it resized one, a sentence saying so. Other size differences are an error.
pub fn match_sizes(
    a: RgbImage,
    a_label: &str,
    b: RgbImage,
    b_label: &str,
) -> Result<(RgbImage, RgbImage, Option<String>)> {
    let factor = |big: &RgbImage, small: &RgbImage| -> Option<usize> {
        (small.width > 0
            && small.height > 0
            && big.width % small.width == 0
            && big.height % small.height == 0
            && big.width / small.width == big.height / small.height)
            .then(|| big.width / small.width)
    };
    let note = |big: &RgbImage, label: &str, k: usize, small: &RgbImage| {
        format!(
            "{label} ({}×{}) box-downsampled by {k} to {}×{} to match the other image",
            big.width, big.height, small.width, small.height
        )
    };
    if (a.width, a.height) == (b.width, b.height) {
        return Ok((a, b, None));
    }
    if let Some(k) = factor(&a, &b) {
        let n = note(&a, a_label, k, &b);
        return Ok((downsample_box(&a, k)?, b, Some(n)));
    }
    if let Some(k) = factor(&b, &a) {
        let n = note(&b, b_label, k, &a);
        return Ok((a, downsample_box(&b, k)?, Some(n)));
    }
    bail!(
        "image sizes differ: {a_label} is {}×{}, {b_label} is {}×{} (sizes must be equal or          differ by one integer factor in both directions)",
        a.width,
        a.height,
        b.width,
        b.height
    )
}

fn check_finite(img: &RgbImage, label: &str) -> Result<()> {
    if let Some(i) = img
        .pixels
        .iter()
        .position(|p| p.iter().any(|v| !v.is_finite()))
    {
        bail!(
            "{label}: pixel (x {}, y {}) is not finite: {:?}",
            i % img.width,
            i / img.width,
            img.pixels[i]
        );
    }
    Ok(())
}

/// CIELAB (D65, Y = 1 white) of a linear sRGB pixel.
pub fn linear_srgb_to_lab(rgb: [f32; 3]) -> [f64; 3] {
    let xyz = linear_srgb_to_xyz([rgb[0] as f64, rgb[1] as f64, rgb[2] as f64]);
    xyz_to_lab(xyz, D65_WHITE_XYZ)
}

/// Per-pixel ΔE00 between same-sized images, row-major.
pub fn delta_e00_map(a: &RgbImage, b: &RgbImage) -> Result<Vec<f64>> {
    check_same_size(a, "A", b, "B")?;
    Ok(a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(&pa, &pb)| delta_e2000(linear_srgb_to_lab(pa), linear_srgb_to_lab(pb)))
        .collect())
}

/// The `q`-quantile of unsorted, NaN-free values ([`crate::stats::percentile`]).
pub fn percentile(values: &[f64], q: f64) -> f64 {
    crate::stats::percentile(&mut values.to_vec(), q)
}

/// Computes every metric of A against the reference B. Errors on size mismatch or
/// non-finite pixels (naming the pixel).
pub fn compare_images(a: &RgbImage, b: &RgbImage) -> Result<ImageMetrics> {
    check_same_size(a, "A", b, "B")?;
    check_finite(a, "A")?;
    check_finite(b, "B")?;
    let n = a.pixels.len() as f64;
    let mut se = 0.0;
    let mut rel = 0.0;
    let mut sum_a = [0.0f64; 3];
    let mut sum_b = [0.0f64; 3];
    for (pa, pb) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            let (va, vb) = (pa[c] as f64, pb[c] as f64);
            let d2 = (va - vb) * (va - vb);
            se += d2;
            rel += d2 / (vb * vb + RELMSE_EPSILON);
            sum_a[c] += va;
            sum_b[c] += vb;
        }
    }
    let de = delta_e00_map(a, b)?;
    let mean_rgb_a = sum_a.map(|s| s / n);
    let mean_rgb_b = sum_b.map(|s| s / n);
    let mean_bias_rgb = std::array::from_fn(|c| {
        let (ma, mb) = (mean_rgb_a[c], mean_rgb_b[c]);
        if mb != 0.0 {
            (ma - mb) / mb
        } else if ma == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    });
    Ok(ImageMetrics {
        width: a.width,
        height: a.height,
        rmse: (se / (3.0 * n)).sqrt(),
        rel_mse: rel / (3.0 * n),
        delta_e00_mean: de.iter().sum::<f64>() / n,
        delta_e00_p95: percentile(&de, 0.95),
        mean_bias_rgb,
        mean_rgb_a,
        mean_rgb_b,
    })
}

/// Box downsample by an integer `factor`: each output pixel is the mean of a factor×factor
/// block. Trailing rows/columns that do not fill a whole block are dropped.
pub fn downsample_box(img: &RgbImage, factor: usize) -> Result<RgbImage> {
    if factor == 0 {
        bail!("downsample factor must be ≥ 1");
    }
    if factor > img.width || factor > img.height {
        bail!(
            "downsample factor {factor} is larger than the image ({}×{})",
            img.width,
            img.height
        );
    }
    let (w, h) = (img.width / factor, img.height / factor);
    let mut out = RgbImage::new(w, h);
    let inv = 1.0 / (factor * factor) as f64;
    for oy in 0..h {
        for ox in 0..w {
            let mut acc = [0.0f64; 3];
            for y in oy * factor..(oy + 1) * factor {
                for x in ox * factor..(ox + 1) * factor {
                    let p = img.get(x, y);
                    for c in 0..3 {
                        acc[c] += p[c] as f64;
                    }
                }
            }
            out.pixels[oy * w + ox] = acc.map(|v| (v * inv) as f32);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> RgbImage {
        let mut im = RgbImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                im.pixels[y * w + x] = f(x, y);
            }
        }
        im
    }

    #[test]
    fn rmse_relmse_bias_hand_computed() {
        // A: two pixels (1,1,1),(0,0,0); B: (0.5,0.5,0.5),(0,0,0).
        let a = img(2, 1, |x, _| if x == 0 { [1.0; 3] } else { [0.0; 3] });
        let b = img(2, 1, |x, _| if x == 0 { [0.5; 3] } else { [0.0; 3] });
        let m = compare_images(&a, &b).unwrap();
        // squared errors: 3 × 0.25 + 3 × 0 over 6 values → mse 0.125.
        assert!((m.rmse - 0.125f64.sqrt()).abs() < 1e-12);
        // rel: 3 × 0.25 / (0.25 + 0.01) over 6 values.
        let expect = 3.0 * 0.25 / 0.26 / 6.0;
        assert!((m.rel_mse - expect).abs() < 1e-12, "{}", m.rel_mse);
        // means: A 0.5, B 0.25 → bias +100 %.
        for c in 0..3 {
            assert!((m.mean_bias_rgb[c] - 1.0).abs() < 1e-12);
        }
        assert!((m.max_abs_bias() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn zero_reference_channel_bias() {
        let a = img(1, 1, |_, _| [0.0, 0.2, 0.0]);
        let b = img(1, 1, |_, _| [0.0, 0.0, 0.1]);
        let m = compare_images(&a, &b).unwrap();
        assert_eq!(m.mean_bias_rgb[0], 0.0);
        assert!(m.mean_bias_rgb[1].is_infinite());
        assert!((m.mean_bias_rgb[2] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn identical_images_are_zero() {
        let a = img(4, 3, |x, y| [x as f32 * 0.1, y as f32 * 0.2, 0.3]);
        let m = compare_images(&a, &a).unwrap();
        assert_eq!(m.rmse, 0.0);
        assert_eq!(m.rel_mse, 0.0);
        assert_eq!(m.delta_e00_mean, 0.0);
        assert_eq!(m.delta_e00_p95, 0.0);
        assert_eq!(m.mean_bias_rgb, [0.0; 3]);
    }

    #[test]
    fn different_sizes_error_names_both() {
        let a = RgbImage::new(4, 4);
        let b = RgbImage::new(4, 2);
        let e = check_same_size(&a, "left.exr", &b, "right.exr").unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("left.exr") && s.contains("right.exr") && s.contains("4×2"),
            "{s}"
        );
        assert!(compare_images(&a, &b).is_err());
    }

    #[test]
    fn nan_pixel_is_an_error_naming_the_pixel() {
        let a = img(3, 2, |x, y| {
            if (x, y) == (2, 1) {
                [f32::NAN, 0.0, 0.0]
            } else {
                [0.1; 3]
            }
        });
        let b = img(3, 2, |_, _| [0.1; 3]);
        let s = compare_images(&a, &b).unwrap_err().to_string();
        assert!(s.contains("x 2, y 1"), "{s}");
    }

    #[test]
    fn white_maps_to_lab_100() {
        let lab = linear_srgb_to_lab([1.0, 1.0, 1.0]);
        assert!((lab[0] - 100.0).abs() < 0.05, "{lab:?}");
        assert!(lab[1].abs() < 0.05 && lab[2].abs() < 0.05, "{lab:?}");
        let black = linear_srgb_to_lab([0.0, 0.0, 0.0]);
        assert!(black.iter().all(|v| v.abs() < 1e-9), "{black:?}");
    }

    #[test]
    fn delta_e_grey_pair_matches_lab_lightness() {
        // Two neutral greys differ only in L*; for ΔL' alone CIEDE2000 gives
        // ΔE00 = ΔL / S_L with S_L = 1 + 0.015 (L̄−50)² / sqrt(20 + (L̄−50)²).
        let a = img(1, 1, |_, _| [0.18; 3]);
        let b = img(1, 1, |_, _| [0.2; 3]);
        let m = compare_images(&a, &b).unwrap();
        let lab = |y: f64| {
            let f = |t: f64| {
                if t > (6.0f64 / 29.0).powi(3) {
                    t.cbrt()
                } else {
                    t / (3.0 * (6.0f64 / 29.0).powi(2)) + 4.0 / 29.0
                }
            };
            116.0 * f(y) - 16.0
        };
        let (l1, l2) = (lab(0.18), lab(0.2));
        let lbar = 0.5 * (l1 + l2);
        let sl = 1.0 + 0.015 * (lbar - 50.0).powi(2) / (20.0 + (lbar - 50.0).powi(2)).sqrt();
        let expect = (l2 - l1).abs() / sl;
        assert!(
            (m.delta_e00_mean - expect).abs() < 1e-3,
            "{} vs {expect}",
            m.delta_e00_mean
        );
        assert_eq!(m.delta_e00_p95, m.delta_e00_mean);
    }

    #[test]
    fn downsample_averages_blocks() {
        let a = img(5, 4, |x, y| [(x + 10 * y) as f32, 1.0, 0.0]);
        let d = downsample_box(&a, 2).unwrap();
        assert_eq!((d.width, d.height), (2, 2));
        // block (0,0): x 0..2, y 0..2 → values 0,1,10,11 → 5.5
        assert_eq!(d.get(0, 0), [5.5, 1.0, 0.0]);
        // block (1,1): x 2..4, y 2..4 → 22,23,32,33 → 27.5
        assert_eq!(d.get(1, 1), [27.5, 1.0, 0.0]);
        assert_eq!(downsample_box(&a, 1).unwrap(), a);
        assert!(downsample_box(&a, 0).is_err());
        assert!(downsample_box(&a, 6).is_err());
    }
}
