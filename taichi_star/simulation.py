"""The public entry point: `simulate` a batch of StarParams and get pandas tables back."""

from __future__ import annotations

import dataclasses
import html
import math
import operator
import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np
import pandas as pd

from . import diagnostics, metrics, output
from .output import in_instance_order
from .provenance import local_time
from .checks import check_flag, is_finite_real, is_whole, shown, warn_user
from .geometry import CENTRE, Topology, build_topology
from .model import validate_batch
from .params import (PER_ACTUATOR_FIELDS, SolverConfig, StarParams, check_precision,
                     parameter_column)
from .driver import (Clock, RunTiming, check_run, drive, fewest_steps, robots_label,
                     shows_progress)
from . import sensitivities as tangents
from .runtime import (RECORDS_REMEDY, Runtime, check_arch, check_host_memory,
                      one_call_at_a_time, stream_chunk_size)
from .state import STATUS_NAMES, STATUS_OK
from .timegrid import SteadySpeedWarning, multiples_within, whole_steps


NOTEBOOK_COLUMNS = ("instance", "gait", "signed_speed_mm_s", "travel_direction_deg",
                    "heading_deg", "status", "failure_time_s")
"""The summary columns a notebook shows of a result (`SimulationResult._repr_html_`; instance
where it has one, a `run_batch` result's)."""
NOTEBOOK_ROWS = 10
"""The summary rows a notebook shows of a result; the rest are counted."""


