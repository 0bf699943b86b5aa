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

import math
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from .checks import warn_user
from .params import PER_ACTUATOR_RANGES, STAR_RANGES, SolverConfig, StarParams
from .sensitivities import (FIELD_LEAST_STEPS, RELATIVE_STEP, Direction, check_directions,
                            instances_per_instance, parse_directions)
from .simulation import simulate

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["check_sensitivities", "whole_run_differences", "extrapolated_difference",
           "difference_step", "check_arguments", "instance_runs"]

TAYLOR_MULTIPLE = 100.0
"""H of the Taylor test in multiples of the differences' h (1e-2 of the value for ε = 1e-4):
its remainder, ~H² relative, stays far above the Newton noise of the runs (1e-12 m against
displacements of 1e-4 m)..."""
TAYLOR_MOST = 0.1
"""... but H at most this share of a nonzero value (C∥, whose ε is 1e-2 of it, moves by 10 %)."""
TAYLOR_LEAST_MULTIPLE = 30.0
"""... but never below this many of a field's least ε (`Direction.least_step`): a
tenth of the wake's exchange time τ_w = 1e-9 s moved it by 1e-10 s, a remainder ~1e-23 m lost
in the runs' Newton noise (Taylor ratios 0.3 to 100: measured, 2026-12)."""
TAYLOR_GAP_SHARE = 0.25
"""... and at most this share of the distance to an excluded end of the range, where the model
is singular: the run at 2H stays half that distance from it (at 100·h it crossed it, where ε is
held to 1e-2 of that distance: `sensitivities.EXCLUDED_END_SHARE`)."""
CHECK_COLUMNS = ("instance", "gait", "parameter", "value", "output", "sensitivity",
                 "difference_h", "difference_2h", "difference_4h", "difference", "absolute_error",
                 "relative_error", "difference_spread", "taylor_ratio", "status",
                 "failure_time_s")
"""Columns of `check_sensitivities`: difference = `extrapolated_difference`; absolute_error =
|sensitivity − difference| (in the output's unit per the parameter's: where the difference is
exactly 0, an actuator the gait never fires, the relative error is inf, or NaN with a
sensitivity of 0 too, and the spread NaN; this alone measures a sensitivity that is not 0);
relative_error = |sensitivity − difference| / |difference|;
difference_spread = |D(h) − difference| / |difference| (how far the differences themselves
scatter: where it is large the check is ill conditioned); taylor_ratio = r(2H) / r(H); status
and failure_time_s (s): those of the first of the row's runs (the centre, then the moved and
the Taylor runs) that did not finish "ok" (a failed run's metrics are NaN), else "ok" and
NaN."""
FAILED_ROWS_NAMED = 5
"""Failed rows that `check_sensitivities`' warning names one by one (it counts them all)."""


MULTIPLES = (1.0, -1.0, 2.0, -2.0, 4.0, -4.0)
"""The differences' runs, in multiples of h: ±h, ±2h and ±4h (`whole_run_differences`); for a
parameter at a one-sided end (`one_sided`) the −kh runs are made at the parameter itself."""

