//! Film index (global) and per-pixel thickness from a multi-angle hyperspectral capture
//! (seed §4, with the corrections for half orders and band quantisation).
//!
//! Three methods share one forward model ([`model::FilmModel`]):
//! - [`Method::Paper`] — the seed as published: band-quantised peak wavelengths, eq. (12)
//!   for n over angle pairs, eq. (13) for d with the integer order m picked by least
//!   squares, eq. (14);
//! - [`Method::Full`] — sub-band peaks tracked over all angles and orders give a robust
//!   (median) first n; a coarse thickness scan whose candidates include whole and
//!   half-order fringes; a joint Gauss–Newton/Levenberg–Marquardt refinement of n (shared)
//!   and d (per pixel) on the full model (polarisation, band integration); order
//!   ambiguities resolved by the spatial smoothness of d (seed assumption 3);
//! - [`Method::Grid`] — the exhaustive (n, d) search the seed compares against.

// `!(x > 0.0)` is deliberate throughout: it is also true for NaN. Per-pixel results are
// small tuples collected from rayon.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::type_complexity)]

pub mod model;
pub mod peaks;
pub mod report;
pub mod synth;
pub mod table;
pub mod tiles;

use crate::capture::CaptureSet;
use anyhow::{bail, Result};
use model::{FilmModel, Geometry, PassSums};
use rayon::prelude::*;
use std::time::Instant;

/// CPU seconds (user + system, all threads) used by this process so far, from
/// `/proc/self/stat` (Linux, 10 ms ticks); `None` where that is unavailable. Benchmarks on
/// a shared machine report it beside wall-clock time, which other load inflates.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ is 100 on every Linux ABI Rust targets
}

/// Wall-clock and CPU seconds of one stage.
pub(crate) struct Stopwatch {
    wall: Instant,
    cpu: Option<f64>,
}

/// Per-stage wall-clock and CPU seconds, in stage order.
#[derive(Default)]
pub(crate) struct Stages {
    wall: Vec<(String, f64)>,
    cpu: Vec<(String, f64)>,
}

impl Stopwatch {
    pub(crate) fn start() -> Self {
        Stopwatch {
            wall: Instant::now(),
            cpu: process_cpu_seconds(),
        }
    }
    pub(crate) fn stop(self, name: &str, stages: &mut Stages) {
        stages
            .wall
            .push((name.to_string(), self.wall.elapsed().as_secs_f64()));
        if let (Some(a), Some(b)) = (self.cpu, process_cpu_seconds()) {
            stages.cpu.push((name.to_string(), b - a));
        }
    }
}
use table::ThicknessTable;

/// Which estimator to run.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The seed's method as published (band-quantised peaks, eqs. 12–14).
    Paper,
    /// Exhaustive (n, d) grid search.
    Grid,
    /// Sub-band peaks + joint least-squares refinement + spatial order resolution.
    Full,
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Method::Paper => "paper",
            Method::Grid => "grid",
            Method::Full => "full",
        })
    }
}

/// Estimator settings.
#[derive(Debug, Clone)]
pub struct Options {
    pub method: Method,
    /// Known film index: fit thickness only (works with a single angle).
    pub film_ior: Option<f64>,
    pub min_thickness_nm: f64,
    pub max_thickness_nm: f64,
    /// Index range searched by `grid` and by `full`'s fallback when no peaks are found.
    pub min_film_ior: f64,
    pub max_film_ior: f64,
    pub grid_ior_step: f64,
    pub grid_thickness_step_nm: f64,
    /// `grid` evaluates the index search on every k-th pixel in x and y (1 = all).
    pub grid_pixel_stride: usize,
    /// Model the camera's Gaussian band response when the capture gives FWHMs.
    pub band_integration: bool,
    /// Pixels used for the joint (n, d) refinement of `full`.
    pub joint_pixels: usize,
    pub progress: bool,
    /// Fit only a band of rows: the index from its pixels (unless given), its thickness
    /// exactly as in the whole fit ([`tiles`]). `None`: every row.
    pub rows: Option<tiles::RowBand>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::Full,
            film_ior: None,
            min_thickness_nm: 0.0,
            max_thickness_nm: 2000.0,
            min_film_ior: 1.1,
            max_film_ior: 3.0,
            grid_ior_step: 0.01,
            grid_thickness_step_nm: 2.0,
            grid_pixel_stride: 1,
            band_integration: true,
            joint_pixels: 256,
            progress: false,
            rows: None,
        }
    }
}

/// A fitted film.
#[derive(Debug, Clone)]
pub struct Fit {
    pub method: Method,
    pub film_ior: f64,
    /// 1σ uncertainty of the index, when the method gives one.
    pub film_ior_sigma: Option<f64>,
    /// How the index was obtained / why it has no uncertainty.
    pub film_ior_note: String,
    pub width: usize,
    /// Rows in this fit (`rows.1 − rows.0`).
    pub height: usize,
    /// Rows `[A, B)` of the capture this fit covers (all of them unless `--rows`).
    pub rows: (usize, usize),
    /// What the thickness map is, for its EXR header (`thinfilm merge` stitches by it).
    pub provenance: tiles::TileInfo,
    /// Per pixel of `rows`, nm, NaN where no thickness was fitted.
    pub thickness_nm: Vec<f32>,
    /// Per pixel residual sum of squares and sample count.
    pub sse: Vec<f32>,
    pub samples: Vec<u32>,
    /// Pixels with no usable angle.
    pub invalid_pixels: usize,
    /// Pixels with data but no thickness (e.g. no peak for `paper`).
    pub unfitted_pixels: usize,
    pub stage_seconds: Vec<(String, f64)>,
    /// CPU seconds (all threads) per stage, where the platform reports them.
    pub stage_cpu_seconds: Vec<(String, f64)>,
    pub warnings: Vec<String>,
}

impl Fit {
    pub fn valid_pixels(&self) -> usize {
        self.thickness_nm.iter().filter(|d| d.is_finite()).count()
    }
    /// Residual RMSE over every fitted sample (seed eq. 16 pooled), `None` if nothing fitted.
    pub fn rmse(&self) -> Option<f64> {
        let (mut s, mut c) = (0.0f64, 0u64);
        for ((&e, &k), d) in self.sse.iter().zip(&self.samples).zip(&self.thickness_nm) {
            if d.is_finite() && k > 0 {
                s += e as f64;
                c += k as u64;
            }
        }
        (c > 0).then(|| (s / c as f64).sqrt())
    }
}

