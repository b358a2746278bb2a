//! BSDF tests in the style of pbrt-v4's `bsdfs_test.cpp`: χ² goodness of fit of sampled
//! directions against the pdf integrated over histogram cells, eval/pdf/sample agreement,
//! energy conservation of the thin film (R + T = 1 when lossless) and finiteness at grazing
//! angles and zero thickness.

use super::microfacet::OpaqueReflector;
use super::*;
use crate::optics::Ior;
use crate::render::counters;
use crate::render::sampler::Sampler;
use crate::render::texture::{Spectrum, Texture};
use crate::scene::{SpectrumDesc, TextureDesc};
use bubble::BubbleBsdf;
use microfacet::Distribution::{self, Beckmann, Ggx};
use microfacet::Microfacet;
use std::f64::consts::PI;

/// Four visible wavelengths for the tests.
pub(super) fn wl() -> SampledWavelengths {
    SampledWavelengths {
        lambda: [420.0, 510.0, 600.0, 690.0],
        pdf: [0.0025; 4],
    }
}

/// The unit direction at polar angle `theta_deg` and azimuth `phi_deg`.
pub(super) fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

pub(super) fn constant(v: f32) -> TextureDesc {
    TextureDesc::Value(SpectrumDesc::Constant(v))
}

pub(super) fn thin_film(alpha: f32, thickness: f32) -> Bsdf {
    let t = constant(thickness);
    thinfilm::ThinFilmBsdf::new(Ior::real(1.37), &t, Ior::real(1.64), alpha)
        .unwrap()
        .into()
}

/// A multilayer coating from the scene syntax (`layers`, substrate).
pub(super) fn stack(layers: &str, substrate: &str, alpha: f32) -> Bsdf {
    let layers = crate::scene::mitsuba::parse_layers(layers).unwrap();
    stack::StackBsdf::new(layers, substrate.parse().unwrap(), alpha)
        .unwrap()
        .into()
}

/// A dielectric interface under a coating (`coateddielectric`), air outside.
pub(super) fn coated(layers: &str, int_ior: &str) -> Bsdf {
    let layers = crate::scene::mitsuba::parse_layers(layers).unwrap();
    coated::CoatedDielectric::new(layers, int_ior.parse().unwrap(), Ior::real(1.0))
        .unwrap()
        .into()
}

/// A free-standing film (soap bubble) of constant thickness.
pub(super) fn bubble(film_ior: &str, thickness: f32) -> Bsdf {
    bubble::BubbleBsdf::new(
        film_ior.parse().unwrap(),
        &constant(thickness),
        &Ior::real(1.0),
    )
    .unwrap()
    .into()
}

pub(super) fn conductor(eta: &str, alpha_u: f32, alpha_v: f32) -> Bsdf {
    conductor::Conductor::new(eta.parse().unwrap(), alpha_u, alpha_v)
        .unwrap()
        .into()
}

pub(super) fn dielectric(int_ior: &str) -> Bsdf {
    dielectric::Dielectric::new(int_ior.parse().unwrap(), Ior::real(1.0)).into()
}

pub(super) fn diffuse(reflectance: f32) -> Bsdf {
    diffuse::Diffuse::constant(reflectance).into()
}

pub(super) fn plastic(alpha: f32, nonlinear: bool) -> Bsdf {
    plastic::Plastic::new(&constant(0.5), 1.49, 1.0, nonlinear, alpha)
        .unwrap()
        .into()
}

fn test_bsdfs() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("diffuse", diffuse(0.7)),
        ("roughconductor", conductor("0.2+3.9i", 0.3, 0.3)),
        ("roughplastic", plastic(0.2, false)),
        ("plastic", plastic(0.0, true)),
        ("roughthinfilm", thin_film(0.25, 400.0)),
        ("roughstack", stack("MgF2:100, TiO2:50", "BK7", 0.2)),
        (
            "twosided-diffuse",
            twosided::TwoSided::new(diffuse(0.9)).unwrap().into(),
        ),
        ("beckmann-conductor", rough_conductor(Beckmann, 0.3, 0.3)),
        (
            "beckmann-conductor-aniso",
            rough_conductor(Beckmann, 0.05, 0.4),
        ),
        ("ggx-conductor-aniso", rough_conductor(Ggx, 0.4, 0.1)),
        ("beckmann-plastic", rough_plastic(Beckmann, 0.3)),
        ("ggx-roughdielectric", rough_dielectric(Ggx, 1.5, 0.3, 0.3)),
        (
            "beckmann-roughdielectric",
            rough_dielectric(Beckmann, 1.33, 0.2, 0.2),
        ),
        (
            "beckmann-roughdielectric-aniso",
            rough_dielectric(Beckmann, 1.5, 0.1, 0.4),
        ),
    ]
}

pub(super) fn rough_conductor(kind: Distribution, alpha_u: f32, alpha_v: f32) -> Bsdf {
    conductor::Conductor::with_distribution("0.2+3.9i".parse().unwrap(), kind, alpha_u, alpha_v)
        .unwrap()
        .into()
}

pub(super) fn rough_plastic(kind: Distribution, alpha: f32) -> Bsdf {
    plastic::Plastic::with_distribution(&constant(0.5), (1.49, 1.0), false, kind, alpha)
        .unwrap()
        .into()
}

