//! Writing a fit: `fit.json`, `thickness.exr`, colour-mapped PNGs (with a scale bar, like
//! the seed's Fig. 5), `material.xml` (Mitsuba-style `thinfilm` BSDF) and `material.gltf`
//! (KHR_materials_iridescence). Also the seed's "BRDF error": mean ΔE*ab (D65) between
//! measured and model spectra over every pixel and angle (seed eq. 15), and RMSE (eq. 16).

use super::model::Geometry;
use super::Fit;
use crate::capture::{CaptureSet, GroundTruth};
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::path::Path;

/// JSON number, or null for non-finite values (fit.json never holds NaN).
pub fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// Thickness statistics over fitted pixels.
#[derive(Debug, Clone, Copy)]
pub struct Stats {
    pub mean: f64,
    pub median: f64,
    pub p5: f64,
    pub p95: f64,
    pub min: f64,
    pub max: f64,
}

/// Linear-interpolated percentile (same definition as on sorted data: between the
/// ⌊q(n−1)⌋-th and the next order statistic), found by selection in O(n) — a
/// megapixel map is sorted in ~0.1 s, and the outputs ask for several percentiles.
/// Reorders `v`; `v` must be non-empty and NaN-free.
fn pct(v: &mut [f64], q: f64) -> f64 {
    let x = q * (v.len() - 1) as f64;
    let i = x.floor() as usize;
    let (_, &mut lo, right) = v.select_nth_unstable_by(i, f64::total_cmp);
    let hi = right.iter().copied().min_by(f64::total_cmp).unwrap_or(lo);
    lo + (hi - lo) * (x - i as f64)
}

pub fn thickness_stats(d: &[f32]) -> Option<Stats> {
    let mut v: Vec<f64> = d
        .iter()
        .filter(|x| x.is_finite())
        .map(|&x| x as f64)
        .collect();
    if v.is_empty() {
        return None;
    }
    // Mean in the input's order (selection reorders v).
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(Stats {
        mean,
        median: pct(&mut v, 0.5),
        p5: pct(&mut v, 0.05),
        p95: pct(&mut v, 0.95),
        min,
        max,
    })
}

/// XYZ weights per band for a tabulated reflectance (the XYZ integral is linear in the
/// samples, so three rows of weights reproduce `tabulated_reflectance_xyz_d65` exactly).
/// `Err` when the colour tables are unavailable.
fn xyz_weights(lambdas: &[f64]) -> Result<Vec<[f64; 3]>, String> {
    let lambdas = lambdas.to_vec();
    std::panic::catch_unwind(move || {
        (0..lambdas.len())
            .map(|b| {
                let mut e = vec![0.0; lambdas.len()];
                e[b] = 1.0;
                crate::spectrum::tabulated_reflectance_xyz_d65(&lambdas, &e)
            })
            .collect::<Vec<_>>()
    })
    .map_err(|_| "colour tables (crate::spectrum) unavailable in this build".to_string())
}

