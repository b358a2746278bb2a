//! Defences every loader shares against hostile or careless input (docs/robustness.md):
//!
//! - a **memory budget**: before allocating what a file declares (pixels × bands, vertex
//!   counts, buffer lengths), [`check_alloc`] compares the bytes with the budget and refuses
//!   with an error that names the number; [`size_product`] multiplies sizes read from a file
//!   with overflow checks, so a header cannot wrap a size check to zero;
//! - **numeric domains**: [`check_range`] for every float from a file or the command line
//!   (finite, inside the physical range), with the limits every stage agrees on;
//! - **panic containment**: [`contain_panics`] runs a loader and turns a panic raised inside a
//!   third-party decoder into an error naming the file, so no panic reaches the user.
//!
//! The budget is [`DEFAULT_MEMORY_LIMIT`] unless the environment variable
//! `THINFILM_MEMORY_LIMIT` sets another (`4G`, `512M`, `1.5G` or bytes).

use anyhow::{anyhow, bail, Result};
use std::cell::Cell;
use std::fmt::Display;
use std::path::Path;
use std::sync::{Once, OnceLock};

/// Bytes one input may make the process allocate for its decoded data (2 GiB).
pub const DEFAULT_MEMORY_LIMIT: u64 = 2 << 30;

/// The environment variable that overrides [`DEFAULT_MEMORY_LIMIT`].
pub const MEMORY_LIMIT_VAR: &str = "THINFILM_MEMORY_LIMIT";

/// Largest film thickness any stage accepts, nm. The fringes of a 20 µm film lie 4–8 nm apart
/// across the visible, no wider than a hyperspectral camera's bands: thicker films show no
/// interference a capture resolves, and simulating them costs band-integration nodes in
/// proportion to the thickness.
pub const MAX_THICKNESS_NM: f64 = 20_000.0;

/// Largest real part of a refractive index accepted anywhere (dielectrics stay below ~5,
/// metals' n below ~30 in the visible and near infrared).
pub const MAX_IOR: f64 = 100.0;

/// Largest extinction coefficient k accepted anywhere.
pub const MAX_EXTINCTION: f64 = 1000.0;

/// Wavelengths at which an index (possibly a formula) is checked: the visible range of the
/// renderer and the colour-matching functions, 360–830 nm.
const CHECK_WAVELENGTHS_NM: [f64; 8] = [360.0, 400.0, 450.0, 500.0, 550.0, 650.0, 750.0, 830.0];

/// Parses `4G`, `512M`, `64K`, `1.5G` or a plain byte count.
fn parse_bytes(s: &str) -> Option<u64> {
    let t = s.trim();
    let (num, mult) = match t.char_indices().last()? {
        (i, 'G' | 'g') => (&t[..i], (1u64 << 30) as f64),
        (i, 'M' | 'm') => (&t[..i], (1u64 << 20) as f64),
        (i, 'K' | 'k') => (&t[..i], 1024.0),
        _ => (t, 1.0),
    };
    let v = num.trim().parse::<f64>().ok()? * mult;
    (v.is_finite() && v >= 1.0 && v < u64::MAX as f64).then_some(v as u64)
}

/// The memory budget in bytes (see the module docs).
pub fn memory_limit() -> u64 {
    static LIMIT: OnceLock<u64> = OnceLock::new();
    *LIMIT.get_or_init(|| match std::env::var(MEMORY_LIMIT_VAR) {
        Err(_) => DEFAULT_MEMORY_LIMIT,
        Ok(v) => parse_bytes(&v).unwrap_or_else(|| {
            eprintln!(
                "warning: {MEMORY_LIMIT_VAR}={v:?} is not a size like 4G or 512M; using {}",
                human_bytes(DEFAULT_MEMORY_LIMIT)
            );
            DEFAULT_MEMORY_LIMIT
        }),
    })
}

