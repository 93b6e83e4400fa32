//! The rayon pool simulations run on: compute never runs on the async runtime's threads.

/// Why no pool could be made.
#[derive(Debug, thiserror::Error)]
pub enum PoolError {
    #[error("at least one compute thread is needed")]
    NoThreads,
    #[error("cannot start compute threads: {0}")]
    Build(#[from] rayon::ThreadPoolBuildError),
}

/// A pool of `threads` workers (one per core by default).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, PoolError> {
    let mut builder =
        rayon::ThreadPoolBuilder::new().thread_name(|i| format!("bouncewear-compute-{i}"));
    if let Some(threads) = threads {
        if threads == 0 {
            return Err(PoolError::NoThreads);
        }
        builder = builder.num_threads(threads);
    }
    Ok(builder.build()?)
}
