"""Studies on Dask distributed: chunks of instances as Dask tasks.

`--workers N` starts a local cluster of N single-threaded worker processes (each its own Taichi
runtime capped at one CPU thread, so N workers use N cores without oversubscribing);
`--scheduler tcp://HOST:PORT` uses an existing cluster (workers started with
``dask worker tcp://HOST:PORT --nthreads 1 --preload studies.dask_worker [--arch gpu]``).
Without either flag a study runs in process as before.

The unit of work is one chunk of `studies.common.plan_chunks`: a worker runs a whole Taichi
batch (`studies.common.run_chunk`) and returns its tables; the client writes each chunk's summary
through the run folder's atomic chunk files (`studies.runs`), so `--resume` works across
distributed runs, and a worker lost mid-chunk costs only that chunk: the scheduler reruns it
elsewhere (`--retries` more tries for a chunk whose task raises).

From Python::

    from studies.common import param_product, run_batch
    from studies.distributed import local_executor
    with local_executor(2) as executor:
        summary = run_batch(param_product({"alpha": [0.4, 0.8]}), executor=executor,
                            chunk_size=1).summary
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import threading
import uuid

from .common import StudyArgumentError

DEFAULT_RETRIES = 2
ADDRESS = re.compile(r"^[a-z][a-z0-9+.-]*://\S+$", re.IGNORECASE)

_task_lock = threading.Lock()
"""One Taichi batch at a time per worker process (a worker started with several threads would
otherwise run two batches in one Taichi runtime)."""


def add_arguments(parser):
    """--workers / --scheduler / --retries (and --run-dir / --resume where `resumable`)."""
    group = parser.add_argument_group("distributed (Dask)")
    group.add_argument("--workers", type=int, default=None, metavar="N",
                       help="run the chunks on a local Dask cluster of N single-threaded worker "
                            "processes (default: in this process)")
    group.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run the chunks on an existing Dask cluster (see the README)")
    group.add_argument("--retries", type=int, default=DEFAULT_RETRIES,
                       help=f"extra tries for a chunk whose task fails (default "
                            f"{DEFAULT_RETRIES}); a chunk whose worker dies is rerun anyway")
    return group


def validate(args):
    """Check the distributed flags before any compute (StudyArgumentError naming the flag)."""
    if args.workers is not None and args.scheduler is not None:
        raise StudyArgumentError("--workers and --scheduler: give one (a local cluster or an "
                                 "existing one), not both")
    if args.workers is not None and args.workers < 1:
        raise StudyArgumentError(f"--workers must be >= 1, got {args.workers}")
    if args.scheduler is not None and not ADDRESS.match(args.scheduler.strip()):
        raise StudyArgumentError(f"--scheduler: expected an address like tcp://HOST:PORT, got "
                                 f"{args.scheduler!r}")
    if args.retries < 0:
        raise StudyArgumentError(f"--retries must be >= 0, got {args.retries}")
    if args.workers is not None or args.scheduler is not None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            flag = "--workers" if args.workers is not None else "--scheduler"
            raise StudyArgumentError(f"{flag} needs Dask: pip install 'dask[distributed]'") \
                from None


def configure_worker_process(cpu_threads=None):
    """Cap this process's Taichi runtime at `cpu_threads` CPU threads (default: the worker's
    `--taichi-threads` from `studies.dask_worker`, else 1), if Taichi is not started yet (the
    cap is applied by `ti.init`, at the first `simulate`)."""
    from taichi_star import simulation
    import taichi as ti
    if cpu_threads is None:
        cpu_threads = _preloaded("WORKER_THREADS") or 1
    if simulation._runtime["arch"] is None:
        simulation._runtime.update(cpu_threads=cpu_threads, log_level=ti.ERROR)


def _preloaded(name):
    try:
        from . import dask_worker
    except ImportError:  # click missing: the preload cannot have run either
        return None
    return getattr(dask_worker, name)


def _worker_arch(requested: str) -> str:
    return _preloaded("WORKER_ARCH") or requested


def run_on_worker(function, *task):
    """Run one task on a Dask worker: Taichi capped at one CPU thread, one batch at a time per
    process, and for `studies.common.run_chunk` the worker's own arch when the worker was
    started with `--preload studies.dask_worker --arch ...`."""
    from . import common
    configure_worker_process()
    if function is common.run_chunk:
        task = list(task)
        task[4] = _worker_arch(task[4])  # run_chunk's arch argument
    with _task_lock:
        return function(*task)


try:
    from distributed.diagnostics.plugin import WorkerPlugin as _PluginBase
except ImportError:  # Dask not installed: only the in-process path is available
    _PluginBase = object


class TaichiWorkerSetup(_PluginBase):
    """Dask worker plugin: caps Taichi at one CPU thread in every worker process (current and
    future, restarted ones included) before its first simulation."""
    name = "taichi_star-setup"
    idempotent = True

    def setup(self, worker):
        configure_worker_process()


class DaskExecutor:
    """Runs chunks as Dask tasks on `client`'s cluster; results arrive as they complete."""

    def __init__(self, client, retries: int = DEFAULT_RETRIES):
        self.client = client
        self.retries = retries
        if hasattr(client, "register_plugin"):
            client.register_plugin(TaichiWorkerSetup())
        else:  # distributed < 2023.9
            client.register_worker_plugin(TaichiWorkerSetup())

    @property
    def n_workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def map(self, function, tasks):
        """Yield (task index, result) as tasks complete. A task whose worker dies is rerun by
        the scheduler; one that raises is retried `retries` times, then its error is raised
        here (the chunks finished before stay written)."""
        from distributed import as_completed
        futures = {}
        run = uuid.uuid4().hex[:12]
        for index, task in enumerate(tasks):
            future = self.client.submit(run_on_worker, function, *task, retries=self.retries, pure=False,
                                        key=f"taichi_star-chunk-{index}-{run}")
            futures[future] = index
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()


