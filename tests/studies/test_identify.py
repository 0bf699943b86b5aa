"""Model identification: per-cycle experimental speeds, the calibration objective, parameter
boxes (values from unit coordinates), argument validation before compute, and the calibrate /
cross-validation / sensitivity studies in --quick mode with value checks."""

import ast
import json
import math

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams, experiment, identification
from taichi_star.batch import RunStoreError
from taichi_star.experiment import (EXPERIMENT_PERIOD_S, PAPER_GAITS)

from studies import calibrate, cli, identify, sensitivity
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]
T = EXPERIMENT_PERIOD_S


# ----------------------------------------------------------------------------- objective

def test_objective_zero_at_measurement_and_grows_when_a_direction_flips():
    table = experiment.measurement_table(PAPER_GAITS)
    assert table["weight"].mean() == pytest.approx(1.0)
    # the best-measured gait (smallest relative spread) weighs most: A1+A4
    assert table["weight"].idxmax() == "A1+A4"
    target = table["target_signed_mm_s"].to_numpy()
    assert list(np.sign(target)) == [1, 1, -1, -1, -1]
    assert experiment.objective_values(target[None, :], table)[0] == 0.0
    for g, gait in enumerate(PAPER_GAITS):
        flipped = target.copy()
        flipped[g] = -flipped[g]
        # r_g = -2 for the flipped gait, 0 elsewhere: objective = 4 w_g / sum(w)
        value = experiment.objective_values(flipped[None, :], table)[0]
        assert value == pytest.approx(4 * table["weight"].iloc[g] / table["weight"].sum())
        # a flipped direction costs more than any speed error of the right sign up to ×2
        half, double = target.copy(), target.copy()
        half[g] *= 0.5
        double[g] *= 2.0
        assert value > experiment.objective_values(np.stack([half, double]), table).max()
    failed = target.copy()
    failed[0] = np.nan
    assert experiment.objective_values(failed[None, :], table)[0] == math.inf
    uniform = experiment.measurement_table(["A1", "A1+A4"], weights="uniform")
    assert list(uniform["weight"]) == [1.0, 1.0]
    with pytest.raises(ValueError, match="empty gait list"):
        experiment.measurement_table([])


# ----------------------------------------------------------------------------- boxes

def test_parameter_values_come_from_unit_coordinates_and_stay_in_range():
    linear = identify.parse_range_spec("alpha=0.4:1.2")
    log = identify.parse_range_spec("cylinder_drag=1:100:log")
    assert linear.values([0.0, 1.0]).tolist() == [0.4, 1.2]  # exactly, no 0.4 − 0.4 leftovers
    assert log.values([0.0, 1.0]).tolist() == [1.0, 100.0]
    assert log.values(0.5) == pytest.approx(10.0)
    unit = np.random.default_rng(0).uniform(-0.1, 1.1, 10_000)  # clipped outside [0, 1]
    for spec in (linear, log):
        values = spec.values(unit)
        assert values.min() >= spec.low and values.max() <= spec.high
        inside = (unit > 0) & (unit < 1)
        assert np.array([spec.unit(v) for v in values[inside][:100]]) == pytest.approx(
            unit[inside][:100], abs=1e-12)
    assert linear.unit(0.0) == 0.0 and linear.unit(5.0) == 1.0  # outside the box: clipped


def test_value_per_unit_is_the_derivative_of_the_values_in_unit_coordinates():
    """The scale that turns gradients and spreads between unit coordinates and values
    (gradient_fit, model_select): against central differences of `values` inside the box
    (relative 1e-8: a step of 1e-5 in u leaves a truncation of (1e-5)²·ln(100)²/6 ≈ 4e-10 on
    the log axis and round-off of 1e-16/1e-5)."""
    linear = identify.parse_range_spec("alpha=0.4:1.2")
    log = identify.parse_range_spec("cylinder_drag=1:100:log")
    h = 1e-5
    for spec in (linear, log):
        for u in (0.1, 0.5, 0.9):
            value = float(spec.values(u))
            central = float(spec.values(u + h) - spec.values(u - h)) / (2 * h)
            assert spec.value_per_unit(value) == pytest.approx(central, rel=1e-8)
    assert linear.value_per_unit(0.7) == pytest.approx(0.8, abs=1e-15)  # high − low anywhere
    assert identify.box_value_per_unit([linear, log], [0.7, 10.0]).tolist() == [
        linear.value_per_unit(0.7), log.value_per_unit(10.0)]


