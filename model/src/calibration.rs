//! Fitting a scenario to measured operations: chosen scenario parameters estimated by least
//! squares from measured bounce times (and, where given, e1, peak force, arc energy), each
//! observation simulated at its own measured impact velocity.
//!
//! The objective is the sum of squared relative residuals,
//! `2 (simulated - measured) / (simulated + measured)` (see `relative_difference`), over every
//! measured quantity of every observation, so that seconds, newtons and joules weigh alike.
//! Parameters are fitted in logarithms (every physical parameter here is positive, so a bound at
//! zero holds by construction) by Levenberg-Marquardt with a finite-difference Jacobian that does
//! not difference across a step of a stepping residual (the total bounce time jumps where a bounce
//! appears or vanishes; see `Problem::jacobian`). Standard errors come from the residual variance
//! `s^2 = RSS / (n - k)` and `(J^T J)^-1` at the optimum. The 95 % intervals are profile-likelihood
//! intervals (see `Profile`): the values of a parameter at which the sum of squares, minimised over
//! the other parameters, stays within `RSS (1 + t^2 / (n - k))`, `t` Student's 0.975 quantile with
//! `n - k` degrees of freedom. Where the model is linear in the logarithm they are
//! `exp(ln x -+ t se)`; where it curves or steps they follow the sum of squares itself, not a
//! derivative at the optimum. The same `(J^T J)^-1` gives the estimates' correlation matrix, and a
//! pair of parameters correlated 0.95 or more in magnitude is warned of: the data fix a
//! combination of them. A parameter the data cannot identify (its column of `J` vanishes, or
//! `J^T J` is singular to working precision) is refused with the reason, naming its place in `fit`.
//!
//! The bounce count is an integer and steps as parameters change, so it does not enter the
//! objective; its residuals are reported with the others.

use crate::error::{FieldError, InvalidInput, Pointer, past_listing};
use crate::linalg::{invert, smallest_pivot, solve};
use crate::montecarlo::Cancelled;
use crate::operation::{Fidelity, Needs, Operation, Simulation, simulate};
use crate::paper_forms::{e_from_bounce_times, e1_from_first_bounce};
use crate::restitution::KappaLaw;
use crate::scenario::{MAX_MAGNITUDE, MIN_MAGNITUDE, Scenario, ScenarioSpec};
use crate::stats::student_t_975;
use crate::wear::{DeviceWear, WearLaw};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};

pub mod study;

/// The most observations one calibration may carry: a fit simulates each of them `2k + 1` times
/// per iteration for `k` parameters (and its profile intervals about twice as often again), so
/// this bounds its time.
pub const MAX_OBSERVATIONS: usize = 1000;
/// The most parameters one calibration may fit.
pub const MAX_PARAMETERS: usize = 8;
/// The magnitude of correlation from which two fitted parameters are warned of as trading off.
pub const TRADE_OFF: f64 = 0.95;
/// The latest operation of an endurance test an observation may be from: every evaluation of the
/// fit runs a device that far, so this bounds a wear curve's cost (10 ms per evaluation).
pub const MAX_OPERATION: u64 = 100_000;

/// A calibration request.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationSpec {
    /// The scenario to start from (defaults as in a job's scenario).
    #[serde(default)]
    pub scenario: ScenarioSpec,
    /// Scenario parameters to fit, as their dotted path in the scenario (`material.kappa`,
    /// `losses.impact_energy_loss_j`, `material.arc_restitution.a`, ...); each a positive number of
    /// the scenario.
    pub fit: Vec<String>,
    /// Measured operations.
    pub observations: Vec<Observation>,
    /// Bounds on fitted parameters, by their name in `fit`: `[lower, upper]`, positive, lower
    /// below upper. The fit stays within them; an estimate on a bound says so.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub bounds: BTreeMap<String, [f64; 2]>,
}

/// One measured operation: any of the quantities, at least one of them measured.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Observation {
    /// Where in an endurance test of the scenario the operation was measured, 0 (a new contact,
    /// the default) to 100000: the operations before it run at the scenario's own conditions and
    /// wear the surface (docs/model.md section 6), so observations along one device's test are
    /// its wear curve.
    pub operation: Option<u64>,
    /// The operation's measured impact velocity, m/s; without it, the scenario's.
    pub impact_velocity_m_s: Option<f64>,
    /// Measured duration of the first bounce, s.
    pub first_bounce_s: Option<f64>,
    /// Measured duration of the second bounce, s (with the first, it gives the paper's eq. 15
    /// reading of e2).
    pub second_bounce_s: Option<f64>,
    /// Measured time from the first touch to the last, s.
    pub total_bounce_s: Option<f64>,
    /// Measured number of bounces (reported against, not fitted: it steps).
    pub bounce_count: Option<u32>,
    /// Coefficient of restitution of the first impact, from a velocity measurement.
    pub e1: Option<f64>,
    /// Measured peak contact force of the first impact, N.
    pub peak_force_n: Option<f64>,
    /// Measured arc energy of the operation, J.
    pub arc_energy_j: Option<f64>,
    /// Measured mass the contacts have lost by erosion, from the start of the test up to and
    /// including this operation, kg.
    pub eroded_mass_kg: Option<f64>,
}

/// The measured quantities that enter the objective, by name: each a positive number.
pub const FITTED: [&str; 7] = [
    "first_bounce_s",
    "second_bounce_s",
    "total_bounce_s",
    "e1",
    "peak_force_n",
    "arc_energy_j",
    "eroded_mass_kg",
];

/// The measured quantities of a bounce, each 0 where the contact closes at no speed.
const BOUNCES: [&str; 4] = ["first_bounce_s", "second_bounce_s", "total_bounce_s", "e1"];

/// The values a measured quantity of [`FITTED`] may take: a scenario's positive magnitudes, and
/// for `e1`, a coefficient of restitution, at most 1 (an `e1` of 1.5 was fitted as if the model
/// could reach it; found from outside).
pub fn measured_range(quantity: &str) -> [f64; 2] {
    match quantity {
        "e1" => [MIN_MAGNITUDE, 1.0],
        _ => [MIN_MAGNITUDE, MAX_MAGNITUDE],
    }
}

impl Observation {
    /// The measured value of a quantity (a field name: `first_bounce_s`, `bounce_count`, ...), if
    /// measured.
    pub fn measured(&self, quantity: &str) -> Option<f64> {
        match quantity {
            "bounce_count" => self.bounce_count.map(f64::from),
            "first_bounce_s" => self.first_bounce_s,
            "second_bounce_s" => self.second_bounce_s,
            "total_bounce_s" => self.total_bounce_s,
            "e1" => self.e1,
            "peak_force_n" => self.peak_force_n,
            "arc_energy_j" => self.arc_energy_j,
            "eroded_mass_kg" => self.eroded_mass_kg,
            _ => None,
        }
    }
}

/// A fitted parameter.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The least-squares estimate.
    pub value: f64,
    /// 95 % profile-likelihood interval, `[lower, upper]`: where the sum of squares, minimised
    /// over the other parameters, stays within `RSS (1 + t^2 / (n - k))`.
    pub ci95: [f64; 2],
    /// Standard error of the parameter's logarithm, linearised at the optimum.
    pub se_ln: f64,
    /// Present and true when the estimate sits on one of its `bounds`, or on an edge of the
    /// scenarios the model takes (a contact radius no smaller than the worn radius): the data
    /// pull it beyond, and its interval is cut there.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub at_bound: bool,
}

/// Residuals of one measured quantity over the observations that measured it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Residuals {
    /// `simulated - measured`, one per observation that measured the quantity, in order.
    pub values: Vec<f64>,
    /// Root mean square of the relative residuals.
    pub rms_relative: f64,
}

/// The paper's reading of a coefficient of restitution off measured bounce times, with its bias
/// under the fitted model.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// The observations (by index) whose bounce times give a reading.
    pub observations: Vec<usize>,
    /// The paper's reading of each.
    pub values: Vec<f64>,
    /// The reading minus the coefficient it stands for (separation over impact speed), both on
    /// the fitted model's own bounces at each observation's conditions: what the reading's
    /// assumptions (constant-force flight, no energy lost per impact) cost there.
    pub biases: Vec<f64>,
    /// The mean of `biases`.
    pub bias: f64,
    /// `values - biases`: the readings corrected by the fitted model.
    pub corrected: Vec<f64>,
}

/// What a calibration found.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// By parameter, as named in `fit`.
    pub estimates: BTreeMap<String, Estimate>,
    /// The starting scenario with the estimates in place: ready to be a job's scenario.
    #[cfg_attr(feature = "openapi", schema(value_type = Object))]
    pub scenario: ScenarioSpec,
    /// By measured quantity.
    pub residuals: BTreeMap<String, Residuals>,
    /// The paper's readings of e off the measured bounce times: `e1` (eq. 14 with the separation
    /// speed from the first bounce time through eq. 4; needs `first_bounce_s` and a static force)
    /// and `e2` (eq. 15, `T2 / T1`; needs both bounce times). A reading no observation allows is
    /// left out.
    pub restitution_from_bounce_times: BTreeMap<String, Reading>,
    /// Levenberg-Marquardt iterations taken.
    pub iterations: u32,
    /// Residual standard deviation of the relative residuals, `sqrt(RSS / (n - k))`.
    pub residual_sd: f64,
    /// The estimates' correlation matrix (of their logarithms, from `(J^T J)^-1`), by parameter
    /// name and then parameter name, each row holding every parameter, itself with 1. Near -1 or
    /// 1, the two parameters trade off: the data fix a combination of them better than either.
    pub correlation: BTreeMap<String, BTreeMap<String, f64>>,
    /// What the fit cannot vouch for, in words: one warning per side of an interval the data do
    /// not bound within a factor `e^10`, one per pair of parameters whose correlation is 0.95
    /// or more in magnitude, naming them, one when the fit took all its iterations without
    /// settling, and one when it reproduces the data exactly (no noise to draw intervals from).
    /// Absent when empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// The request, checked: the starting scenario as JSON (every field present), the parameters'
/// places in it, and the observations.
struct Problem<'c> {
    base: Value,
    parameters: Vec<(String, Vec<String>)>,
    observations: Vec<Observation>,
    /// `(observation, quantity)` of every term of the objective.
    terms: Vec<(usize, &'static str)>,
    /// `[ln lower, ln upper]` of each parameter (unbounded: the whole line).
    bounds_ln: Vec<[f64; 2]>,
    /// Each parameter's start: the scenario's value, or eq. 8's for kappa.
    starts: Vec<f64>,
    /// `(ln value, value)` of the values each parameter takes exactly, not through its
    /// logarithm ([`Problem::value`]): its start, then its bounds, if any; the bounds first where
    /// the start lies outside them.
    exact: Vec<Vec<(f64, f64)>>,
    /// Set once nobody waits for the fit any more ([`calibrate_until`]).
    cancel: Option<&'c AtomicBool>,
}

impl CalibrationSpec {
    /// Parses a calibration request (JSON text) and checks its rules, naming every field at
    /// fault: those of the wrong type or unknown, read past ([`crate::error::read_past_faults`]),
    /// then the rules of the rest.
    pub fn from_json(text: &str) -> Result<Self, InvalidInput> {
        let (spec, faults) =
            crate::error::read_past_faults::<Self>(text, &["/fit", "/observations", "/bounds/*"])?;
        crate::error::with_faults(faults, Problem::new(&spec).map(drop))?;
        Ok(spec)
    }
}

/// Fits the request's parameters; an invalid request or an ill-posed fit is an error naming the
/// field at fault.
pub fn calibrate(spec: &CalibrationSpec) -> Result<Calibration, InvalidInput> {
    fit(Problem::new(spec)?)
}

/// [`calibrate`], stopped once `cancel` is set: each evaluation of the fit then fails at once (one
/// along a wear curve within 1024 simulated operations), so the fit ends within about one
/// evaluation, with [`Cancelled`]. A fit along wear curves may take minutes; a service stops it
/// when the request that waits for it has gone.
pub fn calibrate_until(
    spec: &CalibrationSpec,
    cancel: &AtomicBool,
) -> Result<Result<Calibration, InvalidInput>, Cancelled> {
    let fitted = Problem::new(spec).and_then(|problem| {
        fit(Problem {
            cancel: Some(cancel),
            ..problem
        })
    });
    if cancel.load(Ordering::Relaxed) {
        return Err(Cancelled);
    }
    Ok(fitted)
}

/// How far (in the logarithm) beyond an estimate a scenario is tried, to tell whether the
/// estimate lies on an edge of the scenarios the model takes: a fit stopped by one ends within
/// about 1e-10 of it (its last steps, damped up to 1e12, refused).
const EDGE_LN: f64 = 1e-8;

/// The root mean square of the relative residuals below which a fit is exact (measurements made
/// by the model itself): no measured value is known that well.
const EXACT_FIT_RMS: f64 = 1e-9;

/// The ratio of two measured quantities' relative residuals (root mean square) from which the
/// fit warns that they were measured (or fit) with different precision; each quantity needs
/// [`UNEQUAL_NOISE_VALUES`] values, and more than the parameters, for its spread to count.
const UNEQUAL_NOISE: f64 = 3.0;
/// See [`UNEQUAL_NOISE`].
const UNEQUAL_NOISE_VALUES: usize = 5;

/// Where Levenberg-Marquardt ended: the parameters, their sum of squares, the iterations taken
/// and whether it settled (`false`: [`MAX_ITERATIONS`] stopped it).
struct Minimum {
    theta: Vec<f64>,
    cost: f64,
    iterations: u32,
    settled: bool,
}

/// The most steps of Levenberg-Marquardt a fit (or a point of a profile) takes: a fit that takes
/// them all says so in its warnings.
const MAX_ITERATIONS: u32 = 100;

fn fit(problem: Problem) -> Result<Calibration, InvalidInput> {
    let given = problem.start();
    let start = problem.within_bounds(given.clone());
    // A start no scenario takes (eq. 8's kappa of contacts of 1e-30 m is 1.5e-35) is the
    // parameter's fault, not the scenario's (it read "/scenario: cannot simulate").
    let magnitudes = MIN_MAGNITUDE.ln()..=MAX_MAGNITUDE.ln();
    if let Some(k) = start.iter().position(|theta| !magnitudes.contains(theta)) {
        return Err(InvalidInput::single(
            &Pointer::root().child("fit").child(k),
            format!(
                "{} starts at {} (its value in the scenario, or eq. 8's for kappa), outside the \
                 1e-30 to 1e30 a scenario's numbers keep: give it a start or `bounds` within them",
                problem.parameters[k].0,
                crate::error::shown(problem.value(k, start[k]))
            ),
        ));
    }
    let at_start = moved_out_of_the_scenario(&problem, &given, &start)?;
    let (theta, iterations, settled) = problem.levenberg_marquardt(start, at_start)?;
    problem.report(&theta, iterations, settled)
}

