//! Run outputs: accumulated statistics, `summary.json` and `series.csv`.

pub mod checkpoint;
pub(crate) mod shared;

pub mod vtk;
use crate::timing::PhaseTimes;
use crate::world::{StepReport, World};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

/// Statistics accumulated over the steps of a run.
#[derive(Clone, Debug, Default)]
pub struct RunStats {
    pub steps: u64,
    pub contacts_sum: u64,
    pub contacts_max: usize,
    pub iterations_sum: u64,
    pub max_residual: f64,
    pub not_converged: u64,
    pub max_penetration: f64,
}

impl RunStats {
    /// Adds one step.
    pub fn add(&mut self, r: &StepReport) {
        self.steps += 1;
        self.contacts_sum += r.contacts as u64;
        self.contacts_max = self.contacts_max.max(r.contacts);
        self.iterations_sum += r.solve.iterations as u64;
        self.max_residual = honest_max(self.max_residual, r.solve.residual);
        self.not_converged += u64::from(!r.solve.converged);
        self.max_penetration = honest_max(self.max_penetration, r.max_penetration);
    }

    fn mean(sum: u64, n: u64) -> f64 {
        if n == 0 {
            0.0
        } else {
            sum as f64 / n as f64
        }
    }
}

/// The larger of `a` and `b`, NaN as soon as either is: `f64::max` ignores a NaN, and a
/// diverged step's NaN residual would read as the best one.
fn honest_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// A number for JSON: finite numbers as numbers, NaN and infinities as the strings `"NaN"`,
/// `"inf"` and `"-inf"` (JSON has no such numbers, and `serde_json` would write `null`, which
/// reads as "absent").
pub fn json_number(x: f64) -> serde_json::Value {
    match serde_json::Number::from_f64(x) {
        Some(n) => serde_json::Value::Number(n),
        None if x.is_nan() => "NaN".into(),
        None if x > 0.0 => "inf".into(),
        None => "-inf".into(),
    }
}

/// Serialises an `f64` field as [`json_number`] does.
fn honest_f64<S: serde::Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
    json_number(*x).serialize(s)
}

/// `summary.json`: the contract users' scripts rely on (keys are only ever added).
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub steps: u64,
    #[serde(serialize_with = "honest_f64")]
    pub time: f64,
    pub bodies: usize,
    pub threads: usize,
    /// Processes the run's solves were shared between (MPI ranks; 1: one process).
    pub ranks: usize,
    pub subdomains: String,
    pub timings_s: PhaseTimes,
    pub contacts: ContactSummary,
    pub solver: SolverSummary,
    #[serde(serialize_with = "honest_f64")]
    pub max_penetration: f64,
    #[serde(serialize_with = "honest_f64")]
    pub kinetic_energy: f64,
    pub state_digest: String,
}

/// `summary.json` → `contacts`.
#[derive(Clone, Debug, Serialize)]
pub struct ContactSummary {
    #[serde(serialize_with = "honest_f64")]
    pub mean: f64,
    pub max: usize,
}

/// `summary.json` → `solver`.
#[derive(Clone, Debug, Serialize)]
pub struct SolverSummary {
    #[serde(serialize_with = "honest_f64")]
    pub mean_iterations: f64,
    #[serde(serialize_with = "honest_f64")]
    pub max_residual: f64,
    pub steps_not_converged: u64,
    #[serde(serialize_with = "honest_f64")]
    pub tolerance: f64,
    pub norm: crate::solver::ConvergenceNorm,
}

