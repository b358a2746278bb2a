//! The repository as a newcomer meets it: every command in README.md's `sh` blocks runs as
//! written (at small sizes: spp and image resolution shrunk), every relative link in the
//! Markdown pages resolves inside the repository, and no file points to notes or trackers a
//! user of the repository cannot see.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Lines of the README's ```sh blocks, without comments and blank lines.
fn sh_commands(markdown: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_sh = false;
    for line in markdown.lines() {
        let t = line.trim();
        if let Some(lang) = t.strip_prefix("```") {
            in_sh = !in_sh && lang == "sh";
            continue;
        }
        if in_sh {
            let cmd = t.split(" #").next().unwrap_or("").trim();
            if !cmd.is_empty() && !cmd.starts_with('#') {
                out.push(cmd.to_string());
            }
        }
    }
    out
}

/// A README command at test size: `--spp N` → 4 (a power of two, so split renders still merge
/// exactly), `res=N` → 32 (added to renders that set none).
fn shrink(args: &[&str]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut it = args.iter().peekable();
    let mut has_res = false;
    while let Some(&a) = it.next() {
        out.push(a.to_string());
        if a == "--spp" && it.peek().is_some() {
            it.next();
            out.push("4".into());
        } else if a == "-D" && it.peek().is_some_and(|v| v.starts_with("res=")) {
            it.next();
            out.push("res=32".into());
            has_res = true;
        }
    }
    if args.first() == Some(&"render") && !has_res {
        out.extend(["-D".to_string(), "res=32".to_string()]);
    }
    out
}

#[test]
fn every_readme_command_runs_as_written_at_small_sizes() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let commands = sh_commands(&readme);
    assert!(
        commands.len() >= 10,
        "expected the README's commands, found {commands:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    // The commands use the repository's scenes and references by relative path.
    for d in ["scenes", "tests"] {
        std::os::unix::fs::symlink(repo().join(d), dir.path().join(d)).unwrap();
    }
    let mut ran = 0;
    for cmd in &commands {
        assert!(
            !cmd.contains(['"', '\'', '$', '|', '>', '<']),
            "README command `{cmd}` needs a shell; keep README commands plain"
        );
        let words: Vec<&str> = cmd.split_whitespace().collect();
        match words[0] {
            // The two set-up commands: the test suite itself, and the demo (tests/demo.rs runs
            // its pipeline; the CLI wrapper is checked below with --help).
            "cargo" => {
                assert!(
                    cmd == "cargo run --release -- demo" || cmd == "cargo test --release",
                    "unexpected cargo command in README: `{cmd}`"
                );
                continue;
            }
            "thinfilm" => {}
            other => panic!("README command `{cmd}` runs `{other}`, which this test cannot run"),
        }
        let args = shrink(&words[1..]);
        let out = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
            .args(&args)
            .arg("--quiet")
            .current_dir(dir.path())
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "README command `{cmd}` (run as `thinfilm {}`) failed:\n{stdout}\n{stderr}",
            args.join(" ")
        );
        if words[1] == "compare" {
            // The README renders at 512² against 128² references; here at 32²: either way
            // the sizes differ by an integer factor, and compare must say what it did.
            assert!(
                format!("{stdout}{stderr}").contains("downsampl"),
                "compare did not say it box-downsampled: {stdout}{stderr}"
            );
        }
        ran += 1;
    }
    assert!(ran >= 10, "ran only {ran} README commands");
    let demo = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(["demo", "--help"])
        .output()
        .unwrap();
    assert!(demo.status.success());
}

/// `[text](target)` link targets of a Markdown text (images included).
fn link_targets(markdown: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = markdown;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(end) = rest.find(')') {
            out.push(rest[..end].trim().to_string());
        }
    }
    out
}

fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            if !name.starts_with('.') && name != "target" && name != "build" {
                markdown_files(&path, out);
            }
        } else if name.ends_with(".md") {
            out.push(path);
        }
    }
}

#[test]
fn every_relative_markdown_link_resolves_inside_the_repository() {
    let root = repo();
    let mut files = Vec::new();
    markdown_files(&root, &mut files);
    assert!(files.iter().any(|f| f.ends_with("README.md")));
    let root_canon = root.canonicalize().unwrap();
    let mut broken = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for target in link_targets(&text) {
            if target.starts_with("http://")
                || target.starts_with("https://")
                || target.starts_with('#')
                || target.starts_with("mailto:")
            {
                continue;
            }
            let path = target.split('#').next().unwrap();
            let resolved = file.parent().unwrap().join(path);
            match resolved.canonicalize() {
                Ok(p) if p.starts_with(&root_canon) => {}
                _ => broken.push(format!("{}: {target}", file.display())),
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

/// Text files of the repository (no build outputs, no VCS data, no binaries).
fn text_files(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            let skip = ["target", ".git", "build", "demo-out", "__pycache__"];
            if !skip.contains(&name.as_str()) && !name.ends_with(".egg-info") {
                text_files(&path, out);
            }
        } else if std::fs::metadata(&path).is_ok_and(|m| m.len() < 4 << 20) {
            if let Ok(text) = String::from_utf8(std::fs::read(&path).unwrap()) {
                out.push((path, text));
            }
        }
    }
}

/// Words a reader of the repository cannot follow: tracker numbers and notes kept elsewhere.
fn outside_references(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let mut found = Vec::new();
    for (i, _) in lower.match_indices("issue") {
        let after = lower[i + 5..].trim_start_matches(['s', ' ', '-', '#']);
        if after.starts_with(|c: char| c.is_ascii_digit()) {
            found.push(lower[i..(i + 12).min(lower.len())].to_string());
        }
    }
    // Assembled at run time so that this file does not itself name them.
    let notes = [
        ["design", ".md"].concat(),
        ["conventions", ".md"].concat(),
        ["/work", "/shared"].concat(),
        ["..", "/shared"].concat(),
        ["shared", "/docs"].concat(),
    ];
    for word in &notes {
        if lower.contains(word) {
            found.push(word.clone());
        }
    }
    found
}

#[test]
fn no_file_points_outside_the_repository() {
    let root = repo();
    let mut files = Vec::new();
    text_files(&root, &mut files);
    assert!(files.len() > 50, "found only {} text files", files.len());
    let this = root.join("tests").join("readme.rs");
    let mut bad = Vec::new();
    for (path, text) in &files {
        if *path == this {
            continue;
        }
        for hit in outside_references(text) {
            bad.push(format!("{}: {hit}", path.display()));
        }
    }
    assert!(bad.is_empty(), "outside references:\n{}", bad.join("\n"));
}

#[test]
fn the_checks_can_fail() {
    assert_eq!(
        outside_references(&["see Issue 6 and design", ".md"].concat()).len(),
        2
    );
    assert_eq!(outside_references("issues #12").len(), 1);
    assert!(outside_references("an issue with 3 causes").is_empty());
    assert_eq!(
        link_targets("![a](img/a.png) and [b](../b.md#x)"),
        ["img/a.png", "../b.md#x"]
    );
    assert_eq!(
        shrink(&["render", "s.xml", "--spp", "256", "-D", "res=512"]),
        ["render", "s.xml", "--spp", "4", "-D", "res=32"]
    );
    assert_eq!(
        sh_commands("```sh\nthinfilm a # c\n# x\n```\n```text\nno\n```"),
        ["thinfilm a"]
    );
}
