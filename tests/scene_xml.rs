//! Mitsuba XML subset: every construct, error messages with positions, missing files.

use glam::{Mat4, Vec2, Vec3};
use std::path::Path;
use thinfilm::optics::{Complex64, Ior};
use thinfilm::render::bsdf::roughness::Roughness;
use thinfilm::render::bsdf::Bsdf;
use thinfilm::render::camera::fov_x_deg;
use thinfilm::scene::mitsuba::load_str;
use thinfilm::scene::*;

fn wrap(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n")
}

fn load(body: &str) -> anyhow::Result<Scene> {
    load_str(&wrap(body), Path::new("."), &[], "test.xml")
}

fn load_in(dir: &Path, body: &str) -> anyhow::Result<Scene> {
    load_str(&wrap(body), dir, &[], "test.xml")
}

fn err(body: &str) -> String {
    format!("{:#}", load(body).expect_err("should fail"))
}

fn mat_close(a: Mat4, b: Mat4) {
    assert!(a.abs_diff_eq(b, 1e-5), "\n{a}\n!=\n{b}");
}

const SENSOR: &str = r#"
<default name="spp" value="16"/>
<default name="res" value="64"/>
<sensor type="perspective">
  <float name="fov" value="30"/>
  <string name="fov_axis" value="y"/>
  <float name="near_clip" value="0.5"/>
  <float name="far_clip" value="50"/>
  <sampler type="independent">
    <integer name="sample_count" value="$spp"/>
    <integer name="seed" value="7"/>
  </sampler>
  <film type="hdrfilm">
    <integer name="width" value="$res"/>
    <integer name="height" value="32"/>
    <string name="pixel_format" value="rgb"/>
    <string name="component_format" value="float32"/>
    <rfilter type="tent"><float name="radius" value="1.5"/></rfilter>
  </film>
</sensor>"#;

