//! The path integrator's participating-media hooks (Mitsuba 3 `volpath.cpp`), called only
//! where the scene has media ([`PreparedScene::media`]), so surface-only scenes run the
//! path tracer unchanged. The medium model is [`crate::render::medium`].
//!
//! - [`free_flight`]: before a surface vertex, a distance is sampled in the ray's medium; a
//!   scattering event before the surface is a path vertex of its own (depth + 1, light
//!   sampling with the phase function, phase-function sampling, Russian roulette);
//! - [`cross_null`]: a `null` surface is crossed without a vertex (no depth, the MIS vertex
//!   kept), changing the medium if the shape bounds one — and so is a thin dielectric's
//!   transmission where the path has no vertex left;
//! - [`after_crossing`]: the medium beyond a scattering surface (Mitsuba's
//!   `target_medium`); a thin dielectric's straight transmission is a null interaction;
//! - [`shadow_transmittance`]: shadow rays pass null and thin-dielectric interfaces and are
//!   attenuated by exp(−σ_t d) in each medium they cross (analytic: Mitsuba estimates the
//!   same transmittance by ratio tracking, with noise).

use super::{Branch, Carrier, MisVertex, PathState, Requests, ShadowRequest};
use crate::render::accel::Hit;
use crate::render::bsdf::{Bsdf, BsdfFlags, BsdfSample, Lobes};
use crate::render::camera::Ray;
use crate::render::counters::{count, Counter};
use crate::render::env_sampling::NormalBin;
use crate::render::geometry::{mis_power, offset_ray_origin, SurfaceInteraction};
use crate::render::medium::{
    sample_flight, transmittance, Flight, Medium, NO_MEDIUM, SENSOR_MEDIUM,
};
use crate::render::sampler::Sampler;
use crate::render::texture::Spec;
use crate::render::PreparedScene;
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};

/// Interfaces a shadow ray crosses at most before it counts as blocked.
const MAX_SHADOW_CROSSINGS: usize = 64;

/// Samples the free flight of branch `b`'s ray (closest hit `hit`) in its medium. None: the
/// ray reaches its surface (or escapes), its carrier weighted by the transmittance — the
/// surface vertex follows as usual. Some(goes_on): the path scattered in the medium and
/// that vertex is done.
#[inline]
pub(super) fn free_flight<C: Carrier>(
    scene: &PreparedScene,
    b: &mut Branch<C>,
    hit: Option<Hit>,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    requests: &mut Requests<C>,
) -> Option<bool> {
    let media = scene.media()?;
    if b.path.medium == SENSOR_MEDIUM {
        b.path.medium = media.sensor;
    }
    let medium = media.get(b.path.medium)?;
    let ray = b.path.ray;
    let t_max = hit.map_or(f32::INFINITY, |h| h.t) - ray.tmin;
    let channels = if wl.secondary_terminated() { 1 } else { 4 };
    match sample_flight(medium.sigma_t(wl), t_max, sampler.next_1d(), channels) {
        Flight::Pass { weight } => {
            b.carrier.attenuate(weight);
            None
        }
        Flight::Scatter { t, weight } => {
            b.carrier.attenuate(weight * medium.sigma_s(wl));
            let p = ray.origin + ray.dir * (ray.tmin + t);
            Some(scatter(scene, medium, b, p, wl, sampler, requests))
        }
    }
}

