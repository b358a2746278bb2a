//! The one-command demo: simulate the seed paper's three samples, fit them with the seed's
//! method and with ours, print the Table-1 comparison, render the teapot figures, and write
//! an index (README.md + index.html) that shows them with the numbers.

use crate::capture::{self, simulate::SimulateConfig};
use crate::estimate::{report, Method, Options};
use crate::figure::{self, RenderSettings, SampleRow};
use crate::material::FilmMaterial;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What the demo does, and how big.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    pub out: PathBuf,
    pub width: usize,
    pub height: usize,
    /// Additive reflectance noise σ of the simulated captures (the bench's 0.004).
    pub noise_sigma: f64,
    pub seed: u64,
    pub render: RenderSettings,
    pub progress: bool,
}

impl Default for DemoConfig {
    fn default() -> Self {
        DemoConfig {
            out: PathBuf::from("demo-out"),
            width: 128,
            height: 96,
            noise_sigma: 0.004,
            seed: 1,
            render: RenderSettings {
                resolution: 192,
                spp: 32,
                seed: 0,
                max_depth: 8,
                progress: false,
            },
            progress: true,
        }
    }
}

/// The seed's published Table 1 row for a sample: n, mean thickness, ΔE*ab, RMSE.
#[derive(Debug, Clone, Copy)]
pub struct PaperRow {
    pub film_ior: f64,
    pub mean_thickness_nm: f64,
    pub delta_e_ab: f64,
    pub rmse: f64,
}

/// (preset, label, true n, true d, the paper's row).
/// Samples that get the figure of the published method's fit against ours: sample 3, where
/// the published method fails (half-order maxima). On samples 1 and 2 both fits render alike,
/// and three more renders each would slow the demo for no new picture.
pub const METHODS_FIGURE_SAMPLES: [&str; 1] = ["sample3"];

pub const SAMPLES: [(&str, &str, f64, f64, PaperRow); 3] = [
    (
        "sample1",
        "Sample 1 (MgF2 400 nm)",
        1.37,
        400.0,
        PaperRow {
            film_ior: 1.374,
            mean_thickness_nm: 370.0,
            delta_e_ab: 0.72,
            rmse: 0.04,
        },
    ),
    (
        "sample2",
        "Sample 2 (MgF2 600 nm)",
        1.37,
        600.0,
        PaperRow {
            film_ior: 1.367,
            mean_thickness_nm: 551.0,
            delta_e_ab: 1.21,
            rmse: 0.07,
        },
    ),
    (
        "sample3",
        "Sample 3 (ZnS 500 nm)",
        2.37,
        500.0,
        PaperRow {
            film_ior: 2.674,
            mean_thickness_nm: 541.0,
            delta_e_ab: 5.63,
            rmse: 0.18,
        },
    ),
];

/// One fitted method on one sample.
#[derive(Debug, Clone)]
pub struct MethodResult {
    pub method: Method,
    pub film_ior: f64,
    pub film_ior_abs_error: f64,
    pub mean_thickness_nm: f64,
    pub thickness_mae_nm: f64,
    pub delta_e_ab: Option<f64>,
    pub rmse: Option<f64>,
    pub seconds: f64,
    pub fit_dir: PathBuf,
}

/// Everything the demo measured.
#[derive(Debug, Clone)]
pub struct DemoSummary {
    pub samples: Vec<(String, f64, f64, PaperRow, Vec<MethodResult>)>,
    pub figures: Vec<PathBuf>,
    /// For [`METHODS_FIGURE_SAMPLES`]: the sample's label, its figure of ground truth, the
    /// published method's fit and ours as teapots with ΔE00 maps (`SAMPLE/methods.png`), and
    /// the two fits' mean ΔE00.
    pub method_figures: Vec<(String, PathBuf, Vec<f64>)>,
    pub samples_figure_delta_e00: Vec<f64>,
    pub seconds: f64,
    pub table_markdown: String,
}