/// Refuses a `start` its bounds moved from the `given` one to where the scenario cannot run: the
/// bounds' fault (a radius bounded below the worn radius read "/scenario: cannot simulate", found
/// from outside). Each bound that breaks the scenario alone, the other parameters at their
/// starts, is named with the rule; where none does alone, each that moved (two that break a
/// rule between them). Two moved parameters named the first of them, whichever broke it. A
/// start that cannot run unmoved is the scenario's fault, said where the fit starts. The
/// residuals at `start`, where this found them.
fn moved_out_of_the_scenario(
    problem: &Problem,
    given: &[f64],
    start: &[f64],
) -> Result<Option<Vec<f64>>, InvalidInput> {
    let moved: Vec<usize> = (0..start.len()).filter(|&k| start[k] != given[k]).collect();
    if moved.is_empty() {
        return Ok(None);
    }
    if let Some(residuals) = problem.residuals(start) {
        return Ok(Some(residuals));
    }
    if problem.residuals(given).is_none() {
        return Ok(None);
    }
    let alone = |k: usize| {
        let mut theta = given.to_vec();
        theta[k] = start[k];
        theta
    };
    let breaking: Vec<usize> = moved
        .iter()
        .copied()
        .filter(|&k| problem.residuals(&alone(k)).is_none())
        .collect();
    let (at_fault, together) = match breaking.is_empty() {
        true => (moved, true),
        false => (breaking, false),
    };
    let at = Pointer::root().child("scenario");
    let errors = at_fault.into_iter().map(|k| {
        let theta = if together { start.to_vec() } else { alone(k) };
        let why = match problem.spec(&theta).map(|spec| Scenario::new(spec, &at)) {
            Some(Err(invalid)) => format!("breaks a rule: {invalid}"),
            _ => "cannot simulate every observation".to_owned(),
        };
        let name = &problem.parameters[k].0;
        FieldError {
            pointer: Pointer::root()
                .child("bounds")
                .child(name.as_str())
                .to_string(),
            detail: format!(
                "{name} starts at {} (its value in the scenario, or eq. 8's for kappa), outside \
                 these bounds; at their nearer end{} the scenario {why}",
                crate::error::shown(problem.starts[k]),
                if together { ", with the others'," } else { "" }
            ),
        }
    });
    Err(InvalidInput::new(errors.collect()))
}

/// A relative difference this near its end (2) is a simulated value over 2000 times its
/// measurement (or under a 2000th of it): far enough that a small step of a parameter moves it by
/// less than its rounding.
const FAR_RESIDUAL: f64 = 1.998;

/// The fit's residual of a measured (positive) quantity: `2 (simulated - measured) / (simulated +
/// measured)`, the log ratio `ln(simulated / measured)` to third order. The plain relative
/// difference `(simulated - measured) / measured` divides by the noisy value, and with
/// multiplicative noise of relative size `s` it pulls the fit low by about `2 s^2` (0.08 % at 2 %,
/// 0.19 standard errors of kappa in `study::wear_curve`); the symmetric form's pull is `s^2 / 2`
/// and it stays bounded (-2) where a simulated quantity is 0 (no bounce), as the log ratio does not.
fn relative_difference(simulated: f64, measured: f64) -> f64 {
    2.0 * (simulated - measured) / (simulated + measured)
}

