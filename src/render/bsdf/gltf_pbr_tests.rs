//! Tests of the glTF material: χ² of the sampled directions, eval/pdf/sample agreement, the
//! layers' limits (no film = zero thickness = factor 0; a metal's F0 is its base colour),
//! energy of lossless glass with and without a film, sidedness, absorption, validation.

use super::*;
use crate::render::bsdf::tests::{
    assert_chi2, assert_eval_pdf_sample_agree, ctx_of, dir, wl,
};
use crate::render::bsdf::Bsdf;

fn mat(f: impl FnOnce(&mut GltfMaterial)) -> Bsdf {
    let mut m = GltfMaterial::default();
    f(&mut m);
    GltfPbr::new(m).unwrap().into()
}

fn film(ior: f32, d: f32, factor: f32) -> Option<Iridescence> {
    Some(Iridescence {
        factor,
        factor_texture: None,
        ior,
        thickness_min_nm: 0.0,
        thickness_max_nm: d,
        thickness_texture: None,
    })
}

fn volume() -> Option<Volume> {
    Some(Volume {
        attenuation_color: [1.0; 3],
        attenuation_distance: f32::INFINITY,
    })
}

fn cases() -> Vec<(&'static str, Bsdf)> {
    vec![
        (
            "dielectric",
            mat(|m| {
                m.base_color = [0.4, 0.4, 0.4, 1.0];
                m.metallic = 0.0;
                m.roughness = 0.4;
            }),
        ),
        (
            "dielectric+film",
            mat(|m| {
                m.base_color = [0.4, 0.5, 0.6, 1.0];
                m.metallic = 0.0;
                m.roughness = 0.3;
                m.ior = 2.0;
                m.iridescence = film(1.33, 400.0, 1.0);
            }),
        ),
        (
            "metal+film",
            mat(|m| {
                m.base_color = [0.9, 0.6, 0.3, 1.0];
                m.metallic = 0.7;
                m.roughness = 0.5;
                m.iridescence = film(1.33, 400.0, 0.6);
            }),
        ),
        (
            "rough glass+film",
            mat(|m| {
                m.metallic = 0.0;
                m.roughness = 0.5;
                m.transmission = 1.0;
                m.volume = volume();
                m.iridescence = film(1.8, 300.0, 1.0);
            }),
        ),
        (
            "thin-walled",
            mat(|m| {
                m.metallic = 0.0;
                m.roughness = 0.5;
                m.transmission = 0.6;
            }),
        ),
        (
            "blend",
            mat(|m| {
                m.base_color = [0.8, 0.2, 0.2, 0.5];
                m.alpha_mode = AlphaMode::Blend;
                m.metallic = 0.0;
                m.roughness = 0.6;
                m.double_sided = true;
            }),
        ),
    ]
}

#[test]
fn chi2_sampled_directions_match_pdf() {
    let cases = cases();
    let threshold = 1.0 - (1.0 - 0.01f64).powf(1.0 / (cases.len() * 3) as f64);
    for (name, b) in &cases {
        assert_chi2(name, b, threshold);
    }
}

#[test]
fn eval_pdf_sample_agree() {
    for (name, b) in cases() {
        assert_eval_pdf_sample_agree(name, &b);
    }
}

#[test]
fn gulbrandsen_index_reproduces_f0() {
    for r in [0.02f32, 0.4, 0.9, 0.98] {
        for g in [0.0f32, 0.5, 1.0] {
            let z = gulbrandsen_index(r, g);
            let (n, k) = (z.re, z.im);
            let f0 = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
            assert!((f0 - r).abs() < 1e-4, "r={r} g={g}: n={n} k={k} F0={f0}");
            assert!((fresnel_conductor_f0(n, k) - r).abs() < 1e-4);
        }
    }
    // White edge tint: the smallest n, (1 − r)/(1 + r), all reflectance from k; no tint:
    // a lossless index (k = 0) of the same F0.
    let z = gulbrandsen_index(0.95, 1.0);
    assert!((z.re - 0.05 / 1.95).abs() < 1e-6 && z.im > 0.9, "{z}");
    assert!(gulbrandsen_index(0.5, 0.0).im < 0.01);
}

fn fresnel_conductor_f0(n: f32, k: f32) -> f32 {
    crate::render::bsdf::fresnel::fresnel_conductor(1.0, n, k)
}

