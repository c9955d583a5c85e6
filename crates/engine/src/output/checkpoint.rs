//! Checkpoints: the dynamic state of a run, saved so that it can be resumed bit-identically.
//!
//! The scene (shapes, masses, groups, drivers, friction, settings) is rebuilt from the scenario
//! file; a checkpoint holds only what changes while the simulation runs, plus a description of
//! the scene it was written for, so that resuming with another scenario is refused with a
//! message naming what differs instead of silently producing nonsense.
//!
//! # What is stored
//!
//! * per body: position, orientation, velocity, angular velocity and angular momentum;
//! * the whole [`World::contacts`] set (every field, statuses included): at the start of a
//!   step it holds the previous step's contacts, the source of the warm start, so without it
//!   the first resumed step would start NLGS from zero impulses and the run would diverge;
//! * time, step index and the cumulated phase timers;
//! * the detection's anchor poses (see [`crate::detection::coherence`]): the contact
//!   manifolds of the next steps are computed there, so without them a resumed run would
//!   detect at other poses than the uninterrupted one;
//! * optionally the [`RunStats`] of the run so far, so a resumed run's summary covers all steps;
//! * the scene description (see below).
//!
//! Every `f64` is stored as its exact IEEE-754 bits: a resumed run continues bit-identically.
//!
//! # File format, version 6 (versions 1 to 5 still read)
//!
//! All integers little-endian; `f64` as the little-endian bytes of [`f64::to_bits`]; a vector is
//! `x, y, z`; a quaternion is `x, y, z, w`. An "array" is a `u64` element count followed by the
//! elements. The frame (magic, version, payload length, payload, checksum) is the same for every
//! format version, so a file's integrity is checked before its version is interpreted: a
//! flipped version byte reads as corruption, a genuine file from a newer release as
//! [`CheckpointError::UnsupportedVersion`].
//!
//! | Bytes      | Field                                                                         |
//! |------------|-------------------------------------------------------------------------------|
//! | 11         | magic `BALLASTCKPT` (ASCII)                                                   |
//! | 4          | `u32` format version ([`FORMAT_VERSION`])                                     |
//! | 8          | `u64` payload length `P`                                                      |
//! | `P`        | payload, below                                                                |
//! | 8          | `u64` checksum: 64-bit FNV-1a ([`fnv1a64`]) of all the bytes before it        |
//!
//! Payload:
//!
//! | Field                | Layout                                                                  |
//! |----------------------|-------------------------------------------------------------------------|
//! | scene fingerprint    | `u64`, [`fnv1a64`] of the scene section's bytes ([`scene_fingerprint`]) |
//! | *scene section*      |                                                                         |
//! | settings             | `u64` length + UTF-8 JSON of [`World::settings`]                        |
//! | bodies               | array of records: kind `u8` (0 dynamic, 1 kinematic, 2 fixed), group `u32`, inverse mass `f64`, principal inertia 3 × `f64`, shape hash `u64`, driver hash `u64` (0 = none) |
//! | friction             | array of `(group a u32, group b u32, μ f64)`, `a ≤ b`, over the groups the bodies use |
//! | *clock*              | time `f64`, step index `u64`, timers: array of (`u64` name length, UTF-8 name of a [`PhaseTimes`] field, `f64` seconds) |
//! | *parts*              | `u32` `K` (version ≥ 6): 0, the bodies, contacts and anchors follow here; `K > 0`, they are in `K` part files (see [Parts](#parts-written-by-the-ranks)), and here follow instead `u64` body count, `u64` contact count, `u8` anchors flag and the `K` parts' `u64` checksums |
//! | *bodies*             | `u64` count `n`, then field by field (structure of arrays, `n` values each): positions, orientations, velocities, angular velocities, angular momenta |
//! | *contacts*           | `u64` count `m`, then field by field (`m` values each): body 1 `u32`, body 2 `u32`, point, frame (`n, t, s`: 3 vectors), gap `f64`, μ `f64`, impulse, status `u8` (0 no contact, 1 stick, 2 slide), local point |
//! | *anchors*            | `u8` 0 (absent) or 1 then the `n` anchor positions, then the `n` anchor orientations (version ≥ 2; a version 1 file has no such field) |
//! | *origin*             | `u8` 0 (absent) or 1 then `u64`, the [`crate::world::initial_state_digest`] of the state the run started from (version ≥ 3; older files have no such field and are not checked) |
//! | *drive work*         | array of (driven body `u32`, `f64` work in J): [`World::drive_work`] (version ≥ 4; older files read as no work done) |
//! | *drive lag*          | array of (driven body `u32`, lag 3 × `f64` in m): [`World::drive_lag`] (version ≥ 5; older files read as no lag) |
//! | *run statistics*     | `u8` 0 (absent) or 1 then steps `u64`, contacts sum `u64`, contacts max `u64`, iterations sum `u64`, max residual `f64`, steps not converged `u64`, max penetration `f64` |
//!
//! The shape hash is [`fnv1a64`] over the shape kind and its exact geometry (vertices, faces,
//! radius); the driver hash over the driver's JSON. Settings travel whole, as JSON, so a
//! setting added later (domain decomposition, say) is covered without a format change.
//!
//! The scene says what the bodies are, not where they started: two scenarios with the same
//! bodies placed or launched differently have the same scene. The *origin* field tells their
//! checkpoints apart: a checkpoint is refused by a world whose run started from another state
//! ([`World::origin_digest`]), so a run folder reused by another scenario never resumes the
//! old trajectory.
//!
//! Size: 237 bytes per body plus 169 bytes per contact point, plus under 1 kB. For 1,000
//! grains: 239 kB while they fall, 0.89 MB with 3,850 contact points (a pile settling; a
//! dense pile with 6–8 points per grain gives about 1.3–1.6 MB).
//!
//! Anything added to [`World`] that carries over from one step to the next must be added
//! here (and [`FORMAT_VERSION`] bumped); the `checkpoints_cover_all_state_fields` test fails
//! until a new field is classified.
//!
//! # Parts written by the ranks
//!
//! A world whose solves are shared between ranks ([`World::ranks`] > 1) is checkpointed in
//! parts ([`write_checkpoint_on_ranks`]): rank `R` writes `checkpoint_<step>.part<R>.bin` with
//! the states of the bodies it owns (those of its subdomains in the scene's partition; the
//! driven and fixed bodies on rank 0), their anchor poses, and the contacts whose first dynamic
//! body it owns, each record with its index; once every rank has written its part, rank 0
//! writes `checkpoint_<step>.bin`, the manifest: the file above with `K` parts and their
//! checksums in place of those arrays. A part has the same frame with the magic
//! `BALLASTPART` and the payload: scene fingerprint `u64`, step `u64`, rank `u32`, ranks `u32`,
//! body count `u64`, contact count `u64`; the part's bodies (array of `u32` indices, then
//! field by field their positions, orientations, velocities, angular velocities, angular
//! momenta), `u8` anchors flag then their anchor positions and orientations; its contacts
//! (array of `u32` indices, then field by field as in the contacts section). Reading a
//! manifest reads its parts, checks each against the checksum the manifest names, and puts
//! the whole state back together: any number of ranks (one process too) resumes it, bit for
//! bit. A manifest whose part is missing or damaged is damaged: a resume passes over it to the
//! previous checkpoint.
//!
//! # Files in a run folder
//!
//! Checkpoints are named `checkpoint_<step:010>.bin` ([`checkpoint_path`]) and written
//! atomically (a `.tmp` file, synced, then a rename), so a crash mid-write leaves the previous
//! checkpoints intact and at worst a stray `.tmp` file, which is never read (a resume deletes
//! it: [`remove_partial_checkpoints`]; a write that fails, on a full disk, deletes its own).
//! [`newest_valid_checkpoint`] resumes from the newest file that reads back valid, and
//! [`prune_checkpoints`] keeps the newest few.

