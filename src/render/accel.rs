//! Ray–scene intersection: one obvhs CWBVH (8-wide compressed BVH, Ylitie et al. 2017) over
//! every triangle of the scene, with the triangle array reordered into BVH leaf order so the
//! hot loop reads triangles contiguously, plus analytic spheres tested linearly.

use super::camera::Ray;
use super::geometry::{Frame, SurfaceInteraction};
use crate::scene::{Geometry, Scene, TriangleMesh};
use glam::{Mat3, Vec2, Vec3, Vec4};
use obvhs::cwbvh::CwBvh;
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;

/// An analytic sphere.
#[derive(Debug, Clone, Copy)]
pub struct SphereGeom {
    pub center: Vec3,
    pub radius: f32,
    /// World → the sphere's local frame, where Mitsuba measures its (u, v).
    pub to_local: Mat3,
    pub flip_normals: bool,
    pub shape: u32,
}

/// Rays per packet traversal ([`Accel::intersect_batch`]).
pub const PACKET: usize = 16;
/// Packets are formed of rays whose directions are within this cosine of the first's.
pub const PACKET_MIN_COS: f32 = 0.9;

/// Scenes with at most this many triangles test rays against all of them in SIMD lanes
/// instead of traversing the BVH (a Cornell box: 36).
const SMALL_SCENE: usize = 64;
/// Hits nearer than this are left to the BVH in a small scene (twice the node test's
/// epsilon, see [`Accel::intersect_small`]).
const NEAR_HIT: f32 = 2e-4;
/// Batches of fewer rays than this test each ray against triangles in lanes
/// ([`Accel::intersect_small`]).
const FEW_RAYS: usize = 8;

/// What a closest-hit query found.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    pub t: f32,
    pub prim: Prim,
}

#[derive(Debug, Clone, Copy)]
pub enum Prim {
    /// Index into the BVH-ordered triangle array.
    Triangle(u32),
    /// Index into the sphere list.
    Sphere(u32),
}

/// The acceleration structure and the geometry it needs to build interactions.
pub struct Accel {
    bvh: Option<CwBvh>,
    /// Triangles in BVH order (index = BVH primitive id), with edges and normal precomputed
    /// for the hot intersection loop
    /// (obvhs `RtTriangle`: the same Möller–Trumbore arithmetic as `Triangle::intersect`, so
    /// hits are bit-identical, minus two subtractions and a cross product per test).
    rt_tris: Vec<RtTriangle>,
    /// A small scene's triangles, [`PACKET`] per group in lanes ([`Self::intersect_small`]);
    /// empty otherwise.
    small_groups: Vec<TriLanes>,
    /// (shape, triangle index within the shape's mesh), BVH order.
    tri_ref: Vec<(u32, u32)>,
    spheres: Vec<SphereGeom>,
    /// The CPU has AVX2 (checked once at build): traversal uses the 8-wide node test.
    avx2: bool,
    /// Each BVH node's child boxes decoded to f32 for the AVX2 traversal (empty without
    /// AVX2, and for large BVHs): see [`ChildPlanes`].
    planes: Vec<ChildPlanes>,
    /// Meshes by shape index (None for non-mesh shapes), shared with the scene.
    meshes: Vec<Option<std::sync::Arc<TriangleMesh>>>,
}

impl Accel {
    /// [`Self::build_beside`] with nothing beside.
    #[cfg(test)]
    pub(crate) fn build(scene: &Scene, samples: u64) -> anyhow::Result<(Self, usize)> {
        let (accel, dropped, ()) = Self::build_beside(scene, samples, |_| ())?;
        Ok((accel, dropped))
    }

    /// Builds the BVH. Degenerate, non-finite and repeated triangles are dropped (they cannot
    /// be hit, or add nothing to their twin); the count is returned so the caller can report it.
    /// `samples` (pixels × samples per pixel to render) picks the build's effort, see
    /// [`build_effort`].
    ///
    /// Memory: at 2M triangles the peak is obvhs' BVH2 → CWBVH conversion (a 7-entry cost
    /// table per BVH2 node, ~110 bytes per triangle, beside the BVH2's own 64). Nothing else of
    /// size is held then: triangles are (shape, index) references into the scene's meshes until
    /// the intersection array is made after the build, the build boxes are freed once the BVH2
    /// exists, and the meshes are the scene's own arrays, shared, not copied (what `beside`
    /// holds aside: screen bins are built only with ≥ 4 camera rays per triangle).
    ///
    /// `beside` runs on another thread while the BVH is built: set-up work that needs only
    /// the triangles' vertices (the camera's screen bins: ~11 ms for the 36k-triangle teapot
    /// at 256²) overlaps the build's serial stages (the CWBVH conversion). It sees the
    /// triangles in scene order; [`Self::bvh_order`] maps them to the BVH's ids.
    pub fn build_beside<R: Send>(
        scene: &Scene,
        samples: u64,
        beside: impl FnOnce(&SceneTriangles) -> R + Send,
    ) -> anyhow::Result<(Self, usize, R)> {
        let (tri_ref, spheres, dropped) = collect_triangles(scene)?;
        let scene_tris = SceneTriangles {
            scene,
            tri_ref: &tri_ref,
        };
        let (bvh, beside) = std::thread::scope(|s| {
            let beside = s.spawn(|| beside(&scene_tris));
            let bvh = (!tri_ref.is_empty()).then(|| {
                let effort = build_effort(samples, tri_ref.len());
                build_bvh(&tri_ref, |r| scene_tris.vertices_of(r), effort)
            });
            let beside = (beside.join()).unwrap_or_else(|p| std::panic::resume_unwind(p));
            (bvh, beside)
        });
        let vertices = |r: &TriRef| scene_tris.vertices_of(r);
        let (bvh, rt_tris, tri_ref) = match bvh {
            None => (None, Vec::new(), tri_ref),
            Some(bvh) => {
                // Reorder once so leaf primitive ids index the triangle arrays directly.
                use rayon::prelude::*;
                let order = &bvh.primitive_indices;
                let rt_tris = (order.par_iter())
                    .map(|&i| {
                        let [a, b, c] = vertices(&tri_ref[i as usize]);
                        RtTriangle::new(a.into(), b.into(), c.into())
                    })
                    .collect();
                let tri_ref = order.par_iter().map(|&i| tri_ref[i as usize]).collect();
                (Some(bvh), rt_tris, tri_ref)
            }
        };
        let meshes = (scene.shapes.iter())
            .map(|s| match &s.geometry {
                Geometry::Mesh(m) => Some(std::sync::Arc::clone(m)),
                Geometry::Sphere { .. } => None,
            })
            .collect();
        let small_groups = if rt_tris.len() <= SMALL_SCENE {
            rt_tris.chunks(PACKET).map(TriLanes::of).collect()
        } else {
            Vec::new()
        };
        let avx2 = cpu_has_avx2();
        let planes = match &bvh {
            Some(bvh) if avx2 => ChildPlanes::for_bvh(bvh),
            _ => Vec::new(),
        };
        Ok((
            Accel {
                bvh,
                rt_tris,
                small_groups,
                tri_ref,
                spheres,
                avx2,
                planes,
                meshes,
            },
            dropped,
            beside,
        ))
    }

    /// Triangle ids in BVH order of the triangles [`Self::build_beside`] showed in scene
    /// order: `bvh_order()[j]` is the scene-order index of BVH triangle `j`.
    pub fn bvh_order(&self) -> &[u32] {
        self.bvh.as_ref().map_or(&[], |b| &b.primitive_indices)
    }

    pub fn triangle_count(&self) -> usize {
        self.rt_tris.len()
    }

