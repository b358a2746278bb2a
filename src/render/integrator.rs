//! The `path` integrator: unidirectional path tracing with hero-wavelength spectral transport
//! (four wavelengths follow one path), next-event estimation with multiple importance sampling
//! (power heuristic) between BSDF and emitter sampling, and Russian roulette, all with Mitsuba 3
//! semantics (conventions.md "Path integrator"):
//! - `max_depth` counts path vertices: 1 = directly visible emitters only, −1 = unlimited;
//! - from depth ≥ `rr_depth` a path survives with probability min(max β · η², 0.95).
//!
//! One departure, which changes the noise and not the expectation: at the first
//! [`PreparedScene::fresnel_splits`] smooth reflect/transmit interfaces of a path (glass,
//! coated glass, bubbles; [`Bsdf::is_fresnel_pair`]) *both* lobes are followed with their full
//! Fresnel weights instead of one chosen with probability R (splitting; Arvo & Kirk 1990).
//! Mitsuba picks one; at 4 % reflectance that leaves a glass surface's mirrored highlights to
//! one sample in 25, the main source of noise in `scenes/lens.xml`.

use super::accel::Hit;
use super::bsdf::{Bsdf, BsdfSample, Counters, ShadingCtx};
use super::camera::Ray;
use super::geometry::{mis_power, offset_ray_origin, SurfaceInteraction};
use super::sampler::Sampler;
use super::texture::Spec;
use super::PreparedScene;
use crate::spectrum::SampledWavelengths;
use glam::Vec3;

/// What a path (or one branch of a split path) carries between vertices besides its
/// throughput, which is a spectrum here and Stokes covectors in the polarised integrator.
#[derive(Clone, Copy)]
pub(super) struct PathState {
    pub ray: Ray,
    pub eta: f32,
    pub depth: u32,
    /// Previous vertex and how its direction was sampled, for MIS on emitters hit.
    prev_p: Vec3,
    prev_bsdf_pdf: f32,
    prev_bsdf_delta: bool,
    /// Fresnel splits already made on the way here.
    pub splits: u32,
    /// The pixel a camera ray was generated in (None after the first vertex): lets
    /// [`PreparedScene::intersect`] use the screen bins.
    pub pixel: Option<[u32; 2]>,
}

impl PathState {
    pub fn camera(ray: Ray, pixel: Option<[u32; 2]>) -> Self {
        PathState {
            pixel,
            ray,
            eta: 1.0,
            depth: 0,
            prev_p: ray.origin,
            prev_bsdf_pdf: 1.0,
            prev_bsdf_delta: true,
            splits: 0,
        }
    }

    /// MIS weight of an emitter this ray hit, against light sampling from the previous
    /// vertex; `light_pdf(prev_p)` is evaluated only if the ray was not a delta sample.
    #[inline]
    pub fn emitter_hit_weight(&self, light_pdf: impl FnOnce(Vec3) -> f32) -> f32 {
        if self.prev_bsdf_delta {
            1.0
        } else {
            mis_power(self.prev_bsdf_pdf, light_pdf(self.prev_p))
        }
    }

    /// Moves the path across vertex `si` along the sampled `bs`, returning the new world
    /// direction, or None if it leaves on the wrong side of the geometric surface for its
    /// lobe (shading-normal light leaks), like Mitsuba's one-sided handling.
    #[inline]
    pub fn cross(&mut self, si: &SurfaceInteraction, wi: Vec3, bs: &BsdfSample) -> Option<Vec3> {
        let wo_world = si.shading.to_world(bs.wo);
        let geo_cos_o = si.ng.dot(wo_world);
        let geo_cos_i = si.ng.dot(-self.ray.dir);
        let reflected = bs.wo.z * wi.z > 0.0;
        if geo_cos_o == 0.0
            || (reflected && geo_cos_o * geo_cos_i < 0.0)
            || (!reflected && geo_cos_o * geo_cos_i > 0.0)
        {
            return None;
        }
        self.eta *= bs.eta;
        self.prev_p = si.p;
        self.prev_bsdf_pdf = bs.pdf;
        self.prev_bsdf_delta = bs.delta;
        self.ray = Ray {
            origin: offset_ray_origin(si.p, si.ng, wo_world),
            dir: wo_world,
            tmin: 0.0,
            tmax: f32::INFINITY,
        };
        self.depth += 1;
        self.pixel = None;
        Some(wo_world)
    }

