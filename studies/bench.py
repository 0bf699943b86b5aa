"""Throughput of the batch engine: robot-steps per second against batch size.

    python -m studies bench [--arch cpu|gpu] [--out DIR] [--quick]
                            [--batch-sizes 1,8,64,512,2048,8192] [--precisions f64,f32]
                            [--steps 100] [--repeats 3] [--scenarios all_terms,alpha_0,...|none]
                            [--scenario-batch 64] [--workers-list 1,2] [--no-cache-probe]
                            [--presets paper,accurate] [--accurate-duration 3.15]
                            [--gpu-block-dims 64] [--layouts instance_minor,instance_major]
                            [--kernel-optimisation on,off] [--lanes 1,8]
                            [--meshes 2,6,18,48,144,400]

Gait A1+A3, the paper's discretisation (N = 193 nodes), h = 1 ms, implicit Euler. For every batch
size B and precision: a fresh engine is compiled (its first launch, timed apart as `compile_s`),
then, `--repeats` times from rest, `WARMUP_STEPS` warm-up steps and `--steps` timed steps; the
fastest window counts (the others were disturbed by something else). The timed window starts at
t = 10 ms, inside the 150 ms heating pulse, where Newton needs the most iterations: the figures
are conservative against a whole-cycle average (`newton_iterations_mean` says how hard the
window was).

Phase split: after the timed windows, the engine's profiling kernel repeats, for every instance
at its current state, the residual's assembly alone, the assembly (residual and Jacobian),
assembly + factorisation, and assembly + factorisation + solve (the factorisation is in place,
so it always needs a fresh assembly); the differences give each phase's time per Newton
iteration, and the window's mean iterations and factorisations per step
(`newton_iterations_mean`, `factorisations_mean`; `profiling.step_phases`) µs per
instance-step; bookkeeping (predictor, convergence test, status, step loop) is the rest of the
measured step time. `residual_us` is the part of `assembly_us` that the residual alone costs
(what a chord iteration that keeps its factorisation assembles); the rest is the Jacobian's:
its derivatives and the clearing and scatter of its blocks. All times are wall-clock of the
whole machine divided by the instances processed (so they include the parallel speed-up over
cores); the profile repeats work on a state already in cache, so under noise or when
bookkeeping is small `bookkeeping_us` can come out slightly negative.

The B sweep runs for each Newton Jacobian mode (`jacobian`: "newton" refactors every
iteration, "chord" reuses the step's first LU while it contracts, so that its iterations
assemble the Jacobian and factor only `factorisations_mean` times a step); the plot shows the
"newton" rows' split. Section
"processes": the end-to-end throughput of `run_batch` on N local worker processes (one chunk
per worker) at one batch size, f64 (worker processes are how a machine with few cores is used:
Taichi's own CPU threads gained only ~1.25× on two cores).

Section "mesh" (`--meshes`, n_arc values; off by default): the benchmark robot on other meshes,
measured as the B sweep is at --scenario-batch instances (the first precision): what a step
costs against the robot's nodes (`n_nodes`), the rule the work estimates weigh a step by
(`timegrid.step_work`).

"Skip what a scene does not need": at one batch size, the same measurement with all terms and
with α = 0 (no jet), C_a = 0 (no added mass), drag 0 (rod and cylinder drag off), gait "none"
(no actuation); terms that no instance uses are compiled out (`terms`: the force terms the
engine was compiled with).

Preset "accurate" (`--presets`): the accurate model and solver (adaptive BDF2, N = 433) on the
same gait, `simulate` end to end for `--accurate-duration` simulated seconds from rest (default
one period) after one untimed call that compiles; `real_time_factor` is then simulated
robot-seconds per wall second and `robot_steps_per_s` counts the adaptive steps taken. Its phase
split profiles the same model on fixed steps (a Newton iteration costs the same), counted by
the adaptive run's own iterations and factorisations per accepted step, its rejected steps'
included.

GPU alternatives (`--arch gpu`): the B sweep is repeated for every threads-per-block count
(`--gpu-block-dims`) and layout of the per-instance fields (`--layouts`: instance_minor, the
same element of consecutive instances adjacent; instance_major, the CPU's layout), each a
compiled engine of its own. The memory-bound floor of an engine whose Newton matrix lives in
device memory: per Newton iteration the Jacobian blocks are written by the assembly, read and
written by the in-place LU and read by the solve (4 × n_slots 2×2 blocks), plus the node
vectors (`bytes_per_step`, at the window's mean iterations per step; Newton rows only: chord
skips some of it); `bandwidth_gb_s` is
measured on the same device by a Taichi copy kernel (bytes read + written) and
`bandwidth_fraction` = robot_steps_per_s × bytes_per_step / bandwidth.

Compiler settings (`--kernel-optimisation on,off`): the B sweep (and the accurate preset) is
repeated with Taichi's advanced IR optimisation on and off (`kernel_optimisation`), each a fresh
initialisation and compilation, so that one table shows what the passes cost to compile and
gain per step.

`final_state` is a hash of the final node positions (paper rows) or displacements (accurate
rows; the plain and sensitivities sections: displacements and their sensitivities): equal
hashes across settings show they computed the same bits.

Compile time with a cold and a warm Taichi offline cache: two fresh Python processes that share
an empty temporary cache folder (`TI_OFFLINE_CACHE_FILE_PATH`), the first compiles from scratch,
the second loads the first's kernels (section "compile"; off with --no-cache-probe and in
--quick).

Section "plain": the plain call a user writes, `simulate(params, duration)` with the default
SolverConfig, the five Fig. 4c gaits repeated to the process batch size, one whole period from
rest (pulse and coast: the B sweep's window is the hardest part of the pulse) (CPU; off with
--no-plain-call).

Section "sensitivities": the plain call at B = 64 over the pulse, differentiating by 0, 1, 2
and 4 parameters (`simulate(..., sensitivities=...)`; its cost against the same call without),
every count and Jacobian mode timed in the same rounds (`--repeats` of them, interleaved), and
each differentiating row's cost in runs of the forward call (Newton's Jacobian, no
sensitivities): `cost_in_forward_runs` (the ratio of the best calls) and
`cost_in_forward_runs_median` (the median of the rounds' ratios), and against the call of
its own Jacobian mode without sensitivities, `cost_in_own_forward_runs`.
Both sections run once per Jacobian mode of --plain-jacobians (default Newton's alone), the
modes' calls in the same rounds.
In both sections `time_to_first_step_s` is the first call's (one step, compilation included).

Writes `bench.csv` (`bench_gpu.csv` for --arch gpu): one row per measurement; `section` is
"batch" (B sweep), "skip" (terms at one B), "mesh" (n_arc at one B), "plain",
"sensitivities", "processes" or "compile" (cold/warm cache); columns: machine,
cpu_model, cores, gpu, gpu_driver, arch, preset, layout, block_dim, lanes (the CPU's vector
lanes per group of instances, `--lanes`), section, scenario, terms, batch_size, precision, n_nodes, dt_s,
gait, warmup_steps, steps, repeats, commit, timestamp, import_s, setup_s, compile_s,
time_to_first_step_s, robot_steps_per_s, real_time_factor (= robot_steps_per_s × dt: simulated
robot-seconds per wall second), step_us, newton_iterations_mean, factorisations_mean (per
step), assembly_us, residual_us (of assembly_us), factor_us, solve_us, bookkeeping_us (µs per
instance-step), factor_flops (per factorisation), factor_gflops (achieved by the factorisation; in an engine with lanes its phase includes the
copy of the group's systems into the lanes), matmul_gflops (NumPy's matrix product of
MATMUL_SIZE, quick: QUICK_MATMUL_SIZE, in the row's precision, best of three, timed just before
the row's engine: the machine's attainable rate in the same run; CPU paper rows only),
factor_fraction_of_matmul (their ratio), bytes_per_step, bandwidth_gb_s,
bandwidth_fraction, cost_in_forward_runs, cost_in_forward_runs_median,
cost_in_own_forward_runs, sensitivity_parameters (the sensitivities section; the parameters
differentiated by, space-separated). And `bench.png` (`bench_gpu.png`): throughput
against B (log-log, one line per precision, the design target dashed), the phase split and
the scenarios.
"""

