//! One device of a job as a function of independent standard normals: what the rare-event
//! methods (`montecarlo::rare`) explore. Each scattered input of the device, and of each operation
//! up to the one read, is one coordinate; it becomes the parameter's value through the same
//! marginal, truncation and copula as the job's own draws (`Entries::at_normals`), and the
//! device runs through the engine's own evaluation and wear (the scalar kernel), so the job
//! without its rare event is this function's crude Monte Carlo twin.

use super::{Entries, Plan, Variant};
use crate::montecarlo::rare::question::Reading;
use crate::montecarlo::{Job, Kernel, Metric};
use crate::operation::Outcome;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What one device reads after `operations` operations, at standard normal inputs.
pub struct DeviceFunction<'a> {
    plan: Plan<'a>,
    reading: Reading,
    operations: u64,
}

impl<'a> DeviceFunction<'a> {
    /// `reading` after `operations` operations (an operation metric: at the last of them).
    pub fn new(job: &'a Job, reading: Reading, operations: u64) -> Self {
        let mut plan = Plan::new(job, Kernel::SCALAR);
        if let Reading::Metric(metric) = reading {
            plan.needs.impact |= metric.needs_impact();
        }
        plan.sensitivity = None;
        Self {
            plan,
            reading,
            operations,
        }
    }

    /// The number of inputs: the device's scattered parameters, then each operation's.
    pub fn dimension(&self) -> usize {
        self.plan.device_scatter.len() + self.per_operation() * self.operation_count()
    }

    /// Whether inputs of more than one operation are scattered: an event that any of them can
    /// cause then has a failure region for each, alike (the same parameter's draws), and
    /// importance sampling around one centre misses all but one.
    pub fn scatters_several_operations(&self) -> bool {
        self.per_operation() > 0 && self.operation_count() > 1
    }

    fn per_operation(&self) -> usize {
        self.plan.operation_scatter.len()
    }

    fn operation_count(&self) -> usize {
        usize::try_from(self.operations).expect("a rare event reads a bounded operation")
    }

    /// Each input's name, in order: the parameter's, and `@k` after it for operation `k` (from 1).
    pub fn input_names(&self) -> Vec<String> {
        let job = self.plan.job;
        let name = |index: usize| job.scatter()[index].parameter.name();
        let device = self
            .plan
            .device_scatter
            .scatter
            .iter()
            .map(|&(i, _)| name(i));
        let operations = (1..=self.operations).flat_map(|op| {
            self.plan
                .operation_scatter
                .scatter
                .iter()
                .map(move |&(i, _)| format!("{}@{op}", name(i)))
        });
        device.chain(operations).collect()
    }

    /// The parameters' values at `u`, in the order of [`DeviceFunction::input_names`].
    pub fn physical(&self, u: &[f64]) -> Vec<f64> {
        let job = self.plan.job;
        let (device, operations) = u.split_at(self.plan.device_scatter.len());
        let mut values = Vec::with_capacity(u.len());
        let mut into = |entries: &Entries<'_>, u: &[f64]| {
            let mut row = vec![f64::NAN; job.scatter().len()];
            entries.at_normals(job, u, |index, value| row[index] = value);
            values.extend(entries.scatter.iter().map(|&(index, _)| row[index]));
        };
        into(&self.plan.device_scatter, device);
        if self.per_operation() > 0 {
            for chunk in operations.chunks(self.per_operation()) {
                into(&self.plan.operation_scatter, chunk);
            }
        }
        values
    }

    /// What the device at `u` (of length [`DeviceFunction::dimension`]) reads.
    pub fn value(&self, u: &[f64]) -> f64 {
        debug_assert_eq!(u.len(), self.dimension());
        let (plan, job) = (&self.plan, self.plan.job);
        let (device_u, operations_u) = u.split_at(plan.device_scatter.len());
        let mut device = plan.nominal.clone();
        plan.device_scatter
            .at_normals(job, device_u, |index, value| {
                device.set(job.scatter()[index].parameter, value);
            });
        // The stream is never drawn from: each operation's inputs come from `u`.
        let stream = ChaCha8Rng::seed_from_u64(0);
        let inputs = vec![f64::NAN; job.scatter().len()];
        let mut variant = Variant::<f64>::new(plan, vec![device], vec![stream], vec![inputs]);
        let width = self.per_operation();
        let mut worst = f64::NEG_INFINITY;
        for op in 0..self.operation_count() {
            if width > 0 {
                let draws = &mut variant.op_draws[0];
                draws.clone_from(&variant.draws[0]);
                let u = &operations_u[op * width..(op + 1) * width];
                plan.operation_scatter.at_normals(job, u, |index, value| {
                    draws.set(job.scatter()[index].parameter, value);
                });
            }
            let outcomes = variant.evaluate(plan, &variant.op_draws);
            if op + 1 == self.operation_count()
                && let Reading::Metric(Metric::Operation(metric)) = self.reading
            {
                return metric.value(&outcomes.lane(0));
            }
            variant.wear.add_lanes(&outcomes);
            if self.reading == Reading::FailureMargin {
                // As the engine checks: after the operation's wear.
                let margin = self.margin(&variant, &outcomes.lane(0));
                if margin > 0.0 {
                    return margin;
                }
                worst = worst.max(margin);
            }
        }
        match self.reading {
            Reading::Metric(Metric::Device(metric)) => plan.device_metric(
                &variant.model,
                metric,
                &variant.draws[0],
                &variant.wear.lane(0),
            ),
            Reading::FailureMargin => worst,
            Reading::Metric(Metric::Operation(_)) => {
                unreachable!("an operation metric is read at its operation")
            }
        }
    }

    /// The largest margin past the job's failure criteria after this operation.
    fn margin(&self, variant: &Variant<'_, f64>, outcome: &Outcome) -> f64 {
        let plan = &self.plan;
        plan.job
            .failure()
            .iter()
            .map(|(metric, criterion)| {
                let value = match metric {
                    Metric::Operation(metric) => metric.value(outcome),
                    Metric::Device(metric) => plan.device_metric(
                        &variant.model,
                        *metric,
                        &variant.draws[0],
                        &variant.wear.lane(0),
                    ),
                };
                criterion.margin(value)
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

impl Entries<'_> {
    /// The entries' values at standard normals `u` (one per entry, in order), handed to `set` as
    /// [`Entries::draw`] hands them: uncorrelated entries through `Phi` and their marginal's
    /// inverse CDF (inside its truncation window), correlated ones after the copula's Cholesky
    /// factor.
    fn at_normals(&self, job: &Job, u: &[f64], mut set: impl FnMut(usize, f64)) {
        let mut normals = match &self.correlation {
            Some((correlation, _)) => vec![0.0; correlation.members().len()],
            None => Vec::new(),
        };
        for (k, &(index, scatter)) in self.scatter.iter().enumerate() {
            match self.correlation.as_ref().and_then(|(_, rows)| rows[k]) {
                Some(row) => normals[row] = u[k],
                None => set(index, scatter.distribution.at_normal(u[k])),
            }
        }
        if let Some((correlation, _)) = &self.correlation {
            correlation.correlate(&mut normals);
            for (&index, normal) in correlation.members().iter().zip(normals) {
                set(index, job.scatter()[index].distribution.at_normal(normal));
            }
        }
    }
}
