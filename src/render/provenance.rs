//! What a rendered EXR holds, written into its header so that renders split by sample range
//! (on several machines, or resumed after Ctrl-C) can be merged exactly by `thinfilm merge`,
//! and refused when they do not belong to the same image.
//!
//! Text attributes (any EXR header tool shows them):
//!
//! | attribute | value |
//! |---|---|
//! | `thinfilm.kind` | `render` |
//! | `thinfilm.sampleRange` | global sample indices `A:B` this image averages |
//! | `thinfilm.spp` | `B − A`, samples per pixel in this image |
//! | `thinfilm.requestedRange` | the range the run was asked for (larger when interrupted) |
//! | `thinfilm.seed` | sampler seed |
//! | `thinfilm.sampler` | `independent` or `sobol` |
//! | `thinfilm.filter` | reconstruction filter (`box`, `tent`, `gaussian`) |
//! | `thinfilm.sampleCounts` | `uniform`, or `adaptive` when pixels hold different numbers of samples ([`super::adaptive`]; not mergeable) |
//! | `thinfilm.imageHash` | 64-bit hash (hex) of the loaded scene and of every setting that changes a sample's value |
//! | `thinfilm.version` | thinfilm version |
//!
//! The hash covers the scene as loaded (geometry, materials, textures, lights, camera, film,
//! `-D` values as they were substituted) and the resolved resolution, seed, sampler,
//! `max_depth` and Fresnel splits, plus the thinfilm version. It leaves out what does not
//! change a sample: the sample count, the thread count, the PNG exposure and the scene file's
//! own path (texture and mesh paths are part of the scene, so render every piece from the same
//! scene location).

use super::PreparedScene;
use crate::image_io::Attributes;
use crate::scene::Scene;
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Attribute names.
pub const KIND: &str = "thinfilm.kind";
const SAMPLE_RANGE: &str = "thinfilm.sampleRange";
const SPP: &str = "thinfilm.spp";
const REQUESTED_RANGE: &str = "thinfilm.requestedRange";
const SEED: &str = "thinfilm.seed";
const SAMPLER: &str = "thinfilm.sampler";
const FILTER: &str = "thinfilm.filter";
const SAMPLE_COUNTS: &str = "thinfilm.sampleCounts";
const IMAGE_HASH: &str = "thinfilm.imageHash";
pub const VERSION: &str = "thinfilm.version";
/// Channel holding the per-pixel sum of filter weights (tent / Gaussian filters only).
pub const FILTER_WEIGHT_CHANNEL: &str = "filter_weight";

/// The provenance of one rendered image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RenderInfo {
    pub sample_range: (u32, u32),
    pub requested_range: (u32, u32),
    pub seed: u64,
    pub sampler: String,
    pub filter: String,
    /// Pixels hold different numbers of samples ([`super::adaptive`]).
    pub adaptive: bool,
    /// See the module documentation.
    pub image_hash: u64,
    pub version: String,
}

