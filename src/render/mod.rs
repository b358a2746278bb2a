//! The hero-wavelength spectral path tracer (`docs/architecture.md`, "Rendering").
//!
//! One file per concept, after pbrt-v4's decomposition:
//! [`accel`] (obvhs CWBVH + spheres), [`camera`] (Mitsuba `perspective`), [`sampler`]
//! (deterministic per-sample PCG streams), [`film`] (spectrum → sRGB, reconstruction,
//! exact-merge accumulation), [`lights`] (envmap, constant, area, point), [`bsdf`] (one module
//! per model), [`integrator`] (`path` with MIS and Russian roulette, generic over what a path
//! carries), [`stokes`] (the polarised carrier), [`effects`] (effect analysis), [`texture`]
//! (spectra and textures at the path wavelengths), [`counters`] (per-thread work counters).
//!
//! Rendering is parallel over image rows with rayon; every sample draws its random numbers from
//! its own stream keyed by (pixel, global sample index, seed), so the image does not depend on
//! the number of threads, and `sample_range` splits merge exactly (see [`film`]).

pub mod accel;
pub mod adaptive;
pub mod batch;
pub mod bsdf;
mod bvh_collapse;
mod bvh_sah;
pub mod camera;
pub mod counters;
pub mod effects;
pub mod env_sampling;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod lights;
pub mod medium;
pub mod passes;
pub mod polarization;
pub mod primary;
pub mod provenance;
pub mod sampler;
pub mod stokes;
pub mod texture;

use crate::image_io::RgbImage;
use crate::progress;
use crate::scene::{IntegratorSettings, Scene};

use anyhow::{bail, Context, Result};
use bsdf::Bsdf;
use counters::{count, Counter, Counters};
use film::{tree_sum_in_place, Filter};
use geometry::SurfaceInteraction;
use glam::Vec2;
use integrator::Carrier;
use rayon::prelude::*;
use std::time::Instant;
use texture::Spec;

pub use effects::Effects;

/// Command-line style overrides of the scene's own settings.
#[derive(Debug, Clone, Default)]
pub struct RenderOptions {
    pub spp: Option<u32>,
    pub seed: Option<u64>,
    /// Worker threads (None: rayon's default pool).
    pub threads: Option<usize>,
    pub max_depth: Option<i32>,
    pub resolution: Option<(u32, u32)>,
    /// Render only global sample indices [start, end).
    pub sample_range: Option<(u32, u32)>,
    /// Sample sequence (None: the scene's sampler type).
    pub sampler: Option<sampler::SamplerKind>,
    /// Fresnel splits per path (None: [`DEFAULT_FRESNEL_SPLITS`]; 0: always pick one lobe,
    /// like Mitsuba). Only used where effect analysis found smooth glass or bubbles.
    pub fresnel_splits: Option<u32>,
    /// Draw a progress bar on stderr (only when it is a terminal, after the first second).
    pub progress: bool,
    /// Trace with Stokes vectors even where no polariser asks for it (a check of the
    /// polarised transport: without a polariser it must give the unpolarised image).
    pub force_polarization: bool,
    /// Sample wavelengths also for camera rays that see an emitter directly (by default
    /// their colour is its closed-form expectation over wavelengths:
    /// [`effects::Effect::SpectralDirectView`]).
    pub spectral_direct_view: bool,
    /// Draw environment light samples by radiance alone, over the whole sphere, as Mitsuba
    /// does (by default a reflecting surface draws them from the hemisphere it faces:
    /// [`effects::Effect::HemisphereEnvSampling`]).
    pub plain_env_sampling: bool,
    /// Four wavelengths also on specular reflection chains, as Mitsuba (by default a path
    /// that only reflects off smooth films and coatings, and metals after them, carries eight:
    /// [`effects::Effect::SpecularChainWavelengths`]).
    pub plain_specular_chains: bool,
    /// The same number of samples in every pixel, as Mitsuba (by default the work of a
    /// quarter more goes where neighbouring pixels are noisy:
    /// [`effects::Effect::AdaptiveSampleCounts`]).
    pub uniform_samples: bool,
    /// Asked before each row whether to stop (a Ctrl-C handler's flag); see
    /// [`render_prepared`].
    pub cancel: Option<Cancel>,
}

/// A question the render asks before every row: stop now? Cloning shares it.
#[derive(Clone)]
pub struct Cancel(pub std::sync::Arc<dyn Fn() -> bool + Send + Sync>);

impl Cancel {
    /// Stops once `flag` is raised (e.g. by a signal handler).
    pub fn on_flag(flag: std::sync::Arc<std::sync::atomic::AtomicBool>) -> Self {
        Cancel(std::sync::Arc::new(move || {
            flag.load(std::sync::atomic::Ordering::Relaxed)
        }))
    }
}

impl std::fmt::Debug for Cancel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Cancel")
    }
}

/// Fresnel splits per camera path by default: a path branches in two at its first
/// `DEFAULT_FRESNEL_SPLITS` smooth reflect/transmit interfaces (at most 2^N leaves). Chosen with
/// `thinfilm bench render --fresnel-splits N` (128², against the Mitsuba references; README,
/// "Fresnel splitting"): at 64 spp, mean ΔE00 for N = 0/1/2/3 is 2.23/0.58/0.50/0.36 on
/// `polarizer_spheres` (0.75/1.11/1.14/1.11 s), 1.45/0.94/0.48/0.41 on `bubble`
/// (0.48/0.59/0.79/0.95 s), 2.12/1.65/1.45/1.45 on `lens` (1.6/2.1/2.5/2.3 s).
pub const DEFAULT_FRESNEL_SPLITS: u32 = 3;
/// Most samples per pixel one render takes (2^20; references use 2^14).
pub const MAX_SPP: u32 = 1 << 20;
/// Deepest a path may go without Russian roulette (see `prepare`).
const MAX_UNROULETTED_DEPTH: i32 = 1024;
/// A BSDF without a glossy lobe family ([`glossy_lobes`]).
const NO_LOBE: u8 = u8::MAX;
/// Upper bound on `fresnel_splits`: 2^16 branches per camera sample at worst.
pub const MAX_FRESNEL_SPLITS: u32 = 16;

/// Work done and time taken.
#[derive(Debug, Clone, Default)]
pub struct RenderStats {
    pub seconds: f64,
    /// Time spent building the BVH and light tables.
    pub setup_seconds: f64,
    pub samples: u64,
    pub rays: u64,
    pub shadow_rays: u64,
    pub film_evals: u64,
    /// Paths whose secondary wavelengths were dropped at a dispersive refraction (0 unless
    /// the scene declares dispersion: the proof that the 4-wavelength fast path is kept).
    pub secondary_terminations: u64,
    /// Samples whose estimate was NaN or infinite and were discarded (should be 0).
    pub invalid_samples: u64,
    pub triangles: usize,
    pub degenerate_triangles: usize,
    pub threads: usize,
}

impl RenderStats {
    pub fn samples_per_second(&self) -> f64 {
        self.samples as f64 / self.seconds.max(1e-9)
    }
    /// Closest-hit plus shadow rays per second.
    pub fn rays_per_second(&self) -> f64 {
        (self.rays + self.shadow_rays) as f64 / self.seconds.max(1e-9)
    }
}

/// A finished render.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Linear sRGB (Rec.709, D65).
    pub image: RgbImage,
    pub stats: RenderStats,
    pub effects: Effects,
    /// The global sample indices rendered.
    pub sample_range: (u32, u32),
    /// The sample indices asked for (differs from `sample_range` when interrupted).
    pub requested_range: (u32, u32),
    /// Set when the render was cancelled and holds only a prefix of the asked-for samples.
    pub interrupted: bool,
    /// Pixels hold different numbers of samples ([`adaptive`]).
    pub adaptive: bool,
    /// Per-pixel sum of reconstruction-filter weights (tent and Gaussian filters only; the
    /// box filter's weight is the sample count). Needed to merge split renders exactly.
    pub filter_weights: Option<Vec<f32>>,
}

