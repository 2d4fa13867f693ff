//! The solvers with exact direct light: the direct light as their source, antiradiance for the
//! indirect bounces, the emission added back.

use super::*;
use crate::error::Result;
use crate::mesh::Patches;
use crate::progress::Progress;
use crate::solve::budget::{self, Budget};
use crate::solve::dense;
use crate::solve::health::FailureKind;
use crate::solve::hierarchical::{Element, Prepared};
use crate::solve::solution::finish_sides;
use crate::solve::solution::{Solution, SolveStats};
use crate::solve::{emission_bound, finish, SolverOptions};

/// Per-patch outgoing radiance B = R + E (normalized units) from per-receiver reflected
/// radiance R: the area-weighted mean of each patch's receivers (`faces`: each receiver's patch
/// and area), plus the patch's emission. Patches without receivers (inactive ones) get B = E.
///
/// # Panics
/// When `faces` and `reflected` differ in length or a receiver's patch is out of range.
pub(super) fn add_emission(
    patches: &Patches,
    faces: &[(u32, f64)],
    reflected: &[[f64; 3]],
) -> Vec<[f64; 3]> {
    assert_eq!(faces.len(), reflected.len());
    let means = crate::mesh::patch_means(
        patches.len(),
        faces
            .iter()
            .zip(reflected)
            .map(|(&(patch, area), b)| (patch as usize, area, *b)),
    );
    means
        .iter()
        .zip(&patches.emission)
        .map(|(mean, e)| match mean {
            Some(m) => [0, 1, 2].map(|c| e[c] + m[c]),
            None => *e,
        })
        .collect()
}

/// Each receiver's patch and area (what [`add_emission`] needs of it).
fn faces_of(receivers: &[Element]) -> Vec<(u32, f64)> {
    receivers.iter().map(|r| (r.patch, r.area)).collect()
}

/// Adds the analytic lights' reflected direct radiance (`per_patch`: [`Patches::source`], or
/// [`Patches::source_back`] for back faces) to the receivers' source.
fn add_light_source(per_patch: &[[f64; 3]], receivers: &[Element], source: &mut [[f64; 3]]) {
    for (r, d) in receivers.iter().zip(source.iter_mut()) {
        if let Some(s) = per_patch.get(r.patch as usize) {
            for c in 0..3 {
                d[c] += s[c];
            }
        }
    }
}

/// The active patches as receivers (what the dense solver works on).
pub(super) fn patch_receivers(patches: &Patches) -> Vec<Element> {
    (0..patches.len())
        .filter(|&p| patches.active[p])
        .map(|p| Element {
            corners: patches.corners[p],
            normal: patches.normal[p],
            area: patches.area[p],
            patch: p as u32,
        })
        .collect()
}

/// The coarsening step recorded when the exact direct light does not fit the memory limit.
pub const DIRECT_LIGHT_OFF: &str = "exact direct light off";

/// The direct light of `patches` for `receivers` when it fits `spare` bytes
/// ([`budget::direct_light_bytes`]: the shadow-ray scene and emitter groups are estimated
/// before they are built, each receiver's lights once the groups are known, from a sample of
/// the receivers, [`DirectLight::lights_per_receiver`]), with its estimate; `None` when it does
/// not fit.
pub(super) fn direct_within<'a>(
    patches: &'a Patches,
    receivers: &[Element],
    spare: u64,
    back_faces: Option<&[bool]>,
) -> Option<(DirectLight<'a>, u64)> {
    let (p, e, r) = (
        patches.len() as u64,
        Emitters::count(patches) as u64,
        receivers.len() as u64,
    );
    if budget::direct_light_bytes(p, e, 0, Some(0)) > spare {
        return None;
    }
    let direct = DirectLight::with_back_faces(patches, receivers.len(), back_faces);
    let lights = direct.lights_per_receiver(receivers);
    let bytes = budget::direct_light_bytes(p, e, r, Some(lights));
    (bytes <= spare).then_some((direct, bytes))
}

