"""A study's chunks as tasks of a Dask cluster: the same result, bit for bit, a lost worker and all.

After a lost worker, the particle filter's Hellinger distance is compared to rounding
(:data:`HELLINGER_RTOL`), every other number bit for bit.

The cluster is real: a ``dask scheduler`` and two ``dask worker`` processes
on the loopback interface, started here and killed in ``finally``.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from depthcore.cli.main import main
from depthcore.studies import monte_carlo, tasks

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
#: Seconds the cluster may take to start, and a study on it to finish.
STARTUP, RUN = 60, 120

#: A small study with a deterministic and a random filter, in chunks of 8 trials.
STUDY = dict(trials=48, seed=5, chunk=8, names=("optimal", "ekf", "particle"), n_particles=150)


def _dask(*args, log):
    return subprocess.Popen(
        [sys.executable, "-m", *args], env=ENV, stdout=log, stderr=subprocess.STDOUT
    )


@contextmanager
def _cluster(tmp_path, workers=2):
    """``(address, {name: process})`` of a scheduler and ``workers`` workers on 127.0.0.1.

    All are killed on leaving, or after :data:`RUN` seconds (a study waiting on
    a cluster that hangs then fails instead of waiting for ever).
    """
    file = tmp_path / "scheduler.json"
    log = open(tmp_path / "cluster.log", "w")  # noqa: SIM115 - closed in finally
    procs = {}
    watchdog = threading.Timer(STARTUP + RUN, lambda: [p.kill() for p in procs.values()])
    watchdog.start()
    try:
        procs["scheduler"] = _dask(
            "distributed.cli.dask_scheduler",
            *("--host", "127.0.0.1", "--port", "0", "--no-dashboard"),
            *("--scheduler-file", str(file)),
            log=log,
        )
        for i in range(workers):
            procs[f"w{i}"] = _dask(
                "distributed.cli.dask_worker",
                *("--scheduler-file", str(file), "--host", "127.0.0.1", "--name", f"w{i}"),
                *("--nworkers", "1", "--nthreads", "1", "--no-nanny", "--no-dashboard"),
                *("--preload", "depthcore.studies.monte_carlo"),
                log=log,
            )
        deadline = time.monotonic() + STARTUP
        while not (file.is_file() and file.read_text().strip()):
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        yield json.loads(file.read_text())["address"], procs
    finally:
        watchdog.cancel()
        for p in procs.values():
            p.kill()
        for p in procs.values():
            p.wait(timeout=30)
        log.close()


def _same(a: dict, b: dict) -> bool:
    """Equal bit for bit: floats written with repr, NaN included."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


#: The relative gap allowed in the particle filter's Hellinger distance to the exact
#: density (a kernel density estimate over its weighted draws) between a study run in
#: process and on a cluster that reran a lost worker's chunk: it was seen to differ there
#: by 2.4e-12 in about one run of fifteen, every other number equal bit for bit.
HELLINGER_RTOL = 1e-9


def _same_but_rounding(a: dict, b: dict) -> bool:
    """:func:`_same`, but a leaf under ``hellinger_depth`` may differ by ``HELLINGER_RTOL``."""
    left, right = dict(_leaves(a)), dict(_leaves(b))
    if left.keys() != right.keys():
        return False
    for key, x in left.items():
        y = right[key]
        if repr(x) == repr(y):
            continue
        near = (
            isinstance(x, float) and isinstance(y, float) and abs(x - y) <= HELLINGER_RTOL * abs(y)
        )
        if not ("/hellinger_depth/" in key and near):
            return False
    return True


