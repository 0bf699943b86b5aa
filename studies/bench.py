"""Throughput of the batch engine (design §6, issue 4): robot-steps per second against batch size.

    python -m studies bench [--arch cpu|gpu] [--out results/] [--quick]
                            [--batch-sizes 1,8,64,512,2048,8192] [--precisions f64,f32]
                            [--steps 100] [--repeats 3] [--scenarios all_terms,alpha_0,...|none]
                            [--scenario-batch 64] [--no-cache-probe] [--no-progress]

Gait A1+A3, the paper's discretisation (N = 193 nodes), h = 1 ms, implicit Euler. For every batch
size B and precision: a fresh engine is compiled (its first launch, timed apart as `compile_s`),
then, `--repeats` times from rest, `WARMUP_STEPS` warm-up steps and `--steps` timed steps; the
fastest window counts (the others were disturbed by something else). The timed window starts at
t = 10 ms, inside the 150 ms heating pulse, where Newton needs the most iterations: the figures
are conservative against a whole-cycle average (`newton_iterations_mean` says how hard the
window was).

Phase split: after the timed windows, one profiling kernel per engine repeats, for every instance
at its current state, the assembly alone, assembly + factorisation, and assembly +
factorisation + solve (the factorisation is in place, so it always needs a fresh assembly); the
differences give each phase's time per Newton iteration, times the window's mean iterations per
step gives µs per instance-step, and bookkeeping (predictor, convergence test, status, step
loop) is the rest of the measured step time. All times are wall-clock of the whole machine
divided by the instances processed (so they include the parallel speed-up over cores); the
profile repeats work on a state already in cache, so under noise or when bookkeeping is small
`bookkeeping_us` can come out slightly negative.

The B sweep runs for each Newton Jacobian mode (`jacobian`: "newton" refactors every
iteration, "chord" reuses the step's first LU while it contracts); the phase split assumes one
factorisation per iteration, so only its "newton" rows are meaningful (and plotted). Section "processes": the
end-to-end `simulate(..., workers=N)` throughput at one batch size, f64 (worker processes are
how this machine's two cores are used: Taichi's own CPU threads gained only ~1.25× here).

"Skip what a scene does not need": at one batch size, the same measurement with all terms and
with α = 0 (no jet), C_a = 0 (no added mass), drag 0 (rod and cylinder drag off), gait "none"
(no actuation); terms that no instance uses are compiled out (`terms` column, engine.TERM_*).

Compile time with a cold and a warm Taichi offline cache: two fresh Python processes that share
an empty temporary cache folder (`TI_OFFLINE_CACHE_FILE_PATH`), the first compiles from scratch,
the second loads the first's kernels (section "compile"; off with --no-cache-probe and in
--quick).

Writes `bench.csv` (`bench_gpu.csv` for --arch gpu): one row per measurement; `section` is
"batch" (B sweep), "skip" (terms at one B) or "compile" (cold/warm cache); columns: machine,
cpu_model, cores, gpu, arch, section, scenario, terms, batch_size, precision, n_nodes, dt_s,
gait, warmup_steps, steps, repeats, commit, timestamp, import_s, setup_s, compile_s,
time_to_first_step_s, robot_steps_per_s, real_time_factor (= robot_steps_per_s × dt: simulated
robot-seconds per wall second), step_us, newton_iterations_mean, assembly_us, factor_us,
solve_us, bookkeeping_us (µs per instance-step), factor_flops (per factorisation),
factor_gflops (achieved by the factorisation). And `bench.png` (`bench_gpu.png`): throughput
against B (log-log, one line per precision, the design §6 target dashed), the phase split and
the scenarios.
"""

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import taichi as ti

from taichi_star.engine import STATUS_OK, terms_used
from taichi_star.model import build_model
from taichi_star.params import JACOBIANS, PRECISIONS, SolverConfig, StarParams
from taichi_star.simulation import (STEPS_PER_LAUNCH, available_archs, ensure_taichi, get_engine,
                                    simulate)

from . import common

DESCRIPTION = ("Engine throughput: robot-steps/s against batch size and precision (gait A1+A3, "
               "N = 193, h = 1 ms), compile time apart, phase split, terms compiled out.")