use crate::bodies::BodyKind;
use crate::contacts::ContactSet;
use crate::laws::ContactStatus;
use crate::math::{DQuat, DVec3};
use crate::output::RunStats;
use crate::shapes::Shape;
use crate::timing::PhaseTimes;
use crate::world::World;
use parts::PartsSpec;
pub use parts::{part_path, write_checkpoint_on_ranks};
use std::fmt;

mod parts;
use std::path::{Path, PathBuf};

/// The magic bytes every checkpoint starts with.
pub const MAGIC: &[u8; 11] = b"BALLASTCKPT";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 6;
/// The oldest format version this build still reads (version 1 has no anchor poses: a run
/// resumed from it detects every pair anew at its first step).
pub(crate) const OLDEST_VERSION: u32 = 1;
/// Magic, version, payload length.
const HEADER_LEN: usize = 11 + 4 + 8;
const CHECKSUM_LEN: usize = 8;

/// Why a checkpoint file is damaged.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Corruption {
    /// The file ends early: `len` bytes where at least `needed` are required (a write cut
    /// short, or a damaged length field).
    Truncated { len: u64, needed: u64 },
    /// The file is longer than its header declares.
    TooLong { len: u64, expected: u64 },
    /// The trailing checksum does not match the contents (some byte was altered).
    ChecksumMismatch { stored: u64, computed: u64 },
    /// The checksum is right but the contents do not decode (a writer bug, or a file named
    /// like a checkpoint that holds other data).
    Malformed(String),
}

impl fmt::Display for Corruption {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Corruption::Truncated { len, needed } => write!(
                f,
                "truncated: the file has {len} bytes but needs at least {needed} \
                 (an interrupted write or copy, or a damaged length field)"
            ),
            Corruption::TooLong { len, expected } => write!(
                f,
                "length mismatch: the file has {len} bytes but its header declares {expected}"
            ),
            Corruption::ChecksumMismatch { stored, computed } => write!(
                f,
                "checksum mismatch: stored {stored:016x}, contents give {computed:016x} \
                 (the file was altered or damaged)"
            ),
            Corruption::Malformed(why) => write!(f, "malformed contents: {why}"),
        }
    }
}

/// Why a checkpoint could not be read or used.
#[derive(thiserror::Error, Debug)]
pub enum CheckpointError {
    /// The file or folder could not be read.
    #[error("cannot read checkpoint {}: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with [`MAGIC`].
    #[error(
        "{} is not a ballast checkpoint (it does not start with \"BALLASTCKPT\"); \
         remove it or point at a folder written by `ballast run`",
        .path.display()
    )]
    BadMagic { path: PathBuf },
    /// The file is intact but in a format version this build does not read.
    #[error(
        "{} is in checkpoint format version {found}, this build reads version {supported}; \
         resume it with the ballast release that wrote it, or start the run afresh",
        .path.display()
    )]
    UnsupportedVersion {
        path: PathBuf,
        found: u32,
        supported: u32,
    },
    /// The file is damaged.
    #[error(
        "{} is corrupted, {reason}; delete it to resume from an older checkpoint, \
         or start the run afresh",
        .path.display()
    )]
    Corrupted { path: PathBuf, reason: Corruption },
    /// The checkpoint was written for another scene than the world it is read into.
    #[error(
        "{} was written for a different scene: {what}; resume with the scenario file and \
         settings that produced it, or start a new run in another folder",
        .path.display()
    )]
    SceneMismatch { path: PathBuf, what: String },
}

impl CheckpointError {
    /// True for damage a crash or a bad disk can cause ([`CheckpointError::Corrupted`],
    /// [`CheckpointError::BadMagic`]): [`newest_valid_checkpoint`] skips such files. The other
    /// errors mean the user pointed at the wrong run or release, and stop the search.
    pub fn is_damage(&self) -> bool {
        matches!(
            self,
            CheckpointError::Corrupted { .. } | CheckpointError::BadMagic { .. }
        )
    }
}

/// 64-bit FNV-1a: offset basis `0xcbf29ce484222325`, prime `0x100000001b3`, one byte at a time
/// (`h ^= byte; h *= prime`). Detects accidental damage; it is not a cryptographic hash.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv::new();
    h.write(bytes);
    h.0
}

struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn u32(&mut self, x: u32) {
        self.write(&x.to_le_bytes());
    }
    fn f64(&mut self, x: f64) {
        self.write(&x.to_bits().to_le_bytes());
    }
    fn vec3(&mut self, v: DVec3) {
        v.to_array().into_iter().for_each(|x| self.f64(x));
    }
}

// ---------------------------------------------------------------------------------------------
// Encoding primitives.

/// An encoder: its bytes kept in memory, only counted, or streamed to a file and hashed on
/// the way (see [`write_framed`]).
struct Enc(Sink);

enum Sink {
    Memory(Vec<u8>),
    Count(u64),
    File(FileSink),
}

/// A file being written through a buffer: its checksum so far, its length, and the first
/// write error (the encoder's calls cannot fail; the error is returned when it ends).
struct FileSink {
    w: std::io::BufWriter<std::fs::File>,
    hash: Fnv,
    n: u64,
    error: Option<std::io::Error>,
}

impl Default for Enc {
    fn default() -> Self {
        Enc(Sink::Memory(Vec::new()))
    }
}

impl Enc {
    /// An encoder appending to `bytes`.
    fn memory(bytes: Vec<u8>) -> Enc {
        Enc(Sink::Memory(bytes))
    }
    /// The bytes of an encoder in memory.
    fn bytes(&self) -> &[u8] {
        match &self.0 {
            Sink::Memory(v) => v,
            _ => unreachable!("only an encoder in memory has its bytes"),
        }
    }
    fn into_bytes(self) -> Vec<u8> {
        match self.0 {
            Sink::Memory(v) => v,
            _ => unreachable!("only an encoder in memory has its bytes"),
        }
    }
    /// The number of bytes written so far.
    fn written(&self) -> u64 {
        match &self.0 {
            Sink::Memory(v) => v.len() as u64,
            Sink::Count(n) => *n,
            Sink::File(f) => f.n,
        }
    }
    fn write(&mut self, bytes: &[u8]) {
        match &mut self.0 {
            Sink::Memory(v) => v.extend_from_slice(bytes),
            Sink::Count(n) => *n += bytes.len() as u64,
            Sink::File(f) => {
                use std::io::Write;
                f.n += bytes.len() as u64;
                if f.error.is_none() {
                    f.hash.write(bytes);
                    if let Err(e) = f.w.write_all(bytes) {
                        f.error = Some(e);
                    }
                }
            }
        }
    }
    fn u8(&mut self, x: u8) {
        self.write(&[x]);
    }
    fn u32(&mut self, x: u32) {
        self.write(&x.to_le_bytes());
    }
    fn u64(&mut self, x: u64) {
        self.write(&x.to_le_bytes());
    }
    fn len(&mut self, n: usize) {
        self.u64(n as u64);
    }
    fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
    fn vec3(&mut self, v: DVec3) {
        v.to_array().into_iter().for_each(|x| self.f64(x));
    }
    fn quat(&mut self, q: DQuat) {
        q.to_array().into_iter().for_each(|x| self.f64(x));
    }

