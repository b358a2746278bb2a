//! Multilayer stacks: coherent transfer-matrix method, incoherent (thick) layers with the
//! semantics of `tmm.inc_tmm`, and band averaging.
//!
//! # Coherent layers
//! The characteristic-matrix product of Born & Wolf §1.6 (`tmm.coh_tmm`),
//! `M̃ = (1/t01) [[1, r01], [r01, 1]] · Π_j (1/t_{j,j+1}) [[e^{-iβj}, 0], [0, e^{iβj}]] [[1, r], [r, 1]]`,
//! with `r = M̃10 / M̃00`, `t = 1 / M̃00`, is evaluated from the substrate upwards in its
//! normalised (Rouard / Airy-recursion) form
//! `r_j = (r_{j-1,j} + r_{j+1} e^{2iβj}) / (1 + r_{j-1,j} r_{j+1} e^{2iβj})`,
//! `t_j = t_{j-1,j} t_{j+1} e^{iβj} / (1 + r_{j-1,j} r_{j+1} e^{2iβj})`.
//! The two are algebraically identical (divide each partial product by its (0,0) entry),
//! but the recursion only ever multiplies by `e^{iβ}` with `Im β ≥ 0`, i.e. `|e^{iβ}| ≤ 1`,
//! so thick absorbing layers never overflow (where `coh_tmm` must clamp `Im δ` at 35).
//! For a single layer the first step *is* the Airy sum (seed eq. 4).
//!
//! # Incoherent layers
//! A layer marked [`Coherence::Incoherent`] (thicker than the coherence length) adds
//! powers instead of amplitudes, as in Byrnes, "Multilayer optical calculations",
//! arXiv:1603.02720 §4 (`tmm.inc_tmm`): the coherent groups between incoherent media give
//! forward/backward power coefficients `R, T, R', T'`, and an incoherent layer of single-pass
//! transmission `P = exp(-4π d Im(n cosθ) / λ)` combines the group above with everything
//! below (`R_b, T_b`) as the geometric series
//! `R = R_f + T_f T'_f P² R_b / (1 − R'_f P² R_b)`, `T = T_f P T_b / (1 − R'_f P² R_b)`.
//! This is the same result as `inc_tmm`'s L-matrix product without its `1/P` factors (which
//! `inc_tmm` has to clamp at `P ≥ 1e-30`).

use super::film::{FilmAmplitudes, FilmResponse, ThinFilm};
use super::fresnel::n_cos_theta;
use super::lanes::{lanes, Cx};
use super::OpticsError;
use num_complex::Complex64;
use std::f64::consts::PI;

/// Whether a layer's multiply reflected waves add in amplitude (coherent) or in power.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Coherence {
    /// Thin compared to the coherence length: interference (`tmm` 'c').
    #[default]
    Coherent,
    /// Thick compared to the coherence length: powers add (`tmm` 'i').
    Incoherent,
}

/// One layer of a stack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    /// `n + ik` of the layer at the wavelength of evaluation.
    pub ior: Complex64,
    /// Physical thickness in nanometres.
    pub thickness_nm: f64,
    pub coherence: Coherence,
}

impl Layer {
    pub fn coherent(ior: Complex64, thickness_nm: f64) -> Self {
        Layer {
            ior,
            thickness_nm,
            coherence: Coherence::Coherent,
        }
    }
    pub fn incoherent(ior: Complex64, thickness_nm: f64) -> Self {
        Layer {
            ior,
            thickness_nm,
            coherence: Coherence::Incoherent,
        }
    }
}

/// N layers (top first) between a lossless ambient and a semi-infinite substrate, all
/// indices at one wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct Stack {
    /// Ambient (incidence) medium, real.
    pub ambient_ior: f64,
    /// Layers from the ambient side down to the substrate. May be empty (bare interface).
    pub layers: Vec<Layer>,
    /// Substrate `n + ik`.
    pub substrate_ior: Complex64,
}

