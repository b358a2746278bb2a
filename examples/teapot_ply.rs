//! Writes Newell's Utah teapot tessellated with N subdivisions per patch edge as a binary
//! PLY (32·2·N² − 8·N triangles: N = 4 → 992, 40 → 102,080, 125 → 999,000, 280 →
//! 5,015,360), for the scaling tables of docs/performance.md (`tools/scaling/run_scaling.sh`).
//!
//! `cargo run --release --example teapot_ply -- N OUT.ply`

use anyhow::{bail, Context, Result};
use thinfilm::scene::{meshio, teapot};

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [n, out] = args.as_slice() else {
        bail!("usage: teapot_ply N OUT.ply (N subdivisions per patch edge, 1 to 400)");
    };
    let n: usize = n
        .parse()
        .with_context(|| format!("N must be an integer, got '{n}'"))?;
    if !(1..=400).contains(&n) {
        bail!("N must be between 1 and 400, got {n}");
    }
    let mesh = teapot::teapot_mesh(n);
    meshio::write_ply_binary(std::path::Path::new(out), &mesh)?;
    println!(
        "{out}: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.indices.len()
    );
    Ok(())
}
