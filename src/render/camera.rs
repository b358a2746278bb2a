//! Mitsuba's sensors: `perspective` (a pinhole camera looking along local +Z with +Y up,
//! local +X towards the left edge of the image — Mitsuba's `lookat` builds its frame as
//! (left, up, dir) — `fov` measured along `fov_axis`), `thinlens` (the same frustum through
//! a lens disc focused on a plane) and `orthographic` (parallel rays).

use super::geometry::square_to_uniform_disk_concentric;
use crate::scene::{Camera as CameraDesc, FovAxis, Projection};
use glam::{DMat3, DVec2, DVec3, Mat4, Vec2, Vec3};

/// A ray with origin, unit direction and a valid interval.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

/// A prepared camera of any projection.
#[derive(Debug, Clone)]
pub enum Camera {
    Pinhole(PerspectiveCamera),
    /// Mitsuba `thinlens` (`thinlens.cpp` `sample_ray`): the pinhole's ray through film
    /// position (lx, ly, 1) meets the focal plane at f·(lx, ly, 1); the ray starts at a point
    /// `a` sampled uniformly (concentric map) on the lens disc of radius r in the local z = 0
    /// plane and heads for that focal point. Clip distances are along the optical axis.
    ThinLens {
        pinhole: PerspectiveCamera,
        aperture_radius: f32,
        focus_distance: f32,
    },
    Orthographic(OrthographicCamera),
}

/// Mitsuba `orthographic`: rays along `to_world`·(0, 0, 1) from `to_world`·(x, y, near) with
/// x = 1 − 2u ∈ [−1, 1] (u: film x, left to right) and y = (1 − 2v)/aspect, running
/// far − near.
#[derive(Debug, Clone)]
pub struct OrthographicCamera {
    to_world: Mat4,
    dir: Vec3,
    aspect: f32,
    near_clip: f32,
    far_clip: f32,
}

impl Camera {
    pub fn new(desc: &CameraDesc, width: u32, height: u32) -> anyhow::Result<Self> {
        Ok(match desc.projection {
            Projection::Perspective => {
                Camera::Pinhole(PerspectiveCamera::new(desc, width, height)?)
            }
            Projection::ThinLens {
                aperture_radius,
                focus_distance,
            } => Camera::ThinLens {
                pinhole: PerspectiveCamera::new(desc, width, height)?,
                aperture_radius,
                focus_distance,
            },
            Projection::Orthographic => {
                let m = desc.to_world;
                let dir = m.transform_vector3(Vec3::Z).normalize_or_zero();
                let det = glam::Mat3::from_mat4(m).determinant();
                if !(m.is_finite() && det.abs() > 1e-12 && dir != Vec3::ZERO) {
                    anyhow::bail!("camera to_world transform is singular or not finite");
                }
                Camera::Orthographic(OrthographicCamera {
                    to_world: m,
                    dir,
                    aspect: width as f32 / height as f32,
                    near_clip: desc.near_clip.max(0.0),
                    far_clip: desc.far_clip,
                })
            }
        })
    }

    /// The pinhole camera, for the screen bins (which need rays from one point).
    pub fn pinhole(&self) -> Option<&PerspectiveCamera> {
        match self {
            Camera::Pinhole(p) => Some(p),
            _ => None,
        }
    }

    /// Whether rays need a lens sample ([`Self::generate_ray_through`]).
    pub fn needs_aperture_sample(&self) -> bool {
        matches!(self, Camera::ThinLens { .. })
    }

    /// The ray through film position `film_uv` ∈ [0,1]² (x right, y down) and, for a thin
    /// lens, the centre of the lens.
    pub fn generate_ray(&self, film_uv: Vec2) -> Ray {
        self.generate_ray_through(film_uv, Vec2::splat(0.5))
    }

