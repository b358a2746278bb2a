//! `capture.json` loading: references, masking and counting of invalid samples, and clear
//! errors for malformed sets.

use std::path::Path;
use thinfilm::capture::envi::{self, DataType, WriteOptions};
use thinfilm::capture::{load_capture_set, InvalidCounts, Polarization};
use thinfilm::optics::{Complex64, Ior};

const WL: [f64; 3] = [500.0, 550.0, 600.0];

fn cube(
    dir: &Path,
    name: &str,
    w: usize,
    h: usize,
    dt: DataType,
    data: &[f32],
    ignore: Option<f64>,
) {
    cube_wl(dir, name, w, h, dt, data, ignore, &WL);
}

#[allow(clippy::too_many_arguments)]
fn cube_wl(
    dir: &Path,
    name: &str,
    w: usize,
    h: usize,
    dt: DataType,
    data: &[f32],
    ignore: Option<f64>,
    wl: &[f64],
) {
    let mut o = WriteOptions::new(w, h, wl.len());
    o.data_type = dt;
    o.wavelengths_nm = Some(wl.to_vec());
    o.ignore_value = ignore;
    envi::write_cube(&dir.join(name), data, &o).unwrap();
}

fn json(dir: &Path, text: &str) {
    std::fs::write(dir.join("capture.json"), text).unwrap();
}

fn err(dir: &Path) -> String {
    format!("{:#}", load_capture_set(dir).unwrap_err())
}

#[test]
fn float_cubes_load_as_reflectance() {
    let d = tempfile::tempdir().unwrap();
    let a: Vec<f32> = (0..2 * 2 * 3).map(|i| i as f32 * 0.01).collect();
    let b: Vec<f32> = a.iter().map(|v| v + 0.5).collect();
    cube(d.path(), "t10.hdr", 2, 2, DataType::F32, &a, None);
    cube(d.path(), "t20.hdr", 2, 2, DataType::F64, &b, None);
    json(
        d.path(),
        r#"{"format": "thinfilm-capture/1", "polarization": "unpolarized", "ambient_ior": 1.0,
            "substrate": {"ior": 0.18, "k": 3.4},
            "angles": [{"incident_deg": 10, "cube": "t10.hdr"}, {"incident_deg": 20.5, "cube": "t20.hdr"}]}"#,
    );
    let set = load_capture_set(d.path()).unwrap();
    assert_eq!(set.polarization, Polarization::Unpolarized);
    assert_eq!(set.substrate_ior, Ior::Constant(Complex64::new(0.18, 3.4)));
    assert_eq!((set.width, set.height, set.bands()), (2, 2, 3));
    assert_eq!(set.wavelengths_nm, WL.to_vec());
    assert_eq!(set.angles[1].incident_deg, 20.5);
    assert_eq!(set.angles[0].reflectance, a);
    assert_eq!(set.angles[1].reflectance, b);
    assert!(set.angles.iter().all(|a| a.valid.iter().all(|&v| v)));
    assert_eq!(set.invalid, InvalidCounts::default());
    // The capture.json path itself is accepted too.
    assert_eq!(
        load_capture_set(&d.path().join("capture.json"))
            .unwrap()
            .angles
            .len(),
        2
    );
}

