//! A small raster drawing toolkit for labelled figures: an 8-bit RGB [`Canvas`], text with
//! DejaVu Sans (ab_glyph, the font is compiled in), tone-mapped image panels, heat maps with a
//! colour bar, and [`compose_panels`] that lays titled panels out in a row.
//!
//! [`compose_comparison`] builds the `thinfilm compare --figure` layout, A | B | ΔE00 heat map,
//! with the metrics printed under the panels. The `figure` command reuses the same primitives
//! (ground truth | fitted | ΔE).

use super::metrics::{delta_e00_map, percentile, ImageMetrics};
use crate::image_io::{write_png_rgb8, RgbImage};
use ab_glyph::{Font, FontRef, PxScale, ScaleFont};
use anyhow::{bail, Result};
use std::path::Path;
use std::sync::OnceLock;

use crate::image_io::FONT_BYTES;

fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_BYTES).expect("bundled DejaVuSans.ttf parses"))
}

pub const WHITE: [u8; 3] = [255, 255, 255];
pub const BLACK: [u8; 3] = [0, 0, 0];

/// An 8-bit sRGB-encoded raster, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<[u8; 3]>,
}

impl Canvas {
    pub fn new(width: usize, height: usize, background: [u8; 3]) -> Self {
        Canvas {
            width,
            height,
            pixels: vec![background; width * height],
        }
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> [u8; 3] {
        self.pixels[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.width && y < self.height {
            self.pixels[y * self.width + x] = c;
        }
    }

    /// Tone-maps a linear sRGB image: multiply by `exposure`, clamp to [0, 1], sRGB-encode.
    /// Non-finite pixels are drawn magenta so they cannot hide.
    pub fn from_linear(image: &RgbImage, exposure: f32) -> Self {
        let pixels = image
            .pixels
            .iter()
            .map(|p| {
                if p.iter().any(|v| !v.is_finite()) {
                    return [255, 0, 255];
                }
                p.map(|v| {
                    let e = srgb_encode(((v * exposure) as f64).clamp(0.0, 1.0));
                    (e * 255.0 + 0.5) as u8
                })
            })
            .collect();
        Canvas {
            width: image.width,
            height: image.height,
            pixels,
        }
    }

    /// Nearest-neighbour integer upscale (keeps pixels crisp in figures of small renders).
    pub fn upscale(&self, factor: usize) -> Canvas {
        let f = factor.max(1);
        let mut out = Canvas::new(self.width * f, self.height * f, BLACK);
        for y in 0..out.height {
            for x in 0..out.width {
                out.pixels[y * out.width + x] = self.get(x / f, y / f);
            }
        }
        out
    }

    pub fn fill_rect(&mut self, x: usize, y: usize, w: usize, h: usize, c: [u8; 3]) {
        for yy in y..(y + h).min(self.height) {
            for xx in x..(x + w).min(self.width) {
                self.pixels[yy * self.width + xx] = c;
            }
        }
    }

    /// Copies `src` with its top-left corner at (x, y), clipped to this canvas.
    pub fn blit(&mut self, src: &Canvas, x: usize, y: usize) {
        for sy in 0..src.height {
            for sx in 0..src.width {
                self.set(x + sx, y + sy, src.get(sx, sy));
            }
        }
    }

    /// Draws `text` with its top-left at (x, y), cap height ≈ 0.73 `size_px`; returns the
    /// advance width in pixels. Coverage is alpha-blended over what is there.
    pub fn draw_text(&mut self, text: &str, x: f32, y: f32, size_px: f32, colour: [u8; 3]) -> f32 {
        let font = font();
        let scaled = font.as_scaled(PxScale::from(size_px));
        let baseline = y + scaled.ascent();
        let mut pen = x;
        let mut prev = None;
        for ch in text.chars() {
            let id = font.glyph_id(ch);
            if let Some(p) = prev {
                pen += scaled.kern(p, id);
            }
            let glyph = id.with_scale_and_position(size_px, ab_glyph::point(pen, baseline));
            if let Some(outline) = font.outline_glyph(glyph) {
                let b = outline.px_bounds();
                outline.draw(|gx, gy, cov| {
                    let px = b.min.x as i64 + gx as i64;
                    let py = b.min.y as i64 + gy as i64;
                    if px < 0 || py < 0 || px as usize >= self.width || py as usize >= self.height {
                        return;
                    }
                    let (px, py) = (px as usize, py as usize);
                    let bg = self.get(px, py);
                    let a = cov.clamp(0.0, 1.0);
                    let mixed = std::array::from_fn(|c| {
                        (bg[c] as f32 * (1.0 - a) + colour[c] as f32 * a + 0.5) as u8
                    });
                    self.set(px, py, mixed);
                });
            }
            pen += scaled.h_advance(id);
            prev = Some(id);
        }
        pen - x
    }

    pub fn save_png(&self, path: &Path) -> Result<()> {
        let bytes = self.pixels.iter().flat_map(|p| p.iter().copied()).collect();
        write_png_rgb8(path, self.width, self.height, bytes)
    }
}

/// Advance width of `text` at `size_px`, for centring and layout.
pub fn text_width(text: &str, size_px: f32) -> f32 {
    let font = font();
    let scaled = font.as_scaled(PxScale::from(size_px));
    let mut w = 0.0;
    let mut prev = None;
    for ch in text.chars() {
        let id = font.glyph_id(ch);
        if let Some(p) = prev {
            w += scaled.kern(p, id);
        }
        w += scaled.h_advance(id);
        prev = Some(id);
    }
    w
}

/// Line height (ascent − descent + gap) at `size_px`.
pub fn line_height(size_px: f32) -> f32 {
    let s = font().as_scaled(PxScale::from(size_px));
    s.ascent() - s.descent() + s.line_gap()
}

/// sRGB transfer curve (IEC 61966-2-1), kept local so figures do not depend on the colour
/// module for 8-bit output.
fn srgb_encode(linear: f64) -> f64 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

/// Colour maps for heat maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Colormap {
    /// Matplotlib's perceptually uniform viridis (dark blue → yellow).
    Viridis,
    /// Grey ramp, black → white.
    Grey,
}

impl Colormap {
    /// Colour at `t` in [0, 1] (clamped; NaN maps to magenta).
    pub fn map(self, t: f64) -> [u8; 3] {
        if t.is_nan() {
            return [255, 0, 255];
        }
        let t = t.clamp(0.0, 1.0);
        match self {
            Colormap::Grey => {
                let v = (t * 255.0 + 0.5) as u8;
                [v, v, v]
            }
            Colormap::Viridis => crate::image_io::viridis(t),
        }
    }
}

/// Heat map of `values` (row-major `width × height`) over [0, `vmax`].
pub fn heatmap(
    values: &[f64],
    width: usize,
    height: usize,
    vmax: f64,
    cmap: Colormap,
) -> Result<Canvas> {
    if values.len() != width * height {
        bail!(
            "heat map: {} values for {width}×{height} pixels",
            values.len()
        );
    }
    if !(vmax > 0.0 && vmax.is_finite()) {
        bail!("heat map: vmax must be positive and finite, got {vmax}");
    }
    Ok(Canvas {
        width,
        height,
        pixels: values.iter().map(|&v| cmap.map(v / vmax)).collect(),
    })
}

/// A vertical colour bar `height` pixels tall for [0, `vmax`] with tick labels at 0, ½ and
/// `vmax` to the right of a `bar_width` ramp, and an optional title above.
pub fn colour_bar(height: usize, vmax: f64, cmap: Colormap, title: &str, font_px: f32) -> Canvas {
    let bar_width = 16;
    let ticks = [0.0, 0.5 * vmax, vmax];
    let labels: Vec<String> = ticks.iter().map(|t| format_tick(*t)).collect();
    let label_w = labels
        .iter()
        .map(|l| text_width(l, font_px))
        .fold(0.0f32, f32::max);
    let title_h = if title.is_empty() {
        0
    } else {
        line_height(font_px).ceil() as usize + 4
    };
    let pad = (font_px / 2.0).ceil() as usize;
    let width = (bar_width + 6 + label_w.ceil() as usize + 2)
        .max(text_width(title, font_px).ceil() as usize + 2);
    let mut c = Canvas::new(width, height + title_h + 2 * pad, WHITE);
    if !title.is_empty() {
        c.draw_text(title, 0.0, 0.0, font_px, BLACK);
    }
    let top = title_h + pad;
    for y in 0..height {
        // top of the bar is vmax
        let t = 1.0 - y as f64 / (height.max(2) - 1) as f64;
        c.fill_rect(0, top + y, bar_width, 1, cmap.map(t));
    }
    let lh = line_height(font_px);
    for (t, l) in ticks.iter().zip(&labels) {
        let y = top as f32 + (1.0 - (*t / vmax) as f32) * (height.max(2) - 1) as f32;
        c.fill_rect(bar_width, y as usize, 4, 1, BLACK);
        c.draw_text(l, (bar_width + 6) as f32, y - lh / 2.0, font_px, BLACK);
    }
    c
}

fn format_tick(v: f64) -> String {
    if v == v.round() {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// The smallest of 1, 2, 2.5, 5 × 10^k that is ≥ `v` (a readable colour-bar maximum).
pub fn nice_ceiling(v: f64) -> f64 {
    if !(v > 0.0 && v.is_finite()) {
        return 1.0;
    }
    let e = 10f64.powf(v.log10().floor());
    for m in [1.0, 2.0, 2.5, 5.0, 10.0] {
        if m * e >= v * (1.0 - 1e-12) {
            return m * e;
        }
    }
    10.0 * e
}

/// One titled image in a figure row, with optional caption lines beneath it.
#[derive(Debug, Clone)]
pub struct Panel {
    pub image: Canvas,
    pub title: String,
    pub caption: Vec<String>,
}

/// Lays panels out left to right on white, titles above, captions below, and an optional
/// colour bar at the right end aligned with the images' top.
pub fn compose_panels(panels: &[Panel], colour_bar: Option<&Canvas>, font_px: f32) -> Canvas {
    let margin = 10usize;
    let gap = 12usize;
    let lh = line_height(font_px).ceil() as usize;
    let img_h = panels.iter().map(|p| p.image.height).max().unwrap_or(0);
    let n_caption = panels.iter().map(|p| p.caption.len()).max().unwrap_or(0);
    let col_w: Vec<usize> = panels
        .iter()
        .map(|p| {
            let text_w = std::iter::once(&p.title)
                .chain(&p.caption)
                .map(|t| text_width(t, font_px).ceil() as usize)
                .max()
                .unwrap_or(0);
            p.image.width.max(text_w)
        })
        .collect();
    let bar_w = colour_bar.map(|b| b.width + gap).unwrap_or(0);
    let bar_h = colour_bar.map(|b| b.height).unwrap_or(0);
    let width =
        2 * margin + col_w.iter().sum::<usize>() + gap * panels.len().saturating_sub(1) + bar_w;
    let body_h = (img_h + lh / 2 + n_caption * lh).max(bar_h);
    let height = 2 * margin + lh + 4 + body_h;
    let mut c = Canvas::new(width, height, WHITE);
    let img_top = margin + lh + 4;
    let mut x = margin;
    for (p, &w) in panels.iter().zip(&col_w) {
        let tx = x as f32 + (w as f32 - text_width(&p.title, font_px)) / 2.0;
        c.draw_text(&p.title, tx, margin as f32, font_px, BLACK);
        c.blit(&p.image, x + (w - p.image.width) / 2, img_top);
        for (i, line) in p.caption.iter().enumerate() {
            let y = img_top + p.image.height + lh / 4 + i * lh;
            c.draw_text(line, x as f32, y as f32, font_px, BLACK);
        }
        x += w + gap;
    }
    if let Some(b) = colour_bar {
        c.blit(
            b,
            x,
            img_top.saturating_sub(b.height.saturating_sub(img_h) / 2 + lh + 4),
        );
    }
    c
}

/// Options for [`compose_comparison`].
#[derive(Debug, Clone)]
pub struct ComparisonStyle {
    /// Linear exposure applied to both images before the sRGB curve.
    pub exposure: f32,
    /// Colour-bar maximum of the ΔE00 map; `None` picks a round number ≥ the 99th percentile.
    pub delta_e_max: Option<f64>,
    /// Integer upscale; `None` picks the smallest making panels ≥ 240 px wide.
    pub scale: Option<usize>,
    pub font_px: f32,
}

impl Default for ComparisonStyle {
    fn default() -> Self {
        ComparisonStyle {
            exposure: 1.0,
            delta_e_max: None,
            scale: None,
            font_px: 15.0,
        }
    }
}

/// A | B | ΔE00 heat map with a colour bar, titled with the file names and captioned with
/// the metrics (B is the reference).
pub fn compose_comparison(
    a: &RgbImage,
    a_name: &str,
    b: &RgbImage,
    b_name: &str,
    metrics: &ImageMetrics,
    style: &ComparisonStyle,
) -> Result<Canvas> {
    let de = delta_e00_map(a, b)?;
    let scale = style
        .scale
        .unwrap_or_else(|| 240usize.div_ceil(a.width.max(1)).max(1));
    let vmax = style
        .delta_e_max
        .unwrap_or_else(|| nice_ceiling(percentile(&de, 0.99).max(1.0)));
    let heat = heatmap(&de, a.width, a.height, vmax, Colormap::Viridis)?.upscale(scale);
    let m = metrics;
    let bias = m.mean_bias_rgb;
    let panels = [
        Panel {
            image: Canvas::from_linear(a, style.exposure).upscale(scale),
            title: format!("A: {a_name}"),
            caption: vec![
                format!("RMSE {:.4}", m.rmse),
                format!("relMSE {:.4}", m.rel_mse),
            ],
        },
        Panel {
            image: Canvas::from_linear(b, style.exposure).upscale(scale),
            title: format!("B (reference): {b_name}"),
            caption: vec![
                format!(
                    "bias R {:+.2}% G {:+.2}% B {:+.2}%",
                    100.0 * bias[0],
                    100.0 * bias[1],
                    100.0 * bias[2]
                ),
                format!("{}×{} px", a.width, a.height),
            ],
        },
        Panel {
            image: heat,
            title: "ΔE00".to_string(),
            caption: vec![
                format!("mean {:.3}", m.delta_e00_mean),
                format!("95th pct {:.3}", m.delta_e00_p95),
            ],
        },
    ];
    let bar = colour_bar(
        a.height * scale,
        vmax,
        Colormap::Viridis,
        "ΔE00",
        style.font_px,
    );
    Ok(compose_panels(&panels, Some(&bar), style.font_px))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::metrics::ImageMetrics;

    fn dummy_metrics(w: usize, h: usize) -> ImageMetrics {
        ImageMetrics {
            width: w,
            height: h,
            rmse: 0.01,
            rel_mse: 0.002,
            delta_e00_mean: 0.5,
            delta_e00_p95: 1.2,
            mean_bias_rgb: [0.001, -0.002, 0.0],
            mean_rgb_a: [0.5; 3],
            mean_rgb_b: [0.5; 3],
        }
    }

    #[test]
    fn text_draws_dark_pixels_on_white() {
        let mut c = Canvas::new(120, 30, WHITE);
        let w = c.draw_text("ΔE00 1.5", 2.0, 2.0, 16.0, BLACK);
        assert!(w > 30.0 && w < 118.0, "advance {w}");
        let dark = c.pixels.iter().filter(|p| p[0] < 128).count();
        assert!(dark > 40, "only {dark} dark pixels");
        // nothing drawn right of the advance
        for y in 0..30 {
            for x in (w.ceil() as usize + 3)..120 {
                assert_eq!(c.get(x, y), WHITE);
            }
        }
        assert!((text_width("ΔE00 1.5", 16.0) - w).abs() < 1e-3);
    }

    #[test]
    fn viridis_endpoints_and_clamping() {
        assert_eq!(Colormap::Viridis.map(0.0), [68, 1, 84]);
        assert_eq!(Colormap::Viridis.map(1.0), [253, 231, 37]);
        assert_eq!(Colormap::Viridis.map(7.0), [253, 231, 37]);
        assert_eq!(Colormap::Viridis.map(-1.0), [68, 1, 84]);
        assert_eq!(Colormap::Viridis.map(f64::NAN), [255, 0, 255]);
        assert_eq!(Colormap::Grey.map(0.5), [128, 128, 128]);
    }

    #[test]
    fn nice_ceiling_rounds_up() {
        assert_eq!(nice_ceiling(0.7), 1.0);
        assert_eq!(nice_ceiling(1.0), 1.0);
        assert_eq!(nice_ceiling(1.3), 2.0);
        assert_eq!(nice_ceiling(2.2), 2.5);
        assert_eq!(nice_ceiling(3.0), 5.0);
        assert_eq!(nice_ceiling(7.0), 10.0);
        assert_eq!(nice_ceiling(f64::NAN), 1.0);
    }

    #[test]
    fn heatmap_rejects_bad_input() {
        assert!(heatmap(&[0.0; 3], 2, 2, 1.0, Colormap::Viridis).is_err());
        assert!(heatmap(&[0.0; 4], 2, 2, 0.0, Colormap::Viridis).is_err());
        let h = heatmap(&[0.0, 1.0, 2.0, 0.5], 2, 2, 1.0, Colormap::Grey).unwrap();
        assert_eq!(h.pixels, vec![[0; 3], [255; 3], [255; 3], [128; 3]]);
    }

    #[test]
    fn comparison_figure_layout() {
        let mut a = RgbImage::new(32, 24);
        let mut b = RgbImage::new(32, 24);
        for (i, p) in a.pixels.iter_mut().enumerate() {
            *p = [0.2, 0.4 + 0.01 * (i % 7) as f32, 0.1];
        }
        for p in b.pixels.iter_mut() {
            *p = [0.2, 0.4, 0.1];
        }
        let style = ComparisonStyle::default();
        let fig =
            compose_comparison(&a, "a.exr", &b, "b.exr", &dummy_metrics(32, 24), &style).unwrap();
        // scale = ceil(240/32) = 8 → three 256×192 panels plus a colour bar.
        assert!(fig.width >= 3 * 256 + 16, "width {}", fig.width);
        assert!(fig.height >= 192 + 2 * 15, "height {}", fig.height);
        // The title row above the panels holds text: some pixels differ from the background.
        let title_row_dark = (0..20)
            .flat_map(|y| (0..fig.width).map(move |x| (x, y)))
            .filter(|&(x, y)| fig.get(x, y) != WHITE)
            .count();
        assert!(
            title_row_dark > 50,
            "title text missing ({title_row_dark} px)"
        );
        // The caption area below the images holds text too.
        let below = fig.height - 40;
        let caption_dark = (below..fig.height)
            .flat_map(|y| (0..fig.width).map(move |x| (x, y)))
            .filter(|&(x, y)| fig.get(x, y) != WHITE)
            .count();
        assert!(
            caption_dark > 50,
            "caption text missing ({caption_dark} px)"
        );
        // Panel B shows the tone-mapped constant colour.
        let expect = Canvas::from_linear(&b, 1.0).get(0, 0);
        assert!(fig.pixels.contains(&expect));
        // Size mismatch is an error.
        let c = RgbImage::new(8, 8);
        assert!(compose_comparison(&a, "a", &c, "c", &dummy_metrics(8, 8), &style).is_err());
    }
}