/// A scene prepared for tracing. Read through its methods: a surface point's BSDF and
/// emitter come from [`PreparedScene::interaction`].
pub struct PreparedScene {
    accel: accel::Accel,
    lights: lights::LightSet,
    bsdfs: Vec<Bsdf>,
    /// BSDF index per shape.
    shape_bsdf: Vec<u32>,
    /// Per shape, its BSDF's glossy lobe family ([`glossy_lobes`]) or [`NO_LOBE`].
    shape_lobe: Vec<u8>,
    camera: camera::Camera,
    settings: IntegratorSettings,
    width: u32,
    height: u32,
    filter: Filter,
    seed: u64,
    sampler: sampler::SamplerKind,
    sample_range: (u32, u32),
    /// Fresnel splits per path (0 unless effect analysis switched splitting on).
    fresnel_splits: u32,
    effects: Effects,
    degenerate_triangles: usize,
    /// Set when effect analysis switched polarisation on.
    polarized: Option<stokes::PolarizedSetup>,
    /// Candidate triangles per pixel for camera rays (None: camera rays use the BVH).
    primary_bins: Option<primary::PrimaryBins>,
    /// Participating media (media branch hook; None: surfaces only).
    media: Option<std::sync::Arc<medium::SceneMedia>>,
    /// Camera rays that see an emitter directly take its expected colour instead of a
    /// wavelength-sampled estimate ([`effects::Effect::SpectralDirectView`] off).
    closed_form_direct_view: bool,
    /// Reflecting surfaces draw environment light samples from their normal's bin
    /// ([`effects::Effect::HemisphereEnvSampling`]).
    hemisphere_env_sampling: bool,
    /// Paths that only reflect off Dirac reflectors carry eight wavelengths
    /// ([`effects::Effect::SpecularChainWavelengths`]).
    specular_chains: bool,
    /// Extra samples after `sample_range` where neighbouring pixels are noisy ([`adaptive`]).
    adaptive: bool,
}

/// A surface point of a prepared scene: its geometry (a [`SurfaceInteraction`], by `Deref`)
/// and what is there — [`Interaction::bsdf`], [`Interaction::emitter`].
#[derive(Clone, Copy)]
pub struct Interaction<'s> {
    geometry: SurfaceInteraction,
    scene: &'s PreparedScene,
}

impl<'s> Interaction<'s> {
    /// The BSDF of the shape hit.
    #[inline]
    pub fn bsdf(&self) -> &'s Bsdf {
        self.scene.shape_bsdf_of(self.geometry.shape)
    }

    /// The shape's area light, if it emits.
    #[inline]
    pub fn emitter(&self) -> Option<&'s lights::Light> {
        let lights = &self.scene.lights;
        lights.shape_light[self.geometry.shape as usize].map(|i| &lights.lights[i as usize])
    }
}

impl std::ops::Deref for Interaction<'_> {
    type Target = SurfaceInteraction;
    #[inline]
    fn deref(&self) -> &SurfaceInteraction {
        &self.geometry
    }
}

impl PreparedScene {
    /// The glossy lobe family of `shape`'s BSDF ([`glossy_lobes`]), if it has one.
    #[inline]
    pub(crate) fn lobe_family_of(&self, shape: u32) -> Option<usize> {
        let f = self.shape_lobe[shape as usize];
        (f != NO_LOBE).then_some(f as usize)
    }

    /// The BSDF of shape `shape`.
    #[inline]
    pub(crate) fn shape_bsdf_of(&self, shape: u32) -> &Bsdf {
        &self.bsdfs[self.shape_bsdf[shape as usize] as usize]
    }

    /// Closest hit of `ray`; camera rays (`pixel` = the pixel they were generated in) use
    /// the screen bins when there are some.
    #[inline]
    pub fn intersect(&self, ray: &camera::Ray, pixel: Option<[u32; 2]>) -> Option<accel::Hit> {
        match (pixel, &self.primary_bins) {
            (Some([x, y]), Some(bins)) => bins.intersect(&self.accel, x, y, ray),
            _ => self.accel.intersect(ray),
        }
    }

    /// Closest hits of a batch of rays ([`accel::Accel::intersect_batch`]).
    #[inline]
    pub fn intersect_batch(&self, rays: &[camera::Ray], hits: &mut Vec<Option<accel::Hit>>) {
        self.accel.intersect_batch(rays, hits);
    }

    /// Whether anything blocks `ray` (a shadow ray).
    #[inline]
    pub fn occluded(&self, ray: &camera::Ray) -> bool {
        self.accel.occluded(ray)
    }

    /// The surface point `hit` of `ray`.
    #[inline]
    pub fn interaction(&self, ray: &camera::Ray, hit: &accel::Hit) -> Interaction<'_> {
        Interaction {
            geometry: self.accel.interaction(ray, hit),
            scene: self,
        }
    }

    pub fn lights(&self) -> &lights::LightSet {
        &self.lights
    }

    pub fn settings(&self) -> &IntegratorSettings {
        &self.settings
    }

    pub fn camera(&self) -> &camera::Camera {
        &self.camera
    }

    pub fn accel(&self) -> &accel::Accel {
        &self.accel
    }

    pub fn primary_bins(&self) -> Option<&primary::PrimaryBins> {
        self.primary_bins.as_ref()
    }

    /// Camera rays through the BVH instead of the screen bins (the bins only accelerate:
    /// the image is the same).
    pub fn use_bvh_for_camera_rays(&mut self) {
        self.primary_bins = None;
    }

    /// Image size in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// The global sample indices this render traces.
    pub fn sample_range(&self) -> (u32, u32) {
        self.sample_range
    }

    /// Fresnel splits per path (0 unless effect analysis switched splitting on).
    pub fn fresnel_splits(&self) -> u32 {
        self.fresnel_splits
    }

    pub fn effects(&self) -> &Effects {
        &self.effects
    }

    /// The polarised transport's set-up, when paths carry Stokes vectors.
    pub fn polarized(&self) -> Option<&stokes::PolarizedSetup> {
        self.polarized.as_ref()
    }

    /// The scene's participating media, when it has some (Mitsuba's `volpath`).
    #[inline]
    pub fn media(&self) -> Option<&medium::SceneMedia> {
        self.media.as_deref()
    }

    /// Whether reflecting surfaces draw environment light samples from the hemisphere they
    /// face ([`env_sampling`]).
    #[inline]
    pub fn hemisphere_env_sampling(&self) -> bool {
        self.hemisphere_env_sampling
    }

    /// Whether camera rays start inside a medium (then even those that hit nothing are
    /// traced as paths).
    #[inline]
    pub fn camera_in_medium(&self) -> bool {
        self.media().is_some_and(|m| m.sensor != medium::NO_MEDIUM)
    }
}

