//! Putting split work back together: renders of disjoint sample ranges into the render of
//! their union ([`merge_renders`]), thickness maps fitted row band by row band into the
//! whole map ([`stitch_tiles`]), and the bands' fit folders into one ([`merge_fit_dirs`]). Pieces are recognised and checked by the provenance in their
//! EXR headers ([`crate::render::provenance`], [`crate::estimate::tiles`]).
//!
//! Renders merge exactly: a box-filtered render of `n` samples is the sum of its samples in a
//! fixed tree ([`crate::render::passes`]) divided by `n`. When every piece is a node of that
//! tree and holds a power-of-two number of samples (its mean times its count is then its sum,
//! bit for bit), adding the pieces' sums in the tree's order and dividing by the total
//! reproduces the single render bit for bit. Other splits are merged as the sample-weighted
//! mean, which agrees with the single render up to float rounding (~1e-7 relative), and the
//! result says so; tent- and Gaussian-filtered renders carry their per-pixel filter weights
//! and merge as the weight-weighted mean, also up to rounding.

use crate::estimate::tiles::TileInfo;
use crate::image_io::{ExrFile, RgbImage};
use crate::material::{
    FilmMaterial, FitFile, MapStats, PixelCounts, FIT_JSON, THICKNESS_CHANNEL, THICKNESS_EXR,
};
use crate::render::passes::is_tree_node;
use crate::render::provenance::{RenderInfo, FILTER_WEIGHT_CHANNEL};
use crate::stats::Summary;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// One rendered piece, read from an EXR written by `thinfilm render`.
#[derive(Debug, Clone)]
pub struct RenderPiece {
    pub path: PathBuf,
    pub info: RenderInfo,
    pub image: RgbImage,
    /// Per-pixel filter weight sums (tent / Gaussian filters).
    pub filter_weights: Option<Vec<f32>>,
}

impl RenderPiece {
    pub fn from_exr(path: &Path, exr: ExrFile) -> Result<Self> {
        let what = path.display().to_string();
        let info = RenderInfo::from_attributes(&exr.attributes, &what)?;
        let plane = |c: &str| {
            exr.channel(c)
                .with_context(|| format!("{what}: no channel '{c}'"))
        };
        let (r, g, b) = (plane("R")?, plane("G")?, plane("B")?);
        let pixels = (0..exr.width * exr.height)
            .map(|i| [r[i], g[i], b[i]])
            .collect();
        let filter_weights = exr.channel(FILTER_WEIGHT_CHANNEL).map(<[f32]>::to_vec);
        if info.filter != "box" && filter_weights.is_none() {
            bail!(
                "{what}: a {} -filtered render without its '{FILTER_WEIGHT_CHANNEL}' channel cannot be merged",
                info.filter
            );
        }
        Ok(RenderPiece {
            path: path.to_path_buf(),
            info,
            image: RgbImage {
                width: exr.width,
                height: exr.height,
                pixels,
            },
            filter_weights,
        })
    }
}

/// The merged render.
#[derive(Debug, Clone)]
pub struct MergedRender {
    pub image: RgbImage,
    pub filter_weights: Option<Vec<f32>>,
    pub info: RenderInfo,
    /// True when the result is bit-identical to a single render of the merged range.
    pub exact: bool,
    /// Why the merge is or is not exact, for the log.
    pub note: String,
}

