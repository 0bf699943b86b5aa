"""The host side of the sensitivities (`taichi_star.sensitivities`), without an engine: which
names a run can differentiate by and the errors for the rest, each direction's ε, the checks
made before any compute, the replicas' batch and tables, and the derivatives read back from
their outputs. Each rule is tested at both sides of its boundary."""

import dataclasses
import difflib
import re
import warnings

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star.actuation import CurvatureProfile, _logistic
from taichi_star.model import build_model
from taichi_star.params import DIFFERENTIABLE_FIELDS, STAR_RANGES
from taichi_star import sensitivities as sens
from taichi_star.sensitivities import Direction, parse_directions

BASE = StarParams(gait="A1+A3")


def labels(names):
    return [direction.label for direction in parse_directions(names)]


def test_fields_and_actuator_numbers_become_directions_in_the_order_named():
    assert labels(["alpha"]) == ["alpha"]
    assert labels(("drag_perpendicular", "actuator_gains[0]", "actuator_delays[7]")) == [
        "drag_perpendicular", "actuator_gains[0]", "actuator_delays[7]"]
    assert labels(["actuator_gains"]) == [f"actuator_gains[{k}]" for k in range(8)]
    assert parse_directions([]) == ()
    assert parse_directions(iter(["alpha"])) == (Direction("alpha"),)
    assert Direction("alpha").label == "alpha" and Direction("alpha").index == -1
    # every field the parameters call differentiable is accepted, once each
    assert len(parse_directions(DIFFERENTIABLE_FIELDS)) == len(DIFFERENTIABLE_FIELDS) + 2 * 7


@pytest.mark.parametrize("name", ["actuator_gains[8]", "actuator_gains[-1]", "actuator_gains[1",
                                  "actuator_gains[]", "actuator_gains[x]", "actuator_gains[ 1]",
                                  "actuator_gains[12]", "actuator_gains[10]", "actuator_gains[12",
                                  "actuator_gains[01]", "actuator_gains[00]"])
def test_an_actuator_index_outside_0_to_7_or_not_a_number_is_refused(name):
    with pytest.raises(ValueError) as error:
        parse_directions([name])
    assert str(error.value) == (f"sensitivities: {name!r} must name an actuator index in [0, 7] "
                                f"(Python's: actuator_gains[0] is A1's, actuator_gains[7] A8's)")


@pytest.mark.parametrize("name", ["period", "gait", "n_arc", "alpha[0]", "actuator_profile"])
def test_a_field_that_is_not_a_real_coefficient_is_named_not_differentiable(name):
    with pytest.raises(ValueError, match=rf"^sensitivities: {re.escape(repr(name))} is not "
                                         r"differentiable \(.*; differentiable fields: alpha, "):
        parse_directions([name])


def test_an_unknown_name_gets_the_closest_fields_and_no_hint_when_nothing_is_close():
    listed = ", ".join(DIFFERENTIABLE_FIELDS)
    with pytest.raises(ValueError) as error:
        parse_directions(["alpah"])
    assert str(error.value) == (f"sensitivities: 'alpah' is not a StarParams field; did you mean "
                                f"alpha? (differentiable fields: {listed})")
    # at most the three closest, comma-separated (difflib's order: the closest first)
    close = difflib.get_close_matches("actuator", DIFFERENTIABLE_FIELDS, n=10)
    assert len(close) > 3
    with pytest.raises(ValueError, match=rf"; did you mean {', '.join(close[:3])}\? "):
        parse_directions(["actuator"])
    with pytest.raises(ValueError, match=r"^sensitivities: 'zzzz' is not a StarParams field "
                                         r"\(differentiable fields: "):
        parse_directions(["zzzz"])


SEQUENCE = "sensitivities must be a sequence of StarParams field names (a list or tuple; not a " \
    "set or a mapping), got "


