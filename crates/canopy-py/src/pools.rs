//! Thread pools by size: `threads=None` is rayon's global pool (all cores), shared by
//! every caller; `threads=n` a pool of exactly n workers that belongs to the calling
//! thread, so two Python threads asking for one worker each trace side by side.
//!
//! Each Python thread keeps one pool, of the size it asked for last: a loop over sizes
//! (`threads=1`, `2`, … `128`) never holds more than one pool's workers at a time, and a
//! Python thread's pool ends with it.

use pyo3::exceptions::PyValueError;
use pyo3::PyResult;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::cell::RefCell;
use std::rc::Rc;

/// Most worker threads a call may ask for.
pub const MAX_THREADS: usize = 1024;

thread_local! {
    /// This thread's pool and its size, made on first use and replaced when another size
    /// is asked for (the workers of the old one then end).
    static POOL: RefCell<Option<(usize, Rc<ThreadPool>)>> = const { RefCell::new(None) };
}

/// Runs `work` on a pool of `threads` workers (all cores when `None`).
pub fn install<R: Send>(threads: Option<usize>, work: impl FnOnce() -> R + Send) -> PyResult<R> {
    let Some(n) = threads else {
        return Ok(work());
    };
    if !(1..=MAX_THREADS).contains(&n) {
        return Err(PyValueError::new_err(format!(
            "threads must be in 1..={MAX_THREADS}, not {n}"
        )));
    }
    let pool = POOL.with(|slot| -> PyResult<Rc<ThreadPool>> {
        if let Some((size, pool)) = &*slot.borrow() {
            if *size == n {
                return Ok(pool.clone());
            }
        }
        // The old pool goes first, so its workers and the new ones never add up.
        slot.borrow_mut().take();
        let pool = Rc::new(
            ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| PyValueError::new_err(format!("cannot start {n} threads: {e}")))?,
        );
        *slot.borrow_mut() = Some((n, pool.clone()));
        Ok(pool)
    })?;
    Ok(pool.install(work))
}
