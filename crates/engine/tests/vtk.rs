//! ParaView output: the `.vtu` files are read back by an independent reader (meshio, through
//! `tests/read_vtk.py`) and compared with the world; the `.pvd` collections list the frames
//! with increasing times, and `resume` truncates them.

use ballast_engine::bodies::{BodyKind, BodySet, Driver, Term};
use ballast_engine::laws::{ContactStatus, FrictionTable};
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::shapes::{ConvexPolyhedron, Shape};
use ballast_engine::world::{StepSettings, World};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A fresh, empty folder for one test.
fn test_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("vtk_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A floor (body 0), two dynamic boxes resting on it (1, 2), a kinematic box moving in the air
/// (3) and a fixed inclined wall away from everything (4).
fn scene() -> World {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    let mut a = ConvexPolyhedron::cuboid(DVec3::splat(0.05)).unwrap();
    a.position = DVec3::new(0.0, 0.0, 0.0501);
    bodies.add_polyhedron(a, 2700.0, BodyKind::Dynamic, 1);
    let mut b = ConvexPolyhedron::cuboid(DVec3::new(0.06, 0.04, 0.03)).unwrap();
    b.position = DVec3::new(0.3, 0.0, 0.0301);
    b.orientation = DQuat::from_rotation_z(0.3) * b.orientation;
    let i = bodies.add_polyhedron(b, 2700.0, BodyKind::Dynamic, 2);
    bodies.velocity[i] = DVec3::new(0.2, 0.05, 0.0);
    bodies.set_angular_velocity(i, DVec3::new(0.0, 0.0, 0.7));
    let c = ConvexPolyhedron::cuboid(DVec3::new(0.1, 0.02, 0.02)).unwrap();
    let mut c = c;
    c.position = DVec3::new(0.0, 0.5, 0.4);
    let k = bodies.add_polyhedron(c, 2700.0, BodyKind::Kinematic, 3);
    bodies.driver[k] = Some(Box::new(Driver {
        vx: vec![Term::Constant { value: 0.25 }],
        wz: vec![Term::Constant { value: 1.5 }],
        ..Default::default()
    }));
    bodies.add_plane(DVec3::new(-2.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 0.2), 4);
    World::new(bodies, FrictionTable::new(0.5), StepSettings::default())
}

fn v3(v: DVec3) -> Value {
    json!([v.x, v.y, v.z])
}

/// What the surfaces file of the dynamic (`others == false`) or other bodies must hold,
/// computed here from the body set, independently of the writer.
fn expected_surfaces(world: &World, others: bool) -> Value {
    let b = &world.bodies;
    // Scene box: the polyhedra's bounding spheres.
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for i in 0..b.len() {
        if let Shape::Polyhedron(p) = &b.shape[i] {
            lo = lo.min(b.position[i] - DVec3::splat(p.radius));
            hi = hi.max(b.position[i] + DVec3::splat(p.radius));
        }
    }
    let centre = (lo + hi) * 0.5;
    let (mut num_points, mut cells) = (0, Vec::new());
    let (mut id, mut group, mut vel, mut ang, mut kind) = (vec![], vec![], vec![], vec![], vec![]);
    for i in 0..b.len() {
        if (b.kind[i] != BodyKind::Dynamic) != others {
            continue;
        }
        let (q, x) = (b.orientation[i], b.position[i]);
        let faces = match &b.shape[i] {
            Shape::Polyhedron(p) => {
                num_points += p.vertices.len();
                for f in 0..p.num_faces() {
                    let points: Vec<Value> = p
                        .face(f)
                        .iter()
                        .map(|&v| v3(x + q * p.vertices[v as usize]))
                        .collect();
                    cells.push(json!({ "loop": points }));
                }
                p.num_faces()
            }
            Shape::Plane { normal } => {
                num_points += 4;
                let n = q * *normal;
                cells.push(json!({ "square": {
                    "centre": v3(centre - n * n.dot(centre - x)),
                    "normal": v3(n),
                    "side": 1.5 * (hi - lo).length(),
                }}));
                1
            }
        };
        for _ in 0..faces {
            id.push(i as i64);
            group.push(b.group[i] as i64);
            vel.push(v3(b.velocity[i]));
            ang.push(v3(b.angular_velocity[i]));
            kind.push(match b.kind[i] {
                BodyKind::Dynamic => 0,
                BodyKind::Kinematic => 1,
                BodyKind::Fixed => 2,
            });
        }
    }
    let mut data = json!({ "id": id, "group": group, "velocity": vel, "angular_velocity": ang });
    if others {
        data["kind"] = json!(kind);
    }
    json!({ "num_points": num_points, "num_cells": cells.len(), "cells": cells, "cell_data": data })
}

/// What the contacts file must hold.
fn expected_contacts(world: &World) -> Value {
    let c = &world.contacts;
    let h = world.settings.dt;
    let k = 0..c.len();
    json!({
        "num_points": c.len(),
        "num_cells": c.len(),
        "points": k.clone().map(|k| v3(c.point[k])).collect::<Vec<_>>(),
        "point_data": {
            "normal": k.clone().map(|k| v3(c.frame[k][0])).collect::<Vec<_>>(),
            "normal_force": k.clone().map(|k| v3(c.frame[k][0] * c.impulse[k].x / h)).collect::<Vec<_>>(),
            // Whole force minus its normal part: independent of the (t, s) convention.
            "tangential_force": k.clone().map(|k| {
                let r = c.world_impulse(k);
                let n = c.frame[k][0];
                v3((r - n * r.dot(n)) / h)
            }).collect::<Vec<_>>(),
            "status": k.clone().map(|k| match c.status[k] {
                ContactStatus::NoContact => 0,
                ContactStatus::Stick => 1,
                ContactStatus::Slide => 2,
            }).collect::<Vec<_>>(),
            "body1": c.body1,
            "body2": c.body2,
            "gap": c.gap,
        }
    })
}

fn expected_frame(world: &World, number: usize) -> Value {
    json!({
        "time": world.time,
        "grains": { "file": format!("vtk/grains_{number:06}.vtu"), "expect": expected_surfaces(world, false) },
        "bodies": { "file": format!("vtk/bodies_{number:06}.vtu"), "expect": expected_surfaces(world, true) },
        "contacts": { "file": format!("vtk/contacts_{number:06}.vtu"), "expect": expected_contacts(world) },
    })
}

/// Writes three frames (the first one without contacts), then lets `read_vtk.py` read them
/// back with meshio and compare them with what the world held.
#[test]
fn frames_read_back_with_meshio() {
    let dir = test_dir("read_back");
    let mut world = scene();
    let mut writer = VtkWriter::new(&dir).unwrap();
    let mut frames = Vec::new();
    for number in 0..3 {
        if number > 0 {
            for _ in 0..25 {
                world.step();
            }
            assert!(
                !world.contacts.is_empty(),
                "the boxes should touch the floor"
            );
        }
        writer.write_frame(&world).unwrap();
        frames.push(expected_frame(&world, number));
    }
    assert!(
        world.contacts.status.contains(&ContactStatus::Slide),
        "the moving box should slide"
    );
    let expected = dir.join("expected.json");
    std::fs::write(
        &expected,
        serde_json::to_string_pretty(&json!({ "frames": frames })).unwrap(),
    )
    .unwrap();
    run_checker(&dir, &expected);
}

/// Runs `tests/read_vtk.py`; fails (never skips) without python3 or meshio.
fn run_checker(dir: &Path, expected: &Path) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_vtk.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(dir)
        .arg(expected)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run python3 ({e}): install Python 3 and then `pip install meshio`")
        });
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "read_vtk.py failed ({}):\n{text}",
        out.status
    );
}