    /// Closest hit in (tmin, tmax).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if self.is_small() {
            let mut hit = [None];
            self.intersect_small(std::slice::from_ref(ray), &mut hit);
            return hit[0];
        }
        self.intersect_bvh(ray)
    }

    /// [`Self::intersect`] through the BVH.
    #[inline]
    fn intersect_bvh(&self, ray: &Ray) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tmax = ray.tmax;
        if let Some(bvh) = &self.bvh {
            let scalar = || {
                let r = obvhs::ray::Ray::new(ray.origin.into(), ray.dir.into(), ray.tmin, tmax);
                closest_hit(bvh, &self.rt_tris, r)
            };
            #[cfg(target_arch = "x86_64")]
            let found = if self.avx2 {
                // SAFETY: the CPU supports AVX2 and FMA (checked at build time).
                unsafe { x86::closest_hit_of(bvh, &self.planes, &self.rt_tris, ray) }
            } else {
                scalar()
            };
            #[cfg(not(target_arch = "x86_64"))]
            let found = scalar();
            if let Some((t, id)) = found {
                tmax = t;
                best = Some(Hit {
                    t,
                    prim: Prim::Triangle(id),
                });
            }
        }
        self.closest_sphere(ray, tmax, best)
    }

    /// Closest hits of a batch of rays (`hits[i]` for `rays[i]`, exactly [`Self::intersect`]'s
    /// answers). Rays are grouped greedily into packets of up to [`PACKET`] coherent rays —
    /// directions within [`PACKET_MIN_COS`] of the group's first, wherever they are in the
    /// batch (a pixel's reflected and refracted rays come interleaved) — that share one
    /// packet traversal; rays left alone are traced one by one.
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut Vec<Option<Hit>>) {
        hits.clear();
        if self.is_small() {
            hits.resize(rays.len(), None);
            for (chunk, out) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
                self.intersect_small(chunk, out);
            }
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if let (Some(bvh), true) = (&self.bvh, self.avx2) {
            hits.resize(rays.len(), None);
            // Windows of 64 rays: `free` marks those not yet traced.
            for (w, window) in rays.chunks(64).enumerate() {
                let base = w * 64;
                let mut free = if window.len() == 64 {
                    u64::MAX
                } else {
                    (1u64 << window.len()) - 1
                };
                while free != 0 {
                    let first = free.trailing_zeros() as usize;
                    free &= free - 1;
                    let d0 = window[first].dir;
                    let mut members = [first; PACKET];
                    let mut m = 1;
                    let mut rest = free;
                    while rest != 0 && m < PACKET {
                        let j = rest.trailing_zeros() as usize;
                        rest &= rest - 1;
                        if window[j].dir.dot(d0) >= PACKET_MIN_COS {
                            members[m] = j;
                            m += 1;
                            free &= !(1u64 << j);
                        }
                    }
                    if m == 1 {
                        hits[base + first] = self.intersect_bvh(&window[first]);
                        continue;
                    }
                    let mut packet =
                        [obvhs::ray::Ray::new_inf(Vec3::Z.into(), Vec3::Z.into()); PACKET];
                    for (p, &j) in packet.iter_mut().zip(&members[..m]) {
                        let r = &window[j];
                        *p = obvhs::ray::Ray::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax);
                    }
                    let mut best = [u32::MAX; PACKET];
                    // SAFETY: the CPU supports AVX2 and FMA (checked at build time).
                    let t = unsafe {
                        x86::closest_hit_packet_avx2(
                            bvh,
                            &self.planes,
                            &self.rt_tris,
                            &packet[..m],
                            &mut best,
                        )
                    };
                    for (i, &j) in members[..m].iter().enumerate() {
                        let r = &window[j];
                        let (tri_hit, tmax) = if best[i] != u32::MAX {
                            let hit = Hit {
                                t: t[i],
                                prim: Prim::Triangle(best[i]),
                            };
                            (Some(hit), t[i])
                        } else {
                            (None, r.tmax)
                        };
                        hits[base + j] = self.closest_sphere(r, tmax, tri_hit);
                    }
                }
            }
            return;
        }
        hits.extend(rays.iter().map(|r| self.intersect(r)));
    }

    /// At most [`SMALL_SCENE`] triangles: every closest-hit and any-hit query tests the ray
    /// against all triangles in SIMD lanes ([`Self::intersect_small`],
    /// [`Self::occluded_small`]) instead of traversing the BVH.
    #[inline]
    fn is_small(&self) -> bool {
        self.bvh.is_some() && self.rt_tris.len() <= SMALL_SCENE
    }

    /// Closest hits of up to [`PACKET`] rays of a small scene ([`Self::is_small`]), in
    /// `hits[i]` for `rays[i]`: the rays in SIMD lanes against every triangle in id order, with the BVH's
    /// triangle test and [`closer`] rule, so the nearest hit, ties included, is the one a
    /// traversal finds wherever the traversal's node test does not cull it: a box the ray
    /// leaves within the node test's epsilon (1e-4) of its origin (a ray leaving a floor
    /// within 1e-4 of a wall can pass through the wall there), so a hit nearer than
    /// [`NEAR_HIT`] is traced again by the BVH. Each lane's answer depends on its own ray
    /// only: a ray gets the same hit in any batch, and alone.
    ///
    /// Which data go in the SIMD lanes depends on the batch: below [`FEW_RAYS`] rays (deeper
    /// bounces, where fewer paths live: 8.9 rays per call on average in the Cornell box) each
    /// ray is tested against [`PACKET`] triangles at a time instead. The closest hit is the
    /// lexicographic minimum of (t, id) over the triangles hit before the ray's tmax, whatever
    /// the order of the tests, and each (ray, triangle) distance is the same IEEE operations
    /// either way, so both give the same hits bit for bit.
    fn intersect_small(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        let (mut tmax, mut best) = ([0.0f32; PACKET], [u32::MAX; PACKET]);
        if rays.len() < FEW_RAYS {
            for (i, r) in rays.iter().enumerate() {
                (tmax[i], best[i]) = self.closest_small_triangle(r);
            }
        } else {
            let mut lanes = RayLanes::of_rays(rays);
            for (id, tri) in self.rt_tris.iter().enumerate() {
                lanes.test_triangle(&TriScalars::of(tri), id as u32, &mut best);
            }
            tmax = lanes.tmax;
        }
        for (i, (r, h)) in rays.iter().zip(hits.iter_mut()).enumerate() {
            let t = tmax[i];
            *h = if best[i] == u32::MAX {
                self.closest_sphere(r, t, None)
            } else if t < NEAR_HIT {
                self.intersect_bvh(r)
            } else {
                let hit = Hit {
                    t,
                    prim: Prim::Triangle(best[i]),
                };
                self.closest_sphere(r, t, Some(hit))
            };
        }
    }

    /// One ray of a small scene against its triangles, [`PACKET`] at a time in lanes: the
    /// nearest distance (the ray's tmax if none) and triangle id (`u32::MAX` if none), as
    /// [`RayLanes::test_triangle`] over every triangle in id order finds them.
    fn closest_small_triangle(&self, r: &Ray) -> (f32, u32) {
        let (o, d) = (r.origin.to_array(), r.dir.to_array());
        let (mut best_t, mut best) = (r.tmax, u32::MAX);
        for (g, group) in self.small_groups.iter().enumerate() {
            let t = group.distances(o, d, r.tmin, best_t);
            // Nearest lane, the first (smallest id) on ties; later groups win only when
            // strictly nearer, as `closer` lets a later id win.
            let (mut m, mut lane) = (f32::INFINITY, usize::MAX);
            for (i, &ti) in t[..group.count].iter().enumerate() {
                if ti < m {
                    (m, lane) = (ti, i);
                }
            }
            if lane != usize::MAX && m < best_t {
                (best_t, best) = (m, (g * PACKET + lane) as u32);
            }
        }
        (best_t, best)
    }

    /// [`Self::occluded`] of every ray (`out[i]` for `rays[i]`), [`PACKET`] rays at a time
    /// in a small scene ([`Self::occluded_small`]).
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut Vec<bool>) {
        out.clear();
        if !self.is_small() {
            out.extend(rays.iter().map(|r| self.occluded_bvh(r)));
            return;
        }
        out.resize(rays.len(), false);
        for (chunk, blocked) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            self.occluded_small(chunk, blocked);
        }
    }

    /// Whether each of up to [`PACKET`] shadow rays of a small scene is blocked, in `out[i]`
    /// for `rays[i]`: the rays in SIMD lanes against every triangle until each is blocked; a ray
    /// blocked only nearer than [`NEAR_HIT`] asks the BVH (see [`Self::intersect_small`]).
    fn occluded_small(&self, rays: &[Ray], out: &mut [bool]) {
        let lanes = RayLanes::of_rays(rays);
        let (mut sure, mut unsure) = ([false; PACKET], [false; PACKET]);
        for tris in self.rt_tris.chunks(4) {
            for tri in tris {
                lanes.blocked_by(&TriScalars::of(tri), &mut sure, &mut unsure);
            }
            if sure.iter().all(|&f| f) {
                break;
            }
        }
        for (i, (r, o)) in rays.iter().zip(out.iter_mut()).enumerate() {
            *o = sure[i]
                || (self.spheres.iter())
                    .any(|s| sphere_intersect(s, r.origin, r.dir, r.tmin, r.tmax) < r.tmax)
                || (unsure[i] && self.occluded_bvh(r));
        }
    }

    /// `best` (closest hit so far, at `tmax`) improved by the analytic spheres.
    #[inline]
    pub(super) fn closest_sphere(
        &self,
        ray: &Ray,
        mut tmax: f32,
        mut best: Option<Hit>,
    ) -> Option<Hit> {
        for (i, s) in self.spheres.iter().enumerate() {
            let t = sphere_intersect(s, ray.origin, ray.dir, ray.tmin, tmax);
            if t < tmax {
                tmax = t;
                best = Some(Hit {
                    t,
                    prim: Prim::Sphere(i as u32),
                });
            }
        }
        best
    }

    /// Tests triangle `id` (BVH order) against every lane, keeping each lane's closest hit
    /// (`best`: triangle ids, u32::MAX before a hit; distances in the lanes' tmax): the exact
    /// test and tie rule of the BVH traversal, so a hit found here is the BVH's hit.
    #[inline(always)]
    pub(super) fn test_triangle_lanes(
        &self,
        lanes: &mut RayLanes,
        id: u32,
        best: &mut [u32; PACKET],
    ) {
        lanes.test_triangle(&TriScalars::of(&self.rt_tris[id as usize]), id, best);
    }

    /// True if anything blocks the segment (tmin, tmax) (shadow rays; early exit).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.is_small() {
            let mut blocked = [false];
            self.occluded_small(std::slice::from_ref(ray), &mut blocked);
            return blocked[0];
        }
        self.occluded_bvh(ray)
    }

    /// [`Self::occluded`] through the BVH.
    #[inline]
    fn occluded_bvh(&self, ray: &Ray) -> bool {
        for s in &self.spheres {
            if sphere_intersect(s, ray.origin, ray.dir, ray.tmin, ray.tmax) < ray.tmax {
                return true;
            }
        }
        if let Some(bvh) = &self.bvh {
            #[cfg(target_arch = "x86_64")]
            if self.avx2 {
                // SAFETY: the CPU supports AVX2 and FMA (checked at build time).
                return unsafe { x86::any_hit_of(bvh, &self.planes, &self.rt_tris, ray) };
            }
            let r = obvhs::ray::Ray::new(ray.origin.into(), ray.dir.into(), ray.tmin, ray.tmax);
            return any_hit(bvh, &self.rt_tris, r);
        }
        false
    }

    /// Builds the surface interaction (position, normals, UVs) of a hit.
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> SurfaceInteraction {
        match hit.prim {
            Prim::Triangle(i) => {
                let (shape, local) = self.tri_ref[i as usize];
                let mesh = self.meshes[shape as usize]
                    .as_ref()
                    .expect("triangle of a mesh shape");
                let idx = mesh.indices[local as usize];
                let [v0, v1, v2] = idx.map(|k| mesh.positions[k as usize]);
                let e1 = v1 - v0;
                let e2 = v2 - v0;
                // Barycentrics of the hit point (Möller–Trumbore), robust to the ray's tmin.
                let pvec = ray.dir.cross(e2);
                let det = e1.dot(pvec);
                let inv_det = if det != 0.0 { 1.0 / det } else { 0.0 };
                let tvec = ray.origin - v0;
                let b1 = (tvec.dot(pvec) * inv_det).clamp(0.0, 1.0);
                let qvec = tvec.cross(e1);
                let b2 = (ray.dir.dot(qvec) * inv_det).clamp(0.0, 1.0 - b1);
                let b0 = 1.0 - b1 - b2;
                let p = v0 * b0 + v1 * b1 + v2 * b2;
                let ng = e1.cross(e2).normalize();
                let mut ns = ng;
                if !mesh.normals.is_empty() {
                    let n = mesh.normals[idx[0] as usize] * b0
                        + mesh.normals[idx[1] as usize] * b1
                        + mesh.normals[idx[2] as usize] * b2;
                    let len = n.length();
                    if len > 1e-12 && len.is_finite() {
                        ns = n / len;
                    }
                }
                // Mitsuba's default parameterisation without UVs: the barycentrics, i.e.
                // vertex UVs (0, 0), (1, 0), (0, 1).
                let [t0, t1, t2] = if mesh.uvs.is_empty() {
                    [Vec2::ZERO, Vec2::X, Vec2::Y]
                } else {
                    idx.map(|k| mesh.uvs[k as usize])
                };
                let uv = if mesh.uvs.is_empty() {
                    Vec2::new(b1, b2)
                } else {
                    t0 * b0 + t1 * b1 + t2 * b2
                };
                SurfaceInteraction {
                    p,
                    t: hit.t,
                    ng,
                    shading: Frame::from_normal(ns),
                    uv,
                    dpdu: triangle_dpdu(e1, e2, t1 - t0, t2 - t0),
                    dpdv: triangle_dpdv(e1, e2, t1 - t0, t2 - t0),
                    shape,
                    color: vertex_color(mesh, idx, [b0, b1, b2]),
                    tangent: vertex_tangent(mesh, idx, [b0, b1, b2]),
                }
            }
            Prim::Sphere(i) => {
                let s = &self.spheres[i as usize];
                let p_raw = ray.origin + ray.dir * hit.t;
                let mut n = (p_raw - s.center).normalize();
                // Re-project onto the surface to curb error growth with distance.
                let p = s.center + n * s.radius;
                // Mitsuba's sphere UV: u = φ/2π, v = θ/π in the local frame (z up).
                let local = s.to_local * n;
                let phi = local.y.atan2(local.x);
                let uv = Vec2::new(
                    (phi * std::f32::consts::FRAC_1_PI * 0.5).rem_euclid(1.0),
                    local.z.clamp(-1.0, 1.0).acos() * std::f32::consts::FRAC_1_PI,
                );
                if s.flip_normals {
                    n = -n;
                }
                // Mitsuba's sphere: ∂p/∂u = 2πr (−y, x, 0) in its local frame (zero at the
                // poles), turned with the sphere (anisotropic lobes follow it).
                let dpdu = s.to_local.transpose()
                    * Vec3::new(-local.y, local.x, 0.0)
                    * (s.radius * std::f32::consts::TAU);
                let dpdv = sphere_dpdv(local, s.radius, &s.to_local);
                SurfaceInteraction {
                    p,
                    t: hit.t,
                    ng: n,
                    shading: Frame::from_normal(n),
                    uv,
                    dpdu,
                    dpdv,
                    shape: s.shape,
                    color: Vec3::ONE,
                    tangent: Vec4::ZERO,
                }
            }
        }
    }

    /// A shape's mesh, if it is one.
    pub fn mesh(&self, shape: u32) -> Option<&TriangleMesh> {
        self.meshes.get(shape as usize).and_then(|m| m.as_deref())
    }
}

/// The barycentric blend `b` of triangle `idx`'s vertex colours (white without colours).
#[inline]
fn vertex_color(mesh: &TriangleMesh, idx: [u32; 3], b: [f32; 3]) -> Vec3 {
    if mesh.colors.is_empty() {
        return Vec3::ONE;
    }
    let [c0, c1, c2] = idx.map(|k| mesh.colors[k as usize]);
    c0 * b[0] + c1 * b[1] + c2 * b[2]
}

/// The barycentric blend `b` of triangle `idx`'s vertex tangents (xyz; w the first vertex's
/// bitangent sign), zero without tangents.
#[inline]
fn vertex_tangent(mesh: &TriangleMesh, idx: [u32; 3], b: [f32; 3]) -> Vec4 {
    if mesh.tangents.is_empty() {
        return Vec4::ZERO;
    }
    let [t0, t1, t2] = idx.map(|k| mesh.tangents[k as usize]);
    (t0.truncate() * b[0] + t1.truncate() * b[1] + t2.truncate() * b[2]).extend(t0.w)
}

/// A triangle of the scene: (shape, triangle index within the shape's mesh).
type TriRef = (u32, u32);

