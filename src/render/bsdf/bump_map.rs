//! Mitsuba 3's `bumpmap` BSDF: a height texture's uv gradient tilts the shading frame
//! (Blinn 1978, "Simulation of wrinkled surfaces"; Mitsuba's `BumpMap::frame`), and the
//! nested model scatters in the tilted frame.

use super::normal_map::{dpdu_frame, frame_with_tangent, Perturbation};
use super::{BsdfFlags, BsdfSample, Lobes, MuellerValue, PolarizedBsdf, ShadingCtx};
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::render::texture::Spec;
use crate::scene::{BitmapTexture, TextureDesc};
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// The bump-mapped frame for height gradient `grad` = scale·(∂h/∂u, ∂h/∂v), as Mitsuba:
/// the surface displaced by h along the shading normal n has (to first order, dropping the
/// ∂n terms) ∂p'/∂u = ∂p/∂u with its normal component replaced by ∂h/∂u, likewise for v;
/// n' = normalize(∂p'/∂u × ∂p'/∂v), flipped to the side of the geometric normal; s is
/// ∂p/∂u made orthogonal to n'. The unperturbed frame where the parameterisation
/// degenerates (zero ∂p/∂u or ∂p/∂v, e.g. a sphere's poles).
pub fn bumped_frame(si: &SurfaceInteraction, grad: Vec2) -> Frame {
    match bumped_normal(si, grad) {
        Some(m) => frame_with_tangent(m, si.dpdu).unwrap_or_else(|| Frame::from_normal(m)),
        None => si.shading,
    }
}

/// The normal of [`bumped_frame`] (world space); None where the parameterisation degenerates.
fn bumped_normal(si: &SurfaceInteraction, grad: Vec2) -> Option<Vec3> {
    let n = si.shading.n;
    let dpdu = si.dpdu + n * (grad.x - n.dot(si.dpdu));
    let dpdv = si.dpdv + n * (grad.y - n.dot(si.dpdv));
    let m = dpdu.cross(dpdv);
    if !(m.length_squared() > 1e-30 && m.is_finite()) {
        return None;
    }
    let m = m.normalize();
    Some(if m.dot(si.ng) < 0.0 { -m } else { m })
}

/// Mitsuba's `bumpmap` (3.9's `bumpmap.cpp`): `scale` × the gradient of a height texture (a
/// bitmap; a constant has no gradient) perturbs the frame of the nested model.
///
/// With Mitsuba's defaults (`flip_invalid_normals`, `use_shadowing_function` on) the model
/// scatters in the unperturbed dp/du frame: the bumped normal is computed once per hit
/// ([`super::BsdfModel::perturbed_normal`], in that frame's coordinates) and the shared
/// [`Perturbation`] rules of `normalmap` apply per direction (the flip, the zero where wo lies
/// on different sides of the two normals, Estevez et al.'s shadowing term). The perturbed s
/// axis is the unperturbed one made orthogonal to the bumped normal (Mitsuba orthogonalises
/// the world dp/du against the local normal; the two differ only by a rotation about the
/// normal, visible to anisotropic or polarising nested models alone).
///
/// With both flags off the model is Mitsuba's classic form as before 3.8: the nested model
/// scatters in the bumped frame itself, without the side check.
#[derive(Debug, Clone)]
pub struct BumpMap {
    pub inner: Box<super::Bsdf>,
    /// The height bitmap; None for a constant height (zero gradient).
    pub height: Option<Arc<BitmapTexture>>,
    pub scale: f32,
    pub flip_invalid_normals: bool,
    pub use_shadowing_function: bool,
}

impl BumpMap {
    /// Both flags off: the frame-only form.
    fn classic(&self) -> bool {
        !(self.flip_invalid_normals || self.use_shadowing_function)
    }

    fn rules(&self) -> Perturbation {
        Perturbation {
            flip_invalid_normals: self.flip_invalid_normals,
            use_shadowing_function: self.use_shadowing_function,
        }
    }

