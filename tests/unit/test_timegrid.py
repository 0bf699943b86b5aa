"""The time grid: which times are whole steps, and the record intervals it offers.

Exact checks: the intervals are compared with the integer multiples of dt they must be, and the
tolerance cases sit far inside and far outside STEP_TOLERANCE (1e-9 relative)."""

import math
import warnings

import numpy as np
import pytest

from taichi_star.timegrid import (MAX_STEPS_PER_INSTANCE, STEP_TOLERANCE, LongWorkWarning,
                                  check_duration, check_steps, check_work, interval_for_count,
                                  multiples_within, nearest_interval, on_grid, step_counts,
                                  whole_steps)


@pytest.mark.parametrize("time_s, dt, expected", [
    (3.3, 1e-3, 3300),             # 3.3 / 1e-3 = 3299.9999999999995 in floats: still a step
    (0.05, 1e-3, 50),
    (0.0, 1e-3, 0),
    (-0.002, 1e-3, -2),
    (0.0015, 1e-3, None),          # half a step off
    (1.0 + 1e-6, 1e-3, None),      # 1e-6 relative: a thousand times the tolerance
    (1.0 + 1e-12, 1e-3, 1000),     # 1e-12 relative: a thousandth of it
])
def test_whole_steps(time_s, dt, expected):
    assert whole_steps(time_s, dt) == expected


def test_on_grid_tolerance_is_relative_but_at_least_one_step():
    """The tolerance is STEP_TOLERANCE × max(1, |count|): a time at exactly that distance from a
    whole count is on the grid (≤): 1e-9 of a step from 0; 5e-7 steps from 1,000 (within its
    1e-6), and 1.5e-9 of one step is not (the minimum is one step's worth, not two)."""
    assert on_grid(1e-9, 1.0) and not on_grid(1.5e-9, 1.0)
    assert not on_grid(1.0 + 1.5e-9, 1.0)
    assert on_grid(1000.0 + 5e-7, 1.0) and not on_grid(1000.0 + 1.5e-6, 1.0)


def test_on_grid_tolerance_is_at_most_a_thousandth_of_a_step():
    """Past 10⁶ steps the relative tolerance is capped at MOST_OFF_GRID_STEPS of one step: at
    10⁹ steps it alone took half a step off for a whole number (an audit). Offsets of 2⁻¹⁰
    and 2⁻⁹ steps are exact in binary beside 10⁹ (its float spacing is 2⁻²³): 2⁻¹⁰
    (below 10⁻³) is on the grid, 2⁻⁹ (above) is not."""
    from taichi_star.timegrid import MOST_OFF_GRID_STEPS

    assert 2 ** -10 < MOST_OFF_GRID_STEPS < 2 ** -9
    billion = 1e9
    assert not on_grid(billion + 0.5, 1.0) and whole_steps(billion + 0.5, 1.0) is None
    assert on_grid(billion + 2 ** -10, 1.0) and not on_grid(billion + 2 ** -9, 1.0)
    assert on_grid(1e6 + 9e-4, 1.0)  # 1e-9 relative is 1e-3 of a step here: both rules agree


def test_step_counts_match_whole_steps_and_mark_off_grid_with_zero():
    periods = np.array([3.15, 0.0015, 2.0, 0.0])
    assert step_counts(periods, 1e-3).tolist() == [3150, 0, 2000, 0]
    assert on_grid(periods, 1e-3).tolist() == [True, False, True, True]


def test_multiples_within_counts_a_duration_of_exact_multiples_whatever_the_rounding():
    # 0.3 / 0.1 = 2.9999999999999996 in floats: three intervals, not two
    assert multiples_within(0.3, 0.1) == 3
    assert multiples_within(0.3 * (1 - 10 * STEP_TOLERANCE), 0.1) == 2
    assert multiples_within(0.35, 0.1) == 3


@pytest.mark.parametrize("interval_s, dt, steps", [
    (0.05, 1e-3, 50), (0.0504, 1e-3, 50), (0.0506, 1e-3, 51), (1e-5, 1e-3, 1), (0.1, 2.5e-4, 400)])
