//! Schedules: a job template run on a cron expression in a time zone, the rules a schedule document
//! must pass, and the statistics a schedule follows from run to run.

use super::jobs::{QueuedJob, draw_seed};
use super::{Owner, UnixMs};
use bouncewear_model::error::{MAX_TEXT_CHARS, past_listing};
use bouncewear_model::montecarlo::job::{LIST_FIELDS, check_written};
use bouncewear_model::montecarlo::{Job, JobResult, JobSpec, Metric, needs_polarity};
use bouncewear_model::stats::{QUANTILES, Summary};
use bouncewear_model::{FieldError, InvalidInput, Pointer};
use chrono::{DateTime, TimeDelta, TimeZone, Timelike, Utc};
use chrono_tz::Tz;
use croner::Cron;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;
use utoipa::ToSchema;

/// What a schedule follows when the document names no statistic.
const DEFAULT_STATISTIC: &str = "operations.total_bounce_s.p95";

/// Why a schedule's due times before the one it runs are skipped ([`Timetable::catch_up`]).
pub const MISSED_RUNS: &str = "not run at its due time (the server down, its ticks late, the run \
    before waiting for room, or the schedule replaced by a PUT as its run was made) before a later \
    one came: only the latest due time runs";

/// Most runs missed that one tick counts: a schedule every second, a day down, is 86,400.
pub const MISSED_RUNS_COUNTED: u64 = 100_000;

/// The run a due schedule makes: its latest due time at or before now, and the due times before
/// it since its next run that it misses (counted up to a cap), with the latest of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CatchUp {
    pub due: DateTime<Utc>,
    pub missed: u64,
    pub last_missed: Option<DateTime<Utc>>,
}

/// A schedule as a client writes it.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSpec {
    /// A label for the schedule and its jobs (1 to 200 characters, not only white space).
    pub name: String,
    /// Cron expression: 5 fields (minute hour day month weekday), or 6 with seconds first.
    pub cron: String,
    /// IANA time zone the cron expression is read in (default `UTC`).
    #[serde(default)]
    pub time_zone: Option<String>,
    /// The job each run submits (docs/contract.md "Job"). Without a `seed`, every run draws its own.
    pub template: JobSpec,
    /// Statistics the trend follows, e.g. `operations.total_bounce_s.p95` (last bin),
    /// `devices.eroded_mass_kg.mean`, `life.b10` (default: `operations.total_bounce_s.p95`).
    #[serde(default)]
    pub statistics: Option<Vec<String>>,
    /// Whether it runs on its timetable (default true).
    #[serde(default)]
    pub enabled: Option<bool>,
}

/// What a schedule is, as stored: the parts a client sets, with defaults filled in.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleDefinition {
    pub name: String,
    pub cron: String,
    pub time_zone: String,
    /// The job template, validated when the schedule was written.
    pub template: JobSpec,
    pub statistics: Vec<Statistic>,
    pub enabled: bool,
}

impl ScheduleDefinition {
    /// The job this schedule runs at `due`: its template (a seed is drawn for each run when the
    /// template has none), named after the schedule and the due time. Refused, as a job submitted
    /// now would be, when the template no longer validates or is larger than the server allows
    /// (`max_job_operations`: a limit lowered since the schedule was written, or another
    /// instance's on a shared database).
    pub fn job_at(
        &self,
        owner: Owner,
        due: UnixMs,
        now: UnixMs,
        max_job_operations: u64,
    ) -> Result<QueuedJob, InvalidInput> {
        let template = Pointer::root().child("template");
        let job = Job::new(self.template.clone(), draw_seed, &template)?;
        job.check_size(max_job_operations, &template)?;
        Ok(QueuedJob::new(&job, owner, Some(self.run_name(due)), now))
    }

    /// A run's job name: the schedule's and the due time, within the
    /// [`MAX_TEXT_CHARS`] a job's name may hold (a schedule named with 200 characters made jobs
    /// named with 227, which `POST /v1/jobs` refuses; found from outside). The time stays whole.
    fn run_name(&self, due: UnixMs) -> String {
        let at = format!(" @ {}", due.to_rfc3339());
        let room = MAX_TEXT_CHARS.saturating_sub(at.chars().count());
        let name: String = self.name.chars().take(room).collect();
        format!("{}{at}", name.trim_end())
    }

    /// Whether `at` is one of the schedule's due times: the slot its run on the timetable takes,
    /// which a manual run leaves to it (a run now at that very millisecond took it, and the
    /// night's scheduled run was never made).
    pub fn is_due_time(&self, at: UnixMs) -> bool {
        Timetable::parse(&self.cron, &self.time_zone).is_ok_and(|timetable| timetable.runs_then(at))
    }

    /// Runs' times (RFC 3339, as stored) on the schedule's wall clock, as its trend labels them:
    /// to the minute (`2026-11-22 03:00`), or to the second where two runs share a minute (runs
    /// asked for by hand), or to the millisecond where two share a second (runs asked for by a
    /// script); a time that does not parse as it is. (A stored zone always parses; UTC
    /// stands in should one not.)
    pub fn wall_clock(&self, times: &[&str]) -> Vec<String> {
        let zone = Tz::from_str(&self.time_zone).unwrap_or(Tz::UTC);
        let shown = |pattern: &str| -> Vec<String> {
            times
                .iter()
                .map(|&text| match DateTime::parse_from_rfc3339(text) {
                    Ok(at) => at.with_timezone(&zone).format(pattern).to_string(),
                    Err(_) => text.to_owned(),
                })
                .collect()
        };
        let distinct = |labels: &Vec<String>| {
            labels
                .iter()
                .collect::<std::collections::HashSet<_>>()
                .len()
                == labels.len()
        };
        ["%Y-%m-%d %H:%M", "%Y-%m-%d %H:%M:%S"]
            .into_iter()
            .map(shown)
            .find(distinct)
            .unwrap_or_else(|| shown("%Y-%m-%d %H:%M:%S%.3f"))
    }
}

/// The server's bound on stored schedules: how many one owner may hold, and the free disk (beside
/// a SQLite database) a new one needs, so that no client fills the disk with schedules.
#[derive(Debug, Clone, Copy)]
pub struct ScheduleBound {
    pub per_owner: u64,
    pub min_free_disk_bytes: u64,
}

/// The server's limits on a schedule: each run's job size, and how often it may run.
#[derive(Debug, Clone, Copy)]
pub struct ScheduleLimits {
    pub max_job_operations: u64,
    /// The shortest interval allowed between two runs.
    pub min_interval: TimeDelta,
}

/// Why `timetable` (in `time_zone`) runs more often than `min_interval` allows, over the year
/// after `now`; `None` where it does not. A schedule written so is refused, and one written
/// before the server's limit was raised has its runs skipped by the scheduler.
pub fn too_often(
    timetable: &Timetable,
    time_zone: &str,
    min_interval: TimeDelta,
    now: DateTime<Utc>,
) -> Option<String> {
    let gap = timetable.on_the_wall_clock().gap_below(min_interval, now)?;
    Some(format!(
        "runs {} apart at {} ({time_zone} wall clock): runs must be at least {} apart (the server's --min-schedule-interval-seconds)",
        describe_interval(gap.1 - gap.0),
        // The wall clock's time, which `on_the_wall_clock` holds as if it were UTC.
        gap.1.naive_utc().format("%Y-%m-%d %H:%M:%S"),
        describe_interval(min_interval)
    ))
}

/// A schedule document that passed every rule; only [`ValidSchedule::parse`] makes one.
#[derive(Debug, Clone)]
pub struct ValidSchedule {
    definition: ScheduleDefinition,
    timetable: Timetable,
}

