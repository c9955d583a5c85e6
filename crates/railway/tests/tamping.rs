//! End-to-end track model on a CI-sized bed: preparation (dense, clean, cached bit-identically)
//! and a full tamping cycle that compacts the ballast under the tamped block.

use ballast_engine::math::DVec3;
use ballast_railway::compacity::compacity;
use ballast_railway::preparation::{load_or_prepare, PreparedSample};
use ballast_railway::scenario::TrackScenario;
use ballast_railway::track::TrackSpec;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A small track: a block of 0.14 × 0.28 × 0.10 m on 0.12 m of ballast, 0.32 m spacing, in a
/// 0.40 m wide bed; 31.5/50 ballast with 8–12 vertices (cheaper contacts); tines scaled to
/// the block; coarser steps (4e-4 s).
fn mini() -> TrackScenario {
    let mut s = TrackScenario::default_preset();
    s.track = TrackSpec {
        blocks: 1,
        block_size: [0.14, 0.28, 0.10],
        spacing: 0.32,
        depth: 0.12,
        width: 0.40,
        ..TrackSpec::default()
    };
    s.ballast.grains.vertices = [8, 12];
    s.ballast.seed = 7;
    let t = &mut s.tamping;
    t.blade = [0.015, 0.05, 0.05];
    t.shaft = [0.02, 0.02];
    t.tine_y = vec![-0.07, 0.07];
    t.open_gap = 0.05;
    t.squeeze = 0.035;
    t.lift = 0.015;
    t.depth_below_soffit = 0.015;
    // A CI-sized step, with the springs this bed was measured with: the default job's 1e6 N/m
    // needs its 1e-4 s step.
    s.simulation.dt = 4e-4;
    s.simulation.contact_stiffness = Some(2.5e5);
    s.simulation.tangential_stiffness = Some(2.5e5);
    s.simulation.vtk_interval = 0;
    s.solver.max_iterations = 200;
    s.indicators.depth = 0.05;
    s.validate().unwrap();
    s
}

/// The prepared beds' cache of this file's runs, shared by its tests (never removed, so under
/// cargo's `target/tmp` rather than the system's temporary folder).
fn cache_dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("ballast-tamping-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The mini bed, prepared once for all tests of this file (through the cache).
fn prepared() -> &'static PreparedSample {
    static BED: OnceLock<PreparedSample> = OnceLock::new();
    BED.get_or_init(|| {
        let s = mini();
        let (bed, warning) = load_or_prepare(
            &s.track,
            &s.ballast,
            &s.preparation,
            &s.friction,
            Some(&cache_dir()),
            &mut |_| {},
        )
        .unwrap();
        assert!(warning.is_none(), "{warning:?}");
        bed
    })
}

#[test]
fn prepared_bed_is_dense_level_and_clean() {
    let s = mini();
    let bed = prepared();
    let r = &bed.report;
    eprintln!("{r:?}");
    assert!(r.grains > 200, "{} grains", r.grains);
    assert!(r.removed_in_blocks > 0 && r.removed_above > 0);
    // Overlaps healed below the preparation's bound, at the cost of at most a grain or two.
    assert!(
        r.max_penetration < s.preparation.heal_overlap,
        "overlap {}",
        r.max_penetration
    );
    assert!(r.removed_wedged * 100 <= r.grains, "{r:?}");
    // At rest but for a few rattlers at the surface. The mean is theirs (the fastest moves at
    // 0.6–0.7 m/s) and varies from one deposition to another: 0.019 m/s with every pair
    // detected anew, 0.022 m/s with reused manifolds (the default), same bed otherwise.
    assert!(r.mean_speed < 0.03, "mean speed {}", r.mean_speed);
    assert!(r.max_speed < 1.0, "max speed {}", r.max_speed);
    // Level: no grain centre above the block tops; the cribs filled to near the top.
    let top = s.track.top();
    let zmax = bed.grains.iter().map(|g| g.position.z).fold(0.0, f64::max);
    assert!(zmax <= top + 1e-9, "{zmax} > {top}");
    assert!(zmax > top - 0.03, "cribs filled to {zmax}, top {top}");
    // Bulk compacity, one grain size away from walls and floor, under the soffit.
    let (bodies, layout) = ballast_railway::scene::build_bodies(
        &s.track,
        &ballast_railway::scene::Blocks::Fixed,
        None,
        &bed.grains,
        2700.0,
    );
    let w = s.track.width;
    let c = compacity(
        &bodies,
        |i| layout.grains.contains(&i),
        DVec3::new(0.04, -0.5 * w + 0.04, 0.02),
        DVec3::new(
            s.track.length() - 0.04,
            0.5 * w - 0.04,
            s.track.depth - 0.02,
        ),
    )
    .unwrap();
    eprintln!("bulk compacity {c}");
    assert!((0.55..=0.65).contains(&c), "bulk compacity {c}");
}

