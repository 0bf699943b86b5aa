"""Sensitivities against finite differences of whole runs: the check behind
`python -m studies sensitivity_check` and the tests.

For each instance and direction, six more runs (the parameter moved by ±h, ±2h and ±4h, all in
one batch) give the central differences D(h), D(2h) and D(4h) and their Richardson
extrapolation with the errors of first and second order in h removed (`extrapolated_difference`:
the drag's kink at zero velocity makes a plain central difference first order in h for a
symmetric gait, and over long runs the second-order term of a parameter that moves the rest
geometry is large). The table also holds a Taylor test, which needs no reference: the
remainder r(H) = |f(p + H) − f(p) − H·s| of the sensitivity s shrinks as H² when s is the
derivative (r(2H)/r(H) ≈ 4) and only as H when it is not (≈ 2); two more runs at H and 2H,
with H (`taylor_step`) large enough that the remainder stands above the runs' Newton noise.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from .params import SolverConfig, StarParams
from .sensitivities import RELATIVE_STEP, Direction, parse_directions
from .simulation import simulate

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["check_sensitivities", "whole_run_differences", "extrapolated_difference",
           "difference_step"]

TAYLOR_MULTIPLE = 100.0
"""H of the Taylor test in multiples of the differences' h (1e-2 of the value for ε = 1e-4):
its remainder, ~H² relative, stays far above the Newton noise of the runs (1e-12 m against
displacements of 1e-4 m)..."""
TAYLOR_MOST = 0.1
"""... but H at most this share of a nonzero value (C∥, whose ε is 1e-2 of it, moves by 10 %)."""
CHECK_COLUMNS = ("instance", "gait", "parameter", "value", "output", "sensitivity",
                 "difference_h", "difference_2h", "difference_4h", "difference", "relative_error",
                 "difference_spread", "taylor_ratio")
"""Columns of `check_sensitivities`: difference = `extrapolated_difference`; relative_error =
|sensitivity − difference| / |difference|; difference_spread = |D(h) − difference| /
|difference| (how far the differences themselves scatter: where it is large the check is ill
conditioned); taylor_ratio = r(2H) / r(H)."""


MULTIPLES = (1.0, -1.0, 2.0, -2.0, 4.0, -4.0)
"""The differences' runs, in multiples of h: ±h, ±2h and ±4h (`whole_run_differences`)."""


def extrapolated_difference(small, large, largest):
    """The derivative from central differences of whole runs at steps h, 2h and 4h (arrays or
    numbers): with D(h) = D + a·h + b·h² + O(h³), (8·D(h) − 6·D(2h) + D(4h))/3 = D + O(h³).
    A central difference of a smooth output has no first-order term; a run whose velocities
    sit on the drag's kink at zero (a symmetric gait) has one, and the second-order one of a
    parameter that moves the rest geometry is large over long runs. 2·D(h) − D(2h) removes
    the first alone and doubles the second: for the joint radius over three cycles of A1+A4
    at h = 1e-4 of the value it was 1.2e-5 above plain differences at steps of 1e-5, where
    the truncation is ~1e-7; this one is 8.6e-6 below them (its O(h³) remainder, D(4h) at
    4e-4 of the value): over long runs of that parameter neither is better than ~1e-5."""
    return (8.0 * small - 6.0 * large + largest) / 3.0


def difference_step(direction: Direction, params: StarParams) -> float:
    """h for one instance: the sensitivities' own ε (`Direction.step`) where the parameter is
    not 0. At 0, ten times the default ε there (RELATIVE_STEP of ZERO_VALUE_SCALE of its
    range's top) whatever the field's own: the runs at −h, −2h and −4h leave the parameter's
    range, and the damping time's own 1e-3 gave −4h = −4e-4 s, a negative damping that the
    stiffest modes do not survive (BDF2 runs ended in NaN; Euler's differences spread by 1e-3
    where at the default step they agree within 2.3e-8; sensitivity_check, 0.2 s, measured)."""
    if direction.value(params):
        return direction.step(params)
    return 10.0 * direction.step(params) * RELATIVE_STEP / direction.relative_step


def taylor_step(h: float, value: float) -> float:
    """H of the Taylor test for differences of step h at a parameter value: TAYLOR_MULTIPLE·h,
    at most TAYLOR_MOST·|value| where the value is not 0."""
    step = TAYLOR_MULTIPLE * h
    return min(step, TAYLOR_MOST * abs(value)) if value else step