    /// The start of a framed file in memory: magic, version, and the payload's length,
    /// written by [`Enc::finish_frame`] once the payload follows (encoded in place, not
    /// copied into a frame).
    fn framed(magic: &[u8; 11]) -> Enc {
        let mut e = Enc::default();
        e.write(magic);
        e.u32(FORMAT_VERSION);
        e.u64(0);
        debug_assert_eq!(e.written(), HEADER_LEN as u64);
        e
    }

    /// The framed bytes: the payload's length put in the header, the checksum of all before
    /// it appended.
    fn finish_frame(self) -> Vec<u8> {
        let mut v = self.into_bytes();
        let n = (v.len() - HEADER_LEN) as u64;
        v[HEADER_LEN - 8..HEADER_LEN].copy_from_slice(&n.to_le_bytes());
        let sum = fnv1a64(&v);
        v.extend_from_slice(&sum.to_le_bytes());
        v
    }
}

/// Writes at `path` the framed file (the bytes [`Enc::framed`] and [`Enc::finish_frame`]
/// make) whose payload `encode` writes, without holding it in memory — a checkpoint at scale
/// is hundreds of megabytes: a first pass only counts the payload's bytes for the header, the
/// second streams them to the file, hashing on the way. Atomic and durable: a temporary file,
/// synced, renamed into place, the folder synced. Returns the file's checksum.
fn write_framed(path: &Path, magic: &[u8; 11], encode: impl Fn(&mut Enc)) -> std::io::Result<u64> {
    let mut count = Enc(Sink::Count(0));
    encode(&mut count);
    let n = count.written();
    let tmp = path.with_extension("tmp");
    let written = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut e = Enc(Sink::File(FileSink {
            w: std::io::BufWriter::with_capacity(1 << 20, file),
            hash: Fnv::new(),
            n: 0,
            error: None,
        }));
        e.write(magic);
        e.u32(FORMAT_VERSION);
        e.u64(n);
        encode(&mut e);
        let Sink::File(mut f) = e.0 else {
            unreachable!("a file encoder")
        };
        if let Some(error) = f.error.take() {
            return Err(error);
        }
        if f.n != HEADER_LEN as u64 + n {
            return Err(std::io::Error::other(
                "the checkpoint's two encoding passes differ in length",
            ));
        }
        let sum = f.hash.0;
        use std::io::Write;
        f.w.write_all(&sum.to_le_bytes())?;
        let file = f.w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)?;
        Ok(sum)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    let sum = written?;
    sync_folder(path);
    Ok(sum)
}

/// Bounds-checked reader; errors name the field and the byte offset.
struct Dec<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Offset of `bytes[0]` in the file, for messages.
    base: usize,
}

type DecResult<T> = Result<T, String>;

impl<'a> Dec<'a> {
    fn take(&mut self, n: usize, what: &str) -> DecResult<&'a [u8]> {
        if self.bytes.len() - self.pos < n {
            return Err(format!(
                "{what} at byte {} runs past the end of the payload",
                self.base + self.pos
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self, what: &str) -> DecResult<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }
    fn u8(&mut self, what: &str) -> DecResult<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> DecResult<u32> {
        self.array(what).map(u32::from_le_bytes)
    }
    fn u64(&mut self, what: &str) -> DecResult<u64> {
        self.array(what).map(u64::from_le_bytes)
    }
    fn f64(&mut self, what: &str) -> DecResult<f64> {
        self.u64(what).map(f64::from_bits)
    }
    fn vec3(&mut self, what: &str) -> DecResult<DVec3> {
        Ok(DVec3::new(
            self.f64(what)?,
            self.f64(what)?,
            self.f64(what)?,
        ))
    }
    fn quat(&mut self, what: &str) -> DecResult<DQuat> {
        let [x, y, z, w] = [
            self.f64(what)?,
            self.f64(what)?,
            self.f64(what)?,
            self.f64(what)?,
        ];
        Ok(DQuat::from_xyzw(x, y, z, w))
    }
    /// An element count, checked against the bytes left so a damaged count cannot trigger a
    /// huge allocation.
    fn count(&mut self, elem_size: usize, what: &str) -> DecResult<usize> {
        let at = self.base + self.pos;
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.pos) as u64;
        if n.saturating_mul(elem_size as u64) > left {
            return Err(format!(
                "{what} count {n} at byte {at} needs more than the {left} bytes left"
            ));
        }
        Ok(n as usize)
    }
    fn vec<T>(
        &mut self,
        n: usize,
        mut f: impl FnMut(&mut Self) -> DecResult<T>,
    ) -> DecResult<Vec<T>> {
        (0..n).map(|_| f(self)).collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Scene description.

/// What must be equal for a checkpoint to apply to a world, per body.
#[derive(Clone, Debug, PartialEq, Eq)]
struct BodyRecord {
    kind: u8,
    group: u32,
    /// `f64` bits, so the comparison is exact.
    inv_mass: u64,
    inertia: [u64; 3],
    shape: u64,
    driver: u64,
}

const BODY_RECORD_LEN: usize = 1 + 4 + 8 + 24 + 8 + 8;

#[derive(Clone, Debug, PartialEq)]
struct Scene {
    settings_json: String,
    bodies: Vec<BodyRecord>,
    /// `(a, b, μ bits)`, `a ≤ b`.
    friction: Vec<(u32, u32, u64)>,
}

fn kind_code(k: BodyKind) -> u8 {
    match k {
        BodyKind::Dynamic => 0,
        BodyKind::Kinematic => 1,
        BodyKind::Fixed => 2,
    }
}

fn kind_name(code: u8) -> &'static str {
    match code {
        0 => "dynamic",
        1 => "kinematic",
        2 => "fixed",
        _ => "unknown",
    }
}

fn shape_hash(shape: &Shape) -> u64 {
    let mut h = Fnv::new();
    match shape {
        Shape::Plane { normal } => {
            h.write(b"plane");
            h.vec3(*normal);
        }
        Shape::Polyhedron(p) => {
            h.write(b"polyhedron");
            h.write(&(p.vertices.len() as u64).to_le_bytes());
            p.vertices.iter().for_each(|&v| h.vec3(v));
            h.write(&(p.face_normals.len() as u64).to_le_bytes());
            p.face_normals.iter().for_each(|&v| h.vec3(v));
            p.face_offsets.iter().for_each(|&x| h.f64(x));
            p.face_start.iter().for_each(|&x| h.u32(x));
            p.face_vertices.iter().for_each(|&x| h.u32(x));
            h.f64(p.radius);
        }
    }
    h.0
}

impl Scene {
    fn of(world: &World) -> Self {
        // The settings travel as JSON so that a field added to them later is covered without
        // touching this file, and a difference can be named by its path.
        let settings_json = serde_json::to_string(&world.settings)
            .unwrap_or_else(|e| format!("<settings not serialisable: {e}>"));
        let b = &world.bodies;
        let bodies = (0..b.len())
            .map(|i| BodyRecord {
                kind: kind_code(b.scene_kind(i)),
                group: b.group[i],
                inv_mass: b.inv_mass[i].to_bits(),
                inertia: b.inertia[i].to_array().map(f64::to_bits),
                shape: shape_hash(&b.shape[i]),
                driver: b.driver[i].as_ref().map_or(0, |d| {
                    serde_json::to_string(d).map_or(1, |s| fnv1a64(s.as_bytes()))
                }),
            })
            .collect();
        // μ matters only between the groups present; the table's own entries are private.
        let mut groups = b.group.clone();
        groups.sort_unstable();
        groups.dedup();
        let mut friction = Vec::new();
        for (k, &a) in groups.iter().enumerate() {
            for &g in &groups[k..] {
                friction.push((a, g, world.friction.get(a, g).to_bits()));
            }
        }
        Scene {
            settings_json,
            bodies,
            friction,
        }
    }