impl ValidSchedule {
    /// Parses and validates a schedule document, naming every field at fault. Each run of the
    /// template must fit the server's job size limit, and its runs, over the year after `now`,
    /// must be at least the minimum interval apart, unless it is disabled.
    pub fn parse(
        body: &str,
        limits: ScheduleLimits,
        now: DateTime<Utc>,
    ) -> Result<Self, InvalidInput> {
        let template_lists = LIST_FIELDS.map(|field| format!("/template{field}"));
        let lists: Vec<&str> = std::iter::once("/statistics")
            .chain(template_lists.iter().map(String::as_str))
            .collect();
        let (spec, faults): (ScheduleSpec, _) =
            bouncewear_model::error::read_past_faults(body, &lists)?;
        let root = Pointer::root();
        let mut errors = faults;
        // Longer text was refused before (MAX_TEXT_CHARS); a name must also say something.
        if spec.name.trim().is_empty() {
            errors.push(FieldError {
                pointer: "/name".into(),
                detail: "must have a character other than white space".into(),
            });
        }
        let time_zone = spec.time_zone.unwrap_or_else(|| "UTC".to_owned());
        let timetable = Timetable::parse_written(&spec.cron, &time_zone)
            .map_err(|wrong| {
                errors.extend(wrong.into_iter().map(|(field, detail)| FieldError {
                    pointer: root.child(field).to_string(),
                    detail,
                }))
            })
            .ok();
        if timetable
            .as_ref()
            .is_some_and(|t| t.next_after(now).is_none())
        {
            errors.push(FieldError {
                pointer: "/cron".into(),
                detail: "never runs: no date matches it (e.g. February 30)".into(),
            });
        } else if spec.enabled != Some(false)
            && let Some(detail) = timetable
                .as_ref()
                .and_then(|t| too_often(t, &time_zone, limits.min_interval, now))
        {
            // A disabled schedule makes no runs, so how often it would is no rule of its: one the
            // server's raised --min-schedule-interval-seconds left too frequent can be disabled
            // as it is (it was refused at `/cron`, its skips counting on meanwhile; a probe).
            errors.push(FieldError {
                pointer: "/cron".into(),
                detail,
            });
        }
        let template = root.child("template");
        if let Err(invalid) = check_written(&spec.template, &template) {
            errors.extend_from_slice(invalid.errors());
        }
        let job = Job::new(spec.template.clone(), || 0, &template);
        let size = job
            .as_ref()
            .map_err(Clone::clone)
            .and_then(|job| job.check_size(limits.max_job_operations, &template));
        if let Err(invalid) = size {
            errors.extend_from_slice(invalid.errors());
        }
        let statistics = followed(spec.statistics, job.as_ref().ok(), &mut errors);
        match timetable {
            Some(timetable) if errors.is_empty() => Ok(Self {
                definition: ScheduleDefinition {
                    name: spec.name.trim().to_owned(),
                    cron: spec.cron,
                    time_zone,
                    template: spec.template,
                    statistics,
                    enabled: spec.enabled.unwrap_or(true),
                },
                timetable,
            }),
            _ => Err(InvalidInput::new(errors)),
        }
    }

    /// The first run after `now`; none while the schedule is disabled.
    pub fn next_run_after(&self, now: UnixMs) -> Option<UnixMs> {
        if !self.definition.enabled {
            return None;
        }
        self.timetable
            .next_after(now.to_datetime())
            .map(UnixMs::from_datetime)
    }

    /// The next run of this document replacing a schedule whose next run was `due`: a due time
    /// already past stays while the new timetable runs then too (its run is not made yet: it
    /// waits for room in the queue, or for the scheduler's next tick), else the first run after
    /// `now`; none while disabled. An edit, even of the same body, dropped a night that waited for
    /// room; a new timetable that kept it ran at the new one's latest time, before the edit (a
    /// probe: every second, then `0 0 3 * * *` at 05:50, made a run for 03:00). Judged by the
    /// times, not the cron's text: `0 3 * * *` made `0 3 * * 1-5` at 03:00:00.3 on a Monday,
    /// before the tick, dropped that night unsaid (a probe: `* * * * * *` and `*/1 * * * * *`
    /// in turn lost 8 of 8 due seconds).
    pub fn next_run_replacing(&self, due: Option<UnixMs>, now: UnixMs) -> Option<UnixMs> {
        let next = self.next_run_after(now)?;
        Some(
            due.filter(|&due| due <= now && self.timetable.runs_then(due))
                .unwrap_or(next),
        )
    }

    pub fn into_definition(self) -> ScheduleDefinition {
        self.definition
    }
}

/// A parsed cron expression with its time zone.
#[derive(Debug, Clone)]
pub struct Timetable {
    cron: Cron,
    time_zone: Tz,
}

/// What a schedule's cron expression is, as its errors state the rule.
const CRON_FIELDS: &str = "a cron expression has 5 fields, minute (0-59) hour (0-23) day of the \
    month (1-31) month (1-12 or JAN-DEC) weekday (0-7 or SUN-SAT, 0 and 7 Sunday), or 6 with \
    seconds (0-59) first; each `*`, a value, a range `a-b`, a step `*/n` or `a-b/n`, or a list of \
    them `a,b`";

impl Timetable {
    /// Parses a stored schedule's cron expression and IANA time zone name. Errors are `(field,
    /// message)`, one for each of the two at fault. Whatever croner reads is taken: a schedule
    /// written before [`Timetable::parse_written`]'s rule keeps running.
    pub fn parse(cron: &str, time_zone: &str) -> Result<Self, Vec<(&'static str, String)>> {
        let parsed = Cron::from_str(&sunday_as_zero(cron)).map_err(|e| {
            let e = e.to_string();
            let e = e.trim_end_matches('.');
            (
                "cron",
                format!("is not a cron expression ({e}): {CRON_FIELDS}"),
            )
        });
        Self::with_zone(parsed, time_zone)
    }

    /// [`Timetable::parse`] for a schedule being written, whose cron must have 5 fields (minute
    /// hour day month weekday) or 6 with seconds first, as the API describes it: croner also
    /// reads a year as a seventh field and nicknames such as `@daily`.
    pub fn parse_written(cron: &str, time_zone: &str) -> Result<Self, Vec<(&'static str, String)>> {
        let fields: Vec<&str> = cron.split_whitespace().collect();
        let wrong = if !matches!(fields.len(), 5 | 6) {
            let count = fields.len();
            format!(
                "has {count} field{}: {CRON_FIELDS}",
                if count == 1 { "" } else { "s" }
            )
        } else if let Some(field) = fields.iter().find(|f| f.split(',').any(str::is_empty)) {
            // croner reads `,1` and `1,,2` as `1` and `1,2`: most likely a value left out.
            format!("has an empty item in the list `{field}`: {CRON_FIELDS}")
        } else {
            return Self::parse(cron, time_zone);
        };
        Self::with_zone(Err(("cron", wrong)), time_zone)
    }

