"""Schemathesis hooks for the rules JSON Schema cannot state.

The OpenAPI document gives every request field the range the server enforces on it alone, and
states in words the rules that relate fields to each other (docs/contract.md "Job"). Schemathesis
generates from the schema, so a generated request that the schema accepts may still break one of
those rules, and the server then rightly answers 422. This hook applies those rules to the
requests schemathesis means to be valid (its positive cases), nothing else: negative cases and
everything the schema can say are left to the server, and to the checks.

Each repair names the rule it applies. BOUNCEWEAR_MAX_JOB_OPERATIONS is the server's
`--max-job-operations`.
"""

import os
import uuid

import schemathesis
from schemathesis import GenerationMode

MAX_JOB_OPERATIONS = int(os.environ.get("BOUNCEWEAR_MAX_JOB_OPERATIONS", "2000000000"))
POLAR = {"anode_eroded_mass_kg", "cathode_eroded_mass_kg"}
OPERATION_METRICS = {
    "impact_velocity_m_s", "kappa", "e1", "first_bounce_s", "total_bounce_s", "bounce_count",
    "pre_arc_s", "arc_energy_j", "peak_force_n", "impact_duration_s", "first_impact_plastic_work_j",
}
# The request example of POST /v1/calibrations (service/src/api/openapi.rs).
CALIBRATION_EXAMPLE = {
    "scenario": {},
    "fit": ["material.kappa", "losses.impact_energy_loss_j"],
    "observations": [
        {"impact_velocity_m_s": 0.2, "first_bounce_s": 0.00896, "second_bounce_s": 0.00515, "total_bounce_s": 0.0188, "bounce_count": 4},
        {"impact_velocity_m_s": 0.3, "first_bounce_s": 0.0116, "second_bounce_s": 0.00657, "total_bounce_s": 0.025, "bounce_count": 5},
        {"impact_velocity_m_s": 0.4, "first_bounce_s": 0.0136, "second_bounce_s": 0.00772, "total_bounce_s": 0.0297, "bounce_count": 5},
    ],
}
DEVICE_METRICS = {
    "cumulative_arc_energy_j", "eroded_mass_kg", "final_radius_m", "final_kappa",
    "cumulative_plastic_work_j", "anode_eroded_mass_kg", "cathode_eroded_mass_kg",
}
DEFAULT_STATISTIC = "operations.total_bounce_s.p95"
DEFAULT_CONTACT_RADIUS_M = 7.7e-3
DEFAULT_PRESSURE_PA = 2.0e8


def repair_scenario(scenario):
    material = scenario.get("material")
    if not isinstance(material, dict):
        return
    # worn_radius_m is at most contact_radius_m.
    contact = material.get("contact_radius_m", DEFAULT_CONTACT_RADIUS_M)
    if material.get("worn_radius_m", 0.711e-3) > contact:
        material["worn_radius_m"] = contact
    wear = material.get("wear_law")
    # Under roughening_and_softening, worn_pressure_pa is at most dynamic_yield_pressure_pa.
    if isinstance(wear, dict) and wear.get("law") == "roughening_and_softening":
        pressure = material.get("dynamic_yield_pressure_pa", DEFAULT_PRESSURE_PA)
        if wear.get("worn_pressure_pa", 1.0e8) > pressure:
            wear["worn_pressure_pa"] = pressure
    # The continuous post-arc law must arc at its calibration current: a relation of four fields
    # of two sections; the paper's law has no such rule.
    law = material.get("arc_restitution")
    if isinstance(law, dict) and law.get("law") == "continuous":
        law["law"] = "paper"