GAIT = "A1+A3"
DT = 1e-3
WARMUP_STEPS = 10
DEFAULT_BATCH_SIZES = "1,8,64,512,2048,8192"
DEFAULT_STEPS = 100
DEFAULT_REPEATS = 3
"""Timed windows per measurement; the fastest counts (the others were disturbed)."""
SCENARIO_BATCH = 64
PROCESS_BATCH = 512
QUICK_BATCH_SIZES = "2"
QUICK_STEPS = 5
QUICK_SCENARIO_BATCH = 2
QUICK_SCENARIOS = "all_terms,added_mass_0"
"""--quick keeps to one engine (the smallest, as the other studies' quick batches use) and to
scenarios with the same terms, so that it compiles the stepping kernel at most once."""
PROFILE_SECONDS = 0.5
QUICK_PROFILE_SECONDS = 0.02
"""Target duration of one profiling launch, s: long enough to time, short next to the benchmark."""
PROFILE_LAUNCHES = 3
"""Each phase is timed as the best of this many launches."""
TARGETS = {"cpu": 20_000.0, "gpu": 2_000_000.0}
"""Design §6 throughput goals, robot-steps/s (2-core CPU at B >= 512, H100/H200 at B >= 8192)."""

SCENARIOS = {
    "all_terms": {},
    "alpha_0": {"alpha": 0.0},
    "added_mass_0": {"added_mass_coeff": 0.0},
    "drag_0": {"drag_parallel": 0.0, "drag_perpendicular": 0.0, "cylinder_drag": 0.0},
    "gait_none": {"gait": "none"},
}
"""Scenario name -> StarParams changes from the benchmark robot (gait A1+A3, paper values)."""

COLUMNS = ["machine", "cpu_model", "cores", "gpu", "arch", "section", "scenario", "terms",
           "batch_size", "precision", "jacobian", "workers", "n_nodes", "dt_s", "gait", "warmup_steps", "steps",
           "repeats", "commit", "timestamp", "import_s", "setup_s", "compile_s", "time_to_first_step_s",
           "robot_steps_per_s", "real_time_factor", "step_us", "newton_iterations_mean",
           "assembly_us", "factor_us", "solve_us", "bookkeeping_us", "factor_flops",
           "factor_gflops"]


# --------------------------------------------------------------------------- provenance

def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (platform.processor() elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def gpu_name() -> str:
    """The first GPU's name from nvidia-smi, or "unknown" where nvidia-smi is missing."""
    try:
        output = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                                capture_output=True, text=True, timeout=30, check=True).stdout
        return output.strip().splitlines()[0] if output.strip() else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def machine_info(arch: str) -> dict:
    """machine, cpu_model, cores, gpu ("" for the CPU arch) of this machine."""
    model = cpu_model()
    cores = os.cpu_count() or 0
    gpu = gpu_name() if arch != "cpu" else ""
    machine = f"{model} ({cores} cores)" + (f" + {gpu}" if gpu else "")
    return {"machine": machine, "cpu_model": model, "cores": cores, "gpu": gpu}


def git_commit() -> str:
    """Short hash of HEAD, "-dirty" when tracked files differ from it; "unknown" outside git."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, check=True,
                              capture_output=True, text=True).stdout.strip()
        changes = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                 cwd=root, check=True, capture_output=True, text=True).stdout
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("-dirty" if changes.strip() else "")


def timestamp() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def check_arch(arch: str, flag: str = "--arch"):
    """Raise StudyArgumentError, listing the available archs, when `arch` is missing here."""
    if arch == "cpu":
        return
    available = available_archs()
    if arch not in available:
        raise common.StudyArgumentError(
            f"{flag} {arch}: no such backend on this machine; available archs: "
            f"{', '.join(available)}")


# --------------------------------------------------------------------------- measurement

@ti.kernel
def profile_phases(engine: ti.template(), phases: ti.i32, calls: ti.i32, time_s: float,
                   terms: ti.template()):
    """For every live instance, `calls` times: assemble at the current state (time_s, s),
    then factor when phases >= 2, then solve when phases >= 3."""
    for b in range(engine.capacity):
        if engine.status[b] == STATUS_OK:
            h = engine.dt[None]
            target = engine.natural_curvature_target(b, time_s)
            for _ in range(calls):
                # implicit Euler's inertia scale 1/h² and velocity gain 1/h; with the Jacobian
                engine.assemble(b, target, 1.0 / (h * h), 1.0 / h, 1, terms)
                if phases >= 2:
                    engine.system.factor(b)
                if phases >= 3:
                    engine.system.solve(b)


def advance(engine, first_step: int, n_steps: int, terms: int):
    """Implicit Euler steps in launches of simulate's size, finished when this returns."""
    step = first_step
    while step < first_step + n_steps:
        count = min(STEPS_PER_LAUNCH, first_step + n_steps - step)
        engine.advance(step, count, False, terms)
        step += count
    ti.sync()


