//! Shading frames built from the surface parameterisation: Mitsuba's tangent frame (s along
//! dp/du, for anisotropic lobes and polarisers) and frames perturbed by normal and bump maps
//! (Mitsuba's `normalmap` and `bumpmap`), for models that wrap another one.

use crate::render::geometry::{Frame, SurfaceInteraction};
use glam::Vec3;

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

/// Mitsuba's `normalmap` BSDF: the nested model scatters in the frame of the normal read from
/// an RGB texture (n = 2·rgb − 1 in the dp/du frame). Mitsuba also zeroes `eval` where wo
/// lies on different sides of the unperturbed and the perturbed normal; this renderer's
/// models see only the perturbed frame, so that rare case (grazing wo on strongly tilted
/// texels) is not reproduced.
#[derive(Debug, Clone)]
pub struct NormalMap {
    pub inner: Box<super::Bsdf>,
    pub map: std::sync::Arc<crate::scene::BitmapTexture>,
}

impl super::BsdfPlugin for NormalMap {
    const PLUGINS: &'static [&'static str] = &["normalmap"];

    /// `normalmap`: an RGB bitmap texture (usually `raw`); one nested BSDF.
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
        let inner = match p.bsdfs()?.as_slice() {
            [b] => b.clone(),
            _ => return Err(p.error("normalmap needs exactly one nested BSDF")),
        };
        Ok(NormalMap {
            inner: Box::new(inner),
            map,
        })
    }
}

impl super::BsdfModel for NormalMap {
    super::frame_only_wrapper!();

    fn describe(&self) -> String {
        format!("normalmap {}", self.inner.describe())
    }

    fn shading_frame(&self, si: &SurfaceInteraction) -> Frame {
        let rgb = self.map.eval(si.uv);
        let n = Vec3::new(2.0 * rgb[0] - 1.0, 2.0 * rgb[1] - 1.0, 2.0 * rgb[2] - 1.0);
        perturbed_frame(&dpdu_frame(si), n, si.dpdu).unwrap_or(si.shading)
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
}
