//! Polarised `path` integrator: the same unidirectional hero-wavelength path
//! tracer as [`super::integrator`] (same sampling decisions, MIS, Russian roulette and random
//! stream layout), but light carries Stokes vectors and BSDFs act as Mueller matrices, with
//! Mitsuba 3's conventions ([`super::polarization`]). Used only when the scene asks for a
//! polariser (effect analysis, `effects.rs`); other scenes never reach this file.
//!
//! **Adjoint (covector) transport.** The sensor records S0 only, and emitters are
//! unpolarised, so the measured value of a path with Mueller matrices M₁ … M_k (camera side
//! first) is e₀ᵀ · M₁ ⋯ M_k · (L, 0, 0, 0)ᵀ. Mitsuba multiplies full 4×4 throughput matrices;
//! here the row vector `row = e₀ᵀ · M₁ ⋯ M_j` (4 numbers per wavelength) is carried from the
//! camera instead — exactly the first row of Mitsuba's throughput, at a quarter of the cost.
//! `row[0]` is Mitsuba's `unpolarized_spectrum(throughput)`, used for Russian roulette.
//!
//! **Reference frames.** `row` is expressed against Stokes vectors of light travelling along
//! `−ray.dir` in the basis vector `basis` (world). Each BSDF lobe is built in its natural frame
//! (Mitsuba's: s = n × (−wo) on the incident side, s = n × wi on the outgoing side, with the
//! microfacet normal for rough lobes), and the row is rotated into that frame first:
//! `row ← row · R(wi, s_out → basis) · M`, after which `basis = s_in`. Frame choices cancel, so
//! the result equals Mitsuba's, which routes everything through `stokes_basis(direction)`.
//!
//! **Sensor polariser** ([`crate::scene::Polarizer`]): the path starts from the covector of an
//! ideal polariser, e₀ᵀ·P = (½, ±½, 0, 0) in the polariser's basis: for `S`/`P` the basis is
//! the s direction n × wi of the camera ray's first hit (so S passes R_s/2 of unpolarised
//! light reflected there, P passes R_p/2), for an angle it is the axis in the image plane
//! projected perpendicular to the ray (Korger et al. 2013, as Mitsuba's `polarizer` BSDF).

use super::bsdf::{Bsdf, BsdfSample, Counters, ShadingCtx};
use super::camera::Ray;
use super::geometry::{mis_power, Frame, SurfaceInteraction};
use super::integrator::{run_branches, PathState};
use super::polarization::{
    film_reflection, row_times_rotation, specular_reflection, specular_reflection_conductor,
    specular_transmission, stokes_basis, Mueller, Stokes,
};
use super::sampler::Sampler;
use super::texture::Spec;
use super::PreparedScene;
use crate::scene::{Geometry, Polarizer, Scene};
use crate::spectrum::SampledWavelengths;
use anyhow::{bail, Result};
use glam::{Vec2, Vec3};
use num_complex::Complex32;

/// Scene data the polarised integrator needs beyond the unpolarised one.
#[derive(Debug, Clone)]
pub struct PolarizedSetup {
    /// Polariser in front of the sensor, if any.
    pub sensor: Option<Polarizer>,
    /// World directions of the image's +x (rightwards) and +y (upwards) axes.
    image_x: Vec3,
    image_y: Vec3,
    /// Per shape with a `polarizer` BSDF: its world tangents (u, v) = (dp/du ⟂ n, n × u).
    polarizer_axes: Vec<Option<(Vec3, Vec3)>>,
}

/// Mitsuba's shading tangents (s, t) = (normalize(dp/du ⟂ n), n × s) of a mesh triangle.
fn triangle_axes(p: [Vec3; 3], uv: Option<[Vec2; 3]>, n: Vec3) -> Option<(Vec3, Vec3)> {
    let (dp1, dp2) = (p[1] - p[0], p[2] - p[0]);
    // Without UVs Mitsuba parameterises by the barycentrics: uv = (0,0), (1,0), (0,1).
    let [t0, t1, t2] = uv.unwrap_or([Vec2::ZERO, Vec2::X, Vec2::Y]);
    let (duv1, duv2) = (t1 - t0, t2 - t0);
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if det.abs() < 1e-12 {
        return None;
    }
    let dp_du = (duv2.y * dp1 - duv1.y * dp2) / det;
    let s = dp_du - n * n.dot(dp_du);
    (s.length_squared() > 1e-20).then(|| (s.normalize(), n.cross(s.normalize())))
}

