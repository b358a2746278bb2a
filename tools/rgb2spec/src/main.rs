//! Writes the Jakob & Hanika (2019) sRGB coefficient table used by thinfilm's RGB → spectrum
//! upsampling: `rgb2spec::optimize::optimize(Gamut::SRGB, 64)` (a Rust port of the
//! rgb2spec_opt tool that Mitsuba 3 and pbrt-v4 run at build time; same "SPEC" file format and
//! the same 64³ resolution as Mitsuba's `srgb.coeff`).
//!
//! Usage (from the repository root):
//!   cargo run --release --manifest-path tools/rgb2spec/Cargo.toml -- spectra/srgb_rgb2spec_64.coeff
//!
//! The file is written to `<out>.tmp` and renamed, so an interrupted run leaves nothing
//! half-written. The elapsed optimisation time is printed.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use rgb2spec::optimize::{gamut::Gamut, optimize};

const RESOLUTION: usize = 64;

fn main() -> ExitCode {
    let out = match std::env::args_os().nth(1) {
        Some(p) => PathBuf::from(p),
        None => {
            eprintln!("usage: thinfilm-rgb2spec-gen OUTPUT.coeff");
            return ExitCode::from(2);
        }
    };
    let t0 = Instant::now();
    let model = match optimize(Gamut::SRGB, RESOLUTION) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: rgb2spec optimisation failed: {e}");
            return ExitCode::FAILURE;
        }
    };
    let secs = t0.elapsed().as_secs_f64();
    let mut tmp = out.clone().into_os_string();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    if let Err(e) = model.save(&tmp).and_then(|_| std::fs::rename(&tmp, &out)) {
        eprintln!("error: cannot write {}: {e}", out.display());
        let _ = std::fs::remove_file(&tmp);
        return ExitCode::FAILURE;
    }
    println!(
        "wrote {} (sRGB, res {RESOLUTION}) — optimisation took {secs:.1} s",
        out.display()
    );
    ExitCode::SUCCESS
}
