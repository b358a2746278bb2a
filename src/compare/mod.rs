//! Image comparison: metrics between two linear-sRGB renders ([`metrics`]) and the small
//! drawing toolkit used for side-by-side figures and heat maps ([`figure`]) and
//! error-against-time plots ([`plot`]).
//!
//! Convention throughout: the *second* image is the reference (`B` in `thinfilm compare A B`),
//! so relative errors and biases are measured relative to it.

pub mod figure;
pub mod metrics;
pub mod plot;
pub mod references;

pub use metrics::{compare_images, downsample_box, match_sizes, ImageMetrics};
