//! `thinfilm bench estimate`: reproduces the seed's Table 1 on simulated Samples 1–3 under
//! its conditions (S-polarised, 10–50°, 4 nm bands, σ = 0.004) for the three estimators,
//! sweeps band spacing (1, 2, 4, 8 nm) to show what accuracy costs in time, checks robust
//! cases (thin/thick films, unpolarised, raw uint16 BIL with white/dark, NaN/inf pixels),
//! fits realistic captures (unknown exposure and vignetting, lamp tilt, stray light,
//! dispersive film, approximate substrate, field of view) per method and nuisance setting,
//! and, with `--large`, times a 1-megapixel × 5-angle × 81-band fit.
//!
//! Captures come from the capture module's simulator (`capture::simulate`), in memory
//! except the raw-count case, which goes through ENVI files and `load_capture_set`.

use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use thinfilm::capture::simulate::{
    parse_wavelengths, write_capture_set, SimulateConfig, Simulator,
};
use thinfilm::capture::{load_capture_set, AngleCapture, CaptureSet, InvalidCounts, Polarization};
use thinfilm::estimate::{estimate, report, synth, Fit, Method, Options};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder for the table (`estimate_bench.md`) and plot (`accuracy_vs_time.png`).
    #[arg(long, default_value = "bench_out/estimate")]
    pub out: PathBuf,
    /// Image size for Table 1, WxH.
    #[arg(long, default_value = "128x96")]
    pub size: String,
    /// Image size for the band-spacing sweep, WxH.
    #[arg(long, default_value = "64x48")]
    pub sweep_size: String,
    /// `grid` searches the index on every k-th pixel in x and y (its thickness pass uses all).
    #[arg(long, default_value_t = 8)]
    pub grid_stride: usize,
    /// Also run the 1-megapixel × 5 angles × 81 bands speed test (needs ~4 GB RAM).
    #[arg(long)]
    pub large: bool,
    /// Run only the 1-megapixel speed test (implies `--large`).
    #[arg(long)]
    pub large_only: bool,
    /// Skip the band sweep and robustness sections.
    #[arg(long)]
    pub table_only: bool,
    /// With the 1-megapixel test: also fit it in N row bands with the index given
    /// (`estimate --part K/N --film-ior`), timing each band against the whole fit with
    /// the same index and checking the stitched thickness is bit-identical.
    #[arg(long, default_value_t = 0)]
    pub bands: usize,
    /// ENVI interleave of the 1-megapixel capture's cubes (float32 in any interleave is read
    /// in place from the file's mapping: `bip` as it is, `bsq` and `bil` transposed a tile
    /// of pixels at a time as the fit reads them).
    #[arg(long, default_value = "bsq")]
    pub interleave: thinfilm::capture::envi::Interleave,
}

struct Row {
    label: String,
    method: Method,
    n_fit: f64,
    n_err: f64,
    mean_d: f64,
    mae: f64,
    de: Option<f64>,
    rmse: Option<f64>,
    seconds: f64,
}

fn parse_size(s: &str) -> Result<(usize, usize)> {
    crate::cli::args::size(s).map_err(anyhow::Error::msg)
}

/// Seed conditions for sample 1–3 with the given size and band spacing.
fn seed_config(sample: usize, w: usize, h: usize, spacing_nm: f64) -> Result<SimulateConfig> {
    let mut cfg = SimulateConfig::preset(&format!("sample{sample}"))?;
    cfg.width = w;
    cfg.height = h;
    cfg.noise_sigma = 0.004;
    cfg.fwhm_nm = spacing_nm;
    cfg.wavelengths_nm = parse_wavelengths(&format!("400:720:{spacing_nm}"))?;
    cfg.seed = 1000 + sample as u64;
    Ok(cfg)
}

