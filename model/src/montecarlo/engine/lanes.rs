//! The lane loop: devices in lockstep on a kernel's lanes, operation after operation, with the
//! variants a Sobol' analysis runs alongside, and their per-operation draws.

use super::*;

impl<'a> Plan<'a> {
    /// Runs the `active` devices of the chunk from `first_local` on, in lockstep on `L::LANES`
    /// lanes (spare lanes compute a copy of the first device: they draw from a copy of its
    /// stream, and nothing reads their values or their rejections), into their groups' stats
    /// (`groups`, which may hold several small groups side by side): each from its own stream,
    /// with the draws and the arithmetic it would have alone. Each lane sums its device's values
    /// of a bin in the lanes ([`LaneSums`]), and each group's accumulators of the bin add those
    /// sums device after device, so the sums come out the same to the bit for any number of
    /// lanes, and whichever groups share them.
    ///
    /// With Sobol' indices over device-level parameters, the devices run again alongside, as
    /// variants: `B`, drawn from the devices' Sobol' streams, and `AB_i`, the devices with
    /// parameter `i` taken from `B`, which draw their operations from the devices' own streams
    /// as the devices do. With operation-level parameters, each operation of the devices is also
    /// evaluated at `B'`, drawn from the devices' operation Sobol' streams, and at `AB'_i`, in
    /// the device's state.
    ///
    /// Every [`OPERATIONS_PER_LOOK`] operations it tells `watched` its progress and stops if the
    /// job was cancelled; the rest of its operations it tells at the end.
    #[inline(always)]
    pub(super) fn run_devices<L: Real>(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        active: usize,
        groups: &mut LaneGroups<'_>,
        watched: &Watched<'_>,
    ) -> Result<(), Cancelled> {
        let job = self.job;
        let lanes = L::LANES;
        debug_assert!(
            active == lanes || (active < lanes && self.sensitivity.is_none()),
            "spare lanes only without a sensitivity analysis"
        );
        debug_assert!(
            groups.stats.len() == 1 || self.sensitivity.is_none(),
            "groups share lanes only without a sensitivity analysis"
        );
        let sensitivity = self.sensitivity.as_ref();
        let sobol = sensitivity.filter(|s| s.method == SensitivityMethod::Sobol);
        let mut scratch = vec![0; job.scatter().len()];
        let mut variants = self.variants::<L>(chunk, first_local, active, groups, &mut scratch);
        let operation_sobol = sobol.filter(|p| !p.operation_inputs.is_empty());
        let mut operation_rngs = match operation_sobol {
            Some(_) => self.operation_sobol_rngs(chunk.first + first_local, lanes),
            None => Vec::new(),
        };
        let mut cells = sensitivity.map(|plan| LaneCells::new(plan, lanes));
        let lane_draws = self.lane_draws && sensitivity.is_none();

        let mut failed_at = vec![None; lanes];
        let metrics = job.operation_metrics();
        let operations = job.spec().operations;
        // The lanes' sums of each metric, each group's lanes about its own accumulator's shift.
        let mut sums: Vec<LaneSums<L>> = Vec::with_capacity(metrics.len());
        let bins = usize::try_from(job.bins()).expect("bins fit in memory");
        // Per evaluation (variants, then B' and AB'_i), lane and metric: this operation's values,
        // for the sensitivity cells.
        let evaluations = variants.len() + sobol.map_or(0, |p| p.operation_evaluations());
        let mut values = vec![0.0; evaluations * lanes * metrics.len()];
        let variant_count = variants.len();
        let swaps_at = variant_count * lanes * metrics.len();
        for bin_index in 0..bins {
            let std::ops::Range { start, end } = job.bin_range(bin_index as u64);
            let bin = bin_index * metrics.len()..(bin_index + 1) * metrics.len();
            for op in start..end {
                for (v, variant) in variants.iter_mut().enumerate() {
                    let outcomes = variant.step(self, lane_draws, operations - op);
                    if v == 0 {
                        if let Some(plan) = operation_sobol {
                            let values = &mut values[swaps_at..];
                            let rngs = &mut operation_rngs;
                            self.evaluate_operation_swaps(
                                plan,
                                variant,
                                rngs,
                                &mut scratch,
                                values,
                            );
                        }
                        let first = op == start;
                        accumulate(metrics, &outcomes, groups, bin.clone(), &mut sums, first);
                        for (stats, lanes) in groups.each() {
                            stats.operations_at_max_bounces += lanes
                                .map(|k| u64::from(outcomes.truncated.lane(k)))
                                .sum::<u64>();
                        }
                    }
                    variant.wear.add_lanes(&outcomes);
                    // Each lane's outcome, only for what reads it: the sensitivity cells and
                    // the failure criteria.
                    if cells.is_none() && (v != 0 || job.failure().is_empty()) {
                        continue;
                    }
                    let lanes_read = LanesRead {
                        variant: v,
                        active,
                        operation: op,
                        cells: cells.is_some(),
                    };
                    self.read_lanes(lanes_read, variant, &outcomes, &mut values, &mut failed_at);
                }
                if let Some(cells) = &mut cells {
                    cells.push_operation(&values, &variants[0].inputs, variant_count);
                }
                if (op + 1) % OPERATIONS_PER_LOOK == 0 {
                    watched.ran(active as u64, OPERATIONS_PER_LOOK)?;
                }
            }
            end_bin(cells.as_mut(), groups, bin_index, bin, &sums);
        }
        self.finish_devices(chunk.first + first_local, &variants, &failed_at, groups);
        // The operations since the last look; a cancellation now is seen before the next batch.
        let _ = watched.ran(active as u64, operations % OPERATIONS_PER_LOOK);
        Ok(())
    }

