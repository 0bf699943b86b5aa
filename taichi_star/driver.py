"""The one driver of the engine, for `simulate` and `Simulator.advance`: checks a run's
duration and record interval, and advances a batch from its start through a list of stops
(records, cycle starts, the end) by fixed or adaptive steps, with a progress bar.

A stop is counted from the run's start (`Clock`): with fixed steps a number of steps (the
engine's time is then its own product step·dt), with adaptive steps a time in s, which every
instance reaches exactly from its own start time. `RunTiming` is what both callers report of
where their time went.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

import numpy as np

from .checks import check_finite, check_flag, warn_user
from .params import SolverConfig
from .timegrid import (ESTIMATE_ROBOT_STEPS_PER_S, MAX_STEPS_PER_INSTANCE, STEPS_PER_LAUNCH,
                       check_duration, check_steps, check_work, multiples_within, step_work,
                       steps_in, whole_steps)


@dataclass(frozen=True)
class RunTiming:
    """Where the wall time of a `simulate` call (summed over its chunks, which run one after
    the other) or of a `Simulator` so far went, in s, so that compilation is seen apart from
    the run:

    - `setup_s`: Taichi initialised (the first call of a process), the batch's tables built,
      its engine built (when this process has none yet for its topology, terms, integrator
      and capacity) and loaded with the batch;
    - `compile_s`: the engine's stepping kernel compiled, or loaded from Taichi's offline cache
      (`BatchEngine.compile_stepping`, before the first step; about 0 once this process has
      compiled it);
    - `run_s`: the steps, with the records and the progress bar (a Simulator's: its
      `advance` calls);
    - `collect_s`: the result's tables (0 for a Simulator, whose tables are read on request);
    - `robot_steps`: accepted steps summed over the instances (a sensitivity's replicas are
      not counted: they are moved, not solved)."""

    setup_s: float
    compile_s: float
    run_s: float
    collect_s: float
    robot_steps: int

    @property
    def total_s(self) -> float:
        """The sum of the phases, s (of a `simulate` call: all of it from Taichi's
        initialisation on, all but its argument checks)."""
        return self.setup_s + self.compile_s + self.run_s + self.collect_s

    @property
    def robot_steps_per_s(self) -> float:
        """robot_steps / run_s (NaN for a run of no measurable time)."""
        return self.robot_steps / self.run_s if self.run_s > 0 else math.nan

    def __add__(self, other: "RunTiming") -> "RunTiming":
        """The timing of two calls (or chunks) run one after the other."""
        return RunTiming(*(getattr(self, name.name) + getattr(other, name.name)
                           for name in dataclasses.fields(self)))

    def __str__(self) -> str:
        if self.robot_steps == 0 and self.total_s == 0.0:
            # a result read back from a run store (`batch.read_run`, a finished run resumed):
            # "run 0.00 s (nan robot-steps/s)" read as a fault
            return "nothing simulated by this call (its tables read back)"
        return (f"setup {self.setup_s:.2f} s, compile {self.compile_s:.2f} s, run "
                f"{self.run_s:.2f} s ({self.robot_steps_per_s:,.0f} robot-steps/s), tables "
                f"{self.collect_s:.2f} s")


def fewest_steps(solver: SolverConfig, duration_s: float, record_interval_s: float):
    """(The fewest steps an instance takes in duration_s (s), what bounds them): with fixed
    steps duration_s / dt; with adaptive ones the steps at dt_max, or at the record interval
    (s; 0 = none) where that is shorter (each record ends a step). ValueError naming an
    argument that is not a SolverConfig or a finite time >= 0 s."""
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    for name, value in (("duration_s", duration_s), ("record_interval_s", record_interval_s)):
        check_finite(name, value, 0.0, lowest_included=True, unit=" s")
    if not solver.adaptive:
        return duration_s / solver.dt, f"dt = {solver.dt:g} s"
    if record_interval_s and record_interval_s < solver.dt_max:
        return (duration_s / record_interval_s,
                f"a record every {record_interval_s:g} s, each a step end")
    return duration_s / solver.dt_max, f"dt_max = {solver.dt_max:g} s"


AUTO_PROGRESS_S = 30.0
"""With `progress=None` (the default of simulate, Simulator.advance and run_batch) a run
estimated at this many wall seconds or more (its fewest robot-steps at
`timegrid.ESTIMATE_ROBOT_STEPS_PER_S`) shows a progress bar, a shorter one stays silent: a long
run said nothing about where it was unless asked (an audit, 2026-12)."""


def shows_progress(progress, robot_steps: float, nodes: Optional[float] = None) -> bool:
    """Whether a run of `robot_steps` (its fewest: `fewest_steps` × its instances, replicas
    included) of robots of `nodes` nodes (None: the paper robot's; `timegrid.step_work`) shows
    a progress bar: `progress` if a bool (ValueError otherwise), for None whether the run is
    estimated at AUTO_PROGRESS_S or more."""
    if progress is None:
        return robot_steps * step_work(nodes) / ESTIMATE_ROBOT_STEPS_PER_S >= AUTO_PROGRESS_S
    return check_flag("progress", progress)


def check_run(solver: SolverConfig, duration_s: float, record_interval_s: float, batch: int,
              steps_taken: Optional[int] = None, arch: Optional[str] = None,
              nodes: Optional[float] = None):
    """ValueError before any compute unless a run of `batch` instances for duration_s (s) with
    records every record_interval_s (s; 0 = none) can go on `arch` (None: on some machine):
    at most MAX_STEPS_PER_INSTANCE steps, and robot-steps that such a machine finishes in
    `timegrid.REFUSE_DAYS` (`timegrid.check_work`; `steps_taken`: the steps an instance has
    already taken, None for a run from t = 0; adaptive steps: the fewest, at dt_max or at the
    record interval if shorter, with a RuntimeWarning when the most, at dt_min, could pass the
    limit), with
    adaptive steps a record interval of at least dt_min, and with fixed steps at least one step
    and a record interval of whole steps. A record interval longer than the run warns: no
    record falls after its start. `nodes`: the robots' nodes (None: the paper robot's), which
    weigh their steps in the work (`timegrid.step_work`)."""
    after = "" if steps_taken is None else f"after the {steps_taken} steps taken"
    taken = steps_taken or 0
    if solver.adaptive:
        # the work is known only to lie between the steps at dt_max and at dt_min: refused and
        # estimated by the fewest; the most may exceed the counters, where the engine stops an
        # instance with status step_limit (said before the run). A record is a stop a step must
        # end on, so records closer than dt_max bound the steps from below too, and records
        # closer than dt_min would force steps shorter than the controller's floor
        if record_interval_s and record_interval_s < solver.dt_min:
            raise ValueError(f"record_interval_s must be at least dt_min = {solver.dt_min:g} s "
                             f"with adaptive steps (a step ends on every record), got "
                             f"{record_interval_s!r}")
        fewest, bound = fewest_steps(solver, duration_s, record_interval_s)
        check_work(f"duration_s = {duration_s:g} s at {bound} (the adaptive lower bound"
                   f"{', ' + after if after else ''})", taken + fewest, batch, arch, nodes)
        most = taken + duration_s / solver.dt_min
        if not most <= MAX_STEPS_PER_INSTANCE:
            warn_user(f"duration_s = {duration_s:g} s at dt_min = {solver.dt_min:g} s could "
                      f"take {most:.3g} steps per instance: an instance that reaches "
                      f"{MAX_STEPS_PER_INSTANCE} (the int32 step counter) stops there with "
                      f"status step_limit")
    else:
        check_work(f"duration_s = {duration_s:g} s at dt = {solver.dt:g} s"
                   f"{f' ({after})' if after else ''}", taken + duration_s / solver.dt, batch,
                   arch, nodes)
        check_duration(duration_s, solver.dt)
        if record_interval_s:
            check_steps("record_interval_s", record_interval_s, solver.dt)
    # after the interval's own checks: a subnormal interval made the count of records an
    # OverflowError here (an audit, 2026-12); the time simulated, not the duration asked for
    # (0.0099 s at 5-ms steps runs 0.01 s, which holds a record of 0.01 s: an audit, 2026-12)
    simulated = Clock(solver, duration_s).simulated_s
    if record_interval_s and multiples_within(simulated, record_interval_s) == 0:
        warn_user(f"record_interval_s = {record_interval_s:g} s is longer than the "
                  f"{simulated:g} s simulated (duration_s = {duration_s:g} s): no record falls "
                  f"after the start (simulate's trajectory holds the start alone, "
                  f"Simulator.advance returns no rows)")


class Clock:
    """Where a run of duration_s (s) stops, counted from its start: with fixed steps a stop is
    a number of steps (the duration rounded to whole steps), with adaptive steps a time, s."""

    def __init__(self, solver: SolverConfig, duration_s: float):
        self.adaptive = solver.adaptive
        self.dt = solver.dt
        self.end = duration_s if self.adaptive else steps_in(duration_s, solver.dt)
        """The last stop."""

    @property
    def simulated_s(self) -> float:
        """The time the run simulates, s: with fixed steps the duration rounded to whole
        steps."""
        return self.time_of(self.end)

    def stops_every(self, interval_s: float, first: int = 0) -> list:
        """Stops at first·interval_s, (first + 1)·interval_s, ... up to the end (adaptive: a
        multiple within STEP_TOLERANCE after the end, a rounding past it, is the end: 3 × 0.2 s
        is 0.6000000000000001 s, which made a run of 0.6 s take a last step of 1e-16 s, and a
        batch of periods 0.2 and 0.17 s refused as the groups' last stops differed, until
        2026-12). With fixed steps interval_s must be a whole number of steps."""
        if self.adaptive:
            return [min(k * interval_s, self.end)
                    for k in range(first, multiples_within(self.end, interval_s) + 1)]
        stride = whole_steps(interval_s, self.dt)
        return list(range(first * stride, self.end + 1, stride))

    def times_every(self, interval_s: float) -> np.ndarray:
        """The times (s) of the records of `stops_every(interval_s)`: a step's time with fixed
        steps; with adaptive ones the multiples k·interval_s the stops stand for, also where
        the last stops at the end a rounding before it (0.6 for 3 × 0.2 s =
        0.6000000000000001), so that every instance's record k has one time whatever its run's
        end (a run_batch of two periods' cycles gave one record two times, 0.6 and
        0.6000000000000001, and its xarray Dataset two half-empty columns: an audit,
        2026-12)."""
        stops = self.stops_every(interval_s)
        if self.adaptive:
            return interval_s * np.arange(len(stops), dtype=np.float64)
        return np.array([self.time_of(stop) for stop in stops], dtype=np.float64)

    def time_of(self, stop) -> float:
        """The time of a stop after the start, s."""
        return stop if self.adaptive else stop * self.dt

    @property
    def seconds_per_tick(self) -> float:
        """The unit of `ticks`, s: a step with fixed steps, a nanosecond with adaptive ones."""
        return 1.0 / NANOSECONDS if self.adaptive else self.dt

    def ticks(self, stop) -> int:
        """A stop as a whole number of ticks, at most the end's: the count a progress bar keeps,
        so that its sum ends exactly on its total (a sum of float seconds can pass it by a
        rounding, and an adaptive run's last stop may lie within STEP_TOLERANCE after the
        end)."""
        if not self.adaptive:
            return stop
        return min(round(stop * NANOSECONDS), round(self.end * NANOSECONDS))


class NextOwnStops:
    """Where each instance goes next at every stop of `drive`: its first own stop at or after
    it. `own`: per group, the ascending indices into `stops` of its own stops, the last stop
    among them; `group`: (batch,) each instance's group. Memory: the groups' own stops alone
    (a sweep of many periods has as many groups, each few stops of its own)."""

    def __init__(self, stops: Sequence, own: Sequence[np.ndarray], group: np.ndarray):
        self.stops = np.asarray(stops, dtype=np.float64)
        count = len(self.stops)
        if any(len(indices) == 0 or indices[-1] != count - 1 for indices in own):
            raise ValueError("every group's own stops must end on the last stop (the run's end)")
        self.base = np.arange(len(own)) * count
        # one ascending key per own stop: group·count + index
        self.keys = np.concatenate([g * count + np.asarray(indices, dtype=np.int64)
                                    for g, indices in enumerate(own)])
        self.group = np.asarray(group, dtype=np.int64)

    def at(self, index: int) -> np.ndarray:
        """(batch,) the times (s after the start) each instance goes to at stop `index`."""
        found = self.keys[np.searchsorted(self.keys, self.base + index)] - self.base
        return self.stops[found][self.group]


NANOSECONDS = 1e9
"""Ticks per simulated second of an adaptive run's progress bar."""


