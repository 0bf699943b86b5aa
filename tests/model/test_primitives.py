"""Motion primitives (taichi_star.primitives): the statistics come from the per-cycle table,
every member of a symmetry class steps and turns alike, and the symmetry expansion equals a
direct simulation of image gaits."""

import math

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.primitives import (cycle_displacements, gait_sources, measure_primitives,
                                    primitives_from_sources)


def test_primitives_cover_255_gaits_with_statistics_of_their_cycles(quick_primitives):
    table, cycles = quick_primitives
    assert len(table) == 255 and table["gait"].is_unique and (table["status"] == "ok").all()
    # the statistics are those of the per-cycle table's cycles from first_cycle on
    row = table[table["gait"] == "A2+A3+A4+A6+A7"].iloc[0]
    steady = cycles[(cycles["gait"] == row["gait"]) & (cycles["cycle"] >= row["first_cycle"])]
    assert row["step_x_mm"] == pytest.approx(steady["dx_body_mm"].mean(), rel=1e-12)
    assert row["turn_deg"] == pytest.approx(steady["rotation_deg"].mean(), rel=1e-12)
    assert row["step_mm"] == pytest.approx(math.hypot(row["step_x_mm"], row["step_y_mm"]))
    # symmetry: a member's step is its representative's mirrored across the x axis (y -> -y)
    # where reflected, then turned by 45°·symmetry_rotation, and its turn the representative's,
    # reversed where reflected. Written out here, not through primitives.transform_*. The steps
    # (up to ~30 mm) may differ by a few roundings of the 2x2 rotation and of the mean over
    # cycles (taken after the mapping there, before it here): ~1e-14 mm (measured: equal);
    # 1e-12 mm leaves room, while a wrong rotation or a missed mirror moves a step by its own
    # size (a rotation by 90°·k instead: up to 57 mm). A negation is exact.
    by_gait = table.set_index("gait")
    source = by_gait.loc[table["class_representative"]]
    angle = np.radians(45.0 * table["symmetry_rotation"].to_numpy())
    sign = np.where(table["reflected"], -1.0, 1.0)
    x, y = source["step_x_mm"].to_numpy(), sign * source["step_y_mm"].to_numpy()
    expected = np.column_stack([np.cos(angle) * x - np.sin(angle) * y,
                                np.sin(angle) * x + np.cos(angle) * y])
    assert table["symmetry_rotation"].nunique() == 8 and table["reflected"].nunique() == 2
    np.testing.assert_allclose(table[["step_x_mm", "step_y_mm"]].to_numpy(), expected,
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(table["turn_deg"].to_numpy(),
                                  sign * source["turn_deg"].to_numpy())


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


# A short cycle (0.2 s, just past the 0.163-s heating phase) at dt = 10 ms, one firing and one
# cycle of glide (60 steps), and a part of the 255 gaits (at most 64 robots a batch, the engine
# size the other tests compile): kept cheap for the suite's budget (the steps are still 0.2-2
# mm). Every gait in `sources` is simulated as the all-gaits path does.
SHORT_CYCLE = ts.StarParams(period=0.2)
SHORT_SOLVER = ts.SolverConfig(dt=1e-2)
MIRROR_ATOL = 1e-5
"""mm and deg: a gait and its symmetry image, both simulated, differ only by the Newton solves'
residuals (newton_tol = 1e-10 m a step: at most 60 steps × 1e-10 m = 6e-6 mm over the cycle and
its glide; measured 2e-7); a wrong mapping or a broken symmetry is off by a sizeable part of
the step, tenths of a millimetre and more."""
STEP_COLUMNS = ["step_x_mm", "step_y_mm", "turn_deg", "glide1_x_mm", "glide1_y_mm"]


def measure_directly(base, gaits):
    """The primitive table (one cycle, its glide over one more) of `gaits`, each simulated
    itself: the all-gaits path (`gait_sources(False)`) restricted to them."""
    sources = {gait: source for gait, source in gait_sources(False).items() if gait in gaits}
    assert set(sources) == set(gaits)
    table, _ = primitives_from_sources(base, SHORT_SOLVER, sources, cycles=1, first_cycle=0,
                                       glide_cycles=1)
    return table.set_index("gait")


def test_all_gaits_path_equals_the_symmetry_reduction_with_equal_actuators():
    """With equal actuators, the 24 gaits of two classes (A1+A2's 8 rotations; A1+A2+A4's 8
    rotations and 8 mirror images), each simulated itself, step, turn and glide as
    measure_primitives reads them from the representative through the symmetry, within
    MIRROR_ATOL."""
    reduced, _ = measure_primitives(SHORT_CYCLE, SHORT_SOLVER, cycles=1, first_cycle=0,
                                    glide_cycles=1)
    reduced = reduced.set_index("gait")
    classes = dict(ts.symmetry_classes())
    gaits = classes["A1+A2"] + classes["A1+A2+A4"]
    assert len(gaits) == 24
    direct = measure_directly(SHORT_CYCLE, gaits)
    assert reduced.loc[gaits, "reflected"].sum() == 8
    assert (reduced.loc[gaits, "class_representative"] != pd.Index(gaits)).sum() == 22
    assert (direct["class_representative"] == direct.index).all()
    assert (direct["status"] == "ok").all() and (reduced["status"] == "ok").all()
    assert reduced.loc[gaits, "step_mm"].min() > 0.1  # they move: not a comparison of zeros
    np.testing.assert_allclose(direct.loc[gaits, STEP_COLUMNS].to_numpy(),
                               reduced.loc[gaits, STEP_COLUMNS].to_numpy(), rtol=0,
                               atol=MIRROR_ATOL)


def test_unequal_gains_break_the_mirror_symmetry():
    """Gains 1.5 on A2 and 0.5 on A8 (A1+A2 and A1+A8 are mirror images across A1's axis):
    measure_primitives must simulate every gait (each its own source), because A1+A8's step
    and glide are no longer A1+A2's mirrored (the stronger A2 pushes harder); A1+A3 and A1+A7,
    whose actuators keep gain 1, still are, within MIRROR_ATOL."""
    gains = (1.0, 1.5, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5)
    rows = measure_directly(SHORT_CYCLE.replace(actuator_gains=gains),
                            ["A1+A2", "A1+A8", "A1+A3", "A1+A7"])
    assert (rows["status"] == "ok").all()
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
