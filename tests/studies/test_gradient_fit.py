"""The gradient-fit study's arguments: every bad one refused before any simulation, one line
on stderr, exit code 2 (its numbers come from identification.objective_and_gradient, tested in
tests/unit/test_identification_gradient.py, and from the committed run in results/)."""

import math
import time

import numpy as np
import pandas as pd
import pytest

import taichi_star
from studies import cli, gradient_fit, identify
from studies.__main__ import main as studies_main
from taichi_star import SolverConfig, StarParams, identification
from taichi_star.experiment import PAPER_GAITS


def test_the_study_gradient_adds_the_phases_motion_and_least_squares_does_not(monkeypatch):
    """L-BFGS-B's gradient is 2·Jᵀr plus the phases' motion (that of the re-fitted objective);
    the least-squares fit gets the residuals and the held-phase Jacobian alone."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 3),
                                   SolverConfig(), "cpu")
    rng = np.random.default_rng(5)
    residuals, jacobian, motion = rng.normal(size=7), rng.normal(size=(7, 6)), rng.normal(size=6)
    monkeypatch.setattr(problem, "fit_terms", lambda units: (residuals, jacobian, motion))
    value, gradient = problem.value_and_gradient(np.full(6, 0.5))
    assert value == residuals @ residuals
    np.testing.assert_array_equal(gradient, 2.0 * jacobian.T @ residuals + motion)
    got_residuals, got_jacobian = problem.residuals_and_jacobian(np.full(6, 0.5))
    assert got_residuals is residuals and got_jacobian is jacobian


@pytest.mark.parametrize("parameter_set", ["6", "20fired"])
def test_the_uncertainty_is_taken_per_unit_of_each_value_on_linear_and_log_axes(
        monkeypatch, parameter_set):
    """Problem.uncertainty turns the unit coordinates' Jacobian into one per unit of each value
    (÷ (high − low) on a linear axis, ÷ value·ln(high/low) on a log axis) before
    identification.parameter_uncertainty: the fake fit's Jacobian is built per value and
    multiplied out, and the table must equal the library's on the per-value one. Its rows are
    labelled as the box's axes (an actuator counted from 1, as in --sets and the study's other
    tables), though the sensitivities asked for count from 0."""
    box = [identify.parse_range_spec(text, "--sets")
           for text in gradient_fit.PARAMETER_SETS[parameter_set]]
    assert any(spec.log for spec in box) and not all(spec.log for spec in box)
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 1),
                                   SolverConfig(), "cpu")
    count = len(box)
    units = np.linspace(0.2, 0.7, count)
    values = identify.box_values(box, units[None, :])[0]
    rng = np.random.default_rng(11)
    residuals, per_value = rng.normal(size=40), rng.normal(size=(40, count))
    per_unit = per_value * np.array([spec.high - spec.low if not spec.log
                                     else value * np.log(spec.high / spec.low)
                                     for spec, value in zip(box, values)])
    monkeypatch.setattr(problem, "fit_terms",
                        lambda point: (residuals, per_unit, np.zeros(count)))
    labels = [spec.label for spec in box]
    expected = identification.parameter_uncertainty(residuals, per_value, labels, values)
    # the round trip per value → per unit → per value rounds each entry by an ulp; the SVD
    # turns that into up to cond × 1e-16 of its results: the 20-axis box's relative Jacobian
    # has cond ≈ 3e9 here (its values span 1e-3 to 1e7), so 1e-9; measured 5e-12
    pd.testing.assert_frame_equal(problem.uncertainty(units), expected, rtol=1e-9)
    if parameter_set == "20fired":
        assert "actuator_gains[1]" in labels and "actuator_gains[0]" in problem.names
        assert labels.index("actuator_gains[1]") == problem.names.index("actuator_gains[0]")


def test_a_polish_starts_at_cma_best_point_and_counts_its_cost_on_top(monkeypatch):
    """The polish recorder carries CMA-ES's robot-seconds (both counts), wall time and best
    point; least squares then starts at that point (its first simulation), and its rows add each
    call to CMA-ES's totals; its best stays CMA-ES's until a call beats it."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    cma = gradient_fit.Recorder("6", "CMA-ES")
    cma_best = np.full(6, 0.3)
    for units, objective in ((np.full(6, 0.9), 9.0), (cma_best, 4.0), (np.full(6, 0.6), 5.0)):
        cma.add(units, objective, 10.0, 10.0)
    cma.rows[-1]["wall_s"] = 7.0  # as if CMA-ES had run for 7 s
    polish = gradient_fit.Recorder.continuing(cma, gradient_fit.POLISH)
    assert (polish.robot_seconds, polish.cost_equivalent) == (30.0, 30.0)
    assert polish.best_objective == 4.0 and np.array_equal(polish.best_units, cma_best)
    assert polish.best_units is not cma.best_units
    assert time.perf_counter() - polish.started >= 7.0
    # residuals r = u − 0.5: the minimum (0 at u = 0.5) is one Gauss-Newton step away
    points = []
    monkeypatch.setattr(problem, "residuals",
                        lambda units: points.append(np.array(units)) or np.asarray(units) - 0.5)
    monkeypatch.setattr(problem, "residuals_and_jacobian",
                        lambda units: points.append(np.array(units))
                        or (np.asarray(units) - 0.5, np.eye(6)))
    gradient_fit.fit_least_squares(problem, [polish.best_units], 5, polish, cost_ratio=2.0)
    np.testing.assert_array_equal(points[0], cma_best)
    first, second = polish.rows[:2]
    # the point's own value (6 · 0.2² = 0.24), below CMA-ES's 4.0: it becomes the best
    assert first["objective"] == pytest.approx(0.24) == first["best_objective"]
    window = base.period
    # its residuals and Jacobian: one run with the sensitivities, 1 + 2·6 instances, 2 runs
    # cost-equivalent; the next trial point's residuals: one run
    assert first["robot_seconds"] == pytest.approx(30.0 + window * 13)
    assert first["robot_seconds_cost_equivalent"] == pytest.approx(30.0 + window * 2.0)
    assert second["robot_seconds"] == pytest.approx(30.0 + window * 14)
    assert second["robot_seconds_cost_equivalent"] == pytest.approx(30.0 + window * 3.0)
    assert polish.best_objective == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(polish.best_units, 0.5, atol=1e-6)
    # a call that does not beat CMA-ES's best (0.1 here) leaves it the best
    cma.add(np.full(6, 0.45), 0.1, 10.0, 10.0)
    kept = gradient_fit.Recorder.continuing(cma, gradient_fit.POLISH)
    gradient_fit.fit_least_squares(problem, [np.full(6, 0.3)], 1, kept, cost_ratio=2.0)
    assert kept.rows[0]["objective"] == pytest.approx(0.24)
    assert kept.rows[0]["best_objective"] == 0.1
    np.testing.assert_array_equal(kept.best_units, np.full(6, 0.45))
    # a budget of one trial point: no step can follow it, so no Jacobian is simulated
    assert len(kept.rows) == 1
    assert kept.rows[0]["robot_seconds"] == pytest.approx(40.0 + window)
    # "beats" is strictly below: a call with CMA-ES's best objective exactly leaves CMA-ES's
    # point the best; one an ulp below it replaces it
    tie = gradient_fit.Recorder.continuing(cma, gradient_fit.POLISH)
    tie.add(np.full(6, 0.2), 0.1, 1.0, 1.0)
    assert tie.rows[-1]["best_objective"] == tie.best_objective == 0.1
    np.testing.assert_array_equal(tie.best_units, np.full(6, 0.45))
    just_below = np.nextafter(0.1, 0.0)
    tie.add(np.full(6, 0.25), just_below, 1.0, 1.0)
    assert tie.rows[-1]["best_objective"] == tie.best_objective == just_below
    np.testing.assert_array_equal(tie.best_units, np.full(6, 0.25))


def drawn_axes(monkeypatch, plot, csv_path) -> list:
    """The axes of the figure `plot(csv_path, png_path)` draws, kept instead of saved."""
    drawn = {}

    def keep(fig, png_path, dpi=130):
        drawn["axes"] = fig.axes
        return png_path

    monkeypatch.setattr(gradient_fit.cli, "save_figure", keep)
    plot(csv_path, csv_path.with_suffix(".png"))
    return drawn["axes"]


def test_the_history_plot_draws_both_counts_from_the_csv(tmp_path, monkeypatch):
    """Two parameter sets, two optimisers each: a column of two panels per set, the robot-seconds
    with replicas counted above and the cost-equivalent ones below, one step line per
    optimiser whose points are the CSV's (cost, best objective) pairs."""
    rows = []
    for parameter_set in ("6", "20"):
        for optimiser, scale in (("CMA-ES", 1.0), (gradient_fit.LEAST_SQUARES, 0.25)):
            recorder = gradient_fit.Recorder(parameter_set, optimiser)
            for objective in (9.0, 4.0, 5.0):
                recorder.add([objective], objective, 10.0, 10.0 * scale)
            rows += recorder.rows
    csv_path = tmp_path / "gradient_fit_history.csv"
    pd.DataFrame(rows).to_csv(csv_path, index=False)
    axes = drawn_axes(monkeypatch, gradient_fit.plot_history, csv_path)
    assert len(axes) == 4
    table = pd.read_csv(csv_path, dtype={"parameter_set": str})
    for ax, (parameter_set, count) in zip(axes, [("6", "robot_seconds"), ("20", "robot_seconds"),
                                                 ("6", "robot_seconds_cost_equivalent"),
                                                 ("20", "robot_seconds_cost_equivalent")]):
        assert ax.get_title() == f"{parameter_set} parameters"
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"CMA-ES", gradient_fit.LEAST_SQUARES}
        for optimiser, line in lines.items():
            part = table[(table["parameter_set"] == parameter_set)
                         & (table["optimiser"] == optimiser)]
            np.testing.assert_array_equal(line.get_xdata(), part[count])
            np.testing.assert_array_equal(line.get_ydata(), [9.0, 4.0, 4.0])


def test_the_budgets_plot_draws_each_optimisers_share_from_the_csv(tmp_path, monkeypatch):
    """One panel per parameter set; per optimiser its (generation, share) pairs as the CSV
    has them, NaN where it never reached CMA-ES's objective; the one-fifth line."""
    table = pd.DataFrame({"parameter_set": ["6"] * 4 + ["20"] * 2,
                          "cma_generations": [1, 1, 2, 2, 1, 2], "cma_robot_seconds": 1.0,
                          "cma_objective": 1.0,
                          "optimiser": ["a", "b", "a", "b", "a", "a"],
                          "cost_equivalent_to_cma_objective": 1.0,
                          "share_of_cma_cost_equivalent": [0.5, 0.1, np.nan, 0.3, 2.0, 0.25]})
    csv_path = tmp_path / "gradient_fit_cma_budgets.csv"
    table.to_csv(csv_path, index=False)
    axes = drawn_axes(monkeypatch, gradient_fit.plot_cma_budgets, csv_path)
    assert [ax.get_title() for ax in axes] == ["6 parameters", "20 parameters"]
    expected = {("6", "a"): [0.5, np.nan], ("6", "b"): [0.1, 0.3], ("20", "a"): [2.0, 0.25]}
    for ax, parameter_set in zip(axes, ("6", "20")):
        lines = {line.get_label(): line for line in ax.get_lines()}
        np.testing.assert_array_equal(lines["one fifth"].get_ydata(), [0.2, 0.2])
        for (name, optimiser), shares in expected.items():
            if name == parameter_set:
                np.testing.assert_array_equal(lines[optimiser].get_xdata(), [1, 2])
                np.testing.assert_array_equal(lines[optimiser].get_ydata(), shares)


