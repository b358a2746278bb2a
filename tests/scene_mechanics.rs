//! Mitsuba 3 XML mechanics as Mitsuba 3.9's parser (`src/core/parser.cpp`) implements them:
//! `<include>`, `<path>`, `<default>`/`$param`, forward `<ref>`s and `<alias>`, shapegroups
//! and instances, integrator wrappers, `direct`, serialized meshes, cylinders, image formats,
//! and Mitsuba's defaults where a parameter is omitted. Expected values quoted from Mitsuba
//! were printed by Mitsuba 3.9.1 (`llvm_ad_spectral` / `scalar_rgb`) on the same XML.

use flate2::write::ZlibEncoder;
use flate2::Compression;
use glam::{Mat4, Vec3};
use std::io::Write;
use std::path::Path;
use thinfilm::render::bsdf::microfacet::Microfacet;
use thinfilm::render::bsdf::roughness::Roughness;
use thinfilm::render::bsdf::Bsdf;
use thinfilm::scene::mitsuba::{load_file, load_str};
use thinfilm::scene::*;

/// A diffuse BSDF's reflectance, as described in the file.
fn reflectance(b: &Bsdf) -> TextureDesc {
    match b {
        Bsdf::Diffuse(d) => d.reflectance.desc(),
        b => panic!("not diffuse: {b:?}"),
    }
}

/// A constant, rough microfacet distribution.
fn constant(r: &Roughness) -> Microfacet {
    match r {
        Roughness::Constant(Some(m)) => *m,
        r => panic!("not a constant rough lobe: {r:?}"),
    }
}

fn wrap(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n")
}

fn load_in(dir: &Path, body: &str) -> anyhow::Result<Scene> {
    load_str(&wrap(body), dir, &[], "test.xml")
}

fn load(body: &str) -> anyhow::Result<Scene> {
    load_in(Path::new("."), body)
}

fn err_in(dir: &Path, body: &str) -> String {
    format!("{:#}", load_in(dir, body).unwrap_err())
}

fn err(body: &str) -> String {
    err_in(Path::new("."), body)
}

fn write(dir: &Path, name: &str, text: &str) {
    let p = dir.join(name);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
}

fn mesh(s: &Shape) -> &TriangleMesh {
    match &s.geometry {
        Geometry::Mesh(m) => m,
        g => panic!("not a mesh: {g:?}"),
    }
}