/// Merges renders of disjoint, contiguous sample ranges of the same image (same scene hash,
/// resolution and settings; see the module documentation for exactness).
pub fn merge_renders(mut pieces: Vec<RenderPiece>) -> Result<MergedRender> {
    if pieces.is_empty() {
        bail!("nothing to merge");
    }
    pieces.sort_by_key(|p| p.info.sample_range);
    if let Some(p) = pieces.iter().find(|p| p.info.adaptive) {
        bail!(
            "{} was rendered with adaptive sample counts (its pixels hold different numbers of \
             samples) and cannot be merged: render the pieces with --sample-range or --part, \
             or with --uniform-samples",
            p.path.display()
        );
    }
    let first = &pieces[0];
    for p in &pieces[1..] {
        if p.info.image_hash != first.info.image_hash {
            bail!(
                "{} and {} are renders of different images (image hash {:016x} vs {:016x}: \
                 the scene, a -D value, the resolution, seed, sampler, max_depth, Fresnel splits \
                 or the thinfilm version differ)",
                first.path.display(),
                p.path.display(),
                first.info.image_hash,
                p.info.image_hash
            );
        }
        if (p.image.width, p.image.height) != (first.image.width, first.image.height) {
            bail!(
                "{} is {}×{} but {} is {}×{}",
                p.path.display(),
                p.image.width,
                p.image.height,
                first.path.display(),
                first.image.width,
                first.image.height
            );
        }
    }
    for w in pieces.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let (ra, rb) = (a.info.sample_range, b.info.sample_range);
        if rb.0 < ra.1 {
            bail!(
                "sample ranges overlap: {} holds {}:{} and {} holds {}:{}",
                a.path.display(),
                ra.0,
                ra.1,
                b.path.display(),
                rb.0,
                rb.1
            );
        }
        if rb.0 > ra.1 {
            bail!(
                "samples {}:{} are missing between {} ({}:{}) and {} ({}:{}); render them with \
                 --sample-range {}:{} and merge again",
                ra.1,
                rb.0,
                a.path.display(),
                ra.0,
                ra.1,
                b.path.display(),
                rb.0,
                rb.1,
                ra.1,
                rb.0
            );
        }
    }
    let range = (
        pieces[0].info.sample_range.0,
        pieces[pieces.len() - 1].info.sample_range.1,
    );
    let px = first.image.pixels.len();
    let filtered = first.filter_weights.is_some();
    // Per-piece film accumulators [Σ w·rgb, Σ w] recovered from the stored means.
    let accum = |p: &RenderPiece| -> Vec<[f32; 4]> {
        let n = p.info.spp() as f32;
        (0..px)
            .map(|i| {
                let w = p.filter_weights.as_ref().map_or(n, |wt| wt[i]);
                let c = p.image.pixels[i];
                [c[0] * w, c[1] * w, c[2] * w, w]
            })
            .collect()
    };
    let tree_exact = !filtered
        && pieces
            .iter()
            .all(|p| is_tree_node(range, p.info.sample_range) && p.info.spp().is_power_of_two());
    let (acc, exact, note) = if pieces.len() == 1 {
        let p = &pieces[0];
        (accum(p), true, "a single piece: copied".to_string())
    } else if tree_exact {
        (
            tree_combine(range, &pieces, &accum),
            true,
            "every piece is a power-of-two node of the render's summation tree: bit-identical \
             to a single render of the merged range"
                .to_string(),
        )
    } else {
        let mut acc = vec![[0.0f32; 4]; px];
        for p in &pieces {
            for (d, s) in acc.iter_mut().zip(accum(p)) {
                for k in 0..4 {
                    d[k] += s[k];
                }
            }
        }
        let why = if filtered {
            format!(
                "{}-filtered renders merge by their filter weights, equal to a single render up \
                 to float rounding",
                first.info.filter
            )
        } else {
            "sample-weighted mean, equal to a single render up to float rounding (bit-identical \
             needs power-of-two ranges aligned like 0:16, 16:32, 32:64)"
                .to_string()
        };
        (acc, false, why)
    };
    let mut image = RgbImage::new(first.image.width, first.image.height);
    let total = (range.1 - range.0) as f32;
    for (dst, p) in image.pixels.iter_mut().zip(&acc) {
        // The film divides the box filter's sum by the sample count (as f32).
        let w = if filtered { p[3] } else { total };
        *dst = if w > 0.0 {
            [p[0] / w, p[1] / w, p[2] / w]
        } else {
            [0.0; 3]
        };
    }
    let mut info = first.info.clone();
    info.sample_range = range;
    info.requested_range = range;
    Ok(MergedRender {
        image,
        filter_weights: filtered.then(|| acc.iter().map(|p| p[3]).collect()),
        info,
        exact,
        note,
    })
}

/// Sum of the pieces' accumulators over `[lo, hi)` in the film's tree order. Every piece is
/// a node of the tree of `[lo, hi)` (checked by the caller).
fn tree_combine(
    (lo, hi): (u32, u32),
    pieces: &[RenderPiece],
    accum: &dyn Fn(&RenderPiece) -> Vec<[f32; 4]>,
) -> Vec<[f32; 4]> {
    if let Some(p) = pieces.iter().find(|p| p.info.sample_range == (lo, hi)) {
        return accum(p);
    }
    let n = hi - lo;
    let half = if n.is_power_of_two() {
        n / 2
    } else {
        1 << (u32::BITS - 1 - n.leading_zeros())
    };
    let mid = lo + half;
    let mut a = tree_combine((lo, mid), pieces, accum);
    let b = tree_combine((mid, hi), pieces, accum);
    for (d, s) in a.iter_mut().zip(b) {
        for k in 0..4 {
            d[k] += s[k];
        }
    }
    a
}

/// One fitted row band, read from a tile EXR written by `thinfilm estimate --rows`.
#[derive(Debug, Clone)]
pub struct TilePiece {
    pub path: PathBuf,
    pub info: TileInfo,
    pub exr: ExrFile,
}

