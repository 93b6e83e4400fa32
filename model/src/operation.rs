//! One make operation: the first impact and the bounce sequence that follows it
//! (docs/model.md sections 3-5 and 7).

use crate::arc::{Arc, ArcRestitution, ArcRestitutionLaw, arc_current_a, softened_kappa};
use crate::impact::{Impact, contact_stiffness};
use crate::lanes::{Mask, Real};
use crate::mechanism::{Flight, effective_mass, effective_stiffness, impact_velocity};
use crate::restitution::{self, KappaLaw, LOWER_BOUND_FACTOR};
use crate::scenario::{ArcRestitutionLawKind, Scenario};
use serde::{Deserialize, Serialize};

/// How the model is evaluated (docs/model.md section 7).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fidelity {
    /// Eq. 7 solved to a few ulps, exact flight (eq. 3).
    #[default]
    Exact,
    /// The paper's approximations: eq. 18 for `e`, constant-force flight (eq. 4) whenever `F_s > 0`.
    ClosedForm,
}

impl Fidelity {
    pub const ALL: [Fidelity; 2] = [Fidelity::Exact, Fidelity::ClosedForm];

    pub fn as_str(self) -> &'static str {
        match self {
            Fidelity::Exact => "exact",
            Fidelity::ClosedForm => "closed_form",
        }
    }
}

/// The operating conditions Monte Carlo scatter may replace per device or per operation; everything
/// else comes from the scenario. (Radius and pressure are arguments of [`Operation::run`] because wear
/// changes them from one operation to the next.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conditions {
    pub drop_height_m: f64,
    pub static_force_n: f64,
    pub impact_velocity_m_s: Option<f64>,
    pub current_a: f64,
    pub breakdown_field_v_per_m: f64,
}

impl Conditions {
    pub fn nominal(scenario: &Scenario) -> Self {
        let spec = scenario.spec();
        Self {
            drop_height_m: spec.mechanism.drop_height_m,
            static_force_n: spec.mechanism.static_force_n,
            impact_velocity_m_s: spec.mechanism.impact_velocity_m_s,
            current_a: spec.circuit.current_a,
            breakdown_field_v_per_m: spec.material.breakdown_field_v_per_m,
        }
    }
}

/// Which optional parts of an operation to compute: skip what no metric asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Needs {
    /// First-impact peak force and duration (section 4).
    pub impact: bool,
}

impl Needs {
    pub const ALL: Needs = Needs { impact: true };
}

/// What one operation produced: the `simulate` output of docs/contract.md "Scenario", without the
/// bounce list.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Outcome {
    pub impact_velocity_m_s: f64,
    /// Unsoftened kappa of eq. 8 at this operation's radius and pressure.
    pub kappa: f64,
    /// First impact's coefficient of restitution (after pre-arc softening).
    pub e1: f64,
    pub first_bounce_s: f64,
    pub total_bounce_s: f64,
    pub bounce_count: u32,
    pub pre_arc_s: f64,
    pub arc_energy_j: f64,
    pub peak_force_n: f64,
    pub impact_duration_s: f64,
    /// The sequence reached `max_bounces` with another bounce to come.
    pub truncated: bool,
    /// Energy the first impact leaves in the surface (docs/model.md section 4). A job metric; the
    /// `simulate` output of docs/contract.md "Scenario" keeps its fixed fields and leaves it out.
    #[serde(skip)]
    pub first_impact_plastic_work_j: f64,
}

/// What one operation produced on every lane of a [`Real`]: an [`Outcome`] per lane.
#[derive(Debug, Clone, Copy)]
pub struct Outcomes<L: Real> {
    pub impact_velocity_m_s: L,
    pub kappa: L,
    pub e1: L,
    pub first_bounce_s: L,
    pub total_bounce_s: L,
    /// A whole number per lane.
    pub bounce_count: L,
    pub pre_arc_s: L,
    pub arc_energy_j: L,
    pub peak_force_n: L,
    pub impact_duration_s: L,
    pub truncated: L::Mask,
    pub first_impact_plastic_work_j: L,
}

