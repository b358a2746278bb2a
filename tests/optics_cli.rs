//! `thinfilm reflectance` end to end: CSV/JSON shape, plot written, bad input refused.

use std::process::Command;

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .arg("reflectance")
        .args(args)
        .output()
        .expect("run thinfilm");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn csv_single_film() {
    let (rc, out, err) = run(&[
        "--film-ior",
        "1.37",
        "--thickness",
        "400",
        "--substrate-ior",
        "1.64",
        "--angle",
        "0",
        "--wavelengths",
        "400:700:5",
    ]);
    assert_eq!(rc, 0, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "wavelength_nm,R_s,R_p,R");
    assert_eq!(lines.len(), 1 + 61);
    // At normal incidence R_s = R_p = R.
    let v: Vec<f64> = lines[1].split(',').map(|x| x.parse().unwrap()).collect();
    assert_eq!(v[0], 400.0);
    assert!((v[1] - v[2]).abs() < 1e-15 && (v[3] - v[1]).abs() < 1e-15);
}

#[test]
fn json_stack_with_colour_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("r.png");
    let (rc, out, err) = run(&[
        "--layer",
        "ZnS:60",
        "--layer",
        "MgF2:100",
        "--substrate-ior",
        "BK7",
        "--angle",
        "30",
        "--wavelengths",
        "400,512.5,700",
        "--format",
        "json",
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert_eq!(rc, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in ["wavelength_nm", "R_s", "R_p", "R", "T_s", "T_p", "T"] {
        assert_eq!(v[key].as_array().unwrap().len(), 3, "{key}");
    }
    for key in ["xyz", "srgb_linear", "lab"] {
        assert_eq!(v[key].as_array().unwrap().len(), 3, "{key}");
    }
    // Lossless stack: R + T = 1.
    for i in 0..3 {
        let r = v["R"][i].as_f64().unwrap();
        let t = v["T"][i].as_f64().unwrap();
        assert!((r + t - 1.0).abs() < 1e-12);
    }
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
}

#[test]
fn bad_inputs_exit_nonzero_with_message() {
    for (args, needle) in [
        (vec!["--film-ior", "1.37", "--thickness", "-5"], "thickness"),
        (
            vec!["--film-ior", "nan", "--thickness", "5"],
            "refractive index",
        ),
        (
            vec![
                "--film-ior",
                "1.37",
                "--thickness",
                "5",
                "--wavelengths",
                "0:700:5",
            ],
            "wavelength",
        ),
        (
            vec![
                "--film-ior",
                "1.37",
                "--thickness",
                "5",
                "--wavelengths",
                "-400",
            ],
            "wavelength",
        ),
        (
            vec!["--film-ior", "1.37", "--thickness", "5", "--angle", "90"],
            "angle",
        ),
        (
            vec!["--film-ior", "1.37", "--thickness", "5", "--angle", "-1"],
            "angle",
        ),
        (vec!["--layer", "1.5:x"], "thickness"),
    ] {
        let (rc, out, err) = run(&args);
        assert_ne!(rc, 0, "{args:?} accepted");
        assert!(out.is_empty(), "{args:?} wrote output");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}
