//! `thinfilm render SCENE -o OUT.exr`: renders a Mitsuba 3 XML / glTF / OBJ / PLY scene with the
//! spectral path tracer; writes linear sRGB EXR (`R`,`G`,`B` float32, the render's provenance
//! in the header) and a tone-mapped PNG beside it, and prints time, samples/s and rays/s.
//! Ctrl-C (or SIGTERM) saves the completed sample passes as `OUT.samples-A-B.exr` and prints
//! the commands that finish the render exactly.

use super::{Interrupted, Output};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use thinfilm::render::provenance::{self, RenderInfo};
use thinfilm::render::{prepare, render_prepared, Cancel, RenderOptions, RenderOutput};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file: Mitsuba 3 XML subset, .gltf/.glb, .obj or .ply.
    pub scene: PathBuf,
    /// Output EXR (linear sRGB, Rec.709/D65). A tone-mapped PNG is written beside it.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples per pixel, 1 to 1048576 (overrides the scene's sampler `sample_count`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1 << 20))]
    pub spp: Option<u32>,
    /// Sampler seed (overrides the scene's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Sample sequence, overriding the scene's sampler type: `independent` (PCG, Mitsuba's
    /// `independent`) or `sobol` (Owen-scrambled Sobol', used for Mitsuba's `ldsampler`,
    /// `stratified`, `multijitter`, `orthogonal`): same expected image, less noise.
    #[arg(long)]
    pub sampler: Option<thinfilm::render::sampler::SamplerKind>,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::args::threads)]
    pub threads: Option<usize>,
    /// Path vertices as in Mitsuba (1 = directly visible emitters only, −1 = unlimited).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_max_depth)]
    pub max_depth: Option<i32>,
    /// Image size WxH (overrides the scene's film).
    #[arg(long, value_parser = parse_resolution)]
    pub resolution: Option<(u32, u32)>,
    /// Render only global sample indices START:END, to split a render over processes or
    /// machines; `thinfilm merge` puts the pieces together, bit-identical to one render when
    /// the ranges are powers of two aligned like 0:16 16:32 32:64 64:128.
    #[arg(long, value_parser = parse_range)]
    pub sample_range: Option<(u32, u32)>,
    /// Render part K of N equal sample ranges (K from 0; e.g. a job array's task index and
    /// count): the same as the matching --sample-range. Exact merges need power-of-two spp
    /// and N.
    #[arg(long, value_parser = super::parse_part, value_name = "K/N", conflicts_with = "sample_range")]
    pub part: Option<(usize, usize)>,
    /// Scene parameter `key=value` (Mitsuba `-D`), fills `$key` / `<default name="key">`.
    #[arg(short = 'D', value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Smooth glass and bubble interfaces at which a path follows both the reflection and
    /// the transmission (default 3; 0 = pick one lobe by Fresnel, as Mitsuba does). Same
    /// expected image; splitting costs rays and removes the noise of rarely chosen lobes.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=16))]
    pub fresnel_splits: Option<u32>,
    /// Trace with Stokes vectors and Mueller matrices even without a polariser in the scene
    /// (a check: the image must equal the unpolarised one within float rounding; refused if
    /// a material has no polarised form).
    #[arg(long)]
    pub force_polarization: bool,
    /// Sample wavelengths also for camera rays that see an emitter directly (the
    /// environment, an area light). By default such a ray's colour is the emitter's expected
    /// colour over the sampled wavelengths (each environment texel's and each untextured area
    /// light's spectrum integrated once against the film's matching functions): the same
    /// expected image without the colour noise of the background and of visible lights.
    #[arg(long)]
    pub spectral_direct_view: bool,
    /// Draw environment light samples by radiance alone over the whole sphere, as Mitsuba
    /// does. By default a surface that only reflects draws them from the hemisphere its normal
    /// faces (per bin of normals: each region of the map by its radiance, less part of the
    /// hemisphere's mean, which BSDF samples already find, times the mean cosine towards it),
    /// and a narrow glossy lobe (rough metal or film, GGX α ≤ 0.4) from around its mirror
    /// direction: the same expected image, with fewer samples wasted below the horizon, on
    /// even light or outside the lobe.
    #[arg(long)]
    pub plain_env_sampling: bool,
    /// Carry four wavelengths also on paths that only reflect off smooth films and coatings
    /// (and mirrors after them), as Mitsuba does. By default such a path (its directions the
    /// same at every wavelength) carries eight, stratified, to the emitter it meets: the same
    /// expected image with less colour noise on interference films.
    #[arg(long)]
    pub plain_specular_chains: bool,
    /// Give every pixel the same number of samples, as Mitsuba does. By default (box filter,
    /// 8 or more samples, a whole render rather than a --sample-range piece) every pixel takes
    /// its samples, and then the work of a quarter more goes to the pixels whose neighbours'
    /// samples spread most — edges of lights, glints, caustics — up to 8× the sample count
    /// more in one pixel: the same expected image, nowhere noisier, far less error where it
    /// is largest, for at most ~25 % more time.
    #[arg(long)]
    pub uniform_samples: bool,
    /// Environment replacing the scene's own: a lat-long EXR/HDR file (Mitsuba `envmap`
    /// layout), `constant:V` (D65 of luminance V) or `constant:R,G,B` (RGB illuminant).
    #[arg(long, value_name = "FILE|constant:V|constant:R,G,B")]
    pub environment: Option<thinfilm::scene::environment::EnvironmentSource>,
    /// Turns the environment about the up (+Y) axis by DEG degrees, right-handed, as
    /// Mitsuba's `<rotate y="1" angle="DEG"/>` on an `envmap`.
    #[arg(long, value_name = "DEG", allow_hyphen_values = true, value_parser = super::args::finite_f32)]
    pub environment_rotation: Option<f32>,
    /// Exposure multiplier for the PNG only (finite, ≥ 0).
    #[arg(long, allow_hyphen_values = true, default_value_t = 1.0, value_parser = super::args::non_negative_f32)]
    pub exposure: f32,
}