/// Mean ΔE*ab (CIE76, D65, Y of a perfect reflector = 1) between measured and model
/// spectra over fitted pixels (at most `max_pixels`, evenly spread) and their valid angles.
pub fn mean_delta_e(
    set: &CaptureSet,
    fit: &Fit,
    band_integration: bool,
    max_pixels: usize,
) -> Result<f64, String> {
    if set.wavelengths_nm.windows(2).any(|w| w[1] <= w[0]) {
        return Err("wavelengths are not ascending".into());
    }
    let wts = xyz_weights(&set.wavelengths_nm)?;
    let white = wts
        .iter()
        .fold([0.0; 3], |a, w| [a[0] + w[0], a[1] + w[1], a[2] + w[2]]);
    if !(white[1] > 0.0) {
        return Err("the bands carry no luminance (outside the visible range)".into());
    }
    let geom = Geometry::from_capture(set, band_integration);
    let model = geom.model(fit.film_ior);
    let fitted: Vec<usize> = (0..fit.thickness_nm.len())
        .filter(|&p| fit.thickness_nm[p].is_finite())
        .collect();
    let pixels = super::spread(&fitted, max_pixels);
    let nb = set.bands();
    let lab = |s: &[f32]| {
        let mut xyz = [0.0; 3];
        for (w, &v) in wts.iter().zip(s) {
            for c in 0..3 {
                xyz[c] += w[c] * v as f64;
            }
        }
        crate::spectrum::xyz_to_lab(xyz, white)
    };
    let run = || {
        use rayon::prelude::*;
        // Per-pixel sums in parallel, added in pixel order (same result on any thread count).
        let per_pixel: Vec<(f64, usize)> = pixels
            .par_iter()
            .map_init(
                || vec![0f32; nb],
                |r, &p| {
                    let (mut sum, mut count) = (0.0, 0usize);
                    for (a, ang) in set.angles.iter().enumerate() {
                        let y = &ang.reflectance[p * nb..(p + 1) * nb];
                        if !ang.valid[p] || y.iter().any(|v| !v.is_finite()) {
                            continue;
                        }
                        model.spectrum(a, fit.thickness_nm[p] as f64, r);
                        let de = crate::spectrum::delta_e76(lab(y), lab(r));
                        if de.is_finite() {
                            sum += de;
                            count += 1;
                        }
                    }
                    (sum, count)
                },
            )
            .collect();
        let (sum, count) = per_pixel
            .iter()
            .fold((0.0, 0usize), |a, b| (a.0 + b.0, a.1 + b.1));
        (count > 0).then(|| sum / count as f64)
    };
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)) {
        Ok(Some(v)) => Ok(v),
        Ok(None) => Err("no fitted pixel".into()),
        Err(_) => Err("colour conversion (crate::spectrum) unavailable in this build".into()),
    }
}

/// Errors against ground truth.
#[derive(Debug, Clone, Copy)]
pub struct TruthErrors {
    pub film_ior_true: f64,
    pub film_ior_abs_error: f64,
    pub thickness_mae_nm: f64,
    pub thickness_mean_error_nm: f64,
    pub mean_thickness_true_nm: f64,
    pub pixels_compared: usize,
}

pub fn truth_errors(fit: &Fit, film_ior_true: f64, truth: &[f32]) -> TruthErrors {
    let (mae, signed, n) = super::synth::thickness_errors(&fit.thickness_nm, truth);
    let tstats = thickness_stats(truth);
    TruthErrors {
        film_ior_true,
        film_ior_abs_error: (fit.film_ior - film_ior_true).abs(),
        thickness_mae_nm: mae,
        thickness_mean_error_nm: signed,
        mean_thickness_true_nm: tstats.map(|s| s.mean).unwrap_or(f64::NAN),
        pixels_compared: n,
    }
}

