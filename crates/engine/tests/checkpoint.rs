//! Checkpoints: bit-identical resume (warm start included), exact round trip, clear errors on
//! damaged or foreign files, fallback past interrupted writes, pruning.

use ballast_engine::bodies::BodySet;
use ballast_engine::contacts::ContactSet;
use ballast_engine::digest::state_digest;
use ballast_engine::laws::{ContactStatus, FrictionTable};
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::output::checkpoint::{
    checkpoint_path, encode_checkpoint, fnv1a64, list_checkpoints, newest_valid_checkpoint,
    prune_checkpoints, read_checkpoint, read_checkpoint_with_stats, remove_partial_checkpoints,
    write_checkpoint, write_checkpoint_with_stats, CheckpointError, Corruption, Snapshot,
    FORMAT_VERSION,
};
use ballast_engine::output::RunStats;
use ballast_engine::scenario::presets::pile;
use ballast_engine::scenario::Scenario;
use ballast_engine::world::{StepSettings, World};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const DIAMETER: [f64; 2] = [0.025, 0.05];
const GRAINS: usize = 60;
const SEED: u64 = 5;
/// Grains land around step 300; by 700 there are persisting contacts carrying impulses.
const SPLIT: u64 = 700;
const TOTAL: u64 = 1000;

fn scenario() -> Scenario {
    pile(GRAINS, DIAMETER, SEED, TOTAL)
}

fn build(s: &Scenario) -> World {
    s.build().expect("preset builds")
}

/// Steps `world`, accumulating the run statistics as `ballast run` does.
fn run(world: &mut World, steps: u64, stats: &mut RunStats) {
    for _ in 0..steps {
        let r = world.step();
        stats.add(&r);
    }
}

/// A fresh, empty folder under cargo's per-target temporary folder.
fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("checkpoint_tests")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The reference run at step `SPLIT`: checkpoint bytes (with statistics) and digest.
struct AtSplit {
    bytes: Vec<u8>,
    digest: String,
}

fn at_split() -> &'static AtSplit {
    static CELL: OnceLock<AtSplit> = OnceLock::new();
    CELL.get_or_init(|| {
        let mut w = build(&scenario());
        let mut stats = RunStats::default();
        run(&mut w, SPLIT, &mut stats);
        AtSplit {
            bytes: encode_checkpoint(&w, Some(&stats)),
            digest: state_digest(&w.bodies),
        }
    })
}

fn write_bytes(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap();
}

fn bits3(v: DVec3) -> [u64; 3] {
    v.to_array().map(f64::to_bits)
}

fn bitsq(q: DQuat) -> [u64; 4] {
    q.to_array().map(f64::to_bits)
}

/// Every field of two contact sets, bit for bit.
fn assert_contacts_identical(a: &ContactSet, b: &ContactSet) {
    assert_eq!(a.len(), b.len(), "contact count");
    assert_eq!(a.body1, b.body1);
    assert_eq!(a.body2, b.body2);
    assert_eq!(a.status, b.status);
    for k in 0..a.len() {
        assert_eq!(bits3(a.point[k]), bits3(b.point[k]), "point {k}");
        for j in 0..3 {
            assert_eq!(bits3(a.frame[k][j]), bits3(b.frame[k][j]), "frame {k}");
        }
        assert_eq!(a.gap[k].to_bits(), b.gap[k].to_bits(), "gap {k}");
        assert_eq!(a.mu[k].to_bits(), b.mu[k].to_bits(), "mu {k}");
        assert_eq!(bits3(a.impulse[k]), bits3(b.impulse[k]), "impulse {k}");
        assert_eq!(
            bits3(a.local_point[k]),
            bits3(b.local_point[k]),
            "local point {k}"
        );
    }
}

