"""The benchmark and work-precision studies in --quick mode (CSV schema, row counts, plots) and
their argument errors, raised before any computation. No timing is asserted."""

import numpy as np
import pandas as pd
import pytest

from studies import bench, work_precision
from studies.__main__ import main as studies_main


def test_bench_quick(tmp_path):
    bench.main(["--quick", "--no-progress", "--out", str(tmp_path)])
    table = pd.read_csv(tmp_path / "bench.csv")
    assert list(table.columns) == bench.COLUMNS
    batch = table[table["section"] == "batch"]
    skip = table[table["section"] == "skip"]
    assert len(table) == len(batch) + len(skip)  # --quick: no cache-probe rows
    assert list(batch["batch_size"]) == [int(b) for b in bench.QUICK_BATCH_SIZES.split(",")]
    assert list(skip["scenario"]) == bench.QUICK_SCENARIOS.split(",")
    assert (table["arch"] == "cpu").all() and (table["precision"] == "f64").all()
    assert (table["n_nodes"] == 193).all() and (table["cores"] >= 1).all()
    assert table["commit"].str.len().min() >= 7
    for column in ("robot_steps_per_s", "step_us", "newton_iterations_mean", "assembly_us",
                   "factor_flops"):
        assert (table[column] > 0).all(), column
    # factor and solve are differences of timings: finite, of either sign under noise
    assert np.isfinite(table[["factor_us", "solve_us", "bookkeeping_us"]]).all().all()
    assert np.allclose(table["real_time_factor"], table["robot_steps_per_s"] * table["dt_s"])
    # the phases and the bookkeeping add up to the measured step
    parts = table[["assembly_us", "factor_us", "solve_us", "bookkeeping_us"]].sum(axis=1)
    assert np.allclose(parts, table["step_us"])
    assert (tmp_path / "bench.png").stat().st_size > 1000


def test_work_precision_quick(tmp_path):
    work_precision.main(["--quick", "--no-progress", "--out", str(tmp_path)])
    table = pd.read_csv(tmp_path / "work_precision.csv")
    configs = work_precision.configurations(quick=True)
    gaits = list(work_precision.QUICK_GAITS)
    assert len(table) == (len(configs) + 1) * len(gaits)
    assert table.groupby("config")["gait"].apply(list).map(lambda g: g == gaits).all()
    reference = table[table["varied"] == "reference"]
    assert len(reference) == len(gaits) and (reference["rel_error"] == 0).all()
    assert (reference["dt_s"] == 1.25e-4).all() and (reference["discretisation"] == "2x").all()
    rest = table[table["varied"] != "reference"]
    assert (rest["status"] == "ok").all()
    assert (rest["rel_error"] > 0).all() and (rest["run_time_s"] > 0).all()
    per_config = rest.groupby("config").agg(largest=("rel_error", "max"),
                                            reported=("max_rel_error", "first"))
    assert np.allclose(per_config["largest"], per_config["reported"])
    assert rest["pareto"].any() and not reference["pareto"].any()
    assert set(rest["integrator"]) == set(work_precision.INTEGRATORS)
    orders = pd.read_csv(tmp_path / "work_precision_orders.csv")
    assert list(orders.columns) == work_precision.ORDER_COLUMNS
    assert set(orders["integrator"]) == set(work_precision.INTEGRATORS)
    assert set(orders["gait"]) == set(gaits) | {"max"}
    assert (tmp_path / "work_precision.png").stat().st_size > 1000


def test_pareto_front():
    run_time = [1.0, 2.0, 3.0, 4.0, 0.5]
    error = [0.1, 0.2, 0.01, np.nan, 0.3]
    assert list(work_precision.pareto_front(run_time, error)) == [True, False, True, False, True]


def test_convergence_order_of_a_power_law():
    h = np.array([1e-3, 2e-3, 4e-3])
    rows = pd.DataFrame({"varied": "dt_s", "precision": "f64", "newton_tol": 1e-10,
                         "integrator": "euler", "discretisation": "2x", "dt_s": h,
                         "gait": "A1", "rel_error": 3.0 * h ** 2, "max_rel_error": 3.0 * h ** 2})
    orders = work_precision.convergence_orders(rows)
    assert list(orders["gait"]) == ["A1", "max"]
    for column in ("order_fit", "order_fine", "order_coarse"):
        assert orders[column].to_numpy() == pytest.approx([2.0, 2.0])


@pytest.mark.parametrize("study, argv, message", [
    ("bench", ["--batch-sizes", "0"], "--batch-sizes: every batch size must be >= 1"),
    ("bench", ["--batch-sizes", "8,x"], "--batch-sizes: 'x' is not an integer"),
    ("bench", ["--batch-sizes", ""], "--batch-sizes: empty"),
    ("bench", ["--precisions", "f16"], "--precisions: unknown precision 'f16'"),
    ("bench", ["--steps", "0"], "--steps must be >= 1"),
    ("bench", ["--repeats", "0"], "--repeats must be >= 1"),
    ("bench", ["--scenarios", "no_jet"], "--scenarios: unknown scenario 'no_jet'"),
    ("bench", ["--scenario-batch", "-1"], "--scenario-batch must be >= 1"),
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


def test_gpu_arch_without_a_gpu_lists_the_available_archs(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "available_archs", lambda: ["cpu"])
    for study in ("bench", "work_precision"):
        assert studies_main([study, "--arch", "gpu", "--quick", "--out", str(tmp_path)]) == 2
        error = capsys.readouterr().err
        assert "--arch gpu: no such backend on this machine; available archs: cpu" in error
    assert not any(tmp_path.iterdir())
