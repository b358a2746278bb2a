//! BSDF tests in the style of pbrt-v4's `bsdfs_test.cpp`: χ² goodness of fit of sampled
//! directions against the pdf integrated over histogram cells, eval/pdf/sample agreement,
//! energy conservation of the thin film (R + T = 1 when lossless) and finiteness at grazing
//! angles and zero thickness.

use super::*;
use crate::optics::Ior;
use crate::render::sampler::Sampler;
use crate::render::texture::{Spectrum, Texture};
use crate::scene::{BsdfDesc, SpectrumDesc, TextureDesc};
use std::f64::consts::PI;

fn wl() -> SampledWavelengths {
    SampledWavelengths {
        lambda: [420.0, 510.0, 600.0, 690.0],
        pdf: [0.0025; 4],
    }
}

fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

fn constant(v: f32) -> TextureDesc {
    TextureDesc::Value(SpectrumDesc::Constant(v))
}

fn thin_film(alpha: f32, thickness: f32) -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::ThinFilm {
        film_ior: Ior::real(1.37),
        thickness_nm: constant(thickness),
        substrate_ior: Ior::real(1.64),
        alpha,
    })
    .unwrap()
}

fn test_bsdfs() -> Vec<(&'static str, Bsdf)> {
    vec![
        (
            "diffuse",
            Bsdf::from_desc(&BsdfDesc::Diffuse {
                reflectance: constant(0.7),
            })
            .unwrap(),
        ),
        (
            "roughconductor",
            Bsdf::from_desc(&BsdfDesc::Conductor {
                eta: "0.2+3.9i".parse().unwrap(),
                alpha_u: 0.3,
                alpha_v: 0.3,
            })
            .unwrap(),
        ),
        (
            "roughconductor-aniso",
            Bsdf::from_desc(&BsdfDesc::Conductor {
                eta: "0.2+3.9i".parse().unwrap(),
                alpha_u: 0.1,
                alpha_v: 0.5,
            })
            .unwrap(),
        ),
        (
            "roughplastic",
            Bsdf::from_desc(&BsdfDesc::Plastic {
                diffuse_reflectance: constant(0.5),
                int_ior: 1.49,
                ext_ior: 1.0,
                alpha: 0.2,
                nonlinear: false,
            })
            .unwrap(),
        ),
        (
            "plastic",
            Bsdf::from_desc(&BsdfDesc::Plastic {
                diffuse_reflectance: constant(0.5),
                int_ior: 1.49,
                ext_ior: 1.0,
                alpha: 0.0,
                nonlinear: true,
            })
            .unwrap(),
        ),
        ("roughthinfilm", thin_film(0.25, 400.0)),
        (
            "twosided-diffuse",
            Bsdf::from_desc(&BsdfDesc::TwoSided(Box::new(BsdfDesc::Diffuse {
                reflectance: constant(0.9),
            })))
            .unwrap(),
        ),
    ]
}

/// Regularised lower incomplete gamma P(a, x) (Numerical Recipes §6.2).
fn gamma_p(a: f64, x: f64) -> f64 {
    fn ln_gamma(x: f64) -> f64 {
        let c = [
            76.18009172947146,
            -86.50532032941677,
            24.01409824083091,
            -1.231739572450155,
            0.1208650973866179e-2,
            -0.5395239384953e-5,
        ];
        let mut y = x;
        let tmp = x + 5.5 - (x + 0.5) * (x + 5.5).ln();
        let mut ser = 1.000000000190015;
        for ci in c {
            y += 1.0;
            ser += ci / y;
        }
        -tmp + (2.5066282746310005 * ser / x).ln()
    }
    if x <= 0.0 {
        return 0.0;
    }
    if x < a + 1.0 {
        let (mut sum, mut del, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-12 {
                break;
            }
        }
        sum * (-x + a * x.ln() - ln_gamma(a)).exp()
    } else {
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / 1e-300;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < 1e-300 {
                d = 1e-300;
            }
            c = b + an / c;
            if c.abs() < 1e-300 {
                c = 1e-300;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-12 {
                break;
            }
        }
        1.0 - (-x + a * x.ln() - ln_gamma(a)).exp() * h
    }
}

