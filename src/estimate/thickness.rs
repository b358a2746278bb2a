//! Thickness stage of `full`: d for every pixel with the shared parameters fixed, on the
//! tabulated whitened model ([`super::solver`]).
//!
//! Small images get the global search everywhere. Large ones: global search on a seed
//! lattice, then each row left to right from its left neighbour's thickness (d is smooth,
//! seed assumption 3 — Gauss–Newton converges in one or two steps), falling back to the
//! seeds and then to the global search where the fit is poor. Finally order jumps are
//! removed with the spatial smoothness of d: where d leaves its neighbourhood median by
//! more than a fraction of a fringe, the fit from the median is kept when about as good.
//!
//! A band fit ([`super::tiles`]) searches every seed (their typical residual sets what a good
//! fit is), propagates only the band's rows and [`HALO_ROWS`] above and below, and resolves
//! orders there: the band's rows see exactly the values they see in the whole fit.

use super::data::{median, Observations, PixelData};
use super::nuisance::Whitening;
use super::solver::{FixedModel, ThicknessSolver};
use super::stage::{Context, FilmSolution, ThicknessMap, ThicknessStage};
use anyhow::Result;
use rayon::prelude::*;

/// The `full` method's thickness stage.
pub struct TableThickness;

/// One pixel's fit: (d, χ², samples, curvature).
type PixelFit = (f32, f32, u32, f32);

const NONE: PixelFit = (f32::NAN, 0.0, 0, 0.0);

/// Rows above and below a band that its order resolution reads: two rounds of a median of
/// radius 2 (round two of a band row reads round one two rows away, which read two more).
pub const HALO_ROWS: usize = 4;

impl ThicknessStage for TableThickness {
    fn run(&self, cx: &Context, sol: &FilmSolution) -> Result<ThicknessMap> {
        let obs = &cx.obs;
        let fixed = FixedModel::of(&obs.geom, sol);
        let solver = ThicknessSolver::new(
            &fixed,
            cx.opts.min_thickness_nm,
            cx.opts.max_thickness_nm,
            true,
        );
        let white = Whitening::new(&sol.nuisance, &sol.sigma, obs.angles, obs.stride);
        Ok(fit_all(cx, sol, &solver, &white))
    }
}

