"""Scaling on Dask: wall time of one fixed sweep in process, then on local Dask clusters of 1, 2,
... single-threaded worker processes.

    python -m studies scaling [--workers-list 1,2] [--out results/] [--quick]

The sweep: the five paper gaits × 8 values of alpha (40 instances), one 3.15 s cycle at
dt = 1 ms, in chunks of 5 (8 chunks; one compiled engine). Every mode first runs one chunk per
process (Taichi compiles the engine there; not timed), then the whole sweep is timed
(`wall_s`); a cluster's start is timed apart (`startup_s`). In process, Taichi uses its own CPU
threads (one per core); a Dask worker is one process with one Taichi thread. Every mode's table
is checked to be bitwise the in-process one.

Writes `scaling.csv`: one row per mode with the machine (CPU model, cores, load average before
the run), the versions and the speed-up over in process.
"""

from __future__ import annotations

import contextlib
import datetime
import os
import platform
import time

import pandas as pd

from . import common, distributed, runs

DESCRIPTION = "Wall time of one fixed sweep: in process against 1, 2, ... local Dask workers."

SWEEP_ALPHAS = [0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6]
CHUNK = 5


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def sweep_params(quick: bool):
    from taichi_star.experiment import PAPER_GAITS
    gaits = list(PAPER_GAITS)[:2] if quick else list(PAPER_GAITS)
    alphas = SWEEP_ALPHAS[:2] if quick else SWEEP_ALPHAS
    return common.param_product({"gait": gaits, "alpha": alphas})


def build_parser():
    parser = common.common_parser("scaling", DESCRIPTION)
    parser.add_argument("--workers-list", default="1,2",
                        help="local Dask cluster sizes to time after the in-process run "
                             "(default 1,2)")
    return parser


def time_mode(executor, params, run_kwargs, warm_tasks):
    """Warm every process up with one chunk (untimed), then time the sweep."""
    if isinstance(executor, common.InProcess):
        common.run_chunk(*warm_tasks[0])
    else:
        client = executor.client
        workers = list(client.scheduler_info()["workers"])
        futures = [client.submit(distributed.run_on_worker, common.run_chunk, *warm_tasks[0],
                                 workers=[worker], allow_other_workers=False, pure=False)
                   for worker in workers]
        client.gather(futures)
    start = time.perf_counter()
    summary = common.run_batch(params, executor=executor, **run_kwargs).summary
    return time.perf_counter() - start, summary


def main(argv=None):
    args = build_parser().parse_args(argv)
    counts = common.parse_values(args.workers_list, "--workers-list", int)
    if any(n < 1 for n in counts):
        raise common.StudyArgumentError(f"--workers-list: every count must be >= 1, got "
                                        f"{args.workers_list!r}")
    if args.arch != "cpu":
        raise common.StudyArgumentError("--arch: the scaling study times CPU processes (cpu)")
    chunk = args.chunk_size if args.chunk_size is not None else (1 if args.quick else CHUNK)
    if chunk < 1:
        raise common.StudyArgumentError(f"--chunk-size must be >= 1, got {chunk}")
    solver = common.solver_for(args)
    params = sweep_params(args.quick)
    duration = common.QUICK_DURATION_S if args.quick else params[0].period
    run_kwargs = dict(duration_s=duration, solver=solver, arch="cpu", chunk_size=chunk,
                      progress=False)
    chunks = common.plan_chunks(params, duration_s=duration, chunk_size=chunk)
    duration_c, members = chunks[0]
    warm = [([params[i] for i in members], members, duration_c, solver, "cpu", None, False,
             False, 1, True)]
    steps = int(round(duration / solver.dt))
    out = common.out_dir(args)
    machine = {"cpu_model": cpu_model(), "cores": os.cpu_count(),
               "platform": platform.platform(), "python": platform.python_version()}
    try:
        import dask
        import taichi
        version = taichi.__version__
        machine.update(taichi=".".join(map(str, version)) if isinstance(version, tuple)
                       else str(version), dask=dask.__version__)
    except ImportError:
        pass
    machine.update(code_version=runs.code_version(),
                   date=datetime.datetime.now().isoformat(timespec="seconds"))

    rows, reference = [], None
    modes = [("in-process", 0)] + [("dask-local", n) for n in counts]
    for mode, workers in modes:
        load = os.getloadavg()[0]
        start = time.perf_counter()
        if workers:
            context = distributed.local_executor(workers)
        else:
            context = contextlib.nullcontext(common.InProcess())
        with context as executor:
            startup = time.perf_counter() - start
            wall, summary = time_mode(executor, params, run_kwargs, warm)
        if reference is None:
            reference = summary
        same = summary.equals(reference)
        rows.append({"mode": mode, "workers": workers,
                     "taichi_threads_per_process": "default (one per core)" if not workers else 1,
                     "instances": len(params), "chunks": len(chunks), "chunk_size": chunk,
                     "steps_per_instance": steps, "dt_s": solver.dt,
                     "robot_steps": len(params) * steps, "startup_s": startup, "wall_s": wall,
                     "robot_steps_per_s": len(params) * steps / wall,
                     "same_table_as_in_process": bool(same), "load_1min_before": load,
                     **machine})
        print(f"{mode:>10} workers={workers}: {wall:.2f} s (startup {startup:.2f} s)")
    table = pd.DataFrame(rows)
    table["speedup_vs_in_process"] = table["wall_s"].iloc[0] / table["wall_s"]
    csv = common.write_csv(table, out / "scaling.csv")
    print(common.describe([csv]))
    return table
