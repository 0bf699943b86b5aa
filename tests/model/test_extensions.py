"""The model extensions of issue 28 (1a, 1c): linear drag on the rods and the hub, and
per-actuator gains and delays. Each is off by default; with it on, the reference's elements
against finite differences and the reference's actuation against the profile's formula here;
the engine against the reference in tests/model/test_engine.py
(`test_engine_matches_reference_with_damping_joints_ends_closure_and_extensions`) and the
linear drag term assembled alone in tests/unit/test_assembly.py.

Finite differences follow tests/model/test_reference.py: a central difference of step δ =
1e-6 of the smallest length the element depends on has truncation and round-off errors ~1e-10
relative; we allow 1e-6 of the largest entry (a wrong or missing term is O(1) off).
"""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.geometry import ARC_BEND, SPOKE
from taichi_star.model import build_model
from taichi_star.reference import (ReferenceSimulator, hub_linear_drag_element,
                                   linear_rod_drag_element)

FD_RTOL = 1e-6


def central_jacobian(func, x, step):
    """∂func/∂x (..., m, n) by central differences of func: (..., n) -> (..., m), each
    coordinate perturbed in every element at once (the elements are independent)."""
    columns = []
    for m in range(x.shape[-1]):
        forward, backward = x.copy(), x.copy()
        forward[..., m] += step
        backward[..., m] -= step
        actual = (forward[..., m] - backward[..., m])[..., None]
        columns.append((func(forward) - func(backward)) / actual)
    return np.stack(columns, axis=-1)


def assert_close_to_scale(actual, expected, rtol=FD_RTOL):
    scale = np.abs(expected).max()
    assert scale > 0, "the expected values are all zero: the check would be vacuous"
    assert np.abs(actual - expected).max() <= rtol * scale


# ---- reference elements ----------------------------------------------------------------------

def test_linear_rod_drag_element_is_minus_c_l_times_the_mean_velocity_with_its_jacobian():
    rng = np.random.default_rng(11)
    n = 12
    xa = rng.uniform(-1e-3, 1e-3, (n, 2))
    xb = xa + rng.uniform(-1e-3, 1e-3, (n, 2)) + np.array([1.5e-3, 0.0])
    xa_old = xa - rng.uniform(-1e-4, 1e-4, (n, 2))
    xb_old = xb - rng.uniform(-1e-4, 1e-4, (n, 2))
    dt, rest, coeff = 1e-3, rng.uniform(0.8e-3, 1.2e-3, n), 40.0
    x = np.concatenate([xa, xb], axis=1)

    def element(y):
        return linear_rod_drag_element(y[:, :2], y[:, 2:], xa_old, xb_old, dt, rest, coeff)

    forces, jac = element(x)
    assert_close_to_scale(jac, central_jacobian(lambda y: element(y)[0], x, 1e-6 * 1e-5))
    mean_velocity = 0.5 * ((xa - xa_old) + (xb - xb_old)) / dt
    expected = -coeff * rest[:, None] * mean_velocity
    np.testing.assert_allclose(forces[:, :2], 0.5 * expected, rtol=1e-12)
    np.testing.assert_allclose(forces[:, 2:], 0.5 * expected, rtol=1e-12)
    # it does not depend on the edge's direction (isotropic) and it dissipates
    # (the edge turned, its nodes' velocities kept)
    turned_xb = xa + (xb - xa)[:, ::-1]
    turned = linear_rod_drag_element(xa, turned_xb, xa_old, xb_old + (turned_xb - xb), dt, rest,
                                     coeff)[0]
    np.testing.assert_allclose(turned, forces, rtol=1e-12)  # rounding of the shifted positions
    power = (forces[:, :2] * (xa - xa_old) + forces[:, 2:] * (xb - xb_old)).sum(1) / dt
    assert np.all(power < 0)


def test_hub_linear_drag_element_is_minus_c_h_times_the_velocity_with_its_jacobian():
    rng = np.random.default_rng(12)
    x = rng.uniform(-1e-3, 1e-3, (6, 2))
    x_old = x - rng.uniform(-1e-4, 1e-4, (6, 2))
    dt, coeff = 1e-3, 3.0

    def element(y):
        return hub_linear_drag_element(y, x_old, dt, coeff)

    force, jac = element(x)
    assert_close_to_scale(jac, central_jacobian(lambda y: element(y)[0], x, 1e-6 * 1e-5))
    np.testing.assert_allclose(force, -coeff * (x - x_old) / dt, rtol=1e-12)


