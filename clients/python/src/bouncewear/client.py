"""The client: a `Client` for a server, a `Job` for each job on it, and `BouncewearError` for every
answer that is not a success, with the problem's detail and the JSON pointer of each field at fault.
"""

from __future__ import annotations

import datetime
import email.utils
import io
import logging
import math
import os
import re
import sys
import time
import urllib.parse
import uuid
import warnings
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Optional, TypeVar

import pandas as pd
import requests

JSON = Dict[str, Any]

# The longest `wait_s` the server takes (docs/contract.md, "HTTP API").
MAX_WAIT_S = 30.0
# How long past a deadline (`Job.wait`'s timeout) a request's answer is awaited, as the CLI's
# `wait` does: a server asked to wait all the time left answers just after it.
ANSWER_GRACE_S = 1.0

#: The statuses a job ends in.
ENDED = ("succeeded", "failed", "cancelled")

#: The longest pause before a request is sent again, whatever `Retry-After` asks.
MAX_RETRY_PAUSE = 60.0

#: Requests that change nothing when sent twice. (Not DELETE: a second `?purge=true` deletes the job
#: the first only cancelled.) A POST is sent again only where the server honours its Idempotency-Key.
_REPEATABLE = ("GET", "HEAD", "PUT")
_KEYED = ("/v1/jobs", "/v1/schedules")

_log = logging.getLogger("bouncewear")


@dataclass(frozen=True)
class FieldError:
    """One field of a request that broke one rule: its JSON pointer and the rule in words."""

    pointer: str
    detail: str


@dataclass
class BouncewearError(Exception):
    """An answer that is not a success, as the server's problem (RFC 9457) tells it."""

    status: int
    title: str
    detail: str
    errors: List[FieldError] = field(default_factory=list)
    #: Seconds to wait before trying again (a full queue, a database that cannot answer now).
    retry_after: Optional[float] = None

    def __str__(self) -> str:
        # The server's detail names each field already; a field it leaves out is listed below it.
        fields = "".join(f"\n  {e.pointer or '(document)'}: {e.detail}" for e in self.errors
                         if f"{e.pointer}: {e.detail}" not in self.detail)
        return f"{self.status} {self.title}: {self.detail}{fields}"

    @property
    def pointers(self) -> List[str]:
        """The JSON pointers of the fields at fault, in order."""
        return [e.pointer for e in self.errors]

    def __reduce__(self) -> Any:
        # Rebuilt from its fields, so that it crosses a process boundary (a process pool): an
        # exception's own pickling passes its `args`, which a dataclass leaves empty.
        fields = (self.status, self.title, self.detail, self.errors, self.retry_after)
        return (BouncewearError, fields)

    @classmethod
    def from_response(cls, response: requests.Response) -> "BouncewearError":
        try:
            problem = response.json()
        except ValueError:
            problem = None
        if not isinstance(problem, dict):
            # Not a problem document (a proxy's page, a JSON value of another shape): its text.
            problem = {"detail": response.text}
        errors = problem.get("errors")
        return cls(
            status=response.status_code,
            title=str(problem.get("title", response.reason)),
            detail=str(problem.get("detail", "")),
            errors=[
                FieldError(str(e.get("pointer", "")), str(e.get("detail", "")))
                for e in (errors if isinstance(errors, list) else [])
                if isinstance(e, dict)
            ],
            retry_after=_seconds_to_wait(response.headers.get("Retry-After")),
        )


def _json(response: requests.Response) -> Any:
    """The answer's JSON, or `BouncewearError` naming the request and what came instead (a proxy's
    or a sign-in page's HTML answered with 200, say)."""
    try:
        return response.json()
    except ValueError:
        request = response.request
        kind = response.headers.get("Content-Type") or "no Content-Type"
        raise BouncewearError(
            status=response.status_code, title="Not JSON",
            detail=f"{request.method} {response.url} answered {response.status_code} with {kind}, "
                   f"not JSON: {response.text[:200]!r}") from None


def _non_finite(value: Any, pointer: str = "") -> Optional[str]:
    """The JSON pointer of the first number in `value` that JSON cannot carry (NaN, infinity)."""
    if isinstance(value, float) and not math.isfinite(value):
        return pointer or "/"
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, (list, tuple)) else ())
    for key, item in items:
        escaped = str(key).replace("~", "~0").replace("/", "~1")
        found = _non_finite(item, f"{pointer}/{escaped}")
        if found is not None:
            return found
    return None


