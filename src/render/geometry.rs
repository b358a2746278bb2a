//! Small geometric helpers shared by the renderer: orthonormal frames, sampling warps and the
//! surface interaction record.

use glam::{Vec2, Vec3, Vec4};
use std::f32::consts::{FRAC_1_PI, PI};

/// An orthonormal frame (s, t, n); local coordinates have n as +z.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// Frame around a unit normal (Duff et al. 2017, "Building an orthonormal basis, revisited").
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Cosine-weighted hemisphere direction (Malley's method on a concentric disk).
#[inline]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Shirley–Chiu concentric map of the unit square to the unit disk.
#[inline]
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, (PI / 4.0) * (o.y / o.x))
    } else {
        (o.y, PI / 2.0 - (PI / 4.0) * (o.x / o.y))
    };
    let (s, c) = theta.sin_cos();
    Vec2::new(r * c, r * s)
}

/// Uniform direction on the unit sphere; pdf 1/(4π).
#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Uniform direction in the cone of half-angle acos(`cos_max`) around +Z; pdf
/// 1 / (2π (1 − cos_max)) (Mitsuba `warp::square_to_uniform_cone`).
#[inline]
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let z = 1.0 - u.y * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Uniform barycentrics on a triangle (b1, b2), b0 = 1 − b1 − b2.
#[inline]
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let t = (1.0 - u.x).max(0.0).sqrt();
    Vec2::new(1.0 - t, u.y * t)
}

/// Power heuristic with β = 2 (Veach 1997, §9.2); zero when `pdf_a` is zero.
#[inline]
pub fn mis_power(pdf_a: f32, pdf_b: f32) -> f32 {
    let a2 = pdf_a * pdf_a;
    let b2 = pdf_b * pdf_b;
    if pdf_a > 0.0 && (a2 + b2).is_finite() {
        a2 / (a2 + b2)
    } else if pdf_a > 0.0 {
        // pdf_b overflowed: weight by ratio instead of squares.
        if pdf_a >= pdf_b {
            1.0
        } else {
            0.0
        }
    } else {
        0.0
    }
}

/// Where a ray met a surface.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceInteraction {
    /// Hit point (world).
    pub p: Vec3,
    /// Ray distance to the hit.
    pub t: f32,
    /// Geometric normal (unit, outward as modelled).
    pub ng: Vec3,
    /// Shading frame (interpolated normal as z).
    pub shading: Frame,
    pub uv: Vec2,
    /// ∂p/∂u (world, not normalised; zero where the parameterisation degenerates): the
    /// tangent of models that need one ([`super::bsdf::BsdfModel::shading_frame`]).
    pub dpdu: Vec3,
    /// ∂p/∂v (world, not normalised; zero where degenerate): with `dpdu`, the surface
    /// parameterisation a bump map perturbs ([`super::bsdf::bump_map`]).
    pub dpdv: Vec3,
    /// Index into the prepared scene's shapes.
    pub shape: u32,
    /// The mesh's vertex colour here (linear RGB, barycentric blend; 1 without colours):
    /// glTF `COLOR_0`, Mitsuba's `mesh_attribute` `vertex_color`.
    pub color: Vec3,
    /// The mesh's vertex tangent here (glTF `TANGENT`, barycentric blend of xyz, w = ±1 the
    /// bitangent's sign); zero without tangents (models then use `dpdu`).
    pub tangent: Vec4,
}

/// A point offset off a surface along its geometric normal, on the side of `dir`, to avoid
/// re-hitting the surface it left (scaled with the magnitude of the coordinates, like
/// Mitsuba's `RayEpsilon · (1 + max|p|)`).
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let eps = 1e-4 * (1.0 + p.abs().max_element());
    if ng.dot(dir) >= 0.0 {
        p + ng * eps
    } else {
        p - ng * eps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.4, 0.866).normalize(),
        ] {
            let f = Frame::from_normal(n);
            assert!((f.s.dot(f.t)).abs() < 1e-6 && (f.s.dot(f.n)).abs() < 1e-6);
            assert!((f.s.length() - 1.0).abs() < 1e-6 && (f.t.length() - 1.0).abs() < 1e-6);
            let v = Vec3::new(0.1, 0.7, -0.2);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-6);
        }
    }

    #[test]
    fn mis_weights_sum_to_one() {
        let (a, b) = (0.3, 1.7);
        assert!((mis_power(a, b) + mis_power(b, a) - 1.0).abs() < 1e-6);
        assert_eq!(mis_power(0.0, 1.0), 0.0);
        assert_eq!(mis_power(1.0, f32::INFINITY), 0.0);
    }
}