fn fit_all(
    cx: &Context,
    sol: &FilmSolution,
    solver: &ThicknessSolver,
    white: &Whitening,
) -> ThicknessMap {
    let obs = &cx.obs;
    let (w, h) = (obs.width, obs.height);
    let film = &sol.film;
    // A few hundred seeds get the global search; the rest start from a neighbour.
    let stride = (((w * h) as f64 / 384.0).sqrt().floor() as usize).clamp(1, 48);
    let mut out = vec![NONE; w * h];
    // Rows fitted: the band and the halo its order resolution reads.
    let win = (
        cx.rows.0.saturating_sub(HALO_ROWS),
        (cx.rows.1 + HALO_ROWS).min(h),
    );
    let pb = cx.progress_bar(w * (win.1 - win.0), "thickness");
    let load = |px: &mut PixelData, p: usize| px.load(obs, white, film, p) > 0;
    // 1. Seeds: all of them where rows propagate from them (their typical residual is
    // what a good fit is), else (every pixel a seed) those of the fitted rows.
    let seed_rows = if stride > 1 { 0..h } else { win.0..win.1 };
    let seeds: Vec<usize> = seed_rows
        .step_by(stride)
        .flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x))
        .collect();
    let seed_fits: Vec<(usize, PixelFit)> = seeds
        .par_iter()
        .map_init(
            || PixelData::new(obs),
            |px, &p| {
                if !load(px, p) {
                    return (p, NONE);
                }
                let (d, s, hs) = solver.search(px);
                (p, (d as f32, s as f32, px.samples as u32, hs as f32))
            },
        )
        .collect();
    for (p, f) in seed_fits {
        out[p] = f;
    }
    // 2. Propagate to the rest.
    if stride > 1 {
        let (gw, gh) = (w.div_ceil(stride), h.div_ceil(stride));
        let seed_d: Vec<f32> = (0..gh)
            .flat_map(|gy| (0..gw).map(move |gx| (gy, gx)))
            .map(|(gy, gx)| out[(gy * stride) * w + gx * stride].0)
            .collect();
        let mut seed_chi: Vec<f64> = seeds
            .iter()
            .filter(|&&p| out[p].0.is_finite() && out[p].2 > 0)
            .map(|&p| out[p].1 as f64 / out[p].2 as f64)
            .collect();
        let typical = median(&mut seed_chi).unwrap_or(1.0);
        // A fit this good is taken as the right order (no global search).
        let good = 2.0 * typical + 1e-6;
        let rows: Vec<(usize, Vec<PixelFit>)> = (win.0..win.1)
            .into_par_iter()
            .map_init(
                || PixelData::new(obs),
                |px, yy| {
                    let mut row = Vec::with_capacity(w);
                    let mut left: Option<f64> = None;
                    for x in 0..w {
                        let p = yy * w + x;
                        if yy % stride == 0 && x % stride == 0 {
                            let f = out[p];
                            row.push(f);
                            let ok = f.2 > 0 && (f.1 as f64 / f.2 as f64) <= good;
                            left = (ok && f.0.is_finite()).then_some(f.0 as f64);
                            continue;
                        }
                        if !load(px, p) {
                            row.push(NONE);
                            left = None;
                            continue;
                        }
                        let n = px.samples as f64;
                        let seed = interpolate_seed(&seed_d, gw, gh, stride, x, yy);
                        let mut best = match left.or(seed) {
                            Some(d0) => solver.refine(px, d0, 5),
                            None => (f64::NAN, f64::INFINITY, 0.0),
                        };
                        if !(best.1 / n <= good) && left.is_some() {
                            // The neighbour may sit on another order: try the seeds.
                            if let Some(d0) = seed {
                                let r = solver.refine(px, d0, 5);
                                if r.1 < best.1 {
                                    best = r;
                                }
                            }
                        }
                        if !(best.1 / n <= good) {
                            let r = solver.search(px);
                            if r.1 < best.1 {
                                best = r;
                            }
                        }
                        let ok = best.1 / n <= good;
                        left = (ok && best.0.is_finite()).then_some(best.0);
                        row.push((best.0 as f32, best.1 as f32, n as u32, best.2 as f32));
                    }
                    (yy, row)
                },
            )
            .inspect(|_| pb.inc(w as u64))
            .collect();
        for (yy, row) in rows {
            out[yy * w..(yy + 1) * w].copy_from_slice(&row);
        }
    }
    pb.finish_and_clear();
    resolve_orders(obs, solver, white, film, &mut out, win);
    // Seeds and halo rows outside the band belong to other bands' fits.
    let band = cx.band();
    out[..band.start].fill(NONE);
    out[band.end..].fill(NONE);
    ThicknessMap {
        d: out.iter().map(|f| f.0).collect(),
        chi2: out.iter().map(|f| f.1).collect(),
        samples: out.iter().map(|f| f.2).collect(),
        curvature: Some(out.iter().map(|f| f.3).collect()),
    }
}

/// Spatial order resolution (twice) on rows `win`: where d jumps from its neighbourhood
/// median by more than a quarter fringe, re-fit from the median and keep it when the fit is
/// about as good (an order jump with equal residual is the smoothness prior's call). Rows
/// within [`HALO_ROWS`] of an edge of `win` that is not the image's are not final.
fn resolve_orders(
    obs: &Observations,
    solver: &ThicknessSolver,
    white: &Whitening,
    film: &super::film::FilmIndex,
    out: &mut [PixelFit],
    win: (usize, usize),
) {
    let (w, h) = (obs.width, obs.height);
    for _ in 0..2 {
        let d: Vec<f32> = out.iter().map(|f| f.0).collect();
        let tau = solver.scan_step * 2.0;
        // The 5 × 5 median is only needed where it is farther than tau from the pixel
        // (rare): elsewhere counting the window's values on either side decides.
        let flagged: Vec<(usize, f32)> = (win.0 * w..win.1 * w)
            .into_par_iter()
            .map_init(Vec::new, |buf, p| {
                window_values(&d, w, h, 2, p, buf);
                let far = d[p].is_finite() && median_is_farther(buf, d[p], tau);
                far.then(|| (p, window_median(buf)))
            })
            .flatten()
            .collect();
        let changes: Vec<(usize, PixelFit)> = flagged
            .into_par_iter()
            .map_init(
                || PixelData::new(obs),
                |px, (p, m)| {
                    px.load(obs, white, film, p);
                    let (d2, s2, h2) = solver.refine(px, m as f64, 8);
                    let tol = 1.25 * out[p].1 as f64 + 1e-9;
                    if s2 <= tol && (d2 - m as f64).abs() < tau {
                        (p, (d2 as f32, s2 as f32, out[p].2, h2 as f32))
                    } else {
                        (p, out[p])
                    }
                },
            )
            .collect();
        if changes.is_empty() {
            break;
        }
        for (p, f) in changes {
            out[p] = f;
        }
    }
}

