"""Scaling: wall time of one fixed sweep in process, on local worker processes and on local Dask
clusters of 1, 2, ... single-threaded workers.

    python -m studies scaling [--workers-list 1,2] [--no-dask] [--rounds 3] [--out DIR] [--quick]

The sweep: the five paper gaits × 8 values of alpha (40 instances), one 3.15 s cycle at
dt = 1 ms, in chunks of 5 (8 chunks; one compiled engine). Every mode first runs one chunk per
worker (Taichi compiles or loads the engine there; not timed), then the whole sweep is timed
(`wall_s`); starting the workers is timed apart (`startup_s`, the median of the rounds'). The
sweeps are timed in --rounds interleaved rounds, each timing every mode once in turn, so that
the machine's drifts reach every mode alike; a mode's workers are started for its turn and
stopped after it, so that none idles beside another's sweep. In process, Taichi uses its own
CPU threads (one per core); a worker is one process with one Taichi thread. Every mode's
table is checked to be bitwise the in-process one.

Writes `scaling.csv`: one row per mode with its best round's wall time (`wall_s`), the median
(`wall_s_median`), every round's (`wall_s_rounds`, ";"-separated, in order), the load average
before the rounds, and the speed-up over in process as the median over rounds of the two
modes' ratio in the same round (`speedup_vs_in_process`); machine, code and model on every row.
"""

from __future__ import annotations

import contextlib
import os
import time

import numpy as np
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
    parser.add_argument("--rounds", type=int, default=3, quick=1,
                        help="interleaved rounds, each timing every mode's sweep once in turn "
                             "(default 3)")
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
    cli.check_count(args.rounds, "--rounds", 1, cli.MAX_REPEATS)
    steps = steps_in(duration, solver.dt)
    timed = list(modes(counts, dask=not args.no_dask))
    warmup_instances = sum(min(max(workers, 1) * args.chunk_size, len(params))
                           for _, workers, _ in timed)
    cli.check_robot_steps(f"--rounds {args.rounds} × {len(timed)} modes × the sweep's "
                          f"{len(params)} instances and the warm-ups, of {steps} steps each",
                          args.rounds * (len(timed) * len(params) + warmup_instances) * steps,
                          cli.work_arch(args))
    out = cli.Output(args, argv or [], model={"sweep": sweep}, solver=solver)
    run_kwargs = dict(solver=solver, chunk_size=args.chunk_size, progress=False)  # timed runs
    walls = np.empty((args.rounds, len(timed)))
    startups = np.empty((args.rounds, len(timed)))
    same = np.ones(len(timed), dtype=bool)  # each round's table the in-process one's
    load = os.getloadavg()[0]
    for round_index in range(args.rounds):
        for index, (mode, workers, context) in enumerate(timed):
            # each mode's workers alive only while it is timed (idle Dask workers beside
            # another mode's sweep slowed it by ~8 %, measured)
            start = time.perf_counter()
            with context() as executor:
                # untimed: start the workers and compile (or load) the engine in each
                run_batch(params[:max(workers, 1) * args.chunk_size], duration,
                          executor=executor, **run_kwargs)
                startups[round_index, index] = time.perf_counter() - start
                start = time.perf_counter()
                summary = run_batch(params, duration, executor=executor, **run_kwargs).summary
                walls[round_index, index] = time.perf_counter() - start
            if index == 0:
                reference = summary  # the in-process sweep of this round
            # every round's, not the last alone (a review, 2026-12)
            same[index] &= bool(summary.equals(reference))
            print(f"round {round_index + 1}: {mode:>10} workers={workers}: "
                  f"{walls[round_index, index]:.2f} s (startup "
                  f"{startups[round_index, index]:.2f} s)", flush=True)
    rows = []
    for index, (mode, workers, _) in enumerate(timed):
        wall = float(walls[:, index].min())
        rows.append({"mode": mode, "workers": workers,
                     "taichi_threads_per_process": "default (one per core)" if not workers else 1,
                     "instances": len(params), "chunk_size": args.chunk_size,
                     "steps_per_instance": steps, "dt_s": solver.dt,
                     "robot_steps": len(params) * steps,
                     "startup_s": float(np.median(startups[:, index])), "rounds": args.rounds,
                     "wall_s": wall, "wall_s_median": float(np.median(walls[:, index])),
                     "wall_s_rounds": ";".join(f"{t:.6g}" for t in walls[:, index]),
                     "robot_steps_per_s": len(params) * steps / wall,
                     # the ratio of each round's pair, the machine's drifts reaching both alike
                     "speedup_vs_in_process": float(np.median(walls[:, 0] / walls[:, index])),
                     "same_table_as_in_process": bool(same[index]),
                     "load_1min_before": load})
    # the machine, the code and the model timed, on every row (they were in the sidecar
    # alone: an audit, 2026-12)
    table = pd.DataFrame(rows).assign(preset="paper", precision=solver.precision,
                                      **provenance.timing_columns(args.arch))
    out.write_csv(table, "scaling.csv")
    out.report()
    return table
