//! The `path` integrator: unidirectional path tracing with hero-wavelength spectral transport
//! (four wavelengths follow one path), next-event estimation with multiple importance sampling
//! (power heuristic) between BSDF and emitter sampling, and Russian roulette, all with Mitsuba 3
//! semantics (Mitsuba 3's `path` integrator):
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
use super::lights::LANES;
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
pub(super) struct Branch {
    path: PathState,
    throughput: Spec,
}

/// One camera sample's path in a batch ([`trace_lanes`]): the branch being followed, what
/// the path has collected so far, its random numbers and its wavelengths.
#[derive(Clone, Copy)]
pub(super) struct Lane {
    branch: Branch,
    radiance: Spec,
    pub sampler: Sampler,
    pub wl: SampledWavelengths,
    /// D65 factor at the path's wavelengths (for the environment lookups).
    d65: Spec,
    /// The branch's ray awaits its closest hit.
    active: bool,
}

impl Lane {
    /// A path starting with camera ray `ray`; `d65`: the D65 factor at `wl`
    /// ([`crate::spectrum::sampled::rgb_cmf_d65_f32`]).
    #[inline]
    pub fn camera(ray: Ray, wl: SampledWavelengths, d65: Spec, sampler: Sampler) -> Self {
        Lane {
            branch: Branch {
                path: PathState::camera(ray, None),
                throughput: Spec::ONE,
            },
            radiance: Spec::ZERO,
            sampler,
            wl,
            d65,
            active: false,
        }
    }

    /// Spectral radiance the path collected (complete after [`trace_lanes`]).
    #[inline]
    pub fn radiance(&self) -> Spec {
        self.radiance
    }
}

/// An infinite light seen by an escaped ray: `factor` · Le(`dir`) joins lane `lane`'s
/// radiance once all lookups of the batch are made together.
#[derive(Clone, Copy)]
struct EnvRequest {
    lane: u32,
    light: u32,
    dir: Vec3,
    factor: Spec,
}

/// A light sample's contribution, added to lane `lane` if its shadow ray is unoccluded.
#[derive(Clone, Copy)]
struct ShadowRequest {
    lane: u32,
    ray: Ray,
    contribution: Spec,
}

/// The paths of a batch and the reusable buffers of [`trace_lanes`] (one set per worker
/// row, not per sample).
#[derive(Default)]
pub struct PathScratch {
    /// The batch's paths, filled by the caller with [`Lane::camera`].
    pub(super) lanes: Vec<Lane>,
    /// Closest hit of each lane's camera ray.
    pub(super) first_hits: Vec<Option<Hit>>,
    /// Branches set aside at Fresnel splits, per lane.
    pending: Vec<Vec<Branch>>,
    env: Vec<EnvRequest>,
    shadow: Vec<ShadowRequest>,
    rays: Vec<Ray>,
    lane_of: Vec<u32>,
    hits: Vec<Option<Hit>>,
    dirs: Vec<Vec3>,
    lambdas: Vec<Spec>,
    d65s: Vec<Spec>,
    le: Vec<Spec>,
    gathered: Vec<u32>,
    le_gathered: Vec<Spec>,
}

/// Radiance along `ray` at the path's wavelengths. May terminate secondary wavelengths in
/// `wl` (dispersion; never in a scene with Fresnel splitting on, whose branches share `wl`).
///
/// `pixel`: the pixel a camera ray was generated in (its first hit may then come from the
/// screen bins); None for any other ray. One path through [`trace_lanes`]: the same values
/// as that path in any batch.
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
    let mut scratch = PathScratch::default();
    let d65 = Spec::from_array(
        wl.lambda
            .map(|l| crate::spectrum::sampled::rgb_cmf_d65_f32(l)[3]),
    );
    scratch.lanes.push(Lane::camera(ray, *wl, d65, *sampler));
    scratch.first_hits.push(hit);
    trace_lanes(scene, &mut scratch, counters);
    let lane = &scratch.lanes[0];
    *wl = lane.wl;
    *sampler = lane.sampler;
    lane.radiance
}

