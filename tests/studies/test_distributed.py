"""Sweeps on Dask: a Dask worker process killed mid-sweep costs only its chunk, and the sweep
completes with every row exactly once, bitwise the in-process table (local worker processes:
tests/studies/test_batch.py and the scaling study below). Also the execution flags' validation
before compute."""

import json
import os
import signal
import threading
import time
from types import SimpleNamespace

import pandas as pd
import pytest
from distributed import Client, LocalCluster

from studies import cli, sweep
from studies.__main__ import main as studies_main

# 16 instances, 2 ms steps, 1.2 s each: in chunks of 2 about 0.2 s a chunk on one core (and
# the engine of capacity 64 the other tests compile)
SWEEP = ["--gaits", "A1,A1+A3", "--alpha", "0.4:1.2:8", "--period", "0.3", "--cycles", "4",
         "--dt", "0.002", "--chunk-size", "2", "--no-progress"]
N_INSTANCES = 16


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The in-process table (and its folder)."""
    out = tmp_path_factory.mktemp("inprocess")
    table = sweep.main([*SWEEP, "--out", str(out)])
    table.attrs["out"] = out
    return table


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as local, Client(local) as client:
        yield local, client


@pytest.mark.slow
def test_killed_dask_worker_costs_only_its_chunk(reference, cluster, tmp_path):
    local, client = cluster
    address = local.scheduler_address
    run_dir = tmp_path / "run"
    outcome = {}

    def run():
        try:
            outcome["table"] = sweep.main([*SWEEP, "--out", str(tmp_path), "--scheduler", address,
                                           "--run-dir", str(run_dir)])
        except BaseException as error:  # noqa: BLE001 - reported by the test thread
            outcome["error"] = error

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    while not list(run_dir.glob("chunk_*.parquet")):
        assert thread.is_alive(), outcome
        assert time.monotonic() < deadline, "no chunk finished in 120 s"
        time.sleep(0.005)
    pids = client.run(os.getpid)
    busy = [worker for worker, keys in client.processing().items() if keys]
    assert busy, "no worker busy after the first chunk: the sweep is too short to test"
    lost = client.processing()[busy[0]]
    os.kill(pids[busy[0]], signal.SIGKILL)
    thread.join(timeout=180)
    assert not thread.is_alive(), "the sweep did not complete after a worker was killed"
    assert "error" not in outcome, outcome.get("error")
    table = outcome["table"]
    # the killed worker is gone (its nanny started a new process)
    assert pids[busy[0]] not in client.run(os.getpid).values()
    assert lost and all(key.startswith("taichi_star-chunk-") for key in map(str, lost))
    # every row exactly once, the same numbers as in process
    assert table["instance"].tolist() == list(range(N_INSTANCES))
    assert len(list(run_dir.glob("chunk_*.parquet"))) == N_INSTANCES // 2
    pd.testing.assert_frame_equal(table, reference, check_exact=True)


@pytest.mark.parametrize("argv, message", [
    (["--workers", "0"], "--workers must be in [1, 256], got 0"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"], "give one"),
    (["--scheduler", "localhost"], "--scheduler: expected an address like tcp://HOST:PORT"),
    # refused at once (it waited 31 s for the connection's timeout), and the port named
    (["--scheduler", "tcp://127.0.0.1:65536"],
     "--scheduler: the port of 'tcp://127.0.0.1:65536' must be in 1..65535"),
    (["--retries", "-1"], "--retries must be in [0, 100], got -1"),
    (["--workers", "2", "--retries", "101"], "--retries must be in [0, 100], got 101"),
    # a chunk in this process is never tried again: --retries alone was taken without a word
    (["--retries", "5"], "--retries: only with --workers or --scheduler"),
    (["--chunk-size", "0", "--workers", "2"], "--chunk-size must be >= 1"),
])
@pytest.mark.parametrize("study", ["sweep", "gaits", "calibrate"])
def test_distributed_flags_fail_before_compute(monkeypatch, tmp_path, capsys, study, argv,
                                               message):
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", forbidden)
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--out", str(out), "--quick", "--no-progress"]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def chunk_args(**changes):
    """The flags cli.chunk_size reads: no --chunk-size, a CPU run's default of 2048, not quick."""
    return SimpleNamespace(**{"chunk_size": None, "arch": "cpu", "default_chunk_size": 2048,
                              "quick": False, **changes})