    fn encode(&self, e: &mut Enc) {
        e.len(self.settings_json.len());
        e.write(self.settings_json.as_bytes());
        e.len(self.bodies.len());
        for r in &self.bodies {
            e.u8(r.kind);
            e.u32(r.group);
            e.u64(r.inv_mass);
            r.inertia.iter().for_each(|&x| e.u64(x));
            e.u64(r.shape);
            e.u64(r.driver);
        }
        e.len(self.friction.len());
        for &(a, b, mu) in &self.friction {
            e.u32(a);
            e.u32(b);
            e.u64(mu);
        }
    }

    fn decode(d: &mut Dec) -> DecResult<Self> {
        let n = d.count(1, "settings length")?;
        let settings_json = String::from_utf8(d.take(n, "settings")?.to_vec())
            .map_err(|_| "settings are not UTF-8".to_string())?;
        let n = d.count(BODY_RECORD_LEN, "scene body")?;
        let bodies = d.vec(n, |d| {
            Ok(BodyRecord {
                kind: d.u8("body kind")?,
                group: d.u32("body group")?,
                inv_mass: d.u64("inverse mass")?,
                inertia: [d.u64("inertia")?, d.u64("inertia")?, d.u64("inertia")?],
                shape: d.u64("shape hash")?,
                driver: d.u64("driver hash")?,
            })
        })?;
        let n = d.count(16, "friction entry")?;
        let friction = d.vec(n, |d| Ok((d.u32("group")?, d.u32("group")?, d.u64("mu")?)))?;
        Ok(Scene {
            settings_json,
            bodies,
            friction,
        })
    }

