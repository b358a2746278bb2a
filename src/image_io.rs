//! EXR and PNG reading and writing shared by every stage. Writes go to a temporary file
//! beside the target and are renamed into place, so a failed run leaves nothing half-written.

use anyhow::{bail, Context, Result};
use exr::prelude::*;
use std::path::{Path, PathBuf};

/// A linear RGB float image, row-major, top row first.
#[derive(Clone, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<[f32; 3]>,
}

/// Size and a hash of every bit of the pixels, not the pixels: a render's provenance hashes
/// the scene's `Debug` form, and a 512 × 256 environment printed in full was 393 216 floats
/// to format (~30 ms, a fifth of a small preview's run). Any change to a pixel changes the
/// hash (FNV-1a over the 32-bit words).
impl std::fmt::Debug for RgbImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let hash = (self.pixels.iter().flatten()).fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ v.to_bits() as u64).wrapping_mul(0x0000_0100_0000_01b3)
        });
        f.debug_struct("RgbImage")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("pixels", &self.pixels.len())
            .field("content_hash", &format!("{hash:016x}"))
            .finish()
    }
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

/// Marks temporaries: `.NAME.partial-PID` files and `.thinfilm-staging.partial-PID` folders.
const PARTIAL: &str = ".partial-";

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}{PARTIAL}{}", std::process::id()))
}

/// True unless `pid` is known to have exited (only Linux's /proc can tell; elsewhere every
/// temporary is assumed to belong to a live process and is left alone).
fn process_alive(pid: u32) -> bool {
    !Path::new("/proc/self").exists() || Path::new(&format!("/proc/{pid}")).exists()
}

/// Removes the temporaries a killed run left in `dir` (a temporary of a running process,
/// this one included, stays).
fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let pid = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(PARTIAL))
            .and_then(|(_, pid)| pid.parse::<u32>().ok());
        let Some(pid) = pid else { continue };
        if pid == std::process::id() || process_alive(pid) {
            continue;
        }
        let path = entry.path();
        let _ = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
    }
}

/// Flushes a written file to the storage device, so that a rename never publishes a file
/// whose data a crash of the machine could still lose.
fn sync_file(path: &Path) -> Result<()> {
    std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .and_then(|f| f.sync_all())
        .with_context(|| format!("flushing {}", path.display()))
}