def _leaves(value, path=""):
    """``(path, leaf)`` of every number, string or None in nested dicts and lists."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, f"{path}/{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def _differences(a: dict, b: dict, shown: int = 8) -> str:
    """The first ``shown`` leaves where ``a`` and ``b`` differ, with both values, for a message."""
    left, right = dict(_leaves(a)), dict(_leaves(b))
    keys = sorted(k for k in left.keys() | right.keys() if repr(left.get(k)) != repr(right.get(k)))
    return "; ".join(f"{k}: {left.get(k)!r} vs {right.get(k)!r}" for k in keys[:shown]) + (
        f" and {len(keys) - shown} more" if len(keys) > shown else ""
    )


def test_a_study_on_a_cluster_that_loses_a_worker_equals_it_in_process(tmp_path, monkeypatch):
    from distributed import Client

    small = {**STUDY, "trials": 24, "names": ("optimal", "particle")}
    with _cluster(tmp_path) as (address, procs), Client(address, timeout=STARTUP) as client:
        here, alone = monte_carlo.study(**STUDY), monte_carlo.study(**small)  # as workers start
        client.wait_for_workers(2, timeout=STARTUP)
        names = {w["name"]: a for a, w in client.scheduler_info()["workers"].items()}
        calls, killed = [], []

        def progress(done, total):
            calls.append((done, total))
            if not killed:  # after the first chunk: kill a worker that holds a running chunk
                busy = client.processing()
                victim = max(("w0", "w1"), key=lambda n: len(busy.get(names[n], ())))
                procs[victim].kill()
                killed.append((victim, len(busy.get(names[victim], ()))))

        start = time.monotonic()
        there = monte_carlo.study(**STUDY, client=client, progress=progress)
        assert time.monotonic() - start < RUN
        # on the one worker left, the cluster named by DEPTHCORE_SCHEDULER rather than a client
        monkeypatch.setenv(tasks.SCHEDULER, address)
        try:
            named = monte_carlo.study(**small)
            assert tasks.resolve() is not None
        finally:
            tasks.disconnect()
    assert killed and killed[0][1] >= 1  # a chunk was running on the worker killed
    assert _same_but_rounding(there, here), _differences(there, here)
    assert _same_but_rounding(named, alone), _differences(named, alone)
    assert there["trials"] == STUDY["trials"]
    # each chunk counted once, as it completed: 6 chunks of 8 trials
    done = [d for d, _ in calls]
    assert len(calls) == 6 and {t for _, t in calls} == {48}
    assert done == sorted(done) and done[-1] == 48
    assert all(b - a == 8 for a, b in zip([0] + done, done, strict=False))


def _cli(*args, timeout: float = RUN) -> subprocess.CompletedProcess:
    """``python -m depthcore *args`` in a process of its own, killed after ``timeout`` s."""
    return subprocess.run(
        [sys.executable, "-m", "depthcore", *args],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


@contextmanager
def _port_taken(port: int):
    """Dask's dashboard port held by another listener (or already taken) for the duration."""
    with socket.socket() as holder:
        try:
            holder.bind(("", port))
            holder.listen()
        except OSError:
            pass  # something else holds it already
        yield


def test_the_command_line_on_two_local_workers_prints_the_same_json(capsys):
    # Dask's dashboard port 8787 taken, as by a running dashboard: the local
    # cluster's scheduler listens elsewhere, and nothing is said about it.
    study = ["study", "--trials", "40", "--filters", "ekf", "optimal", "--json"]
    assert main(study) == 0
    alone = capsys.readouterr().out
    with _port_taken(8787):
        cluster = _cli(*study, "--workers", "2")
    assert cluster.returncode == 0, cluster.stderr
    assert cluster.stdout == alone and json.loads(alone)["trials"] == 40
    assert cluster.stderr == ""


def test_without_a_cluster_nothing_of_dask_is_imported():
    code = (
        "import sys; from depthcore.cli.main import main; "
        "s = main(['study', '--trials', '3', '--filters', 'ekf', '--json']); "
        "sys.exit(10 + s if 'distributed' in sys.modules or 'dask' in sys.modules else s)"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], env=ENV, capture_output=True, text=True, timeout=RUN
    )
    assert r.returncode == 0, r.stderr


#: The refusal of a scheduler's address of the wrong form.
_FORM = "--scheduler must be a scheduler's address SCHEME://HOST:PORT (tcp|tls|ws|wss|ucx; "


