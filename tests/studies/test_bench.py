"""The benchmark study in --quick mode (what it measures against direct simulations, row
counts, plots), and the benchmark and work-precision studies' argument errors, raised before
any computation (the work-precision study itself: test_work_precision.py). No timing is
asserted."""

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams, profiling
from taichi_star.experiment import PAPER_GAITS

from studies import bench, cli, work_precision
from studies.__main__ import main as studies_main


@pytest.mark.slow
def test_bench_quick(tmp_path, monkeypatch):
    written = []  # the row counts of every bench.csv written, in order
    write_csv = cli.Output.write_csv

    def recording_write_csv(output, frame, name, extra=None):
        written.append(len(frame))
        return write_csv(output, frame, name, extra)

    monkeypatch.setattr(cli.Output, "write_csv", recording_write_csv)
    bench.main(["--quick", "--no-progress", "--out", str(tmp_path),
                "--kernel-optimisation", "off,on"])
    table = pd.read_csv(tmp_path / "bench.csv")
    assert list(table.columns) == bench.COLUMNS
    # `--lanes auto` (the default): each row records its engine's, one at a time for these
    # small batches and short calls (`Runtime.engine_lanes`)
    assert (table["lanes"] == 1).all()
    # the table is rewritten after every measurement (a run stopped by a time limit keeps
    # what it measured), then once whole
    assert written == [*range(1, len(table) + 1), len(table)]
    # Taichi's IR optimisation passes change the speed, never the bits: every batch size ends
    # in the same state with them on and off (the faster-compiling default loses nothing)
    by_setting = table[table["section"] == "batch"].groupby("kernel_optimisation")
    assert list(by_setting["final_state"].apply(list)["off"]) == \
        list(by_setting["final_state"].apply(list)["on"])
    table = table[table["kernel_optimisation"] == "off"]
    batch = table[table["section"] == "batch"]
    skip = table[table["section"] == "skip"]
    plain = table[table["section"] == "plain"]
    assert len(table) == len(batch) + len(skip) + 1  # --quick: no cache-probe rows
    # the plain call is simulate() with the default solver: its iterations are those of the
    # same call made here
    batch_size = int(plain["batch_size"].iloc[0])
    default = taichi_star.simulate(
        [StarParams(gait=PAPER_GAITS[i % 5]) for i in range(batch_size)],
        int(plain["steps"].iloc[0]) * bench.DT)
    assert plain["jacobian"].iloc[0] == taichi_star.SolverConfig().jacobian
    # the CSV keeps 10 significant digits (5e-10 relative): 2.366666667 of 71/30 updates a step
    assert plain["newton_iterations_mean"].iloc[0] == pytest.approx(
        default.summary["newton_iterations_mean"].mean(), rel=1e-9)
    assert list(batch["batch_size"]) == [int(b) for b in bench.QUICK_BATCH_SIZES.split(",")]
    assert list(skip["scenario"]) == bench.QUICK_SCENARIOS.split(",")
    assert (table["arch"] == "cpu").all() and (table["precision"] == "f64").all()
    assert (table["n_nodes"] == 193).all()
    # the Newton iterations of the timed window are those of the same steps simulated directly
    steps = int(table["steps"].iloc[0])
    solver = bench.bench_solver("f64")
    params = [StarParams(gait=bench.GAIT)]
    before = taichi_star.simulate(params, bench.WARMUP_STEPS * solver.dt, solver).summary
    after = taichi_star.simulate(params, (bench.WARMUP_STEPS + steps) * solver.dt,
                                 solver).summary
    window = (after["newton_iterations_mean"].iloc[0] * (bench.WARMUP_STEPS + steps)
              - before["newton_iterations_mean"].iloc[0] * bench.WARMUP_STEPS) / steps
    assert batch["newton_iterations_mean"].iloc[0] == pytest.approx(window, rel=1e-9)
    # added mass is inertia, not a force term: both quick scenarios share one compiled engine
    terms = dict(zip(skip["scenario"], skip["terms"].str.split("+")))
    assert terms["added_mass_0"] == terms["all_terms"] and "stretching" in terms["all_terms"]
    assert plain["robot_steps_per_s"].iloc[0] > 0
    assert plain["time_to_first_step_s"].iloc[0] > 0  # the first call's wall time, recorded
    assert plain["final_state"].iloc[0] == bench.state_digest(np.column_stack(
        [default.summary[output].to_numpy() for output in bench.DISPLACEMENTS]))
    engine_rows = table[table["section"] != "plain"]  # the plain call has no phase split
    for column in ("robot_steps_per_s", "assembly_us", "residual_us", "factor_flops"):
        assert (engine_rows[column] > 0).all(), column
    # Newton's Jacobian factors at every iteration (the engine's own count)
    assert batch["factorisations_mean"].tolist() == batch["newton_iterations_mean"].tolist()
    # the paper rows' reference rate, timed before each, and the factorisation's share of it
    assert (batch["matmul_gflops"] > 0).all() and skip["matmul_gflops"].isna().all()
    np.testing.assert_allclose(batch["factor_fraction_of_matmul"],
                               batch["factor_gflops"] / batch["matmul_gflops"], rtol=1e-9)
    assert (tmp_path / "bench.png").stat().st_size > 1000


