//! Mitsuba 3's `pplastic`: the polarised plastic pBRDF of Baek et al. 2018 ("Simultaneous
//! acquisition of polarimetric SVBRDF and normals", eqs. 1–6), as Mitsuba's
//! `src/bsdfs/pplastic.cpp` implements it.
//!
//! Two lobes simply added (not a layered model, and not energy conserving):
//! - specular: a rough microfacet reflection, F(wi·h)·D(h)·G(wi, wo)/(4 cos θi), GGX or
//!   Beckmann (Mitsuba's default), possibly anisotropic or textured, times
//!   `specular_reflectance`;
//! - diffuse: a Lambertian base seen through two *smooth* refractions,
//!   (1 − F(cos θo))·ρ·(1 − F(cos θi))·cos θo/π — no internal reflections and no 1/η²,
//!   unlike `plastic`.
//!
//! Polarised, as Mitsuba's Mueller form: the specular lobe is the dielectric reflection
//! matrix at the microfacet; the diffuse lobe is T_out · depolariser(ρ) · T_in (refraction
//! in along wo, depolarisation, refraction out along wi from the refracted direction
//! inside), in the bases perpendicular to the macro-surface's planes of incidence — so light
//! leaving the base is weakly polarised, at 90° to the specular polarisation.
//!
//! Sampling (Mitsuba's): the specular lobe (visible normals) with the constant probability
//! s̄/(s̄ + d̄) of the mean specular and diffuse reflectances, else a cosine-weighted
//! direction; the weight is eval / pdf of the combined density.

use super::fresnel::{fresnel_dielectric, reflect};
use super::lobe_factor::{texture_mean, LobeFactor};
use super::microfacet::{Distribution, Microfacet};
use super::roughness::Roughness;
use super::{
    BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx,
};
use crate::render::geometry::{
    cosine_hemisphere_pdf, square_to_cosine_hemisphere, Frame, SurfaceInteraction,
};
use crate::render::polarization::{
    depolarizer, specular_reflection, specular_transmission, Mueller,
};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::TextureDesc;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Debug, Clone)]
pub struct PolarizedPlastic {
    pub diffuse_reflectance: Texture,
    /// Mitsuba's `specular_reflectance` (1 when absent).
    pub specular: LobeFactor,
    /// The microfacet lobe (never a Dirac delta: Mitsuba floors α at 10⁻⁴).
    pub roughness: Roughness,
    /// Relative index n_int / n_ext.
    pub eta: f32,
    /// Probability of sampling the specular lobe, s̄ / (s̄ + d̄).
    pub specular_sampling_weight: f32,
}

impl PolarizedPlastic {
    /// A pplastic of diffuse reflectance `diffuse`, relative index `eta` and roughness
    /// `roughness`, with `specular_reflectance` `specular`.
    pub fn new(
        diffuse: &TextureDesc,
        specular: LobeFactor,
        roughness: Roughness,
        eta: f32,
    ) -> anyhow::Result<Self> {
        if !(eta.is_finite() && eta > 0.0 && eta != 1.0) {
            anyhow::bail!("pplastic: the relative index must be positive, finite and ≠ 1, got {eta}");
        }
        if !roughness.is_rough() {
            anyhow::bail!("pplastic: a smooth (Dirac) specular lobe is not Mitsuba's pplastic, whose α is floored at 1e-4");
        }
        let diffuse_reflectance = Texture::new(diffuse);
        let (s_mean, d_mean) = (specular.mean(), texture_mean(&diffuse_reflectance));
        Ok(PolarizedPlastic {
            diffuse_reflectance,
            specular,
            roughness,
            eta,
            specular_sampling_weight: s_mean / (d_mean + s_mean),
        })
    }

    /// The microfacet distribution at the shading point.
    fn distribution(&self, ctx: &ShadingCtx) -> Microfacet {
        // `new` refuses a smooth roughness; Mitsuba's 10⁻⁴ floor otherwise.
        self.roughness
            .at(ctx)
            .unwrap_or_else(|| Microfacet::of(Distribution::Beckmann, 0.0, 0.0))
    }

