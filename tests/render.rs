//! End-to-end renderer tests on small programmatic scenes: furnace, determinism across thread
//! counts and sample-range splits, effect analysis, finiteness at grazing views and zero
//! thickness films.

use glam::{Vec2, Vec3};
use thinfilm::optics::Ior;
use thinfilm::render::bsdf::{
    conductor::Conductor, dielectric::Dielectric, diffuse::Diffuse, thinfilm::ThinFilmBsdf,
    twosided::TwoSided, Bsdf,
};
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::*;

fn camera(origin: Vec3, target: Vec3, fov: f32) -> Camera {
    Camera {
        to_world: look_at(origin, target, Vec3::Y),
        fov_deg: fov,
        projection: thinfilm::scene::Projection::Perspective,
        fov_axis: FovAxis::X,
        near_clip: 0.01,
        far_clip: 1000.0,
    }
}

fn base_scene(
    shapes: Vec<Shape>,
    bsdfs: Vec<Bsdf>,
    emitters: Vec<EmitterDesc>,
    res: u32,
    spp: u32,
) -> Scene {
    Scene {
        camera: camera(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, 40.0),
        film: FilmSettings {
            width: res,
            height: res,
            filter: ReconstructionFilter::Box,
        },
        integrator: IntegratorSettings::default(),
        spp,
        seed: 0,
        sampler: SamplerKind::default(),
        shapes,
        bsdfs,
        emitters,
        polarizer: None,
        source: None,
        media: None,
    }
}

fn constant(v: f32) -> TextureDesc {
    TextureDesc::Value(SpectrumDesc::Constant(v))
}

fn sphere(bsdf: usize) -> Shape {
    Shape {
        geometry: Geometry::Sphere {
            center: Vec3::ZERO,
            radius: 1.0,
            rotation: glam::Mat3::IDENTITY,
            flip_normals: false,
        },
        bsdf,
        emission: None,
        name: Some("ball".into()),
    }
}

/// A quad (two triangles) in the plane y = `y`, facing +Y, with UVs.
fn floor(y: f32, half: f32, bsdf: usize) -> Shape {
    let mesh = TriangleMesh {
        colors: Vec::new(),
        tangents: Vec::new(),
        positions: vec![
            Vec3::new(-half, y, -half),
            Vec3::new(half, y, -half),
            Vec3::new(half, y, half),
            Vec3::new(-half, y, half),
        ],
        normals: vec![Vec3::Y; 4],
        uvs: vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ],
        indices: vec![[0, 2, 1], [0, 3, 2]],
    };
    Shape {
        geometry: Geometry::Mesh(mesh.into()),
        bsdf,
        emission: None,
        name: Some("floor".into()),
    }
}

fn white_env() -> EmitterDesc {
    EmitterDesc::Constant {
        radiance: SpectrumDesc::Constant(1.0),
    }
}

fn thin_film(alpha: f32, thickness: f32) -> Bsdf {
    ThinFilmBsdf::new(
        Ior::real(1.37),
        &constant(thickness),
        Ior::real(1.64),
        alpha,
    )
    .unwrap()
    .into()
}

fn assert_all_finite(img: &thinfilm::image_io::RgbImage, what: &str) {
    for (i, p) in img.pixels.iter().enumerate() {
        assert!(
            p.iter().all(|v| v.is_finite()),
            "{what}: pixel ({}, {}) = {p:?}",
            i % img.width,
            i / img.width
        );
    }
}

/// Mean spectral radiance over `n` paths through film position `uv`, at four fixed
/// wavelengths (so the estimate has no colour-matching noise), and the largest deviation of
/// any wavelength from `expect`.
fn furnace_deviation(scene: &Scene, uvs: &[Vec2], n: u32, expect: f32) -> f32 {
    use thinfilm::render::{integrator, prepare, sampler::Sampler};
    use thinfilm::spectrum::SampledWavelengths;
    let prepared = prepare(scene, &RenderOptions::default()).unwrap();
    thinfilm::render::counters::take();
    let mut worst = 0.0f32;
    for (k, uv) in uvs.iter().enumerate() {
        let mut sum = [0.0f64; 4];
        for s in 0..n {
            let mut sampler = Sampler::for_sample(k as u32, 0, s, 1);
            let mut wl = SampledWavelengths {
                lambda: [400.0, 500.0, 600.0, 700.0],
                pdf: [1.0; 4],
            };
            let ray = prepared.camera().generate_ray(*uv);
            let l = integrator::li(&prepared, ray, None, &mut wl, &mut sampler);
            for (s, v) in sum.iter_mut().zip(l.to_array()) {
                *s += v as f64;
            }
        }
        for s in sum {
            worst = worst.max((s / n as f64 - expect as f64).abs() as f32 / expect);
        }
    }
    assert_eq!(thinfilm::render::counters::take().invalid_samples, 0);
    worst
}

fn film_grid(k: usize) -> Vec<Vec2> {
    (0..k * k)
        .map(|i| {
            Vec2::new(
                ((i % k) as f32 + 0.5) / k as f32,
                ((i / k) as f32 + 0.5) / k as f32,
            )
        })
        .collect()
}

/// White furnace: a diffuse albedo-1 sphere in a constant environment of radiance 1 renders
/// 1 ± 1 % at every pixel (and every wavelength), so it is invisible.
#[test]
fn furnace_diffuse_sphere_is_invisible() {
    let scene = base_scene(
        vec![sphere(0)],
        vec![Bsdf::from(Diffuse::new(&constant(1.0)))],
        vec![white_env()],
        24,
        1,
    );
    // Film positions inside the sphere's silhouette (it spans the central ~70 %) and outside.
    let dev = furnace_deviation(&scene, &film_grid(5), 20_000, 1.0);
    assert!(dev < 0.01, "furnace deviation {dev}");
    // The image itself: sphere pixels average like the background, and nothing is invalid.
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(64),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(out.stats.rays > out.stats.samples);
    assert_eq!(out.stats.invalid_samples, 0);
    assert_all_finite(&out.image, "furnace");
}

