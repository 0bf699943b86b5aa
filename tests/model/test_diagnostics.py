"""`SimulationResult.jet_impulses`: the jets' impulses recomputed from the recorded shapes,
checked against the momentum the engine's own run gained, and its refusals."""

import dataclasses

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.diagnostics import check_jet_solver
from taichi_star.reference import ReferenceSimulator

DT = 5e-3


def recorded(params, duration_s, solver=ts.SolverConfig(dt=DT), interval=DT):
    return ts.simulate(params, duration_s, solver, record_interval_s=interval,
                       record_shapes=True, progress=False)


def test_without_drag_the_jets_impulse_is_the_momentum_the_robot_gained():
    """With every drag off the jet is the only external force, and implicit Euler's
    momentum balance over a run from rest is exact: Σ_n (m_n + m_a,n)·v_n at the end equals
    Σ_steps h·F_jet(q_{k+1}), v_n = (q_n^K − q_n^{K−1})/h, the internal forces summing to zero.
    The engine moved the robot; the diagnostic recomputes the jets from its shapes alone."""
    still = dict(drag_parallel=0.0, drag_perpendicular=0.0, cylinder_drag=0.0)
    params = [ts.StarParams(gait="A1+A2+A3", **still),
              ts.StarParams(gait="A2+A5", actuator_delays=(0, 0, 0, 0, 0.05, 0, 0, 0), **still)]
    result = recorded(params, 0.4)
    impulses = result.jet_impulses()
    assert list(impulses["space"]) == list(range(1, 9)) * 2
    for instance, p in enumerate(params):
        twin = ReferenceSimulator(p)
        velocities = (result.shapes[-1, instance] - result.shapes[-2, instance]) / DT
        momentum = ((twin.mass + twin.added_mass)[:, None] * velocities).sum(axis=0)
        rows = impulses[impulses["instance"] == instance]
        total = rows[["impulse_x_n_s_m", "impulse_y_n_s_m"]].sum().to_numpy()
        assert np.abs(total).max() > 1e-4  # the stroke jets: a balance of something
        # measured 5e-10 and 3e-9 relative: each step's positions are converged to newton_tol
        # (1e-10 m, over h = 5 ms a velocity of 2e-8 m/s against ~1e-2 m/s); 1e-7 leaves room
        # for that error to add up over other steps, and a jet off by one step's area rate,
        # its h or its density would be off by far more
        assert total == pytest.approx(momentum, rel=1e-7)
        assert (rows["jetting_s"] > 0).any() and (rows["jetting_s"] <= 0.4 + 1e-12).all()


def test_a_symmetric_gait_jets_symmetrically_and_no_jet_gives_no_impulse():
    """A1+A3+A5+A7 is symmetric under the quarter turn, which maps space k to space k + 2
    (the arms are numbered counter-clockwise, 45° apart): space k + 2's impulse is space k's
    turned by +90°; with α = 0 every impulse is exactly zero."""
    result = recorded([ts.StarParams(gait="A1+A3+A5+A7"),
                       ts.StarParams(gait="A1+A3+A5+A7", alpha=0.0)], 0.3)
    impulses = result.jet_impulses()
    first = impulses[impulses["instance"] == 0].sort_values("space")
    vectors = first[["impulse_x_n_s_m", "impulse_y_n_s_m"]].to_numpy()
    length = np.hypot(vectors[:, 0], vectors[:, 1])
    assert length.min() > 0
    quarter_turn = np.array([[0.0, -1.0], [1.0, 0.0]])
    turned = vectors @ quarter_turn.T
    # to the rounding of the shapes: measured 1.7e-14 of space 1's impulse (1.8e-4 N·s/m, the
    # short one, as are spaces 3, 5, 7) and ≤ 5.4e-15 of the even spaces' (0.046 N·s/m);
    # 1e-12 of each space's own length (a quarter turn the wrong way is off by √2 lengths)
    for k in range(8):
        np.testing.assert_allclose(vectors[(k + 2) % 8], turned[k], rtol=0,
                                   atol=1e-12 * length[k], err_msg=f"space {k + 1}")
    without = impulses[impulses["instance"] == 1]
    assert (without[["impulse_x_n_s_m", "impulse_y_n_s_m", "jetting_s"]] == 0).all().all()


def test_a_failed_instance_gets_nan_rows_and_other_runs_are_refused():
    result = recorded([ts.StarParams(gait="A1"), ts.StarParams(gait="A2")], 0.02)
    shapes = result.shapes.copy()
    shapes[2:, 1] = np.nan  # as a failure leaves them from its time on
    impulses = dataclasses.replace(result, shapes=shapes).jet_impulses()
    assert impulses[impulses["instance"] == 1].drop(columns=["instance", "space"]).isna().all().all()
    assert np.isfinite(impulses[impulses["instance"] == 0]["impulse_x_n_s_m"]).all()
    with pytest.raises(ValueError, match="recorded shapes"):
        dataclasses.replace(result, shapes=None).jet_impulses()
    with pytest.raises(ValueError, match="record at every step"):
        recorded(ts.StarParams(gait="A1"), 0.02, interval=2 * DT).jet_impulses()
    with pytest.raises(ValueError, match="implicit Euler"):
        recorded(ts.StarParams(gait="A1"), 0.02,
                 solver=ts.SolverConfig(dt=DT, integrator="bdf2")).jet_impulses()


def test_jet_impulses_refuse_adaptive_euler_too():
    """Adaptive implicit Euler's steps are not the records' spacing: refused, as BDF2 is."""
    with pytest.raises(ValueError, match=r"implicit Euler with fixed steps.*adaptive=True"):
        check_jet_solver(ts.SolverConfig(adaptive=True))
    check_jet_solver(ts.SolverConfig())  # fixed-step Euler passes


def test_jet_impulses_refuse_a_run_with_a_single_record(taichi_cpu):
    """A run recorded once (at t = 0: record_interval_s past its duration) has no step to
    recompute: a ValueError, not a table of zero impulses."""
    result = ts.simulate([ts.StarParams(gait="A1", n_arc=6, n_limb=2)], 0.005,
                         ts.SolverConfig(dt=0.005), record_interval_s=0.01, record_shapes=True,
                         progress=False)
    assert result.trajectory["t_s"].nunique() == 1
    with pytest.raises(ValueError, match="record at every step"):
        result.jet_impulses()