@pytest.mark.parametrize("study, argv, message", [
    # argparse's own refusals, one line like the studies' checks (cli.OneLineParser)
    ("fig4c", ["--no-such-flag"], "unrecognized arguments: --no-such-flag (see --help)"),
    ("fig4c", ["--cycles", "abc"], "argument --cycles: invalid float value: 'abc'"),
    ("sweep", ["--arch", "tpu"], "argument --arch: invalid choice: 'tpu'"),
    ("calibrate", ["--fit", "alpha=1.5:0.2"], "--fit alpha: reversed or empty bounds"),
    ("calibrate", ["--fit", "alpha=0.5:0.5"], "--fit alpha: reversed or empty bounds"),
    ("calibrate", ["--fit", "alpha=0:inf"], "--fit alpha: 'inf' is not a finite number"),
    ("calibrate", ["--fit", "alpha=nan:1"], "--fit alpha: 'nan' is not a finite number"),
    ("calibrate", ["--fit", "alpha=0.2"], "--fit alpha: malformed bounds"),
    ("calibrate", ["--fit", "beta=0:1"], "unknown parameter 'beta'"),
    ("calibrate", ["--fit", "jet_mode=0:1"], "--fit jet_mode: not a real-valued numeric field"),
    ("calibrate", ["--fit", "n_arc=10:20"], "--fit n_arc: not a real-valued numeric field"),
    ("calibrate", ["--fit", "alpha=0:20"], "--fit alpha: bounds 0:20 leave the field's valid "
                                           "range [0, 10]"),
    ("calibrate", ["--fit", "period=0:5"], "--fit period: bounds 0:5 leave the field's valid "
                                           "range (0, 1000]"),
    ("calibrate", ["--fit", "cylinder_drag=0:100:log"], "--fit cylinder_drag: a log axis needs"),
    ("calibrate", ["--fit", "joint_radius=0.02:0.03"], "joint_radius must be a real number in"),
    ("calibrate", ["--fit", "alpha=0.2:1", "--fit", "alpha=0.3:1"], "--fit alpha: given twice"),
    ("calibrate", ["--gaits", ""], "--gaits: empty gait list"),
    ("calibrate", ["--gaits", "A1,A1+A6"], "--gaits A1+A6: not measured"),
    ("calibrate", ["--gaits", "A1", "--cross-validate"], "--cross-validate: needs at least two"),
    ("calibrate", ["--set", "alpha=1", "--fit", "alpha=0.2:1"], "--set alpha: fitted"),
    ("calibrate", ["--popsize", "1"], "--popsize must be >= 2"),
    ("calibrate", ["--max-generations", "0"], "--max-generations must be >= 1"),
    ("calibrate", ["--restarts", "-1"], "--restarts must be >= 0"),
    ("calibrate", ["--sigma0", "0"], "--sigma0 must be in (0, 1]"),
    ("sensitivity", ["--vary", "alpha=1:0.2"], "--vary alpha: reversed or empty bounds"),
    ("sensitivity", ["--vary", "gait=0:1"], "--vary gait: not a real-valued numeric field"),
    ("sensitivity", ["--base-samples", "6"], "--base-samples must be a power of 2"),
    ("sensitivity", ["--gaits", ""], "--gaits: empty gait list"),
])
def test_invalid_arguments_fail_before_compute(no_compute, tmp_path, capsys, study, argv,
                                               message):
    assert studies_main([study, *argv, "--out", str(tmp_path), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert error.count("\n") == 1 and "Traceback" not in error  # one line, no traceback
    assert not any(tmp_path.iterdir())  # nothing written


def test_reproduce_refuses_an_unknown_flag_in_one_line(no_compute, capsys):
    assert studies_main(["reproduce", "--dry-run", "--bogus"]) == 2
    error = capsys.readouterr().err
    assert error == ("python -m studies reproduce: error: unrecognized arguments: --bogus "
                     "(see --help)\n")


def test_api_bad_input_raises_value_error(no_compute):
    base = StarParams()
    with pytest.raises(ValueError, match="alpha: reversed"):
        identify.parse_range_spec("alpha=2:1")
    with pytest.raises(ValueError, match="no parameters to vary"):
        calibrate.fit_cmaes([], base, experiment.measurement_table(["A1"]))
    with pytest.raises(ValueError, match="tip_radius must be a real number in"):
        identify.check_box([identify.ParameterRange("tip_radius", 0.01, 0.06)], base)
    with pytest.raises(ValueError, match="--popsize must be >= 2"):
        calibrate.fit_cmaes([identify.ParameterRange("alpha", 0.2, 1.0)], base,
                            experiment.measurement_table(["A1"]), calibrate.CMASettings(popsize=1))


# ----------------------------------------------------------------------------- studies, quick

def quick_speeds(points, gaits):
    """Direct `simulate` of {field: value} points on gaits, --quick settings: signed speeds
    (points, gaits)."""
    params = [StarParams(gait=g, **p) for p in points for g in gaits]
    summary = taichi_star.simulate(params, cli.QUICK_DURATION_S,
                                   SolverConfig(dt=cli.QUICK_DT)).summary
    return summary["signed_speed_mm_s"].to_numpy().reshape(len(points), len(gaits))


def test_calibrate_names_fitted_gains_no_gait_fires_before_it_fits(no_compute, monkeypatch,
                                                                  tmp_path, capsys):
    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop
    monkeypatch.setattr(experiment, "measurement_table", stop)  # the step after the note
    for fits, note in ((["actuator_gains[7]=0.3:2", "alpha=0.5:2"],
                        "--fit: actuator_gains[7] belongs to an actuator that no fitted gait "
                        "fires (A1, A1+A2): the fit does not depend on it"),
                       (["actuator_gains[2]=0.3:2"], None)):
        with pytest.raises(Stop):
            calibrate.main([*(f"--fit={fit}" for fit in fits), "--gaits", "A1,A1+A2", "--out",
                            str(tmp_path), "--no-progress"])
        error = capsys.readouterr().err
        assert (note in error) if note else ("note" not in error), error


def test_calibrate_refuses_a_box_no_fitted_gait_moves(no_compute, tmp_path, capsys):
    """A box of unfired gains alone: a flat objective, on which cma failed in one dimension
    with a traceback after the first generations (an audit, 2026-12)."""
    out = tmp_path / "out"
    assert studies_main(["calibrate", "--fit", "actuator_gains[8]=0.5:1.5", "--fit",
                         "actuator_gains[7]=0.5:1.5", "--out", str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert ("--fit: actuator_gains[8], actuator_gains[7]: no fitted gait fires their actuators "
            "(A1, A1+A2, A1+A3, A1+A4, A1+A3+A5), so the fit depends on none of its parameters"
            in error), error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


def test_calibrate_fits_one_actuators_gain_end_to_end(tmp_path):
    """--fit NAME[INDEX]: the plot and the best model read that axis' own columns
    (actuator_gains_1, u_actuator_gains_1); the field's name had been used, a KeyError after
    the whole fit (an audit, 2026-12). The calibrated robot runs with the fitted A1 gain."""
    calibrate.main(["--quick", "--fit", "actuator_gains[1]=0.5:1.5", "--gaits", "A1",
                    "--popsize", "2", "--max-generations", "1", "--out", str(tmp_path),
                    "--no-progress"])
    gain = pd.read_csv(tmp_path / "calibration_best.csv")["actuator_gains_1"].iloc[0]
    assert 0.5 <= gain <= 1.5
    assert (tmp_path / "calibration.png").stat().st_size > 1000
    calibrated = pd.read_csv(tmp_path / "fig4c_calibrated_summary.csv")["actuator_gains"]
    # the tuple's text, A1 first; the CSV's 10 digits of the fitted value
    gains = ast.literal_eval(calibrated.iloc[0])
    assert gains[0] == pytest.approx(gain, rel=1e-9) and gains[1:] == (1.0,) * 7


def test_calibrate_quick_against_a_direct_simulation(tmp_path):
    calibrate.main(["--out", str(tmp_path), *QUICK])
    evaluations = pd.read_csv(tmp_path / "calibration.csv")
    box = [identify.parse_range_spec(text) for text in calibrate.QUICK_FIT]
    assert len(evaluations) == calibrate.QUICK_POPSIZE * calibrate.QUICK_MAX_GENERATIONS
    assert evaluations["evaluation"].tolist() == list(range(len(evaluations)))
    for spec in box:  # every value in its range, computed from its unit coordinate
        unit = evaluations[f"u_{spec.name}"].to_numpy()
        assert ((unit >= 0) & (unit <= 1)).all()
        values = evaluations[spec.name].to_numpy()
        assert ((values >= spec.low) & (values <= spec.high)).all()
        assert values == pytest.approx(spec.values(unit), rel=1e-9)  # CSV keeps 10 digits

    best = pd.read_csv(tmp_path / "calibration_best.csv").iloc[0]
    assert best["objective"] == pytest.approx(evaluations["objective"].min(), rel=1e-9)
    point = {spec.name: float(best[spec.name]) for spec in box}
    # the same robots simulated directly (results do not depend on the batch; values written
    # with 10 significant digits change the speeds far below 1e-6)
    direct = quick_speeds([point], PAPER_GAITS)[0]
    stored = [best[f"signed_speed_{g}"] for g in PAPER_GAITS]
    assert direct == pytest.approx(stored, rel=1e-6)
    measurements = experiment.measurement_table(PAPER_GAITS)
    assert experiment.objective_values(direct[None, :], measurements)[0] == pytest.approx(
        best["objective"], rel=1e-6)
    assert best["all_directions_match"] == all(
        np.sign(direct) == measurements["paper_sign"].to_numpy())
    assert best["fit_box"] == " ".join(spec.spec for spec in box) and best["seed"] == 1
    # --quick runs a duration, not cycles (3 was recorded; an audit, 2026-12)
    assert math.isnan(best["cycles"]) and best["duration_s"] == cli.QUICK_DURATION_S
    sidecar = json.loads((tmp_path / "calibration_best.csv.json").read_text())
    assert sidecar["study"] == "calibrate" and sidecar["solver"]["dt"] == cli.QUICK_DT
    assert sidecar["details"]["fit"] == calibrate.QUICK_FIT

    figure = calibrate.draw_convergence(evaluations, box)
    top, bottom = figure.axes[:2]
    low, high = top.get_ylim()  # a log axis around the objectives, not down to 1e-16
    finite = evaluations["objective"][np.isfinite(evaluations["objective"])]
    assert top.get_yscale() == "log"
    assert finite.min() / 2 <= low < finite.min() and finite.max() < high <= finite.max() * 2
    assert bottom.get_ylim() == pytest.approx((-0.02, 1.02))
    calibrated = pd.read_csv(tmp_path / "fig4c_calibrated.csv")
    assert calibrated["sim_signed_speed_mm_s"].to_numpy() == pytest.approx(direct, rel=1e-6)
    for name in ("calibration.png", "fig4c_calibrated.png"):
        assert (tmp_path / name).stat().st_size > 1000


def test_cross_validation_quick(tmp_path):
    gaits = ["A1", "A1+A2", "A1+A4"]
    calibrate.main(["--out", str(tmp_path), "--cross-validate", "--gaits", ",".join(gaits),
                    "--popsize", "3", "--max-generations", "1", *QUICK])
    predictions = pd.read_csv(tmp_path / "crossval.csv")
    evaluations = pd.read_csv(tmp_path / "crossval_evaluations.csv")
    assert len(predictions) == len(gaits) ** 2
    for held_out in gaits:
        fold = evaluations[evaluations["held_out_gait"] == held_out]
        rows = predictions[predictions["held_out_gait"] == held_out].set_index("gait")
        assert len(fold) == 3
        assert fold[f"signed_speed_{held_out}"].isna().all()  # never fitted on it
        assert rows.loc[held_out, "role"] == "held_out"
        assert (rows.drop(index=held_out)["role"] == "fitted").all()
        best = fold.loc[fold["objective"].idxmin()]
        assert rows["fit_objective"].iloc[0] == pytest.approx(best["objective"], rel=1e-9)
        # the prediction batch reproduces the fit's speeds at the best point
        for gait in rows.index.drop(held_out):
            assert rows.loc[gait, "predicted_signed_mm_s"] == pytest.approx(
                best[f"signed_speed_{gait}"], rel=1e-9)
        # and the held-out prediction is that point simulated directly
        point = {"alpha": float(best["alpha"]), "cylinder_drag": float(best["cylinder_drag"])}
        assert rows.loc[held_out, "predicted_signed_mm_s"] == pytest.approx(
            quick_speeds([point], [held_out])[0, 0], rel=1e-6)
    assert (tmp_path / "crossval.png").stat().st_size > 1000


def test_sobol_indices_of_the_ishigami_function():
    # the analysis code path of the study on a function with known indices (a = 7, b = 0.1 on
    # [-π, π]³): S1 = (0.3139, 0.4424, 0), ST = (0.5576, 0.4424, 0.2437). Each exact index must
    # lie inside the estimate's 95 % confidence interval (deterministic seed; the half-widths
    # are 0.03-0.09 at N = 1024, the errors ≤ 0.023 for seeds 1-3), and those intervals must be
    # narrow enough to tell the three inputs apart.
    box = [identify.ParameterRange(f"x{i}", -math.pi, math.pi) for i in range(3)]
    x = identify.box_values(box, sensitivity.saltelli_units(3, 1024, seed=1))
    y = np.sin(x[:, 0]) + 7 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])
    table = sensitivity.sobol_indices(["x0", "x1", "x2"], {"ishigami": y}, seed=1)
    for key, exact in (("S1", [0.3139, 0.4424, 0.0]), ("ST", [0.5576, 0.4424, 0.2437])):
        error = np.abs(table[key].to_numpy() - exact)
        assert (error <= table[f"{key}_conf"]).all(), (key, error)
        assert (table[f"{key}_conf"] < 0.1).all()
    failed = sensitivity.sobol_indices(["x0", "x1", "x2"], {"f": np.where(x[:, 0] > 3, np.nan, y)})
    assert failed["S1"].isna().all() and failed["n_failed"].iloc[0] > 0


def test_sensitivity_quick_and_resumed(tmp_path, monkeypatch):
    argv = ["--vary", "alpha=0.4:1.2", "--vary", "cylinder_drag=3:30:log", "--gaits",
            "A1,A1+A4", "--base-samples", "4", "--out", str(tmp_path), *QUICK]
    sensitivity.main(argv)
    samples = pd.read_csv(tmp_path / "sensitivity_samples.csv")
    runs = pd.read_csv(tmp_path / "sensitivity_runs.csv")
    indices = pd.read_csv(tmp_path / "sensitivity.csv")
    assert len(samples) == 4 * (2 + 2) and len(runs) == 2 * len(samples)
    assert (runs["status"] == "ok").all()
    assert set(indices["gait"]) == {"A1", "A1+A4"} and len(indices) == 4
    assert (indices["n_instances"] == len(runs)).all()
    # --quick simulates 0.2 s from rest, not the cycles (3 were recorded: an audit, 2026-12)
    assert indices["cycles"].isna().all() and indices["quick"].all()
    # the runs are the sampled robots: two points simulated directly
    points = [{n: float(samples.loc[i, n]) for n in ("alpha", "cylinder_drag")} for i in (0, 5)]
    direct = quick_speeds(points, ["A1", "A1+A4"])
    stored = runs.set_index(["point", "gait"])["signed_speed_mm_s"]
    assert direct[1, 1] == pytest.approx(stored[(5, "A1+A4")], rel=1e-6)
    assert direct[0, 0] == pytest.approx(stored[(0, "A1")], rel=1e-6)
    # the indices are those of the runs CSV
    again = sensitivity.sobol_indices(
        ["alpha", "cylinder_drag"],
        {g: runs.loc[runs["gait"] == g, "signed_speed_mm_s"].to_numpy() for g in ("A1", "A1+A4")},
        seed=1)
    assert indices["ST"].to_numpy() == pytest.approx(again["ST"].to_numpy(), rel=1e-6)
    assert (tmp_path / "sensitivity.png").stat().st_size > 1000
    # resumed from its run store (<out>/chunks): nothing simulated again, the same tables
    def forbidden(*args, **kwargs):
        raise AssertionError("the resumed run simulated a stored chunk again")
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", forbidden)
    sensitivity.main([*argv, "--resume"])
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "sensitivity_runs.csv"), runs)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "sensitivity.csv"), indices)
    # resumed with another seed: the run store refuses, and the folder's tables stay those of
    # its run (the samples were replaced by the other seed's before the refusal; an audit)
    tables = {path.name: path.read_bytes() for path in tmp_path.glob("sensitivity*")}
    with pytest.raises(RunStoreError, match="another definition"):
        sensitivity.main([*argv, "--seed", "2", "--resume"])
    assert {path.name: path.read_bytes() for path in tmp_path.glob("sensitivity*")} == tables