#[test]
fn cached_bed_is_bit_identical() {
    let s = mini();
    let first = prepared();
    let (again, _) = load_or_prepare(
        &s.track,
        &s.ballast,
        &s.preparation,
        &s.friction,
        Some(&cache_dir()),
        &mut |_| panic!("the cached bed must not be prepared again"),
    )
    .unwrap();
    assert!(again.from_cache);
    assert_eq!(again.grains.len(), first.grains.len());
    for (a, b) in again.grains.iter().zip(&first.grains) {
        assert_eq!(a.index, b.index);
        assert_eq!(
            a.position.to_array().map(f64::to_bits),
            b.position.to_array().map(f64::to_bits)
        );
        assert_eq!(
            a.orientation.to_array().map(f64::to_bits),
            b.orientation.to_array().map(f64::to_bits)
        );
        assert_eq!(a.shape.vertices, b.shape.vertices);
    }
    // Another seed is another bed.
    let mut other = s.ballast.clone();
    other.seed += 1;
    assert_ne!(
        ballast_railway::preparation::cache_path(
            &cache_dir(),
            &s.track,
            &s.ballast,
            &s.preparation,
            &s.friction
        ),
        ballast_railway::preparation::cache_path(
            &cache_dir(),
            &s.track,
            &other,
            &s.preparation,
            &s.friction
        )
    );
}

#[test]
fn full_cycle_compacts_the_ballast_under_the_block() {
    let s = mini();
    prepared();
    let mut m = s.build(Some(&cache_dir()), &mut |_| {}).unwrap();
    assert!(m.from_cache);
    let p = m.cycle.phases[0];
    let under = m
        .indicators
        .names()
        .iter()
        .position(|n| n == "compacity_under_block_1")
        .unwrap();
    let block_z = m
        .indicators
        .names()
        .iter()
        .position(|n| n == "block_z_1_m")
        .unwrap();
    let z0 = m.indicators.values(&m.world)[block_z];
    let run_to = |m: &mut ballast_railway::TrackModel, t: f64| {
        while m.world.time < t - 1e-9 {
            m.world.step();
        }
    };
    run_to(&mut m, p.squeeze);
    let before = m.indicators.values(&m.world);
    // Lifted by `lift` and held.
    assert!((before[block_z] - z0 - s.tamping.lift).abs() < 1e-6);
    run_to(&mut m, p.withdraw);
    let after = m.indicators.values(&m.world);
    eprintln!(
        "compacity under the block: {:.4} before the squeeze, {:.4} after",
        before[under], after[under]
    );
    assert!(
        after[under] > before[under] + 0.005,
        "{} → {}",
        before[under],
        after[under]
    );
    // The tines pushed the ballast: a compressive force along the squeeze on both sides.
    let end_time = m.cycle.duration;
    run_to(&mut m, end_time);
    let end = m.indicators.values(&m.world);
    // Let down, the block rests on the tamped ballast, above its initial level and about at
    // the lifted one. Measured on this bed's packs 3, 4, 5 and 7 (the test's seed; edge contacts
    // given both ends, BENCHMARKS.md session 27), let go at once: +15.5, +15.4, +14.9 and
    // +16.4 mm for the 15 mm lift, up to 1.4 mm above the lifted level; let down over half
    // the lower phase, pack 7 +16.1 mm. Hence lift + 2 mm above.
    eprintln!(
        "released block {:+.2} mm from its level before the lift",
        (end[block_z] - z0) * 1e3
    );
    assert!(
        end[block_z] > z0 - 0.005 && end[block_z] < z0 + s.tamping.lift + 2e-3,
        "released block {} m from its level before the lift",
        end[block_z] - z0
    );
    let n = s.steps();
    assert_eq!(m.world.step_index, n);
}