def bench_solver(precision: str, jacobian: str = "newton") -> SolverConfig:
    """The benchmark's solver: h = 1 ms, implicit Euler, the precision's tightest usable tol."""
    return SolverConfig(dt=DT, precision=precision, jacobian=jacobian,
                        newton_tol=1e-10 if precision == "f64" else 1e-7)


def start_batch(params, arch: str, precision: str, jacobian: str = "newton"):
    """(engine, model, solver, terms, setup_s): Taichi initialised, the batch's engine built
    (or reused) and loaded at rest, as `simulate` does."""
    solver = bench_solver(precision, jacobian)
    start = time.perf_counter()
    model = build_model(params)
    ensure_taichi(arch, precision)
    engine = get_engine(model)
    engine.load(model, solver)
    ti.sync()
    return engine, model, solver, terms_used(model), time.perf_counter() - start


def first_launch(engine, terms):
    """(compile_s, first_s): the first one-step launch (compile + step) less a second one."""
    first = time.perf_counter()
    advance(engine, 0, 1, terms)
    first = time.perf_counter() - first
    again = time.perf_counter()
    advance(engine, 1, 1, terms)
    again = time.perf_counter() - again
    return max(first - again, 0.0), first


def measure(params, arch: str, precision: str, steps: int, repeats: int,
            profile_seconds: float, jacobian: str = "newton") -> dict:
    """Throughput and phase split of one batch (see the module docstring): the best of
    `repeats` timed windows, each from rest after the warm-up steps; times in s, µs."""
    engine, model, solver, terms, setup = start_batch(params, arch, precision, jacobian)
    batch = model.batch_size
    compile_s, _ = first_launch(engine, terms)
    timed = math.inf
    for _ in range(repeats):
        engine.load(model, solver)
        advance(engine, 0, WARMUP_STEPS, terms)
        iterations_before = engine.newton_total.to_numpy()[:batch].sum()
        start = time.perf_counter()
        advance(engine, WARMUP_STEPS, steps, terms)
        timed = min(timed, time.perf_counter() - start)
        if (engine.status.to_numpy()[:batch] != STATUS_OK).any():
            raise RuntimeError("an instance failed during the benchmark: its timing is not valid")
        # the same every repeat: the simulation is deterministic
        iterations = ((engine.newton_total.to_numpy()[:batch].sum() - iterations_before)
                      / (batch * steps))

    robot_steps = batch * steps / timed
    step_us = 1e6 / robot_steps
    phase = phase_split(engine, terms, batch, (WARMUP_STEPS + steps) * DT,
                        timed / (steps * iterations), profile_seconds)
    assembly, factor, solve = (iterations * phase[name] for name in ("assembly", "factor", "solve"))
    flops = engine.plan.factor_flops
    return {"gait": params[0].gait, "jacobian": jacobian, "workers": 1, "terms": terms,
            "n_nodes": engine.n_nodes, "setup_s": setup,
            "compile_s": compile_s,
            "robot_steps_per_s": robot_steps, "real_time_factor": robot_steps * DT,
            "step_us": step_us, "newton_iterations_mean": iterations, "assembly_us": assembly,
            "factor_us": factor, "solve_us": solve,
            "bookkeeping_us": step_us - assembly - factor - solve, "factor_flops": flops,
            "factor_gflops": flops / (phase["factor"] * 1e3) if phase["factor"] > 0 else math.nan}