fn fit_one(capture_dir: &Path, gt_dir: &Path, method: Method, out: &Path) -> Result<MethodResult> {
    let opts = Options {
        method,
        progress: false,
        ..Options::default()
    };
    let t = Instant::now();
    let run = report::fit_capture_dir(capture_dir, out, &opts, Some(gt_dir))?;
    let seconds = t.elapsed().as_secs_f64();
    let truth = run.truth.expect("ground truth was given");
    Ok(MethodResult {
        method,
        film_ior: run.fit.film_ior,
        film_ior_abs_error: truth.film_ior_abs_error,
        mean_thickness_nm: crate::stats::Summary::of_finite(&run.fit.thickness_nm)
            .map(|s| s.mean)
            .unwrap_or(f64::NAN),
        thickness_mae_nm: truth.thickness_mae_nm,
        delta_e_ab: run.delta_e.ok(),
        rmse: run.fit.rmse(),
        seconds,
        fit_dir: out.to_path_buf(),
    })
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}"))
        .unwrap_or_else(|| "n/a".into())
}

/// The Table-1 comparison as markdown: the paper's published row, then ours per method.
pub fn table_markdown(samples: &[(String, f64, f64, PaperRow, Vec<MethodResult>)]) -> String {
    let mut s = String::new();
    s.push_str("| sample | method | n | abs n error | mean d (nm) | d MAE (nm) | ΔE*ab | RMSE | seconds |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for (label, n_true, d_true, paper, results) in samples {
        let _ = writeln!(
            s,
            "| {label} (true n {n_true}, d {d_true} nm) | paper (published) | {:.3} | {:.3} | {:.0} | — | {:.2} | {:.2} | — |",
            paper.film_ior,
            (paper.film_ior - n_true).abs(),
            paper.mean_thickness_nm,
            paper.delta_e_ab,
            paper.rmse
        );
        for r in results {
            let _ = writeln!(
                s,
                "| | ours: {} | {:.4} | {:.4} | {:.1} | {:.2} | {} | {} | {:.2} |",
                r.method,
                r.film_ior,
                r.film_ior_abs_error,
                r.mean_thickness_nm,
                r.thickness_mae_nm,
                opt(r.delta_e_ab, 2),
                opt(r.rmse, 4),
                r.seconds
            );
        }
    }
    s
}

/// Runs the whole demo; writes into `cfg.out` and returns what it measured.
pub fn run(cfg: &DemoConfig) -> Result<DemoSummary> {
    let start = Instant::now();
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("creating {}", cfg.out.display()))?;
    // simulate + 2 fits + a figure per sample, the methods figures, the Fig. 6 figure.
    let steps = SAMPLES.len() as u64 * 4 + METHODS_FIGURE_SAMPLES.len() as u64 + 1;
    let bar = crate::progress::bar(
        cfg.progress,
        steps,
        "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg} ({eta} left)",
    );
    let mut samples = Vec::new();
    let mut figures = Vec::new();
    let mut method_figures = Vec::new();
    let mut rows = Vec::new();
    for (preset, label, n_true, d_true, paper) in SAMPLES {
        let dir = cfg.out.join(preset);
        let capture_dir = dir.join("capture");
        bar.set_message(format!("simulating {label}"));
        let mut sim = SimulateConfig::preset(preset)?;
        sim.width = cfg.width;
        sim.height = cfg.height;
        sim.noise_sigma = cfg.noise_sigma;
        sim.seed = cfg.seed;
        sim.progress = false;
        capture::simulate::write_capture_set(&sim, &capture_dir)?;
        bar.inc(1);
        let gt_dir = capture_dir.join("ground_truth");
        let mut results = Vec::new();
        for method in [Method::Paper, Method::Full] {
            bar.set_message(format!("fitting {label} ({method})"));
            results.push(fit_one(
                &capture_dir,
                &gt_dir,
                method,
                &dir.join(format!("fit_{method}")),
            )?);
            bar.inc(1);
        }
        bar.set_message(format!("rendering {label}"));
        let full_dir = dir.join("fit_full");
        let png = dir.join("figure.png");
        figure::fit_figure(&full_dir, &gt_dir, None, &cfg.render, &png)?;
        figures.push(png);
        bar.inc(1);
        let gt = capture::load_ground_truth(&gt_dir)?;
        let truth = FilmMaterial::from_ground_truth(&gt);
        let fitted = FilmMaterial::from_fit_dir(&full_dir)?;
        if METHODS_FIGURE_SAMPLES.contains(&preset) {
            bar.set_message(format!("rendering {label}: the paper's fit and ours"));
            let methods_png = dir.join("methods.png");
            let fits = [
                (
                    "published method".to_string(),
                    FilmMaterial::from_fit_dir(&dir.join("fit_paper"))?,
                ),
                ("ours (full)".to_string(), fitted.clone()),
            ];
            let title = format!("{label}: the published method's fit and ours, rendered");
            let des = figure::methods_figure(&title, &truth, &fits, &cfg.render, &methods_png)?;
            method_figures.push((label.to_string(), methods_png, des));
            bar.inc(1);
        }
        rows.push(SampleRow {
            name: label.to_string(),
            truth,
            fitted,
        });
        samples.push((label.to_string(), n_true, d_true, paper, results));
    }
    bar.set_message("rendering Fig. 6 layout");
    let fig6 = cfg.out.join("fig6_samples.png");
    let des = figure::samples_figure(&rows, None, &cfg.render, &fig6)?;
    bar.inc(1);
    bar.finish_and_clear();
    let table = table_markdown(&samples);
    let summary = DemoSummary {
        samples,
        figures: std::iter::once(fig6).chain(figures).collect(),
        method_figures,
        samples_figure_delta_e00: des,
        seconds: start.elapsed().as_secs_f64(),
        table_markdown: table,
    };
    write_index(cfg, &summary)?;
    Ok(summary)
}

