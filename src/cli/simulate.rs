//! `thinfilm simulate`: parse options into a [`SimulateConfig`] and write a capture set.
//! All physics lives in `thinfilm::capture::simulate`.

use anyhow::Context;
use std::path::PathBuf;
use thinfilm::capture::envi::Interleave;
use thinfilm::capture::simulate::{
    parse_angles, parse_wavelengths, write_capture_set, SimulateConfig,
};
use thinfilm::capture::Polarization;
use thinfilm::optics::{Complex64, Ior};

/// Boxed so the `Command` enum stays small (the options are many).
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub options: Box<Options>,
}

#[derive(clap::Args, Debug)]
pub struct Options {
    /// Output folder (capture.json, one ENVI cube per angle, ground_truth/).
    #[arg(long)]
    pub out: PathBuf,
    /// Start from one of the seed paper's samples (MgF2 400 nm, MgF2 600 nm, ZnS 500 nm on
    /// PET, S-polarised, 10–50°, 4 nm bands); explicit options override it.
    #[arg(long, value_parser = ["sample1", "sample2", "sample3"])]
    pub preset: Option<String>,
    /// Film index: number, n+ki, or material name [default: 1.37].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::index)]
    pub film_ior: Option<Ior>,
    /// Mean film thickness, nm [default: 400].
    #[arg(long, allow_hyphen_values = true, value_name = "NM", value_parser = super::args::thickness_nm)]
    pub thickness: Option<f64>,
    /// Relative amplitude of the smooth thickness field, 0–1 [default: 0.05].
    #[arg(long, value_name = "FRACTION")]
    pub thickness_variation: Option<f64>,
    /// Substrate index: number, n+ki, or material name [default: 1.64 (PET)].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::index)]
    pub substrate_ior: Option<Ior>,
    /// Substrate extinction coefficient k (added to a numeric --substrate-ior).
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::non_negative)]
    pub substrate_k: Option<f64>,
    /// Ambient index, in [1, 3] [default: 1].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::ambient_index)]
    pub ambient_ior: Option<f64>,
    /// Incident angles in degrees, comma-separated [default: 10,20,30,40,50].
    #[arg(long)]
    pub angles: Option<String>,
    /// Band centres: START:END:STEP in nm, or a comma list [default: 400:720:4].
    #[arg(long)]
    pub wavelengths: Option<String>,
    /// Gaussian band FWHM in nm; 0 samples band centres [default: 4].
    #[arg(long, allow_hyphen_values = true, value_name = "NM", value_parser = super::args::non_negative)]
    pub fwhm: Option<f64>,
    /// Additive Gaussian noise, reflectance units [default: 0].
    #[arg(long, allow_hyphen_values = true, value_name = "SIGMA", value_parser = super::args::non_negative)]
    pub noise: Option<f64>,
    /// Write uint16 raw counts with white and dark reference cubes (shot + read noise).
    #[arg(long)]
    pub raw_counts: bool,
    /// Raw mode: white signal at the spectrum's peak, counts [default: 40000].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::non_negative)]
    pub white_counts: Option<f64>,
    /// Raw mode: dark level, counts [default: 800].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::non_negative)]
    pub dark_counts: Option<f64>,
    /// Raw mode: read noise, counts [default: 3].
    #[arg(long, allow_hyphen_values = true, value_parser = super::args::non_negative)]
    pub read_noise: Option<f64>,
    /// s, p or unpolarized [default: s].
    #[arg(long)]
    pub polarization: Option<Polarization>,
    /// Image size WxH [default: 64x64].
    #[arg(long, value_parser = super::args::size)]
    pub size: Option<(usize, usize)>,
    /// Random seed [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
    /// ENVI interleave of the written cubes: bsq, bil or bip [default: bsq].
    #[arg(long)]
    pub interleave: Option<Interleave>,
    /// Realism: exposure of each angle drawn in 1 ± V (0.4 = ±40 %) [default: 0].
    #[arg(long, value_name = "V", help_heading = "Realistic capture effects")]
    pub exposure_variation: Option<f64>,
    /// Realism: vignetting gain in the image corners (radial falloff), 0.5 = half [default: 1].
    #[arg(long, value_name = "GAIN", help_heading = "Realistic capture effects")]
    pub vignetting: Option<f64>,
    /// Realism: lamp drift since the white reference, a tilt across the band drawn in ±V
    /// per angle (0.1 = ±10 % from blue to red end) [default: 0].
    #[arg(long, value_name = "V", help_heading = "Realistic capture effects")]
    pub lamp_tilt: Option<f64>,
    /// Realism: stray light added per angle, drawn in [0, V] (reflectance units) [default: 0].
    #[arg(long, value_name = "V", help_heading = "Realistic capture effects")]
    pub background: Option<f64>,
    /// Realism: error added to the substrate index written into capture.json (the
    /// simulation uses the true one) [default: 0].
    #[arg(
        long,
        value_name = "DN",
        allow_hyphen_values = true,
        help_heading = "Realistic capture effects"
    )]
    pub substrate_error: Option<f64>,
    /// Realism: the incidence varies by ±DEG across the image width (camera field of view)
    /// [default: 0].
    #[arg(long, value_name = "DEG", help_heading = "Realistic capture effects")]
    pub fov_deg: Option<f64>,
    /// Write per-pixel incidence maps (angleNN.exr) and name them in capture.json.
    #[arg(long, help_heading = "Realistic capture effects")]
    pub angle_maps: bool,
}

