//! # ballast-run
//!
//! A run of ballast as a library call, for every front end (the `ballast` command, the Python
//! package): a scenario stepped to its end while its run folder is written.
//!
//! * [`run()`]: `ballast run` as a call ([`RunArgs`]: scenario file or preset, folder, resume,
//!   steps, cache);
//! * [`Job`]: a built scene ([`Job::build`]) that can be stepped on its own ([`Job::step`]) or
//!   run into a folder ([`Job::run`]);
//! * [`Observer`]: progress, messages and stop requests between steps, supplied by the front
//!   end ([`Plain`]: messages on stderr, no progress, no stop);
//! * [`Failure`]: bad input, a file that cannot be written, a run stopped by the health check,
//!   or an interrupted run (the command's exit codes 1, 1, 3 and 130);
//! * [`report`] and [`charts`]: `report.md` and its figures, drawn with `plotters`.
//!
//! The folder's files (`scenario.toml`, `series.csv`, `summary.json`, `report.md`, `plots/`,
//! `*.pvd` with `vtk/`, `checkpoints/`, and `sections/` for track runs) are described in the
//! repository's README.

pub mod charts;
pub mod report;
mod run;

pub use run::{
    run, ArgNames, BuildOptions, Failure, Job, Observer, Plain, Ranks, RunArgs, RunOptions,
    RunOutcome,
};
