//! Scenario files: valid files build, every mistake gives one error naming the field.

use ballast_engine::bodies::{Driver, Term};
use ballast_engine::scenario::Scenario;

const BASE: &str = r#"
[simulation]
dt = 2e-4
steps = 10
[materials]
stone = 2700
[friction]
default = 0.8
[[body]]
shape = "plane"
kind = "fixed"
point = [0, 0, 0]
normal = [0, 0, 1]
[[body]]
shape = "box"
material = "stone"
half_extents = [0.05, 0.05, 0.05]
center = [0, 0, 0.05]
"#;

fn error_of(text: &str) -> String {
    Scenario::from_toml(text)
        .expect_err("should be rejected")
        .to_string()
}

#[test]
fn examples_parse_and_build() {
    for f in ["pile.toml", "sliding_block.toml"] {
        let path = format!("{}/../../examples/{f}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap();
        let s = Scenario::from_toml(&text).unwrap_or_else(|e| panic!("{f}: {e}"));
        s.build().unwrap();
    }
    let w = Scenario::from_toml(BASE).unwrap().build().unwrap();
    assert_eq!(w.bodies.len(), 2);
}

#[test]
fn mistakes_name_the_field() {
    let cases: &[(&str, &str, &[&str])] = &[
        ("dt = 2e-4", "dt = -1.0", &["simulation.dt", "-1"]),
        (
            "steps = 10",
            "steps = 10\ntheta = 0.2",
            &["simulation.theta", "0.2", "[0.5, 1]"],
        ),
        (
            "steps = 10",
            "steps = 10\nduration = 1.0",
            &["steps or duration"],
        ),
        ("stone = 2700", "stone = -5.0", &["materials.stone", "-5"]),
        (
            "default = 0.8",
            "default = -0.1",
            &["friction.default", "-0.1"],
        ),
        (
            "material = \"stone\"",
            "material = \"granite\"",
            &["body[1].material", "granite", "stone"],
        ),
        (
            "half_extents = [0.05, 0.05, 0.05]",
            "half_extents = [0.05, 0.0, 0.05]",
            &["body[1].half_extents = [0.05, 0, 0.05] must be > 0"],
        ),
        (
            "normal = [0, 0, 1]",
            "normal = [0, 0, 0]",
            &["body[0].normal = [0, 0, 0] must be"],
        ),
        (
            "kind = \"fixed\"",
            "kind = \"dynamic\"",
            &["body[0].kind = \"dynamic\": a plane must be \"fixed\""],
        ),
        ("steps = 10", "steps = 10\nwibble = 3", &["wibble"]),
        (
            "center = [0, 0, 0.05]",
            "center = [0, 0, 0.05]\nvertices = [[0, 0, 0]]",
            &["body[1].vertices", "not allowed"],
        ),
        // Friction pairs: groups must exist, pairs are pairs, one coefficient per pair.
        (
            "default = 0.8",
            "default = 0.8\npairs = [{ groups = [\"default\", \"grian\"], mu = 0.5 }]",
            &[
                "friction.pairs[0].groups",
                "\"grian\"",
                "no [[body]] or [[grains]] has",
                "(groups: \"default\")",
            ],
        ),
        (
            "default = 0.8",
            "default = 0.8\npairs = [{ groups = [\"default\", \"default\", \"default\"], mu = 0.5 }]",
            &["friction.pairs[0].groups has 3 entries", "exactly two"],
        ),
        (
            "default = 0.8",
            "default = 0.8\npairs = [{ groups = [\"default\", \"default\"], mu = 0.5 }, \
             { groups = [\"default\", \"default\"], mu = 0.5 }, \
             { groups = [\"default\", \"default\"], mu = 0.7 }]",
            &["friction.pairs[2]", "mu = 0.7", "friction.pairs[0]", "mu = 0.5"],
        ),
        // [body] for [[body]]: say so.
        (
            "[[body]]\nshape = \"box\"",
            "[body]\nshape = \"box\"",
            &["[body] is a single table: use [[body]]"],
        ),
        (
            "steps = 10",
            "steps = 10\nmax_speed = -1",
            &["simulation.max_speed = -1", "> 0"],
        ),
    ];
    for (from, to, needles) in cases {
        assert!(BASE.contains(from), "bad test case {from}");
        let msg = error_of(&BASE.replacen(from, to, 1));
        // Scenario words, not Rust's debug text.
        for rust in ["DVec3", "Dynamic", "Kinematic", "Fixed", "Plane", "Box"] {
            assert!(!msg.contains(rust), "`{rust}` in: {msg}");
        }
        for n in *needles {
            assert!(
                msg.contains(n),
                "error for `{to}` should mention `{n}`: {msg}"
            );
        }
    }
}

#[test]
fn degenerate_polyhedron_is_a_clear_error() {
    let text = BASE.replace(
        "shape = \"box\"\nmaterial = \"stone\"\nhalf_extents = [0.05, 0.05, 0.05]\ncenter = [0, 0, 0.05]",
        "shape = \"polyhedron\"\nmaterial = \"stone\"\nvertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]",
    );
    let msg = error_of(&text);
    assert!(
        msg.contains("body[1].vertices") && msg.contains("degenerate"),
        "{msg}"
    );
}

#[test]
fn driver_terms_and_validation() {
    let d = Driver {
        vx: vec![
            Term::Constant { value: 1.0 },
            Term::Ramp {
                start: 1.0,
                end: 2.0,
                from: 0.0,
                to: 2.0,
            },
            Term::Sine {
                amplitude: 0.5,
                frequency: 1.0,
                phase: 0.0,
                start: 0.0,
                end: f64::INFINITY,
            },
        ],
        vz: vec![Term::Table {
            times: vec![0.0, 1.0, 3.0],
            values: vec![0.0, 1.0, -1.0],
        }],
        ..Default::default()
    };
    let (v, w) = d.velocity(1.5);
    // 1 + 1 (ramp midway) + 0.5 sin(3π) = 2; table at 1.5: 1 + (−2)(0.5/2) = 0.5.
    assert!((v.x - 2.0).abs() < 1e-12 && (v.z - 0.5).abs() < 1e-12 && w.length() == 0.0);
    assert!(d.validate().is_ok());
    let bad = Driver {
        wy: vec![Term::Ramp {
            start: 1.0,
            end: 1.0,
            from: 0.0,
            to: 1.0,
        }],
        ..Default::default()
    };
    let msg = bad.validate().unwrap_err().to_string();
    assert!(msg.contains("wy[0]") && msg.contains("end"), "{msg}");
}

/// `Scenario::to_toml` reads back equal, for every example and with a `[ddm]` table added
/// (what `ballast run --subdomains` writes to the run folder).
#[test]
fn scenarios_round_trip_through_toml() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        // Folders (examples/python) and other files are not engine scenarios.
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        if text.contains("[track]") {
            continue;
        }
        let mut s = Scenario::from_toml(&text).unwrap();
        for ddm in [None, Some([2, 2, 1])] {
            if let Some(d) = ddm {
                s.ddm = Some(ballast_engine::solver::DdmSettings {
                    subdomains: d,
                    ..Default::default()
                });
            }
            let back = Scenario::from_toml(&s.to_toml().unwrap()).unwrap();
            assert_eq!(back, s, "{}", path.display());
        }
        n += 1;
    }
    assert!(n >= 2, "{n} examples");
}

