"""The state of a batch on the device: what changes as the instances advance.

Positions and velocities, the integrator's history (the previous step's positions and
velocities, whether that history is valid), each instance's status and counters, its actuation
`actuation.Schedule` (what has fired, what is pending) and the histories the force terms keep
(see `physics.base.Term.history`). `save` copies all of it to NumPy and `restore` puts it back,
bitwise.
"""

from __future__ import annotations

from typing import Dict, List, Sequence, Tuple

import numpy as np
import taichi as ti
from taichi.lang.field import Field

from .actuation import NEVER, PENDING_CAPACITY, Schedule
from .fields import FieldArena, FieldStore, array_dtype, array_shape
from .gait import N_ACTUATORS

STATUS_OK, STATUS_NEWTON_FAILED, STATUS_NON_FINITE, STATUS_INACTIVE, STATUS_STEP_LIMIT = range(5)
STATUS_NAMES = ("ok", "newton_failed", "non_finite", "inactive", "step_limit")
"""Per-instance status; "inactive" marks the padding of a batch up to the engine's capacity;
"step_limit" an adaptive instance stopped before its stop time because its step count reached
the counter's limit (`timegrid.MAX_STEPS_PER_INSTANCE`) or its step no longer advanced its
time (a step below the time's rounding)."""
LATER_COUNTERS = ("factorisations", "steps_over_tolerance")
"""Work counters the state gained after states were first saved (`Simulator.save`): a saved
state without one (from an earlier version) restores with it at zero."""


SAVED_COUNTS = ("steps_done", "rejected_steps", "steps_over_tolerance", "newton_total",
                "newton_solves", "newton_max", "factorisations", "substep_retries",
                "gait_cycle_steps", "gait_cycles", "pending_count")
"""The counters of a saved state, each at least 0 (`check_saved_values`)."""


def check_saved_values(saved: Dict[str, np.ndarray]):
    """ValueError naming the first field of a saved state (`BatchState.save`'s, its shapes and
    types already checked) whose values no run holds: a status code past `STATUS_NAMES`, a
    negative counter, more pending firings than a schedule holds (`PENDING_CAPACITY`), a time
    that is negative, any real number not finite, a history flag other than 0 or 1, a pending
    firing of no actuator or out of time order. Such a state had loaded and then broken
    `state()` (an unknown status) or let the kernel read past a schedule's firings (an audit,
    2026-12)."""
    status = saved["status"]
    unknown = status[(status < 0) | (status >= len(STATUS_NAMES))]
    if unknown.size:
        raise ValueError(f"saved state field 'status' holds {unknown[0]}, not a status code in "
                         f"[0, {len(STATUS_NAMES) - 1}] (a damaged file)")
    for name in SAVED_COUNTS:
        if (saved[name] < 0).any():
            raise ValueError(f"saved state field {name!r} holds {saved[name].min()}, not a count "
                             f">= 0 (a damaged file)")
    if (saved["pending_count"] > PENDING_CAPACITY).any():
        raise ValueError(f"saved state field 'pending_count' holds {saved['pending_count'].max()}, "
                         f"more than the {PENDING_CAPACITY} firings a schedule holds (a damaged "
                         f"file)")
    times = saved["time"]
    if not (np.isfinite(times) & (times >= 0)).all():
        raise ValueError("saved state field 'time' holds a time that is negative or not finite "
                         "(a damaged file)")
    # a run holds every real number finite (a failed step is undone to its start): a NaN
    # position loaded as "ok", a NaN firing time dropped the firing (an audit, 2026-12)
    for name, values in saved.items():
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            raise ValueError(f"saved state field {name!r} holds a value that is not finite (a "
                             f"damaged file)")
    if not np.isin(saved["history_valid"], (0, 1)).all():
        raise ValueError("saved state field 'history_valid' holds a value other than 0 or 1 (a "
                         "damaged file)")
    # the pending firings a schedule holds: each fires some of the eight actuators (a mask in
    # [1, 255]; -1 had fired all eight), in the order of their times
    held = np.arange(PENDING_CAPACITY)[None, :] < saved["pending_count"][:, None]
    masks = saved["pending_actuators"][held]
    every = (1 << N_ACTUATORS) - 1
    outside = masks[(masks < 1) | (masks > every)]
    if outside.size:
        raise ValueError(f"saved state field 'pending_actuators' holds {outside[0]}, not a set "
                         f"of actuators in [1, {every}] (a damaged file)")
    due = saved["pending_due"]
    if (due[:, 1:] < due[:, :-1])[held[:, 1:]].any():
        raise ValueError("saved state field 'pending_due' holds firings out of the order of "
                         "their times (a damaged file)")