#[test]
fn raw_counts_with_references_and_every_invalid_cause() {
    let d = tempfile::tempdir().unwrap();
    let (w, h) = (3, 2);
    // White 4×1 px (another size than the cube), dark 1×1. Band 2: white == dark → bad reference.
    let white = [
        1100.0, 2100.0, 500.0, 1100.0, 2100.0, 500.0, 1100.0, 2100.0, 500.0, 1100.0, 2100.0, 500.0,
    ];
    // One white sample saturated (65535): excluded from the band mean, not propagated.
    let mut white = white.to_vec();
    white[3] = 65535.0;
    let dark = [100.0, 100.0, 500.0];
    cube(d.path(), "white.hdr", 4, 1, DataType::U16, &white, None);
    cube(d.path(), "dark.hdr", 1, 1, DataType::U16, &dark, None);
    // Raw cube: pixel-major, bands (500, 550, 600).
    let mut raw = Vec::new();
    for p in 0..w * h {
        raw.extend([100.0 + 100.0 * p as f32, 100.0 + 200.0 * p as f32, 700.0]);
    }
    raw[3] = 65535.0; // pixel 1 band 0: saturated
    raw[7] = 7.0; // pixel 2 band 1: the ignore value
    cube(d.path(), "raw.hdr", w, h, DataType::U16, &raw, Some(7.0));
    // A float cube with NaN and inf at a second angle, no references.
    let mut f: Vec<f32> = vec![0.25; w * h * 3];
    f[0] = f32::NAN;
    f[5] = f32::INFINITY;
    f[6] = f32::NEG_INFINITY;
    cube(d.path(), "f.hdr", w, h, DataType::F32, &f, None);
    json(
        d.path(),
        r#"{"format": "thinfilm-capture/1", "polarization": "s", "substrate": 1.64,
            "angles": [{"incident_deg": 30, "cube": "raw.hdr", "white": "white.hdr", "dark": "dark.hdr"},
                       {"incident_deg": 40, "cube": "f.hdr"}]}"#,
    );
    let set = load_capture_set(d.path()).unwrap();
    assert_eq!(set.ambient_ior, 1.0);
    let r = &set.angles[0].reflectance.to_vec();
    // R = (raw − dark)/(white − dark): band 0 span 1000, band 1 span 2000.
    assert_eq!(r[0], 0.0);
    assert!((r[1] - 0.0).abs() < 1e-7);
    assert!(r[3].is_nan()); // saturated
    assert!((r[6] - 0.2).abs() < 1e-6); // pixel 2 band 0: (300 − 100)/1000
    assert!(r[7].is_nan()); // ignore value
    assert!((r[3 * 5 + 1] - 0.5).abs() < 1e-6); // pixel 5 band 1: (1100 − 100)/2000
    assert!(r.chunks(3).all(|px| px[2].is_nan())); // bad reference band
    assert!(set.angles[0].valid.iter().all(|&v| !v));
    let f = &set.angles[1];
    let fr = |i| f.reflectance.at(i);
    assert!(fr(0).is_nan() && fr(5).is_nan() && fr(6).is_nan());
    assert_eq!(f.valid, vec![false, false, false, true, true, true]);
    assert_eq!(
        set.invalid,
        InvalidCounts {
            non_finite: 3,
            ignore_value: 1,
            saturated: 1,
            bad_reference: 6,
        }
    );
}