@pytest.mark.parametrize("changes, n_instances, n_workers, size", [
    ({}, 29, 1, 2048),          # one worker: the default, uncut
    ({}, 29, 2, 4),             # ceil(29 / 8): 8 chunks for 2 workers
    ({}, 32, 2, 4),             # 4 w divides n: exactly 4 chunks a worker
    ({}, 33, 2, 5),             # one instance more: ceil(33 / 8)
    ({}, 3, 2, 1),              # fewer instances than 4 w: chunks of one
    ({}, 0, 2, 1),              # ceil gives 0 only here: the floor of 1 instance
    ({"default_chunk_size": 3}, 100, 2, 3),    # the default caps ceil(100 / 8) = 13
    ({"default_chunk_size": 13}, 100, 2, 13),  # the cap equal to the cut
    ({"default_chunk_size": 12}, 100, 2, 12),  # one below it
    ({"arch": "gpu"}, 29, 1, cli.GPU_CHUNK_SIZE),
    ({"arch": "gpu"}, 10**5, 3, 8334),       # ceil(10**5 / 12), below the GPU's default
    ({"arch": "gpu"}, 10**6, 3, cli.GPU_CHUNK_SIZE),  # 83334 capped by it
    ({"quick": True}, 29, 1, cli.QUICK_CHUNK_SIZE),
    ({"quick": True}, 29, 2, 4),
    ({"chunk_size": 3}, 29, 2, 3),   # --chunk-size wins over the cut
    ({"chunk_size": 3}, 29, 1, 3),
])
def test_default_chunk_size_feeds_every_worker(changes, n_instances, n_workers, size):
    assert cli.chunk_size(chunk_args(**changes), n_instances, n_workers) == size


@pytest.mark.slow
def test_scaling_quick(tmp_path, monkeypatch):
    from studies import scaling
    from taichi_star import SolverConfig, StarParams
    from taichi_star.batch import run_batch
    from taichi_star.experiment import PAPER_GAITS
    calls = []

    def recording_run_batch(params, duration_s, *, executor, **kwargs):
        result = run_batch(params, duration_s, executor=executor, **kwargs)
        calls.append((type(executor).__name__, list(params), duration_s, result.summary))
        return result

    monkeypatch.setattr(scaling, "run_batch", recording_run_batch)
    table = scaling.main(["--quick", "--workers-list", "2", "--no-dask", "--out", str(tmp_path),
                          "--no-progress"])
    written = pd.read_csv(tmp_path / "scaling.csv")
    assert written["mode"].tolist() == ["in-process", "processes"]
    assert written["workers"].tolist() == [0, 2]
    # one round (--quick): each mode in turn, an untimed call on one chunk per worker (of 1
    # instance under --quick), then the timed sweep of 2 gaits × 2 alphas
    assert [(executor, len(params)) for executor, params, _, _ in calls] == [
        ("InProcess", 1), ("InProcess", 4), ("LocalProcesses", 2), ("LocalProcesses", 4)]
    params = calls[1][1]
    assert params == calls[3][1]
    assert sorted((p.gait, p.alpha) for p in params) == sorted(
        (gait, alpha) for gait in list(PAPER_GAITS)[:2] for alpha in (0.2, 0.4))
    assert all(p == StarParams(gait=p.gait, alpha=p.alpha) for p in params)
    assert {duration for _, _, duration, _ in calls} == {cli.QUICK_DURATION_S}
    # every mode's table bitwise that of an in-process run made here, in one chunk, with the
    # quick solver built here (the study's own same_table_as_in_process flag compares the
    # modes with each other only)
    reference = run_batch(params, cli.QUICK_DURATION_S, progress=False,
                          solver=SolverConfig.preset("paper", dt=cli.QUICK_DT)).summary
    for _, _, _, summary in (calls[1], calls[3]):
        pd.testing.assert_frame_equal(summary, reference, check_exact=True)
    assert written["same_table_as_in_process"].all()
    assert (written["wall_s"] > 0).all()
    sidecar = json.loads((tmp_path / "scaling.csv.json").read_text())
    assert sidecar["machine"]["cores"] == os.cpu_count() and sidecar["machine"]["cpu_model"]
    assert len(table) == 2


def test_a_cluster_without_workers_stops_the_run_after_the_timeout(monkeypatch):
    """A scheduler whose last worker is gone (here: one that never had any): the run stops
    with a RuntimeError naming the cluster after no_workers_timeout_s instead of waiting
    forever; the check runs every POLL_S (shortened here)."""
    from taichi_star import SolverConfig, StarParams
    from taichi_star.batch import dask_cluster
    from taichi_star.batch.tasks import ChunkTask

    monkeypatch.setattr(dask_cluster, "POLL_S", 0.2)
    task = ChunkTask(0, (0,), (StarParams(),), 0.01, SolverConfig())
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as local, \
            Client(local) as client:
        executor = dask_cluster.DaskExecutor(client, no_workers_timeout_s=0.5)
        start = time.monotonic()
        with pytest.raises(RuntimeError, match="has had no worker for 0.5 s with 1 chunk"):
            list(executor.run([task]))
        assert 0.5 <= time.monotonic() - start < 30
    with pytest.raises(ValueError, match="no_workers_timeout_s must be a number > 0"):
        dask_cluster.DaskExecutor(client, no_workers_timeout_s=0)
