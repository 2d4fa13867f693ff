//! antiradiance: diffuse global illumination on triangle meshes with the antiradiance method.
//!
//! Pipeline, one module per stage: [`scene`] (load OBJ+MTL) -> [`mesh`] (patches in a unit frame)
//! -> [`transport`] (pair couplings over [`bins`]) -> [`dense`] / hierarchical solvers ->
//! [`output`]. [`reference`] is an independent path tracer used as ground truth.

pub mod bins;
pub mod error;
pub mod geometry;
pub mod mesh;
pub mod progress;
pub mod scene;
pub mod solution;

pub use error::{Error, Result};
