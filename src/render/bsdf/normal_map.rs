//! Shading frames built from the surface parameterisation: Mitsuba's tangent frame (s along
//! dp/du, for anisotropic lobes and polarisers) and frames perturbed by normal and bump maps
//! (Mitsuba's `normalmap` and `bumpmap`), for models that wrap another one.

use super::{BsdfFlags, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::Spec;
use glam::{Vec2, Vec3};

/// Mitsuba's shading frame (`SurfaceInteraction::initialize_sh_frame`): n the shading normal,
/// s = dp/du made orthogonal to n (Gram–Schmidt), t = n × s. Falls back to the normal-only
/// frame where dp/du degenerates.
pub fn dpdu_frame(si: &SurfaceInteraction) -> Frame {
    frame_with_tangent(si.shading.n, si.dpdu).unwrap_or(si.shading)
}

/// The frame of unit normal `n` whose s axis is `tangent` made orthogonal to n; None where
/// the tangent is (nearly) parallel to n or not finite.
pub fn frame_with_tangent(n: Vec3, tangent: Vec3) -> Option<Frame> {
    let s = tangent - n * n.dot(tangent);
    if !(s.length_squared() > 1e-20 && s.is_finite()) {
        return None;
    }
    let s = s.normalize();
    Some(Frame {
        s,
        t: n.cross(s),
        n,
    })
}

/// The frame of a tangent-space normal `n_tangent` (x along the tangent, y along the
/// bitangent, z along the shading normal of `base`; need not be unit): its normal is
/// `base.to_world(n_tangent)` normalised, its s axis `tangent` made orthogonal to it
/// (Mitsuba's `normalmap` frame with base = its dp/du frame and tangent = dp/du; glTF's with
/// base = the vertex tangent frame). None when the normal degenerates.
pub fn perturbed_frame(base: &Frame, n_tangent: Vec3, tangent: Vec3) -> Option<Frame> {
    let n = base.to_world(n_tangent);
    if !(n.length_squared() > 1e-20 && n.is_finite()) {
        return None;
    }
    let n = n.normalize();
    Some(frame_with_tangent(n, tangent).unwrap_or_else(|| Frame::from_normal(n)))
}

/// Mitsuba's `normalmap` BSDF (3.9's `normalmap.cpp`): the nested model scatters in the frame
/// of the normal n = 2·rgb − 1 read from an RGB texture, given relative to the dp/du shading
/// frame (s = (1, 0, 0) made orthogonal to n, t = n × s). As Mitsuba:
/// - `flip_invalid_normals` (default on; Schüssler et al. 2017's simplest fix): where wi lies
///   below the perturbed normal, its tangential part is mirrored, (−x, −y, z);
/// - directions on opposite sides of the unperturbed and the perturbed normal give zero;
/// - `use_shadowing_function` (default on): values and sample weights are multiplied by
///   Estevez et al. 2019's terminator term 2 / (1 + √(1 + α² tan²θo)), with
///   α² = min(tan²θn / 8, 1) of the perturbed normal's tilt θn and θo in the unperturbed frame.
///
/// The model therefore sees wi and wo in the unperturbed frame (its `shading_frame`) and
/// perturbs them itself, per incident direction.
#[derive(Debug, Clone)]
pub struct NormalMap {
    pub inner: Box<super::Bsdf>,
    pub map: std::sync::Arc<crate::scene::BitmapTexture>,
    pub flip_invalid_normals: bool,
    pub use_shadowing_function: bool,
}

/// Mitsuba 3.8+'s handling of a perturbed normal `n` given in the unperturbed shading frame
/// (shared by `normalmap.cpp` and `bumpmap.cpp`, which differ only in how n is made): the
/// wrapper perturbs wi and wo itself, per incident direction.
/// - `flip_invalid_normals` (Schüssler et al. 2017's simplest fix): where wi lies below n,
///   n's tangential part is mirrored, (−x, −y, z);
/// - directions on opposite sides of the unperturbed and the perturbed normal give zero;
/// - `use_shadowing_function`: values and sample weights are multiplied by Estevez et al.
///   2019's terminator term 2 / (1 + √(1 + α² tan²θo)), with α² = min(tan²θn / 8, 1) of the
///   perturbed normal's tilt θn and θo in the unperturbed frame.
#[derive(Debug, Clone, Copy)]
pub struct Perturbation {
    pub flip_invalid_normals: bool,
    pub use_shadowing_function: bool,
}

impl Perturbation {
    /// The perturbed frame (normal `n`, need not be unit, after the flip; s = +x made
    /// orthogonal to it) in the coordinates of the unperturbed one, for incident `wi`; None
    /// where n degenerates.
    pub fn frame(&self, n: Vec3, wi: Vec3) -> Option<Frame> {
        let mut n = n;
        if self.flip_invalid_normals && wi.z * wi.dot(n) <= 0.0 {
            n = Vec3::new(-n.x, -n.y, n.z);
        }
        let n = n.normalize();
        let s = (Vec3::X - n * n.x).normalize();
        (n.is_finite() && s.is_finite()).then(|| Frame {
            s,
            t: n.cross(s),
            n,
        })
    }

    /// Estevez et al. 2019's shadowing of the perturbed normal `n` towards `wo` (both in the
    /// unperturbed frame), or 1 when `use_shadowing_function` is off.
    fn shadowing(&self, n: Vec3, wo: Vec3) -> f32 {
        if !self.use_shadowing_function {
            return 1.0;
        }
        let tan2 = |v: Vec3| (1.0 - v.z * v.z).max(0.0) / (v.z * v.z);
        let alpha2 = (0.125 * tan2(n)).min(1.0);
        2.0 / (1.0 + (1.0 + alpha2 * tan2(wo)).sqrt())
    }

    /// The perturbed frame and (wi, wo) in it, None where Mitsuba's value is zero (no usable
    /// normal, or wo on different sides of the two normals).
    fn perturb(&self, n: Vec3, wi: Vec3, wo: Vec3) -> Option<(Frame, Vec3, Vec3)> {
        let f = self.frame(n, wi)?;
        let (wi_p, wo_p) = (f.to_local(wi), f.to_local(wo));
        (wo.z * wo_p.z > 0.0).then_some((f, wi_p, wo_p))
    }

    /// `inner`'s value in the frame of `n`.
    pub fn eval(&self, inner: &super::Bsdf, ctx: &ShadingCtx, n: Vec3, wi: Vec3, wo: Vec3) -> Spec {
        match self.perturb(n, wi, wo) {
            Some((f, wi_p, wo_p)) => inner.eval(ctx, wi_p, wo_p) * self.shadowing(f.n, wo),
            None => Spec::ZERO,
        }
    }

    /// `inner`'s pdf in the frame of `n` (no shadowing: Mitsuba's pdf is the nested one).
    pub fn pdf(&self, inner: &super::Bsdf, ctx: &ShadingCtx, n: Vec3, wi: Vec3, wo: Vec3) -> f32 {
        match self.perturb(n, wi, wo) {
            Some((_, wi_p, wo_p)) => inner.pdf(ctx, wi_p, wo_p),
            None => 0.0,
        }
    }

    /// `inner` sampled in the frame of `n`, wo returned to the unperturbed frame.
    #[allow(clippy::too_many_arguments)]
    pub fn sample(
        &self,
        inner: &super::Bsdf,
        ctx: &ShadingCtx,
        n: Vec3,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let f = self.frame(n, wi)?;
        let mut s = inner.sample(ctx, f.to_local(wi), u1, u2, lobes)?;
        let wo = f.to_world(s.wo);
        if s.wo.z * wo.z <= 0.0 {
            return None;
        }
        s.wo = wo;
        s.weight *= self.shadowing(f.n, wo);
        Some(s)
    }

    /// [`Self::eval`] as a Mueller operator, Stokes bases in the unperturbed frame.
    pub fn eval_mueller(
        &self,
        inner: &dyn PolarizedBsdf,
        ctx: &ShadingCtx,
        n: Vec3,
        wi: Vec3,
        wo: Vec3,
    ) -> MuellerValue {
        let Some((f, wi_p, wo_p)) = self.perturb(n, wi, wo) else {
            return MuellerValue::ZERO;
        };
        let v = inner.eval_mueller(ctx, wi_p, wo_p).scaled(self.shadowing(f.n, wo));
        mueller_to_parent(v, &f)
    }

    /// [`Self::sample`] with the Mueller weight.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_mueller(
        &self,
        inner: &dyn PolarizedBsdf,
        ctx: &ShadingCtx,
        n: Vec3,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let f = self.frame(n, wi)?;
        let (mut s, v) = inner.sample_mueller(ctx, f.to_local(wi), u1, u2, lobes)?;
        let wo = f.to_world(s.wo);
        if s.wo.z * wo.z <= 0.0 {
            return None;
        }
        let g = self.shadowing(f.n, wo);
        s.wo = wo;
        s.weight *= g;
        Some((s, mueller_to_parent(v.scaled(g), &f)))
    }
}

