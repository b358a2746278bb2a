//! Wavelength supersampling of specular reflection chains.
//!
//! A path that has only reflected off Dirac reflectors since the camera
//! ([`Bsdf::is_specular_reflector`]: smooth films, coatings, metals) meets its emitter along
//! directions that every wavelength shares. Beyond the pixel position, the only noise left in
//! its film value is the hero-wavelength estimate Σ_k rgb̄(λ_k)·β(λ_k)·Le(λ_k)/p(λ_k) from four
//! wavelengths — most of a thin-film teapot's noise: its interference colours are 80 % of the
//! ZnS teapot's pixel variance at 64 spp and 60 % of the MgF2 one's (measured with the pixel
//! position held fixed). Such a chain carries a second hero set through the same vertices and
//! random numbers — eight wavelengths in all, stratified: u + j/8 + k/4 for the path's number
//! u, set j ∈ {0, 1} and wavelength k — and an emitter the chain reaches adds the mean of the
//! two sets' film colours. Each set alone is an unbiased estimate (its u is uniform), so the
//! mean keeps the expectation; the price is one more BSDF sample per reflection and one more
//! emitter lookup at the chain's end. Measured on the teapots (256², 64 spp, 4 seeds): pixel
//! variance 0.26× (ZnS) and 0.38× (MgF2) at 1.28× the render time; sixteen wavelengths (three
//! extra sets) gave 0.18× and 0.37× at 1.93×, worse per unit of time. The chain ends — the
//! path goes on with its own set alone — at the first vertex that is not a specular
//! reflector, where Russian roulette starts, or where the other set's sample would leave in
//! another direction.

use super::super::bsdf::{Bsdf, BsdfFlags, BsdfSample, Lobes, ShadingCtx};
use super::super::texture::Spec;
use crate::spectrum::SampledWavelengths;
use glam::{Vec2, Vec3};

/// Hero sets a chain carries besides the path's own.
pub(in crate::render) const EXTRA_SETS: usize = 1;

/// The weight of each of the chain's 1 + [`EXTRA_SETS`] sets in its emitter terms.
pub(super) const SET_SHARE: f32 = 1.0 / (1 + EXTRA_SETS) as f32;

/// Whether a path's first vertex with BSDF `bsdf` starts a chain: a specular reflector
/// whose reflectance oscillates with wavelength — a film or a coating, whose interference
/// colours four wavelengths estimate poorly. (A smooth metal's reflectance is smooth in λ:
/// there sixteen wavelengths removed a fifth of the gold teapot's noise at 1.8× its time,
/// a loss. A chain that has started goes on through any specular reflector.)
pub(in crate::render) fn starts_chain(bsdf: &Bsdf) -> bool {
    bsdf.is_specular_reflector()
        && bsdf
            .flags()
            .intersects(BsdfFlags::INTERFERENCE | BsdfFlags::MULTILAYER)
}

/// Where a path stands with its chain (a branch's part: one byte; the sets live beside the
/// batch's paths, [`ChainSets`]).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum ChainState {
    /// At the camera, with sets: starts at the path's first vertex if [`starts_chain`].
    Unstarted,
    /// Every vertex so far was a specular reflector: emitter terms are the sets' mean.
    Live,
    /// The path goes on (or went on) with its own wavelengths alone.
    Ended,
}

/// The extra hero sets of a camera path and their throughputs along its chain.
#[derive(Clone, Copy)]
pub(super) struct ChainSets {
    wl: [SampledWavelengths; EXTRA_SETS],
    throughput: [Spec; EXTRA_SETS],
}

impl ChainSets {
    /// The sets of a camera path (for a path with number u, set j is
    /// {u + (j + 1)/(4·(EXTRA_SETS + 1)) + k/4}:
    /// [`crate::render::batch::CameraBatch::chain_wavelengths`]).
    #[inline]
    pub fn camera(wl: [SampledWavelengths; EXTRA_SETS]) -> Self {
        ChainSets {
            wl,
            throughput: [Spec::ONE; EXTRA_SETS],
        }
    }

    /// The sets' wavelengths and throughputs.
    #[inline]
    pub fn sets(&self) -> impl Iterator<Item = (&SampledWavelengths, Spec)> {
        self.wl.iter().zip(self.throughput.iter().copied())
    }

    /// Set `j`'s wavelengths.
    #[inline]
    pub fn wavelengths(&self, j: usize) -> &SampledWavelengths {
        &self.wl[j]
    }
}

impl ChainState {
    /// Whether the path is at the end of a live chain: the emitter it meets here counts
    /// [`SET_SHARE`] for its own wavelengths and the same again for each of the sets.
    #[inline]
    pub fn live(self) -> bool {
        self == ChainState::Live
    }

