//! `thinfilm reflectance`: reflectance/transmittance spectra of a single film or a stack at
//! one (or several) incident angles, as CSV or JSON, with the colour under D65 and an
//! optional plot (the seed paper's Fig. 2 is made this way, see README).

use anyhow::{bail, Context, Result};
use num_complex::Complex64;
use std::path::PathBuf;
use thinfilm::image_io::write_png_rgb8;
use thinfilm::optics::{Coherence, FilmResponse, Ior, Layer, Stack};
use thinfilm::spectrum;

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Csv,
    Json,
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Film index (single film): a number (1.37), complex n+ki (1.5+0.1i) or a material
    /// name (MgF2, ZnS, SiO2, TiO2, water, PET, BK7, Al, Ag, Au, Cu). Needs --thickness.
    #[arg(long, value_name = "IOR", conflicts_with = "layer")]
    pub film_ior: Option<Ior>,
    /// Film thickness in nm (single film).
    #[arg(
        long,
        value_name = "NM",
        requires = "film_ior",
        allow_hyphen_values = true
    )]
    pub thickness: Option<f64>,
    /// A stack layer `IOR:NM` (repeat, top first); append `:i` for an incoherent (thick)
    /// layer, e.g. `--layer ZnS:60 --layer MgF2:100 --layer BK7:1000000:i`.
    #[arg(long, value_name = "IOR:NM")]
    pub layer: Vec<String>,
    /// Substrate index (number, n+ki or material name).
    #[arg(long, value_name = "IOR", default_value = "1.64")]
    pub substrate_ior: Ior,
    /// Substrate extinction coefficient k, added to a real --substrate-ior.
    #[arg(
        long,
        value_name = "K",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    pub substrate_k: f64,
    /// Ambient index (must be lossless).
    #[arg(long, value_name = "IOR", default_value = "1")]
    pub ambient_ior: Ior,
    /// Incident angle in degrees, in [0, 90). Repeat (or comma-separate) for several curves
    /// in the plot; CSV then gains a leading `angle_deg` column and JSON becomes an array.
    #[arg(
        long,
        value_name = "DEG",
        default_value = "0",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub angle: Vec<f64>,
    /// Wavelengths in nm: `start:stop:step` (stop included) or a list `400,512.5,700`.
    #[arg(
        long,
        value_name = "SPEC",
        default_value = "380:780:5",
        allow_hyphen_values = true
    )]
    pub wavelengths: String,
    /// Output format on stdout.
    #[arg(long, value_enum, default_value_t = Format::Csv)]
    pub format: Format,
    /// Also draw R(λ) (unpolarised; one curve per angle) into this PNG.
    #[arg(long, value_name = "PNG")]
    pub plot: Option<PathBuf>,
}

/// Parses `400:700:5` (inclusive) or `400,512.5,700`.
pub fn parse_wavelengths(spec: &str) -> Result<Vec<f64>> {
    let spec = spec.trim();
    let num = |s: &str| -> Result<f64> {
        let v: f64 = s
            .trim()
            .parse()
            .with_context(|| format!("--wavelengths: '{s}' is not a number"))?;
        if !(v.is_finite() && v > 0.0) {
            bail!("--wavelengths: {v} nm is not a wavelength (must be finite and > 0)");
        }
        Ok(v)
    };
    let out: Vec<f64> = if spec.contains(':') {
        let p: Vec<&str> = spec.split(':').collect();
        if p.len() != 3 {
            bail!("--wavelengths: expected start:stop:step, got '{spec}'");
        }
        let (a, b, step) = (num(p[0])?, num(p[1])?, num(p[2])?);
        if b < a {
            bail!("--wavelengths: stop {b} is below start {a}");
        }
        let n = ((b - a) / step + 1e-9).floor() as usize + 1;
        if n > 1_000_000 {
            bail!("--wavelengths: {n} samples is too many");
        }
        (0..n).map(|i| a + i as f64 * step).collect()
    } else {
        spec.split(',').map(num).collect::<Result<_>>()?
    };
    if out.is_empty() {
        bail!("--wavelengths: no wavelengths in '{spec}'");
    }
    Ok(out)
}

/// A layer whose index may depend on wavelength.
#[derive(Debug, Clone)]
pub struct LayerSpec {
    pub ior: Ior,
    pub thickness_nm: f64,
    pub coherence: Coherence,
}

