//! ParaView output: one set of VTK XML unstructured grids (`.vtu`) per output frame, gathered by
//! `.pvd` collections that carry the physical times, so ParaView opens a whole run in one click.
//!
//! Layout of an output folder `dir`:
//!
//! ```text
//! dir/grains.pvd    dir/vtk/grains_000000.vtu    dir/vtk/grains_000001.vtu    …
//! dir/bodies.pvd    dir/vtk/bodies_000000.vtu    …
//! dir/contacts.pvd  dir/vtk/contacts_000000.vtu  …
//! ```
//!
//! * `grains`: the dynamic bodies. Each polyhedron is written as its faces (`VTK_POLYGON` cells,
//!   counter-clockwise seen from outside) over its world vertices (shared by the faces of one
//!   body, not across bodies). Cell data, repeated on every face of a body: `id` (body index,
//!   Int32), `group` (Int32), `velocity` and `angular_velocity` (world frame, Float32 × 3).
//! * `bodies`: the other (kinematic and fixed) bodies, written the same way with an extra cell
//!   field `kind` (Int32: 1 kinematic, 2 fixed). A half-space is drawn as one square in its
//!   boundary plane, centred on the projection of the centre of the scene's bounding box, of
//!   side 1.5 × the box diagonal (1 m without polyhedra); it follows the scene from frame to
//!   frame.
//! * `contacts`: one `VTK_VERTEX` cell per contact point, with point data (point data, so that
//!   ParaView's Glyph filter applies directly, Float32 × 3 but `gap`): `normal` (unit, from body 1 toward body 2),
//!   `normal_force` (`r_n n / h`, N), `tangential_force` (`(r_t t + r_s s) / h`, N), both the
//!   mean force of the last step acting on body 2, `status` (Int32: 0 no contact, 1 stick,
//!   2 slide), `body1`, `body2` (Int32) and `gap` (Float64, m). The contacts are those of the
//!   last step, detected at its start, so they lag the body positions by one step.
//!
//! Every `.vtu` also holds the field `TimeValue` (Float64), for files opened on their own.
//!
//! # Parallel pieces
//!
//! A world whose solves are shared between ranks ([`World::ranks`] > 1, see
//! [`crate::solver::exchange`]) writes each frame of `grains` and `contacts` as pieces: rank
//! `R` writes `vtk/grains_NNNNNN_R.vtu` with the grains it owns (those of the subdomains it
//! owns, [`crate::solver::exchange::owner`], in the frame's partition of the scene) and
//! `vtk/contacts_NNNNNN_R.vtu` with the contacts whose first dynamic body it owns; rank 0
//! writes the parallel file `vtk/grains_NNNNNN.pvtu` (`PUnstructuredGrid`) naming the pieces,
//! which the `.pvd` lists, and `bodies` as one `.vtu` (the driven and fixed bodies are known to
//! every rank). Which rank owns a grain depends on the scene alone, and it changes as grains
//! cross from one rank's subdomains to another's. A frame reaches the `.pvd` only once every
//! rank has written its pieces; a rank that cannot write ends the frame with an error on every
//! rank, naming it.
//!
//! Format: `UnstructuredGrid` version 1.0, little-endian, `header_type="UInt64"`, all arrays in
//! one raw (not base64) `<AppendedData>` block, each compressed with zlib
//! (`compressor="vtkZLibDataCompressor"`: VTK's own compressed layout, read by ParaView/VTK and
//! by meshio): per array a header `[blocks, block size, size of the last block, compressed
//! size of each block]` (UInt64), then the blocks, compressed in parallel. Points and the
//! vector fields are Float32 (7 significant digits: a picture gains nothing from more; the
//! gap and the time stay Float64), and the per-face copies of a body's fields compress to
//! almost nothing, so a frame is several times smaller than raw doubles. Connectivity and
//! offsets are Int32 unless a file needs more.

use super::shared::{gather, Owners};
use super::{naming, write_atomic, write_atomic_with};
use crate::bodies::BodyKind;
use crate::laws::ContactStatus;
use crate::math::{DMat3, DVec3};
use crate::shapes::{ConvexPolyhedron, Shape};
use crate::world::World;
use flate2::write::ZlibEncoder;
use flate2::Compression;
use rayon::prelude::*;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Names of the three series, in the order of `VtkWriter::series`.
const SERIES: [&str; 3] = ["grains", "bodies", "contacts"];
/// Sub-folder of the output folder holding the `.vtu` files.
const SUBDIR: &str = "vtk";
const VTK_VERTEX: u8 = 1;
const VTK_POLYGON: u8 = 7;
/// Side of a half-space's square over the scene's bounding-box diagonal.
const PLANE_SIDE_FACTOR: f64 = 1.5;
/// Side of a half-space's square when there is no polyhedron to size it (m).
const PLANE_SIDE_DEFAULT: f64 = 1.0;
/// Uncompressed size of a zlib block: big enough that each block compresses well and that
/// the headers are negligible, small enough that a frame's arrays compress in parallel.
const BLOCK: usize = 1 << 20;