    /// The timetable of `parsed` in `time_zone`, or the error of each at fault.
    fn with_zone(
        parsed: Result<Cron, (&'static str, String)>,
        time_zone: &str,
    ) -> Result<Self, Vec<(&'static str, String)>> {
        let zone = Tz::from_str(time_zone).map_err(|_| {
            (
                "time_zone",
                format!("`{time_zone}` is not an IANA time zone"),
            )
        });
        match (parsed, zone) {
            (Ok(cron), Ok(time_zone)) => Ok(Self { cron, time_zone }),
            (parsed, zone) => Err(parsed.err().into_iter().chain(zone.err()).collect()),
        }
    }

    /// The same cron on the wall clock alone, without the time zone's DST changes: the schedule
    /// as its author wrote it. The minimum interval between runs is a rule about that schedule;
    /// a daily run that the spring-forward gap moves to just after the gap (23 h or, in
    /// Lord Howe's half-hour change, 30 min from a neighbour) is the zone's artefact, not the
    /// author's cron.
    pub fn on_the_wall_clock(&self) -> Self {
        Self {
            cron: self.cron.clone(),
            time_zone: Tz::UTC,
        }
    }

    /// Two consecutive runs less than `min` apart, within the year and a day after `now` (every
    /// month, weekday and DST change; a Feb 29 of a later leap year aside), if there are any.
    /// Looks at 20,000 runs at most: as many in a year and a day are less than an hour apart on
    /// average.
    pub fn gap_below(
        &self,
        min: TimeDelta,
        now: DateTime<Utc>,
    ) -> Option<(DateTime<Utc>, DateTime<Utc>)> {
        const MAX_RUNS: usize = 20_000;
        let end = now + TimeDelta::days(367);
        let mut previous = self.next_after(now)?;
        for _ in 0..MAX_RUNS {
            let next = self.next_after(previous)?;
            if next - previous < min {
                return Some((previous, next));
            }
            if next > end {
                return None;
            }
            previous = next;
        }
        None
    }

    /// The first due time strictly after `after`, to the whole second. Wall-clock times follow the
    /// time zone, DST included: a fixed time in a spring-forward gap runs right after the gap, and
    /// a wall-clock time in a fall-back overlap runs once, at its first pass (croner, after Vixie
    /// cron). Croner searches the wall clock: given an instant in the second pass, it answers
    /// with a time's first pass, already past. Every wall-clock time of the overlap ran then, so
    /// the search goes on from the overlap's end (an every-minute cron at 00:58 of Havana's
    /// second pass is next due at 01:00, not half an hour on, as a fixed step once made it).
    pub fn next_after(&self, after: DateTime<Utc>) -> Option<DateTime<Utc>> {
        let after = whole_seconds(after);
        let mut from = self.time_zone.from_utc_datetime(&after.naive_utc());
        let mut inclusive = false;
        // A search from an overlap's end, or on from a gap's end that croner made up, finds a
        // time past it; the bound is a guard.
        for _ in 0..6 {
            let next = self.cron.find_next_occurrence(&from, inclusive).ok()?;
            if !self.runs_at(&next) {
                (from, inclusive) = (next, false);
                continue;
            }
            let due = whole_seconds(next.with_timezone(&Utc));
            if due > after {
                return Some(due);
            }
            // No overlap found (not met): half an hour on, as before the overlap's end was sought.
            let at = from.with_timezone(&Utc);
            (from, inclusive) = match self.overlap_end(at, utc_offset(&next)) {
                Some(end) => (end, true),
                None => (from + TimeDelta::minutes(30), false),
            };
        }
        None
    }

    /// Whether `at` is one of the timetable's due times, as [`Timetable::next_after`] finds them.
    pub fn runs_then(&self, at: UnixMs) -> bool {
        self.next_after(at.plus_ms(-1).to_datetime())
            .is_some_and(|due| UnixMs::from_datetime(due) == at)
    }

    /// Whether the cron runs at `at`: at its own wall-clock time, or right after a spring-forward
    /// gap that holds one. Croner 3 answers the gap's end for any search of a fixed-time cron
    /// that steps into the gap on a day the cron runs, whatever the time stepped into: at 01:40
    /// in Berlin on 2027-03-28, `30 1 * * *` was next due at 03:00 CEST, the gap's end (a probe).
    fn runs_at(&self, at: &DateTime<Tz>) -> bool {
        if self.cron.is_time_matching(at).unwrap_or(false) {
            return true;
        }
        let skipped = utc_offset(at) - utc_offset(&(*at - TimeDelta::seconds(1)));
        if skipped <= TimeDelta::zero() {
            return false;
        }
        // The wall-clock times the gap skipped, searched without a zone (as UTC: no gaps).
        let gap_end = at.naive_local();
        let before_gap = Utc.from_utc_datetime(&(gap_end - skipped - TimeDelta::seconds(1)));
        self.cron
            .find_next_occurrence(&before_gap, false)
            .is_ok_and(|skipped_time| skipped_time.naive_utc() < gap_end)
    }

    /// The end of the fall-back overlap whose second pass holds `at`, its first pass at the UTC
    /// offset `first`: the instant the wall clock passes the last repeated time. Found by halving
    /// the offset change, which lies between `at` less the overlap's length and `at`.
    fn overlap_end(&self, at: DateTime<Utc>, first: TimeDelta) -> Option<DateTime<Tz>> {
        let offset_at = |instant: DateTime<Utc>| {
            utc_offset(&self.time_zone.from_utc_datetime(&instant.naive_utc()))
        };
        let second = offset_at(at);
        let length = first - second;
        if length <= TimeDelta::zero() {
            return None;
        }
        let (mut before, mut change) = (at - length, at);
        while change - before > TimeDelta::seconds(1) {
            let middle = before + (change - before) / 2;
            if offset_at(middle) == second {
                change = middle;
            } else {
                before = middle;
            }
        }
        let end = change + length;
        Some(self.time_zone.from_utc_datetime(&end.naive_utc()))
    }

    /// What a schedule due since `from` runs at `now` ([`CatchUp`]): found going forward from
    /// `from`, a step or two for a scheduler on time (a search from a day before `now` took
    /// 86,400 steps a tick for a schedule every second). None if the timetable gives no time from
    /// `from` to `now`: nothing is owed.
    pub fn catch_up(&self, from: DateTime<Utc>, now: DateTime<Utc>, cap: u64) -> Option<CatchUp> {
        let (mut seen, mut latest, mut before) = (0, None, None);
        let mut next = self.next_after(whole_seconds(from) - TimeDelta::seconds(1));
        while let Some(due) = next.filter(|&due| due <= now) {
            if seen > cap {
                // Too many to step through: the latest found from `now` back.
                let due = self.latest_at_or_before(now)?;
                let before = self.latest_at_or_before(due - TimeDelta::seconds(1));
                return Some(CatchUp {
                    due,
                    missed: cap,
                    last_missed: before,
                });
            }
            seen += 1;
            (before, latest) = (latest, Some(due));
            next = self.next_after(due);
        }
        Some(CatchUp {
            due: latest?,
            missed: seen - 1,
            last_missed: before,
        })
    }

    /// The last due time at or before `now`: the one night a catch-up runs, however many were
    /// missed. Found going forward with [`Timetable::next_after`] from a day before `now` (then 8,
    /// 32, 367 and 1462 days, for weekly, monthly, yearly and leap-day crons), so that a run is
    /// made for exactly the time the schedule listed as its next: croner's backward search lands
    /// on the second before a spring-forward gap, or a week early where that second's weekday
    /// does not match.
    pub fn latest_at_or_before(&self, now: DateTime<Utc>) -> Option<DateTime<Utc>> {
        let now = whole_seconds(now);
        for days in [1, 8, 32, 367, 1462] {
            let mut latest = None;
            let mut next = self.next_after(now - TimeDelta::days(days));
            while let Some(due) = next.filter(|&due| due <= now) {
                latest = Some(due);
                next = self.next_after(due);
            }
            if latest.is_some() {
                return latest;
            }
        }
        None
    }
}

/// The statistics a schedule follows, `written` or the default, each one that the runs of `job`
/// (its template, when valid) give ([`Statistic::given_by`]) and none twice; pushes the faults.
fn followed(
    written: Option<Vec<String>>,
    job: Option<&Job>,
    errors: &mut Vec<FieldError>,
) -> Vec<Statistic> {
    let root = Pointer::root();
    let defaulted = written.is_none();
    let names = written.unwrap_or_else(|| vec![DEFAULT_STATISTIC.to_owned()]);
    if names.is_empty() {
        errors.push(FieldError {
            pointer: "/statistics".into(),
            detail: "must name at least one statistic".into(),
        });
    }
    let mut statistics: Vec<Statistic> = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        if past_listing(errors) {
            break;
        }
        let checked = name.parse::<Statistic>().and_then(|statistic| {
            if names[..i].contains(name) {
                return Err(format!("`{name}` is listed twice"));
            }
            // A template that is refused is reported as such; its statistics wait for it.
            if let Some(job) = job {
                statistic.given_by(job)?;
            }
            Ok(statistic)
        });
        match checked {
            Ok(statistic) => statistics.push(statistic),
            Err(detail) if defaulted => errors.push(FieldError {
                pointer: "/statistics".into(),
                detail: format!(
                    "the default statistic does not fit: {detail}; name the statistics to follow"
                ),
            }),
            Err(detail) => errors.push(FieldError {
                pointer: root.child("statistics").child(i).to_string(),
                detail,
            }),
        }
    }
    statistics
}

/// `cron` with a last Sunday written `7L` in its weekday field as `0L`: croner reads 7 as Sunday
/// everywhere but before `L`, where it never matches (a probe found `0 0 * * 7L` refused as never
/// running). The weekday is the fifth field of five and the sixth of six or seven.
fn sunday_as_zero(cron: &str) -> String {
    let mut fields: Vec<&str> = cron.split_whitespace().collect();
    let weekday = match fields.len() {
        5 => 4,
        6 | 7 => 5,
        _ => return cron.to_owned(),
    };
    let items: Vec<&str> = fields[weekday]
        .split(',')
        .map(|item| {
            if item.eq_ignore_ascii_case("7L") {
                "0L"
            } else {
                item
            }
        })
        .collect();
    let written = items.join(",");
    fields[weekday] = &written;
    fields.join(" ")
}

/// How far `time`'s wall clock is ahead of UTC.
fn utc_offset(time: &DateTime<Tz>) -> TimeDelta {
    time.naive_local() - time.naive_utc()
}