/// Validates the scene and options, runs effect analysis, builds the BVH and light tables.
pub fn prepare(scene: &Scene, options: &RenderOptions) -> Result<PreparedScene> {
    let mut effects = effects::analyze(scene)?;
    if let Some(n) = options.fresnel_splits.filter(|&n| n > MAX_FRESNEL_SPLITS) {
        bail!("fresnel_splits must be at most {MAX_FRESNEL_SPLITS} (each split can double a path's branches), got {n}");
    }
    let fresnel_splits = if effects.fresnel_split {
        options.fresnel_splits.unwrap_or(DEFAULT_FRESNEL_SPLITS)
    } else {
        0
    };
    if effects.fresnel_split {
        let off = fresnel_splits == 0;
        if let Some(d) = effects.decision_mut(effects::Effect::FresnelSplitting) {
            if off {
                d.on = false;
                d.reason = "disabled by the options (0 splits)".into();
            } else {
                d.reason
                    .push_str(&format!("; {fresnel_splits} split(s) per path"));
            }
        }
        effects.fresnel_split = !off;
    }
    let (width, height) = options
        .resolution
        .unwrap_or((scene.film.width, scene.film.height));
    if width == 0 || height == 0 || width > 65536 || height > 65536 {
        bail!("image resolution must be between 1×1 and 65536×65536, got {width}×{height}");
    }
    let sample_range = sample_range(scene, options)?;
    let filter = Filter::new(&scene.film.filter)?;
    check_render_memory(&filter, width, height, sample_range, options.threads)?;
    let mut settings = scene.integrator;
    if let Some(d) = options.max_depth {
        settings.max_depth = d;
    }
    if settings.max_depth == 0 || settings.max_depth < -1 {
        bail!(
            "max_depth must be −1 (unlimited) or ≥ 1, got {}",
            settings.max_depth
        );
    }
    // A path ends at max_depth or, past rr_depth, by Russian roulette: with neither within
    // reach, a path between two perfect mirrors would never end.
    if (settings.max_depth == -1 || settings.max_depth > MAX_UNROULETTED_DEPTH)
        && settings.rr_depth > MAX_UNROULETTED_DEPTH
    {
        bail!(
            "rr_depth {} with max_depth {}: paths could bounce forever; give max_depth or rr_depth ≤ {MAX_UNROULETTED_DEPTH}",
            settings.rr_depth,
            settings.max_depth
        );
    }
    if sample_range.1 - sample_range.0 > MAX_SPP {
        bail!(
            "{} samples per pixel: at most {MAX_SPP} per render (split larger ones with --sample-range)",
            sample_range.1 - sample_range.0
        );
    }
    let camera = camera::Camera::new(&scene.camera, width, height)?;
    let samples = width as u64 * height as u64 * (sample_range.1 - sample_range.0) as u64;
    // The emitters (an environment map's rgb2spec texels and sampling tables: ~25 ms for a
    // 512 × 256 map) need no BVH: build them beside it on a second thread. The screen bins
    // (for camera rays from one pinhole: `lights` hook, not for lens cameras) need only the
    // triangles: binned beside the BVH build, then given its ids.
    let pinhole = camera.pinhole();
    let (lobe_families, bsdf_lobe) = glossy_lobes(scene, options);
    let (built, emitters) = std::thread::scope(|s| {
        let emitters = s.spawn(|| lights::LightSet::emitter_lights(scene, &lobe_families));
        let built = accel::Accel::build_beside(scene, samples, |tris| {
            pinhole.and_then(|c| primary::PrimaryBins::build(tris, c, width, height, samples))
        });
        let emitters = (emitters.join()).unwrap_or_else(|p| std::panic::resume_unwind(p));
        (built, emitters)
    });
    let (accel, degenerate_triangles, bins) = built?;
    let primary_bins = bins.map(|b| b.into_bvh_order(accel.bvh_order()));
    let camera_rays = match &primary_bins {
        Some(b) => {
            let s = b.stats();
            format!(
                "screen bins ({} candidates, {} pixels via the BVH, {} triangles crossing the camera plane)",
                s.candidates, s.bvh_pixels, s.crossing
            )
        }
        None => "BVH (screen bins would not pay here)".to_string(),
    };
    effects.decide(
        effects::Effect::CameraRays,
        primary_bins.is_some(),
        camera_rays,
    );
    let lights = lights::LightSet::build(scene, &accel, emitters?)?;
    let closed_form_direct_view = direct_view_decision(scene, options, &lights, &mut effects);
    let hemisphere_env_sampling =
        env_sampling_decision(scene, options, &lights, &lobe_families, &mut effects);
    let shape_lobe = (scene.shapes.iter()).map(|s| bsdf_lobe[s.bsdf]).collect();
    let shape_bsdf = scene.shapes.iter().map(|s| s.bsdf as u32).collect();
    let polarized = if effects.polarization || options.force_polarization {
        if let Some(r) = scene.bsdfs.iter().find_map(|b| b.polarized().err()) {
            bail!("polarised transport forced, but a material has no Mueller matrices: {r}");
        }
        Some(stokes::PolarizedSetup::new(scene))
    } else {
        None
    };
    if polarized.is_some() && scene.media.is_some() {
        bail!("participating media (volpath) with polarised transport are not supported");
    }
    let specular_chains =
        specular_chain_decision(scene, options, polarized.is_some(), &mut effects);
    let adaptive = adaptive_decision(options, &filter, sample_range, &mut effects);
    Ok(PreparedScene {
        accel,
        lights,
        bsdfs: scene.bsdfs.clone(),
        shape_bsdf,
        shape_lobe,
        camera,
        settings,
        width,
        height,
        filter,
        seed: options.seed.unwrap_or(scene.seed),
        sampler: options.sampler.unwrap_or(scene.sampler),
        sample_range,
        fresnel_splits,
        effects,
        degenerate_triangles,
        polarized,
        primary_bins,
        media: scene.media.clone(),
        closed_form_direct_view,
        hemisphere_env_sampling,
        specular_chains,
        adaptive,
    })
}

/// Whether extra samples go where pixels are noisy after every pixel's `spp` (the
/// [`effects::Effect::AdaptiveSampleCounts`] decision, added to `effects`).
fn adaptive_decision(
    options: &RenderOptions,
    filter: &Filter,
    (s0, s1): (u32, u32),
    effects: &mut Effects,
) -> bool {
    let spp = s1 - s0;
    let off = if options.uniform_samples {
        Some("the same count in every pixel asked for (--uniform-samples)".to_string())
    } else if options.sample_range.is_some() {
        Some("a sample range (pieces to merge hold the same samples of every pixel)".into())
    } else if !matches!(filter, Filter::Box) {
        Some(format!(
            "the {} filter mixes neighbouring pixels' samples (box filter only)",
            filter.name()
        ))
    } else if spp < adaptive::MIN_SPP {
        Some(format!(
            "{spp} samples per pixel (at least {} for their spread)",
            adaptive::MIN_SPP
        ))
    } else {
        None
    };
    effects.decide_unless(effects::Effect::AdaptiveSampleCounts, off.as_deref(), || {
        format!(
            "{spp} samples in every pixel, then the work of {} more where the neighbouring pixels' samples spread most (at most {} more in one pixel)",
            adaptive::extra_budget(spp),
            adaptive::MAX_EXTRA_PER_SPP * spp
        )
    })
}

/// Whether camera rays that see an emitter directly — the environment, where they escape,
/// or an untextured area light — take its closed-form colour (the
/// [`effects::Effect::SpectralDirectView`] decision, added to `effects`): the film value of
/// such a ray depends on its wavelengths only through the emitter's spectrum, so its mean
/// over the wavelengths — the same expectation, without colour noise — can be integrated
/// once per texel or light instead of sampled per ray.
fn direct_view_decision(
    scene: &Scene,
    options: &RenderOptions,
    lights: &lights::LightSet,
    effects: &mut Effects,
) -> bool {
    let spectral = if options.spectral_direct_view {
        Some("asked for (--spectral-direct-view)")
    } else if scene
        .media
        .as_ref()
        .is_some_and(|m| m.sensor != medium::NO_MEDIUM)
    {
        Some("the camera is inside a medium")
    } else if !lights.background_colour_in_closed_form() {
        Some("an infinite light without a closed-form colour")
    } else {
        None
    };
    let reason = spectral.map_or_else(
        || "the environment and area lights seen directly take their expected colour (each texel's and light's spectrum integrated once)".to_string(),
        str::to_string,
    );
    !effects.decide(
        effects::Effect::SpectralDirectView,
        spectral.is_some(),
        reason,
    )
}

/// Whether reflecting surfaces draw environment light samples from the hemisphere they face
/// (the [`effects::Effect::HemisphereEnvSampling`] decision, added to `effects`): where an
/// environment map lights surfaces, samples below a surface's horizon add nothing, and
/// drawing them from the normal's bin keeps the expectation with less variance.
fn env_sampling_decision(
    scene: &Scene,
    options: &RenderOptions,
    lights: &lights::LightSet,
    lobe_families: &[f32],
    effects: &mut Effects,
) -> bool {
    let has_tables =
        |l: &lights::Light| matches!(l, lights::Light::Env(e) if e.has_hemisphere_tables());
    let off = if !(lights.lights.iter()).any(|l| matches!(l, lights::Light::Env(_))) {
        Some("no environment map")
    } else if !lights.lights.iter().any(has_tables) {
        Some("the environment map is black")
    } else if options.plain_env_sampling {
        Some("radiance-only sampling asked for (--plain-env-sampling)")
    } else if scene.media.is_some() {
        Some("participating media (their light samples are drawn over the whole sphere)")
    } else {
        None
    };
    effects.decide_unless(effects::Effect::HemisphereEnvSampling, off, || {
        let lobes = if lobe_families.is_empty() {
            String::new()
        } else {
            let alphas: Vec<String> = (lobe_families.iter())
                .map(|a| format!("{}", (a * 1000.0).round() / 1000.0))
                .collect();
            format!(
                "; glossy lobes of α {} around their mirror direction",
                alphas.join(", ")
            )
        };
        format!(
            "reflecting surfaces draw environment samples from the hemisphere they face ({} normal bins){lobes}",
            env_sampling::NORMAL_BINS
        )
    })
}

