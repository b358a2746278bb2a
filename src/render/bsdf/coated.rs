//! Smooth dielectric interface under a multilayer coating (scene type `coateddielectric`
//! with a `coating` string), e.g. an anti-reflection coated lens. The coating is on the
//! outside (`ext_ior` side). R and T are the transfer-matrix powers of the stack seen from
//! the side the light arrives on — ext | layers | int from outside, int | reversed layers | ext
//! from inside (total internal reflection gives T = 0 through the evanescent exit medium) —
//! at each path wavelength. The layers are parallel, so the refracted direction is Snell's
//! between the two bulk media, as for the uncoated [`super::dielectric::Dielectric`].
//!
//! Sampling picks reflection with probability P_R = R̄/(R̄ + T̄) over the live wavelengths;
//! weights R/P_R and T/(1 − P_R)·η_ti² (radiance compression, Veach 1997 §5.2, as in
//! Mitsuba's `dielectric`). With a dispersive bulk index the refracted direction is the hero
//! wavelength's and the secondary wavelengths are terminated (only on refraction: the
//! reflected direction does not depend on wavelength).

use super::bubble::BubbleBsdf;
use super::fresnel::{fresnel_dielectric, reflect_local};
use super::stack::describe_layers;
use super::{BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, PolarizedBsdf, ShadingCtx};
use crate::optics::{Coating, Ior, Stack};
use crate::render::counters::{count, Counter};
use crate::render::texture::Spec;
use crate::scene::mitsuba::PluginParams;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct CoatedDielectric {
    /// (index, thickness nm), outside first.
    pub layers: Vec<(Ior, f64)>,
    pub int_ior: Ior,
    pub ext_ior: Ior,
    /// Either bulk index depends on wavelength.
    pub dispersive: bool,
    /// The coating seen from outside (ext | layers | int) and from inside (boxed: the pair
    /// would make every `Bsdf` value larger).
    coatings: Box<[Coating; 2]>,
}

impl CoatedDielectric {
    /// A coating of `layers` (outside first) on the interface `ext_ior` | `int_ior` (real
    /// indices); the stack is validated from both sides.
    pub fn new(layers: Vec<(Ior, f64)>, int_ior: Ior, ext_ior: Ior) -> anyhow::Result<Self> {
        let outside = Coating::new(ext_ior.clone(), &layers, int_ior.clone());
        let inside = outside.reversed();
        let b = CoatedDielectric {
            coatings: Box::new([outside, inside]),
            layers,
            dispersive: int_ior.is_dispersive() || ext_ior.is_dispersive(),
            int_ior,
            ext_ior,
        };
        for inside in [false, true] {
            b.stack_at(550.0, inside)
                .validate()
                .map_err(|e| anyhow::anyhow!("dielectric coating: {e}"))?;
        }
        for (what, n) in [("int_ior", &b.int_ior), ("ext_ior", &b.ext_ior)] {
            if n.at(550.0).im != 0.0 {
                anyhow::bail!("coated dielectric: {what} must be real, got {n}");
            }
        }
        Ok(b)
    }

    /// The stack seen from outside (`inside` = false) or from inside the object.
    pub fn stack_at(&self, lambda_nm: f64, inside: bool) -> Stack {
        self.coating(inside).stack_at(lambda_nm)
    }

    fn coating(&self, inside: bool) -> &Coating {
        &self.coatings[inside as usize]
    }

