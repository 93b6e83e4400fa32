//! The scenario of one make operation: docs/model.md sections 8 and 9, docs/contract.md "Scenario".
//!
//! [`ScenarioSpec`] is what a user writes: serde types where every field is optional and takes the
//! paper's rig (AgNi 80/20) as default, unknown fields rejected. [`Scenario`] is a spec that passed
//! every rule of docs/model.md section 9; it can only be built by [`Scenario::new`], so the hot
//! loop never re-validates.

use crate::error::{FieldError, InvalidInput, Pointer, shown};
use serde::{Deserialize, Serialize};

/// Every positive physical quantity must lie in `[MIN_MAGNITUDE, MAX_MAGNITUDE]` (and a non-negative
/// one may also be 0). Within this range no product or quotient the model forms leaves f64's range,
/// so a valid scenario always yields finite outputs.
pub const MIN_MAGNITUDE: f64 = 1e-30;
/// See [`MIN_MAGNITUDE`].
pub const MAX_MAGNITUDE: f64 = 1e30;
/// The largest `max_bounces` a scenario may ask for.
pub const MAX_BOUNCES_LIMIT: u32 = 10_000;

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScenarioSpec {
    /// The moving contact's mechanism (docs/model.md section 1); omitted fields take the paper's rig.
    pub mechanism: MechanismSpec,
    /// The contact material and its wear (sections 2-6); omitted fields take AgNi 80/20.
    pub material: MaterialSpec,
    /// The switched circuit; the default (0 V, 0 A) never arcs.
    pub circuit: CircuitSpec,
    /// Energy lost per impact and when a bounce sequence ends (section 7).
    pub losses: LossesSpec,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MechanismSpec {
    /// Moment of inertia of the moving arm about its pivot, kg m² (positive).
    pub inertia_kg_m2: f64,
    /// Stiffness of the contact spring, N/m (non-negative).
    pub spring_stiffness_n_per_m: f64,
    /// Distance from the pivot to the spring, m (positive).
    pub spring_arm_m: f64,
    /// Distance from the pivot to the contact, m (positive).
    pub contact_arm_m: f64,
    /// Contact force once closed, N (non-negative; positive when the spring stiffness is 0).
    pub static_force_n: f64,
    /// Travel of the contact before first touch, m (non-negative); sets the impact velocity by eq. 2.
    pub drop_height_m: f64,
    /// Overrides eq. 2 when given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub impact_velocity_m_s: Option<f64>,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MaterialSpec {
    /// Young's modulus of the contact material, Pa (positive).
    pub youngs_modulus_pa: f64,
    /// Dynamic yield pressure `p0` of a new surface, Pa (positive).
    pub dynamic_yield_pressure_pa: f64,
    /// Radius of curvature `r0` of a new contact, m (positive, at least `worn_radius_m`).
    pub contact_radius_m: f64,
    /// Overrides eq. 8 at the nominal radius and pressure when given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kappa: Option<f64>,
    /// Radius the surface roughens towards, `r_inf`, m (positive, at most `contact_radius_m`).
    pub worn_radius_m: f64,
    /// Arc energy that closes `1 - 1/e` of the radius' fall, J (positive).
    pub roughening_energy_j: f64,
    /// Mass eroded per joule of arc energy, kg/J (non-negative).
    pub erosion_kg_per_j: f64,
    /// Density of the contact material, kg/m³ (positive).
    pub density_kg_m3: f64,
    /// Minimum arc voltage: below it no arc burns, V (non-negative).
    pub min_arc_voltage_v: f64,
    /// Minimum arc current: below it no arc burns, A (non-negative).
    pub min_arc_current_a: f64,
    /// Field strength at which the gap breaks down before touch (pre-arc), V/m (positive).
    pub breakdown_field_v_per_m: f64,
    /// Arc energy over which the pre-arc softens the surface, J (positive).
    pub softening_energy_j: f64,
    /// Restitution after an arcing bounce (section 5).
    pub arc_restitution: ArcRestitutionSpec,
    /// How the surface changes with arc energy over an endurance test (section 6).
    pub wear_law: WearLawSpec,
    /// The share of the eroded mass the anode loses (the cathode loses the rest); the anode/cathode
    /// split of the eroded mass is reported only when it is given (docs/model.md section 6).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anode_erosion_fraction: Option<f64>,
}

/// Restitution after an arcing bounce (docs/model.md section 5).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArcRestitutionSpec {
    /// `continuous` (the default: eq. 16 scaled with the arc current) or `paper` (eq. 16 whenever
    /// an arc burns, with a cliff at the minimum arc current).
    pub law: ArcRestitutionLawKind,
    /// Coefficient `a` of eq. 16 (finite, magnitude at most 1e30).
    pub a: f64,
    /// Coefficient `b` of eq. 16, s/m (finite, magnitude at most 1e30).
    pub b_s_per_m: f64,
    /// The circuit current at which `a` and `b_s_per_m` were fitted (the paper: 15 A).
    pub calibration_current_a: f64,
}

