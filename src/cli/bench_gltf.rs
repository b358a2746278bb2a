//! `thinfilm bench gltf-iridescence`: how far glTF's `KHR_materials_iridescence` Fresnel term
//! (Schlick interfaces + a Fourier fit of the XYZ sensitivities, as glTF viewers draw it;
//! [`thinfilm::optics::gltf_iridescence`]) is from the exact spectral result (the Airy sum
//! with s and p, integrated at 1 nm under D65) over film thickness 0–1200 nm, film index
//! 1.2–2.4 and incidence 0–85°, on a dielectric (n = 1.5) and on a metal (gold, whose glTF
//! base colour is its own normal-incidence reflectance). Colour difference is CIEDE2000 in
//! CIELAB under D65, white = a perfect reflector.

use anyhow::{Context, Result};
use rayon::prelude::*;
use std::io::Write;
use std::path::PathBuf;
use thinfilm::compare::figure::{
    colour_bar, compose_panels, heatmap, nice_ceiling, Canvas, Colormap, Panel,
};
use thinfilm::optics::gltf_iridescence::{f_iridescence, OpdCosine};
use thinfilm::optics::{Complex64, Ior, ThinFilm};
use thinfilm::spectrum::color::{
    delta_e2000, linear_srgb_to_xyz, srgb_encode, xyz_to_lab, xyz_to_linear_srgb,
};
use thinfilm::spectrum::reflectance_xyz_d65;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Folder for the table (CSV of every grid point) and the figure.
    #[arg(long, default_value = "bench-gltf-iridescence")]
    pub out_dir: PathBuf,
    /// Thickness step of the statistics grid (nm; the grid runs 0–1200 nm).
    #[arg(long, default_value_t = 10.0)]
    pub thickness_step_nm: f64,
    /// Angle step of the statistics grid (degrees; the grid runs 0–85°).
    #[arg(long, default_value_t = 5.0)]
    pub angle_step_deg: f64,
}

const FILM_IORS: [f64; 6] = [1.2, 1.33, 1.5, 1.8, 2.0, 2.4];
const MAX_THICKNESS_NM: f64 = 1200.0;
const MAX_ANGLE_DEG: f64 = 85.0;

/// What the film sits on.
struct Base {
    name: &'static str,
    ior: Ior,
    /// glTF's description of the same base: normal-incidence reflectance per Rec.709 channel.
    f0_rgb: [f64; 3],
}

fn bases() -> Result<Vec<Base>> {
    let dielectric = Ior::real(1.5);
    let gold: Ior = "Au".parse().map_err(|e: String| anyhow::anyhow!(e))?;
    Ok([("dielectric n=1.5", dielectric), ("gold (Au)", gold)]
        .into_iter()
        .map(|(name, ior)| {
            let f0_xyz = reflectance_xyz_d65(|l| {
                let n = ior.at(l);
                ((n - 1.0) / (n + 1.0)).norm_sqr()
            });
            let f0_rgb = xyz_to_linear_srgb(f0_xyz).map(|v| v.clamp(0.0, 1.0));
            Base { name, ior, f0_rgb }
        })
        .collect())
}

/// Colour of the exact unpolarised film reflectance under D65.
fn exact_xyz(base: &Base, film_ior: f64, thickness_nm: f64, angle_deg: f64) -> [f64; 3] {
    let cos = angle_deg.to_radians().cos();
    reflectance_xyz_d65(|l| {
        ThinFilm {
            ambient_ior: 1.0,
            film_ior: Complex64::new(film_ior, 0.0),
            thickness_nm,
            substrate_ior: base.ior.at(l),
        }
        .response(l, cos)
        .r()
    })
}

fn gltf_xyz(
    base: &Base,
    film_ior: f64,
    thickness_nm: f64,
    angle_deg: f64,
    o: OpdCosine,
) -> [f64; 3] {
    let cos = angle_deg.to_radians().cos();
    linear_srgb_to_xyz(f_iridescence(
        1.0,
        film_ior,
        cos,
        thickness_nm,
        base.f0_rgb,
        o,
    ))
}

/// ΔE00 between two reflectance colours (XYZ with a perfect reflector at Y = 1).
fn delta_e(a: [f64; 3], b: [f64; 3]) -> f64 {
    let white = linear_srgb_to_xyz([1.0; 3]);
    delta_e2000(xyz_to_lab(a, white), xyz_to_lab(b, white))
}

struct Point {
    base: usize,
    film_ior: f64,
    thickness_nm: f64,
    angle_deg: f64,
    /// ΔE00 of the Sample Viewer's reading (cos θ2), then of the extension text's (cos θ1).
    delta_e: [f64; 2],
}