/// One frame of a series: its physical time and its file, relative to the output folder.
#[derive(Clone, Debug, PartialEq)]
struct Frame {
    time: f64,
    file: String,
}

/// Writes ParaView frames (`.vtu`) and keeps the `.pvd` collections of an output folder up to
/// date; see the [module documentation](self) for the files and their fields.
#[derive(Clone, Debug)]
pub struct VtkWriter {
    dir: PathBuf,
    /// Frames written so far, per series (`grains`, `bodies`, `contacts`).
    series: [Vec<Frame>; 3],
    /// Number of the next frame file.
    next: usize,
    /// This writer's rank and the number of ranks writing the frames' pieces (0 and 1: one
    /// process, whole files).
    rank: usize,
    ranks: usize,
}

impl VtkWriter {
    /// A writer starting a new series in `dir`, creating `dir/vtk/` if needed. Existing `.pvd`
    /// files are replaced at the first [`write_frame`](Self::write_frame); use
    /// [`resume`](Self::resume) to continue them.
    pub fn new(dir: &Path) -> io::Result<Self> {
        Self::new_on(dir, 0, 1)
    }

    /// A writer of rank `rank` of `ranks` (see [Parallel pieces](self#parallel-pieces)); one
    /// rank is [`new`](Self::new). Only rank 0 creates `dir/vtk/` here (the other ranks write
    /// into it once rank 0 has reached the frame: a folder it is still claiming stays its own).
    pub fn new_on(dir: &Path, rank: usize, ranks: usize) -> io::Result<Self> {
        if rank >= ranks.max(1) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("VTK writer: rank {rank} of {ranks}"),
            ));
        }
        if rank == 0 {
            let sub = dir.join(SUBDIR);
            std::fs::create_dir_all(&sub).map_err(|e| naming(&sub, e))?;
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            series: Default::default(),
            next: 0,
            rank,
            ranks: ranks.max(1),
        })
    }

    /// Re-opens the output folder `dir` of an interrupted run, keeping the frames of time
    /// `≤ up_to_time` (the time of the state the run resumes from). The `.pvd` files are
    /// rewritten at once without the later frames, whose `.vtu` files are deleted (they belong
    /// to a history the resumed run replaces); new frames are numbered after the kept ones.
    /// A missing `.pvd` counts as an empty series.
    ///
    /// # Errors
    ///
    /// I/O errors, and [`io::ErrorKind::InvalidData`] for a `.pvd` this writer cannot parse;
    /// every error of this writer names its file.
    pub fn resume(dir: &Path, up_to_time: f64) -> io::Result<Self> {
        Self::resume_on(dir, up_to_time, 0, 1)
    }

    /// [`resume`](Self::resume) for rank `rank` of `ranks`: rank 0 rewrites the `.pvd` files
    /// and deletes the later frames (a parallel file with its pieces); the other ranks only
    /// read the collections, to number their next pieces as rank 0 numbers its frames.
    pub fn resume_on(dir: &Path, up_to_time: f64, rank: usize, ranks: usize) -> io::Result<Self> {
        let mut writer = Self::new_on(dir, rank, ranks)?;
        for (k, name) in SERIES.iter().enumerate() {
            let mut frames = read_pvd(&writer.pvd_path(name))?;
            let keep = frames.iter().take_while(|f| f.time <= up_to_time).count();
            for dropped in frames.drain(keep..) {
                if rank == 0 {
                    remove_frame_file(dir, &dropped.file)?;
                }
            }
            writer.series[k] = frames;
        }
        writer.next = next_number(&writer.series);
        if rank == 0 {
            for (k, name) in SERIES.iter().enumerate() {
                writer.write_pvd(k, name)?;
            }
        }
        Ok(writer)
    }

    /// Writes `vtk/grains_NNNNNN.vtu`, `vtk/bodies_NNNNNN.vtu` and `vtk/contacts_NNNNNN.vtu`
    /// for the current state of `world`, then rewrites `grains.pvd`, `bodies.pvd` and
    /// `contacts.pvd` (atomically: temporary file, then rename) listing every frame written so
    /// far with its physical time. A frame at the same time as the previous one replaces it,
    /// so the collection times stay strictly increasing.
    pub fn write_frame(&mut self, world: &World) -> io::Result<()> {
        if world.ranks() != self.ranks {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "VTK writer of {} rank(s) given a world shared between {}",
                    self.ranks,
                    world.ranks()
                ),
            ));
        }
        if self.ranks > 1 {
            return self.write_pieces(world);
        }
        let time = world.time;
        let scene = scene_box(world);
        let mut appended = false;
        for (k, name) in SERIES.iter().enumerate() {
            let (file, new) = match self.series[k].last() {
                Some(last) if last.time == time => (last.file.clone(), false),
                _ => (format!("{SUBDIR}/{name}_{:06}.vtu", self.next), true),
            };
            let path = self.dir.join(&file);
            match k {
                0 => write_bodies(&path, world, false, &|_| true, scene),
                1 => write_bodies(&path, world, true, &|_| true, scene),
                _ => write_contacts(&path, world, &|_| true),
            }
            .map_err(|e| naming(&path, e))?;
            // Listed only once written, so a failed write never reaches a `.pvd`.
            if new {
                self.series[k].push(Frame { time, file });
                appended = true;
            }
        }
        if appended {
            self.next += 1;
        }
        for (k, name) in SERIES.iter().enumerate() {
            self.write_pvd(k, name)?;
        }
        Ok(())
    }

    /// [`write_frame`](Self::write_frame) over ranks: every rank writes its pieces, rank 0
    /// the bodies, the parallel files and the collections once all pieces are written.
    fn write_pieces(&mut self, world: &World) -> io::Result<()> {
        let time = world.time;
        // Every rank at this frame before any writes: rank 0 has claimed the folder.
        agree(world, true);
        let owners = Owners::of(world, self.ranks);
        let scene = scene_box(world);
        let rank = self.rank;
        let mut files = Vec::with_capacity(SERIES.len());
        let mut mine: io::Result<Vec<PArray>> = Ok(Vec::new());
        let mut declared = [Vec::new(), Vec::new(), Vec::new()];
        for (k, name) in SERIES.iter().enumerate() {
            let (file, new) = match self.series[k].last() {
                Some(last) if last.time == time => (last.file.clone(), false),
                _ if k == 1 => (format!("{SUBDIR}/{name}_{:06}.vtu", self.next), true),
                _ => (format!("{SUBDIR}/{name}_{:06}.pvtu", self.next), true),
            };
            if mine.is_ok() {
                let written = match k {
                    1 if rank == 0 => {
                        let path = self.dir.join(&file);
                        write_bodies(&path, world, true, &|_| true, scene)
                            .map_err(|e| naming(&path, e))
                    }
                    1 => Ok(Vec::new()),
                    _ => {
                        let path = self.dir.join(piece_file(&file, rank));
                        if k == 0 {
                            let mine = |i: usize| owners.body[i] == rank;
                            write_bodies(&path, world, false, &mine, scene)
                        } else {
                            write_contacts(&path, world, &|c| world.holds_contact(c))
                        }
                        .map_err(|e| naming(&path, e))
                    }
                };
                match written {
                    Ok(arrays) => declared[k] = arrays,
                    Err(e) => mine = Err(e),
                }
            }
            files.push((file, new));
        }
        let failed: Vec<usize> = agree(world, mine.is_ok())
            .iter()
            .enumerate()
            .filter(|(_, &ok)| !ok)
            .map(|(r, _)| r)
            .collect();
        mine?;
        if !failed.is_empty() {
            return Err(io::Error::other(format!(
                "frame at t = {time} s: rank(s) {failed:?} could not write their pieces"
            )));
        }
        let mut appended = false;
        for (k, (file, new)) in files.into_iter().enumerate() {
            if rank == 0 && k != 1 {
                let path = self.dir.join(&file);
                write_pvtu(&path, &declared[k], self.ranks).map_err(|e| naming(&path, e))?;
            }
            if new {
                self.series[k].push(Frame { time, file });
                appended = true;
            }
        }
        if appended {
            self.next += 1;
        }
        if rank == 0 {
            for (k, name) in SERIES.iter().enumerate() {
                self.write_pvd(k, name)?;
            }
        }
        Ok(())
    }

    fn pvd_path(&self, name: &str) -> PathBuf {
        self.dir.join(format!("{name}.pvd"))
    }

    fn write_pvd(&self, k: usize, name: &str) -> io::Result<()> {
        let mut text = String::from(
            "<?xml version=\"1.0\"?>\n\
             <VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  \
             <Collection>\n",
        );
        for f in &self.series[k] {
            // `{:?}` prints the shortest string that parses back to the same f64.
            text += &format!(
                "    <DataSet timestep=\"{:?}\" group=\"\" part=\"0\" file=\"{}\"/>\n",
                f.time, f.file
            );
        }
        text += "  </Collection>\n</VTKFile>\n";
        let path = self.pvd_path(name);
        write_atomic(&path, text.as_bytes()).map_err(|e| naming(&path, e))
    }
}

