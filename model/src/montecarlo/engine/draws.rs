//! Draws: the parameters a device or an operation draws from the job's scatter, the model its
//! constants fix, and the scatter entries of one level with their correlation.

use super::*;

/// Parameters of one device or operation that scatter can replace.
#[derive(Debug, PartialEq)]
pub(super) struct Draws {
    pub(super) radius_m: f64,
    pub(super) pressure_pa: f64,
    pub(super) conditions: Conditions,
    /// Drawn constants of the scenario ([`Parameter::is_scenario_constant`]): the scenario is
    /// rebuilt with them.
    pub(super) constants: Vec<(Parameter, f64)>,
}

impl Clone for Draws {
    fn clone(&self) -> Self {
        Self {
            radius_m: self.radius_m,
            pressure_pa: self.pressure_pa,
            conditions: self.conditions,
            constants: self.constants.clone(),
        }
    }

    /// In place, reusing the constants' allocation: each lane's operation draws start from its
    /// device's at every operation.
    fn clone_from(&mut self, source: &Self) {
        self.radius_m = source.radius_m;
        self.pressure_pa = source.pressure_pa;
        self.conditions = source.conditions;
        self.constants.clone_from(&source.constants);
    }
}

impl Draws {
    pub(super) fn set(&mut self, parameter: Parameter, value: f64) {
        if parameter.is_scenario_constant() {
            self.constants.push((parameter, value));
            return;
        }
        match parameter {
            Parameter::ContactRadius => self.radius_m = value,
            Parameter::DynamicYieldPressure => self.pressure_pa = value,
            Parameter::ImpactVelocity => self.conditions.impact_velocity_m_s = Some(value),
            Parameter::DropHeight => self.conditions.drop_height_m = value,
            Parameter::StaticForce => self.conditions.static_force_n = value,
            Parameter::Current => self.conditions.current_a = value,
            Parameter::BreakdownField => self.conditions.breakdown_field_v_per_m = value,
            _ => unreachable!("scenario constants are kept apart"),
        }
    }
}

/// What a scenario's constants fix for all its operations: built once for the job, and again for
/// each draw that scatters one of them.
#[derive(Debug, Clone)]
pub(super) struct Model {
    pub(super) setup: Setup,
    pub(super) wear: WearLaw,
}

impl Model {
    pub(super) fn new(scenario: &Scenario) -> Self {
        Self {
            setup: Setup::new(scenario),
            wear: WearLaw::new(scenario),
        }
    }
}

/// The scatter entries of one `per`, in the job's order, and the correlation among some of them.
pub(super) struct Entries<'a> {
    /// Each entry with its index in the job's scatter.
    pub(super) scatter: Vec<(usize, &'a Scatter)>,
    /// The job's correlation, when it is over entries of this `per`, and each entry's row in its
    /// matrix (if it has one).
    pub(super) correlation: Option<(&'a Correlation, Vec<Option<usize>>)>,
}

impl<'a> Entries<'a> {
    pub(super) fn new(job: &'a Job, per: Per) -> Self {
        let scatter: Vec<_> = job
            .scatter()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.per == per)
            .collect();
        let correlation = job.correlation().filter(|c| c.per() == per).map(|c| {
            let rows = scatter
                .iter()
                .map(|(index, _)| c.members().iter().position(|m| m == index))
                .collect();
            (c, rows)
        });
        Self {
            scatter,
            correlation,
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.scatter.is_empty()
    }

    /// The number of entries, each set once per draw.
    pub(super) fn len(&self) -> usize {
        self.scatter.len()
    }

    /// Draws every entry from `rng`, in the job's order, and hands each value to `set` with the
    /// entry's index in the job's scatter: entry `k` in the stratum `strata` gives device `local` under
    /// LHS (`strata`), otherwise at random, counting the rejections of truncated draws by entry.
    /// Correlated entries draw a standard normal each (from their stratum under LHS), correlated
    /// together and then mapped through `Phi` and the marginal's inverse CDF.
    pub(super) fn draw(
        &self,
        job: &Job,
        strata: Option<(&Strata, usize)>,
        rng: &mut ChaCha8Rng,
        rejections: &mut [u64],
        mut set: impl FnMut(usize, f64),
    ) {
        let mut normals = match &self.correlation {
            Some((correlation, _)) => vec![0.0; correlation.members().len()],
            None => Vec::new(),
        };
        for (k, &(index, scatter)) in self.scatter.iter().enumerate() {
            let stratum = strata.map(|(strata, local)| strata.of(k, local));
            if let Some(row) = self.correlation.as_ref().and_then(|(_, rows)| rows[k]) {
                normals[row] = match stratum {
                    Some((stratum, strata)) => {
                        standard_normal_quantile(stratified_probability(stratum, strata, rng))
                    }
                    None => rng.sample(StandardNormal),
                };
                continue;
            }
            let value = match stratum {
                Some((stratum, strata)) => scatter.distribution.stratified(stratum, strata, rng),
                None => scatter
                    .distribution
                    .sample_counting(rng, &mut rejections[index]),
            };
            set(index, value);
        }
        if let Some((correlation, _)) = &self.correlation {
            correlation.correlate(&mut normals);
            for (&index, normal) in correlation.members().iter().zip(normals) {
                // Phi rounds to 0 or 1 beyond about 8 standard deviations; stay inside (0, 1).
                let u = standard_normal_cdf(normal).clamp(f64::MIN_POSITIVE, 1.0 - f64::EPSILON);
                set(index, job.scatter()[index].distribution.quantile(u));
            }
        }
    }
}

/// The Latin hypercube strata of a batch's devices ([`super::plan::Plan::batch_strata`]): of each
/// device-level scatter entry, a keyed permutation of the batch's devices, evaluated at each device
/// as it draws, so that neither a batch nor any group of it holds or draws more than its own.
pub(super) struct Strata {
    pub(super) permutations: Vec<Permutation>,
}

impl Strata {
    /// The stratum of entry `k` for device `local` of the batch, and the number of strata.
    pub(super) fn of(&self, k: usize, local: usize) -> (u32, u32) {
        let permutation = &self.permutations[k];
        let stratum = permutation.apply(local as u64);
        // Both below 2^32: a batch under LHS has fewer devices (`Plan::batch_strata`).
        (stratum as u32, permutation.size() as u32)
    }
}
