//! The `path` integrator: unidirectional path tracing with hero-wavelength spectral transport
//! (four wavelengths follow one path), next-event estimation with multiple importance sampling
//! (power heuristic) between BSDF and emitter sampling, and Russian roulette, all with Mitsuba 3
//! semantics (conventions.md "Path integrator"):
//! - `max_depth` counts path vertices: 1 = directly visible emitters only, −1 = unlimited;
//! - from depth ≥ `rr_depth` a path survives with probability min(max β · η², 0.95).

use super::bsdf::{Bsdf, Counters, ShadingCtx};
use super::camera::Ray;
use super::geometry::{mis_power, offset_ray_origin};
use super::sampler::Sampler;
use super::texture::Spec;
use super::PreparedScene;
use crate::spectrum::SampledWavelengths;
use glam::Vec3;

/// Radiance along `ray` at the path's wavelengths. May terminate secondary wavelengths in
/// `wl` (dispersion).
pub fn li(
    scene: &PreparedScene,
    mut ray: Ray,
    wl: &mut SampledWavelengths,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spec {
    let max_depth = scene.settings.max_depth;
    let rr_depth = scene.settings.rr_depth.max(0) as u32;
    let lights = &scene.lights;
    let sel_pdf = lights.selection_pdf();

    let mut radiance = Spec::ZERO;
    let mut throughput = Spec::ONE;
    let mut eta = 1.0f32;
    let mut depth: u32 = 0;
    // State of the previous vertex for MIS on emitters hit by BSDF sampling.
    let mut prev_p = ray.origin;
    let mut prev_bsdf_pdf = 1.0f32;
    let mut prev_bsdf_delta = true;

    loop {
        counters.rays += 1;
        let hit = scene.accel.intersect(&ray);

        // ---- Emitter seen by this ray (environment on a miss, area light on a hit) ----
        let Some(hit) = hit else {
            if !(depth == 0 && scene.settings.hide_emitters) {
                for &li in &lights.infinite {
                    let light = &lights.lights[li as usize];
                    let le = light.eval_env(ray.dir, wl);
                    let w = if prev_bsdf_delta {
                        1.0
                    } else {
                        mis_power(
                            prev_bsdf_pdf,
                            sel_pdf
                                * light.pdf_direction(prev_p, ray.dir, f32::INFINITY, Vec3::ZERO),
                        )
                    };
                    radiance += throughput * le * w;
                }
            }
            break;
        };
        let si = scene.accel.interaction(&ray, &hit);
        if let Some(li) = lights.shape_light[si.shape as usize] {
            // One-sided emission from the geometric front face.
            if si.ng.dot(-ray.dir) > 0.0 && !(depth == 0 && scene.settings.hide_emitters) {
                let light = &lights.lights[li as usize];
                if let super::lights::Light::Area { radiance: le, .. } = light {
                    let w = if prev_bsdf_delta {
                        1.0
                    } else {
                        mis_power(
                            prev_bsdf_pdf,
                            sel_pdf * light.pdf_direction(prev_p, ray.dir, si.t, si.ng),
                        )
                    };
                    radiance += throughput * le.eval(wl) * w;
                }
            }
        }

        // ---- Continue? (Mitsuba: depth + 1 < max_depth) ----
        if max_depth >= 0 && depth as i64 + 1 >= max_depth as i64 {
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
                        radiance += throughput * f * ls.radiance * (w / light_pdf);
                    }
                }
            }
        } else {
            // Keep the random stream layout fixed regardless of the branch.
            sampler.skip(1, 1);
        }

        // ---- BSDF sampling ----
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        let Some(bs) = bsdf.sample(&ctx, wi, u1, u2, counters) else {
            break;
        };
        let wo_world = si.shading.to_world(bs.wo);
        // Reject directions on the wrong side of the geometric surface for their lobe
        // (shading-normal light leaks), like Mitsuba's one-sided handling.
        let geo_cos_o = si.ng.dot(wo_world);
        let geo_cos_i = si.ng.dot(-ray.dir);
        let reflected = bs.wo.z * wi.z > 0.0;
        if geo_cos_o == 0.0
            || (reflected && geo_cos_o * geo_cos_i < 0.0)
            || (!reflected && geo_cos_o * geo_cos_i > 0.0)
        {
            break;
        }
        if bs.terminate_secondary && !wl.secondary_terminated() {
            wl.terminate_secondary();
        }
        throughput *= bs.weight;
        if wl.secondary_terminated() {
            throughput = Spec::new(throughput.x, 0.0, 0.0, 0.0);
        }
        eta *= bs.eta;
        prev_p = si.p;
        prev_bsdf_pdf = bs.pdf;
        prev_bsdf_delta = bs.delta;
        ray = Ray {
            origin: offset_ray_origin(si.p, si.ng, wo_world),
            dir: wo_world,
            tmin: 0.0,
            tmax: f32::INFINITY,
        };
        depth += 1;

        // ---- Russian roulette ----
        let tmax_component = throughput.max_element();
        if tmax_component.is_nan() || tmax_component <= 0.0 || !tmax_component.is_finite() {
            break;
        }
        if depth >= rr_depth {
            let q = (tmax_component * eta * eta).min(0.95);
            if sampler.next_1d() >= q {
                break;
            }
            throughput /= q;
        }
    }
    radiance
}