    /// scale × the height gradient at `uv`.
    fn gradient(&self, uv: Vec2) -> Vec2 {
        match &self.height {
            Some(h) => h.eval_grad(uv) * self.scale,
            None => Vec2::ZERO,
        }
    }
}

impl super::BsdfPlugin for BumpMap {
    const PLUGINS: &'static [&'static str] = &["bumpmap"];

    /// `bumpmap`: one nested `<texture>` (any name; a bitmap or a constant), `scale`
    /// (default 1), `flip_invalid_normals` and `use_shadowing_function` (both true), one
    /// nested BSDF.
    fn build(p: &mut crate::scene::mitsuba::PluginParams) -> anyhow::Result<Self> {
        let flip_invalid_normals = p.bool("flip_invalid_normals", true)?;
        let use_shadowing_function = p.bool("use_shadowing_function", true)?;
        let scale = p.float("scale", 1.0)? as f32;
        if !scale.is_finite() {
            return Err(p.error_at("scale", "bumpmap: 'scale' must be finite"));
        }
        let height = match p.nested_textures().as_slice() {
            [TextureDesc::Bitmap(b)] => Some(b.clone()),
            [TextureDesc::Value(_)] => None,
            [_] => {
                return Err(p.error(
                    "bumpmap: the height <texture> must be a bitmap or a constant \
                     (its uv gradient is needed)",
                ))
            }
            _ => return Err(p.error("bumpmap needs exactly one nested height <texture>")),
        };
        let inner = match p.bsdfs()?.as_slice() {
            [b] => b.clone(),
            _ => return Err(p.error("bumpmap needs exactly one nested BSDF")),
        };
        Ok(BumpMap {
            inner: Box::new(inner),
            height,
            scale,
            flip_invalid_normals,
            use_shadowing_function,
        })
    }
}

/// `ctx` for the nested model: this map's normal is consumed here, so a nested bump map
/// sees none (it stays flat, as the classic form leaves it) rather than this one twice.
fn inner_ctx<'a>(ctx: &ShadingCtx<'a>) -> ShadingCtx<'a> {
    ShadingCtx {
        bump_normal: Vec3::Z,
        ..*ctx
    }
}

impl super::BsdfModel for BumpMap {
    fn flags(&self) -> BsdfFlags {
        self.inner.flags()
    }

    fn describe(&self) -> String {
        format!("bumpmap(scale {}) {}", self.scale, self.inner.describe())
    }

    fn eval(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> Spec {
        if self.classic() {
            return self.inner.eval(ctx, wi, wo);
        }
        self.rules()
            .eval(&self.inner, &inner_ctx(ctx), ctx.bump_normal, wi, wo)
    }

    fn pdf(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> f32 {
        if self.classic() {
            return self.inner.pdf(ctx, wi, wo);
        }
        self.rules()
            .pdf(&self.inner, &inner_ctx(ctx), ctx.bump_normal, wi, wo)
    }

    fn sample(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
        lobes: Lobes,
    ) -> Option<BsdfSample> {
        if self.classic() {
            return self.inner.sample(ctx, wi, u1, u2, lobes);
        }
        let n = ctx.bump_normal;
        self.rules()
            .sample(&self.inner, &inner_ctx(ctx), n, wi, u1, u2, lobes)
    }

    fn sample_split(
        &self,
        ctx: &ShadingCtx,
        wi: Vec3,
        u1: f32,
        u2: Vec2,
    ) -> [Option<BsdfSample>; 2] {
        if self.classic() {
            return self.inner.sample_split(ctx, wi, u1, u2);
        }
        [
            self.sample(ctx, wi, u1, u2, Lobes::REFLECTION),
            self.sample(ctx, wi, u1, u2, Lobes::TRANSMISSION),
        ]
    }

    fn polarized(&self) -> Result<&dyn PolarizedBsdf, &'static str> {
        if self.classic() {
            return self.inner.polarized();
        }
        self.inner.polarized().map(|_| self as &dyn PolarizedBsdf)
    }

    /// The bumped frame (classic form) or the unperturbed dp/du frame (Mitsuba's
    /// `si.sh_frame`; the bumped normal then comes through [`Self::perturbed_normal`]).
    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        if self.classic() {
            return bumped_frame(si, self.gradient(si.uv));
        }
        dpdu_frame(si)
    }

