//! Camera rays through the screen bins (`render::primary`) find the BVH's hit: on the
//! committed teapot, inside a room whose floor and walls cross the camera plane, with an
//! edge-on triangle and analytic spheres; the bins step aside where they would not pay; and a
//! render with the bins equals one without.

use glam::{Vec2, Vec3};
use std::path::Path;
use thinfilm::render::accel::{Hit, Prim};
use thinfilm::render::bsdf::{diffuse::Diffuse, Bsdf};
use thinfilm::render::primary::{PrimaryBins, MAX_CROSSING};
use thinfilm::render::{prepare, render_prepared, PreparedScene, RenderOptions};
use thinfilm::scene::*;

fn options(res: u32, spp: u32) -> RenderOptions {
    RenderOptions {
        resolution: Some((res, res)),
        spp: Some(spp),
        threads: Some(1),
        ..Default::default()
    }
}

fn teapot(res: u32, spp: u32) -> PreparedScene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot_mgf2_400.xml");
    let scene = load(&path, &[]).expect("teapot scene loads");
    prepare(&scene, &options(res, spp)).expect("teapot prepares")
}

fn prim_id(h: &Hit) -> (u8, u32) {
    match h.prim {
        Prim::Triangle(i) => (0, i),
        Prim::Sphere(i) => (1, i),
    }
}

/// Casts `per_pixel` camera rays per pixel (corners of the pixel included) through the bins
/// and through the BVH; every pair must agree on the distance (and on the primitive unless
/// two primitives are hit at exactly the same distance). Returns (hits, ties).
fn compare_with_bvh(p: &PreparedScene, bins: &PrimaryBins, per_pixel: u32) -> (usize, usize) {
    let size = Vec2::new(p.width() as f32, p.height() as f32);
    let (mut hits, mut ties) = (0, 0);
    let mut state = 0x9e37_79b9u32;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / 16_777_216.0
    };
    for y in 0..p.height() {
        for x in 0..p.width() {
            for k in 0..per_pixel {
                let jitter = match k {
                    0 => Vec2::ZERO,
                    1 => Vec2::splat(0.999_999_9),
                    2 => Vec2::new(0.0, 0.999_999_9),
                    _ => Vec2::new(next(), next()),
                };
                let pos = Vec2::new(x as f32, y as f32) + jitter;
                let ray = p.camera().generate_ray(pos / size);
                let a = bins.intersect(p.accel(), x, y, &ray);
                let b = p.accel().intersect(&ray);
                match (a, b) {
                    (None, None) => {}
                    (Some(a), Some(b)) => {
                        assert_eq!(
                            a.t.to_bits(),
                            b.t.to_bits(),
                            "pixel ({x}, {y}) at {pos}: bins t = {} ({:?}), BVH t = {} ({:?})",
                            a.t,
                            a.prim,
                            b.t,
                            b.prim
                        );
                        hits += 1;
                        if prim_id(&a) != prim_id(&b) {
                            ties += 1;
                        }
                    }
                    _ => panic!("pixel ({x}, {y}) at {pos}: bins {a:?}, BVH {b:?}"),
                }
            }
        }
    }
    (hits, ties)
}

#[test]
fn teapot_camera_rays_find_the_bvh_hit() {
    let p = teapot(64, 64);
    let bins = p.primary_bins().expect("bins for the teapot");
    let stats = bins.stats();
    assert_eq!(stats.crossing, 0);
    assert!(stats.candidates > 0);
    let (hits, ties) = compare_with_bvh(&p, bins, 12);
    // The teapot covers about a third of the image; ties (a ray exactly on an edge) are rare.
    assert!(hits > 64 * 64 * 12 / 5, "{hits} hits");
    assert!(ties * 1000 < hits, "{ties} ties of {hits}");
}

fn quad(corners: [Vec3; 4], bsdf: usize, name: &str) -> Shape {
    Shape {
        geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions: corners.to_vec(),
            normals: vec![],
            uvs: vec![],
            indices: vec![[0, 1, 2], [0, 2, 3]],
        })),
        bsdf,
        emission: None,
        name: Some(name.into()),
    }
}