/// `1.5 GiB`, `320.0 MiB`, `12 bytes`.
pub fn human_bytes(b: u64) -> String {
    const UNITS: [(&str, u64); 4] = [
        ("TiB", 1 << 40),
        ("GiB", 1 << 30),
        ("MiB", 1 << 20),
        ("KiB", 1 << 10),
    ];
    for (name, size) in UNITS {
        if b >= size {
            return format!("{:.1} {name}", b as f64 / size as f64);
        }
    }
    format!("{b} bytes")
}

/// Refuses to allocate `bytes` for `what` when that exceeds the memory budget.
pub fn check_alloc(what: impl Display, bytes: u64) -> Result<()> {
    let limit = memory_limit();
    if bytes > limit {
        bail!(
            "{what} needs {} ({bytes} bytes), more than the memory limit of {} \
             (raise it with {MEMORY_LIMIT_VAR}=…, e.g. {MEMORY_LIMIT_VAR}=8G)",
            human_bytes(bytes),
            human_bytes(limit)
        );
    }
    Ok(())
}

/// The product of sizes read from a file, as `u64`, or an error naming them when it overflows.
/// `factors` are `(name, value)` pairs, e.g. `[("samples", w), ("lines", h), ("bands", b)]`.
pub fn size_product(what: impl Display, factors: &[(&str, u64)]) -> Result<u64> {
    factors
        .iter()
        .try_fold(1u64, |acc, &(_, v)| acc.checked_mul(v))
        .ok_or_else(|| {
            let list: Vec<String> = factors.iter().map(|(n, v)| format!("{n} {v}")).collect();
            anyhow!("{what}: size {} overflows 64 bits", list.join(" × "))
        })
}

/// `value` if it is finite and inside `[lo, hi]`, else an error naming `what`.
pub fn check_range(what: impl Display, value: f64, lo: f64, hi: f64) -> Result<f64> {
    if !(value.is_finite() && value >= lo && value <= hi) {
        bail!("{what} = {value} must be a finite number in [{lo}, {hi}]");
    }
    Ok(value)
}

/// Checks that a refractive index is physical over 360–830 nm: finite, 0 < n ≤ [`MAX_IOR`],
/// 0 ≤ k ≤ [`MAX_EXTINCTION`] (a dispersion formula may have a pole or go negative there).
pub fn check_index(what: impl Display, ior: &crate::optics::Ior) -> Result<()> {
    for lambda in CHECK_WAVELENGTHS_NM {
        let c = ior.at(lambda);
        let ok = c.re.is_finite()
            && c.im.is_finite()
            && c.re > 0.0
            && c.re <= MAX_IOR
            && (0.0..=MAX_EXTINCTION).contains(&c.im);
        if !ok {
            bail!(
                "{what} = {ior} gives n + ik = {} + {}i at {lambda} nm: an index needs \
                 0 < n ≤ {MAX_IOR} and 0 ≤ k ≤ {MAX_EXTINCTION}",
                c.re,
                c.im
            );
        }
    }
    Ok(())
}

/// Reads a whole input file of kind `what` ("scene file", "capture set", …) whose parsed
/// form takes up to `expansion` times its size in memory. Refuses, with the file's name, what
/// is not a regular file (a folder, a FIFO or `/dev/zero` would block or never end) and files
/// whose size times `expansion` exceeds the memory budget; reads at most that size, so a file
/// that grows while it is read cannot exhaust memory either.
pub fn read_file(path: &Path, what: &str, expansion: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| anyhow!("{what} {}: {e}", path.display()))?;
    if !meta.is_file() {
        bail!("{what} {} is not a regular file", path.display());
    }
    let len = meta.len();
    check_alloc(
        format!("{what} {} ({len} bytes)", path.display()),
        len.saturating_mul(expansion.max(1)),
    )?;
    let mut bytes = Vec::with_capacity(len as usize);
    std::fs::File::open(path)
        .and_then(|f| f.take(len).read_to_end(&mut bytes))
        .map_err(|e| anyhow!("reading {what} {}: {e}", path.display()))?;
    Ok(bytes)
}

