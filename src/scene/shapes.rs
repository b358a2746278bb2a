//! Mesh utilities and Mitsuba 3's canonical shapes as triangle meshes.
//!
//! Canonical shapes (object space, as in Mitsuba 3.9, checked with its Python bindings):
//! - `rectangle`: [−1,1]² in the z = 0 plane, normal +Z, uv = ((x+1)/2, (y+1)/2);
//! - `cube`: [−1,1]³, 24 vertices / 12 triangles with flat normals and per-face uvs (Mitsuba's
//!   `cube.cpp` vertex table);
//! - `disk`: unit disk at z = 0, normal +Z, uv = (r, φ/2π) with φ = atan2(y, x) in [0, 2π).
//!   Tessellated into rings × segments (Mitsuba intersects it analytically; the polygon
//!   with 128 segments has 0.04 % less area).

use super::TriangleMesh;
use anyhow::{bail, Result};
use glam::{Mat4, Vec2, Vec3};
use std::collections::HashMap;

impl TriangleMesh {
    /// Axis-aligned bounds (min, max); None for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        if self.positions.is_empty() {
            return None;
        }
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for &p in &self.positions {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        Some((lo, hi))
    }

    /// Applies a point transform; normals go through the inverse transpose and are
    /// renormalised, tangents through the matrix itself, their bitangent sign flipped by a
    /// mirroring transform (which turns n × t against the transformed bitangent).
    pub fn transform(&mut self, m: &Mat4) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        let nm = m.inverse().transpose();
        for n in &mut self.normals {
            *n = nm.transform_vector3(*n).try_normalize().unwrap_or(*n);
        }
        let sign = if m.determinant() < 0.0 { -1.0 } else { 1.0 };
        for t in &mut self.tangents {
            let v = m.transform_vector3(t.truncate());
            *t = v.try_normalize().unwrap_or(v).extend(t.w * sign);
        }
    }

    /// Turns the surface inside out: reverses the winding and negates the shading normals
    /// (Mitsuba's `flip_normals` flips both the geometric and the shading normal).
    pub fn flip(&mut self) {
        for t in &mut self.indices {
            t.swap(1, 2);
        }
        for n in &mut self.normals {
            *n = -*n;
        }
        // The bitangent w·(n × t) keeps its direction.
        for t in &mut self.tangents {
            t.w = -t.w;
        }
    }

    /// Appends another mesh.
    pub fn append(&mut self, other: &TriangleMesh) {
        let base = self.positions.len() as u32;
        let had = !self.positions.is_empty();
        // Keep "empty or one per vertex" for normals/uvs when merging unlike meshes.
        if had && self.normals.is_empty() != other.normals.is_empty() {
            self.normals.clear();
        }
        if had && self.uvs.is_empty() != other.uvs.is_empty() {
            self.uvs.clear();
        }
        if had && self.colors.is_empty() != other.colors.is_empty() {
            self.colors.clear();
        }
        let keep_n = !had || !self.normals.is_empty();
        let keep_uv = !had || !self.uvs.is_empty();
        let keep_c = !had || !self.colors.is_empty();
        self.positions.extend_from_slice(&other.positions);
        if keep_n {
            self.normals.extend_from_slice(&other.normals);
        }
        if keep_uv {
            self.uvs.extend_from_slice(&other.uvs);
        }
        if keep_c {
            self.colors.extend_from_slice(&other.colors);
        }
        if had && self.tangents.is_empty() != other.tangents.is_empty() {
            self.tangents.clear();
        } else {
            self.tangents.extend_from_slice(&other.tangents);
        }
        self.indices
            .extend(other.indices.iter().map(|t| t.map(|i| i + base)));
        if self.normals.len() != self.positions.len() {
            self.normals.clear();
        }
        if self.uvs.len() != self.positions.len() {
            self.uvs.clear();
        }
        if self.colors.len() != self.positions.len() {
            self.colors.clear();
        }
        if self.tangents.len() != self.positions.len() {
            self.tangents.clear();
        }
    }

    /// Checks the invariants the renderer relies on: indices in range, finite positions,
    /// `normals`/`uvs`/`colors` empty or one per vertex. `what` names the mesh in the message.
    pub fn validate(&self, what: &str) -> Result<()> {
        let n = self.positions.len();
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            bail!(
                "{what}: vertex {i} has a non-finite position {:?}",
                self.positions[i]
            );
        }
        if !self.normals.is_empty() && self.normals.len() != n {
            bail!("{what}: {} normals for {n} vertices", self.normals.len());
        }
        if let Some(i) = self.normals.iter().position(|v| !v.is_finite()) {
            bail!(
                "{what}: vertex {i} has a non-finite normal {:?}",
                self.normals[i]
            );
        }
        if let Some(i) = self.uvs.iter().position(|v| !v.is_finite()) {
            bail!(
                "{what}: vertex {i} has non-finite texture coordinates {:?}",
                self.uvs[i]
            );
        }
        if !self.uvs.is_empty() && self.uvs.len() != n {
            bail!("{what}: {} uvs for {n} vertices", self.uvs.len());
        }
        if let Some(i) = self.colors.iter().position(|c| !c.is_finite()) {
            bail!(
                "{what}: vertex {i} has a non-finite colour {:?}",
                self.colors[i]
            );
        }
        if !self.colors.is_empty() && self.colors.len() != n {
            bail!(
                "{what}: {} vertex colours for {n} vertices",
                self.colors.len()
            );
        }
        if !self.tangents.is_empty() && self.tangents.len() != n {
            bail!("{what}: {} tangents for {n} vertices", self.tangents.len());
        }
        if let Some((k, t)) = self
            .indices
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            bail!("{what}: triangle {k} {t:?} refers to a vertex ≥ {n}");
        }
        Ok(())
    }

    /// Gives every triangle its own three vertices coloured `colors[triangle]` (a per-face
    /// mesh attribute, constant over each face as Mitsuba evaluates it, through the
    /// interpolated vertex colour).
    pub fn split_faces_with_colors(&mut self, colors: &[Vec3]) {
        fn corners<T: Copy>(indices: &[[u32; 3]], n: usize, v: &[T]) -> Vec<T> {
            if v.len() != n {
                return Vec::new(); // absent (or unusable): stays absent
            }
            (indices.iter())
                .flat_map(|t| t.map(|k| v[k as usize]))
                .collect()
        }
        let (idx, n) = (&self.indices, self.positions.len());
        let positions = corners(idx, n, &self.positions);
        let normals = corners(idx, n, &self.normals);
        let uvs = corners(idx, n, &self.uvs);
        self.colors = (colors.iter()).flat_map(|&c| [c; 3]).collect();
        self.indices = (0..self.indices.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        (self.positions, self.normals, self.uvs) = (positions, normals, uvs);
    }

    /// Replaces missing or non-finite normals by angle-weighted smooth normals (what Mitsuba
    /// does for meshes without normals unless `face_normals` is set).
    pub fn ensure_normals(&mut self) {
        if self.normals.len() != self.positions.len()
            || self
                .normals
                .iter()
                .any(|n| !n.is_finite() || n.length_squared() == 0.0)
        {
            self.normals = smooth_normals(&self.positions, &self.indices, false);
        }
    }
}

