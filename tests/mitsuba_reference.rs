//! Our renderer against the committed Mitsuba 3 references (`tests/references/`, made by
//! `tools/mitsuba/render_references.py`, 4096 spp at 128×128 with a box filter).
//!
//! Each reference scene is rendered at low spp and half the size (64×64, same camera). Both
//! images are box-downsampled to 16×16 — with a box pixel filter this averages exactly the
//! same footprint — which averages out most of the Monte Carlo noise, so what remains is
//! systematic: we assert mean ΔE00 ≤ 1.0 and a mean-colour bias < 1 % per channel.
//! A deliberately wrong material (film 10 % too thick) must fail the same check, proving the
//! check can fail.
//!
//! Run with `cargo test --release --test mitsuba_reference` (debug builds are much slower).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use thinfilm::compare::references::{load_manifest, Reference};
use thinfilm::compare::{compare_images, downsample_box, ImageMetrics};
use thinfilm::image_io::{read_exr_rgb, RgbImage};
use thinfilm::render::bsdf::Bsdf;
use thinfilm::render::texture::{Spectrum, Texture};
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::Scene;

/// Our render: 64×64 at this many samples per pixel.
const OUR_SIZE: u32 = 64;
const OUR_SPP: u32 = 128;
/// Both images are compared at 16×16.
const COMPARE_SIZE: usize = 16;
const MAX_MEAN_DELTA_E00: f64 = 1.0;
const MAX_ABS_BIAS: f64 = 0.01;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn references() -> Vec<Reference> {
    load_manifest(&repo()).expect("tests/references/manifest.json")
}

fn load(path: &Path) -> Scene {
    thinfilm::scene::load(path, &[]).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()))
}

/// Samples per pixel for our side. The soap bubble (`bubble`) chooses between two delta lobes
/// at each of two film crossings and sees the environment's sharp softboxes through and in
/// the film, so its per-pixel variance is several times the others': at 128 spp noise alone
/// gives mean ΔE00 ≈ 1.05 (two seeds; mean bias < 0.7 %), at 512 spp 0.58, at 2048 spp 0.32
/// (measured 2026-11-22). 512 spp keeps the ΔE00 ≤ 1 check meaningful for it.
///
///
/// The area-lit scenes are dark apart from small, bright emitters. `cornell_box` at 128 spp
/// shows a blue mean bias of −1.2 % from noise alone, at 1024 spp −0.2 %. In `veach_mis` the
/// smallest light (radius 0.03, radiance 900) covers a fraction of a pixel, so the image mean
/// is heavy-tailed: −1.6 % blue at 1024 spp, +0.16 % at 4096 spp (seed 7, measured
/// 2026-11-25; at 128² and 4096 spp every channel is within 0.07 % of Mitsuba).
fn our_spp(name: &str) -> u32 {
    match name {
        "bubble" => 512,
        "cornell_box" => 1024,
        "veach_mis" => 4096,
        _ => OUR_SPP,
    }
}

fn render_ours(scene: &Scene) -> RgbImage {
    render_ours_spp(scene, OUR_SPP)
}

fn render_ours_spp(scene: &Scene, spp: u32) -> RgbImage {
    let options = RenderOptions {
        spp: Some(spp),
        seed: Some(7),
        resolution: Some((OUR_SIZE, OUR_SIZE)),
        ..Default::default()
    };
    render(scene, &options).expect("render").image
}

fn metrics_against(ours: &RgbImage, reference: &RgbImage) -> ImageMetrics {
    assert_eq!(reference.width % COMPARE_SIZE, 0);
    let a = downsample_box(ours, ours.width / COMPARE_SIZE).unwrap();
    let b = downsample_box(reference, reference.width / COMPARE_SIZE).unwrap();
    compare_images(&a, &b).unwrap()
}

fn passes(m: &ImageMetrics) -> bool {
    m.delta_e00_mean <= MAX_MEAN_DELTA_E00 && m.max_abs_bias() < MAX_ABS_BIAS
}

fn describe(m: &ImageMetrics) -> String {
    format!(
        "mean ΔE00 {:.3} (95th {:.3}), bias R {:+.2}% G {:+.2}% B {:+.2}%, relMSE {:.2e}",
        m.delta_e00_mean,
        m.delta_e00_p95,
        100.0 * m.mean_bias_rgb[0],
        100.0 * m.mean_bias_rgb[1],
        100.0 * m.mean_bias_rgb[2],
        m.rel_mse
    )
}

#[test]
fn every_reference_scene_matches_mitsuba() {
    let refs = references();
    assert!(refs.len() >= 2, "manifest lists {} references", refs.len());
    let mut failures = Vec::new();
    for r in &refs {
        let reference = read_exr_rgb(&r.exr).unwrap();
        assert_eq!(
            (reference.width, reference.height),
            (128, 128),
            "{}: references are 128×128",
            r.name
        );
        let ours = render_ours_spp(&load(&r.scene), our_spp(&r.name));
        let m = metrics_against(&ours, &reference);
        eprintln!("{:24} {}", r.name, describe(&m));
        if !passes(&m) {
            failures.push(format!("{}: {}", r.name, describe(&m)));
        }
    }
    assert!(
        failures.is_empty(),
        "scenes differing from Mitsuba:\n{}",
        failures.join("\n")
    );
}

/// Scales every thin-film thickness in the scene (constants and bitmap textures).
fn scale_thickness(scene: &mut Scene, factor: f32) -> usize {
    let mut changed = 0;
    for b in &mut scene.bsdfs {
        let mut bsdf = b;
        while let Bsdf::TwoSided(t) = bsdf {
            bsdf = &mut t.inner;
        }
        if let Bsdf::ThinFilm(film) = bsdf {
            match &mut film.thickness_nm {
                Texture::Value(Spectrum::Constant(v)) => *v *= factor,
                Texture::Bitmap(bmp) => {
                    let mut t = (**bmp).clone();
                    t.data.iter_mut().for_each(|v| *v *= factor);
                    if let Some((lo, hi)) = &mut t.value_range {
                        *lo *= factor;
                        *hi *= factor;
                    }
                    *bmp = Arc::new(t);
                }
                other => panic!("unexpected thickness {other:?}"),
            }
            changed += 1;
        }
    }
    changed
}

#[test]
fn film_ten_percent_too_thick_fails_the_check() {
    // One constant-thickness teapot and the bitmap-textured estimator material.
    let refs = references();
    for name in ["teapot_mgf2_400", "material"] {
        let r = refs
            .iter()
            .find(|r| r.name == name)
            .unwrap_or_else(|| panic!("reference {name} missing from the manifest"));
        let reference = read_exr_rgb(&r.exr).unwrap();
        let mut scene = load(&r.scene);
        assert!(scale_thickness(&mut scene, 1.1) > 0, "{name}: no thin film");
        let m = metrics_against(&render_ours(&scene), &reference);
        eprintln!("{name} with thickness ×1.1: {}", describe(&m));
        assert!(
            !passes(&m),
            "{name}: a 10 % thickness error went unnoticed: {}",
            describe(&m)
        );
    }
}
