//! The tamping cycle of `examples/python/small_track.toml` (754 grains, one 0.10 m block, the
//! whole 0.47 s cycle at dt = 1e-4 s with contacts of 1e7 N/m per point and ≤ 400 sweeps):
//! the settings that make NLGS converge through the insertion and the squeeze, held to the
//! quality they were measured at (BENCHMARKS.md, session 13), with the machine's limits and
//! the compaction under the block.

use ballast_railway::TrackScenario;
use std::path::PathBuf;

#[test]
fn the_small_track_cycle_converges_on_nearly_every_step() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/python/small_track.toml");
    let s = TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(s.simulation.contact_stiffness, Some(1e7));
    let cache = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("ballast-converged-tamping-{}", std::process::id()));
    std::fs::create_dir_all(&cache).unwrap();
    let mut model = s.build(Some(&cache), &mut |_| {}).unwrap();
    std::fs::remove_dir_all(&cache).ok();
    let names = model.indicators.names().to_vec();
    let col = |name: &str| names.iter().position(|n| n == name).unwrap();
    let under = col("compacity_under_block_1");
    let before = model.indicators.values(&model.world)[under];
    let steps = s.steps();
    let (mut unconverged, mut worst, mut deepest) = (0u64, 0.0f64, 0.0f64);
    let limits = [s.tamping.squeeze_force, s.tamping.insertion_force];
    for _ in 0..steps {
        let r = model.world.step();
        unconverged += u64::from(!r.solve.converged);
        worst = worst.max(r.solve.residual);
        deepest = deepest.max(r.max_penetration);
        for d in model.world.drives() {
            let f = d.impulse_v / s.simulation.dt;
            assert!(f.x.abs() <= limits[0] * (1.0 + 1e-9), "drive {f} N");
            assert!(f.z.abs() <= limits[1] * (1.0 + 1e-9), "drive {f} N");
        }
    }
    let after = model.indicators.values(&model.world)[under];
    eprintln!(
        "{unconverged} of {steps} steps unconverged, largest residual {worst:.3e}, largest \
         overlap {:.2} mm, compacity under the block {before:.3} → {after:.3}",
        deepest * 1e3
    );
    // Measured: 243 of 4,700 (5.2 %; 84 % at dt = 4e-4 s with rigid contacts), largest residual
    // 3.0e-2, largest overlap 2.98 mm, compacity 0.398 → 0.460. The bounds are those plus
    // about 20 %: granular flow is chaotic, and a change that only reorders rounding moves
    // such counts by that much (three grain packs of the same pile: 33 to 68 steps
    // unconverged). These bounds hold this grain pack: the bed's other packs (`[ballast]
    // seed` 4 and 5) give 479 and 248 steps unconverged, residuals up to 0.12 and 0.06, and
    // overlaps of 3.45 and 8.9 mm (BENCHMARKS.md, session 16).
    assert!(unconverged * 100 <= 6 * steps, "{unconverged} of {steps}");
    assert!(worst <= 0.05, "largest residual {worst}");
    assert!(deepest <= 3.5e-3, "largest overlap {deepest} m");
    assert!(after >= 1.1 * before, "compacity {before} → {after}");
}
