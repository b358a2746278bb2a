//! Mitsuba 3's `blendbsdf` (`src/bsdfs/blendbsdf.cpp`, 3.9): a linear blend of two nested
//! BSDFs, f = (1 − w)·f₀ + w·f₁ with `weight` w ∈ [0, 1] (a number or a texture, clipped).
//!
//! Sampling chooses a nested BSDF as Mitsuba does: BSDF 1 when u1 < w (u1 rescaled to u1/w),
//! else BSDF 0 (u1 → (u1 − w)/(1 − w)). A smooth sample's pdf is then the mixture
//! (1 − w)·p₀ + w·p₁ and its weight the mixture's value over it, the other BSDF evaluated in
//! the sampled direction (one-sample MIS over the two), as Mitsuba 3.9's `sample` does.
//! Mitsuba mixes a *delta* sample the same way — the chosen lobe's discrete probability p
//! added to the other BSDF's solid-angle density: weight (w·r·p + (1 − w)·f_other) /
//! (w·p + (1 − w)·pdf_other). That is not an unbiased estimator (the other's smooth lobes
//! have no mass in the one mirror direction): a mirror blended with a rough lobe whose pdf
//! there exceeds 1 comes out darker than the blend of the two, with a diffuse one (pdf < 1)
//! brighter. It is reproduced because scenes must render as Mitsuba renders them (its
//! `bsdf_blendbsdf` documentation scene: 3.5 % brighter in thinfilm without it).
//! Polarised: the same blend of the nested Mueller values.

use super::{
    Bsdf, BsdfFlags, BsdfModel, BsdfPlugin, BsdfSample, Lobes, MuellerValue, PolarizedBsdf,
    ShadingCtx,
};
use crate::render::texture::{Spec, Texture};
use crate::scene::mitsuba::PluginParams;
use crate::scene::TextureDesc;
use glam::{Vec2, Vec3};

#[derive(Debug, Clone)]
pub struct BlendBsdf {
    /// w: 0 gives `bsdfs[0]` alone, 1 `bsdfs[1]` alone.
    pub weight: Texture,
    pub bsdfs: Box<[Bsdf; 2]>,
}

impl BlendBsdf {
    pub fn new(weight: &TextureDesc, bsdfs: [Bsdf; 2]) -> Self {
        BlendBsdf {
            weight: Texture::new(weight),
            bsdfs: Box::new(bsdfs),
        }
    }

    /// w at the shading point, clipped to [0, 1]: Mitsuba's `eval_1`
    /// ([`super::roughness::eval_1`]).
    #[inline]
    fn weight(&self, ctx: &ShadingCtx) -> f32 {
        super::roughness::eval_1(&self.weight, ctx).clamp(0.0, 1.0)
    }

    /// The nested BSDF to sample for `u1` given w, with `u1` rescaled to [0, 1):
    /// (index, u1', its selection probability, the other's). w = 0 or 1 never picks the
    /// BSDF of weight 0.
    #[inline]
    fn choose(w: f32, u1: f32) -> (usize, f32, f32, f32) {
        const BELOW_ONE: f32 = 1.0 - f32::EPSILON / 2.0;
        if u1 < w || w >= 1.0 {
            (1, (u1 / w).min(BELOW_ONE), w, 1.0 - w)
        } else {
            (0, ((u1 - w) / (1.0 - w)).min(BELOW_ONE), 1.0 - w, w)
        }
    }
}

impl BsdfPlugin for BlendBsdf {
    const PLUGINS: &'static [&'static str] = &["blendbsdf"];

    /// `weight` (a number or a texture; required, as in Mitsuba) and exactly two nested
    /// BSDFs, in order.
    fn build(p: &mut PluginParams) -> anyhow::Result<Self> {
        if !p.has("weight") {
            return Err(p.error("blendbsdf needs a 'weight' (a float or a texture)"));
        }
        let weight = p.texture("weight", 0.5)?;
        match p.bsdfs()?.as_slice() {
            [a, b] => Ok(BlendBsdf::new(&weight, [a.clone(), b.clone()])),
            other => Err(p.error(format!(
                "blendbsdf needs exactly two nested BSDFs, got {}",
                other.len()
            ))),
        }
    }
}