@pytest.mark.slow
def test_the_plain_call_of_another_jacobian_mode_is_that_call_made_directly():
    """`--plain-jacobians lagged`: the plain (and sensitivities) section's call with
    SolverConfig(jacobian="lagged"), its iterations, factorisations and digest those of the same
    call made here (and not those of Newton's Jacobian)."""
    (figures,) = bench.measure_plains(5, 0.05, 1, [(("alpha",), "lagged")])
    params = [StarParams(gait=PAPER_GAITS[i % 5]) for i in range(5)]
    direct = taichi_star.simulate(params, 0.05, taichi_star.SolverConfig(jacobian="lagged"),
                                  sensitivities=("alpha",))
    newton = taichi_star.simulate(params, 0.05, sensitivities=("alpha",))
    assert figures["jacobian"] == "lagged"
    for column in ("newton_iterations_mean", "factorisations_mean"):
        assert figures[column] == pytest.approx(direct.summary[column].mean(), rel=1e-12)
    assert figures["factorisations_mean"] != pytest.approx(
        newton.summary["factorisations_mean"].mean(), rel=1e-3)
    assert figures["final_state"] == bench.state_digest(np.column_stack(
        [direct.summary[output].to_numpy() for output in bench.DISPLACEMENTS]
        + [direct.sensitivity(output, "alpha") for output in bench.DISPLACEMENTS]))


class _Result:
    """What the plain sections read of a `SimulationResult`: its summary, topology and
    sensitivities (values of no meaning: the digest's input)."""

    def __init__(self, status="ok"):
        self.summary = pd.DataFrame({"status": [status] * 2, "displacement_x_mm": [1.0, 2.0],
                                     "displacement_y_mm": [3.0, 4.0],
                                     "newton_iterations_mean": [2.0, 2.0],
                                     "factorisations_mean": [1.0, 1.0]})
        self.topology = SimpleNamespace(n_nodes=7)

    def sensitivity(self, output, name):
        return np.array([0.5, 0.25])


def test_interleaved_calls_warm_each_call_then_time_every_call_in_each_round():
    log = []

    def call(label, status="ok"):
        def made():
            log.append(label)
            return _Result(status)
        return made

    results, times, firsts = bench.interleaved_calls(
        [call("a"), call("b")], 3, [call("warm a"), None])
    # b has no warm-up of its own: its call warms it; then a, b in every round, in turn
    assert log == ["warm a", "b", "a", "b", "a", "b", "a", "b"]
    assert times.shape == (3, 2) and (times >= 0).all() and len(firsts) == 2
    assert all(isinstance(result, _Result) for result in results)
    with pytest.raises(RuntimeError, match="not valid"):
        bench.interleaved_calls([call("a"), call("c", status="failed")], 1, [None, None])


