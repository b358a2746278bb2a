//! The capture simulator: spectra against the optics core, band integration limits,
//! simulate → load round trips (float and raw counts), determinism, and the CLI.

use std::path::Path;
use thinfilm::capture::envi::Interleave;
use thinfilm::capture::simulate::{
    thickness_field, write_capture_set, BandModel, SimulateConfig, Simulator,
};
use thinfilm::capture::{load_capture_set, load_ground_truth, InvalidCounts, Polarization};
use thinfilm::optics::{Complex64, Ior, ThinFilm};

fn small(preset: &str) -> SimulateConfig {
    SimulateConfig {
        width: 12,
        height: 9,
        wavelengths_nm: thinfilm::capture::simulate::parse_wavelengths("400:720:8").unwrap(),
        thickness_variation: 0.1,
        ..SimulateConfig::preset(preset).unwrap()
    }
}

fn point_reflectance(cfg: &SimulateConfig, d: f64, lambda: f64, deg: f64) -> f64 {
    let film = ThinFilm {
        ambient_ior: cfg.ambient_ior,
        film_ior: cfg.film_ior.at(lambda),
        thickness_nm: d,
        substrate_ior: cfg.substrate_ior.at(lambda),
    };
    let r = film.response_at_angle(lambda, deg).unwrap();
    cfg.polarization.reflectance(&r)
}

#[test]
fn point_sampled_capture_equals_the_optics_core() {
    for (preset, pol) in [
        ("sample1", Polarization::S),
        ("sample3", Polarization::P),
        ("sample2", Polarization::Unpolarized),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SimulateConfig {
            fwhm_nm: 0.0,
            polarization: pol,
            substrate_ior: Ior::Constant(Complex64::new(1.64, 0.01)),
            interleave: Interleave::Bip,
            ..small(preset)
        };
        write_capture_set(&cfg, dir.path()).unwrap();
        let set = load_capture_set(dir.path()).unwrap();
        let gt = load_ground_truth(dir.path()).unwrap();
        assert_eq!(set.polarization, pol);
        assert_eq!(set.fwhm_nm, None);
        assert_eq!(set.invalid, InvalidCounts::default());
        assert_eq!(gt.film_ior, cfg.film_ior);
        assert_eq!(gt.substrate_ior, cfg.substrate_ior);
        let nb = set.bands();
        let mut worst = 0f64;
        for a in &set.angles {
            for p in 0..set.width * set.height {
                let d = gt.thickness_nm[p] as f64;
                for (b, &l) in set.wavelengths_nm.iter().enumerate() {
                    let want = point_reflectance(&cfg, d, l, a.incident_deg);
                    worst = worst.max((a.reflectance.at(p * nb + b) as f64 - want).abs());
                }
            }
        }
        // f32 storage of values ≤ 1: ≤ 6e-8 rounding.
        assert!(worst < 1e-7, "{preset}: {worst}");
    }
}

