//! Teapot figures from fitted materials (seed Figs. 5 and 6): the same scene, camera, spp
//! and seed rendered once with the ground-truth material and once with the fitted one,
//! composed with a ΔE00 heat map, the fitted thickness map and its error map.
//!
//! The thickness maps are textured onto the teapot through its patch UVs, so the spatial
//! variation the capture showed appears on the rendered surface (a fitted map on a plane is
//! `scenes/plane_thickness_map.xml`).

use crate::capture;
use crate::compare::figure::{
    colour_bar, compose_panels, heatmap, nice_ceiling, Canvas, Colormap, Panel,
};
use crate::compare::metrics::{compare_images, delta_e00_map};
use crate::image_io::{self, RgbImage};
use crate::material::FilmMaterial;
use crate::render::bsdf::Bsdf;
use crate::render::{self, RenderOptions};
use crate::scene::{
    self, look_at, sky, teapot, Camera, EmitterDesc, FilmSettings, FovAxis, Geometry,
    IntegratorSettings, ReconstructionFilter, Scene, Shape,
};
use anyhow::{bail, Context, Result};
use glam::{Mat4, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Image size and sampling of the teapot renders.
#[derive(Debug, Clone, Copy)]
pub struct RenderSettings {
    pub resolution: u32,
    pub spp: u32,
    pub seed: u64,
    pub max_depth: i32,
    pub progress: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            resolution: 256,
            spp: 64,
            seed: 0,
            max_depth: 8,
            progress: true,
        }
    }
}

/// The teapot scene of `scenes/teapot_*.xml` built in memory (tessellated Newell teapot,
/// procedural studio environment), so the figures need no files beside the binary.
pub fn teapot_scene(settings: &RenderSettings) -> Scene {
    let (w, h) = sky::STUDIO_SIZE;
    Scene {
        camera: Camera {
            to_world: look_at(Vec3::new(4.0, 5.5, 10.0), Vec3::new(0.2, 1.3, 0.0), Vec3::Y),
            fov_deg: 32.0,
            projection: crate::scene::Projection::Perspective,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 1000.0,
        },
        film: FilmSettings {
            width: settings.resolution,
            height: settings.resolution,
            filter: ReconstructionFilter::Box,
        },
        integrator: IntegratorSettings {
            max_depth: settings.max_depth,
            ..IntegratorSettings::default()
        },
        spp: settings.spp,
        seed: settings.seed,
        sampler: crate::scene::SamplerKind::Sobol,
        shapes: vec![Shape {
            geometry: Geometry::Mesh(teapot::teapot_mesh(teapot::DEFAULT_SUBDIVISIONS).into()),
            bsdf: 0,
            emission: None,
            name: Some("teapot".into()),
        }],
        bsdfs: vec![Bsdf::default_diffuse()],
        emitters: vec![EmitterDesc::Envmap {
            image: Arc::new(sky::studio_environment(w, h)),
            scale: 1.0,
            to_world: Mat4::IDENTITY,
            path: None,
        }],
        polarizer: None,
        source: None,
        media: None,
    }
}

/// Renders `base` with every shape's BSDF replaced by `material`.
pub fn render_with_material(
    base: &Scene,
    material: &FilmMaterial,
    settings: &RenderSettings,
) -> Result<RgbImage> {
    let mut scene = base.clone();
    scene.bsdfs = vec![material.bsdf()?];
    for shape in &mut scene.shapes {
        shape.bsdf = 0;
    }
    let options = RenderOptions {
        spp: Some(settings.spp),
        seed: Some(settings.seed),
        max_depth: Some(settings.max_depth),
        resolution: Some((settings.resolution, settings.resolution)),
        progress: settings.progress,
        ..RenderOptions::default()
    };
    Ok(render::render(&scene, &options)?.image)
}

/// The base scene: a scene file if given, else the built-in teapot.
pub fn base_scene(scene_path: Option<&Path>, settings: &RenderSettings) -> Result<Scene> {
    match scene_path {
        Some(p) => scene::load(p, &[]),
        None => Ok(teapot_scene(settings)),
    }
}

/// Files written by [`fit_figure`].
#[derive(Debug, Clone)]
pub struct FigureOutput {
    pub png: PathBuf,
    pub exrs: Vec<PathBuf>,
    /// Mean ΔE00 between the two renders (or capture vs model colours).
    pub delta_e00_mean: f64,
}

const FONT_PX: f32 = 16.0;

