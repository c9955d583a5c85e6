//! What the ranks of a shared world write ([`ballast_engine::solver::exchange`], K in-process
//! ranks): ParaView frames in pieces, each rank its grains and contacts, grains changing rank
//! as the pile settles; checkpoints in parts, each rank its bodies and contacts and rank 0 the
//! manifest, which one process or another number of ranks resumes bit for bit; a part missing,
//! damaged or not written.

mod common;

use ballast_engine::bodies::BodyKind;
use ballast_engine::digest::state_digest;
use ballast_engine::output::checkpoint::{
    checkpoint_path, encode_checkpoint, newest_valid_checkpoint, part_path, prune_checkpoints,
    read_checkpoint, remove_partial_checkpoints, write_checkpoint_on_ranks,
};
use ballast_engine::solver::{Exchange, ThreadRanks};
use ballast_engine::world::World;
use common::compliant_pile;
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ballast-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The pile of `common::compliant_pile`, decomposed 2x2x1.
fn make() -> World {
    compliant_pile([2, 2, 1], true, false)
}

/// Runs `f(rank, world)` on `k` in-process ranks, each with its own world from `make()`.
fn on_ranks<T: Send + 'static>(
    k: usize,
    f: impl Fn(usize, &mut World) -> T + Send + Sync + Clone + 'static,
) -> Vec<T> {
    let handles: Vec<_> = ThreadRanks::group(k)
        .into_iter()
        .map(|r| {
            let f = f.clone();
            std::thread::spawn(move || {
                let mut w = make();
                let rank = r.rank();
                let ex: Arc<dyn Exchange> = Arc::new(r);
                w.set_exchange(Some(ex));
                f(rank, &mut w)
            })
        })
        .collect();
    handles.into_iter().map(|h| h.join().unwrap()).collect()
}

