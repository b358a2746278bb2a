//! ENVI reader/writer: interoperability with Spectral Python fixtures (written by
//! `tools/spy_fixtures.py write`, committed) and malformed-input errors.
//!
//! The reverse direction: `cargo test --test capture_envi -- --ignored write_fixtures_for_spy`
//! writes `tests/fixtures/envi/ours/`, then `python3 tools/spy_fixtures.py check` reads them
//! with SPy. `ours_fixtures_are_reproduced` keeps the committed files in step with the writer.

use std::path::{Path, PathBuf};
use thinfilm::capture::envi::{self, DataType, Interleave, WriteOptions};

const LINES: usize = 4;
const SAMPLES: usize = 5;
const BANDS: usize = 6;

/// Mirrors `expected` in tools/spy_fixtures.py.
fn expected(kind: &str, y: usize, x: usize, b: usize) -> f64 {
    let (y, x, b) = (y as f64, x as f64, b as f64);
    match kind {
        "float32" | "float64" => (b * 100.0 + y * 10.0 + x) * 0.25 - 3.5,
        "uint16" if (y, x, b) == (3.0, 4.0, 5.0) => 65535.0,
        "uint16" => b * 10000.0 + y * 100.0 + x * 7.0 + 3.0,
        "int16" => b * 1000.0 + y * 100.0 + x * 7.0 - 3000.0,
        _ => unreachable!(),
    }
}

fn expected_bip(kind: &str) -> Vec<f32> {
    let mut v = Vec::new();
    for y in 0..LINES {
        for x in 0..SAMPLES {
            for b in 0..BANDS {
                v.push(expected(kind, y, x, b) as f32);
            }
        }
    }
    v
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/envi")
}

const WAVELENGTHS: [f64; BANDS] = [400.0, 420.0, 440.0, 460.0, 480.0, 500.0];

#[test]
fn spy_fixtures_read_back_equal() {
    let mut n = 0;
    for kind in ["float32", "uint16", "int16"] {
        for il in ["bsq", "bil", "bip"] {
            let path = fixtures().join(format!("spy/{kind}_{il}.hdr"));
            let cube = envi::read_cube(&path).unwrap_or_else(|e| panic!("{e:#}"));
            let h = &cube.header;
            assert_eq!((h.samples, h.lines, h.bands), (SAMPLES, LINES, BANDS));
            assert_eq!(h.interleave, il.parse::<Interleave>().unwrap());
            assert_eq!(h.data_type, DataType::from_name(kind).unwrap());
            assert_eq!(cube.data, expected_bip(kind), "{}", path.display());
            // uint16 fixtures give wavelengths in micrometres.
            let wl = h.wavelengths_nm.as_ref().unwrap();
            for (a, b) in wl.iter().zip(WAVELENGTHS) {
                assert!((a - b).abs() < 1e-9, "{kind} {il}: {a} vs {b}");
            }
            assert!(h
                .fwhm_nm
                .as_ref()
                .unwrap()
                .iter()
                .all(|f| (f - 5.0).abs() < 1e-9));
            assert_eq!(h.ignore_value, (kind == "int16").then_some(-3000.0));
            // Single-sample access agrees with the bulk decode.
            let file = envi::open(&path).unwrap();
            assert_eq!(file.sample(4, 3, 5) as f64, expected(kind, 3, 4, 5));
            n += 1;
        }
    }
    assert_eq!(n, 9);
    // Big-endian files are among them (checked so the byte-order path is really exercised).
    let be = envi::read_header(&fixtures().join("spy/float32_bsq.hdr")).unwrap();
    assert!(be.big_endian);
}

fn write_ours(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for kind in ["float32", "float64", "uint16", "int16"] {
        for il in [Interleave::Bsq, Interleave::Bil, Interleave::Bip] {
            let mut o = WriteOptions::new(SAMPLES, LINES, BANDS);
            o.interleave = il;
            o.data_type = DataType::from_name(kind).unwrap();
            o.big_endian = matches!(
                (kind, il),
                ("float32", Interleave::Bil)
                    | ("int16", Interleave::Bsq)
                    | ("float64", Interleave::Bip)
            );
            o.wavelengths_nm = Some(WAVELENGTHS.to_vec());
            o.fwhm_nm = Some(vec![5.0; BANDS]);
            o.description = Some(format!("thinfilm test fixture {kind} {il}"));
            let p = dir.join(format!("{kind}_{il}.hdr"));
            envi::write_cube(&p, &expected_bip(kind), &o).unwrap();
            out.push(p);
        }
    }
    out
}

/// Writes the cubes SPy checks (`python3 tools/spy_fixtures.py check`).
#[test]
#[ignore]
fn write_fixtures_for_spy() {
    let dir = fixtures().join("ours");
    for p in write_ours(&dir) {
        println!("wrote {}", p.display());
    }
}

#[test]
fn ours_fixtures_are_reproduced() {
    let tmp = tempfile::tempdir().unwrap();
    let written = write_ours(tmp.path());
    assert_eq!(written.len(), 12);
    for p in written {
        for ext in ["hdr", "img"] {
            let ours = p.with_extension(ext);
            let committed = fixtures().join("ours").join(ours.file_name().unwrap());
            assert_eq!(
                std::fs::read(&ours).unwrap(),
                std::fs::read(&committed).unwrap(),
                "{} differs from the committed fixture: rerun the ignored test and the SPy check",
                committed.display()
            );
        }
        // And our own reader reads it back.
        let cube = envi::read_cube(&p).unwrap();
        let kind = p
            .file_stem()
            .unwrap()
            .to_str()
            .unwrap()
            .split('_')
            .next()
            .unwrap()
            .to_string();
        assert_eq!(cube.data, expected_bip(&kind));
    }
}