@pytest.mark.parametrize("names, message", [
    ("alpha", SEQUENCE + "'alpha'"),
    (5, SEQUENCE + "5"),
    # a set has no order (the columns' would change from run to run), a mapping's values would
    # be dropped unread
    ({"alpha"}, SEQUENCE + "{'alpha'}"),
    (frozenset(["alpha"]), SEQUENCE + "frozenset({'alpha'})"),
    ({"alpha": 1}, SEQUENCE + "{'alpha': 1}"),
    (b"alpha", SEQUENCE + "b'alpha'"),
    # str.isdigit() takes "²", which int() refuses: Python's own message had come through
    (["actuator_gains[²]"], "sensitivities: 'actuator_gains[²]' must name an actuator index in "
                            "[0, 7] (Python's: actuator_gains[0] is A1's, actuator_gains[7] A8's)"),
    (["alpha", 3], "sensitivities must hold field names, got 3"),
    (["alpha", "alpha"], "sensitivities: 'alpha' is named twice"),
    (["actuator_gains", "actuator_gains[2]"], "sensitivities: 'actuator_gains[2]' is named twice"),
])
def test_a_string_a_set_a_mapping_a_number_a_non_name_and_a_repeat_are_refused(names, message):
    with pytest.raises(ValueError) as error:
        parse_directions(names)
    assert str(error.value) == message


def test_epsilon_is_relative_to_the_value_with_its_own_share_for_two_fields():
    params = BASE.replace(alpha=1.3, drag_parallel=0.2, damping_time=0.004)
    assert Direction("alpha").step(params) == sens.RELATIVE_STEP * 1.3
    assert Direction("drag_parallel").step(params) == 1e-2 * 0.2
    assert Direction("damping_time").step(params) == 1e-3 * 0.004
    gains = params.replace(actuator_gains=(1.0, 0.5, 2.0, 1.0, 1.0, 1.0, 1.0, 1.0))
    assert Direction("actuator_gains", 1).step(gains) == sens.RELATIVE_STEP * 0.5
    # a negative value (a replica may lie beyond a range) takes ε from its size
    assert Direction("alpha").step(Direction("alpha").moved(params, -2.0)) == \
        sens.RELATIVE_STEP * 2.0


def test_epsilon_of_a_parameter_at_zero_is_a_share_of_its_range_or_period():
    at_zero = BASE.replace(linear_drag=0.0, actuator_gains=(0.0,) + (1.0,) * 7,
                           actuator_delays=(0.0,) * 8, period=2.0)
    top = STAR_RANGES["linear_drag"][1]
    assert Direction("linear_drag").step(at_zero) == sens.RELATIVE_STEP * (sens.ZERO_VALUE_SCALE * top)
    assert Direction("actuator_delays", 3).step(at_zero) == \
        sens.RELATIVE_STEP * (sens.ZERO_VALUE_SCALE * 2.0)
    # a gain has no declared range: the share of 1
    assert Direction("actuator_gains", 0).step(at_zero) == \
        sens.RELATIVE_STEP * (sens.ZERO_VALUE_SCALE * 1.0)
    assert Direction("actuator_gains", 1).step(at_zero) == sens.RELATIVE_STEP


