//! Primary visibility from screen bins: every camera ray starts at the pinhole and crosses
//! the film inside its own pixel, so the only triangles it can hit are those whose projection
//! overlaps that pixel. Binning each projected triangle (edge-function test against the
//! pixel square grown by a margin far above f32 rounding) into the pixels it covers gives a
//! short, complete candidate list per pixel; a camera ray then runs the BVH's own triangle
//! test on that list only. The hit is the BVH's hit (same test, same closest-t rule with
//! exact ties going to the smaller triangle id), found without a traversal: an empty pixel
//! (background) costs a bounds check, a covered one a few triangle tests per ray, all rays of
//! the pixel's batch tested together against each candidate.
//!
//! This is the screen-space "first-hit" shortcut of hybrid renderers (a visibility buffer
//! made by binning instead of rasterising, so it is exact for any sample position inside the
//! pixel). It applies to the pinhole camera only, and falls back to the BVH where it would
//! not pay: fewer than [`MIN_RAYS_PER_TRIANGLE`] camera rays per triangle (a preview, a huge
//! mesh at a few samples), pixels with more than [`MAX_PER_PIXEL`] candidates, scenes with many triangles
//! crossing the camera plane, a total footprint beyond [`MAX_ENTRIES_PER_PIXEL`] per pixel, or
//! images beyond [`MAX_PIXELS`].

use super::accel::{Accel, Hit, Prim, RayLanes, SceneTriangles, PACKET};
use super::camera::{PerspectiveCamera, Ray};
use glam::Vec3;

/// Candidates beyond which a pixel is left to the BVH (deep depth complexity).
pub const MAX_PER_PIXEL: usize = 64;
/// Triangles crossing the camera plane are candidates of every pixel; beyond this many the
/// bins are not built (the camera is inside dense geometry).
pub const MAX_CROSSING: usize = 32;
/// Budget of the binned footprint (sum of bounding-box pixel counts), per pixel.
pub const MAX_ENTRIES_PER_PIXEL: usize = 64;
/// Camera rays per triangle below which the bins are not built. Binning is single-threaded
/// and costs ~0.14 µs per triangle; a binned camera ray saves less than that on two threads.
/// Measured whole set-up + render, bins against none (2 threads): 100k-triangle sphere 256²
/// × 4 spp (2.6 rays per triangle) 0.44 vs 0.38 s, × 16 spp (10) 0.74 vs 0.77 s, 512² × 16
/// (42) 1.54 vs 2.31 s; 36k-triangle teapot 128² × 4 (1.8) 0.099 vs 0.090 s, 256² × 4 (7)
/// 0.19 vs 0.22 s; a 2M-triangle mesh at 256² × 4 (0.13) spent 0.28 s binning for a 0.15 s
/// render.
pub const MIN_RAYS_PER_TRIANGLE: u64 = 4;
/// Images larger than this (4096², 64 MB of offsets) use the BVH for camera rays.
pub const MAX_PIXELS: usize = 1 << 24;

/// One candidate: a triangle (BVH order) and the smallest camera depth of its vertices.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    /// min over the vertices of camera-local q.z: no point of the triangle is nearer.
    depth: f32,
    tri: u32,
}

/// Per-pixel candidate lists for the camera rays of one image.
#[derive(Debug, Clone)]
pub struct PrimaryBins {
    width: u32,
    height: u32,
    /// Pixel p's candidates are `candidates[offsets[p]..offsets[p + 1]]`, nearest first.
    offsets: Vec<u32>,
    candidates: Vec<Candidate>,
    /// Pixels left to the BVH.
    bvh_pixel: Vec<bool>,
    /// Triangles crossing the camera plane (q.z ≤ 0 at some vertex): tested for every pixel.
    crossing: Vec<u32>,
    /// The camera the bins were made for (q.z = t·k along its rays).
    camera: PerspectiveCamera,
}

/// Statistics of a build, for the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BinStats {
    pub candidates: usize,
    pub bvh_pixels: usize,
    pub crossing: usize,
}

