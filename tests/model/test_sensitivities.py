"""Sensitivities through the implicit solver (`simulate(..., sensitivities=...)`) against finite
differences of whole runs, and the rules of the API."""

import dataclasses
import re

import numpy as np
import pandas as pd
import pytest

from taichi_star import SolverConfig, StarParams, sensitivities, simulate
from taichi_star.sensitivities import SUMMARY_OUTPUTS, parse_directions, sensitivity_column
from taichi_star.sensitivity_check import (check_sensitivities, difference_step, inward,
                                           one_sided, taylor_step)

DURATION_S = 0.1
"""100 steps of 1 ms: the A1 pulse has begun to bend the arcs and the robot to move."""
BASE = StarParams.preset("paper")
BATCH = (dataclasses.replace(BASE, gait="A1+A2"),
         dataclasses.replace(BASE, gait="A1+A3", alpha=1.2))
DIRECTIONS = ("alpha", "actuator_gains[1]", "drag_perpendicular")
TIGHT = dict(newton_tol=1e-12)
"""Newton to 1e-12 m, so that the finite differences' noise (tolerance / step) stays below 1e-7
of the derivatives."""
DAMPING_TIME = 0.01
"""τ (s) of the damped batch."""
ADAPTIVE = dict(integrator="bdf2", adaptive=True, error_tol=1e-3, dt_max=1e-3, **TIGHT)
"""Adaptive BDF2 steps with dt_max = dt and a loose error_tol: every run, the replicas' instance
and the finite differences' alike, takes the same 100 steps of 1 ms over DURATION_S, so the
frozen step sequence is the one the differences see."""


@pytest.fixture(scope="module")
def euler_run(taichi_cpu):
    return simulate(BATCH, DURATION_S, SolverConfig(**TIGHT), record_interval_s=0.05,
                    record_shapes=True, sensitivities=DIRECTIONS)


def test_euler_sensitivities_equal_finite_differences(arch, matches_differences):
    # measured 1.0e-8 at most (C⊥ of A1+A3; α 4.7e-9; the extrapolated difference's own
    # truncation and the Newton noise of the runs): 1e-7, 10×
    matches_differences(check_sensitivities(BATCH, DURATION_S, SolverConfig(**TIGHT),
                                                   ("alpha", "drag_perpendicular"), arch=arch),
                               1e-7)


def test_the_stiffness_matches_its_differences(taichi_cpu, matches_differences):
    """E moves the elastic terms' stiffnesses alone, which their forces are linear in: its
    pairs leave those terms out and the tangent step adds their difference at the instance's
    state (`Term.linear_coefficients`)."""
    # measured 2.5e-7 at most (2.1e-7 with the replicas computing the elastic forces: the
    # whole runs' differences' own error, E's derivative ~1e-10 mm/Pa): 1e-6, 4×
    matches_differences(check_sensitivities(BATCH, DURATION_S, SolverConfig(**TIGHT),
                                            ("youngs_modulus",)), 1e-6)


def test_a_coast_after_the_pulse_keeps_its_sensitivities(taichi_cpu, matches_differences):
    """Over 0.84 s the A1 robot coasts after its pulse: many rod-edge velocity components creep
    past zero, within a replica pair's ε·v̇ of it, for many steps. A pair differencing the drag
    |v|·v across its kink there got an error ε²-small per step that built up (measured when
    the replicas used their own |v|·v: 2.1e-5 here, 1.3e-2 after 2.1 s; taking their
    instance's side of the kink: 8e-8 here; expanding the drag about the instance's velocity,
    `Assembly.primal_instance`: 5e-9)."""
    # measured 6.2e-9: 1e-7, 16× (and 1/200 of the error of a pair across the kink)
    matches_differences(check_sensitivities([BASE.replace(gait="A1")], 0.84,
                                                   SolverConfig(**TIGHT), ("alpha",)), 1e-7)


@pytest.mark.slow
def test_a_glide_does_not_drift_the_tangents_rigid_motion(taichi_cpu, matches_differences):
    """With damping (the stiffness blocks ×(1 + τ/h)) and the rods' linear drag (a long glide),
    the Jacobian's column sums over the stiffness blocks keep a rounding that repeats from step
    to step while the shape is still, and the tangent's rigid-body velocity drifts unless the
    tangent step corrects its rigid motion (`BatchEngine.rigid_correction`). Over 2.2 s of
    A1+A2, α's derivative of the displacement off the extrapolated differences, with and
    without the correction (mutant M14 of tools/engine_mutants.py), measured since Newton stops
    only on an update within newton_tol (2026-12): at newton_tol 1e-11 m 6.8e-10 and 1.0e-7;
    at 1e-10 6.1e-8 and 2.4e-7, at 1e-12 4.8e-8 and 2.3e-8, at 1e-13 8.4e-9 and 1.4e-7 (the
    differences' own spread 1.5e-8 to 2.8e-8): the rounding of 2.2 s of tight solves moves the
    tangent by up to ~5e-8, and the drift stands clear of it at 1e-11 m (at 1e-12 it did
    before the rule changed: 1.4e-9 and 1.0e-7). 2e-8 sits between the two there."""
    glide = [BASE.replace(gait="A1+A2", damping_time=DAMPING_TIME, linear_drag=1.0)]
    table = check_sensitivities(glide, 2.2, SolverConfig(newton_tol=1e-11), ("alpha",))
    matches_differences(table, tolerance=2e-8)


def test_c_parallel_takes_its_own_step_and_then_matches_its_differences(taichi_cpu, matches_differences):
    """C∥ barely moves the robot, so at an ε of 1e-5 of the value its replicas' offsets are a
    few thousand roundings of a position: here its derivative was 4e-4 and 3.6e-3 off, with
    Taylor ratios of 2.0 (measured). At its own ε, 1e-2 of the value, 2.2e-7 and 1.8e-6,
    ratios 3.9 and 4.5."""
    (direction,) = parse_directions(["drag_parallel"])
    assert direction.step(BASE) == pytest.approx(1e-2 * BASE.drag_parallel, rel=1e-15)
    assert difference_step(direction, BASE) == direction.step(BASE)
    # 1e-5: the target, 5× the larger measured error (2.0e-6)
    matches_differences(check_sensitivities(BATCH, DURATION_S, SolverConfig(**TIGHT),
                                                   ("drag_parallel",)), 1e-5)


@pytest.mark.slow  # suite time (7 s); the linear coefficients' steps stay in the unit tests
def test_the_cylinders_drag_takes_its_own_step_and_then_matches_its_differences(
        taichi_cpu, matches_differences):
    """The hub's drag coefficient C_c barely moves the robot: a coarse A1 robot at C_c = 10,
    over 0.687 s, was 1.05e-5 off its extrapolated differences at the default ε of 1e-4 of the
    value (Taylor ratio 3.94; a fuzz audit), beyond the 1e-5 held to. At its own ε, 1e-2 of
    the value, 1.5e-8 (ratio 4.00), measured."""
    (direction,) = parse_directions(["cylinder_drag"])
    robot = BASE.replace(gait="A1", cylinder_drag=10.0, n_arc=6, n_limb=2)
    assert direction.step(robot) == pytest.approx(1e-2 * 10.0, rel=1e-15)
    # 1.5e-7: 10× the measured error, 70× below the default step's
    matches_differences(check_sensitivities([robot], 0.687, SolverConfig(**TIGHT),
                                            ("cylinder_drag",)), 1.5e-7)


