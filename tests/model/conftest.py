"""Fixtures shared by the model tests."""

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.primitives import measure_primitives


@pytest.fixture(scope="session")
def quick_primitives():
    """(primitive table, per-cycle table) of the 29 classes over 2 cycles at dt = 5 ms, the
    statistics over the second cycle: what `python -m studies primitives --quick` measures."""
    return measure_primitives(ts.StarParams(), ts.SolverConfig(dt=5e-3), cycles=2,
                              first_cycle=1)


def assert_matches_differences(table, tolerance):
    """Every row of a `check_sensitivities` table: the sensitivity within `tolerance` of the
    extrapolated differences, and a Taylor remainder of second order. Each caller sets
    `tolerance` at about 10× the largest relative error it measured (1e-5, the target of the
    docs, only where the measured error is itself ~1e-6): a sensitivity scaled by (1 + 5e-6)
    then fails wherever the error measured is ~1e-7 or below."""
    assert len(table) and np.isfinite(table["relative_error"]).all(), table
    assert (table["relative_error"] <= tolerance).all(), table
    # r(2h)/r(h) = 4 for a second-order remainder, 2 if the sensitivity were off by more
    # than O(h); 3-5 leaves room for the remainder's own round-off
    assert table["taylor_ratio"].between(3.0, 5.0).all(), table


@pytest.fixture
def matches_differences():
    """`assert_matches_differences`, for the test files that check sensitivities."""
    return assert_matches_differences
