"""Where the chunks of a batch run: one protocol, three executors.

- `InProcess`: one chunk after the other in this process (the default; no worker processes, so
  scripts need no `if __name__ == "__main__":` guard).
- `LocalProcesses(n)`: n worker processes on this machine ("spawn" start method), each a
  single-threaded Taichi runtime: on CPUs where Taichi's own threads scale poorly, processes use
  the cores. `--workers N` of every study means this.
- `DaskExecutor` (`taichi_star.batch.dask_cluster`): the chunks as tasks of a Dask cluster.

An executor runs `run_chunk` on every task and yields the `ChunkResult`s as they complete (in any
order; `ChunkResult.index` says which chunk).
"""

from __future__ import annotations

import ast
import atexit
import concurrent.futures
import multiprocessing
import os
import sys
import threading
import time
from collections import deque
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Deque, Dict, Iterator, List, Optional, Protocol, Sequence, Tuple

from ..checks import is_whole
from .tasks import ChunkResult, ChunkTask, run_chunk

DEFAULT_RETRIES = 2
"""Extra tries of a chunk. With `LocalProcesses`: after the worker process running it alone
died (a chunk that raises is not retried there: its error is deterministic). On a Dask cluster:
after its task raised (`DaskExecutor`; a worker's death is the scheduler's to rerun)."""
MAX_RETRIES = 100
"""Most extra tries of a chunk (`check_retries`): a chunk that kills its worker at every try is
given up after them, not tried again without end (an audit, 2026-12: `--retries 1000000000`
was taken)."""
MAX_LOCAL_WORKERS = 256
"""The most local worker processes: each is a process with a single-threaded Taichi runtime
(some 200 MB), so more than one per core only competes for the cores; 256 is 16 times the most
cores the committed results ran on (10**6 started processes until memory ran out; more: a
Dask cluster)."""


class Executor(Protocol):
    """Runs chunk tasks somewhere and yields their results as they complete. Where `run` is a
    generator (as every executor here), `run_batch` closes it on an error or an interrupt before
    its end: that should stop the chunks still running."""

    n_workers: int

    def run(self, tasks: Sequence[ChunkTask], progress: bool = False) -> Iterator[ChunkResult]:
        ...


class InProcess:
    """Runs the chunks one after the other in this process."""

    n_workers = 1

    def run(self, tasks: Sequence[ChunkTask], progress: bool = False) -> Iterator[ChunkResult]:
        for task in tasks:
            yield run_chunk(task, progress=progress)


def configure_worker_process(parent_pid: Optional[int] = None):
    """Initialiser of a worker process: Taichi capped at one CPU thread, quiet logs (the cap
    takes effect at the worker's first simulation); with `parent_pid`, the worker ends with
    that process (`end_with_parent`)."""
    import taichi as ti

    from ..runtime import Runtime
    if parent_pid is not None:
        end_with_parent(parent_pid)
    Runtime.current().configure(cpu_threads=1, log_level=ti.ERROR)


PARENT_POLL_S = 1.0
"""How often a worker looks whether its parent still lives (s)."""


def end_with_parent(parent_pid: int):
    """Make this process end when process `parent_pid`, its parent, does: a pool's workers
    outlived a main process killed with SIGKILL (or by the OOM killer), each finishing its chunk
    for nobody and then waiting for ever, competing with the resumed run for the cores (an
    audit, 2026-12: 58 left after 30 kills). A daemon thread polls every `PARENT_POLL_S`; it
    runs between kernel launches, so a worker in a chunk ends within a launch. (Linux's
    PR_SET_PDEATHSIG would be immediate, but it fires when the *thread* that started the
    worker ends, which a pool used from a short-lived thread would take for its death.)"""
    def watch():
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)
    threading.Thread(target=watch, name="end-with-parent", daemon=True).start()


