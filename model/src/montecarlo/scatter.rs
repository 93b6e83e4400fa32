//! What scatter varies and how often: a scattered parameter ([`Parameter`], named as its
//! scenario field), drawn per device or per operation ([`Per`]), from a distribution
//! ([`ScatterSpec`]). The job ([`super::job`]) checks it; correlation ([`super::correlation`])
//! couples entries of one `per`.

use super::distribution::DistributionSpec;
use crate::scenario::ScenarioSpec;
use serde::{Deserialize, Serialize};

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScatterSpec {
    /// The scenario value that varies.
    pub parameter: Parameter,
    /// `device`: drawn once per device; `operation`: drawn again for every operation.
    pub per: Per,
    /// The distribution it is drawn from; every value it can give must be valid for the parameter.
    pub distribution: DistributionSpec,
}

/// The scenario values scatter may replace, named as their scenario fields.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Parameter {
    /// The new-contact radius `r0` (docs/model.md section 6).
    #[serde(rename = "contact_radius_m")]
    ContactRadius,
    #[serde(rename = "dynamic_yield_pressure_pa")]
    DynamicYieldPressure,
    #[serde(rename = "impact_velocity_m_s")]
    ImpactVelocity,
    #[serde(rename = "drop_height_m")]
    DropHeight,
    #[serde(rename = "static_force_n")]
    StaticForce,
    #[serde(rename = "current_a")]
    Current,
    #[serde(rename = "breakdown_field_v_per_m")]
    BreakdownField,
    #[serde(rename = "inertia_kg_m2")]
    Inertia,
    #[serde(rename = "spring_stiffness_n_per_m")]
    SpringStiffness,
    #[serde(rename = "supply_voltage_v")]
    SupplyVoltage,
    #[serde(rename = "impact_energy_loss_j")]
    ImpactEnergyLoss,
    #[serde(rename = "min_separation_m")]
    MinSeparation,
    /// `material.arc_restitution.a`.
    #[serde(rename = "arc_restitution_a")]
    ArcRestitutionA,
    /// `material.arc_restitution.b_s_per_m`.
    #[serde(rename = "arc_restitution_b_s_per_m")]
    ArcRestitutionB,
    #[serde(rename = "erosion_kg_per_j")]
    ErosionRate,
    #[serde(rename = "roughening_energy_j")]
    RougheningEnergy,
    /// The override of eq. 8 at the scenario's nominal radius and pressure (`material.kappa`).
    #[serde(rename = "kappa")]
    Kappa,
}

impl Parameter {
    /// Whether the parameter is an argument of an operation (speed, radius, pressure) rather than
    /// one of its constants: scattering it needs no rebuild, and devices can differ in it while
    /// they run in lockstep.
    pub fn is_lane_value(self) -> bool {
        matches!(
            self,
            Parameter::ImpactVelocity | Parameter::ContactRadius | Parameter::DynamicYieldPressure
        )
    }

    /// Whether the parameter is a constant of the scenario that the operation's conditions do not
    /// carry: scattering it rebuilds the scenario's setup and wear law for each draw.
    pub fn is_scenario_constant(self) -> bool {
        !self.is_lane_value()
            && !matches!(
                self,
                Parameter::DropHeight
                    | Parameter::StaticForce
                    | Parameter::Current
                    | Parameter::BreakdownField
            )
    }

    /// The name a job gives it.
    pub fn name(self) -> String {
        serde_name(&self)
    }

    /// Puts `value` in its field of `spec`.
    pub fn set_in(self, spec: &mut ScenarioSpec, value: f64) {
        let (mech, mat) = (&mut spec.mechanism, &mut spec.material);
        let field = match self {
            Parameter::ContactRadius => &mut mat.contact_radius_m,
            Parameter::DynamicYieldPressure => &mut mat.dynamic_yield_pressure_pa,
            Parameter::ImpactVelocity => {
                mech.impact_velocity_m_s = Some(value);
                return;
            }
            Parameter::Kappa => {
                mat.kappa = Some(value);
                return;
            }
            Parameter::DropHeight => &mut mech.drop_height_m,
            Parameter::StaticForce => &mut mech.static_force_n,
            Parameter::Current => &mut spec.circuit.current_a,
            Parameter::BreakdownField => &mut mat.breakdown_field_v_per_m,
            Parameter::Inertia => &mut mech.inertia_kg_m2,
            Parameter::SpringStiffness => &mut mech.spring_stiffness_n_per_m,
            Parameter::SupplyVoltage => &mut spec.circuit.supply_voltage_v,
            Parameter::ImpactEnergyLoss => &mut spec.losses.impact_energy_loss_j,
            Parameter::MinSeparation => &mut spec.losses.min_separation_m,
            Parameter::ArcRestitutionA => &mut mat.arc_restitution.a,
            Parameter::ArcRestitutionB => &mut mat.arc_restitution.b_s_per_m,
            Parameter::ErosionRate => &mut mat.erosion_kg_per_j,
            Parameter::RougheningEnergy => &mut mat.roughening_energy_j,
        };
        *field = value;
    }
}

/// The name serde gives a unit variant.
fn serde_name<T: Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(name)) => name,
        _ => unreachable!("a unit variant serialises as its name"),
    }
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Per {
    Device,
    Operation,
}

impl Per {
    /// The name a job gives it.
    pub fn name(self) -> String {
        serde_name(&self)
    }
}
