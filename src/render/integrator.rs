//! The `path` integrator: unidirectional path tracing with hero-wavelength spectral transport
//! (four wavelengths follow one path), next-event estimation with multiple importance sampling
//! (power heuristic) between BSDF and emitter sampling, and Russian roulette, all with Mitsuba 3
//! semantics (`docs/physics-and-formats.md`, "Path integrator"):
//! - `max_depth` counts path vertices: 1 = directly visible emitters only, −1 = unlimited;
//! - from depth ≥ `rr_depth` a path survives with probability min(max β · η², 0.95).
//!
//! One integrator for every scene, generic over what a path carries ([`Carrier`]): a spectral
//! throughput (`Spec`), or — when the scene asks for a polariser — a Stokes covector per
//! wavelength ([`super::stokes::StokesPath`]). The sampling decisions, MIS, Russian roulette
//! and random-number layout are the same code for both, and both run in the wavefront
//! batches of [`trace_lanes`].
//!
//! Two departures, which change the noise and not the expectation. At the first
//! `fresnel_splits` smooth reflect/transmit interfaces of a path (glass, coated glass,
//! bubbles; [`Bsdf::is_fresnel_pair`]) *both* lobes are followed with their full Fresnel
//! weights instead of one chosen with probability R (splitting; Arvo & Kirk 1990), sampled
//! with lobe masks ([`Bsdf::sample_split`]). Mitsuba picks one; at 4 % reflectance that
//! leaves a glass surface's mirrored highlights to one sample in 25, the main source of noise
//! in `scenes/lens.xml`. And a path that first reflects off a smooth film or coating, and
//! only off Dirac reflectors since, carries a second set of four wavelengths to the emitter
//! it meets ([`specular_chain`]): its directions are every wavelength's, so only the colour
//! estimate changes.

use super::accel::Hit;
use super::bsdf::{Bsdf, BsdfFlags, BsdfSample, Lobes, ShadingCtx};
use super::camera::Ray;
use super::counters::{count, Counter};
use super::env_sampling::NormalBin;
use super::geometry::{mis_power, offset_ray_origin, Frame, SurfaceInteraction};
use super::lights::LANES;
use super::sampler::Sampler;
use super::texture::Spec;
use super::PreparedScene;
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};

/// Participating media (Mitsuba's `volpath`): the hooks this file calls where the scene has
/// media ([`PreparedScene::media`]).
mod media;
/// Eight wavelengths on paths that only reflect off Dirac reflectors.
mod specular_chain;

pub(super) use specular_chain::{starts_chain, EXTRA_SETS};
use specular_chain::{ChainSets, ChainState, SET_SHARE};

/// What a path carries between vertices besides its state ([`PathState`]): the throughput
/// that the BSDF values along the path multiply.
pub trait Carrier: Copy {
    /// Scene data the carrier needs, prepared once per render.
    type Setup: Sync;
    /// What a BSDF sample multiplies the carrier by.
    type Value;

    /// The carrier of a camera ray along `dir`, before its first vertex.
    fn camera(dir: Vec3) -> Self;

    /// At the path's first vertex, found along `dir` (`normal`: the shading normal there, None
    /// on a miss): a sensor polariser sets the carrier.
    fn at_first_vertex(&mut self, setup: &Self::Setup, dir: Vec3, normal: Option<Vec3>);

    /// What the sensor passes of unpolarised light arriving directly (camera rays that hit
    /// nothing): 1, or ½ behind a polariser.
    fn direct_view(setup: &Self::Setup) -> f32;

    /// What unpolarised light of unit radiance arriving along the path contributes, per
    /// wavelength (the spectral throughput; S0 of a Stokes covector).
    fn s0(&self) -> Spec;

    /// For light sampling: the carrier times the BSDF value for unpolarised light arriving
    /// along `wo` (local), or None where that value is zero.
    fn eval(&self, bsdf: &Bsdf, ctx: &ShadingCtx, v: &VertexFrame, wo: Vec3) -> Option<Spec>;

