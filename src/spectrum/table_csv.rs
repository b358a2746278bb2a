//! Parser for the 1 nm colour tables in `spectra/*.csv`, shared by `build.rs` (which compiles
//! them into arrays, `#[path]`-including this file) and the tests.
//!
//! Format: lines starting with `#` are comments; the first other line is the header and must
//! equal the expected column names; every data row has one number per column, and the first
//! column `lambda_nm` runs 360, 361, …, 830 exactly. Errors name the source and line.

/// First and last wavelength of every table, nm, and the row count.
pub const TABLE_LAMBDA_MIN_NM: i64 = 360;
pub const TABLE_LAMBDA_MAX_NM: i64 = 830;
pub const TABLE_ROWS: usize = (TABLE_LAMBDA_MAX_NM - TABLE_LAMBDA_MIN_NM + 1) as usize;

/// Parse `text` (read from `source`, used in messages) into rows of `columns.len()` numbers.
pub fn parse_1nm_table(
    text: &str,
    source: &str,
    columns: &[&str],
) -> Result<Vec<Vec<f64>>, String> {
    let mut header_seen = false;
    let mut rows: Vec<Vec<f64>> = Vec::with_capacity(TABLE_ROWS);
    for (idx, raw) in text.lines().enumerate() {
        let at = format!("{source}:{}", idx + 1);
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if !header_seen {
            if fields != columns {
                return Err(format!("{at}: header is {fields:?}, expected {columns:?}"));
            }
            header_seen = true;
            continue;
        }
        if fields.len() != columns.len() {
            return Err(format!(
                "{at}: {} fields, expected {} ({})",
                fields.len(),
                columns.len(),
                columns.join(",")
            ));
        }
        let mut row = Vec::with_capacity(columns.len());
        for (field, name) in fields.iter().zip(columns) {
            let v: f64 = field
                .parse()
                .map_err(|e| format!("{at}: column `{name}`: `{field}` is not a number ({e})"))?;
            if !v.is_finite() {
                return Err(format!("{at}: column `{name}`: `{field}` is not finite"));
            }
            row.push(v);
        }
        if rows.len() == TABLE_ROWS {
            return Err(format!("{at}: extra row beyond {TABLE_LAMBDA_MAX_NM} nm"));
        }
        let expected = TABLE_LAMBDA_MIN_NM + rows.len() as i64;
        if row[0] != expected as f64 {
            return Err(format!(
                "{at}: lambda_nm is {}, expected {expected} (tables must be \
                 {TABLE_LAMBDA_MIN_NM}..={TABLE_LAMBDA_MAX_NM} nm in 1 nm steps)",
                row[0]
            ));
        }
        rows.push(row);
    }
    if !header_seen {
        return Err(format!("{source}: no header line"));
    }
    if rows.len() != TABLE_ROWS {
        return Err(format!(
            "{source}: {} data rows, expected {TABLE_ROWS} ({TABLE_LAMBDA_MIN_NM}..={TABLE_LAMBDA_MAX_NM} nm at 1 nm)",
            rows.len()
        ));
    }
    Ok(rows)
}