@pytest.mark.parametrize("argv, message", [
    (["--sets", "7"], "--sets: unknown value '7'"),
    (["--starts", "0"], "--starts must be >= 1"),
    (["--lbfgs-evaluations", "0"], "--lbfgs-evaluations must be >= 1"),
    (["--least-squares-evaluations", "-1"], "--least-squares-evaluations must be >= 0"),
    (["--polish-evaluations", "-1"], "--polish-evaluations must be >= 0"),
    (["--broyden-evaluations", "-1"], "--broyden-evaluations must be >= 0"),
    (["--cma-generations", "0"], "--cma-generations must be >= 1"),
    (["--lm-iterations", "-1"], "--lm-iterations must be >= 0"),
    (["--lm-batch", "0"], "--lm-batch must be in [1, 20], got 0"),
    (["--lm-batch", "21"], "--lm-batch must be in [1, 20], got 21"),
    (["--lm-broyden-iterations", "-1"], "--lm-broyden-iterations must be >= 0"),
    (["--lm-broyden-batch", "0"], "--lm-broyden-batch must be in [1, 20], got 0"),
    (["--lm-broyden-batch", "21"], "--lm-broyden-batch must be in [1, 20], got 21"),
    # everything a set simulates counts, on --quick's one gait, with N Broyden batches:
    # CMA-ES's 18 points; the plain points, least squares' 2, the secant fit's 2, the batches'
    # 7 and the Broyden batches' 7 + (N − 1) × 20; 2 + 2 + 2 + 1 + 2N calls with sensitivities
    # (a second Jacobian per Broyden batch) × 13 instances; the cost ratio's 4 plain and 4
    # sensitive calls (4 × 14) and six optimisers' validation, segments and uncertainty (6 ×
    # 15): 253 + 46N, just over the limit at N = 21,734
    (["--lm-broyden-iterations", "21734", "--lm-broyden-batch", "20"],
     "43475 calls with sensitivities × 13 + 146 for the cost ratio, validation and "
     "uncertainty) × 1 gaits: 1,000,017 instances, more than the 1,000,000"),
    # the sets' instances together: each set alone is within the limit
    (["--sets", "6,20", "--lm-broyden-iterations", "12000"],
     "--sets 6,20: 348,270 + 732,548: 1,080,818 instances, more than the 1,000,000 a study "
     "runs"),
    # the step against the windows the study simulates (--quick's: to cycle 2), not against
    # --quick's 0.2 s (checked there, then refused by simulate with a traceback)
    (["--dt", "1e-9"], "--train-cycles 1:1 and --validate-cycles 2:2 (2 cycles, 6.3 s; 299 "
                       "instances) at dt = 1e-09 s is 6.3e+09 time steps per instance (1.88e+12 "
                       "robot-steps for 299 instances)"),
    (["--popsize", "1"], "--popsize must be >= 2"),
    (["--least-squares-method", "lm"], "--least-squares-method"),
    (["--train-cycles", "0:3"], "--train-cycles: expected FIRST:LAST"),
    (["--train-cycles", "1:2", "--validate-cycles", "2:3"], "--validate-cycles 2:3: must start "
                                                             "after"),
    (["--validate-cycles", "4:40"], "shorter than cycles up to 40"),
    # covered from early phases only: the fit's phase could lie beyond (it failed after the
    # whole fit)
    (["--validate-cycles", "5:7"], "--validate-cycles 5:7: the A1+A2 trial (22.4891 s) covers "
                                   "these cycles only from a phase up to 0.439 s, not from "
                                   "every phase of its 3.15-s period; its windows end at cycle "
                                   "6 at the latest"),
    # the window's bound (MAX_CYCLE 1000) named; at the bound the window parses and the
    # recordings' length refuses it
    (["--validate-cycles", "4:1001"], "1 <= FIRST <= LAST <= 1000, got '4:1001'"),
    (["--validate-cycles", "4:1000"], "shorter than cycles up to 1000"),
    (["--gaits", "A1+A6"], "--gaits A1+A6: not measured"),
    (["--held-out-gaits", "A1+A6"], "--held-out-gaits A1+A6: not measured"),
    # --quick fits A1+A2: holding it out as well is refused, naming it
    (["--held-out-gaits", "A1,A1+A2"], "--held-out-gaits A1+A2: fitted as well"),
])
def test_invalid_arguments_fail_before_compute(no_compute, monkeypatch, tmp_path, capsys, argv,
                                               message):
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    monkeypatch.setattr(gradient_fit, "simulate", forbidden)
    assert studies_main(["gradient_fit", *argv, "--out", str(tmp_path), "--quick",
                         "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert error.count("\n") == 1 and "Traceback" not in error


def test_the_twenty_parameter_set_extends_the_six():
    assert len(gradient_fit.PARAMETER_SETS["6"]) == 6
    assert len(gradient_fit.PARAMETER_SETS["20"]) == 20
    assert gradient_fit.PARAMETER_SETS["20"][:6] == gradient_fit.PARAMETER_SETS["6"]


def test_the_identified_forms_set_is_the_model_selection_candidates_box():
    """Set "gains_with_a1" and model_select's candidate of that name fit the same axes over the
    same ranges (one definition each, kept equal here)."""
    from studies import model_select
    (candidate,) = [c for c in model_select.read_candidates(model_select.CANDIDATES_CSV)
                    if c.name == "gains_with_a1"]
    assert gradient_fit.PARAMETER_SETS["gains_with_a1"] == candidate.fit.split()


def test_start_moves_every_optimisers_start(tmp_path, monkeypatch, capsys):
    """--start: the base model of the whole study becomes the identified.csv's model (the
    provenance names the file); a bad table, or one setting a field --set gives too, is
    refused before compute, naming --start."""
    seen = {}

    class Stop(Exception):
        pass

    def trials(gaits, period):  # the first use of the base model after the checks
        seen["period"] = period
        raise Stop
    monkeypatch.setattr(gradient_fit.identification, "measured_trials", trials)
    table = tmp_path / "identified.csv"
    table.write_text("field,value\nalpha,0.9\nperiod,4.0\n")
    with pytest.raises(Stop):
        gradient_fit.main(["--start", str(table), "--out", str(tmp_path / "out"),
                           "--quick", "--no-progress"])
    assert seen["period"] == 4.0  # the start's period reached the measured trials
    table.write_text("field,value\nalpha,-1\n")
    assert studies_main(["gradient_fit", "--start", str(table), "--out", str(tmp_path / "o2"),
                         "--quick", "--no-progress"]) == 2
    # a field both --start and --set give: refused (the file's value replaced --set's)
    table.write_text("field,value\nalpha,0.9\n")
    assert studies_main(["gradient_fit", "--start", str(table), "--set", "alpha=0.5",
                         "--out", str(tmp_path / "o3"), "--quick", "--no-progress"]) == 2
    assert capsys.readouterr().err.strip().endswith(
        f"--start {table} sets alpha, which --set gives too: give it in one of them")
    with pytest.raises(Stop):  # another field: both apply
        gradient_fit.main(["--start", str(table), "--set", "period=4.0", "--out",
                           str(tmp_path / "o4"), "--quick", "--no-progress"])
    assert seen["period"] == 4.0


def test_a_model_outside_a_sets_box_is_named_and_the_fits_start_at_its_bound(tmp_path,
                                                                            monkeypatch, capsys):
    """Every fit starts at the model's unit coordinates, clipped into the box: where the
    model lies outside a set's box (α = 0.1 below set 6's 0.2) a note on stderr names the axis,
    the value and the bound the fits start at, before anything runs; at the bound itself,
    none."""
    class Stop(Exception):
        pass

    def output(*args, **kwargs):  # the first thing after the checks and their notes
        raise Stop
    monkeypatch.setattr(gradient_fit.cli, "Output", output)
    for alpha, note in ((0.1, "gradient_fit: note: set 6: the model lies outside the box in "
                              "alpha = 0.1 (starts at 0.2, in [0.2, 1.5])\n"), (0.2, None)):
        with pytest.raises(Stop):
            gradient_fit.main(["--sets", "6", "--set", f"alpha={alpha}", "--out",
                               str(tmp_path / "out"), "--quick", "--no-progress"])
        error = capsys.readouterr().err
        if note is None:
            assert "outside the box" not in error
        else:
            assert note in error
        box = box_of("6")
        start = identify.start_units(box, StarParams.preset("paper", alpha=alpha))
        assert box[0].name == "alpha" and start[0] == 0.0


def box_of(name):
    return [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS[name]]


@pytest.mark.parametrize("name, gaits, idle", [
    ("20", ["A1+A2", "A1+A3"], [f"actuator_gains[{k}]" for k in range(4, 9)]),
    ("20", list(PAPER_GAITS), [f"actuator_gains[{k}]" for k in range(6, 9)]),
    ("20fired", list(PAPER_GAITS), []),
    ("20fired", ["A1+A3"], ["actuator_gains[2]", "actuator_gains[4]", "actuator_gains[5]",
                            "actuator_delays[2]", "actuator_delays[4]"]),
    ("6", ["A1"], []),
])
def test_unfired_axes_are_the_per_actuator_ones_no_gait_fires(name, gaits, idle):
    assert identify.unfired_axes(box_of(name), gaits) == idle


def test_a_plain_run_fits_only_parameters_its_gaits_move():
    """The default sets on the default gaits (all five measured) have no unfired axis (set
    "20" would have three, with zero derivatives)."""
    args = gradient_fit.build_parser().parse_args([])
    gaits = identify.measured_gaits(args.gaits)
    for name in args.sets.split(","):
        assert identify.unfired_axes(box_of(name), gaits) == [], name


def test_a_set_with_unfired_axes_is_named_on_stderr_before_any_fit(monkeypatch, tmp_path,
                                                                     capsys):
    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop
    monkeypatch.setattr(gradient_fit, "fit_cma", stop)
    with pytest.raises(Stop):
        gradient_fit.main(["--sets", "20", "--gaits", "A1+A2,A1+A3", "--out", str(tmp_path),
                           "--no-progress"])
    assert ("set 20: actuator_gains[4], actuator_gains[5], actuator_gains[6], "
            "actuator_gains[7], actuator_gains[8] belong to actuators that no fitted gait "
            "fires (A1+A2, A1+A3)") in capsys.readouterr().err
    # a set the gaits move all of gets no such note; its delays of A3-A5 (0 in the model)
    # start at the box's lower bound, which a note says
    with pytest.raises(Stop):
        gradient_fit.main(["--sets", "20fired", "--out", str(tmp_path / "fired"),
                           "--no-progress"])
    error = capsys.readouterr().err
    assert "belong to" not in error and "belongs to" not in error
    assert error == ("gradient_fit: note: set 20fired: the model lies outside the box in "
                     + "; ".join(f"actuator_delays[{k}] = 0 (starts at 0.0005, in [0.0005, "
                                 f"0.2995])" for k in (2, 3, 4)) + "\n")



def test_the_fired_set_names_only_what_the_measured_gaits_move():
    """Twenty distinct parameters, the six first; per-actuator ones only of actuators some
    measured gait fires, and no delay of A1 (a shift of the whole gait: the fitted phase)."""
    fired = gradient_fit.PARAMETER_SETS["20fired"]
    box = [identify.parse_range_spec(text, "--sets") for text in fired]
    assert len(fired) == 20 and len({text.split("=")[0] for text in fired}) == 20
    assert fired[:6] == gradient_fit.PARAMETER_SETS["6"]
    moved = {int(a[1:]) for gait in PAPER_GAITS for a in gait.split("+")}
    actuators = [int(text.split("[")[1].split("]")[0]) for text in fired if "[" in text]
    assert set(actuators) <= moved and "actuator_delays[1]" not in str(fired)
    # a delay's box ends half a default step off the grid (on it the run has no derivative)
    dt = SolverConfig().dt
    ends = [end for axis in box if axis.name == "actuator_delays" for end in (axis.low, axis.high)]
    assert len(ends) == 6
    assert all(abs(abs(end / dt - round(end / dt)) - 0.5) < 1e-9 for end in ends), ends


def test_the_cost_ratio_is_the_fastest_gradient_run_over_the_fastest_plain_one(monkeypatch):
    """measure_cost_ratio runs each simulation once untimed (compilation), then `repeats`
    times interleaved, and divides the fastest gradient run by the fastest plain one: a fake
    clock makes every duration known (gradient runs 3.0, 2.5, 2.8 s; plain 1.1, 1.0, 1.2 s)."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    durations = {"gradient": [9.0, 3.0, 2.5, 2.8], "plain": [9.0, 1.1, 1.0, 1.2]}
    clock, calls = [0.0], []

    def fake_simulate(params, duration_s, solver, sensitivities=(), **kwargs):
        kind = "gradient" if sensitivities else "plain"
        calls.append(kind)
        assert tuple(sensitivities) in ((), tuple(problem.names))
        assert duration_s == pytest.approx(base.period)
        clock[0] += durations[kind].pop(0)

    monkeypatch.setattr(gradient_fit, "simulate", fake_simulate)
    monkeypatch.setattr(gradient_fit.time, "perf_counter", lambda: clock[0])
    assert gradient_fit.measure_cost_ratio(problem, repeats=3) == pytest.approx(2.5 / 1.0)
    assert calls == ["plain", "gradient"] + ["plain", "gradient"] * 3


def test_the_summary_counts_the_cost_to_cma_objective_both_ways():
    """A CMA-ES run of three points (10 robot-seconds each, best objective 2.0) and an
    L-BFGS-B run whose calls count 26 robot-seconds with the replicas as instances and 7 at the
    measured cost: the gradient fit first reaches 2.0 at its second call, after 52 and 14."""
    class FakeProblem:
        box = [None] * 6

        def validate(self, units, validate):
            return float(np.sum(units))

    cma = gradient_fit.Recorder("6", "CMA-ES")
    for objective in (5.0, 3.0, 2.0):
        cma.add([objective], objective, 10.0, 10.0)
    lbfgs = gradient_fit.Recorder("6", "L-BFGS-B")
    for objective in (4.0, 1.5, 1.0):
        lbfgs.add([objective], objective, 26.0, 7.0)
    table = gradient_fit.summarise([cma, lbfgs], {"6": FakeProblem()}, (4, 6), {"6": 3.5})
    row = table[table["optimiser"] == "L-BFGS-B"].iloc[0]
    assert row["robot_seconds_to_cma_objective"] == 52.0
    assert row["share_of_cma_robot_seconds"] == pytest.approx(52.0 / 30.0)
    assert row["cost_equivalent_to_cma_objective"] == 14.0
    assert row["share_of_cma_cost_equivalent"] == pytest.approx(14.0 / 30.0)
    assert row["gradient_cost_ratio"] == 3.5 and row["objective"] == 1.0
    assert row["validate_objective"] == 1.0  # the best point's units, validated
    assert table[table["optimiser"] == "CMA-ES"].iloc[0]["gradient_cost_ratio"] == 1.0
    # why each run stopped, every start's reason in order; none recorded: empty
    assert row["stop_reasons"] == ""
    lbfgs.stopped(0, "CONVERGENCE: NORM OF PROJECTED GRADIENT <= PGTOL")
    lbfgs.stopped(1, "STOP: TOTAL NO. OF F,G EVALUATIONS EXCEEDS LIMIT")
    table = gradient_fit.summarise([cma, lbfgs], {"6": FakeProblem()}, (4, 6), {"6": 3.5})
    assert table[table["optimiser"] == "L-BFGS-B"].iloc[0]["stop_reasons"] == (
        "start 0: CONVERGENCE: NORM OF PROJECTED GRADIENT <= PGTOL; "
        "start 1: STOP: TOTAL NO. OF F,G EVALUATIONS EXCEEDS LIMIT")
    assert list(table.columns) == gradient_fit.RESULT_COLUMNS


def test_the_objective_at_cma_cost_counts_points_up_to_cma_whole_run_and_not_past_it():
    """CMA-ES's three points cost 30 cost-equivalent robot-seconds, its best 2.0. Least squares
    (two starts, a failed point among them) reaches 2.5 at exactly 30 (counted: the budget is
    CMA-ES's whole run, ≤) and 1.0 at 30.5 (not counted); a fit whose first call alone costs
    31 reached nothing within it (NaN); a polish, which starts at CMA-ES's whole run, has
    CMA-ES's best there; another parameter set's points, cheap and low, count for none of
    these, and without a CMA-ES run of its own that set has no budget (NaN)."""
    class FakeProblem:
        box = [None] * 6

        def validate(self, units, validate):
            return 0.0

    cma = gradient_fit.Recorder("6", "CMA-ES")
    for objective in (5.0, 3.0, 2.0):
        cma.add([objective], objective, 10.0, 10.0)
    least_squares = gradient_fit.Recorder("6", "least-squares")
    for start, objective, cost in ((0, 4.0, 10.0), (0, math.inf, 5.0), (1, 2.5, 15.0),
                                   (1, 1.0, 0.5)):
        least_squares.add([objective], objective, 3.0 * cost, cost, start)
    lbfgs = gradient_fit.Recorder("6", "L-BFGS-B")
    lbfgs.add([0.5], 0.5, 100.0, 31.0)
    polish = gradient_fit.Recorder.continuing(cma, "CMA-ES + least-squares")
    polish.add([0.1], 0.1, 4.0, 4.0)
    other = gradient_fit.Recorder("20", "least-squares")
    other.add([0.01], 0.01, 1.0, 1.0)
    table = gradient_fit.summarise([cma, least_squares, lbfgs, polish, other],
                                   {"6": FakeProblem(), "20": FakeProblem()}, (4, 6),
                                   {"6": 3.0, "20": 3.0}).set_index(["parameter_set", "optimiser"])
    assert table.loc[("6", "least-squares"), "objective_at_cma_cost"] == 2.5
    assert table.loc[("6", "least-squares"), "objective"] == 1.0  # its best, past the budget
    assert math.isnan(table.loc[("6", "L-BFGS-B"), "objective_at_cma_cost"])
    # CMA-ES's own: its best over its whole run; the polish: that, where it starts
    assert table.loc[("6", "CMA-ES"), "objective_at_cma_cost"] == 2.0
    assert table.loc[("6", "CMA-ES + least-squares"), "objective_at_cma_cost"] == 2.0
    assert math.isnan(table.loc[("20", "least-squares"), "objective_at_cma_cost"])


def test_least_squares_finds_a_linear_minimum_and_differentiates_only_where_asked(
        monkeypatch):
    """On residuals linear in the units, r = A·u − y with the minimum u* inside the box, the
    Gauss-Newton step is exact: the fit reaches Σ r² at u* (to the solver's tolerances) from
    the base model's units. Every trial point is simulated once without sensitivities (one
    run: gaits × window robot-seconds) but the start, whose residuals come with the Jacobian the
    first step needs; the Jacobian's simulation ((1 + 2·6) × gaits × window, `cost_ratio` runs)
    is made at the start and then only where scipy asks for it: at points whose residuals it
    has just had, right after them."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    rng = np.random.default_rng(4)
    matrix = rng.normal(size=(15, 6))
    best_units = rng.uniform(0.2, 0.8, 6)
    offset = rng.normal(scale=0.1, size=15)
    target = matrix @ best_units + offset     # the minimum of |A u − y|² is u*, value |offset_⊥|²
    minimum = float(np.sum((offset - matrix @ np.linalg.lstsq(matrix, offset, rcond=None)[0])
                           ** 2))
    points, differentiated, calls = [], [], []

    def residuals(units):
        points.append(np.array(units))
        calls.append("residuals")
        return matrix @ units - target

    def residuals_and_jacobian(units):
        differentiated.append(np.array(units))
        calls.append("jacobian")
        return matrix @ units - target, matrix

    monkeypatch.setattr(problem, "residuals", residuals)
    monkeypatch.setattr(problem, "residuals_and_jacobian", residuals_and_jacobian)
    recorder = gradient_fit.fit_least_squares(
        problem, gradient_fit.start_points(problem, 1, 0), 20,
        gradient_fit.Recorder("6", gradient_fit.LEAST_SQUARES), cost_ratio=2.5)
    # scipy's default tolerances stop the linear problem within ~1e-8 of the minimum's value
    assert recorder.best_objective == pytest.approx(minimum, rel=1e-6)
    np.testing.assert_allclose(recorder.best_units, best_units + np.linalg.lstsq(
        matrix, offset, rcond=None)[0], atol=1e-5)
    # the start: one run with the sensitivities (its residuals and the first step's Jacobian)
    assert calls[0] == "jacobian"
    np.testing.assert_array_equal(differentiated[0], identify.start_units(box, base))
    trial_points = [differentiated[0]] + points
    assert len({p.tobytes() for p in trial_points}) == len(trial_points) >= 2
    assert len(recorder.rows) == len(points) + len(differentiated)
    later = differentiated[1:]
    for k, call in enumerate(calls[1:], start=1):
        if call == "jacobian":  # only at the point whose residuals scipy has just had
            assert calls[k - 1] == "residuals"
            np.testing.assert_array_equal(later.pop(0), points[calls[:k].count("residuals") - 1])
    window = base.period
    jacobians = calls.count("jacobian")
    assert recorder.robot_seconds == pytest.approx((len(points) + 13 * jacobians) * window)
    assert recorder.cost_equivalent == pytest.approx((len(points) + 2.5 * jacobians) * window)
    # converged before its cap: scipy's own reason, one of its tolerance tests
    assert len(recorder.stop_reasons) == 1
    assert recorder.stop_reasons[0].startswith("start 0: ")
    assert "termination condition" in recorder.stop_reasons[0]
    assert "maximum number of function evaluations" not in recorder.stop_reasons[0]
    # the same fit capped at its second trial point says so
    points.clear()
    calls.clear()
    capped = gradient_fit.fit_least_squares(
        problem, gradient_fit.start_points(problem, 1, 0), 2,
        gradient_fit.Recorder("6", gradient_fit.LEAST_SQUARES), cost_ratio=2.5)
    assert calls == ["jacobian", "residuals"]  # two trial points: the start, one step
    # (scipy itself reads the zeros that end a spent budget as a zero gradient, "gtol")
    assert capped.stop_reasons == ["start 0: its 2 trial points were spent"]


def test_held_out_scores_are_fresh_fits_of_the_start_and_each_best_point(monkeypatch):
    """gradient_fit_held_out.csv: the start (the base model) and every optimiser's best point
    scored on a gait no optimiser fits, each equal to a fresh simulation of that model on that
    gait with its phase fitted (batch-position independence is bitwise, so exactly); a point
    whose simulation failed scores inf."""
    box = [identify.parse_range_spec("alpha=0.2:1.5", "--sets")]
    base, solver, window = StarParams(), SolverConfig(dt=5e-3), (1, 1)
    trials = identification.measured_trials(["A1+A2"], base.period)
    held_out = gradient_fit.Problem(box, base, ["A1+A2"], trials, window, solver, "cpu")
    fitted = gradient_fit.Recorder("one", "L-BFGS-B")
    fitted.add([0.3], 1.0, 0.0, 0.0)
    table = gradient_fit.held_out_scores(held_out, [fitted])
    assert list(table["point"]) == ["start", "L-BFGS-B"]
    assert list(table["gait"]) == ["A1+A2"] * 2 and (table["parameter_set"] == "one").all()
    for row, alpha in zip(table.itertuples(), (base.alpha,
                                               identify.box_values(box, [[0.3]])[0, 0])):
        fresh = taichi_star.simulate(base.replace(gait="A1+A2", alpha=alpha), base.period,
                                     solver, record_interval_s=held_out.record, progress=False)
        (run,) = identification.simulated_runs(fresh.trajectory, ["A1+A2"], [base.period])
        expected = identification.trajectory_objective({"A1+A2": run}, trials, window)
        assert row.objective == expected["objective"].iloc[0]
        assert row.phase_s == expected["phase_s"].iloc[0]
    assert table["objective"].iloc[0] != table["objective"].iloc[1]  # two different points
    monkeypatch.setattr(held_out, "gait_tables", lambda units: [None] * len(units))
    failed = gradient_fit.held_out_scores(held_out, [fitted])
    assert np.isinf(failed["objective"]).all() and failed["phase_s"].isna().all()


@pytest.mark.slow  # a fit's run with sensitivities (the suite's time); its rule is unit-tested
def test_a_run_with_sensitivities_leaves_out_the_axes_no_gait_moves(monkeypatch):
    """A4's gain with A1+A2 fitted: A4 never fires, so its Jacobian column is exactly zero and
    the run with sensitivities asks only for α's (the replicas counted for α alone). The
    columns land on their axes: the same point with both sensitivities simulated gives the
    same Jacobian, bit for bit (the unfired axis first in the box, so a shifted column
    shows)."""
    box = [identify.parse_range_spec(text, "--sets")
           for text in ("actuator_gains[4]=0.3:2", "alpha=0.2:1.5")]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"],
                                   identification.measured_trials(["A1+A2"], base.period),
                                   (1, 1), SolverConfig(), "cpu")
    assert problem.names == ["actuator_gains[3]", "alpha"]
    assert problem.moved_names == ["alpha"]
    asked = []
    simulate = gradient_fit.simulate

    def spy(*args, sensitivities=(), **kwargs):
        asked.append(list(sensitivities))
        return simulate(*args, sensitivities=sensitivities, **kwargs)

    monkeypatch.setattr(gradient_fit, "simulate", spy)
    units = np.array([0.4, 0.5])
    residuals, jacobian, motion = problem.fit_terms(units)
    assert asked == [["alpha"]]
    assert np.all(jacobian[:, 0] == 0.0) and motion[0] == 0.0
    assert np.any(jacobian[:, 1] != 0.0)
    monkeypatch.setattr(problem, "moved", np.array([True, True]))
    monkeypatch.setattr(problem, "moved_names", problem.names)
    every_residual, every_column, every_motion = problem.fit_terms(units)
    assert asked[-1] == problem.names
    np.testing.assert_array_equal(every_residual, residuals)
    np.testing.assert_array_equal(every_column, jacobian)
    np.testing.assert_array_equal(every_motion, motion)
    recorder = gradient_fit.Recorder("test", gradient_fit.LEAST_SQUARES)
    monkeypatch.setattr(problem, "moved_names", ["alpha"])
    gradient_fit.record_gradient_call(recorder, problem, units, 1.0, 2.0, 0)
    assert recorder.robot_seconds == pytest.approx(base.period * (1 + 2))


def test_broyden_update_meets_the_secant_condition_and_keeps_other_directions():
    """The updated Jacobian maps the step to the residuals' change (the secant condition) and
    any direction orthogonal to the step as before (the least change); round-off only: 1e-12
    on entries of order one."""
    rng = np.random.default_rng(11)
    jacobian, step, change = rng.normal(size=(9, 4)), rng.normal(size=4), rng.normal(size=9)
    updated = gradient_fit.broyden_update(jacobian, step, change)
    np.testing.assert_allclose(updated @ step, change, atol=1e-12)
    orthogonal = rng.normal(size=4)
    orthogonal -= (orthogonal @ step) / (step @ step) * step
    np.testing.assert_allclose(updated @ orthogonal, jacobian @ orthogonal, atol=1e-12)
    # a Jacobian that already meets the condition is kept
    np.testing.assert_allclose(gradient_fit.broyden_update(jacobian, step, jacobian @ step),
                               jacobian, atol=1e-12)


def test_step_agreement_is_the_achieved_over_the_predicted_reduction():
    """On linear residuals with their exact Jacobian every step achieves what it predicts (1);
    a step that achieves half the predicted reduction scores 0.5; none predicted scores 0."""
    rng = np.random.default_rng(12)
    matrix, target = rng.normal(size=(8, 3)), rng.normal(size=8)
    units, step = rng.normal(size=3), rng.normal(size=3) * 0.1
    before, after = matrix @ units - target, matrix @ (units + step) - target
    assert gradient_fit.step_agreement(before, after, matrix, step) == pytest.approx(1.0,
                                                                                    rel=1e-12)
    predicted = before @ before - np.sum((before + matrix @ step) ** 2)
    # residuals scaled so that Σ r² falls by half the prediction
    half = after * np.sqrt((before @ before - predicted / 2) / (after @ after))
    assert gradient_fit.step_agreement(before, half, matrix, step) == pytest.approx(0.5,
                                                                                   rel=1e-12)
    assert gradient_fit.step_agreement(before, after, np.zeros((8, 3)), step) == 0.0


def test_the_secant_jacobian_is_simulated_where_the_last_one_served_badly(monkeypatch):
    """None (simulate) after a refused trial point or below SECANT_AGREEMENT; Broyden's update
    at the threshold itself and above it."""
    jacobian = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    last_units, last_residuals = np.zeros(2), np.array([1.0, 1.0, 2.0])
    units = np.array([-0.5, -0.5])
    predicted_after = last_residuals + jacobian @ units
    predicted = last_residuals @ last_residuals - predicted_after @ predicted_after
    # residuals along the predicted ones whose Σ r² falls by 0.9 of the prediction
    residuals = predicted_after * np.sqrt((last_residuals @ last_residuals - 0.9 * predicted)
                                          / (predicted_after @ predicted_after))
    assert gradient_fit.step_agreement(last_residuals, residuals, jacobian,
                                       units - last_units) == pytest.approx(0.9, rel=1e-12)
    expected = gradient_fit.broyden_update(jacobian, units - last_units,
                                           residuals - last_residuals)

    def secant(refused=False):
        return gradient_fit.secant_jacobian(last_units, last_residuals, jacobian, refused, units,
                                            residuals)

    np.testing.assert_array_equal(secant(), expected)
    assert secant(refused=True) is None
    threshold = gradient_fit.SECANT_AGREEMENT
    for agreement, simulated in ((threshold, False), (np.nextafter(threshold, 0.0), True)):
        monkeypatch.setattr(gradient_fit, "step_agreement", lambda *args, a=agreement: a)
        assert (secant() is None) is simulated


def test_the_secant_fit_reaches_the_exact_fits_minimum_with_fewer_jacobians(monkeypatch):
    """Nonlinear residuals r(u) = A·u + 0.3·B·sin(3u) − y (minimum inside the box): the secant
    fit reaches the minimum the fit with a simulated Jacobian at every accepted point reaches
    (to 1e-5 of its value), simulating fewer Jacobians; each one it simulates
    after the start is at the point whose residuals it has just had."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    rng = np.random.default_rng(13)
    linear, curved = rng.normal(size=(15, 6)), rng.normal(size=(15, 6))
    target = linear @ rng.uniform(0.3, 0.7, 6) + rng.normal(scale=0.05, size=15)
    calls = []

    def values(units):
        return linear @ units + 0.3 * curved @ np.sin(3 * units) - target

    def residuals(units):
        calls.append(("residuals", np.array(units)))
        return values(units)

    def residuals_and_jacobian(units):
        calls.append(("jacobian", np.array(units)))
        return values(units), linear + 0.3 * curved * (3 * np.cos(3 * units))[None, :]

    monkeypatch.setattr(problem, "residuals", residuals)
    monkeypatch.setattr(problem, "residuals_and_jacobian", residuals_and_jacobian)
    fits = {}
    for secant in (False, True):
        calls.clear()
        fits[secant] = (gradient_fit.fit_least_squares(
            problem, gradient_fit.start_points(problem, 1, 0), 40,
            gradient_fit.Recorder("6", gradient_fit.BROYDEN if secant
                                  else gradient_fit.LEAST_SQUARES), cost_ratio=2.5,
            secant=secant), list(calls))
    (exact, exact_calls), (secant, secant_calls) = fits[False], fits[True]
    # the secant Jacobian is approximate near the minimum, so scipy's stopping tests (a
    # relative change of 1e-8) stop it where its model is flat: measured 4.1e-6 above the
    # exact fit's value; 1e-5 allows that, a wrong update or a missed minimum is far beyond
    assert secant.best_objective == pytest.approx(exact.best_objective, rel=1e-5)
    simulated = [units for kind, units in secant_calls if kind == "jacobian"]
    assert 1 <= len(simulated) < sum(kind == "jacobian" for kind, _ in exact_calls)
    for k, (kind, units) in enumerate(secant_calls[1:], start=1):
        if kind == "jacobian":
            assert secant_calls[k - 1][0] == "residuals"
            np.testing.assert_array_equal(units, secant_calls[k - 1][1])


def test_the_secant_state_serves_until_a_step_is_refused_and_again_after_a_jacobian():
    """A trial point scoring no better than the current point (equal counts: scipy refuses a
    step that does not lower the objective) makes the next accepted point's Jacobian a
    simulated one (None); once scipy moves on with a Jacobian the state serves again."""
    jacobian = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    start = np.array([1.0, 1.0, 2.0])
    state = gradient_fit.SecantState(np.zeros(2), start, jacobian)
    units = np.array([-0.5, -0.5])
    good = start + jacobian @ units  # the linear model's own prediction: agreement 1
    assert state.jacobian_at(units, good) is not None
    state.tried(start * 1.0)  # exactly the current objective: refused
    assert state.refused and state.jacobian_at(units, good) is None
    state.moved_to(units, good, jacobian)
    assert not state.refused
    state.tried(good * 0.5)  # better: not refused
    assert not state.refused
    np.testing.assert_array_equal(state.jacobian_at(np.array([-1.0, -0.5]), good + jacobian[:, 0]
                                                    * -0.5), jacobian)


def test_the_gradient_fits_hold_the_axes_no_gait_moves(monkeypatch):
    """Set 20 on A1+A2 and A1+A3: the gains of A4-A8 have zero columns; every point L-BFGS-B,
    both least-squares fits and the batched Levenberg-Marquardt fit try keeps them at the
    start's values (trf's steps wandered
    along them, and Broyden's updates gave them derivatives: an audit, 2026-12), and the fits
    still reach the minimum over the other axes."""
    box = box_of("20")
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2", "A1+A3"], {}, (1, 1), SolverConfig(),
                                   "cpu")
    dead = ~problem.moved
    assert dead.sum() == 5
    rng = np.random.default_rng(14)
    linear = rng.normal(size=(40, 20)) * problem.moved
    target = linear @ rng.uniform(0.3, 0.7, 20) + rng.normal(scale=0.05, size=40)
    tried = []

    def values(units):
        tried.append(np.array(units))
        return linear @ units + 0.2 * np.sin(3 * units) @ (linear.T * 0.1) - target

    def derivatives(units):
        return linear + 0.2 * (linear * 0.1) * (3 * np.cos(3 * units))[None, :]

    monkeypatch.setattr(problem, "residuals", values)
    monkeypatch.setattr(problem, "residuals_and_jacobian",
                        lambda units: (values(units), derivatives(units)))
    monkeypatch.setattr(problem, "value_and_gradient", lambda units: (
        float(values(units) @ values(units)), 2.0 * derivatives(units).T @ values(units)))
    monkeypatch.setattr(problem, "objectives", lambda points: np.array(
        [float(values(units) @ values(units)) for units in points]))
    start = identify.start_units(box, base)
    from scipy.optimize import least_squares
    minimum = 2 * least_squares(
        lambda moved: values(problem.embedded(moved, start)), start[problem.moved],
        jac=lambda moved: derivatives(problem.embedded(moved, start))[:, problem.moved],
        bounds=(0.0, 1.0), xtol=1e-15, ftol=1e-15, gtol=1e-15).cost
    for fit in (lambda recorder: gradient_fit.fit_least_squares(problem, [start], 30, recorder,
                                                                2.0),
                lambda recorder: gradient_fit.fit_least_squares(problem, [start], 30, recorder,
                                                                2.0, secant=True),
                lambda recorder: gradient_fit.fit_lbfgs(problem, 1, 30, 0, recorder, 2.0),
                lambda recorder: gradient_fit.fit_levenberg_marquardt(problem, [start], 30, 7,
                                                                      recorder, 2.0)):
        tried.clear()
        recorder = fit(gradient_fit.Recorder("20", "fit"))
        assert len(tried) > 3
        for units in tried:
            np.testing.assert_array_equal(units[dead], start[dead])
        # the minimum over the moved axes (a direct fit of the same residuals to scipy's
        # tightest tolerances), to 1e-6: the fits stop at scipy's default tolerances or their
        # 30 points (the scipy fits measured 2e-15, 9e-13 and 1.8e-9 above it)
        assert recorder.best_objective == pytest.approx(minimum, rel=1e-6)


def test_lbfgs_stops_at_its_evaluation_budget(monkeypatch):
    """scipy's L-BFGS-B checks `maxfun` between iterations and finishes a line search past it
    (a scaled Rosenbrock function from near a corner: 4 calls for a cap of 2, 7 for 6); a
    start of `fit_lbfgs` makes at most its `max_evaluations`, and says why it stopped."""
    from scipy.optimize import minimize, rosen, rosen_der

    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 1),
                                   SolverConfig(), "cpu")
    corner = np.full(6, 0.05)
    monkeypatch.setattr(gradient_fit, "start_points", lambda problem, starts, seed: [corner])
    made = []

    def value_and_gradient(units):
        made.append(np.array(units))
        return 30.0 * rosen(2.0 * units), 60.0 * rosen_der(2.0 * units)

    monkeypatch.setattr(problem, "value_and_gradient", value_and_gradient)
    overshoots = 0
    for budget in range(1, 9):
        made.clear()
        minimize(value_and_gradient, corner, jac=True, method="L-BFGS-B",
                 bounds=[(0.0, 1.0)] * 6, options={"maxfun": budget, "maxiter": budget})
        overshoots += len(made) > budget
        made.clear()
        recorder = gradient_fit.fit_lbfgs(problem, 1, budget, 0,
                                          gradient_fit.Recorder("6", "L-BFGS-B"), 2.0)
        assert len(made) == len(recorder.rows) == budget
        assert recorder.stop_reasons == [
            f"start 0: stopped after --lbfgs-evaluations ({budget}) evaluations"]
    assert overshoots >= 4  # what the guard is for (measured: 7 of the 8 budgets)


def test_a_failed_trial_point_scores_inf_and_the_fit_goes_on(monkeypatch):
    """A trial point whose run fails gives residuals of inf (`Problem.residuals`): recorded
    with objective inf, never the best, and scipy shrinks its step and reaches the minimum
    (the finite penalty was taken as a step from a point scoring above it: an audit,
    2026-12); a start whose run fails gets the finite penalty (scipy needs a finite start)."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    monkeypatch.setattr(problem, "runs", lambda params, cycles, sensitivities=(): ([None], None))
    failed = problem.residuals(np.full(6, 0.5))
    assert failed.shape == (identification.residual_count(1, (1, 1)),)
    assert np.all(failed == math.inf)
    rng = np.random.default_rng(15)
    matrix = rng.normal(size=(15, 6))
    target = matrix @ rng.uniform(0.3, 0.7, 6)
    calls = []

    def residuals(units):
        calls.append(np.array(units))
        # the first trial after the start fails
        return np.full(15, math.inf) if len(calls) == 1 else matrix @ units - target

    monkeypatch.setattr(problem, "residuals", residuals)
    monkeypatch.setattr(problem, "residuals_and_jacobian",
                        lambda units: (matrix @ units - target, matrix))
    recorder = gradient_fit.fit_least_squares(problem, [np.full(6, 0.9)], 20,
                                              gradient_fit.Recorder("6", "fit"), 2.0)
    assert recorder.rows[1]["objective"] == math.inf
    assert recorder.rows[1]["best_objective"] == recorder.rows[0]["objective"]
    assert recorder.best_objective == pytest.approx(0.0, abs=1e-12)
    # a start that fails: the finite penalty, and the budget of one point ends there
    monkeypatch.setattr(problem, "residuals", lambda units: np.full(15, math.inf))
    monkeypatch.setattr(problem, "failed_residuals", lambda: np.full(15, 10.0))
    alone = gradient_fit.fit_least_squares(problem, [np.full(6, 0.9)], 1,
                                           gradient_fit.Recorder("6", "fit"), 2.0)
    assert [row["objective"] for row in alone.rows] == [1500.0]


def test_the_cost_ratio_simulates_only_the_axes_a_gait_moves(monkeypatch):
    """measure_cost_ratio times the run a fit makes: the sensitivities of the moved axes (A4's
    gain left out with A1+A2 fitted)."""
    box = [identify.parse_range_spec(text, "--sets")
           for text in ("alpha=0.2:1.5", "actuator_gains[4]=0.3:2")]
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 1),
                                   SolverConfig(), "cpu")
    asked = []
    monkeypatch.setattr(gradient_fit, "simulate",
                        lambda params, duration_s, solver, sensitivities=(), **kwargs:
                        asked.append(tuple(sensitivities)))
    gradient_fit.measure_cost_ratio(problem, repeats=1)
    assert set(asked) == {(), ("alpha",)}