impl Problem<'_> {
    fn new(spec: &CalibrationSpec) -> Result<Self, InvalidInput> {
        let mut errors = Vec::new();
        let root = Pointer::root();
        if let Err(invalid) = Scenario::new(spec.scenario.clone(), &root.child("scenario")) {
            errors.extend_from_slice(invalid.errors());
        }
        let base = serde_json::to_value(&spec.scenario).expect("a scenario serialises");
        let parameters = check_fit(spec, &base, &root, &mut errors);
        let terms = check_observations(spec, &root, &mut errors);
        if errors.is_empty() && terms.len() <= parameters.len() {
            errors.push(FieldError {
                pointer: "/observations".into(),
                detail: format!(
                    "{} measured values cannot fit {} parameters with an error estimate: give more than {}",
                    terms.len(),
                    parameters.len(),
                    parameters.len()
                ),
            });
        }
        check_bounds(spec, &parameters, &root, &mut errors);
        if !errors.is_empty() {
            return Err(InvalidInput::new(errors));
        }
        let mut problem = Self {
            bounds_ln: parameters
                .iter()
                .map(|(name, _)| {
                    spec.bounds
                        .get(name)
                        .map_or([f64::NEG_INFINITY, f64::INFINITY], |b| b.map(f64::ln))
                })
                .collect(),
            starts: Vec::new(),
            exact: Vec::new(),
            base,
            parameters,
            observations: spec.observations.clone(),
            terms,
            cancel: None,
        };
        problem.starts = problem
            .parameters
            .iter()
            .map(|(_, path)| problem.start_value(path))
            .collect();
        problem.exact = problem
            .parameters
            .iter()
            .zip(&problem.starts)
            .map(|((name, _), &start)| {
                let bounds = spec.bounds.get(name).copied();
                let outside =
                    bounds.is_some_and(|[lower, upper]| !(lower..=upper).contains(&start));
                let mut values: Vec<f64> = bounds.into_iter().flatten().collect();
                values.insert(if outside { values.len() } else { 0 }, start);
                values
                    .into_iter()
                    .map(|value| (value.ln(), value))
                    .collect()
            })
            .collect();
        Ok(problem)
    }

    /// Parameter `k`'s value at `ln`, its logarithm: exactly its start or a bound where `ln` is
    /// one's logarithm (a start an ulp from a bound shares its logarithm: the start where it lies
    /// within its bounds, else the bound it was moved to), else `exp(ln)`. The round trip through `ln` and `exp` can move a value by an ulp, and a start
    /// or bound on a rule's edge then broke the rule (a radius at the worn radius, found from
    /// outside) or read a hair inside its bound (0.005999999999999998).
    fn value(&self, k: usize, ln: f64) -> f64 {
        let exact = self.exact[k].iter().find(|&&(at, _)| at == ln);
        exact.map_or_else(|| ln.exp(), |&(_, value)| value)
    }

    /// The logarithms of the parameters' starts.
    fn start(&self) -> Vec<f64> {
        self.starts.iter().map(|start| start.ln()).collect()
    }

    fn cancelled(&self) -> bool {
        self.cancel
            .is_some_and(|cancel| cancel.load(Ordering::Relaxed))
    }

    /// Whether parameter `k`, at `theta_k` (its logarithm), lies on a bound that the descent
    /// direction `-gradient` points beyond.
    fn held_on_bound(&self, theta_k: f64, k: usize, gradient: f64) -> bool {
        let [lower, upper] = self.bounds_ln[k];
        (theta_k <= lower && gradient > 0.0) || (theta_k >= upper && gradient < 0.0)
    }

    /// `theta` moved onto its bounds where it lies beyond them (a projected step).
    fn within_bounds(&self, theta: Vec<f64>) -> Vec<f64> {
        theta
            .into_iter()
            .zip(&self.bounds_ln)
            .map(|(t, [lower, upper])| t.clamp(*lower, *upper))
            .collect()
    }

    /// A parameter's starting value: the scenario's, or for an absent kappa the one the model
    /// derives.
    fn start_value(&self, path: &[String]) -> f64 {
        match lookup(&self.base, path).and_then(Value::as_f64) {
            Some(value) => value,
            None => {
                let scenario = self.scenario(&[]).expect("checked in Problem::new");
                simulate(&scenario, Fidelity::Exact).outcome.kappa
            }
        }
    }

    /// The scenario with the parameters at `exp(theta)`; `None` if that breaks a scenario rule.
    fn spec(&self, theta: &[f64]) -> Option<ScenarioSpec> {
        let mut value = self.base.clone();
        for (k, ((_, path), &ln)) in self.parameters.iter().zip(theta).enumerate() {
            let place = path
                .iter()
                .fold(&mut value, |at, key| &mut at[key.as_str()]);
            *place = serde_json::json!(self.value(k, ln));
        }
        serde_json::from_value(value).ok()
    }

    fn scenario(&self, theta: &[f64]) -> Option<Scenario> {
        Scenario::new(self.spec(theta)?, &Pointer::root()).ok()
    }

    /// Every observation's operation at `theta`; `None` where the scenario breaks a rule.
    fn operations(&self, theta: &[f64]) -> Option<Vec<Operation>> {
        let scenario = self.scenario(theta)?;
        self.observations
            .iter()
            .map(|observation| {
                let mut spec = scenario.spec().clone();
                if let Some(v) = observation.impact_velocity_m_s {
                    spec.mechanism.impact_velocity_m_s = Some(v);
                }
                let scenario = Scenario::new(spec, &Pointer::root()).ok()?;
                Some(Operation::nominal(&scenario, Fidelity::Exact))
            })
            .collect()
    }

    /// Every observation simulated at `theta` on the surface its place in the endurance test
    /// gives, with the eroded mass up to it; `None` where the scenario breaks a rule, or once the
    /// fit is cancelled.
    fn simulate_all(&self, theta: &[f64]) -> Option<Vec<Measured>> {
        self.simulate_until(theta, &|| self.cancelled())
    }

    /// [`Problem::simulate_all`] at the optimum, for the report, whether or not the fit was
    /// cancelled meanwhile (its caller drops the report then).
    fn simulate_optimum(&self, theta: &[f64]) -> Vec<Measured> {
        self.simulate_until(theta, &|| false)
            .expect("the optimum simulates")
    }

    fn simulate_until(&self, theta: &[f64], cancelled: &dyn Fn() -> bool) -> Option<Vec<Measured>> {
        if cancelled() {
            return None;
        }
        let scenario = self.scenario(theta)?;
        let law = WearLaw::new(&scenario);
        let energies = self.arc_energy_before(&scenario, &law, cancelled)?;
        let operations = self.operations(theta)?;
        let reference = *operations.first()?.kappa_law();
        Some(
            self.observations
                .iter()
                .zip(&operations)
                .map(|(observation, op)| {
                    let energy_j = energies[&observation.operation.unwrap_or(0)];
                    let (radius_m, pressure_pa) = surface(&law, &reference, energy_j);
                    let mut bounces = Vec::new();
                    let outcome = op.run(radius_m, pressure_pa, Needs::ALL, Some(&mut bounces));
                    Measured {
                        eroded_mass_kg: law.eroded_mass_kg(energy_j + outcome.arc_energy_j),
                        simulation: Simulation { outcome, bounces },
                    }
                })
                .collect(),
        )
    }

    /// The cumulative arc energy before each operation an observation is from: one device run
    /// through the endurance test at the scenario's own conditions; `None` once `cancelled`
    /// (asked every 1024 operations).
    fn arc_energy_before(
        &self,
        scenario: &Scenario,
        law: &WearLaw,
        cancelled: &dyn Fn() -> bool,
    ) -> Option<BTreeMap<u64, f64>> {
        let wanted: BTreeSet<u64> = self
            .observations
            .iter()
            .map(|o| o.operation.unwrap_or(0))
            .collect();
        let last = wanted.last().copied().unwrap_or(0);
        let op = Operation::nominal(scenario, Fidelity::Exact);
        let reference = *op.kappa_law();
        let mut wear = DeviceWear::default();
        let mut energies = BTreeMap::new();
        for j in 0..=last {
            if j % 1024 == 1023 && cancelled() {
                return None;
            }
            if wanted.contains(&j) {
                energies.insert(j, wear.cumulative_arc_energy_j);
            }
            if j < last {
                let (radius_m, pressure_pa) =
                    surface(law, &reference, wear.cumulative_arc_energy_j);
                wear.add(&op.run(radius_m, pressure_pa, Needs::ALL, None));
            }
        }
        Some(energies)
    }

    /// The relative residual of every term at `theta`.
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        self.residuals_of(&self.simulate_all(theta)?)
    }

    /// The relative residual of every term, the observations simulated as `outcomes`.
    fn residuals_of(&self, outcomes: &[Measured]) -> Option<Vec<f64>> {
        let residuals: Vec<f64> = self
            .terms
            .iter()
            .map(|&(i, quantity)| {
                let measured = self.observations[i].measured(quantity).expect("a term");
                relative_difference(simulated(&outcomes[i], quantity), measured)
            })
            .collect();
        residuals.iter().all(|r| r.is_finite()).then_some(residuals)
    }

    /// Jacobian of the residuals in `theta` (log parameters), `at` being the residuals at `theta`;
    /// `None` where steps to both sides leave the scenario's valid range.
    ///
    /// A residual may step as a parameter moves: the total bounce time jumps where a bounce
    /// appears or vanishes. A central difference that straddles such a step gives a derivative of
    /// the jump over the step width, thousands of times the smooth slope, and one such column
    /// entry collapses the covariance. So each residual's forward and backward one-sided
    /// differences are compared: where they agree (the residual is smooth across both), the central
    /// difference stands; where they disagree, a step lies on one side, and the difference of the
    /// smooth side (the smaller in magnitude) is taken. A side whose step leaves the valid range
    /// leaves the other side's difference.
    fn jacobian(&self, theta: &[f64], at: &[f64], free: &[usize]) -> Option<Vec<Vec<f64>>> {
        const STEP: f64 = 1e-5;
        let mut columns = Vec::with_capacity(free.len());
        for &k in free {
            let side = |sign: f64| {
                let mut moved = theta.to_vec();
                moved[k] += sign * STEP;
                self.residuals(&moved)
            };
            let column = match (side(1.0), side(-1.0)) {
                (Some(up), Some(down)) => up
                    .iter()
                    .zip(&down)
                    .zip(at)
                    .map(|((u, d), r)| smooth_side((u - r) / STEP, (r - d) / STEP))
                    .collect(),
                (Some(up), None) => up.iter().zip(at).map(|(u, r)| (u - r) / STEP).collect(),
                (None, Some(down)) => down.iter().zip(at).map(|(d, r)| (r - d) / STEP).collect(),
                (None, None) => return None,
            };
            columns.push(column);
        }
        Some(columns)
    }

    /// Minimises the sum of squared residuals from `start` (its residuals `at_start`, if known);
    /// the optimum, the iterations taken and whether it settled (not stopped by the cap).
    fn levenberg_marquardt(
        &self,
        start: Vec<f64>,
        at_start: Option<Vec<f64>>,
    ) -> Result<(Vec<f64>, u32, bool), InvalidInput> {
        let invalid_start = || {
            InvalidInput::single(
                &Pointer::root().child("scenario"),
                "the starting scenario cannot simulate every observation",
            )
        };
        let all: Vec<usize> = (0..start.len()).collect();
        let residuals = match at_start {
            Some(residuals) => residuals,
            None => self.residuals(&start).ok_or_else(invalid_start)?,
        };
        let minimum = self
            .minimise(start, residuals, &all, 1e-14, |theta, jacobian| {
                self.identifiable(theta, jacobian)
            })?
            .ok_or_else(invalid_start)?;
        Ok((minimum.theta, minimum.iterations, minimum.settled))
    }

    /// Levenberg-Marquardt over the parameters `free` of `theta` (the others held), from
    /// `theta` whose residuals are `residuals`: the optimum, its sum of squares, the iterations
    /// taken and whether it settled (`false`: the cap stopped it), `None` if the Jacobian cannot
    /// be formed. `check` vets each Jacobian (the full fit refuses
    /// parameters the data cannot tell apart).
    fn minimise(
        &self,
        mut theta: Vec<f64>,
        mut residuals: Vec<f64>,
        free: &[usize],
        settle: f64,
        check: impl Fn(&[f64], &[Vec<f64>]) -> Result<(), InvalidInput>,
    ) -> Result<Option<Minimum>, InvalidInput> {
        let mut cost = sum_of_squares(&residuals);
        let mut lambda = 1e-3;
        for iteration in 1..=MAX_ITERATIONS {
            let Some(jacobian) = self.jacobian(&theta, &residuals, free) else {
                return Ok(None);
            };
            check(&theta, &jacobian)?;
            let (jtj, jtr) = normal_equations(&jacobian, &residuals);
            // A parameter on a bound that the descent pushes beyond it stays there, and the step
            // moves the others alone (an active set): the joint step, cut at the bound, would
            // crawl and end at the iteration cap short of the optimum on the bound.
            let moving: Vec<usize> = (0..free.len())
                .filter(|&j| !self.held_on_bound(theta[free[j]], free[j], jtr[j]))
                .collect();
            if moving.is_empty() {
                return Ok(Some(Minimum {
                    theta,
                    cost,
                    iterations: iteration,
                    settled: true,
                }));
            }
            let jtj: Vec<Vec<f64>> = moving
                .iter()
                .map(|&a| moving.iter().map(|&b| jtj[a][b]).collect())
                .collect();
            let jtr: Vec<f64> = moving.iter().map(|&a| jtr[a]).collect();
            let mut improved = false;
            while lambda < 1e12 {
                let mut damped = jtj.clone();
                for (k, row) in damped.iter_mut().enumerate() {
                    row[k] += lambda * jtj[k][k].max(1e-300);
                }
                let Some(step) = solve(damped, jtr.iter().map(|g| -g).collect()) else {
                    lambda *= 10.0;
                    continue;
                };
                let mut trial = theta.clone();
                for (&j, s) in moving.iter().zip(&step) {
                    trial[free[j]] += s;
                }
                let trial = self.within_bounds(trial);
                match self.residuals(&trial) {
                    Some(trial_residuals) if sum_of_squares(&trial_residuals) < cost => {
                        let small = step.iter().all(|s| s.abs() < 1e-10);
                        theta = trial;
                        residuals = trial_residuals;
                        let new_cost = sum_of_squares(&residuals);
                        let converged = small || cost - new_cost <= settle * cost.max(1e-300);
                        cost = new_cost;
                        lambda = (lambda / 10.0).max(1e-12);
                        improved = true;
                        if converged {
                            return Ok(Some(Minimum {
                                theta,
                                cost,
                                iterations: iteration,
                                settled: true,
                            }));
                        }
                        break;
                    }
                    _ => lambda *= 10.0,
                }
            }
            if !improved {
                return Ok(Some(Minimum {
                    theta,
                    cost,
                    iterations: iteration,
                    settled: true,
                }));
            }
        }
        Ok(Some(Minimum {
            theta,
            cost,
            iterations: MAX_ITERATIONS,
            settled: false,
        }))
    }

    /// Refuses a fit whose parameters the data cannot tell apart, naming the first at fault.
    fn identifiable(&self, theta: &[f64], jacobian: &[Vec<f64>]) -> Result<(), InvalidInput> {
        let norms: Vec<f64> = jacobian
            .iter()
            .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
            .collect();
        let largest = norms.iter().copied().fold(0.0, f64::max);
        let fit = Pointer::root().child("fit");
        if let Some(k) = norms
            .iter()
            .position(|&n| n.is_nan() || n <= 1e-9 * largest.max(1e-300))
        {
            let at_start = theta[k] == self.starts[k].ln();
            // Every simulated value thousands of times its measurement (or a thousandth of it):
            // the relative differences sit at their ends (+-2), where no small move shows.
            let far = self
                .residuals(theta)
                .is_some_and(|r| r.iter().all(|r| r.abs() > FAR_RESIDUAL));
            let why = if far {
                " there (every simulated value is over 2000 times its measurement, or under a \
                 2000th of it, where the relative differences no longer move): start the fit \
                 nearer, from the scenario's value of it"
            } else if at_start {
                ", so the data cannot determine it"
            } else {
                // Moved there by the fit: the data drew it where nothing changes.
                ", so the data cannot determine it (the fit moved it there: a measurement beyond \
                 what the model reaches, such as an e1 of 1 or more, or a start far from the \
                 data's value of it, draws the fit to where nothing changes; start it nearer)"
            };
            return Err(InvalidInput::single(
                &fit.child(k),
                format!(
                    "`{}` changes none of the measured quantities at {}{why}",
                    self.parameters[k].0,
                    crate::error::shown(self.value(k, theta[k])),
                ),
            ));
        }
        // Columns scaled to unit length: a near-singular J^T J means two parameters (or more) move
        // the measurements the same way.
        let scaled: Vec<Vec<f64>> = jacobian
            .iter()
            .zip(&norms)
            .map(|(c, n)| c.iter().map(|x| x / n).collect())
            .collect();
        let (gram, _) = normal_equations(&scaled, &vec![0.0; scaled[0].len()]);
        for k in 1..gram.len() {
            let leading: Vec<Vec<f64>> = gram[..=k].iter().map(|r| r[..=k].to_vec()).collect();
            if smallest_pivot(&leading) < 1e-10 {
                let names: Vec<&str> = self.parameters[..=k]
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect();
                return Err(InvalidInput::single(
                    &fit.child(k),
                    format!(
                        "{} move the measured quantities the same way, so the data cannot tell them apart: fit fewer, or measure more quantities",
                        names.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    fn report(
        &self,
        theta: &[f64],
        iterations: u32,
        settled: bool,
    ) -> Result<Calibration, InvalidInput> {
        let outcomes = self.simulate_optimum(theta);
        let residuals = self.residuals_of(&outcomes).expect("the optimum simulates");
        let all: Vec<usize> = (0..theta.len()).collect();
        let jacobian = self.jacobian(theta, &residuals, &all).unwrap_or_else(|| {
            // Neither side of the optimum simulates: no slope, refused as unidentifiable below.
            vec![vec![0.0; residuals.len()]; theta.len()]
        });
        self.identifiable(theta, &jacobian)?;
        let degrees_of_freedom = residuals.len() - theta.len();
        let cost = sum_of_squares(&residuals);
        let (jtj, _) = normal_equations(&jacobian, &residuals);
        let optimum = Optimum {
            theta,
            covariance: invert(jtj).unwrap_or_default(),
            variance: cost / degrees_of_freedom as f64,
            cost,
            degrees_of_freedom,
            t: student_t_975(degrees_of_freedom as u64),
        };
        let mut warnings = Vec::new();
        let estimates = (0..theta.len())
            .map(|i| self.estimate(&optimum, i, &mut warnings))
            .collect();
        let (correlation, trade_offs) = self.correlation(&optimum);
        warnings.extend(trade_offs);
        if (cost / residuals.len() as f64).sqrt() < EXACT_FIT_RMS {
            warnings.push(format!(
                "the fit reproduces the measured values exactly (the root mean square of the \
                 relative residuals is below {EXACT_FIT_RMS:e}): the data hold no estimate of \
                 their noise, so the intervals, drawn from the residuals' spread, are as narrow \
                 as the rounding and say nothing of the measurements' uncertainty"
            ));
        }
        let residuals = self.residuals_by_quantity(&outcomes);
        warnings.extend(unequal_noise(&residuals, theta.len()));
        if !settled {
            warnings.push(format!(
                "the fit took all of its {MAX_ITERATIONS} iterations without settling: the \
                 estimates may lie short of the optimum; start nearer to it (the scenario's \
                 values are the start)"
            ));
        }
        Ok(Calibration {
            estimates,
            scenario: self.spec(theta).expect("the optimum is a scenario"),
            residuals,
            restitution_from_bounce_times: self.readings(theta, outcomes),
            iterations,
            residual_sd: optimum.variance.sqrt(),
            correlation,
            warnings,
        })
    }

    /// Parameter `i`'s estimate with its profile-likelihood interval; a side the data do not
    /// bound adds a warning.
    fn estimate(
        &self,
        optimum: &Optimum,
        i: usize,
        warnings: &mut Vec<String>,
    ) -> (String, Estimate) {
        let (theta, name) = (optimum.theta, &self.parameters[i].0);
        let se_ln = (optimum.variance * optimum.entry(i, i)).sqrt();
        let [lower, upper] = self.bounds_ln[i];
        let profile = Profile {
            problem: self,
            theta,
            parameter: i,
            cost: optimum.cost,
            degrees_of_freedom: optimum.degrees_of_freedom as f64,
            t: optimum.t,
            slopes: (0..theta.len())
                .map(|k| optimum.entry(k, i) / optimum.entry(i, i))
                .collect(),
        };
        // The scenarios the model takes have edges of their own (a contact radius no smaller
        // than the worn one, a yield pressure above the worn pressure): an estimate on one is held
        // there as on a bound, and its interval cut there.
        let on_edge = [-1.0, 1.0].map(|side| {
            let mut beyond = theta.to_vec();
            beyond[i] += side * EDGE_LN;
            self.residuals(&beyond).is_none()
        });
        let wald = optimum.t * se_ln;
        let ends = [-1.0, 1.0].map(|side| {
            if on_edge[usize::from(side > 0.0)] {
                return Bounded::At(0.0);
            }
            match profile.end(side, wald) {
                // An end within a tenth of the Wald half-width is a refit stopped on a step of
                // the sum of squares next to the optimum, not a bound the data set (a wear curve:
                // 22 of 700 kappa intervals, each side so short missed the truth as often as
                // not, where the Wald interval covered 95 %): that side is the Wald end.
                // (An end at the parameter's bound is the bound's: no step stopped it.)
                Bounded::At(end)
                    if end < STUCK_END * wald && wald.is_finite() && end < profile.room(side) =>
                {
                    warnings.push(format!(
                        "`{name}`'s profile could not be followed {} the estimate (its refits stop on steps of the sum of squares); that end of its interval is the Wald one",
                        if side < 0.0 { "below" } else { "above" }
                    ));
                    Bounded::At(profile.room(side).min(wald))
                }
                end => end,
            }
        });
        // An end past an edge of the scenarios the model takes (a Wald end, or a search that
        // stepped over it) is cut at the edge: a radius interval reached 0.00071011 for a worn
        // radius of 0.000711, a value the model refuses.
        let ends = [0, 1].map(|k| self.within_edges(theta, i, [-1.0, 1.0][k], ends[k], warnings));
        for ((end, side), word) in ends.iter().zip(["below", "above"]).zip([-1.0, 1.0]) {
            if let Bounded::Not(reach) = end {
                warnings.push(format!(
                    "`{name}` is not bounded {side} by the data: its sum of squares stays within the 95 % level out to {:.4e}, a factor {:.0} from the estimate, where the search stopped; its interval ends there",
                    (theta[i] + word * reach).exp(),
                    reach.exp()
                ));
            }
        }
        let estimate = Estimate {
            value: self.value(i, theta[i]),
            ci95: [
                self.value(i, (theta[i] - ends[0].reach()).max(lower)),
                self.value(i, (theta[i] + ends[1].reach()).min(upper)),
            ],
            se_ln,
            at_bound: theta[i] == lower || theta[i] == upper || on_edge.contains(&true),
        };
        (name.clone(), estimate)
    }

    /// `end`, on `side` of parameter `i`'s estimate, or the edge of the scenarios the model takes
    /// before it (found by bisection to a part in 1e-12 of the logarithm), with a warning.
    fn within_edges(
        &self,
        theta: &[f64],
        i: usize,
        side: f64,
        end: Bounded,
        warnings: &mut Vec<String>,
    ) -> Bounded {
        let valid = |reach: f64| {
            let mut moved = theta.to_vec();
            moved[i] += side * reach;
            self.residuals(&moved).is_some()
        };
        let reach = end.reach();
        if reach == 0.0 || !reach.is_finite() || valid(reach) {
            return end;
        }
        let (mut inside, mut outside) = (0.0, reach);
        while outside - inside > 1e-12 * outside.max(1.0) {
            let middle = 0.5 * (inside + outside);
            if valid(middle) {
                inside = middle;
            } else {
                outside = middle;
            }
        }
        warnings.push(format!(
            "`{}` is not bounded {} by the data before an edge of the scenarios the model takes \
             (such as a contact radius no smaller than the worn one): its interval ends at the \
             edge, {:.6e}",
            self.parameters[i].0,
            if side < 0.0 { "below" } else { "above" },
            (theta[i] + side * inside).exp()
        ));
        Bounded::At(inside)
    }

    /// The parameters' correlation matrix, by name, and a warning for each pair that trades off.
    fn correlation(
        &self,
        optimum: &Optimum,
    ) -> (BTreeMap<String, BTreeMap<String, f64>>, Vec<String>) {
        let names: Vec<&str> = self.parameters.iter().map(|(n, _)| n.as_str()).collect();
        let correlation = names
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let row = names
                    .iter()
                    .enumerate()
                    .map(|(j, b)| ((*b).to_owned(), optimum.r(i, j)))
                    .collect();
                ((*a).to_owned(), row)
            })
            .collect();
        let mut warnings = Vec::new();
        for i in 0..names.len() {
            for j in i + 1..names.len() {
                let r = optimum.r(i, j);
                if r.abs() >= TRADE_OFF {
                    warnings.push(format!(
                        "`{}` and `{}` trade off (correlation {r:.2}): the data constrain a combination of them; their intervals are wide because each can move with the other, so measure over a wider range of conditions or more quantities, or fix one of them",
                        names[i], names[j]
                    ));
                }
            }
        }
        (correlation, warnings)
    }

    /// The differences simulated minus measured at `theta`, by quantity, with their relative
    /// root mean square.
    fn residuals_by_quantity(&self, outcomes: &[Measured]) -> BTreeMap<String, Residuals> {
        let mut by_quantity: BTreeMap<String, (Vec<f64>, f64)> = BTreeMap::new();
        for (i, observation) in self.observations.iter().enumerate() {
            for quantity in FITTED {
                if let Some(measured) = observation.measured(quantity) {
                    let entry = by_quantity.entry(quantity.to_owned()).or_default();
                    let simulated = simulated(&outcomes[i], quantity);
                    entry.0.push(simulated - measured);
                    // The relative residual the fit minimises, not `(s - m) / m`.
                    entry.1 += relative_difference(simulated, measured).powi(2);
                }
            }
            if let Some(count) = observation.bounce_count {
                let entry = by_quantity.entry("bounce_count".to_owned()).or_default();
                let difference =
                    f64::from(outcomes[i].simulation.outcome.bounce_count) - f64::from(count);
                entry.0.push(difference);
                entry.1 += (difference / f64::from(count.max(1))).powi(2);
            }
        }
        by_quantity
            .into_iter()
            .map(|(quantity, (values, squares))| {
                let rms_relative = (squares / values.len() as f64).sqrt();
                (
                    quantity,
                    Residuals {
                        values,
                        rms_relative,
                    },
                )
            })
            .collect()
    }
}

/// A warning where the fitted quantities' relative residuals differ by [`UNEQUAL_NOISE`] or more:
/// the fit weighs every quantity alike and its intervals take one noise level for all of them,
/// so they hold the truth less often than they say (a probe: `e1` with 1 % noise beside the total
/// bounce time with 10 %, kappa's interval covered 86 % of 300 draws; the eroded mass with 20 %
/// beside bounce times with 1 %, the erosion rate's 77 % of 200).
fn unequal_noise(residuals: &BTreeMap<String, Residuals>, parameters: usize) -> Option<String> {
    let counted: Vec<(&String, f64)> = (residuals.iter())
        .filter(|(quantity, r)| {
            FITTED.contains(&quantity.as_str())
                && r.values.len() >= UNEQUAL_NOISE_VALUES.max(parameters + 1)
        })
        .map(|(quantity, r)| (quantity, r.rms_relative))
        .collect();
    let least = counted.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let most = counted.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    (least.1 > EXACT_FIT_RMS && most.1 >= UNEQUAL_NOISE * least.1).then(|| {
        format!(
            "the measured quantities' relative residuals differ ({} {:.2} %, {} {:.2} %): the \
             fit weighs every quantity alike and its intervals take one noise level for all, so \
             they claim more than the data hold; fit quantities measured with like precision \
             together, or each alone",
            least.0,
            100.0 * least.1,
            most.0,
            100.0 * most.1
        )
    })
}

/// The optimum's linearised statistics, where the report's intervals start.
struct Optimum<'a> {
    theta: &'a [f64],
    /// `(J^T J)^-1`, empty where it is singular.
    covariance: Vec<Vec<f64>>,
    /// The residual variance, `cost / degrees_of_freedom`.
    variance: f64,
    cost: f64,
    degrees_of_freedom: usize,
    /// Student's t at 97.5 % for the degrees of freedom.
    t: f64,
}

impl Optimum<'_> {
    fn entry(&self, i: usize, j: usize) -> f64 {
        self.covariance
            .get(i)
            .and_then(|row| row.get(j))
            .copied()
            .unwrap_or(f64::NAN)
    }

    /// The correlation of parameters `i` and `j`, from the upper triangle only: the inverse is
    /// symmetric up to rounding, the matrix exactly.
    fn r(&self, i: usize, j: usize) -> f64 {
        let (i, j) = (i.min(j), i.max(j));
        if i == j {
            1.0
        } else {
            (self.entry(i, j) / (self.entry(i, i) * self.entry(j, j)).sqrt()).clamp(-1.0, 1.0)
        }
    }
}

/// The share of the Wald half-width below which a profile's end is taken as a refit stuck on a
/// step rather than an end the data set.
const STUCK_END: f64 = 0.1;

/// Where a profile-likelihood interval ends on one side of the estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Bounded {
    /// At this distance (in the logarithm) from the estimate, or at the parameter's bound.
    At(f64),
    /// Not within this distance, where the search stopped.
    Not(f64),
}

