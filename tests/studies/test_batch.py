"""run_batch: chunked, on worker processes, with shapes, it gives bitwise the tables of one
`simulate` call; its arguments are checked before any compute; a process pool started from a
script without a main guard fails with an error that explains the guard."""

import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.batch import InProcess, LocalProcesses, plan_chunks, run_batch

REPO = Path(__file__).resolve().parents[2]
SOLVER = ts.SolverConfig(dt=2e-3)
PARAMS = [ts.StarParams(gait=g, alpha=a, period=0.3) for g in ("A1", "A1+A3") for a in (0.4, 1.2)]
DURATION = 0.6  # two cycles of 0.3 s


@pytest.fixture(scope="module")
def direct():
    return ts.simulate(PARAMS, DURATION, SOLVER, record_interval_s=0.1, record_shapes=True)


def test_chunked_batch_equals_one_simulate_call(direct):
    result = run_batch(PARAMS, cycles=2, solver=SOLVER, chunk_size=3, record_interval_s=0.1,
                       record_shapes=True)
    assert result.summary["instance"].tolist() == list(range(len(PARAMS)))
    assert (result.summary["duration_s"] == DURATION).all()
    pd.testing.assert_frame_equal(result.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary, check_exact=True)
    pd.testing.assert_frame_equal(result.trajectory, direct.trajectory, check_exact=True)
    np.testing.assert_array_equal(result.shapes, direct.shapes)
    assert result.topology.n_nodes == direct.topology.n_nodes
    assert np.isfinite(result.summary["steady_speed_mm_s"]).all()  # cycle 1 of 2 is whole
    # the timing of its two chunks, summed: every robot-step counted once (the wall times are
    # not compared: no timing in tests)
    assert result.timing.robot_steps == direct.timing.robot_steps == len(PARAMS) * 300
    assert result.timing.run_s > 0.0


def test_a_resumed_batch_has_every_chunks_records_from_its_store(tmp_path, direct):
    """The store keeps each chunk's trajectory beside its summary: a run resumed after losing a
    chunk recomputes that one and reads the others' records back, so its trajectory is the
    whole run's, bit for bit (it used to hold the recomputed chunks' records alone)."""
    run_dir = tmp_path / "run"
    whole = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=2, record_interval_s=0.1,
                      run_dir=run_dir)
    (run_dir / "chunk_000001.parquet").unlink()   # as if killed before chunk 1 was stored
    resumed = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=2, record_interval_s=0.1,
                        run_dir=run_dir, resume=True)
    for result in (whole, resumed):
        pd.testing.assert_frame_equal(result.trajectory, direct.trajectory, check_exact=True)
        pd.testing.assert_frame_equal(result.summary.drop(columns=["instance", "duration_s"]),
                                      direct.summary, check_exact=True)
    assert resumed.timing.robot_steps == 2 * 300   # chunk 1 alone was computed


def test_a_single_starparams_is_a_batch_of_one_and_a_string_is_refused(monkeypatch, direct):
    alone = run_batch(PARAMS[0], DURATION, solver=SOLVER)
    pd.testing.assert_frame_equal(alone.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary.iloc[:1], check_exact=True)
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    for bad, name in (("A1", "str"), (None, "NoneType"), (3, "int")):
        with pytest.raises(ValueError, match=rf"^params must be a sequence of StarParams, got "
                                             rf"{name}$"):
            run_batch(bad, DURATION, solver=SOLVER)


@pytest.mark.slow
def test_local_worker_processes_give_the_in_process_tables(direct):
    with LocalProcesses(2) as executor:
        result = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=1,
                           record_interval_s=0.1, executor=executor)
        again = run_batch(PARAMS[:1], DURATION, solver=SOLVER, executor=executor)
    pd.testing.assert_frame_equal(result.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary, check_exact=True)
    pd.testing.assert_frame_equal(result.trajectory, direct.trajectory, check_exact=True)
    pd.testing.assert_frame_equal(again.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary.iloc[:1], check_exact=True)


@pytest.fixture
def deaths(tmp_path, monkeypatch):
    """(DyingProcesses, marker folder): `LocalProcesses` whose workers run
    `worker_deaths.run_chunk_or_die`, the chunks to die marked in the folder."""
    monkeypatch.syspath_prepend(str(Path(__file__).parent))  # the spawned workers inherit it
    import worker_deaths

    folder = tmp_path / "deaths"
    folder.mkdir()
    monkeypatch.setenv(worker_deaths.FOLDER_VARIABLE, str(folder))

    class DyingProcesses(LocalProcesses):
        chunk_function = staticmethod(worker_deaths.run_chunk_or_die)
    return DyingProcesses, folder


