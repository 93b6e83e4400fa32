//! Warnings a Result carries about how far to trust its numbers (docs/contract.md "Result").

use super::PrecisionReport;
use super::job::{Job, Parameter};
use crate::arc::Arc;
use crate::error::Pointer;
use crate::operation::Operation;
use crate::scenario::ArcRestitutionLawKind;
use serde::{Deserialize, Serialize};

/// How far, as a factor either way, from its calibration current a post-arc law may be used
/// before a Result warns (docs/model.md section 5).
pub const CALIBRATION_CURRENT_FACTOR: f64 = 2.0;

/// The quantiles of a scattered current that are checked against the calibration current.
const SCATTERED_CURRENT_QUANTILES: [f64; 2] = [0.01, 0.99];

/// The inputs the paper's measurements cover (docs/model.md sections 8 and 9): impact velocities from the
/// 0.1 m/s of the softening-energy fit to the 0.71 m/s of Fig. 4, static forces from Fig. 6's 0.344 N
/// to Fig. 19's 4.33 N.
pub const PAPER_IMPACT_VELOCITY_M_S: [f64; 2] = [0.1, 0.71];
pub const PAPER_STATIC_FORCE_N: [f64; 2] = [0.344, 4.33];

/// What a run met, counted over all its operations.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Operations run.
    pub operations: u64,
    /// Operations whose bounces reached `scenario.losses.max_bounces` with another to come: their
    /// bounce times and counts are cut short.
    pub operations_at_max_bounces: u64,
    /// Per scatter entry, in the job's order: random draws of its truncated distribution that fell
    /// outside `[min, max]` and were drawn again. Left out when there were none.
    #[serde(default, skip_serializing_if = "none_rejected")]
    pub truncation_rejections: Vec<u64>,
}

fn none_rejected(counts: &[u64]) -> bool {
    counts.iter().all(|&count| count == 0)
}

/// One warning: the field of the job it concerns (a JSON pointer) and what to know about it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Diagnostic {
    /// JSON pointer to the field of the job the warning concerns.
    pub pointer: String,
    /// What to know about it.
    pub detail: String,
}

/// The warning of a precision target met: the run stopped at the first batch whose interval was
/// narrow enough, and such an interval holds the truth less often than its 95 % (docs/contract.md
/// "Precision target": 87.5-92 % over 600-900 jobs of each kind, the mean 93.7 %). Said in the
/// Result itself, so that a decision resting on the interval sees it.
pub fn stopped_early(precision: &PrecisionReport) -> Option<Diagnostic> {
    precision.met.then(|| Diagnostic {
        pointer: "/precision".to_owned(),
        detail: format!(
            "the run stopped at the first batch whose {} interval met the target ({} devices): an \
             interval that stops a run when it is narrow enough holds the truth in about 90 % of \
             runs, not 95 %; for a 95 % interval run {} devices again with another seed and no \
             precision target",
            precision.statistic, precision.devices, precision.devices
        ),
    })
}

/// The warnings of a run: bounce sequences cut at `max_bounces`, an impact velocity or static force
/// outside the paper's measurements, the paper's post-arc law far from its calibration current, and
/// truncated distributions' rejected draws.
pub fn diagnose(job: &Job, counts: &Counts) -> Vec<Diagnostic> {
    let mut found = Vec::new();
    if counts.operations_at_max_bounces > 0 {
        found.push(Diagnostic {
            pointer: "/scenario/losses/max_bounces".to_owned(),
            detail: format!(
                "{} of {} operations reached max_bounces ({}) with another bounce to come: their \
                 bounce times and counts are cut short; a larger max_bounces runs them out",
                counts.operations_at_max_bounces,
                counts.operations,
                job.scenario().spec().losses.max_bounces
            ),
        });
    }
    let nominal_velocity =
        || Operation::nominal(job.scenario(), job.spec().fidelity).impact_velocity_m_s();
    for (parameter, field, [low, high], unit, nominal) in [
        (
            Parameter::ImpactVelocity,
            "impact velocity",
            PAPER_IMPACT_VELOCITY_M_S,
            "m/s",
            Pointer::root()
                .child("scenario")
                .child("mechanism")
                .child("impact_velocity_m_s"),
        ),
        (
            Parameter::StaticForce,
            "static force",
            PAPER_STATIC_FORCE_N,
            "N",
            Pointer::root()
                .child("scenario")
                .child("mechanism")
                .child("static_force_n"),
        ),
    ] {
        let (pointer, values) = match scattered_range(job, parameter) {
            Some(scattered) => scattered,
            None => {
                let value = match parameter {
                    Parameter::ImpactVelocity => nominal_velocity(),
                    _ => job.scenario().spec().mechanism.static_force_n,
                };
                (nominal, [value; 2])
            }
        };
        // Both ends named when both lie outside (a wide lognormal's 1st and 99th percentiles).
        let mut outside: Vec<f64> = values
            .into_iter()
            .filter(|v| !(low..=high).contains(v))
            .collect();
        outside.dedup();
        if !outside.is_empty() {
            let shown: Vec<String> = outside
                .iter()
                .map(|&v| format!("{} {unit}", crate::error::shown(v)))
                .collect();
            let (values, verb) = match outside.len() {
                1 => (shown.join(""), "is"),
                _ => (
                    format!("the 1st and 99th percentiles, {}", shown.join(" and ")),
                    "are",
                ),
            };
            found.push(Diagnostic {
                pointer: pointer.to_string(),
                detail: format!(
                    "{field} {values} {verb} outside the {low} to {high} {unit} the paper's \
                     measurements cover: the model extrapolates there (docs/model.md section 9)"
                ),
            });
        }
    }
    found.extend(current_far_from_calibration(job));
    found.extend(breakdown_gap_beyond_the_opening(job));
    found.extend(truncated_draws(counts));
    found.extend(few_devices_for_sobol(job, counts));
    found
}