fn relative(base: &Path, p: &Path) -> String {
    p.strip_prefix(base).unwrap_or(p).display().to_string()
}

fn write_index(cfg: &DemoConfig, s: &DemoSummary) -> Result<()> {
    let mut md = String::new();
    let _ = writeln!(md, "# thinfilm demo\n");
    let _ = writeln!(
        md,
        "The seed paper's three samples simulated at {}×{} px (S-polarised, 10–50°, 4 nm bands, noise σ {}), \
         fitted with the paper's peak method and with ours (`full`), then rendered as teapots \
         ({}² px, {} spp, same seed for ground truth and fit). Took {:.1} s.\n",
        cfg.width, cfg.height, cfg.noise_sigma, cfg.render.resolution, cfg.render.spp, s.seconds
    );
    md.push_str("## Table 1: paper vs ours\n\n");
    md.push_str(&s.table_markdown);
    md.push_str("\n## Figures\n\n");
    for (i, f) in s.figures.iter().enumerate() {
        let caption = if i == 0 {
            format!(
                "Seed Fig. 6 layout — ground truth | fitted | ΔE00, one row per sample (mean ΔE00: {})",
                s.samples_figure_delta_e00.iter().map(|d| format!("{d:.3}")).collect::<Vec<_>>().join(", ")
            )
        } else {
            format!(
                "{}: teapots, fitted thickness map and its error (seed Fig. 5)",
                s.samples[i - 1].0
            )
        };
        let _ = writeln!(
            md,
            "### {caption}\n\n![{caption}]({})\n",
            relative(&cfg.out, f)
        );
    }
    md.push_str("## The published method's fit against ours\n\n");
    for (label, f, des) in &s.method_figures {
        let caption = format!(
            "{label}: ground truth, the published method's fit (mean ΔE00 {:.2}) and ours ({:.2})",
            des[0], des[1]
        );
        let _ = writeln!(
            md,
            "### {caption}\n\n![{caption}]({})\n",
            relative(&cfg.out, f)
        );
    }
    md.push_str("Each sample folder holds the capture set (`capture/`, ENVI cubes + `capture.json` + `ground_truth/`) \
                 and the fits (`fit_paper/`, `fit_full/`: `fit.json`, `thickness.exr`, `material.xml`, `material.gltf`).\n");
    crate::image_io::write_atomically(&cfg.out.join("README.md"), |p| {
        Ok(std::fs::write(p, md.as_bytes())?)
    })?;

    let mut html = String::from(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>thinfilm demo</title>\
         <style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}table{border-collapse:collapse}\
         td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}img{max-width:100%}</style></head><body>\n",
    );
    html.push_str("<h1>thinfilm demo</h1>\n<table>\n");
    for (i, line) in s.table_markdown.lines().enumerate() {
        if i == 1 {
            continue;
        }
        let tag = if i == 0 { "th" } else { "td" };
        html.push_str("<tr>");
        for cell in line.trim_matches('|').split('|') {
            let _ = write!(html, "<{tag}>{}</{tag}>", cell.trim());
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</table>\n");
    for f in s
        .figures
        .iter()
        .chain(s.method_figures.iter().map(|(_, f, _)| f))
    {
        let _ = writeln!(html, "<p><img src=\"{}\"></p>", relative(&cfg.out, f));
    }
    html.push_str("</body></html>\n");
    crate::image_io::write_atomically(&cfg.out.join("index.html"), |p| {
        Ok(std::fs::write(p, html.as_bytes())?)
    })
}