    /// Russian roulette on the throughput's largest component (Mitsuba: from `rr_depth` on,
    /// survive with q = min(max β · η², 0.95)). None: the path ends (also for a zero or
    /// non-finite throughput); Some(q): divide the throughput by q (1 before `rr_depth`).
    #[inline]
    pub fn roulette(
        &self,
        rr_depth: i32,
        max_component: f32,
        sampler: &mut Sampler,
    ) -> Option<f32> {
        if max_component.is_nan() || max_component <= 0.0 || !max_component.is_finite() {
            return None;
        }
        if self.depth < rr_depth.max(0) as u32 {
            return Some(1.0);
        }
        let q = (max_component * self.eta * self.eta).min(0.95);
        (sampler.next_1d() < q).then_some(q)
    }
}

/// Runs `trace` on the camera path and then on every branch it or its descendants set aside
/// at Fresnel splits (depth first), summing what they collect. A branch made by the k-th split
/// can only add branches of split count > k, so at most `fresnel_splits` wait at a time.
pub(super) fn run_branches<B>(first: B, mut trace: impl FnMut(B, &mut Vec<B>) -> Spec) -> Spec {
    let mut radiance = Spec::ZERO;
    let mut pending = Vec::new();
    let mut branch = first;
    loop {
        radiance += trace(branch, &mut pending);
        match pending.pop() {
            Some(b) => branch = b,
            None => return radiance,
        }
    }
}

/// A path branch of the unpolarised integrator.
#[derive(Clone, Copy)]
struct Branch {
    path: PathState,
    throughput: Spec,
}

