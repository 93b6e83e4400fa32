//! Metrics a job can summarise (docs/contract.md "Job"): per operation, and per device at the end.

use crate::lanes::Real;
use crate::operation::{Outcome, Outcomes};
use serde::{Deserialize, Serialize};

/// A per-operation metric: one field of [`Outcome`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum OperationMetric {
    #[serde(rename = "impact_velocity_m_s")]
    ImpactVelocity,
    #[serde(rename = "kappa")]
    Kappa,
    #[serde(rename = "e1")]
    E1,
    #[serde(rename = "first_bounce_s")]
    FirstBounce,
    #[serde(rename = "total_bounce_s")]
    TotalBounce,
    #[serde(rename = "bounce_count")]
    BounceCount,
    #[serde(rename = "pre_arc_s")]
    PreArc,
    #[serde(rename = "arc_energy_j")]
    ArcEnergy,
    #[serde(rename = "peak_force_n")]
    PeakForce,
    #[serde(rename = "impact_duration_s")]
    ImpactDuration,
    #[serde(rename = "first_impact_plastic_work_j")]
    FirstImpactPlasticWork,
}

impl OperationMetric {
    pub const ALL: [OperationMetric; 11] = [
        Self::ImpactVelocity,
        Self::Kappa,
        Self::E1,
        Self::FirstBounce,
        Self::TotalBounce,
        Self::BounceCount,
        Self::PreArc,
        Self::ArcEnergy,
        Self::PeakForce,
        Self::ImpactDuration,
        Self::FirstImpactPlasticWork,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::ImpactVelocity => "impact_velocity_m_s",
            Self::Kappa => "kappa",
            Self::E1 => "e1",
            Self::FirstBounce => "first_bounce_s",
            Self::TotalBounce => "total_bounce_s",
            Self::BounceCount => "bounce_count",
            Self::PreArc => "pre_arc_s",
            Self::ArcEnergy => "arc_energy_j",
            Self::PeakForce => "peak_force_n",
            Self::ImpactDuration => "impact_duration_s",
            Self::FirstImpactPlasticWork => "first_impact_plastic_work_j",
        }
    }

    /// The metric's values on every lane of `outcomes`, as [`OperationMetric::value`] gives each
    /// lane's: the engine reads a bin's column straight from them, one dispatch per metric rather
    /// than per lane (a whole-number count lane is its `u32` as f64 already).
    #[inline(always)]
    pub fn lanes<L: Real>(self, outcomes: &Outcomes<L>) -> &L {
        match self {
            Self::ImpactVelocity => &outcomes.impact_velocity_m_s,
            Self::Kappa => &outcomes.kappa,
            Self::E1 => &outcomes.e1,
            Self::FirstBounce => &outcomes.first_bounce_s,
            Self::TotalBounce => &outcomes.total_bounce_s,
            Self::BounceCount => &outcomes.bounce_count,
            Self::PreArc => &outcomes.pre_arc_s,
            Self::ArcEnergy => &outcomes.arc_energy_j,
            Self::PeakForce => &outcomes.peak_force_n,
            Self::ImpactDuration => &outcomes.impact_duration_s,
            Self::FirstImpactPlasticWork => &outcomes.first_impact_plastic_work_j,
        }
    }

    #[inline]
    pub fn value(self, outcome: &Outcome) -> f64 {
        match self {
            Self::ImpactVelocity => outcome.impact_velocity_m_s,
            Self::Kappa => outcome.kappa,
            Self::E1 => outcome.e1,
            Self::FirstBounce => outcome.first_bounce_s,
            Self::TotalBounce => outcome.total_bounce_s,
            Self::BounceCount => f64::from(outcome.bounce_count),
            Self::PreArc => outcome.pre_arc_s,
            Self::ArcEnergy => outcome.arc_energy_j,
            Self::PeakForce => outcome.peak_force_n,
            Self::ImpactDuration => outcome.impact_duration_s,
            Self::FirstImpactPlasticWork => outcome.first_impact_plastic_work_j,
        }
    }

    /// Whether every value is a whole number (its quantiles are reported as whole numbers too).
    pub fn is_integer(self) -> bool {
        self == Self::BounceCount
    }

    /// Whether the metric needs the first-impact phase (section 4).
    pub fn needs_impact(self) -> bool {
        matches!(
            self,
            Self::PeakForce | Self::ImpactDuration | Self::FirstImpactPlasticWork
        )
    }
}