/// One medium as seen by a ray with tangential wavevector `kx = n1 sinθ1`.
#[derive(Clone, Copy)]
pub(super) struct Medium {
    n: Complex64,
    n2: Complex64,
    /// `n cosθ` on the forward branch.
    nc: Complex64,
}

impl Medium {
    #[inline]
    pub(super) fn new(n: Complex64, kx: f64) -> Self {
        Medium {
            n,
            n2: n * n,
            nc: n_cos_theta(n, kx),
        }
    }

    /// The lossless ambient of index `n1` at `cos θ1` (clamped to [0, 1]) and the tangential
    /// wavevector `kx = n1 sinθ1` it imposes on every layer below.
    #[inline]
    pub(super) fn ambient(n1: f64, cos_theta1: f64) -> (Self, f64) {
        let cos1 = cos_theta1.clamp(0.0, 1.0);
        let kx = n1 * ((1.0 - cos1) * (1.0 + cos1)).max(0.0).sqrt();
        // Its n cosθ is exactly n1 cosθ1 (no round trip via kx).
        let m = Medium {
            n: Complex64::new(n1, 0.0),
            n2: Complex64::new(n1 * n1, 0.0),
            nc: Complex64::new(n1 * cos1, 0.0),
        };
        (m, kx)
    }
}

/// `N` media side by side (one per wavelength of a bundle), in SIMD-friendly lanes.
#[derive(Clone, Copy)]
pub(super) struct MediumLanes<const N: usize> {
    n: Cx<N>,
    n2: Cx<N>,
    nc: Cx<N>,
}

impl<const N: usize> MediumLanes<N> {
    #[inline]
    pub(super) fn from_lanes(m: &[Medium; N]) -> Self {
        MediumLanes {
            n: Cx::from_fn(|k| m[k].n),
            n2: Cx::from_fn(|k| m[k].n2),
            nc: Cx::from_fn(|k| m[k].nc),
        }
    }
}

/// The complex amplitudes of `N` wavelengths.
#[derive(Clone, Copy)]
pub(super) struct AmplitudeLanes<const N: usize> {
    r_s: Cx<N>,
    r_p: Cx<N>,
    t_s: Cx<N>,
    t_p: Cx<N>,
}

impl<const N: usize> AmplitudeLanes<N> {
    #[inline]
    pub(super) fn lane(&self, k: usize) -> FilmAmplitudes {
        FilmAmplitudes {
            r_s: self.r_s.lane(k),
            r_p: self.r_p.lane(k),
            t_s: self.t_s.lane(k),
            t_p: self.t_p.lane(k),
        }
    }
}

/// Interface amplitudes i → f, written with `n cosθ` so no division by `n` is needed
/// (multiply `tmm.interface_r/t`'s p form by `n_i n_f`).
/// `WITH_T` = false leaves the transmission amplitudes zero (a reflectance needs none).
#[inline(always)]
fn interface<const N: usize, const WITH_T: bool>(
    i: &MediumLanes<N>,
    f: &MediumLanes<N>,
) -> AmplitudeLanes<N> {
    let s_den = i.nc + f.nc;
    let p_a = f.n2 * i.nc;
    let p_b = i.n2 * f.nc;
    let p_den = p_a + p_b;
    let (t_s, t_p) = if WITH_T {
        (i.nc.times(2.0) / s_den, i.n.times(2.0) * f.n * i.nc / p_den)
    } else {
        (Cx::ZERO, Cx::ZERO)
    };
    AmplitudeLanes {
        r_s: (i.nc - f.nc) / s_den,
        r_p: (p_a - p_b) / p_den,
        t_s,
        t_p,
    }
}

/// Power coefficients of a coherent group incident from `first`, exiting into `last`.
#[derive(Debug, Clone, Copy, Default)]
struct Powers {
    r: [f64; 2],
    t: [f64; 2],
}

