//! The tamping cycle of `examples/python/small_track.toml` (754 grains, one 0.10 m block, the
//! whole 0.47 s cycle at dt = 1e-4 s with critically damped contacts of 1e7 N/m per point and
//! ≤ 400 sweeps): the settings that make NLGS converge through most of the insertion and the
//! squeeze, held to the quality they were measured at (BENCHMARKS.md, sessions 13 and 17),
//! with the machine's limits, overlaps that stay near a millimetre and the compaction under
//! the block.

use ballast_railway::TrackScenario;
use std::path::PathBuf;

#[test]
fn the_small_track_cycle_converges_on_most_steps_without_deep_overlaps() {
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
    for step in 0..steps {
        let r = model.world.step();
        unconverged += u64::from(!r.solve.converged);
        // The bed is prepared with rigid contacts: on the first steps its overlaps meet the
        // springs and are pushed out (residual 2.9 on step 1, 4e-2 on step 5, then ≤ 8e-3).
        if step >= 20 {
            worst = worst.max(r.solve.residual);
        }
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
    // Measured: 381 of 4,700 (8.1 %; 84 % at dt = 4e-4 s with rigid contacts), largest
    // residual after step 20 7.9e-2, largest overlap 1.37 mm, compacity 0.398 → 0.444. The
    // bounds are those plus about 20 %: granular flow is chaotic, and a change that only
    // reorders rounding moves such counts by that much. These bounds hold this grain pack:
    // the bed's other packs (`[ballast] seed` 4 and 5) leave 954 and 496 steps unconverged,
    // with overlaps of 1.09 and 1.69 mm (BENCHMARKS.md, session 17); before the contacts'
    // force followed their overlap, this pack's overlaps reached 2.98 mm and the others' 8.9.
    assert!(unconverged * 100 <= 10 * steps, "{unconverged} of {steps}");
    assert!(worst <= 0.1, "largest residual {worst}");
    assert!(deepest <= 1.7e-3, "largest overlap {deepest} m");
    assert!(after >= 1.1 * before, "compacity {before} → {after}");
}