def test_sensitivity_costs_are_ratios_to_newtons_forward_call_in_the_same_rounds(monkeypatch):
    # rounds (rows) of three calls: the forward call (Newton, none), and two differentiating
    times = np.array([[1.0, 2.0, 1.5],
                      [2.0, 3.0, 2.5]])
    monkeypatch.setattr(bench, "interleaved_calls", lambda calls, repeats, warmups: (
        [_Result() for _ in calls], times, [0.1] * len(calls)))
    rows = bench.measure_plains(2, 0.002, 2, [((), "newton"), (("alpha",), "lagged"),
                                              (("alpha",), "newton")])
    assert "cost_in_forward_runs" not in rows[0]
    # the ratio of the best calls, and the median of the rounds' ratios (2 and 1.5; 1.5 and 1.25)
    assert rows[1]["cost_in_forward_runs"] == pytest.approx(2.0, rel=1e-12)
    assert rows[1]["cost_in_forward_runs_median"] == pytest.approx(1.75, rel=1e-12)
    assert rows[2]["cost_in_forward_runs"] == pytest.approx(1.5, rel=1e-12)
    assert rows[2]["cost_in_forward_runs_median"] == pytest.approx(1.375, rel=1e-12)
    # against the call of its own mode: Newton's is the forward call, lagged has none here
    assert rows[2]["cost_in_own_forward_runs"] == pytest.approx(1.5, rel=1e-12)
    assert "cost_in_own_forward_runs" not in rows[1]
    # each row's throughput from its own best call: 2 instances × 2 steps
    assert [row["robot_steps_per_s"] for row in rows] == pytest.approx([4 / 1.0, 4 / 2.0, 4 / 1.5])
    # without Newton's forward call among them, no cost in forward runs (a lagged forward call
    # is not it), but the lagged row's cost in its own: 2 and 3 against 1 and 2, the best 2 / 1
    rows = bench.measure_plains(2, 0.002, 2, [((), "lagged"), (("alpha",), "lagged"),
                                              (("alpha",), "newton")])
    assert not any("cost_in_forward_runs" in row for row in rows)
    assert rows[1]["cost_in_own_forward_runs"] == pytest.approx(2.0, rel=1e-12)
    assert "cost_in_own_forward_runs" not in rows[2]


def test_the_sensitivities_section_differentiates_by_the_first_n_parameters_named(monkeypatch):
    """--sensitivity-parameters: one label per direction (a per-actuator field its eight, in
    actuator order), every count from 0 to their number taken."""
    args = bench.parse_args(["--sensitivity-parameters", "alpha,actuator_gains",
                             "--sensitivity-counts", "0,1,9"])
    assert args.sensitivity_parameters == ["alpha"] + [f"actuator_gains[{k}]" for k in range(8)]
    assert args.sensitivity_counts == [0, 1, 9]
    assert bench.parse_args([]).sensitivity_parameters == list(bench.SENSITIVITY_PARAMETERS)


def test_a_sensitivities_row_records_the_parameters_it_differentiated_by(tmp_path, monkeypatch):
    calls = []

    def measured(batch, duration, repeats, configurations):
        calls.extend(configurations)
        return [{"robot_steps_per_s": 1.0} for _ in configurations]

    monkeypatch.setattr(bench, "measure_plains", measured)
    # the B sweep's and the scenario's measurements stand in too: the rows of the sensitivities
    # section are what is asked (test_bench_quick, slow tier, measures them all; compiling two
    # engines here took ~5 s of the suite)
    monkeypatch.setattr(bench, "measure", lambda *args, **kwargs: {
        "robot_steps_per_s": 1.0, "bytes_per_step": 1.0, "factor_gflops": 1.0})
    bench.main(["--quick", "--no-progress", "--out", str(tmp_path), "--scenarios", "none",
                "--no-plain-call", "--sensitivity-parameters", "alpha,actuator_gains[1]",
                "--sensitivity-counts", "0,2"])
    assert [(list(names), jacobian) for names, jacobian in calls] == [
        ([], "newton"), (["alpha", "actuator_gains[1]"], "newton")]
    rows = pd.read_csv(tmp_path / "bench.csv", keep_default_na=False)
    rows = rows[rows["section"] == "sensitivities"]
    assert list(rows["scenario"]) == ["sensitivities_0", "sensitivities_2"]
    assert list(rows["sensitivity_parameters"]) == ["", "alpha actuator_gains[1]"]


def test_step_phases_count_the_jacobian_only_where_the_matrix_is_refreshed():
    """Every iteration assembles its residual and solves; only the iterations that refresh the
    Newton matrix assemble the Jacobian (assembly − residual per iteration) and factor."""
    phase = {"residual": 2.0, "assembly": 8.0, "factor": 3.0, "solve": 1.5}
    # Newton's Jacobian: every phase once per iteration
    assert profiling.step_phases(phase, 2.0, 2.0) == {
        "residual": 4.0, "assembly": 16.0, "factor": 6.0, "solve": 3.0}
    # the chord's: 2.5 iterations, 1.25 of them refreshing: 2.5 residuals, 1.25 Jacobians of
    # 6 µs, 1.25 factorisations, 2.5 solves (every figure exact in binary)
    assert profiling.step_phases(phase, 2.5, 1.25) == {
        "residual": 5.0, "assembly": 12.5, "factor": 3.75, "solve": 3.75}