def _segment(id: str) -> str:
    """An id, metric or plot's name as one segment of a path: a slash or `?` in it reaches no
    other resource and adds no query."""
    return urllib.parse.quote(str(id), safe="")


def _idempotency_key(key: Optional[str]) -> str:
    """`key` checked as the server takes it (1 to 255 visible ASCII characters: docs/contract.md
    "Idempotency-Key"), or a new one when None."""
    if key is None:
        return f"py-{uuid.uuid4().hex}"
    if not 1 <= len(key) <= 255 or not all("!" <= c <= "~" for c in key):
        raise ValueError(f"idempotency_key must be 1 to 255 visible ASCII characters, got {key!r}")
    return key


def _seconds_to_wait(retry_after: Optional[str]) -> Optional[float]:
    """`Retry-After` in seconds: given as seconds, or as an HTTP date (RFC 9110 10.2.3, as proxies
    send it), counted from now and never below 0; None when absent or unreadable."""
    if not retry_after:
        return None
    try:
        return max(0.0, float(retry_after))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(retry_after)
    except (TypeError, ValueError):
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.timezone.utc)
    return max(0.0, (when - datetime.datetime.now(datetime.timezone.utc)).total_seconds())


class JobFailed(Exception):
    """A job waited for ended `failed` or `cancelled`; `job` is it, `job.error` why."""

    def __init__(self, job: "Job") -> None:
        super().__init__(f"job {job.id} {job.status}: {job.error or 'no reason given'}")
        self.job = job

    def __reduce__(self) -> Any:
        # Rebuilt from its job, so that it crosses a process boundary (a process pool).
        return (JobFailed, (self.job,))


def _check_base_url(base_url: str) -> None:
    """Refuses a base URL the API's paths cannot be added to, by the rules of the command line's
    `--url`: `requests` would send `http://host/?x=1/v1/jobs` to the dashboard, or fail to find an
    adapter for `localhost:8080`, with a message that names neither."""
    def refused(rule: str) -> ValueError:
        shown = re.sub(r"(//[^/@:]*:)[^/@]*@", r"\1***@", base_url)  # no password in a message
        return ValueError(f"base_url {shown!r}: {rule}")
    try:
        parts = urllib.parse.urlsplit(base_url)
        port = parts.port
    except ValueError as error:
        raise refused(f"not a URL such as http://127.0.0.1:8080 ({error})") from None
    if parts.scheme not in ("http", "https"):
        raise refused(f"the scheme must be http or https, got {parts.scheme!r}" if parts.scheme
                      and parts.netloc else "no scheme: write http://HOST:PORT (or https://)")
    if not parts.hostname:
        raise refused("no host: write http://HOST:PORT (or https://)")
    if port == 0:
        raise refused("the port must be from 1 to 65535")
    if parts.query or parts.fragment or "?" in base_url or "#" in base_url:
        raise refused("a base URL has no query or fragment: the API's paths are added to it")


