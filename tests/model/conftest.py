"""Fixtures shared by the model tests."""

import pytest

import taichi_star as ts
from taichi_star.primitives import measure_primitives


@pytest.fixture(scope="session")
def quick_primitives():
    """(primitive table, per-cycle table) of the 29 classes over 2 cycles at dt = 5 ms, the
    statistics over the second cycle: what `python -m studies primitives --quick` measures."""
    return measure_primitives(ts.StarParams(), ts.SolverConfig(dt=5e-3), cycles=2,
                              first_cycle=1)
