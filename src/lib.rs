//! thinfilm — spectral rendering and parameter estimation for thin-film interference.
//!
//! Data flows one way: capture → estimate → material → scene → render → compare.
//! Each module is a room that knows only what it needs:
//! - [`spectrum`]: wavelengths, sampled spectra, CIE tables, XYZ/RGB/Lab, ΔE, RGB→spectrum;
//! - [`optics`]: complex Fresnel, the Airy single film, transfer-matrix stacks, dispersion;
//! - [`capture`]: ENVI cubes, capture sets (`capture.json`), the capture simulator;
//! - [`estimate`]: film index and per-pixel thickness from a capture set;
//! - [`material`]: a fit as types — `fit.json` ([`material::FitFile`]) and the film material
//!   ([`material::FilmMaterial`]) with its `material.xml` / `material.gltf` writers and readers;
//! - [`scene`]: scene description (Mitsuba XML subset, glTF, OBJ, PLY) and assets;
//! - [`render`]: the hero-wavelength spectral path tracer;
//! - [`compare`]: image metrics, side-by-side figures, plots;
//! - [`image_io`]: EXR and PNG reading/writing shared by the stages;
//! - [`limits`]: the memory budget, numeric domains and panic containment every loader uses;
//! - [`stats`]: summary statistics shared by the stages (one percentile definition).

pub mod capture;
pub mod compare;
pub mod demo;
pub mod estimate;
pub mod figure;
pub mod image_io;
pub mod limits;
pub mod material;
pub mod merge;
pub mod optics;
pub mod progress;
pub mod render;
pub mod scene;
pub mod spectrum;
pub mod stats;
