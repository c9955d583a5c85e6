//! `ballast`: run contact-dynamics scenarios and benchmarks.

mod bench;
mod interrupt;
mod paper;
mod progress;
#[cfg(feature = "mpi")]
mod ranks;
mod scaling;

use ballast_run::{Failure, Observer};
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
    /// Run a scenario file (TOML), or a built-in track scenario: with no file, the default
    /// tamping job (one sleeper block, its 4 tines, the paper's 1.764 s cycle).
    Run {
        /// Scenario file (engine scenario, or track scenario with a `[track]` table).
        file: Option<PathBuf>,
        /// Built-in track scenario when no file is given: default, paper.
        #[arg(long, conflicts_with = "file")]
        preset: Option<String>,
        /// Folder of prepared ballast beds, reused by later runs with the same parameters
        /// (default: $BALLAST_CACHE, else ~/.cache/ballast).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Do not read or write prepared beds.
        #[arg(long)]
        no_cache: bool,
        /// Output folder (created): summary.json, series.csv, *.pvd + vtk/, checkpoints/.
        #[arg(long, default_value = "out", conflicts_with = "resume")]
        out: PathBuf,
        /// Continue the run in this folder from its newest valid checkpoint, up to --steps.
        #[arg(long)]
        resume: Option<PathBuf>,
        /// Delete the files of the run already in --out (scenario.toml, summary.json,
        /// series.csv, report.md, *.pvd, vtk/, checkpoints/, plots/, sections/) before
        /// starting; without it such a folder is refused.
        #[arg(long, conflicts_with = "resume")]
        overwrite: bool,
        /// Stop after this many steps (overrides the scenario).
        #[arg(long, value_parser = parse_steps)]
        steps: Option<u64>,
        /// Worker threads (default: all cores; under mpirun, the cores shared by the ranks on
        /// the same machine).
        #[arg(long)]
        threads: Option<usize>,
        /// Domain decomposition into NXxNYxNZ subdomains (e.g. 1x7x1); overrides the
        /// scenario's `[ddm]` subdomains, 1x1x1 = monolithic NLGS.
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
        /// Measured steps (default: 100; 5 with --paper).
        #[arg(long, value_parser = parse_steps)]
        steps: Option<u64>,
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
        /// Scaling study: thread counts to time, comma-separated, e.g. 1,2,4,8,16 (1 is
        /// always timed: speedups are against it; default: 1, 2 and all available threads).
        #[arg(long, value_delimiter = ',', value_parser = parse_thread_count)]
        thread_counts: Vec<usize>,
        /// Scaling study: DDM phases with fewer contacts run on the calling thread (the
        /// scenario key `ddm.min_parallel_contacts`: the value for 2 threads, scaled by
        /// 2/threads; scheduling only, results are unchanged).
        #[arg(long, default_value_t = ballast_engine::MIN_PARALLEL_CONTACTS)]
        min_parallel_contacts: usize,
        /// The paper's computation instead: prepares the paper preset's bed (or reads it from
        /// --cache), then times --steps cycle steps at the paper's 740 fixed sweeps and at the
        /// preset's tolerance stop, on 1 thread and on all threads (--thread-counts).
        #[arg(long, conflicts_with = "scaling")]
        paper: bool,
        /// With --paper: the track scenario benched (a preset name or a scenario file).
        #[arg(long, default_value = "paper", requires = "paper")]
        bed: String,
        /// With --paper: cache folder of prepared beds (default: as `ballast run`).
        #[arg(long, requires = "paper")]
        cache: Option<PathBuf>,
        /// With --paper: no progress messages on stderr.
        #[arg(long)]
        quiet: bool,
        /// Scaling study: detection reuse distance in m (the scenario key
        /// `simulation.reuse_distance`; 0 = every pair detected anew each step).
        #[arg(long, default_value_t = ballast_engine::world::default_reuse_distance(), value_parser = parse_reuse_distance)]
        reuse_distance: f64,
    },
}

/// Parses `--steps`: a whole number written out (`1000`, not `1e3`).
fn parse_steps(s: &str) -> Result<u64, String> {
    s.trim().parse::<u64>().map_err(|_| {
        "expected a whole number of steps ≥ 0 written in digits, e.g. 1000".to_string()
    })
}

/// Parses one `--thread-counts` entry (≥ 1).
fn parse_thread_count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!(
            "--thread-counts {s}: expected whole numbers ≥ 1, e.g. 1,2,4,8,16"
        )),
    }
}

