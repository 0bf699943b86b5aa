"""`run_batch`: a batch of any size, cut into chunks, run by an executor, optionally stored."""

from __future__ import annotations

import contextlib
import logging
import os
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from ..checks import check_flag, warn_user
from ..driver import RunTiming, shows_progress
from ..extras import require
from ..geometry import build_topology
from ..model import instances_of
from ..params import SolverConfig, StarParams
from ..provenance import code_version
from .. import sensitivities as tangents
from ..simulation import SimulationResult, call_arguments, warn_about_ok_instances
from .executors import DEFAULT_RETRIES, Executor, InProcess, LocalProcesses, check_retries
from .store import (RunStore, RunStoreError, StoredRun, current_defaults, read_stored,
                    run_definition)
from .tasks import batch_nodes, batch_robot_steps, plan_chunks

DEFAULT_CHUNK_SIZE = 2048
"""Instances per chunk on the CPU: one compiled engine's worth, large enough to keep a process
busy, small enough that a lost chunk costs little."""

TRAJECTORY_COLUMNS = ["instance", "t_s", "x_mm", "y_mm", "heading_deg"]

log = logging.getLogger("taichi_star.batch")


def run_batch(params: Sequence[StarParams], duration_s: Optional[float] = None, *,
              cycles: Optional[float] = None, solver: SolverConfig = SolverConfig(),
              arch: str = "cpu", chunk_size: int = DEFAULT_CHUNK_SIZE,
              record_interval_s: float = 0.0, record_shapes: bool = False,
              steady_from_cycle: int = 1, workers: Optional[int] = None,
              executor: Optional[Executor] = None, run_dir=None, resume: bool = False,
              progress: Optional[bool] = None, run_dir_flag: str = "run_dir",
              sensitivities: Sequence[str] = ()) -> SimulationResult:
    """Simulate any number of instances, each from rest, for `duration_s` seconds or for
    `cycles` of its own actuation period, and return one `SimulationResult`.

    Unlike `simulate`, the instances may differ in topology (n_arc, n_limb) and period: they are
    grouped and cut into chunks of at most `chunk_size` (`plan_chunks`), each one `simulate`
    call. The summary has simulate's columns plus `instance` (position in `params`) first and
    `duration_s` (the time simulated, over which the speeds are taken: with fixed steps the
    duration rounded to whole steps), in input order; the trajectory's instances are positions
    in `params`; shapes (n_records, B, N, 2), m, need one topology and one duration for the
    whole batch. `topology` is the batch's when it has one, else None. Results are bitwise those of `simulate` on the
    same instances, whatever the chunking and the executor (on one arch).

    Where the chunks run: in this process (default), on `workers` local worker processes
    (`LocalProcesses`, started and stopped by this call), or on an `executor` you keep across
    calls (`LocalProcesses`, `executor_for`, a `DaskExecutor`).

    `progress`: a bar of chunks (and, in this process, of each chunk's simulated seconds);
    None, the default: where the chunks to compute are estimated at `driver.AUTO_PROGRESS_S`
    or more.

    `run_dir`: a run store (`RunStore`): every finished chunk's summary is written there as it
    arrives; with `resume` (which needs `run_dir`), verified chunks already there are not
    recomputed (damaged or foreign ones are reported and recomputed), and the summary and the
    trajectory are read back from the store (a chunk stored before the store kept trajectories
    has none). The store's chunks are Parquet files: `run_dir` needs pyarrow (the `io` extra).
    `run_dir_flag`: how the store's messages name `run_dir` (a command line's "--run-dir").

    `sensitivities`: as `simulate`'s, computed in every chunk: the result's `sensitivities`
    (one row per instance, in the summary's order) and `trajectory_sensitivities` (instance
    and t_s as in the trajectory) are bitwise `simulate`'s for the same instances, and
    `sensitivity(output, parameter)` reads them; a run store keeps them with each chunk (and
    a resume must ask for the same ones).

    `timing` sums the `RunTiming` of the chunks computed by this call (not those a resume
    read back; chunks on worker processes overlap, so its phases add up to more than the
    call's wall time).

    Raises ValueError (RunStoreError for the run folder) naming the argument, or ImportError
    naming the extra for a `run_dir` without pyarrow, before any compute."""
    if workers is not None and executor is not None:
        raise ValueError("give workers (local processes for this call) or executor, not both")
    # a class has a callable run too: it failed at the first chunk with a TypeError and left
    # its run folder locked (an audit, 2026-12)
    if executor is not None and (isinstance(executor, type)
                                 or not callable(getattr(executor, "run", None))):
        raise ValueError(f"executor must be an Executor (InProcess, LocalProcesses, a "
                         f"DaskExecutor: see executor_for(scheduler=...)), got {executor!r}")
    # flags and the run folder's path before the folder is touched: resume="no" would resume
    check_flag("resume", resume)
    if progress is not None:  # None: decided by the work, once the chunks to run are known
        check_flag("progress", progress)
    if run_dir is not None:
        check_run_dir(run_dir)
    if resume and run_dir is None:
        raise ValueError("resume=True needs run_dir (the run store to continue)")
    # the worker processes (started at their first chunk) before the run store is opened: a
    # bad count must not leave a run folder behind that a later call would take as unfinished
    owned = LocalProcesses(workers) if workers is not None else None
    params = instances_of(params)
    tasks = plan_chunks(params, duration_s, cycles=cycles, chunk_size=chunk_size, solver=solver,
                        arch=arch, record_interval_s=record_interval_s,
                        record_shapes=record_shapes, steady_from_cycle=steady_from_cycle,
                        sensitivities=sensitivities)
    topology_keys = {p.topology_key for p in params}
    if record_shapes and (len(topology_keys) > 1 or len({t.duration_s for t in tasks}) > 1):
        raise ValueError("record_shapes needs one topology (n_arc, n_limb) and one duration for "
                         "the whole batch")
    if record_shapes and run_dir is not None:
        raise ValueError("record_shapes cannot be combined with run_dir (shapes are not stored)")
    store, done = None, []
    if run_dir is not None:
        store = RunStore(run_dir, run_definition(params, tasks, chunk_size, cycles, duration_s),
                         flag=run_dir_flag)
        done = store.open(tasks, resume)
    executor = owned if owned is not None else executor if executor is not None else InProcess()
    summaries, trajectories, shapes = {}, [], {}
    timing = RunTiming(setup_s=0.0, compile_s=0.0, run_s=0.0, collect_s=0.0, robot_steps=0)
    outer = results = None
    try:
        # from the folder's opening on: an interrupt anywhere (the progress bar's set-up kept
        # the folder locked: an audit, 2026-12), or an executor failing as it starts, lets go
        # of the folder
        if done:
            log.warning("resuming %s: %d of %d chunks already done", store.path, len(done),
                        len(tasks))
        todo = [task for task in tasks if task.index not in set(done)]
        if isinstance(executor, LocalProcesses) and 0 < len(todo) < executor.n_workers:
            # each chunk runs on one worker: the others were asked for and stay idle (they
            # did so without a word: an audit, 2026-12)
            warn_user(f"{executor.n_workers} worker processes for {len(todo)} chunk(s) to "
                      f"compute: {executor.n_workers - len(todo)} stay idle (chunk_size="
                      f"{chunk_size}; a smaller one gives each worker a share of the batch)")
        progress = shows_progress(progress, batch_robot_steps(todo), batch_nodes(todo))
        # a bar of chunks where the chunks' own bars are not shown (worker processes), even
        # for one chunk: nothing was shown there (an audit, 2026-12)
        if progress and (len(tasks) > 1 or not isinstance(executor, InProcess)):
            from tqdm.auto import tqdm
            outer = tqdm(total=len(tasks), initial=len(done), desc="chunks", unit="chunk")
        results = executor.run(todo, progress=progress and isinstance(executor, InProcess))
        for result in results:
            task = tasks[result.index]
            if store is not None:
                store.write(task, result.summary, result.trajectory)
            summaries[result.index] = result.summary
            trajectories.append(result.trajectory)
            if result.timing is not None:
                timing = timing + result.timing
            if result.shapes is not None:
                shapes[result.index] = result.shapes
            if outer is not None:
                outer.update(1)
    except BaseException:
        # the folder is free again for a resume (in this process too: a notebook's retry)
        if store is not None:
            store.release()
        raise
    finally:
        # closed first: after an error or an interrupt here (Ctrl-C, a notebook's "interrupt
        # kernel") the executor's generator stops its running chunks at once
        # (`LocalProcesses.terminate`; an executor's plain iterator has nothing to close);
        # shutdown then waits only at the end of a whole run, with nothing left running
        if hasattr(results, "close"):
            results.close()
        if outer is not None:
            outer.close()
        if owned is not None:
            owned.shutdown()
    if store is not None:
        try:
            # every chunk's summary and records from the store, those a resume did not
            # compute too
            stored = {task.index: store.read_chunk(task) for task in tasks}
            summaries = {index: summary for index, (summary, _) in stored.items()}
            trajectories = [trajectory for _, trajectory in stored.values()
                            if trajectory is not None]
            store.finish()
        finally:
            store.release()

    shape_array = None
    if record_shapes:
        stacked = np.concatenate([shapes[task.index] for task in tasks], axis=1)
        members = np.concatenate([task.members for task in tasks])
        shape_array = stacked[:, np.argsort(members, kind="stable")]
    # a store resumed under another code holds chunks of each, and one read back another's:
    # the result files say which
    makers = store.code_versions() if store is not None else []
    return gathered_result(
        [summaries[task.index] for task in tasks], trajectories, tasks[0].sensitivities,
        solver=solver, arch=arch, timing=timing, makers=makers, shapes=shape_array,
        topology=build_topology(params[0]) if len(topology_keys) == 1 else None,
        arguments=call_arguments("run_batch", duration_s, cycles, record_interval_s,
                                 record_shapes, steady_from_cycle, list(tasks[0].sensitivities),
                                 chunk_size))


