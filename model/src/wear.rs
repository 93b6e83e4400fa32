//! A device's surface across an endurance test (docs/model.md section 6).
//!
//! Arc energy changes the surface. Under the default law it roughens it: the effective contact
//! radius falls from the new-contact radius `r0` towards the worn radius `r_inf` as the cumulative
//! arc energy `W` grows, which lowers kappa (eq. 8) and the restitution of every later operation.
//! The paper's own suggestion (Section V.B) is to hold kappa constant; a third law also anneals the
//! surface, lowering the dynamic yield pressure towards a floor. Erosion removes `gamma` kg per joule.

use crate::elementary::exp;
use crate::lanes::Real;
use crate::operation::{Outcome, Outcomes};
use crate::scenario::{Scenario, WearLawKind};

/// The material constants of wear.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WearLaw {
    pub kind: WearLawKind,
    pub worn_radius_m: f64,
    /// `1 / W_r`, so that a radius costs one multiplication and one `exp`.
    inverse_roughening_energy: f64,
    pub worn_pressure_pa: f64,
    /// `1 / W_p`, as for the radius.
    inverse_annealing_energy: f64,
    pub erosion_kg_per_j: f64,
    pub density_kg_m3: f64,
    pub anode_erosion_fraction: Option<f64>,
}

impl WearLaw {
    pub fn new(scenario: &Scenario) -> Self {
        let material = &scenario.spec().material;
        Self {
            kind: material.wear_law.law,
            worn_radius_m: material.worn_radius_m,
            inverse_roughening_energy: 1.0 / material.roughening_energy_j,
            worn_pressure_pa: material.wear_law.worn_pressure_pa,
            inverse_annealing_energy: 1.0 / material.wear_law.annealing_energy_j,
            erosion_kg_per_j: material.erosion_kg_per_j,
            density_kg_m3: material.density_kg_m3,
            anode_erosion_fraction: material.anode_erosion_fraction,
        }
    }

    /// Effective radius after cumulative arc energy `W`: `r = r_inf + (r0 - r_inf) exp(-W / W_r)`
    /// when the law roughens; `r0` under the `constant` law.
    #[inline(always)]
    pub fn radius_m<L: Real>(&self, new_radius_m: L, cumulative_arc_energy_j: L) -> L {
        if self.kind == WearLawKind::Constant {
            return new_radius_m;
        }
        relax(
            new_radius_m,
            self.worn_radius_m,
            cumulative_arc_energy_j * L::splat(self.inverse_roughening_energy),
        )
    }

    /// Dynamic yield pressure after cumulative arc energy `W`: under `roughening_and_softening`,
    /// `p = p_inf + (p0 - p_inf) exp(-W / W_p)`; otherwise `p0`.
    #[inline(always)]
    pub fn pressure_pa<L: Real>(&self, new_pressure_pa: L, cumulative_arc_energy_j: L) -> L {
        if self.kind != WearLawKind::RougheningAndSoftening {
            return new_pressure_pa;
        }
        relax(
            new_pressure_pa,
            self.worn_pressure_pa,
            cumulative_arc_energy_j * L::splat(self.inverse_annealing_energy),
        )
    }

    /// Whether the law changes the surface at all (`constant` does not).
    pub fn changes_surface(&self) -> bool {
        self.kind != WearLawKind::Constant
    }

    /// Eroded mass after cumulative arc energy `W`: `M = gamma W` (the sum of `gamma E_j` of section 6,
    /// taken once at the end instead of at every operation).
    pub fn eroded_mass_kg(&self, cumulative_arc_energy_j: f64) -> f64 {
        self.erosion_kg_per_j * cumulative_arc_energy_j
    }

    /// The anode's and the cathode's shares of the eroded mass, `(f M, (1 - f) M)`, when the
    /// scenario gives the anode's share `f`.
    pub fn eroded_mass_split_kg(&self, cumulative_arc_energy_j: f64) -> Option<(f64, f64)> {
        let mass = self.eroded_mass_kg(cumulative_arc_energy_j);
        self.anode_erosion_fraction
            .map(|fraction| (fraction * mass, (1.0 - fraction) * mass))
    }

    /// Eroded volume `M / rho`.
    pub fn eroded_volume_m3(&self, cumulative_arc_energy_j: f64) -> f64 {
        self.eroded_mass_kg(cumulative_arc_energy_j) / self.density_kg_m3
    }
}

/// `worn + (new - worn) exp(-scaled_energy)`: a surface property relaxing from new to worn.
#[inline(always)]
fn relax<L: Real>(new: L, worn: f64, scaled_energy: L) -> L {
    let worn = L::splat(worn);
    worn + (new - worn) * exp(-scaled_energy)
}

