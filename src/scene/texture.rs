//! Image textures: loading (EXR, Radiance HDR, PNG) and lookups with Mitsuba 3's conventions.
//!
//! Conventions (checked against Mitsuba 3.9 `bitmap` in `scalar_rgb`):
//! - uv = `to_uv` · (u, v, 1); u runs left→right, v runs top→bottom (v = 0 is the first row
//!   stored in the file; Mitsuba does not flip bitmaps).
//! - Texel (x, y) covers [x, x+1)/W × [y, y+1)/H; its centre is at ((x+½)/W, (y+½)/H).
//!   Bilinear: p = uv·(W,H) − ½, interpolate texels ⌊p⌋ and ⌊p⌋+1 (each wrapped);
//!   nearest: texel ⌊uv·(W,H)⌋ wrapped.
//! - Wrap: `repeat` (modulo), `mirror` (period 2W, reflected), `clamp` (to the edge texel).
//! - 8/16-bit images (PNG, JPEG, BMP, TGA, PPM/PGM) are sRGB-decoded to linear unless `raw`,
//!   as Mitsuba's `Bitmap` readers mark them sRGB; float images (EXR, HDR) are kept. Alpha is
//!   dropped; grey images become equal RGB (the same spectrum as Mitsuba's one channel).

use super::{BitmapTexture, TextureFilter, WrapMode};
use crate::image_io::{self, RgbImage};
use anyhow::{bail, Context, Result};
use glam::{Mat3, Vec2, Vec3};
use std::path::Path;

impl WrapMode {
    /// Wraps integer texel coordinate `x` into `0..res`.
    #[inline]
    pub fn wrap(self, x: i64, res: usize) -> usize {
        let r = res as i64;
        let w = match self {
            WrapMode::Repeat => x.rem_euclid(r),
            WrapMode::Clamp => x.clamp(0, r - 1),
            WrapMode::Mirror => {
                let m = x.rem_euclid(2 * r);
                if m >= r {
                    2 * r - m - 1
                } else {
                    m
                }
            }
        };
        w as usize
    }

    /// Parses Mitsuba's `wrap_mode` string.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "repeat" => Some(WrapMode::Repeat),
            "mirror" => Some(WrapMode::Mirror),
            "clamp" => Some(WrapMode::Clamp),
            _ => None,
        }
    }
}

impl TextureFilter {
    /// Parses Mitsuba's `filter_type` string.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "bilinear" => Some(TextureFilter::Bilinear),
            "nearest" => Some(TextureFilter::Nearest),
            _ => None,
        }
    }
}

/// Applies a 3×3 homogeneous UV transform.
#[inline]
pub fn transform_uv(to_uv: &Mat3, uv: Vec2) -> Vec2 {
    let p = *to_uv * Vec3::new(uv.x, uv.y, 1.0);
    Vec2::new(p.x, p.y)
}

/// Mitsuba's `checkerboard`: true where `color0` applies (both fractional parts on the same
/// side of ½), false for `color1`.
#[inline]
pub fn checkerboard_is_color0(to_uv: &Mat3, uv: Vec2) -> bool {
    let p = transform_uv(to_uv, uv);
    let fx = p.x - p.x.floor();
    let fy = p.y - p.y.floor();
    (fx > 0.5) == (fy > 0.5)
}