    /// The devices (`A`, in `active` of the lanes) with their draws and streams, and with Sobol'
    /// indices over device-level parameters the variants that run alongside: `B`, drawn from the
    /// devices' Sobol' streams, and each `AB_i`, the devices with parameter `i` taken from `B`.
    /// Each group's devices count their rejections in its stats.
    #[inline(always)]
    pub(super) fn variants<L: Real>(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        active: usize,
        groups: &mut LaneGroups<'_>,
        scratch: &mut [u64],
    ) -> Vec<Variant<'_, L>> {
        let (job, lanes) = (self.job, L::LANES);
        let (mut draws, mut rngs, mut inputs) = (
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
        );
        for (stats, of_group) in groups.each() {
            let (d, r, i) = self.draw_devices(
                chunk,
                first_local + of_group.start as u64,
                of_group.len(),
                |device| device,
                chunk.strata,
                &mut stats.truncation_rejections,
            );
            draws.extend(d);
            rngs.extend(r);
            inputs.extend(i);
        }
        debug_assert_eq!(draws.len(), active, "the groups hold the active lanes");
        draws.resize(lanes, draws[0].clone());
        rngs.resize(lanes, rngs[0].clone());
        inputs.resize(lanes, inputs[0].clone());
        let mut variants = vec![Variant::<L>::new(self, draws, rngs, inputs)];
        let device_sobol = self
            .sensitivity
            .as_ref()
            .filter(|s| s.method == SensitivityMethod::Sobol && !s.device_inputs.is_empty());
        let Some(plan) = device_sobol else {
            return variants;
        };
        let (b_draws, b_rngs, b_inputs) = self.draw_devices(
            chunk,
            first_local,
            lanes,
            |device| SOBOL_DEVICE_STREAM_BASE | device,
            None,
            scratch,
        );
        let a = &variants[0];
        let swapped: Vec<Variant<L>> = plan
            .device_inputs
            .iter()
            .map(|&input| {
                let (mut draws, mut inputs) = (a.draws.clone(), a.inputs.clone());
                for k in 0..lanes {
                    let value = b_inputs[k][input];
                    draws[k].set(job.scatter()[input].parameter, value);
                    inputs[k][input] = value;
                }
                Variant::new(self, draws, a.rngs.clone(), inputs)
            })
            .collect();
        variants.push(Variant::new(self, b_draws, b_rngs, b_inputs));
        variants.extend(swapped);
        variants
    }

    /// Each lane's stream of operation-level `B'` draws: the device's own operation Sobol'
    /// stream, lane `k` being device `first + k`.
    pub(super) fn operation_sobol_rngs(&self, first: u64, lanes: usize) -> Vec<ChaCha8Rng> {
        (0..lanes as u64)
            .map(|k| {
                let mut rng = ChaCha8Rng::seed_from_u64(self.job.seed());
                rng.set_stream(SOBOL_OPERATION_STREAM_BASE | (first + k));
                rng
            })
            .collect()
    }

    /// Each lane's outcome of one operation, only for what reads it: its metrics' values for
    /// the sensitivity cells, and, for the devices themselves, whether it fails them.
    #[inline(always)]
    pub(super) fn read_lanes<L: Real>(
        &self,
        read: LanesRead,
        variant: &Variant<'_, L>,
        outcomes: &Outcomes<L>,
        values: &mut [f64],
        failed_at: &mut [Option<u64>],
    ) {
        let metrics = self.job.operation_metrics();
        for (k, failed_at) in failed_at.iter_mut().enumerate() {
            let outcome = outcomes.lane(k);
            if read.cells {
                let at = (read.variant * L::LANES + k) * metrics.len();
                for (slot, metric) in values[at..at + metrics.len()].iter_mut().zip(metrics) {
                    *slot = metric.value(&outcome);
                }
            }
            if read.variant != 0 || k >= read.active {
                continue;
            }
            if failed_at.is_none()
                && self.fails(
                    &variant.model,
                    &outcome,
                    &variant.draws[k],
                    &variant.wear.lane(k),
                )
            {
                *failed_at = Some(read.operation + 1);
            }
        }
    }

    /// What the devices leave at the end of the test, each in its group's stats: their device
    /// metrics, their share of the device-level sensitivity, their lives (device `first + k` in
    /// lane `k`) and the rejections of their operations' draws.
    #[inline(always)]
    pub(super) fn finish_devices<L: Real>(
        &self,
        first: u64,
        variants: &[Variant<'_, L>],
        failed_at: &[Option<u64>],
        groups: &mut LaneGroups<'_>,
    ) {
        let (job, a) = (self.job, &variants[0]);
        for (stats, lanes) in groups.each() {
            for k in lanes {
                for (accumulator, metric) in stats.devices.iter_mut().zip(job.device_metrics()) {
                    accumulator.push(self.device_metric(
                        &a.model,
                        *metric,
                        &a.draws[k],
                        &a.wear.lane(k),
                    ));
                }
                if let Some(plan) = &self.sensitivity {
                    self.push_device_sensitivity(plan, variants, k, &mut stats.sensitivity);
                }
                if !job.failure().is_empty() {
                    let life = DeviceLife {
                        device: first + k as u64,
                        operations_to_failure: failed_at[k].unwrap_or(job.spec().operations),
                        censored: failed_at[k].is_none(),
                    };
                    stats.lives.record(life, job.listed_lives());
                }
                let counted = stats.truncation_rejections.iter_mut();
                counted
                    .zip(a.rejections(k))
                    .for_each(|(total, n)| *total += n);
            }
        }
    }

    /// Evaluates the operation the devices (`a`) just drew at `B'`, drawn from `rngs`, and at
    /// `AB'_i`, in the devices' state: the values go to `values`, per evaluation, lane and metric.
    #[inline(always)]
    pub(super) fn evaluate_operation_swaps<L: Real>(
        &self,
        plan: &SensitivityPlan,
        a: &Variant<'_, L>,
        rngs: &mut [ChaCha8Rng],
        rejections: &mut [u64],
        values: &mut [f64],
    ) {
        let job = self.job;
        let (lanes, metrics) = (L::LANES, job.operation_metrics());
        let mut b_draws = Vec::with_capacity(lanes);
        let mut b_values = vec![vec![f64::NAN; job.scatter().len()]; lanes];
        for (k, rng) in rngs.iter_mut().enumerate() {
            let mut draws = a.draws[k].clone();
            let row = &mut b_values[k];
            self.operation_scatter
                .draw(job, None, rng, rejections, |index, value| {
                    draws.set(job.scatter()[index].parameter, value);
                    row[index] = value;
                });
            b_draws.push(draws);
        }
        let mut record = |evaluation: usize, outcomes: Outcomes<L>| {
            for k in 0..lanes {
                let outcome = outcomes.lane(k);
                let at = (evaluation * lanes + k) * metrics.len();
                for (slot, metric) in values[at..at + metrics.len()].iter_mut().zip(metrics) {
                    *slot = metric.value(&outcome);
                }
            }
        };
        record(0, a.evaluate(self, &b_draws));
        for (i, &input) in plan.operation_inputs.iter().enumerate() {
            let swapped: Vec<Draws> = (0..lanes)
                .map(|k| {
                    let mut draws = a.op_draws[k].clone();
                    draws.set(job.scatter()[input].parameter, b_values[k][input]);
                    draws
                })
                .collect();
            record(1 + i, a.evaluate(self, &swapped));
        }
    }
}