/// The glossy lobe widths whose environment light samples get tables of their own
/// ([`env_sampling::lobe_families`]; none with `--plain-env-sampling`), and each BSDF's
/// family in them ([`NO_LOBE`] if none).
fn glossy_lobes(scene: &Scene, options: &RenderOptions) -> (Vec<f32>, Vec<u8>) {
    let alpha = |b: &bsdf::Bsdf| b.glossy_lobe().map(|m| (m.alpha_u * m.alpha_v).sqrt());
    let families = if options.plain_env_sampling || scene.media.is_some() {
        Vec::new()
    } else {
        env_sampling::lobe_families(scene.bsdfs.iter().filter_map(alpha))
    };
    let of_bsdf = (scene.bsdfs.iter())
        .map(|b| {
            alpha(b)
                .and_then(|a| env_sampling::lobe_family(&families, a))
                .map_or(NO_LOBE, |f| f as u8)
        })
        .collect();
    (families, of_bsdf)
}

/// Whether paths that only reflect off Dirac reflectors, first off a film or coating, carry
/// eight wavelengths to the emitter they meet (the
/// [`effects::Effect::SpecularChainWavelengths`] decision, added to `effects`): along such a
/// chain the wavelengths share every direction, and most of a smooth film's noise is the
/// four-wavelength estimate of its interference colour.
fn specular_chain_decision(
    scene: &Scene,
    options: &RenderOptions,
    polarized: bool,
    effects: &mut Effects,
) -> bool {
    let mut reflectors: Vec<String> = Vec::new();
    for s in &scene.shapes {
        let b = &scene.bsdfs[s.bsdf];
        if integrator::starts_chain(b) {
            let d = b.describe();
            if !reflectors.contains(&d) {
                reflectors.push(d);
            }
        }
    }
    let off = if reflectors.is_empty() {
        Some("no smooth film or coating that only reflects")
    } else if options.plain_specular_chains {
        Some("four wavelengths asked for (--plain-specular-chains)")
    } else if polarized {
        Some("polarised transport (Stokes vectors)")
    } else if scene.media.is_some() {
        Some("participating media")
    } else {
        None
    };
    effects.decide_unless(effects::Effect::SpecularChainWavelengths, off, || {
        format!(
            "paths from the camera that only reflect off Dirac reflectors, first off a film or coating ({}), carry 8 wavelengths to the emitter they meet",
            reflectors.join(", ")
        )
    })
}

/// The global sample indices to render: the options' range, else 0..spp.
fn sample_range(scene: &Scene, options: &RenderOptions) -> Result<(u32, u32)> {
    let spp = options.spp.unwrap_or(scene.spp);
    match options.sample_range {
        Some((a, b)) => {
            if a >= b {
                bail!("sample range {a}:{b} is empty: START must be < END");
            }
            Ok((a, b))
        }
        None => {
            if spp == 0 {
                bail!("samples per pixel must be ≥ 1");
            }
            Ok((0, spp))
        }
    }
}

/// Refuses a render whose buffers would exceed the memory budget (see [`render_prepared`]):
/// the rows of filter splats, the accumulated and final images and the PNG bytes, plus one
/// pixel's samples per thread.
fn check_render_memory(
    filter: &Filter,
    width: u32,
    height: u32,
    sample_range: (u32, u32),
    threads: Option<usize>,
) -> Result<()> {
    let rows = match filter {
        Filter::Box => 1,
        _ => 2 * filter.radius().ceil() as u64 + 1,
    };
    let pixels = width as u64 * height as u64;
    let threads = threads.unwrap_or_else(rayon::current_num_threads) as u64;
    let samples = (sample_range.1 - sample_range.0) as u64;
    let bytes = pixels
        .saturating_mul(16 * rows + 16 + 12 + 3)
        .saturating_add(threads.saturating_mul(samples).saturating_mul(12));
    crate::limits::check_alloc(
        format!("a {width}×{height} render of {samples} samples per pixel"),
        bytes,
    )
}

use batch::{BatchSpan, Lanes, BATCH};

/// Camera samples traced as one wavefront ([`trace_batches`]) at most: four full batches of
/// [`BATCH`] (one pixel at 64 spp, four pixels at 16 spp, 16 pixels at 4 spp). Measured (one
/// thread, diffuse teapot and Cornell box, alternating runs): one batch per wavefront → four:
/// −4 to −6 % render time at 64 spp; eight or sixteen full batches: no further gain.
const WAVEFRONT_SAMPLES: usize = 4 * BATCH;
/// Camera batches per wavefront at most: batches that are not full (a pixel's last, or 9–15
/// spp, where a batch holds one pixel) still fill a wavefront up to [`WAVEFRONT_SAMPLES`].
const WAVEFRONT_JOBS: usize = 16;

/// A camera batch whose paths are in the wavefront: its camera samples, the radiance of its
/// rays that escaped, and which lanes of the wavefront carry its other samples.
struct StartedBatch {
    cam: batch::CameraBatch,
    radiance: [Lanes; 4],
    /// The expected colour of the lanes whose rays escaped, where it is in closed form
    /// (`PreparedScene::closed_form_direct_view`; those lanes' radiance is left zero).
    escaped_rgb: Option<([bool; BATCH], [[f32; 3]; BATCH])>,
    /// Whether the batch's wavelengths were mapped ([`batch::CameraBatch::sample_wavelengths`]):
    /// not when every ray saw the closed-form background.
    wavelengths: bool,
    /// Sample of the batch traced by wavefront lane `lanes.start + j`.
    hit_index: [usize; BATCH],
    lanes: std::ops::Range<usize>,
}

impl StartedBatch {
    /// A slot of the wavefront, filled by [`start_batch`] (in place: see
    /// [`batch::CameraBatch::generate`]).
    fn empty() -> Self {
        StartedBatch {
            cam: batch::CameraBatch::empty(),
            radiance: [[0.0; BATCH]; 4],
            escaped_rgb: None,
            wavelengths: false,
            hit_index: [0; BATCH],
            lanes: 0..0,
        }
    }
}

/// What [`trace_batches`] keeps between calls (one per thread).
struct WaveScratch<C> {
    paths: integrator::PathScratch<C>,
    started: Vec<StartedBatch>,
    /// A batch's camera rays and hits when they go through the BVH.
    rays: Vec<camera::Ray>,
    hits: Vec<Option<accel::Hit>>,
}

impl<C> Default for WaveScratch<C> {
    fn default() -> Self {
        WaveScratch {
            paths: Default::default(),
            started: Vec::with_capacity(WAVEFRONT_JOBS),
            rays: Vec::with_capacity(BATCH),
            hits: Vec::with_capacity(BATCH),
        }
    }
}

/// The camera batches `jobs` (at most [`WAVEFRONT_JOBS`], [`WAVEFRONT_SAMPLES`] samples)
/// traced together, stage by stage: each batch's camera samples ([`batch::CameraBatch`]),
/// first hits ([`camera_hits`]) and the
/// environment seen by its rays that escape (one batch of lookups); then the paths of every
/// batch's rays that hit, as one wavefront ([`integrator::trace_lanes`], carrying `C`): more
/// rays per traversal call, environment lookup and shadow query than one batch has, and more
/// independent memory accesses in flight; then film values. A sample's values do not depend
/// on the batch or wavefront it is traced in. Writes (film position, finite linear sRGB) per
/// sample, the jobs' samples in order.
fn trace_batches<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    jobs: &[BatchSpan],
    out: &mut [FilmSample],
    scratch: &mut WaveScratch<C>,
) {
    debug_assert!(jobs.len() <= WAVEFRONT_JOBS);
    debug_assert_eq!(out.len(), jobs.iter().map(|j| j.lanes()).sum::<usize>());
    let WaveScratch {
        paths,
        started,
        rays,
        hits,
    } = scratch;
    paths.clear_paths();
    paths.closed_form_direct_view = scene.closed_form_direct_view;
    if started.len() < jobs.len() {
        started.resize_with(jobs.len(), StartedBatch::empty);
    }
    for (job, s) in jobs.iter().zip(started.iter_mut()) {
        start_batch(scene, setup, job, paths, rays, hits, s);
    }
    if !paths.lanes.is_empty() {
        integrator::trace_lanes(scene, setup, paths);
    }
    let mut out = out;
    for (s, job) in started.iter().zip(jobs) {
        let (this, rest) = out.split_at_mut(job.lanes());
        finish_batch(s, &paths.lanes, this);
        out = rest;
    }
}