/// Simulates in memory with the capture module's simulator.
fn simulate(cfg: &SimulateConfig) -> Result<(CaptureSet, Vec<f32>)> {
    let truth = thinfilm::capture::simulate::thickness_field(cfg);
    let sim = Simulator::new(cfg, &truth)?;
    let pb = indicatif::ProgressBar::hidden();
    let nb = cfg.wavelengths_nm.len();
    let angles = (0..cfg.angles_deg.len())
        .map(|a| {
            let s = sim.angle(a, &pb);
            AngleCapture::from_bip(s.incident_deg, s.data, nb)
        })
        .collect();
    Ok((
        CaptureSet {
            polarization: cfg.polarization,
            radiometry: thinfilm::capture::Radiometry::Absolute,
            film_model: None,
            pixel_names: None,
            ambient_ior: cfg.ambient_ior,
            substrate_ior: cfg.substrate_ior.clone(),
            wavelengths_nm: cfg.wavelengths_nm.clone(),
            fwhm_nm: (cfg.fwhm_nm > 0.0).then(|| vec![cfg.fwhm_nm; nb]),
            width: cfg.width,
            height: cfg.height,
            angles,
            invalid: InvalidCounts::default(),
        },
        truth,
    ))
}

fn opts_for(method: Method, grid_stride: usize) -> Options {
    Options {
        method,
        grid_pixel_stride: grid_stride,
        // The grid baseline searches a bracket around the seed's samples (it cannot afford
        // the full range the other methods cover).
        min_film_ior: if method == Method::Grid { 1.2 } else { 1.1 },
        max_film_ior: if method == Method::Grid { 2.6 } else { 3.0 },
        max_thickness_nm: if method == Method::Grid {
            1000.0
        } else {
            2000.0
        },
        // The seed's baseline models point samples (band integration would triple its cost).
        band_integration: method != Method::Grid,
        ..Options::default()
    }
}

fn run_one(
    label: &str,
    set: &CaptureSet,
    truth: &[f32],
    n_true: f64,
    opts: &Options,
) -> Result<(Row, Fit)> {
    let t = Instant::now();
    let fit = estimate(set, opts).with_context(|| format!("{label}: {} failed", opts.method))?;
    let seconds = t.elapsed().as_secs_f64();
    let te = report::truth_errors(&fit, n_true, truth);
    let de = report::mean_delta_e(set, &fit, opts.band_integration, 4000).ok();
    Ok((
        Row {
            label: label.to_string(),
            method: opts.method,
            n_fit: fit.film_ior,
            n_err: te.film_ior_abs_error,
            mean_d: thinfilm::stats::Summary::of_finite(&fit.thickness_nm)
                .map(|s| s.mean)
                .unwrap_or(f64::NAN),
            mae: te.thickness_mae_nm,
            de,
            rmse: fit.rmse(),
            seconds,
        },
        fit,
    ))
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.filter(|x| x.is_finite())
        .map(|x| format!("{x:.prec$}"))
        .unwrap_or_else(|| "—".into())
}

fn table_header(s: &mut String) {
    s.push_str("| sample | method | n | \\|n error\\| | mean d (nm) | thickness MAE (nm) | ΔE*ab | RMSE | seconds |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|\n");
}

fn table_row(s: &mut String, r: &Row) {
    let _ = writeln!(
        s,
        "| {} | {} | {:.4} | {:.4} | {:.1} | {:.2} | {} | {} | {:.2} |",
        r.label,
        r.method,
        r.n_fit,
        r.n_err,
        r.mean_d,
        r.mae,
        opt(r.de, 2),
        opt(r.rmse, 4),
        r.seconds
    );
}

