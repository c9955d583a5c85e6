//! Checkpoints written in parts by the ranks of a shared world (see the
//! [module documentation](super#parts-written-by-the-ranks)): each rank writes the records it
//! owns, rank 0 the manifest once every part is written; reading puts the whole state back
//! together, whatever the number of ranks that reads it.

use super::{
    decode_contacts, encode_anchors, encode_bodies, encode_contacts, unframe_with, CheckpointError,
    Corruption, Dec, DecResult, Enc, State, HEADER_LEN,
};
use crate::contacts::ContactSet;
use crate::math::{DQuat, DVec3};
use crate::output::shared::{gather, Owners};
use crate::output::RunStats;
use crate::world::World;
use std::path::{Path, PathBuf};

/// The magic bytes a part starts with (a part is never taken for a checkpoint).
const PART_MAGIC: &[u8; 11] = b"BALLASTPART";

/// What a manifest says of its parts.
#[derive(Clone, Debug)]
pub(super) struct PartsSpec {
    /// Bodies and contacts of the whole state.
    pub bodies: usize,
    pub contacts: usize,
    /// Whether the parts carry the detection's anchor poses.
    pub anchors: bool,
    /// Each part's checksum, rank by rank.
    pub sums: Vec<u64>,
}

/// Rank `rank`'s part of the checkpoint whose manifest is `manifest`
/// (`checkpoint_<step>.bin` → `checkpoint_<step>.part<rank>.bin`).
pub fn part_path(manifest: &Path, rank: usize) -> PathBuf {
    let stem = manifest
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("checkpoint");
    manifest.with_file_name(format!("{stem}.part{rank}.bin"))
}

/// The step of a part's file name (`checkpoint_<step>.part<rank>.bin`), if it is one.
pub(super) fn step_of_part(name: &str) -> Option<u64> {
    let rest = name.strip_prefix("checkpoint_")?.strip_suffix(".bin")?;
    let (digits, rank) = rest.split_once(".part")?;
    let numeric = |s: &str| !s.is_empty() && s.bytes().all(|c| c.is_ascii_digit());
    (numeric(digits) && numeric(rank))
        .then(|| digits.parse().ok())
        .flatten()
}

/// Whether the world has an anchor pose per body (what a checkpoint stores of them).
pub(super) fn has_anchors(world: &World) -> bool {
    let a = world.detector.anchors();
    let n = world.bodies.len();
    a.position.len() == n && a.orientation.len() == n
}

/// Writes the checkpoint of `world` (and the run statistics `stats`) at `path`: alone, as
/// [`super::write_checkpoint_with_stats`]; shared between ranks ([`World::ranks`] > 1), each
/// rank writes its part (`checkpoint_<step>.part<R>.bin`, atomically) and, once every rank
/// has, rank 0 writes the manifest at `path` naming the parts' checksums. A collective: every
/// rank calls it for the same step. A rank that cannot write its part fails the checkpoint on
/// every rank, naming it, and no manifest is written (the previous checkpoint stays the
/// newest).
///
/// # Errors
///
/// This rank's write error (naming its file), or which ranks could not write their parts.
pub fn write_checkpoint_on_ranks(
    world: &World,
    stats: Option<&RunStats>,
    path: &Path,
) -> std::io::Result<()> {
    let ranks = world.ranks();
    if ranks == 1 {
        return super::write_checkpoint_with_stats(world, stats, path);
    }
    let rank = world.rank();
    let owners = Owners::of(world, ranks);
    let places = world.contact_places();
    let part_file = part_path(path, rank);
    let written = super::write_framed(&part_file, PART_MAGIC, |p| {
        encode_part(p, world, &owners, &places, rank)
    })
    .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", part_file.display())));
    let sum = *written.as_ref().unwrap_or(&0);
    let mine = [
        f64::from(u8::from(written.is_ok())),
        (sum >> 32) as f64,
        (sum & 0xffff_ffff) as f64,
    ];
    let all = gather(world, &mine);
    written?;
    let failed: Vec<usize> = (0..ranks).filter(|&r| all[3 * r] != 1.0).collect();
    if !failed.is_empty() {
        return Err(std::io::Error::other(format!(
            "checkpoint at step {}: rank(s) {failed:?} could not write their parts",
            world.step_index
        )));
    }
    if rank == 0 {
        let sums: Vec<u64> = (0..ranks)
            .map(|r| ((all[3 * r + 1] as u64) << 32) | all[3 * r + 2] as u64)
            .collect();
        super::write_manifest(world, stats, &sums, path)?;
    }
    Ok(())
}

/// The checksum a framed file ends with.
fn trailing_checksum(bytes: &[u8]) -> u64 {
    let mut s = [0u8; 8];
    s.copy_from_slice(&bytes[bytes.len() - 8..]);
    u64::from_le_bytes(s)
}