fn interpolate_seed(
    seed: &[f32],
    gw: usize,
    gh: usize,
    stride: usize,
    x: usize,
    y: usize,
) -> Option<f64> {
    let fx = x as f64 / stride as f64;
    let fy = y as f64 / stride as f64;
    let x0 = (fx.floor() as usize).min(gw - 1);
    let y0 = (fy.floor() as usize).min(gh - 1);
    let x1 = (x0 + 1).min(gw - 1);
    let y1 = (y0 + 1).min(gh - 1);
    let tx = fx - x0 as f64;
    let ty = fy - y0 as f64;
    let mut acc = 0.0;
    let mut wsum = 0.0;
    for (gx, gy, wt) in [
        (x0, y0, (1.0 - tx) * (1.0 - ty)),
        (x1, y0, tx * (1.0 - ty)),
        (x0, y1, (1.0 - tx) * ty),
        (x1, y1, tx * ty),
    ] {
        let v = seed[gy * gw + gx];
        if v.is_finite() {
            acc += wt.max(1e-6) * v as f64;
            wsum += wt.max(1e-6);
        }
    }
    (wsum > 0.0).then(|| acc / wsum)
}

/// Median over the (2r+1)² neighbourhood (inside the image), ignoring NaN, for the pixels
/// of rows `[rows.0, rows.1)`.
/// The finite values of the (2r + 1)² window around pixel `p` of the `w × h` map `d`.
fn window_values(d: &[f32], w: usize, h: usize, r: usize, p: usize, buf: &mut Vec<f32>) {
    let (x, y) = (p % w, p / w);
    buf.clear();
    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
        let row = &d[yy * w..(yy + 1) * w];
        let span = &row[x.saturating_sub(r)..(x + r + 1).min(w)];
        buf.extend(span.iter().filter(|v| v.is_finite()));
    }
}

/// Element `len / 2` of the sorted `values` (NaN when empty).
fn window_median(values: &mut [f32]) -> f32 {
    if values.is_empty() {
        return f32::NAN;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// Whether `|v − median(values)| > tau` (the difference in f32 as it is computed for the
/// median itself), without finding the median: `v − x` falls as x grows, so the median m
/// (element `mid` of the sorted values) has `v − m > tau` exactly when at least `mid + 1`
/// values x do, and `v − m < −tau` exactly when at least `len − mid` do.
fn median_is_farther(values: &[f32], v: f32, tau: f64) -> bool {
    if values.is_empty() {
        return false;
    }
    let mid = values.len() / 2;
    let above = values.iter().filter(|&&x| (v - x) as f64 > tau).count();
    let below = values.iter().filter(|&&x| ((v - x) as f64) < -tau).count();
    above > mid || below >= values.len() - mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The counting test decides exactly as finding the median and comparing does,
        /// including ties, values on the tau boundary and f32 rounding of the difference.
        #[test]
        fn median_is_farther_matches_the_median(
            values in proptest::collection::vec(
                prop_oneof![-3i32..3, -2000i32..2000].prop_map(|k| k as f32 * 0.25), 0..26),
            v_steps in -2000i32..2000,
            tau_steps in 0i32..40,
        ) {
            let v = v_steps as f32 * 0.25;
            let tau = tau_steps as f64 * 0.125;
            let mut sorted = values.clone();
            let m = window_median(&mut sorted);
            let want = m.is_finite() && (v - m).abs() as f64 > tau;
            prop_assert_eq!(median_is_farther(&values, v, tau), want);
        }
    }

    /// The window holds the finite values around the pixel, clipped at the image edges.
    #[test]
    fn window_values_clip_and_skip_non_finite() {
        let (w, h) = (4, 3);
        let mut d: Vec<f32> = (0..w * h).map(|i| i as f32).collect();
        d[5] = f32::NAN;
        let mut buf = Vec::new();
        window_values(&d, w, h, 1, 0, &mut buf);
        assert_eq!(buf, vec![0.0, 1.0, 4.0]);
        window_values(&d, w, h, 2, 6, &mut buf);
        assert_eq!(buf.len(), 11); // 3 rows × 4 columns, less the NaN
        assert!(!buf.contains(&5.0));
    }
}
