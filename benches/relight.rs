//! Time per relight of a prepared scene (tree and links are built once, outside the
//! measurement), each a warm-started re-solve:
//!
//! - `*_sweep_step`: the lights changed by one step of a 30-frame sweep (the animation of
//!   `antiradiance relight`, emitters away from the spot at 10%), to the tolerance, at the
//!   default and the fast preset; the relights step forward through frames 1..29 and wrap
//!   around (one jump in 29 steps), so each starts from the states of the frames before it as
//!   an animation's do;
//! - `default_preset_arbitrary_change`: every emitter to its own random brightness in
//!   [0.2, 1.2] of its own (a new draw each relight: no mix of precomputed lights), to the
//!   tolerance;
//! - `default_preset_progressive_100ms`: the same changes, one progressive frame each
//!   (`Relighter::frame_budget` of 100 ms: the sweeps that fit);
//! - `default_preset_point_light_move` and `..._dim`: a point light added to the scene moved
//!   to a new place each relight, drawn along a 6.4 m path (its shadow rays traced again), or
//!   dimmed to half and back (no shadow ray), to the tolerance;
//! - `*_mix_K_lights`: a mix of K precomputed band lights (no sweep).
//!
//! Scene: the seed room (`../shared/meshes/room_radiosity_small.obj`, `--emit-above 3.65
//! --albedo 0.75`) when present, otherwise a generated Cornell box of similar size (10,350
//! triangles).
//!
//! Run: `cargo bench --bench relight` (a few minutes: each sample is one relight).

use std::path::Path;
use std::time::Duration;

use glam::DVec3;

use antiradiance::details::{
    emitter_centroids, generated, load_obj, sweep_weights, Light, Progress,
};
use antiradiance::{Relighter, Scene, SceneOptions, SolverOptions};
use criterion::{criterion_group, criterion_main, Criterion};

/// Frames of the sweep one relight steps through.
const SWEEP_FRAMES: usize = 30;
/// Bands of emitters precomputed as lights for the mixing benchmark.
const BANDS: usize = 8;
/// Emission kept by emitters far from the spot.
const DIM: f64 = 0.1;

/// The seed room when present, else a generated scene of room size; with its name.
fn bench_scene() -> (String, Scene) {
    let room = Path::new("../shared/meshes/room_radiosity_small.obj");
    if room.exists() {
        let options = SceneOptions {
            emit_above: Some(3.65),
            default_albedo: 0.75,
            ..SceneOptions::default()
        };
        match load_obj(room, &options) {
            Ok(scene) => return ("room".to_string(), scene),
            Err(e) => eprintln!("cannot load the room ({e}); using a generated Cornell box"),
        }
    } else {
        eprintln!(
            "{} not present; using a generated Cornell box of room size",
            room.display()
        );
    }
    let scene = generated::subdivided_cornell_box(9_264);
    (format!("cornell{}", scene.len()), scene)
}

/// The scene's emission in frame `frame` of the sweep.
fn sweep_emission(scene: &Scene, frame: usize) -> Vec<[f64; 3]> {
    let (emitters, centroids) = emitter_centroids(scene);
    let weights = sweep_weights(&centroids, frame, SWEEP_FRAMES, DIM);
    let mut emission = scene.emission.clone();
    for (&t, w) in emitters.iter().zip(weights) {
        emission[t] = scene.emission[t].map(|x| x * w);
    }
    emission
}

/// The scene's emission with every emitter scaled by its own factor in [0.2, 1.2], drawn from
/// `seed` (a deterministic stream).
fn random_emission(scene: &Scene, seed: u64) -> Vec<[f64; 3]> {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut emission = scene.emission.clone();
    for (t, e) in emission.iter_mut().enumerate() {
        if scene.is_emitter(t) {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let f = 0.2 + (state >> 11) as f64 / (1u64 << 53) as f64;
            *e = e.map(|x| x * f);
        }
    }
    emission
}

/// The room's point light (scene units: the room spans about 19 x 9 x 16) at `t` in [0, 1] of
/// its path.
fn point_light(t: f64) -> Light {
    let (from, to) = (DVec3::new(2.0, 2.0, 1.0), DVec3::new(-3.0, 2.5, -2.0));
    Light::Point {
        position: from + t * (to - from),
        intensity: [20.0; 3],
    }
}

