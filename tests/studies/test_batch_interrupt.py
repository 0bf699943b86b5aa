"""Ctrl-C during a `run_batch` on worker processes: a notebook's "interrupt kernel" sends SIGINT
to its own process alone, and the KeyboardInterrupt waited until the running chunks had ended
(their results thrown away: up to a chunk's run time, hours; an audit). Now the workers are
terminated and the interrupt comes at once; no worker process is left, the chunks stored before
are kept, and a resumed run is the uninterrupted one bit for bit."""

import contextlib
import os
import signal
import threading
import time

import pandas as pd
import psutil  # a dependency of distributed (the dask extra, which the test extra holds)
import pytest

import taichi_star as ts
from taichi_star.batch import RunStore, run_batch

# every test starts worker processes and waits on signals: the slow tier
pytestmark = pytest.mark.slow

SOLVER = ts.SolverConfig(dt=2e-3)
TINY = dict(n_arc=6, n_limb=2)


def worker_processes() -> set:
    """This process's children that run a "spawn" pool's worker (not multiprocessing's
    resource tracker, which lives as long as this process)."""
    workers = set()
    for child in psutil.Process().children():
        with contextlib.suppress(psutil.NoSuchProcess):   # one that ended meanwhile
            if "spawn_main" in " ".join(child.cmdline()):
                workers.add(child)
    return workers


def test_an_interrupt_stops_the_workers_at_once_and_keeps_the_stored_chunk(tmp_path,
                                                                            interruptible):
    # a short chunk (20 cycles of 0.3 s: 3,000 steps, ~0.05 s once compiled) and a long one
    # (20 cycles of 1,000 s: 10**7 steps, ~80 s at the 120,000 robot-steps/s measured at rest,
    # 105 s beside other tests); the SIGINT goes to this process once the short one is stored,
    # while the long one runs
    params = [ts.StarParams(gait="A1", period=0.3, **TINY),
              ts.StarParams(gait="A1", period=1000.0, **TINY)]
    run_dir = tmp_path / "run"
    before = worker_processes()
    stop, sent = threading.Event(), {}

    def interrupt_once_the_short_chunk_is_stored():
        try:
            while not stop.is_set():
                # the store writes a chunk's file last, by a rename: there, the chunk is whole
                if (run_dir / "chunk_000000.parquet").exists():
                    sent["workers"] = worker_processes() - before
                    sent["at"] = time.monotonic()
                    os.kill(os.getpid(), signal.SIGINT)
                    return
                stop.wait(0.01)
        except BaseException as error:  # reported by the failure below, not lost with the thread
            sent["error"] = repr(error)

    interrupter = threading.Thread(target=interrupt_once_the_short_chunk_is_stored)
    interrupter.start()
    started = time.monotonic()
    try:
        run_batch(params, cycles=20, solver=SOLVER, run_dir=run_dir, workers=2)
    except KeyboardInterrupt:
        raised_after_s = time.monotonic() - sent["at"]
    else:
        # whether the signal was sent, and when, and the SIGINT handler tell a lost interrupt
        # from a missed one (an ignored SIGINT: the `interruptible` fixture)
        pytest.fail(f"run_batch ended after {time.monotonic() - started:.1f} s without the "
                    f"interrupt: signal sent {sent.get('at', started) - started:.1f} s in "
                    f"({'at' in sent}), interrupter error {sent.get('error')}, SIGINT handler "
                    f"{signal.getsignal(signal.SIGINT)!r}, chunks "
                    f"{sorted(path.name for path in run_dir.glob('chunk_*'))}")
    finally:
        stop.set()
        interrupter.join()
    # terminating and joining the workers took 0.02-0.04 s (this 2-core box, a run of the
    # old code beside it); 10 s is 250 times that and under a tenth of the rest of the long
    # chunk, which the interrupt waited for before (104.5 s, the test run on the old code)
    assert raised_after_s < 10.0
    assert len(sent["workers"]) == 2   # the short chunk's and the long one's, both started
    # joined too: a terminated worker not yet reaped (a zombie) still counts as running
    assert not any(worker.is_running() for worker in sent["workers"])
    assert worker_processes() - before == set()
    assert [path.name for path in run_dir.glob("chunk_*.parquet")] == ["chunk_000000.parquet"]


