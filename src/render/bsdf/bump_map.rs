//! Mitsuba 3's `bumpmap` BSDF: a height texture's uv gradient tilts the shading frame
//! (Blinn 1978, "Simulation of wrinkled surfaces"; Mitsuba's `BumpMap::frame`), and the
//! nested model scatters in the tilted frame.

use super::normal_map::frame_with_tangent;
use crate::render::geometry::{Frame, SurfaceInteraction};
use crate::scene::{BitmapTexture, TextureDesc};
use glam::Vec2;
use std::sync::Arc;

/// The bump-mapped frame for height gradient `grad` = scale·(∂h/∂u, ∂h/∂v), as Mitsuba:
/// the surface displaced by h along the shading normal n has (to first order, dropping the
/// ∂n terms) ∂p'/∂u = ∂p/∂u with its normal component replaced by ∂h/∂u, likewise for v;
/// n' = normalize(∂p'/∂u × ∂p'/∂v), flipped to the side of the geometric normal; s is
/// ∂p/∂u made orthogonal to n'. The unperturbed frame where the parameterisation
/// degenerates (zero ∂p/∂u or ∂p/∂v, e.g. a sphere's poles).
pub fn bumped_frame(si: &SurfaceInteraction, grad: Vec2) -> Frame {
    let n = si.shading.n;
    let dpdu = si.dpdu + n * (grad.x - n.dot(si.dpdu));
    let dpdv = si.dpdv + n * (grad.y - n.dot(si.dpdv));
    let m = dpdu.cross(dpdv);
    if !(m.length_squared() > 1e-30 && m.is_finite()) {
        return si.shading;
    }
    let m = m.normalize();
    let m = if m.dot(si.ng) < 0.0 { -m } else { m };
    frame_with_tangent(m, si.dpdu).unwrap_or_else(|| Frame::from_normal(m))
}

/// Mitsuba's `bumpmap`: `scale` × the gradient of a height texture (a bitmap; a constant
/// has no gradient) perturbs the frame of the nested model. Mitsuba also zeroes `eval`
/// where wo lies on different sides of the unperturbed and the perturbed normal; as for
/// [`super::normal_map::NormalMap`], this renderer's models see only the perturbed frame,
/// so that case (grazing wo on steep slopes) is not reproduced. Mitsuba 3.8+'s default
/// `flip_invalid_normals` and `use_shadowing_function` are not implemented either: this
/// is its `false, false` form (matters near silhouettes and terminators).
#[derive(Debug, Clone)]
pub struct BumpMap {
    pub inner: Box<super::Bsdf>,
    /// The height bitmap; None for a constant height (zero gradient).
    pub height: Option<Arc<BitmapTexture>>,
    pub scale: f32,
}

impl super::BsdfPlugin for BumpMap {
    const PLUGINS: &'static [&'static str] = &["bumpmap"];

    /// `bumpmap`: one nested `<texture>` (any name; a bitmap or a constant), `scale`
    /// (default 1), one nested BSDF.
    fn build(p: &mut crate::scene::mitsuba::PluginParams) -> anyhow::Result<Self> {
        // Mitsuba 3.8+ defaults both to true (a mirrored normal where wi would fall below it,
        // Schüssler et al. 2017; Estevez et al. 2019's terminator shadowing): only their
        // classic `false` form is implemented.
        if !(p.has("flip_invalid_normals") && p.has("use_shadowing_function")) {
            eprintln!(
                "warning: {}: bumpmap: Mitsuba 3.8+ turns flip_invalid_normals and \
                 use_shadowing_function on by default; thinfilm renders both off (set them to \
                 false to silence this): a few % darker or brighter near silhouettes and \
                 shadow terminators",
                p.location()
            );
        }
        p.accept_bool("flip_invalid_normals", |v| !v)?;
        p.accept_bool("use_shadowing_function", |v| !v)?;
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
        })
    }
}

impl super::BsdfModel for BumpMap {
    super::frame_only_wrapper!();

    fn describe(&self) -> String {
        format!("bumpmap(scale {}) {}", self.scale, self.inner.describe())
    }

    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        let grad = match &self.height {
            Some(h) => h.eval_grad(si.uv) * self.scale,
            None => Vec2::ZERO,
        };
        bumped_frame(si, grad)
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
}
