//! Scenes on which the antiradiance iteration amplifies instead of contracting, or comes close:
//! each triangle doubled by a reversed twin (back to back), Venetian blinds, slivers standing on
//! a big floor, two-sided antiradiance on an open scene. On every one, each solve must either
//! return a result that is finite and within the bound `E_max / (1 - rho_max)` the emission and
//! albedos allow (with [`health::BOUND_SLACK`]), with little negative mass, or report a failure
//! (`converged == false`, `stats.failure`), and on the command line exit non-zero without
//! writing a result. Before these checks existed, several of them reported convergence with
//! radiance up to 1e38 (`docs/stability.md`). The figures are printed by
//!
//!     cargo test --release --test divergence -- --nocapture

use std::path::{Path, PathBuf};

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::generated;
use antiradiance::scene::{load_obj, Scene, SceneOptions};
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::direct::{solve_dense_direct, solve_hierarchical_direct};
use antiradiance::solve::health::{self, FailureKind};
use antiradiance::solve::hierarchical::solve_hierarchical;
use antiradiance::solve::relight::Relighter;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::{change_ratio, SolverOptions};
use antiradiance::Error;
use glam::DVec3;
use serde_json::Value;

mod common;
use common::{run, s, stderr};

// ---------------------------------------------------------------------------------------------
// Scenes

/// Triangles with grey materials, turned into a [`Scene`] at the end.
#[derive(Clone, Default)]
struct Build {
    tris: Vec<[DVec3; 3]>,
    albedo: Vec<[f64; 3]>,
    emission: Vec<[f64; 3]>,
}

impl Build {
    fn tri(&mut self, t: [DVec3; 3], albedo: f64, emission: f64) {
        self.tris.push(t);
        self.albedo.push([albedo; 3]);
        self.emission.push([emission; 3]);
    }

    /// The quad a b c d as (a, b, c), (a, c, d); its front is where a -> b -> c turns
    /// counter-clockwise.
    fn quad(&mut self, q: [DVec3; 4], albedo: f64, emission: f64) {
        self.tri([q[0], q[1], q[2]], albedo, emission);
        self.tri([q[0], q[2], q[3]], albedo, emission);
    }

    /// Every triangle followed by its reversed twin, back to back (same material).
    fn twinned(&self) -> Build {
        self.twinned_at(0.0)
    }

    /// [`Build::twinned`] with each reversed copy moved by `gap` (scene units) along its own
    /// normal: for a gap of 1e-9 a pair that is back to back within any tolerance but not bit
    /// for bit, so it is solved as two one-sided surfaces instead of one two-sided one.
    fn twinned_at(&self, gap: f64) -> Build {
        let mut b = Build::default();
        for t in 0..self.tris.len() {
            let [p, q, r] = self.tris[t];
            let n = (q - p).cross(r - p).normalize_or_zero();
            let shift = -n * gap;
            for tri in [[p, q, r], [p + shift, r + shift, q + shift]] {
                b.tris.push(tri);
                b.albedo.push(self.albedo[t]);
                b.emission.push(self.emission[t]);
            }
        }
        b
    }

    /// The triangles and materials of a scene.
    fn of(scene: &Scene) -> Build {
        Build {
            tris: (0..scene.len()).map(|t| scene.corners(t)).collect(),
            albedo: scene.albedo.clone(),
            emission: scene.emission.clone(),
        }
    }