def test_main_runs_each_optimiser_with_its_own_flags(tmp_path, monkeypatch):
    """CMA-ES with --popsize, --cma-generations, --seed and --sigma0 (σ0 was checked and
    recorded but not passed on until an audit, 2026-12); the least-squares fit with
    --least-squares-evaluations, the secant one with --broyden-evaluations, the polish with
    --polish-evaluations, all with --least-squares-method; only the secant one with
    secant=True; the batched fits with --lm-iterations / --lm-broyden-iterations, both with
    --lm-batch, only the Broyden-updated one secant, its later batches --lm-broyden-batch (20,
    the largest allowed)."""
    calls = []

    class Stop(Exception):
        pass

    def fake_cma(problem, settings, recorder):
        calls.append(("CMA-ES", settings))
        recorder.add(np.full(len(problem.box), 0.5), 1.0, 1.0, 1.0)
        return recorder

    def fake_least_squares(problem, points, max_evaluations, recorder, cost_ratio, method,
                           secant=False):
        calls.append((recorder.optimiser, max_evaluations, method, secant))
        return recorder

    def fake_levenberg_marquardt(problem, points, iterations, batch, recorder, cost_ratio,
                                 secant=False, later_batch=None):
        calls.append((recorder.optimiser, iterations, batch, cost_ratio, secant, later_batch))
        return recorder

    def stop(*args, **kwargs):
        raise Stop
    monkeypatch.setattr(gradient_fit, "fit_cma", fake_cma)
    monkeypatch.setattr(gradient_fit, "measure_cost_ratio", lambda problem: 2.0)
    monkeypatch.setattr(gradient_fit, "fit_lbfgs", lambda *args: calls.append(("L-BFGS-B",)))
    monkeypatch.setattr(gradient_fit, "fit_least_squares", fake_least_squares)
    monkeypatch.setattr(gradient_fit, "fit_levenberg_marquardt", fake_levenberg_marquardt)
    monkeypatch.setattr(gradient_fit, "summarise", stop)
    with pytest.raises(Stop):
        gradient_fit.main(["--least-squares-evaluations", "5", "--broyden-evaluations", "3",
                           "--polish-evaluations", "4", "--least-squares-method", "dogbox",
                           "--lm-iterations", "6", "--lm-batch", "3", "--sigma0", "0.05",
                           "--lm-broyden-iterations", "5", "--lm-broyden-batch", "20",
                           "--popsize", "5", "--cma-generations", "3", "--seed", "7",
                           "--out", str(tmp_path / "out"), "--quick", "--no-progress"])
    assert calls[0] == ("CMA-ES", identify.CMASettings(popsize=5, max_generations=3, seed=7,
                                                       sigma0=0.05))
    assert calls[1:] == [("L-BFGS-B",), (gradient_fit.LEAST_SQUARES, 5, "dogbox", False),
                     (gradient_fit.BROYDEN, 3, "dogbox", True),
                     (gradient_fit.LEVENBERG_MARQUARDT, 6, 3, 2.0, False, None),
                     (gradient_fit.LEVENBERG_MARQUARDT_BROYDEN, 5, 3, 2.0, True, 20),
                     (gradient_fit.POLISH, 4, "dogbox", False)]
    # the budgets table gets each set's CMA-ES population (--popsize given: 5)
    populations = []

    def budgets(recorders, given):
        populations.append(given)
        raise Stop

    monkeypatch.setattr(gradient_fit, "summarise", lambda *args: pd.DataFrame({"a": [1.0]}))
    monkeypatch.setattr(gradient_fit, "cma_budget_shares", budgets)
    with pytest.raises(Stop):
        gradient_fit.main(["--popsize", "5", "--out", str(tmp_path / "budgets"), "--quick",
                           "--no-progress"])
    assert populations == [{"6": 5}]
    monkeypatch.setattr(gradient_fit, "summarise", stop)
    # 0 leaves a batched fit out (the other runs, with the least batch, 1)
    calls.clear()
    with pytest.raises(Stop):
        gradient_fit.main(["--lm-iterations", "0", "--lm-broyden-batch", "1", "--out",
                           str(tmp_path / "out0"), "--quick", "--no-progress"])
    assert [call[0] for call in calls] == ["CMA-ES", "L-BFGS-B", gradient_fit.LEAST_SQUARES,
                                           gradient_fit.BROYDEN,
                                           gradient_fit.LEVENBERG_MARQUARDT_BROYDEN]
    assert calls[-1][-1] == 1
    calls.clear()
    with pytest.raises(Stop):
        gradient_fit.main(["--lm-broyden-iterations", "0", "--out", str(tmp_path / "out1"),
                           "--quick", "--no-progress"])
    assert [call[0] for call in calls] == ["CMA-ES", "L-BFGS-B", gradient_fit.LEAST_SQUARES,
                                           gradient_fit.BROYDEN, gradient_fit.LEVENBERG_MARQUARDT]