/// Per-pixel data view: copies one pixel's spectra (angle-major) and its angle mask.
pub(crate) struct Pixels<'a> {
    set: &'a CaptureSet,
}

impl<'a> Pixels<'a> {
    pub fn new(set: &'a CaptureSet) -> Self {
        Pixels { set }
    }
    /// Fills `y` (angles × bands) and `mask`; returns the number of usable angles.
    pub fn get(&self, p: usize, y: &mut [f32], mask: &mut [bool]) -> usize {
        let b = self.set.bands();
        let mut used = 0;
        for (a, ang) in self.set.angles.iter().enumerate() {
            let src = &ang.reflectance[p * b..(p + 1) * b];
            let ok =
                ang.valid.get(p).copied().unwrap_or(false) && src.iter().all(|v| v.is_finite());
            mask[a] = ok;
            if ok {
                y[a * b..(a + 1) * b].copy_from_slice(src);
                used += 1;
            } else {
                y[a * b..(a + 1) * b].iter_mut().for_each(|v| *v = 0.0);
            }
        }
        used
    }
}

fn check_set(set: &CaptureSet) -> Result<()> {
    let b = set.bands();
    if b < 3 {
        bail!("capture has {b} bands; at least 3 are needed to fit a spectrum");
    }
    if set.angles.is_empty() {
        bail!("capture has no incident angles");
    }
    let px = set.width * set.height;
    for a in &set.angles {
        if a.reflectance.len() != px * b || a.valid.len() != px {
            bail!(
                "angle {}°: cube holds {} samples / {} mask entries, expected {}×{}×{} / {}",
                a.incident_deg,
                a.reflectance.len(),
                a.valid.len(),
                set.width,
                set.height,
                b,
                px
            );
        }
        if !(a.incident_deg.is_finite() && (0.0..90.0).contains(&a.incident_deg)) {
            bail!("incident angle {}° is outside [0°, 90°)", a.incident_deg);
        }
    }
    if set
        .wavelengths_nm
        .iter()
        .any(|l| !(l.is_finite() && *l > 0.0))
    {
        bail!("capture wavelengths must be finite and > 0 nm");
    }
    Ok(())
}

/// Runs the chosen estimator.
pub fn estimate(set: &CaptureSet, opts: &Options) -> Result<Fit> {
    check_set(set)?;
    if let Some(band) = opts.rows {
        band.resolve(set.height)?;
    }
    if let Some(n) = opts.film_ior {
        if !(n.is_finite() && n > 0.0) {
            bail!("--film-ior must be a finite positive index, got {n}");
        }
    } else {
        let mut distinct: Vec<f64> = set.angles.iter().map(|a| a.incident_deg).collect();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        if distinct.len() < 2 {
            bail!(
                "the capture has a single incident angle ({}°): the film index cannot be \
                 separated from the thickness (seed eq. 12 needs two angles); pass --film-ior",
                distinct[0]
            );
        }
    }
    if !(opts.max_thickness_nm > opts.min_thickness_nm && opts.min_thickness_nm >= 0.0) {
        bail!(
            "thickness range [{}, {}] nm is empty",
            opts.min_thickness_nm,
            opts.max_thickness_nm
        );
    }
    match opts.method {
        Method::Full => full(set, opts),
        Method::Paper => paper(set, opts),
        Method::Grid => grid(set, opts),
    }
}

fn progress_bar(opts: &Options, len: usize, what: &str) -> indicatif::ProgressBar {
    let pb = crate::progress::bar(
        opts.progress,
        len as u64,
        "{msg:>12} [{bar:40}] {pos}/{len} px ({eta} left)",
    );
    pb.set_message(what.to_string());
    pb
}

/// Evenly spread subset of `items`, at most `max` long.
fn spread<T: Copy>(items: &[T], max: usize) -> Vec<T> {
    if items.len() <= max {
        return items.to_vec();
    }
    (0..max).map(|i| items[i * items.len() / max]).collect()
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Band step used when scoring candidates (speed; the refinement uses every band).
fn score_step(bands: usize) -> usize {
    (bands / 40).max(1)
}

/// Largest thickness table [`DSolver::with_table`] builds; beyond it (very wide thickness
/// ranges or thousands of bands) the solver evaluates the model directly.
const MAX_TABLE_BYTES: usize = 256 << 20;

/// Thickness search context for one film index.
struct DSolver<'a> {
    model: &'a FilmModel,
    /// Point-sampled model (no band quadrature) used for the coarse scan only when there
    /// is no table: the scan just has to land in the right basin, and the quadrature
    /// triples its cost. The Gauss–Newton refinement always uses `model` (or its table).
    scan_model: Option<FilmModel>,
    /// `model` tabulated over [d_min, d_max] (see [`table`]): scan and refinement become
    /// dot products and Hermite interpolation instead of Airy evaluations.
    table: Option<ThicknessTable>,
    d_min: f64,
    d_max: f64,
    /// Coarse scan step: 1/8 of a fringe at the shortest wavelength, so some scan point
    /// always lies inside the Gauss–Newton basin of the true thickness.
    scan_step: f64,
    max_newton_step: f64,
    score_step: usize,
}

impl<'a> DSolver<'a> {
    fn new(model: &'a FilmModel, geom: &Geometry, opts: &Options) -> Self {
        let kx_min = geom
            .incident_deg
            .iter()
            .map(|a| geom.ambient_ior * a.to_radians().sin())
            .fold(f64::INFINITY, f64::min);
        let n_eff = (model.film_ior.powi(2) - kx_min * kx_min).max(1e-6).sqrt();
        let fringe = geom.lambda_min() / (2.0 * n_eff); // d change for one whole order
        let scan_model = geom.band_integration.then(|| {
            let mut point = geom.clone();
            point.band_integration = false;
            point.model(model.film_ior)
        });
        DSolver {
            model,
            scan_model,
            table: None,
            d_min: opts.min_thickness_nm,
            d_max: opts.max_thickness_nm,
            scan_step: fringe / 8.0,
            max_newton_step: fringe / 6.0,
            score_step: score_step(model.bands),
        }
    }

