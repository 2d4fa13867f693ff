//! Scenes and checks of the stability battery (`tests/stability.rs`, `tests/stability_cli.rs`):
//! a triangle builder, the lit box, both solvers, and the finiteness, bound and energy checks.

use antiradiance::mesh::build_patches;
use antiradiance::progress::Progress;
use antiradiance::scene::Scene;
use antiradiance::solve::dense::solve_dense;
use antiradiance::solve::hierarchical::solve_hierarchical;
use antiradiance::solve::solution::Solution;
use antiradiance::solve::SolverOptions;
use glam::DVec3;
// ---------------------------------------------------------------------------------------------
// Scene building

/// Triangles with materials, turned into a [`Scene`] at the end.
#[derive(Clone, Default)]
pub struct Build {
    pub tris: Vec<[DVec3; 3]>,
    pub albedo: Vec<[f64; 3]>,
    pub emission: Vec<[f64; 3]>,
}

impl Build {
    /// Adds one triangle (counter-clockwise = front); returns its index.
    pub fn tri(&mut self, t: [DVec3; 3], albedo: f64, emission: f64) -> usize {
        self.tris.push(t);
        self.albedo.push([albedo; 3]);
        self.emission.push([emission; 3]);
        self.tris.len() - 1
    }

    /// Adds the quad a b c d as (a, b, c), (a, c, d); its front is where a -> b -> c turns
    /// counter-clockwise. Returns the first triangle's index.
    pub fn quad(&mut self, q: [DVec3; 4], albedo: f64, emission: f64) -> usize {
        let first = self.tri([q[0], q[1], q[2]], albedo, emission);
        self.tri([q[0], q[2], q[3]], albedo, emission);
        first
    }

    /// Adds a closed tetrahedron with outward faces; returns the index of its first face.
    pub fn tetrahedron(&mut self, p: [DVec3; 4], albedo: f64) -> usize {
        let centre = (p[0] + p[1] + p[2] + p[3]) / 4.0;
        let first = self.tris.len();
        for [a, b, c] in [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]] {
            let t = [p[a], p[b], p[c]];
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            let t = if n.dot(t[0] - centre) > 0.0 {
                t
            } else {
                [t[0], t[2], t[1]]
            };
            self.tri(t, albedo, 0.0);
        }
        first
    }

    /// Adds a closed axis-aligned cube `[lo, hi]` with outward faces (12 triangles, in the order
    /// -y, +y, -z, +z, -x, +x); returns the index of its first triangle.
    pub fn cube(&mut self, lo: DVec3, hi: DVec3, albedo: f64, emission: f64) -> usize {
        let first = self.tris.len();
        let p = |i: usize| {
            DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        };
        let centre = (lo + hi) * 0.5;
        for f in [
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ] {
            let q = [p(f[0]), p(f[1]), p(f[2]), p(f[3])];
            let n = (q[1] - q[0]).cross(q[2] - q[0]);
            let q = if n.dot(q[0] - centre) > 0.0 {
                q
            } else {
                [q[0], q[3], q[2], q[1]]
            };
            self.quad(q, albedo, emission);
        }
        first
    }

    pub fn scene(&self) -> Scene {
        Scene::from_triangles(&self.tris, &self.albedo, &self.emission)
    }
}

/// A closed box `[0, s]^3` facing inward, two triangles per face, albedo 0.5; the first ceiling
/// triangle (index 2) emits radiance 1. Every front faces the inside and every back the outside,
/// so all the light ends up absorbed by the fronts (see [`absorbed_over_emitted`]).
pub fn lit_box(s: f64) -> Build {
    let mut b = Build::default();
    let v = |x: f64, y: f64, z: f64| DVec3::new(x, y, z) * s;
    let faces = [
        [v(0., 0., 0.), v(0., 0., 1.), v(1., 0., 1.), v(1., 0., 0.)], // floor, +y
        [v(0., 1., 0.), v(1., 1., 0.), v(1., 1., 1.), v(0., 1., 1.)], // ceiling, -y
        [v(0., 0., 0.), v(0., 1., 0.), v(0., 1., 1.), v(0., 0., 1.)], // x = 0, +x
        [v(1., 0., 0.), v(1., 0., 1.), v(1., 1., 1.), v(1., 1., 0.)], // x = s, -x
        [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)], // z = 0, +z
        [v(0., 0., 1.), v(0., 1., 1.), v(1., 1., 1.), v(1., 0., 1.)], // z = s, -z
    ];
    for q in faces {
        b.quad(q, 0.5, 0.0);
    }
    b.emission[2] = [1.0; 3];
    b
}