TAYLOR_MULTIPLES = (1.0, 2.0)
"""The Taylor test's runs, in multiples of its step H (`taylor_step`)."""


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
    range (a delay's are taken forward instead, `one_sided`), and the damping time's own 1e-3
    gave −4h = −4e-4 s, a negative damping that the stiffest modes do not survive (BDF2 runs
    ended in NaN; Euler's differences spread by 1e-3 where at the default step they agree
    within 2.3e-8; sensitivity_check, 0.2 s, measured)."""
    if direction.value(params):
        return direction.step(params)
    return 10.0 * direction.step(params) * RELATIVE_STEP / direction.relative_step


def one_sided(direction: Direction, params: StarParams) -> bool:
    """Whether the differences of `direction` at `params` are taken forward only: a delay
    that its −4h run would take below 0, where τ = max(t − d, 0) has a kink, so that a
    negative delay continues the model along another slope (central differences there
    averaged the two and reported a correct derivative 1.9 % off at 0: an audit; and below
    4h: a review, 2026-12); or a field with a least ε (`sensitivities.FIELD_LEAST_STEPS`)
    that its −4h run would take below its range: the water's exchange time τ_w, whose force
    has a pole at γ·τ_w = −1, which runs at −4h reached on steps of a few µs (failed runs and
    differences 9–12 % off at τ_w = 1e-9 s: a review, 2026-12)."""
    if direction.field == "actuator_delays":  # its kink lies at its range's lowest end, 0
        lowest = PER_ACTUATOR_RANGES["actuator_delays"][0]
    else:
        lowest = (STAR_RANGES[direction.field][0] if direction.field in FIELD_LEAST_STEPS
                  else -math.inf)
    return direction.value(params) - max(MULTIPLES) * difference_step(direction, params) < lowest


def taylor_step(h: float, value: float, gap: float = math.inf, least: float = 0.0) -> float:
    """H of the Taylor test for differences of step h at a parameter value: TAYLOR_MULTIPLE·h,
    at most TAYLOR_MOST·|value| where the value is not 0 (or TAYLOR_LEAST_MULTIPLE times the
    field's least ε `least`, `Direction.least_step`, where that is more), and at
    most TAYLOR_GAP_SHARE of its distance `gap` to an excluded end of its range
    (`Direction.excluded_end_gap`)."""
    step = min(TAYLOR_MULTIPLE * h, TAYLOR_GAP_SHARE * gap)
    return min(step, max(TAYLOR_MOST * abs(value), TAYLOR_LEAST_MULTIPLE * least)) if value \
        else step


def inward(direction: Direction, params: StarParams, step: float) -> float:
    """The Taylor test's step `step`, or −step where its run at +2·step would leave the
    parameter's range and the one at −2·step would not: past an included top the model may
    turn (A1's gain at its top, 5: the displacement's slope flips from −3.6 to +1.0 between
    5.020 and 5.028, and the runs at 5.05 and 5.10 gave Taylor ratios of 0.8–1.1 for a
    derivative within 1e-9: an audit, 2026-12)."""
    value = direction.value(params)
    if not direction.allowed(params, value + TAYLOR_MULTIPLES[-1] * step) \
            and direction.allowed(params, value - TAYLOR_MULTIPLES[-1] * step):
        return -step
    return step


def _moved_runs(params: Sequence[StarParams], steps: np.ndarray, directions, multiples,
                duration_s: float, solver: SolverConfig, arch: str, progress) -> pd.DataFrame:
    """The `simulate` summary of one batch of every instance moved along each direction by
    each of `multiples` times its step (`steps`: (D, B), in the parameter's unit; a negative
    multiple of a `one_sided` one: not moved), in the order direction, multiple, instance:
    D·M·B rows."""
    moved = [direction.moved(p, direction.value(p) + (
                 max(multiple, 0.0) if one_sided(direction, p) else multiple) * step)
             for direction, row in zip(directions, steps) for multiple in multiples
             for p, step in zip(params, row)]
    return simulate(moved, duration_s, solver, arch=arch, progress=progress).summary


def _difference_runs(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                     directions, output: str, arch: str, progress):
    """((D, B, 3) differences as `whole_run_differences` gives them, the summary of their D·6·B
    moved runs in `_moved_runs`' order)."""
    steps = np.array([[difference_step(direction, p) for p in params]
                      for direction in directions])
    summary = _moved_runs(params, steps, directions, MULTIPLES, duration_s, solver, arch,
                          progress)
    runs = summary[output].to_numpy(dtype=float)
    plus, minus = runs.reshape(len(directions), len(MULTIPLES) // 2, 2, len(params)) \
        .transpose(2, 0, 3, 1)
    # a one-sided row's "minus" run is the parameter itself: a forward quotient over kh
    widths = np.array([[1.0 if one_sided(direction, p) else 2.0 for p in params]
                       for direction in directions])
    return (plus - minus) / (widths[..., None] * steps[..., None] * np.array([1.0, 2.0, 4.0])), \
        summary


def whole_run_differences(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                          directions, output: str, arch: str = "cpu",
                          progress: Optional[bool] = None) -> np.ndarray:
    """(D, B, 3): the central differences of `output` (a summary column) of whole runs at
    ±h, ±2h and ±4h for every direction × instance (forward ones from the parameter itself
    where it sits at a one-sided end, `one_sided`: their expansion in h has the same form, so
    `extrapolated_difference` serves both), h each one's `difference_step`, from one
    `simulate` batch of every moved run (`MULTIPLES`; `progress` as simulate takes it);
    `extrapolated_difference` of the last axis is the derivative they give. A failed moved run
    gives NaN differences of a metric output (`simulate` leaves a failed instance's speeds,
    displacements and heading NaN; the runs' statuses: `check_sensitivities`)."""
    return _difference_runs(list(params), duration_s, solver, directions, output, arch,
                            progress)[0]


def first_failure(status: np.ndarray, failure_time_s: np.ndarray):
    """(status, failure_time_s) of each row of (..., runs) arrays of runs' statuses and failure
    times (s): those of the row's first run whose status is not "ok", else "ok" and NaN."""
    failed = status != "ok"
    # argmax: the first True; in a row of "ok" runs it picks the first, whose time is NaN
    first = failed.argmax(axis=-1)[..., None]
    return (np.take_along_axis(status, first, axis=-1)[..., 0],
            np.take_along_axis(failure_time_s, first, axis=-1)[..., 0])


def instance_runs(instances: int, directions: int) -> int:
    """The instances `check_sensitivities` simulates for `instances` instances and `directions`
    directions, each replica of the sensitivities counted as an instance (`simulate`'s count
    of its work): the sensitivities' run (`instances_per_instance`), the differences' moved
    runs (`MULTIPLES`) and the Taylor test's (`TAYLOR_MULTIPLES`)."""
    return instances * (instances_per_instance(directions)
                        + (len(MULTIPLES) + len(TAYLOR_MULTIPLES)) * directions)


def check_arguments(params: Sequence[StarParams], solver: SolverConfig, names: Sequence[str],
                    duration_s: float):
    """ValueError, before any compute, where `simulate` would refuse the sensitivities `names`
    of `check_sensitivities`: an unknown, repeated or non-differentiable name, sensitivities in
    f32, a component height at 0 in any instance (`sensitivities.check_directions`, which also
    warns of a delay on the step grid). For a caller that runs several checks and must refuse
    a later one's names before the first computes (`python -m studies sensitivity_check`)."""
    check_directions(parse_directions(names), list(params), solver, duration_s=duration_s)


def warn_failed_rows(table: pd.DataFrame):
    """One RuntimeWarning (`warn_user`) naming the rows of a `check_sensitivities` table whose
    status is not "ok" (their metrics are NaN or rest on a frozen run): how many, and the
    first few by gait, parameter, status and time. Silent where every row is ok."""
    failed = table[table["status"] != "ok"]
    if failed.empty:
        return
    named = "; ".join(f"{row.gait} {row.parameter} ({row.status} at {row.failure_time_s:g} s)"
                      for row in failed.head(FAILED_ROWS_NAMED).itertuples())
    more = f"; and {len(failed) - FAILED_ROWS_NAMED} more" \
        if len(failed) > FAILED_ROWS_NAMED else ""
    warn_user(f"check_sensitivities: {len(failed)} of {len(table)} rows rest on a run that did "
              f"not finish ok, their differences unusable (columns status, failure_time_s): "
              f"{named}{more}")


def check_sensitivities(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                        names: Sequence[str], output: str = "displacement_x_mm",
                        arch: str = "cpu", progress: Optional[bool] = None) -> pd.DataFrame:
    """One row per (instance, direction) of `names` (as `simulate` takes them), for `output` (a
    summary column): see `CHECK_COLUMNS`. Three `simulate` calls (`progress` as it takes it):
    the sensitivities, the differences' moved runs (`whole_run_differences`) and the Taylor
    test's (H and 2H). A row whose runs did not all finish ok is kept, with the status of the
    first that did not (`CHECK_COLUMNS`), and one warning names such rows (`warn_failed_rows`).

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
    result = simulate(params, duration_s, solver, arch=arch, sensitivities=names,
                      progress=progress)
    centre = result.summary[output].to_numpy(dtype=float)
    differences, difference_runs = _difference_runs(params, duration_s, solver, directions,
                                                    output, arch, progress)
    taylor_steps = np.array([[inward(direction, p, taylor_step(
        difference_step(direction, p), direction.value(p), direction.excluded_end_gap(p),
        direction.least_step(p))) for p in params] for direction in directions])
    taylor_summary = _moved_runs(params, taylor_steps, directions, TAYLOR_MULTIPLES,
                                 duration_s, solver, arch, progress)
    count, batch = len(directions), len(params)
    taylor_runs = taylor_summary[output].to_numpy(dtype=float) \
        .reshape(count, len(TAYLOR_MULTIPLES), batch)
    # (D, B, runs) each: every row's runs in order, its centre run, then its moved runs and its
    # Taylor runs
    statuses, failure_times = first_failure(*(np.concatenate([
        np.broadcast_to(result.summary[column].to_numpy(dtype=kind), (count, 1, batch)),
        difference_runs[column].to_numpy(dtype=kind).reshape(count, len(MULTIPLES), batch),
        taylor_summary[column].to_numpy(dtype=kind).reshape(count, len(TAYLOR_MULTIPLES), batch)],
        axis=1).transpose(0, 2, 1) for column, kind in (("status", object),
                                                         ("failure_time_s", float))))
    rows = []
    for j, direction in enumerate(directions):
        small, large, largest = differences[j].T
        taylor, taylor2 = taylor_runs[j]
        extrapolated = extrapolated_difference(small, large, largest)
        sensitivity = result.sensitivity(output, direction.label)
        step = taylor_steps[j]
        remainder = np.abs(taylor - centre - step * sensitivity)
        remainder2 = np.abs(taylor2 - centre - 2 * step * sensitivity)
        error = np.abs(sensitivity - extrapolated)
        with np.errstate(divide="ignore", invalid="ignore"):
            rows.append(pd.DataFrame({
                "instance": np.arange(len(params)), "gait": [p.gait for p in params],
                "parameter": direction.label, "value": [direction.value(p) for p in params],
                "output": output, "sensitivity": sensitivity, "difference_h": small,
                "difference_2h": large, "difference_4h": largest, "difference": extrapolated,
                "absolute_error": error, "relative_error": error / np.abs(extrapolated),
                "difference_spread": np.abs(small - extrapolated) / np.abs(extrapolated),
                "taylor_ratio": remainder2 / remainder, "status": statuses[j],
                "failure_time_s": failure_times[j]}))
    table = pd.concat(rows, ignore_index=True).reindex(columns=list(CHECK_COLUMNS))
    warn_failed_rows(table)
    return table