def test_a_moved_copy_changes_one_number_unvalidated_and_leaves_the_original():
    top = STAR_RANGES["alpha"][1]
    beyond = Direction("alpha").moved(BASE, top + 1.0)
    assert beyond.alpha == top + 1.0 and BASE.alpha == 0.8
    first = Direction("actuator_gains", 0).moved(BASE, 0.5)   # index 0 is A1's, not the field
    assert first.actuator_gains == (0.5,) + (1.0,) * 7
    delays = Direction("actuator_delays", 2).moved(BASE, 0.25)
    assert delays.actuator_delays == (0.0, 0.0, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert BASE.actuator_delays == (0.0,) * 8
    assert Direction("actuator_delays", 2).value(delays) == 0.25


def test_f32_is_refused_only_with_directions():
    f32 = SolverConfig(precision="f32", newton_tol=1e-7)
    with pytest.raises(ValueError, match=r"^sensitivities need precision 'f64' .*got 'f32'$"):
        sens.check_directions(parse_directions(["alpha"]), [BASE], f32)
    sens.check_directions((), [BASE], f32)


def test_a_component_height_at_zero_names_the_first_such_instance():
    heights = dict(hub_height=0.05, foam_height=0.02, actuator_height=0.03)
    batch = [BASE.replace(**heights), BASE, BASE]
    with pytest.raises(ValueError, match=r"^sensitivities: foam_height is 0 \(the 2.5-D model "
                                         r"off\) for instance 1; "):
        sens.check_directions(parse_directions(["foam_height"]), batch, SolverConfig())
    sens.check_directions(parse_directions(["foam_height"]), batch[:1], SolverConfig())
    # a height that is not differentiated may be 0
    sens.check_directions(parse_directions(["alpha"]), batch, SolverConfig())


def on_grid_delay(dt, steps):
    """A delay that puts the profile's switch (t0 after the firing) on step `steps`."""
    return steps * dt - CurvatureProfile().switch_time


def test_a_delay_puts_the_switch_on_a_step_end_only_when_fired_and_on_the_grid():
    dt = 1e-3
    delay = on_grid_delay(dt, 400)
    fired = BASE.replace(gait="A1+A3", actuator_delays=(0.0, 0.0, delay) + (0.0,) * 5)
    assert sens.delay_on_step_grid(fired, 2, dt)
    # half a step off the grid, or a tenth of a step: no jump at a step end
    for offset in (0.5 * dt, 0.1 * dt, -0.1 * dt):
        moved = fired.replace(actuator_delays=(0.0, 0.0, delay + offset) + (0.0,) * 5)
        assert not sens.delay_on_step_grid(moved, 2, dt)
    # at 5-ms steps t0 = 32.6 steps: the switch, delay + t0, is on the grid, not delay − t0
    coarse = 5e-3
    on_coarse = fired.replace(actuator_delays=(0.0, 0.0, on_grid_delay(coarse, 400)) + (0.0,) * 5)
    assert sens.delay_on_step_grid(on_coarse, 2, coarse)
    minus = fired.replace(actuator_delays=(0.0, 0.0, 400 * coarse + 0.163) + (0.0,) * 5)
    assert not sens.delay_on_step_grid(minus, 2, coarse)
    # A2 does not fire in A1+A3: its delay moves nothing
    assert not sens.delay_on_step_grid(
        fired.replace(actuator_delays=(0.0, delay) + (0.0,) * 6), 1, dt)
    # a profile whose branches meet at the switch (the cooling branch a constant at the
    # heating branch's value there) has no jump to cross
    meeting = CurvatureProfile()
    level = float(_logistic(meeting.heating, meeting.switch_time))
    smooth = dataclasses.replace(meeting, cooling=(0.0, 1.0, 0.0, level))
    assert smooth.switch_jump == 0.0
    # at 1-ms steps t0 is whole steps: the onset, the delay after the firing, is on the grid
    # too, a kink of τ = max(t − d, 0) whatever the profile; at 5 ms neither is
    assert sens.delay_event(fired.replace(actuator_profile=smooth), 2, dt) == (
        pytest.approx(delay), "the profile's onset, the delay after a firing,")
    assert not sens.delay_on_step_grid(on_coarse.replace(actuator_profile=smooth), 2, coarse)


def test_a_simulators_commanded_firings_make_any_actuators_delay_count():
    """A Simulator fires what it is told and reads no gait: A1's delay on the grid has no
    derivative there though the gait field (A2) does not fire A1 (the warning followed the
    gait: it said nothing here, and warned for a gait's actuator a Simulator may never fire)."""
    dt = 1e-3
    quiet = BASE.replace(gait="A2", actuator_delays=(on_grid_delay(dt, 400),) + (0.0,) * 7)
    assert not sens.delay_on_step_grid(quiet, 0, dt)
    assert sens.delay_on_step_grid(quiet, 0, dt, commanded=True)
    moved = quiet.replace(actuator_delays=(on_grid_delay(dt, 400) + 0.5 * dt,) + (0.0,) * 7)
    assert not sens.delay_on_step_grid(moved, 0, dt, commanded=True)
    directions = parse_directions(["actuator_delays[0]"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sens.check_directions(directions, [quiet], SolverConfig(dt=dt))
    with pytest.warns(UserWarning, match=r"^sensitivities: actuator_delays\[0\] = 0.237 s"):
        sens.check_directions(directions, [quiet], SolverConfig(dt=dt), commanded=True)
    with pytest.warns(UserWarning, match=r"^sensitivities: actuator_delays\[0\] = 0.237 s"):
        taichi_star.Simulator([quiet], SolverConfig(dt=dt), sensitivities=["actuator_delays[0]"])


def test_a_delay_on_the_grid_warns_only_for_a_run_that_reaches_its_event():
    """The first event on the grid is the onset, the delay after the start (at 1-ms steps the
    switch, t0 later, is on it too): a run that ends a step before it has a derivative by the
    delay and no warning (every default setup warned, however short the run); one whose last
    step ends on it warns, as a longer one does."""
    dt = 1e-3
    on = BASE.replace(actuator_delays=(0.0, 0.0, on_grid_delay(dt, 400)) + (0.0,) * 5)
    directions = parse_directions(["actuator_delays[2]"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sens.check_directions(directions, [on], SolverConfig(dt=dt), duration_s=0.236)
    for duration_s in (0.237, 0.238, 0.4):
        with pytest.warns(UserWarning, match=r"^sensitivities: actuator_delays\[2\] = 0.237 s"):
            sens.check_directions(directions, [on], SolverConfig(dt=dt), duration_s=duration_s)
    # simulate passes its duration: two steps from rest, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run = taichi_star.simulate([on], 2 * dt, SolverConfig(dt=dt),
                                   sensitivities=["actuator_delays[2]"])
    assert run.summary["status"].tolist() == ["ok"]


def test_a_delay_on_the_grid_warns_with_fixed_steps_only():
    dt = 1e-3
    on = BASE.replace(actuator_delays=(0.0, 0.0, on_grid_delay(dt, 400)) + (0.0,) * 5)
    later = BASE.replace(actuator_delays=(0.0, 0.0, on_grid_delay(dt, 500)) + (0.0,) * 5)
    off = BASE.replace(actuator_delays=(0.0, 0.0, on_grid_delay(dt, 400) + 0.5 * dt) + (0.0,) * 5)
    directions = parse_directions(["actuator_delays[2]"])
    # the first such instance's delay is quoted (0.237 s = 400 ms − t0), the count is all
    with pytest.warns(UserWarning, match=r"^sensitivities: actuator_delays\[2\] = 0.237 s "
                                         r"\(instance 1, 2 in all\) puts the profile's onset, "
                                         r"the delay after a firing, on a step end \(t = 0.237 "
                                         r"s\)"):
        sens.check_directions(directions, [off, on, later], SolverConfig(dt=dt))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sens.check_directions(directions, [off], SolverConfig(dt=dt))
        sens.check_directions(directions, [on], SolverConfig(integrator="bdf2", adaptive=True))
        # another delay's direction does not look at A3's
        sens.check_directions(parse_directions(["actuator_delays[0]"]), [on.replace(
            actuator_delays=(0.0005,) + on.actuator_delays[1:])], SolverConfig(dt=dt))


@pytest.mark.parametrize("period, delay, dt, adaptive, event", [
    # the second firing's onset, 0.2505 + 0.0005 s, on a step end though the first's is not
    # (a period of no whole number of steps fires inside a step)
    (0.2505, 0.0005, 1e-3, False, 0.251),
    (0.2505, 0.0002, 1e-3, False, None),
    # the onset on a step end at 2-ms steps, where the switch (t0 = 81.5 steps) is not
    (0.25, 0.010, 2e-3, False, 0.010),
    (0.25, 0.0105, 2e-3, False, None),
    # adaptive steps held at one length: the same grid
    (3.15, 0.001, 1e-3, True, 0.001),
    # a switch past the next firing never comes (it warned): 0.062 + t0 = 0.225 > 0.2
    (0.2, 0.062, 5e-3, False, None),
])
def test_a_delays_events_on_the_grid_are_those_of_every_firing(period, delay, dt, adaptive,
                                                                event):
    """The warning looked at the first firing's switch alone (an audit, 2026-12): it missed
    the onset (a kink of τ = max(t − d, 0)), later firings where the period is no whole number
    of steps and adaptive steps held at dt_min = dt_max, and warned of a switch the next firing
    pre-empts. A1 over 0.5 s; the event's time where it warns, silence where it does not."""
    robot = BASE.replace(gait="A1", period=period, actuator_delays=(delay,) + (0.0,) * 7)
    solver = SolverConfig(adaptive=True, integrator="bdf2", dt_min=dt, dt_max=dt) if adaptive \
        else SolverConfig(dt=dt)
    directions = parse_directions(["actuator_delays[0]"])
    if event is None:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sens.check_directions(directions, [robot], solver, duration_s=0.5)
    else:
        with pytest.warns(UserWarning, match=re.escape(f"on a step end (t = {event:g} s)")):
            sens.check_directions(directions, [robot], solver, duration_s=0.5)


ONSET = "the profile's onset, the delay after a firing,"
FALLING = dataclasses.replace(CurvatureProfile(), cooling=(94.777, 2.507, 1.019, 4.445 - 200.0))
"""A profile whose curvature jumps down at the switch (the paper's jumps up)."""


@pytest.mark.parametrize("fields, dt, commanded, end, event", [
    # a firing inside the run's last step (at 0.2507 s, the step ending at 0.251 s) happens:
    # its onset on that step end counts
    (dict(period=0.2507, actuator_delays=(0.0003,) + (0.0,) * 7), 1e-3, False, 0.251,
     (0.251, ONSET)),
    # the default delay of 0 has no onset kink (the delay's range starts there), and t0 is
    # 32.6 steps of 5 ms: nothing
    (dict(), 5e-3, False, 0.5, None),
    # a switch whose curvature falls counts as one that rises: 0.002 + t0 = 33 steps of 5 ms
    (dict(actuator_delays=(0.002,) + (0.0,) * 7, actuator_profile=FALLING), 5e-3, False, 0.5,
     (0.165, "switch")),
    # a Simulator's firing is no period's: a switch past the period still comes
    (dict(period=0.2, actuator_delays=(0.062,) + (0.0,) * 7), 5e-3, True, None,
     (0.225, "switch")),
    # an onset on the run's last step end, the float sum 0.1 + 0.2 past 0.3
    (dict(actuator_delays=(0.1 + 0.2,) + (0.0,) * 7), 1e-3, False, 0.3, (0.3, ONSET)),
    # the first event in time, the switch at 0.165 s, not the first kind looked at (the
    # second firing's onset at 0.255 s)
    (dict(period=0.253, actuator_delays=(0.002,) + (0.0,) * 7), 5e-3, False, 0.5,
     (0.165, "switch"))])
def test_a_delays_first_event_on_the_grid_at_each_boundary(fields, dt, commanded, end,
                                                             event):
    """`delay_event` for A1 of gait A1 at each boundary of its rules (a mutation audit,
    2026-12, found these unchecked): (time, what) of the first event up to the run's last
    step end `end`, None for none."""
    found = sens.delay_event(BASE.replace(gait="A1", **fields), 0, dt, commanded, end)
    if event is None:
        assert found is None
    else:
        assert found[0] == pytest.approx(event[0], rel=1e-12)
        assert found[1] == event[1] if event[1] == ONSET else found[1].startswith(
            "the actuation profile's switch")


def test_a_runs_end_is_its_duration_rounded_to_fixed_steps_and_the_duration_itself_held():
    """With fixed steps a run of 0.2507 s takes 251 steps of 1 ms and fires at 0.2507 s inside
    the last: that firing's onset on the step end at 0.251 s is warned of (it was left out:
    a mutation audit, 2026-12). Adaptive steps held at one length end on the duration: a run
    of 1.006 s at 10-ms steps never fires at 1.008 s (rounding its end to 1.01 s warned of
    that firing: a review, 2026-12)."""
    directions = parse_directions(["actuator_delays[0]"])
    fixed = BASE.replace(gait="A1", period=0.2507, actuator_delays=(0.0003,) + (0.0,) * 7)
    with pytest.warns(UserWarning, match=re.escape("on a step end (t = 0.251 s)")):
        sens.check_directions(directions, [fixed], SolverConfig(dt=1e-3), duration_s=0.2507)
    held = SolverConfig(dt=0.01, adaptive=True, dt_min=0.01, dt_max=0.01, integrator="bdf2")
    late = BASE.replace(gait="A1", period=1.008, actuator_delays=(0.002,) + (0.0,) * 7)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sens.check_directions(directions, [late], held, duration_s=1.006)


def test_the_replicas_follow_their_instances_as_plus_then_minus_pairs():
    batch = [BASE, BASE.replace(alpha=1.2), BASE.replace(alpha=0.5, drag_perpendicular=3.0)]
    directions = parse_directions(["alpha", "drag_perpendicular"])
    replicas, steps = sens.replica_batch(batch, directions, scale=2.0)
    assert len(replicas) == 3 * (1 + 2 * 2) and steps.shape == (2, 3)
    assert replicas[:3] == batch
    for j, direction in enumerate(directions):
        plus, minus = sens.pair_slices(j, 3)
        assert (plus.start, plus.stop, minus.start, minus.stop) == (3 + 6 * j, 6 + 6 * j,
                                                                  6 + 6 * j, 9 + 6 * j)
        for b, p in enumerate(batch):
            eps = direction.step(p)
            assert steps[j, b] == eps
            assert direction.value(replicas[plus][b]) == direction.value(p) + 2.0 * eps
            assert direction.value(replicas[minus][b]) == direction.value(p) - 2.0 * eps
            # the other parameters are the instance's
            other = directions[1 - j]
            assert other.value(replicas[plus][b]) == other.value(p)


def test_the_replicas_tables_lie_on_their_instances_tangent():
    """For the joint radius, which moves the rest shape and the elastic tables nonlinearly,
    the replicas' tables are the instance's ± ε times their derivative: symmetric about the
    instance to the rounding, and (plus − minus)/2ε equals a central difference of the host
    tables at a tenth of ε to 1e-6 of the tables' scale (its truncation, ~(ε/10)²·c‴/6, and the
    tables' rounding over ε/10 ~1e-11 relative, are both far below)."""
    batch = [BASE]
    (direction,) = parse_directions(["joint_radius"])
    model, steps = sens.replica_model(batch, (direction,))
    eps = steps[0, 0]
    plus, minus = sens.pair_slices(0, 1)
    small = 0.1 * eps
    above = build_model([direction.moved(BASE, BASE.joint_radius + small)]).rest_positions[0]
    below = build_model([direction.moved(BASE, BASE.joint_radius - small)]).rest_positions[0]
    rest = model.rest_positions
    scale = np.abs(rest[0]).max()
    assert np.abs(rest[plus][0] + rest[minus][0] - 2.0 * rest[0]).max() <= 1e-15 * scale
    tangent = (rest[plus][0] - rest[minus][0]) / (2.0 * eps)
    difference = (above - below) / (2.0 * small)
    assert np.abs(tangent - difference).max() <= 1e-6 * np.abs(difference).max()
    # built plainly at ±ε, a replica's rest shape is off that line by ε²·c″/2 (both the same
    # way): the tables must not be the plain ones
    plain = build_model([direction.moved(BASE, BASE.joint_radius + eps)]).rest_positions[0]
    assert not np.array_equal(plain, rest[plus][0])
    # so for the masses, the inertia and every float coefficient the radius moves (lengths,
    # curvatures, stiffnesses): each replica pair symmetric about the instance and its
    # half-difference the derivative; the integer tables (the gait mask) the instance's
    above_model = build_model([direction.moved(BASE, BASE.joint_radius + small)])
    below_model = build_model([direction.moved(BASE, BASE.joint_radius - small)])
    tables = {"mass": (model.mass, above_model.mass, below_model.mass),
              "inertia": (model.inertia, above_model.inertia, below_model.inertia)}
    for name, table in model.coefficients.items():
        for key, values in table.items():
            tables[f"{name}.{key}"] = (values, above_model.coefficients[name][key],
                                       below_model.coefficients[name][key])
    moved = []
    for label, (values, up, down) in tables.items():
        if not np.issubdtype(values.dtype, np.floating):
            assert (values[plus] == values[0]).all() and (values[minus] == values[0]).all(), label
            continue
        scale = max(np.abs(values[0]).max(), 1e-300)
        assert np.abs(values[plus] + values[minus] - 2 * values[:1]).max() <= 1e-14 * scale, label
        difference = (up[0] - down[0]) / (2.0 * small)
        tangent = (values[plus][0] - values[minus][0]) / (2.0 * eps)
        assert np.abs(tangent - difference).max() <= 1e-6 * max(np.abs(difference).max(),
                                                                 1e-12 * scale), label
        if np.abs(difference).max() > 0:
            moved.append(label)
    assert {"mass", "inertia", "stretching.rest_length", "bending.rest_curvature"} <= set(moved)


def test_a_commanded_model_lets_every_actuator_fire_its_replicas_too():
    """`commanded` (a Simulator's batch) reaches the instances' and the replicas' tables, the
    ±2ε batch's as well: every actuator may fire; without it each fires its gait's."""
    directions = parse_directions(["alpha"])
    gaits, _ = sens.replica_model([BASE], directions)
    commanded, _ = sens.replica_model([BASE], directions, commanded=True)
    mask = np.array([1, 0, 1, 0, 0, 0, 0, 0])  # BASE fires A1+A3
    assert (gaits.coefficients["bending"]["gait_mask"] == mask).all()
    assert (commanded.coefficients["bending"]["gait_mask"] == 1).all()


def test_derivatives_are_the_pairs_central_differences_and_angles_go_the_short_way():
    directions = parse_directions(["alpha", "drag_perpendicular"])
    steps = np.array([[0.1, 0.2], [0.5, 1.0]])
    values = np.array([0.0, 0.0,          # the instances
                       1.0, 2.0, 0.6, 1.0,     # alpha: +ε, then −ε
                       179.0, -179.0, -179.0, 179.0])  # C⊥: across ±180°
    linear = sens.derivatives(values, directions, steps, "displacement_x_mm")
    np.testing.assert_array_equal(linear["alpha"], [(1.0 - 0.6) / 0.2, (2.0 - 1.0) / 0.4])
    np.testing.assert_array_equal(linear["drag_perpendicular"], [358.0 / 1.0, -358.0 / 2.0])
    # every angle output, the travel direction too (a robot swimming toward -x crosses
    # ±180°; the rule tested on heading_deg alone passed with it unwrapped: a mutation audit)
    for angle in ("heading_deg", "travel_direction_deg"):
        angles = sens.derivatives(values, directions, steps, angle)
        np.testing.assert_allclose(angles["drag_perpendicular"], [-2.0 / 1.0, 2.0 / 2.0],
                                   rtol=1e-12)
    # a trajectory output: one row per instance, the records along the second axis
    records = np.arange(10 * 3, dtype=float).reshape(10, 3)
    by_record = sens.derivatives(records, directions, steps, "x_mm")
    assert by_record["alpha"].shape == (2, 3)
    np.testing.assert_array_equal(by_record["alpha"][1], (records[3] - records[5]) / 0.4)


def test_a_runs_tables_split_into_the_instances_and_their_derivatives():
    directions = parse_directions(["alpha"])
    steps = np.array([[0.01, 0.02]])
    total, records = 6, 2  # two instances, their +ε and their −ε replicas; two records
    summary = pd.DataFrame({output: np.arange(total, dtype=float) * (k + 1)
                            for k, output in enumerate(sens.SUMMARY_OUTPUTS)})
    summary["instance"] = np.arange(total)
    # the trajectory as an engine writes it, record by record, instances inside
    trajectory = pd.DataFrame({
        "instance": np.tile(np.arange(total), records),
        "t_s": np.repeat([0.0, 0.5], total),
        **{output: np.concatenate([np.arange(total) * 1.0, np.arange(total) * 3.0])
           for output in sens.TRAJECTORY_OUTPUTS}})
    own, own_trajectory, table, trajectory_table = sens.split_result(summary, trajectory,
                                                                     directions, steps)
    assert own["instance"].tolist() == [0, 1]
    assert list(own.columns) == list(summary.columns)   # no index column added
    assert list(own_trajectory.columns) == list(trajectory.columns)
    assert list(trajectory_table.columns[:2]) == ["instance", "t_s"]
    assert own_trajectory[["instance", "t_s"]].values.tolist() == [[0, 0.0], [0, 0.5],
                                                                   [1, 0.0], [1, 0.5]]
    column = sens.sensitivity_column("displacement_x_mm", "alpha")
    assert column == "d(displacement_x_mm)/d(alpha)"
    assert len(table.columns) == len(sens.SUMMARY_OUTPUTS)
    # +ε replicas are rows 2, 3 and −ε rows 4, 5; displacement_x_mm is the row number
    np.testing.assert_allclose(table[column], [(2 - 4) / 0.02, (3 - 5) / 0.04])
    factor = sens.SUMMARY_OUTPUTS.index("heading_deg") + 1  # its column is the row × this
    np.testing.assert_allclose(table[sens.sensitivity_column("heading_deg", "alpha")],
                               [factor * (2 - 4) / 0.02, factor * (3 - 5) / 0.04])
    x = trajectory_table[sens.sensitivity_column("x_mm", "alpha")]
    # instance 0: records 0 and 0.5 s (values ×1 then ×3); instance 1 likewise
    np.testing.assert_allclose(x, [(2 - 4) / 0.02, 3 * (2 - 4) / 0.02,
                                   (3 - 5) / 0.04, 3 * (3 - 5) / 0.04])
    assert trajectory_table["t_s"].tolist() == [0.0, 0.5, 0.0, 0.5]


LINEAR = ["added_mass_coeff", "cylinder_added_mass_coeff", "drag_perpendicular", "drag_parallel",
          "cylinder_drag", "linear_drag", "hub_linear_drag", "wake_coupling", "alpha",
          "jet_inflow", "stroke_warming"]
"""The scalar StarParams fields the terms declare their forces linear or quadratic in
(`Term.linear_fields`; fluid_density's range excludes a value far below its usual one)."""


@pytest.mark.parametrize("field", LINEAR)
def test_each_declared_linear_coefficient_far_below_its_usual_value_takes_its_usual_step(field):
    """The rule of test_sensitivities' `test_a_small_coefficients_step_is_its_usual_scales`,
    for every coefficient a term declares linear (four missing from their terms' tables lived
    through the suite: a mutation audit, 2026-12-07): a value of 1e-6 of the usual scale takes the
    ε of that scale, not 1e-4 of itself (which leaves the replicas within the positions'
    rounding)."""
    (direction,) = parse_directions((field,))
    tiny = 1e-6 * direction.usual_scale()
    params = StarParams.preset("paper").replace(**{field: tiny})
    assert field in sens.LINEAR_FIELDS
    assert direction.step(params) == direction.relative_step * direction.usual_scale()
    assert direction.step(params) > 10 * direction.relative_step * tiny
