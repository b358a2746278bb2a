//! `thinfilm merge PIECES… -o OUT`: renders of disjoint sample ranges into one render,
//! thickness maps of row bands into one map, or the bands' fit folders into one fit folder
//! (see `thinfilm::merge`). What each piece is comes from its EXR header.

use super::Output;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use thinfilm::estimate::tiles::TileInfo;
use thinfilm::image_io::{
    exr_memory, read_exr, write_exr_channels_with_attributes, write_png_tonemapped,
};
use thinfilm::merge::{merge_fit_dirs, merge_renders, stitch_tiles, RenderPiece, TilePiece};
use thinfilm::render::provenance::{self, KIND};

#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  # one render split four ways (on four machines, or one after another), then merged:
  thinfilm render scene.xml --spp 64 --sample-range 0:16  -o a.exr
  thinfilm render scene.xml --spp 64 --sample-range 16:32 -o b.exr
  thinfilm render scene.xml --spp 64 --sample-range 32:64 -o c.exr
  thinfilm merge a.exr b.exr c.exr -o scene.exr          # = the 0:64 render, bit for bit
  # a capture fitted in row bands with a known index, then stitched:
  thinfilm estimate cap --film-ior 1.37 --rows 0:48  --out band0
  thinfilm estimate cap --film-ior 1.37 --rows 48:96 --out band1
  thinfilm merge band0/thickness.exr band1/thickness.exr -o thickness.exr
  thinfilm merge band0 band1 -o fit        # whole fit folder: fit.json, thickness.exr, material.*")]
pub struct Args {
    /// EXRs written by `thinfilm render` (disjoint, contiguous `--sample-range`s of one image),
    /// thickness maps written by `thinfilm estimate --rows` (row bands covering a capture), or
    /// those estimates' output folders.
    #[arg(required = true, num_args = 1..)]
    pub pieces: Vec<PathBuf>,
    /// The merged EXR (for renders, a tone-mapped PNG is written beside it), or for fit
    /// folders the output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Exposure multiplier for the PNG of a merged render.
    #[arg(long, allow_hyphen_values = true, default_value_t = 1.0, value_parser = super::args::non_negative_f32)]
    pub exposure: f32,
}

pub fn run(args: Args, report: Output) -> Result<()> {
    let dirs = args.pieces.iter().filter(|p| p.is_dir()).count();
    if dirs == args.pieces.len() {
        return merge_folders(&args, report);
    }
    if dirs > 0 {
        bail!("give either EXR files or estimate output folders to merge, not both");
    }
    if args.output.extension().and_then(|e| e.to_str()) != Some("exr") {
        bail!("output {} must end in .exr", args.output.display());
    }
    // Every piece is held at once (plus the merged image): check their sum before reading.
    let mut bytes = 0u64;
    for p in &args.pieces {
        if p == &args.output {
            bail!("the output {} is also an input", p.display());
        }
        bytes = bytes.saturating_add(exr_memory(p)?);
    }
    thinfilm::limits::check_alloc(
        format!("merging {} pieces", args.pieces.len()),
        bytes.saturating_add(bytes / args.pieces.len() as u64),
    )?;
    let mut files = Vec::with_capacity(args.pieces.len());
    for p in &args.pieces {
        files.push(read_exr(p)?);
    }
    let kind = files[0].attributes.get(KIND).cloned().with_context(|| {
        format!(
            "{}: no '{KIND}' attribute: not a render or thickness map written by thinfilm",
            args.pieces[0].display()
        )
    })?;
    match kind.as_str() {
        "render" => {
            let pieces = args
                .pieces
                .iter()
                .zip(files)
                .map(|(p, f)| RenderPiece::from_exr(p, f))
                .collect::<Result<Vec<_>>>()?;
            let count = pieces.len();
            let m = merge_renders(pieces)?;
            let img = &m.image;
            provenance::write_exr(&args.output, img, m.filter_weights.as_deref(), &m.info)?;
            let png = args.output.with_extension("png");
            write_png_tonemapped(&png, img, args.exposure)?;
            let (a, b) = m.info.sample_range;
            report.text(format_args!(
                "merged {count} renders: samples {a}:{b} ({} spp), {}×{}",
                b - a,
                img.width,
                img.height
            ));
            report.text(format_args!(
                "{}: {}",
                if m.exact { "exact" } else { "not bit-exact" },
                m.note
            ));
            report.text(format_args!(
                "wrote {} and {}",
                args.output.display(),
                png.display()
            ));
            report.json(&serde_json::json!({
                "kind": "render",
                "output": args.output,
                "png": png,
                "pieces": count,
                "sample_range": [a, b],
                "spp": b - a,
                "width": img.width,
                "height": img.height,
                "exact": m.exact,
                "note": m.note,
            }))
        }
        "fit" => {
            let tiles = args
                .pieces
                .iter()
                .zip(files)
                .map(|(p, exr)| {
                    let info =
                        TileInfo::from_attributes(&exr.attributes, &p.display().to_string())?;
                    Ok(TilePiece {
                        path: p.clone(),
                        info,
                        exr,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let count = tiles.len();
            let s = stitch_tiles(tiles)?;
            let channels: Vec<(&str, &[f32])> = s
                .channels
                .iter()
                .map(|(n, p)| (n.as_str(), p.as_slice()))
                .collect();
            write_exr_channels_with_attributes(
                &args.output,
                s.width,
                s.height,
                &channels,
                &s.info.attributes(),
            )?;
            report.text(format_args!(
                "stitched {count} row bands into {}×{} (film index {}), wrote {}",
                s.width,
                s.height,
                s.info.film_ior,
                args.output.display()
            ));
            report.json(&serde_json::json!({
                "kind": "fit",
                "output": args.output,
                "pieces": count,
                "width": s.width,
                "height": s.height,
                "film_ior": s.info.film_ior,
            }))
        }
        other => bail!(
            "{}: '{KIND}' is '{other}': thinfilm merges renders and fitted thickness maps",
            args.pieces[0].display()
        ),
    }
}

fn merge_folders(args: &Args, report: Output) -> Result<()> {
    if args.pieces.contains(&args.output) {
        bail!(
            "the output folder {} is also an input",
            args.output.display()
        );
    }
    let m = merge_fit_dirs(&args.pieces, &args.output)?;
    report.text(format_args!(
        "merged {} row bands into {}×{} (film index {}, {} fitted pixels), wrote {}",
        m.bands,
        m.fit.width,
        m.fit.height,
        m.fit.film_ior.map_or("n/a".into(), |n| format!("{n:.4}")),
        m.fit.pixels.valid,
        args.output.display()
    ));
    let mut v = serde_json::to_value(&m.fit)?;
    v["output"] = serde_json::json!(args.output);
    report.json(&v)
}
