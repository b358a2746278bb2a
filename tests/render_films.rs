//! Free-standing films, multilayer stacks and dispersion end to end: scene syntax,
//! effect analysis, the bubble white furnace, and the proof that secondary wavelengths are
//! terminated only where a scene declares dispersion.

use std::path::Path;
use thinfilm::render::bsdf::Bsdf;
use thinfilm::render::counters::{self, Counters};
use thinfilm::render::{effects, integrator, prepare, sampler::Sampler};
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::{mitsuba, Scene};
use thinfilm::spectrum::SampledWavelengths;

fn scenes_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes"))
}

fn load(text: &str) -> anyhow::Result<Scene> {
    mitsuba::load_str(text, scenes_dir(), &[], "test.xml")
}

fn load_file(name: &str, defines: &[(&str, &str)]) -> Scene {
    let d: Vec<(String, String)> = defines
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    mitsuba::load_file(&scenes_dir().join(name), &d).unwrap()
}

/// A scene with one shape using `bsdf` (XML) in a constant white environment.
fn furnace_scene(shape: &str, bsdf: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="-1"/></integrator>
            <sensor type="perspective">
                <float name="fov" value="40"/>
                <transform name="to_world"><lookat origin="0, -4, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
                <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
            </sensor>
            <emitter type="constant"><spectrum name="radiance" value="1"/></emitter>
            <shape type="{shape}">{bsdf}</shape>
        </scene>"#
    )
}

/// Mean radiance over `n` paths through each film position at four fixed wavelengths, and the
/// worst relative deviation from 1 over positions and wavelengths.
fn furnace_deviation(scene: &Scene, n: u32) -> (f32, Counters) {
    let prepared = prepare(scene, &RenderOptions::default()).unwrap();
    counters::take();
    let mut worst = 0.0f32;
    for k in 0..9 {
        let uv = glam::Vec2::new(0.3 + 0.2 * (k % 3) as f32, 0.3 + 0.2 * (k / 3) as f32);
        let mut sum = [0.0f64; 4];
        for s in 0..n {
            let mut sampler = Sampler::for_sample(k, 0, s, 1);
            let mut wl = SampledWavelengths::new([410.0, 495.0, 580.0, 665.0], [1.0; 4]);
            let ray = prepared.camera().generate_ray(uv);
            let l = integrator::li(&prepared, ray, None, &mut wl, &mut sampler);
            for (s, v) in sum.iter_mut().zip(l.to_array()) {
                *s += v as f64;
            }
        }
        for s in sum {
            worst = worst.max((s / n as f64 - 1.0).abs() as f32);
        }
    }
    (worst, counters::take())
}

const BUBBLE_TEXTURED: &str = r#"<bsdf type="thinfilm_bubble">
        <float name="film_ior" value="1.33"/>
        <texture type="bitmap" name="thickness">
            <string name="filename" value="textures/bubble_thickness.exr"/>
            <boolean name="raw" value="true"/>
        </texture>
    </bsdf>"#;

/// White furnace: a lossless soap bubble (textured thickness, and a thick constant film) in a
/// constant environment of radiance 1 renders 1 ± 1 % at every film position and wavelength:
/// R + T = 1 and the lobe choice/weights are unbiased through any number of film crossings.
#[test]
fn bubble_white_furnace() {
    for bsdf in [
        BUBBLE_TEXTURED.to_string(),
        r#"<bsdf type="thinfilm_bubble"><string name="film_ior" value="water"/><float name="thickness" value="800"/></bsdf>"#.to_string(),
    ] {
        let scene = load(&furnace_scene("sphere", &bsdf)).unwrap();
        // 64k paths: the defensive lobe choice (P ≥ 0.25 per lobe) is unbiased but, unlike the
        // Fresnel-proportional one, not zero-variance in a furnace.
        let (dev, c) = furnace_deviation(&scene, 64000);
        eprintln!("bubble furnace: worst deviation {dev:.4} over 9 positions × 4 wavelengths");
        assert!(dev < 0.01, "bubble furnace deviation {dev} for {bsdf}");
        assert_eq!(c.invalid_samples, 0);
        assert!(c.film_evals > 0);
    }
    // A glass sphere under an AR coating (both sides of every crossing, TIR inside): R + T = 1
    // and the η² radiance factors cancel.
    let coated = r#"<bsdf type="coateddielectric"><float name="int_ior" value="1.5168"/><float name="ext_ior" value="1"/><string name="coating" value="MgF2:99.6"/></bsdf>"#;
    let (dev, c) = furnace_deviation(&load(&furnace_scene("sphere", coated)).unwrap(), 4000);
    eprintln!("coated glass furnace: worst deviation {dev:.4}");
    assert!(dev < 0.01, "coated dielectric furnace deviation {dev}");
    assert_eq!(c.invalid_samples, 0);
    // The same furnace *fails* for an absorbing film (the test can fail).
    let lossy = r#"<bsdf type="thinfilm_bubble"><string name="film_ior" value="1.5+0.05i"/><float name="thickness" value="800"/></bsdf>"#;
    let (dev, _) = furnace_deviation(&load(&furnace_scene("sphere", lossy)).unwrap(), 500);
    assert!(dev > 0.05, "absorbing film should darken: {dev}");
}

