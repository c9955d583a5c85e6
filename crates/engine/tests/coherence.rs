//! Temporal coherence of detection (`detection::coherence`): manifolds reused while the bodies
//! stay within the reuse distance of their anchors agree with a fresh detection, depend on the
//! anchors alone, and a reuse distance of 0 is the exact method.

use ballast_engine::bodies::BodySet;
use ballast_engine::detection::{Detector, RawContact};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::presets::pile;
use ballast_engine::shapes::Shape;
use ballast_engine::world::World;
use std::collections::BTreeMap;

/// Deepest gap and its normal per pair.
fn deepest(raw: &[RawContact]) -> BTreeMap<(u32, u32), (f64, DVec3)> {
    let mut m: BTreeMap<(u32, u32), (f64, DVec3)> = BTreeMap::new();
    for c in raw {
        let e = m
            .entry((c.body1, c.body2))
            .or_insert((f64::INFINITY, c.normal));
        if c.gap < e.0 {
            *e = (c.gap, c.normal);
        }
    }
    m
}

/// Support separation of two polyhedra along unit `n` (from `a` toward `b`): `min over b of
/// n·v − max over a of n·v`; `None` when either is not a polyhedron.
fn support_separation(bodies: &BodySet, (a, b): (u32, u32), n: DVec3) -> Option<f64> {
    let extent = |i: u32| {
        let i = i as usize;
        let Shape::Polyhedron(p) = &bodies.shape[i] else {
            return None;
        };
        let (x, q) = (bodies.position[i], bodies.orientation[i]);
        let dots = p.vertices.iter().map(|&v| n.dot(x + q * v));
        Some(
            dots.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
                (lo.min(d), hi.max(d))
            }),
        )
    };
    Some(extent(b)?.0 - extent(a)?.1)
}

fn bits(raw: &[RawContact]) -> Vec<[u64; 8]> {
    raw.iter()
        .map(|c| {
            let (p, n) = (c.point, c.normal);
            [
                u64::from(c.body1) << 32 | u64::from(c.body2),
                p.x.to_bits(),
                p.y.to_bits(),
                p.z.to_bits(),
                n.x.to_bits(),
                n.y.to_bits(),
                n.z.to_bits(),
                c.gap.to_bits(),
            ]
        })
        .collect()
}

/// A pile of 150 grains poured and left to settle for 3500 steps (0.7 s: some grains still move).
fn settling_pile() -> World {
    let mut w = pile(150, [0.025, 0.05], 7, 0).build().unwrap();
    for _ in 0..3500 {
        w.step();
    }
    w
}

/// While a pile settles, the contacts of a detector that reuses manifolds agree with a fresh,
/// exact detection at the same poses: every pair within the alert distance is found; touching
/// or overlapping, its deepest gap is within `4δ` (each body moved at most `δ` since its
/// anchor, and the depth is 1-Lipschitz in each body's displacement); apart, it reports no
/// overlap beyond `4δ` (the separation of bodies apart is the largest over the axes the SAT
/// keeps, which change with the poses: not a Lipschitz function of them). Most pairs are in
/// fact reused.
#[test]
fn reused_manifolds_agree_with_a_fresh_detection() {
    let mut w = settling_pile();
    let (alert, dt) = (w.settings.alert, w.settings.dt);
    let reuse = 1e-5;
    let mut tracked = Detector::default();
    let (mut raw, mut exact) = (Vec::new(), Vec::new());
    let (mut reused, mut candidates, mut compared) = (0, 0, 0);
    let mut worst_gap: f64 = 0.0;
    let mut ties = 0;
    for step in 0..600 {
        w.step();
        tracked.detect(&w.bodies, alert, dt, reuse, &mut raw);
        if step < 100 || step % 10 != 0 {
            continue;
        }
        let (r, c) = tracked.reuse_counts();
        reused += r;
        candidates += c;
        Detector::default().detect(&w.bodies, alert, dt, 0.0, &mut exact);
        let (got, want) = (deepest(&raw), deepest(&exact));
        for (pair, &(gap, normal)) in &want {
            if gap > alert {
                continue;
            }
            let Some(&(g, n)) = got.get(pair) else {
                panic!("step {step}: pair {pair:?} at gap {gap:e} missed");
            };
            if gap <= 0.0 {
                worst_gap = worst_gap.max((g - gap).abs());
            }
            assert!(
                (g - gap).abs() <= 4.0 * reuse + 1e-12 || (gap > 0.0 && g > -4.0 * reuse),
                "step {step}, pair {pair:?}: deepest gap {g:e}, exact {gap:e}"
            );
            // Touching pairs keep their contact plane (faces turn by at most δ/ρ ≈ 1e-3),
            // unless another axis ties with it: then the reused normal must still separate
            // the bodies by the exact depth (within the same 4δ), an equally deep contact
            // plane the fresh detection broke the tie against.
            if gap < 0.0 && n.dot(normal) <= 0.999 {
                let along = support_separation(&w.bodies, *pair, n);
                assert!(
                    along.is_some_and(|s| (s - gap).abs() <= 4.0 * reuse + 1e-12),
                    "pair {pair:?}: normals {n} and {normal}, separation {along:?} along the \
                     reused one against the exact {gap:e}"
                );
                ties += 1;
            }
            compared += 1;
        }
    }
    assert!(compared > 5_000, "only {compared} pairs compared");
    let share = reused as f64 / candidates as f64;
    assert!(
        share > 0.3,
        "only {:.1} % of the pairs reused",
        100.0 * share
    );
    eprintln!(
        "{compared} pairs compared ({ties} ties of axes), {:.1} % reused, worst deepest-gap \
         difference {worst_gap:.2e} m",
        100.0 * share
    );
}