def test_assembled_fluid_jacobian_with_linear_drag_matches_finite_differences():
    """The reference's assembled fluid forces with the linear drag on: the drag's share is
    −c_l·Δl̄·v on the rods and −c_h·v on the hub, and the Jacobian is exact."""
    params = ts.StarParams(gait="A1+A2", linear_drag=60.0, hub_linear_drag=4.0)
    sim = ReferenceSimulator(params)
    without = ReferenceSimulator(params.replace(linear_drag=0.0, hub_linear_drag=0.0))
    rng = np.random.default_rng(13)
    rest = sim.topology.rest_positions
    q_new = rest + rng.uniform(-2e-5, 2e-5, rest.shape)
    q_old = 1.001 * q_new + rng.uniform(-5e-5, 5e-5, rest.shape)
    dt, t_new = 1e-3, 0.08

    def fluid(y):
        return sim.fluid_forces(y.reshape(rest.shape), q_old, dt).reshape(-1)

    # the elastic Jacobian alone: without the linear drag and at v = 0 (q_old = q_new) every
    # other fluid term and its Jacobian vanish
    elastic_jac = without.force_jacobian(q_new, q_new, t_new, dt)[1]
    fluid_jac = sim.force_jacobian(q_new, q_old, t_new, dt)[1] - elastic_jac
    # δ = 1e-6 of the ~1 mm edges, as in test_reference.test_assembled_force_jacobian
    assert_close_to_scale(fluid_jac, central_jacobian(fluid, q_new.reshape(-1), 1e-9))
    added = sim.fluid_forces(q_new, q_old, dt) - without.fluid_forces(q_new, q_old, dt)
    velocity = (q_new - q_old) / dt
    rods = sim.topology.edge_kind != SPOKE  # spokes are inside the hub: no drag
    expected = np.zeros_like(q_new)
    for (i, j), length in zip(sim.topology.edges[rods], sim.topology.rest_length[rods]):
        share = -0.5 * 60.0 * length * 0.5 * (velocity[i] + velocity[j])
        expected[i] += share
        expected[j] += share
    expected[0] += -4.0 * velocity[0]
    # the difference of two sums of ~1e-2 N/m forces: rounding ~1e-17 N/m
    np.testing.assert_allclose(added, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_reference_actuators_follow_their_gain_and_delay():
    """K̄_k(t) = K̄(0) + g_k·(K̄(max(t − d_k, 0)) − K̄(0)) per actuator, within each cycle;
    K̄(0) through the delay, including its last instant, and the profile after it."""
    gains = (1.0, 0.5, 1.0, 2.0, 1.0, 1.0, 0.0, 1.0)
    delays = (0.0, 0.0, 0.04, 0.04, 0.0, 0.0, 0.0, 0.0)
    params = ts.StarParams(gait="A1+A2+A3+A4+A7", actuator_gains=gains, actuator_delays=delays)
    sim = ReferenceSimulator(params)
    profile = params.actuator_profile
    rest = profile.rest_curvature
    for t in (0.0, 0.02, 0.04, 0.1, 0.5, params.period + 0.03, params.period + 0.06):
        since = t % params.period
        driven = sim.driven_curvature(t)
        for k in range(8):
            curvature = profile.curvature(max(since - delays[k], 0.0))
            assert driven[k] == pytest.approx(rest + gains[k] * (curvature - rest), rel=1e-14)
        if since <= 0.04:
            assert driven[2] == rest  # still in A3's delay
    # the actuated triplets of A2 follow its own K̄, not A1's
    t = 0.1
    natural = sim.natural_curvature(t)
    actuated = sim.topology.triplet_actuator == 1
    arc = actuated & (sim.topology.triplet_kind == ARC_BEND)
    assert np.allclose(np.abs(natural[arc]), sim.driven_curvature(t)[1], rtol=1e-14)
    assert not np.isclose(sim.driven_curvature(t)[1], sim.driven_curvature(t)[0])


# ---- the engine -------------------------------------------------------------------------------

def test_extensions_are_off_by_default_and_compiled_out():
    model = build_model([ts.StarParams.preset("paper"), ts.StarParams.preset("accurate")
                         .replace(n_arc=18)])
    assert "linear_drag" not in [cls.name for cls, _ in model.terms_used]
    for preset in ("paper", "accurate"):
        params = ts.StarParams.preset(preset)
        assert (params.linear_drag, params.hub_linear_drag) == (0.0, 0.0)
        assert params.actuator_gains == (1.0,) * 8 and params.actuator_delays == (0.0,) * 8


def test_per_actuator_values_are_per_instance():
    """Instances differing only in A2's gain (or in A2's delay) run in one batch exactly as each
    alone (one thread per instance); a gain or delay of an actuator the gait does not fire
    changes nothing, to the bit; A2's gain does change an A1+A2 gait."""
    base = ts.StarParams(gait="A1+A2")
    batch = [base, base.replace(actuator_gains=(1, 0.7, 1, 1, 1, 1, 1, 1)),
             base.replace(actuator_delays=(0, 0.02, 0, 0, 0, 0, 0, 0)),
             base.replace(actuator_gains=(1, 1, 1, 1, 1, 3.0, 1, 1),
                          actuator_delays=(0, 0, 0, 0, 0, 0, 0.5, 0))]
    together = ts.simulate(batch, 0.05, record_interval_s=0.05).summary
    for index, params in enumerate(batch[:3]):
        alone = ts.simulate([params], 0.05, record_interval_s=0.05).summary
        pd.testing.assert_frame_equal(alone.reset_index(drop=True),
                                      together.iloc[[index]].reset_index(drop=True),
                                      check_exact=True)
    columns = ["displacement_x_mm", "displacement_y_mm", "heading_deg"]
    np.testing.assert_array_equal(together.loc[3, columns], together.loc[0, columns])
    assert together.speed_mm_s[1] != together.speed_mm_s[0]
    assert together.speed_mm_s[2] != together.speed_mm_s[0]


# ---- parameters -------------------------------------------------------------------------------

@pytest.mark.parametrize("changes,message", [
    ({"actuator_gains": (1.0,) * 3}, r"actuator_gains must have 8 entries \(A1..A8\), got 3"),
    ({"actuator_gains": (1.0,) * 9}, r"actuator_gains must have 8 entries \(A1..A8\), got 9"),
    ({"actuator_gains": (1, 1, -0.1, 1, 1, 1, 1, 1)}, r"actuator_gains\[2\] \(A3\) must be a real "
                                                      r"number in \[0, 5\]"),
    ({"actuator_gains": (1, 1, 1, 1, 1, 1, 1, 5.000001)}, r"actuator_gains\[7\] \(A8\)"),
    ({"actuator_gains": (1, float("nan"), 1, 1, 1, 1, 1, 1)}, r"actuator_gains\[1\]"),
    ({"actuator_gains": (1, True, 1, 1, 1, 1, 1, 1)}, r"actuator_gains\[1\]"),
    ({"actuator_gains": 1.0}, "actuator_gains must be a tuple of 8 numbers"),
    ({"actuator_delays": (0, 0, 0, 0, 0, 0, 0, -1e-9)}, r"actuator_delays\[7\] \(A8\) must be a "
                                                        r"real number in \[0, 3.15\)"),
    ({"actuator_delays": (3.15, 0, 0, 0, 0, 0, 0, 0)}, r"actuator_delays\[0\] \(A1\)"),
    ({"period": 0.5, "actuator_delays": (0, 0.5, 0, 0, 0, 0, 0, 0)}, r"in \[0, 0.5\)"),
    ({"linear_drag": -1.0}, r"linear_drag must be a real number in \[0, 10000\]"),
    ({"hub_linear_drag": 1001.0}, r"hub_linear_drag must be a real number in \[0, 1000\]"),
])
def test_extension_fields_refuse_values_out_of_range(changes, message):
    with pytest.raises(ValueError, match=message):
        ts.StarParams(**changes)


def test_extension_fields_accept_their_bounds_lists_and_arrays():
    params = ts.StarParams(actuator_gains=[0, 5, 1, 1, 1, 1, 1, 1],
                           actuator_delays=np.array([0.0, 3.1499, 0, 0, 0, 0, 0, 0]),
                           linear_drag=1e4, hub_linear_drag=0.0)
    assert params.actuator_gains == (0.0, 5.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    assert all(type(v) is float for v in params.actuator_gains + params.actuator_delays)
    assert params.actuator_delays[1] == 3.1499
    hash(params)  # frozen and hashable: usable as a key of a batch or a cache


def test_extension_fields_survive_csv_and_parquet_round_trips(tmp_path):
    """The summary holds the per-actuator tuples as their text (like the actuator profile, a
    type every table format has); to_csv or to_parquet, read back, and from_row gives the same
    StarParams, to the bit (a float's repr reads back exactly)."""
    params = ts.StarParams(gait="A1+A2", linear_drag=12.5, hub_linear_drag=0.1 + 0.2,
                           actuator_gains=(1.0, 0.1 + 0.2, 1, 1, 1, 1, 1, 2.5),
                           actuator_delays=(0.0, 1 / 3, 0, 0, 0, 0, 0, 0))
    result = ts.simulate([params], 0.002, record_interval_s=0.002)
    summary = result.summary
    assert summary["actuator_gains"][0] == str(params.actuator_gains)
    assert summary["linear_drag_pa_s_m"][0] == 12.5
    assert ts.StarParams.from_row(summary.iloc[0]) == params
    row = pd.read_csv(result.to_csv(tmp_path / "summary.csv")).iloc[0]
    assert ts.StarParams.from_row(row) == params
    row = pd.read_parquet(result.to_parquet(tmp_path / "summary.parquet")).iloc[0]
    assert ts.StarParams.from_row(row) == params
    assert ts.StarParams(actuator_delays="[0, 0.25, 0, 0, 0, 0, 0, 0]").actuator_delays[1] == 0.25
    with pytest.raises(ValueError, match="actuator_gains: cannot read 'a, b'"):
        ts.StarParams(actuator_gains="a, b")
