//! Checks shared by the integration tests that compare a render with a Mitsuba 3 reference.

use thinfilm::image_io::RgbImage;

/// Mean of channel `c` over the image.
pub fn channel_mean(img: &RgbImage, c: usize) -> f64 {
    img.pixels.iter().map(|p| p[c] as f64).sum::<f64>() / img.pixels.len() as f64
}

/// `got` against `reference` (same size): each channel's image mean within `mean_tol`
/// (relative), and every bright 8×8 block (sum over its pixels and channels above a quarter
/// of an average block) within `block_tol`. Returns the worst bright-block deviation.
pub fn assert_means_and_blocks(
    name: &str,
    got: &RgbImage,
    reference: &RgbImage,
    mean_tol: f64,
    block_tol: f64,
) -> f64 {
    let (w, h) = (got.width, got.height);
    assert_eq!((w, h), (reference.width, reference.height), "{name}: size");
    for c in 0..3 {
        let (g, want) = (channel_mean(got, c), channel_mean(reference, c));
        let ratio = g / want;
        println!("{name}: channel {c}: thinfilm {g:.5}, Mitsuba {want:.5}, ratio {ratio:.4}");
        assert!(
            (ratio - 1.0).abs() <= mean_tol,
            "{name}: channel {c} mean ratio {ratio:.4}"
        );
    }
    let block = |px: &[[f32; 3]], bx: usize, by: usize| {
        let mut s = 0.0f64;
        for y in by * 8..(by * 8 + 8).min(h) {
            for x in bx * 8..(bx * 8 + 8).min(w) {
                s += px[y * w + x].iter().map(|v| *v as f64).sum::<f64>();
            }
        }
        s
    };
    let image_mean: f64 = (0..3).map(|c| channel_mean(reference, c)).sum::<f64>() * 64.0;
    let mut worst = 0.0f64;
    for by in 0..h.div_ceil(8) {
        for bx in 0..w.div_ceil(8) {
            let (g, want) = (block(&got.pixels, bx, by), block(&reference.pixels, bx, by));
            if want > 0.25 * image_mean {
                let r = g / want;
                worst = worst.max((r - 1.0).abs());
                assert!(
                    (r - 1.0).abs() <= block_tol,
                    "{name}: block ({bx}, {by}) ratio {r:.3}"
                );
            }
        }
    }
    worst
}