import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from typing import List

import numpy as np
import pandas as pd

from taichi_star import STAR_RANGES, SolverConfig, StarParams, simulate
from taichi_star.batch import MAX_LOCAL_WORKERS, LocalProcesses, run_batch
from taichi_star.profiling import (EngineProfile, device_bandwidth, interleaved_rounds,
                                   matmul_gflops, step_phases)
from taichi_star.runtime import (CPU_LANES, GPU_BLOCK_DIM, GPU_INSTANCE_MINOR, Runtime,
                                 kernel_optimisation_default)

from . import cli, provenance

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
AUTO_LANES = "auto"
"""`--lanes` choice for the library's own (`Runtime.engine_lanes`); a row's `lanes` column holds
the lanes its engine had."""
QUICK_BATCH_SIZES = "2"
QUICK_STEPS = 5
QUICK_SCENARIO_BATCH = 2
ACCURATE_DURATION = 3.15
"""One period of the benchmark gait, s."""
# fixed steps of the accurate model whose Newton iterations the phase split profiles
ACCURATE_PHASE_STEPS = 20
PLAIN_DURATION = 3.15
"""Simulated seconds of the plain call (one period: the pulse and the coast)."""
SENSITIVITY_PARAMETERS = ("alpha", "drag_perpendicular", "youngs_modulus", "cylinder_drag")
"""What the sensitivities section differentiates by by default, the first n of them
(`--sensitivity-parameters`)."""
SENSITIVITY_BATCH = 64
"""Instances of the sensitivities section (the cost goal is stated at B = 64)."""
SENSITIVITY_DURATION = 0.3
"""Simulated seconds of the sensitivities section: the pulse and the start of the coast."""
MAX_DURATION = 100.0
"""The longest simulated time of one measurement, s (--plain-duration, --sensitivity-duration,
--accurate-duration): a measurement, not a run."""
MAX_STEPS = round(MAX_DURATION / DT)
"""The most timed steps per measurement (--steps): MAX_DURATION at h = DT."""
QUICK_SCENARIOS = "all_terms,added_mass_0"
"""--quick keeps to one engine (the smallest, as the other studies' quick batches use) and to
scenarios with the same terms, so that it compiles the stepping kernel at most once."""
PROFILE_SECONDS = 0.5
QUICK_PROFILE_SECONDS = 0.02
"""Target duration of one profiling launch, s: long enough to time, short next to the benchmark."""
MATMUL_SIZE = 1024
QUICK_MATMUL_SIZE = 256
"""n of the n × n NumPy matrix product timed before each paper row (`matmul_gflops`)."""
TARGETS = {"cpu": 40_000.0, "gpu": 2_000_000.0}
"""Throughput goals, robot-steps/s (2-core CPU at B >= 512, H100/H200 at B >= 8192)."""

SCENARIOS = {
    "all_terms": {},
    "alpha_0": {"alpha": 0.0},
    "added_mass_0": {"added_mass_coeff": 0.0},
    "drag_0": {"drag_parallel": 0.0, "drag_perpendicular": 0.0, "cylinder_drag": 0.0},
    "gait_none": {"gait": "none"},
    "wake": {"wake_coupling": 5.0, "wake_time": 1.0},
}
"""Scenario name -> StarParams changes from the benchmark robot (gait A1+A3, paper values)."""

LAYOUTS = ("instance_minor", "instance_major")
PHASES = ("residual", "assembly", "factor", "solve")
"""The parts of a Newton iteration `EngineProfile.phase_split` times (the residual is part of
the assembly)."""
PRESETS = ("paper", "accurate")

COLUMNS = ["machine", "cpu_model", "cores", "gpu", "gpu_driver", "arch", "preset", "layout",
           "block_dim", "lanes", "kernel_optimisation", "section", "scenario", "terms",
           "batch_size", "precision", "jacobian", "workers", "n_nodes", "dt_s", "gait",
           "warmup_steps", "steps", "repeats", "commit", "timestamp", "import_s", "setup_s",
           "compile_s", "time_to_first_step_s", "robot_steps_per_s", "real_time_factor",
           "step_us", "newton_iterations_mean", "factorisations_mean", "assembly_us",
           "residual_us", "factor_us", "solve_us",
           "bookkeeping_us", "factor_flops", "factor_gflops", "matmul_gflops",
           "factor_fraction_of_matmul", "bytes_per_step",
           "bandwidth_gb_s", "bandwidth_fraction", "cost_in_forward_runs",
           "cost_in_forward_runs_median", "cost_in_own_forward_runs", "sensitivity_parameters",
           "final_state"]


def timestamp() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- measurement

def bench_solver(precision: str, jacobian: str = "newton") -> SolverConfig:
    """The benchmark's solver: h = 1 ms, implicit Euler, the precision's default newton_tol
    (f32's is the tightest it accepts)."""
    return SolverConfig(dt=DT, precision=precision, jacobian=jacobian)