/// (1) 700 steps, checkpoint, fresh world, 300 more steps = 1000 steps straight, bit for bit.
#[test]
fn resumed_run_is_bit_identical_to_an_uninterrupted_one() {
    let s = scenario();
    let mut straight = build(&s);
    let mut straight_stats = RunStats::default();
    run(&mut straight, TOTAL, &mut straight_stats);

    let dir = tmp("resume");
    let path = checkpoint_path(&dir, SPLIT);
    {
        let mut first = build(&s);
        let mut stats = RunStats::default();
        run(&mut first, SPLIT, &mut stats);
        // The warm start must be exercised: persisting contacts with impulses.
        let loaded = first.contacts.impulse.iter().filter(|r| r.x > 0.0).count();
        assert!(loaded > 5, "only {loaded} loaded contacts at the split");
        // So must the detection's reuse of manifolds (anchor poses saved, cache rebuilt).
        let (reused, pairs) = first.detection_reuse();
        assert!(
            reused > 0,
            "no manifold reused at the split ({pairs} pairs)"
        );
        write_checkpoint_with_stats(&first, Some(&stats), &path).unwrap();
    }

    let mut resumed = build(&s);
    let mut stats = read_checkpoint_with_stats(&path, &mut resumed)
        .unwrap()
        .expect("statistics were saved");
    assert_eq!(resumed.step_index, SPLIT);
    run(&mut resumed, TOTAL - SPLIT, &mut stats);

    assert_eq!(
        state_digest(&resumed.bodies),
        state_digest(&straight.bodies)
    );
    assert_eq!(resumed.step_index, straight.step_index);
    assert_eq!(resumed.time.to_bits(), straight.time.to_bits());
    assert_contacts_identical(&resumed.contacts, &straight.contacts);
    assert_eq!(format!("{stats:?}"), format!("{straight_stats:?}"));

    // Without the stored contacts the first resumed step starts NLGS cold and the run drifts:
    // the comparison above really checks the warm start.
    let mut cold = build(&s);
    read_checkpoint(&path, &mut cold).unwrap();
    cold.contacts = ContactSet::default();
    run(&mut cold, TOTAL - SPLIT, &mut RunStats::default());
    assert_ne!(state_digest(&cold.bodies), state_digest(&straight.bodies));
}

/// The `ballast run` pattern: periodic checkpoints plus one at the end, pruned; a second run
/// resumes from the folder's newest checkpoint and ends where one long run ends.
#[test]
fn run_folder_resume_matches_one_long_run() {
    let s = scenario();
    let dir = tmp("run_folder");
    let mut w = build(&s);
    let mut stats = RunStats::default();
    for _ in 0..SPLIT {
        stats.add(&w.step());
        if w.step_index.is_multiple_of(250) {
            write_checkpoint_with_stats(&w, Some(&stats), &checkpoint_path(&dir, w.step_index))
                .unwrap();
            prune_checkpoints(&dir, 2).unwrap();
        }
    }
    write_checkpoint_with_stats(&w, Some(&stats), &checkpoint_path(&dir, w.step_index)).unwrap();
    prune_checkpoints(&dir, 2).unwrap();
    let steps: Vec<u64> = list_checkpoints(&dir)
        .unwrap()
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    assert_eq!(steps, [500, SPLIT]);

    let mut resumed = build(&s);
    let scan = newest_valid_checkpoint(&dir, &mut resumed).unwrap();
    assert!(scan.skipped.is_empty());
    let r = scan.resumed.expect("a checkpoint");
    assert_eq!((r.step, r.path), (SPLIT, checkpoint_path(&dir, SPLIT)));
    let mut stats = r.stats.expect("statistics");
    run(&mut resumed, TOTAL - SPLIT, &mut stats);

    let mut straight = build(&s);
    let mut straight_stats = RunStats::default();
    run(&mut straight, TOTAL, &mut straight_stats);
    assert_eq!(
        state_digest(&resumed.bodies),
        state_digest(&straight.bodies)
    );
    assert_eq!(format!("{stats:?}"), format!("{straight_stats:?}"));
}

