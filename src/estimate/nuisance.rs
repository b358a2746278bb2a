//! The nuisance model: what a real capture leaves unknown besides the film.
//!
//! A measured spectrum of pixel p at angle a is modelled as
//!
//!   y_pab = g_pa · s_a(λ_b) · R_ab(d_p) + c_a(λ_b) + noise(σ_ab),
//!
//! - g_pa ≥ 0: a gain per pixel and angle (exposure, vignetting, the unknown scale of a
//!   specular reflection against a diffuse white reference). Eliminated analytically in
//!   every fit ([`super::table::GainMode::Free`]); fixed to 1 when the capture declares
//!   absolute radiometry.
//! - s_a(λ) = 1 + Σ_k α_ak P_k(x): a smooth spectral multiplier per angle (lamp drift,
//!   camera response residual), Legendre polynomials P_k of x ∈ [−1, 1] across the band.
//! - c_a(λ) = Σ_j β_aj P_j(x): an additive background per angle (stray light, dark offset).
//! - σ_ab: the noise per angle and band, estimated from the data ([`super::noise`]).
//!
//! Fits work in whitened units: data ỹ = (y − c)/σ and model m̃ = s·R/σ, so that every
//! stage only sees "data", "model" and a free or unit gain. How many α and β terms a
//! capture gets is chosen by the joint stage with an information criterion.

/// Legendre polynomial P_k(x) (Bonnet's recursion).
#[inline]
pub fn legendre(k: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, x);
    match k {
        0 => 1.0,
        1 => x,
        _ => {
            for n in 1..k {
                let p2 = ((2 * n + 1) as f64 * x * p1 - n as f64 * p0) / (n + 1) as f64;
                p0 = p1;
                p1 = p2;
            }
            p1
        }
    }
}

/// Which nuisance terms a fit has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NuisanceSpec {
    /// Free gain per pixel and angle (false: absolute radiometry).
    pub free_gain: bool,
    /// Number of multiplier terms per angle (P_1..P_K; 0 = flat).
    pub multiplier_terms: usize,
    /// Number of background terms per angle (P_0..P_{J−1}; 0 = none).
    pub background_terms: usize,
}

impl NuisanceSpec {
    /// Absolute radiometry: nothing but the film.
    pub const ABSOLUTE: NuisanceSpec = NuisanceSpec {
        free_gain: false,
        multiplier_terms: 0,
        background_terms: 0,
    };

    /// The smallest model a capture of this radiometry allows: the film alone for
    /// calibrated reflectance, a free gain per pixel and angle otherwise.
    pub fn smallest(radiometry: crate::capture::Radiometry) -> NuisanceSpec {
        NuisanceSpec {
            free_gain: radiometry != crate::capture::Radiometry::Absolute,
            ..NuisanceSpec::ABSOLUTE
        }
    }

    /// Global parameters per angle.
    pub fn per_angle(&self) -> usize {
        self.multiplier_terms + self.background_terms
    }

    /// "gain per pixel+angle, multiplier order 2, constant background".
    pub fn describe(&self) -> String {
        let mut parts = vec![if self.free_gain {
            "free gain per pixel and angle".to_string()
        } else {
            "absolute scale".to_string()
        }];
        if self.multiplier_terms > 0 {
            parts.push(format!(
                "spectral multiplier of degree {} per angle",
                self.multiplier_terms
            ));
        }
        match self.background_terms {
            0 => {}
            1 => parts.push("constant background per angle".into()),
            j => parts.push(format!("background of degree {} per angle", j - 1)),
        }
        parts.join(", ")
    }
}

/// Nuisance parameters of every angle (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct Nuisance {
    pub spec: NuisanceSpec,
    /// Per angle: α_1..α_K.
    pub multiplier: Vec<Vec<f64>>,
    /// Per angle: β_0..β_{J−1}.
    pub background: Vec<Vec<f64>>,
    /// Band positions x_b ∈ [−1, 1].
    x: Vec<f64>,
}

impl Nuisance {
    /// All terms zero (multiplier 1, no background).
    pub fn new(spec: NuisanceSpec, angles: usize, wavelengths_nm: &[f64]) -> Self {
        let lo = wavelengths_nm.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = wavelengths_nm.iter().copied().fold(0.0, f64::max);
        let half = ((hi - lo) / 2.0).max(1e-9);
        Nuisance {
            spec,
            multiplier: vec![vec![0.0; spec.multiplier_terms]; angles],
            background: vec![vec![0.0; spec.background_terms]; angles],
            x: wavelengths_nm
                .iter()
                .map(|l| (l - (lo + half)) / half)
                .collect(),
        }
    }

    /// The same values under another spec (common terms kept, new ones zero).
    pub fn with_spec(&self, spec: NuisanceSpec) -> Self {
        let mut n = self.clone();
        n.spec = spec;
        for m in &mut n.multiplier {
            m.resize(spec.multiplier_terms, 0.0);
        }
        for b in &mut n.background {
            b.resize(spec.background_terms, 0.0);
        }
        n
    }

    pub fn bands(&self) -> usize {
        self.x.len()
    }

    /// Multiplier basis k (1-based term k + 1) at band b: ∂s/∂α_{k+1}.
    #[inline]
    pub fn multiplier_basis(&self, k: usize, b: usize) -> f64 {
        legendre(k + 1, self.x[b])
    }

    /// Background basis j at band b: ∂c/∂β_j.
    #[inline]
    pub fn background_basis(&self, j: usize, b: usize) -> f64 {
        legendre(j, self.x[b])
    }

