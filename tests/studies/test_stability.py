"""The stability study: its outcome classification and summaries, and the study itself in --quick
mode (values against a direct simulation, outcome columns, plot). The shape checks it uses are
tested in tests/unit/test_metrics.py."""

import math
from pathlib import Path

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


SCOPES = {"precision": ["precision"], "precision x dt": ["precision", "dt_ms"],
          "precision x dt x stiffness": ["precision", "dt_ms", "stiffness_factor"]}
COUNT_COLUMNS = {f"n_{name.replace('-', '_')}": name for name in stability.OUTCOMES}


def assert_outcome_counts(summary, table):
    """Every scope's n_* columns of an outcome summary against counts of the table's outcomes
    made here by value_counts over the scope's groups (one row per group, no other)."""
    assert list(summary["scope"].unique()) == ["all", *SCOPES]
    total = summary[summary["scope"] == "all"]
    assert len(total) == 1
    counts = table["outcome"].value_counts()
    assert {column: total[column].iloc[0] for column in COUNT_COLUMNS} == \
        {column: counts.get(name, 0) for column, name in COUNT_COLUMNS.items()}
    assert total["n_total"].iloc[0] == len(table)
    for scope, keys in SCOPES.items():
        got = summary[summary["scope"] == scope].set_index(keys)
        expected = (table.groupby(keys)["outcome"].value_counts().unstack(fill_value=0)
                    .reindex(columns=stability.OUTCOMES, fill_value=0))
        assert len(got) == len(expected)
        got = got.loc[expected.index]  # KeyError for a group missing from the summary
        for column, name in COUNT_COLUMNS.items():
            assert got[column].tolist() == expected[name].tolist(), (scope, column)
        assert got["n_total"].tolist() == table.groupby(keys).size()[expected.index].tolist()


def test_paper_and_f32_summaries_from_a_synthetic_table():
    rows = []
    base = dict(alpha=0.8, added_mass_coeff=1.0, period_s=3.15)
    outcomes = {("f64", 1.0): "ok", ("f64", 5.0): "retried-then-ok", ("f64", 20.0): "failed",
                ("f32", 1.0): "insane", ("f32", 5.0): "ok", ("f32", 20.0): "failed"}
    for (precision, dt), outcome in outcomes.items():
        rows.append(dict(gait="A1", stiffness_factor=1.0, **base, dt_ms=dt, precision=precision,
                         outcome=outcome, substep_retries=int(outcome == "retried-then-ok"),
                         speed_mm_s=1.0 if precision == "f64" else 1.05))
    # stiffness x10 (not the paper's): cells where both precisions are stable, for the retry
    # and speed clauses of f32_breaks_down; gait -> (f64 (outcome, speed), f32 (outcome, speed))
    retried, ok = "retried-then-ok", "ok"
    stable_cells = {
        1.0: {"A1": ((ok, 1.0), (retried, 1.0))},        # f32 retried, f64 not
        2.0: {"A1": ((retried, 1.0), (retried, 1.0))},   # both retried: as many retries
        # relative speed differences 0, 0.1 (|11 − 10| / 10 is 0.1 in IEEE), 0.5: median 0.1,
        # on the limit (mean and max are above it)
        5.0: {"A1": ((ok, 10.0), (ok, 10.0)), "A2": ((ok, 10.0), (ok, 11.0)),
              "A3": ((ok, 10.0), (ok, 15.0))},
        # the same with 0.1000001: the median is just above the limit (and below 0.5)
        10.0: {"A1": ((ok, 10.0), (ok, 10.0)), "A2": ((ok, 10.0), (ok, 11.000001)),
               "A3": ((ok, 10.0), (ok, 15.0))}}
    for dt, gaits in stable_cells.items():
        for gait, pair in gaits.items():
            for precision, (outcome, speed) in zip(("f64", "f32"), pair):
                rows.append(dict(gait=gait, stiffness_factor=10.0, **base, dt_ms=dt,
                                 precision=precision, outcome=outcome,
                                 substep_retries=int(outcome == retried), speed_mm_s=speed))
    table = pd.DataFrame(rows)
    paper = stability.paper_summary(table).set_index("precision")
    assert paper.loc["f64", "largest_ok_dt_ms"] == 1.0
    assert paper.loc["f64", "largest_stable_dt_ms"] == 5.0
    assert paper.loc["f64", "stable_up_to_dt_ms"] == 5.0
    assert paper.loc["f32", "largest_stable_dt_ms"] == 5.0
    assert math.isnan(paper.loc["f32", "stable_up_to_dt_ms"])  # insane at the smallest dt
    assert paper.loc["f32", "f32_rel_speed_diff_dt_5ms"] == pytest.approx(0.05)
    assert math.isnan(paper.loc["f32", "f32_rel_speed_diff_dt_1ms"])  # f32 not ok there
    f32 = stability.f32_summary(table).set_index(["stiffness_factor", "dt_ms"])
    paper_cells = f32.loc[1.0]
    assert paper_cells.loc[1.0, "n_f32_worse"] == 1 and paper_cells.loc[5.0, "n_f32_better"] == 0
    assert paper_cells.loc[20.0, "n_f32_worse"] == 0 and paper_cells.loc[20.0, "n_f64_stable"] == 0
    # f32 breaks down where it is unstable and f64 is not (dt 1); not at dt 5 (stable, fewer
    # retries than f64, a 5 % speed difference is below the 10 % limit), nor where both
    # fail (dt 20)
    assert paper_cells["f32_breaks_down"].to_dict() == {1.0: True, 5.0: False, 20.0: False}
    stiff = f32.loc[10.0]
    assert (stiff["n_f32_worse"] == 0).all()
    assert stiff["n_f32_retried"].tolist() == [1, 1, 0, 0]
    assert stiff["n_f64_retried"].tolist() == [0, 1, 0, 0]
    # the boundary is exact: the median at dt 5 is 0.1 itself, not a rounding of it
    assert stiff.loc[5.0, "median_rel_speed_diff"] == stability.F32_SPEED_LIMIT == 0.1
    assert stiff.loc[10.0, "median_rel_speed_diff"] > stability.F32_SPEED_LIMIT
    # more f32 retries than f64 breaks down (dt 1), as many does not (dt 2); a median relative
    # speed difference of exactly 10 % does not (dt 5), one just above it does (dt 10)
    assert stiff["f32_breaks_down"].to_dict() == {1.0: True, 2.0: False, 5.0: False,
                                                  10.0: True}
    counts = stability.outcome_summary(table)
    total = counts[counts["scope"] == "all"].iloc[0]
    # counted by hand: 2 + 1 + 6 + 6 ok, 1 + 1 + 2 retried, the insane f32 at dt 1, 2 failed
    assert (total["n_ok"], total["n_retried_then_ok"], total["n_insane"], total["n_failed"]) == \
        (15, 4, 1, 2)
    assert_outcome_counts(counts, table)


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
    # its outcome from the direct run's status, retries and sanity (the module docstring's
    # rule, written out here): the paper's settings at the default dt run clean
    status = direct.summary["status"].iloc[0]
    retries = direct.summary["substep_retries"].iloc[0]
    assert (first["status"], first["substep_retries"]) == (status, retries)
    expected = ("failed" if status != "ok" else "insane" if not checks["sane"]
                else "retried-then-ok" if retries > 0 else "ok")
    assert first["outcome"] == expected == "ok"
    assert (csv["outcome"] == stability.classify(csv["status"], csv["substep_retries"],
                                                 csv["sane"])).all()
    summary = pd.read_csv(tmp_path / "stability_summary.csv")
    total = summary[summary["scope"] == "all"].iloc[0]
    assert total["n_total"] == 4
    assert total[["n_ok", "n_retried_then_ok", "n_insane", "n_failed"]].sum() == 4
    assert_outcome_counts(summary, csv)
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