/// (5) Every stored field comes back bit for bit, and re-encoding gives the same bytes.
#[test]
fn round_trip_preserves_every_field() {
    let s = scenario();
    let mut original = build(&s);
    let mut stats = RunStats::default();
    run(&mut original, SPLIT, &mut stats);
    let statuses = [ContactStatus::NoContact, ContactStatus::Stick];
    for st in statuses {
        assert!(
            original.contacts.status.contains(&st),
            "no {st:?} contact to test with"
        );
    }

    let path = tmp("round_trip").join("c.bin");
    write_checkpoint_with_stats(&original, Some(&stats), &path).unwrap();
    // Streamed to its file, the checkpoint is the bytes encoded in memory.
    assert!(std::fs::read(&path).unwrap() == encode_checkpoint(&original, Some(&stats)));
    let mut loaded = build(&s);
    let back = read_checkpoint_with_stats(&path, &mut loaded)
        .unwrap()
        .unwrap();

    let (a, b) = (&original.bodies, &loaded.bodies);
    for i in 0..a.len() {
        assert_eq!(bits3(a.position[i]), bits3(b.position[i]), "position {i}");
        assert_eq!(bitsq(a.orientation[i]), bitsq(b.orientation[i]), "q {i}");
        assert_eq!(bits3(a.velocity[i]), bits3(b.velocity[i]), "v {i}");
        assert_eq!(
            bits3(a.angular_velocity[i]),
            bits3(b.angular_velocity[i]),
            "w {i}"
        );
        assert_eq!(
            bits3(a.angular_momentum[i]),
            bits3(b.angular_momentum[i]),
            "L {i}"
        );
    }
    assert_eq!(state_digest(a), state_digest(b));
    assert_contacts_identical(&original.contacts, &loaded.contacts);
    assert_eq!(original.time.to_bits(), loaded.time.to_bits());
    assert_eq!(original.step_index, loaded.step_index);
    assert_eq!(original.timers, loaded.timers);
    assert!(loaded.timers.total > 0.0);
    assert_eq!(format!("{back:?}"), format!("{stats:?}"));
    // Whatever is stored, the loaded world writes it back identically.
    assert_eq!(
        encode_checkpoint(&loaded, Some(&back)),
        std::fs::read(&path).unwrap()
    );
    // No temporary file is left behind by the atomic write.
    let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["c.bin"]);
}

/// Reads `bytes` (written to `name`) into a fresh world; checks the world is untouched on error.
fn read_damaged(dir: &Path, name: &str, bytes: &[u8]) -> CheckpointError {
    let path = dir.join(name);
    write_bytes(&path, bytes);
    let mut w = build(&scenario());
    let before = state_digest(&w.bodies);
    let e = read_checkpoint(&path, &mut w).expect_err(name);
    assert_eq!(state_digest(&w.bodies), before, "{name}: world changed");
    assert_eq!((w.step_index, w.contacts.len()), (0, 0), "{name}");
    let msg = e.to_string();
    assert!(msg.contains(name), "{name}: message lacks the path: {msg}");
    e
}

/// Re-seals `bytes` with a correct checksum after an edit.
fn reseal(bytes: &mut [u8]) {
    let end = bytes.len() - 8;
    let sum = fnv1a64(&bytes[..end]);
    bytes[end..].copy_from_slice(&sum.to_le_bytes());
}