/// Devices running in lockstep with their draws and state: the job's devices, or, for a
/// sensitivity analysis, the same devices with some parameters drawn again.
pub(super) struct Variant<'p, L: Real> {
    pub(super) draws: Vec<Draws>,
    /// Each lane's stream, as its operations draw from it.
    pub(super) rngs: Vec<ChaCha8Rng>,
    /// Each lane's parameter values by scatter entry: the device's, and this operation's.
    pub(super) inputs: Vec<Vec<f64>>,
    /// The model of the lanes' scenario constants (lanes in lockstep share them).
    pub(super) model: Cow<'p, Model>,
    /// The operation of the device's conditions, and the lanes' speed, radius and pressure.
    pub(super) operation: Operation,
    pub(super) speed: L,
    pub(super) radius_m: L,
    pub(super) pressure_pa: L,
    pub(super) wear: DeviceWear<L>,
    /// This operation's draws.
    pub(super) op_draws: Vec<Draws>,
    /// The next operations' per-operation draws, drawn ahead from each lane's stream in one
    /// loop per lane ([`Variant::draw_operation`]): `(scatter index, value)` in the order
    /// [`Entries::draw`] sets them, lane after lane, operation after operation.
    pub(super) ahead: Vec<(usize, f64)>,
    /// The same for [`Variant::draw_lanes`]: values only, by operation, lane and entry, so that
    /// one operation's values of an entry are a short stride apart (drawn lane after lane).
    pub(super) lane_ahead: Vec<f64>,
    /// Operations per lane in `ahead` (or `lane_ahead`), and the next one to use.
    pub(super) ahead_operations: usize,
    pub(super) ahead_next: usize,
    /// The rejections of each lane's per-operation draws, by lane and scatter entry: a lane's
    /// go to its device's group once it has run ([`Plan::finish_devices`]); nobody reads a spare
    /// lane's.
    pub(super) rejections: Vec<u64>,
}