/// Rank `rank`'s part of the checkpoint of `world`: the bodies `owners` gives it and the
/// contacts it holds (contact `k` the `places[k]`-th of the step's, see
/// [`World::contact_places`]).
fn encode_part(p: &mut Enc, world: &World, owners: &Owners, places: &[u32], rank: usize) {
    let (b, c) = (&world.bodies, &world.contacts);
    let bodies: Vec<usize> = (0..b.len()).filter(|&i| owners.body[i] == rank).collect();
    let contacts: Vec<usize> = (0..c.len()).filter(|&k| world.holds_contact(k)).collect();
    p.u64(super::scene_fingerprint(world));
    p.u64(world.step_index);
    p.u32(rank as u32);
    p.u32(world.ranks() as u32);
    p.len(b.len());
    p.len(world.contact_total());

    p.len(bodies.len());
    bodies.iter().for_each(|&i| p.u32(i as u32));
    encode_bodies(p, world, bodies.iter().copied());
    encode_anchors(p, world, bodies.iter().copied());
    p.len(contacts.len());
    contacts.iter().for_each(|&k| p.u32(places[k]));
    encode_contacts(p, c, contacts.iter().copied());
}

/// Reads the parts `spec` names next to the manifest `manifest` (of scene fingerprint
/// `fingerprint`) into `state`: every body and contact from exactly one part.
pub(super) fn fill(
    manifest: &Path,
    fingerprint: u64,
    spec: &PartsSpec,
    state: &mut State,
) -> Result<(), CheckpointError> {
    let (n, m) = (spec.bodies, spec.contacts);
    let mut whole = Whole::new(n, m, spec.anchors);
    for (rank, &sum) in spec.sums.iter().enumerate() {
        let path = part_path(manifest, rank);
        let damaged = |why: String| CheckpointError::Corrupted {
            path: manifest.to_path_buf(),
            reason: Corruption::Malformed(format!("part {}: {why}", path.display())),
        };
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(damaged("missing".into()))
            }
            Err(source) => return Err(CheckpointError::Io { path, source }),
        };
        let (payload, _) = unframe_with(&bytes, &path, PART_MAGIC)?;
        if trailing_checksum(&bytes) != sum {
            return Err(damaged("not the part the manifest names (checksum)".into()));
        }
        let mut d = Dec {
            bytes: payload,
            pos: 0,
            base: HEADER_LEN,
        };
        whole
            .read_part(&mut d, fingerprint, state.step_index, rank, spec)
            .map_err(damaged)?;
        if d.pos != payload.len() {
            return Err(damaged(format!("{} unread bytes", payload.len() - d.pos)));
        }
    }
    whole
        .into_state(state)
        .map_err(|why| CheckpointError::Corrupted {
            path: manifest.to_path_buf(),
            reason: Corruption::Malformed(why),
        })
}

/// The whole state being put back together from its parts.
struct Whole {
    position: Vec<DVec3>,
    orientation: Vec<DQuat>,
    velocity: Vec<DVec3>,
    angular_velocity: Vec<DVec3>,
    angular_momentum: Vec<DVec3>,
    anchors: Option<(Vec<DVec3>, Vec<DQuat>)>,
    contacts: ContactSet,
    /// Which bodies and contacts a part gave already.
    body_seen: Vec<bool>,
    contact_seen: Vec<bool>,
}

impl Whole {
    fn new(n: usize, m: usize, anchors: bool) -> Self {
        let c = ContactSet {
            body1: vec![0; m],
            body2: vec![0; m],
            point: vec![DVec3::ZERO; m],
            frame: vec![[DVec3::ZERO; 3]; m],
            gap: vec![0.0; m],
            mu: vec![0.0; m],
            impulse: vec![DVec3::ZERO; m],
            status: vec![crate::laws::ContactStatus::NoContact; m],
            local_point: vec![DVec3::ZERO; m],
        };
        Whole {
            position: vec![DVec3::ZERO; n],
            orientation: vec![DQuat::IDENTITY; n],
            velocity: vec![DVec3::ZERO; n],
            angular_velocity: vec![DVec3::ZERO; n],
            angular_momentum: vec![DVec3::ZERO; n],
            anchors: anchors.then(|| (vec![DVec3::ZERO; n], vec![DQuat::IDENTITY; n])),
            contacts: c,
            body_seen: vec![false; n],
            contact_seen: vec![false; m],
        }
    }