impl Bounded {
    fn reach(self) -> f64 {
        match self {
            Self::At(d) | Self::Not(d) => d,
        }
    }
}

/// The profile of one fitted parameter's sum of squares: at each value of the parameter's
/// logarithm, the least sum of squares over the other parameters.
///
/// The 95 % interval is the set of values where the profile stays within
/// `RSS (1 + t^2 / (n - k))`, the inversion of the F test of one parameter (Bates & Watts 1988,
/// section 6.1: the profile t statistic `tau = sqrt((S(c) - RSS) / s^2)` reaches Student's `t`).
/// Where the model is linear in the logarithm this is the Wald interval `ln x -+ t se`; where
/// it curves (the roughening energy's effect on a wear curve is not linear in its logarithm),
/// the profile follows the curve and the interval grows on the side where the data bind less.
struct Profile<'a> {
    problem: &'a Problem<'a>,
    /// The optimum.
    theta: &'a [f64],
    parameter: usize,
    /// The optimum's sum of squares, `RSS`.
    cost: f64,
    degrees_of_freedom: f64,
    /// Student's 0.975 quantile for `n - k` degrees of freedom.
    t: f64,
    /// How each other parameter's optimum moves with this one, to first order (the covariance
    /// column over the variance): the start of each profile point's fit.
    slopes: Vec<f64>,
}

impl Profile<'_> {
    /// The distance to the parameter's bound on `side`, in the logarithm.
    fn room(&self, side: f64) -> f64 {
        let j = self.parameter;
        let [lower, upper] = self.problem.bounds_ln[j];
        if side > 0.0 {
            upper - self.theta[j]
        } else {
            self.theta[j] - lower
        }
    }

    /// The farthest the search looks from the estimate, in the logarithm: a factor `e^10`.
    const MAX_REACH: f64 = 10.0;

    /// The profile t statistic at `distance` from the estimate on `side` (-1 or 1): infinite
    /// where the scenario cannot be simulated (the parameter cannot go there).
    fn tau(&self, side: f64, distance: f64) -> f64 {
        let j = self.parameter;
        let c = self.theta[j] + side * distance;
        let guess: Vec<f64> = self
            .theta
            .iter()
            .zip(&self.slopes)
            .enumerate()
            .map(|(k, (t, slope))| {
                if k == j {
                    c
                } else if slope.is_finite() {
                    t + slope * (c - self.theta[j])
                } else {
                    *t
                }
            })
            .collect();
        let mut start = self.problem.within_bounds(guess);
        start[j] = c;
        let residuals = match self.problem.residuals(&start) {
            Some(r) => r,
            None => {
                start = self.theta.to_vec();
                start[j] = c;
                match self.problem.residuals(&start) {
                    Some(r) => r,
                    None => return f64::INFINITY,
                }
            }
        };
        let free: Vec<usize> = (0..self.theta.len()).filter(|&k| k != j).collect();
        let cost = if free.is_empty() {
            sum_of_squares(&residuals)
        } else {
            // The profile t needs the sum of squares to a small part of `RSS t^2 / (n - k)`.
            match self
                .problem
                .minimise(start, residuals, &free, 1e-9, |_, _| Ok(()))
            {
                Ok(Some(minimum)) => minimum.cost,
                _ => return f64::INFINITY,
            }
        };
        ((cost - self.cost).max(0.0) * self.degrees_of_freedom / self.cost).sqrt()
    }

    /// Where the interval ends on `side` (-1 below, 1 above), as a distance from the estimate in
    /// the logarithm, starting the search at `wald` (the Wald half-width): widened until the
    /// profile t reaches `t`, then narrowed by a safeguarded false position to within 0.2 % of
    /// `wald`, the end on the far side of the crossing (the wider interval).
    fn end(&self, side: f64, wald: f64) -> Bounded {
        let room = self.room(side);
        if room <= 0.0 {
            return Bounded::At(0.0);
        }
        if !(self.cost > 0.0 && self.cost.is_finite() && wald > 0.0 && wald.is_finite()) {
            // Data fitted exactly, or no slope: the profile has nothing to measure against.
            return Bounded::At(if wald.is_finite() {
                wald.min(room)
            } else {
                0.0
            });
        }
        let mut distance = wald.min(room).min(Self::MAX_REACH);
        let tolerance = 2e-3 * distance;
        // (distance, tau - t) inside (below t) and outside (at or beyond t).
        let mut inside = (0.0, -self.t);
        let outside = loop {
            let excess = self.tau(side, distance) - self.t;
            if excess >= 0.0 {
                break (distance, excess);
            }
            inside = (distance, excess);
            if distance >= room {
                return Bounded::At(room);
            }
            if distance >= Self::MAX_REACH {
                return Bounded::Not(distance);
            }
            // The profile t is nearly linear in the distance: aim past the crossing.
            let tau = excess + self.t;
            let aim = if tau > 0.0 {
                1.2 * distance * self.t / tau
            } else {
                4.0 * distance
            };
            distance = aim
                .clamp(1.5 * distance, 4.0 * distance)
                .min(room)
                .min(Self::MAX_REACH);
        };
        let (mut a, mut fa) = inside;
        let (mut b, mut fb) = outside;
        for _ in 0..60 {
            if b - a <= tolerance {
                break;
            }
            let secant = if fb.is_finite() {
                a - fa * (b - a) / (fb - fa)
            } else {
                0.5 * (a + b)
            };
            let m = secant.clamp(a + 0.1 * (b - a), b - 0.1 * (b - a));
            let fm = self.tau(side, m) - self.t;
            if fm >= 0.0 {
                (b, fb) = (m, fm);
            } else {
                (a, fa) = (m, fm);
            }
        }
        Bounded::At(b)
    }
}
/// The parameters `fit` names: dotted paths to positive numbers of the scenario (or kappa,
/// which the model derives when absent), each once.
fn check_fit(
    spec: &CalibrationSpec,
    base: &Value,
    root: &Pointer,
    errors: &mut Vec<FieldError>,
) -> Vec<(String, Vec<String>)> {
    let mut parameters: Vec<(String, Vec<String>)> = Vec::new();
    if spec.fit.is_empty() || spec.fit.len() > MAX_PARAMETERS {
        errors.push(FieldError {
            pointer: "/fit".into(),
            detail: format!("must name 1 to {MAX_PARAMETERS} scenario parameters"),
        });
    }
    for (i, name) in spec.fit.iter().enumerate() {
        if past_listing(errors) {
            break;
        }
        let pointer = root.child("fit").child(i).to_string();
        let path: Vec<String> = name.split('.').map(str::to_owned).collect();
        if path.len() < 2 || path.iter().any(String::is_empty) {
            errors.push(FieldError {
                pointer,
                detail: format!(
                    "`{name}` is not a dotted path in the scenario, e.g. `material.kappa`"
                ),
            });
            continue;
        }
        match lookup(base, &path) {
            // A count (`losses.max_bounces`) is stored as an integer: a fit's steps would move
            // it off the integers, and the scenario refuses every such value.
            Some(Value::Number(n)) if !n.is_f64() => {
                errors.push(FieldError {
                    pointer,
                    detail: format!(
                        "`{name}` is a whole number (a count) of the scenario, which a fit cannot vary"
                    ),
                });
                continue;
            }
            Some(Value::Number(n)) if n.as_f64().is_some_and(|x| x > 0.0) => {}
            // An optional number the model derives when absent (kappa).
            None | Some(Value::Null) if name == "material.kappa" => {}
            _ => {
                errors.push(FieldError {
                    pointer,
                    detail: format!(
                        "`{name}` is not a positive number of the scenario that a fit can vary"
                    ),
                });
                continue;
            }
        }
        if parameters.iter().any(|(n, _)| n == name) {
            errors.push(FieldError {
                pointer,
                detail: format!("`{name}` is named twice"),
            });
            continue;
        }
        parameters.push((name.clone(), path));
    }
    parameters
}

/// Every measured value of every observation as a term `(observation, quantity)` of the
/// objective; each observation measures something, at a velocity the scenario allows.
fn check_observations(
    spec: &CalibrationSpec,
    root: &Pointer,
    errors: &mut Vec<FieldError>,
) -> Vec<(usize, &'static str)> {
    if spec.observations.is_empty() || spec.observations.len() > MAX_OBSERVATIONS {
        errors.push(FieldError {
            pointer: "/observations".into(),
            detail: format!("must hold 1 to {MAX_OBSERVATIONS} observations"),
        });
    }
    let mut terms = Vec::new();
    for (i, observation) in spec.observations.iter().enumerate() {
        if past_listing(errors) {
            break;
        }
        let at = root.child("observations").child(i);
        let mut measured = observation.bounce_count.is_some();
        if observation.operation.is_some_and(|j| j > MAX_OPERATION) {
            errors.push(FieldError {
                pointer: at.child("operation").to_string(),
                detail: format!("must be from 0 to {MAX_OPERATION}"),
            });
        }
        if let Some(v) = observation.impact_velocity_m_s {
            // The scenario's rule for an impact velocity, at the observation's place.
            let mut with_velocity = spec.scenario.clone();
            with_velocity.mechanism.impact_velocity_m_s = Some(v);
            if let Err(invalid) = Scenario::new(with_velocity, root) {
                let velocity = "/mechanism/impact_velocity_m_s";
                errors.extend(
                    invalid
                        .errors()
                        .iter()
                        .filter(|e| e.pointer == velocity)
                        .map(|e| FieldError {
                            pointer: at.child("impact_velocity_m_s").to_string(),
                            detail: e.detail.clone(),
                        }),
                );
            }
        }
        for quantity in FITTED {
            if let Some(value) = observation.measured(quantity) {
                measured = true;
                // Within what a simulated value can be compared with.
                let [least, most] = measured_range(quantity);
                if observation.impact_velocity_m_s == Some(0.0) && BOUNCES.contains(&quantity) {
                    // The fit had nothing to move and was told to start nearer (a probe).
                    errors.push(FieldError {
                        pointer: at.child(quantity).to_string(),
                        detail: "is 0 at an impact velocity of 0, whatever the parameters (the \
                                 contact does not bounce): a measured value cannot be fitted; \
                                 give the velocity it was measured at"
                            .to_owned(),
                    });
                } else if (least..=most).contains(&value) {
                    terms.push((i, quantity));
                } else {
                    errors.push(FieldError {
                        pointer: at.child(quantity).to_string(),
                        detail: format!(
                            "must be a positive number from {least:e} to {most:e}, got {}",
                            crate::error::shown(value)
                        ),
                    });
                }
            }
        }
        if !measured {
            errors.push(FieldError {
                pointer: at.to_string(),
                detail: "measures nothing: give at least one of first_bounce_s, second_bounce_s, total_bounce_s, bounce_count, e1, peak_force_n, arc_energy_j, eroded_mass_kg".into(),
            });
        }
    }
    terms
}