fn panel(image: &RgbImage, title: String, caption: Vec<String>) -> Panel {
    Panel {
        image: Canvas::from_linear(image, 1.0),
        title,
        caption,
    }
}

/// A heat map panel of a per-pixel scalar with its own colour bar on the right.
fn scalar_map(
    values: &[f64],
    width: usize,
    height: usize,
    target_px: usize,
    title: &str,
    unit: &str,
    vmin: f64,
) -> Result<Canvas> {
    let shifted: Vec<f64> = values.iter().map(|v| v - vmin).collect();
    let max = shifted
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let vmax = nice_ceiling(max.max(1e-6));
    let scale = target_px.div_ceil(width.max(1)).max(1);
    let heat = heatmap(&shifted, width, height, vmax, Colormap::Viridis)?.upscale(scale);
    let bar_title = if vmin != 0.0 {
        format!("{unit} − {vmin:.0}")
    } else {
        unit.to_string()
    };
    let bar = colour_bar(
        heat.height,
        vmax,
        Colormap::Viridis,
        &bar_title,
        FONT_PX * 0.85,
    );
    Ok(compose_panels(
        &[Panel {
            image: heat,
            title: title.to_string(),
            caption: vec![],
        }],
        Some(&bar),
        FONT_PX,
    ))
}

/// Stacks canvases top to bottom on white, left-aligned.
pub fn stack_rows(rows: &[Canvas]) -> Canvas {
    let width = rows.iter().map(|r| r.width).max().unwrap_or(1);
    let height = rows.iter().map(|r| r.height).sum::<usize>().max(1);
    let mut out = Canvas::new(width, height, [255, 255, 255]);
    let mut y = 0;
    for r in rows {
        out.blit(r, 0, y);
        y += r.height;
    }
    out
}

/// Places canvases side by side on white, top-aligned.
pub fn place_side_by_side(items: &[Canvas], gap: usize) -> Canvas {
    let width = items.iter().map(|c| c.width).sum::<usize>() + gap * items.len().saturating_sub(1);
    let height = items.iter().map(|c| c.height).max().unwrap_or(1);
    let mut out = Canvas::new(width.max(1), height, [255, 255, 255]);
    let mut x = 0;
    for c in items {
        out.blit(c, x, 0);
        x += c.width + gap;
    }
    out
}

/// Ground truth | fitted | ΔE00 row, returning the row canvas and the mean ΔE00.
fn comparison_row(
    gt: &RgbImage,
    gt_title: String,
    fit: &RgbImage,
    fit_title: String,
) -> Result<(Canvas, f64, Vec<f64>)> {
    let metrics = compare_images(fit, gt)?;
    let de = delta_e00_map(fit, gt)?;
    let vmax = nice_ceiling(metrics.delta_e00_p95.max(1.0));
    let heat = heatmap(&de, gt.width, gt.height, vmax, Colormap::Viridis)?;
    let bar = colour_bar(gt.height, vmax, Colormap::Viridis, "ΔE00", FONT_PX * 0.85);
    let panels = [
        panel(gt, gt_title, vec![]),
        panel(fit, fit_title, vec![format!("RMSE {:.4}", metrics.rmse)]),
        Panel {
            image: heat,
            title: format!("ΔE00 (mean {:.2})", metrics.delta_e00_mean),
            caption: vec![format!("95th pct {:.2}", metrics.delta_e00_p95)],
        },
    ];
    Ok((
        compose_panels(&panels, Some(&bar), FONT_PX),
        metrics.delta_e00_mean,
        de,
    ))
}

/// The fitted map (from `fit_dir`) and the data in `dir` it is drawn against must be one size.
fn same_size(
    fitted: &FilmMaterial,
    fit_dir: &Path,
    (w, h): (usize, usize),
    dir: &Path,
) -> Result<()> {
    if (w, h) != (fitted.width, fitted.height) {
        bail!(
            "{} is {w}×{h} px but the fit in {} is {}×{} px",
            dir.display(),
            fit_dir.display(),
            fitted.width,
            fitted.height
        );
    }
    Ok(())
}

