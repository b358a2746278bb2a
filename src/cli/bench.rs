//! `thinfilm bench …`: each benchmark lives in its own file.

use clap::Subcommand;

#[path = "bench_effects.rs"]
mod bench_effects;
#[path = "bench_estimate.rs"]
mod bench_estimate;
#[path = "bench_gltf.rs"]
mod bench_gltf;
#[path = "bench_optics.rs"]
mod bench_optics;
#[path = "bench_render.rs"]
mod bench_render;

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Single-film evaluations per second (4 wavelengths), f32 and f64.
    Optics(bench_optics::Args),
    /// Reproduce the seed's Table 1 on simulated samples; accuracy against time per method.
    Estimate(bench_estimate::Args),
    /// Our renders vs Mitsuba 3 references: error against time.
    Render(bench_render::Args),
    /// glTF's iridescence approximation (Schlick + Fourier XYZ fit) against the exact
    /// spectral film: ΔE00 over thickness, film index and angle, on a dielectric and a metal.
    GltfIridescence(bench_gltf::Args),
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Optics(a) => bench_optics::run(a),
        BenchCommand::Estimate(a) => bench_estimate::run(a),
        BenchCommand::Render(a) => bench_render::run(a),
        BenchCommand::GltfIridescence(a) => bench_gltf::run(a),
    }
}