fn grid(bases: &[Base], d_step: f64, a_step: f64) -> Vec<Point> {
    let nd = (MAX_THICKNESS_NM / d_step).round() as usize;
    let na = (MAX_ANGLE_DEG / a_step).round() as usize;
    let mut keys = Vec::new();
    for b in 0..bases.len() {
        for &n in &FILM_IORS {
            for i in 0..=nd {
                for j in 0..=na {
                    keys.push((b, n, i as f64 * d_step, j as f64 * a_step));
                }
            }
        }
    }
    keys.into_par_iter()
        .map(|(b, n, d, a)| {
            let exact = exact_xyz(&bases[b], n, d, a);
            let de = [OpdCosine::InsideFilm, OpdCosine::Incident]
                .map(|o| delta_e(exact, gltf_xyz(&bases[b], n, d, a, o)));
            Point {
                base: b,
                film_ior: n,
                thickness_nm: d,
                angle_deg: a,
                delta_e: de,
            }
        })
        .collect()
}

/// Mean, 95th percentile and maximum.
fn stats(mut v: Vec<f64>) -> [f64; 3] {
    if v.is_empty() {
        return [f64::NAN; 3];
    }
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let p95 = v[((v.len() - 1) as f64 * 0.95).round() as usize];
    [mean, p95, v[v.len() - 1]]
}

fn print_table(bases: &[Base], points: &[Point]) {
    println!("ΔE00 (CIEDE2000) of glTF's iridescence Fresnel term against the exact spectral film");
    println!("(thickness 0–1200 nm, incidence 0–85°, film index 1.2–2.4; mean / 95th pct / max)\n");
    println!("| base | region | glTF viewers (cos θ2) | extension text (cos θ1) |");
    println!("|---|---|---|---|");
    type Filter = Box<dyn Fn(&Point) -> bool>;
    let regions: Vec<(&str, Filter)> = vec![
        ("all", Box::new(|_| true)),
        ("0–30°", Box::new(|p| p.angle_deg <= 30.0)),
        (
            "35–60°",
            Box::new(|p| p.angle_deg > 30.0 && p.angle_deg <= 60.0),
        ),
        ("65–85°", Box::new(|p| p.angle_deg > 60.0)),
        ("d < 100 nm", Box::new(|p| p.thickness_nm < 100.0)),
        (
            "100–400 nm",
            Box::new(|p| (100.0..=400.0).contains(&p.thickness_nm)),
        ),
        (
            "410–800 nm",
            Box::new(|p| p.thickness_nm > 400.0 && p.thickness_nm <= 800.0),
        ),
        ("810–1200 nm", Box::new(|p| p.thickness_nm > 800.0)),
        ("film n ≤ 1.5", Box::new(|p| p.film_ior <= 1.5)),
        ("film n ≥ 1.8", Box::new(|p| p.film_ior >= 1.8)),
    ];
    for (bi, b) in bases.iter().enumerate() {
        for (name, keep) in &regions {
            let sel: Vec<&Point> = points.iter().filter(|p| p.base == bi && keep(p)).collect();
            let col = |k: usize| {
                let [m, p, x] = stats(sel.iter().map(|p| p.delta_e[k]).collect());
                format!("{m:.2} / {p:.2} / {x:.1}")
            };
            println!("| {} | {name} | {} | {} |", b.name, col(0), col(1));
        }
    }
}

fn write_csv(path: &std::path::Path, bases: &[Base], points: &[Point]) -> Result<()> {
    let mut s =
        String::from("base,film_ior,thickness_nm,incident_deg,delta_e00_viewer,delta_e00_text\n");
    for p in points {
        s += &format!(
            "{},{},{},{},{:.4},{:.4}\n",
            bases[p.base].name, p.film_ior, p.thickness_nm, p.angle_deg, p.delta_e[0], p.delta_e[1]
        );
    }
    thinfilm::image_io::write_atomically(path, |tmp| {
        std::fs::File::create(tmp)?.write_all(s.as_bytes())?;
        Ok(())
    })
    .with_context(|| format!("writing {}", path.display()))
}

/// sRGB display colour of a linear reflectance colour, scaled by `gain`.
fn display(xyz: [f64; 3], gain: f64) -> [u8; 3] {
    xyz_to_linear_srgb(xyz).map(|v| (srgb_encode((v * gain).clamp(0.0, 1.0)) * 255.0 + 0.5) as u8)
}