/// Secondary wavelengths are terminated only where the scene declares a dispersive index:
/// the prism scene with its Sellmeier glass terminates many paths; the same scene with a
/// constant index, and the bubble and coating scenes, terminate none.
#[test]
fn dispersion_only_when_declared() {
    let count = |scene: &Scene| {
        let out = prepare(
            scene,
            &RenderOptions {
                resolution: Some((24, 24)),
                ..Default::default()
            },
        )
        .unwrap();
        counters::take();
        for y in 0..24 {
            for x in 0..24 {
                let mut sampler = Sampler::for_sample(x, y, 0, 0);
                let mut wl = SampledWavelengths::new([420.0, 500.0, 580.0, 660.0], [1.0; 4]);
                let uv = glam::Vec2::new((x as f32 + 0.5) / 24.0, (y as f32 + 0.5) / 24.0);
                let ray = out.camera().generate_ray(uv);
                integrator::li(&out, ray, None, &mut wl, &mut sampler);
            }
        }
        (
            counters::take().secondary_terminations,
            out.effects().dispersion,
        )
    };
    let (n, on) = count(&load_file("prism.xml", &[]));
    assert!(on && n > 20, "prism: {n} terminations, dispersion {on}");
    let (n, on) = count(&load_file("prism.xml", &[("glass", "1.7847")]));
    assert_eq!((n, on), (0, false), "constant-index prism");
    for s in [
        "bubble.xml",
        "coatings.xml",
        "lens.xml",
        "teapot_mgf2_400.xml",
    ] {
        assert_eq!(count(&load_file(s, &[])), (0, false), "{s}");
    }
}

/// The effect log names exactly what each scene calls for.
#[test]
fn effect_analysis_reports_films_and_stacks() {
    let line = |e: &effects::Effects, key: &str| {
        e.lines()
            .into_iter()
            .find(|r| r.starts_with(key))
            .unwrap_or_default()
    };
    let e = effects::analyze(&load_file("bubble.xml", &[])).unwrap();
    assert!(e.bubble && e.interference && e.thickness_texture && !e.stack && !e.dispersion);
    assert!(line(&e, "free-standing film: ON").contains("1.33"), "{e}");
    let e = effects::analyze(&load_file("coatings.xml", &[])).unwrap();
    assert!(e.stack && !e.bubble && !e.rough);
    let l = line(&e, "multilayer stack: ON");
    assert!(l.contains("MgF2:99.6") && l.contains("13 layers"), "{l}");
    let e = effects::analyze(&load_file("teapot_mgf2_400.xml", &[])).unwrap();
    assert!(!e.bubble && !e.stack);
    assert!(!line(&e, "free-standing film: off").is_empty());
    assert!(!line(&e, "multilayer stack: off").is_empty());
    let e = effects::analyze(&load_file("lens.xml", &[])).unwrap();
    assert!(e.stack && !e.dispersion, "{e}");
    assert!(
        line(&e, "multilayer stack: ON").contains("coating [MgF2:99.6]"),
        "{e}"
    );
    let e = effects::analyze(&load_file("prism.xml", &[])).unwrap();
    assert!(e.dispersion && !e.interference);
}