def on_off(flag: bool) -> str:
    """A compiler setting as the table and the flag spell it."""
    return "on" if flag else "off"


DISPLACEMENTS = ("displacement_x_mm", "displacement_y_mm")
"""The outputs whose values (and sensitivities) `measure_plains`'s digest covers."""


def state_digest(values: np.ndarray) -> str:
    """A short hash of an array's bytes: rows measured with different settings (compiler, layout)
    that computed the same bits carry the same digest."""
    return hashlib.sha1(np.ascontiguousarray(values).tobytes()).hexdigest()[:12]


def measure(params, arch: str, precision: str, steps: int, repeats: int,
            profile_seconds: float, jacobian: str = "newton") -> dict:
    """Throughput and phase split of one batch (see the module docstring): the best of
    `repeats` timed windows, each from rest after the warm-up steps; times in s, µs."""
    profile = EngineProfile(params, bench_solver(precision, jacobian), arch)
    compile_s, _ = profile.first_launch()
    timed = math.inf
    for _ in range(repeats):
        # the iterations are the same every repeat: the simulation is deterministic
        seconds, iterations, factorisations = profile.timed_window(WARMUP_STEPS, steps)
        timed = min(timed, seconds)
    final_state = state_digest(profile.positions())
    robot_steps = profile.batch_size * steps / timed
    step_us = 1e6 / robot_steps
    phase = profile.phase_split((WARMUP_STEPS + steps) * DT, timed / (steps * iterations),
                                profile_seconds)
    per_step = step_phases(phase, iterations, factorisations)
    residual, assembly, factor, solve = (per_step[name] for name in PHASES)
    flops = profile.factor_flops
    # the byte count assumes a fresh Jacobian and LU per iteration: Newton's rows only
    bytes_per_step = (iterations * profile.matrix_bytes_per_iteration()
                      if jacobian == "newton" else math.nan)
    return {"gait": params[0].gait, "jacobian": jacobian, "workers": 1, "lanes": profile.lanes,
            "preset": "paper", "bytes_per_step": bytes_per_step, "final_state": final_state,
            "terms": "+".join(profile.terms),
            "n_nodes": profile.n_nodes, "setup_s": profile.setup_s,
            "compile_s": compile_s,
            "robot_steps_per_s": robot_steps, "real_time_factor": robot_steps * DT,
            "step_us": step_us, "newton_iterations_mean": iterations,
            "factorisations_mean": factorisations, "assembly_us": assembly,
            "residual_us": residual, "factor_us": factor, "solve_us": solve,
            "bookkeeping_us": step_us - assembly - factor - solve, "factor_flops": flops,
            "factor_gflops": flops / (phase["factor"] * 1e3) if phase["factor"] > 0 else math.nan}


def accurate_phase_split(params, arch: str, precision: str, profile_seconds: float) -> dict:
    """µs per instance and Newton iteration of the residual, the assembly, the factorisation
    and the solve of the accurate model (its mesh and terms) on fixed BDF2 steps of DT with a
    fresh Jacobian every iteration, WARMUP_STEPS into the pulse (`EngineProfile.phase_split`):
    the adaptive run's iterations cost the same per iteration, and `step_phases` counts its
    chord iterations' fewer Jacobians and factorisations."""
    solver = SolverConfig.preset("accurate", precision=precision, adaptive=False, dt=DT,
                                 jacobian="newton")
    profile = EngineProfile(params, solver, arch)
    profile.first_launch()
    seconds, iterations, _ = profile.timed_window(WARMUP_STEPS, ACCURATE_PHASE_STEPS)
    return profile.phase_split((WARMUP_STEPS + ACCURATE_PHASE_STEPS) * DT,
                               seconds / (ACCURATE_PHASE_STEPS * iterations), profile_seconds)


def measure_accurate(batch: int, arch: str, precision: str, duration: float,
                     profile_seconds: float) -> dict:
    """End-to-end throughput of `simulate` with the accurate preset (model and solver) for
    `duration` simulated seconds from rest, after one untimed call of the same batch that
    compiles (its time less the timed call's is `compile_s`); the phase columns are
    `accurate_phase_split`'s per iteration, taken as many times per accepted step as the run
    iterated and factored (`step_phases`; rejected steps' solves included), bookkeeping the
    rest of the measured step (error estimate, step-size control, records)."""
    params = [StarParams.preset("accurate", gait=GAIT)] * batch
    solver = SolverConfig.preset("accurate", precision=precision)
    first = time.perf_counter()
    simulate(params, duration, solver=solver, arch=arch, progress=False)
    first = time.perf_counter() - first
    start = time.perf_counter()
    result = simulate(params, duration, solver=solver, arch=arch, progress=False)
    timed = time.perf_counter() - start
    summary = result.summary
    if (summary["status"] != "ok").any():
        raise RuntimeError("an instance failed during the benchmark: its timing is not valid")
    steps = float(summary["steps"].sum())
    step_us = 1e6 * timed / steps
    # an adaptive run solves every step it tries once: the accepted and the rejected
    solves = summary["steps"] + summary["rejected_steps"]
    iterations = float((summary["newton_iterations_mean"] * solves).sum() / steps)
    factorisations = float((summary["factorisations_mean"] * solves).sum() / steps)
    phase = accurate_phase_split(params, arch, precision, profile_seconds)
    per_step = step_phases(phase, iterations, factorisations)
    residual, assembly, factor, solve = (per_step[name] for name in PHASES)
    return {"gait": GAIT, "preset": "accurate", "jacobian": solver.jacobian, "workers": 1,
            "lanes": Runtime.current().engine_lanes(batch, solver),
            "n_nodes": result.topology.n_nodes,
            "compile_s": max(first - timed, 0.0), "robot_steps_per_s": steps / timed,
            "real_time_factor": batch * duration / timed, "step_us": step_us,
            "newton_iterations_mean": iterations, "factorisations_mean": factorisations,
            "assembly_us": assembly, "residual_us": residual, "factor_us": factor,
            "solve_us": solve, "bookkeeping_us": step_us - assembly - factor - solve,
            "final_state": state_digest(summary[["displacement_x_mm", "displacement_y_mm"]]
                                        .to_numpy())}


def best_of_calls(call, repeats: int, warmup=None):
    """(result of `call()`, best wall time (s) of `repeats` calls, wall time (s) of the
    `warmup()` (default: `call()`) before them, which starts and compiles what they need).
    Raises if an instance failed (the timing would not be valid)."""
    results, times, firsts = interleaved_calls([call], repeats, [warmup])
    return results[0], times[:, 0].min(), firsts[0]