def test_sensitivity_keeps_two_elements_of_one_field_apart(tmp_path):
    """Two axes of one per-actuator field: their unit coordinates, values and Sobol rows had
    shared the field's name, one axis' range and columns overwriting the other's (an audit,
    2026-12); each is named by its label (NAME[INDEX], the command line's) and its own columns."""
    sensitivity.main(["--vary", "actuator_gains[1]=0.5:1.5", "--vary",
                      "actuator_gains[3]=0.8:1.2", "--gaits", "A1+A3", "--base-samples", "2",
                      "--out", str(tmp_path), *QUICK])
    samples = pd.read_csv(tmp_path / "sensitivity_samples.csv")
    assert {"u_actuator_gains_1", "u_actuator_gains_3", "actuator_gains_1",
            "actuator_gains_3"} <= set(samples.columns)
    assert samples["actuator_gains_1"].between(0.5, 1.5).all()
    assert samples["actuator_gains_3"].between(0.8, 1.2).all()
    indices = pd.read_csv(tmp_path / "sensitivity.csv").set_index("parameter")
    assert list(indices.index) == ["actuator_gains[1]", "actuator_gains[3]"]
    assert indices.loc["actuator_gains[1]", ["low", "high"]].tolist() == [0.5, 1.5]
    assert indices.loc["actuator_gains[3]", ["low", "high"]].tolist() == [0.8, 1.2]


