//! A closed stdout (`thinfilm compare a.exr b.exr | grep -q …`, `| head`) ends the process
//! quietly, as any Unix filter does, instead of panicking in `println!`.

use std::process::{Command, Stdio};

#[cfg(unix)]
#[test]
fn a_closed_stdout_is_not_a_panic() {
    let exr = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/references/blend.exr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(["compare", exr, exr])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end before the child prints anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
}