/// Parses `--reuse-distance` (finite, ≥ 0, at most a quarter of the 1 mm alert distance).
fn parse_reuse_distance(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if (0.0..=2.5e-4).contains(&x) => Ok(x),
        _ => Err(format!(
            "--reuse-distance {s}: expected a distance in m between 0 and 2.5e-4 (a quarter of \
             the 1 mm alert distance), e.g. 1e-5"
        )),
    }
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

/// `$BALLAST_CACHE`, else `$XDG_CACHE_HOME/ballast`, else `~/.cache/ballast`.
fn default_cache() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("BALLAST_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("ballast")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("ballast")))
}

/// Most worker threads per core: beyond, threads only wait on each other (and a huge count
/// exhausts the system's threads while the pool starts).
const THREADS_PER_CORE: usize = 4;

fn set_threads(threads: Option<usize>) -> Result<usize, String> {
    if let Some(n) = threads {
        if n == 0 {
            return Err("--threads = 0: must be ≥ 1".into());
        }
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        if n > THREADS_PER_CORE * cores {
            return Err(format!(
                "--threads = {n}: must be at most {} ({THREADS_PER_CORE} × the {cores} cores \
                 of this machine)",
                THREADS_PER_CORE * cores
            ));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| format!("cannot set --threads {n}: {e}"))?;
    }
    Ok(rayon::current_num_threads())
}

/// Runs `job` on a worker thread of the global pool. The steps' parallel loops then start
/// inside the pool, where a worker hands the work to the others directly; from a thread
/// outside it, each loop (a few hundred a step) is queued and that thread sleeps until the
/// loop ends, two context switches a loop. Scheduling only: results are unchanged.
fn on_pool<R: Send>(job: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| job())
}

/// Longest line of an error message (characters): a TOML error quotes the offending line,
/// which may hold a value of megabytes.
const MESSAGE_LINE_CHARS: usize = 1000;