@pytest.mark.slow
@pytest.mark.timeout(300)  # an executor that never gave up would retry for ever
def test_a_worker_death_on_each_of_four_chunks_is_each_chunks_own(deaths, direct):
    """Four chunks whose workers die on their first try, on two workers with one retry: the
    pool cannot tell whose death broke it, and at most two chunks run at once, so their deaths
    broke it at least twice, which stopped the run when deaths counted for the whole run (an
    audit, 2026-12). Now the rest of the run goes on one chunk per worker, where each death is
    its chunk's: each chunk dies at most once, is retried, and the tables are bitwise
    `simulate`'s."""
    processes, folder = deaths
    for index in range(len(PARAMS)):
        (folder / f"chunk_{index}").write_text("1")
    with processes(2, retries=1) as executor:
        result = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=1,
                           record_interval_s=0.1, executor=executor)
    assert [(folder / f"chunk_{i}").read_text() for i in range(len(PARAMS))] == ["0"] * 4
    pd.testing.assert_frame_equal(result.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary, check_exact=True)
    pd.testing.assert_frame_equal(result.trajectory, direct.trajectory, check_exact=True)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_chunk_that_always_kills_its_worker_is_named_after_the_others_are_done(deaths,
                                                                                 tmp_path,
                                                                                 direct):
    """Chunk 1 kills every worker that runs it: with one retry it dies twice running alone
    (the shared pool's death, anyone's, is not counted), then the error names it, and the
    other three chunks are done and stored in the run folder first; a resume without the
    marker computes chunk 1 alone and gives `simulate`'s tables."""
    processes, folder = deaths
    (folder / "chunk_1").write_text("always")
    run_dir = tmp_path / "run"
    with processes(2, retries=1) as executor:
        with pytest.raises(RuntimeError, match=r"^chunk\(s\) 1 \(2 deaths running alone\) "
                                               r"given up: the worker process running each "
                                               r"alone died more than retries = 1 times"):
            run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=1, executor=executor,
                      run_dir=run_dir)
    stored = sorted(path.name for path in run_dir.glob("chunk_*.parquet"))
    assert stored == ["chunk_000000.parquet", "chunk_000002.parquet", "chunk_000003.parquet"]
    (folder / "chunk_1").unlink()
    resumed = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=1, run_dir=run_dir,
                        resume=True)
    assert resumed.timing.robot_steps == 300   # chunk 1 alone was computed
    pd.testing.assert_frame_equal(resumed.summary.drop(columns=["instance", "duration_s"]),
                                  direct.summary, check_exact=True)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_with_no_retries_the_first_worker_death_stops_the_run(deaths):
    """retries = 0, the boundary: no chunk may be tried again, so the first death stops the
    run, naming the chunks not done (isolated, each would have run again)."""
    processes, folder = deaths
    (folder / "chunk_0").write_text("1")
    with processes(2, retries=0) as executor:
        with pytest.raises(RuntimeError, match=r"^a worker process died \(out of memory or "
                                               r"killed\?\) with \d chunk\(s\) not done "
                                               r"\(chunk 0[,)].*retries = 0 tries none again$"):
            run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=1, executor=executor)
    assert (folder / "chunk_0").read_text() == "0"


class PoolBrokenInSubmit:
    """A process pool whose worker died while `submit` started another (the race behind an
    OSError "handle is closed" in the slow worker-death test, 2026-12-07): submit raises that
    OSError; `_broken` is what the pool's manager thread sets before it closes the pipes."""

    _processes = None

    def __init__(self, broken):
        self._broken = broken

    def submit(self, *args):
        raise OSError("handle is closed")

    def shutdown(self, wait=True, cancel_futures=False):
        pass


@pytest.mark.parametrize("broken", ["A child process terminated abruptly", False])
def test_a_pool_broken_while_a_worker_starts_is_a_worker_death_not_an_oserror(monkeypatch,
                                                                              broken):
    """submit's OSError on a pool its manager marked broken is a worker's death: with
    retries = 0 the run stops naming the chunks not done (it raised the OSError, a traceback
    from multiprocessing's pipes); on a pool not marked broken the OSError is the caller's."""
    processes = LocalProcesses(2, retries=0)
    monkeypatch.setattr(processes, "_new_pool", lambda n_workers: PoolBrokenInSubmit(broken))
    tasks = plan_chunks([TINY, TINY], 0.002, solver=MS_SOLVER, chunk_size=1)
    expected = (pytest.raises(RuntimeError, match=r"^a worker process died \(out of memory or "
                                                   r"killed\?\) with 2 chunk\(s\) not done "
                                                   r"\(chunk 0, 1\)")
                if broken else pytest.raises(OSError, match="^handle is closed$"))
    with expected:
        list(processes.run(tasks))
    assert processes._pools() == []   # let go of, as after any failed run


def test_a_run_with_no_chunks_left_starts_no_workers():
    """A resumed run whose chunks are all done hands the executor no task: no pool (the
    first pool's start spawns workers and reads the main script)."""
    executor = LocalProcesses(2)
    assert list(executor.run([])) == []
    assert executor._pool is None


def test_instances_of_several_topologies_and_periods_are_grouped_in_input_order():
    # n_arc 18 (the default) and 8 with shared ends: engines the other tests compile too
    params = [ts.StarParams(gait="A1", period=0.3),
              ts.StarParams(gait="A1", n_arc=8, actuation_ends="shared", period=0.3),
              ts.StarParams(gait="A1", period=0.4),
              ts.StarParams(gait="A1+A2", period=0.3)]
    tasks = plan_chunks(params, cycles=1, chunk_size=8, solver=SOLVER)
    assert [t.members for t in tasks] == [(0, 3), (1,), (2,)]
    assert [t.duration_s for t in tasks] == pytest.approx([0.3, 0.3, 0.4])
    result = run_batch(params, cycles=1, solver=SOLVER)
    assert result.summary["instance"].tolist() == [0, 1, 2, 3]
    assert result.summary["n_arc"].tolist() == [18, 8, 18, 18]
    assert result.topology is None  # no single topology
    alone = ts.simulate([params[2]], 0.4, SOLVER).summary
    pd.testing.assert_frame_equal(result.summary.iloc[[2]].drop(columns=["instance", "duration_s"])
                                  .reset_index(drop=True), alone, check_exact=True)


