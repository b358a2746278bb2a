//! Mitsuba's `bumpmap` BSDF: a flat height leaves the nested model's image unchanged, a
//! linear height ramp tilts a diffuse plane's normal by the expected angle (radiance under a
//! directional light ∝ cos of the tilted normal to the light), bad input is refused with a
//! message, and a small scene matches Mitsuba 3 (`tests/references/bumpmap/`, made by
//! `tools/mitsuba/render_bumpmap_reference.py`).

use std::path::Path;
use thinfilm::image_io::{write_exr_rgb, RgbImage};
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::mitsuba::load_str;

/// A W×1 height bitmap h = `slope`·x (texel index x), clamped at the edges.
fn write_ramp(dir: &Path, name: &str, w: usize, slope: f32) {
    let pixels = (0..w).map(|x| [slope * x as f32; 3]).collect();
    let img = RgbImage {
        width: w,
        height: 1,
        pixels,
    };
    write_exr_rgb(&dir.join(name), &img).unwrap();
}

/// A diffuse rectangle ([−1,1]², z = 0, so ∂p/∂u = (2, 0, 0)) seen from above through a
/// narrow perspective (the uv centre, away from the clamped edges), lit by a directional
/// light travelling along (0.5, 0, −1); `bsdf` wraps the diffuse BSDF (`{}`).
fn plane_scene(bsdf: &str) -> String {
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>"#;
    format!(
        r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="20"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="rectangle">{}</shape>
  <emitter type="directional">
    <vector name="direction" x="0.5" y="0" z="-1"/>
    <rgb name="irradiance" value="1, 1, 1"/>
  </emitter>
</scene>"#,
        bsdf.replace("{}", diffuse)
    )
}

fn render_mean(dir: &Path, xml: &str) -> (Vec<[f32; 3]>, f64) {
    let scene = load_str(xml, dir, &[], "bump.xml").expect("scene loads");
    let out = render(
        &scene,
        &RenderOptions {
            seed: Some(3),
            ..Default::default()
        },
    )
    .expect("render");
    let px = out.image.pixels;
    let mean = px.iter().map(|p| p[1] as f64).sum::<f64>() / px.len() as f64;
    (px, mean)
}

/// Zero scale, or a constant height, gives the nested diffuse BSDF's image (the same random
/// numbers; the frames differ only in their tangent, which a diffuse lobe ignores).
#[test]
fn flat_height_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    write_ramp(dir.path(), "ramp.exr", 8, 0.075);
    write_ramp(dir.path(), "flat.exr", 8, 0.0);
    let (plain, m) = render_mean(dir.path(), &plane_scene("{}"));
    assert!(m > 0.01, "{m}");
    for wrapper in [
        r#"<bsdf type="bumpmap"><texture type="bitmap" name="arbitrary"><string name="filename" value="ramp.exr"/></texture><float name="scale" value="0"/>{}</bsdf>"#,
        r#"<bsdf type="bumpmap"><texture type="bitmap" name="h"><string name="filename" value="flat.exr"/></texture>{}</bsdf>"#,
    ] {
        let (bumped, _) = render_mean(dir.path(), &plane_scene(wrapper));
        for (a, b) in plain.iter().zip(&bumped) {
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= 1e-5 * (1.0 + a[c].abs()),
                    "{a:?} vs {b:?}"
                );
            }
        }
    }
}

/// Height h = ±0.075·x over 8 texels: ∂h/∂u = ±0.6·scale, so with |∂p/∂u| = 2 the normal
/// tilts to n' ∝ (∓0.3·scale, 0, 1). Radiance ∝ max(0, n'·l), l the direction to the light;
/// the bumped/flat mean ratio must match within 2 % for both slopes (towards and away from
/// the light). (The parser's domain for `scale` is ≥ 0, so a descending ramp stands in for
/// Mitsuba's negative scale.)
#[test]
fn ramp_tilts_the_normal() {
    let dir = tempfile::tempdir().unwrap();
    write_ramp(dir.path(), "up.exr", 8, 0.075);
    write_ramp(dir.path(), "down.exr", 8, -0.075);
    let (_, flat) = render_mean(dir.path(), &plane_scene("{}"));
    let l = glam::Vec3::new(-0.5, 0.0, 1.0).normalize();
    for (file, slope, scale) in [
        ("up", 1.0f32, 1.0f32),
        ("down", -1.0, 1.0),
        ("up", 1.0, 2.5),
    ] {
        let wrapper = format!(
            r#"<bsdf type="bumpmap"><texture type="bitmap" name="arbitrary"><string name="filename" value="{file}.exr"/></texture><float name="scale" value="{scale}"/>{{}}</bsdf>"#
        );
        let (_, bumped) = render_mean(dir.path(), &plane_scene(&wrapper));
        let n = glam::Vec3::new(-0.3 * slope * scale, 0.0, 1.0).normalize();
        let want = (n.dot(l) / l.z) as f64;
        let got = bumped / flat;
        println!("{file} × {scale}: ratio {got:.4}, cos model {want:.4}");
        assert!(
            (got / want - 1.0).abs() < 0.02,
            "{file} × {scale}: {got} vs {want}"
        );
    }
}