/// The scene's triangles that can be hit, as references into its meshes, its spheres, and
/// how many triangles were dropped (degenerate, non-finite or repeated); errors name the
/// mesh whose normals, uvs or indices do not fit its vertices.
fn collect_triangles(scene: &Scene) -> anyhow::Result<(Vec<TriRef>, Vec<SphereGeom>, usize)> {
    use rayon::prelude::*;
    // Hittable triangles with their repeat key, in scene order (shape, then index): checked
    // in parallel, one chunk of a mesh per task.
    let mut candidates: Vec<(TriRef, u64)> = Vec::new();
    let mut spheres = Vec::new();
    let mut n_tris = 0usize;
    for (si, shape) in scene.shapes.iter().enumerate() {
        match &shape.geometry {
            Geometry::Mesh(m) => {
                check_mesh(m, shape.name.as_deref().unwrap_or("<unnamed>"), si)?;
                n_tris += m.indices.len();
                let hittable = (m.indices.par_iter().enumerate()).filter_map(|(ti, idx)| {
                    let [a, b, c] = idx.map(|i| m.positions[i as usize]);
                    let area2 = (b - a).cross(c - a).length();
                    let finite = a.is_finite() && b.is_finite() && c.is_finite();
                    (finite && area2 > 0.0 && area2.is_finite())
                        .then(|| ((si as u32, ti as u32), repeat_hash(&repeat_key([a, b, c]))))
                });
                candidates.par_extend(hittable);
            }
            Geometry::Sphere {
                center,
                radius,
                rotation,
                flip_normals,
            } => {
                if !(center.is_finite() && radius.is_finite() && *radius > 0.0) {
                    anyhow::bail!("sphere shape {si}: radius must be finite and > 0, got {radius}");
                }
                spheres.push(SphereGeom {
                    center: *center,
                    radius: *radius,
                    to_local: rotation.transpose(),
                    flip_normals: *flip_normals,
                    shape: si as u32,
                });
            }
        }
    }
    let vertices = |&(s, t): &TriRef| match &scene.shapes[s as usize].geometry {
        Geometry::Mesh(m) => m.indices[t as usize].map(|i| m.positions[i as usize]),
        Geometry::Sphere { .. } => unreachable!("candidates are mesh triangles"),
    };
    let repeated = repeats(&candidates, |k| repeat_key(vertices(&candidates[k].0)));
    // Exact capacity: for millions of triangles a doubling Vec's spare half was ~100 MB of
    // the peak.
    let kept = candidates.len() - repeated.iter().filter(|&&r| r).count();
    let mut tri_ref = Vec::with_capacity(kept);
    tri_ref.extend((candidates.iter().zip(&repeated)).filter_map(|(c, &r)| (!r).then_some(c.0)));
    Ok((tri_ref, spheres, n_tris - kept))
}

/// A triangle's vertices as bit patterns, in a fixed order: equal for the same triangle
/// listed with its vertices in any order (a repeat), different for any other triangle.
fn repeat_key(v: [Vec3; 3]) -> [[u32; 3]; 3] {
    let mut k = v.map(|p| p.to_array().map(f32::to_bits));
    k.sort_unstable();
    k
}

/// FNV-1a over a [`repeat_key`]'s 36 bytes: a sort key only; equal hashes are compared in full.
fn repeat_hash(k: &[[u32; 3]; 3]) -> u64 {
    (k.iter().flatten()).fold(0xcbf2_9ce4_8422_2325u64, |h, &w| {
        (h ^ w as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Which of `items` (anything, with a [`repeat_hash`] each, in scene order) repeat an
/// earlier item: exact repeats of a triangle already kept (a polygon fan over three
/// vertices, a glTF primitive listed 20 000 times, an instance placed twice at one spot). A
/// copy adds nothing a ray could see, and PLOC pairs identical boxes one merge per pass:
/// 20 000 copies took 15 s of CPU to build (quadratic). They are dropped like degenerate
/// triangles; the first of each group is kept.
///
/// Sorting (hash, position) pairs finds them in O(n log n) on all cores with 16 bytes per
/// triangle; the hash map this replaced probed memory at random (0.6 s and 71 MB for 2M
/// triangles). `key(i)` gives item i's full key: items whose hashes collide are compared in full.
fn repeats<T: Sync>(items: &[(T, u64)], key: impl Fn(usize) -> [[u32; 3]; 3]) -> Vec<bool> {
    use rayon::prelude::*;
    let mut order: Vec<(u64, u32)> = (items.par_iter().enumerate())
        .map(|(i, (_, h))| (*h, i as u32))
        .collect();
    order.par_sort_unstable();
    let mut repeated = vec![false; items.len()];
    for run in order.chunk_by(|a, b| a.0 == b.0).filter(|r| r.len() > 1) {
        // Within a run, positions ascend: each item is compared with the kept ones before it.
        let mut kept: Vec<[[u32; 3]; 3]> = Vec::new();
        for &(_, i) in run {
            let k = key(i as usize);
            if kept.contains(&k) {
                repeated[i as usize] = true;
            } else {
                kept.push(k);
            }
        }
    }
    repeated
}

/// Normals, uvs and colours per vertex (or none), indices within the vertices.
fn check_mesh(m: &TriangleMesh, name: &str, si: usize) -> anyhow::Result<()> {
    if !m.normals.is_empty() && m.normals.len() != m.positions.len() {
        anyhow::bail!(
            "mesh '{name}' (shape {si}): {} normals for {} vertices",
            m.normals.len(),
            m.positions.len()
        );
    }
    if !m.uvs.is_empty() && m.uvs.len() != m.positions.len() {
        anyhow::bail!(
            "mesh '{name}' (shape {si}): {} uvs for {} vertices",
            m.uvs.len(),
            m.positions.len()
        );
    }
    if !m.tangents.is_empty() && m.tangents.len() != m.positions.len() {
        anyhow::bail!(
            "mesh '{name}' (shape {si}): {} tangents for {} vertices",
            m.tangents.len(),
            m.positions.len()
        );
    }
    if !m.colors.is_empty() && m.colors.len() != m.positions.len() {
        anyhow::bail!(
            "mesh '{name}' (shape {si}): {} vertex colours for {} vertices",
            m.colors.len(),
            m.positions.len()
        );
    }
    if let Some((ti, idx)) = (m.indices.iter().enumerate())
        .find(|(_, idx)| idx.iter().any(|&i| i as usize >= m.positions.len()))
    {
        anyhow::bail!(
            "mesh '{name}' (shape {si}): triangle {ti} indexes vertex {:?} but the mesh has {} vertices",
            idx,
            m.positions.len()
        );
    }
    Ok(())
}

/// The scene's hittable triangles in scene order, before the BVH orders them.
pub struct SceneTriangles<'a> {
    scene: &'a Scene,
    tri_ref: &'a [TriRef],
}

impl SceneTriangles<'_> {
    /// How many triangles there are.
    pub fn count(&self) -> usize {
        self.tri_ref.len()
    }

    /// The vertices of triangle `i` (scene order).
    #[inline]
    pub fn vertices(&self, i: u32) -> [Vec3; 3] {
        self.vertices_of(&self.tri_ref[i as usize])
    }

    #[inline]
    fn vertices_of(&self, &(shape, local): &TriRef) -> [Vec3; 3] {
        match &self.scene.shapes[shape as usize].geometry {
            Geometry::Mesh(m) => m.indices[local as usize].map(|k| m.positions[k as usize]),
            Geometry::Sphere { .. } => unreachable!("triangle references point into meshes"),
        }
    }
}

/// The CWBVH over `tris` (vertices through `vertices`): obvhs' `build_cwbvh` steps (PLOC,
/// reinsertion, conversion) with less held at once. PLOC starts from leaves made straight
/// from the triangles (no array of build boxes beside them), and the BVH2's parent links are
/// freed before the conversion, whose cost table (7 entries per BVH2 node) is the peak of the
/// build. `slow_build` splits triangles (pre-split) and goes through obvhs' own builder on
/// the triangles. The boxes are those of obvhs' `Triangle::aabb`, so the BVH is the one
/// obvhs builds from the triangles (test `reference_build_equals_obvhs_triangle_build`).
fn build_bvh(
    tris: &[TriRef],
    vertices: impl Fn(&TriRef) -> [Vec3; 3],
    effort: BuildEffort,
) -> CwBvh {
    let params = effort.params;
    use obvhs::aabb::Aabb;
    use obvhs::ploc::PlocSearchDistance as D;
    let plain_box = |i: usize| Aabb::from_points(&vertices(&tris[i]).map(Into::into));
    let tied = boxes_tie(tris.len(), plain_box);
    let build_box = |i: usize| {
        let b = plain_box(i);
        if tied {
            widen_box(b, i)
        } else {
            b
        }
    };
    if params.pre_split && !tied {
        let tris: Vec<Triangle> = (tris.iter())
            .map(|r| {
                let [a, b, c] = vertices(r);
                Triangle {
                    v0: a.into(),
                    v1: b.into(),
                    v2: c.into(),
                }
            })
            .collect();
        let mut time = std::time::Duration::default();
        let mut bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, params, &mut time);
        bvh.nodes.shrink_to_fit();
        return bvh;
    }
    // obvhs `PlocBuilder::build_ploc`, with the leaves made here.
    let n = tris.len();
    let mut ploc = obvhs::ploc::PlocBuilder::with_capacity(n);
    let mut bvh2 = obvhs::bvh2::Bvh2::zeroed(n);
    bvh2.reset_for_reuse(n, Some((0..n as u32).collect()));
    let mut total = Aabb::empty();
    for (i, node) in ploc.current_nodes.iter_mut().enumerate() {
        let b = build_box(i);
        total.extend(b.min);
        total.extend(b.max);
        *node = obvhs::bvh2::node::Bvh2Node::new(b, 1, i as u32);
    }
    let (precision, depth) = (params.sort_precision, params.search_depth_threshold);
    let b = &mut bvh2;
    match params.ploc_search_distance {
        D::Minimum => ploc.build_ploc_from_leaves::<1, false>(b, total, precision, depth),
        D::VeryLow => ploc.build_ploc_from_leaves::<2, false>(b, total, precision, depth),
        D::Low => ploc.build_ploc_from_leaves::<6, false>(b, total, precision, depth),
        D::Medium => ploc.build_ploc_from_leaves::<14, false>(b, total, precision, depth),
        D::High => ploc.build_ploc_from_leaves::<24, false>(b, total, precision, depth),
        D::VeryHigh => ploc.build_ploc_from_leaves::<32, false>(b, total, precision, depth),
    }
    drop(ploc);
    obvhs::bvh2::reinsertion::ReinsertionOptimizer::default().run(
        &mut bvh2,
        params.reinsertion_batch_ratio,
        None,
    );
    bvh2.parents = Vec::new();
    let mut bvh = match effort.conversion {
        Conversion::Sah => super::bvh_sah::convert(&bvh2, params.max_prims_per_leaf.clamp(1, 3)),
        Conversion::Greedy => super::bvh_collapse::collapse(&bvh2),
    };
    // The node array was reserved at one node per triangle (80 bytes each); ~1/8 is used.
    bvh.nodes.shrink_to_fit();
    bvh
}

/// Whether many distinct triangles share one build box (a hostile input: e.g. triangles
/// spanning one box's diagonal): at least 1/64 of a strided sample of the `n` boxes
/// (`box_of(i)`) repeats another. obvhs' PLOC merges only mutual nearest neighbours; equal
/// boxes tie on every merge cost, and a run of ties merges one pair per pass, so such a mesh
/// builds in O(n²) (60 000 triangles with one box: 33 s of CPU). Then [`widen_box`] breaks
/// the ties.
fn boxes_tie(n: usize, box_of: impl Fn(usize) -> obvhs::aabb::Aabb) -> bool {
    const SAMPLE: usize = 8192;
    let key = |b: &obvhs::aabb::Aabb| {
        let (lo, hi) = (b.min.to_array(), b.max.to_array());
        [lo, hi].map(|v| v.map(f32::to_bits))
    };
    let stride = n.div_ceil(SAMPLE).max(1);
    let mut seen = std::collections::HashSet::new();
    let (mut sampled, mut repeats) = (0usize, 0usize);
    for i in (0..n).step_by(stride) {
        sampled += 1;
        repeats += usize::from(!seen.insert(key(&box_of(i))));
    }
    repeats * 64 >= sampled
}

/// Box `b` of triangle `i` widened by a tiny amount that differs per triangle, which breaks
/// PLOC's ties (see [`boxes_tie`]). The box stays conservative, so the hits do not change
/// (closest hit, ties to the smaller triangle id).
fn widen_box(b: obvhs::aabb::Aabb, i: usize) -> obvhs::aabb::Aabb {
    // A per-triangle fraction in [0, 1) from the index (Knuth's multiplicative hash).
    let u = (i as u32).wrapping_mul(2_654_435_761) as f32 / 4_294_967_296.0;
    let pad = (b.max - b.min).max_element().max(1e-6) * 1e-5 * (1.0 + u);
    obvhs::aabb::Aabb {
        min: b.min - pad,
        max: b.max + pad,
    }
}

/// How much work the BVH build does: obvhs' parameters, and how the BVH2 becomes the
/// 8-wide CWBVH the renderer traverses.
#[derive(Debug, Clone, Copy)]
struct BuildEffort {
    params: obvhs::BvhBuildParams,
    conversion: Conversion,
}

/// How the BVH2 becomes a CWBVH.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Conversion {
    /// obvhs' converter ([`super::bvh_sah`]: its output, ordered faster): children chosen by
    /// SAH dynamic programming and ordered by octant.
    Sah,
    /// [`super::bvh_collapse`]: open the largest child, no cost table, no ordering.
    Greedy,
}

