//! The CSV table parser that build.rs uses: malformed tables are rejected with a message that
//! names the file and line, and the committed tables parse.

use thinfilm::spectrum::table_csv::parse_1nm_table;

const COLS: &[&str] = &["lambda_nm", "d65"];

/// A valid two-column table with `f` applied to its data lines.
fn table(edit: impl Fn(usize, String) -> Option<String>) -> String {
    let mut s = String::from("# comment\nlambda_nm,d65\n");
    for (i, l) in (360..=830).enumerate() {
        if let Some(line) = edit(i, format!("{l},{}", 50.0 + i as f64 * 0.1)) {
            s.push_str(&line);
            s.push('\n');
        }
    }
    s
}

fn err(text: &str) -> String {
    parse_1nm_table(text, "spectra/x.csv", COLS).expect_err("malformed table accepted")
}

#[test]
fn valid_table_parses() {
    let rows = parse_1nm_table(&table(|_, l| Some(l)), "t.csv", COLS).unwrap();
    assert_eq!(rows.len(), 471);
    assert_eq!(rows[470], vec![830.0, 50.0 + 47.0]);
}

#[test]
fn committed_tables_parse() {
    let root = env!("CARGO_MANIFEST_DIR");
    for (name, cols) in [
        (
            "cie1931_2deg_cmf_1nm.csv",
            &["lambda_nm", "x_bar", "y_bar", "z_bar"][..],
        ),
        ("cie_d65_1nm.csv", &["lambda_nm", "d65"][..]),
    ] {
        let path = format!("{root}/spectra/{name}");
        let text = std::fs::read_to_string(&path).unwrap();
        let rows = parse_1nm_table(&text, &path, cols).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rows.len(), 471);
    }
}

#[test]
fn malformed_tables_name_file_and_line() {
    // Data line i sits on file line i + 3 (comment, header).
    let e = err(&table(|i, l| {
        Some(if i == 10 { "370,abc".into() } else { l })
    }));
    assert!(
        e.starts_with("spectra/x.csv:13:") && e.contains("not a number"),
        "{e}"
    );

    let e = err(&table(|i, l| {
        Some(if i == 5 { "365,1,2".into() } else { l })
    }));
    assert!(
        e.starts_with("spectra/x.csv:8:") && e.contains("3 fields"),
        "{e}"
    );

    let e = err(&table(|i, l| if i == 100 { None } else { Some(l) }));
    assert!(
        e.starts_with("spectra/x.csv:103:") && e.contains("expected 460"),
        "{e}"
    );

    let e = err(&table(|i, l| {
        Some(if i == 3 { "363,NaN".into() } else { l })
    }));
    assert!(
        e.starts_with("spectra/x.csv:6:") && e.contains("not finite"),
        "{e}"
    );

    let e = err(&table(|i, l| if i > 400 { None } else { Some(l) }));
    assert!(e.contains("401 data rows"), "{e}");

    let e = err(&table(|_, l| Some(l)).replace("lambda_nm,d65", "lambda,d65"));
    assert!(
        e.starts_with("spectra/x.csv:2:") && e.contains("header"),
        "{e}"
    );

    let e = err(&(table(|_, l| Some(l)) + "831,1\n"));
    assert!(e.contains("extra row"), "{e}");

    assert!(err("").contains("no header"));
}

#[test]
fn rgb2spec_table_parser_rejects_bad_files() {
    use thinfilm::spectrum::{srgb_table, Rgb2SpecTable};
    assert_eq!(srgb_table().resolution(), 64);
    assert!(Rgb2SpecTable::from_bytes(b"").unwrap_err().contains("SPEC"));
    assert!(Rgb2SpecTable::from_bytes(b"SPAM\x40\0\0\0")
        .unwrap_err()
        .contains("SPEC"));
    // Header claims res 64 but the data are missing.
    let e = Rgb2SpecTable::from_bytes(b"SPEC\x40\0\0\0").unwrap_err();
    assert!(e.contains("truncated"), "{e}");
    // A tiny valid table (res 2) with decreasing z-nodes is rejected, a proper one accepted.
    let mut bytes = b"SPEC\x02\0\0\0".to_vec();
    for z in [0.0f32, 1.0] {
        bytes.extend_from_slice(&z.to_le_bytes());
    }
    bytes.extend(std::iter::repeat_n(0u8, 4 * 9 * 8));
    let t = Rgb2SpecTable::from_bytes(&bytes).unwrap();
    // All-zero coefficients: S(0) = ½ everywhere.
    assert_eq!(t.fetch([0.3, 0.6, 0.9]).eval(500.0), 0.5);
    bytes[8..12].copy_from_slice(&2.0f32.to_le_bytes());
    assert!(Rgb2SpecTable::from_bytes(&bytes)
        .unwrap_err()
        .contains("increasing"));
}