# suite time (~4 s beside the engines it shares): its step's rule stays in the unit tests
# (test_sensitivity_parts), τ's derivative against its differences in the default tier at
# τ = 0 (below) and damped adaptive BDF2 sensitivities in test_bdf2_with_damping_chord_...
@pytest.mark.slow
def test_the_damping_time_takes_its_own_step_and_then_matches_its_differences(taichi_cpu, matches_differences):
    """τ barely moves the robot, so at the default ε of 1e-4 of its value its replicas are near
    the rounding of the positions: on the damped batch and adaptive BDF2 steps of the test
    below (whose engines this one shares), A1+A2's derivative was 1.7e-5 off (Taylor ratio
    4.0; measured), beyond the 1e-5 held to. At its own ε, 1e-3 of the value, 2.6e-7 and
    1.8e-6 (ratios 3.8 and 4.0); with implicit Euler over 0.3 s at τ = 0.94 ms the default
    was 1.2e-5 off, over three cycles 2.6e-4 (docs: numerics)."""
    (direction,) = parse_directions(["damping_time"])
    damped = [p.replace(damping_time=DAMPING_TIME) for p in BATCH]
    assert direction.step(damped[0]) == pytest.approx(1e-3 * DAMPING_TIME, rel=1e-15)
    # 1e-5: the target, 5.6× the larger measured error (1.8e-6)
    matches_differences(check_sensitivities(damped, DURATION_S, SolverConfig(**ADAPTIVE),
                                                   ("damping_time",)), 1e-5)


def test_the_damping_time_at_zero_matches_its_differences(taichi_cpu):
    """At τ = 0 the pair straddles the damping's switch: its +ε replica is damped, its −ε one
    not. Each replica must leave the same terms out of the pair's difference (the elastic
    ones: neither may, since the damped one reads the step's start through them); when the −ε
    replica left them out alone, the derivative came out ~2,000 times the differences
    (measured, 0.2 s). Only the relative error is held here: the Taylor test's steps lie on
    the damped side alone, where the run has a kink at τ = 0 to its left."""
    table = check_sensitivities(BATCH, DURATION_S, SolverConfig(**TIGHT), ("damping_time",))
    assert (table["value"] == 0.0).all() and np.isfinite(table["relative_error"]).all(), table
    # 1e-5: the target; measured 1.3e-7 and 8.4e-7 over 0.2 s
    assert (table["relative_error"] <= 1e-5).all(), table


@pytest.mark.parametrize("field, tolerance", [("drag_perpendicular", 1e-7),
                                              ("fluid_density", 1e-6)])
def test_a_derivative_does_not_depend_on_the_replicas_step(taichi_cpu, monkeypatch, field,
                                                           tolerance):
    """The replicas expand the drags and the jet about their instance's velocity
    (`Assembly.primal_instance`), so their residuals are linear in their offsets, and a pair's
    difference depends on ε only through terms of order ε² relative (products of the
    coefficients' offsets with the quadratic part of the states', as in the jet's areas). Over
    0.3 s of the A1+A2 and A1+A3 pulses (the jet switches off as the spaces reopen, velocity
    components cross zero), ε = 1e-3 and 1e-2 of the value give derivatives of the
    displacement 6e-10 (C⊥) and 1.3e-7 (ρ_f, whose derivative here is small: an ε² term of
    1.3e-3 relative at 1e-2) apart, measured; replicas with their own |v|·v and Ṡ² (before
    the expansion) were 6e-3, 7e-3 (C⊥) and 1.6e-2, 6.1e-2 (ρ_f) apart. The tolerances: about
    8× the measured differences, far below the former ones."""
    derivatives = []
    for step in (1e-3, 1e-2):
        monkeypatch.setitem(sensitivities.FIELD_RELATIVE_STEPS, field, step)
        run = simulate(BATCH, 0.3, SolverConfig(), sensitivities=(field,))
        derivatives.append(run.sensitivity("displacement_x_mm", field))
    np.testing.assert_allclose(derivatives[1], derivatives[0], rtol=tolerance)


def test_a_delays_derivative_does_not_depend_on_the_replicas_step(taichi_cpu, monkeypatch):
    """A replica expands the actuation profile in its delay about its instance's
    (`Bending.actuator_curvature`): the profile is steep (heating over ~16 ms) and jumps by
    0.0064 1/m at its switch, and a pair at ±ε straddles that switch for the steps that end
    within ε of it. With delays of 50.5 ms (the switch, 0.2135 s after the firing, off the 1-ms
    grid), over 0.3 s, ε = 1e-3 and 1e-2 of the delay give the same derivatives to 3e-8
    (measured; the expansion is linear in the delay's offset, what is left is rounding); without
    it they were 4.7e-4 apart. 1e-7: three times the measured difference."""
    delays = (0.0505, 0.0505, 0.0505, 0.0, 0.0, 0.0, 0.0, 0.0)
    batch = [p.replace(actuator_delays=delays) for p in BATCH]
    labels = ("actuator_delays[0]", "actuator_delays[1]")
    derivatives = []
    for step in (1e-3, 1e-2):
        monkeypatch.setitem(sensitivities.FIELD_RELATIVE_STEPS, "actuator_delays", step)
        run = simulate(batch, 0.3, SolverConfig(), sensitivities=labels)
        derivatives.append([run.sensitivity("displacement_x_mm", label) for label in labels])
    np.testing.assert_allclose(derivatives[1], derivatives[0], rtol=1e-7)


def test_the_inflow_at_zero_has_a_zero_derivative(taichi_cpu):
    """The inflow force is α_in²-flat at α_in = 0 (the paper's model): its derivative there is
    0, exactly, though a replica pair at ±ε would draw water in on its + side only (its
    − side has no inflow at all) unless the replicas follow their instance, which has none."""
    run = simulate(BATCH, DURATION_S, SolverConfig(), sensitivities=("jet_inflow",))
    for output in SUMMARY_OUTPUTS:  # the steady speeds are NaN over so short a run
        values = run.sensitivity(output, "jet_inflow")
        assert not np.any(values[np.isfinite(values)]), output
    assert np.all(run.sensitivity("displacement_x_mm", "jet_inflow") == 0.0)
    # a pulse and a coast do move the robot: the zero is not for want of motion
    assert np.all(np.abs(run.summary["displacement_x_mm"]) > 1e-3)