#[test]
fn bad_bumpmaps_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_ramp(dir.path(), "ramp.exr", 8, 0.075);
    let tex =
        r#"<texture type="bitmap" name="h"><string name="filename" value="ramp.exr"/></texture>"#;
    let cases = [
        ("{}".to_string(), "exactly one nested height"),
        (
            format!("{tex}{}{{}}", tex.replace("\"h\"", "\"h2\"")),
            "exactly one nested height",
        ),
        (tex.to_string(), "exactly one nested BSDF"),
        (
            r#"<texture type="checkerboard" name="h"/>{}"#.to_string(),
            "must be a bitmap",
        ),
    ];
    for (inner, want) in cases {
        let xml = plane_scene(&format!(r#"<bsdf type="bumpmap">{inner}</bsdf>"#));
        let e = format!(
            "{:#}",
            load_str(&xml, dir.path(), &[], "bad.xml").unwrap_err()
        );
        assert!(e.contains(want) && e.contains("bad.xml"), "{inner}: {e}");
    }
}

/// tests/references/bumpmap/NAME.xml (a diffuse plane, and a sphere, with a bumpy height in
/// u and v under a directional light) against Mitsuba 3's render: mean within 2 % per
/// channel and every bright 8×8 block within 6 %. The plane and `sphere_defaults` keep
/// Mitsuba 3.9's defaults (`flip_invalid_normals`, `use_shadowing_function` on); `sphere`
/// sets both `false` (the classic frame-only form).
#[test]
fn matches_mitsuba() {
    compare("bumpmap");
    compare("sphere");
    compare("sphere_defaults");
}

fn compare(name: &str) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/references/bumpmap");
    let scene = thinfilm::scene::load(&dir.join(format!("{name}.xml")), &[]).expect("loads");
    let reference = thinfilm::image_io::read_exr_rgb(&dir.join(format!("{name}.exr"))).unwrap();
    let out = render(
        &scene,
        &RenderOptions {
            seed: Some(7),
            ..Default::default()
        },
    )
    .expect("render");
    let (w, h) = (out.image.width, out.image.height);
    assert_eq!((w, h), (reference.width, reference.height));
    let (got, want) = (&out.image.pixels, &reference.pixels);
    for c in 0..3 {
        let mean = |px: &[[f32; 3]]| px.iter().map(|p| p[c] as f64).sum::<f64>();
        let r = mean(got) / mean(want);
        println!("{name}: channel {c}: mean ratio {r:.4}");
        assert!(
            (r - 1.0).abs() <= 0.02,
            "{name}: channel {c}: mean ratio {r:.4}"
        );
    }
    let total: f64 = want.iter().flat_map(|p| p.iter().map(|v| *v as f64)).sum();
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            let block = |px: &[[f32; 3]]| {
                let mut s = 0.0f64;
                for y in by * 8..by * 8 + 8 {
                    for x in bx * 8..bx * 8 + 8 {
                        s += px[y * w + x].iter().map(|v| *v as f64).sum::<f64>();
                    }
                }
                s
            };
            // Blocks on the sphere's silhouette are partly background: bright ones only.
            if block(want) > 0.5 * total / ((w / 8) * (h / 8)) as f64 {
                let r = block(got) / block(want);
                assert!(
                    (r - 1.0).abs() <= 0.06,
                    "{name} block ({bx}, {by}): ratio {r:.4}"
                );
            }
        }
    }
}

/// Mitsuba 3.8+'s `flip_invalid_normals` and `use_shadowing_function` default to true: a
/// scene leaving them unset renders as one setting both true, with no warning; setting
/// `use_shadowing_function` false brightens a tilted plane (Estevez et al.'s term is < 1).
#[test]
fn mitsuba_38_flags_default_on() {
    let dir = tempfile::tempdir().unwrap();
    write_ramp(dir.path(), "ramp.exr", 8, 0.075);
    let with = |flags: &str| {
        format!(
            r#"<bsdf type="bumpmap"><texture type="bitmap" name="h"><string name="filename" value="ramp.exr"/></texture><float name="scale" value="2.5"/>{flags}{{}}</bsdf>"#
        )
    };
    let on = r#"<boolean name="flip_invalid_normals" value="true"/>
        <boolean name="use_shadowing_function" value="true"/>"#;
    let (unset, m_unset) = render_mean(dir.path(), &plane_scene(&with("")));
    let (set, _) = render_mean(dir.path(), &plane_scene(&with(on)));
    assert_eq!(unset, set);
    let no_shadow = r#"<boolean name="use_shadowing_function" value="false"/>"#;
    let (_, m_off) = render_mean(dir.path(), &plane_scene(&with(no_shadow)));
    assert!(m_off > m_unset * 1.001, "{m_off} vs {m_unset}");
    let path = dir.path().join("defaults.xml");
    std::fs::write(&path, plane_scene(&with(""))).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_thinfilm"))
        .args(["render", path.to_str().unwrap(), "-o"])
        .arg(dir.path().join("out.exr"))
        .args(["--spp", "1", "--resolution", "4x4"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && !err.contains("flip_invalid_normals"),
        "{err}"
    );
}