impl<L: Real> Outcomes<L> {
    /// The outcome of lane `i`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Outcome {
        Outcome {
            impact_velocity_m_s: self.impact_velocity_m_s.lane(i),
            kappa: self.kappa.lane(i),
            e1: self.e1.lane(i),
            first_bounce_s: self.first_bounce_s.lane(i),
            total_bounce_s: self.total_bounce_s.lane(i),
            // At most `max_bounces`, a u32.
            bounce_count: self.bounce_count.lane(i) as u32,
            pre_arc_s: self.pre_arc_s.lane(i),
            arc_energy_j: self.arc_energy_j.lane(i),
            peak_force_n: self.peak_force_n.lane(i),
            impact_duration_s: self.impact_duration_s.lane(i),
            truncated: self.truncated.lane(i),
            first_impact_plastic_work_j: self.first_impact_plastic_work_j.lane(i),
        }
    }
}

/// The bounce loop's state on every lane of a [`Real`].
#[derive(Clone, Copy)]
struct Flights<L: Real> {
    /// Separation speed of the flight to come.
    v: L,
    /// `kappa^2` of the surface the impacts meet.
    kappa_sq: L,
    /// A whole number per lane.
    bounce_count: L,
    first_bounce_s: L,
    total_bounce_s: L,
    arc_energy_j: L,
    /// Lanes still bouncing.
    active: L::Mask,
    truncated: L::Mask,
}

impl<L: Real> Flights<L> {
    /// The active lanes, at most `L::Part::LANES` of them, moved into the first lanes of a
    /// narrower batch (the rest inactive), with the lanes they came from.
    #[inline(always)]
    fn gather(&self) -> (Gathered, Flights<L::Part>) {
        let mut lanes = Gathered::default();
        for i in 0..L::LANES {
            if self.active.lane(i) {
                lanes.from[lanes.len] = i;
                lanes.len += 1;
            }
        }
        let from = |x: L| L::Part::from_fn(|j| x.lane(lanes.from[j.min(lanes.len - 1)]));
        let narrow = Flights {
            v: from(self.v),
            kappa_sq: from(self.kappa_sq),
            bounce_count: from(self.bounce_count),
            first_bounce_s: from(self.first_bounce_s),
            total_bounce_s: from(self.total_bounce_s),
            arc_energy_j: from(self.arc_energy_j),
            active: <L::Part as Real>::Mask::from_fn(|j| j < lanes.len),
            truncated: <L::Part as Real>::Mask::from_fn(|_| false),
        };
        (lanes, narrow)
    }

    /// Writes the lanes [`Flights::gather`] moved back where they came from.
    #[inline(always)]
    fn scatter(&mut self, lanes: &Gathered, narrow: &Flights<L::Part>) {
        for (j, &i) in lanes.from[..lanes.len].iter().enumerate() {
            self.v.set_lane(i, narrow.v.lane(j));
            self.bounce_count.set_lane(i, narrow.bounce_count.lane(j));
            self.first_bounce_s
                .set_lane(i, narrow.first_bounce_s.lane(j));
            self.total_bounce_s
                .set_lane(i, narrow.total_bounce_s.lane(j));
            self.arc_energy_j.set_lane(i, narrow.arc_energy_j.lane(j));
            self.active.set_lane(i, narrow.active.lane(j));
            self.truncated.set_lane(i, narrow.truncated.lane(j));
        }
    }
}

/// Which lanes of a batch [`Flights::gather`] moved into a narrower one: at most eight, as no
/// [`Real::Part`] is wider.
#[derive(Default)]
struct Gathered {
    from: [usize; 8],
    len: usize,
}

/// One bounce: the flight after a separation.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bounce {
    pub separation_velocity_m_s: f64,
    pub duration_s: f64,
    pub peak_gap_m: f64,
    pub arc_energy_j: f64,
}