#[test]
fn include_splices_scenes_and_objects_and_refuses_cycles() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A scene fragment (its children are spliced in) with a default and a nested include
    // found next to it; and a bare object file included under a property name.
    write(
        d,
        "parts/shapes.xml",
        r#"<scene version="3.0.0">
             <default name="r" value="2"/>
             <include filename="more.xml"/>
             <shape type="sphere"><float name="radius" value="$r"/><ref id="mat"/></shape>
           </scene>"#,
    );
    write(
        d,
        "parts/more.xml",
        r#"<scene version="3.0.0"><shape type="rectangle"/></scene>"#,
    );
    write(
        d,
        "mat.xml",
        r#"<texture version="3.0.0" type="checkerboard"/>"#,
    );
    let s = load_in(
        d,
        r#"<bsdf type="diffuse" id="mat"><include filename="mat.xml" name="reflectance"/></bsdf>
           <include filename="parts/shapes.xml"/>"#,
    )
    .unwrap();
    assert_eq!(s.shapes.len(), 2);
    assert!(matches!(s.shapes[1].geometry, Geometry::Sphere { radius, .. } if radius == 2.0));
    assert!(matches!(
        reflectance(&s.bsdfs[s.shapes[1].bsdf]),
        TextureDesc::Checkerboard { .. }
    ));
    // A cycle names the chain; a missing file names where it looked.
    write(
        d,
        "a.xml",
        r#"<scene version="3.0.0"><include filename="b.xml"/></scene>"#,
    );
    write(
        d,
        "b.xml",
        r#"<scene version="3.0.0"><include filename="a.xml"/></scene>"#,
    );
    let e = err_in(d, r#"<include filename="a.xml"/>"#);
    assert!(
        e.contains("<include> cycle") && e.contains("a.xml → ") && e.contains("b.xml"),
        "{e}"
    );
    let e = err_in(d, r#"<include filename="nope.xml"/>"#);
    assert!(
        e.contains("'nope.xml' not found") && e.contains("searched"),
        "{e}"
    );
    // Errors inside an included file name that file and line.
    write(
        d,
        "bad.xml",
        "<scene version=\"3.0.0\">\n<shape type=\"torus\"/>\n</scene>",
    );
    let e = err_in(d, r#"<include filename="bad.xml"/>"#);
    assert!(e.contains("bad.xml:2:1") && e.contains("\"torus\""), "{e}");
    // Deep (non-cyclic) nesting stops at Mitsuba's limit of 15 files.
    for i in 0..20 {
        write(
            d,
            &format!("deep{i}.xml"),
            &format!(
                r#"<scene version="3.0.0"><include filename="deep{}.xml"/></scene>"#,
                i + 1
            ),
        );
    }
    write(d, "deep20.xml", r#"<scene version="3.0.0"/>"#);
    assert!(err_in(d, r#"<include filename="deep0.xml"/>"#).contains("deeper than 15"));
}

#[test]
fn path_adds_search_directories() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("scenes")).unwrap();
    std::fs::create_dir_all(d.join("common/meshes")).unwrap();
    thinfilm::scene::meshio::write_ply_binary(
        &d.join("common/meshes/tri.ply"),
        &TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        },
    )
    .unwrap();
    // `<path>` relative to the scene file; it also serves files named in included files
    // (Mitsuba resolves every plugin's file through the same resolver).
    write(
        d,
        "scenes/inc.xml",
        r#"<scene version="3.0.0"><shape type="ply"><string name="filename" value="meshes/tri.ply"/></shape></scene>"#,
    );
    let scene = d.join("scenes/s.xml");
    std::fs::write(
        &scene,
        wrap(r#"<include filename="inc.xml"/><path value="../common"/>"#),
    )
    .unwrap();
    let s = load_file(&scene, &[]).unwrap();
    assert_eq!(mesh(&s.shapes[0]).indices.len(), 1);
    // Without the <path>, the mesh is not found and the message lists the directories.
    std::fs::write(&scene, wrap(r#"<include filename="inc.xml"/>"#)).unwrap();
    let e = format!("{:#}", load_file(&scene, &[]).unwrap_err());
    assert!(e.contains("'meshes/tri.ply' not found"), "{e}");
    assert!(err_in(d, r#"<path value="no/such/dir"/>"#).contains("not found"));
    assert!(err(r#"<shape type="cube"><path value="."/></shape>"#).contains("child of the root"));
}

#[test]
fn parameters_substitute_like_mitsuba() {
    // Longest name first: $resx is not $res followed by "x".
    let s = load(
        r#"<default name="res" value="10"/><default name="resx" value="64"/>
           <sensor type="perspective"><film type="hdrfilm">
             <integer name="width" value="$resx"/><integer name="height" value="$res"/>
           </film></sensor>"#,
    )
    .unwrap();
    assert_eq!((s.film.width, s.film.height), (64, 10));
    // Substitution applies to every attribute (plugin types and names too); \$ escapes.
    let s = load(
        r#"<default name="kind" value="path"/><default name="n" value="max_depth"/>
           <integrator type="$kind"><integer name="$n" value="3"/></integrator>
           <texture type="bitmap" id="t"><string name="filename" value="\$x.png"/></texture>"#,
    );
    let e = format!("{:#}", s.unwrap_err());
    assert!(e.contains("'$x.png' not found"), "{e}");
    // A default inside an object applies from there on; a -D value wins over any default.
    let body = r#"<integrator type="path"><default name="d" value="2"/><integer name="max_depth" value="$d"/></integrator>"#;
    assert_eq!(load(body).unwrap().integrator.max_depth, 2);
    let o = [("d".to_string(), "7".to_string())];
    let s = load_str(&wrap(body), Path::new("."), &o, "t.xml").unwrap();
    assert_eq!(s.integrator.max_depth, 7);
    // A -D value that nothing declares or uses is an error (Mitsuba: "unused parameters").
    let o = [("q".to_string(), "1".to_string())];
    let e = format!(
        "{:#}",
        load_str(&wrap(body), Path::new("."), &o, "t.xml").unwrap_err()
    );
    assert!(
        e.contains("no parameter $q") && e.contains("declared: d"),
        "{e}"
    );
    assert!(err(r#"<default name="" value="1"/>"#).contains("must not be empty"));
}

#[test]
fn forward_references_aliases_and_nested_ids() {
    let s = load(
        r#"<shape type="cube"><ref id="later"/></shape>
           <shape type="sphere"><bsdf type="conductor" id="inner"/></shape>
           <shape type="rectangle"><ref id="inner"/></shape>
           <alias id="later" as="again"/>
           <shape type="disk"><ref id="again"/></shape>
           <bsdf type="diffuse" id="later"><rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>"#,
    )
    .unwrap();
    assert_eq!(s.shapes.len(), 4);
    assert!(matches!(
        reflectance(&s.bsdfs[s.shapes[0].bsdf]),
        TextureDesc::Value(SpectrumDesc::Rgb(c)) if c[2] == 0.3
    ));
    assert_eq!(s.shapes[0].bsdf, s.shapes[3].bsdf);
    assert_eq!(s.shapes[1].bsdf, s.shapes[2].bsdf);
    // The forward-referenced BSDF is built once, not again when the walk reaches it.
    assert_eq!(s.bsdfs.len(), 2);
    // A sampler, film or area emitter declared at the top level is used through <ref>.
    let s = load(
        r#"<sampler type="independent" id="smp"><integer name="sample_count" value="9"/></sampler>
           <emitter type="area" id="light"><float name="radiance" value="3"/></emitter>
           <sensor type="perspective"><ref id="smp"/></sensor>
           <shape type="rectangle"><ref id="light"/></shape>"#,
    )
    .unwrap();
    assert_eq!(s.spp, 9);
    assert_eq!(s.shapes[0].emission, Some(SpectrumDesc::D65 { scale: 3.0 }));
    // A reference cycle is an error, not a hang.
    let e = err(r#"<bsdf type="twosided" id="a"><ref id="b"/></bsdf>
           <bsdf type="twosided" id="b"><ref id="a"/></bsdf>"#);
    assert!(e.contains("circular"), "{e}");
}

#[test]
fn instances_flatten_shapegroups_into_world_space() {
    let s = load(
        r#"<shape type="shapegroup" id="g">
             <shape type="rectangle"><transform name="to_world"><translate x="1"/></transform></shape>
             <shape type="sphere"><float name="radius" value="0.5"/></shape>
           </shape>
           <shape type="instance"><ref id="g"/>
             <transform name="to_world"><scale value="2"/><translate z="10"/></transform>
           </shape>
           <shape type="instance"><ref id="g"/></shape>"#,
    )
    .unwrap();
    // The group itself is not drawn: two instances of two shapes.
    assert_eq!(s.shapes.len(), 4);
    let (lo, hi) = mesh(&s.shapes[0]).bounds().unwrap();
    assert!((lo - Vec3::new(0.0, -2.0, 10.0)).length() < 1e-5, "{lo}");
    assert!((hi - Vec3::new(4.0, 2.0, 10.0)).length() < 1e-5, "{hi}");
    assert!(matches!(s.shapes[1].geometry,
        Geometry::Sphere { center, radius, .. } if radius == 1.0 && center == Vec3::new(0.0, 0.0, 10.0)));
    assert!(matches!(s.shapes[3].geometry, Geometry::Sphere { radius, .. } if radius == 0.5));
    assert!(err(r#"<shape type="instance"/>"#).contains("needs a <ref"));
    assert!(err(
        r#"<shape type="shapegroup" id="g"><shape type="cube"><emitter type="area"/></shape></shape>"#
    )
    .contains("area emitter"));
    // A sphere instanced through a non-uniform scale is not a sphere.
    let e = err(
        r#"<shape type="shapegroup" id="g"><shape type="sphere"/></shape>
           <shape type="instance"><ref id="g"/><transform name="to_world"><scale x="2"/></transform></shape>"#,
    );
    assert!(e.contains("similarity"), "{e}");
}

#[test]
fn integrator_wrappers_render_their_first_integrator() {
    for (outer, extra) in [
        ("moment", ""),
        ("aov", r#"<string name="aovs" value="dd.y:depth"/>"#),
        ("stokes", ""),
    ] {
        let s = load(&format!(
            r#"<integrator type="{outer}">{extra}
                 <integrator type="path" name="main"><integer name="max_depth" value="3"/></integrator>
                 <integrator type="path"><integer name="max_depth" value="9"/></integrator>
               </integrator>"#
        ))
        .unwrap();
        assert_eq!(s.integrator.max_depth, 3, "{outer}");
        assert!(err(&format!(r#"<integrator type="{outer}"/>"#)).contains("nested <integrator>"));
    }
}

#[test]
fn direct_is_the_path_tracer_at_depth_two_with_mitsubas_sample_counts() {
    let s = load(
        r#"<integrator type="direct"><boolean name="hide_emitters" value="true"/></integrator>"#,
    )
    .unwrap();
    assert_eq!(
        (s.integrator.max_depth, s.integrator.hide_emitters),
        (2, true)
    );
    assert!(err(r#"<integrator type="direct"><integer name="shading_samples" value="2"/><integer name="bsdf_samples" value="1"/></integrator>"#).contains("not both"));
    assert!(err(r#"<integrator type="direct"><integer name="emitter_samples" value="0"/><integer name="bsdf_samples" value="0"/></integrator>"#).contains("at least one"));
    // Without emitter samples Mitsuba never reaches a point light; without BSDF samples a
    // smooth mirror stays black: the path tracer would differ, so both are refused.
    let e = err(
        r#"<integrator type="direct"><integer name="emitter_samples" value="0"/></integrator>
           <emitter type="point"/>"#,
    );
    assert!(e.contains("emitter_samples = 0"), "{e}");
    let e = err(
        r#"<integrator type="direct"><integer name="bsdf_samples" value="0"/></integrator>
           <shape type="sphere"><bsdf type="conductor"/></shape>"#,
    );
    assert!(e.contains("bsdf_samples = 0"), "{e}");
    // ... but are fine where nothing differs.
    load(
        r#"<integrator type="direct"><integer name="bsdf_samples" value="0"/></integrator>
           <shape type="sphere"><bsdf type="roughconductor"><string name="distribution" value="ggx"/></bsdf></shape><emitter type="point"/>"#,
    )
    .unwrap();
    // Mitsuba weights every one of `emitter_samples` delta-light samples by 1: point lights
    // come out that many times brighter (checked: scenes/hello.xml of mitsuba-data, ×4).
    let s = load(
        r#"<integrator type="direct"><integer name="emitter_samples" value="4"/></integrator>
           <emitter type="point"><rgb name="intensity" value="10"/></emitter>"#,
    )
    .unwrap();
    assert!(matches!(&s.emitters[0],
        EmitterDesc::Point { intensity: SpectrumDesc::Rgb(c), .. } if c[0] == 40.0));
}

#[test]
fn emitters_follow_mitsubas_spectral_defaults() {
    // In spectral variants a number (or nothing: 1) is the D65 illuminant scaled; an RGB
    // is upsampled as an illuminant; a <spectrum value="v"> is flat.
    let s = load(
        r#"<emitter type="constant"/>
           <emitter type="constant"><float name="radiance" value="2"/></emitter>
           <emitter type="constant"><spectrum name="radiance" value="2"/></emitter>
           <emitter type="point"><point name="position" x="1" y="2" z="3"/></emitter>
           <emitter type="point"><transform name="to_world"><translate x="4"/></transform></emitter>
           <shape type="rectangle"><emitter type="area"/></shape>"#,
    )
    .unwrap();
    let spectra: Vec<SpectrumDesc> = s
        .emitters
        .iter()
        .map(|e| match e {
            EmitterDesc::Constant { radiance } => radiance.clone(),
            EmitterDesc::Point { intensity, .. } => intensity.clone(),
            e => panic!("{e:?}"),
        })
        .collect();
    assert_eq!(spectra[0], SpectrumDesc::D65 { scale: 1.0 });
    assert_eq!(spectra[1], SpectrumDesc::D65 { scale: 2.0 });
    assert_eq!(spectra[2], SpectrumDesc::Constant(2.0));
    assert_eq!(spectra[3], SpectrumDesc::D65 { scale: 1.0 });
    assert!(
        matches!(s.emitters[3], EmitterDesc::Point { position, .. } if position == Vec3::new(1.0, 2.0, 3.0))
    );
    assert!(
        matches!(s.emitters[4], EmitterDesc::Point { position, .. } if position == Vec3::new(4.0, 0.0, 0.0))
    );
    assert_eq!(s.shapes[0].emission, Some(SpectrumDesc::D65 { scale: 1.0 }));
    let e = err(
        r#"<emitter type="point"><point name="position" x="1" y="2" z="3"/><transform name="to_world"/></emitter>"#,
    );
    assert!(e.contains("not both"), "{e}");
    // Sampling options that do not change the image are accepted.
    load(r#"<emitter type="constant"><float name="sampling_weight" value="2"/></emitter>"#)
        .unwrap();
}

#[test]
fn rotation_axes_are_used_as_given() {
    // Mitsuba 3.9.1, ScalarTransform4f().rotate([0, 1, 1], 15):
    // [[0.965926, -0.258819, 0.258819], [0.258819, 1, 0.0340742], [-0.258819, 0.0340742, 1]]
    let s = load(
        r#"<sensor type="perspective"><transform name="to_world"><rotate y="1" z="1" angle="15"/></transform></sensor>"#,
    )
    .unwrap();
    let m = s.camera.to_world;
    let rows = [
        [0.965926, -0.258819, 0.258819],
        [0.258819, 1.0, 0.0340742],
        [-0.258819, 0.0340742, 1.0],
    ];
    for (r, row) in rows.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            assert!((m.col(c)[r] - v).abs() < 1e-5, "({r},{c}) {m}");
        }
    }
    assert!(err(r#"<sensor type="perspective"><transform name="to_world"><rotate angle="15"/></transform></sensor>"#).contains("axis is zero"));
}

#[test]
fn scene_without_sensor_gets_mitsubas_default_camera() {
    // Mitsuba ≤ 3.8 (3.9 refuses to render without a sensor): 45° along x, looking along +z
    // at the bounding box from distance = extent / (2·tan 22.5°) before its near face.
    let s = load(
        r#"<shape type="cube"><transform name="to_world"><translate x="1"/></transform></shape>"#,
    )
    .unwrap();
    let d = 2.0 / (2.0 * 22.5f32.to_radians().tan());
    assert_eq!(s.camera.fov_deg, 45.0);
    assert_eq!(s.camera.fov_axis, FovAxis::X);
    assert!(
        (s.camera.to_world - Mat4::from_translation(Vec3::new(1.0, 0.0, -1.0 - d)))
            .abs_diff_eq(Mat4::ZERO, 1e-5)
    );
    assert!((s.camera.near_clip - d / 100.0).abs() < 1e-6);
    assert!((s.camera.far_clip - (10.0 + d)).abs() < 1e-4);
    assert_eq!((s.film.width, s.film.height, s.spp), (768, 576, 4));
}

#[test]
fn accepted_and_refused_parameters() {
    // Parameters Mitsuba's plugins read that change nothing here.
    let s = load(
        r#"<sensor type="perspective">
             <float name="focus_distance" value="6"/><float name="shutter_close" value="0"/>
             <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="4"/>
               <integer name="crop_width" value="8"/><string name="component_format" value="float32"/></film>
             <sampler type="orthogonal"><integer name="strength" value="2"/><boolean name="jitter" value="false"/></sampler>
           </sensor>
           <boolean name="embree_use_robust_intersections" value="true"/>
           <integrator type="path"><float name="timeout" value="-1"/><integer name="samples_per_pass" value="4"/></integrator>"#,
    )
    .unwrap();
    assert_eq!((s.film.width, s.film.height), (8, 4));
    // What would change the image is refused with the parameter's name.
    for (body, needle) in [
        (
            r#"<sensor type="perspective"><film type="hdrfilm"><integer name="crop_width" value="4"/></film></sensor>"#,
            "crop_width",
        ),
        (
            r#"<sensor type="perspective"><float name="principal_point_offset_x" value="0.1"/></sensor>"#,
            "principal_point_offset_x",
        ),
        (
            r#"<sensor type="radiancemeter"/>"#,
            "unsupported sensor plugin \"radiancemeter\"",
        ),
        (
            r#"<emitter type="sunsky"/>"#,
            "unsupported emitter plugin \"sunsky\"",
        ),
        (
            r#"<sampler type="independent"><boolean name="jitter" value="true"/></sampler>"#,
            "'jitter'",
        ),
    ] {
        let e = err(body);
        assert!(e.contains(needle), "{body}: {e}");
    }
}

#[test]
fn rough_models_and_what_is_still_refused() {
    // A model the renderer does not have is refused where it is read, naming the plugin.
    let e = err(r#"<shape type="sphere"><bsdf type="principled"/></shape>"#);
    assert!(e.contains("unsupported bsdf plugin \"principled\""), "{e}");
    // Mitsuba's rough BSDFs default to Beckmann, and Beckmann is what they get.
    use thinfilm::render::bsdf::microfacet::Distribution;
    for (dist, kind) in [
        ("", Distribution::Beckmann),
        (
            r#"<string name="distribution" value="beckmann"/>"#,
            Distribution::Beckmann,
        ),
        (
            r#"<string name="distribution" value="ggx"/>"#,
            Distribution::Ggx,
        ),
    ] {
        for plugin in ["roughconductor", "roughplastic", "roughdielectric"] {
            let s = load(&format!(
                r#"<shape type="sphere"><bsdf type="{plugin}">{dist}<float name="alpha" value="0.2"/></bsdf></shape>"#
            ))
            .unwrap();
            let mf = match &s.bsdfs[s.shapes[0].bsdf] {
                Bsdf::Conductor(c) => constant(&c.roughness),
                Bsdf::Plastic(p) => p.ggx.unwrap(),
                Bsdf::RoughDielectric(d) => constant(&d.roughness),
                b => panic!("{plugin}: {b:?}"),
            };
            assert_eq!(
                (mf.kind, mf.alpha_u, mf.alpha_v),
                (kind, 0.2, 0.2),
                "{plugin} {dist}"
            );
        }
    }
    let e = err(
        r#"<shape type="sphere"><bsdf type="roughconductor"><string name="distribution" value="phong"/></bsdf></shape>"#,
    );
    assert!(e.contains("unknown distribution \"phong\""), "{e}");
    // Anisotropic roughness: α_u along dp/du as in Mitsuba; roughplastic refuses it, as
    // Mitsuba's does.
    let s = load(
        r#"<shape type="sphere"><bsdf type="roughconductor"><float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/></bsdf></shape>"#,
    )
    .unwrap();
    let Bsdf::Conductor(c) = &s.bsdfs[s.shapes[0].bsdf] else {
        panic!()
    };
    let g = constant(&c.roughness);
    assert_eq!((g.alpha_u, g.alpha_v), (0.05, 0.3));
    let e = err(
        r#"<shape type="sphere"><bsdf type="roughplastic"><float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/></bsdf></shape>"#,
    );
    assert!(
        e.contains("roughplastic") && e.contains("anisotropic"),
        "{e}"
    );
    // A scaled specular lobe and RGB-valued indices are read (their values are checked
    // against Mitsuba's in tests/scene_bsdf_points.rs): RGB (0.2, 0.9, 1.1) is clamped to
    // [0, 1] before upsampling, as Mitsuba does. A value of the wrong type names the
    // parameter.
    let s = load(
        r#"<shape type="sphere"><bsdf type="conductor"><rgb name="specular_reflectance" value="0.5"/><rgb name="eta" value="0.2, 0.9, 1.1"/><float name="k" value="3"/></bsdf></shape>"#,
    )
    .unwrap();
    let Bsdf::Conductor(c) = &s.bsdfs[s.shapes[0].bsdf] else {
        panic!()
    };
    assert!(!c.specular.is_one());
    for l in [420.0, 550.0, 680.0] {
        let n = c.eta.at(l);
        assert!(
            n.re > 0.0 && n.re <= 1.0 && (n.im - 3.0).abs() < 1e-9,
            "{l}: {n}"
        );
    }
    let e = err(
        r#"<shape type="sphere"><bsdf type="dielectric"><string name="specular_transmittance" value="x"/></bsdf></shape>"#,
    );
    assert!(e.contains("'specular_transmittance'"), "{e}");
    // The defaults, written out, are fine.
    load(
        r#"<shape type="sphere"><bsdf type="conductor"><rgb name="specular_reflectance" value="1, 1, 1"/></bsdf></shape>"#,
    )
    .unwrap();
}

#[test]
fn old_scene_versions_are_upgraded() {
    // Mitsuba's upgrade of scenes older than 2.0: camelCase parameter names.
    let s = load_str(
        r#"<scene version="0.6.0"><integrator type="path"><integer name="maxDepth" value="3"/><integer name="rrDepth" value="2"/></integrator>
           <shape type="cube"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.25"/></bsdf></shape></scene>"#,
        Path::new("."),
        &[],
        "old.xml",
    )
    .unwrap();
    assert_eq!((s.integrator.max_depth, s.integrator.rr_depth), (3, 2));
    // (A grey RGB is kept as the flat spectrum it upsamples to.)
    let r = reflectance(&s.bsdfs[s.shapes[0].bsdf]);
    assert!(
        matches!(r, TextureDesc::Value(SpectrumDesc::Rgb(c)) if c[0] == 0.25)
            || matches!(r, TextureDesc::Value(SpectrumDesc::Constant(v)) if v == 0.25),
        "{r:?}"
    );
}

/// A version-4 `.serialized` file holding `meshes` (each: positions, triangles).
fn serialized(meshes: &[(&[[f32; 3]], &[[u32; 3]])]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for (positions, faces) in meshes {
        offsets.push(out.len() as u64);
        let mut body = Vec::new();
        body.extend(0x1000u32.to_le_bytes());
        body.extend(b"m\0");
        body.extend((positions.len() as u64).to_le_bytes());
        body.extend((faces.len() as u64).to_le_bytes());
        for v in positions.iter().flatten() {
            body.extend(v.to_le_bytes());
        }
        for i in faces.iter().flatten() {
            body.extend(i.to_le_bytes());
        }
        out.extend(0x041Cu16.to_le_bytes());
        out.extend(4u16.to_le_bytes());
        let mut e = ZlibEncoder::new(Vec::new(), Compression::default());
        e.write_all(&body).unwrap();
        out.extend(e.finish().unwrap());
    }
    for o in &offsets {
        out.extend(o.to_le_bytes());
    }
    out.extend((meshes.len() as u32).to_le_bytes());
    out
}

#[test]
fn serialized_meshes_by_shape_index() {
    let dir = tempfile::tempdir().unwrap();
    let tri: &[[f32; 3]] = &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let quad: &[[f32; 3]] = &[
        [0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 2.0, 0.0],
        [0.0, 2.0, 0.0],
    ];
    std::fs::write(
        dir.path().join("m.serialized"),
        serialized(&[(tri, &[[0, 1, 2]]), (quad, &[[0, 1, 2], [0, 2, 3]])]),
    )
    .unwrap();
    let s = load_in(
        dir.path(),
        r#"<shape type="serialized"><string name="filename" value="m.serialized"/>
             <integer name="shape_index" value="1"/>
             <transform name="to_world"><translate z="5"/></transform></shape>
           <shape type="serialized"><string name="filename" value="m.serialized"/>
             <boolean name="face_normals" value="true"/></shape>"#,
    )
    .unwrap();
    let m = mesh(&s.shapes[0]);
    assert_eq!(m.indices.len(), 2);
    assert_eq!(m.bounds().unwrap().1, Vec3::new(2.0, 2.0, 5.0));
    // No stored normals: smooth normals computed (+z); face_normals keeps none.
    assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    assert!(mesh(&s.shapes[1]).normals.is_empty());
    let e = err_in(
        dir.path(),
        r#"<shape type="serialized"><string name="filename" value="m.serialized"/><integer name="shape_index" value="2"/></shape>"#,
    );
    assert!(
        e.contains("shape_index 2 is out of range") && e.contains("2 meshes"),
        "{e}"
    );
}

#[test]
fn cylinders_lie_where_mitsuba_puts_them() {
    let s = load(
        r#"<shape type="cylinder"><point name="p0" x="1" y="0" z="0"/><point name="p1" x="1" y="0" z="2"/>
             <float name="radius" value="0.5"/></shape>
           <shape type="cylinder"><point name="p0" x="0" y="0" z="0"/><point name="p1" x="3" y="0" z="0"/>
             <boolean name="flip_normals" value="true"/></shape>"#,
    )
    .unwrap();
    let (lo, hi) = mesh(&s.shapes[0]).bounds().unwrap();
    assert!((lo - Vec3::new(0.5, -0.5, 0.0)).length() < 1e-4, "{lo}");
    assert!((hi - Vec3::new(1.5, 0.5, 2.0)).length() < 1e-4, "{hi}");
    // Along x, from p0 to p1, radius 1; flipped normals point at the axis.
    let m = mesh(&s.shapes[1]);
    let (lo, hi) = m.bounds().unwrap();
    assert!(
        (lo - Vec3::new(0.0, -1.0, -1.0)).length() < 1e-4
            && (hi - Vec3::new(3.0, 1.0, 1.0)).length() < 1e-4
    );
    for (p, n) in m.positions.iter().zip(&m.normals) {
        let radial = Vec3::new(0.0, p.y, p.z);
        assert!(n.dot(radial) < -0.999, "{p} {n}");
    }
    assert!(
        err(r#"<shape type="cylinder"><float name="radius" value="0"/></shape>"#)
            .contains("'radius' = 0 must be a finite number > 0")
    );
}

#[test]
fn integer_image_formats_are_srgb_decoded() {
    let dir = tempfile::tempdir().unwrap();
    // 8-bit value 128 decodes to sRGB⁻¹(128/255) = 0.21586 unless raw.
    let img = image::RgbImage::from_pixel(2, 2, image::Rgb([128, 128, 128]));
    for ext in ["png", "jpg", "bmp", "tga", "ppm"] {
        img.save(dir.path().join(format!("t.{ext}"))).unwrap();
        for (raw, want) in [(false, 0.215861f32), (true, 128.0 / 255.0)] {
            let s = load_in(
                dir.path(),
                &format!(
                    r#"<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">
                         <string name="filename" value="t.{ext}"/><boolean name="raw" value="{raw}"/>
                       </texture></bsdf></shape>"#
                ),
            )
            .unwrap();
            let TextureDesc::Bitmap(b) = reflectance(&s.bsdfs[s.shapes[0].bsdf]) else {
                panic!()
            };
            // JPEG is lossy; a flat image still decodes to within one code value.
            let tol = if ext == "jpg" { 0.01 } else { 1e-5 };
            assert!(
                (b.data[0] - want).abs() < tol,
                "{ext} raw={raw}: {}",
                b.data[0]
            );
        }
    }
}

/// Mitsuba's `rawconstant`: a float is a flat constant; a vector is a raw RGB triple, the
/// flat normal (0.5, 0.5, 1) of a `normalmap` leaving its nested BSDF's frame unchanged.
#[test]
fn rawconstant_textures() {
    let s = load(
        r#"<shape type="sphere"><bsdf type="diffuse"><texture type="rawconstant" name="reflectance"><float name="value" value="0.3"/></texture></bsdf></shape>"#,
    )
    .unwrap();
    let wl = thinfilm::spectrum::SampledWavelengths::new([450.0, 520.0, 600.0, 680.0], [1.0; 4]);
    let ctx = thinfilm::render::bsdf::ShadingCtx {
        wl: &wl,
        uv: glam::Vec2::ZERO,
        segment: 0.0,
        color: Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    let f = s.bsdfs[0].eval(&ctx, Vec3::Z, Vec3::Z);
    assert!(
        (f - 0.3 / std::f32::consts::PI).abs().max_element() < 1e-6,
        "{f:?}"
    );
    let s = load(
        r#"<shape type="sphere"><bsdf type="normalmap"><texture name="normalmap" type="rawconstant"><vector name="value" value="0.5, 0.5, 1.0"/></texture><bsdf type="diffuse"/></bsdf></shape>"#,
    )
    .unwrap();
    let (wi, wo) = (Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.0, 0.6, 0.8));
    let f = s.bsdfs[0].eval(&ctx, wi, wo)[0];
    assert!((f - 0.5 / std::f32::consts::PI * 0.8).abs() < 1e-6, "{f}");
    let e = err(r#"<texture type="rawconstant" id="t"/>"#);
    assert!(e.contains("'value'") && e.contains("test.xml:2:"), "{e}");
}
