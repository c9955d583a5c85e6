//! `ballast`: run contact-dynamics scenarios and benchmarks.

mod bench;
mod progress;
mod run;

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
        /// Output folder (created); gets summary.json and series.csv.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Stop after this many steps (overrides the scenario).
        #[arg(long)]
        steps: Option<u64>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
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
    },
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
            steps,
            threads,
            quiet,
        } => set_threads(threads).and_then(|t| run::run(&file, &out, steps, t, quiet)),
        Command::Bench {
            json,
            grains,
            settle_steps,
            steps,
            threads,
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