/// What camera rays that hit nothing see: the infinite lights, unless `hide_emitters` (the
/// value [`trace_lanes`] gives such a lane, factor 1). A batch in struct-of-arrays form
/// (`dir[axis][lane]`, `lambda[k][lane]`, `d65[k][lane]`) is looked up at once, so the long
/// dependency chains of the lookups overlap: `out[k][i]` for the lanes marked `escaped`, the
/// others left as they are.
pub fn escaped_camera_radiance_lanes(
    scene: &PreparedScene,
    dir: &[[f32; LANES]; 3],
    lambda: &[[f32; LANES]; 4],
    d65: &[[f32; LANES]; 4],
    escaped: &[bool; LANES],
    out: &mut [[f32; LANES]; 4],
) {
    for row in out.iter_mut() {
        for (v, &e) in row.iter_mut().zip(escaped) {
            if e {
                *v = 0.0;
            }
        }
    }
    if scene.settings.hide_emitters {
        return;
    }
    for &li in &scene.lights.infinite {
        scene.lights.lights[li as usize].add_env_lanes(dir, lambda, d65, escaped, out);
    }
}

/// Follows the paths of `scratch.lanes` to their ends; `scratch.first_hits[i]` is the
/// closest hit of lane i's camera ray, already found (and counted) by the caller.
///
/// A wavefront over the batch: in each round every lane still going processes the vertex its
/// last ray found and asks for its next ray, and the round's rays are traced together
/// ([`super::accel::Accel::intersect_batch`]: one packet traversal where they are coherent,
/// as the reflections of one pixel's samples off a smooth surface are). Emitters seen by
/// escaped rays and shadow rays are collected and resolved at the end, the environment
/// lookups in SIMD lanes. A lane's result depends only on its own numbers: each lane adds its
/// terms in its own order (vertex emission, then shadow-ray terms, then environment terms), so
/// a batch of one ([`li`]) gives bit-identical values.
pub(super) fn trace_lanes(
    scene: &PreparedScene,
    scratch: &mut PathScratch,
    counters: &mut Counters,
) {
    let PathScratch {
        lanes,
        first_hits,
        pending,
        env,
        shadow,
        rays,
        lane_of,
        hits,
        ..
    } = scratch;
    let n = lanes.len();
    if pending.len() < n {
        pending.resize_with(n, Vec::new);
    }
    env.clear();
    shadow.clear();
    for (i, (lane, &hit)) in lanes.iter_mut().zip(first_hits.iter()).enumerate() {
        pending[i].clear();
        lane.active = step(
            scene,
            i as u32,
            lane,
            hit,
            &mut pending[i],
            env,
            shadow,
            counters,
        );
    }
    loop {
        rays.clear();
        lane_of.clear();
        for (i, lane) in lanes.iter().enumerate() {
            if lane.active {
                rays.push(lane.branch.path.ray);
                lane_of.push(i as u32);
            }
        }
        if rays.is_empty() {
            break;
        }
        counters.rays += rays.len() as u64;
        scene.accel.intersect_batch(rays, hits);
        for (&i, &hit) in lane_of.iter().zip(hits.iter()) {
            let i = i as usize;
            lanes[i].active = step(
                scene,
                i as u32,
                &mut lanes[i],
                hit,
                &mut pending[i],
                env,
                shadow,
                counters,
            );
        }
    }
    for r in shadow.iter() {
        if !scene.accel.occluded(&r.ray) {
            lanes[r.lane as usize].radiance += r.contribution;
        }
    }
    resolve_env(scene, scratch);
}

/// Adds the environment terms of [`trace_lanes`]: every lookup of the batch at once per
/// infinite light ([`super::lights::Light::add_env_batch`]), then each lane's terms in the
/// order they arose.
fn resolve_env(scene: &PreparedScene, scratch: &mut PathScratch) {
    let PathScratch {
        lanes,
        env,
        dirs,
        lambdas,
        d65s,
        le,
        gathered,
        le_gathered,
        ..
    } = scratch;
    if env.is_empty() {
        return;
    }
    le.clear();
    le.resize(env.len(), Spec::ZERO);
    for &li in &scene.lights.infinite {
        gathered.clear();
        dirs.clear();
        lambdas.clear();
        d65s.clear();
        for (k, r) in env.iter().enumerate() {
            if r.light == li {
                let lane = &lanes[r.lane as usize];
                gathered.push(k as u32);
                dirs.push(r.dir);
                lambdas.push(Spec::from_array(lane.wl.lambda));
                d65s.push(lane.d65);
            }
        }
        le_gathered.clear();
        le_gathered.resize(gathered.len(), Spec::ZERO);
        scene.lights.lights[li as usize].add_env_batch(dirs, lambdas, d65s, le_gathered);
        for (&k, &l) in gathered.iter().zip(le_gathered.iter()) {
            le[k as usize] = l;
        }
    }
    for (r, &l) in env.iter().zip(le.iter()) {
        lanes[r.lane as usize].radiance += r.factor * l;
    }
}

