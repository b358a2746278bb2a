//! Error-against-time plots (log–log) with plotters, and the equal-error time ratio between
//! two convergence curves.

use crate::image_io::write_png_rgb8;
use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use std::path::Path;

/// One convergence curve: (seconds, error) points in increasing time.
#[derive(Debug, Clone)]
pub struct Series {
    /// The panel it is drawn in (e.g. the scene); panels appear in first-seen order.
    pub panel: String,
    /// Drawn as the other renderer: thin, cross-marked, second legend entry.
    pub secondary: bool,
    pub points: Vec<(f64, f64)>,
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

/// Colours of the primary and the secondary curves (ours, the other renderer).
const COLOURS: [RGBColor; 2] = [RGBColor(31, 119, 180), RGBColor(255, 127, 14)];

/// Error against time as small multiples: one log–log panel per `Series::panel`, all panels
/// on the same axes (so scenes compare across panels too), primary and secondary curves in
/// two fixed colours, and the legend in a strip above the panels where it covers no data.
/// `legend` names the primary and the secondary curves. Writes a PNG `panel_px` per panel.
pub fn plot_error_vs_time(
    series: &[Series],
    title: &str,
    legend: [&str; 2],
    y_label: &str,
    path: &Path,
    panel_px: (u32, u32),
) -> Result<()> {
    crate::image_io::register_plot_font();
    let positive = |&(t, e): &(f64, f64)| t > 0.0 && e > 0.0 && t.is_finite() && e.is_finite();
    let (mut t0, mut t1, mut e0, mut e1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(t, e) in series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| positive(p))
    {
        t0 = t0.min(t);
        t1 = t1.max(t);
        e0 = e0.min(e);
        e1 = e1.max(e);
    }
    if t0 > t1 {
        bail!("nothing to plot: no positive (time, error) points");
    }
    let mut panels: Vec<&str> = Vec::new();
    for s in series {
        if !panels.contains(&s.panel.as_str()) {
            panels.push(&s.panel);
        }
    }
    let cols = (panels.len() as f64).sqrt().ceil().max(1.0) as u32;
    let rows = (panels.len() as u32).div_ceil(cols);
    let header = 64u32;
    let (w, h) = (cols * panel_px.0, header + rows * panel_px.1);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let err = |e: &dyn std::fmt::Display| anyhow!("plot: {e}");
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let (top, body) = root.split_vertically(header);
        top.draw_text(
            title,
            &("sans-serif", 20).into_font().color(&BLACK),
            (12, 8),
        )
        .map_err(|e| err(&e))?;
        // The legend: a line and marker per renderer, in the header strip.
        for (k, name) in legend.iter().enumerate() {
            let x = 12 + k as i32 * 260;
            let y = 46;
            let c = COLOURS[k];
            top.draw(&PathElement::new(
                vec![(x, y), (x + 30, y)],
                c.stroke_width(2),
            ))
            .map_err(|e| err(&e))?;
            if k == 0 {
                top.draw(&Circle::new((x + 15, y), 3, c.filled()))
            } else {
                top.draw(&Cross::new((x + 15, y), 4, c.stroke_width(1)))
            }
            .map_err(|e| err(&e))?;
            top.draw_text(
                name,
                &("sans-serif", 15).into_font().color(&BLACK),
                (x + 38, y - 8),
            )
            .map_err(|e| err(&e))?;
        }
        let areas = body.split_evenly((rows as usize, cols as usize));
        for (name, area) in panels.iter().zip(&areas) {
            let mut chart = ChartBuilder::on(area)
                .caption(*name, ("sans-serif", 15))
                .margin(6)
                .x_label_area_size(32)
                .y_label_area_size(52)
                .build_cartesian_2d(
                    (t0 / 1.3..t1 * 1.3).log_scale(),
                    (e0 / 1.3..e1 * 1.3).log_scale(),
                )
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc("render time, s")
                .y_desc(y_label)
                .label_style(("sans-serif", 11))
                .axis_desc_style(("sans-serif", 12))
                .x_labels(5)
                .y_labels(5)
                .x_label_formatter(&|v| short_number(*v))
                .y_label_formatter(&|v| short_number(*v))
                .draw()
                .map_err(|e| err(&e))?;
            for s in series.iter().filter(|s| s.panel == *name) {
                let c = COLOURS[s.secondary as usize];
                let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(positive).collect();
                let style = c.stroke_width(if s.secondary { 1 } else { 2 });
                chart
                    .draw_series(LineSeries::new(pts.clone(), style))
                    .map_err(|e| err(&e))?;
                if s.secondary {
                    chart.draw_series(pts.iter().map(|&p| Cross::new(p, 4, c.stroke_width(1))))
                } else {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
                }
                .map_err(|e| err(&e))?;
            }
        }
        root.present().map_err(|e| err(&e))?;
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
    fn plot_draws_one_panel_per_scene_on_shared_axes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let curve = |panel: &str, secondary, scale: f64| Series {
            panel: panel.into(),
            secondary,
            points: vec![(0.1 * scale, 0.1), (0.4 * scale, 0.05)],
        };
        let s = [
            curve("a", false, 1.0),
            curve("a", true, 2.0),
            curve("b", false, 1.0),
            curve("c", false, 1.0),
        ];
        plot_error_vs_time(&s, "t", ["ours", "theirs"], "RMSE", &path, (200, 150)).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        // Three panels: 2 × 2 grid under the 64-px legend strip.
        assert_eq!(img.dimensions(), (400, 64 + 300));
        // Both curve colours are drawn, and the empty fourth cell stays white.
        let has = |c: RGBColor| img.pixels().any(|p| p.0 == [c.0, c.1, c.2]);
        assert!(has(COLOURS[0]) && has(COLOURS[1]));
        let empty = (200..400).all(|x| (64 + 150..364).all(|y| img.get_pixel(x, y).0 == [255; 3]));
        assert!(empty, "the fourth cell should be empty");
        assert!(plot_error_vs_time(&[], "t", ["a", "b"], "RMSE", &path, (200, 150)).is_err());
    }
}