def test_a_fit_of_at_most_the_studys_instances_is_accepted_and_one_more_refused():
    """check_instances' boundary: cli.MAX_INSTANCES simulated instances run, one more is
    refused naming how they add up."""
    cli.check_instances(cli.MAX_INSTANCES, "the fit")
    with pytest.raises(cli.StudyArgumentError, match=r"^the fit: 1,000,001 instances, more than "
                                                     r"the 1,000,000 a study runs$"):
        cli.check_instances(cli.MAX_INSTANCES + 1, "the fit")
    # the evaluations it counts: every generation of every restart, the population doubling
    settings = identify.CMASettings(popsize=3, max_generations=5, restarts=2)
    assert settings.evaluations(4) == 5 * (3 + 6 + 12)


def test_cma_es_reports_why_each_restart_stopped():
    """minimise_cmaes on a quadratic in two unit axes (no simulation): with a cap of 3
    generations and no restart it stops on cma's iteration cap, and says so; with one restart,
    one reason per restart, in order."""
    box = [identify.parse_range_spec("alpha=0.2:1.5", "--fit"),
           identify.parse_range_spec("drag_perpendicular=0.3:3", "--fit")]

    def evaluate(units):
        return pd.DataFrame({"objective": np.sum((units - 0.3) ** 2, axis=1)})

    result = identify.minimise_cmaes(box, np.full(2, 0.5), evaluate,
                                     identify.CMASettings(max_generations=3, seed=1))
    assert result.stop_reasons == ["maxiter=3"]
    assert result.evaluations["generation"].max() == 2  # generations 0, 1, 2: the cap
    restarted = identify.minimise_cmaes(box, np.full(2, 0.5), evaluate,
                                        identify.CMASettings(max_generations=2, seed=1,
                                                             restarts=1))
    assert restarted.stop_reasons == ["maxiter=2", "maxiter=2"]