/// [`read_file`] for a text file: invalid UTF-8 is an error naming the file and the byte.
pub fn read_text(path: &Path, what: &str, expansion: u64) -> Result<String> {
    String::from_utf8(read_file(path, what, expansion)?).map_err(|e| {
        anyhow!(
            "{what} {}: not UTF-8 text (invalid byte at offset {})",
            path.display(),
            e.utf8_error().valid_up_to()
        )
    })
}

thread_local! {
    /// > 0 while this thread runs inside [`contain_panics`]: the panic hook stays silent.
    static CONTAINED: Cell<u32> = const { Cell::new(0) };
}

/// Installs (once) a panic hook that is silent for contained panics and otherwise behaves
/// like the default one.
fn install_quiet_hook() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if CONTAINED.with(Cell::get) == 0 {
                default(info);
            }
        }));
    });
}

/// Runs the loader `f` for `file`; a panic inside it (a third-party decoder meeting input it
/// does not expect) becomes an error naming the file instead of reaching the user.
pub fn contain_panics<T>(file: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    install_quiet_hook();
    CONTAINED.with(|c| c.set(c.get() + 1));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    CONTAINED.with(|c| c.set(c.get() - 1));
    result.unwrap_or_else(|payload| {
        let msg = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown cause".into());
        Err(anyhow!("{}: {CONTAINED_PANIC}: {msg}", file.display()))
    })
}

/// Marker in the message of a contained panic (the fuzz tests look for it: every one is a
/// bug to turn into a validation error).
pub const CONTAINED_PANIC: &str = "malformed file: its decoder failed";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_products_overflow() {
        assert_eq!(parse_bytes("4G"), Some(4 << 30));
        assert_eq!(parse_bytes("1.5g"), Some(3 << 29));
        assert_eq!(parse_bytes("512M"), Some(512 << 20));
        assert_eq!(parse_bytes("1000"), Some(1000));
        for bad in ["", "G", "-1G", "nanG", "1e30G", "lots"] {
            assert_eq!(parse_bytes(bad), None, "{bad}");
        }
        assert_eq!(size_product("x", &[("a", 3), ("b", 5)]).unwrap(), 15);
        let e = size_product("c.hdr", &[("samples", 1 << 32), ("lines", 1 << 32)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("c.hdr") && e.contains("samples 4294967296"),
            "{e}"
        );
        let e = check_alloc("cube c.hdr", 320 << 30)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cube c.hdr") && e.contains("320.0 GiB"), "{e}");
        assert!(check_alloc("small", 1 << 20).is_ok());
    }

    #[test]
    fn ranges_reject_nan_inf_and_outside() {
        assert_eq!(check_range("x", 1.5, 1.0, 3.0).unwrap(), 1.5);
        for v in [f64::NAN, f64::INFINITY, 0.5, 3.5] {
            let e = check_range("ambient_ior", v, 1.0, 3.0)
                .unwrap_err()
                .to_string();
            assert!(e.contains("ambient_ior"), "{e}");
        }
        use crate::optics::Ior;
        assert!(check_index("film", &Ior::real(1.37)).is_ok());
        assert!(check_index("film", &"Au".parse().unwrap()).is_ok());
        for bad in ["1e26", "1.5+5000i"] {
            let ior: Ior = bad.parse().unwrap();
            assert!(check_index("film", &ior).is_err(), "{bad}");
        }
    }

    #[test]
    fn panics_become_errors_naming_the_file() {
        let e = contain_panics(Path::new("bad.glb"), || -> Result<()> {
            let v: Vec<u8> = std::hint::black_box(Vec::new());
            let _ = v[std::hint::black_box(3)];
            Ok(())
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("bad.glb") && e.contains(CONTAINED_PANIC), "{e}");
        assert_eq!(contain_panics(Path::new("ok"), || Ok(7)).unwrap(), 7);
    }
}
