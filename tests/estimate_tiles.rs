//! A capture fitted in row bands (`thinfilm estimate --rows`, known index; each band computes
//! only its rows and a halo) and stitched by `thinfilm merge` equals the whole fit bit for
//! bit, thickness and σ — on a capture large enough that the thickness stage propagates from
//! a seed lattice and resolves orders spatially, with bands that do not line up with that
//! lattice. Tiles of different fits are refused.

use std::path::Path;
use std::process::{Command, Output};
use thinfilm::capture::simulate::{write_capture_set, SimulateConfig};
use thinfilm::image_io::read_exr;

fn thinfilm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(out: Output) -> String {
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn estimate(cap: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "estimate",
        cap.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    ok(thinfilm(&args));
}

fn thickness_bits(path: &Path) -> Vec<u32> {
    channel_bits(path, "Y")
}

fn channel_bits(path: &Path, channel: &str) -> Vec<u32> {
    read_exr(path)
        .unwrap()
        .channel(channel)
        .unwrap_or_else(|| panic!("{} has a channel {channel}", path.display()))
        .iter()
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn stitched_row_bands_equal_the_whole_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    // 60×44 px: the seed lattice has stride 2, so rows propagate from seeds. One angle, a
    // strongly varying film and heavy noise make order jumps that the spatial order
    // resolution repairs near the band edges (without the halo rows, 154 pixels differ).
    let mut cfg = SimulateConfig::preset("sample1").unwrap();
    (cfg.width, cfg.height) = (60, 44);
    cfg.noise_sigma = 0.06;
    cfg.thickness_variation = 0.4;
    cfg.angles_deg = vec![30.0];
    cfg.wavelengths_nm = (0..41).map(|i| 400.0 + 8.0 * i as f64).collect();
    write_capture_set(&cfg, &cap).unwrap();
    let n = "1.37";
    let whole = tmp.path().join("whole");
    estimate(&cap, &whole, &["--film-ior", n]);
    let bands = ["0:7", "7:23", "23:24", "24:44"];
    let mut tiles = Vec::new();
    for (i, rows) in bands.iter().enumerate() {
        let out = tmp.path().join(format!("band{i}"));
        estimate(&cap, &out, &["--film-ior", n, "--rows", rows]);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
        let (a, b) = rows.split_once(':').unwrap();
        assert_eq!(v["rows"][0].as_u64().unwrap().to_string(), a);
        assert_eq!(
            v["height"].as_u64().unwrap(),
            b.parse::<u64>().unwrap() - a.parse::<u64>().unwrap()
        );
        tiles.push(out.join("thickness.exr"));
    }
    let stitched = tmp.path().join("stitched.exr");
    let mut args = vec!["merge", "-o", stitched.to_str().unwrap()];
    args.extend(tiles.iter().rev().map(|t| t.to_str().unwrap()));
    let text = ok(thinfilm(&args));
    assert!(text.contains("stitched 4 row bands"), "{text}");
    let want = thickness_bits(&whole.join("thickness.exr"));
    assert!(
        want.iter()
            .filter(|&&b| f32::from_bits(b).is_finite())
            .count()
            > 2000
    );
    assert_eq!(thickness_bits(&stitched), want);
    // Each band computed only its rows and halo, yet its σ (curvature, χ², sub-fringe
    // refits from its own pixels; shared terms from the whole capture) is the whole fit's.
    let sigma = |dir: &Path| channel_bits(&dir.join("thickness_sigma.exr"), "thickness_sigma");
    let stitched_sigma: Vec<u32> = (0..bands.len())
        .flat_map(|i| sigma(&tmp.path().join(format!("band{i}"))))
        .collect();
    assert_eq!(stitched_sigma, sigma(&whole));
    assert_eq!(
        read_exr(&stitched).unwrap().attributes,
        read_exr(&whole.join("thickness.exr")).unwrap().attributes
    );

    // The bands' folders merge into a whole fit folder that reads like the single fit's.
    let bands: Vec<String> = (0..bands.len())
        .map(|i| tmp.path().join(format!("band{i}")).display().to_string())
        .collect();
    let merged = tmp.path().join("merged");
    let mut args = vec!["merge", "-o", merged.to_str().unwrap()];
    args.extend(bands.iter().map(String::as_str));
    ok(thinfilm(&args));
    assert_eq!(thickness_bits(&merged.join("thickness.exr")), want);
    let read = |d: &Path| thinfilm::material::FitFile::read(&d.join("fit.json")).unwrap();
    let (m, w) = (read(&merged), read(&whole));
    assert_eq!((m.width, m.height, m.rows), (w.width, w.height, None));
    assert_eq!(m.pixels, w.pixels);
    assert_eq!(m.thickness_nm, w.thickness_nm);
    assert_eq!(m.film_ior, w.film_ior);
    let rel = |a: Option<f64>, b: Option<f64>| (a.unwrap() - b.unwrap()).abs() / b.unwrap();
    assert!(rel(m.residual_rmse, w.residual_rmse) < 0.02, "{m:?}");
    // The bands' checks ran on their own pixels; pooled they describe the whole fit.
    assert!(rel(m.chi2_per_dof, w.chi2_per_dof) < 0.02, "{m:?}");
    assert_eq!(m.not_identifiable_pixels, w.not_identifiable_pixels);
    assert_eq!(m.invalid_samples, w.invalid_samples);
    assert_eq!(sigma(&merged), sigma(&whole));
    assert_eq!(
        format!("{:?}", m.thickness_sigma_nm),
        format!("{:?}", w.thickness_sigma_nm)
    );
    let material = thinfilm::material::FilmMaterial::from_fit_dir(&merged).unwrap();
    assert_eq!((material.width, material.height), (60, 44));
    for f in ["material.xml", "material.gltf", "thickness.png"] {
        assert!(merged.join(f).is_file(), "{f}");
    }

    // A band fitted with another index does not belong to this fit.
    let other = tmp.path().join("other");
    estimate(&cap, &other, &["--film-ior", "1.38", "--rows", "23:24"]);
    let bad = thinfilm(&[
        "merge",
        tiles[0].to_str().unwrap(),
        tiles[1].to_str().unwrap(),
        other.join("thickness.exr").to_str().unwrap(),
        tiles[3].to_str().unwrap(),
        "-o",
        tmp.path().join("bad.exr").to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    let e = String::from_utf8_lossy(&bad.stderr);
    assert!(e.contains("different fits") && e.contains("other"), "{e}");
    // Missing rows are named.
    let gap = thinfilm(&[
        "merge",
        tiles[0].to_str().unwrap(),
        tiles[3].to_str().unwrap(),
        "-o",
        tmp.path().join("gap.exr").to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&gap.stderr);
    assert!(
        !gap.status.success() && e.contains("rows 7:24 are missing"),
        "{e}"
    );
}

/// Without a given index, a band fits its own index (phase one of a huge capture) and reports
/// it; `--rows` outside the capture is refused naming the option.
#[test]
fn a_band_fits_its_own_index_and_bad_rows_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    let mut cfg = SimulateConfig::preset("sample1").unwrap();
    (cfg.width, cfg.height) = (24, 40);
    cfg.noise_sigma = 0.004;
    write_capture_set(&cfg, &cap).unwrap();
    let out = tmp.path().join("band");
    let json = ok(thinfilm(&[
        "estimate",
        cap.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--rows",
        "10:20",
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!((v["film_ior"].as_f64().unwrap() - 1.37).abs() < 0.01, "{v}");
    assert_eq!(v["pixels"]["valid"].as_u64().unwrap(), 24 * 10);
    let bad = thinfilm(&[
        "estimate",
        cap.to_str().unwrap(),
        "--out",
        tmp.path().join("x").to_str().unwrap(),
        "--rows",
        "30:41",
    ]);
    let e = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && e.contains("--rows 30:41"), "{e}");
}
