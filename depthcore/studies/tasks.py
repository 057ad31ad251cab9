"""A study's chunks of trials as tasks: in this process, or on a Dask cluster.

Recommended import: ``from depthcore.studies import tasks``.

:func:`fold_chunks` is where every study of :mod:`depthcore.studies` maps its
chunks: it runs ``task(item)`` for each chunk's inputs and folds the results
into the study's running sums **in chunk order**, whatever order they finish
in. A chunk's inputs carry everything it draws from (its trials, drawn in
order by the study, or its own seed, a child of the study's seed by chunk
index, :func:`chunk_seeds`), so a chunk's result does not depend on where,
when or how often it runs, and the study's result is the same, bit for bit,
in one process or on any number of workers.

Where the chunks run (:func:`resolve`):

* ``client=None`` and no :data:`SCHEDULER` in the environment: one after the
  other in this process, importing nothing of Dask;
* ``client``, a ``distributed.Client``: as tasks of its cluster's
  scheduler, at most :func:`window` of them submitted ahead of the next
  chunk to fold, so that the memory held stays that of a few chunks. A
  worker lost mid-study has its chunks run again by the scheduler; each
  chunk is folded and counted once, by its index;
* the environment variable :data:`SCHEDULER` set to a scheduler's address
  (``tcp://host:8786``) and no ``client``: on that cluster, through Dask's
  default client (``distributed.default_client``), made once per process
  (how ``make records`` runs the book's studies on every core).

From the command line: ``python -m depthcore study --workers 4`` starts a local
cluster of four processes for the study, ``--scheduler tcp://host:8786`` uses a
running one (``dask scheduler`` and ``dask worker tcp://host:8786`` start one;
its workers must import the same depthcore).
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import sys
import threading
import traceback
from collections.abc import Callable, Iterable

import numpy as np

from depthcore.problem import checks

#: The environment variable naming a scheduler's address that studies run on when given no client.
SCHEDULER = "DEPTHCORE_SCHEDULER"

#: Most worker processes :func:`cluster` starts.
MAX_WORKERS = 64

#: Seconds to wait for a scheduler named by address to answer before refusing it, and as
#: many again for its first worker.
CONNECT_TIMEOUT = 5.0

#: The environment each worker process of :func:`local_cluster` starts with. Dask's default
#: returns freed memory to the system from 64 KiB on (``MALLOC_TRIM_THRESHOLD_``), so that
#: each large NumPy temporary of a chunk is mapped and zeroed afresh by the system; at 64 MiB
#: a worker keeps at most that much freed memory for reuse. Set it too for the workers of a
#: cluster started by hand (``dask worker``).
WORKER_ENVIRON = {
    "MALLOC_TRIM_THRESHOLD_": str(64 << 20),
    "MALLOC_MMAP_THRESHOLD_": str(64 << 20),
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
}


def chunk_seeds(seed, n: int) -> list[np.random.SeedSequence]:
    """The seeds of ``n`` chunks: the children ``0 .. n - 1`` of ``seed``, by chunk index.

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence
    n : int
        Number of chunks, >= 0.

    Returns
    -------
    list of numpy.random.SeedSequence, length n
        Chunk ``k``'s seed is the same whatever ``n`` (``seed``'s child ``k``).
    """
    return checks.spawn(seed, n)


def connect(
    address: str, timeout: float = CONNECT_TIMEOUT, name: str = "scheduler", default: bool = False
):
    """A ``distributed.Client`` of the scheduler at ``address``, which has a worker.

    Parameters
    ----------
    address : str
        A scheduler's address, ``tcp://host:8786`` (or ``host:8786``).
    timeout : float
        Seconds to wait for the scheduler's answer, and as many again for its first worker.
    name : str
        The argument a refusal names.
    default : bool
        Make the client Dask's default client (``distributed.default_client``).

    Returns
    -------
    distributed.Client
        The caller closes it.

    Raises
    ------
    ValueError
        Naming ``name`` when ``address`` is not an address, when no Dask
        scheduler answers there within ``timeout`` seconds, or when it has
        no worker after as many again.

    Notes
    -----
    A closed port (nothing listens) is refused at once. The client is
    ``distributed.Client(address, timeout=timeout)``, made in a thread of its
    own and waited for ``timeout`` seconds more: Dask's ``timeout`` does not
    bound its handshake, so a server that accepts and never answers would
    hold the caller for ever (dask/distributed#8071). Its first worker is
    ``client.wait_for_workers(1, timeout=timeout)``.
    """
    address, where = _address(address, name)
    _quiet()
    try:
        socket.create_connection(where, timeout=timeout).close()
        client = _client(address, timeout, default)
    except TimeoutError:
        raise ValueError(
            f"{name}: no Dask scheduler answered at {address!r} within {timeout:g} s"
        ) from None
    except Exception as exc:  # noqa: BLE001 - whatever answers, or not, is one refusal
        reason = _one_line(exc) or type(exc).__name__
        raise ValueError(f"{name}: no Dask scheduler answers at {address!r} ({reason})") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except TimeoutError:
        client.close()
        raise ValueError(
            f"{name}: the Dask scheduler at {address!r} has no worker (none joined within "
            f"{timeout:g} s; dask worker {address} starts one)"
        ) from None
    return client


def _client(address: str, timeout: float, default: bool):
    """``distributed.Client(address, timeout=timeout)``, or TimeoutError after twice ``timeout``.

    The client is made in a daemon thread, so that a server that never answers
    holds that thread only.
    """
    from distributed import Client

    made: list = []

    def make():
        try:
            made.append(Client(address, timeout=timeout, set_as_default=default))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            for frame, _ in traceback.walk_tb(exc.__traceback__):
                half = frame.f_locals.get("self")
                if isinstance(half, Client):  # made, not connected: closed here, not at exit
                    half.close(timeout=timeout)
                    break
            made.append(exc)

    thread = threading.Thread(target=make, name="depthcore-connect", daemon=True)
    thread.start()
    thread.join(2 * timeout)
    if not made:
        raise TimeoutError(address)
    if isinstance(made[0], BaseException):
        raise made[0]
    return made[0]


def _one_line(exc) -> str:
    return " ".join(str(exc).split())[:160]


#: The schemes of Dask's addresses that name a host and a port.
_NETWORK = ("tcp", "tls", "ws", "wss", "ucx")


def _address(address, name: str) -> tuple[str, tuple[str, int]]:
    """``address`` without surrounding blanks, and its host and port, if it is an address.

    Parameters
    ----------
    address : str
        ``scheme://host:port`` (a scheme of :data:`_NETWORK`) or ``host:port``
        (``tcp``), the port 1 to 65535.
    name : str
        The argument a refusal names.

    Returns
    -------
    address : str
    where : tuple of (str, int)
        The host and the port.

    Raises
    ------
    ValueError
        Naming ``name`` when ``address`` is not a string of that form.
    """
    shape = f"a scheduler's address SCHEME://HOST:PORT ({'|'.join(_NETWORK)}; 1 to 65535)"
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"{name} must be {shape}, got {address!r}")
    from distributed.comm import parse_address, parse_host_port

    address = address.strip()
    try:
        scheme, location = parse_address(address)
        host, port = parse_host_port(location) if scheme in _NETWORK else ("", 0)
    except ValueError as exc:
        raise ValueError(f"{name} must be {shape}, got {address!r} ({_one_line(exc)})") from None
    if not host or not 1 <= port <= 65535:
        raise ValueError(f"{name} must be {shape}, got {address!r}")
    return address, (host, port)


def _quiet() -> None:
    """Keep Dask's log messages below errors off stderr: a study prints nothing."""
    logging.getLogger("distributed").setLevel(logging.ERROR)


@contextlib.contextmanager
def cluster(workers: int | None = None, scheduler: str | None = None):
    """A client for a study's chunks, closed on leaving: the context of ``client=``.

    Parameters
    ----------
    workers : int, optional
        Start a local cluster of ``workers`` processes (1 to :data:`MAX_WORKERS`) of one thread each
        (``distributed.LocalCluster``, no dashboard), closed on leaving.
    scheduler : str, optional
        The address of a running scheduler (``tcp://host:8786``) to connect to
        (:func:`connect`: it must answer within :data:`CONNECT_TIMEOUT` seconds,
        and have a worker within as many again).

    Yields
    ------
    distributed.Client or None
        None when neither is given: the chunks run in this process, and
        nothing of Dask is imported.

    Raises
    ------
    ValueError
        Naming ``workers`` (not an integer from 1 to :data:`MAX_WORKERS`, or
        given with ``scheduler``) or ``scheduler`` (see :func:`connect`).
    """
    if workers is not None and scheduler is not None:
        raise ValueError("workers: give workers or a scheduler, not both")
    if workers is None and scheduler is None:
        yield None
        return
    if scheduler is not None:
        client = connect(scheduler)
        try:
            yield client
        finally:
            client.close()
        return
    from distributed import Client

    with local_cluster(workers) as local, Client(local, set_as_default=False) as client:
        yield client


def local_cluster(workers: int, host: str | None = None):
    """A ``distributed.LocalCluster`` of ``workers`` processes of one thread, no dashboard.

    Each worker process starts with :data:`WORKER_ENVIRON`. The scheduler's
    HTTP server (health checks; no dashboard) listens on a free port, not
    Dask's 8787, so that a dashboard or another cluster already on that port
    is no obstacle. Use it as a context manager; :func:`cluster` gives a
    client of one.

    Parameters
    ----------
    workers : int
        1 to :data:`MAX_WORKERS`.
    host : str, optional
        The interface the scheduler and workers listen on (``"127.0.0.1"``).

    Raises
    ------
    ValueError
        Naming ``workers`` when it is not an integer from 1 to :data:`MAX_WORKERS`.
    """
    if isinstance(workers, bool) or not (
        isinstance(workers, (int, np.integer)) and 1 <= workers <= MAX_WORKERS
    ):
        raise ValueError(f"workers must be a whole number from 1 to {MAX_WORKERS}, got {workers!r}")
    import dask
    from distributed import LocalCluster

    _quiet()
    with dask.config.set({"distributed.nanny.pre-spawn-environ": WORKER_ENVIRON}):
        return LocalCluster(
            n_workers=int(workers),
            threads_per_worker=1,
            processes=True,
            host=host,
            dashboard_address=None,
            scheduler_kwargs={"dashboard_address": f"{host or ''}:0"},
            silence_logs=logging.ERROR,
        )


def resolve(client=None):
    """The client chunks run on: ``client``, else :data:`SCHEDULER`'s, else None (this process).

    :data:`SCHEDULER`'s client is Dask's default client
    (``distributed.default_client()``) when it is of that scheduler, else a new
    one (:func:`connect`), made the default.
    """
    if client is not None:
        return client
    address = os.environ.get(SCHEDULER, "").strip()
    if not address:
        return None
    current = _current(address)
    if current is not None:
        return current
    return connect(address, name=SCHEDULER, default=True)


def disconnect() -> None:
    """Close Dask's default client if it is :data:`SCHEDULER`'s, made by :func:`resolve`."""
    address = os.environ.get(SCHEDULER, "").strip()
    if not address or "distributed" not in sys.modules:
        return
    current = _current(address)
    if current is not None:
        current.close()


def _current(address: str):
    """Dask's default client if it is running and of the scheduler at ``address``, else None."""
    from distributed import default_client
    from distributed.comm import resolve_address

    try:
        current = default_client()
        same = current.scheduler.address == resolve_address(address)
    except ValueError:  # no default client, or not an address (connect refuses it)
        return None
    return current if same and current.status == "running" else None


def window(client) -> int:
    """Chunks submitted ahead of the next one to fold: twice the cluster's threads, at least 2."""
    return max(2, 2 * sum(client.nthreads().values()))


def fold_chunks(
    task: Callable,
    items: Iterable,
    fold: Callable[[int, object], None],
    sizes: Iterable[int] | None = None,
    total: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    client=None,
) -> int:
    """Run ``task(item)`` for each chunk's ``item`` and fold the results in chunk order.

    Parameters
    ----------
    task : callable
        ``task(item) -> result``, a module-level function (pickled by name
        for a cluster's workers), deterministic given ``item``.
    items : iterable
        Each chunk's inputs, in chunk order; read lazily, as chunks are
        submitted (one at a time in this process).
    fold : callable
        ``fold(k, result)``, called for ``k = 0, 1, ...`` in that order, once per chunk.
    sizes : iterable of int, optional
        The trials of each chunk, in chunk order, for ``progress``; default 1 each.
    total : int, optional
        What ``progress`` counts up to; default the number of chunks.
    progress : callable, optional
        ``progress(done, total)`` as each chunk completes (in any order on a
        cluster), ``done`` the trials of the chunks completed so far.
    client : distributed.Client, optional
        Run the chunks as tasks of its scheduler (see :func:`resolve`).

    Returns
    -------
    int
        Number of chunks.
    """
    items = iter(items)
    sizes = None if sizes is None else iter(sizes)
    client = resolve(client)
    done = 0

    def tick(size):
        nonlocal done
        done += size
        if progress is not None:
            progress(done, done if total is None else total)

    if client is None:
        k = 0
        for k, item in enumerate(items, start=1):
            fold(k - 1, task(item))
            tick(1 if sizes is None else next(sizes))
        return k
    return _fold_on(client, task, items, fold, sizes, tick)


def _fold_on(client, task, items, fold, sizes, tick) -> int:
    """:func:`fold_chunks` on a cluster: a window of futures, folded by index."""
    from distributed import as_completed

    ahead, token = window(client), _token()
    pending, size_of, results = {}, {}, {}
    submitted = folded = 0
    exhausted = False
    completed = as_completed(loop=client.loop)

    def submit_more():
        nonlocal submitted, exhausted
        while not exhausted and submitted < folded + ahead:
            try:
                item = next(items)
            except StopIteration:
                exhausted = True
                return
            key = f"depthcore-chunk-{token}-{submitted}"
            pending[key] = (submitted, client.submit(task, item, pure=False, key=key))
            size_of[submitted] = 1 if sizes is None else next(sizes)
            completed.add(pending[key][1])
            submitted += 1

    try:
        submit_more()
        while folded < submitted:
            future = next(completed)
            if future.key not in pending:
                continue  # a chunk counts once, however often it ran
            k, _ = pending.pop(future.key)
            results[k] = future.result()
            future.release()
            tick(size_of.pop(k))
            while folded in results:
                fold(folded, results.pop(folded))
                folded += 1
            submit_more()
    finally:
        for _, future in pending.values():
            future.cancel()
    return submitted


def _token() -> str:
    """A fresh hex token, so that two studies' chunks never share a task key."""
    return os.urandom(8).hex()
