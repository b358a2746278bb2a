//! Hero-wavelength sampling (4 wavelengths per path) and 4-sample spectra.

/// Wavelengths carried by one path.
pub const N_SPECTRUM_SAMPLES: usize = 4;

/// Four wavelengths (nm) and their sampling pdfs (1/nm). A pdf of 0 marks a terminated
/// secondary wavelength (after a dispersive refraction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampledWavelengths {
    pub lambda: [f32; N_SPECTRUM_SAMPLES],
    pub pdf: [f32; N_SPECTRUM_SAMPLES],
}

impl SampledWavelengths {
    /// Mitsuba/pbrt visible-range importance sampling from one random number `u` ∈ [0,1),
    /// rotated by k/4 for the other three wavelengths.
    pub fn sample_visible(u: f32) -> Self {
        let _ = u;
        todo!("foundation")
    }

    /// Keep only the hero wavelength (index 0); its pdf is divided by 4 so the 4-sample
    /// average stays unbiased.
    pub fn terminate_secondary(&mut self) {
        todo!("foundation")
    }

    pub fn secondary_terminated(&self) -> bool {
        self.pdf[1..].iter().all(|&p| p == 0.0)
    }
}

/// pdf (1/nm) of [`SampledWavelengths::sample_visible`] for one wavelength.
pub fn visible_wavelengths_pdf(lambda_nm: f32) -> f32 {
    let _ = lambda_nm;
    todo!("foundation")
}

/// A spectral quantity at the four path wavelengths.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SampledSpectrum(pub [f32; N_SPECTRUM_SAMPLES]);

impl SampledSpectrum {
    pub const fn splat(v: f32) -> Self {
        SampledSpectrum([v; N_SPECTRUM_SAMPLES])
    }

    /// Monte-Carlo estimate of CIE XYZ: mean over the 4 samples of cmf(λ)·L(λ)/pdf(λ),
    /// divided by [`super::CIE_Y_INTEGRAL`] (zero-pdf samples contribute 0).
    pub fn to_xyz(&self, wavelengths: &SampledWavelengths) -> [f32; 3] {
        let _ = wavelengths;
        todo!("foundation")
    }
}
