//! Killing a render or an estimate while it writes its outputs leaves every output either the
//! previous complete file or the new complete one — never a truncated one — and leaves the
//! other files of the output folder alone.
//!
//! Each run is killed (SIGKILL, which no handler can soften) as soon as its first temporary
//! appears in the output folder, i.e. in the middle of writing, after a few different extra
//! delays; then at random moments of a whole run. After every kill each output must decode
//! completely (EXR, PNG, JSON, XML).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_thinfilm"));
    c.stdout(Stdio::null()).stderr(Stdio::null());
    c
}

/// Checks that `path` holds a complete file of its kind.
fn complete(path: &Path) -> Result<(), String> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let shown = path.display();
    match ext {
        "exr" => thinfilm::image_io::read_exr_channels(path)
            .map(|_| ())
            .map_err(|e| format!("{e:#}")),
        "png" => image::open(path)
            .map(|_| ())
            .map_err(|e| format!("{shown}: {e}")),
        "json" | "gltf" => serde_json::from_slice::<serde_json::Value>(
            &std::fs::read(path).map_err(|e| format!("{shown}: {e}"))?,
        )
        .map(|_| ())
        .map_err(|e| format!("{shown}: {e}")),
        "xml" => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{shown}: {e}"))?;
            roxmltree::Document::parse(&text)
                .map(|_| ())
                .map_err(|e| format!("{shown}: {e}"))
        }
        _ => Ok(()),
    }
}

/// True while `dir` holds a temporary of a running write.
fn writing(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .any(|e| e.file_name().to_string_lossy().contains(".partial-"))
        })
        .unwrap_or(false)
}

fn kill(mut child: Child) {
    let _ = child.kill();
    let _ = child.wait();
}

/// Runs `make` once to completion (the "previous" outputs: every file it writes into `dir`),
/// then kills runs mid-write and at random moments; after each kill every output must be
/// complete and `notes.txt` (a file of the user's) untouched. Returns how many kills landed
/// while a temporary existed.
fn interrupt(make: impl Fn() -> Command, dir: &Path, expected_outputs: usize) -> usize {
    let keep = dir.join("notes.txt");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(&keep, "mine").unwrap();
    let start = Instant::now();
    assert!(
        make().status().unwrap().success(),
        "the uninterrupted run failed"
    );
    let full = start.elapsed();
    let outputs: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != "notes.txt")
        .collect();
    assert!(outputs.len() >= expected_outputs, "outputs: {outputs:?}");
    let check = |when: &str| {
        for name in &outputs {
            let p = dir.join(name);
            assert!(p.exists(), "{when}: {} is missing", p.display());
            if let Err(e) = complete(&p) {
                panic!("{when}: {name} is not a complete file: {e}");
            }
        }
        assert_eq!(std::fs::read_to_string(&keep).unwrap(), "mine", "{when}");
    };
    check("after the first run");
    let mut mid_write = 0;
    // Kill as soon as writing starts, then a little later (other files, the renames).
    for extra_ms in [0u64, 0, 1, 2, 5, 10, 20, 40] {
        let child = make().spawn().unwrap();
        let t = Instant::now();
        while !writing(dir) && t.elapsed() < full * 20 + Duration::from_secs(5) {
            std::thread::sleep(Duration::from_micros(200));
        }
        std::thread::sleep(Duration::from_millis(extra_ms));
        let seen = writing(dir);
        kill(child);
        mid_write += usize::from(seen && writing(dir));
        check(&format!("killed {extra_ms} ms into writing"));
    }
    // Random moments over a whole run (a fixed sequence, so the test is repeatable).
    for k in 0..8u32 {
        let child = make().spawn().unwrap();
        std::thread::sleep(full.mul_f64(0.2 + 0.13 * k as f64));
        let seen = writing(dir);
        kill(child);
        mid_write += usize::from(seen);
        check(&format!(
            "killed at {:.0} % of a run",
            20.0 + 13.0 * k as f64
        ));
    }
    // The next complete run cleans up what the killed ones left.
    assert!(make().status().unwrap().success());
    assert!(!writing(dir), "temporaries of killed runs were not removed");
    check("after a final run");
    mid_write
}