impl PolarizedSetup {
    /// Checks the scene's polarisers and precomputes their frames. A `polarizer` BSDF must
    /// sit on a planar mesh with one consistent (u, v) parameterisation (a `rectangle`, a
    /// `disk`, a flat mesh), because its axis comes from dp/du.
    pub fn build(scene: &Scene, bsdfs: &[Bsdf]) -> Result<Self> {
        let m = scene.camera.to_world;
        let image_x = -m.transform_vector3(Vec3::X).normalize();
        let image_y = m.transform_vector3(Vec3::Y).normalize();
        let mut polarizer_axes = vec![None; scene.shapes.len()];
        for (i, shape) in scene.shapes.iter().enumerate() {
            let name = || shape.name.clone().unwrap_or_else(|| format!("shape {i}"));
            match bsdfs.get(shape.bsdf) {
                Some(Bsdf::Polarizer(_)) => {}
                Some(Bsdf::TwoSided(inner)) if matches!(**inner, Bsdf::Polarizer(_)) => {
                    bail!(
                        "{}: a polarizer is already two-sided; remove the twosided wrapper",
                        name()
                    )
                }
                _ => continue,
            }
            let Geometry::Mesh(mesh) = &shape.geometry else {
                bail!("{}: the polarizer BSDF is supported on planar meshes (rectangle, disk), not on spheres", name());
            };
            let mut axis: Option<(Vec3, Vec3, Vec3)> = None;
            for tri in &mesh.indices {
                let p = tri.map(|k| mesh.positions[k as usize]);
                let ng = (p[1] - p[0]).cross(p[2] - p[0]);
                if ng.length_squared() < 1e-20 {
                    continue;
                }
                let n = if mesh.normals.is_empty() {
                    ng.normalize()
                } else {
                    let s = tri
                        .iter()
                        .map(|&k| mesh.normals[k as usize])
                        .fold(Vec3::ZERO, |a, b| a + b);
                    if s.length_squared() > 0.0 {
                        s.normalize()
                    } else {
                        ng.normalize()
                    }
                };
                let uv = (!mesh.uvs.is_empty()).then(|| tri.map(|k| mesh.uvs[k as usize]));
                let Some((u, t)) = triangle_axes(p, uv, n) else {
                    continue;
                };
                match axis {
                    None => axis = Some((u, t, n)),
                    Some((_, t0, n0)) => {
                        if t.dot(t0) < 0.9999 || n.dot(n0).abs() < 0.9999 {
                            bail!(
                                "{}: the polarizer BSDF needs a planar shape with one (u, v) \
                                 parameterisation (its axis follows dp/du); use a rectangle",
                                name()
                            );
                        }
                    }
                }
            }
            let Some((u, t, _)) = axis else {
                bail!("{}: polarizer shape has no non-degenerate triangle", name());
            };
            polarizer_axes[i] = Some((u, t));
        }
        Ok(PolarizedSetup {
            sensor: scene.polarizer,
            image_x,
            image_y,
            polarizer_axes,
        })
    }
}

/// A BSDF lobe as a Mueller operator: a depolarising part (only S0 survives, scaled per
/// wavelength) plus optionally a polarising part, per wavelength, in its natural frame.
struct Lobe {
    depol: Spec,
    /// (per-wavelength matrices, world basis of the incident light travelling along −wo,
    /// world basis of the outgoing light travelling along wi)
    pol: Option<([Mueller; 4], Vec3, Vec3)>,
}

impl Lobe {
    fn depolarizing(v: Spec) -> Self {
        Lobe {
            depol: v,
            pol: None,
        }
    }