    /// The specular lobe without `specular_reflectance` and Fresnel: h and D·G/(4 cos θi).
    fn specular_geometry(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> (Vec3, f32) {
        let mf = self.distribution(ctx);
        let h = (wi + wo).normalize();
        (h, mf.d(h) * mf.g(wi, wo, h) / (4.0 * wi.z))
    }
}

impl BsdfPlugin for PolarizedPlastic {
    const PLUGINS: &'static [&'static str] = &["pplastic"];

    /// Mitsuba's parameters: `diffuse_reflectance` (0.5), `specular_reflectance` (1),
    /// `int_ior` (polypropylene, 1.49) / `ext_ior` (air) or `eta` (a number),
    /// `distribution` (beckmann), `alpha` (0.1) or `alpha_u`/`alpha_v` (numbers or
    /// textures), `sample_visible` (noise only).
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        let diffuse = p.texture("diffuse_reflectance", 0.5)?;
        let specular = LobeFactor::read(p, "specular_reflectance")?;
        let roughness = Roughness::read(p, false)?;
        let eta = if p.has("eta") {
            if p.has("int_ior") || p.has("ext_ior") {
                return Err(p.error("give either 'eta' or 'int_ior'/'ext_ior', not both"));
            }
            if !p.is_number("eta") {
                return Err(p.error_at(
                    "eta",
                    "a textured relative index is not supported (give a number)",
                ));
            }
            p.float("eta", 1.49)? as f32
        } else {
            let int_ior = p.ior_number("int_ior", 1.49)? as f32;
            let ext_ior = p.ior_number("ext_ior", 1.000277)? as f32;
            if !(int_ior >= 0.0 && ext_ior >= 0.0) || int_ior == ext_ior {
                return Err(p.error(format!(
                    "the interior and exterior indices must be positive and differ (int_ior {int_ior}, ext_ior {ext_ior}), as Mitsuba requires"
                )));
            }
            int_ior / ext_ior
        };
        PolarizedPlastic::new(&diffuse, specular, roughness, eta).map_err(|e| p.error(e))
    }
}

impl BsdfModel for PolarizedPlastic {
    fn flags(&self) -> BsdfFlags {
        (BsdfFlags::GLOSSY_REFLECTION | BsdfFlags::DIFFUSE_REFLECTION).with(
            BsdfFlags::VERTEX_COLOR,
            self.diffuse_reflectance.reads_mesh_attribute()
                || self.specular.reads_mesh_attribute()
                || self.roughness.reads_mesh_attribute(),
        )
    }

    fn describe(&self) -> String {
        format!(
            "pplastic η={} {}{}",
            self.eta,
            self.roughness.describe(),
            self.specular.describe("specular_reflectance")
        )
    }

    /// Mitsuba's frame (s along dp/du) when the roughness may be anisotropic.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        if self.roughness.is_anisotropic() {
            super::normal_map::dpdu_frame(si)
        } else {
            si.shading
        }
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Spec::ZERO;
        }
        let (h, value) = self.specular_geometry(ctx, wi, wo);
        let f = fresnel_dielectric(wi.dot(h), self.eta).0;
        let specular = self.specular.eval(ctx) * (f * value);
        let t_i = 1.0 - fresnel_dielectric(wi.z, self.eta).0;
        let t_o = 1.0 - fresnel_dielectric(wo.z, self.eta).0;
        let rho = self.diffuse_reflectance.eval_at(ctx);
        specular + rho * (t_i * t_o * FRAC_1_PI * wo.z)
    }

    /// Mitsuba's `pdf` with visible-normal sampling: p_s·D(h)·G1(wi, h)/(4 cos θi) +
    /// (1 − p_s)·cos θo/π.
    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let mf = self.distribution(ctx);
        let h = (wi + wo).normalize();
        let p_specular = if wi.dot(h) > 0.0 && wo.dot(h) > 0.0 {
            mf.d(h) * mf.g1(wi, h) / (4.0 * wi.z)
        } else {
            0.0
        };
        let ps = self.specular_sampling_weight;
        ps * p_specular + (1.0 - ps) * cosine_hemisphere_pdf(wo.z)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        if wi.z <= 0.0 || !lobes.reflection() {
            return None;
        }
        let (wo, lobe) = if u1 < self.specular_sampling_weight {
            let m = self.distribution(ctx).sample_visible(wi, u2);
            (reflect(wi, m), BsdfFlags::GLOSSY_REFLECTION)
        } else {
            (
                square_to_cosine_hemisphere(u2),
                BsdfFlags::DIFFUSE_REFLECTION,
            )
        };
        let pdf = self.pdf(ctx, wi, wo);
        BsdfSample::of_mixture(wo, pdf, || self.eval(ctx, wi, wo), lobe)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        Ok(self)
    }
}