/// Closest hits of the camera rays of `span` (`cam`): through the screen bins, pixel by
/// pixel, when there are some and the camera is a pinhole; else together through the BVH (one
/// packet traversal where they are coherent, [`accel::Accel::intersect_batch`]).
#[inline]
fn camera_hits(
    scene: &PreparedScene,
    span: &BatchSpan,
    cam: &batch::CameraBatch,
    rays: &mut Vec<camera::Ray>,
    hits: &mut Vec<Option<accel::Hit>>,
) -> [Option<accel::Hit>; BATCH] {
    let m = span.lanes();
    let mut first_hits = [None; BATCH];
    match (&scene.primary_bins, cam.origins.is_some()) {
        (Some(bins), false) => {
            let len = span.len as usize;
            for j in 0..span.pixels as usize {
                // Pixel j's rays moved to lanes 0.. (the first pixel's are there already).
                let moved;
                let rays = if j == 0 {
                    &cam.rays
                } else {
                    moved = cam.rays.from_lane(j * len);
                    &moved
                };
                let x = span.x0 + j as u32;
                let hits = &mut first_hits[j * len..(j + 1) * len];
                bins.intersect_lanes(&scene.accel, x, span.y, rays, hits);
            }
        }
        _ => {
            rays.clear();
            rays.extend((0..m).map(|i| cam.ray(i)));
            scene.accel.intersect_batch(rays, hits);
            first_hits[..m].copy_from_slice(hits);
        }
    }
    count(Counter::Rays, m as u64);
    first_hits
}

/// The first stages of [`trace_batches`] for one camera batch, into `out`: camera samples,
/// first hits ([`camera_hits`]), the environment of escaped rays; the samples that hit
/// become lanes of `paths`.
fn start_batch<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    span: &BatchSpan,
    paths: &mut integrator::PathScratch<C>,
    rays: &mut Vec<camera::Ray>,
    hits: &mut Vec<Option<accel::Hit>>,
    out: &mut StartedBatch,
) {
    let m = span.lanes();
    let StartedBatch {
        cam,
        radiance,
        escaped_rgb,
        wavelengths,
        hit_index,
        lanes,
    } = out;
    cam.generate(
        &scene.camera,
        scene.sampler,
        scene.seed,
        span,
        [scene.width, scene.height],
        !scene.effects.dispersion,
    );
    let hits = camera_hits(scene, span, cam, rays, hits);
    // Rays that escape see the infinite lights (one batch of lookups, straight on the camera
    // batch's lanes); the others start paths.
    *radiance = [[0.0f32; BATCH]; 4];
    let mut escaped = [false; BATCH];
    for i in 0..m {
        // (Media hook: a camera inside a medium may scatter before the void it sees.)
        escaped[i] = hits[i].is_none() && !scene.camera_in_medium();
    }
    // perf: a batch whose rays all see the environment's closed-form colour needs no
    // wavelengths (most of a teapot scene's batches).
    *wavelengths = !(scene.closed_form_direct_view && escaped[..m].iter().all(|&e| e));
    if *wavelengths {
        cam.sample_wavelengths();
    }
    *hit_index = [0usize; BATCH];
    let first_lane = paths.lanes.len();
    let chain_wl = (scene.specular_chains && *wavelengths)
        .then(|| cam.chain_wavelengths::<{ integrator::EXTRA_SETS }>());
    for i in 0..m {
        match hits[i] {
            _ if escaped[i] => {}
            hit => {
                hit_index[paths.lanes.len() - first_lane] = i;
                let lane = integrator::Lane::camera(
                    cam.ray(i),
                    cam.wavelengths(i),
                    cam.d65(i),
                    cam.samplers[i],
                );
                let sets = chain_wl.as_ref().map(|sets| sets.map(|set| set[i]));
                paths.push_camera_path(lane, hit, sets);
            }
        }
    }
    *escaped_rgb = None;
    let any_escaped = escaped.iter().any(|&e| e);
    if any_escaped && scene.closed_form_direct_view {
        let mut rgb = [[0.0f32; 3]; BATCH];
        if !scene.settings().hide_emitters {
            (scene.lights()).add_background_colour_lanes(&cam.rays.dir, &escaped, &mut rgb);
            let pass = C::direct_view(setup);
            if pass != 1.0 {
                rgb = rgb.map(|c| c.map(|v| v * pass));
            }
        }
        *escaped_rgb = Some((escaped, rgb));
    } else if any_escaped {
        integrator::escaped_camera_radiance_lanes(
            scene,
            &cam.rays.dir,
            &cam.lambda,
            &cam.d65_lanes(),
            &escaped,
            radiance,
        );
        let pass = C::direct_view(setup);
        if pass != 1.0 {
            for row in radiance.iter_mut() {
                for (v, &e) in row.iter_mut().zip(&escaped) {
                    if e {
                        *v *= pass;
                    }
                }
            }
        }
    }
    *lanes = first_lane..paths.lanes.len();
}

/// The last stage of [`trace_batches`] for one camera batch: its samples' film values from
/// the radiance of its escaped rays and of its traced lanes.
fn finish_batch<C: Carrier>(
    s: &StartedBatch,
    lanes: &[integrator::Lane<C>],
    out: &mut [FilmSample],
) {
    let mut radiance = s.radiance;
    let mut pdf = s.cam.pdf;
    for (&i, lane) in s.hit_index.iter().zip(&lanes[s.lanes.clone()]) {
        let l = lane.radiance();
        // A dispersive refraction may have terminated secondary wavelengths.
        for k in 0..4 {
            radiance[k][i] = l[k];
            pdf[k][i] = lane.wl.pdf[k];
        }
    }
    let mut rgb = if s.wavelengths {
        s.cam.to_rgb_lanes(&radiance, &pdf)
    } else {
        [[0.0; 3]; BATCH]
    };
    if let Some((escaped, colour)) = &s.escaped_rgb {
        for ((rgb, &e), c) in rgb.iter_mut().zip(escaped).zip(colour) {
            if e {
                *rgb = *c;
            }
        }
    }
    // Emitters the traced lanes saw directly, in closed form (only where there are some:
    // adding +0 would turn a −0 into +0).
    for (&i, lane) in s.hit_index.iter().zip(&lanes[s.lanes.clone()]) {
        if lane.colour() != [0.0; 3] {
            for (v, c) in rgb[i].iter_mut().zip(lane.colour()) {
                *v += c;
            }
        }
    }
    let mut vertices = [0u32; BATCH];
    for (&i, lane) in s.hit_index.iter().zip(&lanes[s.lanes.clone()]) {
        vertices[i] = lane.vertices();
    }
    for (i, o) in out.iter_mut().enumerate() {
        *o = FilmSample {
            pos: Vec2::new(s.cam.pos[0][i], s.cam.pos[1][i]),
            rgb: finite_rgb(rgb[i]),
            vertices: vertices[i],
        };
    }
}

/// A traced camera sample: its film position, its finite linear sRGB value and the path
/// vertices it reached (0 when the camera ray saw no surface; [`adaptive`] weighs a pixel's
/// samples by this work).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct FilmSample {
    pos: Vec2,
    rgb: [f32; 3],
    vertices: u32,
}

/// The number u ∈ [0, 1) whose hero set {u + k/4 mod 1} are a sample's four wavelengths,
/// from 32 sampler bits whose *high* bits are stratified across a pixel's samples.
///
/// The hero set depends only on u mod ¼: the quarter ⌊4u⌋ only chooses which of the four is
/// the hero. Mapping a stratified number straight to u would spend its two most significant
/// (best stratified) digits on that choice, so 16 Sobol' samples would place their 64
/// wavelengths in only 16 strata (4 per stratum). Here the stratified bits become
/// u mod ¼ and two low, random bits pick the quarter: the 64 wavelengths of 16 samples fall
/// one per 1/64 stratum (test `hero_sets_of_stratified_samples_fill_every_stratum`), which
/// cut the colour noise of a 16-spp teapot by ~4× (mean ΔE00 1.47 → see README). The
/// distribution of each single sample is unchanged (u uniform).
#[inline]
pub(crate) fn hero_wavelength_u(bits: u32) -> f32 {
    let quarter = bits & 3;
    let offset = bits >> 10; // 22 stratified bits: u mod ¼ in units of 2^−24
    ((quarter << 22) | offset) as f32 * (1.0 / 16_777_216.0)
}

/// A sample's RGB, or black (counted) if it is NaN or infinite.
#[inline]
fn finite_rgb(rgb: [f32; 3]) -> [f32; 3] {
    if rgb.iter().all(|v| v.is_finite()) {
        rgb
    } else {
        count(Counter::InvalidSamples, 1);
        [0.0; 3]
    }
}

/// Per-pixel film accumulator of a set of samples: `[Σ w·R, Σ w·G, Σ w·B, Σ w]` (box filter:
/// w = 1 per sample, so the last entry is the sample count).
type Accum = Vec<[f32; 4]>;