/// Builds fit.json.
pub fn fit_json(
    set: &CaptureSet,
    fit: &Fit,
    delta_e: &Result<f64, String>,
    truth: Option<&TruthErrors>,
    extra_seconds: &[(String, f64)],
) -> Value {
    let stats = thickness_stats(&fit.thickness_nm);
    let st = |f: fn(&Stats) -> f64| stats.as_ref().map(|s| num(f(s))).unwrap_or(Value::Null);
    let mut seconds = serde_json::Map::new();
    let mut total = 0.0;
    for (k, v) in fit.stage_seconds.iter().chain(extra_seconds) {
        seconds.insert(k.clone(), num(*v));
        total += v;
    }
    seconds.insert("total".into(), num(total));
    let sub = set.substrate_ior.at(550.0);
    let rmse = fit.rmse();
    let mut v = json!({
        "format": "thinfilm-fit/1",
        "method": fit.method.to_string(),
        "film_ior": num(fit.film_ior),
        "film_ior_uncertainty": fit.film_ior_sigma.map(num).unwrap_or(Value::Null),
        "film_ior_note": fit.film_ior_note,
        "ambient_ior": num(set.ambient_ior),
        "substrate_ior": num(sub.re),
        "substrate_k": num(sub.im),
        "substrate": set.substrate_ior.to_string(),
        "polarization": set.polarization,
        "incident_deg": set.angles.iter().map(|a| num(a.incident_deg)).collect::<Vec<_>>(),
        "bands": set.bands(),
        "width": fit.width,
        "height": fit.height,
        "thickness_nm": {
            "mean": st(|s| s.mean), "median": st(|s| s.median),
            "p5": st(|s| s.p5), "p95": st(|s| s.p95),
            "min": st(|s| s.min), "max": st(|s| s.max),
        },
        "pixels": {
            "valid": fit.valid_pixels(),
            "invalid": fit.invalid_pixels,
            "unfitted": fit.unfitted_pixels,
        },
        "invalid_samples": set.invalid,
        "residual_rmse": rmse.map(num).unwrap_or(Value::Null),
        "delta_e_ab_d65_mean": delta_e.as_ref().map(|v| num(*v)).unwrap_or(Value::Null),
        "seconds": seconds,
        "warnings": fit.warnings,
    });
    if fit.film_ior_sigma.is_none() {
        v["film_ior_uncertainty_reason"] = json!(if fit.film_ior_note.starts_with("given") {
            "index given by the user"
        } else {
            "the method gives no uncertainty"
        });
    }
    if rmse.is_none() {
        v["residual_rmse_reason"] = json!("no pixel was fitted");
    }
    if stats.is_none() {
        v["thickness_nm_reason"] = json!("no pixel was fitted");
    }
    if let Err(e) = delta_e {
        v["delta_e_reason"] = json!(e);
    }
    if let Some(t) = truth {
        v["ground_truth"] = json!({
            "film_ior": num(t.film_ior_true),
            "film_ior_abs_error": num(t.film_ior_abs_error),
            "mean_thickness_nm": num(t.mean_thickness_true_nm),
            "thickness_mae_nm": num(t.thickness_mae_nm),
            "thickness_mean_error_nm": num(t.thickness_mean_error_nm),
            "pixels_compared": t.pixels_compared,
        });
    }
    v
}

/// Viridis (polynomial fit by Matt Zucker, CC0), t in [0, 1] → sRGB8.
pub fn viridis(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    const C: [[f64; 3]; 7] = [
        [0.277_727_327, 0.005_407_345, 0.334_099_805],
        [0.105_093_043, 1.404_613_53, 1.384_590_163],
        [-0.330_861_829, 0.214_847_559, 0.095_095_163],
        [-4.634_230_499, -5.799_100_973, -19.332_440_96],
        [6.228_269_936, 14.179_933_37, 56.690_552_6],
        [4.776_384_998, -13.745_145_38, -65.353_032_63],
        [-5.435_455_856, 4.645_852_612, 26.312_435_25],
    ];
    let mut out = [0u8; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut v = C[6][c];
        for k in (0..6).rev() {
            v = C[k][c] + t * v;
        }
        *o = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    }
    out
}

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
        );
    });
}

