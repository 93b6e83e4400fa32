//! The rayon pool simulations run on: compute never runs on the async runtime's threads.

/// Why no pool could be made.
#[derive(Debug, thiserror::Error)]
pub enum PoolError {
    #[error("at least one compute thread is needed")]
    NoThreads,
    #[error("at most {MAX_THREADS} compute threads, got {0}")]
    TooMany(usize),
    #[error("cannot start compute threads: {0}")]
    Build(#[from] rayon::ThreadPoolBuildError),
}

/// The most compute threads a pool takes: far past any core count this runs on (results are the
/// same bits for any count, so more threads than cores only cost). `run --threads 100000` made
/// 15,931 threads before the system refused more, took a load average of 4,000 on two cores and
/// ran on for 20 minutes (found from outside).
pub const MAX_THREADS: usize = 1024;

/// A pool of `threads` workers (one per core by default), from 1 to [`MAX_THREADS`].
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, PoolError> {
    let mut builder =
        rayon::ThreadPoolBuilder::new().thread_name(|i| format!("bouncewear-compute-{i}"));
    if let Some(threads) = threads {
        if threads == 0 {
            return Err(PoolError::NoThreads);
        }
        if threads > MAX_THREADS {
            return Err(PoolError::TooMany(threads));
        }
        builder = builder.num_threads(threads);
    }
    Ok(builder.build()?)
}
