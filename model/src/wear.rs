//! A device's surface across an endurance test (docs/model.md section 6).
//!
//! Arc energy roughens the surface: the effective contact radius falls from the new-contact radius
//! `r0` towards the worn radius `r_inf` as the cumulative arc energy `W` grows, which lowers kappa
//! (eq. 8) and the restitution of every later operation. Erosion removes `gamma` kg per joule.

use crate::scenario::Scenario;

/// The material constants of wear.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WearLaw {
    pub worn_radius_m: f64,
    /// `1 / W_r`, so that a radius costs one multiplication and one `exp`.
    inverse_roughening_energy: f64,
    pub erosion_kg_per_j: f64,
    pub density_kg_m3: f64,
}

impl WearLaw {
    pub fn new(scenario: &Scenario) -> Self {
        let material = &scenario.spec().material;
        Self {
            worn_radius_m: material.worn_radius_m,
            inverse_roughening_energy: 1.0 / material.roughening_energy_j,
            erosion_kg_per_j: material.erosion_kg_per_j,
            density_kg_m3: material.density_kg_m3,
        }
    }

    /// Effective radius after cumulative arc energy `W`: `r = r_inf + (r0 - r_inf) exp(-W / W_r)`.
    #[inline]
    pub fn radius_m(&self, new_radius_m: f64, cumulative_arc_energy_j: f64) -> f64 {
        let r_inf = self.worn_radius_m;
        r_inf
            + (new_radius_m - r_inf)
                * (-cumulative_arc_energy_j * self.inverse_roughening_energy).exp()
    }

    /// Eroded mass after cumulative arc energy `W`: `M = gamma W` (the sum of `gamma E_j` of section 6,
    /// taken once at the end instead of at every operation).
    pub fn eroded_mass_kg(&self, cumulative_arc_energy_j: f64) -> f64 {
        self.erosion_kg_per_j * cumulative_arc_energy_j
    }

    /// Eroded volume `M / rho`.
    pub fn eroded_volume_m3(&self, cumulative_arc_energy_j: f64) -> f64 {
        self.eroded_mass_kg(cumulative_arc_energy_j) / self.density_kg_m3
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

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
    fn erosion_is_linear_in_arc_energy() {
        let law = WearLaw::new(&Scenario::default());
        assert_relative_eq!(law.eroded_mass_kg(1500.0), 3e-6, max_relative = 1e-15);
        assert_relative_eq!(
            law.eroded_volume_m3(1500.0),
            3e-6 / 9950.0,
            max_relative = 1e-15
        );
    }
}
