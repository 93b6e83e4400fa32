//! The service's rules, in neither HTTP's nor SQL's terms: identities and times, where a seed comes
//! from, how a validated job enters the queue and is cut into shards, what makes a schedule valid, and how a schedule's
//! trend and drift are read. The HTTP handlers, the workers and the scheduler all come here, so each
//! rule is written once.

pub mod cursor;
pub mod idempotency;
mod ids;
pub mod jobs;
pub mod query;
pub mod rare;
pub mod schedules;
pub mod shards;
pub mod trend;

pub use cursor::CursorKey;
pub use idempotency::{IdempotencyKey, Once};
pub use ids::{Attempt, JobId, Owner, ScheduleId, UnixMs};
pub use jobs::{JobStatus, QueueBound, QueuedJob, draw_seed};
pub use query::AfterRunQuery;
pub use schedules::{
    CatchUp, MISSED_RUNS, MISSED_RUNS_COUNTED, ScheduleBound, ScheduleDefinition, ScheduleLimits,
    ScheduleSpec, Statistic, Timetable, ValidSchedule, too_often,
};
pub use shards::{
    Folding, ROOM_RETRY_MS, RetryBudget, SHARD_OVERHEAD_OPERATIONS, ShardId, ShardPlan,
    batch_shards, first_shards, grouped_shards, groups_stay_in_shards, retry_backoff_ms,
};
pub use trend::TrendValue;
