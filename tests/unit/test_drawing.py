"""Which actuators the pictures draw hot (`taichi_star.drawing`): the heating window of each
actuator from its firing and its delay, checked at exactly representable times on both sides
of every edge of the window."""

import numpy as np

from taichi_star.drawing import hot_actuators, periodic_hot_actuators

PERIOD, HEATING = 4.0, 0.25  # s; binary fractions, so the window's edges are exact


def test_an_actuator_heats_from_its_delay_for_the_heating_time():
    """0 <= since − delay < heating: hot at its start, cold at its end (a profile that has
    run `heating` s has finished its pulse), cold before it; never fired (NaN) is cold."""
    delays = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    since = np.array([[0.0, 1.0, 0.25, np.nan, 0.125, 0.0, 0.0, 0.0],
                      [0.25, 0.999, 0.2499, 0.0, 0.0, 0.0, 0.0, 0.0],
                      [0.0, 1.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                      [0.0, 1.2499, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    hot = hot_actuators(since, HEATING, delays)
    assert hot[0, :5].tolist() == [True, True, False, False, True]
    assert hot[1, :3].tolist() == [False, False, True]
    assert hot[2, 1] == np.False_ and hot[3, 1] == np.True_
    # without delays, as before they were drawn: the firing starts the heating
    assert (hot_actuators(since, HEATING) == ((since >= 0) & (since < HEATING))).all()


def test_a_periodic_gait_heats_each_cycle_after_each_actuator_s_delay():
    """A gait firing A1 and A2 at 0, T, 2T: A1 heats at the cycle's start, A2 `delay` later;
    a delay whose window reaches past the next firing is cut there (the firing restarts the
    profile, which then waits its delay again: `physics.bending`); an actuator the gait does
    not fire never heats."""
    fired = np.array([True, True, True, False, False, False, False, False])
    delays = np.array([0.0, 1.0, 3.875, 1.0, 0.0, 0.0, 0.0, 0.0])
    times = np.array([0.0, 0.125, 0.25, 1.0, 1.25, 3.875, 3.9375, 4.0, 4.125, 5.0, 7.9375])
    hot = periodic_hot_actuators(times, fired, PERIOD, HEATING, delays)
    assert hot[:, 0].tolist() == [True, True, False, False, False, False, False, True, True,
                                  False, False]
    assert hot[:, 1].tolist() == [False, False, False, True, False, False, False, False, False,
                                  True, False]
    assert hot[:, 2].tolist() == [False, False, False, False, False, True, True, False, False,
                                  False, True]
    assert not hot[:, 3:].any()
    # no delays: the window at the start of each cycle, bit for bit the rule drawn before
    phase = np.mod(times, PERIOD)
    assert (periodic_hot_actuators(times, fired, PERIOD, HEATING)
            == (phase < HEATING)[:, None] & fired[None, :]).all()