/// `thinfilm figure FIT_DIR --ground-truth DIR`: ground truth | fitted | ΔE00 teapots, then
/// the fitted thickness map and its error map (seed Fig. 5), with EXRs of each panel.
pub fn fit_figure(
    fit_dir: &Path,
    ground_truth: &Path,
    scene_path: Option<&Path>,
    settings: &RenderSettings,
    out_png: &Path,
) -> Result<FigureOutput> {
    let fitted = FilmMaterial::from_fit_dir(fit_dir)?;
    let gt = capture::load_ground_truth(ground_truth)?;
    same_size(&fitted, fit_dir, (gt.width, gt.height), ground_truth)?;
    let truth = FilmMaterial::from_ground_truth(&gt);
    let base = base_scene(scene_path, settings)?;
    let gt_img = render_with_material(&base, &truth, settings)?;
    let fit_img = render_with_material(&base, &fitted, settings)?;
    let (row1, de_mean, _) = comparison_row(
        &gt_img,
        format!("ground truth: {}", truth.label()),
        &fit_img,
        format!("fitted: {}", fitted.label()),
    )?;

    let (w, h) = (fitted.width, fitted.height);
    let thick: Vec<f64> = fitted.thickness_nm.iter().map(|&v| v as f64).collect();
    let err: Vec<f64> = fitted
        .thickness_nm
        .iter()
        .zip(&truth.thickness_nm)
        .map(|(&f, &t)| (f as f64 - t as f64).abs())
        .collect();
    let finite_err: Vec<f64> = err.iter().copied().filter(|v| v.is_finite()).collect();
    let mae = finite_err.iter().sum::<f64>() / finite_err.len().max(1) as f64;
    let tmin = thick
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::INFINITY, f64::min);
    let vmin = if tmin.is_finite() {
        (tmin / 10.0).floor() * 10.0
    } else {
        0.0
    };
    let target = settings.resolution as usize;
    let row2 = place_side_by_side(
        &[
            scalar_map(&thick, w, h, target, "fitted thickness (nm)", "nm", vmin)?,
            scalar_map(
                &err,
                w,
                h,
                target,
                &format!("|d true − d fitted| (MAE {mae:.2} nm)"),
                "nm",
                0.0,
            )?,
        ],
        12,
    );
    let figure = stack_rows(&[row1, row2]);
    save_figure(
        &figure,
        out_png,
        [("ground_truth", &gt_img), ("fitted", &fit_img)],
        de_mean,
    )
}

/// Linear sRGB colour (D65) of each pixel's reflectance spectrum at angle `angle_index`,
/// from a measured capture or from the fitted model.
fn capture_colour_image(
    set: &capture::CaptureSet,
    angle_index: usize,
    spectrum_of: impl Fn(usize) -> Option<Vec<f64>>,
) -> RgbImage {
    let mut img = RgbImage::new(set.width, set.height);
    let _ = angle_index;
    for (p, px) in img.pixels.iter_mut().enumerate() {
        *px = match spectrum_of(p) {
            Some(values) => {
                let xyz =
                    crate::spectrum::tabulated_reflectance_xyz_d65(&set.wavelengths_nm, &values);
                let rgb = crate::spectrum::xyz_to_linear_srgb(xyz);
                [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32]
            }
            None => [f32::NAN; 3],
        };
    }
    img
}