    fn scaled(mut self, f: f32) -> Self {
        self.depol *= f;
        if let Some((m, _, _)) = &mut self.pol {
            for x in m.iter_mut() {
                *x = x.scale(f);
            }
        }
        self
    }

    /// row · M[:, 0] per wavelength (what an unpolarised source contributes), with `row` in
    /// `basis` for light leaving along `wi_world`.
    fn column0(&self, rows: &[Stokes; 4], basis: Vec3, wi_world: Vec3) -> Spec {
        let d = self.depol.to_array();
        let mut out = [0.0; 4];
        for k in 0..4 {
            out[k] = rows[k][0] * d[k];
        }
        if let Some((m, _, s_out)) = &self.pol {
            for k in 0..4 {
                let r = row_times_rotation(rows[k], wi_world, *s_out, basis);
                out[k] += (0..4).map(|j| r[j] * m[k].0[j][0]).sum::<f32>();
            }
        }
        Spec::from_array(out)
    }

    /// The row after this vertex and its new basis (for light travelling along −wo_world).
    fn propagate(&self, rows: &mut [Stokes; 4], basis: &mut Vec3, wi_world: Vec3, wo_world: Vec3) {
        let d = self.depol.to_array();
        match &self.pol {
            None => {
                for k in 0..4 {
                    rows[k] = [rows[k][0] * d[k], 0.0, 0.0, 0.0];
                }
                *basis = stokes_basis(-wo_world);
            }
            Some((m, s_in, s_out)) => {
                for k in 0..4 {
                    let r = row_times_rotation(rows[k], wi_world, *s_out, *basis);
                    let mut out = m[k].left_apply(r);
                    out[0] += rows[k][0] * d[k];
                    rows[k] = out;
                }
                *basis = *s_in;
            }
        }
    }
}

/// Unit s axis n × v (Mitsuba: zero-length → None).
#[inline]
fn s_axis(n: Vec3, v: Vec3) -> Option<Vec3> {
    let c = n.cross(v);
    let l2 = c.length_squared();
    (l2 > 1e-14).then(|| c / l2.sqrt())
}

/// Natural frame of a specular interaction about normal `m` (local): (s_in, s_out), with
/// Mitsuba's fallback (1, 0, 0) when the directions are collinear with `m`.
#[inline]
fn plane_axes(m: Vec3, wi: Vec3, wo: Vec3) -> (Vec3, Vec3) {
    match s_axis(m, -wo) {
        Some(a) => (a, s_axis(m, wi).unwrap_or(a)),
        None => (Vec3::X, Vec3::X),
    }
}

fn polarizing(m: [Mueller; 4], axes: (Vec3, Vec3), frame: &Frame, flip: bool) -> Lobe {
    let unflip = |v: Vec3| if flip { Vec3::new(v.x, v.y, -v.z) } else { v };
    Lobe {
        depol: Spec::ZERO,
        pol: Some((
            m,
            frame.to_world(unflip(axes.0)),
            frame.to_world(unflip(axes.1)),
        )),
    }
}

#[inline]
fn c32(z: crate::optics::Complex64) -> Complex32 {
    Complex32::new(z.re as f32, z.im as f32)
}

/// Fresnel Mueller matrices of a BSDF's specular interface at `cos_i` (per wavelength), for
/// the models whose Fresnel term is polarising; None for the others.
fn fresnel_mueller(
    bsdf: &Bsdf,
    ctx: &ShadingCtx,
    cos_i: f32,
    counters: &mut Counters,
) -> Option<[Mueller; 4]> {
    let l = ctx.wl.lambda;
    Some(match bsdf {
        Bsdf::Conductor(b) => {
            l.map(|lam| specular_reflection_conductor(cos_i, c32(b.eta.at(lam as f64))))
        }
        Bsdf::ThinFilm(b) => {
            counters.film_evals += 1;
            let d = b.thickness_nm.eval_scalar(ctx.uv);
            l.map(|lam| {
                let a = b.film_at(lam, d).amplitudes(lam as f64, cos_i as f64);
                let m = film_reflection(c32(a.r_s), c32(a.r_p));
                if m.is_finite() {
                    m
                } else {
                    Mueller::ZERO
                }
            })
        }
        Bsdf::Plastic(b) => [specular_reflection(cos_i, b.eta); 4],
        _ => return None,
    })
}

