//! In-memory synthetic capture sets for the estimator's tests and benchmark: the exact
//! f64 Airy film ([`crate::optics::ThinFilm`]), optional Gaussian band integration, and
//! seeded Gaussian noise. (File-based captures come from `thinfilm simulate`.)

use crate::capture::{AngleCapture, CaptureSet, InvalidCounts, Polarization};
use crate::optics::{Complex64, Ior, ThinFilm};

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SynthSpec {
    pub film_ior: f64,
    pub substrate_ior: Ior,
    pub ambient_ior: f64,
    pub mean_thickness_nm: f64,
    /// Peak-to-peak variation of the smooth thickness field, nm.
    pub thickness_variation_nm: f64,
    pub width: usize,
    pub height: usize,
    pub wavelengths_nm: Vec<f64>,
    /// Gaussian band FWHM (integrated when given).
    pub fwhm_nm: Option<f64>,
    pub incident_deg: Vec<f64>,
    pub polarization: Polarization,
    pub noise_sigma: f64,
    pub seed: u64,
}

impl SynthSpec {
    /// The seed's conditions: S-polarised, 10–50° in 10° steps, 400–720 nm in 4 nm bands,
    /// σ = 0.004 reflectance noise, PET substrate (n = 1.64), 128×96 pixels.
    pub fn seed_conditions(film_ior: f64, thickness_nm: f64) -> Self {
        SynthSpec {
            film_ior,
            substrate_ior: Ior::real(1.64),
            ambient_ior: 1.0,
            mean_thickness_nm: thickness_nm,
            thickness_variation_nm: 0.1 * thickness_nm,
            width: 128,
            height: 96,
            wavelengths_nm: bands(400.0, 720.0, 4.0),
            fwhm_nm: Some(4.0),
            incident_deg: vec![10.0, 20.0, 30.0, 40.0, 50.0],
            polarization: Polarization::S,
            noise_sigma: 0.004,
            seed: 1,
        }
    }
}

/// Band centres from `lo` to `hi` inclusive every `step` nm.
pub fn bands(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step).floor() as usize + 1;
    (0..n).map(|i| lo + step * i as f64).collect()
}

/// The smooth thickness field (a tilt plus a bump: seed assumption 3), row-major.
pub fn thickness_field(spec: &SynthSpec) -> Vec<f32> {
    let (w, h) = (spec.width, spec.height);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let u = (x as f64 + 0.5) / w as f64 - 0.5;
            let v = (y as f64 + 0.5) / h as f64 - 0.5;
            let bump = (-(u * u + v * v) / 0.08).exp() - 0.5;
            let shape = 0.5 * u + 0.3 * v + 0.4 * bump; // spans about ±0.5
            out.push((spec.mean_thickness_nm + spec.thickness_variation_nm * shape) as f32);
        }
    }
    out
}

/// Small deterministic PRNG (SplitMix64) with Box–Muller normals.
pub struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Exact reflectance of the spec's film at one wavelength and angle (band-integrated with
/// a 9-point rule over ±2σ when a FWHM is set).
pub fn reflectance(spec: &SynthSpec, d: f64, incident_deg: f64, lambda_nm: f64) -> f64 {
    let cos1 = incident_deg.to_radians().cos();
    let at = |lam: f64| {
        let film = ThinFilm {
            ambient_ior: spec.ambient_ior,
            film_ior: Complex64::new(spec.film_ior, 0.0),
            thickness_nm: d,
            substrate_ior: spec.substrate_ior.at(lam),
        };
        let r = film.response(lam, cos1);
        match spec.polarization {
            Polarization::S => r.r_s,
            Polarization::P => r.r_p,
            Polarization::Unpolarized => r.r(),
        }
    };
    match spec.fwhm_nm {
        Some(f) if f > 0.0 => {
            let sigma = f / 2.354_820_045;
            let (mut acc, mut wsum) = (0.0, 0.0);
            for i in -4i32..=4 {
                let x = i as f64 * 0.5; // ±2σ
                let wt = (-0.5 * x * x).exp();
                acc += wt * at(lambda_nm + x * sigma);
                wsum += wt;
            }
            acc / wsum
        }
        _ => at(lambda_nm),
    }
}

/// Builds the capture set and returns it with the true thickness field.
pub fn capture(spec: &SynthSpec) -> (CaptureSet, Vec<f32>) {
    let truth = thickness_field(spec);
    let nb = spec.wavelengths_nm.len();
    let mut rng = Rng::new(spec.seed);
    let angles = spec
        .incident_deg
        .iter()
        .map(|&deg| {
            let mut refl = Vec::with_capacity(truth.len() * nb);
            for &d in &truth {
                for &lam in &spec.wavelengths_nm {
                    let r = reflectance(spec, d as f64, deg, lam) + spec.noise_sigma * rng.normal();
                    refl.push(r as f32);
                }
            }
            AngleCapture::from_bip(deg, refl, nb)
        })
        .collect();
    let set = CaptureSet {
        polarization: spec.polarization,
        radiometry: crate::capture::Radiometry::Absolute,
        film_model: None,
        pixel_names: None,
        ambient_ior: spec.ambient_ior,
        substrate_ior: spec.substrate_ior.clone(),
        wavelengths_nm: spec.wavelengths_nm.clone(),
        fwhm_nm: spec.fwhm_nm.map(|f| vec![f; nb]),
        width: spec.width,
        height: spec.height,
        angles,
        invalid: InvalidCounts::default(),
    };
    (set, truth)
}

/// Accuracy of a thickness map against truth on pixels finite in both:
/// (mean absolute error, mean signed error, pixels compared).
pub fn thickness_errors(fit: &[f32], truth: &[f32]) -> (f64, f64, usize) {
    let (mut abs, mut signed, mut n) = (0.0, 0.0, 0usize);
    for (&a, &b) in fit.iter().zip(truth) {
        if a.is_finite() && b.is_finite() {
            abs += (a - b).abs() as f64;
            signed += (a - b) as f64;
            n += 1;
        }
    }
    if n == 0 {
        (f64::NAN, f64::NAN, 0)
    } else {
        (abs / n as f64, signed / n as f64, n)
    }
}
