//! The tamping cycle of `examples/python/small_track.toml` (754 grains, one 0.10 m block, the
//! whole 0.47 s cycle at dt = 1e-4 s with contacts of 1e7 N/m per point normally and 5e6
//! tangentially, and ≤ 400 sweeps):
//! the settings that make NLGS converge through the insertion and the squeeze, held to the
//! quality they were measured at (BENCHMARKS.md, sessions 13 and 19), with the machine's limits and
//! the compaction under the block.

use ballast_railway::TrackScenario;
use std::path::PathBuf;

#[test]
fn the_small_track_cycle_converges_on_nearly_every_step() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/python/small_track.toml");
    let s = TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(s.simulation.contact_stiffness, Some(1e7));
    assert_eq!(s.simulation.tangential_stiffness, Some(5e6));
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
    // Measured (with `solver.skip = 1`): 76 of 4,700 (1.6 %; 84 % at dt = 4e-4 s with rigid
    // contacts), largest residual 0.082, largest overlap 1.54 mm, compacity 0.398 → 0.460,
    // 42 sweeps a step (without skipping: 245, 0.044, 1.58 mm, 0.466, 52 sweeps; rigid
    // sticking: 214, 0.034, 1.48 mm, 0.446, 83 sweeps). Granular flow is chaotic, and a change
    // that only reorders rounding moves such figures by tens of percent, so the bounds are set
    // over the bed's five grain packs (`[ballast] seed` 3–7, BENCHMARKS.md): 76–279 steps
    // unconverged (1.6–5.9 %; without skipping 73–407, rigid sticking 214–561), residuals
    // 0.033–0.086 (without skipping up to 0.443: seed 6, a grain wedged between the block's
    // end and a wall lets go), overlaps 1.23–1.84 mm (1.45–3.31 mm). The bounds are those
    // set before skipping; every pack measured with it is within them (at most 5.9 % of the
    // steps, a residual of 0.086 and an overlap of 1.84 mm).
    assert!(unconverged * 100 <= 7 * steps, "{unconverged} of {steps}");
    assert!(worst <= 0.25, "largest residual {worst}");
    assert!(deepest <= 2e-3, "largest overlap {deepest} m");
    assert!(after >= 1.1 * before, "compacity {before} → {after}");
}