def test_segments_score_the_way_from_each_best_point_to_the_lowest(monkeypatch):
    """gradient_fit_segments.csv: from each optimiser's best point to the set's lowest (its own
    segment left out, as is a recorder that never scored), each row equal to a fresh batched
    scoring of its point on the segment (batch-position independence is bitwise, so exactly),
    the ends those points' own objectives; a failed point scores inf, its gaits NaN."""
    box = [identify.parse_range_spec("alpha=0.2:1.5", "--sets")]
    base, solver, window = StarParams(), SolverConfig(dt=5e-3), (1, 1)
    gaits = ["A1+A2", "A1+A3"]
    trials = identification.measured_trials(gaits, base.period)
    problem = gradient_fit.Problem(box, base, gaits, trials, window, solver, "cpu")
    ends = {"CMA-ES": 0.2, "L-BFGS-B": 0.8, gradient_fit.LEAST_SQUARES: 0.5}
    recorders = []
    for optimiser, unit in ends.items():
        recorder = gradient_fit.Recorder("one", optimiser)
        recorder.add([unit], problem.objectives([[unit]])[0], 0.0, 0.0)
        recorders.append(recorder)
    never = gradient_fit.Recorder("one", gradient_fit.BROYDEN)
    never.add([0.1], math.inf, 0.0, 0.0)
    recorders.append(never)
    lowest = min(recorders, key=lambda r: r.best_objective)
    fractions = np.array([0.0, 0.25, 1.0])
    table = gradient_fit.segment_scores(problem, recorders, fractions)
    starts = [r for r in recorders if r is not lowest and r is not never]
    assert list(table["optimiser"]) == [r.optimiser for r in starts for _ in fractions]
    assert (table["best_optimiser"] == lowest.optimiser).all()
    assert list(table["fraction"]) == list(fractions) * len(starts)
    points = [[(1 - f) * ends[r.optimiser] + f * ends[lowest.optimiser]]
              for r in starts for f in fractions]
    fresh = problem.gait_tables(np.array(points))
    assert list(table["objective"]) == [identification.objective_of(t) for t in fresh]
    for gait in gaits:
        expected_column = [float(t.set_index("gait").loc[gait, "objective"]) for t in fresh]
        assert list(table[f"objective_{gait}"]) == expected_column
    first = table[table["optimiser"] == starts[0].optimiser]
    assert first["objective"].iloc[0] == starts[0].best_objective
    assert first["objective"].iloc[-1] == lowest.best_objective
    monkeypatch.setattr(problem, "gait_tables", lambda units: [None] * len(units))
    failed = gradient_fit.segment_scores(problem, recorders, fractions)
    assert np.isinf(failed["objective"]).all()
    assert failed[[f"objective_{gait}" for gait in gaits]].isna().all().all()


