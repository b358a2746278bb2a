//! `thinfilm render SCENE -o OUT.exr`: renders a Mitsuba 3 XML / glTF / OBJ / PLY scene with the
//! spectral path tracer; writes linear sRGB EXR (`R`,`G`,`B` float32) and a tone-mapped PNG
//! beside it, and prints time, samples/s and rays/s.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use thinfilm::render::{render, RenderOptions};

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
    /// Render only global sample indices START:END (split a render; merge renders of
    /// power-of-two-aligned ranges by sample-weighted mean to reproduce the full render exactly).
    #[arg(long, value_parser = parse_range)]
    pub sample_range: Option<(u32, u32)>,
    /// Scene parameter `key=value` (Mitsuba `-D`), fills `$key` / `<default name="key">`.
    #[arg(short = 'D', value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Smooth glass and bubble interfaces at which a path follows both the reflection and
    /// the transmission (default 3; 0 = pick one lobe by Fresnel, as Mitsuba does). Same
    /// expected image; splitting costs rays and removes the noise of rarely chosen lobes.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=16))]
    pub fresnel_splits: Option<u32>,
    /// Exposure multiplier for the PNG only (finite, ≥ 0).
    #[arg(long, allow_hyphen_values = true, default_value_t = 1.0, value_parser = super::args::non_negative_f32)]
    pub exposure: f32,
}

fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{s}' is not WxH (e.g. 256x256)"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in '{s}'"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in '{s}'"))?;
    if w == 0 || h == 0 || w > 65536 || h > 65536 {
        return Err(format!(
            "resolution '{s}' must be between 1x1 and 65536x65536"
        ));
    }
    Ok((w, h))
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

pub fn run(args: Args) -> Result<()> {
    let ext = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext != "exr" {
        bail!("output {} must end in .exr", args.output.display());
    }
    let scene = thinfilm::scene::load(&args.scene, &args.define)
        .with_context(|| format!("loading scene {}", args.scene.display()))?;
    let options = RenderOptions {
        spp: args.spp,
        seed: args.seed,
        threads: args.threads,
        max_depth: args.max_depth,
        resolution: args.resolution,
        sample_range: args.sample_range,
        sampler: args.sampler,
        fresnel_splits: args.fresnel_splits,
        progress: true,
    };
    let out =
        render(&scene, &options).with_context(|| format!("rendering {}", args.scene.display()))?;
    eprintln!("effects:\n{}", out.effects);
    thinfilm::image_io::write_exr_rgb(&args.output, &out.image)?;
    let png = args.output.with_extension("png");
    thinfilm::image_io::write_png_tonemapped(&png, &out.image, args.exposure)?;
    let s = &out.stats;
    println!(
        "rendered {}×{} samples {}:{} in {:.3} s (+{:.3} s setup, {} threads, {} triangles)",
        out.image.width,
        out.image.height,
        out.sample_range.0,
        out.sample_range.1,
        s.seconds,
        s.setup_seconds,
        s.threads,
        s.triangles
    );
    println!(
        "{:.3} Msamples/s, {:.3} Mrays/s ({} camera/bounce + {} shadow rays), {} thin-film evaluations",
        s.samples_per_second() / 1e6,
        s.rays_per_second() / 1e6,
        s.rays,
        s.shadow_rays,
        s.film_evals
    );
    if s.secondary_terminations > 0 {
        println!(
            "dispersion: {} paths kept only their hero wavelength after a dispersive refraction",
            s.secondary_terminations
        );
    }
    if s.invalid_samples > 0 {
        eprintln!(
            "warning: {} samples were NaN/inf and were discarded",
            s.invalid_samples
        );
    }
    if s.degenerate_triangles > 0 {
        eprintln!(
            "note: {} degenerate triangles were skipped",
            s.degenerate_triangles
        );
    }
    println!("wrote {} and {}", args.output.display(), png.display());
    Ok(())
}