/// Operations whose per-operation draws a lane takes from its stream in one go.
pub(super) const DRAW_AHEAD: u64 = 64;

impl<'p, L: Real> Variant<'p, L> {
    pub(super) fn new(
        plan: &'p Plan<'_>,
        draws: Vec<Draws>,
        rngs: Vec<ChaCha8Rng>,
        inputs: Vec<Vec<f64>>,
    ) -> Self {
        let model = plan.model(&draws[0]);
        let operation = model
            .setup
            .operation(&draws[0].conditions, plan.job.spec().fidelity);
        let base_speed = operation.impact_velocity_m_s();
        Self {
            speed: L::from_fn(|k| {
                draws[k]
                    .conditions
                    .impact_velocity_m_s
                    .unwrap_or(base_speed)
            }),
            radius_m: L::from_fn(|k| draws[k].radius_m),
            pressure_pa: L::from_fn(|k| draws[k].pressure_pa),
            wear: DeviceWear::new(),
            op_draws: draws.clone(),
            draws,
            rngs,
            inputs,
            model,
            operation,
            ahead: Vec::new(),
            lane_ahead: Vec::new(),
            ahead_operations: 0,
            ahead_next: 0,
            rejections: vec![0; L::LANES * plan.job.scatter().len()],
        }
    }