/// Furnace through triangle meshes: a two-sided diffuse albedo-1 floor in a constant
/// environment. A plane sees the sky only above, so L = 1 exactly as well (BVH hits, MIS
/// between BSDF and light sampling, back faces via `twosided`).
#[test]
fn furnace_two_sided_diffuse_quad() {
    let mut scene = base_scene(
        vec![floor(-0.5, 3.0, 0)],
        vec![TwoSided::new(Diffuse::new(&constant(1.0)).into())
            .unwrap()
            .into()],
        vec![white_env()],
        16,
        1,
    );
    scene.camera = camera(Vec3::new(0.0, 3.0, -2.0), Vec3::ZERO, 40.0);
    assert!(furnace_deviation(&scene, &film_grid(4), 20_000, 1.0) < 0.01);
    // From below (back faces).
    scene.camera = camera(Vec3::new(0.0, -3.0, -2.0), Vec3::ZERO, 40.0);
    assert!(furnace_deviation(&scene, &film_grid(4), 20_000, 1.0) < 0.01);
}

fn film_scene(res: u32, spp: u32) -> Scene {
    let mut scene = base_scene(
        vec![sphere(0), floor(-1.0, 4.0, 1)],
        vec![
            thin_film(0.15, 400.0),
            Bsdf::from(Diffuse::new(&constant(0.6))),
        ],
        vec![
            EmitterDesc::Constant {
                radiance: SpectrumDesc::Constant(0.8),
            },
            EmitterDesc::Point {
                position: Vec3::new(2.0, 3.0, -2.0),
                intensity: SpectrumDesc::Constant(5.0),
            },
        ],
        res,
        spp,
    );
    scene.camera = camera(Vec3::new(0.0, 1.0, -4.0), Vec3::ZERO, 45.0);
    scene
}

fn bits(img: &thinfilm::image_io::RgbImage) -> Vec<u32> {
    img.pixels
        .iter()
        .flat_map(|p| p.map(f32::to_bits))
        .collect()
}

/// Same seed and spp: bit-identical images with 1 and 2 threads, for both samplers (with
/// adaptive sample counts, on by default).
#[test]
fn deterministic_across_thread_counts() {
    for sampler in [SamplerKind::Independent, SamplerKind::Sobol] {
        deterministic_across_thread_counts_with(sampler);
    }
}