def test_nearest_interval_is_a_whole_number_of_steps_and_accepted(interval_s, dt, steps):
    interval = nearest_interval(interval_s, dt)
    assert interval == steps * dt
    assert check_steps("record_interval_s", interval, dt) == steps


@pytest.mark.parametrize("duration_s, count, dt, steps", [
    (3.15, 100, 1e-3, 31), (3.15, 10_000, 1e-3, 1), (1.0, 3, 1e-3, 333), (0.01, 10, 1e-3, 1)])
def test_interval_for_count_gives_at_least_count_records(duration_s, count, dt, steps):
    interval = interval_for_count(duration_s, count, dt)
    assert interval == steps * dt
    total = round(duration_s / dt)
    assert total // steps >= min(count, total)


def test_check_steps_names_the_parameter_and_the_nearest_valid_interval():
    with pytest.raises(ValueError, match=r"record_interval_s must be a whole number of steps "
                                         r"\(dt = 0.001 s\), got 0.0015 \(nearest valid: 0.002 s\)"):
        check_steps("record_interval_s", 0.0015, 1e-3)
    with pytest.raises(ValueError, match=r"got 0.0001 \(nearest valid: 0.001 s\)"):
        check_steps("record_interval_s", 1e-4, 1e-3)  # zero steps


def test_check_duration_refuses_less_than_one_step():
    with pytest.warns(RuntimeWarning, match="not a whole number of steps"):
        assert check_duration(0.0006, 1e-3) == 1  # rounded to whole steps
    with pytest.raises(ValueError, match=r"duration_s must be at least one step \(dt = 0.001 s\)"):
        check_duration(0.0004, 1e-3)


@pytest.mark.parametrize("duration_s, dt, steps, warned", [
    (3.3, 1e-3, 3300, False),           # 3299.9999999999995 steps in floats: on the grid
    (1000.0 + 5e-7, 1.0, 1000, False),  # within STEP_TOLERANCE × 1000 steps (1e-6): on it
    (1000.0 + 1.5e-6, 1.0, 1000, True),  # just past it
    (0.0015, 1e-3, 2, True),            # half a step: rounded up (to even)
    (0.0025, 1e-3, 2, True),            # rounded down (to even)
])
def test_a_duration_off_the_step_grid_is_rounded_with_a_warning_saying_what_is_simulated(
        duration_s, dt, steps, warned):
    """A duration off the grid of dt is rounded to whole steps, and the warning names the
    duration asked and the steps and time simulated (ten Simulator.advance(0.0015) at 1-ms steps
    advanced 0.02 s without a word: an audit, 2026-12); one on the grid is silent (the
    tolerance's edge as in test_on_grid_tolerance_is_relative_but_at_least_one_step)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert check_duration(duration_s, dt) == steps
    messages = [str(warning.message) for warning in caught]
    if warned:
        assert messages == [f"duration_s = {duration_s!r} s is not a whole number of steps "
                            f"(dt = {dt:g} s): {steps} steps, {steps * dt!r} s, are simulated "
                            f"(timegrid.nearest_interval gives a duration on the grid)"]
    else:
        assert messages == []


def test_long_but_possible_work_starts_with_a_warning_giving_its_estimate():
    """Up to WARN_ROBOT_STEPS robot-steps a run starts silently; one step more (× the batch)
    warns with the estimated hours at the stated rate (1e10 / 5e4 / 3600 = 55.6 h)."""
    from taichi_star.timegrid import WARN_ROBOT_STEPS

    assert WARN_ROBOT_STEPS == 1e10
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_work("duration_s = 1e6 s at dt = 0.001 s", 1e9, 10)  # exactly at the threshold
        check_work("duration_s = 2e6 s at dt = 0.001 s", 2e9)  # one instance, under it
    # of its own category, a RuntimeWarning, so that a script meaning a long run silences it
    # alone
    with pytest.warns(LongWorkWarning, match=r"duration_s = x is 1e\+10 robot-steps: about "
                                             r"55.6 h at 50000 robot-steps/s"):
        check_work("duration_s = x", 1e9 + 1, 10)
    assert issubclass(LongWorkWarning, RuntimeWarning)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.simplefilter("ignore", LongWorkWarning)
        check_work("duration_s = x", 1e9 + 1, 10)


def test_work_no_machine_measured_finishes_in_30_days_is_refused_with_its_estimate():
    """Past REFUSE_ROBOT_STEPS (3.6e6 robot-steps/s × 30 days = 9.3312e12) a call is refused
    before any compute, with its days at the fastest rate and its years on a 2-core CPU; at
    exactly the limit it starts (with the long-work warning). 933,120,000 steps × 10,000
    instances is the limit to the step, under the step counter's 2.1e9 per instance."""
    from taichi_star.timegrid import REFUSE_ROBOT_STEPS

    assert REFUSE_ROBOT_STEPS == 9_331_200_000_000.0
    with pytest.warns(RuntimeWarning, match="robot-steps: about"):
        check_work("x", 933_120_000, 10_000)
    with pytest.raises(ValueError) as error:
        check_work("x", 933_120_001, 10_000)
    # 9.3312e12 / 5e4 robot-steps/s is 5.91 years
    assert str(error.value) == (
        "x is 9.33e+12 robot-steps: about 30 days even at 3.6e+06 robot-steps/s (the fastest "
        "measured, one H100 in f32) and 5.91 years on a 2-core CPU; the limit is 9.33e+12 "
        "robot-steps a call (30 days at that rate): run fewer instances or a shorter duration, "
        "or a run_batch spread over several machines")


