"""The model-selection study: candidates as data (a missing field skips a candidate), the
leave-one-gait-out rule for per-actuator axes, bad arguments before compute, and the --quick
run checked against a direct simulation of its identified parameters."""

import ast
import json
import math
import types

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams, identification
from taichi_star.experiment import EXPERIMENT_PERIOD_S
from taichi_star.provenance import table_stamp
from taichi_star.timegrid import nearest_interval

from studies import cli, identify, model_select
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]


def test_candidates_are_data_and_missing_fields_are_noted(tmp_path):
    table = tmp_path / "candidates.csv"
    table.write_text("name,set,fit,description\n"
                     "paper,,alpha=0.2:1.5 cylinder_drag=1:100:log,baseline\n"
                     "future,jet_swirl=on,alpha=0.2:1.5 actuator_stiffnesses[4]=0.3:2,new\n")
    candidates = model_select.read_candidates(table)
    assert [c.name for c in candidates] == ["paper", "future"]
    assert candidates[0].missing_fields() == []
    assert candidates[1].missing_fields() == ["jet_swirl", "actuator_stiffnesses"]
    box = candidates[0].box(StarParams())
    assert [spec.spec for spec in box] == ["alpha=0.2:1.5", "cylinder_drag=1:100:log"]
    ramp = model_select.Candidate("ramp", "profile_closure=ramp", "alpha=0.2:1.5")
    assert ramp.model(StarParams()).profile_closure == "ramp"
    # every candidate of the default table names existing fields or is skipped by name
    for candidate in model_select.read_candidates(model_select.CANDIDATES_CSV):
        if not candidate.missing_fields():
            candidate.box(StarParams())


def test_the_rank_follows_held_out_gaits_plus_later_cycles_then_bic():
    """A candidate better on held-out gaits but worse on later cycles can rank below; equal
    held-out errors fall back to BIC; skipped candidates come last."""
    rows = [{"candidate": "a", "status": "ok", "logo_objective": 20.0, "validate_objective": 70.0,
             "bic": 1.0, "train_objective": 1.0},
            {"candidate": "b", "status": "ok", "logo_objective": 22.0, "validate_objective": 19.0,
             "bic": 9.0, "train_objective": 9.0},
            {"candidate": "c", "status": "ok", "logo_objective": 30.0, "validate_objective": 11.0,
             "bic": 5.0, "train_objective": 5.0},
            {"candidate": "d", "status": "skipped"}]
    table = model_select.ranked(rows)
    assert list(table["candidate"]) == ["c", "b", "a", "d"]
    assert list(table["rank"]) == [1, 2, 3, 4]
    assert table["held_out_objective"].iloc[0] == 41.0 and np.isnan(table["held_out_objective"].iloc[3])
    assert (table["stage"] == "screen").all()  # a row without a stage is a screened one


def test_a_refined_form_ranks_above_every_screened_one():
    """Rank 1 is the best refined form even where a screened form's held-out error is lower
    (the refine stage is the converged fit); the refine stage takes the best screened forms."""
    screen = [{"candidate": name, "stage": "screen", "status": "ok", "logo_objective": logo,
               "validate_objective": 10.0, "bic": 1.0, "train_objective": 1.0}
              for name, logo in (("a", 5.0), ("b", 3.0), ("c", 9.0), ("d", 1.0))]
    screen[3]["status"] = "failed"
    runnable = [model_select.Candidate(name, "", "alpha=0.2:1.5") for name in "abcd"]
    assert [c.name for c in model_select.refined_candidates(model_select.ranked(screen),
                                                            runnable, 2)] == ["b", "a"]
    assert [c.name for c in model_select.refined_candidates(model_select.ranked(screen),
                                                            runnable, 9)] == ["b", "a", "c"]
    refine = [{**screen[1], "stage": "refine", "logo_objective": 8.0},
              {**screen[0], "stage": "refine", "logo_objective": 7.0}]
    table = model_select.ranked(screen + refine)
    assert list(zip(table["stage"], table["candidate"])) == [
        ("refine", "a"), ("refine", "b"), ("screen", "b"), ("screen", "a"), ("screen", "c"),
        ("screen", "d")]
    assert list(table["rank"]) == [1, 2, 3, 4, 5, 6]


def test_a_resumed_candidate_is_reused_only_for_the_same_model(monkeypatch):
    """The definition names the base model by the fields that differ from the defaults: a field
    set to its default value (as a model option added later, off by default) changes nothing; a
    changed coefficient does, and so do phases held on the strokes."""
    candidate = model_select.Candidate("paper", "", "alpha=0.2:1.5 cylinder_drag=1:100:log")
    args = types.SimpleNamespace(fold_generations=2, train_cycles="1:3", validate_cycles="4:6",
                                 phases="fitted", periods="nominal", folds="warm")
    settings, solver = identify.CMASettings(), SolverConfig()
    base = StarParams.preset("paper")

    def definition(model):
        return model_select.definition_of(candidate, args, settings, model, solver, ["A1"])
    assert definition(base) == definition(StarParams.preset("paper", jet_mode="contract"))
    assert definition(base) != definition(StarParams.preset("paper", alpha=0.81))
    assert definition(base) != definition(StarParams.preset("paper", jet_mode="always"))
    fitted = definition(base)
    args.phases = "strokes"
    held = definition(base)
    assert held != fitted
    args.periods = "strokes"
    assert definition(base) != held
    # held results scored with the strokes read another way (their farthest moves, before
    # 2026-12-05) are not reused; fitted phases do not read the strokes at all
    monkeypatch.setattr(model_select, "STROKE_ALIGNMENT", "window")
    assert definition(base) != held
    args.phases, args.periods = "fitted", "nominal"
    assert definition(base) == fitted
    # cold folds assess another way: their results are not the warm folds'
    args.folds = "cold"
    assert definition(base) != fitted


def test_held_phases_refuse_a_trial_whose_strokes_lie_on_no_period_or_end_too_soon():
    """--phases strokes, before any compute: a trial whose strokes lie on no line (three of six
    pulses a second off it) is refused naming the gait and the flag, and one with too few
    strokes for the windows; every measured trial's strokes lie on one (results/strokes.csv:
    read where they begin, A1+A3's too)."""
    t = np.arange(0.0, 6 * 3.15 + 0.5, 1e-3)
    pulses = 0.7 + 3.15 * np.arange(6) + np.array([0.0, 1.0, 0.0, 1.0, 0.0, 1.0])
    surge = sum(1.0 + np.vectorize(math.erf)((t - pulse) / (0.02 * math.sqrt(2)))
                for pulse in pulses)
    trial = identification.Trial("A1+A2", identification.CentroidPath(t, 0.5 * t, surge, 3.15),
                                 1.0)
    with pytest.raises(model_select.cli.StudyArgumentError,
                       match=r"--periods strokes: A1\+A2's strokes do not lie on one period "
                             r"\(\d of 6 within 0.2 s of their line\)"):
        model_select.measured_strokes({"A1+A2": trial}, 3, "--periods strokes")
    measured = identification.measured_trials()
    assert all(read.periodic for read in model_select.measured_strokes(measured, 6).values())
    with pytest.raises(model_select.cli.StudyArgumentError,
                       match=r"--phases strokes: A1\+A2's track has 7 strokes, the windows end "
                             r"at cycle 7 \(one period more is needed\)"):
        model_select.measured_strokes(measured, 7)