/// Which post-arc restitution law applies (docs/model.md section 5).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ArcRestitutionLawKind {
    /// Eq. 16 whenever an arc burns, whatever its current: restitution jumps where the arc current
    /// crosses the minimum arc current (at 48 V the total bounce time falls from 28.6 ms at
    /// 0.5333 A to 13.3 ms at 0.5334 A), so a scattered current near it gives a bimodal result.
    Paper,
    /// The default. The arc's effect on restitution grows linearly with the arc current, from none
    /// at the minimum arc current to eq. 16 at the calibration current, and is eq. 16 to the bit
    /// at the calibration current and above (the paper measured 15 A only).
    #[default]
    Continuous,
}

/// How the surface changes with arc energy over an endurance test (docs/model.md section 6).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WearLawSpec {
    /// `roughening`, `constant` or `roughening_and_softening`.
    pub law: WearLawKind,
    /// `roughening_and_softening`: the dynamic yield pressure the arc-heated surface tends to.
    pub worn_pressure_pa: f64,
    /// `roughening_and_softening`: the arc energy that closes `1 - 1/e` of the pressure's fall.
    pub annealing_energy_j: f64,
}

/// Which wear law applies (docs/model.md section 6).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WearLawKind {
    /// Arc energy lowers the effective radius towards `worn_radius_m`.
    #[default]
    Roughening,
    /// Kappa is held at its new-contact value (the paper's suggestion, Section V.B).
    Constant,
    /// Roughening, and arc energy also lowers the dynamic yield pressure towards `worn_pressure_pa`.
    RougheningAndSoftening,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CircuitSpec {
    /// Supply voltage of the switched circuit, V (non-negative).
    pub supply_voltage_v: f64,
    /// Circuit current once closed, A (non-negative).
    pub current_a: f64,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossesSpec {
    /// Energy lost at each impact besides restitution, J (non-negative).
    pub impact_energy_loss_j: f64,
    /// Smallest peak gap that counts as a bounce, m (non-negative).
    pub min_separation_m: f64,
    /// Most bounces simulated per operation, 1 to 10000; longer sequences are cut and counted.
    pub max_bounces: u32,
}

impl Default for MechanismSpec {
    fn default() -> Self {
        Self {
            inertia_kg_m2: 1.593e-5,
            spring_stiffness_n_per_m: 200.0,
            spring_arm_m: 0.03,
            contact_arm_m: 0.03,
            static_force_n: 0.344,
            drop_height_m: 1e-3,
            impact_velocity_m_s: None,
        }
    }
}

impl Default for MaterialSpec {
    fn default() -> Self {
        Self {
            youngs_modulus_pa: 1.0e11,
            dynamic_yield_pressure_pa: 2.0e8,
            contact_radius_m: 7.7e-3,
            kappa: None,
            worn_radius_m: 0.711e-3,
            roughening_energy_j: 500.0,
            erosion_kg_per_j: 2e-9,
            density_kg_m3: 9950.0,
            min_arc_voltage_v: 12.0,
            min_arc_current_a: 0.4,
            breakdown_field_v_per_m: 1e8,
            softening_energy_j: 6.2e-4,
            arc_restitution: ArcRestitutionSpec::default(),
            wear_law: WearLawSpec::default(),
            anode_erosion_fraction: None,
        }
    }
}

impl Default for ArcRestitutionSpec {
    fn default() -> Self {
        Self {
            law: ArcRestitutionLawKind::Continuous,
            a: 0.235,
            b_s_per_m: 0.371,
            calibration_current_a: 15.0,
        }
    }
}

impl Default for WearLawSpec {
    fn default() -> Self {
        Self {
            law: WearLawKind::Roughening,
            worn_pressure_pa: 1.0e8,
            annealing_energy_j: 500.0,
        }
    }
}

impl Default for LossesSpec {
    fn default() -> Self {
        Self {
            impact_energy_loss_j: 1e-6,
            min_separation_m: 1e-7,
            max_bounces: 64,
        }
    }
}

/// A scenario that satisfies every rule of docs/model.md section 9.
/// The default is the paper's rig, which is valid.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
#[serde(transparent)]
pub struct Scenario(ScenarioSpec);

impl Scenario {
    /// Checks every rule before any computation; all failures are reported, each naming its field as a
    /// JSON pointer below `root` (`""` for a scenario document, `"/scenario"` inside a job).
    pub fn new(spec: ScenarioSpec, root: &Pointer) -> Result<Self, InvalidInput> {
        let mut errors = Vec::new();
        check_spec(&spec, root, &mut errors);
        if errors.is_empty() {
            Ok(Self(spec))
        } else {
            Err(InvalidInput::new(errors))
        }
    }

    /// Parses and validates a scenario document (JSON text).
    pub fn from_json(text: &str) -> Result<Self, InvalidInput> {
        let (spec, faults) = crate::error::read_past_faults::<ScenarioSpec>(text, &[])?;
        crate::error::with_faults(faults, Self::new(spec, &Pointer::root()))
    }

    pub fn spec(&self) -> &ScenarioSpec {
        &self.0
    }

    /// The scenario with Monte Carlo draws in place, not checked again: a job admits only
    /// distributions whose every value keeps its field valid (`montecarlo::job`'s domains).
    pub(crate) fn with_draws(&self, draw: impl FnOnce(&mut ScenarioSpec)) -> Self {
        let mut spec = self.0.clone();
        draw(&mut spec);
        Self(spec)
    }
}

/// Which rule a number must satisfy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    /// From [`MIN_MAGNITUDE`] to [`MAX_MAGNITUDE`].
    Positive,
    /// 0, or as [`Rule::Positive`].
    NonNegative,
    /// Magnitude at most [`MAX_MAGNITUDE`].
    Finite,
}