def interleaved_calls(calls, repeats: int, warmups):
    """`profiling.interleaved_rounds` of `calls` (each a `simulate` or `run_batch`), `repeats`
    rounds after `warmups` (None: the call itself): (the last result of each call, wall times
    (s) as a (repeats, len(calls)) array, each warm-up's wall time (s)). Raises if an instance
    failed (the timing would not be valid)."""
    results, times, firsts = interleaved_rounds(calls, repeats, warmups)
    for result in results:
        if (result.summary["status"] != "ok").any():
            raise RuntimeError("an instance failed during the benchmark: its timing is not "
                               "valid")
    return results, times, firsts


def end_to_end_figures(result, robot_steps: float, timed: float) -> dict:
    """Throughput columns of an end-to-end call that advanced robot_steps in timed s."""
    rate = robot_steps / timed
    return {"newton_iterations_mean": float(result.summary["newton_iterations_mean"].mean()),
            "factorisations_mean": float(result.summary["factorisations_mean"].mean()),
            "robot_steps_per_s": rate, "real_time_factor": rate * DT, "step_us": 1e6 / rate}


def measure_processes(batch: int, workers: int, jacobian: str, steps: int, repeats: int) -> dict:
    """End-to-end throughput of `run_batch` on `workers` local worker processes, one chunk each
    (f64, CPU): the best of `repeats` calls of WARMUP_STEPS + steps steps from rest, after one
    call that starts the processes and compiles their engines; includes splitting the batch,
    the transfers and building the tables."""
    params = [StarParams(gait=GAIT)] * batch
    solver = bench_solver("f64", jacobian)
    duration = (WARMUP_STEPS + steps) * DT
    chunk = math.ceil(batch / workers)
    with LocalProcesses(workers) as executor:
        result, timed, _ = best_of_calls(lambda: run_batch(
            params, duration, solver=solver, chunk_size=chunk, executor=executor), repeats)
    return {"gait": GAIT, "jacobian": jacobian, "workers": workers,
            **end_to_end_figures(result, batch * (WARMUP_STEPS + steps), timed)}


def measure_plains(batch: int, duration: float, repeats: int, configurations) -> list:
    """End-to-end throughput of the plain call a user writes, `simulate(params, duration)`, in
    this process, for each (sensitivities, jacobian) of `configurations` (parameter names the
    call differentiates by, and the SolverConfig's Jacobian mode): the five Fig. 4c gaits
    repeated to `batch` instances from rest, one call of each (one step) that compiles its
    engine, then `repeats` rounds timing every configuration's call once in turn
    (`interleaved_calls`); each figure is its configuration's best call (the robot-steps
    counted are the instances', not their replicas'). `time_to_first_step_s` is that first
    call's: the engine's compilation where this process has not built one of its size and kind
    before (the sections run in order), its loading and a step; `final_state` a digest of the
    displacements and of their sensitivities. A configuration differentiating by parameters
    also gets its cost in runs of the forward call, Newton's Jacobian and no sensitivities,
    where that is among `configurations`: `cost_in_forward_runs` (the ratio of the best calls)
    and `cost_in_forward_runs_median` (the median over the rounds of each round's ratio); and
    `cost_in_own_forward_runs`, the ratio of its best call to that of the call with its own
    Jacobian mode and no sensitivities, where that is among them."""
    params = cli.paper_gaits_batch(batch)
    steps = round(duration / DT)
    calls, warmups = [], []
    for sensitivities, jacobian in configurations:
        solver = SolverConfig(jacobian=jacobian)
        calls.append(lambda solver=solver, names=sensitivities: simulate(
            params, duration, solver, sensitivities=names, progress=False))
        warmups.append(lambda solver=solver, names=sensitivities: simulate(
            params, DT, solver, sensitivities=names, progress=False))
    results, times, firsts = interleaved_calls(calls, repeats, warmups)
    forward = {jacobian: index for index, (names, jacobian) in enumerate(configurations)
               if not names}
    best = times.min(axis=0)
    rows = []
    for index, ((sensitivities, jacobian), result) in enumerate(zip(configurations, results)):
        row = {"gait": "paper_gaits", "jacobian": jacobian, "workers": 1,
               "n_nodes": result.topology.n_nodes, "steps": steps,
               "time_to_first_step_s": firsts[index],
               "final_state": state_digest(np.column_stack(
                   [result.summary[output].to_numpy() for output in DISPLACEMENTS]
                   + [result.sensitivity(output, name) for output in DISPLACEMENTS
                      for name in sensitivities])),
               **end_to_end_figures(result, batch * steps, best[index])}
        if sensitivities and "newton" in forward:
            row["cost_in_forward_runs"] = best[index] / best[forward["newton"]]
            row["cost_in_forward_runs_median"] = float(np.median(
                times[:, index] / times[:, forward["newton"]]))
        if sensitivities and jacobian in forward:
            row["cost_in_own_forward_runs"] = best[index] / best[forward[jacobian]]
        rows.append(row)
    return rows


PROBE_CODE = f"""
import json, sys, time
start = time.perf_counter()
import {__name__} as bench
imported = time.perf_counter() - start
print("BENCH_PROBE " + json.dumps(bench.first_step_probe(sys.argv[1], sys.argv[2],
                                                          int(sys.argv[3]), imported)))
"""


def first_step_probe(arch: str, precision: str, batch_size: int, import_s: float) -> dict:
    """In a fresh process: setup (Taichi init, engine, load) and the first launch of a batch,
    split into compile and step by timing a second launch. Times in s."""
    profile = EngineProfile([StarParams(gait=GAIT)] * batch_size, bench_solver(precision), arch)
    compile_s, first = profile.first_launch()
    return {"gait": GAIT, "import_s": import_s, "setup_s": profile.setup_s, "compile_s": compile_s,
            "time_to_first_step_s": import_s + profile.setup_s + first}


def import_path() -> str:
    """A PYTHONPATH under which a fresh process imports what this one imports, from the same
    places: this process's own sys.path (the empty entry as the current folder). The probe had
    put the folder above its own file on PYTHONPATH, which installed is the taichi_star package
    folder itself (its modules importable as top-level names: an audit, 2026-12)."""
    return os.pathsep.join(os.path.abspath(entry or os.curdir) for entry in sys.path)