@pytest.mark.slow      # suite time; its steps' rule stays in the default tier (below)
def test_a_joint_radius_near_its_arc_bound_keeps_its_steps_inside_it(taichi_cpu,
                                                                   matches_differences):
    """The joint radius's range ends (excluded) where an actuator arc of the profile's rest
    curvature stops reaching from joint to joint; the arc's geometry is a square root of the
    gap. 1e-3 and 1.5e-4 of the value below it, the replicas' tables at ±2ε and the Taylor
    test's runs at 2H crossed it (the derivative 17 times the differences at 1.5e-4, over
    0.2 s: an audit, 2026-12); ε is now held to 1e-2 of the gap
    (`sensitivities.EXCLUDED_END_SHARE`), H to a quarter of it."""
    arc_bound = BASE.allowed_range("joint_radius")[1]
    assert BASE.allowed_range("joint_radius")[3] is False          # excluded
    batch = [BASE.replace(gait="A1+A2", joint_radius=radius, tip_radius=radius + 0.028)
             for radius in (arc_bound * (1 - 1e-3), arc_bound * (1 - 1.5e-4))]
    # measured 9.5e-9 and 3.0e-8, the Taylor ratios 4.79 (the square root's higher orders):
    # 1e-6, 30×
    matches_differences(check_sensitivities(batch, DURATION_S, SolverConfig(**TIGHT),
                                            ("joint_radius",)), 1e-6)


def test_near_its_arc_bound_the_joint_radius_takes_a_hundredth_of_the_gap():
    """The rule of the test above: ε is 1e-2 of the distance to the arc bound there, and the
    joint radius's own ε far from it."""
    arc_bound = BASE.allowed_range("joint_radius")[1]
    batch = [BASE.replace(joint_radius=radius, tip_radius=radius + 0.028)
             for radius in (arc_bound * (1 - 1e-3), arc_bound * (1 - 1.5e-4))]
    (direction,) = parse_directions(("joint_radius",))
    for params in batch:
        assert direction.step(params) == pytest.approx(
            1e-2 * (arc_bound - params.joint_radius), rel=1e-9)
    # far from it, ε's own rule (the paper's joint radius lies 6 % below the bound)
    assert direction.step(BASE) == pytest.approx(1e-4 * BASE.joint_radius, rel=1e-15)


def test_the_allowed_range_is_the_one_validation_holds_values_to():
    """`StarParams.allowed_range` states the range `__post_init__` checks: each end taken or
    refused as it says, for the three fields other fields narrow."""
    for name in ("joint_radius", "tip_radius", "period"):
        lowest, highest, lowest_included, highest_included = BASE.allowed_range(name)
        for end, included in ((lowest, lowest_included), (highest, highest_included)):
            if included:
                assert getattr(BASE.replace(**{name: end}), name) == end
            else:
                with pytest.raises(ValueError, match=name):
                    BASE.replace(**{name: end})
    assert BASE.allowed_range("tip_radius")[0] == BASE.joint_radius
    assert BASE.allowed_range("period")[0] == BASE.actuator_profile.switch_time


def test_the_taylor_step_is_a_hundred_differences_steps_at_most_a_tenth_of_the_value():
    assert taylor_step(1e-5, 1.0) == pytest.approx(1e-3, rel=1e-15)
    assert taylor_step(1e-3, 1.0) == pytest.approx(0.1, rel=1e-15)  # both rules: equal
    assert taylor_step(2e-3, 1.0) == pytest.approx(0.1, rel=1e-15)  # a tenth of the value
    assert taylor_step(2e-3, -1.0) == pytest.approx(0.1, rel=1e-15)
    assert taylor_step(2e-3, 0.0) == pytest.approx(0.2, rel=1e-15)  # at 0: no value to bound
    # a quarter of the distance to an excluded end at most, where that is the nearest bound
    assert taylor_step(1e-5, 1.0, gap=1e-3) == pytest.approx(2.5e-4, rel=1e-15)
    assert taylor_step(1e-5, 1.0, gap=4e-3) == pytest.approx(1e-3, rel=1e-15)  # both: equal
    assert taylor_step(1e-5, 1.0, gap=1.0) == pytest.approx(1e-3, rel=1e-15)
    # a field with a least ε (the water's τ_w, 1e-6 s): at least 30 of those where a tenth of
    # the value is less, a tenth of the value where that is more, and never past 100·h
    assert taylor_step(1e-6, 1e-9, least=1e-6) == pytest.approx(3e-5, rel=1e-15)
    assert taylor_step(1e-6, 3e-4, least=1e-6) == pytest.approx(3e-5, rel=1e-15)  # both
    assert taylor_step(1e-6, 1e-3, least=1e-6) == pytest.approx(1e-4, rel=1e-15)
    assert taylor_step(1e-7, 1e-9, least=1e-6) == pytest.approx(1e-5, rel=1e-15)
    # each field's least ε: a delay's is its ε at 0 (it was left out: a review, 2026-12), a
    # linear field's that of its usual scale, τ_w's its own, and a geometry field has none
    least = {name: parse_directions((name,))[0].least_step(BASE) for name in (
        "actuator_delays[0]", "drag_perpendicular", "wake_time", "thickness")}
    assert least == pytest.approx({"actuator_delays[0]": 1e-4 * 0.01 * BASE.period,
                                   "drag_perpendicular": 1e-4 * 1.0, "wake_time": 1e-6,
                                   "thickness": 0.0}, rel=1e-15)


def test_a_joint_radius_just_inside_its_tip_radius_keeps_its_steps_inside_it():
    """The tip radius's lower end (excluded) is the joint radius: a joint radius 1e-7 m inside
    it took ε = 2.4e-6 m, its replicas' limbs of negative length (a review, 2026-12). ε is
    held to 1e-2 of the nearest excluded end of a range the parameter bounds, its own or
    another field's; the tip radius's own is the same gap."""
    (joint,) = parse_directions(("joint_radius",))
    (tip,) = parse_directions(("tip_radius",))
    close = BASE.replace(tip_radius=BASE.joint_radius + 1e-7)
    gap = close.tip_radius - close.joint_radius
    assert joint.step(close) == pytest.approx(1e-2 * gap, rel=1e-12)
    assert tip.step(close) == pytest.approx(1e-2 * gap, rel=1e-12)
    # far from every excluded end, ε's own rule (the paper's limbs are 28 mm long)
    assert tip.step(BASE) == pytest.approx(1e-4 * BASE.tip_radius, rel=1e-15)


@pytest.mark.slow      # suite time; `test_a_small_coefficients_step_is_its_usual_scales` stays
def test_a_coefficient_far_below_its_usual_value_takes_the_usual_values_step(
        taichi_cpu, matches_differences):
    """ε = 1e-4 of a coefficient far below its usual value (C∥ at 1e-5, the hub's linear drag at
    1e-4, A1's gain at 1e-3) moved the replicas by less than the positions' rounding: up to
    1.8e-3 off the differences, Taylor ratios of 2 (an audit, 2026-12). The residual is linear
    or quadratic in such a field (`sensitivities.LINEAR_FIELDS`), so the pair differences it
    exactly at any ε: it takes the ε of its usual scale. Measured here at most 1.6e-6 (C∥;
    the others within 2.7e-7): 1e-5, the target (the hub's linear drag, measured 1.7e-8, is
    left to the audit's record: suite time)."""
    small = [BASE.replace(gait="A1+A2", drag_parallel=1e-5),
             BASE.replace(gait="A1+A2", actuator_gains=(1e-3,) + BASE.actuator_gains[1:])]
    names = ("drag_parallel", "actuator_gains[0]")
    matches_differences(check_sensitivities(
        small, DURATION_S, SolverConfig(integrator="bdf2", **TIGHT), names), 1e-5)