/// The specular layer's Fresnel term (dielectric, metal) at cos θ.
fn fresnel_of(b: &Bsdf, c: f32) -> (Spec, Spec) {
    let Bsdf::GltfPbr(p) = b else { unreachable!() };
    let wl = wl();
    let ctx = ctx_of(&wl);
    let pt = Point::at(p, &ctx, false);
    pt.fresnel(p, &ctx, c)
}

#[test]
fn film_limits_are_the_bare_base() {
    for metallic in [0.0, 1.0] {
        let base = |f: Option<Iridescence>| {
            mat(|m| {
                m.base_color = [0.9, 0.5, 0.2, 1.0];
                m.metallic = metallic;
                m.roughness = 0.3;
                m.ior = 1.7;
                m.iridescence = f;
            })
        };
        for c in [1.0, 0.7, 0.3, 0.05] {
            let bare = fresnel_of(&base(None), c);
            for f in [film(1.33, 0.0, 1.0), film(1.33, 400.0, 0.0)] {
                let zero_thickness = f.as_ref().is_some_and(|f| f.factor > 0.0);
                let with = fresnel_of(&base(f), c);
                assert!((with.0 - bare.0).abs().max_element() < 1e-4, "{with:?} {bare:?}");
                // Under a film a metal without KHR_materials_specular is Gulbrandsen's index
                // at edge tint 0, the specification's dielectric of reflectance F0
                // (`metal_film_base`): at zero thickness its exact Fresnel curve, which meets
                // the bare (white-tint) metal's at normal incidence.
                let expect = if zero_thickness && metallic > 0.0 {
                    let Bsdf::GltfPbr(p) = &base(None) else { unreachable!() };
                    let wl = wl();
                    let f0 = Point::at(p, &ctx_of(&wl), false).base.to_array();
                    Spec::from_array(f0.map(|f| {
                        let s = f.sqrt();
                        fresnel_dielectric(c, (1.0 + s) / (1.0 - s)).0
                    }))
                } else {
                    bare.1
                };
                assert!((with.1 - expect).abs().max_element() < 1e-4, "{with:?} {expect:?}");
                if c == 1.0 {
                    assert!((with.1 - bare.1).abs().max_element() < 2e-3, "{with:?} {bare:?}");
                }
            }
            // A real film changes the reflectance; half the factor is half the change.
            let full = fresnel_of(&base(film(1.33, 400.0, 1.0)), c);
            let half = fresnel_of(&base(film(1.33, 400.0, 0.5)), c);
            let (a, b) = if metallic > 0.0 {
                (full.1, bare.1)
            } else {
                (full.0, bare.0)
            };
            assert!((a - b).abs().max_element() > 0.01, "c={c}: {a} vs {b}");
            let h = if metallic > 0.0 { half.1 } else { half.0 };
            assert!(((h - b) * 2.0 - (a - b)).abs().max_element() < 1e-4);
        }
    }
}

/// A film on a glTF metal sits on the real index the extension derives from F0: at normal
/// incidence the reflectance is the closed-form Airy sum |(r01 + r12 e^{iφ})/(1 + r01 r12
/// e^{iφ})|², φ = 4π n d/λ, with n_base = (1 + √F0)/(1 − √F0).
#[test]
fn film_on_a_metal_uses_the_specifications_base_index() {
    let b = mat(|m| {
        m.base_color = [0.8, 0.8, 0.8, 1.0];
        m.roughness = 0.3;
        m.iridescence = film(1.3, 600.0, 1.0);
    });
    let Bsdf::GltfPbr(p) = &b else { unreachable!() };
    let wl = wl();
    let f0 = Point::at(p, &ctx_of(&wl), false).base.to_array();
    let (_, f_m) = fresnel_of(&b, 1.0);
    for i in 0..4 {
        let s = (f0[i] as f64).sqrt();
        let nb = (1.0 + s) / (1.0 - s);
        let (r01, r12) = ((1.0 - 1.3) / 2.3, (1.3 - nb) / (1.3 + nb));
        let phi = 4.0 * std::f64::consts::PI * 1.3 * 600.0 / wl.lambda[i] as f64;
        let e = num_complex::Complex64::from_polar(1.0, phi);
        let r = ((e * r12 + r01) / (e * (r01 * r12) + 1.0)).norm_sqr();
        assert!((f_m[i] as f64 - r).abs() < 2e-3, "lane {i}: {} vs {r}", f_m[i]);
    }
}

