"""The stability study: its outcome classification and summaries, and the study itself in --quick
mode (values against a direct simulation, outcome columns, plot). The shape checks it uses are
tested in tests/unit/test_metrics.py."""

import math
import signal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star import timegrid
from taichi_star.metrics import shape_checks

from studies import cli, stability
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


def test_delays_set_beyond_the_presets_period_fit_the_swept_periods():
    """--set actuator_delays past the preset's 3.15-s period, within every swept period: the
    grid is built on them (refused, naming the preset's period, until 2026-12: an audit)."""
    late = ["--set", "actuator_delays=0,0,0,0,0,0,0,4", "--gaits", "A1", "--dts-ms", "1"]
    batches = stability.plan(cli.parse(stability.build_parser(),
                                       ["--quick", "--periods", "5,6", *late]))
    assert {p.actuator_delays[7] for batch in batches for p in batch["params"]} == {4.0}
    assert sorted({p.period for batch in batches for p in batch["params"]}) == [5.0, 6.0]
    assert batches[0]["base"].actuator_delays[7] == 4.0
    with pytest.raises(cli.StudyArgumentError, match=r"actuator_delays\[7\]"):
        stability.plan(cli.parse(stability.build_parser(), ["--quick", "--periods", "3.5,5",
                                                            *late]))


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


# ----------------------------------------------------------------------------- before any compute

class PastTheChecks(Exception):
    """The study got past its checks to the stubbed next step: nothing is built or run."""


def past_the_checks(*args, **kwargs):
    raise PastTheChecks


def no_instances_built(*args, **kwargs):
    raise AssertionError("the grid's instances were built before its work was checked")


def test_the_whole_grids_robot_steps_are_refused_before_its_instances_are_built(
        no_compute, monkeypatch, tmp_path, capsys):
    """Each batch (precision × period × dt) was checked alone, so a grid past the library's
    limit started (an audit, 2026-12): 100 α × the default grid for 100,000 cycles, every
    batch under the limit, is 1.2e13 robot-steps in all, counted here batch by batch."""
    monkeypatch.setattr(stability, "grid_params", no_instances_built)
    out = tmp_path / "out"
    argv = ["--cycles", "100000", "--alphas", "0:1.5:100", "--no-progress", "--out", str(out)]
    assert studies_main(["stability", *argv]) == 2
    per_batch = 3 * 5 * 100 * 3                    # gaits × stiffness × α × C_a
    steps = sum(round(100000 * period / (dt_ms * 1e-3)) for period in (0.3, 3.15)
                for dt_ms in (0.5, 1, 2, 5, 10, 20))
    robot_steps = 2 * per_batch * steps            # f64 and f32
    error = capsys.readouterr().err
    assert (f"error: the grid of 108,000 instances (--dts-ms 6 × --stiffness 5 × --alphas 100 × "
            f"--added-mass 3 × --periods 2 × --gaits 3 × --precisions 2) for --cycles 100000 of "
            f"each period is {robot_steps:.3g} robot-steps: about ") in error
    assert robot_steps == pytest.approx(1.2e13, rel=0.01) and len(error.splitlines()) == 1
    assert not out.exists()


QUICK_GRID = ("the grid of 4 instances (--dts-ms 2 × --stiffness 2 × --alphas 1 × --added-mass "
              "1 × --periods 1 × --gaits 1 × --precisions 1) for --quick (0.05 s)")


@pytest.mark.parametrize("limit, value, refused, told", [
    ("REFUSE_ROBOT_STEPS", 109, True, False), ("REFUSE_ROBOT_STEPS", 110, False, False),
    ("WARN_ROBOT_STEPS", 109, False, True), ("WARN_ROBOT_STEPS", 110, False, False)])
def test_the_grids_robot_steps_are_summed_over_its_batches(no_compute, monkeypatch, tmp_path,
                                                           checked_run, limit, value, refused,
                                                           told):
    """--quick's two stiffnesses at dt 1 and 10 ms for 0.05 s: 2 × 50 + 2 × 5 = 110 robot-steps
    in two batches of at most 100, refused or told past a limit of 109, not at 110 (the rule is
    "over"); told before any instance is built (`grid_params` builds them; the robot's
    parameters, whose mesh weighs the work, are read first)."""
    stub, run = checked_run
    monkeypatch.setattr(timegrid, limit, value)
    monkeypatch.setattr(stability, "grid_params", stub)
    error, said = run(["stability", "--quick", "--no-progress", "--dts-ms", "1,10", "--out",
                       str(tmp_path / "out")], refused)
    assert (f"error: {QUICK_GRID} is 110 robot-steps: about " in error) == refused
    assert said == ([f"{QUICK_GRID} is 110 robot-steps: about {110 / 5e4 / 3600:.3g} h at 50000 "
                     f"robot-steps/s (on a 2-core CPU; a GPU or more cores run faster)"]
                    if told else [])