impl BitmapTexture {
    /// A texture from raw texel data (row-major, top row first).
    pub fn new(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Result<Self> {
        if width == 0 || height == 0 {
            bail!("texture has no texels ({width}×{height})");
        }
        if !(channels == 1 || channels == 3) {
            bail!("texture must have 1 or 3 channels, got {channels}");
        }
        if data.len() != width * height * channels {
            bail!(
                "texture data has {} values, expected {width}×{height}×{channels}",
                data.len()
            );
        }
        Ok(BitmapTexture {
            width,
            height,
            channels,
            data,
            filter: TextureFilter::Bilinear,
            wrap: WrapMode::Repeat,
            to_uv: Mat3::IDENTITY,
            value_range: None,
            path: None,
        })
    }

    #[inline]
    fn texel(&self, x: usize, y: usize) -> [f32; 3] {
        let i = (y * self.width + x) * self.channels;
        if self.channels == 1 {
            let v = self.data[i];
            [v, v, v]
        } else {
            [self.data[i], self.data[i + 1], self.data[i + 2]]
        }
    }

    /// Filtered texel value at `uv` (before `to_uv`), 1-channel textures broadcast to all
    /// three components; `value_range` (if any) is applied: v ↦ min + v·(max − min).
    pub fn eval(&self, uv: Vec2) -> [f32; 3] {
        let p = transform_uv(&self.to_uv, uv);
        let (w, h) = (self.width, self.height);
        let mut out = match self.filter {
            TextureFilter::Nearest => {
                let x = (p.x * w as f32).floor();
                let y = (p.y * h as f32).floor();
                if !(x.is_finite() && y.is_finite()) {
                    return [0.0; 3];
                }
                self.texel(self.wrap.wrap(x as i64, w), self.wrap.wrap(y as i64, h))
            }
            TextureFilter::Bilinear => {
                let fx = p.x * w as f32 - 0.5;
                let fy = p.y * h as f32 - 0.5;
                if !(fx.is_finite() && fy.is_finite()) {
                    return [0.0; 3];
                }
                let (x0, y0) = (fx.floor(), fy.floor());
                let (tx, ty) = (fx - x0, fy - y0);
                let (x0, y0) = (x0 as i64, y0 as i64);
                let xa = self.wrap.wrap(x0, w);
                let xb = self.wrap.wrap(x0 + 1, w);
                let ya = self.wrap.wrap(y0, h);
                let yb = self.wrap.wrap(y0 + 1, h);
                let (a, b, c, d) = (
                    self.texel(xa, ya),
                    self.texel(xb, ya),
                    self.texel(xa, yb),
                    self.texel(xb, yb),
                );
                std::array::from_fn(|k| {
                    (1.0 - ty) * ((1.0 - tx) * a[k] + tx * b[k])
                        + ty * ((1.0 - tx) * c[k] + tx * d[k])
                })
            }
        };
        if let Some((lo, hi)) = self.value_range {
            for v in &mut out {
                *v = lo + *v * (hi - lo);
            }
        }
        out
    }

    /// Gradient (∂/∂u, ∂/∂v, with `uv` before `to_uv`) of the bilinearly filtered value,
    /// RGB texels reduced to their luminance (Rec. 709 weights): Mitsuba's `bitmap`
    /// `eval_1_grad`, the height slope a bump map reads. Per texel cell the value is
    /// bilinear in (x, y) = uv·(W,H) − ½, so ∂f/∂x = (1−ty)(f10−f00) + ty(f11−f01) and
    /// ∂f/∂y = (1−tx)(f01−f00) + tx(f11−f10); the chain rule through ·(W,H) and `to_uv`
    /// gives ∂f/∂u, ∂f/∂v. Zero for nearest filtering (piecewise constant).
    pub fn eval_grad(&self, uv: Vec2) -> Vec2 {
        if self.filter == TextureFilter::Nearest {
            return Vec2::ZERO;
        }
        let p = transform_uv(&self.to_uv, uv);
        let (w, h) = (self.width, self.height);
        let fx = p.x * w as f32 - 0.5;
        let fy = p.y * h as f32 - 0.5;
        if !(fx.is_finite() && fy.is_finite()) {
            return Vec2::ZERO;
        }
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (xa, xb) = (self.wrap.wrap(x0, w), self.wrap.wrap(x0 + 1, w));
        let (ya, yb) = (self.wrap.wrap(y0, h), self.wrap.wrap(y0 + 1, h));
        let lum = |x, y| {
            let [r, g, b] = self.texel(x, y);
            if self.channels == 1 {
                r
            } else {
                0.212671 * r + 0.715160 * g + 0.072169 * b
            }
        };
        let (f00, f10, f01, f11) = (lum(xa, ya), lum(xb, ya), lum(xa, yb), lum(xb, yb));
        let scale = self.value_range.map_or(1.0, |(lo, hi)| hi - lo);
        // ∂f/∂(s, t) in the transformed coordinates, then through s = m00 u + m01 v + …,
        // t = m10 u + m11 v + … (glam is column-major: x_axis = (m00, m10, m20)).
        let ds = ((1.0 - ty) * (f10 - f00) + ty * (f11 - f01)) * w as f32 * scale;
        let dt = ((1.0 - tx) * (f01 - f00) + tx * (f11 - f10)) * h as f32 * scale;
        let m = &self.to_uv;
        Vec2::new(
            ds * m.x_axis.x + dt * m.x_axis.y,
            ds * m.y_axis.x + dt * m.y_axis.y,
        )
    }

    /// First channel of [`eval`](Self::eval) (e.g. a thickness in nm).
    #[inline]
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        self.eval(uv)[0]
    }

    /// Smallest and largest texel value after `value_range` (NaN texels skipped), or None if
    /// every texel is NaN.
    pub fn value_bounds(&self) -> Option<(f32, f32)> {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for &v in self.data.iter().filter(|v| !v.is_nan()) {
            let v = match self.value_range {
                Some((a, b)) => a + v * (b - a),
                None => v,
            };
            lo = lo.min(v);
            hi = hi.max(v);
        }
        (lo <= hi).then_some((lo, hi))
    }