/// With `KHR_materials_specular` the film on a metal sits on the bare metal's Gulbrandsen
/// index whose edge tint is the specular colour (× factor): a complex index (k > 0), and a
/// film of zero thickness on it reflects exactly as the bare tinted metal at every angle.
/// Without the extension the base is Gulbrandsen's index at g = 0, the extension's real
/// index (k = 0).
#[test]
fn film_on_a_metal_with_specular_colour_sits_on_its_tinted_complex_index() {
    let metal = |f: Option<Iridescence>, ext: bool| {
        mat(|m| {
            m.base_color = [0.9, 0.6, 0.3, 1.0];
            m.roughness = 0.3;
            m.has_specular_extension = ext;
            m.specular_color = [0.95, 0.5, 0.2];
            m.specular = 0.9;
            m.iridescence = f;
        })
    };
    let wl = wl();
    let ctx = ctx_of(&wl);
    let point = |b: &Bsdf| {
        let Bsdf::GltfPbr(p) = b else { unreachable!() };
        Point::at(p, &ctx, false)
    };
    let tinted = point(&metal(film(1.5, 0.0, 1.0), true));
    let plain = point(&metal(film(1.5, 0.0, 1.0), false));
    for i in 0..4 {
        assert!(tinted.metal_film[i].im > 0.1, "lane {i}: {}", tinted.metal_film[i]);
        assert_eq!(tinted.metal_film[i], tinted.metal[i]);
        // g = 0: Gulbrandsen's n is the real index from F0, its k only rounding.
        let g0 = gulbrandsen_index(plain.base[i], 0.0);
        assert_eq!(plain.metal_film[i].im, 0.0);
        assert!((g0.re - plain.metal_film[i].re).abs() < 1e-3 * g0.re, "{g0}");
        assert!(g0.im < 0.05, "{g0}");
    }
    for c in [1.0, 0.8, 0.5, 0.2, 0.05] {
        let bare = fresnel_of(&metal(None, true), c).1;
        let zero = fresnel_of(&metal(film(1.5, 0.0, 1.0), true), c).1;
        assert!((zero - bare).abs().max_element() < 1e-5, "cos {c}: {zero} vs {bare}");
        // A real film changes it, and the tint changes the film's colour.
        let thick = fresnel_of(&metal(film(1.5, 300.0, 1.0), true), c).1;
        let untinted = fresnel_of(&metal(film(1.5, 300.0, 1.0), false), c).1;
        assert!((thick - bare).abs().max_element() > 0.01, "cos {c}");
        assert!((thick - untinted).abs().max_element() > 0.01, "cos {c}");
    }
}

#[test]
fn a_metal_reflects_its_base_colour_at_normal_incidence() {
    let b = mat(|m| {
        m.base_color = [0.95, 0.64, 0.54, 1.0];
        m.roughness = 0.2;
    });
    let Bsdf::GltfPbr(p) = &b else { unreachable!() };
    let wl = wl();
    let ctx = ctx_of(&wl);
    let base = Point::at(p, &ctx, false).base;
    let (_, f_m) = fresnel_of(&b, 1.0);
    assert!((f_m - base).abs().max_element() < 2e-3, "{f_m} vs {base}");
    // Coloured: red reflects more than blue (lanes are 420…690 nm).
    assert!(f_m.w > f_m.x + 0.2, "{f_m}");
}

/// Smooth lossless glass from outside: R + η²·T = 1 (T carries the 1/η² of radiance), with
/// and without a film, at all angles.
#[test]
fn lossless_glass_with_and_without_film_conserves_energy() {
    for f in [None, film(1.8, 350.0, 1.0), film(1.3, 120.0, 0.5)] {
        let b = mat(|m| {
            m.metallic = 0.0;
            m.roughness = 0.0;
            m.transmission = 1.0;
            m.ior = 1.5;
            m.volume = volume();
            m.iridescence = f.clone();
        });
        assert!(b.is_fresnel_pair());
        let wl = wl();
        let ctx = ctx_of(&wl);
        for theta in [0.0f32, 30.0, 60.0, 85.0] {
            for wi in [dir(theta, 10.0), -dir(theta, 10.0)] {
                let [r, t] = b.sample_split(&ctx, wi, 0.5, Vec2::splat(0.5));
                let (r, t) = (r.unwrap(), t);
                let eta = if wi.z > 0.0 { 1.5f32 } else { 1.0 / 1.5 };
                let t = t.map_or(Spec::ZERO, |t| t.weight * (eta * eta));
                let sum = r.weight + t;
                assert!((sum - Spec::ONE).abs().max_element() < 1e-3, "{theta}° {wi}: {sum}");
            }
        }
    }
}

