//! BVH2 → compressed wide BVH (CWBVH, Ylitie et al. 2017) by greedy collapse, for fast
//! builds of large meshes.
//!
//! obvhs' converter picks each 8-wide node's children by dynamic programming over the
//! BVH2's SAH costs (Ylitie et al. §4.1): a table of 7 decisions per BVH2 node (8 bytes
//! each: ~220 MB at 2M triangles, the build's peak memory) and ~40 % of a fast build's time.
//! Here each wide node takes its BVH2 node's two children and opens the child with the
//! largest surface area until it has eight (the classic collapse of Wald et al. 2008):
//! first children that must be interior (more than [`MAX_LEAF_PRIMS`] primitives), then
//! small subtrees, so that leaves are as tight as they can be. Subtrees of at most three
//! primitives become one leaf slot. No cost table, one byte per BVH2 node of state.
//!
//! The layout is obvhs' (node quantisation, child metadata, contiguous interior children
//! and leaf primitives), so the renderer's CWBVH traversals run on it unchanged; children
//! are not ordered by octant. Any BVH over the same triangles gives the same closest hits
//! (test `greedy_collapse_finds_the_hits_of_obvhs_conversion`). The node encoding (grid,
//! child boxes, leaf metadata) is shared with the SAH conversion ([`super::bvh_sah`]).

use glam::Vec3A;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::{node::CwBvhNode, CwBvh};

/// Primitives a CWBVH leaf slot holds at most (three bits of unary count in its metadata).
const MAX_LEAF_PRIMS: u8 = 3;
/// 1 / (2⁸ − 1): child boxes are quantised to 8 bits per axis and side.
const DENOM: f32 = 1.0 / 255.0;

/// The CWBVH of `bvh2` (leaves of one primitive each, as PLOC builds them).
pub(super) fn collapse(bvh2: &Bvh2) -> CwBvh {
    if bvh2.nodes.is_empty() {
        return CwBvh::default();
    }
    let small = small_subtrees(bvh2);
    let mut out = CwBvh {
        nodes: vec![CwBvhNode::default()],
        primitive_indices: Vec::with_capacity(bvh2.primitive_indices.len()),
        total_aabb: *bvh2.nodes[0].aabb(),
        exact_node_aabbs: None,
        uses_spatial_splits: bvh2.uses_spatial_splits,
    };
    // (wide node, BVH2 node it stands for); depth-first, as obvhs lays nodes out.
    let mut todo = vec![(0usize, 0usize)];
    while let Some((wide, node2)) = todo.pop() {
        let slots = children(bvh2, &small, node2);
        let interior = fill_node(bvh2, &small, &mut out, wide, node2, &slots);
        // Pushed in reverse so the first interior child is converted first.
        todo.extend(interior.into_iter().rev());
    }
    out
}

/// Primitive count of every BVH2 subtree, capped at `MAX_LEAF_PRIMS + 1` (one byte each;
/// only "fits in one leaf slot or not" matters).
fn small_subtrees(bvh2: &Bvh2) -> Vec<u8> {
    let mut count = vec![0u8; bvh2.nodes.len()];
    // Post-order without recursion: BVH2 depth is unbounded on hostile meshes.
    let mut stack = vec![(0u32, false)];
    while let Some((i, children_done)) = stack.pop() {
        let node = &bvh2.nodes[i as usize];
        if node.is_leaf() {
            assert!(
                node.prim_count <= MAX_LEAF_PRIMS as u32,
                "PLOC leaves hold one primitive"
            );
            count[i as usize] = node.prim_count as u8;
        } else if children_done {
            let (l, r) = (node.first_index as usize, node.first_index as usize + 1);
            count[i as usize] = (count[l] + count[r]).min(MAX_LEAF_PRIMS + 1);
        } else {
            stack.push((i, true));
            stack.push((node.first_index, false));
            stack.push((node.first_index + 1, false));
        }
    }
    count
}

/// The BVH2 nodes that become the eight (or fewer) child slots of `node2`'s wide node.
fn children(bvh2: &Bvh2, small: &[u8], node2: usize) -> Vec<u32> {
    let node = &bvh2.nodes[node2];
    if node.is_leaf() || small[node2] <= MAX_LEAF_PRIMS {
        return vec![node2 as u32];
    }
    let mut slots = vec![node.first_index, node.first_index + 1];
    // Open the largest child that must be interior, then the largest small subtree.
    for must_be_interior in [true, false] {
        while slots.len() < 8 {
            let open = (slots.iter().enumerate())
                .filter(|&(_, &c)| {
                    let n = &bvh2.nodes[c as usize];
                    !n.is_leaf() && (small[c as usize] > MAX_LEAF_PRIMS) == must_be_interior
                })
                .max_by(|a, b| {
                    let area = |c: u32| bvh2.nodes[c as usize].aabb().half_area();
                    area(*a.1).total_cmp(&area(*b.1))
                })
                .map(|(k, _)| k);
            let Some(k) = open else { break };
            let first = bvh2.nodes[slots[k] as usize].first_index;
            slots[k] = first;
            slots.push(first + 1);
        }
    }
    slots
}

