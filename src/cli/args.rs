//! Value parsers shared by the subcommands: every number from the command line is checked
//! for its domain while the arguments are parsed, so a bad value (`nan`, `inf`, a negative
//! count, an index of 10²⁶) is refused by clap with the option's name and exit status 2,
//! before any work starts.

use thinfilm::limits::{check_index, MAX_THICKNESS_NM};
use thinfilm::optics::Ior;

fn number(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if !v.is_finite() {
        return Err(format!("{s} is not a finite number"));
    }
    Ok(v)
}

fn in_range(s: &str, lo: f64, hi: f64) -> Result<f64, String> {
    let v = number(s)?;
    if !(lo..=hi).contains(&v) {
        return Err(format!("{v} is outside [{lo}, {hi}]"));
    }
    Ok(v)
}

/// A finite number ≥ 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    in_range(s, 0.0, f64::MAX)
}

/// A finite number, as f32 (angles).
pub fn finite_f32(s: &str) -> Result<f32, String> {
    in_range(s, f32::MIN as f64, f32::MAX as f64).map(|v| v as f32)
}

/// A finite number ≥ 0, as f32 (exposures).
pub fn non_negative_f32(s: &str) -> Result<f32, String> {
    in_range(s, 0.0, f32::MAX as f64).map(|v| v as f32)
}

/// A thickness in nm, in [0, 20 µm].
pub fn thickness_nm(s: &str) -> Result<f64, String> {
    in_range(s, 0.0, MAX_THICKNESS_NM)
}

/// A real film index for the estimator, in [1, 10].
pub fn film_index(s: &str) -> Result<f64, String> {
    in_range(s, 1.0, 10.0)
}

/// The ambient medium's index, in [1, 3] (air, water, immersion oils).
pub fn ambient_index(s: &str) -> Result<f64, String> {
    in_range(s, 1.0, 3.0)
}

/// An index specification (number, n+ki, material, formula) that is physical over the
/// visible range.
pub fn index(s: &str) -> Result<Ior, String> {
    let ior: Ior = s.parse()?;
    check_index("index", &ior).map_err(|e| e.to_string())?;
    Ok(ior)
}

/// A step of a search grid: finite and > 0 (the command checks how many steps it makes).
pub fn positive(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v <= 0.0 {
        return Err(format!("{v} must be > 0"));
    }
    Ok(v)
}

/// A count ≥ 1 (strides, factors).
pub fn count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("'{s}' is not a whole number ≥ 1")),
    }
}

/// Worker threads: 1 to 1024.
pub fn threads(s: &str) -> Result<usize, String> {
    let n = count(s)?;
    if n > 1024 {
        return Err(format!("{n} threads: at most 1024"));
    }
    Ok(n)
}

/// Width × height for images and captures: `WxH`, each side 1 to 65536.
pub fn size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{s}' is not WxH (e.g. 256x256)"))?;
    let side = |t: &str| {
        t.trim()
            .parse::<usize>()
            .ok()
            .filter(|v| (1..=65536).contains(v))
            .ok_or_else(|| format!("'{s}': '{}' is not a whole number in 1..=65536", t.trim()))
    };
    Ok((side(w)?, side(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domains() {
        assert_eq!(non_negative("2.5"), Ok(2.5));
        for bad in ["nan", "inf", "-1", "x", "1e400"] {
            assert!(non_negative(bad).is_err(), "{bad}");
        }
        assert!(thickness_nm("1e300").is_err());
        assert!(film_index("1e26").is_err());
        assert!(film_index("0").is_err());
        assert!(positive("0").is_err());
        assert_eq!(count("3"), Ok(3));
        assert!(count("0").is_err());
        assert!(threads("100000000").is_err());
        assert_eq!(size("8x6"), Ok((8, 6)));
        for bad in ["0x5", "200000x200000", "99999999999999999999x2", "8"] {
            assert!(size(bad).is_err(), "{bad}");
        }
        assert!(index("1e26").is_err());
        assert!(index("MgF2").is_ok());
    }
}