/// The full `simulate` output: the outcome and its bounces.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Simulation {
    #[serde(flatten)]
    pub outcome: Outcome,
    pub bounces: Vec<Bounce>,
}

/// The model of a make operation under fixed conditions, with everything that does not depend on
/// the surface state worked out once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Operation {
    fidelity: Fidelity,
    mass_kg: f64,
    static_force_n: f64,
    flight: Flight,
    /// Constant-force flight (eq. 4) instead of eq. 3: closed form with `F_s > 0`.
    constant_force_flight: bool,
    impact_velocity_m_s: f64,
    kappa_law: KappaLaw,
    arc: Option<Arc>,
    arc_restitution: ArcRestitution,
    /// How strongly the arc changes restitution (section 5): 1 under the paper law.
    arc_weight: f64,
    /// `2 eps / m`: the squared speed an impact's energy loss removes.
    loss_speed_sq: f64,
    /// The separation speed whose flight just reaches `min_separation_m`; slower flights end the sequence.
    min_bounce_speed: f64,
    /// Neither an impact's energy loss nor a least gap can end a sequence, only the cap: a speed
    /// too small for f64 flies on at the least positive one (docs/model.md section 3).
    never_rests: bool,
    max_bounces: u32,
}

/// What a scenario fixes for all its operations (mechanism, material, losses), worked out once;
/// [`Setup::operation`] then applies the conditions of one device or operation cheaply.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    mass_kg: f64,
    stiffness_n_per_m: f64,
    kappa_law: KappaLaw,
    supply_voltage_v: f64,
    min_arc_voltage_v: f64,
    min_arc_current_a: f64,
    softening_energy_j: f64,
    arc_restitution: ArcRestitution,
    loss_speed_sq: f64,
    min_separation_m: f64,
    max_bounces: u32,
}

impl Setup {
    pub fn new(scenario: &Scenario) -> Self {
        let spec = scenario.spec();
        let (mech, mat) = (&spec.mechanism, &spec.material);
        let mass_kg = effective_mass(mech.inertia_kg_m2, mech.contact_arm_m);
        Self {
            mass_kg,
            stiffness_n_per_m: effective_stiffness(
                mech.spring_stiffness_n_per_m,
                mech.spring_arm_m,
                mech.contact_arm_m,
            ),
            kappa_law: KappaLaw {
                reference_kappa: mat.kappa.unwrap_or_else(|| {
                    restitution::kappa(
                        mat.dynamic_yield_pressure_pa,
                        mat.contact_radius_m,
                        mat.youngs_modulus_pa,
                        mass_kg,
                    )
                }),
                reference_radius_m: mat.contact_radius_m,
                reference_pressure_pa: mat.dynamic_yield_pressure_pa,
            },
            supply_voltage_v: spec.circuit.supply_voltage_v,
            min_arc_voltage_v: mat.min_arc_voltage_v,
            min_arc_current_a: mat.min_arc_current_a,
            softening_energy_j: mat.softening_energy_j,
            arc_restitution: ArcRestitution {
                a: mat.arc_restitution.a,
                b_s_per_m: mat.arc_restitution.b_s_per_m,
                law: match mat.arc_restitution.law {
                    ArcRestitutionLawKind::Paper => ArcRestitutionLaw::Paper,
                    ArcRestitutionLawKind::Continuous => ArcRestitutionLaw::Continuous {
                        calibration_arc_current_a: arc_current_a(
                            mat.arc_restitution.calibration_current_a,
                            spec.circuit.supply_voltage_v,
                            mat.min_arc_voltage_v,
                        ),
                    },
                },
            },
            loss_speed_sq: 2.0 * spec.losses.impact_energy_loss_j / mass_kg,
            min_separation_m: spec.losses.min_separation_m,
            max_bounces: spec.losses.max_bounces,
        }
    }

    pub fn kappa_law(&self) -> &KappaLaw {
        &self.kappa_law
    }