impl PolarizedBsdf for PolarizedPlastic {
    /// Mitsuba's Mueller form (light arrives along −wo, leaves along wi): the microfacet
    /// reflection matrix in the bases of the facet's plane of incidence plus
    /// T_out·depolariser(ρ)·T_in·cos θo/π in those of the macro-surface's.
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return MuellerValue::ZERO;
        }
        let (h, value) = self.specular_geometry(ctx, wi, wo);
        let f = specular_reflection(wo.dot(h), self.eta).scale(value);
        let f = self.specular.scale_mueller(ctx, [f; 4]);
        let specular = MuellerValue::specular(f, h, wi, wo);
        // Refraction in along wo; out along wi from the refracted direction inside, whose
        // cosine is Snell's cos θt of wi.
        let t_in = specular_transmission(wo.z, self.eta);
        let cos_t = (1.0 - (1.0 - wi.z * wi.z) / (self.eta * self.eta))
            .max(0.0)
            .sqrt();
        let t_out = specular_transmission(cos_t, 1.0 / self.eta);
        let rho = self.diffuse_reflectance.eval_at(ctx).to_array();
        let scale = FRAC_1_PI * wo.z;
        let d: [Mueller; 4] = std::array::from_fn(|k| {
            t_out
                .mul(&depolarizer(rho[k]))
                .mul(&t_in)
                .scale(scale)
        });
        let diffuse = MuellerValue::specular(d, Vec3::Z, wi, wo);
        specular.plus(diffuse, wi, wo)
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let s = self.sample(ctx, wi, u1, u2, lobes)?;
        let value = self.eval_mueller(ctx, wi, s.wo).scaled(1.0 / s.pdf);
        Some((s, value))
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{
        albedo, assert_chi2, assert_eval_pdf_sample_agree, assert_mueller_agrees,
        assert_reciprocal, constant, ctx_of, dir, wl,
    };
    use super::super::Bsdf;
    use super::*;
    use crate::scene::mitsuba::load_str;
    use std::path::Path;

    fn pplastic(kind: Distribution, au: f32, av: f32, rho: f32) -> Bsdf {
        let r = Roughness::Constant(Some(Microfacet::of(kind, au, av)));
        PolarizedPlastic::new(&constant(rho), LobeFactor::default(), r, 1.49)
            .unwrap()
            .into()
    }

    #[test]
    fn sampling_matches_eval_and_pdf() {
        let cases = [
            ("beckmann", pplastic(Distribution::Beckmann, 0.1, 0.1, 0.5)),
            ("ggx", pplastic(Distribution::Ggx, 0.4, 0.4, 0.2)),
            ("aniso", pplastic(Distribution::Beckmann, 0.05, 0.3, 0.8)),
        ];
        let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / 9.0);
        for (name, b) in &cases {
            assert_chi2(name, b, alpha);
            assert_eval_pdf_sample_agree(name, b);
            assert_mueller_agrees(name, b);
            assert_reciprocal(name, b, 1e-4);
        }
    }

    /// The two lobes are each at most what reaches them (the specular lobe reflects F, the
    /// base receives 1 − F), so even a white base never returns more than it receives; the
    /// base alone is (1 − F_i)·∫(1 − F_o) cos/π, below 1 − F_i; a black base leaves the
    /// microfacet lobe, whose albedo near normal incidence is about F(0) = 3.9 %.
    #[test]
    fn energy_is_bounded() {
        for wi in [dir(0.0, 0.0), dir(45.0, 30.0), dir(80.0, 0.0)] {
            for kind in [Distribution::Beckmann, Distribution::Ggx] {
                let e = albedo(&pplastic(kind, 0.2, 0.2, 1.0), wi, 40_000);
                assert!(e.max_element() <= 1.0, "{kind:?} {wi}: {e}");
                let black = albedo(&pplastic(kind, 0.2, 0.2, 0.0), wi, 40_000)[0];
                let f = fresnel_dielectric(wi.z, 1.49).0;
                assert!(e[0] > black + 0.5 * (1.0 - f), "{kind:?} {wi}: {e} {black}");
            }
        }
        let black = albedo(&pplastic(Distribution::Ggx, 0.05, 0.05, 0.0), dir(0.0, 0.0), 40_000)[0];
        assert!((black - 0.0387).abs() < 0.004, "{black}");
    }

    /// The base's light is polarised on the way out (s component weaker), at right angles to
    /// the specular lobe's: M₁₀ of the two lobes, in the same bases, have opposite signs.
    #[test]
    fn diffuse_and_specular_polarise_at_right_angles() {
        let wl = wl();
        let ctx = ctx_of(&wl);
        let (wi, wo) = (dir(60.0, 0.0), dir(60.0, 180.0));
        let m10 = |rho: f32, spec: f32| {
            let b = bsdf_of(&format!(
                r#"<bsdf type="pplastic"><float name="diffuse_reflectance" value="{rho}"/><float name="specular_reflectance" value="{spec}"/><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf>"#
            ));
            let v = b.polarized().unwrap().eval_mueller(&ctx, wi, wo);
            let p = v.polarized.unwrap();
            (p.m[0].0[1][0], p.m[0].0[0][0] + v.depolarized[0])
        };
        let (spec, spec00) = m10(0.0, 1.0);
        let (diff, diff00) = m10(1.0, 0.0);
        assert!(spec00 > 0.0 && diff00 > 0.0);
        assert!(spec * diff < 0.0, "specular {spec}, diffuse {diff}");
        assert!(diff.abs() < 0.2 * diff00 && spec.abs() > 0.5 * spec00, "{diff} {spec}");
    }

    fn load(body: &str) -> anyhow::Result<crate::scene::Scene> {
        let xml = format!(r#"<scene version="3.0.0"><shape type="sphere">{body}</shape></scene>"#);
        load_str(&xml, Path::new("."), &[], "t.xml")
    }

    fn bsdf_of(body: &str) -> Bsdf {
        let s = load(body).unwrap();
        s.bsdfs[s.shapes[0].bsdf].clone()
    }

    #[test]
    fn is_read_from_mitsuba_xml() {
        let s = load(r#"<bsdf type="pplastic"/>"#).unwrap();
        let Bsdf::PolarizedPlastic(b) = &s.bsdfs[s.shapes[0].bsdf] else {
            panic!("not a pplastic")
        };
        // Mitsuba's defaults: polypropylene in air, Beckmann α = 0.1, ρ = 0.5, weight 1/1.5.
        assert!((b.eta - 1.49 / 1.000277).abs() < 1e-6, "{}", b.eta);
        assert!(b.roughness.describe().contains("beckmann α=0.1"));
        assert!((b.specular_sampling_weight - 1.0 / 1.5).abs() < 1e-6);
        for (body, want) in [
            (
                r#"<bsdf type="pplastic"><float name="eta" value="1.3"/><float name="int_ior" value="1.5"/></bsdf>"#,
                "not both",
            ),
            (
                r#"<bsdf type="pplastic"><float name="int_ior" value="1.2"/><float name="ext_ior" value="1.2"/></bsdf>"#,
                "differ",
            ),
            (
                r#"<bsdf type="pplastic"><float name="alpha" value="0.1"/><float name="alpha_u" value="0.1"/></bsdf>"#,
                "alpha",
            ),
        ] {
            let e = format!("{:#}", load(body).unwrap_err());
            assert!(e.contains(want) && e.contains("t.xml:1:"), "{e}");
        }
    }
}
