"""Motion primitives (taichi_star.primitives): the statistics come from the per-cycle table,
every member of a symmetry class steps and turns alike, and the symmetry expansion equals a
direct simulation of image gaits."""

import math

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.primitives import cycle_displacements, measure_primitives


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


# A short cycle at dt = 5 ms (100 steps), one firing: the two paths below simulate 255 robots
# each, so the cycle is kept short for the suite's budget.
SHORT_CYCLE = ts.StarParams(period=0.5)
SHORT_SOLVER = ts.SolverConfig(dt=5e-3)
MIRROR_ATOL = 1e-5
"""mm and deg: a gait and its symmetry image, both simulated, differ only by the Newton solves'
residuals (newton_tol = 1e-10 m a step, so up to ~100 steps × 1e-10 m ~ 1e-5 mm over a short
cycle and its glide; see test_expansion_equals_direct_simulation_of_image_gaits); a wrong
mapping or a broken symmetry is off by a sizeable part of the step, millimetres."""


def measure_short(base, all_gaits=False):
    """measure_primitives of one cycle of SHORT_CYCLE's period, with the glide over one more."""
    return measure_primitives(base, SHORT_SOLVER, cycles=1, first_cycle=0, glide_cycles=1,
                              all_gaits=all_gaits)


@pytest.fixture(scope="module")
def equal_actuators_both_ways():
    """(symmetry-reduced table, all-gaits table) of the equal actuators' SHORT_CYCLE robot."""
    return measure_short(SHORT_CYCLE)[0], measure_short(SHORT_CYCLE, all_gaits=True)[0]


def test_all_gaits_path_equals_the_symmetry_reduction_with_equal_actuators(
        equal_actuators_both_ways):
    """With equal actuators, simulating all 255 gaits gives the steps, turns and glides the 29
    representatives give through the symmetry, within MIRROR_ATOL; the reduced table reads 226
    gaits from another gait's run, the direct one none."""
    reduced, direct = equal_actuators_both_ways
    assert reduced["class_representative"].nunique() == 29
    assert (reduced["class_representative"] != reduced["gait"]).sum() == 255 - 29
    assert (direct["class_representative"] == direct["gait"]).all()
    assert list(direct["gait"]) == list(reduced["gait"])
    assert (direct["status"] == "ok").all() and (reduced["status"] == "ok").all()
    columns = ["step_x_mm", "step_y_mm", "turn_deg", "glide1_x_mm", "glide1_y_mm"]
    assert reduced["step_mm"].max() > 1.0  # the robots move: the comparison is not of zeros
    np.testing.assert_allclose(direct[columns].to_numpy(), reduced[columns].to_numpy(),
                               rtol=0, atol=MIRROR_ATOL)


def test_unequal_gains_simulate_every_gait_and_break_the_mirror_symmetry():
    """Gains 1.5 on A2 and 0.5 on A8 (A1+A2 and A1+A8 are mirror images across A1's axis):
    all 255 gaits are simulated, each its own representative, and A1+A8's step and glide are
    no longer A1+A2's mirrored (the stronger A2 pushes harder); A1+A3 and A1+A7, whose
    actuators keep gain 1, still are, within MIRROR_ATOL."""
    gains = (1.0, 1.5, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5)
    table, cycles = measure_short(SHORT_CYCLE.replace(actuator_gains=gains))
    assert len(table) == 255 and (table["status"] == "ok").all()
    assert (table["class_representative"] == table["gait"]).all()
    assert (table["class_size"] == 1).all() and (table["symmetry_rotation"] == 0).all()
    assert not table["reflected"].any() and not cycles["reflected"].any()
    rows = table.set_index("gait")
    mirror = np.array([1.0, -1.0])
    for step in (["step_x_mm", "step_y_mm"], ["glide1_x_mm", "glide1_y_mm"]):
        strong, weak = rows.loc["A1+A2", step].to_numpy(), rows.loc["A1+A8", step].to_numpy()
        assert np.hypot(*(strong * mirror - weak)) > 0.1 * np.hypot(*strong), step
        assert np.hypot(*strong) > np.hypot(*weak), step
        np.testing.assert_allclose(rows.loc["A1+A7", step].to_numpy(),
                                   rows.loc["A1+A3", step].to_numpy() * mirror,
                                   rtol=0, atol=MIRROR_ATOL, err_msg=str(step))
    assert rows.loc["A1+A7", "turn_deg"] == pytest.approx(-rows.loc["A1+A3", "turn_deg"],
                                                         abs=MIRROR_ATOL)