def whole_run_differences(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                          directions, output: str, arch: str = "cpu") -> np.ndarray:
    """(D, B, 3): the central differences of `output` (a summary column) of whole runs at
    ±h, ±2h and ±4h for every direction × instance, h each one's `difference_step`, from one
    `simulate` batch of every moved run (`MULTIPLES`); `extrapolated_difference` of the last
    axis is the derivative they give."""
    params = list(params)
    steps = np.array([[difference_step(direction, p) for p in params]
                      for direction in directions])
    moved = [direction.moved(p, direction.value(p) + multiple * h)
             for direction, row in zip(directions, steps) for multiple in MULTIPLES
             for p, h in zip(params, row)]
    runs = simulate(moved, duration_s, solver, arch=arch).summary[output].to_numpy(dtype=float)
    plus, minus = runs.reshape(len(directions), len(MULTIPLES) // 2, 2, len(params)) \
        .transpose(2, 0, 3, 1)
    return (plus - minus) / (2.0 * steps[..., None] * np.array([1.0, 2.0, 4.0]))


def check_sensitivities(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                        names: Sequence[str], output: str = "displacement_x_mm",
                        arch: str = "cpu") -> pd.DataFrame:
    """One row per (instance, direction) of `names` (as `simulate` takes them), for `output` (a
    summary column): see `CHECK_COLUMNS`. Three `simulate` calls: the sensitivities, the
    differences' moved runs (`whole_run_differences`) and the Taylor test's (H and 2H).

    With adaptive steps hold them: dt_min = dt_max = the step. The sensitivities are those of
    the instance's accepted step sequence, frozen; a moved run on free steps chooses its own,
    whose sizes move with the parameter, and its differences carry that too: 0.3 s of the
    accurate preset (A1+A2, period 0.3 s) on its own adaptive steps checked α to 5e-6 and the
    joint radius to 7 % (differences spread 2.6 %), held at 1 ms to 9e-9 and 2.9e-7. A loose
    error_tol with dt_max the step (what `python -m studies sensitivity_check` uses, over
    0.2 s from rest) holds them only while no step is rejected: a redo's size comes from the
    error estimate, and a damped robot re-fired at 0.3 s was checked 1.2e-5 off for α that
    way, 2.4e-7 with dt_min = dt_max (an audit, 2026-12)."""
    params = list(params)
    directions = parse_directions(names)
    result = simulate(params, duration_s, solver, arch=arch, sensitivities=names)
    centre = result.summary[output].to_numpy(dtype=float)
    differences = whole_run_differences(params, duration_s, solver, directions, output, arch)
    taylor_steps = [[taylor_step(difference_step(direction, p), direction.value(p))
                     for p in params] for direction in directions]
    moved = [direction.moved(p, direction.value(p) + multiple * H)
             for direction, row in zip(directions, taylor_steps) for multiple in (1.0, 2.0)
             for p, H in zip(params, row)]
    taylor_runs = simulate(moved, duration_s, solver, arch=arch).summary[output] \
        .to_numpy(dtype=float).reshape(len(directions), 2, len(params))
    rows = []
    for j, direction in enumerate(directions):
        small, large, largest = differences[j].T
        taylor, taylor2 = taylor_runs[j]
        extrapolated = extrapolated_difference(small, large, largest)
        sensitivity = result.sensitivity(output, direction.label)
        step = np.array(taylor_steps[j])
        remainder = np.abs(taylor - centre - step * sensitivity)
        remainder2 = np.abs(taylor2 - centre - 2 * step * sensitivity)
        with np.errstate(divide="ignore", invalid="ignore"):
            rows.append(pd.DataFrame({
                "instance": np.arange(len(params)), "gait": [p.gait for p in params],
                "parameter": direction.label, "value": [direction.value(p) for p in params],
                "output": output, "sensitivity": sensitivity, "difference_h": small,
                "difference_2h": large, "difference_4h": largest, "difference": extrapolated,
                "relative_error": np.abs(sensitivity - extrapolated) / np.abs(extrapolated),
                "difference_spread": np.abs(small - extrapolated) / np.abs(extrapolated),
                "taylor_ratio": remainder2 / remainder}))
    return pd.concat(rows, ignore_index=True).reindex(columns=list(CHECK_COLUMNS))
