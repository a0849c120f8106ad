//! Thread pools by size: `threads=None` is rayon's global pool (all cores), shared by
//! every caller; `threads=n` a pool of exactly n workers that belongs to the calling
//! thread, so two Python threads asking for one worker each trace side by side.
//!
//! Each Python thread keeps one pool, of the size it asked for last: a loop over sizes
//! (`threads=1`, `2`, … `128`) never holds more than one pool's workers at a time, and a
//! Python thread's pool ends with it.
//!
//! A process forked from one that has pools (`multiprocessing` with "fork") inherits them
//! without their worker threads, which live on in the parent only: work sent to them would
//! wait forever. Pools remember the process that made them, and a forked child makes its
//! own.

use pyo3::exceptions::PyValueError;
use pyo3::PyResult;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::cell::RefCell;
use std::rc::Rc;
use std::sync::{Arc, Mutex, OnceLock};

/// Most worker threads a call may ask for.
pub const MAX_THREADS: usize = 1024;

/// A pool and the process whose threads it has.
struct Owned<P> {
    process: u32,
    threads: usize,
    pool: P,
}

thread_local! {
    /// This thread's pool, made on first use and replaced when another size is asked for
    /// (the workers of the old one then end).
    static POOL: RefCell<Option<Owned<Rc<ThreadPool>>>> = const { RefCell::new(None) };
}

/// The process that uses rayon's global pool: the first to call [`install`].
static GLOBAL_POOL_PROCESS: OnceLock<u32> = OnceLock::new();

/// All cores' pool of a forked child, in place of the global pool it cannot use.
static FORKED_POOL: Mutex<Option<Owned<Arc<ThreadPool>>>> = Mutex::new(None);

/// Runs `work` on a pool of `threads` workers (all cores when `None`).
pub fn install<R: Send>(threads: Option<usize>, work: impl FnOnce() -> R + Send) -> PyResult<R> {
    let process = std::process::id();
    let Some(n) = threads else {
        if *GLOBAL_POOL_PROCESS.get_or_init(|| process) == process {
            return Ok(work());
        }
        return Ok(forked_pool(process)?.install(work));
    };
    if !(1..=MAX_THREADS).contains(&n) {
        return Err(PyValueError::new_err(format!(
            "threads must be in 1..={MAX_THREADS}, not {n}"
        )));
    }
    let pool = POOL.with(|slot| -> PyResult<Rc<ThreadPool>> {
        let mut slot = slot.borrow_mut();
        match slot.take() {
            Some(owned) if owned.process == process && owned.threads == n => {
                let pool = owned.pool.clone();
                *slot = Some(owned);
                return Ok(pool);
            }
            // Another process's pool: its workers are not here to be told to end.
            Some(owned) if owned.process != process => std::mem::forget(owned),
            // The old pool goes first, so its workers and the new ones never add up.
            _ => {}
        }
        let pool = Rc::new(pool_of(n)?);
        *slot = Some(Owned {
            process,
            threads: n,
            pool: pool.clone(),
        });
        Ok(pool)
    })?;
    Ok(pool.install(work))
}

/// The pool of all cores of this forked process.
fn forked_pool(process: u32) -> PyResult<Arc<ThreadPool>> {
    let mut slot = FORKED_POOL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(owned) = slot.take() {
        if owned.process == process {
            let pool = owned.pool.clone();
            *slot = Some(owned);
            return Ok(pool);
        }
        std::mem::forget(owned);
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pool = Arc::new(pool_of(threads)?);
    *slot = Some(Owned {
        process,
        threads,
        pool: pool.clone(),
    });
    Ok(pool)
}

fn pool_of(n: usize) -> PyResult<ThreadPool> {
    ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| PyValueError::new_err(format!("cannot start {n} threads: {e}")))
}
