"""Motion primitives (taichi_star.primitives): the statistics come from the per-cycle table,
every member of a symmetry class steps and turns alike, and the symmetry expansion equals a
direct simulation of image gaits."""

import math

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.primitives import cycle_displacements


def test_primitives_cover_255_gaits_with_statistics_of_their_cycles(quick_primitives):
    table, cycles = quick_primitives
    assert len(table) == 255 and table["gait"].is_unique and (table["status"] == "ok").all()
    # the statistics are those of the per-cycle table's cycles from first_cycle on
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


def test_expansion_equals_direct_simulation_of_image_gaits(quick_primitives):
    """Gaits that are not class representatives, simulated directly, step and turn as the
    symmetry maps their representative's cycles: two mirror images that turn (the rotation's
    sign flips) and one rotated image. Tolerance 1e-5 mm and deg: each step's Newton solve
    leaves at most newton_tol = 1e-10 m, so over the 2 cycles of steps mirror-image runs may
    drift apart by up to (steps × 1e-10 m, ~1e-4 mm, ~1e-4 deg on the 5-cm robot); measured
    1e-6. A wrong symmetry map would be off by the step itself, millimetres."""
    table, cycles = quick_primitives
    solver = ts.SolverConfig(dt=table["dt_s"].iloc[0])
    turning = cycles[(cycles["cycle"] == 1) & (cycles["rotation_deg"].abs() > 0.1)]
    mirrored = list(turning[turning["reflected"]]["gait"].iloc[[0, -1]])
    rotated = turning[~turning["reflected"] & (turning["symmetry_rotation"] > 0)]["gait"].iloc[0]
    gaits = [*mirrored, rotated]
    result = ts.simulate([ts.StarParams(gait=g) for g in gaits], 2 * 3.15, solver,
                         record_interval_s=3.15)
    direct = cycle_displacements(result.trajectory, 3.15)
    for index, gait in enumerate(gaits):
        expected = cycles[cycles["gait"] == gait][["dx_body_mm", "dy_body_mm", "rotation_deg"]]
        got = direct[direct["instance"] == index][["dx_body_mm", "dy_body_mm", "rotation_deg"]]
        np.testing.assert_allclose(got.to_numpy(), expected.to_numpy(), rtol=0, atol=1e-5,
                                   err_msg=gait)