def cache_probe(arch: str, precision: str, batch_size: int) -> dict:
    """{"cold_cache": probe, "warm_cache": probe}: two fresh processes sharing an empty
    temporary Taichi offline cache, so the first compiles everything and the second reuses it."""
    results = {}
    with tempfile.TemporaryDirectory(prefix="taichi_star_cache_") as cache:
        env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=cache, PYTHONPATH=import_path())
        for label in ("cold_cache", "warm_cache"):
            run = subprocess.run([sys.executable, "-c", PROBE_CODE, arch, precision,
                                  str(batch_size)], env=env, capture_output=True, text=True)
            lines = [line for line in run.stdout.splitlines() if line.startswith("BENCH_PROBE ")]
            if run.returncode != 0 or not lines:
                raise RuntimeError(f"compile probe ({label}) failed:\n{run.stderr[-2000:]}")
            results[label] = json.loads(lines[-1].split(" ", 1)[1])
    return results


# --------------------------------------------------------------------------- CLI

def build_parser():
    parser = cli.StudyParser("bench", DESCRIPTION)
    parser.add_argument("--batch-sizes", default=DEFAULT_BATCH_SIZES, quick=QUICK_BATCH_SIZES,
                        help=f"comma list of batch sizes B, each in [1, {cli.MAX_BATCH_SIZE}]")
    parser.add_argument("--precisions", default="f64,f32", quick="f64",
                        help="comma list of f64, f32")
    parser.add_argument("--steps", type=int, default=DEFAULT_STEPS, quick=QUICK_STEPS,
                        help=f"timed steps per measurement, after {WARMUP_STEPS} warm-up steps, "
                             f"at most {MAX_STEPS}")
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS, quick=1,
                        help=f"timed windows per measurement, the best counts (at most "
                             f"{cli.MAX_REPEATS})")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS), quick=QUICK_SCENARIOS,
                        help=f"comma list of {', '.join(SCENARIOS)} measured at the scenario "
                             f"batch size in the first precision, or none")
    parser.add_argument("--meshes", default="none", quick="none",
                        help="comma list of n_arc for the mesh section (the benchmark robot on "
                             "other meshes at --scenario-batch instances, the first precision), "
                             "or none to skip it")
    parser.add_argument("--scenario-batch", type=int, default=SCENARIO_BATCH,
                        quick=QUICK_SCENARIO_BATCH,
                        help=f"batch size of the scenarios, at most {cli.MAX_BATCH_SIZE}")
    parser.add_argument("--jacobians", default="newton,chord", quick="newton",
                        help="comma list of newton, chord, lagged for the B sweep and the "
                             "processes section")
    parser.add_argument("--workers-list", default="1,2", quick="none",
                        help=f"comma list of worker-process counts (each at most "
                             f"{MAX_LOCAL_WORKERS}) for the end-to-end processes section, or "
                             f"none")
    parser.add_argument("--process-batch", type=int, default=PROCESS_BATCH, quick=2,
                        help=f"batch size of the processes and plain sections, at most "
                             f"{cli.MAX_BATCH_SIZE}")
    parser.add_argument("--no-plain-call", dest="plain_call", action="store_false",
                        help="skip the plain section: simulate(params, duration) with the "
                             "default solver at the process batch size (CPU)")
    parser.add_argument("--plain-jacobians", default="newton", quick="newton",
                        help="comma list of Jacobian modes of the plain call and the "
                             "sensitivities sections: newton (SolverConfig's own), chord, "
                             "lagged (opt-in: kept across steps)")
    parser.add_argument("--plain-duration", type=float, default=PLAIN_DURATION,
                        quick=(WARMUP_STEPS + QUICK_STEPS) * DT,
                        help="simulated seconds of the plain call (one period)")
    parser.add_argument("--sensitivity-counts", default="0,1,2,4", quick="none",
                        help=f"comma list of how many of --sensitivity-parameters (the first n) "
                             f"the plain call differentiates by, at B = {SENSITIVITY_BATCH} (0: "
                             f"none, the baseline), or none to skip the section")
    parser.add_argument("--sensitivity-parameters", default=",".join(SENSITIVITY_PARAMETERS),
                        help="comma list of the parameters the sensitivities section "
                             "differentiates by, in order, as simulate(sensitivities=...) names "
                             "them (actuator_gains[1]: A2's gain; actuator_gains: all eight, "
                             "in actuator order), or all; --sensitivity-counts counts them one "
                             "number each")
    parser.add_argument("--sensitivity-duration", type=float, default=SENSITIVITY_DURATION,
                        help=f"simulated seconds of the sensitivities section (default "
                             f"{SENSITIVITY_DURATION} s: the pulse)")
    parser.add_argument("--presets", default="paper", quick="paper",
                        help="comma list of paper (fixed 1-ms Euler steps, the B sweep) and "
                             "accurate (adaptive, simulate end to end at the same B)")
    parser.add_argument("--accurate-duration", type=float, default=ACCURATE_DURATION,
                        help="simulated seconds per accurate measurement (default one period, "
                             f"{ACCURATE_DURATION} s)")
    parser.add_argument("--gpu-block-dims", default=str(GPU_BLOCK_DIM),
                        help="comma list of threads per GPU block (powers of two up to 1024), "
                             "--arch gpu only")
    parser.add_argument("--layouts", default="instance_minor" if GPU_INSTANCE_MINOR else
                        "instance_major",
                        help=f"comma list of {', '.join(LAYOUTS)}: the GPU layout of the "
                             "per-instance fields, --arch gpu only")
    parser.add_argument("--lanes", default=AUTO_LANES,
                        help="comma list of auto, 1, 2, 4, 8, 16: instances whose Newton systems "
                             "the CPU factors and solves together in vector lanes, for the B "
                             "sweep and the plain call (default auto: the library's choice, "
                             f"{CPU_LANES} where they pay, else 1); --arch cpu only")
    parser.add_argument("--kernel-optimisation",
                        default=on_off(kernel_optimisation_default()),
                        help="comma list of on, off: Taichi's advanced IR optimisation for the "
                             "B sweep (default: the library's setting)")
    parser.add_argument("--no-cache-probe", action="store_true",
                        help="skip the cold/warm offline-cache compile probe (two subprocesses; "
                             "skipped by --quick)")
    return parser


def solver_choices(text: str, flag: str, field: str):
    """A comma list of SolverConfig values of `field`, each checked by SolverConfig itself."""
    values = cli.parse_values(text, flag, str)
    for value in values:
        try:
            bench_solver(**{"precision": "f64", field: value})
        except ValueError as error:
            raise cli.StudyArgumentError(f"{flag}: {error}") from None
    return values


def parse_sensitivity_counts(text: str, flag: str, parameters: List[str]):
    """Comma list of parameter counts in [0, len(parameters)]."""
    counts = cli.parse_values(text, flag, int)
    for count in counts:
        if not 0 <= count <= len(parameters):
            raise cli.StudyArgumentError(f"{flag}: each count must be in [0, "
                                         f"{len(parameters)}] (--sensitivity-parameters), "
                                         f"got {count}")
    return counts