/// BVH build effort for `tris` triangles and `samples` camera samples. obvhs' slow_build
/// (pre-split, wider PLOC search, more reinsertion) took ~25 ms more than medium_build on
/// the 36k-triangle teapot, on the render's critical path, and rendered no faster: one thread,
/// 256², 64 spp (114 samples per triangle), six alternating runs, CPU s slow / medium:
/// diffuse 2.07 / 1.93, thin film 0.81 / 0.82, gold 0.88 / 0.87 (medians); at 256 spp
/// diffuse 6.27 / 6.27, thin film 2.82 / 2.89. It is kept for renders of more than 1024
/// samples per triangle, whose build is a small part of them whatever it costs. Its
/// reinsertion pass grows faster than the triangle count (2M-triangle sphere: 4.3 s of CPU
/// against 1.9 s for the whole render with fast_build at 256², 4 spp). Below two samples per
/// triangle the children are not ordered either: the ordering (then obvhs' own, a fifth of
/// the conversion; with [`super::bvh_sah`]'s the 36k teapot converts in 8 ms, not 28) saved
/// less render time than it cost (2M-triangle sphere, 256², 4 spp: 1.93–2.24 s of CPU for
/// the whole render without, 2.24–2.44 s with), and the SAH conversion's cost table is the
/// build's peak memory ([`super::bvh_collapse`]). A closest hit does not depend on the BVH
/// except at exact ties (smaller id in BVH order), so this trades time, not images.
fn build_effort(samples: u64, tris: usize) -> BuildEffort {
    let per_tri = samples as f64 / tris.max(1) as f64;
    let params = if per_tri >= 1024.0 {
        obvhs::BvhBuildParams::slow_build()
    } else if per_tri >= 2.0 {
        obvhs::BvhBuildParams::medium_build()
    } else {
        obvhs::BvhBuildParams::fast_build()
    };
    BuildEffort {
        params,
        conversion: if per_tri >= 2.0 {
            Conversion::Sah
        } else {
            Conversion::Greedy
        },
    }
}

/// Closest triangle hit: obvhs' CWBVH traversal (its `traverse!` macro, as in
/// `CwBvh::ray_traverse`) with the triangle test inlined into the loop (through
/// `ray_traverse`'s closure it was an out-of-line call per candidate triangle).
#[inline]
fn closest_hit(bvh: &CwBvh, tris: &[RtTriangle], ray: obvhs::ray::Ray) -> Option<(f32, u32)> {
    use glam::UVec2;
    let mut traverse_ray = ray;
    let mut best_id = u32::MAX;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    obvhs::traverse!(
        bvh,
        node,
        state,
        node.intersect_ray(&traverse_ray, state.oct_inv4),
        {
            let t = intersect_triangle(&tris[state.primitive_id as usize], &traverse_ray);
            if closer(t, state.primitive_id, traverse_ray.tmax, best_id) {
                best_id = state.primitive_id;
                traverse_ray.tmax = t;
            }
        }
    );
    (best_id != u32::MAX).then_some((traverse_ray.tmax, best_id))
}

/// Whether a triangle hit at `t` with id `id` replaces the closest hit so far (`best_t`,
/// `best_id`; `u32::MAX` before the first). Equal distances go to the smaller id, so the
/// closest hit does not depend on the order triangles are tested in: a packet traversal
/// ([`Accel::intersect_batch`]) and the single-ray one agree even on a ray through an edge
/// two triangles share.
#[inline(always)]
fn closer(t: f32, id: u32, best_t: f32, best_id: u32) -> bool {
    t < best_t || (t == best_t && best_id != u32::MAX && id < best_id)
}

/// Ray–triangle distance, or +inf: obvhs's `RtTriangle::intersect` (Möller–Trumbore on
/// precomputed edges) except that the barycentric test is `≥ 0` instead of a sign-bit test.
/// The sign-bit test rejects −0.0, so a ray exactly on the edge two triangles share (the
/// centre of a two-triangle rectangle seen straight on) missed both; here it hits one.
#[inline(always)]
fn intersect_triangle(tri: &RtTriangle, ray: &obvhs::ray::Ray) -> f32 {
    triangle_distance(
        &TriScalars::of(tri),
        [ray.origin.x, ray.origin.y, ray.origin.z],
        [ray.direction.x, ray.direction.y, ray.direction.z],
        ray.tmin,
        ray.tmax,
    )
}

/// A triangle's precomputed vectors as plain scalars (for [`triangle_distance`]).
#[derive(Clone, Copy)]
struct TriScalars {
    v0: [f32; 3],
    e1: [f32; 3],
    e2: [f32; 3],
    ng: [f32; 3],
}

impl TriScalars {
    #[inline(always)]
    fn of(t: &RtTriangle) -> Self {
        let a = |v: glam::Vec3A| [v.x, v.y, v.z];
        TriScalars {
            v0: a(t.v0),
            e1: a(t.e1),
            e2: a(t.e2),
            ng: a(t.ng),
        }
    }
}

/// Up to [`PACKET`] triangles in struct-of-arrays form (lane i: triangle i of the group;
/// lanes from `count` on are zero and never read).
#[derive(Debug, Clone)]
struct TriLanes {
    v0: [[f32; PACKET]; 3],
    e1: [[f32; PACKET]; 3],
    e2: [[f32; PACKET]; 3],
    ng: [[f32; PACKET]; 3],
    count: usize,
}

impl TriLanes {
    fn of(tris: &[RtTriangle]) -> Self {
        let mut lanes = TriLanes {
            v0: [[0.0; PACKET]; 3],
            e1: [[0.0; PACKET]; 3],
            e2: [[0.0; PACKET]; 3],
            ng: [[0.0; PACKET]; 3],
            count: tris.len().min(PACKET),
        };
        for (i, t) in tris.iter().take(PACKET).enumerate() {
            let s = TriScalars::of(t);
            for k in 0..3 {
                lanes.v0[k][i] = s.v0[k];
                lanes.e1[k][i] = s.e1[k];
                lanes.e2[k][i] = s.e2[k];
                lanes.ng[k][i] = s.ng[k];
            }
        }
        lanes
    }

    /// [`triangle_distance`] of one ray to every lane's triangle.
    #[inline]
    fn distances(&self, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> [f32; PACKET] {
        let mut t = [0.0f32; PACKET];
        for (i, ti) in t.iter_mut().enumerate() {
            let lane = |v: &[[f32; PACKET]; 3]| [v[0][i], v[1][i], v[2][i]];
            let tri = TriScalars {
                v0: lane(&self.v0),
                e1: lane(&self.e1),
                e2: lane(&self.e2),
                ng: lane(&self.ng),
            };
            *ti = triangle_distance(&tri, o, d, tmin, tmax);
        }
        t
    }
}

/// The ray–triangle test written out in scalar operations, branch-free, so that the single-ray
/// test and the packet test ([`TriScalars`] against [`PACKET`] rays in SIMD lanes) are the
/// same IEEE operations in the same order: a ray's distance is bit-identical either way.
#[inline(always)]
fn triangle_distance(tri: &TriScalars, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> f32 {
    let c = [tri.v0[0] - o[0], tri.v0[1] - o[1], tri.v0[2] - o[2]];
    // r = d × c
    let r = [
        d[1] * c[2] - d[2] * c[1],
        d[2] * c[0] - d[0] * c[2],
        d[0] * c[1] - d[1] * c[0],
    ];
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let inv_det = 1.0 / dot(tri.ng, d);
    let u = dot(r, tri.e2) * inv_det;
    let v = dot(r, tri.e1) * inv_det;
    let w = 1.0 - u - v;
    let t = dot(tri.ng, c) * inv_det;
    let hit = inv_det != 0.0 && u >= 0.0 && v >= 0.0 && w >= 0.0 && t >= tmin && t <= tmax;
    if hit {
        t
    } else {
        f32::INFINITY
    }
}

/// Up to [`PACKET`] rays in struct-of-arrays form (lane i: ray i; unused lanes repeat ray 0).
#[derive(Clone, Copy)]
pub(super) struct RayLanes {
    o: [[f32; PACKET]; 3],
    d: [[f32; PACKET]; 3],
    tmin: [f32; PACKET],
    tmax: [f32; PACKET],
}

impl RayLanes {
    /// Lanes of rays sharing `origin`, given lane-wise.
    #[inline]
    pub(super) fn from_lanes(
        origin: Vec3,
        dir: &[[f32; PACKET]; 3],
        tmin: &[f32; PACKET],
        tmax: &[f32; PACKET],
    ) -> Self {
        RayLanes {
            o: [[origin.x; PACKET], [origin.y; PACKET], [origin.z; PACKET]],
            d: *dir,
            tmin: *tmin,
            tmax: *tmax,
        }
    }

    /// Lane i's closest distance so far (its ray's tmax until a hit).
    #[inline(always)]
    pub(super) fn tmax(&self, i: usize) -> f32 {
        self.tmax[i]
    }

    /// Lanes of up to [`PACKET`] rays (unused lanes repeat ray 0).
    fn of_rays(rays: &[Ray]) -> Self {
        Self::from_parts(rays.len(), |i| {
            let r = &rays[i];
            (r.origin.to_array(), r.dir.to_array(), r.tmin, r.tmax)
        })
    }

    /// Lanes of `n` ≥ 1 rays, ray i given as (origin, direction, tmin, tmax); lanes past
    /// `n` (up to [`PACKET`]) repeat ray 0.
    #[inline(always)]
    fn from_parts(n: usize, ray: impl Fn(usize) -> ([f32; 3], [f32; 3], f32, f32)) -> Self {
        let mut l = RayLanes {
            o: [[0.0; PACKET]; 3],
            d: [[0.0; PACKET]; 3],
            tmin: [0.0; PACKET],
            tmax: [0.0; PACKET],
        };
        for i in 0..PACKET {
            let (o, d, tmin, tmax) = ray(if i < n { i } else { 0 });
            for k in 0..3 {
                l.o[k][i] = o[k];
                l.d[k][i] = d[k];
            }
            l.tmin[i] = tmin;
            l.tmax[i] = tmax;
        }
        l
    }

    /// Marks the lanes whose segment (tmin, tmax) `tri` blocks (the any-hit test `t < tmax`
    /// of [`any_hit`]): in `sure` where the BVH is sure to find the blocker too (at least
    /// [`NEAR_HIT`] away), in `unsure` otherwise.
    #[inline(always)]
    fn blocked_by(&self, tri: &TriScalars, sure: &mut [bool; PACKET], unsure: &mut [bool; PACKET]) {
        for i in 0..PACKET {
            let t = triangle_distance(
                tri,
                [self.o[0][i], self.o[1][i], self.o[2][i]],
                [self.d[0][i], self.d[1][i], self.d[2][i]],
                self.tmin[i],
                self.tmax[i],
            );
            let hit = t < self.tmax[i];
            sure[i] |= hit && t >= NEAR_HIT;
            unsure[i] |= hit && t < NEAR_HIT;
        }
    }

    fn new(rays: &[obvhs::ray::Ray]) -> Self {
        Self::from_parts(rays.len(), |i| {
            let r = &rays[i];
            (r.origin.to_array(), r.direction.to_array(), r.tmin, r.tmax)
        })
    }

    /// [`triangle_distance`] of every lane, then the [`closer`] update of each lane's
    /// closest hit (`best`: triangle ids, distances in `tmax`); plain loops over the lanes
    /// that compile to SIMD.
    #[inline(always)]
    fn test_triangle(&mut self, tri: &TriScalars, id: u32, best: &mut [u32; PACKET]) {
        let mut t = [0.0f32; PACKET];
        for (i, ti) in t.iter_mut().enumerate() {
            *ti = triangle_distance(
                tri,
                [self.o[0][i], self.o[1][i], self.o[2][i]],
                [self.d[0][i], self.d[1][i], self.d[2][i]],
                self.tmin[i],
                self.tmax[i],
            );
        }
        for i in 0..PACKET {
            let c = closer(t[i], id, self.tmax[i], best[i]);
            best[i] = if c { id } else { best[i] };
            self.tmax[i] = if c { t[i] } else { self.tmax[i] };
        }
    }
}

/// True if any triangle is hit (shadow rays: stops at the first hit).
#[inline]
fn any_hit(bvh: &CwBvh, tris: &[RtTriangle], ray: obvhs::ray::Ray) -> bool {
    use glam::UVec2;
    let mut hit = false;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    'outer: {
        obvhs::traverse!(
            bvh,
            node,
            state,
            node.intersect_ray(&ray, state.oct_inv4),
            {
                if intersect_triangle(&tris[state.primitive_id as usize], &ray) < ray.tmax {
                    hit = true;
                    break 'outer;
                }
            }
        );
    }
    hit
}

/// One CWBVH node's eight child boxes as f32 planes, in the node's slot order: rows min x,
/// max x, min y, max y, min z, max z (the order of `CwBvhNode`'s quantised planes). obvhs
/// stores each plane as a byte, q, scaled from the node's origin p by a power of two, e; the
/// node test then widens 48 bytes and rescales the ray per node. Decoded once here (p + q·e,
/// rounded outwards to f32, so each box still contains the quantised one), the test is one
/// fused multiply-add per plane with per-ray constants (~30 instructions fewer per node), for
/// 192 more bytes per node (three cache lines, aligned).
///
/// That pays while the planes stay in cache: on incoherent rays (one thread) 10–18 % less
/// time per ray from 992 to 102k triangles (2 MB of planes), on par at 313k (6 MB), slower
/// at 999k (19 MB: 10–20 % more per closest hit). Above [`PLANES_MAX_BYTES`] the traversal
/// keeps the quantised planes (docs/performance.md, "Ninth round").
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct ChildPlanes([[f32; 8]; 6]);

/// The largest BVH, in bytes of [`ChildPlanes`], whose nodes are tested on f32 planes
/// (~20k nodes, ~200k triangles; between the measured 2 MB that gained and 6 MB that did not).
const PLANES_MAX_BYTES: usize = 4 << 20;

impl ChildPlanes {
    /// The planes of every node of `bvh`, or none if they would take more than
    /// [`PLANES_MAX_BYTES`].
    fn for_bvh(bvh: &CwBvh) -> Vec<Self> {
        if bvh.nodes.len() * std::mem::size_of::<Self>() > PLANES_MAX_BYTES {
            return Vec::new();
        }
        Self::of(bvh)
    }