def test_a_cpu_calls_work_is_bounded_by_its_cores_to_the_step(monkeypatch):
    """On the CPU the bound is 2.5e5 robot-steps/s a core × 30 days: with 2 cores exactly
    1.296e12 robot-steps (648,000 steps × 2,000,000 instances) start, with the long-work
    warning, and one step more is refused; on 3 cores the same work starts. A GPU arch and
    None keep the H100's bound."""
    from taichi_star import timegrid
    from taichi_star.timegrid import REFUSE_ROBOT_STEPS, refuse_robot_steps

    monkeypatch.setattr(timegrid, "usable_cores", lambda: 2)
    assert refuse_robot_steps("cpu") == 1_296_000_000_000.0
    assert refuse_robot_steps("gpu") == refuse_robot_steps(None) == REFUSE_ROBOT_STEPS
    with pytest.warns(LongWorkWarning):
        check_work("x", 648_000, 2_000_000, "cpu")
    with pytest.raises(ValueError, match=r"^x is 1\.3e\+12 robot-steps: about 30 days even at "
                                         r"5e\+05 robot-steps/s \(this machine's 2 CPU cores"):
        check_work("x", 648_001, 2_000_000, "cpu")
    with pytest.warns(LongWorkWarning):
        check_work("x", 648_001, 2_000_000, "gpu")
        check_work("x", 648_001, 2_000_000)
    monkeypatch.setattr(timegrid, "usable_cores", lambda: 3)
    with pytest.warns(LongWorkWarning):
        check_work("x", 648_001, 2_000_000, "cpu")
    # never above any machine's bound: 16 cores × 2.5e5 would be 4e6 > the H100's 3.6e6
    monkeypatch.setattr(timegrid, "usable_cores", lambda: 16)
    assert refuse_robot_steps("cpu") == REFUSE_ROBOT_STEPS


def test_usable_cores_counts_the_cores_this_process_may_run_on():
    import os

    from taichi_star.timegrid import usable_cores

    expected = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
        else os.cpu_count()
    assert usable_cores() == expected and 1 <= usable_cores() <= os.cpu_count()


def test_the_cpu_bound_per_core_is_at_least_every_cpu_rate_per_core_measured():
    """No committed CPU benchmark row (arch cpu, with its cores) may run faster per core than
    the CPU's refusal assumes."""
    from pathlib import Path

    import pandas as pd

    from taichi_star.timegrid import FASTEST_CPU_CORE_ROBOT_STEPS_PER_S

    results = Path(__file__).resolve().parents[2] / "results"
    per_core = []
    for path in results.rglob("*.csv"):
        with path.open() as table:
            columns = table.readline().strip().split(",")
        if {"robot_steps_per_s", "arch", "cores"} <= set(columns):
            rows = pd.read_csv(path, usecols=["robot_steps_per_s", "arch", "cores"])
            rows = rows[rows["arch"] == "cpu"]
            per_core.extend(rows["robot_steps_per_s"] / rows["cores"])
    # the lagged Jacobian's plain call on 2 cores, 113,623 a core, is among them
    assert len(per_core) > 100 and max(per_core) > 1.1e5
    assert max(per_core) <= FASTEST_CPU_CORE_ROBOT_STEPS_PER_S