/// (2) Truncated, altered, foreign and future files: the right variant and a useful message.
#[test]
fn damaged_files_give_clear_errors() {
    let good = &at_split().bytes;
    let dir = tmp("damaged");
    let n = good.len();

    for cut in [0, 5, 11, 20, 23, 31, n / 2, n - 1] {
        let name = format!("cut_{cut}.bin");
        let e = read_damaged(&dir, &name, &good[..cut]);
        match &e {
            CheckpointError::Corrupted {
                reason: Corruption::Truncated { len, needed },
                ..
            } => assert!(*len == cut as u64 && needed > len, "{e}"),
            _ => panic!("{name}: {e:?}"),
        }
        let msg = e.to_string();
        assert!(
            msg.contains("truncated") && msg.contains("older checkpoint"),
            "{msg}"
        );
    }

    // One altered byte in the payload, in the checksum, in the version field.
    for at in [n / 2, n - 1, 12] {
        let mut b = good.clone();
        b[at] ^= 0x10;
        let e = read_damaged(&dir, &format!("flip_{at}.bin"), &b);
        assert!(
            matches!(
                e,
                CheckpointError::Corrupted {
                    reason: Corruption::ChecksumMismatch { .. },
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("checksum mismatch"), "{e}");
    }
    // An altered length field cannot be mistaken for a valid file.
    let mut b = good.clone();
    b[15] ^= 0x01;
    let e = read_damaged(&dir, "flip_length.bin", &b);
    assert!(matches!(e, CheckpointError::Corrupted { .. }), "{e:?}");
    assert!(e.to_string().contains("bytes"), "{e}");
    let mut b = good.clone();
    b.push(0);
    let e = read_damaged(&dir, "too_long.bin", &b);
    assert!(e.to_string().contains("header declares"), "{e}");

    // Wrong magic: an altered first byte, or another kind of file.
    let mut b = good.clone();
    b[0] = b'b';
    let e = read_damaged(&dir, "magic.bin", &b);
    assert!(matches!(e, CheckpointError::BadMagic { .. }), "{e:?}");
    assert!(e.to_string().contains("not a ballast checkpoint"), "{e}");
    let e = read_damaged(&dir, "summary.bin", br#"{"steps": 100}"#);
    assert!(matches!(e, CheckpointError::BadMagic { .. }), "{e:?}");

    // A newer release's file, intact: an unsupported version, not corruption.
    let mut b = good.clone();
    b[11..15].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    reseal(&mut b);
    let e = read_damaged(&dir, "future.bin", &b);
    match &e {
        CheckpointError::UnsupportedVersion {
            found, supported, ..
        } => assert_eq!((*found, *supported), (FORMAT_VERSION + 1, FORMAT_VERSION)),
        _ => panic!("{e:?}"),
    }
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("version {}", FORMAT_VERSION + 1))
            && msg.contains(&format!("reads version {FORMAT_VERSION}")),
        "{msg}"
    );

    // Intact frame around contents that do not decode (a writer bug): malformed, not a panic.
    let malformed = |name: &str, b: &mut Vec<u8>| {
        reseal(b);
        let e = read_damaged(&dir, name, b);
        match &e {
            CheckpointError::Corrupted {
                reason: Corruption::Malformed(_),
                ..
            } => e.to_string(),
            _ => panic!("{name}: {e:?}"),
        }
    };
    let mut b = good.clone();
    b[FINGERPRINT_AT..FINGERPRINT_AT + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    let msg = malformed("fingerprint.bin", &mut b);
    assert!(msg.contains("scene fingerprint"), "{msg}");
    let mut b = good.clone();
    b.insert(n - 8, 0);
    let len = u64::from_le_bytes(b[15..23].try_into().unwrap()) + 1;
    b[15..23].copy_from_slice(&len.to_le_bytes());
    let msg = malformed("extra.bin", &mut b);
    assert!(msg.contains("1 unread bytes"), "{msg}");

    let mut w = build(&scenario());
    let e = read_checkpoint(&dir.join("missing.bin"), &mut w).unwrap_err();
    assert!(matches!(e, CheckpointError::Io { .. }), "{e:?}");
}

/// Offset of the scene fingerprint, the first payload field (after magic, version, length).
const FINGERPRINT_AT: usize = 23;

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 200,
        rng_seed: proptest::test_runner::RngSeed::Fixed(7),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Any single altered byte or any truncation is reported as damage, never accepted and
    /// never a panic.
    #[test]
    fn any_damage_is_detected(at in any::<prop::sample::Index>(), mask in 1u8..=255, cut in any::<bool>()) {
        let good = &at_split().bytes;
        let mut b = good.clone();
        if cut {
            b.truncate(at.index(good.len()));
        } else {
            b[at.index(good.len())] ^= mask;
        }
        let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
            "checkpoint_fuzz_{}.bin",
            std::process::id()
        ));
        write_bytes(&path, &b);
        let mut w = build(&scenario());
        let r = read_checkpoint(&path, &mut w);
        let _ = std::fs::remove_file(&path);
        let e = r.expect_err("damaged file accepted");
        prop_assert!(e.is_damage(), "{:?}", e);
        prop_assert_eq!(w.step_index, 0);
    }
}