/// `WxH`, each side 1 to 65536 (so it fits `u32`).
fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    super::args::size(s).map(|(w, h)| (w as u32, h as u32))
}

fn parse_max_depth(s: &str) -> Result<i32, String> {
    match s.trim().parse::<i32>() {
        Ok(d) if d == -1 || d >= 1 => Ok(d),
        _ => Err(format!(
            "'{s}' must be −1 (unlimited) or a whole number ≥ 1"
        )),
    }
}

fn parse_range(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("'{s}' is not START:END (e.g. 0:32)"))?;
    let a: u32 = a
        .trim()
        .parse()
        .map_err(|_| format!("bad START in '{s}'"))?;
    let b: u32 = b.trim().parse().map_err(|_| format!("bad END in '{s}'"))?;
    if a >= b {
        return Err(format!("sample range '{s}' is empty: START must be < END"));
    }
    Ok((a, b))
}

fn parse_define(s: &str) -> Result<(String, String), String> {
    let (k, v) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not key=value"))?;
    if k.trim().is_empty() {
        return Err(format!("empty key in '{s}'"));
    }
    Ok((k.trim().to_string(), v.to_string()))
}

/// Raises the returned flag on Ctrl-C or SIGTERM (a batch system's time limit or `scancel`),
/// so the render stops after the rows in flight and saves what it has; a second signal ends
/// the process at once.
fn cancel_on_interrupt() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    let installed = ctrlc::set_handler(move || {
        if f.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!(
            "\ninterrupt: finishing the rows in flight, then saving the completed sample passes \
             (interrupt again to quit at once)"
        );
    });
    if let Err(e) = installed {
        eprintln!("note: Ctrl-C will not save a partial render ({e})");
    }
    flag
}

/// `out.exr` → `out.samples-A-B.exr`: where a piece of a split render goes.
fn piece_path(output: &Path, (a, b): (u32, u32)) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    output.with_file_name(format!("{stem}.samples-{a}-{b}.exr"))
}