/// `time` without its fraction of a second: due times are whole seconds, so that the (schedule,
/// due time) key of a run is the same whichever tick, instance or restart makes it.
fn whole_seconds(time: DateTime<Utc>) -> DateTime<Utc> {
    time.with_nanosecond(0).unwrap_or(time)
}

/// A statistic a schedule follows from run to run, written `operations.METRIC.STAT` (last bin),
/// `devices.METRIC.STAT` (`STAT` is `mean` or `p01`..`p99`), or `life.b1`, `life.b10`, `life.beta`,
/// `life.eta`. Only parsing makes one, so a `Statistic` always names something a result can have.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Statistic {
    name: String,
    source: Source,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    Operations(Metric, SummaryStat),
    Devices(Metric, SummaryStat),
    Life(LifeStat),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SummaryStat {
    Mean,
    Quantile(&'static str),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LifeStat {
    B1,
    B10,
    Beta,
    Eta,
}

impl FromStr for Statistic {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let summary_stat = |stat: &str| {
            if stat == "mean" {
                Some(SummaryStat::Mean)
            } else {
                QUANTILES
                    .iter()
                    .find(|(name, _)| *name == stat)
                    .map(|(name, _)| SummaryStat::Quantile(name))
            }
        };
        let parts: Vec<&str> = text.split('.').collect();
        let source = match parts.as_slice() {
            ["operations", metric, stat] => Metric::parse(metric)
                .zip(summary_stat(stat))
                .map(|(m, s)| Source::Operations(m, s)),
            ["devices", metric, stat] => Metric::parse(metric)
                .zip(summary_stat(stat))
                .map(|(m, s)| Source::Devices(m, s)),
            ["life", "b1"] => Some(Source::Life(LifeStat::B1)),
            ["life", "b10"] => Some(Source::Life(LifeStat::B10)),
            ["life", "beta"] => Some(Source::Life(LifeStat::Beta)),
            ["life", "eta"] => Some(Source::Life(LifeStat::Eta)),
            _ => None,
        };
        source
            .map(|source| Self {
                name: text.to_owned(),
                source,
            })
            .ok_or_else(|| {
                format!(
                    "`{text}` is not a statistic: use operations.METRIC.STAT, devices.METRIC.STAT (STAT mean or p01..p99) or life.b1|b10|beta|eta"
                )
            })
    }
}

impl Statistic {
    pub fn as_str(&self) -> &str {
        &self.name
    }

    /// Whether every run of `job` gives the statistic a value to follow, or why none ever would:
    /// an operation metric under `operations`, a device metric under `devices`, each among the
    /// metrics the job computes, and life statistics only with failure criteria. (A run may still
    /// leave it without a value: too few failures for a B10 life.) Checked where a schedule is
    /// written; a stored schedule's statistics are read as they were written.
    pub fn given_by(&self, job: &Job) -> Result<(), String> {
        let computed = |metric: Metric| match metric {
            Metric::Operation(m) => job.operation_metrics().contains(&m),
            Metric::Device(m) => job.device_metrics().contains(&m),
        };
        match self.source {
            Source::Operations(Metric::Device(m), _) => Err(format!(
                "`{0}` is a device metric, one value a device: write devices.{0}.STAT",
                m.name()
            )),
            Source::Devices(Metric::Operation(m), _) => Err(format!(
                "`{0}` is an operation metric, summarised per bin: write operations.{0}.STAT",
                m.name()
            )),
            // Not the template's `metrics` at fault: no job has them without the polarity.
            Source::Devices(Metric::Device(m), _)
                if m.needs_polarity()
                    && job
                        .spec()
                        .scenario
                        .material
                        .anode_erosion_fraction
                        .is_none() =>
            {
                Err(needs_polarity(m.name()))
            }
            Source::Operations(metric, _) | Source::Devices(metric, _) if !computed(metric) => {
                Err(format!(
                    "the template's `metrics` leaves out `{}`: its runs have no value of it",
                    metric.name()
                ))
            }
            Source::Life(_) if job.failure().is_empty() => Err(format!(
                "`{}` needs failure criteria: the template has no `failure`",
                self.name
            )),
            _ => Ok(()),
        }
    }

    /// The statistic's value and 95 % interval in a result, if the result has it, with the reason
    /// a quantile the data cannot bound carries.
    pub fn read(&self, result: &JobResult) -> Option<Reading> {
        let bounded = |(value, ci95): (f64, [f64; 2])| Reading {
            value,
            ci95,
            reason: None,
        };
        let from_summary = |summary: &Summary, stat: SummaryStat| match stat {
            SummaryStat::Mean => Some(bounded((summary.mean, summary.mean_ci95))),
            SummaryStat::Quantile(name) => summary.quantiles.get(name).map(|q| Reading {
                value: q.value,
                ci95: q.ci95,
                reason: q.reason.clone(),
            }),
        };
        match self.source {
            Source::Operations(metric, stat) => {
                from_summary(&result.operations.get(metric.name())?.last()?.summary, stat)
            }
            Source::Devices(metric, stat) => from_summary(result.devices.get(metric.name())?, stat),
            Source::Life(which) => {
                let analysis = &result.life.as_ref()?.analysis;
                match which {
                    LifeStat::B1 => analysis.b1.as_ref().map(|b| (b.value, b.bounds())),
                    LifeStat::B10 => analysis.b10.as_ref().map(|b| (b.value, b.bounds())),
                    LifeStat::Beta => analysis.weibull.as_ref().map(|w| (w.beta, w.beta_ci95)),
                    LifeStat::Eta => analysis.weibull.as_ref().map(|w| (w.eta, w.eta_ci95)),
                }
                .map(bounded)
            }
        }
    }
}

/// A run's value of one statistic and its 95 % interval, with the reason its Result gives where
/// the data cannot bound it ([`Statistic::read`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    pub value: f64,
    pub ci95: [f64; 2],
    pub reason: Option<String>,
}

impl fmt::Display for Statistic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

impl Serialize for Statistic {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.name)
    }
}

