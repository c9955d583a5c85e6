//! Contact detection (broad + narrow phase) on a settled packing of random polyhedra.
//!
//! `cargo bench -p ballast-engine --bench detection`. The packing is settled in the set-up
//! (1,000 grains, cheap solver settings); with `BALLAST_PACKING=FILE` and `BALLAST_GRAINS=N`
//! it is read instead from a packing written by `ballast bench --scaling --packing FILE`.

use ballast_engine::detection::{Detector, RawContact};
use ballast_engine::output::checkpoint::read_checkpoint;
use ballast_engine::scenario::presets::pile;
use ballast_engine::solver::SolverSettings;
use ballast_engine::world::World;
use criterion::{criterion_group, criterion_main, Criterion};

fn settled() -> World {
    let grains = std::env::var("BALLAST_GRAINS")
        .ok()
        .and_then(|g| g.parse().ok())
        .unwrap_or(1000);
    let mut scenario = pile(grains, [0.025, 0.05], 1, 1500);
    scenario.solver = SolverSettings {
        tolerance: 1e-3,
        max_iterations: 60,
        ..Default::default()
    };
    let mut world = scenario.build().expect("pile scenario");
    match std::env::var_os("BALLAST_PACKING") {
        Some(path) => read_checkpoint(std::path::Path::new(&path), &mut world).expect("packing"),
        None => (0..1500).for_each(|_| {
            world.step();
        }),
    }
    world
}

fn detection(c: &mut Criterion) {
    let world = settled();
    let (alert, dt) = (world.settings.alert, world.settings.dt);
    let mut detector = Detector::default();
    let mut raw: Vec<RawContact> = Vec::new();
    detector.detect(&world.bodies, alert, dt, 0.0, &mut raw);
    eprintln!(
        "{} bodies, {} contact points",
        world.bodies.len(),
        raw.len()
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    c.bench_function("detect_settled_1_thread", |b| {
        b.iter(|| pool.install(|| detector.detect(&world.bodies, alert, dt, 0.0, &mut raw)))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = detection
}
criterion_main!(benches);
