//! Spectra and textures as the renderer evaluates them: scene descriptions
//! ([`crate::scene::SpectrumDesc`], [`crate::scene::TextureDesc`]) turned into values at the
//! four path wavelengths. RGB reflectances use Jakob & Hanika 2019 upsampling, RGB emitters
//! Mitsuba's `srgb_d65` (`docs/physics-and-formats.md`, "Environment map").

use crate::scene::{BitmapTexture, SpectrumDesc, TextureDesc};
use crate::spectrum::{
    rgb2spec::srgb_reflectance, RgbIlluminantSpectrum, RgbSigmoidPolynomial, SampledWavelengths,
};
use glam::{Mat3, Vec2, Vec3, Vec4};
use std::sync::Arc;

/// A spectrum at the four path wavelengths (one lane per wavelength).
pub use crate::spectrum::Spec;

/// Wavelengths of a path as a `Vec4` (nm).
#[inline]
pub fn lambdas(wl: &SampledWavelengths) -> Vec4 {
    Vec4::from_array(wl.lambda)
}

/// A spectrum ready for evaluation.
#[derive(Debug, Clone)]
pub enum Spectrum {
    Constant(f32),
    /// Bounded RGB reflectance (sigmoid polynomial), and the linear sRGB it came from.
    Albedo(RgbSigmoidPolynomial, [f32; 3]),
    /// RGB emitter: scale · polynomial · normalised D65, and the linear sRGB it came from.
    Illuminant(RgbIlluminantSpectrum, [f32; 3]),
    /// Piecewise-linear (λ nm ascending, value), held constant beyond its ends.
    Tabulated(Arc<[(f32, f32)]>),
    /// Normalised D65 times a scale.
    D65(f32),
}

impl Spectrum {
    /// A reflectance (BSDF parameter): RGB is upsampled without an illuminant.
    pub fn reflectance(desc: &SpectrumDesc) -> Self {
        match desc {
            SpectrumDesc::Constant(v) => Spectrum::Constant(*v),
            SpectrumDesc::Rgb(rgb) if rgb[0] == rgb[1] && rgb[1] == rgb[2] => {
                Spectrum::Constant(rgb[0])
            }
            SpectrumDesc::Rgb(rgb) => Spectrum::Albedo(srgb_reflectance(*rgb), *rgb),
            SpectrumDesc::Tabulated(t) => Spectrum::Tabulated(t.clone().into()),
            SpectrumDesc::D65 { scale } => Spectrum::D65(*scale),
        }
    }

    /// An emitter's radiance: RGB uses Mitsuba's `srgb_d65`.
    pub fn illuminant(desc: &SpectrumDesc) -> Self {
        match desc {
            SpectrumDesc::Rgb(rgb) => Spectrum::Illuminant(RgbIlluminantSpectrum::new(*rgb), *rgb),
            other => Spectrum::reflectance(other),
        }
    }

    #[inline]
    pub fn eval(&self, wl: &SampledWavelengths) -> Spec {
        match self {
            Spectrum::Constant(v) => Spec::splat(*v),
            Spectrum::Albedo(p, _) => p.eval4(Spec::from_array(wl.lambda)),
            Spectrum::Illuminant(s, _) => s.eval4(Spec::from_array(wl.lambda)),
            Spectrum::Tabulated(t) => Spec::from_array(wl.lambda.map(|l| tabulated(t, l))),
            Spectrum::D65(scale) => {
                // RGB (1,1,1) as an illuminant is the normalised D65 curve (scale 2, flat 0.5).
                let white = RgbIlluminantSpectrum::new([1.0; 3]);
                Spec::splat(*scale) * white.eval4(Spec::from_array(wl.lambda))
            }
        }
    }

    /// A wavelength-independent summary used only to weight sampling strategies.
    pub fn mean_hint(&self) -> f32 {
        match self {
            Spectrum::Constant(v) => *v,
            Spectrum::Albedo(p, _) => {
                let s: f32 = (0..16).map(|i| p.eval(400.0 + 20.0 * i as f32)).sum();
                s / 16.0
            }
            Spectrum::Illuminant(s, _) => s.scale,
            Spectrum::Tabulated(t) => t.iter().map(|p| p.1).sum::<f32>() / t.len().max(1) as f32,
            Spectrum::D65(s) => *s,
        }
    }