/// Ranks keep up to date only the grains they own (the others arrive as ghosts when a rank
/// needs them), and the indicators and the sections read each grain on its owner: on 2 and
/// 3 in-process ranks, with every other grain's state spoiled on each rank after every step
/// of the start of the cycle (the lift, the tines going down into the ballast), the run,
/// its indicators and its sections are one process's, bit for bit.
#[test]
fn ranks_step_the_track_from_their_own_grains_and_read_each_from_its_owner() {
    use ballast_engine::math::DQuat;
    use ballast_engine::solver::{Exchange, ThreadRanks};
    use ballast_railway::sections::{section_csv, Sections};
    use std::sync::Arc;
    const STEPS: u64 = 150;
    prepared();
    /// The indicators' bits and each section's CSV after `STEPS` steps, other ranks' bodies
    /// spoiled first.
    fn outputs(exchange: Option<Arc<dyn Exchange>>) -> (Vec<u64>, Vec<String>, usize, String) {
        use ballast_engine::bodies::BodyKind;
        let s = mini();
        let mut m = s.build(Some(&cache_dir()), &mut |_| {}).unwrap();
        m.world.set_exchange(exchange);
        let mut others = Vec::new();
        while m.world.step_index < STEPS {
            m.world.step();
            let w = &mut m.world;
            let n = w.bodies.len();
            let kind = &w.bodies.kind;
            others = (0..n)
                .filter(|&i| kind[i] == BodyKind::Dynamic && !w.answers_for(i))
                .collect();
            for &i in &others {
                w.bodies.position[i] = DVec3::NAN;
                w.bodies.orientation[i] = DQuat::from_xyzw(0.5, 0.5, 0.5, 0.5);
                w.bodies.velocity[i] = DVec3::splat(1e300);
                w.bodies.angular_velocity[i] = DVec3::NAN;
                w.bodies.angular_momentum[i] = DVec3::NAN;
            }
        }
        let values = m.indicators.values(&m.world);
        let sections = Sections::new(
            &s.track,
            s.tamping.tine_y[0],
            &m.layout,
            &m.cycle,
            &s.tamping.blocks,
            s.simulation.dt,
            STEPS,
        );
        let csv = sections
            .planes
            .iter()
            .map(|p| section_csv(&sections.points(&m.world, p)))
            .collect();
        let digest = m.world.state_digest();
        let bits = values.iter().map(|v| v.to_bits()).collect();
        (bits, csv, others.len(), digest)
    }
    let (values, csv, none, digest) = outputs(None);
    assert_eq!(none, 0);
    assert!(values.iter().all(|v| f64::from_bits(*v).is_finite()));
    assert!(csv.iter().all(|c| c.lines().count() > 10), "{csv:?}");
    for k in [2, 3] {
        let got: Vec<_> = ThreadRanks::group(k)
            .into_iter()
            .map(|r| {
                std::thread::spawn(move || {
                    let ex: Arc<dyn Exchange> = Arc::new(r);
                    outputs(Some(ex))
                })
            })
            .collect::<Vec<_>>()
            .into_iter()
            .map(|h| h.join().unwrap())
            .collect();
        for (r, (v, c, spoiled, d)) in got.iter().enumerate() {
            assert!(*spoiled > 0, "rank {r} of {k}: nothing spoiled");
            assert_eq!(d, &digest, "rank {r} of {k}: the run");
            assert_eq!(v, &values, "rank {r} of {k}: indicators");
            assert_eq!(c, &csv, "rank {r} of {k}: sections");
        }
    }
}
