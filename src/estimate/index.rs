//! Index stage of `full`: sub-band peak wavelengths ([`super::peaks`]) tracked from angle
//! to angle, each order separately, give the index through eq. (12) generalised to all
//! angles of a track; the median over tracks is the first estimate. Peak wavelengths do
//! not depend on the gain or background of a spectrum (the seed's reason for using them),
//! so this stage is robust to everything the nuisance model later absorbs. Without
//! trackable peaks (less than a fringe, flat spectra), a coarse index scan on a few
//! pixels takes over.

use super::data::{median, spread, PixelData};
use super::film::FilmIndex;
use super::nuisance::{Nuisance, NuisanceSpec, Whitening};
use super::peaks;
use super::solver::{FixedModel, ThicknessSolver};
use super::stage::{Context, IndexEstimate, IndexStage};
use crate::capture::CaptureSet;
use anyhow::Result;
use rayon::prelude::*;

/// The `full` method's index stage.
pub struct PeaksIndex;

impl IndexStage for PeaksIndex {
    fn run(&self, cx: &Context) -> Result<IndexEstimate> {
        let pixels = cx.obs.pixels_with_angles(2);
        if pixels.is_empty() {
            anyhow::bail!(
                "no pixel is valid at two or more angles: the film index cannot be estimated"
            );
        }
        let sub = spread(&pixels, 4096);
        let tracks = peak_tracks(cx, &sub);
        let mut ns: Vec<f64> = tracks.iter().map(|t| t.1).collect();
        match median(&mut ns) {
            Some(n0) if n0 > cx.obs.geom.min_film_ior() && n0 < 10.0 => Ok(IndexEstimate {
                film: FilmIndex::constant(n0),
                sigma: None,
                note: format!("sub-band peaks: median of {} tracks {n0:.4}", tracks.len()),
                dispersive_start: dispersion_from_tracks(&tracks, &cx.obs.geom),
            }),
            _ => {
                cx.warn("no peak could be tracked across angles; first index from a coarse scan");
                let n = index_scan(cx, &sub)
                    .ok_or_else(|| anyhow::anyhow!("index scan found no candidate"))?;
                Ok(IndexEstimate {
                    film: FilmIndex::constant(n),
                    sigma: None,
                    note: format!("coarse index scan {n:.3}"),
                    dispersive_start: None,
                })
            }
        }
    }
}

/// Angle order by increasing n1 sinθ (peaks move to shorter wavelengths along it).
pub fn angle_order(set: &CaptureSet) -> Vec<(usize, f64)> {
    let mut v: Vec<(usize, f64)> = set
        .angles
        .iter()
        .enumerate()
        .map(|(i, a)| (i, set.ambient_ior * a.incident_deg.to_radians().sin()))
        .collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    v
}

/// Sub-band peaks tracked over angles: (mean wavelength, eq. (12) index) per track.
fn peak_tracks(cx: &Context, pixels: &[usize]) -> Vec<(f64, f64)> {
    let obs = &cx.obs;
    let (na, nb, s) = (obs.angles, obs.bands, obs.stride);
    let order = angle_order(obs.set);
    let n_lo = obs.geom.min_film_ior().max(1.05);
    let lambdas = &obs.geom.wavelengths_nm;
    pixels
        .par_iter()
        .map_init(
            || (vec![0f32; na * s], vec![false; na]),
            |(y, m), &p| {
                obs.get(p, y, m);
                // Peaks per angle (in kx order).
                let per_angle: Vec<(f64, Vec<peaks::Peak>)> = order
                    .iter()
                    .filter(|(a, _)| m[*a])
                    .map(|&(a, kx)| {
                        let ya = &y[a * s..a * s + nb];
                        let sigma = peaks::noise_sigma(ya);
                        // Scale-free floor: 2 % of the spectrum's largest value (0.002 for
                        // a film whose reflectance peaks at 0.1).
                        let top = ya.iter().fold(0f32, |a, &v| a.max(v.abs())) as f64;
                        (
                            kx,
                            peaks::subband_peaks(ya, lambdas, (4.0 * sigma).max(0.02 * top), 10.0),
                        )
                    })
                    .collect();
                tracks(&per_angle, n_lo)
            },
        )
        .flatten()
        .collect()
}

