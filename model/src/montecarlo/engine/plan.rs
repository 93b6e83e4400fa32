//! The plan: the job worked out once for the hot loop, and its batches, each cut into groups
//! that run in parallel, each group's devices in index order.

use super::*;

/// The job worked out for the hot loop.
pub(super) struct Plan<'a> {
    pub(super) job: &'a Job,
    /// The nominal scenario's model.
    pub(super) model: Model,
    pub(super) nominal: Draws,
    pub(super) device_scatter: Entries<'a>,
    pub(super) operation_scatter: Entries<'a>,
    /// Per-operation scatter touches only the velocity, radius or pressure: no operation rebuild.
    pub(super) cheap_operation_scatter: bool,
    /// Per-operation scatter draws a constant of the scenario: a model for every operation.
    pub(super) operation_constants: bool,
    /// Per-operation scatter draws lane values only, none correlated: without a sensitivity
    /// analysis, which reads the draws, they go straight into lanes ([`Variant::draw_lanes`]).
    pub(super) lane_draws: bool,
    pub(super) needs: Needs,
    /// Wear changes the radius only if an arc can burn and a later operation exists.
    pub(super) track_wear: bool,
    /// Only lane parameters (speed, radius, pressure) scatter, so devices can run in lockstep.
    pub(super) lockstep: bool,
    /// The job's kernel and the narrower ones of this CPU, widest first ([`Kernel::narrower`]): a
    /// group's last devices, too few for the kernel's lanes, fill a narrower kernel's.
    pub(super) kernels: Vec<Kernel>,
    pub(super) sensitivity: Option<SensitivityPlan>,
    /// Whether each accumulator keeps its most extreme values ([`crate::stats::Tails`]) for a
    /// threshold asked after the run: not for a run whose groups only make its Result.
    pub(super) keep_tails: bool,
}

impl<'a> Plan<'a> {
    pub(super) fn new(job: &'a Job, kernel: Kernel) -> Self {
        let scenario = job.simulated_scenario();
        let spec = scenario.spec();
        let model = Model::new(scenario);
        let nominal = Draws {
            radius_m: spec.material.contact_radius_m,
            pressure_pa: spec.material.dynamic_yield_pressure_pa,
            conditions: Conditions::nominal(scenario),
            constants: Vec::new(),
        };
        let (device_scatter, operation_scatter) = (
            Entries::new(job, Per::Device),
            Entries::new(job, Per::Operation),
        );
        let cheap_operation_scatter = operation_scatter
            .scatter
            .iter()
            .all(|(_, s)| s.parameter.is_lane_value());
        let operation_constants = operation_scatter
            .scatter
            .iter()
            .any(|(_, s)| s.parameter.is_scenario_constant());
        let lane_draws = !operation_scatter.is_empty()
            && cheap_operation_scatter
            && operation_scatter.correlation.is_none();
        let arcs_scattered = job
            .scatter()
            .iter()
            .any(|s| matches!(s.parameter, Parameter::Current | Parameter::SupplyVoltage));
        let can_arc = model
            .setup
            .operation(&nominal.conditions, job.spec().fidelity)
            .arcs()
            || arcs_scattered;
        let wear = model.wear;
        let mut plan = Self {
            job,
            model,
            nominal,
            device_scatter,
            operation_scatter,
            cheap_operation_scatter,
            operation_constants,
            lane_draws,
            needs: Needs {
                impact: job.operation_metrics().iter().any(|m| m.needs_impact())
                    || job
                        .device_metrics()
                        .iter()
                        .any(|m| Metric::Device(*m).needs_impact())
                    || job.failure().iter().any(|(m, _)| m.needs_impact()),
            },
            track_wear: can_arc && job.spec().operations > 1 && wear.changes_surface(),
            lockstep: job.scatter().iter().all(|s| s.parameter.is_lane_value()),
            kernels: kernel.narrower(),
            sensitivity: None,
            keep_tails: true,
        };
        plan.sensitivity = job.sensitivity().map(|method| {
            // Sums are taken about a new device's values with every scattered parameter at its
            // median: near the outputs' mean, where the nominal scenario's may lie many of their
            // spreads away (a tight scatter about another value), and a variance taken as a small
            // difference of large squares would keep none of its digits.
            let medians: Vec<f64> = (job.scatter().iter())
                .map(|scatter| scatter.distribution.quantile(0.5))
                .collect();
            let mut centre = plan.nominal.clone();
            for (scatter, &median) in job.scatter().iter().zip(&medians) {
                centre.set(scatter.parameter, median);
            }
            let model = plan.model(&centre);
            let operation = model
                .setup
                .operation(&centre.conditions, job.spec().fidelity);
            let outcome = operation
                .run_lanes(
                    operation.impact_velocity_m_s(),
                    centre.radius_m,
                    centre.pressure_pa,
                    plan.needs,
                    |_, _, _, _| {},
                )
                .lane(0);
            let operation_shifts = job
                .operation_metrics()
                .iter()
                .map(|m| m.value(&outcome))
                .collect();
            let device_shifts = job
                .device_metrics()
                .iter()
                .map(|m| plan.device_metric(&model, *m, &centre, &DeviceWear::default()))
                .collect();
            SensitivityPlan::new(job, method, operation_shifts, device_shifts, medians)
        });
        plan
    }