#[test]
fn killed_renders_leave_complete_images() {
    let dir = tempfile::tempdir().unwrap();
    let scene: PathBuf =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/hostile/corpus/xml/ok_sphere.xml");
    let out = dir.path().join("render");
    let make = || {
        let mut c = bin();
        c.arg("render")
            .arg(&scene)
            .arg("-o")
            .arg(out.join("img.exr"))
            .args(["--spp", "1", "--resolution", "1024x768"]);
        c
    };
    let mid = interrupt(make, &out, 2);
    assert!(mid >= 3, "only {mid} kills landed while writing");
}

#[test]
fn killed_estimates_leave_complete_fits() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    let ok = bin()
        .args([
            "simulate",
            "--size",
            "384x256",
            "--wavelengths",
            "400:720:20",
        ])
        .args(["--angles", "10,30,50", "--noise", "0.003", "--out"])
        .arg(&cap)
        .status()
        .unwrap();
    assert!(ok.success());
    let out = dir.path().join("fit");
    let make = || {
        let mut c = bin();
        c.arg("estimate")
            .arg(&cap)
            .arg("--out")
            .arg(&out)
            .args(["--quiet", "--method", "paper"]);
        c
    };
    // fit.json, thickness.exr, PNG maps, material.xml, material.gltf (at least).
    let mid = interrupt(make, &out, 6);
    assert!(mid >= 3, "only {mid} kills landed while writing");
}

/// Ctrl-C saves the samples a render has so far beside its output (`img.samples-A-B.exr`);
/// that save goes through the same temporary-and-rename path: a kill while it is written
/// leaves no truncated piece, and the output's own name is never taken by a partial image.
/// (Each run writes into an empty folder and is killed as soon as any file appears in it, so
/// a save written in place would be caught half-written.)
#[test]
fn ctrl_c_partial_saves_are_atomic_too() {
    let dir = tempfile::tempdir().unwrap();
    let scene: PathBuf =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/hostile/corpus/xml/ok_sphere.xml");
    let render = |out: &Path, spp: &str| {
        let mut c = bin();
        c.arg("render").arg(&scene).arg("-o").arg(out);
        c.args(["--spp", spp, "--resolution", "384x288"]);
        c
    };
    let entries = |d: &Path| -> Vec<PathBuf> {
        std::fs::read_dir(d)
            .map(|r| r.flatten().map(|e| e.path()).collect())
            .unwrap_or_default()
    };
    let (mut saves_seen, mut killed_mid_save) = (0, 0);
    let mut last = PathBuf::new();
    for (k, wait_ms) in [2000u64, 3000, 4500, 6000].into_iter().enumerate() {
        let out_dir = dir.path().join(format!("run{k}"));
        std::fs::create_dir_all(&out_dir).unwrap();
        let out = out_dir.join("img.exr");
        let mut child = render(&out, "65536").spawn().unwrap();
        std::thread::sleep(Duration::from_millis(wait_ms));
        // SAFETY: sends SIGINT to the child this test spawned.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
        let t = Instant::now();
        loop {
            if !entries(&out_dir).is_empty() {
                saves_seen += 1;
                std::thread::sleep(Duration::from_millis(k as u64));
                killed_mid_save += usize::from(writing(&out_dir));
                let _ = child.kill();
                break;
            }
            if child.try_wait().unwrap().is_some() || t.elapsed() > Duration::from_secs(60) {
                break;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        let _ = child.kill();
        let _ = child.wait();
        assert!(!out.exists(), "a partial render took the output's name");
        for p in entries(&out_dir) {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if !name.starts_with('.') {
                if let Err(e) = complete(&p) {
                    panic!("Ctrl-C then kill {k}: {name} is not a complete file: {e}");
                }
            }
        }
        last = out;
    }
    eprintln!("{saves_seen} partial saves started, {killed_mid_save} killed while writing");
    assert!(
        saves_seen > 0,
        "no Ctrl-C reached a render after its first pass"
    );
    // The next write into the folder removes the temporaries of a killed save.
    assert!(render(&last, "1").status().unwrap().success());
    assert!(
        !writing(last.parent().unwrap()),
        "temporaries of killed saves were not removed"
    );
}
