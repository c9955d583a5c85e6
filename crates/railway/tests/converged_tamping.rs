//! The tamping cycle of `examples/python/small_track.toml` (about 750 grains, one 0.10 m block,
//! the whole 0.51 s cycle at dt = 1e-4 s with contacts of 1e7 N/m per point normally and 5e6
//! tangentially, and ≤ 400 sweeps) on the bed's five grain packs (`[ballast] seed` 3–7):
//! the settings that make NLGS converge through the insertion and the squeeze, held to the
//! quality they were measured at (BENCHMARKS.md, sessions 13, 19 and 27), with the machine's
//! limits, the compaction under the block and the released block's level.
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
    let s = TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(s.simulation.contact_stiffness, Some(1e7));
    assert_eq!(s.simulation.tangential_stiffness, Some(5e6));
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
    // Measured (with `solver.skip = 1`), packs 3–7: 81–191 of 5,100 steps unconverged
    // (1.6–3.7 %), largest residuals 0.043–0.39 (one step of the lift, 0.39, in pack 7; before
    // the edge contacts lying across a face got both their ends, 0.033–0.086, which is why the
    // bound is 0.5 rather than 0.25), largest overlaps 1.17–1.51 mm; compacity under the block
    // −1.6 %, +3.0 %, +11.3 %, +12.7 %, +5.2 % (mean +6.1 %), the cribs loosening by
    // 0.7–9.9 % (mean −4.9 %); the block, let down over 0.03 s and settled for 0.07 s more,
    // −1.7, +5.4, +4.6, +9.2, +3.2 mm from its level before the 10 mm lift (it fell through the
    // gap the tines left under it). Let go at once, it was launched (pack 4: +9.7 → +13.2 →
    // +9.7 mm within the 0.06 s it then had), which is why the bound above was lift + 1 mm
    // then and is the lift now.
    // Granular flow is chaotic, and a change that only reorders rounding moves such figures by
    // tens of percent: the bounds leave that margin.
    for c in &cycles {
        assert!(c.unconverged * 100 <= 7 * c.steps, "pack {}: {c:?}", c.seed);
        assert!(c.worst_residual <= 0.5, "pack {}: {c:?}", c.seed);
        assert!(c.deepest <= 2e-3, "pack {}: {c:?}", c.seed);
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
