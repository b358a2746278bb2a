//! glTF (with KHR_materials_iridescence), OBJ, PLY (ascii + binary) and format dispatch.

use glam::{Vec2, Vec3};
use std::path::Path;
use thinfilm::render::bsdf::Bsdf;
use thinfilm::scene::*;

/// A one-triangle glTF with an iridescent material, a thickness texture (G = 128) and a
/// perspective camera; buffer and image as files beside it.
fn write_gltf(dir: &Path, iridescent: bool) -> std::path::PathBuf {
    let positions: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let uvs: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    let mut bin: Vec<u8> = Vec::new();
    for p in positions.iter().flatten().chain(uvs.iter().flatten()) {
        bin.extend_from_slice(&p.to_le_bytes());
    }
    std::fs::write(dir.join("tri.bin"), &bin).unwrap();
    image::RgbImage::from_pixel(2, 2, image::Rgb([10, 128, 250]))
        .save(dir.join("thick.png"))
        .unwrap();
    let material = if iridescent {
        r#"{"name": "film",
            "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.2, 0.2, 1], "metallicFactor": 0, "roughnessFactor": 0.3},
            "extensions": {
              "KHR_materials_ior": {"ior": 1.45},
              "KHR_materials_iridescence": {"iridescenceFactor": 1.0, "iridescenceIor": 1.8,
                 "iridescenceThicknessMinimum": 200, "iridescenceThicknessMaximum": 800,
                 "iridescenceThicknessTexture": {"index": 0}}}}"#
    } else {
        r#"{"name": "metal", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 1, "roughnessFactor": 0.5}}"#
    };
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_ior", "KHR_materials_iridescence"],
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0, "translation": [0, 0, -2]}},
    {{"camera": 0, "translation": [0, 0, 3]}}
  ],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.5, "znear": 0.1, "zfar": 100, "aspectRatio": 2.0}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "material": 0}}]}}],
  "materials": [{material}],
  "textures": [{{"source": 0, "sampler": 0}}],
  "samplers": [{{"wrapS": 33071, "wrapT": 33071}}],
  "images": [{{"uri": "thick.png"}}],
  "buffers": [{{"uri": "tri.bin", "byteLength": {len}}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 24}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}}
  ]
}}"#,
        len = bin.len()
    );
    let path = dir.join("tri.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

#[test]
fn gltf_iridescence_camera_and_transforms() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(dir.path(), true);
    let s = load(&path, &[]).unwrap();
    assert_eq!(s.shapes.len(), 1);
    let Geometry::Mesh(m) = &s.shapes[0].geometry else {
        panic!()
    };
    assert_eq!(m.positions[1], Vec3::new(1.0, 0.0, -2.0));
    assert_eq!(m.uvs[2], Vec2::new(0.0, 1.0));
    assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    match &s.bsdfs[s.shapes[0].bsdf] {
        Bsdf::GltfPbr(p) => {
            let m = &p.material;
            let film = m.iridescence.as_ref().unwrap();
            let b = film.thickness_texture.as_ref().unwrap();
            assert_eq!((film.ior, film.factor), (1.8, 1.0));
            assert_eq!((m.ior, m.roughness, m.metallic), (1.45, 0.3, 0.0));
            assert_eq!(
                (film.thickness_min_nm, film.thickness_max_nm),
                (200.0, 800.0)
            );
            assert_eq!(b.wrap, WrapMode::Clamp);
            // G = 128/255 (the thickness lives in G; min + G·(max − min) nm).
            let g = b.eval(Vec2::new(0.3, 0.7))[1];
            assert!((g - 128.0 / 255.0).abs() < 1e-6, "{g}");
        }
        b => panic!("{b:?}"),
    }
    // Camera at z = 3 looking down −Z (Mitsuba frame: local +Z maps to world −Z).
    let fwd = s.camera.to_world.transform_vector3(Vec3::Z);
    assert!((fwd + Vec3::Z).length() < 1e-6, "{fwd}");
    assert!(
        (s.camera.to_world.transform_point3(Vec3::ZERO) - Vec3::new(0.0, 0.0, 3.0)).length() < 1e-6
    );
    assert_eq!(s.camera.fov_axis, FovAxis::Y);
    assert!((s.camera.fov_deg - 0.5f32.to_degrees()).abs() < 1e-4);
    assert_eq!((s.film.width, s.film.height), (1024, 512));
    assert!(matches!(&s.emitters[0], EmitterDesc::Envmap { .. }));
}