fn room(extra: Vec<Shape>) -> Scene {
    let s = 20.0;
    let mut shapes = vec![
        // Floor and ceiling run far behind the camera: their triangles cross its plane.
        quad(
            [
                Vec3::new(-s, -1.0, -s),
                Vec3::new(s, -1.0, -s),
                Vec3::new(s, -1.0, s),
                Vec3::new(-s, -1.0, s),
            ],
            0,
            "floor",
        ),
        quad(
            [
                Vec3::new(-s, 3.0, -s),
                Vec3::new(-s, 3.0, s),
                Vec3::new(s, 3.0, s),
                Vec3::new(s, 3.0, -s),
            ],
            0,
            "ceiling",
        ),
        // Back wall in front of the camera.
        quad(
            [
                Vec3::new(-s, -1.0, 8.0),
                Vec3::new(-s, 3.0, 8.0),
                Vec3::new(s, 3.0, 8.0),
                Vec3::new(s, -1.0, 8.0),
            ],
            0,
            "wall",
        ),
        // Edge-on from the pinhole (its plane y = 0 contains the camera): projects to a line.
        Shape {
            geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
                colors: Vec::new(),
                tangents: Vec::new(),
                positions: vec![
                    Vec3::new(-0.5, 0.0, 3.0),
                    Vec3::new(0.5, 0.0, 3.0),
                    Vec3::new(0.0, 0.0, 4.0),
                ],
                normals: vec![],
                uvs: vec![],
                indices: vec![[0, 1, 2]],
            })),
            bsdf: 0,
            emission: None,
            name: Some("edge-on".into()),
        },
        Shape {
            geometry: Geometry::Sphere {
                center: Vec3::new(1.0, 0.0, 5.0),
                radius: 0.7,
                rotation: glam::Mat3::IDENTITY,
                flip_normals: false,
            },
            bsdf: 0,
            emission: None,
            name: Some("ball".into()),
        },
    ];
    shapes.extend(extra);
    Scene {
        camera: Camera {
            to_world: look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, 1.0), Vec3::Y),
            fov_deg: 70.0,
            projection: thinfilm::scene::Projection::Perspective,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 1000.0,
        },
        film: FilmSettings {
            width: 40,
            height: 40,
            filter: ReconstructionFilter::Box,
        },
        integrator: IntegratorSettings::default(),
        spp: 4,
        seed: 0,
        sampler: SamplerKind::default(),
        shapes,
        bsdfs: vec![Bsdf::from(Diffuse::new(&TextureDesc::Value(
            SpectrumDesc::Constant(0.5),
        )))],
        emitters: vec![EmitterDesc::Constant {
            radiance: SpectrumDesc::Constant(1.0),
        }],
        polarizer: None,
        source: None,
        media: None,
    }
}

#[test]
fn room_with_geometry_crossing_the_camera_plane() {
    let p = prepare(&room(vec![]), &options(40, 4)).unwrap();
    let bins = p.primary_bins().expect("bins for the room");
    // Floor and ceiling: two triangles each cross the camera plane.
    assert_eq!(bins.stats().crossing, 4);
    let (hits, _) = compare_with_bvh(&p, bins, 16);
    // Every ray hits something in a closed-enough room.
    assert!(hits > 40 * 40 * 16 * 9 / 10, "{hits} hits");
}

#[test]
fn bins_step_aside_when_many_triangles_cross_the_camera_plane() {
    // A fan of small triangles around the camera, each straddling its plane.
    let n = MAX_CROSSING + 8;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for i in 0..n {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        let (s, c) = a.sin_cos();
        let base = positions.len() as u32;
        positions.extend([
            Vec3::new(2.0 * c, 2.0 * s, -0.5),
            Vec3::new(2.1 * c, 2.1 * s, 0.5),
            Vec3::new(2.0 * c + 0.1 * s, 2.0 * s - 0.1 * c, 0.5),
        ]);
        indices.push([base, base + 1, base + 2]);
    }
    let fan = Shape {
        geometry: Geometry::Mesh(std::sync::Arc::new(TriangleMesh {
            colors: Vec::new(),
            tangents: Vec::new(),
            positions,
            normals: vec![],
            uvs: vec![],
            indices,
        })),
        bsdf: 0,
        emission: None,
        name: Some("fan".into()),
    };
    let p = prepare(&room(vec![fan]), &options(40, 4)).unwrap();
    assert!(p.primary_bins().is_none());
    // The render still works (through the BVH).
    let out = render_prepared(&p, &options(40, 4)).unwrap();
    assert!(out.image.pixels.iter().flatten().all(|v| v.is_finite()));
}

/// Too few camera rays per triangle to pay for binning (a 64² one-sample preview of the 36k
/// teapot: 4096 rays): no bins, and they come back at 64 samples per pixel.
#[test]
fn bins_step_aside_for_few_camera_rays_per_triangle() {
    assert!(teapot(64, 1).primary_bins().is_none());
    assert!(teapot(64, 64).primary_bins().is_some());
}

/// The bins are an acceleration only: the image is the BVH-only image.
#[test]
fn render_with_bins_equals_render_without() {
    let with = teapot(48, 64);
    assert!(with.primary_bins().is_some());
    let mut without = teapot(48, 64);
    without.use_bvh_for_camera_rays();
    let a = render_prepared(&with, &options(48, 64)).unwrap();
    let b = render_prepared(&without, &options(48, 64)).unwrap();
    assert_eq!(a.stats.rays, b.stats.rays);
    let differing = a
        .image
        .pixels
        .iter()
        .zip(&b.image.pixels)
        .filter(|(p, q)| {
            p.iter()
                .zip(q.iter())
                .any(|(x, y)| x.to_bits() != y.to_bits())
        })
        .count();
    // Only a ray exactly on an edge shared by two triangles can pick the other triangle.
    assert!(differing <= 2, "{differing} pixels differ");
    for (p, q) in a.image.pixels.iter().zip(&b.image.pixels) {
        for (x, y) in p.iter().zip(q) {
            assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{x} vs {y}");
        }
    }
}