@ti.data_oriented
class BatchState:
    """Per-instance state of `capacity` instances of N nodes. Shapes (capacity, N) 2-vectors
    for positions (m) and velocities (m/s); (capacity,) for the rest."""

    def __init__(self, capacity: int, n_nodes: int, arena: FieldArena):
        per_node = (capacity, n_nodes)
        self.positions = arena.batch_field(float, per_node, vector=2)
        self.velocities = arena.batch_field(float, per_node, vector=2)
        self.previous = arena.batch_field(float, per_node, vector=2)
        """Positions at the start of the current (or last) step, m."""
        self.previous_velocities = arena.batch_field(float, per_node, vector=2)
        self.inertia_offset = arena.batch_field(float, per_node, vector=2)
        self.velocity_offset = arena.batch_field(float, per_node, vector=2)
        self.backup_positions = arena.batch_field(float, per_node, vector=2)
        self.backup_velocities = arena.batch_field(float, per_node, vector=2)
        self.history_valid = arena.batch_field(ti.i32, capacity)
        """1 when the last step was a full, accepted step (BDF2 may use it)."""
        self.status = arena.batch_field(ti.i32, capacity)
        self.failure_step = arena.batch_field(ti.i32, capacity)
        self.steps_done = arena.batch_field(ti.i32, capacity)
        """Accepted steps."""
        self.time = arena.batch_field(float, capacity)
        """The instance's current time, s."""
        self.failure_time = arena.batch_field(float, capacity)
        """End time of the step that failed, s."""
        self.step_size = arena.batch_field(float, capacity)
        """Adaptive stepping: the size of the next step to try, s."""
        self.previous_step_size = arena.batch_field(float, capacity)
        """Adaptive stepping: the size of the last accepted step, s."""
        self.stop_time = arena.batch_field(float, capacity)
        """Adaptive stepping: where the current launch advances the instance to, s."""
        self.rejected_steps = arena.batch_field(ti.i32, capacity)
        """Adaptive stepping: steps rejected by the error estimate or a failed Newton solve."""
        self.steps_over_tolerance = arena.batch_field(ti.i32, capacity)
        """Adaptive stepping: steps accepted with their error estimate above error_tol, because
        they could not shrink further (`stepping.at_smallest`)."""
        self.newton_total = arena.batch_field(ti.i64, capacity)
        """Newton iterations of every solve (retried substeps and rejected steps included)."""
        self.newton_solves = arena.batch_field(ti.i64, capacity)
        """Newton solves (one per attempted step or substep)."""
        self.newton_max = arena.batch_field(ti.i32, capacity)
        """Most Newton iterations of one solve."""
        self.factorisations = arena.batch_field(ti.i64, capacity)
        """Newton matrices assembled and factored (one per iteration with Newton's Jacobian,
        fewer with the chord's; a sensitive engine's tangent steps not included)."""
        self.substep_retries = arena.batch_field(ti.i32, capacity)
        self.schedule = Schedule(capacity, arena, self.time)
        """When the actuators fire: the periodic gait, pending commands, the last firings."""
        self.term_histories: Dict[str, Field] = {}
        self._reads: Dict[tuple, FieldStore] = {}
        """The stores of `read`, by the names they copy."""

    @property
    def fire_time(self) -> Field:
        """(capacity, 8) time (s) each actuator last fired (`actuation.Schedule.fire_time`)."""
        return self.schedule.fire_time

    @property
    def previous_fire_time(self) -> Field:
        """(capacity, 8) the firing before (`actuation.Schedule.previous_fire_time`)."""
        return self.schedule.previous_fire_time

    def own_fields(self) -> Dict[str, Field]:
        return {name: value for name, value in vars(self).items() if isinstance(value, Field)}

    def fields(self) -> Dict[str, Field]:
        """Every state field by name: the schedule's by their names (`Schedule.FIELD_NAMES`),
        the terms' histories as "<term>.<name>"."""
        return {**self.own_fields(), **self.schedule.fields(), **self.term_histories}

    @property
    def store(self) -> FieldStore:
        """Bulk copies of every state field (made on first use, once the terms' histories are
        in)."""
        if getattr(self, "_store", None) is None:
            self._store = FieldStore(self.fields())
        return self._store

    def read(self, names: Sequence[str], count: int) -> Dict[str, np.ndarray]:
        """The named state fields (`fields` names) of the first `count` instances, each of its
        own dtype, copied in one kernel: compiled once per tuple of names (kept), where a
        `to_numpy` per field compiles one kernel each, which costs more than the copy whenever
        an engine is new."""
        key = tuple(names)
        if key not in self._reads:
            fields = self.fields()
            self._reads[key] = FieldStore({name: fields[name] for name in key})
        return {name: values[:count] for name, values in self._reads[key].read().items()}

    def reset_fields(self) -> Tuple[Dict[str, Field], List[str]]:
        """(every state field by name, the names of those that a reset to rest zeroes on the
        device instead of copying): the per-node fields that are zero at rest (velocities, the
        step's start, the backups, the offsets: all but `positions`), which at a batch of
        65,536 would be gigabytes of zeros. The engine writes a reset with its load
        (`engine.BatchEngine.load`)."""
        zeroed = [name for name, field in self.own_fields().items()
                  if len(field.shape) == 2 and name != "positions"]
        return self.fields(), zeroed

    def initial_values(self, rest_positions: np.ndarray, batch_size: int) -> Dict[str, np.ndarray]:
        """The values of the state fields that a reset copies (`reset_fields`: all but the
        zeroed ones) with every instance at rest in its rest shape (capacity, N, 2), status ok
        (padding: inactive), counters and histories zero, nothing fired or scheduled; a caller
        may change entries before writing them."""
        fields, zeroed = self.reset_fields()
        values = {name: np.zeros(array_shape(field), dtype=array_dtype(field))
                  for name, field in fields.items() if name not in zeroed}
        values["positions"] = rest_positions
        values["status"] = np.where(np.arange(len(values["status"])) < batch_size, STATUS_OK,
                                    STATUS_INACTIVE)
        values["failure_step"][:] = -1
        for name in ("fire_time", "previous_fire_time"):
            values[name][:] = NEVER
        return values

    def save(self) -> Dict[str, np.ndarray]:
        """A copy of the whole state (every field, padding included)."""
        return self.store.read()

    def changed_instances(self, saved: Dict[str, np.ndarray]) -> np.ndarray:
        """(capacity,) bool: the instances whose fields in `saved` (a `save` of an engine of the
        same layout) differ in any bit from the state now; all of them where a field is
        missing or of another shape or type."""
        def bytes_per_instance(array):
            return np.ascontiguousarray(array).reshape(len(array), -1).view(np.uint8)

        now = self.save()
        changed = np.zeros(len(now["status"]), dtype=bool)
        for name, values in now.items():
            other = saved.get(name)
            if other is None or other.shape != values.shape or other.dtype != values.dtype:
                changed[:] = True
                continue
            changed |= (bytes_per_instance(values) != bytes_per_instance(other)).any(axis=1)
        return changed

    def restore(self, saved: Dict[str, np.ndarray], check=None):
        """Put back a state from `save` of an engine of the same layout, bitwise (a state saved
        before a `LATER_COUNTERS` counter was kept restores with it at zero). Raises ValueError,
        nothing written, naming the first field that does not match in shape or type, holds
        values no run holds (`check_saved_values`), or that `check` (a callable of the fields,
        called last: what only the caller knows, say its stepping) refuses."""
        shapes = self.store.shapes
        saved = {**{name: np.zeros(shapes[name], dtype=self.store.dtypes[name])
                    for name in LATER_COUNTERS},
                 **saved}
        if set(saved) != set(shapes):
            raise ValueError(f"saved state has fields {sorted(saved)}, this engine "
                             f"{sorted(shapes)} (another topology or term set)")
        self.store.check_saved(saved)
        check_saved_values(saved)
        if check is not None:
            check(saved)
        self.store.write(saved)
