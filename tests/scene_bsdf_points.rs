//! BSDFs read from Mitsuba XML agree with Mitsuba 3's own `eval` and `pdf`, per wavelength:
//! tests/references/bsdf_spectral_points.json holds XML snippets (RGB conductor `eta`/`k`,
//! `specular_reflectance` / `specular_transmittance` ≠ 1) and Mitsuba's `scalar_spectral`
//! values at four wavelengths (tools/mitsuba/bsdf_point_references.py). The same XML text is
//! loaded here, so the parser's handling (Mitsuba clamps RGB indices to [0, 1] before
//! upsampling them like reflectances) is checked with the models.

use glam::{Vec2, Vec3};
use std::path::Path;
use thinfilm::render::bsdf::{Bsdf, ShadingCtx};
use thinfilm::scene::mitsuba::load_str;
use thinfilm::spectrum::SampledWavelengths;

fn bsdf_of(xml: &str) -> Bsdf {
    let scene = format!("<scene version=\"3.0.0\"><shape type=\"sphere\">{xml}</shape></scene>");
    let s = load_str(&scene, Path::new("."), &[], "points.xml").unwrap();
    s.bsdfs[s.shapes[0].bsdf].clone()
}

fn vec3(v: &serde_json::Value) -> Vec3 {
    let a: Vec<f32> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect();
    Vec3::new(a[0], a[1], a[2])
}

/// A reference file's JSON and the four wavelengths its values were taken at.
fn reference_points(json: &str) -> (serde_json::Value, SampledWavelengths) {
    let doc: serde_json::Value = serde_json::from_str(json).unwrap();
    let lambda: Vec<f32> = doc["wavelengths"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect();
    let wl = SampledWavelengths::new([lambda[0], lambda[1], lambda[2], lambda[3]], [1.0; 4]);
    (doc, wl)
}

/// A shading context at `wl` with no texture, vertex colour or bump.
fn ctx_at(wl: &SampledWavelengths) -> ShadingCtx<'_> {
    ShadingCtx {
        wl,
        uv: Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    }
}

/// Within 1 % per wavelength (Mitsuba's Beckmann G1 is a rational fit, 0.35 % off; its
/// upsampling table is its own fit of the same method as thinfilm's).
#[test]
fn rgb_indices_and_specular_factors_match_mitsuba() {
    let (doc, wl) = reference_points(include_str!("references/bsdf_spectral_points.json"));
    let ctx = ctx_at(&wl);
    let points = doc["points"].as_array().unwrap();
    assert!(points.len() >= 16);
    for (k, p) in points.iter().enumerate() {
        let xml = p["xml"].as_str().unwrap();
        let b = bsdf_of(xml);
        let (wi, wo) = (vec3(&p["wi"]), vec3(&p["wo"]));
        let value = b.eval(&ctx, wi, wo).to_array();
        for (i, r) in p["eval"].as_array().unwrap().iter().enumerate() {
            let r = r.as_f64().unwrap();
            let v = value[i] as f64;
            assert!(
                (v - r).abs() <= 0.01 * r + 1e-5,
                "#{k} {xml} λ={}: eval {v} vs Mitsuba {r}",
                wl.lambda[i]
            );
        }
        let pdf = b.pdf(&ctx, wi, wo) as f64;
        let r = p["pdf"].as_f64().unwrap();
        assert!(
            (pdf - r).abs() <= 0.01 * r + 1e-5,
            "#{k} {xml}: pdf {pdf} vs Mitsuba {r}"
        );
    }
}