/// The directional albedo of `b` from `wi` (transmitted weights' 1/η² undone: energy).
fn energy_albedo(b: &Bsdf, wi: Vec3, ior: f32, seed: u64) -> Spec {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let mut s = crate::render::sampler::Sampler::from_seed(seed);
    let n = 100_000;
    let mut sum = Spec::ZERO;
    for _ in 0..n {
        if let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) {
            let eta = if (smp.wo.z < 0.0) == (wi.z > 0.0) {
                if wi.z > 0.0 {
                    ior
                } else {
                    1.0 / ior
                }
            } else {
                1.0
            };
            sum += smp.weight * (eta * eta);
        }
    }
    sum / n as f32
}

/// Rough lossless glass keeps all the energy with the compensation of its lobes (both
/// scaled by 1/(E_R + E_T), Turquin 2019 §4): albedo 1 within 0.02
/// from outside at 0°, 45°, 75° and from inside at 0° and 30°, roughness 0.3, 0.6 and 1 —
/// where the single-scattering pair (E_R + E_T of the interface) keeps visibly less. With a
/// film the albedo stays near 1 (the compensation is computed without it).
#[test]
fn rough_glass_keeps_its_energy_with_compensation() {
    let glass = |roughness: f32, f: Option<Iridescence>| {
        mat(|m| {
            m.metallic = 0.0;
            m.roughness = roughness;
            m.transmission = 1.0;
            m.volume = volume();
            m.iridescence = f;
        })
    };
    let mut worst_single = 1.0f32;
    for roughness in [0.3f32, 0.6, 1.0] {
        let b = glass(roughness, None);
        let dirs = [
            dir(0.0, 0.0),
            dir(45.0, 0.0),
            dir(75.0, 0.0),
            -dir(0.0, 0.0),
            -dir(30.0, 0.0),
        ];
        for (i, wi) in dirs.into_iter().enumerate() {
            let a = energy_albedo(&b, wi, 1.5, 5 + i as u64);
            eprintln!("roughness {roughness}, wi {wi}: albedo {}", a.x);
            assert!(
                (a - Spec::ONE).abs().max_element() < 0.02,
                "roughness {roughness}, wi {wi}: albedo {a}"
            );
            let Bsdf::GltfPbr(p) = &b else { unreachable!() };
            let [er, et] = p.glass.as_ref().unwrap().at(wi.z < 0.0, roughness * roughness, wi.z.abs());
            worst_single = worst_single.min(er + et);
        }
    }
    assert!(worst_single < 0.95, "single scattering keeps {worst_single}");
    let a = energy_albedo(&glass(0.3, film(1.8, 300.0, 1.0)), dir(30.0, 0.0), 1.5, 3);
    assert!(a.min_element() > 0.95 && a.max_element() < 1.03, "{a}");
}

/// White furnace of a white rough metal (F ≈ 1): with the Turquin energy compensation its
/// directional albedo is 1 at every angle and roughness; the single-scattering lobe alone
/// keeps E(μ, α) only, well below 1 at these roughnesses.
#[test]
fn white_rough_metal_keeps_all_energy_with_compensation() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    for roughness in [0.5f32, 1.0] {
        let b = mat(|m| {
            m.base_color = [1.0; 4];
            m.metallic = 1.0;
            m.roughness = roughness;
        });
        for theta in [0.0f32, 45.0, 75.0] {
            let mut s = crate::render::sampler::Sampler::from_seed(9);
            let n = 100_000;
            let mut sum = Spec::ZERO;
            for _ in 0..n {
                let wi = dir(theta, 0.0);
                if let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) {
                    sum += smp.weight;
                }
            }
            let a = sum / n as f32;
            assert!((a - Spec::ONE).abs().max_element() < 0.02, "r={roughness} θ={theta}: {a}");
            let e = layers::ggx_albedo(roughness * roughness, theta.to_radians().cos());
            assert!(e < 0.97, "r={roughness} θ={theta}: single scattering keeps {e}");
        }
    }
}