def test_the_refusals_rate_is_at_least_every_rate_measured():
    """The refusal assumes the fastest machine measured: no committed benchmark row may be
    faster (else work that machine finishes within the 30 days would be refused)."""
    from pathlib import Path

    import pandas as pd

    from taichi_star.timegrid import FASTEST_ROBOT_STEPS_PER_S

    def header(path):
        with path.open() as table:
            return table.readline()

    results = Path(__file__).resolve().parents[2] / "results"
    rates = [pd.read_csv(path, usecols=["robot_steps_per_s"])["robot_steps_per_s"].max()
             for path in results.rglob("*.csv")
             if "robot_steps_per_s" in header(path).split(",")]
    assert len(rates) > 20 and max(rates) > 3.4e6   # the H100's f32 chord row is among them
    assert max(rates) <= FASTEST_ROBOT_STEPS_PER_S


def test_work_up_to_exactly_the_step_counter_is_accepted_and_past_it_refused():
    """MAX_STEPS_PER_INSTANCE steps (2³¹ − 1: the int32 counter) are allowed, one more or an
    infinite estimate is refused with the estimate, the batch's total and the limit."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # 2.1e9 steps: the long-work warning
        check_work("duration_s = x", MAX_STEPS_PER_INSTANCE)
        check_work("duration_s = x", MAX_STEPS_PER_INSTANCE + 0.4)   # rounds to the limit
    with pytest.raises(ValueError, match=r"^duration_s = x is 2\.15e\+09 time steps per instance "
                                         r"\(4\.29e\+09 robot-steps for 2 instances\); the limit is "
                                         r"2147483647 steps per instance \(the int32 step counter\)$"):
        check_work("duration_s = x", MAX_STEPS_PER_INSTANCE + 1, 2)
    with pytest.raises(ValueError, match=r"^duration_s = y is inf time steps per instance; the"):
        check_work("duration_s = y", float("inf"))


def test_a_nan_step_count_is_named_and_an_interval_is_a_python_float():
    """check_work named `name`'s count for steps = NaN ("x is nan time steps"), and
    nearest_interval gave a NumPy float32 for a float32 dt (an audit, 2026-12)."""
    with pytest.raises(ValueError, match=r"^steps must be a real number >= 0 .*got nan$"):
        check_work("x", math.nan)
    interval = nearest_interval(1e-3, np.float32(1e-3))
    assert type(interval) is float and interval == float(np.float32(1e-3))


@pytest.mark.parametrize("duration_s, steady_from_cycle, solver, period, expected", [
    (0.327, 1, None, 0.1635, [0]),  # two whole cycles: cycle 1 is whole, its speed defined
    (0.326, 1, None, 0.1635, []),   # one whole cycle only: NaN whatever the grid
    (0.327, 2, None, 0.1635, []),   # no whole cycle after cycle 2
    (0.491, 2, None, 0.1635, [0]),  # three whole cycles (0.4905 s)
    (0.327, 0, None, 0.1635, [0]),
    (0.1635, 0, None, 0.1635, [0]),  # one cycle, from cycle 0; 0.1635 s rounds to 164 steps
    (0.327, 1, None, 0.164, []),    # a period of whole steps (164)
    (0.3268, 1, None, 0.1635, [0]),  # simulates 0.327 s (whole 1-ms steps): two cycles
    (0.327, 1, "adaptive", 0.1635, []),  # adaptive steps stop at every cycle start
])
def test_off_grid_periods_are_those_whose_steady_speed_the_grid_alone_leaves_nan(
        duration_s, steady_from_cycle, solver, period, expected):
    """`simulation.off_grid_periods`: the instances whose period is not a whole number of
    fixed steps, in a run that holds a whole cycle after `steady_from_cycle` (their steady
    speeds came out NaN, status ok, without a warning: an audit)."""
    from taichi_star import SolverConfig, StarParams
    from taichi_star.simulation import off_grid_periods

    config = SolverConfig(integrator="bdf2", adaptive=True) if solver else SolverConfig()
    on_grid_robot = StarParams(period=0.164)
    assert off_grid_periods([StarParams(period=period), on_grid_robot], duration_s, config,
                            steady_from_cycle) == expected


@pytest.mark.parametrize("duration_s, steady_from_cycle, adaptive, expected", [
    (0.5 - 2 ** -20, 1, True, [0]),   # dt_min short of two periods: cycle 1 left out
    (0.5 - 2 ** -19, 1, True, []),    # two dt_min short: an end the user chose
    (0.5, 1, True, []),               # the whole two periods
    (0.5 - 2 ** -20, 2, True, []),    # the window starts at cycle 2: NaN either way
    (0.5 - 2 ** -20, 0, True, [0]),
    (0.25 - 2 ** -20, 0, True, [0]),  # short of the first period, from cycle 0
    (0.5 - 2 ** -20, 1, False, []),   # fixed steps round it to whole steps (and warn)
])
def test_cycles_cut_short_are_adaptive_runs_ending_within_dt_min_of_a_periods_end(
        duration_s, steady_from_cycle, adaptive, expected):
    """`simulation.cycles_cut_short`: an adaptive run that ends at most dt_min (here 2⁻²⁰ s,
    every time exact in binary) before a whole number of periods leaves the last cycle out of
    its steady speeds (a duration of 0.9 s held in float32 did, silently: an audit)."""
    from taichi_star import SolverConfig, StarParams
    from taichi_star.simulation import cycles_cut_short

    solver = (SolverConfig(integrator="bdf2", adaptive=True, dt_min=2 ** -20) if adaptive
              else SolverConfig(dt=2 ** -10))
    other = StarParams(period=0.3)  # 0.5 s is far from a whole number of its periods
    assert cycles_cut_short([StarParams(period=0.25), other], duration_s, solver,
                            steady_from_cycle) == expected


# --------------------------------------------------------------------------- the mesh's work

def test_a_steps_work_is_the_robots_nodes_over_the_paper_robots():
    """The rates count the paper robot's steps (193 nodes, StarParams' defaults); a robot of N
    nodes weighs N / 193 of them: exactly 1 for the paper robot and for None, 2 for 386 nodes,
    41.7 for n_arc 1000 (8,049 nodes). A count of nodes is a finite number >= 1 (the
    boundary included), anything else is refused naming nodes."""
    from taichi_star import StarParams
    from taichi_star.timegrid import PAPER_NODES, step_work

    assert PAPER_NODES == StarParams().n_nodes == 193
    assert step_work(None) == step_work(PAPER_NODES) == 1.0
    assert step_work(386) == 2.0
    assert step_work(StarParams(n_arc=1000).n_nodes) == pytest.approx(8049 / 193, rel=1e-15)
    assert step_work(1) == 1 / 193
    for bad in (0.999, 0, -193, math.nan, math.inf, "193", True):
        with pytest.raises(ValueError, match=r"^nodes must be a finite number >= 1"):
            step_work(bad)


def test_work_of_a_finer_mesh_is_refused_where_the_paper_robots_would_start():
    """At 386 nodes (twice the work of a step) the bound of 9.3312e12 paper-robot steps holds
    4.6656e12 robot-steps: 466,560 steps × 10,000,000 instances start (with the long-work
    warning), one step more each is refused, naming the mesh, its work, the rate and the limit
    for it; the paper robot's same work starts. A nodes count too far off is refused by name."""
    from taichi_star.timegrid import REFUSE_ROBOT_STEPS

    with pytest.warns(LongWorkWarning):
        check_work("x", 466_560, 10_000_000, None, 386)
    with pytest.raises(ValueError) as error:
        check_work("x", 466_561, 10_000_000, None, 386)
    assert str(error.value) == (
        "x is 4.67e+12 robot-steps of robots of 386 nodes (a step 2 times the work of one of "
        "the paper robot's 193): about 30 days even at 1.8e+06 robot-steps/s (the fastest "
        "measured, one H100 in f32; divided by the work of a step) and 5.91 years on a 2-core "
        "CPU; the limit is 4.67e+12 robot-steps a call (30 days at that rate): run fewer "
        "instances or a shorter duration, or a run_batch spread over several machines")
    assert 466_561 * 10_000_000 * 2 > REFUSE_ROBOT_STEPS >= 466_560 * 10_000_000 * 2
    with pytest.warns(LongWorkWarning):
        check_work("x", 466_561, 10_000_000, None, 193)
        check_work("x", 466_561, 10_000_000)
    with pytest.raises(ValueError, match=r"^nodes must be a finite number >= 1"):
        check_work("x", 10, 10, None, 0)


