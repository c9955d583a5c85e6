//! Per-phase wall-clock timers of the time step, exposed as data.

use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Seconds spent in each phase (of one step, or cumulated).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseTimes {
    /// Broad and narrow phase, contact rebuild and warm-start matching.
    pub detection: f64,
    /// Local problems and NLGS.
    pub nlgs: f64,
    /// Of `nlgs`: subdomain sweeps (domain decomposition only).
    pub subdomains: f64,
    /// Of `nlgs`: interface sweeps (domain decomposition only).
    pub interface: f64,
    /// Of `detection` and `nlgs`: sharing between the ranks of a distributed run (MPI; 0 in
    /// one process).
    #[serde(default)]
    pub communication: f64,
    /// Free velocities, kinematic drivers, position/orientation update.
    pub other: f64,
    /// Whole step.
    pub total: f64,
}

impl std::ops::AddAssign for PhaseTimes {
    fn add_assign(&mut self, o: Self) {
        self.detection += o.detection;
        self.nlgs += o.nlgs;
        self.subdomains += o.subdomains;
        self.interface += o.interface;
        self.communication += o.communication;
        self.other += o.other;
        self.total += o.total;
    }
}

impl std::ops::Sub for PhaseTimes {
    type Output = PhaseTimes;
    /// Time spent between two cumulated readings.
    fn sub(self, o: Self) -> Self {
        PhaseTimes {
            detection: self.detection - o.detection,
            nlgs: self.nlgs - o.nlgs,
            subdomains: self.subdomains - o.subdomains,
            interface: self.interface - o.interface,
            communication: self.communication - o.communication,
            other: self.other - o.other,
            total: self.total - o.total,
        }
    }
}

/// A running stopwatch returning elapsed seconds since the last lap.
pub(crate) struct Lap(Instant);

impl Lap {
    /// Starts the stopwatch.
    pub fn start() -> Self {
        Lap(Instant::now())
    }
    /// Seconds since start or the previous lap.
    pub(crate) fn lap(&mut self) -> f64 {
        let now = Instant::now();
        let s = (now - self.0).as_secs_f64();
        self.0 = now;
        s
    }
}
