//! Writing a fit: `fit.json` ([`FitFile`]), colour-mapped PNGs (with a scale bar, like the
//! seed's Fig. 5) and the material files of [`FilmMaterial::write_files`] (`thickness.exr`,
//! `material.xml`, `material.gltf`). Also the seed's "BRDF error": mean ΔE*ab (D65) between
//! measured and model spectra over every pixel and angle (seed eq. 15), and RMSE (eq. 16).

use super::film::{FilmIndex, FilmModelKind};
use super::model::Geometry;
use super::Fit;
use crate::capture::{CaptureSet, GroundTruth};
use crate::material::{
    finite, FilmMaterial, FilmModelFit, FitFile, MapStats, NoiseFit, NuisanceFit, PixelCounts,
    SubstrateFit, TruthComparison,
};
use crate::stats::{percentile, Summary};
use anyhow::{Context, Result};
use std::path::Path;

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
    let pixels = super::data::spread(&fitted, max_pixels);
    let nb = set.bands();
    // Fit pixel p is capture pixel p + offset (a fit of rows A:B starts at row A).
    let offset = fit.rows.0 * set.width;
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
                || (vec![0f32; nb], vec![0f32; nb]),
                |(y, r), &p| {
                    let (mut sum, mut count) = (0.0, 0usize);
                    let q = p + offset;
                    for (a, ang) in set.angles.iter().enumerate() {
                        if !ang.pixel(q, y) {
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
    let tstats = Summary::of_finite(truth);
    TruthErrors {
        film_ior_true,
        film_ior_abs_error: (fit.film_ior - film_ior_true).abs(),
        thickness_mae_nm: mae,
        thickness_mean_error_nm: signed,
        mean_thickness_true_nm: tstats.map(|s| s.mean).unwrap_or(f64::NAN),
        pixels_compared: n,
    }
}

/// The `fit.json` of a fit.
pub fn fit_json(
    set: &CaptureSet,
    fit: &Fit,
    delta_e: &Result<f64, String>,
    truth: Option<&TruthErrors>,
    extra_seconds: &[(String, f64)],
) -> FitFile {
    let stats = Summary::of_finite(&fit.thickness_nm);
    let mut seconds = std::collections::BTreeMap::new();
    let mut total = 0.0;
    for (k, v) in fit.stage_seconds.iter().chain(extra_seconds) {
        seconds.insert(k.clone(), finite(*v));
        total += v;
    }
    seconds.insert("total".into(), finite(total));
    let sub = set.substrate_ior.at(550.0);
    let rmse = fit.rmse();
    let film_model = match &fit.film {
        FilmIndex::Known(_) => None,
        f => {
            let cauchy = f
                .cauchy_coefficients()
                .filter(|_| f.kind() != Some(FilmModelKind::Constant));
            Some(FilmModelFit {
                model: f.kind().map(|k| k.to_string()).unwrap_or_default(),
                parameters_sigma: fit.film_param_sigma.iter().map(|v| finite(*v)).collect(),
                cauchy_a: cauchy.and_then(|c| finite(c.0)),
                cauchy_b_nm2: cauchy.and_then(|c| finite(c.1)),
                cauchy_c_nm4: cauchy.and_then(|c| finite(c.2)),
            })
        }
    };
    FitFile {
        format: crate::material::FIT_FORMAT.into(),
        method: fit.method.to_string(),
        film_ior: finite(fit.film_ior),
        film_index: fit.film_ior.is_finite().then(|| fit.film.to_ior()),
        film_model,
        substrate_fit: fit.substrate_sigma.map(|s| SubstrateFit {
            shift: finite(fit.substrate_shift),
            shift_sigma: finite(s),
            substrate_ior: finite(sub.re + fit.substrate_shift),
        }),
        nuisance: Some(NuisanceFit {
            model: fit.nuisance.spec.describe(),
            multiplier: fit.nuisance.multiplier.clone(),
            background: fit.nuisance.background.clone(),
        }),
        noise: Some(NoiseFit {
            typical: finite(fit.noise),
            source: fit.noise_source.clone(),
        }),
        chi2_per_dof: finite(fit.chi2_red),
        model_selection: fit.selection.clone(),
        thickness_sigma_nm: Some(MapStats::from(Summary::of_finite(&fit.thickness_sigma_nm))),
        thickness_sigma_file: Some(THICKNESS_SIGMA_EXR.into()),
        not_identifiable_pixels: fit.not_identifiable,
        film_ior_uncertainty: fit.film_ior_sigma.and_then(finite),
        film_ior_uncertainty_reason: fit.film_ior_sigma.is_none().then(|| {
            if fit.film_ior_note.starts_with("given") {
                "index given by the user"
            } else {
                "the method gives no uncertainty"
            }
            .to_string()
        }),
        film_ior_note: fit.film_ior_note.clone(),
        ambient_ior: finite(set.ambient_ior),
        substrate_ior: finite(sub.re),
        substrate_k: finite(sub.im),
        substrate: set.substrate_ior.clone(),
        polarization: set.polarization,
        incident_deg: set.angles.iter().map(|a| finite(a.incident_deg)).collect(),
        bands: set.bands(),
        width: fit.width,
        height: fit.height,
        rows: (fit.rows != (0, fit.provenance.image_height)).then_some([fit.rows.0, fit.rows.1]),
        thickness_nm: MapStats::from(stats),
        thickness_nm_reason: stats.is_none().then(|| "no pixel was fitted".into()),
        pixels: PixelCounts {
            valid: fit.valid_pixels(),
            invalid: fit.invalid_pixels,
            unfitted: fit.unfitted_pixels,
        },
        invalid_samples: set.invalid,
        residual_rmse: rmse.and_then(finite),
        residual_rmse_reason: rmse.is_none().then(|| "no pixel was fitted".into()),
        delta_e_ab_d65_mean: delta_e.as_ref().ok().and_then(|v| finite(*v)),
        delta_e_reason: delta_e.as_ref().err().cloned(),
        seconds,
        warnings: fit.warnings.clone(),
        ground_truth: truth.map(|t| TruthComparison {
            film_ior: finite(t.film_ior_true),
            film_ior_abs_error: finite(t.film_ior_abs_error),
            mean_thickness_nm: finite(t.mean_thickness_true_nm),
            thickness_mae_nm: finite(t.thickness_mae_nm),
            thickness_mean_error_nm: finite(t.thickness_mean_error_nm),
            pixels_compared: t.pixels_compared,
        }),
    }
}

/// Per-pixel 1σ of the thickness (nm), one channel `thickness_sigma`.
pub const THICKNESS_SIGMA_EXR: &str = "thickness_sigma.exr";

/// Point spectra: thickness and 1σ per spectrum (NaN: not fitted or not identifiable).
pub const SPECTRA_CSV: &str = "thickness.csv";

/// The fitted film as a material: the fitted index on the capture's substrate.
pub fn fitted_material(set: &CaptureSet, fit: &Fit) -> FilmMaterial {
    FilmMaterial {
        film_ior: fit.film.to_ior(),
        substrate_ior: set.substrate_ior.clone(),
        width: fit.width,
        height: fit.height,
        thickness_nm: fit.thickness_nm.clone(),
    }
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
    crate::image_io::register_plot_font();
    let mut finite: Vec<f64> = values
        .iter()
        .filter(|v| v.is_finite())
        .map(|&v| v as f64)
        .collect();
    let (lo, hi) = if finite.is_empty() {
        (0.0, 1.0)
    } else {
        let (a, b) = (
            percentile(&mut finite, 0.005),
            percentile(&mut finite, 0.995),
        );
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
                    let [r, g, b] = crate::image_io::viridis((v as f64 - lo) / (hi - lo));
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
            let [r, g, b] = crate::image_io::viridis(t);
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

/// Writes every output file of a fit into `out`, as one step (see
/// [`crate::image_io::write_files_atomically`]): other files in `out` are left alone, and a
/// failed or killed run leaves the previous outputs.
pub fn write_outputs(out: &Path, set: &CaptureSet, fit: &Fit, json: &FitFile) -> Result<()> {
    crate::image_io::write_files_atomically(out, |stage| write_outputs_into(stage, set, fit, json))
}

fn write_outputs_into(out: &Path, set: &CaptureSet, fit: &Fit, json: &FitFile) -> Result<()> {
    let (w, h) = (fit.width, fit.height);
    let chi2_red = || -> Vec<f32> {
        (fit.chi2.iter().zip(&fit.samples).zip(&fit.thickness_nm))
            .map(|((&s, &c), d)| {
                if d.is_finite() && c > 0 {
                    s / c as f32
                } else {
                    f32::NAN
                }
            })
            .collect()
    };
    // Independent files, written side by side: the two colour-mapped PNGs (deflate) and the
    // EXRs were most of a 1-megapixel fit's writing, one after the other.
    let writers: [&(dyn Fn() -> Result<()> + Sync); 4] = [
        &|| {
            write_colormap_png(
                &out.join("thickness.png"),
                &fit.thickness_nm,
                w,
                h,
                "thickness (nm)",
            )
            .context("writing thickness.png")
        },
        &|| {
            let label = "residual χ²/sample (1 = noise level)";
            write_colormap_png(&out.join("residual.png"), &chi2_red(), w, h, label)
                .context("writing residual.png")
        },
        &|| {
            fitted_material(set, fit).write_files_with_provenance(
                out,
                &format!("thinfilm estimate ({})", fit.method),
                &fit.provenance.attributes(),
            )
        },
        &|| {
            let sigma = [("thickness_sigma", &fit.thickness_sigma_nm[..])];
            crate::image_io::write_exr_channels(&out.join(THICKNESS_SIGMA_EXR), w, h, &sigma)
                .with_context(|| format!("writing {THICKNESS_SIGMA_EXR}"))
        },
    ];
    {
        use rayon::prelude::*;
        writers
            .par_iter()
            .map(|write| write())
            .collect::<Result<Vec<()>>>()?;
    }
    if let Some(names) = &set.pixel_names {
        // Point spectra: one line per spectrum.
        let mut csv = String::from("spectrum,thickness_nm,thickness_sigma_nm\n");
        for (i, name) in names.iter().enumerate() {
            let (d, s) = (fit.thickness_nm[i], fit.thickness_sigma_nm[i]);
            csv += &format!("{name},{d},{s}\n");
        }
        crate::image_io::write_atomically(&out.join(SPECTRA_CSV), |p| {
            Ok(std::fs::write(p, csv.as_bytes())?)
        })
        .with_context(|| format!("writing {SPECTRA_CSV}"))?;
    }
    json.write(&out.join(crate::material::FIT_JSON))?;
    Ok(())
}

/// Ground-truth errors from a loaded [`GroundTruth`] (the capture's size; a fit of some
/// rows is compared with those rows).
pub fn truth_from_ground_truth(fit: &Fit, gt: &GroundTruth) -> Result<TruthErrors> {
    let image_height = fit.provenance.image_height;
    if gt.width != fit.width || gt.height != image_height {
        anyhow::bail!(
            "ground truth is {}×{} but the capture is {}×{}",
            gt.width,
            gt.height,
            fit.width,
            image_height
        );
    }
    let (a, b) = fit.rows;
    Ok(truth_errors(
        fit,
        gt.film_ior.at(550.0).re,
        &gt.thickness_nm[a * gt.width..b * gt.width],
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
    fit_loaded(
        || {
            crate::capture::load_capture_set(capture_dir)
                .with_context(|| format!("loading capture set {}", capture_dir.display()))
        },
        out,
        opts,
        ground_truth,
    )
}

/// [`fit_capture_dir`] for a capture set from `load` (a folder, point spectra, …).
pub fn fit_loaded(
    load: impl FnOnce() -> Result<CaptureSet>,
    out: &Path,
    opts: &super::Options,
    ground_truth: Option<&Path>,
) -> Result<FitRun> {
    use super::{Stages, Stopwatch};
    let mut io = Stages::default();
    let t = Stopwatch::start();
    let set = load()?;
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
