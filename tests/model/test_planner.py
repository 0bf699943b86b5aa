"""Driving the simulated robot with the planner (taichi_star.planner.drive): open and closed
loop from the measured primitives."""

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.planner import PrimitiveModel, default_goals, drive


def test_drive_open_and_closed_loop(quick_primitives):
    """Two goals 25 mm away, 3 cycles: the controllers start alike (same first gait, the
    open loop's prediction = the closed loop's after one cycle); the closed loop reaches both
    goals (the best gaits step ~28 mm) and stops firing once there."""
    table, _ = quick_primitives
    model = PrimitiveModel.from_table(table)
    solver = ts.SolverConfig(dt=table["dt_s"].iloc[0])
    goals = default_goals(25.0, count=2, far_mm=None)
    summary, cycles, path = drive(model, goals, solver=solver, max_cycles=3,
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
        drive(model, [[np.nan, 0.0]], solver=solver)
