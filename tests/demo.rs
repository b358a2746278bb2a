//! The demo pipeline at a small size: every output is written and the `full` fits meet the
//! estimator's acceptance bounds (|n error| ≤ 0.005, thickness MAE ≤ 3 nm).

use thinfilm::demo::{run, DemoConfig};
use thinfilm::estimate::Method;
use thinfilm::figure::RenderSettings;

#[test]
fn demo_fits_meet_the_acceptance_bounds_and_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = DemoConfig {
        out: dir.path().to_path_buf(),
        width: 40,
        height: 30,
        noise_sigma: 0.004,
        seed: 7,
        render: RenderSettings {
            resolution: 40,
            spp: 2,
            seed: 0,
            max_depth: 4,
            progress: false,
        },
        progress: false,
    };
    let summary = run(&cfg).unwrap();
    assert_eq!(summary.samples.len(), 3);
    for (label, _, _, _, results) in &summary.samples {
        let full = results
            .iter()
            .find(|r| r.method == Method::Full)
            .expect("full method ran");
        assert!(
            full.film_ior_abs_error <= 0.005,
            "{label}: |n error| {}",
            full.film_ior_abs_error
        );
        assert!(
            full.thickness_mae_nm <= 3.0,
            "{label}: thickness MAE {} nm",
            full.thickness_mae_nm
        );
        assert!(
            full.delta_e_ab.is_some_and(f64::is_finite),
            "{label}: ΔE missing"
        );
        for name in [
            "fit.json",
            "thickness.exr",
            "thickness.png",
            "material.xml",
            "material.gltf",
        ] {
            assert!(
                full.fit_dir.join(name).is_file(),
                "{label}: {name} not written"
            );
        }
        let json = std::fs::read_to_string(full.fit_dir.join("fit.json")).unwrap();
        assert!(
            !json.contains("NaN") && !json.contains("nan"),
            "{label}: NaN in fit.json"
        );
    }
    for f in &summary.figures {
        let img = image::open(f).unwrap().to_rgb8();
        assert!(
            img.width() > 100 && img.height() > 40,
            "{} is too small",
            f.display()
        );
    }
    // The methods figures: on sample 3 (ZnS on PET, reflectance maxima at half orders) the
    // published method's fit renders visibly wrong, ours does not.
    assert_eq!(summary.method_figures.len(), 1);
    let (label, png, sample3) = &summary.method_figures[0];
    assert!(label.starts_with("Sample 3"), "{label}");
    assert!(png.is_file(), "{} not written", png.display());
    assert!(
        sample3[0] > 1.0 && sample3[1] < 0.5 * sample3[0],
        "sample 3: mean ΔE00 published {:.3}, ours {:.3}",
        sample3[0],
        sample3[1]
    );
    // Output names a shell takes without quoting.
    let mut stack = vec![dir.path().to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            assert!(
                !name.contains([' ', '(', ')']),
                "output name needs quoting: {}",
                p.display()
            );
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    assert!(dir.path().join("index.html").is_file() && dir.path().join("README.md").is_file());
    let md = std::fs::read_to_string(dir.path().join("README.md")).unwrap();
    assert!(md.contains("paper (published)") && md.contains("ours: full"));
}