def optional_list(text: str, flag: str, parse):
    return [] if text.strip().lower() == "none" else parse(text, flag)


def parse_meshes(text: str, flag: str) -> List[int]:
    """A comma list of n_arc values, each within StarParams' range for n_arc."""
    lowest, highest, _ = STAR_RANGES["n_arc"]
    values = cli.parse_counts(text, flag, highest)
    if min(values) < lowest:
        raise cli.StudyArgumentError(f"{flag}: every n_arc must be in [{lowest}, {highest}], "
                                     f"got {min(values)}")
    return values


def parse_args(argv):
    """Parsed and validated arguments (StudyArgumentError before any computation)."""
    args = cli.parse(build_parser(), argv)
    args.batch_sizes = cli.parse_counts(args.batch_sizes, "--batch-sizes", cli.MAX_BATCH_SIZE)
    args.precisions = solver_choices(args.precisions, "--precisions", "precision")
    args.jacobians = solver_choices(args.jacobians, "--jacobians", "jacobian")
    args.plain_jacobians = solver_choices(args.plain_jacobians, "--plain-jacobians", "jacobian")
    args.scenarios = optional_list(args.scenarios, "--scenarios",
                                   lambda text, flag: cli.parse_choices(text, flag, SCENARIOS))
    args.meshes = optional_list(args.meshes, "--meshes", parse_meshes)
    args.workers_list = optional_list(
        args.workers_list, "--workers-list",
        lambda text, flag: cli.parse_counts(text, flag, MAX_LOCAL_WORKERS))
    # the bench's robot has the 2.5-D model off: "all" leaves the component heights out
    args.sensitivity_parameters = cli.sensitivity_parameters(
        args.sensitivity_parameters, "--sensitivity-parameters", heights="without")
    args.sensitivity_counts = optional_list(
        args.sensitivity_counts, "--sensitivity-counts",
        lambda text, flag: parse_sensitivity_counts(text, flag, args.sensitivity_parameters))
    args.presets = cli.parse_choices(args.presets, "--presets", PRESETS)
    args.layouts = cli.parse_choices(args.layouts, "--layouts", LAYOUTS)
    args.gpu_block_dims = cli.parse_counts(args.gpu_block_dims, "--gpu-block-dims")
    args.kernel_optimisation = [choice == "on" for choice in cli.parse_choices(
        args.kernel_optimisation, "--kernel-optimisation", ("on", "off"))]
    args.lanes = [None if choice == AUTO_LANES else int(choice) for choice in cli.parse_choices(
        args.lanes, "--lanes", (AUTO_LANES, "1", "2", "4", "8", "16"))]
    if args.arch != "cpu" and args.lanes != [None]:
        raise cli.StudyArgumentError("--lanes compares CPU settings; run it with --arch cpu")
    for block_dim in args.gpu_block_dims:
        if block_dim > 1024 or block_dim & (block_dim - 1):
            raise cli.StudyArgumentError(f"--gpu-block-dims: each must be a power of two up to "
                                         f"1024, got {block_dim}")
    if args.arch == "cpu" and (len(args.layouts) > 1 or len(args.gpu_block_dims) > 1):
        raise cli.StudyArgumentError("--layouts and --gpu-block-dims compare GPU settings; "
                                     "use them with --arch gpu")
    if not (0.0 < args.accurate_duration <= MAX_DURATION):
        raise cli.StudyArgumentError(f"--accurate-duration must be in (0, {MAX_DURATION:g}] s, "
                                     f"got {args.accurate_duration}")
    for flag in ("plain_duration", "sensitivity_duration"):  # fixed steps of DT
        if not (DT <= getattr(args, flag) <= MAX_DURATION):
            raise cli.StudyArgumentError(f"--{flag.replace('_', '-')} must be in [{DT:g}, "
                                         f"{MAX_DURATION:g}] s, got {getattr(args, flag)}")
    cli.check_count(args.repeats, "--repeats", 1, cli.MAX_REPEATS)
    for flag, highest in (("steps", MAX_STEPS), ("scenario_batch", cli.MAX_BATCH_SIZE),
                          ("process_batch", cli.MAX_BATCH_SIZE)):
        cli.check_count(getattr(args, flag), f"--{flag.replace('_', '-')}", 1, highest)
    if args.workers_list and args.arch != "cpu":
        raise cli.StudyArgumentError("--workers-list: worker processes run on the CPU; use "
                                     "--workers-list none with --arch gpu")
    # the batch section's work, before any of it: every batch size, warm-up and --steps,
    # --repeats times, for each preset, precision, Jacobian and lanes setting (each flag within
    # its range, 1,048,576 robots × 100,000 steps × 100 repeats started silently: an audit,
    # 2026-12); the other sections are smaller
    settings = len(args.presets) * len(args.precisions) * len(args.jacobians) * len(args.lanes)
    cli.check_steps(f"the batch section (--batch-sizes summing to {sum(args.batch_sizes):,} "
                    f"robots, {WARMUP_STEPS} warm-up + --steps {args.steps}, --repeats "
                    f"{args.repeats}, {settings} setting(s))",
                    (WARMUP_STEPS + args.steps) * args.repeats * settings, sum(args.batch_sizes),
                    cli.work_arch(args),
                    np.mean([StarParams.preset(preset).n_nodes for preset in args.presets]))
    if args.meshes:  # the mesh section's robots weigh their nodes (`timegrid.step_work`)
        cli.check_steps(f"the mesh section (--meshes {len(args.meshes)} n_arc value(s) × "
                        f"--scenario-batch {args.scenario_batch} robots, {WARMUP_STEPS} warm-up + "
                        f"--steps {args.steps}, --repeats {args.repeats})",
                        (WARMUP_STEPS + args.steps) * args.repeats * len(args.meshes),
                        args.scenario_batch, cli.work_arch(args),
                        np.mean([StarParams.node_count(n_arc, StarParams().n_limb)
                                 for n_arc in args.meshes]))
    args.cache_probe = not (args.no_cache_probe or args.quick)
    return args


def output_names(arch: str):
    """(csv, png) names for the arch: bench.* on the CPU, bench_gpu.* on a GPU."""
    stem = "bench" if arch == "cpu" else "bench_gpu"
    return f"{stem}.csv", f"{stem}.png"


