//! Accumulation: each operation's values into the bins' sums and sketches, each device's
//! metrics into the sensitivity cells, and the failure criteria.

use super::*;

impl<'a> Plan<'a> {
    /// Lane `k`'s device metrics in every variant, into the device cells of `stats`.
    pub(super) fn push_device_sensitivity<L: Real>(
        &self,
        plan: &SensitivityPlan,
        variants: &[Variant<'_, L>],
        k: usize,
        stats: &mut SensitivityStats,
    ) {
        let job = self.job;
        let first_cell = usize::try_from(job.bins()).expect("bins fit in memory")
            * job.operation_metrics().len();
        let a = &variants[0];
        let inputs: Vec<f64> = plan.device_inputs.iter().map(|&i| a.inputs[k][i]).collect();
        for (j, metric) in job.device_metrics().iter().enumerate() {
            let value = |v: &Variant<'_, L>| {
                self.device_metric(&v.model, *metric, &v.draws[k], &v.wear.lane(k))
            };
            let a_value = value(a);
            if plan.device_sobol() {
                let ab: Vec<f64> = variants[2..].iter().map(value).collect();
                stats.device[first_cell + j].push(a_value, value(&variants[1]), &ab);
            }
            stats.regression[first_cell + j].push(&inputs, a_value);
        }
    }

    /// Whether any failure criterion is met by this operation or by the device's state after it.
    #[inline]
    pub(super) fn fails(
        &self,
        model: &Model,
        outcome: &Outcome,
        draws: &Draws,
        device_wear: &DeviceWear,
    ) -> bool {
        self.job.failure().iter().any(|(metric, criterion)| {
            let value = match metric {
                Metric::Operation(metric) => metric.value(outcome),
                Metric::Device(metric) => self.device_metric(model, *metric, draws, device_wear),
            };
            criterion.fails(value)
        })
    }

    /// A device metric of the device with `draws` and its `model` (per-operation draws do not
    /// enter: the device's own values do, as for its radius).
    pub(super) fn device_metric(
        &self,
        model: &Model,
        metric: DeviceMetric,
        draws: &Draws,
        device_wear: &DeviceWear,
    ) -> f64 {
        let wear = &model.wear;
        let energy_j = device_wear.cumulative_arc_energy_j;
        let final_radius_m = || {
            if energy_j > 0.0 {
                wear.radius_m(draws.radius_m, energy_j)
            } else {
                draws.radius_m
            }
        };
        let eroded_mass_split_kg = || {
            wear.eroded_mass_split_kg(energy_j)
                .expect("the job checked that the scenario gives the polarity")
        };
        match metric {
            DeviceMetric::CumulativeArcEnergy => energy_j,
            DeviceMetric::ErodedMass => wear.eroded_mass_kg(energy_j),
            DeviceMetric::FinalRadius => final_radius_m(),
            DeviceMetric::FinalKappa => model.setup.kappa_law().at(
                final_radius_m(),
                wear.pressure_pa(draws.pressure_pa, energy_j),
            ),
            DeviceMetric::CumulativePlasticWork => device_wear.cumulative_plastic_work_j,
            DeviceMetric::AnodeErodedMass => eroded_mass_split_kg().0,
            DeviceMetric::CathodeErodedMass => eroded_mass_split_kg().1,
        }
    }
}

/// Which lanes' outcomes [`Plan::read_lanes`] reads, and for what.
#[derive(Clone, Copy)]
pub(super) struct LanesRead {
    /// The variant evaluated (0 for the devices themselves).
    pub(super) variant: usize,
    /// Lanes that hold devices.
    pub(super) active: usize,
    /// The operation, from 0.
    pub(super) operation: u64,
    /// Whether the sensitivity cells read the values.
    pub(super) cells: bool,
}

/// A group with fewer of a batch's lanes counts its values one at a time
/// ([`Accumulator::count_values`]): a vector pass over every lane of the batch would cost more.
/// Measured on one thread (`engine` bench, 100 operations a device): the 100 devices of groups of
/// three or four ran 10-15 % faster one at a time than with a pass per group; 480 devices, groups
/// of 15 sharing 32 lanes, ran about 5 % faster with a pass per group.
const FEWEST_LANES_COUNTED_TOGETHER: usize = 8;

/// One operation's values of each metric in the lanes of the batch's groups (`groups`), one
/// dispatch per metric: into the lanes' sums (about the shift the first operation of the bin sets
/// in each group's lanes, `first_of_bin`; one set of sums for every group), and counted in each
/// group's sketches.
#[inline(always)]
pub(super) fn accumulate<L: Real>(
    metrics: &[OperationMetric],
    outcomes: &Outcomes<L>,
    groups: &mut LaneGroups<'_>,
    bin: Range<usize>,
    sums: &mut Vec<LaneSums<L>>,
    first_of_bin: bool,
) {
    if metrics.is_empty() {
        return;
    }
    let mut columns = [&outcomes.impact_velocity_m_s; OperationMetric::ALL.len()];
    for (column, metric) in columns.iter_mut().zip(metrics) {
        *column = metric.lanes(outcomes);
    }
    let columns = &columns[..metrics.len()];
    if first_of_bin {
        sums.clear();
        sums.extend(columns.iter().map(|_| LaneSums::empty()));
        for (stats, lanes) in groups.each() {
            let accumulators = &stats.operations[bin.clone()];
            for ((sums, accumulator), column) in sums.iter_mut().zip(accumulators).zip(columns) {
                sums.about(accumulator, column.lane(lanes.start), lanes.clone());
            }
        }
    }
    for (sums, column) in sums.iter_mut().zip(columns) {
        sums.push(**column);
    }
    for (stats, lanes) in groups.each() {
        let accumulators = &mut stats.operations[bin.clone()];
        if lanes.len() >= FEWEST_LANES_COUNTED_TOGETHER.min(L::LANES) {
            Accumulator::count_lanes(accumulators, columns, lanes);
        } else {
            for (accumulator, column) in accumulators.iter_mut().zip(columns) {
                accumulator.count_values(lanes.clone().map(|k| column.lane(k)));
            }
        }
    }
}