@contextlib.contextmanager
def local_executor(n_workers: int, retries: int = DEFAULT_RETRIES, silence_logs=logging.ERROR):
    """A DaskExecutor on a fresh loopback LocalCluster of `n_workers` single-threaded worker
    processes; the cluster is closed on exit."""
    from distributed import Client, LocalCluster
    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None, silence_logs=silence_logs)
    try:
        with Client(cluster) as client:
            yield DaskExecutor(client, retries)
    finally:
        cluster.close()


@contextlib.contextmanager
def remote_executor(address: str, retries: int = DEFAULT_RETRIES, timeout: float = 30):
    """A DaskExecutor on the existing cluster whose scheduler listens at `address`."""
    from distributed import Client
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError) as error:
        raise StudyArgumentError(f"--scheduler: cannot reach {address}: {error}") from None
    try:
        yield DaskExecutor(client, retries)
    finally:
        client.close()


@contextlib.contextmanager
def executor_for(args):
    """The executor the flags ask for: InProcess (neither flag), a local cluster (--workers N)
    or an existing one (--scheduler ADDRESS). Call `validate(args)` first."""
    from .common import InProcess
    if args.workers is not None:
        with local_executor(args.workers, args.retries) as executor:
            yield executor
    elif args.scheduler is not None:
        with remote_executor(args.scheduler.strip(), args.retries) as executor:
            yield executor
    else:
        yield InProcess()


def default_chunk_size(args, n_instances: int, n_workers: int, cpu_default: int = 2048,
                       gpu_default: int = 16384) -> int:
    """--chunk-size if given, else the arch's default, cut down so that every worker gets about
    four chunks (one chunk is one task: fewer chunks than workers leaves workers idle)."""
    if args.chunk_size is not None:
        if args.chunk_size < 1:
            raise StudyArgumentError(f"--chunk-size must be >= 1, got {args.chunk_size}")
        return args.chunk_size
    size = gpu_default if args.arch == "gpu" else cpu_default
    if n_workers > 1:
        size = min(size, max(1, math.ceil(n_instances / (4 * n_workers))))
    return size


def planned_workers(args) -> int:
    """Workers a run will have, as far as known before the cluster starts (for chunk sizes):
    --workers N, else 1 (for --scheduler the executor's n_workers is used)."""
    return args.workers or 1
