//! Error-against-time plots (log–log) with plotters, and the equal-error time ratio between
//! two convergence curves.

use super::figure::FONT_BYTES;
use crate::image_io::write_png_rgb8;
use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use std::path::Path;

/// One convergence curve: (seconds, error) points in increasing time.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// Index into the palette (curves of one scene share a colour).
    pub colour_index: usize,
    /// Draw as a dashed-look cross-marked curve (e.g. the other renderer).
    pub secondary: bool,
}

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Cannot fail for the bundled font; if it did, text drawing would report it.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES);
    });
}

/// Time needed to reach `error` on the curve `points` (seconds, error), interpolating
/// log t linearly in log e between the two nearest points and extrapolating from the end
/// segments. Monte Carlo error falls like t^(−1/2), a straight line in log–log.
/// `None` with fewer than two usable (positive, finite) points.
pub fn time_at_error(points: &[(f64, f64)], error: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && t.is_finite() && e.is_finite())
        .map(|&(t, e)| (t.ln(), e.ln()))
        .collect();
    if p.len() < 2 || !(error > 0.0 && error.is_finite()) {
        return None;
    }
    // Sort by decreasing error (increasing time for a converging curve).
    p.sort_by(|a, b| b.1.total_cmp(&a.1));
    let le = error.ln();
    let seg = p
        .windows(2)
        .position(|w| le <= w[0].1 && le >= w[1].1)
        .unwrap_or(if le > p[0].1 { 0 } else { p.len() - 2 });
    let (a, b) = (p[seg], p[seg + 1]);
    if (b.1 - a.1).abs() < 1e-12 {
        return Some(a.0.exp().min(b.0.exp()));
    }
    let f = (le - a.1) / (b.1 - a.1);
    Some((a.0 + f * (b.0 - a.0)).exp())
}

/// Three significant digits without float noise (0.0100000000001 → 0.01).
fn short_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// Draws all series on log–log axes (x: seconds, y: error) and writes a PNG.
pub fn plot_error_vs_time(
    series: &[Series],
    title: &str,
    y_label: &str,
    path: &Path,
    size: (u32, u32),
) -> Result<()> {
    register_font();
    let pts = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(t, e)| *t > 0.0 && *e > 0.0);
    let (mut t0, mut t1, mut e0, mut e1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(t, e) in pts {
        t0 = t0.min(t);
        t1 = t1.max(t);
        e0 = e0.min(e);
        e1 = e1.max(e);
    }
    if t0 > t1 {
        bail!("nothing to plot: no positive (time, error) points");
    }
    let (w, h) = size;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (t0 / 1.5..t1 * 1.5).log_scale(),
                (e0 / 1.5..e1 * 1.5).log_scale(),
            )
            .map_err(|e| anyhow!("plot: {e}"))?;
        chart
            .configure_mesh()
            .x_desc("render time, s")
            .y_desc(y_label)
            .label_style(("sans-serif", 13))
            .x_label_formatter(&|v| short_number(*v))
            .y_label_formatter(&|v| short_number(*v))
            .draw()
            .map_err(|e| anyhow!("plot: {e}"))?;
        for s in series {
            let c = PALETTE[s.colour_index % PALETTE.len()];
            let style = if s.secondary {
                c.mix(0.6).stroke_width(1)
            } else {
                c.stroke_width(2)
            };
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|(t, e)| *t > 0.0 && *e > 0.0)
                .collect();
            let anno = chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(|e| anyhow!("plot: {e}"))?;
            anno.label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
            if s.secondary {
                chart
                    .draw_series(pts.iter().map(|&p| Cross::new(p, 4, c.stroke_width(1))))
                    .map_err(|e| anyhow!("plot: {e}"))?;
            } else {
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
                    .map_err(|e| anyhow!("plot: {e}"))?;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| anyhow!("plot: {e}"))?;
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    write_png_rgb8(path, w as usize, h as usize, buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_at_error_interpolates_in_log_log() {
        // e = t^(-1/2): t at e is e^-2.
        let pts: Vec<(f64, f64)> = [1.0, 4.0, 16.0, 64.0]
            .iter()
            .map(|&t: &f64| (t, t.powf(-0.5)))
            .collect();
        for e in [0.5, 0.3, 0.2, 0.125] {
            let t = time_at_error(&pts, e).unwrap();
            assert!((t - e.powi(-2)).abs() / t < 1e-9, "e {e}: t {t}");
        }
        // Extrapolation beyond both ends follows the end segments.
        assert!((time_at_error(&pts, 2.0).unwrap() - 0.25).abs() < 1e-9);
        assert!((time_at_error(&pts, 0.0625).unwrap() - 256.0).abs() < 1e-6);
        assert!(time_at_error(&pts[..1], 0.5).is_none());
        assert!(time_at_error(&pts, f64::NAN).is_none());
        assert!(time_at_error(&[(1.0, 0.0), (2.0, 0.1)], 0.1).is_none());
    }

    #[test]
    fn axis_numbers_are_short() {
        assert_eq!(short_number(0.0100000000001), "0.01");
        assert_eq!(short_number(0.00123456), "0.00123");
        assert_eq!(short_number(12.5), "12.5");
        assert_eq!(short_number(100.0), "100");
    }

    #[test]
    fn plot_writes_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let s = vec![
            Series {
                label: "ours".into(),
                points: vec![(0.1, 0.1), (0.4, 0.05)],
                colour_index: 0,
                secondary: false,
            },
            Series {
                label: "mitsuba".into(),
                points: vec![(0.2, 0.1), (0.8, 0.05)],
                colour_index: 0,
                secondary: true,
            },
        ];
        plot_error_vs_time(&s, "t", "RMSE", &path, (400, 300)).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (400, 300));
        assert!(img.pixels().any(|p| p.0 != [255, 255, 255]));
        assert!(plot_error_vs_time(&[], "t", "RMSE", &path, (400, 300)).is_err());
    }
}
