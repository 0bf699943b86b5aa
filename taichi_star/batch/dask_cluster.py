"""Chunks as Dask tasks (`pip install "taichi_star[dask]"`).

A worker runs one whole chunk (a Taichi batch) per task and sends its tables back; the client
writes them to the run store, so resuming works across distributed runs, and a worker lost
mid-chunk costs only that chunk: the scheduler reruns it elsewhere. Workers are started with
``--nthreads 1 --preload taichi_star.batch.dask_worker`` (see there); without the preload, the
`TaichiWorkerSetup` plugin that `DaskExecutor` registers configures them the same way.
"""

from __future__ import annotations

import contextlib
import logging
import re
import threading
import time
import urllib.parse
import uuid
from typing import Iterator, Sequence

from distributed import Client, LocalCluster, get_worker, wait
from distributed.diagnostics.plugin import WorkerPlugin

from ..checks import is_real
from .executors import DEFAULT_RETRIES, configure_worker_process
from .tasks import ChunkResult, ChunkTask, run_chunk

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["DaskExecutor", "ADDRESS", "check_address", "local_executor"]

ADDRESS = re.compile(r"^[a-z][a-z0-9+.-]*://\S+$", re.IGNORECASE)
"""A scheduler address such as tcp://HOST:PORT."""


def check_address(address: str) -> str:
    """`address` stripped, if it is a scheduler address (`ADDRESS`) whose port, where it gives
    one, is in 1..65535; ValueError naming the scheduler otherwise, before any connection (a
    port of 99999 waited 31 s for a timeout: an audit, 2026-12)."""
    address = address.strip()
    if not ADDRESS.match(address):
        raise ValueError(f"scheduler: expected an address like tcp://HOST:PORT, got {address!r}")
    try:
        port = urllib.parse.urlsplit(address).port
    except ValueError:
        port = 0
    if port is not None and not 1 <= port <= 65535:
        raise ValueError(f"scheduler: the port of {address!r} must be in 1..65535")
    return address


def prepare_worker(worker, arch=None, cpu_threads: int = 1):
    """Configure a Dask worker process once: its Taichi runtime (CPU threads, quiet logs), the
    arch its chunks run on (None: the client's) and a lock so that it runs one Taichi batch at a
    time even when started with several threads. Kept on the worker object."""
    if getattr(worker, "taichi_star_lock", None) is not None:
        return
    import taichi as ti

    from ..runtime import Runtime
    if cpu_threads == 1:
        configure_worker_process()
    else:
        Runtime.current().configure(cpu_threads=cpu_threads, log_level=ti.ERROR)
    worker.taichi_star_arch = arch
    worker.taichi_star_lock = threading.Lock()


class TaichiWorkerSetup(WorkerPlugin):
    """Configures every worker of the cluster (current and future, restarted ones included)
    that was not started with the preload."""

    name = "taichi_star-setup"
    idempotent = True

    def setup(self, worker):
        prepare_worker(worker)


def run_on_worker(task: ChunkTask) -> ChunkResult:
    """Run one chunk on this Dask worker, on the worker's own arch when it was started with
    one."""
    worker = get_worker()
    prepare_worker(worker)
    if worker.taichi_star_arch is not None:
        task = task.on(worker.taichi_star_arch)
    with worker.taichi_star_lock:
        return run_chunk(task)


NO_WORKERS_TIMEOUT_S = 120.0
"""How long a run waits, s, on a cluster that has no worker left (time for a nanny or an
autoscaler to bring one back) before it stops with an error."""
POLL_S = 2.0
"""How often a run waiting for its chunks checks that the cluster still has workers, s."""


class DaskExecutor:
    """Runs the chunks as Dask tasks on `client`'s cluster; results arrive as they complete. A
    chunk whose worker dies is rerun by the scheduler; one that raises is retried `retries`
    times, then its error is raised here (the chunks stored before stay stored). A cluster left
    without any worker for `no_workers_timeout_s` seconds stops the run with a RuntimeError
    (the chunks stored before stay stored: resume once the cluster has workers again)."""

    def __init__(self, client: Client, retries: int = DEFAULT_RETRIES,
                 no_workers_timeout_s: float = NO_WORKERS_TIMEOUT_S):
        if not is_real(no_workers_timeout_s) or not no_workers_timeout_s > 0:
            raise ValueError(f"no_workers_timeout_s must be a number > 0, got "
                             f"{no_workers_timeout_s!r}")
        self.client = client
        self.retries = retries
        self.no_workers_timeout_s = float(no_workers_timeout_s)
        client.register_plugin(TaichiWorkerSetup())

    def _workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    @property
    def n_workers(self) -> int:
        return max(1, self._workers())

    def run(self, tasks: Sequence[ChunkTask], progress: bool = False) -> Iterator[ChunkResult]:
        run = uuid.uuid4().hex[:12]
        futures = [self.client.submit(run_on_worker, task, retries=self.retries, pure=False,
                                      key=f"taichi_star-chunk-{task.index}-{run}")
                   for task in tasks]
        pending = set(futures)
        alone_since = None
        try:
            while pending:
                try:
                    done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
                except TimeoutError:  # none finished within POLL_S
                    done = set()
                for future in done:
                    yield future.result()
                if done or self._workers() > 0:
                    alone_since = None
                    continue
                alone_since = time.monotonic() if alone_since is None else alone_since
                if time.monotonic() - alone_since >= self.no_workers_timeout_s:
                    raise RuntimeError(
                        f"the Dask cluster at {self.client.scheduler.address} has had no "
                        f"worker for {self.no_workers_timeout_s:g} s with {len(pending)} "
                        f"chunk(s) unfinished; stopping (chunks already stored are kept: "
                        f"resume once it has workers)")
        finally:
            for future in futures:
                future.cancel()


@contextlib.contextmanager
def local_executor(n_workers: int, retries: int = DEFAULT_RETRIES, silence_logs=logging.ERROR):
    """A DaskExecutor on a fresh loopback LocalCluster of `n_workers` single-threaded worker
    processes, closed on exit."""
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                      host="127.0.0.1", dashboard_address=None, silence_logs=silence_logs) \
            as cluster, Client(cluster) as client:
        yield DaskExecutor(client, retries)


@contextlib.contextmanager
def remote_executor(address: str, retries: int = DEFAULT_RETRIES, timeout: float = 30):
    """A DaskExecutor on the existing cluster whose scheduler listens at `address`. ValueError
    for a malformed or unreachable address."""
    address = check_address(address)
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError) as error:
        raise ValueError(f"scheduler: cannot reach {address}: {error}") from None
    try:
        yield DaskExecutor(client, retries)
    finally:
        client.close()