pub fn run(args: Args) -> Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let (w, h) = parse_size(&args.size)?;
    let mut md = String::new();
    if args.large_only {
        large(&args, &mut md)?;
        println!("{md}");
        let path = args.out.join("estimate_large.md");
        thinfilm::image_io::write_atomically(&path, |p| Ok(std::fs::write(p, md.as_bytes())?))?;
        eprintln!("wrote {}", path.display());
        return Ok(());
    }
    let _ = writeln!(
        md,
        "## Estimator benchmark (seed Table 1 conditions: S-pol, 10–50°, 400–720 nm at 4 nm, σ = 0.004, {w}×{h} px, {} threads)\n",
        rayon::current_num_threads()
    );
    let _ = writeln!(
        md,
        "grid: n step 0.01 over [1.2, 2.6], d step 2 nm over [0, 1000] nm, index searched on every {}th pixel.\n",
        args.grid_stride
    );
    table_header(&mut md);
    let published = [
        (1.37, 400.0, "1.374", "370", "0.72", "0.04"),
        (1.37, 600.0, "1.367", "551", "1.21", "0.07"),
        (2.37, 500.0, "2.674", "541", "5.63", "0.18"),
    ];
    let mut acceptance = Vec::new();
    for (i, p) in published.iter().enumerate() {
        let cfg = seed_config(i + 1, w, h, 4.0)?;
        let (set, truth) = simulate(&cfg)?;
        let _ = writeln!(
            md,
            "| Sample {} | seed (published) | {} | {:.3} | {} | (mean error {:.0}) | {} | {} | — |",
            i + 1,
            p.2,
            (p.2.parse::<f64>()? - p.0).abs(),
            p.3,
            (p.3.parse::<f64>()? - p.1).abs(),
            p.4,
            p.5
        );
        for method in [Method::Paper, Method::Grid, Method::Full] {
            let (row, _) = run_one(
                &format!("Sample {}", i + 1),
                &set,
                &truth,
                p.0,
                &opts_for(method, args.grid_stride),
            )?;
            eprintln!(
                "Sample {} {}: n {:.4} MAE {:.2} nm in {:.2} s",
                i + 1,
                method,
                row.n_fit,
                row.mae,
                row.seconds
            );
            table_row(&mut md, &row);
            if method == Method::Full {
                acceptance.push((row.n_err <= 0.005 && row.mae <= 3.0, row.n_err, row.mae));
            }
        }
    }
    let _ = writeln!(
        md,
        "\nAcceptance (full: |n error| ≤ 0.005, MAE ≤ 3 nm): {}\n",
        acceptance
            .iter()
            .map(|(ok, n, m)| format!(
                "{} (|Δn| {n:.4}, MAE {m:.2} nm)",
                if *ok { "pass" } else { "FAIL" }
            ))
            .collect::<Vec<_>>()
            .join("; ")
    );

    if !args.table_only {
        sweep(&args, &mut md)?;
        robustness(&args, &mut md)?;
        realistic(&args, &mut md)?;
    }
    if args.large {
        large(&args, &mut md)?;
    }
    println!("{md}");
    let path = args.out.join("estimate_bench.md");
    thinfilm::image_io::write_atomically(&path, |p| Ok(std::fs::write(p, md.as_bytes())?))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// Accuracy against time for every method and band spacing (Sample 3, the hard one).
fn sweep(args: &Args, md: &mut String) -> Result<()> {
    let (w, h) = parse_size(&args.sweep_size)?;
    let _ = writeln!(
        md,
        "### What accuracy costs in time (Sample 3, {w}×{h} px, band spacing = FWHM)\n"
    );
    md.push_str("| bands (nm) | method | \\|n error\\| | thickness MAE (nm) | seconds |\n|---|---|---|---|---|\n");
    let mut points: Vec<(Method, f64, f64, f64)> = Vec::new();
    for spacing in [1.0, 2.0, 4.0, 8.0] {
        let cfg = seed_config(3, w, h, spacing)?;
        let (set, truth) = simulate(&cfg)?;
        for method in [Method::Paper, Method::Grid, Method::Full] {
            let (row, _) = run_one(
                "sweep",
                &set,
                &truth,
                2.37,
                &opts_for(method, args.grid_stride),
            )?;
            let _ = writeln!(
                md,
                "| {spacing} | {method} | {:.4} | {:.2} | {:.2} |",
                row.n_err, row.mae, row.seconds
            );
            eprintln!(
                "sweep {spacing} nm {method}: MAE {:.2} in {:.2} s",
                row.mae, row.seconds
            );
            points.push((method, spacing, row.seconds, row.mae));
        }
    }
    let plot = args.out.join("accuracy_vs_time.png");
    plot_points(&plot, &points)?;
    let _ = writeln!(md, "\nPlot: `{}`\n", plot.display());
    Ok(())
}