def test_a_sobol_batch_tells_its_hours_once_before_its_instances_are_built(
        tmp_path, monkeypatch, warnings_before_call):
    """As sweep's: the Sobol batch's robot-steps are told from its sampled points before their
    robots are built (a million took minutes before run_batch told them), each point at its
    own sampled period, and once (run_batch's own telling kept back). Six points of A1 for
    0.1 cycle of their periods (0.5-1 s) at the study's 3.15-ms steps: the sum of
    0.1·T_i/3.15 ms, 133 robot-steps, told past a limit of 100 (each instance's at most 32,
    below it, tells nothing of its own)."""
    from taichi_star import timegrid
    from taichi_star.batch import plan_chunks
    from taichi_star.batch.tasks import batch_robot_steps

    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 100)
    with warnings_before_call(identify, "box_params") as (caught, built):
        sensitivity.main(["--vary", "period=0.5:1", "--gaits", "A1", "--base-samples", "2",
                          "--cycles", "0.1", "--out", str(tmp_path), "--no-progress"])
    told = [str(w.message) for w in caught if w.category is taichi_star.LongWorkWarning]
    samples = pd.read_csv(tmp_path / "sensitivity_samples.csv")
    params = [StarParams(gait="A1", period=period) for period in samples["period_s"]]
    dt = sensitivity.DEFAULT_DT
    steps = batch_robot_steps(plan_chunks(params, cycles=0.1, solver=SolverConfig(dt=dt)))
    assert len(samples) == 6 and steps == pytest.approx((0.1 * samples["period_s"] / dt).sum())
    assert told == [f"the batch of 6 instances (--cycles 0.1 of each period) is {steps:.3g} "
                    f"robot-steps: about {steps / 5e4 / 3600:.3g} h at 50000 robot-steps/s (on "
                    f"a 2-core CPU; a GPU or more cores run faster)"]
    assert built == [told]


