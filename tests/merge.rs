//! Split renders put back together: `thinfilm render --sample-range` pieces and `thinfilm
//! merge` give the single render bit for bit (power-of-two ranges), merges of other splits and
//! of filtered renders agree to rounding and say so, mismatched pieces are refused with a
//! message naming the file, and an interrupted render (cancelled between rows, or Ctrl-C on
//! the command line) saves a prefix that its printed resume commands complete exactly.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use thinfilm::image_io::read_exr;
use thinfilm::merge::{merge_renders, RenderPiece};
use thinfilm::render::provenance::{self, RenderInfo};
use thinfilm::render::{passes, prepare, render_prepared, Cancel, RenderOptions};

const TEAPOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/teapot_mgf2_400.xml");

fn thinfilm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(out: Output) -> String {
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn failure(out: Output) -> String {
    assert!(!out.status.success(), "expected a failure");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Every channel of an EXR as bits.
fn bits(path: &Path) -> Vec<(String, Vec<u32>)> {
    read_exr(path)
        .unwrap()
        .channels
        .into_iter()
        .map(|(n, p)| (n, p.into_iter().map(f32::to_bits).collect()))
        .collect()
}

fn render_range(dir: &Path, name: &str, extra: &[&str], range: Option<&str>) -> PathBuf {
    let out = dir.join(name);
    let mut args = vec![
        "render",
        TEAPOT,
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "64",
        "-D",
        "res=16",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    if let Some(r) = range {
        args.extend(["--sample-range", r]);
    }
    ok(thinfilm(&args));
    out
}

#[test]
fn four_sample_range_renders_merge_to_the_single_render_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Pieces hold every pixel's samples of their range: the single render they equal is the
    // one with the same count in every pixel.
    let full = render_range(d, "full.exr", &["--uniform-samples"], None);
    let pieces: Vec<PathBuf> = ["0:8", "8:16", "16:32", "32:64"]
        .iter()
        .enumerate()
        .map(|(i, r)| render_range(d, &format!("p{i}.exr"), &[], Some(r)))
        .collect();
    let merged = d.join("merged.exr");
    // Pieces in any order on the command line.
    let mut args = vec!["merge", "-o", merged.to_str().unwrap()];
    args.extend(pieces.iter().rev().map(|p| p.to_str().unwrap()));
    let text = ok(thinfilm(&args));
    assert!(text.contains("exact:"), "{text}");
    assert_eq!(bits(&merged), bits(&full));
    // The merged header describes the whole render, like the single run's.
    let (m, f) = (read_exr(&merged).unwrap(), read_exr(&full).unwrap());
    assert_eq!(m.attributes, f.attributes);
    assert!(d.join("merged.png").is_file());
}

/// A split that is not power-of-two aligned still merges (sample-weighted mean, equal up to
/// rounding) and says it is not bit-exact; the JSON summary carries the same verdict.
#[test]
fn unaligned_splits_merge_to_rounding_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let full = render_range(d, "full.exr", &["--uniform-samples"], None);
    let a = render_range(d, "a.exr", &[], Some("0:24"));
    let b = render_range(d, "b.exr", &[], Some("24:64"));
    let merged = d.join("m.exr");
    let json = ok(thinfilm(&[
        "merge",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["exact"], false, "{v}");
    assert_eq!(v["spp"], 64);
    let (m, f) = (read_exr(&merged).unwrap(), read_exr(&full).unwrap());
    for ((_, pm), (_, pf)) in m.channels.iter().zip(&f.channels) {
        for (x, y) in pm.iter().zip(pf) {
            assert!((x - y).abs() <= 1e-6 * y.abs().max(1e-3), "{x} vs {y}");
        }
    }
}

/// A render with adaptive sample counts (pixels hold different numbers of samples) says so in
/// its header, and merge refuses it, naming the file; its sample-range pieces merge.
#[test]
fn adaptive_renders_are_refused_by_merge() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let adaptive = render_range(d, "adaptive.exr", &[], None);
    let header = read_exr(&adaptive).unwrap().attributes;
    let counts = header.get("thinfilm.sampleCounts").map(String::as_str);
    assert_eq!(counts, Some("adaptive"), "{header:?}");
    let more = render_range(d, "more.exr", &[], Some("64:128"));
    let e = failure(thinfilm(&[
        "merge",
        adaptive.to_str().unwrap(),
        more.to_str().unwrap(),
        "-o",
        d.join("m.exr").to_str().unwrap(),
    ]));
    assert!(
        e.contains("adaptive.exr") && e.contains("--uniform-samples"),
        "{e}"
    );
    assert!(!d.join("m.exr").exists());
    let piece = render_range(d, "piece.exr", &[], Some("0:64"));
    let header = read_exr(&piece).unwrap().attributes;
    let counts = header.get("thinfilm.sampleCounts").map(String::as_str);
    assert_eq!(counts, Some("uniform"), "{header:?}");
}

#[test]
fn mismatched_pieces_are_refused_naming_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let a = render_range(d, "a.exr", &[], Some("0:32"));
    let overlap = render_range(d, "overlap.exr", &[], Some("16:48"));
    let gap = render_range(d, "gap.exr", &[], Some("48:64"));
    let other_seed = render_range(d, "seed.exr", &["--seed", "3"], Some("32:64"));
    let other_param = render_range(d, "param.exr", &["-D", "max_depth=3"], Some("32:64"));
    let bigger = d.join("bigger.exr");
    ok(thinfilm(&[
        "render",
        TEAPOT,
        "-o",
        bigger.to_str().unwrap(),
        "--spp",
        "64",
        "-D",
        "res=32",
        "--sample-range",
        "32:64",
        "--quiet",
    ]));
    let out = d.join("out.exr");
    let merge = |b: &Path| {
        failure(thinfilm(&[
            "merge",
            a.to_str().unwrap(),
            b.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]))
    };
    let e = merge(&overlap);
    assert!(e.contains("overlap") && e.contains("overlap.exr"), "{e}");
    let e = merge(&gap);
    assert!(e.contains("32:48") && e.contains("missing"), "{e}");
    for p in [&other_seed, &other_param] {
        let e = merge(p);
        assert!(e.contains("different images") && e.contains("a.exr"), "{e}");
    }
    let e = merge(&bigger);
    assert!(e.contains("bigger.exr"), "{e}");
    // An EXR without thinfilm's header attributes.
    let plain = d.join("plain.exr");
    let img = thinfilm::image_io::RgbImage::new(16, 16);
    thinfilm::image_io::write_exr_rgb(&plain, &img).unwrap();
    let e = merge(&plain);
    assert!(
        e.contains("plain.exr") && e.contains("thinfilm.kind"),
        "{e}"
    );
    assert!(!out.exists(), "a refused merge wrote its output");
}

/// Tent/Gaussian-filtered renders carry their filter weights; merging two halves agrees with
/// the single render to rounding.
#[test]
fn filtered_renders_merge_by_their_weights() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = std::fs::read_to_string(TEAPOT)
        .unwrap()
        .replace(r#"<rfilter type="box"/>"#, r#"<rfilter type="gaussian"/>"#)
        .replace(
            "textures/",
            concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/textures/"),
        )
        .replace(
            "meshes/",
            concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/meshes/"),
        );
    assert!(scene.contains("gaussian"));
    let path = d.join("gauss.xml");
    std::fs::write(&path, scene).unwrap();
    let render = |name: &str, range: &str| {
        let out = d.join(name);
        ok(thinfilm(&[
            "render",
            path.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--spp",
            "32",
            "-D",
            "res=16",
            "--sample-range",
            range,
            "--quiet",
        ]));
        out
    };
    let full = render("full.exr", "0:32");
    let (a, b) = (render("a.exr", "0:16"), render("b.exr", "16:32"));
    let f = read_exr(&full).unwrap();
    assert!(f.channel(provenance::FILTER_WEIGHT_CHANNEL).is_some());
    let merged = d.join("m.exr");
    let text = ok(thinfilm(&[
        "merge",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
    ]));
    assert!(text.contains("filter weights"), "{text}");
    let m = read_exr(&merged).unwrap();
    for c in ["R", "G", "B", provenance::FILTER_WEIGHT_CHANNEL] {
        for (x, y) in m.channel(c).unwrap().iter().zip(f.channel(c).unwrap()) {
            assert!((x - y).abs() <= 2e-6 * y.abs().max(1e-3), "{c}: {x} vs {y}");
        }
    }
}

/// A render cancelled in its third pass keeps the power-of-two prefix of its first two;
/// rendering the remaining tree nodes and merging gives the uninterrupted render bit for bit.
#[test]
fn a_cancelled_render_keeps_a_prefix_that_resumes_exactly() {
    let scene = thinfilm::scene::load(Path::new(TEAPOT), &[("res".into(), "12".into())]).unwrap();
    let opts = |range: (u32, u32)| RenderOptions {
        sample_range: Some(range),
        ..Default::default()
    };
    let full_range = (0, 128);
    let prepared = prepare(&scene, &opts(full_range)).unwrap();
    let full = render_prepared(&prepared, &opts(full_range)).unwrap();
    assert!(!full.interrupted);
    // Stop once 2 passes × 12 rows have started: passes 0:16 and 16:32 complete.
    let rows_started = Arc::new(AtomicUsize::new(0));
    let counter = rows_started.clone();
    let mut cancelled = opts(full_range);
    cancelled.cancel = Some(Cancel(Arc::new(move || {
        counter.fetch_add(1, Ordering::SeqCst) >= 24
    })));
    let partial = render_prepared(&prepared, &cancelled).unwrap();
    assert!(partial.interrupted);
    assert_eq!(partial.sample_range, (0, 32));
    assert_eq!(partial.requested_range, full_range);
    assert_eq!(partial.stats.samples, 12 * 12 * 32);

    let dir = tempfile::tempdir().unwrap();
    let piece = |out: &thinfilm::render::RenderOutput, name: &str| -> RenderPiece {
        let path = dir.path().join(name);
        let info = RenderInfo::new(&scene, &prepared, out.sample_range);
        provenance::write_exr(&path, &out.image, out.filter_weights.as_deref(), &info).unwrap();
        RenderPiece::from_exr(&path, read_exr(&path).unwrap()).unwrap()
    };
    let mut pieces = vec![piece(&partial, "partial.exr")];
    let resume = passes::remaining_nodes(full_range, 32);
    assert_eq!(resume, vec![(32, 64), (64, 128)]);
    for (i, &r) in resume.iter().enumerate() {
        let p = prepare(&scene, &opts(r)).unwrap();
        let out = render_prepared(&p, &opts(r)).unwrap();
        pieces.push(piece(&out, &format!("resume{i}.exr")));
    }
    let merged = merge_renders(pieces).unwrap();
    assert!(merged.exact, "{}", merged.note);
    assert_eq!(merged.image, full.image);
    let bits = |img: &thinfilm::image_io::RgbImage| -> Vec<u32> {
        img.pixels
            .iter()
            .flat_map(|p| p.map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&merged.image), bits(&full.image));

    // Cancelled before the first pass completed: an error, nothing to save.
    let mut at_once = opts(full_range);
    at_once.cancel = Some(Cancel(Arc::new(|| true)));
    let e = render_prepared(&prepared, &at_once).unwrap_err();
    assert!(format!("{e:#}").contains("nothing to write"), "{e:#}");
}

/// CPU seconds (user + system, every thread) the process `pid` has used so far, from
/// `/proc/PID/stat` (fields 14 and 15, in clock ticks); `None` when that cannot be read.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may hold spaces: count fields after its closing ')'.
    let fields: Vec<&str> = stat[stat.rfind(')')? + 1..].split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf only reads a constant of the running system.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    Some(ticks / per_second.max(1) as f64)
}

