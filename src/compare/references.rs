//! The committed Mitsuba 3 reference set: `tests/references/manifest.json`, written by
//! `tools/mitsuba/render_references.py`.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// One reference render and the scene file it was rendered from.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    pub name: String,
    /// Scene file (absolute: joined onto the repository root).
    pub scene: PathBuf,
    /// Reference EXR (absolute).
    pub exr: PathBuf,
    pub width: usize,
    pub height: usize,
    pub spp: u64,
    /// Mitsuba variant the reference was rendered with, when recorded (the polarised scenes
    /// need `*_polarized`); None = the default `llvm_ad_spectral`.
    pub variant: Option<String>,
    /// Seed Mitsuba rendered the reference with (its passes use seeds derived from it), when
    /// recorded.
    pub seed: Option<u64>,
}

/// Reads the manifest at `root/tests/references/manifest.json` (paths inside are relative to
/// `root`), sorted by name.
pub fn load_manifest(root: &Path) -> Result<Vec<Reference>> {
    let path = root.join("tests/references/manifest.json");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "reading {} (run tools/mitsuba/render_references.py)",
            path.display()
        )
    })?;
    let doc: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let refs = doc["references"]
        .as_object()
        .with_context(|| format!("{}: no \"references\" object", path.display()))?;
    let mut out = Vec::new();
    for (name, r) in refs {
        let field = |k: &str| {
            r[k].as_str()
                .with_context(|| format!("{}: references.{name}.{k} missing", path.display()))
        };
        let num = |k: &str| {
            r[k].as_u64()
                .with_context(|| format!("{}: references.{name}.{k} missing", path.display()))
        };
        out.push(Reference {
            name: name.clone(),
            scene: root.join(field("scene")?),
            exr: root.join(field("exr")?),
            width: num("width")? as usize,
            height: num("height")? as usize,
            spp: num("spp")?,
            variant: r["variant"].as_str().map(str::to_string),
            seed: r["seed"].as_u64(),
        });
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn committed_manifest_lists_existing_files() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let refs = load_manifest(root).unwrap();
        assert!(!refs.is_empty());
        for r in &refs {
            assert!(r.scene.is_file(), "{}: {}", r.name, r.scene.display());
            assert!(r.exr.is_file(), "{}: {}", r.name, r.exr.display());
            assert!(r.spp >= 4096, "{}: {} spp", r.name, r.spp);
        }
    }

    #[test]
    fn missing_manifest_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let e = load_manifest(dir.path()).unwrap_err();
        assert!(format!("{e:#}").contains("manifest.json"));
    }
}