def test_the_segments_plot_draws_each_segment_from_the_csv(tmp_path, monkeypatch):
    """One row of panels per set, one panel per segment (a set with fewer segments leaves the
    rest hidden), each with a line per gait and the objective, their points the CSV's."""
    rows = []
    for parameter_set, optimisers in (("6", ["CMA-ES", "L-BFGS-B"]), ("20", ["CMA-ES"])):
        for optimiser in optimisers:
            for fraction, value in ((0.0, 9.0), (0.5, 12.0), (1.0, 3.0)):
                rows.append({"parameter_set": parameter_set, "optimiser": optimiser,
                             "best_optimiser": gradient_fit.LEAST_SQUARES,
                             "fraction": fraction, "objective": value,
                             "objective_A1": value / 2, "objective_A1+A2": value * 1.5})
    csv_path = tmp_path / "gradient_fit_segments.csv"
    pd.DataFrame(rows).to_csv(csv_path, index=False)
    axes = drawn_axes(monkeypatch, gradient_fit.plot_segments, csv_path)
    assert len(axes) == 4 and not axes[3].get_visible()
    for ax, (parameter_set, optimiser) in zip(axes[:3], [("6", "CMA-ES"), ("6", "L-BFGS-B"),
                                                         ("20", "CMA-ES")]):
        assert ax.get_title() == f"{parameter_set} parameters: from {optimiser}'s point"
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"A1", "A1+A2", "objective (mean)"}
        assert list(lines["objective (mean)"].get_ydata()) == [9.0, 12.0, 3.0]
        assert list(lines["A1+A2"].get_ydata()) == [13.5, 18.0, 4.5]