fn plot_points(path: &std::path::Path, pts: &[(Method, f64, f64, f64)]) -> Result<()> {
    use plotters::prelude::*;
    thinfilm::image_io::register_plot_font();
    let (iw, ih) = (900u32, 600u32);
    let mut buf = vec![255u8; (iw * ih * 3) as usize];
    let finite: Vec<&(Method, f64, f64, f64)> = pts
        .iter()
        .filter(|p| p.2 > 0.0 && p.3.is_finite())
        .collect();
    let tmin = finite
        .iter()
        .map(|p| p.2)
        .fold(f64::INFINITY, f64::min)
        .max(1e-4)
        / 2.0;
    let tmax = finite
        .iter()
        .map(|p| p.2)
        .fold(0.0, f64::max)
        .max(tmin * 4.0)
        * 2.0;
    let emin = finite
        .iter()
        .map(|p| p.3.max(1e-3))
        .fold(f64::INFINITY, f64::min)
        / 2.0;
    let emax = finite
        .iter()
        .map(|p| p.3)
        .fold(0.0, f64::max)
        .max(emin * 4.0)
        * 2.0;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (iw, ih)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| anyhow::anyhow!("plot: {e:?}");
        root.fill(&WHITE).map_err(e)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Thickness MAE vs fit time (Sample 3; labels = band spacing nm)",
                ("sans-serif", 20),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((tmin..tmax).log_scale(), (emin..emax).log_scale())
            .map_err(|x| anyhow::anyhow!("plot: {x:?}"))?;
        chart
            .configure_mesh()
            .x_desc("seconds (log)")
            .y_desc("thickness MAE, nm (log)")
            .draw()
            .map_err(|x| anyhow::anyhow!("plot: {x:?}"))?;
        for (method, color) in [
            (Method::Paper, RED),
            (Method::Grid, BLUE),
            (Method::Full, GREEN),
        ] {
            let series: Vec<(f64, f64, f64)> = finite
                .iter()
                .filter(|p| p.0 == method)
                .map(|p| (p.2, p.3.max(emin), p.1))
                .collect();
            chart
                .draw_series(LineSeries::new(
                    series.iter().map(|p| (p.0, p.1)),
                    color.stroke_width(2),
                ))
                .map_err(|x| anyhow::anyhow!("plot: {x:?}"))?
                .label(method.to_string())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(series.iter().map(|p| {
                    EmptyElement::at((p.0, p.1))
                        + Circle::new((0, 0), 5, color.filled())
                        + Text::new(format!("{}", p.2), (7, -12), ("sans-serif", 14).into_font())
                }))
                .map_err(|x| anyhow::anyhow!("plot: {x:?}"))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| anyhow::anyhow!("plot: {x:?}"))?;
        root.present().map_err(|x| anyhow::anyhow!("plot: {x:?}"))?;
    }
    thinfilm::image_io::write_png_rgb8(path, iw as usize, ih as usize, buf)
}