pub(super) fn rough_dielectric(kind: Distribution, eta: f32, alpha_u: f32, alpha_v: f32) -> Bsdf {
    roughdielectric::RoughDielectric::new(eta, Microfacet::of(kind, alpha_u, alpha_v))
        .unwrap()
        .into()
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
pub(super) fn chi2_pvalue(bsdf: &Bsdf, wi: Vec3, n_samples: usize, seed: u64) -> f64 {
    let wl = wl();
    chi2_pvalue_in(bsdf, &ctx_of(&wl), wi, n_samples, seed)
}

/// [`chi2_pvalue`] at shading point `ctx`.
pub(super) fn chi2_pvalue_in(
    bsdf: &Bsdf,
    ctx: &ShadingCtx,
    wi: Vec3,
    n_samples: usize,
    seed: u64,
) -> f64 {
    let mut observed = vec![0.0f64; THETA_BINS * PHI_BINS];
    let mut sampler = Sampler::from_seed(seed);
    for _ in 0..n_samples {
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        if let Some(s) = bsdf.sample(ctx, wi, u1, u2, Lobes::ALL) {
            if !s.is_delta() {
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
                    sum += bsdf.pdf(ctx, wi, w) as f64 * theta.sin();
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

/// Incident directions of the sampling tests: near normal, oblique, grazing (the second one
/// from below for two-sided models).
pub(super) fn incidents(b: &Bsdf) -> [Vec3; 3] {
    let mut out = [dir(10.0, 20.0), dir(45.0, 200.0), dir(80.0, 90.0)];
    if b.flags().contains(BsdfFlags::TWO_SIDED) {
        out[1].z = -out[1].z;
    }
    out
}

/// The χ² test of `b`'s sampled directions against its pdf at [`incidents`], each at
/// significance `alpha` (Šidák-corrected by the caller).
pub(super) fn assert_chi2(name: &str, b: &Bsdf, alpha: f64) {
    for (k, wi) in incidents(b).into_iter().enumerate() {
        let pv = chi2_pvalue(b, wi, 200_000, 7 + k as u64);
        assert!(
            pv > alpha,
            "{name} at wi={wi}: χ² p-value {pv:e} < {alpha:e}"
        );
    }
}

#[test]
fn chi2_sampled_directions_match_pdf() {
    let bsdfs = test_bsdfs();
    let tests = bsdfs.len() * 3;
    // Šidák correction for the number of tests at overall significance 1 %.
    let threshold = 1.0 - (1.0 - 0.01f64).powf(1.0 / tests as f64);
    for (name, b) in &bsdfs {
        assert_chi2(name, b, threshold);
    }
}

/// A deliberately wrong pdf must fail the same test (the test can fail).
#[test]
fn chi2_rejects_a_wrong_pdf() {
    // Sample a rough conductor but histogram against a diffuse pdf.
    let rough = conductor("1.5", 0.2, 0.2);
    let diffuse = diffuse(1.0);
    // Build the mixture by hand: use chi2 of diffuse samples against the conductor's pdf.
    struct Swap;
    let _ = Swap;
    let wi = dir(30.0, 0.0);
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    counters::take();
    let mut s = Sampler::from_seed(1);
    let mut in_lobe = 0;
    for _ in 0..10_000 {
        let smp = diffuse
            .sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL)
            .unwrap();
        if rough.pdf(&ctx, wi, smp.wo) > 1.0 {
            in_lobe += 1;
        }
    }
    // Diffuse samples rarely land in the narrow specular lobe: the two pdfs differ.
    assert!(in_lobe < 2_000, "{in_lobe}");
    assert!(chi2_pvalue(&rough, wi, 50_000, 3) > 1e-4);
}

/// `b`'s non-delta samples have the pdf `pdf` gives and the weight eval / pdf.
pub(super) fn assert_eval_pdf_sample_agree(name: &str, b: &Bsdf) {
    let wl = wl();
    assert_eval_pdf_sample_agree_in(name, b, &ctx_of(&wl));
}

/// [`assert_eval_pdf_sample_agree`] at shading point `ctx`.
pub(super) fn assert_eval_pdf_sample_agree_in(name: &str, b: &Bsdf, ctx: &ShadingCtx) {
    let mut s = Sampler::from_seed(11);
    for k in 0..2000 {
        let wi = dir(5.0 + 80.0 * s.next_1d(), 360.0 * s.next_1d());
        let Some(smp) = b.sample(ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) else {
            continue;
        };
        if smp.is_delta() {
            continue;
        }
        let pdf = b.pdf(ctx, wi, smp.wo);
        let f = b.eval(ctx, wi, smp.wo);
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

#[test]
fn eval_pdf_sample_agree() {
    for (name, b) in test_bsdfs() {
        assert_eval_pdf_sample_agree(name, &b);
    }
}

/// Helmholtz reciprocity of a reflection model: f(wi, wo) = f(wo, wi), i.e.
/// eval(wi, wo)/|cos θo| = eval(wo, wi)/|cos θi|, at random pairs of upper-hemisphere
/// directions (relative tolerance `tol`; models that are reciprocal only up to an
/// approximation pass a looser one).
pub(super) fn assert_reciprocal(name: &str, b: &Bsdf, tol: f32) {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let mut s = Sampler::from_seed(17);
    for k in 0..500 {
        let wi = dir(85.0 * s.next_1d(), 360.0 * s.next_1d());
        let wo = dir(85.0 * s.next_1d(), 360.0 * s.next_1d());
        let f_io = b.eval(&ctx, wi, wo) / wo.z;
        let f_oi = b.eval(&ctx, wo, wi) / wi.z;
        for l in 0..4 {
            assert!(
                (f_io[l] - f_oi[l]).abs() <= tol * f_io[l].abs().max(f_oi[l].abs()).max(1e-3),
                "{name} #{k} λ{l}: f(wi, wo) {} vs f(wo, wi) {}",
                f_io[l],
                f_oi[l]
            );
        }
    }
}

#[test]
fn reflection_models_are_reciprocal() {
    for (name, b) in [
        ("diffuse", diffuse(0.7)),
        ("roughconductor", conductor("0.2+3.9i", 0.3, 0.3)),
        ("roughthinfilm", thin_film(0.25, 400.0)),
    ] {
        assert_reciprocal(name, &b, 1e-4);
    }
}

/// The mean sample weight from `wi` over `n` samples per wavelength: the directional albedo
/// (1 for a lossless BSDF in a white furnace).
pub(super) fn albedo(b: &Bsdf, wi: Vec3, n: u32) -> Spec {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let mut s = Sampler::from_seed(29);
    let mut sum = Spec::ZERO;
    for _ in 0..n {
        if let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) {
            sum += smp.weight;
        }
    }
    sum / n as f32
}

/// Lossless film on a lossless substrate: R + T = 1 inside the BSDF, for any angle,
/// wavelength and thickness (including 0 and grazing incidence).
#[test]
fn thin_film_conserves_energy_when_lossless() {
    let Bsdf::ThinFilm(film) = thin_film(0.0, 0.0) else {
        unreachable!()
    };
    counters::take();
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
                segment: 0.0,
                color: glam::Vec3::ONE,
                bump_normal: glam::Vec3::Z,
            };
            for cos in [1.0f32, 0.8, 0.5, 0.2, 0.05, 1e-3] {
                let (r, t) = f.reflect_transmit(&ctx, cos);
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
    assert!(counters::take().film_evals > 0);
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
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    counters::take();
    for cos in [1.0f32, 0.6, 0.1] {
        let (r, _) = film.reflect_transmit(&ctx, cos);
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
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    counters::take();
    let mut all = test_bsdfs();
    all.push(("film-d0", thin_film(0.0, 0.0)));
    all.push(("film-negative", thin_film(0.1, -5.0)));
    all.push(("film-nan", thin_film(0.0, f32::NAN)));
    all.push(("bubble", bubble("water", 300.0)));
    all.push(("bubble-d0", bubble("1.33", 0.0)));
    all.push(("bubble-nan", bubble("1.33", f32::NAN)));
    all.push(("bubble-absorbing", bubble("1.5+0.2i", 250.0)));
    all.push(("stack", stack("(TiO2:52, SiO2:94)x6, TiO2:52", "BK7", 0.0)));
    all.push(("stack-d0", stack("MgF2:0, TiO2:0", "1.5", 0.0)));
    all.push(("stack-empty-metal", stack("SiO2:0", "Au", 0.3)));
    all.push(("coated-glass", coated("MgF2:99.6", "1.5168")));
    all.push(("coated-glass-d0", coated("MgF2:0", "material:BK7")));
    all.push(("conductor", conductor("0.2+3.9i", 0.0, 0.0)));
    all.push(("dielectric", dielectric("1.5")));
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
                let f = b.eval(&ctx, wi, wo);
                let p = b.pdf(&ctx, wi, wo);
                assert!(
                    f.is_finite() && p.is_finite() && f.min_element() >= 0.0,
                    "{name}: {wi} {wo} → {f} {p}"
                );
            }
            for _ in 0..64 {
                if let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) {
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
    let b = dielectric("1.5");
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    counters::take();
    let wi = dir(30.0, 0.0);
    let t = b.sample(&ctx, wi, 0.99, Vec2::ZERO, Lobes::ALL).unwrap();
    assert!(t.wo.z < 0.0);
    assert!((t.weight.x - 1.0 / 2.25).abs() < 1e-5);
    // Snell: sinθt = sinθi / 1.5.
    let sin_t = (t.wo.x * t.wo.x + t.wo.y * t.wo.y).sqrt();
    assert!((sin_t - 0.5 / 1.5).abs() < 1e-5);
    // From inside beyond the critical angle (41.8°): always reflected.
    let inside = Vec3::new(dir(60.0, 0.0).x, 0.0, -dir(60.0, 0.0).z);
    let r = b
        .sample(&ctx, inside, 0.999, Vec2::ZERO, Lobes::ALL)
        .unwrap();
    assert!(r.wo.z < 0.0 && (r.weight.x - 1.0).abs() < 1e-6);
}

/// Diffuse albedo 1: every sample weight is exactly 1 (white furnace inside the BSDF).
#[test]
fn diffuse_white_furnace_weights() {
    let b = diffuse(1.0);
    let wl = wl();
    let ctx = ShadingCtx {
        wl: &wl,
        uv: Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    };
    counters::take();
    let mut s = Sampler::from_seed(2);
    for _ in 0..1000 {
        let smp = b
            .sample(&ctx, dir(40.0, 10.0), s.next_1d(), s.next_2d(), Lobes::ALL)
            .unwrap();
        assert_eq!(smp.weight, Spec::ONE);
    }
    assert_eq!(albedo(&b, dir(75.0, 0.0), 1000), Spec::ONE);
}

// ---- Free-standing films (thinfilm_bubble) and multilayer stacks (thinfilm + layers) ----

pub(super) fn ctx_of(wl: &SampledWavelengths) -> ShadingCtx<'_> {
    ShadingCtx {
        wl,
        uv: Vec2::ZERO,
        segment: 0.0,
        color: glam::Vec3::ONE,
        bump_normal: glam::Vec3::Z,
    }
}

/// Lossless bubble: R + T = 1 at every wavelength, angle (to grazing) and thickness, from
/// both sides; zero thickness is no film at all (R = 0, T = 1).
#[test]
fn bubble_conserves_energy_when_lossless() {
    counters::take();
    for d in [0.0f32, 1.0, 80.0, 300.0, 612.5, 1500.0, 5000.0] {
        let Bsdf::Bubble(b) = bubble("water", d) else {
            unreachable!()
        };
        for lambda in [380.0f32, 455.0, 550.0, 700.0, 820.0] {
            let wl = SampledWavelengths {
                lambda: [lambda; 4],
                pdf: [1.0; 4],
            };
            for cos in [1.0f32, 0.8, 0.5, 0.2, 0.05, 1e-3, -0.3, -1.0] {
                let (r, t) = b.reflect_transmit(&ctx_of(&wl), cos);
                for k in 0..4 {
                    assert!(
                        (r[k] + t[k] - 1.0).abs() < 2e-5,
                        "d={d} λ={lambda} cos={cos}: R={} T={}",
                        r[k],
                        t[k]
                    );
                    if d == 0.0 {
                        assert!(r[k].abs() < 1e-6, "d=0: R={}", r[k]);
                    }
                }
            }
        }
    }
}

/// The bubble's R and T are the f64 Airy film n1 = 1 | n2 | n3 = 1 of the optics module, and an
/// absorbing film loses energy (R + T < 1).
#[test]
fn bubble_matches_airy_and_absorbs_when_lossy() {
    let wl = wl();
    counters::take();
    let Bsdf::Bubble(b) = bubble("1.33", 350.0) else {
        unreachable!()
    };
    for cos in [1.0f32, 0.7, 0.3, 0.02] {
        let (r, t) = b.reflect_transmit(&ctx_of(&wl), cos);
        for k in 0..4 {
            let f = crate::optics::ThinFilm {
                ambient_ior: 1.0,
                film_ior: crate::optics::Complex64::new(1.33, 0.0),
                thickness_nm: 350.0,
                substrate_ior: crate::optics::Complex64::new(1.0, 0.0),
            }
            .response(wl.lambda[k] as f64, cos as f64);
            assert!(
                (r[k] as f64 - f.r()).abs() < 1e-5,
                "R {} vs {}",
                r[k],
                f.r()
            );
            assert!(
                (t[k] as f64 - f.t()).abs() < 1e-5,
                "T {} vs {}",
                t[k],
                f.t()
            );
        }
    }
    // Colour: a 350 nm water film reflects very differently across the visible.
    let (r, _) = b.reflect_transmit(&ctx_of(&wl), 1.0);
    assert!(r.max_element() - r.min_element() > 0.05, "{r}");
    let Bsdf::Bubble(lossy) = bubble("1.5+0.2i", 250.0) else {
        unreachable!()
    };
    let (r, t) = lossy.reflect_transmit(&ctx_of(&wl), 0.8);
    assert!((r + t).max_element() < 0.99, "{r} {t}");
}

/// Bubble sampling: mirror or straight-through directions, lobe frequencies follow
/// P_R = R̄/(R̄+T̄) (χ² with one degree of freedom), weights R/P_R and T/(1−P_R), and the
/// expected weight E[w] = R + T = 1 per wavelength (a white furnace inside the BSDF).
#[test]
fn bubble_sampling_frequencies_and_weights() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    counters::take();
    let Bsdf::Bubble(inner) = bubble("water", 420.0) else {
        unreachable!()
    };
    let b = bubble("water", 420.0);
    for (theta, back) in [(20.0f32, false), (70.0, false), (50.0, true), (85.0, true)] {
        let mut wi = dir(theta, 30.0);
        if back {
            wi.z = -wi.z;
        }
        let (r, t) = inner.reflect_transmit(&ctx, wi.z);
        let p_r = (r.element_sum() / (r.element_sum() + t.element_sum())).clamp(
            BubbleBsdf::MIN_LOBE_PROBABILITY,
            1.0 - BubbleBsdf::MIN_LOBE_PROBABILITY,
        );
        let n = 100_000;
        let (mut n_r, mut mean) = (0usize, Spec::ZERO);
        let mut s = Sampler::from_seed(17);
        for _ in 0..n {
            let smp = b
                .sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL)
                .unwrap();
            assert!(smp.is_delta() && smp.eta == 1.0);
            if smp.wo.z * wi.z > 0.0 {
                n_r += 1;
                assert!((smp.wo - Vec3::new(-wi.x, -wi.y, wi.z)).length() < 1e-6);
                assert!(((smp.weight - r / p_r).abs()).max_element() < 1e-5);
                assert!((smp.pdf - p_r).abs() < 1e-6);
            } else {
                assert!(
                    (smp.wo + wi).length() < 1e-6,
                    "transmission must go straight through"
                );
                assert!(((smp.weight - t / (1.0 - p_r)).abs()).max_element() < 1e-5);
            }
            mean += smp.weight;
        }
        let expected_r = p_r as f64 * n as f64;
        let expected_t = n as f64 - expected_r;
        let chi2 = (n_r as f64 - expected_r).powi(2) / expected_r
            + ((n - n_r) as f64 - expected_t).powi(2) / expected_t;
        // χ²(1 dof) > 10.83 has probability 0.001.
        assert!(
            chi2 < 10.83,
            "θ={theta}: χ² {chi2}, P_R {p_r}, observed {n_r}/{n}"
        );
        mean /= n as f32;
        for k in 0..4 {
            assert!((mean[k] - 1.0).abs() < 0.02, "θ={theta}: E[w] {mean}");
        }
    }
    // Once secondaries are terminated only the hero decides the lobe.
    let mut hero = wl;
    hero.terminate_secondary();
    let (r, t) = inner.reflect_transmit(&ctx_of(&hero), 0.9);
    let p = BubbleBsdf::reflect_probability(&ctx_of(&hero), r, t, 0.0);
    assert!((p - r.x / (r.x + t.x)).abs() < 1e-6);
}

/// The stack BSDF's R is the transfer-matrix result of `optics::Stack` for the same layers
/// (indices from the dispersion library at each path wavelength) and angle.
#[test]
fn stack_reflectance_equals_tmm() {
    use crate::optics::{dispersion, Layer, Stack};
    let Bsdf::Stack(b) = stack("MgF2:100, TiO2:50", "BK7", 0.0) else {
        unreachable!()
    };
    let wl = wl();
    counters::take();
    let n = |name: &str, l: f32| dispersion::lookup(name).unwrap().nk(l as f64);
    for cos in [1.0f32, 0.75, 0.4, 0.1, 0.0] {
        let r = b.reflectance(&ctx_of(&wl), cos);
        for k in 0..4 {
            let l = wl.lambda[k];
            let reference = Stack {
                ambient_ior: 1.0,
                layers: vec![
                    Layer::coherent(n("MgF2", l), 100.0),
                    Layer::coherent(n("TiO2", l), 50.0),
                ],
                substrate_ior: n("BK7", l),
            }
            .response(l as f64, cos as f64)
            .r();
            assert!(
                (r[k] as f64 - reference).abs() < 1e-6,
                "cos {cos} λ {l}: {} vs {reference}",
                r[k]
            );
        }
    }
    // One layer: the stack path equals the Airy thinfilm path (two independent codes).
    let one = stack("1.37:400", "1.64", 0.0);
    let (Bsdf::Stack(one), Bsdf::ThinFilm(airy)) = (one, thin_film(0.0, 400.0)) else {
        unreachable!()
    };
    for cos in [1.0f32, 0.5, 0.05] {
        let a = one.reflectance(&ctx_of(&wl), cos);
        let (b, _) = airy.reflect_transmit(&ctx_of(&wl), cos);
        assert!((a - b).abs().max_element() < 2e-5, "{a} vs {b}");
    }
}

/// Coatings behave as designed: a quarter-wave MgF2 layer on BK7 cuts the 550 nm reflectance
/// from ≈4.2 % to ≈1.3 %; a (TiO2/SiO2)^6 TiO2 quarter-wave mirror at 550 nm reflects > 95 %
/// there and little far outside its stop band.
#[test]
fn ar_coating_and_dielectric_mirror() {
    let at = |b: &Bsdf, l: f32| {
        let Bsdf::Stack(b) = b else { unreachable!() };
        let wl = SampledWavelengths {
            lambda: [l; 4],
            pdf: [1.0; 4],
        };
        b.reflectance(&ctx_of(&wl), 1.0).x
    };
    let bare = stack("MgF2:0", "BK7", 0.0);
    let ar = stack("MgF2:99.6", "BK7", 0.0);
    assert!(
        (at(&bare, 550.0) - 0.0420).abs() < 0.002,
        "{}",
        at(&bare, 550.0)
    );
    assert!(at(&ar, 550.0) < 0.014, "{}", at(&ar, 550.0));
    // Blue and red reflect more than green: the purple look of coated optics.
    assert!(at(&ar, 420.0) > at(&ar, 550.0) && at(&ar, 700.0) > at(&ar, 550.0));
    let mirror = stack("(TiO2:51.9, SiO2:94.2)x6, TiO2:51.9", "BK7", 0.0);
    assert!(at(&mirror, 550.0) > 0.95, "{}", at(&mirror, 550.0));
    assert!(at(&mirror, 780.0) < 0.5, "{}", at(&mirror, 780.0));
}

/// A dispersive dielectric asks for secondary termination; a constant-index one never does.
#[test]
fn dispersion_terminates_only_when_declared() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let glass = dielectric;
    counters::take();
    let constant = glass("1.5046");
    let mut s = Sampler::from_seed(3);
    for _ in 0..1000 {
        let smp = constant
            .sample(&ctx, dir(40.0, 0.0), s.next_1d(), s.next_2d(), Lobes::ALL)
            .unwrap();
        assert!(!smp.terminate_secondary);
    }
    for spec in ["cauchy:1.5046,4200", "material:BK7"] {
        counters::take();
        let g = glass(spec);
        let smp = g
            .sample(&ctx, dir(40.0, 0.0), 0.99, Vec2::ZERO, Lobes::ALL)
            .unwrap();
        assert!(smp.terminate_secondary && smp.wo.z < 0.0, "{spec}");
        // Refraction uses the hero wavelength's index (420 nm): Snell with n(420).
        let n420 = spec.parse::<Ior>().unwrap().at(420.0).re as f32;
        let sin_t = (smp.wo.x * smp.wo.x + smp.wo.y * smp.wo.y).sqrt();
        assert!((sin_t - dir(40.0, 0.0).x / n420).abs() < 1e-5, "{spec}");
    }
}

/// Coated dielectric: a zero-thickness coating is the bare Fresnel interface from both sides
/// (including total internal reflection); a lossless coating keeps R + T = 1 from both sides;
/// the AR coating transmits more than bare glass at 550 nm.
#[test]
fn coated_dielectric_limits_and_energy() {
    let wl = wl();
    counters::take();
    let Bsdf::CoatedDielectric(bare) = coated("MgF2:0", "1.5") else {
        unreachable!()
    };
    for cos in [1.0f32, 0.7, 0.2, 0.01, -1.0, -0.8, -0.5, -0.2] {
        let (r, t) = bare.reflect_transmit(&ctx_of(&wl), cos);
        let fresnel = fresnel::fresnel_dielectric(cos, 1.5).0;
        assert!(
            (r.x - fresnel).abs() < 1e-5,
            "cos {cos}: R {} vs Fresnel {fresnel}",
            r.x
        );
        assert!(
            (r + t - Spec::ONE).abs().max_element() < 1e-5,
            "cos {cos}: {r} {t}"
        );
    }
    let Bsdf::CoatedDielectric(ar) = coated("MgF2:99.6", "material:BK7") else {
        unreachable!()
    };
    for cos in [1.0f32, 0.5, 0.05, -1.0, -0.9, -0.75, -0.3] {
        let (r, t) = ar.reflect_transmit(&ctx_of(&wl), cos);
        assert!(
            (r + t - Spec::ONE).abs().max_element() < 1e-5,
            "cos {cos}: {r} {t}"
        );
    }
    let green = SampledWavelengths::new([550.0; 4], [1.0; 4]);
    let (r_ar, _) = ar.reflect_transmit(&ctx_of(&green), 1.0);
    let (r_bare, _) = bare.reflect_transmit(&ctx_of(&green), 1.0);
    assert!(r_ar.x < 0.014 && r_bare.x > 0.035, "{r_ar} {r_bare}");
    // Sampling: refraction obeys Snell with the η² radiance factor; dispersive glass
    // terminates secondaries on refraction only.
    let Bsdf::CoatedDielectric(disp) = coated("MgF2:99.6", "cauchy:1.5046,4200") else {
        unreachable!()
    };
    let wi = dir(30.0, 0.0);
    let (r, t) = disp.reflect_transmit(&ctx_of(&wl), wi.z);
    let p_r = r.element_sum() / (r + t).element_sum();
    let refr = disp
        .sample(&ctx_of(&wl), wi, 0.999, Vec2::ZERO, Lobes::ALL)
        .unwrap();
    let n420 = 1.5046 + 4200.0 / (420.0f32 * 420.0);
    let sin_t = (refr.wo.x * refr.wo.x + refr.wo.y * refr.wo.y).sqrt();
    assert!(refr.wo.z < 0.0 && (sin_t - 0.5 / n420).abs() < 1e-5);
    assert!(refr.terminate_secondary && (refr.pdf - (1.0 - p_r)).abs() < 1e-6);
    let w = t / (1.0 - p_r) / (n420 * n420);
    assert!(
        (refr.weight - w).abs().max_element() < 1e-4,
        "{} vs {w}",
        refr.weight
    );
    let refl = disp
        .sample(&ctx_of(&wl), wi, 0.0, Vec2::ZERO, Lobes::ALL)
        .unwrap();
    assert!(refl.wo.z > 0.0 && !refl.terminate_secondary);
    assert!((refl.weight - r / p_r).abs().max_element() < 1e-5);
}

/// Fresnel splitting's lobes are exactly the lobes `sample` chooses between, each weighted by
/// its full value (sampled weight × selection probability): for glass, coated glass and a
/// bubble, from both sides, at normal, oblique, total-internal-reflection and grazing angles.
#[test]
fn split_lobes_are_the_sampled_lobes_at_full_weight() {
    let glass = dielectric("1.5");
    let cases = [
        ("glass", glass),
        ("coated", coated("MgF2:99.6", "1.5168")),
        ("bubble", bubble("1.33", 400.0)),
    ];
    let w = wl();
    let ctx = ctx_of(&w);
    counters::take();
    for (name, b) in &cases {
        assert!(b.is_fresnel_pair(), "{name}");
        for theta in [0.0f32, 30.0, 60.0, 85.0, 89.9] {
            for inside in [false, true] {
                let mut wi = dir(theta, 20.0);
                if inside {
                    wi.z = -wi.z;
                }
                let [r, t] = b.sample_split(&ctx, wi, 0.5, Vec2::ZERO);
                // The lobes sample() picks with u1 = 0 (reflection) and u1 → 1 (transmission).
                let forced = |u1: f32, reflection: bool| {
                    b.sample(&ctx, wi, u1, Vec2::ZERO, Lobes::ALL)
                        .filter(|s| (s.wo.z * wi.z > 0.0) == reflection)
                };
                for (what, got, want) in [("R", r, forced(0.0, true)), ("T", t, forced(1.0, false))]
                {
                    let at = format!("{name} θ={theta} inside={inside} {what}");
                    match (got, want) {
                        (Some(g), Some(s)) => {
                            assert!((g.wo - s.wo).abs().max_element() < 1e-6, "{at}");
                            assert_eq!((g.pdf, g.eta, g.is_delta()), (1.0, s.eta, true), "{at}");
                            let full = s.weight * s.pdf;
                            let err = (g.weight - full).abs().max_element();
                            assert!(
                                err <= 1e-5 * full.max_element().max(1e-3),
                                "{at}: {g:?} vs {s:?}"
                            );
                        }
                        // A lobe sampling cannot reach has zero weight in the split.
                        (None, None) => {}
                        (Some(g), None) => assert_eq!(g.weight.max_element(), 0.0, "{at}"),
                        (None, Some(s)) => panic!("{at}: split lost lobe {s:?}"),
                    }
                }
                // Lossless: R + T = 1 for glass and bubble (the transmitted weight is T·η_ti²,
                // η_ti = 1/η_it, and the sample's eta is η_it).
                if *name != "coated" {
                    let rt = r.map_or(0.0, |s| s.weight.x)
                        + t.map_or(0.0, |s| s.weight.x * s.eta * s.eta);
                    assert!(
                        (rt - 1.0).abs() < 1e-5,
                        "{name} θ={theta} inside={inside}: R+T {rt}"
                    );
                }
            }
        }
    }
}

/// `b`'s polarised form agrees with it: for unpolarised light a Mueller value's S0 response
/// is the unpolarised value (`eval`, and `sample`'s weight), and `sample_mueller` samples what
/// `sample` samples (direction, pdf, lobe) from the same random numbers.
pub(super) fn assert_mueller_agrees(name: &str, b: &Bsdf) {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let close =
        |a: Spec, b: Spec| (a - b).abs().max_element() <= 1e-4 * b.abs().max_element().max(1.0);
    let mut s = Sampler::from_seed(23);
    let m = b.polarized().unwrap_or_else(|e| panic!("{name}: {e}"));
    for k in 0..300 {
        let mut wi = dir(2.0 + 85.0 * s.next_1d(), 360.0 * s.next_1d());
        if k % 3 == 0 && b.flags().contains(BsdfFlags::TWO_SIDED) {
            wi.z = -wi.z;
        }
        let wo = dir(2.0 + 85.0 * s.next_1d(), 360.0 * s.next_1d());
        let (f, fm) = (
            b.eval(&ctx, wi, wo),
            m.eval_mueller(&ctx, wi, wo).unpolarized(),
        );
        assert!(close(fm, f), "{name} #{k}: Mueller eval {fm} vs {f}");
        let (u1, u2) = (s.next_1d(), s.next_2d());
        let plain = b.sample(&ctx, wi, u1, u2, Lobes::ALL);
        let pol = m.sample_mueller(&ctx, wi, u1, u2, Lobes::ALL);
        match (plain, pol) {
            (Some(a), Some((p, v))) => {
                assert!(
                    (a.wo - p.wo).length() < 1e-5 && (a.pdf - p.pdf).abs() <= 1e-5 * a.pdf.max(1.0),
                    "{name} #{k}"
                );
                assert_eq!(a.lobe, p.lobe, "{name} #{k}");
                assert!(
                    close(v.unpolarized(), a.weight),
                    "{name} #{k}: {} vs {}",
                    v.unpolarized(),
                    a.weight
                );
            }
            (None, None) => {}
            (a, p) => {
                // The unpolarised sample drops what is unusable (zero pdf, NaN).
                let kept = p.filter(|(p, _)| p.pdf > 0.0 && p.weight.max_element() > 0.0);
                assert!(
                    a.is_none() && kept.is_none(),
                    "{name} #{k}: {a:?} vs {kept:?}"
                );
            }
        }
    }
}

/// Every polarised form agrees with its model ([`assert_mueller_agrees`]).
#[test]
fn mueller_forms_agree_with_the_unpolarised_models() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    let mut all = test_bsdfs();
    all.push(("film", thin_film(0.0, 400.0)));
    all.push(("stack", stack("MgF2:100, TiO2:50", "BK7", 0.0)));
    all.push(("conductor", conductor("0.2+3.9i", 0.0, 0.0)));
    all.push(("dielectric", dielectric("1.5")));
    let film: Bsdf = twosided::TwoSided::new(thin_film(0.2, 300.0))
        .unwrap()
        .into();
    all.push(("twosided-film", film));
    // Models without a polarised form say so instead (a polarised scene is then refused).
    all.retain(|(_, b)| b.polarized().is_ok());
    assert!(all.len() >= 12);
    for (name, b) in &all {
        assert_mueller_agrees(name, b);
    }
    // A one-layer stack and the single film: two codes, one Mueller matrix.
    let (Bsdf::Stack(one), Bsdf::ThinFilm(film)) =
        (stack("1.37:400", "1.64", 0.0), thin_film(0.0, 400.0))
    else {
        unreachable!()
    };
    for theta in [0.0f32, 40.0, 75.0] {
        let wi = dir(theta, 30.0);
        let (a, b) = (
            one.sample_mueller(&ctx, wi, 0.5, Vec2::ZERO, Lobes::ALL)
                .unwrap()
                .1,
            film.sample_mueller(&ctx, wi, 0.5, Vec2::ZERO, Lobes::ALL)
                .unwrap()
                .1,
        );
        let (a, b) = (a.polarized.unwrap(), b.polarized.unwrap());
        for k in 0..4 {
            for i in 0..4 {
                for j in 0..4 {
                    let (x, y) = (a.m[k].0[i][j], b.m[k].0[i][j]);
                    assert!(
                        (x - y).abs() < 2e-5,
                        "θ {theta} λ{k} [{i}][{j}]: {x} vs {y}"
                    );
                }
            }
        }
    }
}

/// The rough dielectric in a white furnace: reflected plus transmitted energy (the
/// transmitted weight times η² undoes the radiance compression) is at most 1 and loses only
/// the few per cent single-scattering microfacets lose at α = 0.1, from either side; at
/// α → 0 the reflected fraction is the smooth interface's Fresnel reflectance.
#[test]
fn rough_dielectric_furnace_and_smooth_limit() {
    let wl = wl();
    let ctx = ctx_of(&wl);
    for kind in [Ggx, Beckmann] {
        for (alpha, wi) in [
            (0.1, dir(30.0, 10.0)),
            (0.1, -dir(50.0, 100.0)),
            (1e-3, dir(60.0, 0.0)),
        ] {
            let b = rough_dielectric(kind, 1.5, alpha, alpha);
            let mut s = Sampler::from_seed(5);
            let (mut energy, mut reflected) = (0.0f64, 0usize);
            let n = 200_000;
            for _ in 0..n {
                let Some(smp) = b.sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL) else {
                    continue;
                };
                let w = smp.weight[0] as f64;
                if smp.wo.z * wi.z > 0.0 {
                    reflected += 1;
                    energy += w;
                } else {
                    energy += w * (smp.eta as f64).powi(2);
                }
            }
            let energy = energy / n as f64;
            assert!(
                (0.95..=1.002).contains(&energy),
                "{kind:?} α={alpha} wi={wi}: energy {energy}"
            );
            if alpha < 0.01 {
                let f = fresnel::fresnel_dielectric(wi.z, 1.5).0 as f64;
                let freq = reflected as f64 / n as f64;
                assert!(
                    (freq - f).abs() < 0.005,
                    "{kind:?}: reflected {freq} vs Fresnel {f}"
                );
            }
        }
    }
}