/// A grain count beyond the machine's memory is refused before anything is allocated, with
/// the estimate; within it, the scenario builds.
#[test]
fn grain_counts_are_checked_against_memory() {
    let text = std::fs::read_to_string(format!(
        "{}/../../examples/pile.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let s = Scenario::from_toml(&text.replace("count = 300", "count = 1000000000000")).unwrap();
    // 1e12 grains of at most 20 vertices: 9 kB each, 9 PB.
    assert_eq!(s.memory_estimate() / 1_000_000_000_000, 9_000);
    let e = s
        .check_memory(Some(16_000_000_000))
        .unwrap_err()
        .to_string();
    for part in [
        "grains[0].count = 1000000000000",
        "about 9.0 PB",
        "16.0 GB available",
    ] {
        assert!(e.contains(part), "{part}: {e}");
    }
    let s = Scenario::from_toml(&text).unwrap();
    assert!(s.memory_estimate() < 3_000_000, "{}", s.memory_estimate());
    s.check_memory(Some(16_000_000_000)).unwrap();
    if ballast_engine::scenario::available_memory().is_some() {
        let big = Scenario::from_toml(&text.replace("count = 300", "count = 1000000000000"));
        let e = big.unwrap().build().unwrap_err().to_string();
        assert!(e.contains("grains[0].count"), "{e}");
    }
}
