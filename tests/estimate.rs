//! Estimator accuracy on small simulated versions of the seed's Samples 1–3 and its
//! failure modes (no peaks, flat spectra, single angle, n² < sin²θ).

use thinfilm::capture::Polarization;
use thinfilm::estimate::synth::{self, SynthSpec};
use thinfilm::estimate::{estimate, report, Method, Options};
use thinfilm::optics::Ior;

fn small(n: f64, d: f64) -> SynthSpec {
    let mut s = SynthSpec::seed_conditions(n, d);
    s.width = 16;
    s.height = 12;
    s
}

#[test]
fn full_fits_the_three_seed_samples() {
    for (n, d) in [(1.37, 400.0), (1.37, 600.0), (2.37, 500.0)] {
        let spec = small(n, d);
        let (set, truth) = synth::capture(&spec);
        let fit = estimate(&set, &Options::default()).unwrap();
        let (mae, _, cnt) = synth::thickness_errors(&fit.thickness_nm, &truth);
        assert_eq!(cnt, spec.width * spec.height);
        let nerr = (fit.film_ior - n).abs();
        eprintln!(
            "full n={n} d={d}: n_fit={:.5} err={nerr:.5} mae={mae:.3}",
            fit.film_ior
        );
        assert!(nerr <= 0.005, "n error {nerr}");
        assert!(mae <= 3.0, "thickness MAE {mae}");
        let sigma = fit.film_ior_sigma.expect("uncertainty");
        assert!(sigma > 0.0 && sigma < 0.01);
        let rmse = fit.rmse().unwrap();
        assert!(
            (rmse - 0.004).abs() < 0.001,
            "residual RMSE {rmse} should match the noise"
        );
    }
}

#[test]
fn paper_and_grid_run_and_paper_is_worse_on_sample3() {
    let spec = small(2.37, 500.0);
    let (set, truth) = synth::capture(&spec);
    let paper = estimate(
        &set,
        &Options {
            method: Method::Paper,
            ..Options::default()
        },
    )
    .unwrap();
    let full = estimate(&set, &Options::default()).unwrap();
    let (mae_p, _, _) = synth::thickness_errors(&paper.thickness_nm, &truth);
    let (mae_f, _, _) = synth::thickness_errors(&full.thickness_nm, &truth);
    eprintln!(
        "paper n={:.4} mae={mae_p:.2}; full n={:.4} mae={mae_f:.2}",
        paper.film_ior, full.film_ior
    );
    assert!(paper.film_ior.is_finite());
    assert!(mae_f < mae_p);
    let mut g = small(1.37, 400.0);
    g.width = 6;
    g.height = 4;
    let (gset, gtruth) = synth::capture(&g);
    let grid = estimate(
        &gset,
        &Options {
            method: Method::Grid,
            min_film_ior: 1.2,
            max_film_ior: 1.6,
            max_thickness_nm: 800.0,
            ..Options::default()
        },
    )
    .unwrap();
    let (mae_g, _, _) = synth::thickness_errors(&grid.thickness_nm, &gtruth);
    assert!(
        (grid.film_ior - 1.37).abs() <= 0.02,
        "grid n {}",
        grid.film_ior
    );
    assert!(mae_g < 15.0, "grid mae {mae_g}");
}

#[test]
fn half_order_peaks_when_film_is_denser_than_substrate() {
    // ZnS (2.37) on PET (1.64): maxima at (m + ½)λ = φ. A thin film has one such peak;
    // reading it as a whole order would give d off by a half-fringe.
    for d in [150.0, 320.0] {
        let mut spec = small(2.37, d);
        spec.noise_sigma = 0.002;
        let (set, truth) = synth::capture(&spec);
        let fit = estimate(&set, &Options::default()).unwrap();
        let (mae, _, _) = synth::thickness_errors(&fit.thickness_nm, &truth);
        assert!(
            (fit.film_ior - 2.37).abs() < 0.01,
            "d={d} n {}",
            fit.film_ior
        );
        assert!(mae < 5.0, "d={d} mae {mae}");
    }
}

#[test]
fn known_index_works_with_one_angle_and_unknown_index_is_a_clear_error() {
    let mut spec = small(1.37, 400.0);
    spec.incident_deg = vec![30.0];
    let (set, truth) = synth::capture(&spec);
    let err = estimate(&set, &Options::default()).unwrap_err().to_string();
    assert!(
        err.contains("single incident angle") && err.contains("--film-ior"),
        "{err}"
    );
    let fit = estimate(
        &set,
        &Options {
            film_ior: Some(Ior::real(1.37)),
            ..Options::default()
        },
    )
    .unwrap();
    let (mae, _, _) = synth::thickness_errors(&fit.thickness_nm, &truth);
    assert!(mae < 3.0, "mae {mae}");
    let bad = estimate(
        &set,
        &Options {
            film_ior: Some(Ior::real(0.3)),
            ..Options::default()
        },
    );
    assert!(bad.unwrap_err().to_string().contains("propagating"));
}