def test_a_small_coefficients_step_is_its_usual_scales():
    """The rule of the test above, and that no preset's ε changes by it: the usual scale lies
    at or below every preset's value of every field in LINEAR_FIELDS."""
    small = [BASE.replace(drag_parallel=1e-5),
             BASE.replace(actuator_gains=(1e-3,) + BASE.actuator_gains[1:])]
    for direction, params in zip(parse_directions(("drag_parallel", "actuator_gains[0]")),
                                 small):
        assert direction.step(params) == direction.relative_step * direction.usual_scale()
        assert direction.step(params) > 10 * direction.relative_step * direction.value(params)
    for preset in ("paper", "accurate", "identified"):
        params = StarParams.preset(preset)
        for direction in parse_directions(sorted(sensitivities.LINEAR_FIELDS)):
            value = abs(direction.value(params))
            if value:
                assert direction.step(params) == direction.relative_step * value


@pytest.mark.parametrize("gain, inwards", [
    (5.0, True),           # at the top (included): the runs at +H and +2H would leave it
    (4.9, False),          # +2H = 5.0 exactly: on the top, allowed
    (4.9000001, True),     # +2H just past it
    (1.0, False)])
def test_the_taylor_test_steps_inward_at_the_top_of_a_range(gain, inwards):
    """Past A1's top gain, 5, the model turns (the displacement's slope flips between 5.020 and
    5.028), and the Taylor runs at 5.05 and 5.10 gave ratios of 0.8–1.1 for a derivative right
    within 1e-9 (an audit, 2026-12): the Taylor step is taken inward where +2H would leave the
    range and −2H would not."""
    (direction,) = parse_directions(("actuator_gains[0]",))
    params = BASE.replace(actuator_gains=(gain,) + BASE.actuator_gains[1:])
    assert inward(direction, params, 0.05) == (-0.05 if inwards else 0.05)


@pytest.mark.parametrize("exchange_time, forward", [
    (1e-9, True), (3.9e-6, True),
    (4e-6 + 1.001e-9, False),  # its −4h run just above the range's lowest, 1e-9 s: central
    (4e-6 + 0.999e-9, True),   # just below it: forward
    (1.0, False)])
def test_a_field_with_a_least_step_is_differenced_forward_where_it_would_leave_its_range(
        exchange_time, forward):
    """`check_sensitivities`' runs at −h, −2h and −4h of τ_w (ε at least 1e-6 s) went below
    the range, to −4e-6 s at 1e-9 s, where on steps of a few µs the force's pole at
    γ·τ_w = −1 failed the runs (a review, 2026-12): such rows are differenced forward. Other
    fields at 0 are still differenced centrally through their negative values."""
    (direction,) = parse_directions(("wake_time",))
    watered = BASE.replace(wake_coupling=30.0, wake_time=exchange_time)
    assert difference_step(direction, watered) == pytest.approx(
        max(1e-6, 1e-4 * exchange_time), rel=1e-15)
    assert one_sided(direction, watered) is forward
    (alpha,) = parse_directions(("alpha",))
    assert one_sided(alpha, BASE.replace(alpha=0.0)) is False


def test_an_actuator_the_gait_never_fires_has_no_influence(euler_run, matches_differences):
    gains = euler_run.sensitivity("displacement_x_mm", "actuator_gains[1]")
    # A1+A3 never fires A2: its replicas differ only in a coefficient no kernel reads
    assert gains[1] == 0.0
    # measured 7.2e-10: 1e-8, 14×
    matches_differences(check_sensitivities(BATCH[:1], DURATION_S, SolverConfig(**TIGHT),
                                                   ("actuator_gains[1]",)), 1e-8)


def test_bending_reads_an_actuators_gain_and_delay_only_once_it_has_fired(taichi_cpu):
    """What `Bending.fired_columns` declares, and the engine's skipping of a waiting pair's
    tangent rests on: the gains and delays of actuators that never fire change no bit."""
    other = BASE.replace(gait="A1", actuator_gains=(1.0,) + (1.7,) * 7,
                         actuator_delays=(0.0,) + (0.01,) * 7)
    runs = simulate([BASE.replace(gait="A1"), other], DURATION_S, record_interval_s=0.05,
                    record_shapes=True)
    np.testing.assert_array_equal(runs.shapes[:, 0], runs.shapes[:, 1])  # (records, B, N, 2)


def test_a_direction_waiting_for_its_actuator_wakes_exact_when_it_fires(taichi_cpu):
    """The pair of A2's gain or delay waits (no tangent work) while A2 has never fired, with
    its derivative exactly zero, and takes it up from the step A2 first fires: then it equals
    central differences of whole runs."""
    from taichi_star import Simulator

    params = BASE.replace(gait="A1+A2", actuator_delays=(0.0, 0.0005) + (0.0,) * 6)
    solver = SolverConfig(**TIGHT)

    def run(p, directions=()):
        simulator = Simulator([p], solver, sensitivities=directions)
        simulator.fire(["A1"])
        simulator.advance(0.04)
        early = [simulator.sensitivity("centroid_x_mm", name)[0] for name in directions]
        simulator.fire(["A2"])
        simulator.advance(0.06)
        if directions:
            return early, [simulator.sensitivity("centroid_x_mm", name)[0]
                           for name in directions]
        return simulator.state()["centroid_x_mm"].to_numpy()[0]

    early, late = run(params, ("actuator_gains[1]", "actuator_delays[1]"))
    assert early == [0.0, 0.0]
    for value, (field, step) in zip(late, [("actuator_gains", 1e-3), ("actuator_delays", 1e-6)]):
        moved = [list(getattr(params, field)) for _ in range(2)]
        moved[0][1] += step
        moved[1][1] -= step
        difference = (run(params.replace(**{field: tuple(moved[0])}))
                      - run(params.replace(**{field: tuple(moved[1])}))) / (2 * step)
        # measured 5.4e-8 (the gain) and 5.0e-8 (the delay): the differences' truncation and
        # Newton noise; 1e-6, ~20x. A pair that woke a step late is off by 1.8e-5 in the delay
        # (2.8e-7 only in the gain, whose profile has barely moved after one step: an audit,
        # 2026-12); that it keeps every bit: the test below
        assert value != 0.0 and value == pytest.approx(difference, rel=1e-6), field