def test_the_long_work_warning_and_the_progress_bar_weigh_the_mesh():
    """5e9 robot-steps of 386-node robots are the warning's 1e10 paper-robot steps exactly: no
    warning; one step more warns, with the hours at the rate for that mesh (25,000
    robot-steps/s: 55.6 h). The progress bar's automatic choice (30 s at 5e4 paper-robot
    steps/s) weighs them the same: 750,000 robot-steps of 386 nodes are 30 s (a bar),
    749,999 are not."""
    from taichi_star.driver import AUTO_PROGRESS_S, shows_progress
    from taichi_star.timegrid import warn_long_work

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_long_work("x", 5e9, 386)
    with pytest.warns(LongWorkWarning, match=r"^x is 5e\+09 robot-steps of robots of 386 nodes "
                                             r"\(a step 2 times .*\): about 55\.6 h at "
                                             r"2\.5e\+04 robot-steps/s"):
        warn_long_work("x", 5e9 + 1, 386)
    assert AUTO_PROGRESS_S == 30.0
    assert shows_progress(None, 750_000, 386) and not shows_progress(None, 749_999, 386)
    assert not shows_progress(None, 1_499_999) and shows_progress(None, 1_500_000)


MESH_WORK_TOLERANCE = 0.25
"""How far a mesh's measured cost of a step per node may be from the median over the meshes
(a fraction of it): `step_work` holds it constant; a part of a step does not grow with the
nodes (the step loop, the convergence test) and the caches favour some sizes, and this
machine's speed drifts by up to 20 % between measurements minutes apart (docs/performance.md),
which one row alone can carry; measured within 0.21 of it from 65 to 3,249 nodes."""