    /// Lane `k`'s rejections by scatter entry.
    pub(super) fn rejections(&self, k: usize) -> &[u64] {
        let entries = self.rejections.len() / L::LANES;
        &self.rejections[k * entries..(k + 1) * entries]
    }

    /// Draws the next operation's per-operation scatter of every lane from its stream, of
    /// `remaining` operations (this one included) the device has left. Each lane draws up to
    /// [`DRAW_AHEAD`] operations at a time from its stream, in one loop: the same values from the
    /// same streams in the same order as one operation at a time, and never a draw past the
    /// device's last operation, so the truncation rejections count the same.
    #[inline(always)]
    pub(super) fn draw_operation(&mut self, plan: &Plan<'_>, remaining: u64) {
        let entries = plan.operation_scatter.len();
        if entries == 0 {
            return;
        }
        let job = plan.job;
        if self.start_block(remaining) {
            let mut ahead = std::mem::take(&mut self.ahead);
            ahead.clear();
            self.draw_block(|_, _, rng, rejections| {
                plan.operation_scatter
                    .draw(job, None, rng, rejections, |index, value| {
                        ahead.push((index, value));
                    });
            });
            self.ahead = ahead;
        }
        for k in 0..L::LANES {
            let draws = &mut self.op_draws[k];
            draws.clone_from(&self.draws[k]);
            let row = &mut self.inputs[k];
            let at = (k * self.ahead_operations + self.ahead_next) * entries;
            for &(index, value) in &self.ahead[at..at + entries] {
                draws.set(job.scatter()[index].parameter, value);
                row[index] = value;
            }
        }
        self.ahead_next += 1;
    }

    /// Whether the operations drawn ahead are used up; if so, starts a new block of up to
    /// [`DRAW_AHEAD`] operations, never past the device's last (`remaining` left, this one
    /// included), so that the rejections count as if drawn one operation at a time.
    #[inline(always)]
    pub(super) fn start_block(&mut self, remaining: u64) -> bool {
        if self.ahead_next < self.ahead_operations {
            return false;
        }
        self.ahead_operations =
            usize::try_from(remaining.min(DRAW_AHEAD)).expect("a block fits in memory");
        self.ahead_next = 0;
        true
    }

    /// Draws the block [`Variant::start_block`] started: lane after lane, each from its own
    /// stream, `draw(lane, operation, stream, rejections)` for each of the block's operations,
    /// counting the lane's rejections.
    #[inline(always)]
    pub(super) fn draw_block(
        &mut self,
        mut draw: impl FnMut(usize, usize, &mut ChaCha8Rng, &mut [u64]),
    ) {
        let entries = self.rejections.len() / L::LANES;
        for (k, rng) in self.rngs.iter_mut().enumerate() {
            let rejections = &mut self.rejections[k * entries..(k + 1) * entries];
            for op in 0..self.ahead_operations {
                draw(k, op, rng, rejections);
            }
        }
    }

    /// Draws this operation's inputs and evaluates it in every lane: from the lanes' own draws
    /// (`lane_draws`), or one lane after another.
    #[inline(always)]
    pub(super) fn step(
        &mut self,
        plan: &Plan<'_>,
        lane_draws: bool,
        remaining: u64,
    ) -> Outcomes<L> {
        if lane_draws {
            let (speed, radius_m, pressure_pa) = self.draw_lanes(plan, remaining);
            self.evaluate_lanes(
                plan,
                &self.operation,
                self.model.wear,
                speed,
                radius_m,
                pressure_pa,
            )
        } else {
            self.draw_operation(plan, remaining);
            self.evaluate(plan, &self.op_draws)
        }
    }