def test_waiting_pairs_keep_every_bit_of_pairs_that_do_not_wait(taichi_cpu, monkeypatch):
    """The same Simulator run (A1 fired at 0, A2 at 0.04 s, a reset of one robot and a
    re-fire) with the pairs of A2's and A4's gains and delays waiting and with no pair waiting
    (`replica_waiting` made to find none): the same bits in every sensitivity and state."""
    from taichi_star import Simulator
    from taichi_star.engine import BatchEngine

    params = [BASE.replace(gait="A1+A2", actuator_delays=(0.0, 0.0005) + (0.0,) * 6),
              BASE.replace(gait="A1+A3", alpha=1.2)]
    names = ("actuator_gains[1]", "actuator_delays[1]", "actuator_gains[3]", "alpha")

    def run():
        simulator = Simulator(params, SolverConfig(**TIGHT), sensitivities=names)
        simulator.fire(["A1", "A1"])
        simulator.advance(0.04)
        simulator.fire(["A2", "A3"])
        simulator.advance(0.03)
        simulator.reset([1])
        simulator.fire(["A1", "A1+A3"])
        simulator.advance(0.03)
        return ([simulator.sensitivity(column, name) for column in ("centroid_x_mm", "heading_deg")
                 for name in names], simulator.state())

    waiting, waiting_state = run()
    monkeypatch.setattr(BatchEngine, "replica_waiting",
                        lambda self, model, primal_count: np.full(self.capacity, -1, np.int32))
    moving, moving_state = run()
    for with_waiting, without in zip(waiting, moving):
        np.testing.assert_array_equal(with_waiting, without)
    pd.testing.assert_frame_equal(waiting_state, moving_state, check_exact=True)
    # the A4 pairs waited throughout: exactly zero
    assert not waiting[2].any() and not waiting[6].any()


@pytest.mark.parametrize("jacobian", ["newton", "lagged"])
def test_pairs_that_add_their_difference_agree_with_replicas_computing_it(
        taichi_cpu, monkeypatch, jacobian):
    """Where a pair's drag coefficients are its instance's (here α's and E's), both replicas
    leave the rod drag out of their residuals and the tangent step adds the pair's difference
    from the ∂F/∂v the instance kept (`Term.pairs_linearly`); where they differ in the drag
    coefficients alone (C⊥'s), it adds the drag with their difference as well, and where the
    stiffnesses alone differ (E's), the elastic terms' gradients with it
    (`Term.linear_coefficients`): the same sensitivities, to the rounding of sums taken in
    another order, as with every replica computing every term (`replica_sameness` made to
    find no pair like its instance in the drag, nor any whose stiffnesses alone differ)."""
    from taichi_star.engine import LINEAR_IN_DIFFERENCE, SAME_AS_INSTANCE, BatchEngine

    params = [BASE.replace(gait="A1+A3", drag_perpendicular=1.2),
              BASE.replace(gait="A1+A3+A5", alpha=1.1)]
    names = ("alpha", "drag_perpendicular", "youngs_modulus")
    columns = [sensitivity_column(output, name) for output in SUMMARY_OUTPUTS for name in names]
    seen = []
    found = BatchEngine.replica_sameness

    def recorded(self, model, primal_count):
        same = found(self, model, primal_count)
        seen.append((same, [term.name for term in self.terms]))
        return same

    def computed(self, model, primal_count):
        same = found(self, model, primal_count)
        same[:, [term.name for term in self.terms].index("rod_drag")] = 0
        same[same == LINEAR_IN_DIFFERENCE] = 0
        return same

    def run(sameness):
        monkeypatch.setattr(BatchEngine, "replica_sameness", sameness)
        result = simulate(params, 0.06, SolverConfig(jacobian=jacobian, **TIGHT),
                          sensitivities=names, record_interval_s=0.02)
        return result.sensitivities[columns], result.trajectory_sensitivities

    paired_summary, paired_path = run(recorded)
    same, terms = seen[-1]
    # rows: the 2 instances, α's +ε and −ε replicas, then C⊥'s, then E's
    equal, linear = SAME_AS_INSTANCE, LINEAR_IN_DIFFERENCE
    by_direction = {"rod_drag": [equal, linear, equal], "stretching": [equal, equal, linear],
                    "bending": [equal, equal, linear]}
    for term, values in by_direction.items():
        assert same[:14, terms.index(term)].tolist() == [0, 0] + np.repeat(values, 4).tolist()
    computed_summary, computed_path = run(computed)
    positions = [column for column in paired_path if "heading" not in column] + [
        sensitivity_column(output, name) for output in SUMMARY_OUTPUTS[:4] for name in names]
    for paired, reference in ((paired_summary, computed_summary), (paired_path, computed_path)):
        pd.testing.assert_frame_equal(paired.isna(), reference.isna())  # the steady speeds
        # α's and C⊥'s, rounding apart: each difference within 1e-9 of its output's largest
        # derivative. Over this window they are the same bits (a replica's position q* ± ε·q̇
        # rounds off the last bits of the tangent); over a second of the five Fig. 4c gaits
        # the drag's pairs moved by up to 1.3e-8 relative (C⊥) and 5.8e-8 (C∥)
        drag = [column for column in reference if "youngs_modulus" not in column]
        bound = 1e-9 * reference[drag].abs().max().fillna(0.0)
        assert ((paired[drag] - reference[drag]).abs().fillna(0.0) <= bound).all().all()
        # E's: the replicas' difference of the elastic forces, ~1e6 times the drag's and
        # nearly balanced at each node, keeps their rounding over ε: measured up to 9e-7 of
        # the largest derivative here (paired, no ε, exact), 9.4e-8 over a second of the five
        # gaits; both within the whole runs' differences (2.5e-7 and 2.1e-7 off them over
        # 0.1 s of A1+A2 and A1+A3): 5e-6. Headings and travel directions left out: along E
        # they are rounding (~1e-17 deg/Pa, where the displacements' are ~1e-10 mm/Pa)
        stiffness = [column for column in reference
                     if "youngs_modulus" in column and column in positions]
        bound = 5e-6 * reference[stiffness].abs().max()
        assert ((paired[stiffness] - reference[stiffness]).abs() <= bound).all().all()
    for name in names:  # every tangent moved (A1+A3+A5 along y, A1+A3 along x)
        moved = np.hypot(paired_summary[sensitivity_column("displacement_x_mm", name)],
                         paired_summary[sensitivity_column("displacement_y_mm", name)])
        assert (moved > 1e-3 * moved.max()).all()


def test_the_instances_rows_are_those_of_a_run_without_sensitivities(euler_run):
    plain = simulate(BATCH, DURATION_S, SolverConfig(**TIGHT), record_interval_s=0.05)
    for column in SUMMARY_OUTPUTS:
        # the replicas ride in the same engine but never touch an instance's arithmetic
        assert np.array_equal(plain.summary[column].to_numpy(), euler_run.summary[column].to_numpy(),
                              equal_nan=True), column
    assert plain.trajectory.equals(euler_run.trajectory)
    # the timing counts the instances' steps, not their replicas' (moved, never solved)
    assert euler_run.timing.robot_steps == plain.timing.robot_steps == plain.summary["steps"].sum()


def test_trajectory_sensitivities_start_at_zero_and_end_at_the_displacements(euler_run):
    dx = euler_run.sensitivity("x_mm", "alpha")
    assert dx.shape == (2, 3)
    # x_mm is relative to the start: its derivative is exactly 0 there
    assert np.all(dx[:, 0] == 0.0)
    # the last record is the end of the run: the same difference of the same centroids
    np.testing.assert_allclose(dx[:, -1], euler_run.sensitivity("displacement_x_mm", "alpha"),
                               rtol=1e-12)


