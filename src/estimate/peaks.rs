//! Peak wavelengths of a reflectance spectrum (seed §4: maxima where the optical path
//! difference is a whole — or, when n2 > n3, half — number of wavelengths).
//!
//! Two flavours: the seed's band-quantised maximum (the peak wavelength is a band centre,
//! which limits Sample 3 — `docs/physics-and-formats.md`, "Thin-film physics"), and sub-band localisation by a least-squares
//! parabola through the samples around each maximum.

/// One detected maximum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    pub lambda_nm: f64,
    /// Height above the higher of the two flanking valleys (reflectance units).
    pub prominence: f64,
}

/// Robust noise estimate of a spectrum: MAD of second differences, scaled to σ of white
/// noise (a second difference of white noise has variance 6σ²).
pub fn noise_sigma(y: &[f32]) -> f64 {
    if y.len() < 3 {
        return 0.0;
    }
    let mut d: Vec<f64> = y
        .windows(3)
        .map(|w| (w[0] as f64 - 2.0 * w[1] as f64 + w[2] as f64).abs())
        .collect();
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m / 0.6745 / 6f64.sqrt()
}

/// Moving average of odd width `w` (shrinking at the ends).
fn smooth(y: &[f32], w: usize) -> Vec<f64> {
    let h = w / 2;
    (0..y.len())
        .map(|i| {
            let lo = i.saturating_sub(h);
            let hi = (i + h + 1).min(y.len());
            y[lo..hi].iter().map(|&v| v as f64).sum::<f64>() / (hi - lo) as f64
        })
        .collect()
}

/// Interior local maxima of `s` with their prominence.
fn maxima(s: &[f64]) -> Vec<(usize, f64)> {
    let n = s.len();
    let mut out = Vec::new();
    for i in 1..n.saturating_sub(1) {
        // Plateaus: count the first sample of a flat top once.
        if !(s[i] > s[i - 1] && s[i] >= s[i + 1]) {
            continue;
        }
        let mut left_min = s[i];
        let mut j = i;
        while j > 0 {
            j -= 1;
            if s[j] > s[i] {
                break;
            }
            left_min = left_min.min(s[j]);
        }
        let mut right_min = s[i];
        let mut j = i;
        while j + 1 < n {
            j += 1;
            if s[j] > s[i] {
                break;
            }
            right_min = right_min.min(s[j]);
        }
        out.push((i, s[i] - left_min.max(right_min)));
    }
    out
}

fn mean_spacing(l: &[f64]) -> f64 {
    if l.len() < 2 {
        return 1.0;
    }
    ((l[l.len() - 1] - l[0]) / (l.len() - 1) as f64)
        .abs()
        .max(1e-6)
}

/// The seed's peak: the band centre of the most prominent maximum (3-band smoothing against
/// noise), or `None` when the spectrum has no interior maximum above `min_prominence`.
pub fn band_peak(y: &[f32], lambdas: &[f64], min_prominence: f64) -> Option<Peak> {
    let s = smooth(y, 3);
    maxima(&s)
        .into_iter()
        .filter(|&(_, p)| p > min_prominence)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, p)| Peak {
            lambda_nm: lambdas[i],
            prominence: p,
        })
}

/// All maxima above `min_prominence`, each located below the band spacing by a
/// least-squares parabola through the raw samples within ±`half_window_nm` (at least ±1
/// band) of the smoothed maximum.
pub fn subband_peaks(
    y: &[f32],
    lambdas: &[f64],
    min_prominence: f64,
    half_window_nm: f64,
) -> Vec<Peak> {
    let n = y.len();
    if n < 5 {
        return Vec::new();
    }
    let dl = mean_spacing(lambdas);
    // Smooth over ~12 nm: enough to suppress σ≈0.004 noise, far below a fringe width.
    let w = ((12.0 / dl).round() as usize).max(1) | 1;
    let s = smooth(y, w);
    let h = ((half_window_nm / dl).round() as usize).max(1);
    let mut out = Vec::new();
    for (i, prom) in maxima(&s) {
        if prom <= min_prominence {
            continue;
        }
        let lo = i.saturating_sub(h);
        let hi = (i + h + 1).min(n);
        if hi - lo < 3 {
            continue;
        }
        let x0 = lambdas[i];
        // Normal equations of y = a + b x + c x² (x in units of the band spacing).
        let mut m = [[0.0f64; 3]; 3];
        let mut v = [0.0f64; 3];
        for j in lo..hi {
            let x = (lambdas[j] - x0) / dl;
            let yj = y[j] as f64;
            if !yj.is_finite() {
                continue;
            }
            let pw = [1.0, x, x * x];
            for r in 0..3 {
                for c in 0..3 {
                    m[r][c] += pw[r] * pw[c];
                }
                v[r] += pw[r] * yj;
            }
        }
        let lambda = match solve3(m, v) {
            Some([_, b, c]) if c < 0.0 => {
                let xv = -b / (2.0 * c);
                if xv.abs() <= h as f64 + 0.5 {
                    x0 + xv * dl
                } else {
                    x0
                }
            }
            _ => x0,
        };
        out.push(Peak {
            lambda_nm: lambda,
            prominence: prom,
        });
    }
    out
}

/// Cramer's rule for a 3×3 system; `None` when singular.
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    if d.abs() < 1e-12 {
        return None;
    }
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut mk = m;
        for r in 0..3 {
            mk[r][k] = v[r];
        }
        *o = det(mk) / d;
    }
    Some(out)
}