fn add_accum(dst: &mut Accum, src: &Accum) {
    for (d, s) in dst.iter_mut().zip(src) {
        for k in 0..4 {
            d[k] += s[k];
        }
    }
}

/// How a pass's samples become pixels: with the box filter each pixel keeps its own samples
/// (summed as a tree, see [`film`]); wider filters splat every sample onto the pixels of rows
/// y − `reach` ..= y + `reach` within their radius.
struct Accumulation {
    filter: Filter,
    radius: f32,
    reach: i64,
    width: usize,
    height: usize,
}

impl Accumulation {
    fn of(scene: &PreparedScene) -> Self {
        let filter = scene.filter;
        let radius = filter.radius();
        let reach = if matches!(filter, Filter::Box) {
            0
        } else {
            radius.ceil() as i64
        };
        Accumulation {
            filter,
            radius,
            reach,
            width: scene.width as usize,
            height: scene.height as usize,
        }
    }

    /// Adds sample `rgb` at film position `pos` (generated in row `y`) to the row buffer
    /// `buf` of splat rows y − reach ..= y + reach: onto every pixel whose centre lies within
    /// the filter radius.
    fn splat(&self, buf: &mut [[f32; 4]], y: usize, pos: Vec2, rgb: [f32; 3]) {
        let (w, h, reach) = (self.width, self.height as i64, self.reach);
        let x_lo = ((pos.x - 0.5 - self.radius).ceil() as i64).max(0);
        let x_hi = ((pos.x - 0.5 + self.radius).floor() as i64).min(w as i64 - 1);
        for py in (y as i64 - reach)..=(y as i64 + reach) {
            if py < 0 || py >= h {
                continue;
            }
            let wy = self.filter.eval_1d(py as f32 + 0.5 - pos.y);
            if wy <= 0.0 {
                continue;
            }
            for px in x_lo..=x_hi {
                let wgt = wy * self.filter.eval_1d(px as f32 + 0.5 - pos.x);
                if wgt > 0.0 {
                    let cell = &mut buf[(py - y as i64 + reach) as usize * w + px as usize];
                    cell[0] += wgt * rgb[0];
                    cell[1] += wgt * rgb[1];
                    cell[2] += wgt * rgb[2];
                    cell[3] += wgt;
                }
            }
        }
    }

    /// The pass's accumulator from the rows' buffers, merged in a fixed order (the result
    /// does not depend on scheduling).
    fn merge(&self, rows: &[Vec<[f32; 4]>]) -> Accum {
        let (w, h, reach) = (self.width, self.height, self.reach);
        let mut acc = vec![[0.0f32; 4]; w * h];
        for (y, row) in rows.iter().enumerate() {
            if reach == 0 {
                acc[y * w..(y + 1) * w].copy_from_slice(row);
                continue;
            }
            for r in 0..(2 * reach + 1) as usize {
                let py = y as i64 - reach + r as i64;
                if py < 0 || py >= h as i64 {
                    continue;
                }
                for x in 0..w {
                    let src = row[r * w + x];
                    let dst = &mut acc[py as usize * w + x];
                    for k in 0..4 {
                        dst[k] += src[k];
                    }
                }
            }
        }
        acc
    }
}

/// The camera batches of row `y`, samples `[p0, p1)` of every pixel, in pixel order: each
/// pixel's samples [`BATCH`] at a time, or — below [`BATCH`] samples per pixel — all samples of
/// as many neighbouring pixels as fill a batch.
fn row_batches(width: u32, y: u32, (p0, p1): (u32, u32)) -> impl Iterator<Item = BatchSpan> {
    // `step` pixels per batch, `len` samples of each.
    let n = p1 - p0;
    let (step, len) = if n >= BATCH as u32 {
        (1, BATCH as u32)
    } else {
        (BATCH as u32 / n.max(1), n)
    };
    (0..width).step_by(step as usize).flat_map(move |x0| {
        let pixels = step.min(width - x0);
        (p0..p1)
            .step_by(len.max(1) as usize)
            .map(move |first| BatchSpan {
                x0,
                y,
                pixels,
                first,
                len: len.min(p1 - first),
            })
    })
}

/// The camera batches of row `y` when pixel `x` takes samples `[start, start + counts[x])`:
/// each pixel's samples [`BATCH`] at a time.
fn pixel_batches(counts: &[u32], y: u32, start: u32) -> impl Iterator<Item = BatchSpan> + '_ {
    (counts.iter().enumerate()).flat_map(move |(x, &n)| {
        (start..start + n)
            .step_by(BATCH)
            .map(move |first| BatchSpan {
                x0: x as u32,
                y,
                pixels: 1,
                first,
                len: (BATCH as u32).min(start + n - first),
            })
    })
}

/// Which samples a pass renders.
#[derive(Clone, Copy)]
enum PassSamples<'a> {
    /// Samples `[p0, p1)` of every pixel.
    Every((u32, u32)),
    /// Samples `[start, start + counts[i])` of pixel `i` (row-major; box filter only).
    PerPixel { start: u32, counts: &'a [u32] },
}

impl PassSamples<'_> {
    /// Samples of row `y` (of `width` pixels), for the progress bar.
    fn in_row(&self, y: usize, width: usize) -> u64 {
        match *self {
            PassSamples::Every((p0, p1)) => width as u64 * (p1 - p0) as u64,
            PassSamples::PerPixel { counts, .. } => counts[y * width..(y + 1) * width]
                .iter()
                .map(|&n| n as u64)
                .sum(),
        }
    }
}

/// Per pixel of a row (when asked for, else empty): the samples'
/// [`adaptive::sum_squared_deviations`] and their summed [`adaptive::sample_cost`].
#[derive(Default)]
struct RowSpread {
    m2: Vec<f32>,
    work_done: Vec<f32>,
}

/// What [`render_row`] hands back: its buffer ([`Accumulation`]), this thread's work counters
/// for it and its [`RowSpread`].
type RowResult = (Vec<[f32; 4]>, Counters, RowSpread);

/// Row `y`: the pass's samples of every pixel, [`BATCH`] at a time, several batches per
/// wavefront ([`trace_batches`]), carrying `C`. With `spread` (box filter, every pixel's
/// samples `[p0, p1)`), also each pixel's spread for [`adaptive`].
fn render_row<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    acc: &Accumulation,
    work: PassSamples,
    y: usize,
    spread: bool,
) -> RowResult {
    counters::take();
    let (w, reach) = (acc.width, acc.reach);
    let (p0, n) = match work {
        PassSamples::Every((p0, p1)) => (p0, (p1 - p0) as usize),
        // Summed batch by batch (the extra samples' sums need not merge exactly).
        PassSamples::PerPixel { start, .. } => (start, BATCH),
    };
    // One pixel's samples, summed in order once its last one is in (box filter).
    let mut samples = vec![[0.0f32; 3]; n];
    let rows = (2 * reach + 1) as usize;
    let mut buf = vec![[0.0f32; 4]; if reach == 0 { w } else { rows * w }];
    let mut m2 = if spread { vec![0.0f32; w] } else { Vec::new() };
    let mut work_done = if spread { vec![0.0f32; w] } else { Vec::new() };
    let mut out = [FilmSample::default(); WAVEFRONT_SAMPLES];
    let mut scratch = WaveScratch::<C>::default();
    let jobs: Box<dyn Iterator<Item = BatchSpan>> = match work {
        PassSamples::Every(range) => Box::new(row_batches(w as u32, y as u32, range)),
        PassSamples::PerPixel { start, counts } => {
            Box::new(pixel_batches(&counts[y * w..(y + 1) * w], y as u32, start))
        }
    };
    let mut wave = Vec::with_capacity(WAVEFRONT_JOBS);
    let mut jobs = jobs.peekable();
    while jobs.peek().is_some() {
        wave.clear();
        let mut lanes = 0;
        while let Some(job) =
            jobs.next_if(|j| wave.len() < WAVEFRONT_JOBS && lanes + j.lanes() <= WAVEFRONT_SAMPLES)
        {
            lanes += job.lanes();
            wave.push(job);
        }
        trace_batches(scene, setup, &wave, &mut out[..lanes], &mut scratch);
        let mut done = out[..lanes].iter();
        for job in &wave {
            if let PassSamples::PerPixel { .. } = work {
                debug_assert_eq!(reach, 0, "per-pixel counts need the box filter");
                let k = job.lanes();
                for (s, sample) in samples.iter_mut().zip(done.by_ref().take(k)) {
                    *s = sample.rgb;
                }
                let sum = tree_sum_in_place(&mut samples[..k]);
                let cell = &mut buf[job.x0 as usize];
                *cell = [
                    cell[0] + sum[0],
                    cell[1] + sum[1],
                    cell[2] + sum[2],
                    cell[3] + k as f32,
                ];
                continue;
            }
            for ((j, k), sample) in job.lane_samples().zip(done.by_ref()) {
                if reach != 0 {
                    acc.splat(&mut buf, y, sample.pos, sample.rgb);
                    continue;
                }
                let i = (job.first - p0 + k) as usize;
                let x = (job.x0 + j) as usize;
                samples[i] = sample.rgb;
                if spread {
                    work_done[x] += adaptive::sample_cost(sample.vertices);
                }
                if i + 1 == n {
                    if spread {
                        m2[x] = adaptive::sum_squared_deviations(&samples);
                    }
                    let sum = tree_sum_in_place(&mut samples);
                    buf[x] = [sum[0], sum[1], sum[2], n as f32];
                }
            }
        }
    }
    (buf, counters::take(), RowSpread { m2, work_done })
}