/// `(timestep, file)` of every `DataSet` of a `.pvd`.
fn pvd(path: &Path) -> Vec<(f64, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    let attr = |tag: &str, name: &str| {
        let key = format!("{name}=\"");
        let start = tag.find(&key).unwrap() + key.len();
        tag[start..start + tag[start..].find('"').unwrap()].to_string()
    };
    text.split("<DataSet")
        .skip(1)
        .map(|tag| (attr(tag, "timestep").parse().unwrap(), attr(tag, "file")))
        .collect()
}

fn files(series: &str, numbers: &[usize]) -> Vec<String> {
    numbers
        .iter()
        .map(|n| format!("vtk/{series}_{n:06}.vtu"))
        .collect()
}

/// Checks every series' `.pvd` lists `times` with files `numbers`, and that those files exist.
fn assert_series(dir: &Path, times: &[f64], numbers: &[usize]) {
    for series in ["grains", "bodies", "contacts"] {
        let listed = pvd(&dir.join(format!("{series}.pvd")));
        let got_times: Vec<f64> = listed.iter().map(|f| f.0).collect();
        let got_files: Vec<String> = listed.iter().map(|f| f.1.clone()).collect();
        assert_eq!(got_times, times, "{series}.pvd times");
        assert_eq!(got_files, files(series, numbers), "{series}.pvd files");
        assert!(
            got_times.windows(2).all(|w| w[0] < w[1]),
            "{series}: times not increasing"
        );
        for f in &got_files {
            assert!(dir.join(f).is_file(), "{f} missing");
        }
    }
}