class Client:
    """A bouncewear server at `base_url`, with `api_key` when the server has keys.

    A request the server is too busy for (429, or 503 for a request that may be repeated: a GET,
    HEAD or PUT, or a POST the server honours an Idempotency-Key on) is sent again after its
    `Retry-After` (at most a minute), and a repeatable one whose connection was refused, reset or
    cut short after 0.5, 1, 2, ... s, up to `retries` times, each noted on the `bouncewear`
    logger; then the last `BouncewearError` (or `requests.ConnectionError`,
    `requests.exceptions.ChunkedEncodingError` for an answer cut short, or `requests.Timeout` for
    an answer that took longer than `timeout` seconds) is raised. `submit`
    always sends an Idempotency-Key, so a job is never queued twice.

    An `https` URL is checked against the CA certificates `requests` trusts, or instead those of
    the PEM file `ca_cert` (default: the `BOUNCEWEAR_CA_CERT` environment variable, as for the
    command line's `--ca-cert`), for a server whose certificate a company's own CA signed; a
    certificate not trusted raises `requests.exceptions.SSLError` at once. A `base_url` the API's
    paths cannot follow (no scheme or host, a query or fragment, a port beyond 1 to 65535) raises
    `ValueError` naming the rule, as the command line's `--url` is refused."""

    def __init__(self, base_url: str = "http://127.0.0.1:8080", api_key: Optional[str] = None,
                 timeout: Optional[float] = 60.0, retries: int = 3, ca_cert: Optional[str] = None) -> None:
        if retries < 0:
            raise ValueError(f"retries must be 0 or more, got {retries}")
        if timeout is not None and not timeout > 0:
            raise ValueError(f"timeout must be a number of seconds above 0 (or None), got {timeout!r}")
        if api_key is not None and (api_key.strip() != api_key or not api_key or not all(
                c == " " or "!" <= c <= "~" for c in api_key)):
            # As the command line's --api-key; the key itself is not repeated.
            raise ValueError("api_key: a key is printable ASCII, not empty and with no space at "
                             "either end, and the one given is not")
        _check_base_url(base_url)
        self.base_url = base_url.rstrip("/")
        self.timeout = timeout
        self.retries = retries
        self._session = requests.Session()
        ca_cert = ca_cert or os.environ.get("BOUNCEWEAR_CA_CERT") or None
        if ca_cert is not None and not os.path.isfile(ca_cert):
            raise ValueError(f"ca_cert {ca_cert!r} is not a file")
        # Given with each request: `requests` lets REQUESTS_CA_BUNDLE override a session's own.
        self._verify: Dict[str, Any] = {} if ca_cert is None else {"verify": ca_cert}
        if api_key is not None:
            self._session.headers["Authorization"] = f"Bearer {api_key}"

    def __repr__(self) -> str:
        return f"Client({self.base_url!r})"

    def request(self, method: str, path: str, *, json: Optional[JSON] = None,
                params: Optional[Dict[str, Any]] = None, headers: Optional[Dict[str, str]] = None,
                deadline: Optional[float] = None) -> requests.Response:
        """One request, sent again while the server is busy or cannot be reached (see `Client`),
        but never pausing past `deadline` (a `time.monotonic()` value); the response of a success,
        else `BouncewearError`. A `json` body holding NaN or an infinity, which JSON cannot carry,
        is a `ValueError` naming its field's pointer, as the server names a field it refuses."""
        if json is not None:
            pointer = _non_finite(json)
            if pointer is not None:
                raise ValueError(f"{pointer}: NaN and infinities are not JSON numbers; give a "
                                 "finite number")
        keyed = method.upper() == "POST" and path in _KEYED and any(
            name.lower() == "idempotency-key" and value for name, value in (headers or {}).items())
        repeatable = method.upper() in _REPEATABLE or keyed
        attempt = 0
        while True:
            failure: Exception
            timeout = self.timeout
            if deadline is not None:
                # No request outlasts the deadline by more than the answer's grace, whatever the
                # client's own timeout.
                left = max(deadline - time.monotonic(), 0.0) + ANSWER_GRACE_S
                timeout = min(timeout, left) if timeout else left
            try:
                response = self._session.request(method, self.base_url + path, json=json,
                                                 params=params, headers=headers, timeout=timeout,
                                                 **self._verify)
            except requests.exceptions.SSLError:
                raise  # a TLS fault, which another try would meet again
            except (requests.ConnectionError, requests.exceptions.ChunkedEncodingError,
                    requests.exceptions.Timeout) as error:
                # Refused, reset, closed before the whole answer, or no answer in time (a keyed
                # submission sent again gets the job it may have queued).
                failure, again = error, repeatable
                pause, why = 0.5 * 2 ** min(attempt, 7), str(error)
            else:
                if response.ok:
                    return response
                failure = BouncewearError.from_response(response)
                # A 429 refused before doing anything; a 503 may have come after.
                again = response.status_code == 429 or (response.status_code == 503 and repeatable)
                pause = 1.0 if failure.retry_after is None else failure.retry_after
                why = f"{response.status_code} from the server"
            pause = min(pause, MAX_RETRY_PAUSE)
            past = deadline is not None and time.monotonic() + pause > deadline
            if not again or attempt == self.retries or past:
                raise failure
            attempt += 1
            _log.warning("%s %s: %s; again in %.1f s (%d of %d)", method, path, why, pause,
                         attempt, self.retries)
            time.sleep(pause)

    def submit(self, job: JSON, *, idempotency_key: Optional[str] = None) -> "Job":
        """Queues `job` (a Job document: docs/contract.md "Job"); the job, queued.

        With `idempotency_key`, a retry of the same submission within 24 hours gives the same job;
        without, a key of its own makes this call's own retries safe.
        """
        headers = {"Idempotency-Key": _idempotency_key(idempotency_key)}
        return Job(self, _json(self.request("POST", "/v1/jobs", json=job, headers=headers)))

    def job(self, id: str) -> "Job":
        """The job `id` as it stands now."""
        return Job(self, _json(self.request("GET", f"/v1/jobs/{_segment(id)}")))

    def jobs(self, limit: Optional[int] = None) -> List["Job"]:
        """Your jobs, newest first: every one, or the newest `limit`."""
        if limit is not None and limit < 0:
            raise ValueError(f"limit must be 0 or more, got {limit}")
        found: List[Job] = []
        cursor = None
        while limit is None or len(found) < limit:
            page = min(100, limit - len(found)) if limit is not None else 100
            params: Dict[str, Any] = {"limit": page}
            if cursor:
                params["cursor"] = cursor
            body = _json(self.request("GET", "/v1/jobs", params=params))
            found.extend(Job(self, resource) for resource in body["jobs"])
            cursor = body.get("next_cursor")
            if not cursor:
                break
        return found

    def create_schedule(self, schedule: JSON, *, idempotency_key: Optional[str] = None) -> "Schedule":
        """Creates a schedule (`{"name", "cron", "time_zone", "template": JOB, "statistics",
        "enabled"}`: docs/manual.md "Nightly endurance runs"); a retry is safe as `submit`'s."""
        headers = {"Idempotency-Key": _idempotency_key(idempotency_key)}
        return Schedule(self, _json(self.request("POST", "/v1/schedules", json=schedule, headers=headers)))

    def schedule(self, id: str) -> "Schedule":
        """The schedule `id` as it stands now."""
        return Schedule(self, _json(self.request("GET", f"/v1/schedules/{_segment(id)}")))

    def schedules(self) -> List["Schedule"]:
        """Your schedules, oldest first."""
        found: List[Schedule] = []
        params: Dict[str, Any] = {}
        while True:
            body = _json(self.request("GET", "/v1/schedules", params=params))
            found.extend(Schedule(self, resource) for resource in body["schedules"])
            if not body.get("next_cursor"):
                return found
            params = {"cursor": body["next_cursor"]}

    def simulate(self, scenario: Optional[JSON] = None, fidelity: str = "exact") -> JSON:
        """One make operation of `scenario` (every field optional): its bounces and arc energy."""
        return _json(self.request("POST", "/v1/simulate", json=scenario or {}, params={"fidelity": fidelity}))

    def calibrate(self, request: JSON) -> JSON:
        """Scenario parameters fitted to measured operations (docs/contract.md "Calibration")."""
        return _json(self.request("POST", "/v1/calibrations", json=request))