impl BsdfModel for BlendBsdf {
    fn flags(&self) -> BsdfFlags {
        (self.bsdfs[0].flags() | self.bsdfs[1].flags())
            .with(BsdfFlags::VERTEX_COLOR, self.weight.reads_mesh_attribute())
    }

    fn describe(&self) -> String {
        format!(
            "blendbsdf of {} and {}",
            self.bsdfs[0].describe(),
            self.bsdfs[1].describe()
        )
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        let w = self.weight(ctx);
        self.bsdfs[0].eval(ctx, wi, wo) * (1.0 - w) + self.bsdfs[1].eval(ctx, wi, wo) * w
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        let w = self.weight(ctx);
        self.bsdfs[0].pdf(ctx, wi, wo) * (1.0 - w) + self.bsdfs[1].pdf(ctx, wi, wo) * w
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let (i, u1, w_i, w_other) = Self::choose(self.weight(ctx), u1);
        let mut s = self.bsdfs[i].sample(ctx, wi, u1, u2, lobes)?;
        let other = &self.bsdfs[1 - i];
        let pdf = w_other * other.pdf(ctx, wi, s.wo) + w_i * s.pdf;
        let value = other.eval(ctx, wi, s.wo) * w_other + s.weight * (w_i * s.pdf);
        s.weight = if pdf > 0.0 { value / pdf } else { Spec::ZERO };
        s.pdf = pdf;
        Some(s)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        self.bsdfs[0].polarized()?;
        self.bsdfs[1].polarized()?;
        Ok(self)
    }
}

impl PolarizedBsdf for BlendBsdf {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        let w = self.weight(ctx);
        let [a, b] = [0, 1].map(|i| match self.bsdfs[i].polarized() {
            Ok(m) => m.eval_mueller(ctx, wi, wo),
            Err(_) => MuellerValue::ZERO,
        });
        a.scaled(1.0 - w).plus(b.scaled(w), wi, wo)
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let (i, u1, w_i, w_other) = Self::choose(self.weight(ctx), u1);
        let (mut s, value) = self.bsdfs[i]
            .polarized()
            .ok()?
            .sample_mueller(ctx, wi, u1, u2, lobes)?;
        let other = &self.bsdfs[1 - i];
        let pdf = w_other * other.pdf(ctx, wi, s.wo) + w_i * s.pdf;
        let other_value = other.polarized().ok()?.eval_mueller(ctx, wi, s.wo);
        let blended = value
            .scaled(w_i * s.pdf)
            .plus(other_value.scaled(w_other), wi, s.wo);
        let inv = if pdf > 0.0 { 1.0 / pdf } else { 0.0 };
        s.pdf = pdf;
        s.weight = blended.unpolarized() * inv;
        Some((s, blended.scaled(inv)))
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{
        albedo, assert_chi2, assert_eval_pdf_sample_agree, assert_mueller_agrees,
        assert_reciprocal, conductor, constant, ctx_of, diffuse, dir, wl,
    };
    use super::*;
    use crate::scene::mitsuba::load_str;
    use std::path::Path;

    fn blend(w: f32, a: Bsdf, b: Bsdf) -> Bsdf {
        BlendBsdf::new(&constant(w), [a, b]).into()
    }