/// Parses `IOR:NM` or `IOR:NM:i` / `IOR:NM:c`.
pub fn parse_layer(s: &str) -> Result<LayerSpec> {
    let p: Vec<&str> = s.split(':').collect();
    if !(2..=3).contains(&p.len()) {
        bail!("--layer '{s}': expected IOR:NM or IOR:NM:i");
    }
    let ior: Ior = p[0]
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--layer '{s}': {e}"))?;
    let thickness_nm: f64 = p[1]
        .trim()
        .parse()
        .with_context(|| format!("--layer '{s}': thickness '{}' is not a number", p[1]))?;
    check_thickness(thickness_nm, &format!("--layer '{s}'"))?;
    let coherence = match p.get(2).map(|c| c.trim()) {
        None | Some("c") => Coherence::Coherent,
        Some("i") => Coherence::Incoherent,
        Some(o) => bail!("--layer '{s}': coherence '{o}' must be 'c' or 'i'"),
    };
    Ok(LayerSpec {
        ior,
        thickness_nm,
        coherence,
    })
}

fn check_thickness(d: f64, what: &str) -> Result<()> {
    if !(d.is_finite() && d >= 0.0) {
        bail!("{what}: thickness must be finite and ≥ 0 nm, got {d}");
    }
    Ok(())
}

/// The optical system with possibly dispersive indices, evaluated per wavelength.
#[derive(Debug, Clone)]
pub struct System {
    pub ambient: Ior,
    pub layers: Vec<LayerSpec>,
    pub substrate: Ior,
    pub substrate_k: f64,
}

impl System {
    pub fn from_args(a: &Args) -> Result<Self> {
        let layers = match (&a.film_ior, a.thickness, a.layer.is_empty()) {
            (Some(ior), Some(d), true) => {
                check_thickness(d, "--thickness")?;
                vec![LayerSpec {
                    ior: ior.clone(),
                    thickness_nm: d,
                    coherence: Coherence::Coherent,
                }]
            }
            (Some(_), None, _) => bail!("--film-ior needs --thickness NM"),
            (None, _, false) => a
                .layer
                .iter()
                .map(|s| parse_layer(s))
                .collect::<Result<_>>()?,
            _ => bail!("give a film (--film-ior X --thickness NM) or one or more --layer IOR:NM"),
        };
        if !(a.substrate_k.is_finite() && a.substrate_k >= 0.0) {
            bail!(
                "--substrate-k must be finite and ≥ 0, got {}",
                a.substrate_k
            );
        }
        if a.substrate_k > 0.0
            && (a.substrate_ior.is_dispersive() || a.substrate_ior.at(550.0).im > 0.0)
        {
            bail!(
                "--substrate-k applies to a real --substrate-ior; '{}' already has its own k",
                a.substrate_ior
            );
        }
        // Light arrives through the ambient, so it must be lossless (k = 0) over the
        // visible range in which colours are computed.
        if (360..=830).any(|l| a.ambient_ior.at(l as f64).im != 0.0) {
            bail!("--ambient-ior '{}' must be lossless (k = 0)", a.ambient_ior);
        }
        Ok(System {
            ambient: a.ambient_ior.clone(),
            layers,
            substrate: a.substrate_ior.clone(),
            substrate_k: a.substrate_k,
        })
    }

    /// The stack at one wavelength.
    pub fn at(&self, lambda_nm: f64) -> Stack {
        Stack {
            ambient_ior: self.ambient.at(lambda_nm).re,
            layers: self
                .layers
                .iter()
                .map(|l| Layer {
                    ior: l.ior.at(lambda_nm),
                    thickness_nm: l.thickness_nm,
                    coherence: l.coherence,
                })
                .collect(),
            substrate_ior: self.substrate.at(lambda_nm) + Complex64::new(0.0, self.substrate_k),
        }
    }

    /// Checked response.
    pub fn response(&self, lambda_nm: f64, incident_deg: f64) -> Result<FilmResponse> {
        self.at(lambda_nm)
            .response_at_angle(lambda_nm, incident_deg)
            .with_context(|| format!("at λ = {lambda_nm} nm, θ = {incident_deg}°"))
    }
}

/// One spectrum at one angle.
pub struct Spectrum {
    pub angle_deg: f64,
    pub wavelength_nm: Vec<f64>,
    pub response: Vec<FilmResponse>,
}