def measure_processes(batch: int, workers: int, jacobian: str, steps: int, repeats: int) -> dict:
    """End-to-end throughput of `simulate(..., workers=workers)` (f64, CPU): the best of
    `repeats` calls of WARMUP_STEPS + steps steps from rest, after one call that starts the
    worker processes and compiles their engines; includes splitting the batch, the processes'
    transfers and building the tables."""
    params = [StarParams(gait=GAIT)] * batch
    solver = bench_solver("f64", jacobian)
    duration = (WARMUP_STEPS + steps) * DT
    simulate(params, duration, solver, workers=workers)
    timed = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        result = simulate(params, duration, solver, workers=workers)
        timed = min(timed, time.perf_counter() - start)
    if (result.summary["status"] != "ok").any():
        raise RuntimeError("an instance failed during the benchmark: its timing is not valid")
    robot_steps = batch * (WARMUP_STEPS + steps) / timed
    return {"gait": GAIT, "jacobian": jacobian, "workers": workers,
            "newton_iterations_mean": float(result.summary["newton_iterations_mean"].mean()),
            "robot_steps_per_s": robot_steps, "real_time_factor": robot_steps * DT,
            "step_us": 1e6 / robot_steps}


def phase_split(engine, terms, batch, time_s, iteration_s, profile_seconds) -> dict:
    """µs per instance and Newton iteration of assembly, factorisation and solve, from launches
    of `calls` assemblies, assembly + factor, and assembly + factor + solve per instance;
    `iteration_s` (one Newton iteration of the batch, s) sizes `calls`."""
    calls = int(min(max(round(profile_seconds / iteration_s), 1), 10_000))
    profile_phases(engine, 3, 1, time_s, terms)  # compile outside the timings
    ti.sync()
    cumulative = []
    for phases in (1, 2, 3):
        # best of a few launches: the differences of noisy timings would be noisier still
        best = math.inf
        for _ in range(PROFILE_LAUNCHES):
            start = time.perf_counter()
            profile_phases(engine, phases, calls, time_s, terms)
            ti.sync()
            best = min(best, time.perf_counter() - start)
        cumulative.append(best * 1e6 / (batch * calls))
    return {"assembly": cumulative[0], "factor": cumulative[1] - cumulative[0],
            "solve": cumulative[2] - cumulative[1]}


PROBE_CODE = """
import json, sys, time
start = time.perf_counter()
import studies.bench as bench
imported = time.perf_counter() - start
print("BENCH_PROBE " + json.dumps(bench.first_step_probe(sys.argv[1], sys.argv[2],
                                                          int(sys.argv[3]), imported)))
"""


def first_step_probe(arch: str, precision: str, batch_size: int, import_s: float) -> dict:
    """In a fresh process: setup (Taichi init, engine, load) and the first launch of a batch,
    split into compile and step by timing a second launch. Times in s."""
    engine, _, _, terms, setup = start_batch([StarParams(gait=GAIT)] * batch_size, arch,
                                             precision)
    compile_s, first = first_launch(engine, terms)
    return {"gait": GAIT, "import_s": import_s, "setup_s": setup, "compile_s": compile_s,
            "time_to_first_step_s": import_s + setup + first}


def cache_probe(arch: str, precision: str, batch_size: int) -> dict:
    """{"cold_cache": probe, "warm_cache": probe}: two fresh processes sharing an empty
    temporary Taichi offline cache, so the first compiles everything and the second reuses it."""
    root = Path(__file__).resolve().parents[1]
    results = {}
    with tempfile.TemporaryDirectory(prefix="taichi_star_cache_") as cache:
        env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=cache,
                   PYTHONPATH=os.pathsep.join(filter(None, [str(root),
                                                            os.environ.get("PYTHONPATH")])))
        for label in ("cold_cache", "warm_cache"):
            run = subprocess.run([sys.executable, "-c", PROBE_CODE, arch, precision,
                                  str(batch_size)], cwd=root, env=env, capture_output=True,
                                 text=True)
            lines = [line for line in run.stdout.splitlines() if line.startswith("BENCH_PROBE ")]
            if run.returncode != 0 or not lines:
                raise RuntimeError(f"compile probe ({label}) failed:\n{run.stderr[-2000:]}")
            results[label] = json.loads(lines[-1].split(" ", 1)[1])
    return results


