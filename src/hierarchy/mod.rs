//! Stage 4: the cluster tree over the patches ([`tree`]) and the links between its nodes
//! ([`links`]: refinement, validation, statistics).

pub mod cost;
pub mod links;
pub mod tree;

pub use tree::*;
