//! antiradiance: diffuse global illumination on triangle meshes with the antiradiance method.
//!
//! One module per stage of the pipeline, each using only the ones before it in this list:
//!
//! - [`geometry`]: exact kernels (solid angles, form factors, clipping), direction bins,
//!   sampling, ray tracing over a BVH and every tolerance;
//! - [`scene`]: what the user gives (OBJ+MTL loading, generated scenes, OBJ writing);
//! - [`mesh`]: the solver's patches in a unit frame (splitting, twins);
//! - [`hierarchy`]: the cluster tree and the links between its nodes;
//! - [`transport`]: the couplings of one sender to one receiver, shared by every solver;
//! - [`solve`]: options and presets, the dense oracle, the hierarchical solver, exact direct
//!   light, relighting, and the [`solve::solution::Solution`] every solver returns;
//! - [`reference`]: the path tracer used as ground truth;
//! - [`output`]: CSV, PLY, PNG pictures, atomic writes.
//!
//! The command line (`src/cli/`, the `cli` feature) is a client of this library like any other.

// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod files;
pub mod geometry;
pub mod hierarchy;
pub mod memory;
pub mod mesh;
pub mod output;
pub mod progress;
pub mod reference;
pub mod scene;
pub mod solve;
pub mod transport;

pub use error::{Error, Result};
