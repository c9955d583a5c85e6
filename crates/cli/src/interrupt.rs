//! Ctrl-C (SIGINT) and SIGTERM during a run's steps: the first one asks the run to stop after
//! the step in progress, with a checkpoint and `"status": "interrupted"`, so that no work is
//! lost; a second one ends the process at once.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_signal(_: libc::c_int) {
    // Only async-signal-safe calls here: an atomic swap and _exit.
    if REQUESTED.swap(true, Ordering::SeqCst) {
        unsafe { libc::_exit(130) };
    }
}

/// From now on, SIGINT and SIGTERM request a stop ([`requested`]) instead of killing the
/// process (installed once the steps start: during a bed's preparation Ctrl-C still stops at
/// once).
pub fn install() {
    #[cfg(unix)]
    unsafe {
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::signal(libc::SIGINT, handler);
        libc::signal(libc::SIGTERM, handler);
    }
}

/// Whether a stop was requested since [`install`].
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}
