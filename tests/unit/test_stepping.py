"""The adaptive step-size control (taichi_star.stepping) on hand-worked cases: every expected
value below follows from the rules in the functions' docstrings by exact arithmetic, so the
comparisons allow only the rounding of a few operations (1e-15 relative)."""

import math

import pytest
import taichi as ti

from taichi_star import stepping

TOL = 1e-6  # m, the error tolerance of these cases
DT_MIN = 2 ** -20  # s, the smallest step of the acceptance cases (binary-exact)


@ti.kernel
def _step_end_kernel(start: float, proposed: float, target: float, firing: int,
                     firing_step: float, slack: float) -> float:
    return stepping.step_end(start, proposed, target, firing, firing_step, slack)


def _step_end(start, proposed, target, firing, firing_step, slack=0.0):
    return _step_end_kernel(start, proposed, target, firing, firing_step, slack)


@ti.kernel
def _accepts(error: float, h: float, proposed: float) -> int:
    return stepping.accepts(error, TOL, h, proposed, DT_MIN)


@ti.kernel
def _is_sliver(start: float, end: float, target: float, limit: float, least: float,
               most: float) -> int:
    return stepping.is_sliver(start, end, target, limit, least, most)


@ti.kernel
def _accepted_size(h: float, proposed: float, error: float, firing: int) -> float:
    return stepping.accepted_size(h, proposed, error, TOL, firing, 1e-6, 0.05)


@ti.kernel
def _rejected_size(h: float, error: float) -> float:
    return stepping.rejected_size(h, error, TOL, 1e-6)


@pytest.mark.parametrize("proposed, target, firing, expected", [
    (0.01, 1.0, 0, 0.01),      # far from the stop: the proposed step
    (0.01, 0.008, 0, 0.008),   # would pass the stop: lands on it
    (2 ** -7, 2 ** -7, 0, 2 ** -7),  # ends exactly on the stop (binary-exact): lands on it
    (0.01, 0.012, 0, 0.006),   # would leave 0.002 < a quarter step: the rest split in two
    (2 ** -7, 1.25 * 2 ** -7, 0, 2 ** -7),  # leaves exactly a quarter step (binary-exact): kept
    (0.01, 0.0105, 1, 0.0095),  # a firing: end dt = 0.001 short of it
    (0.01, 0.0015, 1, 0.00075),  # a firing within 2 dt: halfway there
    (0.01, 0.0008, 1, 0.0008),  # a firing within dt: on it
])
def test_step_end(taichi_cpu, proposed, target, firing, expected):
    assert _step_end(0.0, proposed, target, firing, 0.001) == pytest.approx(expected, rel=1e-15)


def test_a_firing_exactly_one_firing_step_away_is_reached_in_one_step(taichi_cpu):
    """The approach splits only when the firing is more than firing_step away (>): exactly
    firing_step away the step ends on it; with a firing step one ulp shorter it stops halfway
    (binary-exact values: the comparisons are exact)."""
    away = 2 ** -10
    assert _step_end(0.0, 0.01, away, 1, away) == away
    assert _step_end(0.0, 0.01, away, 1, away * (1 - 2 ** -52)) == away / 2
    # with a slack (dt_min = dt_max: a rounding's), a firing that far past firing_step is
    # still reached in one step, one a hair farther is not
    assert _step_end(0.0, 0.01, away, 1, away * (1 - 2 ** -52), away * 2 ** -52) == away
    assert _step_end(0.0, 0.01, away, 1, away * (1 - 2 ** -51), away * 2 ** -52) == away / 2
    # and a step that ends within it short of a stop ends on the stop (without: the rest,
    # under a quarter step, is split in two)
    short = away * (1 - 2 ** -52)
    assert _step_end(0.0, short, away, 0, 0.001, away * 2 ** -52) == away
    assert _step_end(0.0, short, away, 0, 0.001) == away / 2


@pytest.mark.parametrize("h, proposed, error, firing, expected", [
    (0.01, 0.01, TOL / 4, 0, 0.01 * 1.8),   # 0.9·√4
    (0.01, 0.01, 0.0, 0, 0.02),             # no error: doubles
    (0.04, 0.04, 1e-12, 0, 0.05),           # at most dt_max
    (0.004, 0.01, TOL / 4, 0, 0.01 * 1.8),  # cut short to land: grows from the proposed size
    (0.004, 0.01, TOL / 4, 1, 0.004 * 1.8),  # cut short by a firing: from its own size
    (0.004, 0.01, TOL, 0, 0.004 * 0.9),     # shrinking: from its own size
    (4e-6, 4e-6, 100 * TOL, 0, 1e-6),       # shrunk by the least factor 0.2 below dt_min: dt_min
])
def test_accepted_size(taichi_cpu, h, proposed, error, firing, expected):
    assert _accepted_size(h, proposed, error, firing) == pytest.approx(expected, rel=1e-15)