/// Robust cases, `full` only.
fn robustness(args: &Args, md: &mut String) -> Result<()> {
    let (w, h) = (64, 48);
    md.push_str(
        "### Robustness (full, 64×48 px, σ = 0.004; target |n error| ≤ 0.01, MAE ≤ 5 nm)\n\n",
    );
    md.push_str("| case | n true | n fit | \\|n error\\| | thickness MAE (nm) | valid px | seconds | pass |\n|---|---|---|---|---|---|---|---|\n");
    let mut cases: Vec<(String, CaptureSet, Vec<f32>, f64)> = Vec::new();
    let base = |n: f64, d: f64| -> Result<SimulateConfig> {
        let mut c = seed_config(1, w, h, 4.0)?;
        c.film_ior = thinfilm::optics::Ior::real(n);
        c.thickness_nm = d;
        c.seed = 77;
        Ok(c)
    };
    let c = base(1.37, 150.0)?;
    let (s, t) = simulate(&c)?;
    cases.push(("150 nm MgF2 (one fringe)".into(), s, t, 1.37));
    let c = base(1.37, 1500.0)?;
    let (s, t) = simulate(&c)?;
    cases.push(("1500 nm MgF2 (many orders)".into(), s, t, 1.37));
    let mut c = base(2.37, 500.0)?;
    c.polarization = Polarization::Unpolarized;
    let (s, t) = simulate(&c)?;
    cases.push(("unpolarised ZnS 500 nm".into(), s, t, 2.37));
    // Raw uint16 BIL with white/dark references, through ENVI files and the loader.
    let mut c = base(1.37, 400.0)?;
    c.raw_counts = true;
    c.interleave = thinfilm::capture::envi::Interleave::Bil;
    let dir = args.out.join("raw_bil_capture");
    let summary = write_capture_set(&c, &dir)?;
    let s = load_capture_set(&dir)?;
    cases.push((
        "raw uint16 BIL + white/dark (files)".into(),
        s,
        summary.thickness_nm,
        1.37,
    ));
    // NaN / inf pixels.
    let c = base(1.37, 600.0)?;
    let (mut s, t) = simulate(&c)?;
    let nb = s.bands();
    let mut rng = synth::Rng::new(5);
    for a in &mut s.angles {
        let r = (a.reflectance.as_bip_mut()).context("a simulated capture is BIP in memory")?;
        for _ in 0..(w * h / 20) {
            let p = (rng.next_u64() % (w * h) as u64) as usize;
            let b = (rng.next_u64() % nb as u64) as usize;
            r[p * nb + b] = if b % 2 == 0 { f32::NAN } else { f32::INFINITY };
            a.valid[p] = false;
        }
    }
    cases.push(("NaN/inf pixels (5% per angle)".into(), s, t, 1.37));
    for (label, set, truth, n_true) in cases {
        let (row, fit) = run_one(&label, &set, &truth, n_true, &Options::default())?;
        let ok = row.n_err <= 0.01 && row.mae <= 5.0;
        eprintln!(
            "robust {label}: n {:.4} MAE {:.2} {}",
            row.n_fit,
            row.mae,
            if ok { "ok" } else { "FAIL" }
        );
        let _ = writeln!(
            md,
            "| {label} | {n_true} | {:.4} | {:.4} | {:.2} | {} | {:.2} | {} |",
            row.n_fit,
            row.n_err,
            row.mae,
            fit.valid_pixels(),
            row.seconds,
            if ok { "yes" } else { "NO" }
        );
    }
    md.push('\n');
    Ok(())
}

/// One realistic capture type: label, film index (index syntax), thickness, preset, and
/// the simulator options that make it realistic.
type RealisticCase = (
    &'static str,
    &'static str,
    f64,
    usize,
    fn(&mut SimulateConfig),
);

