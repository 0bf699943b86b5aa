"""Scaling: wall time of one fixed sweep in process, on local worker processes and on local Dask
clusters of 1, 2, ... single-threaded workers.

    python -m studies scaling [--workers-list 1,2] [--no-dask] [--out DIR] [--quick]

The sweep: the five paper gaits × 8 values of alpha (40 instances), one 3.15 s cycle at
dt = 1 ms, in chunks of 5 (8 chunks; one compiled engine). Every mode first runs one chunk per
worker (Taichi compiles or loads the engine there; not timed), then the whole sweep is timed
(`wall_s`); starting the workers is timed apart (`startup_s`). In process, Taichi uses its own
CPU threads (one per core); a worker is one process with one Taichi thread. Every mode's table
is checked to be bitwise the in-process one.

Writes `scaling.csv`: one row per mode with the load average before the run and the speed-up
over in process (the machine and versions are in its provenance sidecar).
"""

from __future__ import annotations

import contextlib
import os
import time

import pandas as pd

from taichi_star.batch import MAX_LOCAL_WORKERS, InProcess, LocalProcesses, run_batch
from taichi_star.extras import missing_extra
from taichi_star.experiment import PAPER_GAITS
from taichi_star.timegrid import steps_in

from . import cli, provenance

DESCRIPTION = ("Wall time of one fixed sweep: in process against 1, 2, ... local worker "
               "processes and Dask workers.")

SWEEP_ALPHAS = [0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6]
CHUNK = 5


def sweep_params(quick: bool):
    gaits = list(PAPER_GAITS)[:2] if quick else list(PAPER_GAITS)
    alphas = SWEEP_ALPHAS[:2] if quick else SWEEP_ALPHAS
    return cli.param_product({"gait": gaits, "alpha": alphas})


def build_parser():
    parser = cli.StudyParser("scaling", DESCRIPTION, archs=("cpu",))
    parser.add_argument("--workers-list", default="1,2",
                        help=f"worker counts to time after the in-process run, each once and at "
                             f"most {MAX_LOCAL_WORKERS} (default 1,2)")
    parser.add_argument("--no-dask", action="store_true",
                        help="time local worker processes only, not Dask clusters")
    parser.add_argument("--chunk-size", type=int, default=CHUNK, quick=1,
                        help="instances per chunk")
    cli.add_dt_flag(parser)
    return parser


def modes(counts, dask: bool):
    """(mode name, workers, executor context factory) in the order they are timed."""
    yield "in-process", 0, lambda: contextlib.nullcontext(InProcess())
    for count in counts:
        yield "processes", count, lambda n=count: LocalProcesses(n)
        if dask:
            from taichi_star.batch.dask_cluster import local_executor
            yield "dask-local", count, lambda n=count: local_executor(n)


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    missing_dask = "" if args.no_dask else missing_extra("dask")
    if missing_dask:
        raise cli.StudyArgumentError(f"timing Dask clusters: {missing_dask} (or pass --no-dask)")
    counts = cli.parse_counts(args.workers_list, "--workers-list", MAX_LOCAL_WORKERS)
    solver = cli.solver(args)
    params = sweep_params(args.quick)
    duration = cli.QUICK_DURATION_S if args.quick else params[0].period
    # the study has no --cycles for cli.solver to check its run against
    cli.check_length(f"--quick ({duration:g} s)" if args.quick
                     else f"the sweep's cycle ({duration:g} s)", duration, solver.dt, "--dt")
    sweep = {"gait": sorted({p.gait for p in params}), "alpha": sorted({p.alpha for p in params})}
    out = cli.Output(args, argv or [], model={"sweep": sweep}, solver=solver)
    run_kwargs = dict(solver=solver, chunk_size=args.chunk_size, progress=False)  # timed runs
    steps = steps_in(duration, solver.dt)
    rows, reference = [], None
    for mode, workers, context in modes(counts, dask=not args.no_dask):
        load = os.getloadavg()[0]
        start = time.perf_counter()
        with context() as executor:
            # untimed: start the workers and compile (or load) the engine in each
            run_batch(params[:max(workers, 1) * args.chunk_size], duration, executor=executor,
                      **run_kwargs)
            startup = time.perf_counter() - start
            start = time.perf_counter()
            summary = run_batch(params, duration, executor=executor, **run_kwargs).summary
            wall = time.perf_counter() - start
        reference = summary if reference is None else reference
        rows.append({"mode": mode, "workers": workers,
                     "taichi_threads_per_process": "default (one per core)" if not workers else 1,
                     "instances": len(params), "chunk_size": args.chunk_size,
                     "steps_per_instance": steps, "dt_s": solver.dt,
                     "robot_steps": len(params) * steps, "startup_s": startup, "wall_s": wall,
                     "robot_steps_per_s": len(params) * steps / wall,
                     "same_table_as_in_process": bool(summary.equals(reference)),
                     "load_1min_before": load})
        print(f"{mode:>10} workers={workers}: {wall:.2f} s (startup {startup:.2f} s)")
    # the machine, the code and the model timed, on every row (they were in the sidecar
    # alone: an audit, 2026-12)
    table = pd.DataFrame(rows).assign(preset="paper", precision=solver.precision,
                                      **provenance.timing_columns(args.arch))
    table["speedup_vs_in_process"] = table["wall_s"].iloc[0] / table["wall_s"]
    out.write_csv(table, "scaling.csv")
    out.report()
    return table