/// Writes wide node `wide` (for BVH2 node `node2`) with child `slots`: quantised child
/// boxes, leaf primitives appended to the primitive list, interior children allocated
/// contiguously. Returns the (wide node, BVH2 node) pairs still to convert.
fn fill_node(
    bvh2: &Bvh2,
    small: &[u8],
    out: &mut CwBvh,
    wide: usize,
    node2: usize,
    slots: &[u32],
) -> Vec<(usize, usize)> {
    let aabb = bvh2.nodes[node2].aabb();
    let mut node = CwBvhNode::default();
    let rcp_e = set_grid(&mut node, aabb);
    node.primitive_base_idx = out.primitive_indices.len() as u32;
    node.child_base_idx = out.nodes.len() as u32;
    let mut interior = Vec::new();
    let mut prims_in_node = 0u8;
    for (i, &c) in slots.iter().enumerate() {
        set_child_box(&mut node, i, bvh2.nodes[c as usize].aabb(), aabb.min, rcp_e);
        if small[c as usize] <= MAX_LEAF_PRIMS {
            let n = push_primitives(bvh2, c, &mut out.primitive_indices);
            node.child_meta[i] = leaf_meta(prims_in_node, n);
            prims_in_node += n;
        } else {
            node.imask |= 1 << i;
            node.child_meta[i] = (24 + i as u8) | 0b0010_0000;
            interior.push((out.nodes.len() + interior.len(), c as usize));
        }
    }
    out.nodes
        .resize(out.nodes.len() + interior.len(), CwBvhNode::default());
    out.nodes[wide] = node;
    interior
}

/// Appends the primitives of BVH2 subtree `c` (at most three) in left-to-right order and
/// returns how many.
pub(super) fn push_primitives(bvh2: &Bvh2, c: u32, prims: &mut Vec<u32>) -> u8 {
    let before = prims.len();
    push_subtree(bvh2, c, prims);
    (prims.len() - before) as u8
}

fn push_subtree(bvh2: &Bvh2, c: u32, prims: &mut Vec<u32>) {
    let node = &bvh2.nodes[c as usize];
    if node.is_leaf() {
        let first = node.first_index as usize;
        prims.extend_from_slice(&bvh2.primitive_indices[first..first + node.prim_count as usize]);
    } else {
        push_subtree(bvh2, node.first_index, prims);
        push_subtree(bvh2, node.first_index + 1, prims);
    }
}

/// A leaf slot's metadata: the unary count of its `n` (1–3) primitives in the top three
/// bits, the offset of its first among the node's primitives in the low five.
pub(super) fn leaf_meta(offset: u8, n: u8) -> u8 {
    assert!(
        (1..=MAX_LEAF_PRIMS).contains(&n),
        "a CWBVH leaf slot holds 1–3 primitives, not {n}"
    );
    offset | (((1u8 << n) - 1) << 5)
}

/// Sets `node`'s quantisation grid over `aabb` and returns 1/e (obvhs'
/// `convert_to_cwbvh_impl`): origin p = the box's minimum, per axis the smallest power of
/// two e whose 255 steps span the box, so that the quantised child boxes stay conservative.
pub(super) fn set_grid(node: &mut CwBvhNode, aabb: &obvhs::aabb::Aabb) -> Vec3A {
    node.p = aabb.min.into();
    let e = ((aabb.max - aabb.min).max(Vec3A::splat(1e-20)) * DENOM)
        .log2()
        .ceil()
        .exp2();
    node.e = e.to_array().map(|c| (c.to_bits() >> 23) as u8);
    1.0 / e
}

/// Slot `i`'s box `child` on the node's grid (origin `p`, steps 1/`rcp_e`), rounded
/// outwards and clamped to the 8-bit range.
pub(super) fn set_child_box(
    node: &mut CwBvhNode,
    i: usize,
    child: &obvhs::aabb::Aabb,
    p: Vec3A,
    rcp_e: Vec3A,
) {
    let lo = ((child.min - p) * rcp_e)
        .floor()
        .clamp(Vec3A::ZERO, Vec3A::splat(255.0));
    let hi = ((child.max - p) * rcp_e)
        .ceil()
        .clamp(Vec3A::ZERO, Vec3A::splat(255.0));
    (
        node.child_min_x[i],
        node.child_min_y[i],
        node.child_min_z[i],
    ) = (lo.x as u8, lo.y as u8, lo.z as u8);
    (
        node.child_max_x[i],
        node.child_max_y[i],
        node.child_max_z[i],
    ) = (hi.x as u8, hi.y as u8, hi.z as u8);
}
