//! Every shipped scene file loads and renders (tiny image, few samples) without NaN/inf, with
//! the expected effects switched on; and the `render` CLI writes EXR + PNG.

use std::path::Path;
use thinfilm::render::{render, RenderOptions};

fn scenes() -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "xml"))
        .collect();
    v.sort();
    v
}

#[test]
fn all_scene_files_render_finite() {
    let list = scenes();
    assert!(
        list.len() >= 7,
        "expected the issue's scene set, found {list:?}"
    );
    for path in list {
        let defaults = [
            ("spp".to_string(), "2".to_string()),
            ("res".to_string(), "24".to_string()),
        ];
        let scene = thinfilm::scene::load(&path, &defaults)
            .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        let out = render(
            &scene,
            &RenderOptions {
                resolution: Some((24, 24)),
                spp: Some(2),
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        for p in &out.image.pixels {
            // Spectral → sRGB may leave the gamut (slightly negative components): only finiteness.
            assert!(p.iter().all(|v| v.is_finite()), "{}: {p:?}", path.display());
        }
        assert_eq!(out.stats.invalid_samples, 0, "{}", path.display());
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let film = name.contains("mgf2")
            || name.contains("zns")
            || name.contains("thinfilm")
            || name.contains("thickness")
            // soap bubble, multilayer coatings, AR-coated lens.
            || ["bubble", "coatings", "lens"].iter().any(|k| name.contains(k));
        assert_eq!(
            out.effects.interference, film,
            "{name}: {:?}",
            out.effects.reasons
        );
        assert_eq!(out.stats.film_evals > 0, film, "{name}");
    }
}

#[test]
fn cli_writes_exr_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.exr");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot_mgf2_400.xml");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--spp",
            "1",
            "--resolution",
            "16x12",
            "--threads",
            "2",
            "-D",
            "max_depth=3",
        ])
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let stdout = String::from_utf8_lossy(&status.stdout);
    assert!(stdout.contains("Mrays/s"), "{stdout}");
    let img = thinfilm::image_io::read_exr_rgb(&out).unwrap();
    assert_eq!((img.width, img.height), (16, 12));
    assert!(dir.path().join("t.png").is_file());
    // Bad input: a clear error and a non-zero exit, nothing written.
    let bad = dir.path().join("bad.exr");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args([
            "render",
            scene.to_str().unwrap(),
            "-o",
            bad.to_str().unwrap(),
            "--sample-range",
            "8:4",
        ])
        .output()
        .unwrap();
    assert!(!status.status.success());
    assert!(String::from_utf8_lossy(&status.stderr).contains("START must be < END"));
    assert!(!bad.exists());
}