/// (3) A checkpoint of another scene is refused, naming the difference.
#[test]
fn other_scene_is_refused_naming_the_difference() {
    let dir = tmp("mismatch");
    let path = dir.join("c.bin");
    write_bytes(&path, &at_split().bytes);
    let mismatch = |s: Scenario| -> String {
        let mut w = build(&s);
        let before = state_digest(&w.bodies);
        let e = read_checkpoint(&path, &mut w).unwrap_err();
        assert_eq!(state_digest(&w.bodies), before);
        let msg = e.to_string();
        assert!(
            msg.contains("different scene") && msg.contains("scenario file"),
            "{msg}"
        );
        match e {
            CheckpointError::SceneMismatch { what, .. } => what,
            e => panic!("{e:?}"),
        }
    };

    let what = mismatch(pile(GRAINS, DIAMETER, SEED + 1, TOTAL));
    // Bodies 0–4 are the box; body 5 is the first grain.
    assert!(
        what.starts_with("body 5 (dynamic): shape differs"),
        "{what}"
    );
    assert!(what.contains("more bodies differ"), "{what}");

    let what = mismatch(pile(GRAINS - 10, DIAMETER, SEED, TOTAL));
    assert_eq!(
        what,
        format!(
            "number of bodies is {} in the checkpoint, {} in the scenario",
            GRAINS + 5,
            GRAINS - 5
        )
    );

    let mut s = scenario();
    s.simulation.dt = 1e-4;
    let what = mismatch(s);
    assert_eq!(
        what,
        "dt is 0.0002 in the checkpoint, 0.0001 in the scenario"
    );

    let mut s = scenario();
    s.solver.tolerance = 1e-6;
    let what = mismatch(s);
    assert!(what.starts_with("solver.tolerance is 0.0001"), "{what}");

    let mut s = scenario();
    s.friction.default = 0.7;
    let what = mismatch(s);
    assert!(
        what.contains("friction coefficient between groups") && what.contains("0.7"),
        "{what}"
    );

    let mut s = scenario();
    s.materials.insert("stone".into(), 2500.0);
    let what = mismatch(s);
    assert!(what.contains("inverse mass"), "{what}");

    // Steps to run are not part of the scene: `--steps` may change on resume.
    let mut w = build(&pile(GRAINS, DIAMETER, SEED, 5 * TOTAL));
    read_checkpoint(&path, &mut w).unwrap();
    assert_eq!(state_digest(&w.bodies), at_split().digest);
}

/// (4) A crash mid-write leaves a `.tmp` file or (on a bad disk) a damaged newer checkpoint:
/// resuming picks the newest valid one and says what it skipped.
#[test]
fn interrupted_write_falls_back_to_the_newest_valid_checkpoint() {
    let good = &at_split().bytes;
    let dir = tmp("interrupted");
    write_bytes(&checkpoint_path(&dir, 350), good); // contents at step 700: damaged name
    write_bytes(&checkpoint_path(&dir, SPLIT), good);
    // The temporary file `write_atomic` was writing when the process died.
    write_bytes(
        &checkpoint_path(&dir, 900).with_extension("tmp"),
        &good[..good.len() / 2],
    );
    let mut flipped = good.clone();
    flipped[good.len() / 3] ^= 1;
    write_bytes(&checkpoint_path(&dir, 800), &flipped);
    write_bytes(&checkpoint_path(&dir, 950), &good[..good.len() / 2]);
    write_bytes(&checkpoint_path(&dir, 1000), b"");
    write_bytes(&checkpoint_path(&dir, 720), good); // a copy under the wrong name

    let mut w = build(&scenario());
    let scan = newest_valid_checkpoint(&dir, &mut w).unwrap();
    let r = scan.resumed.expect("the step-700 checkpoint");
    assert_eq!((r.step, &r.path), (SPLIT, &checkpoint_path(&dir, SPLIT)));
    assert!(r.stats.is_some());
    assert_eq!(state_digest(&w.bodies), at_split().digest);
    assert_eq!(w.step_index, SPLIT);

    let skipped: Vec<(PathBuf, String)> = scan
        .skipped
        .iter()
        .map(|s| (s.path.clone(), s.error.to_string()))
        .collect();
    let expect = [
        (1000, "truncated"),
        (950, "truncated"),
        (800, "checksum mismatch"),
        (
            720,
            "the file name says step 720 but the contents are at step 700",
        ),
    ];
    assert_eq!(skipped.len(), expect.len(), "{skipped:#?}");
    for ((path, msg), (step, why)) in skipped.iter().zip(expect) {
        assert_eq!(path, &checkpoint_path(&dir, step));
        assert!(msg.contains(why), "{msg}");
    }
    assert!(scan.skipped.iter().all(|s| s.error.is_damage()));

    // Nothing valid: no resume, world untouched.
    let dir = tmp("all_damaged");
    write_bytes(&checkpoint_path(&dir, 100), &good[..100]);
    write_bytes(&checkpoint_path(&dir, 50).with_extension("tmp"), good);
    let mut w = build(&scenario());
    let scan = newest_valid_checkpoint(&dir, &mut w).unwrap();
    assert!(scan.resumed.is_none());
    assert_eq!(scan.skipped.len(), 1);
    assert_eq!(w.step_index, 0);

    // A newest checkpoint of another scene stops the search instead of resuming from older.
    let dir = tmp("foreign_newest");
    write_bytes(&checkpoint_path(&dir, SPLIT), good);
    let mut other = build(&pile(GRAINS, DIAMETER, SEED + 1, TOTAL));
    other.step_index = 900;
    write_checkpoint(&other, &checkpoint_path(&dir, 900)).unwrap();
    let mut w = build(&scenario());
    let e = newest_valid_checkpoint(&dir, &mut w).unwrap_err();
    assert!(matches!(e, CheckpointError::SceneMismatch { .. }), "{e:?}");
    assert_eq!(w.step_index, 0);

    let e = newest_valid_checkpoint(&dir.join("nope"), &mut w).unwrap_err();
    assert!(matches!(e, CheckpointError::Io { .. }), "{e:?}");
}