fn deterministic_across_thread_counts_with(sampler: SamplerKind) {
    let mut scene = film_scene(20, 8);
    scene.sampler = sampler;
    let one = render(
        &scene,
        &RenderOptions {
            threads: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    let two = render(
        &scene,
        &RenderOptions {
            threads: Some(2),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(bits(&one.image), bits(&two.image));
    // With adaptive counts: they come from every pixel's samples, the same on any thread.
    assert!(one.adaptive && two.adaptive);
    let other_seed = render(
        &scene,
        &RenderOptions {
            threads: Some(2),
            seed: Some(9),
            ..Default::default()
        },
    )
    .unwrap();
    assert_ne!(bits(&one.image), bits(&other_seed.image));
}

/// Renders of samples 0:32 and 32:64 merge (sample-weighted mean) to exactly the 0:64 render,
/// also after a round trip through EXR files, for both samplers.
#[test]
fn sample_ranges_merge_exactly() {
    for sampler in [SamplerKind::Independent, SamplerKind::Sobol] {
        sample_ranges_merge_exactly_with(sampler);
    }
}

fn sample_ranges_merge_exactly_with(sampler: SamplerKind) {
    let mut scene = film_scene(12, 64);
    scene.sampler = sampler;
    let full = render(
        &scene,
        &RenderOptions {
            sample_range: Some((0, 64)),
            ..Default::default()
        },
    )
    .unwrap();
    let a = render(
        &scene,
        &RenderOptions {
            sample_range: Some((0, 32)),
            threads: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    let b = render(
        &scene,
        &RenderOptions {
            sample_range: Some((32, 64)),
            threads: Some(2),
            ..Default::default()
        },
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("a.exr"), dir.path().join("b.exr"));
    thinfilm::image_io::write_exr_rgb(&pa, &a.image).unwrap();
    thinfilm::image_io::write_exr_rgb(&pb, &b.image).unwrap();
    let ra = thinfilm::image_io::read_exr_rgb(&pa).unwrap();
    let rb = thinfilm::image_io::read_exr_rgb(&pb).unwrap();
    for i in 0..full.image.pixels.len() {
        for c in 0..3 {
            let merged = (32.0 * ra.pixels[i][c] + 32.0 * rb.pixels[i][c]) / 64.0;
            assert_eq!(
                merged.to_bits(),
                full.image.pixels[i][c].to_bits(),
                "pixel {i} channel {c}"
            );
        }
    }
    // The default range with the same count in every pixel is the same as an explicit 0:spp;
    // by default the counts adapt (a whole render, box filter) and the image differs.
    let uniform = RenderOptions {
        uniform_samples: true,
        ..Default::default()
    };
    let default = render(&scene, &uniform).unwrap();
    assert_eq!(bits(&default.image), bits(&full.image));
    let adaptive = render(&scene, &RenderOptions::default()).unwrap();
    assert!(adaptive.adaptive && !full.adaptive && !default.adaptive);
    assert_ne!(bits(&adaptive.image), bits(&full.image));
}

/// Effect analysis: a scene without thin film never calls the film code; one with it does,
/// and the log says why.
#[test]
fn effect_analysis_switches_interference() {
    let plain = base_scene(
        vec![sphere(0), floor(-1.0, 4.0, 1)],
        vec![
            Bsdf::from(Conductor::new("0.2+3.9i".parse().unwrap(), 0.2, 0.2).unwrap()),
            Bsdf::from(Diffuse::new(&constant(0.5))),
            // Declared but used by no shape: must not switch interference on.
            thin_film(0.0, 300.0),
        ],
        vec![white_env()],
        12,
        4,
    );
    let out = render(&plain, &RenderOptions::default()).unwrap();
    assert!(!out.effects.interference && out.effects.rough && !out.effects.dispersion);
    assert_eq!(out.stats.film_evals, 0);
    assert!(out
        .effects
        .lines()
        .iter()
        .any(|r| r.starts_with("interference: off")));

    let film = film_scene(12, 4);
    let out = render(&film, &RenderOptions::default()).unwrap();
    assert!(out.effects.interference);
    assert!(out.stats.film_evals > 0);
    assert!(out
        .effects
        .lines()
        .iter()
        .any(|r| r.starts_with("interference: ON")));

    let mut polarised = film_scene(4, 1);
    polarised.polarizer = Some(Polarizer::S);
    // Polarised rendering: the polariser switches Stokes transport on.
    let out = render(&polarised, &RenderOptions::default()).unwrap();
    assert!(out.effects.polarization);
    assert!(out
        .effects
        .lines()
        .iter()
        .any(|r| r.starts_with("polarisation: ON")));
}

/// No NaN/inf: grazing views of a film-coated floor, zero-thickness films, smooth and rough,
/// a camera inside a sphere, glass.
#[test]
fn no_nan_at_grazing_views_and_zero_thickness() {
    for (alpha, d) in [(0.0, 0.0), (0.3, 0.0), (0.0, 400.0), (0.05, 1e5)] {
        let mut scene = base_scene(
            vec![floor(0.0, 100.0, 0), sphere(1)],
            vec![thin_film(alpha, d), thin_film(alpha, d)],
            vec![white_env()],
            16,
            8,
        );
        // Eye 1 mm above a 200 m floor: most rays graze it.
        scene.camera = camera(Vec3::new(0.0, 1e-3, -50.0), Vec3::new(0.0, 1e-3, 0.0), 60.0);
        let out = render(&scene, &RenderOptions::default()).unwrap();
        assert_all_finite(&out.image, &format!("grazing film α={alpha} d={d}"));
        assert_eq!(out.stats.invalid_samples, 0, "α={alpha} d={d}");
    }
    // Camera inside a diffuse sphere lit by a point light.
    let mut scene = base_scene(
        vec![sphere(0)],
        vec![TwoSided::new(Diffuse::new(&constant(0.9)).into())
            .unwrap()
            .into()],
        vec![EmitterDesc::Point {
            position: Vec3::new(0.2, 0.1, 0.0),
            intensity: SpectrumDesc::Constant(1.0),
        }],
        12,
        8,
    );
    scene.camera = camera(Vec3::ZERO, Vec3::Z, 90.0);
    let out = render(&scene, &RenderOptions::default()).unwrap();
    assert_all_finite(&out.image, "inside sphere");
    assert!(out.image.pixels.iter().all(|p| p[1] > 0.0));
    let glass = base_scene(
        vec![sphere(0), floor(-1.0, 4.0, 1)],
        vec![
            Bsdf::from(Dielectric::new(Ior::real(1.5), Ior::real(1.0))),
            Bsdf::from(Diffuse::new(&constant(0.5))),
        ],
        vec![white_env()],
        12,
        8,
    );
    let out = render(&glass, &RenderOptions::default()).unwrap();
    assert_all_finite(&out.image, "glass");
    assert_eq!(out.stats.invalid_samples, 0);
}

/// max_depth 1 shows only directly visible emitters: the sphere is black, the sky is not.
#[test]
fn max_depth_one_shows_only_emitters() {
    let scene = base_scene(
        vec![sphere(0)],
        vec![Bsdf::from(Diffuse::new(&constant(1.0)))],
        vec![white_env()],
        16,
        2,
    );
    let out = render(
        &scene,
        &RenderOptions {
            max_depth: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(out.image.get(8, 8), [0.0; 3]);
    assert!(out.image.get(0, 0)[1] > 0.5);
}

/// Tent and Gaussian reconstruction: deterministic and finite; a flat scene stays flat.
#[test]
fn splatting_filters_are_deterministic() {
    for filter in [
        ReconstructionFilter::Tent { radius: 1.0 },
        ReconstructionFilter::Gaussian { stddev: 0.5 },
    ] {
        let mut scene = film_scene(10, 4);
        scene.film.filter = filter;
        let one = render(
            &scene,
            &RenderOptions {
                threads: Some(1),
                ..Default::default()
            },
        )
        .unwrap();
        let two = render(
            &scene,
            &RenderOptions {
                threads: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(bits(&one.image), bits(&two.image));
        assert_all_finite(&one.image, "filter");
    }
}

/// Bad user input is an error, never a panic.
#[test]
fn bad_inputs_are_errors() {
    let scene = film_scene(8, 4);
    assert!(render(
        &scene,
        &RenderOptions {
            resolution: Some((0, 8)),
            ..Default::default()
        }
    )
    .is_err());
    assert!(render(
        &scene,
        &RenderOptions {
            sample_range: Some((5, 5)),
            ..Default::default()
        }
    )
    .is_err());
    assert!(render(
        &scene,
        &RenderOptions {
            max_depth: Some(0),
            ..Default::default()
        }
    )
    .is_err());
    assert!(render(
        &scene,
        &RenderOptions {
            threads: Some(0),
            ..Default::default()
        }
    )
    .is_err());
    let err = render(
        &scene,
        &RenderOptions {
            fresnel_splits: Some(17),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(format!("{err:#}").contains("fresnel_splits"));
    let mut bad = film_scene(8, 4);
    bad.shapes[0].bsdf = 99;
    assert!(render(&bad, &RenderOptions::default()).is_err());
    let mut bad = film_scene(8, 4);
    bad.shapes.push(Shape {
        geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions: vec![Vec3::ZERO; 3],
            normals: vec![],
            uvs: vec![],
            indices: vec![[0, 1, 7]],
        })),
        bsdf: 0,
        emission: None,
        name: Some("broken".into()),
    });
    let err = render(&bad, &RenderOptions::default()).unwrap_err();
    assert!(format!("{err:#}").contains("broken"));
}

/// An inward-facing emissive cube of half-size `h` (12 triangles, normals pointing inwards).
fn emissive_box(h: f32, bsdf: usize) -> Shape {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |a: f32, b: f32| {
                let mut p = [0.0f32; 3];
                p[axis] = sign * h;
                p[u] = a * h;
                p[v] = b * h;
                Vec3::from_array(p)
            };
            let base = positions.len() as u32;
            positions.extend([
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(1.0, 1.0),
                corner(-1.0, 1.0),
            ]);
            let (a, b, c) = (
                positions[base as usize],
                positions[base as usize + 1],
                positions[base as usize + 2],
            );
            let inward = (b - a).cross(c - a).dot(-a) > 0.0;
            if inward {
                indices.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
            } else {
                indices.extend([[base, base + 2, base + 1], [base, base + 3, base + 2]]);
            }
        }
    }
    Shape {
        geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions,
            normals: vec![],
            uvs: vec![],
            indices,
        })),
        bsdf,
        emission: Some(SpectrumDesc::Constant(1.0)),
        name: Some("light box".into()),
    }
}

/// Area lights: a diffuse albedo-0.5 sphere inside a black enclosure that emits radiance 1
/// inwards sees radiance 1 from every direction, so it renders 0.5 ± 1 % (light sampling of
/// spheres and of triangle meshes, MIS with BSDF sampling, one-sided emission).
#[test]
fn area_light_enclosure() {
    let black = Bsdf::from(Diffuse::new(&constant(0.0)));
    let grey = Bsdf::from(Diffuse::new(&constant(0.5)));
    let centre: Vec<Vec2> = (0..9)
        .map(|i| Vec2::new(0.45 + 0.05 * (i % 3) as f32, 0.45 + 0.05 * (i / 3) as f32))
        .collect();
    let mut sphere_light = Shape {
        geometry: Geometry::Sphere {
            center: Vec3::ZERO,
            radius: 10.0,
            rotation: glam::Mat3::IDENTITY,
            flip_normals: true,
        },
        bsdf: 1,
        emission: Some(SpectrumDesc::Constant(1.0)),
        name: Some("light sphere".into()),
    };
    let scene = base_scene(
        vec![sphere(0), sphere_light.clone()],
        vec![grey.clone(), black.clone()],
        vec![],
        8,
        1,
    );
    let dev = furnace_deviation(&scene, &centre, 20_000, 0.5);
    assert!(dev < 0.01, "sphere light: {dev}");
    let scene = base_scene(
        vec![sphere(0), emissive_box(10.0, 1)],
        vec![grey, black.clone()],
        vec![],
        8,
        1,
    );
    let dev = furnace_deviation(&scene, &centre, 20_000, 0.5);
    assert!(dev < 0.01, "mesh light: {dev}");
    // Emission is one-sided: with outward normals the enclosure is dark inside.
    if let Geometry::Sphere { flip_normals, .. } = &mut sphere_light.geometry {
        *flip_normals = false;
    }
    let scene = base_scene(
        vec![sphere(0), sphere_light],
        vec![Bsdf::from(Diffuse::new(&constant(0.5))), black],
        vec![],
        8,
        1,
    );
    assert!((furnace_deviation(&scene, &centre, 200, 1.0) - 1.0).abs() < 1e-6);
}

/// Per-path estimates at one film position and four fixed wavelengths (the first one's
/// value per path), with `splits` Fresnel splits; unpolarised or polarised integrator.
fn path_estimates(scene: &Scene, uv: Vec2, n: u32, splits: u32) -> Vec<f64> {
    use thinfilm::render::{counters, integrator, prepare, sampler::Sampler};
    use thinfilm::spectrum::SampledWavelengths;
    let prepared = prepare(
        scene,
        &RenderOptions {
            fresnel_splits: Some(splits),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(prepared.fresnel_splits(), splits);
    counters::take();
    let out = (0..n)
        .map(|s| {
            let mut sampler = Sampler::for_sample(0, 0, s, 3);
            let mut wl = SampledWavelengths {
                lambda: [450.0, 520.0, 600.0, 680.0],
                pdf: [1.0; 4],
            };
            let ray = prepared.camera().generate_ray(uv);
            let l = integrator::li(&prepared, ray, None, &mut wl, &mut sampler);
            l.x as f64
        })
        .collect();
    assert_eq!(counters::take().invalid_samples, 0);
    out
}

/// Fresnel splitting follows both lobes of a smooth glass interface with their full weights:
/// the estimate keeps its expectation (the mean of Mitsuba-style one-lobe sampling) and loses
/// the lobe-choice variance — over a single glass interface in a white environment, every
/// path gives R + T/η² exactly. Unpolarised and polarised (sensor polariser) integrators.
#[test]
fn fresnel_splitting_keeps_the_mean_and_removes_lobe_noise() {
    for polarizer in [None, Some(Polarizer::AngleDeg(30.0))] {
        let mut scene = base_scene(
            vec![floor(0.0, 50.0, 0)],
            vec![Bsdf::from(Dielectric::new(Ior::real(1.5), Ior::real(1.0)))],
            vec![white_env()],
            8,
            1,
        );
        scene.camera = camera(Vec3::new(0.0, 1.0, -2.0), Vec3::ZERO, 30.0);
        scene.polarizer = polarizer;
        let uv = Vec2::new(0.5, 0.5);
        let n = 4096;
        let one_lobe = path_estimates(&scene, uv, n, 0);
        let split = path_estimates(&scene, uv, n, 2);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (m0, m2) = (mean(&one_lobe), mean(&split));
        let var0 = one_lobe.iter().map(|x| (x - m0).powi(2)).sum::<f64>() / n as f64;
        let spread2 = split.iter().map(|x| (x - m2).abs()).fold(0.0, f64::max);
        // One-lobe sampling is a Bernoulli choice between 1 and 1/η²: real noise…
        assert!(
            var0.sqrt() > 0.05,
            "{polarizer:?}: one-lobe std {}",
            var0.sqrt()
        );
        // …which splitting removes (only the polariser's angle varies nothing per path here),
        assert!(spread2 < 1e-5, "{polarizer:?}: split spread {spread2}");
        // and the means agree within 4 standard errors of the one-lobe estimate.
        let se = (var0 / n as f64).sqrt();
        assert!(
            (m0 - m2).abs() < 4.0 * se,
            "{polarizer:?}: {m0} vs {m2} (se {se})"
        );
    }
}

/// Splitting is switched on only for smooth reflect/transmit interfaces without dispersion.
#[test]
fn effect_analysis_switches_fresnel_splitting() {
    let glass = |n: Ior| {
        base_scene(
            vec![sphere(0)],
            vec![Bsdf::from(Dielectric::new(n, Ior::real(1.0)))],
            vec![white_env()],
            4,
            1,
        )
    };
    let prepared = |s: &Scene| thinfilm::render::prepare(s, &RenderOptions::default()).unwrap();
    let p = prepared(&glass(Ior::real(1.5)));
    assert!(p.effects().fresnel_split);
    assert_eq!(p.fresnel_splits(), thinfilm::render::DEFAULT_FRESNEL_SPLITS);
    let bk7: Ior = "material:BK7".parse().unwrap();
    let p = prepared(&glass(bk7));
    assert!(p.effects().dispersion && !p.effects().fresnel_split);
    assert_eq!(p.fresnel_splits(), 0);
    let p = prepared(&film_scene(4, 1));
    assert!(!p.effects().fresnel_split && p.fresnel_splits() == 0);
    assert!(p
        .effects()
        .lines()
        .iter()
        .any(|r| r.starts_with("Fresnel splitting: off")));
}

/// A diffuse ball of albedo `albedo` (the [`sphere`], 24², `independent` sampler) lit by the
/// environment map `sky` turned by `to_world`.
fn diffuse_ball_under(
    sky: thinfilm::image_io::RgbImage,
    to_world: glam::Mat4,
    albedo: f32,
) -> Scene {
    let env = EmitterDesc::Envmap {
        image: std::sync::Arc::new(sky),
        scale: 1.0,
        to_world,
        path: None,
    };
    let mut scene = base_scene(
        vec![sphere(0)],
        vec![Bsdf::from(Diffuse::new(&constant(albedo)))],
        vec![env],
        24,
        64,
    );
    scene.sampler = SamplerKind::Independent;
    scene
}

/// Camera rays that see the environment directly take its closed-form colour (the mean of
/// the film's spectral estimate over the wavelengths): samples that hit the scene are
/// untouched (pixels they alone cover are the same bit for bit), the background converges
/// to the same colours as a wavelength-sampled render, without its colour noise.
#[test]
fn closed_form_background_keeps_the_expectation_without_colour_noise() {
    let mut sky = thinfilm::image_io::RgbImage::new(16, 8);
    for (i, p) in sky.pixels.iter_mut().enumerate() {
        *p = match i % 4 {
            0 => [3.0, 0.1, 0.0],
            1 => [0.0, 0.8, 1.5],
            2 => [0.2, 0.2, 0.2],
            _ => [0.0, 0.0, 0.0],
        };
    }
    let scene = diffuse_ball_under(sky, glam::Mat4::IDENTITY, 0.5);
    let run = |spp: u32, spectral: bool| {
        // The same count in every pixel: adaptive counts would follow the background's
        // colour noise, which differs between the two.
        let options = RenderOptions {
            spp: Some(spp),
            spectral_direct_view: spectral,
            uniform_samples: true,
            ..Default::default()
        };
        let lines = effect_lines(&scene, &options);
        let want = if spectral {
            "wavelength sampling of emitters seen directly: ON — asked for"
        } else {
            "wavelength sampling of emitters seen directly: off"
        };
        assert_effect_line(&lines, want);
        render(&scene, &options).unwrap().image
    };
    let (closed, sampled) = (run(64, false), run(64, true));
    let truth = run(4096, true);
    // The sphere (radius 1 at distance 4, 40° field of view) covers the centre pixels.
    let (w, h) = (closed.width, closed.height);
    let centre = (h / 2) * w + w / 2;
    assert_eq!(
        bits_of(&closed.pixels[centre]),
        bits_of(&sampled.pixels[centre])
    );
    let same = (closed.pixels.iter().zip(&sampled.pixels))
        .filter(|(a, b)| bits_of(a) == bits_of(b))
        .count();
    assert!(same >= w * h / 10, "only {same} pixels identical");
    // The background: the image's outer ring, which only the environment covers.
    let ring: Vec<usize> = (0..w * h)
        .filter(|i| i % w < 3 || i % w >= w - 3 || i / w < 3 || i / w >= h - 3)
        .collect();
    let error = |img: &thinfilm::image_io::RgbImage| offset_and_rmse(img, &truth, &ring);
    let ((bias_closed, rmse_closed), (_, rmse_sampled)) = (error(&closed), error(&sampled));
    assert!(
        rmse_closed < 0.3 * rmse_sampled,
        "background RMSE closed form {rmse_closed} vs sampled {rmse_sampled}"
    );
    // The reference's own noise (4096 samples) bounds what is left, bias included.
    assert!(
        bias_closed.abs() < 0.2 * rmse_sampled / 8.0 + 1e-4,
        "bias {bias_closed}"
    );
}

/// Hemisphere-aware environment sampling: a diffuse ball under a studio-like map (a small
/// bright light, a sky holding most of the light, a dark ground) renders to the same image as
/// with radiance-only sampling (a 1024-spp render's mean over the ball agrees with a
/// 4096-spp radiance-only one within the noise), with less error at 64 spp against it (under
/// 0.9× the RMSE pooled over four seeds; 0.84× measured with MIS compensation, 0.77–0.86× per
/// seed before it: on this sky-dominated map compensation moves little).
#[test]
fn hemisphere_env_sampling_keeps_the_image_with_less_noise() {
    let scene = diffuse_ball_under(studio_sky(), glam::Mat4::from_rotation_y(0.4), 0.7);
    // (One seed's ratio varies by ±0.04: squared errors pooled over four.)
    let (rmse_plain, rmse_hemisphere) =
        env_sampling_against_radiance_only(&scene, "hemisphere-aware environment sampling: ON");
    assert!(
        rmse_hemisphere < 0.9 * rmse_plain,
        "RMSE over the ball: hemisphere {rmse_hemisphere} vs radiance-only {rmse_plain}"
    );
    // A black map has no tables: sampling by radiance alone, and the log says so.
    let mut dark = scene.clone();
    dark.emitters = vec![EmitterDesc::Envmap {
        image: std::sync::Arc::new(thinfilm::image_io::RgbImage::new(8, 4)),
        scale: 1.0,
        to_world: glam::Mat4::IDENTITY,
        path: None,
    }];
    let lines = effect_lines(&dark, &RenderOptions::default());
    let want = "hemisphere-aware environment sampling: off — the environment map is black";
    assert_effect_line(&lines, want);
}

/// Environment light sampling of `scene` (a ball, [`ball_pixels`]) against radiance-only
/// sampling (`--plain-env-sampling`): checks that the log says `want_on` by default and
/// radiance-only when asked, and that a 1024-spp default render's mean over the ball agrees
/// with a 4096-spp radiance-only render within the noise (bias included); returns the RMSE
/// over the ball at 64 spp against that render, pooled over four seeds, radiance-only and
/// default.
fn env_sampling_against_radiance_only(scene: &Scene, want_on: &str) -> (f64, f64) {
    let run = |spp: u32, seed: u64, plain: bool| {
        let options = RenderOptions {
            spp: Some(spp),
            seed: Some(seed),
            plain_env_sampling: plain,
            ..Default::default()
        };
        let lines = effect_lines(scene, &options);
        let want = match plain {
            true => "hemisphere-aware environment sampling: off — radiance-only sampling asked for",
            false => want_on,
        };
        assert_effect_line(&lines, want);
        render(scene, &options).unwrap().image
    };
    let truth = run(4096, 1, true);
    let ball = ball_pixels();
    assert_mean_within_noise(&run(1024, 3, false), &truth, &ball);
    let error = |img: &thinfilm::image_io::RgbImage| offset_and_rmse(img, &truth, &ball);
    let pooled = |plain: bool| pooled_rmse(|seed| error(&run(64, seed, plain)).1);
    (pooled(true), pooled(false))
}

/// A studio-like map: a small bright light, a sky holding most of the light, a dark ground.
fn studio_sky() -> thinfilm::image_io::RgbImage {
    let (w, h) = (32, 16);
    let mut sky = thinfilm::image_io::RgbImage::new(w, h);
    for (i, p) in sky.pixels.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        *p = if y >= h / 2 {
            [0.04, 0.035, 0.03]
        } else if (5..7).contains(&x) && (4..6).contains(&y) {
            [20.0, 18.0, 15.0]
        } else {
            [0.8, 1.0, 1.6]
        };
    }
    sky
}

/// A photo studio's map: four softboxes (~35° × 20°, two high, one at each side near the
/// horizon) in a dim room.
fn softbox_sky() -> thinfilm::image_io::RgbImage {
    let (w, h) = (64, 32);
    let mut sky = thinfilm::image_io::RgbImage::new(w, h);
    let boxes = [(4, 5), (22, 8), (38, 13), (52, 6)];
    for (i, p) in sky.pixels.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        let lit =
            (boxes.iter()).any(|&(bx, by)| (bx..bx + 6).contains(&x) && (by..by + 4).contains(&y));
        *p = if lit {
            [6.0, 5.8, 5.2]
        } else {
            [0.05, 0.05, 0.06]
        };
    }
    sky
}

/// Narrow glossy lobes draw environment light samples around their mirror direction: a rough
/// (GGX α 0.15) metal ball under [`softbox_sky`] renders to the same image as with
/// radiance-only sampling (1024 spp against 4096 within the noise), with less error at 64 spp
/// (pooled RMSE over the ball under 0.7× radiance-only's: 0.58× measured; the normal bins
/// alone, without the lobe's tables, gave 0.79×), and the log names the lobe width.
#[test]
fn glossy_lobe_env_sampling_keeps_the_image_with_less_noise() {
    let mut scene = diffuse_ball_under(softbox_sky(), glam::Mat4::from_rotation_y(0.4), 0.7);
    scene.bsdfs[0] = Conductor::new("0.2+3.9i".parse().unwrap(), 0.15, 0.15)
        .unwrap()
        .into();
    let want = "hemisphere-aware environment sampling: ON — reflecting surfaces draw environment samples from the hemisphere they face (256 normal bins); glossy lobes of α 0.15 around their mirror direction";
    let (rmse_plain, rmse_lobe) = env_sampling_against_radiance_only(&scene, want);
    assert!(
        rmse_lobe < 0.7 * rmse_plain,
        "RMSE over the ball: lobe bins {rmse_lobe} vs radiance-only {rmse_plain}"
    );
}

/// Paths that only reflect off a smooth film carry eight wavelengths to the emitter they meet
/// (the environment, an area light): a ZnS-film ball renders to the same image as with four,
/// with less colour noise at 64 spp (pooled RMSE over the ball under 0.75× four wavelengths';
/// ~0.55× measured), and a 1024-spp render's mean agrees with a 4096-spp four-wavelength one
/// within the noise. A smooth metal alone does not start a chain, and the log says so.
#[test]
fn specular_chains_keep_the_image_with_less_colour_noise() {
    let (w, h) = (32, 16);
    let mut sky = thinfilm::image_io::RgbImage::new(w, h);
    for (i, p) in sky.pixels.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        *p = match (y >= h / 2, x % 8 < 4) {
            (true, _) => [0.05, 0.04, 0.03],
            (false, true) => [0.9, 1.0, 1.4],
            (false, false) => [1.6, 0.9, 0.3],
        };
    }
    let film = ThinFilmBsdf::new(Ior::real(2.37), &constant(500.0), Ior::real(1.64), 0.0).unwrap();
    let lamp = Shape {
        geometry: Geometry::Sphere {
            center: Vec3::new(1.2, 0.8, -6.0),
            radius: 0.6,
            rotation: glam::Mat3::IDENTITY,
            flip_normals: false,
        },
        bsdf: 1,
        emission: Some(SpectrumDesc::Rgb([6.0, 5.0, 3.0])),
        name: Some("lamp".into()),
    };
    let env = EmitterDesc::Envmap {
        image: std::sync::Arc::new(sky),
        scale: 1.0,
        to_world: glam::Mat4::from_rotation_y(0.3),
        path: None,
    };
    let mut scene = base_scene(
        vec![sphere(0), lamp],
        vec![Bsdf::from(film), Bsdf::from(Diffuse::new(&constant(0.0)))],
        vec![env],
        24,
        64,
    );
    scene.sampler = SamplerKind::Independent;
    let run = |scene: &Scene, spp: u32, seed: u64, plain: bool| {
        let options = RenderOptions {
            spp: Some(spp),
            seed: Some(seed),
            plain_specular_chains: plain,
            ..Default::default()
        };
        let lines = effect_lines(scene, &options);
        (render(scene, &options).unwrap().image, lines)
    };
    let (truth, lines) = run(&scene, 4096, 1, true);
    let want = "wavelength supersampling of specular chains: off — four wavelengths asked for";
    assert_effect_line(&lines, want);
    let lines = run(&scene, 1, 1, false).1;
    let want = "wavelength supersampling of specular chains: ON";
    assert_effect_line(&lines, want);
    let ball = ball_pixels();
    let error = |img: &thinfilm::image_io::RgbImage| offset_and_rmse(img, &truth, &ball);
    let pooled = |plain: bool| pooled_rmse(|seed| error(&run(&scene, 64, seed, plain).0).1);
    let (rmse_plain, rmse_chains) = (pooled(true), pooled(false));
    assert!(
        rmse_chains < 0.75 * rmse_plain,
        "RMSE over the ball: eight wavelengths {rmse_chains} vs four {rmse_plain}"
    );
    assert_mean_within_noise(&run(&scene, 1024, 3, false).0, &truth, &ball);
    // A gold ball: its reflectance is smooth in wavelength, no chain.
    let mut gold = scene.clone();
    gold.bsdfs[0] = Conductor::new("Au".parse().unwrap(), 0.0, 0.0)
        .unwrap()
        .into();
    let lines = run(&gold, 1, 1, false).1;
    let want = "wavelength supersampling of specular chains: off — no smooth film or coating";
    assert_effect_line(&lines, want);
}

/// The pixels of a 24² render of the unit ball at the origin seen from 4 units away with a 40°
/// field of view ([`base_scene`]) that lie within 0.8 of its projected radius.
fn ball_pixels() -> Vec<usize> {
    (0..24 * 24)
        .filter(|i| {
            let (x, y) = ((i % 24) as f32 - 11.5, (i / 24) as f32 - 11.5);
            (x * x + y * y).sqrt() < 0.8 * 8.7
        })
        .collect()
}

/// Asserts that the mean of `img` over the pixels `at` equals `truth`'s within the noise:
/// `img`'s RMSE from it, over the square root of the values' count, bounds the mean offset
/// (bias included; `truth` a render of 4× the samples).
fn assert_mean_within_noise(
    img: &thinfilm::image_io::RgbImage,
    truth: &thinfilm::image_io::RgbImage,
    at: &[usize],
) {
    let (bias, rmse) = offset_and_rmse(img, truth, at);
    let bound = 4.0 * rmse / (3.0 * at.len() as f64).sqrt();
    assert!(
        bias.abs() < bound,
        "mean offset {bias} (noise bound {bound})"
    );
}

/// The render log's effect lines for `scene` prepared with `options`.
fn effect_lines(scene: &Scene, options: &RenderOptions) -> Vec<String> {
    let prepared = thinfilm::render::prepare(scene, options).unwrap();
    prepared.effects().lines()
}

/// Asserts that one of the render log's effect lines `lines` starts with `want`.
fn assert_effect_line(lines: &[String], want: &str) {
    assert!(lines.iter().any(|l| l.starts_with(want)), "{lines:?}");
}

/// The RMSE pooled over seeds 2–5 (the root of the mean squared `rmse(seed)`).
fn pooled_rmse(rmse: impl Fn(u64) -> f64) -> f64 {
    let sq: f64 = (2..6).map(|seed| rmse(seed).powi(2)).sum();
    (sq / 4.0).sqrt()
}

/// Mean difference and RMSE of `img` from `truth` over the pixels `at` (all channels).
fn offset_and_rmse(
    img: &thinfilm::image_io::RgbImage,
    truth: &thinfilm::image_io::RgbImage,
    at: &[usize],
) -> (f64, f64) {
    let (mut mean, mut sq) = (0.0f64, 0.0f64);
    for &i in at {
        for c in 0..3 {
            let d = (img.pixels[i][c] - truth.pixels[i][c]) as f64;
            mean += d;
            sq += d * d;
        }
    }
    let n = (3 * at.len()) as f64;
    (mean / n, (sq / n).sqrt())
}

fn bits_of(p: &[f32; 3]) -> [u32; 3] {
    p.map(f32::to_bits)
}

/// An area light seen straight from the camera takes its closed-form colour: the pixels it
/// fully covers are the same for every seed (no colour noise), equal to the mean of a
/// wavelength-sampled render; seen from behind (one-sided emission) it stays black.
#[test]
fn area_light_seen_directly_takes_its_closed_form_colour() {
    let quad = Shape {
        geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            normals: vec![],
            uvs: vec![],
            // Facing −z, towards the camera at z = −4.
            indices: vec![[0, 2, 1], [0, 3, 2]],
        })),
        bsdf: 0,
        emission: Some(SpectrumDesc::Rgb([3.0, 1.0, 0.2])),
        name: Some("panel".into()),
    };
    let mut scene = base_scene(
        vec![quad],
        vec![Bsdf::from(Diffuse::new(&constant(0.0)))],
        vec![],
        9,
        64,
    );
    scene.sampler = SamplerKind::Independent;
    let centre = |scene: &Scene, spp: u32, seed: u64, spectral: bool| {
        let options = RenderOptions {
            spp: Some(spp),
            seed: Some(seed),
            spectral_direct_view: spectral,
            ..Default::default()
        };
        let img = render(scene, &options).unwrap().image;
        img.pixels[(img.height / 2) * img.width + img.width / 2]
    };
    let (a, b) = (centre(&scene, 64, 1, false), centre(&scene, 64, 2, false));
    assert_eq!(bits_of(&a), bits_of(&b), "closed form: {a:?} vs {b:?}");
    let (sa, sb) = (centre(&scene, 64, 1, true), centre(&scene, 64, 2, true));
    assert_ne!(
        bits_of(&sa),
        bits_of(&sb),
        "sampled wavelengths have colour noise"
    );
    let truth = centre(&scene, 4096, 3, true);
    for c in 0..3 {
        assert!(
            (a[c] - truth[c]).abs() < 0.01 * truth[0],
            "{a:?} vs {truth:?}"
        );
    }
    // Its linear-sRGB round trip: (3, 1, 0.2) within 1 %.
    for (v, want) in a.iter().zip([3.0, 1.0, 0.2]) {
        assert!((v - want).abs() < 0.01 * 3.0, "{a:?}");
    }
    scene.camera = camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 40.0);
    assert_eq!(centre(&scene, 16, 1, false), [0.0; 3]);
}