    /// The operation under the given conditions.
    pub fn operation(&self, conditions: &Conditions, fidelity: Fidelity) -> Operation {
        let static_force_n = conditions.static_force_n;
        let constant_force_flight = fidelity == Fidelity::ClosedForm && static_force_n > 0.0;
        // g(v) is increasing in v, and the flight that peaks at g_min is the drop from height g_min
        // (eq. 2 with H = g_min): comparing speeds is comparing gaps, without a gap per flight.
        let gap_stiffness = if constant_force_flight {
            0.0
        } else {
            self.stiffness_n_per_m
        };
        let min_bounce_speed = impact_velocity(
            self.mass_kg,
            gap_stiffness,
            static_force_n,
            self.min_separation_m,
        );
        let arc = Arc::strike(
            self.supply_voltage_v,
            conditions.current_a,
            self.min_arc_voltage_v,
            self.min_arc_current_a,
            conditions.breakdown_field_v_per_m,
            self.softening_energy_j,
        );
        // The weight matters only while an arc burns, and only then is it a number.
        let arc_weight = if arc.is_some() {
            self.arc_restitution.weight(
                arc_current_a(
                    conditions.current_a,
                    self.supply_voltage_v,
                    self.min_arc_voltage_v,
                ),
                self.min_arc_current_a,
            )
        } else {
            1.0
        };
        Operation {
            fidelity,
            mass_kg: self.mass_kg,
            static_force_n,
            flight: Flight::new(self.mass_kg, self.stiffness_n_per_m, static_force_n),
            constant_force_flight,
            impact_velocity_m_s: conditions.impact_velocity_m_s.unwrap_or_else(|| {
                impact_velocity(
                    self.mass_kg,
                    self.stiffness_n_per_m,
                    static_force_n,
                    conditions.drop_height_m,
                )
            }),
            kappa_law: self.kappa_law,
            arc,
            arc_restitution: self.arc_restitution,
            arc_weight,
            loss_speed_sq: self.loss_speed_sq,
            min_bounce_speed,
            never_rests: self.loss_speed_sq == 0.0 && min_bounce_speed == 0.0,
            max_bounces: self.max_bounces,
        }
    }
}

impl Operation {
    /// The nominal operation of a scenario.
    pub fn nominal(scenario: &Scenario, fidelity: Fidelity) -> Self {
        Setup::new(scenario).operation(&Conditions::nominal(scenario), fidelity)
    }

    /// Changes the impact velocity (per-operation velocity scatter) in place, without rebuilding
    /// or copying anything else.
    pub fn set_impact_velocity(&mut self, impact_velocity_m_s: f64) {
        self.impact_velocity_m_s = impact_velocity_m_s;
    }

    pub fn impact_velocity_m_s(&self) -> f64 {
        self.impact_velocity_m_s
    }

    pub fn kappa_law(&self) -> &KappaLaw {
        &self.kappa_law
    }

    pub fn arcs(&self) -> bool {
        self.arc.is_some()
    }

    /// The flight between impacts, for the paper's closed forms ([`crate::paper_forms`]).
    pub fn flight(&self) -> &Flight {
        &self.flight
    }

    pub fn static_force_n(&self) -> f64 {
        self.static_force_n
    }

    /// Eq. 16's line `e = a + b v`, as `(a, b)`.
    pub fn arc_restitution_line(&self) -> (f64, f64) {
        (self.arc_restitution.a, self.arc_restitution.b_s_per_m)
    }

    /// Runs one operation on a surface of radius `radius_m` and pressure `pressure_pa`.
    ///
    /// Allocates nothing; the bounces are pushed to `bounces` when it is given.
    pub fn run(
        &self,
        radius_m: f64,
        pressure_pa: f64,
        needs: Needs,
        bounces: Option<&mut Vec<Bounce>>,
    ) -> Outcome {
        let u = self.impact_velocity_m_s;
        let outcomes = match bounces {
            Some(list) => self.run_lanes(
                u,
                radius_m,
                pressure_pa,
                needs,
                |_, v, duration_s, arc_energy_j| {
                    list.push(Bounce {
                        separation_velocity_m_s: v,
                        duration_s,
                        peak_gap_m: self.peak_gap_m(v),
                        arc_energy_j,
                    });
                },
            ),
            None => self.run_lanes(u, radius_m, pressure_pa, needs, |_, _, _, _| {}),
        };
        outcomes.lane(0)
    }