def test_a_bad_output_is_named_before_the_parameter(euler_run):
    """Arguments swapped, an unknown output, a summary output asked of the trajectory: each
    error names the output, listing each allowed one once."""
    with pytest.raises(ValueError, match=r"^output must be one of \[.*\], got 'alpha'$") as error:
        euler_run.sensitivity("alpha", "signed_speed_mm_s")
    listed = str(error.value).split("[", 1)[1].split("]", 1)[0].split(", ")
    assert len(listed) == len(set(listed)) and "'heading_deg'" in listed
    with pytest.raises(ValueError, match=r"^output 'signed_speed_mm_s' is a summary output"):
        euler_run.sensitivity("signed_speed_mm_s", "alpha", trajectory=True)
    # a text for the flag: named as such (it had been read as True, and the output blamed)
    with pytest.raises(ValueError, match=r"^trajectory must be True or False, got 'yes'$"):
        euler_run.sensitivity("speed_mm_s", "alpha", "yes")
    assert np.array_equal(euler_run.sensitivity("heading_deg", "alpha", np.bool_(True)),
                          euler_run.sensitivity("heading_deg", "alpha", trajectory=True))


def test_a_per_actuator_field_gives_one_column_per_actuator(euler_run):
    # only [1] was run: the error names the argument as given (`parameter`, not simulate's
    # `sensitivities`) and lists what the run has
    run_has = "['alpha', 'actuator_gains[1]', 'drag_perpendicular']"
    for output, parameter, message in (
            ("displacement_x_mm", "actuator_gains",
             f"parameter 'actuator_gains' was not among this run's sensitivities {run_has}"),
            ("x_mm", "thickness",
             f"parameter 'thickness' was not among this run's sensitivities {run_has}"),
            ("displacement_x_mm", "period", "parameter: 'period' is not differentiable"),
            ("displacement_x_mm", 3, "parameter must be a StarParams field name, got 3")):
        with pytest.raises(ValueError, match="^" + re.escape(message)):
            euler_run.sensitivity(output, parameter)
    table = euler_run.sensitivities
    assert sensitivity_column("signed_speed_mm_s", "actuator_gains[1]") in table
    assert len(table) == len(BATCH)


def test_bdf2_with_damping_chord_and_adaptive_steps(arch, matches_differences):
    batch = [dataclasses.replace(p, damping_time=DAMPING_TIME) for p in BATCH]
    table = check_sensitivities(batch, DURATION_S, SolverConfig(jacobian="chord", **ADAPTIVE),
                                ("alpha", "drag_perpendicular"), arch=arch)
    steps = simulate(batch, DURATION_S, SolverConfig(**ADAPTIVE), arch=arch).summary["steps"]
    assert (steps == 100).all()
    # measured 3.8e-8 at most (C⊥ of A1+A2; α 3.0e-8): 4e-7, 11×
    matches_differences(table, 4e-7)


def test_the_lagged_jacobian_gets_the_exact_tangent_too(taichi_cpu, matches_differences):
    """The tangent's Jacobian is assembled and factored at each converged step whatever the
    forward iteration used (and the lagged Jacobian's next step starts with it), so the
    sensitivities match the differences of whole lagged runs as Newton's do (measured
    2.0e-8 at newton_tol 1e-12 m; held to 2e-7, 10×)."""
    table = check_sensitivities(BATCH, DURATION_S, SolverConfig(jacobian="lagged", **TIGHT),
                                ("alpha", "drag_perpendicular"))
    matches_differences(table, 2e-7)


@pytest.mark.parametrize("names, message", [
    (("alpah",), "did you mean alpha"),
    (("gait",), "not differentiable"),
    (("period",), "not differentiable"),
    (("n_arc",), "not differentiable"),
    (("actuator_gains[8]",), r"actuator index in \[0, 7\]"),
    (("alpha", "alpha"), "named twice"),
    ("alpha", "sequence of StarParams field names"),
])
def test_bad_names_are_refused_before_any_compute(names, message):
    with pytest.raises(ValueError, match=message):
        simulate(BATCH, DURATION_S, sensitivities=names)


def test_f32_and_an_unset_component_height_are_refused():
    with pytest.raises(ValueError, match="precision 'f64'"):
        simulate(BATCH, DURATION_S, SolverConfig(precision="f32", newton_tol=1e-7),
                 sensitivities=("alpha",))
    with pytest.raises(ValueError, match="hub_height is 0"):
        simulate(BATCH, DURATION_S, sensitivities=("hub_height",))


def test_a_whole_per_actuator_field_names_its_eight_numbers():
    directions = parse_directions(["actuator_delays", "alpha"])
    assert [d.label for d in directions] == [f"actuator_delays[{k}]" for k in range(8)] + ["alpha"]


def test_a_simulator_gives_the_same_sensitivities_as_simulate(euler_run):
    from taichi_star import Simulator

    simulator = Simulator(BATCH, SolverConfig(**TIGHT), sensitivities=("alpha",))
    simulator.fire(["A1+A2", "A1+A3"])  # at t = 0: what simulate's periodic gait does
    simulator.advance(DURATION_S)
    # the same steps in the same order: the same bits up to the last rounding of the centroids
    np.testing.assert_allclose(simulator.sensitivity("centroid_x_mm", "alpha"),
                               euler_run.sensitivity("displacement_x_mm", "alpha"), rtol=1e-12)
    before = simulator.sensitivity("centroid_x_mm", "alpha")
    saved = simulator.save()
    simulator.reset([1])
    moved = simulator.sensitivity("centroid_x_mm", "alpha")
    # a reset instance is back at rest with its replicas: nothing has moved yet
    assert moved[1] == 0.0 and moved[0] == before[0]
    simulator.load(saved)  # the replicas are part of the saved state
    np.testing.assert_array_equal(simulator.sensitivity("centroid_x_mm", "alpha"), before)
    # a whole per-actuator field: named as given, then the first actuator missing
    for parameter, message in (
            ("drag_perpendicular", "parameter 'drag_perpendicular' is not among this "
                                   "Simulator's sensitivities ['alpha']"),
            ("actuator_gains", "parameter 'actuator_gains' is not among this Simulator's "
                               "sensitivities ['alpha'] (actuator_gains[0] is not)"),
            ("gait", "parameter: 'gait' is not differentiable")):
        with pytest.raises(ValueError, match="^" + re.escape(message)):
            simulator.sensitivity("centroid_x_mm", parameter)
    with pytest.raises(ValueError, match="column must be one of"):
        simulator.sensitivity("since_A1_s", "alpha")
    # a state of other parameters would carry tangents scaled by their ε: refused (derivatives
    # 1.8-6.3 % off before, no warning), the state unchanged
    other = Simulator([BATCH[0].replace(alpha=BATCH[0].alpha * 1.1), BATCH[1]],
                      SolverConfig(**TIGHT), sensitivities=("alpha",))
    unchanged = other.save().fields
    with pytest.raises(ValueError, match=r"^the saved state belongs to instances of other "
                                         r"parameters \(instance 0's alpha .*a Simulator with "
                                         r"sensitivities continues only its own parameters' "
                                         r"state"):
        other.load(saved, other_params=True)
    # nor one that records no parameters to compare (its header damaged or older)
    with pytest.raises(ValueError, match=r"^the saved state records no parameters: a Simulator "
                                         r"with sensitivities"):
        other.load(dataclasses.replace(saved, params=()), other_params=True)
    assert all(np.array_equal(other.save().fields[name], unchanged[name]) for name in unchanged)
    # nor does a Simulator of other sensitivities take it (its replicas are other directions')
    del other
    plain = Simulator(BATCH, SolverConfig(**TIGHT), sensitivities=("drag_perpendicular",))
    with pytest.raises(ValueError, match=r"^the saved state belongs to another engine \(.*"
                                         r"sensitivities\)"):
        plain.load(saved)


