//! EXR and PNG reading and writing shared by every stage. Writes go to a temporary file
//! beside the target and are renamed into place, so a failed run leaves nothing half-written.

use anyhow::{bail, Context, Result};
use exr::prelude::*;
use std::path::{Path, PathBuf};

/// A linear RGB float image, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<[f32; 3]>,
}

impl RgbImage {
    pub fn new(width: usize, height: usize) -> Self {
        RgbImage {
            width,
            height,
            pixels: vec![[0.0; 3]; width * height],
        }
    }
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        self.pixels[y * self.width + x]
    }
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.partial-{}", std::process::id()))
}

/// Runs `write` against a temporary path, then renames it onto `path`.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating directory {}", dir.display()))?;
    }
    let tmp = temp_path(path);
    let result = write(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path)
            .with_context(|| format!("moving output into place at {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("writing {}", path.display()))
}

/// Writes float32 channels named `R`, `G`, `B` (ZIP compressed).
pub fn write_exr_rgb(path: &Path, image: &RgbImage) -> Result<()> {
    let planes: [Vec<f32>; 3] =
        std::array::from_fn(|c| image.pixels.iter().map(|p| p[c]).collect());
    write_exr_channels(
        path,
        image.width,
        image.height,
        &[("R", &planes[0]), ("G", &planes[1]), ("B", &planes[2])],
    )
}

/// Writes any number of float32 channels (row-major planes of `width * height`).
pub fn write_exr_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[(&str, &[f32])],
) -> Result<()> {
    write_exr_channels_with_attributes(path, width, height, channels, &[])
}

/// Header attributes of an EXR: `(name, text value)` pairs (OpenEXR `string` attributes, shown
/// by any EXR header tool); thinfilm writes a render's or a fit's provenance in them.
pub type Attributes = Vec<(String, String)>;

/// [`write_exr_channels`] plus text attributes in the header.
pub fn write_exr_channels_with_attributes(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[(&str, &[f32])],
    attributes: &[(String, String)],
) -> Result<()> {
    for (name, plane) in channels {
        if plane.len() != width * height {
            bail!(
                "channel {name} has {} samples, expected {}×{}",
                plane.len(),
                width,
                height
            );
        }
    }
    write_atomically(path, |tmp| {
        let list: Vec<AnyChannel<FlatSamples>> = channels
            .iter()
            .map(|(name, plane)| AnyChannel::new(*name, FlatSamples::F32(plane.to_vec())))
            .collect();
        let mut attrs = LayerAttributes::named("");
        attrs.layer_name = None;
        for (name, value) in attributes {
            let (Some(n), Some(v)) = (Text::new_or_none(name), Text::new_or_none(value)) else {
                bail!("EXR attribute {name:?} = {value:?} is not Latin-1 text");
            };
            attrs.other.insert(n, AttributeValue::Text(v));
        }
        let layer = Layer::new(
            (width, height),
            attrs,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(list.into()),
        );
        Image::from_layer(layer)
            .write()
            .to_file(tmp)
            .map_err(|e| anyhow::anyhow!("{e}"))
    })
}

/// A named channel plane: `(name, row-major samples)`.
pub type NamedPlane = (String, Vec<f32>);

/// Reads every channel of the first layer as f32 planes: `(width, height, [(name, plane)])`.
pub fn read_exr_channels(path: &Path) -> Result<(usize, usize, Vec<NamedPlane>)> {
    let e = read_exr(path)?;
    Ok((e.width, e.height, e.channels))
}

/// An EXR's first layer: its float planes and its text header attributes.
#[derive(Debug, Clone)]
pub struct ExrFile {
    pub width: usize,
    pub height: usize,
    pub channels: Vec<NamedPlane>,
    /// Text attributes of the header, by name (other attribute types are left out).
    pub attributes: std::collections::BTreeMap<String, String>,
}

impl ExrFile {
    /// The plane of channel `name`, if there is one.
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p.as_slice())
    }
}