    /// The ray through film position `film_uv` and lens sample `aperture` ∈ [0,1)² (ignored
    /// without a lens).
    pub fn generate_ray_through(&self, film_uv: Vec2, aperture: Vec2) -> Ray {
        match self {
            Camera::Pinhole(p) => p.generate_ray(film_uv),
            Camera::ThinLens {
                pinhole: c,
                aperture_radius,
                focus_distance,
            } => {
                let lx = (1.0 - 2.0 * film_uv.x) * c.tan_half_x;
                let ly = (1.0 - 2.0 * film_uv.y) * c.tan_half_y;
                let a = square_to_uniform_disk_concentric(aperture) * *aperture_radius;
                let local = (Vec3::new(lx, ly, 1.0) * *focus_distance - a.extend(0.0)).normalize();
                let world = c.axis_x * local.x + c.axis_y * local.y + c.axis_z * local.z;
                let len = world.length();
                Ray {
                    origin: c.origin + c.axis_x * a.x + c.axis_y * a.y,
                    dir: world / len,
                    // Mitsuba: near/far over local d.z, in the units of `to_world * d`.
                    tmin: c.near_clip * len / local.z,
                    tmax: c.far_clip * len / local.z,
                }
            }
            Camera::Orthographic(o) => {
                let x = 1.0 - 2.0 * film_uv.x;
                let y = (1.0 - 2.0 * film_uv.y) / o.aspect;
                Ray {
                    origin: o.to_world.transform_point3(Vec3::new(x, y, o.near_clip)),
                    dir: o.dir,
                    tmin: 0.0,
                    tmax: o.far_clip - o.near_clip,
                }
            }
        }
    }
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
        FovAxis::FitY { min_aspect } => from_tan(half(fov_deg) * aspect.max(min_aspect)),
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

    fn cam() -> PerspectiveCamera {
        let desc = CameraDesc {
            to_world: Mat4::IDENTITY,
            fov_deg: 90.0,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 1000.0,
            projection: Projection::Perspective,
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

    /// Every thin-lens ray through one film point meets the others on the focal plane; at
    /// the lens centre it is the pinhole's ray.
    #[test]
    fn thin_lens_rays_converge_on_the_focal_plane() {
        let desc = CameraDesc {
            to_world: Mat4::from_translation(Vec3::new(0.0, 1.0, 0.0)),
            fov_deg: 40.0,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 100.0,
            projection: Projection::ThinLens {
                aperture_radius: 0.2,
                focus_distance: 3.0,
            },
        };
        let cam = Camera::new(&desc, 64, 48).unwrap();
        let uv = Vec2::new(0.3, 0.7);
        let pin = PerspectiveCamera::new(&desc, 64, 48)
            .unwrap()
            .generate_ray(uv);
        let centre = cam.generate_ray(uv);
        assert!((centre.dir - pin.dir).length() < 1e-6);
        let focus = |r: Ray| r.origin + r.dir * ((3.0 - r.origin.z) / r.dir.z);
        let want = focus(pin);
        for a in [
            Vec2::new(0.1, 0.9),
            Vec2::new(0.8, 0.2),
            Vec2::new(0.5, 0.0),
        ] {
            let r = cam.generate_ray_through(uv, a);
            assert!(r.origin.distance(Vec3::new(0.0, 1.0, 0.0)) <= 0.2 + 1e-6);
            assert!((focus(r) - want).length() < 1e-4, "{a}");
        }
    }

    #[test]
    fn orthographic_rays_are_parallel_and_span_the_scaled_square() {
        let desc = CameraDesc {
            to_world: Mat4::from_scale(Vec3::new(2.0, 2.0, 1.0)),
            fov_deg: 90.0,
            fov_axis: FovAxis::X,
            near_clip: 0.5,
            far_clip: 10.0,
            projection: Projection::Orthographic,
        };
        let cam = Camera::new(&desc, 40, 20).unwrap();
        let left = cam.generate_ray(Vec2::new(0.0, 0.5));
        let top = cam.generate_ray(Vec2::new(0.5, 0.0));
        assert_eq!(left.dir, Vec3::Z);
        assert!((left.origin - Vec3::new(2.0, 0.0, 0.5)).length() < 1e-6);
        assert!((top.origin - Vec3::new(0.0, 1.0, 0.5)).length() < 1e-6);
    }

    #[test]
    fn fov_axis_conversions() {
        assert!((fov_x_deg(60.0, FovAxis::X, 2.0) - 60.0).abs() < 1e-4);
        let fx = fov_x_deg(60.0, FovAxis::Y, 2.0);
        let expect = 2.0 * ((30.0f32).to_radians().tan() * 2.0).atan().to_degrees();
        assert!((fx - expect).abs() < 1e-4);
        assert!((fov_x_deg(60.0, FovAxis::Smaller, 0.5) - 60.0).abs() < 1e-4);
        // FitY: along y down to min_aspect, then the width of a min_aspect film.
        let fit = FovAxis::FitY { min_aspect: 0.8 };
        assert!((fov_x_deg(60.0, fit, 2.0) - expect).abs() < 1e-4);
        let narrow = 2.0 * ((30.0f32).to_radians().tan() * 0.8).atan().to_degrees();
        assert!((fov_x_deg(60.0, fit, 0.5) - narrow).abs() < 1e-4);
        assert!((fov_x_deg(60.0, fit, 0.8) - narrow).abs() < 1e-4);
    }
}