def _is_main_test(test: ast.expr) -> bool:
    """`__name__ == "__main__"` (either order)."""
    if not (isinstance(test, ast.Compare) and len(test.ops) == 1
            and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = [test.left, test.comparators[0]]
    names = [s.id for s in sides if isinstance(s, ast.Name)]
    texts = [s.value for s in sides if isinstance(s, ast.Constant)]
    return names == ["__name__"] and texts == ["__main__"]


def check_main_guard():
    """RuntimeError unless worker processes can be started from this program: a "spawn" worker
    re-imports the main script, so a script without an `if __name__ == "__main__":` guard would
    run its own top-level code (and start a pool) again in every worker. Interactive sessions and
    notebooks have no main script and need no guard."""
    path = getattr(sys.modules.get("__main__"), "__file__", None)
    if path is None or not str(path).endswith(".py") or not Path(path).is_file():
        return
    try:
        tree = ast.parse(Path(path).read_text())
    except (OSError, SyntaxError, ValueError):
        return
    if not any(isinstance(node, ast.If) and _is_main_test(node.test) for node in tree.body):
        raise RuntimeError(
            f"worker processes re-import the main script {path}, which has no "
            f"'if __name__ == \"__main__\":' guard, so its top-level code would run again in "
            f"every worker: put the code that runs the batch under that guard, or run in this "
            f"process (workers=None)")


def _stop_now(pool: concurrent.futures.ProcessPoolExecutor):
    """Stop `pool`'s worker processes now, busy or not, and wait until they have exited.
    ProcessPoolExecutor stops busy workers only from Python 3.14 (terminate_workers): its own
    processes, terminated, are found dead by its manager thread, which fails their futures and
    joins them; shutdown(wait=True) waits for that thread alone."""
    for process in list((pool._processes or {}).values()):  # None once shut down
        process.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def check_retries(retries):
    """ValueError naming `retries` unless it is an integer from 0 to MAX_RETRIES."""
    if not is_whole(retries) or not 0 <= retries <= MAX_RETRIES:
        raise ValueError(f"retries must be an integer from 0 to {MAX_RETRIES} (MAX_RETRIES), "
                         f"got {retries!r}")


class LocalProcesses:
    """`n_workers` worker processes on this machine, started on first use with the "spawn" start
    method (a fresh interpreter: no Taichi state is inherited), each configured by
    `configure_worker_process`. A worker that dies breaks the whole pool, which cannot tell
    whose chunk killed it, so the rest of the run goes on isolated: `n_workers` pools of one
    worker each, one chunk at a time, where a death is its chunk's alone. A chunk whose worker
    died there more than `retries` times is given up: the others run to the end (kept in a
    run_dir), then a RuntimeError names it. With `retries` 0 the first death stops the run, as
    no chunk may be tried again. (Until 2026-12 the deaths counted for the whole run: three on
    three chunks, or one chunk that always killed its worker, stopped it, naming no chunk: an
    audit.) Shut down by `shutdown`, at the end of a `with` block, or at interpreter exit;
    stopped at once by `terminate`, which an error or an interrupt during `run` or in the
    `with` block calls."""

    chunk_function = staticmethod(run_chunk)
    """What a worker runs on each task (`tasks.run_chunk`): a module-level function, which a
    worker imports by name. Tests put one there that kills its worker."""

    def __init__(self, n_workers: int, retries: int = DEFAULT_RETRIES):
        if not is_whole(n_workers) or not 1 <= n_workers <= MAX_LOCAL_WORKERS:
            raise ValueError(f"workers must be an integer from 1 to {MAX_LOCAL_WORKERS} "
                             f"(MAX_LOCAL_WORKERS), got {n_workers!r}")
        check_retries(retries)
        self.n_workers = int(n_workers)
        self.retries = int(retries)
        self._pool: Optional[concurrent.futures.ProcessPoolExecutor] = None
        """The shared pool of `n_workers` workers."""
        self._isolated: List[Optional[concurrent.futures.ProcessPoolExecutor]] = []
        """After a death, the pools of one worker each (None where none runs)."""
        self._started = False
        """Whether a pool has started (its workers imported the main script)."""

    def _new_pool(self, n_workers: int) -> concurrent.futures.ProcessPoolExecutor:
        """A pool of `n_workers` spawned workers; the first pool of this executor is tried
        with a task that does nothing before any chunk runs. Stopped at once if that try
        fails or is interrupted (a Ctrl-C there left a worker running)."""
        check_main_guard()
        pool = concurrent.futures.ProcessPoolExecutor(
            n_workers, mp_context=multiprocessing.get_context("spawn"),
            initializer=configure_worker_process, initargs=(os.getpid(),))
        # a worker re-imports the main script: where that fails (code after the guard that
        # needs what the guard made), every worker dies at once, and the retries blamed
        # memory (an audit); a task that does nothing tells that apart before any chunk runs,
        # once (a restart after a worker died has imported the script before)
        if self._started:
            return pool
        try:
            pool.submit(int).result()
            self._started = True
        except BaseException as error:
            _stop_now(pool)
            if not isinstance(error, BrokenProcessPool):
                raise
            path = getattr(sys.modules.get("__main__"), "__file__", "the main script")
            raise RuntimeError(f"worker processes could not start: each re-imports {path}, and "
                               f"that failed (a worker's traceback is above); its code outside "
                               f"the 'if __name__ == \"__main__\":' guard must run in a fresh "
                               f"process") from None
        return pool

    def run(self, tasks: Sequence[ChunkTask], progress: bool = False) -> Iterator[ChunkResult]:
        pending = {task.index: task for task in tasks}
        if not pending:  # a resumed run with every chunk done starts no workers
            return
        # at interpreter exit the workers are stopped (registered once: a second registration
        # is removed by the same unregister)
        atexit.register(self.shutdown)
        try:
            yield from self._run_shared(pending)
            if pending and self.retries == 0:
                left = ", ".join(str(index) for index in sorted(pending)[:10])
                raise RuntimeError(f"a worker process died (out of memory or killed?) with "
                                   f"{len(pending)} chunk(s) not done (chunk "
                                   f"{left}{' ...' if len(pending) > 10 else ''}), and "
                                   f"retries = 0 tries none again")
            if pending:
                yield from self._run_isolated(pending)
        except BaseException:
            # an error, an interrupt (Ctrl-C; a notebook's "interrupt kernel" signals this
            # process alone) or a caller that closed this generator: the running chunks'
            # results would be thrown away, and waiting for them took up to a chunk's run time
            # (hours; an audit)
            self.terminate()
            raise

    def _run_shared(self, pending: Dict[int, ChunkTask]) -> Iterator[ChunkResult]:
        """The chunks `pending` (by index; each removed as its result is yielded) on the shared
        pool, until they are done or a worker dies (then the pool is shut down, and the chunks
        that had finished before are yielded too)."""
        futures: Dict[concurrent.futures.Future, int] = {}
        try:
            if self._pool is None:
                self._pool = self._new_pool(self.n_workers)
            # inside the try: a worker that died while the pool stood idle between two runs
            # breaks it at the first submit
            for index, task in pending.items():
                futures[self._submit_shared(task)] = index
            for future in concurrent.futures.as_completed(futures):
                result = future.result()
                del pending[futures[future]]
                yield result
        except BrokenProcessPool:
            pool, self._pool = self._pool, None
            pool.shutdown(wait=True, cancel_futures=True)
            for future, index in futures.items():
                if index in pending and future.done() and not future.cancelled() \
                        and future.exception() is None:
                    del pending[index]
                    yield future.result()

    def _submit_shared(self, task: ChunkTask) -> concurrent.futures.Future:
        """The shared pool's submit of `task`. The pool starts its workers as tasks come: a
        worker that dies while submit starts another breaks the pool under it, the new
        worker's pipes closed, and submit raised OSError ("handle is closed", once in the
        suite's worker-death test) where the pool's own check, a moment later, raises
        BrokenProcessPool. A pool marked broken (its `_broken`, set before it closes its pipes)
        raises BrokenProcessPool here too; another OSError is raised as it is."""
        try:
            return self._pool.submit(self.chunk_function, task)
        except OSError as error:
            broken = getattr(self._pool, "_broken", False)
            if not broken:
                raise
            raise BrokenProcessPool(str(broken)) from error

    def _run_isolated(self, pending: Dict[int, ChunkTask]) -> Iterator[ChunkResult]:
        """The chunks `pending` after the shared pool broke (any of them may have caused it, so
        none is blamed), each on a pool of its own, retried where its worker dies, given up
        after `retries` retries; a RuntimeError at the end names the chunks given up."""
        deaths = dict.fromkeys(pending, 0)
        waiting: Deque[int] = deque(sorted(pending))
        given_up: List[int] = []
        self._isolated = [None] * self.n_workers
        # each running chunk's future: (its slot in _isolated, its chunk index)
        running: Dict[concurrent.futures.Future, Tuple[int, int]] = {}
        while waiting or running:
            busy_slots = {slot for slot, _ in running.values()}
            for slot in range(self.n_workers):
                if waiting and slot not in busy_slots:
                    if self._isolated[slot] is None:
                        self._isolated[slot] = self._new_pool(1)
                    index = waiting.popleft()
                    future = self._isolated[slot].submit(self.chunk_function, pending[index])
                    running[future] = (slot, index)
            finished, _ = concurrent.futures.wait(
                running, return_when=concurrent.futures.FIRST_COMPLETED)
            for future in finished:
                slot, index = running.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:
                    self._isolated[slot].shutdown(wait=True, cancel_futures=True)
                    self._isolated[slot] = None
                    deaths[index] += 1
                    (given_up if deaths[index] > self.retries else waiting).append(index)
                    continue
                del pending[index]
                yield result
        self.shutdown()
        if given_up:
            named = ", ".join(f"{index} ({deaths[index]} deaths running alone)"
                              for index in sorted(given_up)[:10])
            raise RuntimeError(f"chunk(s) {named}{' ...' if len(given_up) > 10 else ''} given "
                               f"up: the worker process running each alone died more than "
                               f"retries = {self.retries} times (out of memory or killed?); "
                               f"the other chunks are done (a run_dir keeps them for a resume)")

    def _pools(self) -> List[concurrent.futures.ProcessPoolExecutor]:
        """The started pools, shared and isolated."""
        return [pool for pool in (self._pool, *self._isolated) if pool is not None]

    def _forget_pools(self):
        """No pool is this executor's any more (nothing for the exit handler to stop)."""
        self._pool, self._isolated = None, []
        atexit.unregister(self.shutdown)

    def shutdown(self):
        """Stop the worker processes (if started) once their running chunks end: the end of a
        run that finished. The pools stay this executor's until they have ended, so that an
        interrupt meanwhile still reaches them (`terminate`)."""
        for pool in self._pools():
            pool.shutdown(wait=True, cancel_futures=True)
        self._forget_pools()

    def terminate(self):
        """Stop the worker processes (if started) now: the queued chunks are cancelled and the
        running ones lost (on an error or an interrupt, whose results no one would read).
        Returns once every worker process has exited; the next `run` starts a new pool."""
        pools = self._pools()
        self._forget_pools()
        for pool in pools:
            _stop_now(pool)

    def __enter__(self) -> "LocalProcesses":
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        if exc_type is None:
            self.shutdown()
        else:
            self.terminate()
