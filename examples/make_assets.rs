//! Regenerates the scene assets the project makes itself:
//! - `scenes/meshes/teapot.ply` — Newell's Utah teapot tessellated (src/scene/teapot.rs);
//! - `scenes/textures/studio.exr` — the procedural studio sky (src/scene/sky.rs);
//! - `scenes/textures/thickness_example.exr` — a smooth synthetic film-thickness map in nm
//!   (one channel named `Y`, so Mitsuba's bitmap plugin reads it as a monochrome texture).
//!
//! Run from the repository root: `cargo run --release --example make_assets [OUT_DIR]`
//! (OUT_DIR defaults to `scenes`).

use anyhow::Result;
use std::path::PathBuf;
use thinfilm::image_io::write_exr_channels;
use thinfilm::scene::{meshio, sky, teapot};

fn main() -> Result<()> {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("scenes"));
    let mesh = teapot::teapot_mesh(teapot::DEFAULT_SUBDIVISIONS);
    let ply = out.join("meshes/teapot.ply");
    meshio::write_ply_binary(&ply, &mesh)?;
    let (lo, hi) = mesh.bounds().expect("teapot has vertices");
    println!(
        "{}: {} vertices, {} triangles, bounds {lo} .. {hi}",
        ply.display(),
        mesh.positions.len(),
        mesh.indices.len()
    );

    let (w, h) = sky::STUDIO_SIZE;
    let env = sky::studio_environment(w, h);
    let exr = out.join("textures/studio.exr");
    sky::write_exr_rgb_half(&exr, &env)?;
    println!("{}: {w}×{h} half-float RGB", exr.display());

    let (tw, th) = (256, 256);
    let thickness = sky::thickness_example(tw, th);
    let path = out.join("textures/thickness_example.exr");
    write_exr_channels(&path, tw, th, &[("Y", &thickness)])?;
    let (mn, mx) = thickness
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    println!("{}: {tw}×{th}, {mn:.1}–{mx:.1} nm", path.display());
    Ok(())
}