#[test]
fn defaults_and_overrides() {
    let s = load(SENSOR).unwrap();
    assert_eq!(s.spp, 16);
    assert_eq!(s.seed, 7);
    assert_eq!(s.sampler, SamplerKind::Independent);
    // Mitsuba's stratified samplers are rendered with the Owen-scrambled Sobol' sampler.
    for t in ["ldsampler", "stratified", "multijitter", "orthogonal"] {
        let body = SENSOR.replace("\"independent\"", &format!("\"{t}\""));
        assert_eq!(load(&body).unwrap().sampler, SamplerKind::Sobol, "{t}");
    }
    // No sampler: Mitsuba's default, independent.
    let no_sampler = r#"<sensor type="perspective"><float name="fov" value="30"/></sensor>"#;
    assert_eq!(load(no_sampler).unwrap().sampler, SamplerKind::Independent);
    assert!(err(&SENSOR.replace("\"independent\"", "\"halton\"")).contains("halton"));
    assert_eq!((s.film.width, s.film.height), (64, 32));
    assert_eq!(s.film.filter, ReconstructionFilter::Tent { radius: 1.5 });
    assert_eq!(s.camera.fov_deg, 30.0);
    assert_eq!(s.camera.fov_axis, FovAxis::Y);
    assert_eq!((s.camera.near_clip, s.camera.far_clip), (0.5, 50.0));
    let o = [
        ("spp".to_string(), "128".to_string()),
        ("res".into(), "100".into()),
    ];
    let s = load_str(&wrap(SENSOR), Path::new("."), &o, "t.xml").unwrap();
    assert_eq!(s.spp, 128);
    assert_eq!(s.film.width, 100);
    // An override for a parameter the file neither declares nor uses is a typo.
    let o = [("sp".to_string(), "1".to_string())];
    let e = format!(
        "{:#}",
        load_str(&wrap(SENSOR), Path::new("."), &o, "t.xml").unwrap_err()
    );
    assert!(
        e.contains("no parameter $sp") && e.contains("res, spp"),
        "{e}"
    );
    // A parameter used without <default> can be provided by an override.
    let body = r#"<integrator type="path"><integer name="max_depth" value="$d"/></integrator>"#;
    let o = [("d".to_string(), "3".to_string())];
    let s = load_str(&wrap(body), Path::new("."), &o, "t.xml").unwrap();
    assert_eq!(s.integrator.max_depth, 3);
    let e = err(body);
    assert!(
        e.contains("undefined parameter $d") && e.contains("test.xml:2:"),
        "{e}"
    );
    // Mitsuba defaults when no sensor parts are given.
    let s = load(r#"<sensor type="perspective"/>"#).unwrap();
    assert_eq!((s.film.width, s.film.height, s.spp), (768, 576, 4));
    assert_eq!(
        s.film.filter,
        ReconstructionFilter::Gaussian { stddev: 0.5 }
    );
    // Mitsuba's default 50 mm focal length on a 36 × 24 mm film, measured along the diagonal
    // (2·atan(√(36² + 24²) / 100) = 46.793°): Mitsuba 3.9.1 reports x_fov = 38.1848° for a
    // 768 × 576 film, 34.0221° for 512 × 512 and 39.5978° for 600 × 400.
    assert!((s.camera.fov_deg - 46.79301).abs() < 1e-4);
    assert_eq!(s.camera.fov_axis, FovAxis::Diagonal);
    for ((w, h), x_fov) in [
        ((768.0, 576.0), 38.1848),
        ((512.0, 512.0), 34.0221),
        ((600.0, 400.0), 39.5978),
    ] {
        let got = fov_x_deg(s.camera.fov_deg, s.camera.fov_axis, w / h);
        assert!((got - x_fov).abs() < 1e-3, "{w}×{h}: {got}");
    }
    let s =
        load(r#"<sensor type="perspective"><string name="focal_length" value="35mm"/></sensor>"#)
            .unwrap();
    // Mitsuba 3.9.1: x_fov = 52.6225° at 768 × 576.
    let got = fov_x_deg(s.camera.fov_deg, s.camera.fov_axis, 768.0 / 576.0);
    assert!((got - 52.6225).abs() < 1e-3, "{got}");
    // fov_axis without fov: Mitsuba rejects it as unused.
    assert!(
        err(r#"<sensor type="perspective"><string name="fov_axis" value="y"/></sensor>"#)
            .contains("'fov_axis' applies to 'fov' only")
    );
    assert!(format!("{:#}", load(r#"<sensor type="perspective"><float name="fov" value="30"/><string name="focal_length" value="35mm"/></sensor>"#).unwrap_err()).contains("not both"));
}

#[test]
fn integrator_settings() {
    let s = load(
        r#"<integrator type="path">
            <integer name="max_depth" value="8"/>
            <integer name="rr_depth" value="3"/>
            <boolean name="hide_emitters" value="true"/>
        </integrator>"#,
    )
    .unwrap();
    assert_eq!(
        s.integrator,
        IntegratorSettings {
            max_depth: 8,
            rr_depth: 3,
            hide_emitters: true
        }
    );
    assert_eq!(load("").unwrap().integrator, IntegratorSettings::default());
    // Without participating media volpath is the path tracer.
    let s =
        load(r#"<integrator type="volpath"><integer name="max_depth" value="4"/></integrator>"#)
            .unwrap();
    assert_eq!(s.integrator.max_depth, 4);
    assert!(err(r#"<integrator type="bdpt"/>"#).contains("unsupported integrator plugin \"bdpt\""));
    assert!(
        err(r#"<integrator type="path"><float name="max_depth" value="8"/></integrator>"#)
            .contains("must be an <integer>")
    );
}

#[test]
fn transforms_compose_in_document_order() {
    let s = load(
        r#"<sensor type="perspective"><transform name="to_world">
            <translate x="1" y="2" z="3"/>
            <rotate y="1" angle="90"/>
            <scale value="2"/>
        </transform></sensor>"#,
    )
    .unwrap();
    // M = S · R_y(90°) · T: linear part 2·R, translation S·R·(1,2,3) = (6, 4, −2).
    let expected = Mat4::from_cols(
        [0.0, 0.0, -2.0, 0.0].into(),
        [0.0, 2.0, 0.0, 0.0].into(),
        [2.0, 0.0, 0.0, 0.0].into(),
        [6.0, 4.0, -2.0, 1.0].into(),
    );
    mat_close(s.camera.to_world, expected);

    // matrix is row-major; scale with x/y/z defaults 1; value= forms.
    let s = load(
        r#"<sensor type="perspective"><transform name="to_world">
            <matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>
            <scale x="2"/>
            <translate value="1, 1, 1"/>
        </transform></sensor>"#,
    )
    .unwrap();
    let expected = Mat4::from_cols(
        [2.0, 0.0, 0.0, 0.0].into(),
        [0.0, 1.0, 0.0, 0.0].into(),
        [0.0, 0.0, 1.0, 0.0].into(),
        [11.0, 7.0, 8.0, 1.0].into(),
    );
    mat_close(s.camera.to_world, expected);

    // lookat: from +5 Z towards the origin → forward −Z, left = up × dir = −X.
    let s = load(
        r#"<sensor type="perspective"><transform name="to_world">
            <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
        </transform></sensor>"#,
    )
    .unwrap();
    let expected = Mat4::from_cols(
        [-1.0, 0.0, 0.0, 0.0].into(),
        [0.0, 1.0, 0.0, 0.0].into(),
        [0.0, 0.0, -1.0, 0.0].into(),
        [0.0, 0.0, 5.0, 1.0].into(),
    );
    mat_close(s.camera.to_world, expected);
    // rotate value= axis, 3x3 matrix.
    let s = load(
        r#"<sensor type="perspective"><transform name="to_world">
            <rotate value="0 0 1" angle="90"/>
            <matrix value="1 0 0 0 1 0 0 0 3"/>
        </transform></sensor>"#,
    )
    .unwrap();
    let expected = Mat4::from_cols(
        [0.0, 1.0, 0.0, 0.0].into(),
        [-1.0, 0.0, 0.0, 0.0].into(),
        [0.0, 0.0, 3.0, 0.0].into(),
        [0.0, 0.0, 0.0, 1.0].into(),
    );
    mat_close(s.camera.to_world, expected);
    assert!(err(r#"<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,0" target="0,0,0"/></transform></sensor>"#).contains("degenerate"));
    assert!(err(r#"<sensor type="perspective"><transform name="to_world"><matrix value="1 2 3"/></transform></sensor>"#).contains("expected 9 or 16"));
}

#[test]
fn refs_and_ids() {
    let s = load(
        r#"<texture type="checkerboard" id="checks">
              <rgb name="color0" value="1, 0, 0"/>
              <float name="color1" value="0.1"/>
           </texture>
           <bsdf type="diffuse" id="mat"><ref name="reflectance" id="checks"/></bsdf>
           <shape type="rectangle"><ref id="mat"/></shape>
           <shape type="cube"><ref name="bsdf" id="mat"/></shape>
           <shape type="sphere"/>"#,
    )
    .unwrap();
    assert_eq!(s.shapes.len(), 3);
    assert_eq!(s.shapes[0].bsdf, s.shapes[1].bsdf);
    assert_ne!(s.shapes[0].bsdf, s.shapes[2].bsdf);
    match reflectance(&s.bsdfs[s.shapes[0].bsdf]) {
        TextureDesc::Checkerboard { color0, color1, .. } => {
            assert_eq!(color0, SpectrumDesc::Rgb([1.0, 0.0, 0.0]));
            assert_eq!(color1, SpectrumDesc::Constant(0.1));
        }
        t => panic!("{t:?}"),
    }
    // The sphere got Mitsuba's default BSDF.
    assert!(matches!(
        reflectance(&s.bsdfs[s.shapes[2].bsdf]),
        TextureDesc::Value(SpectrumDesc::Constant(v)) if v == 0.5
    ));
    let e = err(r#"<shape type="cube"><ref id="nope"/></shape>"#);
    assert!(
        e.contains("unknown id \"nope\"") && e.contains("test.xml:2:"),
        "{e}"
    );
    let e = err(r#"<bsdf type="diffuse" id="a"/><bsdf type="diffuse" id="a"/>"#);
    assert!(e.contains("duplicate id"), "{e}");
}

#[test]
fn errors_name_element_plugin_and_position() {
    let e = err("<foo/>");
    assert!(e.contains("test.xml:2:1") && e.contains("<foo>"), "{e}");
    let e = err(r#"<shape type="cube" colour="red"/>"#);
    assert!(
        e.contains("test.xml:2:20") && e.contains("unknown attribute 'colour'"),
        "{e}"
    );
    let e = err("<bsdf type=\"velvet\"/>");
    assert!(
        e.contains("test.xml:2:1") && e.contains("\"velvet\"") && e.contains("diffuse"),
        "{e}"
    );
    let e = err("<shape type=\"cube\">\n  <bsdf type=\"diffuse\">\n    <float name=\"bogus\" value=\"1\"/>\n  </bsdf>\n</shape>");
    assert!(
        e.contains("test.xml:4:5")
            && e.contains("'bogus'")
            && e.contains("bsdf plugin \"diffuse\""),
        "{e}"
    );
    let e = err(r#"<shape type="obj"><string name="filename" value="missing.obj"/></shape>"#);
    assert!(e.contains("missing.obj") && e.contains("not found"), "{e}");
    let e = err(r#"<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>"#);
    assert!(e.contains("sky.exr") && e.contains("not found"), "{e}");
    assert!(err(r#"<float name="x" value="abc"/>"#).contains("'abc' is not a finite number"));
    assert!(
        err(r#"<shape type="cube"><float name="x" value="abc"/></shape>"#)
            .contains("not a finite number")
    );
    assert!(
        err(r#"<shape type="cube"><boolean name="flip_normals" value="maybe"/></shape>"#)
            .contains("boolean")
    );
    assert!(
        err(r#"<shape type="cube"><float name="flip_normals" value="1"/></shape>"#)
            .contains("must be a <boolean>")
    );
    let e = format!(
        "{:#}",
        load_str(
            "<scene version=\"3.0.0\"><shape></scene>",
            Path::new("."),
            &[],
            "bad.xml"
        )
        .unwrap_err()
    );
    assert!(e.contains("bad.xml") && e.contains("malformed XML"), "{e}");
    let e = format!(
        "{:#}",
        load_str("<scene/>", Path::new("."), &[], "v.xml").unwrap_err()
    );
    assert!(e.contains("version"), "{e}");
    // (Media: tests/scene_media.rs.)
    assert!(err(r#"<medium type="heterogeneous"/>"#)
        .contains("unsupported medium plugin \"heterogeneous\""));
    assert!(
        err(r#"<shape type="cube"><bsdf type="diffuse"/><bsdf type="diffuse"/></shape>"#)
            .contains("one BSDF")
    );
    assert!(
        err(r#"<shape type="cube"><emitter type="point"/></shape>"#).contains("of type \"area\"")
    );
}

#[test]
fn values_and_spectra() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("r.spd"),
        "# test\n400 0.1\n500, 0.5\n600 0.9\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("bad.spd"), "400 0.1\n300 x\n").unwrap();
    let s = load_in(
        dir.path(),
        r#"<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" filename="r.spd"/></bsdf></shape>
           <shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" value="400:0.2, 700:0.8"/></bsdf></shape>
           <shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf></shape>
           <shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="0.2 0.4 0.6"/></bsdf></shape>
           <emitter type="constant"><spectrum type="d65" name="radiance"><float name="scale" value="2"/></spectrum></emitter>"#,
    )
    .unwrap();
    let refl = |i: usize| match reflectance(&s.bsdfs[s.shapes[i].bsdf]) {
        TextureDesc::Value(v) => v,
        t => panic!("{t:?}"),
    };
    assert_eq!(
        refl(0),
        SpectrumDesc::Tabulated(vec![(400.0, 0.1), (500.0, 0.5), (600.0, 0.9)])
    );
    assert_eq!(
        refl(1),
        SpectrumDesc::Tabulated(vec![(400.0, 0.2), (700.0, 0.8)])
    );
    assert_eq!(refl(2), SpectrumDesc::Constant(0.3));
    assert_eq!(refl(3), SpectrumDesc::Rgb([0.2, 0.4, 0.6]));
    assert!(
        matches!(&s.emitters[0], EmitterDesc::Constant { radiance: SpectrumDesc::D65 { scale } } if *scale == 2.0)
    );
    let e = format!("{:#}", load_in(dir.path(), r#"<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" filename="bad.spd"/></bsdf></shape>"#).unwrap_err());
    assert!(e.contains("bad.spd:2"), "{e}");
    assert!(err(r#"<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" value="500:0.2, 400:0.8"/></bsdf></shape>"#).contains("increase"));
    // point/vector forms and a point light.
    let s = load(
        r#"<emitter type="point"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="5"/></emitter>
           <emitter type="point"><transform name="to_world"><translate value="4 5 6"/></transform></emitter>"#,
    )
    .unwrap();
    assert!(
        matches!(&s.emitters[0], EmitterDesc::Point { position, intensity: SpectrumDesc::Rgb(c) } if *position == Vec3::new(1.0, 2.0, 3.0) && *c == [5.0; 3])
    );
    assert!(
        matches!(&s.emitters[1], EmitterDesc::Point { position, .. } if *position == Vec3::new(4.0, 5.0, 6.0))
    );
}

fn bsdf(body: &str) -> Bsdf {
    let s = load(&format!("<shape type=\"cube\">{body}</shape>")).unwrap();
    s.bsdfs[s.shapes[0].bsdf].clone()
}

/// A diffuse BSDF's reflectance, as described in the file.
fn reflectance(b: &Bsdf) -> TextureDesc {
    match b {
        Bsdf::Diffuse(d) => d.reflectance.desc(),
        b => panic!("not diffuse: {b:?}"),
    }
}

/// The (film index, thickness description, substrate index, α) of a single-film BSDF.
fn film(b: Bsdf) -> (Ior, TextureDesc, Ior, f32) {
    match b {
        Bsdf::ThinFilm(f) => (
            f.film_ior,
            f.thickness_nm.desc(),
            f.substrate_ior,
            f.ggx.map_or(0.0, |g| g.alpha_u),
        ),
        b => panic!("not a thin film: {b:?}"),
    }
}

/// The (index, α_u, α_v) of a conductor.
fn conductor(b: Bsdf) -> (Ior, f32, f32) {
    match b {
        Bsdf::Conductor(c) => {
            let Roughness::Constant(g) = c.roughness else {
                panic!("textured roughness: {:?}", c.roughness)
            };
            (
                c.eta,
                g.map_or(0.0, |g| g.alpha_u),
                g.map_or(0.0, |g| g.alpha_v),
            )
        }
        b => panic!("not a conductor: {b:?}"),
    }
}

#[test]
fn bsdfs() {
    match bsdf(
        r#"<bsdf type="dielectric"><string name="int_ior" value="water"/><float name="ext_ior" value="1.0"/></bsdf>"#,
    ) {
        Bsdf::Dielectric(d) => {
            assert_eq!(d.int_ior, Ior::real(1.333));
            assert_eq!(d.ext_ior, Ior::real(1.0));
        }
        b => panic!("{b:?}"),
    }
    // Mitsuba defaults: bk7 inside, air outside.
    match bsdf(r#"<bsdf type="dielectric"/>"#) {
        Bsdf::Dielectric(d) => {
            assert_eq!(
                (d.int_ior, d.ext_ior),
                (Ior::real(1.5046), Ior::real(1.000277))
            );
        }
        b => panic!("{b:?}"),
    }
    // A rough dielectric: Mitsuba's defaults (bk7 in air, Beckmann, α = 0.1).
    match bsdf(r#"<bsdf type="roughdielectric"/>"#) {
        Bsdf::RoughDielectric(d) => {
            assert!((d.eta - 1.5046 / 1.000277).abs() < 1e-6, "{}", d.eta);
            let Roughness::Constant(Some(mf)) = d.roughness else {
                panic!("{:?}", d.roughness)
            };
            assert_eq!((mf.alpha_u, mf.alpha_v), (0.1, 0.1));
        }
        b => panic!("{b:?}"),
    }
    // A dispersive index is refused for it (Mitsuba's is a constant), naming the plugin.
    let e = err(
        r#"<shape type="cube"><bsdf type="roughdielectric"><string name="int_ior" value="cauchy:1.5,4200"/></bsdf></shape>"#,
    );
    assert!(
        e.contains("roughdielectric") && e.contains("dispersive") && e.contains("test.xml:2:"),
        "{e}"
    );
    let (eta, au, av) = conductor(bsdf(
        r#"<bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha_u" value="0.3"/><float name="alpha_v" value="0.3"/><float name="eta" value="0.2"/><float name="k" value="3"/></bsdf>"#,
    ));
    assert_eq!(eta, Ior::Constant(Complex64::new(0.2, 3.0)));
    assert_eq!((au, av), (0.3, 0.3));
    // Spectral eta/k: tabulated on the union grid, linear in between, clamped outside.
    let (eta, _, _) = conductor(bsdf(
        r#"<bsdf type="conductor"><spectrum name="eta" value="400:0.5, 700:0.2"/><spectrum name="k" value="500:3, 600:4"/></bsdf>"#,
    ));
    assert!(matches!(eta, Ior::Material(_)));
    let c = eta.at(550.0);
    assert!(
        (c.re - 0.35).abs() < 1e-6 && (c.im - 3.5).abs() < 1e-6,
        "{c}"
    );
    let c = eta.at(450.0);
    assert!(
        (c.re - 0.45).abs() < 1e-6 && (c.im - 3.0).abs() < 1e-6,
        "{c}"
    );
    let c = eta.at(800.0);
    assert!(
        (c.re - 0.2).abs() < 1e-6 && (c.im - 4.0).abs() < 1e-6,
        "{c}"
    );
    let (film_ior, _, substrate_ior, _) = film(bsdf(
        r#"<bsdf type="thinfilm"><spectrum name="film_ior" value="400:1.40, 800:1.36"/><spectrum name="substrate_k" value="400:0.1, 800:0.3"/></bsdf>"#,
    ));
    assert!((film_ior.at(600.0).re - 1.38).abs() < 1e-6);
    let c = substrate_ior.at(600.0);
    assert!(
        (c.re - 1.64).abs() < 1e-6 && (c.im - 0.2).abs() < 1e-6,
        "{c}"
    );
    // An RGB index is upsampled as Mitsuba does (like a reflectance).
    let (eta, _, _) = conductor(bsdf(
        r#"<bsdf type="conductor"><rgb name="eta" value="0.2, 0.3, 0.4"/></bsdf>"#,
    ));
    assert!((0.15..0.45).contains(&eta.at(550.0).re), "{eta}");
    assert!(err(r#"<shape type="cube"><bsdf type="thinfilm"><string name="substrate_ior" value="bk7"/><float name="substrate_k" value="0.1"/></bsdf></shape>"#).contains("named substrate"));
    assert!(err(
        r#"<shape type="cube"><bsdf type="conductor"><float name="eta" value="-1"/></bsdf></shape>"#
    )
    .contains("'eta' = -1 is outside"));
    // "none" = perfect mirror.
    let (eta, au, _) = conductor(bsdf(r#"<bsdf type="conductor"/>"#));
    assert_eq!((eta, au), (Ior::Constant(Complex64::new(0.0, 1.0)), 0.0));
    let e = err(
        r#"<shape type="cube"><bsdf type="conductor"><string name="material" value="Unobtainium"/></bsdf></shape>"#,
    );
    assert!(e.contains("Unobtainium") && e.contains("available"), "{e}");
    match bsdf(
        r#"<bsdf type="roughplastic"><string name="distribution" value="ggx"/><rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/><float name="int_ior" value="1.6"/><boolean name="nonlinear" value="true"/></bsdf>"#,
    ) {
        Bsdf::Plastic(p) => {
            assert_eq!(
                p.diffuse_reflectance.desc(),
                TextureDesc::Value(SpectrumDesc::Rgb([0.1, 0.2, 0.3]))
            );
            assert_eq!(p.eta, 1.6 / 1.000277);
            assert_eq!((p.ggx.map(|g| g.alpha_u), p.nonlinear), (Some(0.1), true));
        }
        b => panic!("{b:?}"),
    }
    assert!(
        matches!(bsdf(r#"<bsdf type="plastic"/>"#), Bsdf::Plastic(p) if p.eta == 1.49 / 1.000277 && p.ggx.is_none())
    );
    match bsdf(r#"<bsdf type="twosided"><bsdf type="thinfilm"/></bsdf>"#) {
        Bsdf::TwoSided(t) => {
            // The thinfilm defaults (docs/physics-and-formats.md).
            let (film_ior, d, substrate_ior, alpha) = film(*t.inner);
            assert_eq!(
                (film_ior, d, substrate_ior, alpha),
                (
                    Ior::real(1.37),
                    TextureDesc::Value(SpectrumDesc::Constant(400.0)),
                    Ior::real(1.64),
                    0.0
                )
            );
        }
        b => panic!("{b:?}"),
    }
    let (film_ior, d, substrate_ior, alpha) = film(bsdf(
        r#"<bsdf type="thinfilm"><float name="film_ior" value="2.37"/><float name="thickness" value="500"/><float name="substrate_ior" value="0.2"/><float name="substrate_k" value="3.1"/><float name="alpha" value="0.15"/></bsdf>"#,
    ));
    assert_eq!(
        (film_ior, d, alpha),
        (
            Ior::real(2.37),
            TextureDesc::Value(SpectrumDesc::Constant(500.0)),
            0.15
        )
    );
    assert_eq!(substrate_ior, Ior::Constant(Complex64::new(0.2, 3.1)));
    // A film index by name comes from the dispersion library (wavelength-dependent) …
    let (film_ior, ..) = film(bsdf(
        r#"<bsdf type="thinfilm"><string name="film_ior" value="MgF2"/></bsdf>"#,
    ));
    assert!(matches!(film_ior, Ior::Material(m) if m.name == "MgF2"));
    // … or from Mitsuba's table when the library lacks it.
    let (film_ior, ..) = film(bsdf(
        r#"<bsdf type="thinfilm"><string name="film_ior" value="acetone"/></bsdf>"#,
    ));
    assert_eq!(film_ior, Ior::real(1.36));
    assert!(err(r#"<shape type="cube"><bsdf type="thinfilm"><float name="thickness" value="-5"/></bsdf></shape>"#).contains("'thickness' = -5 is outside"));
    assert!(err(r#"<shape type="cube"><bsdf type="thinfilm"><string name="film_ior" value="cheese"/></bsdf></shape>"#).contains("cheese"));
    assert!(err(r#"<shape type="cube"><bsdf type="dielectric"><string name="int_ior" value="cheese"/></bsdf></shape>"#).contains("unknown IOR name"));
    assert!(err(r#"<shape type="cube"><bsdf type="roughconductor"><string name="distribution" value="phong"/></bsdf></shape>"#).contains("phong"));
}

#[test]
fn textures() {
    let dir = tempfile::tempdir().unwrap();
    let th: Vec<f32> = (0..8).map(|i| 100.0 * i as f32).collect();
    thinfilm::image_io::write_exr_channels(&dir.path().join("th.exr"), 4, 2, &[("thickness", &th)])
        .unwrap();
    // An 8-bit PNG: sRGB 188 ≈ linear 0.5.
    image::RgbImage::from_pixel(2, 2, image::Rgb([188, 0, 255]))
        .save(dir.path().join("c.png"))
        .unwrap();
    let s = load_in(
        dir.path(),
        r#"<shape type="rectangle"><bsdf type="thinfilm">
             <texture type="bitmap" name="thickness">
               <string name="filename" value="th.exr"/>
               <boolean name="raw" value="true"/>
               <string name="filter_type" value="nearest"/>
               <string name="wrap_mode" value="clamp"/>
               <transform name="to_uv"><scale x="0.5"/><translate x="0.25"/></transform>
             </texture></bsdf></shape>
           <shape type="rectangle"><bsdf type="diffuse">
             <texture type="bitmap" name="reflectance"><string name="filename" value="c.png"/></texture>
           </bsdf></shape>
           <shape type="rectangle"><bsdf type="diffuse">
             <texture type="bitmap" name="reflectance"><string name="filename" value="c.png"/><boolean name="raw" value="true"/></texture>
           </bsdf></shape>"#,
    )
    .unwrap();
    match film(s.bsdfs[s.shapes[0].bsdf].clone()).1 {
        TextureDesc::Bitmap(b) => {
            assert_eq!((b.width, b.height, b.channels), (4, 2, 1));
            assert_eq!(b.filter, TextureFilter::Nearest);
            assert_eq!(b.wrap, WrapMode::Clamp);
            // uv (0.5, 0.25) → to_uv → (0.5, 0.25) → texel (2, 0) = 200 nm.
            assert_eq!(b.eval_scalar(Vec2::new(0.5, 0.25)), 200.0);
            // uv (0, 0.75) → (0.25, 0.75) → texel (1, 1) = 500 nm.
            assert_eq!(b.eval_scalar(Vec2::new(0.0, 0.75)), 500.0);
        }
        b => panic!("{b:?}"),
    }
    let texel = |i: usize| match reflectance(&s.bsdfs[s.shapes[i].bsdf]) {
        TextureDesc::Bitmap(b) => b.eval(Vec2::new(0.5, 0.5)),
        t => panic!("{t:?}"),
    };
    let lin = texel(1);
    assert!(
        (lin[0] - 0.5029).abs() < 1e-3 && lin[1] == 0.0 && (lin[2] - 1.0).abs() < 1e-6,
        "{lin:?}"
    );
    let raw = texel(2);
    assert!((raw[0] - 188.0 / 255.0).abs() < 1e-4, "{raw:?}");
    assert!(err(r#"<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="c.png"/><string name="wrap_mode" value="tile"/></texture></bsdf></shape>"#).contains("not found"));
    let e = format!("{:#}", load_in(dir.path(), r#"<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="c.png"/><string name="wrap_mode" value="tile"/></texture></bsdf></shape>"#).unwrap_err());
    assert!(e.contains("wrap_mode \"tile\""), "{e}");
    assert!(err(r#"<texture type="noise" id="n"/>"#).contains("\"noise\""));
}

#[test]
fn shapes_and_emitters() {
    let dir = tempfile::tempdir().unwrap();
    let env = thinfilm::image_io::RgbImage {
        width: 4,
        height: 2,
        pixels: vec![[1.0, 0.5, 0.25]; 8],
    };
    thinfilm::image_io::write_exr_rgb(&dir.path().join("env.exr"), &env).unwrap();
    let s = load_in(
        dir.path(),
        r#"<emitter type="envmap">
             <string name="filename" value="env.exr"/>
             <float name="scale" value="2"/>
             <transform name="to_world"><rotate y="1" angle="90"/></transform>
           </emitter>
           <shape type="sphere">
             <point name="center" x="1" y="0" z="0"/><float name="radius" value="0.5"/>
             <transform name="to_world"><scale value="2"/><translate z="1"/></transform>
             <boolean name="flip_normals" value="true"/>
           </shape>
           <shape type="rectangle" id="light">
             <transform name="to_world"><translate z="3"/></transform>
             <boolean name="flip_normals" value="true"/>
             <emitter type="area"><rgb name="radiance" value="10"/></emitter>
           </shape>
           <shape type="disk"><boolean name="face_normals" value="true"/></shape>
           <shape type="cube"><transform name="to_world"><scale x="2"/></transform></shape>"#,
    )
    .unwrap();
    match &s.emitters[0] {
        EmitterDesc::Envmap {
            image,
            scale,
            to_world,
            path,
        } => {
            assert_eq!((image.width, image.height, *scale), (4, 2, 2.0));
            assert_eq!(image.pixels[0], [1.0, 0.5, 0.25]);
            assert!(to_world.abs_diff_eq(Mat4::from_rotation_y(90f32.to_radians()), 1e-6));
            assert!(path.as_ref().unwrap().ends_with("env.exr"));
        }
        e => panic!("{e:?}"),
    }
    match &s.shapes[0].geometry {
        Geometry::Sphere {
            center,
            radius,
            flip_normals,
            ..
        } => {
            assert!((*center - Vec3::new(2.0, 0.0, 1.0)).length() < 1e-6);
            assert!((*radius - 1.0).abs() < 1e-6);
            assert!(*flip_normals);
        }
        g => panic!("{g:?}"),
    }
    let light = &s.shapes[1];
    assert_eq!(light.name.as_deref(), Some("light"));
    assert_eq!(light.emission, Some(SpectrumDesc::Rgb([10.0; 3])));
    match &light.geometry {
        Geometry::Mesh(m) => {
            assert!(m.positions.iter().all(|p| p.z == 3.0));
            assert!(m.normals.iter().all(|n| *n == -Vec3::Z));
            let [a, b, c] = m.indices[0].map(|i| m.positions[i as usize]);
            assert!((b - a).cross(c - a).z < 0.0, "winding follows flip_normals");
        }
        g => panic!("{g:?}"),
    }
    match &s.shapes[2].geometry {
        Geometry::Mesh(m) => assert!(m.normals.is_empty() && !m.uvs.is_empty()),
        g => panic!("{g:?}"),
    }
    match &s.shapes[3].geometry {
        Geometry::Mesh(m) => {
            let (lo, hi) = m.bounds().unwrap();
            assert_eq!(
                (lo, hi),
                (Vec3::new(-2.0, -1.0, -1.0), Vec3::new(2.0, 1.0, 1.0))
            );
            assert_eq!(m.indices.len(), 12);
        }
        g => panic!("{g:?}"),
    }
    let e = err(
        r#"<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>"#,
    );
    assert!(e.contains("similarity"), "{e}");
    assert!(err(r#"<shape type="torus"/>"#).contains("\"torus\""));
    assert!(err(r#"<shape type="cube"><emitter type="constant"/></shape>"#).contains("area"));
}

/// A 2 × 2 quad in z = 0 facing +z as a PLY with per-vertex colours: binary with `uchar`
/// red/green/blue, or ascii with float r/g/b; vertices (−1,−1), (1,−1), (1,1), (−1,1).
fn coloured_quad_ply(path: &Path, colors: [[f32; 3]; 4], binary_u8: bool) {
    let xy = [[-1.0f32, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
    let (format, ty, names) = if binary_u8 {
        ("binary_little_endian", "uchar", ["red", "green", "blue"])
    } else {
        ("ascii", "float", ["r", "g", "b"])
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    )
    .into_bytes();
    for n in names {
        out.extend(format!("property {ty} {n}\n").bytes());
    }
    out.extend(b"element face 2\nproperty list uchar int vertex_indices\nend_header\n");
    for (p, c) in xy.iter().zip(colors) {
        if binary_u8 {
            for v in [p[0], p[1], 0.0] {
                out.extend(v.to_le_bytes());
            }
            out.extend(c.map(|v| (v * 255.0).round() as u8));
        } else {
            out.extend(format!("{} {} 0 {} {} {}\n", p[0], p[1], c[0], c[1], c[2]).bytes());
        }
    }
    for f in [[0i32, 1, 2], [0, 2, 3]] {
        if binary_u8 {
            out.push(3);
            for i in f {
                out.extend(i.to_le_bytes());
            }
        } else {
            out.extend(format!("3 {} {} {}\n", f[0], f[1], f[2]).bytes());
        }
    }
    std::fs::write(path, out).unwrap();
}

/// The quad of `ply` with a diffuse `mesh_attribute` reflectance, seen head-on in a white
/// furnace (radiance 1: a Lambert surface shows its albedo), 8 × 1 pixels over x ∈ ±0.8.
fn furnace_row(dir: &Path, ply: &str) -> Vec<[f32; 3]> {
    let scene = load_in(
        dir,
        &format!(
            r#"<sensor type="perspective"><float name="fov" value="30"/>
                 <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
                 <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="1"/></film>
               </sensor>
               <emitter type="constant"><float name="radiance" value="1"/></emitter>
               <shape type="ply"><string name="filename" value="{ply}"/>
                 <bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">
                   <string name="name" value="vertex_color"/></texture></bsdf></shape>"#
        ),
    )
    .unwrap();
    let out = thinfilm::render::render(
        &scene,
        &thinfilm::render::RenderOptions {
            spp: Some(64),
            seed: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(out.image.width, 8);
    out.image.pixels
}

/// Mitsuba's `mesh_attribute` texture: a PLY's vertex colours (u8 normalised by 255, floats
/// as stored) become the diffuse albedo, interpolated across the triangles; a mesh without
/// them, or another attribute, is refused naming the shape / the attribute.
#[test]
fn mesh_attribute_vertex_colors() {
    let dir = tempfile::tempdir().unwrap();
    let grey = [[128.0 / 255.0; 3]; 4];
    coloured_quad_ply(&dir.path().join("grey.ply"), grey, true);
    coloured_quad_ply(&dir.path().join("white.ply"), [[1.0; 3]; 4], false);
    // Relative to white float colours (a flat spectrum is not RGB (1, 1, 1) on the film).
    let white = furnace_row(dir.path(), "white.ply");
    for (p, w) in furnace_row(dir.path(), "grey.ply").iter().zip(&white) {
        for c in 0..3 {
            let r = p[c] / w[c];
            assert!(
                (r - 128.0 / 255.0).abs() < 0.005,
                "grey u8 128: {p:?} / {w:?}"
            );
        }
    }
    // Red on the left edge (x = −1), blue on the right (x = 1): a linear blend along x.
    let (red, blue) = ([0.9, 0.05, 0.05], [0.05, 0.05, 0.9]);
    coloured_quad_ply(&dir.path().join("ramp.ply"), [red, blue, blue, red], false);
    let row = furnace_row(dir.path(), "ramp.ply");
    assert!(row[0][0] > 3.0 * row[0][2], "left is red: {row:?}");
    assert!(row[7][2] > 3.0 * row[7][0], "right is blue: {row:?}");
    for w in row.windows(2) {
        assert!(
            w[1][0] < w[0][0] && w[1][2] > w[0][2],
            "monotone ramp: {row:?}"
        );
    }
    // Refusals: a mesh without the attribute, a name Mitsuba refuses, a parameter that takes
    // no texture (tests/scene_mesh_attributes.rs has the attributes on other BSDFs).
    let e = err(
        r#"<shape type="rectangle" id="plain"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">
             <string name="name" value="vertex_color"/></texture></bsdf></shape>"#,
    );
    assert!(e.contains("rectangle") && e.contains("vertex_color"), "{e}");
    let e = err(
        r#"<texture type="mesh_attribute" id="t"><string name="name" value="weight"/></texture>"#,
    );
    assert!(e.contains("\"weight\"") && e.contains("vertex_"), "{e}");
    let e = err(
        r#"<shape type="rectangle"><bsdf type="roughplastic"><texture type="mesh_attribute" name="alpha">
             <string name="name" value="vertex_color"/></texture></bsdf></shape>"#,
    );
    // (roughplastic's α is a number in Mitsuba too.)
    assert!(e.contains("'alpha'") && e.contains("texture"), "{e}");
}