/// A breakdown gap `d_b = V_s / E_b` wider than the contacts ever open (the drop height): the
/// pre-impact arc would strike before the arm moves, yet the model burns it over `d_b` at the
/// impact speed (docs/model.md section 5). An outside probe's 48 V at 1e3 V/m, 48 mm against
/// 1 mm, gave 29 J of arc with nothing said.
fn breakdown_gap_beyond_the_opening(job: &Job) -> Option<Diagnostic> {
    let spec = job.scenario().spec();
    let (circuit, mat, height) = (&spec.circuit, &spec.material, spec.mechanism.drop_height_m);
    // Only an arc that burns strikes; its gap is the model's own.
    let gap = Arc::strike(
        circuit.supply_voltage_v,
        circuit.current_a,
        mat.min_arc_voltage_v,
        mat.min_arc_current_a,
        mat.breakdown_field_v_per_m,
        mat.softening_energy_j,
    )?
    .breakdown_gap_m;
    (gap > height).then(|| Diagnostic {
        pointer: "/scenario/material/breakdown_field_v_per_m".to_owned(),
        detail: format!(
            "the pre-impact arc strikes at d_b = V_s / E_b = {gap:e} m, wider than the contacts \
             open (drop_height_m {height:e} m): the model burns it over d_b at the impact speed, \
             an arc longer than the contacts ever draw (docs/model.md section 5)"
        ),
    })
}

/// The fewest devices whose Sobol' intervals cover about as they claim: 0.93-0.96 at 512 devices,
/// 0.91-0.95 at 64 (docs/manual.md "Which input drives it").
pub const SOBOL_INTERVAL_DEVICES: u64 = 256;

/// Sobol' indices over fewer than [`SOBOL_INTERVAL_DEVICES`] devices: their intervals come from
/// the spread between devices, which the delta method reads too narrow with few of them. Measured
/// from outside (analytic indices of kappa, 200 seeds each): coverage 0.55-0.69 at 2 devices,
/// 0.86-0.92 at 16, 0.89-0.94 at 32, with nothing in the Result saying so.
fn few_devices_for_sobol(job: &Job, counts: &Counts) -> Option<Diagnostic> {
    let devices = counts.operations / job.spec().operations.max(1);
    (job.sensitivity() == Some(super::job::SensitivityMethod::Sobol)
        && devices < SOBOL_INTERVAL_DEVICES)
        .then(|| Diagnostic {
            pointer: "/devices".to_owned(),
            detail: format!(
                "Sobol' indices over {devices} devices: their intervals come from the spread \
                 between devices and are too narrow with so few (measured coverage of a 95 % \
                 interval: 0.55-0.69 at 2 devices, 0.86-0.92 at 16, 0.91-0.95 at 64); run \
                 {SOBOL_INTERVAL_DEVICES} devices or more when the intervals matter"
            ),
        })
}

/// Each scatter entry whose truncated distribution rejected draws: how many, against the draws kept.
fn truncated_draws(counts: &Counts) -> impl Iterator<Item = Diagnostic> + '_ {
    counts
        .truncation_rejections
        .iter()
        .enumerate()
        .filter(|(_, rejected)| **rejected > 0)
        .map(|(i, rejected)| Diagnostic {
            pointer: Pointer::root()
                .child("scatter")
                .child(i)
                .child("distribution")
                .to_string(),
            detail: format!(
                "{rejected} random draws fell outside the truncation window [min, max] and were \
                 drawn again: the values follow the truncated distribution, as asked; many \
                 rejections per kept draw mean the window cuts away much of the distribution"
            ),
        })
}

