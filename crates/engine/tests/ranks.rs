//! The domain decomposition shared between ranks ([`ballast_engine::solver::exchange`]): K
//! in-process ranks ([`ThreadRanks`]), each stepping its own copy of a scene, give on every
//! rank the bodies, impulses, sweep counts and residuals of one process with the same
//! partition, bit for bit — with compliant contacts and the overlap correction, with a
//! force-limited drive, with the interface solved in one group, for K = 2, 3, 4; and the
//! ParaView frames they write in pieces, grains changing rank as the pile settles.

mod common;

use ballast_engine::bodies::{BodyKind, Driver, Term};
use ballast_engine::digest::state_digest;
use ballast_engine::laws::{FrictionTable, NormalLaw};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{
    ConvergenceNorm, DdmSettings, Exchange, SolveReport, SolverSettings, ThreadRanks,
};
use ballast_engine::world::{StepSettings, World};
use std::sync::Arc;

/// A pile of 150 grains settling at μ = 1 with the default job's contact law (compliant,
/// overlap law, hyperbolic closure, recovery), decomposed into `subdomains`; with `paddle`, a
/// force-limited paddle stirs it (its drive row is solved after the interface).
fn pile(subdomains: [usize; 3], parallel_interface: bool, paddle: bool) -> World {
    let mut bodies = common::open_box(0.2);
    if paddle {
        let mut p = ConvexPolyhedron::cuboid(DVec3::new(0.005, 0.05, 0.03)).unwrap();
        p.position = DVec3::new(0.03, 0.1, 0.05);
        let i = bodies.add_polyhedron(p, 7850.0, BodyKind::Kinematic, 2);
        bodies.driver[i] = Some(Driver {
            vx: vec![Term::Constant { value: 0.5 }],
            vz: vec![Term::Sine {
                amplitude: 0.2,
                frequency: 20.0,
                phase: 0.0,
                start: 0.0,
                end: f64::INFINITY,
            }],
            max_force: [2.0, f64::INFINITY, 8.0],
            ..Default::default()
        });
    }
    let pack = GrainPack {
        count: 150,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.2, 0.2],
        diameter: [0.025, 0.045],
        vertices: [10, 16],
        elongation: 1.3,
        flatness: 1.1,
        seed: 5,
    };
    common::pour(&mut bodies, &pack, 2700.0, 1);
    let settings = StepSettings {
        dt: 4e-4,
        theta: 0.55,
        contact_stiffness: Some(1e7),
        tangential_stiffness: Some(5e6),
        overlap_recovery: 0.2,
        max_closure: Some(1e-4),
        normal_law: NormalLaw::Overlap,
        solver: SolverSettings {
            tolerance: 1e-3,
            max_iterations: 300,
            norm: ConvergenceNorm::NaturalMap,
            ..Default::default()
        },
        ddm: Some(DdmSettings {
            subdomains,
            parallel_interface,
            // Every phase dispatched to the workers, as on many cores.
            min_parallel_contacts: 0,
            ..Default::default()
        }),
        ..Default::default()
    };
    World::new(bodies, FrictionTable::new(1.0), settings)
}

/// What a run leaves: each step's solve, the bodies' digest, the impulses' bits, and the
/// seconds its ranks spent sharing.
#[derive(Debug, PartialEq)]
struct Trace {
    solves: Vec<SolveReport>,
    digest: String,
    impulses: Vec<[u64; 3]>,
}

fn trace(w: &mut World, steps: usize) -> (Trace, f64) {
    let solves = (0..steps).map(|_| w.step().solve).collect();
    let impulses = w
        .contacts
        .impulse
        .iter()
        .map(|r| [r.x.to_bits(), r.y.to_bits(), r.z.to_bits()])
        .collect();
    let t = Trace {
        solves,
        digest: state_digest(&w.bodies),
        impulses,
    };
    (t, w.timers.communication)
}

/// Runs `make()`'s scene on `k` in-process ranks; every rank's trace.
fn on_ranks(k: usize, steps: usize, make: fn() -> World) -> Vec<(Trace, f64)> {
    let handles: Vec<_> = ThreadRanks::group(k)
        .into_iter()
        .map(|r| {
            std::thread::spawn(move || {
                let mut w = make();
                let ex: Arc<dyn Exchange> = Arc::new(r);
                w.set_exchange(Some(ex));
                trace(&mut w, steps)
            })
        })
        .collect();
    handles.into_iter().map(|h| h.join().unwrap()).collect()
}

