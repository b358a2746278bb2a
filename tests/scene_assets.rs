//! The project's own assets (teapot, studio environment, thickness map) and every scene in
//! `scenes/` loading.

use glam::Vec3;
use std::collections::HashMap;
use std::path::Path;
use thinfilm::scene::*;

#[test]
fn teapot_mesh_sanity() {
    let m = teapot::teapot_mesh(teapot::DEFAULT_SUBDIVISIONS);
    assert_eq!(m.indices.len(), 36_672);
    m.validate("teapot").unwrap();
    let (lo, hi) = m.bounds().unwrap();
    // Newell's data: handle to spout tip −3 … 3.434, height 3.15, body radius 2.
    assert!((lo - Vec3::new(-3.0, 0.0, -2.0)).length() < 1e-3, "{lo}");
    assert!((hi - Vec3::new(3.434, 3.15, 2.0)).length() < 1e-2, "{hi}");
    assert!(m.positions.iter().all(|p| p.is_finite()));
    assert!(m
        .normals
        .iter()
        .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-4));
    assert!(m
        .uvs
        .iter()
        .all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y)));
    // Outward orientation: positive volume, and face normals agree with smooth normals.
    assert!(teapot::signed_volume(&m) > 20.0);
    let agree = m
        .indices
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let g = (b - a).cross(c - a).normalize();
            t.iter().all(|&i| g.dot(m.normals[i as usize]) > 0.0)
        })
        .count();
    assert!(agree as f64 > 0.995 * m.indices.len() as f64, "{agree}");
    // Watertight-ish: after welding positions, almost every edge is shared by two triangles.
    // (Newell's teapot has open seams where the lid meets the rim and the spout/handle meet
    // the body.)
    let key = |p: Vec3| {
        let q = (p * 1e4).round();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    type Key = (i64, i64, i64);
    let mut edges: HashMap<(Key, Key), u32> = HashMap::new();
    for t in &m.indices {
        for k in 0..3 {
            let (a, b) = (
                key(m.positions[t[k] as usize]),
                key(m.positions[t[(k + 1) % 3] as usize]),
            );
            *edges
                .entry(if a < b { (a, b) } else { (b, a) })
                .or_default() += 1;
        }
    }
    let open = edges.values().filter(|&&c| c == 1).count();
    assert!(
        (open as f64) < 0.03 * edges.len() as f64,
        "{open} of {}",
        edges.len()
    );
}

#[test]
fn committed_teapot_matches_generator() {
    let m = meshio::load_ply(Path::new("scenes/meshes/teapot.ply")).unwrap();
    let g = teapot::teapot_mesh(teapot::DEFAULT_SUBDIVISIONS);
    assert_eq!(m.indices, g.indices);
    assert_eq!(m.positions, g.positions);
    assert_eq!(m.normals, g.normals);
}

#[test]
fn studio_environment_sanity() {
    let img = load_rgb_image(Path::new("scenes/textures/studio.exr")).unwrap();
    let (w, h) = sky::STUDIO_SIZE;
    assert_eq!((img.width, img.height), (w, h));
    assert!(img
        .pixels
        .iter()
        .flatten()
        .all(|v| v.is_finite() && *v > 0.0));
    assert_eq!(
        img.pixels,
        sky::studio_environment(w, h).pixels,
        "regenerate with make_assets"
    );
    // The brightest texel is the sun, 40° above the horizon.
    let (imax, _) = img
        .pixels
        .iter()
        .enumerate()
        .max_by(|a, b| a.1[1].total_cmp(&b.1[1]))
        .unwrap();
    let d = sky::texel_direction(imax % w, imax / w, w, h);
    let sun = sky::direction_from_angles(45.0, 40.0);
    assert!(d.dot(sun) > 0.999, "{d}");
    // Sky above is brighter than the ground below.
    let row_mean = |i: usize| {
        img.pixels[i * w..(i + 1) * w]
            .iter()
            .map(|p| p[1])
            .sum::<f32>()
            / w as f32
    };
    assert!(row_mean(h / 4) > 3.0 * row_mean(3 * h / 4));
    assert!(
        std::fs::metadata("scenes/textures/studio.exr")
            .unwrap()
            .len()
            < 1_500_000
    );
}

#[test]
fn thickness_example_map() {
    let t = BitmapTexture::load(Path::new("scenes/textures/thickness_example.exr"), true).unwrap();
    assert_eq!((t.width, t.height, t.channels), (256, 256, 1));
    let (lo, hi) = t.value_bounds().unwrap();
    assert!(lo > 200.0 && hi < 700.0 && hi - lo > 200.0, "{lo}..{hi}");
}

#[test]
fn every_scene_loads() {
    let mut n = 0;
    for entry in std::fs::read_dir("scenes").unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "xml") {
            continue;
        }
        let defaults = [
            ("spp".to_string(), "4".to_string()),
            ("res".to_string(), "32".to_string()),
        ];
        let s = load(&path, &defaults).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        assert_eq!(
            (s.spp, s.film.width, s.film.height),
            (4, 32, 32),
            "{}",
            path.display()
        );
        assert_eq!(s.film.filter, ReconstructionFilter::Box);
        assert_eq!(s.integrator.max_depth, 8);
        // Lit by the studio environment, or (the area-light scenes) by emitting shapes only.
        let area_lit = s.shapes.iter().any(|sh| sh.emission.is_some());
        assert!(
            matches!(s.emitters.as_slice(), [EmitterDesc::Envmap { .. }])
                || (area_lit && s.emitters.is_empty()),
            "{}: unexpected lighting",
            path.display()
        );
        assert!(!s.shapes.is_empty());
        if path.ends_with("teapot_gold.xml") {
            assert!(
                matches!(&s.bsdfs[s.shapes[0].bsdf], thinfilm::render::bsdf::Bsdf::Conductor(c) if matches!(c.eta, thinfilm::optics::Ior::Material(m) if m.name == "Au"))
            );
        }
        // The camera sees the geometry's centre.
        let (lo, hi) = shapes_bounds(&s.shapes).unwrap();
        let eye = s.camera.to_world.transform_point3(Vec3::ZERO);
        let fwd = s.camera.to_world.transform_vector3(Vec3::Z).normalize();
        assert!(
            ((lo + hi) * 0.5 - eye).normalize().dot(fwd) > 0.95,
            "{}",
            path.display()
        );
        n += 1;
    }
    assert!(
        n >= 7,
        "expected at least the 7 teapot/plane scenes, found {n}"
    );
}

#[test]
fn camera_matches_mitsuba() {
    // Mitsuba 3.9.1: mi.load_file("scenes/teapot_diffuse.xml").sensors()[0].world_transform()
    let s = load(Path::new("scenes/teapot_diffuse.xml"), &[]).unwrap();
    let mitsuba_rows = [
        [-0.934784, -0.129815, -0.330647, 4.0],
        [0.0, 0.93083, -0.365452, 5.5],
        [0.355218, -0.341619, -0.870125, 10.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let m = s.camera.to_world;
    for (r, row) in mitsuba_rows.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            assert!(
                (m.col(c)[r] - v).abs() < 1e-5,
                "({r},{c}): {} vs {v}",
                m.col(c)[r]
            );
        }
    }
    assert_eq!((s.spp, s.film.width), (64, 256));
}