/// A number of a scenario with a rule of its own (docs/model.md section 9).
#[derive(Debug, Clone, Copy)]
pub struct NumberRule {
    /// Its place in a scenario: the section (and sub-section), then the field.
    pub path: &'static [&'static str],
    /// The spec type that holds it, as the OpenAPI document names its schema.
    pub schema: &'static str,
    pub rule: Rule,
    /// Its value in a scenario; `None` for an optional field left out.
    pub value: fn(&ScenarioSpec) -> Option<f64>,
}

impl NumberRule {
    /// The field's name, the last step of its path.
    pub fn field(&self) -> &'static str {
        self.path[self.path.len() - 1]
    }
}

/// A [`NumberRule`] from the field's place, written once: `number!(Positive, "MechanismSpec",
/// mechanism.inertia_kg_m2)` names the path and reads the value from the same words.
macro_rules! number {
    ($rule:ident, $schema:expr, $($step:ident).+) => {
        NumberRule {
            path: &[$(stringify!($step)),+],
            schema: $schema,
            rule: Rule::$rule,
            value: |s| Present::present(s.$($step).+),
        }
    };
}

/// A number field's value, `None` where an optional field is left out.
trait Present {
    fn present(self) -> Option<f64>;
}

impl Present for f64 {
    fn present(self) -> Option<f64> {
        Some(self)
    }
}