/// Angle-weighted vertex normals. With `weld`, vertices sharing a position (to 1e-5) share a
/// normal, so seams between separately parameterised pieces shade smoothly. Vertices that
/// touch no non-degenerate face get +Y.
pub fn smooth_normals(positions: &[Vec3], indices: &[[u32; 3]], weld: bool) -> Vec<Vec3> {
    let groups: Vec<usize> = if weld {
        let mut group_of: HashMap<(i64, i64, i64), usize> = HashMap::new();
        positions
            .iter()
            .map(|&p| {
                let q = (p * 1e5).round();
                let next = group_of.len();
                *group_of
                    .entry((q.x as i64, q.y as i64, q.z as i64))
                    .or_insert(next)
            })
            .collect()
    } else {
        (0..positions.len()).collect()
    };
    let count = groups.iter().copied().max().map_or(0, |m| m + 1);
    let mut acc = vec![Vec3::ZERO; count];
    for t in indices {
        let [a, b, c] = t.map(|k| positions[k as usize]);
        let Some(face) = (b - a).cross(c - a).try_normalize() else {
            continue;
        };
        for (k, (p, q, r)) in [(a, b, c), (b, c, a), (c, a, b)].into_iter().enumerate() {
            let angle = (q - p).angle_between(r - p);
            if angle.is_finite() {
                acc[groups[t[k] as usize]] += angle * face;
            }
        }
    }
    groups
        .iter()
        .map(|&g| acc[g].try_normalize().unwrap_or(Vec3::Y))
        .collect()
}

