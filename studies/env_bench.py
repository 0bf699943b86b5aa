"""Throughput of the vector environment: simulated robot-seconds per wall second.

    python -m studies env_bench [--num-envs 64] [--steps 2] [--presets paper,accurate]
                                [--jacobians newton,chord] [--control-period S] [--dt S]
                                [--arch cpu|gpu] [--out DIR] [--quick]

For each preset (StarParams.preset and SolverConfig.preset of that name) and Jacobian mode
(SolverConfig.jacobian: "chord" reuses a step's first LU; same converged solution) builds
`StarSwimmerVectorEnv(num_envs)` (one Simulator), resets it, takes one untimed step (the
engine compiles on the first advance) and then times --steps steps of seeded random actions
(each actuator fired with probability 1/2). Writes `env_bench.csv` (one row per preset and
Jacobian: preset, jacobian, num_envs, steps, control_period_s, dt_s, n_nodes, wall_s,
robot_seconds_per_s, robot_steps_per_s, cores, load_average_1min (before the run), cpu_model,
arch) with its provenance sidecar (`.csv.json`) into --out (default a fresh
runs/env_bench/<timestamp>/). robot_steps_per_s counts steps of dt_s, so it is NaN for a solver
with adaptive steps (the accurate preset's), which take steps of their own length: counted in
1-ms steps it was about 11 times the steps taken (an audit, 2026-12).

--quick: 4 environments, one 0.2-s step at dt = 5 ms.

The robot-steps of every setting together are refused past the library's limit, or estimated
when long, before any environment is built.
"""

from __future__ import annotations

import math
import os
import time

import pandas as pd

from taichi_star import JACOBIANS, PRESETS, SolverConfig, StarParams, fewest_steps
from taichi_star.envs import StarSwimmerVectorEnv, control_period
from taichi_star.provenance import cpu_model
from taichi_star.runtime import check_batch_memory

from . import cli

DESCRIPTION = "Vector environment throughput: simulated robot-seconds per wall second."
QUICK_NUM_ENVS = 4
QUICK_STEPS = 1
QUICK_CONTROL_PERIOD_S = 0.2
QUICK_DT = 5e-3


def measure(preset: str, solver: SolverConfig, num_envs: int, steps: int,
            control_period_s=None, arch: str = "cpu") -> dict:
    """One row of env_bench.csv (see the module docstring): the robots of `preset` stepped
    with `solver`."""
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
    period = envs.control_period_s
    robot_seconds = num_envs * steps * period
    return {"preset": preset, "jacobian": solver.jacobian, "num_envs": num_envs, "steps": steps,
            "control_period_s": period, "dt_s": solver.dt,
            "n_nodes": envs.simulator.n_nodes, "wall_s": wall,
            "robot_seconds_per_s": robot_seconds / wall,
            "robot_steps_per_s": (math.nan if solver.adaptive
                                  else robot_seconds / solver.dt / wall),
            "cores": os.cpu_count(),
            "load_average_1min": load, "cpu_model": cpu_model(), "arch": arch}


def build_parser():
    parser = cli.StudyParser("env_bench", DESCRIPTION)
    cli.add_dt_flag(parser, quick=QUICK_DT, jacobian=False)
    parser.add_argument("--num-envs", type=int, default=64, quick=QUICK_NUM_ENVS,
                        help=f"robots in the vector env, at most {cli.MAX_BATCH_SIZE}")
    parser.add_argument("--steps", type=int, default=2, quick=QUICK_STEPS, help="timed steps")
    parser.add_argument("--presets", default="paper,accurate",
                        help=f"comma list of presets from {','.join(PRESETS)} (default "
                             f"paper,accurate)")
    parser.add_argument("--jacobians", default="newton",
                        help=f"comma list of Jacobian modes, {' and/or '.join(JACOBIANS)} "
                             f"(default newton)")
    parser.add_argument("--control-period", type=float, default=None,
                        quick=QUICK_CONTROL_PERIOD_S,
                        help="control period, s (none: the actuation period, 3.15)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    presets = cli.parse_choices(args.presets, "--presets", PRESETS)
    jacobians = cli.parse_choices(args.jacobians, "--jacobians", JACOBIANS)
    cli.check_count(args.num_envs, "--num-envs", 1, cli.MAX_BATCH_SIZE)
    if args.steps < 1:
        raise cli.StudyArgumentError(f"--steps must be >= 1, got {args.steps}")
    solvers = {}
    robot_steps = 0.0
    for preset in presets:
        for jacobian in jacobians:
            try:
                solvers[preset, jacobian] = SolverConfig.preset(
                    preset, jacobian=jacobian, **({} if args.dt is None else {"dt": args.dt}))
            except ValueError as error:
                raise cli.StudyArgumentError(f"--dt: {error}") from None
            try:
                period = control_period(StarParams.preset(preset), solvers[preset, jacobian],
                                        args.control_period)
            except ValueError as error:
                raise cli.StudyArgumentError(f"--control-period: {error}") from None
            # the timed steps and the one that compiles, one control period each
            duration = (args.steps + 1) * period
            cli.check_run(f"--steps {args.steps} (+1 compiling) of --control-period {period:g} s "
                          f"({duration:.3g} s)", duration, solvers[preset, jacobian])
            steps, _ = fewest_steps(solvers[preset, jacobian], duration, 0.0)
            robot_steps += args.num_envs * steps
    # each setting's steps checked above; all settings' robots together refused or estimated
    # here (--num-envs 65536 --steps 50000, 1.03e13 robot-steps, started without a word: an
    # audit, 2026-12), before the memory (whose refusal depends on what the machine has free)
    cli.check_robot_steps(f"--num-envs {args.num_envs} × --steps {args.steps} (+1 compiling) × "
                          f"{len(solvers)} preset and Jacobian setting(s)", robot_steps)
    for preset in presets:
        try:  # a million robots' engine: 116 GiB, failed after two minutes (an audit)
            check_batch_memory([StarParams.preset(preset)] * args.num_envs,
                               solvers[preset, jacobians[0]].precision, args.arch)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--num-envs: {error}") from None
    out = cli.Output(args, argv or [], model={"presets": presets},
                     solver={f"{preset}, {jacobian}": solver
                             for (preset, jacobian), solver in solvers.items()},
                     extra={"jacobians": jacobians, "num_envs": args.num_envs,
                            "steps": args.steps})
    rows = []
    for (preset, jacobian), solver in solvers.items():
        with cli.batch_work_told():  # told above for the whole run: not again for each step
            rows.append(measure(preset, solver, args.num_envs, args.steps,
                                args.control_period, args.arch))
        steps_rate = rows[-1]["robot_steps_per_s"]
        print(f"{preset}, {jacobian}: {rows[-1]['robot_seconds_per_s']:.1f} robot-s per wall s"
              + ("" if math.isnan(steps_rate) else f" ({steps_rate:,.0f} robot-steps/s)"))
    table = pd.DataFrame(rows)
    out.write_csv(table, "env_bench.csv")
    out.report()
    return table