/// Why eq. (12) gives no index for a pair of peaks.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Eq12Error {
    #[error("equal peak wavelengths (λ1 = λ2): eq. (12) divides by λ2² − λ1² = 0")]
    EqualWavelengths,
    #[error("equal incident angles: the pair carries no index information")]
    EqualAngles,
    #[error("eq. (12) gives n² ≤ sin²θ (no propagating film wave): peaks mismatched or noisy")]
    NoRealIndex,
}

/// Seed eq. (12): n² = (λ2² sin²θ1 − λ1² sin²θ2) / (λ2² − λ1²), for the same order m seen at
/// two angles (ambient index `n1` folded into sinθ: n1 sinθ1 = n2 sinθ2).
pub fn index_from_pair(lambda1: f64, kx1: f64, lambda2: f64, kx2: f64) -> Result<f64, Eq12Error> {
    if (kx1 - kx2).abs() < 1e-12 {
        return Err(Eq12Error::EqualAngles);
    }
    let den = lambda2 * lambda2 - lambda1 * lambda1;
    if den.abs() < 1e-9 * lambda1 * lambda1 {
        return Err(Eq12Error::EqualWavelengths);
    }
    let n2 = (lambda2 * lambda2 * kx1 * kx1 - lambda1 * lambda1 * kx2 * kx2) / den;
    if !(n2.is_finite() && n2 > kx1 * kx1 && n2 > kx2 * kx2) {
        return Err(Eq12Error::NoRealIndex);
    }
    Ok(n2.sqrt())
}

/// All-angle generalisation of eq. (12) for one peak order tracked over K ≥ 2 angles:
/// λ_k² = C (n² − kx_k²) is linear in kx_k², so a line fit λ² = α + β kx² gives
/// n² = −α/β (β = −C < 0). With two angles this is exactly eq. (12).
pub fn index_from_track(track: &[(f64, f64)]) -> Result<f64, Eq12Error> {
    if track.len() == 2 {
        return index_from_pair(track[0].1, track[0].0, track[1].1, track[1].0);
    }
    let k = track.len() as f64;
    let (mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0);
    for &(kx, lambda) in track {
        let x = kx * kx;
        let y = lambda * lambda;
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    let den = k * sxx - sx * sx;
    if den.abs() < 1e-15 {
        return Err(Eq12Error::EqualAngles);
    }
    let beta = (k * sxy - sx * sy) / den;
    let alpha = (sy - beta * sx) / k;
    if beta.abs() < 1e-12 * alpha.abs() {
        return Err(Eq12Error::EqualWavelengths);
    }
    let n2 = -alpha / beta;
    let kmax = track.iter().map(|t| t.0).fold(0.0, f64::max);
    if !(n2.is_finite() && beta < 0.0 && n2 > kmax * kmax) {
        return Err(Eq12Error::NoRealIndex);
    }
    Ok(n2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq12_recovers_index_and_refuses_degenerate_pairs() {
        let (n, d) = (1.37f64, 400.0);
        let s1 = 10f64.to_radians().sin();
        let s2 = 40f64.to_radians().sin();
        let l1 = 2.0 * d * (n * n - s1 * s1).sqrt() / 2.0;
        let l2 = 2.0 * d * (n * n - s2 * s2).sqrt() / 2.0;
        assert!((index_from_pair(l1, s1, l2, s2).unwrap() - n).abs() < 1e-12);
        assert_eq!(
            index_from_pair(500.0, s1, 500.0, s2),
            Err(Eq12Error::EqualWavelengths)
        );
        assert_eq!(
            index_from_pair(500.0, s1, 520.0, s1),
            Err(Eq12Error::EqualAngles)
        );
        // Peak moving red with angle → n² < sin²θ: refused, never NaN.
        assert_eq!(
            index_from_pair(500.0, s1, 520.0, s2),
            Err(Eq12Error::NoRealIndex)
        );
        let track: Vec<(f64, f64)> = [10.0f64, 20.0, 30.0, 40.0, 50.0]
            .iter()
            .map(|a| {
                let s = a.to_radians().sin();
                (s, 2.0 * d * (n * n - s * s).sqrt() / 3.5)
            })
            .collect();
        assert!((index_from_track(&track).unwrap() - n).abs() < 1e-9);
    }

    #[test]
    fn subband_peak_beats_band_quantisation() {
        let lambdas: Vec<f64> = (0..81).map(|i| 400.0 + 4.0 * i as f64).collect();
        let truth = 541.3;
        let y: Vec<f32> = lambdas
            .iter()
            .map(|&l| (0.05 * (-((l - truth) / 40.0).powi(2)).exp()) as f32)
            .collect();
        let p = subband_peaks(&y, &lambdas, 0.01, 10.0);
        assert_eq!(p.len(), 1);
        assert!((p[0].lambda_nm - truth).abs() < 0.3, "{}", p[0].lambda_nm);
        let b = band_peak(&y, &lambdas, 0.01).unwrap();
        assert!((b.lambda_nm - 540.0).abs() < 1e-9);
        // Flat and monotonic spectra have no peak.
        let flat = vec![0.04f32; 81];
        assert!(subband_peaks(&flat, &lambdas, 0.001, 10.0).is_empty());
        assert!(band_peak(&flat, &lambdas, 0.001).is_none());
        let ramp: Vec<f32> = (0..81).map(|i| i as f32 * 1e-3).collect();
        assert!(band_peak(&ramp, &lambdas, 0.001).is_none());
        assert!(noise_sigma(&flat) == 0.0);
    }
}
