//! Engine settings of the track job shared by its scenario ([`crate::scenario`]) and its bed's
//! preparation ([`crate::preparation`]), which both read them here rather than from each
//! other.

use ballast_engine::solver::DdmSettings;

/// Default alert distance of track runs and of their preparation (m). The speculative margins
/// already cover each body's own motion: 0.4 mm rather than 1 mm leaves 16 % fewer contacts
/// (fewer idle ones) with the same overlaps (their 99th and 99.9th percentiles) on the
/// default cycle; see BENCHMARKS.md.
pub(crate) const DEFAULT_ALERT: f64 = 4e-4;

/// The default job's domain decomposition: 2 × 2 contact-balanced boxes (along and across the
/// track), more subdomains than the 2 cores this job is sized for. The split depends on the
/// scene alone, so results are the same on any number of threads.
pub(crate) fn default_ddm() -> DdmSettings {
    DdmSettings {
        subdomains: [2, 2, 1],
        ..DdmSettings::default()
    }
}

/// Normal and tangential stiffness of a contact point in track runs (N/m). Soft enough for
/// NLGS to converge on the tamping cycle at [`DEFAULT_DT`] (stiffer springs: more sweeps per
/// step), stiff enough that the force a step starts from at the overlap cap (`4 k V_m` = 3 kN)
/// carries the force chains under the tines (softer springs let them ratchet deeper each
/// step); the hyperbolic closure ([`DEFAULT_MAX_CLOSURE`]) bounds the deflection.
pub(crate) const DEFAULT_STIFFNESS: f64 = 1e6;

/// Time step of track runs (s): half the paper's, so that the contacts' own vibration at the
/// closure's stiff end is resolved (ω h ≈ 1.8 at the cap with [`DEFAULT_STIFFNESS`] and an
/// 80 g grain); at 2e-4 s the same springs leave ten times more steps unconverged.
pub(crate) const DEFAULT_DT: f64 = 1e-4;

/// Maximum closure of a contact point in track runs (m): no spring deflects more than 0.75 mm,
/// 3 % of the smallest grain of the default grading, whatever it carries.
pub(crate) const DEFAULT_MAX_CLOSURE: f64 = 7.5e-4;