    fn of(bvh: &CwBvh) -> Vec<Self> {
        use rayon::prelude::*;
        let decode = |n: &obvhs::cwbvh::node::CwBvhNode| {
            let ext = n.compute_extent();
            let rows = [
                (&n.child_min_x, n.p.x, ext.x, false),
                (&n.child_max_x, n.p.x, ext.x, true),
                (&n.child_min_y, n.p.y, ext.y, false),
                (&n.child_max_y, n.p.y, ext.y, true),
                (&n.child_min_z, n.p.z, ext.z, false),
                (&n.child_max_z, n.p.z, ext.z, true),
            ];
            ChildPlanes(rows.map(|(q, p, e, up)| {
                q.map(|q| {
                    // Exact in f64 (an f32 plus a byte times a power of two), then rounded
                    // towards the outside of the box.
                    let exact = p as f64 + q as f64 * e as f64;
                    let f = exact as f32;
                    if (up && (f as f64) < exact) || (!up && (f as f64) > exact) {
                        next_f32(f, up)
                    } else {
                        f
                    }
                })
            }))
        };
        bvh.nodes.par_iter().map(decode).collect()
    }
}

/// The f32 next to finite `f` upwards (`up`) or downwards (`f32::next_up`/`next_down`, not
/// in the minimum Rust version).
fn next_f32(f: f32, up: bool) -> f32 {
    if f == 0.0 {
        let tiny = f32::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let bits = f.to_bits();
    // Away from zero is one more in the magnitude bits, towards zero one less.
    f32::from_bits(if (f > 0.0) == up { bits + 1 } else { bits - 1 })
}

/// Whether the AVX2 traversal can run: AVX2, FMA, POPCNT and LZCNT (every AVX2 CPU has the
/// other three; checked all the same).
fn cpu_has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("popcnt")
            && std::arch::is_x86_feature_detected!("lzcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The same traversals compiled for AVX2 and FMA (runtime-detected; the release build
/// targets baseline x86-64): the CWBVH node test does all eight children in one 256-bit
/// register, on the node's [`ChildPlanes`] where the BVH has them (its quantised boxes
/// decoded to f32 once, rounded outwards), else on the quantised bytes with obvhs'
/// arithmetic. On f32 planes a node may be entered where obvhs' test rounds the other way at
/// a box's face, never skipped where a triangle in it is hit; the traversal order and the
/// triangle test are obvhs', so the hits are the baseline path's either way
/// (`tests::avx2_traversal_matches_baseline`, `child_planes_contain_what_their_slots_hold`).
#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{
        closer, intersect_triangle, ChildPlanes, RayLanes, RtTriangle, TriScalars, PACKET,
    };
    use obvhs::cwbvh::node::CwBvhNode;
    use obvhs::cwbvh::CwBvh;
    use obvhs::ray::Ray;
    use std::arch::x86_64::*;

    /// obvhs' node-test epsilon (`cwbvh::node::EPSILON`, crate-private there).
    const NODE_EPSILON: f32 = 0.0001;

    /// Per-ray constants of the node test: for each axis, the inverse direction and
    /// −origin × inverse direction in all lanes (a plane at x is crossed at
    /// t = x·inv + (−o·inv)), which [`ChildPlanes`] rows hold the planes the ray meets first
    /// and last (min then max where the direction component is non-negative), and the byte
    /// offsets of the same planes among a [`CwBvhNode`]'s quantised ones.
    #[derive(Clone, Copy)]
    struct RayPlanes {
        inv: [__m256; 3],
        neg_o_inv: [__m256; 3],
        near: [usize; 3],
        far: [usize; 3],
        quantised_near: [usize; 3],
        quantised_far: [usize; 3],
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn ray_planes(ray: &Ray) -> RayPlanes {
        let (o, inv) = (ray.origin.to_array(), ray.inv_direction.to_array());
        let neg = ray.direction.to_array().map(|d| d < 0.0);
        let near = std::array::from_fn(|k| 2 * k + usize::from(neg[k]));
        let far = std::array::from_fn(|k| 2 * k + 1 - usize::from(neg[k]));
        // The quantised rows are eight bytes each, in the same order, from `child_min_x`.
        let quantised = |row: usize| std::mem::offset_of!(CwBvhNode, child_min_x) + 8 * row;
        RayPlanes {
            inv: inv.map(|v| _mm256_set1_ps(v)),
            neg_o_inv: std::array::from_fn(|k| _mm256_set1_ps(-(o[k] * inv[k]))),
            near,
            far,
            quantised_near: near.map(quantised),
            quantised_far: far.map(quantised),
        }
    }

    /// Which of a node's eight child slots the ray's slab test hits (bit j: slot j): on the
    /// node's f32 planes where the BVH has them ([`ChildPlanes::for_bvh`]: `planes` is empty
    /// otherwise), else on its quantised ones.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn child_slots(
        node: &CwBvhNode,
        index: usize,
        planes: &[ChildPlanes],
        ray: &Ray,
        ray_planes: &RayPlanes,
        ray_tmax: f32,
    ) -> u32 {
        match planes.get(index) {
            Some(planes) => float_slots(planes, ray_planes, ray_tmax),
            None => quantised_slots(node, ray, ray_planes, ray_tmax),
        }
    }

    /// [`child_slots`] on f32 planes: one fused multiply-add per plane.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn float_slots(planes: &ChildPlanes, ray: &RayPlanes, ray_tmax: f32) -> u32 {
        let cross = |row: usize, axis: usize| {
            // SAFETY: `row` < 6 (see `ray_planes`); rows are 32-byte aligned 8-float arrays.
            let plane = unsafe { _mm256_load_ps(planes.0.get_unchecked(row).as_ptr()) };
            _mm256_fmadd_ps(plane, ray.inv[axis], ray.neg_o_inv[axis])
        };
        let near = std::array::from_fn(|k| cross(ray.near[k], k));
        let far = std::array::from_fn(|k| cross(ray.far[k], k));
        overlapping_slots(near, far, ray_tmax)
    }