    /// Unpolarised (R, T) at the four path wavelengths for `cos θ` (signed: < 0 = inside).
    pub fn reflect_transmit(&self, ctx: &ShadingCtx, cos_theta: f32) -> (Spec, Spec) {
        count(Counter::FilmEvals, 1);
        let inside = cos_theta < 0.0;
        let cos = (cos_theta.abs() as f64).min(1.0);
        let clean = |v: f64| {
            if v.is_finite() {
                (v as f32).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let resp = (self.coating(inside)).response(ctx.wl.lambda.map(f64::from), cos);
        (
            Spec::from_array(resp.map(|r| clean(r.r()))),
            Spec::from_array(resp.map(|r| clean(r.t()))),
        )
    }

    /// The refracted lobe with `weight`·η_ti² and selection probability `pdf` (Snell's
    /// direction at the hero wavelength's bulk index); None under total internal reflection
    /// at the hero wavelength, which the stack can miss when only a secondary wavelength's
    /// index lets light through.
    fn refraction(&self, ctx: &ShadingCtx, wi: Vec3, weight: Spec, pdf: f32) -> Option<BsdfSample> {
        let lambda = ctx.wl.lambda[0] as f64;
        let eta = (self.int_ior.at(lambda).re / self.ext_ior.at(lambda).re) as f32;
        let (_, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, eta);
        if cos_t == 0.0 {
            return None;
        }
        let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
        let mut s = BsdfSample::delta(
            wo,
            weight * (eta_ti * eta_ti),
            pdf,
            BsdfFlags::DELTA_TRANSMISSION,
        );
        s.eta = eta_it;
        s.terminate_secondary = self.dispersive;
        s.wo.is_finite().then_some(s)
    }

    /// [reflection, transmission] at full weight for film values (R, T) already evaluated.
    fn lobes_of(&self, ctx: &ShadingCtx, wi: Vec3, r: Spec, t: Spec) -> [Option<BsdfSample>; 2] {
        [
            (r.max_element() > 0.0)
                .then(|| BsdfSample::delta(reflect_local(wi), r, 1.0, BsdfFlags::DELTA_REFLECTION)),
            (t.max_element() > 0.0)
                .then(|| self.refraction(ctx, wi, t, 1.0))
                .flatten(),
        ]
    }
}

impl BsdfPlugin for CoatedDielectric {
    const PLUGINS: &'static [&'static str] = &["coateddielectric"];

    /// `int_ior`, `ext_ior` (as `dielectric`'s) and the `coating` string of layers, outside
    /// first ("MgF2:99.6").
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let int_ior = p.dielectric_ior("int_ior", 1.5046)?;
        let ext_ior = p.dielectric_ior("ext_ior", 1.000277)?;
        let Some(layers) = p.layers("coating")? else {
            return Err(p.error(
                "coateddielectric needs a <string name=\"coating\"> of layers, e.g. \"MgF2:99.6\"",
            ));
        };
        CoatedDielectric::new(layers, int_ior, ext_ior).map_err(|e| p.error(e))
    }
}

impl BsdfModel for CoatedDielectric {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::DELTA_REFLECTION
            | BsdfFlags::DELTA_TRANSMISSION
            | BsdfFlags::TWO_SIDED
            | BsdfFlags::MULTILAYER)
            .with(BsdfFlags::DISPERSIVE, self.dispersive)
    }

    fn describe(&self) -> String {
        format!(
            "coating [{}] on dielectric {}/{}",
            describe_layers(&self.layers),
            self.int_ior,
            self.ext_ior
        )
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
        let pair = BubbleBsdf::delta_pair_head(
            wi,
            lobes,
            |cos| self.reflect_transmit(ctx, cos),
            |r, t| self.lobes_of(ctx, wi, r, t),
        );
        let (r, t) = match pair {
            Ok(both) => both,
            Err(one) => return one,
        };
        let p_r = BubbleBsdf::reflect_probability(ctx, r, t, 0.0);
        if u1 < p_r {
            return Some(BsdfSample::delta(
                reflect_local(wi),
                r / p_r,
                p_r,
                BsdfFlags::DELTA_REFLECTION,
            ));
        }
        let p_t = 1.0 - p_r;
        self.refraction(ctx, wi, t / p_t, p_t)
            .filter(|s| s.pdf > 0.0)
    }

    /// One transfer-matrix evaluation for both lobes.
    fn sample_split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        _u1: f32,
        _u2: Vec2,
    ) -> [Option<BsdfSample>; 2] {
        let rt = (wi.z != 0.0 && wi.is_finite()).then(|| self.reflect_transmit(ctx, wi.z));
        rt.map_or([None, None], |(r, t)| self.lobes_of(ctx, wi, r, t))
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Err("the coated interface's Mueller matrices (complex r and t of the coating from either side) are not implemented")
    }
}