/// Realistic captures (ENVI files through the loader, 64×48 px, σ = 0.004), three seeds
/// each, per method and nuisance setting: worst |n error| and MAE over the seeds, how many
/// seeds' claimed σ(n) covers the error (|error| ≤ 5 max(σ, 0.002)), warnings, seconds.
fn realistic(args: &Args, md: &mut String) -> Result<()> {
    let cases: [RealisticCase; 7] = [
        ("exposure ±40 %, vignetting 0.5", "2.37", 500.0, 3, |c| {
            c.realism.exposure_variation = 0.4;
            c.realism.vignetting_min = 0.5;
        }),
        ("exposure ±40 %, vignetting 0.5", "1.37", 400.0, 1, |c| {
            c.realism.exposure_variation = 0.4;
            c.realism.vignetting_min = 0.5;
        }),
        ("lamp tilt ±10 %", "1.37", 400.0, 1, |c| {
            c.realism.lamp_tilt = 0.1
        }),
        ("substrate off by 0.03", "1.37", 400.0, 1, |c| {
            c.realism.substrate_error = 0.03
        }),
        (
            "dispersive ZnS (Cauchy)",
            "cauchy:2.232,50912",
            500.0,
            3,
            |_| {},
        ),
        ("all at once, unpolarised", "1.38", 800.0, 1, |c| {
            c.polarization = Polarization::Unpolarized;
            c.realism.exposure_variation = 0.4;
            c.realism.vignetting_min = 0.5;
            c.realism.lamp_tilt = 0.1;
            c.realism.background = 0.02;
            c.realism.substrate_error = 0.03;
        }),
        ("±4° field of view", "1.37", 400.0, 1, |c| {
            c.realism.fov_half_deg = 4.0
        }),
    ];
    let settings: [(&str, Method, Option<thinfilm::capture::Radiometry>); 3] = [
        (
            "full (relative: nuisance chosen by the data)",
            Method::Full,
            None,
        ),
        (
            "full, absolute radiometry (no nuisance terms)",
            Method::Full,
            Some(thinfilm::capture::Radiometry::Absolute),
        ),
        ("paper", Method::Paper, None),
    ];
    md.push_str(
        "### Realistic captures (64×48 px, σ = 0.004, 3 seeds; worst over seeds)\n\n\
         | capture | n(550) true | method / nuisance | worst \\|n error\\| | worst MAE (nm) | σ(n) covers | warned | seconds |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for (label, ior, d, preset, effect) in cases {
        let film: thinfilm::optics::Ior = ior.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
        let n_true = film.at(550.0).re;
        let mut sets = Vec::new();
        for seed in 1..=3u64 {
            let mut c = seed_config(preset, 64, 48, 4.0)?;
            c.film_ior = film.clone();
            c.thickness_nm = d;
            c.seed = 300 + seed;
            effect(&mut c);
            let dir = args.out.join(format!("realistic_capture_{seed}"));
            let summary = write_capture_set(&c, &dir)?;
            sets.push((load_capture_set(&dir)?, summary.thickness_nm));
            std::fs::remove_dir_all(&dir).ok();
        }
        for (name, method, radiometry) in settings {
            let opts = Options {
                method,
                radiometry,
                ..Options::default()
            };
            let (mut n_err, mut mae, mut covered, mut warned, mut secs) = (0f64, 0f64, 0, 0, 0.0);
            for (set, truth) in &sets {
                let (row, fit) = run_one(label, set, truth, n_true, &opts)?;
                n_err = n_err.max(row.n_err);
                mae = mae.max(row.mae);
                let sigma = fit.film_ior_sigma.unwrap_or(0.0);
                covered += (row.n_err <= 5.0 * sigma.max(0.002)) as usize;
                warned += !fit.warnings.is_empty() as usize;
                secs += row.seconds / sets.len() as f64;
            }
            eprintln!("realistic {label} / {name}: |Δn| {n_err:.4} MAE {mae:.2} nm");
            let _ = writeln!(
                md,
                "| {label} | {n_true:.3} | {name} | {n_err:.4} | {mae:.2} | {covered}/3 | {warned}/3 | {secs:.2} |"
            );
        }
    }
    md.push('\n');
    Ok(())
}