/// The pass's samples of every pixel carrying `C`: the pass's accumulator, work counters and
/// (with `spread`) per-pixel spread, or None when `cancelled()` turned true before every row
/// was done. One row per task: rows cost very different amounts (background vs object), and
/// rayon's adaptive splitting otherwise left one of two threads idle ~10 % of a teapot render
/// (measured: 2-thread speed-up 1.77× → 1.94×).
fn render_pass<C: Carrier>(
    scene: &PreparedScene,
    setup: &C::Setup,
    acc: &Accumulation,
    work: PassSamples,
    spread: bool,
    pb: &indicatif::ProgressBar,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Option<(Accum, Counters, RowSpread)> {
    let rows: Vec<Option<RowResult>> = (0..acc.height)
        .into_par_iter()
        .with_max_len(1)
        .map(|y| {
            if cancelled() {
                return None;
            }
            let row = render_row::<C>(scene, setup, acc, work, y, spread);
            pb.inc(work.in_row(y, acc.width) / acc.width as u64);
            Some(row)
        })
        .collect();
    let mut counters = Counters::default();
    let mut buffers = Vec::with_capacity(rows.len());
    let mut spread = RowSpread::default();
    for row in rows {
        let (buf, c, row_spread) = row?;
        counters.add(&c);
        buffers.push(buf);
        spread.m2.extend(row_spread.m2);
        spread.work_done.extend(row_spread.work_done);
    }
    Some((acc.merge(&buffers), counters, spread))
}

/// [`render_pass`] with the scene's carrier (Stokes vectors when polarised), in `pool`.
fn render_pass_in(
    scene: &PreparedScene,
    acc: &Accumulation,
    work: PassSamples,
    spread: bool,
    pb: &indicatif::ProgressBar,
    cancelled: &(dyn Fn() -> bool + Sync),
    pool: Option<&rayon::ThreadPool>,
) -> Option<(Accum, Counters, RowSpread)> {
    let pass = || match scene.polarized() {
        None => render_pass::<Spec>(scene, &(), acc, work, spread, pb, cancelled),
        Some(setup) => {
            render_pass::<stokes::StokesPath>(scene, setup, acc, work, spread, pb, cancelled)
        }
    };
    match pool {
        Some(pool) => pool.install(pass),
        None => pass(),
    }
}

/// What the passes of a render produced: its blocks' sums, or the completed prefix of an
/// interrupted render.
struct Passes {
    /// Completed blocks.
    blocks: Vec<Accum>,
    /// On interruption, the completed part of the first block and its end.
    prefix: Option<(Accum, u32)>,
    interrupted: bool,
    counters: Counters,
    /// With adaptive sample counts, every pixel's spread.
    spread: Option<adaptive::Spread>,
}

/// Runs the passes of [`passes::plan`] in order, stopping between passes (and rows) when
/// `cancelled()` turns true; with `spread`, keeps every pixel's spread for [`adaptive`].
fn run_passes(
    scene: &PreparedScene,
    plan: &[passes::Block],
    spread: bool,
    pb: &indicatif::ProgressBar,
    cancelled: &(dyn Fn() -> bool + Sync),
    pool: Option<&rayon::ThreadPool>,
) -> Passes {
    let acc = Accumulation::of(scene);
    let (s0, s1) = scene.sample_range;
    let mut out = Passes {
        blocks: Vec::new(),
        prefix: None,
        interrupted: false,
        counters: Counters::default(),
        spread: spread.then(adaptive::Spread::default),
    };
    'blocks: for block in plan {
        let mut sum: Option<Accum> = None;
        let mut done = block.range.0;
        for &(p0, p1) in &block.passes {
            pb.set_message(format!("{p0}:{p1} of {s0}:{s1}"));
            let work = PassSamples::Every((p0, p1));
            let result = render_pass_in(scene, &acc, work, spread, pb, cancelled, pool);
            let Some((pass_acc, c, pass_spread)) = result else {
                out.interrupted = true;
                if out.blocks.is_empty() {
                    // The first block's running sum is the power-of-two prefix [s0, done).
                    out.prefix = sum.map(|s| (s, done));
                }
                break 'blocks;
            };
            out.counters.add(&c);
            if let Some(spread) = &mut out.spread {
                spread.add_pass(&pass_spread.m2, &pass_spread.work_done, p1 - p0);
            }
            match &mut sum {
                None => sum = Some(pass_acc),
                Some(s) => add_accum(s, &pass_acc),
            }
            done = p1;
        }
        out.blocks.extend(sum);
        if cancelled() && block.range.1 < s1 {
            out.interrupted = true;
            break;
        }
    }
    out
}

/// The extra samples of an adaptive render (every pixel's `spread` over the range known): per
/// pixel, counts from [`adaptive::extra_counts`] after the range. Their accumulator, counters
/// and the number of samples, or None when cancelled.
fn run_extra_samples(
    scene: &PreparedScene,
    spread: &adaptive::Spread,
    pb: &indicatif::ProgressBar,
    cancelled: &(dyn Fn() -> bool + Sync),
    pool: Option<&rayon::ThreadPool>,
) -> Option<(Accum, Counters, u64)> {
    let (w, h) = (scene.width as usize, scene.height as usize);
    let (s0, s1) = scene.sample_range;
    let spp = s1 - s0;
    let cap = adaptive::MAX_EXTRA_PER_SPP * spp;
    // Sobol' pixels take whole blocks of a power of two (each a stratified set).
    let granule = match scene.sampler {
        sampler::SamplerKind::Sobol => 1 << (u32::BITS - 1 - spp.leading_zeros()),
        sampler::SamplerKind::Independent => 1,
    };
    let extra = adaptive::extra_budget(spp);
    let counts = adaptive::extra_counts(spread, (w, h), extra, cap, granule);
    let total: u64 = counts.iter().map(|&n| n as u64).sum();
    // The bar counts rows × samples per pixel.
    pb.inc_length(total / w as u64);
    pb.set_message(format!("{s1}:… where pixels are noisy, after {s0}:{s1}"));
    let work = PassSamples::PerPixel {
        start: s1,
        counts: &counts,
    };
    let acc = Accumulation::of(scene);
    let (sum, counters, _) = render_pass_in(scene, &acc, work, false, pb, cancelled, pool)?;
    Some((sum, counters, total))
}

