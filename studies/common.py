"""Shared pieces of the studies: value lists and ranges, parameter products, running a batch in
chunks, per-cycle metrics, CSV writing.

Everything here is public and usable from a notebook, e.g. a sensitivity sweep in five lines::

    from studies.common import param_product, parse_values, run_batch
    grid = param_product({"alpha": parse_values("0.2:1.2:6"), "gait": ["A1", "A1+A2"]})
    result = run_batch(grid, cycles=3)
    result.summary[["gait", "alpha", "speed_mm_s", "steady_speed_mm_s", "status"]]
"""

from __future__ import annotations

import argparse
import itertools
import math
import typing
from pathlib import Path
from types import SimpleNamespace
from typing import Dict, Iterable, List, Mapping, Sequence

import numpy as np
import pandas as pd

import taichi_star
from taichi_star.gait import Gait
from taichi_star.params import CONVERGED_DISCRETISATION, SolverConfig, StarParams

DEFAULT_OUT = "results"

DISCRETISATIONS = {"paper": {}, "converged": dict(CONVERGED_DISCRETISATION)}
"""`--discretisation`: "paper" = the paper's N = 193 (n_arc 18, n_limb 6, clamped ends);
"converged" = `StarParams.converged()` (n_arc 320, N = 2609 nodes, ≈ 0.8 % in speed)."""

DISCRETISATION_HELP = ("paper: the paper's N = 193 nodes (n_arc 18, ~16 %% low in speed); "
                       "converged: StarParams.converged(), n_arc 320, N = 2609, ~0.8 %%")

QUICK_DURATION_S = 0.2
QUICK_DT = 2e-3


class StudyArgumentError(ValueError):
    """A study argument is invalid; raised before any computation, naming the flag."""


# --------------------------------------------------------------------------- values and ranges

def _number(text: str, flag: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise StudyArgumentError(f"{flag}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise StudyArgumentError(f"{flag}: {text!r} is not a finite number")
    return value


def parse_range(text: str, flag: str = "value") -> List[float]:
    """"start:stop:n" -> n evenly spaced values from start to stop inclusive;
    "start:stop:n:log" -> n geometrically spaced values (start, stop > 0)."""
    parts = [p.strip() for p in text.split(":")]
    if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].lower() != "log"):
        raise StudyArgumentError(
            f"{flag}: malformed range {text!r}; expected start:stop:n or start:stop:n:log "
            f"(e.g. 0.2:1.2:11)")
    start, stop = _number(parts[0], flag), _number(parts[1], flag)
    try:
        count = int(parts[2])
    except ValueError:
        raise StudyArgumentError(f"{flag}: malformed range {text!r}: the number of points "
                                 f"{parts[2]!r} is not an integer") from None
    if count < 1:
        raise StudyArgumentError(f"{flag}: range {text!r} has {count} points; need at least 1")
    if count == 1 and start != stop:
        raise StudyArgumentError(f"{flag}: range {text!r} has one point but start != stop")
    if len(parts) == 4:
        if start <= 0 or stop <= 0:
            raise StudyArgumentError(f"{flag}: log range {text!r} needs start, stop > 0")
        values = np.geomspace(start, stop, count)
    else:
        values = np.linspace(start, stop, count)
    return [float(v) for v in values]


def parse_values(text: str, flag: str = "value", kind: type = float) -> list:
    """A comma-separated list ("0,0.5,1", "contract,always") or, for numbers, a range
    ("0.2:1.2:11", "1e6:1e7:5:log"). Raises StudyArgumentError naming `flag` when malformed or
    empty."""
    if text is None or not str(text).strip():
        raise StudyArgumentError(f"{flag}: empty value list (the product would be empty)")
    text = str(text).strip()
    if kind is float and ":" in text:
        return parse_range(text, flag)
    items = [item.strip() for item in text.split(",")]
    if any(not item for item in items):
        raise StudyArgumentError(f"{flag}: malformed list {text!r} (an empty item)")
    if kind is float:
        return [_number(item, flag) for item in items]
    if kind is int:
        out = []
        for item in items:
            try:
                out.append(int(item))
            except ValueError:
                raise StudyArgumentError(f"{flag}: {item!r} is not an integer") from None
        return out
    return items


