"""The public entry point: `simulate` a batch of StarParams and get pandas tables back."""

from __future__ import annotations

import math
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
import pandas as pd
import taichi as ti

from .engine import STATUS_NAMES, STATUS_OK, BatchEngine, terms_used
from .geometry import Topology
from .metrics import METERS_TO_MM, swimming_metrics
from .model import build_model
from .params import SolverConfig, StarParams

ARCHS = {"cpu": "cpu", "gpu": "gpu", "cuda": "cuda", "vulkan": "vulkan", "metal": "metal"}
STEPS_PER_LAUNCH = 50
"""Steps fused into one kernel launch: enough to hide launch cost, few enough for a live
progress bar."""

_runtime = {"arch": None, "precision": None, "cpu_threads": None, "log_level": ti.WARN}
_engines = {}
"""Engines of this Taichi runtime by (n_arc, n_limb, capacity): each compiles once per process."""


def available_archs():
    """The arch names `simulate` accepts on this machine."""
    names = ["cpu"]
    for name in ("cuda", "vulkan", "metal"):
        if ti.lang.misc.is_arch_supported(getattr(ti, name)):
            names.append(name)
    if len(names) > 1:
        names.insert(1, "gpu")
    return names


def ensure_taichi(arch: str = "cpu", precision: str = "f64"):
    """Initialise Taichi once per process, again only when arch or precision change.
    Raises ValueError for an arch this machine does not have."""
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {sorted(ARCHS)}, got {arch!r}")
    if _runtime["arch"] == arch and _runtime["precision"] == precision:
        return
    available = ["cpu"] if arch == "cpu" else available_archs()
    if arch not in available:
        raise ValueError(f"arch {arch!r} is not available on this machine; available: {available}")
    threads = {} if _runtime["cpu_threads"] is None else {"cpu_max_num_threads": _runtime["cpu_threads"]}
    ti.init(arch=getattr(ti, ARCHS[arch]), default_fp=ti.f64 if precision == "f64" else ti.f32,
            fast_math=False, offline_cache=True, log_level=_runtime["log_level"], **threads)
    _runtime.update(arch=arch, precision=precision)
    _engines.clear()


MIN_CAPACITY = 8


def batch_capacity(batch_size: int) -> int:
    """Engine capacity for a batch: the next power of two, at least MIN_CAPACITY, so that
    batches of similar size share one compiled engine (padding instances are inactive and cost
    nothing)."""
    return max(MIN_CAPACITY, 1 << max(batch_size - 1, 0).bit_length())


def get_engine(model) -> BatchEngine:
    """The cached engine for this batch's topology and capacity (created on first use)."""
    key = (*model.params[0].topology_key, batch_capacity(model.batch_size))
    if key not in _engines:
        _engines[key] = BatchEngine(model.topology, key[-1],
                                    instances_per_block=1 if _runtime["arch"] == "cpu" else 64)
    return _engines[key]


@dataclass
class SimulationResult:
    summary: pd.DataFrame
    """One row per instance, in input order: every StarParams field, the swimming metrics of
    `metrics.swimming_metrics`, newton_iterations_mean/max, substep_retries (failed steps
    redone with substeps), status and failure_time_s."""
    trajectory: pd.DataFrame
    """Long table (instance, t_s, x_mm, y_mm): the centroid relative to its start, every
    record_every steps from t = 0 (NaN after a failure); empty when record_every = 0."""
    shapes: Optional[np.ndarray]
    """(n_records, B, N, 2) node positions in m at the trajectory's times, when requested."""
    topology: Topology
    solver: SolverConfig