# --------------------------------------------------------------------------- CLI

def build_parser():
    parser = argparse.ArgumentParser(prog="python -m studies bench", description=DESCRIPTION)
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu",
                        help="Taichi backend (default cpu); gpu writes bench_gpu.csv/png")
    parser.add_argument("--out", default=common.DEFAULT_OUT, help="output folder (default results/)")
    parser.add_argument("--quick", action="store_true",
                        help=f"small fast run for tests: B {QUICK_BATCH_SIZES}, f64, "
                             f"{QUICK_STEPS} steps, scenarios {QUICK_SCENARIOS} at "
                             f"B = {QUICK_SCENARIO_BATCH}, no cache probe")
    parser.add_argument("--batch-sizes", default=None,
                        help=f"comma list of batch sizes B >= 1 (default {DEFAULT_BATCH_SIZES})")
    parser.add_argument("--precisions", default=None,
                        help=f"comma list of {', '.join(PRECISIONS)} (default f64,f32)")
    parser.add_argument("--steps", type=int, default=None,
                        help=f"timed steps per measurement, after {WARMUP_STEPS} warm-up steps "
                             f"(default {DEFAULT_STEPS})")
    parser.add_argument("--repeats", type=int, default=None,
                        help=f"timed windows per measurement, the best counts (default "
                             f"{DEFAULT_REPEATS}; --quick 1)")
    parser.add_argument("--scenarios", default=None,
                        help=f"comma list of {', '.join(SCENARIOS)} (default all), measured at "
                             f"B = {SCENARIO_BATCH} in the first precision; 'none' skips them")
    parser.add_argument("--scenario-batch", type=int, default=None,
                        help=f"batch size of the scenarios (default {SCENARIO_BATCH})")
    parser.add_argument("--jacobians", default=None,
                        help=f"comma list of {', '.join(JACOBIANS)} for the B sweep and the "
                             f"processes section (default newton,chord; --quick newton)")
    parser.add_argument("--workers", default=None,
                        help="comma list of worker-process counts for the end-to-end "
                             "`simulate(workers=...)` section (default 1,2; --quick none)")
    parser.add_argument("--process-batch", type=int, default=None,
                        help=f"batch size of the processes section (default {PROCESS_BATCH})")
    parser.add_argument("--no-cache-probe", action="store_true",
                        help="skip the cold/warm offline-cache compile probe (two subprocesses)")
    parser.add_argument("--no-progress", action="store_true", help="print no per-row lines")
    return parser


