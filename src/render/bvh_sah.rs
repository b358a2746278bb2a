//! BVH2 → compressed wide BVH (CWBVH, Ylitie et al. 2017) by obvhs' SAH conversion, with its
//! child ordering done in a fraction of the time; the output is obvhs'
//! `bvh2_to_cwbvh(bvh2, max_prims_per_leaf, true, false)` node for node (test
//! `sah_conversion_is_obvhs_conversion`).
//!
//! The conversion (obvhs 0.4, MIT OR Apache-2.0) chooses each 8-wide node's children by
//! dynamic programming over the BVH2's SAH costs (§4.1; obvhs' `calculate_cost` and
//! `get_children`, called here), then orders them by octant (§4.2) so that a ray visits a
//! node's children roughly front to back: child c goes to slot s in order of the cost
//! d_s · (centre_c − centre_node), d_s the diagonal of octant s, the cheapest free pair of
//! all first. obvhs evaluates that greedy assignment by scanning all 8 × 8 pairs for each of
//! up to 8 picks with a data-dependent branch per pair, and reads each child's box once per
//! slot: 20 of the 28 ms of the conversion of the 36,672-triangle teapot, on the set-up's
//! critical path. Here the 64 costs are computed once into one array and each pick is a
//! branch-free minimum over it; the costs, and which pair wins a tie, are obvhs'.

use super::bvh_collapse::{leaf_meta, push_primitives, set_child_box, set_grid};
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::{Bvh2Converter, DecisionKind};
use obvhs::cwbvh::{node::CwBvhNode, CwBvh};

/// An empty child slot.
const EMPTY: u32 = u32::MAX;

/// The CWBVH of `bvh2` (leaves of one primitive each, as PLOC builds them) with leaf slots of
/// at most `max_prims_per_leaf` (1–3) primitives.
pub(super) fn convert(bvh2: &Bvh2, max_prims_per_leaf: u32) -> CwBvh {
    if bvh2.nodes.is_empty() {
        return CwBvh::default();
    }
    let mut converter = Bvh2Converter::new(bvh2, false, false);
    converter.calculate_cost(max_prims_per_leaf);
    fill_node(&mut converter, 0, 0);
    CwBvh {
        nodes: converter.nodes,
        primitive_indices: converter.primitive_indices,
        total_aabb: *bvh2.nodes[0].aabb(),
        exact_node_aabbs: None,
        uses_spatial_splits: bvh2.uses_spatial_splits,
    }
}

/// Wide node `wide` for BVH2 node `node2`, then its interior children depth first (obvhs'
/// `convert_to_cwbvh_impl`, operation for operation, with [`order_children`]).
fn fill_node(c: &mut Bvh2Converter, wide: usize, node2: usize) {
    let bvh2 = c.bvh2;
    let mut node = c.nodes[wide];
    let aabb = bvh2.nodes[node2].aabb();
    let rcp_e = set_grid(&mut node, aabb);

    let mut children = [EMPTY; 8];
    let mut child_count = 0;
    c.get_children(node2, &mut children, &mut child_count, 0);
    order_children(bvh2, node2, &mut children, child_count as usize);

    node.imask = 0;
    node.primitive_base_idx = c.primitive_indices.len() as u32;
    node.child_base_idx = c.nodes.len() as u32;
    let mut interior = 0;
    let mut primitives = 0u8;
    for (i, &child) in children.iter().enumerate() {
        if child == EMPTY {
            continue;
        }
        set_child_box(
            &mut node,
            i,
            bvh2.nodes[child as usize].aabb(),
            aabb.min,
            rcp_e,
        );
        match c.decisions[child as usize * 7].kind {
            DecisionKind::LEAF => {
                let count = push_primitives(bvh2, child, &mut c.primitive_indices);
                node.child_meta[i] = leaf_meta(primitives, count);
                primitives += count;
            }
            DecisionKind::INTERNAL => {
                node.imask |= 1 << i;
                node.child_meta[i] = (24 + i as u8) | 0b0010_0000;
                interior += 1;
            }
            DecisionKind::DISTRIBUTE => unreachable!("get_children resolves distributions"),
        }
    }
    c.nodes
        .resize(c.nodes.len() + interior, CwBvhNode::default());
    c.nodes[wide] = node;
    let mut offset = 0;
    for (i, &child) in children.iter().enumerate() {
        if child != EMPTY && node.imask & (1 << i) != 0 {
            fill_node(c, (node.child_base_idx + offset) as usize, child as usize);
            offset += 1;
        }
    }
}