/// One figure row: exact colours | glTF colours | ΔE00, over thickness (x, 5 nm/px) and
/// incidence (y, 1°/px, 0° at the top), each pixel doubled.
fn figure_row(base: &Base, film_ior: f64, de_max: f64) -> Result<(Vec<Panel>, f64)> {
    let (w, h) = (241usize, 86usize);
    let cells: Vec<(usize, usize)> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).collect();
    let xyz: Vec<([f64; 3], [f64; 3])> = cells
        .par_iter()
        .map(|&(x, y)| {
            let (d, a) = (x as f64 * 5.0, y as f64);
            (
                exact_xyz(base, film_ior, d, a),
                gltf_xyz(base, film_ior, d, a, OpdCosine::InsideFilm),
            )
        })
        .collect();
    // Same display gain for both: the exact image's 95th-percentile luminance at 0.7.
    let mut ys: Vec<f64> = xyz.iter().map(|(e, _)| e[1]).collect();
    ys.sort_by(f64::total_cmp);
    let gain = 0.7 / ys[(ys.len() as f64 * 0.95) as usize].max(1e-6);
    let paint = |f: &dyn Fn(&([f64; 3], [f64; 3])) -> [u8; 3]| {
        let mut c = Canvas::new(w, h, [255; 3]);
        for (&(x, y), v) in cells.iter().zip(&xyz) {
            c.set(x, y, f(v));
        }
        c.upscale(2)
    };
    let de: Vec<f64> = xyz.iter().map(|(e, g)| delta_e(*e, *g)).collect();
    let mean = de.iter().sum::<f64>() / de.len() as f64;
    let label = format!("{}, film n = {film_ior}", base.name);
    Ok((
        vec![
            Panel {
                image: paint(&|(e, _)| display(*e, gain)),
                title: format!("exact: {label}"),
                caption: vec![],
            },
            Panel {
                image: paint(&|(_, g)| display(*g, gain)),
                title: "glTF viewers".into(),
                caption: vec![],
            },
            Panel {
                image: heatmap(&de, w, h, de_max, Colormap::Viridis)?.upscale(2),
                title: format!("ΔE00 (mean {mean:.1})"),
                caption: vec![],
            },
        ],
        mean,
    ))
}

fn write_figure(path: &std::path::Path, bases: &[Base]) -> Result<()> {
    let font = 15.0;
    let de_max = 40.0;
    let bar = colour_bar(172, nice_ceiling(de_max), Colormap::Viridis, "ΔE00", font);
    let mut rows = Vec::new();
    for base in bases {
        for n in [1.33, 1.8] {
            let (panels, _) = figure_row(base, n, nice_ceiling(de_max))?;
            rows.push(compose_panels(&panels, Some(&bar), font));
        }
    }
    let caption = "x: film thickness 0–1200 nm; y: incidence 0° (top) – 85° (bottom)";
    let lh = thinfilm::compare::figure::line_height(font).ceil() as usize + 8;
    let width = rows.iter().map(|r| r.width).max().unwrap_or(0);
    let height = rows.iter().map(|r| r.height).sum::<usize>() + lh;
    let mut c = Canvas::new(width, height, [255; 3]);
    c.draw_text(caption, 10.0, 4.0, font, [0; 3]);
    let mut y = lh;
    for r in &rows {
        c.blit(r, 0, y);
        y += r.height;
    }
    thinfilm::image_io::write_atomically(path, |tmp| c.save_png(tmp))
        .with_context(|| format!("writing {}", path.display()))
}

pub fn run(args: Args) -> Result<()> {
    for (name, v, max) in [
        (
            "--thickness-step-nm",
            args.thickness_step_nm,
            MAX_THICKNESS_NM,
        ),
        ("--angle-step-deg", args.angle_step_deg, MAX_ANGLE_DEG),
    ] {
        if !(v.is_finite() && v > 0.0 && v <= max) {
            anyhow::bail!("{name} must be in (0, {max}], got {v}");
        }
    }
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;
    let bases = bases()?;
    let t0 = std::time::Instant::now();
    let points = grid(&bases, args.thickness_step_nm, args.angle_step_deg);
    print_table(&bases, &points);
    let csv = args.out_dir.join("gltf_iridescence.csv");
    write_csv(&csv, &bases, &points)?;
    let png = args.out_dir.join("gltf_iridescence.png");
    write_figure(&png, &bases)?;
    println!(
        "\n{} grid points in {:.1} s; wrote {} and {}",
        points.len(),
        t0.elapsed().as_secs_f64(),
        csv.display(),
        png.display()
    );
    Ok(())
}