/// Solves the scene with the hierarchical solver and exact direct light: the reflected direct
/// light `D` per element (shadow rays) is the source of the antiradiance solve, which then
/// carries the indirect bounces only; the emission is added back at the end. The direct light
/// is skipped (`stats.direct_light_skipped`) when it would cost more than the work budget
/// ([`DirectLight::over_budget`]) or than the memory the model leaves (then
/// [`DIRECT_LIGHT_OFF`] is in `stats.memory.coarsened`).
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
///
/// Errors: [`crate::Error::Memory`] as [`Prepared::new`].
pub fn solve_hierarchical_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let mut prepared = Prepared::new(patches, options, false)?;
    // Every face: the elements' fronts, then the two-sided elements' backs.
    let receivers: Vec<Element> = prepared.faces().collect();
    let n = prepared.element_count();
    let t_direct = std::time::Instant::now();
    let skip = |mut prepared: Prepared, step: Option<&str>| {
        prepared.note_memory(0, step);
        let (mut solution, state) = prepared.solve(patches, progress);
        solution.stats.direct_light_skipped = true;
        solution.elements = prepared.kept_elements(patches, state.radiance(), false);
        solution
    };
    let back_faces = prepared.patches_with_back_faces(patches.len());
    let Some((direct, bytes)) = direct_within(
        patches,
        &receivers,
        prepared.spare_bytes(),
        Some(&back_faces),
    ) else {
        return Ok(skip(prepared, Some(DIRECT_LIGHT_OFF)));
    };
    if direct.over_budget(receivers.len()) {
        drop(direct);
        return Ok(skip(prepared, None));
    }
    prepared.note_direct_light(bytes, receivers.len() as u64);
    let (mut source, direct_stats) = direct.reflected(&receivers, progress);
    // Only each receiver's patch and area are needed from here on (the receivers' corners
    // would take 112 MB through the sweeps of a 1M-triangle scene).
    let faces = faces_of(&receivers[..n]);
    drop(receivers);
    // The analytic lights' direct light per face, not the patch's mean: an element near a
    // point light gets its own.
    crate::mesh::lights::add_into(&mut source, prepared.light_source_of_faces(patches));
    drop(direct);
    // The per-receiver lists of lights were small blocks: freed, they need not stay resident
    // through the sweeps.
    crate::memory::release_freed();
    prepared.timings.direct = t_direct.elapsed().as_secs_f64();
    let (reflected, state) = prepared.solve_with_source(patches, &source, None, progress);
    let elements = prepared.kept_elements(patches, state.radiance(), true);
    // The tree and links are done with: the per-patch results below need not sit on them.
    drop((prepared, source));
    // `reflected` is R clamped and scaled; B is formed from the unclamped element values.
    let radiance = add_emission(patches, &faces, state.radiance());
    let radiance_back = if state.radiance_back().is_empty() {
        Vec::new()
    } else {
        add_emission(patches, &faces, state.radiance_back())
    };
    let mut stats = without_negative_check(reflected.stats);
    stats.direct = Some(direct_stats);
    let mut solution = finish_sides(
        patches,
        radiance,
        radiance_back,
        stats,
        options.clamp_negative,
        emission_bound(patches, options.antiradiance),
    );
    solution.elements = elements;
    Ok(solution)
}

/// Solves the scene with the dense solver and exact direct light (the reflected direct light is
/// computed per patch and is the dense solve's source; the emission is added back at the end).
/// Skipped as in [`solve_hierarchical_direct`], the memory left being what the dense solver's
/// estimate leaves.
/// Preconditions: `options.validate()` passed (`options.direct_light` itself is not read).
///
/// Errors: [`crate::Error::Memory`] as [`dense::solve_dense`].
pub fn solve_dense_direct(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    // As `dense::solve_dense`: back faces as one-sided patches of their own.
    Solution::of_one_sided_faces(patches, |p| dense_direct_one_sided(p, options, progress))
}

/// [`solve_dense_direct`] of patches that are all one-sided.
fn dense_direct_one_sided(
    patches: &Patches,
    options: &SolverOptions,
    progress: &Progress,
) -> Result<Solution> {
    let receivers = patch_receivers(patches);
    let budget = Budget::start(options.memory_limit());
    // The dense solve, and the copy of the patches that carries its source.
    let dense_bytes =
        budget::dense_bytes(patches.len() as u64, options.bins, options.near_quadrature)
            + patches.len() as u64 * 256;
    let skip = |step: Option<&str>| -> Result<Solution> {
        let mut solution = dense::solve_dense(patches, options, progress)?;
        solution.stats.direct_light_skipped = true;
        if let (Some(step), Some(memory)) = (step, solution.stats.memory.as_mut()) {
            memory.coarsened.push(step.to_string());
        }
        Ok(solution)
    };
    let Some((direct, _)) = direct_within(patches, &receivers, budget.spare(dense_bytes), None)
    else {
        return skip(Some(DIRECT_LIGHT_OFF));
    };
    if direct.over_budget(receivers.len()) {
        drop(direct);
        return skip(None);
    }
    let (mut source, direct_stats) = direct.reflected(&receivers, progress);
    add_light_source(&patches.source, &receivers, &mut source);
    drop(direct);
    let mut with_source = patches.clone();
    with_source.source = Vec::new();
    with_source.emission = vec![[0.0; 3]; patches.len()];
    for (r, d) in receivers.iter().zip(&source) {
        with_source.emission[r.patch as usize] = *d;
    }
    let unclamped = SolverOptions {
        clamp_negative: false,
        ..options.clone()
    };
    let reflected = dense::solve_dense(&with_source, &unclamped, progress)?;
    // Back to normalized units (the solution was scaled by the scene's emission scale).
    let inv_scale = 1.0 / patches.emission_scale;
    let patch_reflected: Vec<[f64; 3]> = receivers
        .iter()
        .map(|r| reflected.patch_radiance[r.patch as usize].map(|x| x * inv_scale))
        .collect();
    let radiance = add_emission(patches, &faces_of(&receivers), &patch_reflected);
    let mut stats = without_negative_check(reflected.stats);
    stats.direct = Some(direct_stats);
    Ok(finish(
        patches,
        radiance,
        stats,
        options.clamp_negative,
        emission_bound(patches, options.antiradiance),
    ))
}

/// The statistics of the indirect solve without its negative-mass check, which is made again on
/// `B = E + R`, what the solve returns (R's negative mass against R's positive mass alone would
/// overstate it). Every other failure stays: in particular R beyond its own bound
/// `D_max / (1 - rho_max)`, far tighter than the emission's.
pub(super) fn without_negative_check(mut stats: SolveStats) -> SolveStats {
    if stats
        .failure
        .as_ref()
        .is_some_and(|f| f.kind == FailureKind::NegativeMass)
    {
        stats.failure = None;
    }
    stats
}