/// Frames listed in a `.pvd` written by [`VtkWriter`], in file order; empty if it is missing.
fn read_pvd(path: &Path) -> io::Result<Vec<Frame>> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(naming(path, e)),
    };
    let bad = |what: &str| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{}: {what}", path.display()),
        )
    };
    let mut frames = Vec::new();
    for chunk in text.split("<DataSet").skip(1) {
        let tag = &chunk[..chunk.find('>').ok_or_else(|| bad("unterminated DataSet"))?];
        let time = attribute(tag, "timestep")
            .and_then(|t| t.parse::<f64>().ok())
            .ok_or_else(|| bad("DataSet without a numeric timestep"))?;
        let file = attribute(tag, "file").ok_or_else(|| bad("DataSet without a file"))?;
        frames.push(Frame {
            time,
            file: file.to_string(),
        });
    }
    Ok(frames)
}

/// Value of the attribute `name="…"` in the inside of an XML tag.
fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let len = tag[start..].find('"')?;
    Some(&tag[start..start + len])
}

/// `N` of `vtk/<series>_N.vtu` or `vtk/<series>_N.pvtu`.
fn frame_number(file: &str) -> Option<usize> {
    let stem = file
        .strip_suffix(".pvtu")
        .or_else(|| file.strip_suffix(".vtu"))?;
    stem[stem.rfind('_')? + 1..].parse().ok()
}