    /// The description it was made from (an RGB emitter's as its colour).
    pub fn desc(&self) -> SpectrumDesc {
        match self {
            Spectrum::Constant(v) => SpectrumDesc::Constant(*v),
            Spectrum::Albedo(_, rgb) => SpectrumDesc::Rgb(*rgb),
            Spectrum::Illuminant(_, rgb) => SpectrumDesc::Rgb(*rgb),
            Spectrum::Tabulated(t) => SpectrumDesc::Tabulated(t.to_vec()),
            Spectrum::D65(scale) => SpectrumDesc::D65 { scale: *scale },
        }
    }
}

fn tabulated(t: &[(f32, f32)], lambda: f32) -> f32 {
    if t.is_empty() {
        return 0.0;
    }
    if lambda <= t[0].0 {
        return t[0].1;
    }
    if lambda >= t[t.len() - 1].0 {
        return t[t.len() - 1].1;
    }
    let i = t.partition_point(|p| p.0 <= lambda).clamp(1, t.len() - 1);
    let (l0, v0) = t[i - 1];
    let (l1, v1) = t[i];
    let f = if l1 > l0 {
        (lambda - l0) / (l1 - l0)
    } else {
        0.0
    };
    v0 + f * (v1 - v0)
}

/// A texture evaluated at surface UVs.
#[derive(Debug, Clone)]
pub enum Texture {
    Value(Spectrum),
    Bitmap(Arc<BitmapTexture>),
    Checkerboard {
        color0: Spectrum,
        color1: Spectrum,
        to_uv: Mat3,
    },
    /// The interpolated vertex colour ([`Texture::eval_at`] reads it; the scene parser
    /// admits it only where a BSDF evaluates through `eval_at`, elsewhere it is white).
    VertexColor,
}

impl Texture {
    /// A reflectance-like texture (RGB bitmaps upsampled as reflectances).
    pub fn new(desc: &TextureDesc) -> Self {
        match desc {
            TextureDesc::Value(v) => Texture::Value(Spectrum::reflectance(v)),
            TextureDesc::Bitmap(b) => Texture::Bitmap(b.clone()),
            TextureDesc::Checkerboard {
                color0,
                color1,
                to_uv,
            } => Texture::Checkerboard {
                color0: Spectrum::reflectance(color0),
                color1: Spectrum::reflectance(color1),
                to_uv: *to_uv,
            },
            TextureDesc::VertexColor => Texture::VertexColor,
        }
    }

    /// Spectral value at a shading point: [`Texture::eval`] at its UV, or its vertex colour
    /// upsampled as a reflectance (Jakob & Hanika 2019; grey stays flat).
    #[inline]
    pub fn eval_at(&self, ctx: &crate::render::bsdf::ShadingCtx) -> Spec {
        match self {
            Texture::VertexColor => {
                let c = ctx.color;
                if c.x == c.y && c.y == c.z {
                    Spec::splat(c.x)
                } else {
                    let p = srgb_reflectance(c.to_array());
                    p.eval4(Spec::from_array(ctx.wl.lambda))
                }
            }
            _ => self.eval(ctx.uv, ctx.wl),
        }
    }