class _Resource:
    """A resource of a server under `_collection` (`/v1/jobs`, `/v1/schedules`), as last read."""

    _collection = ""

    def __init__(self, client: Client, resource: JSON) -> None:
        self.client = client
        self.resource = resource

    @property
    def id(self) -> str:
        return str(self.resource["id"])

    def _path(self, part: str = "") -> str:
        return f"{self._collection}/{_segment(self.id)}{part}"

    def refresh(self: "_R") -> "_R":
        """Reads it again."""
        self.resource = _json(self.client.request("GET", self._path()))
        return self


_R = TypeVar("_R", bound=_Resource)


class Job(_Resource):
    """A job on a server. Its attributes are the job resource as last read; `refresh` reads it
    again, `wait` until it ends."""

    _collection = "/v1/jobs"

    def __repr__(self) -> str:
        return f"Job({self.id!r}, status={self.status!r})"

    @property
    def status(self) -> str:
        """`queued`, `running`, `succeeded`, `failed` or `cancelled`, as last read."""
        return str(self.resource["status"])

    @property
    def progress(self) -> JSON:
        """`operations_done` and `operations_total`, as last read."""
        return dict(self.resource["progress"])

    @property
    def error(self) -> Optional[str]:
        """Why it failed."""
        return self.resource.get("error")

    @property
    def waiting(self) -> Optional[str]:
        """While it runs, why its work waits, if it does (no room on the server's disk, no
        database), as last read."""
        return self.resource.get("waiting")

    def wait(self, progress: bool = True, timeout: Optional[float] = None, poll: float = 1.0) -> "Job":
        """Waits until the job ends; itself. With `progress`, a line on stderr shows how far it is.

        Each read asks the server to answer the moment the job ends (`wait_s`), or with its
        progress after `poll` seconds (10 s without `progress`). Raises `JobFailed` when it failed
        or was cancelled, and `TimeoutError` when `timeout` seconds passed first.
        """
        started = time.monotonic()
        while True:
            # At most the server's 30 s (docs/contract.md), and half the client's own timeout.
            wait_s = min(poll if progress else 10.0, MAX_WAIT_S)
            if self.client.timeout:
                wait_s = min(wait_s, self.client.timeout / 2)
            if timeout is not None:
                wait_s = min(wait_s, timeout - (time.monotonic() - started))
            asked = time.monotonic()
            deadline = None if timeout is None else started + timeout
            try:
                self.resource = _json(self.client.request(
                    "GET", self._path(), params={"wait_s": max(wait_s, 0.0)}, deadline=deadline))
            except (requests.ConnectionError, requests.exceptions.ChunkedEncodingError,
                    requests.exceptions.Timeout) as error:
                if deadline is None or time.monotonic() < deadline:
                    raise
                raise TimeoutError(f"job {self.id}: no answer from the server within {timeout} s "
                                   f"({error})") from error
            if self.status in ENDED:
                break
            if progress:
                done, total = self.progress["operations_done"], self.progress["operations_total"]
                waits = f" ({self.waiting})" if self.waiting else ""
                print(f"\r{self.id}: {self.status} {done:,}/{total:,} operations{waits}", end="", file=sys.stderr)
            # The job as read at the timeout or after: the last read waits until then.
            if timeout is not None and time.monotonic() - started >= timeout:
                if progress:
                    print(file=sys.stderr)
                raise TimeoutError(f"job {self.id} is still {self.status} after {timeout} s")
            # A server that did not wait (all its places taken) is asked again after a pause,
            # never past the timeout.
            pause = 0.2 - (time.monotonic() - asked)
            if timeout is not None:
                pause = min(pause, started + timeout - time.monotonic())
            time.sleep(max(0.0, pause))
        if progress:
            print(f"\r{self.id}: {self.status} in {time.monotonic() - started:.1f} s" + " " * 20, file=sys.stderr)
        if self.status != "succeeded":
            raise JobFailed(self)
        return self

    def result(self) -> JSON:
        """The Result (docs/contract.md "Result"); 409 until the job succeeded."""
        return _json(self.client.request("GET", self._path("/result")))

    def distribution(self, metric: str = "total_bounce_s", *, op_start: Optional[int] = None,
                     op_end: Optional[int] = None, quantiles: Optional[Iterable[float]] = None,
                     exceedance: Optional[Iterable[str]] = None) -> pd.DataFrame:
        """A metric's bins, one row each (`op_start`, `op_end`, `n`, `mean` with its interval,
        `sd`, `min`, `max`, each quantile with its interval, the exceedance of the job's limit and
        of each limit of its list, with their intervals),
        optionally in a range of operations and with quantiles (`[0.999]`) and exceedances
        (`["above:0.012"]`) answered after the run, each with its 95 % interval. The histograms
        are in the JSON answer (`Client.request`) and the plots, as is which numbers carry a
        `reason` (a quantile a decision should not rest on) or a `bucket` resolution."""
        params: Dict[str, Any] = {"format": "csv"}
        if op_start is not None:
            params["op_start"] = op_start
        if op_end is not None:
            params["op_end"] = op_end
        if quantiles is not None:
            params["quantiles"] = ",".join(repr(float(q)) for q in quantiles)
        if exceedance is not None:
            params["exceedance"] = ",".join(exceedance)
        path = self._path(f"/distributions/{_segment(metric)}")
        frame = _csv(self.client.request("GET", path, params=params))
        # Every statistic a float, whatever its values (a column of zeros reads as integers).
        counts = {"op_start", "op_end", "n"}
        for column in frame.columns:
            if column not in counts and pd.api.types.is_integer_dtype(frame[column]):
                frame[column] = frame[column].astype(float)
        return frame

    def life(self) -> pd.DataFrame:
        """Each listed device's life: `device`, `operations_to_failure` (missing for a censored
        device) and `censored`; 404 for a job without failure criteria. The server lists the
        first `--max-listed-lives` devices (docs/contract.md "Sizes"): with fewer rows than the
        job's devices (`frame.attrs["devices"]`, all that ran: a precision target's batches too), a
        `UserWarning` says so; `life_analysis` counts every device."""
        frame = _csv(self.client.request("GET", self._path("/life"), params={"format": "csv"}))
        frame["operations_to_failure"] = frame["operations_to_failure"].astype("Int64")
        frame["censored"] = frame["censored"].astype(bool)
        spec = self.resource.get("spec") or self.refresh().resource.get("spec") or {}
        devices = spec.get("devices")
        if spec.get("precision") is not None:
            # A precision target adds batches of devices: the analysis counts every one that ran.
            analysis = self.life_analysis()
            devices = analysis["failures"] + analysis["censored"]
        frame.attrs["devices"] = devices
        if devices is not None and len(frame) < devices:
            warnings.warn(f"job {self.id}: {len(frame):,} of its {devices:,} devices listed (the "
                          "server lists at most --max-listed-lives); life_analysis() counts every "
                          "device", stacklevel=2)
        return frame

    def life_analysis(self) -> JSON:
        """The life analysis: failures, censored devices, the Weibull fit with its bounds, B-lives."""
        return _json(self.client.request("GET", self._path("/life")))

    def shards(self) -> pd.DataFrame:
        """The shards the job runs as, one row each (read page by page: at most 1000 a page)."""
        shards: List[JSON] = []
        params: Dict[str, Any] = {}
        while True:
            body = _json(self.client.request("GET", self._path("/shards"), params=params))
            shards.extend(body["shards"])
            if not body.get("next_cursor"):
                frame = pd.DataFrame(shards)
                # A merge step has no group: integers with gaps, not floats; a job run whole is
                # its merge step alone, and the column is there all the same.
                frame["group"] = (frame["group"] if "group" in frame else pd.NA)
                frame["group"] = frame["group"].astype("Int64")
                return frame
            params = {"cursor": body["next_cursor"]}

    def plot(self, kind: str = "bands.svg", metric: Optional[str] = None) -> str:
        """A plot as SVG text (`bands.svg`, `histograms.svg`, `weibull.svg`, `sensitivity.svg`,
        `tail.svg`); in Jupyter, `IPython.display.SVG(job.plot())` shows it."""
        params = {"metric": metric} if metric else None
        return self.client.request("GET", self._path(f"/plots/{_segment(kind)}"), params=params).text

    def compare(self, other: "Job", metric: Optional[str] = None,
                statistics: Optional[Iterable[str]] = None,
                b_lives: Optional[Iterable[float]] = None) -> JSON:
        """This job (design a) against `other` (design b), both succeeded: per bin both share,
        each statistic (`mean`, `p01` ... `p99`, `exceedance`) with `a - b` and `a / b` and their
        95 % intervals; with failure criteria, B-lives and the probability that a device of a
        outlasts one of b (docs/contract.md "Comparing designs")."""
        params: Dict[str, Any] = {}
        if metric:
            params["metric"] = metric
        if statistics is not None:
            params["statistics"] = ",".join(statistics)
        if b_lives is not None:
            params["b_lives"] = ",".join(repr(float(p)) for p in b_lives)
        return _json(self.client.request("GET", self._path(f"/compare/{_segment(other.id)}"), params=params))

    def compare_statistics(self, other: "Job", metric: Optional[str] = None,
                           statistics: Optional[Iterable[str]] = None) -> pd.DataFrame:
        """`compare`'s statistics as a frame, one row per bin and statistic: `op_start`, `op_end`,
        `statistic`, `a`, `b`, `difference`, `difference_lo`, `difference_hi`, `ratio`, `ratio_lo`,
        `ratio_hi` (missing where there is no interval)."""
        comparison = self.compare(other, metric=metric, statistics=statistics)
        rows = []
        for b in comparison["bins"]:
            for name, d in b["statistics"].items():
                difference = d.get("difference_ci95") or [None, None]
                ratio = d.get("ratio_ci95") or [None, None]
                rows.append({"op_start": b["op_start"], "op_end": b["op_end"], "statistic": name,
                             "a": d["a"], "b": d["b"], "difference": d["difference"],
                             "difference_lo": difference[0], "difference_hi": difference[1],
                             "ratio": d.get("ratio"), "ratio_lo": ratio[0], "ratio_hi": ratio[1]})
        # The same columns and types with no bin shared (the answer's `notes` say why) and with
        # no interval anywhere: numbers are floats, a missing one NaN.
        frame = pd.DataFrame(rows, columns=_COMPARED)
        for column in _COMPARED[3:]:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype(float)
        return frame.astype({"op_start": "int64", "op_end": "int64", "statistic": object})

    def compare_plot(self, other: "Job", kind: str = "bands.svg", metric: Optional[str] = None) -> str:
        """Both jobs' `bands.svg` (wear curves) or `weibull.svg` overlaid, as SVG text."""
        params = {"metric": metric} if metric else None
        return self.client.request("GET", self._path(f"/compare/{_segment(other.id)}/plots/{_segment(kind)}"), params=params).text

    def cancel(self) -> "Job":
        """Cancels the job if it is queued or running; itself, as it stands then. A job that had
        ended is left as it is, never deleted (`POST /v1/jobs/{id}/cancel`)."""
        self.resource = _json(self.client.request("POST", self._path("/cancel")))
        return self