impl Present for Option<f64> {
    fn present(self) -> Option<f64> {
        self
    }
}

/// The one list of the scenario's number rules: `check_spec` applies them, the OpenAPI document
/// states them as each field's range. Rules that relate fields to each other follow in
/// `check_spec`.
pub const NUMBER_RULES: [NumberRule; 28] = {
    const MECHANISM: &str = "MechanismSpec";
    const MATERIAL: &str = "MaterialSpec";
    const ARC: &str = "ArcRestitutionSpec";
    const WEAR: &str = "WearLawSpec";
    const CIRCUIT: &str = "CircuitSpec";
    const LOSSES: &str = "LossesSpec";
    [
        number!(Positive, MECHANISM, mechanism.inertia_kg_m2),
        number!(NonNegative, MECHANISM, mechanism.spring_stiffness_n_per_m),
        number!(Positive, MECHANISM, mechanism.spring_arm_m),
        number!(Positive, MECHANISM, mechanism.contact_arm_m),
        number!(NonNegative, MECHANISM, mechanism.static_force_n),
        number!(NonNegative, MECHANISM, mechanism.drop_height_m),
        number!(NonNegative, MECHANISM, mechanism.impact_velocity_m_s),
        number!(Positive, MATERIAL, material.youngs_modulus_pa),
        number!(Positive, MATERIAL, material.dynamic_yield_pressure_pa),
        number!(Positive, MATERIAL, material.contact_radius_m),
        number!(Positive, MATERIAL, material.kappa),
        number!(Positive, MATERIAL, material.worn_radius_m),
        number!(Positive, MATERIAL, material.roughening_energy_j),
        number!(NonNegative, MATERIAL, material.erosion_kg_per_j),
        number!(Positive, MATERIAL, material.density_kg_m3),
        number!(NonNegative, MATERIAL, material.min_arc_voltage_v),
        number!(NonNegative, MATERIAL, material.min_arc_current_a),
        number!(Positive, MATERIAL, material.breakdown_field_v_per_m),
        number!(Positive, MATERIAL, material.softening_energy_j),
        number!(Finite, ARC, material.arc_restitution.a),
        number!(Finite, ARC, material.arc_restitution.b_s_per_m),
        number!(
            Positive,
            ARC,
            material.arc_restitution.calibration_current_a
        ),
        number!(Positive, WEAR, material.wear_law.worn_pressure_pa),
        number!(Positive, WEAR, material.wear_law.annealing_energy_j),
        number!(NonNegative, CIRCUIT, circuit.supply_voltage_v),
        number!(NonNegative, CIRCUIT, circuit.current_a),
        number!(NonNegative, LOSSES, losses.impact_energy_loss_j),
        number!(NonNegative, LOSSES, losses.min_separation_m),
    ]
};

fn check_number(errors: &mut Vec<FieldError>, pointer: Pointer, value: f64, rule: Rule) {
    let detail = if !value.is_finite() {
        Some("must be a finite number".to_owned())
    } else {
        match rule {
            Rule::Positive if value <= 0.0 => {
                Some(format!("must be positive, got {}", shown(value)))
            }
            Rule::NonNegative if value < 0.0 => {
                Some(format!("must be non-negative, got {}", shown(value)))
            }
            Rule::Positive | Rule::NonNegative
                if value != 0.0 && !(MIN_MAGNITUDE..=MAX_MAGNITUDE).contains(&value) =>
            {
                Some(format!(
                    "must lie between {MIN_MAGNITUDE:e} and {MAX_MAGNITUDE:e} (the supported range), got {value:e}"
                ))
            }
            Rule::Finite if value.abs() > MAX_MAGNITUDE => Some(format!(
                "must lie between -{MAX_MAGNITUDE:e} and {MAX_MAGNITUDE:e}, got {value:e}"
            )),
            _ => None,
        }
    };
    if let Some(detail) = detail {
        errors.push(FieldError {
            pointer: pointer.to_string(),
            detail,
        });
    }
}

