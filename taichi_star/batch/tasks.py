"""Chunks of a batch: the unit of work of every executor.

A batch of instances is cut into chunks (`plan_chunks`), each one `simulate` call: instances
that share a topology (n_arc, n_limb) and a duration, in input order. `run_chunk` runs one chunk
wherever it is sent (this process, a worker process, a Dask worker) and returns its tables with
the instances numbered by their position in the whole batch.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from ..checks import check_finite, is_whole, told_by_caller
from ..driver import Clock, RunTiming, fewest_steps
from ..geometry import Topology
from ..model import instances_of
from ..params import SolverConfig, StarParams
from ..runtime import RECORDS_REMEDY, check_arch, check_host_memory
from .. import sensitivities as tangents
from ..simulation import (cycles_cut_short, off_grid_periods, simulate, tables_bytes,
                          validate_call, warn_cycles_cut_short, warn_off_grid_periods)
from ..timegrid import steps_in, warn_long_work, warn_off_grid, weighted_nodes


@dataclass(frozen=True)
class ChunkTask:
    """One `simulate` call of a chunked batch. `members`: the positions in the whole batch of
    the instances `params` (same length, same order); durations and intervals in s;
    `sensitivities`: the labels of the parameters to differentiate by ("alpha",
    "actuator_gains[2]", ...: `sensitivities.Direction.label`)."""

    index: int
    members: Tuple[int, ...]
    params: Tuple[StarParams, ...]
    duration_s: float
    solver: SolverConfig
    arch: str = "cpu"
    record_interval_s: float = 0.0
    record_shapes: bool = False
    steady_from_cycle: int = 1
    sensitivities: Tuple[str, ...] = ()

    @property
    def replicas(self) -> int:
        """Instances simulated per instance of the chunk (its sensitivities' replicas too)."""
        return tangents.instances_per_instance(len(self.sensitivities))

    def on(self, arch: str) -> "ChunkTask":
        """The same task on another arch (a Dask worker started for one)."""
        return dataclasses.replace(self, arch=arch)


@dataclass
class ChunkResult:
    """What `run_chunk` returns. summary: simulate's summary with `instance` (position in the
    whole batch) first and `duration_s` added; trajectory: its instance column renumbered the
    same way; with sensitivities, the summary has their columns after its own and the
    trajectory its derivatives' (`sensitivities.sensitivity_column`: one table each, so that a
    run store keeps and verifies them with the chunk); shapes: (n_records, len(members), N,
    2) m or None; timing: the chunk's `simulate` call's."""

    index: int
    summary: pd.DataFrame
    trajectory: pd.DataFrame
    shapes: Optional[np.ndarray]
    topology: Topology
    timing: Optional[RunTiming] = None


def _check_duration(duration_s, cycles):
    if (duration_s is None) == (cycles is None):
        raise ValueError("give exactly one of duration_s (s, the same for every instance) and "
                         "cycles (actuation periods of each instance)")
    name, value = ("duration_s", duration_s) if duration_s is not None else ("cycles", cycles)
    check_finite(name, value, 0.0)


def plan_chunks(params: Sequence[StarParams], duration_s: Optional[float] = None, *,
                cycles: Optional[float] = None, chunk_size: int = 2048,
                solver: SolverConfig = SolverConfig(), arch: str = "cpu",
                record_interval_s: float = 0.0, record_shapes: bool = False,
                steady_from_cycle: int = 1, sensitivities: Sequence[str] = ()
                ) -> List[ChunkTask]:
    """The chunks of a batch, deterministic: instances grouped by topology and duration
    (`duration_s`, or `cycles` × the instance's period), groups in order of first appearance,
    each cut into runs of at most `chunk_size` in input order. Every chunk's arguments are
    validated here, so a bad batch fails before any chunk is computed (ValueError naming the
    argument); a single StarParams is a batch of one, as for `simulate`. `sensitivities`: as
    simulate's (`sensitivities.parse_directions`), checked for each group of the batch, whose
    messages number the instances by their positions in `params`."""
    params = instances_of(params)
    directions = tangents.parse_directions(sensitivities)
    labels = tuple(direction.label for direction in directions)
    replicas = tangents.instances_per_instance(len(directions))
    if not is_whole(chunk_size) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    _check_duration(duration_s, cycles)
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    check_arch(arch)
    groups: Dict[tuple, List[int]] = {}
    for position, p in enumerate(params):
        duration = duration_s if duration_s is not None else cycles * p.period
        if not math.isfinite(duration):
            raise ValueError(f"cycles must give a finite duration: {cycles!r} periods of "
                             f"params[{position}] ({p.period:g} s) overflow a float")
        # past a float's range in steps the run is refused below, by its step count
        if duration_s is None and not solver.adaptive \
                and math.isfinite(duration / solver.dt) and steps_in(duration, solver.dt) < 1:
            raise ValueError(f"cycles must give at least one step (dt = {solver.dt:g} s): "
                             f"{cycles:g} periods of params[{position}] ({p.period:g} s) are "
                             f"{duration:.3g} s, got cycles = {cycles!r}")
        groups.setdefault((p.topology_key, round(float(duration), 12)), []).append(position)
    tasks = []
    # a chunk's long-run warning tells one chunk's hours: the batch's are told below, and a
    # duration off the step grid (of duration_s or of cycles) once for the batch
    with told_by_caller("long_work", "off_grid_duration"):
        for (_, duration), positions in groups.items():
            tangents.check_directions(directions, [params[m] for m in positions], solver,
                                      duration_s=duration, positions=positions)
            for start in range(0, len(positions), chunk_size):
                members = tuple(positions[start:start + chunk_size])
                chunk = tuple(params[m] for m in members)
                try:
                    validate_call(chunk, duration, solver, record_interval_s, record_shapes,
                                  steady_from_cycle, replicas)
                except ValueError as error:
                    if duration_s is not None or not str(error).startswith("duration_s"):
                        raise
                    # the duration is the caller's cycles: name them, not duration_s
                    raise ValueError(f"cycles = {cycles!r} ({duration:.6g} s for "
                                     f"params[{members[0]}]): {error}") from None
                tasks.append(ChunkTask(index=len(tasks), members=members, params=chunk,
                                       duration_s=duration, solver=solver, arch=arch,
                                       record_interval_s=record_interval_s,
                                       record_shapes=record_shapes,
                                       steady_from_cycle=steady_from_cycle,
                                       sensitivities=labels))
    check_batch_work(tasks, len(params))
    if duration_s is not None and not solver.adaptive:
        warn_off_grid(float(duration_s), solver.dt)
    if duration_s is None and not solver.adaptive:
        warn_off_grid_cycles(tasks, cycles, solver.dt)
    warn_off_grid_periods(sorted(task.members[inside] for task in tasks
                                 for inside in off_grid_periods(task.params, task.duration_s,
                                                                solver, steady_from_cycle)),
                          params, solver.dt)
    if duration_s is not None:  # whole cycles end on their cycle's start
        warn_cycles_cut_short(cycles_cut_short(params, duration_s, solver, steady_from_cycle),
                              params, duration_s)
    return tasks


def warn_off_grid_cycles(tasks: Sequence[ChunkTask], cycles: float, dt: float):
    """A RuntimeWarning (kind "off_grid_duration") where `cycles` periods of some instance are
    not a whole number of steps of dt (s): the first such chunk's duration, and the time its
    rounding to whole steps simulates (rounded silently until 2026-12, so that a "cycle" of a
    period of 3.1505 s at 1-ms steps simulated 3.15 s: an audit)."""
    for task in tasks:
        if warn_off_grid(task.duration_s, dt, f"cycles = {cycles!r} periods of "
                         f"params[{task.members[0]}], {task.duration_s!r} s,",
                         "each instance's duration_s in the summary"):
            return


def chunk_robot_steps(task: ChunkTask) -> float:
    """The fewest robot-steps of a chunk (`driver.fewest_steps` × its instances, their
    sensitivities' replicas counted)."""
    return len(task.params) * task.replicas * fewest_steps(task.solver, task.duration_s,
                                                           task.record_interval_s)[0]


def batch_robot_steps(tasks: Sequence[ChunkTask]) -> float:
    """The fewest robot-steps of a batch's chunks together (`chunk_robot_steps`)."""
    return sum(chunk_robot_steps(task) for task in tasks)


def batch_nodes(tasks: Sequence[ChunkTask]) -> Optional[float]:
    """The robots' nodes of a batch's chunks (`timegrid.weighted_nodes` by their robot-steps);
    None for no work."""
    return weighted_nodes([(chunk_robot_steps(task), task.params[0].n_nodes) for task in tasks])


def check_batch_work(tasks: Sequence[ChunkTask], instances: int):
    """What a whole batch asks for, beyond each chunk's own checks: its robot-steps (a
    RuntimeWarning with the estimated hours past timegrid.WARN_ROBOT_STEPS; each chunk's
    warning told one chunk's, an audit: 448 h of a 2-year sweep) and the memory of the tables
    it gathers, its summary and records (`simulation.tables_bytes` of each chunk;
    `runtime.check_host_memory`: a million instances recorded every millisecond for three
    cycles are 1.4 TiB)."""
    warn_long_work(f"the batch of {instances:,} instances", batch_robot_steps(tasks),
                   batch_nodes(tasks))
    if not tasks:
        return
    recorded = tasks[0].record_interval_s
    # each chunk's run checks its own peak; what stays is its tables' rows (a chunk's
    # per-record overhead counted once per chunk refused small chunks, an audit)
    needed = sum(tables_bytes(task.params, task.duration_s, task.record_interval_s,
                              task.record_shapes, task.replicas, per_call=False)
                 for task in tasks)
    check_host_memory("record_interval_s" if recorded else "params",
                      f"the tables of the batch of {instances:,} instances", needed,
                      RECORDS_REMEDY if recorded else "run the batch in parts")


def run_chunk(task: ChunkTask, progress: bool = False) -> ChunkResult:
    """Simulate one chunk (in whatever process calls it) and number its rows by `members`. Its
    warnings about "ok" instances are left to `run_batch`, which tells the batch's numbers
    once (a chunk's named its own rows, and on a worker process went to the worker's stderr)."""
    # the batch's long-run warning was told when it was planned (`check_batch_work`), and so
    # were a duration, periods and the sensitivities' delays off or on the step grid
    # (`plan_chunks`, numbering the batch's instances)
    with told_by_caller("ok_instances", "long_work", "off_grid_duration", "off_grid_period",
                        "cycle_cut_short", "delay_event"):
        result = simulate(list(task.params), task.duration_s, task.solver, arch=task.arch,
                          record_interval_s=task.record_interval_s,
                          record_shapes=task.record_shapes,
                          steady_from_cycle=task.steady_from_cycle, progress=progress,
                          sensitivities=task.sensitivities)
    members = np.asarray(task.members)
    summary = result.summary
    summary.insert(0, "instance", members)
    # the time simulated, over which the speeds are taken: with fixed steps the duration
    # rounded to whole steps (0.0126 s asked at 1-ms steps is 0.013 s)
    clock = Clock(task.solver, task.duration_s)
    summary.insert(summary.columns.get_loc("displacement_x_mm"), "duration_s",
                   clock.simulated_s)
    trajectory = result.trajectory
    trajectory["instance"] = members[trajectory["instance"].to_numpy(dtype=int)]
    if task.sensitivities:
        # the same rows in the same order (`sensitivities.split_result`)
        summary = pd.concat([summary, result.sensitivities], axis=1)
        trajectory = pd.concat([trajectory, result.trajectory_sensitivities.drop(
            columns=["instance", "t_s"])], axis=1)
    return ChunkResult(index=task.index, summary=summary, trajectory=trajectory,
                       shapes=result.shapes, topology=result.topology, timing=result.timing)