    /// One part's records, checked against the manifest.
    fn read_part(
        &mut self,
        d: &mut Dec,
        fingerprint: u64,
        step: u64,
        rank: usize,
        spec: &PartsSpec,
    ) -> DecResult<()> {
        let (n, m) = (spec.bodies, spec.contacts);
        if d.u64("scene fingerprint")? != fingerprint {
            return Err("written for another scene than its manifest".into());
        }
        let at = d.u64("step")?;
        if at != step {
            return Err(format!("at step {at}, its manifest at step {step}"));
        }
        let (r, k) = (d.u32("rank")? as usize, d.u32("ranks")? as usize);
        if (r, k) != (rank, spec.sums.len()) {
            return Err(format!(
                "rank {r} of {k}, named as rank {rank} of {}",
                spec.sums.len()
            ));
        }
        let (pn, pm) = (d.u64("body count")?, d.u64("contact count")?);
        if (pn, pm) != (n as u64, m as u64) {
            return Err(format!(
                "{pn} bodies and {pm} contacts, the manifest {n} and {m}"
            ));
        }
        let nb = d.count(4 + 16 * 8, "part body")?;
        let bodies = d.vec(nb, |d| index(d, n, "body index"))?;
        let take = |seen: &mut Vec<bool>, idx: &[usize], what: &str| -> DecResult<()> {
            for &i in idx {
                if std::mem::replace(&mut seen[i], true) {
                    return Err(format!("{what} {i} in two parts"));
                }
            }
            Ok(())
        };
        take(&mut self.body_seen, &bodies, "body")?;
        for &i in &bodies {
            self.position[i] = d.vec3("position")?;
        }
        for &i in &bodies {
            self.orientation[i] = d.quat("orientation")?;
        }
        for a in [
            &mut self.velocity,
            &mut self.angular_velocity,
            &mut self.angular_momentum,
        ] {
            for &i in &bodies {
                a[i] = d.vec3("velocity")?;
            }
        }
        match (d.u8("anchors flag")?, &mut self.anchors) {
            (0, None) => {}
            (1, Some((position, orientation))) => {
                for &i in &bodies {
                    position[i] = d.vec3("anchor position")?;
                }
                for &i in &bodies {
                    orientation[i] = d.quat("anchor orientation")?;
                }
            }
            (f, _) => return Err(format!("anchors flag {f}, not the manifest's")),
        }
        let nc = d.count(4 + 4 + 4 + 24 + 72 + 8 + 8 + 24 + 1 + 24, "part contact")?;
        let contacts = d.vec(nc, |d| index(d, m, "contact index"))?;
        take(&mut self.contact_seen, &contacts, "contact")?;
        let mut rows = ContactSet::default();
        decode_contacts(d, nc, n, &mut rows)?;
        let c = &mut self.contacts;
        for (j, &k) in contacts.iter().enumerate() {
            c.body1[k] = rows.body1[j];
            c.body2[k] = rows.body2[j];
            c.point[k] = rows.point[j];
            c.frame[k] = rows.frame[j];
            c.gap[k] = rows.gap[j];
            c.mu[k] = rows.mu[j];
            c.impulse[k] = rows.impulse[j];
            c.status[k] = rows.status[j];
            c.local_point[k] = rows.local_point[j];
        }
        Ok(())
    }

    /// The state, once every body and contact came from a part.
    fn into_state(self, state: &mut State) -> DecResult<()> {
        if let Some(i) = self.body_seen.iter().position(|s| !s) {
            return Err(format!("body {i} is in no part"));
        }
        if let Some(k) = self.contact_seen.iter().position(|s| !s) {
            return Err(format!("contact {k} is in no part"));
        }
        state.position = self.position;
        state.orientation = self.orientation;
        state.velocity = self.velocity;
        state.angular_velocity = self.angular_velocity;
        state.angular_momentum = self.angular_momentum;
        state.anchors = self.anchors;
        state.contacts = self.contacts;
        Ok(())
    }
}

/// An index below `n`.
fn index(d: &mut Dec, n: usize, what: &str) -> DecResult<usize> {
    let i = d.u32(what)? as usize;
    if i >= n {
        return Err(format!("{what} {i} of {n}"));
    }
    Ok(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_round_trip() {
        let manifest = Path::new("/x/checkpoints/checkpoint_0000000300.bin");
        let p = part_path(manifest, 2);
        assert_eq!(
            p,
            Path::new("/x/checkpoints/checkpoint_0000000300.part2.bin")
        );
        let name = p.file_name().unwrap().to_str().unwrap();
        assert_eq!(step_of_part(name), Some(300));
        assert_eq!(
            super::super::step_of(name),
            None,
            "a part is not a checkpoint"
        );
        for not in [
            "checkpoint_0000000300.bin",
            "checkpoint_0000000300.part.bin",
            "checkpoint_0000000300.partx.bin",
            "checkpoint_.part1.bin",
            "checkpoint_0000000300.part1.bin.tmp",
        ] {
            assert_eq!(step_of_part(not), None, "{not}");
        }
    }
}
