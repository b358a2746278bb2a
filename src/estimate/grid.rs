//! The exhaustive baseline the seed compares against (its §4, O(m n²)): for every index
//! on a grid, every pixel's best thickness on a thickness grid; the index minimises the
//! total residual. Calibrated reflectance, point-sampled model unless band integration is
//! asked for.

use super::data::PixelData;
use super::film::FilmIndex;
use super::model::FilmModel;
use super::stage::{
    Context, FilmSolution, IndexEstimate, IndexStage, ThicknessMap, ThicknessStage,
};
use anyhow::{bail, Result};
use rayon::prelude::*;

/// Index by exhaustive search.
pub struct GridIndex;
/// Thickness by exhaustive search.
pub struct GridThickness;

/// Best thickness on the grid: (d, SSE).
fn best_d(cx: &Context, m: &FilmModel, y: &[f32], mask: &[bool]) -> (f64, f64) {
    let o = cx.opts;
    let steps =
        ((o.max_thickness_nm - o.min_thickness_nm) / o.grid_thickness_step_nm).floor() as usize + 1;
    (0..steps)
        .map(|i| {
            let d = o.min_thickness_nm + i as f64 * o.grid_thickness_step_nm;
            (d, m.sse(d, y, cx.obs.stride, mask, 1))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((f64::NAN, f64::INFINITY))
}

impl IndexStage for GridIndex {
    fn run(&self, cx: &Context) -> Result<IndexEstimate> {
        let obs = &cx.obs;
        let o = cx.opts;
        let stride = o.grid_pixel_stride.max(1);
        let (w, h) = (obs.width, obs.height);
        let sub: Vec<usize> = (0..h)
            .step_by(stride)
            .flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x))
            .filter(|&p| obs.usable_angles(p) >= 2)
            .collect();
        if sub.is_empty() {
            bail!("grid: no pixel valid at two angles");
        }
        let data: Vec<PixelData> = sub
            .iter()
            .map(|&p| {
                let mut px = PixelData::new(obs);
                px.used = obs.get(p, &mut px.y, &mut px.mask);
                px
            })
            .collect();
        let lo = o.min_film_ior.max(obs.geom.min_film_ior());
        let n_steps = ((o.max_film_ior - lo) / o.grid_ior_step).floor().max(0.0) as usize + 1;
        let pb = cx.progress_bar(n_steps, "grid n");
        let mut best = (f64::NAN, f64::INFINITY);
        for i in 0..n_steps {
            let n = lo + i as f64 * o.grid_ior_step;
            let m = obs.geom.model(n);
            // Added in pixel order: the same total in every run and on any thread count.
            let per_pixel: Vec<f64> = data
                .par_iter()
                .map(|px| best_d(cx, &m, &px.y, &px.mask).1)
                .collect();
            let total: f64 = per_pixel.iter().sum();
            if total < best.1 {
                best = (n, total);
            }
            pb.inc(1);
        }
        pb.finish_and_clear();
        Ok(IndexEstimate {
            film: FilmIndex::constant(best.0),
            sigma: Some(o.grid_ior_step / 12f64.sqrt()),
            note: format!(
                "grid: n step {} over [{lo:.3}, {:.3}], d step {} nm, {} pixels",
                o.grid_ior_step,
                o.max_film_ior,
                o.grid_thickness_step_nm,
                sub.len()
            ),
            dispersive_start: None,
        })
    }
}

impl ThicknessStage for GridThickness {
    fn run(&self, cx: &Context, sol: &FilmSolution) -> Result<ThicknessMap> {
        let obs = &cx.obs;
        let m = obs.geom.model_of(&sol.film, 0.0);
        let sigma2 = cx.noise.typical * cx.noise.typical;
        let band = cx.band();
        let res: Vec<(f32, f32, u32)> = (0..obs.pixels())
            .into_par_iter()
            .map_init(
                || PixelData::new(obs),
                |px, p| {
                    let used = if band.contains(&p) {
                        obs.get(p, &mut px.y, &mut px.mask)
                    } else {
                        0
                    };
                    if used == 0 {
                        return (f32::NAN, 0.0, 0);
                    }
                    let (d, s) = best_d(cx, &m, &px.y, &px.mask);
                    (d as f32, (s / sigma2) as f32, (used * obs.bands) as u32)
                },
            )
            .collect();
        Ok(ThicknessMap {
            d: res.iter().map(|r| r.0).collect(),
            chi2: res.iter().map(|r| r.1).collect(),
            samples: res.iter().map(|r| r.2).collect(),
            curvature: None,
        })
    }
}