/// Where the job scatters `parameter`, its distribution's pointer and the 1st and 99th
/// percentiles ([`SCATTERED_CURRENT_QUANTILES`]) that stand for its range.
fn scattered_range(job: &Job, parameter: Parameter) -> Option<(Pointer, [f64; 2])> {
    let i = job
        .scatter()
        .iter()
        .position(|s| s.parameter == parameter)?;
    let pointer = Pointer::root()
        .child("scatter")
        .child(i)
        .child("distribution");
    let quantiles = SCATTERED_CURRENT_QUANTILES.map(|q| job.scatter()[i].distribution.quantile(q));
    Some((pointer, quantiles))
}

/// An arcing current (the nominal one, or one from the 1st to the 99th percentile of a scattered
/// one, at the highest supply drawn) more than [`CALIBRATION_CURRENT_FACTOR`] away from the
/// post-arc law's calibration current (the 15 A of the paper's tests by default), under either
/// law: the paper measured restitution after arcs at that current alone, so elsewhere eq. 16 (the
/// paper's law) or its fade and hold (the continuous law) stand in for a measurement.
fn current_far_from_calibration(job: &Job) -> Option<Diagnostic> {
    let spec = job.scenario().spec();
    let (mat, circuit) = (&spec.material, &spec.circuit);
    let (pointer, currents) = match scattered_range(job, Parameter::Current) {
        Some(scattered) => scattered,
        None => (
            Pointer::root()
                .child("scenario")
                .child("circuit")
                .child("current_a"),
            [circuit.current_a; 2],
        ),
    };
    let calibration_a = mat.arc_restitution.calibration_current_a;
    // Arcs burn most readily at the highest supply a job draws (a scattered one's 99th percentile).
    let supply_v = scattered_range(job, Parameter::SupplyVoltage)
        .map_or(circuit.supply_voltage_v, |(_, [_, high])| high);
    let arcs = |current_a: f64| {
        Arc::strike(
            supply_v,
            current_a,
            mat.min_arc_voltage_v,
            mat.min_arc_current_a,
            mat.breakdown_field_v_per_m,
            mat.softening_energy_j,
        )
        .is_some()
    };
    let [low, high] = currents;
    let (below, above) = (
        calibration_a / CALIBRATION_CURRENT_FACTOR,
        calibration_a * CALIBRATION_CURRENT_FACTOR,
    );
    // The lowest arcing current of the range under the window (a range from a current that
    // does not arc to one within the window arcs in between: it said nothing), else the highest
    // above it.
    let under = (low < below).then(|| high.min(below * (1.0 - f64::EPSILON)));
    let far = match under {
        Some(top) if arcs(top) => Some(lowest_arcing(low, top, arcs)),
        _ => (high > above && arcs(high)).then_some(high),
    };
    let current_a = far?;
    let law = match mat.arc_restitution.law {
        ArcRestitutionLawKind::Paper if current_a < calibration_a => {
            "the paper's law (eq. 16) is an extrapolation there; \"material.arc_restitution.law\": \
             \"continuous\" fades the arc's effect out towards the minimum arc current"
        }
        ArcRestitutionLawKind::Paper => "the paper's law (eq. 16) is an extrapolation there",
        ArcRestitutionLawKind::Continuous if current_a < calibration_a => {
            "the continuous law's restitution there is its linear fade between no arc and eq. 16, \
             not a measurement"
        }
        ArcRestitutionLawKind::Continuous => {
            "the continuous law holds eq. 16 there, where the paper measured nothing"
        }
    };
    Some(Diagnostic {
        pointer: pointer.to_string(),
        detail: format!(
            "arcs burn at {} A, more than a factor {CALIBRATION_CURRENT_FACTOR} from the \
             {calibration_a} A the post-arc law is calibrated at (`calibration_current_a`; the \
             paper's tests ran at 15 A): {law} (docs/model.md section 5)",
            crate::error::shown(current_a)
        ),
    })
}

