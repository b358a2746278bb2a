//! `thinfilm bench render [--mitsuba]`: error against time on every Mitsuba reference scene.
//!
//! For each scene in `tests/references/manifest.json`, renders with our path tracer at each
//! spp (16 … 1024 by default) at the reference's size, timing the render (BVH/light setup
//! excluded) and measuring RMSE against the high-spp Mitsuba reference. With `--mitsuba` the
//! same spp are rendered by Mitsuba 3 (`llvm_ad_spectral`, the Python thinfilm plugin) in the
//! same run through `tools/mitsuba/render_references.py --bench` (warm JIT, render time only),
//! and each of our rows gets "our time ÷ Mitsuba's time at equal error", interpolated on
//! Mitsuba's curve in log–log. Prints a markdown table and writes an error-against-time plot.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use std::process::Command;
use thinfilm::compare::metrics::{compare_images, downsample_box};
use thinfilm::compare::plot::{plot_error_vs_time, time_at_error, Series};
use thinfilm::compare::references::load_manifest;
use thinfilm::image_io::{read_exr_rgb, RgbImage};
use thinfilm::render::sampler::SamplerKind;
use thinfilm::render::{render, RenderOptions};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Also render with Mitsuba 3 (needs Python with `mitsuba`; see tools/mitsuba/).
    #[arg(long)]
    pub mitsuba: bool,
    /// Samples per pixel to try, comma-separated. Powers of 4: Mitsuba's `ldsampler` rounds
    /// other counts up to the next square power of two.
    #[arg(long, default_value = "16,64,256,1024", value_delimiter = ',')]
    pub spp: Vec<u32>,
    /// Only these reference scenes (names in the manifest); repeatable.
    #[arg(long)]
    pub only: Vec<String>,
    /// Repository root (holds tests/references and tools/mitsuba).
    #[arg(long, default_value = ".")]
    pub root: PathBuf,
    /// Error-against-time plot (PNG).
    #[arg(long, default_value = "bench_render.png")]
    pub plot: PathBuf,
    /// Also write the markdown table here.
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// Render nothing: redraw the plot from a table this command wrote before (`--table`),
    /// e.g. `--replot tests/references/bench_render.md --plot docs/img/bench_render.png`.
    #[arg(long, value_name = "TABLE.md")]
    pub replot: Option<PathBuf>,
    /// Python interpreter for the Mitsuba side.
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Sampler seed for both renderers (of the first run; see `--repeats`).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads for our renderer (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Sample sequence for both renderers, overriding each scene's sampler type:
    /// `independent` (both independent) or `sobol` (ours Owen-scrambled Sobol', Mitsuba's
    /// `ldsampler`). Default: each scene's own sampler, for both.
    #[arg(long)]
    pub sampler: Option<SamplerKind>,
    /// Render both at K× the reference's size and box-downsample by K before comparing
    /// (a K²-pixel box average is exactly the reference's box-filtered pixel), e.g.
    /// `--scale 2` times the 256×256 teapot scenes against the 128×128 references.
    #[arg(long, default_value_t = 1)]
    pub scale: u32,
    /// Fresnel splits per path for our renderer (default: the renderer's; 0 = one lobe
    /// chosen by Fresnel, as Mitsuba does).
    #[arg(long)]
    pub fresnel_splits: Option<u32>,
    /// Our renderer samples wavelengths also for camera rays that see an emitter directly
    /// (as Mitsuba does), instead of taking its closed-form expected colour.
    #[arg(long)]
    pub spectral_direct_view: bool,
    /// Our renderer draws environment light samples by radiance alone over the whole sphere
    /// (as Mitsuba does), instead of from the hemisphere a reflecting surface faces (or the
    /// cone around a narrow glossy lobe's mirror direction).
    #[arg(long)]
    pub plain_env_sampling: bool,
    /// Our renderer carries four wavelengths also on specular reflection chains (as Mitsuba
    /// does), instead of eight.
    #[arg(long)]
    pub plain_specular_chains: bool,
    /// Our renderer gives every pixel the same number of samples (as Mitsuba does), instead
    /// of adding the work of a quarter more where neighbouring pixels are noisy.
    #[arg(long)]
    pub uniform_samples: bool,
    /// Runs per spp, for both renderers, run j with seed `--seed` + j. Each row reports the
    /// fastest run's time (Mitsuba's first render at a new spp can include JIT compilation of
    /// its kernels — seen: 0.42 s instead of 0.14 s for a 64-spp teapot on a cold kernel
    /// cache —, and the shared machine's noise only ever adds time) and the error over all
    /// runs' images: RMSE over their pixels together, mean ΔE00.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeats: u32,
    #[command(flatten)]
    pub effects: super::bench_effects::Args,
}