def parse_args(argv):
    """Parsed and validated arguments (StudyArgumentError before any computation)."""
    args = build_parser().parse_args(argv)
    batch_text = args.batch_sizes if args.batch_sizes is not None else (
        QUICK_BATCH_SIZES if args.quick else DEFAULT_BATCH_SIZES)
    args.batch_sizes = common.parse_values(batch_text, "--batch-sizes", int)
    if any(b < 1 for b in args.batch_sizes):
        raise common.StudyArgumentError(f"--batch-sizes: every batch size must be >= 1, got "
                                        f"{batch_text!r}")
    precision_text = args.precisions if args.precisions is not None else (
        "f64" if args.quick else "f64,f32")
    args.precisions = common.parse_values(precision_text, "--precisions", str)
    unknown = [p for p in args.precisions if p not in PRECISIONS]
    if unknown:
        raise common.StudyArgumentError(f"--precisions: unknown precision {unknown[0]!r}; "
                                        f"choose from {', '.join(PRECISIONS)}")
    if args.steps is None:
        args.steps = QUICK_STEPS if args.quick else DEFAULT_STEPS
    if args.steps < 1:
        raise common.StudyArgumentError(f"--steps must be >= 1, got {args.steps}")
    if args.repeats is None:
        args.repeats = 1 if args.quick else DEFAULT_REPEATS
    if args.repeats < 1:
        raise common.StudyArgumentError(f"--repeats must be >= 1, got {args.repeats}")
    scenario_text = args.scenarios if args.scenarios is not None else (
        QUICK_SCENARIOS if args.quick else ",".join(SCENARIOS))
    args.scenarios = ([] if scenario_text.strip().lower() == "none"
                      else common.parse_values(scenario_text, "--scenarios", str))
    unknown = [s for s in args.scenarios if s not in SCENARIOS]
    if unknown:
        raise common.StudyArgumentError(f"--scenarios: unknown scenario {unknown[0]!r}; choose "
                                        f"from {', '.join(SCENARIOS)} or none")
    if args.scenario_batch is None:
        args.scenario_batch = QUICK_SCENARIO_BATCH if args.quick else SCENARIO_BATCH
    if args.scenario_batch < 1:
        raise common.StudyArgumentError(f"--scenario-batch must be >= 1, got "
                                        f"{args.scenario_batch}")
    jacobian_text = args.jacobians if args.jacobians is not None else (
        "newton" if args.quick else ",".join(JACOBIANS))
    args.jacobians = common.parse_values(jacobian_text, "--jacobians", str)
    unknown = [j for j in args.jacobians if j not in JACOBIANS]
    if unknown:
        raise common.StudyArgumentError(f"--jacobians: unknown Jacobian mode {unknown[0]!r}; "
                                        f"choose from {', '.join(JACOBIANS)}")
    worker_text = args.workers if args.workers is not None else ("none" if args.quick else "1,2")
    args.workers = ([] if worker_text.strip().lower() == "none"
                    else common.parse_values(worker_text, "--workers", int))
    if any(w < 1 for w in args.workers):
        raise common.StudyArgumentError(f"--workers: every count must be >= 1, got {worker_text!r}")
    if args.workers and args.arch != "cpu":
        raise common.StudyArgumentError("--workers: worker processes run on the CPU; use "
                                        "--workers none with --arch gpu")
    if args.process_batch is None:
        args.process_batch = PROCESS_BATCH
    if args.process_batch < 1:
        raise common.StudyArgumentError(f"--process-batch must be >= 1, got {args.process_batch}")
    args.cache_probe = not (args.no_cache_probe or args.quick)
    check_arch(args.arch)
    return args


def output_paths(out: Path, arch: str):
    """(csv, png) for the arch: bench.* on the CPU, bench_gpu.* on a GPU."""
    stem = "bench" if arch == "cpu" else "bench_gpu"
    return out / f"{stem}.csv", out / f"{stem}.png"


def run_bench(args) -> pd.DataFrame:
    """Every measurement of the parsed arguments as one table (columns `COLUMNS`)."""
    base = {**machine_info(args.arch), "arch": args.arch, "dt_s": DT,
            "warmup_steps": WARMUP_STEPS, "steps": args.steps,
            "repeats": args.repeats, "commit": git_commit()}
    profile_seconds = QUICK_PROFILE_SECONDS if args.quick else PROFILE_SECONDS
    rows = []

    def add(row):
        rows.append({**base, **row, "timestamp": timestamp()})
        if not args.no_progress:
            row = rows[-1]
            print(f"  {row['section']:<7} {row['scenario']:<12} B={row['batch_size']:<5} "
                  f"{row['precision']}: {row.get('robot_steps_per_s', math.nan):12.0f} "
                  f"robot-steps/s, compile {row.get('compile_s', math.nan):6.2f} s", flush=True)

    for index, precision in enumerate(args.precisions):
        for jacobian in args.jacobians:
            for batch in args.batch_sizes:
                figures = measure([StarParams(gait=GAIT)] * batch, args.arch, precision,
                                  args.steps, args.repeats, profile_seconds, jacobian)
                add({"section": "batch", "scenario": "all_terms", "batch_size": batch,
                     "precision": precision, **figures})
        if index == 0:
            # while this precision's runtime is live (a precision switch re-initialises Taichi)
            for scenario in args.scenarios:
                params = [StarParams(gait=GAIT).replace(**SCENARIOS[scenario])] * args.scenario_batch
                figures = measure(params, args.arch, precision, args.steps, args.repeats,
                                  profile_seconds)
                add({"section": "skip", "scenario": scenario, "batch_size": args.scenario_batch,
                     "precision": precision, **figures})
    for workers in args.workers:
        for jacobian in args.jacobians:
            figures = measure_processes(args.process_batch, workers, jacobian, args.steps,
                                        args.repeats)
            add({"section": "processes", "scenario": "all_terms",
                 "batch_size": args.process_batch, "precision": "f64", **figures})
    if args.cache_probe:
        for precision in args.precisions:
            for label, figures in cache_probe(args.arch, precision, args.scenario_batch).items():
                add({"section": "compile", "scenario": label, "batch_size": args.scenario_batch,
                     "precision": precision, **figures})
    return pd.DataFrame(rows).reindex(columns=COLUMNS)