DTS_RANGE = "--dts-ms: every value must be in (0, 50] ms, got "
STIFFNESS_RANGE = ("--stiffness: every factor must be in [0.0002, 2000] (youngs_modulus = "
                   "factor × 5e+06 Pa must be in [1000, 1e+10] Pa), got ")


@pytest.mark.parametrize("argv, message", [
    # a step in ms was refused in s ("dt must be a real number in (0, 0.05], got 1.0"), a
    # factor by youngs_modulus's range in Pa (an audit, 2026-12)
    (["--dts-ms", "1000"], DTS_RANGE + "1000"),
    (["--dts-ms", "50.0001"], DTS_RANGE + "50.0001"),
    (["--dts-ms", "1,0"], DTS_RANGE + "0"),
    (["--stiffness", "1e12"], STIFFNESS_RANGE + "1e+12"),
    (["--stiffness", "2000.0001"], STIFFNESS_RANGE + "2000.0001"),
    (["--stiffness", "0.00019999"], STIFFNESS_RANGE + "0.00019999"),
])
def test_steps_and_stiffness_factors_are_refused_in_their_own_units(no_compute, tmp_path, capsys,
                                                                    argv, message):
    out = tmp_path / "out"
    assert studies_main(["stability", "--quick", "--no-progress", "--out", str(out), *argv]) == 2
    error = capsys.readouterr().err
    assert error.strip().endswith(f"error: {message}") and len(error.splitlines()) == 1, error
    assert not out.exists()


@pytest.mark.parametrize("argv", [["--dts-ms", "50"], ["--dts-ms", "0.001"],
                                  ["--stiffness", "2000"], ["--stiffness", "0.0002"]])
def test_steps_and_stiffness_factors_at_the_ends_of_their_ranges_are_accepted(
        no_compute, monkeypatch, tmp_path, argv):
    """The longest step (one of --quick's 0.05 s), a step far below a millisecond and the
    factors at youngs_modulus's ends (1000 and 1e10 Pa) get past every check of the values,
    youngs_modulus's own among them, to the building of the grid (stubbed)."""
    monkeypatch.setattr(stability, "grid_params", past_the_checks)
    with pytest.raises(PastTheChecks):
        studies_main(["stability", "--quick", "--no-progress", "--out", str(tmp_path), *argv])


@pytest.mark.parametrize("flags, chunk_size", [
    ([], 2048), (["--workers", "1"], 2048), (["--workers", "2"], 17), (["--workers", "3"], 12),
    (["--workers", "2", "--chunk-size", "5"], 5)])
def test_a_batch_is_cut_to_give_every_worker_about_four_chunks(monkeypatch, tmp_path, flags,
                                                               chunk_size):
    """A batch of 135 instances (3 gaits × 5 stiffnesses × 3 α × 3 C_a) was one chunk, so
    --workers 2 left a worker idle (an audit, 2026-12): ceil(135 / (4 × workers)) now, the
    default chunk size (2048) for one, --chunk-size as given."""
    chosen = []

    def first_batch(params, duration_s, **options):
        chosen.append((len(params), options["chunk_size"]))
        raise PastTheChecks
    monkeypatch.setattr(stability, "run_batch", first_batch)
    with pytest.raises(PastTheChecks):
        stability.main(["--dts-ms", "1", "--periods", "3.15", "--precisions", "f64",
                        "--no-progress", "--out", str(tmp_path), *flags])
    assert chosen == [(135, chunk_size)]


def synthetic_grid(stiffness_factor: float, precisions) -> pd.DataFrame:
    """A per-instance table as `run_grid` returns it (the columns the summaries, the notes and
    the tables read): gait A1 at the paper's α, C_a and period, dt 1 and 2 ms, all ok."""
    rows = [dict(instance=0, gait="A1", alpha=0.8, added_mass_coeff=1.0, period_s=3.15,
                 stiffness_factor=stiffness_factor, dt_ms=dt, precision=precision,
                 outcome="ok", substep_retries=0, speed_mm_s=1.0, status="ok", sane=True,
                 max_strain=0.01, cycles=2.0)
            for precision in precisions for dt in (1.0, 2.0)]
    return pd.DataFrame(rows).assign(instance=lambda table: range(len(table)))


