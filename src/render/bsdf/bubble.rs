//! Free-standing thin film (scene type `thinfilm_bubble`): a soap bubble or any lossless or
//! absorbing film of index n_f and thickness d with the same ambient medium n_a on both
//! sides. Reflection and transmission are the coherent Airy sums (`docs/physics-and-formats.md`,
//! "Thin-film optics") with n1 = n3 = n_a (seed eq. 4 for r;
//! t = t12 t23 e^{iβ} / (1 + r12 r23 e^{2iβ})), averaged over s and p (unpolarised light).
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

use super::{BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx};
use crate::optics::film_f32::ThinFilmX4;
use crate::optics::Ior;
use crate::render::counters::{count, Counter};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::TextureDesc;
use glam::{Vec2, Vec3};
use num_complex::Complex32;

#[derive(Debug, Clone)]
pub struct BubbleBsdf {
    pub film_ior: Ior,
    /// Film thickness in nm (a value or a bitmap).
    pub thickness_nm: Texture,
    /// Ambient medium on both sides (real, lossless).
    pub ext_ior: f32,
}

impl BubbleBsdf {
    /// A film of index `film_ior` (n > 0, k ≥ 0) and thickness `thickness_nm` in the
    /// constant, real ambient index `ext_ior`.
    pub fn new(film_ior: Ior, thickness_nm: &TextureDesc, ext_ior: &Ior) -> anyhow::Result<Self> {
        let ext = ext_ior.at(550.0);
        if ext_ior.is_dispersive() || ext.im != 0.0 || !(ext.re > 0.0 && ext.re.is_finite()) {
            anyhow::bail!(
                "thinfilm_bubble: ext_ior must be a constant real index > 0, got {ext_ior}"
            );
        }
        let n = film_ior.at(550.0);
        if !(n.re > 0.0 && n.re.is_finite() && n.im >= 0.0) {
            anyhow::bail!("thinfilm_bubble: film_ior must have n > 0 and k ≥ 0, got {film_ior}");
        }
        Ok(BubbleBsdf {
            film_ior,
            thickness_nm: Texture::new(thickness_nm),
            ext_ior: ext.re as f32,
        })
    }

    /// Unpolarised (R, T) at the four path wavelengths for |cos θ| at the film. A texture
    /// hole (negative, NaN or infinite thickness) counts as no film: R = 0, T = 1.
    #[inline]
    pub fn reflect_transmit(&self, ctx: &ShadingCtx, cos_theta: f32) -> (Spec, Spec) {
        count(Counter::FilmEvals, 1);
        let d = super::thinfilm::usable_thickness(self.thickness_nm.eval_scalar(ctx.uv));
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

    /// The lobes of [`BsdfModel::sample`] for film values (R, T) already evaluated.
    #[inline]
    /// The head of `sample` for a model with one delta reflection and one delta transmission
    /// lobe (this one and `coateddielectric`): `Err(answer)` when `wi` is grazing or not
    /// finite, or when `lobes` asks for at most one lobe (that lobe at probability 1, from
    /// `lobes_of`); `Ok((r, t))` when the caller chooses between both.
    pub(super) fn delta_pair_head(
        wi: Vec3,
        lobes: Lobes,
        reflect_transmit: impl FnOnce(f32) -> (Spec, Spec),
        lobes_of: impl FnOnce(Spec, Spec) -> [Option<BsdfSample>; 2],
    ) -> Result<(Spec, Spec), Option<BsdfSample>> {
        if wi.z == 0.0 || !wi.is_finite() {
            return Err(None);
        }
        let (r, t) = reflect_transmit(wi.z);
        let [reflected, transmitted] = match (lobes.reflection(), lobes.transmission()) {
            (true, true) => return Ok((r, t)),
            (false, false) => return Err(None),
            _ => lobes_of(r, t),
        };
        Err(if lobes.reflection() {
            reflected
        } else {
            transmitted
        })
    }

    fn lobes_of(wi: Vec3, r: Spec, t: Spec) -> [Option<BsdfSample>; 2] {
        let delta = |wo, v, lobe| BsdfSample::delta(wo, v, 1.0, lobe);
        [
            (r.max_element() > 0.0).then(|| {
                delta(
                    Vec3::new(-wi.x, -wi.y, wi.z),
                    r,
                    BsdfFlags::DELTA_REFLECTION,
                )
            }),
            (t.max_element() > 0.0).then(|| delta(-wi, t, BsdfFlags::DELTA_TRANSMISSION)),
        ]
    }
}

impl BsdfPlugin for BubbleBsdf {
    const PLUGINS: &'static [&'static str] = &["thinfilm_bubble"];

    /// `film_ior` (default 1.33), `thickness` (nm, a number or a texture; default 400),
    /// `ext_ior` (a constant real index; default 1).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let film_ior = p.index("film_ior", Ior::real(1.33))?;
        let thickness_nm = p.film_thickness(400.0)?;
        let ext_ior = p.index("ext_ior", Ior::real(1.0))?;
        BubbleBsdf::new(film_ior, &thickness_nm, &ext_ior).map_err(|e| p.error_at("ext_ior", e))
    }
}

impl BsdfModel for BubbleBsdf {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::DELTA_REFLECTION
            | BsdfFlags::DELTA_TRANSMISSION
            | BsdfFlags::TWO_SIDED
            | BsdfFlags::INTERFERENCE)
            .with(BsdfFlags::THICKNESS_MAP, self.thickness_nm.is_varying())
    }

    fn describe(&self) -> String {
        format!("thinfilm_bubble n={} in n={}", self.film_ior, self.ext_ior)
    }

    super::delta_lobes_only!();

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        _u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let head = Self::delta_pair_head(wi, lobes, |cos| self.reflect_transmit(ctx, cos), |r, t| {
            Self::lobes_of(wi, r, t)
        });
        let Ok((r, t)) = head else {
            return head.err().flatten();
        };
        let p_r = Self::reflect_probability(ctx, r, t, Self::MIN_LOBE_PROBABILITY);
        let s = if u1 < p_r {
            BsdfSample::delta(
                Vec3::new(-wi.x, -wi.y, wi.z),
                r / p_r,
                p_r,
                BsdfFlags::DELTA_REFLECTION,
            )
        } else {
            let p_t = 1.0 - p_r;
            BsdfSample::delta(-wi, t / p_t, p_t, BsdfFlags::DELTA_TRANSMISSION)
        };
        // Same medium on both sides: no η² radiance scaling (eta stays 1).
        (s.pdf > 0.0).then_some(s)
    }

    /// One film evaluation for both lobes.
    fn sample_split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        _u2: Vec2,
    ) -> [Option<BsdfSample>; 2] {
        let rt = (wi.z != 0.0 && wi.is_finite()).then(|| self.reflect_transmit(ctx, wi.z));
        rt.map_or([None, None], |(r, t)| Self::lobes_of(wi, r, t))
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("the free-standing film's Mueller matrices (coherent r and t of s and p through the film) are not implemented")
    }
}