/// The number of the next frame: after the highest kept number, so no kept file is ever
/// overwritten.
fn next_number(series: &[Vec<Frame>; 3]) -> usize {
    series
        .iter()
        .flatten()
        .map(|f| frame_number(&f.file).map_or(0, |n| n + 1))
        .chain(series.iter().map(Vec::len))
        .max()
        .unwrap_or(0)
}

/// Rank `rank`'s piece of the parallel file `vtk/<series>_N.pvtu`: `vtk/<series>_N_<rank>.vtu`.
fn piece_file(file: &str, rank: usize) -> String {
    format!("{}_{rank}.vtu", file.strip_suffix(".pvtu").unwrap_or(file))
}

/// Whether `file` (relative to the output folder) is one this writer names: in `vtk/`, a
/// `.vtu` or `.pvtu`, never a path leaving the folder.
fn is_own_file(file: &str) -> bool {
    file.starts_with("vtk/")
        && (file.ends_with(".vtu") || file.ends_with(".pvtu"))
        && !file.contains("..")
}

/// Deletes a dropped frame's file, and the pieces a parallel file names.
fn remove_frame_file(dir: &Path, file: &str) -> io::Result<()> {
    if !is_own_file(file) {
        return Ok(());
    }
    let mut doomed = Vec::new();
    if file.ends_with(".pvtu") {
        if let Ok(text) = std::fs::read_to_string(dir.join(file)) {
            for chunk in text.split("<Piece").skip(1) {
                let tag = &chunk[..chunk.find('>').unwrap_or(chunk.len())];
                if let Some(source) = attribute(tag, "Source") {
                    let piece = format!("{SUBDIR}/{source}");
                    if is_own_file(&piece) && !source.contains('/') {
                        doomed.push(piece);
                    }
                }
            }
        }
    }
    doomed.push(file.to_string());
    for f in doomed {
        match std::fs::remove_file(dir.join(&f)) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(naming(&dir.join(&f), e)),
            _ => {}
        }
    }
    Ok(())
}

/// Every rank's `ok`, gathered in rank order (a collective: every rank calls it at the same
/// point of a frame).
fn agree(world: &World, ok: bool) -> Vec<bool> {
    gather(world, &[f64::from(u8::from(ok))])
        .into_iter()
        .map(|x| x == 1.0)
        .collect()
}

/// An array as a parallel file declares it.
#[derive(Clone, Debug)]
struct PArray {
    section: Section,
    name: &'static str,
    ty: Type,
    components: usize,
}

/// Writes a `PUnstructuredGrid` naming the pieces `<stem>_0.vtu` … `<stem>_{ranks−1}.vtu`
/// next to it, with the point and cell arrays every piece holds.
fn write_pvtu(path: &Path, arrays: &[PArray], ranks: usize) -> io::Result<()> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| io::Error::other("parallel file without a name"))?;
    let section = |s: Section, open: &str, close: &str| {
        let mut x = format!("    <{open}>\n");
        for a in arrays.iter().filter(|a| a.section == s) {
            let components = if a.components > 1 {
                format!(" NumberOfComponents=\"{}\"", a.components)
            } else {
                String::new()
            };
            x += &format!(
                "      <PDataArray type=\"{}\" Name=\"{}\"{components}/>\n",
                a.ty.name(),
                a.name
            );
        }
        x + "    </" + close + ">\n"
    };
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  \
         <PUnstructuredGrid GhostLevel=\"0\">\n",
    );
    xml += &section(Section::Point, "PPointData", "PPointData");
    xml += &section(Section::Cell, "PCellData", "PCellData");
    xml += &section(Section::Points, "PPoints", "PPoints");
    for r in 0..ranks {
        xml += &format!("    <Piece Source=\"{}\"/>\n", piece_file(name, r));
    }
    xml += "  </PUnstructuredGrid>\n</VTKFile>\n";
    write_atomic(path, xml.as_bytes())
}

