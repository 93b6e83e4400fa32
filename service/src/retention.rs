//! Retention (`--retain-days`): jobs that ended that many days ago are deleted with everything
//! stored for them, at start-up and then every hour. Every instance may run it: a job deleted by
//! one is simply gone for the others.

use crate::store::Store;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

const PASS: Duration = Duration::from_secs(3600);
const DAY_MS: i64 = 86_400_000;

pub async fn run(store: Arc<Store>, retain_days: u32, mut stopping: watch::Receiver<bool>) {
    let mut passes = tokio::time::interval(PASS);
    loop {
        tokio::select! {
            _ = passes.tick() => {}
            _ = stopping.wait_for(|stop| *stop) => return,
        }
        // The ends are stamped on the database's clock, and so is their age.
        match store
            .prune_jobs(i64::from(retain_days) * DAY_MS, None)
            .await
        {
            Ok(0) => {}
            Ok(deleted) => tracing::info!(deleted, retain_days, "deleted jobs past retention"),
            Err(error) => tracing::warn!(%error, "deleting jobs past retention failed"),
        }
    }
}