#[test]
fn pvd_lists_frames_and_resume_truncates() {
    let dir = test_dir("resume");
    let mut world = scene();
    let mut writer = VtkWriter::new(&dir).unwrap();
    let mut times = Vec::new();
    for _ in 0..4 {
        writer.write_frame(&world).unwrap();
        times.push(world.time);
        world.step();
        world.step();
    }
    assert_series(&dir, &times, &[0, 1, 2, 3]);
    // No temporary file left behind by the atomic rewrite.
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        assert!(!name.ends_with(".tmp"), "{name} left behind");
    }

    // A second frame at the same time replaces the first one.
    writer.write_frame(&world).unwrap();
    writer.write_frame(&world).unwrap();
    times.push(world.time);
    assert_series(&dir, &times, &[0, 1, 2, 3, 4]);

    // Resuming from the third frame's time drops the later two, files included.
    let mut writer = VtkWriter::resume(&dir, times[2]).unwrap();
    assert_series(&dir, &times[..3], &[0, 1, 2]);
    for series in ["grains", "bodies", "contacts"] {
        for n in [3, 4] {
            assert!(!dir.join(format!("vtk/{series}_{n:06}.vtu")).exists());
        }
    }
    // The resumed run goes on from its checkpoint (here a world at a later time).
    world.step();
    writer.write_frame(&world).unwrap();
    let resumed = [times[0], times[1], times[2], world.time];
    assert_series(&dir, &resumed, &[0, 1, 2, 3]);

    // A time between frames keeps the earlier ones; before every frame, none.
    let between = 0.5 * (times[0] + times[1]);
    VtkWriter::resume(&dir, between).unwrap();
    assert_series(&dir, &resumed[..1], &[0]);
    VtkWriter::resume(&dir, -1.0).unwrap();
    assert_series(&dir, &[], &[]);

    // A folder without collections resumes as empty.
    let fresh = test_dir("resume_fresh");
    let mut writer = VtkWriter::resume(&fresh, 1.0).unwrap();
    assert!(fresh.join("vtk").is_dir());
    writer.write_frame(&world).unwrap();
    assert_series(&fresh, &[world.time], &[0]);
}

/// Write speed on a 90,000-grain frame (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn write_speed_large_frame() {
    use ballast_engine::shapes::random::{random_grain, GrainParams};
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let shapes: Vec<_> = (0..200)
        .map(|_| random_grain(&mut rng, &GrainParams::default(), 0.04).unwrap())
        .collect();
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    let n = 90_000;
    let side = (n as f64).cbrt().ceil() as usize;
    for k in 0..n {
        let mut g = shapes[k % shapes.len()].clone();
        g.position = DVec3::new(
            (k % side) as f64,
            ((k / side) % side) as f64,
            (k / side / side) as f64,
        ) * 0.05;
        bodies.add_polyhedron(g, 2700.0, BodyKind::Dynamic, 1);
    }
    let world = World::new(bodies, FrictionTable::new(0.5), StepSettings::default());
    let dir = test_dir("speed");
    let mut writer = VtkWriter::new(&dir).unwrap();
    let start = std::time::Instant::now();
    writer.write_frame(&world).unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let bytes: u64 = std::fs::read_dir(dir.join("vtk"))
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    println!(
        "{n} grains: {:.0} ms, {:.1} MB, {:.0} MB/s, {:.2} ms per 1000 grains",
        seconds * 1e3,
        bytes as f64 / 1e6,
        bytes as f64 / 1e6 / seconds,
        seconds * 1e3 / (n as f64 / 1000.0)
    );
}