/// Adaptive sample counts on the Cornell box, whose error at uniform counts lies almost all
/// along the outline of the light seen directly: a 1024-spp adaptive render keeps the mean of
/// an 8192-spp uniform one within the noise, and at 64 spp the pooled RMSE falls below 0.6× the
/// uniform render's (measured: 0.50×) for at most 30 % more work (rays traced: measured
/// 1.23×: every pixel's 64 samples and extra ones).
#[test]
fn adaptive_sample_counts_keep_the_mean_and_cut_the_error_at_a_lights_edge() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.xml");
    let scene = thinfilm::scene::load(&path, &[("res".into(), "32".into())]).unwrap();
    let run = |spp: u32, seed: u64, uniform: bool| {
        let options = RenderOptions {
            spp: Some(spp),
            seed: Some(seed),
            uniform_samples: uniform,
            ..Default::default()
        };
        let lines = effect_lines(&scene, &options);
        let want = match uniform {
            true => "adaptive sample counts: off — the same count in every pixel asked for",
            false => "adaptive sample counts: ON",
        };
        assert_effect_line(&lines, want);
        let out = render(&scene, &options).unwrap();
        assert_eq!(out.adaptive, !uniform);
        let every_pixel = out.image.pixels.len() as u64 * spp as u64;
        assert!(out.stats.samples > every_pixel || uniform && out.stats.samples == every_pixel);
        out
    };
    let truth = run(8192, 1, true).image;
    let all: Vec<usize> = (0..truth.pixels.len()).collect();
    assert_mean_within_noise(&run(1024, 3, false).image, &truth, &all);
    let rays = |o: &thinfilm::render::RenderOutput| (o.stats.rays + o.stats.shadow_rays) as f64;
    let traced = [std::cell::Cell::new(0.0), std::cell::Cell::new(0.0)];
    let pooled = |uniform: bool| {
        pooled_rmse(|seed| {
            let out = run(64, seed, uniform);
            let total = &traced[uniform as usize];
            total.set(total.get() + rays(&out));
            offset_and_rmse(&out.image, &truth, &all).1
        })
    };
    let (uniform, adaptive) = (pooled(true), pooled(false));
    assert!(adaptive < 0.6 * uniform, "RMSE {adaptive} vs {uniform}");
    let work = traced[0].get() / traced[1].get();
    assert!(
        (1.0..1.3).contains(&work),
        "rays {work}× the uniform render's"
    );
}