const THETA_BINS: usize = 10;
const PHI_BINS: usize = 20;

fn cell_of(w: Vec3) -> usize {
    let theta = (w.z.clamp(-1.0, 1.0) as f64).acos();
    let mut phi = (w.y as f64).atan2(w.x as f64);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let ti = ((theta / PI * THETA_BINS as f64) as usize).min(THETA_BINS - 1);
    let pi = ((phi / (2.0 * PI) * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
    ti * PHI_BINS + pi
}

/// χ² test (pbrt-v4 `Chi2Test`): returns the p-value.
fn chi2_pvalue(bsdf: &Bsdf, wi: Vec3, n_samples: usize, seed: u64) -> f64 {
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut counters = Counters::default();
    let mut observed = vec![0.0f64; THETA_BINS * PHI_BINS];
    let mut sampler = Sampler::from_seed(seed);
    for _ in 0..n_samples {
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        if let Some(s) = bsdf.sample(&ctx, wi, u1, u2, &mut counters) {
            if !s.delta {
                observed[cell_of(s.wo)] += 1.0;
            }
        }
    }
    // Expected counts: pdf integrated over each cell with a 16×16 midpoint rule.
    let mut expected = vec![0.0f64; THETA_BINS * PHI_BINS];
    let sub = 16;
    for ti in 0..THETA_BINS {
        for pi in 0..PHI_BINS {
            let mut sum = 0.0;
            for a in 0..sub {
                for b in 0..sub {
                    let theta =
                        PI * (ti as f64 + (a as f64 + 0.5) / sub as f64) / THETA_BINS as f64;
                    let phi =
                        2.0 * PI * (pi as f64 + (b as f64 + 0.5) / sub as f64) / PHI_BINS as f64;
                    let w = Vec3::new(
                        (theta.sin() * phi.cos()) as f32,
                        (theta.sin() * phi.sin()) as f32,
                        theta.cos() as f32,
                    );
                    sum += bsdf.pdf(wi, w) as f64 * theta.sin();
                }
            }
            let area = (PI / THETA_BINS as f64) * (2.0 * PI / PHI_BINS as f64) / (sub * sub) as f64;
            expected[ti * PHI_BINS + pi] = sum * area * n_samples as f64;
        }
    }
    // Pool cells with small expected counts (pbrt: < 5); observed counts where expected is
    // zero are an immediate failure.
    let mut order: Vec<usize> = (0..expected.len()).collect();
    order.sort_by(|&a, &b| expected[a].partial_cmp(&expected[b]).unwrap());
    let (mut pooled_e, mut pooled_o, mut chsq, mut dof) = (0.0, 0.0, 0.0, 0usize);
    for &i in &order {
        if expected[i] == 0.0 {
            if observed[i] > n_samples as f64 * 1e-5 {
                return 0.0;
            }
        } else if expected[i] < 5.0 || (pooled_e > 0.0 && pooled_e < 5.0) {
            pooled_e += expected[i];
            pooled_o += observed[i];
        } else {
            let d = observed[i] - expected[i];
            chsq += d * d / expected[i];
            dof += 1;
        }
    }
    if pooled_e > 0.0 {
        let d = pooled_o - pooled_e;
        chsq += d * d / pooled_e;
        dof += 1;
    }
    if dof < 2 {
        return 1.0;
    }
    1.0 - gamma_p((dof - 1) as f64 / 2.0, chsq / 2.0)
}

#[test]
fn chi2_sampled_directions_match_pdf() {
    let bsdfs = test_bsdfs();
    let incidents = [(10.0, 20.0), (45.0, 200.0), (80.0, 90.0)];
    let tests = bsdfs.len() * incidents.len();
    // Šidák correction for the number of tests at overall significance 1 %.
    let threshold = 1.0 - (1.0 - 0.01f64).powf(1.0 / tests as f64);
    for (name, b) in &bsdfs {
        for (k, &(t, p)) in incidents.iter().enumerate() {
            let mut wi = dir(t, p);
            if *name == "twosided-diffuse" && k == 1 {
                wi.z = -wi.z; // back face
            }
            let pv = chi2_pvalue(b, wi, 200_000, 7 + k as u64);
            assert!(
                pv > threshold,
                "{name} at θi={t}°: χ² p-value {pv:e} < {threshold:e}"
            );
        }
    }
}

/// A deliberately wrong pdf must fail the same test (the test can fail).
#[test]
fn chi2_rejects_a_wrong_pdf() {
    // Sample a rough conductor but histogram against a diffuse pdf.
    let rough = Bsdf::from_desc(&BsdfDesc::Conductor {
        eta: Ior::real(1.5),
        alpha_u: 0.2,
        alpha_v: 0.2,
    })
    .unwrap();
    let diffuse = Bsdf::from_desc(&BsdfDesc::Diffuse {
        reflectance: constant(1.0),
    })
    .unwrap();
    // Build the mixture by hand: use chi2 of diffuse samples against the conductor's pdf.
    struct Swap;
    let _ = Swap;
    let wi = dir(30.0, 0.0);
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    let mut s = Sampler::from_seed(1);
    let mut in_lobe = 0;
    for _ in 0..10_000 {
        let smp = diffuse
            .sample(&ctx, wi, s.next_1d(), s.next_2d(), &mut c)
            .unwrap();
        if rough.pdf(wi, smp.wo) > 1.0 {
            in_lobe += 1;
        }
    }
    // Diffuse samples rarely land in the narrow specular lobe: the two pdfs differ.
    assert!(in_lobe < 2_000, "{in_lobe}");
    assert!(chi2_pvalue(&rough, wi, 50_000, 3) > 1e-4);
}

#[test]
fn eval_pdf_sample_agree() {
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    for (name, b) in test_bsdfs() {
        let mut s = Sampler::from_seed(11);
        for k in 0..2000 {
            let wi = dir(5.0 + 80.0 * s.next_1d(), 360.0 * s.next_1d());
            let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), &mut c) else {
                continue;
            };
            if smp.delta {
                continue;
            }
            let pdf = b.pdf(wi, smp.wo);
            let f = b.eval(&ctx, wi, smp.wo, &mut c);
            assert!(
                (pdf - smp.pdf).abs() <= 2e-3 * pdf.max(1.0),
                "{name} #{k}: pdf {pdf} vs sampled {}",
                smp.pdf
            );
            let expect = f / smp.pdf;
            for l in 0..4 {
                assert!(
                    (expect[l] - smp.weight[l]).abs() <= 2e-3 * expect[l].max(1.0),
                    "{name} #{k}: weight {} vs eval/pdf {}",
                    smp.weight[l],
                    expect[l]
                );
            }
        }
    }
}