/// Builds the configuration: preset (or defaults), then every explicit option.
pub fn config(args: &Options, progress: bool) -> anyhow::Result<SimulateConfig> {
    let mut cfg = match &args.preset {
        Some(p) => SimulateConfig::preset(p)?,
        None => SimulateConfig::default(),
    };
    if let Some(v) = &args.film_ior {
        cfg.film_ior = v.clone();
    }
    if let Some(v) = args.thickness {
        cfg.thickness_nm = v;
    }
    if let Some(v) = args.thickness_variation {
        cfg.thickness_variation = v;
    }
    if let Some(v) = &args.substrate_ior {
        cfg.substrate_ior = v.clone();
    }
    if let Some(k) = args.substrate_k {
        cfg.substrate_ior = match &cfg.substrate_ior {
            Ior::Constant(c) => Ior::Constant(Complex64::new(c.re, k)),
            Ior::Material(m) => anyhow::bail!(
                "--substrate-k cannot be combined with the material '{}'",
                m.name
            ),
        };
    }
    if let Some(v) = args.ambient_ior {
        cfg.ambient_ior = v;
    }
    if let Some(v) = &args.angles {
        cfg.angles_deg = parse_angles(v).context("--angles")?;
    }
    if let Some(v) = &args.wavelengths {
        cfg.wavelengths_nm = parse_wavelengths(v).context("--wavelengths")?;
    }
    if let Some(v) = args.fwhm {
        cfg.fwhm_nm = v;
    }
    if let Some(v) = args.noise {
        cfg.noise_sigma = v;
    }
    cfg.raw_counts |= args.raw_counts;
    if let Some(v) = args.white_counts {
        cfg.white_counts = v;
    }
    if let Some(v) = args.dark_counts {
        cfg.dark_counts = v;
    }
    if let Some(v) = args.read_noise {
        cfg.read_noise = v;
    }
    if let Some(v) = args.polarization {
        cfg.polarization = v;
    }
    if let Some((w, h)) = args.size {
        cfg.width = w;
        cfg.height = h;
    }
    if let Some(v) = args.seed {
        cfg.seed = v;
    }
    if let Some(v) = args.interleave {
        cfg.interleave = v;
    }
    let r = &mut cfg.realism;
    if let Some(v) = args.exposure_variation {
        r.exposure_variation = v;
    }
    if let Some(v) = args.vignetting {
        r.vignetting_min = v;
    }
    if let Some(v) = args.lamp_tilt {
        r.lamp_tilt = v;
    }
    if let Some(v) = args.background {
        r.background = v;
    }
    if let Some(v) = args.substrate_error {
        r.substrate_error = v;
    }
    if let Some(v) = args.fov_deg {
        r.fov_half_deg = v;
    }
    r.write_angle_maps |= args.angle_maps;
    cfg.progress = progress;
    cfg.validate().context("simulate options")?;
    Ok(cfg)
}

pub fn run(args: Args, report: super::Output) -> anyhow::Result<()> {
    let cfg = config(&args.options, report.progress())?;
    let summary = write_capture_set(&cfg, &args.options.out)?;
    let stats = thinfilm::capture::simulate::thickness_stats(&summary.thickness_nm);
    let stat = |k: &str| stats[k].as_f64().unwrap_or(f64::NAN);
    report.log(format_args!(
        "wrote {} ({} angles, {}×{} px, {} bands); ground truth {} (thickness mean {:.1} nm, range {:.1}–{:.1} nm)",
        summary.capture_json.display(),
        cfg.angles_deg.len(),
        cfg.width,
        cfg.height,
        cfg.wavelengths_nm.len(),
        summary.ground_truth_json.display(),
        stat("mean"),
        stat("min"),
        stat("max"),
    ));
    report.json(&serde_json::json!({
        "capture_json": summary.capture_json,
        "ground_truth_json": summary.ground_truth_json,
        "angles_deg": cfg.angles_deg,
        "width": cfg.width,
        "height": cfg.height,
        "bands": cfg.wavelengths_nm.len(),
        "thickness_nm": stats,
    }))
}
