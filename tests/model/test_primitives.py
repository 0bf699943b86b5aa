"""Motion primitives (symmetry expansion against direct simulation, statistics), the planner's
model and choices, open- and closed-loop driving, the primitives and plan studies in --quick
mode, and the step_batch example."""

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from studies.__main__ import main as studies_main
from taichi_star.planner import PrimitiveModel, default_goals, drive
from taichi_star.primitives import cycle_displacements, transform_vectors

ROOT = Path(__file__).resolve().parent.parent
SOLVER = ts.SolverConfig(dt=5e-3)  # the studies' --quick step: 630 steps per 3.15-s cycle


@pytest.fixture(scope="module")
def primitives_run(tmp_path_factory):
    """`python -m studies primitives --quick`: 2 cycles of the 29 classes at dt = 5 ms."""
    out = tmp_path_factory.mktemp("primitives")
    assert studies_main(["primitives", "--quick", "--no-progress", "--out", str(out)]) == 0
    return out


def test_primitives_study_writes_255_gaits_and_a_plot(primitives_run):
    table = pd.read_csv(primitives_run / "primitives.csv")
    assert len(table) == 255 and table["gait"].is_unique and (table["status"] == "ok").all()
    assert (primitives_run / "primitives.png").stat().st_size > 0
    assert (primitives_run / "primitives.csv.json").exists()
    # the statistics are those of the per-cycle table's cycles from first_cycle on
    cycles = pd.read_csv(primitives_run / "primitives_cycles.csv")
    row = table[table["gait"] == "A2+A3+A4+A6+A7"].iloc[0]
    steady = cycles[(cycles["gait"] == row["gait"]) & (cycles["cycle"] >= row["first_cycle"])]
    assert row["step_x_mm"] == pytest.approx(steady["dx_body_mm"].mean(), rel=1e-12)
    assert row["turn_deg"] == pytest.approx(steady["rotation_deg"].mean(), rel=1e-12)
    assert row["step_mm"] == pytest.approx(math.hypot(row["step_x_mm"], row["step_y_mm"]))
    # symmetry: every member of a class steps as far and turns as much (up to reflection)
    for _, members in table.groupby("class_representative"):
        np.testing.assert_allclose(members["step_mm"], members["step_mm"].iloc[0], rtol=1e-12)
        np.testing.assert_allclose(np.abs(members["turn_deg"]),
                                   abs(members["turn_deg"].iloc[0]), rtol=1e-12, atol=1e-15)


def test_transform_vectors_follows_the_gait_symmetry():
    """A1's bisector (1, 0) goes where Gait.transform sends A1."""
    for rotation in range(8):
        for reflect in (False, True):
            image = ts.Gait.parse("A1+A2").transform(rotation, reflect).forward
            vector = transform_vectors(ts.Gait.parse("A1+A2").forward, rotation, reflect)
            np.testing.assert_allclose(vector, image, atol=1e-15)


def test_expansion_equals_direct_simulation_of_image_gaits(primitives_run):
    """Gaits that are not class representatives, simulated directly, step and turn as the
    symmetry maps their representative's cycles: two mirror images that turn (the rotation's
    sign flips) and one rotated image. Tolerance 1e-7 mm and deg: each step's Newton solve
    is converged to |Δq| < 1e-10 m = 1e-7 mm, so mirror-image runs may differ by that much
    (measured: ~3e-11)."""
    cycles = pd.read_csv(primitives_run / "primitives_cycles.csv")
    turning = cycles[(cycles["cycle"] == 1) & (cycles["rotation_deg"].abs() > 0.1)]
    mirrored = list(turning[turning["reflected"]]["gait"].iloc[[0, -1]])
    rotated = turning[~turning["reflected"] & (turning["symmetry_rotation"] > 0)]["gait"].iloc[0]
    gaits = [*mirrored, rotated]
    result = ts.simulate([ts.StarParams(gait=g) for g in gaits], 2 * 3.15, SOLVER,
                         record_interval_s=3.15)
    direct = cycle_displacements(result.trajectory, 3.15)
    for index, gait in enumerate(gaits):
        expected = cycles[cycles["gait"] == gait][["dx_body_mm", "dy_body_mm", "rotation_deg"]]
        got = direct[direct["instance"] == index][["dx_body_mm", "dy_body_mm", "rotation_deg"]]
        np.testing.assert_allclose(got.to_numpy(), expected.to_numpy(), rtol=0, atol=1e-7,
                                   err_msg=gait)