@pytest.mark.parametrize("periods, chunk_size, adaptive, told", [
    # the first chunk's cycles on the grid (0.006 s), the second's off it: told (an audit of
    # the tests: a rule that looked at the first chunk alone passed them)
    ((0.3, 0.3337), 2048, False, "params[1], 0.006674 s"),
    # once for the batch, naming the robot: the 4th robot is in the 3rd chunk, and the 5th's
    # cycles are off the grid too
    ((0.3, 0.3, 0.3, 0.3337, 0.3339), 2, False, "params[3], 0.006674 s"),
    ((0.3337,), 2048, True, None),  # adaptive steps end where the cycles end
])
def test_cycles_off_the_step_grid_are_told_once_naming_the_first_such_robot(periods, chunk_size,
                                                                            adaptive, told):
    """Planning only (no compute): `cycles` periods that are not a whole number of steps."""
    solver = ts.SolverConfig(integrator="bdf2", adaptive=True, dt=2e-3) if adaptive else SOLVER
    params = [ts.StarParams(n_arc=6, n_limb=2, period=period) for period in periods]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan_chunks(params, cycles=0.02, solver=solver, chunk_size=chunk_size)
    assert [str(warning.message) for warning in caught] == ([] if told is None else [
        f"cycles = 0.02 periods of {told}, is not a whole number of steps (dt = 0.002 s): 3 "
        f"steps, 0.006 s, are simulated (each instance's duration_s in the summary)"])


def test_periods_off_the_step_grid_name_the_first_robot_in_input_order_across_topologies():
    """The chunks come in groups of a topology (first appearance): robots 2 and 1 of the
    batch, in that order; the warning names the first in the batch (planning only)."""
    coarse = ts.StarParams(gait="A1+A2", n_arc=6, n_limb=2, period=0.164)  # 164 whole steps
    params = [coarse, coarse.replace(n_arc=8, period=0.1635), coarse.replace(period=0.1645)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan_chunks(params, 0.33, chunk_size=1, solver=ts.SolverConfig())
    assert [str(warning.message)[:60] for warning in caught] == [
        "2 of 3 instances (the first params[1], period 0.1635 s) have"]


@pytest.mark.parametrize("kwargs, message", [
    (dict(duration_s=0.1, cycles=1), "exactly one of duration_s"),
    (dict(), "exactly one of duration_s"),
    (dict(cycles=0), "cycles must be a finite number > 0"),
    (dict(cycles=1, chunk_size=0), "chunk_size must be an integer >= 1"),
    (dict(cycles=1, record_interval_s=0.0011), "record_interval_s must be a whole number"),
    (dict(cycles=1, workers=0), "workers must be an integer from 1 to 256"),
    (dict(cycles=1, arch="tpu"), "arch must be one of"),
    (dict(cycles=1, executor="dask"), "executor must be an Executor.*got 'dask'"),
    (dict(cycles=1, resume=True), "resume=True needs run_dir"),
])
def test_bad_arguments_fail_before_compute(monkeypatch, kwargs, message):
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with pytest.raises(ValueError, match=message):
        run_batch(PARAMS, solver=SOLVER, **kwargs)


def test_shapes_need_one_topology_and_duration(monkeypatch):
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with pytest.raises(ValueError, match="record_shapes needs one topology"):
        run_batch([ts.StarParams(period=0.3), ts.StarParams(period=0.4)], cycles=1,
                  solver=SOLVER, record_interval_s=0.1, record_shapes=True)


def _forbidden(*args, **kwargs):
    raise AssertionError("simulate was called despite invalid arguments")


@pytest.mark.slow
def test_a_script_without_main_guard_gets_an_error_explaining_it(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text(textwrap.dedent("""
        import taichi_star as ts
        from taichi_star.batch import run_batch
        run_batch([ts.StarParams()], 0.01, workers=2)
    """))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode != 0
    assert "if __name__ == \"__main__\":" in run.stderr and "guard" in run.stderr
    assert "BrokenProcessPool" not in run.stderr
    # the in-process default needs no guard
    script.write_text(script.read_text().replace(", workers=2", ""))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 0, run.stderr[-2000:]


def test_a_batch_tells_its_long_work_once_and_records_the_time_it_simulated(monkeypatch):
    """Planning warned of the batch's robot-steps and then each chunk's run warned of its own
    again, with other numbers (an audit, 2026-12): one warning now, the batch's. And the
    `duration_s` column is the time simulated, over which the speeds are taken: 0.0126 s asked
    at 1-ms steps is 13 steps, 0.013 s (it gave the 0.0126 asked, so speed × duration_s missed
    the displacement by 3 %)."""
    from taichi_star import timegrid
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 15)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_batch([ts.StarParams(gait="A1+A3")] * 4, 0.0126, chunk_size=2)
    told = [str(w.message) for w in caught if "robot-steps: about" in str(w.message)]
    assert len(told) == 1 and told[0].startswith("the batch of 4 instances is "), told
    summary = result.summary
    np.testing.assert_allclose(summary["duration_s"], 0.013, rtol=1e-15)   # 13 × 0.001 s
    displacement = np.hypot(summary["displacement_x_mm"], summary["displacement_y_mm"])
    np.testing.assert_allclose(summary["speed_mm_s"] * summary["duration_s"], displacement,
                               rtol=1e-12)   # both from the same time, to rounding


def test_a_batchs_work_and_trajectory_are_judged_whole_not_by_chunk(monkeypatch,
                                                                  memory_budget):
    """Each chunk checked its own work and records, so a 2-year sweep warned of one chunk's
    448 h (an audit) and a batch's gathered trajectory was never estimated. The batch's
    robot-steps warn once past WARN_ROBOT_STEPS (here 1,500: four instances of 500 steps, in
    chunks of one that stay below it; three of them, at it, do not), and its trajectory rows
    and summary rows, the tables it gathers (`simulation.tables_bytes` of each chunk: the
    shapes and summary were left out, an audit), are refused past the memory budget, a byte
    over it."""
    from taichi_star import runtime, simulation, timegrid
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 1500)
    for count, warned in ((4, True), (3, False)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            plan_chunks([ts.StarParams()] * count, 0.5, chunk_size=1)
        messages = [str(w.message) for w in caught if w.category is ts.LongWorkWarning]
        assert messages == ([f"the batch of {count} instances is {500 * count:.3g} robot-steps: "
                             f"about {500 * count / 5e4 / 3600:.3g} h at 50000 robot-steps/s (on "
                             f"a 2-core CPU; a GPU or more cores run faster)"] if warned else [])
    # four chunks of ten instances, 51 records each (0.5 s every 10 ms, the start included);
    # what the batch keeps of a chunk is its rows (its run's per-record overhead is transient)
    chunk = 10 * simulation.SUMMARY_ROW_BYTES + 51 * 10 * simulation.RECORD_ROW_BYTES
    for refused in memory_budget(4 * chunk):  # each chunk's own tables fit within either
        if refused:
            with pytest.raises(ValueError, match=r"^record_interval_s: the tables of the batch "
                                                 r"of 40 instances would need about "):
                plan_chunks([ts.StarParams()] * 40, 0.5, chunk_size=10, record_interval_s=0.01)
        else:
            plan_chunks([ts.StarParams()] * 40, 0.5, chunk_size=10, record_interval_s=0.01)
            # in chunks of one the same rows: accepted too (each chunk's overhead was added)
            plan_chunks([ts.StarParams()] * 40, 0.5, chunk_size=1, record_interval_s=0.01)
    # with shapes (193 nodes) the stacked shapes count too: refused a byte under their total
    shaped = 4 * (10 * simulation.SUMMARY_ROW_BYTES + 51 * 10 * (
        simulation.RECORD_ROW_BYTES + 193 * simulation.RECORD_NODE_BYTES))
    monkeypatch.setattr(runtime, "available_memory_bytes",
                        lambda: (shaped - 1) / runtime.MEMORY_SHARE)
    with pytest.raises(ValueError, match=r"^record_interval_s: the tables of the batch of 40 "):
        plan_chunks([ts.StarParams()] * 40, 0.5, chunk_size=10, record_interval_s=0.01,
                    record_shapes=True)


def test_a_batch_in_chunks_of_two_warns_once_with_all_its_robot_steps(monkeypatch):
    """In chunks of more than one, counting per chunk is not counting per instance, and a
    chunk can warn on its own: with WARN_ROBOT_STEPS at 999, each chunk of two robots (1,000
    robot-steps in 0.5 s) is past it alone, and the batch of four (2,000) is told once, whole
    (counted per chunk it said 1e+03; unfiltered, each chunk added its own warning)."""
    from taichi_star import timegrid
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 999)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan_chunks([ts.StarParams()] * 4, 0.5, chunk_size=2)
    messages = [str(w.message) for w in caught if w.category is ts.LongWorkWarning]
    assert messages == [f"the batch of 4 instances is 2e+03 robot-steps: about "
                        f"{2000 / 5e4 / 3600:.3g} h at 50000 robot-steps/s (on a 2-core CPU; a "
                        f"GPU or more cores run faster)"]


