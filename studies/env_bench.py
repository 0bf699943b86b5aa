"""Throughput of the vector environment: simulated robot-seconds per wall second.

    python -m studies env_bench [--num-envs 64] [--steps 2] [--presets paper,accurate]
                                [--jacobians newton,chord] [--control-period S]
                                [--arch cpu|gpu] [--out DIR] [--quick]

For each preset (StarParams.preset and SolverConfig.preset of that name) and Jacobian mode
(SolverConfig.jacobian: "chord" reuses a step's first LU; same converged solution) builds
`StarSwimmerVectorEnv(num_envs)` (one Simulator), resets it, takes one untimed step (the
engine compiles on the first advance) and then times --steps steps of seeded random actions
(each actuator fired with probability 1/2). Writes `env_bench.csv` (one row per preset and
Jacobian: preset, jacobian, num_envs, steps, control_period_s, dt_s, n_nodes, wall_s,
robot_seconds_per_s, robot_steps_per_s, cores, load_average_1min (before the run), cpu_model)
with a JSON sidecar into --out (default a fresh runs/env_bench/<timestamp>/).

--quick: 4 environments, one 0.2-s step at dt = 5 ms.
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import pandas as pd

from taichi_star.envs import StarSwimmerVectorEnv
from taichi_star.params import JACOBIANS, PRESETS, SolverConfig, StarParams

from . import common

DESCRIPTION = "Vector environment throughput: simulated robot-seconds per wall second."
QUICK = {"num_envs": 4, "steps": 1, "control_period": 0.2, "dt": 5e-3}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def measure(preset: str, num_envs: int, steps: int, control_period_s=None, dt=None,
            jacobian: str = "newton", arch: str = "cpu") -> dict:
    """One row of env_bench.csv (see the module docstring)."""
    solver = SolverConfig.preset(preset, jacobian=jacobian,
                                 **({} if dt is None else {"dt": dt}))
    envs = StarSwimmerVectorEnv(num_envs, params=StarParams.preset(preset), solver=solver,
                                control_period_s=control_period_s, arch=arch,
                                max_episode_steps=steps + 2)
    envs.reset(seed=0)
    envs.action_space.seed(0)
    load = os.getloadavg()[0]
    envs.step(envs.action_space.sample())  # compiles the engine
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    wall = time.perf_counter() - start
    period = envs.batch.control_period_s
    robot_seconds = num_envs * steps * period
    return {"preset": preset, "jacobian": jacobian, "num_envs": num_envs, "steps": steps,
            "control_period_s": period, "dt_s": solver.dt,
            "n_nodes": envs.batch.simulator.model.topology.n_nodes, "wall_s": wall,
            "robot_seconds_per_s": robot_seconds / wall,
            "robot_steps_per_s": robot_seconds / solver.dt / wall, "cores": os.cpu_count(),
            "load_average_1min": load, "cpu_model": cpu_model(), "arch": arch}


def build_parser():
    parser = common.common_parser("env_bench", DESCRIPTION)
    parser.set_defaults(out=None)
    parser.add_argument("--num-envs", type=int, default=None,
                        help=f"robots in the vector env (default 64; --quick {QUICK['num_envs']})")
    parser.add_argument("--steps", type=int, default=None,
                        help=f"timed steps (default 2; --quick {QUICK['steps']})")
    parser.add_argument("--presets", default=",".join(PRESETS),
                        help=f"comma list of presets (default {','.join(PRESETS)})")
    parser.add_argument("--jacobians", default="newton",
                        help="comma list of Jacobian modes, newton and/or chord (default newton)")
    parser.add_argument("--control-period", type=float, default=None,
                        help="control period, s (default the actuation period, 3.15; --quick "
                             f"{QUICK['control_period']})")
    return parser


def main(argv=None):
    argv = list(argv or [])
    args = build_parser().parse_args(argv)
    num_envs = args.num_envs if args.num_envs is not None else (
        QUICK["num_envs"] if args.quick else 64)
    steps = args.steps if args.steps is not None else (QUICK["steps"] if args.quick else 2)
    period = args.control_period if args.control_period is not None else (
        QUICK["control_period"] if args.quick else None)
    dt = args.dt if args.dt is not None else (QUICK["dt"] if args.quick else None)
    presets = common.parse_values(args.presets, "--presets", str)
    jacobians = common.parse_values(args.jacobians, "--jacobians", str)
    for value, flag in ((num_envs, "--num-envs"), (steps, "--steps")):
        if value < 1:
            raise common.StudyArgumentError(f"{flag} must be >= 1, got {value}")
    for flag, values, allowed in (("--presets", presets, PRESETS),
                                  ("--jacobians", jacobians, JACOBIANS)):
        unknown = [value for value in values if value not in allowed]
        if unknown:
            raise common.StudyArgumentError(f"{flag}: unknown {unknown}; choose from {allowed}")
    out = common.fresh_output(args, "env_bench")
    rows = []
    for preset in presets:
        for jacobian in jacobians:
            try:
                rows.append(measure(preset, num_envs, steps, period, dt, jacobian, args.arch))
            except ValueError as error:
                raise common.StudyArgumentError(str(error)) from None
            print(f"{preset}, {jacobian}: {rows[-1]['robot_seconds_per_s']:.1f} robot-s per "
                  f"wall s ({rows[-1]['robot_steps_per_s']:,.0f} robot-steps/s)")
    table = pd.DataFrame(rows)
    path = common.write_table(table, out / "env_bench.csv", "env_bench", argv)
    print(common.describe([path]))
    return table