def run_on(monkeypatch, table, out) -> int:
    """The study's command line, its grid's run (and its plot) replaced by `table`."""
    monkeypatch.setattr(stability, "run_grid", lambda batches, **options: table)
    monkeypatch.setattr(stability, "plot_maps", lambda table, path: Path(path))
    return studies_main(["stability", "--quick", "--no-progress", "--out", str(out)])


COMPANIONS = ("stability_paper.csv", "stability_paper.csv.json", "stability_f32.csv",
              "stability_f32.csv.json")


def test_a_later_run_removes_the_companion_tables_it_has_no_rows_for(monkeypatch, tmp_path):
    """A run at the paper's parameters in both precisions writes the paper and f32 tables with
    their sidecars; a later run into the same folder at another stiffness in f64 alone has no
    rows for either, and removes them (they were left beside its own tables, read as its
    results: an audit, 2026-12)."""
    assert run_on(monkeypatch, synthetic_grid(1.0, ["f64", "f32"]), tmp_path) == 0
    assert all((tmp_path / name).is_file() for name in COMPANIONS)
    assert run_on(monkeypatch, synthetic_grid(10.0, ["f64"]), tmp_path) == 0
    assert [name for name in COMPANIONS if (tmp_path / name).exists()] == []
    assert set(pd.read_csv(tmp_path / "stability.csv")["stiffness_factor"]) == {10.0}
    assert "paper parameters" not in (tmp_path / "stability_notes.txt").read_text()


def test_the_notes_are_written_whole_or_not_at_all(monkeypatch, tmp_path, capsys):
    """Notes that cannot be written whole (past a file size limit here, as on a full disk)
    leave the earlier run's as they were, and the study says so on one line; `write_text`
    truncated them first, then failed with a traceback (an audit, 2026-12)."""
    resource = pytest.importorskip("resource")
    notes = tmp_path / "stability_notes.txt"
    notes.write_text("the earlier run's notes\n")
    limit = 4096
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)

    def long_notes(*tables):  # the tables are written: from here on files stop at `limit`
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
        return "x" * (2 * limit)
    monkeypatch.setattr(stability, "report", long_notes)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past it fails instead
    try:
        code = run_on(monkeypatch, synthetic_grid(1.0, ["f64"]), tmp_path)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)
    assert code == 2
    assert notes.read_text() == "the earlier run's notes\n"
    error = capsys.readouterr().err
    assert error.strip().endswith(f"error: --out {tmp_path}: cannot write stability_notes.txt "
                                  f"(File too large); the files written before are intact")
    assert [path.name for path in tmp_path.glob(".stability_notes*")] == []


@pytest.mark.parametrize("study, told", [("stability", False), ("sensitivity", False),
                                         ("sweep", True), ("fig4c", True)])
def test_the_steady_speeds_warning_is_told_by_the_studies_that_report_them(
        monkeypatch, study, told):
    """A study whose tables hold no steady speeds leaves their SteadySpeedWarning unsaid
    (stability's grid, a varied period, a --dt: "a dt that divides the period" to no purpose,
    a review, 2026-12); fig4c, gaits and sweep tell it. The study's run is a stand-in that
    warns, then one other RuntimeWarning, which every study tells."""
    import importlib
    import warnings

    from studies import STEADY_SPEED_STUDIES, study_names

    assert set(STEADY_SPEED_STUDIES) <= set(study_names())  # a renamed one would go unsaid
    module = importlib.import_module(f"studies.{study}")

    def warning_run(argv):
        warnings.warn("steady speeds NaN", taichi_star.SteadySpeedWarning)
        warnings.warn("another", RuntimeWarning)

    monkeypatch.setattr(module, "main", warning_run)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert studies_main([study]) == 0
    said = [str(warning.message) for warning in caught]
    assert said == (["steady speeds NaN", "another"] if told else ["another"])


def test_a_grid_with_periods_off_its_steps_runs_without_the_steady_speeds_warning():
    """stability's grid runs 3.15-s periods at 20-ms steps on purpose, and does not read the
    steady speeds: their SteadySpeedWarning said "a dt that divides the period" gives them (a
    review, 2026-12). Within `cli.steady_speeds_unread` it says nothing, and other warnings
    still do."""
    import warnings

    robot = StarParams(gait="A1", n_arc=6, n_limb=2, period=0.1635)
    with pytest.warns(taichi_star.SteadySpeedWarning, match="not a whole number of steps"):
        taichi_star.simulate([robot], 0.33)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with cli.steady_speeds_unread():
            taichi_star.simulate([robot], 0.33)
            warnings.warn("another", RuntimeWarning)
    assert [str(warning.message) for warning in caught] == ["another"]