/// One body's surface in world coordinates.
enum Surface<'a> {
    Polyhedron {
        shape: &'a ConvexPolyhedron,
        rotation: DMat3,
        position: DVec3,
    },
    /// A finite square standing for a half-space, counter-clockwise seen from outside.
    Square([DVec3; 4]),
}

impl Surface<'_> {
    fn num_points(&self) -> usize {
        match self {
            Surface::Polyhedron { shape, .. } => shape.vertices.len(),
            Surface::Square(_) => 4,
        }
    }

    fn num_faces(&self) -> usize {
        match self {
            Surface::Polyhedron { shape, .. } => shape.num_faces(),
            Surface::Square(_) => 1,
        }
    }

    fn num_face_vertices(&self) -> usize {
        match self {
            Surface::Polyhedron { shape, .. } => shape.face_vertices.len(),
            Surface::Square(_) => 4,
        }
    }
}

/// Centre and diagonal of the bounding box of the polyhedra (their bounding spheres), if any:
/// the frame the planes are drawn in. On ranks that share the bodies, each rank bounds the
/// bodies it answers for and the boxes are combined: a collective.
fn scene_box(world: &World) -> Option<(DVec3, f64)> {
    let b = &world.bodies;
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for i in (0..b.len()).filter(|&i| world.answers_for(i)) {
        if let Shape::Polyhedron(poly) = &b.shape[i] {
            lo = lo.min(b.position[i] - DVec3::splat(poly.radius));
            hi = hi.max(b.position[i] + DVec3::splat(poly.radius));
        }
    }
    if world.shares_bodies() {
        for r in gather(world, &[lo.x, lo.y, lo.z, hi.x, hi.y, hi.z]).chunks_exact(6) {
            lo = lo.min(DVec3::new(r[0], r[1], r[2]));
            hi = hi.max(DVec3::new(r[3], r[4], r[5]));
        }
    }
    (lo.x <= hi.x).then(|| ((lo + hi) * 0.5, (hi - lo).length()))
}

/// Surfaces of the dynamic bodies (`others == false`) or of the other bodies, those `keep`
/// takes, with their index.
fn surfaces<'w>(
    world: &'w World,
    others: bool,
    keep: &dyn Fn(usize) -> bool,
    scene: Option<(DVec3, f64)>,
) -> Vec<(usize, Surface<'w>)> {
    let b = &world.bodies;
    (0..b.len())
        .filter(|&i| (b.kind[i] != BodyKind::Dynamic) == others && keep(i))
        .map(|i| {
            let q = b.orientation[i];
            let surface = match &b.shape[i] {
                Shape::Polyhedron(shape) => Surface::Polyhedron {
                    shape,
                    rotation: DMat3::from_quat(q),
                    position: b.position[i],
                },
                Shape::Plane { normal } => {
                    let n = (q * *normal).normalize();
                    let origin = b.position[i];
                    let (centre, side) = match scene {
                        Some((c, diagonal)) => (c, PLANE_SIDE_FACTOR * diagonal),
                        None => (origin, PLANE_SIDE_DEFAULT),
                    };
                    let c = centre - n * n.dot(centre - origin);
                    let (mut t, mut s) = n.any_orthonormal_pair();
                    if t.cross(s).dot(n) < 0.0 {
                        std::mem::swap(&mut t, &mut s);
                    }
                    let (t, s) = (t * 0.5 * side, s * 0.5 * side);
                    Surface::Square([c - t - s, c + t - s, c + t + s, c - t + s])
                }
            };
            (i, surface)
        })
        .collect()
}

/// Calls `f(body)` once per face of every body, in file order: per-body values as cell data.
fn per_face(
    parts: &[(usize, Surface)],
    mut f: impl FnMut(usize) -> io::Result<()>,
) -> io::Result<()> {
    for (i, s) in parts {
        for _ in 0..s.num_faces() {
            f(*i)?;
        }
    }
    Ok(())
}