def plot_bench(csv_path, png_path):
    """Three panels from a bench CSV: throughput against B (log-log, one line per precision,
    the design §6 target dashed, real-time factor on the right axis); the phase split per
    instance-step of the B sweep; the scenarios' throughput."""
    plt = common.use_agg()
    table = pd.read_csv(csv_path, dtype={"commit": str})  # a hash like 83e1667 reads as a float
    arch = str(table["arch"].iloc[0])
    sweep = table[table["section"] == "batch"]
    skip = table[table["section"] == "skip"]
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.5), layout="constrained")
    fig.get_layout_engine().set(wspace=0.12)  # room for the real-time factor axis

    ax = axes[0]
    for (precision, jacobian), part in sweep.groupby(["precision", "jacobian"], sort=False):
        part = part.sort_values("batch_size")
        ax.plot(part["batch_size"], part["robot_steps_per_s"], "o-",
                label=f"{precision}, {jacobian}, in-process")
    processes = table[table["section"] == "processes"]
    for row in processes.to_dict("records"):
        ax.plot(row["batch_size"], row["robot_steps_per_s"], "s", markersize=8,
                label=f"simulate(workers={int(row['workers'])}), {row['jacobian']}, f64")
    target = TARGETS["cpu" if arch == "cpu" else "gpu"]
    ax.axhline(target, color="k", ls="--", lw=1,
               label=f"design §6 target {target:,.0f}/s")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("batch size B (instances)")
    ax.set_ylabel("robot-steps / s")
    dt = float(table["dt_s"].iloc[0])
    right = ax.secondary_yaxis("right", functions=(lambda s: s * dt, lambda r: r / dt))
    right.set_ylabel(f"real-time factor (h = {dt * 1e3:g} ms)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"{table['machine'].iloc[0]}, {arch}, {table['commit'].iloc[0]}", fontsize=8)

    phases = ["assembly_us", "factor_us", "solve_us", "bookkeeping_us"]
    # the phase split assumes one factorisation per Newton iteration: the newton mode only
    for ax, part, label in ((axes[1], sweep[sweep["jacobian"] == "newton"], "B={batch_size} {precision}"),
                            (axes[2], skip, "{scenario}\nB={batch_size} {precision}")):
        names = [label.format(**row) for row in part.to_dict("records")]
        bottom = np.zeros(len(part))
        for phase in phases:
            values = np.nan_to_num(part[phase].to_numpy(dtype=float).clip(min=0.0))
            ax.bar(names, values, bottom=bottom, label=phase.replace("_us", ""))
            bottom += values
        ax.set_ylabel("µs per instance-step (whole machine)")
        ax.tick_params(axis="x", labelrotation=60, labelsize=7)
        ax.grid(alpha=0.3, axis="y")
        ax.set_ylim(0.0, 1.15 * max(bottom.max(initial=0.0), 1e-9))
        for x, (total, rate) in enumerate(zip(bottom, part["robot_steps_per_s"])):
            ax.annotate(f"{rate:,.0f}/s", (x, total), ha="center", va="bottom", fontsize=6)
    axes[1].set_title("phase split of the B sweep (bar labels: robot-steps/s)", fontsize=8)
    axes[1].legend(fontsize=7)
    axes[2].set_title("skip what a scene does not need", fontsize=8)
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
    return png_path


def main(argv=None):
    args = parse_args(argv)
    out = common.out_dir(args)
    csv_path, png_path = output_paths(out, args.arch)
    table = run_bench(args)
    common.write_csv(table, csv_path)
    plot_bench(csv_path, png_path)
    print(common.describe([csv_path, png_path]))
    return table