    /// Spectral value at `uv`.
    pub fn eval(&self, uv: Vec2, wl: &SampledWavelengths) -> Spec {
        match self {
            Texture::Value(s) => s.eval(wl),
            Texture::Bitmap(b) => {
                let v = b.eval(uv);
                if b.channels >= 3 {
                    let rgb = [v[0], v[1], v[2]];
                    if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
                        Spec::splat(rgb[0])
                    } else {
                        let p = srgb_reflectance(rgb);
                        p.eval4(Spec::from_array(wl.lambda))
                    }
                } else {
                    Spec::splat(v[0])
                }
            }
            Texture::Checkerboard {
                color0,
                color1,
                to_uv,
            } => {
                if checker_is_first(*to_uv, uv) {
                    color0.eval(wl)
                } else {
                    color1.eval(wl)
                }
            }
            Texture::VertexColor => Spec::splat(1.0),
        }
    }

    /// Scalar value at `uv` (thickness maps, roughness): first channel, or the constant /
    /// mean of a spectrum. A bitmap with `value_range` maps [0,1] onto (min, max).
    pub fn eval_scalar(&self, uv: Vec2) -> f32 {
        match self {
            Texture::Value(s) => s.mean_hint(),
            Texture::Bitmap(b) => {
                // glTF iridescence thickness lives in the G channel.
                // `eval` applies `value_range`; Mitsuba's lattice (v = 0 is the top row).
                let v = b.eval(uv);
                if b.value_range.is_some() && b.channels >= 3 {
                    v[1]
                } else {
                    v[0]
                }
            }
            Texture::Checkerboard {
                color0,
                color1,
                to_uv,
            } => {
                if checker_is_first(*to_uv, uv) {
                    color0.mean_hint()
                } else {
                    color1.mean_hint()
                }
            }
            Texture::VertexColor => 1.0,
        }
    }

    /// The description it was made from ([`Texture::new`]'s argument).
    pub fn desc(&self) -> TextureDesc {
        match self {
            Texture::Value(s) => TextureDesc::Value(s.desc()),
            Texture::Bitmap(b) => TextureDesc::Bitmap(b.clone()),
            Texture::Checkerboard {
                color0,
                color1,
                to_uv,
            } => TextureDesc::Checkerboard {
                color0: color0.desc(),
                color1: color1.desc(),
                to_uv: *to_uv,
            },
            Texture::VertexColor => TextureDesc::VertexColor,
        }
    }

    /// Whether this is a `mesh_attribute` (read from the shading point's vertex colour).
    pub fn reads_mesh_attribute(&self) -> bool {
        matches!(self, Texture::VertexColor)
    }

    /// Whether the value varies over the surface.
    pub fn is_varying(&self) -> bool {
        !matches!(self, Texture::Value(_))
    }
}

fn checker_is_first(to_uv: Mat3, uv: Vec2) -> bool {
    let p = to_uv * Vec3::new(uv.x, uv.y, 1.0);
    let fu = p.x - p.x.floor();
    let fv = p.y - p.y.floor();
    // Mitsuba: color0 where both or neither fractional part is below 0.5.
    (fu < 0.5) == (fv < 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{TextureFilter, WrapMode};

    #[test]
    fn tabulated_interpolates_and_clamps() {
        let t = [(400.0, 1.0), (500.0, 3.0)];
        assert_eq!(tabulated(&t, 300.0), 1.0);
        assert_eq!(tabulated(&t, 450.0), 2.0);
        assert_eq!(tabulated(&t, 900.0), 3.0);
    }

    /// A one-channel `width × height` bitmap, nearest lookup, clamped.
    fn scalar_bitmap(width: usize, height: usize, data: Vec<f32>) -> BitmapTexture {
        BitmapTexture {
            width,
            height,
            channels: 1,
            data,
            filter: TextureFilter::Nearest,
            wrap: WrapMode::Clamp,
            to_uv: Mat3::IDENTITY,
            value_range: None,
            path: None,
        }
    }

    #[test]
    fn bitmap_scalar_lookup_and_range() {
        let b = scalar_bitmap(2, 1, vec![100.0, 300.0]);
        let t = Texture::Bitmap(Arc::new(b.clone()));
        assert_eq!(t.eval_scalar(Vec2::new(0.1, 0.5)), 100.0);
        assert_eq!(t.eval_scalar(Vec2::new(0.9, 0.5)), 300.0);
        let mut r = b;
        r.data = vec![0.0, 1.0];
        r.value_range = Some((200.0, 600.0));
        let t = Texture::Bitmap(Arc::new(r));
        assert_eq!(t.eval_scalar(Vec2::new(0.9, 0.5)), 600.0);
    }

    /// Mitsuba 3's bitmap puts v = 0 on the image's first (top) row; a flipped lookup made
    /// textured thin films disagree with the Mitsuba references by ΔE00 ≈ 5.
    #[test]
    fn bitmap_v_zero_is_the_top_row() {
        let b = scalar_bitmap(1, 2, vec![100.0, 300.0]);
        let t = Texture::Bitmap(Arc::new(b));
        assert_eq!(t.eval_scalar(Vec2::new(0.5, 0.1)), 100.0);
        assert_eq!(t.eval_scalar(Vec2::new(0.5, 0.9)), 300.0);
    }
}