impl PrimaryBins {
    /// Bins the scene's triangles for a `width`×`height` image seen by `camera` that will
    /// trace `camera_rays` camera rays (pixels × samples per pixel); None when
    /// the bins would not pay (see the module doc) and every camera ray should use the BVH.
    /// The lists hold scene-order ids until [`SceneOrderBins::into_bvh_order`] (the BVH is
    /// built meanwhile).
    pub fn build(
        tris: &SceneTriangles,
        camera: &PerspectiveCamera,
        width: u32,
        height: u32,
        camera_rays: u64,
    ) -> Option<SceneOrderBins> {
        let n_tris = tris.count();
        let (w, h) = (width as usize, height as usize);
        if n_tris == 0
            || w == 0
            || h == 0
            || w * h > MAX_PIXELS
            || camera_rays < MIN_RAYS_PER_TRIANGLE * n_tris as u64
        {
            return None;
        }
        // Conservative margin in pixels: f32 ray directions and triangle tests are accurate
        // to ~1e-6 relative, i.e. far below 1e-3 px even at 8K.
        let margin = 0.05 + 1e-5 * w.max(h) as f64;
        let mut crossing = Vec::new();
        // Ids of the triangles with a footprint; footprints (~130 bytes) are recomputed for
        // the second pass instead of kept: at 2M triangles they were 256 MB, the render's
        // peak memory.
        let mut visible = Vec::new();
        let mut counts = vec![0u32; w * h];
        let mut bbox_pixels = 0usize;
        for id in 0..n_tris as u32 {
            let f = match project(tris, camera, id, margin, width, height) {
                Projection::Hidden => continue,
                Projection::Crossing => {
                    crossing.push(id);
                    if crossing.len() > MAX_CROSSING {
                        return None;
                    }
                    continue;
                }
                Projection::Footprint(f) => f,
            };
            bbox_pixels += (f.x1 - f.x0 + 1) * (f.y1 - f.y0 + 1);
            if bbox_pixels > MAX_ENTRIES_PER_PIXEL * w * h {
                return None;
            }
            f.for_each_pixel(|x, y| counts[y * w + x] += 1);
            visible.push(id);
        }
        let footprints =
            visible.iter().map(
                |&id| match project(tris, camera, id, margin, width, height) {
                    Projection::Footprint(f) => f,
                    _ => unreachable!("the same projection as in the first pass"),
                },
            );

        let bvh_pixel: Vec<bool> = counts.iter().map(|&c| c as usize > MAX_PER_PIXEL).collect();
        let mut offsets = Vec::with_capacity(w * h + 1);
        let mut total = 0u32;
        offsets.push(0);
        for (c, &bvh) in counts.iter().zip(&bvh_pixel) {
            if !bvh {
                total += c;
            }
            offsets.push(total);
        }
        let mut fill: Vec<u32> = offsets[..w * h].to_vec();
        let mut candidates = vec![Candidate { depth: 0.0, tri: 0 }; total as usize];
        for f in footprints {
            f.for_each_pixel(|x, y| {
                let p = y * w + x;
                if !bvh_pixel[p] {
                    candidates[fill[p] as usize] = Candidate {
                        depth: f.depth,
                        tri: f.tri,
                    };
                    fill[p] += 1;
                }
            });
        }
        Some(SceneOrderBins(PrimaryBins {
            width,
            height,
            offsets,
            candidates,
            bvh_pixel,
            crossing,
            camera: camera.clone(),
        }))
    }

    pub fn stats(&self) -> BinStats {
        BinStats {
            candidates: self.candidates.len(),
            bvh_pixels: self.bvh_pixel.iter().filter(|&&b| b).count(),
            crossing: self.crossing.len(),
        }
    }
}

/// Screen bins whose lists hold scene-order triangle ids ([`PrimaryBins::build`]), before
/// the BVH exists.
pub struct SceneOrderBins(PrimaryBins);

