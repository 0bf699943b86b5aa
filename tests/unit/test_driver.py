"""The run driver's progress bar (taichi_star.driver) with a stand-in engine: its count ends
exactly on its total, whatever the float sums of the stops' times."""

import warnings

import numpy as np
import pytest

from taichi_star.driver import Clock, RunTiming, drive, robots_label
from taichi_star.params import SolverConfig


class CountingEngine:
    """Takes the driver's calls and counts them; simulates nothing."""

    def __init__(self):
        self.steps, self.targets = 0, []

    def advance(self, count):
        self.steps += count

    def advance_adaptive_to(self, targets, batch):
        self.targets.append(float(targets[0]))


@pytest.mark.parametrize("adaptive, duration_s, interval_s", [
    (False, 0.21, 0.01),    # 210 steps of 1 ms: 210 × 0.001 in floats passes 0.21
    (True, 0.3, 0.1),       # stops 0.1, 0.2, 0.30000000000000004: the last past the end
])
def test_the_bar_ends_on_its_total_without_a_warning(capsys, adaptive, duration_s, interval_s):
    solver = SolverConfig(adaptive=adaptive)
    clock = Clock(solver, duration_s)
    stops = clock.stops_every(interval_s)
    engine, reached = CountingEngine(), []
    with warnings.catch_warnings():
        warnings.simplefilter("error")      # tqdm's "clamping frac to range [0, 1]"
        drive(engine, clock, stops, reached.append, batch=1, progress_label=robots_label(1))
    assert reached == stops
    last_line = capsys.readouterr().err.strip().split("\r")[-1]
    assert last_line.startswith("1 robot: 100%")
    assert f"{duration_s:.3f}/{duration_s:.3f} s simulated" in last_line
    if adaptive:
        assert engine.targets == pytest.approx([0.1, 0.2, 0.3], rel=1e-15)
    else:
        assert engine.steps == 210


class InterruptedEngine(CountingEngine):
    """Raises KeyboardInterrupt at its second launch, as a notebook's "interrupt kernel" does
    in the middle of a run."""

    def advance(self, count):
        if self.steps:
            raise KeyboardInterrupt
        super().advance(count)

    def advance_adaptive_to(self, targets, batch):
        if self.targets:
            raise KeyboardInterrupt
        super().advance_adaptive_to(targets, batch)


@pytest.mark.parametrize("adaptive", [False, True])
def test_an_interrupted_runs_bar_is_closed(monkeypatch, adaptive):
    """The bar was closed only after the last stop: an interrupted run's stayed open while the
    traceback lived (IPython keeps the last one), and in a notebook the next run's bar was
    drawn below it, a line per update (an audit, 2026-12)."""
    from taichi_star import driver

    bars = []

    def kept(*args):
        bars.append(progress_bar(*args))
        return bars[-1]

    progress_bar = driver.progress_bar
    monkeypatch.setattr(driver, "progress_bar", kept)
    clock = Clock(SolverConfig(adaptive=adaptive), 0.3)
    stops = clock.stops_every(0.1) if adaptive else [0, clock.end]  # 300 steps: 6 launches
    with pytest.raises(KeyboardInterrupt) as interrupt:
        drive(InterruptedEngine(), clock, stops, lambda stop: None, batch=1,
              progress_label=robots_label(1))
    (bar,) = bars
    # closed (tqdm disables a bar it closes) while the traceback still holds it, after the
    # first launch was counted
    assert interrupt.traceback and bar.disable
    assert bar.n == (clock.ticks(0.1) if adaptive else 50)


def test_robots_label_counts_one_robot_in_the_singular():
    assert [robots_label(n) for n in (1, 2, 64)] == ["1 robot", "2 robots", "64 robots"]


def test_a_record_interval_longer_than_the_run_warns_and_one_as_long_does_not():
    """Records fall at whole multiples of the interval: one as long as the run records its end
    (no warning), a longer one only the start (warned, naming both); 0 asks for none. With
    fixed steps the run is the duration rounded to whole steps: 0.0099 s at 5-ms steps runs
    0.01 s and records it (it was warned as holding no record: an audit, 2026-12)."""
    from taichi_star.driver import check_run

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_run(SolverConfig(), 0.2, 0.2, 1)
        check_run(SolverConfig(), 0.2, 0.0, 1)
        check_run(SolverConfig(adaptive=True), 0.3, 0.1, 1)   # 0.3 / 0.1 = 2.9999999999999996
        warnings.filterwarnings("ignore", message="duration_s = 0.0099 s is not a whole number")
        check_run(SolverConfig(dt=0.005), 0.0099, 0.01, 1)
    with pytest.warns(RuntimeWarning, match=r"^record_interval_s = 0\.201 s is longer than "
                                            r"the 0\.2 s simulated \(duration_s = 0\.2 s\): no "
                                            r"record falls after the start"):
        check_run(SolverConfig(), 0.2, 0.201, 1)
    with pytest.warns(RuntimeWarning, match=r"^record_interval_s = 0\.01 s is longer than the "
                                            r"0\.005 s simulated \(duration_s = 0\.0074 s\)"):
        check_run(SolverConfig(dt=0.005), 0.0074, 0.01, 1)