def read_run(run_dir, *, partial: bool = False,
             run_dir_flag: str = "run_dir") -> SimulationResult:
    """The result of the run stored in the folder `run_dir` (a `run_batch(...,
    run_dir=...)`'s run store), read back without the run's arguments: on another machine, in
    a later session, or while the run is still going.

    Its summary, trajectory and sensitivities are those `run_batch(..., resume=True)` with the
    run's own arguments returns, bit for bit; `solver` and `arch` are the run's (from its
    manifest), `arguments` those of the run (function "run_batch") and `code_versions` the
    code that made its chunks where that is not this code; `timing` is zero (nothing is
    computed), shapes None (a store keeps none), `topology` the batch's where it has one. Every
    chunk is verified as a resume verifies it; nothing is written, locked or deleted (a store
    on read-only media reads the same, and a run still going keeps its folder).

    `partial`: a run not finished (or with a damaged chunk) is a RunStoreError naming its
    missing chunks, unless partial=True: then the result holds the instances of the chunks
    that are stored and verified, and a RuntimeWarning says how many chunks and instances are
    left out. Raises RunStoreError (a ValueError) naming `run_dir_flag` for a folder that is
    not a run store, ImportError naming the `io` extra without pyarrow; nothing is computed."""
    check_run_dir(run_dir)
    check_flag("partial", partial)
    stored = read_stored(run_dir, flag=run_dir_flag)
    definition = stored.definition
    total = definition["n_chunks"]
    if stored.unusable:
        missing = sorted(stored.unusable)
        listed = "; ".join(f"chunk {index}: {stored.unusable[index]}" for index in missing[:3])
        more = f"; and {len(missing) - 3} more" if len(missing) > 3 else ""
        if not partial:
            raise RunStoreError(
                f"{run_dir_flag} {stored.path}: {len(missing)} of {total} chunks are not "
                f"stored or not usable ({listed}{more}); run_batch(..., resume=True) with the "
                f"run's own arguments computes them, read_run(..., partial=True) reads the "
                f"others")
        if not stored.chunks:
            raise RunStoreError(f"{run_dir_flag} {stored.path}: none of its {total} chunks is "
                                f"stored and usable yet ({listed}{more})")
        held = sum(len(members) for members, _, _ in stored.chunks.values())
        warn_user(f"{run_dir_flag} {stored.path}: {len(missing)} of {total} chunks left out "
                  f"({listed}{more}); the result holds {held} of the run's "
                  f"{definition['n_instances']} instances")
    order = sorted(stored.chunks)
    summaries = [stored.chunks[index][1] for index in order]
    trajectories = [stored.chunks[index][2] for index in order
                    if stored.chunks[index][2] is not None]
    labels = tuple(definition.get("sensitivities", ()))
    return gathered_result(
        summaries, trajectories, labels, solver=stored_solver(stored), arch=definition["arch"],
        timing=RunTiming(setup_s=0.0, compile_s=0.0, run_s=0.0, collect_s=0.0, robot_steps=0),
        makers=stored.code_versions(), shapes=None, topology=summary_topology(summaries),
        arguments=call_arguments("run_batch", definition.get("duration_s"),
                                 definition.get("cycles"), definition["record_interval_s"],
                                 False, definition["steady_from_cycle"], list(labels),
                                 definition["chunk_size"]))


