//! Regenerates the scene assets the project makes itself:
//! - `scenes/meshes/teapot.ply` — Newell's Utah teapot tessellated (src/scene/teapot.rs);
//! - `scenes/textures/studio.exr` — the procedural studio sky (src/scene/sky.rs);
//! - `scenes/textures/thickness_example.exr` — a smooth synthetic film-thickness map in nm
//!   (one channel named `Y`, so Mitsuba's bitmap plugin reads it as a monochrome texture).
//! - `scenes/textures/bubble_thickness.exr` — soap-film thickness in nm on a sphere's (u, v)
//!   (v = 0 at the top pole): gravity drainage, thin (~30 nm, "black film") at the top and
//!   ~900 nm at the bottom, with swirls; periodic in u so the sphere has no seam.
//! - `scenes/meshes/lens.ply` — a biconvex lens (aperture radius 1, both surfaces of
//!   curvature radius 2.5, edge thickness 0.06; optical axis +z), analytic normals.
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

    let (bw, bh) = (256, 128);
    let bubble = bubble_thickness(bw, bh);
    let path = out.join("textures/bubble_thickness.exr");
    write_exr_channels(&path, bw, bh, &[("Y", &bubble)])?;
    let (mn, mx) = bubble
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    println!("{}: {bw}×{bh}, {mn:.1}–{mx:.1} nm", path.display());

    let lens = lens_mesh(1.0, 2.5, 0.06, 24, 96);
    let ply = out.join("meshes/lens.ply");
    meshio::write_ply_binary(&ply, &lens)?;
    println!(
        "{}: {} vertices, {} triangles",
        ply.display(),
        lens.positions.len(),
        lens.indices.len()
    );
    Ok(())
}

/// A symmetric biconvex lens around the z axis: two spherical caps (curvature radius
/// `curvature`, aperture radius `aperture`) joined by a cylindrical rim of height `edge`.
/// Caps and rim have separate vertices so the edges stay sharp; normals are the analytic
/// outward sphere / cylinder normals; triangles wind counter-clockwise seen from outside.
fn lens_mesh(
    aperture: f32,
    curvature: f32,
    edge: f32,
    rings: u32,
    segments: u32,
) -> thinfilm::scene::TriangleMesh {
    use glam::Vec3;
    use std::f32::consts::PI;
    let mut m = thinfilm::scene::TriangleMesh::default();
    let sag = curvature - (curvature * curvature - aperture * aperture).sqrt();
    let half = 0.5 * edge;
    for side in [1.0f32, -1.0] {
        // Sphere centre on the axis, behind the cap's vertex: z = side·(half + sag − R).
        let centre = Vec3::new(0.0, 0.0, side * (half + sag - curvature));
        let base = m.positions.len() as u32;
        m.positions.push(Vec3::new(0.0, 0.0, side * (half + sag)));
        m.normals.push(Vec3::new(0.0, 0.0, side));
        for i in 1..=rings {
            let r = aperture * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = 2.0 * PI * j as f32 / segments as f32;
                let (x, y) = (r * phi.cos(), r * phi.sin());
                let z = centre.z + side * (curvature * curvature - r * r).sqrt();
                let p = Vec3::new(x, y, z);
                m.positions.push(p);
                m.normals.push((p - centre).normalize());
            }
        }
        let ring = |i: u32, j: u32| base + 1 + (i - 1) * segments + (j % segments);
        let mut tri = |a: u32, b: u32, c: u32| {
            m.indices
                .push(if side > 0.0 { [a, b, c] } else { [a, c, b] });
        };
        for j in 0..segments {
            tri(base, ring(1, j), ring(1, j + 1));
        }
        for i in 1..rings {
            for j in 0..segments {
                tri(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
                tri(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
            }
        }
    }
    // Rim: a cylinder of radius `aperture` from z = −half to +half.
    let base = m.positions.len() as u32;
    for j in 0..segments {
        let phi = 2.0 * PI * j as f32 / segments as f32;
        let n = Vec3::new(phi.cos(), phi.sin(), 0.0);
        for z in [-half, half] {
            m.positions.push(n * aperture + Vec3::new(0.0, 0.0, z));
            m.normals.push(n);
        }
    }
    for j in 0..segments {
        let k = (j + 1) % segments;
        let (b0, t0, b1, t1) = (
            base + 2 * j,
            base + 2 * j + 1,
            base + 2 * k,
            base + 2 * k + 1,
        );
        m.indices.push([b0, b1, t1]);
        m.indices.push([b0, t1, t0]);
    }
    m
}

/// Soap-bubble thickness (nm) over a sphere's Mitsuba UVs (u = φ/2π, v = θ/π, θ from the top
/// pole +z). A draining film thins from the top: its thickness grows roughly as a power of
/// the depth below the top (the marginal-regeneration profile of draining vertical soap films,
/// h ∝ depth^½…^1; here ^1.4 for a visible band sequence), plus convective swirls whose
/// amplitude vanishes at the poles. Periodic in u (integer angular frequencies).
fn bubble_thickness(width: usize, height: usize) -> Vec<f32> {
    use std::f32::consts::PI;
    let mut out = Vec::with_capacity(width * height);
    for i in 0..height {
        for j in 0..width {
            let u = (j as f32 + 0.5) / width as f32;
            let v = (i as f32 + 0.5) / height as f32;
            let base = 30.0 + 870.0 * v.powf(1.4);
            let phase = 2.0 * PI * (3.0 * u) + 9.0 * v + 1.5 * (2.0 * PI * u).sin();
            let swirl = 90.0 * (PI * v).sin() * phase.sin()
                + 40.0 * (PI * v).sin().powi(2) * (2.0 * PI * 5.0 * u - 14.0 * v).sin();
            out.push((base + swirl).max(10.0));
        }
    }
    out
}