def repair_job(job):
    if not isinstance(job, dict):
        return
    if isinstance(job.get("scenario"), dict):
        repair_scenario(job["scenario"])
    devices = job.get("devices", 1000)
    operations = job.get("operations", 1000)
    # devices x operations (max_devices with a precision target) within the server's limit.
    if devices * operations > MAX_JOB_OPERATIONS:
        devices = job["devices"] = min(devices, MAX_JOB_OPERATIONS)
        operations = job["operations"] = max(1, MAX_JOB_OPERATIONS // devices)
    # bin_operations is at most operations and makes at most 1000 bins.
    bins = job.get("bin_operations")
    if bins is not None and (bins > operations or -(-operations // bins) > 1000):
        del job["bin_operations"]
    if "bin_operations" not in job and operations > 1000 * max(1, operations // 10):
        job["bin_operations"] = -(-operations // 1000)
    # Each scatter distribution's numbers relate to each other and to the scenario: the request
    # examples send a valid scatter.
    job.pop("scatter", None)
    # A correlation is over scatter entries of the same `per`, so it goes with them.
    job.pop("correlation", None)
    # A sensitivity analysis needs a scattered parameter, so it goes with them too.
    job.pop("sensitivity", None)
    # So does a rare event.
    job.pop("rare_event", None)
    # The anode/cathode masses need scenario.material.anode_erosion_fraction.
    polarity = has_polarity(job)
    metrics = job.get("metrics")
    if isinstance(metrics, list) and not polarity:
        metrics[:] = [m for m in metrics if m not in POLAR]
        if not metrics:
            del job["metrics"]
    available = lambda name: name in computed_metrics(job)
    # Limits are on the job's metrics.
    if isinstance(job.get("limits"), dict):
        job["limits"] = {k: v for k, v in job["limits"].items() if available(k)}
    # A failure criterion gives exactly one of above or below, on a metric the scenario has.
    if isinstance(job.get("failure"), dict):
        failure = {}
        for name, criterion in job["failure"].items():
            if not (polarity or name not in POLAR):
                continue
            given = {k: v for k, v in criterion.items() if v is not None}
            failure[name] = given if len(given) == 1 else {"above": next(iter(given.values()), 0)}
        job["failure"] = failure
    # A precision target is on one of the job's operation metrics, in batches of at least 16
    # devices, with max_devices from devices to what the size limit allows.
    precision = job.get("precision")
    if isinstance(precision, dict):
        fits = precision.get("max_devices", 0) * operations <= MAX_JOB_OPERATIONS
        if (
            not available(precision.get("metric"))
            or precision.get("metric") not in OPERATION_METRICS
            or devices < 16
            or precision.get("max_devices", 0) < devices
            or not fits
        ):
            del job["precision"]


def has_polarity(job):
    """Whether the job's scenario splits the eroded mass by polarity (the anode/cathode metrics)."""
    return (job.get("scenario") or {}).get("material", {}).get("anode_erosion_fraction") is not None


def computed_metrics(job):
    """The metrics a (repaired) job computes: those it lists, else all its scenario has."""
    polarity = has_polarity(job)
    every = {m for m in OPERATION_METRICS | DEVICE_METRICS if polarity or m not in POLAR}
    return set(job.get("metrics") or []) & every or every


def repair_statistics(schedule):
    """A schedule follows only statistics its template's runs give (docs/manual.md, schedules):
    an operation metric under `operations`, a device metric under `devices`, among the metrics
    the template computes; life statistics only with failure criteria; none twice. Those that do
    not fit are dropped, and a list left empty (or a default that does not fit) gets one that
    does."""
    template = schedule.get("template")
    if not isinstance(template, dict):
        return
    computed = computed_metrics(template)
    life = bool(template.get("failure"))

    def fits(statistic):
        section, _, rest = statistic.partition(".")
        metric = rest.partition(".")[0]
        if section == "operations":
            return metric in OPERATION_METRICS and metric in computed
        if section == "devices":
            return metric in DEVICE_METRICS and metric in computed
        return section == "life" and life

    statistics = schedule.get("statistics")
    if statistics is None:
        if fits(DEFAULT_STATISTIC):
            return
        statistics = []
    if not isinstance(statistics, list):
        return
    kept = []
    for statistic in statistics:
        if isinstance(statistic, str) and fits(statistic) and statistic not in kept:
            kept.append(statistic)
    if not kept:
        operation = sorted(computed & OPERATION_METRICS)
        kept = [f"operations.{operation[0]}.p95" if operation
                else f"devices.{sorted(computed)[0]}.mean"]
    schedule["statistics"] = kept


def finite(text):
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value - value == 0 else None


def repair_after_run_query(query):
    """A query after the run: each level a number strictly between 0 and 1, each threshold a finite
    number (the patterns state the characters, not the values)."""
    levels = query.get("quantiles")
    if levels is not None and not all(
        (finite(level) or 0) > 0 and (finite(level) or 1) < 1 for level in levels.split(",")
    ):
        query["quantiles"] = "0.5,0.999"
    thresholds = query.get("exceedance")
    if thresholds is not None and not all(
        finite(item.partition(":")[2]) is not None for item in thresholds.split(",")
    ):
        query["exceedance"] = "above:0.005,below:0.002"


# Just before each call: the stateful phase fills bodies from earlier responses after generation.
@schemathesis.hook
def before_call(context, case, kwargs):
    meta = case.meta
    if meta is None or meta.generation.mode != GenerationMode.POSITIVE:
        return
    # An Idempotency-Key names one request: a key used again with another body is refused (422)
    # by design, so each generated request gets its own.
    if case.headers and "Idempotency-Key" in case.headers:
        case.headers["Idempotency-Key"] = uuid.uuid4().hex
    operation = case.operation
    # A listing's cursor is one the server sealed with its database's secret (24 hex digits is
    # its form, not its validity): a made-up one is refused (400), so a valid request has none.
    if operation.path in ("/v1/jobs", "/v1/schedules") and case.query:
        case.query.pop("cursor", None)
    if operation.path.endswith("/distributions/{metric}") and case.query:
        repair_after_run_query(case.query)
    # `confidence` is the confidence of a Weibayes demonstration: it comes with its shape.
    if operation.path.endswith("/life") and case.query and "confidence" in case.query:
        case.query.setdefault("weibayes_beta", 2.0)
    # A Weibayes demonstration is the JSON analysis's: the CSV of devices' lives takes neither
    # (400 with them).
    if operation.path.endswith("/life") and case.query and case.query.get("format") == "csv":
        case.query.pop("weibayes_beta", None)
        case.query.pop("confidence", None)
    body = case.body if isinstance(case.body, dict) else None
    if body is None:
        return
    if operation.path == "/v1/jobs" and operation.method.upper() == "POST":
        repair_job(body)
    elif operation.path == "/v1/simulate":
        repair_scenario(body)
    elif operation.path == "/v1/calibrations":
        # Whether a fit is well posed depends on what the measurements are and how the chosen
        # parameters move them, which no schema can say: a valid request is the documented
        # example (schemathesis' negative cases still fuzz every field).
        body.clear()
        body.update(CALIBRATION_EXAMPLE)
    elif operation.path.startswith("/v1/schedules"):
        repair_job(body.get("template"))
        repair_statistics(body)
        # A cron expression's syntax (croner's) is not a regular expression worth keeping in step.
        body["cron"] = "0 3 * * *"