/// A per-device metric, taken at the end of the test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum DeviceMetric {
    #[serde(rename = "cumulative_arc_energy_j")]
    CumulativeArcEnergy,
    #[serde(rename = "eroded_mass_kg")]
    ErodedMass,
    #[serde(rename = "final_radius_m")]
    FinalRadius,
    #[serde(rename = "final_kappa")]
    FinalKappa,
    #[serde(rename = "cumulative_plastic_work_j")]
    CumulativePlasticWork,
    #[serde(rename = "anode_eroded_mass_kg")]
    AnodeErodedMass,
    #[serde(rename = "cathode_eroded_mass_kg")]
    CathodeErodedMass,
}

impl DeviceMetric {
    pub const ALL: [DeviceMetric; 7] = [
        Self::CumulativeArcEnergy,
        Self::ErodedMass,
        Self::FinalRadius,
        Self::FinalKappa,
        Self::CumulativePlasticWork,
        Self::AnodeErodedMass,
        Self::CathodeErodedMass,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::CumulativeArcEnergy => "cumulative_arc_energy_j",
            Self::ErodedMass => "eroded_mass_kg",
            Self::FinalRadius => "final_radius_m",
            Self::FinalKappa => "final_kappa",
            Self::CumulativePlasticWork => "cumulative_plastic_work_j",
            Self::AnodeErodedMass => "anode_eroded_mass_kg",
            Self::CathodeErodedMass => "cathode_eroded_mass_kg",
        }
    }

    /// Whether the metric splits the eroded mass by polarity, which needs the scenario's
    /// `material.anode_erosion_fraction`.
    pub fn needs_polarity(self) -> bool {
        matches!(self, Self::AnodeErodedMass | Self::CathodeErodedMass)
    }
}

/// Any metric, by its contract name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Metric {
    Operation(OperationMetric),
    Device(DeviceMetric),
}

impl Metric {
    pub fn parse(name: &str) -> Option<Self> {
        OperationMetric::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .map(Metric::Operation)
            .or_else(|| {
                DeviceMetric::ALL
                    .into_iter()
                    .find(|m| m.name() == name)
                    .map(Metric::Device)
            })
    }

    pub fn name(self) -> &'static str {
        match self {
            Metric::Operation(m) => m.name(),
            Metric::Device(m) => m.name(),
        }
    }

    /// The values one device gives a bin of this metric over `operations`: one an operation, or
    /// its one value for a device metric. A bin's values over it are its number of devices, the
    /// units independent whatever the scatter ([`crate::stats::summarize`]).
    pub fn values_per_device(self, operations: std::ops::Range<u64>) -> u64 {
        match self {
            Metric::Operation(_) => operations.end.saturating_sub(operations.start),
            Metric::Device(_) => 1,
        }
    }

    /// Whether the metric needs the first-impact phase (section 4), at every operation.
    pub fn needs_impact(self) -> bool {
        match self {
            Metric::Operation(m) => m.needs_impact(),
            Metric::Device(m) => m == DeviceMetric::CumulativePlasticWork,
        }
    }

    /// Every name, for error messages.
    pub fn all_names() -> String {
        let operation = OperationMetric::ALL.iter().map(|m| m.name());
        let device = DeviceMetric::ALL.iter().map(|m| m.name());
        operation.chain(device).collect::<Vec<_>>().join(", ")
    }
}

/// Why the anode/cathode metric `name` cannot be had without the scenario's polarity: its fault
/// wherever a job names it.
pub fn needs_polarity(name: &str) -> String {
    format!(
        "`{name}` needs the anode's share of the eroded mass: set the job's \
         /scenario/material/anode_erosion_fraction"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::Lanes;

    #[test]
    fn lanes_give_each_lanes_value() {
        // Every field distinct on every lane, the count a whole number.
        let field = |f: f64| Lanes::<4>(std::array::from_fn(|k| f + k as f64 / 8.0));
        let outcomes = Outcomes {
            impact_velocity_m_s: field(1.0),
            kappa: field(2.0),
            e1: field(3.0),
            first_bounce_s: field(4.0),
            total_bounce_s: field(5.0),
            bounce_count: Lanes(std::array::from_fn(|k| k as f64 + 1.0)),
            pre_arc_s: field(7.0),
            arc_energy_j: field(8.0),
            peak_force_n: field(9.0),
            impact_duration_s: field(10.0),
            truncated: field(0.0).lt(Lanes::splat(0.2)),
            first_impact_plastic_work_j: field(11.0),
        };
        for metric in OperationMetric::ALL {
            for k in 0..4 {
                let value = metric.value(&outcomes.lane(k));
                assert_eq!(metric.lanes(&outcomes).lane(k).to_bits(), value.to_bits());
            }
        }
    }
}
