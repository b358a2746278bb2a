//! Sample passes: the order in which a render of samples `[s0, s1)` visits its samples, so
//! that it can stop after any pass (Ctrl-C, a batch system's time limit) with an image that
//! still merges exactly with renders of the samples it did not reach.
//!
//! The box-filtered film sums a pixel's samples in a fixed binary tree over their indices
//! relative to `s0` ([`super::film::tree_sum`]): `n` samples split at the largest power of two
//! below `n` (at `n/2` when `n` is one), so the top level is a chain of power-of-two *blocks*
//! in decreasing size (`n = 56`: 32 + 16 + 8, summed as `B32 + (B16 + B8)`), and each block is
//! a perfect binary tree. A block of `2^k` samples is rendered in doubling passes —
//! `[0, 16)`, `[16, 32)`, `[32, 64)`, … — and each pass's sum added to the block's running
//! sum: `[0, 2m) = [0, m) + [m, 2m)` is exactly the tree's own addition, so a pass-by-pass
//! render is bit-identical to summing all samples at once, and after every pass of the first
//! block the running sum is the complete tree of the power-of-two prefix `[0, 2^j)`.
//!
//! A mean of a power-of-two number of samples times that number is its sum, exactly (scaling
//! by a power of two only moves the exponent), so such a prefix, written as an ordinary image,
//! merges exactly with renders of the remaining tree nodes ([`remaining_nodes`]); `thinfilm
//! merge` does the arithmetic.

/// Smallest pass: one batch of the wavefront integrator (`render::batch::BATCH`), so passes
/// never run partial batches except in renders of fewer samples.
pub const MIN_PASS: u32 = 16;

/// A power-of-two run of samples at the top level of the summation tree, with its passes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Block {
    /// Absolute sample indices `[start, end)`.
    pub range: (u32, u32),
    /// Absolute sample ranges of the passes, in order; they tile `range`.
    pub passes: Vec<(u32, u32)>,
}

/// The blocks and passes of a render of samples `[s0, s1)`.
pub fn plan(range: (u32, u32)) -> Vec<Block> {
    let (s0, s1) = range;
    let mut blocks = Vec::new();
    let mut start = s0;
    while start < s1 {
        let len = largest_power_of_two_at_most(s1 - start);
        let first = len.min(MIN_PASS);
        let mut passes = vec![(start, start + first)];
        let mut done = first;
        while done < len {
            passes.push((start + done, start + 2 * done));
            done *= 2;
        }
        blocks.push(Block {
            range: (start, start + len),
            passes,
        });
        start += len;
    }
    blocks
}

fn largest_power_of_two_at_most(n: u32) -> u32 {
    debug_assert!(n > 0);
    1 << (u32::BITS - 1 - n.leading_zeros())
}

/// The nodes of the summation tree of `[s0, s1)` that, rendered one by one (`--sample-range`)
/// and merged with a render of the prefix `[s0, done_end)` (a power-of-two number of samples
/// from the start of the first block), give exactly the render of `[s0, s1)`: the rest of
/// the first block in doubling ranges, then every later block whole.
pub fn remaining_nodes(range: (u32, u32), done_end: u32) -> Vec<(u32, u32)> {
    let blocks = plan(range);
    let mut out = Vec::new();
    let Some(first) = blocks.first() else {
        return out;
    };
    let mut at = done_end;
    while at < first.range.1 {
        let len = at - range.0;
        out.push((at, at + len));
        at += len;
    }
    out.extend(blocks[1..].iter().map(|b| b.range));
    out
}

/// Part `index` of `count` equal parts of a render of `spp` samples per pixel: samples
/// `⌊k·spp/N⌋ .. ⌊(k+1)·spp/N⌋`. When `spp` and `count` are powers of two every part is a
/// node of the summation tree, so the parts merge bit-identically.
pub fn part(spp: u32, index: u32, count: u32) -> anyhow::Result<(u32, u32)> {
    if index >= count || count > spp {
        anyhow::bail!("--part {index}/{count} must satisfy K < N ≤ {spp} (the samples per pixel)");
    }
    let at = |k: u32| (k as u64 * spp as u64 / count as u64) as u32;
    Ok((at(index), at(index + 1)))
}