def test_phase_bars_keep_one_bar_per_setting_and_split_the_assembly():
    row = {"section": "batch", "scenario": "all_terms", "batch_size": 512, "precision": "f64",
           "jacobian": "newton", "preset": "paper", "lanes": 1, "kernel_optimisation": "on",
           "layout": "instance_major", "block_dim": 1, "robot_steps_per_s": 40000.0,
           "assembly_us": 12.0, "residual_us": 4.0, "factor_us": 5.0, "solve_us": 2.0,
           "bookkeeping_us": 1.0}
    rows = pd.DataFrame([row,
                         dict(row, robot_steps_per_s=45000.0, assembly_us=11.0),  # a faster round
                         dict(row, lanes=8, solve_us=1.0),  # another setting: its own bar
                         dict(row, jacobian="chord")])
    part, names, split = bench.phase_bars(rows, "B={batch_size} {jacobian} {lanes}")
    assert names == ["B=512 newton 1", "B=512 newton 8", "B=512 chord 1"]
    assert list(split) == ["residual", "Jacobian", "factor", "solve", "bookkeeping"]
    # the faster round of the first setting, its assembly cut at the residual
    assert split["Jacobian"].tolist() == [7.0, 8.0, 8.0]
    assert split["solve"].tolist() == [2.0, 1.0, 2.0]
    # a table from before the residual was timed apart: the assembly whole
    _, _, whole = bench.phase_bars(rows.drop(columns="residual_us"), "{lanes}")
    assert list(whole) == ["assembly", "factor", "solve", "bookkeeping"]
    assert whole["assembly"].tolist() == [11.0, 12.0, 12.0]


def test_matmul_rate_is_the_products_flops_over_its_best_time(monkeypatch):
    """2·n³ floating-point operations over the fastest of three products."""
    clock = iter([0.0, 0.5, 1.0, 1.25, 2.0, 3.0])  # three products of 0.5, 0.25 and 1 s
    monkeypatch.setattr(profiling.time, "perf_counter", lambda: next(clock))
    rate = profiling.matmul_gflops(100, "f64", np.random.default_rng(0))
    assert rate == pytest.approx(2 * 100 ** 3 / 0.25 / 1e9, rel=1e-12)


@pytest.mark.parametrize("study, argv, message", [
    ("bench", ["--batch-sizes", "0"], "--batch-sizes: every value must be >= 1"),
    ("bench", ["--sensitivity-parameters", "alpha,bogus"],
     "--sensitivity-parameters: sensitivities: 'bogus' is not a StarParams field"),
    ("bench", ["--sensitivity-parameters", "alpha", "--sensitivity-counts", "0,2"],
     "--sensitivity-counts: each count must be in [0, 1] (--sensitivity-parameters), got 2"),
    ("bench", ["--batch-sizes", "8,x"], "--batch-sizes: 'x' is not an integer"),
    ("bench", ["--batch-sizes", ""], "--batch-sizes: empty"),
    ("bench", ["--precisions", "f16"], "--precisions: precision must be one of"),
    ("bench", ["--jacobians", "broyden"], "--jacobians: jacobian must be one of"),
    ("bench", ["--plain-jacobians", "broyden"], "--plain-jacobians: jacobian must be one of"),
    ("bench", ["--steps", "0"], "--steps must be in [1, 100000], got 0"),
    ("bench", ["--repeats", "0"], "--repeats must be in [1, "),
    ("bench", ["--scenarios", "no_jet"], "--scenarios: unknown value 'no_jet'"),
    ("bench", ["--scenario-batch", "-1"], "--scenario-batch must be in [1, 1048576], got -1"),
    ("bench", ["--workers-list", "0"], "--workers-list: every value must be >= 1"),
    ("bench", ["--kernel-optimisation", "fast"], "--kernel-optimisation: unknown value 'fast'"),
    ("bench", ["--meshes", "1"], "--meshes: every n_arc must be in [2, 1000], got 1"),
    ("bench", ["--meshes", "18,1001"], "--meshes: every value must be in [1, 1000], got 1001"),
    ("work_precision", ["--cycles", "0"], "--cycles must be > 0"),
    ("work_precision", ["--gaits", "A1,A9"], "unknown actuator 'A9'"),
    ("work_precision", ["--gaits", "A1,A1"], "listed twice"),
])
def test_invalid_arguments_fail_before_compute(monkeypatch, tmp_path, capsys, study, argv,
                                               message):
    def forbidden(*args, **kwargs):
        raise AssertionError("computation started despite invalid arguments")
    monkeypatch.setattr(bench, "measure", forbidden)
    monkeypatch.setattr(work_precision, "run_config", forbidden)
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--out", str(out), "--quick"]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert not out.exists()  # nothing written


