"""The predictability study: its quick run against plain simulations and a finite-difference
Jacobian (the standard errors by another route than the sensitivities), and its refusals."""

import math
import types

import numpy as np
import pandas as pd
import pytest

from taichi_star import SolverConfig, StarParams, identification, simulate

from studies import cli, identify
from studies import predictability as study
from studies.__main__ import main as studies_main

QUICK_GAITS = ("A1+A2", "A1+A3")
QUICK_NAMES = ("alpha", "drag_perpendicular")
WINDOW = (1, 1)
STEP = 1e-3
"""Relative step of the central differences. The runs converge each step to newton_tol 1e-10 m,
and a step moves the path by ~1e-3 × 1 mm = 1e-6 m: noise ~1e-4 of a difference, truncation
(the step squared) ~1e-6."""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One quick run: A1+A2 and A1+A3 measured, A2 predicted, α and C⊥, cycle 1 at 2 ms. Its cost
    is the compilation of the engine that carries tangents (about a minute on 2 cores)."""
    out = tmp_path_factory.mktemp("predictability")
    table = study.main(["--quick", "--no-progress", "--out", str(out)])
    return out, table


def _runs(params, base_solver):
    result = simulate(params, WINDOW[1] * params[0].period, base_solver,
                      record_interval_s=identify.RECORD_INTERVAL_S, progress=False)
    return identification.result_runs(result, params)


@pytest.mark.slow
def test_quick_run_against_plain_runs_and_a_finite_difference_jacobian(run):
    out, _ = run
    written = pd.read_csv(out / "predictability.csv")
    assert list(zip(written["gait"], written["role"])) == [
        ("A1+A2", "fitted"), ("A1+A3", "fitted"), ("A1+A2", "held_out"), ("A1+A3", "held_out"),
        ("A2", "unmeasured")]
    assert (written["status"] == "ok").all()
    base = StarParams.preset("identified")
    solver = SolverConfig.preset("identified", dt=cli.QUICK_DT)
    gaits = list(QUICK_GAITS) + ["A2"]
    trials = identification.measured_trials(QUICK_GAITS)
    centre = dict(zip(gaits, _runs([base.replace(gait=g) for g in gaits], solver)))
    fits = identification.trajectory_objective({g: centre[g] for g in QUICK_GAITS}, trials,
                                               WINDOW)
    phases = dict(zip(fits["gait"], fits["phase_s"]))
    for row in written.itertuples():
        # the instances of a run with sensitivities are bitwise those of the run without; the
        # CSV keeps 10 significant digits
        fit = identification.trial_fit(centre[row.gait], trials[row.gait], WINDOW) \
            if row.gait in trials else None
        speed = (fit.sim_speed_mm_s if fit else
                 identification.window_speed(centre[row.gait],
                                             np.zeros((len(centre[row.gait].path.t_s), 2, 1)),
                                             WINDOW)[0])
        assert row.predicted_speed_mm_s == pytest.approx(speed, rel=1e-9)
        path = centre[row.gait].path
        ends = path.position(np.array([WINDOW[0] - 1, WINDOW[1]]) * path.period_s)
        distance = np.hypot(*(ends[1] - ends[0])) / ((WINDOW[1] - WINDOW[0] + 1) * path.period_s)
        assert row.distance_speed_mm_s == pytest.approx(distance, rel=1e-9)
        assert row.distance_speed_mm_s >= abs(row.predicted_speed_mm_s) * (1 - 1e-9)
        if fit:
            assert row.measured_speed_mm_s == pytest.approx(
                trials[row.gait].paper_sign * fit.meas_speed_mm_s, rel=1e-9)
    # the residuals' Jacobian (phases held at the centre's) and A2's speed gradient by central
    # differences of whole runs, one batch of the four moved points
    values = np.array([base.alpha, base.drag_perpendicular])
    moved = [base.replace(**{name: value * (1 + sign * STEP)})
             for name, value in zip(QUICK_NAMES, values) for sign in (1.0, -1.0)]
    runs = _runs([p.replace(gait=g) for p in moved for g in gaits], solver)
    columns, speed_gradient, curve_columns = [], [], []
    for k in range(len(QUICK_NAMES)):
        ends = []
        for side in range(2):
            part = dict(zip(gaits, runs[(2 * k + side) * 3:(2 * k + side + 1) * 3]))
            residuals, _, _ = identification.objective_residuals(
                {g: part[g] for g in QUICK_GAITS},
                {g: np.zeros((len(part[g].path.t_s), 2, 1)) for g in QUICK_GAITS}, trials,
                WINDOW, phases=phases)
            ends.append((residuals, identification.window_speed(
                part["A2"], np.zeros((len(part["A2"].path.t_s), 2, 1)), WINDOW)[0],
                identification.cycle_curves(part["A2"].path, 0.0, WINDOW,
                                            identification.SAMPLES_PER_CYCLE).ravel()))
        width = 2 * STEP * values[k]
        columns.append((ends[0][0] - ends[1][0]) / width)
        speed_gradient.append((ends[0][1] - ends[1][1]) / width)
        curve_columns.append((ends[0][2] - ends[1][2]) / width)
    jacobian, gradient = np.stack(columns, axis=1), np.array(speed_gradient)
    residuals, _, _ = identification.objective_residuals(
        {g: centre[g] for g in QUICK_GAITS},
        {g: np.zeros((len(centre[g].path.t_s), 2, 1)) for g in QUICK_GAITS}, trials, WINDOW,
        phases=phases)
    variance = residuals @ residuals / (len(residuals) - 2)
    expected = math.sqrt(variance * gradient @ np.linalg.inv(jacobian.T @ jacobian) @ gradient)
    a2 = written[written["role"] == "unmeasured"].iloc[0]
    # the differences' noise (~1e-4, STEP) carried through an inverse of condition ~4
    assert a2["standard_error_mm_s"] == pytest.approx(expected, rel=2e-3)
    parameters = pd.read_csv(out / "predictability_parameters.csv")
    assert parameters["parameter"].tolist() == list(QUICK_NAMES)
    np.testing.assert_allclose(parameters["value"], values, rtol=1e-9)
    errors = np.sqrt(variance * np.diag(np.linalg.inv(jacobian.T @ jacobian)))
    np.testing.assert_allclose(parameters["standard_error"], errors, rtol=2e-3)
    assert (out / "predictability.png").stat().st_size > 0
    # the design: A2's trial taken as made, its rows the differences of its cycle curves over
    # σ·√(samples) (σ the measured trials' median, at its floor on one cycle), over √2 as
    # the fit of two gaits weighs each; the fit's own s²
    design = pd.read_csv(out / "predictability_design.csv")
    assert list(dict.fromkeys(design["added_trials"])) == ["none", "A2"]
    sigma = float(np.median(fits["sigma_mm"]))
    assert (design.loc[design["added_trials"] == "A2", "added_sigma_mm"] == sigma).all()
    curves = np.stack(curve_columns, axis=1)
    added = curves / (sigma * math.sqrt(len(curves))) / math.sqrt(2)
    normal = jacobian.T @ jacobian + added.T @ added
    expected = math.sqrt(variance * gradient @ np.linalg.inv(normal) @ gradient)
    own = design[(design["added_trials"] == "A2") & (design["role"] == "added")].iloc[0]
    assert own["gait"] == "A2"
    # as above: the differences' noise through an inverse of condition ~4
    assert own["standard_error_mm_s"] == pytest.approx(expected, rel=2e-3)
    assert own["standard_error_mm_s"] < a2["standard_error_mm_s"]
    none = design[design["added_trials"] == "none"].drop(columns=["added_trials",
                                                                  "added_sigma_mm"])
    pd.testing.assert_frame_equal(none.reset_index(drop=True), written, check_exact=False,
                                  rtol=1e-12)
    assert (out / "predictability_design.png").stat().st_size > 0
    # the parameters with A2's trial: the normal equations' errors of the same matrices
    parameter_design = pd.read_csv(out / "predictability_design_parameters.csv")
    with_a2 = parameter_design[parameter_design["added_trials"] == "A2"]
    assert with_a2["parameter"].tolist() == list(QUICK_NAMES)
    np.testing.assert_allclose(with_a2["standard_error"],
                               np.sqrt(variance * np.diag(np.linalg.inv(normal))), rtol=2e-3)
    plain = parameter_design[parameter_design["added_trials"] == "none"]
    np.testing.assert_allclose(plain["standard_error"], parameters["standard_error"],
                               rtol=1e-12)


@pytest.mark.slow
def test_the_returned_table_is_the_written_one(run):
    out, table = run
    written = pd.read_csv(out / "predictability.csv")
    within = "within_two_standard_errors"  # empty for an unmeasured gait: None, read as NaN
    pd.testing.assert_frame_equal(written.drop(columns=within), table.drop(columns=within),
                                  check_exact=False, rtol=1e-9, check_dtype=False)
    assert written[within].isna().tolist() == table[within].isna().tolist() == [False] * 4 + [
        True]
    assert written[within].iloc[:4].tolist() == table[within].iloc[:4].tolist()


@pytest.mark.parametrize("flags, message", [
    (["--window", "3:2"], "--window: "),
    (["--window", "1-3"], "--window: expected FIRST:LAST"),
    (["--gaits", "A1"], "--gaits: at least two measured gaits"),
    (["--gaits", "A1,A2"], "--gaits A2: not measured"),
    (["--predict", "A1+A2"], "--predict A1+A2: it is one of --gaits"),
    (["--predict", "A1+A2+A3+A4+A5+A6+A7+A8"], "a gait with no forward axis"),
    (["--parameters", "alpha,nope"], "--parameters: "),
    (["--window", "1:40"], "--window 1:40: "),
    (["--predict-window", "4:x"], "--predict-window: expected FIRST:LAST"),
    (["--predict-window", "30:31"], "--predict-window 30:31: "),
    (["--window", "1:3:5"], "--window: expected FIRST:LAST, two whole numbers"),
    (["--window", "1.5:3"], "--window: expected FIRST:LAST, two whole numbers"),
    (["--predict", "none,A2"], "--predict none,A2: none stands alone"),
    (["--trial-sigma", "0.049"], "--trial-sigma must be >= 0.05 mm (the tracking noise"),
    (["--trial-sigma", "-0.1"], "--trial-sigma must be >= 0.05 mm"),
    (["--predict", "none", "--trial-sigma", "0.5"], "--trial-sigma: only with gaits to --predict"),
    (["--predict", "none", "--max-trials", "2"], "--max-trials: only with gaits to --predict"),
    (["--trial-sigma", "nan"], "--trial-sigma: 'nan' is not a finite number"),
    (["--trial-sigma", "wide"], "--trial-sigma: 'wide' is not a number"),
    (["--max-trials", "0"], "--max-trials must be >= 1, got 0"),
    (["--max-trials", "two"], "--max-trials: invalid int value: 'two'"),
    # 11 gaits, at most 5: 1,023 sets (allowed, ≤ 1,024); at most 6: 1,485
    (["--predict", "A2,A3,A4,A5,A6,A7,A8,A2+A3,A2+A4,A2+A5,A3+A4", "--max-trials", "6"],
     "--max-trials 6 over the 11 --predict gaits asks for 1485 sets of trials, more than 1024"),
])
def test_bad_flags_are_refused_in_one_line_before_any_compute(flags, message, tmp_path,
                                                                capsys):
    out = tmp_path / "out"
    assert studies_main(["predictability", "--no-progress", "--out", str(out)] + flags) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error and "Traceback" not in error
    assert not out.exists()


def _with_status(result, instance: int, status: str, time_s: float):
    """The result with one instance's summary marked failed (its records stay as they ran: a
    flagged instance's records can be finite, and `result_runs` reads the status)."""
    summary = result.summary.copy()
    summary.loc[instance, "status"] = status
    summary.loc[instance, "failure_time_s"] = time_s
    return types.SimpleNamespace(trajectory=result.trajectory, summary=summary,
                                 trajectory_sensitivities=result.trajectory_sensitivities)