/// Stitched tiles: every channel of the tiles over the whole image.
#[derive(Debug, Clone)]
pub struct Stitched {
    pub width: usize,
    pub height: usize,
    pub channels: Vec<(String, Vec<f32>)>,
    pub info: TileInfo,
}

/// Stitches row tiles of one fit (same fit hash, width and height, the same channels) that
/// cover every row exactly once.
pub fn stitch_tiles(mut tiles: Vec<TilePiece>) -> Result<Stitched> {
    if tiles.is_empty() {
        bail!("nothing to merge");
    }
    tiles.sort_by_key(|t| t.info.rows);
    let first = &tiles[0];
    let names: Vec<&str> = first.exr.channels.iter().map(|(n, _)| n.as_str()).collect();
    let (width, height) = (first.exr.width, first.info.image_height);
    for t in &tiles {
        if t.info.fit_hash != first.info.fit_hash {
            bail!(
                "{} and {} are tiles of different fits (fit hash {:016x} vs {:016x}: the capture, \
                 --film-ior or another fit option differ)",
                first.path.display(),
                t.path.display(),
                first.info.fit_hash,
                t.info.fit_hash
            );
        }
        let t_names: Vec<&str> = t.exr.channels.iter().map(|(n, _)| n.as_str()).collect();
        if t_names != names {
            bail!(
                "{} has channels {} but {} has {}",
                t.path.display(),
                t_names.join(", "),
                first.path.display(),
                names.join(", ")
            );
        }
        let (a, b) = t.info.rows;
        if t.exr.width != width || t.exr.height != b - a || t.info.image_height != height {
            bail!(
                "{}: a {}×{} tile of rows {a}:{b} of a {}-row image does not fit a {width}×{height} image",
                t.path.display(),
                t.exr.width,
                t.exr.height,
                t.info.image_height
            );
        }
    }
    let mut next = 0;
    for t in &tiles {
        let (a, b) = t.info.rows;
        if a < next {
            bail!("{}: rows {a}:{b} overlap another tile", t.path.display());
        }
        if a > next {
            bail!("rows {next}:{a} are missing: no tile covers them");
        }
        next = b;
    }
    if next < height {
        bail!("rows {next}:{height} are missing: no tile covers them");
    }
    let channels = names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let mut plane = Vec::with_capacity(width * height);
            for t in &tiles {
                plane.extend_from_slice(&t.exr.channels[c].1);
            }
            (name.to_string(), plane)
        })
        .collect();
    let mut info = first.info.clone();
    info.rows = (0, height);
    Ok(Stitched {
        width,
        height,
        channels,
        info,
    })
}

/// What [`merge_fit_dirs`] wrote.
#[derive(Debug, Clone)]
pub struct MergedFit {
    pub fit: FitFile,
    pub bands: usize,
}