    /// The model of the scenario with the constants `draws` holds: the nominal one when it holds none.
    pub(super) fn model(&self, draws: &Draws) -> Cow<'_, Model> {
        if draws.constants.is_empty() {
            return Cow::Borrowed(&self.model);
        }
        let scenario = self.job.simulated_scenario().with_draws(|spec| {
            for &(parameter, value) in &draws.constants {
                parameter.set_in(spec, value);
            }
        });
        Cow::Owned(Model::new(&scenario))
    }

    /// Draws the device-level scatter of `lanes` devices from `stream_of(device)`, each from its
    /// own stream: their draws, their streams as the operations go on to use them, and the drawn
    /// values by scatter entry (NaN for entries drawn per operation).
    pub(super) fn draw_devices(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        lanes: usize,
        stream_of: impl Fn(u64) -> u64,
        strata: Option<&Strata>,
        rejections: &mut [u64],
    ) -> (Vec<Draws>, Vec<ChaCha8Rng>, Vec<Vec<f64>>) {
        let job = self.job;
        let mut drawn = (
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
        );
        for local in first_local..first_local + lanes as u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(job.seed());
            rng.set_stream(stream_of(chunk.first + local));
            let local_index = usize::try_from(local).expect("batch fits in memory");
            let mut device = self.nominal.clone();
            let mut values = vec![f64::NAN; job.scatter().len()];
            self.device_scatter.draw(
                job,
                strata.map(|p| (p, local_index)),
                &mut rng,
                rejections,
                |index, value| {
                    device.set(job.scatter()[index].parameter, value);
                    values[index] = value;
                },
            );
            drawn.0.push(device);
            drawn.1.push(rng);
            drawn.2.push(values);
        }
        drawn
    }
}

impl<'a> Plan<'a> {
    /// The LHS strata of batch `batch` of `size` devices, when the job samples that way: of each
    /// device-level parameter, a keyed permutation of the batch's devices ([`Permutation`]) whose
    /// keys come from the batch's own stream, evaluated device by device as each draws. Nothing
    /// is held per device, so a group run alone (on a server, a shard) computes its own devices'
    /// strata and no other's: every group of a batch of 1e7 devices drew the five permutations of
    /// all 1e7 with Fisher and Yates's shuffle before, 2 GB of them at 1e8 devices.
    ///
    /// # Panics
    /// If the batch holds 2^32 devices or more (a job holds at most 1e8).
    pub(super) fn batch_strata(&self, batch: u64, size: u64) -> Option<Strata> {
        if self.job.spec().sampler != SamplerKind::Lhs || self.device_scatter.is_empty() {
            return None;
        }
        assert!(size < 1 << 32, "an LHS batch has fewer than 2^32 devices");
        let mut rng = ChaCha8Rng::seed_from_u64(self.job.seed());
        rng.set_stream(LHS_STREAM_BASE | batch);
        let permutations = self
            .device_scatter
            .scatter
            .iter()
            .map(|_| Permutation::new(size, std::array::from_fn(|_| rng.random::<u64>())))
            .collect();
        Some(Strata { permutations })
    }

    /// Runs devices `first..first + size` as batch `batch`, in parallel: each group alone, or a
    /// few small groups side by side on the kernel's lanes ([`Plan::tasks`]).
    pub(super) fn run_batch(
        &self,
        batch: u64,
        first: u64,
        size: u64,
        observer: &dyn Observer,
        done: &AtomicU64,
        total: u64,
    ) -> Result<Vec<GroupStats>, Cancelled> {
        let strata = self.batch_strata(batch, size);
        let chunk = Chunk {
            first,
            size,
            strata: strata.as_ref(),
        };
        let tasks: Vec<Vec<GroupStats>> = self
            .tasks(size)
            .into_par_iter()
            .map(|groups| self.run_groups(&chunk, groups, observer, done, total))
            .collect::<Result<_, _>>()?;
        Ok(tasks.into_iter().flatten().collect())
    }

