"""The strokes study in --quick mode against the library run directly: the measured trial's
strokes, a direct simulation's and the trajectory fit's phase, and the circular gap."""

import types

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams, identification

from studies import identify, strokes


@pytest.mark.parametrize("later, earlier, gap", [(0.2, 3.1, 0.25), (3.1, 0.2, -0.25),
                                                 (1.0, 0.2, 0.8), (0.2 + 1.575, 0.2, 1.575)])
def test_the_circular_gap_lies_in_minus_half_to_half_the_period(later, earlier, gap):
    """(−T/2, T/2]: half a period exactly is +T/2 (the boundary), 0.25 s across the period's
    start is 0.25 s, not 2.9."""
    assert identification.circular_difference(later, earlier, 3.15) == pytest.approx(gap,
                                                                                     abs=1e-12)


def test_each_gaits_hub_path_is_read_off_its_own_instance():
    """Gait k's hub is node 0 of instance k (m, read in mm) at its run's record times; a failed
    run (None) has no hub path and shifts no other gait's instance."""
    times = np.array([0.0, 0.5, 1.0])
    shapes = np.zeros((3, 2, 4, 2))
    shapes[:, 0] = 7.0  # the failed instance, every node
    shapes[:, 1, 0, 0] = [0.001, 0.002, 0.004]  # instance 1's hub moves along x
    shapes[:, 1, 1:] = 9.0  # its other nodes stand elsewhere
    path = identification.CentroidPath(times, np.zeros(3), np.zeros(3), 3.15)
    paths = strokes.hub_paths(types.SimpleNamespace(shapes=shapes),
                              {"A1+A2": None,
                               "A1+A4": identification.SimulatedRun("A1+A4", path, (1.0, 0.0))})
    assert list(paths) == ["A1+A4"]
    hub = paths["A1+A4"]
    np.testing.assert_array_equal(hub.t_s, times)
    np.testing.assert_allclose(hub.x_mm, [1.0, 2.0, 4.0], rtol=1e-15)  # mm from m: one rounding
    np.testing.assert_array_equal(hub.y_mm, np.zeros(3))
    assert hub.period_s == 3.15


def test_quick_run_against_the_library(tmp_path):
    table = strokes.main(["--quick", "--out", str(tmp_path), "--no-progress"])
    written = pd.read_csv(tmp_path / "strokes.csv")
    assert written["gait"].tolist() == ["A1+A2"] and written["status"].tolist() == ["ok"]
    # check_dtype off: the CSV keeps 10 significant digits, so a float that is a whole number
    # (the identified model's fitted phase is 0 s on this track) reads back as an integer
    pd.testing.assert_frame_equal(written, table, check_exact=False, rtol=1e-9,
                                  check_dtype=False)
    row = written.iloc[0]
    trial = identification.measured_trial("A1+A2")
    measured = identification.strokes(trial.path)
    # the CSV keeps 10 significant digits
    assert row["stroke_phase_s"] == pytest.approx(measured.phase_s, rel=1e-9)
    assert row["drift_s"] == pytest.approx(measured.drift_s, rel=1e-9)
    assert row["pulse_period_s"] == pytest.approx(3.15 + measured.drift_s, rel=1e-9)
    assert (row["cycles"], row["consistent_cycles"]) == (measured.cycles,
                                                         measured.consistent_cycles)
    assert row["jump_ratio"] == pytest.approx(measured.jump_mm / measured.typical_mm, rel=1e-9)
    assert (row["on_line_cycles"], row["periodic"]) == (measured.on_line_cycles, True)
    assert row["line_phase_s"] == pytest.approx(measured.line_phase_s, rel=1e-9)
    for column, share in (("pulse_period_low_onset_s", 0.4), ("pulse_period_high_onset_s", 0.6)):
        assert row[column] == pytest.approx(
            3.15 + identification.strokes(trial.path, onset_share=share).drift_s, rel=1e-9)
    # the model: the identified preset at --quick's 2-ms steps, three cycles from rest and
    # a window and a record more (its third stroke is read too)
    params = StarParams.preset("identified", gait="A1+A2")
    result = taichi_star.simulate([params], 3 * params.period + 0.1 + 0.01,
                                  SolverConfig.preset("identified", dt=2e-3),
                                  record_interval_s=identify.RECORD_INTERVAL_S, record_shapes=True)
    runs = dict(zip(["A1+A2"], identification.simulated_runs(result.trajectory, ["A1+A2"],
                                                             [params.period])))
    model = identification.strokes(runs["A1+A2"].path, from_rest=True, min_jump_ratio=1.0)
    assert model.cycles == row["model_cycles"] == 3
    assert row["model_stroke_phase_s"] == pytest.approx(model.phase_s, rel=1e-9, abs=1e-12)
    assert row["model_jump_mm"] == pytest.approx(model.jump_mm, rel=1e-9)
    # the hub is node 0 (docs/model.md), its path in mm at the same records
    hub = identification.CentroidPath(runs["A1+A2"].path.t_s, *(1e3 * result.shapes[:, 0, 0].T),
                                      params.period)
    assert row["model_hub_jump_mm"] == pytest.approx(identification.strokes(hub).jump_mm,
                                                     rel=1e-9)
    # the hub swings with the strokes: it jumps farther than the centroid (0.42 against 0.30
    # mm at 1-ms steps), though nowhere near the measured 2.7 mm
    assert model.jump_mm < row["model_hub_jump_mm"] < row["jump_mm"] / 2
    fitted = identification.trajectory_objective(runs, {"A1+A2": trial})["phase_s"].iloc[0]
    assert row["fitted_phase_s"] == pytest.approx(fitted, rel=1e-9)
    firing = identification.stroke_aligned_phase(runs["A1+A2"], trial, (1, 3))
    assert row["firing_phase_s"] == pytest.approx(firing, rel=1e-9)
    assert row["phase_gap_s"] == pytest.approx(
        identification.circular_difference(fitted, firing, 3.15), rel=1e-9)
    moves = pd.read_csv(tmp_path / "strokes_moves.csv")
    kept = trial.path.t_s[trial.path.t_s <= trial.path.t_s[-1] - 0.1]
    # 22.5 s: seven whole periods and part of an eighth, whose moves are plotted too
    assert len(moves) == len(kept) and set(moves["cycle"]) == set(range(1, 9))
    # each period's farthest move is the stroke's jump: their median is the table's
    farthest = moves.groupby("cycle")["move_mm"].max()
    assert np.median(farthest[farthest.index <= measured.cycles]) == pytest.approx(
        row["jump_mm"], rel=1e-9)
    # the moves mark where the library reads each period's stroke, and its onset
    starts = moves[moves["stroke"]]
    assert starts["cycle"].tolist() == list(range(1, measured.cycles + 1))
    np.testing.assert_allclose(starts["phase_s"], measured.cycle_phases_s, rtol=1e-9)
    np.testing.assert_allclose(starts["onset_mm"], measured.cycle_onsets_mm, rtol=1e-9)
    assert (starts["move_mm"] >= starts["onset_mm"]).all()
    assert moves.loc[moves["cycle"] > measured.cycles, "onset_mm"].isna().all()
    assert (tmp_path / "strokes.png").stat().st_size > 1000