#[test]
fn prune_keeps_the_newest_checkpoints() {
    let dir = tmp("prune");
    let mut w = World::new(
        BodySet::default(),
        FrictionTable::new(0.5),
        StepSettings::default(),
    );
    for step in [100, 200, 300, 400, 12_345_678_901] {
        w.step_index = step;
        write_checkpoint(&w, &checkpoint_path(&dir, step)).unwrap();
    }
    write_bytes(&dir.join("checkpoint_0000000050.tmp"), b"partial");
    write_bytes(&dir.join("summary.json"), b"{}");
    assert_eq!(
        checkpoint_path(&dir, 7).file_name().unwrap(),
        "checkpoint_0000000007.bin"
    );

    let removed = prune_checkpoints(&dir, 2).unwrap();
    assert_eq!(
        removed,
        [100, 200, 300].map(|s| checkpoint_path(&dir, s)).to_vec()
    );
    let left: Vec<u64> = list_checkpoints(&dir)
        .unwrap()
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    assert_eq!(left, [400, 12_345_678_901]);
    prune_checkpoints(&dir, 0).unwrap();
    assert_eq!(list_checkpoints(&dir).unwrap().len(), 1, "the newest stays");
    assert!(dir.join("checkpoint_0000000050.tmp").exists());
    assert!(dir.join("summary.json").exists());
    // A resume deletes the cut writes, and only them.
    write_bytes(&dir.join("series.tmp"), b"x");
    let removed = remove_partial_checkpoints(&dir).unwrap();
    assert_eq!(removed, [dir.join("checkpoint_0000000050.tmp")]);
    assert!(dir.join("series.tmp").exists() && dir.join("summary.json").exists());
    assert_eq!(list_checkpoints(&dir).unwrap().len(), 1);
}

/// A snapshot taken between two steps puts the same world back exactly (statistics, warm
/// start, detection anchors and clock included): stepping on repeats what it did.
#[test]
fn a_snapshot_puts_the_world_back_exactly() {
    let mut w = build(&scenario());
    let mut stats = RunStats::default();
    run(&mut w, SPLIT, &mut stats);
    let snap = Snapshot::take(&w, Some(&stats));
    assert!(!snap.is_empty() && snap.len() < encode_checkpoint(&w, Some(&stats)).len());
    let mut later = stats.clone();
    run(&mut w, 20, &mut later);
    let (digest, contacts) = (state_digest(&w.bodies), w.contacts.clone());
    let back = snap.restore(&mut w).unwrap().unwrap();
    assert_eq!(w.step_index, SPLIT);
    assert_eq!(state_digest(&w.bodies), at_split().digest);
    assert_eq!(
        (back.steps, back.iterations_sum),
        (stats.steps, stats.iterations_sum)
    );
    run(&mut w, 20, &mut stats);
    assert_eq!(state_digest(&w.bodies), digest);
    assert_contacts_identical(&w.contacts, &contacts);
    assert_eq!(stats.iterations_sum, later.iterations_sum);
    // A world of other bodies is refused and left as it is.
    let mut other = build(&pile(GRAINS + 1, DIAMETER, SEED, TOTAL));
    assert!(snap.restore(&mut other).unwrap_err().contains("bodies"));
    assert_eq!(other.step_index, 0);
}