/// Each bound names a fitted parameter and is `[lower, upper]` with `0 < lower < upper`,
/// reaching into the magnitudes a scenario keeps.
fn check_bounds(
    spec: &CalibrationSpec,
    parameters: &[(String, Vec<String>)],
    root: &Pointer,
    errors: &mut Vec<FieldError>,
) {
    for (name, &[lower, upper]) in &spec.bounds {
        if past_listing(errors) {
            break;
        }
        let pointer = root.child("bounds").child(name.as_str()).to_string();
        if !parameters.iter().any(|(n, _)| n == name) {
            errors.push(FieldError {
                pointer,
                detail: format!("`{name}` is not a parameter in `fit`"),
            });
        } else if !(lower > 0.0 && lower < upper && upper.is_finite()) {
            errors.push(FieldError {
                pointer,
                detail: format!(
                    "must be [lower, upper] with 0 < lower < upper, got [{lower}, {upper}]"
                ),
            });
        } else if upper < MIN_MAGNITUDE || lower > MAX_MAGNITUDE {
            // No scenario takes a value there: the fit could not start (it read as the start's
            // fault, found from outside).
            errors.push(FieldError {
                pointer,
                detail: format!(
                    "[{lower:e}, {upper:e}] lies outside the 1e-30 to 1e30 a scenario's numbers \
                     keep"
                ),
            });
        }
    }
}

/// The value at a dotted path of a scenario's JSON, if there is one.
fn lookup<'a>(scenario: &'a Value, path: &[String]) -> Option<&'a Value> {
    path.iter().try_fold(scenario, |at, key| at.get(key))
}

/// An observation as simulated: the operation, and the mass eroded up to it.
struct Measured {
    simulation: Simulation,
    eroded_mass_kg: f64,
}

/// The surface after `energy_j` of arc energy: new while no arc has burnt (as the engine has it).
fn surface(law: &WearLaw, reference: &KappaLaw, energy_j: f64) -> (f64, f64) {
    let (radius_m, pressure_pa) = (
        reference.reference_radius_m,
        reference.reference_pressure_pa,
    );
    if energy_j > 0.0 {
        (
            law.radius_m(radius_m, energy_j),
            law.pressure_pa(pressure_pa, energy_j),
        )
    } else {
        (radius_m, pressure_pa)
    }
}

fn simulated(measured: &Measured, quantity: &str) -> f64 {
    let simulation = &measured.simulation;
    let outcome = &simulation.outcome;
    match quantity {
        "eroded_mass_kg" => measured.eroded_mass_kg,
        "first_bounce_s" => outcome.first_bounce_s,
        // No second bounce lasts no time.
        "second_bounce_s" => simulation.bounces.get(1).map_or(0.0, |b| b.duration_s),
        "total_bounce_s" => outcome.total_bounce_s,
        "e1" => outcome.e1,
        "peak_force_n" => outcome.peak_force_n,
        "arc_energy_j" => outcome.arc_energy_j,
        _ => unreachable!("only fitted quantities"),
    }
}

impl Problem<'_> {
    /// The paper's readings of e1 and e2 off the measured bounce times, each with its bias under
    /// the model at `theta`, whose simulations are `outcomes`.
    fn readings(&self, theta: &[f64], outcomes: Vec<Measured>) -> BTreeMap<String, Reading> {
        let operations = self.operations(theta).expect("the optimum simulates");
        let mut readings = BTreeMap::new();
        // e1 = u1 / u_i with u1 from T1 through eq. 4, against the model's own v1 / u_i.
        let e1 = |i: usize, op: &Operation, simulation: &Simulation| {
            let measured = self.observations[i].first_bounce_s?;
            let first = simulation.bounces.first()?;
            let reading = e1_from_first_bounce(op, measured)?;
            let modelled = e1_from_first_bounce(op, first.duration_s)?
                - first.separation_velocity_m_s / op.impact_velocity_m_s();
            Some((reading, modelled))
        };
        // e2 = T2 / T1, against the model's own v2 / v1.
        let e2 = |i: usize, _: &Operation, simulation: &Simulation| {
            let observation = &self.observations[i];
            let reading =
                e_from_bounce_times(observation.first_bounce_s?, observation.second_bounce_s?);
            let [first, second] = [simulation.bounces.first()?, simulation.bounces.get(1)?];
            let modelled = e_from_bounce_times(first.duration_s, second.duration_s)
                - second.separation_velocity_m_s / first.separation_velocity_m_s;
            Some((reading, modelled))
        };
        let simulations: Vec<Simulation> = outcomes
            .into_iter()
            .map(|measured| measured.simulation)
            .collect();
        type Read<'a> = &'a dyn Fn(usize, &Operation, &Simulation) -> Option<(f64, f64)>;
        for (name, read) in [("e1", &e1 as Read), ("e2", &e2 as Read)] {
            let (observations, pairs): (Vec<usize>, Vec<(f64, f64)>) = (0..operations.len())
                .filter_map(|i| Some((i, read(i, &operations[i], &simulations[i])?)))
                .unzip();
            if observations.is_empty() {
                continue;
            }
            let (values, biases): (Vec<f64>, Vec<f64>) = pairs.into_iter().unzip();
            let bias = biases.iter().sum::<f64>() / biases.len() as f64;
            let corrected = values.iter().zip(&biases).map(|(v, b)| v - b).collect();
            readings.insert(
                name.to_owned(),
                Reading {
                    observations,
                    values,
                    biases,
                    bias,
                    corrected,
                },
            );
        }
        readings
    }
}

fn sum_of_squares(values: &[f64]) -> f64 {
    values.iter().map(|v| v * v).sum()
}

/// A derivative from a residual's forward and backward differences: their mean where they agree
/// to within half the larger (on a smooth residual they differ by the step times the curvature,
/// orders of magnitude less), else the smaller, the side without a step.
fn smooth_side(forward: f64, backward: f64) -> f64 {
    if (forward - backward).abs() <= 0.5 * forward.abs().max(backward.abs()) {
        0.5 * (forward + backward)
    } else if forward.abs() <= backward.abs() {
        forward
    } else {
        backward
    }
}

/// `J^T J` and `J^T r` from the columns of `J`.
fn normal_equations(columns: &[Vec<f64>], residuals: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let jtj = columns
        .iter()
        .map(|a| columns.iter().map(|b| dot(a, b)).collect())
        .collect();
    let jtr = columns.iter().map(|a| dot(a, residuals)).collect();
    (jtj, jtr)
}

#[cfg(test)]
mod tests {
    use super::study::{
        CASES, bounce_times, coverage, coverage_by_block, one_velocity_wear_curve, together,
        wear_curve,
    };
    use super::*;

    #[test]
    fn an_interval_end_next_to_the_estimate_is_the_wald_one() {
        // Of seeds 0 to 299, 15 had the roughening energy's profile stop next to the estimate
        // below it (its refits held on a step of the sum of squares): an end 0.01-0.1 % from the
        // estimate, against a Wald half-width of 3 %.
        for seed in [38, 57] {
            let fit = calibrate(&one_velocity_wear_curve(seed)).unwrap();
            for (name, e) in &fit.estimates {
                let wald = 0.1 * student_t_975(78) * e.se_ln;
                let [lo, hi] = e.ci95.map(|x| (x / e.value).ln().abs());
                assert!(lo >= wald && hi >= wald, "seed {seed}: {name} {e:?}");
            }
            assert!(
                fit.warnings
                    .iter()
                    .any(|w| w.contains("could not be followed below")),
                "{:?}",
                fit.warnings
            );
        }
    }
    use crate::stats::test_util::SplitMix;
    use approx::assert_relative_eq;

    /// The noise draw of issue 29's case the test keeps.
    const ISSUE_29_SEED: u64 = 42;