/// A reused manifold is a function of the anchors alone: when every body sits at its anchor,
/// a detector that reused its manifolds and a fresh one (no cache) give the same contacts bit
/// for bit. This is what makes a resumed run (anchors restored, cache empty) identical.
/// A body moved by less than `δ` keeps its manifolds, carried rigidly: under a translation `d`
/// of body 2 every gap grows by exactly `n·d`. Moved by more than `δ`, its pairs are computed
/// anew and the others are still reused.
#[test]
fn cached_manifolds_depend_on_the_anchors_alone() {
    let mut w = settling_pile();
    for _ in 0..400 {
        w.step();
    }
    let (alert, dt, reuse) = (w.settings.alert, w.settings.dt, 1e-5);
    // At rest: margins below δ, so every manifold may be reused.
    for i in 0..w.bodies.len() {
        w.bodies.velocity[i] = DVec3::ZERO;
        w.bodies.angular_velocity[i] = DVec3::ZERO;
    }
    let mut tracked = Detector::default();
    let (mut first, mut again, mut fresh) = (Vec::new(), Vec::new(), Vec::new());
    tracked.detect(&w.bodies, alert, dt, reuse, &mut first);
    tracked.detect(&w.bodies, alert, dt, reuse, &mut again);
    let (reused, all) = tracked.reuse_counts();
    assert_eq!(reused, all, "at rest every pair is reused");
    assert_eq!(bits(&first), bits(&again));

    // A grain in contact, moved by half the reuse distance: carried, not recomputed.
    let k = first
        .iter()
        .filter(|c| {
            c.gap < 0.0 && w.bodies.kind[c.body1 as usize] == w.bodies.kind[c.body2 as usize]
        })
        .map(|c| c.body2)
        .next()
        .expect("a grain–grain contact") as usize;
    let d = DVec3::new(0.3, -0.2, 0.25).normalize() * 0.5 * reuse;
    w.bodies.position[k] += d;
    tracked.detect(&w.bodies, alert, dt, reuse, &mut again);
    assert_eq!(
        tracked.reuse_counts().0,
        all,
        "a motion below δ reuses every pair"
    );
    assert_eq!(first.len(), again.len());
    let mut carried = 0;
    for (a, b) in first.iter().zip(&again) {
        let expected = if b.body2 as usize == k {
            a.gap + a.normal.dot(d)
        } else if b.body1 as usize == k {
            a.gap - a.normal.dot(d)
        } else {
            a.gap
        };
        assert!(
            (b.gap - expected).abs() < 1e-15,
            "gap {} expected {expected}",
            b.gap
        );
        carried += usize::from(b.body1 as usize == k || b.body2 as usize == k);
    }
    assert!(carried > 0);

    // Moved by twice δ: re-anchored, so every body is at its anchor again, and the contacts
    // equal those of a detector without any cache, bit for bit.
    w.bodies.position[k] += 3.0 * d;
    tracked.detect(&w.bodies, alert, dt, reuse, &mut again);
    let (reused, all) = tracked.reuse_counts();
    assert!(
        reused < all && reused > all / 2,
        "{reused} of {all} pairs reused"
    );
    Detector::default().detect(&w.bodies, alert, dt, reuse, &mut fresh);
    assert_eq!(bits(&again), bits(&fresh));
}

/// With a reuse distance of 0 nothing is cached: each detection equals a fresh detector's, bit
/// for bit, step after step of a moving pile.
#[test]
fn reuse_distance_zero_is_the_exact_method() {
    let mut w = pile(60, [0.025, 0.05], 2, 0).build().unwrap();
    let (alert, dt) = (w.settings.alert, w.settings.dt);
    let mut tracked = Detector::default();
    let (mut raw, mut fresh) = (Vec::new(), Vec::new());
    let mut touching = 0;
    for step in 0..1200 {
        w.step();
        tracked.detect(&w.bodies, alert, dt, 0.0, &mut raw);
        assert_eq!(tracked.reuse_counts().0, 0);
        if step % 100 == 0 {
            Detector::default().detect(&w.bodies, alert, dt, 0.0, &mut fresh);
            assert_eq!(bits(&raw), bits(&fresh), "step {step}");
            touching += raw.iter().filter(|c| c.gap < 0.0).count();
        }
    }
    assert!(touching > 50, "only {touching} touching points compared");
}