/// Renders a prepared scene, pass by pass ([`passes`]); with adaptive sample counts, then the
/// extra samples ([`adaptive`]). When `options.cancel` is raised the render
/// stops between rows, drops the unfinished pass and returns the longest completed
/// power-of-two prefix of its samples (`interrupted` set, `sample_range` saying which), or an
/// error when not even the first pass was complete.
pub fn render_prepared(scene: &PreparedScene, options: &RenderOptions) -> Result<RenderOutput> {
    let start = Instant::now();
    let (w, h) = (scene.width as usize, scene.height as usize);
    let (s0, s1) = scene.sample_range;
    let total = (s1 - s0) as u64;
    let pb = progress::bar(
        options.progress,
        h as u64 * total,
        "{spinner} [{elapsed_precise}] {bar:40.cyan/blue} {percent:>3}% samples {msg} ({eta} left)",
    );
    let cancelled = || options.cancel.as_ref().is_some_and(|c| (c.0)());
    let threads = match options.threads {
        Some(0) => bail!("--threads must be ≥ 1"),
        Some(t) => t,
        None => rayon::current_num_threads(),
    };
    let pool = match options.threads {
        Some(t) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .context("creating the thread pool")?,
        ),
        None => None,
    };
    let plan = passes::plan(scene.sample_range);
    let Passes {
        mut blocks,
        mut prefix,
        mut interrupted,
        mut counters,
        spread,
    } = run_passes(scene, &plan, scene.adaptive, &pb, &cancelled, pool.as_ref());
    let mut extra = None;
    if let (Some(spread), false) = (&spread, interrupted) {
        extra = run_extra_samples(scene, spread, &pb, &cancelled, pool.as_ref());
        // Cancelled among the extra samples: the power-of-two prefix, as below.
        interrupted = extra.is_none();
    }
    pb.finish_and_clear();
    let (mut acc, range) = if interrupted {
        if prefix.is_none() && !blocks.is_empty() {
            let first = blocks.swap_remove(0);
            prefix = Some((first, plan[0].range.1));
        }
        match prefix {
            Some((acc, end)) => (acc, (s0, end)),
            None => bail!(
                "interrupted before the first sample pass ({s0}:{}) was complete; nothing to write",
                plan[0].passes[0].1
            ),
        }
    } else {
        // Blocks combine right to left, like the film's summation tree.
        let acc = blocks
            .into_iter()
            .rev()
            .reduce(|mut acc, mut b| {
                std::mem::swap(&mut acc, &mut b);
                add_accum(&mut acc, &b);
                acc
            })
            .context("no samples rendered")?;
        (acc, (s0, s1))
    };
    let mut samples = (w * h) as u64 * (range.1 - range.0) as u64;
    if let (Some((sum, c, n)), false) = (&extra, interrupted) {
        add_accum(&mut acc, sum);
        counters.add(c);
        samples += n;
    }
    let mut image = RgbImage::new(w, h);
    for (dst, p) in image.pixels.iter_mut().zip(&acc) {
        *dst = if p[3] > 0.0 {
            [p[0] / p[3], p[1] / p[3], p[2] / p[3]]
        } else {
            [0.0; 3]
        };
    }
    let filter_weights =
        (!matches!(scene.filter, Filter::Box)).then(|| acc.iter().map(|p| p[3]).collect());
    let seconds = start.elapsed().as_secs_f64();
    Ok(RenderOutput {
        image,
        filter_weights,
        stats: RenderStats {
            seconds,
            setup_seconds: 0.0,
            samples,
            rays: counters.rays,
            shadow_rays: counters.shadow_rays,
            film_evals: counters.film_evals,
            secondary_terminations: counters.secondary_terminations,
            invalid_samples: counters.invalid_samples,
            triangles: scene.accel.triangle_count(),
            degenerate_triangles: scene.degenerate_triangles,
            threads,
        },
        effects: scene.effects.clone(),
        sample_range: range,
        requested_range: scene.sample_range,
        interrupted,
        adaptive: extra.is_some() && !interrupted,
    })
}

/// Renders `scene` with command-line overrides.
pub fn render(scene: &Scene, options: &RenderOptions) -> Result<RenderOutput> {
    let t0 = Instant::now();
    let prepared = prepare(scene, options)?;
    let setup = t0.elapsed().as_secs_f64();
    let mut out = render_prepared(&prepared, options)?;
    out.stats.setup_seconds = setup;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample's film position and RGB do not depend on the batch or wavefront it is traced
    /// in (bit for bit): full and partial batches, alone and in wavefronts of batches from
    /// several pixels (up to [`WAVEFRONT_JOBS`]), batches of several pixels' samples, against
    /// each sample traced alone; nor do the work counters. On the teapot (camera rays through
    /// the BVH; pixels that see the teapot, its reflections and the bare environment) and the
    /// Cornell box (camera rays through the screen bins).
    #[test]
    fn samples_do_not_depend_on_their_batch() {
        for (name, binned) in [("teapot_mgf2_400", false), ("cornell_box", true)] {
            samples_do_not_depend_on_their_batch_in(name, binned);
        }
    }

    fn samples_do_not_depend_on_their_batch_in(name: &str, binned: bool) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(format!("{name}.xml"));
        let scene = crate::scene::load(&path, &[]).unwrap();
        let options = RenderOptions {
            resolution: Some((32, 32)),
            spp: Some(16),
            ..Default::default()
        };
        let p = prepare(&scene, &options).unwrap();
        assert!(p.polarized.is_none());
        assert_eq!(p.primary_bins().is_some(), binned, "{name}");
        let job = |(x, y): (u32, u32), first: u32, len: u32| BatchSpan {
            x0: x,
            y,
            pixels: 1,
            first,
            len,
        };
        let pixels = [(16, 16), (3, 2), (20, 12), (10, 22), (31, 31)];
        let mut waves: Vec<Vec<BatchSpan>> = Vec::new();
        for &px in &pixels {
            for len in [BATCH as u32, 3, 1] {
                waves.push(vec![job(px, 5, len)]);
            }
        }
        // Wavefronts of up to four batches: several pixels, partial batches among full ones.
        waves.push(
            pixels[..4]
                .iter()
                .map(|&px| job(px, 5, BATCH as u32))
                .collect(),
        );
        waves.push(vec![
            job(pixels[0], 5, 3),
            job(pixels[4], 40, BATCH as u32),
            job(pixels[1], 0, 1),
            job(pixels[0], 21, BATCH as u32),
        ]);
        // As many partial batches as a wavefront takes (low spp).
        let partial = (0..WAVEFRONT_JOBS).map(|k| job(pixels[k % 5], k as u32, 1 + k as u32 % 4));
        waves.push(partial.collect());
        // Batches of several pixels (low spp): 16 × 1, 5 × 3 (a lane left over), 2 × 8, at a
        // row's end, with the rest of the row.
        let row = |x0, pixels, len| BatchSpan {
            x0,
            y: 16,
            pixels,
            first: 2,
            len,
        };
        waves.push(vec![
            row(0, 16, 1),
            row(16, 5, 3),
            row(21, 2, 8),
            row(29, 3, 1),
        ]);
        let mut seen_hit = false;
        let mut scratch = WaveScratch::<Spec>::default();
        for wave in &waves {
            let n = wave.iter().map(|j| j.lanes()).sum();
            let mut out = vec![FilmSample::default(); n];
            counters::take();
            trace_batches(&p, &(), wave, &mut out, &mut scratch);
            let c_wave = counters::take();
            let singles = wave
                .iter()
                .flat_map(|b| b.lane_samples().map(move |jk| (b, jk)));
            for (sample, (b, (j, k))) in out.iter().zip(singles) {
                let (x, s) = (b.x0 + j, b.first + k);
                let mut one = [FilmSample::default()];
                trace_batches(&p, &(), &[job((x, b.y), s, 1)], &mut one, &mut scratch);
                assert_eq!(sample.pos, one[0].pos);
                assert_eq!(sample.vertices, one[0].vertices);
                assert_eq!(
                    sample.rgb.map(f32::to_bits),
                    one[0].rgb.map(f32::to_bits),
                    "pixel ({x}, {}), sample {s}",
                    b.y
                );
            }
            let c_single = counters::take();
            assert_eq!(c_wave, c_single);
            seen_hit |= c_single.film_evals > 0 || c_single.shadow_rays > 0;
        }
        assert!(seen_hit, "{name}: no pixel saw the scene");
    }

    #[test]
    fn hero_sets_of_stratified_samples_fill_every_stratum() {
        use sampler::{Sampler, SamplerKind};
        for (x, y, grid) in [(0, 0, true), (7, 3, true), (100, 250, false), (1, 2, false)] {
            let mut strata = [0u32; 64];
            for s in 0..16 {
                let (bits, _) = Sampler::new(SamplerKind::Sobol, x, y, s, 4).camera_sample(grid);
                let u = hero_wavelength_u(bits);
                assert!((0.0..1.0).contains(&u));
                for k in 0..4 {
                    let v = (u + k as f32 * 0.25) % 1.0;
                    strata[(v * 64.0) as usize] += 1;
                }
            }
            assert!(
                strata.iter().all(|&n| n == 1),
                "pixel ({x}, {y}): {strata:?}"
            );
        }
        // u stays uniform and below 1 at the extremes.
        assert_eq!(hero_wavelength_u(0), 0.0);
        assert!(hero_wavelength_u(u32::MAX) < 1.0);
        assert!((hero_wavelength_u(2) - 0.5).abs() < 1e-7);
    }
}