    /// Runs one operation on every lane: impact speed `u` (in place of this operation's own) on a
    /// surface of radius `radius_m` and pressure `pressure_pa`. The lanes advance in lockstep, each
    /// exactly as it would alone; the bounce loop runs until every lane has stopped, a stopped lane
    /// keeping its values. `on_bounce(lane, v, duration, arc energy)` sees every bounce of every
    /// lane, in order for each lane.
    #[inline(always)]
    pub fn run_lanes<L: Real>(
        &self,
        u: L,
        radius_m: L,
        pressure_pa: L,
        needs: Needs,
        mut on_bounce: impl FnMut(usize, f64, f64, f64),
    ) -> Outcomes<L> {
        let c = L::splat;
        let zero = c(0.0);
        let kappa = self.kappa_law.at(radius_m, pressure_pa);
        // A lane that does not move keeps its speed and kappa, and zero for everything else.
        let moving = zero.lt(u);
        let keep = |x: L| L::select(moving, x, zero);

        let (pre_arc_s, pre_arc_energy_j, kappa_1, pressure_1) =
            self.pre_arc(u, kappa, pressure_pa);
        let e1 = match self.fidelity {
            Fidelity::Exact => restitution::restitution(u, kappa_1),
            Fidelity::ClosedForm => restitution::restitution_closed_form(u, kappa_1),
        };
        let (peak_force_n, impact_duration_s, plastic_work_j) = if needs.impact {
            let impact = Impact {
                mass_kg: c(self.mass_kg),
                contact_stiffness_n_per_m: contact_stiffness(radius_m, pressure_1),
                static_force_n: c(self.static_force_n),
                impact_speed_m_s: u,
            };
            let (peak, duration) = impact.peak_force_and_duration(e1);
            (peak, duration, impact.plastic_work_j(peak))
        } else {
            (zero, zero, zero)
        };

        // The loop carries squared speeds: an impact multiplies v^2 by e^2 and removes 2 eps / m.
        let rebound = e1 * u;
        let v = self.separation_speed(rebound * rebound);
        let mut flights = Flights {
            active: moving & self.bouncing(v),
            v,
            // The surface every later impact meets: softened while an arc burns (section 5).
            kappa_sq: if self.arc.is_some() {
                kappa_1 * kappa_1
            } else {
                kappa * kappa
            },
            bounce_count: zero,
            first_bounce_s: zero,
            total_bounce_s: zero,
            arc_energy_j: pre_arc_energy_j,
            truncated: zero.lt(zero),
        };
        // Once no more lanes bounce than a narrower batch holds, they move into one and finish
        // there, so that the stopped lanes stop costing (docs/performance-history.md "Lanes
        // that have stopped"); each lane computes the same in either.
        while flights.active.any() {
            if L::LANES > L::Part::LANES && flights.active.count() <= L::Part::LANES {
                let (lanes, mut narrow) = flights.gather();
                while narrow.active.any() {
                    self.bounce(&mut narrow, &mut |j, v, duration_s, arc_energy_j| {
                        on_bounce(lanes.from[j], v, duration_s, arc_energy_j)
                    });
                }
                flights.scatter(&lanes, &narrow);
                break;
            }
            self.bounce(&mut flights, &mut on_bounce);
        }
        let Flights {
            bounce_count,
            first_bounce_s,
            total_bounce_s,
            arc_energy_j,
            truncated,
            ..
        } = flights;
        Outcomes {
            impact_velocity_m_s: u,
            kappa,
            e1: keep(e1),
            first_bounce_s,
            total_bounce_s,
            bounce_count,
            pre_arc_s: keep(pre_arc_s),
            arc_energy_j: keep(arc_energy_j),
            peak_force_n: keep(peak_force_n),
            impact_duration_s: keep(impact_duration_s),
            truncated,
            first_impact_plastic_work_j: keep(plastic_work_j),
        }
    }

