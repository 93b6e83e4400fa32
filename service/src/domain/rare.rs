//! A rare event's rounds across workers. After a job's last batch of devices, its rare event
//! (docs/contract.md "Rare events") is estimated in rounds of independent tasks
//! ([`bouncewear_model::montecarlo::rare::Estimator`]). A merge step runs each round itself while
//! rounds are small; a round of at least [`SHARDED_ROUND_OPERATIONS`] goes to the queue as a batch
//! of its own (batch [`RARE_ROUNDS`] + round): its tasks as groups, which any worker runs, and a
//! merge step that takes their outcomes, runs the next rounds, and stores the Result once the
//! estimate is made. The estimator's state between rounds is the round's merge step's stored
//! partial. A round's tasks give the same bits wherever they run and however the round is cut, so
//! the Result is the one of the job run whole.

use bouncewear_model::montecarlo::rare::{
    self, Estimator, Outcome, RareEventError, RareEventReport, Task,
};
use bouncewear_model::montecarlo::{Job, Observer, RunError};
use serde::{Deserialize, Serialize};

/// Batches at and above this are a rare event's rounds: round `r` is batch `RARE_ROUNDS + r`.
pub const RARE_ROUNDS: u64 = 1 << 40;

/// The fewest operations of a round that runs as shards (about 30 ms of one compute thread): a
/// smaller round runs in the merge step that reaches it, on that process's compute threads, where
/// each task's claim and store (1-5 ms) would cost about what the task does. Every level of
/// subset simulation (900 or 1000 evaluations) and every batch of importance samples of a device
/// read at operation 1000 is larger.
pub const SHARDED_ROUND_OPERATIONS: u64 = 500_000;

/// Operations per task of a sharded round, about: a round is cut into as many tasks, at least two
/// and at most [`MAX_ROUND_TASKS`].
const TASK_OPERATIONS: u64 = 250_000;
const MAX_ROUND_TASKS: u64 = 32;

/// A rare event between rounds: what a round's tasks and its merge step take up.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Rounds {
    /// The job's last batch of devices, whose groups the Result is summed up from.
    pub devices_last: u64,
    /// The round queued: batch [`RARE_ROUNDS`] + `round`.
    pub round: u64,
    /// The tasks it is cut into.
    pub tasks: u64,
    pub estimator: Estimator,
}

impl Rounds {
    /// The round's batch.
    pub fn batch(&self) -> u64 {
        RARE_ROUNDS + self.round
    }

    /// Task `group` of the round, if it has one.
    pub fn task(&self, group: u64) -> Option<Task> {
        let tasks = self.estimator.tasks(usize::try_from(self.tasks).ok()?);
        tasks.get(usize::try_from(group).ok()?).copied()
    }

    /// The operations of each of the round's tasks, in order.
    pub fn task_operations(&self, job: &Job) -> Vec<u64> {
        let tasks = self.estimator.tasks(self.tasks as usize);
        tasks
            .into_iter()
            .map(|task| self.operations_of(job, task))
            .collect()
    }

    /// The operations of `task`: its evaluations, each of the job's operations per evaluation.
    pub fn operations_of(&self, job: &Job, task: Task) -> u64 {
        let evaluations = self.estimator.task_evaluations(task);
        evaluations.saturating_mul(rare::operations_per_evaluation(job))
    }
}

/// Whether batch `batch` is a rare event's round.
pub fn is_round(batch: u64) -> bool {
    batch >= RARE_ROUNDS
}

/// Where a rare event's estimate stands after a merge step.
#[derive(Debug)]
pub enum Estimated {
    /// Made: the Result follows from the devices' groups (none if the job asks no rare event).
    Made(Option<RareEventReport>),
    /// Another round to queue.
    Queued(Rounds),
}