def stored_solver(stored: StoredRun) -> SolverConfig:
    """The SolverConfig of a stored run: the defaults its manifest recorded (those of fields
    this version has; today's where it recorded none) with its definition's changes from them;
    RunStoreError where this version cannot take them (a value outside today's range)."""
    recorded = (stored.manifest.get("defaults") or {}).get("solver")
    recorded = recorded if isinstance(recorded, dict) else {}
    today = current_defaults()["solver"]
    settings = {name: value for name, value in recorded.items() if name in today}
    settings.update(stored.definition["solver"])
    try:
        return SolverConfig(**settings)
    except (TypeError, ValueError) as error:
        raise RunStoreError(f"{stored.path}: its solver settings {settings} are not this "
                            f"version's ({str(error).splitlines()[0]})") from None


def summary_topology(summaries: Sequence[pd.DataFrame]):
    """The topology of the instances of these summaries where they share one, else None
    (also where their rows no longer make a StarParams: the topology serves only shapes,
    which a store does not keep, so a convenience must not stop a table being read)."""
    pairs = pd.concat([table[["n_arc", "n_limb"]] for table in summaries]).drop_duplicates()
    if len(pairs) != 1:
        return None
    try:
        return build_topology(StarParams.from_row(summaries[0].iloc[0]))
    except ValueError:
        return None