    /// The pre-impact arc at impact speed `u` (section 5): its duration and energy, and the
    /// kappa and pressure the first impact meets on the surface it softened, in full under the
    /// paper law (a weight of exactly 1 changes no bit). Without an arc: none, and the surface as
    /// it is.
    #[inline(always)]
    fn pre_arc<L: Real>(&self, u: L, kappa: L, pressure_pa: L) -> (L, L, L, L) {
        let Some(arc) = &self.arc else {
            return (L::splat(0.0), L::splat(0.0), kappa, pressure_pa);
        };
        let pre_arc_s = arc.pre_arc_duration_s(u);
        let energy_j = arc.energy_j(pre_arc_s);
        let ratio = arc.softening_ratio(L::splat(self.arc_weight) * energy_j);
        (
            pre_arc_s,
            energy_j,
            softened_kappa(kappa, ratio),
            pressure_pa * ratio,
        )
    }

    /// Whether a flight at separation speed `v` counts as a bounce: it opens the contact and reaches
    /// `min_separation_m`.
    #[inline(always)]
    fn bouncing<L: Real>(&self, v: L) -> L::Mask {
        L::splat(0.0).lt(v) & L::splat(self.min_bounce_speed).le(v)
    }

    /// One step of the bounce loop on the lanes of `f`: a lane at `max_bounces` stops (truncated);
    /// every other active lane flies, lands and separates again, or stops.
    #[inline(always)]
    fn bounce<L: Real>(
        &self,
        f: &mut Flights<L>,
        on_bounce: &mut impl FnMut(usize, f64, f64, f64),
    ) {
        let c = L::splat;
        let at_cap = f.active & f.bounce_count.eq(c(f64::from(self.max_bounces)));
        f.truncated = f.truncated | at_cap;
        f.active = f.active & !at_cap;
        if !f.active.any() {
            return;
        }
        let active = f.active;
        let v = f.v;
        let duration_s = self.flight_time_s(v);
        f.bounce_count = L::select(active, f.bounce_count + c(1.0), f.bounce_count);
        f.total_bounce_s = L::select(active, f.total_bounce_s + duration_s, f.total_bounce_s);
        f.first_bounce_s = L::select(
            active & f.bounce_count.eq(c(1.0)),
            duration_s,
            f.first_bounce_s,
        );
        let bounce_arc_energy_j = match &self.arc {
            Some(arc) => arc.energy_j(duration_s),
            None => c(0.0),
        };
        f.arc_energy_j = L::select(active, f.arc_energy_j + bounce_arc_energy_j, f.arc_energy_j);
        for i in 0..L::LANES {
            if active.lane(i) {
                on_bounce(
                    i,
                    v.lane(i),
                    duration_s.lane(i),
                    bounce_arc_energy_j.lane(i),
                );
            }
        }
        // Whether the impact gives any rebound at all: eq. 16's `a + b v` may reach 0, eq. 7's and
        // eq. 18's `e` never do.
        let (rebound_sq, rebounds) = if self.arc.is_some() {
            let e_sq = self.arc_restitution_squared(v, f.kappa_sq);
            (e_sq * (v * v), c(0.0).lt(e_sq))
        } else {
            (self.rebound_squared(v, f.kappa_sq), active)
        };
        f.v = self.separation_speed(rebound_sq);
        if self.never_rests {
            // The exact sequence never ends: a rebound speed that f64 rounds to 0 (below about
            // 1e-162 m/s) is the least positive one, and the sequence runs on to the cap.
            let underflowed = active & rebounds & f.v.eq(c(0.0));
            f.v = L::select(underflowed, c(f64::from_bits(1)), f.v);
        }
        f.active = active & self.bouncing(f.v);
    }