    /// Loads an image file as a texture. `.exr`: an RGB image if it has R, G, B channels,
    /// otherwise its single channel (e.g. `thickness`, or `Y`), values as stored.
    /// `.hdr`: RGB float. `.png`: 8/16-bit, sRGB-decoded unless `raw`.
    pub fn load(path: &Path, raw: bool) -> Result<Self> {
        let ext = extension(path);
        // Checks of the decoded texels (e.g. a 0×0 image) name the file too.
        let new = |w, h, c, data| {
            BitmapTexture::new(w, h, c, data).with_context(|| path.display().to_string())
        };
        let mut tex = match ext.as_str() {
            "exr" => {
                let (w, h, channels) = image_io::read_exr_channels(path)?;
                let find = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, p)| p);
                if let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B")) {
                    let data = (0..w * h).flat_map(|i| [r[i], g[i], b[i]]).collect();
                    new(w, h, 3, data)?
                } else if channels.len() == 1 || find("Y").is_some() {
                    let plane = find("Y").unwrap_or(&channels[0].1).clone();
                    new(w, h, 1, plane)?
                } else {
                    let names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
                    bail!(
                        "{}: expected channels R, G, B or a single channel, found {}",
                        path.display(),
                        names.join(", ")
                    );
                }
            }
            e if e == "hdr" || INTEGER_FORMATS.contains(&e) => {
                let img = load_rgb_image_raw(path, raw)?;
                let data = img.pixels.iter().flatten().copied().collect();
                new(img.width, img.height, 3, data)?
            }
            _ => bail!(
                "{}: unsupported texture format '.{ext}' ({})",
                path.display(),
                SUPPORTED
            ),
        };
        tex.path = Some(path.to_path_buf());
        Ok(tex)
    }
}

/// Integer-valued image formats, read through the `image` crate and sRGB-decoded unless raw.
const INTEGER_FORMATS: &[&str] = &["png", "jpg", "jpeg", "bmp", "tga", "ppm", "pgm"];
const SUPPORTED: &str = "use .exr, .hdr, .png, .jpg, .bmp, .tga or .ppm";

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Loads an RGB image as linear values: EXR (R,G,B or Y), Radiance HDR, or an integer
/// format (PNG, JPEG, BMP, TGA, PPM; sRGB-decoded).
pub fn load_rgb_image(path: &Path) -> Result<RgbImage> {
    load_rgb_image_raw(path, false)
}