impl SceneOrderBins {
    /// The bins with the BVH's triangle ids (`bvh_order[j]`: the scene-order index of BVH
    /// triangle `j`, [`Accel::bvh_order`]), each pixel's list nearest first (exact depth
    /// ties: smaller id first) and the crossing triangles in id order.
    pub fn into_bvh_order(self, bvh_order: &[u32]) -> PrimaryBins {
        use rayon::prelude::*;
        let mut bins = self.0;
        let mut bvh_id = vec![0u32; bvh_order.len()];
        for (j, &i) in bvh_order.iter().enumerate() {
            bvh_id[i as usize] = j as u32;
        }
        for t in &mut bins.crossing {
            *t = bvh_id[*t as usize];
        }
        bins.crossing.sort_unstable();
        // Rows of pixels as independent tasks: disjoint runs of the candidate array.
        let w = bins.width as usize;
        let mut rows = Vec::with_capacity(bins.height as usize);
        let mut rest = bins.candidates.as_mut_slice();
        for y in 0..bins.height as usize {
            let (start, end) = (bins.offsets[y * w], bins.offsets[(y + 1) * w]);
            let (row, tail) = std::mem::take(&mut rest).split_at_mut((end - start) as usize);
            rows.push((y, row));
            rest = tail;
        }
        let offsets = &bins.offsets;
        rows.into_par_iter().for_each(|(y, row)| {
            let row_start = offsets[y * w];
            for t in row.iter_mut() {
                t.tri = bvh_id[t.tri as usize];
            }
            for p in y * w..(y + 1) * w {
                let (a, b) = (offsets[p] - row_start, offsets[p + 1] - row_start);
                row[a as usize..b as usize]
                    .sort_unstable_by(|a, b| a.depth.total_cmp(&b.depth).then(a.tri.cmp(&b.tri)));
            }
        });
        bins
    }
}

impl PrimaryBins {
    /// Closest hit of camera ray `ray` generated inside pixel (`x`, `y`): the same hit as
    /// [`Accel::intersect`] (spheres included).
    #[inline]
    pub fn intersect(&self, accel: &Accel, x: u32, y: u32, ray: &Ray) -> Option<Hit> {
        let mut hit = [None];
        self.intersect_batch(accel, x, y, std::slice::from_ref(ray), &mut hit);
        hit[0]
    }

