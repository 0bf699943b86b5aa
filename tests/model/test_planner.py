"""Driving the simulated robot with the planner (taichi_star.planner.drive): open and closed
loop from the measured primitives, planning for the glide and judged at rest."""

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.planner import PrimitiveModel, default_goals, drive
from taichi_star.primitives import GLIDE_COLUMNS, measure_glides


def test_drive_plans_for_the_glide_and_judges_goals_at_rest(quick_primitives):
    """Two goals 40 mm away, 3 cycles and one of settling, with the quick primitives and their
    one-cycle glides: planning for the glide, both controllers fire once and the robot glides
    to rest within 5 mm of each goal; the same primitives without their glides fire until the
    model puts the robot on the goal and it glides on, 12-16 mm past (measured)."""
    table, _ = quick_primitives
    solver = ts.SolverConfig(dt=table["dt_s"].iloc[0])
    glides = measure_glides(ts.StarParams(), solver, fire_cycles=2, glide_cycles=1)
    assert list(glides.columns) == GLIDE_COLUMNS and len(glides) == 255
    aware = PrimitiveModel.from_table(table.merge(glides, on="gait"))
    blind = PrimitiveModel.from_table(table)
    goals = default_goals(40.0, count=2, far_mm=None)
    summary, cycles, path = drive(aware, goals, solver=solver, max_cycles=3,
                                  frames_per_cycle=3, settle_cycles=1)
    blind_summary, _, _ = drive(blind, goals, solver=solver, max_cycles=3, frames_per_cycle=3,
                                settle_cycles=1)
    assert list(summary["mode"]) == ["open", "closed"] * 2
    first = cycles[cycles["cycle"] == 0]
    assert first.groupby("goal")["gait"].nunique().eq(1).all()
    # judged at rest, after the settling cycle
    assert (summary["reached"] == (summary["end_error_mm"] <= 5.0)).all()
    assert summary["reached"].all() and (summary["cycles_fired"] == 1).all()
    assert (summary["final_error_mm"] > 5.0).all()  # when it stopped firing it was gliding
    assert (summary["run_cycles"] == cycles["cycle"].max() + 1).all()
    assert not blind_summary["reached"].any()
    assert (blind_summary["end_error_mm"] > 2 * summary["end_error_mm"]).all()
    # the path starts at the origin and passes through each recorded cycle boundary
    row = cycles[(cycles["mode"] == "closed") & (cycles["goal"] == 0) & (cycles["cycle"] == 1)]
    on_path = path[(path["mode"] == "closed") & (path["goal"] == 0)
                   & np.isclose(path["t_s"], 3.15)]
    np.testing.assert_allclose(on_path[["x_mm", "y_mm"]].to_numpy(),
                               row[["x_mm", "y_mm"]].to_numpy())
    assert path.groupby(["goal", "mode"])["controlled"].first().all()
    assert not path.groupby(["goal", "mode"])["controlled"].last().any()  # the glide
    with pytest.raises(ValueError, match="goals_mm"):
        drive(aware, [[np.nan, 0.0]], solver=solver)
    with pytest.raises(ValueError, match="settle_cycles"):
        drive(aware, goals, solver=solver, settle_cycles=-1)
