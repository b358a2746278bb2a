//! `material.xml`: a [`FilmMaterial`] as a Mitsuba-style `thinfilm` BSDF whose thickness is
//! a `bitmap` texture (the fit's `thickness.exr`), and back through the scene parser.
//!
//! Constant indices are written as floats (`film_ior`; `substrate_ior` and `substrate_k`), so
//! that Mitsuba's Python `thinfilm` plugin (`tools/mitsuba/thinfilm_mitsuba.py`) reads the
//! file too; a dispersive index is written as a string in the index syntax
//! (`cauchy:A,B[,C]`, `sellmeier:…` or a material name), which thinfilm's parser reads.

use super::FilmMaterial;
use crate::optics::Ior;
use anyhow::{Context, Result};
use std::fmt::Write;
use std::path::Path;

/// Text safe inside an XML attribute value.
fn attr(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `<float>` for a real constant index, else `<string>` (complex constants: `n+ki`).
fn index_element(name: &str, ior: &Ior) -> String {
    match ior {
        Ior::Constant(c) if c.im == 0.0 => format!("<float name=\"{name}\" value=\"{}\"/>", c.re),
        other => format!(
            "<string name=\"{name}\" value=\"{}\"/>",
            attr(&other.to_string())
        ),
    }
}

/// The `<bsdf type="thinfilm">` element of `material`, its thickness read from
/// `thickness_file` (relative to the XML file); the comment starts with `note`.
pub fn write(material: &FilmMaterial, thickness_file: &str, note: &str) -> String {
    let mean = material.mean_thickness_nm();
    let mean = if mean.is_finite() {
        format!("{mean:.2} nm")
    } else {
        "n/a".into()
    };
    let mut xml = format!(
        "<!-- {}: film index {} and per-pixel thickness (nm, {thickness_file}) on substrate {}. \
         Mean thickness {mean}. -->\n<bsdf type=\"thinfilm\" id=\"fitted_film\">\n",
        note.replace("--", "-"),
        material.film_ior,
        material.substrate_ior,
    );
    let line = |xml: &mut String, s: &str| {
        let _ = writeln!(xml, "    {s}");
    };
    line(&mut xml, &index_element("film_ior", &material.film_ior));
    line(&mut xml, "<texture type=\"bitmap\" name=\"thickness\">");
    line(
        &mut xml,
        &format!(
            "    <string name=\"filename\" value=\"{}\"/>",
            attr(thickness_file)
        ),
    );
    line(&mut xml, "    <boolean name=\"raw\" value=\"true\"/>");
    line(
        &mut xml,
        "    <string name=\"filter_type\" value=\"bilinear\"/>",
    );
    line(&mut xml, "</texture>");
    match &material.substrate_ior {
        // Mitsuba's plugin takes n and k as two floats.
        Ior::Constant(c) => {
            line(
                &mut xml,
                &format!("<float name=\"substrate_ior\" value=\"{}\"/>", c.re),
            );
            line(
                &mut xml,
                &format!("<float name=\"substrate_k\" value=\"{}\"/>", c.im),
            );
        }
        other => line(&mut xml, &index_element("substrate_ior", other)),
    }
    xml.push_str("</bsdf>\n");
    xml
}

/// Reads a `material.xml` (a `<bsdf type="thinfilm">` element; its thickness texture is
/// found relative to the file) through the Mitsuba scene parser.
pub fn read(path: &Path) -> Result<FilmMaterial> {
    let text = crate::limits::read_text(path, "material file", 16)?;
    // The element alone is not a scene: parse it as the BSDF of a shape.
    let body = text.trim_start();
    let body = body
        .strip_prefix("<?xml")
        .and_then(|rest| rest.split_once("?>"))
        .map_or(body, |(_, rest)| rest);
    let scene =
        format!("<scene version=\"3.0.0\"><shape type=\"rectangle\">{body}</shape></scene>");
    let dir = path.parent().unwrap_or(Path::new("."));
    let file = path.display().to_string();
    let scene = crate::scene::mitsuba::load_str(&scene, dir, &[], &file)?;
    let bsdf = scene
        .shapes
        .first()
        .and_then(|s| scene.bsdfs.get(s.bsdf))
        .with_context(|| format!("{file}: no BSDF"))?;
    FilmMaterial::from_bsdf(bsdf).with_context(|| file.clone())
}

#[cfg(test)]
mod tests {
    use super::super::tests::example;
    use super::*;

    #[test]
    fn round_trips_constant_and_dispersive_indices() {
        for (film, substrate) in [
            ("1.38", "1.52"),
            ("1.37", "0.18+3.4i"),
            ("cauchy:1.36,3400", "PET"),
            (
                "MgF2",
                "sellmeier:1.03961212,0.00600069867,0.231792344,0.0200179144",
            ),
        ] {
            let dir = tempfile::tempdir().unwrap();
            let m = example(film, substrate);
            m.write_files(dir.path(), "round trip").unwrap();
            let path = dir.path().join(super::super::MATERIAL_XML);
            let back = read(&path).unwrap_or_else(|e| panic!("{film}/{substrate}: {e:#}"));
            assert_eq!(back, m, "{film} on {substrate}");
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.contains("thickness.exr"), "{text}");
            if film == "1.38" {
                // What Mitsuba's plugin reads: floats only.
                assert!(!text.contains("<string name=\"film_ior\""), "{text}");
                assert!(text.contains("<float name=\"substrate_k\" value=\"0\"/>"));
            }
        }
    }

    #[test]
    fn the_committed_reference_material_reads() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/references/material/material.xml");
        let m = read(&path).unwrap();
        assert_eq!(m.film_ior, Ior::real(1.38));
        assert_eq!(m.substrate_ior, Ior::real(1.52));
        assert!(m.width > 1 && m.thickness_nm.iter().all(|v| v.is_finite()));
    }
}