pub(crate) fn srgb_to_linear(v: f32) -> f32 {
    // IEC 61966-2-1 inverse transfer function.
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn load_rgb_image_raw(path: &Path, raw: bool) -> Result<RgbImage> {
    if !path.is_file() {
        bail!("image file {} does not exist", path.display());
    }
    match extension(path).as_str() {
        "exr" => image_io::read_exr_rgb(path),
        "hdr" => {
            let img = image_io::read_image(path, 24)
                .with_context(|| format!("reading Radiance HDR {}", path.display()))?
                .to_rgb32f();
            let (w, h) = (img.width() as usize, img.height() as usize);
            let pixels = img.pixels().map(|p| p.0).collect();
            Ok(RgbImage {
                width: w,
                height: h,
                pixels,
            })
        }
        e if INTEGER_FORMATS.contains(&e) => {
            let img = image_io::read_image(path, 24)
                .with_context(|| format!("reading image {}", path.display()))?
                .to_rgb16();
            let (w, h) = (img.width() as usize, img.height() as usize);
            let pixels = img
                .pixels()
                .map(|p| {
                    p.0.map(|c| {
                        let v = c as f32 / 65535.0;
                        if raw {
                            v
                        } else {
                            srgb_to_linear(v)
                        }
                    })
                })
                .collect();
            Ok(RgbImage {
                width: w,
                height: h,
                pixels,
            })
        }
        other => bail!(
            "{}: unsupported image format '.{other}' ({SUPPORTED})",
            path.display()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex2x2() -> BitmapTexture {
        // top row: 1, 2; bottom row: 3, 4
        BitmapTexture::new(2, 2, 1, vec![1.0, 2.0, 3.0, 4.0]).unwrap()
    }

    #[test]
    fn gradient_matches_finite_differences() {
        // A linear ramp f = 0.25·x + 0.5·y over texel indices: ∂f/∂u = 0.25·W, ∂f/∂v = 0.5·H
        // inside (clamped edges excepted).
        let (w, h) = (5usize, 4usize);
        let data: Vec<f32> = (0..w * h)
            .map(|i| 0.25 * (i % w) as f32 + 0.5 * (i / w) as f32)
            .collect();
        let mut t = BitmapTexture::new(w, h, 1, data).unwrap();
        t.wrap = WrapMode::Clamp;
        let g = t.eval_grad(Vec2::new(0.43, 0.61));
        assert!((g.x - 0.25 * w as f32).abs() < 1e-4, "{g:?}");
        assert!((g.y - 0.5 * h as f32).abs() < 1e-4, "{g:?}");
        // A non-linear RGB texture under a rotated, scaled uv transform, repeat wrap:
        // the analytic gradient equals central differences of `eval` (luminance).
        let data: Vec<f32> = (0..w * h * 3)
            .map(|i| ((i * 7919) % 13) as f32 / 13.0)
            .collect();
        let mut t = BitmapTexture::new(w, h, 3, data).unwrap();
        t.to_uv = Mat3::from_cols_array(&[1.3, 0.4, 0.0, -0.7, 0.9, 0.0, 0.1, 0.2, 1.0]);
        t.value_range = Some((0.5, 2.5));
        let lum = |uv: Vec2| {
            let [r, g, b] = t.eval(uv);
            0.212671 * r + 0.715160 * g + 0.072169 * b
        };
        let e = 1e-3f32;
        for uv in [
            Vec2::new(0.31, 0.77),
            Vec2::new(-0.42, 1.13),
            Vec2::new(0.05, 0.52),
        ] {
            let g = t.eval_grad(uv);
            let fd = Vec2::new(
                (lum(uv + Vec2::X * e) - lum(uv - Vec2::X * e)) / (2.0 * e),
                (lum(uv + Vec2::Y * e) - lum(uv - Vec2::Y * e)) / (2.0 * e),
            );
            assert!(
                (g - fd).length() < 2e-2 * (1.0 + fd.length()),
                "{uv}: {g} vs {fd}"
            );
            assert!(g.length() > 0.1, "{g}");
        }
        t.filter = TextureFilter::Nearest;
        assert_eq!(t.eval_grad(Vec2::new(0.31, 0.77)), Vec2::ZERO);
    }

    #[test]
    fn texel_centres_and_filters() {
        let mut t = tex2x2();
        // Texel centres return the texel exactly.
        assert_eq!(t.eval_scalar(Vec2::new(0.25, 0.25)), 1.0);
        assert_eq!(t.eval_scalar(Vec2::new(0.75, 0.75)), 4.0);
        // Midpoint between all four.
        assert!((t.eval_scalar(Vec2::new(0.5, 0.5)) - 2.5).abs() < 1e-6);
        // Repeat wraps: u = 0 lies between texel 1 (x=-1 → 1) and texel 0.
        assert!((t.eval_scalar(Vec2::new(0.0, 0.25)) - 1.5).abs() < 1e-6);
        t.wrap = WrapMode::Clamp;
        assert_eq!(t.eval_scalar(Vec2::new(0.0, 0.25)), 1.0);
        t.wrap = WrapMode::Mirror;
        assert_eq!(t.eval_scalar(Vec2::new(0.0, 0.25)), 1.0);
        assert_eq!(t.wrap.wrap(-1, 2), 0);
        assert_eq!(t.wrap.wrap(2, 2), 1);
        assert_eq!(t.wrap.wrap(3, 2), 0);
        t.filter = TextureFilter::Nearest;
        assert_eq!(t.eval_scalar(Vec2::new(0.74, 0.26)), 2.0);
        // NaN uv never panics.
        assert_eq!(t.eval(Vec2::new(f32::NAN, 0.0)), [0.0; 3]);
        t.value_range = Some((100.0, 400.0));
        assert_eq!(t.eval_scalar(Vec2::new(0.25, 0.25)), 400.0 + 300.0 * 0.0);
    }

    #[test]
    fn to_uv_and_checkerboard() {
        let mut t = tex2x2();
        t.filter = TextureFilter::Nearest;
        t.to_uv = Mat3::from_scale(Vec2::new(2.0, 2.0));
        // uv (0.6, 0.1) → (1.2, 0.2) → repeat → texel (0, 0).
        assert_eq!(t.eval_scalar(Vec2::new(0.6, 0.1)), 1.0);
        assert!(checkerboard_is_color0(&Mat3::IDENTITY, Vec2::new(0.2, 0.2)));
        assert!(!checkerboard_is_color0(
            &Mat3::IDENTITY,
            Vec2::new(0.7, 0.2)
        ));
        assert!(checkerboard_is_color0(&Mat3::IDENTITY, Vec2::new(0.7, 0.7)));
    }

    #[test]
    fn bad_textures_are_errors() {
        assert!(BitmapTexture::new(0, 1, 1, vec![]).is_err());
        assert!(BitmapTexture::new(1, 1, 2, vec![0.0; 2]).is_err());
        assert!(BitmapTexture::new(2, 1, 1, vec![0.0]).is_err());
        assert!(BitmapTexture::load(Path::new("/nonexistent/x.png"), false).is_err());
        assert!(BitmapTexture::load(Path::new("x.jpg"), false).is_err());
        assert!(BitmapTexture::load(Path::new("x.pfm"), false)
            .unwrap_err()
            .to_string()
            .contains("unsupported"));
    }
}