    /// Closest hits of camera rays generated inside pixel (`x`, `y`), `hits[i]` for
    /// `rays[i]`, each the same hit as [`Accel::intersect`]'s ([`Self::intersect_lanes`],
    /// [`PACKET`] rays at a time). Camera rays share the pinhole as origin.
    pub fn intersect_batch(
        &self,
        accel: &Accel,
        x: u32,
        y: u32,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
    ) {
        for (rays, hits) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            let mut lanes = PixelRays {
                origin: rays[0].origin,
                dir: [[0.0; PACKET]; 3],
                tmin: [0.0; PACKET],
                tmax: [0.0; PACKET],
            };
            for i in 0..PACKET {
                let r = rays.get(i).unwrap_or(&rays[0]);
                debug_assert_eq!(r.origin, lanes.origin);
                for k in 0..3 {
                    lanes.dir[k][i] = r.dir[k];
                }
                lanes.tmin[i] = r.tmin;
                lanes.tmax[i] = r.tmax;
            }
            self.intersect_lanes(accel, x, y, &lanes, hits);
        }
    }

    /// Closest hits of the first `hits.len()` (≤ [`PACKET`]) rays of `rays`, generated inside
    /// pixel (`x`, `y`). The pixel's candidates are tested against all rays at once (SIMD
    /// lanes), nearest first, until every ray's hit is nearer than the next candidate can
    /// be. (Out of line: a batch-level stage, so profiles attribute it.)
    #[inline(never)]
    pub fn intersect_lanes(
        &self,
        accel: &Accel,
        x: u32,
        y: u32,
        rays: &PixelRays,
        hits: &mut [Option<Hit>],
    ) {
        let n = hits.len();
        debug_assert!(n <= PACKET);
        let ray = |i: usize| rays.ray(i);
        let p = y as usize * self.width as usize + x as usize;
        if x >= self.width || y >= self.height || self.bvh_pixel[p] {
            for (i, h) in hits.iter_mut().enumerate() {
                *h = accel.intersect(&ray(i));
            }
            return;
        }
        let list = &self.candidates[self.offsets[p] as usize..self.offsets[p + 1] as usize];
        // A hit at t has q.z = t·k; a triangle whose nearest vertex is deeper than the best
        // hit cannot be nearer (with slack for rounding in k and the depths). Rays without a
        // positive depth rate (never for a camera ray) use the BVH.
        let mut k = [0.0f32; PACKET];
        let mut binned = [false; PACKET];
        for i in 0..n {
            k[i] = self.camera.local_depth_rate(rays.direction(i)) * (1.0 + 1e-4);
            binned[i] = k[i] > 0.0;
        }
        if list.is_empty() && self.crossing.is_empty() {
            for (i, h) in hits.iter_mut().enumerate() {
                *h = if binned[i] {
                    accel.closest_sphere(&ray(i), rays.tmax[i], None)
                } else {
                    accel.intersect(&ray(i))
                };
            }
            return;
        }
        let mut lanes = RayLanes::from_lanes(rays.origin, &rays.dir, &rays.tmin, &rays.tmax);
        let mut best = [u32::MAX; PACKET];
        for &tri in &self.crossing {
            accel.test_triangle_lanes(&mut lanes, tri, &mut best);
        }
        for c in list {
            if (0..n).all(|i| !binned[i] || c.depth > lanes.tmax(i) * k[i]) {
                break;
            }
            accel.test_triangle_lanes(&mut lanes, c.tri, &mut best);
        }
        for (i, h) in hits.iter_mut().enumerate() {
            *h = if !binned[i] {
                accel.intersect(&ray(i))
            } else if best[i] == u32::MAX {
                accel.closest_sphere(&ray(i), rays.tmax[i], None)
            } else {
                let t = lanes.tmax(i);
                let hit = Hit {
                    t,
                    prim: Prim::Triangle(best[i]),
                };
                accel.closest_sphere(&ray(i), t, Some(hit))
            };
        }
    }
}

/// [`PACKET`] camera rays of one pixel in lanes: the pinhole and per-lane directions and
/// ranges (all lanes valid rays, also those past the ones asked about).
pub struct PixelRays {
    pub origin: Vec3,
    pub dir: [[f32; PACKET]; 3],
    pub tmin: [f32; PACKET],
    pub tmax: [f32; PACKET],
}

impl PixelRays {
    /// The rays from lane `first` on, moved to lanes 0, 1, …; the lanes past the end repeat
    /// the last ray (a batch of several pixels' samples, one pixel at a time through its bins).
    #[inline]
    pub fn from_lane(&self, first: usize) -> PixelRays {
        let lane = |i: usize| (first + i).min(PACKET - 1);
        PixelRays {
            origin: self.origin,
            dir: self.dir.map(|d| std::array::from_fn(|i| d[lane(i)])),
            tmin: std::array::from_fn(|i| self.tmin[lane(i)]),
            tmax: std::array::from_fn(|i| self.tmax[lane(i)]),
        }
    }

    #[inline]
    pub fn direction(&self, i: usize) -> Vec3 {
        Vec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i])
    }

    #[inline]
    pub fn ray(&self, i: usize) -> Ray {
        Ray {
            origin: self.origin,
            dir: self.direction(i),
            tmin: self.tmin[i],
            tmax: self.tmax[i],
        }
    }
}

/// Where triangle `id` (BVH order) lies for the screen bins.
enum Projection {
    /// Wholly behind the pinhole, off screen, or NaN: no camera ray can hit it.
    Hidden,
    /// Crosses the camera plane: tried in every pixel.
    Crossing,
    Footprint(Footprint),
}