pub fn compute(system: &System, wavelengths: &[f64], angle_deg: f64) -> Result<Spectrum> {
    let response = wavelengths
        .iter()
        .map(|&l| system.response(l, angle_deg))
        .collect::<Result<Vec<_>>>()?;
    Ok(Spectrum {
        angle_deg,
        wavelength_nm: wavelengths.to_vec(),
        response,
    })
}

/// Colour of the unpolarised reflectance under D65 (360–830 nm at 1 nm, CIE 1931 2°,
/// Y = 1 for a perfect reflector): (XYZ, linear sRGB, CIELAB).
pub fn colour(system: &System, angle_deg: f64) -> Result<([f64; 3], [f64; 3], [f64; 3])> {
    let lo = spectrum::LAMBDA_MIN_NM as usize;
    let hi = spectrum::LAMBDA_MAX_NM as usize;
    let mut r = Vec::with_capacity(hi - lo + 1);
    for l in lo..=hi {
        r.push(system.response(l as f64, angle_deg)?.r());
    }
    let xyz = spectrum::reflectance_xyz_d65(|l| {
        let i = (l.round() as usize).clamp(lo, hi) - lo;
        r[i]
    });
    let rgb = spectrum::xyz_to_linear_srgb(xyz);
    let lab = spectrum::xyz_to_lab(xyz, spectrum::D65_WHITE_XYZ);
    Ok((xyz, rgb, lab))
}

fn csv(spectra: &[Spectrum]) -> String {
    let multi = spectra.len() > 1;
    let mut s = String::from(if multi {
        "angle_deg,wavelength_nm,R_s,R_p,R\n"
    } else {
        "wavelength_nm,R_s,R_p,R\n"
    });
    for sp in spectra {
        for (l, r) in sp.wavelength_nm.iter().zip(&sp.response) {
            if multi {
                s += &format!("{},", sp.angle_deg);
            }
            s += &format!("{l},{},{},{}\n", r.r_s, r.r_p, r.r());
        }
    }
    s
}

fn json_one(system: &System, sp: &Spectrum) -> Result<serde_json::Value> {
    let col = |f: fn(&FilmResponse) -> f64| sp.response.iter().map(f).collect::<Vec<f64>>();
    let (xyz, rgb, lab) = colour(system, sp.angle_deg)?;
    Ok(serde_json::json!({
        "angle_deg": sp.angle_deg,
        "wavelength_nm": sp.wavelength_nm,
        "R_s": col(|r| r.r_s),
        "R_p": col(|r| r.r_p),
        "R": col(|r| r.r()),
        "T_s": col(|r| r.t_s),
        "T_p": col(|r| r.t_p),
        "T": col(|r| r.t()),
        "xyz": xyz,
        "srgb_linear": rgb,
        "lab": lab,
    }))
}

pub fn run(args: Args) -> Result<()> {
    let system = System::from_args(&args)?;
    let wavelengths = parse_wavelengths(&args.wavelengths)?;
    if args.angle.is_empty() {
        bail!("--angle: give at least one angle");
    }
    for &a in &args.angle {
        if !(a.is_finite() && (0.0..90.0).contains(&a)) {
            bail!("--angle {a}: the incident angle must be in [0°, 90°)");
        }
    }
    let spectra = args
        .angle
        .iter()
        .map(|&a| compute(&system, &wavelengths, a))
        .collect::<Result<Vec<_>>>()?;
    // Build the whole output before writing anything.
    let text = match args.format {
        Format::Csv => csv(&spectra),
        Format::Json => {
            let mut all = spectra
                .iter()
                .map(|sp| json_one(&system, sp))
                .collect::<Result<Vec<_>>>()?;
            let v = if all.len() == 1 {
                all.remove(0)
            } else {
                serde_json::Value::Array(all)
            };
            serde_json::to_string_pretty(&v)? + "\n"
        }
    };
    if let Some(path) = &args.plot {
        let title = describe(&system);
        plot(path, &spectra, &title)?;
    }
    use std::io::Write;
    std::io::stdout()
        .write_all(text.as_bytes())
        .context("writing to stdout")?;
    Ok(())
}

