//! Mitsuba's `perspective` sensor: pinhole camera looking along local +Z with +Y up, local +X
//! towards the left edge of the image (Mitsuba's `lookat` builds its frame as
//! (left, up, dir)); `fov` measured along `fov_axis`.

use crate::scene::{Camera as CameraDesc, FovAxis};
use glam::{DMat3, DVec2, DVec3, Vec2, Vec3};

/// A ray with origin, unit direction and a valid interval.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

/// A prepared pinhole camera.
#[derive(Debug, Clone)]
pub struct PerspectiveCamera {
    origin: Vec3,
    /// World vectors of camera-local x, y, z (unnormalised if `to_world` scales).
    axis_x: Vec3,
    axis_y: Vec3,
    axis_z: Vec3,
    /// tan(fov_x / 2) and tan(fov_y / 2).
    tan_half_x: f32,
    tan_half_y: f32,
    near_clip: f32,
    far_clip: f32,
    /// Inverse of the matrix with columns (axis_x, axis_y, axis_z), in f64: maps a world
    /// offset from the pinhole to camera-local coordinates (for [`Self::camera_local`]).
    to_local: DMat3,
}

/// Horizontal field of view in degrees, converted like Mitsuba's `parse_fov`.
pub fn fov_x_deg(fov_deg: f32, axis: FovAxis, aspect: f32) -> f32 {
    let half = |d: f32| (0.5 * d.to_radians()).tan();
    let from_tan = |t: f32| 2.0 * t.atan().to_degrees();
    match axis {
        FovAxis::X => fov_deg,
        FovAxis::Y => from_tan(half(fov_deg) * aspect),
        FovAxis::Diagonal => {
            let diagonal = 2.0 * half(fov_deg);
            let width = diagonal / (1.0 + 1.0 / (aspect * aspect)).sqrt();
            from_tan(0.5 * width)
        }
        FovAxis::Smaller => {
            if aspect > 1.0 {
                fov_x_deg(fov_deg, FovAxis::Y, aspect)
            } else {
                fov_deg
            }
        }
        FovAxis::Larger => {
            if aspect > 1.0 {
                fov_deg
            } else {
                fov_x_deg(fov_deg, FovAxis::Y, aspect)
            }
        }
    }
}

impl PerspectiveCamera {
    pub fn new(desc: &CameraDesc, width: u32, height: u32) -> anyhow::Result<Self> {
        let aspect = width as f32 / height as f32;
        let fov_x = fov_x_deg(desc.fov_deg, desc.fov_axis, aspect);
        if !(fov_x > 0.0 && fov_x < 180.0) {
            anyhow::bail!(
                "camera field of view must be in (0°, 180°), got {} along {:?}",
                desc.fov_deg,
                desc.fov_axis
            );
        }
        let tan_half_x = (0.5 * fov_x.to_radians()).tan();
        let m = desc.to_world;
        let origin = m.transform_point3(Vec3::ZERO);
        let axis_x = m.transform_vector3(Vec3::X);
        let axis_y = m.transform_vector3(Vec3::Y);
        let axis_z = m.transform_vector3(Vec3::Z);
        if !(origin.is_finite() && axis_x.cross(axis_y).dot(axis_z).abs() > 1e-12) {
            anyhow::bail!("camera to_world transform is singular or not finite");
        }
        Ok(PerspectiveCamera {
            origin,
            axis_x,
            axis_y,
            axis_z,
            tan_half_x,
            tan_half_y: tan_half_x / aspect,
            near_clip: desc.near_clip.max(0.0),
            far_clip: if desc.far_clip > 0.0 {
                desc.far_clip
            } else {
                f32::INFINITY
            },
            to_local: DMat3::from_cols(axis_x.as_dvec3(), axis_y.as_dvec3(), axis_z.as_dvec3())
                .inverse(),
        })
    }

    /// Camera-local coordinates q of world point `p`: `p = origin + M q` with M's columns the
    /// camera axes. A primary ray's points are `q = t·k·(lx, ly, 1)`, so q.z ≥ 0 on every ray
    /// and q.z grows linearly along it ([`Self::local_depth_rate`]).
    pub fn camera_local(&self, p: Vec3) -> DVec3 {
        self.to_local * (p.as_dvec3() - self.origin.as_dvec3())
    }