def _validate_call(params, duration_s, solver, record_every, record_shapes, workers=1):
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1 (processes), got {workers!r}")
    if isinstance(params, StarParams):
        raise ValueError("params must be a sequence of StarParams (wrap a single one in a list)")
    if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) \
            or not math.isfinite(duration_s) or duration_s <= 0:
        raise ValueError(f"duration_s must be a finite number > 0 s, got {duration_s!r}")
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    if isinstance(record_every, bool) or not isinstance(record_every, int) or record_every < 0:
        raise ValueError(f"record_every must be an integer >= 0 (steps; 0 = off), got {record_every!r}")
    if record_shapes and record_every == 0:
        raise ValueError("record_shapes needs record_every > 0 (the stride of the shape records)")
    n_steps = int(round(duration_s / solver.dt))
    if n_steps < 1:
        raise ValueError(f"duration_s must be at least one step (dt = {solver.dt} s), got {duration_s!r}")
    return n_steps


def simulate(params: Sequence[StarParams], duration_s: float, solver: SolverConfig = SolverConfig(),
             arch: str = "cpu", record_every: int = 0, progress: bool = False,
             record_shapes: bool = False, workers: int = 1) -> SimulationResult:
    """Simulate a batch of robot instances from rest for duration_s seconds (rounded to whole
    steps of solver.dt). Every instance may have its own parameters except the topology
    (n_arc, n_limb). An instance whose Newton solve fails is frozen and reported in `summary`
    (status, failure_time_s); the others are unaffected.

    workers > 1 splits the batch over that many worker processes, each a single-threaded
    Taichi CPU runtime (on the 2-core machines measured here, Taichi's own threads gained 1.25×
    and two processes 2×); results are bitwise those of one process."""
    n_steps = _validate_call(params, duration_s, solver, record_every, record_shapes, workers)
    model = build_model(params)
    if workers > 1 and model.batch_size > 1:
        return _simulate_in_processes(model, duration_s, solver, arch, record_every, progress,
                                      record_shapes, workers)
    ensure_taichi(arch, solver.precision)
    engine = get_engine(model)
    engine.load(model, solver)
    terms = terms_used(model)
    centroids, shapes = [], []
    engine.compute_centroids()
    start = engine.centroids.to_numpy()[:model.batch_size].astype(np.float64)

    def record():
        engine.compute_centroids()
        centroids.append(engine.centroids.to_numpy()[:model.batch_size])
        if record_shapes:
            shapes.append(engine.positions.to_numpy()[:model.batch_size])

    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=n_steps, unit="step", desc=f"{model.batch_size} robots")
    if record_every:
        record()
    step = 0
    while step < n_steps:
        # a launch never runs past a record point, so records are taken between launches
        count = min(STEPS_PER_LAUNCH, n_steps - step)
        if record_every:
            count = min(count, record_every - step % record_every)
        engine.advance(step, count, solver.integrator == "bdf2", terms)
        step += count
        if record_every and step % record_every == 0:
            record()
        if bar is not None:
            bar.update(count)
    if bar is not None:
        bar.close()
    return _collect(engine, model, solver, n_steps, record_every, start, centroids, shapes)


