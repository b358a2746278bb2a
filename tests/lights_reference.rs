//! Emitters and sensors against Mitsuba 3: the scenes of `tests/references/lights/` (spot,
//! directional, thin lens, orthographic) rendered by thinfilm and compared with the
//! references `tools/mitsuba/render_light_references.py` made from the same files. The
//! image mean must agree within 2 % per channel, every bright 8×8 block within 8 % (which
//! catches a cone or a view extent in the wrong place), and for the thin lens the edge
//! energy of its checkerboard floor within 10 % (a pinhole's is 1.5× too high: the lens must
//! blur as much as Mitsuba's).

mod common;

use std::path::Path;
use thinfilm::render::{render, RenderOptions};

fn compare(name: &str, spp: u32, check_edges: bool) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/references/lights");
    let scene = thinfilm::scene::load(&dir.join(format!("{name}.xml")), &[]).expect("scene loads");
    let reference = thinfilm::image_io::read_exr_rgb(&dir.join(format!("{name}.exr"))).unwrap();
    let out = render(
        &scene,
        &RenderOptions {
            spp: Some(spp),
            seed: Some(5),
            ..Default::default()
        },
    )
    .expect("render");
    common::assert_means_and_blocks(name, &out.image, &reference, 0.02, 0.08);
    let (w, h) = (out.image.width, out.image.height);
    // Edge energy of the 2×2-binned luminance: a lens blurs edges, a pinhole does not.
    let sharpness = |px: &[[f32; 3]]| {
        let (bw, bh) = (w / 2, h / 2);
        let lum = |x: usize, y: usize| -> f64 {
            let mut s = 0.0;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let p = px[(2 * y + dy) * w + 2 * x + dx];
                s += 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
            }
            s
        };
        let mut g = 0.0;
        for y in 0..bh - 1 {
            for x in 0..bw - 1 {
                g += (lum(x + 1, y) - lum(x, y)).abs() + (lum(x, y + 1) - lum(x, y)).abs();
            }
        }
        g
    };
    if check_edges {
        let r = sharpness(&out.image.pixels) / sharpness(&reference.pixels);
        println!("{name}: edge energy ratio {r:.4}");
        assert!((r - 1.0).abs() <= 0.1, "{name}: edge energy ratio {r:.3}");
    }
}

#[test]
fn spot_matches_mitsuba() {
    compare("spot", 256, false);
}

#[test]
fn spot_with_default_cone_matches_mitsuba() {
    compare("spot_default", 256, false);
}

#[test]
fn directional_matches_mitsuba() {
    compare("directional", 256, false);
}

#[test]
fn thinlens_matches_mitsuba() {
    compare("thinlens", 1024, true);
}

#[test]
fn orthographic_matches_mitsuba() {
    compare("orthographic", 256, false);
}