/// Radiance along `ray` at the path's wavelengths. May terminate secondary wavelengths in
/// `wl` (dispersion; never in a scene with Fresnel splitting on, whose branches share `wl`).
///
/// `pixel`: the pixel a camera ray was generated in (its first hit may then come from the
/// screen bins); None for any other ray.
pub fn li(
    scene: &PreparedScene,
    ray: Ray,
    pixel: Option<[u32; 2]>,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spec {
    let hit = scene.intersect(&ray, pixel);
    counters.rays += 1;
    li_from_first_hit(scene, ray, hit, wl, sampler, counters)
}

/// [`li`] for a camera ray whose first intersection `hit` the caller has already found (and
/// counted): the batched camera stage of the renderer.
pub fn li_from_first_hit(
    scene: &PreparedScene,
    ray: Ray,
    hit: Option<Hit>,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spec {
    let first = Branch {
        path: PathState::camera(ray, None),
        throughput: Spec::ONE,
    };
    let mut first_hit = Some(hit);
    run_branches(first, |b, pending| {
        trace(scene, b, first_hit.take(), wl, sampler, counters, pending)
    })
}

/// What camera rays that hit nothing see: the infinite lights, unless `hide_emitters`. Equal
/// to [`li_from_first_hit`] with `hit` None, computed a stage at a time over a batch so the
/// long dependency chains of several lookups overlap (directions first, then texels).
pub fn escaped_camera_radiance(
    scene: &PreparedScene,
    dirs: &[Vec3],
    wls: &[SampledWavelengths],
    out: &mut [Spec],
) {
    out.fill(Spec::ZERO);
    if scene.settings.hide_emitters {
        return;
    }
    for &li in &scene.lights.infinite {
        scene.lights.lights[li as usize].add_env_batch(dirs, wls, out);
    }
}

/// Follows one branch to its end; returns what it collected, pushes split-off branches.
///
/// `known_hit`: the intersection of the branch's first ray if already found (and counted).
fn trace(
    scene: &PreparedScene,
    mut b: Branch,
    mut known_hit: Option<Option<Hit>>,
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
        let hit = match known_hit.take() {
            Some(hit) => hit,
            None => {
                counters.rays += 1;
                scene.intersect(&ray, b.path.pixel)
            }
        };

        // ---- Emitter seen by this ray (environment on a miss, area light on a hit) ----
        let Some(hit) = hit else {
            if !(b.path.depth == 0 && scene.settings.hide_emitters) {
                for &li in &lights.infinite {
                    let light = &lights.lights[li as usize];
                    let le = light.eval_env(ray.dir, wl);
                    let w = b.path.emitter_hit_weight(|prev_p| {
                        sel_pdf * light.pdf_direction(prev_p, ray.dir, f32::INFINITY, Vec3::ZERO)
                    });
                    radiance += b.throughput * le * w;
                }
            }
            break;
        };
        let si = scene.accel.interaction(&ray, &hit);
        if let Some(li) = lights.shape_light[si.shape as usize] {
            // One-sided emission from the geometric front face.
            if si.ng.dot(-ray.dir) > 0.0 && !(b.path.depth == 0 && scene.settings.hide_emitters) {
                let light = &lights.lights[li as usize];
                if let super::lights::Light::Area { radiance: le, .. } = light {
                    let w = b.path.emitter_hit_weight(|prev_p| {
                        sel_pdf * light.pdf_direction(prev_p, ray.dir, si.t, si.ng)
                    });
                    radiance += b.throughput * le.eval(wl) * w;
                }
            }
        }

        // ---- Continue? (Mitsuba: depth + 1 < max_depth) ----
        if max_depth >= 0 && b.path.depth as i64 + 1 >= max_depth as i64 {
            break;
        }
        let bsdf: &Bsdf = &scene.bsdfs[scene.shape_bsdf[si.shape as usize] as usize];
        let wi = si.shading.to_local(-ray.dir);
        let ctx = ShadingCtx { wl, uv: si.uv };

        // ---- Emitter sampling ----
        if bsdf.has_smooth_component() && !lights.lights.is_empty() {
            let n = lights.lights.len();
            let pick = if n == 1 {
                sampler.skip(1, 0);
                0
            } else {
                ((sampler.next_1d() * n as f32) as usize).min(n - 1)
            };
            let light = &lights.lights[pick];
            if let Some(ls) = light.sample(si.p, sampler.next_2d(), wl) {
                let wo = si.shading.to_local(ls.wi);
                let f = bsdf.eval(&ctx, wi, wo, counters);
                if ls.pdf > 0.0 && f.max_element() > 0.0 && ls.radiance.max_element() > 0.0 {
                    let origin = offset_ray_origin(si.p, si.ng, ls.wi);
                    let tmax = if ls.dist.is_finite() {
                        (ls.dist * (1.0 - 1e-4)).max(0.0)
                    } else {
                        f32::INFINITY
                    };
                    let shadow = Ray {
                        origin,
                        dir: ls.wi,
                        tmin: 0.0,
                        tmax,
                    };
                    counters.shadow_rays += 1;
                    if !scene.accel.occluded(&shadow) {
                        let light_pdf = sel_pdf * ls.pdf;
                        let w = if ls.delta {
                            1.0
                        } else {
                            mis_power(light_pdf, bsdf.pdf(wi, wo))
                        };
                        radiance += b.throughput * f * ls.radiance * (w / light_pdf);
                    }
                }
            }
        } else {
            // Keep the random stream layout fixed regardless of the branch.
            sampler.skip(1, 1);
        }

        // ---- BSDF sampling, or both lobes of a Fresnel pair ----
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        if b.path.splits < scene.fresnel_splits && bsdf.is_fresnel_pair() {
            let [reflected, transmitted] = bsdf.split(&ctx, wi, counters);
            b.path.splits += 1;
            if let Some(bs) = reflected {
                let mut r = b;
                if advance(scene, &mut r, &si, wi, &bs, wl, sampler) {
                    pending.push(r);
                }
            }
            match transmitted {
                Some(bs) if advance(scene, &mut b, &si, wi, &bs, wl, sampler) => continue,
                _ => break,
            }
        }
        let Some(bs) = bsdf.sample(&ctx, wi, u1, u2, counters) else {
            break;
        };
        if !advance(scene, &mut b, &si, wi, &bs, wl, sampler) {
            break;
        }
    }
    radiance
}

/// Moves branch `b` across vertex `si` along the sampled `bs`, with Russian roulette; false
/// if the path ends there.
fn advance(
    scene: &PreparedScene,
    b: &mut Branch,
    si: &SurfaceInteraction,
    wi: Vec3,
    bs: &BsdfSample,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
) -> bool {
    if b.path.cross(si, wi, bs).is_none() {
        return false;
    }
    if bs.terminate_secondary && !wl.secondary_terminated() {
        wl.terminate_secondary();
    }
    b.throughput *= bs.weight;
    if wl.secondary_terminated() {
        b.throughput = Spec::new(b.throughput.x, 0.0, 0.0, 0.0);
    }
    let max = b.throughput.max_element();
    match b.path.roulette(scene.settings.rr_depth, max, sampler) {
        None => false,
        Some(q) => {
            if q != 1.0 {
                b.throughput /= q;
            }
            true
        }
    }
}