def test_steps_redone_with_substeps_are_followed(euler_run, matches_differences):
    # 20-ms steps with 4 Newton iterations at most: the pulse's steps fail and are redone in
    # substeps, which the replicas follow (and are restored with their instance between tries)
    solver = SolverConfig(dt=0.02, max_newton=4, **TIGHT)
    batch = BATCH[1:]
    result = simulate(batch, 0.2, solver, sensitivities=("alpha",))
    assert result.summary["substep_retries"].iloc[0] > 0
    table = check_sensitivities(batch, 0.2, solver, ("alpha",))
    moved = dataclasses.replace(batch[0], alpha=batch[0].alpha
                                + difference_step(parse_directions(["alpha"])[0], batch[0]))
    plus = simulate([moved], 0.2, solver).summary
    # the moved runs retry the same steps: the differences are those of one substep sequence
    assert plus["substep_retries"].iloc[0] == result.summary["substep_retries"].iloc[0]
    # measured 3.5e-9: 5e-8, 14×
    matches_differences(table, 5e-8)


FAILING_SOLVER = SolverConfig(dt=0.005, max_newton=3, max_substep_halvings=0)
"""5-ms steps, at most three Newton updates, no substeps: A1+A3+A5's first step fails."""
SWIMMING = BASE.replace(gait="A1+A2", youngs_modulus=1e5)
"""A softer robot that swims on under FAILING_SOLVER."""


@pytest.fixture(scope="module")
def failed_beside_swimming(taichi_cpu):
    """A1+A3+A5 (failing at its first step) beside SWIMMING, differentiated by alpha, 0.1 s
    under FAILING_SOLVER with its shapes recorded at every step end (5 ms)."""
    return simulate([BASE.replace(gait="A1+A3+A5"), SWIMMING], 0.1, FAILING_SOLVER,
                    sensitivities=("alpha",), record_interval_s=0.005, record_shapes=True)


def test_a_failed_instance_has_no_derivatives_and_leaves_its_neighbour_alone(
        failed_beside_swimming):
    """A1+A3+A5's first step fails and the instance is frozen; its replicas share its status,
    so every derivative of it is NaN (not its replicas' frozen offsets divided by 2ε). A softer
    A1+A2 beside it swims on and keeps exactly the derivatives of a run of its own."""
    both = failed_beside_swimming
    alone = simulate([SWIMMING], 0.1, FAILING_SOLVER, sensitivities=("alpha",))
    assert both.summary["status"].tolist() == ["newton_failed", "ok"]
    assert both.summary["failure_time_s"].iloc[0] == 0.005
    assert both.sensitivities.iloc[0].isna().all()
    moving = alone.sensitivity("displacement_x_mm", "alpha")
    assert np.isfinite(moving).all() and (moving != 0.0).all()
    np.testing.assert_array_equal(both.sensitivities.iloc[1].to_numpy(),
                                  alone.sensitivities.iloc[0].to_numpy())


def test_a_failed_instances_shapes_are_nan_from_its_failure_on(failed_beside_swimming):
    """A failed instance's recorded shapes are NaN from its failure time on, the record at
    that time included (its trajectory's rows are NaN there too), not its last good shape
    frozen; the shapes are of the instances asked for alone (not their replicas), and the
    neighbour's stay finite."""
    shapes = failed_beside_swimming.shapes
    assert shapes.shape[:2] == (21, 2)  # 0 to 0.1 s every 5 ms; the instances asked for
    times = failed_beside_swimming.trajectory.query("instance == 0")["t_s"].to_numpy()
    failed = times >= failed_beside_swimming.summary["failure_time_s"].iloc[0]
    assert failed.tolist() == [False] + [True] * 20  # the failure at the first step's end
    assert np.isnan(shapes[failed, 0]).all() and np.isfinite(shapes[~failed, 0]).all()
    assert np.isfinite(shapes[:, 1]).all()


def test_a_failed_instances_path_derivatives_are_nan_from_its_failure_on(failed_beside_swimming):
    """The derivatives of a failed instance's path are finite before its failure (the record at
    t = 0: 0) and NaN from it on; its replicas hold its failing step (until the fix the replicas
    kept a failing step of −1, read as a failure at −dt, and every record's derivative was NaN,
    t = 0 included: a review, 2026-12). The neighbour's stay finite."""
    both = failed_beside_swimming
    derivative = both.sensitivity("x_mm", "alpha")
    assert derivative.shape == (2, 21)
    assert derivative[0, 0] == 0.0 and np.isnan(derivative[0, 1:]).all()
    assert np.isfinite(derivative[1]).all()