impl RenderInfo {
    /// Provenance of a render of `scene` prepared as `prepared` that covered `sample_range`.
    pub fn new(scene: &Scene, prepared: &PreparedScene, sample_range: (u32, u32)) -> Self {
        RenderInfo {
            sample_range,
            requested_range: prepared.sample_range,
            seed: prepared.seed,
            sampler: prepared.sampler.name().to_string(),
            filter: prepared.filter.name().to_string(),
            adaptive: false,
            image_hash: image_hash(scene, prepared),
            version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }

    /// Samples per pixel in the image.
    pub fn spp(&self) -> u32 {
        self.sample_range.1 - self.sample_range.0
    }

    pub fn attributes(&self) -> Attributes {
        let range = |(a, b): (u32, u32)| format!("{a}:{b}");
        vec![
            (KIND.into(), "render".into()),
            (SAMPLE_RANGE.into(), range(self.sample_range)),
            (SPP.into(), self.spp().to_string()),
            (REQUESTED_RANGE.into(), range(self.requested_range)),
            (SEED.into(), self.seed.to_string()),
            (SAMPLER.into(), self.sampler.clone()),
            (FILTER.into(), self.filter.clone()),
            (
                SAMPLE_COUNTS.into(),
                if self.adaptive { "adaptive" } else { "uniform" }.into(),
            ),
            (IMAGE_HASH.into(), format!("{:016x}", self.image_hash)),
            (VERSION.into(), self.version.clone()),
        ]
    }

    /// Reads the attributes back; `what` names the file in errors.
    pub fn from_attributes(attrs: &BTreeMap<String, String>, what: &str) -> Result<Self> {
        let get = |key: &str| -> Result<&str> {
            attrs.get(key).map(String::as_str).with_context(|| {
                format!("{what}: no '{key}' attribute in the EXR header (not an image written by thinfilm render)")
            })
        };
        if get(KIND)? != "render" {
            bail!("{what}: '{KIND}' is '{}', not 'render'", get(KIND)?);
        }
        let range = |key: &str| -> Result<(u32, u32)> {
            let v = get(key)?;
            parse_range(v).with_context(|| format!("{what}: attribute '{key}' = '{v}'"))
        };
        let info = RenderInfo {
            sample_range: range(SAMPLE_RANGE)?,
            requested_range: range(REQUESTED_RANGE)?,
            seed: get(SEED)?
                .parse()
                .with_context(|| format!("{what}: attribute '{SEED}'"))?,
            sampler: get(SAMPLER)?.to_string(),
            filter: get(FILTER)?.to_string(),
            // Absent in files from before adaptive sample counts: uniform.
            adaptive: match attrs.get(SAMPLE_COUNTS).map(String::as_str) {
                None | Some("uniform") => false,
                Some("adaptive") => true,
                Some(v) => bail!("{what}: '{SAMPLE_COUNTS}' is '{v}', not 'uniform' or 'adaptive'"),
            },
            image_hash: u64::from_str_radix(get(IMAGE_HASH)?, 16)
                .with_context(|| format!("{what}: attribute '{IMAGE_HASH}' is not hex"))?,
            version: get(VERSION)?.to_string(),
        };
        let spp: u32 = get(SPP)?
            .parse()
            .with_context(|| format!("{what}: attribute '{SPP}'"))?;
        if spp != info.spp() {
            bail!(
                "{what}: '{SPP}' = {spp} disagrees with '{SAMPLE_RANGE}' = {}:{}",
                info.sample_range.0,
                info.sample_range.1
            );
        }
        Ok(info)
    }
}

/// Writes a render (or merged render) as float32 `R`, `G`, `B` (plus [`FILTER_WEIGHT_CHANNEL`]
/// for tent and Gaussian filters) with `info` in the header.
pub fn write_exr(
    path: &std::path::Path,
    image: &crate::image_io::RgbImage,
    filter_weights: Option<&[f32]>,
    info: &RenderInfo,
) -> Result<()> {
    let planes: [Vec<f32>; 3] =
        std::array::from_fn(|c| image.pixels.iter().map(|p| p[c]).collect());
    let mut channels: Vec<(&str, &[f32])> =
        vec![("R", &planes[0]), ("G", &planes[1]), ("B", &planes[2])];
    if let Some(w) = filter_weights {
        channels.push((FILTER_WEIGHT_CHANNEL, w));
    }
    crate::image_io::write_exr_channels_rle(
        path,
        image.width,
        image.height,
        &channels,
        &info.attributes(),
    )
}

/// `A:B` with A < B.
pub fn parse_range(s: &str) -> Result<(u32, u32)> {
    let (a, b) = s
        .split_once(':')
        .with_context(|| format!("'{s}' is not START:END"))?;
    let a: u32 = a
        .trim()
        .parse()
        .with_context(|| format!("bad START in '{s}'"))?;
    let b: u32 = b
        .trim()
        .parse()
        .with_context(|| format!("bad END in '{s}'"))?;
    if a >= b {
        bail!("range '{s}' is empty: START must be < END");
    }
    Ok((a, b))
}

/// 64-bit FNV-1a over text written into it (a fingerprint to tell renders of different
/// images apart, not a cryptographic hash).
pub(crate) struct Fnv(pub u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl std::fmt::Write for Fnv {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        for &b in s.as_bytes() {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
        Ok(())
    }
}

/// See the module documentation. The scene's `Debug` form lists every field (floats in
/// shortest round-trip form), so any change to what is drawn changes the hash.
fn image_hash(scene: &Scene, p: &PreparedScene) -> u64 {
    let Scene {
        camera,
        film,
        integrator: _, // resolved below (max_depth may be overridden)
        spp: _,
        seed: _,
        sampler: _,
        shapes,
        bsdfs,
        emitters,
        polarizer,
        source: _,
        media,
    } = scene;
    let mut h = Fnv::default();
    let _ = write!(
        h,
        "{camera:?}{film:?}{shapes:?}{bsdfs:?}{emitters:?}{polarizer:?}|{:?}|{}x{}|{}|{}|{}|{}",
        p.settings,
        p.width,
        p.height,
        p.seed,
        p.sampler.name(),
        p.fresnel_splits,
        env!("CARGO_PKG_VERSION"),
    );
    // Media only where there are some: the hashes of surface-only scenes stay as they were.
    if let Some(m) = media {
        let _ = write!(h, "|{m:?}");
    }
    h.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attributes_round_trip_and_are_checked() {
        let info = RenderInfo {
            sample_range: (32, 64),
            requested_range: (0, 64),
            seed: u64::MAX,
            sampler: "sobol".into(),
            filter: "box".into(),
            adaptive: true,
            image_hash: 0x0123_4567_89ab_cdef,
            version: "9.9.9".into(),
        };
        let map: BTreeMap<String, String> = info.attributes().into_iter().collect();
        assert_eq!(RenderInfo::from_attributes(&map, "x.exr").unwrap(), info);
        let mut bad = map.clone();
        bad.insert(SPP.into(), "31".into());
        let e = RenderInfo::from_attributes(&bad, "x.exr").unwrap_err();
        assert!(format!("{e:#}").contains("thinfilm.spp"), "{e:#}");
        let mut older = map.clone();
        older.remove(SAMPLE_COUNTS);
        assert!(
            !RenderInfo::from_attributes(&older, "x.exr")
                .unwrap()
                .adaptive
        );
        let mut odd = map.clone();
        odd.insert(SAMPLE_COUNTS.into(), "some".into());
        let e = RenderInfo::from_attributes(&odd, "x.exr").unwrap_err();
        assert!(format!("{e:#}").contains("sampleCounts"), "{e:#}");
        let mut missing = map;
        missing.remove(IMAGE_HASH);
        let e = RenderInfo::from_attributes(&missing, "x.exr").unwrap_err();
        assert!(format!("{e:#}").contains("x.exr"), "{e:#}");
    }
}