    /// [`Variant::draw_operation`] when the operation draws only lane values, uncorrelated, and
    /// nothing reads the draws but the lanes (no sensitivity analysis): the same values from the
    /// same streams in the same order, counting the same rejections, straight into this
    /// operation's speed, radius and pressure lanes, without a [`Draws`] and an input row per
    /// lane and operation.
    #[inline(always)]
    pub(super) fn draw_lanes(&mut self, plan: &Plan<'_>, remaining: u64) -> (L, L, L) {
        let entries = &plan.operation_scatter.scatter;
        let width = entries.len();
        if self.start_block(remaining) {
            let mut ahead = std::mem::take(&mut self.lane_ahead);
            ahead.resize(self.ahead_operations * L::LANES * width, 0.0);
            self.draw_block(|k, op, rng, rejections| {
                let at = (op * L::LANES + k) * width;
                for (slot, &(index, scatter)) in ahead[at..at + width].iter_mut().zip(entries) {
                    *slot = scatter
                        .distribution
                        .sample_counting(rng, &mut rejections[index]);
                }
            });
            self.lane_ahead = ahead;
        }
        let (mut speed, mut radius_m, mut pressure_pa) =
            (self.speed, self.radius_m, self.pressure_pa);
        let row = self.ahead_next * L::LANES * width;
        // In the job's order, as `Draws::set` takes them: a later entry of a parameter wins.
        for (e, &(_, scatter)) in entries.iter().enumerate() {
            let value = L::from_fn(|k| self.lane_ahead[row + k * width + e]);
            match scatter.parameter {
                Parameter::ImpactVelocity => speed = value,
                Parameter::ContactRadius => radius_m = value,
                Parameter::DynamicYieldPressure => pressure_pa = value,
                _ => unreachable!("only lane values draw straight into lanes"),
            }
        }
        self.ahead_next += 1;
        (speed, radius_m, pressure_pa)
    }

    /// The operation with the lanes' draws `op_draws` (this operation's, or swapped ones), on the
    /// lanes' surfaces as their wear has left them.
    #[inline(always)]
    pub(super) fn evaluate(&self, plan: &Plan<'_>, op_draws: &[Draws]) -> Outcomes<L> {
        let fidelity = plan.job.spec().fidelity;
        let lane_speed = |d: &Draws| {
            d.conditions
                .impact_velocity_m_s
                .unwrap_or(self.operation.impact_velocity_m_s())
        };
        let (operation, wear_law, speed, radius_m, pressure_pa) =
            if plan.operation_scatter.is_empty() {
                (
                    self.operation,
                    self.model.wear,
                    self.speed,
                    self.radius_m,
                    self.pressure_pa,
                )
            } else if plan.cheap_operation_scatter {
                (
                    self.operation,
                    self.model.wear,
                    L::from_fn(|k| lane_speed(&op_draws[k])),
                    L::from_fn(|k| op_draws[k].radius_m),
                    L::from_fn(|k| op_draws[k].pressure_pa),
                )
            } else {
                debug_assert_eq!(L::LANES, 1, "only lane parameters scatter in lockstep");
                let draws = &op_draws[0];
                let model = if plan.operation_constants {
                    plan.model(draws)
                } else {
                    Cow::Borrowed(&*self.model)
                };
                let operation = model.setup.operation(&draws.conditions, fidelity);
                (
                    operation,
                    model.wear,
                    L::splat(operation.impact_velocity_m_s()),
                    L::splat(draws.radius_m),
                    L::splat(draws.pressure_pa),
                )
            };
        self.evaluate_lanes(plan, &operation, wear_law, speed, radius_m, pressure_pa)
    }

    /// The operation at the lanes' speed, radius and pressure, on the lanes' surfaces as their
    /// wear has left them.
    #[inline(always)]
    pub(super) fn evaluate_lanes(
        &self,
        plan: &Plan<'_>,
        operation: &Operation,
        wear_law: WearLaw,
        speed: L,
        radius_m: L,
        pressure_pa: L,
    ) -> Outcomes<L> {
        let (radius_m, pressure_pa) = if plan.track_wear {
            let energy_j = self.wear.cumulative_arc_energy_j;
            let worn = L::splat(0.0).lt(energy_j);
            (
                L::select(worn, wear_law.radius_m(radius_m, energy_j), radius_m),
                L::select(
                    worn,
                    wear_law.pressure_pa(pressure_pa, energy_j),
                    pressure_pa,
                ),
            )
        } else {
            (radius_m, pressure_pa)
        };
        operation.run_lanes(speed, radius_m, pressure_pa, plan.needs, |_, _, _, _| {})
    }
}