    /// The slots whose slab interval, from the latest of the `near` crossings to the
    /// earliest `far` one (per axis x, y, z), overlaps [`NODE_EPSILON`, `ray_tmax`]: obvhs'
    /// reduction order (the crossings are finite, so max/min are exact in any order).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn overlapping_slots(near: [__m256; 3], far: [__m256; 3], ray_tmax: f32) -> u32 {
        let tmin = _mm256_max_ps(near[0], _mm256_max_ps(near[1], near[2]));
        let tmax = _mm256_min_ps(far[0], _mm256_min_ps(far[1], far[2]));
        let tmin = _mm256_max_ps(tmin, _mm256_set1_ps(NODE_EPSILON));
        let tmax = _mm256_min_ps(tmax, _mm256_set1_ps(ray_tmax));
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(tmin, tmax)) as u32
    }

    /// [`child_slots`] on the quantised planes: obvhs' `intersect_ray_simd` arithmetic
    /// operation for operation (the ray moved into the node's byte grid, mul then add, the
    /// same max/min order, no FMA), so the same slots as obvhs' node test, with all eight
    /// children in one register and each near and far plane widened straight from the node
    /// at the ray's offsets.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn quantised_slots(node: &CwBvhNode, ray: &Ray, planes: &RayPlanes, ray_tmax: f32) -> u32 {
        let adj_dir_inv = node.compute_extent() * ray.inv_direction;
        let adj_orig = (glam::Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
        let base = node as *const CwBvhNode as *const u8;
        let widen = |offset: usize| {
            // SAFETY: `offset` starts one of the node's `[u8; 8]` plane rows (`ray_planes`).
            unsafe {
                _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(
                    base.add(offset) as *const __m128i
                )))
            }
        };
        let slab = |axis: usize, dinv: f32, orig: f32| {
            let (d, o) = (_mm256_set1_ps(dinv), _mm256_set1_ps(orig));
            let near = widen(planes.quantised_near[axis]);
            let far = widen(planes.quantised_far[axis]);
            (
                _mm256_add_ps(_mm256_mul_ps(near, d), o),
                _mm256_add_ps(_mm256_mul_ps(far, d), o),
            )
        };
        let (tmin_x, tmax_x) = slab(0, adj_dir_inv.x, adj_orig.x);
        let (tmin_y, tmax_y) = slab(1, adj_dir_inv.y, adj_orig.y);
        let (tmin_z, tmax_z) = slab(2, adj_dir_inv.z, adj_orig.z);
        overlapping_slots([tmin_x, tmin_y, tmin_z], [tmax_x, tmax_y, tmax_z], ray_tmax)
    }

    /// obvhs' node hit mask (child node bits in the high byte in traversal order, leaf
    /// primitive bits below) from the hit slots.
    #[inline]
    #[target_feature(enable = "avx2,popcnt,lzcnt")]
    fn slot_hit_bits(node: &CwBvhNode, mut slots: u32, oct_inv4: u32) -> u32 {
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        while slots != 0 {
            let j = slots.trailing_zeros();
            slots &= slots - 1;
            let child_bits = ((child_bits8 >> (j * 8)) as u32) & 0xff;
            let bit_index = ((bit_index8 >> (j * 8)) as u32) & 0xff;
            hit_mask |= child_bits << bit_index;
        }
        hit_mask
    }

    #[inline]
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    fn node_hits(
        (node, index): (&CwBvhNode, usize),
        planes: &[ChildPlanes],
        (ray, ray_planes): (&Ray, &RayPlanes),
        ray_tmax: f32,
        oct_inv4: u32,
    ) -> u32 {
        let slots = child_slots(node, index, planes, ray, ray_planes, ray_tmax);
        slot_hit_bits(node, slots, oct_inv4)
    }

    /// CWBVH traversal with the AVX2 node test: obvhs' `traverse!` macro step for step (same
    /// child and primitive visiting order, same saturating 32-entry stack), so the hits are
    /// its hits, but written as one tight loop: the traversal state stays in registers
    /// (through the macro's `Traversal` struct it lived on the stack and was stored back on
    /// every step), the stack is not zeroed per ray, and the bit counts compile to single
    /// `popcnt`/`lzcnt` instructions (enabled together with AVX2: every AVX2 CPU has them,
    /// and [`super::cpu_has_avx2`] checks all of them).
    ///
    /// `node_mask(state, node, index)` is the node test (obvhs' hit mask for octant `oct_inv4`);
    /// `on_prim(state, id)` tests primitive `id`, may shorten the ray(s) in `state`, and
    /// returns true to stop the traversal (any-hit queries).
    #[inline(always)]
    unsafe fn traverse_avx2<S>(
        bvh: &CwBvh,
        oct_inv4: u32,
        state: &mut S,
        node_mask: impl Fn(&S, &CwBvhNode, usize) -> u32,
        mut on_prim: impl FnMut(&mut S, u32) -> bool,
    ) {
        const STACK_SIZE: usize = 32;
        if bvh.nodes.is_empty() {
            return;
        }
        let nodes = &bvh.nodes[..];
        // Not zeroed per ray: every entry is written by a push before a pop reads it.
        let mut stack = [std::mem::MaybeUninit::<(u32, u32)>::uninit(); STACK_SIZE];
        let mut sp = 0usize;
        // (first child node index, node hit bits << 24 | imask) and (first primitive index,
        // primitive hit bits), as in obvhs' `Traversal`.
        let (mut cur_base, mut cur_bits) = (0u32, 0x8000_0000u32);
        let (mut prim_base, mut prim_bits) = (0u32, 0u32);
        loop {
            while prim_bits != 0 {
                let local = 31 - prim_bits.leading_zeros();
                prim_bits &= !(1u32 << local);
                if on_prim(state, prim_base + local) {
                    return;
                }
            }
            if cur_bits & 0xff00_0000 != 0 {
                let hits_imask = cur_bits;
                let child_index_offset = 31 - hits_imask.leading_zeros();
                cur_bits &= !(1u32 << child_index_offset);
                if cur_bits & 0xff00_0000 != 0 {
                    // Saturating push (obvhs `StackStack::push`).
                    stack.get_unchecked_mut(sp).write((cur_base, cur_bits));
                    sp = (sp + 1).min(STACK_SIZE - 1);
                }
                let slot_index = (child_index_offset - 24) ^ (oct_inv4 & 0xff);
                let relative_index = (hits_imask & !(0xffff_ffffu32 << slot_index)).count_ones();
                let index = (cur_base + relative_index) as usize;
                let node = &nodes[index];
                let hitmask = node_mask(state, node, index);
                cur_base = node.child_base_idx;
                cur_bits = (hitmask & 0xff00_0000) | node.imask as u32;
                prim_base = node.primitive_base_idx;
                prim_bits = hitmask & 0x00ff_ffff;
            } else {
                cur_bits = 0;
            }
            if prim_bits == 0 && cur_bits & 0xff00_0000 == 0 {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                (cur_base, cur_bits) = stack.get_unchecked(sp).assume_init();
            }
        }
    }

    /// [`super::closest_hit`] with the AVX2 node test.
    ///
    /// # Safety
    /// The CPU must support AVX2, FMA, POPCNT and LZCNT.
    #[inline]
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    pub(super) unsafe fn closest_hit_avx2(
        bvh: &CwBvh,
        planes: &[ChildPlanes],
        tris: &[RtTriangle],
        ray: Ray,
    ) -> Option<(f32, u32)> {
        let ray_planes = ray_planes(&ray);
        let oct_inv4 = octant_inv4(&ray);
        let mut state = (ray, u32::MAX);
        traverse_avx2(
            bvh,
            oct_inv4,
            &mut state,
            |(r, _), node, i| node_hits((node, i), planes, (&ray, &ray_planes), r.tmax, oct_inv4),
            |(r, best_id), id| {
                let t = intersect_triangle(&tris[id as usize], r);
                if closer(t, id, r.tmax, *best_id) {
                    *best_id = id;
                    r.tmax = t;
                }
                false
            },
        );
        let (r, best_id) = state;
        (best_id != u32::MAX).then_some((r.tmax, best_id))
    }

    /// Closest hits of up to [`PACKET`] rays in one traversal: a node's children are visited
    /// if any ray of the packet hits them (each ray's own AVX2 node test, OR-ed), and each
    /// leaf triangle is tested against every ray. Every ray thus tests a superset of the
    /// triangles its own traversal would, with the same arithmetic and the [`closer`] rule,
    /// so its hit is exactly the single-ray hit. Pays where the rays are coherent (one
    /// pixel's reflections off a smooth surface: the node loads, decoding and branches are
    /// shared, and the rays' tests overlap); `best[i]` returns ray i's triangle (u32::MAX: no
    /// hit) and `rays[i].tmax` its distance.
    ///
    /// # Safety
    /// As [`closest_hit_avx2`].
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    pub(super) unsafe fn closest_hit_packet_avx2(
        bvh: &CwBvh,
        planes: &[ChildPlanes],
        tris: &[RtTriangle],
        rays: &[Ray],
        best: &mut [u32; PACKET],
    ) -> [f32; PACKET] {
        let n = rays.len().min(PACKET);
        let mut ray_planes = [ray_planes(&rays[0]); PACKET];
        for (p, r) in ray_planes.iter_mut().zip(&rays[..n]).skip(1) {
            *p = self::ray_planes(r);
        }
        let oct_inv4 = octant_inv4(&rays[0]);
        let mut lanes = RayLanes::new(&rays[..n]);
        traverse_avx2(
            bvh,
            oct_inv4,
            &mut (&mut lanes, &mut *best),
            |(lanes, _), node, index| {
                let mut slots = 0;
                for (i, (r, p)) in rays[..n].iter().zip(&ray_planes).enumerate() {
                    slots |= child_slots(node, index, planes, r, p, lanes.tmax[i]);
                }
                slot_hit_bits(node, slots, oct_inv4)
            },
            |(lanes, best), id| {
                lanes.test_triangle(&TriScalars::of(&tris[id as usize]), id, best);
                false
            },
        );
        lanes.tmax
    }

    /// [`super::any_hit`] with the AVX2 node test.
    ///
    /// # Safety
    /// As [`closest_hit_avx2`].
    #[inline]
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    pub(super) unsafe fn any_hit_avx2(
        bvh: &CwBvh,
        planes: &[ChildPlanes],
        tris: &[RtTriangle],
        ray: Ray,
    ) -> bool {
        let ray_planes = ray_planes(&ray);
        let oct_inv4 = octant_inv4(&ray);
        let mut hit = false;
        traverse_avx2(
            bvh,
            oct_inv4,
            &mut hit,
            |_, node, i| node_hits((node, i), planes, (&ray, &ray_planes), ray.tmax, oct_inv4),
            |hit, id| {
                *hit = intersect_triangle(&tris[id as usize], &ray) < ray.tmax;
                *hit
            },
        );
        hit
    }

    /// [`closest_hit_avx2`] of a renderer ray. The obvhs ray (with its inverse direction) is
    /// built here, inside the AVX2 code, and stays in registers: built by a caller outside
    /// it, it went through memory and was read back at other widths right after it was
    /// written, which stalled every query on store forwarding (~a third of the time of a ray
    /// that misses the scene's bounds).
    ///
    /// # Safety
    /// As [`closest_hit_avx2`].
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    pub(super) unsafe fn closest_hit_of(
        bvh: &CwBvh,
        planes: &[ChildPlanes],
        tris: &[RtTriangle],
        ray: &super::Ray,
    ) -> Option<(f32, u32)> {
        let r = Ray::new(ray.origin.into(), ray.dir.into(), ray.tmin, ray.tmax);
        closest_hit_avx2(bvh, planes, tris, r)
    }

    /// [`any_hit_avx2`] of a renderer ray (see [`closest_hit_of`]).
    ///
    /// # Safety
    /// As [`closest_hit_avx2`].
    #[target_feature(enable = "avx2,fma,popcnt,lzcnt")]
    pub(super) unsafe fn any_hit_of(
        bvh: &CwBvh,
        planes: &[ChildPlanes],
        tris: &[RtTriangle],
        ray: &super::Ray,
    ) -> bool {
        let r = Ray::new(ray.origin.into(), ray.dir.into(), ray.tmin, ray.tmax);
        any_hit_avx2(bvh, planes, tris, r)
    }

    /// obvhs' `oct_inv4`: per byte, the octant bits of the ray direction, inverted.
    #[inline(always)]
    fn octant_inv4(ray: &Ray) -> u32 {
        (if ray.direction.x < 0.0 {
            0
        } else {
            0x0404_0404u32
        }) | if ray.direction.y < 0.0 {
            0
        } else {
            0x0202_0202
        } | if ray.direction.z < 0.0 {
            0
        } else {
            0x0101_0101
        }
    }
}

