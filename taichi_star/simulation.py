"""The public entry point: `simulate` a batch of StarParams and get pandas tables back."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from . import metrics
from .geometry import CENTRE, Topology
from .model import build_model, validate_batch
from .params import SolverConfig, StarParams
from .runtime import Runtime, check_arch
from .state import STATUS_NAMES, STATUS_OK

STEPS_PER_LAUNCH = 50
"""Steps fused into one kernel launch: enough to hide launch cost, few enough for a live
progress bar."""
STEP_TOLERANCE = 1e-9
"""Relative tolerance within which a time is taken to be a whole number of steps."""


def whole_steps(time_s: float, dt: float) -> Optional[int]:
    """time_s / dt as an integer if it is one (within STEP_TOLERANCE), else None."""
    ratio = time_s / dt
    steps = int(round(ratio))
    return steps if abs(ratio - steps) <= STEP_TOLERANCE * max(1.0, ratio) else None


@dataclass
class SimulationResult:
    """What `simulate` returns.

    summary: one row per instance, in input order: every StarParams field; the whole-run
        metrics displacement_x_mm, displacement_y_mm, speed_mm_s, signed_speed_mm_s (on the
        gait's forward direction; NaN where it is undefined), travel_direction_deg (direction of
        the displacement from +x); heading_deg (body rotation at the end, counter-clockwise);
        steady_speed_mm_s and steady_signed_speed_mm_s (over cycles [steady_from_cycle, last
        full cycle), NaN where the run has fewer cycles or the cycle boundaries are not whole
        steps); newton_iterations_mean / newton_iterations_max (per step, over accepted and
        failed attempts), substep_retries (steps redone with substeps), status ("ok",
        "newton_failed", "non_finite") and failure_time_s (NaN when ok). Metrics of failed
        instances are NaN.
    trajectory: long table (instance, t_s, x_mm, y_mm, heading_deg): the centroid relative to its
        start and the body rotation at every record time (NaN from a failure on); empty without
        records.
    shapes: (n_records, B, N, 2) node positions in m at the record times, when requested.
    """

    summary: pd.DataFrame
    trajectory: pd.DataFrame
    shapes: Optional[np.ndarray]
    topology: Topology = field(repr=False)
    solver: SolverConfig = field(repr=False)

    def __repr__(self) -> str:
        status = self.summary["status"].value_counts().to_dict() if len(self.summary) else {}
        return (f"SimulationResult({len(self.summary)} instances, status {status}, "
                f"{self.trajectory['t_s'].nunique() if len(self.trajectory) else 0} records, "
                f"shapes {'recorded' if self.shapes is not None else 'not recorded'})")


def _check_real(name, value, lowest, allow_equal=False):
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) \
            or value < lowest or (value == lowest and not allow_equal):
        bound = f">= {lowest}" if allow_equal else f"> {lowest}"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return float(value)


def validate_call(params, duration_s, solver, record_interval_s, record_shapes, steady_from_cycle):
    """Check simulate's arguments before any compute; returns (params tuple, n_steps,
    record stride in steps or 0)."""
    params = validate_batch(params)
    duration_s = _check_real("duration_s", duration_s, 0.0)
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    n_steps = int(round(duration_s / solver.dt))
    if n_steps < 1:
        raise ValueError(f"duration_s must be at least one step (dt = {solver.dt} s), got {duration_s!r}")
    record_interval_s = _check_real("record_interval_s", record_interval_s, 0.0, allow_equal=True)
    stride = 0
    if record_interval_s > 0:
        stride = whole_steps(record_interval_s, solver.dt)
        if stride is None or stride < 1:
            raise ValueError(f"record_interval_s must be a whole number of steps (dt = "
                             f"{solver.dt} s), got {record_interval_s!r}")
    if record_shapes and stride == 0:
        raise ValueError("record_shapes needs record_interval_s > 0 (the spacing of the records)")
    if isinstance(steady_from_cycle, bool) or not isinstance(steady_from_cycle, numbers.Integral) \
            or steady_from_cycle < 0:
        raise ValueError(f"steady_from_cycle must be an integer >= 0, got {steady_from_cycle!r}")
    return params, n_steps, stride


def simulate(params: Sequence[StarParams], duration_s: float, solver: SolverConfig = SolverConfig(),
             *, arch: str = "cpu", record_interval_s: float = 0.0, record_shapes: bool = False,
             steady_from_cycle: int = 1, progress: bool = False) -> SimulationResult:
    """Simulate a batch of robot instances from rest in their rest shape for duration_s seconds
    (rounded to whole steps of solver.dt) and return a `SimulationResult` (see there for every
    column, with units).

    Every instance may have its own parameters except the topology (n_arc, n_limb). An
    instance whose Newton solve fails even with substeps is frozen and reported (status,
    failure_time_s); the others are unaffected. record_interval_s (s, a whole number of steps;
    0 = none) sets the trajectory's spacing, record_shapes adds the node positions then. The
    centroid is also taken at every cycle boundary that falls on a step, for the steady
    (cycle-window) speeds from cycle `steady_from_cycle` on. Raises ValueError for any bad
    argument before computing anything."""
    params, n_steps, stride = validate_call(params, duration_s, solver, record_interval_s,
                                            record_shapes, steady_from_cycle)
    check_arch(arch)
    model = build_model(params)
    runtime = Runtime.current()
    runtime.ensure(arch, solver.precision)
    engine = runtime.engine_for(model, solver)
    batch = model.batch_size

    record_steps = set(range(0, n_steps + 1, stride)) if stride else set()
    boundary_steps = []
    for p in params:
        per_cycle = whole_steps(p.period, solver.dt)
        boundary_steps.append([] if per_cycle is None else
                              list(range(0, n_steps + 1, per_cycle)))
    n_boundaries = max(len(steps) for steps in boundary_steps)
    boundaries = np.full((batch, max(n_boundaries, 1), 2), np.nan)
    by_step = {}
    for b, steps in enumerate(boundary_steps):
        for index, step in enumerate(steps):
            by_step.setdefault(step, []).append((b, index))
    stops = sorted(record_steps | set(by_step) | {n_steps})

    centroids, shapes = [], []
    state = engine.state

    def take(step):
        now = engine.centroids_of(batch)
        for b, index in by_step.get(step, ()):
            boundaries[b, index] = now[b]
        if step in record_steps:
            positions = state.positions.to_numpy()[:batch]
            centroids.append(now)
            rotations.append(metrics.body_rotation(positions, model.rest_positions,
                                                   model.topology.joints, CENTRE))
            if record_shapes:
                shapes.append(positions.astype(np.float64))

    rotations = []
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=n_steps, unit="step", desc=f"{batch} robots")
    start = engine.centroids_of(batch)
    take(0)
    step = 0
    for stop in stops:
        while step < stop:
            # a launch never runs past a stop, so records are taken between launches
            count = min(STEPS_PER_LAUNCH, stop - step)
            engine.advance(count)
            step += count
            if bar is not None:
                bar.update(count)
        if stop > 0:
            take(stop)
    if bar is not None:
        bar.close()
    return _collect(engine, model, solver, n_steps, stride, start, centroids, rotations, shapes,
                    boundaries, steady_from_cycle)


def _collect(engine, model, solver, n_steps, stride, start, centroids, rotations, shapes,
             boundaries, steady_from_cycle):
    batch = model.batch_size
    state = engine.state
    final = engine.centroids_of(batch)
    status = state.status.to_numpy()[:batch]
    failure_step = state.failure_step.to_numpy()[:batch]
    steps_done = state.steps_done.to_numpy()[:batch]
    newton_total = state.newton_total.to_numpy()[:batch]
    attempted = steps_done + (status != STATUS_OK)
    duration = n_steps * solver.dt
    params = model.params
    gaits = [p.gait for p in params]
    failed = status != STATUS_OK

    rows = {name: [getattr(p, name) for p in params] for name in StarParams.field_names()}
    rows.update(metrics.swimming_metrics(final - start, duration, gaits))
    positions = state.positions.to_numpy()[:batch].astype(np.float64)
    rows["heading_deg"] = np.degrees(metrics.body_rotation(
        positions, model.rest_positions, model.topology.joints, CENTRE))
    boundaries[failed] = np.nan
    rows.update(metrics.cycle_window_speeds(boundaries, np.array([p.period for p in params]),
                                            gaits, steady_from_cycle))
    rows["newton_iterations_mean"] = newton_total / np.maximum(attempted, 1)
    rows["newton_iterations_max"] = state.newton_max.to_numpy()[:batch]
    rows["substep_retries"] = state.substep_retries.to_numpy()[:batch]
    rows["status"] = [STATUS_NAMES[s] for s in status]
    rows["failure_time_s"] = np.where(failed, failure_step * solver.dt, np.nan)
    summary = pd.DataFrame(rows)
    metric_columns = [*metrics.SPEED_COLUMNS, "heading_deg", "steady_speed_mm_s",
                      "steady_signed_speed_mm_s"]
    summary.loc[failed, metric_columns] = np.nan

    trajectory = pd.DataFrame({"instance": pd.Series(dtype=int), "t_s": pd.Series(dtype=float),
                               "x_mm": pd.Series(dtype=float), "y_mm": pd.Series(dtype=float),
                               "heading_deg": pd.Series(dtype=float)})
    shape_array = None
    if stride:
        n_records = len(centroids)
        record_steps = np.arange(n_records) * stride
        # a frozen instance keeps its last good state: its records from the failure on are NaN
        after_failure = failed[:, None] & (record_steps[None, :] >= failure_step[:, None])
        relative = (np.stack(centroids, axis=1) - start[:, None, :]) * metrics.METERS_TO_MM
        relative[after_failure] = np.nan
        heading = np.degrees(np.stack(rotations, axis=1))
        heading[after_failure] = np.nan
        trajectory = pd.DataFrame({
            "instance": np.repeat(np.arange(batch), n_records),
            "t_s": np.tile(record_steps * solver.dt, batch),
            "x_mm": relative[:, :, 0].ravel(),
            "y_mm": relative[:, :, 1].ravel(),
            "heading_deg": heading.ravel(),
        })
        if shapes:
            shape_array = np.stack(shapes)
            shape_array[after_failure.T] = np.nan
    return SimulationResult(summary=summary, trajectory=trajectory, shapes=shape_array,
                            topology=model.topology, solver=solver)
