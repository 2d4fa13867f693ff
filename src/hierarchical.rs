//! The hierarchical antiradiance solver (work in progress: currently delegates to the dense one).

use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solution::Solution;
use crate::solve::SolverOptions;

/// Solves the scene with the hierarchical solver. Preconditions: `options.validate()` passed.
pub fn solve_hierarchical(patches: &Patches, options: &SolverOptions, progress: &Progress) -> Solution {
    crate::dense::solve_dense(patches, options, progress)
}