fn write_text(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

const GOOD_HEADER: &str =
    "ENVI\nsamples = 2\nlines = 2\nbands = 3\nheader offset = 0\ndata type = 4\n\
                           interleave = bsq\nbyte order = 0\nwavelength = {500, 510, 520}\n";

fn err_of(path: &Path) -> String {
    format!("{:#}", envi::read_cube(path).unwrap_err())
}

#[test]
fn binary_found_by_stem_with_any_extension() {
    let dir = tempfile::tempdir().unwrap();
    let data: Vec<u8> = (0..12).flat_map(|i| (i as f32).to_le_bytes()).collect();
    for (i, ext) in ["img", "raw", "dat", "bin", ""].iter().enumerate() {
        let hdr = dir.path().join(format!("c{i}.hdr"));
        write_text(&hdr, GOOD_HEADER);
        let bin = if ext.is_empty() {
            dir.path().join(format!("c{i}"))
        } else {
            hdr.with_extension(ext)
        };
        std::fs::write(&bin, &data).unwrap();
        let cube = envi::read_cube(&hdr).unwrap();
        // BSQ → BIP: pixel 0 holds samples 0, 4, 8.
        assert_eq!(&cube.data[..3], &[0.0, 4.0, 8.0], "{ext}");
        // Opening by the binary path finds the header too.
        if !ext.is_empty() {
            assert_eq!(envi::read_cube(&bin).unwrap().data, cube.data);
        }
    }
}

#[test]
fn header_offset_and_ignore_value() {
    let dir = tempfile::tempdir().unwrap();
    let hdr = dir.path().join("off.hdr");
    write_text(
        &hdr,
        &GOOD_HEADER
            .replace("header offset = 0", "header offset = 7")
            .replace("data type = 4", "data type = 2\ndata ignore value = -1"),
    );
    let mut bytes = vec![0xAAu8; 7];
    bytes.extend((0..12).flat_map(|i| (i as i16 - 1).to_le_bytes()));
    std::fs::write(hdr.with_extension("img"), bytes).unwrap();
    let cube = envi::read_cube(&hdr).unwrap();
    assert_eq!(cube.data[0], -1.0);
    assert_eq!(cube.data[3], 0.0);
    assert_eq!(cube.header.ignore_value, Some(-1.0));
}

#[test]
fn malformed_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin: Vec<u8> = vec![0; 48];

    // Missing binary.
    let p = d.join("nobin.hdr");
    write_text(&p, GOOD_HEADER);
    let e = err_of(&p);
    assert!(
        e.contains("nobin.hdr") && e.contains("no binary data file"),
        "{e}"
    );

    // Truncated binary.
    let p = d.join("trunc.hdr");
    write_text(&p, GOOD_HEADER);
    std::fs::write(d.join("trunc.img"), &bin[..40]).unwrap();
    let e = err_of(&p);
    assert!(
        e.contains("trunc.img") && e.contains("truncated") && e.contains("48"),
        "{e}"
    );

    let cases: [(&str, String, &[&str]); 7] = [
        (
            "nosamples",
            GOOD_HEADER.replace("samples = 2\n", ""),
            &["samples"],
        ),
        (
            "dtype",
            GOOD_HEADER.replace("data type = 4", "data type = 6"),
            &["data type", "6"],
        ),
        (
            "dtype99",
            GOOD_HEADER.replace("data type = 4", "data type = 99"),
            &["data type", "99"],
        ),
        (
            "wlcount",
            GOOD_HEADER.replace("{500, 510, 520}", "{500, 510}"),
            &["wavelength", "2 values", "3 bands"],
        ),
        (
            "wlnum",
            GOOD_HEADER.replace("510", "5l0"),
            &["wavelength", "5l0"],
        ),
        (
            "interleave",
            GOOD_HEADER.replace("bsq", "bsx"),
            &["interleave", "bsx"],
        ),
        (
            "units",
            format!("{GOOD_HEADER}wavelength units = parsecs\n"),
            &["wavelength units", "parsecs"],
        ),
    ];
    for (name, text, needles) in cases {
        let p = d.join(format!("{name}.hdr"));
        write_text(&p, &text);
        std::fs::write(p.with_extension("img"), &bin).unwrap();
        let e = err_of(&p);
        assert!(e.contains(&format!("{name}.hdr")), "{name}: {e}");
        for n in needles {
            assert!(e.contains(n), "{name}: '{n}' not in: {e}");
        }
    }

    // Missing byte order for multi-byte data, missing header, not a header.
    let p = d.join("noorder.hdr");
    write_text(&p, &GOOD_HEADER.replace("byte order = 0\n", ""));
    assert!(err_of(&p).contains("byte order"));
    let e = err_of(&d.join("absent.hdr"));
    assert!(e.contains("absent.hdr"), "{e}");
    let p = d.join("garbage.hdr");
    std::fs::write(&p, [0u8, 159, 146, 150, 10, 61]).unwrap();
    assert!(err_of(&p).contains("not an ENVI header"));
}