    fn scene(&self) -> Scene {
        Scene::from_triangles(&self.tris, &self.albedo, &self.emission)
    }
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// A closed room 4 x 3 x 4 facing inward, albedo 0.75, lit by a 1.2 x 1.2 ceiling light of
/// radiance 1 facing down (albedo 0): every B is at most 1 / (1 - 0.75) = 4.
fn room() -> Build {
    let mut b = Build::default();
    let (w, h) = (4.0, 3.0);
    let rho = 0.75;
    b.quad(
        [v(0., 0., 0.), v(0., 0., w), v(w, 0., w), v(w, 0., 0.)],
        rho,
        0.0,
    ); // floor, +y
    b.quad(
        [v(0., h, 0.), v(w, h, 0.), v(w, h, w), v(0., h, w)],
        rho,
        0.0,
    ); // ceiling, -y
    b.quad(
        [v(0., 0., 0.), v(0., h, 0.), v(0., h, w), v(0., 0., w)],
        rho,
        0.0,
    ); // x = 0
    b.quad(
        [v(w, 0., 0.), v(w, 0., w), v(w, h, w), v(w, h, 0.)],
        rho,
        0.0,
    ); // x = w
    b.quad(
        [v(0., 0., 0.), v(w, 0., 0.), v(w, h, 0.), v(0., h, 0.)],
        rho,
        0.0,
    ); // z = 0
    b.quad(
        [v(0., 0., w), v(0., h, w), v(w, h, w), v(w, 0., w)],
        rho,
        0.0,
    ); // z = w
    let (a, c, y) = (0.35 * w, 0.65 * w, h - 0.01);
    b.quad([v(a, y, a), v(c, y, a), v(c, y, c), v(a, y, c)], 0.0, 1.0);
    b
}

/// The room with Venetian blinds along one wall: `slats` slats 3 long and 5 cm deep, 6 cm
/// apart, their fronts facing up (30 slats: 72 triangles in all).
fn blinds_room(slats: usize) -> Build {
    let mut b = room();
    for k in 0..slats {
        let y = 0.5 + 0.06 * k as f64;
        let (z0, z1) = (0.2, 0.25);
        b.quad(
            [
                v(0.5, y, z0),
                v(0.5, y, z1),
                v(3.5, y + 0.01, z1),
                v(3.5, y + 0.01, z0),
            ],
            0.75,
            0.0,
        );
    }
    b
}

/// The room with a fan of `count` slivers standing on its floor (two big triangles): each runs
/// from an apex 1.5 above the centre of the floor down to the floor, where it is 1 cm wide
/// (every fourth 0.1 mm wide), about 1.9 long: aspect ratios 190 and 19,000.
fn sliver_room(count: usize) -> Build {
    let mut b = room();
    let apex = v(2.0, 1.5, 2.0);
    for k in 0..count {
        let t = std::f64::consts::TAU * k as f64 / count as f64;
        let (dir, side) = (v(t.cos(), 0.0, t.sin()), v(-t.sin(), 0.0, t.cos()));
        let width = if k % 4 == 0 { 1e-4 } else { 1e-2 };
        let foot = v(2.0, 0.0, 2.0) + 1.2 * dir;
        let (p, q) = (foot - 0.5 * width * side, foot + 0.5 * width * side);
        b.tri([apex, p, q], 0.75, 0.0);
    }
    b
}

/// An open scene: a 4 x 4 floor (albedo 0.75) under a 2 x 2 light facing down at height 3, and
/// between them `plates` 2 x 2 plates facing down, each lit from behind by the light (only the
/// floor's light reaches their fronts). Nothing encloses it.
fn open_plates(plates: usize) -> Build {
    let mut b = Build::default();
    b.quad(
        [v(0., 0., 0.), v(0., 0., 4.), v(4., 0., 4.), v(4., 0., 0.)],
        0.75,
        0.0,
    );
    b.quad(
        [v(1., 3., 1.), v(3., 3., 1.), v(3., 3., 3.), v(1., 3., 3.)],
        0.0,
        1.0,
    );
    for k in 0..plates {
        let y = 0.5 + 0.3 * k as f64;
        b.quad(
            [v(1., y, 1.), v(3., y, 1.), v(3., y, 3.), v(1., y, 3.)],
            0.75,
            0.0,
        );
    }
    b
}

// ---------------------------------------------------------------------------------------------
// Solving and checking

/// The solvers of the library: (name, solve).
type Solver = (
    &'static str,
    fn(&antiradiance::mesh::Patches, &SolverOptions, &Progress) -> antiradiance::Result<Solution>,
);

const SOLVERS: [Solver; 4] = [
    ("hierarchical", solve_hierarchical),
    ("dense", solve_dense),
    ("hierarchical, direct light", solve_hierarchical_direct),
    ("dense, direct light", solve_dense_direct),
];

/// The bound `E_max / (1 - rho_max)` of a scene, from its own materials.
fn bound_of(scene: &Scene) -> f64 {
    let e_max = scene
        .emission
        .iter()
        .flatten()
        .fold(0.0f64, |m, &x| m.max(x));
    let rho_max = scene.albedo.iter().flatten().fold(0.0f64, |m, &x| m.max(x));
    e_max / (1.0 - rho_max)
}

/// Solves `scene` with `solver` and checks the outcome: either a healthy result (finite, its
/// largest B within the bound and its slack, negative mass under the limit, the report's figures
/// consistent with the radiance) or a failure the caller cannot take for convergence. Prints
/// the figures; returns true when the solve failed.
fn check(what: &str, scene: &Scene, options: &SolverOptions, solver: Solver) -> bool {
    check_solution(what, scene, &solve_with(scene, options, solver), solver)
}

/// Solves `scene` with `solver`.
fn solve_with(scene: &Scene, options: &SolverOptions, solver: Solver) -> Solution {
    let patches = build_patches(scene, None);
    (solver.1)(&patches, options, &Progress::hidden()).expect("fits the memory limit")
}

/// The checks of [`check`] on a solution of `scene` by `solver`.
fn check_solution(what: &str, scene: &Scene, solution: &Solution, solver: Solver) -> bool {
    let st = &solution.stats;
    let bound = bound_of(scene);
    println!(
        "{what} [{}]: {} sweeps, converged {}, residual {:.3e}, max row sum {:.3}, negative {:.2}%, largest B / bound {:.3}{}",
        solver.0,
        st.iterations,
        st.converged,
        st.residual,
        st.max_row_sum,
        100.0 * st.negative_fraction,
        st.largest_b_over_bound,
        st.failure.as_ref().map(|f| format!(": FAILED: {f}")).unwrap_or_default()
    );
    // Rows deeper than DAMP_ROW_SUM damp the antiradiance from the second sweep, and only
    // they do (the stall rules need several sweeps).
    if st.iterations > 1 {
        assert_eq!(
            st.damped_after == Some(1),
            st.max_row_sum > health::DAMP_ROW_SUM,
            "{what} [{}]: damped after {:?}, max row sum {}",
            solver.0,
            st.damped_after,
            st.max_row_sum
        );
    }
    match &st.failure {
        Some(f) => {
            assert!(
                !st.converged,
                "{what} [{}]: a failure is not convergence",
                solver.0
            );
            let err = st
                .check(solver.0)
                .expect_err("a failed solve checks as an error");
            assert!(matches!(err, Error::Solve(_)), "{err}");
            let text = err.to_string();
            assert!(!text.contains('\n') && text.contains(solver.0), "{text}");
            assert!(text.contains("sweep"), "{text}");
            // The figures of the failure are those of the solve.
            assert_eq!(f.max_row_sum, st.max_row_sum);
            assert!(f.sweep >= 1 && f.sweep <= st.iterations.max(1));
            if f.kind == FailureKind::OverBound && !f.in_result {
                assert!(
                    f.largest_b_over_bound > health::DIVERGED_BOUND_FACTOR,
                    "{f:?}"
                );
            }
            // Even a failed solve gives no NaN to whoever reads it anyway.
            for b in solution.patch_radiance.iter().flatten() {
                assert!(b.is_finite());
            }
            true
        }
        None => {
            assert!(st.check(solver.0).is_ok());
            let largest = solution
                .patch_radiance
                .iter()
                .flatten()
                .fold(0.0f64, |m, &x| {
                    assert!(x.is_finite(), "{what} [{}]: non-finite B", solver.0);
                    m.max(x.abs())
                });
            assert!(
                largest <= (1.0 + health::BOUND_SLACK) * bound,
                "{what} [{}]: B = {largest} beyond the bound {bound}",
                solver.0
            );
            // The report's ratio is the radiance's (clamped values cannot be larger).
            assert!(st.largest_b_over_bound <= 1.0 + health::BOUND_SLACK);
            assert!(
                largest <= st.largest_b_over_bound * st.radiance_bound * (1.0 + 1e-9),
                "{what} [{}]: {largest} vs {} x {}",
                solver.0,
                st.largest_b_over_bound,
                st.radiance_bound
            );
            assert!(
                (st.radiance_bound - bound).abs() <= 1e-9 * bound,
                "{}",
                st.radiance_bound
            );
            assert!(st.negative_fraction <= health::NEGATIVE_LIMIT);
            false
        }
    }
}

/// Checks every solver on `scene` with `options`; returns whether each failed, in the order
/// of [`SOLVERS`].
fn check_all(what: &str, scene: &Scene, options: &SolverOptions) -> Vec<bool> {
    SOLVERS
        .iter()
        .map(|&solver| check(what, scene, options, solver))
        .collect()
}

/// How many of `outcomes` are failures.
fn failures(outcomes: &[bool]) -> usize {
    outcomes.iter().filter(|&&f| f).count()
}

/// The default options with at most 150 sweeps: the slowest divergences (Anderson mixing
/// holds them back) then end at the cap, where the result's checks judge them.
fn front_only() -> SolverOptions {
    SolverOptions {
        max_iterations: 150,
        ..SolverOptions::default()
    }
}

/// [`front_only`] with two-sided antiradiance.
fn two_sided() -> SolverOptions {
    SolverOptions {
        two_sided: true,
        ..front_only()
    }
}

// ---------------------------------------------------------------------------------------------
// The cases

/// The shipped Cornell box with each triangle doubled by its reversed twin. Front-only: every
/// solver converges within the bound (largest B 0.22 of it), and the twin box gives the box's
/// own answer on the original triangles. Two-sided antiradiance cancels light twice at every
/// twin: the hierarchical solver still converges (with 14-25% negative mass), the dense
/// solver's plain sweeps diverge (unchecked, they reach 1e38 after 523 sweeps and report
/// convergence) and must say so.
#[test]
fn back_to_back_twins_of_the_cornell_box() {
    let box_ = generated::cornell_box();
    let twins = Build::of(&box_).twinned().scene();
    assert_eq!(twins.len(), 2 * box_.len());
    assert!(
        twins.duplicates().iter().all(Option::is_none),
        "reversed twins are not duplicates"
    );
    let outcomes = check_all("Cornell box twins", &twins, &front_only());
    assert_eq!(failures(&outcomes), 0, "the twin Cornell box converges");
    let outcomes = check_all("Cornell box twins, two-sided", &twins, &two_sided());
    assert!(
        !outcomes[0] && !outcomes[2],
        "the hierarchical solver converges"
    );
    // Front-only: the twins' backs face the outside, which nothing lights.
    let options = SolverOptions::default();
    let one =
        solve_hierarchical(&build_patches(&box_, None), &options, &Progress::hidden()).unwrap();
    let two =
        solve_hierarchical(&build_patches(&twins, None), &options, &Progress::hidden()).unwrap();
    let front: Vec<[f64; 3]> = (0..box_.len())
        .map(|t| two.triangle_radiance[2 * t])
        .collect();
    let areas: Vec<f64> = (0..box_.len()).map(|t| box_.area(t)).collect();
    let emissive: Vec<bool> = (0..box_.len()).map(|t| box_.is_emitter(t)).collect();
    let e = antiradiance::solve::solution::relative_error(
        &areas,
        &emissive,
        &front,
        &one.triangle_radiance,
    );
    println!(
        "Cornell box twins, front-only: fronts against the one-sided box {:.3}%",
        100.0 * e
    );
    assert!(e < 0.05, "{e}");
}

/// A room with Venetian blinds, as given and with every triangle doubled by its reversed twin:
/// the stacked slats (and their twins) make the unoccluded rows sum to 2.5 (5 doubled). Every
/// solve must end within the bound or report its failure. Exact twins are merged into
/// two-sided slats, which the hierarchical solvers converge on (the dense oracle solves them
/// as the twins again, and its plain sweeps stop at the cap unconverged: reported); twins
/// 1e-9 apart stay two one-sided surfaces, which the hierarchical solvers converge on with
/// front-only antiradiance.
#[test]
fn back_to_back_twins_of_venetian_blinds() {
    let blinds = blinds_room(30);
    let one_sided = blinds.scene();
    check_all("blinds", &one_sided, &front_only());
    let merged = check_all(
        "blinds exact twins",
        &blinds.twinned().scene(),
        &front_only(),
    );
    assert!(
        !merged[0] && !merged[2],
        "the hierarchical solvers converge on the two-sided slats"
    );
    // Twins 1e-9 apart stay two one-sided surfaces: every solve stays within the bound or
    // reports its failure (`check_solution`), the hierarchical solvers converge with front-only
    // antiradiance, and a solve that does neither stopped at the cap, unconverged.
    let twins = blinds.twinned_at(NEAR_TWIN_GAP).scene();
    for options in [front_only(), two_sided()] {
        for solver in SOLVERS {
            let solution = solve_with(&twins, &options, solver);
            let failed = check_solution("blinds twins", &twins, &solution, solver);
            let st = &solution.stats;
            assert!(
                st.converged || failed || st.iterations == options.max_iterations,
                "blinds twins [{}]: {st:?}",
                solver.0
            );
            if solver.0.starts_with("hierarchical") && !options.two_sided {
                assert!(st.converged, "blinds twins [{}]: {st:?}", solver.0);
            }
        }
    }
}

/// The twin blinds 1e-9 apart (two one-sided surfaces back to back at every slat face),
/// front-only antiradiance, hierarchical solver: the solve ends within the bound, converged
/// (plain sweeps, or projected ones ([`health::Projection`]) once damped), near the answer of the
/// same slats merged into two-sided ones (measured 1.02%: 98 sweeps, row sums up to 5.0).
#[test]
fn twin_blinds_converge_near_the_merged_slats() {
    let blinds = blinds_room(30);
    let hierarchical = SOLVERS[0];
    let merged = solve_with(&blinds.twinned().scene(), &front_only(), hierarchical);
    let twins = blinds.twinned_at(NEAR_TWIN_GAP).scene();
    let projected = solve_with(&twins, &front_only(), hierarchical);
    assert!(!check_solution(
        "blinds twins, projected",
        &twins,
        &projected,
        hierarchical
    ));
    let st = &projected.stats;
    assert!(
        st.converged,
        "{} sweeps, residual {}",
        st.iterations, st.residual
    );
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..twins.len() {
        let a = twins.area(t);
        for c in 0..3 {
            let (b, m) = (
                projected.triangle_radiance[t][c],
                merged.triangle_radiance[t][c],
            );
            num += a * (b - m).abs();
            den += a * m.abs();
        }
    }
    let diff = num / den;
    println!(
        "blinds twins, projected, against the merged slats: {:.3}%",
        100.0 * diff
    );
    assert!(diff < 0.015, "{:.3}%", 100.0 * diff);
}

/// The gap of the near twins that are not merged ([`Build::twinned_at`]).
const NEAR_TWIN_GAP: f64 = 1e-9;

/// The one-sided blinds with the dense solver: its plain sweeps oscillate with a growing
/// amplitude (an eigenvalue below -1, from slats that block light at both sides; they reached
/// 34 times the bound and failed at sweep 17), and the solver recovers by damping its sweeps
/// ([`health::DAMPING`]): the same fixed point, reached within the bound. Plain sweeps on the
/// same scene would not converge: that is what the damping record shows.
#[test]
fn dense_blinds_recover_by_damping() {
    let scene = blinds_room(30).scene();
    let dense = SOLVERS[1];
    let solution = solve_with(&scene, &front_only(), dense);
    assert!(
        !check_solution("blinds, damped", &scene, &solution, dense),
        "the damped dense solve must not fail"
    );
    let st = &solution.stats;
    assert!(
        st.converged,
        "{} sweeps, residual {}",
        st.iterations, st.residual
    );
    let damped = st.damped_after.expect("the plain sweeps stop contracting");
    assert!(
        damped < st.iterations,
        "damped after {damped} of {}",
        st.iterations
    );
    assert!(
        st.negative_fraction < health::NEGATIVE_WARNING,
        "{}",
        st.negative_fraction
    );
}

/// Slivers touching a big polygon: a fan of 40 slivers (aspect ratios 190 and 19,000) standing
/// on a floor made of two big triangles, one-sided and doubled back to back, front-only and
/// two-sided antiradiance: within the bound or a reported failure.
#[test]
fn slivers_touching_a_big_floor() {
    let fan = sliver_room(40);
    for (what, scene) in [
        ("sliver fan", fan.scene()),
        ("sliver fan twins", fan.twinned().scene()),
    ] {
        for options in [front_only(), two_sided()] {
            check_all(what, &scene, &options);
        }
    }
}

/// Two-sided antiradiance on an open scene (a floor, a light and six plates lit from behind,
/// nothing around them), the case the option is for, and the same plates doubled back to back.
#[test]
fn two_sided_antiradiance_on_an_open_scene() {
    let plates = open_plates(6);
    let mut failed = 0;
    for (what, scene) in [
        ("open plates", plates.scene()),
        ("open plate twins", plates.twinned().scene()),
    ] {
        let outcomes = check_all(what, &scene, &two_sided());
        if what == "open plates" {
            // As the option intends: the hierarchical solver handles it.
            assert!(
                !outcomes[0] && !outcomes[2],
                "the hierarchical solver converges"
            );
        }
        failed += failures(&outcomes);
    }
    println!("two-sided antiradiance on the open scenes: {failed} failed solves");
}

/// The shipped scenes and the seed room stay healthy and unchanged by the checks: no failure,
/// converged, largest B under the bound, no capped row (nothing but the furnace is convex, and
/// its rows are 1 within 1e-8).
#[test]
fn shipped_scenes_are_healthy() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cases: Vec<(PathBuf, SceneOptions)> = ["cornell_box", "occluder", "furnace"]
        .iter()
        .map(|n| {
            (
                root.join(format!("scenes/{n}.obj")),
                SceneOptions::default(),
            )
        })
        .collect();
    let room = root.join("../shared/meshes/room_radiosity_small.obj");
    if room.exists() {
        let options = SceneOptions {
            emit_above: Some(3.65),
            default_albedo: 0.75,
            ..SceneOptions::default()
        };
        cases.push((room, options));
    } else {
        eprintln!("skipped the seed room: {} is not there", room.display());
    }
    for (path, scene_options) in cases {
        let scene = load_obj(&path, &scene_options).unwrap();
        let patches = build_patches(&scene, None);
        let room = path.ends_with("room_radiosity_small.obj");
        let solvers: &[Solver] = if room { &SOLVERS[2..3] } else { &SOLVERS };
        for &(name, solve) in solvers {
            let solution = solve(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
            let st = &solution.stats;
            println!(
                "{} [{name}]: largest B / bound {:.4}, max row sum {:.6}",
                path.display(),
                st.largest_b_over_bound,
                st.max_row_sum
            );
            assert!(
                st.failure.is_none() && st.converged,
                "{}: {:?}",
                path.display(),
                st.failure
            );
            assert!(st.largest_b_over_bound > 0.0 && st.largest_b_over_bound <= 1.0 + 1e-6);
            assert_eq!(st.capped_rows, 0);
            if path.ends_with("furnace.obj") {
                assert!((st.max_row_sum - 1.0).abs() < 1e-6, "{}", st.max_row_sum);
            }
        }
    }
}

/// The dense solver's rows in a convex enclosure (the furnace split to 0.1, where far senders'
/// centroid rule puts them 3.4e-4 above 1) stay under the capping tolerance: nothing is capped
/// and B = E / (1 - rho) = 2 within 0.1%.
#[test]
fn convex_furnace_rows_stay_under_the_tolerance() {
    let scene = generated::furnace_box(1.0, 0.5);
    let patches = build_patches(&scene, Some(0.1));
    let solution = solve_dense(&patches, &SolverOptions::default(), &Progress::hidden()).unwrap();
    let st = &solution.stats;
    println!(
        "furnace split to 0.1 [dense]: max row sum {:.7}",
        st.max_row_sum
    );
    assert!(st.max_row_sum > 1.0 && st.max_row_sum <= 1.0 + health::ROW_SUM_TOLERANCE);
    assert_eq!(st.capped_rows, 0);
    assert!(st.failure.is_none());
    for b in &solution.triangle_radiance {
        assert!((b[0] - 2.0).abs() < 2e-3, "{b:?}");
    }
}

/// The relighter's re-solves are checked too: on the twin blinds without antiradiance (unoccluded
/// radiosity, whose rows of up to 4.8 amplify the light) the solve reports its failure, the next one starts cold (not from the diverged state), and a
/// precomputed light whose solve failed is an error and is not added.
#[test]
fn relighting_a_diverging_scene_fails_cleanly() {
    let twins = blinds_room(30).twinned_at(NEAR_TWIN_GAP).scene();
    let unoccluded = SolverOptions {
        antiradiance: false,
        ..front_only()
    };
    let mut relighter = Relighter::new(&twins, None, &unoccluded).unwrap();
    let first = relighter.solve(&Progress::hidden());
    let failure = first
        .solution
        .stats
        .failure
        .clone()
        .expect("the twin blinds diverge");
    println!("relight, twin blinds, unoccluded: {failure}");
    assert!(!first.solution.stats.converged);
    let second = relighter.relight(&twins.emission).unwrap();
    assert!(!second.warm_started, "no warm start from a failed solve");
    let err = relighter
        .add_light("all", &twins.emission)
        .expect_err("the light's solve fails");
    assert!(matches!(err, Error::Solve(_)), "{err}");
    assert!(err.to_string().contains("light 'all'"), "{err}");
    assert!(relighter.light_names().is_empty());
}

/// The bug behind all this: an overflowed sweep's change `inf / inf` or `NaN / NaN` read as 0,
/// "converged". It is NaN now, and 0 only when nothing is lit.
#[test]
fn an_overflowed_change_is_not_zero() {
    assert!(change_ratio(f64::INFINITY, f64::INFINITY).is_nan());
    assert!(change_ratio(f64::NAN, f64::NAN).is_nan());
    assert!(change_ratio(1.0, f64::NAN).is_nan());
    assert_eq!(change_ratio(0.0, 0.0), 0.0);
    assert_eq!(change_ratio(1.0, 4.0), 0.25);
}

/// On the command line a failed solve is one `error:` line naming the solver, the sweep and
/// the row sum, exit code 1, no CSV, PLY or PNG; the report is written, with `converged:
/// false` and the failure. Unoccluded radiosity on the twin blinds fails (negative mass). The
/// dense solver's plain sweeps on them stay within the bound without converging: they must
/// end at the cap with its `warning:` line and `converged: false`, or fail as above, never
/// pass for converged.
#[test]
fn diverging_solve_on_the_command_line_writes_no_result() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("blinds_twins.obj");
    generated::write_obj(
        &blinds_room(30).twinned_at(NEAR_TWIN_GAP).scene(),
        &obj,
        "blinds doubled back to back",
    )
    .unwrap();
    for flags in [&["--solver", "dense"][..], &["--no-antiradiance"][..]] {
        let out = |name: &str| dir.path().join(name);
        let (csv, ply, png, report) = (out("t.csv"), out("t.ply"), out("t.png"), out("r.json"));
        let mut args = vec![
            "solve",
            s(&obj),
            "--quiet",
            "--triangles",
            s(&csv),
            "--ply",
            s(&ply),
            "--png",
            s(&png),
            "--report",
            s(&report),
        ];
        args.extend_from_slice(flags);
        let o = run(&args);
        let err = stderr(&o);
        println!("{flags:?}: {err}");
        if flags.contains(&"--solver") && o.status.code() == Some(0) {
            assert!(
                err.contains("warning: the dense solver stopped at the iteration cap"),
                "{err}"
            );
            let r: Value =
                serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
            assert_eq!(r["stats"]["converged"], false, "{r}");
            assert!(
                r["stats"]["largest_b_over_bound"].as_f64().unwrap() <= 1.0,
                "{r}"
            );
            // Its results are written, flagged as not converged.
            for path in [&csv, &ply, &png, &report] {
                std::fs::remove_file(path).unwrap();
            }
            continue;
        }
        assert_eq!(o.status.code(), Some(1), "{err}");
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(errors.len(), 1, "{err}");
        let line = errors[0];
        assert!(
            line.contains("solver failed") && line.contains("sweep"),
            "{line}"
        );
        // Unoccluded radiosity has no bound to name.
        assert!(line.contains("row sum"), "{line}");
        if flags.contains(&"--solver") {
            assert!(line.contains("bound"), "{line}");
        }
        for path in [&csv, &ply, &png] {
            assert!(
                !path.exists(),
                "{} written by a failed solve",
                path.display()
            );
        }
        let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(r["stats"]["converged"], false, "{r}");
        assert!(r["stats"]["failure"]["kind"].is_string(), "{r}");
        assert!(
            r["stats"]["failure"]["message"]
                .as_str()
                .unwrap()
                .contains("sweep"),
            "{r}"
        );
        assert!(r["stats"]["largest_b_over_bound"].is_number(), "{r}");
        std::fs::remove_file(&report).unwrap();
    }
}