def test_a_run_interrupted_after_a_stored_chunk_resumes_to_the_uninterrupted_one(tmp_path,
                                                                                  monkeypatch):
    """The interrupt here lands in `run_batch` itself (just after a chunk was stored) rather
    than in the wait for the workers' results: the workers are stopped all the same, and the
    resume reads that chunk back and computes the other two, bit for bit the whole run."""
    params = [ts.StarParams(gait=gait, period=0.3, **TINY) for gait in ("A1", "A1+A3", "A2")]
    run = dict(cycles=2, solver=SOLVER, chunk_size=1, record_interval_s=0.1)
    uninterrupted = run_batch(params, **run)
    run_dir = tmp_path / "run"
    write = RunStore.write

    def write_then_interrupt(store, *args, **kwargs):
        write(store, *args, **kwargs)
        raise KeyboardInterrupt

    before = worker_processes()
    with monkeypatch.context() as patched:
        patched.setattr(RunStore, "write", write_then_interrupt)
        with pytest.raises(KeyboardInterrupt):
            run_batch(params, **run, run_dir=run_dir, workers=2)
    assert worker_processes() - before == set()
    assert len(list(run_dir.glob("chunk_*.parquet"))) == 1
    resumed = run_batch(params, **run, run_dir=run_dir, resume=True)
    # two chunks computed (each 2 cycles of 0.3 s at dt = 2 ms: 300 steps), one read back
    assert resumed.timing.robot_steps == 2 * 300
    pd.testing.assert_frame_equal(resumed.summary, uninterrupted.summary, check_exact=True)
    pd.testing.assert_frame_equal(resumed.trajectory, uninterrupted.trajectory, check_exact=True)


PARENT_OF_A_POOL = """
import os, time
from taichi_star.batch import LocalProcesses
if __name__ == "__main__":
    # the pool LocalProcesses itself makes: one built here by hand with the initialiser let a
    # LocalProcesses that forgot to pass its pid live through the suite (a mutation audit)
    pool = LocalProcesses(1)._new_pool(1)
    print(pool.submit(os.getpid).result(), flush=True)
    time.sleep(600)
"""


def test_a_pools_worker_ends_with_its_main_process_killed_with_sigkill(tmp_path):
    """A main process killed with SIGKILL (or by the OOM killer) left its pool's workers
    running for ever, each ~240 MB (an audit, 2026-12: 58 after 30 kills): the worker of
    `LocalProcesses`' initialiser now ends with it, within seconds."""
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(PARENT_OF_A_POOL)
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    worker = None
    try:
        worker = psutil.Process(int(parent.stdout.readline()))
        assert worker.is_running() and worker.ppid() == parent.pid
        parent.kill()
        parent.wait(timeout=10)
        # its watcher looks every PARENT_POLL_S (1 s)
        gone, _ = psutil.wait_procs([worker], timeout=20)
        assert gone, "the worker outlived its killed parent"
    finally:
        parent.kill()
        if worker is not None and worker.is_running():
            worker.kill()


def test_a_pools_worker_started_from_a_thread_that_ended_lives_on():
    """A worker that ended with the *thread* that started it (Linux's PR_SET_PDEATHSIG, tried
    first: a review, 2026-12) broke a pool first used from a short-lived thread: its next task
    raised BrokenProcessPool. The worker watches its parent process instead."""
    import concurrent.futures
    import multiprocessing
    import threading

    from taichi_star.batch.executors import configure_worker_process

    pool = concurrent.futures.ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn"),
        initializer=configure_worker_process, initargs=(os.getpid(),))
    try:
        first = []
        starter = threading.Thread(target=lambda: first.append(pool.submit(os.getpid).result()))
        starter.start()
        starter.join()
        time.sleep(1.5)  # past a poll of the worker's watcher
        assert pool.submit(os.getpid).result(timeout=60) == first[0]
    finally:
        pool.shutdown()


@pytest.mark.timeout(120)
def test_an_error_in_the_with_block_stops_a_busy_worker_at_once():
    """LocalProcesses' `with` block ending in an error terminates its workers, busy or not
    (shutting them down instead, waiting for the running task, 60 s here, lived through the
    suite: a mutation audit, 2026-12-07)."""
    from taichi_star.batch import LocalProcesses

    start = time.monotonic()
    with pytest.raises(KeyError):
        with LocalProcesses(1) as executor:
            executor._pool = executor._new_pool(1)
            executor._pool.submit(time.sleep, 60)
            time.sleep(0.5)
            raise KeyError("stop")
    assert time.monotonic() - start < 30  # the task alone would take 60 s