/// Runs `write` against a temporary path beside `path`, flushes it, then renames it onto
/// `path`: readers (and a run that is killed or fails) see either the previous file or the
/// complete new one, never a partial one. Temporaries left by killed runs are removed.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating directory {}", dir.display()))?;
    }
    remove_stale_temporaries(dir.unwrap_or(Path::new(".")));
    let tmp = temp_path(path);
    let result = write(&tmp).and_then(|()| sync_file(&tmp)).and_then(|()| {
        std::fs::rename(&tmp, path)
            .with_context(|| format!("moving output into place at {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("writing {}", path.display()))
}

/// Writes a set of files into `dir` as one step: `write` creates them in a fresh staging
/// folder inside `dir`, and only when all succeeded is each renamed over its namesake in
/// `dir` (JSON files last: they name the others). Other files in `dir` are left alone; on an
/// error, or if the process is killed before the renames, `dir` keeps its previous files.
pub fn write_files_atomically(dir: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("creating output folder {}", dir.display()))?;
    remove_stale_temporaries(dir);
    let stage = dir.join(format!(".thinfilm-staging{PARTIAL}{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&stage);
    std::fs::create_dir(&stage)
        .with_context(|| format!("creating staging folder {}", stage.display()))?;
    let result = write(&stage).and_then(|()| {
        let mut names: Vec<std::ffi::OsString> = std::fs::read_dir(&stage)
            .with_context(|| format!("listing {}", stage.display()))?
            .flatten()
            .filter(|e| e.path().is_file())
            .map(|e| e.file_name())
            .collect();
        names.sort_by_key(|n| {
            (
                Path::new(n).extension().is_some_and(|e| e == "json"),
                n.clone(),
            )
        });
        for n in names {
            std::fs::rename(stage.join(&n), dir.join(&n)).with_context(|| {
                format!("moving output into place at {}", dir.join(&n).display())
            })?;
        }
        Ok(())
    });
    let _ = std::fs::remove_dir_all(&stage);
    result
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
    write_exr_encoded(
        path,
        (width, height),
        channels,
        attributes,
        Encoding::SMALL_LOSSLESS,
    )
}

/// [`write_exr_channels_with_attributes`] with run-length instead of ZIP compression, for
/// path-traced renders: their float noise barely deflates (a 256² teapot: 770 kB instead of
/// 786 kB raw) but ZIP took ~35 ms of CPU per 256² image, a tenth of a small render's
/// process; run-length still shrinks flat (e.g. black) regions.
pub fn write_exr_channels_rle(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[(&str, &[f32])],
    attributes: &[(String, String)],
) -> Result<()> {
    let rle = Encoding {
        compression: Compression::RLE,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    write_exr_encoded(path, (width, height), channels, attributes, rle)
}

fn write_exr_encoded(
    path: &Path,
    (width, height): (usize, usize),
    channels: &[(&str, &[f32])],
    attributes: &[(String, String)],
    encoding: Encoding,
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
            encoding,
            AnyChannels::sort(list.into()),
        );
        let image = Image::from_layer(layer);
        let writer = image.write();
        // Run-length blocks cost less than handing them to a thread pool (whose idle
        // workers spin while the file is written); deflate blocks are worth spreading.
        let writer = if encoding.compression == Compression::RLE {
            writer.non_parallel()
        } else {
            writer
        };
        writer.to_file(tmp).map_err(|e| anyhow::anyhow!("{e}"))
    })
}

/// A named channel plane: `(name, row-major samples)`.
pub type NamedPlane = (String, Vec<f32>);

/// Decoded EXR bytes can exceed the file by the compression ratio; deflate (ZIP, PXR24)
/// reaches at most 1032:1, run-length 64:1, PIZ and DWA stay well below 2048:1. A header
/// declaring more than this many decoded bytes per file byte is corrupt.
const MAX_EXR_EXPANSION: u64 = 2048;

/// Checks an EXR header's declared pixels against the file size and the memory budget
/// before the decoder allocates them (a flipped byte in a header can declare gigapixels), and
/// returns the bytes reading the file takes.
pub fn exr_memory(path: &Path) -> Result<u64> {
    crate::limits::contain_panics(path, || exr_memory_checked(path))
}

fn exr_memory_checked(path: &Path) -> Result<u64> {
    if !path.is_file() {
        bail!("EXR file {} does not exist", path.display());
    }
    let file_bytes = std::fs::metadata(path)
        .with_context(|| format!("reading EXR {}", path.display()))?
        .len();
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| anyhow::anyhow!("{}: not a readable EXR header: {e}", path.display()))?;
    let mut total = 0u64;
    for (i, h) in meta.headers.iter().enumerate() {
        let (w, ht) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
        let sample_bytes: u64 = h
            .channels
            .list
            .iter()
            .map(|c| c.sample_type.bytes_per_sample() as u64)
            .sum();
        let raw = crate::limits::size_product(
            format!("{} layer {i}", path.display()),
            &[
                ("width", w),
                ("height", ht),
                ("bytes per pixel", sample_bytes),
            ],
        )?;
        let ratio = if h.compression == exr::compression::Compression::Uncompressed {
            1
        } else {
            MAX_EXR_EXPANSION
        };
        if raw > file_bytes.saturating_mul(ratio) {
            bail!(
                "{}: the header declares {w}×{ht} pixels ({raw} bytes of samples) but the file has {file_bytes} bytes: corrupt or truncated",
                path.display()
            );
        }
        // Decoded samples, their f32 copies and an RGB image made from them.
        let channels = h.channels.list.len() as u64;
        let bytes = raw.saturating_add((w * ht).saturating_mul(4 * channels + 12));
        crate::limits::check_alloc(
            format!("{}: {w}×{ht} pixels × {channels} channels", path.display()),
            bytes,
        )?;
        total = total.saturating_add(bytes);
    }
    Ok(total)
}

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
    crate::limits::contain_panics(path, || read_exr_checked(path))
}

