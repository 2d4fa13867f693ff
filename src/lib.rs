//! antiradiance: diffuse global illumination on triangle meshes with the antiradiance method.
//!
//! Pipeline, one module per stage: [`scene`] (load OBJ+MTL) -> [`mesh`] (patches in a unit frame)
//! -> [`transport`] (pair couplings over [`bins`]) -> [`dense`] / hierarchical solvers ->
//! [`output`]. [`reference`] is an independent path tracer used as ground truth. [`relight`]
//! re-solves a prepared scene for new emission (interactive relighting), with an example.

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accelerate;
pub mod bins;
pub mod budget;
pub mod dense;
pub mod direct;
pub mod driver;
pub mod error;
pub mod geometry;
pub mod gltf_in;
pub mod gltf_out;
pub mod health;
pub mod hierarchical;
pub mod hierarchy;
pub mod interiors;
pub mod lights;
pub mod links;
pub mod memory;
pub mod mesh;
pub mod model;
pub mod output;
pub mod progress;
pub mod raytrace;
pub mod reference;
pub mod relight;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod scenes;
pub mod solution;
pub mod solve;
pub mod stage;
pub mod sweep;
pub mod texture;
pub mod transport;
pub mod variants;

pub use error::{Error, Result};