def field_kind(name: str) -> type:
    """float, int or str: the type of a StarParams field."""
    hints = typing.get_type_hints(StarParams)
    if name not in hints:
        raise StudyArgumentError(
            f"unknown parameter {name!r}; StarParams fields: {', '.join(StarParams.field_names())}")
    return hints[name]


def parse_assignment(text: str, flag: str):
    """"name=values" (e.g. "alpha=0.2:1.2:6") -> (field name, list of values)."""
    if "=" not in text:
        raise StudyArgumentError(f"{flag}: expected NAME=VALUES (e.g. alpha=0.2:1.2:6), got "
                                 f"{text!r}")
    name, values = text.split("=", 1)
    name = name.strip().replace("-", "_")
    kind = field_kind(name)
    return name, parse_values(values, f"{flag} {name}", kind)


def parse_overrides(items, flag="--set"):
    """["alpha=1.0", "jet_mode=always"] -> {"alpha": 1.0, "jet_mode": "always"} (one value each)."""
    overrides = {}
    for item in items:
        name, values = parse_assignment(item, flag)
        if len(values) != 1:
            raise StudyArgumentError(f"{flag} {name}: give exactly one value, got {values}")
        overrides[name] = values[0]
    return overrides


def resolve_gaits(text: str, flag: str = "--gaits") -> List[str]:
    """"paper" -> the five Fig. 4 gaits; "all" -> all 255 non-empty gaits; otherwise a comma
    list of gait strings (validated)."""
    from taichi_star.experiment import PAPER_GAITS
    if text is None or not text.strip():
        raise StudyArgumentError(f"{flag}: empty gait list (the product would be empty)")
    key = text.strip().lower()
    if key == "paper":
        return list(PAPER_GAITS)
    if key == "all":
        return [Gait.from_mask([bits >> m & 1 for m in range(8)]).name for bits in range(1, 256)]
    gaits = []
    for item in text.split(","):
        try:
            gaits.append(Gait.parse(item.strip()).name)
        except ValueError as error:
            raise StudyArgumentError(f"{flag}: {error}") from None
    return gaits


# --------------------------------------------------------------------------- parameter products

def param_product(axes: Mapping[str, Sequence], base: StarParams = StarParams()) -> List[StarParams]:
    """Every combination of the given StarParams field values (the last axis varies fastest),
    on top of `base`. Validates every field name and value before returning; raises
    StudyArgumentError naming the parameter for an unknown field, an invalid value or an empty
    axis."""
    names = list(axes)
    for name in names:
        field_kind(name)
        if len(axes[name]) == 0:
            raise StudyArgumentError(f"empty product: parameter {name!r} has no values")
    combos = []
    for values in itertools.product(*(axes[name] for name in names)):
        try:
            combos.append(base.replace(**dict(zip(names, values))))
        except (ValueError, TypeError) as error:
            raise StudyArgumentError(f"invalid parameter value: {error}") from None
    if not combos:
        raise StudyArgumentError("empty product: no parameter combinations")
    return combos


def solver_for(args) -> SolverConfig:
    """SolverConfig from the common flags (--dt; --quick coarsens the default step)."""
    dt = args.dt if args.dt is not None else (QUICK_DT if args.quick else 1e-3)
    try:
        return SolverConfig(dt=dt)
    except ValueError as error:
        raise StudyArgumentError(f"--dt: {error}") from None


def base_params(args) -> StarParams:
    """StarParams defaults with the chosen --discretisation."""
    return StarParams().replace(**DISCRETISATIONS[args.discretisation])


# --------------------------------------------------------------------------- running