impl NormalMap {
    /// The flag rules of this map.
    fn rules(&self) -> Perturbation {
        Perturbation {
            flip_invalid_normals: self.flip_invalid_normals,
            use_shadowing_function: self.use_shadowing_function,
        }
    }

    /// The texel's normal 2·rgb − 1 in the unperturbed frame (not normalised).
    fn texel_normal(&self, uv: Vec2) -> Vec3 {
        let rgb = self.map.eval(uv);
        Vec3::new(2.0 * rgb[0] - 1.0, 2.0 * rgb[1] - 1.0, 2.0 * rgb[2] - 1.0)
    }
}

impl super::BsdfPlugin for NormalMap {
    const PLUGINS: &'static [&'static str] = &["normalmap"];

    /// `normalmap`: an RGB bitmap texture (usually `raw`); `flip_invalid_normals` and
    /// `use_shadowing_function` (both true); one nested BSDF.
    fn build(p: &mut crate::scene::mitsuba::PluginParams) -> anyhow::Result<Self> {
        let map = match p.texture("normalmap", 0.0)? {
            crate::scene::TextureDesc::Bitmap(b) if b.channels == 3 => b,
            _ => {
                return Err(p.error_at(
                    "normalmap",
                    "normalmap: 'normalmap' must be an RGB bitmap <texture>",
                ))
            }
        };
        let flip_invalid_normals = p.bool("flip_invalid_normals", true)?;
        let use_shadowing_function = p.bool("use_shadowing_function", true)?;
        let inner = match p.bsdfs()?.as_slice() {
            [b] => b.clone(),
            _ => return Err(p.error("normalmap needs exactly one nested BSDF")),
        };
        Ok(NormalMap {
            inner: Box::new(inner),
            map,
            flip_invalid_normals,
            use_shadowing_function,
        })
    }
}