fn project(
    tris: &SceneTriangles,
    camera: &PerspectiveCamera,
    id: u32,
    margin: f64,
    width: u32,
    height: u32,
) -> Projection {
    let q = tris.vertices(id).map(|v| camera.camera_local(v));
    let zmin = q[0].z.min(q[1].z).min(q[2].z);
    let zmax = q[0].z.max(q[1].z).max(q[2].z);
    if zmax.is_nan() || zmax < 0.0 {
        // Wholly behind the pinhole (q.z ≥ 0 on every camera ray), or NaN.
        return Projection::Hidden;
    }
    if zmin <= 0.0 {
        return Projection::Crossing;
    }
    // In front of the camera a triangle projects to the triangle of its projected
    // vertices: a ray can hit it only if that 2-D triangle meets the ray's pixel.
    let r = q.map(|qi| camera.raster_of(qi, width, height));
    let (w, h) = (width as usize, height as usize);
    match Footprint::new(id, zmin as f32, r, margin, w, h) {
        Some(f) => Projection::Footprint(f),
        None => Projection::Hidden, // off screen
    }
}

/// A triangle's projection: its pixel bounding box and edge functions.
struct Footprint {
    tri: u32,
    depth: f32,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
    /// Edge functions a·x + b·y + c, ≥ 0 inside; None for a (near-)degenerate projection,
    /// which keeps the whole bounding box.
    edges: Option<[[f64; 3]; 3]>,
    margin: f64,
}

impl Footprint {
    /// None if the (margin-grown) projection misses the image.
    fn new(
        tri: u32,
        depth: f32,
        r: [glam::DVec2; 3],
        margin: f64,
        w: usize,
        h: usize,
    ) -> Option<Self> {
        let (xmin, xmax) = (
            r[0].x.min(r[1].x).min(r[2].x),
            r[0].x.max(r[1].x).max(r[2].x),
        );
        let (ymin, ymax) = (
            r[0].y.min(r[1].y).min(r[2].y),
            r[0].y.max(r[1].y).max(r[2].y),
        );
        let x0 = (xmin - margin).floor().max(0.0);
        let x1 = (xmax + margin).floor().min(w as f64 - 1.0);
        let y0 = (ymin - margin).floor().max(0.0);
        let y1 = (ymax + margin).floor().min(h as f64 - 1.0);
        if !(x0 <= x1 && y0 <= y1) {
            return None;
        }
        let area2 = (r[1] - r[0]).perp_dot(r[2] - r[0]);
        let extent = (xmax - xmin).max(ymax - ymin);
        let edges = (area2.abs() > 1e-9 * extent * extent).then(|| {
            let s = area2.signum();
            [0, 1, 2].map(|i| {
                let (a, b) = (r[i], r[(i + 1) % 3]);
                // Inside (for either winding) where s·((b − a) × (p − a)) ≥ 0.
                let (ea, eb) = (-s * (b.y - a.y), s * (b.x - a.x));
                [ea, eb, -(ea * a.x + eb * a.y)]
            })
        });
        Some(Footprint {
            tri,
            depth,
            x0: x0 as usize,
            x1: x1 as usize,
            y0: y0 as usize,
            y1: y1 as usize,
            edges,
            margin,
        })
    }

    /// Calls `f(x, y)` for every pixel whose square, grown by the margin, meets the
    /// projected triangle (separating-axis test on the three edges; the box is the rest).
    fn for_each_pixel(&self, mut f: impl FnMut(usize, usize)) {
        let half = 0.5 + self.margin;
        for y in self.y0..=self.y1 {
            for x in self.x0..=self.x1 {
                let inside = self.edges.is_none_or(|edges| {
                    let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                    edges
                        .iter()
                        .all(|&[a, b, c]| a * cx + b * cy + c + (a.abs() + b.abs()) * half >= 0.0)
                });
                if inside {
                    f(x, y);
                }
            }
        }
    }
}