def steps_per_cycle(period: float, dt: float):
    """Integer steps in one actuation cycle, or None when period/dt is not an integer."""
    ratio = period / dt
    steps = int(round(ratio))
    return steps if steps >= 1 and abs(ratio - steps) <= 1e-9 * max(1.0, ratio) else None


def plan_chunks(params: Sequence[StarParams], cycles: float = 3.0, duration_s: float = None,
                chunk_size: int = 4096) -> List[tuple]:
    """The chunks of a batch: [(duration, [input indices])], deterministic. Instances are grouped
    by what one `simulate` call must share (topology, and the duration = cycles × period when
    `duration_s` is None), groups in order of first appearance, each cut into runs of at most
    `chunk_size` instances in input order."""
    groups: Dict[tuple, List[int]] = {}
    for index, p in enumerate(params):
        duration = duration_s if duration_s is not None else cycles * p.period
        groups.setdefault((p.topology_key, round(duration, 12)), []).append(index)
    return [(key[1], members[i:i + chunk_size]) for key, members in groups.items()
            for i in range(0, len(members), chunk_size)]


def run_chunk(params: Sequence[StarParams], members: Sequence[int], duration: float,
              solver: SolverConfig = SolverConfig(), arch: str = "cpu", record_every: int = None,
              record_shapes: bool = False, progress: bool = False, steady_from_cycle: int = 1,
              fixed_duration: bool = False):
    """One `simulate` call for the instances `params` (input indices `members`): the summary
    (with `instance`, `duration_s`, `dt_s` and the steady speeds), the trajectory (instances
    renumbered to input indices), the shapes by input index and the topology. This is the unit
    of work of a chunked run, in process or on a Dask worker."""
    params = list(params)
    period = params[0].period
    per_cycle = steps_per_cycle(period, solver.dt)
    every = record_every
    if every is None:
        same_period = all(p.period == period for p in params)
        every = per_cycle if (per_cycle and same_period and not fixed_duration) else 0
    result = taichi_star.simulate(params, duration, solver=solver, arch=arch, record_every=every,
                                  progress=progress, record_shapes=record_shapes)
    summary = result.summary.copy()
    summary.insert(0, "instance", list(members))
    summary["duration_s"] = duration
    summary["dt_s"] = solver.dt
    traj = result.trajectory.copy()
    if len(traj):
        traj["instance"] = np.asarray(members)[traj["instance"].to_numpy(dtype=int)]
    _add_steady(summary, traj, params, duration, steady_from_cycle)
    shapes = {}
    if record_shapes and result.shapes is not None:
        shapes = {index: result.shapes[:, local] for local, index in enumerate(members)}
    return SimpleNamespace(summary=summary, trajectory=traj, shapes=shapes,
                           topology=result.topology)


class InProcess:
    """Runs chunks one after the other in this process (the default executor)."""
    n_workers = 1

    def map(self, function, tasks):
        """Yield (task index, result) for every task (a tuple of positional arguments)."""
        for index, task in enumerate(tasks):
            yield index, function(*task)