/// Without ground truth: the capture's colour at one angle (from the measured spectra) beside
/// the fitted model's colour at the same angle, and their ΔE00.
pub fn capture_figure(
    fit_dir: &Path,
    capture_dir: &Path,
    angle_index: usize,
    out_png: &Path,
) -> Result<FigureOutput> {
    let fitted = FilmMaterial::from_fit_dir(fit_dir)?;
    let set = capture::load_capture_set(capture_dir)?;
    same_size(&fitted, fit_dir, (set.width, set.height), capture_dir)?;
    let angle = set.angles.get(angle_index).with_context(|| {
        format!(
            "angle index {angle_index} out of range: the capture has {} angles",
            set.angles.len()
        )
    })?;
    let bands = set.bands();
    let measured = capture_colour_image(&set, angle_index, |p| {
        angle.valid[p].then(|| {
            let mut y = vec![0f32; bands];
            angle.reflectance.pixel(p, &mut y);
            y.iter().map(|&v| v as f64).collect()
        })
    });
    let cos1 = angle.incident_deg.to_radians().cos();
    let film_ior = fitted.film_ior.clone();
    let model = capture_colour_image(&set, angle_index, |p| {
        let d = fitted.thickness_nm[p];
        if !d.is_finite() {
            return None;
        }
        Some(
            set.wavelengths_nm
                .iter()
                .map(|&l| {
                    let film = crate::optics::ThinFilm {
                        ambient_ior: set.ambient_ior,
                        film_ior: film_ior.at(l),
                        thickness_nm: d as f64,
                        substrate_ior: set.substrate_ior.at(l),
                    };
                    let r = film.response(l, cos1);
                    match set.polarization {
                        capture::Polarization::S => r.r_s,
                        capture::Polarization::P => r.r_p,
                        capture::Polarization::Unpolarized => r.r(),
                    }
                })
                .collect(),
        )
    });
    // Invalid pixels are NaN in both; show them black rather than propagate NaN into metrics.
    let clean = |img: &RgbImage| RgbImage {
        pixels: img
            .pixels
            .iter()
            .map(|p| if p[0].is_finite() { *p } else { [0.0; 3] })
            .collect(),
        ..img.clone()
    };
    let (measured, model) = (clean(&measured), clean(&model));
    // Reflectance colours are dim; expose so the brightest pixel is near white.
    let peak = measured
        .pixels
        .iter()
        .flat_map(|p| p.iter())
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-3);
    let exposed = |img: &RgbImage| RgbImage {
        pixels: img.pixels.iter().map(|p| p.map(|v| v / peak)).collect(),
        ..img.clone()
    };
    let (row, de_mean, _) = comparison_row(
        &exposed(&measured),
        format!("captured at {:.0}°", angle.incident_deg),
        &exposed(&model),
        format!("fitted model: {}", fitted.label()),
    )?;
    let row = upscale_small(row, 2);
    save_figure(
        &row,
        out_png,
        [("captured", &measured), ("fitted", &model)],
        de_mean,
    )
}

/// Saves `figure` as `out_png` and each panel's image beside it as `STEM_NAME.exr`.
fn save_figure(
    figure: &Canvas,
    out_png: &Path,
    panels: [(&str, &RgbImage); 2],
    delta_e00_mean: f64,
) -> Result<FigureOutput> {
    figure.save_png(out_png)?;
    let stem = out_png.with_extension("");
    let mut exrs = Vec::new();
    for (name, img) in panels {
        let path = PathBuf::from(format!("{}_{name}.exr", stem.display()));
        image_io::write_exr_rgb(&path, img)?;
        exrs.push(path);
    }
    Ok(FigureOutput {
        png: out_png.to_path_buf(),
        exrs,
        delta_e00_mean,
    })
}

fn upscale_small(c: Canvas, factor: usize) -> Canvas {
    if c.width < 400 {
        c.upscale(factor)
    } else {
        c
    }
}

/// A file-name part from a label: lower-case letters and digits, runs of anything else as
/// one `_` ("Sample 1 (MgF2 400 nm)" → "sample_1_mgf2_400_nm").
pub fn slug(label: &str) -> String {
    let mut s = String::with_capacity(label.len());
    for c in label.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('_') {
            s.push('_');
        }
    }
    s.trim_matches('_').to_string()
}

/// Ground truth beside fits of the same capture by several methods, as teapots, with each
/// fit's ΔE00 map against the ground truth under it — all maps on one colour scale, so they
/// compare at a glance. Returns each fit's mean ΔE00.
pub fn methods_figure(
    title: &str,
    truth: &FilmMaterial,
    fits: &[(String, FilmMaterial)],
    settings: &RenderSettings,
    out_png: &Path,
) -> Result<Vec<f64>> {
    let base = base_scene(None, settings)?;
    let gt_img = render_with_material(&base, truth, settings)?;
    let mut images = Vec::new();
    let mut maps = Vec::new();
    let mut means = Vec::new();
    let mut p95 = 1.0f64;
    for (_, m) in fits {
        let img = render_with_material(&base, m, settings)?;
        let metrics = compare_images(&img, &gt_img)?;
        maps.push(delta_e00_map(&img, &gt_img)?);
        means.push(metrics.delta_e00_mean);
        p95 = p95.max(metrics.delta_e00_p95);
        images.push(img);
    }
    let vmax = nice_ceiling(p95);
    let (w, h) = (gt_img.width, gt_img.height);
    // One column per material: its teapot, and under a fit its ΔE00 map.
    let one = |p: Panel| compose_panels(&[p], None, FONT_PX);
    let mut columns = vec![one(panel(
        &gt_img,
        format!("ground truth: {}", truth.label()),
        vec![],
    ))];
    for (((label, m), img), (de, mean)) in fits.iter().zip(&images).zip(maps.iter().zip(&means)) {
        let map = Panel {
            image: heatmap(de, w, h, vmax, Colormap::Viridis)?,
            title: format!("ΔE00 against the truth: mean {mean:.2}"),
            caption: vec![],
        };
        columns.push(stack_rows(&[
            one(panel(img, format!("{label}: {}", m.label()), vec![])),
            one(map),
        ]));
    }
    let bar = colour_bar(h, vmax, Colormap::Viridis, "ΔE00", FONT_PX * 0.85);
    // Beside the maps: the bottom of the bar at the bottom of the columns.
    let tallest = columns.iter().map(|c| c.height).max().unwrap_or(0);
    let mut bar_column = Canvas::new(bar.width, tallest.max(bar.height), [255, 255, 255]);
    bar_column.blit(&bar, 0, tallest.saturating_sub(bar.height));
    columns.push(bar_column);
    let body = place_side_by_side(&columns, 16);
    let mut header = Canvas::new(body.width, (FONT_PX * 2.0) as usize, [255, 255, 255]);
    header.draw_text(title, 8.0, FONT_PX * 0.4, FONT_PX * 1.15, [0, 0, 0]);
    stack_rows(&[header, body]).save_png(out_png)?;
    Ok(means)
}

