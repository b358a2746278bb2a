//! Mitsuba's `projector` emitter against Mitsuba 3: `tests/references/projector/projector.xml`
//! (a textured projector — an asymmetric 8×4 slide, so a mirrored or transposed image would
//! land colours in the wrong place — and a constant one, on a floor and a sphere) rendered by
//! thinfilm and compared with the reference `tools/mitsuba/render_light_references.py --dir
//! tests/references/projector` made from the same file: the image mean within 2 % per channel,
//! and every 8×8 block holding light within 8 % per channel.

use std::path::Path;
use thinfilm::render::{render, RenderOptions};

#[test]
fn projector_matches_mitsuba() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/references/projector");
    let scene = thinfilm::scene::load(&dir.join("projector.xml"), &[]).expect("scene loads");
    let reference = thinfilm::image_io::read_exr_rgb(&dir.join("projector.exr")).unwrap();
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(256),
            seed: Some(3),
            ..Default::default()
        },
    )
    .expect("render");
    let (w, h) = (out.image.width, out.image.height);
    assert_eq!((w, h), (reference.width, reference.height));
    let mean =
        |px: &[[f32; 3]], c: usize| px.iter().map(|p| p[c] as f64).sum::<f64>() / px.len() as f64;
    for c in 0..3 {
        let (got, want) = (mean(&out.image.pixels, c), mean(&reference.pixels, c));
        assert!(want > 0.01, "channel {c}: the reference is dark");
        let ratio = got / want;
        assert!(
            (ratio - 1.0).abs() <= 0.02,
            "channel {c}: mean ratio {ratio:.4}"
        );
    }
    let block = |px: &[[f32; 3]], bx: usize, by: usize, c: usize| {
        let mut s = 0.0f64;
        for y in by * 8..(by * 8 + 8).min(h) {
            for x in bx * 8..(bx * 8 + 8).min(w) {
                s += px[y * w + x][c] as f64;
            }
        }
        s
    };
    let brightest = (0..3)
        .map(|c| mean(&reference.pixels, c) * 64.0)
        .fold(0.0, f64::max);
    let mut lit = 0;
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            for c in 0..3 {
                let (got, want) = (
                    block(&out.image.pixels, bx, by, c),
                    block(&reference.pixels, bx, by, c),
                );
                if want > 0.5 * brightest {
                    lit += 1;
                    let ratio = got / want;
                    assert!(
                        (ratio - 1.0).abs() <= 0.08,
                        "block ({bx}, {by}) channel {c}: ratio {ratio:.3}"
                    );
                }
            }
        }
    }
    assert!(lit >= 20, "only {lit} lit blocks");
}