/// Polarised f·|cos θo| for the non-delta components at (wi, wo), local, one-sided models
/// flipped by `TwoSided`.
fn eval_lobe(
    bsdf: &Bsdf,
    ctx: &ShadingCtx,
    frame: &Frame,
    wi: Vec3,
    wo: Vec3,
    flip: bool,
    counters: &mut Counters,
) -> Lobe {
    match bsdf {
        Bsdf::TwoSided(inner) => {
            if wi.z < 0.0 {
                let f = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
                eval_lobe(inner, ctx, frame, f(wi), f(wo), !flip, counters)
            } else {
                eval_lobe(inner, ctx, frame, wi, wo, flip, counters)
            }
        }
        Bsdf::Conductor(b) => match b.ggx.and_then(|g| g.reflection(wi, wo)) {
            Some((m, w)) => match fresnel_mueller(bsdf, ctx, wi.dot(m), counters) {
                Some(f) => polarizing(f.map(|x| x.scale(w)), plane_axes(m, wi, wo), frame, flip),
                None => Lobe::depolarizing(Spec::ZERO),
            },
            None => Lobe::depolarizing(Spec::ZERO),
        },
        Bsdf::ThinFilm(b) => match b.ggx.and_then(|g| g.reflection(wi, wo)) {
            Some((m, w)) => match fresnel_mueller(bsdf, ctx, wi.dot(m), counters) {
                Some(f) => polarizing(f.map(|x| x.scale(w)), plane_axes(m, wi, wo), frame, flip),
                None => Lobe::depolarizing(Spec::ZERO),
            },
            None => Lobe::depolarizing(Spec::ZERO),
        },
        Bsdf::Plastic(b) => {
            // Diffuse part depolarised, specular microfacet part polarised (Fresnel at the
            // microfacet, as Mitsuba's polarised plastic).
            let total = b.eval(ctx, wi, wo);
            match b.ggx {
                Some(ggx) if wi.z > 0.0 && wo.z > 0.0 => {
                    let m = (wi + wo).normalize();
                    let scale = ggx.d(m) * ggx.g(wi, wo, m) / (4.0 * wi.z);
                    let f = specular_reflection(wi.dot(m), b.eta).scale(scale);
                    let mut lobe = polarizing([f; 4], plane_axes(m, wi, wo), frame, flip);
                    lobe.depol = total - Spec::splat(f.0[0][0]);
                    lobe
                }
                _ => Lobe::depolarizing(total),
            }
        }
        other => Lobe::depolarizing(other.eval(ctx, wi, wo, counters)),
    }
}