fn check_spec(spec: &ScenarioSpec, root: &Pointer, errors: &mut Vec<FieldError>) {
    for number in &NUMBER_RULES {
        if let Some(value) = (number.value)(spec) {
            let pointer = number
                .path
                .iter()
                .fold(root.clone(), |at, step| at.child(step));
            check_number(errors, pointer, value, number.rule);
        }
    }
    let mech = &spec.mechanism;
    let at = root.child("mechanism");
    if mech.static_force_n == 0.0 && mech.spring_stiffness_n_per_m == 0.0 {
        errors.push(FieldError {
            pointer: at.child("static_force_n").to_string(),
            detail:
                "must be positive when spring_stiffness_n_per_m is 0 (nothing would return the arm)"
                    .to_owned(),
        });
    }

    let mat = &spec.material;
    let at = root.child("material");
    if mat.contact_radius_m > 0.0 && mat.worn_radius_m > mat.contact_radius_m {
        errors.push(FieldError {
            pointer: at.child("worn_radius_m").to_string(),
            detail: format!(
                "must not exceed contact_radius_m ({} m), got {} m",
                shown(mat.contact_radius_m),
                shown(mat.worn_radius_m)
            ),
        });
    }
    let (wear, at_wear) = (&mat.wear_law, at.child("wear_law"));
    if wear.law == WearLawKind::RougheningAndSoftening
        && wear.worn_pressure_pa > mat.dynamic_yield_pressure_pa
    {
        errors.push(FieldError {
            pointer: at_wear.child("worn_pressure_pa").to_string(),
            detail: format!(
                "must not exceed dynamic_yield_pressure_pa ({} Pa) under roughening_and_softening, got {} Pa",
                shown(mat.dynamic_yield_pressure_pa),
                shown(wear.worn_pressure_pa)
            ),
        });
    }
    // A non-zero fraction at least the least magnitude, as every other number: 5e-324 left an
    // anode's mass of exactly 0.
    if let Some(fraction) = mat.anode_erosion_fraction
        && !(fraction == 0.0 || (MIN_MAGNITUDE..=1.0).contains(&fraction))
    {
        errors.push(FieldError {
            pointer: at.child("anode_erosion_fraction").to_string(),
            detail: format!(
                "must be 0, or from {MIN_MAGNITUDE:e} to 1, got {}",
                crate::error::shown(fraction)
            ),
        });
    }

    let losses = &spec.losses;
    if !(1..=MAX_BOUNCES_LIMIT).contains(&losses.max_bounces) {
        errors.push(FieldError {
            pointer: root.child("losses").child("max_bounces").to_string(),
            detail: format!(
                "must be from 1 to {MAX_BOUNCES_LIMIT}, got {}",
                losses.max_bounces
            ),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pointers(text: &str) -> Vec<String> {
        match Scenario::from_json(text) {
            Ok(_) => Vec::new(),
            Err(invalid) => invalid.errors().iter().map(|e| e.pointer.clone()).collect(),
        }
    }

    #[test]
    fn empty_document_is_the_papers_rig() {
        assert_eq!(Scenario::from_json("{}").unwrap(), Scenario::default());
    }

    /// Each entry of `NUMBER_RULES` reads the field its path names: a value breaking its rule at
    /// that path is refused at that pointer, and the default scenario keeps every rule.
    #[test]
    fn every_number_rule_reads_the_field_it_names() {
        let defaults = ScenarioSpec::default();
        let defaults_json = serde_json::to_value(&defaults).unwrap();
        for number in &NUMBER_RULES {
            let bad = match number.rule {
                Rule::Positive | Rule::NonNegative => -1.0,
                Rule::Finite => 2.0 * MAX_MAGNITUDE,
            };
            let mut document = serde_json::json!({});
            let mut at = &mut document;
            for step in &number.path[..number.path.len() - 1] {
                at = &mut at[*step];
            }
            at[number.field()] = serde_json::json!(bad);
            let pointer = format!("/{}", number.path.join("/"));
            assert!(
                pointers(&document.to_string()).contains(&pointer),
                "{pointer} with {bad}"
            );
            // The accessor reads the same field as the path.
            let spec: ScenarioSpec = serde_json::from_value(document).unwrap();
            assert_eq!((number.value)(&spec), Some(bad), "{pointer}");
            if let Some(value) = (number.value)(&defaults) {
                assert_eq!(
                    defaults_json.pointer(&pointer),
                    Some(&serde_json::json!(value))
                );
            }
        }
    }

    /// One document per rule of section 9 that breaks it, and the field the error must name.
    const BROKEN_RULES: &[(&str, &str)] = &[
        (
            r#"{"mechanism":{"inertia_kg_m2":0}}"#,
            "/mechanism/inertia_kg_m2",
        ),
        (
            r#"{"mechanism":{"spring_stiffness_n_per_m":-1}}"#,
            "/mechanism/spring_stiffness_n_per_m",
        ),
        (
            r#"{"mechanism":{"spring_arm_m":-0.1}}"#,
            "/mechanism/spring_arm_m",
        ),
        (
            r#"{"mechanism":{"contact_arm_m":0}}"#,
            "/mechanism/contact_arm_m",
        ),
        (
            r#"{"mechanism":{"static_force_n":-0.1}}"#,
            "/mechanism/static_force_n",
        ),
        (
            r#"{"mechanism":{"drop_height_m":-1e-3}}"#,
            "/mechanism/drop_height_m",
        ),
        (
            r#"{"mechanism":{"impact_velocity_m_s":-1}}"#,
            "/mechanism/impact_velocity_m_s",
        ),
        (
            r#"{"mechanism":{"static_force_n":0,"spring_stiffness_n_per_m":0}}"#,
            "/mechanism/static_force_n",
        ),
        (
            r#"{"material":{"youngs_modulus_pa":0}}"#,
            "/material/youngs_modulus_pa",
        ),
        (
            r#"{"material":{"dynamic_yield_pressure_pa":-2e8}}"#,
            "/material/dynamic_yield_pressure_pa",
        ),
        (
            r#"{"material":{"contact_radius_m":0}}"#,
            "/material/contact_radius_m",
        ),
        (r#"{"material":{"kappa":0}}"#, "/material/kappa"),
        (
            r#"{"material":{"worn_radius_m":0.1}}"#,
            "/material/worn_radius_m",
        ),
        (
            r#"{"material":{"roughening_energy_j":0}}"#,
            "/material/roughening_energy_j",
        ),
        (
            r#"{"material":{"erosion_kg_per_j":-1}}"#,
            "/material/erosion_kg_per_j",
        ),
        (
            r#"{"material":{"density_kg_m3":0}}"#,
            "/material/density_kg_m3",
        ),
        (
            r#"{"material":{"min_arc_voltage_v":-12}}"#,
            "/material/min_arc_voltage_v",
        ),
        (
            r#"{"material":{"min_arc_current_a":-1}}"#,
            "/material/min_arc_current_a",
        ),
        (
            r#"{"material":{"breakdown_field_v_per_m":0}}"#,
            "/material/breakdown_field_v_per_m",
        ),
        (
            r#"{"material":{"softening_energy_j":0}}"#,
            "/material/softening_energy_j",
        ),
        (
            r#"{"material":{"arc_restitution":{"a":1e300}}}"#,
            "/material/arc_restitution/a",
        ),
        (
            r#"{"material":{"arc_restitution":{"calibration_current_a":0}}}"#,
            "/material/arc_restitution/calibration_current_a",
        ),
        (
            r#"{"material":{"wear_law":{"worn_pressure_pa":-1}}}"#,
            "/material/wear_law/worn_pressure_pa",
        ),
        (
            r#"{"material":{"wear_law":{"annealing_energy_j":0}}}"#,
            "/material/wear_law/annealing_energy_j",
        ),
        (
            r#"{"material":{"wear_law":{"law":"roughening_and_softening","worn_pressure_pa":3e8}}}"#,
            "/material/wear_law/worn_pressure_pa",
        ),
        (
            r#"{"material":{"anode_erosion_fraction":1.5}}"#,
            "/material/anode_erosion_fraction",
        ),
        (
            r#"{"material":{"anode_erosion_fraction":5e-324}}"#,
            "/material/anode_erosion_fraction",
        ),
        (
            r#"{"circuit":{"supply_voltage_v":-48}}"#,
            "/circuit/supply_voltage_v",
        ),
        (r#"{"circuit":{"current_a":-15}}"#, "/circuit/current_a"),
        (
            r#"{"losses":{"impact_energy_loss_j":-1e-6}}"#,
            "/losses/impact_energy_loss_j",
        ),
        (
            r#"{"losses":{"min_separation_m":-1}}"#,
            "/losses/min_separation_m",
        ),
        (r#"{"losses":{"max_bounces":0}}"#, "/losses/max_bounces"),
        (r#"{"losses":{"max_bounces":10001}}"#, "/losses/max_bounces"),
        (
            r#"{"mechanism":{"inertia_kg_m2":1e-40}}"#,
            "/mechanism/inertia_kg_m2",
        ),
        (
            r#"{"mechanism":{"static_force_n":1e40}}"#,
            "/mechanism/static_force_n",
        ),
    ];

    #[test]
    fn every_rule_of_section_9_names_its_field() {
        for &(text, pointer) in BROKEN_RULES {
            assert_eq!(pointers(text), vec![pointer.to_owned()], "{text}");
        }
    }

    #[test]
    fn malformed_documents_name_the_field_or_position() {
        let cases = [
            (r#"{"mechanism":{"bogus":1}}"#, "/mechanism/bogus"),
            (r#"{"losses":{"max_bounces":1.5}}"#, "/losses/max_bounces"),
            (r#"{"circuit":{"current_a":"15"}}"#, "/circuit/current_a"),
            (r#"{"circuit":[]}"#, "/circuit"),
            (r#"{"unknown_section":{}}"#, "/unknown_section"),
            (
                r#"{"material":{"wear_law":{"law":"melting"}}}"#,
                "/material/wear_law/law",
            ),
            (
                r#"{"material":{"arc_restitution":{"law":"linear"}}}"#,
                "/material/arc_restitution/law",
            ),
            (
                r#"{"material":{"wear_law":{"worn_radius_m":1e-3}}}"#,
                "/material/wear_law/worn_radius_m",
            ),
            (r#"{"mechanism":{"static_force_n":1}"#, ""),
            ("[]", ""),
        ];
        for (text, pointer) in cases {
            assert_eq!(pointers(text), vec![pointer.to_owned()], "{text}");
        }
    }

    #[test]
    fn all_failures_are_reported_together() {
        let found = pointers(r#"{"mechanism":{"inertia_kg_m2":-1},"circuit":{"current_a":-1}}"#);
        assert_eq!(found, ["/mechanism/inertia_kg_m2", "/circuit/current_a"]);
    }

    #[test]
    fn pointers_nest_below_the_root_they_are_given() {
        let spec = ScenarioSpec {
            circuit: CircuitSpec {
                supply_voltage_v: -1.0,
                current_a: 0.0,
            },
            ..Default::default()
        };
        let err = Scenario::new(spec, &Pointer::root().child("scenario")).unwrap_err();
        assert_eq!(
            err.errors()[0].pointer,
            "/scenario/circuit/supply_voltage_v"
        );
    }
}