/// What a device has accumulated over the operations it has run (docs/model.md section 6): one
/// device's, or, over [`Lanes`](crate::lanes::Lanes), each lane's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeviceWear<L: Real = f64> {
    /// `W`: the arc energy of every operation so far.
    pub cumulative_arc_energy_j: L,
    /// The first-impact plastic work of every operation so far (section 4).
    pub cumulative_plastic_work_j: L,
}

impl<L: Real> DeviceWear<L> {
    /// A new device on every lane.
    pub fn new() -> Self {
        Self {
            cumulative_arc_energy_j: L::splat(0.0),
            cumulative_plastic_work_j: L::splat(0.0),
        }
    }

    /// Adds one operation on every lane.
    #[inline(always)]
    pub fn add_lanes(&mut self, outcomes: &Outcomes<L>) {
        self.add_operation(outcomes.arc_energy_j, outcomes.first_impact_plastic_work_j);
    }

    #[inline(always)]
    fn add_operation(&mut self, arc_energy_j: L, first_impact_plastic_work_j: L) {
        self.cumulative_arc_energy_j = self.cumulative_arc_energy_j + arc_energy_j;
        self.cumulative_plastic_work_j =
            self.cumulative_plastic_work_j + first_impact_plastic_work_j;
    }

    /// Lane `i`'s device.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> DeviceWear {
        DeviceWear {
            cumulative_arc_energy_j: self.cumulative_arc_energy_j.lane(i),
            cumulative_plastic_work_j: self.cumulative_plastic_work_j.lane(i),
        }
    }
}

impl DeviceWear {
    /// Adds one operation.
    #[inline]
    pub fn add(&mut self, outcome: &Outcome) {
        self.add_operation(outcome.arc_energy_j, outcome.first_impact_plastic_work_j);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ScenarioSpec;
    use approx::assert_relative_eq;

    fn law(kind: WearLawKind) -> WearLaw {
        let mut spec = ScenarioSpec::default();
        spec.material.wear_law.law = kind;
        spec.material.anode_erosion_fraction = Some(0.75);
        WearLaw::new(&Scenario::new(spec, &crate::Pointer::root()).unwrap())
    }

    #[test]
    fn radius_starts_new_and_tends_to_the_worn_radius() {
        let law = WearLaw::new(&Scenario::default());
        assert_eq!(law.radius_m(7.7e-3, 0.0), 7.7e-3);
        assert_relative_eq!(law.radius_m(7.7e-3, 1e6), 0.711e-3, max_relative = 1e-15);
        // one roughening energy closes 1 - 1/e of the gap
        let r = law.radius_m(7.7e-3, 500.0);
        assert_relative_eq!(
            (r - 0.711e-3) / (7.7e-3 - 0.711e-3),
            (-1.0f64).exp(),
            max_relative = 1e-14
        );
    }

    #[test]
    fn the_default_law_roughens_but_keeps_the_pressure() {
        let law = WearLaw::new(&Scenario::default());
        assert_eq!(law.kind, WearLawKind::Roughening);
        assert_eq!(law.pressure_pa(2e8, 1e6), 2e8);
    }

    #[test]
    fn the_constant_law_holds_radius_and_pressure() {
        let law = law(WearLawKind::Constant);
        assert_eq!(law.radius_m(7.7e-3, 1e6), 7.7e-3);
        assert_eq!(law.pressure_pa(2e8, 1e6), 2e8);
        assert!(!law.changes_surface());
    }

    #[test]
    fn softening_lowers_the_pressure_towards_its_floor_as_it_roughens() {
        let law = law(WearLawKind::RougheningAndSoftening);
        assert_eq!(law.pressure_pa(2e8, 0.0), 2e8);
        assert_relative_eq!(law.pressure_pa(2e8, 1e6), 1e8, max_relative = 1e-15);
        let p = law.pressure_pa(2e8, 500.0);
        assert_relative_eq!((p - 1e8) / 1e8, (-1.0f64).exp(), max_relative = 1e-14);
        assert_relative_eq!(law.radius_m(7.7e-3, 1e6), 0.711e-3, max_relative = 1e-15);
    }

    #[test]
    fn erosion_is_linear_in_arc_energy() {
        let law = WearLaw::new(&Scenario::default());
        assert_relative_eq!(law.eroded_mass_kg(1500.0), 3e-6, max_relative = 1e-15);
        assert_relative_eq!(
            law.eroded_volume_m3(1500.0),
            3e-6 / 9950.0,
            max_relative = 1e-15
        );
        assert_eq!(law.eroded_mass_split_kg(1500.0), None);
    }

    #[test]
    fn the_anode_and_cathode_shares_add_up_to_the_eroded_mass() {
        let (anode, cathode) = law(WearLawKind::Roughening)
            .eroded_mass_split_kg(1500.0)
            .unwrap();
        assert_relative_eq!(anode, 2.25e-6, max_relative = 1e-15);
        assert_relative_eq!(anode + cathode, 3e-6, max_relative = 1e-15);
    }
}