/// Lossless film on a lossless substrate: R + T = 1 inside the BSDF, for any angle,
/// wavelength and thickness (including 0 and grazing incidence).
#[test]
fn thin_film_conserves_energy_when_lossless() {
    let Bsdf::ThinFilm(film) = thin_film(0.0, 0.0) else {
        unreachable!()
    };
    let mut c = Counters::default();
    for d in [0.0f32, 1.0, 120.0, 400.0, 612.5, 5000.0] {
        let mut f = film.clone();
        f.thickness_nm = Texture::Value(Spectrum::Constant(d));
        for lambda in [380.0f32, 455.0, 550.0, 700.0, 820.0] {
            let wl = SampledWavelengths {
                lambda: [lambda; 4],
                pdf: [1.0; 4],
            };
            let ctx = ShadingCtx {
                wl: &wl,
                uv: Vec2::ZERO,
            };
            for cos in [1.0f32, 0.8, 0.5, 0.2, 0.05, 1e-3] {
                let (r, t) = f.reflect_transmit(&ctx, cos, &mut c);
                let sum = r + t;
                for k in 0..4 {
                    assert!(
                        (sum[k] - 1.0).abs() < 1e-5,
                        "d={d} λ={lambda} cos={cos}: R+T={}",
                        sum[k]
                    );
                }
            }
        }
    }
    assert!(c.film_evals > 0);
}