#[test]
fn sides_and_opacity() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let (wi, wo) = (dir(30.0, 0.0), dir(40.0, 180.0));
    let back = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
    let one = mat(|m| {
        m.metallic = 0.0;
        m.roughness = 0.5;
    });
    assert!(one.eval(&ctx, wi, wo).max_element() > 0.0);
    assert_eq!(one.eval(&ctx, back(wi), back(wo)), Spec::ZERO);
    let two = mat(|m| {
        m.metallic = 0.0;
        m.roughness = 0.5;
        m.double_sided = true;
    });
    assert_eq!(two.eval(&ctx, back(wi), back(wo)), one.eval(&ctx, wi, wo));
    // MASK: below the cutoff the surface is absent (a null lobe of weight 1).
    let cut = mat(|m| {
        m.base_color = [1.0, 1.0, 1.0, 0.3];
        m.alpha_mode = AlphaMode::Mask(0.5);
        m.metallic = 0.0;
        m.roughness = 0.5;
    });
    let s = cut.sample(&ctx, wi, 0.5, Vec2::splat(0.5), Lobes::ALL).unwrap();
    assert_eq!((s.wo, s.weight, s.lobe), (-wi, Spec::ONE, BsdfFlags::NULL));
    assert_eq!(cut.eval(&ctx, wi, wo), Spec::ZERO);
}

#[test]
fn volume_absorbs_along_the_inside_segment() {
    let b = mat(|m| {
        m.metallic = 0.0;
        m.roughness = 0.0;
        m.transmission = 1.0;
        m.volume = Some(Volume {
            attenuation_color: [0.5; 3],
            attenuation_distance: 2.0,
        });
    });
    let wl = wl();
    let wi = -dir(0.0, 0.0);
    let weight = |segment: f32| {
        let ctx = ShadingCtx {
            wl: &wl,
            uv: Vec2::ZERO,
            segment,
            color: glam::Vec3::ONE,
            bump_normal: glam::Vec3::Z,
        };
        b.sample_split(&ctx, wi, 0.5, Vec2::splat(0.5))[1].unwrap().weight
    };
    // Twice the attenuation distance: 0.5² of what crossed no distance.
    let ratio = weight(4.0) / weight(0.0);
    assert!((ratio - Spec::splat(0.25)).abs().max_element() < 1e-4, "{ratio}");
    // From outside nothing is absorbed.
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
        segment: 4.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    let out = b.sample_split(&ctx, -wi, 0.5, Vec2::splat(0.5))[1].unwrap().weight;
    let ctx0 = ctx_of(&wl);
    let out0 = b.sample_split(&ctx0, -wi, 0.5, Vec2::splat(0.5))[1].unwrap().weight;
    assert_eq!(out, out0);
}

#[test]
fn invalid_factors_are_refused_by_key() {
    for (key, f) in [
        ("metallicFactor", (|m: &mut GltfMaterial| m.metallic = f32::NAN) as fn(&mut GltfMaterial)),
        ("roughnessFactor", |m| m.roughness = 1.5),
        ("baseColorFactor", |m| m.base_color[1] = -0.1),
        ("KHR_materials_ior.ior", |m| m.ior = 0.5),
        ("transmissionFactor", |m| m.transmission = 2.0),
        ("iridescenceThicknessMaximum", |m| {
            m.iridescence = film(1.3, f32::INFINITY, 1.0)
        }),
        ("attenuationDistance", |m| {
            m.volume = Some(Volume {
                attenuation_color: [1.0; 3],
                attenuation_distance: 0.0,
            })
        }),
    ] {
        let mut m = GltfMaterial::default();
        f(&mut m);
        let e = GltfPbr::new(m).unwrap_err().to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
}

#[test]
fn is_read_from_mitsuba_xml() {
    let load = |body: &str| {
        let xml = format!(r#"<scene version="3.0.0"><shape type="sphere">{body}</shape></scene>"#);
        crate::scene::mitsuba::load_str(&xml, std::path::Path::new("."), &[], "t.xml")
    };
    let s = load(
        r#"<bsdf type="gltf_pbr"><rgb name="base_color" value="0.2, 0.4, 0.6"/><float name="metallic" value="0"/><float name="roughness" value="0.3"/><float name="iridescence" value="0.5"/></bsdf>"#,
    )
    .unwrap();
    let Bsdf::GltfPbr(p) = &s.bsdfs[s.shapes[0].bsdf] else {
        panic!("not a glTF material")
    };
    assert_eq!(p.material.base_color, [0.2, 0.4, 0.6, 1.0]);
    assert_eq!((p.material.metallic, p.material.roughness), (0.0, 0.3));
    assert_eq!(p.material.iridescence.as_ref().unwrap().factor, 0.5);
    let e = format!(
        "{:#}",
        load(r#"<bsdf type="gltf_pbr"><float name="metallic" value="2"/></bsdf>"#).unwrap_err()
    );
    assert!(e.contains("t.xml") && e.contains("metallicFactor"), "{e}");
}
