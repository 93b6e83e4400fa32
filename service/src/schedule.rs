//! Schedules: a job template run on a cron expression in a time zone, and the night-by-night trend of
//! chosen statistics with a drift flag.

use bouncewear_model::montecarlo::JobResult;
use bouncewear_model::stats::Summary;
use chrono::{DateTime, TimeZone, Utc};
use chrono_tz::Tz;
use croner::Cron;
use serde::Serialize;
use std::str::FromStr;
use utoipa::ToSchema;

/// A parsed cron expression with its time zone.
#[derive(Debug, Clone)]
pub struct Timetable {
    cron: Cron,
    time_zone: Tz,
}

impl Timetable {
    /// Parses a cron expression (5 fields, or 6 with seconds first) and an IANA time zone name.
    /// Errors are `(field, message)`.
    pub fn parse(cron: &str, time_zone: &str) -> Result<Self, (&'static str, String)> {
        let parsed =
            Cron::from_str(cron).map_err(|e| ("cron", format!("is not a cron expression: {e}")))?;
        let time_zone = Tz::from_str(time_zone).map_err(|_| {
            (
                "time_zone",
                format!("`{time_zone}` is not an IANA time zone"),
            )
        })?;
        Ok(Self {
            cron: parsed,
            time_zone,
        })
    }

    /// The first due time strictly after `after`. Wall-clock times follow the time zone, DST
    /// included: a fixed time in a spring-forward gap runs right after the gap, and a fixed time in
    /// a fall-back overlap runs once, at its first occurrence (croner, after Vixie cron).
    pub fn next_after(&self, after: DateTime<Utc>) -> Option<DateTime<Utc>> {
        let local = self.time_zone.from_utc_datetime(&after.naive_utc());
        self.cron
            .find_next_occurrence(&local, false)
            .ok()
            .map(|t| t.with_timezone(&Utc))
    }

    /// The last due time at or before `now`: the one night a catch-up runs, however many were missed.
    pub fn latest_at_or_before(&self, now: DateTime<Utc>) -> Option<DateTime<Utc>> {
        let local = self.time_zone.from_utc_datetime(&now.naive_utc());
        self.cron
            .find_previous_occurrence(&local, true)
            .ok()
            .map(|t| t.with_timezone(&Utc))
    }
}

/// A statistic a schedule follows from night to night, written `operations.METRIC.STAT` (last bin),
/// `devices.METRIC.STAT` (`STAT` is `mean` or `p01`..`p99`), or `life.b1`, `life.b10`, `life.beta`,
/// `life.eta`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Statistic(pub String);

impl Statistic {
    pub fn check(text: &str) -> Result<Self, String> {
        let parts: Vec<&str> = text.split('.').collect();
        let summary_stat = |stat: &str| {
            stat == "mean"
                || bouncewear_model::stats::QUANTILES
                    .iter()
                    .any(|(name, _)| *name == stat)
        };
        let valid = match parts.as_slice() {
            ["operations" | "devices", metric, stat] => {
                bouncewear_model::montecarlo::Metric::parse(metric).is_some() && summary_stat(stat)
            }
            ["life", "b1" | "b10" | "beta" | "eta"] => true,
            _ => false,
        };
        if valid {
            Ok(Self(text.to_owned()))
        } else {
            Err(format!(
                "`{text}` is not a statistic: use operations.METRIC.STAT, devices.METRIC.STAT (STAT mean or p01..p99) or life.b1|b10|beta|eta"
            ))
        }
    }

    /// The statistic's value and 95 % interval in a result, if the result has it.
    pub fn read(&self, result: &JobResult) -> Option<(f64, [f64; 2])> {
        let parts: Vec<&str> = self.0.split('.').collect();
        let from_summary = |summary: &Summary, stat: &str| {
            if stat == "mean" {
                Some((summary.mean, summary.mean_ci95))
            } else {
                summary.quantiles.get(stat).map(|q| (q.value, q.ci95))
            }
        };
        match parts.as_slice() {
            ["operations", metric, stat] => {
                from_summary(&result.operations.get(*metric)?.last()?.summary, stat)
            }
            ["devices", metric, stat] => from_summary(result.devices.get(*metric)?, stat),
            ["life", which] => {
                let analysis = &result.life.as_ref()?.analysis;
                match *which {
                    "b1" => analysis.b1.as_ref().map(|b| (b.value, b.ci95)),
                    "b10" => analysis.b10.as_ref().map(|b| (b.value, b.ci95)),
                    "beta" => analysis.weibull.as_ref().map(|w| (w.beta, w.beta_ci95)),
                    "eta" => analysis.weibull.as_ref().map(|w| (w.eta, w.eta_ci95)),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

/// One night's value of one statistic.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct TrendValue {
    pub value: f64,
    pub ci95: [f64; 2],
    /// The value left the previous night's 95 % interval.
    pub drift: bool,
}

/// Flags every value that leaves the interval of the value before it (nights without a value are
/// skipped: the comparison is with the last night that has one).
pub fn flag_drift(values: &[Option<(f64, [f64; 2])>]) -> Vec<Option<TrendValue>> {
    let mut previous: Option<[f64; 2]> = None;
    values
        .iter()
        .map(|entry| {
            entry.map(|(value, ci95)| {
                let drift = previous.is_some_and(|[lo, hi]| value < lo || value > hi);
                previous = Some(ci95);
                TrendValue { value, ci95, drift }
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
            Timetable::parse("every night", "UTC").unwrap_err().0,
            "cron"
        );
        assert_eq!(
            Timetable::parse("0 3 * * *", "Mars/Olympus").unwrap_err().0,
            "time_zone"
        );
    }

    #[test]
    fn drift_is_a_value_outside_the_previous_nights_interval() {
        let flags = flag_drift(&[
            Some((1.0, [0.9, 1.1])),
            Some((1.05, [0.95, 1.15])),
            None,
            Some((1.3, [1.2, 1.4])),
            Some((1.35, [1.25, 1.45])),
        ]);
        let drift: Vec<Option<bool>> = flags.iter().map(|f| f.as_ref().map(|v| v.drift)).collect();
        assert_eq!(
            drift,
            [Some(false), Some(false), None, Some(true), Some(false)]
        );
    }

    #[test]
    fn statistics_are_checked_and_read() {
        assert!(Statistic::check("operations.total_bounce_s.p95").is_ok());
        assert!(Statistic::check("devices.eroded_mass_kg.mean").is_ok());
        assert!(Statistic::check("life.b10").is_ok());
        assert!(Statistic::check("operations.total_bounce_s.p42").is_err());
        assert!(Statistic::check("life.mtbf").is_err());
    }
}
