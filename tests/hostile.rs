//! Every hostile input of `tests/hostile/cases.txt` (written by
//! `tools/hostile/make_corpus.py`: malformed, truncated, huge, NaN, cyclic and garbage files
//! of every format, and bad command-line values) run through the `thinfilm` binary, each
//! under a 2 GiB address-space limit and a 20 s timeout. Every case must end as the manifest
//! says: refused with exit status 1 (2 for a value clap rejects) and a message naming the
//! culprit, or — for the odd-but-legal inputs — succeed. A panic (status 101), a signal
//! (abort, segfault, out of memory) or a timeout fails the test.
//!
//! `tools/hostile/run.sh` runs the same cases from the shell with peak-memory reporting.

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(20);
const ADDRESS_SPACE: u64 = 2 << 30;

struct Case {
    id: String,
    expect: Option<Vec<String>>,
    args: String,
}

fn manifest(root: &Path) -> (Vec<(String, u64)>, Vec<Case>) {
    let text = std::fs::read_to_string(root.join("cases.txt")).unwrap();
    let (mut sparse, mut cases) = (Vec::new(), Vec::new());
    for line in text
        .lines()
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        if let Some(rest) = line.strip_prefix("@sparse ") {
            let (path, bytes) = rest.rsplit_once(' ').unwrap();
            sparse.push((path.to_string(), bytes.parse().unwrap()));
            continue;
        }
        let mut f = line.splitn(3, '\t');
        let (id, expect, args) = (f.next().unwrap(), f.next().unwrap(), f.next().unwrap());
        let expect = match expect {
            "ok" => None,
            e => Some(
                e.strip_prefix("fail:")
                    .unwrap()
                    .split('|')
                    .filter(|s| !s.is_empty())
                    .map(str::to_lowercase)
                    .collect(),
            ),
        };
        cases.push(Case {
            id: id.into(),
            expect,
            args: args.into(),
        });
    }
    (sparse, cases)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let dst = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// Runs one case; `Err` describes how it went wrong.
fn run_case(case: &Case, corpus: &Path, out: &Path) -> Result<Duration, String> {
    let args = case
        .args
        .replace("{C}", &corpus.display().to_string())
        .replace("{O}", &out.display().to_string());
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_thinfilm"));
    cmd.args(args.split(' '))
        .env("RAYON_NUM_THREADS", "2")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: ADDRESS_SPACE,
                rlim_max: ADDRESS_SPACE,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let start = Instant::now();
    let mut child = cmd.spawn().map_err(|e| format!("spawn: {e}"))?;
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("HANG: still running after {TIMEOUT:?}"));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let elapsed = start.elapsed();
    let err = reader.join().unwrap();
    let tail: String = err.lines().rev().take(3).collect::<Vec<_>>().join(" | ");
    let code = status.code();
    if code == Some(101) || err.contains("panicked") {
        return Err(format!("PANIC: {tail}"));
    }
    let Some(code) = code else {
        return Err(format!("CRASH (signal): {tail}"));
    };
    match &case.expect {
        None if code == 0 => Ok(elapsed),
        None => Err(format!("REFUSED a legal input (status {code}): {tail}")),
        Some(_) if code == 0 => Err("ACCEPTED a hostile input".into()),
        Some(_) if code != 1 && code != 2 => Err(format!("status {code}: {tail}")),
        Some(needles) => {
            let lower = err.to_lowercase();
            match needles.iter().find(|n| !lower.contains(n.as_str())) {
                None => Ok(elapsed),
                Some(n) => Err(format!("VAGUE: message does not name '{n}': {tail}")),
            }
        }
    }
}

#[test]
fn hostile_inputs_are_refused_cleanly() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/hostile");
    let (sparse, cases) = manifest(&root);
    assert!(cases.len() > 300, "{} cases", cases.len());
    let work = tempfile::tempdir().unwrap();
    let corpus = work.path().join("corpus");
    copy_dir(&root.join("corpus"), &corpus);
    // Extended to the declared length keeping what the file starts with (a valid header
    // followed by a hole), as `truncate -s` in tools/hostile/run.sh.
    for (path, bytes) in &sparse {
        std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(corpus.join(path))
            .unwrap()
            .set_len(*bytes)
            .unwrap();
    }
    let mut failures = Vec::new();
    let mut slowest = (Duration::ZERO, String::new());
    for case in &cases {
        let out = work.path().join("out").join(&case.id);
        std::fs::create_dir_all(&out).unwrap();
        match run_case(case, &corpus, &out) {
            Ok(t) if t > slowest.0 => slowest = (t, case.id.clone()),
            Ok(_) => {}
            Err(e) => failures.push(format!("{}: {e}", case.id)),
        }
        let _ = std::fs::remove_dir_all(&out);
    }
    eprintln!(
        "{} hostile cases, {} failed; slowest {} ({:.2} s)",
        cases.len(),
        failures.len(),
        slowest.1,
        slowest.0.as_secs_f64()
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