    fn perturbed_normal(&self, si: &SurfaceInteraction) -> Vec3 {
        if self.classic() {
            return Vec3::Z;
        }
        match bumped_normal(si, self.gradient(si.uv)) {
            Some(m) => dpdu_frame(si).to_local(m),
            None => Vec3::Z,
        }
    }
}

impl PolarizedBsdf for BumpMap {
    fn eval_mueller(&self, ctx: &ShadingCtx, wi: Vec3, wo: Vec3) -> MuellerValue {
        let Ok(inner) = self.inner.polarized() else {
            return MuellerValue::ZERO;
        };
        self.rules()
            .eval_mueller(inner, &inner_ctx(ctx), ctx.bump_normal, wi, wo)
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
        let n = ctx.bump_normal;
        self.rules()
            .sample_mueller(inner, &inner_ctx(ctx), n, wi, u1, u2, lobes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn si(ng: Vec3, dpdu: Vec3, dpdv: Vec3) -> SurfaceInteraction {
        SurfaceInteraction {
            p: Vec3::ZERO,
            t: 1.0,
            ng,
            shading: Frame::from_normal(ng),
            uv: Vec2::ZERO,
            dpdu,
            dpdv,
            shape: 0,
            color: Vec3::ONE,
            tangent: glam::Vec4::ZERO,
        }
    }

    /// Zero gradient keeps the normal; a slope g along u on a plane with |∂p/∂u| = L tilts
    /// it by atan(g/L) away from +u; the flip follows the geometric normal whatever the
    /// handedness of (u, v); degenerate ∂p/∂v leaves the frame alone.
    #[test]
    fn slopes_tilt_the_normal() {
        let (du, dv) = (Vec3::X * 2.0, Vec3::Y * 3.0);
        let flat = bumped_frame(&si(Vec3::Z, du, dv), Vec2::ZERO);
        assert!((flat.n - Vec3::Z).length() < 1e-6 && (flat.s - Vec3::X).length() < 1e-6);
        let f = bumped_frame(&si(Vec3::Z, du, dv), Vec2::new(1.0, 0.0));
        let tilt = f.n.dot(Vec3::Z).acos();
        assert!((tilt - 0.5f32.atan()).abs() < 1e-5, "{tilt}");
        assert!(f.n.x < 0.0 && f.n.y.abs() < 1e-6, "{:?}", f.n);
        assert!(f.s.dot(f.n).abs() < 1e-6 && (f.t - f.n.cross(f.s)).length() < 1e-6);
        // Mirrored parameterisation (v along −y): same normal, still on the +z side.
        let g = bumped_frame(&si(Vec3::Z, du, -dv), Vec2::new(1.0, 0.0));
        assert!((g.n - f.n).length() < 1e-5, "{:?} vs {:?}", g.n, f.n);
        let d = bumped_frame(&si(Vec3::Z, du, Vec3::ZERO), Vec2::new(1.0, 0.0));
        assert!((d.n - Vec3::Z).length() < 1e-6);
    }

    use super::super::tests::{
        assert_eval_pdf_sample_agree_in, assert_mueller_agrees, chi2_pvalue_in,
        conductor, ctx_of, diffuse, dir, wl,
    };
    use super::super::{Bsdf, BsdfModel};

    /// A bumpmap over `inner` whose gradient is `grad` everywhere (a 1×1 bitmap has none,
    /// so the tests feed the gradient through `bumped_normal` directly).
    fn bump(inner: Bsdf, flip: bool, shadow: bool) -> BumpMap {
        BumpMap {
            inner: Box::new(inner),
            height: None,
            scale: 1.0,
            flip_invalid_normals: flip,
            use_shadowing_function: shadow,
        }
    }

    /// The bumped normal of slope `grad` on the plane z = 0 with ∂p/∂u = 2x, ∂p/∂v = 3y, in
    /// the unperturbed frame (what `perturbed_normal` hands the model).
    fn local_normal(grad: Vec2) -> Vec3 {
        let s = si(Vec3::Z, Vec3::X * 2.0, Vec3::Y * 3.0);
        dpdu_frame(&s).to_local(bumped_normal(&s, grad).unwrap())
    }

    /// With the flags on the model scatters in the unperturbed dp/du frame and the bumped
    /// normal it is handed, expressed there, is the classic bumped frame's normal; a flat
    /// height is the nested model.
    #[test]
    fn flat_height_is_the_nested_model() {
        let wl = wl();
        let s = si(Vec3::new(0.0, 0.6, 0.8), Vec3::new(2.0, 0.3, -0.2), Vec3::Y * 3.0);
        let b = bump(diffuse(0.8), true, true);
        let f = b.shading_frame(&s);
        assert!((f.n - s.shading.n).length() < 1e-6);
        let n = b.perturbed_normal(&s);
        assert!((n - Vec3::Z).length() < 1e-6, "{n:?}");
        let grad = Vec2::new(0.4, -0.7);
        let classic = bumped_frame(&s, grad);
        let m = dpdu_frame(&s).to_local(bumped_normal(&s, grad).unwrap());
        assert!((f.to_world(m) - classic.n).length() < 1e-5);
        let ctx = ShadingCtx {
            bump_normal: n,
            ..ctx_of(&wl)
        };
        let inner = diffuse(0.8);
        let (wi, wo) = (dir(30.0, 10.0), dir(70.0, 200.0));
        let (a, e) = (b.eval(&ctx, wi, wo), inner.eval(&ctx, wi, wo));
        assert!((a - e).abs().max_element() < 1e-6, "{a} {e}");
        assert!((b.pdf(&ctx, wi, wo) - inner.pdf(&ctx, wi, wo)).abs() < 1e-6);
    }

    /// A slope tilts the normal by θn = atan(g/|∂p/∂u|); with the shadowing function on the
    /// value is multiplied by Estevez et al.'s 2/(1 + √(1 + α² tan²θo)), α² = min(tan²θn/8, 1).
    #[test]
    fn tilt_shadows() {
        let wl = wl();
        let ctx = ShadingCtx {
            bump_normal: local_normal(Vec2::new(1.0, 0.0)),
            ..ctx_of(&wl)
        };
        let (wi, wo) = (dir(30.0, 10.0), dir(70.0, 200.0));
        let on = bump(diffuse(0.8), true, true);
        let off = bump(diffuse(0.8), true, false);
        // tan θn = 1/2.
        let tan2_o = (1.0 - wo.z * wo.z) / (wo.z * wo.z);
        let g = 2.0 / (1.0 + (1.0 + 0.25 / 8.0 * tan2_o).sqrt());
        let (a, b) = (on.eval(&ctx, wi, wo)[0], off.eval(&ctx, wi, wo)[0]);
        assert!(b > 0.0 && (a / b - g).abs() < 1e-5, "{a} {b} {g}");
        assert!(g < 0.99);
    }

    /// A bump map nested in another does not apply the outer one's normal a second time.
    #[test]
    fn nested_map_sees_no_second_tilt() {
        let wl = wl();
        let ctx = ShadingCtx {
            bump_normal: local_normal(Vec2::new(1.0, 0.0)),
            ..ctx_of(&wl)
        };
        let single = bump(diffuse(0.8), true, true);
        let nested = bump(bump(diffuse(0.8), true, true).into(), true, true);
        let (wi, wo) = (dir(30.0, 10.0), dir(70.0, 200.0));
        let (a, b) = (single.eval(&ctx, wi, wo), nested.eval(&ctx, wi, wo));
        assert!(a[0] > 0.0 && (a - b).abs().max_element() < 1e-6, "{a} {b}");
    }

    /// A steep slope (normal tilted 60° towards −x): wi grazing from +x lies below it. With
    /// `flip_invalid_normals` the normal is mirrored to face wi and the diffuse lobe answers;
    /// without it nothing does. wo above the macro surface but below the bumped normal gives
    /// zero.
    #[test]
    fn invalid_normals_are_flipped_and_sides_checked() {
        let wl = wl();
        let n = local_normal(Vec2::new(2.0 * 3f32.sqrt(), 0.0));
        assert!((n.z - 0.5).abs() < 1e-5 && n.x < 0.0, "{n:?}");
        let ctx = ShadingCtx {
            bump_normal: n,
            ..ctx_of(&wl)
        };
        let flipped = bump(diffuse(0.8), true, false);
        let kept = bump(diffuse(0.8), false, true);
        let (wi, wo) = (dir(80.0, 0.0), dir(20.0, 180.0));
        assert!(flipped.eval(&ctx, wi, wo)[0] > 0.0);
        assert_eq!(kept.eval(&ctx, wi, wo)[0], 0.0);
        let (wi, below_n) = (dir(10.0, 180.0), dir(80.0, 0.0));
        assert_eq!(kept.eval(&ctx, wi, below_n)[0], 0.0);
        assert_eq!(kept.pdf(&ctx, wi, below_n), 0.0);
    }

    /// Both flags off is the frame-only model as before: the bumped frame, the nested
    /// model's values and samples bit for bit, no perturbed normal.
    #[test]
    fn flags_off_is_the_classic_frame() {
        let wl = wl();
        let ctx = ctx_of(&wl);
        let s = si(Vec3::Z, Vec3::X * 2.0, Vec3::Y * 3.0);
        let inner = conductor("0.2+3.9i", 0.3, 0.3);
        let b = bump(inner.clone(), false, false);
        assert_eq!(b.shading_frame(&s).n, bumped_frame(&s, Vec2::ZERO).n);
        assert_eq!(b.perturbed_normal(&s), Vec3::Z);
        let (wi, wo) = (dir(30.0, 10.0), dir(35.0, 185.0));
        assert_eq!(b.eval(&ctx, wi, wo), inner.eval(&ctx, wi, wo));
        assert_eq!(b.pdf(&ctx, wi, wo), inner.pdf(&ctx, wi, wo));
        let (x, y) = (
            b.sample(&ctx, wi, 0.3, Vec2::new(0.2, 0.7), Lobes::ALL).unwrap(),
            inner.sample(&ctx, wi, 0.3, Vec2::new(0.2, 0.7), Lobes::ALL).unwrap(),
        );
        assert_eq!((x.wo, x.weight, x.pdf), (y.wo, y.weight, y.pdf));
    }

    #[test]
    fn sampling_matches_eval_and_pdf() {
        let wl = wl();
        let ctx = ShadingCtx {
            bump_normal: local_normal(Vec2::new(1.2, -0.8)),
            ..ctx_of(&wl)
        };
        let cases = [
            ("bumpmap-rough", bump(conductor("0.2+3.9i", 0.3, 0.3), true, true)),
            ("bumpmap-diffuse", bump(diffuse(0.6), true, true)),
        ];
        let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / 6.0);
        for (name, b) in cases {
            let b: Bsdf = b.into();
            for (k, wi) in [dir(10.0, 20.0), dir(45.0, 200.0), dir(80.0, 90.0)]
                .into_iter()
                .enumerate()
            {
                let pv = chi2_pvalue_in(&b, &ctx, wi, 200_000, 7 + k as u64);
                assert!(pv > alpha, "{name} at {wi}: χ² p-value {pv:e}");
            }
            assert_eval_pdf_sample_agree_in(name, &b, &ctx);
            assert_mueller_agrees(name, &b);
        }
    }
}