def test_the_mesh_section_measures_the_robot_on_each_n_arc_at_the_scenario_batch(monkeypatch):
    """--meshes 2,1000 (both ends of n_arc's range): one row per n_arc, section "mesh", of
    --scenario-batch robots of the benchmark gait on that mesh (65 and 8,049 nodes), measured
    as the B sweep is; none without the flag."""
    measured = []

    def fake_measure(params, arch, precision, steps, repeats, profile_seconds,
                     jacobian="newton"):
        measured.append(params)
        return {"n_nodes": params[0].n_nodes, "robot_steps_per_s": 1.0, "factor_gflops": 1.0,
                "bytes_per_step": 1.0}

    monkeypatch.setattr(bench, "measure", fake_measure)
    monkeypatch.setattr(bench, "matmul_gflops", lambda *args: 1.0)
    flags = ["--quick", "--no-progress", "--no-plain-call", "--scenarios", "none",
             "--scenario-batch", "3"]
    table = bench.run_bench(bench.parse_args([*flags, "--meshes", "2,1000"]))
    mesh = table[table["section"] == "mesh"]
    assert list(mesh["scenario"]) == ["n_arc_2", "n_arc_1000"]
    assert list(mesh["n_nodes"]) == [65, 8049] and (mesh["batch_size"] == 3).all()
    robots = measured[-2:]
    assert [len(params) for params in robots] == [3, 3]
    assert [{(p.n_arc, p.gait) for p in params} for params in robots] == \
        [{(2, bench.GAIT)}, {(1000, bench.GAIT)}]
    assert "mesh" not in set(bench.run_bench(bench.parse_args(flags))["section"])


def test_gpu_arch_without_a_gpu_lists_the_available_archs(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr("taichi_star.runtime.available_archs", lambda: ["cpu"])
    for study in ("bench", "work_precision"):
        assert studies_main([study, "--arch", "gpu", "--quick", "--out", str(tmp_path)]) == 2
        error = capsys.readouterr().err
        assert "--arch gpu: no such backend on this machine; available archs: cpu" in error
    assert not any(tmp_path.iterdir())


def test_engine_profile_refuses_an_adaptive_solver_before_compute(monkeypatch):
    """EngineProfile times fixed steps: an adaptive solver is a ValueError naming `solver`,
    raised before Taichi or an engine is touched."""
    def forbidden(*args, **kwargs):
        raise AssertionError("the model was built or Taichi started despite the refusal")

    monkeypatch.setattr(profiling, "build_model", forbidden)
    monkeypatch.setattr(profiling.Runtime, "ensure", forbidden)
    with pytest.raises(ValueError, match=r"^solver: EngineProfile times fixed steps; got an "
                                         r"adaptive solver \(profile it end to end with "
                                         r"simulate\)$"):
        taichi_star.EngineProfile([StarParams()], SolverConfig.preset("accurate"))


def test_the_compile_probe_imports_the_study_from_where_this_process_does(tmp_path):
    """A process started as `python -c` in the checkout (its path's first entry empty: the
    current folder) gives a fresh process in another folder, under the probe's PYTHONPATH, the
    bench study as it named it, from the same file. Installed, the probe had put the taichi_star
    package folder itself on PYTHONPATH (an audit, 2026-12)."""
    inner = f"import {bench.__name__} as b; print(b.__file__)"
    outer = (f"import os, subprocess, sys; import {bench.__name__} as bench; "
             f"run = subprocess.run([sys.executable, '-c', {inner!r}], cwd={str(tmp_path)!r}, "
             f"env=dict(os.environ, PYTHONPATH=bench.import_path()), capture_output=True, "
             f"text=True); print(run.stdout.strip() or run.stderr[-500:])")
    environment = {name: value for name, value in os.environ.items() if name != "PYTHONPATH"}
    run = subprocess.run([sys.executable, "-c", outer], cwd=Path(bench.__file__).parents[1],
                         env=environment, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert Path(run.stdout.strip().splitlines()[-1]).resolve() == Path(bench.__file__).resolve()