/// Short description for the plot title, e.g. `n = 1.37, d = 400 nm on n = 1.64`.
fn describe(s: &System) -> String {
    let layers: Vec<String> = s
        .layers
        .iter()
        .map(|l| format!("n = {}, d = {} nm", l.ior, l.thickness_nm))
        .collect();
    let sub = if s.substrate_k > 0.0 {
        format!("{}+{}i", s.substrate, s.substrate_k)
    } else {
        s.substrate.to_string()
    };
    format!("film {}  on substrate n = {}", layers.join(" | "), sub)
}

/// Draws R(λ) (unpolarised) for each angle in the style of a paper figure.
pub fn plot(path: &std::path::Path, spectra: &[Spectrum], title: &str) -> Result<()> {
    use plotters::prelude::*;
    use plotters::style::{register_font, FontStyle};
    static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
    register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow::anyhow!("the bundled DejaVuSans.ttf failed to load"))?;
    let (w, h) = (1000u32, 640u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let (lmin, lmax) = spectra
        .iter()
        .flat_map(|s| s.wavelength_nm.iter())
        .fold((f64::MAX, f64::MIN), |(a, b), &l| (a.min(l), b.max(l)));
    let (lmin, lmax) = if lmax > lmin {
        (lmin, lmax)
    } else {
        (lmin - 1.0, lmax + 1.0)
    };
    let rmax = spectra
        .iter()
        .flat_map(|s| s.response.iter().map(|r| r.r()))
        .fold(0.0f64, f64::max);
    // Round the R axis up to a tidy value so curves do not touch the frame.
    let top = [
        0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0,
    ]
    .into_iter()
    .find(|&t| t >= rmax * 1.08)
    .unwrap_or(1.0);
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| anyhow::anyhow!("plot: {e:?}");
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(60)
            .y_label_area_size(80)
            .build_cartesian_2d(lmin..lmax, 0.0..top)
            .map_err(|e| anyhow::anyhow!("plot: {e:?}"))?;
        chart
            .configure_mesh()
            .x_desc("wavelength λ (nm)")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.2}"))
            .y_desc("R")
            .axis_desc_style(("sans-serif", 24))
            .label_style(("sans-serif", 18))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(210, 210, 210))
            .draw()
            .map_err(|e| anyhow::anyhow!("plot: {e:?}"))?;
        let colours = [
            RGBColor(0, 90, 181),
            RGBColor(220, 50, 32),
            RGBColor(26, 133, 60),
            RGBColor(150, 60, 170),
            RGBColor(230, 140, 0),
            RGBColor(0, 0, 0),
        ];
        for (i, sp) in spectra.iter().enumerate() {
            let c = colours[i % colours.len()];
            let pts: Vec<(f64, f64)> = sp
                .wavelength_nm
                .iter()
                .zip(&sp.response)
                .map(|(&l, r)| (l, r.r()))
                .collect();
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(3)))
                .map_err(|e| anyhow::anyhow!("plot: {e:?}"))?
                .label(format!("θ = {}°", sp.angle_deg))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 30, y)], c.stroke_width(3))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 20))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(|e| anyhow::anyhow!("plot: {e:?}"))?;
        root.present().map_err(|e| anyhow::anyhow!("plot: {e:?}"))?;
    }
    write_png_rgb8(path, w as usize, h as usize, buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wavelength_specs() {
        assert_eq!(
            parse_wavelengths("400:700:100").unwrap(),
            vec![400.0, 500.0, 600.0, 700.0]
        );
        assert_eq!(
            parse_wavelengths("400,512.5,700").unwrap(),
            vec![400.0, 512.5, 700.0]
        );
        assert_eq!(
            parse_wavelengths("400:410:3").unwrap(),
            vec![400.0, 403.0, 406.0, 409.0]
        );
        for bad in [
            "0:700:5",
            "400:300:5",
            "400:700",
            "-1,500",
            "400,x",
            "400:700:0",
            "",
        ] {
            assert!(parse_wavelengths(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn layer_specs() {
        let l = parse_layer("MgF2:100").unwrap();
        assert_eq!(l.thickness_nm, 100.0);
        assert_eq!(
            parse_layer("1.5+0.1i:5:i").unwrap().coherence,
            Coherence::Incoherent
        );
        for bad in ["1.5", "1.5:-3", "x:3", "1.5:3:q", "1.5:nan"] {
            assert!(parse_layer(bad).is_err(), "{bad}");
        }
    }
}