/// A scattering vertex at `p` in `medium`: light sampling (the phase function in place of a
/// BSDF, MIS by the power heuristic), then phase-function sampling and Russian roulette.
/// False if the path ends there.
fn scatter<C: Carrier>(
    scene: &PreparedScene,
    medium: &Medium,
    b: &mut Branch<C>,
    p: Vec3,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    requests: &mut Requests<C>,
) -> bool {
    let settings = scene.settings();
    b.path.depth += 1;
    // Mitsuba's volpath: a medium vertex counts towards max_depth like a surface vertex.
    if settings.max_depth >= 0 && b.path.depth as i64 >= settings.max_depth as i64 {
        return false;
    }
    let wi = -b.path.ray.dir;
    let lights = scene.lights();
    if medium.sample_emitters && !lights.lights.is_empty() {
        let sel_pdf = lights.selection_pdf();
        let li = lights.pick_index(sampler);
        let u = sampler.next_2d();
        if let Some(ls) = lights.lights[li].sample(p, u, wl) {
            let phase = medium.phase.pdf(wi, ls.wi);
            if ls.pdf > 0.0 && phase > 0.0 && ls.radiance.max_element() > 0.0 {
                let light_pdf = sel_pdf * ls.pdf;
                let w = if ls.delta {
                    1.0
                } else {
                    mis_power(light_pdf, phase)
                };
                count(Counter::ShadowRays, 1);
                requests.shadow.push(ShadowRequest {
                    lane: requests.lane,
                    ray: ls.shadow_ray(p, Vec3::ZERO),
                    contribution: b.carrier.s0() * ls.radiance * (phase * w / light_pdf),
                    medium: b.path.medium,
                });
            }
        }
    } else {
        sampler.skip(1, 1);
    }
    let (wo, pdf) = medium.phase.sample(wi, sampler.next_2d());
    if pdf.is_nan() || pdf <= 0.0 {
        return false;
    }
    // Emitters hit next are weighted against light sampling from here — unless this medium
    // does not sample emitters (Mitsuba: they then count in full).
    b.path.mis = MisVertex {
        p,
        bsdf_pdf: pdf,
        bsdf_delta: !medium.sample_emitters,
        normal_bin: NormalBin::WHOLE_SPHERE,
    };
    b.path.ray = Ray {
        origin: p,
        dir: wo,
        tmin: 0.0,
        tmax: f32::INFINITY,
    };
    match b
        .path
        .roulette(settings.rr_depth, b.carrier.max_component(), sampler)
    {
        None => false,
        Some(q) => {
            if q != 1.0 {
                b.carrier.divide(q);
            }
            true
        }
    }
}

/// At a `null` surface: moves the ray on past it (into the shape's medium on that side, if
/// it bounds one): Some(true). Also at a thin dielectric where the path has no vertex left
/// (depth + 1 = max_depth): `volpath` still follows its transmission, a null interaction
/// that takes no vertex — chosen with probability 1 − R' (Some(true)), or the reflection,
/// which ends the path (Some(false)). None for any other surface.
#[inline]
pub(super) fn cross_null<C: Carrier>(
    scene: &PreparedScene,
    b: &mut Branch<C>,
    si: &SurfaceInteraction,
    wl: &SampledWavelengths,
    sampler: &mut Sampler,
) -> Option<bool> {
    let media = scene.media()?;
    let bsdf = scene.shape_bsdf_of(si.shape);
    let dir = b.path.ray.dir;
    match bsdf {
        Bsdf::Null(_) => {}
        Bsdf::ThinDielectric(_) => {
            let max_depth = scene.settings().max_depth;
            if max_depth < 0 || (b.path.depth as i64 + 1) < max_depth as i64 {
                return None;
            }
            let frame = bsdf.shading_frame(si);
            let ctx = super::shading_ctx(wl, si, bsdf);
            let wi = frame.to_local(-dir);
            match bsdf.sample(&ctx, wi, sampler.next_1d(), Vec2::ZERO, Lobes::ALL) {
                Some(s) if s.lobe.contains(BsdfFlags::DELTA_TRANSMISSION) => {
                    b.carrier.attenuate(s.weight)
                }
                _ => return Some(false),
            }
        }
        _ => return None,
    }
    if let Some(m) = media.target(si.shape, si.ng, dir) {
        b.path.medium = m;
    }
    b.path.ray = Ray {
        origin: offset_ray_origin(si.p, si.ng, dir),
        dir,
        tmin: 0.0,
        tmax: f32::INFINITY,
    };
    Some(true)
}

