"""The stability study: its outcome classification and summaries, and the study itself in --quick
mode (values against a direct simulation, outcome columns, plot). The shape checks it uses are
tested in tests/unit/test_metrics.py."""

import math

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star.metrics import shape_checks

from studies import stability
from studies.__main__ import main as studies_main


# ----------------------------------------------------------------------------- outcomes

def test_classify_orders_failed_insane_retried_ok():
    outcome = stability.classify(
        status=["ok", "ok", "ok", "newton_failed", "non_finite", "ok"],
        substep_retries=[0, 3, 0, 0, 2, 5],
        sane=[True, True, False, True, False, False])
    assert outcome.tolist() == ["ok", "retried-then-ok", "insane", "failed", "failed", "insane"]


@pytest.mark.parametrize("n_steps,dt,stride", [
    (12600, 0.5e-3, 120), (315, 20e-3, 3), (30, 20e-3, 3), (50, 1e-3, 50), (7, 1e-3, 7),
    (1260, 5e-3, 12), (13, 1e-4, 13)])
def test_record_stride_divides_the_run(n_steps, dt, stride):
    assert stability.record_stride(n_steps, dt) == stride
    assert n_steps % stride == 0


def test_paper_and_f32_summaries_from_a_synthetic_table():
    rows = []
    outcomes = {("f64", 1.0): "ok", ("f64", 5.0): "retried-then-ok", ("f64", 20.0): "failed",
                ("f32", 1.0): "insane", ("f32", 5.0): "ok", ("f32", 20.0): "failed"}
    for (precision, dt), outcome in outcomes.items():
        rows.append(dict(gait="A1", stiffness_factor=1.0, alpha=0.8, added_mass_coeff=1.0,
                         period_s=3.15, dt_ms=dt, precision=precision, outcome=outcome,
                         substep_retries=int(outcome == "retried-then-ok"),
                         speed_mm_s=1.0 if precision == "f64" else 1.05))
    table = pd.DataFrame(rows)
    paper = stability.paper_summary(table).set_index("precision")
    assert paper.loc["f64", "largest_ok_dt_ms"] == 1.0
    assert paper.loc["f64", "largest_stable_dt_ms"] == 5.0
    assert paper.loc["f64", "stable_up_to_dt_ms"] == 5.0
    assert paper.loc["f32", "largest_stable_dt_ms"] == 5.0
    assert math.isnan(paper.loc["f32", "stable_up_to_dt_ms"])  # insane at the smallest dt
    assert paper.loc["f32", "f32_rel_speed_diff_dt_5ms"] == pytest.approx(0.05)
    assert math.isnan(paper.loc["f32", "f32_rel_speed_diff_dt_1ms"])  # f32 not ok there
    f32 = stability.f32_summary(table).set_index("dt_ms")
    assert f32.loc[1.0, "n_f32_worse"] == 1 and f32.loc[5.0, "n_f32_better"] == 0
    assert f32.loc[20.0, "n_f32_worse"] == 0 and f32.loc[20.0, "n_f64_stable"] == 0
    # f32 breaks down where it is unstable and f64 is not (dt 1); not at dt 5 (stable, fewer
    # retries than f64, a 5 % speed difference is below the 10 % limit), nor where both
    # fail (dt 20)
    assert f32["f32_breaks_down"].to_dict() == {1.0: True, 5.0: False, 20.0: False}
    counts = stability.outcome_summary(table)
    total = counts[counts["scope"] == "all"].iloc[0]
    assert (total["n_ok"], total["n_retried_then_ok"], total["n_insane"], total["n_failed"]) == \
        (2, 1, 1, 2)


# ----------------------------------------------------------------------------- the study

def test_quick_stability_study(tmp_path):
    table = stability.main(["--quick", "--no-progress", "--out", str(tmp_path)])
    csv = pd.read_csv(tmp_path / "stability.csv")
    # 2 dt × 2 stiffness × 1 gait, f64
    assert len(csv) == len(table) == 4
    required = {"dt_ms", "stiffness_factor", "precision", "newton_tol_m", "gait", "alpha",
                "added_mass_coeff", "period_s", "youngs_modulus_pa", "status", "substep_retries",
                "newton_iterations_max", "max_strain", "limbs_cross", "arc_inverted",
                "limbs_cross_final", "arc_inverted_final", "sane", "outcome"}
    assert required <= set(csv.columns)
    assert set(csv["outcome"]) <= set(stability.OUTCOMES)
    assert set(csv["status"]) <= {"ok", "newton_failed", "non_finite"}
    assert sorted(csv["dt_ms"].unique()) == list(stability.QUICK_DTS_MS)
    assert sorted(csv["stiffness_factor"].unique()) == list(stability.QUICK_STIFFNESS)
    assert np.allclose(csv["youngs_modulus_pa"], csv["stiffness_factor"] * stability.BASE_MODULUS)
    assert (csv["duration_s"] == stability.QUICK_DURATION_S).all()
    # the first cell (dt 1 ms, stiffness x1) simulated directly, with the same records
    first = csv.iloc[0]
    solver = SolverConfig(dt=1e-3)
    direct = taichi_star.simulate([StarParams(gait="A1")], stability.QUICK_DURATION_S, solver,
                                  record_interval_s=first["record_every_steps"] * solver.dt,
                                  record_shapes=True)
    assert first["speed_mm_s"] == pytest.approx(direct.summary["speed_mm_s"].iloc[0], rel=1e-9)
    checks = shape_checks(direct.shapes, direct.topology).iloc[0]
    assert first["max_strain"] == pytest.approx(checks["max_strain"], rel=1e-9)
    assert first["sane"] == checks["sane"]
    assert (csv["outcome"] == stability.classify(csv["status"], csv["substep_retries"],
                                                 csv["sane"])).all()
    summary = pd.read_csv(tmp_path / "stability_summary.csv")
    total = summary[summary["scope"] == "all"].iloc[0]
    assert total["n_total"] == 4
    assert total[["n_ok", "n_retried_then_ok", "n_insane", "n_failed"]].sum() == 4
    png = tmp_path / "stability.png"
    assert png.exists() and png.stat().st_size > 1000
    assert (tmp_path / "stability_notes.txt").read_text().startswith("outcome counts")


@pytest.mark.parametrize("argv,match", [
    (["--dt", "0.001"], "unrecognized arguments: --dt"),
    (["--workers", "0"], "--workers"),
    (["--dts-ms", "0,1"], "--dts-ms"),
    (["--dts-ms", "0.7"], "does not divide"),
    (["--stiffness", "-1"], "--stiffness"),
    (["--precisions", "f16"], "--precisions"),
    (["--gaits", "A9"], "--gaits"),
    (["--alphas", "-1"], "alpha"),
    (["--cycles", "0"], "--cycles"),
    (["--periods", "nan"], "--periods"),
])
def test_bad_arguments_fail_before_compute(tmp_path, argv, match, monkeypatch, capsys):
    def no_compute(*args, **kwargs):
        raise AssertionError("simulate called before the arguments were validated")
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", no_compute)
    out = tmp_path / "out"
    assert studies_main(["stability", "--quick", "--no-progress", "--out", str(out), *argv]) == 2
    assert match in capsys.readouterr().err
    assert not out.exists()
