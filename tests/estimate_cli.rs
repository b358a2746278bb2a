//! End to end: `thinfilm simulate`'s library writer → `thinfilm estimate` binary → every
//! output file, and the CLI's error for a single-angle capture without `--film-ior`.

use std::process::Command;
use thinfilm::capture::simulate::{write_capture_set, SimulateConfig};

fn small_capture(dir: &std::path::Path, angles: Vec<f64>) {
    let mut cfg = SimulateConfig::preset("sample1").unwrap();
    cfg.width = 12;
    cfg.height = 8;
    cfg.noise_sigma = 0.004;
    cfg.angles_deg = angles;
    write_capture_set(&cfg, dir).unwrap();
}

#[test]
fn estimate_writes_every_output_and_reports_truth_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    small_capture(&cap, vec![10.0, 20.0, 30.0, 40.0, 50.0]);
    let out = tmp.path().join("fit");
    let st = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "estimate",
            cap.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ])
        .arg("--ground-truth")
        .arg(&cap)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for f in [
        "fit.json",
        "thickness.exr",
        "thickness.png",
        "residual.png",
        "material.xml",
        "material.gltf",
        "thickness_gltf.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let text = std::fs::read_to_string(out.join("fit.json")).unwrap();
    assert!(!text.contains("NaN"));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["method"], "full");
    let n = v["film_ior"].as_f64().unwrap();
    assert!((n - 1.37).abs() < 0.01, "n {n}");
    assert!(v["ground_truth"]["thickness_mae_nm"].as_f64().unwrap() < 5.0);
    assert!(
        v["thickness_nm"]["p5"].as_f64().unwrap() <= v["thickness_nm"]["p95"].as_f64().unwrap()
    );
    assert_eq!(v["pixels"]["valid"].as_u64().unwrap(), 96);
    let de = &v["delta_e_ab_d65_mean"];
    assert!(de
        .as_f64()
        .map(|d| (0.0..5.0).contains(&d))
        .unwrap_or(v["delta_e_reason"].is_string()));
    let (w, h, d) = thinfilm::image_io::read_exr_channel(&out.join("thickness.exr"), "Y").unwrap();
    assert_eq!((w, h, d.len()), (12, 8, 96));
    let xml = std::fs::read_to_string(out.join("material.xml")).unwrap();
    assert!(
        xml.contains("type=\"thinfilm\"")
            && xml.contains("thickness.exr")
            && xml.contains("film_ior")
    );
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("material.gltf")).unwrap()).unwrap();
    let ir = &g["materials"][0]["extensions"]["KHR_materials_iridescence"];
    assert!(
        ir["iridescenceThicknessMinimum"].as_f64().unwrap()
            < ir["iridescenceThicknessMaximum"].as_f64().unwrap()
    );
}

#[test]
fn single_angle_without_index_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    small_capture(&cap, vec![30.0]);
    let out = tmp.path().join("fit");
    let st = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "estimate",
            cap.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("--film-ior"), "{err}");
    assert!(!out.join("fit.json").exists(), "nothing half-written");
    let st = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "estimate",
            cap.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            "--film-ior",
            "1.37",
            "--method",
            "paper",
        ])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
}

/// A noise-free capture fitted exactly is not reported as a misfit (its χ²/dof against a
/// noise estimate at the floor only measures the model's own float rounding), while the
/// same capture with the wrong fixed index still is.
#[test]
fn noise_free_capture_fits_without_a_misfit_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    let mut cfg = SimulateConfig::preset("sample1").unwrap();
    cfg.width = 16;
    cfg.height = 16;
    cfg.noise_sigma = 0.0;
    let true_n = match cfg.film_ior {
        thinfilm::optics::Ior::Constant(n) => n.re,
        _ => panic!("sample1 has a constant index"),
    };
    write_capture_set(&cfg, &cap).unwrap();
    let run = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_thinfilm"))
            .arg("estimate")
            .arg(&cap)
            .arg("--out")
            .arg(tmp.path().join("fit"))
            .arg("--quiet")
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let err = run(&[]);
    assert!(!err.contains("does not explain the data"), "{err}");
    let wrong = format!("{}", true_n + 0.01);
    let err = run(&["--film-ior", &wrong]);
    assert!(err.contains("does not explain the data"), "{err}");
}