@dataclass
class SimulationResult:
    """What `simulate` returns.

    `summary`: one row per instance, in input order. Its first columns are the instance's
    parameters, every StarParams field named with its unit where it has one (youngs_modulus_pa,
    period_s, thickness_m, ...: `StarParams.columns()`; `StarParams.from_row(row)` rebuilds the
    parameters of a row, also of a table read back from CSV, Parquet or netCDF; the
    actuator_profile column holds the profile's text, `CurvatureProfile.to_text`, and the
    per-actuator columns actuator_gains and actuator_delays_s the text of their tuples). Then the
    run's results (metrics of a failed instance are NaN):

    | column | unit | meaning |
    |---|---|---|
    | displacement_x_mm | mm | centroid displacement along x over the whole run |
    | displacement_y_mm | mm | centroid displacement along y over the whole run |
    | speed_mm_s | mm/s | length of the displacement / duration |
    | signed_speed_mm_s | mm/s | displacement on the gait's forward direction / duration (NaN where no direction is defined) |
    | travel_direction_deg | degree | direction of the displacement, from +x |
    | heading_deg | degree | body rotation at the end, counter-clockwise |
    | max_strain | — | largest absolute axial strain of an edge in the final shape |
    | shape_sane | — | final shape finite, no limbs crossing, no arc inverted, max_strain within `metrics.STRAIN_LIMIT` (False: not physical even if converged; False for a failed instance too, whose run has no final shape) |
    | steady_speed_mm_s | mm/s | speed over cycles [steady_from_cycle, last full cycle) (NaN with fewer cycles, or cycle boundaries not whole steps) |
    | steady_signed_speed_mm_s | mm/s | signed speed over the same cycles |
    | steps | — | accepted time steps |
    | rejected_steps | — | steps rejected by the adaptive error control |
    | steps_over_tolerance | — | adaptive steps accepted with their error estimate above error_tol, at dt_min where they could not shrink further (0 otherwise: with more, the run does not hold error_tol there; a smaller dt_min may) |
    | newton_iterations_mean | — | Newton iterations per solve (every attempted step and substep, rejected and failed ones included) |
    | newton_iterations_max | — | most Newton iterations of one solve (≥ the mean) |
    | factorisations_mean | — | Newton matrices assembled and factored per solve: newton_iterations_mean with Newton's Jacobian, fewer with the chord's (which keeps a factorisation while it contracts) |
    | substep_retries | — | steps redone with substeps |
    | newton_capped | — | a Newton solve used all max_newton iterations (ran out of them, or converged on the last; for an "ok" instance that ran out: a step accepted only after a retry rescued it, with the chord or lagged Jacobian maybe the same step's solve started again with Newton's; in f32 also a RuntimeWarning). A retry for a non-finite update counts in substep_retries without it |
    | status | — | "ok", "newton_failed", "non_finite" or (adaptive steps) "step_limit" |
    | failure_time_s | s | simulated time of the failure (NaN when ok) |

    "ok" means every step converged to newton_tol, not that the time step is small enough:
    see docs/numerics.md, "What ok promises". An ok instance whose final shape is not physical
    (shape_sane False) is reported in a RuntimeWarning as well.

    `trajectory`: long table (instance, t_s, x_mm, y_mm, heading_deg): the centroid relative to
    its start and the body rotation at every record time (NaN from a failure on); empty without
    records. A record's t_s is its step count × dt, with adaptive steps its multiple
    k·record_interval_s, the same for every instance (the last one a rounding past a duration
    it ends: 3 × 0.2 s = 0.6000000000000001 s for 0.6 s).

    `shapes`: (n_records, B, N, 2) node positions in m at the record times, when requested.

    With `simulate(..., sensitivities=names)`: `sensitivities`, one row per instance with a
    column "d(output)/d(parameter)" for every output of `sensitivities.SUMMARY_OUTPUTS` and
    every parameter (in the output's unit per the parameter's unit), and
    `trajectory_sensitivities`, the same for x_mm, y_mm and heading_deg at every record
    (instance, t_s, ...); `sensitivity(output, parameter)` reads one as an array.
    """

    summary: pd.DataFrame
    trajectory: pd.DataFrame
    shapes: Optional[np.ndarray]
    topology: Optional[Topology] = field(repr=False)
    """The batch's topology (None for a run_batch result mixing topologies)."""
    solver: SolverConfig = field(repr=False)
    sensitivities: Optional[pd.DataFrame] = field(default=None, repr=False)
    trajectory_sensitivities: Optional[pd.DataFrame] = field(default=None, repr=False)
    timing: Optional[RunTiming] = field(default=None, repr=False)
    arch: Optional[str] = field(default=None, repr=False)
    """The arch the run used ("cpu", "gpu", ...; `simulate`'s and `run_batch`'s argument), which
    the result files record (results on two archs may differ in the last bits)."""
    code_versions: Optional[List[Dict]] = field(default=None, repr=False)
    """A `run_batch` result read from a run store that more than one code version wrote: each
    version (`provenance.code_version`) with the indices of the chunks it made ("chunks"), as
    the store's manifest keeps them; None for a result of one code version."""
    made_at: Optional[str] = field(default=None, repr=False)
    """When the result was made (`provenance.local_time`, set when it is built),
    which its files record as their `date` (they gave the moment a file was written: an audit,
    2026-12); the code and machine they record are those of the writing process."""
    arguments: Optional[Dict] = field(default=None, repr=False)
    """The call that made the result, as its files record it (`output.provenance`): "function"
    ("simulate" or "run_batch") and the arguments its tables do not hold: duration_s (s, as
    simulated: with fixed steps the whole steps it was rounded to; run_batch's as given, None
    with cycles), cycles (run_batch's; None with duration_s), record_interval_s (s),
    record_shapes, steady_from_cycle (which the steady speeds are measured from), sensitivities
    (the parameters differentiated by, as labels: "actuator_gains[0]", ...) and chunk_size
    (run_batch's). None for a result built otherwise."""

    def __post_init__(self):
        if self.made_at is None:
            self.made_at = local_time()

    def sensitivity(self, output: str, parameter: str, trajectory: bool = False) -> np.ndarray:
        """d(output)/d(parameter) for every instance: (B,) for a summary output
        (`sensitivities.SUMMARY_OUTPUTS`), (B, n_records) for a trajectory one (x_mm, y_mm, and
        heading_deg with `trajectory=True`: the summary has a heading_deg too; a `run_batch`
        of several durations, whose instances have different records: (B, n_times) over every
        record time of the batch in order, NaN where an instance has no record). `parameter`
        as named in `simulate` ("alpha"; "actuator_gains" gives (B, 8) or (B, 8, n_records),
        "actuator_gains[2]" one actuator). ValueError for an output or parameter the run did
        not differentiate."""
        if self.sensitivities is None:
            raise ValueError("this result has no sensitivities: pass sensitivities=(...) to "
                             "simulate")
        trajectory = check_flag("trajectory", trajectory)
        outputs = list(dict.fromkeys(tangents.SUMMARY_OUTPUTS + tangents.TRAJECTORY_OUTPUTS))
        if output not in outputs:   # before the parameter: swapped arguments name the output
            raise ValueError(f"output must be one of {outputs}, got {output!r}")
        directions = tangents.parse_parameter(parameter)
        if output in tangents.SUMMARY_OUTPUTS and not trajectory:
            table = in_instance_order(self.sensitivities, "sensitivities")
            shape = (len(self.summary),)
        elif output in tangents.TRAJECTORY_OUTPUTS:
            table = in_instance_order(self.trajectory_sensitivities,
                                      "trajectory_sensitivities")
            shape = (len(self.summary), len(table) // max(len(self.summary), 1))
            if shape[1] == 0:
                raise ValueError(f"output {output!r}: this run recorded no trajectory "
                                 f"(simulate with record_interval_s > 0 for it)")
        else:
            raise ValueError(f"output {output!r} is a summary output, not one of the trajectory's "
                             f"{list(tangents.TRAJECTORY_OUTPUTS)} (trajectory=True)")
        columns = [tangents.sensitivity_column(output, direction.label) for direction in directions]
        missing = [column for column in columns if column not in table]
        if missing:
            prefix = tangents.sensitivity_column(output, "")[:-1]
            differentiated = [column[len(prefix):-1] for column in table.columns
                              if column.startswith(prefix)]
            raise ValueError(f"parameter {parameter!r} was not among this run's sensitivities "
                             f"{differentiated}")
        if len(shape) == 2 and len(table) != shape[0] * shape[1]:
            # records of several durations (`run_batch(cycles=...)` over several periods): on
            # the union of their times, as `to_xarray` lays them out
            values = np.stack([table.pivot(index="instance", columns="t_s", values=column)
                               .reindex(index=range(shape[0])).to_numpy()
                               for column in columns], axis=1)
        else:
            values = np.stack([table[column].to_numpy().reshape(shape) for column in columns],
                              axis=1)
        return values if len(columns) > 1 else values[:, 0]

    def to_xarray(self):
        """The result as a labelled xarray Dataset with units (see `output.to_xarray`)."""
        return output.to_xarray(self)

    def to_netcdf(self, path):
        """Save `to_xarray()` as a netCDF file (whole or not at all; the provenance in its
        attributes); returns the path."""
        return output.to_netcdf(self, path)

    def to_parquet(self, path, table: str = "summary"):
        """Save the summary (or table="trajectory", and with sensitivities "sensitivities" or
        "trajectory_sensitivities") as Parquet, whole or not at all, with the
        provenance (version, git commit, parameters, solver) in the file's metadata
        (`output.read_provenance`); returns the path. `self.summary.to_parquet(path)` (plain
        pandas) works too, without the provenance. Needs pyarrow (the `io` extra)."""
        return output.to_parquet(self, path, table)

    def to_csv(self, path, table: str = "summary"):
        """Save the summary (or another of `output.TABLES`) as CSV with the provenance in a
        JSON sidecar `<path>.json`, each whole or not at all; returns the path."""
        return output.to_csv(self, path, table)

    def jet_impulses(self) -> pd.DataFrame:
        """Each inter-limb space's jet impulse on the robot over the run, one row per instance
        and space (`diagnostics.jet_impulses`: needs shapes recorded at every step of a
        fixed-step implicit Euler run)."""
        return diagnostics.jet_impulses(self)

    def animate(self, path, instances=None, frame: str = "world", fps: int = 15,
                size_px: int = 720, title=None):
        """Animate the recorded shapes to an MP4 or GIF: fired actuators red while they heat,
        labels A1..A8, a scale bar, the centroid's path (see `output.animate`)."""
        return output.animate(self, path, instances=instances, frame=frame, fps=fps,
                              size_px=size_px, title=title)

    def _repr_html_(self) -> str:
        """A notebook cell's view of the result: the repr's line, the sensitivities' parameters
        where it has them, and the first `NOTEBOOK_ROWS` rows of the summary's
        `NOTEBOOK_COLUMNS` (which a robot, how fast and which way, whether it is right); the
        whole table is `result.summary` (pandas draws that one itself)."""
        shown_rows = self.summary[[column for column in NOTEBOOK_COLUMNS
                                   if column in self.summary]].head(NOTEBOOK_ROWS)
        parts = [f"<p><code>{html.escape(repr(self))}</code></p>"]
        labels = (self.arguments or {}).get("sensitivities")
        if labels:
            parts.append(f"<p>differentiated by {html.escape(', '.join(labels))}: "
                         f"<code>result.sensitivity(output, parameter)</code></p>")
        parts.append(shown_rows.to_html())
        hidden = len(self.summary) - len(shown_rows)
        parts.append(f"<p>{f'{hidden} more rows; ' if hidden else ''}all "
                     f"{len(self.summary.columns)} columns: <code>result.summary</code></p>")
        return "\n".join(parts)

    def __repr__(self) -> str:
        status = self.summary["status"].value_counts().to_dict() if len(self.summary) else {}
        timing = f"; {self.timing}" if self.timing is not None else ""
        return (f"SimulationResult({len(self.summary)} instances, status {status}, "
                f"{self.trajectory['t_s'].nunique() if len(self.trajectory) else 0} records, "
                f"shapes {'recorded' if self.shapes is not None else 'not recorded'}{timing})")


def _check_seconds(name, value, allow_zero=False):
    """`value` (s) as a float, judged as the float it becomes (10**400 is not finite, a
    fraction that rounds to 0 is 0); ValueError naming `name`, the bound and its unit
    otherwise."""
    number = float(value) if is_finite_real(value) else math.nan
    if not (number > 0.0 or (allow_zero and number == 0.0)):
        bound = ">= 0 s" if allow_zero else "> 0 s"
        raise ValueError(f"{name} must be a finite number {bound}, got {shown(value)}")
    return number


RECORD_ROW_BYTES = 160
"""Host memory (bytes) a record of one instance takes in `simulate` at its peak (its centroid
and heading, the arrays made of them, its row of the trajectory table): measured 103 (f64,
B = 64, 10,001 records; docs/reliability.md), with room."""
RECORD_NODE_BYTES = 40
"""... and a recorded shape's, per node (two f64 as recorded and as stacked: measured 32.6)."""
RECORD_BYTES = 1024
"""... and each record whatever the batch (its stop in the clock's lists: measured 540)."""
SUMMARY_ROW_BYTES = 1024
"""Host memory (bytes) of an instance's row of the summary (about 60 columns, the parameters'
texts among them): measured 659 (`memory_usage(deep=True)`, 4,096 instances)."""


def tables_bytes(params, duration_s: float, record_interval_s: float, record_shapes: bool,
                 replicas: int = 1, per_call: bool = True) -> float:
    """Host memory (bytes) of a run's tables at their peak: the summary, and with records
    (every record_interval_s s; 0 = none) the trajectory and the shapes (`SUMMARY_ROW_BYTES`,
    `RECORD_ROW_BYTES`, `RECORD_NODE_BYTES`, and with `per_call` the run's own `RECORD_BYTES`,
    which a batch gathering its chunks' tables does not keep); `replicas` instances simulated
    per instance (sensitivities add them; shapes are kept of the first alone)."""
    needed = len(params) * replicas * SUMMARY_ROW_BYTES
    if record_interval_s:
        records = multiples_within(duration_s, record_interval_s) + 1
        nodes = build_topology(params[0]).n_nodes if record_shapes else 0
        needed += records * (len(params) * (replicas * RECORD_ROW_BYTES
                                            + nodes * RECORD_NODE_BYTES)
                             + (RECORD_BYTES if per_call else 0))
    return needed


def check_tables_memory(params, duration_s: float, record_interval_s: float,
                        record_shapes: bool, replicas: int = 1):
    """ValueError before any compute when a run's tables (`tables_bytes`) would not fit in the
    memory budget (`runtime.check_host_memory`; the engine is streamed in chunks that fit,
    `stream_chunk_size`, the tables are not)."""
    instances = robots_label(len(params) * replicas, "instance")
    if record_interval_s:
        records = multiples_within(duration_s, record_interval_s) + 1
        name, what, remedy = (
            "record_interval_s", f"the summary and {records:,} records of {instances}"
            f"{' with their shapes' if record_shapes else ''}", RECORDS_REMEDY)
    else:
        name, what, remedy = "params", f"the summary of {instances}", \
            "simulate the batch in parts"
    check_host_memory(name, what, tables_bytes(params, duration_s, record_interval_s,
                                                record_shapes, replicas), remedy)


def validate_call(params, duration_s, solver, record_interval_s, record_shapes, steady_from_cycle,
                  replicas: int = 1, arch: Optional[str] = None):
    """Check simulate's arguments before any compute; returns (params tuple, duration in s,
    record interval in s or 0). With fixed steps the duration is rounded to whole steps and the
    record interval must be a whole number of steps. `replicas`: the instances simulated per
    instance asked for (sensitivities add replicas): the work and the records count them.
    `arch`: where the call runs, for the work's bound (`driver.check_run`; None: a chunk that
    may run on another machine, which holds it to its own bound there)."""
    params = validate_batch(params)
    duration_s = _check_seconds("duration_s", duration_s)
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    check_precision(params, solver)
    record_interval_s = _check_seconds("record_interval_s", record_interval_s, allow_zero=True)
    check_run(solver, duration_s, record_interval_s, len(params) * replicas, arch=arch,
              nodes=params[0].n_nodes)
    if check_flag("record_shapes", record_shapes) and record_interval_s == 0:
        raise ValueError("record_shapes needs record_interval_s > 0 (the spacing of the records)")
    check_tables_memory(params, duration_s, record_interval_s, record_shapes, replicas)
    if not is_whole(steady_from_cycle) or steady_from_cycle < 0:
        raise ValueError(f"steady_from_cycle must be an integer >= 0, got {steady_from_cycle!r}")
    return params, duration_s, record_interval_s


def cycle_starts_taken(period: float, solver: SolverConfig) -> bool:
    """Whether a run takes the centroid at each cycle start of `period` (s), where the steady
    speeds are measured: adaptive steps stop there, fixed ones where the period is a whole
    number of steps."""
    return solver.adaptive or whole_steps(period, solver.dt) is not None


def off_grid_periods(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                     steady_from_cycle: int) -> List[int]:
    """The positions in `params` whose steady speeds a fixed-step run of duration_s (s) leaves
    NaN only because the period is not a whole number of steps of dt: their cycles begin
    between steps (each fired at its exact time), where no centroid is taken, though the run
    holds a whole cycle after cycle `steady_from_cycle`. Empty with adaptive steps, which stop
    at every cycle start (`cycle_starts_taken`)."""
    simulated = Clock(solver, duration_s).simulated_s
    # once per period: a batch has few (per instance it took 0.6 s for 100,000 robots)
    left_nan = {period: not cycle_starts_taken(period, solver)
                and multiples_within(simulated, period) > steady_from_cycle
                for period in {p.period for p in params}}
    return [position for position, p in enumerate(params) if left_nan[p.period]]


def warn_off_grid_periods(positions: Sequence[int], params: Sequence[StarParams], dt: float):
    """A RuntimeWarning (kind "off_grid_period") naming the instances of `off_grid_periods`
    (`positions` in `params`, run at steps of dt s): their steady speeds came out NaN with
    status ok and no word (an audit, 2026-12)."""
    if positions:
        first = params[positions[0]]
        warn_user(f"{len(positions)} of {len(params)} instances (the first params[{positions[0]}],"
                  f" period {first.period!r} s) have a period that is not a whole number of "
                  f"steps (dt = {dt!r} s): their cycles begin between steps, and "
                  f"steady_speed_mm_s and steady_signed_speed_mm_s, taken at cycle starts, are "
                  f"NaN (a dt that divides the period, or adaptive steps, give them)",
                  kind="off_grid_period", category=SteadySpeedWarning)


def cycles_cut_short(params: Sequence[StarParams], duration_s: float, solver: SolverConfig,
                     steady_from_cycle: int) -> List[int]:
    """The positions in `params` whose adaptive run of duration_s (s) ends at most dt_min
    before the start of a cycle that the steady speeds would then have taken in: a duration
    of k·T held in float32 or written to a few digits (0.8999999762 s for three periods of
    0.3 s) left out the last cycle (their steady speed 11 % off, silently: an audit, 2026-12),
    where fixed steps round such a duration to k·T. Empty with fixed steps."""
    if not solver.adaptive:
        return []
    cut = []
    for position, p in enumerate(params):
        begun = periods_begun(duration_s, p.period)
        if begun > steady_from_cycle and begun * p.period - duration_s <= solver.dt_min:
            cut.append(position)
    return cut


def periods_begun(duration_s: float, period: float) -> int:
    """The periods (s) a run of duration_s (s) has begun: its whole ones and the one it ends in
    (`timegrid.multiples_within` + 1)."""
    return multiples_within(duration_s, period) + 1


def warn_cycles_cut_short(positions: Sequence[int], params: Sequence[StarParams],
                          duration_s: float):
    """A RuntimeWarning (kind "cycle_cut_short") naming the instances of `cycles_cut_short`."""
    if positions:
        period = params[positions[0]].period
        cycle = periods_begun(duration_s, period)
        warn_user(f"duration_s = {duration_s!r} s ends {cycle * period - duration_s:.3g} s "
                  f"short of {cycle} whole periods of {len(positions)} of {len(params)} "
                  f"instances (the first params[{positions[0]}], period {period!r} s): their "
                  f"steady speeds leave out the last of them (duration_s = "
                  f"{cycle * period:.12g} s takes it in)", kind="cycle_cut_short",
                  category=SteadySpeedWarning)


@one_call_at_a_time
def simulate(params: Sequence[StarParams], duration_s: float, solver: SolverConfig = SolverConfig(),
             *, arch: str = "cpu", record_interval_s: float = 0.0, record_shapes: bool = False,
             steady_from_cycle: int = 1, progress: Optional[bool] = None,
             sensitivities: Sequence[str] = ()) -> SimulationResult:
    """Simulate a batch of robot instances (a sequence of StarParams; a single StarParams is a
    batch of one) from rest in their rest shape for duration_s seconds and return a `SimulationResult` (see there for every column, with units).

    Every instance may have its own parameters except the topology (n_arc, n_limb), and fires
    its gait at t = 0 and at the start of every period. An instance whose Newton solve fails
    (even with substeps, or at the smallest adaptive step) is frozen and reported (status,
    failure_time_s); the others are unaffected. With fixed steps (the default) the duration is
    rounded to whole steps of solver.dt and record_interval_s (s; 0 = no records) must be a whole
    number of steps (`timegrid.nearest_interval` gives the nearest one,
    `timegrid.interval_for_count` one for a number of records); with `solver.adaptive` every
    instance chooses its own steps, which land exactly on the records, the cycle starts and the
    end. record_shapes adds the node positions at the records. The centroid is also taken at
    every cycle start (with fixed steps: those that fall on a step) for the steady speeds from
    cycle `steady_from_cycle` on. `progress`: a progress bar in simulated seconds (None: where
    the run is estimated at `driver.AUTO_PROGRESS_S` or more). Raises ValueError for any bad
    argument before computing anything.

    `sensitivities`: StarParams fields (`params.DIFFERENTIABLE_FIELDS`; "actuator_gains" for
    all eight, "actuator_gains[3]" for one) to differentiate every output by, for every
    instance (`SimulationResult.sensitivity`; how: `taichi_star.sensitivities`). Each one costs
    two replica instances per instance, which are moved along the exact tangent, not solved;
    the gain or delay of an actuator an instance has not fired costs next to no time until it
    fires (its derivative is exactly 0 until then).

    Memory: on the CPU a batch larger than one engine of `runtime.CPU_ENGINE_BUDGET_BYTES` is
    streamed through such an engine in equal chunks, one after the other; the result is the
    same, bit for bit, as in one engine (instances never interact), and the memory a batch
    needs grows only with its tables. The engine stays for later calls, the process's kept
    engines within `runtime.FREE_ENGINES_BYTES` (`Runtime.release_engines` gives them back)."""
    directions = tangents.parse_directions(sensitivities)
    # replicas travel in their instance's chunk: a chunk holds (1 + 2·directions) × its instances
    per_instance = tangents.instances_per_instance(len(directions))
    params, duration_s, record_interval_s = validate_call(params, duration_s, solver,
                                                          record_interval_s, record_shapes,
                                                          steady_from_cycle, per_instance, arch)
    progress = shows_progress(progress, fewest_steps(solver, duration_s, record_interval_s)[0]
                              * len(params) * per_instance, params[0].n_nodes)
    tangents.check_directions(directions, params, solver, duration_s=duration_s)
    check_arch(arch)
    warn_off_grid_periods(off_grid_periods(params, duration_s, solver, steady_from_cycle), params,
                          solver.dt)
    warn_cycles_cut_short(cycles_cut_short(params, duration_s, solver, steady_from_cycle), params,
                          duration_s)
    started = time.perf_counter()
    runtime = Runtime.current()
    runtime.ensure(arch, solver.precision)
    initialise_s = time.perf_counter() - started
    chunk = stream_chunk_size(params, solver.precision, arch, per_instance)
    # parts as equal as whole robots allow (steps of `chunk` left the rest to a last sliver:
    # 421 robots as 20 of 21 and one, a review, 2026-12)
    count = -(-len(params) // chunk)
    bounds = [len(params) * part // count for part in range(count + 1)]
    results = []
    for number, (start, end) in enumerate(zip(bounds, bounds[1:])):
        label = robots_label(end - start) + (f", chunk {number + 1}/{count}" if count > 1 else "")
        results.append(_simulate_chunk(params[start:end], duration_s, solver, runtime,
                                       record_interval_s, record_shapes, steady_from_cycle,
                                       label if progress else None, directions,
                                       chunk * per_instance))
    result = results[0] if len(results) == 1 else _concatenate(results)
    # once for the whole batch, its rows renumbered (each chunk named its own rows)
    warn_about_ok_instances(result.summary, solver)
    result.timing = dataclasses.replace(result.timing, setup_s=result.timing.setup_s + initialise_s)
    result.arch = arch
    clock = Clock(solver, duration_s)
    result.arguments = call_arguments("simulate", clock.simulated_s, None,
                                      record_interval_s, record_shapes, steady_from_cycle,
                                      [direction.label for direction in directions], None)
    return result


def call_arguments(function: str, duration_s, cycles, record_interval_s, record_shapes,
                   steady_from_cycle, sensitivities, chunk_size) -> Dict:
    """`SimulationResult.arguments` of a call of `function` ("simulate" or "run_batch"), as
    plain JSON values (None where the call has no such argument)."""
    return {"function": function,
            "duration_s": None if duration_s is None else float(duration_s),
            "cycles": None if cycles is None else float(cycles),
            "record_interval_s": float(record_interval_s), "record_shapes": bool(record_shapes),
            "steady_from_cycle": int(steady_from_cycle), "sensitivities": list(sensitivities),
            "chunk_size": None if chunk_size is None else int(chunk_size)}


def _concatenate(results: Sequence[SimulationResult]) -> SimulationResult:
    """One result from the results of consecutive chunks of a batch (instances renumbered)."""
    offsets = np.cumsum([0] + [len(result.summary) for result in results[:-1]])
    trajectory = pd.concat([result.trajectory.assign(instance=result.trajectory["instance"] + offset)
                            for result, offset in zip(results, offsets)], ignore_index=True)
    shapes = (np.concatenate([result.shapes for result in results], axis=1)
              if results[0].shapes is not None else None)
    sensitivities, trajectory_sensitivities = None, None
    if results[0].sensitivities is not None:
        sensitivities = pd.concat([result.sensitivities for result in results], ignore_index=True)
        trajectory_sensitivities = pd.concat(
            [result.trajectory_sensitivities.assign(
                instance=result.trajectory_sensitivities["instance"] + offset)
             for result, offset in zip(results, offsets)], ignore_index=True)
    return SimulationResult(summary=pd.concat([result.summary for result in results],
                                              ignore_index=True),
                            trajectory=trajectory, shapes=shapes, topology=results[0].topology,
                            solver=results[0].solver, sensitivities=sensitivities,
                            trajectory_sensitivities=trajectory_sensitivities,
                            timing=sum((result.timing for result in results[1:]), results[0].timing))


def _simulate_chunk(params, duration_s, solver, runtime, record_interval_s, record_shapes,
                    steady_from_cycle, progress_label, directions=(), chunk_instances=0):
    """`simulate` of one batch in one engine (arguments validated, Taichi initialised):
    the engine of `chunk_instances` instances (replicas included) where that is more, so that
    every chunk of a streamed call takes its first chunk's (its capacity and lanes,
    `runtime.engine_capacity`, `Runtime.engine_lanes`: the last, smaller, took one of its own,
    and with the kept engines bounded each call destroyed and built both again, a review,
    2026-12); progress_label: the progress bar's description, None for no bar; `directions`:
    those of the sensitivities (`sensitivities.parse_directions`). The result's `timing` has
    every phase but Taichi's initialisation (`simulate` adds it)."""
    started = time.perf_counter()
    model, steps = tangents.replica_model(params, directions)
    params = model.params
    clock = Clock(solver, duration_s)
    engine_instances = max(len(params), chunk_instances)
    work = None if clock.adaptive else engine_instances * clock.end
    engine = runtime.engine_for(model, solver, tangents=len(directions), robot_steps=work,
                                least_batch=engine_instances)
    set_up = time.perf_counter()
    engine.compile_stepping(solver.adaptive)
    compiled = time.perf_counter()
    batch = model.batch_size

    record_stops = clock.stops_every(record_interval_s) if record_interval_s else []
    by_stop = {}
    n_boundaries = 1
    stops_of_period = {}  # a batch has few periods
    for b, p in enumerate(params):
        if p.period not in stops_of_period:
            stops_of_period[p.period] = (clock.stops_every(p.period)
                                         if cycle_starts_taken(p.period, solver) else None)
        boundary_stops = stops_of_period[p.period]
        if boundary_stops is not None:
            n_boundaries = max(n_boundaries, len(boundary_stops))
            for index, stop in enumerate(boundary_stops):
                by_stop.setdefault(stop, []).append((b, index))
    boundaries = np.full((batch, n_boundaries, 2), np.nan)
    # the start is always taken: the centroids of the first cycle start
    stops = sorted(set(record_stops) | set(by_stop) | {0, clock.end})
    record_set = set(record_stops)

    centroids, rotations, shapes = [], [], []
    state = engine.state
    # the instances the caller asked for; a sensitive batch's replicas follow them, and their
    # shapes would only be dropped (kept, they held 17× the memory of the result's)
    primal = len(params) // tangents.instances_per_instance(len(directions))

    def take(stop):
        now = engine.centroids_of(batch)
        for b, index in by_stop.get(stop, ()):
            boundaries[b, index] = now[b]
        if stop in record_set:
            # in float64 as the summary's and the Simulator's headings are: an f32 heading
            # differed from theirs by ~2 % at the same state (an audit, 2026-12)
            positions = state.positions.to_numpy()[:batch].astype(np.float64)
            centroids.append(now)
            rotations.append(metrics.body_rotation(positions, model.rest_positions,
                                                   model.topology.joints, CENTRE))
            if record_shapes:
                shapes.append(positions[:primal].copy())  # not a view of the replicas too

    start_centroids = engine.centroids_of(batch)
    # fixed steps never end a step early for a stop: only adaptive ones need each its own
    stop_groups = (_stops_by_period(params, stops_of_period, stops, record_set | {0, clock.end})
                   if clock.adaptive else None)
    drive(engine, clock, stops, take, batch, progress_label=progress_label,
          stop_groups=stop_groups)
    ran = time.perf_counter()
    record_times = clock.times_every(record_interval_s) if record_interval_s else np.array([])
    result = _collect(engine, model, solver, clock.simulated_s, record_times,
                      start_centroids, centroids, rotations, shapes, boundaries, steady_from_cycle)
    if directions:
        summary, trajectory, sensitivities, trajectory_sensitivities = tangents.split_result(
            result.summary, result.trajectory, directions, steps)
        result = SimulationResult(
            summary=summary, trajectory=trajectory, shapes=result.shapes,
            topology=result.topology, solver=solver, sensitivities=sensitivities,
            trajectory_sensitivities=trajectory_sensitivities)
    result.timing = RunTiming(setup_s=set_up - started, compile_s=compiled - set_up,
                              run_s=ran - compiled, collect_s=time.perf_counter() - ran,
                              robot_steps=int(result.summary["steps"].sum()))
    return result


def _stops_by_period(params, stops_of_period: dict, stops: list, shared: set):
    """`drive`'s stop_groups: one group per period of the batch, its own stops the `shared`
    ones (records, start, end) and the boundaries of its cycles (`stops_of_period`)."""
    index_of = {stop: index for index, stop in enumerate(stops)}
    common = [index_of[stop] for stop in shared]
    group_of = {period: g for g, period in enumerate(stops_of_period)}
    own = [np.unique(common + [index_of[stop] for stop in boundaries or ()])
           for boundaries in stops_of_period.values()]
    return own, np.array([group_of[p.period] for p in params], dtype=np.int64)


def _texts(values: Sequence, to_text) -> list:
    """to_text(value) of every value, computed once per distinct object: a batch of 65,536
    instances shares a few profiles and gain tuples, and these are immutable."""
    by_object = {}
    for value in values:
        if id(value) not in by_object:
            by_object[id(value)] = to_text(value)
    return [by_object[id(value)] for value in values]


SUMMARY_STATE = ("status", "failure_time", "failure_step", "steps_done", "rejected_steps",
                 "steps_over_tolerance", "newton_total", "newton_solves", "newton_max",
                 "factorisations", "substep_retries", "positions")
"""The state fields a run's summary reads at its end (`BatchState.read`)."""


def failure_times(status: np.ndarray, failure_time: np.ndarray, failure_step: np.ndarray,
                  solver: SolverConfig) -> np.ndarray:
    """(B,) float64: when each failed instance stopped (s), NaN for the others; the engine's
    `failure_time`, `failure_step` and `status` (B,) each. With fixed steps the failing step's
    end in float64, failure_step × dt: the engine's own in the state's precision was an f32
    rounding of it, and a record at the failing step's end read as before the failure (its
    frozen position instead of NaN: an audit, 2026-12); in f64 the same number."""
    failed = status != STATUS_OK
    if solver.adaptive:
        return np.where(failed, failure_time.astype(np.float64), np.nan)
    return np.where(failed, failure_step.astype(np.float64) * solver.dt, np.nan)


def newton_capped(newton_max: np.ndarray, solver: SolverConfig) -> np.ndarray:
    """(B,) bool: instances a Newton solve of which used all the solver's max_newton iterations
    (`newton_max`: (B,) each one's most iterations in a solve)."""
    return np.asarray(newton_max) >= solver.max_newton


def warn_about_capped(capped: np.ndarray, names: np.ndarray, solver: SolverConfig):
    """The RuntimeWarning of `warn_about_ok_instances` about "ok" instances whose Newton solves
    used all max_newton iterations: `capped` (B,) bool marks them, `names` (B,) names the
    instances (the first capped one is named); nothing where none is capped."""
    if not capped.any():
        return
    if solver.precision == "f32":
        reason = (f"f32 barely resolves newton_tol = {solver.newton_tol:g} m for them, and "
                  f"their results can be far off; run them in f64")
    else:
        reason = ("such runs can have converged to another solution of a step's equations "
                  "(at a re-firing's jump) or more loosely than newton_tol (where the "
                  "robot's shortest edge is far below its size): check them with a "
                  "smaller dt")
    warn_user(f"{int(capped.sum())} of {len(capped)} {solver.precision} instances (the "
              f"first: instance {names[np.flatnonzero(capped)[0]]}) are 'ok' only after a "
              f"Newton solve used all its {solver.max_newton} iterations (newton_capped): "
              f"{reason}", kind="ok_instances")


def warn_about_ok_instances(summary: pd.DataFrame, solver: SolverConfig):
    """RuntimeWarnings about "ok" instances of a summary (its rows in order: the first named
    by its row, or by its `instance` column where it has one, a batch's) that need a second
    look, each naming how many and the first:

    - a Newton solve that used all max_newton iterations (newton_capped): the step was then
      redone (a retry) and accepted, and such a run can be off by far more than newton_tol.
      In f32 the precision barely resolves newton_tol; in f64 an audit found two causes
      (docs/numerics.md, "What ok promises"): steps that converge to another solution of
      their equations (at a re-firing whose natural curvature jumps, period 0.2 s: a
      centroid 13 mm away in one 2-ms step) and a robot whose shortest edge is thousands of
      times below its size (8-90 % off);
    - a final shape that is not physical (shape_sane False).

    Of kind "ok_instances" (`batch.run_batch` keeps its chunks' to itself and warns once with
    the batch's numbers: `checks.told_by_caller`)."""
    ok = summary["status"].eq("ok").to_numpy()
    names = (summary["instance"].to_numpy() if "instance" in summary
             else np.arange(len(summary)))
    warn_about_capped(ok & summary["newton_capped"].to_numpy(dtype=bool), names, solver)
    unphysical = ok & ~summary["shape_sane"].to_numpy(dtype=bool)
    if unphysical.any():
        warn_user(f"{int(unphysical.sum())} of {len(summary)} 'ok' instances (the first: "
                  f"instance {names[np.flatnonzero(unphysical)[0]]}) end in a shape that is not "
                  f"physical (shape_sane False, max_strain up to "
                  f"{summary['max_strain'].to_numpy()[unphysical].max():.3g}): every step was "
                  f"solved, but their parameters or time step take the rods beyond what the "
                  f"model describes", kind="ok_instances")


def _collect(engine, model, solver, duration, record_times, start, centroids, rotations, shapes,
             boundaries, steady_from_cycle):
    batch = model.batch_size
    state = engine.state
    final = engine.centroids_of(batch)
    counts = state.read(SUMMARY_STATE, batch)
    status = counts["status"]
    failure_time = failure_times(status, counts["failure_time"], counts["failure_step"], solver)
    newton_solves = counts["newton_solves"]
    params = model.params
    gaits = [p.gait for p in params]
    failed = status != STATUS_OK

    columns = StarParams.columns()
    # one attrgetter call per instance, not a getattr per field and instance
    by_field = zip(*map(operator.attrgetter(*columns), params))
    rows = {column: list(values) for column, values in zip(columns.values(), by_field)}
    # as text, so that every column has an Arrow type (Parquet, netCDF) and from_row reads it
    rows["actuator_profile"] = _texts([p.actuator_profile for p in params],
                                      lambda profile: profile.to_text())
    for name in PER_ACTUATOR_FIELDS:  # "(1.0, 0.5, ...)": every float's repr reads back exactly
        rows[parameter_column(name)] = _texts([getattr(p, name) for p in params], str)
    rows.update(metrics.swimming_metrics(final - start, duration, gaits))
    positions = counts["positions"].astype(np.float64)
    rows["heading_deg"] = np.degrees(metrics.body_rotation(
        positions, model.rest_positions, model.topology.joints, CENTRE))
    sanity = metrics.shape_checks(positions[None], model.topology, model.rest_positions)
    rows["max_strain"] = sanity["max_strain_final"].to_numpy()
    rows["shape_sane"] = sanity["sane"].to_numpy()
    boundaries[failed] = np.nan
    rows.update(metrics.cycle_window_speeds(boundaries, np.array([p.period for p in params]),
                                            gaits, steady_from_cycle))
    rows["steps"] = counts["steps_done"]
    rows["rejected_steps"] = counts["rejected_steps"]
    rows["steps_over_tolerance"] = counts["steps_over_tolerance"]
    rows["newton_iterations_mean"] = counts["newton_total"] / np.maximum(newton_solves, 1)
    rows["newton_iterations_max"] = counts["newton_max"]
    rows["factorisations_mean"] = counts["factorisations"] / np.maximum(newton_solves, 1)
    rows["substep_retries"] = counts["substep_retries"]
    rows["newton_capped"] = newton_capped(rows["newton_iterations_max"], solver)
    rows["status"] = [STATUS_NAMES[s] for s in status]
    rows["failure_time_s"] = failure_time
    summary = pd.DataFrame(rows)
    metric_columns = [*metrics.SPEED_COLUMNS, "heading_deg", "max_strain", "steady_speed_mm_s",
                      "steady_signed_speed_mm_s"]
    summary.loc[failed, metric_columns] = np.nan
    # the frozen last good shape is not the run's: a failed robot passed `shape_sane` filters
    # with max_strain 0 (an audit, 2026-12)
    summary.loc[failed, "shape_sane"] = False

    trajectory = pd.DataFrame({"instance": pd.Series(dtype=int), "t_s": pd.Series(dtype=float),
                               "x_mm": pd.Series(dtype=float), "y_mm": pd.Series(dtype=float),
                               "heading_deg": pd.Series(dtype=float)})
    shape_array = None
    if len(record_times):
        n_records = len(centroids)
        # a frozen instance keeps its last good state: its records from the failure on are NaN,
        # compared in the state's precision (an adaptive f32 run's failure at a record's stop
        # is that stop rounded to f32, 0.05000000074505806 for 0.05: a review, 2026-12)
        real = counts["failure_time"].dtype.type
        after_failure = failed[:, None] & (record_times[None, :].astype(real)
                                           >= failure_time.astype(real)[:, None])
        relative = (np.stack(centroids, axis=1) - start[:, None, :]) * metrics.METERS_TO_MM
        relative[after_failure] = np.nan
        heading = np.degrees(np.stack(rotations, axis=1))
        heading[after_failure] = np.nan
        trajectory = pd.DataFrame({
            "instance": np.repeat(np.arange(batch), n_records),
            "t_s": np.tile(record_times, batch),
            "x_mm": relative[:, :, 0].ravel(),
            "y_mm": relative[:, :, 1].ravel(),
            "heading_deg": heading.ravel(),
        })
        if shapes:
            shape_array = np.stack(shapes)
            # the first instances' (a sensitive batch keeps no shapes of its replicas)
            shape_array[after_failure.T[:, :shape_array.shape[1]]] = np.nan
    return SimulationResult(summary=summary, trajectory=trajectory, shapes=shape_array,
                            topology=model.topology, solver=solver)