/// Writes the grains file (`others == false`) or the other bodies' file, with the bodies
/// `keep` takes; returns the arrays as a parallel file declares them.
fn write_bodies(
    path: &Path,
    world: &World,
    others: bool,
    keep: &dyn Fn(usize) -> bool,
    scene: Option<(DVec3, f64)>,
) -> io::Result<Vec<PArray>> {
    let b = &world.bodies;
    let parts = surfaces(world, others, keep, scene);
    let parts = &parts;
    let num_points: usize = parts.iter().map(|(_, s)| s.num_points()).sum();
    let num_cells: usize = parts.iter().map(|(_, s)| s.num_faces()).sum();
    let num_conn: usize = parts.iter().map(|(_, s)| s.num_face_vertices()).sum();
    let index = IndexType::for_sizes(num_points.max(num_conn));

    let mut arrays = vec![
        Array::field_time(world.time),
        Array::new(Section::Cell, "id", Type::I32, 1, num_cells, move |o| {
            per_face(parts, |i| o.i32(i as i32))
        }),
        Array::new(Section::Cell, "group", Type::I32, 1, num_cells, move |o| {
            per_face(parts, |i| o.i32(b.group[i] as i32))
        }),
        Array::new(
            Section::Cell,
            "velocity",
            Type::F32,
            3,
            num_cells,
            move |o| per_face(parts, |i| o.vec3_f32(b.velocity[i])),
        ),
        Array::new(
            Section::Cell,
            "angular_velocity",
            Type::F32,
            3,
            num_cells,
            move |o| per_face(parts, |i| o.vec3_f32(b.angular_velocity[i])),
        ),
    ];
    if others {
        arrays.push(Array::new(
            Section::Cell,
            "kind",
            Type::I32,
            1,
            num_cells,
            move |o| {
                per_face(parts, |i| {
                    o.i32(match b.kind[i] {
                        BodyKind::Dynamic => 0,
                        BodyKind::Kinematic => 1,
                        BodyKind::Fixed => 2,
                    })
                })
            },
        ));
    }
    arrays.push(Array::new(
        Section::Points,
        "Points",
        Type::F32,
        3,
        num_points,
        move |o| {
            for (_, s) in parts {
                match s {
                    Surface::Polyhedron {
                        shape,
                        rotation,
                        position,
                    } => {
                        for &v in &shape.vertices {
                            o.vec3_f32(*position + *rotation * v)?;
                        }
                    }
                    Surface::Square(corners) => {
                        for &c in corners {
                            o.vec3_f32(c)?;
                        }
                    }
                }
            }
            Ok(())
        },
    ));
    arrays.push(Array::new(
        Section::Cells,
        "connectivity",
        index.ty(),
        1,
        num_conn,
        move |o| {
            let mut base = 0;
            for (_, s) in parts {
                match s {
                    Surface::Polyhedron { shape, .. } => {
                        for &v in &shape.face_vertices {
                            o.index(index, base + v as usize)?;
                        }
                    }
                    Surface::Square(_) => {
                        for v in 0..4 {
                            o.index(index, base + v)?;
                        }
                    }
                }
                base += s.num_points();
            }
            Ok(())
        },
    ));
    arrays.push(Array::new(
        Section::Cells,
        "offsets",
        index.ty(),
        1,
        num_cells,
        move |o| {
            let mut end = 0;
            for (_, s) in parts {
                match s {
                    Surface::Polyhedron { shape, .. } => {
                        for f in 0..shape.num_faces() {
                            end += shape.face(f).len();
                            o.index(index, end)?;
                        }
                    }
                    Surface::Square(_) => {
                        end += 4;
                        o.index(index, end)?;
                    }
                }
            }
            Ok(())
        },
    ));
    arrays.push(Array::cell_types(num_cells, VTK_POLYGON));
    write_vtu(path, num_points, num_cells, &arrays)
}

/// Writes the contacts file with the contacts `keep` takes; returns the arrays as a parallel
/// file declares them.
fn write_contacts(
    path: &Path,
    world: &World,
    keep: &dyn Fn(usize) -> bool,
) -> io::Result<Vec<PArray>> {
    let c = &world.contacts;
    let kept: Vec<usize> = (0..c.len()).filter(|&k| keep(k)).collect();
    let kept = &kept;
    let n = kept.len();
    let inv_h = 1.0 / world.settings.dt;
    let index = IndexType::for_sizes(n);
    let arrays = vec![
        Array::field_time(world.time),
        Array::new(Section::Point, "normal", Type::F32, 3, n, move |o| {
            kept.iter().try_for_each(|&k| o.vec3_f32(c.frame[k][0]))
        }),
        Array::new(Section::Point, "normal_force", Type::F32, 3, n, move |o| {
            kept.iter()
                .try_for_each(|&k| o.vec3_f32(c.frame[k][0] * (c.impulse[k].x * inv_h)))
        }),
        Array::new(
            Section::Point,
            "tangential_force",
            Type::F32,
            3,
            n,
            move |o| {
                kept.iter().try_for_each(|&k| {
                    let [_, t, s] = c.frame[k];
                    let r = c.impulse[k];
                    o.vec3_f32((t * r.y + s * r.z) * inv_h)
                })
            },
        ),
        Array::new(Section::Point, "status", Type::I32, 1, n, move |o| {
            kept.iter().try_for_each(|&k| {
                o.i32(match c.status[k] {
                    ContactStatus::NoContact => 0,
                    ContactStatus::Stick => 1,
                    ContactStatus::Slide => 2,
                })
            })
        }),
        Array::new(Section::Point, "body1", Type::I32, 1, n, move |o| {
            kept.iter().try_for_each(|&k| o.i32(c.body1[k] as i32))
        }),
        Array::new(Section::Point, "body2", Type::I32, 1, n, move |o| {
            kept.iter().try_for_each(|&k| o.i32(c.body2[k] as i32))
        }),
        Array::new(Section::Point, "gap", Type::F64, 1, n, move |o| {
            kept.iter().try_for_each(|&k| o.f64(c.gap[k]))
        }),
        Array::new(Section::Points, "Points", Type::F32, 3, n, move |o| {
            kept.iter().try_for_each(|&k| o.vec3_f32(c.point[k]))
        }),
        Array::new(Section::Cells, "connectivity", index.ty(), 1, n, move |o| {
            (0..n).try_for_each(|k| o.index(index, k))
        }),
        Array::new(Section::Cells, "offsets", index.ty(), 1, n, move |o| {
            (1..=n).try_for_each(|k| o.index(index, k))
        }),
        Array::cell_types(n, VTK_VERTEX),
    ];
    write_vtu(path, n, n, &arrays)
}

