//! Ray traversal alone, against Embree through Mitsuba 3: closest-hit and any-hit queries of
//! N incoherent rays (origins uniform in the scene's triangle bounds grown by 10 %, directions
//! uniform on the sphere), timed over all cores with the renderer's own `Accel`, median of
//! five runs, in ns of wall time per ray. The rays are written to RAYS.f32 (six f32 per ray:
//! origin, direction) so that `tools/mitsuba/trace_rays.py` times Mitsuba's
//! `ray_intersect_preliminary` / `ray_test` (Embree in the LLVM variants) on the same rays.
//!
//! ```sh
//! cargo run --release --example trace_rays -- scenes/teapot_diffuse.xml /tmp/rays.f32
//! python3 tools/mitsuba/trace_rays.py scenes/teapot_diffuse.xml /tmp/rays.f32
//! ```

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::io::Write;
use thinfilm::render::camera::Ray;
use thinfilm::scene::Geometry;

fn main() {
    if let Err(err) = run() {
        eprintln!("error: {err:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, scene_path, rays_path, rest @ ..] = args.as_slice() else {
        bail!("usage: trace_rays SCENE RAYS.f32 [N]");
    };
    let n: usize = match rest.first() {
        Some(s) => match s.parse() {
            Ok(n) if n > 0 => n,
            _ => bail!("N '{s}': expected a positive number of rays"),
        },
        None => 1_000_000,
    };
    let scene = thinfilm::scene::load(std::path::Path::new(scene_path), &[])?;
    let (mut lo, mut hi) = (glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN));
    for shape in &scene.shapes {
        if let Geometry::Mesh(m) = &shape.geometry {
            for &p in &m.positions {
                (lo, hi) = (lo.min(p), hi.max(p));
            }
        }
    }
    if lo.x > hi.x {
        bail!("{scene_path}: no triangle mesh");
    }
    let grow = (hi - lo) * 0.05;
    let (lo, hi) = (lo - grow, hi + grow);
    let prepared = thinfilm::render::prepare(&scene, &Default::default())?;
    let accel = prepared.accel();
    // xorshift64: the same rays on every run and machine.
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let rays: Vec<Ray> = (0..n)
        .map(|_| {
            let o = lo + (hi - lo) * glam::Vec3::new(uniform(), uniform(), uniform());
            let z = 1.0 - 2.0 * uniform();
            let phi = std::f32::consts::TAU * uniform();
            let r = (1.0 - z * z).max(0.0).sqrt();
            Ray {
                origin: o,
                dir: glam::Vec3::new(r * phi.cos(), r * phi.sin(), z),
                tmin: 0.0,
                tmax: f32::INFINITY,
            }
        })
        .collect();
    let mut bytes = Vec::with_capacity(n * 24);
    for r in &rays {
        for v in [
            r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z,
        ] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::File::create(rays_path)
        .and_then(|mut f| f.write_all(&bytes))
        .with_context(|| format!("writing {rays_path}"))?;
    let time = |query: &(dyn Fn(&Ray) -> bool + Sync)| {
        let mut runs: Vec<(f64, usize)> = (0..5)
            .map(|_| {
                let t = std::time::Instant::now();
                let count = rays
                    .par_chunks(4096)
                    .map(|c| c.iter().filter(|r| query(r)).count());
                let count = count.sum::<usize>();
                (t.elapsed().as_secs_f64() * 1e9 / n as f64, count)
            })
            .collect();
        runs.sort_by(|a, b| a.0.total_cmp(&b.0));
        runs[2]
    };
    let (closest, hits) = time(&|r| accel.intersect(r).is_some());
    let (any, blocked) = time(&|r| accel.occluded(r));
    println!(
        "thinfilm ({} threads): closest hit {closest:.1} ns/ray ({hits} hits), any hit {any:.1} ns/ray ({blocked} blocked), {n} rays",
        rayon::current_num_threads()
    );
    Ok(())
}