#[test]
fn band_integration_limits() {
    let cfg = small("sample1");
    let cos = 30f64.to_radians().cos();
    // fwhm → 0 equals point sampling.
    let narrow = BandModel::new(
        &SimulateConfig {
            fwhm_nm: 1e-4,
            ..cfg.clone()
        },
        500.0,
    );
    let point = BandModel::new(
        &SimulateConfig {
            fwhm_nm: 0.0,
            ..cfg.clone()
        },
        500.0,
    );
    for b in 0..cfg.wavelengths_nm.len() {
        let (n, p) = (
            narrow.reflectance(b, 420.0, cos),
            point.reflectance(b, 420.0, cos),
        );
        assert!((n - p).abs() < 1e-9, "band {b}: {n} vs {p}");
        assert_eq!(
            p,
            point_reflectance(&cfg, 420.0, cfg.wavelengths_nm[b], 30.0)
        );
    }
    // A wide band on a spectrally flat response (d = 0: bare interface) changes nothing.
    let wide = BandModel::new(
        &SimulateConfig {
            fwhm_nm: 30.0,
            ..cfg.clone()
        },
        0.0,
    );
    let bare = point_reflectance(&cfg, 0.0, 500.0, 30.0);
    assert!((wide.reflectance(5, 0.0, cos) - bare).abs() < 1e-12);
    // A wide band smooths the fringes of a thin film: its spectrum varies less.
    let wide = BandModel::new(
        &SimulateConfig {
            fwhm_nm: 40.0,
            ..cfg.clone()
        },
        3000.0,
    );
    let point = BandModel::new(
        &SimulateConfig {
            fwhm_nm: 0.0,
            ..cfg.clone()
        },
        3000.0,
    );
    let range = |m: &BandModel| {
        let v: Vec<f64> = (0..cfg.wavelengths_nm.len())
            .map(|b| m.reflectance(b, 3000.0, cos))
            .collect();
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    assert!(
        range(&wide) < 0.5 * range(&point),
        "{} vs {}",
        range(&wide),
        range(&point)
    );
    // A very thick film (fringes ≪ band): the band value tends to the incoherent sum
    // R12 + T12² R23 / (1 − R12 R23) (lossless, s-polarised), it never aliases.
    let thick = 60_000.0;
    let cfg_thick = SimulateConfig {
        fwhm_nm: 10.0,
        wavelengths_nm: vec![500.0, 600.0],
        ..cfg.clone()
    };
    let m = BandModel::new(&cfg_thick, thick);
    let (n1, n2, n3) = (1.0f64, 1.37f64, 1.64f64);
    let sin1 = 30f64.to_radians().sin();
    let c1 = cos;
    let c2 = (1.0 - (n1 * sin1 / n2).powi(2)).sqrt();
    let c3 = (1.0 - (n1 * sin1 / n3).powi(2)).sqrt();
    let r12 = ((n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)).powi(2);
    let r23 = ((n2 * c2 - n3 * c3) / (n2 * c2 + n3 * c3)).powi(2);
    let incoherent = r12 + (1.0 - r12).powi(2) * r23 / (1.0 - r12 * r23);
    for b in 0..2 {
        let v = m.reflectance(b, thick, cos);
        assert!(
            (v - incoherent).abs() < 2e-4,
            "band {b}: {v} vs incoherent {incoherent}"
        );
    }
}

#[test]
fn round_trip_every_interleave_with_references_of_another_size() {
    for il in [Interleave::Bsq, Interleave::Bil, Interleave::Bip] {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SimulateConfig {
            interleave: il,
            width: 40,
            height: 35,
            ..small("sample2")
        };
        let summary = write_capture_set(&cfg, dir.path()).unwrap();
        let set = load_capture_set(dir.path()).unwrap();
        assert_eq!((set.width, set.height), (40, 35));
        assert_eq!(set.wavelengths_nm, cfg.wavelengths_nm);
        assert_eq!(set.fwhm_nm, Some(vec![4.0; cfg.wavelengths_nm.len()]));
        assert_eq!(
            set.angles
                .iter()
                .map(|a| a.incident_deg)
                .collect::<Vec<_>>(),
            cfg.angles_deg
        );
        assert_eq!(set.substrate_ior, Ior::real(1.64));
        let gt = load_ground_truth(&dir.path().join("ground_truth")).unwrap();
        assert_eq!(gt.thickness_nm, summary.thickness_nm);
        assert_eq!(gt.thickness_nm, thickness_field(&cfg));
        let sim = Simulator::new(&cfg, &gt.thickness_nm).unwrap();
        for (a, angle) in set.angles.iter().enumerate() {
            assert_eq!(angle.reflectance, sim.clean_cube(a, None), "{il} angle {a}");
        }
    }
}

fn stats(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("ground_truth/ground_truth.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn raw_counts_recover_reflectance_within_shot_noise() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SimulateConfig {
        raw_counts: true,
        width: 30,
        height: 20,
        ..small("sample3")
    };
    write_capture_set(&cfg, dir.path()).unwrap();
    let set = load_capture_set(dir.path()).unwrap();
    assert_eq!(set.invalid, InvalidCounts::default());
    let hdr = thinfilm::capture::envi::read_header(&dir.path().join("theta10.hdr")).unwrap();
    assert_eq!(hdr.data_type, thinfilm::capture::envi::DataType::U16);
    let white = thinfilm::capture::envi::read_header(&dir.path().join("white10.hdr")).unwrap();
    assert_eq!((white.samples, white.lines), (30, 20));
    let gt = load_ground_truth(dir.path()).unwrap();
    let sim = Simulator::new(&cfg, &gt.thickness_nm).unwrap();
    let nb = set.bands();
    let (mut sum_z2, mut n, mut worst_z) = (0.0, 0.0, 0f64);
    for (a, angle) in set.angles.iter().enumerate() {
        let clean = sim.clean_cube(a, None);
        for (i, (&got, &want)) in angle.reflectance.to_vec().iter().zip(&clean).enumerate() {
            // Shot + read noise of one reading, divided by the white signal (the white
            // reference itself is averaged over 600 samples: negligible).
            let lambda = cfg.wavelengths_nm[i % nb];
            let s =
                cfg.white_counts * (0.35 + 0.65 * (-((lambda - 600.0) / 170.0f64).powi(2)).exp());
            let sigma = ((want as f64 * s) + cfg.read_noise.powi(2) + 1.0 / 12.0).sqrt() / s;
            let z = (got as f64 - want as f64) / sigma;
            sum_z2 += z * z;
            n += 1.0;
            worst_z = worst_z.max(z.abs());
        }
    }
    let rms_z = (sum_z2 / n).sqrt();
    // The error really is noise of the predicted size: RMS z ≈ 1, nothing beyond ~6σ.
    assert!((rms_z - 1.0).abs() < 0.05, "rms z {rms_z}");
    assert!(worst_z < 6.0, "worst z {worst_z}");
    assert_eq!(stats(dir.path())["options"]["raw_counts"], true);
}

#[test]
fn additive_noise_has_the_requested_sigma_and_is_seeded() {
    let run = |seed: u64| {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SimulateConfig {
            noise_sigma: 0.01,
            seed,
            angles_deg: vec![20.0],
            ..small("sample1")
        };
        write_capture_set(&cfg, dir.path()).unwrap();
        let set = load_capture_set(dir.path()).unwrap();
        let field = thickness_field(&cfg);
        let sim = Simulator::new(&cfg, &field).unwrap();
        let clean = sim.clean_cube(0, None);
        let diff: Vec<f64> = set.angles[0]
            .reflectance
            .to_vec()
            .iter()
            .zip(&clean)
            .map(|(a, b)| (a - b) as f64)
            .collect();
        (set.angles[0].reflectance.clone(), diff)
    };
    let (a, diff) = run(5);
    let n = diff.len() as f64;
    let mean = diff.iter().sum::<f64>() / n;
    let sd = (diff.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(
        mean.abs() < 0.002 && (sd / 0.01 - 1.0).abs() < 0.1,
        "mean {mean} sd {sd}"
    );
    assert_eq!(run(5).0, a);
    assert_ne!(run(6).0, a);
}

#[test]
fn cli_presets_and_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "simulate",
            "--preset",
            "sample3",
            "--size",
            "8x6",
            "--thickness",
            "450",
            "--angles",
            "15,35",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let gt = stats(&out);
    assert_eq!(gt["options"]["preset"], "sample3");
    assert_eq!(gt["film"]["ior"], 2.37);
    assert_eq!(gt["options"]["thickness_nm"], 450.0);
    assert_eq!(gt["width"], 8);
    assert_eq!(gt["options"]["polarization"], "s");
    let mean = gt["thickness_nm"]["mean"].as_f64().unwrap();
    assert!((mean - 450.0).abs() < 1e-3, "{mean}");
    let set = load_capture_set(&out).unwrap();
    assert_eq!(set.angles.len(), 2);
    assert_eq!(set.bands(), 81);
    // Bad options: non-zero exit and a message, nothing written.
    for bad in [
        vec!["--size", "8"],
        vec!["--polarization", "q"],
        vec!["--thickness-variation", "2"],
        vec!["--wavelengths", "700:400:4"],
        vec!["--film-ior", "Unobtainium"],
    ] {
        let bad_out = dir.path().join("bad");
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_thinfilm"))
            .arg("simulate")
            .args(&bad)
            .arg("--out")
            .arg(&bad_out)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{bad:?}");
        assert!(!o.stderr.is_empty());
        assert!(!bad_out.join("capture.json").exists());
    }
}