/// Coherent amplitudes of media `m[0] | m[1..len-1] (thicknesses d) | m[len-1]`.
fn coherent_amplitudes(m: &[Medium], d_nm: &[f64], lambda_nm: f64) -> FilmAmplitudes {
    debug_assert_eq!(m.len(), d_nm.len() + 2);
    let media: Vec<MediumLanes<1>> = m.iter().map(|m| MediumLanes::from_lanes(&[*m])).collect();
    let phase = |j: usize, m: &MediumLanes<1>| layer_phase(m, d_nm[j], [lambda_nm]);
    rouard::<1, true>(m.len(), |j| &media[j], phase).lane(0)
}

/// The Rouard recursion of the module doc over `len` media, from the substrate
/// (`medium(len - 1)`) up to the ambient (`medium(0)`); `phase(j, m)` is layer `j`'s
/// ([`layer_phase`] of its medium `m = medium(j + 1)`). Each medium and phase is asked for
/// once, so a caller can compute them on the fly or share them between equal layers. `N`
/// wavelengths go through in lanes (the same operations as one at a time, so the same values
/// bit for bit); `WITH_T` = false skips the transmission amplitudes (left zero).
#[inline]
pub(super) fn rouard<'m, const N: usize, const WITH_T: bool>(
    len: usize,
    medium: impl Fn(usize) -> &'m MediumLanes<N>,
    phase: impl Fn(usize, &MediumLanes<N>) -> LayerPhase<N>,
) -> AmplitudeLanes<N> {
    let last = len - 1;
    let mut below = medium(last - 1);
    let mut acc = interface::<N, WITH_T>(below, medium(last));
    for j in (1..last).rev() {
        let above = medium(j - 1);
        let step = interface::<N, WITH_T>(above, below);
        let LayerPhase { e_half, e_full } = phase(j - 1, below);
        let ds = (step.r_s * acc.r_s * e_full).plus(1.0);
        let dp = (step.r_p * acc.r_p * e_full).plus(1.0);
        let (t_s, t_p) = if WITH_T {
            (
                step.t_s * acc.t_s * e_half / ds,
                step.t_p * acc.t_p * e_half / dp,
            )
        } else {
            (Cx::ZERO, Cx::ZERO)
        };
        acc = AmplitudeLanes {
            r_s: (step.r_s + acc.r_s * e_full) / ds,
            r_p: (step.r_p + acc.r_p * e_full) / dp,
            t_s,
            t_p,
        };
        below = above;
    }
    acc
}

/// A layer's one-pass phase factor `e^{iβ}` and its square (the round trip), per lane.
#[derive(Clone, Copy)]
pub(super) struct LayerPhase<const N: usize> {
    e_half: Cx<N>,
    e_full: Cx<N>,
}

impl<const N: usize> LayerPhase<N> {
    /// A placeholder for buffers (no layer has it: |e^{iβ}| = 0 only in the limit).
    pub(super) const ZERO: Self = LayerPhase {
        e_half: Cx::ZERO,
        e_full: Cx::ZERO,
    };
}

/// The phase of a layer of medium `m`, `d_nm` thick: β = 2π d n cosθ / λ; on the forward
/// branch Im β ≥ 0, so |e^{iβ}| ≤ 1.
#[inline(always)]
pub(super) fn layer_phase<const N: usize>(
    m: &MediumLanes<N>,
    d_nm: f64,
    lambda_nm: [f64; N],
) -> LayerPhase<N> {
    let beta = m.nc.scale(lanes(|k| 2.0 * PI * d_nm / lambda_nm[k]));
    let e_half = phase_factor(beta);
    LayerPhase {
        e_half,
        e_full: e_half * e_half,
    }
}