/// 1 MP × 5 angles × 81 bands, timed end to end like `thinfilm estimate`: load the ENVI
/// cubes from disk, fit, ΔE, write every output. The simulated capture is kept in
/// `OUT/large_capture` and reused when its recorded simulation options match (simulating
/// takes minutes; the fit is what is timed).
fn large(args: &Args, md: &mut String) -> Result<()> {
    let mut cfg = seed_config(1, 1024, 1024, 4.0)?;
    cfg.seed = 9;
    cfg.interleave = args.interleave;
    let dir = args.out.join(format!("large_capture_{}", args.interleave));
    let gt_json = dir.join("ground_truth").join("ground_truth.json");
    let cached = std::fs::read_to_string(&gt_json)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .is_some_and(|v| v.get("options") == Some(&cfg.to_json()))
        && dir.join("capture.json").is_file();
    if cached {
        eprintln!("large: reusing the simulated capture in {}", dir.display());
    } else {
        eprintln!("large: simulating 1024×1024×5×81 into {} …", dir.display());
        cfg.progress = true;
        write_capture_set(&cfg, &dir)?;
        cfg.progress = false;
    }
    // The capture is calibrated ("absolute"): no nuisance terms. "relative" fits a gain per
    // pixel and angle and a multiplier and background per angle as a real capture needs.
    let runs = [
        ("no nuisance terms", None),
        (
            "nuisance terms",
            Some(thinfilm::capture::Radiometry::Relative),
        ),
    ];
    let mut timed = Vec::new();
    for (i, (what, radiometry)) in runs.into_iter().enumerate() {
        let t = Instant::now();
        let cpu0 = thinfilm::estimate::process_cpu_seconds();
        let run = report::fit_capture_dir(
            &dir,
            &args.out.join(format!("large_fit{i}")),
            &Options {
                progress: true,
                radiometry,
                ..Options::default()
            },
            Some(&dir.join("ground_truth")),
        )?;
        let total = t.elapsed().as_secs_f64();
        let cpu = cpu0
            .zip(thinfilm::estimate::process_cpu_seconds())
            .map(|(a, b)| b - a);
        eprintln!("large ({what}): {total:.2} s");
        timed.push((what, run, total, cpu));
    }
    let fit = &timed[0].1.fit;
    let (w, h) = (fit.width, fit.height);
    let (na, nb) = (cfg.angles_deg.len(), cfg.wavelengths_nm.len());
    let _ = writeln!(
        md,
        "### 1-megapixel speed run (full, {w}×{h} × {na} angles × {nb} bands = {:.2} GB float32 {} ENVI on disk, {} threads, load average {})\n",
        (w * h * na * nb * 4) as f64 / 1e9,
        args.interleave,
        rayon::current_num_threads(),
        load_average()
    );
    large_table(md, &timed, (w * h) as f64 / 1e6);
    if args.bands > 0 {
        band_costs(&dir, fit.film_ior, args.bands, md)?;
    }
    Ok(())
}

/// The one-minute load average (`/proc/loadavg`), to read wall times on a shared machine.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next().map(String::from))
        .unwrap_or_else(|| "unknown".into())
}

/// Per-stage wall and CPU seconds of the large runs, side by side.
fn large_table(md: &mut String, timed: &[(&str, report::FitRun, f64, Option<f64>)], mp: f64) {
    md.push_str("| stage |");
    for (what, ..) in timed {
        let _ = write!(md, " wall s ({what}) | CPU s ({what}) |");
    }
    md.push_str("\n|---|");
    md.push_str(&"---|---|".repeat(timed.len()));
    md.push('\n');
    let names = |run: &report::FitRun| -> Vec<String> {
        let load = run.io_seconds.iter().filter(|(k, _)| k == "load");
        let rest = run.io_seconds.iter().filter(|(k, _)| k != "load");
        load.chain(&run.fit.stage_seconds)
            .chain(rest)
            .map(|(k, _)| k.clone())
            .collect()
    };
    let mut rows = names(&timed[0].1);
    for (_, run, ..) in &timed[1..] {
        for k in names(run) {
            if !rows.contains(&k) {
                rows.push(k);
            }
        }
    }
    let find = |v: &[(String, f64)], k: &str| v.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
    for k in &rows {
        let _ = write!(md, "| {k} |");
        for (_, run, ..) in timed {
            let wall = find(&run.fit.stage_seconds, k).or(find(&run.io_seconds, k));
            let cpu = find(&run.fit.stage_cpu_seconds, k).or(find(&run.io_cpu_seconds, k));
            let _ = write!(md, " {} | {} |", opt(wall, 2), opt(cpu, 2));
        }
        md.push('\n');
    }
    md.push_str("| **total** |");
    for (_, _, total, cpu) in timed {
        let _ = write!(md, " **{total:.2}** | {} |", opt(*cpu, 2));
    }
    let _ = writeln!(
        md,
        "\n\nWall-clock time includes waiting for the cores when the machine is shared; CPU \
         time / {} threads is the least wall time the same work needs on idle cores ({:.2} MP).",
        rayon::current_num_threads(),
        mp
    );
    for (what, run, ..) in timed {
        let (n_err, mae) = run
            .truth
            .as_ref()
            .map(|t| (t.film_ior_abs_error, t.thickness_mae_nm))
            .unwrap_or((f64::NAN, f64::NAN));
        let _ = writeln!(
            md,
            "\n{what}: |n error| {n_err:.4}, thickness MAE {mae:.2} nm, {} valid px.",
            run.fit.valid_pixels()
        );
    }
    md.push('\n');
}