fn read_exr_checked(path: &Path) -> Result<ExrFile> {
    exr_memory_checked(path)?;
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
    let channels: Vec<NamedPlane> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    if let Some((name, plane)) = channels.iter().find(|(_, p)| p.len() != w * h) {
        bail!(
            "{}: channel '{name}' has {} samples for {w}×{h} pixels (subsampled channels are not supported)",
            path.display(),
            plane.len()
        );
    }
    if channels.is_empty() {
        bail!("{}: the image has no channels", path.display());
    }
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

/// Decodes an image file (PNG, Radiance HDR, JPEG …) after checking the size its header
/// declares against the memory budget; `bytes_per_pixel` is what the caller keeps per pixel
/// after converting the result.
pub fn read_image(path: &Path, bytes_per_pixel: u64) -> Result<image::DynamicImage> {
    let open = || {
        image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .with_context(|| format!("reading image {}", path.display()))
    };
    crate::limits::contain_panics(path, || {
        decode_checked(open, &path.display().to_string(), bytes_per_pixel)
    })
}

/// [`read_image`] for an image held in memory (e.g. inside a glTF buffer); `what` names it.
pub fn decode_image_bytes(
    bytes: &[u8],
    what: &str,
    bytes_per_pixel: u64,
) -> Result<image::DynamicImage> {
    let open = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .with_context(|| format!("reading image {what}"))
    };
    decode_checked(open, what, bytes_per_pixel)
}

fn decode_checked<R: std::io::BufRead + std::io::Seek>(
    open: impl Fn() -> Result<image::ImageReader<R>>,
    what: &str,
    bytes_per_pixel: u64,
) -> Result<image::DynamicImage> {
    let (w, h) = open()?
        .into_dimensions()
        .with_context(|| format!("{what}: not a readable image"))?;
    let pixels = w as u64 * h as u64;
    crate::limits::check_alloc(
        format!("{what}: {w}×{h} pixels"),
        pixels.saturating_mul(bytes_per_pixel.max(16)),
    )?;
    let mut reader = open()?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(crate::limits::memory_limit());
    reader.limits(limits);
    reader
        .decode()
        .with_context(|| format!("{what}: cannot decode the image"))
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

/// DejaVu Sans, compiled in (once) so figures and plots never depend on system fonts.
pub static FONT_BYTES: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/assets/fonts/DejaVuSans.ttf"
));

/// Registers [`FONT_BYTES`] as plotters' "sans-serif" face (once per process).
pub fn register_plot_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Cannot fail for the bundled font; if it did, text drawing would report it.
        let _ = plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            FONT_BYTES,
        );
    });
}

/// Matplotlib's viridis at `t` in [0, 1] (clamped) as sRGB8: linear between the colour map
/// sampled at t = 0, 1/8, …, 1 (matplotlib `_viridis_data`).
pub fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let s = t.clamp(0.0, 1.0) * 8.0;
    let i = (s.floor() as usize).min(7);
    let f = s - i as f64;
    std::array::from_fn(|c| (STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f + 0.5) as u8)
}

#[cfg(test)]
mod tests {
    use super::RgbImage;

    /// The provenance hash sees every bit of every pixel through `Debug`, without the floats.
    #[test]
    fn debug_form_changes_with_any_pixel_bit() {
        let mut img = RgbImage::new(3, 2);
        img.pixels[4] = [0.25, 0.5, 1.0];
        let before = format!("{img:?}");
        assert!(!before.contains("0.25"), "{before}");
        let mut changed = img.clone();
        changed.pixels[4][1] = f32::from_bits(0.5f32.to_bits() + 1);
        assert_ne!(format!("{changed:?}"), before);
        let mut moved = img.clone();
        moved.pixels.swap(4, 5);
        assert_ne!(format!("{moved:?}"), before);
        assert_eq!(format!("{:?}", img.clone()), before);
    }
}
