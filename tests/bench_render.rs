//! `thinfilm bench render --mitsuba` scores Mitsuba's renders against references Mitsuba
//! itself rendered: a bench seed equal to a reference's seed would make the two share
//! samples, so it is refused before anything renders.

use std::process::Command;

/// The run's output and whether it left its scratch directory behind.
fn bench(seed: &str) -> (std::process::Output, bool) {
    let root = env!("CARGO_MANIFEST_DIR");
    let plot = std::env::temp_dir().join(format!("bench_seed_{}.png", std::process::id()));
    let child = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(["bench", "render", "--mitsuba", "--only", "teapot_gold"])
        .args([
            "--spp",
            "1",
            "--repeats",
            "1",
            "--seed",
            seed,
            "--root",
            root,
        ])
        // A Python that cannot exist: a run past the seed check fails at Mitsuba instead.
        .args(["--python", "/nonexistent/python3"])
        .arg("--plot")
        .arg(&plot)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let scratch = std::env::temp_dir().join(format!("thinfilm-bench-render-{}", child.id()));
    let out = child.wait_with_output().unwrap();
    (out, scratch.exists())
}

#[test]
fn the_references_own_seed_is_refused() {
    let (out, _) = bench("0");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("--seed 0"), "{stderr}");
    assert!(stderr.contains("teapot_gold"), "{stderr}");
    assert!(!stderr.contains("/nonexistent/python3"), "{stderr}");
}

#[test]
fn another_seed_passes_the_check() {
    let (out, left_scratch) = bench("1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // It gets as far as starting Mitsuba (which fails here), not stopped by the seed check.
    assert!(!out.status.success());
    assert!(!stderr.contains("--seed 1 is the seed"), "{stderr}");
    assert!(stderr.contains("/nonexistent/python3"), "{stderr}");
    // The failed run removed its scratch directory.
    assert!(!left_scratch);
}