/// Rough conductors of unit reflectance lose only the Smith single-scattering energy: the
/// mean sample weight is ≤ 1 and within a few per cent of 1 at α = 0.1 (both distributions,
/// isotropic and anisotropic), falling well below as α grows (GGX α = 0.8 keeps about half).
#[test]
fn rough_conductor_white_furnace() {
    for kind in [Ggx, Beckmann] {
        let mirror = |au, av| -> Bsdf {
            let mirror_index = Ior::Constant(crate::optics::Complex64::new(0.0, 1.0));
            conductor::Conductor::with_distribution(mirror_index, kind, au, av)
                .unwrap()
                .into()
        };
        let wi = dir(40.0, 70.0);
        let smooth = albedo(&mirror(0.1, 0.1), wi, 100_000)[0];
        let aniso = albedo(&mirror(0.05, 0.2), wi, 100_000)[0];
        let rough = albedo(&mirror(0.8, 0.8), wi, 100_000)[0];
        assert!((0.97..=1.0).contains(&smooth), "{kind:?}: {smooth}");
        assert!((0.95..=1.0).contains(&aniso), "{kind:?}: {aniso}");
        assert!(rough < smooth - 0.2 && rough > 0.3, "{kind:?}: {rough}");
    }
}

/// Mitsuba 3's own `eval` and `pdf` of `roughconductor`, `roughplastic` and
/// `roughdielectric` at direction pairs near their lobes (tests/references/bsdf_points.json,
/// from tools/mitsuba/bsdf_point_references.py): within 1 % (Mitsuba's Beckmann G1 is a
/// rational fit of the exact one, 0.35 % apart). Covers Beckmann as the default, anisotropy
/// along the frame's s axis, the rough plastic's tabulated coating transmittance and internal
/// reflectance at α = 0.01…1, and rough refraction from both sides.
#[test]
fn microfacet_models_match_mitsuba_points() {
    let doc: serde_json::Value =
        serde_json::from_str(include_str!("../../../tests/references/bsdf_points.json")).unwrap();
    let wl = wl();
    let ctx = ctx_of(&wl);
    let points = doc["points"].as_array().unwrap();
    assert!(points.len() >= 100);
    for (k, p) in points.iter().enumerate() {
        let c = &p["bsdf"];
        let num = |key: &str, default: f64| c[key].as_f64().unwrap_or(default) as f32;
        let kind = match c["distribution"].as_str() {
            Some("ggx") => Ggx,
            _ => Beckmann,
        };
        let (au, av) = (
            num("alpha_u", num("alpha", 0.1) as f64),
            num("alpha_v", num("alpha", 0.1) as f64),
        );
        let b: Bsdf = match c["type"].as_str().unwrap() {
            "roughconductor" => conductor::Conductor::with_distribution(
                format!("{}+{}i", num("eta", 0.0), num("k", 1.0))
                    .parse()
                    .unwrap(),
                kind,
                au,
                av,
            )
            .unwrap()
            .into(),
            "roughplastic" => plastic::Plastic::with_distribution(
                &constant(0.5),
                (num("int_ior", 1.49), num("ext_ior", 1.000277)),
                c["nonlinear"].as_bool().unwrap_or(false),
                kind,
                au,
            )
            .unwrap()
            .into(),
            _ => rough_dielectric(
                kind,
                num("int_ior", 1.5046) / num("ext_ior", 1.000277),
                au,
                av,
            ),
        };
        let v3 = |key: &str| {
            let a: Vec<f32> = p[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect();
            Vec3::new(a[0], a[1], a[2])
        };
        let (wi, wo) = (v3("wi"), v3("wo"));
        let value = b.eval(&ctx, wi, wo)[0] as f64;
        let pdf = b.pdf(&ctx, wi, wo) as f64;
        let (ref_value, ref_pdf) = (p["eval"].as_f64().unwrap(), p["pdf"].as_f64().unwrap());
        assert!(
            (value - ref_value).abs() <= 0.01 * ref_value + 1e-5,
            "#{k} {c}: eval {value} vs Mitsuba {ref_value} (wi {wi}, wo {wo})"
        );
        assert!(
            (pdf - ref_pdf).abs() <= 0.01 * ref_pdf + 1e-5,
            "#{k} {c}: pdf {pdf} vs Mitsuba {ref_pdf} (wi {wi}, wo {wo})"
        );
    }
}

/// The thin slab reflects R + T²R/(1 − R²) (Mitsuba's `thindielectric`): the sampled
/// reflection frequency matches it, transmission leaves along −wi with weight 1, and the two
/// lobes sum to 1 (lossless).
#[test]
fn thin_dielectric_reflectance_and_pass_through() {
    let b: Bsdf = thindielectric::ThinDielectric {
        eta: 1.5,
        factors: Default::default(),
    }
    .into();
    let wl = wl();
    let ctx = ctx_of(&wl);
    for wi in [dir(10.0, 0.0), dir(70.0, 40.0), -dir(45.0, 10.0)] {
        let r = fresnel::fresnel_dielectric(wi.z.abs(), 1.5).0;
        let expect = r + (1.0 - r) * (1.0 - r) * r / (1.0 - r * r);
        assert!(expect > r && expect < 2.0 * r + 1e-6);
        let mut s = Sampler::from_seed(3);
        let (mut refl, n) = (0usize, 100_000);
        for _ in 0..n {
            let smp = b
                .sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL)
                .unwrap();
            assert_eq!(smp.weight[0], 1.0);
            if smp.wo.z * wi.z > 0.0 {
                refl += 1;
            } else {
                assert!((smp.wo + wi).length() < 1e-6);
            }
        }
        let freq = refl as f32 / n as f32;
        assert!((freq - expect).abs() < 0.004, "wi {wi}: {freq} vs {expect}");
        let [r_lobe, t_lobe] = b.sample_split(&ctx, wi, 0.5, Vec2::splat(0.5));
        let total = r_lobe.unwrap().weight[0] + t_lobe.unwrap().weight[0];
        assert!((total - 1.0).abs() < 1e-6, "{total}");
    }
}

