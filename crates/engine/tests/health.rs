//! The health check: a diverging run is caught within a step, naming the step, the bodies,
//! their groups and the quantity; a healthy one never is.

use ballast_engine::health::{HealthCheck, Quantity, SPEED_FACTOR};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::presets::pile;
use ballast_engine::scenario::Scenario;
use ballast_engine::world::World;

/// A floor, a resting box (group "block") and a second box (group "projectile"), with
/// `extra` appended to the projectile's table.
fn two_boxes(simulation: &str, extra: &str) -> (Scenario, World) {
    let text = format!(
        r#"
[simulation]
dt = 1e-3
steps = 100
{simulation}

[materials]
stone = 2700

[friction]
default = 0.5

[[body]]
shape = "plane"
kind = "fixed"
group = "floor"
point = [0, 0, 0]
normal = [0, 0, 1]

[[body]]
shape = "box"
group = "block"
material = "stone"
half_extents = [0.05, 0.05, 0.05]
center = [0, 0, 0.05]

[[body]]
shape = "box"
group = "projectile"
material = "stone"
half_extents = [0.02, 0.02, 0.02]
{extra}
"#
    );
    let s = Scenario::from_toml(&text).unwrap();
    let w = s.build().unwrap();
    (s, w)
}

/// Steps until the check fails (at most `n` steps).
fn run_until_fault(
    world: &mut World,
    check: &HealthCheck,
    n: u64,
) -> Option<ballast_engine::health::Divergence> {
    for _ in 0..n {
        world.step();
        if let Err(d) = check.check(world) {
            return Some(d);
        }
    }
    None
}

#[test]
fn a_body_thrown_at_1e12_m_s_is_named_at_the_first_step() {
    let (s, mut w) = two_boxes("", "center = [1, 0, 0.5]\nvelocity = [1e12, 0, 0]");
    let check = s.health_check(&w);
    // No driver; the scene spans H = 0.5 m plus the two boxes' bounding radii (the block's
    // lowest and the projectile's highest point): 10 × √(2 · 9.81 · 0.571) = 33.5 m/s.
    let h = 0.5 + 0.02 * 3f64.sqrt() - 0.05 + 0.05 * 3f64.sqrt();
    let fall = (2.0 * 9.81 * h).sqrt();
    assert!(
        (check.max_speed - SPEED_FACTOR * fall).abs() < 1e-9,
        "{}",
        check.max_speed
    );
    let d = run_until_fault(&mut w, &check, 3).expect("caught");
    assert_eq!((d.step, d.quantity), (1, Quantity::Speed));
    assert_eq!(d.bodies, [2]);
    assert_eq!(d.groups, ["projectile"]);
    assert_eq!(d.value, 1e12);
    let msg = d.to_string();
    for part in [
        "step 1",
        "body 2 (group \"projectile\")",
        "1.000e12 m/s",
        "33.478",
        "max_speed",
    ] {
        assert!(msg.contains(part), "{part}: {msg}");
    }
    // The scenario may allow it.
    let (s, mut w) = two_boxes(
        "max_speed = 2e12",
        "center = [1, 0, 0.5]\nvelocity = [1e12, 0, 0]",
    );
    assert_eq!(
        {
            let c = s.health_check(&w);
            run_until_fault(&mut w, &c, 3)
        },
        None
    );
}

#[test]
fn huge_gravity_is_caught_at_the_first_step_without_overflow() {
    let (s, mut w) = two_boxes("gravity = [0, 0, -1e200]", "center = [0, 0, 0.3]");
    let check = s.health_check(&w);
    // √(2 g H) computed without squaring g: finite.
    assert!(check.max_speed.is_finite() && check.max_speed > 1e100);
    let d = run_until_fault(&mut w, &check, 2).expect("caught");
    // The falling projectile reaches 2e197 m/s; the block pressed into the floor by such a
    // weight ends with a non-finite state, which is reported first.
    assert_eq!(d.step, 1);
    assert_eq!(d.bodies, [1]);
    assert!(d.to_string().contains("step 1"), "{d}");
}

#[test]
fn non_finite_state_is_named() {
    let (s, mut w) = two_boxes("", "center = [0, 0, 0.3]");
    let check = s.health_check(&w);
    w.step();
    w.bodies.angular_velocity[1].y = f64::NAN;
    let d = check.check(&w).unwrap_err();
    assert_eq!(d.quantity, Quantity::AngularVelocity);
    assert_eq!((d.bodies.as_slice(), d.count), (&[1u32][..], 1));
    let msg = d.to_string();
    assert!(
        msg.contains("body 1 (group \"block\") has a non-finite angular velocity (NaN)"),
        "{msg}"
    );
    // A position beats a speed: non-finite state is reported first.
    w.bodies.position[2].x = f64::INFINITY;
    w.bodies.velocity[1] = DVec3::new(1e9, 0.0, 0.0);
    let d = check.check(&w).unwrap_err();
    assert_eq!(d.count, 2);
    assert_eq!(d.bodies, [1], "the first body in order");
}