@pytest.mark.slow
def test_a_failed_run_is_named_and_left_out_never_dropped(run):
    """A predicted gait whose run failed keeps its row, with the failure's reason and time and
    no numbers, and the others are computed as without it; a measured gait that failed leaves
    fewer than two to fit: refused, naming it."""
    base = StarParams.preset("identified")
    solver = SolverConfig.preset("identified", dt=cli.QUICK_DT)
    gaits = list(QUICK_GAITS) + ["A2"]
    params = [base.replace(gait=g) for g in gaits]
    result = simulate(params, WINDOW[1] * base.period, solver,
                      record_interval_s=identify.RECORD_INTERVAL_S, sensitivities=QUICK_NAMES,
                      progress=False)
    values = study.parameter_values(base, QUICK_NAMES)
    measured, names = list(QUICK_GAITS), list(QUICK_NAMES)
    whole, _ = study.predictability_table(study.runs_that_ran(result, params, measured, names),
                                          measured, names, values, WINDOW)
    with pytest.warns(RuntimeWarning, match=r"A2: the simulation diverged at 1\.23 s; left out"):
        ran = study.runs_that_ran(_with_status(result, 2, "diverged", 1.234), params, measured,
                                  names)
    table, _ = study.predictability_table(ran, measured, names, values, WINDOW)
    failed = table[table["gait"] == "A2"]
    assert failed["status"].tolist() == ["diverged at 1.23 s"]
    assert failed["role"].tolist() == ["unmeasured"]
    assert failed["predicted_speed_mm_s"].isna().all()
    kept = table[table["gait"] != "A2"].reset_index(drop=True)
    pd.testing.assert_frame_equal(kept, whole[whole["gait"] != "A2"].reset_index(drop=True),
                                  check_dtype=False)
    # the design keeps the failed candidate's row once, under no trial added, and has no set
    # with it
    design, parameter_design = study.design_tables(ran, measured, ["A2"], names, values, WINDOW)
    assert set(design["added_trials"]) == set(parameter_design["added_trials"]) == {"none"}
    failed_rows = design[design["gait"] == "A2"]
    assert failed_rows["status"].tolist() == ["diverged at 1.23 s"]
    assert failed_rows["predicted_speed_mm_s"].isna().all()
    with pytest.warns(RuntimeWarning, match="A1\\+A3: the simulation"), \
            pytest.raises(cli.StudyOutputError, match=r"fewer than two measured gaits ran "
                                                      r"\(A1\+A3 failed\)"):
        study.runs_that_ran(_with_status(result, 1, "diverged", 0.5), params, measured, names)