/// Top-level field names in a `{:#?}` rendering.
fn field_names(pretty: &str) -> Vec<String> {
    pretty
        .lines()
        .filter(|l| l.starts_with("    ") && !l.starts_with("     "))
        .filter_map(|l| l.trim().split_once(':').map(|(k, _)| k.to_string()))
        .collect()
}

/// Guards the "state only" design: every field of `World`, `BodySet` and `ContactSet` is
/// either stored in checkpoints, rebuilt from the scenario, or scratch rebuilt every step. A
/// new field fails here until it is classified (and stored, if it is state).
#[test]
fn checkpoints_cover_all_state_fields() {
    let w = World::new(
        BodySet::default(),
        FrictionTable::new(0.5),
        StepSettings::default(),
    );
    let classify = |debug: String, known: &[&str], what: &str| {
        for f in field_names(&debug) {
            assert!(
                known.contains(&f.as_str()),
                "{what}.{f} is new: store it in output/checkpoint.rs (and bump FORMAT_VERSION) \
                 if it carries state from one step to the next, else list it here"
            );
        }
    };
    classify(
        format!("{w:#?}"),
        &[
            // stored
            "bodies",
            "contacts",
            "time",
            "step_index",
            "timers",
            // the digest of the run's initial state
            "origin",
            // the work each drive has done so far, and how far it lags behind its program
            "drive_work",
            "drive_lag",
            // its anchor poses (the rest of it is rebuilt every step)
            "detector",
            // from the scenario
            "friction",
            "settings",
            "group_names",
            // rebuilt every step: the drives start from zero impulse each step (kept as the
            // last step's result), and the pipeline's buffers (`World::release_scratch`; a
            // step detected but not yet solved is held there too: front ends checkpoint
            // between steps, never inside one)
            "drives",
            "scratch",
            // how the process runs, not what it simulates: the ranks a distributed run
            // shares its solves with, set by the front end on every start and resume
            "exchange",
            // counted every step when the ranks hold their own contacts: the step's number
            // of contacts over all ranks (stored in the checkpoint's manifest; a resumed world
            // has every contact on every rank until its first step)
            "contact_total",
        ],
        "World",
    );
    classify(
        format!("{:#?}", BodySet::default()),
        &[
            "position",
            "orientation",
            "velocity",
            "angular_velocity",
            "angular_momentum",
            "kind",
            "shape",
            "group",
            "inv_mass",
            "inertia",
            "driver",
        ],
        "BodySet",
    );
    classify(
        format!("{:#?}", ContactSet::default()),
        &[
            "body1",
            "body2",
            "point",
            "frame",
            "gap",
            "mu",
            "impulse",
            "status",
            "local_point",
        ],
        "ContactSet",
    );
}