/// `e^{iβ}` for `Im β ≥ 0` without overflow (the decay underflows gracefully to 0), in
/// lanes. (A polynomial sine and cosine in SIMD lanes measured no faster than the library's
/// `sin_cos` per lane here, and once the phases of equal layers were shared, slower:
/// docs/performance.md, seventh round.)
#[inline(always)]
fn phase_factor<const N: usize>(beta: Cx<N>) -> Cx<N> {
    let mut e = Cx::ZERO;
    for k in 0..N {
        // A lossless layer's β is real: e^0 = 1 exactly, without the call.
        let decay = if beta.im[k] == 0.0 {
            1.0
        } else {
            (-beta.im[k]).exp()
        };
        let (s, c) = beta.re[k].sin_cos();
        e.re[k] = decay * c;
        e.im[k] = decay * s;
    }
    e
}

/// `tmm.T_from_t`: power transmittance from the amplitude, incident medium `i`, exit `f`.
#[inline]
pub(super) fn t_power(a: &FilmAmplitudes, i: &Medium, f: &Medium) -> [f64; 2] {
    let cos_i = i.nc / i.n;
    let cos_f = f.nc / f.n;
    let den_s = i.nc.re;
    let den_p = (i.n * cos_i.conj()).re;
    let ts = if den_s > 0.0 {
        a.t_s.norm_sqr() * f.nc.re / den_s
    } else {
        0.0
    };
    let tp = if den_p > 0.0 {
        a.t_p.norm_sqr() * (f.n * cos_f.conj()).re / den_p
    } else {
        0.0
    };
    [ts.max(0.0), tp.max(0.0)]
}

fn coherent_powers(m: &[Medium], d_nm: &[f64], lambda_nm: f64) -> Powers {
    let a = coherent_amplitudes(m, d_nm, lambda_nm);
    Powers {
        r: [a.r_s.norm_sqr(), a.r_p.norm_sqr()],
        t: t_power(&a, &m[0], &m[m.len() - 1]),
    }
}

pub(crate) fn check_index(n: Complex64) -> Result<(), OpticsError> {
    if n.re.is_finite() && n.im.is_finite() && n.re > 0.0 && n.im >= 0.0 {
        Ok(())
    } else {
        Err(OpticsError::BadIndex(format!("{}{:+}i", n.re, n.im)))
    }
}

pub(crate) fn check_wavelength(lambda_nm: f64) -> Result<(), OpticsError> {
    if lambda_nm.is_finite() && lambda_nm > 0.0 {
        Ok(())
    } else {
        Err(OpticsError::BadWavelength(lambda_nm))
    }
}

pub(crate) fn check_angle(incident_deg: f64) -> Result<(), OpticsError> {
    if incident_deg.is_finite() && (0.0..90.0).contains(&incident_deg) {
        Ok(())
    } else {
        Err(OpticsError::BadAngle(incident_deg))
    }
}

impl From<&ThinFilm> for Stack {
    fn from(f: &ThinFilm) -> Self {
        Stack {
            ambient_ior: f.ambient_ior,
            layers: vec![Layer::coherent(f.film_ior, f.thickness_nm)],
            substrate_ior: f.substrate_ior,
        }
    }
}

impl Stack {
    /// Rejects inputs that would otherwise give NaN (negative/non-finite thickness,
    /// non-physical indices).
    pub fn validate(&self) -> Result<(), OpticsError> {
        check_index(Complex64::new(self.ambient_ior, 0.0))?;
        for l in &self.layers {
            if !(l.thickness_nm.is_finite() && l.thickness_nm >= 0.0) {
                return Err(OpticsError::BadThickness(l.thickness_nm));
            }
            check_index(l.ior)?;
        }
        check_index(self.substrate_ior)
    }

    fn media(&self, cos_theta1: f64) -> Vec<Medium> {
        let (ambient, kx) = Medium::ambient(self.ambient_ior, cos_theta1);
        let mut m = Vec::with_capacity(self.layers.len() + 2);
        m.push(ambient);
        m.extend(self.layers.iter().map(|l| Medium::new(l.ior, kx)));
        m.push(Medium::new(self.substrate_ior, kx));
        m
    }