    /// Measurements of the paper's rig at five impact velocities with kappa and the impact
    /// energy loss set, each quantity scaled by `1 + noise * u`, `u` a fixed pattern in [-1, 1].
    fn synthetic(kappa: f64, loss_j: f64, noise: f64) -> CalibrationSpec {
        let mut truth = ScenarioSpec::default();
        truth.material.kappa = Some(kappa);
        truth.losses.impact_energy_loss_j = loss_j;
        let pattern = [0.9, -0.7, 0.3, -0.1, 0.6, -0.8, 0.2, -0.4, 0.5, -0.6];
        let observations = [0.15, 0.25, 0.35, 0.45, 0.6]
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let mut spec = truth.clone();
                spec.mechanism.impact_velocity_m_s = Some(v);
                let scenario = Scenario::new(spec, &Pointer::root()).unwrap();
                let simulation = simulate(&scenario, Fidelity::Exact);
                let outcome = simulation.outcome;
                let jitter = |k: usize| 1.0 + noise * pattern[(2 * i + k) % pattern.len()];
                Observation {
                    impact_velocity_m_s: Some(v),
                    first_bounce_s: Some(outcome.first_bounce_s * jitter(0)),
                    second_bounce_s: simulation.bounces.get(1).map(|b| b.duration_s * jitter(3)),
                    e1: Some(outcome.e1 * jitter(1)),
                    total_bounce_s: Some(outcome.total_bounce_s * jitter(2)),
                    bounce_count: Some(outcome.bounce_count),
                    ..Observation::default()
                }
            })
            .collect();
        CalibrationSpec {
            scenario: ScenarioSpec::default(),
            fit: vec!["material.kappa".into()],
            observations,
            bounds: BTreeMap::new(),
        }
    }

    /// The exact outcome of `truth` at each impact velocity.
    fn outcomes(truth: &ScenarioSpec, velocities: &[f64]) -> Vec<(f64, crate::operation::Outcome)> {
        velocities
            .iter()
            .map(|&v| {
                let mut spec = truth.clone();
                spec.mechanism.impact_velocity_m_s = Some(v);
                let scenario = Scenario::new(spec, &Pointer::root()).unwrap();
                (v, simulate(&scenario, Fidelity::Exact).outcome)
            })
            .collect()
    }

    /// The standard error of the first parameter's logarithm at `theta`, from the Jacobian
    /// `columns` there.
    fn se_ln_at(problem: &Problem, theta: &[f64], columns: &[Vec<f64>]) -> f64 {
        let residuals = problem.residuals(theta).unwrap();
        let (jtj, _) = normal_equations(columns, &residuals);
        let variance = sum_of_squares(&residuals) / (residuals.len() - theta.len()) as f64;
        (variance * invert(jtj).unwrap()[0][0]).sqrt()
    }

    /// The plain central difference the fit used before (step 1e-5 in the logarithm), at
    /// `theta`.
    fn central_difference(problem: &Problem, theta: &[f64]) -> Vec<Vec<f64>> {
        (0..theta.len())
            .map(|k| {
                let mut up = theta.to_vec();
                let mut down = theta.to_vec();
                up[k] += 1e-5;
                down[k] -= 1e-5;
                let (up, down) = (
                    problem.residuals(&up).unwrap(),
                    problem.residuals(&down).unwrap(),
                );
                up.iter().zip(&down).map(|(u, d)| (u - d) / 2e-5).collect()
            })
            .collect()
    }

    /// Issue 29: with the first and total bounce times together, a central difference across a
    /// step of the total bounce time (a bounce appearing) gave an interval 25 times too narrow,
    /// 17 standard errors off the truth. The step-aware Jacobian gives an interval around 0.33
    /// with a standard error between the single times' ones.
    #[test]
    fn first_and_total_bounce_times_together_give_an_honest_interval() {
        let spec = together(ISSUE_29_SEED);
        let fit = calibrate(&spec).unwrap();
        let kappa = &fit.estimates["material.kappa"];
        let single = |keep: &str| {
            let mut one = spec.clone();
            for o in &mut one.observations {
                if keep == "first_bounce_s" {
                    o.total_bounce_s = None;
                } else {
                    o.first_bounce_s = None;
                }
            }
            calibrate(&one).unwrap().estimates["material.kappa"].se_ln
        };
        let (first, total) = (single("first_bounce_s"), single("total_bounce_s"));
        eprintln!("together {kappa:?}; first alone se_ln {first:.3e}, total alone {total:.3e}");
        assert!(kappa.ci95[0] < 0.33 && 0.33 < kappa.ci95[1], "{kappa:?}");
        // Together, at least as precise as the better single time, and not by more than the
        // two independent halves' combination allows (with room for a different optimum).
        let combined = 1.0 / (first.powi(-2) + total.powi(-2)).sqrt();
        assert!(
            kappa.se_ln > 0.5 * combined && kappa.se_ln < 1.5 * first.min(total),
            "{kappa:?}: first alone {first}, total alone {total}"
        );
        // Near the optimum lie steps of the total bounce time. Where the central difference's
        // two sides straddle one it collapses the standard error; the step-aware Jacobian there
        // gives about the optimum's.
        let problem = Problem::new(&spec).unwrap();
        let optimum = kappa.value.ln();
        let straddling = (0..2000)
            .map(|j| [optimum + (f64::from(j) - 1000.0) * 1.5e-5])
            .find(|theta| {
                se_ln_at(&problem, theta, &central_difference(&problem, theta)) < 0.1 * kappa.se_ln
            })
            .expect("a step of the total bounce time within 0.015 of the optimum");
        let residuals = problem.residuals(&straddling).unwrap();
        let aware = se_ln_at(
            &problem,
            &straddling,
            &problem.jacobian(&straddling, &residuals, &[0]).unwrap(),
        );
        assert!(
            (0.5 * kappa.se_ln..2.0 * kappa.se_ln).contains(&aware),
            "{aware} at {straddling:?} against {kappa:?}"
        );
    }

    /// The profile t statistic of `fit`'s parameter `name` at `value`, from its definition:
    /// the sum of squares minimised over the other parameters, against the optimum's.
    fn profile_t(spec: &CalibrationSpec, fit: &Calibration, name: &str, value: f64) -> f64 {
        let problem = Problem::new(spec).unwrap();
        let theta: Vec<f64> = spec
            .fit
            .iter()
            .map(|p| fit.estimates[p].value.ln())
            .collect();
        let cost = sum_of_squares(&problem.residuals(&theta).unwrap());
        let parameter = spec.fit.iter().position(|p| p == name).unwrap();
        let degrees_of_freedom = (problem.terms.len() - theta.len()) as f64;
        let profile = Profile {
            problem: &problem,
            theta: &theta,
            parameter,
            cost,
            degrees_of_freedom,
            t: student_t_975(degrees_of_freedom as u64),
            // Where the other parameters' fits start changes nothing but their iterations.
            slopes: vec![0.0; theta.len()],
        };
        let distance = value.ln() - theta[parameter];
        profile.tau(distance.signum(), distance.abs())
    }

    /// Each end of a 95 % interval sits where the profile t statistic reaches Student's t:
    /// just past it at the end, below it a little inside. Checked for one parameter (the
    /// profile is the sum of squares itself) and for two (the other one refitted at each point).
    #[test]
    fn the_interval_ends_where_the_profile_t_reaches_students_t() {
        for (spec, dof) in [(together(ISSUE_29_SEED), 79), (wear_curve(1), 38)] {
            let fit = calibrate(&spec).unwrap();
            let t = student_t_975(dof);
            for (name, estimate) in &fit.estimates {
                let ln = estimate.value.ln();
                for end in estimate.ci95 {
                    let at = profile_t(&spec, &fit, name, end);
                    let inside = profile_t(&spec, &fit, name, (ln + 0.98 * (end.ln() - ln)).exp());
                    eprintln!("{name}: end {end}: tau {at}, 2 % inside {inside}, t {t}");
                    assert!(
                        at >= t && at <= 1.01 * t,
                        "{name} at {end}: {at} against {t}"
                    );
                    assert!(inside < t, "{name} inside {end}: {inside} against {t}");
                }
            }
        }
    }

    /// A fit that may be cancelled but is not gives [`calibrate`]'s answer to the bit; one
    /// cancelled before or while it runs ends with [`Cancelled`], without a panic at whatever
    /// point the flag found it (the report at the optimum simulates whatever the flag says).
    #[test]
    fn a_fit_ends_with_cancelled_once_its_flag_is_set() {
        let spec = wear_curve(2);
        let flag = AtomicBool::new(false);
        let fit = calibrate_until(&spec, &flag).unwrap().unwrap();
        let alone = calibrate(&spec).unwrap();
        assert_eq!(
            serde_json::to_string(&fit).unwrap(),
            serde_json::to_string(&alone).unwrap()
        );
        flag.store(true, Ordering::Relaxed);
        assert_eq!(calibrate_until(&spec, &flag).unwrap_err(), Cancelled);
        // Set from another thread at points spread over the fit's own time: whatever it was
        // doing then, it ends with Cancelled (or, had it already ended, with its answer).
        let started = std::time::Instant::now();
        calibrate(&spec).unwrap();
        let whole = started.elapsed();
        for eighths in 0..8 {
            let flag = AtomicBool::new(false);
            let ended = std::thread::scope(|scope| {
                scope.spawn(|| {
                    std::thread::sleep(whole * eighths / 8);
                    flag.store(true, Ordering::Relaxed);
                });
                calibrate_until(&spec, &flag)
            });
            match ended {
                Err(Cancelled) => {}
                Ok(fit) => assert_eq!(
                    serde_json::to_string(&fit.unwrap()).unwrap(),
                    serde_json::to_string(&alone).unwrap()
                ),
            }
        }
    }

    /// Where the model is nearly linear in a parameter's logarithm, the profile interval is the
    /// Wald interval `ln x -+ t se` to within a few per cent of its half-width.
    #[test]
    fn a_nearly_linear_profile_gives_the_wald_interval() {
        let fit = calibrate(&wear_curve(1)).unwrap();
        let t = student_t_975(38);
        for (name, estimate) in &fit.estimates {
            let half = t * estimate.se_ln;
            let ln = estimate.value.ln();
            let ends = [ln - estimate.ci95[0].ln(), estimate.ci95[1].ln() - ln];
            eprintln!("{name}: profile half-widths {ends:?}, Wald {half}");
            for end in ends {
                assert_relative_eq!(end, half, max_relative = 0.05);
            }
        }
    }

    /// A parameter the data bound on one side only: the roughening energy from new contacts and
    /// contacts two operations into their test, whose surfaces have barely worn. However large it
    /// is the fit stays good, so its interval runs to where the search stops, and a warning says
    /// so, naming it.
    #[test]
    fn a_side_the_data_do_not_bound_is_warned_of() {
        let mut spec = wear_curve(3);
        let places: Vec<(u64, f64)> = (0..20)
            .map(|i| (if i < 10 { 0 } else { 2 }, 0.15 + 0.02 * (i % 10) as f64))
            .collect();
        let mut truth = spec.scenario.clone();
        truth.material.kappa = Some(0.33);
        truth.material.roughening_energy_j = 500.0;
        spec.observations = bounce_times(&truth, &places, 0.02, &mut SplitMix(3));
        let fit = calibrate(&spec).unwrap();
        let energy = &fit.estimates["material.roughening_energy_j"];
        eprintln!("{energy:?}; {:?}", fit.warnings);
        assert_relative_eq!(
            energy.ci95[1],
            energy.value * Profile::MAX_REACH.exp(),
            max_relative = 1e-12
        );
        assert!(
            fit.warnings
                .iter()
                .any(|w| w.contains("`material.roughening_energy_j` is not bounded above")),
            "{:?}",
            fit.warnings
        );
    }

    /// Quantities measured with different precision are warned of, naming both (an outside
    /// probe: `e1` with 1 % noise beside the total bounce time with 10 %, kappa's interval
    /// covered 86 % of 300 draws); alike, they are not.
    #[test]
    fn quantities_of_unlike_noise_are_warned_of() {
        let mut truth = ScenarioSpec::default();
        truth.material.kappa = Some(0.33);
        let places: Vec<(u64, f64)> = (0..10).map(|i| (0, 0.15 + 0.05 * f64::from(i))).collect();
        let exact = study::bounce_times(&truth, &places, 0.0, &mut SplitMix(1));
        for (first, total, warned) in [(0.01, 0.10, true), (0.02, 0.02, false)] {
            for seed in 0..5 {
                let mut rng = SplitMix(seed);
                let observations = (exact.iter())
                    .map(|o| Observation {
                        first_bounce_s: o.first_bounce_s.map(|x| x * (1.0 + first * rng.normal())),
                        total_bounce_s: o.total_bounce_s.map(|x| x * (1.0 + total * rng.normal())),
                        ..*o
                    })
                    .collect();
                let fit = calibrate(&CalibrationSpec {
                    scenario: ScenarioSpec::default(),
                    fit: vec!["material.kappa".into()],
                    observations,
                    bounds: BTreeMap::new(),
                })
                .unwrap();
                let warning = fit.warnings.iter().find(|w| w.contains("differ"));
                assert_eq!(warning.is_some(), warned, "{seed}: {:?}", fit.warnings);
                if let Some(warning) = warning {
                    assert!(
                        warning.contains("first_bounce_s") && warning.contains("total_bounce_s"),
                        "{warning}"
                    );
                }
            }
        }
    }

    /// The 95 % intervals hold the truth about 95 % of the time over 40 noise draws (a band
    /// for 40 draws: 0.85 to 1) for kappa from the first and total bounce times together, and
    /// for kappa and the roughening energy from a wear curve, as does the exact interval of the
    /// linearised model on the same draws. Measured: 0.975; 0.975 and 0.95. The 1000-draw
    /// version is `the_intervals_cover_the_truth_95_percent_of_the_time`.
    #[test]
    fn the_intervals_cover_the_truth() {
        for case in &CASES {
            let shares = coverage(case, 1000..1040);
            eprintln!("{} over 40 draws: {shares:?}", case.name);
            for c in shares.profile.into_iter().chain(shares.linear_reference) {
                assert!((0.85..=1.0).contains(&c), "{c}");
            }
        }
    }

    /// As `the_intervals_cover_the_truth` over 1000 noise draws, in the band 0.93 to 0.97 (the
    /// binomial standard deviation of a true 0.95 over 1000 draws is 0.007), and each disjoint
    /// block of 200 within three of its standard deviations (0.015): 0.90 to 0.99; the exact
    /// interval of the linearised model on the same draws covers 0.93 to 0.97 over the 1000 and
    /// within a block differs from the profile intervals' share by at most 0.03 (it shares the
    /// block's luck). Measured over the 1000: 0.952; 0.951 and 0.943 (the reference 0.958; 0.948
    /// and 0.945); the roughening energy's blocks 0.915, 0.95, 0.955, 0.95 and 0.945 against
    /// the reference's 0.92, 0.95, 0.96, 0.95 and 0.945: its first block's draws are unlucky for
    /// any exact interval. About 175 s in release:
    /// `cargo test --release -p bouncewear-model --lib calibration -- --ignored --nocapture`.
    #[test]
    #[ignore = "1000 fits of each case: run with --release -- --ignored"]
    fn the_intervals_cover_the_truth_95_percent_of_the_time() {
        for case in &CASES {
            let study = coverage_by_block(case, 1000, 200, 5);
            for (seeds, block) in &study.blocks {
                eprintln!("{}, seeds {seeds:?}: {block:?}", case.name);
                for (c, r) in block.profile.iter().zip(&block.linear_reference) {
                    assert!((0.90..=0.99).contains(c), "{c}");
                    assert!((c - r).abs() <= 0.03, "{c} against the reference's {r}");
                }
            }
            eprintln!("{}, seeds 1000..2000: {:?}", case.name, study.all);
            for c in study.all.profile.iter().chain(&study.all.linear_reference) {
                assert!((0.93..=0.97).contains(c), "{c}");
            }
        }
    }

    /// The correlation matrix is symmetric with a unit diagonal; kappa and the pre-arc's
    /// softening energy over a narrow band of impact velocities (0.215 to 0.225 m/s at 48 V /
    /// 15 A) soften the first impact the same way, and are warned of as trading off (and their
    /// profiles, each refitting the other, as not bounded on one side).
    #[test]
    fn a_pair_that_trades_off_is_warned_of() {
        let fit = calibrate(&wear_curve(1)).unwrap();
        assert!(fit.warnings.is_empty(), "{:?}", fit.warnings);
        let json = serde_json::to_value(&fit).unwrap();
        assert!(json.get("warnings").is_none(), "{json}");
        for (a, row) in &fit.correlation {
            assert_eq!(row.len(), 2);
            for (b, r) in row {
                assert_eq!(*r, fit.correlation[b][a]);
                if a == b {
                    assert_eq!(*r, 1.0);
                } else {
                    assert!(r.abs() < 0.95, "{:?}", fit.correlation);
                }
            }
        }
        let mut truth = ScenarioSpec::default();
        truth.circuit.supply_voltage_v = 48.0;
        truth.circuit.current_a = 15.0;
        truth.material.kappa = Some(0.33);
        let places: Vec<(u64, f64)> = (0..11).map(|i| (0, 0.215 + 0.001 * f64::from(i))).collect();
        let spec = CalibrationSpec {
            scenario: truth.clone(),
            fit: vec![
                "material.kappa".into(),
                "material.softening_energy_j".into(),
            ],
            observations: bounce_times(&truth, &places, 0.02, &mut SplitMix(7)),
            bounds: BTreeMap::new(),
        };
        let fit = calibrate(&spec).unwrap();
        eprintln!(
            "{:?} {:?} {:?}",
            fit.estimates, fit.correlation, fit.warnings
        );
        let r = fit.correlation["material.kappa"]["material.softening_energy_j"];
        assert_eq!(
            r,
            fit.correlation["material.softening_energy_j"]["material.kappa"]
        );
        assert!(r.abs() >= 0.95, "{r}");
        let trade_off = format!(
            "`material.kappa` and `material.softening_energy_j` trade off (correlation {r:.2})"
        );
        assert_eq!(
            fit.warnings
                .iter()
                .filter(|w| w.starts_with(&trade_off))
                .count(),
            1,
            "{:?}",
            fit.warnings
        );
        // Each moving with the other, the data bound neither far from the estimate: the other
        // warnings say which sides run to where the search stopped, which side's refits stopped
        // on a step next to the estimate (its end the Wald one), and that the search along the
        // flat valley took all its iterations.
        for warning in fit.warnings.iter().filter(|w| !w.starts_with(&trade_off)) {
            assert!(
                warning.contains("is not bounded")
                    || warning.contains("could not be followed")
                    || warning.starts_with("the fit took all"),
                "{warning}"
            );
        }
    }

    #[test]
    fn kappa_is_recovered_exactly_from_exact_data() {
        let fit = calibrate(&synthetic(0.3, 1e-6, 0.0)).unwrap();
        let kappa = &fit.estimates["material.kappa"];
        assert!((kappa.value / 0.3 - 1.0).abs() < 1e-6, "{kappa:?}");
        // Its interval is as narrow as the rounding, which the fit says (a probe found exact
        // data given zero-width intervals without a word).
        assert!(
            fit.warnings
                .iter()
                .any(|w| w.contains("no estimate of their noise")),
            "{:?}",
            fit.warnings
        );
        assert_eq!(fit.scenario.material.kappa, Some(kappa.value));
        assert!(fit.residuals["e1"].rms_relative < 1e-6);
    }

    /// At 1 % and 5 % noise the estimate moves, its interval still holds the truth, and it widens
    /// with the noise.
    #[test]
    fn noisy_data_give_an_interval_around_the_truth() {
        let widths: Vec<f64> = [0.01, 0.05]
            .into_iter()
            .map(|noise| {
                let fit = calibrate(&synthetic(0.3, 1e-6, noise)).unwrap();
                let kappa = &fit.estimates["material.kappa"];
                assert!(
                    kappa.ci95[0] < 0.3 && 0.3 < kappa.ci95[1],
                    "noise {noise}: {kappa:?}"
                );
                assert!(fit.residual_sd > 0.2 * noise, "{fit:?}");
                kappa.ci95[1] / kappa.ci95[0] - 1.0
            })
            .collect();
        assert!(widths[1] > 3.0 * widths[0], "{widths:?}");
    }

    /// Kappa and the extra energy loss per impact together: the first bounce and e1 fix kappa,
    /// the total bounce time the loss.
    #[test]
    fn two_parameters_are_recovered_within_their_intervals() {
        let mut spec = synthetic(0.35, 3e-6, 0.01);
        spec.fit.push("losses.impact_energy_loss_j".into());
        let fit = calibrate(&spec).unwrap();
        for (name, truth) in [
            ("material.kappa", 0.35),
            ("losses.impact_energy_loss_j", 3e-6),
        ] {
            let estimate = &fit.estimates[name];
            assert!(
                estimate.ci95[0] < truth && truth < estimate.ci95[1],
                "{name}: {estimate:?}"
            );
        }
    }

    /// The paper's readings of e off exact bounce times are biased (constant-force flight, no
    /// loss per impact); corrected by the fitted model, they give the model's own coefficients.
    #[test]
    fn the_papers_readings_of_e_are_corrected_by_their_bias() {
        let spec = synthetic(0.3, 1e-6, 0.0);
        let fit = calibrate(&spec).unwrap();
        let readings = &fit.restitution_from_bounce_times;
        assert_eq!(readings["e1"].observations, [0, 1, 2, 3, 4]);
        assert!(readings["e1"].bias.abs() > 1e-3, "{readings:?}");
        assert!(readings["e2"].bias.abs() > 1e-3, "{readings:?}");
        let scenario = Scenario::new(fit.scenario.clone(), &Pointer::root()).unwrap();
        for (k, observation) in spec.observations.iter().enumerate() {
            let mut with_velocity = scenario.spec().clone();
            with_velocity.mechanism.impact_velocity_m_s = observation.impact_velocity_m_s;
            let bounces = simulate(
                &Scenario::new(with_velocity, &Pointer::root()).unwrap(),
                Fidelity::Exact,
            )
            .bounces;
            let e1 = bounces[0].separation_velocity_m_s / observation.impact_velocity_m_s.unwrap();
            let e2 = bounces[1].separation_velocity_m_s / bounces[0].separation_velocity_m_s;
            // The bias is a mean over the observations: each corrected reading is near its own.
            assert!(
                (readings["e1"].corrected[k] / e1 - 1.0).abs() < 0.05,
                "{k}: {readings:?}"
            );
            assert!(
                (readings["e2"].corrected[k] / e2 - 1.0).abs() < 0.05,
                "{k}: {readings:?}"
            );
        }
    }

    /// A parameter deeper in the scenario, the post-arc law's intercept `a`, from arcing
    /// operations' bounce times.
    #[test]
    fn a_nested_parameter_is_fitted_by_its_dotted_path() {
        let mut truth = ScenarioSpec::default();
        truth.circuit.supply_voltage_v = 48.0;
        truth.circuit.current_a = 15.0;
        truth.material.arc_restitution.a = 0.3;
        let observations = outcomes(&truth, &[0.2, 0.3, 0.4, 0.5])
            .into_iter()
            .map(|(v, outcome)| Observation {
                impact_velocity_m_s: Some(v),
                total_bounce_s: Some(outcome.total_bounce_s),
                ..Observation::default()
            })
            .collect();
        let mut scenario = truth.clone();
        scenario.material.arc_restitution.a = 0.235;
        let fit = calibrate(&CalibrationSpec {
            scenario,
            fit: vec!["material.arc_restitution.a".into()],
            observations,
            bounds: BTreeMap::new(),
        })
        .unwrap();
        let a = &fit.estimates["material.arc_restitution.a"];
        assert!((a.value / 0.3 - 1.0).abs() < 1e-6, "{a:?}");
        assert_eq!(fit.scenario.material.arc_restitution.a, a.value);
    }

    /// The model's own default output on the paper's rig at 0.344 N and H = 1 mm, rounded: a
    /// first bounce of 10.4 ms and 7 bounces in 29 ms (10.42 ms and 28.63 ms unrounded). These are
    /// not the paper's numbers (docs/model.md section 10). The fit gives back the defaults' own
    /// kappa, 0.3625, moved to 0.364 by the rounding (95 % interval 0.354 to 0.375); and kappa
    /// 0.3, which the paper says its Fig. 6 curve uses, gives a first bounce of 9.0 ms on this
    /// rig.
    #[test]
    fn the_models_rounded_output_gives_back_its_own_kappa() {
        let spec = CalibrationSpec::from_json(
            r#"{"fit": ["material.kappa"], "observations": [
                {"first_bounce_s": 0.0104, "total_bounce_s": 0.029, "bounce_count": 7}]}"#,
        )
        .unwrap();
        let fit = calibrate(&spec).unwrap();
        let kappa = &fit.estimates["material.kappa"];
        assert!((kappa.value - 0.364).abs() < 0.002, "{kappa:?}");
        // Two measured values (a count is not fitted) and one parameter: Student's t for one
        // degree of freedom, 12.706, and an interval near the linearised exp(ln x -+ t se_ln).
        let [lo, hi] = kappa.ci95;
        assert!(
            (lo - 0.354).abs() < 0.001 && (hi - 0.375).abs() < 0.001,
            "{kappa:?}"
        );
        let linear = |sign: f64| kappa.value * (sign * 12.706 * kappa.se_ln).exp();
        assert_relative_eq!(lo, linear(-1.0), max_relative = 5e-3);
        assert_relative_eq!(hi, linear(1.0), max_relative = 5e-3);
        let mut at_0_3 = ScenarioSpec::default();
        at_0_3.material.kappa = Some(0.3);
        let first = simulate(
            &Scenario::new(at_0_3, &Pointer::root()).unwrap(),
            Fidelity::Exact,
        )
        .outcome
        .first_bounce_s;
        assert!((first - 0.0090).abs() < 0.0002, "{first}");
    }

    /// A wear curve: one device's first and total bounce times and eroded mass at five points of
    /// a 1000-operation test at 48 V / 15 A, from the independent 50-digit trajectory of
    /// `tools/wear_reference.py`. Started from the wrong roughening energy and erosion rate, the
    /// fit finds the trajectory's own, and its simulated curve is the reference's to 1e-9.
    #[test]
    fn a_wear_curve_gives_the_roughening_energy_and_the_erosion_rate() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/data/wear_reference.json"
        );
        let reference: Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let trajectory = &reference["roughening"]["operations"];
        let at = |name: &str, j: usize| trajectory[name][j].as_f64().unwrap();
        let observations = [0_usize, 100, 250, 500, 999]
            .into_iter()
            .map(|j| {
                let energy_j: f64 = (0..=j).map(|k| at("arc_energy_j", k)).sum();
                Observation {
                    operation: Some(j as u64),
                    first_bounce_s: Some(at("first_bounce_s", j)),
                    total_bounce_s: Some(at("total_bounce_s", j)),
                    eroded_mass_kg: Some(2e-9 * energy_j),
                    ..Observation::default()
                }
            })
            .collect();
        let mut scenario: ScenarioSpec =
            serde_json::from_value(reference["roughening"]["scenario"].clone()).unwrap();
        scenario.material.roughening_energy_j = 800.0;
        scenario.material.erosion_kg_per_j = 5e-9;
        let fit = calibrate(&CalibrationSpec {
            scenario,
            fit: vec![
                "material.roughening_energy_j".into(),
                "material.erosion_kg_per_j".into(),
            ],
            observations,
            bounds: BTreeMap::new(),
        })
        .unwrap();
        let estimates = &fit.estimates;
        assert!(
            (estimates["material.roughening_energy_j"].value / 500.0 - 1.0).abs() < 1e-8,
            "{estimates:?}"
        );
        assert!(
            (estimates["material.erosion_kg_per_j"].value / 2e-9 - 1.0).abs() < 1e-8,
            "{estimates:?}"
        );
        for quantity in ["first_bounce_s", "total_bounce_s", "eroded_mass_kg"] {
            assert!(
                fit.residuals[quantity].rms_relative < 1e-9,
                "{quantity}: {fit:?}"
            );
        }
    }

    #[test]
    fn a_parameter_the_data_cannot_see_is_refused_naming_it() {
        let mut spec = synthetic(0.3, 1e-6, 0.01);
        // With kappa given, the contact radius no longer changes e1 or the bounce times.
        spec.scenario.material.kappa = Some(0.3);
        spec.fit.push("material.contact_radius_m".into());
        let invalid = calibrate(&spec).unwrap_err();
        assert_eq!(invalid.errors()[0].pointer, "/fit/1", "{invalid:?}");
        assert!(invalid.errors()[0].detail.contains("cannot determine"));
        // At its start: no word of data beyond the model's reach.
        assert!(!invalid.errors()[0].detail.contains("moved"), "{invalid}");
    }

    /// Bounds around the truth change nothing; bounds that leave it out hold the estimate on the
    /// nearer one, which the estimate says.
    #[test]
    fn bounds_hold_the_estimate() {
        let free = calibrate(&synthetic(0.3, 1e-6, 0.01)).unwrap();
        let mut spec = synthetic(0.3, 1e-6, 0.01);
        spec.bounds.insert("material.kappa".into(), [0.2, 0.4]);
        let within = calibrate(&spec).unwrap();
        assert_eq!(within.estimates, free.estimates);
        spec.bounds.insert("material.kappa".into(), [0.32, 0.4]);
        let held = &calibrate(&spec).unwrap().estimates["material.kappa"];
        assert!(
            held.at_bound && (held.value / 0.32 - 1.0).abs() < 1e-12,
            "{held:?}"
        );
        assert!(held.ci95[0] >= held.value * (1.0 - 1e-12), "{held:?}");
        let json = serde_json::to_value(&free.estimates["material.kappa"]).unwrap();
        assert!(json.get("at_bound").is_none(), "{json}");
    }

    /// Two parameters, one held on its bound: the other's estimate is the fit with the first
    /// fixed at the bound, from any start. The step cut at the bound crawled before, ending at
    /// the 100-iteration cap 1 % short, its answer depending on the start (a probe found it).
    #[test]
    fn a_parameter_on_its_bound_leaves_the_others_at_their_optimum_there() {
        let mut spec = synthetic(0.3, 2e-5, 0.02);
        spec.fit.push("losses.impact_energy_loss_j".into());
        spec.bounds.insert("material.kappa".into(), [0.31, 0.5]);
        let mut fixed = spec.clone();
        fixed.scenario.material.kappa = Some(0.31);
        fixed.fit = vec!["losses.impact_energy_loss_j".into()];
        fixed.bounds.clear();
        let expected = calibrate(&fixed).unwrap().estimates["losses.impact_energy_loss_j"].value;
        for (kappa, loss) in [(None, None), (Some(0.05), None), (Some(0.32), Some(2e-5))] {
            let mut start = spec.clone();
            start.scenario.material.kappa = kappa;
            if let Some(loss) = loss {
                start.scenario.losses.impact_energy_loss_j = loss;
            }
            let fit = calibrate(&start).unwrap();
            let held = &fit.estimates["material.kappa"];
            assert!(held.at_bound && held.value == 0.31, "{held:?}");
            let loss = fit.estimates["losses.impact_energy_loss_j"].value;
            assert!(
                (loss / expected - 1.0).abs() < 1e-6,
                "{loss} against {expected}: {fit:?}"
            );
            assert!(fit.iterations < 100, "{fit:?}");
        }
    }

    /// The request as docs/contract.md writes it: `bounds` maps a fitted parameter to `[lower,
    /// upper]`. The shape check took those pairs for mistaken arrays, so no request could set one.
    #[test]
    fn bounds_are_read_as_the_contract_writes_them() {
        let request = |bounds: &str| {
            CalibrationSpec::from_json(&format!(
                r#"{{"fit": ["material.kappa"], "bounds": {bounds},
                    "observations": [{{"first_bounce_s": 0.009}}, {{"first_bounce_s": 0.0095}}]}}"#
            ))
        };
        let spec = request(r#"{"material.kappa": [0.2, 0.5]}"#).unwrap();
        assert_eq!(spec.bounds["material.kappa"], [0.2, 0.5]);
        // Any other array there is still refused where it stands.
        let nested = request(r#"{"material.kappa": [[0.2], 0.5]}"#).unwrap_err();
        assert_eq!(nested.pointers(), ["/bounds/material.kappa/0"]);
        let listed = request(r#"[0.2, 0.5]"#).unwrap_err();
        assert_eq!(listed.pointers(), ["/bounds"]);
    }

    /// A member of the wrong type or unknown is named and read past, and the rules of the rest
    /// are checked too, as for a job (docs/contract.md, "Errors"): the request named `/bogus`
    /// alone before.
    #[test]
    fn every_field_at_fault_is_named_past_a_wrong_type_or_an_unknown_member() {
        for (text, pointers) in [
            (
                r#"{"fit": ["material.kappa"], "bogus": 1,
                    "observations": [{"first_bounce_s": -1}]}"#,
                vec!["/bogus", "/observations/0/first_bounce_s"],
            ),
            (
                r#"{"fit": ["material.kappa"], "scenario": {"circuit": {"current_a": "x"}},
                    "observations": [{"first_bounce_s": 0.009, "bogus": 1},
                                     {"first_bounce_s": -1}]}"#,
                vec![
                    "/observations/0/bogus",
                    "/scenario/circuit/current_a",
                    "/observations/1/first_bounce_s",
                ],
            ),
            (
                // Its one measured value left out, the observation measures nothing: a
                // consequence, said once at the value.
                r#"{"fit": ["material.kappa"], "observations": [{"e1": "x"},
                    {"first_bounce_s": 0.009}, {"first_bounce_s": 0.0095}]}"#,
                vec!["/observations/0/e1"],
            ),
        ] {
            let invalid = CalibrationSpec::from_json(text).unwrap_err();
            assert_eq!(invalid.pointers(), pointers, "{invalid}");
        }
    }

    /// An estimate that a rule of the scenario stops (the contact radius no smaller than the
    /// worn radius) is held on that edge as on a bound, its interval cut there: it was reported
    /// as an optimum, its interval reaching radii the scenario refuses.
    #[test]
    fn an_estimate_on_an_edge_of_the_scenario_is_marked_and_cut_there() {
        let mut truth = ScenarioSpec::default();
        truth.material.contact_radius_m = 0.0033;
        let observations = outcomes(&truth, &[0.15, 0.25, 0.35, 0.45])
            .into_iter()
            .map(|(v, outcome)| Observation {
                impact_velocity_m_s: Some(v),
                first_bounce_s: Some(outcome.first_bounce_s),
                total_bounce_s: Some(outcome.total_bounce_s),
                ..Observation::default()
            })
            .collect();
        let mut scenario = ScenarioSpec::default();
        scenario.material.worn_radius_m = 0.0077;
        let fit = calibrate(&CalibrationSpec {
            scenario,
            fit: vec!["material.contact_radius_m".into()],
            observations,
            bounds: BTreeMap::new(),
        })
        .unwrap();
        let radius = &fit.estimates["material.contact_radius_m"];
        assert!(radius.at_bound, "{radius:?}");
        assert_eq!(radius.ci95[0], radius.value, "{radius:?}");
        assert!(
            radius.value >= 0.0077 && radius.ci95[1] > radius.value,
            "{radius:?}"
        );
    }

    /// Data the model cannot reach (e1 of 1, which e(u, kappa) only nears; above 1 is refused at
    /// the field) draw kappa to where e1 saturates: refused at `/fit/0`, the message saying where
    /// the fit had taken it and why, not only that kappa "changes none of the measured
    /// quantities".
    #[test]
    fn data_beyond_the_models_reach_are_refused_saying_so() {
        let invalid = CalibrationSpec::from_json(
            r#"{"fit": ["material.kappa"], "observations": [
                {"impact_velocity_m_s": 0.2, "e1": 1}, {"impact_velocity_m_s": 0.3, "e1": 1},
                {"impact_velocity_m_s": 0.4, "e1": 1}]}"#,
        )
        .and_then(|spec| calibrate(&spec))
        .unwrap_err();
        assert_eq!(invalid.pointers(), ["/fit/0"], "{invalid}");
        let detail = &invalid.errors()[0].detail;
        assert!(detail.contains("the fit moved it there"), "{detail}");
        assert!(
            !detail.contains("at 0.36"),
            "the fit moved kappa from its start: {detail}"
        );
    }

    /// Measurements 1e11 times below the start's (an e1 of 1e-12 against 0.5) leave the relative
    /// differences at their end, where no step moves them: refused saying so, not that kappa
    /// changes nothing; from a start near them (kappa 1e-11) the same data fit.
    #[test]
    fn measurements_far_from_the_start_are_refused_saying_so() {
        let data = r#""observations": [{"e1": 1e-12}, {"e1": 1.01e-12}]"#;
        let invalid =
            CalibrationSpec::from_json(&format!(r#"{{"fit": ["material.kappa"], {data}}}"#))
                .and_then(|spec| calibrate(&spec))
                .unwrap_err();
        assert_eq!(invalid.pointers(), ["/fit/0"], "{invalid}");
        let detail = &invalid.errors()[0].detail;
        assert!(
            detail.contains("over 2000 times its measurement"),
            "{detail}"
        );
        let near = CalibrationSpec::from_json(&format!(
            r#"{{"scenario": {{"material": {{"kappa": 1e-11}}}}, "fit": ["material.kappa"],
                {data}}}"#
        ))
        .unwrap();
        let kappa = calibrate(&near).unwrap().estimates["material.kappa"].value;
        assert!(kappa > 1e-13 && kappa < 1e-11, "{kappa:e}");
    }

    /// Noisy e1 data (40 %) that do not bound a parameter before an edge of the scenarios the
    /// model takes: an outside check found the radius interval ending at 0.00071011 for a worn
    /// radius of 0.000711, and a yield pressure's at 9.99e7 under a worn pressure of 1e8, values
    /// the model refuses, with no warning. Each ends at its edge now, saying so.
    #[test]
    fn an_interval_the_data_do_not_bound_ends_at_the_scenarios_edge() {
        let e1 = |values: [f64; 7]| {
            let velocities = [0.12, 0.2, 0.28, 0.36, 0.45, 0.55, 0.65];
            let observations: Vec<String> = velocities
                .iter()
                .zip(values)
                .map(|(v, e1)| format!(r#"{{"impact_velocity_m_s": {v}, "e1": {e1}}}"#))
                .collect();
            observations.join(",")
        };
        let radius = format!(
            r#"{{"fit": ["material.contact_radius_m"], "observations": [{}]}}"#,
            e1([
                0.6291476617474576,
                0.4117722683708596,
                0.4019885679704418,
                0.010629931071048128,
                0.7408018486272392,
                0.5986548376422403,
                0.34328541465837087
            ])
        );
        let pressure = format!(
            r#"{{"scenario": {{"material": {{"wear_law": {{"law": "roughening_and_softening"}}}}}},
                "fit": ["material.dynamic_yield_pressure_pa"], "observations": [{}]}}"#,
            e1([
                0.4324184423515469,
                0.4842514504626833,
                0.8020222366731249,
                0.5737232390848098,
                0.14792971120875217,
                0.4098392299587084,
                0.2962357642294031
            ])
        );
        let defaults = ScenarioSpec::default();
        for (text, name, edge) in [
            (
                radius,
                "material.contact_radius_m",
                defaults.material.worn_radius_m,
            ),
            (
                pressure,
                "material.dynamic_yield_pressure_pa",
                defaults.material.wear_law.worn_pressure_pa,
            ),
        ] {
            let fit = calibrate(&CalibrationSpec::from_json(&text).unwrap()).unwrap();
            let lower = fit.estimates[name].ci95[0];
            assert!(
                lower >= edge && lower < edge * (1.0 + 1e-9),
                "{name}: {lower:e}"
            );
            assert!(
                fit.warnings
                    .iter()
                    .any(|w| w.contains("before an edge of the scenarios")),
                "{:?}",
                fit.warnings
            );
        }
    }

    /// An estimate on its bound (kappa within [0.2, 0.3], the data pulling above) ends its
    /// interval there: it was told its profile "could not be followed above the estimate" and
    /// that the end was the Wald one, which it was not.
    #[test]
    fn an_end_at_a_bound_is_not_taken_for_a_stuck_profile() {
        let text = r#"{"fit": ["material.kappa"], "bounds": {"material.kappa": [0.2, 0.3]},
            "observations": [{"impact_velocity_m_s": 0.12, "e1": 0.5426886419685151},
            {"impact_velocity_m_s": 0.2, "e1": 0.48898186270611427},
            {"impact_velocity_m_s": 0.28, "e1": 0.445326146428378},
            {"impact_velocity_m_s": 0.36, "e1": 0.3992272230593513},
            {"impact_velocity_m_s": 0.45, "e1": 0.4046538968763057},
            {"impact_velocity_m_s": 0.55, "e1": 0.38049985705326805},
            {"impact_velocity_m_s": 0.65, "e1": 0.35488431826240147}]}"#;
        let fit = calibrate(&CalibrationSpec::from_json(text).unwrap()).unwrap();
        let kappa = &fit.estimates["material.kappa"];
        assert!(kappa.at_bound, "{kappa:?}");
        assert_eq!(kappa.ci95[1], 0.3, "{kappa:?}");
        assert!(
            !fit.warnings
                .iter()
                .any(|w| w.contains("could not be followed")),
            "{:?}",
            fit.warnings
        );
    }

    /// A count cannot be fitted: `losses.max_bounces` was refused at `/scenario` as "the starting
    /// scenario cannot simulate every observation" (its first step left the integers).
    #[test]
    fn a_count_is_refused_at_its_place_in_fit() {
        let invalid = CalibrationSpec::from_json(
            r#"{"fit": ["material.kappa", "losses.max_bounces"], "observations": [
                {"first_bounce_s": 0.009}, {"first_bounce_s": 0.0095}, {"e1": 0.4}]}"#,
        )
        .unwrap_err();
        assert_eq!(invalid.pointers(), ["/fit/1"], "{invalid}");
        assert!(invalid.to_string().contains("a whole number"), "{invalid}");
    }

    /// A start no scenario takes (eq. 8's kappa of contacts of 1e-30 m, 1.5e-35) is refused at
    /// its place in `fit`, not blamed on the scenario (found from outside); inside the
    /// magnitudes it starts.
    #[test]
    fn a_start_beyond_a_scenarios_magnitudes_names_its_parameter() {
        let text = |bounds: &str| {
            format!(
                r#"{{"scenario": {{"material": {{"contact_radius_m": 1e-30, "worn_radius_m": 1e-30,
                    "dynamic_yield_pressure_pa": 1e-30}}}}, "fit": ["material.kappa"]{bounds},
                    "observations": [{{"e1": 0.3}}, {{"e1": 0.2}}]}}"#
            )
        };
        let invalid = calibrate(&CalibrationSpec::from_json(&text("")).unwrap()).unwrap_err();
        assert_eq!(invalid.pointers(), ["/fit/0"], "{invalid}");
        assert!(
            invalid.to_string().contains("material.kappa starts at 1.4"),
            "{invalid}"
        );
        // Bounds wholly outside the magnitudes are the bounds' fault, not the start's.
        for outside in ["[1e31, 1e35]", "[1e-40, 1e-35]"] {
            let bounds = format!(r#", "bounds": {{"material.kappa": {outside}}}"#);
            let invalid = CalibrationSpec::from_json(&text(&bounds)).unwrap_err();
            assert_eq!(invalid.pointers(), ["/bounds/material.kappa"], "{invalid}");
        }
        let bounded = text(r#", "bounds": {"material.kappa": [1e-20, 1]}"#);
        let refused = calibrate(&CalibrationSpec::from_json(&bounded).unwrap()).unwrap_err();
        assert!(!refused.to_string().contains("starts at"), "{refused}");
    }

    /// Bounds that move the start to where the scenario breaks a rule name themselves and the
    /// rule (a probe's radius bounded below the worn radius read "/scenario: cannot simulate").
    #[test]
    fn bounds_that_move_the_start_out_of_the_scenario_name_themselves() {
        let text = r#"{"fit": ["material.contact_radius_m"],
            "bounds": {"material.contact_radius_m": [1e-30, 1e-29]},
            "observations": [{"e1": 0.3}, {"e1": 0.31}]}"#;
        let refused = calibrate(&CalibrationSpec::from_json(text).unwrap()).unwrap_err();
        assert_eq!(
            refused.pointers(),
            ["/bounds/material.contact_radius_m"],
            "{refused}"
        );
        let message = refused.to_string();
        for part in ["starts at 0.0077 (", "breaks a rule: /scenario/material/"] {
            assert!(message.contains(part), "{part}: {message}");
        }
        // Bounds the start simulates within are taken as before.
        let within = text.replace("[1e-30, 1e-29]", "[5e-3, 2e-2]");
        calibrate(&CalibrationSpec::from_json(&within).unwrap()).unwrap();
        // Two moved: the one that breaks the rule is named, whichever is listed first.
        let two = r#"{"fit": ["material.kappa", "material.contact_radius_m"],
            "bounds": {"material.kappa": [0.5, 0.6], "material.contact_radius_m": [1e-30, 1e-29]},
            "observations": [{"e1": 0.3, "first_bounce_s": 0.01},
                             {"e1": 0.31, "first_bounce_s": 0.011}]}"#;
        let refused = calibrate(&CalibrationSpec::from_json(two).unwrap()).unwrap_err();
        assert_eq!(
            refused.pointers(),
            ["/bounds/material.contact_radius_m"],
            "{refused}"
        );
    }

    /// A start or bound on a rule's edge is taken exactly, not through its logarithm's round
    /// trip: a radius bounded at the worn radius, or starting there, broke the rule by an ulp
    /// (found from outside), and an estimate held by its bound read a hair inside it.
    #[test]
    fn a_start_or_bound_on_a_rules_edge_is_taken_exactly() {
        let request = |scenario: &str, bounds: &str| {
            let text = format!(
                r#"{{"scenario": {{"material": {scenario}}}, "fit": ["material.contact_radius_m"]
                    {bounds}, "observations": [{{"e1": 0.3}}, {{"e1": 0.31}}]}}"#
            );
            calibrate(&CalibrationSpec::from_json(&text).unwrap())
        };
        let at_edge = r#"{"worn_radius_m": 0.000703, "contact_radius_m": 0.000703}"#;
        let fit = request(at_edge, "").unwrap();
        assert!(fit.estimates["material.contact_radius_m"].value >= 0.000703);
        let worn = r#"{"worn_radius_m": 0.000703}"#;
        request(
            worn,
            r#", "bounds": {"material.contact_radius_m": [1e-4, 0.000703]}"#,
        )
        .unwrap();
        // A start on the edge, its bound an ulp beyond the edge with the same logarithm: the
        // start as written (the bound was taken for it, and the scenario refused).
        let below = f64::from_bits(0.000703f64.to_bits() - 1);
        assert_eq!(below.ln(), 0.000703f64.ln());
        let bounds = format!(r#", "bounds": {{"material.contact_radius_m": [{below:e}, 2e-2]}}"#);
        request(at_edge, &bounds).unwrap();
        // Held by its lower bound (the data's radius is 1.9e-3), the estimate is the bound, as
        // written.
        let held = request(
            "{}",
            r#", "bounds": {"material.contact_radius_m": [3e-3, 6e-3]}"#,
        );
        let estimate = &held.unwrap().estimates["material.contact_radius_m"];
        assert!(estimate.at_bound, "{estimate:?}");
        assert_eq!(
            (estimate.value, estimate.ci95[0]),
            (3e-3, 3e-3),
            "{estimate:?}"
        );
    }

    /// A measured value beyond a scenario's magnitudes is refused at its field (a sweep of the
    /// HTTP API found `first_bounce_s: 1e308` blamed on the starting scenario).
    #[test]
    fn a_measured_value_beyond_the_supported_range_names_its_field() {
        for value in ["1e308", "1e31", "1e-31"] {
            let text = format!(
                r#"{{"fit": ["material.kappa"], "observations":
                    [{{"first_bounce_s": 0.009}}, {{"first_bounce_s": {value}}}]}}"#
            );
            let invalid = CalibrationSpec::from_json(&text).unwrap_err();
            assert_eq!(
                invalid.pointers(),
                ["/observations/1/first_bounce_s"],
                "{invalid}"
            );
        }
    }

    #[test]
    fn bad_requests_name_their_fields() {
        let spec = CalibrationSpec {
            bounds: BTreeMap::from([
                ("material.kappa".into(), [0.5, 0.4]),
                ("losses.impact_energy_loss_j".into(), [1e-7, 1e-5]),
            ]),
            scenario: ScenarioSpec::default(),
            fit: vec!["kappa".into(), "material.nothing".into()],
            observations: vec![
                Observation::default(),
                Observation {
                    first_bounce_s: Some(-1.0),
                    impact_velocity_m_s: Some(-0.2),
                    ..Observation::default()
                },
                // A coefficient of restitution is at most 1.
                Observation {
                    e1: Some(1.5),
                    total_bounce_s: Some(0.02),
                    ..Observation::default()
                },
                // Nothing bounces at no speed.
                Observation {
                    impact_velocity_m_s: Some(0.0),
                    first_bounce_s: Some(0.01),
                    peak_force_n: Some(0.3),
                    ..Observation::default()
                },
            ],
        };
        let invalid = calibrate(&spec).unwrap_err();
        assert_eq!(
            invalid.pointers(),
            [
                "/fit/0",
                "/fit/1",
                "/observations/0",
                "/observations/1/impact_velocity_m_s",
                "/observations/1/first_bounce_s",
                "/observations/2/e1",
                "/observations/3/first_bounce_s",
                "/bounds/losses.impact_energy_loss_j",
                "/bounds/material.kappa"
            ]
        );
    }
}