/// Starts `thinfilm ARGS` and sends it SIGINT once it has used `cpu` seconds of CPU time
/// (or when it has exited). A condition on the work done, not on the wall clock, so the
/// signal lands at the same point of the render on an idle or a loaded machine.
fn interrupt_after_cpu(args: &[&str], cpu: f64) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    // A last resort against a child that stops using CPU (it never should).
    let give_up = std::time::Instant::now() + std::time::Duration::from_secs(600);
    while child.try_wait().unwrap().is_none()
        && cpu_seconds(pid).is_some_and(|used| used < cpu)
        && std::time::Instant::now() < give_up
    {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    if child.try_wait().unwrap().is_none() {
        Command::new("kill")
            .args(["-INT", &pid.to_string()])
            .status()
            .unwrap();
    }
    child.wait_with_output().unwrap()
}

/// Ctrl-C on the command line: exit status 130, the completed passes saved beside the output
/// (never in its place), and the printed commands finish the render exactly.
///
/// The signal is sent once the render has used 0.5 s of CPU time: setup and the first
/// 16-sample pass take about 0.17 s of it and all 4096 samples about 1.3 s (measured on
/// the CI machine), so the signal falls between the first pass and the end whatever the
/// load. Should a much slower setup still be inside its first pass, the run is repeated
/// with twice the CPU budget.
#[test]
fn ctrl_c_saves_the_completed_passes_and_prints_exact_resume_commands() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("teapot.exr");
    let args = [
        "render",
        TEAPOT,
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "4096",
        "-D",
        "res=32",
    ];
    let mut cpu = 0.5;
    let result = loop {
        let result = interrupt_after_cpu(&args, cpu);
        let stderr = String::from_utf8_lossy(&result.stderr);
        if cpu < 2.0 && stderr.contains("nothing to write") {
            eprintln!("the signal came before the first pass ended at {cpu} s CPU; again");
            cpu *= 2.0;
            continue;
        }
        break result;
    };
    assert!(
        !result.status.success(),
        "the render finished before the signal ({cpu} s CPU): raise --spp"
    );
    let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
    let full = d.join("full.exr");
    let mut full_args = args.to_vec();
    full_args[3] = full.to_str().unwrap();
    // The resumed pieces are sample ranges: the render they finish has the same count in
    // every pixel.
    full_args.extend(["--quiet", "--uniform-samples"]);
    ok(thinfilm(&full_args));
    assert_eq!(result.status.code(), Some(130), "{stderr}");
    assert!(!out.exists(), "the partial render took the output's name");
    let commands: Vec<Vec<String>> = stderr
        .lines()
        .filter_map(|l| l.strip_prefix("  thinfilm "))
        .map(|l| {
            l.split(' ')
                .map(|a| a.trim_matches('\'').to_string())
                .collect()
        })
        .collect();
    assert!(commands.last().is_some_and(|c| c[0] == "merge"), "{stderr}");
    for c in &commands {
        let c: Vec<&str> = c.iter().map(String::as_str).collect();
        ok(thinfilm(&c));
    }
    assert_eq!(bits(&out), bits(&full));
}