/// Puts the `count` children of BVH2 node `parent` into octant slots: repeatedly the
/// (child, slot) pair of least cost among unassigned children and free slots, the first in
/// (child, slot) order on a tie — obvhs' `order_children`, whose scan keeps the first strict
/// minimum below `f32::MAX`. The cost of child c in slot s is d_s · v_c with v_c = centre_c −
/// centre_parent and d_s = (±1, ±1, ±1) (bit 2 of s: −x, bit 1: −y, bit 0: −z), summed as
/// glam's SSE dot product does, (x + y) + z, so every cost is obvhs' bit for bit.
fn order_children(bvh2: &Bvh2, parent: usize, children: &mut [u32; 8], count: usize) {
    let p = bvh2.nodes[parent].aabb().center();
    // Pairs that can never win (a child beyond `count`, a NaN or ≥ f32::MAX cost) hold +∞.
    let mut cost = [f32::INFINITY; 64];
    for (c, &child) in children.iter().enumerate().take(count) {
        let v = bvh2.nodes[child as usize].aabb().center() - p;
        for s in 0..8 {
            let sign = |bit: usize| if s & bit != 0 { -1.0 } else { 1.0 };
            let d = (sign(4) * v.x + sign(2) * v.y) + sign(1) * v.z;
            cost[c * 8 + s] = if d < f32::MAX { d } else { f32::INFINITY };
        }
    }
    let mut slot_of = [usize::MAX; 8];
    for _ in 0..count {
        // Branch-free minimum, slot by slot over the children (eight independent minima in
        // SIMD lanes, not one chain of 64), then the first pair that holds it. No cost is NaN,
        // so the order the minimum is taken in does not change it (±0 compare equal below).
        let mut per_slot = [f32::INFINITY; 8];
        for row in cost.chunks_exact(8) {
            for (m, &x) in per_slot.iter_mut().zip(row) {
                *m = if x < *m { x } else { *m };
            }
        }
        let least = (per_slot.iter()).fold(f32::INFINITY, |m, &x| if x < m { x } else { m });
        if least == f32::INFINITY {
            break;
        }
        let k = cost.iter().position(|&x| x == least).unwrap_or(0);
        let (c, s) = (k / 8, k % 8);
        slot_of[c] = s;
        // Child c is assigned, slot s is filled.
        cost[c * 8..c * 8 + 8].fill(f32::INFINITY);
        for row in cost.chunks_exact_mut(8) {
            row[s] = f32::INFINITY;
        }
    }
    let original = std::mem::replace(children, [EMPTY; 8]);
    let mut free = (0..8).filter(|&s| !slot_of.contains(&s));
    for (c, &slot) in slot_of.iter().enumerate().take(count) {
        // A child whose every cost is NaN (a box with NaN corners, which the renderer never
        // builds) made obvhs panic; here it takes a free slot.
        let slot = if slot == usize::MAX {
            free.next().unwrap_or(c)
        } else {
            slot
        };
        children[slot] = original[c];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::triangle::Triangle;

    /// The BVH2 PLOC builds from `tris` (leaves of one triangle), as the renderer's build does.
    fn bvh2_of(tris: &[Triangle]) -> Bvh2 {
        let params = obvhs::BvhBuildParams::medium_build();
        let mut bvh2 = Bvh2::default();
        obvhs::ploc::PlocBuilder::with_capacity(tris.len()).build_ploc::<14, Triangle>(
            &mut bvh2,
            tris,
            (0..tris.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        bvh2
    }

    /// Node for node and primitive for primitive obvhs' conversion with ordered children, for
    /// every leaf size: on a sphere with a plane, a soup of random triangles, a grid of equal
    /// triangles (children whose costs tie), triangles all with one centre (every cost zero,
    /// signed zeros included) and meshes of one to nine triangles.
    #[test]
    fn sah_conversion_is_obvhs_conversion() {
        let mut rng = crate::render::sampler::Sampler::from_seed(3);
        let mut v = || glam::Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 2.0 - 1.0;
        let tri = |a: glam::Vec3, b: glam::Vec3, c: glam::Vec3| Triangle {
            v0: a.into(),
            v1: b.into(),
            v2: c.into(),
        };
        let mut sphere: Vec<Triangle> = obvhs::test_util::geometry::icosphere(4);
        sphere.extend(obvhs::test_util::geometry::PLANE);
        let soup: Vec<Triangle> = (0..3000)
            .map(|_| {
                let c = v();
                tri(c, c + v() * 0.2, c + v() * 0.2)
            })
            .collect();
        let grid: Vec<Triangle> = (0..40 * 40)
            .map(|k| {
                let o = glam::Vec3::new((k % 40) as f32, 0.0, (k / 40) as f32);
                tri(o, o + glam::Vec3::X, o + glam::Vec3::Z)
            })
            .collect();
        // Triangles through one point in every direction: their boxes share a centre.
        let star: Vec<Triangle> = (0..64)
            .map(|_| {
                let d = v();
                tri(-d, d, glam::Vec3::ZERO)
            })
            .collect();
        let mut meshes = vec![sphere, soup.clone(), grid, star];
        meshes.extend((1..=9).map(|n| soup[..n].to_vec()));
        for tris in &meshes {
            let bvh2 = bvh2_of(tris);
            for leaf in 1..=3 {
                let ours = convert(&bvh2, leaf);
                let theirs = obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh(&bvh2, leaf, true, false);
                assert_eq!(ours.primitive_indices, theirs.primitive_indices);
                assert_eq!(ours.nodes.len(), theirs.nodes.len());
                for (k, (a, b)) in ours.nodes.iter().zip(&theirs.nodes).enumerate() {
                    assert!(a == b, "{} triangles, leaf {leaf}, node {k}", tris.len());
                }
                assert_eq!(ours.total_aabb, theirs.total_aabb);
            }
        }
    }

    /// The slots are those of obvhs' `order_children` for 2–8 children of random boxes whose
    /// centre offsets mix magnitudes (so that the summation order of a cost decides a
    /// minimum), repeat values (ties) and signed zeros.
    #[test]
    fn children_take_obvhs_slots() {
        let mut rng = crate::render::sampler::Sampler::from_seed(11);
        let values = [0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 1.0e8, -1.0e8, 1.0e-7, 12.0];
        let pick = |rng: &mut crate::render::sampler::Sampler| {
            let v = values[(rng.next_1d() * values.len() as f32) as usize % values.len()];
            if rng.next_1d() < 0.3 {
                v + rng.next_1d() * 4.0 - 2.0
            } else {
                v
            }
        };
        for round in 0..20_000 {
            let count = 2 + round % 7;
            let mut nodes = Vec::new();
            for _ in 0..=count {
                let c = glam::Vec3A::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
                let h = glam::Vec3A::splat(rng.next_1d());
                let b = obvhs::aabb::Aabb::new(c - h, c + h);
                nodes.push(obvhs::bvh2::node::Bvh2Node::new(b, 1, 0));
            }
            let bvh2 = Bvh2 {
                nodes,
                ..Default::default()
            };
            let mut ours = [EMPTY; 8];
            for (k, c) in ours.iter_mut().enumerate().take(count) {
                *c = k as u32 + 1;
            }
            let mut theirs = ours;
            order_children(&bvh2, 0, &mut ours, count);
            Bvh2Converter::new(&bvh2, true, false).order_children(0, &mut theirs, count);
            assert_eq!(ours, theirs, "round {round}");
        }
    }
}