    /// As [`DSolver::new`], plus a thickness table with 64 nodes per scan fringe (8 per
    /// scan step) when it fits in [`MAX_TABLE_BYTES`]. Worth it when many pixels share
    /// the index: building costs about as much as fitting a few hundred pixels directly.
    fn with_table(model: &'a FilmModel, geom: &Geometry, opts: &Options) -> Self {
        let mut s = Self::new(model, geom, opts);
        let step = s.scan_step / 8.0;
        if step > 0.0 && ThicknessTable::bytes_for(model, s.d_min, s.d_max, step) <= MAX_TABLE_BYTES
        {
            s.table = Some(ThicknessTable::build(model, s.d_min, s.d_max, step));
            s.scan_model = None;
        }
        s
    }

    #[inline]
    fn pass(&self, d: f64, y: &[f32], mask: &[bool]) -> PassSums {
        match &self.table {
            Some(t) => t.pass(d, y, mask),
            None => self.model.pass(d, y, mask),
        }
    }

    /// Damped Gauss–Newton in d from `d0`.
    fn refine(&self, y: &[f32], mask: &[bool], d0: f64, iters: usize) -> (f64, f64) {
        let mut d = d0.clamp(self.d_min, self.d_max);
        let mut cur = self.pass(d, y, mask);
        for _ in 0..iters {
            if !(cur.hess > 0.0) {
                break;
            }
            let mut step =
                (-cur.grad / cur.hess).clamp(-self.max_newton_step, self.max_newton_step);
            if !(step.abs() > 1e-2) {
                break; // converged: 0.01 nm is far below the accuracy needed
            }
            let mut moved = false;
            for _ in 0..6 {
                let dn = (d + step).clamp(self.d_min, self.d_max);
                let nw = self.pass(dn, y, mask);
                if nw.sse <= cur.sse {
                    moved = (dn - d).abs() > 1e-2; // 0.01 nm: far below the accuracy needed
                    d = dn;
                    cur = nw;
                    break;
                }
                step *= 0.5;
            }
            if !moved {
                break;
            }
        }
        (d, cur.sse)
    }

    /// Coarse scan scores (d, SSE) over [d_min, d_max] every `scan_step`.
    fn scan(&self, y: &[f32], mask: &[bool]) -> Vec<(f64, f64)> {
        if let Some(t) = &self.table {
            // Same spacing as the direct scan, on table nodes, every band, exact model.
            let stride = ((self.scan_step / t.step_nm).round() as usize).max(1);
            let last = (((self.d_max - t.d_min) / t.step_nm).ceil() as usize).min(t.nodes - 1);
            let yy: f32 = y.iter().map(|v| v * v).sum();
            let mut idx: Vec<usize> = (0..=last).step_by(stride).collect();
            if idx.last() != Some(&last) {
                idx.push(last);
            }
            return idx
                .into_iter()
                .map(|i| {
                    (
                        t.node_d(i).min(self.d_max),
                        t.node_sse(i, y, mask, yy) as f64,
                    )
                })
                .collect();
        }
        let steps = ((self.d_max - self.d_min) / self.scan_step).ceil() as usize + 1;
        let scan = self.scan_model.as_ref().unwrap_or(self.model);
        (0..steps)
            .map(|i| {
                let d = (self.d_min + i as f64 * self.scan_step).min(self.d_max);
                (d, scan.sse(d, y, mask, self.score_step))
            })
            .collect()
    }

    /// Global search: coarse scan (covering whole- and half-order fringe positions alike)
    /// then Gauss–Newton from the best few local minima.
    fn search(&self, y: &[f32], mask: &[bool]) -> (f64, f64) {
        let scores = self.scan(y, mask);
        let mut minima: Vec<(f64, f64)> = (0..scores.len())
            .filter(|&i| {
                let s = scores[i].1;
                (i == 0 || scores[i - 1].1 >= s) && (i + 1 == scores.len() || scores[i + 1].1 >= s)
            })
            .map(|i| scores[i])
            .collect();
        minima.sort_by(|a, b| a.1.total_cmp(&b.1));
        let mut best = (f64::NAN, f64::INFINITY);
        for &(d0, _) in minima.iter().take(3) {
            let (d, s) = self.refine(y, mask, d0, 8);
            if s < best.1 {
                best = (d, s);
            }
        }
        best
    }
}

/// Output of the per-pixel thickness stage.
struct Thickness {
    d: Vec<f32>,
    sse: Vec<f32>,
    samples: Vec<u32>,
}