class Schedule(_Resource):
    """A schedule on a server: a job template run on a cron timetable. Its attributes are the
    schedule resource as last read; `refresh` reads it again."""

    _collection = "/v1/schedules"

    def __repr__(self) -> str:
        return f"Schedule({self.id!r}, {self.resource.get('cron')!r}, enabled={self.enabled!r})"

    @property
    def enabled(self) -> bool:
        return bool(self.resource["enabled"])

    @property
    def skipped_runs(self) -> int:
        """How many runs were skipped at their due time (a template the server refuses now, a key
        over its quota or no longer among the server's keys); `last_skipped` says when and why."""
        return int(self.resource.get("skipped_runs", 0))

    @property
    def last_skipped(self) -> Optional[JSON]:
        return self.resource.get("last_skipped")

    def replace(self, schedule: JSON) -> "Schedule":
        """Replaces its definition with `schedule` (a whole one, as for creation); its runs stay."""
        self.resource = _json(self.client.request("PUT", self._path(), json=schedule))
        return self

    def delete(self) -> None:
        """Deletes it; the jobs it submitted stay."""
        self.client.request("DELETE", self._path())

    def run_now(self) -> Job:
        """Runs its template now, outside its timetable; the job, queued."""
        return Job(self.client, _json(self.client.request("POST", self._path("/run"))))

    def trend(self, limit: Optional[int] = None) -> pd.DataFrame:
        """Its latest runs (60, or `limit` up to 366), oldest first, one row per run and
        statistic: `scheduled_for` (a UTC timestamp), `job_id`, `status`, `manual`, `statistic`,
        `value`, `lo`, `hi` (its 95 % interval), `drift` (it left the previous run's interval) and
        `reason` (why a decision should not rest on the value: a quantile beyond what the run's
        data bound, as its Result says); value, interval and drift missing until the run's job
        succeeded."""
        params = {"limit": limit} if limit is not None else None
        body = _json(self.client.request("GET", self._path("/runs"), params=params))
        rows = []
        for run in body["runs"]:
            for statistic in body["statistics"]:
                value = run["values"].get(statistic) or {}
                interval = value.get("ci95") or [None, None]
                rows.append({"scheduled_for": run["scheduled_for"], "job_id": run["job_id"],
                             "status": run["status"], "manual": run["manual"],
                             "statistic": statistic, "value": value.get("value"),
                             "lo": interval[0], "hi": interval[1], "drift": value.get("drift"),
                             "reason": value.get("reason")})
        columns = ["scheduled_for", "job_id", "status", "manual", "statistic", "value", "lo", "hi",
                   "drift", "reason"]
        frame = pd.DataFrame(rows, columns=columns)
        frame["scheduled_for"] = pd.to_datetime(frame["scheduled_for"], utc=True)
        for column in ("value", "lo", "hi"):
            frame[column] = frame[column].astype(float)
        frame["drift"] = frame["drift"].astype("boolean")
        return frame


# The columns of `Job.compare_statistics`.
_COMPARED = ["op_start", "op_end", "statistic", "a", "b", "difference", "difference_lo",
             "difference_hi", "ratio", "ratio_lo", "ratio_hi"]


# Every number as the server wrote it: before pandas 3, the default reader keeps about 17 decimals
# of a number written without an exponent (2.9865e-11 for 2.986509987185039e-11; 0 below 1e-17).
_EXACT_FLOATS: Dict[str, str] = (
    {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"})


def _csv(response: requests.Response) -> pd.DataFrame:
    return pd.read_csv(io.StringIO(response.text), **_EXACT_FLOATS)


