//! `mpirun -np K ballast run …` (the `mpi` feature): the run's ranks over MPI (rsmpi on the
//! system's MPI library). Each rank keeps its own grains up to date and is sent the others it
//! reads; the domain-decomposed solves are shared (`ballast_engine::solver::exchange`), so
//! the run is bit-identical to one process with the same partition.

use ballast_engine::solver::Exchange;
use ballast_run::{Observer, Ranks};
use mpi::collective::SystemOperation;
use mpi::datatype::{Partition, PartitionMut};
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;
use std::sync::Arc;

/// The world communicator of a run launched by `mpirun`.
pub struct MpiRanks {
    world: SimpleCommunicator,
    rank: usize,
    size: usize,
}

// MPI is initialised with `Threading::Funneled` and every call below is made by the thread
// that steps the world (the main thread: the solves call the exchange from it, never from a
// worker), which is what that level allows; the handle is only ever used there.
unsafe impl Send for MpiRanks {}
unsafe impl Sync for MpiRanks {}

impl std::fmt::Debug for MpiRanks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MpiRanks {{ rank: {}, size: {} }}", self.rank, self.size)
    }
}

impl MpiRanks {
    /// The world communicator of the initialised `universe`.
    pub fn new(universe: &mpi::environment::Universe) -> Self {
        let world = universe.world();
        let (rank, size) = (world.rank() as usize, world.size() as usize);
        MpiRanks { world, rank, size }
    }

    /// Whether any rank passes `true` (every rank must call it).
    pub fn any(&self, flag: bool) -> bool {
        let mut all = 0i32;
        self.world
            .all_reduce_into(&i32::from(flag), &mut all, SystemOperation::max());
        all != 0
    }

    /// Ends every rank of the job at once with exit code `code` (a failing rank: waiting for
    /// the others in `MPI_Finalize` would hang).
    pub fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}

impl Exchange for MpiRanks {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn all_gather(&self, mine: &[f64], counts: &[usize], all: &mut [f64]) {
        let (counts, displs) = counts_and_displacements(counts);
        let mut part = PartitionMut::new(all, counts, displs);
        self.world.all_gather_varcount_into(mine, &mut part);
    }

    fn all_to_all(
        &self,
        send: &[f64],
        send_counts: &[usize],
        recv_counts: &[usize],
        recv: &mut [f64],
    ) {
        let (sc, sd) = counts_and_displacements(send_counts);
        let (rc, rd) = counts_and_displacements(recv_counts);
        let send = Partition::new(send, sc, sd);
        let mut recv = PartitionMut::new(recv, rc, rd);
        self.world.all_to_all_varcount_into(&send, &mut recv);
    }

    fn sum_counts(&self, values: &mut [f64]) {
        let mine = values.to_vec();
        self.world
            .all_reduce_into(&mine[..], values, SystemOperation::sum());
    }
}

/// MPI's counts and displacements of parts of `counts` values laid one after another.
fn counts_and_displacements(counts: &[usize]) -> (Vec<i32>, Vec<i32>) {
    let counts: Vec<i32> = counts.iter().map(|&c| c as i32).collect();
    let displs = counts
        .iter()
        .scan(0, |at, &c| {
            let d = *at;
            *at += c;
            Some(d)
        })
        .collect();
    (counts, displs)
}

/// The worker threads a rank takes by default: this machine's cores divided among the ranks
/// running on it (at least 1), so `mpirun -np K` on one machine does not start K pools of all
/// its cores that wait on each other; `None` for one process (all cores). Results do not
/// depend on it.
pub fn threads_per_rank(universe: &mpi::environment::Universe) -> Option<usize> {
    let world = universe.world();
    if world.size() <= 1 {
        return None;
    }
    let local = world.split_shared(world.rank()).size().max(1) as usize;
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    Some((cores / local).max(1))
}

/// [`Ranks`] over an [`MpiRanks`] shared with the world.
pub struct RunRanks(pub Arc<MpiRanks>);

impl Ranks for RunRanks {
    fn exchange(&self) -> Arc<dyn Exchange> {
        self.0.clone()
    }
}

/// A rank's observer: `inner`'s, with the stop decided by all ranks together (a Ctrl-C or
/// SIGTERM seen by any rank stops every rank after the same step).
pub struct Agreed<'a> {
    pub inner: &'a mut dyn Observer,
    pub ranks: &'a MpiRanks,
}

impl Observer for Agreed<'_> {
    fn start(&mut self, total: u64) {
        self.inner.start(total);
    }

    fn step(&mut self, done: u64, r: &ballast_engine::world::StepReport) {
        self.inner.step(done, r);
    }

    fn finish(&mut self) {
        self.inner.finish();
    }

    fn stop_requested(&mut self) -> bool {
        let mine = self.inner.stop_requested();
        self.ranks.any(mine)
    }

    fn message(&mut self, line: &str) {
        self.inner.message(line);
    }
}