/// Fits d for every pixel with the index fixed. Small images: global search everywhere.
/// Large ones: global search on a seed lattice, propagation (GN from interpolated seeds)
/// elsewhere, global search again only where the propagated fit is poor. Then order jumps
/// are removed with the spatial smoothness of d (seed assumption 3). With `opts.rows`, only
/// those rows (and the halo their order resolution reads) are fitted, from the seeds of the
/// whole image, so they come out exactly as in the whole fit ([`tiles`]); other rows stay NaN.
fn fit_thickness(set: &CaptureSet, geom: &Geometry, n: f64, opts: &Options) -> Thickness {
    let model = geom.model(n);
    let solver = DSolver::with_table(&model, geom, opts);
    let px = Pixels::new(set);
    let (w, h) = (set.width, set.height);
    let (na, nb) = (set.angles.len(), set.bands());
    // A few hundred seeds get the global search; the rest start from interpolated
    // seeds and need only a few Gauss–Newton steps (global search again where poor).
    let stride = (((w * h) as f64 / 384.0).sqrt().floor() as usize).clamp(1, 48);
    let mut d = vec![f32::NAN; w * h];
    let mut sse = vec![0f32; w * h];
    let mut samples = vec![0u32; w * h];
    let (r0, r1) = tiles::compute_rows(fitted_rows(set, opts), h);

    // 1. Seeds: every pixel of the computed rows when there is no propagation (stride 1),
    // otherwise the lattice over the whole image (a band propagates from the same seeds).
    let seed_rows = if stride == 1 { r0..r1 } else { 0..h };
    let seeds: Vec<usize> = seed_rows
        .step_by(stride)
        .flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x))
        .collect();
    let seed_fits: Vec<(usize, f32, f32, u32)> = seeds
        .par_iter()
        .map_init(
            || (vec![0f32; na * nb], vec![false; na]),
            |(y, m), &p| {
                let used = px.get(p, y, m);
                if used == 0 {
                    return (p, f32::NAN, 0.0, 0);
                }
                let (dd, s) = solver.search(y, m);
                (p, dd as f32, s as f32, (used * nb) as u32)
            },
        )
        .collect();
    let pb = progress_bar(opts, w * (r1 - r0), "thickness");
    pb.inc((seeds.len() as u64).min(pb.length().unwrap_or(0)));
    for (p, dd, s, c) in seed_fits {
        d[p] = dd;
        sse[p] = s;
        samples[p] = c;
    }
    // 2. Propagate to the rest.
    if stride > 1 {
        let (gw, gh) = (w.div_ceil(stride), h.div_ceil(stride));
        let seed_d: Vec<f32> = (0..gh)
            .flat_map(|gy| (0..gw).map(move |gx| (gy, gx)))
            .map(|(gy, gx)| d[(gy * stride) * w + gx * stride])
            .collect();
        let mut seed_rmse: Vec<f64> = seeds
            .iter()
            .filter(|&&p| d[p].is_finite() && samples[p] > 0)
            .map(|&p| (sse[p] as f64 / samples[p] as f64).sqrt())
            .collect();
        let typical = median(&mut seed_rmse).unwrap_or(0.0);
        // A fit this good is taken as the right order (no global search).
        let good_rmse = 2.0 * typical + 1e-4;
        let rows: Vec<(usize, Vec<(f32, f32, u32)>)> = (r0..r1)
            .into_par_iter()
            .map_init(
                || (vec![0f32; na * nb], vec![false; na]),
                |(yb, m), yy| {
                    let mut row = Vec::with_capacity(w);
                    // Last well-fitting thickness in this row: d is smooth (seed assumption
                    // 3), so the left neighbour predicts d far better than the seed lattice
                    // and Gauss–Newton converges in one or two steps. Rows only depend on
                    // the seeds, so the result does not depend on the thread schedule.
                    let mut left: Option<f64> = None;
                    for x in 0..w {
                        let p = yy * w + x;
                        if yy % stride == 0 && x % stride == 0 {
                            row.push((d[p], sse[p], samples[p]));
                            let ok = samples[p] > 0
                                && (sse[p] as f64 / samples[p] as f64).sqrt() <= good_rmse;
                            left = (ok && d[p].is_finite()).then_some(d[p] as f64);
                            continue;
                        }
                        let used = px.get(p, yb, m);
                        if used == 0 {
                            row.push((f32::NAN, 0.0, 0));
                            left = None;
                            continue;
                        }
                        let init =
                            left.or_else(|| interpolate_seed(&seed_d, gw, gh, stride, x, yy));
                        let (mut dd, mut s) = match init {
                            Some(d0) => solver.refine(yb, m, d0, 5),
                            None => (f64::NAN, f64::INFINITY),
                        };
                        let mut rmse = (s / (used * nb) as f64).sqrt();
                        if !(rmse <= good_rmse) && left.is_some() {
                            // The neighbour may sit on another order: try the seeds.
                            if let Some(d0) = interpolate_seed(&seed_d, gw, gh, stride, x, yy) {
                                let (d2, s2) = solver.refine(yb, m, d0, 5);
                                if s2 < s {
                                    (dd, s) = (d2, s2);
                                    rmse = (s / (used * nb) as f64).sqrt();
                                }
                            }
                        }
                        if !(rmse <= good_rmse) {
                            let (d2, s2) = solver.search(yb, m);
                            if s2 < s {
                                dd = d2;
                                s = s2;
                            }
                        }
                        let ok = (s / (used * nb) as f64).sqrt() <= good_rmse;
                        left = (ok && dd.is_finite()).then_some(dd);
                        row.push((dd as f32, s as f32, (used * nb) as u32));
                    }
                    (yy, row)
                },
            )
            .inspect(|_| pb.inc(w as u64))
            .collect();
        for (yy, row) in rows {
            for (x, (dd, s, c)) in row.into_iter().enumerate() {
                let p = yy * w + x;
                d[p] = dd;
                sse[p] = s;
                samples[p] = c;
            }
        }
    }
    pb.finish_and_clear();
    // 3. Spatial order resolution: where d jumps from its neighbourhood median by more
    // than a fraction of a fringe, re-fit from the median and keep it when the fit is
    // about as good (an order jump with equal residual is the smoothness prior's call).
    for _ in 0..2 {
        let med = median_filter(&d, w, h, 2, (r0, r1));
        let tau = solver.scan_step * 2.0;
        let changes: Vec<(usize, f32, f32)> = (r0 * w..r1 * w)
            .into_par_iter()
            .filter(|&p| {
                d[p].is_finite() && med[p].is_finite() && (d[p] - med[p]).abs() as f64 > tau
            })
            .map_init(
                || (vec![0f32; na * nb], vec![false; na]),
                |(yb, m), p| {
                    px.get(p, yb, m);
                    let (d2, s2) = solver.refine(yb, m, med[p] as f64, 8);
                    let tol = 1.25 * sse[p] as f64 + 1e-9;
                    if s2 <= tol && (d2 - med[p] as f64).abs() < tau {
                        (p, d2 as f32, s2 as f32)
                    } else {
                        (p, d[p], sse[p])
                    }
                },
            )
            .collect();
        if changes.is_empty() {
            break;
        }
        for (p, dd, s) in changes {
            d[p] = dd;
            sse[p] = s;
        }
    }
    // Keep the fitted rows only.
    let (a, b) = fitted_rows(set, opts);
    for v in [&mut d, &mut sse] {
        v.truncate(b * w);
        v.drain(..a * w);
    }
    samples.truncate(b * w);
    samples.drain(..a * w);
    Thickness { d, sse, samples }
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