/// Samples like [`Bsdf::sample`] (same directions, pdfs, random numbers) and returns the
/// Mueller weight (eval / pdf) of the sampled direction.
#[allow(clippy::too_many_arguments)]
fn sample_lobe(
    bsdf: &Bsdf,
    ctx: &ShadingCtx,
    frame: &Frame,
    wi: Vec3,
    u1: f32,
    u2: Vec2,
    flip: bool,
    counters: &mut Counters,
) -> Option<(BsdfSample, Lobe)> {
    if let Bsdf::TwoSided(inner) = bsdf {
        if wi.z < 0.0 {
            let f = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
            let (mut s, lobe) = sample_lobe(inner, ctx, frame, f(wi), u1, u2, !flip, counters)?;
            s.wo = f(s.wo);
            return Some((s, lobe));
        }
        return sample_lobe(inner, ctx, frame, wi, u1, u2, flip, counters);
    }
    // The unpolarised sample fixes direction, pdf and lobe choice (its own Fresnel work is
    // not counted: the Mueller version below is what this integrator uses).
    let s = bsdf.sample(ctx, wi, u1, u2, &mut Counters::default())?;
    let wo = s.wo;
    let lobe = match bsdf {
        Bsdf::Conductor(_) | Bsdf::ThinFilm(_) => match b_ggx(bsdf) {
            None => {
                let f = fresnel_mueller(bsdf, ctx, wi.z, counters)?;
                polarizing(f, plane_axes(Vec3::Z, wi, wo), frame, flip)
            }
            Some(g) => {
                let m = (wi + wo).normalize();
                let g1 = g.g1(wo, m);
                let f = fresnel_mueller(bsdf, ctx, wi.dot(m), counters)?;
                polarizing(f.map(|x| x.scale(g1)), plane_axes(m, wi, wo), frame, flip)
            }
        },
        Bsdf::Dielectric(b) => {
            // Mitsuba: the Mueller matrix of the interface for light arriving along −wo
            // (cos θ of wo, signed), divided by the lobe probability; transmission also
            // carries the η_ti² radiance compression already in the unpolarised weight.
            let reflected = wo.z * wi.z > 0.0;
            let w = s.weight.to_array();
            let m: [Mueller; 4] = std::array::from_fn(|k| {
                let lam = ctx.wl.lambda[k] as f64;
                let eta = (b.int_ior.at(lam).re / b.ext_ior.at(lam).re) as f32;
                let x = if reflected {
                    specular_reflection(wo.z, eta)
                } else {
                    specular_transmission(wo.z, eta)
                };
                x.scale(w[k] / s.pdf)
            });
            polarizing(m, plane_axes(Vec3::Z, wi, wo), frame, flip)
        }
        Bsdf::Plastic(b) => {
            if s.delta {
                let f = specular_reflection(wi.z, b.eta).scale(1.0 / s.pdf);
                polarizing([f; 4], plane_axes(Vec3::Z, wi, wo), frame, flip)
            } else if b.ggx.is_some() {
                eval_lobe(bsdf, ctx, frame, wi, wo, flip, counters).scaled(1.0 / s.pdf)
            } else {
                Lobe::depolarizing(s.weight)
            }
        }
        _ => Lobe::depolarizing(s.weight),
    };
    Some((s, lobe))
}

fn b_ggx(b: &Bsdf) -> Option<super::bsdf::microfacet::Ggx> {
    match b {
        Bsdf::Conductor(c) => c.ggx,
        Bsdf::ThinFilm(t) => t.ggx,
        Bsdf::Plastic(p) => p.ggx,
        _ => None,
    }
}

/// The sensor polariser's covector and basis for a camera ray (`dir`), given the first hit's
/// shading normal (None on a miss).
fn sensor_row(setup: &PolarizedSetup, dir: Vec3, first_normal: Option<Vec3>) -> (Stokes, Vec3) {
    let forward = -dir;
    let fallback = stokes_basis(forward);
    match setup.sensor {
        None => ([1.0, 0.0, 0.0, 0.0], fallback),
        Some(Polarizer::AngleDeg(deg)) => {
            let (s, c) = deg.to_radians().sin_cos();
            let a = c * setup.image_x + s * setup.image_y;
            let a = a - a.dot(forward) * forward;
            let basis = if a.length_squared() > 1e-12 {
                a.normalize()
            } else {
                fallback
            };
            ([0.5, 0.5, 0.0, 0.0], basis)
        }
        Some(p) => {
            // s direction of the first hit's plane of incidence: n × wi (Mitsuba's s_axis_out).
            let basis = first_normal
                .and_then(|n| s_axis(n, forward))
                .unwrap_or(fallback);
            let sign = if p == Polarizer::S { 0.5 } else { -0.5 };
            ([0.5, sign, 0.0, 0.0], basis)
        }
    }
}

/// One path or split branch between vertices: the Stokes covectors (per wavelength) and
/// their basis carry what the unpolarised integrator's throughput carries.
#[derive(Clone, Copy)]
struct Branch {
    path: PathState,
    rows: [Stokes; 4],
    basis: Vec3,
}