def gathered_result(summaries: Sequence[pd.DataFrame], trajectories: Sequence[pd.DataFrame],
                    labels: Sequence[str], *, solver: SolverConfig, arch: str,
                    timing: RunTiming, makers: list, shapes, topology,
                    arguments: dict) -> SimulationResult:
    """One `SimulationResult` of a batch from its chunks' tables (`ChunkResult`'s or a run
    store's): the summaries concatenated in input order of their `instance` column, the
    trajectories by instance and time, the derivatives by the parameters `labels` split off
    both (`split_sensitivities`); `makers` the code versions that made them (recorded where
    one is not this code); "ok" instances that need a second look are warned about."""
    summary = pd.concat(summaries, ignore_index=True)
    order = np.argsort(summary["instance"].to_numpy(), kind="stable")
    summary = summary.iloc[order].reset_index(drop=True)
    derivatives = trajectory_derivatives = None
    if labels:
        summary, derivatives = split_sensitivities(
            summary, [], sensitivity_columns(tangents.SUMMARY_OUTPUTS, labels))
    warn_about_ok_instances(summary, solver)
    # no records: the empty table with simulate's column types (object columns before: an
    # audit, 2026-12)
    trajectory = (pd.concat(trajectories, ignore_index=True) if trajectories
                  else pd.DataFrame({column: pd.Series(dtype=np.int64 if column == "instance"
                                                       else np.float64)
                                     for column in TRAJECTORY_COLUMNS}))
    trajectory = trajectory.sort_values(["instance", "t_s"], kind="stable").reset_index(drop=True)
    if labels:
        trajectory, trajectory_derivatives = split_sensitivities(
            trajectory, ["instance", "t_s"], sensitivity_columns(tangents.TRAJECTORY_OUTPUTS,
                                                                 labels))
    current = code_version() if makers else None
    foreign = any(maker["code"] != current for maker in makers)
    return SimulationResult(summary=summary, trajectory=trajectory, shapes=shapes,
                            topology=topology, solver=solver, sensitivities=derivatives,
                            trajectory_sensitivities=trajectory_derivatives,
                            timing=timing, arch=arch,
                            code_versions=makers if len(makers) > 1 or foreign else None,
                            arguments=arguments)


