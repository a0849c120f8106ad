//! Ctrl-C, SIGTERM and SIGHUP, from the first line of `main` to the last.
//!
//! Before a render's passes start (loading, building, benchmarks, checks) there is no
//! work to keep, so a signal ends the process at once with status 130. While a render
//! runs, the first signal asks it to stop after the pass in flight (it then saves its
//! checkpoint and image); a second one ends the process at once. Either way, the
//! temporary files of writes in flight are removed first, so nothing half-written is
//! ever left behind.

use std::sync::atomic::{AtomicU8, Ordering};

/// No render running: a signal ends the process.
const PREPARING: u8 = 0;
/// A render is running: the first signal asks it to stop.
const RENDERING: u8 = 1;
/// A stop was asked for: the next signal ends the process.
const STOPPING: u8 = 2;

static STATE: AtomicU8 = AtomicU8::new(PREPARING);

/// Installs the handler; without it (another one is installed) a signal just ends the
/// process.
pub fn install() {
    let _ = ctrlc::set_handler(|| {
        let previous = STATE
            .compare_exchange(RENDERING, STOPPING, Ordering::SeqCst, Ordering::SeqCst)
            .unwrap_or_else(|state| state);
        if previous != RENDERING {
            end_now();
        }
        // Said, so that a user (or a test) knows the first signal was received: two
        // signals sent at once arrive as one.
        eprintln!("\nstopping after the pass in flight; a second signal stops at once, keeping nothing more");
    });
}

/// Removes the temporary files of writes in flight and exits with status 130.
fn end_now() -> ! {
    canopy_render::output::abandon_temporary_files();
    std::process::exit(crate::EXIT_INTERRUPTED);
}

/// From now on, the first signal asks the render to stop rather than ending the process.
pub fn render_started() {
    let _ = STATE.compare_exchange(PREPARING, RENDERING, Ordering::SeqCst, Ordering::SeqCst);
}

/// Whether a signal has asked the render to stop.
pub fn stop_requested() -> bool {
    STATE.load(Ordering::SeqCst) == STOPPING
}