/// Median over the (2r+1)² neighbourhood, ignoring NaN, for the pixels of `rows` (NaN
/// elsewhere).
fn median_filter(d: &[f32], w: usize, h: usize, r: usize, rows: (usize, usize)) -> Vec<f32> {
    (0..w * h)
        .into_par_iter()
        .map_init(Vec::new, |buf: &mut Vec<f32>, p| {
            let (x, y) = (p % w, p / w);
            if !(rows.0..rows.1).contains(&y) {
                return f32::NAN;
            }
            buf.clear();
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    let v = d[yy * w + xx];
                    if v.is_finite() {
                        buf.push(v);
                    }
                }
            }
            if buf.is_empty() {
                return f32::NAN;
            }
            let mid = buf.len() / 2;
            *buf.select_nth_unstable_by(mid, f32::total_cmp).1
        })
        .collect()
}

/// Pixels usable for index estimation (≥ 2 angles), of the fitted rows.
fn multi_angle_pixels(set: &CaptureSet, opts: &Options) -> Vec<usize> {
    row_pixels(set, opts)
        .filter(|&p| set.angles.iter().filter(|a| a.valid[p]).count() >= 2)
        .collect()
}

/// Rows `[A, B)` the fit covers.
fn fitted_rows(set: &CaptureSet, opts: &Options) -> (usize, usize) {
    opts.rows
        .and_then(|b| b.resolve(set.height).ok())
        .unwrap_or((0, set.height))
}

/// Pixel indices of the fitted rows.
fn row_pixels(set: &CaptureSet, opts: &Options) -> std::ops::Range<usize> {
    let (a, b) = fitted_rows(set, opts);
    a * set.width..b * set.width
}

/// Angle order by increasing n1 sinθ (peaks move to shorter wavelengths along it).
fn angle_order(set: &CaptureSet) -> Vec<(usize, f64)> {
    let mut v: Vec<(usize, f64)> = set
        .angles
        .iter()
        .enumerate()
        .map(|(i, a)| (i, set.ambient_ior * a.incident_deg.to_radians().sin()))
        .collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    v
}

/// First index estimate of `full`: sub-band peaks tracked from angle to angle (each order
/// separately), eq. (12) generalised to all angles of a track, median over tracks.
fn index_from_peaks(
    set: &CaptureSet,
    pixels: &[usize],
    geom: &Geometry,
) -> Option<(f64, f64, usize)> {
    let px = Pixels::new(set);
    let (na, nb) = (set.angles.len(), set.bands());
    let order = angle_order(set);
    let n_lo = geom.min_film_ior().max(1.05);
    let lambdas = &set.wavelengths_nm;
    let mut estimates: Vec<f64> = pixels
        .par_iter()
        .map_init(
            || (vec![0f32; na * nb], vec![false; na]),
            |(y, m), &p| {
                px.get(p, y, m);
                // Peaks per angle (in kx order).
                let per_angle: Vec<(f64, Vec<peaks::Peak>)> = order
                    .iter()
                    .filter(|(a, _)| m[*a])
                    .map(|&(a, kx)| {
                        let ya = &y[a * nb..(a + 1) * nb];
                        let sigma = peaks::noise_sigma(ya);
                        (
                            kx,
                            peaks::subband_peaks(ya, lambdas, (4.0 * sigma).max(0.002), 10.0),
                        )
                    })
                    .collect();
                let mut out = Vec::new();
                // Track each peak of the first angle that has peaks through later angles.
                for start in 0..per_angle.len() {
                    for pk in &per_angle[start].1 {
                        // Only start tracks at peaks not continuing an earlier track.
                        if start > 0
                            && track_prev(
                                &per_angle[start - 1],
                                per_angle[start].0,
                                pk.lambda_nm,
                                n_lo,
                            )
                            .is_some()
                        {
                            continue;
                        }
                        let mut track = vec![(per_angle[start].0, pk.lambda_nm)];
                        let mut lam = pk.lambda_nm;
                        let mut kx = per_angle[start].0;
                        for next in &per_angle[start + 1..] {
                            match track_next(kx, lam, next, n_lo) {
                                Some(l2) => {
                                    track.push((next.0, l2));
                                    lam = l2;
                                    kx = next.0;
                                }
                                None => break,
                            }
                        }
                        if track.len() >= 2 {
                            if let Ok(n) = peaks::index_from_track(&track) {
                                out.push(n);
                            }
                        }
                    }
                }
                out
            },
        )
        .flatten()
        .collect();
    let count = estimates.len();
    let med = median(&mut estimates)?;
    let mut dev: Vec<f64> = estimates.iter().map(|e| (e - med).abs()).collect();
    let mad = median(&mut dev).unwrap_or(0.0) * 1.4826;
    Some((med, mad / (count as f64).sqrt(), count))
}

/// Same-order peak at the next angle: the nearest one at a shorter wavelength within the
/// largest shift any index ≥ `n_lo` allows (λ2/λ1 = √((n²−kx2²)/(n²−kx1²))).
fn track_next(kx1: f64, lambda1: f64, next: &(f64, Vec<peaks::Peak>), n_lo: f64) -> Option<f64> {
    let kx2 = next.0;
    let lo_ratio = ((n_lo * n_lo - kx2 * kx2) / (n_lo * n_lo - kx1 * kx1))
        .max(0.25)
        .sqrt();
    next.1
        .iter()
        .map(|p| p.lambda_nm)
        .filter(|&l| l <= lambda1 * 1.003 && l >= lambda1 * lo_ratio * 0.997)
        .min_by(|a, b| (lambda1 - a).abs().total_cmp(&(lambda1 - b).abs()))
}

fn track_prev(prev: &(f64, Vec<peaks::Peak>), kx: f64, lambda: f64, n_lo: f64) -> Option<f64> {
    prev.1.iter().map(|p| p.lambda_nm).find(|&l0| {
        track_next(
            prev.0,
            l0,
            &(
                kx,
                vec![peaks::Peak {
                    lambda_nm: lambda,
                    prominence: 0.0,
                }],
            ),
            n_lo,
        )
        .is_some()
    })
}