#[test]
fn an_overlap_deeper_than_the_inradius_is_named() {
    // The projectile's centre 30 mm inside the block's top face: 50 mm overlap, more than
    // twice its 20 mm inradius.
    let (s, mut w) = two_boxes("", "center = [0, 0, 0.07]");
    let check = s.health_check(&w);
    let d = run_until_fault(&mut w, &check, 1).expect("caught");
    assert_eq!((d.step, d.quantity), (1, Quantity::Overlap));
    let mut bodies = d.bodies.clone();
    bodies.sort_unstable();
    assert_eq!(bodies, [1, 2]);
    assert!((d.value - 0.05).abs() < 1e-6, "{}", d.value);
    assert!((d.bound - 0.04).abs() < 1e-12, "{}", d.bound);
    let msg = d.to_string();
    assert!(
        msg.contains("overlap by 50 mm, more than the bound 40 mm")
            && msg.contains("2 × the smaller inradius of the two bodies, 20 mm"),
        "{msg}"
    );
    // 30 mm overlap, more than the inradius: within the bound; a fixed bound of 1 mm
    // catches it.
    let (s, mut w) = two_boxes("", "center = [0, 0, 0.09]");
    assert_eq!(
        {
            let c = s.health_check(&w);
            run_until_fault(&mut w, &c, 1)
        },
        None
    );
    let (s, mut w) = two_boxes("max_overlap = 1e-3", "center = [0, 0, 0.09]");
    let d = {
        let c = s.health_check(&w);
        run_until_fault(&mut w, &c, 1)
    }
    .expect("caught");
    assert_eq!(d.bound, 1e-3);
    assert!(d.to_string().contains("max_overlap"), "{d}");
}

/// A pile of 60 grains falling into a box and settling passes the check at every step, with
/// a wide margin.
#[test]
fn a_settling_pile_is_healthy() {
    let s = pile(60, [0.025, 0.05], 5, 1500);
    let mut w = s.build().unwrap();
    let check = s.health_check(&w);
    let (mut speed, mut overlap) = (0.0f64, 0.0f64);
    for _ in 0..1500 {
        w.step();
        check.check(&w).unwrap();
        let (a, b) = check.margins(&w);
        speed = speed.max(a);
        overlap = overlap.max(b);
    }
    assert!(speed > 0.01 && speed < 0.5, "speed margin {speed}");
    assert!(overlap > 0.0 && overlap < 0.5, "overlap margin {overlap}");
}

/// Two bodies in the same spot overlap by their width, twice the inradius: the running bound
/// lets that pass, the initial state's bound (one inradius) refuses it, and the warnings name
/// the pair and a body placed under the floor.
#[test]
fn the_initial_state_is_checked_more_strictly() {
    let (s, mut w) = two_boxes("", "center = [0.5, 0, 0.3]");
    let check = s.health_check(&w);
    w.bodies.position[2] = w.bodies.position[1];
    w.bodies.position[1].z = -5.0;
    w.bodies.position[2].z = 0.5;
    let twin = w.bodies.shape[1].clone();
    w.bodies.shape[2] = twin;
    // Box 1 (50 mm half extents) under the floor, and a twin of it where box 2 was.
    w.detect();
    let warnings = ballast_engine::health::initial_warnings(&w, 1e-3, 5);
    assert!(
        warnings.iter().any(|m| m
            == "body 1 (group \"block\") lies wholly beneath the plane of body 0 (group \"floor\"), its centre 5 m under it"),
        "{warnings:?}"
    );
    assert!(check.check(&w).is_err(), "5 m under the floor");
    // Now the twins in the same spot above the floor.
    let (s, mut w) = two_boxes("", "center = [0.5, 0, 0.3]");
    w.bodies.shape[2] = w.bodies.shape[1].clone();
    w.bodies.position[1].z = 0.5;
    w.bodies.position[2] = w.bodies.position[1];
    w.detect();
    let check = s.health_check(&w);
    assert_eq!(
        check.check(&w),
        Ok(()),
        "100 mm overlap, the running bound is 2 × 50 mm"
    );
    let d = check.initial().check(&w).unwrap_err();
    assert_eq!((d.step, d.quantity), (0, Quantity::Overlap));
    assert!((d.value - 0.1).abs() < 1e-9 && d.bound == 0.05, "{d}");
    assert!(
        d.to_string()
            .starts_with("the initial state (step 0) is out of bounds"),
        "{d}"
    );
    let warnings = ballast_engine::health::initial_warnings(&w, 1e-3, 5);
    assert_eq!(
        warnings,
        ["bodies 1 (group \"block\") and 2 (group \"projectile\") overlap by 100 mm at the start"]
    );
}
