//! In-process, structure-aware fuzzing of every input format (targets in `fuzz/targets.rs`):
//! valid seed files are mutated — bytes flipped, ranges cut, duplicated or spliced, numbers
//! replaced by hostile ones (NaN, ±inf, 2⁶⁴, 1e308, −1, 0), JSON values replaced by other
//! types, lines dropped or repeated — and fed to the loaders the command line uses. A panic,
//! a contained panic (an error carrying `limits::CONTAINED_PANIC`) or an input that takes
//! longer than [`SLOW`] fails the test, printing the input's file name under
//! `target/fuzz-findings/` so it can become a regression case.
//!
//! CI runs a fixed seed and [`DEFAULT_ITERATIONS`] inputs per target (well inside 2 minutes
//! on 2 cores). Longer campaigns: `THINFILM_FUZZ_ITERS=20000 THINFILM_FUZZ_SEED=7 cargo test
//! --release --test fuzz -- --nocapture` (see docs/robustness.md); the AFL targets in `fuzz/`
//! run the same loaders under coverage-guided fuzzing.

#[path = "../fuzz/targets.rs"]
mod targets;

use std::path::PathBuf;
use std::time::{Duration, Instant};
use targets::Target;

/// Inputs per target in CI.
const DEFAULT_ITERATIONS: usize = 600;
/// Longest any single input may take (a normal one takes milliseconds).
const SLOW: Duration = Duration::from_secs(10);

/// SplitMix64: small, fast, reproducible from its seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// Numbers that break size checks, domains and parsers.
const HOSTILE_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "-0",
    "1e308",
    "-1e308",
    "1e39",
    "3.4028236e38",
    "1e-320",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
    "65535",
    "65536",
    "2147483648",
    "1e26",
    "0.0000001",
    "99999999999999999999999",
];

/// Byte sequences worth splicing in.
const HOSTILE_BYTES: &[&[u8]] = &[
    b"\0",
    b"\xff\xff\xff\xff",
    b"\xff\xff\xff\x7f",
    b"\x00\x00\x00\x80",
    b"\x00\x00\xc0\x7f",
    b"\x00\x00\x80\x7f",
    b"{",
    b"}",
    b"[",
    b"]",
    b"\"",
    b"<",
    b">",
    b"</",
    b"&amp;",
    b"\n",
    b"=",
    b",",
    b"$x",
];

/// Spans of ASCII numbers in `data` (digits with sign, dot and exponent).
fn number_spans(data: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < data.len() {
        if data[i].is_ascii_digit() {
            let mut s = i;
            if s > 0 && data[s - 1] == b'-' {
                s -= 1;
            }
            let mut e = i;
            while e < data.len()
                && (data[e].is_ascii_digit() || matches!(data[e], b'.' | b'e' | b'E' | b'+' | b'-'))
            {
                e += 1;
            }
            spans.push((s, e));
            i = e;
        } else {
            i += 1;
        }
    }
    spans
}

/// Replaces a random JSON value with a hostile value of another type.
fn mutate_json(data: &[u8], rng: &mut Rng) -> Option<Vec<u8>> {
    let mut v: serde_json::Value = serde_json::from_slice(data).ok()?;
    let mut paths = Vec::new();
    collect_paths(&v, &mut Vec::new(), &mut paths);
    let path = rng.pick(&paths).clone();
    let mut at = &mut v;
    for key in &path {
        at = match (at, key) {
            (serde_json::Value::Object(m), Err(k)) => m.get_mut(k.as_str())?,
            (serde_json::Value::Array(a), Ok(i)) => a.get_mut(*i)?,
            _ => return None,
        };
    }
    let big = rng.below(1 << 20) as u64 * 4096;
    *at = match rng.below(10) {
        0 => serde_json::json!(null),
        1 => serde_json::json!("x"),
        2 => serde_json::json!(-1),
        3 => serde_json::json!(big),
        4 => serde_json::json!(u64::MAX),
        5 => serde_json::json!(1e300),
        6 => serde_json::json!([]),
        7 => serde_json::json!({}),
        8 => serde_json::json!(0),
        _ => match at {
            serde_json::Value::Array(a) if !a.is_empty() => {
                let mut a = a.clone();
                let dup = a[rng.below(a.len())].clone();
                a.push(dup);
                serde_json::Value::Array(a)
            }
            _ => serde_json::json!(true),
        },
    };
    serde_json::to_vec(&v).ok()
}

