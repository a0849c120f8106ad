//! Thread pools by size: `threads=None` is rayon's global pool (all cores), shared by
//! every caller; `threads=n` a pool of exactly n workers that belongs to the calling
//! thread, so two Python threads asking for one worker each trace side by side.

use pyo3::exceptions::PyValueError;
use pyo3::PyResult;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

/// Most worker threads a call may ask for.
pub const MAX_THREADS: usize = 1024;

thread_local! {
    /// This thread's pools, by size, made on first use and kept.
    static POOLS: RefCell<HashMap<usize, Rc<ThreadPool>>> = RefCell::new(HashMap::new());
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
    let pool = POOLS.with(|pools| -> PyResult<Rc<ThreadPool>> {
        if let Some(pool) = pools.borrow().get(&n) {
            return Ok(pool.clone());
        }
        let pool = Rc::new(
            ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| PyValueError::new_err(format!("cannot start {n} threads: {e}")))?,
        );
        pools.borrow_mut().insert(n, pool.clone());
        Ok(pool)
    })?;
    Ok(pool.install(work))
}
