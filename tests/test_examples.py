"""The example scripts run as a user would run them (quick mode, in a fresh folder), and what
they print or write agrees with the library called directly."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts

REPO = Path(__file__).resolve().parents[1]


def run_example(name, cwd):
    environment = dict(os.environ, EXAMPLE_QUICK="1", PYTHONPATH=str(REPO))
    result = subprocess.run([sys.executable, str(REPO / "examples" / name)], capture_output=True,
                            text=True, env=environment, cwd=cwd, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def test_sweep_alpha_writes_the_library_table_and_a_plot(tmp_path):
    """Its CSV holds the same speeds as simulate on the same batch (bitwise: same engine, same
    instructions; the CSV round-trips float64)."""
    run_example("sweep_alpha.py", tmp_path)
    table = pd.read_csv(tmp_path / "sweep_alpha.csv")
    alphas = np.linspace(0.0, 2.0, 3)
    params = [ts.StarParams(gait=g, alpha=a) for g in ("A1+A2", "A1+A3") for a in alphas]
    direct = ts.simulate(params, 0.3).summary
    np.testing.assert_array_equal(table.signed_speed_mm_s, direct.signed_speed_mm_s)
    assert table.alpha.tolist() == [p.alpha for p in params]
    assert (tmp_path / "sweep_alpha.png").stat().st_size > 1000


@pytest.mark.slow
def test_compare_presets_prints_both_presets_for_the_five_gaits(tmp_path):
    output = run_example("compare_presets.py", tmp_path)
    for gait in ("A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5"):
        assert gait in output
    assert "accurate" in output and "paper" in output
    assert "directions as in the paper:" in output


@pytest.mark.slow
def test_fit_with_gradients_recovers_the_twin_experiments_values(tmp_path):
    """The exact derivatives it prints agree with the central differences it prints (whole
    runs at h = 1e-4 of α, plain simulate calls) to 1e-5, the sensitivities' stated accuracy,
    and the fit finds the values that made its target speeds again (to 1e-6: least squares on
    an exact Jacobian converges quadratically, its sum of squares reaching ~1e-20 (mm/s)^2)."""
    output = run_example("fit_with_gradients.py", tmp_path)
    lines = output.splitlines()

    def printed_array(start):
        line = next(line for line in lines if line.startswith(start))
        return np.array(line.split("[")[1].rstrip("]").split(), dtype=float)

    exact = printed_array("d speed / d alpha")
    difference = printed_array("central difference")
    assert len(exact) == 5 and (np.abs(exact) > 1.0).all()  # five gaits, none near zero
    # printed to 6 decimals: rounding adds up to 1e-6 absolute on values of 1-21 mm/s
    np.testing.assert_allclose(exact, difference, rtol=1e-5, atol=1e-6)
    recovered = next(line for line in lines if line.startswith("recovered:"))
    alpha = float(recovered.split("alpha = ")[1].split()[0])
    drag = float(recovered.split("drag_perpendicular = ")[1].split()[0])
    assert abs(alpha - 1.1) <= 1e-6 and abs(drag - 1.3) <= 1e-6


@pytest.mark.slow
def test_which_trial_next_prints_what_its_design_table_says(tmp_path):
    """Every line it prints agrees with the table it writes: per set of trials the held-out
    gaits left undetermined and the widest two standard errors of the others (to the printed
    three decimals), and the smallest sets that determine them all (none within two trials
    in the quick run: A5's gain stays free without A5). The table is `trial_design`'s: its
    columns, and with no trial added the same held-out gaits undetermined as the measured
    data leave (A1+A2, A1+A4, A1+A3+A5: each fires an actuator no other measured gait fires)."""
    output = run_example("which_trial_next.py", tmp_path)
    from taichi_star import identification
    table = pd.read_csv(tmp_path / "which_trial_next.csv")
    assert list(table.columns) == identification.DESIGN_COLUMNS
    held = table[table.role == "held_out"]
    lines = [line for line in output.splitlines() if "undetermined" in line]
    assert [line.split(":")[0].strip() for line in lines] == ["none", "A2", "A4", "A2 A4"]
    for line in lines:
        trials = line.split(":")[0].strip()
        rows = held[held.added_trials == trials]
        free = rows.gait[~rows.determined].tolist()
        assert line.split("undetermined")[1].split("widest")[0].strip() == (
            " ".join(free) or "none")
        widest = 2 * rows.standard_error_mm_s[rows.determined].max()
        assert f"{widest:.3f} mm/s" in line
    nothing_added = held[held.added_trials == "none"]
    assert nothing_added.gait[~nothing_added.determined].tolist() == [
        "A1+A2", "A1+A4", "A1+A3+A5"]
    assert output.strip().endswith("smallest sets that determine every held-out gait: none "
                                   "within two trials")


def test_lookahead_chooses_the_nearest_candidate_and_its_path_is_the_robots_own(tmp_path):
    """The gaits it chose, fired period by period on a robot of its own (no copies), give the
    positions it wrote to the bit: each copied future is the robot's; and the first chosen gait
    ends nearest the goal of the candidates simulated from rest."""
    run_example("lookahead.py", tmp_path)
    table = pd.read_csv(tmp_path / "lookahead.csv")
    assert table["period"].tolist() == [1, 2]
    params, solver = ts.StarParams.preset("paper"), ts.SolverConfig(dt=5e-3)
    goal = np.array([-20.0, -30.0])
    candidates = ["none"] + [f"A{m}" for m in range(1, 9)]
    # the first period's candidates from rest, each on a robot of its own (one batch)
    alone = ts.Simulator([params] * len(candidates), solver)
    alone.fire(candidates)
    alone.advance(params.period)
    distances = np.hypot(*(alone.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
                           - goal).T)
    assert table["gait"].iloc[0] == candidates[int(np.argmin(distances))]
    assert table["distance_mm"].iloc[0] == distances.min()
    robot = ts.Simulator([params], solver)
    for row in table.itertuples():
        robot.fire([row.gait])
        robot.advance(params.period)
        state = robot.state().iloc[0]
        assert (state.centroid_x_mm, state.centroid_y_mm) == (row.x_mm, row.y_mm)
        assert row.distance_mm == np.hypot(*(np.array([row.x_mm, row.y_mm]) - goal))