/// A deterministic stream of numbers in [0, 1): the `i`-th.
fn uniform(i: u64) -> f64 {
    let x = (i.wrapping_add(1))
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .rotate_left(31)
        .wrapping_mul(0xbf58_476d_1ce4_e5b9);
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// The relights of arbitrary changes, progressive frames and a moving or dimmed point light,
/// at the default preset.
fn arbitrary(c: &mut Criterion, name: &str, scene: &Scene) {
    let mut group = c.benchmark_group(format!("relight/{name}/{}", scene.len()));
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(20));
    let options = SolverOptions::default_preset();
    let Ok(mut relighter) = Relighter::new(scene, None, &options) else {
        eprintln!("skipping the arbitrary changes: the relighter cannot be built");
        return;
    };
    relighter.solve(&Progress::hidden());
    let mut seed = 1;
    group.bench_function("default_preset_arbitrary_change", |b| {
        b.iter(|| {
            seed += 1;
            let relit = relighter
                .relight(&random_emission(scene, seed))
                .expect("valid emission");
            relit.solution.stats.iterations
        })
    });
    relighter.frame_budget = Some(Duration::from_millis(100));
    group.bench_function("default_preset_progressive_100ms", |b| {
        b.iter(|| {
            seed += 1;
            let relit = relighter
                .relight(&random_emission(scene, seed))
                .expect("valid emission");
            relit.solution.stats.iterations
        })
    });
    drop(relighter);

    let mut lit = scene.clone();
    lit.lights.push(point_light(0.0));
    let Ok(mut relighter) = Relighter::new(&lit, None, &options) else {
        eprintln!("skipping the point light: the relighter cannot be built");
        return;
    };
    relighter.solve(&Progress::hidden());
    // A new place each relight: no earlier state is of the same place.
    let (mut draw, mut at) = (0, 0.0);
    group.bench_function("default_preset_point_light_move", |b| {
        b.iter(|| {
            draw += 1;
            at = uniform(draw);
            relighter
                .set_analytic_light(0, point_light(at))
                .expect("valid light");
            relighter
                .solve(&Progress::hidden())
                .solution
                .stats
                .iterations
        })
    });
    let mut half = false;
    group.bench_function("default_preset_point_light_dim", |b| {
        b.iter(|| {
            half = !half;
            let k = if half { 0.5 } else { 1.0 };
            let light = point_light(at);
            relighter
                .set_analytic_light(0, light.with_colour(light.colour().map(|x| x * k)))
                .expect("valid light");
            relighter
                .solve(&Progress::hidden())
                .solution
                .stats
                .iterations
        })
    });
    group.finish();
}

fn relight(c: &mut Criterion) {
    let (name, scene) = bench_scene();
    // The sweep's frames after the first; each relight steps to the next one (after the last,
    // back to the first of them).
    let frames: Vec<Vec<[f64; 3]>> = (1..SWEEP_FRAMES)
        .map(|frame| sweep_emission(&scene, frame))
        .collect();
    let mut group = c.benchmark_group(format!("relight/{name}/{}", scene.len()));
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(20));
    for (preset, options) in [
        ("default", SolverOptions::default_preset()),
        ("fast", SolverOptions::fast()),
    ] {
        let mut relighter = match Relighter::new(&scene, None, &options) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("skipping the {preset} preset: {e}");
                continue;
            }
        };
        eprintln!(
            "{name}, {preset} preset: tree and links built once in {:.2} s ({} links)",
            relighter.build_seconds(),
            relighter.prepared().links.len()
        );
        // Converge on the first frame so every measured relight is a warm-started step.
        relighter.relight(&frames[0]).expect("valid emission");
        let mut next = 1;
        group.bench_function(format!("{preset}_preset_sweep_step"), |b| {
            b.iter(|| {
                let relit = relighter.relight(&frames[next]).expect("valid emission");
                next = (next + 1) % frames.len();
                relit.solution.stats.iterations
            })
        });
        // Relighting by precomputed lights: the emitters cut into BANDS bands, each solved once,
        // then every relight is a linear combination (no sweep).
        // The relighter's emission is the last frame's: restore the scene's own first.
        relighter
            .set_emission(&scene.emission)
            .expect("valid emission");
        let (emitters, centroids) = emitter_centroids(&scene);
        let centres = relighter
            .add_band_lights(&emitters, &centroids, BANDS)
            .expect("valid bands");
        let mixes: Vec<Vec<[f64; 3]>> = [SWEEP_FRAMES / 2, SWEEP_FRAMES / 2 + 1]
            .iter()
            .map(|&frame| {
                sweep_weights(&centres, frame, SWEEP_FRAMES, DIM)
                    .iter()
                    .map(|&w| [w; 3])
                    .collect()
            })
            .collect();
        let mut next = 0;
        group.bench_function(
            format!("{preset}_preset_mix_{}_lights", centres.len()),
            |b| {
                b.iter(|| {
                    let relit = relighter.mix(&mixes[next]).expect("valid intensities");
                    next = 1 - next;
                    relit.solution.triangle_radiance.len()
                })
            },
        );
    }
    group.finish();
    arbitrary(c, &name, &scene);
}

criterion_group!(benches, relight);
criterion_main!(benches);
