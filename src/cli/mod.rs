//! Subcommand definitions. Each subcommand lives in its own file with its `Args` and a `run`.

use clap::{Parser, Subcommand};

mod args;
mod bench;
mod compare;
mod demo;
mod estimate;
mod figure;
mod merge;
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
    #[command(flatten)]
    pub output: Output,
    #[command(subcommand)]
    pub command: Command,
}

/// How a command reports: flags accepted by every subcommand, before or after its name.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct Output {
    /// No progress bars and no log lines on stderr (results, warnings and errors still print).
    /// Progress bars only ever appear on a terminal, for work longer than a second.
    #[arg(long, global = true)]
    pub quiet: bool,
    /// Print one JSON document with the results on stdout instead of text (render, estimate,
    /// merge, compare, simulate); the log goes to stderr.
    #[arg(long, global = true)]
    pub json: bool,
}

impl Output {
    pub fn progress(self) -> bool {
        !self.quiet && !self.json
    }
    /// A log line on stderr (hidden by `--quiet`).
    pub fn log(self, line: impl std::fmt::Display) {
        if !self.quiet {
            eprintln!("{line}");
        }
    }
    /// A result line on stdout (text mode only; `--json` prints one document instead).
    pub fn text(self, line: impl std::fmt::Display) {
        if !self.json {
            println!("{line}");
        }
    }
    /// Prints `value` as the JSON document of the run when `--json` was given.
    pub fn json(self, value: &serde_json::Value) -> anyhow::Result<()> {
        if self.json {
            println!("{}", serde_json::to_string_pretty(value)?);
        }
        Ok(())
    }
    /// Refuses `--json` in commands that have no JSON summary.
    pub fn no_json(self, command: &str) -> anyhow::Result<()> {
        if self.json {
            anyhow::bail!("--json: `thinfilm {command}` has no JSON summary (render, estimate, merge, compare and simulate do)");
        }
        Ok(())
    }
}

/// `K/N` (part K of N, counted from 0), for splitting work over a job array.
pub(crate) fn parse_part(s: &str) -> Result<(usize, usize), String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("'{s}' is not K/N (part K of N, from 0), e.g. 0/4"))?;
    let k: usize = k.trim().parse().map_err(|_| format!("bad K in '{s}'"))?;
    let n: usize = n.trim().parse().map_err(|_| format!("bad N in '{s}'"))?;
    if k >= n {
        return Err(format!(
            "part '{s}': K must be < N (parts are counted from 0)"
        ));
    }
    Ok((k, n))
}

/// Returned when Ctrl-C (or SIGTERM) stopped the work after saving what was done; the
/// process exits with status 130, as a shell does for an interrupted command.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted")
    }
}

impl std::error::Error for Interrupted {}

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
    /// Merge renders of disjoint sample ranges into one (exactly), or stitch thickness maps
    /// fitted in row bands (`estimate --rows`) into the whole map.
    Merge(merge::Args),
    /// Benchmarks: what accuracy costs in time.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    let out = cli.output;
    match cli.command {
        Command::Demo(a) => out.no_json("demo").and_then(|()| demo::run(a, out)),
        Command::Reflectance(a) => out
            .no_json("reflectance (use --format json)")
            .and_then(|()| reflectance::run(a)),
        Command::Simulate(a) => simulate::run(a, out),
        Command::Estimate(a) => estimate::run(a, out),
        Command::Render(a) => render::run(a, out),
        Command::Compare(a) => compare::run(a, out),
        Command::Figure(a) => out.no_json("figure").and_then(|()| figure::run(a, out)),
        Command::Merge(a) => merge::run(a, out),
        Command::Bench(b) => out.no_json("bench").and_then(|()| bench::run(b)),
    }
}
