//! Point spectra (`thinfilm estimate --spectra`): simulated white-light spectra of
//! free-standing soap films as a fibre spectrometer records them (lamp spectrum × film
//! reflectance + stray light, arbitrary scale, a dark "void" spectrum, noise), fitted with
//! the index known. Measured spectra are checked when `THINFILM_SOAP_SPECTRA` names a
//! folder of `orderK/*.xy` files with `orderK/known_value.yaml` labels and a `void.xy`
//! (skipped otherwise: such data is not redistributable).

use std::path::{Path, PathBuf};
use std::process::Command;

/// Normal-incidence reflectance of a free-standing film of index n (Airy sum).
fn soap_reflectance(n: f64, d_nm: f64, lambda_nm: f64) -> f64 {
    let r = (1.0 - n) / (1.0 + n);
    let r2 = r * r;
    let c = (4.0 * std::f64::consts::PI * n * d_nm / lambda_nm).cos();
    2.0 * r2 * (1.0 - c) / (1.0 + r2 * r2 - 2.0 * r2 * c)
}

/// A deterministic uniform in [-0.5, 0.5).
fn jitter(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
}

fn write_spectrum(path: &Path, f: impl Fn(f64) -> f64) {
    let mut text = String::from("wavelength_nm,intensity\n");
    for i in 0..801 {
        let l = 400.0 + 0.5 * i as f64;
        text += &format!("{l:.2},{:.6}\n", f(l));
    }
    std::fs::write(path, text).unwrap();
}

fn within(d: f64, label: f64) -> bool {
    (d - label).abs() <= (0.01 * label).max(10.0)
}

/// Runs the estimator on `files` and returns (file, thickness, σ) per spectrum.
fn fit(files: &[PathBuf], dark: &Path, out: &Path, ior: &str) -> Vec<(String, f64, f64)> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_thinfilm"));
    cmd.args(["estimate", "--quiet", "--out"])
        .arg(out)
        .args(["--film-ior", ior, "--max-thickness-nm", "5000", "--dark"])
        .arg(dark)
        .arg("--spectra")
        .args(files);
    let o = cmd.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("thickness.csv")).unwrap();
    csv.lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.rsplitn(3, ',').collect();
            (
                c[2].to_string(),
                c[1].parse().unwrap(),
                c[0].parse().unwrap(),
            )
        })
        .collect()
}