def test_a_window_must_be_covered_from_every_phase_of_a_period():
    """A1+A2's track (22.49 s, 7.14 periods of 3.15 s) covers cycles 4-6 from every phase
    and cycles 5-7 only from phases up to 0.44 s: the first accepted, the second refused
    naming the gait and the last window that works."""
    trials = identification.measured_trials(["A1+A2"])
    identify.check_trials_cover(trials, (4, 6), "4:6")
    with pytest.raises(cli.StudyArgumentError, match=r"^--validate-cycles 5:7: the A1\+A2 "
                                                     r"trial .* end at cycle 6 at the latest$"):
        identify.check_trials_cover(trials, (5, 7), "5:7")


def test_a_sobol_seed_of_zero_is_refused_since_salib_seeds_nothing_for_it():
    """SALib seeds its sample and its bootstrap only for a true seed: 0 gave other confidence
    intervals at every call (an audit, 2026-12). Refused in the library and on the command
    line; 1 reproduces bit for bit."""
    x = sensitivity.saltelli_units(3, 64, seed=1)
    y = {"f": x[:, 0] + 2 * x[:, 1] * x[:, 2]}
    first, again = (sensitivity.sobol_indices(["a", "b", "c"], y, seed=1) for _ in range(2))
    pd.testing.assert_frame_equal(first, again)
    for call in (lambda: sensitivity.saltelli_units(3, 64, seed=0),
                 lambda: sensitivity.sobol_indices(["a", "b", "c"], y, seed=0),
                 lambda: sensitivity.sobol_indices(["a", "b", "c"], y, seed=True)):
        with pytest.raises(ValueError, match=r"^seed must be an integer >= 1 \(SALib takes 0 "):
            call()