def test_a_batch_without_records_past_the_memory_budget_names_params(memory_budget):
    """Without records the batch's tables are its summary rows, and the argument to change
    is params (record_interval_s is not given): four rows refused a byte under their total,
    accepted at it, while each chunk of two rows fits its own check in either case."""
    from taichi_star import simulation
    for refused in memory_budget(4 * simulation.SUMMARY_ROW_BYTES):
        if refused:
            with pytest.raises(ValueError, match=r"^params: the tables of the batch of 4 "
                                                 r"instances would need about .*: run the "
                                                 r"batch in parts$"):
                plan_chunks([ts.StarParams()] * 4, 0.5, chunk_size=2)
        else:
            assert len(plan_chunks([ts.StarParams()] * 4, 0.5, chunk_size=2)) == 2


def test_a_worker_that_cannot_import_the_script_is_named_so_not_retried(tmp_path):
    """Code after the guard that needs the guard's names (a print of the result) fails in
    every worker's import of the script: the pool broke, was retried, and the error blamed
    memory (an audit). Now one error says the workers could not start."""
    script = tmp_path / "after_guard.py"
    script.write_text(textwrap.dedent("""
        import taichi_star as ts
        from taichi_star.batch import run_batch
        if __name__ == "__main__":
            result = run_batch([ts.StarParams()] * 2, 0.01, workers=2)
        print(result.summary)
    """))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode != 0
    assert "worker processes could not start: each re-imports" in run.stderr
    assert "out of memory or killed" not in run.stderr


def test_a_sweep_tells_its_batchs_hours_once_before_it_builds_the_instances(
        monkeypatch, tmp_path, warnings_before_call):
    """A sweep near the studies' million instances built them (about two minutes) before
    run_batch told its hours (an audit, 2026-12); now the study tells them first, counted as
    run_batch counts them (`batch_robot_steps` of its chunks: each instance's steps at its own
    period), and run_batch's own telling is kept back: one warning. Two periods of 0.5 and 1 s
    at 1-ms steps for one cycle are 1,500 robot-steps: told past a limit of 1,499, not at
    1,500 (the rule is "over")."""
    from taichi_star import timegrid
    from studies import cli, sweep

    argv = ["--gaits", "A1", "--period", "0.5,1", "--cycles", "1", "--no-progress"]
    expected = (f"the batch of 2 instances (--cycles 1 of each period) is 1.5e+03 robot-steps: "
                f"about {1500 / 5e4 / 3600:.3g} h at 50000 robot-steps/s (on a 2-core CPU; a "
                f"GPU or more cores run faster)")
    for limit, told in ((1499, [expected]), (1500, [])):
        monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", limit)
        with warnings_before_call(cli, "param_product") as (caught, built):
            table = sweep.main([*argv, "--out", str(tmp_path / str(limit))])
        assert [str(w.message) for w in caught if w.category is ts.LongWorkWarning] == told
        assert built == [told]  # told before the instances were built
    # the study's count is run_batch's
    params = [ts.StarParams(gait="A1", period=p) for p in (0.5, 1.0)]
    tasks = plan_chunks(params, cycles=1)
    from taichi_star.batch.tasks import batch_robot_steps
    arguments = cli.parse(sweep.build_parser(), argv)
    assert cli.tell_batch_work(arguments, ts.SolverConfig(), 2, periods=[0.5, 1.0]) \
        == batch_robot_steps(tasks) == 1500
    assert table["duration_s"].tolist() == [0.5, 1.0]