/// VTK scalar types used here.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Type {
    U8,
    I32,
    I64,
    F32,
    F64,
}

impl Type {
    fn name(self) -> &'static str {
        match self {
            Type::U8 => "UInt8",
            Type::I32 => "Int32",
            Type::I64 => "Int64",
            Type::F32 => "Float32",
            Type::F64 => "Float64",
        }
    }

    fn size(self) -> u64 {
        match self {
            Type::U8 => 1,
            Type::I32 | Type::F32 => 4,
            Type::F64 | Type::I64 => 8,
        }
    }
}

/// Integer type of connectivity and offsets: Int32 while every value fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum IndexType {
    I32,
    I64,
}

impl IndexType {
    fn for_sizes(largest: usize) -> Self {
        if largest <= i32::MAX as usize {
            IndexType::I32
        } else {
            IndexType::I64
        }
    }

    fn ty(self) -> Type {
        match self {
            IndexType::I32 => Type::I32,
            IndexType::I64 => Type::I64,
        }
    }
}

/// Where an array goes in the XML.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Section {
    Field,
    Point,
    Cell,
    Points,
    Cells,
}

/// Fills an array's bytes into the file.
type Fill<'a> = Box<dyn Fn(&mut Sink) -> io::Result<()> + 'a>;

/// One data array: where it goes, its layout, and how to produce its bytes.
struct Array<'a> {
    section: Section,
    name: &'static str,
    ty: Type,
    components: usize,
    tuples: usize,
    fill: Fill<'a>,
}

impl<'a> Array<'a> {
    fn new(
        section: Section,
        name: &'static str,
        ty: Type,
        components: usize,
        tuples: usize,
        fill: impl Fn(&mut Sink) -> io::Result<()> + 'a,
    ) -> Self {
        Self {
            section,
            name,
            ty,
            components,
            tuples,
            fill: Box::new(fill),
        }
    }

    /// The `TimeValue` field ParaView reads from a single file.
    fn field_time(time: f64) -> Self {
        Self::new(Section::Field, "TimeValue", Type::F64, 1, 1, move |o| {
            o.f64(time)
        })
    }

    /// `count` cells of one VTK type.
    fn cell_types(count: usize, cell_type: u8) -> Self {
        Self::new(Section::Cells, "types", Type::U8, 1, count, move |o| {
            let chunk = [cell_type; 4096];
            let mut left = count;
            while left > 0 {
                let k = left.min(chunk.len());
                o.bytes(&chunk[..k])?;
                left -= k;
            }
            Ok(())
        })
    }

    fn num_bytes(&self) -> u64 {
        (self.tuples * self.components) as u64 * self.ty.size()
    }
}

/// Little-endian bytes of one array, gathered before compression.
struct Sink {
    out: Vec<u8>,
}

impl Sink {
    #[inline]
    fn bytes(&mut self, b: &[u8]) -> io::Result<()> {
        self.out.extend_from_slice(b);
        Ok(())
    }

    #[inline]
    fn f64(&mut self, x: f64) -> io::Result<()> {
        self.bytes(&x.to_le_bytes())
    }

    #[inline]
    fn i32(&mut self, x: i32) -> io::Result<()> {
        self.bytes(&x.to_le_bytes())
    }

    #[inline]
    fn vec3_f32(&mut self, v: DVec3) -> io::Result<()> {
        let mut b = [0u8; 12];
        b[..4].copy_from_slice(&(v.x as f32).to_le_bytes());
        b[4..8].copy_from_slice(&(v.y as f32).to_le_bytes());
        b[8..].copy_from_slice(&(v.z as f32).to_le_bytes());
        self.bytes(&b)
    }