/// One row of the seed's Fig. 6: a sample's name, its true and fitted materials.
#[derive(Debug, Clone)]
pub struct SampleRow {
    pub name: String,
    pub truth: FilmMaterial,
    pub fitted: FilmMaterial,
}

/// The seed's Fig. 6 layout: real material (simulated ground truth) left, fitted right,
/// ΔE00 beside them, one row per sample. Returns each row's mean ΔE00.
pub fn samples_figure(
    rows: &[SampleRow],
    scene_path: Option<&Path>,
    settings: &RenderSettings,
    out_png: &Path,
) -> Result<Vec<f64>> {
    let base = base_scene(scene_path, settings)?;
    let mut canvases = Vec::new();
    let mut des = Vec::new();
    for row in rows {
        let gt_img = render_with_material(&base, &row.truth, settings)?;
        let fit_img = render_with_material(&base, &row.fitted, settings)?;
        let (canvas, de, _) = comparison_row(
            &gt_img,
            format!("{}: ground truth, {}", row.name, row.truth.label()),
            &fit_img,
            format!("fitted, {}", row.fitted.label()),
        )?;
        let stem = out_png.with_extension("");
        let slug = slug(&row.name);
        image_io::write_exr_rgb(
            Path::new(&format!("{}_{slug}_ground_truth.exr", stem.display())),
            &gt_img,
        )?;
        image_io::write_exr_rgb(
            Path::new(&format!("{}_{slug}_fitted.exr", stem.display())),
            &fit_img,
        )?;
        canvases.push(canvas);
        des.push(de);
    }
    stack_rows(&canvases).save_png(out_png)?;
    Ok(des)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material(d: f32) -> FilmMaterial {
        FilmMaterial {
            film_ior: crate::optics::Ior::real(1.37),
            substrate_ior: crate::optics::Ior::real(1.64),
            width: 4,
            height: 3,
            thickness_nm: vec![d; 12],
        }
    }

    #[test]
    fn samples_figure_has_labelled_rows_and_shows_a_difference() {
        let settings = RenderSettings {
            resolution: 48,
            spp: 4,
            seed: 1,
            max_depth: 3,
            progress: false,
        };
        let rows = vec![
            SampleRow {
                name: "same".into(),
                truth: material(400.0),
                fitted: material(400.0),
            },
            SampleRow {
                name: "off".into(),
                truth: material(400.0),
                fitted: material(460.0),
            },
        ];
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("fig.png");
        let des = samples_figure(&rows, None, &settings, &out).unwrap();
        // Same material, same seed: identical renders. A 60 nm error must show.
        assert_eq!(des[0], 0.0);
        assert!(
            des[1] > 1.0,
            "ΔE00 of a 15 % thickness error was {}",
            des[1]
        );
        let img = image::open(&out).unwrap().to_rgb8();
        assert!(img.width() > 3 * 48 && img.height() > 2 * 48);
        // Titles are drawn: the strip above the first panel is not all white.
        let title_ink = (0..img.width())
            .flat_map(|x| (8..24).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 != [255, 255, 255])
            .count();
        assert!(title_ink > 50, "no title pixels found");
        assert!(dir.path().join("fig_off_fitted.exr").is_file());
    }
}
