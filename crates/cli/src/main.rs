//! `ballast`: run contact-dynamics scenarios and benchmarks.

mod bench;
mod progress;
mod report;
mod run;
mod scaling;

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "ballast",
    version,
    about = "Non-Smooth Contact Dynamics of railway ballast"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario file (TOML).
    Run {
        /// Scenario file.
        file: PathBuf,
        /// Output folder (created): summary.json, series.csv, *.pvd + vtk/, checkpoints/.
        #[arg(long, default_value = "out", conflicts_with = "resume")]
        out: PathBuf,
        /// Continue the run in this folder from its newest valid checkpoint, up to --steps.
        #[arg(long)]
        resume: Option<PathBuf>,
        /// Stop after this many steps (overrides the scenario).
        #[arg(long)]
        steps: Option<u64>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Domain decomposition into NXxNYxNZ subdomains (e.g. 1x7x1); overrides the
        /// scenario's [ddm] subdomains, 1x1x1 = monolithic NLGS.
        #[arg(long, value_parser = parse_subdomains)]
        subdomains: Option<[usize; 3]>,
        /// No progress output.
        #[arg(long)]
        quiet: bool,
    },
    /// Benchmark: piles of random grains settling in a box.
    Bench {
        /// Write the results as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Pile sizes (number of grains), comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1000,5000")]
        grains: Vec<usize>,
        /// Steps of settling before measuring.
        #[arg(long, default_value_t = 1500)]
        settle_steps: u64,
        /// Measured steps.
        #[arg(long, default_value_t = 100)]
        steps: u64,
        /// Worker threads (default: 1, the single-thread figure the target is stated for).
        #[arg(long, default_value_t = 1)]
        threads: usize,
        /// Thread-scaling study instead: one settled packing of the first `--grains` size,
        /// monolithic NLGS and DDM for each `--partitions`, on 1, 2 and all threads.
        #[arg(long)]
        scaling: bool,
        /// Scaling study: fixed NLGS sweeps per step (as the paper's 740) instead of the
        /// tolerance-based stop.
        #[arg(long)]
        sweeps: Option<usize>,
        /// Scaling study: settled packing to reuse, written after settling if absent
        /// (`--steps 0` only prepares it).
        #[arg(long)]
        packing: Option<PathBuf>,
        /// Partitions of the scaling study.
        #[arg(long, value_delimiter = ',', value_parser = parse_subdomains, default_value = "2x1x1,2x2x1,4x4x1")]
        partitions: Vec<[usize; 3]>,
    },
}

/// Parses `NXxNYxNZ` (each ≥ 1).
fn parse_subdomains(s: &str) -> Result<[usize; 3], String> {
    let parts: Vec<&str> = s.split(['x', 'X']).collect();
    let bad = || format!("--subdomains {s}: expected NXxNYxNZ with integers ≥ 1, e.g. 1x7x1");
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut out = [0usize; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p.trim().parse().map_err(|_| bad())?;
        if *o == 0 {
            return Err(bad());
        }
    }
    Ok(out)
}

fn set_threads(threads: Option<usize>) -> Result<usize, String> {
    if let Some(n) = threads {
        if n == 0 {
            return Err("--threads = 0: must be ≥ 1".into());
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| format!("cannot set --threads {n}: {e}"))?;
    }
    Ok(rayon::current_num_threads())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run {
            file,
            out,
            resume,
            steps,
            threads,
            subdomains,
            quiet,
        } => set_threads(threads).and_then(|threads| {
            run::run(&run::RunArgs {
                file: &file,
                out: resume.as_deref().unwrap_or(&out),
                resume: resume.is_some(),
                steps,
                threads,
                subdomains,
                quiet,
            })
        }),
        Command::Bench {
            json,
            grains,
            settle_steps,
            steps,
            scaling: true,
            partitions,
            sweeps,
            packing,
            ..
        } => scaling::scaling(&scaling::ScalingArgs {
            json: json.as_deref(),
            grains: grains[0],
            settle_steps,
            steps,
            partitions: &partitions,
            sweeps,
            packing: packing.as_deref(),
        }),
        Command::Bench {
            json,
            grains,
            settle_steps,
            steps,
            threads,
            ..
        } => set_threads(Some(threads))
            .and_then(|t| bench::bench(json.as_deref(), &grains, settle_steps, steps, t)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