def run_bench(args, on_table=None) -> pd.DataFrame:
    """Every measurement of the parsed arguments as one table (columns `COLUMNS`);
    `on_table(table)`, if given, receives the table so far after every measurement (so that a
    run stopped by a time limit keeps what it measured)."""
    base = {**provenance.machine_columns(args.arch), "arch": args.arch, "dt_s": DT,
            "warmup_steps": WARMUP_STEPS, "steps": args.steps,
            "repeats": args.repeats, "commit": provenance.short_commit(),
            "kernel_optimisation": on_off(kernel_optimisation_default())}
    profile_seconds = QUICK_PROFILE_SECONDS if args.quick else PROFILE_SECONDS
    rows = []

    def add(row):
        rows.append({**base, **row, "timestamp": timestamp()})
        if on_table is not None:
            on_table(pd.DataFrame(rows).reindex(columns=COLUMNS))
        if not args.no_progress:
            row = rows[-1]
            print(f"  {row['section']:<7} {row['scenario']:<12} {row.get('preset', ''):<8} "
                  f"{row.get('layout', '')} {row.get('block_dim', '')} "
                  f"{row.get('jacobian', '')} B={row['batch_size']:<5} {row['precision']}: "
                  f"{row.get('robot_steps_per_s', math.nan):12.0f} robot-steps/s, "
                  f"{row.get('real_time_factor', math.nan):10.1f} robot-s/s, "
                  f"compile {row.get('compile_s', math.nan):6.2f} s", flush=True)

    gpu = args.arch != "cpu"
    settings = [(layout, block_dim) for layout in args.layouts for block_dim in args.gpu_block_dims]
    compilers = [(optimise, precision) for optimise in args.kernel_optimisation
                 for precision in args.precisions]
    for index, (optimise, precision) in enumerate(compilers):
        Runtime.current().configure_compiler(optimise)
        bandwidth = device_bandwidth(args.arch, precision) if gpu else math.nan
        for layout, block_dim, lanes in ([(*setting, 1) for setting in settings] if gpu else
                                         [("instance_major", 1, lanes) for lanes in args.lanes]):
            if gpu:
                Runtime.current().configure_gpu(block_dim, layout == "instance_minor")
            else:
                Runtime.current().configure_lanes(lanes)
            place = {"layout": layout, "block_dim": block_dim,
                     "bandwidth_gb_s": bandwidth, "kernel_optimisation": on_off(optimise)}
            if "paper" in args.presets:
                for jacobian in args.jacobians:
                    for batch in args.batch_sizes:
                        matmul = math.nan if gpu else matmul_gflops(
                            QUICK_MATMUL_SIZE if args.quick else MATMUL_SIZE, precision,
                            np.random.default_rng(0))
                        figures = measure([StarParams(gait=GAIT)] * batch, args.arch, precision,
                                          args.steps, args.repeats, profile_seconds, jacobian)
                        moved = figures["robot_steps_per_s"] * figures["bytes_per_step"]
                        add({"section": "batch", "scenario": "all_terms", "batch_size": batch,
                             "precision": precision, **place, **figures,
                             "matmul_gflops": matmul,
                             "factor_fraction_of_matmul": figures["factor_gflops"] / matmul,
                             "bandwidth_fraction": moved / (bandwidth * 1e9)})
            if "accurate" in args.presets:
                for batch in args.batch_sizes:
                    figures = measure_accurate(batch, args.arch, precision, args.accurate_duration,
                                               profile_seconds)
                    add({"section": "batch", "scenario": "all_terms", "batch_size": batch,
                         "precision": precision, **place, **figures})
        Runtime.current().configure_lanes()
        if index == 0:
            # while this precision's runtime is live (a precision switch re-initialises Taichi)
            if gpu:
                Runtime.current().configure_gpu()
            for scenario in args.scenarios:
                params = [StarParams(gait=GAIT).replace(**SCENARIOS[scenario])] * args.scenario_batch
                figures = measure(params, args.arch, precision, args.steps, args.repeats,
                                  profile_seconds)
                add({"section": "skip", "scenario": scenario, "batch_size": args.scenario_batch,
                     "precision": precision, "kernel_optimisation": on_off(optimise),
                     **figures})
            for n_arc in args.meshes:
                figures = measure([StarParams(gait=GAIT, n_arc=n_arc)] * args.scenario_batch,
                                  args.arch, precision, args.steps, args.repeats, profile_seconds)
                add({"section": "mesh", "scenario": f"n_arc_{n_arc}",
                     "batch_size": args.scenario_batch, "precision": precision,
                     "kernel_optimisation": on_off(optimise), **figures})
    Runtime.current().configure_compiler()
    if args.plain_call and not gpu:
        for lanes in args.lanes:
            Runtime.current().configure_lanes(lanes)
            measured = measure_plains(args.process_batch, args.plain_duration, args.repeats,
                                      [((), jacobian) for jacobian in args.plain_jacobians])
            for jacobian, figures in zip(args.plain_jacobians, measured):
                add({"section": "plain", "scenario": "all_terms", "preset": "paper",
                     "batch_size": args.process_batch, "precision": "f64", **figures,
                     "lanes": Runtime.current().engine_lanes(
                         args.process_batch, SolverConfig(jacobian=jacobian),
                         robot_steps=args.process_batch * figures["steps"])})
        Runtime.current().configure_lanes()
    configurations = [(args.sensitivity_parameters[:count], jacobian)
                      for count in args.sensitivity_counts for jacobian in args.plain_jacobians]
    if configurations:
        # every count and Jacobian timed in the same rounds: their costs are ratios of calls
        # made minutes apart otherwise, and this machine's speed drifts by 20 % in that time
        measured = measure_plains(SENSITIVITY_BATCH, args.sensitivity_duration, args.repeats,
                                  configurations)
        for (names, _), figures in zip(configurations, measured):
            add({"section": "sensitivities", "scenario": f"sensitivities_{len(names)}",
                 "preset": "paper", "batch_size": SENSITIVITY_BATCH, "precision": "f64",
                 "sensitivity_parameters": " ".join(names), **figures})
    for workers in args.workers_list:
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


def phase_bars(rows: pd.DataFrame, label: str):
    """The stacked bars of a phase-split panel from bench rows: (the rows kept, their names
    (`label` formatted with each row), {phase: µs per instance-step}). Of the rounds of one
    setting the fastest is kept; the assembly is split into the residual and the Jacobian
    where every row has `residual_us` (tables from before it show the assembly whole)."""
    part = rows.sort_values("robot_steps_per_s").drop_duplicates(
        ["scenario", "batch_size", "precision", "jacobian", "preset", "lanes",
         "kernel_optimisation", "layout", "block_dim"], keep="last").sort_index()
    names = [label.format(**row) for row in part.to_dict("records")]
    split = {"assembly": part["assembly_us"]}
    if "residual_us" in part and part["residual_us"].notna().all():
        split = {"residual": part["residual_us"],
                 "Jacobian": part["assembly_us"] - part["residual_us"]}
    split.update(factor=part["factor_us"], solve=part["solve_us"],
                 bookkeeping=part["bookkeeping_us"])
    return part, names, split