impl Summary {
    /// Summary of `world` after a run with statistics `stats`. Its kinetic energy and digest
    /// are gathered from the bodies' owners: a collective when the ranks share the bodies
    /// ([`World::gather_body_values`]).
    pub fn new(world: &World, stats: &RunStats, threads: usize) -> Self {
        Summary {
            steps: world.step_index,
            time: world.time,
            bodies: world.bodies.len(),
            threads,
            ranks: world.ranks(),
            subdomains: world
                .settings
                .ddm
                .as_ref()
                .map_or("1x1x1".into(), |d| d.label()),
            timings_s: world.timers,
            contacts: ContactSummary {
                mean: RunStats::mean(stats.contacts_sum, stats.steps),
                max: stats.contacts_max,
            },
            solver: SolverSummary {
                mean_iterations: RunStats::mean(stats.iterations_sum, stats.steps),
                max_residual: stats.max_residual,
                steps_not_converged: stats.not_converged,
                tolerance: world.settings.solver.tolerance,
                norm: world.settings.solver.norm,
            },
            max_penetration: stats.max_penetration,
            kinetic_energy: world.kinetic_energy(),
            state_digest: world.state_digest(),
        }
    }

    /// Writes the summary as pretty JSON, atomically (temporary file, then rename).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        write_atomic(path, text.as_bytes())
    }
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a
/// crash never leaves a half-written file. A write that fails (a full disk) deletes its
/// temporary file, giving back the space it took, and leaves any previous file at `path` as
/// it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// [`write_atomic`] of what `write` writes, in pieces (through a buffer): a large file need
/// not be put together in memory first.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    let written = (|| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        write(&mut f)?;
        let f = f
            .into_inner()
            .map_err(std::io::IntoInnerError::into_error)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// `e` with its message prefixed by `path` (`DIR/vtk/grains_000003.vtu: File too large`), for
/// writers of several files whose caller cannot tell which one failed.
pub fn naming(path: &Path, e: std::io::Error) -> std::io::Error {
    std::io::Error::new(e.kind(), format!("{}: {e}", path.display()))
}

/// Header of `series.csv` (units in brackets).
pub const SERIES_HEADER: &str = "step,time_s,contacts,iterations,quad,residual,converged,max_penetration_m,kinetic_energy_J,t_detection_s,t_nlgs_s,t_other_s";

/// Header of `quality.csv`: a row for every step that missed the solver's tolerance or
/// overlapped by more than a run's report threshold, so that each is named (the body ids of
/// the deepest overlap, empty when nothing overlaps).
pub const QUALITY_HEADER: &str =
    "step,time_s,contacts,iterations,quad,residual,converged,max_penetration_m,body1,body2";

/// The columns `series.csv` and `quality.csv` share: step to largest overlap.
fn step_columns(r: &StepReport) -> String {
    format!(
        "{},{:.9e},{},{},{:.6e},{:.6e},{},{:.6e}",
        r.step,
        r.time,
        r.contacts,
        r.solve.iterations,
        r.solve.quad,
        r.solve.residual,
        u8::from(r.solve.converged),
        r.max_penetration,
    )
}

/// One `quality.csv` row.
pub fn quality_row(r: &StepReport) -> String {
    let columns = step_columns(r);
    if r.max_penetration > 0.0 {
        format!("{columns},{},{}", r.deepest[0], r.deepest[1])
    } else {
        format!("{columns},,")
    }
}

/// One `series.csv` row.
pub fn series_row(r: &StepReport, kinetic_energy: f64) -> String {
    format!(
        "{},{:.9e},{:.6e},{:.6e},{:.6e}",
        step_columns(r),
        kinetic_energy,
        r.times.detection,
        r.times.nlgs,
        r.times.other
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file written in pieces replaces the previous one whole, or not at all: a write that
    /// fails halfway leaves the previous file as it was and no temporary file.
    #[test]
    fn an_atomic_write_in_pieces_is_whole_or_absent() {
        let dir = std::env::temp_dir().join(format!("ballast-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.vtu");
        write_atomic(&path, b"old").unwrap();
        let failed = write_atomic_with(&path, |f| {
            f.write_all(&[7; 100_000])?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert!(!path.with_extension("tmp").exists());
        write_atomic_with(&path, |f| {
            f.write_all(b"new ")?;
            f.write_all(&[b'x'; 100_000])
        })
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!((bytes.len(), &bytes[..4]), (100_004, &b"new "[..]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