    #[test]
    fn sampling_matches_eval_and_pdf() {
        let cases = [
            (
                "rough gold + diffuse",
                blend(0.3, conductor("Au", 0.2, 0.2), diffuse(0.8)),
            ),
            (
                "diffuse + rough",
                blend(0.7, diffuse(0.5), conductor("0.2+3.9i", 0.1, 0.4)),
            ),
            (
                "mirror + diffuse",
                blend(0.5, conductor("Au", 0.0, 0.0), diffuse(0.5)),
            ),
        ];
        let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / 9.0);
        for (name, b) in &cases {
            assert_chi2(name, b, alpha);
            assert_eval_pdf_sample_agree(name, b);
            assert_mueller_agrees(name, b);
        }
        assert_reciprocal("blend", &cases[0].1, 1e-4);
    }

    /// f = (1 − w)·f₀ + w·f₁; w = 0 and 1 are the nested BSDFs alone; a blend of two white
    /// diffusers is a white diffuser (furnace).
    #[test]
    fn blends_linearly_and_conserves_energy() {
        let (a, b) = (conductor("Au", 0.3, 0.3), diffuse(0.6));
        let wl = wl();
        let ctx = ctx_of(&wl);
        let (wi, wo) = (dir(30.0, 10.0), dir(50.0, 200.0));
        let (fa, fb) = (a.eval(&ctx, wi, wo), b.eval(&ctx, wi, wo));
        for w in [0.0f32, 0.25, 1.0] {
            let f = blend(w, a.clone(), b.clone()).eval(&ctx, wi, wo);
            assert!(
                (f - (fa * (1.0 - w) + fb * w)).abs().max_element() < 1e-6,
                "w {w}"
            );
        }
        let white = blend(0.4, diffuse(1.0), diffuse(1.0));
        let e = albedo(&white, dir(60.0, 0.0), 20_000);
        assert!((e - Spec::ONE).abs().max_element() < 1e-5, "{e}");
    }

    /// A delta sample is mixed as Mitsuba 3.9 mixes it: weight (w·r·p + (1 − w)·f_o) /
    /// (w·p + (1 − w)·pdf_o) with the mirror's weight r and probability p = 1 and the diffuse
    /// BSDF's value and pdf in the mirror direction, not the mirror's weight alone. Also
    /// w = 0 and w = 1 with u1 = 0 pick the BSDF of non-zero weight.
    #[test]
    fn delta_samples_are_mixed_as_mitsuba_mixes_them() {
        let (mirror, matte) = (conductor("Au", 0.0, 0.0), diffuse(0.5));
        let wl = wl();
        let ctx = ctx_of(&wl);
        let wi = dir(40.0, 30.0);
        for w in [0.3f32, 0.5] {
            let b = blend(w, mirror.clone(), matte.clone());
            // u1 ≥ w picks BSDF 0, the mirror (Mitsuba: BSDF 1 when u1 ≤ w).
            let s = b.sample(&ctx, wi, 0.99, Vec2::splat(0.3), Lobes::ALL).unwrap();
            let r = mirror.sample(&ctx, wi, 0.5, Vec2::splat(0.3), Lobes::ALL).unwrap();
            let (f_o, pdf_o) = (matte.eval(&ctx, wi, s.wo), matte.pdf(&ctx, wi, s.wo));
            assert!(pdf_o > 0.1 && f_o.min_element() > 0.01);
            let want = (r.weight * (1.0 - w) + f_o * w) / ((1.0 - w) + w * pdf_o);
            assert!(s.is_delta() && (s.weight - want).abs().max_element() < 1e-5, "w {w}");
            assert!((s.weight - r.weight).abs().max_element() > 0.01, "w {w}: not mixed");
        }
        for (w, lobe) in [(0.0, BsdfFlags::DELTA_REFLECTION), (1.0, BsdfFlags::DIFFUSE_REFLECTION)] {
            let b = blend(w, mirror.clone(), matte.clone());
            let s = b.sample(&ctx, wi, 0.0, Vec2::splat(0.3), Lobes::ALL).unwrap();
            assert!(s.lobe == lobe && s.weight.is_finite(), "w {w}: {s:?}");
        }
    }

    #[test]
    fn is_read_from_mitsuba_xml() {
        let load = |body: &str| {
            let xml =
                format!(r#"<scene version="3.0.0"><shape type="sphere">{body}</shape></scene>"#);
            load_str(&xml, Path::new("."), &[], "t.xml")
        };
        let s = load(r#"<bsdf type="blendbsdf"><float name="weight" value="0.3"/><bsdf type="diffuse"/><bsdf type="conductor"/></bsdf>"#).unwrap();
        let Bsdf::Blend(b) = &s.bsdfs[s.shapes[0].bsdf] else {
            panic!("not a blend")
        };
        assert!(matches!(b.bsdfs[0], Bsdf::Diffuse(_)) && matches!(b.bsdfs[1], Bsdf::Conductor(_)));
        assert_eq!(b.weight.eval_scalar(glam::Vec2::ZERO), 0.3);
        for (body, want) in [
            (
                r#"<bsdf type="blendbsdf"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
                "weight",
            ),
            (
                r#"<bsdf type="blendbsdf"><float name="weight" value="0.3"/><bsdf type="diffuse"/></bsdf>"#,
                "exactly two",
            ),
        ] {
            let e = format!("{:#}", load(body).unwrap_err());
            assert!(e.contains(want) && e.contains("t.xml:1:"), "{e}");
        }
    }
}