/// After the path crossed surface `si` along `wo_world` (sample `bs`): the medium it now
/// travels in, and — for a thin dielectric's straight transmission, which Mitsuba flags as
/// a null interaction — no vertex: the depth and the MIS vertex before it are kept.
#[inline]
pub(super) fn after_crossing(
    scene: &PreparedScene,
    path: &mut PathState,
    si: &SurfaceInteraction,
    bs: &BsdfSample,
    wo_world: Vec3,
    mis_vertex: MisVertex,
) {
    let Some(media) = scene.media() else {
        return;
    };
    if let Some(m) = media.target(si.shape, si.ng, wo_world) {
        path.medium = m;
    }
    if bs.lobe.contains(BsdfFlags::DELTA_TRANSMISSION)
        && matches!(scene.shape_bsdf_of(si.shape), Bsdf::ThinDielectric(_))
    {
        path.mis = mis_vertex;
        path.depth -= 1;
    }
}

/// The medium a shadow ray from surface vertex `si` towards `wi` starts in.
#[inline]
pub(super) fn shadow_medium(
    scene: &PreparedScene,
    path: &PathState,
    si: &SurfaceInteraction,
    wi: Vec3,
) -> u32 {
    match scene.media() {
        None => NO_MEDIUM,
        Some(media) => media.target(si.shape, si.ng, wi).unwrap_or(path.medium),
    }
}

/// The fraction of light shadow ray `r` carries to its end at wavelengths `wl`: the product
/// of exp(−σ_t d) over the media it crosses and of the null transmission of the interfaces
/// between them (1 for `null`, 1 − R' for a thin dielectric, Mitsuba's
/// `eval_null_transmission`); 0 at any other surface.
pub(super) fn shadow_transmittance(
    scene: &PreparedScene,
    r: &ShadowRequest,
    wl: &SampledWavelengths,
) -> Spec {
    let Some(media) = scene.media() else {
        return Spec::ONE;
    };
    let mut ray = r.ray;
    let mut medium = r.medium;
    if medium == NO_MEDIUM && !scene.occluded(&ray) {
        return Spec::ONE;
    }
    let mut tr = Spec::ONE;
    for _ in 0..MAX_SHADOW_CROSSINGS {
        let hit = scene.intersect(&ray, None);
        let end = hit.map_or(ray.tmax, |h| h.t);
        if let Some(m) = media.get(medium) {
            tr *= transmittance(m.sigma_t(wl), end - ray.tmin);
        }
        let Some(hit) = hit else {
            return tr;
        };
        if tr.max_element() <= 0.0 {
            return Spec::ZERO;
        }
        let si = scene.interaction(&ray, &hit);
        let Some(t) = null_transmission(si.bsdf(), &si, ray.dir, wl) else {
            return Spec::ZERO;
        };
        tr *= t;
        if let Some(m) = media.target(si.shape, si.ng, ray.dir) {
            medium = m;
        }
        // Past this hit (relative step: the ray's origin stays fixed).
        ray.tmin = hit.t + 1e-5 * (1.0 + hit.t);
        if ray.tmin >= ray.tmax {
            return tr;
        }
    }
    Spec::ZERO
}

/// What a surface passes straight through along `dir`: None for a surface that blocks.
fn null_transmission(
    bsdf: &Bsdf,
    si: &SurfaceInteraction,
    dir: Vec3,
    wl: &SampledWavelengths,
) -> Option<Spec> {
    match bsdf {
        Bsdf::Null(_) => Some(Spec::ONE),
        Bsdf::ThinDielectric(_) => {
            let frame = bsdf.shading_frame(si);
            let ctx = super::shading_ctx(wl, si, bsdf);
            // The transmitted lobe alone carries its full value, 1 − R'.
            let s = bsdf.sample(
                &ctx,
                frame.to_local(-dir),
                0.5,
                Vec2::ZERO,
                Lobes::TRANSMISSION,
            )?;
            Some(s.weight)
        }
        _ => None,
    }
}