/// The lowest current from `low` to `top` at which an arc burns, `top` being one: `low` where it
/// burns already, else by bisection (an arc burns from a current on as it rises).
fn lowest_arcing(low: f64, top: f64, arcs: impl Fn(f64) -> bool) -> f64 {
    if arcs(low) {
        return low;
    }
    let (mut quiet, mut burning) = (low, top);
    for _ in 0..64 {
        let middle = 0.5 * (quiet + burning);
        if middle <= quiet || middle >= burning {
            break;
        }
        if arcs(middle) {
            burning = middle;
        } else {
            quiet = middle;
        }
    }
    burning
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diagnose_json(text: &str) -> Vec<Diagnostic> {
        diagnose(&Job::from_json(text, || 1).unwrap(), &Counts::default())
    }

    /// A breakdown gap wider than the drop height is said; the default's 0.48 um is not.
    #[test]
    fn a_breakdown_gap_beyond_the_opening_warns() {
        let job = |field: f64| {
            diagnose_json(&format!(
                r#"{{"devices": 2, "operations": 2, "scenario": {{
                    "circuit": {{"supply_voltage_v": 48, "current_a": 15}},
                    "material": {{"breakdown_field_v_per_m": {field}}}}}}}"#
            ))
        };
        let wide = job(1e3);
        let said: Vec<_> = (wide.iter())
            .filter(|d| d.pointer == "/scenario/material/breakdown_field_v_per_m")
            .collect();
        assert_eq!(said.len(), 1, "{wide:?}");
        assert!(
            said[0].detail.contains("d_b = V_s / E_b = 4.8e-2 m"),
            "{}",
            said[0].detail
        );
        assert!(job(1e8).iter().all(|d| !d.pointer.contains("breakdown")));
    }

    /// Sobol' indices warn below 256 devices run, where their intervals cover too rarely; the
    /// regression's coefficients, which claim no interval, do not.
    #[test]
    fn sobol_indices_over_few_devices_warn() {
        let job = |devices: u64, method: &str| {
            let text = format!(
                r#"{{"devices": {devices}, "operations": 4, "sensitivity": {{"method": "{method}"}},
                    "scatter": [{{"parameter": "contact_radius_m", "per": "device",
                        "distribution": {{"kind": "lognormal", "median": 7.7e-3, "sigma": 0.4,
                                         "min": 7.11e-4}}}}]}}"#
            );
            Job::from_json(&text, || 1).unwrap()
        };
        let found = |devices: u64, method: &str| {
            let counts = Counts {
                operations: devices * 4,
                ..Counts::default()
            };
            diagnose(&job(devices, method), &counts)
        };
        let few = found(16, "sobol");
        assert_eq!(few.len(), 1, "{few:?}");
        assert_eq!(few[0].pointer, "/devices");
        assert!(
            few[0].detail.starts_with("Sobol' indices over 16 devices"),
            "{few:?}"
        );
        assert!(found(256, "sobol").is_empty());
        assert!(found(16, "regression").is_empty());
    }

    #[test]
    fn no_warning_without_arcs_or_near_the_calibration_current() {
        assert!(diagnose_json("{}").is_empty());
        assert!(
            diagnose_json(
                r#"{"scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}}}"#
            )
            .is_empty()
        );
    }

    /// Either law warns at an arcing current more than a factor 2 from its calibration current,
    /// saying what stands in for a measurement there; no law warns where no arc burns.
    #[test]
    fn an_arcing_current_far_from_15_a_warns_under_either_law() {
        let detail = |current_a: f64, law: &str| {
            let found = diagnose_json(&format!(
                r#"{{"scenario": {{"circuit": {{"supply_voltage_v": 48, "current_a": {current_a}}},
                    "material": {{"arc_restitution": {{"law": "{law}"}}}}}}}}"#
            ));
            assert!(found.len() <= 1, "{found:?}");
            found.first().map(|found| {
                assert_eq!(found.pointer, "/scenario/circuit/current_a");
                found.detail.clone()
            })
        };
        for law in ["paper", "continuous"] {
            for quiet in [7.5, 10.0, 15.0, 30.0, 0.3] {
                assert_eq!(detail(quiet, law), None, "{quiet} A, {law}");
            }
        }
        // What stands in for a measurement: eq. 16 (and, below, the continuous law named), or
        // the continuous law's fade below and hold above.
        for (current_a, law, says) in [
            (0.6, "paper", "\"continuous\" fades"),
            (40.0, "paper", "is an extrapolation there (docs"),
            (0.6, "continuous", "linear fade"),
            (7.49, "continuous", "linear fade"),
            (30.1, "continuous", "holds eq. 16"),
        ] {
            let found = detail(current_a, law).unwrap();
            let named = format!("arcs burn at {current_a} A");
            assert!(found.contains(&named) && found.contains(says), "{found}");
        }
        // A scattered current is judged from its 1st to its 99th percentile, named by its
        // entry; a range from a current that does not arc to one within the window arcs in
        // between, from about 0.53 A at 48 V (it said nothing: a re-probe); so does a current
        // whose arc burns only at the higher supplies a scattered supply draws.
        for (circuit, scatter, pointer, says) in [
            (
                r#"{"supply_voltage_v": 48, "current_a": 15}"#,
                r#"{"parameter": "current_a", "per": "device", "distribution":
                    {"kind": "normal", "mean": 15, "sd": 4, "min": 0}}"#,
                "/scatter/0/distribution",
                "arcs burn at 5.70",
            ),
            (
                r#"{"supply_voltage_v": 48, "current_a": 15}"#,
                r#"{"parameter": "current_a", "per": "device", "distribution":
                    {"kind": "uniform", "min": 0.1, "max": 20}}"#,
                "/scatter/0/distribution",
                "arcs burn at 0.53",
            ),
            (
                r#"{"supply_voltage_v": 0, "current_a": 1}"#,
                r#"{"parameter": "supply_voltage_v", "per": "device", "distribution":
                    {"kind": "uniform", "min": 20, "max": 48}}"#,
                "/scenario/circuit/current_a",
                "arcs burn at 1 A",
            ),
        ] {
            let found = diagnose_json(&format!(
                r#"{{"scenario": {{"circuit": {circuit}}}, "scatter": [{scatter}]}}"#
            ));
            assert_eq!(found.len(), 1, "{found:?}");
            assert_eq!(found[0].pointer, pointer);
            assert!(found[0].detail.contains(says), "{}", found[0].detail);
        }
    }

    #[test]
    fn cut_bounce_sequences_are_counted_over_every_group_and_warned_of() {
        use crate::montecarlo::{Silent, run_job};
        let job = Job::from_json(
            r#"{"devices": 40, "operations": 5, "scenario": {"losses": {"max_bounces": 3}}}"#,
            || 1,
        )
        .unwrap();
        let result = run_job(&job, &Silent).unwrap();
        // The default rig bounces 7 times mechanically: every operation is cut at 3.
        assert_eq!(
            result.counts,
            Counts {
                operations: 200,
                operations_at_max_bounces: 200,
                truncation_rejections: Vec::new(),
            }
        );
        assert_eq!(
            result.diagnostics[0].pointer,
            "/scenario/losses/max_bounces"
        );
        assert!(
            result.diagnostics[0]
                .detail
                .starts_with("200 of 200 operations")
        );
        let whole = run_job(
            &Job::from_json(r#"{"devices": 4, "operations": 5}"#, || 1).unwrap(),
            &Silent,
        )
        .unwrap();
        assert_eq!(whole.counts.operations_at_max_bounces, 0);
        assert!(whole.diagnostics.is_empty());
    }

    #[test]
    fn inputs_outside_the_papers_measurements_are_flagged_by_their_field() {
        let fast = diagnose_json(r#"{"scenario": {"mechanism": {"impact_velocity_m_s": 1.5}}}"#);
        assert_eq!(fast.len(), 1);
        assert_eq!(fast[0].pointer, "/scenario/mechanism/impact_velocity_m_s");
        assert!(fast[0].detail.contains("1.5 m/s"), "{}", fast[0].detail);
        let forces = diagnose_json(
            r#"{"scatter": [{"parameter": "static_force_n", "per": "device",
                             "distribution": {"kind": "uniform", "min": 0.3, "max": 2}}]}"#,
        );
        assert_eq!(forces.len(), 1);
        assert_eq!(forces[0].pointer, "/scatter/0/distribution");
        // A probe's lognormal velocity whose 1st percentile (0.0108) and 99th (3.38) both lie
        // outside: it named the first only.
        let wide = diagnose_json(
            r#"{"scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                             "distribution": {"kind": "lognormal", "median": 0.19, "sigma": 1.24}}]}"#,
        );
        assert_eq!(wide.len(), 1);
        assert!(
            wide[0]
                .detail
                .contains("the 1st and 99th percentiles, 0.01")
                && wide[0].detail.contains(" m/s and 3.")
                && wide[0].detail.contains("are outside"),
            "{}",
            wide[0].detail
        );
    }

    #[test]
    fn a_scattered_current_warns_at_its_tails() {
        let found = diagnose_json(
            r#"{"scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15},
                             "material": {"arc_restitution": {"law": "paper"}}},
                "scatter": [{"parameter": "current_a", "per": "device",
                             "distribution": {"kind": "uniform", "min": 10, "max": 40}}]}"#,
        );
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].pointer, "/scatter/0/distribution");
    }
}