/// Scene syntax: layers (names, numbers, n+ki, repeated groups), bubble defaults, dielectric
/// indices (Mitsuba names stay constant; material:/cauchy:/sellmeier:/library names disperse),
/// and clear errors.
#[test]
fn scene_syntax_for_films_stacks_and_dispersion() {
    let bsdf = |xml: &str| -> anyhow::Result<Bsdf> {
        let s = load(&format!(
            r#"<scene version="3.0.0"><shape type="sphere">{xml}</shape></scene>"#
        ))?;
        Ok(s.bsdfs[s.shapes[0].bsdf].clone())
    };
    match bsdf(r#"<bsdf type="thinfilm"><string name="layers" value="MgF2:100; 2.3:50, 1.5+0.1i:10, (TiO2:5, SiO2:6)x3"/><string name="substrate_ior" value="Au"/><float name="alpha" value="0.1"/></bsdf>"#).unwrap() {
        Bsdf::Stack(b) => {
            let (layers, substrate_ior, alpha) = (b.layers, b.substrate_ior, b.ggx.unwrap().alpha_u);
            assert_eq!(layers.len(), 9);
            assert_eq!(layers[0].1, 100.0);
            assert!(layers[0].0.is_dispersive());
            assert_eq!(layers[1].0.at(500.0).re, 2.3);
            assert_eq!(layers[2].0.at(500.0).im, 0.1);
            assert_eq!(layers[8].1, 6.0);
            assert_eq!(substrate_ior.to_string(), "Au");
            assert_eq!(alpha, 0.1);
        }
        other => panic!("{other:?}"),
    }
    match bsdf(r#"<bsdf type="thinfilm_bubble"/>"#).unwrap() {
        Bsdf::Bubble(b) => {
            assert_eq!(b.film_ior.at(500.0).re, 1.33);
            assert_eq!(b.ext_ior, 1.0);
        }
        other => panic!("{other:?}"),
    }
    let dielectric = |v: &str| match bsdf(&format!(
        r#"<bsdf type="dielectric"><string name="int_ior" value="{v}"/></bsdf>"#
    )) {
        Ok(Bsdf::Dielectric(d)) => Ok(d.int_ior),
        Ok(other) => panic!("{other:?}"),
        Err(e) => Err(format!("{e:#}")),
    };
    // Mitsuba's IOR table wins for bare names: the scene renders as in Mitsuba.
    let bk7 = dielectric("bk7").unwrap();
    assert!(!bk7.is_dispersive() && bk7.at(500.0).re == 1.5046);
    for v in [
        "material:BK7",
        "SiO2",
        "cauchy:1.5046,4200",
        "sellmeier:1.03961212,0.00600069867",
    ] {
        assert!(dielectric(v).unwrap().is_dispersive(), "{v}");
    }
    // Tabulated spectrum → dispersive too.
    match bsdf(
        r#"<bsdf type="dielectric"><spectrum name="int_ior" value="400:1.53, 700:1.51"/></bsdf>"#,
    )
    .unwrap()
    {
        Bsdf::Dielectric(d) => assert!(d.int_ior.is_dispersive()),
        other => panic!("{other:?}"),
    }
    // Errors name the problem and the line.
    for (xml, want) in [
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="MgF2"/></bsdf>"#,
            "MgF2:100",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="MgF2:-3"/></bsdf>"#,
            "≥ 0",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="Unobtainium:30"/></bsdf>"#,
            "Unobtainium",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="(MgF2:3"/></bsdf>"#,
            "unbalanced",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="(MgF2:3)x0"/></bsdf>"#,
            "xN",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="MgF2:3,"/></bsdf>"#,
            "empty layer",
        ),
        (
            r#"<bsdf type="thinfilm"><string name="layers" value="MgF2:3"/><float name="thickness" value="3"/></bsdf>"#,
            "cannot be combined",
        ),
        (
            r#"<bsdf type="thinfilm_bubble"><float name="thickness" value="-1"/></bsdf>"#,
            "'thickness' = -1 is outside [0, 20000]",
        ),
        (
            r#"<bsdf type="thinfilm_bubble"><string name="ext_ior" value="water"/></bsdf>"#,
            "constant real",
        ),
        (
            r#"<bsdf type="dielectric"><string name="int_ior" value="Au"/></bsdf>"#,
            "absorbs",
        ),
        (
            r#"<bsdf type="dielectric"><string name="int_ior" value="cauchy:1.5"/></bsdf>"#,
            "cauchy",
        ),
        (
            r#"<bsdf type="dielectric"><string name="int_ior" value="glass?"/></bsdf>"#,
            "Mitsuba IOR names",
        ),
    ] {
        let err = format!("{:#}", bsdf(xml).unwrap_err());
        assert!(
            err.contains(want) && err.contains("test.xml:"),
            "{xml}: {err}"
        );
    }
}

/// The new scenes render without NaN or discarded samples.
#[test]
fn new_scenes_render_finite() {
    for name in ["bubble.xml", "coatings.xml", "prism.xml", "lens.xml"] {
        let out = render(
            &load_file(name, &[]),
            &RenderOptions {
                spp: Some(4),
                resolution: Some((32, 32)),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(out.stats.invalid_samples, 0, "{name}");
        assert!(
            // (Saturated spectra may map to slightly negative linear sRGB: only finiteness.)
            out.image.pixels.iter().flatten().all(|v| v.is_finite()),
            "{name}"
        );
    }
}