/// Mitsuba's `rectangle`.
pub fn rectangle() -> TriangleMesh {
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    TriangleMesh {
        colors: Vec::new(),
        tangents: Vec::new(),
        positions: corners.iter().map(|&(x, y)| Vec3::new(x, y, 0.0)).collect(),
        normals: vec![Vec3::Z; 4],
        uvs: corners
            .iter()
            .map(|&(x, y)| Vec2::new((x + 1.0) / 2.0, (y + 1.0) / 2.0))
            .collect(),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Mitsuba's `cube` (vertex table of Mitsuba 3 `cube.cpp`).
pub fn cube() -> TriangleMesh {
    #[rustfmt::skip]
    const P: [[f32; 3]; 24] = [
        [1., -1., -1.], [1., -1., 1.], [-1., -1., 1.], [-1., -1., -1.],
        [1., 1., -1.], [-1., 1., -1.], [-1., 1., 1.], [1., 1., 1.],
        [1., -1., -1.], [1., 1., -1.], [1., 1., 1.], [1., -1., 1.],
        [1., -1., 1.], [1., 1., 1.], [-1., 1., 1.], [-1., -1., 1.],
        [-1., -1., 1.], [-1., 1., 1.], [-1., 1., -1.], [-1., -1., -1.],
        [1., 1., -1.], [1., -1., -1.], [-1., -1., -1.], [-1., 1., -1.],
    ];
    const N: [[f32; 3]; 6] = [
        [0., -1., 0.],
        [0., 1., 0.],
        [1., 0., 0.],
        [0., 0., 1.],
        [-1., 0., 0.],
        [0., 0., -1.],
    ];
    const UV: [[f32; 2]; 4] = [[0., 1.], [1., 1.], [1., 0.], [0., 0.]];
    TriangleMesh {
        colors: Vec::new(),
        tangents: Vec::new(),
        positions: P.iter().map(|&p| Vec3::from(p)).collect(),
        normals: (0..24).map(|i| Vec3::from(N[i / 4])).collect(),
        uvs: (0..24).map(|i| Vec2::from(UV[i % 4])).collect(),
        indices: (0..6u32)
            .flat_map(|f| {
                let b = 4 * f;
                [[b, b + 1, b + 2], [b + 3, b, b + 2]]
            })
            .collect(),
    }
}

/// Mitsuba's `disk` as `rings` × `segments` quads (the centre ring as a fan).
pub fn disk(rings: usize, segments: usize) -> TriangleMesh {
    let (rings, segments) = (rings.max(1), segments.max(3));
    let mut m = TriangleMesh::default();
    // Centre: one vertex per segment so each fan triangle gets its own φ (uv.y).
    for s in 0..segments {
        m.positions.push(Vec3::ZERO);
        m.normals.push(Vec3::Z);
        m.uvs
            .push(Vec2::new(0.0, (s as f32 + 0.5) / segments as f32));
    }
    let ring_base = |r: usize| (segments + (r - 1) * (segments + 1)) as u32;
    for r in 1..=rings {
        let radius = r as f32 / rings as f32;
        // segments + 1 vertices: the seam at φ = 0 / 2π is duplicated for the uv wrap.
        for s in 0..=segments {
            let v = s as f32 / segments as f32;
            let phi = v * std::f32::consts::TAU;
            m.positions
                .push(Vec3::new(radius * phi.cos(), radius * phi.sin(), 0.0));
            m.normals.push(Vec3::Z);
            m.uvs.push(Vec2::new(radius, v));
        }
    }
    for s in 0..segments as u32 {
        let b = ring_base(1);
        m.indices.push([s, b + s, b + s + 1]);
    }
    for r in 2..=rings {
        let (inner, outer) = (ring_base(r - 1), ring_base(r));
        for s in 0..segments as u32 {
            m.indices.push([inner + s, outer + s, outer + s + 1]);
            m.indices.push([inner + s, outer + s + 1, inner + s + 1]);
        }
    }
    m
}

/// Segments around a tessellated `cylinder`: the polygon's sides lie within
/// 1 − cos(π/N) ≈ 1.9·10⁻⁵ radii of the analytic surface (and its area within 7·10⁻⁶).
pub const CYLINDER_SEGMENTS: usize = 512;

/// Mitsuba's `cylinder` in its local frame — the open tube of radius 1 around the z axis
/// from z = 0 to 1 — as `segments` quads with the analytic normals (x, y, 0) and Mitsuba's
/// uv = (φ / 2π, z), φ = atan2(y, x) ∈ [0, 2π). The seam vertices at φ = 0 and 2π are
/// duplicated so that u runs to 1.
pub fn cylinder(segments: usize) -> TriangleMesh {
    let segments = segments.max(3);
    let mut m = TriangleMesh::default();
    for s in 0..=segments {
        let u = s as f32 / segments as f32;
        let (sin, cos) = (u * std::f32::consts::TAU).sin_cos();
        for z in [0.0, 1.0] {
            m.positions.push(Vec3::new(cos, sin, z));
            m.normals.push(Vec3::new(cos, sin, 0.0));
            m.uvs.push(Vec2::new(u, z));
        }
    }
    for s in 0..segments as u32 {
        let (a, d, b, c) = (2 * s, 2 * s + 1, 2 * s + 2, 2 * s + 3);
        // Counter-clockwise seen from outside: the faces' normals point away from the axis.
        m.indices.push([a, b, c]);
        m.indices.push([a, c, d]);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(m: &TriangleMesh) -> f32 {
        m.indices
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Geometric normals must agree with the stored shading normals (outward winding).
    fn winding_matches_normals(m: &TriangleMesh) {
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let g = (b - a).cross(c - a).normalize();
            for &i in t {
                assert!(g.dot(m.normals[i as usize]) > 0.99, "{t:?}");
            }
        }
    }

    #[test]
    fn canonical_shapes() {
        let r = rectangle();
        assert_eq!(area(&r), 4.0);
        winding_matches_normals(&r);
        let c = cube();
        assert_eq!(area(&c), 24.0);
        winding_matches_normals(&c);
        let d = disk(8, 128);
        assert!((area(&d) - std::f32::consts::PI).abs() < 0.002);
        winding_matches_normals(&d);
        d.validate("disk").unwrap();
        // uv = (r, φ/2π): the vertex at (0, 1) (φ = 90°) has v = 0.25.
        let i = d
            .positions
            .iter()
            .position(|p| (*p - Vec3::Y).length() < 1e-5)
            .unwrap();
        assert!((d.uvs[i] - Vec2::new(1.0, 0.25)).length() < 1e-5);
    }

    #[test]
    fn transform_and_flip() {
        let mut r = rectangle();
        r.transform(&Mat4::from_scale(Vec3::new(2.0, 1.0, 1.0)));
        assert_eq!(area(&r), 8.0);
        r.flip();
        assert_eq!(r.normals[0], -Vec3::Z);
        winding_matches_normals(&r);
        let mut bad = rectangle();
        bad.indices.push([0, 1, 9]);
        assert!(bad.validate("bad").is_err());
        let mut nan = rectangle();
        nan.positions[0].x = f32::NAN;
        assert!(nan.validate("nan").is_err());
    }

    #[test]
    fn cylinder_matches_mitsubas_parameterisation() {
        let m = cylinder(CYLINDER_SEGMENTS);
        m.validate("cylinder").unwrap();
        // Lateral area 2π r h, face normals outward and equal to the vertex normals.
        let expected = std::f32::consts::TAU;
        assert!(
            (area(&m) - expected).abs() < 1e-4 * expected,
            "{}",
            area(&m)
        );
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a).normalize();
            let centre = (a + b + c) / 3.0;
            assert!(n.dot(Vec3::new(centre.x, centre.y, 0.0)) > 0.999);
        }
        for (p, uv) in m.positions.iter().zip(&m.uvs) {
            let phi = p.y.atan2(p.x).rem_euclid(std::f32::consts::TAU);
            let u = phi / std::f32::consts::TAU;
            assert!(
                (uv.x - u).abs() < 1e-5 || (uv.x - 1.0).abs() < 1e-6,
                "{uv} at {p}"
            );
            assert_eq!(uv.y, p.z);
        }
    }
}