#[derive(Debug, Clone)]
struct Row {
    spp: u32,
    seconds: f64,
    rmse: f64,
    delta_e00: f64,
}

fn run_mitsuba(
    args: &Args,
    scene: &std::path::Path,
    variant: &str,
    size: usize,
    out_dir: &std::path::Path,
) -> Result<(String, String, Vec<(Row, Vec<PathBuf>)>)> {
    let script = args.root.join("tools/mitsuba/render_references.py");
    let spp: Vec<String> = args.spp.iter().map(|s| s.to_string()).collect();
    let mut cmd = Command::new(&args.python);
    cmd.arg(&script)
        .arg("--bench")
        .arg(scene)
        .args(["--spp", &spp.join(",")])
        .args(["--size", &size.to_string()])
        .args(["--seed", &args.seed.to_string()])
        .args(["--repeats", &args.repeats.to_string()])
        .arg("--out-dir")
        .arg(out_dir)
        .args(["--json", "--skip-tmm-check", "--variant", variant]);
    if let Some(kind) = args.sampler {
        cmd.args([
            "--sampler",
            match kind {
                SamplerKind::Independent => "independent",
                SamplerKind::Sobol => "ldsampler",
            },
        ]);
    }
    if std::env::var_os("DRJIT_LIBLLVM_PATH").is_none() {
        cmd.env(
            "DRJIT_LIBLLVM_PATH",
            "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
        );
    }
    let out = cmd
        .output()
        .with_context(|| format!("running {} {}", args.python, script.display()))?;
    if !out.status.success() {
        bail!(
            "Mitsuba bench failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .rev()
                .take(5)
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    // Mitsuba logs warnings to stdout; the JSON document is the last line that is one.
    let stdout = String::from_utf8_lossy(&out.stdout);
    let json_line = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
        .unwrap_or("");
    let doc: serde_json::Value = serde_json::from_str(json_line).with_context(|| {
        format!(
            "parsing the Mitsuba bench JSON: {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })?;
    let variant = doc["variant"].as_str().unwrap_or("?").to_string();
    let sampler = doc["sampler"].as_str().unwrap_or("?").to_string();
    let runs = doc["runs"]
        .as_array()
        .context("Mitsuba bench JSON: no runs")?;
    let mut rows = Vec::new();
    for r in runs {
        let exrs = r["exrs"]
            .as_array()
            .context("run.exrs")?
            .iter()
            .map(|p| p.as_str().map(PathBuf::from).context("run.exrs[]"))
            .collect::<Result<Vec<_>>>()?;
        rows.push((
            Row {
                spp: r["spp"].as_u64().context("run.spp")? as u32,
                seconds: r["seconds"].as_f64().context("run.seconds")?,
                rmse: f64::NAN,
                delta_e00: f64::NAN,
            },
            exrs,
        ));
    }
    Ok((variant, sampler, rows))
}

/// The error of `repeats` renders (seeds S … S + repeats − 1) of one row against the
/// reference: RMSE over all their pixels (the root of the mean of the images' squared
/// errors) and the mean ΔE00. One seed's error is partly luck where a few pixels hold most of
/// it (a Cornell box's light edge, a gold teapot's highlights, `veach_mis`' glints): Mitsuba's
/// Cornell box at 256 spp had RMSE 0.0217 with seed 1 and 0.0235 over seeds 1–2 and 1–4.
/// Pooling N seeds narrows that spread by ~√N, for both renderers alike.
#[derive(Default)]
struct PooledError {
    squared: f64,
    delta_e00: f64,
    images: usize,
}

impl PooledError {
    fn add(&mut self, image: &RgbImage, reference: &RgbImage) -> Result<()> {
        let m = compare_images(image, reference)?;
        self.squared += m.rmse * m.rmse;
        self.delta_e00 += m.delta_e00_mean;
        self.images += 1;
        Ok(())
    }

    /// (RMSE, mean ΔE00) over the images added.
    fn get(&self) -> (f64, f64) {
        let n = self.images as f64;
        ((self.squared / n).sqrt(), self.delta_e00 / n)
    }
}

/// Our renders of reference `r` at each `--spp`: `--repeats` runs each with seeds S, S + 1,
/// …, the fastest run's time and the error pooled over all runs ([`PooledError`]).
fn render_ours(
    args: &Args,
    scene: &thinfilm::scene::Scene,
    r: &thinfilm::compare::references::Reference,
    reference: &thinfilm::image_io::RgbImage,
) -> Result<Vec<Row>> {
    let k = args.scale as usize;
    let mut ours = Vec::new();
    // Warm-up (page faults, thread pool) so the first timed row is not penalised.
    render(
        scene,
        &RenderOptions {
            spp: Some(1),
            resolution: Some((16, 16)),
            threads: args.threads,
            ..Default::default()
        },
    )?;
    for &spp in &args.spp {
        let (mut seconds, mut error) = (f64::INFINITY, PooledError::default());
        for j in 0..args.repeats as u64 {
            let options = RenderOptions {
                spp: Some(spp),
                seed: Some(args.seed + j),
                threads: args.threads,
                resolution: Some((k as u32 * r.width as u32, k as u32 * r.height as u32)),
                sampler: args.sampler,
                fresnel_splits: args.fresnel_splits,
                spectral_direct_view: args.spectral_direct_view,
                plain_env_sampling: args.plain_env_sampling,
                plain_specular_chains: args.plain_specular_chains,
                uniform_samples: args.uniform_samples,
                ..Default::default()
            };
            let out = render(scene, &options)?;
            seconds = seconds.min(out.stats.seconds);
            error
                .add(&downsample_box(&out.image, k)?, reference)
                .with_context(|| format!("{}: comparing with {}", r.name, r.exr.display()))?;
        }
        let (rmse, delta_e00) = error.get();
        eprintln!(
            "{:24} ours    {spp:5} spp {seconds:8.3} s RMSE {rmse:.5}",
            r.name
        );
        ours.push(Row {
            spp,
            seconds,
            rmse,
            delta_e00,
        });
    }
    Ok(ours)
}

/// Size of one scene's panel in the error-against-time plot.
const PANEL_PX: (u32, u32) = (330, 250);
const PLOT_TITLE: &str =
    "RMSE against render time, per scene: ours and Mitsuba 3 (same spp, seeds, sampler)";

/// The (seconds, RMSE) curves of ours and Mitsuba per scene, from a table written by this
/// command (columns: scene, spp, ours s, ours RMSE, ours ΔE00, Mitsuba s, Mitsuba RMSE, …).
fn series_from_table(path: &std::path::Path) -> Result<Vec<Series>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut series: Vec<Series> = Vec::new();
    for (i, line) in text.lines().enumerate().skip(2) {
        let cells: Vec<&str> = line
            .trim()
            .trim_matches('|')
            .split('|')
            .map(str::trim)
            .collect();
        if cells.len() < 7 {
            bail!(
                "{}:{}: expected the table of `bench render`",
                path.display(),
                i + 1
            );
        }
        let num = |k: usize| -> Result<f64> {
            cells[k].parse().with_context(|| {
                format!(
                    "{}:{}: column {} is '{}'",
                    path.display(),
                    i + 1,
                    k + 1,
                    cells[k]
                )
            })
        };
        let point = [(num(2)?, num(3)?), (num(5)?, num(6)?)];
        for (secondary, p) in [false, true].into_iter().zip(point) {
            match series
                .iter_mut()
                .find(|s| s.panel == cells[0] && s.secondary == secondary)
            {
                Some(s) => s.points.push(p),
                None => series.push(Series {
                    panel: cells[0].to_string(),
                    secondary,
                    points: vec![p],
                }),
            }
        }
    }
    Ok(series)
}

fn write_plot(series: &[Series], path: &std::path::Path) -> Result<()> {
    let legend = ["ours", "Mitsuba 3"];
    plot_error_vs_time(series, PLOT_TITLE, legend, "RMSE", path, PANEL_PX)?;
    println!("plot: {}", path.display());
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    if let Some(table) = &args.replot {
        return write_plot(&series_from_table(table)?, &args.plot);
    }
    if args.effects.effects {
        let table = args.table.as_deref();
        return args.effects.run(&args.root, args.seed, args.threads, table);
    }
    if args.spp.is_empty() || args.spp.contains(&0) {
        bail!("--spp needs positive sample counts");
    }
    if args.scale == 0 || args.scale > 16 {
        bail!("--scale must be between 1 and 16, got {}", args.scale);
    }
    let k = args.scale as usize;
    let at_reference_size = |img: &thinfilm::image_io::RgbImage| downsample_box(img, k);
    let mut refs = load_manifest(&args.root)?;
    if !args.only.is_empty() {
        for n in &args.only {
            if !refs.iter().any(|r| &r.name == n) {
                bail!("--only {n}: no such reference in the manifest");
            }
        }
        refs.retain(|r| args.only.contains(&r.name));
    }
    if args.seed.checked_add(args.repeats as u64).is_none() {
        bail!(
            "--seed {} with --repeats {}: the runs' seeds would overflow",
            args.seed,
            args.repeats
        );
    }
    if args.mitsuba {
        check_seeds_apart(&refs, args.seed, args.repeats)?;
    }
    let tmp = tempfile_dir()?;
    let mut table = String::new();
    let mut series = Vec::new();
    let mut mitsuba_variants = std::collections::BTreeSet::new();
    let mut summary = Vec::new();
    table.push_str("| scene | spp | ours s | ours RMSE | ours ΔE00 | Mitsuba s | Mitsuba RMSE | Mitsuba ΔE00 | our time ÷ Mitsuba's at equal error |\n");
    table.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in &refs {
        let reference = read_exr_rgb(&r.exr)?;
        let scene = thinfilm::scene::load(&r.scene, &[])
            .with_context(|| format!("loading {}", r.scene.display()))?;
        let ours = render_ours(&args, &scene, r, &reference)?;
        let mut theirs: Vec<Row> = Vec::new();
        if args.mitsuba {
            let dir = tmp.0.join(&r.name);
            let (variant, sampler, runs) = run_mitsuba(
                &args,
                &r.scene,
                r.variant.as_deref().unwrap_or("llvm_ad_spectral"),
                k * r.width.max(r.height),
                &dir,
            )?;
            let mut rows = Vec::new();
            for (mut row, exrs) in runs {
                let mut error = PooledError::default();
                for exr in &exrs {
                    error.add(&at_reference_size(&read_exr_rgb(exr)?)?, &reference)?;
                }
                if error.images != args.repeats as usize {
                    bail!(
                        "Mitsuba bench: {} images at {} spp, expected {} (--repeats)",
                        error.images,
                        row.spp,
                        args.repeats
                    );
                }
                (row.rmse, row.delta_e00) = error.get();
                eprintln!(
                    "{:24} mitsuba {:5} spp {:8.3} s RMSE {:.5}",
                    r.name, row.spp, row.seconds, row.rmse
                );
                rows.push(row);
            }
            mitsuba_variants.insert(format!("{variant} ({sampler})"));
            theirs = rows;
        }
        let their_curve: Vec<(f64, f64)> = theirs.iter().map(|r| (r.seconds, r.rmse)).collect();
        let mut last_ratio = None;
        for row in &ours {
            let t = theirs.iter().find(|t| t.spp == row.spp);
            // Only interpolate (or extrapolate by at most 2× in error) on Mitsuba's measured
            // curve: a biased render's error never reaches Mitsuba's, and a ratio read off a
            // far extrapolation would mean nothing.
            let (lo, hi) = their_curve
                .iter()
                .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p.1), h.max(p.1)));
            let in_range = row.rmse >= 0.5 * lo && row.rmse <= 2.0 * hi;
            let ratio = time_at_error(&their_curve, row.rmse)
                .filter(|_| in_range)
                .map(|tm| row.seconds / tm);
            last_ratio = ratio.map(|x| (x, row.spp)).or(last_ratio);
            table.push_str(&format!(
                "| {} | {} | {:.3} | {:.5} | {:.3} | {} | {} | {} | {} |\n",
                r.name,
                row.spp,
                row.seconds,
                row.rmse,
                row.delta_e00,
                t.map(|t| format!("{:.3}", t.seconds))
                    .unwrap_or_else(|| "–".into()),
                t.map(|t| format!("{:.5}", t.rmse))
                    .unwrap_or_else(|| "–".into()),
                t.map(|t| format!("{:.3}", t.delta_e00))
                    .unwrap_or_else(|| "–".into()),
                ratio
                    .map(|x| format!("{x:.2}"))
                    .unwrap_or_else(|| "–".into()),
            ));
        }
        if let Some((x, at_spp)) = last_ratio {
            summary.push((
                r.name.clone(),
                x,
                at_spp,
                ours.last().map(|r| r.delta_e00).unwrap_or(f64::NAN),
            ));
        }
        series.push(Series {
            panel: r.name.clone(),
            secondary: false,
            points: ours.iter().map(|r| (r.seconds, r.rmse)).collect(),
        });
        if !theirs.is_empty() {
            series.push(Series {
                panel: r.name.clone(),
                secondary: true,
                points: their_curve,
            });
        }
    }
    println!("{table}");
    if !mitsuba_variants.is_empty() {
        let v = mitsuba_variants.into_iter().collect::<Vec<_>>().join(", ");
        println!("Mitsuba variant(s) (sampler): {v} (polarised scenes use a *_polarized variant). Time ratio < 1: we reach the same RMSE faster.");
        for (n, x, at_spp, de) in &summary {
            println!("- {n}: our time ÷ Mitsuba's at equal error (at {at_spp} spp, the highest where Mitsuba's curve reaches our error) {x:.2}; our mean ΔE00 at {} spp {de:.3}", args.spp.last().unwrap());
        }
    }
    if let Some(p) = &args.table {
        thinfilm::image_io::write_atomically(p, |tmp| Ok(std::fs::write(tmp, &table)?))?;
    }
    write_plot(&series, &args.plot)?;
    Ok(())
}

/// Mitsuba's bench renders must not share samples with the reference they are scored
/// against: `render_references.py` renders seed S as passes with seeds S·1000003 + i
/// (i < 16), so a bench run with the reference's own seed would repeat the first
/// reference pass's samples and understate Mitsuba's error. The bench's runs use seeds
/// `seed` … `seed + repeats − 1`.
fn check_seeds_apart(
    refs: &[thinfilm::compare::references::Reference],
    seed: u64,
    repeats: u32,
) -> Result<()> {
    let seeds = seed..seed.saturating_add(repeats as u64);
    if let Some((r, s)) = refs
        .iter()
        .find_map(|r| r.seed.filter(|s| seeds.contains(s)).map(|s| (r, s)))
    {
        let runs = if repeats > 1 {
            format!(
                " (--repeats {repeats} renders seeds {seed}…{})",
                seeds.end - 1
            )
        } else {
            String::new()
        };
        bail!(
            "--seed {seed}{runs}: seed {s} is the seed reference '{}' was rendered with (tests/references/manifest.json): \
             Mitsuba's bench renders would share samples with it; pick another --seed",
            r.name
        );
    }
    Ok(())
}

/// The bench's scratch directory (Mitsuba's EXRs), removed when dropped: also when a run
/// fails half-way (a missing Python, a Mitsuba error), so no run leaves it behind.
struct ScratchDir(PathBuf);

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn tempfile_dir() -> Result<ScratchDir> {
    let dir = std::env::temp_dir().join(format!("thinfilm-bench-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(ScratchDir(dir))
}

#[cfg(test)]
mod tests {
    use super::*;
    use thinfilm::compare::references::Reference;

    fn reference(seed: u64) -> Reference {
        Reference {
            name: "box".into(),
            scene: "box.xml".into(),
            exr: "box.exr".into(),
            width: 1,
            height: 1,
            spp: 1,
            variant: None,
            seed: Some(seed),
        }
    }

    /// Every run's seed is checked, not only the first: seeds 3, 4, 5 against a reference
    /// rendered with seed 5.
    #[test]
    fn every_runs_seed_is_kept_apart_from_the_references() {
        let refs = [reference(5)];
        let err = check_seeds_apart(&refs, 3, 3).unwrap_err().to_string();
        assert!(
            err.contains("seeds 3…5") && err.contains("seed 5 is"),
            "{err}"
        );
        assert!(check_seeds_apart(&refs, 3, 2).is_ok());
        assert!(check_seeds_apart(&refs, 6, 4).is_ok());
        assert!(check_seeds_apart(&refs, u64::MAX, 2).is_ok());
    }

    /// The pooled RMSE is the RMSE over all images' pixels together.
    #[test]
    fn pooled_error_is_the_rms_over_all_images() {
        let image = |v: f32| RgbImage {
            width: 2,
            height: 1,
            pixels: vec![[v; 3]; 2],
        };
        let reference = image(0.0);
        let mut e = PooledError::default();
        e.add(&image(0.3), &reference).unwrap();
        e.add(&image(0.4), &reference).unwrap();
        let (rmse, _) = e.get();
        assert!((rmse - (0.125f64).sqrt()).abs() < 1e-6, "{rmse}");
    }
}