/// This command line with the output and sample range replaced (for the resume hint).
fn command_for(output: &Path, range: (u32, u32)) -> String {
    let mut args: Vec<String> = Vec::new();
    let mut skip = false;
    for (i, a) in std::env::args().enumerate() {
        if std::mem::take(&mut skip) {
            continue;
        }
        if i == 0 {
            args.push("thinfilm".into());
            continue;
        }
        match a.as_str() {
            "-o" | "--output" | "--sample-range" | "--part" => skip = true,
            _ if a.starts_with("--output=")
                || a.starts_with("--sample-range=")
                || a.starts_with("--part=")
                || (a.starts_with("-o") && a.len() > 2 && !a.starts_with("--")) => {}
            _ => args.push(a),
        }
    }
    args.push("--sample-range".into());
    args.push(format!("{}:{}", range.0, range.1));
    args.push("-o".into());
    args.push(output.display().to_string());
    args.iter()
        .map(|a| {
            if a.chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_./:=,+@%".contains(c))
            {
                a.clone()
            } else {
                format!("'{}'", a.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

pub fn run(args: Args, report: Output) -> Result<()> {
    let ext = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext != "exr" {
        bail!("output {} must end in .exr", args.output.display());
    }
    let mut scene = thinfilm::scene::load(&args.scene, &args.define)
        .with_context(|| format!("loading scene {}", args.scene.display()))?;
    thinfilm::scene::environment::apply(
        &mut scene,
        args.environment.as_ref(),
        args.environment_rotation,
    )?;
    let options = options(&args, scene.spp, report)?;
    let t0 = std::time::Instant::now();
    let prepared =
        prepare(&scene, &options).with_context(|| format!("preparing {}", args.scene.display()))?;
    let setup = t0.elapsed().as_secs_f64();
    // The provenance hash formats the whole scene; it runs beside the render.
    let (out, info) = std::thread::scope(|s| {
        let info = s.spawn(|| RenderInfo::new(&scene, &prepared, prepared.sample_range()));
        let out = render_prepared(&prepared, &options);
        (out, info.join())
    });
    let mut out = out.with_context(|| format!("rendering {}", args.scene.display()))?;
    let mut info = info.map_err(|_| anyhow::anyhow!("hashing the scene failed"))?;
    info.sample_range = out.sample_range;
    info.adaptive = out.adaptive;
    out.stats.setup_seconds = setup;
    report.log(format_args!("effects:\n{}", out.effects));
    let path = if out.interrupted {
        piece_path(&args.output, out.sample_range)
    } else {
        args.output.clone()
    };
    // The PNG is written beside the EXR (two independent files from the same pixels).
    let png = path.with_extension("png");
    let (exr_written, png_written) = std::thread::scope(|s| {
        let png_written =
            s.spawn(|| thinfilm::image_io::write_png_tonemapped(&png, &out.image, args.exposure));
        let exr_written =
            provenance::write_exr(&path, &out.image, out.filter_weights.as_deref(), &info);
        let png_written = (png_written.join()).unwrap_or_else(|p| std::panic::resume_unwind(p));
        (exr_written, png_written)
    });
    exr_written?;
    png_written?;
    print_stats(report, &out);
    report.text(format_args!(
        "wrote {} and {}",
        path.display(),
        png.display()
    ));
    let resume = if out.interrupted {
        thinfilm::render::passes::remaining_nodes(out.requested_range, out.sample_range.1)
    } else {
        Vec::new()
    };
    report.json(&summary_json(&out, &info, &path, &png, &resume))?;
    if out.interrupted {
        eprintln!("{}", resume_hint(&args, &out, &path, &resume));
        return Err(Interrupted.into());
    }
    // The process ends here: returning the scene's and the BVH's pages one allocation at a
    // time (~0.1 s for 2M triangles) is work the exit does at once.
    std::mem::forget((prepared, scene, out));
    Ok(())
}

/// The render options of the command line (`--part K/N` becomes its sample range).
fn options(args: &Args, scene_spp: u32, report: Output) -> Result<RenderOptions> {
    let sample_range = match args.part {
        Some((k, n)) => Some(thinfilm::render::passes::part(
            args.spp.unwrap_or(scene_spp),
            u32::try_from(k).unwrap_or(u32::MAX),
            u32::try_from(n).unwrap_or(u32::MAX),
        )?),
        None => args.sample_range,
    };
    Ok(RenderOptions {
        spp: args.spp,
        seed: args.seed,
        threads: args.threads,
        max_depth: args.max_depth,
        resolution: args.resolution,
        sample_range,
        sampler: args.sampler,
        fresnel_splits: args.fresnel_splits,
        progress: report.progress(),
        cancel: Some(Cancel::on_flag(cancel_on_interrupt())),
        force_polarization: args.force_polarization,
        spectral_direct_view: args.spectral_direct_view,
        plain_env_sampling: args.plain_env_sampling,
        plain_specular_chains: args.plain_specular_chains,
        uniform_samples: args.uniform_samples,
    })
}

/// Time, throughput and the counters worth a line (warnings on stderr).
fn print_stats(report: Output, out: &RenderOutput) {
    let s = &out.stats;
    let (r0, r1) = out.sample_range;
    report.text(format_args!(
        "rendered {}×{} samples {r0}:{r1} in {:.3} s (+{:.3} s setup, {} threads, {} triangles)",
        out.image.width, out.image.height, s.seconds, s.setup_seconds, s.threads, s.triangles
    ));
    report.text(format_args!(
        "{:.3} Msamples/s, {:.3} Mrays/s ({} camera/bounce + {} shadow rays), {} thin-film evaluations",
        s.samples_per_second() / 1e6,
        s.rays_per_second() / 1e6,
        s.rays,
        s.shadow_rays,
        s.film_evals
    ));
    if s.secondary_terminations > 0 {
        report.text(format_args!(
            "dispersion: {} paths kept only their hero wavelength after a dispersive refraction",
            s.secondary_terminations
        ));
    }
    if s.invalid_samples > 0 {
        eprintln!(
            "warning: {} samples were NaN/inf and were discarded",
            s.invalid_samples
        );
    }
    if s.degenerate_triangles > 0 {
        report.log(format_args!(
            "note: {} degenerate or repeated triangles were skipped",
            s.degenerate_triangles
        ));
    }
}

/// The `--json` result.
fn summary_json(
    out: &RenderOutput,
    info: &RenderInfo,
    path: &Path,
    png: &Path,
    resume: &[(u32, u32)],
) -> serde_json::Value {
    let s = &out.stats;
    let (r0, r1) = out.sample_range;
    serde_json::json!({
        "output": path,
        "png": png,
        "width": out.image.width,
        "height": out.image.height,
        "sample_range": [r0, r1],
        "requested_range": [out.requested_range.0, out.requested_range.1],
        "interrupted": out.interrupted,
        "resume_sample_ranges": resume.iter().map(|&(a, b)| [a, b]).collect::<Vec<_>>(),
        "image_hash": format!("{:016x}", info.image_hash),
        "seconds": s.seconds,
        "setup_seconds": s.setup_seconds,
        "threads": s.threads,
        "samples": s.samples,
        "samples_per_second": s.samples_per_second(),
        "rays_per_second": s.rays_per_second(),
        "invalid_samples": s.invalid_samples,
    })
}

/// What an interrupted render saved, and the commands that finish it exactly.
fn resume_hint(args: &Args, out: &RenderOutput, path: &Path, resume: &[(u32, u32)]) -> String {
    let (r0, r1) = out.sample_range;
    let (q0, q1) = out.requested_range;
    let mut pieces = vec![path.display().to_string()];
    let mut lines = Vec::new();
    for &range in resume {
        let piece = piece_path(&args.output, range);
        lines.push(format!("  {}", command_for(&piece, range)));
        pieces.push(piece.display().to_string());
    }
    format!(
        "interrupted: {} holds samples {r0}:{r1} of {q0}:{q1} (a whole number of \
         power-of-two sample passes). To finish the render exactly, run\n{}\n  thinfilm merge {} -o {}",
        path.display(),
        lines.join("\n"),
        pieces.join(" "),
        args.output.display()
    )
}