def test_where_every_axis_moves_the_fit_is_scipys_on_the_whole_box_bit_for_bit(monkeypatch):
    """Holding the axes no gait moves must change nothing where every axis moves: the fit's
    trial points are those of scipy's least_squares on the whole box with the Jacobian as the
    problem gives it (row-major), bit for bit. The moved columns were once passed column-major
    (a boolean index), and on these ill-conditioned residuals (column scales 1 to 1e-6, like
    the study's) scipy's steps then differ in the last bits from the second on (an audit,
    2026-12: on "20fired" that took the secant fit to 841.9 instead of 808.2)."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    base = StarParams(gait="A1+A2")
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    assert problem.moved.all()
    rng = np.random.default_rng(3)
    matrix = rng.normal(size=(330, 6)) @ np.diag(np.logspace(0, -6, 6))
    target = rng.normal(size=330)

    def values(units):
        return matrix @ np.tanh(3 * units) - target + 0.1 * np.sin(5 * (matrix @ units))

    def jacobian(units):
        return (matrix * (3 / np.cosh(3 * units) ** 2)
                + 0.5 * np.cos(5 * (matrix @ units))[:, None] * matrix)

    monkeypatch.setattr(problem, "residuals", values)
    monkeypatch.setattr(problem, "residuals_and_jacobian",
                        lambda units: (values(units), jacobian(units)))
    recorder = gradient_fit.fit_least_squares(
        problem, gradient_fit.start_points(problem, 1, 0), 12,
        gradient_fit.Recorder("6", gradient_fit.LEAST_SQUARES), cost_ratio=2.0)
    from scipy.optimize import least_squares
    direct = []

    def residuals(units):
        direct.append(float(values(units) @ values(units)))
        return values(units)

    least_squares(residuals, identify.start_units(box, base), jac=jacobian, bounds=(0.0, 1.0),
                  method=gradient_fit.DEFAULT_LEAST_SQUARES_METHOD, x_scale="jac", max_nfev=12)
    fitted = [row["objective"] for row in recorder.rows if row["robot_seconds"]]
    trial_objectives = list(dict.fromkeys(fitted))
    assert len(direct) >= 4
    assert trial_objectives == list(dict.fromkeys(direct))


def test_a_point_on_two_segments_is_simulated_once(monkeypatch):
    """A polish that kept CMA-ES's point (and two fits ending at one point) has CMA-ES's
    segment: its rows are CMA-ES's, and the batch simulates each distinct point once (an
    audit: the quick run simulated 22 of its 33 points twice)."""
    box = [identify.parse_range_spec("alpha=0.2:1.5", "--sets")]
    base = StarParams()
    problem = gradient_fit.Problem(box, base, ["A1+A2"], {}, (1, 1), SolverConfig(), "cpu")
    batches = []

    def gait_tables(unit_points):
        batches.append(np.array(unit_points))
        return [pd.DataFrame({"gait": ["A1+A2"], "objective": [float(u[0]) + 1.0]})
                for u in unit_points]

    monkeypatch.setattr(problem, "gait_tables", gait_tables)
    recorders = []
    for optimiser, unit, objective in (("CMA-ES", 0.2, 5.0), (gradient_fit.POLISH, 0.2, 5.0),
                                       (gradient_fit.LEAST_SQUARES, 0.6, 1.0)):
        recorder = gradient_fit.Recorder("one", optimiser)
        recorder.add([unit], objective, 0.0, 0.0)
        recorders.append(recorder)
    fractions = np.array([0.0, 0.5, 1.0])
    table = gradient_fit.segment_scores(problem, recorders, fractions)
    assert len(batches) == 1 and len(batches[0]) == len(fractions)
    cma = table[table["optimiser"] == "CMA-ES"].drop(columns="optimiser")
    polish = table[table["optimiser"] == gradient_fit.POLISH].drop(columns="optimiser")
    assert cma.reset_index(drop=True).equals(polish.reset_index(drop=True))
    np.testing.assert_allclose(cma["objective"], [1.2, 1.4, 1.6])


def test_the_damping_grid_is_decades_around_its_centre():
    np.testing.assert_allclose(gradient_fit.damping_grid(0.01, 7),
                               [1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0], rtol=1e-15)
    # an even batch: one decade more below the centre than above
    np.testing.assert_allclose(gradient_fit.damping_grid(2.0, 4), [0.02, 0.2, 2.0, 20.0],
                               rtol=1e-15)
    np.testing.assert_array_equal(gradient_fit.damping_grid(3.0, 1), [3.0])


def damped_model_gradient(residuals, jacobian, units, point, damping):
    """The gradient of |r + J·s|² + λ·|diag(d)·s|² / 2 at s = point - units (d the column
    norms): zero on a free axis of the box-constrained minimum, of the sign that pushes
    outwards on an axis at a bound (the KKT conditions)."""
    step = point - units
    scale = np.linalg.norm(jacobian, axis=0)
    return jacobian.T @ (residuals + jacobian @ step) + damping * scale ** 2 * step


def test_damped_steps_are_levenberg_marquardts_steps_within_the_box():
    """Inside the box each point is Marquardt's step -(JᵀJ + λ·diag(JᵀJ))⁻¹ Jᵀr (a linear
    solve of its own, not scipy's); λ → 0 reaches the minimum of the linear model; where the
    model's minimum lies outside the box each point meets the box-constrained problem's KKT
    conditions; a larger damping never gives a longer scaled step."""
    rng = np.random.default_rng(7)
    jacobian = rng.normal(size=(12, 4)) * np.array([1.0, 10.0, 0.1, 3.0])
    units = np.full(4, 0.5)
    inside = rng.normal(size=4) * 0.05
    residuals = -jacobian @ inside + 0.01 * rng.normal(size=12)
    dampings = [1e-12, 1e-2, 1.0, 100.0]
    points = gradient_fit.damped_steps(residuals, jacobian, units, dampings)
    curvature = jacobian.T @ jacobian
    for point, damping in zip(points, dampings):
        step = -np.linalg.solve(curvature + damping * np.diag(np.diag(curvature)),
                                jacobian.T @ residuals)
        assert np.all(np.abs(step) < 0.5)    # inside the box: the bounds are inactive
        # bvls solves the stacked system by QR; the two agree to ~cond(JᵀJ)·eps ≈ 1e-12
        np.testing.assert_allclose(point - units, step, rtol=1e-9, atol=1e-12)
    # λ = 1e-12: the model's minimum (lstsq), to λ·cond relative
    np.testing.assert_allclose(points[0] - units,
                               np.linalg.lstsq(jacobian, -residuals, rcond=None)[0],
                               rtol=1e-8, atol=1e-12)
    scale = np.linalg.norm(jacobian, axis=0)
    lengths = [np.linalg.norm(scale * (p - units)) for p in points]
    assert all(a >= b for a, b in zip(lengths, lengths[1:]))
    # an axis the residuals do not see (a zero column) does not move, whatever the damping
    blind = np.hstack([jacobian, np.zeros((12, 1))])
    for point in gradient_fit.damped_steps(residuals, blind, np.append(units, 0.3), dampings):
        assert point[-1] == 0.3
    # the model's minimum far outside the box: every point inside it, some axis on a bound,
    # and the KKT conditions of the damped problem on the box
    far = -jacobian @ np.array([2.0, -3.0, 0.1, 0.05])
    units = np.array([0.9, 0.1, 0.5, 0.0])
    for damping in (1e-6, 1e-2, 1.0):
        point = gradient_fit.damped_steps(far, jacobian, units, [damping])[0]
        assert np.all((point >= 0.0) & (point <= 1.0))
        gradient = damped_model_gradient(far, jacobian, units, point, damping)
        # |g| relative to |Jᵀr|: bvls's optimality to round-off
        tolerance = 1e-9 * np.linalg.norm(jacobian.T @ far)
        at_lower, at_upper = point <= 1e-12, point >= 1.0 - 1e-12
        assert at_lower.any() or at_upper.any()
        free = ~(at_lower | at_upper)
        assert np.all(np.abs(gradient[free]) <= tolerance)
        assert np.all(gradient[at_lower] >= -tolerance)
        assert np.all(gradient[at_upper] <= tolerance)


def linear_levenberg_marquardt_problem(monkeypatch, seed=4):
    """A Problem on set 6 whose residuals are linear in the units, r = A·u − y, the minimum
    inside the box: (problem, calls, matrix, target), `calls` the fit's simulations in order
    ("jacobian" at a point, or ("batch", points))."""
    box = [identify.parse_range_spec(text, "--sets") for text in gradient_fit.PARAMETER_SETS["6"]]
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 1),
                                   SolverConfig(), "cpu")
    rng = np.random.default_rng(seed)
    matrix = rng.normal(size=(15, 6))
    target = matrix @ rng.uniform(0.2, 0.8, 6) + rng.normal(scale=0.1, size=15)
    calls = []

    def residuals_and_jacobian(units):
        calls.append(("jacobian", np.array(units)))
        return matrix @ units - target, matrix

    def objectives(points):
        calls.append(("batch", np.array(points)))
        return np.array([float(np.sum((matrix @ p - target) ** 2)) for p in points])

    def scored_points(points):
        calls.append(("batch", np.array(points)))
        residuals = np.array([matrix @ p - target for p in points])
        return np.array([float(np.sum(r ** 2)) for r in residuals]), residuals

    monkeypatch.setattr(problem, "residuals_and_jacobian", residuals_and_jacobian)
    monkeypatch.setattr(problem, "objectives", objectives)
    monkeypatch.setattr(problem, "scored_points", scored_points)
    return problem, calls, matrix, target


def test_levenberg_marquardt_reaches_a_linear_minimum_and_differentiates_only_where_it_moves(
        monkeypatch):
    """From the base model: a Jacobian, then a batch of `batch` damped steps, the best taken
    and the Jacobian simulated there, the next grid centred on its damping; none after the
    last batch. The linear minimum is reached (the small dampings' steps are Gauss-Newton's,
    exact here). A batch's cost, all its points' runs, is on its first row."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    minimum_units = np.linalg.lstsq(matrix, target, rcond=None)[0]
    minimum = float(np.sum((matrix @ minimum_units - target) ** 2))
    grids = []
    steps = gradient_fit.damped_steps

    def spy(residuals, jacobian, units, dampings):
        grids.append(np.array(dampings))
        return steps(residuals, jacobian, units, dampings)

    monkeypatch.setattr(gradient_fit, "damped_steps", spy)
    recorder = gradient_fit.fit_levenberg_marquardt(
        problem, gradient_fit.start_points(problem, 1, 0), 3, 5,
        gradient_fit.Recorder("6", gradient_fit.LEVENBERG_MARQUARDT), cost_ratio=2.5)
    kinds = [call[0] for call in calls]
    assert kinds == ["jacobian", "batch", "jacobian", "batch", "jacobian", "batch"]
    np.testing.assert_array_equal(calls[0][1], identify.start_units(problem.box, problem.base))
    for k in (2, 4):  # each Jacobian at the best point of the batch before it
        points = calls[k - 1][1]
        best = points[np.argmin([np.sum((matrix @ p - target) ** 2) for p in points])]
        np.testing.assert_array_equal(calls[k][1], best)
    np.testing.assert_allclose(grids[0], gradient_fit.damping_grid(
        gradient_fit.MARQUARDT_DAMPING, 5), rtol=1e-15)
    for before, after, batch in zip(grids, grids[1:], (calls[1][1], calls[3][1])):
        chosen = before[np.argmin([np.sum((matrix @ p - target) ** 2) for p in batch])]
        np.testing.assert_allclose(after, gradient_fit.damping_grid(chosen, 5), rtol=1e-15)
    # the smallest damping of the last grid is ≤ 1e-7 relative: its step reaches the minimum
    # to ~1e-7 of the distance, the objective's excess to its square
    assert recorder.best_objective == pytest.approx(minimum, rel=1e-9)
    window = problem.base.period
    assert recorder.robot_seconds == pytest.approx((3 * 5 + 3 * 13) * window)
    assert recorder.cost_equivalent == pytest.approx((3 * 5 + 3 * 2.5) * window)
    batch_rows = recorder.rows[1:6]
    assert batch_rows[0]["robot_seconds"] - recorder.rows[0]["robot_seconds"] == \
        pytest.approx(5 * window)
    assert {row["robot_seconds"] for row in batch_rows} == {batch_rows[0]["robot_seconds"]}
    assert len(recorder.rows) == 3 * 5 + 3
    assert recorder.stop_reasons == ["start 0: its 3 batches were spent"]