def test_the_notes_f32_median_is_over_the_pairs_not_the_cells_medians():
    """At one stiffness, a cell of three pairs that agree (relative difference 0) and a cell of
    one pair 100 % apart: the pairs' median is 0, the median of the cells' medians 0.5, which
    the notes printed (108 % and 2,440 % for the committed grid's 80 % and 1,010 %; an audit,
    2026-12)."""
    rows = []
    base = dict(alpha=0.8, added_mass_coeff=1.0, period_s=3.15, stiffness_factor=10.0)
    for dt, gaits in ((1.0, {"A1": 1.0, "A2": 1.0, "A3": 1.0}), (5.0, {"A1": 2.0})):
        for gait, f32_speed in gaits.items():
            for precision, speed in (("f64", 1.0), ("f32", f32_speed)):
                rows.append(dict(gait=gait, **base, dt_ms=dt, precision=precision,
                                 outcome="ok", substep_retries=0, speed_mm_s=speed,
                                 status="ok", sane=True, max_strain=0.01, cycles=2.0))
    table = pd.DataFrame(rows)
    notes = stability.report(table, stability.outcome_summary(table),
                             stability.paper_summary(table), stability.f32_summary(table))
    (line,) = [line for line in notes.splitlines() if line.strip().startswith("x10 ")]
    assert "median 0.00e+00," in line and "max 1.00e+00" in line


def test_the_committed_notes_are_the_reports_of_the_committed_tables():
    """results/stability_notes.txt is what `report` writes for the committed tables (its f32
    medians were a median of the cells' medians, which the study no longer takes, until the
    notes were rewritten from the tables: an audit, 2026-12)."""
    results = Path(__file__).resolve().parents[2] / "results"
    tables = [pd.read_csv(results / f"stability{suffix}.csv")
              for suffix in ("", "_summary", "_paper", "_f32")]
    assert (results / "stability_notes.txt").read_text() == stability.report(*tables) + "\n"