/// Paths to every value: object keys as `Err(key)`, array indices as `Ok(i)`.
fn collect_paths(
    v: &serde_json::Value,
    prefix: &mut Vec<Result<usize, String>>,
    out: &mut Vec<Vec<Result<usize, String>>>,
) {
    out.push(prefix.clone());
    match v {
        serde_json::Value::Object(m) => {
            for (k, c) in m {
                prefix.push(Err(k.clone()));
                collect_paths(c, prefix, out);
                prefix.pop();
            }
        }
        serde_json::Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                prefix.push(Ok(i));
                collect_paths(c, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

/// One mutation of `data`.
fn mutate_once(data: &mut Vec<u8>, rng: &mut Rng) {
    let len = data.len();
    match rng.below(11) {
        0 if len > 0 => {
            let i = rng.below(len);
            data[i] ^= 1 << rng.below(8);
        }
        1 if len > 0 => {
            let i = rng.below(len);
            data[i] = *rng.pick(&[0u8, 0xff, 0x7f, 0x80, b'9', b'-']);
        }
        2 if len > 0 => data.truncate(rng.below(len)),
        3 if len > 0 => {
            let a = rng.below(len);
            let b = (a + 1 + rng.below(64)).min(len);
            data.drain(a..b);
        }
        4 if len > 0 => {
            let a = rng.below(len);
            let b = (a + 1 + rng.below(256)).min(len);
            let chunk = data[a..b].to_vec();
            let at = rng.below(len);
            data.splice(at..at, chunk);
        }
        5 => {
            let at = rng.below(len + 1);
            data.splice(at..at, rng.pick(HOSTILE_BYTES).iter().copied());
        }
        6..=8 => {
            let spans = number_spans(data);
            if !spans.is_empty() {
                let (a, b) = *rng.pick(&spans);
                data.splice(a..b, rng.pick(HOSTILE_NUMBERS).bytes());
            }
        }
        9 => {
            if let Some(j) = mutate_json(data, rng) {
                *data = j;
            }
        }
        _ => {
            // Drop or repeat a line.
            let lines: Vec<usize> = std::iter::once(0)
                .chain(
                    data.iter()
                        .enumerate()
                        .filter(|(_, &c)| c == b'\n')
                        .map(|(i, _)| i + 1),
                )
                .collect();
            let a = *rng.pick(&lines);
            let b = data[a..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(len, |p| a + p + 1);
            if rng.below(2) == 0 {
                data.drain(a..b);
            } else {
                let line = data[a..b].to_vec();
                data.splice(a..a, line);
            }
        }
    }
}

fn env_number(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Mutates `target`'s seeds for the configured number of iterations; panics on a finding.
fn campaign(target: Target) {
    // Keep what one input may allocate small: this process runs many targets at once.
    std::env::set_var(thinfilm::limits::MEMORY_LIMIT_VAR, "256M");
    let iterations = env_number("THINFILM_FUZZ_ITERS", DEFAULT_ITERATIONS as u64) as usize;
    let seed = env_number("THINFILM_FUZZ_SEED", 1);
    let dir = tempfile::tempdir().unwrap();
    targets::prepare_assets(dir.path()).unwrap();
    let seeds = targets::seeds(target, dir.path());
    let mut rng = Rng(seed ^ (target as u64).wrapping_mul(0x1234_5678_9abc_def1));
    let (mut accepted, mut slowest) = (0usize, Duration::ZERO);
    let findings = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-findings");
    std::fs::create_dir_all(&findings).unwrap();
    // The input being run, kept in case it kills the whole process (an abort, the OOM killer).
    let current = findings.join(format!("{target:?}-current"));
    for i in 0..iterations {
        let mut data = rng.pick(&seeds).clone();
        for _ in 0..1 + rng.below(4) {
            mutate_once(&mut data, &mut rng);
        }
        std::fs::write(&current, &data).unwrap();
        let start = Instant::now();
        let outcome = std::panic::catch_unwind(|| targets::run(target, &data, dir.path()));
        let took = start.elapsed();
        slowest = slowest.max(took);
        let finding = match &outcome {
            Err(_) => Some("panic".to_string()),
            Ok(Err(msg)) if msg.contains(thinfilm::limits::CONTAINED_PANIC) => {
                Some(format!("contained panic: {msg}"))
            }
            _ if took > SLOW => Some(format!("took {took:?}")),
            Ok(Ok(())) => {
                accepted += 1;
                None
            }
            Ok(Err(_)) => None,
        };
        if let Some(what) = finding {
            let file = findings.join(format!("{target:?}-seed{seed}-iter{i}"));
            std::fs::write(&file, &data).unwrap();
            panic!(
                "{target:?} iteration {i}: {what}; input saved to {}",
                file.display()
            );
        }
    }
    let _ = std::fs::remove_file(&current);
    eprintln!(
        "{target:?}: {iterations} inputs, {accepted} accepted, slowest {:.3} s",
        slowest.as_secs_f64()
    );
}

#[test]
fn fuzz_envi_header() {
    campaign(Target::EnviHeader);
}

#[test]
fn fuzz_envi_cube() {
    campaign(Target::EnviCube);
}

#[test]
fn fuzz_capture_json() {
    campaign(Target::CaptureJson);
}

#[test]
fn fuzz_mitsuba_xml() {
    campaign(Target::MitsubaXml);
}

#[test]
fn fuzz_ply() {
    campaign(Target::Ply);
}

#[test]
fn fuzz_obj() {
    campaign(Target::Obj);
}

#[test]
fn fuzz_gltf() {
    campaign(Target::Gltf);
}

#[test]
fn fuzz_glb() {
    campaign(Target::Glb);
}

#[test]
fn fuzz_exr() {
    campaign(Target::Exr);
}

#[test]
fn fuzz_serialized() {
    campaign(Target::Serialized);
}

#[test]
fn fuzz_include() {
    campaign(Target::Include);
}

#[test]
fn fuzz_image() {
    campaign(Target::Image);
}

#[test]
fn fuzz_provenance() {
    campaign(Target::Provenance);
}

#[test]
fn seeds_are_accepted() {
    // The mutations start from valid files: each seed must load (and render or fit).
    let dir = tempfile::tempdir().unwrap();
    targets::prepare_assets(dir.path()).unwrap();
    for target in targets::ALL {
        for (k, seed) in targets::seeds(target, dir.path()).iter().enumerate() {
            targets::run(target, seed, dir.path())
                .unwrap_or_else(|e| panic!("{target:?} seed {k} refused: {e}"));
        }
    }
}