impl<'de> Deserialize<'de> for Statistic {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        String::deserialize(deserializer)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// An interval as a person reads it: `1 h`, `30 min`, `1 d 2 h`, `45 s`.
fn describe_interval(interval: TimeDelta) -> String {
    let seconds = interval.num_seconds().max(0);
    let parts = [(86_400, "d"), (3_600, "h"), (60, "min"), (1, "s")];
    let mut rest = seconds;
    let mut text = Vec::new();
    for (unit, name) in parts {
        if rest >= unit {
            text.push(format!("{} {name}", rest / unit));
            rest %= unit;
        }
    }
    if text.is_empty() {
        "0 s".to_owned()
    } else {
        text.join(" ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Due times are whole seconds whatever fraction `now` has, so that two ticks or instances
    /// make the same key; and a run is made for the time the schedule listed, across DST: a fixed
    /// time in Berlin's repeated hour once, at its first occurrence, never for a night already
    /// past; one in the spring gap just after the gap; a weekly midnight in Havana's gap on its own
    /// Sunday, not the one before. Truths by hand from the zones' rules (zoneinfo).
    #[test]
    fn due_times_are_whole_seconds_and_those_listed_across_dst() {
        let berlin = Timetable::parse("30 2 * * *", "Europe/Berlin").unwrap();
        let now = utc("2027-05-02T09:13:20.168Z");
        assert_eq!(
            berlin.latest_at_or_before(now),
            Some(utc("2027-05-02T00:30:00Z"))
        );
        assert_eq!(berlin.next_after(now), Some(utc("2027-05-03T00:30:00Z")));
        // Fall back, 2027-10-31: 02:30 CEST is 00:30Z; at 01:10Z (02:10 CET, the repeated hour)
        // tonight's run is past and the next is tomorrow's 02:30 CET.
        let repeated = utc("2027-10-31T01:10:00.994Z");
        assert_eq!(
            berlin.next_after(repeated),
            Some(utc("2027-11-01T01:30:00Z"))
        );
        assert_eq!(
            berlin.latest_at_or_before(repeated),
            Some(utc("2027-10-31T00:30:00Z"))
        );
        // Spring forward, 2027-03-28: 02:30 does not exist; it runs at 03:00 CEST, 01:00Z.
        let listed = berlin.next_after(utc("2027-03-27T12:00:00Z"));
        assert_eq!(listed, Some(utc("2027-03-28T01:00:00Z")));
        let made = berlin.latest_at_or_before(utc("2027-03-28T01:00:05.5Z"));
        assert_eq!(made, listed);
        // Seconds that are not one value follow real time: none of them runs that night.
        let thrice = Timetable::parse("*/20 30 2 * * *", "Europe/Berlin").unwrap();
        let next = thrice.next_after(utc("2027-03-27T12:00:00Z"));
        assert_eq!(next, Some(utc("2027-03-29T00:30:00Z")));
        // Havana skips from 00:00 to 01:00 on Sunday 2027-03-14 (CST, UTC-5, to CDT, UTC-4).
        let havana = Timetable::parse("0 0 * * 0", "America/Havana").unwrap();
        let listed = havana.next_after(utc("2027-03-10T00:00:00Z"));
        assert_eq!(listed, Some(utc("2027-03-14T05:00:00Z")));
        let made = havana.latest_at_or_before(utc("2027-03-14T05:00:01Z"));
        assert_eq!(made, listed);
        // A yearly cron looks back far enough.
        let yearly = Timetable::parse("0 3 1 1 *", "UTC").unwrap();
        let made = yearly.latest_at_or_before(utc("2027-12-31T00:00:00Z"));
        assert_eq!(made, Some(utc("2027-01-01T03:00:00Z")));
    }

    #[test]
    fn the_wall_clock_is_the_schedules_zone_to_the_minute_or_second() {
        let definition = ScheduleDefinition {
            name: "nightly".into(),
            cron: "0 1 * * *".into(),
            time_zone: "Europe/Berlin".into(),
            template: JobSpec::default(),
            statistics: Vec::new(),
            enabled: true,
        };
        // 00:00:00.123 UTC is 01:00 in Berlin in winter; two runs in one minute (run by hand)
        // are told apart by their seconds (their labels were the same, found from outside).
        assert_eq!(
            definition.wall_clock(&["2026-11-22T00:00:00.123Z", "2026-11-23T00:00:00Z", "x"]),
            ["2026-11-22 01:00", "2026-11-23 01:00", "x"]
        );
        assert_eq!(
            definition.wall_clock(&["2026-11-22T00:00:00.123Z", "2026-11-22T00:00:41Z"]),
            ["2026-11-22 01:00:00", "2026-11-22 01:00:41"]
        );
        assert_eq!(
            definition.wall_clock(&["2026-11-22T00:00:00.123Z", "2026-11-22T00:00:00.130Z"]),
            ["2026-11-22 01:00:00.123", "2026-11-22 01:00:00.130"]
        );
        // The due time itself, to the millisecond, is the scheduled run's slot; a manual run
        // takes the next millisecond.
        let at = |text| UnixMs::from_datetime(utc(text));
        assert!(definition.is_due_time(at("2026-11-22T00:00:00.000Z")));
        assert!(!definition.is_due_time(at("2026-11-22T00:00:00.001Z")));
        assert!(!definition.is_due_time(at("2026-11-21T23:59:59.999Z")));
        assert!(!definition.is_due_time(at("2026-11-22T01:00:00.000Z")));
        assert_eq!(
            definition.run_name(at("2026-11-22T00:00:00.123Z")),
            "nightly @ 2026-11-22T00:00:00.123Z"
        );
        let long = ScheduleDefinition {
            name: "\u{e9}".repeat(MAX_TEXT_CHARS),
            ..definition
        };
        let name = long.run_name(at("2026-11-22T00:00:00.123Z"));
        assert_eq!(name.chars().count(), MAX_TEXT_CHARS);
        assert!(
            name.ends_with("\u{e9} @ 2026-11-22T00:00:00.123Z"),
            "{name}"
        );
    }

    fn utc(text: &str) -> DateTime<Utc> {
        DateTime::parse_from_rfc3339(text)
            .unwrap()
            .with_timezone(&Utc)
    }

    #[test]
    fn a_night_at_three_follows_new_york_across_both_dst_changes() {
        let nightly = Timetable::parse("0 3 * * *", "America/New_York").unwrap();
        // EST (UTC-5) before 2026-03-08, EDT (UTC-4) after; back to EST on 2026-11-01.
        assert_eq!(
            nightly.next_after(utc("2026-03-07T12:00:00Z")),
            Some(utc("2026-03-08T07:00:00Z"))
        );
        assert_eq!(
            nightly.next_after(utc("2026-03-06T12:00:00Z")),
            Some(utc("2026-03-07T08:00:00Z"))
        );
        assert_eq!(
            nightly.next_after(utc("2026-10-31T12:00:00Z")),
            Some(utc("2026-11-01T08:00:00Z"))
        );
    }

    #[test]
    fn a_time_in_the_spring_gap_runs_after_the_gap_and_an_overlap_time_runs_once() {
        let at_half_past_two = Timetable::parse("30 2 * * *", "Europe/Berlin").unwrap();
        // 2026-03-29: 02:00 CET jumps to 03:00 CEST, so 02:30 does not exist; it runs at 03:00 CEST.
        assert_eq!(
            at_half_past_two.next_after(utc("2026-03-28T12:00:00Z")),
            Some(utc("2026-03-29T01:00:00Z"))
        );
        // 2026-10-25: 03:00 CEST falls back to 02:00 CET, so 02:30 happens twice; it runs at the first.
        let first = at_half_past_two
            .next_after(utc("2026-10-24T12:00:00Z"))
            .unwrap();
        assert_eq!(first, utc("2026-10-25T00:30:00Z"));
        assert_eq!(
            at_half_past_two.next_after(first),
            Some(utc("2026-10-26T01:30:00Z")),
            "not again at 01:30Z"
        );
    }

    /// In the hour before a spring-forward gap, a fixed time of that hour already past is next due
    /// the day after, not at the gap's end, where croner put it (a probe); one in the gap still
    /// runs at its end, and a time after the gap at that time. Truths from zoneinfo.
    #[test]
    fn a_time_before_the_spring_gap_is_not_moved_to_its_end() {
        // From 01:40 CET, and from 01:59 CET, just after a run at that time.
        let (at_01_40, at_01_59) = ("2027-03-28T00:40:00Z", "2027-03-28T00:59:00Z");
        for (cron, from, due) in [
            ("30 1 * * *", at_01_40, "2027-03-28T23:30:00Z"),
            ("15 1 * * *", at_01_40, "2027-03-28T23:15:00Z"),
            ("0 1 * * *", at_01_40, "2027-03-28T23:00:00Z"),
            ("45 1 * * *", at_01_40, "2027-03-28T00:45:00Z"),
            ("30 2 * * *", at_01_40, "2027-03-28T01:00:00Z"),
            ("0 3 * * *", at_01_40, "2027-03-28T01:00:00Z"),
            ("0 12 * * *", at_01_40, "2027-03-28T10:00:00Z"),
            ("59 1 * * *", at_01_59, "2027-03-28T23:59:00Z"),
            ("59 1 * * 0", at_01_59, "2027-04-03T23:59:00Z"),
            ("59 1 28 3 *", at_01_59, "2028-03-27T23:59:00Z"),
        ] {
            let timetable = Timetable::parse(cron, "Europe/Berlin").unwrap();
            assert_eq!(timetable.next_after(utc(from)), Some(utc(due)), "{cron}");
            // Nothing is made at the gap's end but for a time in the gap or at 03:00 itself.
            let gap_end = utc("2027-03-28T01:00:00Z");
            let made = timetable.latest_at_or_before(gap_end + TimeDelta::seconds(30));
            assert_eq!(
                made == Some(gap_end),
                utc(due) == gap_end,
                "{cron}: {made:?}"
            );
        }
    }

    /// Antarctica/Troll falls back two hours (03:00 +02 to 01:00 +00): from an instant in the
    /// second pass, a time in the overlap ran at its first pass and is next due the day after. The
    /// search gave up after an hour and a half, so the schedule's next run became none for good
    /// and the same cron was refused as "never runs" while in the overlap (a probe found it).
    #[test]
    fn a_two_hour_overlap_runs_its_times_once_and_goes_on() {
        for cron in ["50 2 * * *", "30 1 * * *"] {
            let daily = Timetable::parse(cron, "Antarctica/Troll").unwrap();
            let first = daily.next_after(utc("2027-10-30T12:00:00Z")).unwrap();
            for within in [
                "2027-10-31T01:05:00Z",
                "2027-10-31T02:40:00Z",
                "2027-10-31T02:59:59Z",
            ] {
                let next = daily.next_after(utc(within)).unwrap();
                assert_eq!(
                    next,
                    daily.next_after(first).unwrap(),
                    "{cron} from {within}"
                );
                assert!(
                    next > utc(within) && next > utc("2027-11-01T00:00:00Z"),
                    "{cron}: {next}"
                );
            }
        }
    }

    /// Havana falls back from 01:00 CDT (UTC-4) to 00:00 CST (UTC-5) on 2027-11-07: 00:00-00:59
    /// runs at 04:00-04:59Z and again at 05:00-05:59Z. An every-minute cron runs each wall-clock
    /// minute once, at its first pass; asked from the second pass, its next is 01:00 CST
    /// (06:00Z). A fixed step of half an hour past croner's answer made it 06:29Z (a probe
    /// against a brute-force reference). Truths by hand from the zone's rule.
    #[test]
    fn from_the_second_pass_of_an_overlap_the_next_run_follows_it() {
        let every_minute = Timetable::parse("* * * * *", "America/Havana").unwrap();
        for asked in [
            "2027-11-07T05:58:00Z",
            "2027-11-07T05:00:00Z",
            "2027-11-07T05:59:59Z",
        ] {
            assert_eq!(
                every_minute.next_after(utc(asked)),
                Some(utc("2027-11-07T06:00:00Z")),
                "{asked}"
            );
        }
        let mut due = utc("2027-11-07T03:59:00Z");
        let mut runs = Vec::new();
        while due < utc("2027-11-07T06:03:00Z") {
            due = every_minute.next_after(due).unwrap();
            runs.push(due);
        }
        assert_eq!(
            runs.len(),
            64,
            "60 minutes at the first pass, then 06:00-06:03Z"
        );
        assert_eq!(runs[59], utc("2027-11-07T04:59:00Z"));
        assert_eq!(runs[60], utc("2027-11-07T06:00:00Z"));
        let made = every_minute.latest_at_or_before(utc("2027-11-07T06:00:05Z"));
        assert_eq!(made, Some(utc("2027-11-07T06:00:00Z")));
        // Every quarter hour; and a half-hour overlap (Lord Howe, 02:00 +11 to 01:30 +10:30 on
        // 2027-04-04, 15:00Z): from 01:40 of the second pass the next is 02:00 +10:30.
        let quarterly = Timetable::parse("*/15 * * * *", "America/Havana").unwrap();
        let next = quarterly.next_after(utc("2027-11-07T05:20:00Z"));
        assert_eq!(next, Some(utc("2027-11-07T06:00:00Z")));
        let lord_howe = Timetable::parse("*/10 * * * *", "Australia/Lord_Howe").unwrap();
        let next = lord_howe.next_after(utc("2027-04-03T15:10:00Z"));
        assert_eq!(next, Some(utc("2027-04-03T15:30:00Z")));
    }

    /// In every IANA zone that falls back in 2027, around each of its changes (spring forward
    /// too), the next run asked at any instant is the first of the runs listed from before the
    /// change that lies after it: the
    /// schedule's runs are one sequence, whenever it is asked (the half-hour step answered 06:29Z
    /// from Havana's second pass where the sequence goes on at 06:00Z).
    #[test]
    fn the_next_run_is_the_listed_one_whenever_asked_across_every_fall_back() {
        let mut zones = 0;
        for zone in chrono_tz::TZ_VARIANTS {
            let offset = |at: DateTime<Utc>| utc_offset(&zone.from_utc_datetime(&at.naive_utc()));
            let year = utc("2027-01-01T00:00:00Z");
            let changes: Vec<DateTime<Utc>> = (0..365)
                .map(|d| year + TimeDelta::days(d))
                .filter(|&d| offset(d + TimeDelta::days(1)) != offset(d))
                .collect();
            if !changes
                .iter()
                .any(|&d| offset(d + TimeDelta::days(1)) < offset(d))
            {
                continue;
            }
            zones += 1;
            for (day, cron) in changes.iter().flat_map(|&day| {
                ["* * * * *", "*/7 * * * *", "30 * * * *", "15 1 * * *"].map(|cron| (day, cron))
            }) {
                let timetable = Timetable::parse(cron, zone.name()).unwrap();
                let mut listed = vec![timetable.next_after(day - TimeDelta::days(1)).unwrap()];
                while *listed.last().unwrap() < day + TimeDelta::days(3) {
                    let next = timetable.next_after(*listed.last().unwrap()).unwrap();
                    listed.push(next);
                }
                for step in 0..(48 * 6) {
                    let asked = day + TimeDelta::minutes(10 * step) + TimeDelta::seconds(17);
                    let expected = listed.iter().find(|&&due| due > asked).copied();
                    assert_eq!(
                        timetable.next_after(asked),
                        expected,
                        "{cron} in {zone} at {asked}"
                    );
                }
            }
        }
        assert!(zones > 50, "{zones} zones fall back in 2027");
    }

    #[test]
    fn catch_up_runs_only_the_latest_missed_night() {
        let nightly = Timetable::parse("0 3 * * *", "UTC").unwrap();
        let now = utc("2026-11-22T08:00:00Z");
        assert_eq!(
            nightly.latest_at_or_before(now),
            Some(utc("2026-11-22T03:00:00Z"))
        );
        assert_eq!(
            nightly.latest_at_or_before(utc("2026-11-22T03:00:00Z")),
            Some(utc("2026-11-22T03:00:00Z"))
        );
    }

    #[test]
    fn bad_cron_and_time_zone_name_their_field() {
        assert_eq!(
            Timetable::parse("every night", "UTC").unwrap_err()[0].0,
            "cron"
        );
        assert_eq!(
            Timetable::parse("0 3 * * *", "Mars/Olympus").unwrap_err()[0].0,
            "time_zone"
        );
        // The rule is stated, not only croner's "Number out of bounds" (a probe).
        let (field, message) = &Timetable::parse("60 * * * *", "UTC").unwrap_err()[0];
        assert_eq!(*field, "cron");
        assert!(
            message.contains("out of bounds") && message.contains("minute (0-59)"),
            "{message}"
        );
        let both = Timetable::parse("bad", "Mars/Olympus").unwrap_err();
        let fields: Vec<&str> = both.iter().map(|(field, _)| *field).collect();
        assert_eq!(fields, ["cron", "time_zone"]);
    }

    /// A schedule being written has 5 or 6 fields, as the API says; croner alone also reads a
    /// year (a seventh field) and nicknames, which a stored schedule keeps.
    #[test]
    fn a_written_cron_has_five_or_six_fields() {
        for cron in ["0 3 * * *", "30 0 3 * * *"] {
            assert!(Timetable::parse_written(cron, "UTC").is_ok(), "{cron}");
        }
        for (cron, count) in [
            ("0 0 3 * * * 2027", "has 7 fields"),
            ("@daily", "has 1 field:"),
            ("0 3 * *", "has 4 fields"),
            ("", "has 0 fields"),
        ] {
            let wrong = Timetable::parse_written(cron, "Mars/Olympus").unwrap_err();
            assert_eq!(wrong[0].0, "cron", "{cron}");
            assert!(wrong[0].1.contains(count), "{cron}: {}", wrong[0].1);
            assert_eq!(wrong[1].0, "time_zone", "{cron}");
        }
        for stored in ["0 0 3 * * * 2027", "@daily"] {
            assert!(Timetable::parse(stored, "UTC").is_ok(), "{stored}");
        }
        // croner reads an empty item of a list as if it were not there.
        for (cron, field) in [(",1 * * * *", "`,1`"), ("0 1,,2 * * *", "`1,,2`")] {
            let wrong = Timetable::parse_written(cron, "UTC").unwrap_err();
            assert_eq!(wrong[0].0, "cron", "{cron}");
            assert!(
                wrong[0]
                    .1
                    .contains(&format!("empty item in the list {field}")),
                "{cron}"
            );
        }
    }

    /// The last Sunday of a month is `0L` or `7L`, as 0 and 7 are Sunday elsewhere; croner
    /// matched no day for `7L` (2027-03-28 and 2027-10-31 are last Sundays, by the calendar).
    #[test]
    fn a_last_sunday_is_written_with_zero_or_seven() {
        for cron in ["0 0 * * 7L", "0 0 * * 0L", "0 0 * * SUNL"] {
            let last_sunday = Timetable::parse_written(cron, "UTC").unwrap();
            let next = last_sunday.next_after(utc("2027-03-01T00:00:00Z"));
            assert_eq!(next, Some(utc("2027-03-28T00:00:00Z")), "{cron}");
            let later = last_sunday.next_after(next.unwrap());
            assert_eq!(later, Some(utc("2027-04-25T00:00:00Z")), "{cron}");
        }
        // A day of the month and a weekday run on either, as in Vixie cron: after Monday
        // 2027-03-29 comes Thursday the 1st (both at once would be Monday 2027-11-01).
        let first_or_monday = Timetable::parse_written("0 3 1 * MON", "UTC").unwrap();
        let next = first_or_monday.next_after(utc("2027-03-29T04:00:00Z"));
        assert_eq!(next, Some(utc("2027-04-01T03:00:00Z")));
        let second_monday = Timetable::parse_written("0 3 * * 1#2", "UTC").unwrap();
        let next = second_monday.next_after(utc("2027-03-01T04:00:00Z"));
        assert_eq!(next, Some(utc("2027-03-08T03:00:00Z")));
        // In a list, with seconds: Mondays and the last Sunday.
        let with_mondays = Timetable::parse_written("0 0 0 * * 1,7l", "UTC").unwrap();
        let next = with_mondays.next_after(utc("2027-03-25T00:00:00Z"));
        assert_eq!(next, Some(utc("2027-03-28T00:00:00Z")));
        let next = with_mondays.next_after(next.unwrap());
        assert_eq!(next, Some(utc("2027-03-29T00:00:00Z")));
    }

    #[test]
    fn statistics_are_parsed_and_keep_their_name() {
        for name in [
            "operations.total_bounce_s.p95",
            "devices.eroded_mass_kg.mean",
            "life.b10",
        ] {
            assert_eq!(name.parse::<Statistic>().unwrap().as_str(), name);
        }
        for name in [
            "operations.total_bounce_s.p42",
            "operations.no_such_metric.mean",
            "life.mtbf",
        ] {
            assert!(name.parse::<Statistic>().is_err(), "{name}");
        }
    }

    #[test]
    fn a_statistic_reads_its_value_and_interval_from_a_result() {
        // Velocity scattered per operation, so that devices fail at different operations.
        let job = Job::from_json(
            r#"{"devices": 16, "operations": 50, "seed": 1,
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                  "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.04, "min": 0.05}}],
                "failure": {"total_bounce_s": {"above": 0.013}}}"#,
            || 1,
        )
        .unwrap();
        let result =
            bouncewear_model::montecarlo::run_job(&job, &bouncewear_model::montecarlo::Silent)
                .unwrap();
        let last_bin = &result.operations["total_bounce_s"].last().unwrap().summary;
        let p95 = &last_bin.quantiles["p95"];
        let read = |name: &str| {
            let reading = name.parse::<Statistic>().unwrap().read(&result)?;
            Some((reading.value, reading.ci95))
        };
        assert_eq!(
            read("operations.total_bounce_s.p95"),
            Some((p95.value, p95.ci95))
        );
        assert_eq!(
            read("devices.eroded_mass_kg.mean").map(|(v, _)| v),
            Some(result.devices["eroded_mass_kg"].mean)
        );
        let weibull = result
            .life
            .as_ref()
            .unwrap()
            .analysis
            .weibull
            .as_ref()
            .unwrap();
        // A B-life's by likelihood ratio, as a comparison's: the delta method's are too narrow
        // with few failures, and drift was flagged where the data did not show it.
        let b10 = result.life.as_ref().unwrap().analysis.b10.as_ref().unwrap();
        assert_eq!(read("life.b10"), Some((b10.value, b10.lr_ci95.unwrap())));
        assert_eq!(read("life.eta"), Some((weibull.eta, weibull.eta_ci95)));
        assert_eq!(read("life.beta"), Some((weibull.beta, weibull.beta_ci95)));
    }

    /// Each statistic is one the template's runs give: the kind of metric its section names, a
    /// metric the template computes, life statistics only with failure criteria, none twice; the
    /// default statistic is checked too. Statistics that fit are taken.
    #[test]
    fn statistics_the_template_never_gives_are_refused() {
        let now = utc("2026-11-22T08:00:00Z");
        let parse = |template: &str, statistics: &str| {
            let statistics = if statistics.is_empty() {
                String::new()
            } else {
                format!(r#", "statistics": [{statistics}]"#)
            };
            let body = format!(
                r#"{{"name": "n", "cron": "0 3 * * *", "template": {template}{statistics}}}"#
            );
            ValidSchedule::parse(&body, HOURLY, now)
        };
        let refused = parse(
            r#"{"devices": 20, "operations": 50, "metrics": ["e1", "eroded_mass_kg"]}"#,
            r#""life.b1", "devices.total_bounce_s.mean", "operations.eroded_mass_kg.mean",
               "operations.total_bounce_s.p95", "operations.e1.p50", "operations.e1.p50",
               "devices.eroded_mass_kg.mean""#,
        )
        .unwrap_err();
        assert_eq!(
            refused.pointers(),
            [
                "/statistics/0",
                "/statistics/1",
                "/statistics/2",
                "/statistics/3",
                "/statistics/5"
            ]
        );
        let details: Vec<&str> = refused.errors().iter().map(|e| e.detail.as_str()).collect();
        for (detail, says) in details.iter().zip([
            "needs failure criteria",
            "operation metric",
            "device metric",
            "leaves out `total_bounce_s`",
            "listed twice",
        ]) {
            assert!(detail.contains(says), "{detail}: {says}");
        }
        // Anode and cathode masses exist only with the polarity, whatever the `metrics` (the
        // template's `metrics` was blamed where it had none).
        let unpolar = parse(r#"{}"#, r#""devices.anode_eroded_mass_kg.mean""#).unwrap_err();
        let detail = &unpolar.errors()[0].detail;
        assert!(detail.contains("anode_erosion_fraction"), "{detail}");
        let polar = r#"{"scenario": {"material": {"anode_erosion_fraction": 0.6}}}"#;
        assert!(parse(polar, r#""devices.anode_eroded_mass_kg.mean""#).is_ok());
        let defaulted = parse(r#"{"metrics": ["e1"]}"#, "").unwrap_err();
        assert_eq!(defaulted.pointers(), ["/statistics"]);
        assert!(defaulted.errors()[0].detail.contains("default"));
        let taken = parse(
            r#"{"metrics": ["e1", "eroded_mass_kg"], "failure": {"e1": {"below": 0.1}}}"#,
            r#""operations.e1.p50", "devices.eroded_mass_kg.mean", "life.b10""#,
        );
        assert_eq!(taken.unwrap().into_definition().statistics.len(), 3);
        assert!(
            parse("{}", "").is_ok(),
            "the default fits a template of every metric"
        );
    }

    const HOURLY: ScheduleLimits = ScheduleLimits {
        max_job_operations: u64::MAX,
        min_interval: TimeDelta::hours(1),
    };

    #[test]
    fn a_schedule_names_every_field_at_fault() {
        let invalid = ValidSchedule::parse(
            r#"{"name": " ", "cron": "every night", "template": {"devices": 0}, "statistics": ["life.mtbf"]}"#,
            HOURLY,
            utc("2026-11-22T08:00:00Z"),
        )
        .unwrap_err();
        assert_eq!(
            invalid.pointers(),
            ["/name", "/cron", "/template/devices", "/statistics/0"]
        );
    }

    /// Runs closer than the minimum interval are refused wherever they fall: every minute, twice
    /// in one hour of one day a week, or an hour apart across the autumn DST change.
    #[test]
    fn runs_closer_than_the_minimum_interval_are_refused_naming_the_cron() {
        let now = utc("2026-11-22T08:00:00Z");
        let check = |cron: &str, zone: &str| {
            let body = format!(
                r#"{{"name": "n", "cron": "{cron}", "time_zone": "{zone}", "template": {{}}}}"#
            );
            ValidSchedule::parse(&body, HOURLY, now).map(|_| ())
        };
        // The second run of the first pair too close, on the zone's wall clock (Tuesday 24
        // November 2026 03:30 in Berlin is 02:30 UTC).
        for (cron, zone, at) in [
            (
                "* * * * *",
                "UTC",
                "1 min apart at 2026-11-22 08:02:00 (UTC wall clock)",
            ),
            (
                "0,30 3 * * 2",
                "Europe/Berlin",
                "30 min apart at 2026-11-24 03:30:00 (Europe/Berlin wall clock)",
            ),
        ] {
            let invalid = check(cron, zone).unwrap_err();
            assert_eq!(invalid.errors().len(), 1, "{cron}");
            assert_eq!(invalid.errors()[0].pointer, "/cron");
            let detail = &invalid.errors()[0].detail;
            assert!(detail.contains("at least 1 h apart"), "{invalid:?}");
            assert!(detail.contains(at), "{detail}");
        }
        assert!(check("0 * * * *", "UTC").is_ok(), "hourly is allowed");
        // Disabled, it makes no runs: held to the interval only once enabled again.
        let disabled = |enabled: bool| {
            let body = format!(
                r#"{{"name": "n", "cron": "* * * * *", "template": {{}}, "enabled": {enabled}}}"#
            );
            ValidSchedule::parse(&body, HOURLY, now).map(|_| ())
        };
        assert!(disabled(false).is_ok());
        assert_eq!(disabled(true).unwrap_err().pointers(), ["/cron"]);
        assert!(check("0 3 * * *", "Europe/Berlin").is_ok());
        assert!(check("0 0 29 2 *", "UTC").is_ok(), "a leap day alone");
        let day = ScheduleLimits {
            min_interval: TimeDelta::hours(24),
            ..HOURLY
        };
        // The night the clocks go forward, two 03:00 runs in Berlin are 23 h apart: the zone's
        // doing, not the cron's, which runs once a day on the wall clock.
        let body =
            r#"{"name": "n", "cron": "0 3 * * *", "time_zone": "Europe/Berlin", "template": {}}"#;
        assert!(ValidSchedule::parse(body, day, now).is_ok());
        let utc_body = r#"{"name": "n", "cron": "0 3 * * *", "template": {}}"#;
        assert!(ValidSchedule::parse(utc_body, day, now).is_ok());
    }

    /// A plain nightly cron is accepted in every IANA zone, half-hour DST changes and midnight
    /// changes included: the minimum interval is measured on the wall clock's schedule.
    #[test]
    fn a_daily_cron_is_accepted_in_every_time_zone() {
        let now = utc("2026-11-22T08:00:00Z");
        for zone in chrono_tz::TZ_VARIANTS {
            for cron in ["30 1 * * *", "0 0 * * *", "30 2 * * *", "0 3 * * *"] {
                let body = format!(
                    r#"{{"name": "n", "cron": "{cron}", "time_zone": "{}", "template": {{}}}}"#,
                    zone.name()
                );
                let parsed = ValidSchedule::parse(&body, HOURLY, now);
                assert!(parsed.is_ok(), "{cron} in {}: {parsed:?}", zone.name());
            }
        }
    }

    #[test]
    fn a_cron_that_never_runs_is_refused() {
        let now = utc("2026-11-22T08:00:00Z");
        let body = r#"{"name": "n", "cron": "0 0 30 2 *", "template": {}}"#;
        let invalid = ValidSchedule::parse(body, HOURLY, now).unwrap_err();
        assert_eq!(invalid.pointers(), ["/cron"], "{invalid:?}");
        assert!(
            invalid.errors()[0].detail.contains("never runs"),
            "{invalid:?}"
        );
    }

    #[test]
    fn a_disabled_schedule_has_no_next_run() {
        let body = |enabled: bool| {
            format!(
                r#"{{"name": "n", "cron": "0 3 * * *", "template": {{}}, "enabled": {enabled}}}"#
            )
        };
        let now = UnixMs::from_datetime(utc("2026-11-22T08:00:00Z"));
        let next = |enabled| {
            ValidSchedule::parse(&body(enabled), HOURLY, now.to_datetime())
                .unwrap()
                .next_run_after(now)
        };
        assert_eq!(
            next(true),
            Some(UnixMs::from_datetime(utc("2026-11-23T03:00:00Z")))
        );
        assert_eq!(next(false), None);
    }

    /// A schedule due since `from` runs its latest time at or before now and misses the ones
    /// before, found stepping forward; past the cap, from now back; nothing from a time the
    /// timetable does not give to a now before its next.
    #[test]
    fn a_catch_up_runs_the_latest_time_and_counts_the_ones_before() {
        let at = |text| utc(text);
        let timetable = |cron| Timetable::parse(cron, "UTC").unwrap();
        let nightly = timetable("0 3 * * *");
        let caught = nightly.catch_up(at("2026-11-19T03:00:00Z"), at("2026-11-22T08:00:00Z"), 10);
        assert_eq!(
            caught,
            Some(CatchUp {
                due: at("2026-11-22T03:00:00Z"),
                missed: 3,
                last_missed: Some(at("2026-11-21T03:00:00Z")),
            })
        );
        let on_time = nightly.catch_up(at("2026-11-22T03:00:00Z"), at("2026-11-22T03:00:00Z"), 10);
        assert_eq!(on_time.map(|c| (c.missed, c.last_missed)), Some((0, None)));
        assert_eq!(
            nightly.catch_up(at("2026-11-22T05:00:00Z"), at("2026-11-22T05:30:00Z"), 10),
            None
        );
        // Every second, a day down: the cap counts, the latest two come from now back.
        let secondly = timetable("* * * * * *");
        let day = secondly.catch_up(at("2026-11-21T08:00:00Z"), at("2026-11-22T08:00:00Z"), 1000);
        assert_eq!(
            day,
            Some(CatchUp {
                due: at("2026-11-22T08:00:00Z"),
                missed: 1000,
                last_missed: Some(at("2026-11-22T07:59:59Z")),
            })
        );
        let late = secondly.catch_up(
            at("2026-11-22T08:00:00Z"),
            at("2026-11-22T08:00:04.5Z"),
            1000,
        );
        assert_eq!(late.map(|c| c.missed), Some(4));
    }

    /// A schedule replaced while its run is due (waiting for room in the queue) keeps that due
    /// time while the new timetable runs then too, however it is written; one whose next run is
    /// ahead, or whose new timetable does not run at the due time, gets the new document's; a
    /// disabled one none.
    #[test]
    fn a_replaced_schedule_keeps_a_night_still_owed_by_its_timetable() {
        let body = |cron: &str, zone: &str, enabled: bool| {
            format!(
                r#"{{"name": "n", "cron": "{cron}", "time_zone": "{zone}", "template": {{}}, "enabled": {enabled}}}"#
            )
        };
        let at = |text| UnixMs::from_datetime(utc(text));
        let now = at("2026-11-22T03:00:10Z");
        let parse = |cron, zone, enabled| {
            ValidSchedule::parse(&body(cron, zone, enabled), HOURLY, now.to_datetime()).unwrap()
        };
        let replacing =
            |cron, zone, enabled, due| parse(cron, zone, enabled).next_run_replacing(due, now);
        let owed = Some(at("2026-11-22T03:00:00Z"));
        let tomorrow = Some(at("2026-11-23T03:00:00Z"));
        assert_eq!(replacing("0 3 * * *", "UTC", true, owed), owed);
        assert_eq!(replacing("0  3 * *  *", "UTC", true, owed), owed);
        // Other words for a timetable that runs then too (22 November 2026 is a Sunday).
        for cron in ["0 0 3 * * *", "0 3 * * 0", "0 3 22 * *", "0 */3 * * *"] {
            assert_eq!(replacing(cron, "UTC", true, owed), owed, "{cron}");
        }
        assert_eq!(
            replacing("0 3 * * 1-5", "UTC", true, owed),
            Some(at("2026-11-23T03:00:00Z"))
        );
        assert_eq!(replacing("0 3 * * *", "UTC", true, tomorrow), tomorrow);
        assert_eq!(replacing("0 3 * * *", "UTC", true, None), tomorrow);
        assert_eq!(replacing("0 3 * * *", "UTC", false, owed), None);
        // A new timetable owes nothing of the old one: its first time after the edit.
        assert_eq!(
            replacing("0 4 * * *", "UTC", true, owed),
            Some(at("2026-11-22T04:00:00Z"))
        );
        assert_eq!(
            replacing("0 3 * * *", "Europe/Berlin", true, owed),
            Some(at("2026-11-23T02:00:00Z"))
        );
    }
}
