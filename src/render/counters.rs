//! Work counters, kept per thread and summed: whatever runs on a thread adds to that thread's
//! cells ([`count`]), and the renderer takes a thread's totals after each image row
//! ([`take`]) and sums the rows in a fixed order, so the statistics do not depend on
//! scheduling and nothing passes counters through call signatures.

use std::cell::Cell;

/// Work done, summed into the render statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Thin-film or layer-stack evaluations (each covers a path's 4 wavelengths).
    pub film_evals: u64,
    /// Closest-hit rays traced.
    pub rays: u64,
    /// Shadow (occlusion) rays traced.
    pub shadow_rays: u64,
    /// Samples whose estimate was NaN/inf and was discarded.
    pub invalid_samples: u64,
    /// Paths whose secondary wavelengths were terminated at a dispersive interface (0 in a
    /// scene without dispersion: the proof that the 4-wavelength fast path is kept).
    pub secondary_terminations: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.film_evals += o.film_evals;
        self.rays += o.rays;
        self.shadow_rays += o.shadow_rays;
        self.invalid_samples += o.invalid_samples;
        self.secondary_terminations += o.secondary_terminations;
    }
}

/// One counter of [`Counters`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Counter {
    FilmEvals,
    Rays,
    ShadowRays,
    InvalidSamples,
    SecondaryTerminations,
}

struct Cells([Cell<u64>; 5]);

thread_local! {
    static CELLS: Cells = const {
        Cells([Cell::new(0), Cell::new(0), Cell::new(0), Cell::new(0), Cell::new(0)])
    };
}

/// Adds `n` to this thread's `counter`.
#[inline]
pub fn count(counter: Counter, n: u64) {
    CELLS.with(|c| {
        let cell = &c.0[counter as usize];
        cell.set(cell.get() + n);
    });
}

/// This thread's counts since the last `take`, resetting them to zero.
pub fn take() -> Counters {
    CELLS.with(|c| {
        let [f, r, s, i, t] = std::array::from_fn(|k| c.0[k].replace(0));
        Counters {
            film_evals: f,
            rays: r,
            shadow_rays: s,
            invalid_samples: i,
            secondary_terminations: t,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_per_thread_and_taken_once() {
        take();
        count(Counter::Rays, 3);
        count(Counter::FilmEvals, 1);
        let other = std::thread::spawn(|| {
            count(Counter::Rays, 100);
            take()
        })
        .join()
        .unwrap();
        assert_eq!(other.rays, 100);
        let mine = take();
        assert_eq!((mine.rays, mine.film_evals, mine.shadow_rays), (3, 1, 0));
        assert_eq!(take(), Counters::default());
    }
}
