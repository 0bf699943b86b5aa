"""`Simulator`: a batch of robots that stays in memory and is driven by commands.

Where `simulate` runs every instance's gait from rest to the end, a Simulator holds the batch's
state and advances it piecewise: `fire` actuators (per instance, any subset of the eight, now or
at later times, any number of them pending), `advance` by a duration, read `state()` (position,
heading, velocities, time since each actuator fired, status), `reset` instances, `save` and
`load` the whole state. The StarParams' `gait` field is not used: an actuator fires only when
commanded.

Firing. An actuator fired at time t_f follows the actuation profile K̄(τ), τ = t − t_f: heating
to its smallest curvature at τ = t0, then cooling. Firing an actuator that is still hot restarts
its profile at τ = 0 (K̄ jumps back to K̄(0), as at every cycle start of a periodic gait). The
profile is right-continuous: a firing scheduled for a future step sets K̄(0) at that step's end,
exactly as `simulate` starts each cycle of a periodic gait, while `fire(commands)` now acts on
the steps after now (the state at the current time has already been computed). With the
"jump" closure an actuator that is not fired again stays at the fit's cooled curvature
K̄(∞) ≈ 99.2 1/m (the fit does not return to K̄(0) = 102.1 1/m); with "ramp" it returns exactly
to K̄(0) at τ = T (its `period`) and stays there.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import pandas as pd

from . import metrics
from . import sensitivities as tangents
from .actuation import NEVER
from .checks import check_finite, check_flag, is_finite_real, shown, warn_user
from .driver import (Clock, RunTiming, check_run, drive, fewest_steps, robots_label,
                     shows_progress)
from .gait import N_ACTUATORS, Gait
from .geometry import CENTRE
from .model import validate_batch
from .params import SolverConfig, StarParams, check_precision
from .provenance import code_record, file_path, write_atomic
from .runtime import (RECORDS_REMEDY, Runtime, check_arch, check_batch_memory,
                      check_host_memory, one_call_at_a_time)
from .simulation import failure_times, newton_capped, warn_about_capped
from .state import STATUS_INACTIVE, STATUS_NAMES, STATUS_OK
from .timegrid import MAX_STEPS_PER_INSTANCE, check_work, multiples_within, whole_steps

ACTUATOR_COLUMNS = tuple(f"since_A{m + 1}_s" for m in range(N_ACTUATORS))
STATE_COLUMNS = ("instance", "t_s", "centroid_x_mm", "centroid_y_mm", "heading_deg",
                 "velocity_x_mm_s", "velocity_y_mm_s", "angular_velocity_deg_s",
                 *ACTUATOR_COLUMNS, "status", "failure_time_s", "newton_capped")
"""Columns of `Simulator.state()`."""
DIFFERENTIABLE_STATE_COLUMNS = ("centroid_x_mm", "centroid_y_mm", "heading_deg",
                                "velocity_x_mm_s", "velocity_y_mm_s", "angular_velocity_deg_s")
"""The `state()` columns `Simulator.sensitivity` differentiates."""
STATE_ROW_BYTES = 640
"""Host memory (bytes) a record of one instance takes in `Simulator.advance` at its peak (its
`state()` columns as recorded and as the table): measured 440 (B = 64, 10,001 records), with
room."""
STATE_RECORD_BYTES = 6144
"""... and each record whatever the batch (its columns' arrays: measured 3.6 kB)."""


def empty_records() -> pd.DataFrame:
    """`Simulator.advance`'s table without records: its columns with the types a recorded
    one has (untyped, every column was object, and a concatenation with recorded tables turned
    their numbers into objects: an audit, 2026-12)."""
    # one row of each column's kind, dropped: pandas infers the status's text type as it
    # does for a recorded table (object in pandas 2, str in pandas 3)
    sample = {"instance": np.zeros(1, dtype=np.int64), "record": np.zeros(1, dtype=np.int64),
              "status": np.array([STATUS_NAMES[STATUS_OK]], dtype=object),
              "newton_capped": np.zeros(1, dtype=bool)}
    return pd.DataFrame({name: sample.get(name, np.zeros(1)) for name in
                         (*STATE_COLUMNS, "record")}).iloc[:0]


NOT_COPIED = ("a Simulator is not copied or pickled (its robots live in the engine's device "
              "memory): save() its state and load() it into a Simulator of the same "
              "parameters, or make another Simulator")
"""The TypeError of copying, deep-copying or pickling a Simulator (an environment raises its
own, `envs.swimmer.ENV_NOT_COPIED`)."""


def parameter_texts(params: Sequence[StarParams]) -> Tuple[Dict[str, str], ...]:
    """Each instance's parameters as {field: repr of its value} (floats to the last bit), what
    a snapshot records of the instances it belongs to: every field but the gait, which a
    Simulator does not use (its actuators fire when commanded)."""
    return tuple({field.name: repr(getattr(p, field.name))
                  for field in dataclasses.fields(StarParams) if field.name != "gait"}
                 for p in params)


def differing_fields(saved: Dict[str, str], own: Dict[str, str],
                     defaults: Dict[str, str]) -> List[str]:
    """The fields whose text in `saved` (a snapshot's record) is not `own`'s, a field the
    record lacks counting as its text in `defaults`: a snapshot saved before a field was added
    holds that field's default (it was refused as "not recorded" even where this side's value
    is the default: an audit, 2026-12)."""
    return [name for name in own if saved.get(name, defaults.get(name)) != own[name]]


def solver_texts(solver: SolverConfig) -> Dict[str, str]:
    """The solver's settings as {field: repr of its value}, what a snapshot records of the
    solver that stepped it."""
    return {field.name: repr(getattr(solver, field.name))
            for field in dataclasses.fields(SolverConfig)}


SNAPSHOT_CODE_KEYS = ("taichi_star_version", "git_commit", "git_changes_sha256",
                      "source_sha256", "taichi_version")
"""The entries of a snapshot's `code` that `Simulator.load` compares with its own: where one
differs, other code wrote the state (the continuation is bit for bit only with the same)."""


def warn_about_other_code(saved: Dict[str, object]):
    """A RuntimeWarning naming the first of `SNAPSHOT_CODE_KEYS` in which the code that wrote a
    snapshot (`saved`, its `code`; empty: nothing to compare) differs from this process's."""
    if not saved:
        return
    own = code_record()
    changed = [key for key in SNAPSHOT_CODE_KEYS if saved.get(key) != own.get(key)]
    if changed:
        key = changed[0]
        warn_user(f"the saved state was written by other code ({key} {saved.get(key)} there, "
                  f"{own.get(key)} here; written {saved.get('date', 'at a time not recorded')}): "
                  f"it goes on, but not necessarily bit for bit as the saved run would have")


@dataclass(frozen=True)
class SimulatorSnapshot:
    """The whole state of a Simulator's batch (from `Simulator.save`): every device field as a
    NumPy array (padding included) and what the state belongs to: the engine, the batch size,
    the step, each instance's parameters (`parameter_texts`) and the solver's settings
    (`solver_texts`), how far each failed instance's clock lags (`behind`, fixed steps) and,
    with adaptive steps, the time each failed instance's clock would show (`shown_s`); those
    empty in a snapshot written before they were recorded."""

    fields: Dict[str, np.ndarray]
    engine_key: str
    n_instances: int
    dt: float
    params: Tuple[Dict[str, str], ...] = ()
    solver: Dict[str, str] = dataclasses.field(default_factory=dict)
    behind: Tuple[float, ...] = ()
    """How far each failed instance's clock lags the others' (`Simulator._behind`: steps, or
    in a snapshot of adaptive steps written before `shown_s` seconds), which its later
    records' times add; empty in a snapshot written before it was recorded."""
    shown_s: Tuple[float, ...] = ()
    """With adaptive steps, the time each failed instance's clock would show, s, NaN for one
    running (`Simulator._shown_s`); empty in a snapshot of fixed steps or one written before
    it was recorded."""
    code: Dict[str, object] = dataclasses.field(default_factory=dict)
    """The code that wrote the file (`provenance.code_record`: taichi_star's version and commit,
    Taichi's version, the date), which `Simulator.load` compares with its own; empty for a
    snapshot kept in memory (the same process's code) or one written before it was recorded."""

    def header(self) -> Dict[str, object]:
        """Everything but the fields, as JSON values (what `write` stores beside them)."""
        return {"engine_key": self.engine_key, "n_instances": self.n_instances, "dt": self.dt,
                "params": list(self.params), "solver": dict(self.solver),
                "behind": list(self.behind), "shown_s": list(self.shown_s),
                "code": dict(self.code)}

    @classmethod
    def from_header(cls, fields: Dict[str, np.ndarray], header: Dict) -> "SimulatorSnapshot":
        """The snapshot of `fields` and a `header()` read back (KeyError, TypeError or
        ValueError for a header that is not one; `read` says which file)."""
        return cls(fields=fields, engine_key=str(header["engine_key"]),
                   n_instances=int(header["n_instances"]), dt=float(header["dt"]),
                   params=tuple({str(name): str(text) for name, text in row.items()}
                                for row in header.get("params", ())),
                   solver={str(name): str(text)
                           for name, text in header.get("solver", {}).items()},
                   behind=tuple(float(lag) for lag in header.get("behind", ())),
                   shown_s=tuple(float(time) for time in header.get("shown_s", ())),
                   code=dict(header.get("code", {})))

    def write(self, path) -> Path:
        """Save to an .npz file (arrays plus a JSON header; ".npz" is added to a path without
        it), whole or not at all (`provenance.write_atomic`: a kill or a full disk leaves a
        snapshot already there as it was), with the code that wrote it (`code`). Returns the
        file's path."""
        path = file_path(path, "path of the snapshot's .npz file")
        if path.is_dir():  # "runs/mine" wrote runs/mine.npz beside the folder
            raise ValueError(f"path {str(path)!r} is a folder: give the snapshot's file, e.g. "
                             f"{str(path / 'state.npz')!r}")
        path = path if path.suffix == ".npz" else path.with_name(path.name + ".npz")
        archive = io.BytesIO()
        header = {**self.header(), "code": code_record()}
        np.savez(archive, __header__=np.array(json.dumps(header)), **self.fields)
        # an OSError all the same, but naming the file asked for, not the temporary beside it
        write_atomic(path, archive.getvalue(), failure=OSError)
        return path

    @classmethod
    def read(cls, path) -> "SimulatorSnapshot":
        """A snapshot from an .npz file written by `write` (".npz" is added to a path without it
        that names no file, as `write` adds it). ValueError naming the file when it cannot be
        read or is not such a file."""
        if not isinstance(path, (str, os.PathLike)):
            raise ValueError(f"snapshot must be a SimulatorSnapshot or the path of its .npz "
                             f"file, got {type(path).__name__}")
        path = Path(path)
        if path.suffix != ".npz" and not path.exists():
            path = path.with_name(path.name + ".npz")
        try:
            with np.load(path, allow_pickle=False) as archive:
                header = json.loads(str(archive["__header__"]))
                fields = {name: archive[name] for name in archive.files if name != "__header__"}
            snapshot = cls.from_header(fields, header)
        except OSError as error:
            raise ValueError(f"snapshot {path}: cannot read it ({error.strerror or error})") \
                from None
        except Exception as error:  # noqa: BLE001 -- whatever a foreign file makes numpy raise
            raise ValueError(f"snapshot {path}: not a Simulator snapshot (.npz from "
                             f"Simulator.save): {type(error).__name__}") from None
        return snapshot


class NotCopied:
    """A holder of robots that live in an engine: copying, deep-copying or pickling it is a
    TypeError with `not_copied` (a shallow copy would share the robots, the others failed in
    Taichi's words: an audit, 2026-12)."""

    not_copied: str = NOT_COPIED

    def __copy__(self):
        raise TypeError(self.not_copied)

    def __deepcopy__(self, memo):
        raise TypeError(self.not_copied)

    def __reduce_ex__(self, protocol):
        raise TypeError(self.not_copied)


class Simulator(NotCopied):
    """A batch of robot instances driven by commands (see the module docstring).

    params: a sequence of StarParams sharing n_arc and n_limb (their `gait` is ignored);
    solver: the SolverConfig of the batch; arch: "cpu" or a GPU arch. The robots start at rest
    in their rest shape at t = 0 with no actuator fired. `sensitivities`: parameters to
    differentiate the state by, as in `simulate` (`sensitivity`). `timing`: where its time
    has gone so far (`RunTiming`: the setup here, the stepping kernel's compilation at the first
    `advance`, the steps of every `advance`)."""

    @one_call_at_a_time
    def __init__(self, params: Sequence[StarParams], solver: SolverConfig = SolverConfig(),
                 *, arch: str = "cpu", sensitivities: Sequence[str] = ()):
        started = time.perf_counter()
        params = validate_batch(params)
        if not isinstance(solver, SolverConfig):
            raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
        check_precision(params, solver)
        self.directions = tangents.parse_directions(sensitivities)
        """The parameters the state is differentiated by (`sensitivities.Direction`)."""
        # its firings are commands: any actuator's delay may put a switch on a step end (the
        # warning followed the unread gait field: an audit, 2026-12)
        tangents.check_directions(self.directions, params, solver, commanded=True)
        self.arch = check_arch(arch)
        """The arch the robots run on ("cpu", "gpu", ...)."""
        check_batch_memory(params, solver.precision, arch,
                           tangents.instances_per_instance(len(self.directions)))
        self.params = params
        self.solver = solver
        self.model, self._steps_of_directions = tangents.replica_model(params, self.directions,
                                                                       commanded=True)
        """The batch's model: the instances and, with sensitivities, their replicas after them."""
        runtime = Runtime.current()
        runtime.ensure(arch, solver.precision)
        carried = len(self.directions)
        self._engine = runtime.lease_engine(self.model, solver, self, sensitive=carried > 0)
        self.engine.load(self.model, solver, periodic_gaits=False, tangents=carried)
        self._initial = self.engine.save_state()
        self._start_centroids = self.engine.centroids_of(self.model.batch_size)
        self._compiled = False
        """Whether `advance` has had the stepping kernel compiled (timed apart, once)."""
        self._capped_named = np.zeros(self.n_instances, dtype=bool)
        """Instances whose capped Newton solves a warning of `advance` has named (each once,
        until it is reset)."""
        self._running = np.ones(self.n_instances, dtype=bool)
        """`ok` as of the last `advance`, `reset` or `load` (where a status can change), for
        `fire` to skip failed instances without reading the device at every command."""
        self._shown_s = np.full(self.n_instances, np.nan)
        """With adaptive steps, the time each failed instance's clock would show at the start
        of the next `advance`, s (NaN for one running), kept as a running instance's is, the
        state's precision of its start time + the stop: a lag added to its frozen time rounded
        otherwise, so its records fell an ulp or two off its neighbours' times and a table
        pivoted on t_s split them (an audit, 2026-12)."""
        self._behind = np.zeros(self.n_instances)
        """How far each instance's clock lags the one it would show had it run on (steps with
        fixed steps, s with adaptive ones): a failed instance's stops at its failure, and
        `advance` records it at the times it would show (`_record_columns`). 0 for one that
        runs, and after `reset` or `load` (a snapshot holds the frozen clock alone)."""
        self.timing = RunTiming(setup_s=time.perf_counter() - started, compile_s=0.0,
                                run_s=0.0, collect_s=0.0, robot_steps=0)

    # ---------------------------------------------------------------- properties
    @property
    def n_instances(self) -> int:
        return len(self.params)

    @property
    def engine(self):
        """The engine that holds the robots (`engine.BatchEngine`). RuntimeError in a process
        forked from the one that made the Simulator, where its kernels would wait for ever, or
        after a `ti.init` outside this package destroyed it (`runtime.Runtime
        .check_engine_usable`)."""
        Runtime.current().check_engine_usable(self._engine)
        return self._engine

    @property
    def n_nodes(self) -> int:
        """N, the nodes of each robot (the middle axis of `shapes`' (B, N, 2))."""
        return self.model.topology.n_nodes

    @property
    def engine_key(self) -> tuple:
        """What a saved state must match: the engine (topology and terms), the integrator, the
        capacity, the stepping (fixed or adaptive: what the clock of pending firings reads,
        steps or seconds) and the parameters differentiated by, if any."""
        key = (self.model.engine_key, self.solver.integrator, self.engine.capacity,
               "adaptive" if self.solver.adaptive else "fixed")
        return key + ((tuple(d.label for d in self.directions),) if self.directions else ())

    def _steps(self) -> np.ndarray:
        return self.engine.state.steps_done.to_numpy()[:self.n_instances].astype(np.int64)

    @property
    @one_call_at_a_time
    def time_s(self) -> np.ndarray:
        """(B,) each instance's current time, s."""
        return self.engine.state.time.to_numpy()[:self.n_instances].astype(np.float64)

    # ---------------------------------------------------------------- commands
    def _command_mask(self, commands) -> np.ndarray:
        """(B, 8) bool from a (B, 8) boolean (or 0/1 integer) array or B gait texts (a list, or
        any one-dimensional sequence of them: a table's column, an array of texts)."""
        batch = self.n_instances
        if not isinstance(commands, (str, Gait, list, tuple)) and np.ndim(commands) == 1:
            # a pandas Series or a NumPy array of texts is the list it holds: read as an array,
            # it was refused for its shape, (B,), which was right (an audit, 2026-12)
            commands = list(commands)
        if isinstance(commands, (str, Gait)):
            # read as an array of shape () before (an audit, 2026-12)
            raise ValueError(f"commands must be a list of {batch} gaits, one per instance, got "
                             f"the single gait {str(commands)!r}: [{str(commands)!r}] * {batch} "
                             f"fires it on every instance")
        if isinstance(commands, (list, tuple)) and any(c is None for c in commands):
            # "no firing" as None read as an array of objects: "got shape (3,)" said nothing
            first = next(b for b, c in enumerate(commands) if c is None)
            raise ValueError(f"commands[{first}] is None: give every instance a gait, 'none' "
                             f"for no firing (or a row of {N_ACTUATORS} booleans)")
        if isinstance(commands, (list, tuple)) and all(isinstance(c, (str, Gait)) for c in commands):
            if len(commands) != batch:
                raise ValueError(f"commands must hold one gait per instance ({batch}), got "
                                 f"{len(commands)}")
            return np.stack([Gait.parse(c).mask.astype(bool) for c in commands])
        try:
            array = np.asarray(commands)
        except ValueError:  # rows of different lengths or kinds (a gait beside an array)
            raise ValueError(f"commands must be a ({batch}, {N_ACTUATORS}) boolean array or a "
                             f"list of {batch} gaits, got a mixture that is neither") from None
        if array.shape != (batch, N_ACTUATORS):
            raise ValueError(f"commands must be a ({batch}, {N_ACTUATORS}) boolean array or a list "
                             f"of {batch} gaits, got shape {array.shape}")
        if array.dtype == bool:
            return array
        # as the environments take actions: NumPy's own arrays (np.ones) are floats
        if array.dtype.kind in "iuf" and np.isin(array, (0, 1)).all():
            return array.astype(bool)
        raise ValueError(f"commands must be boolean (or numbers that are exactly 0 or 1), got "
                         f"dtype {array.dtype}")

    @one_call_at_a_time
    def fire(self, commands, at_s: Optional[float] = None):
        """Fire actuators: `commands` is a (B, 8) boolean array (column m = actuator A(m+1)) or
        B gait texts ("A1+A3", "none"; a list, a table's column, an array). With at_s None
        they fire now (each instance at its own current time) and act on the steps after now;
        with at_s (s, after every commanded instance's current time, a whole number of steps
        ahead with fixed steps) they fire at that time, so the step ending then already sees
        K̄(0). Firings at different times are all kept, each actuator any number of them (an
        instance holds `actuation.PENDING_CAPACITY` distinct pending times); the same time
        again adds actuators to that firing. Failed instances ignore commands (their
        `since_A*_s` stay as they were). Raises ValueError (state unchanged) for a bad shape,
        dtype, gait or time, or a full queue of pending firings."""
        mask = self._command_mask(commands) & self._running[:, None]
        schedule = self.engine.state.schedule
        if at_s is None:
            schedule.command(mask)
            return
        if not is_finite_real(at_s):
            raise ValueError(f"at_s must be a finite time in s, got {shown(at_s)}")
        at_s = float(at_s)
        # a firing beyond the step counter is never reached (adaptive: even at dt_max)
        step, step_name = ((self.solver.dt_max, "dt_max") if self.solver.adaptive
                           else (self.solver.dt, "dt"))
        check_work(f"at_s = {at_s!r} s (at most {MAX_STEPS_PER_INSTANCE * step:.6g} s at "
                   f"{step_name} = {step:g} s)", abs(at_s / step))
        if self.solver.adaptive:
            # a step ends on every firing: one closer than dt_min after an instance's time would
            # force a step shorter than the controller's floor (at or before it: refused below)
            times = self.time_s
            soon = np.flatnonzero(mask.any(axis=1) & (times < at_s)
                                  & (at_s < times + self.solver.dt_min))
            if len(soon):
                raise ValueError(f"at_s = {at_s:.9g} s is less than dt_min = "
                                 f"{self.solver.dt_min:g} s after the current time of instance "
                                 f"{int(soon[0])} ({times[soon[0]]:.9g} s): a step would have to "
                                 f"end there")
            schedule.command(mask, at_s, times)
            return
        due = whole_steps(at_s, self.solver.dt)
        if due is None:
            raise ValueError(f"at_s must be a whole number of steps (dt = {self.solver.dt} "
                             f"s), got {at_s!r}")
        schedule.command(mask, due, self._steps(), step_s=self.solver.dt)

    @one_call_at_a_time
    def advance(self, duration_s: float, record_interval_s: float = 0.0,
                progress: Optional[bool] = None) -> pd.DataFrame:
        """Advance every live instance by duration_s (with fixed steps rounded to whole steps).
        Returns the `state()` rows at every multiple of record_interval_s after now (s, with
        fixed steps a whole number of steps: `timegrid.nearest_interval` gives one; 0 = none),
        with a `record` column; empty without records. An instance failed by a record has
        that record's time and NaN in its measured columns (as `simulate`'s records from a
        failure on); its status and failure_time_s say why. `progress`: a progress bar in simulated
        seconds (None: where the call is estimated at `driver.AUTO_PROGRESS_S` or more). With
        adaptive steps the end ends a step (as a record time does): pieces give one call's bits
        where they end on its step ends (docs: Control, The Simulator). A RuntimeWarning names
        the instances still "ok" whose Newton solves first used all max_newton iterations in
        this call (`state()`'s newton_capped; as `simulate` warns: such a result can be far
        off)."""
        check_finite("duration_s", duration_s, 0.0, unit=" s")
        # the kind first: an empty text or list, None or False is not 0, and an array has no
        # truth value
        if not (is_finite_real(record_interval_s)
                and (record_interval_s == 0 or float(record_interval_s) > 0)):
            raise ValueError(f"record_interval_s must be a finite number > 0 s (or 0: no "
                             f"records), got {shown(record_interval_s)}")
        duration_s, record_interval_s = float(duration_s), float(record_interval_s)
        check_run(self.solver, duration_s, record_interval_s, self.model.batch_size,
                  steps_taken=int(self._steps().max(initial=0)), arch=self.arch,
                  nodes=self.n_nodes)
        progress = shows_progress(progress, self.model.batch_size * fewest_steps(
            self.solver, duration_s, record_interval_s)[0], self.n_nodes)  # replicas counted
        if record_interval_s:
            records = multiples_within(duration_s, record_interval_s)
            check_host_memory("record_interval_s", f"{records:,} records of "
                              f"{robots_label(self.n_instances, 'instance')}",
                              records * (self.n_instances * STATE_ROW_BYTES + STATE_RECORD_BYTES),
                              RECORDS_REMEDY)
        clock = Clock(self.solver, duration_s)
        record_stops = clock.stops_every(record_interval_s, first=1) if record_interval_s else []
        record_numbers = {stop: number + 1 for number, stop in enumerate(record_stops)}
        stops = record_stops + ([clock.end] if not record_stops or record_stops[-1] < clock.end
                                else [])
        records, numbers = [], []
        start_steps, start_times = self._steps(), self.time_s

        def take(stop):
            if stop in record_numbers:
                records.append(self._record_columns(clock, stop, start_steps, start_times))
                numbers.append(record_numbers[stop])

        compile_s = 0.0
        if not self._compiled:
            started = time.perf_counter()
            self.engine.compile_stepping(self.solver.adaptive)
            compile_s = time.perf_counter() - started
            self._compiled = True
        started = time.perf_counter()
        whole = False
        try:
            drive(self.engine, clock, stops, take, self.n_instances,
                  start_times=self.time_s if self.solver.adaptive else None,
                  progress_label=robots_label(self.n_instances) if progress else None)
            whole = True
        finally:
            # after a Ctrl-C too: the steps taken count, and `fire` must know who failed
            # meanwhile (an interrupted advance left a failed robot taking commands: an audit,
            # 2026-12). One read for the step count, the statuses and the capped solves
            run_s = time.perf_counter() - started
            after = self.engine.state.read(("steps_done", "status", "newton_max", "time"),
                                           self.n_instances)
            self.timing = self.timing + RunTiming(
                setup_s=0.0, compile_s=compile_s, run_s=run_s, collect_s=0.0,
                robot_steps=int((after["steps_done"].astype(np.int64) - start_steps).sum()))
            self._running = after["status"] == STATUS_OK
            # how far the stopped robots' clocks fell behind in this advance: to its end, or
            # where the running robots got when it was interrupted (after a Ctrl-C the failed
            # robots' records lagged: an audit, 2026-12)
            stopped = ~self._running
            ran = (after["time"].astype(np.float64) - start_times if clock.adaptive
                   else after["steps_done"].astype(np.int64) - start_steps)
            reached = ((clock.time_of(clock.end) if clock.adaptive else clock.end) if whole
                       else ran[self._running].max() if self._running.any() else None)
            if reached is not None and clock.adaptive:
                real = np.float32 if self.solver.precision == "f32" else np.float64
                clocks = self._shown_from(start_times)
                self._shown_s[stopped] = real(clocks[stopped] + reached)
            elif reached is not None:
                self._behind[stopped] += reached - ran[stopped]
        capped = newton_capped(after["newton_max"], self.solver) & self._running \
            & ~self._capped_named
        self._capped_named |= capped
        warn_about_capped(capped, np.arange(self.n_instances), self.solver)
        if not records:
            return empty_records()
        return pd.DataFrame({**{name: np.concatenate([record[name] for record in records])
                                for name in records[0]},
                             "record": np.repeat(numbers, self.n_instances)})

    @one_call_at_a_time
    def reset(self, instances: Union[None, int, Sequence[int]] = None):
        """Put instances (all by default; one index or a sequence of them) back at rest in
        their rest shape at t = 0, nothing fired, no firing pending (those `fire` scheduled
        with at_s are dropped), status ok; the others are untouched."""
        rows = self._instance_rows("instances", instances)
        if rows.size == 0:  # no instance to reset (an RL loop where none finished)
            return
        self._capped_named[rows] = False
        self._running[rows] = True
        self._behind[rows] = 0.0
        self._shown_s[rows] = np.nan
        fields = self.engine.save_state()
        replica_rows = self._with_replicas(rows)
        for name, values in fields.items():
            values[replica_rows] = self._initial[name][replica_rows]
        self.engine.restore_state(fields)

    @one_call_at_a_time
    def copy_state(self, source: int, to: Union[None, int, Sequence[int]] = None, *,
                   other_params: bool = False):
        """Give instances `to` (every other one by default; one index or a sequence of them)
        instance `source`'s present: its shape and velocities, the integrator's history, its
        time and step count, the actuators fired and the firings pending, its status, what
        the terms carry, with the lagged Jacobian its kept factorisation, with sensitivities
        its tangents. Each keeps its own parameters, and `state()` measures its displacement
        from its own start (the source's where their parameters agree). The batch so branches
        one robot's present into as many futures: advanced under the same commands, each
        target gives the source's bits (a robot's results do not depend on the other robots of
        the batch), and under others, say a candidate gait each, what each would do from there
        (a lookahead controller's rollouts, `examples/lookahead.py`).

        ValueError, state unchanged: `source` or `to` not instances of the batch, the source
        among `to`, an instance named twice; a target whose parameters differ from the
        source's (naming the first and the field), unless other_params=True: the state then
        goes on under the target's parameters, as `load(..., other_params=True)` does (never
        with sensitivities, whose tangents are scaled by the source's parameters)."""
        check_flag("other_params", other_params)
        if isinstance(source, (bool, np.bool_)) or not (
                isinstance(source, (int, np.integer)) and 0 <= source < self.n_instances):
            raise ValueError(f"source must be an instance of the batch, an integer in [0, "
                             f"{self.n_instances}), got {source!r}")
        source = int(source)
        rows = (np.delete(np.arange(self.n_instances), source) if to is None
                else self._instance_rows("to", to))
        if source in rows:
            raise ValueError(f"to names the source, instance {source}, among its targets")
        if rows.size == 0:
            return
        if self.directions or not other_params:
            texts = self._parameter_texts
            for target in rows:
                changed = differing_fields(texts[source], texts[target], texts[source])
                if changed:
                    remedy = ("a Simulator with sensitivities copies a state only between "
                              "instances of the same parameters" if self.directions else
                              "copy_state(..., other_params=True) continues it under the "
                              "target's parameters")
                    raise ValueError(f"instance {target}'s {changed[0]} is "
                                     f"{texts[target][changed[0]]}, the source's (instance "
                                     f"{source}) {texts[source][changed[0]]} "
                                     f"({len(changed)} field(s) differ): {remedy}")
        fields = self.engine.save_state(factorisations=self.solver.jacobian == "lagged")
        # row k·B + b of the engine is instance b's k-th replica (k = 0: the instance)
        targets = self._with_replicas(rows)
        sources = np.repeat(self._with_replicas(np.array([source])), rows.size)
        for values in fields.values():
            values[targets] = values[sources]
        self.engine.restore_state(fields)
        for bookkeeping in (self._capped_named, self._running, self._behind, self._shown_s):
            bookkeeping[rows] = bookkeeping[source]

    def _instance_rows(self, name: str, instances) -> np.ndarray:
        """`instances` (None: every instance; one index or a sequence of distinct ones) as a
        1-D integer array; ValueError naming the argument `name`."""
        rows = (np.arange(self.n_instances) if instances is None
                else np.atleast_1d(np.asarray(instances)))
        if rows.size == 0:  # none (an RL loop where none finished): [] is float
            return rows.astype(np.int64)
        # a bool among integers is an int to NumPy ([0, True] reset instance 1: an audit)
        mixed = isinstance(instances, (list, tuple)) and any(
            isinstance(value, (bool, np.bool_)) for value in instances)
        if rows.ndim != 1 or rows.dtype.kind not in "iu" or mixed or (
                rows.min() < 0 or rows.max() >= self.n_instances):
            raise ValueError(f"{name} must be an integer or a sequence of integers in [0, "
                             f"{self.n_instances}), got {instances!r}")
        values, counts = np.unique(rows, return_counts=True)
        if (counts > 1).any():
            # a robot named twice is a slip in the caller's bookkeeping (accepted: an audit)
            raise ValueError(f"{name} names instance {values[counts > 1][0]} more than "
                             f"once, got {instances!r}")
        return rows

    def _with_replicas(self, rows: np.ndarray) -> np.ndarray:
        """The engine's rows of instances `rows` and of their sensitivities' replicas (every
        n_instances rows after each), grouped replica by replica ((copies · len(rows),))."""
        copies = self.model.batch_size // self.n_instances
        return (rows[None, :] + self.n_instances * np.arange(copies)[:, None]).ravel()

    # ---------------------------------------------------------------- observations
    @one_call_at_a_time
    def shapes(self) -> np.ndarray:
        """(B, N, 2) node positions now, m."""
        return self.engine.state.positions.to_numpy()[:self.n_instances].astype(np.float64)

    @one_call_at_a_time
    def state(self) -> pd.DataFrame:
        """One row per instance now (columns `STATE_COLUMNS`): t_s; the centroid relative to
        its start (mm, the frame of `simulate`'s displacement); heading_deg (body rotation,
        counter-clockwise); the centroid's velocity (mm/s) and the body's angular velocity
        (deg/s); since_A1_s..since_A8_s, the time since each actuator last fired (NaN: never);
        status; failure_time_s (s, when a failed instance stopped; NaN while it runs);
        newton_capped (bool: a Newton solve used all max_newton iterations since the start or
        a reset)."""
        return self._state_of(self.n_instances)

    @one_call_at_a_time
    def sensitivity(self, column: str, parameter: str) -> np.ndarray:
        """d(column of `state()`)/d(parameter) now for every instance, (B,) ((B, 8) for a whole
        per-actuator field), in the column's unit per the parameter's SI unit (e.g. mm per
        unit of α): column one of `DIFFERENTIABLE_STATE_COLUMNS`, parameter one the Simulator
        was built with (`sensitivities`). ValueError otherwise; NaN for a failed instance."""
        if column not in DIFFERENTIABLE_STATE_COLUMNS:
            raise ValueError(f"column must be one of {DIFFERENTIABLE_STATE_COLUMNS}, got "
                             f"{column!r}")
        wanted = tangents.parse_parameter(parameter)
        missing = [d.label for d in wanted if d not in self.directions]
        if missing:
            which = "" if missing == [parameter] else f" ({missing[0]} is not)"
            raise ValueError(f"parameter {parameter!r} is not among this Simulator's "
                             f"sensitivities {[d.label for d in self.directions]}{which}")
        values = self._state_of(self.model.batch_size)[column].to_numpy(dtype=float)
        derivatives = tangents.derivatives(values, self.directions, self._steps_of_directions,
                                           column)
        stacked = np.stack([derivatives[d.label] for d in wanted], axis=1)
        # a failed instance's tangents are void, as in `simulate` (they held the frozen
        # state's derivative, finite, with nothing to say so: an audit, 2026-12)
        stacked[~self.ok] = np.nan
        return stacked if len(wanted) > 1 else stacked[:, 0]

    def _record_columns(self, clock: Clock, stop, start_steps: np.ndarray,
                        start_times: np.ndarray) -> Dict[str, np.ndarray]:
        """`_state_columns` at a record of `advance` (`stop` of its `clock`, which started
        with each instance at start_steps steps and start_times s): an instance that has failed
        by then is at the record's time like the others and its measured columns are NaN, as
        `simulate`'s records from a failure on (its frozen state, repeated with its frozen
        time, broke a table pivoted on t_s: an audit, 2026-12)."""
        columns = self._state_columns(self.n_instances)
        failed = columns["status"] != STATUS_NAMES[STATUS_OK]
        if failed.any():
            real = np.float32 if self.solver.precision == "f32" else np.float64
            # the engine's own arithmetic: a fixed step's time is its number × dt, an adaptive
            # run's stop its start time + the stop; from the clock it would show (`_behind`,
            # `_shown_s`)
            at = (real(self._shown_from(start_times) + clock.time_of(stop)) if clock.adaptive
                  else (start_steps + self._behind + stop).astype(real) * real(clock.dt))
            columns["t_s"] = np.where(failed, at.astype(np.float64), columns["t_s"])
            for name in (*DIFFERENTIABLE_STATE_COLUMNS, *ACTUATOR_COLUMNS):
                columns[name] = np.where(failed, np.nan, columns[name])
        return columns

    def _shown_from(self, start_times: np.ndarray) -> np.ndarray:
        """(B,) with adaptive steps, the time each instance's clock shows at the start of an
        advance that started at `start_times` (s): a failed instance's `_shown_s`, a running
        one's own."""
        return np.where(np.isnan(self._shown_s), start_times, self._shown_s)

    def _state_of(self, batch: int) -> pd.DataFrame:
        """`state()` of the engine's first `batch` instances (with sensitivities: the
        replicas too)."""
        return pd.DataFrame(self._state_columns(batch))

    def _state_columns(self, batch: int) -> Dict[str, np.ndarray]:
        """`_state_of`'s columns, one array each (`advance` keeps its records so: a table per
        record cost ~30 kB of overhead)."""
        values = self.engine.state.read(("positions", "velocities", "time", "fire_time",
                                         "previous_fire_time", "status", "failure_time",
                                         "failure_step", "newton_max"), batch)
        positions = values["positions"].astype(np.float64)
        velocities = values["velocities"].astype(np.float64)
        mass = self.model.mass[:batch]
        centroid = self.engine.centroids_of(batch)
        velocity = metrics.centroid(velocities, mass)
        joints = self.model.topology.joints
        arm = positions[:, joints] - positions[:, CENTRE:CENTRE + 1]
        arm_velocity = velocities[:, joints] - velocities[:, CENTRE:CENTRE + 1]
        spin = (arm[..., 0] * arm_velocity[..., 1] - arm[..., 1] * arm_velocity[..., 0]) \
            / (arm ** 2).sum(-1)
        # summed joint by joint: NumPy's reduction along a contiguous axis may group the terms
        # differently with the batch's size, and an instance must not depend on its neighbours
        spin_sum = spin[:, 0]
        for joint in range(1, spin.shape[1]):
            spin_sum = spin_sum + spin[:, joint]
        times = values["time"].astype(np.float64)
        fired = values["fire_time"].astype(np.float64)
        # a firing due at the end of a step that failed is recorded but never happened: the
        # frozen state is driven by the one before, as the bending term reads it (time < the
        # firing's time: the previous firing); since_* < 0 until 2026-12 (a fuzz audit)
        fired = np.where(fired > times[:, None], values["previous_fire_time"].astype(np.float64),
                         fired)
        since = np.where(fired == NEVER, np.nan, times[:, None] - fired)
        columns = {
            "instance": np.arange(batch), "t_s": times,
            "centroid_x_mm": (centroid[:, 0] - self._start_centroids[:batch, 0]) * metrics.METERS_TO_MM,
            "centroid_y_mm": (centroid[:, 1] - self._start_centroids[:batch, 1]) * metrics.METERS_TO_MM,
            "heading_deg": np.degrees(metrics.body_rotation(
                positions, self.model.rest_positions[:batch], joints, CENTRE)),
            "velocity_x_mm_s": velocity[:, 0] * metrics.METERS_TO_MM,
            "velocity_y_mm_s": velocity[:, 1] * metrics.METERS_TO_MM,
            "angular_velocity_deg_s": np.degrees(spin_sum / spin.shape[1]),
        }
        for m, column in enumerate(ACTUATOR_COLUMNS):
            columns[column] = since[:, m]
        columns["status"] = np.array([STATUS_NAMES[s] for s in values["status"]], dtype=object)
        columns["failure_time_s"] = failure_times(values["status"], values["failure_time"],
                                                  values["failure_step"], self.solver)
        columns["newton_capped"] = newton_capped(values["newton_max"], self.solver)
        return columns

    @property
    @one_call_at_a_time
    def ok(self) -> np.ndarray:
        """(B,) bool: instances still running."""
        return self.engine.state.status.to_numpy()[:self.n_instances] == STATUS_OK

    # ---------------------------------------------------------------- save / load
    @functools.cached_property
    def _parameter_texts(self) -> Tuple[Dict[str, str], ...]:
        """`parameter_texts` of the batch, made at the first save or load (the parameters of
        a Simulator never change)."""
        return parameter_texts(self.params)

    @one_call_at_a_time
    def save(self, path=None) -> Union[SimulatorSnapshot, Path]:
        """The whole batch state as a SimulatorSnapshot; with `path`, written to an .npz file
        (returns its path). With SolverConfig(jacobian="lagged") it holds the kept
        factorisations too (about 54 kB per instance of the paper robot), so that `load`
        continues bit for bit."""
        lagged = self.solver.jacobian == "lagged"
        snapshot = SimulatorSnapshot(fields=self.engine.save_state(factorisations=lagged),
                                     engine_key=repr(self.engine_key),
                                     n_instances=self.n_instances, dt=self.solver.dt,
                                     params=self._parameter_texts,
                                     solver=solver_texts(self.solver),
                                     behind=tuple(self._behind.tolist()),
                                     shown_s=tuple(self._shown_s.tolist())
                                     if self.solver.adaptive else ())
        return snapshot.write(path) if path is not None else snapshot

    @one_call_at_a_time
    def load(self, snapshot: Union[SimulatorSnapshot, str, Path], *,
             other_params: bool = False):
        """Continue from a saved state, bit for bit as if never interrupted (with
        SolverConfig(jacobian="lagged") and a snapshot without kept factorisations, one saved
        by a simulator of another Jacobian mode, the next step refactors and the continuation
        agrees with an uninterrupted run to newton_tol per step). Raises ValueError, state
        unchanged, for a state of another topology, term set, integrator, stepping (fixed or
        adaptive), precision, batch size or step, and for one saved by instances of other
        parameters, naming the first instance and field that differ: the state would go on under
        this simulator's coefficients, rest shape and start centroids, as no run did. With
        `other_params=True` that is what happens, on purpose (a parameter changed mid-run:
        the positions, velocities and firings carry over, the rest is this simulator's, and
        displacements are measured from this simulator's start); not with sensitivities
        (ValueError: the carried tangents are scaled by the saved parameters).

        The state goes on under this simulator's solver settings; where the snapshot records
        others (say newton_tol, or the Jacobian mode), a RuntimeWarning names them after the
        state is loaded: the continuation is then not the saved run's bit for bit."""
        check_flag("other_params", other_params)  # "no" would load other parameters' state
        if not isinstance(snapshot, SimulatorSnapshot):
            snapshot = SimulatorSnapshot.read(snapshot)
        if snapshot.engine_key != repr(self.engine_key):
            raise ValueError(f"the saved state belongs to another engine (topology, terms, "
                             f"integrator, capacity, stepping or sensitivities): "
                             f"{snapshot.engine_key} vs {self.engine_key!r}")
        if snapshot.n_instances != self.n_instances or snapshot.dt != self.solver.dt:
            raise ValueError(f"the saved state has {snapshot.n_instances} instances at dt = "
                             f"{snapshot.dt} s; this simulator {self.n_instances} at "
                             f"{self.solver.dt} s")
        # compared only where a difference is refused (other_params=True without sensitivities
        # takes any parameters: no need to compare 65,536 instances' texts)
        checked = snapshot.params if (self.directions or not other_params) else None
        if checked is not None and not checked:
            # a header without the parameters (a snapshot from before they were recorded, or
            # a damaged one) had skipped the comparison without a word (an audit, 2026-12)
            if self.directions:
                raise ValueError("the saved state records no parameters: a Simulator with "
                                 "sensitivities continues only its own parameters' state, "
                                 "which this snapshot cannot show")
            warn_user("the saved state records no parameters, so they cannot be compared with "
                      "this simulator's: it goes on under this simulator's parameters "
                      "(load(..., other_params=True) says that is meant)")
        if checked and len(checked) != self.n_instances:
            # zip would compare the first instances alone (a damaged header)
            raise ValueError(f"the saved state records the parameters of {len(checked)} "
                             f"instances for its {snapshot.n_instances} (a damaged snapshot)")
        default_params = parameter_texts([StarParams()])[0]
        for b, (saved, own) in enumerate(zip(checked or (), self._parameter_texts)):
            changed = differing_fields(saved, own, default_params)
            there = saved.get(changed[0], "not recorded: " + default_params[changed[0]]) \
                if changed else ""
            if changed and self.directions:
                # the replicas carry their tangents as offsets of ±ε of the saved parameters,
                # and ε is a share of the value: under others every derivative came out
                # mis-scaled (α 1.8 %, the joint radius 6.3 % off, no warning; an audit)
                raise ValueError(
                    f"the saved state belongs to instances of other parameters (instance {b}'s "
                    f"{changed[0]} is {there} there, "
                    f"{own[changed[0]]} here): a Simulator with sensitivities continues only "
                    f"its own parameters' state (other_params=True is for one without)")
            if changed and not other_params:
                raise ValueError(
                    f"the saved state belongs to instances of other parameters: instance "
                    f"{b}'s {changed[0]} is {there} there, "
                    f"{own[changed[0]]} here ({len(changed)} field(s) differ); load(..., "
                    f"other_params=True) continues it under this simulator's parameters")
        if snapshot.behind and (len(snapshot.behind) != self.n_instances or not all(
                math.isfinite(lag) and lag >= 0.0 for lag in snapshot.behind)):
            raise ValueError(f"the saved state records {len(snapshot.behind)} clock lags for "
                             f"its {snapshot.n_instances} instances, or one not finite and >= 0 "
                             f"(a damaged snapshot)")
        if snapshot.shown_s and (len(snapshot.shown_s) != self.n_instances or not all(
                math.isnan(time) or (math.isfinite(time) and time >= 0.0)
                for time in snapshot.shown_s)):
            raise ValueError(f"the saved state records {len(snapshot.shown_s)} clock times for "
                             f"its {snapshot.n_instances} instances, or one neither NaN nor "
                             f"finite and >= 0 (a damaged snapshot)")
        self.engine.restore_state(snapshot.fields, check=self._check_saved_clocks)
        loaded = self.engine.state.read(("status", "newton_max"), self.n_instances)
        self._running = loaded["status"] == STATUS_OK
        # a failed instance's records go on at the clock it would show (they fell back to its
        # frozen clock after a load: an audit, 2026-12)
        self._behind[:] = snapshot.behind if snapshot.behind else 0.0
        self._shown_s[:] = np.nan
        if snapshot.shown_s:
            self._shown_s[:] = snapshot.shown_s
        elif self.solver.adaptive:  # a snapshot from before: its lags, in seconds
            self._shown_s[:] = np.where(self._behind != 0.0, self.time_s + self._behind, np.nan)
            self._behind[:] = 0.0
        # the saved run's capped solves are its history, shown in state(), not news
        self._capped_named = newton_capped(loaded["newton_max"], self.solver)
        warn_about_other_code(snapshot.code)
        own = solver_texts(self.solver)
        defaults = solver_texts(SolverConfig())
        changed = differing_fields(snapshot.solver, own, defaults) if snapshot.solver else []
        if changed:
            saved = snapshot.solver.get(changed[0], "not recorded: " + defaults[changed[0]])
            warn_user(f"the saved state was stepped with {changed[0]} = {saved}, this simulator's "
                      f"is {own[changed[0]]} ({len(changed)} setting(s) differ): it goes on "
                      f"under this simulator's settings, not bit for bit as the saved run "
                      f"would have")

    def _check_saved_clocks(self, fields: Dict[str, np.ndarray]):
        """ValueError for a saved state whose robots' rows no run of this simulator holds: a
        robot marked "inactive" (the padding's status: it would never step again, and
        `state()` would show it as a robot that is not there), or, with fixed steps, a time
        other than the step count times dt, which is how the engine sets it (a clock edited
        apart from its count had loaded, and the records then took one and the firings the
        other: an audit, 2026-12)."""
        status = fields["status"]
        if (status[:self.n_instances] == STATUS_INACTIVE).any():
            robot = int(np.flatnonzero(status[:self.n_instances] == STATUS_INACTIVE)[0])
            raise ValueError(f"saved state field 'status' marks robot {robot} "
                             f"{STATUS_NAMES[STATUS_INACTIVE]!r}, the status of a batch's "
                             f"padding, not of a robot (a damaged file)")
        if self.solver.adaptive:
            return
        times, steps = fields["time"], fields["steps_done"]
        # the engine's own product: the step count in the state's precision times its dt
        real = times.dtype.type
        off = np.flatnonzero(times != steps.astype(times.dtype) * real(self.solver.dt))
        if off.size:
            raise ValueError(f"saved state field 'time' holds {float(times[off[0]])} s for row "
                             f"{int(off[0])}, not its {int(steps[off[0]])} fixed steps of "
                             f"{self.solver.dt} s (a damaged file)")

    def __repr__(self) -> str:
        times = self.time_s
        return (f"Simulator({self.n_instances} instances, t = {times.min():.4g}"
                f"{'' if times.min() == times.max() else f'..{times.max():.4g}'} s, "
                f"{int(self.ok.sum())} running)")