    /// s_a(λ_b).
    pub fn multiplier_at(&self, a: usize, b: usize) -> f64 {
        1.0 + self.multiplier[a]
            .iter()
            .enumerate()
            .map(|(k, v)| v * self.multiplier_basis(k, b))
            .sum::<f64>()
    }

    /// c_a(λ_b).
    pub fn background_at(&self, a: usize, b: usize) -> f64 {
        self.background[a]
            .iter()
            .enumerate()
            .map(|(j, v)| v * self.background_basis(j, b))
            .sum()
    }

    /// Global parameters as one vector (angle-major: multiplier terms, then background).
    pub fn to_vec(&self) -> Vec<f64> {
        let mut v = Vec::new();
        for a in 0..self.multiplier.len() {
            v.extend_from_slice(&self.multiplier[a]);
            v.extend_from_slice(&self.background[a]);
        }
        v
    }

    /// Inverse of [`Nuisance::to_vec`].
    pub fn from_vec(&self, v: &[f64]) -> Self {
        let mut n = self.clone();
        let (k, j) = (self.spec.multiplier_terms, self.spec.background_terms);
        for a in 0..self.multiplier.len() {
            let o = a * (k + j);
            n.multiplier[a].copy_from_slice(&v[o..o + k]);
            n.background[a].copy_from_slice(&v[o + k..o + k + j]);
        }
        n
    }
}

/// Per angle and band: data offset (background) and scale (1/σ, times the multiplier for
/// the model side) in padded rows, applied to a pixel's raw spectra before a fit.
#[derive(Debug, Clone)]
pub struct Whitening {
    pub stride: usize,
    /// c_ab per padded sample.
    pub offset: Vec<f32>,
    /// 1/σ_ab per padded sample (0 in the padding).
    pub weight: Vec<f32>,
}

impl Whitening {
    /// From the background of `nuisance` and the noise `sigma` (angles × bands).
    pub fn new(nuisance: &Nuisance, sigma: &[f32], angles: usize, stride: usize) -> Self {
        let nb = nuisance.bands();
        let mut offset = vec![0f32; angles * stride];
        let mut weight = vec![0f32; angles * stride];
        for a in 0..angles {
            for b in 0..nb {
                offset[a * stride + b] = nuisance.background_at(a, b) as f32;
                weight[a * stride + b] = 1.0 / sigma[a * nb + b];
            }
        }
        Whitening {
            stride,
            offset,
            weight,
        }
    }

    /// ỹ = (y − c)·w on the angles in `mask` (others zeroed); returns Σỹ² per angle in `yy`.
    #[inline]
    pub fn apply(&self, y: &mut [f32], mask: &[bool], yy: &mut [f32]) {
        let s = self.stride;
        for (a, (&m, e)) in mask.iter().zip(yy.iter_mut()).enumerate() {
            let row = &mut y[a * s..(a + 1) * s];
            if !m {
                row.iter_mut().for_each(|v| *v = 0.0);
                *e = 0.0;
                continue;
            }
            let (o, w) = (
                &self.offset[a * s..(a + 1) * s],
                &self.weight[a * s..(a + 1) * s],
            );
            // Eight partial sums (rows are padded to a multiple of 8): one running f32 sum
            // was a chain of dependent adds, ~1 CPU-ns per sample over a megapixel's fit.
            let mut acc = [0f32; 8];
            let lanes = row.chunks_exact_mut(8).zip(o.chunks_exact(8));
            for ((v, o), w) in lanes.zip(w.chunks_exact(8)) {
                for k in 0..8 {
                    v[k] = (v[k] - o[k]) * w[k];
                    acc[k] += v[k] * v[k];
                }
            }
            *e = ((acc[0] + acc[4]) + (acc[2] + acc[6])) + ((acc[1] + acc[5]) + (acc[3] + acc[7]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_matches_closed_forms_and_vector_round_trips() {
        for &x in &[-1.0, -0.3, 0.0, 0.7, 1.0] {
            assert!((legendre(2, x) - 0.5 * (3.0 * x * x - 1.0)).abs() < 1e-12);
            assert!((legendre(3, x) - 0.5 * (5.0 * x * x * x - 3.0 * x)).abs() < 1e-12);
            assert!((legendre(5, 1.0) - 1.0).abs() < 1e-12);
        }
        let spec = NuisanceSpec {
            free_gain: true,
            multiplier_terms: 2,
            background_terms: 1,
        };
        let wl: Vec<f64> = (0..11).map(|i| 400.0 + 32.0 * i as f64).collect();
        let mut n = Nuisance::new(spec, 3, &wl);
        let v: Vec<f64> = (0..9).map(|i| 0.01 * i as f64).collect();
        n = n.from_vec(&v);
        assert_eq!(n.to_vec(), v);
        // x spans [−1, 1]: s at the red end = 1 + α1 + α2.
        assert!((n.multiplier_at(1, 10) - (1.0 + 0.03 + 0.04)).abs() < 1e-12);
        assert!((n.background_at(2, 4) - 0.08).abs() < 1e-12);
        let w = Whitening::new(&n, &[0.5; 33], 3, 16);
        let mut y = vec![1.0f32; 48];
        let mut yy = [0f32; 3];
        w.apply(&mut y, &[true, false, true], &mut yy);
        // Angle 0: background β = 0.02, weight 1/0.5.
        assert!((y[0] - 1.96).abs() < 1e-6 && y[16] == 0.0 && y[11] == 0.0);
        assert!((yy[0] - 11.0 * 1.96f32.powi(2)).abs() < 1e-3 && yy[1] == 0.0);
    }
}
