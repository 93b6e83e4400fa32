//! The durable job queue's workers: claim a job with a lease, run it on the compute pool (never on
//! the async runtime), heartbeat with the fencing attempt number, and write the result only while the
//! attempt still holds the job.
//!
//! A job interrupted by a crash or kill keeps its lease until it expires; then any worker (this
//! instance after a restart, or another) claims it again and reruns it from the start. The seed was
//! fixed at submission, so the result is identical to an uninterrupted run. On a graceful shutdown the
//! running job is stopped and handed back to the queue at once.

use crate::domain::UnixMs;
use crate::store::{Claim, Fence, Lease, LeaseTerms, QueueEvent, Store};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::{Cancelled, Job, JobResult, Watch, run_job};
use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{Notify, broadcast, oneshot, watch};
use tokio::task::JoinHandle;

/// Progress and the lease are written at most this often per running job.
const HEARTBEAT_MAX_PERIOD: Duration = Duration::from_millis(500);
/// An idle worker looks for expired leases at least this often.
const IDLE_POLL: Duration = Duration::from_millis(500);

pub struct Workers {
    pub store: Arc<dyn Store>,
    pub compute: Arc<rayon::ThreadPool>,
    pub lease: Duration,
    /// Times a job is run again after its lease expired, before it fails.
    pub retries: u64,
    pub instance: String,
    /// Notified on every submission, so an idle worker starts at once.
    pub wake: Arc<Notify>,
}

impl Workers {
    /// Starts `count` worker loops; they stop, handing running jobs back, when `shutdown` turns true.
    pub fn spawn(
        self: Arc<Self>,
        count: usize,
        shutdown: watch::Receiver<bool>,
    ) -> Vec<JoinHandle<()>> {
        if count > 0
            && let Some(events) = self.store.events()
        {
            tokio::spawn(wake_on_announcements(
                events,
                Arc::clone(&self.wake),
                shutdown.clone(),
            ));
        }
        (0..count)
            .map(|slot| {
                let workers = Arc::clone(&self);
                let shutdown = shutdown.clone();
                tokio::spawn(async move { workers.work(slot, shutdown).await })
            })
            .collect()
    }

    /// The lease a claim or heartbeat asks for, from now.
    fn lease_terms(&self) -> LeaseTerms {
        LeaseTerms {
            now: UnixMs::now(),
            duration_ms: i64::try_from(self.lease.as_millis()).unwrap_or(i64::MAX),
        }
    }

    async fn work(&self, slot: usize, mut shutdown: watch::Receiver<bool>) {
        let worker = format!("{}/{slot}", self.instance);
        while !*shutdown.borrow() {
            match self
                .store
                .claim(&worker, self.lease_terms(), self.retries)
                .await
            {
                Ok(Some(claim)) => self.run(claim, &mut shutdown).await,
                Ok(None) => {
                    tokio::select! {
                        () = self.wake.notified() => {}
                        () = tokio::time::sleep(IDLE_POLL) => {}
                        _ = shutdown.changed() => {}
                    }
                }
                Err(error) => {
                    tracing::error!(%error, "claiming a job failed");
                    tokio::time::sleep(IDLE_POLL).await;
                }
            }
        }
    }

    /// Ends the claim's job as failed, with the reason; a failure to write it leaves the lease to
    /// expire, and the job to be rerun.
    async fn fail(&self, fence: &Fence, reason: &str) {
        tracing::error!(reason, "job failed");
        metrics::counter!("bouncewear_jobs_finished_total", "status" => "failed").increment(1);
        if let Err(error) = self.store.fail(fence, UnixMs::now(), reason).await {
            tracing::error!(%error, "could not mark the job failed; its lease will expire");
        }
    }

