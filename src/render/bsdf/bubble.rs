//! Free-standing thin film (scene type `thinfilm_bubble`): a soap bubble or any lossless or
//! absorbing film of index n_f and thickness d with the same ambient medium n_a on both
//! sides. Reflection and transmission are the coherent Airy sums with
//! n1 = n3 = n_a (seed eq. 4 for r; t = t12 t23 e^{iβ} / (1 + r12 r23 e^{2iβ})), averaged over
//! s and p (unpolarised light).
//!
//! Geometry: the film is far thinner than anything the renderer resolves, so the transmitted
//! ray leaves in the incident direction (the lateral shift n_a → n_f → n_a is ~d, nanometres)
//! and the reflected ray is the mirror direction. Both lobes are Dirac deltas. The film is
//! symmetric, so it scatters identically from either side (two-sided).
//!
//! Sampling picks reflection with probability P_R = R̄ / (R̄ + T̄), R̄ and T̄ the averages over
//! the path's live wavelengths (only the hero once secondaries are terminated); the weights
//! are R / P_R and T / (1 − P_R) per wavelength. For a lossless film R + T = 1 at every
//! wavelength, so a bubble in a white furnace is invisible (tested in `tests/render_films.rs`).

use super::{BsdfSample, Counters, ShadingCtx};
use crate::optics::film_f32::ThinFilmX4;
use crate::optics::Ior;
use crate::render::texture::{Spec, Texture};
use glam::Vec3;
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct BubbleBsdf {
    pub film_ior: Ior,
    /// Film thickness in nm (a value or a bitmap).
    pub thickness_nm: Texture,
    /// Ambient medium on both sides (real part used; must be lossless).
    pub ext_ior: f32,
}

impl BubbleBsdf {
    /// Unpolarised (R, T) at the four path wavelengths for |cos θ| at the film. Negative, NaN
    /// or infinite thickness counts as 0 (no film: R = 0, T = 1), so a texture hole never
    /// poisons the image.
    #[inline]
    pub fn reflect_transmit(
        &self,
        ctx: &ShadingCtx,
        cos_theta: f32,
        counters: &mut Counters,
    ) -> (Spec, Spec) {
        counters.film_evals += 1;
        let d = self.thickness_nm.eval_scalar(ctx.uv);
        let d = if d.is_finite() && d > 0.0 { d } else { 0.0 };
        let c32 = |z: crate::optics::Complex64| Complex32::new(z.re as f32, z.im as f32);
        let ambient = Complex32::new(self.ext_ior, 0.0);
        let film = ThinFilmX4 {
            ambient_ior: self.ext_ior,
            film_ior: ctx.wl.lambda.map(|l| c32(self.film_ior.at(l as f64))),
            thickness_nm: d,
            substrate_ior: [ambient; 4],
        };
        let resp = film.response(ctx.wl.lambda, cos_theta.abs().min(1.0));
        let clean = |v: f32| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let r = resp.r().map(clean);
        let t = resp.t().map(clean);
        (Spec::from_array(r), Spec::from_array(t))
    }

    /// Each lobe is chosen with probability ≥ this. The Fresnel-proportional choice
    /// R̄/(R̄ + T̄) sends only ~5 % of the samples at near-normal incidence into the
    /// reflection, which carries the interference colours and the bright mirrored studio
    /// lights; a defensive floor (still unbiased: weights R/P_R and T/(1 − P_R)) lowers the
    /// noise where it shows. `scenes/bubble.xml`, 128², 256 spp, two seeds: RMSE 0.042 → 0.034,
    /// mean ΔE00 between the seeds 1.60 → 1.04 (a floor of 0.4 gave 1.20: 0.25 kept).
    pub const MIN_LOBE_PROBABILITY: f32 = 0.25;

    /// Probability of choosing the reflection lobe: R̄/(R̄ + T̄) over the live wavelengths,
    /// clamped to [`min_probability`, 1 − `min_probability`].
    #[inline]
    pub fn reflect_probability(ctx: &ShadingCtx, r: Spec, t: Spec, min_probability: f32) -> f32 {
        let (rs, ts) = if ctx.wl.secondary_terminated() {
            (r.x, t.x)
        } else {
            (r.element_sum(), t.element_sum())
        };
        if rs + ts > 0.0 {
            (rs / (rs + ts)).clamp(min_probability, 1.0 - min_probability)
        } else {
            // Nothing leaves the film (fully absorbing): any choice has weight 0.
            0.5
        }
    }

    pub fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        counters: &mut Counters,
    ) -> Option<BsdfSample> {
        if wi.z == 0.0 || !wi.is_finite() {
            return None;
        }
        let (r, t) = self.reflect_transmit(ctx, wi.z, counters);
        let p_r = Self::reflect_probability(ctx, r, t, Self::MIN_LOBE_PROBABILITY);
        let mut s = if u1 < p_r {
            let mut s = BsdfSample::delta(Vec3::new(-wi.x, -wi.y, wi.z), r / p_r);
            s.pdf = p_r;
            s
        } else {
            let p_t = 1.0 - p_r;
            let mut s = BsdfSample::delta(-wi, t / p_t);
            s.pdf = p_t;
            s
        };
        // Same medium on both sides: no η² radiance scaling.
        s.eta = 1.0;
        (s.pdf > 0.0).then_some(s)
    }

    /// [reflection, transmission] with weights R and T (Fresnel splitting, see
    /// [`super::Bsdf::split`]): one film evaluation for both lobes.
    pub fn split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        counters: &mut Counters,
    ) -> [Option<BsdfSample>; 2] {
        if wi.z == 0.0 || !wi.is_finite() {
            return [None, None];
        }
        let (r, t) = self.reflect_transmit(ctx, wi.z, counters);
        [
            (r.max_element() > 0.0).then(|| BsdfSample::delta(Vec3::new(-wi.x, -wi.y, wi.z), r)),
            (t.max_element() > 0.0).then(|| BsdfSample::delta(-wi, t)),
        ]
    }
}
