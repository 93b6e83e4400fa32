//! Warnings a Result carries about how far to trust its numbers (docs/contract.md "Result").

use super::job::{Job, Parameter};
use crate::arc::Arc;
use crate::error::Pointer;
use crate::scenario::ArcRestitutionLawKind;
use serde::{Deserialize, Serialize};

/// How far, as a factor either way, from its calibration current the paper's eq. 16 may be used
/// before a Result warns (docs/model.md section 5).
pub const PAPER_LAW_CURRENT_FACTOR: f64 = 2.0;

/// The quantiles of a scattered current that are checked against the calibration current.
const SCATTERED_CURRENT_QUANTILES: [f64; 2] = [0.01, 0.99];

/// One warning: the field of the job it concerns (a JSON pointer) and what to know about it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Diagnostic {
    pub pointer: String,
    pub detail: String,
}

/// The warnings of a job: under the paper's post-arc law, an arcing current (the nominal one, or
/// the 1st and 99th percentiles of a scattered one) more than [`PAPER_LAW_CURRENT_FACTOR`] away from
/// the calibration current.
pub fn diagnose(job: &Job) -> Vec<Diagnostic> {
    let spec = job.scenario().spec();
    let (mat, circuit) = (&spec.material, &spec.circuit);
    if mat.arc_restitution.law != ArcRestitutionLawKind::Paper {
        return Vec::new();
    }
    let scattered = job
        .scatter()
        .iter()
        .position(|s| s.parameter == Parameter::Current);
    let (pointer, currents) = match scattered {
        Some(i) => (
            Pointer::root()
                .child("scatter")
                .child(i)
                .child("distribution"),
            SCATTERED_CURRENT_QUANTILES.map(|q| job.scatter()[i].distribution.quantile(q)),
        ),
        None => (
            Pointer::root()
                .child("scenario")
                .child("circuit")
                .child("current_a"),
            [circuit.current_a; 2],
        ),
    };
    let calibration_a = mat.arc_restitution.calibration_current_a;
    let far = currents.into_iter().find(|&current_a| {
        let arcs = Arc::strike(
            circuit.supply_voltage_v,
            current_a,
            mat.min_arc_voltage_v,
            mat.min_arc_current_a,
            mat.breakdown_field_v_per_m,
            mat.softening_energy_j,
        )
        .is_some();
        arcs && !(calibration_a / PAPER_LAW_CURRENT_FACTOR
            ..=calibration_a * PAPER_LAW_CURRENT_FACTOR)
            .contains(&current_a)
    });
    far.map(|current_a| Diagnostic {
        pointer: pointer.to_string(),
        detail: format!(
            "arcs burn at {current_a} A, more than a factor {PAPER_LAW_CURRENT_FACTOR} from the \
             {calibration_a} A at which the paper fitted its post-arc law (eq. 16): its restitution \
             is an extrapolation here. \"material.arc_restitution.law\": \"continuous\" fades the \
             arc's effect out towards the minimum arc current (docs/model.md section 5)"
        ),
    })
    .into_iter()
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diagnose_json(text: &str) -> Vec<Diagnostic> {
        diagnose(&Job::from_json(text, || 1).unwrap())
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

    #[test]
    fn the_paper_law_far_from_15_a_warns_and_the_continuous_law_does_not() {
        let found = diagnose_json(
            r#"{"scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 0.6}}}"#,
        );
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].pointer, "/scenario/circuit/current_a");
        assert!(found[0].detail.contains("0.6 A"), "{}", found[0].detail);
        assert!(
            diagnose_json(
                r#"{"scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 0.6},
                    "material": {"arc_restitution": {"law": "continuous"}}}}"#
            )
            .is_empty()
        );
    }

    #[test]
    fn a_scattered_current_warns_at_its_tails() {
        let found = diagnose_json(
            r#"{"scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "scatter": [{"parameter": "current_a", "per": "device",
                             "distribution": {"kind": "uniform", "min": 10, "max": 40}}]}"#,
        );
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].pointer, "/scatter/0/distribution");
    }
}
