"""The client against a live `bouncewear serve` at BOUNCEWEAR_URL (CI starts one), and the
binary at BOUNCEWEAR_BIN for the local Result to compare with."""

import contextlib
import datetime
import email.utils
import json
import os
import select
import subprocess
import threading
import time

import pandas as pd
import pytest
import requests

from bouncewear import BouncewearError, Client, Job, JobFailed

BASE = os.environ.get("BOUNCEWEAR_URL", "http://127.0.0.1:8080")
BIN = os.environ.get("BOUNCEWEAR_BIN", "bouncewear")

WEARING = {
    "devices": 40, "operations": 300, "seed": 11,
    "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
    "scatter": [{"parameter": "contact_radius_m", "per": "device",
                 "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}}],
    "failure": {"e1": {"below": 0.36}},
}


@pytest.fixture(scope="module")
def client():
    return Client(BASE)


@pytest.fixture(scope="module")
def job(client):
    return client.submit(WEARING).wait(progress=False)


def test_a_waited_job_has_the_result_run_gives(job, tmp_path):
    assert job.status == "succeeded"
    assert job.progress == {"operations_done": 12000, "operations_total": 12000}
    path = tmp_path / "job.json"
    path.write_text(json.dumps(WEARING))
    local = json.loads(subprocess.run([BIN, "run", "-q", str(path)], check=True, capture_output=True).stdout)
    served = job.result()
    assert served["operations"] == local["operations"]
    assert served["devices"] == local["devices"]
    assert served["life"] == local["life"]


def test_a_distribution_is_a_frame_of_its_bins(job):
    frame = job.distribution("total_bounce_s")
    assert list(frame.columns[:4]) == ["op_start", "op_end", "n", "mean"]
    assert len(frame) == 10
    assert frame["n"].sum() == 12000
    assert (frame["op_end"] - frame["op_start"] == 30).all()
    asked = job.distribution("total_bounce_s", op_start=0, op_end=30, quantiles=[0.5],
                             exceedance=["above:0.011"])
    assert len(asked) == 1
    assert {"q0.5", "q0.5_ci95_lo", "q0.5_ci95_hi"} <= set(asked.columns)
    assert asked["q0.5_ci95_lo"][0] <= asked["q0.5"][0] <= asked["q0.5_ci95_hi"][0]
    # A threshold no value passes: its probability and interval's low end are 0, still floats.
    beyond = job.distribution("total_bounce_s", exceedance=["above:1"])
    assert (beyond["above:1"] == 0).all()
    assert all(beyond[c].dtype == float for c in beyond.columns if c not in ("op_start", "op_end", "n"))


def test_lives_are_a_frame_with_censored_devices_missing_a_failure(job):
    lives = job.life()
    analysis = job.life_analysis()
    assert len(lives) == 40
    assert lives["censored"].sum() == analysis["censored"]
    assert lives.loc[lives["censored"], "operations_to_failure"].isna().all()
    failed = lives.loc[~lives["censored"], "operations_to_failure"]
    assert failed.notna().all() and (failed <= 300).all()
    assert analysis["analysis"]["weibull"]["beta"] > 0


def test_lives_cut_at_the_servers_listing_say_so(tmp_path):
    """A server listing 5 lives gave 5 rows of a 12-device job without a word (found from
    outside): the frame keeps the job's devices and a warning says how many are listed."""
    with _idle_server(tmp_path, "--max-listed-lives", "5", workers="1") as url:
        cut = Client(url).submit(dict(WEARING, devices=12, operations=20)).wait(progress=False)
        with pytest.warns(UserWarning, match="5 of its 12 devices listed"):
            lives = Client(url).job(cut.id).life()
        assert len(lives) == 5 and lives.attrs["devices"] == 12
        analysis = cut.life_analysis()
        assert analysis["failures"] + analysis["censored"] == 12


def test_a_long_poll_asks_no_more_than_the_server_waits(job):
    """`wait_s` is at most 30 s whatever the client's timeout and `poll` (it asked 45 and got 400)."""
    patient = Client(BASE, timeout=120)
    again = patient.job(job.id).wait(progress=True, poll=45)
    assert again.status == "succeeded"


def test_jobs_list_and_read_again(client, job):
    assert job.id in [j.id for j in client.jobs(limit=50)]
    again = client.job(job.id)
    assert again.status == "succeeded"
    assert again.resource["spec"]["seed"] == 11
    assert isinstance(job.shards(), pd.DataFrame)
    assert job.plot("weibull.svg").lstrip().startswith("<svg")


def test_cancelling_an_ended_job_leaves_it_as_it_is(client):
    ended = client.submit({"devices": 4, "operations": 10, "seed": 3}).wait(progress=False)
    assert ended.cancel().status == "succeeded"
    assert client.job(ended.id).status == "succeeded"
    assert ended.result()["job"]["seed"] == 3


def test_a_base_url_the_paths_cannot_follow_is_refused_naming_the_rule():
    # As the command line's --url: a query swallowed the paths (the dashboard's HTML came back as
    # a JSONDecodeError), and no scheme left `requests` without an adapter.
    for url, rule in [("http://127.0.0.1:8080/?x=1", "no query or fragment"),
                      ("http://127.0.0.1:8080#top", "no query or fragment"),
                      ("localhost:8080", "no scheme"), ("ftp://h/", "http or https"),
                      ("http://", "no host"), ("http://h:0", "from 1 to 65535"),
                      ("http://h:99999", "not a URL"),
                      ("http://me:secret@h:1/?x", "no query")]:
        with pytest.raises(ValueError, match=rule) as refused:
            Client(url)
        assert "secret" not in str(refused.value)
    for url in ["http://127.0.0.1:8080", "https://example.com/prefix/", "http://[::1]:8080"]:
        assert Client(url).base_url == url.rstrip("/")


def test_a_refused_job_names_its_fields(client):
    with pytest.raises(BouncewearError) as refused:
        client.submit({"devices": 0, "operations": 0})
    assert refused.value.status == 422
    assert refused.value.pointers == ["/devices", "/operations"]
    # Each field's rule once: the server's detail names them (they were listed twice).
    told = str(refused.value)
    assert "/devices" in told
    assert all(told.count(f"{e.pointer}: {e.detail}") == 1 for e in refused.value.errors), told


def test_unknown_jobs_and_results_before_success_are_errors(client):
    with pytest.raises(BouncewearError) as missing:
        client.job("no-such-job")
    assert missing.value.status == 404
    queued = client.submit({"devices": 20000, "operations": 2000, "seed": 1})
    queued.cancel()
    assert queued.status == "cancelled"
    with pytest.raises(JobFailed) as failed:
        queued.wait(progress=False)
    assert failed.value.job.status == "cancelled"
    with pytest.raises(BouncewearError) as early:
        queued.result()
    assert early.value.status == 409


def test_simulate_gives_one_operation(client):
    operation = client.simulate({"circuit": {"supply_voltage_v": 48, "current_a": 15}})
    assert operation["bounce_count"] == 2
    assert abs(operation["first_bounce_s"] - 0.008613068539770941) < 1e-15


def test_a_job_compared_with_itself_shows_no_difference(job):
    comparison = job.compare(job, statistics=["mean", "p50"], b_lives=[0.1])
    assert comparison["a"] == comparison["b"] == job.id
    assert comparison["life"]["b_lives"][0]["ratio"] == 1.0
    assert abs(comparison["life"]["outlasts"]["weibull"] - 0.5) < 1e-12
    frame = job.compare_statistics(job, statistics=["mean"])
    assert len(frame) == 10
    assert (frame["difference"] == 0).all()
    assert (frame["difference_lo"] < 0).all() and (frame["difference_hi"] > 0).all()
    assert job.compare_plot(job, "weibull.svg").startswith("<svg")
    with pytest.raises(BouncewearError) as refused:
        job.compare(job, statistics=["median"])
    assert refused.value.status == 400


def _answer(status, body, headers=None):
    """An answer as `requests` gives it, for what a proxy in front of the server may send."""
    response = requests.Response()
    response.status_code = status
    response.reason = "Service Unavailable" if status == 503 else "Error"
    response._content = body.encode()
    response.headers.update(headers or {})
    return response


def test_any_failed_answer_is_a_bouncewear_error_with_its_text_and_wait():
    later = email.utils.format_datetime(
        datetime.datetime.now(datetime.timezone.utc) + datetime.timedelta(seconds=120), usegmt=True
    )
    dated = BouncewearError.from_response(_answer(503, "<html>busy</html>", {"Retry-After": later}))
    assert dated.status == 503 and dated.detail == "<html>busy</html>"
    assert 100 < dated.retry_after <= 120
    listed = BouncewearError.from_response(_answer(500, '["oops"]', {"Retry-After": "soon"}))
    assert (listed.detail, listed.errors, listed.retry_after) == ('["oops"]', [], None)
    odd = BouncewearError.from_response(_answer(422, '{"detail": "bad", "errors": [1, {"pointer": "/a", "detail": "x"}]}'))
    assert odd.pointers == ["/a"]
    assert BouncewearError.from_response(_answer(429, "{}", {"Retry-After": "5"})).retry_after == 5.0


def test_an_id_with_a_slash_reaches_no_other_resource(client, job):
    with pytest.raises(BouncewearError) as unknown:
        client.job(f"{job.id}/life")
    assert unknown.value.status == 404
    # A metric's or a plot's name is one segment too: it read e1's bins, and added queries.
    for metric in ("total_bounce_s/../e1", "../result", "total_bounce_s?op_start=0"):
        with pytest.raises(BouncewearError) as unknown:
            job.distribution(metric)
        assert unknown.value.status == 404, metric
    with pytest.raises(BouncewearError) as unknown:
        job.plot("../result")
    assert unknown.value.status == 404


def test_comparisons_keep_their_columns_and_types_with_no_bin_or_interval(client, job):
    """Found from outside: no shared bin gave a frame without columns, and no interval anywhere
    columns of None."""
    apart = client.submit({"devices": 4, "operations": 10, "seed": 3}).wait(progress=False)
    empty = job.compare_statistics(apart)
    assert len(empty) == 0
    assert list(empty.columns) == ["op_start", "op_end", "statistic", "a", "b", "difference",
                                   "difference_lo", "difference_hi", "ratio", "ratio_lo",
                                   "ratio_hi"]
    # Four values a bin bound neither end's quantile: no interval, nor a ratio's.
    same = apart.compare_statistics(apart, statistics=["p01", "p99"])
    assert len(same) == 20
    assert all(same[c].dtype == float for c in same.columns[3:])
    assert (same["difference_hi"] - same["difference_lo"]).isna().all()


def test_a_job_run_whole_has_its_shards_group_column(client):
    small = client.submit({"devices": 4, "operations": 10, "seed": 4}).wait(progress=False)
    shards = small.shards()
    assert len(shards) == 1 and "group" in shards
    assert shards["group"].isna().all() and str(shards["group"].dtype) == "Int64"


def test_an_idempotency_key_the_server_would_refuse_is_refused_here(client):
    for key in ("", "\u20ac", "a b", "x" * 256):
        with pytest.raises(ValueError, match="idempotency_key"):
            client.submit({"devices": 1, "operations": 1}, idempotency_key=key)


def test_a_frame_holds_every_number_as_the_json_gives_it(client):
    """A tiny metric (eroded mass, about 1e-11 kg) is written in the CSV without an exponent; read
    at pandas' default precision it kept 5 digits of its sd."""
    tiny = client.submit({"devices": 30, "operations": 1, "seed": 5,
                          "scenario": {"circuit": {"supply_voltage_v": 24, "current_a": 1}},
                          "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                                       "distribution": {"kind": "uniform", "min": 0.2, "max": 0.6}}],
                          "metrics": ["eroded_mass_kg"]}).wait(progress=False)
    served = tiny.result()["devices"]["eroded_mass_kg"]
    frame = tiny.distribution("eroded_mass_kg")
    for column in ("mean", "sd", "min", "max"):
        assert frame[column].iloc[0] == served[column], column
    assert 0 < served["sd"] < 1e-9


def test_a_key_no_header_can_carry_is_refused_without_repeating_it():
    for key in ("", " k1", "k1 ", "k1\n", "k\u20ac"):
        with pytest.raises(ValueError, match="api_key") as refused:
            Client(api_key=key)
        assert key.strip() == "" or key.strip() not in str(refused.value)
    for timeout in (0, -1.0):
        with pytest.raises(ValueError, match="timeout"):
            Client(timeout=timeout)
    with pytest.raises(ValueError, match="limit"):
        Client("http://127.0.0.1:1").jobs(limit=-1)


def _notes(caplog):
    """The retry notes the client logged, each's end: "again in S s (N of M)"."""
    return [record.getMessage().split("; ")[-1] for record in caplog.records
            if record.name == "bouncewear"]


@contextlib.contextmanager
def _idle_server(tmp_path, *flags, workers="0"):
    """A server of its own that runs no job (or `workers` at once), with `flags`; its URL."""
    server = subprocess.Popen(
        [BIN, "serve", "--bind", "127.0.0.1:0", "--workers", workers, *flags,
         "--database", f"sqlite://{tmp_path}/queue.db"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        ready, _, _ = select.select([server.stdout], [], [], 60)
        assert ready, "the server did not start within a minute"
        yield server.stdout.readline().split()[-1]  # "bouncewear listening on URL"
    finally:
        server.terminate()
        server.wait()


def test_a_wait_that_times_out_says_the_job_is_still_queued(tmp_path):
    """The last read's answer is awaited a little past the timeout: asked to wait all the time left,
    the server answered after the read's deadline, and each wait of 1-3 s said "no answer from the
    server"."""
    with _idle_server(tmp_path) as url:
        job = Client(url).submit({"devices": 2, "operations": 2})
        for timeout in [0.5, 1.0, 1.0, 2.0]:
            with pytest.raises(TimeoutError) as waited:
                job.wait(progress=False, timeout=timeout)
            assert str(waited.value) == f"job {job.id} is still queued after {timeout} s"
        # A job that ends just before the timeout is told as it ended: with the last read asked
        # to answer a quarter second early, one that ended then was told as still queued.
        cancel = threading.Timer(0.85, lambda: Client(url).job(job.id).cancel())
        cancel.start()
        with pytest.raises(JobFailed):
            job.wait(progress=False, timeout=1.0)
        cancel.join()
        assert job.status == "cancelled"


def test_a_submission_to_a_full_queue_is_sent_again_once_there_is_room(tmp_path, caplog):
    """A server of its own whose queue holds one job and runs none: the second submission's 429 is
    waited out (its Retry-After, 5 s) and the job queued once the first is cancelled."""
    with _idle_server(tmp_path, "--max-queued", "1") as url:
        small = {"devices": 2, "operations": 2}
        first = Client(url).submit(small)
        with pytest.raises(BouncewearError) as full:
            Client(url, retries=0).submit(small)
        assert full.value.status == 429 and full.value.retry_after == 5.0
        # Cancelled from a client of its own once the submission below has had its 429.
        canceller = Client(url)

        def cancel_when_waiting():
            given_up = time.monotonic() + 30
            while not _notes(caplog) and time.monotonic() < given_up:
                time.sleep(0.05)
            canceller.job(first.id).cancel()

        cancel = threading.Thread(target=cancel_when_waiting)
        cancel.start()
        second = Client(url).submit(small)
        cancel.join()
        assert _notes(caplog) == ["again in 5.0 s (1 of 3)"]
        assert second.status == "queued" and second.id != first.id
        assert sorted(job.status for job in Client(url).jobs()) == ["cancelled", "queued"]


def test_a_server_that_cannot_be_reached_is_tried_again_then_raises(caplog):
    client = Client("http://127.0.0.1:1", retries=2)
    with pytest.raises(requests.ConnectionError):
        client.job("any")
    assert _notes(caplog) == ["again in 0.5 s (1 of 2)", "again in 1.0 s (2 of 2)"]


def test_what_may_not_be_repeated_is_sent_once_and_wait_keeps_its_timeout(caplog):
    client = Client("http://127.0.0.1:1")
    # A second purge would delete the job the first only cancelled; a POST without a key the
    # server honours could act twice.
    with pytest.raises(requests.ConnectionError):
        client.request("DELETE", "/v1/jobs/any", params={"purge": "true"})
    with pytest.raises(requests.ConnectionError):
        client.request("POST", "/v1/schedules/any/run", headers={"Idempotency-Key": "k"})
    assert _notes(caplog) == []
    # After 0.5 s, a pause of 1 s would end past the wait's timeout of 1 s.
    job = Job(client, {"id": "any", "status": "queued"})
    with pytest.raises(requests.ConnectionError):
        job.wait(progress=False, timeout=1.0)
    assert _notes(caplog) == ["again in 0.5 s (1 of 3)"]
    with pytest.raises(ValueError):
        Client(retries=-1)


def _listening():
    """A socket that accepts connections and never answers; its URL and the socket."""
    import socket
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(16)
    return f"http://127.0.0.1:{silent.getsockname()[1]}", silent


def test_wait_ends_at_its_timeout_against_a_server_that_never_answers():
    url, silent = _listening()
    try:
        started = time.monotonic()
        with pytest.raises(TimeoutError):
            Job(Client(url, timeout=120), {"id": "any", "status": "queued"}).wait(progress=False, timeout=1.0)
        # Its own timeout bounds it, not a request's 120 s (a generous margin for a busy host).
        assert time.monotonic() - started < 60
    finally:
        silent.close()


def _holding_first_answer(base):
    """A proxy to `base` that hands the first request on and holds its answer back; later
    connections it relays both ways. Its URL."""
    import socket
    host, port = base.split("//")[1].rsplit(":", 1)
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    held = []

    def relay(source, sink):
        try:
            while data := source.recv(65536):
                sink.sendall(data)
        except OSError:
            pass

    def serve():
        first = True
        while True:
            client, _ = listener.accept()
            upstream = socket.create_connection((host, int(port)))
            if first:
                first = False
                request = b""
                while b"\r\n\r\n" not in request:
                    request += client.recv(65536)
                head, body = request.split(b"\r\n\r\n", 1)
                length = next(int(line.split(b":")[1]) for line in head.split(b"\r\n")
                              if line.lower().startswith(b"content-length:"))
                while len(body) < length:
                    body += client.recv(65536)
                upstream.sendall(head + b"\r\n\r\n" + body)
                upstream.recv(1)  # the server answered: the job is queued
                held.append(client)
                continue
            for source, sink in ((client, upstream), (upstream, client)):
                threading.Thread(target=relay, args=(source, sink), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return f"http://127.0.0.1:{listener.getsockname()[1]}"


def test_a_submission_answered_too_late_is_sent_again_and_queues_one_job(caplog):
    proxy = _holding_first_answer(BASE)
    before = {job.id for job in Client(BASE).jobs()}
    submitted = Client(proxy, timeout=2).submit({"devices": 2, "operations": 2})
    assert len(_notes(caplog)) == 1
    new = [job.id for job in Client(BASE).jobs() if job.id not in before]
    assert new == [submitted.id]


def test_a_failed_job_crosses_a_process_boundary():
    import pickle
    failed = JobFailed(Job(Client(BASE), {"id": "j-1", "status": "failed", "error": "why"}))
    again = pickle.loads(pickle.dumps(failed))
    assert str(again) == str(failed) and again.job.id == "j-1"


def test_a_refusal_crosses_a_process_boundary(client):
    import pickle
    from concurrent.futures import ProcessPoolExecutor
    with pytest.raises(BouncewearError) as refused:
        client.submit({"devices": 0})
    again = pickle.loads(pickle.dumps(refused.value))
    assert (again.status, again.pointers, str(again)) == (422, ["/devices"], str(refused.value))
    # Raised in a worker process, it reaches the caller whole (it broke the pool before). Forked,
    # so that the worker finds this module's function whatever the Python's default start method.
    import multiprocessing
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        with pytest.raises(BouncewearError) as remote:
            pool.submit(_submit_nothing, BASE).result()
    assert (remote.value.status, remote.value.pointers) == (422, ["/devices"])


def _submit_nothing(base):
    Client(base).submit({"devices": 0})


def test_the_other_job_of_a_comparison_reaches_no_other_resource(client, job):
    with pytest.raises(BouncewearError) as unknown:
        job.compare(Job(client, {"id": f"{job.id}?metric=e1", "status": "succeeded"}))
    assert unknown.value.status == 404


TLS = os.path.join(os.path.dirname(__file__), "..", "..", "..", "tests", "data", "tls")


def _terminating(backend):
    """A TLS terminator in front of the server at `backend` (as a deployment puts one), with the
    test CA's certificate for localhost (tests/data/tls): its https URL and listening socket."""
    import socket
    import ssl
    host, port = backend.removeprefix("http://").rsplit(":", 1)
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(os.path.join(TLS, "localhost.pem"), os.path.join(TLS, "localhost.key"))
    listening = socket.socket()
    listening.bind(("127.0.0.1", 0))
    listening.listen(16)

    def pump(source, sink):
        try:
            while data := source.recv(65536):
                sink.sendall(data)
        except OSError:
            pass
        finally:
            for end in (source, sink):
                try:
                    end.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def serve():
        while True:
            try:
                raw, _ = listening.accept()
            except OSError:
                return
            try:
                client = context.wrap_socket(raw, server_side=True)
            except (OSError, ssl.SSLError):
                raw.close()  # a client that did not trust the certificate
                continue
            server = socket.create_connection((host, int(port)))
            threading.Thread(target=pump, args=(client, server), daemon=True).start()
            threading.Thread(target=pump, args=(server, client), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return f"https://localhost:{listening.getsockname()[1]}", listening


def test_https_trusts_the_ca_it_is_told_and_refuses_others_at_once(job, monkeypatch, caplog):
    url, listening = _terminating(BASE)
    try:
        ca = os.path.join(TLS, "ca.pem")
        assert Client(url, ca_cert=ca).job(job.id).status == "succeeded"
        monkeypatch.setenv("BOUNCEWEAR_CA_CERT", ca)
        assert Client(url).job(job.id).status == "succeeded"
        monkeypatch.delenv("BOUNCEWEAR_CA_CERT")
        with pytest.raises(requests.exceptions.SSLError):
            Client(url).job(job.id)
        assert _notes(caplog) == []
        with pytest.raises(ValueError):
            Client(url, ca_cert=os.path.join(TLS, "missing.pem"))
    finally:
        listening.close()


def test_a_schedule_runs_now_and_its_trend_is_a_frame(client):
    spec = {"name": "py nightly", "cron": "0 3 * * *", "time_zone": "Europe/Berlin",
            "template": {"devices": 20, "operations": 50, "seed": 3},
            "statistics": ["operations.total_bounce_s.p95", "operations.total_bounce_s.mean"]}
    schedule = client.create_schedule(spec)
    assert schedule.enabled and schedule.skipped_runs == 0 and schedule.last_skipped is None
    assert schedule.id in [s.id for s in client.schedules()]
    assert client.schedule(schedule.id).resource["name"] == "py nightly"
    runs = [schedule.run_now().wait(progress=False) for _ in range(2)]
    trend = schedule.trend()
    assert list(trend["job_id"]) == [run.id for run in runs for _ in spec["statistics"]]
    assert list(trend["statistic"]) == spec["statistics"] * 2
    assert str(trend["scheduled_for"].dt.tz) == "UTC" and trend["manual"].all()
    # The template's seed gives each run the same numbers: no drift, each inside its interval.
    p95 = trend[trend["statistic"] == "operations.total_bounce_s.p95"]
    assert p95["value"].iloc[0] == p95["value"].iloc[1] > 0
    assert ((trend["lo"] <= trend["value"]) & (trend["value"] <= trend["hi"])).all()
    assert not trend["drift"].any()
    # The trend's p95 is the Result's last bin's.
    last = runs[0].distribution("total_bounce_s").iloc[-1]
    assert p95["value"].iloc[0] == last["p95"]
    assert len(schedule.trend(limit=1)) == len(spec["statistics"])
    schedule.replace(dict(spec, enabled=False))
    assert not schedule.enabled and schedule.resource["next_run_at"] is None
    schedule.delete()
    with pytest.raises(BouncewearError) as missing:
        client.schedule(schedule.id)
    assert missing.value.status == 404


def test_a_page_that_is_not_json_is_an_error_naming_the_request():
    """A sign-in page answered with 200 raised a bare `JSONDecodeError` (found from outside)."""
    import http.server

    class SignIn(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            body = b"<html>please sign in</html>"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    portal = http.server.ThreadingHTTPServer(("127.0.0.1", 0), SignIn)
    threading.Thread(target=portal.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{portal.server_address[1]}"
        with pytest.raises(BouncewearError) as page:
            Client(url).job("abc")
        assert page.value.status == 200 and page.value.title == "Not JSON"
        assert page.value.detail.startswith(f"GET {url}/v1/jobs/abc answered 200 with text/html")
        assert "please sign in" in page.value.detail
    finally:
        portal.shutdown()


def test_a_number_json_cannot_carry_is_refused_naming_its_field(client):
    """NaN raised `requests`' "Out of range float values are not JSON compliant", naming no field."""
    spec = {"devices": 2, "scenario": {"circuit": {"current_a": float("nan")}},
            "scatter": [{"distribution": {"max": float("inf")}}]}
    with pytest.raises(ValueError, match=r"^/scenario/circuit/current_a: NaN and infinities"):
        client.submit(spec)
    del spec["scenario"]
    with pytest.raises(ValueError, match=r"^/scatter/0/distribution/max: "):
        client.submit(spec)


def test_lives_of_a_job_grown_by_its_precision_target_count_every_device(tmp_path):
    """The warning and `attrs["devices"]` read the devices asked for, 16, where 32 ran (found
    from outside)."""
    grown = dict(WEARING, devices=16, operations=20,
                 precision={"metric": "total_bounce_s", "statistic": "mean",
                            "relative_half_width": 1e-9, "max_devices": 32})
    with _idle_server(tmp_path, "--max-listed-lives", "20", workers="1") as url:
        job = Client(url).submit(grown).wait(progress=False)
        with pytest.warns(UserWarning, match="20 of its 32 devices listed"):
            lives = job.life()
        assert len(lives) == 20 and lives.attrs["devices"] == 32


def test_a_trend_keeps_the_reason_a_value_carries(client):
    """A p99 of 8 devices is beyond what they bound: the HTTP runs said why, the frame dropped it
    (found from outside)."""
    template = dict(WEARING, devices=8, operations=20, seed=5)
    del template["failure"]
    schedule = client.create_schedule({
        "name": "py reason", "cron": "0 3 * * *", "template": template,
        "statistics": ["operations.total_bounce_s.p99", "operations.total_bounce_s.mean"]})
    try:
        schedule.run_now().wait(progress=False)
        trend = schedule.trend()
        assert list(trend.columns)[-1] == "reason"
        reasons = dict(zip(trend["statistic"], trend["reason"]))
        assert reasons["operations.total_bounce_s.p99"].startswith("beyond the data")
        assert pd.isna(reasons["operations.total_bounce_s.mean"])
    finally:
        schedule.delete()