    #[tracing::instrument(skip_all, fields(job = %claim.fence.job, attempt = claim.fence.attempt.0))]
    async fn run(&self, claim: Claim, shutdown: &mut watch::Receiver<bool>) {
        let fence = &claim.fence;
        let job = match Job::new(claim.spec, || 0, &Pointer::root()) {
            Ok(job) => job,
            Err(invalid) => {
                let reason = format!("the stored job no longer validates: {invalid}");
                return self.fail(fence, &reason).await;
            }
        };
        tracing::info!(operations = claim.operations_total, "job started");
        let cancel = Arc::new(AtomicBool::new(false));
        let done = Arc::new(AtomicU64::new(0));
        let (sender, mut finished) = oneshot::channel();
        {
            let (cancel, done) = (Arc::clone(&cancel), Arc::clone(&done));
            self.compute.spawn(move || {
                let observer = Watch {
                    cancel: &cancel,
                    on_progress: |d, _| done.store(d, Ordering::Relaxed),
                };
                let _ = sender.send(std::panic::catch_unwind(AssertUnwindSafe(|| {
                    run_job(&job, &observer)
                })));
            });
        }
        let period = (self.lease / 3).min(HEARTBEAT_MAX_PERIOD);
        let mut heartbeat = tokio::time::interval(period);
        let mut stopping = false;
        let outcome = loop {
            tokio::select! {
                outcome = &mut finished => break outcome,
                _ = heartbeat.tick() => {
                    let progress = done.load(Ordering::Relaxed);
                    match self.store.heartbeat(fence, self.lease_terms(), progress).await {
                        Ok(Lease::Held) => {}
                        Ok(lease @ (Lease::Cancelled | Lease::Lost)) => {
                            tracing::info!(?lease, "stopping: the job is no longer ours to run");
                            cancel.store(true, Ordering::Relaxed);
                        }
                        Err(error) => tracing::warn!(%error, "heartbeat failed; the lease may expire"),
                    }
                }
                _ = shutdown.changed(), if !stopping => {
                    stopping = true;
                    cancel.store(true, Ordering::Relaxed);
                }
            }
        };
        match outcome {
            Ok(Ok(Ok(result))) => self.succeed(fence, &result).await,
            Ok(Ok(Err(Cancelled))) if stopping => match self.store.release(fence).await {
                Ok(_) => tracing::info!("handed back to the queue for shutdown"),
                Err(error) => {
                    tracing::error!(%error, "could not hand the job back; its lease will expire")
                }
            },
            Ok(Ok(Err(Cancelled))) => tracing::info!("job stopped (cancelled or taken over)"),
            Ok(Err(_)) | Err(_) => {
                self.fail(fence, "internal error: the simulation panicked")
                    .await
            }
        }
    }

    async fn succeed(&self, fence: &Fence, result: &JobResult) {
        match self.store.succeed(fence, UnixMs::now(), result).await {
            Ok(true) => {
                let operations = result.job.devices_run() * result.job.spec().operations;
                metrics::counter!("bouncewear_jobs_finished_total", "status" => "succeeded")
                    .increment(1);
                metrics::counter!("bouncewear_operations_simulated_total").increment(operations);
                tracing::info!(wall_s = result.timing.wall_s, "job succeeded");
            }
            Ok(false) => {
                tracing::info!("result discarded: the job was cancelled or taken over meanwhile")
            }
            Err(error) => {
                tracing::error!(%error, "storing the result failed; the lease will expire and the job rerun")
            }
        }
    }
}

/// Wakes idle workers when the database announces a queued job (from any instance), so that a
/// second machine starts at once rather than at its next poll.
async fn wake_on_announcements(
    mut events: broadcast::Receiver<QueueEvent>,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        tokio::select! {
            event = events.recv() => match event {
                Ok(QueueEvent::Queued) | Err(broadcast::error::RecvError::Lagged(_)) => wake.notify_waiters(),
                Ok(QueueEvent::Changed(_)) => {}
                Err(broadcast::error::RecvError::Closed) => return,
            },
            _ = shutdown.changed() => return,
        }
    }
}