    /// Follows the path across a vertex with BSDF `bsdf` (seen as `ctx`, from `wi`), where
    /// its own wavelengths sampled `sampled` with the random numbers `u1`, `u2`: each of
    /// `sets` samples with the same numbers and multiplies its throughput by its weight. The
    /// chain ends unless the vertex is a specular reflector (the first one: one that
    /// [`starts_chain`]) and every set leaves along the same direction.
    #[inline]
    pub fn scatter(
        &mut self,
        sets: Option<&mut ChainSets>,
        bsdf: &Bsdf,
        ctx: &ShadingCtx,
        wi: Vec3,
        (u1, u2): (f32, Vec2),
        sampled: &BsdfSample,
    ) {
        let sets = match (*self, sets) {
            (ChainState::Ended, _) => return,
            (ChainState::Unstarted, Some(s)) if starts_chain(bsdf) => s,
            (ChainState::Live, Some(s)) if bsdf.is_specular_reflector() => s,
            _ => return *self = ChainState::Ended,
        };
        *self = ChainState::Live;
        for (wl, throughput) in sets.wl.iter().zip(&mut sets.throughput) {
            let ctx = ShadingCtx {
                wl,
                uv: ctx.uv,
                segment: ctx.segment,
                color: ctx.color,
                bump_normal: ctx.bump_normal,
            };
            match bsdf.sample(&ctx, wi, u1, u2, Lobes::ALL) {
                Some(s) if s.wo == sampled.wo && s.is_delta() => *throughput *= s.weight,
                _ => return *self = ChainState::Ended,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Ior;
    use crate::render::bsdf::{conductor::Conductor, thinfilm::ThinFilmBsdf};
    use crate::scene::{SpectrumDesc, TextureDesc};

    fn ctx(wl: &SampledWavelengths) -> ShadingCtx<'_> {
        ShadingCtx {
            wl,
            uv: Vec2::ZERO,
            segment: 0.0,
            color: Vec3::ONE,
            bump_normal: Vec3::Z,
        }
    }

    /// A chain starts at a film, multiplies each set's own weights there and at a smooth
    /// metal, and ends at a diffuse vertex; a metal alone does not start one.
    #[test]
    fn chains_start_at_films_follow_mirrors_and_end_at_diffuse_vertices() {
        let thickness = TextureDesc::Value(SpectrumDesc::Constant(500.0));
        let film: Bsdf = ThinFilmBsdf::new(Ior::real(2.37), &thickness, Ior::real(1.64), 0.0)
            .unwrap()
            .into();
        let gold: Bsdf = Conductor::new("Au".parse().unwrap(), 0.0, 0.0)
            .unwrap()
            .into();
        let diffuse = Bsdf::default_diffuse();
        assert!(starts_chain(&film) && gold.is_specular_reflector() && !starts_chain(&gold));
        assert!(!diffuse.is_specular_reflector());
        let own = SampledWavelengths::sample_visible(0.1);
        let sets = [0.225].map(SampledWavelengths::sample_visible);
        let wi = Vec3::new(0.3, 0.0, 0.954).normalize();
        let u = (0.5, Vec2::new(0.2, 0.7));
        let sample = |b: &Bsdf, wl| b.sample(&ctx(wl), wi, u.0, u.1, Lobes::ALL).unwrap();

        let mut s = ChainSets::camera(sets);
        let mut metal_first = ChainState::Unstarted;
        metal_first.scatter(Some(&mut s), &gold, &ctx(&own), wi, u, &sample(&gold, &own));
        assert!(!metal_first.live());
        metal_first.scatter(Some(&mut s), &film, &ctx(&own), wi, u, &sample(&film, &own));
        assert!(!metal_first.live(), "an ended chain does not start again");

        let mut s = ChainSets::camera(sets);
        let mut chain = ChainState::Unstarted;
        chain.scatter(Some(&mut s), &film, &ctx(&own), wi, u, &sample(&film, &own));
        chain.scatter(Some(&mut s), &gold, &ctx(&own), wi, u, &sample(&gold, &own));
        assert!(chain.live());
        let expected = sets
            .each_ref()
            .map(|wl| sample(&film, wl).weight * sample(&gold, wl).weight);
        for ((wl, t), (set, expected)) in s.sets().zip(sets.iter().zip(expected)) {
            assert_eq!(wl, set);
            assert_eq!(t, expected);
        }
        chain.scatter(
            Some(&mut s),
            &diffuse,
            &ctx(&own),
            wi,
            u,
            &sample(&diffuse, &own),
        );
        assert!(!chain.live());

        let mut off = ChainState::Unstarted;
        off.scatter(None, &film, &ctx(&own), wi, u, &sample(&film, &own));
        assert!(!off.live(), "without sets a chain never starts");
    }
}