def run_batch(params: Sequence[StarParams], cycles: float = 3.0, duration_s: float = None,
              solver: SolverConfig = SolverConfig(), arch: str = "cpu", chunk_size: int = 4096,
              record_every: int = None, record_shapes: bool = False, progress: bool = False,
              steady_from_cycle: int = 1, executor=None, run_dir=None, resume: bool = False,
              description: Mapping = None):
    """Simulate `params` and return (summary, trajectory, shapes, topologies) as a namespace.

    Instances are grouped by what must be shared by one `simulate` call (topology, and the
    duration = cycles × period when `duration_s` is None) and each group is run in chunks of at
    most `chunk_size` (`plan_chunks`); the summary comes back in input order with an `instance`
    column (input index). When every cycle boundary is a recorded time (the default
    `record_every` = steps per cycle), the summary also gets `steady_speed_mm_s` /
    `steady_signed_speed_mm_s`: the speed over cycles [steady_from_cycle, cycles) (design §3),
    NaN where unavailable.

    `executor`: where the chunks run: None = in this process, one after the other; a
    `studies.distributed.DaskExecutor` = on Dask workers (each chunk one task, retried when its
    worker is lost). `run_dir`: a run folder (`studies.runs`): each finished chunk's summary is
    written there atomically as it arrives, with a manifest of the run's definition; `resume`
    skips the chunks already there (refusing a folder holding another definition), and the
    summary is assembled from the chunk files. With a run folder the trajectory and shapes
    cover only the chunks computed by this call. `description` (e.g. the sweep's axes) goes into
    the manifest for the reader.
    """
    params = list(params)
    if not params:
        raise StudyArgumentError("empty product: no instances to simulate")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise StudyArgumentError(f"--chunk-size must be an integer >= 1, got {chunk_size!r}")
    executor = executor if executor is not None else InProcess()
    chunks = plan_chunks(params, cycles, duration_s, chunk_size)
    folder, done = None, set()
    if run_dir is not None:
        from . import runs
        folder = runs.RunFolder(run_dir)
        manifest = runs.build_manifest(params, [m for _, m in chunks], chunk_size, cycles,
                                       duration_s, solver, record_every, steady_from_cycle,
                                       description=dict(description or {}), arch=arch)
        try:
            done = set(folder.open(manifest, resume))
        except runs.RunFolderError as error:
            raise StudyArgumentError(str(error)) from None
        if done:
            print(f"resuming {folder.path}: {len(done)} of {len(chunks)} chunks already done")
    todo = [i for i in range(len(chunks)) if i not in done]
    in_process = isinstance(executor, InProcess)
    tasks = [([params[j] for j in chunks[i][1]], chunks[i][1], chunks[i][0], solver, arch,
              record_every, record_shapes, progress and in_process, steady_from_cycle,
              duration_s is not None) for i in todo]

    summaries, trajectories, shapes, topologies = {}, [], {}, {}
    outer = None
    if progress and len(chunks) > 1:
        from tqdm.auto import tqdm
        outer = tqdm(total=len(chunks), initial=len(done), desc="batches", unit="batch")
    for position, result in executor.map(run_chunk, tasks):
        index = todo[position]
        if folder is not None:
            folder.write(index, result.summary)
        summaries[index] = result.summary
        trajectories.append(result.trajectory)
        shapes.update(result.shapes)
        for member in chunks[index][1]:
            topologies[member] = result.topology
        if outer is not None:
            outer.update(1)
    if outer is not None:
        outer.close()
    if folder is not None:
        summaries = {i: folder.read(i, members) for i, (_, members) in enumerate(chunks)}
        folder.finish()
    summary = pd.concat([summaries[i] for i in range(len(chunks))])
    summary = summary.sort_values("instance", kind="stable").reset_index(drop=True)
    trajectories = [t for t in trajectories if len(t)]
    trajectory = (pd.concat(trajectories).sort_values(["instance", "t_s"]).reset_index(drop=True)
                  if trajectories else pd.DataFrame(columns=["instance", "t_s", "x_mm", "y_mm"]))
    return SimpleNamespace(summary=summary, trajectory=trajectory, shapes=shapes,
                           topologies=topologies)