/// Zero thickness is the bare ambient|substrate Fresnel term.
#[test]
fn zero_thickness_film_is_bare_substrate() {
    let Bsdf::ThinFilm(film) = thin_film(0.0, 0.0) else {
        unreachable!()
    };
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    for cos in [1.0f32, 0.6, 0.1] {
        let (r, _) = film.reflect_transmit(&ctx, cos, &mut c);
        let bare = fresnel::fresnel_dielectric(cos, 1.64).0;
        assert!((r.x - bare).abs() < 1e-5, "{} vs {bare}", r.x);
    }
}

/// Every BSDF returns finite values, including grazing and below-horizon directions and
/// zero-thickness or negative (texture hole) films.
#[test]
fn finite_at_grazing_and_degenerate_inputs() {
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    let mut all = test_bsdfs();
    all.push(("film-d0", thin_film(0.0, 0.0)));
    all.push(("film-negative", thin_film(0.1, -5.0)));
    all.push(("film-nan", thin_film(0.0, f32::NAN)));
    all.push((
        "conductor",
        Bsdf::from_desc(&BsdfDesc::Conductor {
            eta: "0.2+3.9i".parse().unwrap(),
            alpha_u: 0.0,
            alpha_v: 0.0,
        })
        .unwrap(),
    ));
    all.push((
        "dielectric",
        Bsdf::from_desc(&BsdfDesc::Dielectric {
            int_ior: Ior::real(1.5),
            ext_ior: Ior::real(1.0),
            alpha: 0.0,
        })
        .unwrap(),
    ));
    let dirs = [
        Vec3::Z,
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.6, 0.0, -0.8),
        Vec3::new(1.0, 0.0, -1e-7).normalize(),
    ];
    let mut s = Sampler::from_seed(5);
    for (name, b) in &all {
        for wi in dirs {
            for wo in dirs {
                let f = b.eval(&ctx, wi, wo, &mut c);
                let p = b.pdf(wi, wo);
                assert!(
                    f.is_finite() && p.is_finite() && f.min_element() >= 0.0,
                    "{name}: {wi} {wo} → {f} {p}"
                );
            }
            for _ in 0..64 {
                if let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), &mut c) {
                    assert!(
                        smp.weight.is_finite() && smp.wo.is_finite() && smp.pdf.is_finite(),
                        "{name}: {wi} → {smp:?}"
                    );
                    assert!(smp.weight.min_element() >= 0.0);
                }
            }
        }
    }
}

/// Smooth dielectric: radiance weights for reflection 1 and refraction 1/η²; TIR from inside.
#[test]
fn dielectric_sampling() {
    let b = Bsdf::from_desc(&BsdfDesc::Dielectric {
        int_ior: Ior::real(1.5),
        ext_ior: Ior::real(1.0),
        alpha: 0.0,
    })
    .unwrap();
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    let wi = dir(30.0, 0.0);
    let t = b.sample(&ctx, wi, 0.99, Vec2::ZERO, &mut c).unwrap();
    assert!(t.wo.z < 0.0);
    assert!((t.weight.x - 1.0 / 2.25).abs() < 1e-5);
    // Snell: sinθt = sinθi / 1.5.
    let sin_t = (t.wo.x * t.wo.x + t.wo.y * t.wo.y).sqrt();
    assert!((sin_t - 0.5 / 1.5).abs() < 1e-5);
    // From inside beyond the critical angle (41.8°): always reflected.
    let inside = Vec3::new(dir(60.0, 0.0).x, 0.0, -dir(60.0, 0.0).z);
    let r = b.sample(&ctx, inside, 0.999, Vec2::ZERO, &mut c).unwrap();
    assert!(r.wo.z < 0.0 && (r.weight.x - 1.0).abs() < 1e-6);
}

/// Diffuse albedo 1: every sample weight is exactly 1 (white furnace inside the BSDF).
#[test]
fn diffuse_white_furnace_weights() {
    let b = Bsdf::from_desc(&BsdfDesc::Diffuse {
        reflectance: constant(1.0),
    })
    .unwrap();
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
    };
    let mut c = Counters::default();
    let mut s = Sampler::from_seed(2);
    for _ in 0..1000 {
        let smp = b
            .sample(&ctx, dir(40.0, 10.0), s.next_1d(), s.next_2d(), &mut c)
            .unwrap();
        assert_eq!(smp.weight, Spec::ONE);
    }
}