def test_a_fixed_step_run_is_checked_against_the_step_counter_before_any_compute():
    """At most MAX_STEPS_PER_INSTANCE steps counted from t = 0, those already taken included:
    exactly the limit goes (warned as long work), one step more is refused naming the call,
    the steps taken and the batch's total. Steps of 1/32 s keep every duration exact."""
    import re

    from taichi_star.driver import check_run
    from taichi_star.timegrid import MAX_STEPS_PER_INSTANCE

    solver = SolverConfig(dt=1 / 32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        check_run(solver, (MAX_STEPS_PER_INSTANCE - 10) / 32, 0.0, 2, steps_taken=10)
    over = (MAX_STEPS_PER_INSTANCE - 9) / 32
    with pytest.raises(ValueError, match="^" + re.escape(
            f"duration_s = {over:g} s at dt = 0.03125 s (after the 10 steps taken) is 2.15e+09 "
            f"time steps per instance (4.29e+09 robot-steps for 2 instances)")):
        check_run(solver, over, 0.0, 2, steps_taken=10)
    # from t = 0: the whole limit is the run's own, and the message names no steps taken
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        check_run(solver, MAX_STEPS_PER_INSTANCE / 32, 0.0, 1)
    over = (MAX_STEPS_PER_INSTANCE + 1) / 32
    with pytest.raises(ValueError, match="^" + re.escape(
            f"duration_s = {over:g} s at dt = 0.03125 s is 2.15e+09 time steps per instance "
            f"(2.15e+09 robot-steps for 1 instance)")):
        check_run(solver, over, 0.0, 1)
    with pytest.raises(ValueError, match=r"^record_interval_s must be a whole number of steps"):
        check_run(SolverConfig(dt=1e-3), 0.2, 0.0015, 1)


def test_an_adaptive_run_is_refused_by_its_fewest_steps_and_warned_by_its_most():
    """Adaptive steps: the fewest (duration / dt_max, plus those taken) must fit the counter;
    the most (duration / dt_min) may not, which is said before the run; at exactly the limit
    nothing is said (dt_min 1/32 s, dt_max 3/64 s: exact quotients)."""
    import re

    from taichi_star.driver import check_run
    from taichi_star.timegrid import MAX_STEPS_PER_INSTANCE

    limit = MAX_STEPS_PER_INSTANCE
    solver = SolverConfig(adaptive=True, dt=1 / 32, dt_min=1 / 32, dt_max=3 / 64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_run(solver, (limit - 6) / 32, 0.0, 1, steps_taken=6)   # the most: the limit
    longer = (limit - 5) / 32
    with pytest.warns(RuntimeWarning, match="^" + re.escape(
            f"duration_s = {longer:g} s at dt_min = 0.03125 s could take 2.15e+09 steps per "
            f"instance: an instance that reaches {limit}")):
        check_run(solver, longer, 0.0, 1, steps_taken=6)
    fewest_over = limit * 3 / 64              # limit steps at dt_max, 6 more taken before
    for taken, after in ((6, ", after the 6 steps taken"), (None, "")):
        duration = fewest_over if taken else fewest_over + 3 / 64
        with pytest.raises(ValueError, match="^" + re.escape(
                f"duration_s = {duration:g} s at dt_max = 0.046875 s (the adaptive lower "
                f"bound{after}) is 2.15e+09 time steps per instance (2.15e+09 robot-steps for 1 "
                f"instance); the limit")):
            check_run(solver, duration, 0.0, 1, steps_taken=taken)


def test_adaptive_records_closer_than_dt_max_bound_the_steps_and_closer_than_dt_min_are_refused():
    """Every record is a step end: with records closer than dt_max the fewest steps are the
    records (a run of 0.05 s recorded every 1e-8 s asked 5e6 records and steps below dt_min, and
    ran on unrefused); a record interval of dt_min itself is accepted, one below refused, and
    one of dt_max or more leaves the estimate at dt_max (dt_min 1/1024 s, dt_max 1/64 s,
    exact quotients)."""
    import re

    from taichi_star.driver import check_run
    from taichi_star.timegrid import MAX_STEPS_PER_INSTANCE

    solver = SolverConfig(adaptive=True, dt=1 / 64, dt_min=1 / 1024, dt_max=1 / 64)
    check_run(solver, 0.5, 1 / 1024, 1)
    with pytest.raises(ValueError, match="^" + re.escape(
            "record_interval_s must be at least dt_min = 0.000976562 s with adaptive steps (a "
            "step ends on every record), got 0.0009765624999999999")):
        check_run(solver, 0.5, 1 / 1024 * (1 - 1e-16), 1)
    over = (MAX_STEPS_PER_INSTANCE + 1) / 1024      # one record more than the counter holds
    with pytest.raises(ValueError, match="^" + re.escape(
            f"duration_s = {over:g} s at a record every 0.000976562 s, each a step end (the "
            f"adaptive lower bound) is 2.15e+09 time steps per instance")):
        check_run(solver, over, 1 / 1024, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # the most steps, at dt_min, may not fit
        check_run(solver, over, 1 / 64, 1)                # records at dt_max: the fewest at dt_max
        with pytest.raises(ValueError, match=re.escape("at dt_max = 0.015625 s (the adaptive")):
            check_run(solver, (MAX_STEPS_PER_INSTANCE + 1) / 64, 1 / 32, 1)


def test_stops_fall_on_the_record_grid_from_the_first_one_asked():
    fixed = Clock(SolverConfig(dt=1e-3), 0.01)
    assert fixed.stops_every(0.004) == [0, 4, 8] and fixed.stops_every(0.004, first=1) == [4, 8]
    adaptive = Clock(SolverConfig(adaptive=True), 0.3)
    assert adaptive.stops_every(0.1, first=2) == pytest.approx([0.2, 0.3], rel=1e-15)
    assert adaptive.time_of(0.25) == 0.25 and fixed.time_of(4) == pytest.approx(0.004)


def test_next_own_stops_go_to_each_groups_first_own_stop_at_or_after_the_stop():
    """An adaptive instance passes the stops of other instances (their cycle boundaries) and
    goes to its own next one: at a stop of its own it goes exactly there."""
    from taichi_star.driver import NextOwnStops

    stops = [0.0, 0.25, 0.4, 0.5, 0.75, 0.8]
    own = [np.array([0, 2, 5]), np.array([0, 1, 3, 4, 5])]  # a period of 0.4 s; of 0.25 s
    going = NextOwnStops(stops, own, np.array([1, 0, 1]))
    np.testing.assert_array_equal(going.at(1), [0.25, 0.4, 0.25])
    np.testing.assert_array_equal(going.at(2), [0.5, 0.4, 0.5])  # its own: exactly there
    np.testing.assert_array_equal(going.at(3), [0.5, 0.8, 0.5])
    np.testing.assert_array_equal(going.at(5), [0.8, 0.8, 0.8])
    with pytest.raises(ValueError, match="must end on the last stop"):
        NextOwnStops(stops, [np.array([0, 2])], np.array([0]))


@pytest.mark.parametrize("instances, shown", [(1499, False), (1500, True)])
def test_a_run_estimated_at_thirty_seconds_or_more_shows_progress_by_default(instances, shown):
    """progress=None (the default) draws a bar from AUTO_PROGRESS_S = 30 s of estimated work
    on: one second of 1-ms steps is 1,000 steps, and 1,500 instances of it 1.5e6 robot-steps,
    30 s at the estimate's 5e4 robot-steps/s; a bool is taken as given, anything else refused."""
    from taichi_star.driver import AUTO_PROGRESS_S, fewest_steps, shows_progress
    from taichi_star.timegrid import ESTIMATE_ROBOT_STEPS_PER_S

    assert AUTO_PROGRESS_S * ESTIMATE_ROBOT_STEPS_PER_S == 1500 * 1000
    robot_steps = instances * fewest_steps(SolverConfig(dt=1e-3), 1.0, 0.0)[0]
    assert shows_progress(None, robot_steps) is shown
    assert shows_progress(not shown, robot_steps) is (not shown)
    with pytest.raises(ValueError, match="^progress must be True or False, got 'no'$"):
        shows_progress("no", robot_steps)


@pytest.mark.parametrize("interval", [1e-310, 5e-324])
@pytest.mark.parametrize("adaptive", [False, True])
def test_a_subnormal_record_interval_is_refused_as_a_value_error(interval, adaptive):
    """A record interval of a subnormal number of seconds made the count of records an
    OverflowError (int of an infinite quotient) before the interval's own checks (an audit,
    2026-12): refused by those, as ValueErrors naming record_interval_s."""
    from taichi_star.driver import check_run

    solver = SolverConfig(adaptive=adaptive)
    with pytest.raises(ValueError, match=r"^record_interval_s must be "):
        check_run(solver, 1.0, interval, 1)


@pytest.mark.parametrize("phases, steps, read_back", [
    ((0.0, 0.0, 0.0, 0.0), 0, True),      # nothing done by the call: tables read back
    ((0.0, 0.0, 0.0, 0.0), 1, False),     # a step counted: simulated (however fast)
    ((0.5, 0.0, 0.0, 0.0), 0, False),     # set up, no step taken (every robot failed at once)
])
def test_a_timing_of_nothing_done_says_so_rather_than_a_rate_of_nan(phases, steps, read_back):
    text = str(RunTiming(*phases, robot_steps=steps))
    assert (text == "nothing simulated by this call (its tables read back)") is read_back
    assert ("robot-steps/s" in text) is not read_back