    /// The first difference between the checkpoint's scene `self` and the world's `other`, in
    /// words, or `None` when they are the same.
    fn difference(&self, other: &Scene) -> Option<String> {
        let (nc, nw) = (self.bodies.len(), other.bodies.len());
        if nc != nw {
            return Some(format!(
                "number of bodies is {nc} in the checkpoint, {nw} in the scenario"
            ));
        }
        let settings = current_settings_json(&self.settings_json);
        if settings != other.settings_json {
            return Some(settings_difference(&settings, &other.settings_json));
        }
        let differing: Vec<usize> = (0..nc)
            .filter(|&i| self.bodies[i] != other.bodies[i])
            .collect();
        if let Some(&i) = differing.first() {
            let (c, w) = (&self.bodies[i], &other.bodies[i]);
            let f = |bits: u64| f64::from_bits(bits);
            let what = if c.kind != w.kind {
                format!(
                    "kind is {} in the checkpoint, {} in the scenario",
                    kind_name(c.kind),
                    kind_name(w.kind)
                )
            } else if c.group != w.group {
                format!(
                    "group is {} in the checkpoint, {} in the scenario",
                    c.group, w.group
                )
            } else if c.shape != w.shape {
                "shape differs (other geometry: grain seed, size or vertices changed)".into()
            } else if c.inv_mass != w.inv_mass {
                format!(
                    "inverse mass is {} in the checkpoint, {} in the scenario (density changed?)",
                    f(c.inv_mass),
                    f(w.inv_mass)
                )
            } else if c.inertia != w.inertia {
                format!(
                    "principal inertia is {:?} in the checkpoint, {:?} in the scenario",
                    c.inertia.map(f),
                    w.inertia.map(f)
                )
            } else {
                "kinematic driver differs".into()
            };
            let others = match differing.len() - 1 {
                0 => String::new(),
                k => format!(" (and {k} more bodies differ)"),
            };
            return Some(format!("body {i} ({}): {what}{others}", kind_name(w.kind)));
        }
        if self.friction != other.friction {
            for (c, w) in self.friction.iter().zip(&other.friction) {
                if c != w {
                    return Some(if (c.0, c.1) == (w.0, w.1) {
                        format!(
                            "friction coefficient between groups {} and {} is {} in the \
                             checkpoint, {} in the scenario",
                            c.0,
                            c.1,
                            f64::from_bits(c.2),
                            f64::from_bits(w.2)
                        )
                    } else {
                        "the bodies' groups differ".into()
                    });
                }
            }
            return Some("the bodies' groups differ".into());
        }
        None
    }
}

/// A checkpoint's settings as this version writes them: a setting added since the checkpoint
/// was written reads as its default, so a run resumes when its scenario keeps that default
/// (session 8 added three overlap correction settings, and every older checkpoint then failed
/// to resume). Settings this version cannot read are left as they were written.
fn current_settings_json(json: &str) -> String {
    serde_json::from_str::<crate::world::StepSettings>(json)
        .ok()
        .and_then(|s| serde_json::to_string(&s).ok())
        .unwrap_or_else(|| json.to_string())
}

/// Names the first setting that differs, by its path (`solver.tolerance`), with both values.
fn settings_difference(ckpt: &str, world: &str) -> String {
    fn first(path: &str, a: &serde_json::Value, b: &serde_json::Value) -> Option<String> {
        use serde_json::Value;
        match (a, b) {
            (Value::Object(ma), Value::Object(mb)) => {
                let mut keys: Vec<&String> = ma.keys().chain(mb.keys()).collect();
                keys.sort();
                keys.dedup();
                keys.into_iter().find_map(|k| {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    match (ma.get(k), mb.get(k)) {
                        (Some(x), Some(y)) => first(&p, x, y),
                        (Some(_), None) => {
                            Some(format!("setting {p} exists only in the checkpoint"))
                        }
                        (None, _) => Some(format!("setting {p} exists only in the scenario")),
                    }
                })
            }
            _ if a != b => Some(format!(
                "{path} is {a} in the checkpoint, {b} in the scenario"
            )),
            _ => None,
        }
    }
    match (
        serde_json::from_str::<serde_json::Value>(ckpt),
        serde_json::from_str::<serde_json::Value>(world),
    ) {
        (Ok(a), Ok(b)) => first("", &a, &b),
        _ => None,
    }
    .unwrap_or_else(|| {
        format!("settings differ: {ckpt} in the checkpoint, {world} in the scenario")
    })
}

/// Fingerprint of everything in `world` that a checkpoint does not store but that changes the
/// results: settings, body kinds, groups, masses, inertias, shapes, drivers and the friction
/// coefficients between the groups present (64-bit FNV-1a of the scene section of the format).
pub fn scene_fingerprint(world: &World) -> u64 {
    let mut e = Enc::default();
    Scene::of(world).encode(&mut e);
    fnv1a64(e.bytes())
}

// ---------------------------------------------------------------------------------------------
// Writing.

fn status_code(s: ContactStatus) -> u8 {
    match s {
        ContactStatus::NoContact => 0,
        ContactStatus::Stick => 1,
        ContactStatus::Slide => 2,
    }
}

/// The checkpoint of `world` (and optionally the run statistics) as bytes.
pub fn encode_checkpoint(world: &World, stats: Option<&RunStats>) -> Vec<u8> {
    encode_manifest(world, stats, &[])
}

/// The checkpoint of `world` whose bodies, contacts and anchors are in the parts of checksums
/// `parts` (none: in the file).
fn encode_manifest(world: &World, stats: Option<&RunStats>, parts: &[u64]) -> Vec<u8> {
    let scene = encode_scene(world);
    let mut p = Enc::framed(MAGIC);
    encode_manifest_payload(&mut p, world, stats, parts, &scene);
    p.finish_frame()
}

/// The scene section of a checkpoint (see [`Scene`]), encoded.
fn encode_scene(world: &World) -> Vec<u8> {
    let mut scene = Enc::default();
    Scene::of(world).encode(&mut scene);
    scene.into_bytes()
}

/// A checkpoint's payload: the scene's checksum and bytes (`scene`), then the state.
fn encode_manifest_payload(
    p: &mut Enc,
    world: &World,
    stats: Option<&RunStats>,
    parts: &[u64],
    scene: &[u8],
) {
    p.u64(fnv1a64(scene));
    p.write(scene);
    encode_state_with(p, world, stats, parts);
}

/// Writes the checkpoint of `world` whose bodies, contacts and anchors are in the parts of
/// checksums `parts` (none: in the file) at `path`, streamed (see [`write_framed`]).
fn write_manifest(
    world: &World,
    stats: Option<&RunStats>,
    parts: &[u64],
    path: &Path,
) -> std::io::Result<()> {
    let scene = encode_scene(world);
    write_framed(path, MAGIC, |p| {
        encode_manifest_payload(p, world, stats, parts, &scene)
    })
    .map(|_| ())
}

/// The state section of a checkpoint: clock, timers, body states, contacts, detection
/// anchors, the run's origin and the statistics (everything after the scene).
fn encode_state(p: &mut Enc, world: &World, stats: Option<&RunStats>) {
    encode_state_with(p, world, stats, &[]);
}

/// [`encode_state`], with the bodies, contacts and anchors left to the parts of checksums
/// `parts` when there are any.
fn encode_state_with(p: &mut Enc, world: &World, stats: Option<&RunStats>, parts: &[u64]) {
    p.f64(world.time);
    p.u64(world.step_index);
    encode_timers(p, &world.timers);
    p.u32(parts.len() as u32);
    if parts.is_empty() {
        encode_arrays(p, world);
    } else {
        p.len(world.bodies.len());
        p.len(world.contact_total());
        p.u8(u8::from(parts::has_anchors(world)));
        parts.iter().for_each(|&s| p.u64(s));
    }
    encode_tail(p, world, stats);
}

/// Body states, contacts and anchors, whole.
fn encode_arrays(p: &mut Enc, world: &World) {
    p.len(world.bodies.len());
    encode_bodies(p, world, 0..world.bodies.len());
    p.len(world.contacts.len());
    encode_contacts(p, &world.contacts, 0..world.contacts.len());
    encode_anchors(p, world, 0..world.bodies.len());
}

/// The states of bodies `rows`, field by field.
fn encode_bodies(p: &mut Enc, world: &World, rows: impl Iterator<Item = usize> + Clone) {
    let b = &world.bodies;
    rows.clone().for_each(|i| p.vec3(b.position[i]));
    rows.clone().for_each(|i| p.quat(b.orientation[i]));
    for a in [&b.velocity, &b.angular_velocity, &b.angular_momentum] {
        rows.clone().for_each(|i| p.vec3(a[i]));
    }
}

/// Contacts `rows` of `c`, field by field (read back by [`decode_contacts`]).
fn encode_contacts(p: &mut Enc, c: &ContactSet, rows: impl Iterator<Item = usize> + Clone) {
    rows.clone().for_each(|k| p.u32(c.body1[k]));
    rows.clone().for_each(|k| p.u32(c.body2[k]));
    rows.clone().for_each(|k| p.vec3(c.point[k]));
    rows.clone()
        .for_each(|k| c.frame[k].iter().for_each(|&v| p.vec3(v)));
    rows.clone().for_each(|k| p.f64(c.gap[k]));
    rows.clone().for_each(|k| p.f64(c.mu[k]));
    rows.clone().for_each(|k| p.vec3(c.impulse[k]));
    rows.clone().for_each(|k| p.u8(status_code(c.status[k])));
    rows.for_each(|k| p.vec3(c.local_point[k]));
}

/// The anchors flag, then (flag 1) the anchor poses of bodies `rows`.
fn encode_anchors(p: &mut Enc, world: &World, rows: impl Iterator<Item = usize> + Clone) {
    if parts::has_anchors(world) {
        let a = world.detector.anchors();
        p.u8(1);
        rows.clone().for_each(|i| p.vec3(a.position[i]));
        rows.for_each(|i| p.quat(a.orientation[i]));
    } else {
        p.u8(0);
    }
}

/// The run's origin, the drives' work and lag, and the statistics.
fn encode_tail(p: &mut Enc, world: &World, stats: Option<&RunStats>) {
    match world.origin_digest() {
        Some(o) => {
            p.u8(1);
            p.u64(o);
        }
        None => p.u8(0),
    }

    p.len(world.drive_work.len());
    for &(body, work) in &world.drive_work {
        p.u32(body);
        p.f64(work);
    }
    p.len(world.drive_lag.len());
    for &(body, lag) in &world.drive_lag {
        p.u32(body);
        p.vec3(lag);
    }

    match stats {
        None => p.u8(0),
        Some(s) => {
            p.u8(1);
            p.u64(s.steps);
            p.u64(s.contacts_sum);
            p.len(s.contacts_max);
            p.u64(s.iterations_sum);
            p.f64(s.max_residual);
            p.u64(s.not_converged);
            p.f64(s.max_penetration);
        }
    }
}

/// Writes the checkpoint of `world` to `path` atomically (temporary file, synced, then
/// renamed), so a crash mid-write leaves any previous file at `path` intact; streamed, never
/// held whole in memory.
pub fn write_checkpoint(world: &World, path: &Path) -> std::io::Result<()> {
    write_checkpoint_with_stats(world, None, path)
}

/// [`write_checkpoint`], also saving the run statistics so far (returned on resume by
/// [`read_checkpoint_with_stats`] and [`newest_valid_checkpoint`]).
pub fn write_checkpoint_with_stats(
    world: &World,
    stats: Option<&RunStats>,
    path: &Path,
) -> std::io::Result<()> {
    write_manifest(world, stats, &[], path)
}

/// Makes the rename of a file into `path`'s folder durable, so that after a power cut the
/// folder does not still name the previous (possibly pruned) file. Best effort: not every
/// platform can sync a folder, and the data is already safe.
fn sync_folder(path: &Path) {
    #[cfg(unix)]
    if let Some(dir) = path.parent() {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Reading.

/// A decoded checkpoint, not yet applied to a world.
struct Decoded {
    /// The scene section's fingerprint.
    fingerprint: u64,
    scene: Scene,
    state: State,
}

/// A decoded state section ([`encode_state`]).
struct State {
    time: f64,
    step_index: u64,
    timers: PhaseTimes,
    position: Vec<DVec3>,
    orientation: Vec<DQuat>,
    velocity: Vec<DVec3>,
    angular_velocity: Vec<DVec3>,
    angular_momentum: Vec<DVec3>,
    contacts: ContactSet,
    /// Detection anchor poses (version ≥ 2, when the writer had them).
    anchors: Option<(Vec<DVec3>, Vec<DQuat>)>,
    /// Digest of the run's initial state (version ≥ 3).
    origin: Option<u64>,
    /// Work done by each drive (version ≥ 4).
    drive_work: Vec<(u32, f64)>,
    drive_lag: Vec<(u32, DVec3)>,
    stats: Option<RunStats>,
    /// The parts holding the bodies, contacts and anchors, still to be read (version ≥ 6).
    parts: Option<PartsSpec>,
}

/// Checks the frame (magic, length, checksum, version) and returns the payload.
fn unframe<'a>(bytes: &'a [u8], path: &Path) -> Result<(&'a [u8], u32), CheckpointError> {
    unframe_with(bytes, path, MAGIC)
}

/// [`unframe`] for a file of magic `magic`.
fn unframe_with<'a>(
    bytes: &'a [u8],
    path: &Path,
    magic: &[u8; 11],
) -> Result<(&'a [u8], u32), CheckpointError> {
    let corrupted = |reason| CheckpointError::Corrupted {
        path: path.to_path_buf(),
        reason,
    };
    let len = bytes.len() as u64;
    let m = bytes.len().min(magic.len());
    if bytes[..m] != magic[..m] {
        return Err(CheckpointError::BadMagic {
            path: path.to_path_buf(),
        });
    }
    if bytes.len() < HEADER_LEN + CHECKSUM_LEN {
        return Err(corrupted(Corruption::Truncated {
            len,
            needed: (HEADER_LEN + CHECKSUM_LEN) as u64,
        }));
    }
    let version = u32::from_le_bytes([bytes[11], bytes[12], bytes[13], bytes[14]]);
    let mut p = [0u8; 8];
    p.copy_from_slice(&bytes[15..HEADER_LEN]);
    let payload_len = u64::from_le_bytes(p);
    let expected = payload_len.saturating_add((HEADER_LEN + CHECKSUM_LEN) as u64);
    if len < expected {
        return Err(corrupted(Corruption::Truncated {
            len,
            needed: expected,
        }));
    }
    if len > expected {
        return Err(corrupted(Corruption::TooLong { len, expected }));
    }
    let body_end = bytes.len() - CHECKSUM_LEN;
    let mut s = [0u8; 8];
    s.copy_from_slice(&bytes[body_end..]);
    let stored = u64::from_le_bytes(s);
    let computed = fnv1a64(&bytes[..body_end]);
    if stored != computed {
        return Err(corrupted(Corruption::ChecksumMismatch { stored, computed }));
    }
    // The frame is shared by all versions, so an intact file with another version number was
    // genuinely written in another format.
    if !(OLDEST_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(CheckpointError::UnsupportedVersion {
            path: path.to_path_buf(),
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    Ok((&bytes[HEADER_LEN..body_end], version))
}

fn decode_payload(payload: &[u8], version: u32) -> DecResult<Decoded> {
    let mut d = Dec {
        bytes: payload,
        pos: 0,
        base: HEADER_LEN,
    };
    let fingerprint = d.u64("scene fingerprint")?;
    let scene_start = d.pos;
    let scene = Scene::decode(&mut d)?;
    if fnv1a64(&payload[scene_start..d.pos]) != fingerprint {
        return Err("the scene fingerprint does not match the scene section".into());
    }
    let state = decode_state(&mut d, version, scene.bodies.len())?;
    if d.pos != payload.len() {
        return Err(format!(
            "{} unread bytes after the last section",
            payload.len() - d.pos
        ));
    }
    Ok(Decoded {
        fingerprint,
        scene,
        state,
    })
}

/// Reads a state section written by [`encode_state`] (in format `version`) for `bodies`
/// bodies.
fn decode_state(d: &mut Dec, version: u32, bodies: usize) -> DecResult<State> {
    let time = d.f64("time")?;
    let step_index = d.u64("step index")?;
    let timers = decode_timers(d)?;

    let parts = if version >= 6 { d.u32("parts")? } else { 0 };
    let (mut position, mut orientation) = (Vec::new(), Vec::new());
    let (mut velocity, mut angular_velocity, mut angular_momentum) =
        (Vec::new(), Vec::new(), Vec::new());
    let mut c = ContactSet::default();
    let mut anchors = None;
    let mut spec = None;
    if parts == 0 {
        let n = d.count(16 * 8, "body")?;
        if n != bodies {
            return Err(format!(
                "{n} body states for {bodies} bodies in the scene section"
            ));
        }
        position = d.vec(n, |d| d.vec3("position"))?;
        orientation = d.vec(n, |d| d.quat("orientation"))?;
        velocity = d.vec(n, |d| d.vec3("velocity"))?;
        angular_velocity = d.vec(n, |d| d.vec3("angular velocity"))?;
        angular_momentum = d.vec(n, |d| d.vec3("angular momentum"))?;

        let m = d.count(4 + 4 + 24 + 72 + 8 + 8 + 24 + 1 + 24, "contact")?;
        decode_contacts(d, m, n, &mut c)?;

        anchors = match version {
            1 => None,
            _ => match d.u8("anchors flag")? {
                0 => None,
                1 => {
                    let position = d.vec(n, |d| d.vec3("anchor position"))?;
                    let orientation = d.vec(n, |d| d.quat("anchor orientation"))?;
                    Some((position, orientation))
                }
                f => return Err(format!("anchors flag {f} is not 0 or 1")),
            },
        };
    } else {
        let n = d.u64("body count")?;
        if n != bodies as u64 {
            return Err(format!(
                "{n} body states for {bodies} bodies in the scene section"
            ));
        }
        let m = d.u64("contact count")?;
        let anchors = match d.u8("anchors flag")? {
            0 => false,
            1 => true,
            f => return Err(format!("anchors flag {f} is not 0 or 1")),
        };
        let k = parts as usize;
        if k.saturating_mul(8) > d.bytes.len() - d.pos {
            return Err(format!("{k} parts need more than the bytes left"));
        }
        let sums = d.vec(k, |d| d.u64("part checksum"))?;
        let m = usize::try_from(m).map_err(|_| format!("{m} contacts do not fit in memory"))?;
        spec = Some(PartsSpec {
            bodies,
            contacts: m,
            anchors,
            sums,
        });
    }
    let origin = match version {
        1 | 2 => None,
        _ => match d.u8("origin flag")? {
            0 => None,
            1 => Some(d.u64("origin digest")?),
            f => return Err(format!("origin flag {f} is not 0 or 1")),
        },
    };
    let drive_work = match version {
        1..=3 => Vec::new(),
        _ => {
            let k = d.count(12, "drive count")?;
            d.vec(k, |d| Ok((d.u32("driven body")?, d.f64("drive work")?)))?
        }
    };
    let drive_lag = match version {
        1..=4 => Vec::new(),
        _ => {
            let k = d.count(28, "drive lag count")?;
            d.vec(k, |d| Ok((d.u32("lagging body")?, d.vec3("drive lag")?)))?
        }
    };

    let stats = match d.u8("statistics flag")? {
        0 => None,
        1 => {
            let mut s = RunStats::default();
            decode_stats(d, &mut s)?;
            Some(s)
        }
        f => return Err(format!("statistics flag {f} is not 0 or 1")),
    };
    Ok(State {
        time,
        step_index,
        timers,
        position,
        orientation,
        velocity,
        angular_velocity,
        angular_momentum,
        contacts: c,
        anchors,
        origin,
        drive_work,
        drive_lag,
        stats,
        parts: spec,
    })
}

/// The timers as `(field name, f64)` pairs taken from their serde form, so a timer added to
/// [`PhaseTimes`] is saved without touching this file and an older checkpoint still reads
/// (the missing timer starts at zero). Through `serde_json::Value`, not text, so the values
/// are exact.
fn encode_timers(e: &mut Enc, t: &PhaseTimes) {
    let fields: Vec<(String, f64)> = match serde_json::to_value(t) {
        Ok(serde_json::Value::Object(m)) => m
            .into_iter()
            .filter_map(|(k, v)| v.as_f64().map(|x| (k, x)))
            .collect(),
        _ => Vec::new(),
    };
    e.len(fields.len());
    for (k, x) in fields {
        e.len(k.len());
        e.write(k.as_bytes());
        e.f64(x);
    }
}

fn decode_timers(d: &mut Dec) -> DecResult<PhaseTimes> {
    let mut map = match serde_json::to_value(PhaseTimes::default()) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => return Ok(PhaseTimes::default()),
    };
    let n = d.count(8 + 8 + 1, "timer")?;
    for _ in 0..n {
        let len = d.count(1, "timer name length")?;
        let name = String::from_utf8_lossy(d.take(len, "timer name")?).into_owned();
        let x = d.f64("timer")?;
        // A timer this build no longer has is dropped.
        if let (Some(slot), Some(num)) = (map.get_mut(&name), serde_json::Number::from_f64(x)) {
            *slot = serde_json::Value::Number(num);
        }
    }
    serde_json::from_value(serde_json::Value::Object(map)).map_err(|e| format!("timers: {e}"))
}

fn decode_contacts(d: &mut Dec, m: usize, n: usize, c: &mut ContactSet) -> DecResult<()> {
    let body = |d: &mut Dec, what: &str| -> DecResult<u32> {
        let b = d.u32(what)?;
        if b as usize >= n {
            return Err(format!("{what} {b} does not exist ({n} bodies)"));
        }
        Ok(b)
    };
    c.body1 = d.vec(m, |d| body(d, "contact body 1"))?;
    c.body2 = d.vec(m, |d| body(d, "contact body 2"))?;
    c.point = d.vec(m, |d| d.vec3("contact point"))?;
    c.frame = d.vec(m, |d| {
        Ok([
            d.vec3("contact frame")?,
            d.vec3("contact frame")?,
            d.vec3("contact frame")?,
        ])
    })?;
    c.gap = d.vec(m, |d| d.f64("contact gap"))?;
    c.mu = d.vec(m, |d| d.f64("contact mu"))?;
    c.impulse = d.vec(m, |d| d.vec3("contact impulse"))?;
    c.status = d.vec(m, |d| match d.u8("contact status")? {
        0 => Ok(ContactStatus::NoContact),
        1 => Ok(ContactStatus::Stick),
        2 => Ok(ContactStatus::Slide),
        s => Err(format!("contact status {s} is not 0, 1 or 2")),
    })?;
    c.local_point = d.vec(m, |d| d.vec3("contact local point"))?;
    Ok(())
}

fn decode_stats(d: &mut Dec, s: &mut RunStats) -> DecResult<()> {
    s.steps = d.u64("statistics")?;
    s.contacts_sum = d.u64("statistics")?;
    s.contacts_max = usize::try_from(d.u64("statistics")?)
        .map_err(|_| "contacts max does not fit in memory".to_string())?;
    s.iterations_sum = d.u64("statistics")?;
    s.max_residual = d.f64("statistics")?;
    s.not_converged = d.u64("statistics")?;
    s.max_penetration = d.f64("statistics")?;
    Ok(())
}

/// Reads and fully validates the file (frame and contents), without touching a world.
fn load(path: &Path) -> Result<Decoded, CheckpointError> {
    let bytes = std::fs::read(path).map_err(|source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (payload, version) = unframe(&bytes, path)?;
    let mut d = decode_payload(payload, version).map_err(|why| CheckpointError::Corrupted {
        path: path.to_path_buf(),
        reason: Corruption::Malformed(why),
    })?;
    if let Some(spec) = d.state.parts.take() {
        parts::fill(path, d.fingerprint, &spec, &mut d.state)?;
    }
    Ok(d)
}

/// Checks the scene, then replaces the state of `world`; `world` is untouched on error.
fn apply(d: Decoded, path: &Path, world: &mut World) -> Result<Option<RunStats>, CheckpointError> {
    if let Some(what) = d.scene.difference(&Scene::of(world)) {
        return Err(CheckpointError::SceneMismatch {
            path: path.to_path_buf(),
            what,
        });
    }
    if let (Some(c), Some(w)) = (d.state.origin, world.origin_digest()) {
        if c != w {
            return Err(CheckpointError::SceneMismatch {
                path: path.to_path_buf(),
                what: format!(
                    "the run started from another initial state (positions, orientations or \
                     velocities of the bodies: digest {c:016x} in the checkpoint, {w:016x} in \
                     the scenario)"
                ),
            });
        }
    }
    Ok(apply_state(d.state, world))
}

/// Replaces the state of `world` by `d` (of the same scene), returning its statistics.
fn apply_state(d: State, world: &mut World) -> Option<RunStats> {
    let b = &mut world.bodies;
    b.position = d.position;
    b.orientation = d.orientation;
    b.velocity = d.velocity;
    b.angular_velocity = d.angular_velocity;
    b.angular_momentum = d.angular_momentum;
    world.contacts = d.contacts;
    let (position, orientation) = d.anchors.unwrap_or_default();
    world.detector.set_anchors(position, orientation);
    world.time = d.time;
    world.step_index = d.step_index;
    // A checkpoint without an origin leaves the run's origin unknown rather than wrong.
    world.origin = d.origin;
    world.drive_work = d.drive_work;
    world.drive_lag = d.drive_lag;
    // Released bodies follow the checkpoint's clock, whichever world reads it.
    for i in 0..world.bodies.len() {
        world.bodies.kind[i] = world.bodies.scene_kind(i);
    }
    world.bodies.apply_releases(world.time);
    world.timers = d.timers;
    d.stats
}

/// A world's state kept in memory, to put the same world back to it: what a checkpoint holds
/// but the scene (the world is the one it was taken from), so no file, checksum or scene
/// comparison. A front end that steps on takes one before each step, and puts the world back
/// to it when the health check finds the step diverged.
#[derive(Clone, Debug, Default)]
pub struct Snapshot {
    bytes: Vec<u8>,
}

impl Snapshot {
    /// The state of `world` (and of the run statistics `stats`) now.
    pub fn take(world: &World, stats: Option<&RunStats>) -> Self {
        let mut s = Snapshot::default();
        s.retake(world, stats);
        s
    }

    /// [`Snapshot::take`] into this snapshot, reusing its memory (one step to the next).
    pub fn retake(&mut self, world: &World, stats: Option<&RunStats>) {
        let mut bytes = std::mem::take(&mut self.bytes);
        bytes.clear();
        let mut e = Enc::memory(bytes);
        encode_state(&mut e, world, stats);
        self.bytes = e.into_bytes();
    }

    /// Puts `world` back to the state taken (stepping on then gives bit-identically what it
    /// gave from there), returning the statistics taken with it. `world` must be the world
    /// the snapshot was taken from, between two steps (not [`World::is_detected`]); a world
    /// with another number of bodies is refused and left unchanged.
    pub fn restore(&self, world: &mut World) -> Result<Option<RunStats>, String> {
        let mut d = Dec {
            bytes: &self.bytes,
            pos: 0,
            base: 0,
        };
        let state = decode_state(&mut d, FORMAT_VERSION, world.bodies.len())
            .map_err(|e| format!("snapshot: {e}"))?;
        Ok(apply_state(state, world))
    }

    /// Bytes held.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Whether nothing was taken yet.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
}

/// Reads the checkpoint at `path` into `world`, which must be built from the same scenario
/// (scene mismatches are reported, see [`CheckpointError::SceneMismatch`]). Replaces the body
/// states, the contacts (the warm start of the next step), the clock and the timers; stepping
/// on then gives bit-identically what the run that wrote the checkpoint would have. On error
/// `world` is left unchanged. Never panics on a bad file.
pub fn read_checkpoint(path: &Path, world: &mut World) -> Result<(), CheckpointError> {
    read_checkpoint_with_stats(path, world).map(|_| ())
}

/// [`read_checkpoint`], also returning the run statistics stored with
/// [`write_checkpoint_with_stats`] (`None` when there were none).
pub fn read_checkpoint_with_stats(
    path: &Path,
    world: &mut World,
) -> Result<Option<RunStats>, CheckpointError> {
    let d = load(path)?;
    apply(d, path, world)
}

// ---------------------------------------------------------------------------------------------
// Run folders.

/// `dir/checkpoint_<step:010>.bin`: zero-padded, so names sort like steps.
pub fn checkpoint_path(dir: &Path, step: u64) -> PathBuf {
    dir.join(format!("checkpoint_{step:010}.bin"))
}

/// The step number in a checkpoint file name, if it is one (`.tmp` files are not).
fn step_of(name: &str) -> Option<u64> {
    let digits = name.strip_prefix("checkpoint_")?.strip_suffix(".bin")?;
    if digits.is_empty() || !digits.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// The checkpoint files in `dir`, `(step, path)` in increasing step order.
pub fn list_checkpoints(dir: &Path) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        if let Some(step) = entry.file_name().to_str().and_then(step_of) {
            found.push((step, entry.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// The checkpoint [`newest_valid_checkpoint`] resumed from.
#[derive(Debug)]
pub struct Resumed {
    pub path: PathBuf,
    /// Steps done at the checkpoint (`World::step_index`).
    pub step: u64,
    /// Run statistics, when the checkpoint holds them.
    pub stats: Option<RunStats>,
}

/// A newer checkpoint file that was passed over, and why.
#[derive(Debug)]
pub struct Skipped {
    pub path: PathBuf,
    pub error: CheckpointError,
}

/// Outcome of [`newest_valid_checkpoint`].
#[derive(Debug)]
pub struct ResumeScan {
    /// The checkpoint now loaded in the world, or `None` when no file was valid (the world is
    /// then unchanged).
    pub resumed: Option<Resumed>,
    /// Damaged files newer than the one loaded, newest first, each with its error; callers
    /// should report them.
    pub skipped: Vec<Skipped>,
}

/// Loads into `world` (built from the run's scenario) the newest checkpoint in `dir` that reads
/// back valid, trying files from the highest step down.
///
/// Damaged files ([`CheckpointError::is_damage`]: truncated, altered, not a checkpoint, or whose
/// contents name another step than the file name) are skipped and listed in
/// [`ResumeScan::skipped`]; they are what a crash or a bad disk leaves. A scene mismatch, an
/// unsupported version or an unreadable file stops the search with that error instead: an
/// older file would not fix it, and quietly resuming from far back would hide the problem.
/// `.tmp` files (interrupted writes) are ignored. A missing `dir` is an
/// [`CheckpointError::Io`] error; a folder without any valid checkpoint gives
/// `resumed: None`.
pub fn newest_valid_checkpoint(
    dir: &Path,
    world: &mut World,
) -> Result<ResumeScan, CheckpointError> {
    let files = list_checkpoints(dir).map_err(|source| CheckpointError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut skipped = Vec::new();
    for (step, path) in files.into_iter().rev() {
        let loaded = load(&path).and_then(|d| {
            if d.state.step_index == step {
                Ok(d)
            } else {
                Err(CheckpointError::Corrupted {
                    path: path.clone(),
                    reason: Corruption::Malformed(format!(
                        "the file name says step {step} but the contents are at step {}",
                        d.state.step_index
                    )),
                })
            }
        });
        match loaded.and_then(|d| apply(d, &path, world)) {
            Ok(stats) => {
                return Ok(ResumeScan {
                    resumed: Some(Resumed { path, step, stats }),
                    skipped,
                })
            }
            Err(error) if error.is_damage() => skipped.push(Skipped { path, error }),
            Err(error) => return Err(error),
        }
    }
    Ok(ResumeScan {
        resumed: None,
        skipped,
    })
}

/// Deletes the temporary files of checkpoint writes cut short in `dir` (`checkpoint_*.tmp`,
/// left by a run killed while writing one; never read, but each as large as a checkpoint) and
/// the parts whose manifest was never written, returning the paths removed.
pub fn remove_partial_checkpoints(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let partial = name.starts_with("checkpoint_") && name.ends_with(".tmp")
            // A part whose manifest was never written (a job stopped between the two).
            || parts::step_of_part(name).is_some_and(|s| !checkpoint_path(dir, s).exists());
        if partial {
            std::fs::remove_file(&path)?;
            removed.push(path);
        }
    }
    Ok(removed)
}

/// Deletes all but the `keep` newest checkpoint files in `dir` (at least one is always kept),
/// with their parts, returning the paths removed. Only `checkpoint_<step>.bin` files are
/// counted.
pub fn prune_checkpoints(dir: &Path, keep: usize) -> std::io::Result<Vec<PathBuf>> {
    let files = list_checkpoints(dir)?;
    let excess = files.len().saturating_sub(keep.max(1));
    let mut removed = Vec::with_capacity(excess);
    let pruned: Vec<u64> = files.iter().take(excess).map(|(s, _)| *s).collect();
    for (_, path) in files.into_iter().take(excess) {
        std::fs::remove_file(&path)?;
        removed.push(path);
    }
    if !pruned.is_empty() {
        for entry in std::fs::read_dir(dir)? {
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if parts::step_of_part(name).is_some_and(|s| pruned.contains(&s)) {
                std::fs::remove_file(&path)?;
                removed.push(path);
            }
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bodies::BodySet;
    use crate::laws::FrictionTable;
    use crate::world::StepSettings;

    /// A checkpoint written before a setting existed resumes under its default, and only then.
    #[test]
    fn settings_added_later_read_as_their_defaults() {
        let world = World::new(
            BodySet::default(),
            FrictionTable::new(0.5),
            StepSettings::default(),
        );
        let now = Scene::of(&world);
        let mut old = Scene::of(&world);
        for added in [
            ",\"max_push\":null",
            ",\"guard\":false",
            ",\"rotation\":true",
            ",\"overlap_recovery\":0.0",
            ",\"overlap_slop\":0.00025",
        ] {
            assert!(old.settings_json.contains(added), "{}", old.settings_json);
            old.settings_json = old.settings_json.replace(added, "");
        }
        assert_eq!(old.difference(&now), None);
        // And a checkpoint written now (an unlimited `max_push` is `null` in JSON) too.
        assert_eq!(now.difference(&Scene::of(&world)), None);
        assert!(serde_json::from_str::<StepSettings>(&now.settings_json).is_ok());
        assert_eq!(current_settings_json(&now.settings_json), now.settings_json);
        // The scenario turning the new setting on is a difference, named.
        let mut world = world;
        world.settings.correction.guard = true;
        let e = old.difference(&Scene::of(&world)).unwrap();
        assert!(e.contains("correction.guard"), "{e}");
    }
}