/// One batch of devices, as its groups share it.
pub(super) struct Chunk<'a> {
    pub(super) first: u64,
    pub(super) size: u64,
    pub(super) strata: Option<&'a Strata>,
}

/// The devices of a chunk from `first_local` on, as many as the kernel has lanes.
pub(super) struct Devices<'p, 'a> {
    pub(super) plan: &'p Plan<'a>,
    pub(super) chunk: &'p Chunk<'p>,
    pub(super) first_local: u64,
    /// The batch's devices: its first `active` lanes; the others copy the first device.
    pub(super) active: usize,
    pub(super) groups: LaneGroups<'p>,
    pub(super) watched: &'p Watched<'p>,
}

impl LaneWork for Devices<'_, '_> {
    #[inline(always)]
    fn run<L: Real>(mut self) {
        let stopped = self
            .plan
            .run_devices::<L>(
                self.chunk,
                self.first_local,
                self.active,
                &mut self.groups,
                self.watched,
            )
            .is_err();
        self.watched.stopped.set(stopped);
    }
}

/// Operations of a batch between two looks at its [`Observer`]: how soon a batch of devices
/// with many operations each stops when its job is cancelled, and how often it tells its progress
/// (a few milliseconds of a batch of 32 lanes; a look is a branch an operation and an atomic read
/// each time).
pub(super) const OPERATIONS_PER_LOOK: u64 = 1024;

/// The observer a batch reports to as it runs, with the run's shared count of operations done;
/// `stopped` once it saw the job cancelled.
pub(super) struct Watched<'p> {
    pub(super) observer: &'p dyn Observer,
    pub(super) done: &'p AtomicU64,
    pub(super) total: u64,
    pub(super) stopped: std::cell::Cell<bool>,
}

impl Watched<'_> {
    /// Tells the observer that `devices` ran `operations` more each; whether to go on.
    fn ran(&self, devices: u64, operations: u64) -> Result<(), Cancelled> {
        let ran = devices * operations;
        let done = self.done.fetch_add(ran, Ordering::Relaxed) + ran;
        self.observer.progress(done, self.total);
        if self.observer.cancelled() {
            return Err(Cancelled);
        }
        Ok(())
    }
}

/// The groups whose devices share a kernel's lanes, side by side in lane order: `stats[i]` is
/// the stats of the group whose devices are in the lanes `lanes[i]`; together they hold the
/// active lanes.
pub(super) struct LaneGroups<'p> {
    pub(super) stats: &'p mut [GroupStats],
    pub(super) lanes: Vec<Range<usize>>,
}

impl LaneGroups<'_> {
    /// Each group's stats with its lanes.
    pub(super) fn each(&mut self) -> impl Iterator<Item = (&mut GroupStats, Range<usize>)> {
        self.stats.iter_mut().zip(self.lanes.iter().cloned())
    }
}

/// A bin's end: the sensitivity cells' sums of the bin into the group's (`bin_index`), and each
/// group's lane sums into its accumulators of the bin (`bin`, by metric).
#[inline(always)]
fn end_bin<L: Real>(
    cells: Option<&mut LaneCells<'_>>,
    groups: &mut LaneGroups<'_>,
    bin_index: usize,
    bin: Range<usize>,
    sums: &[LaneSums<L>],
) {
    if let Some(cells) = cells {
        cells.merge_bin(&mut groups.stats[0].sensitivity, bin_index);
    }
    for (stats, lanes) in groups.each() {
        for (accumulator, sums) in stats.operations[bin.clone()].iter_mut().zip(sums) {
            accumulator.add_lanes(sums, lanes.clone());
        }
    }
}