def _add_steady(summary, trajectory, params, duration, first_cycle):
    steady, steady_signed = [], []
    for local, (instance, p) in enumerate(zip(summary["instance"], params)):
        value = signed = math.nan
        cycles = duration / p.period
        last = int(round(cycles))
        if (len(trajectory) and abs(cycles - last) < 1e-9 and last > first_cycle
                and summary["status"].iloc[local] == "ok"):
            rows = trajectory[trajectory["instance"] == instance]
            times = rows["t_s"].to_numpy()
            start = np.flatnonzero(np.isclose(times, first_cycle * p.period, atol=1e-9, rtol=0))
            end = np.flatnonzero(np.isclose(times, last * p.period, atol=1e-9, rtol=0))
            if len(start) and len(end):
                xy = rows[["x_mm", "y_mm"]].to_numpy()
                delta = xy[end[0]] - xy[start[0]]
                span = (last - first_cycle) * p.period
                value = float(np.hypot(*delta)) / span
                forward = Gait.parse(p.gait).forward
                signed = float(delta @ forward) / span if forward is not None else math.nan
        steady.append(value)
        steady_signed.append(signed)
    summary["steady_speed_mm_s"] = steady
    summary["steady_signed_speed_mm_s"] = steady_signed
    summary["steady_from_cycle"] = first_cycle


# --------------------------------------------------------------------------- CLI and output

def common_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """Parser with the flags every study takes."""
    parser = argparse.ArgumentParser(prog=f"python -m studies {prog}", description=description)
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu",
                        help="Taichi backend (default cpu)")
    parser.add_argument("--out", default=DEFAULT_OUT, help="output folder (default results/)")
    parser.add_argument("--quick", action="store_true",
                        help=f"small fast run for tests: {QUICK_DURATION_S} s simulated, "
                             f"dt {QUICK_DT} s unless --dt is given")
    parser.add_argument("--discretisation", choices=tuple(DISCRETISATIONS), default="paper",
                        help=DISCRETISATION_HELP)
    parser.add_argument("--dt", type=float, default=None, help="time step, s (default 1e-3)")
    parser.add_argument("--chunk-size", type=int, default=None,
                        help="instances per simulate call (default 2048 cpu, 16384 gpu)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    return parser


def check_positive(value: float, flag: str):
    """StudyArgumentError naming the flag unless value is a finite number > 0."""
    if not (math.isfinite(value) and value > 0):
        raise StudyArgumentError(f"{flag} must be > 0, got {value}")


def chunk_size_for(args) -> int:
    size = args.chunk_size if args.chunk_size is not None else (16384 if args.arch == "gpu"
                                                                 else 2048)
    if size < 1:
        raise StudyArgumentError(f"--chunk-size must be >= 1, got {size}")
    return size


def out_dir(args) -> Path:
    path = Path(args.out)
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_csv(frame: pd.DataFrame, path) -> Path:
    """Write a table (no index, full float precision) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(path, index=False, float_format="%.10g")
    return path


def use_agg():
    """Select the non-interactive Agg backend and return pyplot."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def params_columns() -> List[str]:
    return StarParams.field_names()


def describe(paths: Iterable) -> str:
    return "\n".join(f"  wrote {p}" for p in paths)


def fresh_output(args, study: str) -> Path:
    """The output folder of a study whose --out defaults to None: --out, or a fresh
    runs/<study>/<timestamp>/. --quick may not write into results/ (the committed results)."""
    import datetime
    if args.out is None:
        stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S-%f")
        return out_dir(SimpleNamespace(out=Path("runs") / study / stamp))
    if args.quick and Path(args.out).resolve().parts[-1:] == (DEFAULT_OUT,):
        raise StudyArgumentError(f"--out {args.out}: a --quick run does not write into "
                                 f"{DEFAULT_OUT}/")
    return out_dir(args)


def write_table(frame: pd.DataFrame, path, study: str, argv: Sequence[str],
                details: Mapping = None) -> Path:
    """`write_csv` plus a JSON sidecar `<path>.json`: the study, its command line, the package
    version, the date and `details`."""
    import datetime
    import json
    path = write_csv(frame, path)
    sidecar = {"study": study, "command": ["python", "-m", "studies", study, *argv],
               "taichi_star_version": taichi_star.__version__,
               "date": datetime.datetime.now().isoformat(timespec="seconds"),
               "details": dict(details or {})}
    Path(f"{path}.json").write_text(json.dumps(sidecar, indent=2, default=str) + "\n")
    return path