def _collect(engine, model, solver, n_steps, record_every, start, centroids, shapes):
    batch = model.batch_size
    engine.compute_centroids()
    final = engine.centroids.to_numpy()[:batch].astype(np.float64)
    status = engine.status.to_numpy()[:batch]
    failure_step = engine.failure_step.to_numpy()[:batch]
    steps_done = engine.steps_done.to_numpy()[:batch]
    newton_total = engine.newton_total.to_numpy()[:batch]
    attempted = steps_done + (status != STATUS_OK)
    duration = n_steps * solver.dt
    rows = {name: [getattr(p, name) for p in model.params] for name in StarParams.field_names()}
    rows.update(swimming_metrics(final - start, duration, [p.gait for p in model.params]))
    rows["newton_iterations_mean"] = newton_total / np.maximum(attempted, 1)
    rows["newton_iterations_max"] = engine.newton_max.to_numpy()[:batch]
    rows["substep_retries"] = engine.substep_retries.to_numpy()[:batch]
    rows["status"] = [STATUS_NAMES[s] for s in status]
    failed = status != STATUS_OK
    rows["failure_time_s"] = np.where(failed, failure_step * solver.dt, np.nan)
    summary = pd.DataFrame(rows)
    for column in ("displacement_x_mm", "displacement_y_mm", "speed_mm_s", "signed_speed_mm_s",
                   "heading_deg"):
        summary.loc[failed, column] = np.nan

    trajectory = pd.DataFrame({"instance": pd.Series(dtype=int), "t_s": pd.Series(dtype=float),
                               "x_mm": pd.Series(dtype=float), "y_mm": pd.Series(dtype=float)})
    shape_array = None
    if record_every:
        n_records = len(centroids)
        times = np.arange(n_records) * record_every * solver.dt
        record_steps = np.arange(n_records) * record_every
        # a frozen instance keeps its last good state: its records from the failure on are NaN
        after_failure = failed[:, None] & (record_steps[None, :] >= failure_step[:, None])
        relative = (np.stack(centroids, axis=1).astype(np.float64) - start[:, None, :]) * METERS_TO_MM
        relative[after_failure] = np.nan
        trajectory = pd.DataFrame({
            "instance": np.repeat(np.arange(batch), n_records),
            "t_s": np.tile(times, batch),
            "x_mm": relative[:, :, 0].ravel(),
            "y_mm": relative[:, :, 1].ravel(),
        })
        if shapes:
            shape_array = np.stack(shapes).astype(np.float64)
            shape_array[after_failure.T] = np.nan
    return SimulationResult(summary=summary, trajectory=trajectory, shapes=shape_array,
                            topology=model.topology, solver=solver)


_pools = {}
"""Worker pools by (workers, arch): started once per process, their engines stay compiled."""


def _start_worker():
    # one thread per worker process; workers share the offline cache, whose lock contention
    # Taichi reports as warnings that mean nothing here
    _runtime.update(cpu_threads=1, log_level=ti.ERROR)


def _simulate_chunk(params, duration_s, solver, arch, record_every, record_shapes):
    return simulate(params, duration_s, solver, arch, record_every, False, record_shapes)


def _simulate_in_processes(model, duration_s, solver, arch, record_every, progress,
                           record_shapes, workers):
    """`simulate` with the batch cut into contiguous chunks run by a pool of processes; the
    chunks' tables are joined back in input order."""
    if arch != "cpu":
        raise ValueError(f"workers > 1 runs CPU processes; arch must be 'cpu', got {arch!r}")
    key = (workers, arch)
    if key not in _pools:
        _pools[key] = ProcessPoolExecutor(max_workers=workers, initializer=_start_worker,
                                          mp_context=multiprocessing.get_context("spawn"))
    params = list(model.params)
    # a few chunks per worker for a live progress bar; equal sizes share one compiled engine
    n_chunks = min(len(params), 4 * workers)
    bounds = np.linspace(0, len(params), n_chunks + 1).round().astype(int)
    futures = [_pools[key].submit(_simulate_chunk, params[start:stop], duration_s, solver, arch,
                                  record_every, record_shapes)
               for start, stop in zip(bounds[:-1], bounds[1:])]
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=len(params), unit="robot", desc=f"{len(params)} robots, {workers} workers")
    results = []
    for future, start, stop in zip(futures, bounds[:-1], bounds[1:]):
        results.append(future.result())
        if bar is not None:
            bar.update(stop - start)
    if bar is not None:
        bar.close()
    trajectories = []
    for result, start in zip(results, bounds[:-1]):
        trajectory = result.trajectory.copy()
        trajectory["instance"] += start
        trajectories.append(trajectory)
    return SimulationResult(
        summary=pd.concat([r.summary for r in results], ignore_index=True),
        trajectory=pd.concat(trajectories, ignore_index=True),
        shapes=np.concatenate([r.shapes for r in results], axis=1) if record_shapes else None,
        topology=model.topology, solver=solver)