    /// The groups of a batch of `size` devices that run together, in order. Groups smaller than
    /// the widest kernel (a small job's: 100 devices make groups of 3 and 4) run side by side on
    /// its lanes, as many as it holds. Run alone, each on a narrower kernel with lanes to spare,
    /// a 100 x 100 job's groups took 2.6 of its 6 ms on one thread (the portable 4 lanes, where
    /// AVX2 has 8). Each group's devices run in index order and add to its own accumulators
    /// device after device, so sharing lanes changes no bit. A sensitivity analysis, or a job
    /// whose devices cannot run in lockstep, runs each group alone.
    pub(super) fn tasks(&self, size: u64) -> Vec<Range<u64>> {
        let groups = GROUPS.min(size);
        let shares = self.lockstep && self.sensitivity.is_none();
        let widest = match self.kernels.first() {
            Some(kernel) if shares => kernel.lanes() as u64,
            _ => 1,
        };
        let devices = |groups_of: Range<u64>| {
            group_start(size, groups_of.end) - group_start(size, groups_of.start)
        };
        let mut tasks = Vec::new();
        let mut start = 0;
        while start < groups {
            let mut end = start + 1;
            while end < groups && devices(start..end + 1) <= widest {
                end += 1;
            }
            tasks.push(start..end);
            start = end;
        }
        tasks
    }

    /// Runs group `group`'s contiguous share of a batch alone, its devices in index order.
    pub(super) fn run_chunk(
        &self,
        chunk: &Chunk<'_>,
        group: u64,
        observer: &dyn Observer,
        done: &AtomicU64,
        total: u64,
    ) -> Result<GroupStats, Cancelled> {
        let mut stats = self.run_groups(chunk, group..group + 1, observer, done, total)?;
        Ok(stats.pop().expect("the stats of one group"))
    }

    /// Runs the groups `groups` of a batch, consecutive, their devices in index order, as many
    /// at a time as a kernel has lanes: a group's last devices share a kernel's lanes with the
    /// next group's first.
    pub(super) fn run_groups(
        &self,
        chunk: &Chunk<'_>,
        groups: Range<u64>,
        observer: &dyn Observer,
        done: &AtomicU64,
        total: u64,
    ) -> Result<Vec<GroupStats>, Cancelled> {
        let bound = |group: u64| group_start(chunk.size, group);
        let mut stats: Vec<GroupStats> = (groups.clone())
            .map(|_| GroupStats::new(self.job, self.sensitivity.as_ref(), self.keep_tails))
            .collect();
        let (mut local, end) = (bound(groups.start), bound(groups.end));
        while local < end {
            if observer.cancelled() {
                return Err(Cancelled);
            }
            let left = end - local;
            // A batch of lanes, full or (without a sensitivity analysis) at least half full, its
            // spare lanes computing a copy of its first device, whose values nobody reads: half a
            // batch costs less in lockstep than its devices one by one (docs/performance.md). A
            // group's last devices take the widest kernel they fill so; fewer devices run one by
            // one, through the same code. Every kernel gives the same bits, so the choice changes
            // nothing but the time.
            let fills = |kernel: &&Kernel| {
                let lanes = kernel.lanes() as u64;
                left >= lanes || (2 * left >= lanes && self.sensitivity.is_none())
            };
            let kernel = match self.kernels.iter().find(fills) {
                Some(&kernel) if self.lockstep => kernel,
                _ => Kernel::SCALAR,
            };
            let devices = left.min(kernel.lanes() as u64);
            // The groups with devices among these, and their lanes.
            let lane = |device: u64| usize::try_from(device - local).expect("lanes are few");
            let mut first = None;
            let mut lanes = Vec::new();
            for (i, group) in groups.clone().enumerate() {
                let (from, to) = (
                    bound(group).max(local),
                    bound(group + 1).min(local + devices),
                );
                if from < to {
                    first.get_or_insert(i);
                    lanes.push(lane(from)..lane(to));
                }
            }
            let first = first.expect("the devices belong to the groups");
            let watched = Watched {
                observer,
                done,
                total,
                stopped: false.into(),
            };
            kernel.run(Devices {
                plan: self,
                chunk,
                first_local: local,
                active: usize::try_from(devices).expect("a batch fits in memory"),
                groups: LaneGroups {
                    stats: &mut stats[first..first + lanes.len()],
                    lanes,
                },
                watched: &watched,
            });
            if watched.stopped.get() {
                return Err(Cancelled);
            }
            local += devices;
        }
        Ok(stats)
    }
}