/// The large capture fitted whole and in `parts` row bands with the index `film_ior` given,
/// each on the loaded capture (no load or write): what a band costs against the whole fit,
/// and whether the stitched bands equal it bit for bit.
fn band_costs(dir: &std::path::Path, film_ior: f64, parts: usize, md: &mut String) -> Result<()> {
    let set = load_capture_set(dir)?;
    let base = Options {
        film_ior: Some(thinfilm::optics::Ior::Constant(
            thinfilm::optics::Complex64::new(film_ior, 0.0),
        )),
        ..Options::default()
    };
    let timed = |opts: &Options| -> Result<(Fit, f64, Option<f64>)> {
        let t = Instant::now();
        let cpu0 = thinfilm::estimate::process_cpu_seconds();
        let fit = estimate(&set, opts)?;
        let cpu = cpu0
            .zip(thinfilm::estimate::process_cpu_seconds())
            .map(|(a, b)| b - a);
        Ok((fit, t.elapsed().as_secs_f64(), cpu))
    };
    let (whole, whole_s, whole_cpu) = timed(&base)?;
    let _ = writeln!(
        md,
        "### Row bands ({parts} bands, index given, fit only: no load or write; load average {})\n",
        load_average()
    );
    md.push_str(
        "| fit | rows | wall s | CPU s | wall ÷ whole | CPU ÷ whole |\n|---|---|---|---|---|---|\n",
    );
    let row = |md: &mut String, what: &str, rows: (usize, usize), s: f64, c: Option<f64>| {
        let _ = writeln!(
            md,
            "| {what} | {}:{} | {s:.2} | {} | {:.2} | {} |",
            rows.0,
            rows.1,
            opt(c, 2),
            s / whole_s,
            opt(c.zip(whole_cpu).map(|(c, w)| c / w), 2)
        );
    };
    row(md, "whole", whole.rows, whole_s, whole_cpu);
    let mut stitched: Vec<u32> = Vec::with_capacity(whole.thickness_nm.len());
    for k in 0..parts {
        let opts = Options {
            rows: Some(thinfilm::estimate::tiles::RowBand::Part {
                index: k,
                count: parts,
            }),
            ..base.clone()
        };
        let (fit, s, c) = timed(&opts)?;
        row(md, &format!("band {k}/{parts}"), fit.rows, s, c);
        stitched.extend(fit.thickness_nm.iter().map(|v| v.to_bits()));
    }
    let want: Vec<u32> = whole.thickness_nm.iter().map(|v| v.to_bits()).collect();
    let _ = writeln!(
        md,
        "\nStitched bands {} the whole fit's thickness bit for bit.\n",
        if stitched == want {
            "equal"
        } else {
            "DIFFER FROM"
        }
    );
    Ok(())
}