def test_a_batch_of_several_meshes_weighs_each_chunks_steps_by_its_nodes(monkeypatch):
    """run_batch's estimate of a batch of several meshes: the nodes of its chunks weighted by
    their robot-steps, which gives the batch's work exactly (a step's work is proportional to
    the nodes: `timegrid.step_work`). One cycle of 0.5 s at n_arc 18 (193 nodes, 500 steps)
    and of 1 s at n_arc 48 (433 nodes, 1,000 steps): 353 nodes; one robot of 193 and two of
    201 nodes for the same time: 198.3, said "on average"."""
    from taichi_star import timegrid
    from taichi_star.batch.tasks import batch_nodes, batch_robot_steps, check_batch_work

    tasks = plan_chunks([ts.StarParams(period=0.5), ts.StarParams(n_arc=48, period=1.0)],
                        cycles=1)
    assert batch_robot_steps(tasks) == 1500 and batch_nodes(tasks) == 353.0
    tasks = plan_chunks([ts.StarParams(), ts.StarParams(n_arc=19), ts.StarParams(n_arc=19)],
                        cycles=1)
    assert batch_nodes(tasks) == pytest.approx((193 + 2 * 201) / 3, rel=1e-15)
    assert batch_nodes([]) is None
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 1)
    with pytest.warns(ts.LongWorkWarning, match=r"^the batch of 3 instances is 9\.45e\+03 "
                                                r"robot-steps of robots of 198 nodes on average "
                                                r"\(a step 1\.03 times the work"):
        check_batch_work(tasks, 3)


def test_chunks_on_workers_show_a_bar_even_one_and_no_records_keep_simulates_types(tmp_path,
                                                                                   capsys):
    """With an executor that runs chunks elsewhere (worker processes show no bar of their own)
    `progress=True` showed nothing for a batch of one chunk, the default chunk size's usual
    case (an audit, 2026-12): a bar of chunks now. A run without records, stored or not, has
    an empty trajectory of simulate's column types (object columns before)."""
    from taichi_star.batch import InProcess

    class Elsewhere:  # not an InProcess: as worker processes, no bars of the chunks' own
        def run(self, tasks, progress=False):
            assert progress is False
            return InProcess().run(tasks)

    run_batch(PARAMS[:1], 0.01, solver=SOLVER, executor=Elsewhere(), progress=True)
    assert "chunks" in capsys.readouterr().err
    run_batch(PARAMS[:1], 0.01, solver=SOLVER, executor=Elsewhere(), progress=False)
    assert "chunks" not in capsys.readouterr().err
    plain = ts.simulate(PARAMS[:1], 0.01, SOLVER, progress=False).trajectory
    for run_dir in (None, tmp_path / "run"):
        stored = run_batch(PARAMS[:1], 0.01, solver=SOLVER, run_dir=run_dir).trajectory
        assert stored.empty and stored.dtypes.to_dict() == plain.dtypes.to_dict()


@pytest.mark.parametrize("workers, chunks, idle", [(3, 2, 1), (2, 2, 0), (3, 3, 0)])
def test_more_workers_than_chunks_are_named_idle_before_any_starts(workers, chunks, idle):
    """More worker processes than chunks to compute: the idle ones are said before the run
    (they stood idle without a word: an audit, 2026-12); as many workers as chunks, nothing.
    The executor stops at its start, so nothing is computed."""

    class Started(Exception):
        pass

    class StopsAtStart(LocalProcesses):
        def run(self, tasks, progress=False):
            raise Started(len(tasks))

    params = [ts.StarParams(gait="A1")] * chunks
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(Started):
            run_batch(params, 0.01, solver=SOLVER, chunk_size=1, executor=StopsAtStart(workers))
    said = [str(w.message) for w in caught if "stay idle" in str(w.message)]
    assert said == ([f"{workers} worker processes for {chunks} chunk(s) to compute: {idle} stay "
                     f"idle (chunk_size=1; a smaller one gives each worker a share of the "
                     f"batch)"] if idle else [])


# a mutation audit of run_batch and plan_chunks (2026-12): each test below failed a mutant
# the suite let live. A coarse robot at 1-ms steps
TINY = ts.StarParams(n_arc=6, n_limb=2)
MS_SOLVER = ts.SolverConfig()


@pytest.mark.parametrize("kwargs, message", [
    (dict(workers=2, executor=InProcess()), "^give workers .* or executor, not both"),
    (dict(record_interval_s=0.001, record_shapes=True, run_dir="RUN"),
     r"^record_shapes cannot be combined with run_dir"),
    (dict(sensitivities=("alpah",)), r"^sensitivities: 'alpah' is not a StarParams field; "
                                     r"did you mean alpha\?"),
    (dict(sensitivities=("gait",)), r"^sensitivities: 'gait' is not differentiable"),
    (dict(sensitivities="alpha"), r"^sensitivities must be a sequence of StarParams field"),
    (dict(sensitivities=("alpha",), solver=ts.SolverConfig(precision="f32")),
     r"^sensitivities need precision 'f64'"),
])
def test_run_batch_refuses_before_compute(monkeypatch, tmp_path, kwargs, message):
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    if kwargs.get("run_dir") == "RUN":
        kwargs["run_dir"] = tmp_path / "run"
    with pytest.raises(ValueError, match=message):
        run_batch([TINY], 0.002, **{"solver": MS_SOLVER, **kwargs})
    assert not list(tmp_path.iterdir())