    /// The full `simulate` output at this operation's nominal radius and pressure.
    pub fn simulate(&self) -> Simulation {
        let mut bounces = Vec::new();
        let law = self.kappa_law;
        let outcome = self.run(
            law.reference_radius_m,
            law.reference_pressure_pa,
            Needs::ALL,
            Some(&mut bounces),
        );
        Simulation { outcome, bounces }
    }

    /// The squared rebound speed `(e v)^2` of an impact at speed `v` at this fidelity (eq. 7 or
    /// eq. 18), from `kappa^2`. Eq. 18 needs no division: `(e v)^2 = min(v^2, kappa^2 v sqrt(v))`.
    #[inline(always)]
    fn rebound_squared<L: Real>(&self, v: L, kappa_sq: L) -> L {
        let v_sq = v * v;
        match self.fidelity {
            Fidelity::Exact => restitution::restitution_squared_scaled(kappa_sq / v.sqrt()) * v_sq,
            Fidelity::ClosedForm => (kappa_sq * v * v.sqrt()).min(v_sq),
        }
    }

    /// Eq. 16 after an arcing bounce, squared: `min(e(v; kappa_1), max(0, a + b v))^2`. Where the
    /// linear law is at or below eq. 7's cheap lower bound `min(1, (5/8)^(3/8) eps0)` it is the
    /// minimum, and eq. 7's root is not needed (the result is identical either way). An arc
    /// weighted below 1 (the continuous law, section 5) takes [`ArcRestitution::weighted`] instead.
    #[inline(always)]
    fn arc_restitution_squared<L: Real>(&self, v: L, kappa_1_sq: L) -> L {
        let eps0_sq = kappa_1_sq / v.sqrt();
        if self.arc_weight < 1.0 {
            let mechanical = self.mechanical_restitution_squared(eps0_sq).sqrt();
            let e = self
                .arc_restitution
                .weighted(mechanical, v, self.arc_weight);
            return e * e;
        }
        let linear = self.arc_restitution.linear(v);
        let linear_sq = linear * linear;
        let below_bound = linear_sq
            .le((L::splat(LOWER_BOUND_FACTOR * LOWER_BOUND_FACTOR) * eps0_sq).min(L::splat(1.0)));
        L::select(
            below_bound,
            linear_sq,
            linear_sq.min(self.mechanical_restitution_squared(eps0_sq)),
        )
    }

    /// `e^2` of eq. 7 (or eq. 18) from the squared scaled speed `eps0^2 = kappa^2 / sqrt(v)`.
    #[inline(always)]
    fn mechanical_restitution_squared<L: Real>(&self, eps0_sq: L) -> L {
        match self.fidelity {
            Fidelity::Exact => restitution::restitution_squared_scaled(eps0_sq),
            Fidelity::ClosedForm => eps0_sq.min(L::splat(1.0)),
        }
    }

    /// Speed after an impact from the squared rebound speed `(e v)^2`, less the energy `eps` every
    /// impact loses (section 3): `v' = sqrt(max(0, (e v)^2 - 2 eps / m))`.
    #[inline(always)]
    fn separation_speed<L: Real>(&self, rebound_sq: L) -> L {
        (rebound_sq - L::splat(self.loss_speed_sq))
            .max(L::splat(0.0))
            .sqrt()
    }

    #[inline(always)]
    fn flight_time_s<L: Real>(&self, v: L) -> L {
        if self.constant_force_flight {
            self.flight.constant_force_time_s(v)
        } else {
            self.flight.exact_time_s(v)
        }
    }

    fn peak_gap_m(&self, v: f64) -> f64 {
        if self.constant_force_flight {
            self.flight.constant_force_peak_gap_m(v)
        } else {
            self.flight.exact_peak_gap_m(v)
        }
    }
}

/// `simulate` of docs/contract.md "Scenario": one operation of a scenario at the given fidelity,
/// with every bounce.
pub fn simulate(scenario: &Scenario, fidelity: Fidelity) -> Simulation {
    Operation::nominal(scenario, fidelity).simulate()
}
