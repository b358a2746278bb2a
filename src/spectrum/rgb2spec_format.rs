//! Checks of the rgb2spec "SPEC" table format (mitsuba-renderer/rgb2spec: magic, u32
//! resolution, `res` f32 z-nodes, then `[3][res][res][res][3]` f32 coefficients, all
//! little-endian), shared by `build.rs` (which checks the embedded table once, `#[path]`-
//! including this file) and [`super::rgb2spec`] (which reads that table in place unchecked and
//! parses other files with the same checks).

/// The resolution in a "SPEC" header, checked against the number of bytes (trailing bytes,
/// e.g. newer Mitsuba's forward-model block, are allowed).
pub fn spec_resolution(bytes: &[u8]) -> Result<usize, String> {
    if bytes.len() < 8 || &bytes[..4] != b"SPEC" {
        return Err("not an rgb2spec table (missing \"SPEC\" header)".into());
    }
    let res = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
    if !(2..=1024).contains(&res) {
        return Err(format!("implausible resolution {res}"));
    }
    let need = 8 + 4 * (res + 9 * res * res * res);
    if bytes.len() < need {
        return Err(format!(
            "truncated: {} bytes, resolution {res} needs {need}",
            bytes.len()
        ));
    }
    Ok(res)
}

/// [`spec_resolution`], and the values: strictly increasing z-nodes, finite coefficients.
pub fn check_spec(bytes: &[u8]) -> Result<usize, String> {
    let res = spec_resolution(bytes)?;
    let float = |k: usize| {
        let b = &bytes[8 + 4 * k..12 + 4 * k];
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    };
    if (1..res).any(|k| float(k).partial_cmp(&float(k - 1)) != Some(std::cmp::Ordering::Greater)) {
        return Err("z-nodes are not strictly increasing".into());
    }
    if let Some(i) = (0..9 * res * res * res).position(|i| !float(res + i).is_finite()) {
        return Err(format!("non-finite coefficient at index {i}"));
    }
    Ok(res)
}