def test_a_height_at_zero_is_refused_naming_its_place_in_the_batch(monkeypatch, tmp_path):
    """A batch of two topologies, the second robot's heights at 0: its group's check names it
    by its position in the batch (1), not in its group (0), before any compute or folder."""
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    tall = TINY.replace(n_arc=8, hub_height=0.02, foam_height=0.02, actuator_height=0.02)
    with pytest.raises(ValueError, match=r"^sensitivities: hub_height is 0 \(the 2.5-D model "
                                         r"off\) for instance 1;"):
        run_batch([tall, TINY], 0.002, solver=MS_SOLVER, sensitivities=("hub_height",),
                  run_dir=tmp_path / "run")
    assert not list(tmp_path.iterdir())


def test_shapes_of_two_topologies_of_one_duration_are_refused_before_compute(monkeypatch):
    """One duration, two topologies: refused for its topologies (the existing test's batch
    differs in duration too, which the other half of the check refuses)."""
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with pytest.raises(ValueError, match="^record_shapes needs one topology"):
        run_batch([TINY, ts.StarParams(n_arc=6, n_limb=3)], 0.002, solver=MS_SOLVER,
                  record_interval_s=0.001, record_shapes=True)


def test_a_resume_with_nothing_left_to_compute_names_no_idle_workers(tmp_path):
    """Idle workers are named where some chunks are to compute, fewer than the workers; a
    resumed run whose chunks are all stored computes none and says nothing of idle workers."""

    class NoWorkers(LocalProcesses):
        def run(self, tasks, progress=False):
            assert not tasks
            return iter([])

    folder = tmp_path / "run"
    first = run_batch([TINY], 0.002, solver=MS_SOLVER, run_dir=folder)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = run_batch([TINY], 0.002, solver=MS_SOLVER, run_dir=folder, resume=True,
                          executor=NoWorkers(2))
    assert [str(w.message) for w in caught if "stay idle" in str(w.message)] == []
    pd.testing.assert_frame_equal(again.summary, first.summary)


def test_a_resumed_runs_bar_of_chunks_starts_at_the_chunks_already_done(tmp_path, capsys):
    """A resume's bar counts the stored chunks as done: 2/2 at the end of a run of two chunks
    whose first was stored before (it said 1/2: the resumed chunk alone)."""

    class Stop(Exception):
        pass

    class FirstOnly:
        def run(self, tasks, progress=False):
            yield from InProcess().run(tasks[:1])
            raise Stop

    class Elsewhere:  # not an InProcess: the bar of chunks is shown even for one chunk
        def run(self, tasks, progress=False):
            assert [task.index for task in tasks] == [1]
            return InProcess().run(tasks)

    folder, params = tmp_path / "run", [TINY, ts.StarParams(n_arc=6, n_limb=2, alpha=0.5)]
    with pytest.raises(Stop):
        run_batch(params, 0.002, solver=MS_SOLVER, chunk_size=1, run_dir=folder,
                  executor=FirstOnly())
    capsys.readouterr()
    run_batch(params, 0.002, solver=MS_SOLVER, chunk_size=1, run_dir=folder, resume=True,
              executor=Elsewhere(), progress=True)
    bar = capsys.readouterr().err.split("\r")[-1]
    assert "chunks" in bar and "2/2" in bar


def test_a_batchs_trajectory_is_in_instance_order_whatever_its_chunks():
    """Instances grouped into chunks out of input order (by duration: instance 1 apart from 0
    and 2): the trajectory is sorted by instance and time all the same, numbered 0, 1, ..."""
    params = [ts.StarParams(n_arc=6, n_limb=2, period=p) for p in (0.2, 0.3, 0.2)]
    result = run_batch(params, cycles=0.01, solver=MS_SOLVER, record_interval_s=0.001)
    trajectory = result.trajectory
    assert sorted(set(trajectory["instance"])) == [0, 1, 2]
    keys = list(zip(trajectory["instance"], trajectory["t_s"]))
    assert keys == sorted(keys)
    assert trajectory.index.equals(pd.RangeIndex(len(trajectory)))


@pytest.mark.parametrize("timing", [dict(cycles=1), dict(duration_s=0.002)])
def test_a_batch_with_no_solverconfig_is_refused_naming_solver(monkeypatch, timing):
    """solver="x" with cycles: a ValueError naming solver, not an AttributeError from the
    step-count check that reads solver.adaptive first."""
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with pytest.raises(ValueError, match="^solver must be a SolverConfig, got str"):
        run_batch([TINY], solver="x", **timing)