/// Stitches the output folders of `thinfilm estimate --rows` (or `--part`) runs of one fit
/// into a complete fit folder `out`: `thickness.exr` (stitched, with its provenance),
/// `thickness.png`, `material.xml`, `material.gltf` and a `fit.json` whose numbers cover the
/// whole map — thickness and σ statistics recomputed from the stitched maps (and
/// `thickness_sigma.exr` written), pixel and not-identifiable counts and stage times summed,
/// residual RMSE, χ²/dof and ΔE pooled over the bands by their fitted pixels. The bands'
/// `residual.png` maps are not stitched.
pub fn merge_fit_dirs(dirs: &[PathBuf], out: &Path) -> Result<MergedFit> {
    let mut tiles = Vec::with_capacity(dirs.len());
    let mut fits = Vec::with_capacity(dirs.len());
    // Each band's σ map, by its first row (stitched when every band has one).
    let mut sigmas: Vec<(usize, Option<Vec<f32>>)> = Vec::with_capacity(dirs.len());
    for dir in dirs {
        let fit = FitFile::read(&dir.join(FIT_JSON))?;
        let path = dir.join(THICKNESS_EXR);
        let exr = crate::image_io::read_exr(&path)?;
        let info = TileInfo::from_attributes(&exr.attributes, &path.display().to_string())?;
        let sigma = fit
            .thickness_sigma_file
            .as_ref()
            .map(|f| crate::image_io::read_exr(&dir.join(f)))
            .transpose()?
            .and_then(|e| e.channel(SIGMA_CHANNEL).map(<[f32]>::to_vec));
        sigmas.push((info.rows.0, sigma));
        tiles.push(TilePiece { path, info, exr });
        fits.push(fit);
    }
    let stitched = stitch_tiles(tiles)?;
    sigmas.sort_by_key(|s| s.0);
    let sigma: Option<Vec<f32>> = sigmas
        .into_iter()
        .map(|s| s.1)
        .collect::<Option<Vec<_>>>()
        .map(|s| s.concat())
        .filter(|s| s.len() == stitched.width * stitched.height);
    let (_, thickness) = stitched
        .channels
        .iter()
        .find(|(n, _)| n == THICKNESS_CHANNEL)
        .with_context(|| {
            format!("the bands' thickness maps have no channel '{THICKNESS_CHANNEL}'")
        })?;
    let first = &fits[0];
    let material = FilmMaterial {
        film_ior: first.film_index()?,
        substrate_ior: first.substrate.clone(),
        width: stitched.width,
        height: stitched.height,
        thickness_nm: thickness.clone(),
    };
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    material.write_files_with_provenance(
        out,
        &format!(
            "thinfilm estimate ({}), {} row bands merged",
            first.method,
            fits.len()
        ),
        &stitched.info.attributes(),
    )?;
    crate::estimate::report::write_colormap_png(
        &out.join("thickness.png"),
        thickness,
        stitched.width,
        stitched.height,
        "thickness (nm)",
    )?;
    let mut fit = pooled_fit_file(&fits, thickness, stitched.width, stitched.height);
    fit.thickness_sigma_nm = None;
    fit.thickness_sigma_file = None;
    if let Some(sigma) = &sigma {
        let name = fits[0]
            .thickness_sigma_file
            .clone()
            .unwrap_or_else(|| "thickness_sigma.exr".into());
        crate::image_io::write_exr_channels(
            &out.join(&name),
            stitched.width,
            stitched.height,
            &[(SIGMA_CHANNEL, sigma)],
        )
        .with_context(|| format!("writing {name}"))?;
        fit.thickness_sigma_nm = Some(MapStats::from(Summary::of_finite(sigma)));
        fit.thickness_sigma_file = Some(name);
    }
    fit.write(&out.join(FIT_JSON))?;
    Ok(MergedFit {
        fit,
        bands: fits.len(),
    })
}

/// The channel of a fit's σ map (`thickness_sigma.exr`).
const SIGMA_CHANNEL: &str = "thickness_sigma";

/// One `fit.json` for bands of one fit (see [`merge_fit_dirs`]).
fn pooled_fit_file(fits: &[FitFile], thickness: &[f32], width: usize, height: usize) -> FitFile {
    let weight = |f: &FitFile| f.pixels.valid as f64;
    let total: f64 = fits.iter().map(weight).sum();
    // Mean of a per-band value weighted by fitted pixels; RMSEs are pooled as mean squares.
    let pool = |value: fn(&FitFile) -> Option<f64>, squared: bool| -> Option<f64> {
        let mut acc = 0.0;
        for f in fits {
            let v = value(f)?;
            acc += weight(f) * if squared { v * v } else { v };
        }
        (total > 0.0).then(|| {
            if squared {
                (acc / total).sqrt()
            } else {
                acc / total
            }
        })
    };
    let mut fit = fits[0].clone();
    fit.width = width;
    fit.height = height;
    fit.rows = None;
    fit.thickness_nm = MapStats::from(Summary::of_finite(thickness));
    fit.thickness_nm_reason = fit
        .thickness_nm
        .mean
        .is_none()
        .then(|| "no pixel was fitted".into());
    // Per band: χ²/dof, identifiability (the checks run on the band's pixels).
    fit.chi2_per_dof = pool(|f| f.chi2_per_dof, false);
    fit.not_identifiable_pixels = fits.iter().map(|f| f.not_identifiable_pixels).sum();
    fit.pixels = PixelCounts {
        valid: fits.iter().map(|f| f.pixels.valid).sum(),
        invalid: fits.iter().map(|f| f.pixels.invalid).sum(),
        unfitted: fits.iter().map(|f| f.pixels.unfitted).sum(),
    };
    // `invalid_samples` counts the whole capture's masked samples in every band's fit.json.
    for f in &fits[1..] {
        for (stage, s) in &f.seconds {
            let e = fit.seconds.entry(stage.clone()).or_insert(Some(0.0));
            *e = e.zip(*s).map(|(a, b)| a + b);
        }
        for w in &f.warnings {
            if !fit.warnings.contains(w) {
                fit.warnings.push(w.clone());
            }
        }
    }
    fit.residual_rmse = pool(|f| f.residual_rmse, true);
    fit.delta_e_ab_d65_mean = pool(|f| f.delta_e_ab_d65_mean, false);
    fit.ground_truth = None;
    fit.film_ior_note = format!("{} ({} row bands merged)", fit.film_ior_note, fits.len());
    fit
}
