//! Mitsuba's `mesh_attribute` texture wherever a BSDF takes a texture: PLY vertex and face
//! attributes named as Mitsuba's PLY loader names them (`color_0..2` → `vertex_color` /
//! `face_color`, `weight_0` → `face_weight`), face attributes constant over each triangle,
//! vertex attributes interpolated, and clear errors for what cannot be drawn.

use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};
use thinfilm::render::bsdf::{BsdfFlags, ShadingCtx};
use thinfilm::scene::mitsuba::load_str;
use thinfilm::scene::{Geometry, Scene};
use thinfilm::spectrum::SampledWavelengths;

/// Two triangles sharing an edge, with per-vertex `color_*` and per-face `color_*` and
/// `weight_0` properties (ASCII PLY).
fn write_ply(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("quad.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         property float color_0\nproperty float color_1\nproperty float color_2\n\
         element face 2\nproperty list uchar int vertex_indices\n\
         property float color_0\nproperty float color_1\nproperty float color_2\nproperty float weight_0\nend_header\n\
         0 0 0 1 0 0\n1 0 0 0 1 0\n1 1 0 0 0 1\n0 1 0 0.5 0.5 0.5\n\
         3 0 1 2 0.9 0.1 0.1 0.2\n3 0 2 3 0.1 0.1 0.9 0.8\n",
    )
    .unwrap();
    path
}

fn load(dir: &Path, texture: &str, bsdf: &str) -> anyhow::Result<Scene> {
    let xml = format!(
        r#"<scene version="3.0.0">{texture}<shape type="ply"><string name="filename" value="quad.ply"/>{bsdf}</shape></scene>"#
    );
    load_str(&xml, dir, &[], "attr.xml")
}

fn mesh(s: &Scene) -> &thinfilm::scene::TriangleMesh {
    match &s.shapes[0].geometry {
        Geometry::Mesh(m) => m,
        _ => panic!("not a mesh"),
    }
}

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("thinfilm_{name}_{}", std::process::id()))
}

/// A face attribute on a rough plastic's diffuse reflectance (not a `diffuse` BSDF): every
/// triangle gets its own vertices carrying its face's colour, so the interpolated colour is
/// constant over the face; positions and triangles are unchanged.
#[test]
fn face_colors_are_constant_per_triangle_on_any_bsdf() {
    let dir = tmp("face_attr");
    write_ply(&dir);
    let tex = r#"<texture type="mesh_attribute" id="t"><string name="name" value="face_color"/></texture>"#;
    let s = load(
        &dir,
        tex,
        r#"<bsdf type="roughplastic"><ref name="diffuse_reflectance" id="t"/></bsdf>"#,
    )
    .unwrap();
    let m = mesh(&s);
    assert_eq!((m.indices.len(), m.positions.len()), (2, 6));
    for (k, want) in [Vec3::new(0.9, 0.1, 0.1), Vec3::new(0.1, 0.1, 0.9)]
        .into_iter()
        .enumerate()
    {
        for v in m.indices[k] {
            assert!((m.colors[v as usize] - want).abs().max_element() < 1e-6);
        }
    }
    assert!(s.bsdfs[s.shapes[0].bsdf]
        .flags()
        .contains(BsdfFlags::VERTEX_COLOR));
    // The same mesh read by a vertex attribute keeps its shared vertices.
    let tex = r#"<texture type="mesh_attribute" id="t"><string name="name" value="vertex_color"/></texture>"#;
    let s = load(
        &dir,
        tex,
        r#"<bsdf type="conductor"><ref name="specular_reflectance" id="t"/></bsdf>"#,
    )
    .unwrap();
    let m = mesh(&s);
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.colors[2], Vec3::new(0.0, 0.0, 1.0));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A one-channel face attribute as a blend weight (Mitsuba's `eval_1`): the blend of a black
/// and a white diffuse reflects the weight.
#[test]
fn scalar_face_attribute_weights_a_blend() {
    let dir = tmp("face_weight");
    write_ply(&dir);
    let tex = r#"<texture type="mesh_attribute" id="t"><string name="name" value="face_weight"/></texture>"#;
    let s = load(
        &dir,
        tex,
        r#"<bsdf type="blendbsdf"><ref name="weight" id="t"/><bsdf type="diffuse"><float name="reflectance" value="0"/></bsdf><bsdf type="diffuse"><float name="reflectance" value="1"/></bsdf></bsdf>"#,
    )
    .unwrap();
    let m = mesh(&s);
    let b = &s.bsdfs[s.shapes[0].bsdf];
    let wl = SampledWavelengths::new([450.0, 520.0, 600.0, 680.0], [1.0; 4]);
    let (wi, wo) = (Vec3::Z, Vec3::Z);
    for (k, w) in [(0usize, 0.2f32), (1, 0.8)] {
        let ctx = ShadingCtx {
            wl: &wl,
            uv: Vec2::ZERO,
            segment: 0.0,
            color: m.colors[m.indices[k][0] as usize],
            bump_normal: glam::Vec3::Z,
        };
        let f = b.eval(&ctx, wi, wo)[0] * std::f32::consts::PI;
        assert!((f - w).abs() < 1e-5, "triangle {k}: {f} vs {w}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn unusable_attributes_are_refused_with_their_names() {
    let dir = tmp("attr_errors");
    write_ply(&dir);
    let tex = |name: &str| {
        format!(
            r#"<texture type="mesh_attribute" id="t"><string name="name" value="{name}"/></texture>"#
        )
    };
    let diffuse = r#"<bsdf type="diffuse"><ref name="reflectance" id="t"/></bsdf>"#;
    for (texture, bsdf, want) in [
        (tex("face_normal"), diffuse, "no attribute \"face_normal\""),
        (
            tex("colour"),
            diffuse,
            "must start with \"vertex_\" or \"face_\"",
        ),
        (
            tex("face_color")
                + r#"<texture type="mesh_attribute" id="u"><string name="name" value="vertex_color"/></texture>"#,
            diffuse,
            "supports one per scene",
        ),
    ] {
        let e = format!("{:#}", load(&dir, &texture, bsdf).unwrap_err());
        assert!(e.contains(want) && e.contains("attr.xml:1:"), "{e}");
    }
    // A sphere has no mesh attributes (Mitsuba fails on it too).
    let xml = format!(
        r#"<scene version="3.0.0">{}<shape type="sphere">{diffuse}</shape></scene>"#,
        tex("vertex_color")
    );
    let e = format!("{:#}", load_str(&xml, &dir, &[], "attr.xml").unwrap_err());
    assert!(e.contains("vertex_color") && e.contains("sphere"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