#[test]
fn flat_peakless_and_broken_spectra_give_finite_json() {
    // Bare substrate (d = 0, no fringes) and NaN/inf pixels.
    let mut spec = small(1.37, 0.0);
    spec.thickness_variation_nm = 0.0;
    let (mut set, _) = synth::capture(&spec);
    let nb = set.bands();
    set.angles[0].reflectance.as_bip_mut().unwrap()[3 * nb] = f32::NAN;
    set.angles[1].reflectance.as_bip_mut().unwrap()[5 * nb + 2] = f32::INFINITY;
    set.angles[2].valid[7] = false;
    for a in &mut set.angles {
        a.valid[11] = false;
    }
    for method in [Method::Full, Method::Paper] {
        let r = estimate(
            &set,
            &Options {
                method,
                ..Options::default()
            },
        );
        match r {
            Ok(fit) => {
                assert_eq!(fit.invalid_pixels, 1);
                assert!(fit.film_ior.is_finite());
                assert!(fit.thickness_nm[11].is_nan());
                let de: Result<f64, String> = Err("test".into());
                let v = report::fit_json(&set, &fit, &de, None, &[]);
                let text = serde_json::to_string(&v).unwrap();
                assert!(!text.contains("NaN") && v.film_ior.is_some(), "{text}");
            }
            Err(e) => {
                // The paper method has no peaks to work with: it must say so.
                assert_eq!(method, Method::Paper);
                assert!(e.to_string().contains("peaks"), "{e}");
            }
        }
    }
    // Completely flat spectra (no film signal at all, constant reflectance).
    for a in &mut set.angles {
        (a.reflectance.as_bip_mut().unwrap())
            .iter_mut()
            .for_each(|v| *v = 0.05);
        a.valid.iter_mut().for_each(|v| *v = true);
    }
    for method in [Method::Full, Method::Paper] {
        if let Ok(fit) = estimate(
            &set,
            &Options {
                method,
                ..Options::default()
            },
        ) {
            assert!(fit.film_ior.is_finite());
            let v = report::fit_json(&set, &fit, &Ok(0.0), None, &[]);
            assert!(!serde_json::to_string(&v).unwrap().contains("NaN"));
        }
    }
}

#[test]
fn unpolarised_metal_substrate_and_thick_film() {
    let mut spec = small(1.45, 1500.0);
    spec.polarization = Polarization::Unpolarized;
    spec.thickness_variation_nm = 60.0;
    let (set, truth) = synth::capture(&spec);
    let fit = estimate(&set, &Options::default()).unwrap();
    let (mae, _, _) = synth::thickness_errors(&fit.thickness_nm, &truth);
    assert!((fit.film_ior - 1.45).abs() < 0.01, "n {}", fit.film_ior);
    assert!(mae < 5.0, "mae {mae}");

    let mut spec = small(1.38, 300.0);
    spec.substrate_ior = Ior::Constant(thinfilm::optics::Complex64::new(0.18, 3.4));
    let (set, truth) = synth::capture(&spec);
    let fit = estimate(&set, &Options::default()).unwrap();
    let (mae, _, _) = synth::thickness_errors(&fit.thickness_nm, &truth);
    assert!(
        (fit.film_ior - 1.38).abs() < 0.01,
        "metal n {}",
        fit.film_ior
    );
    assert!(mae < 5.0, "metal mae {mae}");
}

/// A fit is the same to the last bit on any number of threads and in every run: its
/// parallel sums are added in a fixed order, not in the order work was split.
#[test]
fn fits_are_bit_identical_on_any_thread_count() {
    let mut spec = SynthSpec::seed_conditions(1.37, 450.0);
    (spec.width, spec.height) = (48, 32);
    spec.noise_sigma = 0.01;
    let (mut set, _) = synth::capture(&spec);
    // Relative amplitudes: the nuisance terms' joint refinement sums over pixels too.
    set.radiometry = thinfilm::capture::Radiometry::Relative;
    let fit_on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let fit = pool.install(|| estimate(&set, &Options::default()).unwrap());
        let bits: Vec<u32> = fit.thickness_nm.iter().map(|v| v.to_bits()).collect();
        (fit.film_ior.to_bits(), bits)
    };
    let one = fit_on(1);
    for threads in [2, 3, 4, 3] {
        assert!(fit_on(threads) == one, "{threads} threads differ from one");
    }
}