#[test]
fn malformed_sets_are_clear_errors() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    let data = vec![0.1f32; 2 * 2 * 3];
    cube(p, "a.hdr", 2, 2, DataType::F32, &data, None);
    cube(p, "b.hdr", 2, 2, DataType::F32, &data, None);
    cube(p, "small.hdr", 1, 2, DataType::F32, &data[..6], None);
    cube_wl(
        p,
        "wl.hdr",
        2,
        2,
        DataType::F32,
        &data,
        None,
        &[500.0, 550.0, 610.0],
    );
    cube_wl(
        p,
        "wl4.hdr",
        1,
        1,
        DataType::F32,
        &data[..4],
        None,
        &[500.0, 550.0, 600.0, 650.0],
    );
    let doc = |pol: &str, angles: &str| {
        format!(
            r#"{{"format": "thinfilm-capture/1", "polarization": "{pol}", "substrate": {{"ior": 1.64}}, "angles": [{angles}]}}"#
        )
    };
    let cases: Vec<(String, Vec<&str>)> = vec![
        (doc("q", r#"{"incident_deg": 10, "cube": "a.hdr"}"#), vec!["capture.json", "polarization", "'q'"]),
        (doc("s", r#"{"incident_deg": 10, "cube": "missing.hdr"}"#), vec!["capture.json", "angles[0].cube", "missing.hdr", "not found"]),
        (
            doc("s", r#"{"incident_deg": 10, "cube": "a.hdr"}, {"incident_deg": 20, "cube": "small.hdr"}"#),
            vec!["a.hdr", "small.hdr", "2×2", "1×2"],
        ),
        (
            doc("s", r#"{"incident_deg": 10, "cube": "a.hdr"}, {"incident_deg": 20, "cube": "wl.hdr"}"#),
            vec!["a.hdr", "wl.hdr", "wavelengths differ"],
        ),
        (
            doc("s", r#"{"incident_deg": 10, "cube": "a.hdr", "white": "wl4.hdr"}"#),
            vec!["angles[0].white", "wl4.hdr", "4 bands", "a.hdr"],
        ),
        (
            doc("s", r#"{"incident_deg": 10, "cube": "a.hdr", "dark": "b.hdr"}"#),
            vec!["angles[0]", "'white'"],
        ),
        (doc("s", r#"{"incident_deg": 95, "cube": "a.hdr"}"#), vec!["angles[0].incident_deg", "95"]),
        (doc("s", ""), vec!["'angles' is empty"]),
        (doc("s", r#"{"incident_deg": 10, "cube": "a.hdr", "whit": "b.hdr"}"#), vec!["capture.json", "whit"]),
        (
            r#"{"format": "thinfilm-capture/2", "polarization": "s", "substrate": 1.5, "angles": []}"#.into(),
            vec!["format", "thinfilm-capture/2"],
        ),
        (
            r#"{"format": "thinfilm-capture/1", "polarization": "s", "substrate": {"material": "Unobtainium"}, "angles": []}"#.into(),
            vec!["substrate", "Unobtainium"],
        ),
        (
            r#"{"format": "thinfilm-capture/1", "polarization": "s", "ambient_ior": "1.3+0.1i", "substrate": 1.5, "angles": []}"#.into(),
            vec!["ambient_ior", "real"],
        ),
        (r#"{"format": "thinfilm-capture/1", "polarization": "s", "#.into(), vec!["capture.json", "JSON"]),
    ];
    for (text, needles) in cases {
        json(p, &text);
        let e = err(p);
        for n in needles {
            assert!(e.contains(n), "'{n}' not in: {e}\n(json: {text})");
        }
    }
    // A folder without capture.json.
    let empty = tempfile::tempdir().unwrap();
    assert!(err(empty.path()).contains("capture.json"));
    // A cube without wavelengths.
    let mut o = WriteOptions::new(2, 2, 3);
    o.data_type = DataType::F32;
    envi::write_cube(&p.join("nowl.hdr"), &data, &o).unwrap();
    json(p, &doc("s", r#"{"incident_deg": 10, "cube": "nowl.hdr"}"#));
    let e = err(p);
    assert!(e.contains("nowl.hdr") && e.contains("wavelength"), "{e}");
}

/// Loads a capture.json in `dir` with `angles` (JSON objects) on `substrate`.
fn load_angles(dir: &Path, substrate: f64, angles: &[String]) -> thinfilm::capture::CaptureSet {
    json(
        dir,
        &format!(
            r#"{{"format": "thinfilm-capture/1", "polarization": "s", "substrate": {substrate}, "angles": [{}]}}"#,
            angles.join(", ")
        ),
    );
    load_capture_set(dir).unwrap()
}

/// Float32 cubes in this machine's byte order are read in place, whatever their
/// interleave (their samples are the file's mapping: no decoding pass, no copy); masking a
/// sample writes NaN into the loaded set, never into the file; the same data big-endian
/// (decoded and transposed in memory) loads to the same samples, masks and counts.
#[test]
fn float_cubes_are_read_in_place_and_equal_their_decoded_twins() {
    let d = tempfile::tempdir().unwrap();
    let (w, h) = (3, 2);
    let mut data: Vec<f32> = (0..w * h * 3).map(|i| 0.1 + i as f32 * 0.01).collect();
    data[4] = f32::INFINITY; // pixel 1
    data[9] = -1.0; // pixel 3: the ignore value
    let layouts = [
        ("bip", envi::Interleave::Bip, false),
        ("bsq", envi::Interleave::Bsq, false),
        ("bil", envi::Interleave::Bil, false),
        ("bsq_be", envi::Interleave::Bsq, true),
    ];
    for (name, il, big_endian) in layouts {
        let mut o = WriteOptions::new(w, h, 3);
        o.wavelengths_nm = Some(WL.to_vec());
        o.ignore_value = Some(-1.0);
        o.interleave = il;
        o.big_endian = big_endian;
        envi::write_cube(&d.path().join(format!("{name}.hdr")), &data, &o).unwrap();
    }
    let bytes_before: Vec<Vec<u8>> = (layouts.iter())
        .map(|l| std::fs::read(d.path().join(format!("{}.img", l.0))).unwrap())
        .collect();
    let angles: Vec<String> = (layouts.iter().enumerate())
        .map(|(i, l)| {
            format!(
                r#"{{"incident_deg": {}, "cube": "{}.hdr"}}"#,
                10 * (i + 1),
                l.0
            )
        })
        .collect();
    let set = load_angles(d.path(), 1.64, &angles);
    let mapped: Vec<bool> = set
        .angles
        .iter()
        .map(|a| a.reflectance.is_mapped())
        .collect();
    assert_eq!(mapped, vec![true, true, true, false]);
    let bits = |a: &thinfilm::capture::AngleCapture| {
        let v = a.reflectance.to_vec();
        v.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    let bip = &set.angles[0];
    for other in &set.angles[1..] {
        assert_eq!(bits(bip), bits(other), "{}°", other.incident_deg);
        assert_eq!(bip.valid, other.valid, "{}°", other.incident_deg);
    }
    assert!(bip.reflectance.at(9).is_nan() && bip.reflectance.at(10) == data[10]);
    assert_eq!(bip.valid, vec![true, false, true, false, true, true]);
    assert_eq!(set.invalid.non_finite, 4);
    assert_eq!(set.invalid.ignore_value, 4);
    for (l, before) in layouts.iter().zip(&bytes_before) {
        let now = std::fs::read(d.path().join(format!("{}.img", l.0))).unwrap();
        assert_eq!(&now, before, "{} was written", l.0);
    }
}

/// A planar (BSQ/BIL) float32 cube read in place gives every pixel exactly as decoding it
/// to BIP does, in any order of reading: row after row (tiles transposed), backwards and
/// scattered (pixels gathered alone), interleaved across more cubes than a thread keeps
/// tiles of, on a width that is not a multiple of the tile, from several threads.
#[test]
fn planar_cubes_read_in_place_match_their_decoded_twins_in_any_order() {
    use rayon::prelude::*;
    let d = tempfile::tempdir().unwrap();
    let (w, h, nb) = (301, 5, 11);
    let wl: Vec<f64> = (0..nb).map(|b| 450.0 + 20.0 * b as f64).collect();
    let (mut angles, mut written) = (Vec::new(), Vec::new());
    for k in 0..10 {
        // A different cube per angle: reading one in another's tile would show.
        let data: Vec<f32> = (0..w * h * nb)
            .map(|i| ((i * 7919 + k * 104_729) % 100_003) as f32 * 1e-5 + 0.01)
            .collect();
        written.push(data.clone());
        for (name, il, big) in [
            ("p", envi::Interleave::Bsq, false),
            ("d", envi::Interleave::Bsq, true),
        ] {
            let il = if k % 2 == 1 && name == "p" {
                envi::Interleave::Bil
            } else {
                il
            };
            let mut o = WriteOptions::new(w, h, nb);
            o.wavelengths_nm = Some(wl.clone());
            o.interleave = il;
            o.big_endian = big;
            envi::write_cube(&d.path().join(format!("{name}{k}.hdr")), &data, &o).unwrap();
        }
        angles.push(format!(
            r#"{{"incident_deg": {}, "cube": "p{k}.hdr"}}"#,
            5 * k
        ));
        angles.push(format!(
            r#"{{"incident_deg": {}, "cube": "d{k}.hdr"}}"#,
            5 * k + 1
        ));
    }
    let set = load_angles(d.path(), 1.5, &angles);
    let pairs: Vec<_> = set.angles.chunks(2).map(|c| (&c[0], &c[1])).collect();
    for (planar, decoded) in &pairs {
        assert!(planar.reflectance.as_bip().is_none() && decoded.reflectance.as_bip().is_some());
    }
    let n = w * h;
    let sequential: Vec<usize> = (0..n).collect();
    let backwards: Vec<usize> = (0..n).rev().collect();
    let scattered: Vec<usize> = (0..n).map(|i| (i * 7_877) % n).collect();
    let check = |order: &[usize]| {
        let (mut a, mut b) = (vec![0f32; nb], vec![0f32; nb]);
        for &p in order {
            for (planar, decoded) in &pairs {
                planar.reflectance.pixel(p, &mut a);
                decoded.reflectance.pixel(p, &mut b);
                assert_eq!(a, b, "pixel {p}, {}°", planar.incident_deg);
            }
        }
    };
    for order in [&sequential, &backwards, &scattered] {
        check(order);
    }
    // Rows on several threads, each with its own tiles.
    (0..h)
        .into_par_iter()
        .for_each(|y| check(&sequential[y * w..(y + 1) * w]));
    for (planar, decoded) in &pairs {
        assert_eq!(planar.reflectance.to_vec(), decoded.reflectance.to_vec());
    }
    // Both transpositions give the samples as written (BIP order).
    for ((planar, decoded), data) in pairs.iter().zip(&written) {
        assert_eq!(&planar.reflectance.to_vec(), data);
        assert_eq!(&decoded.reflectance.to_vec(), data);
        for i in [0, 5 * nb + 3, (w * h - 1) * nb + nb - 1] {
            assert_eq!(planar.reflectance.at(i), decoded.reflectance.at(i));
        }
    }
    let rows = set.rows(2, 4);
    for pair in rows.angles.chunks(2) {
        assert_eq!(pair[0].reflectance.to_vec(), pair[1].reflectance.to_vec());
    }
}
