//! The tamping cycle of `examples/python/small_track.toml` (about 750 grains, one 0.10 m block,
//! the whole 0.51 s cycle) with the default job's contact law and solver (dt = 1e-4 s, springs
//! of 1e6 N/m per point with the hyperbolic closure and the overlap law, a natural-map residual
//! of 1e-3 within 300 sweeps) on the bed's five grain packs (`[ballast] seed` 3–7): the CI-sized
//! run of issue 15, held to the default job's bounds (steps unconverged, overlaps), with the
//! machine's limits, the compaction under the block and the released block's level.
//!
//! Under the 0.10 × 0.18 m block the 5 cm control volume holds one layer of 31.5/50 grains, so
//! whether one pack compacts depends on where a few grains sit: the compaction is asserted on
//! the mean over the packs, every other figure on each pack.

use ballast_railway::TrackScenario;
use std::path::PathBuf;

/// What one pack's cycle measured.
#[derive(Debug)]
struct Cycle {
    seed: u64,
    steps: u64,
    unconverged: u64,
    worst_residual: f64,
    deepest: f64,
    /// Compacity under the block before the lift and after the release.
    under: [f64; 2],
    /// Mean compacity of the two half-cribs before the lift and after the release.
    cribs: [f64; 2],
    /// The released block's level against its level before the lift (m).
    settled: f64,
}

/// The cycle of `s` on grain pack `seed`.
fn cycle(mut s: TrackScenario, seed: u64) -> Cycle {
    s.ballast.seed = seed;
    let cache = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "ballast-converged-tamping-{}-{seed}",
        std::process::id()
    ));
    std::fs::create_dir_all(&cache).unwrap();
    let mut model = s.build(Some(&cache), &mut |_| {}).unwrap();
    std::fs::remove_dir_all(&cache).ok();
    let names = model.indicators.names().to_vec();
    let col = |name: &str| names.iter().position(|n| n == name).unwrap();
    let (under, crib0, crib1, block_z) = (
        col("compacity_under_block_1"),
        col("compacity_crib_0"),
        col("compacity_crib_1"),
        col("block_z_1_m"),
    );
    let before = model.indicators.values(&model.world);
    let steps = s.steps();
    let (mut unconverged, mut worst, mut deepest) = (0u64, 0.0f64, 0.0f64);
    let limits = [s.tamping.squeeze_force, s.tamping.insertion_force];
    let lowering = s.tamping.lowering_force(&s.track);
    let blocks = model.layout.blocks.clone();
    for _ in 0..steps {
        let r = model.world.step();
        unconverged += u64::from(!r.solve.converged);
        worst = worst.max(r.solve.residual);
        deepest = deepest.max(r.max_penetration);
        for d in model.world.drives() {
            let f = d.impulse_v / s.simulation.dt;
            if blocks.contains(&(d.body as usize)) {
                // The lifting unit letting the block down, within its falling bound.
                assert!(
                    f.abs().max_element() <= lowering * (1.0 + 1e-9),
                    "seed {seed}: block drive {f} N"
                );
                continue;
            }
            assert!(
                f.x.abs() <= limits[0] * (1.0 + 1e-9),
                "seed {seed}: drive {f} N"
            );
            assert!(
                f.z.abs() <= limits[1] * (1.0 + 1e-9),
                "seed {seed}: drive {f} N"
            );
        }
    }
    let after = model.indicators.values(&model.world);
    let c = Cycle {
        seed,
        steps,
        unconverged,
        worst_residual: worst,
        deepest,
        under: [before[under], after[under]],
        cribs: [
            (before[crib0] + before[crib1]) / 2.0,
            (after[crib0] + after[crib1]) / 2.0,
        ],
        settled: after[block_z] - before[block_z],
    };
    eprintln!("{c:?}");
    c
}

#[test]
fn the_small_track_cycle_converges_and_compacts_under_the_block() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/python/small_track.toml");
    let mut s = TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    // The file keeps the stiff linear springs it was first measured with; the default job's
    // law and solver replace them here.
    let default = TrackScenario::default_preset();
    (s.simulation, s.solver) = (default.simulation, default.solver);
    assert_eq!(s.simulation.contact_stiffness, Some(1e6));
    assert_eq!(s.simulation.dt, 1e-4);
    let lift = s.tamping.lift;
    // The packs run side by side (each run's own result does not depend on it).
    let cycles: Vec<Cycle> = std::thread::scope(|scope| {
        let runs: Vec<_> = (3..=7)
            .map(|seed| {
                let s = s.clone();
                scope.spawn(move || cycle(s, seed))
            })
            .collect();
        runs.into_iter().map(|r| r.join().unwrap()).collect()
    });
    // Measured, packs 3–7: 0, 1, 0, 7, 12 of 5,100 steps unconverged (at most 0.24 %, the
    // default job's bound is 1 %), largest residuals 0.001–0.165, largest overlaps 0.95, 0.90,
    // 0.98, 0.93, 0.89 mm (the closure law holds a contact's deflection to 0.75 mm); compacity
    // under the block +11.4, +3.6, +4.1, +16.4, +13.9 % (mean +9.9 %), the cribs loosening by
    // 2.2–10.3 % (mean −4.5 %); the block, let down over 0.03 s and settled for 0.07 s more,
    // −0.6, +7.6, +4.1, +8.7, +4.1 mm from its level before the 10 mm lift (it falls through
    // the gap the tines left under it). With the file's stiff linear springs (1e7 N/m, rate
    // form) the same packs left 1.6–3.7 % of their steps unconverged and overlaps of 1.17–1.51
    // mm (BENCHMARKS.md, sessions 27 and 37).
    // Granular flow is chaotic, and a change that only reorders rounding moves such figures by
    // tens of percent: the bounds on the residual and the compaction leave that margin; the
    // overlap bound is the project's (1 mm), which the closure law is built to keep.
    for c in &cycles {
        assert!(c.unconverged * 100 <= c.steps, "pack {}: {c:?}", c.seed);
        assert!(c.worst_residual <= 0.5, "pack {}: {c:?}", c.seed);
        assert!(c.deepest <= 1e-3, "pack {}: {c:?}", c.seed);
        // Let down, the block rests on the tamped ballast: not sunk below its level before
        // the lift by more than a few millimetres, nor above the lift.
        assert!(
            c.settled > -5e-3 && c.settled < lift,
            "pack {}: {c:?}",
            c.seed
        );
    }
    let n = cycles.len() as f64;
    let gain = cycles
        .iter()
        .map(|c| c.under[1] / c.under[0] - 1.0)
        .sum::<f64>()
        / n;
    let cribs = cycles
        .iter()
        .map(|c| c.cribs[1] / c.cribs[0] - 1.0)
        .sum::<f64>()
        / n;
    eprintln!("compacity under the block {gain:+.3}, in the cribs {cribs:+.3} (means)");
    // Shi et al. (2020): +7.6 % in the top layer under the sleeper, the cribs looser.
    assert!(gain >= 0.03, "mean compaction under the block {gain}");
    assert!(cribs < 0.0, "mean change in the cribs {cribs}");
}
