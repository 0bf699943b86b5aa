"""Which actuators the pictures draw hot (`taichi_star.drawing`): the heating window of each
actuator from its firing and its delay, checked at exactly representable times on both sides
of every edge of the window."""

import numpy as np
import pytest

import taichi_star as ts
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


# Found by a mutation audit of the drawing (2026-12-07): each test below kills a change of
# the code that the suite let live.


def drawn_robot(hot, shift_mm=(0.0, 0.0)):
    """A coarse robot at rest, shifted by shift_mm, drawn by a RobotArtist with actuators `hot`
    (8 bools): (artist, topology, positions in mm)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from taichi_star.drawing import RobotArtist
    from taichi_star.geometry import build_topology

    topology = build_topology(ts.StarParams(n_arc=6, n_limb=2))
    positions = topology.rest_positions * 1e3 + np.asarray(shift_mm)
    ax = Figure().add_subplot()
    artist = RobotArtist(ax, topology, 10.0)
    artist.update(positions, np.asarray(hot, dtype=bool))
    return artist, topology, positions



def test_a_hot_actuator_colours_and_widens_its_own_arc_and_label_alone():
    """A8 hot: its arc's edges red and wider, its label red, nothing else (limbs and spokes,
    actuator -1, stay grey); the cylinder on the hub; A1's label beyond its arc's middle."""
    from matplotlib.colors import to_rgba

    from taichi_star.drawing import HOT_COLOUR, LABEL_OFFSET_MM, edge_actuators
    from taichi_star.geometry import ARC, CENTRE

    hot = np.zeros(8, dtype=bool)
    hot[7] = True  # A8: the last actuator, which an index of -1 would name
    artist, topology, positions = drawn_robot(hot, shift_mm=(30.0, -20.0))
    colours = artist.lines.get_colors()
    widths = np.broadcast_to(artist.lines.get_linewidths(), (len(topology.edges),))
    actuator = edge_actuators(topology)
    assert ((actuator >= 0) == (topology.edge_kind == ARC)).all()
    red = np.all(np.isclose(colours, to_rgba(HOT_COLOUR)), axis=1)
    assert red.tolist() == (actuator == 7).tolist() and red.any()
    assert (widths[red] == 2.4).all() and not (widths[~red] == 2.4).any()
    labels = [label.get_color() for label in artist.labels]
    assert labels == ["0.25"] * 7 + [HOT_COLOUR]
    # the cylinder follows the hub; A1's label sits LABEL_OFFSET_MM beyond its arc's middle node
    assert artist.cylinder.center == pytest.approx(tuple(positions[CENTRE]))
    arc = topology.arcs[0]
    middle = positions[arc[len(arc) // 2]]
    outward = (middle - positions[CENTRE]) / np.hypot(*(middle - positions[CENTRE]))
    assert artist.labels[0].get_position() == pytest.approx(
        tuple(middle + LABEL_OFFSET_MM * outward))



def test_a_scale_bar_is_the_round_length_nearest_a_fifth_of_the_view():
    """1, 2 or 5 times a power of ten, at most a fifth of the span."""
    from taichi_star.drawing import nice_length

    assert [nice_length(span) for span in (25.0, 36.0, 100.0, 0.3)] == \
        pytest.approx([5.0, 5.0, 20.0, 0.05])



def test_a_goal_far_from_the_robot_is_in_its_picture():
    """A goal 300 mm away is inside the view: its green star is drawn."""
    from taichi_star.drawing import robot_image
    from taichi_star.geometry import build_topology

    topology = build_topology(ts.StarParams(n_arc=6, n_limb=2))
    positions = topology.rest_positions * 1e3
    picture = robot_image(positions, topology, np.zeros(8, bool), 10.0,
                          goal_mm=np.array([300.0, 0.0]), size_px=200)
    green = (picture[..., 1] > 130) & (picture[..., 0] < 90) & (picture[..., 2] < 90)
    assert green.sum() > 10



def test_a_pictures_view_is_the_robot_and_its_goal_with_12_mm_around(monkeypatch):
    """The view is a square about the robot, 12 mm beyond its largest extent, and its scale
    bar `nice_length` of the view's width."""
    from taichi_star import drawing
    from taichi_star.geometry import build_topology

    views = []
    monkeypatch.setattr(drawing, "add_scale_bar",
                        lambda ax, length: views.append((ax.get_xlim(), ax.get_ylim(), length)))
    topology = build_topology(ts.StarParams(n_arc=6, n_limb=2))
    positions = topology.rest_positions * 1e3
    drawing.robot_image(positions, topology, np.zeros(8, bool), 10.0, size_px=100)
    low, high = positions.min(axis=0), positions.max(axis=0)
    half = 0.5 * (high - low).max() + 12.0
    centre = 0.5 * (low + high)
    (x, y, length), = views
    assert x == pytest.approx((centre[0] - half, centre[0] + half))
    assert y == pytest.approx((centre[1] - half, centre[1] + half))
    assert length == drawing.nice_length(2 * half)