    #[inline]
    fn index(&mut self, ty: IndexType, x: usize) -> io::Result<()> {
        match ty {
            IndexType::I32 => self.i32(x as i32),
            IndexType::I64 => self.bytes(&(x as i64).to_le_bytes()),
        }
    }
}

/// `data` in VTK's zlib layout: the UInt64 header `[blocks, BLOCK, size of the last block if
/// partial (else 0), compressed size of each block]`, then the compressed blocks. Blocks are
/// compressed independently (in parallel), so the bytes do not depend on the thread count.
fn compress(data: &[u8]) -> io::Result<Vec<u8>> {
    let blocks: Vec<Vec<u8>> = data
        .par_chunks(BLOCK)
        .map(|chunk| {
            let mut z = ZlibEncoder::new(Vec::with_capacity(chunk.len() / 4), Compression::fast());
            z.write_all(chunk)?;
            z.finish()
        })
        .collect::<io::Result<_>>()?;
    let last = data.len() % BLOCK;
    let mut out =
        Vec::with_capacity(8 * (3 + blocks.len()) + blocks.iter().map(Vec::len).sum::<usize>());
    for x in [blocks.len(), BLOCK, last] {
        out.extend_from_slice(&(x as u64).to_le_bytes());
    }
    for b in &blocks {
        out.extend_from_slice(&(b.len() as u64).to_le_bytes());
    }
    for b in &blocks {
        out.extend_from_slice(b);
    }
    Ok(out)
}

/// Writes an `UnstructuredGrid` with every array in one appended block, each compressed (see
/// [`compress`]): the arrays are filled and compressed first, so the XML header can give
/// their offsets; the file is then written atomically (temporary file, then rename).
fn write_vtu(
    path: &Path,
    num_points: usize,
    num_cells: usize,
    arrays: &[Array],
) -> io::Result<Vec<PArray>> {
    let mut packed = Vec::with_capacity(arrays.len());
    for a in arrays {
        let expected = a.num_bytes();
        let mut sink = Sink {
            out: Vec::with_capacity(expected as usize),
        };
        (a.fill)(&mut sink)?;
        // A size mismatch would make the file unreadable: fail rather than write garbage.
        if sink.out.len() as u64 != expected {
            return Err(io::Error::other(format!(
                "{}: array {} has {} bytes, {expected} declared",
                path.display(),
                a.name,
                sink.out.len()
            )));
        }
        packed.push(compress(&sink.out)?);
    }
    let mut offsets = Vec::with_capacity(arrays.len());
    let mut offset = 0u64;
    for p in &packed {
        offsets.push(offset);
        offset += p.len() as u64;
    }
    let tag = |a: &Array, offset: u64| {
        let components = if a.section == Section::Field {
            " NumberOfTuples=\"1\"".to_string()
        } else if a.components > 1 {
            format!(" NumberOfComponents=\"{}\"", a.components)
        } else {
            String::new()
        };
        format!(
            "<DataArray type=\"{}\" Name=\"{}\"{components} format=\"appended\" offset=\"{offset}\"/>\n",
            a.ty.name(),
            a.name
        )
    };
    let section = |s: Section, open: &str, close: &str, indent: &str| {
        let mut x = format!("{indent}{open}\n");
        for (a, &o) in arrays.iter().zip(&offsets) {
            if a.section == s {
                x += &format!("{indent}  {}", tag(a, o));
            }
        }
        x + indent + close + "\n"
    };
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\" \
         compressor=\"vtkZLibDataCompressor\">\n  <UnstructuredGrid>\n",
    );
    xml += &section(Section::Field, "<FieldData>", "</FieldData>", "    ");
    xml += &format!("    <Piece NumberOfPoints=\"{num_points}\" NumberOfCells=\"{num_cells}\">\n");
    xml += &section(Section::Point, "<PointData>", "</PointData>", "      ");
    xml += &section(Section::Cell, "<CellData>", "</CellData>", "      ");
    xml += &section(Section::Points, "<Points>", "</Points>", "      ");
    xml += &section(Section::Cells, "<Cells>", "</Cells>", "      ");
    xml += "    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _";

    // Written piece by piece: the compressed arrays are not copied into one buffer first.
    write_atomic_with(path, |f| {
        f.write_all(xml.as_bytes())?;
        for p in &packed {
            f.write_all(p)?;
        }
        f.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
    })?;
    Ok(arrays
        .iter()
        .filter(|a| matches!(a.section, Section::Point | Section::Cell | Section::Points))
        .map(|a| PArray {
            section: a.section,
            name: a.name,
            ty: a.ty,
            components: a.components,
        })
        .collect())
}