#[inline]
fn s0(rows: &[Stokes; 4]) -> Spec {
    Spec::new(rows[0][0], rows[1][0], rows[2][0], rows[3][0])
}

/// Radiance (S0 at the sensor) along `ray` at the path's wavelengths, with polarisation.
/// Mirrors [`super::integrator::li`] step by step, Fresnel splitting included.
pub fn li(
    scene: &PreparedScene,
    setup: &PolarizedSetup,
    ray: Ray,
    pixel: Option<[u32; 2]>,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spec {
    let first = Branch {
        path: PathState::camera(ray, pixel),
        rows: [[1.0, 0.0, 0.0, 0.0]; 4],
        basis: stokes_basis(-ray.dir),
    };
    run_branches(first, |b, pending| {
        trace(scene, setup, b, wl, sampler, counters, pending)
    })
}

/// Follows one branch to its end; returns what it collected, pushes split-off branches.
fn trace(
    scene: &PreparedScene,
    setup: &PolarizedSetup,
    mut b: Branch,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    counters: &mut Counters,
    pending: &mut Vec<Branch>,
) -> Spec {
    let max_depth = scene.settings.max_depth;
    let lights = &scene.lights;
    let sel_pdf = lights.selection_pdf();
    let mut radiance = Spec::ZERO;

    loop {
        let ray = b.path.ray;
        counters.rays += 1;
        let hit = scene.intersect(&ray, b.path.pixel);
        let si = hit.map(|h| scene.accel.interaction(&ray, &h));
        if b.path.depth == 0 && setup.sensor.is_some() {
            let (row, basis) = sensor_row(setup, ray.dir, si.map(|s| s.shading.n));
            b.rows = [row; 4];
            b.basis = basis;
        }

        let Some(si) = si else {
            if !(b.path.depth == 0 && scene.settings.hide_emitters) {
                for &li in &lights.infinite {
                    let light = &lights.lights[li as usize];
                    let le = light.eval_env(ray.dir, wl);
                    let w = b.path.emitter_hit_weight(|prev_p| {
                        sel_pdf * light.pdf_direction(prev_p, ray.dir, f32::INFINITY, Vec3::ZERO)
                    });
                    radiance += s0(&b.rows) * le * w;
                }
            }
            break;
        };
        if let Some(li) = lights.shape_light[si.shape as usize] {
            if si.ng.dot(-ray.dir) > 0.0 && !(b.path.depth == 0 && scene.settings.hide_emitters) {
                let light = &lights.lights[li as usize];
                if let super::lights::Light::Area { radiance: le, .. } = light {
                    let w = b.path.emitter_hit_weight(|prev_p| {
                        sel_pdf * light.pdf_direction(prev_p, ray.dir, si.t, si.ng)
                    });
                    radiance += s0(&b.rows) * le.eval(wl) * w;
                }
            }
        }

        if max_depth >= 0 && b.path.depth as i64 + 1 >= max_depth as i64 {
            break;
        }
        let bsdf: &Bsdf = &scene.bsdfs[scene.shape_bsdf[si.shape as usize] as usize];
        let wi_world = -ray.dir;
        let wi = si.shading.to_local(wi_world);
        let ctx = ShadingCtx { wl, uv: si.uv };

        // ---- Emitter sampling ----
        if bsdf.has_smooth_component() && !lights.lights.is_empty() {
            let light = lights.pick(sampler);
            if let Some(ls) = light.sample(si.p, sampler.next_2d(), wl) {
                let wo = si.shading.to_local(ls.wi);
                let lobe = eval_lobe(bsdf, &ctx, &si.shading, wi, wo, false, counters);
                let f = lobe.column0(&b.rows, b.basis, wi_world);
                if ls.pdf > 0.0 && f.max_element() > 0.0 && ls.radiance.max_element() > 0.0 {
                    let shadow = ls.shadow_ray(si.p, si.ng);
                    counters.shadow_rays += 1;
                    if !scene.accel.occluded(&shadow) {
                        let light_pdf = sel_pdf * ls.pdf;
                        let w = if ls.delta {
                            1.0
                        } else {
                            mis_power(light_pdf, bsdf.pdf(wi, wo))
                        };
                        radiance += f * ls.radiance * (w / light_pdf);
                    }
                }
            }
        } else {
            sampler.skip(1, 1);
        }

        // ---- BSDF sampling, or both lobes of a Fresnel pair ----
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        if b.path.splits < scene.fresnel_splits && bsdf.is_fresnel_pair() {
            b.path.splits += 1;
            // The lobes of `sample_lobe` forced by u1 (0: reflection, 1: transmission), with
            // the selection probability multiplied back in, as [`Bsdf::split`] does.
            let mut forced = |u1: f32, reflection: bool| {
                let (mut bs, lobe) =
                    sample_lobe(bsdf, &ctx, &si.shading, wi, u1, u2, false, counters)?;
                if (bs.wo.z * wi.z > 0.0) != reflection {
                    return None;
                }
                let lobe = lobe.scaled(bs.pdf);
                bs.weight *= bs.pdf;
                bs.pdf = 1.0;
                Some((bs, lobe))
            };
            let reflected = forced(0.0, true);
            let transmitted = forced(1.0, false);
            if let Some((bs, lobe)) = reflected {
                let mut r = b;
                if advance(scene, &mut r, &si, wi, &bs, &lobe, wl, sampler) {
                    pending.push(r);
                }
            }
            match transmitted {
                Some((bs, lobe)) if advance(scene, &mut b, &si, wi, &bs, &lobe, wl, sampler) => {
                    continue
                }
                _ => break,
            }
        }
        let (bs, lobe) = if let Bsdf::Polarizer(p) = bsdf {
            // Mitsuba `polarizer`: the beam travels along wi_world through the sheet.
            let (Some((u_axis, v_axis)), Some(bs)) =
                (setup.polarizer_axes[si.shape as usize], p.sample(&ctx, wi))
            else {
                break;
            };
            let (m, basis) = p.mueller(wi_world, u_axis, v_axis);
            let t = p.transmittance.eval(si.uv, wl).to_array();
            let lobe = Lobe {
                depol: Spec::ZERO,
                pol: Some((std::array::from_fn(|k| m.scale(t[k])), basis, basis)),
            };
            (bs, lobe)
        } else {
            match sample_lobe(bsdf, &ctx, &si.shading, wi, u1, u2, false, counters) {
                Some(x) => x,
                None => break,
            }
        };
        if !advance(scene, &mut b, &si, wi, &bs, &lobe, wl, sampler) {
            break;
        }
    }
    radiance
}

/// Moves branch `b` across vertex `si` along the sampled `bs` with Mueller weight `lobe`,
/// with Russian roulette on e₀ᵀ·throughput·e₀ (Mitsuba's unpolarized_spectrum); false if the
/// path ends there.
#[allow(clippy::too_many_arguments)]
fn advance(
    scene: &PreparedScene,
    b: &mut Branch,
    si: &SurfaceInteraction,
    wi: Vec3,
    bs: &BsdfSample,
    lobe: &Lobe,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
) -> bool {
    let wi_world = -b.path.ray.dir;
    let Some(wo_world) = b.path.cross(si, wi, bs) else {
        return false;
    };
    if bs.terminate_secondary && !wl.secondary_terminated() {
        wl.terminate_secondary();
    }
    lobe.propagate(&mut b.rows, &mut b.basis, wi_world, wo_world);
    if wl.secondary_terminated() {
        for r in b.rows.iter_mut().skip(1) {
            *r = [0.0; 4];
        }
    }
    let max = s0(&b.rows).max_element();
    match b.path.roulette(scene.settings.rr_depth, max, sampler) {
        None => false,
        Some(q) => {
            if q != 1.0 {
                for r in b.rows.iter_mut() {
                    for v in r.iter_mut() {
                        *v /= q;
                    }
                }
            }
            true
        }
    }
}
