//! The tiled preparation (`[preparation] tiled`): one block's segment prepared and repeated
//! along the track, then settled and healed as a whole.

use ballast_railway::clipped_volume;
use ballast_railway::grading::GradingCurve;
use ballast_railway::preparation::{prepare, BallastSpec, PreparationSpec, PreparedSample};
use ballast_railway::scene::TrackFriction;
use ballast_railway::track::{Aabb, TrackSpec};

/// Two small blocks on a thin bed (the CI-sized track of `examples/python/small_track.toml`,
/// two segments long).
fn specs() -> (TrackSpec, BallastSpec, PreparationSpec) {
    let track = TrackSpec {
        blocks: 2,
        block_size: [0.10, 0.18, 0.08],
        spacing: 0.32,
        depth: 0.08,
        width: 0.26,
        length: Some(0.64),
        ..TrackSpec::default()
    };
    let mut ballast = BallastSpec::default();
    ballast.grains.grading = GradingCurve::en13450_31_5_50();
    ballast.grains.vertices = [8, 12];
    ballast.seed = 3;
    let prep = PreparationSpec {
        dt: 1e-3,
        settle_time: 0.1,
        max_extra_time: 0.15,
        cache: false,
        ..PreparationSpec::default()
    };
    (track, ballast, prep)
}

/// Solid fraction of the grains in `b`.
fn compacity(s: &PreparedSample, b: &Aabb) -> f64 {
    let solid: f64 = s
        .grains
        .iter()
        .map(|g| clipped_volume(&g.shape, g.position, g.orientation, b.min, b.max))
        .sum();
    solid / b.volume()
}

#[test]
fn a_tiled_bed_repeats_its_segment_and_keeps_the_deposited_density() {
    let (track, ballast, prep) = specs();
    let friction = TrackFriction::default();
    let mut no_progress = |_| {};
    let deposited = prepare(&track, &ballast, &prep, &friction, &mut no_progress).unwrap();
    let tiled_prep = PreparationSpec {
        tiled: true,
        ..prep.clone()
    };
    let tiled = prepare(&track, &ballast, &tiled_prep, &friction, &mut no_progress).unwrap();
    let r = &tiled.report;
    eprintln!("deposited {:?}\ntiled {r:?}", deposited.report);

    // Healed like any prepared bed.
    assert!(r.max_penetration < prep.heal_overlap, "{r:?}");
    // The segment's grains once per block: copy c of grain i is grain c·n + i.
    let n = r.generated / 2;
    assert_eq!(r.generated, 2 * n);
    let first: Vec<_> = tiled.grains.iter().filter(|g| g.index < n).collect();
    let second: Vec<_> = tiled.grains.iter().filter(|g| g.index >= n).collect();
    assert_eq!(first.len() + second.len(), tiled.grains.len());
    assert!(first.len().abs_diff(second.len()) <= r.removed_wedged);
    // Each copy sits one spacing on from the other, moved only by the short settling of the
    // whole bed: the median grain by less than 2 mm.
    let mut moved: Vec<f64> = first
        .iter()
        .filter_map(|a| {
            let b = second.iter().find(|b| b.index == a.index + n)?;
            Some((b.position - a.position - glam_x(track.spacing)).length())
        })
        .collect();
    assert!(
        moved.len() > first.len() * 9 / 10,
        "{} of {}",
        moved.len(),
        first.len()
    );
    moved.sort_by(f64::total_cmp);
    let median = moved[moved.len() / 2];
    assert!(median < 2e-3, "median shift off the tiling: {median} m");

    // About as many grains and as dense as the bed deposited in one piece. On this bed of
    // 50 mm grains a segment is only 0.32 m long, and its end walls loosen the ballast
    // beside them: measured 528 grains deposited, 498 tiled (5.7 % fewer).
    let (a, b) = (deposited.grains.len() as f64, tiled.grains.len() as f64);
    assert!((a - b).abs() <= 0.08 * a, "{a} grains deposited, {b} tiled");
    // The ballast under the soffits over the whole bed, 2 cm from its walls and floor.
    let bulk = Aabb {
        min: ballast_engine::math::DVec3::new(0.02, -0.11, 0.02),
        max: ballast_engine::math::DVec3::new(0.62, 0.11, track.depth),
    };
    let (ca, cb) = (compacity(&deposited, &bulk), compacity(&tiled, &bulk));
    eprintln!("compacity under the soffits: deposited {ca:.4}, tiled {cb:.4}");
    // The cribs, where the segments join (the middle crib) and where a segment's half-crib
    // lay against its end wall: on average as dense as deposited, within the scatter of beds
    // this small. Measured with seeds 1–6: mean crib
    // compacity tiled against deposited +0.2, −4.7, +8.1, −14.6, +6.6, −10.3 % (−2.5 % on
    // average), under the soffits +6.6, +6.3, −3.2, −1.2, −5.9, +0.4 % (+0.5 %): the bounds
    // are those spreads, which a gap or a pile-up where the segments join would exceed.
    let mean_crib = |s: &PreparedSample| {
        (0..=2)
            .map(|k| compacity(s, &track.crib(k).unwrap()))
            .sum::<f64>()
            / 3.0
    };
    let (ma, mb) = (mean_crib(&deposited), mean_crib(&tiled));
    eprintln!("mean crib compacity: deposited {ma:.4}, tiled {mb:.4}");
    assert!(
        (ma - mb).abs() <= 0.15 * ma,
        "cribs: deposited {ma}, tiled {mb}"
    );
    assert!((ca - cb).abs() <= 0.07 * ca, "deposited {ca}, tiled {cb}");
}

fn glam_x(x: f64) -> ballast_engine::math::DVec3 {
    ballast_engine::math::DVec3::new(x, 0.0, 0.0)
}

#[test]
fn tiling_needs_a_whole_number_of_segments() {
    let (mut track, ballast, prep) = specs();
    track.length = Some(0.70);
    let prep = PreparationSpec {
        tiled: true,
        ..prep
    };
    let err = prepare(
        &track,
        &ballast,
        &prep,
        &TrackFriction::default(),
        &mut |_| {},
    )
    .expect_err("refused");
    let text = err.to_string();
    assert!(
        text.contains("preparation.tiled") && text.contains("blocks × spacing"),
        "{text}"
    );
}