def square_model(turn_deg=0.0):
    """Four gaits stepping 10 mm along ±x and ±y, one of them turning."""
    return PrimitiveModel(["A1", "A3", "A5", "A7"], [(10, 0), (0, 10), (-10, 0), (0, -10)],
                          [turn_deg, 0.0, 0.0, 0.0])


def test_model_predicts_in_the_body_frame():
    model = square_model(turn_deg=90.0)
    a1 = model.gaits.index("A1")
    position, heading = model.predict(np.zeros((2, 2)), np.array([0.0, math.pi / 2]),
                                      np.array([a1, a1]))
    np.testing.assert_allclose(position, [(10, 0), (0, 10)], atol=1e-12)
    np.testing.assert_allclose(heading, [math.pi / 2, math.pi])
    assert model.gaits[0] == "none" and not model.masks[0].any()


def test_plan_reaches_a_lattice_goal_in_the_fewest_cycles():
    model = square_model()
    plan = model.plan(np.array([[30.0, 20.0], [0.5, 0.0]]), tolerance_mm=1.0, max_cycles=8)
    steps = model.steps_mm[plan].sum(axis=1)
    np.testing.assert_allclose(steps, [(30, 20), (0, 0)])
    assert (plan[0, :5] != 0).all() and (plan[0, 5:] == 0).all() and (plan[1] == 0).all()


def test_drive_open_and_closed_loop(primitives_run):
    """Two goals 25 mm away, 3 cycles: the controllers start alike (same first gait, the
    open loop's prediction = the closed loop's after one cycle); the closed loop reaches both
    goals (the best gaits step ~28 mm) and stops firing once there."""
    model = PrimitiveModel.from_table(pd.read_csv(primitives_run / "primitives.csv"))
    goals = default_goals(25.0, count=2, far_mm=None)
    summary, cycles, path = drive(model, goals, solver=SOLVER, max_cycles=3,
                                  frames_per_cycle=3)
    assert list(summary["mode"]) == ["open", "closed"] * 2
    first = cycles[cycles["cycle"] == 0]
    assert first.groupby("goal")["gait"].nunique().eq(1).all()
    closed = summary[summary["mode"] == "closed"]
    assert closed["reached"].all() and (closed["final_error_mm"] <= 5.0).all()
    stopped = cycles[(cycles["mode"] == "closed") & (cycles["distance_mm"] <= 5.0)]
    assert (stopped["gait"] == "none").all()
    # the path starts at the origin and passes through each recorded cycle boundary
    row = cycles[(cycles["mode"] == "closed") & (cycles["goal"] == 0) & (cycles["cycle"] == 1)]
    on_path = path[(path["mode"] == "closed") & (path["goal"] == 0)
                   & np.isclose(path["t_s"], 3.15)]
    np.testing.assert_allclose(on_path[["x_mm", "y_mm"]].to_numpy(),
                               row[["x_mm", "y_mm"]].to_numpy())
    assert path.groupby(["goal", "mode"])["controlled"].first().all()
    with pytest.raises(ValueError, match="goals_mm"):
        drive(model, [[np.nan, 0.0]], solver=SOLVER)


def test_plan_study_quick_with_given_primitives(primitives_run, tmp_path):
    primitives = str(primitives_run / "primitives.csv")
    code = studies_main(["plan", "--quick", "--no-progress", "--primitives", primitives,
                         "--directions", "2", "--far", "0", "--out", str(tmp_path)])
    assert code == 0
    summary = pd.read_csv(tmp_path / "plan.csv")
    assert len(summary) == 4 and (tmp_path / "plan.png").stat().st_size > 0
    gain = pd.read_csv(tmp_path / "plan_gain.csv")
    assert {"open_mean_error_mm", "closed_mean_error_mm"} <= set(gain.columns)


@pytest.mark.parametrize("argv, words", [
    (["plan", "--quick", "--tolerance", "-1"], "--tolerance"),
    (["plan", "--quick", "--primitives", "missing.csv"], "--primitives"),
    (["plan", "--quick", "--out", "results"], "results"),
    (["primitives", "--quick", "--first-cycle", "5"], "--first-cycle"),
])
def test_study_errors_are_one_line_and_exit_2(argv, words, capsys):
    assert studies_main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert words in error and "\n" not in error


def test_step_batch_example_runs():
    environment = dict(os.environ, STEP_BATCH_QUICK="1", PYTHONPATH=str(ROOT))
    result = subprocess.run([sys.executable, str(ROOT / "examples" / "step_batch.py")],
                            capture_output=True, text=True, env=environment, cwd=ROOT,
                            timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "robots" in result.stdout