impl super::BsdfModel for NormalMap {
    fn flags(&self) -> BsdfFlags {
        self.inner.flags()
    }

    fn describe(&self) -> String {
        format!("normalmap {}", self.inner.describe())
    }

    /// The unperturbed dp/du frame (Mitsuba's `si.sh_frame`); the map perturbs per call.
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        dpdu_frame(si)
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        let n = self.texel_normal(ctx.uv);
        self.rules().eval(&self.inner, ctx, n, wi, wo)
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        let n = self.texel_normal(ctx.uv);
        self.rules().pdf(&self.inner, ctx, n, wi, wo)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        let n = self.texel_normal(ctx.uv);
        self.rules()
            .sample(&self.inner, ctx, n, wi, u1, u2, lobes)
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        self.inner.polarized().map(|_| self as &dyn PolarizedBsdf)
    }
}

/// `v` (a value in the perturbed frame `f`) with its Stokes bases in `f`'s parent frame.
fn mueller_to_parent(mut v: MuellerValue, f: &Frame) -> MuellerValue {
    if let Some(p) = &mut v.polarized {
        p.s_in = f.to_world(p.s_in);
        p.s_out = f.to_world(p.s_out);
    }
    v
}

impl PolarizedBsdf for NormalMap {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        let Ok(inner) = self.inner.polarized() else {
            return MuellerValue::ZERO;
        };
        let n = self.texel_normal(ctx.uv);
        self.rules().eval_mueller(inner, ctx, n, wi, wo)
    }

    fn sample_mueller(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<(BsdfSample, MuellerValue)> {
        let inner = self.inner.polarized().ok()?;
        let n = self.texel_normal(ctx.uv);
        self.rules()
            .sample_mueller(inner, ctx, n, wi, u1, u2, lobes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn si(n: Vec3, dpdu: Vec3) -> SurfaceInteraction {
        SurfaceInteraction {
            p: Vec3::ZERO,
            t: 1.0,
            ng: n,
            shading: Frame::from_normal(n),
            uv: glam::Vec2::ZERO,
            dpdu,
            dpdv: Vec3::ZERO,
            shape: 0,
            color: Vec3::ONE,
            tangent: glam::Vec4::ZERO,
        }
    }

    /// The dp/du frame is orthonormal with s along dp/du's tangential part; a flat normal map
    /// texel (0.5, 0.5, 1) leaves it unchanged; a tilted texel tilts the normal towards +s.
    #[test]
    fn frames_follow_dpdu_and_the_map() {
        let n = Vec3::new(0.0, 0.6, 0.8);
        let dpdu = Vec3::new(2.0, 0.3, 0.0);
        let f = dpdu_frame(&si(n, dpdu));
        assert!((f.s.dot(f.n)).abs() < 1e-6 && (f.s.length() - 1.0).abs() < 1e-6);
        assert!((f.t - f.n.cross(f.s)).length() < 1e-6);
        assert!(f.s.dot(dpdu) > 0.0 && f.s.x > 0.9);
        let flat = perturbed_frame(&f, Vec3::Z, dpdu).unwrap();
        assert!((flat.n - f.n).length() < 1e-6 && (flat.s - f.s).length() < 1e-6);
        let tilted = perturbed_frame(&f, Vec3::new(0.5, 0.0, 0.866), dpdu).unwrap();
        assert!((tilted.n.dot(f.s) - 0.5).abs() < 1e-3, "{:?}", tilted.n);
        assert!(tilted.s.dot(tilted.n).abs() < 1e-6);
        // Degenerate dp/du: the normal-only frame.
        let g = dpdu_frame(&si(n, Vec3::ZERO));
        assert!((g.n - n).length() < 1e-6);
    }

    use super::super::tests::{
        assert_chi2, assert_eval_pdf_sample_agree, assert_mueller_agrees, conductor, ctx_of,
        diffuse, dir, wl,
    };
    use super::super::{Bsdf, BsdfModel};

    /// A normal map of one texel `rgb` over `inner`.
    fn mapped(rgb: [f32; 3], inner: Bsdf, flip: bool, shadow: bool) -> NormalMap {
        let map = crate::scene::BitmapTexture::new(1, 1, 3, rgb.to_vec()).unwrap();
        NormalMap {
            inner: Box::new(inner),
            map: std::sync::Arc::new(map),
            flip_invalid_normals: flip,
            use_shadowing_function: shadow,
        }
    }

    /// A flat texel is the nested model (no tilt: the shadowing term is 1); a tilted one
    /// applies Estevez et al.'s term 2/(1 + √(1 + α² tan²θo)), α² = min(tan²θn/8, 1).
    #[test]
    fn flat_map_is_the_nested_model_and_tilt_shadows() {
        let wl = wl();
        let ctx = ctx_of(&wl);
        let (wi, wo) = (dir(30.0, 10.0), dir(70.0, 20.0));
        let inner = diffuse(0.8);
        let flat = mapped([0.5, 0.5, 1.0], inner.clone(), true, true);
        assert!((flat.eval(&ctx, wi, wo) - inner.eval(&ctx, wi, wo)).abs().max_element() < 1e-6);
        // n = (0.6, 0, 0.8): tan²θn = 0.5625, α² = 0.0703.
        let rgb = [0.8, 0.5, 0.9];
        let on = mapped(rgb, inner.clone(), true, true);
        let off = mapped(rgb, inner.clone(), true, false);
        let tan2_o = (1.0 - wo.z * wo.z) / (wo.z * wo.z);
        let g = 2.0 / (1.0 + (1.0 + 0.5625 / 8.0 * tan2_o).sqrt());
        let (a, b) = (on.eval(&ctx, wi, wo)[0], off.eval(&ctx, wi, wo)[0]);
        assert!(b > 0.0 && (a / b - g).abs() < 1e-5, "{a} {b} {g}");
        assert!(g < 0.97);
    }

    /// Where wi lies below the perturbed normal, `flip_invalid_normals` mirrors the normal's
    /// tangential part so that wi sees its front; without it the nested diffuse model sees wi
    /// from below and returns nothing. Directions on different sides of the two normals give
    /// zero.
    #[test]
    fn invalid_normals_are_flipped_and_sides_checked() {
        let wl = wl();
        let ctx = ctx_of(&wl);
        // n tilted 60° towards +x; wi grazing from −x is below it.
        let rgb = [0.5 + 0.5 * 0.866, 0.5, 0.75];
        let wi = dir(80.0, 180.0);
        let wo = dir(20.0, 0.0);
        let flipped = mapped(rgb, diffuse(0.8), true, false);
        let kept = mapped(rgb, diffuse(0.8), false, false);
        assert!(flipped.eval(&ctx, wi, wo)[0] > 0.0);
        assert_eq!(kept.eval(&ctx, wi, wo)[0], 0.0);
        let f = flipped
            .rules()
            .frame(flipped.texel_normal(ctx.uv), wi)
            .unwrap();
        assert!(f.n.x < 0.0 && wi.dot(f.n) > 0.0, "{:?}", f.n);
        // wo above the macro surface but below the perturbed normal (and the converse).
        let (wi, below_n) = (dir(10.0, 0.0), dir(80.0, 180.0));
        assert_eq!(kept.eval(&ctx, wi, below_n)[0], 0.0);
        assert_eq!(kept.pdf(&ctx, wi, below_n), 0.0);
    }

    #[test]
    fn sampling_matches_eval_and_pdf() {
        let rgb = [0.7, 0.45, 0.9];
        let cases = [
            ("normalmap-rough", mapped(rgb, conductor("0.2+3.9i", 0.3, 0.3), true, true)),
            ("normalmap-diffuse", mapped(rgb, diffuse(0.6), true, true)),
        ];
        let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / 6.0);
        for (name, b) in cases {
            let b: Bsdf = b.into();
            assert_chi2(name, &b, alpha);
            assert_eval_pdf_sample_agree(name, &b);
            assert_mueller_agrees(name, &b);
        }
    }
}