    /// Complex amplitudes treating every layer as coherent. No validation (hot path).
    pub fn amplitudes(&self, lambda_nm: f64, cos_theta1: f64) -> FilmAmplitudes {
        let m = self.media(cos_theta1);
        let d: Vec<f64> = self.layers.iter().map(|l| l.thickness_nm).collect();
        coherent_amplitudes(&m, &d, lambda_nm)
    }

    /// Power R and T (s, p). Layers marked incoherent add in power (`tmm.inc_tmm`).
    /// No validation (hot path): call [`Stack::validate`] once on untrusted input.
    pub fn response(&self, lambda_nm: f64, cos_theta1: f64) -> FilmResponse {
        let m = self.media(cos_theta1);
        // Indices (into m) of incoherent media: ambient, incoherent layers, substrate.
        let mut inc: Vec<usize> = vec![0];
        inc.extend(
            self.layers
                .iter()
                .enumerate()
                .filter(|(_, l)| l.coherence == Coherence::Incoherent)
                .map(|(i, _)| i + 1),
        );
        inc.push(m.len() - 1);
        let d_of = |a: usize, b: usize| -> Vec<f64> {
            self.layers[a..b - 1]
                .iter()
                .map(|l| l.thickness_nm)
                .collect()
        };

        // Last group (from the deepest incoherent medium to the substrate): forward only.
        let g = inc.len() - 2;
        let mut below = coherent_powers(
            &m[inc[g]..=inc[g + 1]],
            &d_of(inc[g], inc[g + 1]),
            lambda_nm,
        );
        for g in (0..inc.len() - 2).rev() {
            let (a, b) = (inc[g], inc[g + 1]);
            let fwd = coherent_powers(&m[a..=b], &d_of(a, b), lambda_nm);
            let rev_media: Vec<Medium> = m[a..=b].iter().rev().copied().collect();
            let mut rev_d = d_of(a, b);
            rev_d.reverse();
            let back = coherent_powers(&rev_media, &rev_d, lambda_nm);
            // Single-pass power transmission through incoherent layer b.
            let layer = &self.layers[b - 1];
            let p = (-4.0 * PI * layer.thickness_nm * m[b].nc.im / lambda_nm).exp();
            let p2 = p * p;
            let mut next = Powers::default();
            for k in 0..2 {
                let denom = 1.0 - back.r[k] * p2 * below.r[k];
                next.r[k] = fwd.r[k] + fwd.t[k] * back.t[k] * p2 * below.r[k] / denom;
                next.t[k] = fwd.t[k] * p * below.t[k] / denom;
            }
            below = next;
        }
        FilmResponse {
            r_s: below.r[0],
            r_p: below.r[1],
            t_s: below.t[0],
            t_p: below.t[1],
        }
    }

    /// Checked [`Stack::response`] with the incident angle in degrees.
    pub fn response_at_angle(
        &self,
        lambda_nm: f64,
        incident_deg: f64,
    ) -> Result<FilmResponse, OpticsError> {
        self.validate()?;
        check_wavelength(lambda_nm)?;
        check_angle(incident_deg)?;
        Ok(self.response(lambda_nm, incident_deg.to_radians().cos()))
    }

    /// Response averaged uniformly over the band `λ ± bandwidth/2` (midpoint rule with
    /// `samples` points, indices held at their values here). This is what a spectrometer
    /// band or a finite coherence length sees: for a thick layer the fringes average out
    /// and the result tends to the incoherent one.
    pub fn band_averaged_response(
        &self,
        lambda_nm: f64,
        bandwidth_nm: f64,
        samples: usize,
        cos_theta1: f64,
    ) -> FilmResponse {
        let n = samples.max(1);
        let mut acc = FilmResponse::default();
        for i in 0..n {
            let l = lambda_nm + bandwidth_nm * ((i as f64 + 0.5) / n as f64 - 0.5);
            let r = self.response(l, cos_theta1);
            acc.r_s += r.r_s;
            acc.r_p += r.r_p;
            acc.t_s += r.t_s;
            acc.t_p += r.t_p;
        }
        let w = 1.0 / n as f64;
        FilmResponse {
            r_s: acc.r_s * w,
            r_p: acc.r_p * w,
            t_s: acc.t_s * w,
            t_p: acc.t_p * w,
        }
    }