/// A dispersive first guess from how the tracks' index changes with wavelength. For a
/// dispersive film, eq. (12) on a peak's shift with angle measures √(n·n_g) (n_g = n − λ
/// dn/dλ, the group index) instead of n: differentiating mλ = 2d√(n(λ)² − kx²) along a
/// track gives dλ/dkx² = −λ / (2 (n² − λ n n' − kx²)). With Cauchy's n = A + B/λ²,
/// n·n_g = (A + B/λ²)(A + 3B/λ²); (A, B) are fitted to the medians of the tracks in six
/// wavelength bins. `None` without enough tracks spread over the band or when the fit
/// finds no dispersion.
fn dispersion_from_tracks(
    tracks: &[(f64, f64)],
    geom: &super::model::Geometry,
) -> Option<FilmIndex> {
    if tracks.len() < 12 {
        return None;
    }
    let mut t = tracks.to_vec();
    t.sort_by(|a, b| a.0.total_cmp(&b.0));
    let span = geom.lambda_max() - geom.lambda_min();
    if t[t.len() - 1].0 - t[0].0 < 0.15 * span {
        return None;
    }
    let bins = 6;
    let pts: Vec<(f64, f64)> = (0..bins)
        .filter_map(|i| {
            let chunk = &t[i * t.len() / bins..(i + 1) * t.len() / bins];
            let mut l: Vec<f64> = chunk.iter().map(|c| c.0).collect();
            let mut n: Vec<f64> = chunk.iter().map(|c| c.1).collect();
            Some((median(&mut l)?, median(&mut n)?.powi(2)))
        })
        .collect();
    // Gauss–Newton on (A, B) for v = (A + B u)(A + 3 B u), u = 1/λ².
    let mut a = pts.iter().map(|p| p.1.sqrt()).sum::<f64>() / pts.len() as f64;
    let mut b = 0.0;
    for _ in 0..20 {
        let (mut h, mut g) = ([0.0; 3], [0.0; 2]);
        for &(l, v) in &pts {
            let u = 1.0 / (l * l);
            let (n, ng) = (a + b * u, a + 3.0 * b * u);
            let e = n * ng - v;
            let (ja, jb) = (n + ng, u * ng + 3.0 * u * n);
            h[0] += ja * ja;
            h[1] += ja * jb;
            h[2] += jb * jb;
            g[0] += ja * e;
            g[1] += jb * e;
        }
        let det = h[0] * h[2] - h[1] * h[1];
        if !(det.abs() > 0.0) {
            return None;
        }
        let da = -(h[2] * g[0] - h[1] * g[1]) / det;
        let db = -(h[0] * g[1] - h[1] * g[0]) / det;
        a += da;
        b += db;
        if da.abs() < 1e-9 && db.abs() < 1e-3 {
            break;
        }
    }
    let r = super::film::REFERENCE_NM;
    // Normal dispersion only, and at least 0.002 change of n over the band.
    let change = b * (1.0 / geom.lambda_min().powi(2) - 1.0 / geom.lambda_max().powi(2));
    (a.is_finite() && b.is_finite() && b > 0.0 && change > 0.002).then(|| FilmIndex::Fitted {
        kind: super::film::FilmModelKind::Cauchy,
        p: vec![a + b / (r * r), b / (r * r)],
    })
}

/// (mean wavelength, index) of every peak track of one pixel.
fn tracks(per_angle: &[(f64, Vec<peaks::Peak>)], n_lo: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
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
            let (mut lam, mut kx) = (pk.lambda_nm, per_angle[start].0);
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
                    let l = track.iter().map(|t| t.1).sum::<f64>() / track.len() as f64;
                    out.push((l, n));
                }
            }
        }
    }
    out
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
    let here = (
        kx,
        vec![peaks::Peak {
            lambda_nm: lambda,
            prominence: 0.0,
        }],
    );
    prev.1
        .iter()
        .map(|p| p.lambda_nm)
        .find(|&l0| track_next(prev.0, l0, &here, n_lo).is_some())
}

/// Index scan fallback when no peak can be tracked: the index whose best thicknesses fit
/// a few pixels best, every 0.03 over the searched range.
fn index_scan(cx: &Context, pixels: &[usize]) -> Option<f64> {
    let obs = &cx.obs;
    let sample = spread(pixels, 16);
    let spec = NuisanceSpec::smallest(obs.radiometry);
    let nuisance = Nuisance::new(spec, obs.angles, &obs.geom.wavelengths_nm);
    let white = Whitening::new(&nuisance, &cx.noise.sigma, obs.angles, obs.stride);
    let lo = cx.opts.min_film_ior.max(obs.geom.min_film_ior());
    let steps = ((cx.opts.max_film_ior - lo) / 0.03).ceil().max(0.0) as usize + 1;
    (0..steps)
        .map(|i| {
            let film = FilmIndex::constant(lo + 0.03 * i as f64);
            let fixed = FixedModel {
                geom: &obs.geom,
                film: &film,
                substrate_shift: 0.0,
                nuisance: &nuisance,
                sigma: &cx.noise.sigma,
            };
            let solver = ThicknessSolver::new(
                &fixed,
                cx.opts.min_thickness_nm,
                cx.opts.max_thickness_nm,
                true,
            );
            // Collected, then added in pixel order: the same total in every run (a parallel
            // sum adds in the order work happened to be split).
            let per_pixel: Vec<f64> = sample
                .par_iter()
                .map_init(
                    || PixelData::new(obs),
                    |px, &p| {
                        px.load(obs, &white, &film, p);
                        solver.search(px).1
                    },
                )
                .collect();
            let total: f64 = per_pixel.iter().sum();
            (film.n550(), total)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(n, _)| n)
}