#[test]
fn simulated_soap_film_spectra_are_fitted_with_honest_sigma() {
    let dir = std::env::temp_dir().join(format!("thinfilm-soap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lamp = |l: f64| 0.6 + 0.4 * (-((l - 620.0) / 160.0).powi(2)).exp();
    let stray = |l: f64| 0.05 + 0.02 * (l - 400.0) / 400.0;
    let dark = dir.join("void.xy");
    write_spectrum(&dark, stray);
    let mut seed = 7u64;
    let mut files = Vec::new();
    let mut labels = Vec::new();
    for i in 0..24 {
        let d = 300.0 + 150.0 * i as f64 + 40.0 * jitter(&mut seed);
        let gain = 2.0 + jitter(&mut seed);
        let noise: Vec<f64> = (0..801).map(|_| 0.004 * jitter(&mut seed)).collect();
        let p = dir.join(format!("film{i:02}.xy"));
        write_spectrum(&p, |l| {
            let k = ((l - 400.0) / 0.5).round() as usize;
            gain * lamp(l) * soap_reflectance(1.33, d, l) + stray(l) + noise[k]
        });
        files.push(p);
        labels.push(d);
    }
    let rows = fit(&files, &dark, &dir.join("fit"), "1.33");
    assert_eq!(rows.len(), labels.len());
    let mut hits = 0;
    for ((_, d, s), label) in rows.iter().zip(&labels) {
        hits += within(*d, *label) as usize;
        // The claimed σ covers the error (5σ, at least 0.5 nm of model error).
        assert!(
            (d - label).abs() <= 5.0 * s.max(0.5),
            "d {d} nm ± {s} vs {label} nm"
        );
    }
    assert!(hits >= 23, "{hits} of 24 within max(1 %, 10 nm)");
    std::fs::remove_dir_all(&dir).ok();
}

/// Films thinner than one fringe recorded with another lamp shape than the thick films
/// that fix the shared spectral multiplier (lamp drift between sessions, a re-taken
/// reference): their thickness is not identifiable independent of that multiplier, so the
/// claimed σ must cover what the mismatch does to them.
#[test]
fn sub_fringe_films_with_a_lamp_mismatch_get_a_sigma_that_covers_it() {
    let dir = std::env::temp_dir().join(format!("thinfilm-soap-thin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Lamp × spectrometer response of the thick films' session: a strong red tilt.
    let lamp =
        |l: f64| (0.6 + 0.4 * (-((l - 620.0) / 160.0).powi(2)).exp()) * (0.5 + (l - 400.0) / 400.0);
    // The thin films' session: the same lamp, a third of that tilt gone.
    let lamp_thin = |l: f64| lamp(l).powf(2.0 / 3.0);
    let stray = |l: f64| 0.05 + 0.02 * (l - 400.0) / 400.0;
    let dark = dir.join("void.xy");
    write_spectrum(&dark, stray);
    let mut seed = 11u64;
    let mut files = Vec::new();
    let mut labels = Vec::new();
    for i in 0..20 {
        let thin = i >= 12;
        let d = if thin {
            80.0 + 6.0 * (i - 12) as f64
        } else {
            400.0 + 250.0 * i as f64
        } + 4.0 * jitter(&mut seed);
        let gain = 2.0 + jitter(&mut seed);
        let noise: Vec<f64> = (0..801).map(|_| 0.004 * jitter(&mut seed)).collect();
        let p = dir.join(format!("film{i:02}.xy"));
        write_spectrum(&p, |l| {
            let k = ((l - 400.0) / 0.5).round() as usize;
            let s = if thin { lamp_thin(l) } else { lamp(l) };
            gain * s * soap_reflectance(1.33, d, l) + stray(l) + noise[k]
        });
        files.push(p);
        labels.push(d);
    }
    let rows = fit(&files, &dark, &dir.join("fit"), "1.33");
    assert_eq!(rows.len(), labels.len());
    for ((f, d, s), label) in rows.iter().zip(&labels) {
        assert!(
            (d - label).abs() <= 3.0 * s.max(0.5),
            "{f}: d {d:.1} nm ± {s:.2} vs {label:.1} nm"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// What measured soap-film spectra do (fibre spectrometer): thick films lose fringe
/// contrast towards the blue (their thickness varies across the light spot), a lamp ×
/// response curve, a dark offset and stray light (given as the void spectrum), noise. A
/// multiplier shared with the thick films absorbs their contrast loss as a red-rising
/// lamp and biased films of less than half a fringe thin (15–25 nm at 80–125 nm on
/// measured data): they must land within max(1 %, 10 nm) with σ covering the error.
#[test]
fn thin_films_are_not_biased_by_the_thick_films_contrast_loss() {
    let dir = std::env::temp_dir().join(format!("thinfilm-soap-contrast-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Lamp × response over the reference's: a colour-temperature drift, a tilt.
    let lamp = |l: f64| 0.7 + 0.6 * (l - 400.0) / 400.0;
    let void = |l: f64| 0.04 + 0.03 * (l - 400.0) / 400.0;
    let dark = dir.join("void.xy");
    write_spectrum(&dark, void);
    // Thickness spread across the spot: R averaged over d ± δ (Gauss–Hermite-like nodes).
    let smeared = |d: f64, delta: f64, l: f64| {
        let nodes = [
            (-2.0, 0.054),
            (-1.0, 0.242),
            (0.0, 0.4),
            (1.0, 0.242),
            (2.0, 0.054),
        ];
        let w: f64 = nodes.iter().map(|n| n.1).sum();
        nodes
            .iter()
            .map(|(x, wt)| wt * soap_reflectance(1.33, d + x * delta, l))
            .sum::<f64>()
            / w
    };
    let mut seed = 23u64;
    let (mut files, mut labels) = (Vec::new(), Vec::new());
    for i in 0..30 {
        let thin = i >= 14;
        let (d, delta) = if thin {
            (80.0 + 3.0 * (i - 14) as f64, 2.0)
        } else {
            (250.0 + 40.0 * i as f64, 25.0)
        };
        let d = d + 2.0 * jitter(&mut seed);
        let gain = 8.0 + 2.0 * jitter(&mut seed);
        let noise: Vec<f64> = (0..801).map(|_| 0.01 * jitter(&mut seed)).collect();
        let p = dir.join(format!("film{i:02}.xy"));
        write_spectrum(&p, |l| {
            let k = ((l - 400.0) / 0.5).round() as usize;
            gain * lamp(l) * smeared(d, delta, l) + void(l) + noise[k]
        });
        files.push(p);
        labels.push(d);
    }
    let rows = fit(&files, &dark, &dir.join("fit"), "1.33");
    let mut hits = 0;
    for ((f, d, s), label) in rows.iter().zip(&labels) {
        hits += within(*d, *label) as usize;
        assert!(
            (d - label).abs() <= 5.0 * s.max(0.5),
            "{f}: d {d:.1} nm ± {s:.2} vs {label:.1} nm"
        );
    }
    assert!(hits >= 26, "{hits} of 30 within max(1 %, 10 nm)");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn measured_soap_film_spectra_when_available() {
    let Some(base) = std::env::var_os("THINFILM_SOAP_SPECTRA").map(PathBuf::from) else {
        eprintln!("THINFILM_SOAP_SPECTRA not set: measured spectra skipped");
        return;
    };
    let mut files = Vec::new();
    let mut labels = std::collections::HashMap::new();
    // `known_value_large_tol.yaml`: labels its authors check at 25 % only (the thinnest).
    for k in 0..10 {
        for name in ["known_value.yaml", "known_value_large_tol.yaml"] {
            let yaml = base.join(format!("order{k}/{name}"));
            let Ok(text) = std::fs::read_to_string(&yaml) else {
                continue;
            };
            for line in text.lines().filter(|l| !l.trim_start().starts_with('#')) {
                if let Some((f, v)) = line.trim().split_once(".xy:") {
                    let path = base.join(format!("order{k}/{f}.xy"));
                    let key = path.display().to_string();
                    if labels
                        .insert(key, v.trim().parse::<f64>().unwrap())
                        .is_none()
                    {
                        files.push(path);
                    }
                }
            }
        }
    }
    assert!(
        !files.is_empty(),
        "no labelled spectra under {}",
        base.display()
    );
    let out = std::env::temp_dir().join(format!("thinfilm-soap-measured-{}", std::process::id()));
    let rows = fit(&files, &base.join("void.xy"), &out, "1.33");
    let hits = rows
        .iter()
        .filter(|(f, d, _)| within(*d, labels[f]))
        .count();
    let covered = rows
        .iter()
        .filter(|(f, d, s)| (d - labels[f]).abs() <= 5.0 * s)
        .count();
    eprintln!(
        "{hits} of {} within max(1 %, 10 nm); |error| ≤ 5σ for {covered}",
        rows.len()
    );
    assert!(hits as f64 >= 0.85 * rows.len() as f64);
    assert!(covered as f64 >= 0.95 * rows.len() as f64);
    std::fs::remove_dir_all(&out).ok();
}