/// `mask`: with opacity o the null lobe (wo = −wi, weight 1) is sampled with probability
/// 1 − o, the nested model's eval and pdf scale by o, and its samples keep their weight.
#[test]
fn mask_passes_through_with_one_minus_opacity() {
    let b: Bsdf = mask::Mask {
        inner: Box::new(diffuse(0.8)),
        opacity: Texture::new(&constant(0.3)),
    }
    .into();
    let wl = wl();
    let ctx = ctx_of(&wl);
    let wi = dir(30.0, 50.0);
    let wo = dir(60.0, 200.0);
    let d = diffuse(0.8);
    assert!((b.eval(&ctx, wi, wo)[0] - 0.3 * d.eval(&ctx, wi, wo)[0]).abs() < 1e-6);
    assert!((b.pdf(&ctx, wi, wo) - 0.3 * d.pdf(&ctx, wi, wo)).abs() < 1e-6);
    let mut s = Sampler::from_seed(9);
    let (mut null, n) = (0usize, 100_000);
    for _ in 0..n {
        let smp = b
            .sample(&ctx, wi, s.next_1d(), s.next_2d(), Lobes::ALL)
            .unwrap();
        if smp.lobe == BsdfFlags::NULL {
            null += 1;
            assert!((smp.wo + wi).length() < 1e-6 && smp.weight[0] == 1.0);
        } else {
            assert!((smp.weight[0] - 0.8).abs() < 1e-4, "{}", smp.weight[0]);
        }
    }
    let freq = null as f32 / n as f32;
    assert!((freq - 0.7).abs() < 0.005, "{freq}");
    assert_eval_pdf_sample_agree("mask", &b);
    assert_chi2("mask", &b, 1e-3);
}