/// Ray–sphere distance in (tmin, tmax), or +inf. Uses the numerically stable form of the
/// quadratic (pbrt-v4 §6.8.1: b² − 4ac computed from the perpendicular distance).
#[inline]
fn sphere_intersect(s: &SphereGeom, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> f32 {
    let oc = origin - s.center;
    let b = oc.dot(dir);
    let perp = oc - dir * b;
    let disc = s.radius * s.radius - perp.length_squared();
    if disc < 0.0 {
        return f32::INFINITY;
    }
    let sq = disc.sqrt();
    let c = oc.length_squared() - s.radius * s.radius;
    let q = if b > 0.0 { -b - sq } else { -b + sq };
    let (mut t0, mut t1) = (q, if q != 0.0 { c / q } else { q });
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > tmin && t0 < tmax {
        t0
    } else if t1 > tmin && t1 < tmax {
        t1
    } else {
        f32::INFINITY
    }
}

/// ∂p/∂u of a triangle with edges `e1` = p1 − p0, `e2` = p2 − p0 and UV edges `duv1`,
/// `duv2` (pbrt-v4 / Mitsuba); zero for a degenerate parameterisation.
#[inline]
fn triangle_dpdu(e1: Vec3, e2: Vec3, duv1: Vec2, duv2: Vec2) -> Vec3 {
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if det.abs() < 1e-12 {
        return Vec3::ZERO;
    }
    (duv2.y * e1 - duv1.y * e2) / det
}

/// ∂p/∂v of a triangle (the companion of [`triangle_dpdu`], pbrt-v4 / Mitsuba).
#[inline]
fn triangle_dpdv(e1: Vec3, e2: Vec3, duv1: Vec2, duv2: Vec2) -> Vec3 {
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if det.abs() < 1e-12 {
        return Vec3::ZERO;
    }
    (duv1.x * e2 - duv2.x * e1) / det
}

/// ∂p/∂v of Mitsuba's sphere parameterisation v = θ/π at unit local direction `local`:
/// πr (z cos φ, z sin φ, −sin θ), turned to world; zero at the poles (φ undefined).
fn sphere_dpdv(local: Vec3, radius: f32, to_local: &glam::Mat3) -> Vec3 {
    let rd = local.truncate().length();
    if rd.is_nan() || rd <= 1e-7 {
        return Vec3::ZERO;
    }
    let d = Vec3::new(local.z * local.x / rd, local.z * local.y / rd, -rd);
    to_local.transpose() * d * (radius * std::f32::consts::PI)
}
#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 traversal returns exactly the baseline traversal's hits (t bits and triangle)
    /// and occlusion answers, on f32 and on quantised planes, from inside and outside a
    /// closed mesh plus a plane.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_traversal_matches_baseline() {
        if !cpu_has_avx2() {
            eprintln!("no AVX2 on this CPU: nothing to compare");
            return;
        }
        let mut tris: Vec<Triangle> = obvhs::test_util::geometry::icosphere(3);
        tris.extend(obvhs::test_util::geometry::PLANE);
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &tris,
            obvhs::BvhBuildParams::medium_build(),
            &mut std::time::Duration::default(),
        );
        let rt: Vec<RtTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        let decoded = ChildPlanes::of(&bvh);
        let mut rng = crate::render::sampler::Sampler::from_seed(7);
        let (mut hits, mut occluded) = (0, 0);
        for i in 0..20_000 {
            let o = Vec3::new(
                rng.next_1d() * 6.0 - 3.0,
                rng.next_1d() * 6.0 - 3.0,
                rng.next_1d() * 6.0 - 3.0,
            ) * if i % 2 == 0 { 1.0 } else { 0.2 };
            let d = Vec3::new(
                rng.next_1d() - 0.5,
                rng.next_1d() - 0.5,
                rng.next_1d() - 0.5,
            )
            .normalize();
            // Some axis-aligned directions (zero components → infinite inverse).
            let d = if i % 7 == 0 {
                Vec3::new(0.0, d.y.signum(), 0.0)
            } else {
                d
            };
            let tmax = if i % 3 == 0 { 1.5 } else { f32::INFINITY };
            let r = obvhs::ray::Ray::new(o.into(), d.into(), 0.0, tmax);
            let base = closest_hit(&bvh, &rt, r);
            let occ = any_hit(&bvh, &rt, r);
            // The renderer's entry points build the obvhs ray themselves.
            let ray = Ray {
                origin: o,
                dir: d,
                tmin: 0.0,
                tmax,
            };
            // Nodes tested on f32 planes, and on the quantised ones (large BVHs).
            for planes in [&decoded[..], &[]] {
                // SAFETY: AVX2 checked above.
                let (fast, fast_occ, of, occ_of) = unsafe {
                    (
                        x86::closest_hit_avx2(&bvh, planes, &rt, r),
                        x86::any_hit_avx2(&bvh, planes, &rt, r),
                        x86::closest_hit_of(&bvh, planes, &rt, &ray),
                        x86::any_hit_of(&bvh, planes, &rt, &ray),
                    )
                };
                let bits = |h: Option<(f32, u32)>| h.map(|(t, id)| (t.to_bits(), id));
                let mode = if planes.is_empty() {
                    "quantised"
                } else {
                    "f32"
                };
                assert_eq!(bits(base), bits(fast), "{mode} planes, ray {i}");
                assert_eq!(bits(base), bits(of), "{mode} planes, ray {i}");
                assert_eq!((occ, occ), (fast_occ, occ_of), "{mode} planes, ray {i}");
            }
            hits += base.is_some() as u32;
            occluded += occ as u32;
        }
        assert!(
            hits > 2_000 && occluded > 2_000,
            "{hits} hits, {occluded} occluded"
        );
    }

    /// In a small scene (the Cornell box: 36 triangles) the all-triangle SIMD queries find
    /// the BVH traversal's closest hits and blockers, bit for bit, and a ray's answer is the
    /// same alone and in a batch.
    #[test]
    fn small_scene_queries_match_the_bvh() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell_box.xml");
        let scene = crate::scene::load(&path, &[]).unwrap();
        let (accel, _) = Accel::build(&scene, 1).unwrap();
        assert!(accel.is_small());
        let mut rng = crate::render::sampler::Sampler::from_seed(11);
        let rays: Vec<Ray> = (0..20_000)
            .map(|i| {
                let u = |rng: &mut crate::render::sampler::Sampler| rng.next_1d() * 2.0 - 1.0;
                let origin = Vec3::new(u(&mut rng), u(&mut rng), u(&mut rng)) * 0.99;
                let dir = Vec3::new(u(&mut rng), u(&mut rng), u(&mut rng)).normalize();
                let tmax = if i % 3 == 0 { 0.7 } else { f32::INFINITY };
                Ray {
                    origin,
                    dir,
                    tmin: 0.0,
                    tmax,
                }
            })
            .collect();
        let key = |h: Option<Hit>| {
            h.map(|h| match h.prim {
                Prim::Triangle(id) => (h.t.to_bits(), id),
                Prim::Sphere(_) => unreachable!("no spheres in the scene"),
            })
        };
        let (mut batch, mut blocked) = (Vec::new(), Vec::new());
        accel.intersect_batch(&rays, &mut batch);
        accel.occluded_batch(&rays, &mut blocked);
        // Batches of every size below a full packet (the few-ray path and the lane path).
        let mut sized = Vec::new();
        let mut start = 0;
        for n in (1..=PACKET).cycle() {
            if start >= rays.len() {
                break;
            }
            let end = (start + n).min(rays.len());
            let mut out = Vec::new();
            accel.intersect_batch(&rays[start..end], &mut out);
            sized.extend(out);
            start = end;
        }
        let (mut hits, mut occluded) = (0, 0);
        for (i, r) in rays.iter().enumerate() {
            let bvh = accel.intersect_bvh(r);
            assert_eq!(key(accel.intersect(r)), key(bvh), "ray {i}");
            assert_eq!(key(batch[i]), key(bvh), "ray {i} in a batch");
            assert_eq!(key(sized[i]), key(bvh), "ray {i} in a smaller batch");
            let occ = accel.occluded_bvh(r);
            assert_eq!(accel.occluded(r), occ, "ray {i}");
            assert_eq!(blocked[i], occ, "ray {i} in a batch");
            hits += bvh.is_some() as u32;
            occluded += occ as u32;
        }
        assert!(hits > 10_000 && occluded > 5_000 && occluded < 19_000);
    }

    /// Distinct triangles sharing one bounding box (a hostile mesh that made PLOC quadratic) are
    /// built from tie-broken boxes, an ordinary mesh is not, and the tie-broken BVH finds
    /// exactly the hits of the one built from the triangles.
    #[test]
    fn shared_box_triangles_build_from_tie_broken_boxes_with_the_same_hits() {
        let mut rng = crate::render::sampler::Sampler::from_seed(3);
        let tris: Vec<Triangle> = (0..3000)
            .map(|_| Triangle {
                v0: Vec3::ZERO.into(),
                v1: Vec3::ONE.into(),
                v2: Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()).into(),
            })
            .collect();
        let sphere = obvhs::test_util::geometry::icosphere(3);
        assert!(!boxes_tie(sphere.len(), |i| sphere[i].aabb()));
        assert!(boxes_tie(tris.len(), |i| tris[i].aabb()), "one shared box");
        for (i, t) in tris.iter().enumerate() {
            let (a, b) = (t.aabb(), widen_box(t.aabb(), i));
            assert!(b.min.cmple(a.min).all() && b.max.cmpge(a.max).all());
        }
        let params = obvhs::BvhBuildParams::fast_build();
        let mut time = std::time::Duration::default();
        let refs: Vec<TriRef> = (0..tris.len() as u32).map(|i| (0, i)).collect();
        let effort = BuildEffort {
            params,
            conversion: Conversion::Sah,
        };
        let with_boxes = build_bvh(&refs, |&(_, i)| tri_vertices(&tris[i as usize]), effort);
        let with_tris = obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, params, &mut time);
        let rt = |bvh: &CwBvh| -> Vec<RtTriangle> {
            (bvh.primitive_indices.iter())
                .map(|&i| RtTriangle::from(&tris[i as usize]))
                .collect()
        };
        let (rt_boxes, rt_tris) = (rt(&with_boxes), rt(&with_tris));
        let mut hits = 0;
        for i in 0..5_000 {
            let o = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 4.0 - 2.0;
            let d = (Vec3::splat(0.5) - o + Vec3::new(rng.next_1d(), rng.next_1d(), 0.0) * 0.5)
                .normalize();
            let r = obvhs::ray::Ray::new(o.into(), d.into(), 0.0, f32::INFINITY);
            let a = closest_hit(&with_boxes, &rt_boxes, r).map(|(t, _)| t.to_bits());
            let b = closest_hit(&with_tris, &rt_tris, r).map(|(t, _)| t.to_bits());
            assert_eq!(a, b, "ray {i}");
            assert_eq!(any_hit(&with_boxes, &rt_boxes, r), b.is_some(), "ray {i}");
            hits += a.is_some() as u32;
        }
        assert!(hits > 1_000, "{hits} hits");
    }

    /// Repeats are found as a quadratic scan finds them — the first of each group kept, every
    /// later equal triangle (vertices in any order) dropped — also when every hash collides.
    #[test]
    fn repeats_are_the_later_copies_of_equal_triangles() {
        let mut state = 0x9e37_79b9_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        // Vertices from a pool of 6 points: many triangles repeat, in rotated and mirrored
        // vertex orders.
        let pool: Vec<Vec3> = (0..6)
            .map(|i| Vec3::new(i as f32, (i * i) as f32, 1.0))
            .collect();
        let tris: Vec<[Vec3; 3]> = (0..400)
            .map(|_| [0, 1, 2].map(|_| pool[next() as usize % pool.len()]))
            .collect();
        let expected: Vec<bool> = (0..tris.len())
            .map(|i| (0..i).any(|j| repeat_key(tris[j]) == repeat_key(tris[i])))
            .collect();
        assert!(expected.iter().filter(|&&r| r).count() > 100);
        for constant_hash in [false, true] {
            let items: Vec<((), u64)> = (tris.iter())
                .map(|&t| {
                    (
                        (),
                        if constant_hash {
                            7
                        } else {
                            repeat_hash(&repeat_key(t))
                        },
                    )
                })
                .collect();
            assert_eq!(repeats(&items, |i| repeat_key(tris[i])), expected);
        }
    }

    /// The BVH's triangles: degenerate, non-finite and repeated triangles (also across shapes)
    /// are dropped and counted, the rest kept in scene order.
    #[test]
    fn collect_triangles_drops_degenerate_and_repeated_triangles() {
        let p = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 0.0),
        ];
        let mesh = |indices: Vec<[u32; 3]>| crate::scene::TriangleMesh {
            positions: p.to_vec(),
            indices,
            ..Default::default()
        };
        let mut scene = crate::figure::teapot_scene(&Default::default());
        let template = scene.shapes[0].clone();
        scene.shapes.clear();
        for m in [
            mesh(vec![
                [0, 1, 2],
                [2, 0, 1],
                [0, 1, 3],
                [0, 1, 4],
                [1, 2, 3],
                [2, 1, 0],
            ]),
            mesh(vec![[1, 0, 2], [1, 3, 2]]),
        ] {
            scene.shapes.push(crate::scene::Shape {
                geometry: Geometry::Mesh(m.into()),
                ..template.clone()
            });
        }
        let (kept, spheres, dropped) = collect_triangles(&scene).unwrap();
        assert_eq!(kept, vec![(0, 0), (0, 4)]);
        assert!(spheres.is_empty());
        assert_eq!(dropped, 6);
    }

    fn tri_vertices(t: &Triangle) -> [Vec3; 3] {
        [t.v0.into(), t.v1.into(), t.v2.into()]
    }

    /// The build from triangle references (boxes freed before the conversion) is obvhs'
    /// build from the triangles: the same primitive order and nodes, for each effort level.
    #[test]
    fn reference_build_equals_obvhs_triangle_build() {
        let mut tris: Vec<Triangle> = obvhs::test_util::geometry::icosphere(4);
        tris.extend(obvhs::test_util::geometry::PLANE);
        let refs: Vec<TriRef> = (0..tris.len() as u32).map(|i| (0, i)).collect();
        let vertices = |&(_, i): &TriRef| tri_vertices(&tris[i as usize]);
        for params in [
            obvhs::BvhBuildParams::fast_build(),
            obvhs::BvhBuildParams::medium_build(),
            obvhs::BvhBuildParams::slow_build(),
        ] {
            let effort = BuildEffort {
                params,
                conversion: Conversion::Sah,
            };
            let ours = build_bvh(&refs, vertices, effort);
            let mut time = std::time::Duration::default();
            let theirs = obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, params, &mut time);
            assert_eq!(ours.primitive_indices, theirs.primitive_indices);
            assert!(ours.nodes == theirs.nodes);
        }
    }

    /// The greedy collapse of the fast build finds the closest hits (t bit for bit, the same
    /// triangle) and occlusion answers of obvhs' SAH conversion, with every triangle in
    /// exactly one leaf: on a sphere with a plane, a soup of random triangles, and meshes of
    /// one, two and three triangles (a root that is itself a leaf slot).
    #[test]
    fn greedy_collapse_finds_the_hits_of_obvhs_conversion() {
        let mut rng = crate::render::sampler::Sampler::from_seed(5);
        let mut v = || Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 2.0 - 1.0;
        let mut sphere: Vec<Triangle> = obvhs::test_util::geometry::icosphere(4);
        sphere.extend(obvhs::test_util::geometry::PLANE);
        let soup: Vec<Triangle> = (0..3000)
            .map(|_| {
                let c = v();
                Triangle {
                    v0: c.into(),
                    v1: (c + v() * 0.2).into(),
                    v2: (c + v() * 0.2).into(),
                }
            })
            .collect();
        let mut rng = crate::render::sampler::Sampler::from_seed(9);
        for tris in [
            sphere,
            soup.clone(),
            soup[..1].to_vec(),
            soup[..2].to_vec(),
            soup[..3].to_vec(),
        ] {
            let refs: Vec<TriRef> = (0..tris.len() as u32).map(|i| (0, i)).collect();
            let vertices = |&(_, i): &TriRef| tri_vertices(&tris[i as usize]);
            let params = obvhs::BvhBuildParams::fast_build();
            let build = |conversion| {
                let bvh = build_bvh(&refs, vertices, BuildEffort { params, conversion });
                let rt: Vec<RtTriangle> = (bvh.primitive_indices.iter())
                    .map(|&i| RtTriangle::from(&tris[i as usize]))
                    .collect();
                (bvh, rt)
            };
            let ((sah, rt_s), (greedy, rt_g)) = (build(Conversion::Sah), build(Conversion::Greedy));
            let planes_g = ChildPlanes::of(&greedy);
            let mut prims = greedy.primitive_indices.clone();
            prims.sort_unstable();
            assert_eq!(prims, (0..tris.len() as u32).collect::<Vec<_>>());
            let mut hits = 0;
            for i in 0..4_000 {
                // From a 6-unit cube towards a point inside the geometry's box.
                let o = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 6.0 - 3.0;
                let target = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 2.0 - 1.0;
                let d = (target - o).normalize();
                let r = obvhs::ray::Ray::new(o.into(), d.into(), 0.0, f32::INFINITY);
                let original = |h: Option<(f32, u32)>, bvh: &CwBvh| {
                    h.map(|(t, k)| (t.to_bits(), bvh.primitive_indices[k as usize]))
                };
                let a = original(closest_hit(&sah, &rt_s, r), &sah);
                let b = original(closest_hit(&greedy, &rt_g, r), &greedy);
                assert_eq!(a, b, "{} triangles, ray {i}", tris.len());
                assert_eq!(any_hit(&greedy, &rt_g, r), a.is_some(), "ray {i}");
                #[cfg(target_arch = "x86_64")]
                if cpu_has_avx2() {
                    // SAFETY: AVX2 (and fma/popcnt/lzcnt) checked just above.
                    let c = unsafe { x86::closest_hit_avx2(&greedy, &planes_g, &rt_g, r) };
                    assert_eq!(original(c, &greedy), a, "AVX2, ray {i}");
                }
                hits += a.is_some() as u32;
            }
            assert!(hits > 0, "{} triangles: no hits", tris.len());
            if tris.len() > 100 {
                assert!(hits > 1_000, "{hits} hits");
            }
        }
    }

    /// Packet traversals (coherent rays: one camera's neighbouring directions, and bundles
    /// reflected off one spot) find obvhs' single-ray closest hits, bit for bit, on a mesh
    /// whose BVH has f32 planes and on the same BVH without them (as a large mesh's).
    #[test]
    fn packets_find_the_single_ray_hits_on_both_kinds_of_planes() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot_diffuse.xml");
        let scene = crate::scene::load(&path, &[]).unwrap();
        let (mut accel, _) = Accel::build(&scene, 1 << 24).unwrap();
        if !accel.avx2 {
            eprintln!("no AVX2 on this CPU: no packet traversal");
            return;
        }
        assert!(!accel.is_small() && !accel.planes.is_empty());
        let (lo, hi) = accel.rt_tris.iter().fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), t| (lo.min(t.v0.into()), hi.max(t.v0.into())),
        );
        let mut rng = crate::render::sampler::Sampler::from_seed(3);
        let mut rays = Vec::new();
        for bundle in 0..400 {
            // A bundle of 16 rays from near one point towards near one point of the mesh.
            let mut u = || Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d());
            let (from, to) = (lo + (hi - lo) * (u() * 3.0 - 1.0), lo + (hi - lo) * u());
            let spread = (hi - lo).length() * if bundle % 2 == 0 { 0.01 } else { 0.1 };
            for i in 0..16 {
                let origin = from + (u() - 0.5) * spread * 0.1;
                let dir = (to + (u() - 0.5) * spread - origin).normalize();
                let tmax = if i % 5 == 0 {
                    0.5 * (to - from).length()
                } else {
                    f32::INFINITY
                };
                rays.push(Ray {
                    origin,
                    dir,
                    tmin: 0.0,
                    tmax,
                });
            }
        }
        let key = |h: Option<(f32, u32)>| h.map(|(t, id)| (t.to_bits(), id));
        let bvh = accel.bvh.clone().unwrap();
        let single: Vec<_> = (rays.iter())
            .map(|r| {
                let o = obvhs::ray::Ray::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax);
                key(closest_hit(&bvh, &accel.rt_tris, o))
            })
            .collect();
        assert!(single.iter().filter(|h| h.is_some()).count() > 1_000);
        for planes in ["f32", "quantised"] {
            if planes == "quantised" {
                accel.planes.clear();
            }
            let mut hits = Vec::new();
            accel.intersect_batch(&rays, &mut hits);
            for (i, (h, s)) in hits.iter().zip(&single).enumerate() {
                let h = h.map(|h| match h.prim {
                    Prim::Triangle(id) => (h.t, id),
                    Prim::Sphere(_) => unreachable!("no spheres in the scene"),
                });
                assert_eq!(key(h), *s, "{planes} planes, ray {i}");
            }
        }
    }

    /// The f32 child planes hold what the node test must not miss: each slot's box contains
    /// every vertex of every triangle under it, on meshes with flat boxes (a quad in a
    /// plane), far from the origin (coarse f32 spacing), a closed sphere and a random soup.
    #[test]
    fn child_planes_contain_what_their_slots_hold() {
        let mut rng = crate::render::sampler::Sampler::from_seed(11);
        let mut soup = Vec::new();
        for _ in 0..3_000 {
            let c = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 40.0 - 20.0;
            let mut v = || c + Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) - 0.5;
            soup.push(Triangle {
                v0: v().into(),
                v1: v().into(),
                v2: v().into(),
            });
        }
        let far = |offset: f32| -> Vec<Triangle> {
            (soup.iter())
                .map(|t| Triangle {
                    v0: t.v0 * 1e-3 + offset,
                    v1: t.v1 * 1e-3 + offset,
                    v2: t.v2 * 1e-3 + offset,
                })
                .collect()
        };
        let (far_pos, far_neg) = (far(1e5), far(-1e5));
        let mut quad = Vec::new();
        for i in 0..400 {
            let (x, z) = ((i % 20) as f32 * 0.1, (i / 20) as f32 * 0.1);
            let p = |dx: f32, dz: f32| Vec3::new(x + dx, 0.25, z + dz).into();
            quad.push(Triangle {
                v0: p(0.0, 0.0),
                v1: p(0.1, 0.0),
                v2: p(0.0, 0.1),
            });
        }
        let mut inexact_planes = 0;
        let sphere = obvhs::test_util::geometry::icosphere(4);
        for tris in [soup, far_pos, far_neg, quad, sphere] {
            let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
                &tris,
                obvhs::BvhBuildParams::medium_build(),
                &mut std::time::Duration::default(),
            );
            let planes = ChildPlanes::of(&bvh);
            // The primitives under slot `slot` of node `n`.
            fn under(bvh: &CwBvh, n: usize, slot: usize, out: &mut Vec<u32>) {
                let node = &bvh.nodes[n];
                let meta = node.child_meta[slot];
                if meta == 0 {
                    return;
                }
                if node.is_leaf(slot) {
                    let (first, count) = ((meta & 0b11111) as u32, (meta >> 5).count_ones());
                    let base = node.primitive_base_idx + first;
                    out.extend((base..base + count).map(|j| bvh.primitive_indices[j as usize]));
                } else {
                    let below = (node.imask & ((1u8 << slot) - 1)).count_ones();
                    let child = (node.child_base_idx + below) as usize;
                    for s in 0..8 {
                        under(bvh, child, s, out);
                    }
                }
            }
            let mut ids = Vec::new();
            let (mut checked, mut inexact) = (0usize, 0usize);
            for (n, rows) in planes.iter().enumerate() {
                // Each plane is on the outer side of the quantised one (exact in f64).
                let node = &bvh.nodes[n];
                let e = node.compute_extent().to_array();
                let p = node.p.to_array();
                let q = [
                    &node.child_min_x,
                    &node.child_max_x,
                    &node.child_min_y,
                    &node.child_max_y,
                    &node.child_min_z,
                    &node.child_max_z,
                ];
                for (row, q) in q.iter().enumerate() {
                    for slot in (0..8).filter(|&j| node.child_meta[j] != 0) {
                        let (k, exact) = (row / 2, rows.0[row][slot] as f64);
                        let quantised = p[k] as f64 + q[slot] as f64 * e[k] as f64;
                        inexact += usize::from(exact != quantised);
                        if row % 2 == 0 {
                            assert!(exact <= quantised, "node {n} row {row} slot {slot}");
                        } else {
                            assert!(exact >= quantised, "node {n} row {row} slot {slot}");
                        }
                    }
                }
                for slot in 0..8 {
                    ids.clear();
                    under(&bvh, n, slot, &mut ids);
                    for &id in &ids {
                        let t = &tris[id as usize];
                        for v in [t.v0, t.v1, t.v2] {
                            let v = [v.x as f64, v.y as f64, v.z as f64];
                            assert!(
                                (0..3).all(|k| rows.0[2 * k][slot] as f64 <= v[k]
                                    && rows.0[2 * k + 1][slot] as f64 >= v[k]),
                                "node {n} slot {slot}: vertex {v:?} outside its box"
                            );
                            checked += 1;
                        }
                    }
                }
            }
            // Every triangle is under the root's slots, and again under each deeper node.
            assert!(checked >= 3 * tris.len(), "{checked} vertices checked");
            inexact_planes += inexact;
        }
        // The far meshes' planes are not all f32 numbers: the rounding was exercised.
        assert!(inexact_planes > 0);
    }

    /// Axis-aligned rays onto an axis-aligned flat quad (a zero-thickness box, infinite
    /// inverse direction components): a camera looking straight down at a floor.
    #[test]
    fn axis_aligned_rays_hit_a_flat_quad() {
        let (a, b, c, d) = (
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(-1.0, 0.0, 1.0),
        );
        let tri = |p: Vec3, q: Vec3, r: Vec3| Triangle {
            v0: p.into(),
            v1: q.into(),
            v2: r.into(),
        };
        let tris = vec![tri(a, b, c), tri(a, c, d)];
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &tris,
            obvhs::BvhBuildParams::slow_build(),
            &mut std::time::Duration::default(),
        );
        let rt: Vec<RtTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        let mut misses = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                let (x, z) = (i as f32 * 0.09 - 0.9, j as f32 * 0.09 - 0.9);
                for (o, dir) in [
                    (Vec3::new(x, 1.0, z), Vec3::NEG_Y),
                    (Vec3::new(x, -1.0, z), Vec3::Y),
                ] {
                    let r = obvhs::ray::Ray::new(o.into(), dir.into(), 0.0, f32::INFINITY);
                    let hit = closest_hit(&bvh, &rt, r);
                    if hit.is_none_or(|(t, _)| (t - 1.0).abs() > 1e-5) || !any_hit(&bvh, &rt, r) {
                        misses.push((o, dir));
                    }
                }
            }
        }
        assert!(
            misses.is_empty(),
            "{} misses, e.g. {:?}",
            misses.len(),
            &misses[..misses.len().min(4)]
        );
    }

    #[test]
    fn rotated_sphere_uv_turn_with_the_sphere() {
        // Mitsuba 3.9 (scalar_rgb), sphere to_world = translate(0,0,1)·rotate(z, 225°): the
        // rays hit (1,0,1) at uv (0.375, 0.5), (0,1,1) at (0.625, 0.5), (0,0,2) at (0, 0).
        let scene = crate::scene::mitsuba::load_str(
            r#"<scene version="3.0.0"><shape type="sphere"><transform name="to_world">
                 <rotate z="1" angle="225"/><translate z="1"/></transform></shape></scene>"#,
            std::path::Path::new("."),
            &[],
            "sphere.xml",
        )
        .unwrap();
        let (accel, _) = Accel::build(&scene, 1 << 20).unwrap();
        for (origin, dir, uv) in [
            (Vec3::new(5.0, 0.0, 1.0), -Vec3::X, Vec2::new(0.375, 0.5)),
            (Vec3::new(0.0, 5.0, 1.0), -Vec3::Y, Vec2::new(0.625, 0.5)),
            (Vec3::new(0.0, 0.0, 6.0), -Vec3::Z, Vec2::new(0.0, 0.0)),
        ] {
            let ray = Ray {
                origin,
                dir,
                tmin: 0.0,
                tmax: f32::INFINITY,
            };
            let si = accel.interaction(&ray, &accel.intersect(&ray).unwrap());
            // u wraps at the seam (1 ≡ 0) and is undefined at the pole.
            let du = (si.uv.x - uv.x)
                .rem_euclid(1.0)
                .min((uv.x - si.uv.x).rem_euclid(1.0));
            assert!(
                (du < 1e-4 || uv.y == 0.0) && (si.uv.y - uv.y).abs() < 1e-3,
                "{origin}: {} vs Mitsuba's {uv}",
                si.uv
            );
        }
    }

    #[test]
    fn sphere_hits_from_outside_and_inside() {
        let s = SphereGeom {
            center: Vec3::ZERO,
            radius: 1.0,
            to_local: Mat3::IDENTITY,
            flip_normals: false,
            shape: 0,
        };
        let t = sphere_intersect(&s, Vec3::new(0.0, 0.0, -3.0), Vec3::Z, 0.0, f32::INFINITY);
        assert!((t - 2.0).abs() < 1e-5);
        let t = sphere_intersect(&s, Vec3::ZERO, Vec3::Z, 1e-4, f32::INFINITY);
        assert!((t - 1.0).abs() < 1e-5);
        let t = sphere_intersect(&s, Vec3::new(0.0, 2.0, -3.0), Vec3::Z, 0.0, f32::INFINITY);
        assert!(t.is_infinite());
    }
}