@pytest.mark.parametrize("h, error, expected", [
    (0.01, 2 * TOL, 0.01 * 0.9 / math.sqrt(2)), (0.01, 100 * TOL, 0.01 * 0.2),
    (4e-6, 100 * TOL, 1e-6),    # 0.2 × 4e-6 s is under dt_min = 1e-6 s: dt_min
])
def test_rejected_size(taichi_cpu, h, error, expected):
    assert _rejected_size(h, error) == pytest.approx(expected, rel=1e-15)


@pytest.mark.parametrize("error, h, proposed, kept", [
    (TOL, 0.01, 0.01, True),                   # the error exactly at the tolerance: kept
    (TOL * (1 + 2 ** -40), 0.01, 0.01, False),  # just over it: redone
    (2 * TOL, DT_MIN, DT_MIN, True),           # over it at exactly dt_min: kept (cannot shrink)
    # just above dt_min, as set and as taken: redone smaller
    (2 * TOL, DT_MIN * (1 + 2 ** -30), DT_MIN * (1 + 2 ** -30), False),
    (2 * TOL, 0.5 * DT_MIN, 0.01, True),       # cut below dt_min to land on a stop: kept
    # set at dt_min, taken a hair longer (end - start rounded up): kept, not redone forever
    (2 * TOL, DT_MIN * (1 + 2 ** -30), DT_MIN, True),
])
def test_accepts(taichi_cpu, error, h, proposed, kept):
    # exact comparisons of binary-exact or nearly equal values: no tolerance involved
    assert bool(_accepts(error, h, proposed)) is kept


SLIVER = 2 ** -46  # the relative limit of the sliver cases (64 f64 roundings, binary-exact)


@pytest.mark.parametrize("start, end, target, sliver", [
    (4.0 - 4 * SLIVER, 4.0, 4.0, True),            # exactly at the limit, SLIVER·4 s: a sliver
    (4.0 - 4 * SLIVER - 2 ** -51, 4.0, 4.0, False),  # one rounding (at 4 s) longer: solved
    (4.0 - 4 * SLIVER, 4.0, 5.0, False),          # not on its stop: a step the controller asked
                                                  # for, solved however short
    (0.25, 0.25 + SLIVER, 0.25 + SLIVER, True),   # under 1 s the limit is SLIVER s
    (0.25, 0.25 + 2 * SLIVER, 0.25 + 2 * SLIVER, False),
])
def test_is_sliver(taichi_cpu, start, end, target, sliver):
    # binary-exact times and limits: the comparisons are exact, no tolerance involved (the
    # shortest bound, 0 s, and the longest, 1 s, leave the relative limit alone)
    assert bool(_is_sliver(start, end, target, SLIVER, 0.0, 1.0)) is sliver


MOST = 2 ** -21  # s, the longest sliver of these cases (half a binary-exact dt_min)


@pytest.mark.parametrize("start, end, sliver", [
    (1.0, 1.0 + MOST, True),             # exactly the longest: a sliver
    (1.0, 1.0 + MOST + 2 ** -52, False),  # one rounding (at 1 s) longer: solved
])
def test_a_sliver_is_never_longer_than_its_share_of_dt_min(taichi_cpu, start, end, sliver):
    """In f32, 64 roundings of the time can exceed real steps (7.6e-6 s below 1 s): a relative
    limit far above the longest sliver (2^-10 here) stands for it, and the share of dt_min
    bounds it (binary-exact values: exact comparisons)."""
    assert bool(_is_sliver(start, end, end, 2 ** -10, 0.0, MOST)) is sliver


LEAST = 2 ** -33  # s, the shortest bound of these cases (~1.2e-10 s, binary-exact)


@pytest.mark.parametrize("start, end, sliver", [
    (1.0, 1.0 + LEAST, True),             # exactly the shortest bound: a sliver
    (1.0, 1.0 + LEAST + 2 ** -52, False),  # one rounding (at 1 s) longer: solved
])
def test_a_stop_a_longer_sum_away_is_still_a_sliver(taichi_cpu, start, end, sliver):
    """Far more than 64 roundings (2^-46 relative here) but at most the share of dt_min: a
    stop that a sum of many steps put ~1e-13 s off another is crossed, not solved (binary-exact
    values: exact comparisons)."""
    assert bool(_is_sliver(start, end, end, SLIVER, LEAST, 1.0)) is sliver