def test_the_check_study_writes_what_it_measured(euler_run, tmp_path):
    import pandas as pd

    from studies.__main__ import main as studies_main

    assert studies_main(["sensitivity_check", "--quick", "--no-progress",
                         "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "sensitivity_check.csv")
    assert list(table["parameter"]) == ["alpha", "actuator_gains[0]"]
    # the derived columns are what their names say, from the same row's cells (written to 10
    # significant digits; the differences cancel ~2 of them)
    np.testing.assert_allclose(table["difference"],
                               (8 * table["difference_h"] - 6 * table["difference_2h"]
                                + table["difference_4h"]) / 3, rtol=1e-7)
    # (the error recomputed from two 10-digit cells is itself uncertain by ~1e-10 absolute,
    # which a relative error of ~1e-7 feels in its fourth digit)
    np.testing.assert_allclose(table["relative_error"],
                               (table["sensitivity"] - table["difference"]).abs()
                               / table["difference"].abs(), rtol=1e-4, atol=1e-9)
    # 0.02 s from rest moves the robot by ~1 µm: the differences keep fewer digits than over
    # 0.1 s (measured 3e-5)
    assert (table["relative_error"] <= 1e-4).all()
    assert (tmp_path / "sensitivity_check.png").stat().st_size > 0


def test_a_delay_on_the_step_grid_warns_and_one_off_it_is_differentiable(taichi_cpu, matches_differences):
    """The fitted profile's branches miss each other at the switch t0 = 0.163 s by `switch_jump`
    (K̄ just after minus just before). With A2's delay a whole number of 1-ms steps (0
    included) the switch lies on a step end and a run that reaches it jumps as the delay moves:
    a warning, for a gait that fires A2 only. Off the grid (12.3 ms) the derivative is one:
    within 1e-6 of the differences with a Taylor ratio of 4 (measured 1.0e-7 and 3.79; 1e-6 is
    10×)."""
    profile = BASE.actuator_profile
    below = profile.curvature(np.nextafter(profile.switch_time, 0.0))
    # the slope times one ulp of t0 (~1e-15 1/m) is all that separates the two
    assert profile.switch_jump == pytest.approx(profile.curvature(profile.switch_time) - below,
                                                abs=1e-12)
    assert abs(profile.switch_jump) > 1e-3
    # a run that reaches the switch (its last step ends on it; shorter ones have no jump)
    with pytest.warns(UserWarning, match=r"actuator_delays\[1\] = 0 s .* not defined"):
        simulate([BASE.replace(gait="A1+A2")], profile.switch_time,
                 sensitivities=("actuator_delays[1]",))
    import warnings
    off_grid = (0.0, 0.0123, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate([BASE.replace(gait="A1+A3")], 0.002, sensitivities=("actuator_delays[1]",))
        table = check_sensitivities([BASE.replace(gait="A1+A2", actuator_delays=off_grid)], 0.2,
                                    SolverConfig(**TIGHT), ("actuator_delays[1]",))
    matches_differences(table, 1e-6)


def test_a_zero_or_tiny_delays_derivative_is_that_of_its_differences(taichi_cpu):
    """At a delay of 0 (the default) the slope dτ/d(delay) was −1 on a step that ends on a
    firing, where a longer delay leaves τ at 0 (its derivative 0 for every delay above 0), so
    the replicas took the heating slope there: at every cycle start after the first, and
    every firing of a Simulator (an audit, 2026-12: 17 % and 26 % off by 1.2 s at 5-ms
    steps). At a tiny delay (1e-9 s) ε = 1e-4 of it left the replicas' offsets below the
    positions' rounding (11 % off). Against forward differences (a delay below 0 is none),
    extrapolated from steps of 1e-5 and 2e-5 s (O(h²)): within 1e-5 over two cycles of 0.4 s
    at 5-ms steps, which put the firings at 0.4 and 0.8 s on step ends (measured at 0:
    3.6e-8 and 1.1e-7; the sensitivities' 1e-5). One batch of both delays, one of their moves."""
    solver = SolverConfig(dt=5e-3, **TIGHT)

    def robots(delays):
        return [BASE.replace(gait=gait, period=0.4, actuator_delays=(delay,) + (0.0,) * 7)
                for delay in delays for gait in ("A1", "A1+A2")]
    delays = np.array([0.0, 1e-9])
    duration = 0.85
    result = simulate(robots(delays), duration, solver, sensitivities=("actuator_delays[0]",))
    exact = result.sensitivity("displacement_x_mm", "actuator_delays[0]")
    base, once, twice = simulate(robots(np.concatenate([delays, delays + 1e-5, delays + 2e-5])),
                                 duration, solver).summary["displacement_x_mm"].to_numpy() \
        .reshape(3, -1)
    forward = 2 * (once - base) / 1e-5 - (twice - base) / 2e-5
    assert np.all(np.abs(forward) > 1.0)   # a derivative that matters
    np.testing.assert_allclose(exact, forward, rtol=1e-5)


@pytest.mark.parametrize("delay", [0.0, 1e-9])
def test_the_check_takes_a_zero_delays_differences_forward(taichi_cpu, delay):
    """check_sensitivities differenced a delay at 0 centrally, through negative delays, where
    τ = max(t − d, 0) continues the model along another slope: it reported the correct
    derivative 1.9 % off, with a spread of 2.5e-6 that hid it (an audit, 2026-12), and a delay
    below its −4h run's step so too (a review). Forward differences from the delay itself now:
    within 1e-5 (measured 4.2e-9 at 0 by the audit's forward Richardson reference), A1 at a
    period of 0.4 s past its second firing."""
    robot = BASE.replace(gait="A1", period=0.4, actuator_delays=(delay,) + (0.0,) * 7)
    table = check_sensitivities([robot], 0.5, SolverConfig(dt=2e-3, **TIGHT),
                                ("actuator_delays[0]",))
    row = table[table["output"] == "displacement_x_mm"].iloc[0]
    assert abs(row["difference"]) > 1.0 and row["status"] == "ok"
    assert row["relative_error"] < 1e-5, row["relative_error"]


def test_recorded_shapes_are_the_callers_instances_alone(euler_run):
    """The shapes were a view of every instance's, the replicas' too (an audit: 4.7 MiB of
    result holding 80.5 MiB); now only the instances asked for are kept, in an array of their
    own."""
    records = len(euler_run.trajectory) // len(BATCH)
    assert euler_run.shapes.shape[:2] == (records, len(BATCH))
    assert euler_run.shapes.base is None or euler_run.shapes.base.nbytes == euler_run.shapes.nbytes
    assert np.isfinite(euler_run.shapes).all()


def test_the_sensitivities_are_written_with_their_provenance(euler_run, tmp_path):
    """They were in no file (an audit): now tables of to_parquet and to_csv, with the units of
    their columns (the summary's were written, 2026-12): the directions are dimensionless, so
    each derivative has its output's unit."""
    from taichi_star.output import read_provenance

    trajectory_units = {"t_s": "s", **{f"d({output})/d({field})": unit for field in DIRECTIONS
                                       for output, unit in (("x_mm", "mm"), ("y_mm", "mm"),
                                                            ("heading_deg", "degree"))}}
    for table in ("sensitivities", "trajectory_sensitivities"):
        path = euler_run.to_parquet(tmp_path / f"{table}.parquet", table=table)
        pd.testing.assert_frame_equal(pd.read_parquet(path), getattr(euler_run, table))
        assert read_provenance(path)["solver"]["newton_tol"] == TIGHT["newton_tol"]
        units = read_provenance(path)["units"]
        if table == "trajectory_sensitivities":
            assert units == trajectory_units
        else:
            assert units["d(signed_speed_mm_s)/d(alpha)"] == "mm/s"
            assert len(units) == len(euler_run.sensitivities.columns)
        csv = euler_run.to_csv(tmp_path / f"{table}.csv", table=table)
        np.testing.assert_array_equal(pd.read_csv(csv).to_numpy(dtype=float),
                                      getattr(euler_run, table).to_numpy(dtype=float))


def test_a_sensitivity_reads_its_instances_rows_after_a_users_sort_in_place(euler_run):
    """`sensitivity` takes the tables in the run's order, whatever order a user's in-place
    sort left their rows in (without that, each instance got another's derivative: a mutation
    audit, 2026-12, found no test of it)."""
    # the rows reversed, their labels kept, as an in-place sort leaves them (on a copy of the
    # result: the fixture stays as it is)
    reversed_rows = dataclasses.replace(
        euler_run, sensitivities=euler_run.sensitivities.iloc[::-1],
        trajectory_sensitivities=euler_run.trajectory_sensitivities.iloc[::-1])
    for output in ("displacement_x_mm", "x_mm"):
        np.testing.assert_array_equal(reversed_rows.sensitivity(output, "alpha"),
                                      euler_run.sensitivity(output, "alpha"))