/// Processes the vertex that lane `index`'s ray found (`hit`: its closest hit) and moves the
/// lane on: true if it has a new ray to trace, false once its path (every branch) has ended.
#[allow(clippy::too_many_arguments)]
#[inline]
fn step(
    scene: &PreparedScene,
    index: u32,
    lane: &mut Lane,
    hit: Option<Hit>,
    pending: &mut Vec<Branch>,
    env: &mut Vec<EnvRequest>,
    shadow: &mut Vec<ShadowRequest>,
    counters: &mut Counters,
) -> bool {
    if vertex(scene, index, lane, hit, pending, env, shadow, counters) {
        return true;
    }
    match pending.pop() {
        Some(b) => {
            lane.branch = b;
            true
        }
        None => false,
    }
}

/// One vertex of the lane's current branch: emission seen, light sampling, BSDF sampling (or
/// both lobes of a Fresnel pair). True if the branch goes on (its ray is the next one).
#[allow(clippy::too_many_arguments)]
#[inline]
fn vertex(
    scene: &PreparedScene,
    index: u32,
    lane: &mut Lane,
    hit: Option<Hit>,
    pending: &mut Vec<Branch>,
    env: &mut Vec<EnvRequest>,
    shadow: &mut Vec<ShadowRequest>,
    counters: &mut Counters,
) -> bool {
    let Lane {
        branch: b,
        radiance,
        sampler,
        wl,
        ..
    } = lane;
    let max_depth = scene.settings.max_depth;
    let lights = &scene.lights;
    let sel_pdf = lights.selection_pdf();
    let ray = b.path.ray;

    // ---- Emitter seen by this ray (environment on a miss, area light on a hit) ----
    let Some(hit) = hit else {
        if !(b.path.depth == 0 && scene.settings.hide_emitters) {
            for &li in &lights.infinite {
                let light = &lights.lights[li as usize];
                let w = b.path.emitter_hit_weight(|prev_p| {
                    sel_pdf * light.pdf_direction(prev_p, ray.dir, f32::INFINITY, Vec3::ZERO)
                });
                env.push(EnvRequest {
                    lane: index,
                    light: li,
                    dir: ray.dir,
                    factor: b.throughput * w,
                });
            }
        }
        return false;
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
                *radiance += b.throughput * le.eval(wl) * w;
            }
        }
    }

    // ---- Continue? (Mitsuba: depth + 1 < max_depth) ----
    if max_depth >= 0 && b.path.depth as i64 + 1 >= max_depth as i64 {
        return false;
    }
    let bsdf: &Bsdf = &scene.bsdfs[scene.shape_bsdf[si.shape as usize] as usize];
    let wi = si.shading.to_local(-ray.dir);
    let ctx = ShadingCtx { wl, uv: si.uv };

    // ---- Emitter sampling (the shadow ray is traced with the batch's others) ----
    if bsdf.has_smooth_component() && !lights.lights.is_empty() {
        let light = lights.pick(sampler);
        if let Some(ls) = light.sample(si.p, sampler.next_2d(), wl) {
            let wo = si.shading.to_local(ls.wi);
            let f = bsdf.eval(&ctx, wi, wo, counters);
            if ls.pdf > 0.0 && f.max_element() > 0.0 && ls.radiance.max_element() > 0.0 {
                let light_pdf = sel_pdf * ls.pdf;
                let w = if ls.delta {
                    1.0
                } else {
                    mis_power(light_pdf, bsdf.pdf(wi, wo))
                };
                counters.shadow_rays += 1;
                shadow.push(ShadowRequest {
                    lane: index,
                    ray: ls.shadow_ray(si.p, si.ng),
                    contribution: b.throughput * f * ls.radiance * (w / light_pdf),
                });
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
            let mut r = *b;
            if advance(scene, &mut r, &si, wi, &bs, wl, sampler) {
                pending.push(r);
            }
        }
        return match transmitted {
            Some(bs) => advance(scene, b, &si, wi, &bs, wl, sampler),
            None => false,
        };
    }
    let Some(bs) = bsdf.sample(&ctx, wi, u1, u2, counters) else {
        return false;
    };
    advance(scene, b, &si, wi, &bs, wl, sampler)
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