def test_a_per_actuator_axis_is_informed_only_by_gaits_that_fire_it():
    # a stand-in model with a per-actuator field (the extensions add such fields)
    base = types.SimpleNamespace(actuator_gains=(1.0,) * 8, pair=(0.0, 0.0))
    box = [identify.ParameterRange("alpha", 0.2, 1.5),
           identify.ParameterRange("actuator_gains", 0.3, 2.0, index=4),
           identify.ParameterRange("actuator_gains", 0.3, 2.0, index=3),
           identify.ParameterRange("pair", 0.0, 1.0, index=2)]  # not per actuator
    # A1+A4 held out: no other paper gait fires A4, so its gain stays at the prior
    others = ["A1", "A1+A2", "A1+A3", "A1+A3+A5"]
    assert model_select.informed_axes(box, base, others) == [True, False, True, True]
    assert model_select.informed_axes(box, base, ["A1+A4"]) == [True, True, False, True]
    changes = identify.point_changes(box[1:3], [0.5, 0.7], base)
    assert changes == {"actuator_gains": (1.0, 1.0, 0.7, 0.5, 1.0, 1.0, 1.0, 1.0)}


@pytest.mark.parametrize("argv, message", [
    (["--train-cycles", "0:3"], "--train-cycles: expected FIRST:LAST"),
    (["--train-cycles", "1:2", "--validate-cycles", "2:3"], "--validate-cycles 2:3: must start "
                                                             "after"),
    (["--only", "nothing"], "--only: unknown value 'nothing'"),
    (["--fold-generations", "-1"], "--fold-generations must be >= 0"),
    (["--budget-hours", "0"], "--budget-hours must be > 0"),
    (["--refine-top", "-1"], "--refine-top must be >= 0, got -1"),
    (["--refine-popsize", "1"], "--refine-popsize must be >= 2, got 1"),
    (["--refine-generations", "0"], "--refine-generations must be >= 1, got 0"),
    (["--candidates", "/nonexistent.csv"], "--candidates /nonexistent.csv: cannot read it"),
    (["--gaits", "A1+A6"], "--gaits A1+A6: not measured"),
    (["--validate-cycles", "4:40"], "shorter than cycles up to 40"),
    # covered from early phases only: the fit's phase could lie beyond (it failed after the
    # whole fit)
    (["--validate-cycles", "5:7"], "--validate-cycles 5:7: the A1+A2 trial (22.4891 s) covers "
                                   "these cycles only from a phase up to 0.439 s, not from "
                                   "every phase of its 3.15-s period; its windows end at cycle "
                                   "6 at the latest"),
    (["--reassess"], "has no done/ folder (give the folder of an earlier run)"),
    (["--reassess", "--resume"], "--resume and --reassess: give one"),
])
def test_invalid_arguments_fail_before_compute(no_compute, tmp_path, capsys, argv, message):
    assert studies_main(["model_select", *argv, "--out", str(tmp_path), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert error.count("\n") == 1 and "Traceback" not in error


@pytest.mark.slow
def test_quick_run_against_a_direct_simulation(tmp_path, capsys, monkeypatch):
    # every run long enough for a progress bar of its own: --no-progress must still show none
    # (a long run's evaluations each showed one)
    from taichi_star import driver
    monkeypatch.setattr(driver, "AUTO_PROGRESS_S", 0.0)
    table = model_select.main(["--out", str(tmp_path), *QUICK])
    assert "simulated" not in capsys.readouterr().err
    written = pd.read_csv(tmp_path / "model_select.csv")
    assert list(written["candidate"]) == list(table["candidate"])
    assert set(written["candidate"]) == {"paper", "ramp"}
    # --quick refines the one best screened form: its refined row ranks first
    assert list(written["stage"]) == ["refine", "screen", "screen"]
    assert list(written["rank"]) == [1, 2, 3]
    assert (written["status"] == "ok").all()
    held_out = written["held_out_objective"].to_numpy()
    # ranked by the held-out error: held-out gaits plus later cycles (the CSV keeps 10
    # significant digits: three cells each rounded by up to 5e-10 relative)
    np.testing.assert_allclose(held_out, written["logo_objective"] + written["validate_objective"],
                               rtol=2e-9)
    assert held_out[1] <= held_out[2]
    assert written["candidate"].iloc[0] == written["candidate"].iloc[1]
    parameters = pd.read_csv(tmp_path / "model_select_parameters.csv")
    gaits = ["A1+A2", "A1+A4"]  # --quick
    budgets = {"screen": (model_select.QUICK_POPSIZE * model_select.QUICK_MAX_GENERATIONS, ""),
               "refine": (model_select.QUICK_REFINE_POPSIZE
                          * model_select.QUICK_REFINE_GENERATIONS, "refine/")}
    for _, row in written.iterrows():
        name = row["candidate"]
        evaluations, subfolder = budgets[row["stage"]]
        fits = pd.read_csv(tmp_path / "fits" / f"{subfolder}{name}.csv")
        assert len(fits) == evaluations == row["n_evaluations"]
        # the training objective of the re-simulated best point is the best evaluation's
        assert row["train_objective"] == pytest.approx(fits["objective"].min(), rel=1e-9)
        assert row["n_parameters"] == 2 + len(gaits)
        # the CSV keeps 10 significant digits
        assert row["aic"] == pytest.approx(row["chi2"] + 2 * row["n_parameters"], rel=1e-9)
        # a direct simulation of the identified parameters gives the same objective (CSV
        # values have 10 significant digits: the objective moves far less than 1e-6)
        values = parameters[(parameters["candidate"] == name)
                            & (parameters["stage"] == row["stage"])].set_index("parameter")["value"]
        candidate = next(c for c in model_select.QUICK_CANDIDATES if c["name"] == name)
        model = model_select.Candidate(**candidate).model(StarParams())
        params = [model.replace(gait=g, **values.to_dict()) for g in gaits]
        result = taichi_star.simulate(params, 2 * params[0].period,
                                      SolverConfig(dt=model_select.QUICK_DT),
                                      record_interval_s=nearest_interval(
                                          identify.RECORD_INTERVAL_S, model_select.QUICK_DT))
        runs = identification.simulated_runs(result.trajectory, gaits,
                                             [p.period for p in params])
        trials = identification.measured_trials(gaits)
        train = identification.trajectory_objective(dict(zip(gaits, runs)), trials, (1, 1))
        assert identification.objective_of(train) == pytest.approx(row["train_objective"],
                                                                   rel=1e-6)
        # χ²: 64 curve samples per gait (one cycle) times each gait's objective
        assert row["n_samples"] == len(gaits) * identification.SAMPLES_PER_CYCLE
        assert row["chi2"] == pytest.approx(identification.SAMPLES_PER_CYCLE
                                            * train["objective"].sum(), rel=1e-6)
        assert row["bic"] == pytest.approx(row["chi2"] + row["n_parameters"]
                                           * np.log(row["n_samples"]), rel=1e-9)
        validate = identification.trajectory_objective(
            dict(zip(gaits, runs)), trials, (2, 2), phases=dict(zip(gaits, train["phase_s"])))
        assert identification.objective_of(validate) == pytest.approx(
            row["validate_objective"], rel=1e-6)
        assert row["train_directions_right"] == int(train["direction_matches"].sum())
    folds = pd.read_csv(tmp_path / "model_select_folds.csv")
    assert len(folds) == 3 * len(gaits) and set(folds["held_out_gait"]) == set(gaits)
    assert folds["frozen_axes"].isna().all()  # alpha and C_c: every gait informs them
    for (name, stage), part in folds.groupby(["candidate", "stage"]):
        row = written.set_index(["candidate", "stage"]).loc[(name, stage)]
        assert row["logo_objective"] == pytest.approx(part["objective"].mean(), rel=1e-9)
        assert row["logo_directions_right"] == int(part["direction_matches"].sum())
    for name in ("paper", "ramp", f"{written['candidate'].iloc[0]}_refined"):
        assert (tmp_path / f"fig4c_{name}.png").stat().st_size > 1000
        assert (tmp_path / f"fig4b_{name}.png").stat().st_size > 1000
    assert (tmp_path / "model_select.png").stat().st_size > 1000
    assert np.isfinite(parameters["std"]).all() and (parameters["std"] > 0).all()
    # the preset's fields: the rank-1 candidate's refined model, field by field
    identified = pd.read_csv(tmp_path / "identified.csv", dtype={"value": str})
    best = written.iloc[0]
    assert set(identified["candidate"]) == {best["candidate"]}
    assert set(identified["stage"]) == {"refine"}
    fields = {row["field"]: ast.literal_eval(row["value"]) for _, row in identified.iterrows()}
    best_values = parameters[(parameters["candidate"] == best["candidate"])
                             & (parameters["stage"] == "refine")]
    for _, axis in best_values.iterrows():
        assert fields[axis["parameter"]] == pytest.approx(axis["value"], rel=1e-9)
    if best["candidate"] == "ramp":
        assert fields["profile_closure"] == "ramp"

    # --resume reads the finished candidates back, compute-free, to the same table
    def forbidden(*args, **kwargs):
        raise AssertionError("a finished candidate was simulated again")
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", forbidden)
    capsys.readouterr()
    model_select.main(["--out", str(tmp_path), "--resume", *QUICK])
    printed = capsys.readouterr().out
    assert "paper (screen): read back from" in printed
    assert f"{best['candidate']} (refine): read back from" in printed
    resumed = pd.read_csv(tmp_path / "model_select.csv")
    pd.testing.assert_frame_equal(written.drop(columns="note"), resumed.drop(columns="note"))
    # each row read back names its fit (the run's sidecar names only the reading commit)
    for stage, name, note in zip(resumed["stage"], resumed["candidate"], resumed["note"]):
        folder = "fits/" if stage == "screen" else f"fits/{stage}/"
        assert note.startswith(f"read back: {folder}{name}.csv, fitted at "), note


def test_a_budget_spent_before_the_first_fit_still_runs_that_fit(tmp_path, capsys):
    """--budget-hours 1e-9 skipped every candidate and wrote tables of skipped rows with exit
    status 0 (an audit, 2026-12): the first fit of a run always runs, the next one, starting
    after the spent budget, is skipped with the note."""
    model_select.main(["--out", str(tmp_path), "--budget-hours", "1e-9", "--refine-top", "0",
                       *QUICK])
    written = pd.read_csv(tmp_path / "model_select.csv").set_index("candidate")
    assert written.loc["paper", "status"] == "ok"
    assert written.loc["ramp", "status"] == "skipped"
    assert written.loc["ramp", "note"] == "budget of 1e-09 h spent"


def test_a_candidate_whose_axes_no_fitted_gait_moves_is_skipped_and_none_left_is_refused(
        no_compute, tmp_path, capsys):
    """A candidate fitting only gains of actuators the fitted gaits never fire was fitted on a
    flat objective, ranked first and written as the identified model (a review, 2026-12):
    skipped with a note; a table with nothing left to fit is refused before any compute."""
    table = tmp_path / "candidates.csv"
    table.write_text("name,set,fit,description\n"
                     "idle,,actuator_gains[8]=0.5:1.5 actuator_gains[7]=0.5:1.5,never fired\n")
    out = tmp_path / "out"
    assert studies_main(["model_select", "--candidates", str(table), "--gaits", "A1+A2,A1+A4",
                         "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert ("--candidates: none can be fitted (idle: no fitted gait fires the actuators of "
            "actuator_gains[8], actuator_gains[7])") in error, error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


# the nominal periods' case in the slow tier (suite time: a quick run of the study, 4-7 s):
# the study's other default-tier runs fit at the nominal periods
@pytest.mark.parametrize("periods", [pytest.param("nominal", marks=pytest.mark.slow),
                                     "strokes"])
def test_phases_held_on_the_strokes_in_every_window(tmp_path, periods):
    """--phases strokes: no phase is fitted (k = the fitted axes), and each window's phases
    are where a direct simulation's strokes meet the measured ones, the validation window
    its own; its objectives are the trajectory objective at those phases. --periods strokes:
    each gait's model fires at the period of its strokes' line and its track is cut into
    periods of it."""
    model_select.main(["--out", str(tmp_path), "--only", "paper", "--refine-top", "0",
                       "--phases", "strokes", "--periods", periods, *QUICK])
    row = pd.read_csv(tmp_path / "model_select.csv").iloc[0]
    assert (row["candidate"], row["status"], row["n_parameters"]) == ("paper", "ok", 2)
    # the table re-simulates the best point through the validation window: its training error
    # is the one the fit minimised over the training window alone (the CSVs keep 10 digits)
    fits = pd.read_csv(tmp_path / "fits" / "paper.csv")
    assert row["train_objective"] == pytest.approx(fits["objective"].min(), rel=1e-8)
    values = pd.read_csv(tmp_path / "model_select_parameters.csv").set_index(
        "parameter")["value"]
    gaits = ["A1+A2", "A1+A4"]  # --quick
    nominal = identification.measured_trials(gaits)
    lines = {g: identification.strokes(nominal[g].path) for g in gaits}
    period = {g: (lines[g].period_s + lines[g].drift_s if periods == "strokes"
                  else EXPERIMENT_PERIOD_S) for g in gaits}
    if periods == "strokes":
        # A1+A2's strokes come every 3.178 s, A1+A4's every 3.177 s (results/strokes.csv)
        assert period["A1+A2"] == pytest.approx(3.178, abs=1e-3)
        assert period["A1+A4"] == pytest.approx(3.177, abs=1e-3)
    identified = pd.read_csv(tmp_path / "identified.csv")
    if periods == "strokes":  # the preset's fields were fitted at other periods than its own
        assert (identified["fitted_at_periods"] == "each gait at its strokes' period: "
                "A1+A2 3.178 s, A1+A4 3.177 s").all()
    else:
        assert "fitted_at_periods" not in identified
    sidecar = json.loads((tmp_path / "model_select.csv.json").read_text())
    assert sidecar["details"].get("pulse_periods_s") == (period if periods == "strokes" else None)
    runs = {}
    for gait in gaits:
        params = StarParams(gait=gait, period=period[gait], **values.to_dict())
        # the windows' last cycle (2) and the strokes' tail past it
        result = taichi_star.simulate(
            [params], (2 + model_select.STROKE_TAIL_CYCLES) * params.period,
            SolverConfig(dt=model_select.QUICK_DT),
            record_interval_s=nearest_interval(identify.RECORD_INTERVAL_S,
                                               model_select.QUICK_DT))
        runs[gait] = identification.simulated_runs(result.trajectory, [gait],
                                                   [params.period])[0]
    trials = {g: identification.measured_trial(g, period[g]) for g in gaits}
    stored = pd.read_csv(tmp_path / "model_select_gaits.csv")
    for window, cycles, column in (("train", (1, 1), "train_objective"),
                                   ("validate", (2, 2), "validate_objective")):
        phases = {g: identification.stroke_aligned_phase(runs[g], trials[g], cycles)
                  for g in gaits}
        part = stored[stored["window"] == window].set_index("gait")
        # 10 significant digits in the CSV
        assert part.loc[gaits, "phase_s"].to_numpy() == pytest.approx(
            [phases[g] for g in gaits], rel=1e-9, abs=1e-12)
        direct = identification.trajectory_objective(runs, trials, cycles, phases=phases)
        # the parameters' 10 digits move the objective far less than 1e-6
        assert row[column] == pytest.approx(identification.objective_of(direct), rel=1e-6)


@pytest.mark.parametrize("arguments, message", [
    ([], "--periods strokes needs --phases strokes"),
    (["--phases", "strokes", "--set", "period=3.3"],
     "--set: sets or fits period, which --periods strokes reads off each trial's strokes"),
    (["--phases", "strokes", "--candidates", "{table}"],
     "candidate timed: sets or fits period, which --periods strokes reads off each trial's"),
])
def test_periods_from_the_strokes_refuse_what_they_would_override(tmp_path, capsys,
                                                                   arguments, message):
    """--periods strokes reads the periods off the strokes' lines: with fitted phases, or with
    a period set (--set) or fitted (a candidate), which it would drop, it is refused before
    any compute, in one line."""
    table = tmp_path / "candidates.csv"
    table.write_text("name,set,fit,description\n"
                     "timed,,alpha=0.2:1.5 period=3.1:3.2,a fitted period\n")
    out = tmp_path / "out"
    arguments = [a.format(table=table) for a in arguments]
    assert studies_main(["model_select", "--periods", "strokes", *arguments, "--out",
                         str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.slow
def test_a_reassessed_fit_gets_the_tables_of_a_fresh_run(tmp_path, monkeypatch, capsys):
    """--reassess reads a finished fit back and does everything after it again: a record
    whose tables were scored another way is assessed again to the tables of a fresh run,
    without fitting it."""
    argv = ["--out", str(tmp_path), "--only", "paper", "--refine-top", "0", "--phases",
            "strokes", *QUICK]
    model_select.main(argv)
    fresh = {name: pd.read_csv(tmp_path / name) for name in
             ("model_select.csv", "model_select_gaits.csv", "model_select_folds.csv",
              "model_select_parameters.csv")}
    done = tmp_path / "done" / "paper.json"
    record = model_select.read_done(done)
    record["row"]["train_objective"] = 99.0  # scored another way
    record["gaits"]["objective"] = [2 * value for value in record["gaits"]["objective"]]
    done.write_bytes(model_select.done_record_bytes(record))

    def forbidden(*args, **kwargs):
        raise AssertionError("the stored fit was run again")
    monkeypatch.setattr(model_select, "fit_candidate", forbidden)
    capsys.readouterr()
    model_select.main([*argv, "--reassess"])
    assert "paper: assessed again, the fit read back from fits/paper.csv, fitted at" in \
        capsys.readouterr().out
    again = {name: pd.read_csv(tmp_path / name) for name in fresh}
    note = again["model_select.csv"].pop("note").iloc[0]
    assert note.startswith("assessed again (--reassess), the fit read back from fits/paper.csv")
    # the fit's own columns kept, its definition today's
    assert again["model_select.csv"].pop("definition").iloc[0] == \
        fresh["model_select.csv"].pop("definition").iloc[0]
    fresh["model_select.csv"].pop("note")
    for name in ("model_select.csv", "model_select_gaits.csv", "model_select_parameters.csv"):
        pd.testing.assert_frame_equal(again[name], fresh[name], check_exact=True)
    # the folds start from the best point's unit coordinates recovered from its values (one
    # rounding each): their CMA-ES runs agree to far better than 1e-6
    pd.testing.assert_frame_equal(again["model_select_folds.csv"],
                                  fresh["model_select_folds.csv"], rtol=1e-6)


class StoredFit:
    """A --reassess setting in `folder`: one candidate (the paper model, two axes) on gait A1,
    its record done/paper.json (`record`) and its evaluations fits/paper.csv; `name()` is what
    `stored_fit_of` names the stored fit (None: fitted anew)."""

    def __init__(self, folder):
        self.folder = folder
        self.candidate = model_select.Candidate("paper", "",
                                                "alpha=0.2:1.5 cylinder_drag=1:100:log")
        self.args = types.SimpleNamespace(fold_generations=2, train_cycles="1:3",
                                          validate_cycles="4:6", phases="strokes",
                                          periods="nominal", folds="warm")
        self.settings, self.solver = identify.CMASettings(), SolverConfig()
        self.base = StarParams.preset("paper")
        self.done = folder / "done" / "paper.json"
        self.done.parent.mkdir()

    def definition(self, **kwargs) -> str:
        return model_select.definition_of(self.candidate, self.args, self.settings, self.base,
                                          self.solver, ["A1"], **kwargs)

    def record(self, definition: str, status: str = "ok"):
        self.done.write_bytes(model_select.done_record_bytes(
            {"row": {"status": status, "definition": definition, "n_parameters": 2,
                     "n_samples": 10},
             "parameters": {}, "gaits": {}, "folds": {}}))

    def name(self):
        found = model_select.stored_fit_of(self.done, self.folder, "fits/paper.csv",
                                           self.candidate, self.args, self.settings, self.base,
                                           self.solver, ["A1"])
        return None if found is None else found[1]


def test_a_stored_fit_is_reassessed_only_if_fitted_as_today(tmp_path, monkeypatch):
    """A stored fit is reused by --reassess if its definition is today's; one whose strokes
    were read at their farthest moves (before 2026-12-05), a failed fit, another definition or
    no record: fitted anew (None)."""
    setting = StoredFit(tmp_path)
    args, definition = setting.args, setting.definition

    def stored(definition, status="ok"):
        setting.record(definition, status)
        return setting.name()
    assert setting.name() is None  # no record
    assert stored(definition()) == "fits/paper.csv"  # no sidecar: no commit to name
    (tmp_path / "fits").mkdir()
    (tmp_path / "fits" / "paper.csv.json").write_text(json.dumps({"git_commit": "0123456789"}))
    assert stored(definition()) == "fits/paper.csv, fitted at 0123456"
    with monkeypatch.context() as farthest:
        farthest.setattr(model_select, "STROKE_ALIGNMENT", "window")
        read_at_farthest = definition()
    assert stored(read_at_farthest) is None
    assert stored(definition(), status="fit_failed") is None
    args.train_cycles, args.validate_cycles = "2:3", "4:6"
    assert stored(definition()) is not None
    args.train_cycles = "1:3"
    earlier = definition()
    args.fold_generations = 3  # today's run would assess with other folds
    assert stored(earlier) is None
    # but --folds is the assessment's alone: a fit assessed with warm folds is reassessed with
    # cold ones, and one assessed with cold folds with warm ones, without fitting it again
    args.fold_generations = 2
    args.folds = "cold"
    assert definition() != earlier
    assert stored(earlier) is not None
    assert stored(definition()) is not None
    cold = definition()
    args.folds = "warm"
    assert stored(cold) is not None


def test_a_reassessed_fit_is_named_without_a_commit_its_sidecar_no_longer_vouches_for(
        tmp_path, capsys):
    """The commit that names a stored fit comes from its evaluations' sidecar through
    `read_provenance`: once the evaluations are edited since, or the sidecar damaged, the fit
    is named without it, and that is said (a damaged sidecar was a traceback mid-run)."""
    setting = StoredFit(tmp_path)
    setting.record(setting.definition())
    csv = tmp_path / "fits" / "paper.csv"
    csv.parent.mkdir()
    data = b"generation,objective\n0,1.5\n"
    csv.write_bytes(data)
    sidecar = tmp_path / "fits" / "paper.csv.json"
    sidecar.write_text(json.dumps({"git_commit": "0123456789", **table_stamp(1, data)}))
    assert setting.name() == "fits/paper.csv, fitted at 0123456"
    assert capsys.readouterr().out == ""
    csv.write_bytes(data + b"1,1.25\n")  # edited since
    assert setting.name() == "fits/paper.csv"
    assert capsys.readouterr().out == (
        f"{csv}: not the table its provenance paper.csv.json describes (its SHA-256 differs: "
        f"damaged or edited since it was written); the fit is named without its commit\n")
    csv.write_bytes(data)
    sidecar.write_text(sidecar.read_text()[:10])  # cut: no longer JSON
    assert setting.name() == "fits/paper.csv"
    assert capsys.readouterr().out.startswith(f"{sidecar}: no taichi_star provenance in it "
                                              f"(JSONDecodeError: ")


def test_start_reads_an_identified_table_and_moves_only_the_search_start(tmp_path, monkeypatch):
    """--start: the search begins at the identified.csv's values (the committed rank-1 fit
    here), while the base model, the prior a held-out fold keeps, stays --preset's; the
    definition names the start, so a resumed run does not reuse a fit started elsewhere."""
    from pathlib import Path
    committed = Path(__file__).resolve().parents[2] / "results" / "model_select" / "identified.csv"
    base = StarParams.preset("paper")
    start = identify.read_start(committed, base)
    table = pd.read_csv(committed, dtype={"value": str})
    for name, text in zip(table["field"], table["value"]):
        assert getattr(start, name) == ast.literal_eval(text)
    candidate = model_select.Candidate("gains", "", "alpha=0.2:1.5 actuator_gains[4]=0.3:2")
    box = candidate.box(base)
    seen = {}

    class Stop(Exception):
        pass

    def stub(box_, start_units, *args, **kwargs):
        seen["start"] = start_units
        raise Stop
    monkeypatch.setattr(identify, "minimise_cmaes", stub)
    setup = types.SimpleNamespace(gaits=("A1+A4",))
    for start_model, expected in ((None, base), (start, start)):
        with pytest.raises(Stop):
            model_select.fit_candidate(candidate, base, identify.CMASettings(),
                                       model_select.FoldPlan(0), setup, start_model=start_model)
        np.testing.assert_array_equal(seen["start"], [box[0].unit(expected.alpha),
                                                      box[1].unit(expected.actuator_gains[3])])
    # the fitted start is not the prior: A4's unit coordinate moved from 1 to ~1.99
    assert box[1].unit(start.actuator_gains[3]) > box[1].unit(base.actuator_gains[3])
    args = types.SimpleNamespace(fold_generations=2, train_cycles="1:3", validate_cycles="4:6",
                                 phases="fitted", periods="nominal", folds="warm")

    def definition(start_model):
        return model_select.definition_of(candidate, args, identify.CMASettings(), base,
                                          SolverConfig(), ["A1"], start_model=start_model)
    assert definition(None) != definition(start)
    assert definition(start) == definition(identify.read_start(committed, base))


@pytest.mark.parametrize("text, message", [
    (None, "cannot read it"),
    ("field,value\n", "no rows"),
    ("name,value\nalpha,1.0\n", "not an identified.csv (rows of field, value; no column(s) "
                                "field)"),
    ("field,value\nspeed,1.0\n", "'speed' is not a model field"),
    ("field,value\nalpha,one\n", "alpha = 'one' is not a value"),
    ("field,value\nalpha,-1.0\n", "alpha must be a real number in [0, 10], got -1.0"),
])
def test_a_bad_start_table_fails_before_compute(no_compute, tmp_path, capsys, text, message):
    path = tmp_path / "identified.csv"
    if text is not None:
        path.write_text(text)
    out = tmp_path / "out"
    assert studies_main(["model_select", "--start", str(path), "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert f"--start {path}: " in error and message in error, error
    assert error.count("\n") == 1 and "Traceback" not in error


def test_a_fit_record_that_cannot_be_read_is_fitted_again_not_a_traceback(tmp_path, capsys):
    """done/ records were written in place: a kill mid-write left one that --resume and
    --reassess read with json.loads and failed on (an audit, 2026-12). They are written whole
    now; one damaged otherwise is said and its candidate fitted again."""
    done = tmp_path / "paper.json"
    assert model_select.read_done(done) is None   # none yet
    for text in ('{"row": {"status": "ok"', "[1, 2]", ""):
        done.write_text(text)
        assert model_select.read_done(done) is None
        assert capsys.readouterr().out.startswith(f"{done}: unreadable (")
    record = {"row": {"status": "ok", "n_parameters": 3, "n_samples": 240},
              "parameters": {"parameter": ["alpha"], "value": [1.2345678901234567]},
              "gaits": {"gait": ["A1", "A1+A3"], "objective": [0.5, 1.5]}, "folds": {}}
    done.write_text(json.dumps(record))   # a record from before the checksums
    assert model_select.read_done(done) == record
    done.write_bytes(model_select.done_record_bytes(record))
    assert model_select.read_done(done) == record
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("damage, reason", [
    # a value changed by hand or by the disk: read back as the fit's result without a word
    (lambda text: text.replace("1.2345678901234567", "1.2845678901234567"),
     "its record does not match its checksum"),
    # a table's name damaged: a KeyError after the fits before it (an audit, 2026-12)
    (lambda text: text.replace("gaits", "gaitr"),
     "its record does not match its checksum"),
])
def test_a_damaged_fit_record_is_fitted_again(tmp_path, capsys, damage, reason):
    done = tmp_path / "paper.json"
    record = {"row": {"status": "ok", "n_parameters": 3, "n_samples": 240},
              "parameters": {"parameter": ["alpha"], "value": [1.2345678901234567]},
              "gaits": {"gait": ["A1"], "objective": [0.5]}, "folds": {}}
    done.write_text(damage(model_select.done_record_bytes(record).decode()))
    assert model_select.read_done(done) is None
    assert capsys.readouterr().out == (f"{done}: unreadable ({reason}); its candidate is "
                                       f"fitted again\n")


@pytest.mark.parametrize("record, reason", [
    ({"row": {"status": "ok", "n_parameters": 3, "n_samples": 240}, "parameters": {},
      "gaitr": {}, "folds": {}}, "its gaits table is missing or not columns of equal length"),
    ({"row": {"status": "ok", "n_parameters": 3, "n_samples": 240}, "parameters": {},
      "gaits": {"gait": ["A1"], "objective": []}, "folds": {}},
     "its gaits table is missing or not columns of equal length"),
    ({"row": {"status": "ok", "n_parameters": 3}, "parameters": {}, "gaits": {}, "folds": {}},
     "its row lacks the counts of parameters and samples"),
    ({"row": {"n_parameters": 3}, "parameters": {}, "gaits": {}, "folds": {}},
     "not a fit's record"),
])
def test_a_fit_record_of_the_wrong_shape_is_fitted_again(tmp_path, capsys, record, reason):
    """A record (with or without its checksum) lacking what --resume reads is fitted again
    instead of failing with a KeyError."""
    done = tmp_path / "paper.json"
    for data in (json.dumps(record).encode(), model_select.done_record_bytes(record)):
        done.write_bytes(data)
        assert model_select.read_done(done) is None
        assert capsys.readouterr().out == (f"{done}: unreadable ({reason}); its candidate is "
                                           f"fitted again\n")


def test_a_candidate_with_one_axis_is_refused_before_compute(no_compute, tmp_path, capsys):
    """CMA-ES needs two axes: a one-axis candidate failed after its first generation with a
    traceback (an audit, 2026-12); now one line, exit 2, naming it."""
    table = tmp_path / "one.csv"
    table.write_text("name,set,fit,description\none,,alpha=0.2:1.5,x\n")
    assert studies_main(["model_select", "--candidates", str(table), "--out",
                         str(tmp_path / "out"), *QUICK]) == 2
    error = capsys.readouterr().err
    assert "candidate one: fit 'alpha=0.2:1.5': CMA-ES needs two axes at least, got 1" in error
    assert error.count("\n") == 1 and "Traceback" not in error
    two = model_select.Candidate("two", "", "alpha=0.2:1.5 cylinder_drag=1:100:log")
    assert len(two.box(StarParams())) == 2  # two axes: the least accepted


def test_without_folds_the_rank_follows_the_later_cycles():
    """No held-out gaits (--fold-generations 0, one gait: logo_objective NaN): the held-out
    error is the later cycles' alone, so a form far worse there but better in BIC ranks below
    (the sum was NaN and the rank fell to BIC: an audit, 2026-12); a failed fold (inf) ranks
    after every finite one."""
    rows = [{"candidate": "bic_best", "status": "ok", "logo_objective": math.nan,
             "validate_objective": 500.0, "bic": 100.0, "train_objective": 1.0},
            {"candidate": "later_best", "status": "ok", "logo_objective": math.nan,
             "validate_objective": 5.0, "bic": 200.0, "train_objective": 2.0}]
    table = model_select.ranked(rows)
    assert list(table["candidate"]) == ["later_best", "bic_best"]
    assert list(table["held_out_objective"]) == [5.0, 500.0]
    rows.append({"candidate": "fold_failed", "status": "ok", "logo_objective": math.inf,
                 "validate_objective": 1.0, "bic": 1.0, "train_objective": 0.5})
    assert list(model_select.ranked(rows)["candidate"]) == ["later_best", "bic_best",
                                                            "fold_failed"]


def test_a_failed_held_out_prediction_counts_and_is_named(monkeypatch):
    """A fold whose prediction failed makes logo_objective inf and is named in the note (the
    mean of the other folds stood for it: an audit, 2026-12); the counts take the ok folds."""
    candidate = model_select.Candidate("c", "", "alpha=0.2:1.5 cylinder_drag=1:100:log")
    setup = types.SimpleNamespace(gaits=("A1", "A1+A2", "A1+A4"), train=(1, 1),
                                  validate=(2, 2), strokes=None)
    per_gait = pd.DataFrame({"gait": list(setup.gaits), "objective": [1.0, 2.0, 3.0],
                             "phase_s": 0.0, "direction_matches": True})
    folds = pd.DataFrame([
        {"held_out_gait": "A1", "status": "ok", "objective": 4.0, "speed_ratio": 1.1,
         "direction_matches": True},
        {"held_out_gait": "A1+A2", "status": "failed", "objective": math.inf},
        {"held_out_gait": "A1+A4", "status": "ok", "objective": 6.0, "speed_ratio": 2.0,
         "direction_matches": True}])
    monkeypatch.setattr(model_select, "simulate_points", lambda params, last, setup: [None] * 3)
    monkeypatch.setattr(model_select, "score", lambda *args, **kwargs: per_gait)
    monkeypatch.setattr(model_select, "leave_one_gait_out", lambda *args: folds)
    row = model_select.assess_point(candidate, StarParams(), np.array([0.5, 0.5]),
                                    np.array([0.8, 10.0]), identify.CMASettings(),
                                    model_select.FoldPlan(2), setup, np.array([0.4, 0.4]))["row"]
    assert row["logo_objective"] == math.inf
    assert row["note"] == "held-out prediction failed: A1+A2"
    assert (row["logo_directions_right"], row["logo_within_35pct"], row["n_folds"]) == (2, 1, 3)
    every_fold_ok = folds.drop(index=1)
    monkeypatch.setattr(model_select, "leave_one_gait_out", lambda *args: every_fold_ok)
    row = model_select.assess_point(candidate, StarParams(), np.array([0.5, 0.5]),
                                    np.array([0.8, 10.0]), identify.CMASettings(),
                                    model_select.FoldPlan(2), setup, np.array([0.4, 0.4]))["row"]
    assert (row["logo_objective"], row["note"]) == (5.0, "")


def test_a_fold_plan_gives_each_fold_its_start_and_budget():
    """Warm folds: the full fit's best point, half its step, --fold-generations generations, no
    restart, its population and seed; cold folds: the search's start at the stage's own
    settings. 0 generations (no folds) is allowed, -1 and an unknown mode are not."""
    stage = identify.CMASettings(popsize=6, max_generations=8, restarts=1, seed=3, sigma0=0.25)
    best, start = np.array([0.7, 0.2]), np.array([0.5, 0.5])
    warm = model_select.FoldPlan(2, "warm")
    assert warm.settings(stage) == identify.CMASettings(popsize=6, max_generations=2, restarts=0,
                                                        seed=3, sigma0=0.125)
    assert warm.start(best, start) is best
    cold = model_select.FoldPlan(2, "cold")
    assert cold.settings(stage) == stage
    assert cold.start(best, start) is start
    assert model_select.FoldPlan(0).generations == 0
    with pytest.raises(ValueError, match="fold generations must be >= 0, got -1"):
        model_select.FoldPlan(-1)
    with pytest.raises(ValueError, match="folds must be one of warm, cold, got 'hot'"):
        model_select.FoldPlan(2, "hot")


@pytest.mark.parametrize("mode", model_select.FOLD_MODES)
def test_each_fold_searches_from_its_start_along_its_informed_axes(monkeypatch, mode):
    """leave_one_gait_out hands each fold's search the start it is given, cut to the axes its
    gaits inform, with the plan's settings (warm: 1 generation, no restart, half the step;
    cold: the stage's): the fold without A1+A4 leaves A4's gain out; a fold whose every point
    failed is recorded so, not predicted."""
    base = StarParams.preset("paper")
    candidate = model_select.Candidate("g", "", "alpha=0.2:1.5 actuator_gains[4]=0.3:2")
    box = candidate.box(base)
    stage = identify.CMASettings(popsize=4, max_generations=3, restarts=1, seed=2)
    plan = model_select.FoldPlan(1, mode)
    searches = []

    def search(fold_box, start, objective, settings):
        searches.append(([spec.label for spec in fold_box], start, settings))
        return types.SimpleNamespace(evaluations=pd.DataFrame({"objective": [math.inf]}))
    monkeypatch.setattr(identify, "minimise_cmaes", search)
    monkeypatch.setattr(model_select, "simulate_points", lambda params, last, setup: [None] * 2)
    setup = model_select.Setup(gaits=("A1", "A1+A4"), trials={}, train=(1, 1), validate=(2, 2),
                               run_kwargs={}, record_interval_s=0.1)
    units = np.array([0.3, 0.9])
    folds = model_select.leave_one_gait_out(box, units, candidate.model(base), stage, plan,
                                            setup)
    assert list(folds["held_out_gait"]) == ["A1", "A1+A4"]
    assert list(folds["status"]) == ["fit_failed", "fit_failed"]
    assert list(folds["frozen_axes"]) == ["", box[1].label]
    assert [labels for labels, _, _ in searches] == [[box[0].label, box[1].label],
                                                     [box[0].label]]
    np.testing.assert_array_equal(searches[0][1], units)
    np.testing.assert_array_equal(searches[1][1], units[:1])
    expected = (stage if mode == "cold" else
                identify.CMASettings(popsize=4, max_generations=1, restarts=0, seed=2,
                                     sigma0=0.125))
    assert all(settings == expected for _, _, settings in searches)


@pytest.mark.parametrize("mode", model_select.FOLD_MODES)
def test_the_folds_start_at_the_best_point_warm_and_at_the_search_s_start_cold(monkeypatch,
                                                                               mode):
    """assess_point gives the folds the best point (warm) or the search's start (cold), and
    --reassess's search start is --start's model where given, else the base model's."""
    candidate = model_select.Candidate("c", "", "alpha=0.2:1.5 cylinder_drag=1:100:log")
    setup = types.SimpleNamespace(gaits=("A1", "A1+A2"), train=(1, 1), validate=(2, 2),
                                  strokes=None)
    per_gait = pd.DataFrame({"gait": list(setup.gaits), "objective": [1.0, 2.0],
                             "phase_s": 0.0, "direction_matches": True})
    handed = []
    monkeypatch.setattr(model_select, "simulate_points", lambda params, last, setup: [None] * 2)
    monkeypatch.setattr(model_select, "score", lambda *args, **kwargs: per_gait)
    monkeypatch.setattr(model_select, "leave_one_gait_out",
                        lambda box, units, *args: handed.append(units) or pd.DataFrame())
    best, start = np.array([0.7, 0.2]), np.array([0.5, 0.5])
    plan = model_select.FoldPlan(2, mode)
    model_select.assess_point(candidate, StarParams(), best, np.array([0.8, 10.0]),
                              identify.CMASettings(), plan, setup, start)
    assert handed.pop() is (start if mode == "cold" else best)
    base = StarParams.preset("paper")
    box = candidate.box(base)
    elsewhere = base.replace(alpha=1.2, cylinder_drag=30.0)
    stored = {"parameters": model_select.parameter_table("c", box, [0.9, 20.0], [0.1, 0.1]),
              "row": {key: 0 for key in ("candidate", "fit", "set", "description", "n_fitted",
                                         "n_parameters", "n_gaits", "n_evaluations",
                                         "fit_time_s")}}
    for start_model, point in ((None, base), (elsewhere, elsewhere)):
        model_select.reassess_candidate(candidate, base, identify.CMASettings(), plan, setup,
                                        stored, "fits/c.csv", start_model=start_model)
        reached = handed.pop()
        if mode == "cold":
            np.testing.assert_array_equal(reached, [box[0].unit(point.alpha),
                                                    box[1].unit(point.cylinder_drag)])
        else:  # the stored best point, recovered from its values
            np.testing.assert_allclose(reached, [box[0].unit(0.9), box[1].unit(20.0)])


def test_the_definitions_of_committed_fits_are_today_s():
    """A committed fit's definition recomputed from its run's flags (warm folds, the default)
    equals the one it was stored with: a change to what a definition hashes would make every
    stored fit one that --resume and --reassess fit again."""
    from pathlib import Path
    folder = (Path(__file__).resolve().parents[2] / "results" / "model_select_onsets" / "seeds"
              / "paper_seed4")
    command = json.loads((folder / "model_select.csv.json").read_text())["command"].split()
    args = cli.parse(model_select.build_parser(), command[command.index("model_select") + 1:])
    settings = identify.CMASettings(popsize=args.popsize, max_generations=args.max_generations,
                                    restarts=args.restarts, seed=args.seed, sigma0=args.sigma0)
    candidate = model_select.select_candidates(args)[0]
    stored = json.loads((folder / "done" / f"{candidate.name}.json").read_text())
    assert model_select.definition_of(
        candidate, args, settings, cli.base_params(args), cli.solver(args),
        identify.measured_gaits(args.gaits)) == stored["row"]["definition"]


def test_cold_folds_are_counted_as_whole_fits():
    """The work a run plans (the instance cap) and its estimate count a cold fold as a fit of
    the stage's budget on the other gaits, a warm one as its generations at the first
    population; no folds with 0 generations or one gait."""
    candidate = model_select.Candidate("c", "", "alpha=0.2:1.5 cylinder_drag=1:100:log")
    stage = identify.CMASettings(popsize=4, max_generations=3, restarts=1)
    work = [(candidate, stage)]
    fit = (3 * 4 + 3 * 8) * 3  # every generation of both runs, on three gaits
    warm = 3 * (2 * 4 * 2 + 1)  # per held-out gait: 2 generations of 4 on two gaits, + 1
    cold = 3 * ((3 * 4 + 3 * 8) * 2 + 1)
    for mode, folds in (("warm", warm), ("cold", cold)):
        plan = model_select.FoldPlan(2, mode)
        assert model_select.planned_instances(work, plan, 3) == fit + folds
        # the estimate: the same instances over 3 training cycles, then the assessment's 3
        # gaits over 6 cycles and 5 Fig. 4c gaits over 3, at 1 s per instance-cycle
        assert model_select.estimate_seconds(1.0, work, plan, 3, 3, 6) == \
            3 * (fit + folds) + 3 * 6 + 5 * 3
    for plan, gaits in ((model_select.FoldPlan(0, "cold"), 3), (model_select.FoldPlan(2), 1)):
        assert model_select.planned_instances(work, plan, gaits) == fit // 3 * gaits


# slow tier: four quick runs of the study, 11 s cold (the default tier's budget; the folds'
# starts and counts are held in the default tier by the two tests above)
@pytest.mark.slow
def test_a_cold_fold_is_the_fit_on_the_other_gaits_from_the_start(tmp_path):
    """--folds cold: the fold that holds A1+A2 out is the fit a run on A1+A4 alone makes (the
    same start, settings and seed), so it moves from the start exactly as far as that fit's
    best point lies from it; the run records its folds; --reassess --folds warm of it fits
    nothing again and gives the warm folds of a fresh warm run."""
    common = ["--only", "paper", "--refine-top", "0", *QUICK]
    cold_dir, alone_dir, warm_dir = tmp_path / "cold", tmp_path / "alone", tmp_path / "warm"
    model_select.main(["--out", str(cold_dir), "--folds", "cold", *common])
    model_select.main(["--out", str(alone_dir), "--gaits", "A1+A4", *common])
    folds = pd.read_csv(cold_dir / "model_select_folds.csv").set_index("held_out_gait")
    assert set(folds.index) == {"A1+A2", "A1+A4"} and (folds["status"] == "ok").all()
    alone = pd.read_csv(alone_dir / "model_select_parameters.csv")
    base = StarParams.preset("paper")
    candidate = model_select.select_candidates(
        cli.parse(model_select.build_parser(), ["--quick", "--only", "paper"]))[0]
    box = candidate.box(base)
    values = model_select.stored_values(box, alone)
    start = model_select.search_start(candidate, base)
    move = max(abs(spec.unit(value) - u) for spec, value, u in zip(box, values, start))
    # the CSVs keep 10 significant digits (5e-10 relative each); a fold started elsewhere or
    # with other settings moves by another amount altogether
    assert folds.loc["A1+A2", "fold_move_units"] == pytest.approx(move, rel=2e-9)
    sidecar = json.loads((cold_dir / "model_select.csv.json").read_text())
    assert sidecar["details"]["folds"] == "cold"
    model_select.main(["--out", str(warm_dir), *common])
    cold_row = pd.read_csv(cold_dir / "model_select.csv").iloc[0]
    warm_row = pd.read_csv(warm_dir / "model_select.csv").iloc[0]
    assert cold_row["definition"] != warm_row["definition"]
    assert cold_row["train_objective"] == warm_row["train_objective"]  # the same fit
    model_select.main(["--out", str(cold_dir), "--reassess", *common])
    assert pd.read_csv(cold_dir / "model_select.csv")["note"].iloc[0].startswith(
        "assessed again (--reassess), the fit read back from fits/paper.csv")
    pd.testing.assert_frame_equal(pd.read_csv(cold_dir / "model_select_folds.csv"),
                                  pd.read_csv(warm_dir / "model_select_folds.csv"), rtol=1e-6)


def test_the_ranking_reads_candidates_named_as_pandas_missing_values_by_their_names(tmp_path):
    """A candidate's name is the user's text: "NA", "null" and "nan" were read as NaN by the
    ranking plot (two bars labelled "nan"); an empty objective stays NaN."""
    path = tmp_path / "model_select.csv"
    pd.DataFrame({"candidate": ["NA", "null", "nan", "paper"],
                  "stage": ["screen", "screen", "refined", "screen"],
                  "status": ["ok", "ok", "ok", "failed"],
                  "train_objective": [1.0, 2.0, 3.0, np.nan]}).to_csv(path, index=False)
    table = model_select.fitted_candidates(path)
    assert table["candidate"].tolist() == ["NA", "null", "nan"]
    assert table["train_objective"].tolist() == [1.0, 2.0, 3.0]
    assert np.isnan(pd.read_csv(path, **cli.NAMES_AS_WRITTEN)["train_objective"].iloc[3])
