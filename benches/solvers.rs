//! Dense vs hierarchical, stage by stage: hierarchy build, link refinement, one iteration, full
//! solve. Scenes: the seed room and bear from ../shared/meshes when present (skipped cleanly when
//! absent), and a generated Cornell box of room scale (about 10k triangles) always.
//!
//! Run: `cargo bench --bench solvers` (add `-- hierarchical` to filter). The end-to-end benches
//! run without (`build+links+solve`) and with (`with_direct_light`, the CLI's default) exact
//! direct light.

use std::path::Path;
use std::time::Duration;

use antiradiance::details::{
    build_patches, generated, link_params, links, load_obj, solve_dense, solve_hierarchical_direct,
    Bins, ClusterTree, LinkBudget, Patches, Prepared, Progress,
};
use antiradiance::{SceneOptions, SolverOptions};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

fn bench_scenes() -> Vec<(String, Patches)> {
    let mut out = Vec::new();
    let seed = [
        (
            "room",
            "../shared/meshes/room_radiosity_small.obj",
            Some(3.65),
        ),
        ("bear", "../shared/meshes/bear.obj", None),
    ];
    for (name, path, emit_above) in seed {
        let path = Path::new(path);
        if !path.exists() {
            eprintln!("skipping {name}: {} not present", path.display());
            continue;
        }
        let mut options = SceneOptions {
            emit_above,
            ..SceneOptions::default()
        };
        if emit_above.is_none() {
            // The bear has no emitter of its own: light it from above its bounds.
            if let Ok(scene) = load_obj(path, &options) {
                let (_, hi) = scene.bounds();
                options.emit_above = Some(hi.y - 0.05 * (hi.y - scene.bounds().0.y));
            }
        }
        if let Ok(scene) = load_obj(path, &options) {
            out.push((name.to_string(), build_patches(&scene, None)));
        }
    }
    let cornell = generated::subdivided_cornell_box(10_000);
    out.push(("cornell10k".to_string(), build_patches(&cornell, None)));
    out
}

fn stages(c: &mut Criterion) {
    let options = SolverOptions::default();
    let bins = Bins::new(options.bins);
    for (name, patches) in bench_scenes() {
        let mut group = c.benchmark_group(format!("{name}/{}", patches.len()));
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(20));
        group.bench_function("hierarchy_build", |b| {
            b.iter(|| ClusterTree::build(&patches))
        });
        group.bench_function("link_refinement", |b| {
            b.iter_batched(
                || ClusterTree::build(&patches),
                |mut tree| {
                    links::refine(
                        &mut tree,
                        &bins,
                        &link_params(&options),
                        &options.coupling(),
                        false,
                        &LinkBudget::unlimited(options.bins),
                    )
                    .unwrap()
                },
                criterion::BatchSize::LargeInput,
            )
        });
        let one = SolverOptions {
            max_iterations: 1,
            ..options.clone()
        };
        let mut prepared = Prepared::new(&patches, &one, false).unwrap();
        group.bench_function("hierarchical_one_iteration", |b| {
            b.iter(|| prepared.solve(&patches, &Progress::hidden()))
        });
        let mut prepared = Prepared::new(&patches, &options, false).unwrap();
        group.bench_function("hierarchical_full_solve", |b| {
            b.iter(|| prepared.solve(&patches, &Progress::hidden()))
        });
        group.bench_function(
            BenchmarkId::new("hierarchical_end_to_end", "build+links+solve"),
            |b| {
                b.iter(|| {
                    Prepared::new(&patches, &options, false)
                        .unwrap()
                        .solve(&patches, &Progress::hidden())
                })
            },
        );
        // What the CLI's default runs (load and output aside): the above plus exact direct light.
        group.bench_function(
            BenchmarkId::new("hierarchical_end_to_end", "with_direct_light"),
            |b| {
                b.iter(|| {
                    solve_hierarchical_direct(&patches, &options, &Progress::hidden()).unwrap()
                })
            },
        );
        // The dense solver's full solve takes minutes at this size: one sweep (near-pair cache
        // plus one streamed pass over all pairs) is measured; multiply by the iteration count.
        group.bench_function("dense_one_iteration", |b| {
            b.iter(|| solve_dense(&patches, &one, &Progress::hidden()).unwrap())
        });
        group.finish();
    }
}

criterion_group!(benches, stages);
criterion_main!(benches);