fn steps(w: &mut World, to: u64) {
    while w.step_index < to {
        w.step();
    }
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
    let make = || compliant_pile([2, 2, 1], true, false);
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
        let d = dir.clone();
        let digests = on_ranks(k, move |rank, w| {
            let mut writer = VtkWriter::new_on(&d, rank, k).unwrap();
            writer.write_frame(w).unwrap();
            for s in 1..=steps {
                w.step();
                if s % every == 0 {
                    writer.write_frame(w).unwrap();
                }
            }
            w.state_digest()
        });
        for d in digests {
            assert_eq!(d, state_digest(&alone.bodies), "{k} ranks");
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
    let d = dir.clone();
    let errors = on_ranks(2, move |rank, w| {
        let mut writer = VtkWriter::new_on(&d, rank, 2).unwrap();
        writer.write_frame(w).unwrap_err().to_string()
    });
    assert!(errors[0].contains("rank(s) [1]"), "{}", errors[0]);
    assert!(errors[1].contains("grains_000000_1.vtu"), "{}", errors[1]);
    assert!(
        !dir.join("grains.pvd").exists(),
        "a failed frame reached the collection"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two ranks checkpoint the pile at step 1500 (settled: most contacts reuse their manifold, so
/// the anchors matter) in parts and run on to 1550: one process and three
/// ranks resume those parts to the same state, bit for bit, as the uninterrupted run (and as
/// one process from the start). Each part holds its rank's share only.
#[test]
fn checkpoint_in_parts_resumes_on_any_number_of_ranks() {
    let dir = scratch("parts");
    let manifest = checkpoint_path(&dir, 1500);
    let mut alone = make();
    steps(&mut alone, 1500);
    // One process's checkpoint at step 1500 (a rank holds its own contacts only).
    let whole = encode_checkpoint(&alone, None).len();
    let records = alone.bodies.len() + alone.contacts.len();
    steps(&mut alone, 1550);
    let expected = state_digest(&alone.bodies);
    let m = manifest.clone();
    let written = on_ranks(2, move |_, w| {
        steps(w, 1500);
        write_checkpoint_on_ranks(w, None, &m).unwrap();
        steps(w, 1550);
        w.state_digest()
    });
    for d in &written {
        assert_eq!(*d, expected, "2 ranks");
    }
    let size = |p: &Path| std::fs::metadata(p).unwrap().len() as usize;
    let parts: Vec<usize> = (0..2).map(|r| size(&part_path(&manifest, r))).collect();
    // The manifest and the parts hold the whole checkpoint once, plus each record's index and
    // each part's header; each part its share.
    let total = size(&manifest) + parts.iter().sum::<usize>();
    assert!(
        total >= whole && total <= whole + 4 * records + 2 * 128,
        "manifest {} + parts {parts:?} against {whole} whole",
        size(&manifest)
    );
    for &p in &parts {
        assert!(
            p < whole * 9 / 10,
            "a part holds its share: {parts:?} of {whole}"
        );
    }

    let mut one = make();
    read_checkpoint(&manifest, &mut one).unwrap();
    assert_eq!(one.step_index, 1500);
    steps(&mut one, 1550);
    assert_eq!(
        state_digest(&one.bodies),
        expected,
        "resumed by one process"
    );
    let m = manifest.clone();
    for d in on_ranks(3, move |_, w| {
        read_checkpoint(&m, w).unwrap();
        steps(w, 1550);
        w.state_digest()
    }) {
        assert_eq!(d, expected, "resumed by 3 ranks");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A checkpoint whose part is damaged or missing is passed over for the previous one; a part
/// without its manifest (a job stopped between the two) is deleted as a partial write;
/// pruning a checkpoint deletes its parts.
#[test]
fn a_damaged_or_missing_part_falls_back_to_the_previous_checkpoint() {
    let dir = scratch("parts-damage");
    let d = dir.clone();
    on_ranks(2, move |_, w| {
        for s in [100, 200, 300] {
            steps(w, s);
            write_checkpoint_on_ranks(w, None, &checkpoint_path(&d, s)).unwrap();
        }
    });
    // Step 300's manifest lost: its parts are partial writes.
    std::fs::remove_file(checkpoint_path(&dir, 300)).unwrap();
    let removed = remove_partial_checkpoints(&dir).unwrap();
    assert_eq!(removed.len(), 2, "{removed:?}");
    assert!(!part_path(&checkpoint_path(&dir, 300), 0).exists());
    // A byte of step 200's second part flipped.
    let p = part_path(&checkpoint_path(&dir, 200), 1);
    let mut bytes = std::fs::read(&p).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&p, bytes).unwrap();
    let mut w = make();
    let scan = newest_valid_checkpoint(&dir, &mut w).unwrap();
    assert_eq!(scan.resumed.unwrap().step, 100);
    assert_eq!(scan.skipped.len(), 1);
    let why = scan.skipped[0].error.to_string();
    assert!(why.contains("part1"), "{why}");
    // Step 200's first part gone instead.
    std::fs::remove_file(part_path(&checkpoint_path(&dir, 200), 0)).unwrap();
    let scan = newest_valid_checkpoint(&dir, &mut make()).unwrap();
    assert_eq!(scan.resumed.unwrap().step, 100);
    let why = scan.skipped[0].error.to_string();
    assert!(why.contains("part0") && why.contains("missing"), "{why}");
    // Keeping the newest checkpoint only: step 100's manifest and both its parts go.
    let removed = prune_checkpoints(&dir, 1).unwrap();
    assert_eq!(removed.len(), 3, "{removed:?}");
    assert!(!part_path(&checkpoint_path(&dir, 100), 1).exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A rank that cannot write its part (a folder stands where its file goes) fails the
/// checkpoint on every rank, naming it; no manifest is written.
#[test]
fn a_part_that_cannot_be_written_fails_the_checkpoint_on_every_rank() {
    let dir = scratch("parts-fail");
    let manifest = checkpoint_path(&dir, 20);
    std::fs::create_dir_all(part_path(&manifest, 1)).unwrap();
    let m = manifest.clone();
    let errors = on_ranks(2, move |_, w| {
        steps(w, 20);
        write_checkpoint_on_ranks(w, None, &m)
            .unwrap_err()
            .to_string()
    });
    assert!(errors[0].contains("rank(s) [1]"), "{}", errors[0]);
    assert!(errors[1].contains("part1"), "{}", errors[1]);
    assert!(!manifest.exists(), "a manifest without its parts");
    let _ = std::fs::remove_dir_all(&dir);
}

/// What an output computes over every body — the kinetic energy, the state digest — each rank
/// computes from the bodies it answers for, gathered in body order: with every other body's
/// state spoiled on each rank (NaN positions, huge velocities), every rank gives one process's
/// bits, and each body is answered for by exactly one rank.
#[test]
fn outputs_over_every_body_read_only_its_owners() {
    use ballast_engine::math::{DQuat, DVec3};
    let at = 200;
    let mut alone = make();
    steps(&mut alone, at);
    let energy = alone.kinetic_energy();
    assert_eq!(energy.to_bits(), alone.bodies.kinetic_energy().to_bits());
    assert_eq!(alone.state_digest(), state_digest(&alone.bodies));
    let expect = (energy.to_bits(), alone.state_digest());
    let n = alone.bodies.len();
    for k in [2, 3] {
        let got = on_ranks(k, move |_, w| {
            steps(w, at);
            let answered: Vec<usize> = (0..n).filter(|&i| w.answers_for(i)).collect();
            let b = &mut w.bodies;
            for i in (0..n).filter(|i| !answered.contains(i)) {
                b.position[i] = DVec3::NAN;
                b.orientation[i] = DQuat::from_xyzw(0.5, 0.5, 0.5, 0.5);
                b.velocity[i] = DVec3::splat(1e300);
                b.angular_velocity[i] = DVec3::splat(-1e300);
                b.angular_momentum[i] = DVec3::splat(1e300);
            }
            let spoiled = state_digest(&w.bodies);
            (
                (w.kinetic_energy().to_bits(), w.state_digest()),
                spoiled,
                answered,
            )
        });
        let mut owners = vec![0; n];
        for (r, (values, spoiled, answered)) in got.iter().enumerate() {
            assert_eq!(values, &expect, "rank {r} of {k}");
            assert_ne!(spoiled, &expect.1, "rank {r} of {k}: nothing spoiled");
            let dynamic = answered
                .iter()
                .filter(|&&i| alone.bodies.kind[i] == BodyKind::Dynamic)
                .count();
            assert!(dynamic > 0, "rank {r} of {k} answers for no grain");
            answered.iter().for_each(|&i| owners[i] += 1);
        }
        assert!(owners.iter().all(|&o| o == 1), "{k} ranks: {owners:?}");
    }
}