    /// k = dq.z/dt along a unit direction `dir` (1/|unnormalised direction| for a primary ray).
    #[inline]
    pub fn local_depth_rate(&self, dir: Vec3) -> f32 {
        let r = self.to_local.row(2);
        (r.x * dir.x as f64 + r.y * dir.y as f64 + r.z * dir.z as f64) as f32
    }

    /// Raster position (pixels, x right, y down) at which the primary ray through
    /// camera-local point `q` (q.z > 0) crosses the film: the inverse of [`Self::generate_ray`].
    pub fn raster_of(&self, q: DVec3, width: u32, height: u32) -> DVec2 {
        let lx = q.x / (q.z * self.tan_half_x as f64);
        let ly = q.y / (q.z * self.tan_half_y as f64);
        DVec2::new(
            0.5 * (1.0 - lx) * width as f64,
            0.5 * (1.0 - ly) * height as f64,
        )
    }

    /// The primary ray through film position `film_uv` ∈ [0,1]² (x right, y down).
    #[inline]
    pub fn generate_ray(&self, film_uv: Vec2) -> Ray {
        let local = Vec3::new(
            (1.0 - 2.0 * film_uv.x) * self.tan_half_x,
            (1.0 - 2.0 * film_uv.y) * self.tan_half_y,
            1.0,
        );
        let world = self.axis_x * local.x + self.axis_y * local.y + self.axis_z * local.z;
        let len = world.length();
        let dir = world / len;
        // Clip planes are distances along the optical axis (local z = 1 here), so in world
        // units the ray parameter is scaled by the length of the unnormalised direction.
        Ray {
            origin: self.origin,
            dir,
            tmin: self.near_clip * len,
            tmax: self.far_clip * len,
        }
    }

    /// The pinhole every camera ray starts from.
    #[inline]
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// [`Self::generate_ray`] for `N` film positions at once in struct-of-arrays form
    /// (directions, tmin, tmax; every ray starts at [`Self::origin`]): the same operations
    /// per lane, so the same rays bit for bit, in loops that compile to SIMD.
    #[inline]
    pub fn generate_rays<const N: usize>(
        &self,
        film_uv: &[[f32; N]; 2],
    ) -> ([[f32; N]; 3], [f32; N], [f32; N]) {
        let (ax, ay, az) = (self.axis_x, self.axis_y, self.axis_z);
        let mut dir = [[0.0f32; N]; 3];
        let mut tmin = [0.0f32; N];
        let mut tmax = [0.0f32; N];
        for i in 0..N {
            let lx = (1.0 - 2.0 * film_uv[0][i]) * self.tan_half_x;
            let ly = (1.0 - 2.0 * film_uv[1][i]) * self.tan_half_y;
            let lz = 1.0;
            let w = [
                ax.x * lx + ay.x * ly + az.x * lz,
                ax.y * lx + ay.y * ly + az.y * lz,
                ax.z * lx + ay.z * ly + az.z * lz,
            ];
            let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            for k in 0..3 {
                dir[k][i] = w[k] / len;
            }
            tmin[i] = self.near_clip * len;
            tmax[i] = self.far_clip * len;
        }
        (dir, tmin, tmax)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat4;

    fn cam() -> PerspectiveCamera {
        let desc = CameraDesc {
            to_world: Mat4::IDENTITY,
            fov_deg: 90.0,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 1000.0,
        };
        PerspectiveCamera::new(&desc, 200, 100).unwrap()
    }

    #[test]
    fn centre_ray_looks_forward_and_left_edge_is_plus_x() {
        let c = cam();
        let r = c.generate_ray(Vec2::new(0.5, 0.5));
        assert!((r.dir - Vec3::Z).length() < 1e-6);
        // Mitsuba: the left image edge is the camera's local +X, the top is +Y.
        let left = c.generate_ray(Vec2::new(0.0, 0.5));
        assert!(left.dir.dot(c.axis_x) > 0.7);
        let top = c.generate_ray(Vec2::new(0.5, 0.0));
        assert!(top.dir.y > 0.4);
    }

    #[test]
    fn fov_axis_conversions() {
        assert!((fov_x_deg(60.0, FovAxis::X, 2.0) - 60.0).abs() < 1e-4);
        let fx = fov_x_deg(60.0, FovAxis::Y, 2.0);
        let expect = 2.0 * ((30.0f32).to_radians().tan() * 2.0).atan().to_degrees();
        assert!((fx - expect).abs() < 1e-4);
        assert!((fov_x_deg(60.0, FovAxis::Smaller, 0.5) - 60.0).abs() < 1e-4);
    }
}