    /// The same stack with every layer thicker than `coherence_length_nm` (optical
    /// thickness n·d) marked incoherent.
    pub fn with_coherence_length(&self, coherence_length_nm: f64) -> Stack {
        let mut s = self.clone();
        for l in &mut s.layers {
            if l.ior.re * l.thickness_nm > coherence_length_nm {
                l.coherence = Coherence::Incoherent;
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex64 {
        Complex64::new(re, im)
    }

    #[test]
    fn one_layer_equals_airy() {
        for &(n2, n3, d) in &[
            (c(1.37, 0.0), c(1.64, 0.0), 400.0),
            (c(2.37, 0.0), c(1.64, 0.0), 123.0),
            (c(1.5, 0.2), c(0.18, 3.4), 60.0),
            (c(1.38, 0.0), c(1.0, 0.0), 3000.0),
        ] {
            let f = ThinFilm {
                ambient_ior: 1.0,
                film_ior: n2,
                thickness_nm: d,
                substrate_ior: n3,
            };
            let s = Stack::from(&f);
            for deg in [0.0, 30.0, 60.0, 85.0, 89.9] {
                let cos1 = f64::to_radians(deg).cos();
                for l in [380.0, 550.0, 779.0] {
                    let a = f.response(l, cos1);
                    let b = s.response(l, cos1);
                    for (x, y) in [
                        (a.r_s, b.r_s),
                        (a.r_p, b.r_p),
                        (a.t_s, b.t_s),
                        (a.t_p, b.t_p),
                    ] {
                        assert!(
                            (x - y).abs() < 1e-12,
                            "{x} vs {y} at {deg}° {l} nm {n2} {n3}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn incoherent_slab_matches_closed_form() {
        // Glass slab in air, incoherent: R = R1 + T1² R1 / (1 − R1²) at normal incidence.
        let s = Stack {
            ambient_ior: 1.0,
            layers: vec![Layer::incoherent(c(1.5, 0.0), 1e6)],
            substrate_ior: c(1.0, 0.0),
        };
        let r1: f64 = (0.5f64 / 2.5).powi(2);
        let want = r1 + (1.0 - r1).powi(2) * r1 / (1.0 - r1 * r1);
        let got = s.response(550.0, 1.0);
        assert!((got.r_s - want).abs() < 1e-14);
        assert!((got.r_s + got.t_s - 1.0).abs() < 1e-14);
    }

    #[test]
    fn rejects_bad_inputs() {
        let mut s = Stack {
            ambient_ior: 1.0,
            layers: vec![Layer::coherent(c(1.5, 0.0), -1.0)],
            substrate_ior: c(1.5, 0.0),
        };
        assert!(matches!(
            s.response_at_angle(500.0, 0.0),
            Err(OpticsError::BadThickness(_))
        ));
        s.layers[0].thickness_nm = 10.0;
        s.layers[0].ior = c(f64::NAN, 0.0);
        assert!(matches!(
            s.response_at_angle(500.0, 0.0),
            Err(OpticsError::BadIndex(_))
        ));
        s.layers[0].ior = c(1.5, 0.0);
        assert!(matches!(
            s.response_at_angle(0.0, 0.0),
            Err(OpticsError::BadWavelength(_))
        ));
        assert!(matches!(
            s.response_at_angle(500.0, 90.0),
            Err(OpticsError::BadAngle(_))
        ));
        assert!(s.response_at_angle(500.0, 89.99).is_ok());
    }
}
