//! The `thinfilm` command line: parses arguments and calls the library. Nothing else.

mod cli;

use clap::Parser;

fn main() -> std::process::ExitCode {
    // Like any Unix filter, end quietly when the reader of stdout goes away
    // (`thinfilm compare … | grep -q …`) instead of panicking in `println!`. Outputs are
    // written to staged files and renamed, so dying here never leaves a half-written file.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of one signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = cli::Cli::parse();
    match cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) if err.is::<cli::Interrupted>() => std::process::ExitCode::from(130),
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