// ---------------------------------------------------------------------------------------------
// Solving and measuring

pub fn hidden() -> Progress {
    Progress::hidden()
}

/// Dense and hierarchical solutions of one scene, with their names.
pub fn solve_both(scene: &Scene, options: &SolverOptions) -> [(&'static str, Solution); 2] {
    let patches = build_patches(scene, None);
    [
        ("dense", solve_dense(&patches, options, &hidden()).unwrap()),
        (
            "hierarchical",
            solve_hierarchical(&patches, options, &hidden()).unwrap(),
        ),
    ]
}

/// Every per-triangle and per-patch value is finite and >= 0 (the default clamps negatives).
pub fn assert_finite_non_negative(what: &str, solution: &Solution) {
    for b in solution
        .triangle_radiance
        .iter()
        .chain(&solution.patch_radiance)
    {
        assert!(
            b.iter().all(|x| x.is_finite() && *x >= 0.0),
            "{what}: B = {b:?}"
        );
    }
    let s = &solution.stats;
    assert!(
        s.residual.is_finite() && s.negative_fraction.is_finite(),
        "{what}: {s:?}"
    );
}

/// The maximum principle of the model: with albedo rho <= rho_max < 1, no triangle can be
/// brighter than E_max / (1 - rho_max) (what it would get if it saw that everywhere); `slack`
/// allows for discretization error.
pub fn assert_bounded(what: &str, scene: &Scene, solution: &Solution, slack: f64) {
    let e_max = scene
        .emission
        .iter()
        .flatten()
        .fold(0.0f64, |a, &b| a.max(b));
    let rho_max = scene.albedo.iter().flatten().fold(0.0f64, |a, &b| a.max(b));
    let bound = e_max / (1.0 - rho_max) * (1.0 + slack);
    for (t, b) in solution.triangle_radiance.iter().enumerate() {
        assert!(
            b.iter().all(|&x| x <= bound),
            "{what}: triangle {t} B = {b:?} above {bound}"
        );
    }
}

/// Power absorbed by the front sides over power emitted, from B alone: a front absorbs
/// (1 - rho) H with H = pi (B - E) / rho, and emits pi E. In a closed scene where nothing
/// reaches a back side this is 1.
pub fn absorbed_over_emitted(scene: &Scene, solution: &Solution) -> f64 {
    let (mut absorbed, mut emitted) = (0.0, 0.0);
    for t in 0..scene.len() {
        let a = scene.area(t);
        for c in 0..3 {
            let (rho, e, b) = (
                scene.albedo[t][c],
                scene.emission[t][c],
                solution.triangle_radiance[t][c],
            );
            emitted += a * e;
            if rho > 0.0 {
                absorbed += a * (1.0 - rho) * (b - e) / rho;
            }
        }
    }
    absorbed / emitted
}

/// Longest edge over the height onto it: 1 for a fat triangle, 1e6 for the slivers here.
pub fn aspect_ratio(t: [DVec3; 3]) -> f64 {
    let edges = [t[1] - t[0], t[2] - t[1], t[0] - t[2]];
    let longest = edges.iter().map(|e| e.length()).fold(0.0, f64::max);
    let twice_area = edges[0].cross(-edges[2]).length();
    longest * longest / twice_area
}

pub fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}