/// Reads the first layer of an EXR with its text attributes.
pub fn read_exr(path: &Path) -> Result<ExrFile> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("reading EXR {}", path.display()))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    let attributes = image
        .attributes
        .other
        .iter()
        .chain(&layer.attributes.other)
        .filter_map(|(k, v)| match v {
            AttributeValue::Text(t) => Some((k.to_string(), t.to_string())),
            _ => None,
        })
        .collect();
    Ok(ExrFile {
        width: w,
        height: h,
        channels,
        attributes,
    })
}

/// Reads one named channel (e.g. `thickness`).
pub fn read_exr_channel(path: &Path, name: &str) -> Result<(usize, usize, Vec<f32>)> {
    let (w, h, channels) = read_exr_channels(path)?;
    let names: Vec<String> = channels.iter().map(|(n, _)| n.clone()).collect();
    let plane = channels
        .into_iter()
        .find(|(n, _)| n == name)
        .map(|(_, p)| p)
        .with_context(|| {
            format!(
                "{}: no channel named '{name}' (channels: {})",
                path.display(),
                names.join(", ")
            )
        })?;
    Ok((w, h, plane))
}

/// Reads a one-quantity image: the first of the channels `names` present, or the only
/// channel of a single-channel file.
pub fn read_exr_scalar(path: &Path, names: &[&str]) -> Result<(usize, usize, Vec<f32>)> {
    let (w, h, channels) = read_exr_channels(path)?;
    let listed: Vec<String> = channels.iter().map(|(n, _)| n.clone()).collect();
    let single = channels.len() == 1;
    let plane = channels
        .into_iter()
        .enumerate()
        .filter(|(_, (n, _))| single || names.contains(&n.as_str()))
        .min_by_key(|(_, (n, _))| names.iter().position(|m| m == n).unwrap_or(usize::MAX))
        .map(|(_, (_, p))| p)
        .with_context(|| {
            format!(
                "{}: no channel named {} (channels: {})",
                path.display(),
                names.join(" or "),
                listed.join(", ")
            )
        })?;
    Ok((w, h, plane))
}

/// Reads an RGB EXR (channels R, G, B; a single Y channel is read as grey).
pub fn read_exr_rgb(path: &Path) -> Result<RgbImage> {
    let (w, h, channels) = read_exr_channels(path)?;
    let find = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, p)| p);
    let (r, g, b) = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => (r, g, b),
        (_, _, _, Some(y)) => (y, y, y),
        _ => bail!("{}: expected channels R, G, B (or Y)", path.display()),
    };
    let pixels = (0..w * h).map(|i| [r[i], g[i], b[i]]).collect();
    Ok(RgbImage {
        width: w,
        height: h,
        pixels,
    })
}

/// Writes 8-bit RGB PNG from already-encoded bytes (`width * height * 3`).
pub fn write_png_rgb8(path: &Path, width: usize, height: usize, bytes: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(width as u32, height as u32, bytes)
        .context("PNG buffer size does not match width × height × 3")?;
    write_atomically(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(Into::into)
    })
}

/// Tone-maps linear sRGB to an 8-bit sRGB PNG: exposure scale, clamp, sRGB transfer curve.
/// NaN/inf show as magenta so they cannot hide.
pub fn write_png_tonemapped(path: &Path, image: &RgbImage, exposure: f32) -> Result<()> {
    let mut bytes = Vec::with_capacity(image.pixels.len() * 3);
    for p in &image.pixels {
        if p.iter().any(|v| !v.is_finite()) {
            bytes.extend_from_slice(&[255, 0, 255]);
            continue;
        }
        for &v in p {
            let e = crate::spectrum::srgb_encode((v * exposure).clamp(0.0, 1.0) as f64);
            bytes.push((e * 255.0 + 0.5).clamp(0.0, 255.0) as u8);
        }
    }
    write_png_rgb8(path, image.width, image.height, bytes)
}