def test_a_batch_with_no_better_point_moves_the_grid_up_without_a_jacobian(monkeypatch):
    """A batch whose every point scores no better than the current one (here: every run
    failed, inf; then every point exactly the current objective, a tie) keeps the point and
    its Jacobian: the next batch, from the same point, tries the `batch` decades above the
    last grid. A batch whose best point is not its first moves the fit to that point (the
    Jacobian simulated there) and centres the next grid on that point's damping."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    grids, batches = [], []
    steps = gradient_fit.damped_steps
    monkeypatch.setattr(gradient_fit, "damped_steps", lambda r, j, u, dampings: (
        grids.append(np.array(dampings)), steps(r, j, u, dampings))[1])
    start = identify.start_units(problem.box, problem.base)
    residuals = matrix @ start - target
    current = float(residuals @ residuals)  # as the fit computes it: a tie to the last bit
    answers = iter([[math.inf] * 3, [current] * 3, [current + 1.0, current - 1.0, current]])

    def objectives(points):  # three batches answered as above, the fourth scored
        calls.append(("batch", np.array(points)))
        batches.append(np.array(points))
        answer = next(answers, None)
        return np.array(answer) if answer is not None else np.array(
            [float(np.sum((matrix @ p - target) ** 2)) for p in points])

    monkeypatch.setattr(problem, "objectives", objectives)
    recorder = gradient_fit.fit_levenberg_marquardt(
        problem, [start], 4, 3, gradient_fit.Recorder("6", "fit"), cost_ratio=2.0)
    assert [call[0] for call in calls] == ["jacobian", "batch", "batch", "batch", "jacobian",
                                           "batch"]
    np.testing.assert_allclose(grids[0], [1e-3, 1e-2, 1e-1], rtol=1e-15)
    np.testing.assert_allclose(grids[1], [1.0, 10.0, 100.0], rtol=1e-15)
    np.testing.assert_allclose(grids[2], [1e3, 1e4, 1e5], rtol=1e-15)
    assert [row["objective"] for row in recorder.rows[1:4]] == [math.inf] * 3
    # after two batches the start is still the best (a tie does not move the fit: the calls
    # above, no Jacobian before the third batch)
    assert recorder.rows[6]["best_objective"] == recorder.rows[0]["objective"]
    # the third batch's middle point is taken: the Jacobian there, the grid around 1e4
    np.testing.assert_array_equal(calls[4][1], batches[2][1])
    np.testing.assert_allclose(grids[3], [1e3, 1e4, 1e5], rtol=1e-15)
    assert recorder.rows[9]["best_objective"] == current - 1.0


def spied_grids(monkeypatch):
    """The grids of dampings (and Jacobians) `damped_steps` is called with, in order."""
    grids, jacobians = [], []
    steps = gradient_fit.damped_steps

    def spy(residuals, jacobian, units, dampings):
        grids.append(np.array(dampings))
        jacobians.append(np.array(jacobian))
        return steps(residuals, jacobian, units, dampings)

    monkeypatch.setattr(gradient_fit, "damped_steps", spy)
    return grids, jacobians


def test_broyden_batches_keep_an_exact_jacobian_and_simulate_only_at_the_start(monkeypatch):
    """On linear residuals Broyden's update of the exact Jacobian along any step is that
    Jacobian again (to round-off) and every step achieves the reduction it predicted, so the
    Broyden-updated batches simulate the Jacobian at the start only: one run with
    sensitivities, then batches of `batch` points first and `later_batch` after, each grid
    centred on the damping that served, to the linear minimum. Costs: one call and every
    batch point."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    grids, jacobians = spied_grids(monkeypatch)
    minimum_units = np.linalg.lstsq(matrix, target, rcond=None)[0]
    minimum = float(np.sum((matrix @ minimum_units - target) ** 2))
    recorder = gradient_fit.fit_levenberg_marquardt(
        problem, gradient_fit.start_points(problem, 1, 0), 4, 5,
        gradient_fit.Recorder("6", gradient_fit.LEVENBERG_MARQUARDT_BROYDEN), cost_ratio=2.5,
        secant=True, later_batch=3)
    assert [call[0] for call in calls] == ["jacobian", "batch", "batch", "batch", "batch"]
    assert [len(call[1]) for call in calls[1:]] == [5, 3, 3, 3]
    np.testing.assert_allclose(grids[0], gradient_fit.damping_grid(
        gradient_fit.MARQUARDT_DAMPING, 5), rtol=1e-15)
    for before, after, batch in zip(grids, grids[1:], [call[1] for call in calls[1:]]):
        chosen = before[np.argmin([np.sum((matrix @ p - target) ** 2) for p in batch])]
        np.testing.assert_allclose(after, gradient_fit.damping_grid(chosen, 3), rtol=1e-15)
    # the updates change the exact Jacobian by round-off only: the rounding of the residuals'
    # change (~1e-16 of residuals ~1) over the step's length, ~1e-16 after the first step (~0.1
    # long), growing as the steps shrink near the minimum (3.3e-8 measured after the third);
    # a wrong Jacobian's error would be ~1
    np.testing.assert_allclose(jacobians[1], matrix, rtol=0.0, atol=1e-12)
    for jacobian in jacobians[2:]:
        np.testing.assert_allclose(jacobian, matrix, rtol=0.0, atol=1e-6)
    # the last grid's smallest damping is 1e-7 relative: the minimum to its square
    assert recorder.best_objective == pytest.approx(minimum, rel=1e-9)
    window = problem.base.period
    assert recorder.robot_seconds == pytest.approx((13 + 5 + 3 * 3) * window)
    assert recorder.cost_equivalent == pytest.approx((2.5 + 5 + 3 * 3) * window)
    assert len(recorder.rows) == 1 + 5 + 3 * 3