def check_run_dir(run_dir):
    """ValueError unless `run_dir` is the path of a folder (a text or a path, not empty)."""
    if not isinstance(run_dir, (str, os.PathLike)):
        raise ValueError(f"run_dir must be the path of the run store's folder, got "
                         f"{type(run_dir).__name__}")
    if isinstance(run_dir, str) and not run_dir.strip():
        # "" was the current folder: a run's chunks written among the user's files, or a
        # finished run there replaced (an audit, 2026-12)
        raise ValueError(f"run_dir must be the path of the run store's folder, got "
                         f"{run_dir!r} (the current folder is \".\")")


def sensitivity_columns(outputs: Sequence[str], labels: Sequence[str]) -> list:
    """The columns of `outputs`' derivatives by the parameters `labels`, in the order a
    `simulate` result's tables have them (`sensitivities.split_result`)."""
    return [tangents.sensitivity_column(output, label) for output in outputs for label in labels]


def split_sensitivities(table: pd.DataFrame, keys: Sequence[str], columns: Sequence[str]):
    """(the table without the derivatives' `columns`, those columns after `keys`' columns) of
    a batch's summary or trajectory gathered from its chunks (`ChunkResult`), in the same rows;
    a table of no rows without them (no records: the chunks' trajectories were not stored)
    gets them empty, float."""
    if not len(table) and not set(columns) <= set(table.columns):
        return table, table[list(keys)].assign(**{column: pd.Series(dtype=np.float64)
                                                  for column in columns})
    return table.drop(columns=list(columns)), table[list(keys) + list(columns)]


@contextlib.contextmanager
def executor_for(workers: Optional[int] = None, scheduler: Optional[str] = None,
                 retries: int = DEFAULT_RETRIES):
    """The executor asked for: `InProcess` (neither), `LocalProcesses(workers)`, or a
    `DaskExecutor` on the cluster whose scheduler listens at `scheduler` (tcp://HOST:PORT);
    closed on exit."""
    if workers is not None and scheduler is not None:
        raise ValueError("give workers (local processes) or scheduler (a Dask cluster), not both")
    check_retries(retries)
    if scheduler is not None and not isinstance(scheduler, str):
        raise ValueError(f"scheduler must be an address like tcp://HOST:PORT, got {scheduler!r}")
    if scheduler is not None:
        require("distributed", "dask")
        from .dask_cluster import remote_executor
        with remote_executor(scheduler, retries) as executor:
            yield executor
    elif workers is not None:
        with LocalProcesses(workers, retries) as executor:
            yield executor
    else:
        yield InProcess()