/// Whether `[a, b)` is a node of the summation tree of a render of `range` (see the module
/// documentation): the tree's own subtrees, found by descending from the root.
pub fn is_tree_node(range: (u32, u32), node: (u32, u32)) -> bool {
    let (mut lo, mut hi) = range;
    loop {
        if (lo, hi) == node {
            return true;
        }
        let n = hi - lo;
        if n < 2 || node.0 < lo || node.1 > hi {
            return false;
        }
        let half = if n.is_power_of_two() {
            n / 2
        } else {
            largest_power_of_two_at_most(n)
        };
        let mid = lo + half;
        if node.1 <= mid {
            hi = mid;
        } else if node.0 >= mid {
            lo = mid;
        } else {
            return false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::film::tree_sum;

    #[test]
    fn blocks_are_the_binary_digits_and_passes_double() {
        let p = plan((0, 56));
        let ranges: Vec<_> = p.iter().map(|b| b.range).collect();
        assert_eq!(ranges, vec![(0, 32), (32, 48), (48, 56)]);
        assert_eq!(p[0].passes, vec![(0, 16), (16, 32)]);
        assert_eq!(p[1].passes, vec![(32, 48)]);
        assert_eq!(p[2].passes, vec![(48, 56)]);
        let p = plan((100, 1124));
        assert_eq!(p.len(), 1);
        assert_eq!(
            p[0].passes,
            vec![
                (100, 116),
                (116, 132),
                (132, 164),
                (164, 228),
                (228, 356),
                (356, 612),
                (612, 1124)
            ]
        );
        assert_eq!(plan((3, 4))[0].passes, vec![(3, 4)]);
    }

    /// Summing pass by pass (running block sums, blocks combined right to left) gives the
    /// bits of the one-shot tree sum, for every length up to 300.
    #[test]
    fn pass_sums_equal_the_tree_sum() {
        for n in 1..=300u32 {
            let vals: Vec<[f32; 3]> = (0..n)
                .map(|i| {
                    let x = i as f32;
                    [(x * 0.377).sin() * 1e3, 0.1 * x + 1e-3, 1.0 / (x + 1.0)]
                })
                .collect();
            let add = |a: [f32; 3], b: [f32; 3]| [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
            let mut block_sums = Vec::new();
            for block in plan((0, n)) {
                let mut sum: Option<[f32; 3]> = None;
                for (a, b) in block.passes {
                    let s = tree_sum(&vals[a as usize..b as usize]);
                    sum = Some(sum.map_or(s, |t| add(t, s)));
                }
                block_sums.push(sum.unwrap());
            }
            let total = block_sums.into_iter().rev().reduce(|acc, b| add(b, acc));
            assert_eq!(
                total.unwrap().map(f32::to_bits),
                tree_sum(&vals).map(f32::to_bits),
                "n = {n}"
            );
        }
    }

    #[test]
    fn remaining_nodes_complete_the_prefix() {
        assert_eq!(
            remaining_nodes((0, 1024), 256),
            vec![(256, 512), (512, 1024)]
        );
        assert_eq!(
            remaining_nodes((0, 56), 16),
            vec![(16, 32), (32, 48), (48, 56)]
        );
        assert_eq!(remaining_nodes((64, 128), 96), vec![(96, 128)]);
        assert!(remaining_nodes((0, 64), 64).is_empty());
        for (range, done) in [((0, 1000), 64), ((5, 77), 21), ((0, 56), 32)] {
            for node in remaining_nodes(range, done) {
                assert!(is_tree_node(range, node), "{node:?} of {range:?}");
                assert!((node.1 - node.0).is_power_of_two());
            }
            assert!(is_tree_node(range, (range.0, done)));
        }
    }

    #[test]
    fn equal_parts_of_power_of_two_renders_are_tree_nodes() {
        for (spp, count) in [(64, 4), (1024, 8), (16, 16), (256, 1)] {
            let mut next = 0;
            for k in 0..count {
                let r = part(spp, k, count).unwrap();
                assert_eq!(r.0, next);
                assert!(is_tree_node((0, spp), r), "{r:?} of {spp}");
                next = r.1;
            }
            assert_eq!(next, spp);
        }
        assert_eq!(part(100, 2, 3).unwrap(), (66, 100));
        assert!(part(8, 3, 3).is_err());
        assert!(part(4, 0, 8).is_err());
    }

    #[test]
    fn tree_nodes() {
        assert!(is_tree_node((0, 64), (0, 64)));
        assert!(is_tree_node((0, 64), (16, 32)));
        assert!(!is_tree_node((0, 64), (16, 48)));
        assert!(is_tree_node((0, 24), (16, 24)));
        assert!(!is_tree_node((0, 24), (8, 24)));
        assert!(is_tree_node((0, 56), (32, 56)));
        assert!(!is_tree_node((0, 56), (0, 48)));
        assert!(!is_tree_node((0, 64), (60, 70)));
    }
}