def test_an_evaluated_point_names_each_failed_gait_and_when(monkeypatch):
    """`evaluate_points` gave a failed point's status alone (an audit, 2026-12): which gait
    failed, and when, are its `failed_gaits`; a point whose gaits all ran has none, and a failed
    gait's speeds are NaN and its objective inf. The run is a stand-in: no simulation."""
    gaits = ["A1", "A1+A2"]
    measurements = experiment.measurement_table(gaits, "uniform")
    box = [identify.parse_range_spec("alpha=0.2:1.2", "--vary")]
    # two points of two gaits each, in run_batch's order (point-major): the second point's
    # A1+A2 failed at 1.2345 s
    summary = pd.DataFrame({"status": ["ok", "ok", "ok", "newton_failed"],
                            "failure_time_s": [np.nan, np.nan, np.nan, 1.2345],
                            "signed_speed_mm_s": [4.0, 3.0, 5.0, np.nan],
                            "speed_mm_s": [4.0, 3.0, 5.0, np.nan]})

    class Run:
        pass

    def fake_run_batch(params, **kwargs):
        assert [p.gait for p in params] == gaits * 2
        run = Run()
        run.summary = summary
        return run

    monkeypatch.setattr(identify, "run_batch", fake_run_batch)
    table = identify.evaluate_points(box, [[0.0], [1.0]], StarParams(), measurements, {})
    assert table["status"].tolist() == ["ok", "newton_failed"]
    assert table["failed_gaits"].tolist() == ["", "A1+A2 newton_failed at 1.234 s"]
    assert np.isnan(table["signed_speed_A1+A2"].iloc[1]) and table["objective"].iloc[1] == np.inf
    assert table["signed_speed_A1"].tolist() == [4.0, 5.0]