/// Adaptive counts are switched off, saying why, where they cannot apply: a sample range (pieces
/// to merge), a filter wider than a pixel, too few samples, or when asked.
#[test]
fn adaptive_sample_counts_say_why_they_are_off() {
    let scene = film_scene(8, 16);
    let lines = |options: RenderOptions| effect_lines(&scene, &options);
    let on = lines(RenderOptions::default());
    assert_effect_line(
        &on,
        "adaptive sample counts: ON — 16 samples in every pixel",
    );
    let range = lines(RenderOptions {
        sample_range: Some((0, 16)),
        ..Default::default()
    });
    assert_effect_line(&range, "adaptive sample counts: off — a sample range");
    let few = lines(RenderOptions {
        spp: Some(4),
        ..Default::default()
    });
    assert_effect_line(&few, "adaptive sample counts: off — 4 samples per pixel");
    let mut gaussian = scene.clone();
    gaussian.film.filter = ReconstructionFilter::Gaussian { stddev: 0.5 };
    let wide = effect_lines(&gaussian, &RenderOptions::default());
    assert_effect_line(&wide, "adaptive sample counts: off — the gaussian filter");
    // Off, every pixel holds the same count: the image is that of the explicit range 0:16.
    let uniform = RenderOptions {
        uniform_samples: true,
        threads: Some(1),
        ..Default::default()
    };
    let explicit = RenderOptions {
        sample_range: Some((0, 16)),
        threads: Some(2),
        ..Default::default()
    };
    let (a, b) = (
        render(&scene, &uniform).unwrap(),
        render(&scene, &explicit).unwrap(),
    );
    assert_eq!(bits(&a.image), bits(&b.image));
}