def lanes_note(lanes) -> str:
    """", 8 lanes" for a row that grouped its instances in lanes, "" for one instance at a time
    (1, or "" in a table from before the setting)."""
    return f", {int(lanes)} lanes" if lanes not in ("", 1) else ""


def plot_bench(csv_path, png_path):
    """Three panels from a bench CSV: throughput against B (log-log, one line per precision,
    the target dashed, real-time factor on the right axis); the phase split per
    instance-step of the B sweep; that of the scenarios and the other meshes."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path, dtype={"commit": str})  # a hash like 83e1667 reads as a float
    if "kernel_optimisation" not in table:
        table["kernel_optimisation"] = "on"  # tables from before the setting: the passes ran
    if "lanes" not in table:
        table["lanes"] = 1  # tables from before the setting: one instance at a time
    compilers = table["kernel_optimisation"].dropna().unique()
    arch = str(table["arch"].iloc[0])
    sweep = table[table["section"] == "batch"]
    # the scenarios and the meshes: each at --scenario-batch, the same split per instance-step
    skip = table[table["section"].isin(["skip", "mesh"])]
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.5), layout="constrained")
    fig.get_layout_engine().set(wspace=0.12)  # room for the real-time factor axis

    ax = axes[0]
    lines = ["precision", "jacobian", "preset", "layout", "block_dim", "kernel_optimisation",
             "lanes"]
    sweep = sweep.assign(**{name: sweep[name].fillna("") for name in lines})
    for key, part in sweep[sweep["preset"] != "accurate"].groupby(lines, sort=False):
        precision, jacobian, _, layout, block_dim, optimise, lanes = key
        # rounds of the same setting: the fastest counts, as within a measurement
        best = part.groupby("batch_size")["robot_steps_per_s"].max()
        place = (f", {layout}, {int(block_dim)}/block" if arch != "cpu"
                 else f", in-process{lanes_note(lanes)}")
        compiler = f", IR optimisation {optimise}" if len(compilers) > 1 else ""
        ax.plot(best.index, best.to_numpy(), "o-",
                label=f"{precision}, {jacobian}{place}{compiler}")
    processes = table[table["section"] == "processes"]
    for row in processes.to_dict("records"):
        ax.plot(row["batch_size"], row["robot_steps_per_s"], "s", markersize=8,
                label=f"{int(row['workers'])} worker processes, {row['jacobian']}, f64")
    target = TARGETS["cpu" if arch == "cpu" else "gpu"]
    ax.axhline(target, color="k", ls="--", lw=1,
               label=f"target {target:,.0f}/s")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("batch size B (instances)")
    ax.set_ylabel("robot-steps / s")
    dt = float(table["dt_s"].iloc[0])
    right = ax.secondary_yaxis("right", functions=(lambda s: s * dt, lambda r: r / dt))
    right.set_ylabel(f"real-time factor (h = {dt * 1e3:g} ms)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    if sweep[sweep["preset"] != "accurate"].empty and processes.empty:
        ax.text(0.5, 0.5, "no paper-preset B sweep in this run\n(the accurate preset's steps vary "
                "in size: its rows are in the phase split)", ha="center", va="center",
                fontsize=8, transform=ax.transAxes)
    ax.set_title(f"{table['machine'].iloc[0]}, {arch}, {table['commit'].iloc[0]}", fontsize=8)

    # the split takes the Jacobian and its factorisation as often as they happen (profiling.
    # step_phases), so every Jacobian mode and preset has one; tables from before the residual
    # was timed apart show the assembly whole (phase_bars)
    split_label = ("B={batch_size} {precision} {jacobian}{preset_note}{lanes_note}"
                   + (" opt {kernel_optimisation}" if len(compilers) > 1 else ""))
    sweep = sweep.assign(
        preset_note=np.where(sweep["preset"] == "accurate", " accurate", ""),
        lanes_note=[lanes_note(lanes) for lanes in sweep["lanes"]])
    split_rows = sweep
    if "factorisations_mean" not in table:
        # tables from before the factorisations were counted charged one to every iteration:
        # right for Newton's fixed steps only
        split_rows = sweep[(sweep["jacobian"] == "newton") & (sweep["preset"] != "accurate")]
    for ax, part, label in ((axes[1], split_rows, split_label),
                            (axes[2], skip, "{scenario}\nB={batch_size} {precision}")):
        part, names, split = phase_bars(part, label)
        bottom = np.zeros(len(part))
        for phase, column in split.items():
            values = np.nan_to_num(column.to_numpy(dtype=float).clip(min=0.0))
            ax.bar(names, values, bottom=bottom, label=phase)
            bottom += values
        ax.set_ylabel("µs per instance-step (whole machine)")
        ax.tick_params(axis="x", labelrotation=60, labelsize=7)
        ax.grid(alpha=0.3, axis="y")
        ax.set_ylim(0.0, 1.15 * max(bottom.max(initial=0.0), 1e-9))
        for x, (total, rate) in enumerate(zip(bottom, part["robot_steps_per_s"])):
            ax.annotate(f"{rate:,.0f}/s", (x, total), ha="center", va="bottom", fontsize=6)
    axes[1].set_title("phase split of the B sweep (bar labels: robot-steps/s)", fontsize=8)
    axes[1].legend(fontsize=7)
    axes[2].set_title("skip what a scene does not need; other meshes (n_arc)", fontsize=8)
    if skip.empty:
        axes[2].text(0.5, 0.5, "no scenarios or meshes in this run", ha="center", va="center",
                     transform=axes[2].transAxes)
        axes[2].set_axis_off()
    cli.write_figure(fig, png_path, dpi=120)
    plt.close(fig)
    return png_path


def main(argv=None):
    args = parse_args(argv)
    out = cli.Output(args, argv or [], model={"gait": GAIT, "scenarios": SCENARIOS},
                     solver={precision: bench_solver(precision) for precision in args.precisions})
    csv_name, png_name = output_names(args.arch)
    table = run_bench(args, on_table=lambda partial: out.write_csv(partial, csv_name))
    csv_path = out.write_csv(table, csv_name)
    out.wrote(plot_bench(csv_path, out.path(png_name)))
    out.report()
    return table