/// Runs rounds here while they have fewer than `sharded_from` operations: the report once the
/// estimate is made, or `None` when the round `estimator` is at goes to the queue.
fn run_small_rounds(
    job: &Job,
    estimator: &mut Estimator,
    sharded_from: u64,
    observer: &dyn Observer,
) -> Result<Option<RareEventReport>, RunError> {
    let per_evaluation = rare::operations_per_evaluation(job);
    loop {
        let operations = estimator.round_evaluations().saturating_mul(per_evaluation);
        if operations >= sharded_from {
            return Ok(None);
        }
        let outcomes = estimator
            .tasks(1)
            .into_iter()
            .map(|task| rare::run_task(job, estimator, task))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(report) = rare::advance(job, estimator, outcomes, observer)? {
            return Ok(Some(report));
        }
    }
}

/// Queues the round `estimator` is at as round `round`, cut by its operations.
fn queued(job: &Job, estimator: Estimator, devices_last: u64, round: u64) -> Rounds {
    let operations = estimator
        .round_evaluations()
        .saturating_mul(rare::operations_per_evaluation(job));
    // A round of fewer chains or samples than that is cut into one task each.
    let wanted = (operations / TASK_OPERATIONS).clamp(2, MAX_ROUND_TASKS) as usize;
    Rounds {
        devices_last,
        round,
        tasks: estimator.tasks(wanted).len() as u64,
        estimator,
    }
}

/// The job's devices are done (batches up to `devices_last`): its rare event, if it asks one,
/// estimated here while its rounds are small, or the first round that is not.
pub fn first_round(
    job: &Job,
    devices_last: u64,
    sharded_from: u64,
    observer: &dyn Observer,
) -> Result<Estimated, RunError> {
    let Some(mut estimator) = rare::start(job) else {
        return Ok(Estimated::Made(None));
    };
    Ok(
        match run_small_rounds(job, &mut estimator, sharded_from, observer)? {
            Some(report) => Estimated::Made(Some(report)),
            None => Estimated::Queued(queued(job, estimator, devices_last, 0)),
        },
    )
}

/// A round's merge step: takes its tasks' outcomes (in task order), then runs rounds here while
/// they are small.
pub fn merge_round(
    job: &Job,
    mut rounds: Rounds,
    outcomes: Vec<Outcome>,
    sharded_from: u64,
    observer: &dyn Observer,
) -> Result<Estimated, RunError> {
    if outcomes.len() as u64 != rounds.tasks {
        return Err(RunError::RareEvent(RareEventError(format!(
            "round {} has {} of its {} tasks' outcomes",
            rounds.round,
            outcomes.len(),
            rounds.tasks
        ))));
    }
    let estimator = &mut rounds.estimator;
    if let Some(report) = rare::advance(job, estimator, outcomes, observer)? {
        return Ok(Estimated::Made(Some(report)));
    }
    Ok(
        match run_small_rounds(job, estimator, sharded_from, observer)? {
            Some(report) => Estimated::Made(Some(report)),
            None => {
                let next = rounds.round + 1;
                Estimated::Queued(queued(job, rounds.estimator, rounds.devices_last, next))
            }
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_round_is_cut_by_its_operations_and_each_task_found_by_its_group() {
        // A device read at operation 2000: a first level of 1000 samples is 2e6 operations.
        let job = Job::from_json(
            r#"{"devices": 1, "operations": 2000, "seed": 3,
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                    "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
                "rare_event": {"metric": "total_bounce_s", "above": 0.02, "operation": 2000,
                    "method": "subset"}}"#,
            || 1,
        )
        .unwrap();
        let rounds = queued(&job, rare::start(&job).unwrap(), 0, 3);
        assert_eq!((rounds.tasks, rounds.batch()), (8, RARE_ROUNDS + 3));
        assert_eq!(rounds.task_operations(&job), [250_000; 8]);
        assert!(rounds.task(7).is_some() && rounds.task(8).is_none());
        assert!(is_round(RARE_ROUNDS) && !is_round(RARE_ROUNDS - 1));
    }
}