def robots_label(count: int, noun: str = "robot") -> str:
    """A progress bar's description of a batch: "1 robot", "1,024 robots" (or of `noun`s)."""
    return f"{count:,} {noun}" + ("" if count == 1 else "s")


def progress_bar(clock: Clock, label: str):
    """A tqdm bar over the run in the clock's `ticks`, shown in simulated seconds to the
    millisecond."""
    from tqdm.auto import tqdm
    return tqdm(total=clock.ticks(clock.end), unit="s", unit_scale=clock.seconds_per_tick,
                desc=label,
                bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s simulated "
                           "[{elapsed}<{remaining}]")


def drive(engine, clock: Clock, stops: Sequence, at_stop: Callable, batch: int,
          start_times: Optional[np.ndarray] = None, progress_label: Optional[str] = None,
          stop_groups: Optional[Tuple[Sequence[np.ndarray], np.ndarray]] = None):
    """Advance every live instance of the engine's first `batch` from its start through
    `stops` (ascending, from `clock`; a stop at 0 is the start itself) and call at_stop(stop)
    on reaching each. Fixed steps advance in launches of STEPS_PER_LAUNCH steps; adaptive
    ones take each instance to its start time (s, (batch,); None: all at t = 0) plus the
    stop, an adaptive step ending there. `stop_groups` (own, group): for each group of
    instances the ascending indices into `stops` of those it must end a step on (the last
    stop among them), and each instance's group ((batch,) int); default: every stop for
    every instance. An adaptive instance goes straight on to its next own stop past the
    others, so that another instance's stops (its cycle boundaries) do not cut its steps:
    at_stop(stop) may read only the instances whose stop it is.
    progress_label: the description of a progress bar in simulated seconds, None for no
    bar."""
    if clock.adaptive and start_times is None:
        start_times = np.zeros(batch)
    next_own = None
    if clock.adaptive and stop_groups is not None:
        next_own = NextOwnStops(stops, *stop_groups)
    previous = 0
    bar = progress_bar(clock, progress_label) if progress_label is not None else None
    try:
        for index, stop in enumerate(stops):
            if stop != previous:
                if clock.adaptive:
                    engine.advance_adaptive_to(
                        start_times + (stop if next_own is None else next_own.at(index)), batch)
                    if bar is not None:
                        bar.update(clock.ticks(stop) - clock.ticks(previous))
                else:
                    step = previous
                    while step < stop:
                        count = min(STEPS_PER_LAUNCH, stop - step)
                        engine.advance(count)
                        step += count
                        if bar is not None:
                            bar.update(count)
            at_stop(stop)
            previous = stop
    finally:
        # also on an interrupt or an error: a notebook's interrupted bar stayed open, and the
        # next one was drawn below it, a line per update (an audit, 2026-12)
        if bar is not None:
            bar.close()