def test_the_rule_for_a_steps_work_holds_on_every_mesh_measured():
    """results/bench_meshes/bench.csv (section "mesh": the benchmark robot on n_arc 2 to 400
    at B = 64, 65 to 3,249 nodes, the paper robot's among them): each mesh's µs per robot-step
    per node is within MESH_WORK_TOLERANCE of their median, as a work proportional to the nodes
    (`step_work`) makes it."""
    from pathlib import Path

    import pandas as pd

    from taichi_star.timegrid import PAPER_NODES

    path = Path(__file__).resolve().parents[2] / "results" / "bench_meshes" / "bench.csv"
    rows = pd.read_csv(path)
    rows = rows[rows["section"] == "mesh"]
    assert len(rows) >= 5 and rows["n_nodes"].min() < 100 and rows["n_nodes"].max() > 3000
    assert PAPER_NODES in set(rows["n_nodes"])
    per_node = rows["step_us"] / rows["n_nodes"]
    deviation = per_node / per_node.median() - 1
    assert (deviation.abs() <= MESH_WORK_TOLERANCE).all(), \
        pd.DataFrame({"n_nodes": rows["n_nodes"], "per_node_us": per_node})


def test_a_batchs_nodes_are_its_parts_weighted_by_their_robot_steps():
    """500 robot-steps of 193 nodes and 1,000 of 433: 353 (what gives their work under
    `step_work`); one mesh gives its nodes exactly, where the weighted sum would round
    (25.2 × 193 × 2 / 50.4 is not 193 in floats: the paper robot's estimates named a mesh "of
    193 nodes on average"); no work gives None."""
    from taichi_star.timegrid import weighted_nodes

    assert weighted_nodes([(500, 193), (1000, 433)]) == 353.0
    assert (25.2 * 193 + 25.2 * 193) / 50.4 != 193
    assert weighted_nodes([(25.2, 193), (25.2, 193)]) == 193
    assert weighted_nodes([]) is None and weighted_nodes([(0, 193)]) is None