/// A textured specular factor and textured roughness are read, not refused: a checkerboard
/// `specular_reflectance` darkens the lobe where it is 0.25, and a checkerboard `alpha`
/// narrows the lobe (a higher peak) where α is small — on the squares where the same
/// checkerboard *as a colour* shows color1, because Mitsuba's `eval_1` (roughness) swaps the
/// squares of its `eval` (colour).
#[test]
fn textured_factor_and_roughness_vary_over_the_surface() {
    let wl = SampledWavelengths::new([450.0, 520.0, 600.0, 680.0], [1.0; 4]);
    let at = |uv: Vec2| ShadingCtx {
        wl: &wl,
        uv,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    let (a, b) = (Vec2::new(0.25, 0.25), Vec2::new(0.75, 0.25));
    let wi = Vec3::new(0.3, 0.1, 0.95).normalize();
    let wo = Vec3::new(-wi.x, -wi.y, wi.z);
    let checker = |name: &str, c0: f32, c1: f32| {
        format!(
            r#"<texture name="{name}" type="checkerboard"><float name="color0" value="{c0}"/><float name="color1" value="{c1}"/></texture>"#
        )
    };
    let factor = bsdf_of(&format!(
        r#"<bsdf type="roughconductor"><float name="alpha" value="0.2"/>{}</bsdf>"#,
        checker("specular_reflectance", 1.0, 0.25)
    ));
    let (fa, fb) = (
        factor.eval(&at(a), wi, wo)[0],
        factor.eval(&at(b), wi, wo)[0],
    );
    assert!((fb / fa - 0.25).abs() < 1e-4, "{fa} {fb}");
    let rough = bsdf_of(&format!(
        r#"<bsdf type="roughconductor">{}</bsdf>"#,
        checker("alpha", 0.05, 0.4)
    ));
    let (ra, rb) = (rough.eval(&at(a), wi, wo)[0], rough.eval(&at(b), wi, wo)[0]);
    assert!(rb > 10.0 * ra, "peak at α=0.05 {rb} vs α=0.4 {ra}");
    assert!(rough
        .flags()
        .intersects(thinfilm::render::bsdf::BsdfFlags::GLOSSY));
}

/// The polarised forms agree with Mitsuba 3's `scalar_spectral_polarized` Mueller matrices
/// (tests/references/bsdf_mueller_points.json: `pplastic`), every element within 1 % of that
/// wavelength's M₀₀, once thinfilm's value is re-expressed in Mitsuba's implicit Stokes bases
/// (stokes_basis(−wo) for the arriving light, stokes_basis(wi) for the leaving light).
#[test]
fn mueller_matrices_match_mitsuba() {
    use thinfilm::render::bsdf::MuellerValue;
    use thinfilm::render::polarization::{stokes_basis, Mueller};
    let (doc, wl) = reference_points(include_str!("references/bsdf_mueller_points.json"));
    let ctx = ctx_at(&wl);
    let points = doc["points"].as_array().unwrap();
    assert!(points.len() >= 8);
    let mut polarizing = 0;
    for (k, p) in points.iter().enumerate() {
        let xml = p["xml"].as_str().unwrap();
        let b = bsdf_of(xml);
        let (wi, wo) = (vec3(&p["wi"]), vec3(&p["wo"]));
        let value = b.polarized().unwrap().eval_mueller(&ctx, wi, wo);
        let implicit = MuellerValue::polarizing(
            [Mueller([[0.0; 4]; 4]); 4],
            stokes_basis(-wo),
            stokes_basis(wi),
        )
        .plus(value, wi, wo);
        let lobe = implicit.polarized.expect("a polarising lobe");
        let r = &p["eval"];
        for w in 0..4 {
            let want = |i: usize, j: usize| r[i][j][w].as_f64().unwrap() as f32;
            let tol = 0.01 * want(0, 0) + 1e-5;
            for i in 0..4 {
                for j in 0..4 {
                    let mut got = lobe.m[w].0[i][j];
                    if i == 0 && j == 0 {
                        got += value.depolarized[w];
                    }
                    assert!(
                        (got - want(i, j)).abs() <= tol,
                        "#{k} {xml} λ={} M[{i}][{j}]: {got} vs Mitsuba {}",
                        wl.lambda[w],
                        want(i, j)
                    );
                }
            }
            polarizing += usize::from(want(1, 0).abs() > 100.0 * 1e-5);
        }
    }
    // The references do polarise (the comparison is not only of M₀₀).
    assert!(polarizing > points.len(), "{polarizing}");
}