@pytest.mark.parametrize(
    "args, message",
    [
        (["--workers", "0"], "--workers must be a whole number from 1 to 64, got '0'"),
        (["--workers", "-3"], "--workers must be a whole number from 1 to 64, got '-3'"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"], "--workers and --scheduler"),
        (["--workers", "x", "--scheduler", "tcp://127.0.0.1:8786"], "--workers and --scheduler"),
        (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler: no Dask scheduler answers at"),
        (["--scheduler", "tcp://[::1]:1"], "--scheduler: no Dask scheduler answers at"),
        (["--scheduler", "tls://127.0.0.1:1"], "--scheduler: no Dask scheduler answers at"),
        *(
            (["--scheduler", address], _FORM)
            for address in (
                *("", " ", "abc", "nonsense", "tcp://", "tcp://127.0.0.1", "tcp://:1"),
                *("tcp://127.0.0.1:0", "tcp://127.0.0.1:99999", "tcp://127.0.0.1:-1"),
                *("http://127.0.0.1:8786", "inproc://x", "tcp://127.0.0.1:1 tcp://127.0.0.1:2"),
            )
        ),
        (["--truth", "prior", "--prior", "fixed", "--workers", "2"], "--workers: not used by"),
    ],
)
def test_the_command_line_refuses_a_bad_cluster_in_one_line(capsys, recwarn, args, message):
    # in this process; below, in processes of their own, each class of value and of server
    start = time.monotonic()
    assert main(["study", "--trials", "3", *args]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err.startswith(f"python -m depthcore study: error: {message}"), err
    assert "Traceback" not in err and "Warning" not in err and not recwarn.list
    assert time.monotonic() - start < 2 * tasks.CONNECT_TIMEOUT


#: Seconds within which the command line answers any value of --workers or --scheduler, its
#: start included: a value of the wrong form at once (1-2 s), an address within
#: tasks.CONNECT_TIMEOUT for the scheduler's answer and as many again for its first worker.
#: A guard against a hang, generous for a loaded machine; not a measure.
ANSWER = 30


@contextmanager
def _refusing():
    """The address of a port on 127.0.0.1 bound but not listening: it refuses a connection."""
    with socket.socket() as bound:
        bound.bind(("127.0.0.1", 0))
        yield f"tcp://127.0.0.1:{bound.getsockname()[1]}"


@contextmanager
def _silent():
    """The address of a TCP server on 127.0.0.1 that accepts connections and never answers."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)  # the system accepts; nothing reads or writes
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"


@contextmanager
def _http():
    """The address of an HTTP server on 127.0.0.1 (as a dashboard's port), answering 4xx."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Quiet(BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


@contextmanager
def _idle(tmp_path):
    """The address of a real scheduler on 127.0.0.1 without any worker."""
    with _cluster(tmp_path, workers=0) as (address, _):
        yield address


@contextmanager
def _worker(tmp_path):
    """The address of a real worker (a Dask server, but no scheduler) on 127.0.0.1."""
    from distributed import Client

    with _cluster(tmp_path, workers=1) as (address, _), Client(address, timeout=STARTUP) as c:
        c.wait_for_workers(1, timeout=STARTUP)
        yield next(iter(c.scheduler_info()["workers"]))


_SERVERS = {"refusing": _refusing, "silent": _silent, "http": _http}
_SCHEDULERS = {"idle": _idle, "worker": _worker}


def _answer(*args) -> tuple[subprocess.CompletedProcess, float]:
    """``study`` of 3 trials with ``args`` in a process of its own, and its seconds."""
    start = time.monotonic()
    result = _cli("study", "--trials", "3", "--filters", "ekf", *args, timeout=2 * ANSWER)
    return result, time.monotonic() - start


def _one_refusal(result, seconds: float, message: str, address: str = "") -> None:
    """Exit status 2, one line naming the argument (and ``address``), nothing else, in time.

    In time: within :data:`ANSWER` seconds.
    """
    both = result.stdout + result.stderr
    assert result.returncode == 2, both
    assert result.stdout == "" and result.stderr.count("\n") == 1, both
    assert result.stderr.startswith(f"python -m depthcore study: error: {message}"), both
    assert not address or repr(address) in result.stderr, both
    assert "Traceback" not in both and "Warning" not in both
    assert seconds < ANSWER, seconds


@pytest.mark.parametrize(
    "args, message",
    [
        (["--workers", "10000"], "--workers must be a whole number from 1 to 64, got '10000'"),
        (["--workers", "1.5"], "--workers must be a whole number from 1 to 64, got '1.5'"),
        (["--workers", ""], "--workers must be a whole number from 1 to 64, got ''"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers and --scheduler"),
        (["--scheduler", ""], _FORM),
        (["--scheduler", "http://127.0.0.1:8786"], _FORM),
    ],
    ids=["out-of-range", "not-whole", "empty", "both", "no-address", "not-dask"],
)
def test_a_process_answers_a_bad_value_in_one_line_within_seconds(args, message):
    _one_refusal(*_answer(*args), message)


@pytest.mark.parametrize(
    "kind, message",
    [
        ("refusing", "--scheduler: no Dask scheduler answers at"),
        ("silent", "--scheduler: no Dask scheduler answered at"),
        ("http", "--scheduler: no Dask scheduler answer"),  # it closes, or keeps silent
        ("idle", "--scheduler: the Dask scheduler at"),
        ("worker", "--scheduler: no Dask scheduler answers at"),
    ],
)
def test_a_process_refuses_a_server_that_is_no_scheduler_with_a_worker(tmp_path, kind, message):
    # each server on 127.0.0.1 for the test's duration; Dask's own timeouts would wait for ever
    # on the silent one (dask/distributed#8071) and on the idle scheduler's missing workers
    server = _SERVERS[kind]() if kind in _SERVERS else _SCHEDULERS[kind](tmp_path)
    with server as address:
        result, seconds = _answer("--scheduler", address)
    _one_refusal(result, seconds, message, address)


def test_the_command_line_on_a_running_scheduler_named_localhost_prints_the_same_json(
    tmp_path, capsys
):
    from distributed import Client

    study = ["study", "--trials", "40", "--filters", "ekf", "optimal", "--json"]
    assert main(study) == 0
    alone = capsys.readouterr().out
    with _cluster(tmp_path, workers=1) as (address, _), Client(address, timeout=STARTUP) as c:
        c.wait_for_workers(1, timeout=STARTUP)
        named = address.replace("tcp://127.0.0.1:", "tcp://localhost:")
        result = _cli(*study, "--scheduler", named, timeout=RUN)
    assert result.returncode == 0, result.stderr
    assert result.stdout == alone and json.loads(alone)["trials"] == 40
    assert result.stderr == ""


def test_chunks_are_folded_in_order_and_counted_once():
    folded, ticks = [], []
    n = tasks.fold_chunks(
        lambda x: x * x,
        iter(range(5)),
        lambda k, r: folded.append((k, r)),
        sizes=[3, 3, 3, 3, 1],
        total=13,
        progress=lambda d, t: ticks.append((d, t)),
    )
    assert n == 5 and folded == [(k, k * k) for k in range(5)]
    assert ticks == [(3, 13), (6, 13), (9, 13), (12, 13), (13, 13)]
    assert [s.spawn_key for s in tasks.chunk_seeds(7, 3)] == [(0,), (1,), (2,)]


def _encoded(result) -> str:
    """A study's result as its record writes it: arrays and floats exactly."""
    from depthbook.provenance import records

    return json.dumps(records.encode(result), sort_keys=True)


def test_the_books_other_studies_on_two_local_workers_equal_them_in_process():
    from depthbook import beyond_bound, beyond_frames, beyond_particles
    from depthcore.problem.scenarios import SCENARIOS

    fig2 = SCENARIOS["fig2"]
    calls = [
        (
            beyond_bound.bound_study,
            ([3, 5], 8, 1, ("optimal", "ekf", "particle", "rbpf")),
            {"particle_trials": 4, "n_particles": 50},
        ),
        (monte_carlo.prior_study, (), {"trials": 300, "seed": 2}),
        (beyond_particles.particle_convergence, (fig2, [20, 40], 3, 1), {}),
        (beyond_particles.resample_move_runs, (fig2, 50, 3, 1), {"moves": 2}),
        (
            beyond_frames.track_marginals,
            (3, 6, [3, 6], ("optimal", "ekf", "particle")),
            {"n_points": 21},
        ),
    ]
    here = [_encoded(f(*a, **k)) for f, a, k in calls]
    with tasks.cluster(workers=2) as client:
        there = [_encoded(f(*a, **k, client=client)) for f, a, k in calls]
        environ = client.run(_worker_environ)  # each worker's, by its address
    for (f, _, _), a, b in zip(calls, here, there, strict=True):
        assert a == b, f.__name__
    # the workers keep freed memory up to tasks.WORKER_ENVIRON's threshold, not Dask's 64 KiB
    assert len(environ) == 2
    assert all(e == tasks.WORKER_ENVIRON for e in environ.values()), environ


def _worker_environ() -> dict:
    """The variables of :data:`depthcore.studies.tasks.WORKER_ENVIRON` in this process."""
    return {k: os.environ.get(k) for k in tasks.WORKER_ENVIRON}


def test_only_the_hellinger_distance_may_differ_and_only_by_rounding():
    base = {"filters": {"particle": {"hellinger_depth": {"mean": 0.112}, "rmse": 0.5}}}
    near = json.loads(json.dumps(base))
    near["filters"]["particle"]["hellinger_depth"]["mean"] *= 1 + 1e-12
    assert _same_but_rounding(near, base) and not _same(near, base)
    far = json.loads(json.dumps(base))
    far["filters"]["particle"]["hellinger_depth"]["mean"] *= 1 + 1e-6
    elsewhere = json.loads(json.dumps(base))
    elsewhere["filters"]["particle"]["rmse"] *= 1 + 1e-12
    missing = {"filters": {"particle": {"rmse": 0.5}}}
    for other in (far, elsewhere, missing):
        assert not _same_but_rounding(other, base)
