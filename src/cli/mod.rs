//! Subcommand definitions. Each subcommand lives in its own file with its `Args` and a `run`.

use clap::{Parser, Subcommand};

mod args;
mod bench;
mod compare;
mod demo;
mod estimate;
mod figure;
mod reflectance;
mod render;
mod simulate;

/// Spectral rendering and parameter estimation for thin-film interference materials
/// (soap bubbles, oil films, evaporated MgF2/ZnS coatings, films on metals).
///
/// Typical workflow: `simulate` (or capture) → `estimate` → `render` → `compare` / `figure`.
/// `demo` runs the whole chain on the seed paper's three samples.
#[derive(Parser, Debug)]
#[command(name = "thinfilm", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run the whole pipeline on built-in defaults: simulate the seed paper's three samples,
    /// fit them, print the Table-1 comparison and render the figures.
    Demo(demo::Args),
    /// Thin-film (or multilayer) reflectance and transmittance spectra at one angle,
    /// as CSV or JSON, with the colour under D65 and an optional plot.
    Reflectance(reflectance::Args),
    /// Write a synthetic hyperspectral capture set (ENVI cubes + capture.json) and its ground truth.
    Simulate(simulate::Args),
    /// Fit the film index (global) and thickness (per pixel) from a capture set.
    Estimate(estimate::Args),
    /// Render a scene (Mitsuba 3 XML subset, glTF, OBJ) with the spectral path tracer.
    Render(render::Args),
    /// Compare two renders (RMSE, relMSE, ΔE00) and optionally draw a side-by-side figure.
    Compare(compare::Args),
    /// Render ground truth vs fitted teapots and compose a labelled figure.
    Figure(figure::Args),
    /// Benchmarks: what accuracy costs in time.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Reflectance(a) => reflectance::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Estimate(a) => estimate::run(a),
        Command::Render(a) => render::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Figure(a) => figure::run(a),
        Command::Bench(b) => bench::run(b),
    }
}