fn assert_same(label: &str, make: fn() -> World, steps: usize, ranks: &[usize]) {
    let (alone, comm) = trace(&mut make(), steps);
    assert_eq!(comm, 0.0, "{label}: one process shares nothing");
    let sweeps: usize = alone.solves.iter().map(|r| r.iterations).sum();
    assert!(
        sweeps > 3 * steps,
        "{label}: {sweeps} sweeps in {steps} steps: too few to test the sharing"
    );
    for &k in ranks {
        for (rank, (t, comm)) in on_ranks(k, steps, make).into_iter().enumerate() {
            assert!(comm > 0.0, "{label}, {k} ranks: rank {rank} shared nothing");
            for (s, (a, b)) in alone.solves.iter().zip(&t.solves).enumerate() {
                assert_eq!(
                    (a.iterations, a.residual.to_bits(), a.quad.to_bits()),
                    (b.iterations, b.residual.to_bits(), b.quad.to_bits()),
                    "{label}, {k} ranks, rank {rank}, step {s}"
                );
            }
            assert_eq!(alone, t, "{label}, {k} ranks, rank {rank}");
        }
    }
}

#[test]
fn compliant_pile_on_ranks_is_bit_identical() {
    assert_same(
        "compliant pile, 2x2x1",
        || pile([2, 2, 1], true, false),
        700,
        &[2, 3, 4],
    );
}

#[test]
fn more_ranks_than_a_row_of_subdomains() {
    assert_same(
        "compliant pile, 3x2x1",
        || pile([3, 2, 1], true, false),
        600,
        &[4],
    );
}

#[test]
fn force_limited_drive_on_ranks_is_bit_identical() {
    assert_same(
        "stirred pile, 2x2x1",
        || pile([2, 2, 1], true, true),
        600,
        &[2, 3],
    );
}

#[test]
fn one_interface_group_on_ranks_is_bit_identical() {
    assert_same(
        "compliant pile, 2x2x1, sequential interface",
        || pile([2, 2, 1], false, false),
        600,
        &[2],
    );
}

