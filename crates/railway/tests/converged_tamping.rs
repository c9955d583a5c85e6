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
    // Measured: 214 of 4,700 (4.6 %; 84 % at dt = 4e-4 s with rigid contacts), largest
    // residual 0.034, largest overlap 1.48 mm, compacity 0.398 → 0.446 (with the correction
    // counting whole overlaps: 196, 0.157, 3.31 mm, 0.440). Granular flow is chaotic, and a
    // change that only reorders rounding moves such figures by tens of percent, so the bounds
    // are set over the bed's five grain packs (`[ballast] seed` 3–7, BENCHMARKS.md): 214–561
    // steps unconverged (4.6–11.9 %), residuals 0.029–1.006 (seed 6: one step as a grain
    // wedged at 20 kN between the block's end and a wall lets go), overlaps 1.21–2.79 mm. The
    // unconverged bound holds this pack with a 30 % margin, the residual bound this pack's
    // residual seven times over, and the overlap bound this pack's plus 35 %.
    assert!(unconverged * 100 <= 6 * steps, "{unconverged} of {steps}");
    assert!(worst <= 0.25, "largest residual {worst}");
    assert!(deepest <= 2e-3, "largest overlap {deepest} m");
    assert!(after >= 1.1 * before, "compacity {before} → {after}");
}