#[test]
fn gltf_metal_and_default_camera() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_gltf(dir.path(), false);
    let s = load(&path, &[]).unwrap();
    match &s.bsdfs[0] {
        Bsdf::GltfPbr(p) => {
            let m = &p.material;
            assert_eq!(m.base_color, [0.5, 0.5, 0.5, 1.0]);
            assert_eq!((m.metallic, m.roughness), (1.0, 0.5));
            assert!(m.iridescence.is_none());
        }
        b => panic!("{b:?}"),
    }
    // Malformed glTF → error naming the file.
    std::fs::write(dir.path().join("bad.gltf"), "{not json").unwrap();
    let e = format!("{:#}", load(&dir.path().join("bad.gltf"), &[]).unwrap_err());
    assert!(e.contains("bad.gltf"), "{e}");
}

#[test]
fn obj_quad_with_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("quad.obj");
    std::fs::write(
        &p,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 0.25\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    let m = meshio::load_obj(&p).unwrap();
    assert_eq!(m.indices.len(), 2);
    assert_eq!(m.positions.len(), 4);
    // Mitsuba flips OBJ v.
    assert_eq!(m.uvs[3], Vec2::new(0.0, 0.75));
    assert!(m.normals.is_empty());
    // Standalone: default camera sees the mesh, default material and environment.
    let s = load(&p, &[]).unwrap();
    let Geometry::Mesh(m) = &s.shapes[0].geometry else {
        panic!()
    };
    assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    let to_center =
        (Vec3::new(0.5, 0.5, 0.0) - s.camera.to_world.transform_point3(Vec3::ZERO)).normalize();
    assert!(to_center.dot(s.camera.to_world.transform_vector3(Vec3::Z).normalize()) > 0.999);
    assert!(matches!(s.bsdfs[0], Bsdf::Diffuse(_)));
    assert_eq!(s.emitters.len(), 1);
    let e = format!("{:#}", load(&p, &[("spp".into(), "4".into())]).unwrap_err());
    assert!(e.contains("Mitsuba XML scenes only"), "{e}");
    std::fs::write(dir.path().join("empty.obj"), "v 0 0 0\n").unwrap();
    assert!(meshio::load_obj(&dir.path().join("empty.obj")).is_err());
}

#[test]
fn ply_ascii_and_binary() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.ply");
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         property float s\nproperty float t\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 0.25\n4 0 1 2 3\n",
    )
    .unwrap();
    let m = meshio::load_ply(&p).unwrap();
    assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(m.uvs[3], Vec2::new(0.0, 0.25), "PLY uvs are not flipped");
    // Binary round trip with normals and uvs.
    let mut mesh = shapes::cube();
    mesh.transform(&glam::Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)));
    let b = dir.path().join("b.ply");
    meshio::write_ply_binary(&b, &mesh).unwrap();
    let r = meshio::load_ply(&b).unwrap();
    assert_eq!(r.positions, mesh.positions);
    assert_eq!(r.normals, mesh.normals);
    assert_eq!(r.uvs, mesh.uvs);
    assert_eq!(r.indices, mesh.indices);
    let s = load(&b, &[]).unwrap();
    assert_eq!(s.shapes.len(), 1);
    // Out-of-range index and truncated data are errors, not panics.
    std::fs::write(
        dir.path().join("bad.ply"),
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 2\n",
    )
    .unwrap();
    let e = format!(
        "{:#}",
        meshio::load_ply(&dir.path().join("bad.ply")).unwrap_err()
    );
    assert!(e.contains("face 0 refers to vertex 1"), "{e}");
    let bytes = std::fs::read(&b).unwrap();
    std::fs::write(dir.path().join("trunc.ply"), &bytes[..bytes.len() - 7]).unwrap();
    assert!(meshio::load_ply(&dir.path().join("trunc.ply")).is_err());
}

#[test]
fn dispatch_errors() {
    let e = format!(
        "{:#}",
        load(Path::new("/nonexistent/scene.xml"), &[]).unwrap_err()
    );
    assert!(
        e.contains("/nonexistent/scene.xml") && e.contains("does not exist"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.blend");
    std::fs::write(&p, "").unwrap();
    let e = format!("{:#}", load(&p, &[]).unwrap_err());
    assert!(e.contains("unknown scene format"), "{e}");
}