/// Joint Levenberg–Marquardt of n (shared) and d_i (per pixel) on `pixels`, with the
/// block-arrow normal equations solved through the Schur complement of the d block.
/// Returns (n, σ_n, d per pixel).
fn joint_refine(
    set: &CaptureSet,
    geom: &Geometry,
    pixels: &[usize],
    n0: f64,
    d0: &[f64],
    opts: &Options,
) -> (f64, Option<f64>, Vec<f64>) {
    let px = Pixels::new(set);
    let (na, nb) = (set.angles.len(), set.bands());
    let n_min = geom.min_film_ior();
    let data: Vec<(Vec<f32>, Vec<bool>)> = pixels
        .iter()
        .map(|&p| {
            let mut y = vec![0f32; na * nb];
            let mut m = vec![false; na];
            px.get(p, &mut y, &mut m);
            (y, m)
        })
        .collect();
    let total_sse = |n: f64, d: &[f64]| -> f64 {
        let m = geom.model(n);
        data.par_iter()
            .zip(d)
            .map(|((y, mk), &di)| m.sse(di, y, mk, 1))
            .sum()
    };
    let mut n = n0;
    let mut d = d0.to_vec();
    let mut cur = total_sse(n, &d);
    let mut mu = 1e-3;
    let mut sigma = None;
    let dn_h = 1e-4;
    for _ in 0..30 {
        let m0 = geom.model(n);
        let m1 = geom.model(n + dn_h);
        // Per pixel: a = ΣJd², b = ΣJd Jn, g = ΣJd e, c = ΣJn², hn = ΣJn e.
        let parts: Vec<[f64; 5]> = data
            .par_iter()
            .zip(&d)
            .map_init(
                || (vec![0f32; nb], vec![0f32; nb], vec![0f32; nb]),
                |(r, dr, r1), ((y, mk), &di)| {
                    let mut acc = [0.0f64; 5];
                    for a in 0..na {
                        if !mk[a] {
                            continue;
                        }
                        m0.spectrum_and_derivative(a, di, r, dr);
                        m1.spectrum(a, di, r1);
                        for b in 0..nb {
                            let e = (r[b] - y[a * nb + b]) as f64;
                            let jd = dr[b] as f64;
                            let jn = (r1[b] - r[b]) as f64 / dn_h;
                            acc[0] += jd * jd;
                            acc[1] += jd * jn;
                            acc[2] += jd * e;
                            acc[3] += jn * jn;
                            acc[4] += jn * e;
                        }
                    }
                    acc
                },
            )
            .collect();
        let c: f64 = parts.iter().map(|p| p[3]).sum();
        let hn: f64 = parts.iter().map(|p| p[4]).sum();
        // Undamped Schur complement for the uncertainty at the current point.
        let schur0: f64 = c - parts
            .iter()
            .filter(|p| p[0] > 0.0)
            .map(|p| p[1] * p[1] / p[0])
            .sum::<f64>();
        let dof = data
            .iter()
            .map(|(_, m)| m.iter().filter(|&&v| v).count() * nb)
            .sum::<usize>() as f64
            - (pixels.len() + 1) as f64;
        if schur0 > 0.0 && dof > 0.0 {
            sigma = Some((cur / dof / schur0).sqrt());
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut s_c = c * (1.0 + mu);
            let mut s_h = hn;
            for p in &parts {
                let a = p[0] * (1.0 + mu) + 1e-12;
                s_c -= p[1] * p[1] / a;
                s_h -= p[1] * p[2] / a;
            }
            let dn = if s_c > 0.0 {
                (-s_h / s_c).clamp(-0.05, 0.05)
            } else {
                0.0
            };
            let n_new = (n + dn).max(n_min);
            let d_new: Vec<f64> = parts
                .iter()
                .zip(&d)
                .map(|(p, &di)| {
                    let a = p[0] * (1.0 + mu) + 1e-12;
                    let step = (-(p[2] + p[1] * dn) / a).clamp(-30.0, 30.0);
                    (di + step).clamp(opts.min_thickness_nm, opts.max_thickness_nm)
                })
                .collect();
            let s_new = total_sse(n_new, &d_new);
            if s_new < cur {
                let converged = (n_new - n).abs() < 1e-7 && (cur - s_new) < 1e-9 * cur;
                n = n_new;
                d = d_new;
                cur = s_new;
                mu = (mu / 3.0).max(1e-9);
                improved = !converged;
                break;
            }
            mu *= 8.0;
        }
        if !improved {
            break;
        }
    }
    (n, sigma, d)
}