def test_a_batchs_duration_off_the_step_grid_is_told_once_as_it_is_planned():
    """duration_s = 0.0015 s at 1-ms steps: the batch says so once (its chunks are told not
    to); on the grid, nothing."""
    with pytest.warns(RuntimeWarning) as caught:
        plan_chunks([TINY, TINY], 0.0015, solver=MS_SOLVER, chunk_size=1)
    said = [str(w.message) for w in caught if "whole number of steps" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("duration_s = 0.0015 s is not a whole number "
                                                 "of steps (dt = 0.001 s): 2 steps")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plan_chunks([TINY, TINY], 0.002, solver=MS_SOLVER, chunk_size=1)


def test_an_adaptive_batch_whose_duration_ends_just_short_of_a_cycle_says_so():
    """Three periods of 0.3 s held in float32 (0.8999999762 s) with adaptive steps leave out
    the last cycle from the steady speed: the batch warns, as simulate does."""
    adaptive = ts.SolverConfig(adaptive=True)
    with pytest.warns(Warning, match=r"short of 3 whole periods of 1 of 1 instances"):
        plan_chunks([ts.StarParams(n_arc=6, n_limb=2, period=0.3)], 0.8999999762,
                    solver=adaptive)


@pytest.mark.parametrize("cycles, shown", [
    (-10 ** 38, "-1" + "0" * 38),             # 40 characters: shown whole
    (-10 ** 39, "an integer of 40 digits")])  # 41: by its length
def test_a_refused_numbers_text_is_whole_up_to_40_characters(cycles, shown):
    with pytest.raises(ValueError) as error:
        run_batch([TINY], cycles=cycles, solver=MS_SOLVER)
    assert str(error.value) == f"cycles must be a finite number > 0, got {shown}"


@pytest.mark.parametrize("guard, guarded", [
    ('if __name__ == "__main__":', True), ('if "__main__" == __name__:', True),
    ('if __name__ == "__mian__":', False), ('if name == "__main__":', False)])
def test_only_a_real_main_guard_counts(tmp_path, monkeypatch, guard, guarded):
    """check_main_guard takes `__name__ == "__main__"` (either order) alone: any comparison
    with __name__ or with "__main__", a misspelt guard among them, lived through the suite (a
    mutation audit, 2026-12-07)."""
    from taichi_star.batch.executors import check_main_guard

    script = tmp_path / "script.py"
    script.write_text(f"name = 1\n{guard}\n    pass\n")
    monkeypatch.setattr(sys.modules["__main__"], "__file__", str(script), raising=False)
    if guarded:
        check_main_guard()
    else:
        with pytest.raises(RuntimeError, match="has no 'if __name__ == \"__main__\":' guard"):
            check_main_guard()


def test_one_chunk_in_this_process_shows_its_simulated_seconds_bar(capsys):
    """progress=True with one chunk in this process: no bar of chunks, the chunk's own bar of
    simulated seconds (InProcess dropping `progress`, nothing shown, lived through the suite:
    a mutation audit, 2026-12-07)."""
    run_batch([ts.StarParams(n_arc=6, n_limb=2)], 0.002, solver=ts.SolverConfig(),
              progress=True)
    err = capsys.readouterr().err
    assert "s simulated" in err and "chunks" not in err


def test_a_batch_warns_about_its_capped_ok_instances():
    """run_batch keeps its chunks' warnings to itself and warns once about the batch's 'ok'
    instances whose Newton solves ran out (its warning dropped lived through the suite: a
    mutation audit, 2026-12-07); a coarse A1 robot at dt = 10 ms, max_newton = 3 is ok and
    capped."""
    with pytest.warns(RuntimeWarning, match=r"^1 of 1 \w+ instances \(the first"):
        result = run_batch([ts.StarParams(n_arc=6, n_limb=2, gait="A1")], 0.1,
                           solver=ts.SolverConfig(dt=0.01, max_newton=3))
    assert result.summary["status"].tolist() == ["ok"]
    assert result.summary["newton_capped"].tolist() == [True]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_an_isolated_run_leaves_no_pool_running(deaths):
    """After a run that went on isolated (a worker died), its one-worker pools are shut down
    when the run ends, not left to the executor's shutdown (left running, each next run's
    isolation replacing them without stopping them, lived through the suite: a mutation
    audit, 2026-12-07)."""
    dying, folder = deaths
    (folder / "chunk_0").write_text("1")
    coarse = ts.StarParams(n_arc=6, n_limb=2)
    with dying(1, retries=1) as executor:
        result = run_batch([coarse, coarse.replace(alpha=0.5)], 0.002, chunk_size=1,
                           executor=executor)
        assert (folder / "chunk_0").read_text() == "0"  # chunk 0's worker died once
        assert executor._pools() == []
    assert result.summary["status"].tolist() == ["ok", "ok"]


# sensitivities: three coarse robots, the middle one of a shorter period (a group of its own
# under `cycles`: two durations, one topology, so one engine to build)
SENSITIVE = [TINY.replace(gait="A1", period=0.3), TINY.replace(gait="A1+A2", period=0.2),
             TINY.replace(gait="A1+A3", period=0.3, alpha=1.2)]
SENSITIVE_CALL = dict(solver=SOLVER, record_interval_s=0.02,
                      sensitivities=("alpha", "actuator_gains[0]"))


def _renumbered(table: pd.DataFrame, positions) -> pd.DataFrame:
    """A `simulate` call's sensitivities table with its instances numbered by their positions
    in a batch: a trajectory's instance column, a summary's rows."""
    table = table.copy()
    if "instance" in table:
        table["instance"] = np.asarray(positions)[table["instance"].to_numpy()]
    else:
        table.index = positions
    return table


def test_a_batchs_sensitivities_are_simulates_whatever_its_chunks_and_its_store(tmp_path):
    """run_batch(..., sensitivities=...) over 0.2 cycles of two periods (runs of 0.06 and
    0.04 s): every instance's derivatives, of the summary and of each record, are bitwise
    those of `simulate` on its duration's instances, in input order across the groups; a run
    store keeps them with each chunk, a resume reads them back for the chunks it did not
    compute, and a resume asking for others is another run (refused). The records' derivatives
    of instances with 4 and 3 records come from `sensitivity` on the union of their times, NaN
    where an instance has no record (it failed to reshape them), as `to_xarray` lays them."""
    from taichi_star.batch import RunStoreError
    same = ts.simulate([SENSITIVE[0], SENSITIVE[2]], 0.06, **SENSITIVE_CALL)
    short = ts.simulate([SENSITIVE[1]], 0.04, **SENSITIVE_CALL)
    expected = pd.concat([_renumbered(same.sensitivities, [0, 2]),
                          _renumbered(short.sensitivities, [1])]).sort_index()
    expected_records = pd.concat([
        _renumbered(same.trajectory_sensitivities, [0, 2]),
        _renumbered(short.trajectory_sensitivities, [1])]).sort_values(
            ["instance", "t_s"], kind="stable").reset_index(drop=True)
    # real derivatives, not zeros: α moves every gait, A1's gain every gait here (all fire A1)
    assert (expected.filter(like="d(displacement_x_mm)").abs() > 1e-6).all().all()
    run_dir = tmp_path / "run"
    whole = run_batch(SENSITIVE, cycles=0.2, chunk_size=1, run_dir=run_dir, **SENSITIVE_CALL)
    (run_dir / "chunk_000001.parquet").unlink()   # as if killed before chunk 1 was stored
    resumed = run_batch(SENSITIVE, cycles=0.2, chunk_size=1, run_dir=run_dir, resume=True,
                        **SENSITIVE_CALL)
    for result in (whole, resumed):
        pd.testing.assert_frame_equal(result.sensitivities, expected.reset_index(drop=True),
                                      check_exact=True)
        pd.testing.assert_frame_equal(result.trajectory_sensitivities, expected_records,
                                      check_exact=True)
        assert not [column for column in result.summary if column.startswith("d(")]
        assert result.trajectory.columns.tolist() == ["instance", "t_s", "x_mm", "y_mm",
                                                      "heading_deg"]
        assert result.arguments["sensitivities"] == ["alpha", "actuator_gains[0]"]
    np.testing.assert_array_equal(resumed.sensitivity("signed_speed_mm_s", "alpha"),
                                  expected["d(signed_speed_mm_s)/d(alpha)"].to_numpy())
    assert resumed.timing.robot_steps == 30   # chunk 1 alone (instance 2's 30 steps)
    for output in ("x_mm", "heading_deg"):
        column = f"d({output})/d(actuator_gains[0])"
        values = resumed.sensitivity(output, "actuator_gains[0]", trajectory=True)
        assert values.shape == (3, 4)   # records at 0, 0.02, 0.04 and (0 and 2 alone) 0.06 s
        for b in range(3):
            own = expected_records[expected_records["instance"] == b][column].to_numpy()
            np.testing.assert_array_equal(values[b, :len(own)], own)
        assert np.isnan(values[1, 3]) and not np.isnan(values[[0, 2], 3]).any()
    with pytest.raises(RunStoreError, match=r"\(sensitivities: \['alpha', 'actuator_gains\[0\]'\] "
                                            r"-> \['alpha'\]\)"):
        run_batch(SENSITIVE, cycles=0.2, chunk_size=1, run_dir=run_dir, resume=True,
                  **{**SENSITIVE_CALL, "sensitivities": ("alpha",)})


def test_a_batchs_sensitivities_without_records_have_simulates_empty_record_table(tmp_path):
    """No records: the trajectory sensitivities are simulate's empty table, column for column
    and type for type (the chunks' trajectories, empty, carry no columns of their own, and a
    run store keeps no trajectory file of them), also read back by a resume."""
    call = {**SENSITIVE_CALL, "record_interval_s": 0.0}
    direct = ts.simulate(SENSITIVE[:1], 0.02, **call)
    batch = run_batch(SENSITIVE[:1], 0.02, run_dir=tmp_path / "run", **call)
    resumed = run_batch(SENSITIVE[:1], 0.02, run_dir=tmp_path / "run", resume=True, **call)
    for result in (batch, resumed):
        pd.testing.assert_frame_equal(result.trajectory_sensitivities,
                                      direct.trajectory_sensitivities, check_exact=True)
        pd.testing.assert_frame_equal(result.sensitivities, direct.sensitivities,
                                      check_exact=True)
    assert resumed.timing.robot_steps == 0   # read back, not computed


def test_a_delay_on_the_step_grid_is_told_once_naming_its_place_in_the_batch():
    """The delay warning comes as the batch is planned, naming the robot by its position in
    the batch (a chunk's own check would name its place in the chunk, 0), once: the chunks'
    own checks, in simulate, say nothing more. The engine of the test above (two directions,
    chunks of one robot)."""
    robots = [SENSITIVE[0].replace(actuator_delays=(delay,) + (0.0,) * 7)
              for delay in (0.001, 0.003, 0.02)]   # the last on the 2-ms grid
    with warnings.catch_warnings(record=True) as told:
        warnings.simplefilter("always")
        tasks = plan_chunks(robots, 0.06, solver=SOLVER, chunk_size=1,
                            sensitivities=("alpha", "actuator_delays[0]"))
        result = run_batch(robots, 0.06, solver=SOLVER, chunk_size=1,
                           sensitivities=("alpha", "actuator_delays[0]"))
    on_grid = [str(w.message) for w in told if "on a step end" in str(w.message)]
    assert len(on_grid) == 2   # plan_chunks', then run_batch's own planning: one each
    assert all(message.startswith("sensitivities: actuator_delays[0] = 0.02 s (instance 2, 1 in "
                                  "all) puts the profile's onset") for message in on_grid)
    assert [task.sensitivities for task in tasks] == [("alpha", "actuator_delays[0]")] * 3
    assert [task.replicas for task in tasks] == [5, 5, 5]
    assert result.sensitivity("displacement_x_mm", "actuator_delays[0]").shape == (3,)


@pytest.mark.slow
def test_a_batchs_sensitivities_on_worker_processes_are_the_in_process_ones():
    """The chunks' tasks carry their sensitivities to worker processes (pickled) and back:
    the same derivatives, bit for bit, as in this process."""
    here = run_batch(SENSITIVE, 0.06, chunk_size=1, **SENSITIVE_CALL)
    there = run_batch(SENSITIVE, 0.06, chunk_size=1, workers=2, **SENSITIVE_CALL)
    pd.testing.assert_frame_equal(there.sensitivities, here.sensitivities, check_exact=True)
    pd.testing.assert_frame_equal(there.trajectory_sensitivities, here.trajectory_sensitivities,
                                  check_exact=True)
    pd.testing.assert_frame_equal(there.summary, here.summary, check_exact=True)