/// `message` with every line cut to [`MESSAGE_LINE_CHARS`] characters, saying how much is cut.
fn cut_lines(message: &str) -> String {
    message
        .lines()
        .map(|l| {
            let n = l.chars().count();
            if n > MESSAGE_LINE_CHARS {
                let head: String = l.chars().take(MESSAGE_LINE_CHARS).collect();
                format!("{head} … ({} more characters)", n - MESSAGE_LINE_CHARS)
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Exit code of a run stopped by the health check (1 is any other error, 2 a command-line
/// error).
const EXIT_DIVERGED: u8 = 3;

/// Exit code of a run stopped by Ctrl-C or SIGTERM after saving its state (128 + SIGINT, the
/// shells' convention).
const EXIT_INTERRUPTED: u8 = 130;

/// `ballast run`'s front end: a progress bar (or plain lines), Ctrl-C and SIGTERM as stop
/// requests once the steps start.
struct Terminal {
    quiet: bool,
    progress: Option<progress::Progress>,
}

impl Observer for Terminal {
    fn start(&mut self, total: u64) {
        self.progress = Some(progress::Progress::new(total, self.quiet));
        interrupt::install();
    }

    fn step(&mut self, done: u64, r: &ballast_engine::world::StepReport) {
        if let Some(p) = &mut self.progress {
            p.update(done, r.time, r.contacts, r.solve.iterations);
        }
    }

    fn finish(&mut self) {
        if let Some(p) = &self.progress {
            p.finish();
        }
    }

    fn stop_requested(&mut self) -> bool {
        interrupt::requested()
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result: Result<(), Failure> = match cli.command {
        Command::Run {
            file,
            preset,
            cache,
            no_cache,
            out,
            resume,
            overwrite,
            steps,
            threads,
            subdomains,
            quiet,
        } => {
            // Launched by `mpirun -np K` (K > 1): this process is one rank of the run, and
            // by default the ranks on one machine share its cores.
            #[cfg(feature = "mpi")]
            let universe = mpi::initialize_with_threading(mpi::Threading::Funneled).map(|(u, _)| u);
            #[cfg(feature = "mpi")]
            let threads = threads.or_else(|| universe.as_ref().and_then(ranks::threads_per_rank));
            set_threads(threads)
                .map_err(Failure::Error)
                .and_then(|threads| {
                    #[cfg(feature = "mpi")]
                    let ranks = universe
                        .as_ref()
                        .map(|u| std::sync::Arc::new(ranks::MpiRanks::new(u)))
                        .filter(|r| ballast_engine::solver::Exchange::size(&**r) > 1);
                    #[cfg(feature = "mpi")]
                    let rank = ranks
                        .as_ref()
                        .map_or(0, |r| ballast_engine::solver::Exchange::rank(&**r));
                    #[cfg(not(feature = "mpi"))]
                    let rank = 0;
                    // Only rank 0 speaks.
                    let quiet = quiet || rank != 0;
                    let mut terminal = Terminal {
                        quiet,
                        progress: None,
                    };
                    let cache = if no_cache {
                        None
                    } else {
                        cache.or_else(default_cache)
                    };
                    let job =
                        |observer: &mut dyn Observer, ranks: Option<&dyn ballast_run::Ranks>| {
                            ballast_run::run(
                                &ballast_run::RunArgs {
                                    file: file.as_deref(),
                                    preset: preset.as_deref(),
                                    cache: cache.clone(),
                                    out: resume.as_deref().unwrap_or(&out),
                                    resume: resume.is_some(),
                                    overwrite,
                                    steps,
                                    threads,
                                    subdomains,
                                    quiet,
                                    ranks,
                                },
                                observer,
                            )
                            .map(|_| ())
                        };
                    // A distributed run stays on the thread that initialised MPI (funneled:
                    // only it may call MPI).
                    #[cfg(feature = "mpi")]
                    let result = match &ranks {
                        Some(r) => {
                            let run_ranks = ranks::RunRanks(r.clone());
                            let mut agreed = ranks::Agreed {
                                inner: &mut terminal,
                                ranks: r,
                            };
                            job(&mut agreed, Some(&run_ranks))
                        }
                        None => on_pool(|| job(&mut terminal, None)),
                    };
                    #[cfg(not(feature = "mpi"))]
                    let result = on_pool(|| job(&mut terminal, None));
                    // A rank that fails alone (a write error on rank 0) ends the whole job: the
                    // others would wait for it forever. A divergence or a stop is every rank's.
                    #[cfg(feature = "mpi")]
                    if let (Err(Failure::Error(e) | Failure::Io(e)), Some(r)) = (&result, &ranks) {
                        eprintln!("error: rank {rank}: {}", cut_lines(e));
                        r.abort(1);
                    }
                    result
                })
        }
        Command::Bench {
            json,
            steps,
            paper: true,
            bed,
            cache,
            thread_counts,
            quiet,
            ..
        } => {
            let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
            let mut counts = if thread_counts.is_empty() {
                vec![1, cores]
            } else {
                thread_counts
            };
            counts.dedup();
            paper::paper(&paper::PaperArgs {
                bed: &bed,
                cache: cache.or_else(default_cache).as_deref(),
                json: json.as_deref(),
                steps: steps.unwrap_or(5),
                thread_counts: &counts,
                quiet,
            })
            .map(|_| ())
            .map_err(Failure::Error)
        }
        Command::Bench {
            json,
            grains,
            settle_steps,
            steps,
            scaling: true,
            partitions,
            sweeps,
            packing,
            thread_counts,
            min_parallel_contacts,
            reuse_distance,
            ..
        } => scaling::scaling(&scaling::ScalingArgs {
            json: json.as_deref(),
            grains: grains[0],
            settle_steps,
            steps: steps.unwrap_or(100),
            partitions: &partitions,
            sweeps,
            packing: packing.as_deref(),
            thread_counts: &thread_counts,
            min_parallel_contacts,
            reuse_distance,
        })
        .map_err(Failure::Error),
        Command::Bench {
            json,
            grains,
            settle_steps,
            steps,
            threads,
            ..
        } => set_threads(Some(threads))
            .and_then(|t| {
                bench::bench(
                    json.as_deref(),
                    &grains,
                    settle_steps,
                    steps.unwrap_or(100),
                    t,
                )
            })
            .map_err(Failure::Error),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Error(e) | Failure::Io(e)) => {
            eprintln!("error: {}", cut_lines(&e));
            ExitCode::FAILURE
        }
        Err(Failure::Diverged(e)) => {
            eprintln!("error: {}", cut_lines(&e));
            ExitCode::from(EXIT_DIVERGED)
        }
        Err(Failure::Interrupted(e)) => {
            eprintln!("{}", cut_lines(&e));
            ExitCode::from(EXIT_INTERRUPTED)
        }
    }
}