/// The cell data array `name` (Int32) of a `.vtu` written by the VTK writer: its appended,
/// zlib-compressed block (VTK's layout: block count, block size, last block's size, the
/// compressed sizes, then the blocks) inflated.
fn int32_array(path: &std::path::Path, name: &str) -> Vec<i32> {
    use std::io::Read;
    let bytes = std::fs::read(path).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let tag = format!("Name=\"{name}\"");
    let at = text
        .find(&tag)
        .unwrap_or_else(|| panic!("{path:?}: no {name}"));
    let offset: usize = text[at..]
        .split("offset=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    let start = bytes.windows(2).position(|w| w == b" _").unwrap() + 2 + offset;
    let word = |k: usize| {
        u64::from_le_bytes(bytes[start + 8 * k..start + 8 * k + 8].try_into().unwrap()) as usize
    };
    let blocks = word(0);
    let mut at = start + 8 * (3 + blocks);
    let mut raw = Vec::new();
    for b in 0..blocks {
        let size = word(3 + b);
        flate2::read::ZlibDecoder::new(&bytes[at..at + size])
            .read_to_end(&mut raw)
            .unwrap();
        at += size;
    }
    raw.chunks(4)
        .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// The Int32 array `name` of each piece a parallel file (`dir/vtk/….pvtu`) names.
fn pieces(dir: &std::path::Path, pvtu: &str, name: &str) -> Vec<Vec<i32>> {
    let text = std::fs::read_to_string(dir.join(pvtu)).unwrap();
    text.split("Source=\"")
        .skip(1)
        .map(|s| int32_array(&dir.join("vtk").join(s.split('"').next().unwrap()), name))
        .collect()
}

/// Frames written on K in-process ranks: each rank writes the grains and contacts it owns as
/// pieces, rank 0 the parallel files and the collections. Every frame's pieces hold the
/// grains and contacts of one process's frame, each once; grains move from one rank's pieces
/// to another's as the pile settles (the partition follows them), and the run stays
/// bit-identical while they do.
#[test]
fn frames_in_pieces_hold_one_process_frame() {
    use ballast_engine::output::vtk::VtkWriter;
    let root = std::env::temp_dir().join(format!("ballast-pieces-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let (steps, every) = (600, 100);
    let make = || pile([2, 2, 1], true, false);
    let alone_dir = root.join("alone");
    let mut alone = make();
    let mut writer = VtkWriter::new(&alone_dir).unwrap();
    writer.write_frame(&alone).unwrap();
    let mut contacts_alone = vec![alone.contacts.len()];
    for s in 1..=steps {
        alone.step();
        if s % every == 0 {
            writer.write_frame(&alone).unwrap();
            contacts_alone.push(alone.contacts.len());
        }
    }
    let grains = alone
        .bodies
        .kind
        .iter()
        .filter(|k| **k == BodyKind::Dynamic)
        .count();
    for k in [2, 3] {
        let dir = root.join(format!("ranks-{k}"));
        let handles: Vec<_> = ThreadRanks::group(k)
            .into_iter()
            .map(|r| {
                let dir = dir.clone();
                std::thread::spawn(move || {
                    let mut w = make();
                    let rank = r.rank();
                    w.set_exchange(Some(Arc::new(r)));
                    let mut writer = VtkWriter::new_on(&dir, rank, k).unwrap();
                    writer.write_frame(&w).unwrap();
                    for s in 1..=steps {
                        w.step();
                        if s % every == 0 {
                            writer.write_frame(&w).unwrap();
                        }
                    }
                    state_digest(&w.bodies)
                })
            })
            .collect();
        for h in handles {
            assert_eq!(h.join().unwrap(), state_digest(&alone.bodies), "{k} ranks");
        }
        let pvd = std::fs::read_to_string(dir.join("grains.pvd")).unwrap();
        let frames: Vec<&str> = pvd
            .split("file=\"")
            .skip(1)
            .map(|s| s.split('"').next().unwrap())
            .collect();
        assert_eq!(frames.len(), steps / every + 1, "{k} ranks: {pvd}");
        let mut owner_of = vec![Vec::new(); alone.bodies.len()];
        for (f, file) in frames.iter().enumerate() {
            assert!(file.ends_with(".pvtu"), "{file}");
            // A grain's faces are consecutive cells, each with its id.
            let mut ps = pieces(&dir, file, "id");
            ps.iter_mut().for_each(|ids| ids.dedup());
            assert_eq!(ps.len(), k, "{file}");
            let mut all: Vec<i32> = ps.concat();
            all.sort_unstable();
            let n = all.len();
            all.dedup();
            assert_eq!(
                (n, all.len()),
                (grains, grains),
                "{k} ranks, {file}: each grain once"
            );
            for (r, ids) in ps.iter().enumerate() {
                for &i in ids {
                    owner_of[i as usize].push(r);
                }
            }
            let contacts: usize = pieces(&dir, &file.replace("grains", "contacts"), "body1")
                .iter()
                .map(Vec::len)
                .sum();
            assert_eq!(contacts, contacts_alone[f], "{k} ranks, {file}: contacts");
        }
        let moved = owner_of
            .iter()
            .filter(|o| o.windows(2).any(|w| w[0] != w[1]))
            .count();
        assert!(
            moved > 0,
            "{k} ranks: no grain changed rank in {} frames",
            frames.len()
        );
        println!("{k} ranks: {moved} of {grains} grains changed rank between frames");
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// A rank that cannot write its piece (a folder stands where its file goes) fails the frame
/// on every rank, naming it; nothing reaches the collection, and no rank waits for ever.
#[test]
fn a_piece_that_cannot_be_written_fails_the_frame_on_every_rank() {
    use ballast_engine::output::vtk::VtkWriter;
    let dir = std::env::temp_dir().join(format!("ballast-piece-fail-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("vtk/grains_000000_1.vtu")).unwrap();
    let handles: Vec<_> = ThreadRanks::group(2)
        .into_iter()
        .map(|r| {
            let dir = dir.clone();
            std::thread::spawn(move || {
                let mut w = pile([2, 2, 1], true, false);
                let rank = r.rank();
                w.set_exchange(Some(Arc::new(r)));
                let mut writer = VtkWriter::new_on(&dir, rank, 2).unwrap();
                writer.write_frame(&w).map_err(|e| e.to_string())
            })
        })
        .collect();
    let errors: Vec<String> = handles
        .into_iter()
        .map(|h| h.join().unwrap().unwrap_err())
        .collect();
    assert!(errors[0].contains("rank(s) [1]"), "{}", errors[0]);
    assert!(errors[1].contains("grains_000000_1.vtu"), "{}", errors[1]);
    assert!(
        !dir.join("grains.pvd").exists(),
        "a failed frame reached the collection"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