/// Version 1 to 5 files (written before the detection's anchor poses, the run's origin, the
/// drives' work, their lag, resp. the parts field were stored) still read: a version 1 run
/// resumes with every body anchored anew at its first step, versions 1 and 2 are not checked
/// against the initial state, and the drives start from no work done and no lag. The same
/// bytes labelled an older version with the newer sections left in are refused as malformed,
/// not misread.
#[test]
fn older_version_files_still_read() {
    let s = scenario();
    let mut w = build(&s);
    run(&mut w, SPLIT, &mut RunStats::default());
    let relabel = |mut b: Vec<u8>, version: u32| {
        b[11..15].copy_from_slice(&version.to_le_bytes());
        let payload = (b.len() - 23) as u64;
        b[15..23].copy_from_slice(&payload.to_le_bytes());
        b.extend_from_slice(&[0; 8]);
        reseal(&mut b);
        b
    };
    // Version 6 puts the parts count (u32 0: none) after the timers, whose last one (sorted by
    // name) is `total`.
    let v6 = encode_checkpoint(&w, None);
    let total = [&5u64.to_le_bytes()[..], b"total"].concat();
    let at = v6
        .windows(total.len())
        .position(|x| x == &total[..])
        .expect("the timers end with `total`")
        + total.len()
        + 8;
    assert_eq!(&v6[at..at + 4], &[0u8; 4], "no parts");
    let v5 = relabel([&v6[..at], &v6[at + 4..v6.len() - 8]].concat(), 5);
    // Payload tail: anchor flag 1, n positions (24 bytes), n orientations (32 bytes), origin
    // flag 1 and its u64, the drive count 0 (this scene has no drive), the lag count 0, then
    // the statistics flag 0; then the checksum.
    let anchors = 1 + 56 * w.bodies.len();
    let origin = 1 + 8;
    let lag = 8;
    let work = 8 + lag;
    let end = v5.len() - 8;
    assert_eq!(
        (
            v5[end - 1 - work - origin - anchors],
            v5[end - 1 - work - origin],
            &v5[end - 1 - work..end - 1],
            v5[end - 1]
        ),
        (1, 1, &[0u8; 16][..], 0)
    );
    let older = |cut: usize| {
        let mut b = v5[..end - 1 - cut].to_vec();
        b.push(0);
        b
    };
    let dir = tmp("version1");
    for (version, bytes) in [
        (1, older(work + origin + anchors)),
        (2, older(work + origin)),
        (3, older(work)),
        (4, older(lag)),
        (5, older(0)),
    ] {
        let path = dir.join(format!("v{version}.bin"));
        write_bytes(&path, &relabel(bytes, version));
        let mut resumed = build(&s);
        read_checkpoint(&path, &mut resumed).expect("an older version reads");
        assert_eq!(state_digest(&resumed.bodies), state_digest(&w.bodies));
        assert_eq!(resumed.step_index, w.step_index);
        // No origin in the file: unknown, not made up.
        if version < 3 {
            assert_eq!(resumed.origin_digest(), None);
        } else {
            assert_eq!(resumed.origin_digest(), w.origin_digest());
        }
        resumed.step();
        assert!(
            resumed.contacts.len() > 5,
            "{} contacts",
            resumed.contacts.len()
        );
    }

    for version in [1, 2, 3, 4] {
        let e = read_damaged(
            &dir,
            &format!("mislabelled{version}.bin"),
            &relabel(v5[..end].to_vec(), version),
        );
        assert!(
            matches!(e, CheckpointError::Corrupted { .. }),
            "a version 5 payload read as version {version}: {e:?}"
        );
    }
    let e = read_damaged(
        &dir,
        "mislabelled5.bin",
        &relabel(v6[..v6.len() - 8].to_vec(), 5),
    );
    assert!(
        matches!(e, CheckpointError::Corrupted { .. }),
        "a version 6 payload read as version 5: {e:?}"
    );
}

/// A checkpoint carries the state its run started from: the same scene started elsewhere (the
/// grains 1 mm higher, or one grain thrown) refuses it, naming the initial state; the run's
/// own scenario reads it, and the checkpoints it writes later carry the same origin.
#[test]
fn checkpoint_of_another_initial_state_is_refused() {
    let dir = tmp("origin");
    let path = dir.join("c.bin");
    write_bytes(&path, &at_split().bytes);
    let mut moved = scenario();
    moved.grains[0].pack.min[2] += 1e-3;
    let mut thrown = build(&scenario());
    thrown.bodies.velocity[7] = DVec3::new(0.1, 0.0, 0.0);
    for (what, mut w) in [("moved", build(&moved)), ("thrown", thrown)] {
        let before = state_digest(&w.bodies);
        let e = read_checkpoint(&path, &mut w).unwrap_err();
        assert_eq!(state_digest(&w.bodies), before, "{what}");
        let msg = e.to_string();
        assert!(
            matches!(e, CheckpointError::SceneMismatch { .. })
                && msg.contains("another initial state"),
            "{what}: {msg}"
        );
    }
    let mut w = build(&scenario());
    let origin = w.origin_digest();
    assert!(origin.is_some());
    read_checkpoint(&path, &mut w).expect("its own scenario reads it");
    assert_eq!(w.origin_digest(), origin);
    w.step();
    let again = dir.join("again.bin");
    write_checkpoint(&w, &again).unwrap();
    let mut fresh = build(&scenario());
    read_checkpoint(&again, &mut fresh).expect("a resumed run's checkpoint reads");
    assert_eq!(fresh.step_index, SPLIT + 1);
}