    /// Samples the BSDF (all lobes).
    fn sample(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> Option<(BsdfSample, Self::Value)>;

    /// Both lobes of a Fresnel pair at full weight ([`Bsdf::sample_split`]).
    fn sample_split(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> [Option<(BsdfSample, Self::Value)>; 2];

    /// Crosses a vertex along `wo_world` with the sampled `value`.
    fn scatter(&mut self, value: &Self::Value, v: &VertexFrame, wo_world: Vec3);

    /// Drops the secondary wavelengths (a dispersive refraction).
    fn keep_hero_only(&mut self);

    /// The largest S0 throughput, for Russian roulette (Mitsuba's
    /// `unpolarized_spectrum(throughput)`).
    fn max_component(&self) -> f32;

    /// Divides by the survival probability of Russian roulette.
    fn divide(&mut self, q: f32);

    /// Multiplies by a spectral factor (a medium's transmittance or albedo).
    fn attenuate(&mut self, factor: Spec);
}

/// A vertex as its BSDF scatters: the frame it scatters in and the direction back along the
/// path, local and world.
#[derive(Clone, Copy)]
pub struct VertexFrame {
    pub frame: Frame,
    pub wi: Vec3,
    pub wi_world: Vec3,
    /// The vertex's environment-sampling bin: its environment light samples are drawn from
    /// it, and the MIS weight of the ray it scatters into, if that escapes, uses it.
    pub normal_bin: NormalBin,
}

/// The spectral throughput of an unpolarised path.
impl Carrier for Spec {
    type Setup = ();
    type Value = Spec;

    #[inline]
    fn camera(_dir: Vec3) -> Self {
        Spec::ONE
    }

    #[inline]
    fn at_first_vertex(&mut self, _setup: &(), _dir: Vec3, _normal: Option<Vec3>) {}

    #[inline]
    fn direct_view(_setup: &()) -> f32 {
        1.0
    }

    #[inline]
    fn s0(&self) -> Spec {
        *self
    }

    #[inline]
    fn eval(&self, bsdf: &Bsdf, ctx: &ShadingCtx, v: &VertexFrame, wo: Vec3) -> Option<Spec> {
        let f = bsdf.eval(ctx, v.wi, wo);
        (f.max_element() > 0.0).then(|| *self * f)
    }

    #[inline]
    fn sample(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> Option<(BsdfSample, Spec)> {
        let s = bsdf.sample(ctx, v.wi, u1, u2, Lobes::ALL)?;
        Some((s, s.weight))
    }

    #[inline]
    fn sample_split(
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        v: &VertexFrame,
        u1: f32,
        u2: Vec2,
    ) -> [Option<(BsdfSample, Spec)>; 2] {
        bsdf.sample_split(ctx, v.wi, u1, u2)
            .map(|s| s.map(|s| (s, s.weight)))
    }

    #[inline]
    fn scatter(&mut self, value: &Spec, _v: &VertexFrame, _wo_world: Vec3) {
        *self *= *value;
    }

    #[inline]
    fn keep_hero_only(&mut self) {
        *self = Spec::new(self.x, 0.0, 0.0, 0.0);
    }

    #[inline]
    fn max_component(&self) -> f32 {
        self.max_element()
    }

    #[inline]
    fn divide(&mut self, q: f32) {
        *self /= q;
    }

    #[inline]
    fn attenuate(&mut self, factor: Spec) {
        *self *= factor;
    }
}

/// What a path (or one branch of a split path) carries between vertices besides its
/// [`Carrier`].
#[derive(Clone, Copy)]
pub(super) struct PathState {
    pub ray: Ray,
    pub eta: f32,
    pub depth: u32,
    /// The previous vertex, for MIS on emitters hit.
    mis: MisVertex,
    /// Fresnel splits already made on the way here.
    pub splits: u32,
    /// The medium the ray travels in ([`super::medium::NO_MEDIUM`] outside every medium).
    medium: u32,
}

/// The vertex a ray left and how its direction was sampled: what the MIS weight of an
/// emitter the ray hits needs.
#[derive(Clone, Copy)]
pub(super) struct MisVertex {
    p: Vec3,
    bsdf_pdf: f32,
    /// A Dirac sample (or no light sampling there): emitters hit count in full.
    bsdf_delta: bool,
    /// [`VertexFrame::normal_bin`].
    normal_bin: NormalBin,
}

impl PathState {
    pub fn camera(ray: Ray) -> Self {
        PathState {
            ray,
            eta: 1.0,
            depth: 0,
            mis: MisVertex {
                p: ray.origin,
                bsdf_pdf: 1.0,
                bsdf_delta: true,
                normal_bin: NormalBin::WHOLE_SPHERE,
            },
            splits: 0,
            medium: super::medium::SENSOR_MEDIUM,
        }
    }

    /// MIS weight of an emitter this ray hit, against light sampling from the previous
    /// vertex; `light_pdf(previous vertex)` is evaluated only if the ray was not a delta
    /// sample.
    #[inline]
    pub fn emitter_hit_weight(&self, light_pdf: impl FnOnce(&MisVertex) -> f32) -> f32 {
        if self.mis.bsdf_delta {
            1.0
        } else {
            mis_power(self.mis.bsdf_pdf, light_pdf(&self.mis))
        }
    }

    /// Moves the path across vertex `si` (scattering in `frame`) along the sampled `bs`,
    /// returning the new world direction, or None if it leaves on the wrong side of the
    /// geometric surface for its lobe (shading-normal light leaks), like Mitsuba's one-sided
    /// handling.
    #[inline]
    pub fn cross(
        &mut self,
        si: &SurfaceInteraction,
        v: &VertexFrame,
        bs: &BsdfSample,
    ) -> Option<Vec3> {
        let wo_world = v.frame.to_world(bs.wo);
        let geo_cos_o = si.ng.dot(wo_world);
        let geo_cos_i = si.ng.dot(-self.ray.dir);
        let reflected = bs.wo.z * v.wi.z > 0.0;
        if geo_cos_o == 0.0
            || (reflected && geo_cos_o * geo_cos_i < 0.0)
            || (!reflected && geo_cos_o * geo_cos_i > 0.0)
        {
            return None;
        }
        self.eta *= bs.eta;
        self.mis = MisVertex {
            p: si.p,
            bsdf_pdf: bs.pdf,
            bsdf_delta: bs.is_delta(),
            normal_bin: v.normal_bin,
        };
        self.ray = Ray {
            origin: offset_ray_origin(si.p, si.ng, wo_world),
            dir: wo_world,
            tmin: 0.0,
            tmax: f32::INFINITY,
        };
        self.depth += 1;
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

/// A path branch.
#[derive(Clone, Copy)]
pub(super) struct Branch<C> {
    path: PathState,
    carrier: C,
    /// Its specular chain ([`specular_chain`]; the sets are the lane's
    /// [`PathScratch`]`::chain_sets` entry).
    chain: ChainState,
}

/// One camera sample's path in a batch ([`trace_lanes`]): the branch being followed, what
/// the path has collected so far, its random numbers and its wavelengths.
#[derive(Clone, Copy)]
pub(super) struct Lane<C> {
    branch: Branch<C>,
    radiance: Spec,
    /// Film colour (linear sRGB) collected outside `radiance`: an emitter seen straight from
    /// the camera in closed form ([`PathScratch::closed_form_direct_view`]), and the terms of
    /// a specular chain's extra wavelengths ([`specular_chain`]).
    colour: [f32; 3],
    pub sampler: Sampler,
    pub wl: SampledWavelengths,
    /// D65 factor at the path's wavelengths (for the environment lookups).
    d65: Spec,
    /// The branch's ray awaits its closest hit.
    active: bool,
}

impl<C: Carrier> Lane<C> {
    /// A path starting with camera ray `ray`; `d65`: the D65 factor at `wl`
    /// ([`crate::spectrum::sampled::rgb_cmf_d65_f32`]).
    #[inline]
    pub fn camera(ray: Ray, wl: SampledWavelengths, d65: Spec, sampler: Sampler) -> Self {
        Lane {
            branch: Branch {
                path: PathState::camera(ray),
                carrier: C::camera(ray.dir),
                chain: ChainState::Ended,
            },
            radiance: Spec::ZERO,
            colour: [0.0; 3],
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

    /// Film colour the path collected outside its radiance (closed-form emitters, a specular
    /// chain's extra wavelengths), added to the film value of [`Self::radiance`] (complete
    /// after [`trace_lanes`]).
    #[inline]
    pub fn colour(&self) -> [f32; 3] {
        self.colour
    }

    /// Vertices the path reached (its last branch's), a measure of the work it took.
    #[inline]
    pub fn vertices(&self) -> u32 {
        self.branch.path.depth + 1
    }
}

/// An infinite light seen by an escaped ray: `factor` · Le(`dir`) joins lane `lane`'s
/// radiance once all lookups of the batch are made together.
#[derive(Clone, Copy)]
struct EnvRequest {
    lane: u32,
    light: u32,
    dir: Vec3,
    /// The texture coordinates of `dir` on the scene's only environment map, if already
    /// computed (`uv_known`; [`super::lights::LightSet::sole_env`]). Not an `Option`: with
    /// its flag beside `set` the request stays 48 bytes.
    uv: Vec2,
    uv_known: bool,
    factor: Spec,
    /// Whose wavelengths: 0 the lane's own; j > 0 its specular chain's set j − 1, whose
    /// term joins the lane's [`Lane::colour`].
    set: u8,
}

/// A light sample's contribution, added to lane `lane` if its shadow ray is unoccluded.
#[derive(Clone, Copy)]
struct ShadowRequest {
    lane: u32,
    ray: Ray,
    contribution: Spec,
    /// The medium the shadow ray starts in (participating media only).
    medium: u32,
}

/// An environment light sample drawn at a lane's vertex (its random numbers and everything
/// the shadow term needs), finished with the round's others by [`resolve_env_samples`]: one
/// sample is a chain of dependent cache misses (marginal → row's guide and CDF → texels), and
/// done vertex by vertex the misses of different lanes never overlapped (~30 % of a diffuse
/// teapot's render). Done together they do. Same arithmetic, so the same values.
#[derive(Clone, Copy)]
struct EnvSample<C> {
    lane: u32,
    light: u32,
    u: Vec2,
    p: Vec3,
    ng: Vec3,
    shape: u32,
    v: VertexFrame,
    /// The lane's wavelengths at the vertex (a later bounce may terminate secondaries).
    wl: SampledWavelengths,
    uv: Vec2,
    segment: f32,
    color: Vec3,
    bump_normal: Vec3,
    /// The carrier before the vertex scattered it.
    carrier: C,
}

/// Where a lane's vertex puts what it asks for: branches set aside at Fresnel splits,
/// environment lookups, environment light samples and shadow rays.
struct Requests<'a, C> {
    lane: u32,
    pending: &'a mut Vec<Branch<C>>,
    env: &'a mut Vec<EnvRequest>,
    env_samples: &'a mut Vec<EnvSample<C>>,
    shadow: &'a mut Vec<ShadowRequest>,
    /// The texture coordinates of the lane's ray on the sole environment map, if it escaped
    /// and they were computed for the round's escaped rays together.
    env_uv: Option<Vec2>,
    /// [`PathScratch::closed_form_direct_view`].
    closed_form: bool,
    /// The lane's specular-chain sets, if it has some.
    chain: Option<&'a mut ChainSets>,
}

/// The paths of a batch and the reusable buffers of [`trace_lanes`] (one set per worker
/// row, not per sample).
pub struct PathScratch<C> {
    /// The batch's paths, filled by the caller with [`Lane::camera`].
    pub(super) lanes: Vec<Lane<C>>,
    /// An area light seen straight from the camera adds its closed-form film colour
    /// ([`super::lights::Light::direct_colour`]) to the lane's [`Lane::colour`] instead of
    /// its spectral radiance (the renderer's batches; not [`li`], which returns radiance).
    pub(super) closed_form_direct_view: bool,
    /// Closest hit of each lane's camera ray.
    pub(super) first_hits: Vec<Option<Hit>>,
    /// Branches set aside at Fresnel splits, per lane.
    pending: Vec<Vec<Branch<C>>>,
    env: Vec<EnvRequest>,
    env_samples: Vec<EnvSample<C>>,
    /// Directions and pdfs, then radiances, of `env_samples`.
    env_drawn: Vec<Option<(Vec3, f32)>>,
    env_le: Vec<Spec>,
    shadow: Vec<ShadowRequest>,
    rays: Vec<Ray>,
    lane_of: Vec<u32>,
    hits: Vec<Option<Hit>>,
    /// Whether each shadow ray of the batch is blocked.
    occluded: Vec<bool>,
    dirs: Vec<Vec3>,
    lambdas: Vec<Spec>,
    d65s: Vec<Spec>,
    le: Vec<Spec>,
    gathered: Vec<u32>,
    le_gathered: Vec<Spec>,
    /// A round's escaped directions and their environment-map texture coordinates.
    escaped_dirs: Vec<Vec3>,
    escaped_uvs: Vec<Vec2>,
    /// Lane i's specular-chain sets (where lanes have them: [`Self::push_camera_path`]).
    chain_sets: Vec<ChainSets>,
}

impl<C: Carrier> PathScratch<C> {
    /// Empties the batch of paths.
    pub(super) fn clear_paths(&mut self) {
        self.lanes.clear();
        self.first_hits.clear();
        self.chain_sets.clear();
    }

    /// Adds a camera path, `first_hit` the closest hit of its ray; with `chain_wl` it
    /// carries those extra wavelength sets along a specular chain from the camera
    /// ([`specular_chain`]; what the chain's emitters add goes to [`Lane::colour`]).
    pub(super) fn push_camera_path(
        &mut self,
        mut lane: Lane<C>,
        first_hit: Option<Hit>,
        chain_wl: Option<[SampledWavelengths; specular_chain::EXTRA_SETS]>,
    ) {
        if let Some(wl) = chain_wl {
            let i = self.lanes.len();
            // Lanes before it without sets get (unused) entries: entry i is lane i's.
            if self.chain_sets.len() < i {
                self.chain_sets.resize(i, ChainSets::camera(wl));
            }
            self.chain_sets.push(ChainSets::camera(wl));
            lane.branch.chain = ChainState::Unstarted;
        }
        self.lanes.push(lane);
        self.first_hits.push(first_hit);
    }
}

impl<C> Default for PathScratch<C> {
    fn default() -> Self {
        PathScratch {
            lanes: Vec::new(),
            closed_form_direct_view: false,
            first_hits: Vec::new(),
            pending: Vec::new(),
            env: Vec::new(),
            env_samples: Vec::new(),
            env_drawn: Vec::new(),
            env_le: Vec::new(),
            shadow: Vec::new(),
            rays: Vec::new(),
            lane_of: Vec::new(),
            hits: Vec::new(),
            occluded: Vec::new(),
            dirs: Vec::new(),
            lambdas: Vec::new(),
            d65s: Vec::new(),
            le: Vec::new(),
            gathered: Vec::new(),
            le_gathered: Vec::new(),
            escaped_dirs: Vec::new(),
            escaped_uvs: Vec::new(),
            chain_sets: Vec::new(),
        }
    }
}

/// Radiance along `ray` at the path's wavelengths, with the scene's transport (polarised or
/// not). May terminate secondary wavelengths in `wl` (dispersion; never in a scene with
/// Fresnel splitting on, whose branches share `wl`).
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
) -> Spec {
    match scene.polarized() {
        None => li_with::<Spec>(scene, &(), ray, pixel, wl, sampler),
        Some(setup) => li_with::<super::stokes::StokesPath>(scene, setup, ray, pixel, wl, sampler),
    }
}

fn li_with<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    ray: Ray,
    pixel: Option<[u32; 2]>,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
) -> Spec {
    let hit = scene.intersect(&ray, pixel);
    count(Counter::Rays, 1);
    let mut scratch = PathScratch::<C>::default();
    scratch
        .lanes
        .push(Lane::camera(ray, *wl, d65_at(wl), *sampler));
    scratch.first_hits.push(hit);
    trace_lanes(scene, setup, &mut scratch);
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
    if scene.settings().hide_emitters {
        return;
    }
    let lights = scene.lights();
    for &li in &lights.infinite {
        lights.lights[li as usize].add_env_lanes(dir, lambda, d65, escaped, out);
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
pub(super) fn trace_lanes<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    scratch: &mut PathScratch<C>,
) {
    let PathScratch {
        lanes,
        closed_form_direct_view,
        first_hits,
        pending,
        env,
        env_samples,
        env_drawn,
        env_le,
        shadow,
        rays,
        lane_of,
        hits,
        occluded,
        escaped_dirs,
        escaped_uvs,
        dirs,
        lambdas,
        d65s,
        chain_sets,
        ..
    } = scratch;
    let closed_form = *closed_form_direct_view && scene.media().is_none();
    let n = lanes.len();
    if pending.len() < n {
        pending.resize_with(n, Vec::new);
    }
    env.clear();
    shadow.clear();
    env_samples.clear();
    for (i, (lane, &hit)) in lanes.iter_mut().zip(first_hits.iter()).enumerate() {
        pending[i].clear();
        let mut requests = Requests {
            lane: i as u32,
            pending: &mut pending[i],
            env,
            env_samples,
            shadow,
            env_uv: None,
            closed_form,
            chain: chain_sets.get_mut(i),
        };
        lane.active = step(scene, setup, lane, hit, &mut requests);
    }
    // A lane makes at most one light sample per round, so finishing the environment samples
    // after each round keeps every lane's shadow terms in its own vertex order.
    let mut env_buf = EnvBuffers {
        drawn: env_drawn,
        le: env_le,
        dirs,
        lambdas,
        d65s,
    };
    resolve_env_samples(scene, env_samples, &mut env_buf, shadow);
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
        count(Counter::Rays, rays.len() as u64);
        scene.intersect_batch(rays, hits);
        // perf: the environment lookups of escaped rays start before any lane waits on one;
        // with a sole environment map their texture coordinates are computed once, together
        // in SIMD lanes, for both lookups (MIS pdf, radiance).
        let sole_env = scene.lights().sole_env();
        escaped_uvs.clear();
        match sole_env {
            Some(e) => {
                escaped_dirs.clear();
                let escaped = rays.iter().zip(hits.iter()).filter(|(_, h)| h.is_none());
                escaped_dirs.extend(escaped.map(|(r, _)| r.dir));
                escaped_uvs.resize(escaped_dirs.len(), Vec2::ZERO);
                e.uvs_prefetch(escaped_dirs, escaped_uvs, !scene.hemisphere_env_sampling());
            }
            None => scene.lights().prefetch_escaped(rays, hits),
        }
        let mut escaped_uv = escaped_uvs.iter();
        for (&i, &hit) in lane_of.iter().zip(hits.iter()) {
            let i = i as usize;
            let mut requests = Requests {
                lane: i as u32,
                pending: &mut pending[i],
                env,
                env_samples,
                shadow,
                env_uv: if hit.is_none() {
                    escaped_uv.next().copied()
                } else {
                    None
                },
                closed_form,
                chain: chain_sets.get_mut(i),
            };
            lanes[i].active = step(scene, setup, &mut lanes[i], hit, &mut requests);
        }
        resolve_env_samples(scene, env_samples, &mut env_buf, shadow);
    }
    if scene.media().is_none() {
        // One batched any-hit query for the batch's shadow rays (a small scene tests them in
        // SIMD lanes).
        rays.clear();
        rays.extend(shadow.iter().map(|r| r.ray));
        scene.accel.occluded_batch(rays, occluded);
    }
    for (k, r) in shadow.iter().enumerate() {
        if scene.media().is_some() {
            // Media hook: transmittance through media and null interfaces.
            let lane = &mut lanes[r.lane as usize];
            lane.radiance += r.contribution * media::shadow_transmittance(scene, r, &lane.wl);
            continue;
        }
        // gltf branch hook: shadow rays pass alpha cut-outs
        // (`lights::blocked_shadow_transmittance`).
        let tr = if occluded[k] {
            super::lights::blocked_shadow_transmittance(scene, &r.ray)
        } else {
            1.0
        };
        if tr > 0.0 {
            lanes[r.lane as usize].radiance += r.contribution * tr;
        }
    }
    resolve_env(scene, scratch);
}

/// Adds the environment terms of [`trace_lanes`]: every lookup of the batch at once per
/// infinite light ([`super::lights::Light::add_env_batch`]), then each lane's terms in the
/// order they arose.
fn resolve_env<C>(scene: &PreparedScene, scratch: &mut PathScratch<C>) {
    let PathScratch {
        lanes,
        env,
        dirs,
        lambdas,
        d65s,
        le,
        gathered,
        le_gathered,
        escaped_uvs: uvs,
        chain_sets,
        ..
    } = scratch;
    if env.is_empty() {
        return;
    }
    le.clear();
    le.resize(env.len(), Spec::ZERO);
    let lights = scene.lights();
    // The requests whose texture coordinates are known (sole environment map), then the
    // others (by direction); each request's value is the same either way.
    for known_uv in [true, false] {
        for &li in &lights.infinite {
            gathered.clear();
            dirs.clear();
            uvs.clear();
            lambdas.clear();
            d65s.clear();
            for (k, r) in env.iter().enumerate() {
                if r.light == li && r.uv_known == known_uv {
                    let lane = &lanes[r.lane as usize];
                    gathered.push(k as u32);
                    dirs.push(r.dir);
                    if r.uv_known {
                        uvs.push(r.uv);
                    }
                    if r.set == 0 {
                        lambdas.push(Spec::from_array(lane.wl.lambda));
                        d65s.push(lane.d65);
                    } else {
                        let wl = chain_sets[r.lane as usize].wavelengths(r.set as usize - 1);
                        lambdas.push(Spec::from_array(wl.lambda));
                        d65s.push(d65_at(wl));
                    }
                }
            }
            if gathered.is_empty() {
                continue;
            }
            le_gathered.clear();
            le_gathered.resize(gathered.len(), Spec::ZERO);
            match (known_uv, &lights.lights[li as usize]) {
                (true, super::lights::Light::Env(e)) => {
                    e.add_batch_uv(uvs, lambdas, d65s, le_gathered)
                }
                (_, light) => light.add_env_batch(dirs, lambdas, d65s, le_gathered),
            }
            for (&k, &l) in gathered.iter().zip(le_gathered.iter()) {
                le[k as usize] = l;
            }
        }
    }
    for (r, &l) in env.iter().zip(le.iter()) {
        let lane = &mut lanes[r.lane as usize];
        if r.set == 0 {
            lane.radiance += r.factor * l;
        } else {
            let wl = chain_sets[r.lane as usize].wavelengths(r.set as usize - 1);
            add_colour(&mut lane.colour, r.factor * l, wl);
        }
    }
}

/// The D65 factor at `wl` (for an environment lookup).
#[inline]
fn d65_at(wl: &SampledWavelengths) -> Spec {
    Spec::from_array(
        wl.lambda
            .map(|l| crate::spectrum::sampled::rgb_cmf_d65_f32(l)[3]),
    )
}

/// Adds the film colour of `radiance` at wavelengths `wl` to `colour`.
#[inline]
fn add_colour(colour: &mut [f32; 3], radiance: Spec, wl: &SampledWavelengths) {
    let c = crate::spectrum::sampled::spectrum_to_linear_srgb(radiance, wl);
    for (acc, c) in colour.iter_mut().zip(c) {
        *acc += c;
    }
}

/// Processes the vertex that lane's ray found (`hit`: its closest hit) and moves the lane
/// on: true if it has a new ray to trace, false once its path (every branch) has ended.
#[inline]
fn step<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    lane: &mut Lane<C>,
    hit: Option<Hit>,
    requests: &mut Requests<C>,
) -> bool {
    if vertex(scene, setup, lane, hit, requests) {
        return true;
    }
    match requests.pending.pop() {
        Some(b) => {
            lane.branch = b;
            true
        }
        None => false,
    }
}

/// One vertex of the lane's current branch: emission seen, light sampling, BSDF sampling (or
/// both lobes of a Fresnel pair). True if the branch goes on (its ray is the next one).
#[inline]
fn vertex<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    lane: &mut Lane<C>,
    hit: Option<Hit>,
    requests: &mut Requests<C>,
) -> bool {
    let Lane {
        branch: b,
        radiance,
        colour,
        sampler,
        wl,
        ..
    } = lane;
    // ---- Media hook: free flight to the surface, or a scattering vertex in the medium ----
    if scene.media().is_some() {
        if let Some(goes_on) = media::free_flight(scene, b, hit, wl, sampler, requests) {
            return goes_on;
        }
    }
    let settings = scene.settings();
    let lights = scene.lights();
    let sel_pdf = lights.selection_pdf();
    let ray = b.path.ray;
    let hide_emitter = b.path.depth == 0 && settings.hide_emitters;

    // ---- Emitter seen by this ray (environment on a miss, area light on a hit) ----
    let Some(hit) = hit else {
        if b.path.depth == 0 {
            b.carrier.at_first_vertex(setup, ray.dir, None);
        }
        if !hide_emitter {
            request_infinite_lights(scene, b, requests);
        }
        return false;
    };
    let si = scene.interaction(&ray, &hit);
    if b.path.depth == 0 {
        b.carrier
            .at_first_vertex(setup, ray.dir, Some(si.shading.n));
    }
    if let (Some(light), false) = (si.emitter(), hide_emitter) {
        add_emission_seen(b, &si, light, sel_pdf, requests, wl, radiance, colour);
    }

    // Media hook: a null interface is crossed without a path vertex (as `volpath` does).
    if scene.media().is_some() {
        if let Some(goes_on) = media::cross_null(scene, b, &si, wl, sampler) {
            return goes_on;
        }
    }

    // ---- Continue? (Mitsuba: depth + 1 < max_depth) ----
    if settings.max_depth >= 0 && b.path.depth as i64 + 1 >= settings.max_depth as i64 {
        return false;
    }
    let bsdf = si.bsdf();
    let frame = bsdf.shading_frame(&si);
    let v = VertexFrame {
        frame,
        wi: frame.to_local(-ray.dir),
        wi_world: -ray.dir,
        normal_bin: env_normal_bin(scene, bsdf, &frame, -ray.dir, si.shape),
    };
    let ctx = shading_ctx(wl, &si, bsdf);

    // ---- Emitter sampling (the shadow ray is traced with the batch's others; an
    // environment sample is finished with the round's others) ----
    if bsdf.has_smooth_lobe() && !lights.lights.is_empty() {
        let li = lights.pick_index(sampler);
        let u = sampler.next_2d();
        let light = &lights.lights[li];
        // (Media hook: not deferred where shadow rays cross media — same values.)
        if matches!(light, super::lights::Light::Env(_)) && scene.media().is_none() {
            requests.env_samples.push(EnvSample {
                lane: requests.lane,
                light: li as u32,
                u,
                p: si.p,
                ng: si.ng,
                shape: si.shape,
                v,
                wl: *wl,
                uv: si.uv,
                segment: si.t,
                color: si.color,
                bump_normal: ctx.bump_normal,
                carrier: b.carrier,
            });
        } else if let Some(ls) = light.sample(si.p, u, wl) {
            let shadow = shadow_term(&b.carrier, bsdf, &ctx, &v, &ls, sel_pdf, si.p, si.ng);
            if let Some((ray, contribution)) = shadow {
                requests.shadow.push(ShadowRequest {
                    lane: requests.lane,
                    ray,
                    contribution,
                    medium: media::shadow_medium(scene, &b.path, &si, ls.wi),
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
    if b.path.splits < scene.fresnel_splits() && bsdf.is_fresnel_pair() {
        b.chain = ChainState::Ended;
        let [reflected, transmitted] = C::sample_split(bsdf, &ctx, &v, u1, u2);
        b.path.splits += 1;
        if let Some((bs, value)) = reflected {
            let mut r = *b;
            if advance(scene, &mut r, &si, &v, &bs, &value, wl, sampler) {
                requests.pending.push(r);
            }
        }
        return match transmitted {
            Some((bs, value)) => advance(scene, b, &si, &v, &bs, &value, wl, sampler),
            None => false,
        };
    }
    let Some((bs, value)) = C::sample(bsdf, &ctx, &v, u1, u2) else {
        return false;
    };
    (b.chain).scatter(
        requests.chain.as_deref_mut(),
        bsdf,
        &ctx,
        v.wi,
        (u1, u2),
        &bs,
    );
    advance(scene, b, &si, &v, &bs, &value, wl, sampler)
}

/// Asks for the infinite lights seen by branch `b`'s escaped ray: one lookup per light,
/// MIS-weighted against light sampling at the previous vertex, or — at the end of a live
/// specular chain — one per wavelength set, each with half the weight (`SET_SHARE`).
#[inline]
fn request_infinite_lights<C: Carrier>(
    scene: &PreparedScene,
    b: &Branch<C>,
    requests: &mut Requests<C>,
) {
    let lights = scene.lights();
    let sel_pdf = lights.selection_pdf();
    let ray = b.path.ray;
    for &li in &lights.infinite {
        let light = &lights.lights[li as usize];
        let uv = requests.env_uv;
        let w = b
            .path
            .emitter_hit_weight(|m| sel_pdf * light.pdf_escaped(m.p, ray.dir, uv, m.normal_bin));
        let request = |factor, set| EnvRequest {
            lane: requests.lane,
            light: li,
            dir: ray.dir,
            uv: uv.unwrap_or_default(),
            uv_known: uv.is_some(),
            factor,
            set,
        };
        match (b.chain.live(), requests.chain.as_deref()) {
            (true, Some(sets)) => {
                let w = w * SET_SHARE;
                requests.env.push(request(b.carrier.s0() * w, 0));
                for (j, (_, throughput)) in sets.sets().enumerate() {
                    requests.env.push(request(throughput * w, j as u8 + 1));
                }
            }
            _ => requests.env.push(request(b.carrier.s0() * w, 0)),
        }
    }
}

/// The environment-sampling bin of a vertex with BSDF `bsdf` in shading frame `frame`, seen
/// from `wi_world` ([`super::env_sampling`]): the bin of the normal on the side the path
/// arrives from, where a surface without a non-Dirac transmission lobe receives all the light
/// that light sampling can find — or, for a narrow glossy lobe with tables of its own (on
/// `shape`), the bin of its mirror direction; radiance-only sampling elsewhere, in scenes with
/// media (their light samples are drawn whole-sphere) and where hemisphere sampling is off.
/// (A vertex with Dirac lobes only makes no light sample, and its rays' emitters count in
/// full.)
#[inline]
fn env_normal_bin(
    scene: &PreparedScene,
    bsdf: &Bsdf,
    frame: &Frame,
    wi_world: Vec3,
    shape: u32,
) -> NormalBin {
    let flags = bsdf.flags();
    let transmits = BsdfFlags::DIFFUSE_TRANSMISSION | BsdfFlags::GLOSSY_TRANSMISSION;
    if !scene.hemisphere_env_sampling()
        || !flags.intersects(BsdfFlags::SMOOTH)
        || flags.intersects(transmits)
    {
        return NormalBin::WHOLE_SPHERE;
    }
    let cos = frame.n.dot(wi_world);
    let n = if cos >= 0.0 { frame.n } else { -frame.n };
    match scene.lobe_family_of(shape) {
        Some(family) => NormalBin::of_lobe(family, 2.0 * cos.abs() * n - wi_world),
        None => NormalBin::of(n),
    }
}

/// Adds what the area light `light` under hit `si` emits towards branch `b`'s ray: its
/// spectral radiance (MIS-weighted against light sampling) to `radiance`, or — seen straight
/// from the camera, untextured, with a carrier equal at every wavelength, and
/// `requests.closed_form` — its closed-form film colour to `colour`: the mean of its
/// radiance's film value over the wavelengths, without their noise. At the end of a live
/// specular chain, the mean of the chain's sets (the path's own to `radiance`, the others'
/// film colours to `colour`).
#[allow(clippy::too_many_arguments)]
#[inline]
fn add_emission_seen<C: Carrier>(
    b: &Branch<C>,
    si: &SurfaceInteraction,
    light: &super::lights::Light,
    sel_pdf: f32,
    requests: &Requests<C>,
    wl: &SampledWavelengths,
    radiance: &mut Spec,
    colour: &mut [f32; 3],
) {
    let closed_form = requests.closed_form;
    let ray = b.path.ray;
    let s0 = b.carrier.s0();
    let weight = || {
        b.path.emitter_hit_weight(|m| {
            // From the MIS vertex, which may lie before null interactions (gltf hook).
            sel_pdf * light.pdf_direction(m.p, ray.dir, (si.p - m.p).length(), si.ng)
        })
    };
    let direct = (b.path.depth == 0 && closed_form && s0 == Spec::splat(s0.x))
        .then(|| light.direct_colour(si.ng, ray.dir))
        .flatten();
    if let Some(c) = direct {
        let w = s0.x * weight();
        for (acc, c) in colour.iter_mut().zip(c) {
            *acc += w * c;
        }
    } else if let (true, Some(sets)) = (b.chain.live(), requests.chain.as_deref()) {
        let w = weight() * SET_SHARE;
        if let Some(le) = light.emitted(si.ng, si.uv, ray.dir, wl) {
            *radiance += s0 * le * w;
        }
        for (wl, throughput) in sets.sets() {
            if let Some(le) = light.emitted(si.ng, si.uv, ray.dir, wl) {
                add_colour(colour, throughput * le * w, wl);
            }
        }
    } else if let Some(le) = light.emitted(si.ng, si.uv, ray.dir, wl) {
        *radiance += s0 * le * weight();
    }
}

/// What `bsdf` sees of the shading point `si` besides the directions (the segment length for
/// glTF volume absorption, a bump map's normal computed once per hit).
pub(super) fn shading_ctx<'a>(
    wl: &'a SampledWavelengths,
    si: &SurfaceInteraction,
    bsdf: &Bsdf,
) -> ShadingCtx<'a> {
    ShadingCtx {
        wl,
        uv: si.uv,
        segment: si.t,
        color: si.color,
        bump_normal: bsdf.perturbed_normal(si),
    }
}

/// The shadow ray and the contribution it carries if unoccluded, for light sample `ls` at a
/// vertex (BSDF × radiance × MIS weight ÷ pdf); None if the sample adds nothing.
#[allow(clippy::too_many_arguments)]
#[inline]
fn shadow_term<C: Carrier>(
    carrier: &C,
    bsdf: &Bsdf,
    ctx: &ShadingCtx,
    v: &VertexFrame,
    ls: &super::lights::LightSample,
    sel_pdf: f32,
    p: Vec3,
    ng: Vec3,
) -> Option<(Ray, Spec)> {
    let wo = v.frame.to_local(ls.wi);
    let f = carrier.eval(bsdf, ctx, v, wo);
    let (true, Some(f), true) = (ls.pdf > 0.0, f, ls.radiance.max_element() > 0.0) else {
        return None;
    };
    let light_pdf = sel_pdf * ls.pdf;
    let w = if ls.delta {
        1.0
    } else {
        mis_power(light_pdf, bsdf.pdf(ctx, v.wi, wo))
    };
    count(Counter::ShadowRays, 1);
    Some((ls.shadow_ray(p, ng), f * ls.radiance * (w / light_pdf)))
}

/// The buffers [`resolve_env_samples`] reuses from round to round.
struct EnvBuffers<'a> {
    /// Directions and pdfs, then radiances, of the samples.
    drawn: &'a mut Vec<Option<(Vec3, f32)>>,
    le: &'a mut Vec<Spec>,
    /// The radiance lookups' directions, wavelengths and D65 factors.
    dirs: &'a mut Vec<Vec3>,
    lambdas: &'a mut Vec<Spec>,
    d65s: &'a mut Vec<Spec>,
}

/// Finishes a round's environment light samples ([`EnvSample`]) stage by stage — all
/// directions, then all radiances, then the shadow terms — so that the cache misses of
/// different samples overlap; the values are [`super::lights::Light::sample`]'s.
fn resolve_env_samples<C: Carrier>(
    scene: &PreparedScene,
    samples: &mut Vec<EnvSample<C>>,
    buf: &mut EnvBuffers,
    shadow: &mut Vec<ShadowRequest>,
) {
    let EnvBuffers {
        drawn,
        le,
        dirs,
        lambdas,
        d65s,
    } = buf;
    if samples.is_empty() {
        return;
    }
    let lights = scene.lights();
    let env = |s: &EnvSample<C>| match &lights.lights[s.light as usize] {
        super::lights::Light::Env(e) => e,
        _ => unreachable!("only environment samples are deferred"),
    };
    drawn.clear();
    // perf: every sample's first cache miss is under way before any sample waits on its own
    // (the prefetching draw then starts the texel loads of the radiance stage).
    let bin = |s: &EnvSample<C>| s.v.normal_bin;
    samples
        .iter()
        .for_each(|s| env(s).prefetch_sample(s.u, bin(s)));
    samples
        .iter()
        .for_each(|s| env(s).prefetch_sample_guided(s.u, bin(s)));
    drawn.extend((samples.iter()).map(|s| env(s).sample_direction_prefetch(s.u, bin(s))));
    le.clear();
    match lights.sole_env() {
        // perf: the radiances in SIMD lanes ([`super::lights::EnvMap::add_batch`], the
        // values of `eval` bit for bit); a sample that drew nothing adds nothing below.
        Some(e) => {
            dirs.clear();
            lambdas.clear();
            d65s.clear();
            for (s, d) in samples.iter().zip(drawn.iter()) {
                dirs.push(d.map_or(Vec3::Z, |(wi, _)| wi));
                lambdas.push(Spec::from_array(s.wl.lambda));
                d65s.push(d65_at(&s.wl));
            }
            le.resize(samples.len(), Spec::ZERO);
            e.add_batch(dirs, lambdas, d65s, le);
        }
        None => le.extend((samples.iter().zip(drawn.iter())).map(|(s, d)| match d {
            Some((wi, _)) => env(s).eval(*wi, &s.wl),
            None => Spec::ZERO,
        })),
    }
    let sel_pdf = lights.selection_pdf();
    for ((s, d), &radiance) in samples.iter().zip(drawn.iter()).zip(le.iter()) {
        let Some((wi, pdf)) = *d else { continue };
        let ls = super::lights::LightSample::from_infinity(wi, radiance, pdf, false);
        let bsdf = scene.shape_bsdf_of(s.shape);
        let ctx = ShadingCtx {
            wl: &s.wl,
            uv: s.uv,
            segment: s.segment,
            color: s.color,
            bump_normal: s.bump_normal,
        };
        let term = shadow_term(&s.carrier, bsdf, &ctx, &s.v, &ls, sel_pdf, s.p, s.ng);
        if let Some((ray, contribution)) = term {
            shadow.push(ShadowRequest {
                lane: s.lane,
                ray,
                contribution,
                medium: super::medium::NO_MEDIUM,
            });
        }
    }
    samples.clear();
}

/// Moves branch `b` across vertex `si` along the sampled `bs` of value `value`, with
/// Russian roulette; false if the path ends there.
#[allow(clippy::too_many_arguments)]
#[inline]
fn advance<C: Carrier>(
    scene: &PreparedScene,
    b: &mut Branch<C>,
    si: &SurfaceInteraction,
    v: &VertexFrame,
    bs: &BsdfSample,
    value: &C::Value,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
) -> bool {
    let mis_vertex = b.path.mis;
    let Some(wo_world) = b.path.cross(si, v, bs) else {
        return false;
    };
    // gltf branch hook: passing an alpha cut-out (a null interaction that shadow rays also
    // pass, `lights::blocked_shadow_transmittance`) keeps the MIS state of the vertex before it.
    if bs.lobe.contains(super::bsdf::BsdfFlags::NULL)
        && super::lights::passes_shadow_rays(scene, si.shape)
    {
        b.path.mis = mis_vertex;
    }
    // Media hook: the medium beyond the surface; a thin dielectric's transmission is a null
    // interaction in `volpath` (no vertex: depth and MIS vertex kept).
    if scene.media().is_some() {
        media::after_crossing(scene, &mut b.path, si, bs, wo_world, mis_vertex);
    }
    if bs.terminate_secondary && !wl.secondary_terminated() {
        wl.terminate_secondary();
        count(Counter::SecondaryTerminations, 1);
    }
    b.carrier.scatter(value, v, wo_world);
    if wl.secondary_terminated() {
        b.carrier.keep_hero_only();
    }
    let max = b.carrier.max_component();
    match b.path.roulette(scene.settings().rr_depth, max, sampler) {
        None => false,
        Some(q) => {
            if q != 1.0 {
                b.carrier.divide(q);
                // The chain ends here: its sets' throughputs would need the same factor, and
                // a chain may end at any vertex (rare: chains are shorter than `rr_depth`).
                b.chain = ChainState::Ended;
            }
            true
        }
    }
}
