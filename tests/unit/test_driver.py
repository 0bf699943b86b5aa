"""The run driver's progress bar (taichi_star.driver) with a stand-in engine: its count ends
exactly on its total, whatever the float sums of the stops' times."""

import warnings

import pytest

from taichi_star.driver import Clock, drive, robots_label
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


def test_robots_label_counts_one_robot_in_the_singular():
    assert [robots_label(n) for n in (1, 2, 64)] == ["1 robot", "2 robots", "64 robots"]


def test_a_record_interval_longer_than_the_run_warns_and_one_as_long_does_not():
    """Records fall at whole multiples of the interval: one as long as the run records its end
    (no warning), a longer one only the start (warned, naming both); 0 asks for none."""
    from taichi_star.driver import check_run

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_run(SolverConfig(), 0.2, 0.2, 1)
        check_run(SolverConfig(), 0.2, 0.0, 1)
        check_run(SolverConfig(adaptive=True), 0.3, 0.1, 1)   # 0.3 / 0.1 = 2.9999999999999996
    with pytest.warns(RuntimeWarning, match=r"^record_interval_s = 0\.201 s is longer than "
                                            r"duration_s = 0\.2 s: the trajectory holds only the "
                                            r"start"):
        check_run(SolverConfig(), 0.2, 0.201, 1)