/// Index scan fallback when no peak can be tracked (e.g. flat or single-fringe spectra).
fn index_scan(set: &CaptureSet, geom: &Geometry, pixels: &[usize], opts: &Options) -> Option<f64> {
    let px = Pixels::new(set);
    let (na, nb) = (set.angles.len(), set.bands());
    let sample = spread(pixels, 24);
    let data: Vec<(Vec<f32>, Vec<bool>)> = sample
        .iter()
        .map(|&p| {
            let mut y = vec![0f32; na * nb];
            let mut m = vec![false; na];
            px.get(p, &mut y, &mut m);
            (y, m)
        })
        .collect();
    let lo = opts.min_film_ior.max(geom.min_film_ior());
    let steps = ((opts.max_film_ior - lo) / 0.03).ceil().max(0.0) as usize + 1;
    (0..steps)
        .into_par_iter()
        .map(|i| {
            let n = lo + 0.03 * i as f64;
            let m = geom.model(n);
            let s = DSolver::new(&m, geom, opts);
            let total: f64 = data.iter().map(|(y, mk)| s.search(y, mk).1).sum();
            (n, total)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(n, _)| n)
}

fn full(set: &CaptureSet, opts: &Options) -> Result<Fit> {
    let geom = Geometry::from_capture(set, opts.band_integration);
    let mut stages = Stages::default();
    let mut warnings = Vec::new();
    let (n, sigma, note) = if let Some(n) = opts.film_ior {
        if n <= geom.max_kx() {
            bail!(
                "--film-ior {n} ≤ n1·sinθ = {:.4} at the largest angle: no propagating wave in the film",
                geom.max_kx()
            );
        }
        (n, None, "given (--film-ior)".to_string())
    } else {
        let t = Stopwatch::start();
        let pixels = multi_angle_pixels(set, opts);
        if pixels.is_empty() {
            bail!("no pixel is valid at two or more angles: the film index cannot be estimated");
        }
        let sub = spread(&pixels, 4096);
        let first = index_from_peaks(set, &sub, &geom);
        let n0 = match first {
            Some((n0, _, _)) if n0 > geom.min_film_ior() && n0 < 10.0 => n0,
            _ => {
                warnings.push(
                    "no peak could be tracked across angles; index from a coarse scan".into(),
                );
                index_scan(set, &geom, &sub, opts)
                    .ok_or_else(|| anyhow::anyhow!("index scan found no candidate"))?
            }
        };
        t.stop("index_from_peaks", &mut stages);
        let t = Stopwatch::start();
        let joint = spread(&pixels, opts.joint_pixels.max(1));
        let px = Pixels::new(set);
        let (na, nb) = (set.angles.len(), set.bands());
        let mut n = n0;
        let mut sigma = None;
        // Two rounds: thickness orders found with the first index may change once the
        // index is refined.
        for round in 0..2 {
            // The second round only matters when the index moved enough to change which
            // thickness order fits best (a fringe shifts by d·Δn/n); skip it otherwise.
            if round == 1 && (n - n0).abs() < 2e-3 {
                break;
            }
            let m = geom.model(n);
            let s = DSolver::with_table(&m, &geom, opts);
            let d0: Vec<f64> = joint
                .par_iter()
                .map_init(
                    || (vec![0f32; na * nb], vec![false; na]),
                    |(y, mk), &p| {
                        px.get(p, y, mk);
                        s.search(y, mk).0
                    },
                )
                .collect();
            let (n2, s2, _) = joint_refine(set, &geom, &joint, n, &d0, opts);
            n = n2;
            sigma = s2;
        }
        t.stop("joint_refinement", &mut stages);
        let note = match first {
            Some((n0, _, k)) => format!(
                "sub-band peaks: median of {k} tracks {n0:.4}; joint Gauss–Newton on {} pixels; σ from the Schur complement",
                joint.len()
            ),
            None => format!("coarse index scan; joint Gauss–Newton on {} pixels", joint.len()),
        };
        (n, sigma, note)
    };
    let t = Stopwatch::start();
    let th = fit_thickness(set, &geom, n, opts);
    t.stop("thickness", &mut stages);
    Ok(finish(
        set,
        opts,
        Method::Full,
        n,
        sigma,
        note,
        th,
        stages,
        warnings,
    ))
}

/// The fit of the rows `opts.rows` (`th` holds exactly those rows).
#[allow(clippy::too_many_arguments)]
fn finish(
    set: &CaptureSet,
    opts: &Options,
    method: Method,
    n: f64,
    sigma: Option<f64>,
    note: String,
    th: Thickness,
    stages: Stages,
    warnings: Vec<String>,
) -> Fit {
    let rows = fitted_rows(set, opts);
    let pixels = row_pixels(set, opts);
    let count = pixels.len();
    debug_assert_eq!(th.d.len(), count);
    let invalid = pixels
        .filter(|&p| !set.angles.iter().any(|a| a.valid[p]))
        .count();
    let fitted = th.d.iter().filter(|d| d.is_finite()).count();
    Fit {
        method,
        film_ior: n,
        film_ior_sigma: sigma.filter(|s| s.is_finite()),
        film_ior_note: note,
        width: set.width,
        height: rows.1 - rows.0,
        rows,
        provenance: tiles::TileInfo {
            rows,
            image_height: set.height,
            fit_hash: tiles::fit_hash(set, n, opts),
            film_ior: n,
            version: env!("CARGO_PKG_VERSION").to_string(),
        },
        unfitted_pixels: count - invalid - fitted.min(count - invalid),
        thickness_nm: th.d,
        sse: th.sse,
        samples: th.samples,
        invalid_pixels: invalid,
        stage_seconds: stages.wall,
        stage_cpu_seconds: stages.cpu,
        warnings,
    }
}

/// The seed's method as published.
fn paper(set: &CaptureSet, opts: &Options) -> Result<Fit> {
    let geom = Geometry::from_capture(set, false);
    let px = Pixels::new(set);
    let (na, nb) = (set.angles.len(), set.bands());
    let order = angle_order(set);
    let lambdas = &set.wavelengths_nm;
    let mut stages = Stages::default();
    let mut warnings = Vec::new();
    let t = Stopwatch::start();
    // Band-quantised peak per pixel and angle.
    let peaks_of = |y: &[f32], m: &[bool]| -> Vec<Option<f64>> {
        (0..na)
            .map(|a| {
                if !m[a] {
                    return None;
                }
                let ya = &y[a * nb..(a + 1) * nb];
                let sigma = peaks::noise_sigma(ya);
                peaks::band_peak(ya, lambdas, (4.0 * sigma).max(0.002)).map(|p| p.lambda_nm)
            })
            .collect()
    };
    let all: Vec<usize> = row_pixels(set, opts).collect();
    let (n, note) = if let Some(n) = opts.film_ior {
        (n, "given (--film-ior)".to_string())
    } else {
        let sub = spread(&multi_angle_pixels(set, opts), 4096);
        let mut ests: Vec<f64> = sub
            .par_iter()
            .map_init(
                || (vec![0f32; na * nb], vec![false; na]),
                |(y, m), &p| {
                    px.get(p, y, m);
                    let pk = peaks_of(y, m);
                    let mut out = Vec::new();
                    for i in 0..order.len() {
                        for j in i + 1..order.len() {
                            let (ai, ki) = order[i];
                            let (aj, kj) = order[j];
                            if let (Some(l1), Some(l2)) = (pk[ai], pk[aj]) {
                                if let Ok(n) = peaks::index_from_pair(l1, ki, l2, kj) {
                                    out.push(n);
                                }
                            }
                        }
                    }
                    out
                },
            )
            .flatten()
            .collect();
        let k = ests.len();
        let n = median(&mut ests).ok_or_else(|| {
            anyhow::anyhow!(
                "paper method: no pixel has peaks at two angles that satisfy eq. (12) \
                 (flat or peak-less spectra, or λ1 = λ2); try --method full or --film-ior"
            )
        })?;
        (
            n,
            format!("eq. (12): median over {k} angle pairs of band-quantised peaks"),
        )
    };
    if n <= geom.max_kx() {
        bail!("paper method: index {n} ≤ n1 sinθ: eq. (13) has no real solution");
    }
    t.stop("index_eq12", &mut stages);
    let t = Stopwatch::start();
    let m = geom.model(n);
    let pb = progress_bar(opts, all.len(), "thickness");
    let res: Vec<(f32, f32, u32)> = all
        .par_iter()
        .map_init(
            || (vec![0f32; na * nb], vec![false; na]),
            |(y, mk), &p| {
                let used = px.get(p, y, mk);
                if used == 0 {
                    return (f32::NAN, 0.0, 0);
                }
                let pk = peaks_of(y, mk);
                // Eq. (13) per angle with integer m; eq. (14) picks m.
                let mut best = (f64::NAN, f64::INFINITY);
                for order_m in 1..200 {
                    let mut sum = 0.0;
                    let mut cnt = 0;
                    for &(a, kx) in &order {
                        if let Some(l) = pk[a] {
                            sum += order_m as f64 * l / (2.0 * (n * n - kx * kx).sqrt());
                            cnt += 1;
                        }
                    }
                    if cnt == 0 {
                        break;
                    }
                    let d = sum / cnt as f64;
                    if d > opts.max_thickness_nm {
                        break;
                    }
                    let s = m.sse(d, y, mk, 1);
                    if s < best.1 {
                        best = (d, s);
                    }
                }
                (best.0 as f32, best.1 as f32, (used * nb) as u32)
            },
        )
        .inspect(|_| pb.inc(1))
        .collect();
    pb.finish_and_clear();
    let nopeak = res.iter().filter(|r| r.2 > 0 && !r.0.is_finite()).count();
    if nopeak > 0 {
        warnings.push(format!(
            "{nopeak} pixels had no peak at any angle: no thickness (eq. 13 needs a peak)"
        ));
    }
    t.stop("thickness_eq13_14", &mut stages);
    let th = Thickness {
        d: res.iter().map(|r| r.0).collect(),
        sse: res
            .iter()
            .map(|r| if r.0.is_finite() { r.1 } else { 0.0 })
            .collect(),
        samples: res.iter().map(|r| r.2).collect(),
    };
    Ok(finish(
        set,
        opts,
        Method::Paper,
        n,
        None,
        note,
        th,
        stages,
        warnings,
    ))
}

/// Exhaustive grid: for every n, every pixel's best d on the thickness grid; n minimises
/// the total residual (seed §4's O(m n²) baseline).
fn grid(set: &CaptureSet, opts: &Options) -> Result<Fit> {
    let geom = Geometry::from_capture(set, opts.band_integration);
    let px = Pixels::new(set);
    let (na, nb) = (set.angles.len(), set.bands());
    let w = set.width;
    let mut stages = Stages::default();
    let d_steps = ((opts.max_thickness_nm - opts.min_thickness_nm) / opts.grid_thickness_step_nm)
        .floor() as usize
        + 1;
    let d_at = |i: usize| opts.min_thickness_nm + i as f64 * opts.grid_thickness_step_nm;
    let best_d = |m: &FilmModel, y: &[f32], mk: &[bool]| -> (f64, f64) {
        (0..d_steps)
            .map(|i| (d_at(i), m.sse(d_at(i), y, mk, 1)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((f64::NAN, f64::INFINITY))
    };
    let t = Stopwatch::start();
    let (n, note) = if let Some(n) = opts.film_ior {
        (n, "given (--film-ior)".to_string())
    } else {
        let stride = opts.grid_pixel_stride.max(1);
        let (r0, r1) = fitted_rows(set, opts);
        let sub: Vec<usize> = (r0..r1)
            .step_by(stride)
            .flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x))
            .filter(|&p| set.angles.iter().filter(|a| a.valid[p]).count() >= 2)
            .collect();
        if sub.is_empty() {
            bail!("grid: no pixel valid at two angles");
        }
        let data: Vec<(Vec<f32>, Vec<bool>)> = sub
            .iter()
            .map(|&p| {
                let mut y = vec![0f32; na * nb];
                let mut m = vec![false; na];
                px.get(p, &mut y, &mut m);
                (y, m)
            })
            .collect();
        let lo = opts.min_film_ior.max(geom.min_film_ior());
        let n_steps = ((opts.max_film_ior - lo) / opts.grid_ior_step)
            .floor()
            .max(0.0) as usize
            + 1;
        let pb = progress_bar(opts, n_steps, "grid n");
        let mut best = (f64::NAN, f64::INFINITY);
        for i in 0..n_steps {
            let n = lo + i as f64 * opts.grid_ior_step;
            let m = geom.model(n);
            let total: f64 = data.par_iter().map(|(y, mk)| best_d(&m, y, mk).1).sum();
            if total < best.1 {
                best = (n, total);
            }
            pb.inc(1);
        }
        pb.finish_and_clear();
        (
            best.0,
            format!(
                "grid: n step {} over [{lo:.3}, {:.3}], d step {} nm, {} pixels",
                opts.grid_ior_step,
                opts.max_film_ior,
                opts.grid_thickness_step_nm,
                sub.len()
            ),
        )
    };
    t.stop("index_grid", &mut stages);
    let t = Stopwatch::start();
    let m = geom.model(n);
    let res: Vec<(f32, f32, u32)> = row_pixels(set, opts)
        .into_par_iter()
        .map_init(
            || (vec![0f32; na * nb], vec![false; na]),
            |(y, mk), p| {
                let used = px.get(p, y, mk);
                if used == 0 {
                    return (f32::NAN, 0.0, 0);
                }
                let (d, s) = best_d(&m, y, mk);
                (d as f32, s as f32, (used * nb) as u32)
            },
        )
        .collect();
    t.stop("thickness_grid", &mut stages);
    let th = Thickness {
        d: res.iter().map(|r| r.0).collect(),
        sse: res.iter().map(|r| r.1).collect(),
        samples: res.iter().map(|r| r.2).collect(),
    };
    let sigma = Some(opts.grid_ior_step / 12f64.sqrt());
    Ok(finish(
        set,
        opts,
        Method::Grid,
        n,
        sigma,
        note,
        th,
        stages,
        Vec::new(),
    ))
}