/// Colour-mapped image of `values` (NaN → grey) with a labelled colour bar (Fig. 5 style).
pub fn write_colormap_png(
    path: &Path,
    values: &[f32],
    width: usize,
    height: usize,
    label: &str,
) -> Result<()> {
    use plotters::prelude::*;
    register_font();
    let mut finite: Vec<f64> = values
        .iter()
        .filter(|v| v.is_finite())
        .map(|&v| v as f64)
        .collect();
    let (lo, hi) = if finite.is_empty() {
        (0.0, 1.0)
    } else {
        let (a, b) = (pct(&mut finite, 0.005), pct(&mut finite, 0.995));
        if b > a {
            (a, b)
        } else {
            (a - 0.5, a + 0.5)
        }
    };
    let scale = (512 / width.max(1)).clamp(1, 8);
    let (mw, mh) = (width * scale, height * scale);
    let (iw, ih) = (mw + 170, mh.max(240) + 50);
    let mut buf = vec![255u8; iw * ih * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (iw as u32, ih as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
        for y in 0..height {
            for x in 0..width {
                let v = values[y * width + x];
                let c = if v.is_finite() {
                    let [r, g, b] = viridis((v as f64 - lo) / (hi - lo));
                    RGBColor(r, g, b)
                } else {
                    RGBColor(128, 128, 128)
                };
                let (x0, y0) = ((x * scale + 10) as i32, (y * scale + 40) as i32);
                root.draw(&Rectangle::new(
                    [(x0, y0), (x0 + scale as i32, y0 + scale as i32)],
                    c.filled(),
                ))
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            }
        }
        root.draw(&Text::new(
            label.to_string(),
            (10, 12),
            ("sans-serif", 18).into_font(),
        ))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
        // Colour bar.
        let (bx, by, bh) = (mw as i32 + 30, 40i32, mh.max(200) as i32 - 10);
        for i in 0..bh {
            let t = 1.0 - i as f64 / (bh - 1).max(1) as f64;
            let [r, g, b] = viridis(t);
            root.draw(&Rectangle::new(
                [(bx, by + i), (bx + 20, by + i + 1)],
                RGBColor(r, g, b).filled(),
            ))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        for k in 0..=4 {
            let t = k as f64 / 4.0;
            let v = hi - t * (hi - lo);
            let yy = by + (t * (bh - 1) as f64) as i32;
            root.draw(&PathElement::new(vec![(bx + 20, yy), (bx + 26, yy)], BLACK))
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let txt = if (hi - lo) < 0.1 {
                format!("{v:.4}")
            } else {
                format!("{v:.1}")
            };
            root.draw(&Text::new(
                txt,
                (bx + 30, yy - 7),
                ("sans-serif", 14).into_font(),
            ))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    crate::image_io::write_png_rgb8(path, iw, ih, buf)
}

/// `material.xml`: the `thinfilm` BSDF with the fitted index and the thickness texture.
pub fn material_xml(fit: &Fit, set: &CaptureSet) -> String {
    let sub = set.substrate_ior.at(550.0);
    let stats = thickness_stats(&fit.thickness_nm);
    format!(
        "<!-- thinfilm estimate ({method}): film index and per-pixel thickness (nm) fitted from a capture.\n     \
         Substrate index evaluated at 550 nm ({subname}). Mean thickness {mean}. -->\n\
         <bsdf type=\"thinfilm\" id=\"fitted_film\">\n    \
         <float name=\"film_ior\" value=\"{n:.6}\"/>\n    \
         <texture type=\"bitmap\" name=\"thickness\">\n        \
         <string name=\"filename\" value=\"thickness.exr\"/>\n        \
         <boolean name=\"raw\" value=\"true\"/>\n        \
         <string name=\"filter_type\" value=\"bilinear\"/>\n    \
         </texture>\n    \
         <float name=\"substrate_ior\" value=\"{sn:.6}\"/>\n    \
         <float name=\"substrate_k\" value=\"{sk:.6}\"/>\n\
         </bsdf>\n",
        method = fit.method,
        subname = set.substrate_ior,
        mean = stats.map(|s| format!("{:.2} nm", s.mean)).unwrap_or_else(|| "n/a".into()),
        n = fit.film_ior,
        sn = sub.re,
        sk = sub.im,
    )
}

/// glTF thickness texture: G = (d − min)/(max − min); invalid pixels take the median.
pub fn gltf_texture(fit: &Fit) -> (Vec<u8>, f64, f64) {
    let s = thickness_stats(&fit.thickness_nm);
    let (lo, hi, med) = s
        .map(|s| (s.min, s.max, s.median))
        .unwrap_or((0.0, 0.0, 0.0));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut bytes = Vec::with_capacity(fit.thickness_nm.len() * 3);
    for &d in &fit.thickness_nm {
        let d = if d.is_finite() { d as f64 } else { med };
        let g = (((d - lo) / span).clamp(0.0, 1.0) * 255.0).round() as u8;
        bytes.extend_from_slice(&[0, g, 0]);
    }
    (bytes, lo, hi)
}

pub fn material_gltf(fit: &Fit, set: &CaptureSet, min: f64, max: f64, texture: &str) -> Value {
    let sub = set.substrate_ior.at(550.0);
    json!({
        "asset": {"version": "2.0", "generator": "thinfilm estimate"},
        "extensionsUsed": ["KHR_materials_iridescence", "KHR_materials_ior"],
        "materials": [{
            "name": "fitted_film",
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0},
            "extensions": {
                "KHR_materials_ior": {"ior": num(sub.re)},
                "KHR_materials_iridescence": {
                    "iridescenceFactor": 1.0,
                    "iridescenceIor": num(fit.film_ior),
                    "iridescenceThicknessMinimum": num(min),
                    "iridescenceThicknessMaximum": num(max),
                    "iridescenceThicknessTexture": {"index": 0}
                }
            }
        }],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729}],
        "images": [{"uri": texture, "mimeType": "image/png"}]
    })
}

/// Writes every output file of a fit into `out`, as one step (see
/// [`crate::image_io::write_files_atomically`]): other files in `out` are left alone, and a
/// failed or killed run leaves the previous outputs.
pub fn write_outputs(out: &Path, set: &CaptureSet, fit: &Fit, json: &Value) -> Result<()> {
    crate::image_io::write_files_atomically(out, |stage| write_outputs_into(stage, set, fit, json))
}

fn write_outputs_into(out: &Path, set: &CaptureSet, fit: &Fit, json: &Value) -> Result<()> {
    let (w, h) = (fit.width, fit.height);
    crate::image_io::write_exr_channels(
        &out.join("thickness.exr"),
        w,
        h,
        &[("thickness", &fit.thickness_nm)],
    )
    .context("writing thickness.exr")?;
    write_colormap_png(
        &out.join("thickness.png"),
        &fit.thickness_nm,
        w,
        h,
        "thickness (nm)",
    )
    .context("writing thickness.png")?;
    let rmse: Vec<f32> = fit
        .sse
        .iter()
        .zip(&fit.samples)
        .zip(&fit.thickness_nm)
        .map(|((&s, &c), d)| {
            if d.is_finite() && c > 0 {
                (s / c as f32).sqrt()
            } else {
                f32::NAN
            }
        })
        .collect();
    write_colormap_png(
        &out.join("residual.png"),
        &rmse,
        w,
        h,
        "residual RMSE (reflectance)",
    )
    .context("writing residual.png")?;
    let (tex, lo, hi) = gltf_texture(fit);
    crate::image_io::write_png_rgb8(&out.join("thickness_gltf.png"), w, h, tex)
        .context("writing thickness_gltf.png")?;
    let xml = material_xml(fit, set);
    crate::image_io::write_atomically(&out.join("material.xml"), |p| {
        Ok(std::fs::write(p, xml.as_bytes())?)
    })?;
    let gltf =
        serde_json::to_string_pretty(&material_gltf(fit, set, lo, hi, "thickness_gltf.png"))?;
    crate::image_io::write_atomically(&out.join("material.gltf"), |p| {
        Ok(std::fs::write(p, gltf.as_bytes())?)
    })?;
    let text = serde_json::to_string_pretty(json)?;
    crate::image_io::write_atomically(&out.join("fit.json"), |p| {
        Ok(std::fs::write(p, text.as_bytes())?)
    })?;
    Ok(())
}

/// Ground-truth errors from a loaded [`GroundTruth`] (sizes must match).
pub fn truth_from_ground_truth(fit: &Fit, gt: &GroundTruth) -> Result<TruthErrors> {
    if gt.width != fit.width || gt.height != fit.height {
        anyhow::bail!(
            "ground truth is {}×{} but the capture is {}×{}",
            gt.width,
            gt.height,
            fit.width,
            fit.height
        );
    }
    Ok(truth_errors(
        fit,
        gt.film_ior.at(550.0).re,
        &gt.thickness_nm,
    ))
}

/// What [`fit_capture_dir`] measured and wrote.
#[derive(Debug, Clone)]
pub struct FitRun {
    pub fit: Fit,
    /// Mean ΔE*ab (D65) between measured and model spectra, or why it is unavailable.
    pub delta_e: Result<f64, String>,
    pub truth: Option<TruthErrors>,
    /// Wall-clock seconds of the stages around the fit: `load`, `delta_e`, `write`.
    pub io_seconds: Vec<(String, f64)>,
    /// CPU seconds (all threads) of the same stages, where the platform reports them.
    pub io_cpu_seconds: Vec<(String, f64)>,
}

/// The whole `thinfilm estimate` job: load the capture set in `capture_dir`, fit it, compare
/// with a ground truth when given, and write every output into `out` (see [`write_outputs`]).
pub fn fit_capture_dir(
    capture_dir: &Path,
    out: &Path,
    opts: &super::Options,
    ground_truth: Option<&Path>,
) -> Result<FitRun> {
    use super::{Stages, Stopwatch};
    let mut io = Stages::default();
    let t = Stopwatch::start();
    let set = crate::capture::load_capture_set(capture_dir)
        .with_context(|| format!("loading capture set {}", capture_dir.display()))?;
    t.stop("load", &mut io);
    let fit = super::estimate(&set, opts)?;
    let t = Stopwatch::start();
    let delta_e = mean_delta_e(&set, &fit, opts.band_integration, 20_000);
    t.stop("delta_e", &mut io);
    let truth = match ground_truth {
        Some(dir) => {
            let gt = crate::capture::load_ground_truth(dir)
                .with_context(|| format!("loading ground truth {}", dir.display()))?;
            Some(truth_from_ground_truth(&fit, &gt)?)
        }
        None => None,
    };
    let json = fit_json(&set, &fit, &delta_e, truth.as_ref(), &io.wall);
    let t = Stopwatch::start();
    write_outputs(out, &set, &fit, &json)?;
    t.stop("write", &mut io);
    Ok(FitRun {
        fit,
        delta_e,
        truth,
        io_seconds: io.wall,
        io_cpu_seconds: io.cpu,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Selection-based percentiles equal interpolation between sorted order statistics.
    #[test]
    fn percentiles_match_sorted_definition() {
        let data: Vec<f64> = (0..1001)
            .map(|i| ((i * 7919) % 1009) as f64 * 0.5)
            .collect();
        let mut sorted = data.clone();
        sorted.sort_by(f64::total_cmp);
        for q in [0.0, 0.005, 0.05, 0.5, 0.95, 0.995, 1.0] {
            let x = q * (sorted.len() - 1) as f64;
            let i = x.floor() as usize;
            let j = (i + 1).min(sorted.len() - 1);
            let want = sorted[i] + (sorted[j] - sorted[i]) * (x - i as f64);
            let mut v = data.clone();
            assert_eq!(pct(&mut v, q), want, "q={q}");
        }
        let single = thickness_stats(&[f32::NAN, 3.0, f32::INFINITY]).unwrap();
        assert_eq!((single.min, single.median, single.max), (3.0, 3.0, 3.0));
        let s = thickness_stats(&[4.0, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!((s.min, s.median, s.max, s.mean), (1.0, 2.5, 4.0, 2.5));
        assert!(thickness_stats(&[f32::NAN]).is_none());
    }
}