def test_a_broyden_jacobian_that_served_badly_is_simulated_where_the_fit_moved(monkeypatch):
    """After each improving batch the fit asks `secant_jacobian` (the secant fit's rule) with
    its point, residuals and Jacobian, no step refused, and the batch's best point and its
    residuals: where it answers None the Jacobian is simulated at that best point before the
    next batch; where it answers an update, the next batch steps with that update, no run."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    grids, jacobians = spied_grids(monkeypatch)
    asked, answers = [], iter([None, "update"])
    update = matrix + 0.5

    def secant_jacobian(last_units, last_residuals, last_jacobian, refused, units, residuals):
        asked.append((np.array(last_units), np.array(last_residuals), np.array(last_jacobian),
                      refused, np.array(units), np.array(residuals)))
        return None if next(answers) is None else update

    monkeypatch.setattr(gradient_fit, "secant_jacobian", secant_jacobian)
    start = identify.start_units(problem.box, problem.base)
    gradient_fit.fit_levenberg_marquardt(problem, [start], 3, 5,
                                         gradient_fit.Recorder("6", "fit"), cost_ratio=2.0,
                                         secant=True, later_batch=3)
    assert [call[0] for call in calls] == ["jacobian", "batch", "jacobian", "batch", "batch"]
    first_best = calls[1][1][np.argmin([np.sum((matrix @ p - target) ** 2)
                                        for p in calls[1][1]])]
    np.testing.assert_array_equal(calls[2][1], first_best)
    last_units, last_residuals, last_jacobian, refused, units, residuals = asked[0]
    np.testing.assert_array_equal(last_units, start)
    np.testing.assert_array_equal(last_residuals, matrix @ start - target)
    np.testing.assert_array_equal(last_jacobian, matrix)
    assert refused is False
    np.testing.assert_array_equal(units, first_best)
    np.testing.assert_array_equal(residuals, matrix @ first_best - target)
    assert len(asked) == 2
    np.testing.assert_array_equal(jacobians[1], matrix)  # simulated at the best point
    np.testing.assert_array_equal(jacobians[2], update)  # the update, no run


def test_a_broyden_batch_with_no_better_point_simulates_the_jacobian_where_the_fit_is(
        monkeypatch):
    """A batch with no better point from an updated Jacobian (every run failed) simulates the
    Jacobian at the current point and retries the same grid; from that simulated Jacobian a
    batch with none better (a tie with the current point's objective, as the batch scored it)
    moves the grid up its size in decades, no run; on the last batch nothing is simulated."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    grids, _ = spied_grids(monkeypatch)
    scored = problem.scored_points
    batches = []

    def scored_points(points):  # the 2nd and 5th batches fail, the 3rd ties
        objectives, residuals = scored(points)
        batches.append(np.array(points))
        if len(batches) in (2, 5):
            return np.full(len(points), math.inf), np.full(residuals.shape, math.inf)
        if len(batches) == 3:
            first = batches[0][np.argmin([np.sum((matrix @ p - target) ** 2)
                                          for p in batches[0]])]
            tie = float(np.sum((matrix @ first - target) ** 2))
            return np.full(len(points), tie), residuals
        return objectives, residuals

    monkeypatch.setattr(problem, "scored_points", scored_points)
    start = identify.start_units(problem.box, problem.base)
    recorder = gradient_fit.fit_levenberg_marquardt(problem, [start], 5, 5,
                                                    gradient_fit.Recorder("6", "fit"),
                                                    cost_ratio=2.0, secant=True, later_batch=3)
    assert [call[0] for call in calls] == ["jacobian", "batch", "batch", "jacobian", "batch",
                                           "batch", "batch"]
    first = batches[0][np.argmin([np.sum((matrix @ p - target) ** 2) for p in batches[0]])]
    np.testing.assert_array_equal(calls[3][1], first)
    np.testing.assert_array_equal(grids[2], grids[1])
    np.testing.assert_allclose(grids[3], grids[2] * 1e3, rtol=1e-15)
    assert recorder.rows[-1]["best_objective"] < recorder.rows[1 + 5]["best_objective"]
    assert recorder.stop_reasons == ["start 0: its 5 batches were spent"]
    # two Jacobians (13 instances each literally, 2 runs at cost) and 5 + 4 × 3 points
    window = problem.base.period
    assert recorder.robot_seconds == pytest.approx((2 * 13 + 5 + 4 * 3) * window)
    assert recorder.cost_equivalent == pytest.approx((2 * 2.0 + 5 + 4 * 3) * window)
    assert len(recorder.rows) == 2 + 5 + 4 * 3


def test_a_failed_first_batch_moves_a_narrower_grid_to_just_above_it(monkeypatch):
    """A start's first batch (5 dampings, 1e-4 to 1) with no better point from its simulated
    Jacobian: the next grid (3 points) starts a decade above its largest damping, 10 to 1000,
    none skipped (moving its centre 5 decades would leave 10 out)."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    grids, _ = spied_grids(monkeypatch)
    scored = problem.scored_points
    answered = []

    def scored_points(points):  # the first batch fails, the second is scored
        answered.append(len(points))
        objectives, residuals = scored(points)
        if len(answered) == 1:
            return np.full(len(points), math.inf), np.full(residuals.shape, math.inf)
        return objectives, residuals

    monkeypatch.setattr(problem, "scored_points", scored_points)
    gradient_fit.fit_levenberg_marquardt(problem, [identify.start_units(problem.box,
                                                                        problem.base)], 2, 5,
                                         gradient_fit.Recorder("6", "fit"), cost_ratio=2.0,
                                         secant=True, later_batch=3)
    np.testing.assert_allclose(grids[0], [1e-4, 1e-3, 1e-2, 1e-1, 1.0], rtol=1e-15)
    np.testing.assert_allclose(grids[1], [10.0, 100.0, 1000.0], rtol=1e-15)
    assert [call[0] for call in calls] == ["jacobian", "batch", "batch"]


def test_vanishing_steps_from_an_updated_jacobian_are_checked_with_a_simulated_one(
        monkeypatch):
    """An update that leaves the Jacobian zero makes every damped step vanish: the fit
    simulates the Jacobian where it is and steps with that before it would end the start (a
    stationary point of the update need not be one of the residuals)."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    monkeypatch.setattr(gradient_fit, "secant_jacobian",
                        lambda *args: np.zeros_like(matrix))
    recorder = gradient_fit.fit_levenberg_marquardt(
        problem, [identify.start_units(problem.box, problem.base)], 2, 5,
        gradient_fit.Recorder("6", "fit"), cost_ratio=2.0, secant=True, later_batch=3)
    assert [call[0] for call in calls] == ["jacobian", "batch", "jacobian", "batch"]
    first = calls[1][1][np.argmin([np.sum((matrix @ p - target) ** 2) for p in calls[1][1]])]
    np.testing.assert_array_equal(calls[2][1], first)
    assert recorder.stop_reasons == ["start 0: its 2 batches were spent"]


def test_scored_points_are_the_objectives_and_residuals_of_one_batched_run(monkeypatch):
    """Each point's objective is `objectives`' and its residuals are `residuals`', bitwise (the
    same per-gait fits), their squares summing to the objective; a point whose run failed
    scores inf with a row of inf, the others as alone."""
    box = [identify.parse_range_spec("alpha=0.2:1.5", "--sets")]
    base, solver, window = StarParams(), SolverConfig(dt=5e-3), (1, 1)
    gaits = ["A1+A2", "A1+A3"]
    trials = identification.measured_trials(gaits, base.period)
    problem = gradient_fit.Problem(box, base, gaits, trials, window, solver, "cpu")
    points = np.array([[0.3], [0.7]])
    objectives, residuals = problem.scored_points(points)
    np.testing.assert_array_equal(objectives, problem.objectives(points))
    for point, row in zip(points, residuals):
        np.testing.assert_array_equal(row, problem.residuals(point))
    # Σ r² and the mean of the gaits' objectives sum the same numbers in another order
    np.testing.assert_allclose(np.sum(residuals ** 2, axis=1), objectives, rtol=1e-12)
    runs = problem.runs

    def second_point_fails(params, cycles, sensitivities=()):
        simulated, result = runs(params, cycles, sensitivities)
        return simulated[:2] + [None] + simulated[3:], result

    monkeypatch.setattr(problem, "runs", second_point_fails)
    failed_objectives, failed_residuals = problem.scored_points(points)
    assert failed_objectives[0] == objectives[0] and failed_objectives[1] == math.inf
    np.testing.assert_array_equal(failed_residuals[0], residuals[0])
    assert np.all(failed_residuals[1] == math.inf)


def recorder_of(parameter_set, optimiser, objectives, costs, equivalent_costs=None):
    """A Recorder with one row per objective, each costing `costs[k]` robot-seconds counted
    literally and `equivalent_costs[k]` (default the same) counted at a call's cost."""
    recorder = gradient_fit.Recorder(parameter_set, optimiser)
    for objective, cost, equivalent in zip(objectives, costs, equivalent_costs or costs):
        recorder.add(np.zeros(2), objective, cost, equivalent)
    return recorder


def test_the_cma_budgets_compare_each_optimiser_with_cma_after_each_generation():
    """After CMA-ES's generation g (two points each): its best so far (a worse later
    generation keeps it) and its robot-seconds; each other optimiser's cost-equivalent
    robot-seconds at its first point at or below that objective (a point equal to it counts),
    NaN where none is; an unfinished generation gives no row; the polish, whose costs include
    CMA-ES's whole run, has none."""
    cma = recorder_of("6", "CMA-ES", [10.0, 8.0, 9.0, 7.0, 9.5, 9.0, 5.0, 6.0, 1.0], [1.0] * 9)
    fit = recorder_of("6", "fit", [9.0, 7.0, 6.0], [30.0, 20.0, 40.0], [3.0, 2.0, 4.0])
    polish = recorder_of("6", gradient_fit.POLISH, [0.5], [100.0])
    other_set = recorder_of("20", "fit", [0.0], [1.0])
    table = gradient_fit.cma_budget_shares([cma, fit, polish, other_set], {"6": 2, "20": 2})
    assert list(table.columns) == gradient_fit.CMA_BUDGET_COLUMNS
    assert table["cma_generations"].tolist() == [1, 2, 3, 4]
    assert table["cma_objective"].tolist() == [8.0, 7.0, 7.0, 5.0]
    assert table["cma_robot_seconds"].tolist() == [2.0, 4.0, 6.0, 8.0]
    assert set(table["optimiser"]) == {"fit"} and set(table["parameter_set"]) == {"6"}
    # 8 is first passed at the fit's second point (7, cost-equivalent 3 + 2); 7 is met there
    np.testing.assert_array_equal(table["cost_equivalent_to_cma_objective"],
                                  [5.0, 5.0, 5.0, np.nan])
    np.testing.assert_array_equal(table["share_of_cma_cost_equivalent"],
                                  [2.5, 1.25, 5.0 / 6.0, np.nan])
    assert gradient_fit.cma_budget_shares([fit], {"6": 2}).empty


def test_a_start_whose_damped_steps_vanish_stops_before_its_batch(monkeypatch):
    """A zero Jacobian (a start whose run failed) gives steps of length zero: the start ends
    before its first batch, saying so, and the next start runs; at the minimum of a linear
    problem the steps vanish too, and the fit stops there before its budget."""
    problem, calls, matrix, target = linear_levenberg_marquardt_problem(monkeypatch)
    fitted = problem.residuals_and_jacobian
    answers = iter([(np.full(15, 10.0), np.zeros((15, 6)))])
    monkeypatch.setattr(problem, "residuals_and_jacobian",
                        lambda units: next(answers, None) or fitted(units))
    start = identify.start_units(problem.box, problem.base)
    recorder = gradient_fit.fit_levenberg_marquardt(
        problem, [start, start], 40, 7, gradient_fit.Recorder("6", "fit"), cost_ratio=2.0)
    assert recorder.rows[0]["objective"] == 1500.0 and recorder.rows[1]["start"] == 1
    assert recorder.stop_reasons[0] == ("start 0: its damped steps vanished (at most 1e-12) "
                                        "after 0 batches")
    assert recorder.stop_reasons[1].startswith("start 1: its damped steps vanished")
    batches = int(recorder.stop_reasons[1].split("after ")[1].split()[0])
    assert 1 <= batches < 40
    minimum_units = np.linalg.lstsq(matrix, target, rcond=None)[0]
    minimum = float(np.sum((matrix @ minimum_units - target) ** 2))
    assert recorder.best_objective == pytest.approx(minimum, rel=1e-12)


def test_cma_es_runs_with_the_settings_it_is_given(monkeypatch):
    """fit_cma hands its settings, σ0 included, to the CMA-ES driver unchanged."""
    box = box_of("6")
    problem = gradient_fit.Problem(box, StarParams(gait="A1+A2"), ["A1+A2"], {}, (1, 1),
                                   SolverConfig(), "cpu")
    settings = identify.CMASettings(popsize=3, max_generations=2, seed=5, sigma0=0.05)
    given = []

    def driver(box, start, evaluate, settings):
        given.append(settings)
        return identify.CMAResult(pd.DataFrame(), None, ["maxiter=2"])

    monkeypatch.setattr(identify, "minimise_cmaes", driver)
    recorder = gradient_fit.fit_cma(problem, settings, gradient_fit.Recorder("6", "CMA-ES"))
    assert given == [settings] and given[0].sigma0 == 0.05
    assert recorder.stop_reasons == ["start 0: maxiter=2"]


@pytest.mark.parametrize("argv, refused", [
    # a setting moves only with every fit it sets left out; one of its fits left is enough
    (["--lm-batch", "3", "--lm-iterations", "0", "--lm-broyden-iterations", "0"], True),
    (["--lm-batch", "3", "--lm-iterations", "0", "--lm-broyden-iterations", "1"], False),
    (["--lm-batch", "3", "--lm-iterations", "1", "--lm-broyden-iterations", "0"], False),
    (["--lm-batch", str(gradient_fit.DEFAULT_LM_BATCH), "--lm-iterations", "0",
      "--lm-broyden-iterations", "0"], False),
    (["--lm-broyden-batch", "2", "--lm-broyden-iterations", "0"], True),
    (["--lm-broyden-batch", "2", "--lm-broyden-iterations", "1", "--lm-iterations", "0"], False),
    (["--least-squares-method", "dogbox", "--least-squares-evaluations", "0",
      "--broyden-evaluations", "0"], True),
    (["--least-squares-method", "dogbox", "--least-squares-evaluations", "0",
      "--broyden-evaluations", "0", "--polish-evaluations", "1"], False),
    (["--least-squares-method", "dogbox", "--least-squares-evaluations", "1",
      "--broyden-evaluations", "0"], False),
])
def test_a_setting_of_fits_all_left_out_is_refused_and_one_fit_left_keeps_it(argv, refused):
    """The flags' edge: a changed setting is refused when every fit it sets is at 0 and taken
    when one of them (any one) runs, or when it is the default."""
    args = gradient_fit.build_parser().parse_args(argv)
    if refused:
        with pytest.raises(cli.StudyArgumentError, match=r"^--[\w-]+ \w+: unused"):
            gradient_fit.check_flags_of_fits_left_out(args)
    else:
        gradient_fit.check_flags_of_fits_left_out(args)