@pytest.mark.slow
def test_the_design_flags_reach_the_tables(tmp_path):
    """--trial-sigma sets the spread of every trial taken as made, and --max-trials the sets:
    with A2 and A3 predicted and at most one trial, none, A2 and A3 (no pair); a wider spread
    weighs a trial less, so A2's own error grows."""
    flags = ["--quick", "--no-progress", "--predict", "A2,A3"]
    tables = {}
    for sigma in ("0.05", "0.5"):
        out = tmp_path / sigma
        study.main(flags + ["--trial-sigma", sigma, "--max-trials", "1", "--out", str(out)])
        tables[sigma] = pd.read_csv(out / "predictability_design.csv")
        design = tables[sigma]
        assert list(dict.fromkeys(design["added_trials"])) == ["none", "A2", "A3"]
        assert (design.loc[design["added_trials"] != "none", "added_sigma_mm"]
                == float(sigma)).all()
    own = {sigma: table[(table["added_trials"] == "A2") & (table["role"] == "added")]
           ["standard_error_mm_s"].iloc[0] for sigma, table in tables.items()}
    assert own["0.5"] > own["0.05"]
    # the summary: one row per set, as design_summary makes it from the table, with its sidecar
    summary = pd.read_csv(tmp_path / "0.5" / "predictability_design_summary.csv")
    pd.testing.assert_frame_equal(summary, identification.design_summary(tables["0.5"]),
                                  check_exact=False, rtol=1e-9)
    assert summary["added_trials"].tolist() == ["none", "A2", "A3"]
    assert (tmp_path / "0.5" / "predictability_design_summary.csv.json").exists()
    assert (tmp_path / "0.5" / "predictability_design_parameters.png").stat().st_size > 0


def test_the_parameter_plot_marks_a_parameter_the_fit_would_not_determine(tmp_path):
    """A hand-made parameter design with a parameter not identifiable with nothing added and
    identifiable with a trial: the plot is drawn (its cells "not id." and "12 %"), from a
    table without a sidecar too."""
    rows = [{"added_trials": trials, "parameter": "alpha", "identifiable": identifiable,
             "relative_standard_error": error}
            for trials, identifiable, error in (("none", False, math.inf), ("A4", True, 0.12))]
    path = tmp_path / "design_parameters.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    written = study.plot_parameter_design(path, tmp_path / "design_parameters.png")
    assert written.stat().st_size > 0


def test_the_design_size_is_checked_at_the_librarys_count():
    """11 gaits to predict: at most 5 trials (1,023 sets) is allowed, 6 (1,485) refused; a
    count above the candidates is every subset (4 gaits, at most 9: 15 sets, allowed)."""
    study.check_design_size(5, 11)
    study.check_design_size(9, 4)
    with pytest.raises(cli.StudyArgumentError, match="asks for 1485 sets of trials"):
        study.check_design_size(6, 11)
